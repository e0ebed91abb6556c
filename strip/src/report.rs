//! Verification report (thesis Section 5.2.1, 5.3.2, Table D.1): eigenfrequencies and static
//! wheel response of the full, Craig-Bampton and reduced models.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Instant;

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use serde::{Deserialize, Serialize};

use crate::eig::{lowest_modes, Want};
use crate::error::{numeric, Result};
use crate::model::{gaussian_weights, Artifacts, StripModel};
use crate::params::StripParams;
use crate::sparse::Cholesky;

/// Wheel force of the static comparison (N, pressing), Section 4.2.
pub const REPORT_WHEEL_FORCE_N: f64 = 10.0;
/// Bond pressure the tape needs (Pa), Section 4.2.
pub const BOND_PRESSURE_PA: f64 = 100e3;
const N_FREQ: usize = 30;

/// Static response of one model to the report wheel load.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StaticResult {
    /// Wheel force over the Gaussian-weighted top displacement under the wheel (N/m).
    pub k_s_n_per_m: f64,
    /// Gaussian-weighted top u_y under the wheel (m, +y: negative when pressed).
    pub top_displacement_m: f64,
    /// Largest bottom pressure on the centre line x = 0 (Pa, compressive positive).
    pub centreline_peak_pressure_pa: f64,
    /// Centre-line z range where the pressure exceeds 100 kPa ([from, to], m), if any.
    pub centreline_over_100kpa_z_m: Option<[f64; 2]>,
    /// Sum of all bottom reactions (N, +y on the strip): equals the wheel force.
    pub total_bottom_reaction_n: f64,
    /// Centre-line pressure profile: (z m, Pa).
    pub centreline_pressure: Vec<[f64; 2]>,
    /// Top u_y of every top node (m).
    pub top_uy_m: Vec<f64>,
    /// Bottom reactions of every bottom node (N).
    pub bottom_reaction_n: Vec<f64>,
    /// Largest sideways (x) bottom displacement (m): nonzero on the sliding substrate only
    /// (Figures 4.3, 5.3); None for the reduced model, which does not output it.
    pub bottom_sideways_max_m: Option<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StaticSet {
    pub full: StaticResult,
    pub cb: StaticResult,
    pub reduced: StaticResult,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    pub params: StripParams,
    pub dof_free: usize,
    pub cb_boundary_dofs: usize,
    pub cb_modes: usize,
    pub cb_states: usize,
    pub order: usize,
    pub wheel_z_m: f64,
    pub freq_full_hz: Vec<f64>,
    pub freq_cb_hz: Vec<f64>,
    pub freq_reduced_hz: Vec<f64>,
    #[serde(rename = "static")]
    pub statics: StaticSet,
    pub hankel_singular_values: Vec<f64>,
    pub d_nonzero: bool,
    /// Relative DC residual of the matched-DC formulas from rounding (folded into D).
    pub dc_residual_rel: f64,
    pub max_real_pole_per_s: f64,
    pub timings_s: BTreeMap<String, f64>,
}

fn static_result(model: &StripModel, w: &[f64], top_uy: Vec<f64>, react: Vec<f64>) -> StaticResult {
    let wu: f64 = w.iter().zip(&top_uy).map(|(a, b)| a * b).sum();
    let prof: Vec<[f64; 2]> = model.centre_line().map(|(i, z, a)| [z, react[i] / a]).collect();
    let peak = prof.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let over = over_range(&prof, BOND_PRESSURE_PA);
    StaticResult {
        k_s_n_per_m: REPORT_WHEEL_FORCE_N / -wu,
        top_displacement_m: wu,
        centreline_peak_pressure_pa: peak,
        centreline_over_100kpa_z_m: over,
        total_bottom_reaction_n: react.iter().sum(),
        centreline_pressure: prof,
        top_uy_m: top_uy,
        bottom_reaction_n: react,
        bottom_sideways_max_m: None,
    }
}

/// z range (linear interpolation between nodes) where the profile exceeds `level`.
pub fn over_range(prof: &[[f64; 2]], level: f64) -> Option<[f64; 2]> {
    let first = prof.iter().position(|p| p[1] >= level)?;
    let last = prof.iter().rposition(|p| p[1] >= level)?;
    let cross = |a: [f64; 2], b: [f64; 2]| a[0] + (level - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
    let from = if first > 0 { cross(prof[first - 1], prof[first]) } else { prof[first][0] };
    let to = if last + 1 < prof.len() { cross(prof[last], prof[last + 1]) } else { prof[last][0] };
    Some([from, to])
}

/// Builds the model (no cache: the intermediate systems are needed) and compares the models.
pub fn make_report(p: &StripParams) -> Result<(Report, StripModel)> {
    let (model, art) = StripModel::build_detailed(p)?;
    let report = compare(&model, &art)?;
    Ok((report, model))
}

pub fn compare(model: &StripModel, art: &Artifacts) -> Result<Report> {
    let p = &model.params;
    let mut timings: BTreeMap<String, f64> = model.info.timings_s.iter().cloned().collect();
    let total: f64 = model.info.timings_s.iter().map(|t| t.1).sum();
    timings.insert("build_total".into(), total);
    let sys = &art.sys;
    let t0 = Instant::now();
    crate::progress::stage("full model: factorisation and eigenfrequencies");
    let kf = Cholesky::new(&sys.k_ff, "full model stiffness")?;
    let full_modes = lowest_modes(&kf, &sys.k_ff, &sys.m_ff, Want::Count(N_FREQ))?;
    let freq_full_hz: Vec<f64> = full_modes.lambda.iter().map(|l| l.sqrt() / (2.0 * std::f64::consts::PI)).collect();
    timings.insert("report_full_eigen".into(), t0.elapsed().as_secs_f64());

    let t1 = Instant::now();
    let z_a = 0.5 * p.length_m;
    let n_top = model.n_top();
    let mut w = vec![0.0; n_top];
    gaussian_weights(&model.top_xyz_m, z_a, &mut w);
    let u: Vec<f64> = w.iter().map(|wi| -REPORT_WHEEL_FORCE_N * wi).collect();
    // full
    let mut q = vec![0.0; sys.n_free()];
    for (j, &f) in sys.top_y_free.iter().enumerate() {
        q[f] = u[j];
    }
    kf.solve_vec(&mut q);
    let mut r_full = vec![0.0; sys.bottom_nodes.len()];
    sys.reactions(&q, None, &mut r_full);
    let sideways = |q: &[f64]| {
        sys.bottom_nodes
            .iter()
            .map(|&n| sys.free_of[3 * n]) // x DOF
            .filter(|&f| f != usize::MAX)
            .map(|f| q[f].abs())
            .fold(0.0f64, f64::max)
    };
    let mut full = static_result(model, &w, sys.top_y_free.iter().map(|&f| q[f]).collect(), r_full);
    full.bottom_sideways_max_m = Some(sideways(&q));
    // Craig-Bampton
    let cb = &art.cb;
    let n = cb.k.nrows();
    let mut pcb = Mat::<f64>::zeros(n, 1);
    for (j, &c) in cb.input_coord.iter().enumerate() {
        pcb[(c, 0)] = u[j];
    }
    cb.k.llt(Side::Lower).map_err(|e| numeric("CB statics", format!("{e:?}")))?.solve_in_place(pcb.as_mut());
    let rcb = &cb.c_react * &pcb;
    let mut cbr =
        static_result(model, &w, cb.input_coord.iter().map(|&c| pcb[(c, 0)]).collect(), (0..rcb.nrows()).map(|i| rcb[(i, 0)]).collect());
    let pv: Vec<f64> = (0..n).map(|i| pcb[(i, 0)]).collect();
    cbr.bottom_sideways_max_m = Some(sideways(&cb.expand(&pv, sys.n_free())));
    // reduced
    let y = model.static_response(&u);
    let red = static_result(model, &w, y[..n_top].to_vec(), y[n_top..].to_vec());
    timings.insert("report_statics".into(), t1.elapsed().as_secs_f64());

    let freq_cb_hz = art.cb_modal.omega2.iter().take(N_FREQ).map(|l| l.sqrt() / (2.0 * std::f64::consts::PI)).collect();
    let mut fr: Vec<f64> = model.modal.lam.iter().map(|l| l.norm() / (2.0 * std::f64::consts::PI)).collect();
    fr.sort_by(f64::total_cmp);
    fr.truncate(N_FREQ);
    let max_real = model.modal.lam.iter().map(|l| l.re).fold(f64::NEG_INFINITY, f64::max);
    Ok(Report {
        params: p.clone(),
        dof_free: model.info.dof_free,
        cb_boundary_dofs: model.info.cb_boundary_dofs,
        cb_modes: model.info.cb_modes,
        cb_states: model.info.cb_states,
        order: model.order(),
        wheel_z_m: z_a,
        freq_full_hz,
        freq_cb_hz,
        freq_reduced_hz: fr,
        statics: StaticSet { full, cb: cbr, reduced: red },
        hankel_singular_values: model.hsv.clone(),
        d_nonzero: model.d.norm_max() > 0.0,
        dc_residual_rel: model.info.dc_residual_rel,
        max_real_pole_per_s: max_real,
        timings_s: timings,
    })
}

impl Report {
    /// Human-readable table.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let p = &self.params;
        let _ = writeln!(
            s,
            "weatherstrip model: L = {:.1} mm, h = {:.2} mm, nu = {}, {:?} substrate, CB boundary {:?}, cut-off {} Hz",
            p.length_m * 1e3,
            p.element_m * 1e3,
            p.poisson,
            p.substrate,
            p.cb_boundary,
            p.cb_cutoff_hz
        );
        let _ = writeln!(
            s,
            "free DOF {}  |  CB: {} boundary + {} modes = {} states  |  reduced order {}  |  D nonzero: {}  |  slowest pole Re {:.3e} 1/s  |  matched-DC rounding residue {:.1e}",
            self.dof_free, self.cb_boundary_dofs, self.cb_modes, self.cb_states, self.order, self.d_nonzero, self.max_real_pole_per_s, self.dc_residual_rel
        );
        let _ = writeln!(s, "\neigenfrequencies (Table D.1 comparison)");
        let _ = writeln!(s, "{:>4} {:>12} {:>10} {:>10}", "mode", "full [Hz]", "full/CB", "full/red");
        for i in 0..self.freq_full_hz.len() {
            let f = self.freq_full_hz[i];
            let r = |v: &Vec<f64>| v.get(i).map(|x| format!("{:.4}", f / x)).unwrap_or_else(|| "-".into());
            let _ = writeln!(s, "{:>4} {:>12.2} {:>10} {:>10}", i + 1, f, r(&self.freq_cb_hz), r(&self.freq_reduced_hz));
        }
        let _ = writeln!(s, "\nstatic response, {} N wheel at z = {:.1} mm", REPORT_WHEEL_FORCE_N, self.wheel_z_m * 1e3);
        let _ = writeln!(
            s,
            "{:>8} {:>12} {:>14} {:>16} {:>22} {:>12} {:>16}",
            "model", "k_s [N/mm]", "top u_y [mm]", "peak p_c [kPa]", "p_c > 100 kPa z [mm]", "sum R [N]", "max |u_x| bot [mm]"
        );
        for (name, r) in [("full", &self.statics.full), ("cb", &self.statics.cb), ("reduced", &self.statics.reduced)] {
            let over =
                r.centreline_over_100kpa_z_m.map(|[a, b]| format!("{:.2} .. {:.2}", a * 1e3, b * 1e3)).unwrap_or_else(|| "none".into());
            let _ = writeln!(
                s,
                "{:>8} {:>12.3} {:>14.5} {:>16.2} {:>22} {:>12.5} {:>16}",
                name,
                r.k_s_n_per_m * 1e-3,
                r.top_displacement_m * 1e3,
                r.centreline_peak_pressure_pa * 1e-3,
                over,
                r.total_bottom_reaction_n,
                r.bottom_sideways_max_m.map(|v| format!("{:.5}", v * 1e3)).unwrap_or_else(|| "-".into())
            );
        }
        let hs = &self.hankel_singular_values;
        let o = self.order.min(hs.len());
        let _ = writeln!(
            s,
            "\nHankel singular values: first {:.3e}, at order {} {:.3e}, next {:.3e}, last {:.3e}",
            hs[0],
            o,
            hs[o - 1],
            hs.get(o).copied().unwrap_or(0.0),
            hs[hs.len() - 1]
        );
        let _ = writeln!(s, "\ntimings [s]");
        for (k, v) in &self.timings_s {
            let _ = writeln!(s, "  {k:<28} {v:>8.3}");
        }
        s
    }
}
