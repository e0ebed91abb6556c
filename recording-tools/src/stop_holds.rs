//! What each safe stop did to the wheel: how far it went from where the stop began and how hard
//! it still pressed, from the recording's plant status and `/strip` rows.
//!
//! The plant's safe stop after misses, a controller fault or a lost controller is a position
//! hold (messages/README.md, "The plant's hold"): the wheel should stop within `v / (ω e)` of
//! where the stop began and stay on the strip. After a reflex, or with
//! `loop.hold_bandwidth_hz = 0`, the hold is compliant and the wheel may coast and lift off.
//! Either way the report says what happened, so a stall that lost the strip is not silent.

use serde::Serialize;

use crate::read::Recording;

/// Safe stops listed in the report (the count is in its `safe stops` line).
pub const STOPS_LISTED: usize = 3;

/// One safe stop (a run of ticks whose state reported `plant_status` = safe stop).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StopHold {
    /// The stop's first tick (its state is the first to report the safe stop).
    pub first_tick: u64,
    /// Ticks in the stop.
    pub ticks: u64,
    /// Where the wheel was along the strip (or contour) on the tick before the stop, m.
    pub wheel_from_m: f64,
    /// The wheel's largest distance along the strip from there during the stop, m.
    pub wheel_reach_m: f64,
    /// The weakest press of the wheel on the strip during the stop, N (0: it lost contact).
    pub weakest_press_n: f64,
}

impl StopHold {
    /// The report's line (without a newline).
    pub fn line(&self, period_s: f64) -> String {
        let press = if self.weakest_press_n > 0.0 {
            format!("and pressed {:.2} N or more throughout", self.weakest_press_n)
        } else {
            "and lost contact with the strip".to_string()
        };
        format!(
            "stop hold   tick {} ({:.3} s): the wheel went at most {:.2} mm along the strip from where the stop began ({:.2} mm) {press}",
            self.first_tick,
            self.ticks as f64 * period_s,
            self.wheel_reach_m * 1e3,
            self.wheel_from_m * 1e3
        )
    }
}

/// Every safe stop of a recording with `/strip` rows, in order (none without them).
pub fn stop_holds(rec: &Recording) -> Vec<StopHold> {
    let stopped = messages::PlantStatus::SafeStop as u32;
    let row = |tick: u64| rec.strip.binary_search_by_key(&tick, |r| r.tick).ok().map(|i| &rec.strip[i]);
    let mut out = Vec::new();
    let mut i = 0;
    let js = &rec.joint_state;
    while i < js.len() {
        if js[i].plant_status != stopped {
            i += 1;
            continue;
        }
        let first = i;
        while i < js.len() && js[i].plant_status == stopped {
            i += 1;
        }
        let (first_tick, last_tick) = (js[first].tick, js[i - 1].tick);
        // The strip row of a tick is the state at its start, as the joint state's.
        let Some(from) = first_tick.checked_sub(1).and_then(row).or_else(|| row(first_tick)) else { continue };
        let rows = || (first_tick..=last_tick).filter_map(row);
        out.push(StopHold {
            first_tick,
            ticks: last_tick - first_tick + 1,
            wheel_from_m: from.wheel_z_m,
            wheel_reach_m: rows().map(|r| (r.wheel_z_m - from.wheel_z_m).abs()).fold(0.0, f64::max),
            weakest_press_n: rows().map(|r| (-r.contact_force_n).max(0.0)).fold(f64::INFINITY, f64::min),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_line_says_how_far_the_wheel_went_and_whether_it_stayed_on_the_strip() {
        let hold = StopHold { first_tick: 1549, ticks: 981, wheel_from_m: 0.007115, wheel_reach_m: 0.00022, weakest_press_n: 3.97 };
        let l = hold.line(1e-3);
        for part in ["tick 1549 (0.981 s)", "at most 0.22 mm", "(7.12 mm)", "pressed 3.97 N or more"] {
            assert!(l.contains(part), "{part:?} not in {l:?}");
        }
        let lost = StopHold { weakest_press_n: 0.0, ..hold }.line(1e-3);
        assert!(lost.contains("lost contact with the strip"), "{lost}");
    }
}
