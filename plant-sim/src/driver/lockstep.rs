//! The plant's lockstep loop (DESIGN section 6): no sleeping; the plant waits for every torque up
//! to the watchdog (`loop.lockstep_watchdog_s`), so the run goes as fast as both processes allow
//! and identical inputs give identical runs.
//!
//! Before the first controller answers, tick 0 is republished every few milliseconds (a
//! late-joining controller gets no history) and the simulation does not advance. When the
//! watchdog expires the controller is presumed gone: the plant counts the miss and continues
//! paced in real time (the real-time loop's pacing and budget waits, `driver/realtime.rs`), so the safe
//! stop is reached after `max_consecutive_misses` periods and a returning controller can take
//! over; its first fresh answer brings the loop back to lockstep.
//!
//! The ports, the tick and the recorder hand-off are the real-time loop's ([`PlantLoop`]).

use std::time::{Duration, Instant};

use messages::PlantStatus;

use crate::driver::realtime::{PlantLoop, Wait};
use crate::recording::EventKind;
use crate::stats::LoopStats;
use rig_process::clock;

/// How long a lockstep plant republishes the waiting state while no controller has answered yet.
const LOCKSTEP_REPUBLISH: Duration = Duration::from_millis(5);

impl PlantLoop<'_> {
    /// The lockstep loop: run until `n_ticks` ticks are integrated or a stop signal arrives.
    pub fn run_lockstep(&mut self) -> LoopStats {
        let p = self.params;
        let mut run = self.start();
        // Paced in real time after the watchdog expired, until a controller answers again.
        let mut paced = false;
        let mut tick: u64 = self.plant.tick();
        while tick < p.n_ticks {
            if self.signals.stop_requested() {
                run.stats.stopped_by_signal = true;
                break;
            }
            let sim_t = tick as f64 * p.period_ns as f64 * 1e-9;
            let (deadline_ns, skipped) = if paced { self.pace(&mut run, tick) } else { (clock::now_mono_ns(), 0) };
            let mut pb = self.publish(&mut run, tick, deadline_ns, skipped);
            // Wait for the torque of this tick (the active controller's; see the arbiter).
            let (budget_end_ns, budget_ns) = if paced {
                let end = pb.budget_end_ns(&p);
                let lost = self.wait_for_answers(tick, run.at(end), &mut run.answers, Wait::Budget);
                run.stats.note_lost_wakeups(lost);
                (end, p.budget_ns)
            } else if self.plant.gate().status() == PlantStatus::WaitingForController {
                // Start-up: hold tick 0 until a controller answers it.
                let end = pb.budget_end_ns(&p);
                // rig's report that the controller ended (or never connected) ends it too.
                while !self.signals.stop_requested() && !self.signals.controller_end_pending() {
                    let lost = self.wait_for_answers(tick, Instant::now() + LOCKSTEP_REPUBLISH, &mut run.answers, Wait::Watchdog);
                    run.stats.note_lost_wakeups(lost);
                    if !run.answers.is_empty() {
                        break;
                    }
                    let _ = self.ports.publish(&pb.state, &pb.wrench);
                    pb.publish_ns = clock::now_mono_ns();
                }
                (end, p.watchdog_ns)
            } else {
                let end = pb.publish_ns + p.watchdog_ns;
                let lost = self.wait_for_answers(tick, run.at(end), &mut run.answers, Wait::Watchdog);
                run.stats.note_lost_wakeups(lost);
                (end, p.watchdog_ns)
            };
            let Some(applied) = self.apply(&mut run, tick, &pb) else { break };
            let decision = applied.outcome.decision;
            if !paced && decision.missed && applied.torque.is_none() {
                // Watchdog expired: pace in real time until a controller answers again.
                paced = true;
                run.pacer.restart_at(clock::now_mono_ns() + p.period_ns);
                let text = if run.gone_reported {
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
            self.record(&mut run, &pb, &applied, budget_end_ns, budget_ns);
            tick += 1;
            if paced {
                run.pacer.next();
            }
        }
        self.finish(run, tick)
    }
}
