//! The plant's real-time loop (DESIGN section 6), on a plain OS thread, and the parts of a tick
//! every port-driven loop shares: the ports (publish the state, collect the answers, choose one
//! with the arbiter), the tick itself ([`PlantTick`]) and the recorder hand-off. The lockstep
//! loop (`driver/lockstep.rs`) drives the same parts with its own waits.
//!
//! Real-time mode, tick k: sleep until the absolute deadline t_k (CLOCK_MONOTONIC, TIMER_ABSTIME),
//! publish state and wrench of tick k, wait on the torque listener's fd (`ppoll`) until
//! budget after the publish (at most until t_k+1) for the torque answering tick k, let the
//! [`PlantTick`] apply it (gate, physics, limits), record. If the thread falls behind by more than
//! a period (a VM stall), the missed deadlines are skipped and counted as overruns instead of
//! being run in a burst.
//!
//! Per tick there is no allocation, no lock, no blocking I/O and no logging: ticks and events go
//! to the recorder's wait-free queue; only rare events (miss streak start, safe stop, takeover,
//! refusal, overrun) are also logged.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use messages::{ControllerDiagnostics, JointState, JointTorque, Wrench};
use rig_process::liveness::PeerWatch;
use rig_process::ports::{Answers, PlantPorts, Wake};
use scenarios::Mode;

use crate::arbiter::{Arbiter, ArbiterEvents, TakeoverReason};
use crate::driver::pacer::Pacer;
use crate::recording::{ControllerStamps, EventKind, EventRecord, Recorder, StageStamps, TimingRecord};
use crate::signals::{ControllerEnd, Signals};
use crate::stack_text::StackText;
use crate::stats::LoopStats;
use crate::tick::{PlantTick, TickOutcome};
use crate::tick_events::EventHandOn;
use rig_process::clock;

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

/// Everything the loop touches.
pub struct PlantLoop<'a> {
    pub ports: &'a PlantPorts,
    /// Physics, gate and limits: the tick itself.
    pub plant: &'a mut PlantTick,
    pub recorder: Option<&'a mut Recorder>,
    pub params: LoopParams,
    /// One controller at a time.
    pub arbiter: &'a mut Arbiter,
    /// Liveness of the active controller's node (None: no watcher, death only by silence).
    pub watch: Option<&'a PeerWatch>,
    /// The host-floor probe's latest wake-up, read once per tick (None: no probe).
    pub probe: Option<&'a crate::probe::Latest>,
    /// Stop requests and `rig`'s reports of the controller's end.
    pub signals: Signals,
}

/// How long [`PlantLoop::wait_for_answers`] waits: see there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Wait {
    /// Until the torque budget's end, whatever the controller's state.
    Budget,
    /// Until the lockstep watchdog, or until the active controller is known gone.
    Watchdog,
}

/// Longest single sleep while waiting for a torque (see `wait_for_answers`).
const WAIT_SLICE: Duration = Duration::from_millis(1);

/// What a run carries from tick to tick: clocks, pacing, the answers buffer, statistics.
pub(crate) struct RunState {
    pub(crate) stats: LoopStats,
    pub(crate) answers: Answers,
    /// The controller's end was reported (and not yet followed by a takeover).
    pub(crate) gone_reported: bool,
    /// One reference instant for both clocks: Instant is CLOCK_MONOTONIC on Linux.
    origin: Instant,
    origin_ns: u64,
    origin_wall_ns: u64,
    /// The grid of the paced ticks.
    pub(crate) pacer: Pacer,
    last_publish_ns: u64,
    /// (publish time, tick) of the first tick a controller answered.
    first_answer: Option<(u64, u64)>,
    /// The plant's tick events to the recorder and the log.
    pub(crate) hand_on: EventHandOn,
}

impl RunState {
    /// The instant of a CLOCK_MONOTONIC time.
    pub(crate) fn at(&self, ns: u64) -> Instant {
        self.origin + Duration::from_nanos(ns.saturating_sub(self.origin_ns))
    }
}

/// A tick's state and wrench as published, with the stamps the record needs (CLOCK_MONOTONIC
/// ns unless named wall).
pub(crate) struct Published {
    pub(crate) state: JointState,
    pub(crate) wrench: Wrench,
    deadline_ns: u64,
    skipped: u64,
    wake_ns: u64,
    publish_wall_ns: u64,
    /// When the state went out; a lockstep start-up that republishes moves it to the last time.
    pub(crate) publish_ns: u64,
    published_ns: u64,
    /// Since the previous tick's publish (0 at the first).
    period_ns: u64,
    /// Wake → publish, the plant's work before the wait.
    pre_ns: u64,
}

impl Published {
    /// End of the torque budget: `budget_ns` after the publish (a plant that woke late must not
    /// blame the controller), but never past the next tick's deadline.
    pub(crate) fn budget_end_ns(&self, p: &LoopParams) -> u64 {
        (self.publish_ns + p.budget_ns).min(self.deadline_ns + p.period_ns)
    }
}

/// What the tick applied, with the answer it chose and when that came.
pub(crate) struct Applied {
    pub(crate) torque: Option<JointTorque>,
    pub(crate) outcome: TickOutcome,
    recv_ns: u64,
    recv_wall_ns: u64,
    diag: Option<ControllerDiagnostics>,
    late_diag: Option<ControllerDiagnostics>,
}

impl PlantLoop<'_> {
    pub(crate) fn event(&mut self, tick: u64, sim_time_s: f64, kind: EventKind, text: &str) {
        if let Some(r) = self.recorder.as_deref_mut() {
            r.record_event(&EventRecord::new(tick, sim_time_s, kind, text));
        }
    }

    fn sim_time_s(&self, tick: u64) -> f64 {
        tick as f64 * self.params.period_ns as f64 * 1e-9
    }

    /// A run starting now: the paced grid's first deadline one period ahead (the probe's grid
    /// placed against it).
    pub(crate) fn start(&self) -> RunState {
        let p = self.params;
        let (origin, origin_ns, origin_wall_ns) = (Instant::now(), clock::now_mono_ns(), clock::now_wall_ns());
        let next_deadline_ns = origin_ns + p.period_ns;
        if let Some(probe) = self.probe {
            probe.set_grid(next_deadline_ns);
        }
        RunState {
            stats: LoopStats::empty(),
            answers: Answers::default(),
            gone_reported: false,
            origin,
            origin_ns,
            origin_wall_ns,
            pacer: Pacer::new(next_deadline_ns, p.period_ns),
            last_publish_ns: 0,
            first_answer: None,
            hand_on: EventHandOn::new(p.period_ns),
        }
    }

    /// Real-time pacing: the deadline of `tick` on the run's grid, slept until (see [`Pacer::pace`]).
    /// Returns (deadline, periods skipped now).
    pub(crate) fn pace(&mut self, run: &mut RunState, tick: u64) -> (u64, u64) {
        run.pacer.pace(tick, &mut run.stats, self.recorder.as_deref_mut())
    }

    /// Publish state and wrench of `tick` (due at `deadline_ns`), and empty the answers buffer
    /// for its answers.
    pub(crate) fn publish(&mut self, run: &mut RunState, tick: u64, deadline_ns: u64, skipped: u64) -> Published {
        let wake_ns = clock::now_mono_ns();
        let (state, wrench) = self.plant.outputs();
        let publish_wall_ns = clock::now_wall_ns();
        let publish_ns = clock::now_mono_ns();
        if let Err(e) = self.ports.publish(&state, &wrench) {
            tracing::error!("{}", rig_process::ports::WithCauses(&e));
            self.event(tick, self.sim_time_s(tick), EventKind::Fault, "publishing the state failed");
        }
        let published_ns = clock::now_mono_ns();
        let period_ns = if run.last_publish_ns == 0 { 0 } else { publish_ns - run.last_publish_ns };
        if self.params.mode == Mode::Realtime && run.last_publish_ns != 0 {
            run.stats.jitter.record(period_ns.abs_diff(self.params.period_ns));
        }
        run.last_publish_ns = publish_ns;
        run.answers.clear();
        Published {
            state,
            wrench,
            deadline_ns,
            skipped,
            wake_ns,
            publish_wall_ns,
            publish_ns,
            published_ns,
            period_ns,
            pre_ns: publish_ns - wake_ns,
        }
    }

    /// The active controller's node is known dead.
    fn active_gone(&self) -> bool {
        self.arbiter.active().is_some_and(|a| self.watch.is_some_and(|w| w.is_gone(a)))
    }

    /// Collect the answers to `tick` into `answers` until the arbiter calls the tick settled (the
    /// active controller answered, see [`Arbiter::settled`]) or `deadline` passes.
    ///
    /// `Wait::Budget` (real time, and a lockstep plant pacing in real time) waits for the answer
    /// until `deadline` whatever the controller's state: also in a safe stop, before the first
    /// controller and while the active controller is known gone, since the tick is settled by
    /// any candidate's answer then and a new controller answering within the budget must be
    /// seen on time to take over. Only a stop signal ends it early. `Wait::Watchdog` (lockstep)
    /// also ends early when the active controller is known gone or its process ended: that
    /// wait may last the whole watchdog.
    ///
    /// Returns the wake-ups lost on the way: wait slices that ran out although a notification
    /// had come and the answer then settled the tick (see `rig_process::ports` on iceoryx2's
    /// notification state; each costs up to one [`WAIT_SLICE`]).
    pub(crate) fn wait_for_answers(&self, tick: u64, deadline: Instant, answers: &mut Answers, wait: Wait) -> u64 {
        let settled = |answers: &Answers| self.arbiter.settled(answers, self.active_gone());
        // Optional busy-wait first: a halted vCPU takes tens of µs to wake on the controller's
        // notification; polling the subscriber (shared memory, no syscall) sees the torque at once.
        if self.params.spin_ns > 0 {
            let spin_end = deadline.min(Instant::now() + Duration::from_nanos(self.params.spin_ns));
            loop {
                self.ports.receive_answers(tick, answers);
                if settled(answers) {
                    // Its notification stays in the listener: the next wait drains it first.
                    return 0;
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
        let mut lost = 0;
        let mut slice_ran_out = false;
        loop {
            // After a slice ran out: notifications that are there woke nobody.
            let unwoken = if slice_ran_out { self.ports.drain_torque_events() } else { 0 };
            self.ports.receive_answers(tick, answers);
            if settled(answers) {
                return lost + u64::from(unwoken > 0);
            }
            if self.signals.stop_requested() {
                return lost;
            }
            if wait == Wait::Watchdog && (self.signals.controller_end_pending() || self.active_gone()) {
                return lost;
            }
            let now = Instant::now();
            if now >= deadline {
                return lost;
            }
            // Not settled: a stranger's (or a late) answer; its notification may still be lost.
            lost += u64::from(unwoken > 0);
            let slice_end = deadline.min(now + WAIT_SLICE);
            slice_ran_out = self.ports.wait_torque(slice_end) == Wake::Timeout && slice_end < deadline;
        }
    }

    /// Record the arbiter's rare events.
    fn report_arbiter(&mut self, tick: u64, t: f64, ev: &ArbiterEvents) {
        if let Some((origin, controller_id)) = ev.ignored {
            let mut s = StackText::new();
            let _ = write!(
                s,
                "tick {tick}: ignoring torques of publisher {:#x} (controller_id {controller_id:#x}): another controller is active",
                origin as u64
            );
            tracing::warn!("{}", s.as_str());
            self.event(tick, t, EventKind::ForeignTorque, s.as_str());
        }
        if let Some((Some(old), new, why)) = ev.takeover {
            let mut s = StackText::new();
            let _ = match why {
                TakeoverReason::Missed(n) => {
                    write!(s, "tick {tick}: publisher {:#x} takes over from {:#x}, which missed {n} ticks in a row", new as u64, old as u64)
                }
                TakeoverReason::Gone => {
                    write!(s, "tick {tick}: publisher {:#x} takes over from {:#x}, whose node is gone", new as u64, old as u64)
                }
                TakeoverReason::First => write!(s, "tick {tick}: publisher {:#x} takes over", new as u64),
            };
            tracing::info!("{}", s.as_str());
            self.event(tick, t, EventKind::ControllerChange, s.as_str());
        }
    }

    /// After the wait: choose the answer to obey (the arbiter), put a controller that is gone
    /// into safe stop, and let the plant apply the torque and integrate the tick. None: a stop
    /// signal came and no torque, so the run ends before this tick is integrated.
    pub(crate) fn apply(&mut self, run: &mut RunState, tick: u64, pb: &Published) -> Option<Applied> {
        let sim_t = self.sim_time_s(tick);
        let active_gone = self.active_gone();
        let (torque, arb_events) = self.arbiter.choose(&run.answers, active_gone, tick);
        if let Some(w) = self.watch {
            w.follow(self.arbiter.active().unwrap_or(0));
        }
        self.report_arbiter(tick, sim_t, &arb_events);
        let recv_ns = clock::now_mono_ns();
        if torque.is_some() && run.first_answer.is_none() {
            run.first_answer = Some((pb.publish_ns, tick));
        }
        let recv_wall_ns = if torque.is_some() { clock::now_wall_ns() } else { 0 };
        let (diag, late_diag) = self.ports.receive_diagnostics_from(self.watch.map_or(0, |w| w.companion()), tick);

        // A controller that is gone (rig reports its process ended, or the watcher saw its
        // node dead) and was not replaced: safe stop now, not after max_consecutive_misses.
        let ended = self.signals.take_controller_end();
        let still_gone = arb_events.takeover.is_none() && torque.is_none() && active_gone;
        if ended.is_some() || (still_gone && !run.gone_reported) {
            run.stats.controller_ended = true;
            run.gone_reported = true;
            let mut s = StackText::new();
            let _ = match ended {
                Some(end @ ControllerEnd::NeverConnected { .. }) => write!(s, "tick {tick}: the controller {end}"),
                Some(end) => write!(s, "tick {tick}: controller process ended ({end})"),
                None => write!(s, "tick {tick}: the active controller's node is dead"),
            };
            tracing::error!("{}", s.as_str());
            self.event(tick, sim_t, EventKind::ControllerEnded, s.as_str());
            if let Some(e) = self.plant.controller_gone() {
                run.hand_on.one(&e, self.recorder.as_deref_mut());
            }
        }
        if arb_events.takeover.is_some() {
            run.gone_reported = false;
        }
        // Stopping (after the controller-end report above is recorded).
        if self.signals.stop_requested() && torque.is_none() {
            run.stats.stopped_by_signal = true;
            return None;
        }
        if self.plant.is_lockstep() {
            crate::tick_events::make_room_for_tick(self.recorder.as_deref_mut());
        }
        let outcome = self.plant.advance(torque.as_ref());
        run.hand_on.hand_on(&outcome.events, self.recorder.as_deref_mut());
        Some(Applied { torque, outcome, recv_ns, recv_wall_ns, diag, late_diag })
    }

    /// Hand the tick to the recorder with its timing (`budget_end_ns`: when the wait for the
    /// torque ended at the latest; `budget_ns`: the budget it had), and count it.
    pub(crate) fn record(&mut self, run: &mut RunState, pb: &Published, a: &Applied, budget_end_ns: u64, budget_ns: u64) {
        let decision = a.outcome.decision;
        let round_trip_ns = if a.torque.is_some() { a.recv_ns - pb.publish_ns } else { 0 };
        if a.torque.is_some() && !decision.missed {
            run.stats.round_trip.record(round_trip_ns);
        }
        if let Some(d) = a.diag.as_ref() {
            run.stats.controller_compute.record(d.compute_time_ns);
        }
        let timing = TimingRecord {
            publish_wall_ns: pb.publish_wall_ns,
            torque_receive_wall_ns: a.recv_wall_ns,
            round_trip_ns,
            period_ns: pb.period_ns,
            missed: decision.missed,
            plant_compute_ns: 0,
            controller_compute_ns: a.diag.map_or(0, |d| d.compute_time_ns),
            stages: None,
        };
        let mut rec = crate::tick::tick_record(pb.state, pb.wrench, &a.outcome, a.diag, timing);
        let done_ns = clock::now_mono_ns();
        let plant_ns = pb.pre_ns + (done_ns - a.recv_ns);
        rec.timing.plant_compute_ns = plant_ns;
        let deadline_ns = pb.deadline_ns;
        let rel = |t: u64| t as i64 - deadline_ns as i64;
        let (probe_late_ns, probe_at_ns) = self.probe.map_or((0, 0), |p| p.take());
        let origin_wall_ns = run.origin_wall_ns;
        let since_start_us = |wall: u64| if wall == 0 { 0.0 } else { (wall as i64 - origin_wall_ns as i64) as f64 * 1e-3 };
        rec.timing.stages = Some(StageStamps {
            deadline_since_start_ns: deadline_ns.saturating_sub(run.origin_ns),
            publish_since_start_us: since_start_us(pb.publish_wall_ns),
            torque_receive_since_start_us: since_start_us(a.recv_wall_ns),
            skipped_periods: pb.skipped.min(u64::from(u32::MAX)) as u32,
            plant_woke_ns: rel(pb.wake_ns),
            state_published_ns: rel(pb.published_ns),
            budget_end_ns: rel(budget_end_ns),
            torque_budget_ns: budget_ns,
            torque_received_ns: rel(a.recv_ns),
            plant_done_ns: rel(done_ns),
            answered: a.torque.is_some(),
            refused: decision.refused.is_some(),
            controller: a.diag.and_then(|d| ControllerStamps::from_diag(&d, deadline_ns)),
            late: a.late_diag.and_then(|d| Some((d.tick, ControllerStamps::from_diag(&d, deadline_ns)?))),
            probe: self.probe.is_some(),
            probe_late_ns,
            probe_stall_from_ns: if probe_late_ns > 0 { rel(probe_at_ns) } else { 0 },
            probe_period_ns: self.probe.map_or(0, |p| p.period_ns()),
        });
        run.stats.plant_compute.record(plant_ns);
        if let Some(r) = self.recorder.as_deref_mut() {
            // Applied torque in the record, plus the controller's own answer (for replay).
            r.record_tick_commanded(&rec, a.torque.as_ref());
        }
    }

    /// The end of a run after `tick` ticks: the statistics, and the goodbye (the last state says
    /// ShuttingDown so controllers exit).
    pub(crate) fn finish(&mut self, mut run: RunState, tick: u64) -> LoopStats {
        let p = self.params;
        let stats = &mut run.stats;
        stats.ticks = tick;
        stats.count_plant(self.plant);
        stats.foreign_answers = self.arbiter.ignored_answers();
        stats.wall_s = (clock::now_mono_ns() - run.origin_ns) as f64 * 1e-9;
        if let Some((t0, k0)) = run.first_answer {
            stats.active_wall_s = (clock::now_mono_ns() - t0) as f64 * 1e-9;
            stats.active_sim_s = (tick - k0) as f64 * p.period_ns as f64 * 1e-9;
        }
        let (last, last_wrench) = self.plant.goodbye();
        let _ = self.ports.publish(&last, &last_wrench);
        let t_end = stats.sim_s;
        let mut s = StackText::new();
        let _ = write!(s, "plant stopped after {tick} ticks ({})", if stats.stopped_by_signal { "signal" } else { "duration reached" });
        self.event(tick, t_end, EventKind::Stop, s.as_str());
        run.stats
    }

    /// The real-time loop: run until `n_ticks` ticks are integrated or a stop signal arrives.
    pub fn run_realtime(&mut self) -> LoopStats {
        let p = self.params;
        let mut run = self.start();
        let mut tick: u64 = self.plant.tick();
        while tick < p.n_ticks {
            if self.signals.stop_requested() {
                run.stats.stopped_by_signal = true;
                break;
            }
            let (deadline_ns, skipped) = self.pace(&mut run, tick);
            let pb = self.publish(&mut run, tick, deadline_ns, skipped);
            // Wait for the torque of this tick (the active controller's; see the arbiter).
            let budget_end_ns = pb.budget_end_ns(&p);
            let lost = self.wait_for_answers(tick, run.at(budget_end_ns), &mut run.answers, Wait::Budget);
            run.stats.note_lost_wakeups(lost);
            let Some(applied) = self.apply(&mut run, tick, &pb) else { break };
            self.record(&mut run, &pb, &applied, budget_end_ns, p.budget_ns);
            tick += 1;
            run.pacer.next();
        }
        self.finish(run, tick)
    }
}
