//! `rig timing` end to end (issue 15): the real launcher, both daemons, the host probe, the MCAP
//! recording read back, and the attribution `rig timing` and `rig report` print.
//!
//! Real time on a shared host: other misses happen. The tests assert on what they caused (the
//! ticks they delayed, the stall they made) and never on a total miss count or a latency.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use harness::*;
use recording_tools::attribution::{attribute, Cause};
use recording_tools::read::Recording;

static SERIAL: Mutex<()> = Mutex::new(());

/// One real-time run at a time: two at once on two CPUs would make each other's misses.
fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// `rig timing --seconds S --scenario F --out DIR [--controller PATH]`, started as a process. The
/// scenario is, like the built-in timing one, without the strip and holding the start pose, plus
/// [`HOST_STALLS_TOLERATED`]: CI's host once stalled the controller's CPU for 13-21 periods at a
/// time, and with the every-100th-tick sleep that made 20 misses in a row, a safe stop, exit 4
/// (2026-12-06). These tests are about attribution and skipped periods, not the miss safety.
fn rig_timing(dir: &Path, seconds: &str, controller: Option<&Path>) -> Daemon {
    let out = dir.join("out");
    let scenario = write_scenario(dir, "realtime", "[trajectory]\nsettle_s = 1.0e6\n");
    let mut args = vec!["timing", "--seconds", seconds, "--scenario", scenario.to_str().unwrap(), "--out", out.to_str().unwrap()];
    if let Some(c) = controller {
        args.extend(["--controller", c.to_str().unwrap()]);
    }
    Daemon::start("rig", &bin("rig"), &args, dir)
}

fn recording(dir: &Path) -> PathBuf {
    dir.join("out/run.mcap")
}

/// The cause table's lines (`| cause | n | rate |`) of a `rig timing` or `rig report` output.
fn table_lines(out: &str) -> Vec<String> {
    out.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| ---") && !l.starts_with("| cause")).map(str::to_string).collect()
}

/// A controller that sleeps 700 µs before answering every 100th tick (`fault-controller
/// --sleep-us 700 --every 100`; `rig timing --controller` passes only `--rig` and `--scenario`,
/// so a two-line script adds the rest). 700 µs is past the 500 µs budget: each of those ticks
/// misses, and the controller's own stamps (woke before the sleep, handed over after it) say why.
/// Every delayed tick must be attributed to controller compute, none to the host; the other misses
/// of a shared host are not counted against it.
#[test]
fn a_controller_sleeping_700_us_every_100th_tick_gets_exactly_those_misses_as_its_compute() {
    let _g = serial();
    let rig = unique_rig("timing-delay");
    let dir = temp_dir(&rig);
    let script = dir.join("slow-controller");
    // SCHED_FIFO 80 as the rig's own controller: on time when it is not sleeping.
    std::fs::write(
        &script,
        format!("#!/bin/sh\nexec {} \"$@\" --sleep-us 700 --every 100 --rt-priority 80\n", bin("fault-controller").display()),
    )
    .unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let mut run = rig_timing(&dir, "12", Some(&script));
    let st = run.expect_exit(Duration::from_secs(120));
    let out = run.stdout();
    assert!(st.success(), "rig timing: {st}\n{out}\n{}", run.stderr());
    let rec = Recording::open_complete(recording(&dir)).unwrap();
    let a = attribute(&rec.timing);
    assert!(a.stamped && a.probe, "stage stamps and the probe in the recording");
    let first = rec.timing.iter().find(|t| t.timing.stages.is_some_and(|s| s.answered)).map(|t| t.tick).expect("answered");
    let last = rec.timing.last().unwrap().tick;
    // The ticks it delayed: every 100th that it answered at all (its stamps came, in time or
    // late; a tick whose state it never saw, because it woke after the next one, it did not delay).
    let stamped = |k: u64| {
        rec.timing
            .iter()
            .any(|t| t.timing.stages.is_some_and(|s| (t.tick == k && s.controller.is_some()) || s.late.is_some_and(|l| l.0 == k)))
    };
    // Left out too: a tick whose state the plant itself published late (it skipped periods or
    // its budget was cut at the next deadline; the plant's stamps say so), as happens on this
    // shared host; there the host came first, and the test did not make that.
    // So is a tick the controller woke for later than its wake share after the publish (the
    // stamps say so): a wake-up held up by the host or another rig's real-time threads on this
    // machine is a cause of its own, and the test only delayed the compute. And so is a tick in
    // which the plant itself woke for its budget's end more than a host stall late: the host
    // stalled the plant's CPU then, and the probe's report, merged over the CPUs, shows that
    // stall in the controller's compute as well (seen on 2026-12-02: 165 us late, a 503 us stall),
    // or the plant, woken late, found the late torque already there and took it.
    let plant_late = |k: u64| {
        let s = rec.timing.iter().find(|t| t.tick == k).and_then(|t| t.timing.stages);
        let own = s.and_then(|s| s.controller);
        let late = rec
            .timing
            .iter()
            .find_map(|t| t.timing.stages.and_then(|s| s.late).filter(|l| l.0 == k).map(|l| (t.timing.stages.unwrap(), l.1)));
        let woke_after_publish = match (s, own, late) {
            (Some(s), Some(c), _) => c.woke_ns - s.state_published_ns,
            (Some(s), None, Some((at, c))) => {
                c.woke_ns + (at.deadline_since_start_ns as i64 - s.deadline_since_start_ns as i64) - s.state_published_ns
            }
            _ => 0,
        };
        s.is_some_and(|s| {
            s.skipped_periods > 0
                || s.budget_end_ns - s.plant_woke_ns < s.torque_budget_ns as i64
                || woke_after_publish > (recording_tools::attribution::WAKE_SHARE * s.torque_budget_ns as f64) as i64
                || s.torque_received_ns - s.budget_end_ns > recording_tools::attribution::HOST_STALL_NS as i64
        })
    };
    // And so, last, is a tick in whose compute window (woke to handed over) the probe saw a host
    // stall: the probe's report merges both CPUs, so the attribution cannot tell a stall of the
    // controller's CPU, which stretched its compute, from one of the CPU the sleeping plant left
    // idle; the rule gives such a tick to the host when the stall covers the overrun. The test
    // made neither; the unit tests of `attribution` hold that rule to known stalls.
    let stalls: Vec<(i64, i64)> = rec
        .timing
        .iter()
        .filter_map(|t| t.timing.stages)
        .filter(|o| o.probe && o.probe_late_ns >= recording_tools::attribution::HOST_STALL_NS)
        .map(|o| {
            let at = o.deadline_since_start_ns as i64 + o.probe_stall_from_ns;
            (at, at + o.probe_late_ns as i64)
        })
        .collect();
    let stall_in_compute = |k: u64| {
        let Some(s) = rec.timing.iter().find(|t| t.tick == k).and_then(|t| t.timing.stages) else { return false };
        let d = s.deadline_since_start_ns as i64;
        let window = s.controller.map(|c| (d + c.woke_ns, d + c.published_ns)).or_else(|| {
            rec.timing.iter().filter_map(|t| t.timing.stages).find_map(|n| {
                n.late
                    .filter(|l| l.0 == k)
                    .map(|(_, c)| (n.deadline_since_start_ns as i64 + c.woke_ns, n.deadline_since_start_ns as i64 + c.published_ns))
            })
        });
        window.is_some_and(|(a, b)| stalls.iter().any(|&(from, to)| from < b && to > a))
    };
    let every_100th: Vec<u64> = (first + 1..=last).filter(|&k| k % 100 == 0).collect();
    let seen: Vec<u64> = every_100th.iter().copied().filter(|&k| stamped(k) && !plant_late(k)).collect();
    let delayed: Vec<u64> = seen.iter().copied().filter(|&k| !stall_in_compute(k)).collect();
    eprintln!(
        "{} of {} 100th ticks delayed without a host stall in them ({} more had one; the rest unseen by the controller, published late or woken for late)",
        delayed.len(),
        every_100th.len(),
        seen.len() - delayed.len()
    );
    assert!(delayed.len() >= 40, "{} delayed ticks from tick {first} to {last}", delayed.len());
    let mut wrong = Vec::new();
    for &k in &delayed {
        match a.cause_of_tick(k) {
            // 700 µs of sleep past a 500 µs budget: a delayed tick cannot be answered in time.
            None => wrong.push(format!("tick {k} did not miss")),
            Some(Cause::ControllerCompute) => {}
            Some(c) => wrong.push(format!("tick {k}: {c:?}")),
        }
    }
    let host_delayed: Vec<String> = delayed
        .iter()
        .filter(|&&k| a.cause_of_tick(k) == Some(Cause::Host))
        .map(|&k| {
            format!("{:?}", rec.timing.iter().filter(|t| t.tick + 1 >= k && t.tick <= k + 1).map(|t| t.timing.stages).collect::<Vec<_>>())
        })
        .collect();
    eprintln!("{} delayed ticks; attribution {:?}; {} misses in all", delayed.len(), a.by_cause, a.misses);
    assert!(host_delayed.is_empty(), "delayed ticks attributed to the host, with the stamps of the ticks around them: {host_delayed:#?}");
    assert!(wrong.is_empty(), "delayed ticks not attributed to controller compute: {wrong:?}");
    assert!(a.count(Cause::ControllerCompute) >= delayed.len() as u64);
    // The table rig timing printed is the attribution of its recording, and rig report prints it too.
    let compute_line = format!("| controller compute over its share | {} |", a.count(Cause::ControllerCompute));
    assert!(out.contains(&compute_line), "{compute_line:?} not in:\n{out}");
    let mut report = Daemon::start(
        "report",
        &bin("rig"),
        &["report", recording(&dir).to_str().unwrap(), "--out", dir.join("report").to_str().unwrap()],
        &dir,
    );
    assert!(report.expect_exit(Duration::from_secs(120)).success(), "rig report: {}", report.stderr());
    let report = report.stdout();
    assert_eq!(table_lines(&report), table_lines(&out), "rig report's cause table differs from rig timing's:\n{report}");
}

/// A 100 ms host stall never ends a timing run: both daemons are stopped (SIGSTOP, plant first)
/// for 100 ms in the middle of `rig timing` and continued (controller first). The run completes
/// with exit 0, and the stall shows as a host-attributed burst of about 100 periods: the plant
/// skipped them, and the probe (in the plant's process, stopped with it) saw the same stall.
#[test]
fn a_100_ms_stall_of_both_daemons_is_a_host_burst_and_the_run_completes() {
    let _g = serial();
    let rig = unique_rig("timing-stall");
    let dir = temp_dir(&rig);
    let mut run = rig_timing(&dir, "4", None);
    let (plant, ctrl) = (|| {
        for _ in 0..600 {
            if let (Some(p), Some(c)) = (child_pid(run.pid(), "plant-sim"), child_pid(run.pid(), "controller")) {
                return (p, c);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!("rig timing started no daemons:\n{}", run.stderr());
    })();
    std::thread::sleep(Duration::from_millis(2000));
    let stopped_at = wall_ns();
    // SAFETY: signalling processes this test's rig started.
    // SAFETY: kill(2) on pids of processes this test spawned.
    unsafe {
        libc::kill(plant, libc::SIGSTOP);
        libc::kill(ctrl, libc::SIGSTOP);
    }
    std::thread::sleep(Duration::from_millis(100));
    // SAFETY: kill(2) on pids of processes this test spawned.
    unsafe {
        libc::kill(ctrl, libc::SIGCONT);
        libc::kill(plant, libc::SIGCONT);
    }
    let st = run.expect_exit(Duration::from_secs(120));
    let out = run.stdout();
    assert!(st.success(), "a 100 ms stall ended the run: {st}\n{out}\n{}", run.stderr());
    let rec = Recording::open_complete(recording(&dir)).unwrap();
    let a = attribute(&rec.timing);
    let stall_tick = tick_at_wall_ns(&rec, stopped_at).expect("stopped during the run");
    eprintln!("stopped at tick {stall_tick}; bursts {:?}; skipped {}; causes {:?}", a.bursts, a.skipped_periods, a.by_cause);
    // The tick after the stall: the plant skipped the periods it slept through.
    let after = rec
        .timing
        .iter()
        .find(|t| t.tick >= stall_tick && t.timing.stages.is_some_and(|s| s.skipped_periods > 0))
        .expect("a skip after the stall");
    let skipped = after.timing.stages.unwrap().skipped_periods;
    assert!((90..=400).contains(&skipped), "{skipped} periods skipped after a 100 ms stop");
    // A burst holds the tick the stop caught (it woke 100 ms late) or starts at the one after it;
    // it may begin a few ticks earlier when a stall of the host just before the stop joins it.
    let burst = a
        .bursts
        .iter()
        .find(|b| b.tick <= after.tick && b.tick + b.periods >= stall_tick)
        .unwrap_or_else(|| panic!("no host burst from tick {stall_tick} to {}: {:?}", after.tick, a.bursts));
    assert!(burst.periods >= u64::from(skipped), "{burst:?}");
    assert!(out.contains(&format!("host burst: {} periods lost from tick {}", burst.periods, burst.tick)), "{out}");
    assert!(out.contains("rig: exit 0"), "{out}");
    // The recording says what the probe saw: one /events entry at the end, whose worst wake-up is
    // the stop's (the probe threads live in the stopped plant).
    let probe: Vec<String> =
        rec.events_of(recordings::EventKind::Info).map(|e| e.text.clone()).filter(|t| t.starts_with("host probe: ")).collect();
    assert_eq!(probe.len(), 1, "{:?}", rec.events);
    let worst_ms: f64 = probe[0].split("worst wake-up ").nth(1).and_then(|t| t.split(" ms late").next()).unwrap().parse().unwrap();
    assert!((90.0..400.0).contains(&worst_ms), "{}", probe[0]);
}
