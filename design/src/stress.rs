//! Bottom stress check of issue 6 (thesis Figure 7.4): the centre-line bottom pressure recorded
//! while the wheel passes a position, against the static FULL finite-element solution for the same
//! wheel force at the same position (plus the bulge's static reactions, also from the full model).

use anyhow::Context;
use recording_tools::read::Recording;
use strip::sparse::Cholesky;
use strip::system::FullSystem;
use strip::{gaussian_weights, StripModel};

/// Centre-line comparison at one wheel position.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StressComparison {
    pub tick: u64,
    pub wheel_z_m: f64,
    /// Contact force of that tick (N, negative = pressing), used for the static load.
    pub wheel_force_n: f64,
    /// (z m, recorded Pa, full static Pa) per centre-line node.
    pub profile: Vec<(f64, f64, f64)>,
    /// max |recorded − full| / max full over the centre line.
    pub max_rel_diff: f64,
}

/// Compare at the first recorded tick where the wheel reaches `z_m` while pressing.
pub fn compare_at(rec: &Recording, model: &StripModel, z_m: f64) -> anyhow::Result<StressComparison> {
    let i = rec
        .strip
        .iter()
        .position(|s| s.wheel_z_m >= z_m && s.contact_force_n < 0.0)
        .with_context(|| format!("{}: the wheel never pressed at z >= {z_m} m", rec.path.display()))?;
    let row = &rec.strip[i];
    let sys = FullSystem::build(&model.params);
    let kf = Cholesky::new(&sys.k_ff, "full model stiffness").map_err(|e| anyhow::anyhow!("{e}"))?;
    let top_xyz: Vec<[f64; 3]> = sys.top_nodes.iter().map(|&n| sys.mesh.coords[n]).collect();
    let mut w = vec![0.0; top_xyz.len()];
    gaussian_weights(&top_xyz, row.wheel_z_m, &mut w);
    let mut q = vec![0.0; sys.n_free()];
    for (j, &f) in sys.top_y_free.iter().enumerate() {
        q[f] = row.contact_force_n * w[j];
    }
    kf.solve_vec(&mut q);
    let mut react = vec![0.0; sys.bottom_nodes.len()];
    sys.reactions(&q, None, &mut react);
    let z_rec = rec.centreline_z_m();
    let mut profile = Vec::new();
    for (c, (bi, z, area)) in model.centre_line().enumerate() {
        let full = (react[bi] + model.bulge_bottom_reaction_n[bi]) / area;
        let recorded = *row.centreline_pressure_pa.get(c).context("recorded centre line shorter than the model's")? as f64;
        debug_assert!((z_rec.get(c).copied().unwrap_or(z) - z).abs() < 1e-6);
        profile.push((z, recorded, full));
    }
    let peak = profile.iter().map(|p| p.2.abs()).fold(0.0, f64::max);
    let max_rel_diff = profile.iter().map(|p| (p.1 - p.2).abs()).fold(0.0, f64::max) / peak;
    Ok(StressComparison {
        tick: rec.joint_state[i].tick,
        wheel_z_m: row.wheel_z_m,
        wheel_force_n: row.contact_force_n,
        profile,
        max_rel_diff,
    })
}
