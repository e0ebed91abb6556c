//! The six-axis force/torque sensor of the realistic cell (DESIGN section 12, `[sensor]`), as a
//! chain of small stages (each one off at 0), run once per tick:
//!
//!   true contact wrench + tool load ([`ToolLoad`]) → + bias + drift + noise → low-pass →
//!   sample delay → quantisation → saturation
//!
//! The sensor sits between the flange and the tool bracket, so it carries the whole tool: the
//! wrench it reports is the contact's plus the tool's weight and inertial load
//! `m (g − a_c)`, with their moment and `−(I α + ω × I ω)` about the centre of mass. Like the
//! ideal sensor it reports in tool axes about the TCP (`messages::WrenchFrame::SensorAtTcp`: ATI's
//! "tool transform" moved to the wheel centre), in the sense of a wrench ON the tool.
//!
//! Per axis `[Fx, Fy, Fz, Tx, Ty, Tz]`. Fixed-size and allocation-free (the 1 kHz path).

use nalgebra::{Matrix3, Vector3};
use robot::{Frames, Robot, Vec6};
use scenarios::SensorConfig;

use crate::rng::Rng;

/// Longest sample delay, ticks (`sensor.delay_ticks` is checked against it).
pub const MAX_DELAY_TICKS: usize = 100;

/// The chain's stages and state.
#[derive(Debug, Clone)]
pub struct SensorChain {
    cfg: SensorConfig,
    rng: Rng,
    bias: [f64; 6],
    drift: [f64; 6],
    /// Drift increment's standard deviation per tick: rate √T.
    drift_step: [f64; 6],
    /// Low-pass: y += α (x − y), α = 1 − exp(−2π f_c T) (1: no filter).
    alpha: f64,
    filtered: [f64; 6],
    /// Ring of the last `delay + 1` filtered samples.
    ring: [[f64; 6]; MAX_DELAY_TICKS + 1],
    head: usize,
    delay: usize,
    started: bool,
}

impl SensorChain {
    /// The sensor of `cfg` at power-on, its bias drawn from `cfg.seed`; `period_s`: the tick.
    pub fn new(cfg: &SensorConfig, period_s: f64) -> SensorChain {
        let mut rng = Rng::new(cfg.seed);
        let bias = std::array::from_fn(|i| cfg.bias_range[i] * (2.0 * rng.uniform() - 1.0));
        let alpha = if cfg.lowpass_hz > 0.0 { 1.0 - (-std::f64::consts::TAU * cfg.lowpass_hz * period_s).exp() } else { 1.0 };
        SensorChain {
            cfg: cfg.clone(),
            rng,
            bias,
            drift: [0.0; 6],
            drift_step: std::array::from_fn(|i| cfg.drift_per_sqrt_s[i] * period_s.sqrt()),
            alpha,
            filtered: [0.0; 6],
            ring: [[0.0; 6]; MAX_DELAY_TICKS + 1],
            head: 0,
            delay: (cfg.delay_ticks as usize).min(MAX_DELAY_TICKS),
            started: false,
        }
    }

    /// The power-on bias drawn from the seed, per axis.
    pub fn bias(&self) -> [f64; 6] {
        self.bias
    }

    /// The low-pass' coefficient α of `y_k = y_{k−1} + α (x_k − y_{k−1})` (1 without a filter):
    /// H(z) = α / (1 − (1 − α) z⁻¹).
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// One sample: the wrench on the sensor this tick (contact + tool load) in, the reported one
    /// and whether an axis is beyond its range out. The first sample fills the filter and the
    /// delay line (the sensor was on long before the run).
    pub fn sample(&mut self, input: &[f64; 6]) -> ([f64; 6], bool) {
        let mut x = [0.0; 6];
        for i in 0..6 {
            let noise = self.rng.normal();
            let step = self.rng.normal();
            if self.started {
                self.drift[i] += step * self.drift_step[i];
            }
            x[i] = input[i] + self.bias[i] + self.drift[i] + noise * self.cfg.noise_sd[i];
        }
        if !self.started {
            self.filtered = x;
            self.ring = [x; MAX_DELAY_TICKS + 1];
            self.started = true;
        }
        for (y, xi) in self.filtered.iter_mut().zip(x) {
            *y += self.alpha * (xi - *y);
        }
        self.head = (self.head + 1) % (MAX_DELAY_TICKS + 1);
        self.ring[self.head] = self.filtered;
        let delayed = self.ring[(self.head + MAX_DELAY_TICKS + 1 - self.delay) % (MAX_DELAY_TICKS + 1)];
        let mut out = [0.0; 6];
        let mut saturated = false;
        for i in 0..6 {
            let q = self.cfg.resolution[i];
            let mut v = if q > 0.0 { (delayed[i] / q).round() * q } else { delayed[i] };
            let r = self.cfg.range[i];
            if r > 0.0 && v.abs() > r {
                saturated = true;
                v = v.clamp(-r, r);
            }
            out[i] = v;
        }
        (out, saturated)
    }
}

/// The tool's gravity and inertial load on the sensor. The tool's accelerations are the
/// difference quotients of its COM velocity and angular velocity over the tick that ended.
#[derive(Debug, Clone)]
pub struct ToolLoad {
    mass_kg: f64,
    com_flange_m: Vector3<f64>,
    inertia_com: Matrix3<f64>,
    period_s: f64,
    /// COM velocity and angular velocity at the previous sample, base axes (None before it).
    prev: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl ToolLoad {
    /// The load of `robot`'s tool (none without a tool).
    pub fn new(robot: &Robot, period_s: f64) -> ToolLoad {
        let (mass_kg, com_flange_m, inertia_com) =
            robot.tool().map_or((0.0, Vector3::zeros(), Matrix3::zeros()), |t| (t.mass_kg, t.com_flange_m, t.inertia_com));
        ToolLoad { mass_kg, com_flange_m, inertia_com, period_s, prev: None }
    }

    /// The tool's load on the sensor at `(q, q̇)`, tool axes about the TCP, as a wrench on the
    /// tool (the sense of `messages::Wrench`).
    pub fn sample(&mut self, robot: &Robot, q: &Vec6, qd: &Vec6) -> [f64; 6] {
        self.sample_at(robot, &robot.frames(q), qd)
    }

    /// [`ToolLoad::sample`] at the joints' `frames` (`robot.frames(q)`), which the plant computes
    /// once per tick for the contact wrench as well: the same numbers, one forward kinematics
    /// fewer.
    pub fn sample_at(&mut self, robot: &Robot, frames: &Frames, qd: &Vec6) -> [f64; 6] {
        let rot = frames.rot[6];
        let tcp = robot.tcp_position(frames);
        let com = frames.pos[6] + rot * self.com_flange_m;
        let jac = robot.jacobian_point(frames, &com);
        let twist = jac * qd;
        let (v, w) = (Vector3::new(twist[0], twist[1], twist[2]), Vector3::new(twist[3], twist[4], twist[5]));
        let (v0, w0) = self.prev.unwrap_or((v, w));
        self.prev = Some((v, w));
        let (a, alpha) = ((v - v0) / self.period_s, (w - w0) / self.period_s);
        let g = Vector3::new(0.0, 0.0, -Robot::GRAVITY_MPS2);
        let f = (g - a) * self.mass_kg;
        let i_base = rot * self.inertia_com * rot.transpose();
        let m = (com - tcp).cross(&f) - (i_base * alpha + w.cross(&(i_base * w)));
        let (f, m) = (rot.transpose() * f, rot.transpose() * m);
        [f.x, f.y, f.z, m.x, m.y, m.z]
    }
}

/// The static gravity load of a tool of `mass_kg` with its centre at `com_flange_m` on a sensor
/// reporting in tool axes about the TCP at `tcp_flange_m`, the tool at orientation `rot_base_tool`:
/// what [`ToolLoad::sample`] gives at rest, and what a controller subtracts with its nominal values.
pub fn gravity_load(mass_kg: f64, com_flange_m: &Vector3<f64>, tcp_flange_m: &Vector3<f64>, rot_base_tool: &Matrix3<f64>) -> [f64; 6] {
    let f = rot_base_tool.transpose() * Vector3::new(0.0, 0.0, -Robot::GRAVITY_MPS2 * mass_kg);
    let m = (com_flange_m - tcp_flange_m).cross(&f);
    [f.x, f.y, f.z, m.x, m.y, m.z]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> SensorConfig {
        SensorConfig { enabled: true, ..SensorConfig::default() }
    }

    #[test]
    fn with_every_stage_off_the_sensor_passes_the_wrench_through() {
        let mut s = SensorChain::new(&cfg(), 1e-3);
        let w = [1.0, -2.0, 3.5, 0.01, -0.02, 0.03];
        for _ in 0..5 {
            assert_eq!(s.sample(&w), (w, false));
        }
    }

    #[test]
    fn quantisation_rounds_to_the_step_and_saturation_clips_and_flags() {
        let mut c = cfg();
        c.resolution = [0.01; 6];
        c.range = [20.0, 20.0, 60.0, 1.0, 1.0, 1.0];
        let mut s = SensorChain::new(&c, 1e-3);
        let (out, sat) = s.sample(&[0.014, -0.016, 61.0, 0.0, 0.0, 0.0]);
        assert_eq!((out[0], out[1], out[2], sat), (0.01, -0.02, 60.0, true));
        let (_, sat) = s.sample(&[0.0; 6]);
        assert!(!sat);
    }

    #[test]
    fn the_delay_shifts_by_whole_ticks() {
        let mut c = cfg();
        c.delay_ticks = 3;
        let mut s = SensorChain::new(&c, 1e-3);
        let out: Vec<f64> = (0..8).map(|k| s.sample(&[k as f64, 0.0, 0.0, 0.0, 0.0, 0.0]).0[0]).collect();
        assert_eq!(out, [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn the_bias_lies_in_its_range_and_differs_between_seeds() {
        let mut c = cfg();
        c.bias_range = [0.4, 0.4, 1.2, 0.02, 0.02, 0.02];
        let b1 = SensorChain::new(&c, 1e-3).bias();
        c.seed = 1;
        let b2 = SensorChain::new(&c, 1e-3).bias();
        assert_ne!(b1, b2);
        for b in [b1, b2] {
            assert!((0..6).all(|i| b[i].abs() <= c.bias_range[i]), "{b:?}");
        }
    }

    /// At rest the tool hangs on the sensor with its weight m g, in every orientation.
    #[test]
    fn the_tool_at_rest_loads_the_sensor_with_its_weight() {
        let robot = Robot::irb2400_with_tool(robot::Tool::wheel_on_bracket(1.3, 0.1, 0.01));
        let mut load = ToolLoad::new(&robot, 1e-3);
        for q in [[0.0, -1.2, 0.3, 0.0, 0.9, 0.0], [0.5, -0.8, 0.1, 1.0, -0.4, 2.0]] {
            let q = Vec6::from(q);
            let w = load.sample(&robot, &q, &Vec6::zeros());
            let f = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            assert!((f - 1.3 * Robot::GRAVITY_MPS2).abs() < 1e-12, "{f}");
            let t = robot.tool().unwrap();
            let g = gravity_load(t.mass_kg, &t.com_flange_m, &t.tcp_offset_flange_m, &robot.frames(&q).rot[6]);
            assert!((0..6).all(|i| (g[i] - w[i]).abs() < 1e-12), "{g:?} {w:?}");
        }
    }
}
