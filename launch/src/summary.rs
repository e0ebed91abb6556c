//! Human-readable summaries of a run and of a timing run, from the plant's summary
//! ([`PlantSummary`], every field required: a line without one never gets here).

use recording_tools::report::ReportNumbers;
use recordings::plant_summary::{Distribution, HostProbe, PlantSummary};

/// The summary of `rig run`: ticks, misses, safe stops, round-trip latency p50/p99/max (the
/// recording follows in [`recording_summary`]).
pub fn run_summary(v: &PlantSummary) -> String {
    let mut s = String::new();
    s += &format!(
        "ticks {}  misses {}  safe stops {}  refused {}  overruns {}  recorder drops {}\n",
        v.ticks, v.misses, v.safe_stops, v.refusals, v.overruns, v.drops
    );
    s += &format!("round trip  p50 {:.1} us  p99 {:.1} us  max {:.1} us\n", v.rt_p50_us, v.rt_p99_us, v.rt_max_us);
    let mode = v.mode.name();
    if v.ticks == 0 {
        // Not "(0.0x real time)": nothing ran (in lockstep: no controller answered tick 0).
        s += &format!("mode {mode}  nothing simulated in {:.3} s wall: no tick was integrated\n", v.wall_s);
    } else {
        s += &format!("mode {mode}  simulated {:.3} s in {:.3} s wall ({:.1}x real time)\n", v.sim_s, v.wall_s, v.speed_factor);
    }
    if let Some(live) = &v.live {
        s += &format!("live view   ws://{}  {} messages sent, {} dropped\n", live.addr, live.sent, live.dropped);
    }
    s
}

/// The recording part of `rig run`'s summary, each line once: the report's numbers when the file
/// reads back (their first line names it, a warning line says how it ends if not complete), else
/// the path alone; plus one line with the plant's reason if the recording stopped early and the
/// file does not say so itself.
pub fn recording_summary(v: &PlantSummary, numbers: Option<&ReportNumbers>) -> String {
    let mut s = match numbers {
        Some(n) => recording_tools::report::format_text(n),
        None => format!("recording   {}\n", v.recording.as_deref().unwrap_or("(not recorded)")),
    };
    if let Some(why) = &v.recording_stopped_early {
        if numbers.is_none_or(|n| n.integrity != "stopped_early") {
            s += &format!("WARNING     the plant stopped the recording early: {why}\n");
        }
    }
    s
}

fn plural(n: u64, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// What keeps a run that reached its end from exit status 0, from the plant's summary: reflexes,
/// safe stops, refused torques (each with its count and first tick), a recording stopped early
/// (`recording_stopped_early`: its reason, null when complete) or with ticks the recorder
/// dropped. Misses alone are not incidents (real time on a noisy host).
pub fn incidents(v: &PlantSummary) -> Vec<String> {
    let mut out = Vec::new();
    let first = |k: Option<u64>| k.map_or(String::new(), |k| format!(" (first at tick {k})"));
    for (n, first_tick, one, many) in [
        (v.reflexes, v.first_reflex_tick, "reflex", "reflexes"),
        (v.safe_stops, v.first_safe_stop_tick, "safe stop", "safe stops"),
        (v.refusals, v.first_refusal_tick, "refused torque", "refused torques"),
    ] {
        if n > 0 {
            out.push(format!("{}{}", plural(n, one, many), first(first_tick)));
        }
    }
    if let Some(why) = &v.recording_stopped_early {
        out.push(format!("recording stopped early ({why})"));
    }
    if v.drops > 0 {
        out.push(format!("recording incomplete ({} dropped by the recorder)", plural(v.drops, "tick", "ticks")));
    }
    out
}

impl crate::supervise::Outcome {
    /// `rig run`'s exit status: a run that reached its end is 0 only without safe stop, reflex,
    /// refused torque or an incomplete recording (and with the plant's summary to say so), else 4;
    /// 2, 3, 130, 143 by the ending.
    pub fn exit_code(&self) -> i32 {
        use crate::supervise::Ending;
        match (&self.ending, &self.plant_summary) {
            (Ending::Completed, Some(v)) if incidents(v).is_empty() => 0,
            (Ending::Completed, _) => 4,
            (e, _) => e.exit_code(),
        }
    }
}

/// The last line of `rig run`'s summary: the exit status and why.
pub fn status_line(code: i32, ending: &crate::supervise::Ending, plant_summary: Option<&PlantSummary>) -> String {
    use crate::supervise::Ending;
    let found = plant_summary.map(incidents).unwrap_or_default();
    let also = if found.is_empty() { String::new() } else { format!("; plant: {}", found.join(", ")) };
    match ending {
        Ending::Completed if plant_summary.is_none() => {
            format!("rig: exit {code}: reached the end, but the plant printed no summary to tell how")
        }
        Ending::Completed if found.is_empty() => {
            format!("rig: exit {code}: reached the end; no safe stop, reflex or refused torque; recording complete")
        }
        Ending::Completed => format!("rig: exit {code}: {}", found.join(", ")),
        Ending::PlantFailed(why) => format!("rig: exit {code}: plant failed: {why}{also}"),
        Ending::ControllerFailed(why) => format!("rig: exit {code}: controller failed: {why}{also}"),
        Ending::NeverConnected(why) => format!("rig: exit {code}: controller never connected: {why}{also}"),
        Ending::Interrupted => format!("rig: exit {code}: interrupted (SIGINT), both daemons stopped{also}"),
        Ending::Terminated => format!("rig: exit {code}: terminated (SIGTERM), both daemons stopped{also}"),
    }
}

/// One distribution line: p50/p90/p99/p99.9/max in µs.
fn dist_line(name: &str, d: &Distribution) -> String {
    format!(
        "{name:<22} n {:>7}  p50 {:>8.1}  p90 {:>8.1}  p99 {:>8.1}  p99.9 {:>8.1}  max {:>8.1}  (us)\n",
        d.count, d.p50_us, d.p90_us, d.p99_us, d.p999_us, d.max_us
    )
}

/// ASCII histogram of a distribution's bins (log-scaled bars, counts printed).
pub fn ascii_histogram(d: &Distribution, width: usize) -> String {
    let mut s = String::new();
    let max = d.bins.iter().map(|b| b.2).max().unwrap_or(0).max(1) as f64;
    for &(lo, hi, c) in &d.bins {
        let label = match hi {
            Some(hi) => format!("{lo:>6.0}-{hi:<6.0}us"),
            None => format!("{lo:>6.0}+      us"),
        };
        let bar = if c == 0 { 0 } else { (((c as f64).ln_1p() / max.ln_1p()) * width as f64).ceil() as usize };
        s += &format!("  {label} |{:<width$}| {c}\n", "#".repeat(bar));
    }
    s
}

/// The report of `rig timing`.
pub fn timing_report(v: &PlantSummary) -> String {
    let mut s = String::new();
    let (ticks, misses) = (v.ticks, v.misses);
    s += &format!(
        "timing run: {} ticks in {:.1} s wall, misses {} ({:.2e} of ticks), overruns (skipped periods) {}, SCHED_FIFO {}, mlockall {}\n",
        ticks,
        v.wall_s,
        misses,
        if ticks > 0 { misses as f64 / ticks as f64 } else { 0.0 },
        v.overruns,
        v.sched_fifo,
        v.mlockall,
    );
    for (d, name) in [
        (&v.round_trip, "round trip"),
        (&v.jitter, "period jitter |T-1ms|"),
        (&v.plant_compute, "plant compute/tick"),
        (&v.controller_compute, "controller compute"),
    ] {
        s += &dist_line(name, d);
    }
    if let Some(probe) = &v.host_probe {
        s += &host_probe_lines(probe);
    }
    for (d, name) in [(&v.round_trip, "round-trip latency"), (&v.jitter, "tick-period jitter")] {
        s += &format!("{name} histogram (bar length ~ log count):\n");
        s += &ascii_histogram(d, 40);
    }
    s
}

/// The host-floor probe's wake-up latency per CPU, next to the rig's distributions, its stall
/// count and the latest stalls with their times.
fn host_probe_lines(p: &HostProbe) -> String {
    let mut s = String::new();
    let threshold = p.stall_threshold_us;
    for c in &p.cpus {
        let cpu = c.cpu;
        s += &dist_line(&format!("host probe CPU {cpu}, every {:.0} us", c.period_us), &c.latency);
        let stalls: Vec<String> =
            c.recent_stalls.iter().rev().take(5).map(|(at_ms, late_us)| format!("{late_us:.1} us at {at_ms:.1} ms")).collect();
        s += &format!(
            "  CPU {cpu}: {} stalls (wake-up >= {threshold:.0} us){}{}\n",
            c.stalls,
            if stalls.is_empty() { String::new() } else { format!(", latest: {}", stalls.join(", ")) },
            if c.sched_fifo { "" } else { "; SCHED_FIFO refused: the probe measured the normal scheduler" }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use recordings::plant_summary::{CpuProbe, LiveReport};

    fn dist(count: u64) -> Distribution {
        Distribution {
            count,
            mean_us: 0.0,
            p50_us: 0.0,
            p90_us: 0.0,
            p99_us: 0.0,
            p999_us: 0.0,
            p9999_us: 0.0,
            max_us: 0.0,
            bins: Vec::new(),
        }
    }

    /// A run with nothing to report: every count 0, nothing recorded.
    fn clean() -> PlantSummary {
        PlantSummary {
            rig: "t".into(),
            mode: scenarios::Mode::Lockstep,
            ticks: 0,
            misses: 0,
            safe_stops: 0,
            refusals: 0,
            reflexes: 0,
            foreign_answers: 0,
            first_safe_stop_tick: None,
            first_reflex_tick: None,
            first_refusal_tick: None,
            controller_ended: false,
            overruns: 0,
            lost_wakeups: 0,
            lost_wakeups_in_a_row: 0,
            rt_p50_us: 0.0,
            rt_p99_us: 0.0,
            rt_max_us: 0.0,
            recording: None,
            drops: 0,
            recording_stopped_early: None,
            live: None,
            wall_s: 0.0,
            sim_s: 0.0,
            speed_factor: 0.0,
            stopped_by_signal: false,
            sched_fifo: false,
            mlockall: false,
            round_trip: dist(0),
            jitter: dist(0),
            plant_compute: dist(0),
            controller_compute: dist(0),
            host_probe: None,
            egm: None,
        }
    }

    #[test]
    fn summary_names_every_required_number() {
        let v = PlantSummary {
            ticks: 1200,
            misses: 3,
            safe_stops: 1,
            rt_p50_us: 21.5,
            rt_p99_us: 60.25,
            rt_max_us: 140.0,
            recording: Some("runs/x/run.mcap".into()),
            sim_s: 1.2,
            wall_s: 0.05,
            speed_factor: 24.0,
            ..clean()
        };
        let s = run_summary(&v) + &recording_summary(&v, None);
        for needle in
            ["ticks 1200", "misses 3", "safe stops 1", "p50 21.5", "p99 60.2", "max 140.0", "recording   runs/x/run.mcap\n", "24.0x"]
        {
            assert!(s.contains(needle), "{needle:?} missing in {s}");
        }
        assert_eq!(s.matches("recording").count(), 1, "{s}");
        let live = PlantSummary { live: Some(LiveReport { addr: "127.0.0.1:8765".into(), sent: 5, dropped: 1 }), ..v };
        assert!(run_summary(&live).ends_with("live view   ws://127.0.0.1:8765  5 messages sent, 1 dropped\n"), "{}", run_summary(&live));
    }

    #[test]
    fn the_recording_and_an_early_stop_are_each_named_once() {
        let why = "disk full (ENOSPC) at tick 812: write failed";
        let v = PlantSummary { recording: Some("runs/x/run.mcap".into()), recording_stopped_early: Some(why.into()), ..clean() };
        let rec = recording_tools::read::Recording { path: "runs/x/run.mcap".into(), ..Default::default() };
        let read_back = |integrity: recording_tools::read::Integrity| {
            let mut n = recording_tools::report::numbers(&rec);
            (n.integrity, n.integrity_detail) = (integrity.kind(), integrity.describe());
            n
        };
        let stopped = read_back(recording_tools::read::Integrity::StoppedEarly(why.into()));
        let complete = read_back(recording_tools::read::Integrity::Complete);
        for s in [recording_summary(&v, None), recording_summary(&v, Some(&stopped)), recording_summary(&v, Some(&complete))] {
            assert_eq!(s.matches("runs/x/run.mcap").count(), 1, "{s}");
            assert_eq!(s.matches("stopped the recording early").count(), 1, "{s}");
            assert_eq!(s.matches(why).count(), 1, "{s}");
        }
        let v = PlantSummary { recording_stopped_early: None, ..v };
        let s = recording_summary(&v, Some(&complete));
        assert!(!s.contains("early") && s.starts_with("recording   runs/x/run.mcap\n"), "{s}");
    }

    #[test]
    fn incidents_name_counts_and_first_ticks_and_misses_alone_are_none() {
        assert!(incidents(&PlantSummary { misses: 40, ..clean() }).is_empty());
        let v = PlantSummary {
            safe_stops: 1,
            first_safe_stop_tick: Some(512),
            reflexes: 1,
            first_reflex_tick: Some(512),
            refusals: 200,
            first_refusal_tick: Some(100),
            recording_stopped_early: Some("disk full".into()),
            drops: 1,
            ..clean()
        };
        assert_eq!(
            incidents(&v),
            [
                "1 reflex (first at tick 512)",
                "1 safe stop (first at tick 512)",
                "200 refused torques (first at tick 100)",
                "recording stopped early (disk full)",
                "recording incomplete (1 tick dropped by the recorder)"
            ]
        );
        let two = PlantSummary { reflexes: 2, first_reflex_tick: Some(7), ..clean() };
        let line = status_line(4, &crate::supervise::Ending::Completed, Some(&two));
        assert_eq!(line, "rig: exit 4: 2 reflexes (first at tick 7)");
    }

    #[test]
    fn exit_status_is_0_only_for_a_clean_end_and_4_for_an_end_with_incidents() {
        use crate::supervise::{Ending, Outcome};
        let out = |ending, v: Option<PlantSummary>| Outcome { ending, plant_summary: v }.exit_code();
        assert_eq!(out(Ending::Completed, Some(PlantSummary { misses: 12, ..clean() })), 0);
        assert_eq!(out(Ending::Completed, Some(PlantSummary { safe_stops: 1, ..clean() })), 4);
        assert_eq!(
            out(Ending::Completed, Some(PlantSummary { recording_stopped_early: Some("No space left on device".into()), ..clean() })),
            4
        );
        assert_eq!(out(Ending::Completed, None), 4);
        assert_eq!(out(Ending::PlantFailed("x".into()), Some(PlantSummary { safe_stops: 1, ..clean() })), 2);
        assert_eq!(out(Ending::ControllerFailed("x".into()), None), 3);
        assert_eq!(out(Ending::Interrupted, None), 130);
        assert_eq!(out(Ending::Terminated, None), 143);
    }

    #[test]
    fn a_summary_line_without_a_field_fails_the_run_with_a_sentence_naming_the_field() {
        use crate::supervise::{read_summary, Ending, Outcome};
        let full = clean().to_line();
        let (ending, s) = read_summary(Ending::Completed, &format!("some log line\n{full}\n"));
        assert!(matches!(ending, Ending::Completed) && s == Some(clean()), "{ending:?}");
        for field in ["safe_stops", "first_reflex_tick", "round_trip", "egm"] {
            let mut v = clean().to_value();
            v.as_object_mut().unwrap().remove(field);
            let (ending, s) = read_summary(Ending::Completed, &format!("{v}\n"));
            let outcome = Outcome { ending, plant_summary: s };
            let code = outcome.exit_code();
            let line = status_line(code, &outcome.ending, outcome.plant_summary.as_ref());
            assert_eq!(code, 2, "{line}");
            assert!(
                line.starts_with(&format!("rig: exit 2: plant failed: the plant's summary does not read: missing field `{field}`")),
                "{line}"
            );
        }
        // A nested part too.
        let mut v = PlantSummary { host_probe: Some(HostProbe { stall_threshold_us: 100.0, cpus: Vec::new() }), ..clean() }.to_value();
        v["jitter"].as_object_mut().unwrap().remove("p99_us");
        v["host_probe"].as_object_mut().unwrap().remove("cpus");
        let (ending, _) = read_summary(Ending::Completed, &v.to_string());
        assert!(matches!(&ending, Ending::PlantFailed(why) if why.contains("missing field")), "{ending:?}");
    }

    #[test]
    fn the_timing_report_shows_each_probe_cpu_and_its_stalls() {
        let lat = Distribution { count: 60000, p50_us: 3.1, p90_us: 4.0, p99_us: 9.5, p999_us: 40.0, max_us: 2100.0, ..dist(0) };
        let cpu = |cpu, sched_fifo, stalls, recent_stalls| CpuProbe {
            cpu,
            period_us: 250.0,
            pinned: true,
            sched_fifo,
            latency: lat.clone(),
            stalls,
            recent_stalls,
        };
        let probe = HostProbe {
            stall_threshold_us: 100.0,
            cpus: vec![cpu(0, true, 3, vec![(1000.5, 150.0), (2000.5, 2100.0)]), cpu(1, false, 0, vec![])],
        };
        let v = PlantSummary { ticks: 60000, misses: 2, host_probe: Some(probe), ..clean() };
        let s = timing_report(&v);
        assert!(s.contains("host probe CPU 0, every 250 us") && s.contains("host probe CPU 1"), "{s}");
        assert!(s.contains("CPU 0: 3 stalls (wake-up >= 100 us), latest: 2100.0 us at 2000.5 ms, 150.0 us at 1000.5 ms\n"), "{s}");
        assert!(s.contains("CPU 1: 0 stalls (wake-up >= 100 us); SCHED_FIFO refused"), "{s}");
    }

    #[test]
    fn histogram_bars_grow_with_counts_and_show_them() {
        let d = Distribution { bins: vec![(0.0, Some(10.0), 1000), (10.0, Some(20.0), 10), (20.0, None, 0)], ..dist(1010) };
        let h = ascii_histogram(&d, 20);
        let lines: Vec<&str> = h.lines().collect();
        let bars: Vec<usize> = lines.iter().map(|l| l.matches('#').count()).collect();
        assert_eq!(bars[0], 20);
        assert!(bars[1] > 0 && bars[1] < bars[0]);
        assert_eq!(bars[2], 0);
        assert!(lines[0].ends_with("1000") && lines[2].contains("20+"));
    }
}
