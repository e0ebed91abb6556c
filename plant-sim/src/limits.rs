//! The robot cell's limits (DESIGN section 10): mechanical end stops and the drives'
//! torque–speed limit act inside the integration like the hardware does; reflexes watch the state
//! at every tick and put the plant into safe stop at once.
//!
//! Data: `robot::params` (axis ranges, axis speeds, torque limits, ABB's product specification)
//! and the scenario's `[safety]` section (TCP speed, contact force). Everything here is fixed-size
//! and allocation-free: it runs on the 1 kHz path.

use robot::params::{
    DRIVE_FULL_BRAKE_SPEED_RATIO, DRIVE_KNEE_SPEED_RATIO, DRIVE_ZERO_TORQUE_SPEED_RATIO, END_STOP_PENETRATION_AT_TORQUE_LIMIT_RAD,
    POSITION_LIMIT_RAD, TORQUE_LIMIT_NM, VELOCITY_LIMIT_RADPS,
};
use robot::Vec6;

/// End stops and drives of the six axes.
#[derive(Debug, Clone, Copy)]
pub struct JointLimits {
    /// `[lower, upper]` range per joint, rad (DH convention).
    pub range_rad: [[f64; 2]; 6],
    /// End-stop stiffness, N m/rad: the torque limit presses a stop in by 0.25 degree.
    pub stop_stiffness_nm_per_rad: [f64; 6],
    /// End-stop damping, N m s/rad: critical for the joint's inertia at the start pose
    /// (`2 sqrt(k M_ii)`), acting only while the joint is beyond its range.
    pub stop_damping_nms_per_rad: [f64; 6],
    /// Axis speed, rad/s (the reflex limit and the drive's knee).
    pub speed_radps: [f64; 6],
    pub torque_nm: [f64; 6],
}

impl JointLimits {
    /// The IRB 2400's limits; `mass_diag` = diag M(q) at the start pose sets the stop damping.
    pub fn irb2400(mass_diag: &Vec6) -> JointLimits {
        let k: [f64; 6] = std::array::from_fn(|i| TORQUE_LIMIT_NM[i] / END_STOP_PENETRATION_AT_TORQUE_LIMIT_RAD);
        JointLimits {
            range_rad: POSITION_LIMIT_RAD,
            stop_stiffness_nm_per_rad: k,
            stop_damping_nms_per_rad: std::array::from_fn(|i| 2.0 * (k[i] * mass_diag[i]).sqrt()),
            speed_radps: VELOCITY_LIMIT_RADPS,
            torque_nm: TORQUE_LIMIT_NM,
        }
    }

    /// No stops and ideal drives: infinite ranges and speeds (integrator tests on the bare arm).
    pub fn none() -> JointLimits {
        JointLimits {
            range_rad: [[f64::NEG_INFINITY, f64::INFINITY]; 6],
            stop_stiffness_nm_per_rad: [0.0; 6],
            stop_damping_nms_per_rad: [0.0; 6],
            speed_radps: [f64::INFINITY; 6],
            torque_nm: TORQUE_LIMIT_NM,
        }
    }

    /// Torque of the end stops at `(q, q̇)`: `−k δ − d q̇` on the penetration δ beyond a range
    /// limit, zero inside the range (the damping also only acts beyond it, so a joint leaving a
    /// stop is not held back).
    #[inline]
    pub fn end_stop_torque(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        Vec6::from_fn(|i, _| {
            let [lo, hi] = self.range_rad[i];
            let delta = if q[i] > hi {
                q[i] - hi
            } else if q[i] < lo {
                q[i] - lo
            } else {
                return 0.0;
            };
            -self.stop_stiffness_nm_per_rad[i] * delta - self.stop_damping_nms_per_rad[i] * qd[i]
        })
    }

    /// Index of a joint beyond its range, if any.
    pub fn joint_in_end_stop(&self, q: &Vec6) -> Option<usize> {
        (0..6).find(|&i| q[i] < self.range_rad[i][0] || q[i] > self.range_rad[i][1])
    }

    /// The torque the drives deliver for the command `tau` at speed `qd`: full torque while braking
    /// or below the knee ω_k (the axis speed); while motoring above it, at most
    /// `τ_max (ω_0 − |q̇|)/(ω_0 − ω_k)`, zero at ω_0 = 1.05 × the axis speed; beyond ω_0 the drive
    /// brakes whatever the command, reaching `τ_max` at 1.1 × the axis speed
    /// (`robot::params::DRIVE_*`).
    #[inline]
    pub fn drive_torque(&self, tau: &Vec6, qd: &Vec6) -> Vec6 {
        Vec6::from_fn(|i, _| {
            let (t, w) = (tau[i], qd[i]);
            let (knee, zero, full) = (
                DRIVE_KNEE_SPEED_RATIO * self.speed_radps[i],
                DRIVE_ZERO_TORQUE_SPEED_RATIO * self.speed_radps[i],
                DRIVE_FULL_BRAKE_SPEED_RATIO * self.speed_radps[i],
            );
            if w.abs() > zero {
                // Overspeed: brake (a braking command stronger than the limiter is kept).
                let brake = self.torque_nm[i] * ((w.abs() - zero) / (full - zero)).min(1.0);
                return if t * w < 0.0 && t.abs() > brake { t } else { -brake * w.signum() };
            }
            if t * w <= 0.0 {
                return t;
            }
            let available = self.torque_nm[i] * ((zero - w.abs()) / (zero - knee)).clamp(0.0, 1.0);
            t.clamp(-available, available)
        })
    }
}

impl JointLimits {
    /// The drive's speed limiter as a constraint: a joint its drive is motoring (command and
    /// speed of one sign) does not leave ±ω_0 (1.05 × its axis speed) within a substep. Why: the
    /// torque–speed curve is a feedback far stiffer than a substep (the wrist under its 50 N m
    /// accelerates by 9 rad/s in 100 µs, more than its whole speed range), so an explicit step
    /// alone overshoots it; projecting the speed back is what the limiter does in one substep.
    /// Inside the speed range this changes nothing (bit for bit).
    #[inline]
    pub fn limit_driven_speed(&self, tau_cmd: &Vec6, qd: &mut Vec6) {
        for i in 0..6 {
            let zero = DRIVE_ZERO_TORQUE_SPEED_RATIO * self.speed_radps[i];
            if qd[i].abs() > zero && tau_cmd[i] * qd[i] > 0.0 {
                qd[i] = zero.copysign(qd[i]);
            }
        }
    }
}

/// What tripped a reflex.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reflex {
    JointSpeed { joint: usize, value_radps: f64, limit_radps: f64 },
    TcpSpeed { value_mps: f64, limit_mps: f64 },
    ContactForce { value_n: f64, limit_n: f64 },
}

impl std::fmt::Display for Reflex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Reflex::JointSpeed { joint, value_radps, limit_radps } => {
                write!(f, "reflex: joint {} speed {:.3} rad/s exceeds its limit {:.3} rad/s", joint + 1, value_radps, limit_radps)
            }
            Reflex::TcpSpeed { value_mps, limit_mps } => {
                write!(f, "reflex: TCP speed {value_mps:.3} m/s exceeds the limit {limit_mps:.3} m/s")
            }
            Reflex::ContactForce { value_n, limit_n } => {
                write!(f, "reflex: contact force {value_n:.2} N exceeds the limit {limit_n:.2} N")
            }
        }
    }
}

/// Reflex limits (scenario `[safety]` plus the axis speeds).
#[derive(Debug, Clone, Copy)]
pub struct ReflexLimits {
    pub joint_speed_radps: [f64; 6],
    pub tcp_speed_mps: f64,
    pub contact_force_n: f64,
}

impl ReflexLimits {
    pub fn from_scenario(s: &scenarios::Scenario) -> ReflexLimits {
        ReflexLimits {
            joint_speed_radps: VELOCITY_LIMIT_RADPS,
            tcp_speed_mps: s.safety.max_tcp_speed_mps,
            contact_force_n: s.safety.max_contact_force_n,
        }
    }

    /// The first limit the state crosses: joint speeds, then TCP speed, then contact force.
    pub fn check(&self, qd: &Vec6, tcp_speed_mps: f64, contact_force_n: f64) -> Option<Reflex> {
        if let Some(joint) = (0..6).find(|&i| qd[i].abs() > self.joint_speed_radps[i]) {
            return Some(Reflex::JointSpeed { joint, value_radps: qd[joint], limit_radps: self.joint_speed_radps[joint] });
        }
        if tcp_speed_mps > self.tcp_speed_mps {
            return Some(Reflex::TcpSpeed { value_mps: tcp_speed_mps, limit_mps: self.tcp_speed_mps });
        }
        if contact_force_n.abs() > self.contact_force_n {
            return Some(Reflex::ContactForce { value_n: contact_force_n.abs(), limit_n: self.contact_force_n });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> JointLimits {
        JointLimits::irb2400(&Vec6::from_element(1.0))
    }

    #[test]
    fn end_stop_is_zero_inside_and_a_damped_spring_beyond() {
        let l = limits();
        let q = Vec6::zeros();
        assert_eq!(l.end_stop_torque(&q, &Vec6::from_element(3.0)), Vec6::zeros());
        let mut q = Vec6::zeros();
        q[2] = l.range_rad[2][1] + 0.01;
        let t = l.end_stop_torque(&q, &Vec6::zeros());
        assert!((t[2] + l.stop_stiffness_nm_per_rad[2] * 0.01).abs() < 1e-9);
        // The torque limit presses a stop in by exactly 0.25 degree.
        let d = TORQUE_LIMIT_NM[2] / l.stop_stiffness_nm_per_rad[2];
        assert!((d - 0.25f64.to_radians()).abs() < 1e-12);
        q[2] = l.range_rad[2][0] - 0.01;
        assert!(l.end_stop_torque(&q, &Vec6::zeros())[2] > 0.0);
        assert_eq!(l.joint_in_end_stop(&q), Some(2));
    }

    #[test]
    fn drive_delivers_full_torque_to_the_knee_then_falls_to_zero_and_always_brakes() {
        let l = limits();
        let w = l.speed_radps[5];
        let tau = Vec6::from_element(45.0);
        let at = |speed: f64| l.drive_torque(&tau, &Vec6::from_element(speed))[5];
        assert_eq!(at(0.5 * w), 45.0);
        assert_eq!(at(w), 45.0);
        // Halfway between knee and zero: half of the 50 N m limit.
        assert!((at(1.025 * w) - 25.0).abs() < 1e-9);
        assert!(at(1.05 * w).abs() < 1e-9);
        // Beyond the zero the drive brakes: half its torque halfway to 1.1, all of it from there.
        assert!((at(1.075 * w) + 25.0).abs() < 1e-9);
        assert_eq!(at(1.1 * w), -50.0);
        assert_eq!(at(2.0 * w), -50.0);
        // Braking (torque against the motion) is never limited.
        assert_eq!(l.drive_torque(&tau, &Vec6::from_element(-0.5 * w))[5], 45.0);
        assert_eq!(l.drive_torque(&tau, &Vec6::from_element(-2.0 * w))[5], 50.0);
    }

    #[test]
    fn reflexes_name_the_quantity_the_value_and_the_limit() {
        let r = ReflexLimits { joint_speed_radps: VELOCITY_LIMIT_RADPS, tcp_speed_mps: 0.25, contact_force_n: 40.0 };
        assert_eq!(r.check(&Vec6::zeros(), 0.1, -10.0), None);
        let mut qd = Vec6::zeros();
        qd[5] = 8.0;
        let text = r.check(&qd, 0.0, 0.0).unwrap().to_string();
        assert!(text.contains("joint 6") && text.contains("8.000") && text.contains("7.854"), "{text}");
        assert!(matches!(r.check(&Vec6::zeros(), 0.3, 0.0), Some(Reflex::TcpSpeed { .. })));
        let text = r.check(&Vec6::zeros(), 0.0, -41.0).unwrap().to_string();
        assert!(text.contains("41.00") && text.contains("40.00"), "{text}");
    }
}
