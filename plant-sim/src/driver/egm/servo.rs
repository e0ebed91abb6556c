//! ABB's motion controller between EGM and the rigid-body plant, emulated (DESIGN section 11).
//!
//! Per 1 ms tick, on the joint references `r` (rad, DH) and speed references `v` (rad/s) of the
//! last accepted `EgmSensor` (held between EGM cycles):
//!
//! 1. **Delay**: `(r, v)` pass a delay line of `d = lag_s − 1/ω_c − T/2` (transport and the
//!    controller's own processing), whole ticks plus a fraction by linear interpolation between
//!    two slots.
//! 2. **Position correction with low-pass**: the servo reference `q_r` follows
//!    `q̇_r = v_D + ω_c (r_D − q_r)`, `ω_c = pos_corr_gain · 2π · lowpass_hz`, advanced exactly over
//!    the tick. With gain 1 and no speed reference this is a first-order low-pass on the position
//!    references (ramp lag and step time constant `1/ω_c`); with gain 0 only the speed references
//!    move the robot (ABB's `PosCorrGain`).
//! 3. **Joint servo with model feed-forward**: `τ = M(q)(a_ff + k_d (q̇_r − q̇) + k_p (q_r − q)) +
//!    C(q, q̇) q̇ + g(q)` (the robot crate's inverse dynamics), `k_p = ω_s²`, `k_d = 2 ζ ω_s`, where
//!    `a_ff` is the reference's velocity change over the tick divided by `T` (so the velocity step
//!    a new reference makes is fed forward, not left to the PD).
//!
//! With the model exact the joint follows `q_r` half a tick behind (the torque is held over the
//! tick, so a velocity step of the reference is reached over one tick), so the total lag from a
//! reference to the joint is `d + T/2 + 1/ω_c = lag_s` (a step reaches 63.2 % after it; a ramp is
//! followed that much behind): 3.54 ms + 0.5 ms + 7.96 ms = 12 ms with the defaults. The servo's model is the nominal one (the scenario's arm, tool, armature and
//! friction without `plant_inertia_scale`): ABB's controller does not know a mismatch either.
//! Nothing here allocates: it runs on the 1 kHz path.

use robot::{Robot, Vec6};
use scenarios::Scenario;

/// The longest delay line, ticks (1 s at 1 kHz; `egm.lag_s` is at most 1 s).
pub const MAX_DELAY_TICKS: usize = 1001;

/// The servo's parameters, from the scenario's `[egm]` section.
#[derive(Debug, Clone, Copy)]
pub struct ServoParams {
    pub period_s: f64,
    /// The delay, whole ticks and the fraction of one more.
    pub delay_ticks: usize,
    pub delay_frac: f64,
    /// ω_c, rad/s (0: position correction off).
    pub correction_radps: f64,
    pub kp: f64,
    pub kd: f64,
}

impl ServoParams {
    pub fn from_scenario(s: &Scenario) -> ServoParams {
        let e = &s.egm;
        let w_s = 2.0 * std::f64::consts::PI * e.servo_bandwidth_hz;
        let d = (e.delay_s(s.loop_.period_s).max(0.0) / s.loop_.period_s).min((MAX_DELAY_TICKS - 2) as f64);
        ServoParams {
            period_s: s.loop_.period_s,
            delay_ticks: d.floor() as usize,
            delay_frac: d - d.floor(),
            correction_radps: e.pos_corr_gain * 2.0 * std::f64::consts::PI * e.lowpass_hz,
            kp: w_s * w_s,
            kd: 2.0 * e.servo_damping_ratio * w_s,
        }
    }

    /// The lag this servo realises, s: `d + T/2 + 1/ω_c`.
    pub fn lag_s(&self) -> f64 {
        (self.delay_ticks as f64 + self.delay_frac + 0.5) * self.period_s
            + if self.correction_radps > 0.0 { 1.0 / self.correction_radps } else { 0.0 }
    }
}

/// The emulated motion controller's state.
pub struct Servo {
    p: ServoParams,
    model: Robot,
    /// Delay line of (r, v), a ring of `delay_ticks + 2` slots.
    line: Box<[(Vec6, Vec6); MAX_DELAY_TICKS]>,
    head: usize,
    /// The newest reference (what the delay line is fed).
    r: Vec6,
    v: Vec6,
    /// Servo reference position and its velocity at the start of the current tick.
    q_r: Vec6,
    qd_r: Vec6,
}

impl Servo {
    /// A servo holding `q0` at rest; `model` is the controller's robot model.
    pub fn new(p: ServoParams, model: Robot, q0: Vec6) -> Servo {
        Servo {
            p,
            model,
            line: Box::new([(q0, Vec6::zeros()); MAX_DELAY_TICKS]),
            head: 0,
            r: q0,
            v: Vec6::zeros(),
            q_r: q0,
            qd_r: Vec6::zeros(),
        }
    }

    pub fn params(&self) -> &ServoParams {
        &self.p
    }

    /// Take a new joint reference (rad) and speed reference (rad/s); held until the next one.
    pub fn set_reference(&mut self, r: Vec6, v: Vec6) {
        self.r = r;
        self.v = v;
    }

    /// The newest reference taken.
    pub fn reference(&self) -> Vec6 {
        self.r
    }

    /// Servo reference position now (after delay and correction), rad.
    pub fn servo_reference(&self) -> Vec6 {
        self.q_r
    }

    /// Stop where the servo reference is now: the delay line and the reference are set to it,
    /// speed zero (the end of an EGM session: the robot holds).
    pub fn hold(&mut self) {
        let q = self.q_r;
        self.r = q;
        self.v = Vec6::zeros();
        for s in self.line.iter_mut() {
            *s = (q, Vec6::zeros());
        }
    }

    /// One tick: the torque to hold over `[t_k, t_k + T)` for the plant state `(q, q̇)`, and the
    /// servo reference advanced to `t_{k+1}`.
    pub fn tick(&mut self, q: &Vec6, qd: &Vec6) -> Vec6 {
        let (d, f) = (self.p.delay_ticks, self.p.delay_frac);
        let n = d + 2;
        self.line[self.head] = (self.r, self.v);
        // The slots written d and d + 1 ticks ago (d = 0: this one), interpolated by the fraction.
        let (a, b) = (self.line[(self.head + n - d) % n], self.line[(self.head + n - d - 1) % n]);
        let (r_d, v_d) = (a.0 * (1.0 - f) + b.0 * f, a.1 * (1.0 - f) + b.1 * f);
        self.head = (self.head + 1) % n;
        let w = self.p.correction_radps;
        let t = self.p.period_s;
        let q_next = if w > 0.0 {
            let target = r_d + v_d / w;
            target + (self.q_r - target) * (-w * t).exp()
        } else {
            self.q_r + v_d * t
        };
        let qd_next = v_d + (r_d - q_next) * w;
        let a_ff = (qd_next - self.qd_r) / t;
        let a = a_ff + (self.qd_r - qd) * self.p.kd + (self.q_r - q) * self.p.kp;
        let (m, bias) = self.model.mass_matrix_and_bias(q, qd);
        self.q_r = q_next;
        self.qd_r = qd_next;
        m * a + bias
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(delay_ticks: usize, fc_hz: f64) -> ServoParams {
        let w_s = 2.0 * std::f64::consts::PI * 30.0;
        ServoParams {
            period_s: 1e-3,
            delay_ticks,
            delay_frac: 0.0,
            correction_radps: 2.0 * std::f64::consts::PI * fc_hz,
            kp: w_s * w_s,
            kd: 2.0 * w_s,
        }
    }

    #[test]
    fn servo_reference_is_the_delayed_first_order_response_to_a_step() {
        let q0 = Vec6::from(Robot::ABB_ZERO_Q);
        let p = params(4, 20.0);
        let mut s = Servo::new(p, Robot::irb2400(), q0);
        let step = Vec6::from([0.0, 0.0, 0.0, 0.0, 0.0, 0.01]);
        s.set_reference(q0 + step, Vec6::zeros());
        let w = p.correction_radps;
        for k in 1..=40u32 {
            s.tick(&q0, &Vec6::zeros());
            // after tick k the reference has moved for k - D ticks (closed form of the low-pass)
            let moved = (k as f64 - 4.0).max(0.0) * 1e-3;
            let expect = 0.01 * (1.0 - (-w * moved).exp());
            assert!((s.servo_reference()[5] - q0[5] - expect).abs() < 1e-15, "tick {k}");
        }
        assert!((p.lag_s() - (4.5e-3 + 1.0 / w)).abs() < 1e-15);
    }

    #[test]
    fn model_feed_forward_holds_the_arm_against_gravity_with_no_error() {
        let q0 = Vec6::from(Robot::ABB_ZERO_Q);
        let r = Robot::irb2400();
        let mut s = Servo::new(params(0, 20.0), r.clone(), q0);
        let tau = s.tick(&q0, &Vec6::zeros());
        assert!((tau - r.gravity_torque(&q0)).norm() < 1e-9);
    }
}
