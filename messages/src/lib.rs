//! The wire contract between `plant-sim` and a controller.
//!
//! Every payload is a `#[repr(C)]` plain-old-data record sent zero-copy over iceoryx2 shared memory
//! (publish-subscribe), with an explicit, language-neutral `#[type_name]`. A peer written in C, C++
//! or Python against iceoryx2's own bindings declares the same structs field for field; the byte
//! layout of each record is pinned by the compile-time assertions at the bottom of this file and
//! documented in `messages/README.md`.
//!
//! Units are SI (m, rad, s, N, N m). Joint quantities are in the order of the DH joints 1..6 of the
//! IRB 2400 (thesis Table 7.1). Every record carries [`CONTRACT_VERSION`] in its first field; a
//! peer with another version is refused (see [`check_version`]).
//!
//! This crate is the contract and nothing else: payloads, their version, the service names and
//! QoS, and the iceoryx2 configuration every peer of a rig loads. Opening the ports, host checks,
//! liveness and the clocks of the rig's own processes are `rig-process`'s.

pub mod qos;
pub mod services;

use iceoryx2::prelude::*;

/// Version of this contract. Bump on any change of layout or meaning.
/// 2: [`ControllerDiagnostics`] carries the controller's stage stamps (woke, computed, published),
/// on the service `controller_diagnostics_v2`.
pub const CONTRACT_VERSION: u32 = 2;

/// The template of the iceoryx2 configuration every peer of a rig loads (`messages/iceoryx2.toml`;
/// `rig_process::host` fills in its per-user values and writes it to the rig's state directory,
/// see messages/README.md, "iceoryx2 configuration"). A peer with other settings does not see
/// the rig's services.
pub const ICEORYX2_CONFIG_TEMPLATE: &str = include_str!("../iceoryx2.toml");

/// Number of robot joints.
pub const DOF: usize = 6;

/// Plant loop state, as reported in [`JointState::plant_status`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PlantStatus {
    /// The plant runs and has not yet received a valid torque from any controller.
    WaitingForController = 0,
    /// Normal operation: the torque of the previous tick arrived in time and was applied.
    Running = 1,
    /// The torque for the previous tick was late, missing or refused; the last good one was held.
    HoldingTorque = 2,
    /// Too many consecutive misses, a controller fault or lost controller, or a reflex: the
    /// plant applies its hold (messages/README.md, "The plant's hold").
    SafeStop = 3,
    /// The plant is shutting down; this is the last state it publishes. Controllers should exit.
    ShuttingDown = 4,
}

impl PlantStatus {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::WaitingForController,
            1 => Self::Running,
            2 => Self::HoldingTorque,
            3 => Self::SafeStop,
            4 => Self::ShuttingDown,
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            Self::WaitingForController => "waiting_for_controller",
            Self::Running => "running",
            Self::HoldingTorque => "holding_torque",
            Self::SafeStop => "safe_stop",
            Self::ShuttingDown => "shutting_down",
        }
    }
}

/// Controller state, as reported in [`JointTorque::controller_status`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControllerStatus {
    /// Normal closed-loop operation.
    Active = 0,
    /// The controller is ramping in after (re)connecting to a running plant.
    Starting = 1,
    /// The controller detected a fault of its own and requests the plant's safe stop.
    Fault = 2,
}

impl ControllerStatus {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Active,
            1 => Self::Starting,
            2 => Self::Fault,
            _ => return None,
        })
    }
}

/// Frame in which [`Wrench`] is expressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum WrenchFrame {
    /// Sensor frame: axes of DH frame 6 (the flange), reference point at the tool centre point.
    /// This is what a flange-mounted 6-axis force/torque sensor reports once its tool offset is set.
    SensorAtTcp = 0,
    /// Base axes, reference point at the tool centre point.
    BaseAtTcp = 1,
}

/// Bit flags in [`JointState::flags`].
pub mod state_flags {
    /// The torque applied over the previous tick was held from an earlier tick (late/missing/refused).
    pub const TORQUE_HELD: u32 = 1 << 0;
    /// The torque for the previous tick was refused (NaN, infinite, out of limits or wrong version).
    pub const TORQUE_REFUSED: u32 = 1 << 1;
    /// The plant is in lockstep mode (waits for every torque).
    pub const LOCKSTEP: u32 = 1 << 2;
    /// The wheel is in contact with the strip.
    pub const IN_CONTACT: u32 = 1 << 3;
    /// The safe stop is latched by a reflex (joint speed, TCP speed or contact force over its
    /// limit): torques are not applied until an answer with `controller_status` = 1 (starting)
    /// acknowledges it.
    pub const REFLEX: u32 = 1 << 4;
    /// A joint is beyond its working range, in its mechanical end stop.
    pub const END_STOP: u32 = 1 << 5;
    /// The force/torque sensor (scenario `[sensor]`) reads beyond its range on some axis: the
    /// wrench is clipped there (an `/events` entry marks the start and the end).
    pub const SENSOR_SATURATED: u32 = 1 << 6;
}

/// Joint state of tick `tick`, published by the plant at the start of the tick (plant → controller).
///
/// `q`, `qd` are the state at simulated time `sim_time_s = tick * period`. The controller answers
/// with a [`JointTorque`] carrying the same `tick`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("rig::JointState")]
#[repr(C)]
pub struct JointState {
    /// [`CONTRACT_VERSION`] of the sender.
    pub contract_version: u32,
    /// [`PlantStatus`] as u32.
    pub plant_status: u32,
    /// Tick number, 0-based, one tick per control period.
    pub tick: u64,
    /// Simulated time of this state, s.
    pub sim_time_s: f64,
    /// Joint positions, rad (DH convention of Table 7.1; ABB's zero is q = (0, -pi/2, 0, 0, 0, 0)).
    pub q: [f64; DOF],
    /// Joint velocities, rad/s.
    pub qd: [f64; DOF],
    /// Torque the plant applied over the previous tick, N m (what the controller's last answer became).
    pub tau_applied: [f64; DOF],
    /// Control period, s (1e-3 at 1 kHz).
    pub period_s: f64,
    /// [`state_flags`] bits.
    pub flags: u32,
    /// Consecutive ticks without a valid, timely torque.
    pub consecutive_misses: u32,
    /// Total ticks without a valid, timely torque since the plant started.
    pub total_misses: u64,
}

impl JointState {
    /// The state of a robot at rest at `q` on tick `tick` of a 1 kHz loop: no velocity, no applied
    /// torque, no flags, no misses (test fixtures, tools that fake a plant).
    pub fn at_rest(tick: u64, status: PlantStatus, q: [f64; DOF]) -> JointState {
        JointState {
            contract_version: CONTRACT_VERSION,
            plant_status: status as u32,
            tick,
            sim_time_s: tick as f64 * 1e-3,
            q,
            qd: [0.0; DOF],
            tau_applied: [0.0; DOF],
            period_s: 1e-3,
            flags: 0,
            consecutive_misses: 0,
            total_misses: 0,
        }
    }
}

/// End-effector wrench of tick `tick`, as a 6-axis force/torque sensor reports it (plant → controller).
///
/// This is the wrench the strip exerts ON the tool, what a wrist sensor measures: −F_e, where F_e
/// (thesis (7.1), the controller's law) is always the wrench the tool exerts on the strip.
/// Pressing the strip down gives a force along +y_task (= +z_base) on the tool.
/// See messages/README.md, "Frames and signs".
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("rig::Wrench")]
#[repr(C)]
pub struct Wrench {
    pub contract_version: u32,
    /// [`WrenchFrame`] as u32.
    pub frame: u32,
    pub tick: u64,
    /// Force on the tool (−F_e), N.
    pub force: [f64; 3],
    /// Torque on the tool about the reference point (−F_e's moment), N m.
    pub torque: [f64; 3],
}

/// Joint torque command answering tick `tick` (controller → plant). Applied over [t_tick, t_tick + period).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("rig::JointTorque")]
#[repr(C)]
pub struct JointTorque {
    pub contract_version: u32,
    /// [`ControllerStatus`] as u32.
    pub controller_status: u32,
    /// The tick of the [`JointState`] this torque answers.
    pub tick: u64,
    /// Identifies one controller process instance (e.g. pid << 32 | start nonce); a change tells the
    /// plant that a different controller took over.
    pub controller_id: u64,
    /// Joint torques, N m.
    pub tau: [f64; DOF],
}

/// Optional controller diagnostics for tick `tick` (controller → plant, recorded on `/controller`).
///
/// Task frame of DESIGN section 3: x = across the strip, y = strip normal (pressing is -y),
/// z = along the strip; origin at the strip's start, bottom centre.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("rig::ControllerDiagnostics")]
#[repr(C)]
pub struct ControllerDiagnostics {
    pub contract_version: u32,
    /// 1 while the force law is active along task y, 0 in pure motion control.
    pub force_control_active: u32,
    pub tick: u64,
    /// Force set-point along task y on the strip (F_r), N (negative = pressing, thesis sign).
    pub force_ref_n: f64,
    /// Measured force on the strip along task y (F_e's task-y component), N (same sign as `force_ref_n`).
    pub force_meas_n: f64,
    /// TCP position reference in the task frame, m (along a contour: path coordinates, lateral,
    /// height, arc length; `scenarios::path`).
    pub pos_ref_task_m: [f64; 3],
    /// TCP position error (reference - actual) in the task frame, m (along a contour: in the
    /// moving frame at the reference's arc length).
    pub pos_err_task_m: [f64; 3],
    /// Orientation error as a rotation vector (log map on SO(3)), task axes (along a contour the
    /// moving frame's), rad.
    pub rot_err_task_rad: [f64; 3],
    /// Integral state of the force loop, N s (0 if no integral action).
    pub force_integral_ns: f64,
    /// Controller compute time for this tick (wake to publish), ns.
    pub compute_time_ns: u64,
    /// Stage stamps of this tick, CLOCK_MONOTONIC ns (the plant's clock on the same host; 0 = not stamped): the
    /// controller woke for this tick's state, finished computing its torque, handed the torque
    /// to iceoryx2 (taken just before this record and the torque are sent). The plant turns them
    /// into offsets from the tick's deadline on `/timing` and attributes misses with them.
    pub woke_mono_ns: u64,
    pub computed_mono_ns: u64,
    pub published_mono_ns: u64,
}

impl ControllerDiagnostics {
    /// All-zero diagnostics of contract version `contract_version` (no force control, no errors):
    /// the value recorded for a tick whose controller published none.
    pub const fn zeroed(contract_version: u32) -> Self {
        ControllerDiagnostics {
            contract_version,
            force_control_active: 0,
            tick: 0,
            force_ref_n: 0.0,
            force_meas_n: 0.0,
            pos_ref_task_m: [0.0; 3],
            pos_err_task_m: [0.0; 3],
            rot_err_task_rad: [0.0; 3],
            force_integral_ns: 0.0,
            compute_time_ns: 0,
            woke_mono_ns: 0,
            computed_mono_ns: 0,
            published_mono_ns: 0,
        }
    }
}

/// Error returned when a peer speaks another contract version.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VersionMismatch {
    pub ours: u32,
    pub theirs: u32,
    pub what: &'static str,
}

impl std::fmt::Display for VersionMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "contract version mismatch on {}: peer speaks version {}, this process speaks version {}",
            self.what, self.theirs, self.ours
        )
    }
}

impl std::error::Error for VersionMismatch {}

/// Refuse a record whose contract version differs from `ours`.
pub fn check_version(ours: u32, theirs: u32, what: &'static str) -> Result<(), VersionMismatch> {
    if ours == theirs {
        Ok(())
    } else {
        Err(VersionMismatch { ours, theirs, what })
    }
}

// Layout pins: a change here is a contract change (bump CONTRACT_VERSION and the README table).
const _: () = {
    use core::mem::{offset_of, size_of};
    assert!(size_of::<JointState>() == 192);
    assert!(offset_of!(JointState, tick) == 8);
    assert!(offset_of!(JointState, q) == 24);
    assert!(offset_of!(JointState, qd) == 72);
    assert!(offset_of!(JointState, tau_applied) == 120);
    assert!(offset_of!(JointState, period_s) == 168);
    assert!(offset_of!(JointState, flags) == 176);
    assert!(offset_of!(JointState, total_misses) == 184);
    assert!(size_of::<Wrench>() == 64);
    assert!(offset_of!(Wrench, force) == 16);
    assert!(size_of::<JointTorque>() == 72);
    assert!(offset_of!(JointTorque, tau) == 24);
    assert!(size_of::<ControllerDiagnostics>() == 144);
    assert!(offset_of!(ControllerDiagnostics, force_ref_n) == 16);
    assert!(offset_of!(ControllerDiagnostics, compute_time_ns) == 112);
    assert!(offset_of!(ControllerDiagnostics, woke_mono_ns) == 120);
    assert!(offset_of!(ControllerDiagnostics, computed_mono_ns) == 128);
    assert!(offset_of!(ControllerDiagnostics, published_mono_ns) == 136);
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_mismatch_names_both_versions() {
        let e = check_version(1, 7, "joint torque").unwrap_err();
        let s = e.to_string();
        assert!(s.contains("version 7") && s.contains("version 1"), "{s}");
        assert!(check_version(3, 3, "x").is_ok());
    }

    #[test]
    fn status_codes_round_trip() {
        for s in [
            PlantStatus::WaitingForController,
            PlantStatus::Running,
            PlantStatus::HoldingTorque,
            PlantStatus::SafeStop,
            PlantStatus::ShuttingDown,
        ] {
            assert_eq!(PlantStatus::from_u32(s as u32), Some(s));
        }
        assert_eq!(PlantStatus::from_u32(99), None);
        assert_eq!(ControllerStatus::from_u32(2), Some(ControllerStatus::Fault));
    }
}
