//! One plant tick as a value: [`PlantTick`] holds the physics, the torque gate and the limits
//! between ticks. [`PlantTick::outputs`] gives the tick's joint state and wrench (what the plant
//! publishes); [`PlantTick::advance`] applies the torque received for it (or none) through the
//! gate, integrates the tick, checks the reflexes and end stops and gives what was applied, the
//! strip record and the tick's rare events. EGM's motion controller applies its own servo torque
//! through [`PlantTick::advance_servo`], with the same integration, sensors, reflexes and end
//! stops. The real-time loop (`loop_rt.rs`), the lockstep loop (`loop_lockstep.rs`), the EGM loop
//! (`egm/`), `rig run --in-process`, `rig sweep` and the design servo drive this one type: the
//! drivers add only pacing, ports and the hand-off of records and events.
//!
//! Per tick: no allocation (`tests/tests/no_alloc.rs` counts), no lock, no recording, no logging
//! and no waiting: rare events (miss streak, safe stop, reflex, end stop, refusal, controller
//! change) come back in [`TickOutcome::events`] for the driver to hand on
//! ([`crate::tick_events::EventHandOn`]).

use messages::{state_flags, ControllerDiagnostics, JointState, JointTorque, PlantStatus, Wrench, WrenchFrame, CONTRACT_VERSION};
use robot::Vec6;
use scenarios::{Mode, Scenario};

use crate::gate::{Decision, Gate, GateConfig, GateEvents};
use crate::limits::ReflexLimits;
use crate::physics::Physics;
use crate::recording::{StripRecord, TickRecord, TimingRecord};
use crate::tick_events::{PlantEvent, Raised, SafeStopCause, TickEvents};

/// What one [`PlantTick::advance`] applied and measured.
#[derive(Debug, Clone, Copy)]
pub struct TickOutcome {
    /// The gate's decision (torque applied, held, missed, refused, events).
    pub decision: Decision,
    /// The torque as applied over the tick, as recorded: its `tick` is the answered state's.
    pub applied: JointTorque,
    /// The strip after the tick was integrated (as recorded with the tick).
    pub strip: StripRecord,
    /// What the tick raised, for the driver to record and log.
    pub events: TickEvents,
}

/// The first tick of a safe stop, a reflex, a refused torque (the exit status' story).
#[derive(Debug, Clone, Copy, Default)]
pub struct FirstTicks {
    pub safe_stop: Option<u64>,
    pub reflex: Option<u64>,
    pub refusal: Option<u64>,
}

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
    /// over: safe stop now. Returns the safe stop's event if the plant entered it.
    pub fn controller_gone(&mut self) -> Option<Raised> {
        if !self.gate.controller_gone() {
            return None;
        }
        let tick = self.tick;
        self.first.safe_stop.get_or_insert(tick);
        Some(Raised { tick, sim_time_s: self.sim_time_s(), event: PlantEvent::SafeStop(SafeStopCause::ControllerGone) })
    }

    /// Whether the states say LOCKSTEP (a lockstep driver waits for its recorder, see
    /// [`crate::loop_rt`]).
    pub fn is_lockstep(&self) -> bool {
        self.lockstep
    }

    /// Apply `torque` (this tick's answer, None if none came in time) through the gate,
    /// integrate the tick, check reflexes and end stops of the new state, and move on to the
    /// next tick.
    pub fn advance(&mut self, torque: Option<&JointTorque>) -> TickOutcome {
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
        let mut events = TickEvents::default();
        self.gate_events(tick, t, &decision, prev_refused, &mut events);
        if let Some(a) = torque.filter(|_| !decision.held) {
            self.applied_answer_tick = a.tick;
        }
        let status = torque.map_or(recordings::STATUS_NO_ANSWER, |a| a.controller_status);
        self.integrate(decision, status, self.applied_answer_tick, events)
    }

    /// EGM: the robot controller's own motion servo applies `tau` (already within the joints'
    /// limits) over this tick, as its answer to this tick; no controller, no gate. Integration,
    /// sensors, reflexes and end stops are the torque path's.
    pub fn advance_servo(&mut self, tau: &Vec6) -> TickOutcome {
        let tick = self.tick;
        self.gate.servo_applied(*tau);
        let decision = Decision { tau: *tau, held: false, missed: false, refused: None, events: GateEvents::default() };
        self.applied_answer_tick = tick;
        self.integrate(decision, 0, tick, TickEvents::default())
    }

    /// Integrate `decision.tau` over the tick; the sensors, reflexes and end stops of the new
    /// state, which is the next tick's; the record of what was applied.
    fn integrate(&mut self, decision: Decision, controller_status: u32, answered_tick: u64, mut events: TickEvents) -> TickOutcome {
        let tick = self.tick;
        let t_next = self.sim_time_s() + self.period_ns as f64 * 1e-9;
        self.physics.step_tick(&decision.tau);
        self.read_sensors(tick + 1, t_next, &mut events);
        self.check_limits(tick + 1, t_next, &mut events);
        self.physics.fill_strip_record(&mut self.strip);
        let applied = JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status,
            tick: answered_tick,
            controller_id: self.gate.controller_id().unwrap_or(0),
            tau: decision.tau.into(),
        };
        self.prev = Some(decision);
        self.tick += 1;
        TickOutcome { decision, applied, strip: self.strip, events }
    }

    /// The gate's rare events of this tick, in the order they are recorded.
    fn gate_events(&self, tick: u64, t: f64, d: &Decision, prev_refused: bool, events: &mut TickEvents) {
        let e = d.events;
        if let Some(r) = d.refused.filter(|_| !prev_refused) {
            events.push(tick, t, PlantEvent::Refused(r));
        }
        if e.miss_streak_started {
            events.push(tick, t, PlantEvent::MissStreak { total_misses: self.gate.total_misses() });
        }
        if e.safe_stop_entered {
            let cause = if e.controller_fault {
                SafeStopCause::ControllerFault
            } else {
                SafeStopCause::Misses(self.gate.consecutive_misses())
            };
            events.push(tick, t, PlantEvent::SafeStop(cause));
        }
        if e.safe_stop_cleared {
            events.push(tick, t, PlantEvent::SafeStopCleared);
        }
        if let Some((old, new)) = e.controller_change {
            events.push(tick, t, PlantEvent::ControllerChange { old, new });
        }
    }

    /// After integrating: the cell's sensor and encoders read the new state, which is tick
    /// `tick`'s; a sensor entering or leaving saturation is an event.
    fn read_sensors(&mut self, tick: u64, t: f64, events: &mut TickEvents) {
        if let Some(e) = self.encoders.as_mut() {
            e.update(&self.physics.q(), &self.physics.qd());
        }
        let Some(sensor) = self.sensor.as_mut() else { return };
        let was = sensor.saturated;
        sensor.read(&self.physics);
        if sensor.saturated != was {
            let event =
                if sensor.saturated { PlantEvent::SensorSaturated { reading: sensor.reading } } else { PlantEvent::SensorWithinRange };
            events.push(tick, t, event);
        }
    }

    /// After integrating: reflexes (safe stop at once) and end-stop entries of the new state,
    /// which is tick `tick`'s.
    fn check_limits(&mut self, tick: u64, t: f64, events: &mut TickEvents) {
        let reflex = self.reflex_limits.check(&self.physics.qd(), self.physics.tcp_speed_mps(), self.physics.contact_force_n());
        if let Some(r) = reflex {
            if !self.gate.reflex_latched() {
                self.gate.reflex();
                self.first.reflex.get_or_insert(tick);
                self.first.safe_stop.get_or_insert(tick);
                events.push(tick, t, PlantEvent::Reflex(r));
            }
        }
        let stop = self.physics.limits().joint_in_end_stop(&self.physics.q());
        if let (Some(j), None) = (stop, self.in_end_stop) {
            let range_rad = self.physics.limits().range_rad[j];
            events.push(tick, t, PlantEvent::EndStop { joint: j, q_rad: self.physics.q()[j], range_rad });
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
