//! The recording's channels: topic, ROS 2 `.msg` schema (embedded in the file, encoding
//! `ros2msg`), and the CDR encoder/decoder of each, kept side by side so field order cannot drift.
//!
//! Every field is SI (m, s, N, N m, Pa, rad); `tick` is the plant's tick number. Log time of
//! every message is the run's wall-clock start + the simulated time of its tick in ns; publish
//! time is the same.

use crate::cdr::{CdrError, CdrReader, CdrWriter};
use crate::{ControllerStamps, EgmRecord, EventKind, EventRecord, StageStamps, TickRecord, TimingRecord, MAX_CENTRELINE};

use messages::{ControllerDiagnostics, JointState, JointTorque, Wrench, CONTRACT_VERSION};

/// Schema encoding of every channel (MCAP well-known schema encoding).
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// Message encoding of every channel (MCAP well-known message encoding).
pub const MESSAGE_ENCODING: &str = "cdr";

/// One channel of the recording.
#[derive(Debug, Clone, Copy)]
pub struct ChannelDef {
    pub topic: &'static str,
    pub schema_name: &'static str,
    pub schema_text: &'static str,
}

pub const JOINT_STATE: ChannelDef = ChannelDef {
    topic: "/joint_state",
    schema_name: "rig_msgs/msg/JointState",
    schema_text: "\
# Joint state of one tick as the plant published it. DH joints 1..6 of the IRB 2400 (thesis Table 7.1).
uint32 STATUS_WAITING_FOR_CONTROLLER=0
uint32 STATUS_RUNNING=1
uint32 STATUS_HOLDING_TORQUE=2
uint32 STATUS_SAFE_STOP=3
uint32 STATUS_SHUTTING_DOWN=4
uint32 FLAG_TORQUE_HELD=1
uint32 FLAG_TORQUE_REFUSED=2
uint32 FLAG_LOCKSTEP=4
uint32 FLAG_IN_CONTACT=8
uint64 tick                 # tick number, one per control period
float64 sim_time            # s, simulated time of this state (tick * period)
float64[6] q                # rad, joint positions
float64[6] qd               # rad/s, joint velocities
float64[6] tau_applied      # N m, torque applied over the previous tick
float64 period              # s, control period
uint32 plant_status         # STATUS_*
uint32 flags                # FLAG_* bits
uint32 consecutive_misses   # ticks in a row without a valid, timely torque
uint64 total_misses         # ticks without a valid, timely torque since start
",
};

pub const JOINT_TORQUE: ChannelDef = ChannelDef {
    topic: "/joint_torque",
    schema_name: "rig_msgs/msg/JointTorque",
    schema_text: "\
# Joint torque as APPLIED by the plant over [t_tick, t_tick + period).
uint32 CONTROLLER_ACTIVE=0
uint32 CONTROLLER_STARTING=1
uint32 CONTROLLER_FAULT=2
uint32 CONTROLLER_NO_ANSWER=3  # recording only: no answer arrived for this tick
uint64 tick                 # tick whose interval this torque was applied over
uint64 answered_tick        # tick of the state whose answer was last applied (< tick if held; 2^64-1: none yet)
float64[6] tau              # N m, as applied
bool held                   # true if held from an earlier tick (late, missing or refused answer)
uint32 controller_status    # CONTROLLER_*
uint64 controller_id        # identifies the controller process that computed it
bool has_commanded          # the plant recorded the controller's own answer for this tick
float64[6] tau_commanded    # N m, that answer as received (before hold, refusal or blend-in)
",
};

pub const WRENCH: ChannelDef = ChannelDef {
    topic: "/wrench",
    schema_name: "rig_msgs/msg/Wrench",
    schema_text: "\
# Wrench the environment (strip) exerts on the tool, as the 6-axis force/torque sensor reports it.
uint32 FRAME_SENSOR_AT_TCP=0
uint32 FRAME_BASE_AT_TCP=1
uint64 tick
float64[3] force            # N
float64[3] torque           # N m, about the tool centre point
uint32 frame                # FRAME_*: axes of the flange (sensor) or of the base, reference point TCP
",
};

pub const STRIP: ChannelDef = ChannelDef {
    topic: "/strip",
    schema_name: "rig_msgs/msg/Strip",
    schema_text: "\
# Weatherstrip outputs of one tick. Task frame: x across, y up (strip normal), z along the strip.
uint64 tick
float64 wheel_z                 # m, wheel position along the strip (z_a of the force map, thesis 5.33)
float64 contact_force           # N, force of the wheel on the strip
float64 bottom_force            # N, total bottom reaction force
float64 max_bottom_pressure     # Pa, largest bottom pressure on the centre line x = 0
float64 top_displacement        # m, top-surface normal displacement under the wheel
float32[] centreline_pressure   # Pa, bottom pressure at the centre-line nodes (x = 0), by z
float32[] centreline_z          # m, z of those nodes along the strip (single model: the same every tick; windowed long strip: the nodes around the wheel)
",
};

pub const CONTROLLER: ChannelDef = ChannelDef {
    topic: "/controller",
    schema_name: "rig_msgs/msg/ControllerDiagnostics",
    schema_text: "\
# Controller diagnostics of one tick (only ticks for which the controller published them).
# Task frame: x across the strip, y strip normal (pressing is -y), z along the strip.
uint64 tick
bool force_control_active       # force law active along task y
float64 force_ref               # N, force set-point along task y (negative = pressing)
float64 force_meas              # N, measured contact force along task y, same sign
float64[3] pos_ref_task         # m, TCP position reference
float64[3] pos_err_task         # m, TCP position error (reference - actual)
float64[3] rot_err_task         # rad, orientation error as a rotation vector
float64 force_integral          # N s, integral state of the force loop
uint64 compute_time_ns          # ns, controller compute time
",
};

pub const TIMING: ChannelDef = ChannelDef {
    topic: "/timing",
    schema_name: "rig_msgs/msg/Timing",
    schema_text: "\
# Loop timing of one tick. Wall-clock times are CLOCK_REALTIME since the Unix epoch.
uint64 tick
builtin_interfaces/Time publish_stamp   # wall clock at publish (exact in JavaScript)
uint64 publish_wall_ns          # ns, wall clock at publish
uint64 torque_receive_wall_ns   # ns, wall clock when the torque arrived, 0 if none
uint64 round_trip_ns            # ns, receive - publish (0 if none)
uint64 period_ns                # ns, since the previous publish
bool missed                     # torque late, missing or refused
uint64 plant_compute_ns         # ns
uint64 controller_compute_ns    # ns, from the diagnostics (0 if none)
uint64 recorder_dropped         # records the recorder dropped so far (must stay 0)
# Stage stamps (README, Timing): CLOCK_MONOTONIC ns after this tick's deadline (negative =
# before it). Recordings made before them end at recorder_dropped.
bool stamped                    # false: a writer without stamps, the fields below are zero
uint64 deadline_since_start_ns  # ns, this tick's deadline after the run's first one
float64 publish_since_start_us  # us, publish_wall_ns after the run's start (plots without rounding)
float64 torque_receive_since_start_us  # us, torque_receive_wall_ns after the start, 0 if none
uint32 skipped_periods          # periods the plant skipped just before this tick (a stall)
int64 plant_woke_ns             # the plant woke from its deadline sleep
int64 state_published_ns        # state and wrench published, controller notified
int64 budget_end_ns             # the plant waits for the torque until then
uint64 torque_budget_ns         # ns, the torque budget from the publish
int64 torque_received_ns        # the wait ended: torque arrived (answered) or budget over
int64 plant_done_ns             # the plant finished the tick
bool answered                   # the active controller's torque arrived within the budget
bool refused                    # ... and was refused (non-finite, limits, contract version)
bool controller_stamped         # the controller's stamps of this tick came with its answer
int64 controller_woke_ns        # controller woke for this state (0 if not stamped)
int64 controller_computed_ns    # controller finished computing
int64 torque_published_ns       # controller handed the torque to iceoryx2
bool late_stamped               # a late answer's stamps arrived during this tick:
uint64 late_tick                # its tick
int64 late_controller_woke_ns   # its stamps, after THIS tick's deadline
int64 late_controller_computed_ns
int64 late_torque_published_ns
bool probe                      # the host-floor probe ran (rig timing)
uint64 probe_late_ns            # ns, latest probe wake-up finished since the previous tick
int64 probe_stall_from_ns       # the deadline it was late for: the stall ran from here
uint64 probe_period_ns          # ns, the probe's period: the stall began at most this long before
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
",
};

pub const EVENTS: ChannelDef = ChannelDef {
    topic: "/events",
    schema_name: "rig_msgs/msg/Event",
    schema_text: "\
# Faults, safe stops, controller and mode changes, recording errors.
uint8 KIND_START=0
uint8 KIND_STOP=1
uint8 KIND_MODE_CHANGE=2
uint8 KIND_CONTROLLER_CHANGE=3
uint8 KIND_MISS=4
uint8 KIND_SAFE_STOP=5
uint8 KIND_SAFE_STOP_CLEARED=6
uint8 KIND_TORQUE_REFUSED=7
uint8 KIND_VERSION_MISMATCH=8
uint8 KIND_RECORDING_ERROR=9
uint8 KIND_FAULT=10
uint8 KIND_INFO=11
uint8 KIND_REFLEX=12
uint8 KIND_END_STOP=13
uint8 KIND_FOREIGN_TORQUE=14
uint8 KIND_CONTROLLER_ENDED=15
uint8 KIND_EGM_SESSION=16
uint8 KIND_EGM_REFUSED=17
uint64 tick
float64 sim_time                # s
uint8 kind                      # KIND_*
string kind_name
string text
",
};

pub const EGM: ChannelDef = ChannelDef {
    topic: "/egm",
    schema_name: "rig_msgs/msg/EgmCycle",
    schema_text: "\
# One EGM cycle of the plant acting as the ABB robot controller (only in EGM runs).
# Angles: ABB axis convention in degrees where the name ends in _deg, DH joints in rad otherwise.
uint8 SESSION_WAITING=0
uint8 SESSION_RUNNING=1
uint8 SESSION_STOPPED=2
uint64 tick
float64 sim_time                # s
uint32 robot_seqno              # header.seqno of the EgmRobot sent this cycle
uint32 sensor_seqno             # header.seqno of the last accepted EgmSensor (0 before any)
uint8 session_state             # SESSION_*
uint32 replies                  # EgmSensor messages taken this cycle
uint32 accepted                 # of them accepted (the others are in /events)
float64[6] joints_ref_deg       # reference in force, as received
float64[6] speed_ref_deg_s      # speed reference in force, as received (0 if none)
float64[6] servo_ref            # rad, the motion controller's servo reference now
uint64 reply_latency_ns         # ns, EgmRobot sent -> reply taken (0 without a reply)
float64 servo_lag               # s, the motion controller's lag from reference to joints
",
};

/// All channels, in the order the writer registers them; [`Channel`] names each by its index.
pub const CHANNELS: [ChannelDef; 8] = [JOINT_STATE, JOINT_TORQUE, WRENCH, STRIP, CONTROLLER, TIMING, EVENTS, EGM];

/// The ROS 2 channels by name: `Channel::Events.index()` instead of `CHANNELS[6]`. The value is
/// the index in [`CHANNELS`] (the writer's registration order, and the live view's numbering).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    JointState,
    JointTorque,
    Wrench,
    Strip,
    Controller,
    Timing,
    Events,
    /// Only in EGM runs; last, so the others keep their index without it.
    Egm,
}

impl Channel {
    /// Every channel, in [`CHANNELS`] order.
    pub const ALL: [Channel; 8] = [
        Channel::JointState,
        Channel::JointTorque,
        Channel::Wrench,
        Channel::Strip,
        Channel::Controller,
        Channel::Timing,
        Channel::Events,
        Channel::Egm,
    ];

    /// Its index in [`CHANNELS`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Its topic, schema name and schema.
    pub const fn def(self) -> &'static ChannelDef {
        &CHANNELS[self as usize]
    }

    /// The channel at `index` in [`CHANNELS`], None past the end.
    pub fn at(index: usize) -> Option<Channel> {
        Self::ALL.get(index).copied()
    }

    /// The channel with this topic, None: not one of ours.
    pub fn of_topic(topic: &str) -> Option<Channel> {
        Self::ALL.into_iter().find(|c| c.def().topic == topic)
    }
}

// Each name is at its own index with its own topic (a reordering of CHANNELS fails the build).
const _: () = {
    const fn same(a: &str, b: &str) -> bool {
        let (a, b) = (a.as_bytes(), b.as_bytes());
        if a.len() != b.len() {
            return false;
        }
        let mut i = 0;
        while i < a.len() {
            if a[i] != b[i] {
                return false;
            }
            i += 1;
        }
        true
    }
    let topics = [
        (Channel::JointState, JOINT_STATE.topic),
        (Channel::JointTorque, JOINT_TORQUE.topic),
        (Channel::Wrench, WRENCH.topic),
        (Channel::Strip, STRIP.topic),
        (Channel::Controller, CONTROLLER.topic),
        (Channel::Timing, TIMING.topic),
        (Channel::Events, EVENTS.topic),
        (Channel::Egm, EGM.topic),
    ];
    assert!(topics.len() == CHANNELS.len() && Channel::ALL.len() == CHANNELS.len());
    let mut i = 0;
    while i < topics.len() {
        assert!(Channel::ALL[i] as usize == i && topics[i].0 as usize == i && same(topics[i].0.def().topic, topics[i].1));
        i += 1;
    }
};

// ---------------------------------------------------------------------------------------------
// Encoders (writer thread).

/// A [`TickRecord`] without its centre-line pressure array: what the queue carries in full (the
/// pressures follow it as f32, only the valid ones), and what the encoders read.
#[derive(Debug, Clone, Copy)]
pub struct TickHead {
    pub state: JointState,
    pub wrench: Wrench,
    pub torque: JointTorque,
    pub torque_held: bool,
    /// The controller's own answer for this tick, if the plant passed it
    /// ([`crate::Recorder::record_tick_commanded`]).
    pub commanded: Option<[f64; messages::DOF]>,
    pub diag: ControllerDiagnostics,
    pub has_diag: bool,
    pub strip: StripHead,
    pub timing: TimingRecord,
}

/// The scalar part of a [`crate::StripRecord`].
#[derive(Debug, Clone, Copy)]
pub struct StripHead {
    pub wheel_z_m: f64,
    pub contact_force_n: f64,
    pub bottom_force_n: f64,
    pub max_bottom_pressure_pa: f64,
    pub top_displacement_m: f64,
    pub n_centreline: u32,
    /// [`crate::StripRecord::centreline_z0_m`], `centreline_dz_m`: the nodes' z when they move.
    pub centreline_z0_m: f64,
    pub centreline_dz_m: f64,
    /// [`crate::StripRecord::modal_len`]: nonzero until the writer has filled in the centre line.
    pub modal_len: u32,
}

impl TickHead {
    #[inline]
    pub fn of(r: &TickRecord) -> Self {
        let s = &r.strip;
        Self {
            state: r.state,
            wrench: r.wrench,
            torque: r.torque,
            torque_held: r.torque_held,
            commanded: None,
            diag: r.diag,
            has_diag: r.has_diag,
            strip: StripHead {
                wheel_z_m: s.wheel_z_m,
                contact_force_n: s.contact_force_n,
                bottom_force_n: s.bottom_force_n,
                max_bottom_pressure_pa: s.max_bottom_pressure_pa,
                top_displacement_m: s.top_displacement_m,
                n_centreline: (s.n_centreline as usize).min(MAX_CENTRELINE) as u32,
                centreline_z0_m: s.centreline_z0_m,
                centreline_dz_m: s.centreline_dz_m,
                modal_len: (s.modal_len as usize).min(crate::MAX_MODAL_STATE) as u32,
            },
            timing: r.timing,
        }
    }
}

pub fn encode_joint_state(buf: &mut Vec<u8>, r: &TickHead) {
    let s = &r.state;
    let mut w = CdrWriter::new(buf);
    w.u64(s.tick);
    w.f64(s.sim_time_s);
    w.f64_array(&s.q);
    w.f64_array(&s.qd);
    w.f64_array(&s.tau_applied);
    w.f64(s.period_s);
    w.u32(s.plant_status);
    w.u32(s.flags);
    w.u32(s.consecutive_misses);
    w.u64(s.total_misses);
}

pub fn encode_joint_torque(buf: &mut Vec<u8>, r: &TickHead) {
    let mut w = CdrWriter::new(buf);
    w.u64(r.state.tick);
    w.u64(r.torque.tick);
    w.f64_array(&r.torque.tau);
    w.bool(r.torque_held);
    w.u32(r.torque.controller_status);
    w.u64(r.torque.controller_id);
    w.bool(r.commanded.is_some());
    w.f64_array(&r.commanded.unwrap_or([0.0; messages::DOF]));
}

pub fn encode_wrench(buf: &mut Vec<u8>, r: &TickHead) {
    let mut w = CdrWriter::new(buf);
    w.u64(r.state.tick);
    w.f64_array(&r.wrench.force);
    w.f64_array(&r.wrench.torque);
    w.u32(r.wrench.frame);
}

/// `centreline_pressure_pa`: the valid pressures; `centreline_z_m`: the nodes' z, from the
/// metadata (empty if unknown) or, for a windowed strip, this tick's ([`StripHead::centreline_z0_m`]).
pub fn encode_strip(buf: &mut Vec<u8>, r: &TickHead, centreline_pressure_pa: &[f32], centreline_z_m: &[f32]) {
    let s = &r.strip;
    let mut w = CdrWriter::new(buf);
    w.u64(r.state.tick);
    w.f64(s.wheel_z_m);
    w.f64(s.contact_force_n);
    w.f64(s.bottom_force_n);
    w.f64(s.max_bottom_pressure_pa);
    w.f64(s.top_displacement_m);
    w.f32_seq(centreline_pressure_pa.iter().copied());
    w.f32_seq(centreline_z_m.iter().copied());
}

pub fn encode_controller(buf: &mut Vec<u8>, r: &TickHead) {
    let d = &r.diag;
    let mut w = CdrWriter::new(buf);
    w.u64(r.state.tick);
    w.bool(d.force_control_active != 0);
    w.f64(d.force_ref_n);
    w.f64(d.force_meas_n);
    w.f64_array(&d.pos_ref_task_m);
    w.f64_array(&d.pos_err_task_m);
    w.f64_array(&d.rot_err_task_rad);
    w.f64(d.force_integral_ns);
    w.u64(d.compute_time_ns);
}

pub fn encode_timing(buf: &mut Vec<u8>, r: &TickHead, recorder_dropped: u64) {
    let t = &r.timing;
    let mut w = CdrWriter::new(buf);
    w.u64(r.state.tick);
    w.i32((t.publish_wall_ns / 1_000_000_000) as i32);
    w.u32((t.publish_wall_ns % 1_000_000_000) as u32);
    w.u64(t.publish_wall_ns);
    w.u64(t.torque_receive_wall_ns);
    w.u64(t.round_trip_ns);
    w.u64(t.period_ns);
    w.bool(t.missed);
    w.u64(t.plant_compute_ns);
    w.u64(t.controller_compute_ns);
    w.u64(recorder_dropped);
    let g = t.stages.unwrap_or_default();
    w.bool(t.stages.is_some());
    w.u64(g.deadline_since_start_ns);
    w.f64(g.publish_since_start_us);
    w.f64(g.torque_receive_since_start_us);
    w.u32(g.skipped_periods);
    w.i64(g.plant_woke_ns);
    w.i64(g.state_published_ns);
    w.i64(g.budget_end_ns);
    w.u64(g.torque_budget_ns);
    w.i64(g.torque_received_ns);
    w.i64(g.plant_done_ns);
    w.bool(g.answered);
    w.bool(g.refused);
    let c = g.controller.unwrap_or_default();
    w.bool(g.controller.is_some());
    w.i64(c.woke_ns);
    w.i64(c.computed_ns);
    w.i64(c.published_ns);
    let (late_tick, l) = g.late.unwrap_or_default();
    w.bool(g.late.is_some());
    w.u64(late_tick);
    w.i64(l.woke_ns);
    w.i64(l.computed_ns);
    w.i64(l.published_ns);
    w.bool(g.probe);
    w.u64(g.probe_late_ns);
    w.i64(g.probe_stall_from_ns);
    w.u64(g.probe_period_ns);
}

pub fn encode_event(buf: &mut Vec<u8>, e: &EventRecord) {
    let mut w = CdrWriter::new(buf);
    w.u64(e.tick);
    w.f64(e.sim_time_s);
    w.u8(e.kind as u8);
    w.string(e.kind.name());
    w.string(e.text());
}

pub fn encode_egm(buf: &mut Vec<u8>, e: &EgmRecord) {
    let mut w = CdrWriter::new(buf);
    w.u64(e.tick);
    w.f64(e.sim_time_s);
    w.u32(e.robot_seqno);
    w.u32(e.sensor_seqno);
    w.u8(e.session_state);
    w.u32(e.replies);
    w.u32(e.accepted);
    w.f64_array(&e.joints_ref_deg);
    w.f64_array(&e.speed_ref_deg_s);
    w.f64_array(&e.servo_ref_rad);
    w.u64(e.reply_latency_ns);
    w.f64(e.servo_lag_s);
}

pub fn decode_egm(msg: &[u8]) -> Result<EgmRecord, CdrError> {
    let mut r = CdrReader::new(msg)?;
    Ok(EgmRecord {
        tick: r.u64("tick")?,
        sim_time_s: r.f64("sim_time")?,
        robot_seqno: r.u32("robot_seqno")?,
        sensor_seqno: r.u32("sensor_seqno")?,
        session_state: r.u8("session_state")?,
        replies: r.u32("replies")?,
        accepted: r.u32("accepted")?,
        joints_ref_deg: r.f64_array("joints_ref_deg")?,
        speed_ref_deg_s: r.f64_array("speed_ref_deg_s")?,
        servo_ref_rad: r.f64_array("servo_ref")?,
        reply_latency_ns: r.u64("reply_latency_ns")?,
        servo_lag_s: r.f64("servo_lag")?,
    })
}

// ---------------------------------------------------------------------------------------------
// Decoded rows (reader). Wire payload types are reused where the channel carries one whole.

/// A `/joint_torque` message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueRow {
    /// Tick whose interval the torque was applied over.
    pub tick: u64,
    /// The applied torque; `torque.tick` is the tick it answered.
    pub torque: JointTorque,
    pub held: bool,
    /// The controller's own answer for this tick, when the plant recorded it.
    pub commanded: Option<[f64; messages::DOF]>,
}

/// A `/strip` message.
#[derive(Debug, Clone, PartialEq)]
pub struct StripRow {
    pub tick: u64,
    pub wheel_z_m: f64,
    pub contact_force_n: f64,
    pub bottom_force_n: f64,
    pub max_bottom_pressure_pa: f64,
    pub top_displacement_m: f64,
    /// Pa, by centre-line node (stored as f32: a 0.1 Pa resolution is ample against 100 kPa).
    /// Their z: `recording_tools::read::Recording::centreline_z_m`.
    pub centreline_pressure_pa: Vec<f32>,
}

/// A `/timing` message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimingRow {
    pub tick: u64,
    pub timing: TimingRecord,
    /// Records the recorder had dropped when it wrote this tick.
    pub recorder_dropped: u64,
}

/// An `/events` message.
#[derive(Debug, Clone, PartialEq)]
pub struct EventRow {
    pub tick: u64,
    pub sim_time_s: f64,
    /// `None` for a kind this version does not know (a newer writer).
    pub kind: Option<EventKind>,
    pub kind_name: String,
    pub text: String,
    /// MCAP publish time, ns: the run's wall-clock start + the event's simulated time.
    pub wall_ns: u64,
}

pub fn decode_joint_state(msg: &[u8]) -> Result<JointState, CdrError> {
    let mut r = CdrReader::new(msg)?;
    Ok(JointState {
        contract_version: CONTRACT_VERSION,
        tick: r.u64("tick")?,
        sim_time_s: r.f64("sim_time")?,
        q: r.f64_array("q")?,
        qd: r.f64_array("qd")?,
        tau_applied: r.f64_array("tau_applied")?,
        period_s: r.f64("period")?,
        plant_status: r.u32("plant_status")?,
        flags: r.u32("flags")?,
        consecutive_misses: r.u32("consecutive_misses")?,
        total_misses: r.u64("total_misses")?,
    })
}

pub fn decode_joint_torque(msg: &[u8]) -> Result<TorqueRow, CdrError> {
    let mut r = CdrReader::new(msg)?;
    let tick = r.u64("tick")?;
    let answered = r.u64("answered_tick")?;
    let tau = r.f64_array("tau")?;
    let held = r.bool("held")?;
    let controller_status = r.u32("controller_status")?;
    let controller_id = r.u64("controller_id")?;
    let has_commanded = r.bool("has_commanded")?;
    let commanded: [f64; messages::DOF] = r.f64_array("tau_commanded")?;
    Ok(TorqueRow {
        tick,
        torque: JointTorque { contract_version: CONTRACT_VERSION, controller_status, tick: answered, controller_id, tau },
        held,
        commanded: has_commanded.then_some(commanded),
    })
}

pub fn decode_wrench(msg: &[u8]) -> Result<Wrench, CdrError> {
    let mut r = CdrReader::new(msg)?;
    let tick = r.u64("tick")?;
    let force = r.f64_array("force")?;
    let torque = r.f64_array("torque")?;
    let frame = r.u32("frame")?;
    Ok(Wrench { contract_version: CONTRACT_VERSION, frame, tick, force, torque })
}

/// Decodes a `/strip` message; its `centreline_z` (the same every tick for the single model,
/// moving with the wheel on a windowed strip) only if `want_z`.
pub fn decode_strip(msg: &[u8], want_z: bool) -> Result<(StripRow, Option<Vec<f32>>), CdrError> {
    let mut r = CdrReader::new(msg)?;
    let row = StripRow {
        tick: r.u64("tick")?,
        wheel_z_m: r.f64("wheel_z")?,
        contact_force_n: r.f64("contact_force")?,
        bottom_force_n: r.f64("bottom_force")?,
        max_bottom_pressure_pa: r.f64("max_bottom_pressure")?,
        top_displacement_m: r.f64("top_displacement")?,
        centreline_pressure_pa: r.f32_seq("centreline_pressure")?,
    };
    let z = if want_z { Some(r.f32_seq("centreline_z")?) } else { None };
    Ok((row, z))
}

pub fn decode_controller(msg: &[u8]) -> Result<ControllerDiagnostics, CdrError> {
    let mut r = CdrReader::new(msg)?;
    let tick = r.u64("tick")?;
    let active = r.bool("force_control_active")?;
    Ok(ControllerDiagnostics {
        contract_version: CONTRACT_VERSION,
        force_control_active: active as u32,
        tick,
        force_ref_n: r.f64("force_ref")?,
        force_meas_n: r.f64("force_meas")?,
        pos_ref_task_m: r.f64_array("pos_ref_task")?,
        pos_err_task_m: r.f64_array("pos_err_task")?,
        rot_err_task_rad: r.f64_array("rot_err_task")?,
        force_integral_ns: r.f64("force_integral")?,
        compute_time_ns: r.u64("compute_time_ns")?,
        // The stage stamps go to /timing, as offsets from the tick's deadline.
        woke_mono_ns: 0,
        computed_mono_ns: 0,
        published_mono_ns: 0,
    })
}

pub fn decode_timing(msg: &[u8]) -> Result<TimingRow, CdrError> {
    let mut r = CdrReader::new(msg)?;
    let tick = r.u64("tick")?;
    let _sec = r.i32("publish_stamp.sec")?;
    let _nanosec = r.u32("publish_stamp.nanosec")?;
    let timing = TimingRecord {
        publish_wall_ns: r.u64("publish_wall_ns")?,
        torque_receive_wall_ns: r.u64("torque_receive_wall_ns")?,
        round_trip_ns: r.u64("round_trip_ns")?,
        period_ns: r.u64("period_ns")?,
        missed: r.bool("missed")?,
        plant_compute_ns: r.u64("plant_compute_ns")?,
        controller_compute_ns: r.u64("controller_compute_ns")?,
        stages: None,
    };
    let recorder_dropped = r.u64("recorder_dropped")?;
    let mut timing = timing;
    if !r.at_end() {
        let stamped = r.bool("stamped")?;
        let stages = decode_stages(&mut r)?;
        timing.stages = stamped.then_some(stages);
    }
    Ok(TimingRow { tick, timing, recorder_dropped })
}

/// The host probe's period in files written before `/timing` carried it (the first probe).
pub const LEGACY_PROBE_PERIOD_NS: u64 = 1_000_000;

fn decode_stages(r: &mut CdrReader) -> Result<StageStamps, CdrError> {
    let mut g = StageStamps {
        deadline_since_start_ns: r.u64("deadline_since_start_ns")?,
        publish_since_start_us: r.f64("publish_since_start_us")?,
        torque_receive_since_start_us: r.f64("torque_receive_since_start_us")?,
        skipped_periods: r.u32("skipped_periods")?,
        plant_woke_ns: r.i64("plant_woke_ns")?,
        state_published_ns: r.i64("state_published_ns")?,
        budget_end_ns: r.i64("budget_end_ns")?,
        torque_budget_ns: r.u64("torque_budget_ns")?,
        torque_received_ns: r.i64("torque_received_ns")?,
        plant_done_ns: r.i64("plant_done_ns")?,
        answered: r.bool("answered")?,
        refused: r.bool("refused")?,
        ..StageStamps::default()
    };
    let stamped = r.bool("controller_stamped")?;
    let c = ControllerStamps {
        woke_ns: r.i64("controller_woke_ns")?,
        computed_ns: r.i64("controller_computed_ns")?,
        published_ns: r.i64("torque_published_ns")?,
    };
    g.controller = stamped.then_some(c);
    let late = r.bool("late_stamped")?;
    let late_tick = r.u64("late_tick")?;
    let l = ControllerStamps {
        woke_ns: r.i64("late_controller_woke_ns")?,
        computed_ns: r.i64("late_controller_computed_ns")?,
        published_ns: r.i64("late_torque_published_ns")?,
    };
    g.late = late.then_some((late_tick, l));
    g.probe = r.bool("probe")?;
    g.probe_late_ns = r.u64("probe_late_ns")?;
    g.probe_stall_from_ns = r.i64("probe_stall_from_ns")?;
    // Files written before the field: the probe ran at the 1 ms period then.
    g.probe_period_ns = if r.at_end() { LEGACY_PROBE_PERIOD_NS } else { r.u64("probe_period_ns")? };
    Ok(g)
}

pub fn decode_event(msg: &[u8], wall_ns: u64) -> Result<EventRow, CdrError> {
    let mut r = CdrReader::new(msg)?;
    let tick = r.u64("tick")?;
    let sim_time_s = r.f64("sim_time")?;
    let kind = EventKind::from_u8(r.u8("kind")?);
    Ok(EventRow { tick, sim_time_s, kind, kind_name: r.string("kind_name")?, text: r.string("text")?, wall_ns })
}

/// The metadata's `centreline_z_m` (m) as the `/strip` channel carries it (f32), checked against
/// [`MAX_CENTRELINE`].
pub fn centreline_z_f32(z: &[f64]) -> Result<Vec<f32>, String> {
    if z.len() > MAX_CENTRELINE {
        return Err(format!("metadata centreline_z_m has {} entries, at most {MAX_CENTRELINE} allowed", z.len()));
    }
    Ok(z.iter().map(|&v| v as f32).collect())
}

/// Parses a flat JSON array of numbers exactly (Rust's float parsing is correctly rounded, so a
/// value written with `{:?}` or by serde_json comes back bit for bit).
pub fn parse_f64_list(json: &str) -> Result<Vec<f64>, String> {
    let inner = json
        .trim()
        .strip_prefix('[')
        .and_then(|s| s.strip_suffix(']'))
        .ok_or_else(|| format!("expected [..], found {:?}", json.chars().take(40).collect::<String>()))?;
    if inner.trim().is_empty() {
        return Ok(Vec::new());
    }
    inner.split(',').map(|v| v.trim().parse::<f64>().map_err(|e| format!("{:?}: {e}", v.trim()))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::EventKind;

    fn sample() -> TickRecord {
        let mut r = TickRecord::default();
        r.state.tick = 41;
        r.state.sim_time_s = 0.041;
        r.state.q = [0.1, -1.2, 0.3, 0.4, -0.5, 0.6];
        r.state.qd = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        r.state.tau_applied = [-1.0, -2.0, -3.0, -4.0, -5.0, -6.0];
        r.state.period_s = 1e-3;
        r.state.plant_status = 2;
        r.state.flags = 0b1011;
        r.state.consecutive_misses = 3;
        r.state.total_misses = 17;
        r.torque.tick = 40;
        r.torque.tau = [9.0, 8.0, 7.0, 6.0, 5.0, 4.0];
        r.torque.controller_id = (1234 << 32) | 5;
        r.torque.controller_status = 1;
        r.torque_held = true;
        r.wrench.tick = 41;
        r.wrench.force = [0.5, -10.0, 0.25];
        r.wrench.torque = [0.01, 0.02, -0.03];
        r.wrench.frame = 1;
        r.diag.tick = 41;
        r.diag.force_control_active = 1;
        r.diag.force_ref_n = -10.0;
        r.diag.force_meas_n = -9.7;
        r.diag.pos_ref_task_m = [0.0, 0.004, 0.012];
        r.diag.pos_err_task_m = [1e-6, -2e-6, 3e-6];
        r.diag.rot_err_task_rad = [1e-4, 2e-4, 3e-4];
        r.diag.force_integral_ns = 0.25;
        r.diag.compute_time_ns = 12_345;
        r.strip.wheel_z_m = 0.012;
        r.strip.contact_force_n = 10.1;
        r.strip.bottom_force_n = -9.9;
        r.strip.max_bottom_pressure_pa = 123_456.5;
        r.strip.top_displacement_m = -4.2e-4;
        r.strip.n_centreline = 3;
        r.strip.centreline_pressure_pa[..3].copy_from_slice(&[1.5, 100_000.25, 2.0]);
        r.timing = TimingRecord {
            publish_wall_ns: 1_763_779_200_123_456_789,
            torque_receive_wall_ns: 1_763_779_200_123_500_000,
            round_trip_ns: 43_211,
            period_ns: 1_000_020,
            missed: true,
            plant_compute_ns: 80_000,
            controller_compute_ns: 12_345,
            stages: Some(StageStamps {
                deadline_since_start_ns: 41_000_123,
                publish_since_start_us: 41_012.5,
                torque_receive_since_start_us: 41_556.25,
                skipped_periods: 3,
                plant_woke_ns: 2_100,
                state_published_ns: 9_800,
                budget_end_ns: 509_800,
                torque_budget_ns: 500_000,
                torque_received_ns: 509_900,
                plant_done_ns: 540_000,
                answered: false,
                refused: true,
                controller: Some(ControllerStamps { woke_ns: 20_000, computed_ns: 30_000, published_ns: 31_000 }),
                late: Some((39, ControllerStamps { woke_ns: -1_900_000, computed_ns: -1_100_000, published_ns: -1_099_000 })),
                probe: true,
                probe_late_ns: 250_000,
                probe_stall_from_ns: -400_000,
                probe_period_ns: 250_000,
            }),
        };
        r
    }

    #[test]
    fn every_channel_round_trips_field_for_field() {
        let full = sample();
        let r = TickHead::of(&full);
        let p: Vec<f32> = full.strip.centreline().iter().map(|&p| p as f32).collect();
        let mut buf = Vec::new();
        encode_joint_state(&mut buf, &r);
        assert_eq!(decode_joint_state(&buf).unwrap(), r.state);
        encode_joint_torque(&mut buf, &r);
        assert_eq!(decode_joint_torque(&buf).unwrap(), TorqueRow { tick: 41, torque: r.torque, held: true, commanded: None });
        let mut with_cmd = r;
        with_cmd.commanded = Some([1.5, -2.5, 3.5, -4.5, 5.5, -6.5]);
        encode_joint_torque(&mut buf, &with_cmd);
        assert_eq!(decode_joint_torque(&buf).unwrap().commanded, with_cmd.commanded);
        encode_wrench(&mut buf, &r);
        assert_eq!(decode_wrench(&buf).unwrap(), r.wrench);
        encode_controller(&mut buf, &r);
        assert_eq!(decode_controller(&buf).unwrap(), r.diag);
        encode_timing(&mut buf, &r, 7);
        assert_eq!(decode_timing(&buf).unwrap(), TimingRow { tick: 41, timing: r.timing, recorder_dropped: 7 });
        // One written before the probe's period was (ends at probe_stall_from_ns): a 1 ms probe.
        buf.truncate(buf.len() - 8);
        let legacy = decode_timing(&buf).unwrap().timing.stages.unwrap();
        assert_eq!(legacy.probe_period_ns, LEGACY_PROBE_PERIOD_NS);
        assert_eq!(legacy, StageStamps { probe_period_ns: LEGACY_PROBE_PERIOD_NS, ..r.timing.stages.unwrap() });
        // A message of the schema before the stage stamps (ends at recorder_dropped) still reads.
        let mut old = r;
        old.timing.stages = None;
        encode_timing(&mut buf, &old, 7);
        buf.truncate(4 + 8 + 8 + 8 * 4 + 1 + 7 + 8 * 3);
        assert_eq!(decode_timing(&buf).unwrap(), TimingRow { tick: 41, timing: old.timing, recorder_dropped: 7 });
        // publish_stamp: sec + nanosec reassemble the wall clock exactly.
        let sec = i32::from_le_bytes(buf[12..16].try_into().unwrap()) as u64;
        let nsec = u32::from_le_bytes(buf[16..20].try_into().unwrap()) as u64;
        assert_eq!(sec * 1_000_000_000 + nsec, r.timing.publish_wall_ns);
        encode_strip(&mut buf, &r, &p, &[0.001, 0.002, 0.003]);
        let (s, z) = decode_strip(&buf, true).unwrap();
        assert_eq!(s.tick, 41);
        assert_eq!(s.wheel_z_m, 0.012);
        assert_eq!(s.max_bottom_pressure_pa, 123_456.5);
        assert_eq!(s.centreline_pressure_pa, vec![1.5, 100_000.25, 2.0]);
        assert_eq!(z.unwrap(), vec![0.001, 0.002, 0.003]);
        let e = EventRecord::new(41, 0.041, EventKind::SafeStop, "20 misses in a row");
        encode_event(&mut buf, &e);
        let d = decode_event(&buf, e.wall_ns).unwrap();
        assert_eq!(
            (d.tick, d.kind, d.kind_name.as_str(), d.text.as_str()),
            (41, Some(EventKind::SafeStop), "safe_stop", "20 misses in a row")
        );
    }

    #[test]
    fn schema_fields_are_in_encoder_order() {
        // Field names of each schema (constants and comments stripped) against the names the
        // decoders ask for, read off the encoded layout: a renamed or reordered field fails here.
        let fields = |text: &str| -> Vec<String> {
            text.lines()
                .take_while(|l| !l.starts_with("====="))
                .map(|l| l.split('#').next().unwrap().trim())
                .filter(|l| !l.is_empty() && !l.contains('='))
                .map(|l| l.split_whitespace().nth(1).unwrap().to_string())
                .collect()
        };
        assert_eq!(
            fields(JOINT_STATE.schema_text),
            ["tick", "sim_time", "q", "qd", "tau_applied", "period", "plant_status", "flags", "consecutive_misses", "total_misses"]
        );
        assert_eq!(
            fields(JOINT_TORQUE.schema_text),
            ["tick", "answered_tick", "tau", "held", "controller_status", "controller_id", "has_commanded", "tau_commanded"]
        );
        assert_eq!(fields(WRENCH.schema_text), ["tick", "force", "torque", "frame"]);
        assert_eq!(
            fields(STRIP.schema_text),
            [
                "tick",
                "wheel_z",
                "contact_force",
                "bottom_force",
                "max_bottom_pressure",
                "top_displacement",
                "centreline_pressure",
                "centreline_z"
            ]
        );
        assert_eq!(fields(EVENTS.schema_text), ["tick", "sim_time", "kind", "kind_name", "text"]);
        assert_eq!(
            fields(TIMING.schema_text),
            [
                "tick",
                "publish_stamp",
                "publish_wall_ns",
                "torque_receive_wall_ns",
                "round_trip_ns",
                "period_ns",
                "missed",
                "plant_compute_ns",
                "controller_compute_ns",
                "recorder_dropped",
                "stamped",
                "deadline_since_start_ns",
                "publish_since_start_us",
                "torque_receive_since_start_us",
                "skipped_periods",
                "plant_woke_ns",
                "state_published_ns",
                "budget_end_ns",
                "torque_budget_ns",
                "torque_received_ns",
                "plant_done_ns",
                "answered",
                "refused",
                "controller_stamped",
                "controller_woke_ns",
                "controller_computed_ns",
                "torque_published_ns",
                "late_stamped",
                "late_tick",
                "late_controller_woke_ns",
                "late_controller_computed_ns",
                "late_torque_published_ns",
                "probe",
                "probe_late_ns",
                "probe_stall_from_ns",
                "probe_period_ns"
            ]
        );
        for k in EventKind::ALL {
            let line = format!("uint8 KIND_{}={}", k.name().to_uppercase(), k as u8);
            assert!(EVENTS.schema_text.contains(&line), "missing {line}");
        }
    }

    #[test]
    fn centreline_z_metadata_is_checked() {
        assert_eq!(centreline_z_f32(&[0.001, 0.0015]).unwrap(), vec![0.001f32, 0.0015]);
        assert!(centreline_z_f32(&[0.0; MAX_CENTRELINE + 1]).unwrap_err().contains("centreline_z_m"));
    }
}
