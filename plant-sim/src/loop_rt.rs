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

use messages::liveness::PeerWatch;
use messages::ports::{Answers, PlantPorts};
use messages::PlantStatus;
use scenario::Mode;

use crate::arbiter::{Arbiter, ArbiterEvents, TakeoverReason};
use crate::histogram::Histogram;
use crate::recording::{ControllerStamps, EventKind, EventRecord, Recorder, StageStamps, TimingRecord};
use crate::rt;
use crate::tick::{PlantTick, StackText};

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
    /// The plant's counters at the end of a run (misses, safe stops, refusals, reflexes, their
    /// first ticks, simulated time).
    pub fn count_plant(&mut self, plant: &PlantTick) {
        let g = plant.gate();
        self.misses = g.total_misses();
        self.safe_stops = g.safe_stops();
        self.refusals = g.refusals();
        self.reflexes = g.reflexes();
        let f = plant.first_ticks();
        self.first_safe_stop_tick = f.safe_stop;
        self.first_reflex_tick = f.reflex;
        self.first_refusal_tick = f.refusal;
        self.sim_s = plant.physics().time_s();
    }

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

    /// Run until `n_ticks` ticks are integrated or a stop signal arrives.
    pub fn run(&mut self) -> LoopStats {
        let p = self.params;
        let mut stats = LoopStats::empty();
        let mut answers = Answers::default();
        let mut gone_reported = false;
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
        let mut last_publish_ns: u64 = 0;
        let mut tick: u64 = self.plant.tick();
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
            let (state, wrench) = self.plant.outputs();
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
            } else if self.plant.gate().status() == PlantStatus::WaitingForController {
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
                self.plant.controller_gone(self.recorder.as_deref_mut());
            }
            if arb_events.takeover.is_some() {
                gone_reported = false;
            }
            // Stopping (after the controller-end report above is recorded).
            if rt::stop_requested() && torque.is_none() {
                stats.stopped_by_signal = true;
                break;
            }
            let outcome = self.plant.advance(torque.as_ref(), self.recorder.as_deref_mut());
            let decision = outcome.decision;
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
            // 5. Record.
            let round_trip_ns = if torque.is_some() { recv_ns - publish_ns } else { 0 };
            if torque.is_some() && !decision.missed {
                stats.round_trip.record(round_trip_ns);
            }
            if let Some(d) = diag.as_ref() {
                stats.controller_compute.record(d.compute_time_ns);
            }
            let timing = TimingRecord {
                publish_wall_ns,
                torque_receive_wall_ns: recv_wall_ns,
                round_trip_ns,
                period_ns,
                missed: decision.missed,
                plant_compute_ns: 0,
                controller_compute_ns: diag.map_or(0, |d| d.compute_time_ns),
                stages: None,
            };
            let mut rec = crate::tick::tick_record(state, wrench, &outcome, diag, timing);
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

            tick += 1;
            if paced {
                next_deadline_ns += p.period_ns;
            }
        }

        stats.ticks = tick;
        stats.count_plant(self.plant);
        stats.foreign_answers = self.arbiter.ignored_answers();
        stats.wall_s = (rt::now_mono_ns() - origin_ns) as f64 * 1e-9;
        if let Some((t0, k0)) = first_answer {
            stats.active_wall_s = (rt::now_mono_ns() - t0) as f64 * 1e-9;
            stats.active_sim_s = (tick - k0) as f64 * p.period_ns as f64 * 1e-9;
        }

        // Goodbye: the last state says ShuttingDown so controllers exit.
        let (last, last_wrench) = self.plant.goodbye();
        let _ = self.ports.publish(&last, &last_wrench);
        let t_end = stats.sim_s;
        let mut s = StackText::new();
        let _ = write!(s, "plant stopped after {tick} ticks ({})", if stats.stopped_by_signal { "signal" } else { "duration reached" });
        self.event(tick, t_end, EventKind::Stop, s.as_str());
        stats
    }
}

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
