//! The plant's tick loop (DESIGN section 6), on a plain OS thread.
//!
//! Real-time mode, tick k: sleep until the absolute deadline t_k (CLOCK_MONOTONIC, TIMER_ABSTIME),
//! publish state and wrench of tick k, wait on the torque listener's fd (`ppoll`) until
//! budget after the publish (at most until t_k+1) for the torque answering tick k, let the [`Gate`] decide what to apply, integrate
//! [t_k, t_k + T), record. If the thread falls behind by more than a period (a VM stall), the
//! missed deadlines are skipped and counted as overruns instead of being run in a burst.
//!
//! Lockstep mode: no sleeping; the plant waits for every torque up to the watchdog. Before the first
//! controller answers, tick 0 is republished every few milliseconds (a late-joining controller
//! gets no history) and the simulation does not advance, so identical inputs give identical
//! runs. When the watchdog expires the controller is presumed gone: the plant counts the miss and
//! continues paced in real time (budget waits), so the safe stop is reached after
//! `max_consecutive_misses` periods and a returning controller can take over.
//!
//! Per tick there is no allocation, no lock, no blocking I/O and no logging: ticks and events go
//! to the recorder's wait-free queue; only rare events (miss streak start, safe stop, takeover,
//! refusal, overrun) are also logged.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use messages::ports::PlantPorts;
use messages::{state_flags, ControllerDiagnostics, JointState, JointTorque, PlantStatus, Wrench, WrenchFrame, CONTRACT_VERSION};
use scenario::Mode;

use crate::arbiter::{Arbiter, ArbiterEvents, TakeoverReason};
use crate::gate::{Decision, Gate};
use crate::limits::ReflexLimits;
use messages::liveness::PeerWatch;
use messages::ports::Answers;
use crate::histogram::Histogram;
use crate::physics::Physics;
use crate::recording::{ControllerStamps, EventKind, EventRecord, Recorder, StageStamps, StripRecord, TickRecord, TimingRecord};
use crate::rt;

/// Loop parameters.
#[derive(Debug, Clone, Copy)]
pub struct LoopParams {
    pub mode: Mode,
    pub period_ns: u64,
    pub budget_ns: u64,
    pub watchdog_ns: u64,
    /// Ticks to run (the run ends after tick `n_ticks - 1` was integrated).
    pub n_ticks: u64,
    /// Busy-wait this long for the torque before sleeping in `ppoll` (0 = never spin).
    pub spin_ns: u64,
}

/// Statistics of a run, kept in fixed-size histograms.
#[derive(Debug, Clone)]
pub struct LoopStats {
    pub ticks: u64,
    pub misses: u64,
    pub safe_stops: u64,
    pub refusals: u64,
    pub overruns: u64,
    /// Publish → torque received, for ticks answered in time.
    pub round_trip: Histogram,
    /// |actual period − nominal period| between consecutive publishes (real-time pacing only).
    pub jitter: Histogram,
    /// Plant work per tick: wake → publish plus torque received → tick integrated and recorded.
    pub plant_compute: Histogram,
    /// Controller compute as it reports it in its diagnostics.
    pub controller_compute: Histogram,
    pub wall_s: f64,
    pub sim_s: f64,
    /// Wall and simulated time from the first controller answer to the end (the speed factor's
    /// basis: start-up waits for the controller are excluded).
    pub active_wall_s: f64,
    pub active_sim_s: f64,
    pub stopped_by_signal: bool,
    pub reflexes: u64,
    /// Answers from publishers other than the active controller, ignored.
    pub foreign_answers: u64,
    /// First tick of a safe stop, a reflex, a refused torque (the exit status' story).
    pub first_safe_stop_tick: Option<u64>,
    pub first_reflex_tick: Option<u64>,
    pub first_refusal_tick: Option<u64>,
    /// The launcher reported the controller process ended, or its node was seen dead.
    pub controller_ended: bool,
}

impl LoopStats {
    /// A run's statistics before its first tick.
    pub fn empty() -> LoopStats {
        LoopStats {
            ticks: 0,
            misses: 0,
            safe_stops: 0,
            refusals: 0,
            overruns: 0,
            round_trip: Histogram::for_latency(),
            jitter: Histogram::for_latency(),
            plant_compute: Histogram::for_latency(),
            controller_compute: Histogram::for_latency(),
            wall_s: 0.0,
            sim_s: 0.0,
            active_wall_s: 0.0,
            active_sim_s: 0.0,
            stopped_by_signal: false,
            reflexes: 0,
            foreign_answers: 0,
            first_safe_stop_tick: None,
            first_reflex_tick: None,
            first_refusal_tick: None,
            controller_ended: false,
        }
    }
}

/// A short text on the stack for rare events (no heap allocation).
pub(crate) struct StackText {
    buf: [u8; 192],
    len: usize,
}

impl StackText {
    pub(crate) fn new() -> Self {
        StackText { buf: [0; 192], len: 0 }
    }
    pub(crate) fn as_str(&self) -> &str {
        std::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}

impl std::fmt::Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let n = s.len().min(self.buf.len() - self.len);
        // Cut on a char boundary.
        let n = (0..=n).rev().find(|&i| s.is_char_boundary(i)).unwrap_or(0);
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

/// Everything the loop touches.
pub struct PlantLoop<'a> {
    pub ports: &'a PlantPorts,
    pub physics: &'a mut Physics,
    pub gate: &'a mut Gate,
    pub recorder: Option<&'a mut Recorder>,
    pub params: LoopParams,
    /// Tick of the last miss/refusal log line (rate limit: one per second of ticks).
    pub last_log_tick: Option<u64>,
    /// One controller at a time.
    pub arbiter: &'a mut Arbiter,
    /// Liveness of the active controller's node (None: no watcher, death only by silence).
    pub watch: Option<&'a PeerWatch>,
    pub reflex_limits: ReflexLimits,
    /// The host-floor probe's latest wake-up, read once per tick (None: no probe).
    pub probe: Option<&'a crate::probe::Latest>,
}

/// Longest single sleep while waiting for a torque (see `wait_for_answers`).
const WAIT_SLICE: Duration = Duration::from_millis(1);

/// How long a lockstep plant republishes the waiting state while no controller has answered yet.
const LOCKSTEP_REPUBLISH: Duration = Duration::from_millis(5);

impl PlantLoop<'_> {
    fn event(&mut self, tick: u64, sim_time_s: f64, kind: EventKind, text: &str) {
        if let Some(r) = self.recorder.as_deref_mut() {
            r.record_event(&EventRecord::new(tick, sim_time_s, kind, text));
        }
    }

    fn state(&self, tick: u64, prev: Option<&Decision>) -> JointState {
        let mut flags = 0;
        if let Some(d) = prev {
            if d.held {
                flags |= state_flags::TORQUE_HELD;
            }
            if d.refused.is_some() {
                flags |= state_flags::TORQUE_REFUSED;
            }
        }
        if self.params.mode == Mode::Lockstep {
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
        JointState {
            contract_version: CONTRACT_VERSION,
            plant_status: self.gate.status() as u32,
            tick,
            sim_time_s: tick as f64 * self.params.period_ns as f64 * 1e-9,
            q: self.physics.q().into(),
            qd: self.physics.qd().into(),
            tau_applied: self.gate.last_applied().into(),
            period_s: self.params.period_ns as f64 * 1e-9,
            flags,
            consecutive_misses: self.gate.consecutive_misses(),
            total_misses: self.gate.total_misses(),
        }
    }

    fn wrench(&self, tick: u64) -> Wrench {
        let (force, torque) = self.physics.wrench();
        Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::SensorAtTcp as u32, tick, force, torque }
    }

    /// Turn the gate's rare events into recorded events and log lines.
    fn report(&mut self, tick: u64, t: f64, d: &Decision, prev_refused: bool) {
        let e = d.events;
        // A flapping controller starts a streak every few ticks: record each, log one per second.
        let ticks_per_s = 1_000_000_000 / self.params.period_ns.max(1);
        let may_log = self.last_log_tick.is_none_or(|l| tick >= l + ticks_per_s);
        if may_log && (e.miss_streak_started || (d.refused.is_some() && !prev_refused)) {
            self.last_log_tick = Some(tick);
        }
        if let Some(r) = d.refused {
            // Log and record the first refusal of a streak only (a bad controller refuses every tick).
            if !prev_refused {
                let mut s = StackText::new();
                let _ = write!(s, "tick {tick}: {r}");
                let kind = if matches!(r, crate::gate::Refusal::Version(_)) { EventKind::VersionMismatch } else { EventKind::TorqueRefused };
                if may_log {
                    tracing::warn!("{}", s.as_str());
                }
                self.event(tick, t, kind, s.as_str());
            }
        }
        if e.miss_streak_started {
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: no valid torque in time, holding the last one");
            if may_log {
                tracing::warn!("{} (total misses {})", s.as_str(), self.gate.total_misses());
            }
            self.event(tick, t, EventKind::Miss, s.as_str());
        }
        if e.safe_stop_entered {
            let mut s = StackText::new();
            if e.controller_fault {
                let _ = write!(s, "tick {tick}: safe stop requested by the controller (fault)");
            } else {
                let _ = write!(s, "tick {tick}: safe stop after {} consecutive misses (gravity compensation + joint damping)", self.gate.consecutive_misses());
            }
            tracing::error!("{}", s.as_str());
            self.event(tick, t, EventKind::SafeStop, s.as_str());
        }
        if e.safe_stop_cleared {
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: safe stop cleared, controller resumes (blended in)");
            tracing::info!("{}", s.as_str());
            self.event(tick, t, EventKind::SafeStopCleared, s.as_str());
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
            self.event(tick, t, EventKind::ControllerChange, s.as_str());
        }
    }

    /// Collect the answers to `tick` into `answers` until the arbiter calls the tick settled (the
    /// active controller answered, see [`Arbiter::settled`]) or `deadline` passes.
    fn wait_for_answers(&self, tick: u64, deadline: Instant, answers: &mut Answers) {
        let settled = |answers: &Answers| {
            let gone = self.arbiter.active().is_some_and(|a| self.watch.is_some_and(|w| w.is_gone(a)));
            self.arbiter.settled(answers, gone)
        };
        // Optional busy-wait first: a halted vCPU takes tens of µs to wake on the controller's
        // notification; polling the subscriber (shared memory, no syscall) sees the torque at once.
        if self.params.spin_ns > 0 {
            let spin_end = deadline.min(Instant::now() + Duration::from_nanos(self.params.spin_ns));
            loop {
                self.ports.receive_answers(tick, answers);
                if settled(answers) {
                    // Consume the notification that came with it (non-blocking).
                    let _ = self.ports.wait_torque(Instant::now());
                    return;
                }
                if Instant::now() >= spin_end {
                    break;
                }
                std::hint::spin_loop();
            }
        }
        // Then sleep on the notification, in slices of at most WAIT_SLICE: a stop signal, the
        // launcher's report that the controller ended, or the watcher finding the active
        // controller gone end the wait early (a lockstep wait may last the 2 s watchdog), and an
        // answer whose notification was lost is still found within a slice.
        loop {
            self.ports.receive_answers(tick, answers);
            if settled(answers) {
                return;
            }
            let gone = self.arbiter.active().is_some_and(|a| self.watch.is_some_and(|w| w.is_gone(a)));
            if rt::stop_requested() || rt::controller_end_pending() || gone {
                return;
            }
            let now = Instant::now();
            if now >= deadline {
                return;
            }
            let _ = self.ports.wait_torque(deadline.min(now + WAIT_SLICE));
        }
    }

    /// After integrating: reflexes (safe stop at once) and end-stop entries of the new state,
    /// which is tick `tick`'s.
    fn check_limits(&mut self, tick: u64, t: f64, stats: &mut LoopStats, in_end_stop: &mut Option<usize>) {
        let reflex = self.reflex_limits.check(&self.physics.qd(), self.physics.tcp_speed_mps(), self.physics.contact_force_n());
        if let Some(r) = reflex {
            if !self.gate.reflex_latched() {
                self.gate.reflex();
                stats.first_reflex_tick.get_or_insert(tick);
                stats.first_safe_stop_tick.get_or_insert(tick);
                let mut s = StackText::new();
                let _ = write!(s, "tick {tick}: {r}: safe stop until the controller acknowledges");
                tracing::error!("{}", s.as_str());
                self.event(tick, t, EventKind::Reflex, s.as_str());
            }
        }
        let stop = self.physics.limits().joint_in_end_stop(&self.physics.q());
        if let (Some(j), None) = (stop, *in_end_stop) {
            let [lo, hi] = self.physics.limits().range_rad[j];
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: joint {} in its end stop at {:.4} rad (range {lo:.4} .. {hi:.4} rad)", j + 1, self.physics.q()[j]);
            tracing::warn!("{}", s.as_str());
            self.event(tick, t, EventKind::EndStop, s.as_str());
        }
        *in_end_stop = stop;
    }

    /// Record the arbiter's rare events.
    fn report_arbiter(&mut self, tick: u64, t: f64, ev: &ArbiterEvents) {
        if let Some((origin, controller_id)) = ev.ignored {
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: ignoring torques of publisher {:#x} (controller_id {controller_id:#x}): another controller is active", origin as u64);
            tracing::warn!("{}", s.as_str());
            self.event(tick, t, EventKind::ForeignTorque, s.as_str());
        }
        if let Some((Some(old), new, why)) = ev.takeover {
            let mut s = StackText::new();
            let _ = match why {
                TakeoverReason::Missed(n) => write!(s, "tick {tick}: publisher {:#x} takes over from {:#x}, which missed {n} ticks in a row", new as u64, old as u64),
                TakeoverReason::Gone => write!(s, "tick {tick}: publisher {:#x} takes over from {:#x}, whose node is gone", new as u64, old as u64),
                TakeoverReason::First => write!(s, "tick {tick}: publisher {:#x} takes over", new as u64),
            };
            tracing::info!("{}", s.as_str());
            self.event(tick, t, EventKind::ControllerChange, s.as_str());
        }
    }

    /// Run until `n_ticks` ticks are integrated or a stop signal arrives.
    pub fn run(&mut self) -> LoopStats {
        let p = self.params;
        let mut stats = LoopStats::empty();
        let mut answers = Answers::default();
        let mut in_end_stop: Option<usize> = None;
        let mut gone_reported = false;
        // Tick of the state whose answer was last applied: what `/joint_torque.answered_tick`
        // records (the current tick when fresh, older when held).
        let mut applied_answer_tick = recordings::NEVER_ANSWERED;
        // Overruns come in bursts on a stalling host: each is recorded in `/events`, but this
        // SCHED_FIFO thread writes at most one log line per second of ticks about them.
        let mut last_overrun_log: Option<(u64, u64)> = None;
        let ticks_per_s = 1_000_000_000 / p.period_ns.max(1);
        // One reference instant for both clocks: Instant is CLOCK_MONOTONIC on Linux.
        let (origin, origin_ns, origin_wall_ns) = (Instant::now(), rt::now_mono_ns(), rt::now_wall_ns());
        let at = |ns: u64| origin + Duration::from_nanos(ns.saturating_sub(origin_ns));
        let mut next_deadline_ns = origin_ns + p.period_ns;
        if let Some(probe) = self.probe {
            probe.set_grid(next_deadline_ns);
        }
        let mut paced = p.mode == Mode::Realtime;
        let mut prev: Option<Decision> = None;
        let mut last_publish_ns: u64 = 0;
        let mut tick: u64 = 0;
        let mut strip = StripRecord::default();
        // (wake time, tick) of the first tick a controller answered.
        let mut first_answer: Option<(u64, u64)> = None;

        while tick < p.n_ticks {
            if rt::stop_requested() {
                stats.stopped_by_signal = true;
                break;
            }
            let sim_t = tick as f64 * p.period_ns as f64 * 1e-9;
            let mut skipped_now = 0;
            // 1. The deadline of this tick (paced modes), skipping ahead after a stall.
            let deadline_ns = if paced {
                let now = rt::now_mono_ns();
                let (deadline, skipped) = skip_ahead(now, next_deadline_ns, p.period_ns);
                if skipped > 0 {
                    let late_us = (now - next_deadline_ns) / 1000;
                    next_deadline_ns = deadline;
                    stats.overruns += skipped;
                    skipped_now = skipped;
                    let mut s = StackText::new();
                    let _ = write!(s, "tick {tick}: loop {late_us} us late, skipped {skipped} periods");
                    if last_overrun_log.is_none_or(|(l, _)| tick >= l + ticks_per_s) {
                        let since = last_overrun_log.map_or(0, |(_, n)| n);
                        tracing::warn!("{} ({} overrun(s) since the last such line)", s.as_str(), stats.overruns - since);
                        last_overrun_log = Some((tick, stats.overruns));
                    }
                    self.event(tick, sim_t, EventKind::Info, s.as_str());
                }
                rt::sleep_until_mono_ns(next_deadline_ns);
                next_deadline_ns
            } else {
                rt::now_mono_ns()
            };
            let wake_ns = rt::now_mono_ns();

            // 2. Publish state and wrench of this tick.
            let state = self.state(tick, prev.as_ref());
            let wrench = self.wrench(tick);
            let publish_wall_ns = rt::now_wall_ns();
            let mut publish_ns = rt::now_mono_ns();
            if let Err(e) = self.ports.publish(&state, &wrench) {
                tracing::error!("{e}");
                self.event(tick, sim_t, EventKind::Fault, "publishing the state failed");
            }
            let published_ns = rt::now_mono_ns();
            let period_ns = if last_publish_ns == 0 { 0 } else { publish_ns - last_publish_ns };
            if p.mode == Mode::Realtime && last_publish_ns != 0 {
                stats.jitter.record(period_ns.abs_diff(p.period_ns));
            }
            last_publish_ns = publish_ns;
            let pre_ns = publish_ns - wake_ns;

            // 3. Wait for the torque of this tick (the active controller's; see the arbiter).
            answers.clear();
            // The budget counts from the publish (a plant that woke late must not blame the
            // controller), but never past the next tick's deadline.
            let mut budget_end_ns = (publish_ns + p.budget_ns).min(deadline_ns + p.period_ns);
            let budget_ns = if paced { p.budget_ns } else { p.watchdog_ns };
            if paced {
                self.wait_for_answers(tick, at(budget_end_ns), &mut answers);
            } else if self.gate.status() == PlantStatus::WaitingForController {
                // Lockstep start-up: hold tick 0 until a controller answers it.
                while !rt::stop_requested() {
                    self.wait_for_answers(tick, Instant::now() + LOCKSTEP_REPUBLISH, &mut answers);
                    if !answers.is_empty() {
                        break;
                    }
                    let _ = self.ports.publish(&state, &wrench);
                    publish_ns = rt::now_mono_ns();
                }
            } else {
                budget_end_ns = publish_ns + p.watchdog_ns;
                self.wait_for_answers(tick, at(budget_end_ns), &mut answers);
            }
            let active_gone = self.arbiter.active().is_some_and(|a| self.watch.is_some_and(|w| w.is_gone(a)));
            let (torque, arb_events) = self.arbiter.choose(&answers, active_gone, tick);
            if let Some(w) = self.watch {
                w.follow(self.arbiter.active().unwrap_or(0));
            }
            self.report_arbiter(tick, sim_t, &arb_events);
            let recv_ns = rt::now_mono_ns();
            if torque.is_some() && first_answer.is_none() {
                first_answer = Some((publish_ns, tick));
            }
            let recv_wall_ns = if torque.is_some() { rt::now_wall_ns() } else { 0 };
            let (diag, late_diag) = self.ports.receive_diagnostics_from(self.watch.map_or(0, |w| w.companion()), tick);

            // 4. Decide and integrate.
            // A controller that is gone (rig reports its process ended, or the watcher saw its
            // node dead) and was not replaced: safe stop now, not after max_consecutive_misses.
            let ended = rt::take_controller_end();
            let still_gone = arb_events.takeover.is_none() && torque.is_none() && active_gone;
            if ended.is_some() || (still_gone && !gone_reported) {
                stats.controller_ended = true;
                gone_reported = true;
                let mut s = StackText::new();
                let _ = match ended {
                    Some(end) => write!(s, "tick {tick}: controller process ended ({end})"),
                    None => write!(s, "tick {tick}: the active controller's node is dead"),
                };
                tracing::error!("{}", s.as_str());
                self.event(tick, sim_t, EventKind::ControllerEnded, s.as_str());
                if self.gate.controller_gone() {
                    let mut s = StackText::new();
                    let _ = write!(s, "tick {tick}: safe stop: the controller is gone (gravity compensation + joint damping)");
                    self.event(tick, sim_t, EventKind::SafeStop, s.as_str());
                    stats.first_safe_stop_tick.get_or_insert(tick);
                }
            }
            if arb_events.takeover.is_some() {
                gone_reported = false;
            }
            // Stopping (after the controller-end report above is recorded).
            if rt::stop_requested() && torque.is_none() {
                stats.stopped_by_signal = true;
                break;
            }
            let decision = self.gate.decide(torque.as_ref(), &self.physics.gravity_torque(), &self.physics.qd());
            if decision.events.safe_stop_entered {
                stats.first_safe_stop_tick.get_or_insert(tick);
            }
            if decision.refused.is_some() {
                stats.first_refusal_tick.get_or_insert(tick);
            }
            if p.mode == Mode::Lockstep {
                // Watchdog expired: pace in real time until a controller answers again.
                if !paced && decision.missed && torque.is_none() {
                    paced = true;
                    next_deadline_ns = rt::now_mono_ns() + p.period_ns;
                    let text = if gone_reported {
                        "the controller is gone: pacing in real time until a controller answers"
                    } else {
                        "lockstep watchdog expired: pacing in real time until a controller answers"
                    };
                    tracing::warn!("tick {tick}: {text}");
                    self.event(tick, sim_t, EventKind::ModeChange, text);
                } else if paced && !decision.held {
                    paced = false;
                    self.event(tick, sim_t, EventKind::ModeChange, "controller answers again: back to lockstep");
                }
            }
            self.report(tick, sim_t, &decision, prev.as_ref().is_some_and(|d| d.refused.is_some()));
            self.physics.step_tick(&decision.tau);
            self.check_limits(tick + 1, sim_t + p.period_ns as f64 * 1e-9, &mut stats, &mut in_end_stop);

            // 5. Record.
            let round_trip_ns = if torque.is_some() { recv_ns - publish_ns } else { 0 };
            if torque.is_some() && !decision.missed {
                stats.round_trip.record(round_trip_ns);
            }
            if let Some(d) = diag.as_ref() {
                stats.controller_compute.record(d.compute_time_ns);
            }
            self.physics.fill_strip_record(&mut strip);
            if let Some(t) = torque.as_ref().filter(|_| !decision.held) {
                applied_answer_tick = t.tick;
            }
            let applied = JointTorque {
                contract_version: CONTRACT_VERSION,
                controller_status: torque.map_or(recordings::STATUS_NO_ANSWER, |t| t.controller_status),
                tick: applied_answer_tick,
                controller_id: self.gate.controller_id().unwrap_or(0),
                tau: decision.tau.into(),
            };
            let mut rec = TickRecord {
                state,
                wrench,
                torque: applied,
                torque_held: decision.held,
                diag: diag.unwrap_or(ZERO_DIAG),
                has_diag: diag.is_some(),
                strip,
                timing: TimingRecord {
                    publish_wall_ns,
                    torque_receive_wall_ns: recv_wall_ns,
                    round_trip_ns,
                    period_ns,
                    missed: decision.missed,
                    plant_compute_ns: 0,
                    controller_compute_ns: diag.map_or(0, |d| d.compute_time_ns),
                    stages: None,
                },
            };
            let done_ns = rt::now_mono_ns();
            let plant_ns = pre_ns + (done_ns - recv_ns);
            rec.timing.plant_compute_ns = plant_ns;
            let rel = |t: u64| t as i64 - deadline_ns as i64;
            let (probe_late_ns, probe_at_ns) = self.probe.map_or((0, 0), |p| p.take());
            let since_start_us = |wall: u64| if wall == 0 { 0.0 } else { (wall as i64 - origin_wall_ns as i64) as f64 * 1e-3 };
            rec.timing.stages = Some(StageStamps {
                deadline_since_start_ns: deadline_ns.saturating_sub(origin_ns),
                publish_since_start_us: since_start_us(publish_wall_ns),
                torque_receive_since_start_us: since_start_us(recv_wall_ns),
                skipped_periods: skipped_now.min(u64::from(u32::MAX)) as u32,
                plant_woke_ns: rel(wake_ns),
                state_published_ns: rel(published_ns),
                budget_end_ns: rel(budget_end_ns),
                torque_budget_ns: budget_ns,
                torque_received_ns: rel(recv_ns),
                plant_done_ns: rel(done_ns),
                answered: torque.is_some(),
                refused: decision.refused.is_some(),
                controller: diag.and_then(|d| ControllerStamps::from_diag(&d, deadline_ns)),
                late: late_diag.and_then(|d| Some((d.tick, ControllerStamps::from_diag(&d, deadline_ns)?))),
                probe: self.probe.is_some(),
                probe_late_ns,
                probe_stall_from_ns: if probe_late_ns > 0 { rel(probe_at_ns) } else { 0 },
                probe_period_ns: self.probe.map_or(0, |p| p.period_ns()),
            });
            stats.plant_compute.record(plant_ns);
            if let Some(r) = self.recorder.as_deref_mut() {
                // Applied torque in the record, plus the controller's own answer (for replay).
                r.record_tick_commanded(&rec, torque.as_ref());
            }

            prev = Some(decision);
            tick += 1;
            if paced {
                next_deadline_ns += p.period_ns;
            }
        }

        stats.ticks = tick;
        stats.misses = self.gate.total_misses();
        stats.safe_stops = self.gate.safe_stops();
        stats.refusals = self.gate.refusals();
        stats.reflexes = self.gate.reflexes();
        stats.foreign_answers = self.arbiter.ignored_answers();
        stats.wall_s = (rt::now_mono_ns() - origin_ns) as f64 * 1e-9;
        stats.sim_s = self.physics.time_s();
        if let Some((t0, k0)) = first_answer {
            stats.active_wall_s = (rt::now_mono_ns() - t0) as f64 * 1e-9;
            stats.active_sim_s = (tick - k0) as f64 * p.period_ns as f64 * 1e-9;
        }

        // Goodbye: the last state says ShuttingDown so controllers exit.
        let mut last = self.state(tick, prev.as_ref());
        last.plant_status = PlantStatus::ShuttingDown as u32;
        let _ = self.ports.publish(&last, &self.wrench(tick));
        let t_end = stats.sim_s;
        let mut s = StackText::new();
        let _ = write!(s, "plant stopped after {tick} ticks ({})", if stats.stopped_by_signal { "signal" } else { "duration reached" });
        self.event(tick, t_end, EventKind::Stop, s.as_str());
        stats
    }
}

const ZERO_DIAG: ControllerDiagnostics = ControllerDiagnostics::zeroed(0);

/// The deadline to run next after waking at `now_ns` for `next_deadline_ns`, and the number of
/// whole periods skipped. Up to one period late, the tick runs late and the next ones catch up
/// on the grid; later than that (a VM stall), the missed deadlines are dropped so the loop lands
/// on the grid slot just before `now` instead of running a burst of back-to-back ticks.
fn skip_ahead(now_ns: u64, next_deadline_ns: u64, period_ns: u64) -> (u64, u64) {
    if now_ns > next_deadline_ns + period_ns {
        let skipped = (now_ns - next_deadline_ns) / period_ns;
        (next_deadline_ns + skipped * period_ns, skipped)
    } else {
        (next_deadline_ns, 0)
    }
}

#[cfg(test)]
mod tests {
    use super::skip_ahead;

    const T: u64 = 1_000_000;

    #[test]
    fn on_time_and_slightly_late_ticks_keep_their_deadline() {
        let d = 5 * T;
        assert_eq!(skip_ahead(d - 300_000, d, T), (d, 0));
        assert_eq!(skip_ahead(d + 999_999, d, T), (d, 0));
        assert_eq!(skip_ahead(d + T, d, T), (d, 0));
    }

    #[test]
    fn a_stall_skips_whole_periods_and_lands_on_the_grid_before_now() {
        let d = 7 * T + 123; // grid phase 123 ns
        // 3.4 periods late: 3 deadlines dropped, the next one is 0.4 periods in the past.
        let (d2, k) = skip_ahead(d + 3_400_000, d, T);
        assert_eq!((d2, k), (d + 3 * T, 3));
        // Any lateness beyond a period: on the grid, not after now, less than a period before it.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..10_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let late = T + 1 + x % (50 * T);
            let (d2, k) = skip_ahead(d + late, d, T);
            assert_eq!((d2 - d) % T, 0);
            assert_eq!(d2, d + k * T);
            assert!(k >= 1 && d2 <= d + late && d + late - d2 < T, "late {late}: deadline {d2}, skipped {k}");
        }
    }
}
