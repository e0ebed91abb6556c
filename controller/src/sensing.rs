//! What the default controller does with a real force/torque sensor's reading before the law
//! sees it (DESIGN section 12), each step off unless the scenario's `[controller]` asks for it:
//!
//! 1. Tool load compensation (`tool_load_compensation`): subtract the tool's gravity load from
//!    the nominal mass and centre the controller believes (`scenarios::geometry::controller_tool`),
//!    rotating with the tool: `F = Rᵀ m g`, `M = (c − p_tcp) × F` in tool axes about the TCP;
//!    and its inertial load `−m a_c`, `−I α` from the acceleration the controller commanded on
//!    the previous tick, passed through the sensor's nominal low-pass and sample delay (`[sensor]`
//!    lowpass_hz, delay_ticks: the datasheet's values) so that it lines up with the reading.
//!    Why the inertial part matters: the impedance (6.3) has m_d ≈ 0.2 kg, the tool beyond the
//!    sensor 1 kg; uncompensated, the tool's own acceleration −m ÿ in the measured force closes a
//!    loop of gain m/m_d ≈ 5 through a_y = (F_r − F_e)/m_d, which diverges at the Nyquist rate.
//!    Only the commanded acceleration's part above [`INERTIAL_HIGH_PASS_HZ`] is used: below it,
//!    when stiction holds the arm against the motion PD, the commanded acceleration is not what
//!    the tool does (a phantom force m k_p e of about 0.4 N in free air, enough to trip the
//!    contact detection), and the tool's true low-frequency inertial load is tiny here
//!    (m ÿ ≈ 0.05 N on the roll's cosine profile).
//! 2. Tare (`tare_s`), as on a real cell: the robot stands still in free air in its start pose
//!    (the reference generator's settle phase, before the approach); over the first `tare_s` of
//!    states the controller averages the compensated reading and from then on subtracts that
//!    mean, the sensor's offset (its bias and whatever of the tool's load the nominal values
//!    missed in this orientation). While it tares it hands the law a zero wrench (no contact in
//!    free air).
//! 3. Force filter (`force_filter_hz`): a first-order low-pass on the result,
//!    y += β (x − y), β = 1 − exp(−2π f T).
//!
//! Fixed-size, allocation-free.

use messages::{Wrench, WrenchFrame};
use nalgebra::{Matrix3, Vector3};
use robot::Robot;
use scenarios::Scenario;

/// The controller's sensor processing between ticks.
#[derive(Debug, Clone)]
pub struct ForceSensing {
    compensate: bool,
    mass_kg: f64,
    com_flange_m: Vector3<f64>,
    tcp_flange_m: Vector3<f64>,
    tare_ticks: u32,
    tared: u32,
    sum: [f64; 6],
    offset: [f64; 6],
    /// Filter coefficient β (None: no filter) and state.
    beta: Option<f64>,
    filtered: Option<[f64; 6]>,
    inertia_com: Matrix3<f64>,
    /// The sensor's nominal low-pass coefficient and delay (1, 0 without a sensor model) and the
    /// predicted inertial load through them.
    sensor_alpha: f64,
    sensor_delay: usize,
    inertial_filtered: [f64; 6],
    inertial_ring: [[f64; 6]; DELAY_RING],
    head: usize,
    /// High-pass: y_k = γ (y_{k−1} + x_k − x_{k−1}), γ = exp(−2π f T); its last input and output.
    high_pass: f64,
    hp_in: [f64; 6],
    hp_out: [f64; 6],
}

/// Corner of the first-order high-pass on the predicted inertial load, Hz (module docs).
pub const INERTIAL_HIGH_PASS_HZ: f64 = 2.0;

/// Longest sensor delay the compensation models, ticks (the scenario allows 100).
const DELAY_RING: usize = 101;

impl ForceSensing {
    pub fn from_scenario(s: &Scenario) -> ForceSensing {
        let c = &s.controller;
        let tool = scenarios::geometry::controller_tool(s);
        let period = s.loop_.period_s;
        ForceSensing {
            compensate: c.tool_load_compensation,
            mass_kg: tool.mass_kg,
            com_flange_m: tool.com_flange_m,
            tcp_flange_m: tool.tcp_offset_flange_m,
            tare_ticks: (c.tare_s / period).round() as u32,
            tared: 0,
            sum: [0.0; 6],
            offset: [0.0; 6],
            beta: (c.force_filter_hz > 0.0).then(|| 1.0 - (-std::f64::consts::TAU * c.force_filter_hz * period).exp()),
            filtered: None,
            inertia_com: tool.inertia_com,
            sensor_alpha: if s.sensor.enabled && s.sensor.lowpass_hz > 0.0 {
                1.0 - (-std::f64::consts::TAU * s.sensor.lowpass_hz * period).exp()
            } else {
                1.0
            },
            sensor_delay: if s.sensor.enabled { (s.sensor.delay_ticks as usize).min(DELAY_RING - 1) } else { 0 },
            inertial_filtered: [0.0; 6],
            inertial_ring: [[0.0; 6]; DELAY_RING],
            head: 0,
            high_pass: (-std::f64::consts::TAU * INERTIAL_HIGH_PASS_HZ * period).exp(),
            hp_in: [0.0; 6],
            hp_out: [0.0; 6],
        }
    }

    /// The tool's inertial load on the sensor (tool axes, about the TCP, a wrench on the tool) for
    /// the TCP acceleration `accel_base` (linear then angular, base axes): `−m a_c` with
    /// `a_c = a + α × r`, its moment, and `−I α` (the ω terms are negligible at these speeds).
    pub fn inertial_load(&self, rot_base_tool: &Matrix3<f64>, accel_base: &robot::Vec6) -> [f64; 6] {
        let r_tool = self.com_flange_m - self.tcp_flange_m;
        let a = rot_base_tool.transpose() * Vector3::new(accel_base[0], accel_base[1], accel_base[2]);
        let alpha = rot_base_tool.transpose() * Vector3::new(accel_base[3], accel_base[4], accel_base[5]);
        let f = -(a + alpha.cross(&r_tool)) * self.mass_kg;
        let m = r_tool.cross(&f) - self.inertia_com * alpha;
        [f.x, f.y, f.z, m.x, m.y, m.z]
    }

    /// The inertial load of the previous tick's commanded acceleration as the sensor reports it
    /// now (through its nominal filter and delay).
    fn inertial_as_read(&mut self, rot_base_tool: &Matrix3<f64>, accel_prev_base: &robot::Vec6) -> [f64; 6] {
        let x = self.inertial_load(rot_base_tool, accel_prev_base);
        for (y, xi) in self.inertial_filtered.iter_mut().zip(x) {
            *y += self.sensor_alpha * (xi - *y);
        }
        self.head = (self.head + 1) % DELAY_RING;
        self.inertial_ring[self.head] = self.inertial_filtered;
        let read = self.inertial_ring[(self.head + DELAY_RING - self.sensor_delay) % DELAY_RING];
        for ((out, r), prev) in self.hp_out.iter_mut().zip(read).zip(self.hp_in) {
            *out = self.high_pass * (*out + r - prev);
        }
        self.hp_in = read;
        self.hp_out
    }

    /// True when any step is on (otherwise the reading goes to the law untouched).
    pub fn is_active(&self) -> bool {
        self.compensate || self.tare_ticks > 0 || self.beta.is_some()
    }

    /// True while taring.
    pub fn taring(&self) -> bool {
        self.tared < self.tare_ticks
    }

    /// The offset the tare found (zero before and without one), per axis of the reading's frame.
    pub fn offset(&self) -> [f64; 6] {
        self.offset
    }

    /// The tool's nominal gravity load in tool axes about the TCP at orientation `rot_base_tool`.
    pub fn tool_load(&self, rot_base_tool: &Matrix3<f64>) -> [f64; 6] {
        let f = rot_base_tool.transpose() * Vector3::new(0.0, 0.0, -Robot::GRAVITY_MPS2 * self.mass_kg);
        let m = (self.com_flange_m - self.tcp_flange_m).cross(&f);
        [f.x, f.y, f.z, m.x, m.y, m.z]
    }

    /// The wrench the law uses this tick, from the reading `w` with the tool at `rot_base_tool`;
    /// `accel_prev_base`: the TCP acceleration the law commanded on the previous tick.
    pub fn process(&mut self, w: &Wrench, rot_base_tool: &Matrix3<f64>, accel_prev_base: &robot::Vec6) -> Wrench {
        let mut x = [w.force[0], w.force[1], w.force[2], w.torque[0], w.torque[1], w.torque[2]];
        if self.compensate {
            let mut load = self.tool_load(rot_base_tool);
            let inertial = self.inertial_as_read(rot_base_tool, accel_prev_base);
            for (l, i) in load.iter_mut().zip(inertial) {
                *l += i;
            }
            if w.frame != WrenchFrame::SensorAtTcp as u32 {
                // A reading in base axes: the load too.
                let (f, m) =
                    (rot_base_tool * Vector3::new(load[0], load[1], load[2]), rot_base_tool * Vector3::new(load[3], load[4], load[5]));
                load = [f.x, f.y, f.z, m.x, m.y, m.z];
            }
            for (xi, l) in x.iter_mut().zip(load) {
                *xi -= l;
            }
        }
        if self.taring() {
            for (s, xi) in self.sum.iter_mut().zip(x) {
                *s += xi;
            }
            self.tared += 1;
            if !self.taring() {
                self.offset = self.sum.map(|s| s / self.tare_ticks as f64);
            }
            return Wrench { force: [0.0; 3], torque: [0.0; 3], ..*w };
        }
        for (xi, o) in x.iter_mut().zip(self.offset) {
            *xi -= o;
        }
        if let Some(b) = self.beta {
            let y = self.filtered.get_or_insert(x);
            for (yi, xi) in y.iter_mut().zip(x) {
                *yi += b * (xi - *yi);
            }
            x = *y;
        }
        Wrench { force: [x[0], x[1], x[2]], torque: [x[3], x[4], x[5]], ..*w }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use messages::CONTRACT_VERSION;

    fn reading(x: [f64; 6]) -> Wrench {
        Wrench {
            contract_version: CONTRACT_VERSION,
            frame: WrenchFrame::SensorAtTcp as u32,
            tick: 0,
            force: [x[0], x[1], x[2]],
            torque: [x[3], x[4], x[5]],
        }
    }

    /// An offset plus the tool's weight in the tare's orientation comes out as zero after the
    /// tare; a contact force added afterwards comes out as itself.
    #[test]
    fn tare_and_compensation_leave_the_contact_wrench() {
        let mut s = Scenario::default();
        s.trajectory.settle_s = 0.2;
        s.controller.tare_s = 0.1;
        s.controller.tool_load_compensation = true;
        let mut f = ForceSensing::from_scenario(&s);
        let rot = scenarios::geometry::tool_down_rotation();
        let load = f.tool_load(&rot);
        assert!((load[2] - 9.81 * s.robot.tool_mass_kg * -rot[(2, 2)]).abs() < 1e-12, "{load:?}");
        let bias = [0.3, -0.2, 1.1, 0.01, -0.02, 0.005];
        let at = |c: [f64; 6]| reading(std::array::from_fn(|i| c[i] + bias[i] + load[i]));
        for _ in 0..100 {
            assert!(f.taring());
            assert_eq!(f.process(&at([0.0; 6]), &rot, &robot::Vec6::zeros()).force, [0.0; 3]);
        }
        assert!(!f.taring());
        let out = f.process(&at([0.0, 0.0, 10.0, 0.0, 0.0, 0.0]), &rot, &robot::Vec6::zeros());
        assert!((out.force[2] - 10.0).abs() < 1e-12 && out.force[0].abs() < 1e-12, "{out:?}");
    }
}
