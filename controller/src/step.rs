//! The controller's step as a value: [`Controller`] holds the law, the reference generator and
//! the anti-windup state, and [`Controller::process`] turns one joint state and wrench into one
//! torque and its diagnostics. The daemon (`daemon.rs`), `rig run --in-process`, `rig sweep` and
//! the tests all drive this one type, so the same code answers over iceoryx2 and in-process.
//!
//! Allocation-free per call (`tests/tests/no_alloc.rs` counts, over a whole servo run).

use messages::{state_flags, ControllerDiagnostics, ControllerStatus, JointState, JointTorque, PlantStatus, Wrench, WrenchFrame};
use nalgebra::{Matrix3, Vector3};
use robot::Vec6;
use scenarios::geometry::{tool_down_rotation, TaskFrame};
use scenarios::Scenario;

use crate::gains::Gains;
use crate::law::ControlLaw;
use crate::reference::ReferenceGenerator;
use crate::sensing::ForceSensing;

/// Measured wrench on the tool in base axes at the TCP, (force, torque) as one 6-vector
/// (messages/README.md, "Frames and signs").
pub fn wrench_on_tool_base(w: &Wrench, rot_base_tool: &Matrix3<f64>) -> Vec6 {
    let f = Vector3::from(w.force);
    let m = Vector3::from(w.torque);
    let (f, m) = if w.frame == WrenchFrame::SensorAtTcp as u32 { (rot_base_tool * f, rot_base_tool * m) } else { (f, m) };
    Vec6::new(f.x, f.y, f.z, m.x, m.y, m.z)
}

/// The controller's robot model (defined with the law it serves).
pub use crate::law::controller_robot;

/// The force controller of a scenario, between ticks.
pub struct Controller {
    law: ControlLaw,
    /// Tool load compensation, tare and force filter (`sensing.rs`; inactive by default).
    sensing: ForceSensing,
    reference: ReferenceGenerator,
    contract_version: u32,
    controller_id: u64,
    /// No state answered yet: the next one starts the references from where the TCP is.
    first: bool,
    /// The last state said safe stop (re-engage when it clears).
    was_stopped: bool,
}

impl Controller {
    /// The scenario's controller: its robot model (without the plant's inertia scale), task
    /// frame (along a `[contour]`, the path's moving frame), gains from the design rule, tool
    /// pointing down (turned with the contour's heading), references from `[trajectory]`.
    pub fn from_scenario(s: &Scenario) -> Controller {
        let law =
            ControlLaw::new(controller_robot(s), TaskFrame::from_scenario(s), Gains::from_scenario(s, f64::NAN), tool_down_rotation())
                .along_scenario_path(s);
        Controller {
            law,
            sensing: ForceSensing::from_scenario(s),
            reference: ReferenceGenerator::from_scenario(s),
            contract_version: messages::CONTRACT_VERSION,
            controller_id: 0,
            first: true,
            was_stopped: false,
        }
    }

    /// The `controller_id` its torques carry (the plant follows one id at a time).
    pub fn with_id(mut self, controller_id: u64) -> Controller {
        self.controller_id = controller_id;
        self
    }

    /// The contract version its torques and diagnostics say (tests pretend others).
    pub fn with_contract_version(mut self, v: u32) -> Controller {
        self.contract_version = v;
        self
    }

    pub fn law(&self) -> &ControlLaw {
        &self.law
    }

    /// The sensor processing (tare offset, tool load).
    pub fn sensing(&self) -> &ForceSensing {
        &self.sensing
    }

    pub fn reference(&self) -> &ReferenceGenerator {
        &self.reference
    }

    /// Start over as on a first connection (a new plant): the next state starts the references.
    pub fn restart(&mut self) {
        self.first = true;
    }

    /// No state answered yet.
    pub fn is_first(&self) -> bool {
        self.first
    }

    /// Answer one state: references (started from the TCP at the first state; held while the
    /// plant holds our torque or stands in safe stop; re-engaged from the measured pose and force
    /// when a safe stop ends, DESIGN section 10), the law, the diagnostics. `wrench` is the same
    /// tick's. The diagnostics' stage stamps are 0 here: a transport that has clocks sets them.
    pub fn process(&mut self, state: &JointState, wrench: &Wrench) -> (JointTorque, ControllerDiagnostics) {
        let q = Vec6::from(state.q);
        let qd = Vec6::from(state.qd);
        let sensed;
        let wrench = if self.sensing.is_active() {
            sensed = self.sensing.process(wrench, &self.law.robot().frames(&q).rot[6], &self.law.last_accel_base());
            &sensed
        } else {
            wrench
        };
        let first = self.first;
        if first {
            // A take-over of a running plant first moves the TCP from where it is to the start
            // pose, then starts its own run.
            let kin = self.law.kinematics(&q, &qd);
            self.reference.reset_from(state.sim_time_s, &kin.pos_task_m);
        }
        let status = PlantStatus::from_u32(state.plant_status);
        let stopped = status == Some(PlantStatus::SafeStop);
        let running = matches!(status, Some(PlantStatus::Running | PlantStatus::WaitingForController));
        if stopped && !self.was_stopped && !first {
            let kin = self.law.kinematics(&q, &qd);
            let w = wrench_on_tool_base(wrench, &kin.rot_base_tool);
            let force_y = self.law.strip_force_y(&Vector3::new(w[0], w[1], w[2]));
            self.reference.reengage(state.sim_time_s, &kin.pos_task_m, &kin.vel_task_mps, force_y);
        } else if !running && !first {
            self.reference.hold(state.period_s);
        }
        self.was_stopped = stopped;
        self.first = false;
        self.law.set_integrating(running && state.flags & state_flags::IN_CONTACT != 0);
        let (tau, diag) = step(&mut self.law, &mut self.reference, state, wrench, &q, &qd, self.contract_version);
        let torque = JointTorque {
            contract_version: self.contract_version,
            // A reflex latched the plant's safe stop: acknowledge it (starting) with the
            // re-engaged torque, as libfranka's automatic error recovery does.
            controller_status: if !tau.iter().all(|x| x.is_finite()) {
                ControllerStatus::Fault as u32
            } else if state.flags & state_flags::REFLEX != 0 {
                ControllerStatus::Starting as u32
            } else {
                ControllerStatus::Active as u32
            },
            tick: state.tick,
            controller_id: self.controller_id,
            tau: tau.into(),
        };
        (torque, diag)
    }
}

/// One control step (allocation-free): references, law, diagnostics (stamps 0). The law and
/// reference as [`Controller`] wires them; kept public for the step benchmark.
pub fn step(
    law: &mut ControlLaw,
    reference: &mut ReferenceGenerator,
    state: &JointState,
    wrench: &Wrench,
    q: &Vec6,
    qd: &Vec6,
    contract_version: u32,
) -> (Vec6, ControllerDiagnostics) {
    let kin = law.kinematics(q, qd);
    let w = wrench_on_tool_base(wrench, &kin.rot_base_tool);
    let force_y = law.strip_force_y(&Vector3::new(w[0], w[1], w[2]));
    let r = reference.update(state.sim_time_s, force_y, kin.pos_task_m.y);
    let out = law.compute(q, qd, &kin, &w, &r, state.period_s);
    let diag = ControllerDiagnostics {
        contract_version,
        force_control_active: u32::from(r.force_mode),
        tick: state.tick,
        force_ref_n: r.force_y_n,
        force_meas_n: out.force_meas_n,
        pos_ref_task_m: r.pos_m.into(),
        pos_err_task_m: out.pos_err_task_m.into(),
        rot_err_task_rad: out.rot_err_task_rad.into(),
        force_integral_ns: out.force_integral_ns,
        compute_time_ns: 0,
        woke_mono_ns: 0,
        computed_mono_ns: 0,
        published_mono_ns: 0,
    };
    (out.tau, diag)
}

#[cfg(test)]
mod tests {
    //! Each branch of [`Controller::process`] against a closed form or against a twin controller
    //! that saw the ticks the branch should make it equal to. A fake plant: states at rest where
    //! the test puts the arm, wrenches as the test sets them.

    use super::*;
    use crate::reference::{Phase, REENGAGE_S};
    use messages::CONTRACT_VERSION;
    use nalgebra::{Isometry3, Translation3};
    use robot::Robot;
    use scenarios::geometry::{start_tcp_pose, start_tcp_task_m};
    use std::f64::consts::TAU;

    #[test]
    fn controller_robot_ignores_plant_inertia_scale() {
        let mut s = Scenario::default();
        let a = controller_robot(&s).total_mass_kg();
        s.robot.plant_inertia_scale = 1.1;
        assert_eq!(controller_robot(&s).total_mass_kg(), a);
    }

    /// The default scenario's controller (sensor processing off: the law sees the wrench as
    /// sent), its robot model and the start pose q0.
    fn setup() -> (Scenario, Controller, Robot, Vec6) {
        let s = Scenario::default();
        let c = Controller::from_scenario(&s).with_id(7);
        assert!(!c.sensing().is_active());
        let robot = controller_robot(&s);
        let q0 = robot.ik_tcp(&start_tcp_pose(&s), &robot::ik_seed_tool_down()).unwrap();
        (s, c, robot, q0)
    }

    /// The joints that put the TCP `offset_task_m` (task axes) from the start point, tool down.
    fn q_at(s: &Scenario, robot: &Robot, offset_task_m: Vector3<f64>) -> Vec6 {
        let p = TaskFrame::from_scenario(s).point_to_base(&(start_tcp_task_m(s) + offset_task_m));
        let pose = Isometry3::from_parts(Translation3::from(p), start_tcp_pose(s).rotation);
        robot.ik_tcp(&pose, &robot::ik_seed_tool_down()).unwrap()
    }

    /// The TCP of `q` in task coordinates.
    fn tcp_task(s: &Scenario, robot: &Robot, q: &Vec6) -> Vector3<f64> {
        TaskFrame::from_scenario(s).point_to_task(&robot.tcp_pose(q).translation.vector)
    }

    /// The arm at rest at `q` on tick `tick` (1 kHz) with `status` and `flags`.
    fn state(tick: u64, status: PlantStatus, q: &Vec6, flags: u32) -> JointState {
        JointState { flags, ..JointState::at_rest(tick, status, (*q).into()) }
    }

    /// A force `force_base_n` (base axes, at the TCP) on the tool on tick `tick`, no moment.
    fn wrench(tick: u64, force_base_n: [f64; 3]) -> Wrench {
        Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::BaseAtTcp as u32, tick, force: force_base_n, torque: [0.0; 3] }
    }

    fn tau(t: &JointTorque) -> Vec6 {
        Vec6::from(t.tau)
    }

    fn status(t: &JointTorque) -> Option<ControllerStatus> {
        ControllerStatus::from_u32(t.controller_status)
    }

    /// Answers `c` gives at rest at `q`, no wrench, `status` and `flags`, for `ticks`.
    fn run(
        c: &mut Controller,
        ticks: std::ops::Range<u64>,
        st: PlantStatus,
        q: &Vec6,
        flags: u32,
    ) -> Vec<(JointTorque, ControllerDiagnostics)> {
        ticks.map(|k| c.process(&state(k, st, q, flags), &wrench(k, [0.0; 3]))).collect()
    }

    /// Normal tracking. Tick 0 at rest at the start pose: the references start there (settle),
    /// so τ = g(q0). Tick 1, still settling, with the arm displaced by δ at rest: the PD (7.8)
    /// asks a_x = (−k_p R_bt δ, 0) with k_p = (2π f_m)², J̇ q̇ = 0, so (7.2)-(7.6) give
    /// τ = M(q1) J(q1)⁻¹ a_x + g(q1).
    #[test]
    fn tracking_answers_a_displacement_with_the_pd_through_the_arms_inertia() {
        let (s, mut c, robot, q0) = setup();
        let (t0, d0) = c.process(&state(0, PlantStatus::Running, &q0, 0), &wrench(0, [0.0; 3]));
        let g0 = robot.gravity_torque(&q0);
        // (to the IK's accuracy: k_p times a 1e-10 m miss is about 1e-6 N m)
        assert!((tau(&t0) - g0).norm() < 1e-7 * g0.norm(), "{} vs g(q0) {g0}", tau(&t0));
        assert_eq!(status(&t0), Some(ControllerStatus::Active));
        assert_eq!((t0.tick, t0.controller_id, t0.contract_version), (0, 7, CONTRACT_VERSION));
        assert!((Vector3::from(d0.pos_ref_task_m) - start_tcp_task_m(&s)).norm() < 1e-12);
        assert_eq!(c.reference().phase(), Phase::Settle);

        let delta = Vector3::new(1e-3, -0.5e-3, 2e-3);
        let q1 = q_at(&s, &robot, delta);
        let (t1, d1) = c.process(&state(1, PlantStatus::Running, &q1, 0), &wrench(1, [0.0; 3]));
        let w = TAU * s.controller.motion_bandwidth_hz;
        let a_lin = TaskFrame::from_scenario(&s).vector_to_base(&(-delta * (w * w)));
        let a_x = Vec6::new(a_lin.x, a_lin.y, a_lin.z, 0.0, 0.0, 0.0);
        let a_q = robot.jacobian_tcp(&q1).lu().solve(&a_x).unwrap();
        let pd = robot.mass_matrix(&q1) * a_q;
        let expect = pd + robot.gravity_torque(&q1);
        assert!(pd.norm() > 1.0, "the PD's share must show: {pd}");
        assert!((tau(&t1) - expect).norm() < 1e-6 * pd.norm(), "{} vs {expect}", tau(&t1));
        assert!((Vector3::from(d1.pos_err_task_m) + delta).norm() < 1e-9, "{:?}", d1.pos_err_task_m);
        assert_eq!((status(&t1), t1.tick, d1.tick), (Some(ControllerStatus::Active), 1, 1));
    }

    /// The first state (a take-over of a running plant) away from the start: the references
    /// start where the TCP is (the return move), so at rest the answer is g(q), no pull towards
    /// the start. `restart` makes the next state a first one again; without it the same state
    /// is pulled back.
    #[test]
    fn a_first_state_begins_the_references_where_the_arm_is() {
        let (s, mut c, robot, _) = setup();
        let q = q_at(&s, &robot, Vector3::new(0.0, 0.05, -0.02));
        let (t, d) = c.process(&state(500, PlantStatus::Running, &q, 0), &wrench(500, [0.0; 3]));
        let g = robot.gravity_torque(&q);
        assert!((tau(&t) - g).norm() < 1e-9 * g.norm(), "{} vs g(q) {g}", tau(&t));
        assert_eq!(c.reference().phase(), Phase::Return);
        assert!((Vector3::from(d.pos_ref_task_m) - tcp_task(&s, &robot, &q)).norm() < 1e-12);

        let q2 = q_at(&s, &robot, Vector3::new(0.01, 0.03, 0.0));
        let g2 = robot.gravity_torque(&q2);
        let pulled = c.process(&state(501, PlantStatus::Running, &q2, 0), &wrench(501, [0.0; 3])).0;
        assert!((tau(&pulled) - g2).norm() > 1.0, "not first: pulled to the reference");
        c.restart();
        assert!(c.is_first());
        let (t2, _) = c.process(&state(502, PlantStatus::Running, &q2, 0), &wrench(502, [0.0; 3]));
        assert!((tau(&t2) - g2).norm() < 1e-9 * g2.norm(), "{} vs g(q2) {g2}", tau(&t2));
        assert!(!c.is_first());
    }

    /// A reflex latched the plant's safe stop (SafeStop with REFLEX): the answer acknowledges it
    /// as Starting, with the torque re-engaged where the arm is: the references from the
    /// measured pose, so at rest τ = g(q1), where a running state at the same pose is pulled
    /// back to the start. Once the plant has cleared the flag the answer is Active again.
    #[test]
    fn a_reflex_stop_is_acknowledged_as_starting_with_the_torque_re_engaged_where_the_arm_is() {
        let (s, mut c, robot, q0) = setup();
        let mut twin = Controller::from_scenario(&s).with_id(7);
        run(&mut c, 0..1, PlantStatus::Running, &q0, 0);
        run(&mut twin, 0..1, PlantStatus::Running, &q0, 0);
        let q1 = q_at(&s, &robot, Vector3::new(2e-3, 1e-3, 0.0));
        let g1 = robot.gravity_torque(&q1);

        let (t, d) = c.process(&state(1, PlantStatus::SafeStop, &q1, state_flags::REFLEX), &wrench(1, [0.0; 3]));
        assert_eq!(status(&t), Some(ControllerStatus::Starting));
        assert_eq!(t.controller_status, 1, "the wire value of starting");
        assert!((tau(&t) - g1).norm() < 1e-9 * g1.norm(), "{} vs g(q1) {g1}", tau(&t));
        assert!((Vector3::from(d.pos_ref_task_m) - tcp_task(&s, &robot, &q1)).norm() < 1e-12);
        let (t_running, _) = twin.process(&state(1, PlantStatus::Running, &q1, 0), &wrench(1, [0.0; 3]));
        assert_eq!(status(&t_running), Some(ControllerStatus::Active));
        assert!((tau(&t_running) - g1).norm() > 1.0, "running, the same pose is pulled back");

        let (t2, _) = c.process(&state(2, PlantStatus::SafeStop, &q1, 0), &wrench(2, [0.0; 3]));
        assert_eq!(status(&t2), Some(ControllerStatus::Active));
    }

    /// A safe stop during the approach (ticks k .. k+N−1, N periods longer than [`REENGAGE_S`]),
    /// then running again. At the stop the references re-engage from the measured pose (zero
    /// error); the plan's clock stands still through the stop while the re-engagement's offset
    /// fades, so at its end the reference is the plan of tick k−1; back in running it moves on
    /// from there: tick k+N answers as a controller that never stopped answers tick k.
    #[test]
    fn after_a_safe_stop_the_plan_goes_on_from_where_it_stood() {
        let (s, mut c, robot, q0) = setup();
        let mut twin = Controller::from_scenario(&s).with_id(7);
        let (k, n) = (200u64, 400u64);
        assert!(n as f64 * s.loop_.period_s > REENGAGE_S);
        run(&mut c, 0..k, PlantStatus::Running, &q0, 0);
        let plan = run(&mut twin, 0..k + n + 1, PlantStatus::Running, &q0, 0);
        assert_eq!(c.reference().phase(), Phase::Approach);

        let stop = run(&mut c, k..k + n, PlantStatus::SafeStop, &q0, 0);
        assert!(Vector3::from(stop[0].1.pos_err_task_m).norm() < 1e-12, "re-engaged where the arm is");
        // ... and as fast (at rest), at the approach's cruise (no acceleration): τ = g(q0).
        let g0 = robot.gravity_torque(&q0);
        assert!((tau(&stop[0].0) - g0).norm() < 1e-9 * g0.norm(), "{} vs g(q0) {g0}", tau(&stop[0].0));
        let end = Vector3::from(stop[n as usize - 1].1.pos_ref_task_m);
        assert!((end - Vector3::from(plan[k as usize - 1].1.pos_ref_task_m)).norm() < 1e-12, "{end:?}");
        let (t, d) = c.process(&state(k + n, PlantStatus::Running, &q0, 0), &wrench(k + n, [0.0; 3]));
        let (t_plan, d_plan) = plan[k as usize];
        assert!((Vector3::from(d.pos_ref_task_m) - Vector3::from(d_plan.pos_ref_task_m)).norm() < 1e-12);
        assert!((tau(&t) - tau(&t_plan)).norm() < 1e-9 * tau(&t_plan).norm(), "{} vs {}", tau(&t), tau(&t_plan));
        // The plan moved meanwhile in the twin: the comparison can tell.
        let moved = Vector3::from(plan[(k + n) as usize].1.pos_ref_task_m) - Vector3::from(d_plan.pos_ref_task_m);
        assert!(moved.norm() > 1e-3, "{moved:?}");
    }

    /// The plant holds the last torque (HoldingTorque, ticks k .. k+N−1): the plan's clock stands
    /// still, so each held tick answers as tick k−1 did (same state: same torque), and running
    /// again, tick k+N answers as a controller that was never held answers tick k.
    #[test]
    fn while_the_plant_holds_the_plan_stands_still() {
        let (s, mut c, _, q0) = setup();
        let mut twin = Controller::from_scenario(&s).with_id(7);
        let (k, n) = (200u64, 50u64);
        run(&mut c, 0..k, PlantStatus::Running, &q0, 0);
        let plan = run(&mut twin, 0..k + 1, PlantStatus::Running, &q0, 0);
        let (t_before, d_before) = plan[k as usize - 1];
        for (t, d) in run(&mut c, k..k + n, PlantStatus::HoldingTorque, &q0, 0) {
            assert_eq!(status(&t), Some(ControllerStatus::Active));
            assert!((Vector3::from(d.pos_ref_task_m) - Vector3::from(d_before.pos_ref_task_m)).norm() < 1e-12);
            assert!((tau(&t) - tau(&t_before)).norm() < 1e-9 * tau(&t_before).norm(), "{} vs {}", tau(&t), tau(&t_before));
        }
        let (t, d) = c.process(&state(k + n, PlantStatus::Running, &q0, 0), &wrench(k + n, [0.0; 3]));
        let (t_plan, d_plan) = plan[k as usize];
        assert!((Vector3::from(d.pos_ref_task_m) - Vector3::from(d_plan.pos_ref_task_m)).norm() < 1e-12);
        assert!((tau(&t) - tau(&t_plan)).norm() < 1e-9 * tau(&t_plan).norm());
        // At 10 mm/s the approach moves 10 µm a tick: holding is visible.
        assert!((Vector3::from(d_plan.pos_ref_task_m) - Vector3::from(d_before.pos_ref_task_m)).norm() > 5e-6);
    }

    /// The force integral runs only while the plant runs and the wheel is in contact: pressed
    /// down into the force ramp, each running tick in contact adds (F_r − F_e) T (6.3), a held
    /// tick or a tick out of contact adds nothing.
    #[test]
    fn the_force_integral_runs_only_while_running_in_contact() {
        let (s, mut c, _, q0) = setup();
        let period = s.loop_.period_s;
        run(&mut c, 0..150, PlantStatus::Running, &q0, 0);
        assert_eq!(c.reference().phase(), Phase::Approach);
        // 2 N up on the tool (base z = task y): the strip is pressed with −2 N, then −1 N.
        let contact = state_flags::IN_CONTACT;
        let press = |c: &mut Controller, k: u64, st: PlantStatus, flags: u32, f: f64| {
            c.process(&state(k, st, &q0, flags), &wrench(k, [0.0, 0.0, f]))
        };
        let mut k = 150;
        while c.reference().phase() != Phase::ForceRamp {
            press(&mut c, k, PlantStatus::Running, contact, 2.0);
            k += 1;
            assert!(k < 300, "never reached the force ramp");
        }
        let mut last = press(&mut c, k, PlantStatus::Running, contact, 1.0).1;
        assert_eq!(last.force_control_active, 1);
        let mut step = |c: &mut Controller, k: u64, st: PlantStatus, flags: u32| {
            let d = press(c, k, st, flags, 1.0).1;
            let di = d.force_integral_ns - last.force_integral_ns;
            last = d;
            (di, d)
        };
        for j in 1..=5 {
            let (di, d) = step(&mut c, k + j, PlantStatus::Running, contact);
            assert_eq!(d.force_meas_n, -1.0);
            assert!(di.abs() > 1e-4, "running in contact: integrates ({di})");
            assert!((di - (d.force_ref_n - d.force_meas_n) * period).abs() < 1e-15, "{di} vs (F_r − F_e) T");
        }
        assert_eq!(step(&mut c, k + 6, PlantStatus::HoldingTorque, contact).0, 0.0, "held: stands still");
        assert_eq!(step(&mut c, k + 7, PlantStatus::Running, 0).0, 0.0, "out of contact: stands still");
        assert!(step(&mut c, k + 8, PlantStatus::Running, contact).0.abs() > 1e-4, "and runs again");
    }

    /// A state the law cannot answer (a NaN joint angle, or a NaN in the wrench) gives a
    /// non-finite torque marked Fault (2 on the wire), which the plant refuses; Fault goes before
    /// a reflex acknowledgement.
    #[test]
    fn a_non_finite_torque_is_marked_fault() {
        let (s, mut c, _, q0) = setup();
        run(&mut c, 0..1, PlantStatus::Running, &q0, 0);
        let mut q = q0;
        q[2] = f64::NAN;
        let (t, _) = c.process(&state(1, PlantStatus::Running, &q, 0), &wrench(1, [0.0; 3]));
        assert_eq!((status(&t), t.controller_status), (Some(ControllerStatus::Fault), 2));
        assert!(tau(&t).iter().any(|x| !x.is_finite()));

        let mut c = Controller::from_scenario(&s);
        run(&mut c, 0..1, PlantStatus::Running, &q0, 0);
        let (t, _) = c.process(&state(1, PlantStatus::SafeStop, &q0, state_flags::REFLEX), &wrench(1, [f64::NAN, 0.0, 0.0]));
        assert_eq!(status(&t), Some(ControllerStatus::Fault));
        // The same tick with a finite wrench is acknowledged.
        let mut c = Controller::from_scenario(&s);
        run(&mut c, 0..1, PlantStatus::Running, &q0, 0);
        let (t, _) = c.process(&state(1, PlantStatus::SafeStop, &q0, state_flags::REFLEX), &wrench(1, [0.0; 3]));
        assert_eq!(status(&t), Some(ControllerStatus::Starting));
    }
}
