//! Drives and encoders of the realistic cell (DESIGN section 12, `[drives]`).
//!
//! Friction per joint, Coulomb + viscous + Stribeck with stiction, as an elasto-plastic
//! ("bristle") model so that no explicit step chatters around zero speed:
//!
//!   F(q̇) = τ_c + (τ_s − τ_c) exp(−(q̇/v_s)²)          (the Stribeck curve, τ_s the breakaway)
//!   p = −k (q − a)                                    (the stick spring about its anchor a)
//!   τ_f = clamp(p − d q̇, −F(q̇), F(q̇)) − b q̇
//!
//! Under a torque below breakaway the spring holds the joint (it deflects by τ/k, which is
//! τ/τ_max of the end stop's 0.25 degree, and stays there); above it the spring saturates, the
//! anchor slides with the joint (`a = q + sign(p) F/k` after each substep) and the joint feels
//! the Stribeck curve. k and d are the end stops' (`limits.rs`: the torque limit presses in by
//! 0.25 degree, critical damping for the joint's inertia), which the integrator already resolves
//! at the default substep. The friction is a continuous function of (q, q̇) inside each
//! integrator stage, like the end stops.
//!
//! Encoders: the state's q is the joint angle quantised to 2π/counts; its q̇ is the difference
//! quotient of successive quantised angles through a first-order low-pass (a drive's velocity
//! estimate), not the exact velocity.

use robot::Vec6;
use scenarios::DrivesConfig;

use crate::limits::JointLimits;

/// Friction of the six joints and the stick springs' anchors.
#[derive(Debug, Clone)]
pub struct Friction {
    coulomb: [f64; 6],
    breakaway: [f64; 6],
    stribeck: [f64; 6],
    viscous: [f64; 6],
    stiffness: [f64; 6],
    damping: [f64; 6],
    anchor: [f64; 6],
    /// A lower bound of the Stribeck curve (the Coulomb level when breakaway ≥ Coulomb, else 0):
    /// a spring torque within it is below the friction level whatever the speed, so neither the
    /// clamp nor the slip needs the curve's exp() (the same result, bit for bit, cheaper).
    floor: [f64; 6],
    /// 1 + torque-constant error.
    gain: [f64; 6],
}

impl Friction {
    /// The drives of `cfg` on joints at rest at `q` (every joint stuck where it stands).
    pub fn new(cfg: &DrivesConfig, limits: &JointLimits, q: &Vec6) -> Friction {
        Friction {
            coulomb: cfg.coulomb_nm,
            breakaway: cfg.breakaway_nm,
            stribeck: cfg.stribeck_radps,
            viscous: cfg.viscous_nms,
            stiffness: limits.stop_stiffness_nm_per_rad,
            damping: limits.stop_damping_nms_per_rad,
            anchor: std::array::from_fn(|i| q[i]),
            floor: std::array::from_fn(|i| if cfg.breakaway_nm[i] >= cfg.coulomb_nm[i] { cfg.coulomb_nm[i].max(0.0) } else { 0.0 }),
            gain: std::array::from_fn(|i| 1.0 + cfg.torque_constant_error[i]),
        }
    }

    /// The torque the drives apply for the command `tau` (the torque-constant errors).
    pub fn applied(&self, tau: &Vec6) -> Vec6 {
        Vec6::from_fn(|i, _| self.gain[i] * tau[i])
    }

    /// Stribeck curve: the friction level at speed `w` of joint `i`, N m.
    #[inline]
    pub fn level(&self, i: usize, w: f64) -> f64 {
        if self.stribeck[i] == 0.0 {
            return if w == 0.0 { self.breakaway[i] } else { self.coulomb[i] };
        }
        let x = w / self.stribeck[i];
        self.coulomb[i] + (self.breakaway[i] - self.coulomb[i]) * (-x * x).exp()
    }

    /// Friction torque at `(q, q̇)` (module docs), N m.
    #[inline]
    pub fn torque(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        Vec6::from_fn(|i, _| {
            let p = -self.stiffness[i] * (q[i] - self.anchor[i]);
            let x = p - self.damping[i] * qd[i];
            let stick = if x.abs() <= self.floor[i] {
                x
            } else {
                let f = self.level(i, qd[i]);
                x.clamp(-f, f)
            };
            stick - self.viscous[i] * qd[i]
        })
    }

    /// After a substep: a stick spring stretched beyond the friction level slips, its anchor
    /// follows the joint.
    pub fn slip(&mut self, q: &Vec6, qd: &Vec6) {
        for i in 0..6 {
            let p = -self.stiffness[i] * (q[i] - self.anchor[i]);
            if p.abs() <= self.floor[i] {
                continue;
            }
            let f = self.level(i, qd[i]);
            if p.abs() > f {
                self.anchor[i] = q[i] + p.signum() * f / self.stiffness[i];
            }
        }
    }
}

/// The encoders and the drive's velocity estimate.
#[derive(Debug, Clone)]
pub struct Encoders {
    step_rad: [f64; 6],
    /// Velocity filter: v += β (Δq̂/T − v), β = 1 − exp(−2π f T) (None: exact q̇).
    beta: Option<f64>,
    period_s: f64,
    q: Vec6,
    qd: Vec6,
}

impl Encoders {
    pub fn new(cfg: &DrivesConfig, period_s: f64, q: &Vec6) -> Encoders {
        let step_rad = std::array::from_fn(|i| {
            let c = cfg.encoder_counts_per_rev[i];
            if c > 0.0 {
                std::f64::consts::TAU / c
            } else {
                0.0
            }
        });
        let beta = (cfg.velocity_filter_hz > 0.0).then(|| 1.0 - (-std::f64::consts::TAU * cfg.velocity_filter_hz * period_s).exp());
        let mut e = Encoders { step_rad, beta, period_s, q: Vec6::zeros(), qd: Vec6::zeros() };
        e.q = e.quantise(q);
        e
    }

    fn quantise(&self, q: &Vec6) -> Vec6 {
        Vec6::from_fn(|i, _| if self.step_rad[i] > 0.0 { (q[i] / self.step_rad[i]).round() * self.step_rad[i] } else { q[i] })
    }

    /// A new tick's true `(q, q̇)` in; what the state reports is then [`Encoders::q`],
    /// [`Encoders::qd`].
    pub fn update(&mut self, q: &Vec6, qd: &Vec6) {
        let qn = self.quantise(q);
        match self.beta {
            Some(b) => self.qd += ((qn - self.q) / self.period_s - self.qd) * b,
            None => self.qd = *qd,
        }
        self.q = qn;
    }

    pub fn q(&self) -> Vec6 {
        self.q
    }
    pub fn qd(&self) -> Vec6 {
        self.qd
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoders_quantise_to_whole_counts_and_estimate_a_ramp_s_speed() {
        let cfg = DrivesConfig { encoder_counts_per_rev: [100_000.0; 6], velocity_filter_hz: 50.0, ..DrivesConfig::default() };
        let mut e = Encoders::new(&cfg, 1e-3, &Vec6::from_element(0.000031));
        let step = std::f64::consts::TAU / 100_000.0;
        assert!((e.q()[0] - 0.0).abs() < 1e-15, "{}", e.q()[0]);
        let w = 2.0;
        for k in 1..=2000 {
            e.update(&Vec6::from_element(w * k as f64 * 1e-3), &Vec6::zeros());
            let counts = e.q()[0] / step;
            assert!((counts - counts.round()).abs() < 1e-9);
        }
        assert!((e.qd()[0] - w).abs() < 0.05 * w, "{}", e.qd()[0]);
    }

    #[test]
    fn friction_follows_the_stribeck_curve_and_holds_below_breakaway() {
        let cfg = DrivesConfig {
            coulomb_nm: [5.0; 6],
            breakaway_nm: [8.0; 6],
            stribeck_radps: [0.02; 6],
            viscous_nms: [1.0; 6],
            ..DrivesConfig::default()
        };
        let limits = JointLimits::irb2400(&Vec6::from_element(1.0));
        let f = Friction::new(&cfg, &limits, &Vec6::zeros());
        assert_eq!(f.level(0, 0.0), 8.0);
        assert!((f.level(0, 1.0) - 5.0).abs() < 1e-12);
        // Sliding fast: the spring is saturated, friction = -(Coulomb + viscous).
        let t = f.torque(&Vec6::from_element(1.0), &Vec6::from_element(1.0))[0];
        assert!((t + 6.0).abs() < 1e-12, "{t}");
        // At rest, displaced by less than breakaway / k: the spring pushes back, unclamped.
        let dq = 4.0 / limits.stop_stiffness_nm_per_rad[0];
        let t = f.torque(&Vec6::from_element(dq), &Vec6::zeros())[0];
        assert!((t + 4.0).abs() < 1e-9, "{t}");
    }
}
