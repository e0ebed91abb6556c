//! A recording's tick rows as the rolling-phase metric ([`crate::tracking`]) takes them: one
//! reading of the recording for `rig report`, its bond map and `rig compare`.

use crate::read::Recording;
use crate::tracking::TrackingTick;

/// Every tick row of a recording as the rolling-phase metric sees it ([`crate::tracking`]): the
/// reference z and the set-point from the controller's diagnostics of the tick; an EGM run has no
/// diagnostics (EGM carries no force reference back), its set-point is the scenario's constant
/// `trajectory.force_ref_n` (none with a table).
pub fn tracking_ticks(rec: &Recording) -> Vec<TrackingTick> {
    let ctrl = rec.controller_by_tick();
    let egm_ref = if rec.controller.is_empty() { egm_force_ref(rec) } else { None };
    let n = rec.strip.len().min(rec.joint_state.len());
    (0..n)
        .map(|i| {
            let c = ctrl[i].map(|k| &rec.controller[k]);
            TrackingTick {
                in_contact: rec.joint_state[i].flags & messages::state_flags::IN_CONTACT != 0 || rec.strip[i].contact_force_n != 0.0,
                z_ref_m: c.map(|c| c.pos_ref_task_m[2]),
                wheel_z_m: rec.strip[i].wheel_z_m,
                force_ref_n: c.map(|c| c.force_ref_n).or(egm_ref),
                bottom_force_n: rec.strip[i].bottom_force_n,
            }
        })
        .collect()
}

/// The constant force set-point of an EGM run's scenario (`[egm] enabled`, no force table), N.
fn egm_force_ref(rec: &Recording) -> Option<f64> {
    let s: scenarios::Scenario = toml::from_str(&rec.run_metadata().ok()?.scenario?.toml).ok()?;
    (s.egm.enabled && s.trajectory.force_ref_along_z.is_empty()).then_some(s.trajectory.force_ref_n)
}
