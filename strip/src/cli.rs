//! `rig model ...` subcommands: build (and cache), report, export. Millimetres at this edge only.

use std::path::PathBuf;

use anyhow::Context;

use crate::params::{CbBoundary, StripParams, Substrate};
use crate::StripModel;

/// Model parameters on the command line (defaults = DESIGN section 4).
#[derive(clap::Args, Debug, Clone)]
pub struct ModelArgs {
    /// JSON file with a full or partial `StripParams` (SI units); flags below override it.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Strip length (mm).
    #[arg(long)]
    pub length_mm: Option<f64>,
    /// Element edge (mm): 2 (thesis, ~2000 DOF), 1 (default), 0.5.
    #[arg(long)]
    pub element_mm: Option<f64>,
    /// Poisson's ratio.
    #[arg(long)]
    pub nu: Option<f64>,
    /// Young's modulus (MPa).
    #[arg(long)]
    pub youngs_mpa: Option<f64>,
    /// Density (kg/m^3).
    #[arg(long)]
    pub density: Option<f64>,
    /// Reduced order (states).
    #[arg(long)]
    pub order: Option<usize>,
    #[arg(long, value_enum)]
    pub substrate: Option<Substrate>,
    #[arg(long, value_enum)]
    pub cb_boundary: Option<CbBoundary>,
    /// Fixed-interface mode cut-off (Hz).
    #[arg(long)]
    pub cutoff_hz: Option<f64>,
    /// Rayleigh alpha (1/s).
    #[arg(long)]
    pub alpha: Option<f64>,
    /// Rayleigh beta (s).
    #[arg(long)]
    pub beta: Option<f64>,
    #[arg(long)]
    pub bulge_amplitude_mm: Option<f64>,
    #[arg(long)]
    pub bulge_width_mm: Option<f64>,
    #[arg(long)]
    pub bulge_center_mm: Option<f64>,
}

impl ModelArgs {
    pub fn to_params(&self) -> anyhow::Result<StripParams> {
        let mut p = match &self.params {
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                serde_json::from_str(&text).with_context(|| format!("parsing strip parameters in {}", path.display()))?
            }
            None => StripParams::default(),
        };
        let mm = 1e-3;
        if let Some(v) = self.length_mm {
            p.length_m = v * mm;
        }
        if let Some(v) = self.element_mm {
            p.element_m = v * mm;
        }
        if let Some(v) = self.nu {
            p.poisson = v;
        }
        if let Some(v) = self.youngs_mpa {
            p.youngs_pa = v * 1e6;
        }
        if let Some(v) = self.density {
            p.density_kg_m3 = v;
        }
        if let Some(v) = self.order {
            p.order = v;
        }
        if let Some(v) = self.substrate {
            p.substrate = v;
        }
        if let Some(v) = self.cb_boundary {
            p.cb_boundary = v;
        }
        if let Some(v) = self.cutoff_hz {
            p.cb_cutoff_hz = v;
        }
        if let Some(v) = self.alpha {
            p.damping_alpha_per_s = v;
        }
        if let Some(v) = self.beta {
            p.damping_beta_s = v;
        }
        if let Some(v) = self.bulge_amplitude_mm {
            p.bulge_amplitude_m = v * mm;
        }
        if let Some(v) = self.bulge_width_mm {
            p.bulge_width_m = v * mm;
        }
        if let Some(v) = self.bulge_center_mm {
            p.bulge_center_m = v * mm;
        }
        p.validate()?;
        Ok(p)
    }
}

#[derive(clap::Subcommand, Debug, Clone)]
pub enum Command {
    /// Build the reduced model (or find it in the cache) and print a summary.
    Build {
        #[command(flatten)]
        model: ModelArgs,
        /// Rebuild even if a cached model exists.
        #[arg(long)]
        force: bool,
    },
    /// Compare full, Craig-Bampton and reduced models (Table D.1, static 10 N wheel).
    Report {
        #[command(flatten)]
        model: ModelArgs,
        /// Write the report as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Bond check on the full FE model in statics: the centre-line peak pressure of a roll for
    /// the strip bonded everywhere (the plant's model) and for the laying process (glued behind
    /// the wheel, resting without friction ahead), and the force the bonded strip needs.
    Bond {
        #[command(flatten)]
        model: ModelArgs,
        /// Wheel force (N, pressing magnitude).
        #[arg(long, default_value_t = 10.0)]
        force_n: f64,
        /// Wheel travel (mm): from, to, and the sampling step.
        #[arg(long, default_value_t = 2.0)]
        from_mm: f64,
        #[arg(long, default_value_t = 38.0)]
        to_mm: f64,
        #[arg(long, default_value_t = 0.5)]
        step_mm: f64,
        /// The range judged (mm), as in issue 6: every node from z = 4 to 36 mm.
        #[arg(long, default_value_t = 4.0)]
        judge_from_mm: f64,
        #[arg(long, default_value_t = 36.0)]
        judge_to_mm: f64,
    },
    /// What a contour's curvature does to the pressure under the wheel (issue 26): the full FE
    /// strip in statics, bonded everywhere, straight and bent about its normal along a circle of
    /// the given radius (the inside of the bend at +x), the wheel rolled along the centre line.
    /// The loop's strip neglects the curvature; this measures what that costs.
    Curvature {
        #[command(flatten)]
        model: ModelArgs,
        /// Bend radius of the strip's centre line (mm): the smallest of the contour.
        #[arg(long, default_value_t = 50.0)]
        radius_mm: f64,
        /// Wheel force (N, pressing magnitude).
        #[arg(long, default_value_t = 10.0)]
        force_n: f64,
        /// Wheel travel (mm): from, to, and the sampling step.
        #[arg(long, default_value_t = 4.0)]
        from_mm: f64,
        #[arg(long, default_value_t = 36.0)]
        to_mm: f64,
        #[arg(long, default_value_t = 1.0)]
        step_mm: f64,
    },
    /// Export A, B, C, D, node coordinates and the input/output maps as NumPy .npz.
    Export {
        #[command(flatten)]
        model: ModelArgs,
        #[arg(long)]
        npz: PathBuf,
    },
}

pub fn run(cmd: Command) -> anyhow::Result<()> {
    match cmd {
        Command::Build { model, force } => {
            let p = model.to_params()?;
            let dir = crate::cache::cache_dir();
            let path = crate::cache::cache_path(&dir, &p);
            if force {
                let _ = std::fs::remove_file(&path);
            }
            let t = std::time::Instant::now();
            let m = StripModel::load_or_build_in(&dir, &p)?;
            println!(
                "strip model: {} free DOF, CB {} states, order {}, {} inputs, {} outputs ({:.3} s)\ncache: {}",
                m.info.dof_free,
                m.info.cb_states,
                m.order(),
                m.n_top(),
                m.c.nrows(),
                t.elapsed().as_secs_f64(),
                path.display()
            );
            for (k, v) in &m.info.timings_s {
                println!("  {k:<24} {v:>8.3} s");
            }
        }
        Command::Report { model, json } => {
            let p = model.to_params()?;
            let (r, m) = {
                let _progress = crate::progress::Progress::start("report");
                crate::report::make_report(&p)?
            };
            // the report built the model anyway: keep it in the cache (which holds the
            // reference bump's model only; another height's is that one scaled)
            let path = crate::cache::cache_path(&crate::cache::cache_dir(), &p);
            if m.params == p.with_reference_bulge() {
                if let Err(e) = crate::cache::save(&m, &path) {
                    tracing::warn!(error = %e, "could not cache the model");
                }
            }
            print!("{}", r.table());
            if let Some(out) = json {
                let text = serde_json::to_string_pretty(&r)?;
                std::fs::write(&out, text).with_context(|| format!("writing {}", out.display()))?;
                println!("report written to {}", out.display());
            }
        }
        Command::Bond { model, force_n, from_mm, to_mm, step_mm, judge_from_mm, judge_to_mm } => {
            bond(&model.to_params()?, force_n, [from_mm, to_mm, step_mm], [judge_from_mm, judge_to_mm])?;
        }
        Command::Curvature { model, radius_mm, force_n, from_mm, to_mm, step_mm } => {
            curvature(&model.to_params()?, radius_mm * 1e-3, force_n, [from_mm, to_mm, step_mm])?;
        }
        Command::Export { model, npz } => {
            let p = model.to_params()?;
            let m = StripModel::load_or_build(&p)?;
            crate::export::write_npz(&m, &npz)?;
            println!("exported order-{} model to {}", m.order(), npz.display());
        }
    }
    Ok(())
}

/// The statics commands' wheel: a pressing force (N, positive) and a roll `[from, to, step]` (mm)
/// within the strip, the roll returned in m.
fn roll_in_m(p: &StripParams, force_n: f64, roll_mm: [f64; 3]) -> anyhow::Result<[f64; 3]> {
    if !(force_n.is_finite() && force_n > 0.0) {
        anyhow::bail!("--force-n {force_n}: give the pressing force as a positive number of newtons");
    }
    let [from, to, step] = roll_mm.map(|v| v * 1e-3);
    if !(step > 0.0 && from < to && from >= 0.0 && to <= p.length_m) {
        anyhow::bail!("--from-mm/--to-mm/--step-mm {roll_mm:?}: need 0 <= from < to <= strip length and step > 0");
    }
    Ok([from, to, step])
}

/// `rig model bond`: prints the table and the weakest node of each support.
fn bond(p: &StripParams, force_n: f64, roll_mm: [f64; 3], judged_mm: [f64; 2]) -> anyhow::Result<()> {
    use crate::laying::{bond_check, bonded_min_force, BottomSupport, LayingModel};
    use crate::report::BOND_PRESSURE_PA;
    let [from, to, step] = roll_in_m(p, force_n, roll_mm)?;
    let _progress = crate::progress::Progress::start("bond");
    let m = LayingModel::build(p)?;
    let (bonded, _) = bond_check(&m, -force_n, BottomSupport::BondedEverywhere, from, to, step)?;
    let (front, lifted) = bond_check(&m, -force_n, BottomSupport::BondFront, from, to, step)?;
    let need = bonded_min_force(&m, BOND_PRESSURE_PA, from, to, step)?;
    drop(_progress);
    println!(
        "centre-line peak bottom pressure, wheel {force_n} N rolled z = {:.1}..{:.1} mm every {:.2} mm; bump {:.3} mm high, {:.1} mm wide at z = {:.1} mm",
        roll_mm[0], roll_mm[1], roll_mm[2], p.bulge_amplitude_m * 1e3, p.bulge_width_m * 1e3, p.bulge_center_m * 1e3
    );
    println!("{:>7} {:>12} {:>16} {:>22}", "z (mm)", "bonded (kPa)", "laying (kPa)", "bonded needs (N)");
    for ((b, f), n) in bonded.iter().zip(&front).zip(&need) {
        println!("{:>7.1} {:>12.1} {:>16.1} {:>22.2}", b.0 * 1e3, b.1 * 1e-3, f.1 * 1e-3, n.1);
    }
    let judged = |q: &&(f64, f64)| q.0 >= judged_mm[0] * 1e-3 - 1e-9 && q.0 <= judged_mm[1] * 1e-3 + 1e-9;
    let weakest = |v: &[(f64, f64)]| v.iter().filter(judged).fold((f64::NAN, f64::INFINITY), |w, q| if q.1 < w.1 { *q } else { w });
    let share = |v: &[(f64, f64)]| {
        let all: Vec<_> = v.iter().filter(judged).collect();
        100.0 * all.iter().filter(|q| q.1 >= BOND_PRESSURE_PA).count() as f64 / all.len().max(1) as f64
    };
    let most = need.iter().filter(judged).fold((f64::NAN, 0.0), |w, q| if q.1 > w.1 { *q } else { w });
    let (wb, wf) = (weakest(&bonded), weakest(&front));
    println!("judged z = {:.1}..{:.1} mm, bond needs {:.0} kPa:", judged_mm[0], judged_mm[1], BOND_PRESSURE_PA * 1e-3);
    println!("  bonded everywhere: weakest {:.1} kPa at z = {:.1} mm, {:.1} % of the nodes bond", wb.1 * 1e-3, wb.0 * 1e3, share(&bonded));
    println!(
        "  laying process:    weakest {:.1} kPa at z = {:.1} mm, {:.1} % of the nodes bond ({lifted} nodes lifted at most)",
        wf.1 * 1e-3,
        wf.0 * 1e3,
        share(&front)
    );
    println!("  bonded everywhere needs a constant {:.2} N (set by z = {:.1} mm)", most.1, most.0 * 1e3);
    Ok(())
}

/// `rig model curvature`: the centre line's pressure under the wheel and the section's largest
/// bottom pressure there, straight and bent, per wheel position, and the largest differences.
fn curvature(p: &StripParams, radius_m: f64, force_n: f64, roll_mm: [f64; 3]) -> anyhow::Result<()> {
    use crate::laying::{BottomSupport, LayingModel};
    if !(radius_m.is_finite() && radius_m > crate::mesh::HALF_WIDTH_M) {
        anyhow::bail!(
            "--radius-mm {}: give a radius larger than the strip's half width ({} mm)",
            radius_m * 1e3,
            crate::mesh::HALF_WIDTH_M * 1e3
        );
    }
    let [from, to, step] = roll_in_m(p, force_n, roll_mm)?;
    let _progress = crate::progress::Progress::start("curvature");
    let (straight, bent) = (LayingModel::build(p)?, LayingModel::build_bent(p, Some(radius_m))?);
    let line = straight.centre_line();
    let per = line.get(1).map_or(1, |b| b.0 - line[0].0);
    // Per wheel position: z, and the centre-line and section-maximum pressures, straight and bent.
    struct Row {
        z_m: f64,
        centre_pa: [f64; 2],
        section_max_pa: [f64; 2],
    }
    let mut rows = Vec::new();
    let mut z = from;
    while z <= to + 1e-12 {
        let (a, b) =
            (straight.solve(z, -force_n, BottomSupport::BondedEverywhere)?, bent.solve(z, -force_n, BottomSupport::BondedEverywhere)?);
        // the centre-line node nearest the wheel, and its layer across the section
        let &(i, _) = line.iter().min_by(|x, y| (x.1 - z).abs().total_cmp(&(y.1 - z).abs())).expect("a centre line");
        let layer = i / per * per..i / per * per + per;
        let max = |v: &[f64]| v[layer.clone()].iter().fold(f64::MIN, |m, &x| m.max(x));
        rows.push(Row {
            z_m: z,
            centre_pa: [a.pressure_pa[i], b.pressure_pa[i]],
            section_max_pa: [max(&a.pressure_pa), max(&b.pressure_pa)],
        });
        z += step;
    }
    drop(_progress);
    println!(
        "bottom pressure under a {force_n} N wheel, strip straight and bent along R = {:.1} mm (bonded everywhere; bump {:.3} mm high at z = {:.1} mm)",
        radius_m * 1e3,
        p.bulge_amplitude_m * 1e3,
        p.bulge_center_m * 1e3
    );
    println!(
        "{:>7} {:>22} {:>20} {:>9} {:>24} {:>22} {:>9}",
        "z (mm)", "centre, straight (kPa)", "centre, bent (kPa)", "diff %", "section max, straight", "section max, bent", "diff %"
    );
    let pct = |[a, b]: [f64; 2]| 100.0 * (b - a) / a;
    for r in &rows {
        let ([cs, cb], [ms, mb]) = (r.centre_pa, r.section_max_pa);
        println!(
            "{:>7.1} {:>22.2} {:>20.2} {:>9.2} {:>24.2} {:>22.2} {:>9.2}",
            r.z_m * 1e3,
            cs * 1e-3,
            cb * 1e-3,
            pct(r.centre_pa),
            ms * 1e-3,
            mb * 1e-3,
            pct(r.section_max_pa)
        );
    }
    let worst = |f: fn(&Row) -> [f64; 2]| {
        rows.iter().map(|r| (r.z_m, pct(f(r)))).fold((f64::NAN, 0.0f64), |w, x| if x.1.abs() > w.1.abs() { x } else { w })
    };
    let ((zc, dc), (zm, dm)) = (worst(|r| r.centre_pa), worst(|r| r.section_max_pa));
    println!(
        "largest change from the bend: centre line under the wheel {dc:+.2} % (z = {:.1} mm), section maximum {dm:+.2} % (z = {:.1} mm)",
        zc * 1e3,
        zm * 1e3
    );
    Ok(())
}
