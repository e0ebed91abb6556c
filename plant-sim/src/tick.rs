//! One plant tick as a value: [`PlantTick`] holds the physics, the torque gate and the limits
//! between ticks. [`PlantTick::outputs`] gives the tick's joint state and wrench (what the plant
//! publishes); [`PlantTick::advance`] applies the torque received for it (or none) through the
//! gate, integrates the tick, checks the reflexes and end stops and gives what was applied, the
//! strip record and the tick's rare events. EGM's motion controller applies its own servo torque
//! through [`PlantTick::advance_servo`], with the same integration, sensors, reflexes and end
//! stops. The real-time loop (`driver/realtime.rs`), the lockstep loop (`driver/lockstep.rs`), the EGM loop
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

use crate::contact::StripDetail;
use crate::gate::{ArmNow, Decision, Gate, GateConfig, GateEvents};
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
    /// How much of the strip the record carries (full unless a case records nothing).
    strip_detail: StripDetail,
    /// Every how many ticks a full record carries the top line (the recording's scene ticks);
    /// None: never (no scene).
    top_line_every: Option<u64>,
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
        let mass_diag = physics.robot().mass_matrix(&physics.q()).diagonal();
        let gate = Gate::new(GateConfig {
            max_consecutive_misses: l.max_consecutive_misses,
            blend_ticks: (l.takeover_blend_s / l.period_s).round() as u32,
            safe_stop_damping_nms: crate::gate::safe_stop_damping(l.safe_stop_damping_nms, &mass_diag, l.period_s),
            hold_omega_radps: 2.0 * std::f64::consts::PI * l.hold_bandwidth_hz,
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
            strip_detail: StripDetail::Full,
            top_line_every: Some(1),
        }
    }

    /// Fill the strip record's top line (read only by the recording's 3D scene) on ticks that
    /// are a multiple of `every` only, None: never; by default every tick. A driver passes its
    /// recorder's [`recordings::Recorder::scene_every`]: the top line is about half of the
    /// record's cost, O(nodes × modes) per tick.
    pub fn with_top_line_every(mut self, every: Option<u64>) -> PlantTick {
        self.top_line_every = every;
        self
    }

    /// The detail of the strip's record in each tick's outcome (default full: the recording's).
    pub fn with_strip_detail(mut self, detail: StripDetail) -> PlantTick {
        self.strip_detail = detail;
        self
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
    /// [`crate::driver::realtime`]).
    pub fn is_lockstep(&self) -> bool {
        self.lockstep
    }

    /// Apply `torque` (this tick's answer, None if none came in time) through the gate,
    /// integrate the tick, check reflexes and end stops of the new state, and move on to the
    /// next tick.
    pub fn advance(&mut self, torque: Option<&JointTorque>) -> TickOutcome {
        let tick = self.tick;
        let t = self.sim_time_s();
        let physics = &self.physics;
        let arm = ArmNow {
            gravity: &|| physics.gravity_torque(),
            q: physics.q(),
            qd: physics.qd(),
            mass_matrix: &|| physics.robot().mass_matrix(&physics.q()),
        };
        let decision = self.gate.decide(torque, &arm);
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
        let detail = match (self.strip_detail, self.top_line_every) {
            (StripDetail::Full, Some(every)) if tick.is_multiple_of(every) => StripDetail::Full,
            (StripDetail::Full, _) => StripDetail::NoTopLine,
            (detail, _) => detail,
        };
        self.physics.fill_strip_record_with(&mut self.strip, detail);
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
            let cause =
                if e.controller_fault { SafeStopCause::ControllerFault } else { SafeStopCause::Misses(self.gate.consecutive_misses()) };
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

#[cfg(test)]
mod tests {
    //! Each gate decision, the reflexes and the stall (misses) of the plant's one core, against
    //! hand-computed ticks: the blend's straight line (`from + (τ − from) k / N`), the position
    //! hold's `g(q) + K (q_a − q) − D_h q̇`, the compliant stop's `g(q) − D q̇` after a reflex, and a
    //! twin [`Physics`] stepped with what the tick says it applied.
    use super::*;
    use messages::ControllerStatus;
    use std::path::Path;

    /// The bare arm (no strip: fast, and the start pose is free of contact).
    fn scenario() -> Scenario {
        let mut s = Scenario::default();
        s.strip.enabled = false;
        s
    }

    fn plant(s: &Scenario) -> PlantTick {
        PlantTick::new(s, Physics::new(s, Path::new("/nonexistent")).unwrap(), Mode::Lockstep)
    }

    fn twin(s: &Scenario) -> Physics {
        Physics::new(s, Path::new("/nonexistent")).unwrap()
    }

    /// Controller `id`'s answer to the plant's current state.
    fn answer(p: &PlantTick, id: u64, status: ControllerStatus, tau: Vec6) -> JointTorque {
        JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status: status as u32,
            tick: p.tick(),
            controller_id: id,
            tau: tau.into(),
        }
    }

    fn events(o: &TickOutcome) -> Vec<PlantEvent> {
        o.events.iter().map(|r| r.event).collect()
    }

    fn bits(v: &Vec6) -> [u64; 6] {
        std::array::from_fn(|i| v[i].to_bits())
    }

    /// The start pose's diagonal inertia (the gate fixes its gains from it at start).
    fn start_mass_diag(s: &Scenario) -> Vec6 {
        let start = twin(s);
        start.robot().mass_matrix(&start.q()).diagonal()
    }

    /// The compliant hold (waiting for the first answer, after a reflex) as the gate's docs state it: `g(q) − D q̇`, with D per
    /// joint capped at `0.3 M_ii(q₀) / T`.
    fn compliant_torque(s: &Scenario, physics: &Physics) -> Vec6 {
        let m = start_mass_diag(s);
        let d = Vec6::from_fn(|i, _| s.loop_.safe_stop_damping_nms.min(0.3 * m[i] / s.loop_.period_s));
        physics.gravity_torque() - physics.qd().component_mul(&d)
    }

    /// The position hold about `anchor` as the gate's docs state it:
    /// `g(q) + M(q) (ω² (q_a − q) − 2ω q̇)`, `ω = 2π loop.hold_bandwidth_hz`.
    fn hold_torque(s: &Scenario, physics: &Physics, anchor: &Vec6) -> Vec6 {
        let w = 2.0 * std::f64::consts::PI * s.loop_.hold_bandwidth_hz;
        let m = physics.robot().mass_matrix(&physics.q());
        physics.gravity_torque() + m * ((anchor - physics.q()) * (w * w) - physics.qd() * (2.0 * w))
    }

    /// A small torque on top of gravity compensation: the arm moves, slowly.
    fn nudge() -> Vec6 {
        Vec6::new(2.0, -1.0, 0.5, 0.02, 0.01, 0.005)
    }

    #[test]
    fn the_first_state_is_tick_zero_at_rest_waiting_in_lockstep() {
        let s = scenario();
        let p = plant(&s);
        let (state, wrench) = p.outputs();
        assert_eq!((state.tick, wrench.tick), (0, 0));
        assert_eq!(state.sim_time_s, 0.0);
        assert_eq!(state.plant_status, PlantStatus::WaitingForController as u32);
        assert_eq!(state.flags, state_flags::LOCKSTEP, "no contact, no reflex, nothing held yet");
        assert_eq!(state.q, <[f64; 6]>::from(p.physics().q()));
        assert_eq!(state.qd, [0.0; 6]);
        assert_eq!(state.period_s, s.loop_.period_s);
    }

    #[test]
    fn without_a_controller_the_plant_holds_the_compliant_torque_and_counts_no_miss() {
        let s = scenario();
        let mut p = plant(&s);
        let mut t = twin(&s);
        let q0 = p.physics().q();
        for k in 0..100 {
            let expected = compliant_torque(&s, &t);
            let o = p.advance(None);
            assert_eq!(bits(&o.decision.tau), bits(&expected), "tick {k}");
            assert!(o.decision.held && !o.decision.missed && o.events.is_empty(), "tick {k}: {:?}", o.decision);
            assert_eq!(o.applied.tick, recordings::NEVER_ANSWERED);
            assert_eq!(o.applied.controller_status, recordings::STATUS_NO_ANSWER);
            t.step_tick(&expected);
        }
        let (state, _) = p.outputs();
        assert_eq!((state.tick, state.consecutive_misses, state.total_misses), (100, 0, 0));
        assert_eq!(state.plant_status, PlantStatus::WaitingForController as u32);
        assert!(state.flags & state_flags::TORQUE_HELD != 0);
        assert!((p.physics().q() - q0).norm() < 1e-9, "the arm drifted {}", (p.physics().q() - q0).norm());
        assert_eq!(bits(&p.physics().q()), bits(&t.q()), "the tick integrates exactly what it applied");
    }

    #[test]
    fn the_first_controller_is_blended_in_on_a_straight_line_then_applied_exactly() {
        let s = scenario();
        let n = (s.loop_.takeover_blend_s / s.loop_.period_s).round() as u32;
        assert_eq!(n, 50);
        let mut p = plant(&s);
        let mut t = twin(&s);
        for k in 1..=2 * n {
            let tau = t.gravity_torque() + nudge();
            // The compliant hold the plant waited in.
            let from = compliant_torque(&s, &t);
            let answered = p.tick();
            let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, tau)));
            let expected = if k <= n { from + (tau - from) * (f64::from(k) / f64::from(n)) } else { tau };
            assert!((o.decision.tau - expected).norm() < 1e-12, "tick {k}: {} vs {}", o.decision.tau, expected);
            if k > n {
                // (At k = n the line's end is `from + (τ − from)·1`, τ to rounding.)
                assert_eq!(bits(&o.decision.tau), bits(&tau), "tick {k}: after the blend the answer is applied as sent");
            }
            assert!(!o.decision.held && !o.decision.missed);
            assert_eq!((o.applied.tick, o.applied.controller_id), (answered, 7));
            let ev = events(&o);
            if k == 1 {
                assert_eq!(ev, vec![PlantEvent::ControllerChange { old: None, new: 7 }]);
            } else {
                assert!(ev.is_empty(), "tick {k}: {ev:?}");
            }
            t.step_tick(&o.decision.tau);
            assert_eq!(bits(&p.physics().q()), bits(&t.q()), "tick {k}");
            let (state, _) = p.outputs();
            assert_eq!(state.plant_status, PlantStatus::Running as u32);
            assert_eq!(state.tau_applied, <[f64; 6]>::from(o.decision.tau));
        }
        assert!(p.physics().qd().norm() > 1e-4, "the nudge moved the arm");
    }

    /// The plant after `ticks` answered ticks of controller 7 (past its blend).
    fn running(s: &Scenario, ticks: u32) -> PlantTick {
        let mut p = plant(s);
        for _ in 0..ticks {
            let tau = p.physics().gravity_torque() + nudge();
            p.advance(Some(&answer(&p, 7, ControllerStatus::Active, tau)));
        }
        p
    }

    #[test]
    fn misses_hold_the_last_torque_then_safe_stop_at_the_limit_then_an_answer_clears_it() {
        let s = scenario();
        let limit = s.loop_.max_consecutive_misses;
        let mut p = running(&s, 60);
        let last = p.gate().last_applied();
        let mut anchor = None;
        for m in 1..=limit {
            let tick = p.tick();
            if m == limit {
                // The hold's anchor: where the arm is on the safe stop's first tick.
                anchor = Some(p.physics().q());
            }
            let o = p.advance(None);
            assert!(o.decision.held && o.decision.missed);
            let ev = events(&o);
            if m == 1 {
                assert_eq!(bits(&o.decision.tau), bits(&last), "the first miss holds the last torque");
                assert_eq!(ev, vec![PlantEvent::MissStreak { total_misses: 1 }]);
                assert_eq!(p.outputs().0.plant_status, PlantStatus::HoldingTorque as u32);
            } else if m < limit {
                assert_eq!(bits(&o.decision.tau), bits(&last), "miss {m}");
                assert!(ev.is_empty(), "miss {m}: {ev:?}");
            } else {
                assert_eq!(ev, vec![PlantEvent::SafeStop(SafeStopCause::Misses(limit))]);
                assert_eq!(p.first_ticks().safe_stop, Some(tick));
                assert_eq!(p.outputs().0.plant_status, PlantStatus::SafeStop as u32);
            }
        }
        // In the safe stop the torque is the hold about the anchor, of each tick's state.
        let anchor = anchor.unwrap();
        assert!(p.physics().qd().norm() > 1e-4, "the arm was moving when the stop began");
        let expected = hold_torque(&s, p.physics(), &anchor);
        let o = p.advance(None);
        assert_eq!(bits(&o.decision.tau), bits(&expected));
        let (state, _) = p.outputs();
        assert_eq!((state.consecutive_misses, state.total_misses), (limit + 1, u64::from(limit) + 1));
        // The same controller answers again: the safe stop clears, no controller change, and it
        // blends in from the safe stop.
        let tau = p.physics().gravity_torque() + nudge();
        let from = hold_torque(&s, p.physics(), &anchor);
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, tau)));
        assert_eq!(events(&o), vec![PlantEvent::SafeStopCleared]);
        assert!((o.decision.tau - (from + (tau - from) / 50.0)).norm() < 1e-12);
        assert_eq!(p.outputs().0.consecutive_misses, 0);
    }

    /// A stalled controller's safe stop, from a swing of the bare arm: per joint the largest
    /// distance from the anchor after the stop began, the joint speeds at its first tick, and
    /// where the arm is after `settle` more ticks.
    fn stop_from_a_swing(s: &Scenario, settle: u32) -> (Vec6, Vec6, Vec6, PlantTick) {
        let mut p = plant(s);
        for _ in 0..300 {
            // The arm's heavy joints pushed (the light wrist only rides along).
            let tau = p.physics().gravity_torque() + Vec6::new(10.0, -5.0, 2.5, 0.0, 0.0, 0.0);
            p.advance(Some(&answer(&p, 7, ControllerStatus::Active, tau)));
        }
        while p.gate().status() != PlantStatus::SafeStop {
            p.advance(None);
        }
        assert_eq!(p.gate().reflexes(), 0, "a stall's stop, not a reflex's");
        let anchor = p.gate().hold_anchor().unwrap_or(p.physics().q());
        let qd0 = p.physics().qd();
        let mut reach = Vec6::zeros();
        for _ in 0..settle {
            p.advance(None);
            reach = reach.zip_map(&(p.physics().q() - anchor), |r, e| r.max(e.abs()));
        }
        (reach, qd0, p.physics().q() - anchor, p)
    }

    /// The position hold stops a swinging arm joint by joint as a critically damped joint does
    /// (computed torque cancels the coupling): from speed `v` no farther than `v / (ω e)` from
    /// the anchor (closed form of `x = v t e^(−ωt)`; the bound has 10 % for the torque held over
    /// each tick, which adds 4.4-4.7 % on every joint at `ωT` = 0.031), and it settles onto the
    /// anchor. The compliant hold (`hold_bandwidth_hz` = 0) coasts many times farther, as every
    /// safe stop did before the position hold.
    #[test]
    fn the_position_hold_stops_a_swing_within_the_closed_form_and_settles_on_the_anchor() {
        let s = scenario();
        let w = 2.0 * std::f64::consts::PI * s.loop_.hold_bandwidth_hz;
        let (reach, qd0, offset, p) = stop_from_a_swing(&s, 1000);
        assert!(qd0.norm() > 0.05, "the arm swung: {qd0}");
        for i in 0..6 {
            let bound = qd0[i].abs() / (w * std::f64::consts::E);
            assert!(reach[i] <= 1.1 * bound + 1e-9, "joint {}: {} rad from the anchor, closed form {bound}", i + 1, reach[i]);
        }
        assert!(offset.norm() < 1e-6, "settled {offset} from the anchor after 1 s");
        assert!(p.physics().qd().norm() < 1e-6);
        let mut compliant = scenario();
        compliant.loop_.hold_bandwidth_hz = 0.0;
        let (coast, _, _, _) = stop_from_a_swing(&compliant, 1000);
        assert!(coast.norm() > 5.0 * reach.norm(), "compliant {coast} vs hold {reach}");
    }

    #[test]
    fn a_refused_torque_is_one_event_per_streak_and_flags_the_next_state() {
        let s = scenario();
        let mut p = running(&s, 60);
        let mut bad = p.physics().gravity_torque();
        bad[2] = f64::NAN;
        let tick = p.tick();
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, bad)));
        assert!(o.decision.refused.is_some() && o.decision.held && o.decision.missed);
        let ev = events(&o);
        assert!(matches!(ev[..], [PlantEvent::Refused(_), PlantEvent::MissStreak { total_misses: 1 }]), "{ev:?}");
        assert_eq!(p.first_ticks().refusal, Some(tick));
        assert!(p.outputs().0.flags & state_flags::TORQUE_REFUSED != 0);
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, bad)));
        assert!(o.decision.refused.is_some() && events(&o).is_empty(), "the streak's second refusal is not a new event");
        assert_eq!(p.first_ticks().refusal, Some(tick));
        let good = p.physics().gravity_torque();
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, good)));
        assert!(o.decision.refused.is_none() && events(&o).is_empty());
        assert_eq!(p.outputs().0.flags & (state_flags::TORQUE_REFUSED | state_flags::TORQUE_HELD), 0);
        assert_eq!(p.gate().refusals(), 2);
    }

    #[test]
    fn a_controller_fault_is_a_safe_stop_not_a_miss() {
        let s = scenario();
        let mut p = running(&s, 60);
        // The hold's first tick: anchored where the arm is, so only its damping acts.
        let expected = hold_torque(&s, p.physics(), &p.physics().q());
        let tick = p.tick();
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Fault, nudge())));
        assert_eq!(events(&o), vec![PlantEvent::SafeStop(SafeStopCause::ControllerFault)]);
        assert_eq!(bits(&o.decision.tau), bits(&expected), "the fault's torque is not applied");
        assert!(o.decision.held && !o.decision.missed);
        assert_eq!(p.first_ticks().safe_stop, Some(tick));
        assert_eq!(p.outputs().0.total_misses, 0);
    }

    #[test]
    fn a_new_controller_is_blended_in_from_the_held_torque() {
        let s = scenario();
        let mut p = running(&s, 60);
        let held = p.gate().last_applied();
        let tau = p.physics().gravity_torque() - nudge();
        let o = p.advance(Some(&answer(&p, 9, ControllerStatus::Starting, tau)));
        assert_eq!(events(&o), vec![PlantEvent::ControllerChange { old: Some(7), new: 9 }]);
        assert!((o.decision.tau - (held + (tau - held) / 50.0)).norm() < 1e-12);
        assert_eq!(o.applied.controller_id, 9);
    }

    #[test]
    fn a_reflex_latches_the_safe_stop_once_until_the_controller_acknowledges_it() {
        // A TCP speed limit of 1 mm/s: the nudge crosses it within the run.
        let mut s = scenario();
        s.safety.max_tcp_speed_mps = 1e-3;
        let mut p = plant(&s);
        let mut reflex_tick = None;
        let mut compliant_before = compliant_torque(&s, p.physics());
        for _ in 0..2000 {
            let tau = p.physics().gravity_torque() + nudge() * 5.0;
            let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Active, tau)));
            let reflexes = o.events.iter().filter(|r| matches!(r.event, PlantEvent::Reflex(_))).count();
            if reflex_tick.is_none() {
                if let Some(r) = o.events.reflex() {
                    assert!(matches!(r, crate::limits::Reflex::TcpSpeed { limit_mps, .. } if limit_mps == 1e-3), "{r:?}");
                    assert!(p.physics().tcp_speed_mps() > 1e-3);
                    reflex_tick = Some(p.tick());
                }
            } else {
                assert_eq!(reflexes, 0, "a latched reflex is raised once");
                // Answered but not acknowledged: the compliant stop's torque, not the answer
                // (no position hold: the arm gives way, relieving what tripped the reflex).
                assert!(o.decision.held && !o.decision.missed);
                assert_eq!(bits(&o.decision.tau), bits(&compliant_before), "tick {}", p.tick());
                assert_eq!(p.gate().hold_anchor(), None);
            }
            let compliant_before_next = compliant_torque(&s, p.physics());
            compliant_before = compliant_before_next;
            if reflex_tick.is_some_and(|t| p.tick() > t + 5) {
                break;
            }
        }
        let t = reflex_tick.expect("the reflex tripped");
        assert_eq!(p.first_ticks().reflex, Some(t));
        assert_eq!(p.first_ticks().safe_stop, Some(t));
        let (state, _) = p.outputs();
        assert!(state.flags & state_flags::REFLEX != 0);
        assert_eq!(state.plant_status, PlantStatus::SafeStop as u32);
        // Acknowledged with status starting: cleared, blended in from the safe stop.
        let tau = p.physics().gravity_torque();
        let o = p.advance(Some(&answer(&p, 7, ControllerStatus::Starting, tau)));
        assert!(o.decision.events.reflex_acknowledged);
        assert_eq!(events(&o)[0], PlantEvent::SafeStopCleared);
        assert!(!o.decision.held);
    }

    #[test]
    fn a_controller_gone_is_a_safe_stop_once_and_nothing_before_any_controller() {
        let s = scenario();
        let mut p = plant(&s);
        assert_eq!(p.controller_gone(), None, "nobody was there to go");
        let mut p = running(&s, 10);
        let tick = p.tick();
        let r = p.controller_gone().expect("safe stop");
        assert_eq!((r.tick, r.event), (tick, PlantEvent::SafeStop(SafeStopCause::ControllerGone)));
        assert_eq!(p.first_ticks().safe_stop, Some(tick));
        assert_eq!(p.controller_gone(), None, "already in the safe stop");
    }

    #[test]
    fn the_servo_path_applies_its_torque_as_the_answer_to_its_own_tick() {
        let s = scenario();
        let mut p = plant(&s);
        let mut t = twin(&s);
        for _ in 0..20 {
            let tau = t.gravity_torque() + nudge();
            let tick = p.tick();
            let o = p.advance_servo(&tau);
            assert_eq!(bits(&o.decision.tau), bits(&tau));
            assert_eq!(o.applied.tick, tick);
            assert!(o.events.is_empty());
            t.step_tick(&tau);
            assert_eq!(bits(&p.physics().q()), bits(&t.q()));
            assert_eq!(p.outputs().0.tau_applied, <[f64; 6]>::from(tau));
        }
    }
}
