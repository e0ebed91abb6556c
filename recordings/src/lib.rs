//! Recording rig runs as MCAP files (DESIGN section 8): the record types, the schema and CDR
//! encoder, the writer thread and the live view. This is what the plant links; reading a file
//! back, the report, plots, compare, replay and the miss attribution live in `recording-tools`.
//!
//! The plant hands one fixed-size [`TickRecord`] per tick (and an [`EventRecord`] per event) to a
//! [`Recorder`]: a wait-free push into a bounded single-producer queue; a writer thread encodes the
//! records as ROS 2 messages (CDR, `ros2msg` schemas embedded) into zstd-compressed MCAP chunks.
//! Channels and their fields are listed in `recordings/README.md` and in [`schema`]; what Foxglove
//! draws (URDF, transforms, strip scene, log) in [`scene`]. Log time = the run's wall-clock start +
//! simulated time; publish time = log time.
//!
//! [`synthetic`] writes a run known in closed form through the same [`Recorder`], for the
//! writer's benchmark and the tools' tests.

pub mod cdr;
pub mod live;
pub mod plant_summary;
pub mod run_metadata;
pub mod scene;
pub mod schema;
pub mod synthetic;
mod writer;

pub use live::{LiveConfig, LiveSummary};
pub use plant_summary::PlantSummary;
pub use run_metadata::{RunMetadata, EGM_METADATA_KEY};
pub use writer::{CentreLineFromState, Recorder, RecorderConfig, RecorderError, RecorderTuning, RecordingSummary};

use messages::{ControllerDiagnostics, JointState, JointTorque, Wrench, DOF};

/// Most centre-line nodes a [`StripRecord`] carries (the 0.5 mm mesh of a 40 mm strip has 81).
pub const MAX_CENTRELINE: usize = 256;

/// Longest strip state a [`StripRecord`] carries for the writer thread ([`StripRecord::modal_len`];
/// the default model's has 500: 250 complex modes).
pub const MAX_MODAL_STATE: usize = 512;

/// `/joint_torque.controller_status` of a tick for which no answer arrived (the wire's statuses
/// are 0 to 2, `messages::ControllerStatus`): the torque was held or the safe stop's.
pub const STATUS_NO_ANSWER: u32 = 3;

/// `/joint_torque.answered_tick` before any answer was applied.
pub const NEVER_ANSWERED: u64 = u64::MAX;
/// MCAP header profile of the files this crate writes: ROS 2 channels (`cdr`, `ros2msg`) and
/// Foxglove channels (`protobuf`), log time = the run's wall-clock start + simulated time.
pub const RECORDING_PROFILE: &str = "rig-weatherstrip";

/// Format version of the files this crate writes (metadata `rig/recording_format`).
pub const RECORDING_FORMAT_VERSION: u32 = 2;

/// The 8 magic bytes every MCAP file starts (and a complete one ends) with.
pub const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A host-probe wake-up later than this is a host stall: what the plant's probe counts and
/// time-stamps (`StageStamps::probe_late_ns`), and what the miss attribution of `rig timing` and
/// `rig report` counts as the host's (the controller's wake share of the default 500 µs budget).
pub const HOST_STALL_NS: u64 = 100_000;

/// Everything recorded for one tick. Fixed size and `Copy`, so the plant fills it on the stack and
/// the queue copies it without touching the heap.
#[derive(Debug, Clone, Copy)]
pub struct TickRecord {
    /// The joint state as published for this tick (tick, sim time, q, qd, status, flags, misses).
    pub state: JointState,
    /// The wrench as published for this tick.
    pub wrench: Wrench,
    /// Torque as APPLIED over [t_k, t_k + period) (fresh or held); its `tick` is the tick it answered.
    pub torque: JointTorque,
    /// True if `torque` was held from an earlier tick (late, missing or refused answer).
    pub torque_held: bool,
    /// Controller diagnostics for this tick, valid if `has_diag`.
    pub diag: ControllerDiagnostics,
    pub has_diag: bool,
    pub strip: StripRecord,
    pub timing: TimingRecord,
}

/// Strip outputs of one tick (DESIGN section 4). Task frame: z along the strip.
#[derive(Debug, Clone, Copy)]
pub struct StripRecord {
    /// Wheel position along the strip (task z), m. This is z_a of the force map (5.33).
    pub wheel_z_m: f64,
    /// Force of the wheel on the strip along task y, N: F_e's task-y component, negative when
    /// pressing (messages/README.md, "Frames and signs").
    pub contact_force_n: f64,
    /// Force of the strip on the substrate along task y (the bottom reactions summed, their
    /// opposite), N: negative when pressing, as `contact_force_n`.
    pub bottom_force_n: f64,
    /// Largest bottom pressure on the centre line x = 0, Pa.
    pub max_bottom_pressure_pa: f64,
    /// Normal displacement of the top surface under the wheel, m.
    pub top_displacement_m: f64,
    /// Number of valid entries in `centreline_pressure_pa`.
    pub n_centreline: u32,
    /// Where this tick's centre-line nodes lie along the strip when they move with the wheel (a
    /// windowed long strip, issue 25): node i at `centreline_z0_m + i centreline_dz_m`, m. A
    /// `centreline_dz_m` of 0 (the single model) means the nodes are fixed and their z went once
    /// into the recording's metadata (key `centreline_z_m`). Two scalars rather than a z per
    /// node: the plant's record stays the same fixed size and the writer thread expands them.
    pub centreline_z0_m: f64,
    pub centreline_dz_m: f64,
    /// Bottom pressure at the centre-line nodes (x = 0), ordered by z, Pa. The nodes' z: see
    /// `centreline_z0_m`.
    pub centreline_pressure_pa: [f64; MAX_CENTRELINE],
    /// Normal (task +y) displacement of the top surface's centre line (the bulb's crest, x = 0)
    /// at the same z as `centreline_pressure_pa`, m, bulge included; `n_centreline` valid. Drawn
    /// by the decimated `/strip_scene` only (the per-tick `/strip` schema is unchanged).
    pub top_centreline_uy_m: [f64; MAX_CENTRELINE],
    /// Nonzero: the loop left the centre line (`centreline_pressure_pa`, `top_centreline_uy_m`,
    /// `max_bottom_pressure_pa`) to the writer thread, which computes it from the strip's state
    /// `modal_state[..modal_len]` and the scalars above with the plant's [`CentreLineFromState`]
    /// (issue 22: those n_centreline dot products over the state were a seventh of the lockstep
    /// loop's CPU). Zero: the centre line is filled in.
    pub modal_len: u32,
    pub modal_state: [f64; MAX_MODAL_STATE],
}

/// Loop timing of one tick. Wall-clock times are CLOCK_REALTIME ns since the Unix epoch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TimingRecord {
    /// Wall clock when the plant published this tick's state.
    pub publish_wall_ns: u64,
    /// Wall clock when this tick's torque arrived, 0 if none arrived.
    pub torque_receive_wall_ns: u64,
    /// Receive minus publish, ns (0 if no torque arrived).
    pub round_trip_ns: u64,
    /// Time since the previous publish, ns.
    pub period_ns: u64,
    /// The torque for this tick was late, missing or refused.
    pub missed: bool,
    /// Plant compute time of this tick (integration, contact, strip), ns.
    pub plant_compute_ns: u64,
    /// Controller compute time reported in its diagnostics, ns (0 if none).
    pub controller_compute_ns: u64,
    /// The tick's stage stamps (None in recordings made before they existed).
    pub stages: Option<StageStamps>,
}

/// Where one tick's time went (README, "Timing: whose fault is a miss"). Every `*_ns` stamp is
/// CLOCK_MONOTONIC ns after the tick's deadline (negative = before it), so a plot of them needs no
/// rounding; `deadline_since_start_ns` places the deadline on the run's time line.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageStamps {
    /// The tick's deadline, ns after the run's first deadline.
    pub deadline_since_start_ns: u64,
    /// The wall clock of `publish_wall_ns` / `torque_receive_wall_ns` as µs since the run's start
    /// (a float64 that a plot does not round; 0 when no torque arrived).
    pub publish_since_start_us: f64,
    pub torque_receive_since_start_us: f64,
    /// Whole periods the plant skipped just before this tick (it woke more than a period late).
    pub skipped_periods: u32,
    /// The plant woke from its deadline sleep.
    pub plant_woke_ns: i64,
    /// The plant's state and wrench were published (taken after the publish call; the controller,
    /// notified inside it, may wake before this stamp).
    pub state_published_ns: i64,
    /// The end of the torque budget: the plant waits for the answer until then.
    pub budget_end_ns: i64,
    /// The torque budget from the publish, ns (`loop.torque_budget_us`; lockstep: the watchdog);
    /// `budget_end_ns` is earlier when the next deadline cuts it.
    pub torque_budget_ns: u64,
    /// The plant stopped waiting: the answer arrived (`answered`) or the budget ran out.
    pub torque_received_ns: i64,
    /// The plant finished the tick (integrated; recording follows).
    pub plant_done_ns: i64,
    /// The active controller's torque for this tick arrived within the budget.
    pub answered: bool,
    /// That torque was refused (non-finite, beyond the limits, another contract version).
    pub refused: bool,
    /// The controller's own stamps for this tick came with its answer.
    pub controller: Option<ControllerStamps>,
    /// A late answer's stamps (diagnostics of an earlier tick that arrived during this one), and
    /// that tick; its stamps are relative to THIS tick's deadline.
    pub late: Option<(u64, ControllerStamps)>,
    /// The host-floor probe ran (`rig timing`), and the latest any of its wake-ups was, ns, among
    /// those it finished between the previous tick's end and this one's.
    pub probe: bool,
    pub probe_late_ns: u64,
    /// The deadline that wake-up was late for: the stall ran from here for `probe_late_ns`.
    pub probe_stall_from_ns: i64,
    /// The probe's period, ns (0: not recorded, files before it: a 1 ms probe). The deadline
    /// before `probe_stall_from_ns` was met, so the stall began at most this long before it.
    pub probe_period_ns: u64,
}

/// The controller's stage stamps of one tick, ns after a deadline ([`StageStamps`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ControllerStamps {
    pub woke_ns: i64,
    pub computed_ns: i64,
    pub published_ns: i64,
}

impl ControllerStamps {
    /// From a controller's diagnostics, relative to the deadline `deadline_mono_ns`; None when the
    /// controller did not stamp (its stamps are 0).
    #[inline]
    pub fn from_diag(d: &ControllerDiagnostics, deadline_mono_ns: u64) -> Option<Self> {
        let rel = |t: u64| t as i64 - deadline_mono_ns as i64;
        (d.woke_mono_ns != 0 && d.published_mono_ns != 0).then(|| ControllerStamps {
            woke_ns: rel(d.woke_mono_ns),
            computed_ns: rel(d.computed_mono_ns.max(d.woke_mono_ns)),
            published_ns: rel(d.published_mono_ns),
        })
    }
}

/// What kind of event an [`EventRecord`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum EventKind {
    Start = 0,
    Stop = 1,
    ModeChange = 2,
    ControllerChange = 3,
    /// First miss of a streak.
    Miss = 4,
    SafeStop = 5,
    SafeStopCleared = 6,
    TorqueRefused = 7,
    VersionMismatch = 8,
    RecordingError = 9,
    Fault = 10,
    Info = 11,
    /// A reflex (joint speed, TCP speed, contact force over its limit) put the plant in safe stop.
    Reflex = 12,
    /// A joint entered its mechanical end stop.
    EndStop = 13,
    /// Torques from a publisher that is not the active controller were ignored (once per publisher).
    ForeignTorque = 14,
    /// The controller process ended (reported by the launcher) or its node was found dead.
    ControllerEnded = 15,
    /// The EGM session started (first valid sensor message) or ended (comm_timeout, reflex).
    EgmSession = 16,
    /// An `EgmSensor` message was refused (sequence number, joint or speed limits, malformed).
    EgmRefused = 17,
}

impl EventKind {
    pub const ALL: [EventKind; 18] = [
        Self::Start,
        Self::Stop,
        Self::ModeChange,
        Self::ControllerChange,
        Self::Miss,
        Self::SafeStop,
        Self::SafeStopCleared,
        Self::TorqueRefused,
        Self::VersionMismatch,
        Self::RecordingError,
        Self::Fault,
        Self::Info,
        Self::Reflex,
        Self::EndStop,
        Self::ForeignTorque,
        Self::ControllerEnded,
        Self::EgmSession,
        Self::EgmRefused,
    ];

    pub fn from_u8(v: u8) -> Option<Self> {
        Self::ALL.get(v as usize).copied()
    }

    /// Snake-case name, as written into `/events.kind_name`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Start => "start",
            Self::Stop => "stop",
            Self::ModeChange => "mode_change",
            Self::ControllerChange => "controller_change",
            Self::Miss => "miss",
            Self::SafeStop => "safe_stop",
            Self::SafeStopCleared => "safe_stop_cleared",
            Self::TorqueRefused => "torque_refused",
            Self::VersionMismatch => "version_mismatch",
            Self::RecordingError => "recording_error",
            Self::Fault => "fault",
            Self::Info => "info",
            Self::Reflex => "reflex",
            Self::EndStop => "end_stop",
            Self::ForeignTorque => "foreign_torque",
            Self::ControllerEnded => "controller_ended",
            Self::EgmSession => "egm_session",
            Self::EgmRefused => "egm_refused",
        }
    }
}

/// One EGM cycle of a plant acting as the ABB robot controller (`/egm`, `plant-sim/src/driver/egm`).
/// Angles in ABB's axis convention and degrees where the name says `_deg`, DH rad otherwise.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EgmRecord {
    pub tick: u64,
    pub sim_time_s: f64,
    /// `header.seqno` of the EgmRobot sent this cycle.
    pub robot_seqno: u32,
    /// `header.seqno` of the last accepted EgmSensor (0 before any).
    pub sensor_seqno: u32,
    /// 0 waiting for the sensor, 1 running, 2 stopped.
    pub session_state: u8,
    /// Sensor messages this cycle: taken in all, of them accepted.
    pub replies: u32,
    pub accepted: u32,
    /// The reference in force (last accepted), as received.
    pub joints_ref_deg: [f64; 6],
    pub speed_ref_deg_s: [f64; 6],
    /// The emulated motion controller's servo reference now (after delay and correction), rad.
    pub servo_ref_rad: [f64; 6],
    /// Send → reply taken, ns (0 without a reply this cycle): the sensor's measured lag.
    pub reply_latency_ns: u64,
    /// The motion controller's lag from a reference to the joints, s (its configuration).
    pub servo_lag_s: f64,
}

/// Longest event text kept; longer texts are cut at a character boundary.
pub const EVENT_TEXT_MAX: usize = 192;

/// One event (fault, safe stop, controller change, mode change...). Fixed size, no heap.
#[derive(Debug, Clone, Copy)]
pub struct EventRecord {
    pub tick: u64,
    pub sim_time_s: f64,
    pub kind: EventKind,
    pub text: [u8; EVENT_TEXT_MAX],
    pub text_len: u16,
    /// Wall clock (CLOCK_REALTIME ns) when the event was created (the MCAP stamps are the run's
    /// start + `sim_time_s`, like every message's).
    pub wall_ns: u64,
}

impl EventRecord {
    /// Builds an event, cutting `text` to [`EVENT_TEXT_MAX`] bytes at a character boundary.
    pub fn new(tick: u64, sim_time_s: f64, kind: EventKind, text: &str) -> Self {
        let mut n = text.len().min(EVENT_TEXT_MAX);
        while !text.is_char_boundary(n) {
            n -= 1;
        }
        let mut buf = [0u8; EVENT_TEXT_MAX];
        buf[..n].copy_from_slice(&text.as_bytes()[..n]);
        Self { tick, sim_time_s, kind, text: buf, text_len: n as u16, wall_ns: wall_clock_ns() }
    }

    pub fn text(&self) -> &str {
        // `new` only ever cuts at a character boundary.
        std::str::from_utf8(&self.text[..self.text_len as usize]).unwrap_or("<invalid utf-8>")
    }
}

/// CLOCK_REALTIME in ns since the Unix epoch (vDSO, no syscall on Linux).
pub fn wall_clock_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: ts is a valid timespec to write into.
    unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

impl Default for StripRecord {
    fn default() -> Self {
        Self {
            wheel_z_m: 0.0,
            contact_force_n: 0.0,
            bottom_force_n: 0.0,
            max_bottom_pressure_pa: 0.0,
            top_displacement_m: 0.0,
            n_centreline: 0,
            centreline_z0_m: 0.0,
            centreline_dz_m: 0.0,
            centreline_pressure_pa: [0.0; MAX_CENTRELINE],
            top_centreline_uy_m: [0.0; MAX_CENTRELINE],
            modal_len: 0,
            modal_state: [0.0; MAX_MODAL_STATE],
        }
    }
}

impl StripRecord {
    /// The valid centre-line pressures.
    pub fn centreline(&self) -> &[f64] {
        &self.centreline_pressure_pa[..(self.n_centreline as usize).min(MAX_CENTRELINE)]
    }
}

impl Default for TickRecord {
    /// All zeros, current contract version: the plant overwrites what it has.
    fn default() -> Self {
        let v = messages::CONTRACT_VERSION;
        Self {
            state: JointState {
                contract_version: v,
                plant_status: 0,
                tick: 0,
                sim_time_s: 0.0,
                q: [0.0; DOF],
                qd: [0.0; DOF],
                tau_applied: [0.0; DOF],
                period_s: 0.0,
                flags: 0,
                consecutive_misses: 0,
                total_misses: 0,
            },
            wrench: Wrench { contract_version: v, frame: 0, tick: 0, force: [0.0; 3], torque: [0.0; 3] },
            torque: JointTorque { contract_version: v, controller_status: 0, tick: 0, controller_id: 0, tau: [0.0; DOF] },
            torque_held: false,
            diag: ControllerDiagnostics::zeroed(v),
            has_diag: false,
            strip: StripRecord::default(),
            timing: TimingRecord::default(),
        }
    }
}

/// An error with its sources, `outer: inner: ...` (mcap's I/O error hides the OS error otherwise);
/// the writer's and the live view's messages.
pub(crate) fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cur = c.source();
    }
    s
}

/// Simulated time of a tick in ns: added to the run's wall-clock start, the MCAP log (and publish)
/// time of every message of that tick.
pub fn sim_time_ns(sim_time_s: f64) -> u64 {
    if sim_time_s <= 0.0 || !sim_time_s.is_finite() {
        0
    } else {
        (sim_time_s * 1e9).round() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_text_is_cut_at_a_character_boundary() {
        let long: String = "ä".repeat(150); // 300 bytes, 2 per char
        let e = EventRecord::new(3, 0.003, EventKind::Fault, &long);
        assert_eq!(e.text_len as usize, EVENT_TEXT_MAX);
        assert_eq!(e.text(), &long[..EVENT_TEXT_MAX]);
        let odd = format!("x{}", "ä".repeat(150)); // boundary falls inside a char at 192
        let e = EventRecord::new(3, 0.003, EventKind::Fault, &odd);
        assert_eq!(e.text_len as usize, EVENT_TEXT_MAX - 1);
        assert!(odd.starts_with(e.text()));
    }

    #[test]
    fn event_kinds_round_trip() {
        for k in EventKind::ALL {
            assert_eq!(EventKind::from_u8(k as u8), Some(k));
        }
        assert_eq!(EventKind::from_u8(EventKind::ALL.len() as u8), None);
    }
}
