//! Issue-6 acceptance figures measured from a run's MCAP recording.
//!
//! Rolling phase: the ticks whose position reference along the strip (controller diagnostics,
//! task z) has left `z_start` and not yet reached `z_end` — exactly the thesis' Figure 6.7 window.
//! Tracking error per tick: | |bottom force| − |force reference| |.

use recording_tools::read::Recording;
use scenario::Scenario;

use crate::servo::Tracking;

/// Tracking over the rolling phase of a recording.
pub fn tracking_from_recording(rec: &Recording, s: &Scenario) -> anyhow::Result<Tracking> {
    let (z0, z1) = (s.trajectory.z_start_mm * 1e-3, s.trajectory.z_end_mm * 1e-3);
    let by_tick = rec.controller_by_tick();
    let mut e = Vec::new();
    for (i, c) in by_tick.iter().enumerate() {
        let Some(c) = c.map(|k| &rec.controller[k]) else { continue };
        let z_ref = c.pos_ref_task_m[2];
        if c.force_control_active == 1 && z_ref > z0 + 1e-12 && z_ref < z1 - 1e-12 {
            let strip = rec.strip.get(i).ok_or_else(|| anyhow::anyhow!("{}: no /strip row for tick row {i}", rec.path.display()))?;
            e.push((strip.bottom_force_n.abs() - c.force_ref_n.abs()).abs());
        }
    }
    if e.is_empty() {
        anyhow::bail!("{}: no rolling phase found (controller diagnostics never moved the wheel along the strip)", rec.path.display());
    }
    Ok(Tracking {
        max_n: e.iter().cloned().fold(0.0, f64::max),
        rms_n: (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt(),
        samples: e.len(),
    })
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
