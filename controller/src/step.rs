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
use crate::reference::{ReferenceGenerator, ReferenceParams};
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
    /// frame, gains from the design rule, tool pointing down, references from `[trajectory]`.
    pub fn from_scenario(s: &Scenario) -> Controller {
        let law =
            ControlLaw::new(controller_robot(s), TaskFrame::from_scenario(s), Gains::from_scenario(s, f64::NAN), tool_down_rotation());
        Controller {
            law,
            sensing: ForceSensing::from_scenario(s),
            reference: ReferenceGenerator::new(ReferenceParams::from_scenario(s)),
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
    use super::*;

    #[test]
    fn controller_robot_ignores_plant_inertia_scale() {
        let mut s = Scenario::default();
        let a = controller_robot(&s).total_mass_kg();
        s.robot.plant_inertia_scale = 1.1;
        assert_eq!(controller_robot(&s).total_mass_kg(), a);
    }
}
