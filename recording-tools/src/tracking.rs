//! The rolling-phase force-tracking metric, one rule for every caller: `rig report` and the
//! numbers `rig run` prints, `rig compare`, `rig sweep`, the design crate's servo runs and
//! recordings, and the tests (README, "What the shipped scenarios show": 0.029 N for the default
//! scenario).
//!
//! A tick is *rolling* when the wheel is in contact and the controller's position reference along
//! the strip (task z) changed since the previous tick; without a reference for both ticks (no
//! controller diagnostics, e.g. an EGM run), when the wheel itself moved more than
//! [`ROLLING_MIN_STEP_M`]. Over the rolling ticks that have a force set-point, the error is
//! e = |bottom force| − |force set-point| (N, positive: pressed harder than asked).

/// A wheel that moved less than this along the strip in one tick counts as standing still when
/// the controller published no reference to tell (0.1 mm/s at 1 kHz).
pub const ROLLING_MIN_STEP_M: f64 = 1e-7;

/// One tick as the metric sees it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackingTick {
    /// The wheel touches the strip (the plant's in-contact flag, or a non-zero contact force).
    pub in_contact: bool,
    /// The controller's position reference along the strip (task z) for this tick, m; None
    /// without controller diagnostics.
    pub z_ref_m: Option<f64>,
    /// The wheel's position along the strip (task z), m.
    pub wheel_z_m: f64,
    /// The force set-point, N (negative = pressing); None when the tick has none.
    pub force_ref_n: Option<f64>,
    /// The total bottom reaction force of the strip, N.
    pub bottom_force_n: f64,
}

impl TrackingTick {
    /// e = |bottom force| − |force set-point|, N; None without a set-point.
    pub fn force_error_n(&self) -> Option<f64> {
        self.force_ref_n.map(|r| self.bottom_force_n.abs() - r.abs())
    }
}

/// Index i of every rolling tick of `ticks` (the module's rule; i ≥ 1, it compares with i − 1).
pub fn rolling_ticks(ticks: &[TrackingTick]) -> Vec<usize> {
    (1..ticks.len())
        .filter(|&i| {
            let (prev, now) = (&ticks[i - 1], &ticks[i]);
            now.in_contact
                && match (prev.z_ref_m, now.z_ref_m) {
                    (Some(a), Some(b)) => a != b,
                    _ => (now.wheel_z_m - prev.wheel_z_m).abs() > ROLLING_MIN_STEP_M,
                }
        })
        .collect()
}

/// Force tracking over the rolling phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceTracking {
    /// Rolling ticks with a set-point (the samples of the figures below).
    pub samples: usize,
    /// max |e|, N.
    pub max_abs_n: f64,
    /// RMS of e, N.
    pub rms_n: f64,
    /// Mean of e, N (the steady error of a controller without integral action).
    pub mean_n: f64,
}

/// The force tracking of `ticks` over its rolling ticks `rolling` ([`rolling_ticks`]); None when
/// no rolling tick has a set-point.
pub fn force_tracking(ticks: &[TrackingTick], rolling: &[usize]) -> Option<ForceTracking> {
    let errors: Vec<f64> = rolling.iter().filter_map(|&i| ticks[i].force_error_n()).collect();
    if errors.is_empty() {
        return None;
    }
    let n = errors.len() as f64;
    Some(ForceTracking {
        samples: errors.len(),
        max_abs_n: errors.iter().fold(0.0f64, |m, e| m.max(e.abs())),
        rms_n: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        mean_n: errors.iter().sum::<f64>() / n,
    })
}

/// [`force_tracking`] over [`rolling_ticks`] of `ticks`.
pub fn rolling_force_tracking(ticks: &[TrackingTick]) -> Option<ForceTracking> {
    force_tracking(ticks, &rolling_ticks(ticks))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tick(in_contact: bool, z_ref: Option<f64>, wheel_z: f64, force_ref: Option<f64>, bottom: f64) -> TrackingTick {
        TrackingTick { in_contact, z_ref_m: z_ref, wheel_z_m: wheel_z, force_ref_n: force_ref, bottom_force_n: bottom }
    }

    /// The reference decides when it is there; the tick that reaches the end of the roll counts,
    /// the one after it (reference unchanged) does not; out of contact nothing counts.
    #[test]
    fn a_tick_rolls_when_in_contact_and_its_reference_moved_since_the_previous_one() {
        let t = [
            tick(true, Some(0.002), 0.002, Some(-10.0), -10.0),
            tick(true, Some(0.002), 0.002, Some(-10.0), -10.0),
            tick(true, Some(0.003), 0.00299, Some(-10.0), -10.1),
            tick(true, Some(0.004), 0.00399, Some(-10.0), -9.8),
            tick(true, Some(0.004), 0.004, Some(-10.0), -10.0),
            tick(false, Some(0.005), 0.005, Some(-10.0), 0.0),
        ];
        assert_eq!(rolling_ticks(&t), [2, 3]);
        let f = rolling_force_tracking(&t).unwrap();
        assert_eq!(f.samples, 2);
        assert!((f.max_abs_n - 0.2).abs() < 1e-12 && (f.mean_n + 0.05).abs() < 1e-12, "{f:?}");
        assert!((f.rms_n - ((0.01 + 0.04) / 2.0f64).sqrt()).abs() < 1e-12, "{f:?}");
    }

    /// Without a reference the wheel's own motion decides; a tick without a set-point rolls but
    /// gives no error sample.
    #[test]
    fn without_a_reference_the_wheel_must_move_more_than_the_minimum_step() {
        let t = [
            tick(true, None, 0.0, None, -10.0),
            tick(true, None, 0.5 * ROLLING_MIN_STEP_M, Some(-10.0), -10.0),
            tick(true, None, 0.001, None, -10.5),
            tick(true, None, 0.002, Some(-10.0), -10.25),
        ];
        assert_eq!(rolling_ticks(&t), [2, 3]);
        let f = rolling_force_tracking(&t).unwrap();
        assert_eq!((f.samples, f.max_abs_n), (1, 0.25));
        assert_eq!(rolling_force_tracking(&t[..3]), None);
    }
}
