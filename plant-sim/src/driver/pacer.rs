//! Real-time pacing on an absolute grid of deadlines (CLOCK_MONOTONIC, TIMER_ABSTIME), written
//! once for every real-time driver (the torque loop, a lockstep plant pacing after its watchdog,
//! EGM): if the thread falls behind by more than a period (a VM stall), the missed deadlines are
//! skipped and counted as overruns instead of being run in a burst.

use std::fmt::Write as _;

use crate::recording::{EventKind, Recorder};
use crate::stack_text::StackText;
use crate::stats::LoopStats;
use crate::tick_events::record_event;
use rig_process::clock;

/// The grid of deadlines and the overrun log's rate limit.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    period_ns: u64,
    ticks_per_s: u64,
    /// Next deadline, CLOCK_MONOTONIC ns.
    next_deadline_ns: u64,
    /// (tick, overruns) of the last overrun log line: at most one per second of ticks.
    last_overrun_log: Option<(u64, u64)>,
}

impl Pacer {
    /// A grid whose next deadline is `first_deadline_ns`.
    pub fn new(first_deadline_ns: u64, period_ns: u64) -> Pacer {
        Pacer { period_ns, ticks_per_s: 1_000_000_000 / period_ns.max(1), next_deadline_ns: first_deadline_ns, last_overrun_log: None }
    }

    pub fn next_deadline_ns(&self) -> u64 {
        self.next_deadline_ns
    }

    /// Start the grid again at `deadline_ns` (a lockstep plant that starts pacing).
    pub fn restart_at(&mut self, deadline_ns: u64) {
        self.next_deadline_ns = deadline_ns;
    }

    /// The tick ran: the next deadline is one period on.
    pub fn next(&mut self) {
        self.next_deadline_ns += self.period_ns;
    }

    /// The deadline of `tick`, skipping ahead after a stall (the skipped periods counted in
    /// `stats.overruns`, each stall recorded in `/events` and logged at most once per second of
    /// ticks), slept until. Returns (deadline, periods skipped now).
    pub fn pace(&mut self, tick: u64, stats: &mut LoopStats, recorder: Option<&mut Recorder>) -> (u64, u64) {
        let now = clock::now_mono_ns();
        let (deadline, skipped) = skip_ahead(now, self.next_deadline_ns, self.period_ns);
        if skipped > 0 {
            let late_us = (now - self.next_deadline_ns) / 1000;
            self.next_deadline_ns = deadline;
            stats.overruns += skipped;
            let mut s = StackText::new();
            let _ = write!(s, "tick {tick}: loop {late_us} us late, skipped {skipped} periods");
            // Overruns come in bursts on a stalling host: each is recorded in `/events`, but this
            // SCHED_FIFO thread writes at most one log line per second of ticks about them.
            if self.last_overrun_log.is_none_or(|(l, _)| tick >= l + self.ticks_per_s) {
                let since = self.last_overrun_log.map_or(0, |(_, n)| n);
                tracing::warn!("{} ({} overrun(s) since the last such line)", s.as_str(), stats.overruns - since);
                self.last_overrun_log = Some((tick, stats.overruns));
            }
            let sim_time_s = tick as f64 * self.period_ns as f64 * 1e-9;
            record_event(recorder, tick, sim_time_s, EventKind::Info, s.as_str());
        }
        clock::sleep_until_mono_ns(self.next_deadline_ns);
        (self.next_deadline_ns, skipped)
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
