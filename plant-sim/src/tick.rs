//! One plant tick as a value: [`PlantTick`] holds the physics, the torque gate and the limits
//! between ticks. [`PlantTick::outputs`] gives the tick's joint state and wrench (what the plant
//! publishes); [`PlantTick::advance`] applies the torque received for it (or none) through the
//! gate, integrates the tick, checks the reflexes and end stops and gives what was applied and
//! the strip record. The real-time loop (`loop_rt.rs`), the lockstep loop (`loop_lockstep.rs`),
//! `rig run --in-process` and `rig sweep` drive this one type: the loops add only pacing, ports
//! and the recorder hand-off.
//!
//! Per tick: no allocation (`tests/tests/no_alloc.rs` counts), no lock; rare events (miss streak, safe stop, reflex, end stop,
//! refusal, controller change) go to the recorder's wait-free queue and, rate-limited, the log.

use std::fmt::Write as _;

use messages::{state_flags, ControllerDiagnostics, JointState, JointTorque, PlantStatus, Wrench, WrenchFrame, CONTRACT_VERSION};
use scenarios::{Mode, Scenario};

use crate::gate::{Decision, Gate, GateConfig};
use crate::limits::ReflexLimits;
use crate::physics::Physics;
use crate::recording::{EventKind, EventRecord, Recorder, StripRecord, TickRecord, TimingRecord};
use crate::stack_text::StackText;

/// What one [`PlantTick::advance`] applied and measured.
#[derive(Debug, Clone, Copy)]
pub struct TickOutcome {
    /// The gate's decision (torque applied, held, missed, refused, events).
    pub decision: Decision,
    /// The torque as applied over the tick, as recorded: its `tick` is the answered state's.
    pub applied: JointTorque,
    /// The strip after the tick was integrated (as recorded with the tick).
    pub strip: StripRecord,
}

/// The first tick of a safe stop, a reflex, a refused torque (the exit status' story).
#[derive(Debug, Clone, Copy, Default)]
pub struct FirstTicks {
    pub safe_stop: Option<u64>,
    pub reflex: Option<u64>,
    pub refusal: Option<u64>,
}

/// Queue slots a lockstep tick waits for before it advances: its tick record and the events one
/// tick can raise (a decision's, a reflex's, an end stop's) with room to spare.
const LOCKSTEP_RECORD_SLOTS: usize = 16;
/// The longest a lockstep tick waits for the writer; after that the record is a counted drop
/// (a writer that no longer drains its queue must not hang the run).
const LOCKSTEP_RECORD_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// The plant between ticks: physics, gate, limits and what the next state reports.
pub struct PlantTick {
    physics: Physics,
    gate: Gate,
    reflex_limits: ReflexLimits,
    lockstep: bool,
    period_ns: u64,
    /// The tick whose state [`PlantTick::outputs`] gives next.
    tick: u64,
    /// The last tick's decision (the next state's held/refused flags).
    prev: Option<Decision>,
    /// Tick of the state whose answer was last applied (`/joint_torque.answered_tick`).
    applied_answer_tick: u64,
    in_end_stop: Option<usize>,
    /// Tick of the last miss/refusal log line (rate limit: one per second of ticks).
    last_log_tick: Option<u64>,
    first: FirstTicks,
    strip: StripRecord,
    /// `[sensor]`: the force/torque sensor's chain and this tick's reading (None: exact wrench).
    sensor: Option<Sensor>,
    /// `[drives]` with encoders: what the state reports as q and q̇ (None: exact).
    encoders: Option<crate::drives::Encoders>,
}

/// The cell's sensor between ticks: its chain, the tool's load on it and the current reading.
struct Sensor {
    chain: crate::sensor::SensorChain,
    load: crate::sensor::ToolLoad,
    reading: [f64; 6],
    saturated: bool,
}

impl Sensor {
    /// Read the sensor at the physics' current state (one sample of the chain).
    fn read(&mut self, physics: &Physics) {
        // One forward kinematics for the contact wrench's axes and the tool's load.
        let frames = physics.robot().frames(&physics.q());
        let (f, m) = physics.wrench_on_tool_at(&frames.rot[6]);
        let load = self.load.sample_at(physics.robot(), &frames, &physics.qd());
        let input = std::array::from_fn(|i| if i < 3 { f[i] } else { m[i - 3] } + load[i]);
        (self.reading, self.saturated) = self.chain.sample(&input);
    }
}

impl PlantTick {
    /// The plant of a scenario around `physics` (built from the same scenario), at tick 0,
    /// waiting for a controller. `mode` is what the states' LOCKSTEP flag says.
    pub fn new(s: &Scenario, physics: Physics, mode: Mode) -> PlantTick {
        let l = &s.loop_;
        let gate = Gate::new(GateConfig {
            max_consecutive_misses: l.max_consecutive_misses,
            blend_ticks: (l.takeover_blend_s / l.period_s).round() as u32,
            safe_stop_damping_nms: crate::gate::safe_stop_damping(
                l.safe_stop_damping_nms,
                &physics.robot().mass_matrix(&physics.q()).diagonal(),
                l.period_s,
            ),
            torque_limit_nm: robot::Robot::TORQUE_LIMIT_NM,
        });
        let period_s = l.period_s;
        let sensor = s.sensor.enabled.then(|| {
            let mut sensor = Sensor {
                chain: crate::sensor::SensorChain::new(&s.sensor, period_s),
                load: crate::sensor::ToolLoad::new(physics.robot(), period_s),
                reading: [0.0; 6],
                saturated: false,
            };
            sensor.read(&physics);
            sensor
        });
        let encoders = (s.drives.enabled
            && (s.drives.encoder_counts_per_rev.iter().any(|&c| c > 0.0) || s.drives.velocity_filter_hz > 0.0))
            .then(|| crate::drives::Encoders::new(&s.drives, period_s, &physics.q()));
        PlantTick {
            sensor,
            encoders,
            physics,
            gate,
            reflex_limits: ReflexLimits::from_scenario(s),
            lockstep: mode == Mode::Lockstep,
            period_ns: (l.period_s * 1e9).round() as u64,
            tick: 0,
            prev: None,
            applied_answer_tick: recordings::NEVER_ANSWERED,
            in_end_stop: None,
            last_log_tick: None,
            first: FirstTicks::default(),
            strip: StripRecord::default(),
        }
    }

    /// [`PlantTick::new`] with the scenario's physics (`cache_dir`: the strip model cache).
    pub fn from_scenario(s: &Scenario, cache_dir: &std::path::Path, mode: Mode) -> anyhow::Result<PlantTick> {
        Ok(PlantTick::new(s, Physics::new(s, cache_dir)?, mode))
    }

    pub fn physics(&self) -> &Physics {
        &self.physics
    }
    pub fn gate(&self) -> &Gate {
        &self.gate
    }
    /// The tick whose state [`PlantTick::outputs`] gives.
    pub fn tick(&self) -> u64 {
        self.tick
    }
    pub fn first_ticks(&self) -> FirstTicks {
        self.first
    }
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }
    /// Simulated time of the current state, s.
    pub fn sim_time_s(&self) -> f64 {
        self.tick as f64 * self.period_ns as f64 * 1e-9
    }

    /// The state and wrench of the current tick, as published.
    pub fn outputs(&self) -> (JointState, Wrench) {
        (self.state(), self.wrench())
    }

    fn state(&self) -> JointState {
        let mut flags = 0;
        if let Some(d) = self.prev.as_ref() {
            if d.held {
                flags |= state_flags::TORQUE_HELD;
            }
            if d.refused.is_some() {
                flags |= state_flags::TORQUE_REFUSED;
            }
        }
        if self.lockstep {
            flags |= state_flags::LOCKSTEP;
        }
        if self.physics.in_contact() {
            flags |= state_flags::IN_CONTACT;
        }
        if self.gate.reflex_latched() {
            flags |= state_flags::REFLEX;
        }
        if self.physics.limits().joint_in_end_stop(&self.physics.q()).is_some() {
            flags |= state_flags::END_STOP;
        }
        if self.sensor.as_ref().is_some_and(|s| s.saturated) {
            flags |= state_flags::SENSOR_SATURATED;
        }
        let (q, qd) = match &self.encoders {
            Some(e) => (e.q(), e.qd()),
            None => (self.physics.q(), self.physics.qd()),
        };
        JointState {
            contract_version: CONTRACT_VERSION,
            plant_status: self.gate.status() as u32,
            tick: self.tick,
            sim_time_s: self.sim_time_s(),
            q: q.into(),
            qd: qd.into(),
            tau_applied: self.gate.last_applied().into(),
            period_s: self.period_ns as f64 * 1e-9,
            flags,
            consecutive_misses: self.gate.consecutive_misses(),
            total_misses: self.gate.total_misses(),
        }
    }

    fn wrench(&self) -> Wrench {
        let (force, torque) = match &self.sensor {
            Some(s) => ([s.reading[0], s.reading[1], s.reading[2]], [s.reading[3], s.reading[4], s.reading[5]]),
            None => self.physics.wrench_on_tool(),
        };
        Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::SensorAtTcp as u32, tick: self.tick, force, torque }
    }

    /// The last state of a run: the current one, status `ShuttingDown` (controllers exit on it).
    pub fn goodbye(&self) -> (JointState, Wrench) {
        let mut last = self.state();
        last.plant_status = PlantStatus::ShuttingDown as u32;
        (last, self.wrench())
    }

    /// The active controller is gone (its process ended or its node is dead) and nobody took
    /// over: safe stop now. Returns true if the plant entered it (recorded in `/events`).
    pub fn controller_gone(&mut self, recorder: Option<&mut Recorder>) -> bool {
        let entered = self.gate.controller_gone();
        if entered {
            let tick = self.tick;
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: safe stop: the controller is gone (gravity compensation + joint damping)");
            event(recorder, tick, self.sim_time_s(), EventKind::SafeStop, s.as_str());
            self.first.safe_stop.get_or_insert(tick);
        }
        entered
    }

    /// Apply `torque` (this tick's answer, None if none came in time) through the gate,
    /// integrate the tick, check reflexes and end stops of the new state, and move on to the
    /// next tick.
    pub fn advance(&mut self, torque: Option<&JointTorque>, mut recorder: Option<&mut Recorder>) -> TickOutcome {
        // Lockstep has no deadline: wait for the writer (on a loaded host it falls behind a plant
        // running 30x real time) instead of dropping this tick's record and events.
        if let Some(r) = recorder.as_deref().filter(|_| self.lockstep) {
            r.wait_for_room(LOCKSTEP_RECORD_SLOTS, LOCKSTEP_RECORD_WAIT);
        }
        let tick = self.tick;
        let t = self.sim_time_s();
        let decision = self.gate.decide(torque, &self.physics.gravity_torque(), &self.physics.qd());
        if decision.events.safe_stop_entered {
            self.first.safe_stop.get_or_insert(tick);
        }
        if decision.refused.is_some() {
            self.first.refusal.get_or_insert(tick);
        }
        let prev_refused = self.prev.as_ref().is_some_and(|d| d.refused.is_some());
        self.report(tick, t, &decision, prev_refused, recorder.as_deref_mut());
        self.physics.step_tick(&decision.tau);
        let t_next = t + self.period_ns as f64 * 1e-9;
        self.read_sensors(tick + 1, t_next, recorder.as_deref_mut());
        self.check_limits(tick + 1, t_next, recorder);
        self.physics.fill_strip_record(&mut self.strip);
        if let Some(a) = torque.filter(|_| !decision.held) {
            self.applied_answer_tick = a.tick;
        }
        let applied = JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status: torque.map_or(recordings::STATUS_NO_ANSWER, |a| a.controller_status),
            tick: self.applied_answer_tick,
            controller_id: self.gate.controller_id().unwrap_or(0),
            tau: decision.tau.into(),
        };
        self.prev = Some(decision);
        self.tick += 1;
        TickOutcome { decision, applied, strip: self.strip }
    }

    /// Turn the gate's rare events into recorded events and log lines.
    fn report(&mut self, tick: u64, t: f64, d: &Decision, prev_refused: bool, mut recorder: Option<&mut Recorder>) {
        let e = d.events;
        // A flapping controller starts a streak every few ticks: record each, log one per second.
        let ticks_per_s = 1_000_000_000 / self.period_ns.max(1);
        let may_log = self.last_log_tick.is_none_or(|l| tick >= l + ticks_per_s);
        if may_log && (e.miss_streak_started || (d.refused.is_some() && !prev_refused)) {
            self.last_log_tick = Some(tick);
        }
        if let Some(r) = d.refused {
            // Log and record the first refusal of a streak only (a bad controller refuses every tick).
            if !prev_refused {
                let mut s = StackText::new();
                let _ = write!(s, "tick {tick}: {r}");
                let kind =
                    if matches!(r, crate::gate::Refusal::Version(_)) { EventKind::VersionMismatch } else { EventKind::TorqueRefused };
                if may_log {
                    tracing::warn!("{}", s.as_str());
                }
                event(recorder.as_deref_mut(), tick, t, kind, s.as_str());
            }
        }
        if e.miss_streak_started {
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: no valid torque in time, holding the last one");
            if may_log {
                tracing::warn!("{} (total misses {})", s.as_str(), self.gate.total_misses());
            }
            event(recorder.as_deref_mut(), tick, t, EventKind::Miss, s.as_str());
        }
        if e.safe_stop_entered {
            let mut s = StackText::new();
            if e.controller_fault {
                let _ = write!(s, "tick {tick}: safe stop requested by the controller (fault)");
            } else {
                let _ = write!(
                    s,
                    "tick {tick}: safe stop after {} consecutive misses (gravity compensation + joint damping)",
                    self.gate.consecutive_misses()
                );
            }
            tracing::error!("{}", s.as_str());
            event(recorder.as_deref_mut(), tick, t, EventKind::SafeStop, s.as_str());
        }
        if e.safe_stop_cleared {
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: safe stop cleared, controller resumes (blended in)");
            tracing::info!("{}", s.as_str());
            event(recorder.as_deref_mut(), tick, t, EventKind::SafeStopCleared, s.as_str());
        }
        if let Some((old, new)) = e.controller_change {
            let mut s = StackText::new();
            match old {
                Some(old) => {
                    let _ = write!(s, "tick {tick}: controller {new:#x} takes over from {old:#x} (blended in)");
                }
                None => {
                    let _ = write!(s, "tick {tick}: controller {new:#x} connected");
                }
            }
            tracing::info!("{}", s.as_str());
            event(recorder, tick, t, EventKind::ControllerChange, s.as_str());
        }
    }

    /// After integrating: the cell's sensor and encoders read the new state, which is tick
    /// `tick`'s; a sensor entering or leaving saturation is an `/events` entry.
    fn read_sensors(&mut self, tick: u64, t: f64, recorder: Option<&mut Recorder>) {
        if let Some(e) = self.encoders.as_mut() {
            e.update(&self.physics.q(), &self.physics.qd());
        }
        let Some(sensor) = self.sensor.as_mut() else { return };
        let was = sensor.saturated;
        sensor.read(&self.physics);
        if sensor.saturated != was {
            let mut s = StackText::new();
            if sensor.saturated {
                let r = sensor.reading;
                let _ = write!(
                    s,
                    "tick {tick}: force/torque sensor saturated: reads ({:.3}, {:.3}, {:.3}) N, ({:.4}, {:.4}, {:.4}) N m at its range",
                    r[0], r[1], r[2], r[3], r[4], r[5]
                );
                tracing::warn!("{}", s.as_str());
            } else {
                let _ = write!(s, "tick {tick}: force/torque sensor back within its range");
            }
            event(recorder, tick, t, EventKind::Info, s.as_str());
        }
    }

    /// After integrating: reflexes (safe stop at once) and end-stop entries of the new state,
    /// which is tick `tick`'s.
    fn check_limits(&mut self, tick: u64, t: f64, mut recorder: Option<&mut Recorder>) {
        let reflex = self.reflex_limits.check(&self.physics.qd(), self.physics.tcp_speed_mps(), self.physics.contact_force_n());
        if let Some(r) = reflex {
            if !self.gate.reflex_latched() {
                self.gate.reflex();
                self.first.reflex.get_or_insert(tick);
                self.first.safe_stop.get_or_insert(tick);
                let mut s = StackText::new();
                let _ = write!(s, "tick {tick}: {r}: safe stop until the controller acknowledges");
                tracing::error!("{}", s.as_str());
                event(recorder.as_deref_mut(), tick, t, EventKind::Reflex, s.as_str());
            }
        }
        let stop = self.physics.limits().joint_in_end_stop(&self.physics.q());
        if let (Some(j), None) = (stop, self.in_end_stop) {
            let [lo, hi] = self.physics.limits().range_rad[j];
            let mut s = StackText::new();
            let _ =
                write!(s, "tick {tick}: joint {} in its end stop at {:.4} rad (range {lo:.4} .. {hi:.4} rad)", j + 1, self.physics.q()[j]);
            tracing::warn!("{}", s.as_str());
            event(recorder, tick, t, EventKind::EndStop, s.as_str());
        }
        self.in_end_stop = stop;
    }
}

/// The record of one tick as every driver hands it to the recorder; `timing` is the driver's
/// (zero in-process: no transport to time).
pub fn tick_record(
    state: JointState,
    wrench: Wrench,
    o: &TickOutcome,
    diag: Option<ControllerDiagnostics>,
    timing: TimingRecord,
) -> TickRecord {
    TickRecord {
        state,
        wrench,
        torque: o.applied,
        torque_held: o.decision.held,
        diag: diag.unwrap_or(ZERO_DIAG),
        has_diag: diag.is_some(),
        strip: o.strip,
        timing,
    }
}

const ZERO_DIAG: ControllerDiagnostics = ControllerDiagnostics::zeroed(0);

/// Record a rare event, if there is a recorder.
pub(crate) fn event(recorder: Option<&mut Recorder>, tick: u64, t: f64, kind: EventKind, text: &str) {
    if let Some(r) = recorder {
        r.record_event(&EventRecord::new(tick, t, kind, text));
    }
}
