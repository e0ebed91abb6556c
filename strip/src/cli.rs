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
        if let Some(v) = self.length_mm { p.length_m = v * mm; }
        if let Some(v) = self.element_mm { p.element_m = v * mm; }
        if let Some(v) = self.nu { p.poisson = v; }
        if let Some(v) = self.youngs_mpa { p.youngs_pa = v * 1e6; }
        if let Some(v) = self.density { p.density_kg_m3 = v; }
        if let Some(v) = self.order { p.order = v; }
        if let Some(v) = self.substrate { p.substrate = v; }
        if let Some(v) = self.cb_boundary { p.cb_boundary = v; }
        if let Some(v) = self.cutoff_hz { p.cb_cutoff_hz = v; }
        if let Some(v) = self.alpha { p.damping_alpha_per_s = v; }
        if let Some(v) = self.beta { p.damping_beta_s = v; }
        if let Some(v) = self.bulge_amplitude_mm { p.bulge_amplitude_m = v * mm; }
        if let Some(v) = self.bulge_width_mm { p.bulge_width_m = v * mm; }
        if let Some(v) = self.bulge_center_mm { p.bulge_center_m = v * mm; }
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
            // the report built the model anyway: keep it in the cache
            let path = crate::cache::cache_path(&crate::cache::cache_dir(), &p);
            if let Err(e) = crate::cache::save(&m, &path) {
                tracing::warn!(error = %e, "could not cache the model");
            }
            print!("{}", r.table());
            if let Some(out) = json {
                let text = serde_json::to_string_pretty(&r)?;
                std::fs::write(&out, text).with_context(|| format!("writing {}", out.display()))?;
                println!("report written to {}", out.display());
            }
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
