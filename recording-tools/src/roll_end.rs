//! Where the roll's reference ended against the scenario's plan, and for how many ticks the plant
//! held the torque or stopped the arm.
//!
//! The shipped controller lets its plan stand still on every such tick (its reference clock's
//! anti-windup, `controller::reference::ReferenceGenerator::hold`), and also while it finds the
//! strip again after a safe stop; a run lasts its fixed duration. So after host stalls or a
//! stalled controller the roll can end short of its plan. This says so, with the figures,
//! instead of a silently shorter roll.

use serde::Serialize;

use crate::read::Recording;
use crate::tracking::TrackingTick;

/// A reference ending closer than this to the plan's end reached it (rounding of the profile).
pub const REACHED_TOLERANCE_M: f64 = 1e-6;

/// The roll's end against its plan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RollEnd {
    /// Where the plan ends along the strip or the contour (`trajectory.z_end_mm`), m.
    pub planned_end_m: f64,
    /// The controller's reference along it on the last tick that has one (its diagnostics'
    /// `pos_ref_task_m[2]`), m.
    pub reached_m: f64,
    /// How far the reference stopped before the plan's end, m (0 when it reached the end).
    pub short_m: f64,
    /// Ticks whose state reported the torque held or the arm in safe stop: the ticks the shipped
    /// controller's plan waits for.
    pub held_or_stopped_ticks: u64,
    /// Those ticks' time, s.
    pub held_or_stopped_s: f64,
}

impl RollEnd {
    /// True when the reference stopped short of the plan's end.
    pub fn is_short(&self) -> bool {
        self.short_m > REACHED_TOLERANCE_M
    }

    /// The report's line (without a newline), for a roll that ended short.
    pub fn line(&self) -> String {
        let mm = |m: f64| m * 1e3;
        let why = if self.held_or_stopped_ticks > 0 {
            format!(
                "the plant held the torque or stopped the arm on {} ticks ({:.3} s); a controller whose plan waits for those \
                 (the shipped one does, and also while it finds the strip again) ends later, and the run's duration is fixed",
                self.held_or_stopped_ticks, self.held_or_stopped_s
            )
        } else {
            "no tick was held or stopped: the run ended before its plan did".to_string()
        };
        format!(
            "roll end    the reference stopped at {:.2} mm, {:.2} mm before the plan's end ({:.2} mm): {why}",
            mm(self.reached_m),
            mm(self.short_m),
            mm(self.planned_end_m)
        )
    }
}

/// The roll's end of a recording made from a scenario, whose ticks carry a controller reference;
/// None otherwise (no scenario recorded, no controller diagnostics).
pub fn roll_end(rec: &Recording, ticks: &[TrackingTick]) -> Option<RollEnd> {
    let reached_m = ticks.iter().rev().find_map(|t| t.z_ref_m)?;
    let src = rec.run_metadata().ok()?.scenario?;
    let s = scenarios::Scenario::from_toml_str(&src.toml, std::path::Path::new("<recording>")).ok()?;
    let (start_m, planned_end_m) = (s.trajectory.z_start_mm * 1e-3, s.trajectory.z_end_mm * 1e-3);
    // Along the roll's direction (a plan may roll towards smaller z).
    let short_m = ((planned_end_m - reached_m) * (planned_end_m - start_m).signum()).max(0.0);
    let (held, stopped) = (messages::PlantStatus::HoldingTorque as u32, messages::PlantStatus::SafeStop as u32);
    let held_or_stopped_ticks = rec.joint_state.iter().filter(|j| j.plant_status == held || j.plant_status == stopped).count() as u64;
    Some(RollEnd {
        planned_end_m,
        reached_m,
        short_m,
        held_or_stopped_ticks,
        held_or_stopped_s: held_or_stopped_ticks as f64 * rec.period_s(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn end(short_m: f64, held: u64) -> RollEnd {
        RollEnd {
            planned_end_m: 0.038,
            reached_m: 0.038 - short_m,
            short_m,
            held_or_stopped_ticks: held,
            held_or_stopped_s: held as f64 * 1e-3,
        }
    }

    #[test]
    fn a_short_roll_names_its_figures_and_its_cause() {
        assert!(!end(0.0, 0).is_short());
        assert!(!end(0.5 * REACHED_TOLERANCE_M, 3).is_short());
        let l = end(0.0054, 300).line();
        for part in ["stopped at 32.60 mm", "5.40 mm before the plan's end (38.00 mm)", "on 300 ticks (0.300 s)"] {
            assert!(l.contains(part), "{part:?} not in {l:?}");
        }
        assert!(end(0.002, 0).line().contains("the run ended before its plan did"));
    }
}
