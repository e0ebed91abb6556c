//! Human-readable summaries of a run and of a timing run, from the plant's JSON summary line.

use recording_tools::report::ReportNumbers;
use serde_json::Value;

fn num(v: &Value, key: &str) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

fn int(v: &Value, key: &str) -> u64 {
    v.get(key).and_then(Value::as_u64).unwrap_or(0)
}

/// The summary of `rig run`: ticks, misses, safe stops, round-trip latency p50/p99/max (the
/// recording follows in [`recording_summary`]).
pub fn run_summary(v: &Value) -> String {
    let mut s = String::new();
    s += &format!(
        "ticks {}  misses {}  safe stops {}  refused {}  overruns {}  recorder drops {}\n",
        int(v, "ticks"),
        int(v, "misses"),
        int(v, "safe_stops"),
        int(v, "refusals"),
        int(v, "overruns"),
        int(v, "drops")
    );
    s += &format!("round trip  p50 {:.1} us  p99 {:.1} us  max {:.1} us\n", num(v, "rt_p50_us"), num(v, "rt_p99_us"), num(v, "rt_max_us"));
    let mode = v.get("mode").and_then(Value::as_str).unwrap_or("?");
    if int(v, "ticks") == 0 {
        // Not "(0.0x real time)": nothing ran (in lockstep: no controller answered tick 0).
        s += &format!("mode {mode}  nothing simulated in {:.3} s wall: no tick was integrated\n", num(v, "wall_s"));
    } else {
        s += &format!(
            "mode {mode}  simulated {:.3} s in {:.3} s wall ({:.1}x real time)\n",
            num(v, "sim_s"),
            num(v, "wall_s"),
            num(v, "speed_factor")
        );
    }
    if let Some(live) = v.get("live").filter(|l| !l.is_null()) {
        s += &format!(
            "live view   ws://{}  {} messages sent, {} dropped\n",
            live.get("addr").and_then(Value::as_str).unwrap_or("?"),
            int(live, "sent"),
            int(live, "dropped")
        );
    }
    s
}

/// The recording part of `rig run`'s summary, each line once: the report's numbers when the file
/// reads back (their first line names it, a warning line says how it ends if not complete), else
/// the path alone; plus one line with the plant's reason if the recording stopped early and the
/// file does not say so itself.
pub fn recording_summary(v: &Value, numbers: Option<&ReportNumbers>) -> String {
    let mut s = match numbers {
        Some(n) => recording_tools::report::format_text(n),
        None => format!("recording   {}\n", v.get("recording").and_then(Value::as_str).unwrap_or("(not recorded)")),
    };
    if let Some(why) = v.get("recording_stopped_early").and_then(Value::as_str) {
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
/// (`recording_stopped_early`: its reason, absent or null when complete) or with ticks the
/// recorder dropped. Misses alone are not incidents (real time on a noisy host).
pub fn incidents(v: &Value) -> Vec<String> {
    let mut out = Vec::new();
    let first = |key: &str| v.get(key).and_then(Value::as_u64).map_or(String::new(), |k| format!(" (first at tick {k})"));
    for (count, first_key, one, many) in [
        ("reflexes", "first_reflex_tick", "reflex", "reflexes"),
        ("safe_stops", "first_safe_stop_tick", "safe stop", "safe stops"),
        ("refusals", "first_refusal_tick", "refused torque", "refused torques"),
    ] {
        let n = int(v, count);
        if n > 0 {
            out.push(format!("{}{}", plural(n, one, many), first(first_key)));
        }
    }
    match v.get("recording_stopped_early") {
        None | Some(Value::Null) => {}
        Some(Value::String(why)) => out.push(format!("recording stopped early ({why})")),
        Some(other) => out.push(format!("recording stopped early ({other})")),
    }
    let drops = int(v, "drops");
    if drops > 0 {
        out.push(format!("recording incomplete ({} dropped by the recorder)", plural(drops, "tick", "ticks")));
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
pub fn status_line(code: i32, ending: &crate::supervise::Ending, plant_summary: Option<&Value>) -> String {
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
fn dist_line(name: &str, d: &Value) -> String {
    format!(
        "{name:<22} n {:>7}  p50 {:>8.1}  p90 {:>8.1}  p99 {:>8.1}  p99.9 {:>8.1}  max {:>8.1}  (us)\n",
        int(d, "count"),
        num(d, "p50_us"),
        num(d, "p90_us"),
        num(d, "p99_us"),
        num(d, "p999_us"),
        num(d, "max_us")
    )
}

/// ASCII histogram of a distribution's bins (log-scaled bars, counts printed).
pub fn ascii_histogram(d: &Value, width: usize) -> String {
    let mut s = String::new();
    let Some(bins) = d.get("bins").and_then(Value::as_array) else { return s };
    let counts: Vec<u64> = bins.iter().map(|b| b.get(2).and_then(Value::as_u64).unwrap_or(0)).collect();
    let max = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    for (b, &c) in bins.iter().zip(counts.iter()) {
        let lo = b.get(0).and_then(Value::as_f64).unwrap_or(0.0);
        let label = match b.get(1).and_then(Value::as_f64) {
            Some(hi) => format!("{lo:>6.0}-{hi:<6.0}us"),
            None => format!("{lo:>6.0}+      us"),
        };
        let bar = if c == 0 { 0 } else { (((c as f64).ln_1p() / max.ln_1p()) * width as f64).ceil() as usize };
        s += &format!("  {label} |{:<width$}| {c}\n", "#".repeat(bar));
    }
    s
}

/// The report of `rig timing`.
pub fn timing_report(v: &Value) -> String {
    let mut s = String::new();
    let ticks = int(v, "ticks");
    let misses = int(v, "misses");
    s += &format!(
        "timing run: {} ticks in {:.1} s wall, misses {} ({:.2e} of ticks), overruns (skipped periods) {}, SCHED_FIFO {}, mlockall {}\n",
        ticks,
        num(v, "wall_s"),
        misses,
        if ticks > 0 { misses as f64 / ticks as f64 } else { 0.0 },
        int(v, "overruns"),
        v.get("sched_fifo").and_then(Value::as_bool).unwrap_or(false),
        v.get("mlockall").and_then(Value::as_bool).unwrap_or(false),
    );
    for (key, name) in [
        ("round_trip", "round trip"),
        ("jitter", "period jitter |T-1ms|"),
        ("plant_compute", "plant compute/tick"),
        ("controller_compute", "controller compute"),
    ] {
        if let Some(d) = v.get(key) {
            s += &dist_line(name, d);
        }
    }
    if let Some(probe) = v.get("host_probe").filter(|p| !p.is_null()) {
        s += &host_probe_lines(probe);
    }
    for (key, name) in [("round_trip", "round-trip latency"), ("jitter", "tick-period jitter")] {
        if let Some(d) = v.get(key) {
            s += &format!("{name} histogram (bar length ~ log count):\n");
            s += &ascii_histogram(d, 40);
        }
    }
    s
}

/// The host-floor probe's wake-up latency per CPU, next to the rig's distributions, its stall
/// count and the latest stalls with their times.
fn host_probe_lines(p: &Value) -> String {
    let mut s = String::new();
    let threshold = num(p, "stall_threshold_us");
    for c in p.get("cpus").and_then(Value::as_array).into_iter().flatten() {
        let cpu = int(c, "cpu");
        if let Some(d) = c.get("latency") {
            let every = c.get("period_us").and_then(Value::as_f64).map_or(String::new(), |us| format!(", every {us:.0} us"));
            s += &dist_line(&format!("host probe CPU {cpu}{every}"), d);
        }
        let fifo = c.get("sched_fifo").and_then(Value::as_bool).unwrap_or(false);
        let stalls: Vec<String> = c
            .get("recent_stalls")
            .and_then(Value::as_array)
            .map(|a| a.iter().rev().take(5).map(|x| format!("{:.1} us at {:.1} ms", num_at(x, 1), num_at(x, 0))).collect())
            .unwrap_or_default();
        s += &format!(
            "  CPU {cpu}: {} stalls (wake-up >= {threshold:.0} us){}{}\n",
            int(c, "stalls"),
            if stalls.is_empty() { String::new() } else { format!(", latest: {}", stalls.join(", ")) },
            if fifo { "" } else { "; SCHED_FIFO refused: the probe measured the normal scheduler" }
        );
    }
    s
}

fn num_at(v: &Value, i: usize) -> f64 {
    v.get(i).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_names_every_required_number() {
        let v = serde_json::json!({"ticks": 1200, "misses": 3, "safe_stops": 1, "rt_p50_us": 21.5, "rt_p99_us": 60.25,
            "rt_max_us": 140.0, "recording": "runs/x/run.mcap", "drops": 0, "mode": "lockstep", "sim_s": 1.2, "wall_s": 0.05, "speed_factor": 24.0});
        let s = run_summary(&v) + &recording_summary(&v, None);
        for needle in
            ["ticks 1200", "misses 3", "safe stops 1", "p50 21.5", "p99 60.2", "max 140.0", "recording   runs/x/run.mcap\n", "24.0x"]
        {
            assert!(s.contains(needle), "{needle:?} missing in {s}");
        }
        assert_eq!(s.matches("recording").count(), 1, "{s}");
    }

    #[test]
    fn the_recording_and_an_early_stop_are_each_named_once() {
        let why = "disk full (ENOSPC) at tick 812: write failed";
        let v = serde_json::json!({"recording": "runs/x/run.mcap", "recording_stopped_early": why});
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
        let v = serde_json::json!({"recording": "runs/x/run.mcap", "recording_stopped_early": null});
        let s = recording_summary(&v, Some(&complete));
        assert!(!s.contains("early") && s.starts_with("recording   runs/x/run.mcap\n"), "{s}");
    }

    #[test]
    fn incidents_name_counts_and_first_ticks_and_misses_alone_are_none() {
        let clean =
            serde_json::json!({"misses": 40, "safe_stops": 0, "reflexes": 0, "refusals": 0, "drops": 0, "recording_stopped_early": null});
        assert!(incidents(&clean).is_empty());
        // An older plant without the new fields: nothing to report either.
        assert!(incidents(&serde_json::json!({"misses": 3})).is_empty());
        let v = serde_json::json!({"safe_stops": 1, "first_safe_stop_tick": 512, "reflexes": 1, "first_reflex_tick": 512,
            "refusals": 200, "first_refusal_tick": 100, "recording_stopped_early": "disk full", "drops": 1});
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
        let line = status_line(4, &crate::supervise::Ending::Completed, Some(&serde_json::json!({"reflexes": 2, "first_reflex_tick": 7})));
        assert_eq!(line, "rig: exit 4: 2 reflexes (first at tick 7)");
    }

    #[test]
    fn exit_status_is_0_only_for_a_clean_end_and_4_for_an_end_with_incidents() {
        use crate::supervise::{Ending, Outcome};
        let out = |ending, v: Option<serde_json::Value>| Outcome { ending, plant_summary: v }.exit_code();
        assert_eq!(out(Ending::Completed, Some(serde_json::json!({"misses": 12, "safe_stops": 0}))), 0);
        assert_eq!(out(Ending::Completed, Some(serde_json::json!({"safe_stops": 1}))), 4);
        assert_eq!(out(Ending::Completed, Some(serde_json::json!({"recording_stopped_early": "No space left on device"}))), 4);
        assert_eq!(out(Ending::Completed, None), 4);
        assert_eq!(out(Ending::PlantFailed("x".into()), Some(serde_json::json!({"safe_stops": 1}))), 2);
        assert_eq!(out(Ending::ControllerFailed("x".into()), None), 3);
        assert_eq!(out(Ending::Interrupted, None), 130);
        assert_eq!(out(Ending::Terminated, None), 143);
    }

    #[test]
    fn the_timing_report_shows_each_probe_cpu_and_its_stalls() {
        let lat = serde_json::json!({"count": 60000, "p50_us": 3.1, "p90_us": 4.0, "p99_us": 9.5, "p999_us": 40.0, "max_us": 2100.0});
        let v = serde_json::json!({"ticks": 60000, "misses": 2, "host_probe": {"stall_threshold_us": 100.0, "cpus": [
            {"cpu": 0, "sched_fifo": true, "latency": lat, "stalls": 3, "recent_stalls": [[1000.5, 150.0], [2000.5, 2100.0]]},
            {"cpu": 1, "sched_fifo": false, "latency": lat, "stalls": 0, "recent_stalls": []}]}});
        let s = timing_report(&v);
        assert!(s.contains("host probe CPU 0") && s.contains("host probe CPU 1"), "{s}");
        assert!(s.contains("CPU 0: 3 stalls (wake-up >= 100 us), latest: 2100.0 us at 2000.5 ms, 150.0 us at 1000.5 ms\n"), "{s}");
        assert!(s.contains("CPU 1: 0 stalls (wake-up >= 100 us); SCHED_FIFO refused"), "{s}");
    }

    #[test]
    fn histogram_bars_grow_with_counts_and_show_them() {
        let d = serde_json::json!({"bins": [[0.0, 10.0, 1000], [10.0, 20.0, 10], [20.0, null, 0]]});
        let h = ascii_histogram(&d, 20);
        let lines: Vec<&str> = h.lines().collect();
        let bars: Vec<usize> = lines.iter().map(|l| l.matches('#').count()).collect();
        assert_eq!(bars[0], 20);
        assert!(bars[1] > 0 && bars[1] < bars[0]);
        assert_eq!(bars[2], 0);
        assert!(lines[0].ends_with("1000") && lines[2].contains("20+"));
    }
}
