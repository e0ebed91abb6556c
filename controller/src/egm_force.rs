//! The thesis' force task through EGM (DESIGN section 11): a position-based admittance along the
//! strip normal on the measured force, for a robot that takes joint references, not torques.
//!
//! Each EGM cycle `T_c` (4 ms) the sensor gets the robot's joints and the wheel's measured force
//! and answers one joint reference: the TCP pose of the scenario's trajectory (the same
//! [`ReferenceGenerator`] as the torque path), with task y, while force controlled, replaced by
//! the admittance state
//!
//! `ẏ_c = (F_ref − F) / b  (+ Ḟ_ref / k_s with controller.force_rate_feedforward)`
//!
//! (a damper of `b` N s/m: integral force control, no steady error), and the motion directions
//! led by the robot's documented lag (`pos + vel · egm.lag_s`), mapped to joints by inverse
//! kinematics.
//!
//! Design rule ([`EgmForceDesign`]): with the strip of stiffness `k_s` under the wheel and the
//! motion controller as a delay `τ` and the position correction's low-pass `ω_c`, the loop is
//! `L(s) = k_s e^{−sτ} / (b s (1 + s/ω_c))`, `τ = (egm.lag_s − 1/ω_c) + T_c/2` (the motion
//! controller's delay and servo half-tick, plus the hold of each reference over a cycle). `b`
//! puts the crossover `ω_x` (`|L(jω_x)| = 1`: `b = k_s / (ω_x |1 + jω_x/ω_c|)`) where the phase
//! margin is `egm.force_phase_margin_deg`: `ω_x τ + atan(ω_x/ω_c) = 90° − PM`. With the defaults (12 ms lag, 20 Hz, 4 ms, 60°):
//! τ = 6.04 ms, crossover 6.1 Hz. `rig design --egm` evaluates the same loop on the reduced
//! strip model.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use robot::{Robot, Vec6};
use scenarios::geometry::{self, TaskFrame};
use scenarios::Scenario;

use crate::reference::{ReferenceGenerator, ReferenceParams, TaskReference};

/// Deepest the admittance may command below the height where force control took over, m.
pub const MAX_PRESS_DEPTH_M: f64 = 0.01;

/// The admittance design of a scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgmForceDesign {
    /// Strip stiffness under the wheel assumed by the rule, N/m (`controller.strip_stiffness_n_per_m`).
    pub strip_stiffness_n_per_m: f64,
    /// Delay of the loop, s (motion controller's delay and half tick, half an EGM cycle).
    pub delay_s: f64,
    /// The position correction's low-pass, rad/s.
    pub correction_radps: f64,
    /// Admittance damping b, N s/m.
    pub damping_ns_per_m: f64,
    /// Crossover of the rule's loop, Hz, and its phase margin, degrees.
    pub crossover_hz: f64,
    pub phase_margin_deg: f64,
}

impl EgmForceDesign {
    pub fn from_scenario(s: &Scenario) -> EgmForceDesign {
        let e = &s.egm;
        let w_c = e.pos_corr_gain * std::f64::consts::TAU * e.lowpass_hz;
        let delay_s = e.delay_s(s.loop_.period_s) + 0.5 * s.loop_.period_s + 0.5 * e.cycle_s;
        let k_s = s.controller.strip_stiffness_n_per_m;
        let pm = e.force_phase_margin_deg.to_radians();
        let lag = |w: f64| w * delay_s + if w_c > 0.0 { (w / w_c).atan() } else { 0.0 };
        // lag(w) rises monotonically from 0: bisect for lag = 90° − PM.
        let target = std::f64::consts::FRAC_PI_2 - pm;
        let (mut lo, mut hi) = (0.0, 1.0);
        while lag(hi) < target {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if lag(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let w_x = 0.5 * (lo + hi);
        EgmForceDesign {
            strip_stiffness_n_per_m: k_s,
            delay_s,
            correction_radps: w_c,
            // |L(jω_x)| = 1 with the low-pass's roll-off: b = k_s / (ω_x |1 + jω_x/ω_c|).
            damping_ns_per_m: k_s / (w_x * if w_c > 0.0 { (1.0 + (w_x / w_c).powi(2)).sqrt() } else { 1.0 }),
            crossover_hz: w_x / std::f64::consts::TAU,
            phase_margin_deg: 90.0 - lag(w_x).to_degrees(),
        }
    }
}

/// What one EGM cycle gives the law.
#[derive(Debug, Clone, Copy)]
pub struct EgmInput {
    /// Simulated time of the robot's message, s (`header.tm`).
    pub t_s: f64,
    /// Feedback joints, DH rad.
    pub q: Vec6,
    /// Measured force on the tool, sensor (flange) axes, N.
    pub force_sensor_n: Vector3<f64>,
}

/// One cycle's answer.
#[derive(Debug, Clone, Copy)]
pub struct EgmOutput {
    /// Joint reference, DH rad.
    pub q_ref: Vec6,
    pub reference: TaskReference,
    /// Measured force on the strip along task y (F_e's task-y component), N (negative = pressing;
    /// messages/README.md, "Frames and signs").
    pub force_y_n: f64,
    /// Commanded TCP position, task frame, m.
    pub pos_cmd_task_m: Vector3<f64>,
}

/// The EGM force controller's state.
pub struct EgmForceLaw {
    robot: Robot,
    task: TaskFrame,
    gen: ReferenceGenerator,
    design: EgmForceDesign,
    cycle_s: f64,
    lead_s: f64,
    rate_feedforward: bool,
    rot_base_tool: nalgebra::Matrix3<f64>,
    /// Commanded task y (admittance state), m; None before the first cycle.
    y_cmd: Option<f64>,
    last_q_ref: Option<Vec6>,
}

impl EgmForceLaw {
    pub fn new(s: &Scenario) -> EgmForceLaw {
        EgmForceLaw {
            robot: crate::step::controller_robot(s),
            task: TaskFrame::from_scenario(s),
            gen: ReferenceGenerator::new(ReferenceParams::from_scenario(s)),
            design: EgmForceDesign::from_scenario(s),
            cycle_s: s.egm.cycle_s,
            lead_s: s.egm.lag_s,
            rate_feedforward: s.controller.force_rate_feedforward,
            rot_base_tool: geometry::tool_down_rotation(),
            y_cmd: None,
            last_q_ref: None,
        }
    }

    pub fn design(&self) -> &EgmForceDesign {
        &self.design
    }

    /// One EGM cycle.
    pub fn step(&mut self, inp: &EgmInput) -> EgmOutput {
        let frames = self.robot.frames(&inp.q);
        let tcp_task = self.task.point_to_task(&self.robot.tcp_position(&frames));
        let force_base = frames.rot[6] * inp.force_sensor_n;
        let force_y_n = -self.task.vector_to_task(&force_base).y;
        let r = self.gen.update(inp.t_s, force_y_n, tcp_task.y);
        let mut p = r.pos_m + r.vel_mps * self.lead_s;
        let y = self.y_cmd.get_or_insert(tcp_task.y);
        if r.force_mode {
            let mut rate = (r.force_y_n - force_y_n) / self.design.damping_ns_per_m;
            if self.rate_feedforward {
                rate += r.force_rate_y_nps / self.design.strip_stiffness_n_per_m;
            }
            *y += rate * self.cycle_s;
            // At most 10 mm below where force control took over (the strip is 8 mm high): a
            // lost strip must not drive the wheel into the table.
            *y = y.max(r.pos_m.y - MAX_PRESS_DEPTH_M);
            p.y = *y;
        } else {
            *y = p.y;
        }
        let target =
            Isometry3::from_parts(Translation3::from(self.task.point_to_base(&p)), UnitQuaternion::from_matrix(&self.rot_base_tool));
        let seed = self.last_q_ref.unwrap_or(inp.q);
        let q_ref = self.robot.ik_tcp(&target, &seed).unwrap_or(seed);
        self.last_q_ref = Some(q_ref);
        EgmOutput { q_ref, reference: r, force_y_n, pos_cmd_task_m: p }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule's loop `k_s e^{−sτ}/(b s (1 + s/ω_c))` evaluated at the crossover it reports:
    /// unit gain, and the phase margin asked for.
    #[test]
    fn the_rules_crossover_has_unit_gain_and_the_asked_phase_margin() {
        let mut s = Scenario::default();
        for pm in [45.0, 60.0, 75.0] {
            s.egm.force_phase_margin_deg = pm;
            let d = EgmForceDesign::from_scenario(&s);
            let w = std::f64::consts::TAU * d.crossover_hz;
            let gain = d.strip_stiffness_n_per_m / (d.damping_ns_per_m * w * (1.0 + (w / d.correction_radps).powi(2)).sqrt());
            let phase = -90.0 - (w / d.correction_radps).atan().to_degrees() - (w * d.delay_s).to_degrees();
            assert!((gain - 1.0).abs() < 1e-9, "gain {gain}");
            assert!((180.0 + phase - pm).abs() < 1e-6, "phase margin {} vs {pm}", 180.0 + phase);
        }
        // the defaults: 12 ms lag, 20 Hz, 1 ms ticks, 4 ms cycles
        s.egm.force_phase_margin_deg = 60.0;
        let d = EgmForceDesign::from_scenario(&s);
        let expect_delay = 0.012 - 1.0 / (std::f64::consts::TAU * 20.0) - 0.0005 + 0.0005 + 0.002;
        assert!((d.delay_s - expect_delay).abs() < 1e-15, "{}", d.delay_s);
    }
}
