//! The plant's physics: the IRB 2400 with its applicator wheel, (7.1)
//! `M(q) q̈ + C(q, q̇) q̇ + g(q) + Jᵀ(q) F_e = τ`, advanced one control tick at a time.
//!
//! Integrator: classic fourth-order Runge–Kutta on `(q, q̇)` with `loop.substeps` equal substeps
//! per tick (default 10, i.e. 100 µs at 1 kHz). The torque is held constant over the tick (zero-order
//! hold, as a real drive applies the controller's command). The wrist inertias are small
//! (M66 ≈ 6e-5 kg m² bare, a few 1e-4 with the tool), so the free arm's fastest dynamics come from
//! the controller's gains, not from the plant; RK4 at 100 µs resolves them with a wide margin
//! (its stability limit is |λ| dt ≈ 2.8). Until the weatherstrip contact lands (`contact.rs`), the
//! environment wrench F_e is zero.

use std::path::Path;

use anyhow::Context;
use robot::{Robot, Tool, Vec6};
use scenario::Scenario;

pub use scenario::STRIP_TOP_HEIGHT_M;

/// The tool the scenario describes (DESIGN section 3). Starts from [`Tool::default`] (a solid
/// cylinder on the flange z axis) with its mass and inertia scaled to `robot.tool_mass_kg`, the
/// TCP — the wheel centre, as the scenario field says — at `robot.tool_offset_m` along flange z,
/// the COM half-way there, and the wheel radius from `robot.wheel_radius_mm`. The wheel's lowest
/// point lies one radius below the TCP when the tool points down.
/// The controller builds its model with the same rule (`controller::model::tool_from_scenario`).
pub fn tool_from_scenario(s: &Scenario) -> Tool {
    Tool::wheel_on_bracket(s.robot.tool_mass_kg, s.robot.tool_offset_m, s.robot.wheel_radius_mm * 1e-3)
}

/// The plant robot of a scenario: arm + tool, armature and viscous friction from `[robot]`, every
/// mass and inertia scaled by `robot.plant_inertia_scale` (plant/controller mismatch studies).
pub fn plant_robot(s: &Scenario) -> Robot {
    Robot::irb2400_with_tool(tool_from_scenario(s))
        .with_armature(Vec6::from(s.robot.armature_kgm2))
        .with_viscous(Vec6::from(s.robot.viscous_nms))
        .scaled_inertia(s.robot.plant_inertia_scale)
}

/// Start pose of the TCP (wheel centre) in the base frame: the wheel's lowest point
/// `trajectory.approach_height_mm` above the undeformed strip top, over the strip's centre line at
/// task z = `trajectory.z_start_mm`, tool pointing straight down.
pub fn start_tcp_pose(s: &Scenario) -> nalgebra::Isometry3<f64> {
    let p = &s.placement;
    let t = &s.trajectory;
    robot::scenario_tcp_pose(
        p.strip_start_x_m + t.z_start_mm * 1e-3,
        p.strip_y_m,
        p.table_z_m + STRIP_TOP_HEIGHT_M + t.approach_height_mm * 1e-3 + s.robot.wheel_radius_mm * 1e-3,
    )
}

/// Plant state and integrator.
pub struct Physics {
    robot: Robot,
    q: Vec6,
    qd: Vec6,
    /// Substeps per tick and their length, s.
    substeps: u32,
    dt_sub_s: f64,
    /// Simulated time of the current state, s.
    time_s: f64,
    /// Task z of the strip start (base x), m, for the recorded wheel position.
    strip_start_x_m: f64,
    /// Strip + wheel contact (`contact.rs`); None when `strip.enabled = false`.
    contact: Option<crate::contact::StripContact>,
}

impl Physics {
    /// Build the plant of a scenario, at rest in the start pose (IK of [`start_tcp_pose`]).
    /// `cache_dir` is where a reduced strip model is cached (unused while the plant is robot-only).
    pub fn new(s: &Scenario, cache_dir: &Path) -> anyhow::Result<Physics> {
        let contact = if s.strip.enabled {
            let params = crate::contact::strip_params(s);
            let model = strip::StripModel::load_or_build_in(cache_dir, &params)
                .with_context(|| format!("strip model (cache {})", cache_dir.display()))?;
            let h = s.loop_.period_s / s.loop_.substeps as f64;
            Some(crate::contact::StripContact::new(&model, crate::contact::ContactGeometry::from_scenario(s), h))
        } else {
            None
        };
        let robot = plant_robot(s);
        let target = start_tcp_pose(s);
        let q = robot
            .ik_tcp(&target, &robot::scenario_ik_seed())
            .with_context(|| format!("start pose {:?} of the scenario is not reachable", target.translation.vector))?;
        Ok(Physics {
            robot,
            q,
            qd: Vec6::zeros(),
            substeps: s.loop_.substeps,
            dt_sub_s: s.loop_.period_s / s.loop_.substeps as f64,
            time_s: 0.0,
            strip_start_x_m: s.placement.strip_start_x_m,
            contact,
        })
    }

    /// Joint positions, rad.
    pub fn q(&self) -> Vec6 {
        self.q
    }

    /// Joint velocities, rad/s.
    pub fn qd(&self) -> Vec6 {
        self.qd
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The plant's robot model.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Gravity torque g(q) of the plant at the current state, N m (the safe stop's feed-forward).
    pub fn gravity_torque(&self) -> Vec6 {
        self.robot.gravity_torque(&self.q)
    }

    /// Joint accelerations under `tau` at `(q, qd)`.
    #[inline]
    fn qdd(&self, q: &Vec6, qd: &Vec6, tau: &Vec6) -> Vec6 {
        self.robot.forward_dynamics(q, qd, tau)
    }

    /// Advance one tick with the joint torque `tau` (N m) held constant: `substeps` RK4 steps.
    /// With the strip, each substep first advances the contact (`contact.rs`: strip exact, force
    /// implicit at the substep end) from the TCP state at the substep start; its wrench on the
    /// tool W enters the robot as the generalized force J(q)ᵀ W held over the RK4 substep.
    pub fn step_tick(&mut self, tau_cmd: &Vec6) {
        let h = self.dt_sub_s;
        for _ in 0..self.substeps {
            let (q, qd) = (self.q, self.qd);
            let tau_ext = match self.contact.as_mut() {
                Some(c) => {
                    let frames = self.robot.frames(&q);
                    let p = self.robot.tcp_position(&frames);
                    let jac = self.robot.jacobian_point(&frames, &p);
                    let w = c.substep(&p, &frames.rot[6], &(jac * qd));
                    jac.transpose() * w.as_vec6()
                }
                None => Vec6::zeros(),
            };
            let tau = &(tau_cmd + tau_ext);
            let k1v = qd;
            let k1a = self.qdd(&q, &qd, tau);
            let q2 = q + k1v * (0.5 * h);
            let v2 = qd + k1a * (0.5 * h);
            let k2a = self.qdd(&q2, &v2, tau);
            let q3 = q + v2 * (0.5 * h);
            let v3 = qd + k2a * (0.5 * h);
            let k3a = self.qdd(&q3, &v3, tau);
            let q4 = q + v3 * h;
            let v4 = qd + k3a * h;
            let k4a = self.qdd(&q4, &v4, tau);
            self.q = q + (k1v + v2 * 2.0 + v3 * 2.0 + v4) * (h / 6.0);
            self.qd = qd + (k1a + k2a * 2.0 + k3a * 2.0 + k4a) * (h / 6.0);
        }
        self.time_s += h * self.substeps as f64;
    }

    /// End-effector wrench the strip exerts on the tool, as the sensor reports it
    /// ([`messages::WrenchFrame::SensorAtTcp`]): `(force N, torque N m)`. Zero without contact.
    pub fn wrench(&self) -> ([f64; 3], [f64; 3]) {
        match &self.contact {
            Some(c) => c.wrench_sensor(&self.robot.frames(&self.q).rot[6]),
            None => ([0.0; 3], [0.0; 3]),
        }
    }

    /// True while the wheel touches the strip.
    pub fn in_contact(&self) -> bool {
        self.contact.as_ref().is_some_and(|c| c.in_contact())
    }

    /// The strip contact, if the scenario has a strip (centre-line z for the recording metadata).
    pub fn contact(&self) -> Option<&crate::contact::StripContact> {
        self.contact.as_ref()
    }

    /// Strip outputs of the current state for the recording. Robot-only: the wheel position along
    /// the strip (task z = base x − strip start) and zero forces.
    pub fn fill_strip_record(&self, r: &mut recordings::StripRecord) {
        if let Some(c) = &self.contact {
            c.fill_record(r);
            return;
        }
        let tcp = self.robot.tcp_pose(&self.q);
        r.wheel_z_m = tcp.translation.vector.x - self.strip_start_x_m;
        r.contact_force_n = 0.0;
        r.bottom_force_n = 0.0;
        r.max_bottom_pressure_pa = 0.0;
        r.top_displacement_m = 0.0;
        r.n_centreline = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario() -> Scenario {
        let mut s = Scenario::default();
        s.strip.enabled = false;
        s
    }

    #[test]
    fn starts_at_rest_in_the_start_pose() {
        let s = scenario();
        let p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
        let tcp = p.robot().tcp_pose(&p.q());
        let err = (tcp.translation.vector - start_tcp_pose(&s).translation.vector).norm();
        assert!(err < 1e-9, "TCP {err} m from the start pose");
        assert_eq!(p.qd(), Vec6::zeros());
    }

    #[test]
    fn gravity_compensation_holds_the_arm_still() {
        let s = scenario();
        let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
        let q0 = p.q();
        for _ in 0..100 {
            let tau = p.gravity_torque();
            p.step_tick(&tau);
        }
        assert!((p.q() - q0).norm() < 1e-9, "drift {}", (p.q() - q0).norm());
        assert!((p.time_s() - 0.1).abs() < 1e-12);
    }

    /// RK4 is fourth order: with the arm falling freely (no torque), the state after 100 ms
    /// changes ~16x less between 2 and 4 substeps than between 1 and 2 (Richardson).
    #[test]
    fn substep_refinement_converges_at_fourth_order() {
        let run = |substeps: u32| {
            let mut s = scenario();
            s.loop_.substeps = substeps;
            let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
            let tau = Vec6::zeros();
            for _ in 0..100 {
                p.step_tick(&tau);
            }
            assert!(p.qd().norm() > 1e-3, "the arm should be moving");
            p.q()
        };
        let (q1, q2, q4) = (run(1), run(2), run(4));
        let (e_coarse, e_fine) = ((q1 - q2).norm(), (q2 - q4).norm());
        eprintln!("substep refinement: {e_coarse:.3e} rad (1 vs 2), {e_fine:.3e} rad (2 vs 4)");
        assert!(e_fine > 1e-14 && e_fine < 1e-6, "{e_fine}");
        let ratio = e_coarse / e_fine;
        assert!(ratio > 10.0 && ratio < 24.0, "ratio {ratio}, fourth order gives 16");
    }

    #[test]
    fn identical_inputs_give_bit_identical_states() {
        let s = scenario();
        let run = || {
            let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
            for k in 0..50 {
                let tau = p.gravity_torque() + Vec6::from_element((k as f64 * 0.1).sin());
                p.step_tick(&tau);
            }
            (p.q(), p.qd())
        };
        let (a, b) = (run(), run());
        assert!(a.0.iter().zip(b.0.iter()).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert!(a.1.iter().zip(b.1.iter()).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}
