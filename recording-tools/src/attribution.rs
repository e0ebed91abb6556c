//! Whose fault is a miss: every missed tick of a real-time run attributed to one cause from its
//! stage stamps (`/timing`), and the control success rate (libfranka's figure of merit). One
//! function, [`attribute`], serves `rig timing` and `rig report`; the rules are the README's
//! ("Timing: whose fault is a miss") and [`cause_of`]'s.
//!
//! Shares of the torque budget B (`loop.torque_budget_us`, counted from the state's publish):
//! the controller's wake-up 20 % ([`WAKE_SHARE`]), its compute (woke → torque handed to
//! iceoryx2) 70 %, the transport back 10 %.

use crate::read::TimingRow;
use recordings::{ControllerStamps, StageStamps};

/// Share of the budget for the controller's wake-up (publish → controller woke).
pub const WAKE_SHARE: f64 = 0.2;
/// Share of the budget for the controller's compute (woke → torque handed to iceoryx2).
pub const COMPUTE_SHARE: f64 = 0.7;
/// A probe wake-up later than this is a host stall (defined with the record it is judged from).
pub use recordings::HOST_STALL_NS;
/// Stalls that count for a missed tick are those overlapping its deadline's period before (more
/// before skipped periods) up to this many periods after its deadline (the budget and a late
/// publish end before that), or up to the plant's finish if that was later.
const STALL_LOOKAHEAD_PERIODS: i64 = 2;
/// The sliding window of the success rate, periods (100 ms at 1 kHz).
pub const WINDOW_PERIODS: usize = 100;

/// The one cause of a missed tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cause {
    /// The host stalled: the probe saw a stall in the tick long enough to explain the miss (the
    /// plant woke late, or the controller's stage over its share was covered by the stall).
    Host,
    /// The plant woke or published so late that the budget was cut, and no host stall was seen:
    /// the rig's own.
    PlantLate,
    /// The controller woke later than its share after the publish.
    ControllerWake,
    /// The controller's compute exceeded its share of the budget.
    ControllerCompute,
    /// The controller handed the torque over within the budget, the plant got it too late.
    Transport,
    /// No answer within the budget and no stamps telling why (it never answered, or it does not
    /// stamp).
    NoAnswer,
    /// An answer came in time but was refused (non-finite, beyond the limits, another version).
    Refused,
}

impl Cause {
    pub const ALL: [Cause; 7] =
        [Cause::Host, Cause::PlantLate, Cause::ControllerWake, Cause::ControllerCompute, Cause::Transport, Cause::NoAnswer, Cause::Refused];

    pub fn name(self) -> &'static str {
        match self {
            Cause::Host => "host stall (probe saw it)",
            Cause::PlantLate => "plant late (no host stall seen)",
            Cause::ControllerWake => "controller woke late",
            Cause::ControllerCompute => "controller compute over its share",
            Cause::Transport => "transport (published in time, received late)",
            Cause::NoAnswer => "controller never answered",
            Cause::Refused => "torque refused",
        }
    }

    /// Misses of the rig or the controller itself (every cause but the host's).
    pub fn is_own(self) -> bool {
        self != Cause::Host
    }
}

/// A host stall the probe saw: from the deadline its wake-up was late for, that long; ns
/// relative to the deadline of the tick being attributed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stall {
    pub from_ns: i64,
    pub to_ns: i64,
}

/// The longest any of `stalls` overlaps [a, b].
fn overlap(stalls: &[Stall], a: i64, b: i64) -> i64 {
    stalls.iter().map(|s| (s.to_ns.min(b) - s.from_ns.max(a)).max(0)).max().unwrap_or(0)
}

/// The cause of one missed tick from its plant stamps `t`, the controller's stamps of that tick
/// `ctrl` (its own, or a late answer's, relative to this tick's deadline), and the host stalls
/// the probe reported with this tick and the ones before and after it (none without the probe).
/// A stall counts where it overlaps the stage in question. First match wins:
///
/// 1. the answer came in time but was refused: [`Cause::Refused`];
/// 2. the plant skipped periods before the tick or woke so late that its budget was cut at the
///    next deadline: [`Cause::Host`] if a stall of at least [`HOST_STALL_NS`] overlaps the time
///    before it woke, else [`Cause::PlantLate`];
/// 3. no controller stamps: [`Cause::Host`] if a stall overlaps the budget (publish to its end)
///    by at least the compute share, else [`Cause::NoAnswer`];
/// 4. the controller handed the torque over before the budget's end: [`Cause::Transport`], the
///    host's if a stall covers the rest of the budget (or [`HOST_STALL_NS`] of it);
/// 5. it handed it over after the end: of its wake-up and its compute, the stage furthest over
///    its share ([`Cause::ControllerWake`] or [`Cause::ControllerCompute`]); the host's instead
///    if a stall overlaps that stage by both its excess and the overshoot past the budget's end
///    (had the host not stalled, the answer would have been in time).
pub fn cause_of(t: &StageStamps, ctrl: Option<ControllerStamps>, stalls: &[Stall]) -> Cause {
    let budget = t.torque_budget_ns as i64;
    let host_stall = HOST_STALL_NS as i64;
    if t.answered && t.refused {
        return Cause::Refused;
    }
    // Cut: the budget ends at the next deadline, earlier than a full budget after the publish
    // (which follows the wake-up by a few µs).
    if t.skipped_periods > 0 || t.budget_end_ns - t.plant_woke_ns < budget {
        return if overlap(stalls, i64::MIN / 2, t.plant_woke_ns) >= host_stall { Cause::Host } else { Cause::PlantLate };
    }
    let wake_share = (WAKE_SHARE * budget as f64) as i64;
    let compute_share = (COMPUTE_SHARE * budget as f64) as i64;
    let Some(c) = ctrl else {
        let host = overlap(stalls, t.state_published_ns, t.budget_end_ns) >= compute_share;
        return if host { Cause::Host } else { Cause::NoAnswer };
    };
    if c.published_ns <= t.budget_end_ns {
        let rest = t.budget_end_ns - c.published_ns;
        let host = overlap(stalls, c.published_ns, t.budget_end_ns + host_stall) >= rest.clamp(1, host_stall);
        return if host { Cause::Host } else { Cause::Transport };
    }
    let wake_excess = c.woke_ns - t.state_published_ns - wake_share;
    let compute_excess = c.published_ns - c.woke_ns - compute_share;
    let (cause, excess, stage) = if wake_excess > compute_excess {
        (Cause::ControllerWake, wake_excess, (t.state_published_ns, c.woke_ns))
    } else {
        (Cause::ControllerCompute, compute_excess, (c.woke_ns, c.published_ns))
    };
    let overshoot = c.published_ns - t.budget_end_ns;
    if overlap(stalls, stage.0, stage.1) >= excess.max(overshoot) {
        Cause::Host
    } else {
        cause
    }
}

/// A run of consecutive host-attributed periods (skipped ones and host misses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Burst {
    /// The first tick after the stall (or the first host-missed tick).
    pub tick: u64,
    /// Periods lost to the host in the burst (skipped plus missed).
    pub periods: u64,
    /// Its start, ms after the run's first deadline.
    pub at_ms: f64,
}

/// Attribution of a whole run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Attribution {
    /// The run carried stage stamps (recordings before them: only success rates).
    pub stamped: bool,
    /// The host-floor probe ran.
    pub probe: bool,
    /// Periods from the first answered tick to the end, skipped ones included.
    pub periods: u64,
    /// Ticks answered within the budget (and applied).
    pub answered_in_budget: u64,
    /// Missed ticks from the first answer on.
    pub misses: u64,
    /// Periods skipped by the plant (host stalls longer than a period).
    pub skipped_periods: u64,
    /// Misses per cause, in [`Cause::ALL`] order.
    pub by_cause: [u64; 7],
    /// Every missed tick and its cause.
    pub missed_ticks: Vec<(u64, Cause)>,
    /// Ticks whose probe wake-up was a stall (≥ [`HOST_STALL_NS`]).
    pub probe_stall_ticks: u64,
    /// Host bursts of at least 10 periods.
    pub bursts: Vec<Burst>,
    /// Control success rate over the run: answered in budget / periods.
    pub success_rate: f64,
    /// The worst success rate over any [`WINDOW_PERIODS`] consecutive periods, and the tick its
    /// window starts at.
    pub worst_window: Option<(f64, u64)>,
}

impl Attribution {
    pub fn count(&self, c: Cause) -> u64 {
        self.by_cause[Cause::ALL.iter().position(|&x| x == c).unwrap_or(0)]
    }
    /// Misses of the rig or the controller itself, and their rate per period.
    pub fn own_misses(&self) -> u64 {
        Cause::ALL.iter().filter(|c| c.is_own()).map(|&c| self.count(c)).sum()
    }
    pub fn own_miss_rate(&self) -> f64 {
        if self.periods == 0 {
            0.0
        } else {
            self.own_misses() as f64 / self.periods as f64
        }
    }
    /// The cause of tick `tick`, if it missed.
    pub fn cause_of_tick(&self, tick: u64) -> Option<Cause> {
        self.missed_ticks.binary_search_by_key(&tick, |m| m.0).ok().map(|i| self.missed_ticks[i].1)
    }
}

/// Attribute every miss of a run from its `/timing` rows (in tick order), and its success rates.
/// Ticks before the first answered one (the plant waiting for a controller) do not count.
pub fn attribute(rows: &[TimingRow]) -> Attribution {
    let mut a = Attribution { stamped: rows.iter().any(|r| r.timing.stages.is_some()), ..Default::default() };
    a.probe = rows.iter().any(|r| r.timing.stages.is_some_and(|s| s.probe));
    let Some(first) = rows.iter().position(|r| r.timing.torque_receive_wall_ns != 0 || r.timing.stages.is_some_and(|s| s.answered)) else {
        return a;
    };
    let rows = &rows[first..];
    // Controller stamps of a tick that arrived late, from the rows after it: relative to the
    // deadline of the row they came with, moved to the late tick's own deadline.
    let late_stamps = |i: usize| -> Option<ControllerStamps> {
        let tick = rows[i].tick;
        let d0 = rows[i].timing.stages?.deadline_since_start_ns as i64;
        rows[i + 1..].iter().take(4).find_map(|r| {
            let s = r.timing.stages?;
            let (k, c) = s.late?;
            let shift = s.deadline_since_start_ns as i64 - d0;
            (k == tick).then_some(ControllerStamps {
                woke_ns: c.woke_ns + shift,
                computed_ns: c.computed_ns + shift,
                published_ns: c.published_ns + shift,
            })
        })
    };
    // Success per period: index = periods since the first answered tick's deadline.
    let period_ns = rows.windows(2).filter_map(|w| {
        let (a, b) = (w[0].timing.stages?, w[1].timing.stages?);
        (b.skipped_periods == 0).then(|| b.deadline_since_start_ns.saturating_sub(a.deadline_since_start_ns))
    });
    let period_ns = median(period_ns.collect()).unwrap_or(1_000_000).max(1);
    let d_first = rows[0].timing.stages.map_or(0, |s| s.deadline_since_start_ns);
    let mut ok: Vec<bool> = Vec::with_capacity(rows.len());
    let mut host_periods: Vec<u64> = Vec::new(); // per period index: 1 if lost to the host
    let mut mark = |idx: usize, success: bool, host: bool, ok: &mut Vec<bool>| {
        if ok.len() <= idx {
            ok.resize(idx + 1, false);
            host_periods.resize(idx + 1, 0);
        }
        ok[idx] = success;
        if host {
            host_periods[idx] = 1;
        }
    };
    // Every wake-up the probe reported, on the run's time line (ns since its start), by start: a
    // stall is reported at the plant's first tick after the probe woke, so one that held a CPU
    // for 7 ms is reported 7 ticks after the first tick it cost; it is found by time, not by row.
    // A stall counts from the deadline the probe was late for to its wake-up: the CPU was surely
    // not the probe's (FIFO 90, the highest there) for that long. It may have begun up to a probe
    // period earlier, but nothing shows it did; counting that period too handed the host a
    // controller's 720 µs overrun for a 142 µs late probe (a stall of two CPUs' merged report
    // need not even be the controller's CPU).
    let mut seen: Vec<Stall> = rows
        .iter()
        .filter_map(|r| r.timing.stages.filter(|o| o.probe && o.probe_late_ns > 0))
        .map(|o| {
            let at = o.deadline_since_start_ns as i64 + o.probe_stall_from_ns;
            Stall { from_ns: at, to_ns: at + o.probe_late_ns as i64 }
        })
        .collect();
    seen.sort_by_key(|s| s.from_ns);
    let longest_ns = seen.iter().map(|s| s.to_ns - s.from_ns).max().unwrap_or(0);
    for (i, r) in rows.iter().enumerate() {
        let t = &r.timing;
        let idx = match t.stages {
            Some(s) => ((s.deadline_since_start_ns.saturating_sub(d_first) + period_ns / 2) / period_ns) as usize,
            None => (r.tick - rows[0].tick) as usize,
        };
        let mut host = false;
        if let Some(s) = t.stages {
            a.skipped_periods += u64::from(s.skipped_periods);
            if s.probe && s.probe_late_ns >= HOST_STALL_NS {
                a.probe_stall_ticks += 1;
            }
            // The probe's latest wake-up within a tick either side: it reports a stall when it
            // runs again, which may be before or after the plant's next tick.
            let probe_near = rows[i.saturating_sub(1)..rows.len().min(i + 2)]
                .iter()
                .filter_map(|n| n.timing.stages)
                .map(|n| n.probe_late_ns)
                .max()
                .unwrap_or(0);
            if s.skipped_periods > 0 {
                let lost_host = probe_near >= HOST_STALL_NS;
                for k in 1..=s.skipped_periods as usize {
                    if idx >= k {
                        mark(idx - k, false, lost_host, &mut ok);
                    }
                }
            }
            if t.missed {
                let ctrl = s.controller.or_else(|| late_stamps(i));
                // The stalls around this tick, on its time line (ns from its deadline).
                let d = s.deadline_since_start_ns as i64;
                let p = period_ns as i64;
                // ... up to the plant's finish when that was later (a plant woken 5 ms late).
                let (lo, hi) = (d - (i64::from(s.skipped_periods) + 1) * p, d + (STALL_LOOKAHEAD_PERIODS * p).max(s.plant_done_ns));
                let end = seen.partition_point(|x| x.from_ns < hi);
                let begin = seen[..end].partition_point(|x| x.from_ns < lo - longest_ns);
                let stalls: Vec<Stall> = seen[begin..end]
                    .iter()
                    .filter(|x| x.to_ns > lo)
                    .map(|x| Stall { from_ns: x.from_ns - d, to_ns: x.to_ns - d })
                    .collect();
                let c = cause_of(&s, ctrl, &stalls);
                host = c == Cause::Host;
                a.by_cause[Cause::ALL.iter().position(|&x| x == c).unwrap()] += 1;
                a.missed_ticks.push((r.tick, c));
            }
        }
        if t.missed {
            a.misses += 1;
        } else {
            a.answered_in_budget += 1;
        }
        mark(idx, !t.missed, host, &mut ok);
    }
    a.periods = ok.len() as u64;
    a.success_rate = if ok.is_empty() { 0.0 } else { a.answered_in_budget as f64 / ok.len() as f64 };
    if ok.len() >= WINDOW_PERIODS {
        let mut n = ok[..WINDOW_PERIODS].iter().filter(|&&x| x).count();
        let mut worst = (n, 0usize);
        for s in 1..=ok.len() - WINDOW_PERIODS {
            n = n + usize::from(ok[s + WINDOW_PERIODS - 1]) - usize::from(ok[s - 1]);
            if n < worst.0 {
                worst = (n, s);
            }
        }
        let start_tick = rows
            .iter()
            .find(|r| {
                r.timing
                    .stages
                    .map_or(r.tick - rows[0].tick, |s| (s.deadline_since_start_ns.saturating_sub(d_first) + period_ns / 2) / period_ns)
                    >= worst.1 as u64
            })
            .map_or(rows[0].tick, |r| r.tick);
        a.worst_window = Some((worst.0 as f64 / WINDOW_PERIODS as f64, start_tick));
    }
    // Host bursts: runs of host-lost periods (gaps of up to 2 periods joined), 10 or more long.
    let mut i = 0;
    while i < host_periods.len() {
        if host_periods[i] == 0 {
            i += 1;
            continue;
        }
        let (start, mut end, mut n) = (i, i, 0u64);
        while end < host_periods.len() && (host_periods[end] == 1 || host_periods[end..host_periods.len().min(end + 3)].contains(&1)) {
            n += host_periods[end];
            end += 1;
        }
        if n >= 10 {
            let tick = rows
                .iter()
                .find(|r| {
                    r.timing
                        .stages
                        .is_some_and(|s| (s.deadline_since_start_ns.saturating_sub(d_first) + period_ns / 2) / period_ns >= start as u64)
                })
                .map_or(0, |r| r.tick);
            a.bursts.push(Burst { tick, periods: n, at_ms: (d_first + start as u64 * period_ns) as f64 * 1e-6 });
        }
        i = end;
    }
    a
}

fn median(mut v: Vec<u64>) -> Option<u64> {
    if v.is_empty() {
        return None;
    }
    v.sort_unstable();
    Some(v[v.len() / 2])
}

/// The cause table as text (`rig timing`, `rig report`).
pub fn format_table(a: &Attribution) -> String {
    let mut s = String::new();
    if a.periods == 0 {
        return s;
    }
    s += &format!("control success rate {:.5} ({} of {} periods answered in budget)", a.success_rate, a.answered_in_budget, a.periods);
    match a.worst_window {
        Some((w, tick)) => s += &format!(", worst {WINDOW_PERIODS}-period window {w:.2} (from tick {tick})\n"),
        None => s += "\n",
    }
    if !a.stamped {
        s += "misses not attributed: the recording has no stage stamps\n";
        return s;
    }
    s += "| cause of a miss | misses | rate |\n| --- | --- | --- |\n";
    let rate = |n: u64| n as f64 / a.periods as f64;
    for c in Cause::ALL {
        let n = a.count(c);
        s += &format!("| {} | {n} | {:.1e} |\n", c.name(), rate(n));
    }
    s += &format!("| all misses | {} | {:.1e} |\n", a.misses, rate(a.misses));
    s += &format!("| the rig's and controller's own (all but the host's) | {} | {:.1e} |\n", a.own_misses(), a.own_miss_rate());
    s += &format!("periods skipped by the plant (stalls > 1 period) {}", a.skipped_periods);
    if a.probe {
        s += &format!(", ticks with a probe stall (wake-up >= {} us) {}\n", HOST_STALL_NS / 1000, a.probe_stall_ticks);
    } else {
        s += "; the host probe did not run (rig timing runs it): host stalls show as plant-late or controller misses\n";
    }
    for b in &a.bursts {
        s += &format!("host burst: {} periods lost from tick {} ({:.1} ms into the run)\n", b.periods, b.tick, b.at_ms);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use recordings::TimingRecord;

    const B: i64 = 500_000;

    /// An on-time tick: woke 5 µs, published 10 µs after its deadline, budget to 510 µs.
    fn stamps() -> StageStamps {
        StageStamps {
            plant_woke_ns: 5_000,
            state_published_ns: 10_000,
            budget_end_ns: 10_000 + B,
            torque_budget_ns: B as u64,
            torque_received_ns: 60_000,
            plant_done_ns: 90_000,
            answered: true,
            ..Default::default()
        }
    }

    fn missed() -> StageStamps {
        StageStamps { answered: false, torque_received_ns: 10_000 + B, ..stamps() }
    }

    fn ctrl(woke_us: i64, published_us: i64) -> ControllerStamps {
        ControllerStamps { woke_ns: woke_us * 1000, computed_ns: published_us * 1000 - 1000, published_ns: published_us * 1000 }
    }

    /// A stall from `from_us` for `len_us` after the deadline.
    fn stall(from_us: i64, len_us: i64) -> Vec<Stall> {
        vec![Stall { from_ns: from_us * 1000, to_ns: (from_us + len_us) * 1000 }]
    }

    #[test]
    fn each_cause_once_from_synthetic_stamps() {
        // Refused: it came in time, the gate refused it.
        assert_eq!(cause_of(&StageStamps { refused: true, ..stamps() }, Some(ctrl(20, 40)), &[]), Cause::Refused);
        // The plant woke 695 µs late, so its budget was cut at the next deadline; the probe was
        // stalled for 690 µs from its deadline 0.5 ms before ours: the host. Without: the plant's own.
        let late_plant = StageStamps { plant_woke_ns: 695_000, state_published_ns: 700_000, budget_end_ns: 1_000_000, ..missed() };
        assert_eq!(cause_of(&late_plant, None, &stall(-500, 1190)), Cause::Host);
        assert_eq!(cause_of(&late_plant, None, &[]), Cause::PlantLate);
        // Skipped periods before the tick, the probe stalled 3 ms just before: host.
        assert_eq!(cause_of(&StageStamps { skipped_periods: 3, ..missed() }, None, &stall(-3500, 3000)), Cause::Host);
        // Controller woke 450 µs after the publish, computed 20 µs: over its wake share (100 µs).
        assert_eq!(cause_of(&missed(), Some(ctrl(460, 530)), &[]), Cause::ControllerWake);
        // Woke 10 µs after the publish, computed 700 µs (share 350 µs).
        assert_eq!(cause_of(&missed(), Some(ctrl(20, 720)), &[]), Cause::ControllerCompute);
        // Handed over at 480 µs (budget end 510 µs), not received by then: transport.
        assert_eq!(cause_of(&missed(), Some(ctrl(20, 480)), &[]), Cause::Transport);
        // No answer, no stamps.
        assert_eq!(cause_of(&missed(), None, &[]), Cause::NoAnswer);
    }

    #[test]
    fn the_host_takes_a_miss_only_when_its_stall_overlaps_the_stage_enough() {
        // Compute from 20 to 720 µs: 350 µs over its share, 210 µs past the budget's end.
        let c = Some(ctrl(20, 720));
        assert_eq!(cause_of(&missed(), c, &stall(100, 300)), Cause::ControllerCompute, "300 µs do not cover a 350 µs excess");
        assert_eq!(cause_of(&missed(), c, &stall(100, 360)), Cause::Host);
        // The same stall, but outside the compute (before the deadline, or after the answer).
        assert_eq!(cause_of(&missed(), c, &stall(-900, 360)), Cause::ControllerCompute);
        assert_eq!(cause_of(&missed(), c, &stall(730, 5000)), Cause::ControllerCompute);
        // A plant that woke late while a stall of under 100 µs ran is late by itself.
        let late_plant = StageStamps { plant_woke_ns: 695_000, state_published_ns: 700_000, budget_end_ns: 1_000_000, ..missed() };
        assert_eq!(cause_of(&late_plant, None, &stall(0, 99)), Cause::PlantLate);
        // Transport: handed over 30 µs before the end; a stall over those 30 µs is the host's.
        assert_eq!(cause_of(&missed(), Some(ctrl(20, 480)), &stall(470, 20)), Cause::Transport);
        assert_eq!(cause_of(&missed(), Some(ctrl(20, 480)), &stall(470, 45)), Cause::Host);
        // No stamps: only a stall over the compute share (350 µs) of the budget explains it.
        assert_eq!(cause_of(&missed(), None, &stall(20, 349)), Cause::NoAnswer);
        assert_eq!(cause_of(&missed(), None, &stall(20, 350)), Cause::Host);
    }

    fn row(tick: u64, s: StageStamps, missed: bool) -> TimingRow {
        let s = StageStamps { deadline_since_start_ns: tick * 1_000_000, probe: true, ..s };
        TimingRow {
            tick,
            timing: TimingRecord { missed, torque_receive_wall_ns: u64::from(s.answered), stages: Some(s), ..Default::default() },
            recorder_dropped: 0,
        }
    }

    #[test]
    fn a_run_late_answers_skips_and_windows() {
        // 1000 ticks answered; tick 300 answered late (its stamps arrive with tick 301), tick 600
        // follows a 50-period stall the probe saw (skips), tick 800 is not answered at all.
        let mut rows = Vec::new();
        let mut deadline_shift = 0;
        for k in 0..1000u64 {
            let mut s = stamps();
            let mut m = false;
            if k == 300 {
                s = missed();
                m = true;
            }
            if k == 301 {
                // Tick 300's diagnostics: woke 20 µs after its deadline, handed over 720 µs after,
                // i.e. -980 µs and -280 µs relative to tick 301's deadline.
                s.late = Some((300, ControllerStamps { woke_ns: -980_000, computed_ns: -281_000, published_ns: -280_000 }));
            }
            if k == 600 {
                deadline_shift = 50;
                // The probe was late by 50.3 ms for its deadline 50.5 ms before this one.
                s = StageStamps { skipped_periods: 50, probe_late_ns: 50_300_000, probe_stall_from_ns: -50_500_000, ..missed() };
                m = true;
            }
            if k == 800 {
                s = missed();
                m = true;
            }
            let mut r = row(k, s, m);
            if let Some(st) = r.timing.stages.as_mut() {
                st.deadline_since_start_ns = (k + deadline_shift) * 1_000_000;
            }
            rows.push(r);
        }
        let a = attribute(&rows);
        assert_eq!(a.missed_ticks, vec![(300, Cause::ControllerCompute), (600, Cause::Host), (800, Cause::NoAnswer)]);
        assert_eq!((a.count(Cause::Host), a.own_misses(), a.skipped_periods), (1, 2, 50));
        assert_eq!(a.periods, 1050);
        assert_eq!(a.answered_in_budget, 997);
        assert!((a.success_rate - 997.0 / 1050.0).abs() < 1e-12);
        // The worst 100-period window holds the 50 skipped periods and the miss after them.
        let (w, _) = a.worst_window.unwrap();
        assert!((w - 0.49).abs() < 1e-12, "{w}");
        assert_eq!(a.bursts.len(), 1);
        assert_eq!((a.bursts[0].periods, a.bursts[0].tick), (51, 600));
        let text = format_table(&a);
        assert!(text.contains("| controller compute over its share | 1 |") && text.contains("host burst: 51 periods"), "{text}");
    }

    /// Ticks 0..10 answered, tick 5 not answered; the probe's report of a stall comes with tick
    /// 6: late `late_us` for its deadline `at_us` after tick 5's, on a `period_us` grid.
    fn stall_after_no_answer(period_us: u64, at_us: i64, late_us: u64) -> Cause {
        let rows: Vec<TimingRow> = (0..10u64)
            .map(|k| match k {
                5 => row(k, StageStamps { probe_period_ns: period_us * 1000, ..missed() }, true),
                6 => row(
                    k,
                    StageStamps {
                        probe_period_ns: period_us * 1000,
                        probe_late_ns: late_us * 1000,
                        probe_stall_from_ns: (at_us - 1000) * 1000,
                        ..stamps()
                    },
                    false,
                ),
                _ => row(k, StageStamps { probe_period_ns: period_us * 1000, ..stamps() }, false),
            })
            .collect();
        attribute(&rows).cause_of_tick(5).unwrap()
    }

    /// A 7 ms stall of the controller's CPU from 125 µs after tick 5's deadline, as seen on
    /// 2026-12-02 (ticks 14884-14890 of a `rig timing` run): ticks 5..=11 get no answer, and the
    /// probe on that CPU reports its wake-up only with tick 12, seven rows after the first tick the
    /// stall cost. Every one of those misses is the host's.
    #[test]
    fn a_long_stall_reported_many_ticks_later_takes_every_tick_it_covered() {
        let rows: Vec<TimingRow> = (0..20u64)
            .map(|k| match k {
                5..=11 => row(k, StageStamps { probe_period_ns: 250_000, ..missed() }, true),
                12 => row(
                    k,
                    StageStamps { probe_period_ns: 250_000, probe_late_ns: 6_866_799, probe_stall_from_ns: -6_875_000, ..stamps() },
                    false,
                ),
                _ => row(k, StageStamps { probe_period_ns: 250_000, ..stamps() }, false),
            })
            .collect();
        let a = attribute(&rows);
        let causes: Vec<Cause> = (5..=11).map(|k| a.cause_of_tick(k).unwrap()).collect();
        assert_eq!(causes, vec![Cause::Host; 7]);
        // The same stall reported with no tick near it is nobody's excuse: a miss 5 ms after it
        // ended is the controller's.
        let mut rows = rows;
        rows[17] = row(17, StageStamps { probe_period_ns: 250_000, ..missed() }, true);
        assert_eq!(attribute(&rows).cause_of_tick(17), Some(Cause::NoAnswer));
    }

    /// Tick 2978 of a `rig timing` run on 2026-12-02: the plant woke 5.62 ms after its deadline,
    /// and the probe's report in the same row says it was 1.63 ms late for its deadline 2.875 ms
    /// after the plant's: a stall inside the time the plant slept past its deadline, more than
    /// two periods after the deadline. The host's; without that report, the plant's own.
    #[test]
    fn a_plant_woken_ms_late_is_the_hosts_if_the_probe_saw_a_stall_before_it_woke() {
        let late = StageStamps {
            probe_period_ns: 250_000,
            plant_woke_ns: 5_622_000,
            state_published_ns: 5_670_000,
            budget_end_ns: 1_000_000,
            torque_received_ns: 5_673_000,
            plant_done_ns: 5_696_000,
            ..missed()
        };
        let rows = |probe_late_ns: u64| -> Vec<TimingRow> {
            (0..12u64)
                .map(|k| match k {
                    5 => row(k, StageStamps { probe_late_ns, probe_stall_from_ns: 2_875_000, ..late }, true),
                    _ => row(k, StageStamps { probe_period_ns: 250_000, ..stamps() }, false),
                })
                .collect()
        };
        assert_eq!(attribute(&rows(1_630_000)).cause_of_tick(5), Some(Cause::Host));
        assert_eq!(attribute(&rows(0)).cause_of_tick(5), Some(Cause::PlantLate));
    }

    /// A stall counts from the deadline the probe was late for, not from its previous one: the
    /// probe shows the CPU was not its own from then until it woke, and nothing earlier. Tick 5's
    /// budget runs from its publish at +10 µs to +510 µs; the controller's share is 350 µs.
    #[test]
    fn a_stall_counts_from_the_deadline_the_probe_was_late_for() {
        // A 1 ms probe late at +500 µs (by 546 µs): 10 µs of the budget, the controller's miss.
        assert_eq!(stall_after_no_answer(1000, 500, 546), Cause::NoAnswer);
        // Late at +100 µs instead: the host took 410 µs of the budget.
        assert_eq!(stall_after_no_answer(1000, 100, 546), Cause::Host);
        // A 250 µs probe late at +625 or +375 µs: 0 and 135 µs of the budget, under the share.
        assert_eq!(stall_after_no_answer(250, 625, 700), Cause::NoAnswer);
        assert_eq!(stall_after_no_answer(250, 375, 700), Cause::NoAnswer);
        // Late at +125 µs: 385 µs of it.
        assert_eq!(stall_after_no_answer(250, 125, 700), Cause::Host);
    }
}
