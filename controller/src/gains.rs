//! Gain design (thesis Section 6.2), as a rule instead of hand-picked constants.
//!
//! Force loop along the strip normal. With the inverse dynamics (7.2)-(7.6) the wheel obeys
//! ÿ = a_y, and the hybrid impedance law (6.3) a_y = (F_r − F_e + u_I − b_d ẏ)/m_d with the strip
//! as a spring F_e = k_s y (k_s: driving-point stiffness of the strip under the wheel) gives the
//! loop gain from the force error e = F_r − F_e to F_e
//!
//!   L(s) = k_s / (s (m_d s + b_d)) · (1 + k_i/s)          (k_i = 0 without integral action)
//!
//! Design rule, given the crossover ω_c (Section 6.2: 25 Hz):
//! 1. Impedance pole: b_d/m_d = N ω_c with N = [`IMPEDANCE_POLE_RATIO`]. Far above ω_c it costs
//!    only atan(1/N) of phase (the thesis' ~90° margin is the limit N → ∞); it must also stay
//!    well inside the sampled loop: the discrete velocity pole 1 − T b_d/m_d = 1 − N ω_c T is 0.06
//!    at 25 Hz and 1 kHz (no ringing).
//! 2. Integral zero (optional): k_i = ratio · ω_c, a decade-ish below crossover.
//! 3. b_d from |L(jω_c)| = 1 exactly: b_d = k_s √(1 + (k_i/ω_c)²) / (ω_c √(1 + 1/N²)); m_d = b_d/(N ω_c).
//!
//! The predicted phase margin is 90° − atan(1/N) − atan(k_i/ω_c) − ω_c T/2 (the last term is the
//! zero-order hold's half-sample delay). The wheel's effective mass m_eff does not enter the loop
//! (inverse dynamics cancels it); it sets the uncontrolled contact resonance √(k_s/m_eff), reported
//! so one can see how far the controller moves the closed loop from it.
//!
//! Motion directions (7.8): critically damped PD, k_p = ω_m², k_d = 2 ζ ω_m.

use scenarios::Scenario;
use std::f64::consts::TAU;

/// b_d/m_d in units of the crossover frequency (see the module docs).
pub const IMPEDANCE_POLE_RATIO: f64 = 6.0;

/// Result of the force-loop design rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceDesign {
    /// Strip stiffness under the wheel the design used, N/m.
    pub strip_stiffness_n_per_m: f64,
    /// Effective moving mass of the wheel along the normal, kg (informative, see module docs).
    pub effective_mass_kg: f64,
    /// Target crossover, rad/s.
    pub crossover_radps: f64,
    /// Desired impedance mass m_d (kg) and damping b_d (N s/m) of (6.3).
    pub m_d_kg: f64,
    pub b_d_nspm: f64,
    /// Integral gain k_i (1/s); 0 without integral action.
    pub k_i_per_s: f64,
    /// Predicted phase margin of the sampled loop, degrees.
    pub predicted_phase_margin_deg: f64,
    /// Uncontrolled contact resonance √(k_s/m_eff), Hz.
    pub contact_resonance_hz: f64,
}

/// The design rule of the module docs.
pub fn design_force_gains(
    strip_stiffness_n_per_m: f64,
    effective_mass_kg: f64,
    crossover_hz: f64,
    integral_ratio: Option<f64>,
    period_s: f64,
) -> ForceDesign {
    let wc = TAU * crossover_hz;
    let n = IMPEDANCE_POLE_RATIO;
    let k_i = integral_ratio.map_or(0.0, |r| r * wc);
    let b_d = strip_stiffness_n_per_m * (1.0 + (k_i / wc).powi(2)).sqrt() / (wc * (1.0 + 1.0 / (n * n)).sqrt());
    let m_d = b_d / (n * wc);
    let pm = 90.0 - (1.0 / n).atan().to_degrees() - (k_i / wc).atan().to_degrees() - (0.5 * wc * period_s).to_degrees();
    ForceDesign {
        strip_stiffness_n_per_m,
        effective_mass_kg,
        crossover_radps: wc,
        m_d_kg: m_d,
        b_d_nspm: b_d,
        k_i_per_s: k_i,
        predicted_phase_margin_deg: pm,
        contact_resonance_hz: (strip_stiffness_n_per_m / effective_mass_kg.max(1e-12)).sqrt() / TAU,
    }
}

/// Critically damped (for ζ = 1) PD gains for bandwidth `hz`: (k_p 1/s², k_d 1/s).
pub fn pd_gains(hz: f64, damping_ratio: f64) -> (f64, f64) {
    let w = TAU * hz;
    (w * w, 2.0 * damping_ratio * w)
}

/// Every gain of the control law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains {
    pub force: ForceDesign,
    /// Anti-windup clamp on the integral's force contribution, N.
    pub integral_limit_n: f64,
    /// Velocity feed-forward dF_r/dt / k_s along the normal (scenario
    /// `controller.force_rate_feedforward`).
    pub force_rate_feedforward: bool,
    /// Translational PD (x, z; y outside contact).
    pub kp_pos: f64,
    pub kd_pos: f64,
    /// Rotational PD.
    pub kp_rot: f64,
    pub kd_rot: f64,
    /// Extra joint damping, N m s/rad.
    pub joint_damping_nms: f64,
}

impl Gains {
    /// Gains for a scenario: strip stiffness from `controller.strip_stiffness_n_per_m`, wheel
    /// effective mass `effective_mass_kg` (task-space mass along the normal at the start pose).
    pub fn from_scenario(s: &Scenario, effective_mass_kg: f64) -> Gains {
        let c = &s.controller;
        let force = design_force_gains(
            c.strip_stiffness_n_per_m,
            effective_mass_kg,
            c.force_crossover_hz,
            c.force_integral.then_some(c.force_integral_ratio),
            s.loop_.period_s,
        );
        let (kp_pos, kd_pos) = pd_gains(c.motion_bandwidth_hz, c.motion_damping_ratio);
        let (kp_rot, kd_rot) = pd_gains(c.rotation_bandwidth_hz, c.motion_damping_ratio);
        Gains {
            force,
            integral_limit_n: c.force_integral_limit_n,
            force_rate_feedforward: c.force_rate_feedforward,
            kp_pos,
            kd_pos,
            kp_rot,
            kd_rot,
            joint_damping_nms: c.joint_damping_nms,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// |L(jω)| and arg L(jω) of the module's loop, evaluated directly in complex arithmetic.
    fn loop_gain(d: &ForceDesign, w: f64) -> (f64, f64) {
        // L = k_s (jω + k_i) / ((jω)² (m_d jω + b_d))
        let num = (d.strip_stiffness_n_per_m * w, d.strip_stiffness_n_per_m * d.k_i_per_s); // k_s(k_i + jω) as (im, re)
        let (num_re, num_im) = (num.1, num.0);
        // (jω)² = −ω²; (m_d jω + b_d)
        let (den_re, den_im) = (-w * w * d.b_d_nspm, -w * w * d.m_d_kg * w);
        let mag = (num_re.hypot(num_im)) / den_re.hypot(den_im);
        let phase = num_im.atan2(num_re) - den_im.atan2(den_re);
        (mag, phase)
    }

    #[test]
    fn loop_crosses_over_at_the_target_with_the_predicted_margin() {
        for integral in [None, Some(0.2)] {
            let d = design_force_gains(3.0e4, 10.0, 25.0, integral, 0.0);
            let (mag, phase) = loop_gain(&d, d.crossover_radps);
            assert!((mag - 1.0).abs() < 1e-12, "{mag}");
            let pm = 180.0 + (phase.to_degrees().rem_euclid(360.0) - 360.0);
            assert!((pm - d.predicted_phase_margin_deg).abs() < 1e-9, "{pm} vs {}", d.predicted_phase_margin_deg);
            assert!((d.b_d_nspm / d.m_d_kg - IMPEDANCE_POLE_RATIO * d.crossover_radps).abs() < 1e-9);
        }
    }

    #[test]
    fn stiffer_strip_needs_proportionally_more_damping() {
        let a = design_force_gains(1.0e4, 10.0, 25.0, None, 1e-3);
        let b = design_force_gains(4.0e4, 10.0, 25.0, None, 1e-3);
        assert!((b.b_d_nspm / a.b_d_nspm - 4.0).abs() < 1e-12);
        assert!((b.m_d_kg / a.m_d_kg - 4.0).abs() < 1e-12);
    }

    #[test]
    fn pd_gains_give_the_requested_natural_frequency() {
        let (kp, kd) = pd_gains(10.0, 1.0);
        assert!((kp.sqrt() - TAU * 10.0).abs() < 1e-12);
        assert!((kd * kd - 4.0 * kp).abs() < 1e-9);
    }
}
