//! Issue-6 acceptance figures measured from a run's MCAP recording.
//!
//! Rolling phase and tracking error: `recording_tools::tracking`'s one rule (the figures `rig
//! report` and `rig run` print): the wheel in contact and the controller's reference z changed
//! since the previous tick; e = |bottom force| − |force reference|.

use recording_tools::read::Recording;

use crate::servo::Tracking;

/// Tracking over the rolling phase of a recording.
pub fn tracking_from_recording(rec: &Recording) -> anyhow::Result<Tracking> {
    let t = recording_tools::report::force_tracking(rec).ok_or_else(|| {
        anyhow::anyhow!("{}: no rolling phase found (controller diagnostics never moved the wheel along the strip)", rec.path.display())
    })?;
    Ok(t.into())
}

/// Bond check: for every centre-line node with z in [z_from, z_to], the largest bottom pressure
/// it saw during the run. Returns (z, peak pressure) per node.
pub fn peak_centreline_pressure(rec: &Recording, z_from_m: f64, z_to_m: f64) -> Vec<(f64, f64)> {
    let z = rec.centreline_z_m();
    let mut peak = vec![f64::NEG_INFINITY; z.len()];
    for row in &rec.strip {
        for (p, &x) in peak.iter_mut().zip(&row.centreline_pressure_pa) {
            *p = p.max(x as f64);
        }
    }
    z.iter().zip(peak).filter(|(z, _)| **z >= z_from_m - 1e-9 && **z <= z_to_m + 1e-9).map(|(z, p)| (*z, p)).collect()
}
