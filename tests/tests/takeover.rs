//! Issue 22 item 3: a controller that takes over from a dead one is taken over within a few ticks,
//! every time, also when it answers late in the budget. The real `plant-sim` and two
//! `hold-controller`s on their own rig: the active one is SIGKILLed, a new one that answers
//! 200-300 µs after each state (`--answer-after-us`) is started, and it must be the active
//! controller within 25 ticks of its first answer, blended in. In real time and in lockstep
//! (which paces in real time once its controller is gone).
//!
//! `TAKEOVER_RUNS` (default 3) runs per mode. Build first: `cargo build --release --workspace --bins`.

use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Ticks after the new controller's first answer by which it must be the active one.
const WITHIN_TICKS: u64 = 25;
/// Joint 1 offset of the new controller, N m: without the blend the applied torque jumps by it.
const OFFSET_NM: f64 = 100.0;

fn runs() -> usize {
    std::env::var("TAKEOVER_RUNS").ok().and_then(|s| s.parse().ok()).unwrap_or(3)
}

/// The tick the controller's log names as its first answer.
fn first_answer(c: &Daemon) -> u64 {
    let err = c.stderr();
    err.lines()
        .find_map(|l| l.strip_prefix("hold-controller: first answer: tick ")?.trim().parse().ok())
        .unwrap_or_else(|| panic!("{} never answered:\n{err}", c.name))
}

/// One run: plant in `mode`, controller A, A SIGKILLed, the slow controller C started. Returns
/// (C's first answered tick, the tick C took over).
fn one_run(mode: &str, run: usize) -> (u64, u64) {
    let t = TestRig::new(&format!("takeover-{mode}-{run}"), mode);
    // Lockstep: A answers late too, so the run is still going when A is killed.
    let (duration_s, kill_after, a_args): (f64, u64, &[&str]) =
        if mode == "lockstep" { (4.0, 100, &["--answer-after-us", "200:300"]) } else { (2.5, 300, &[]) };
    let mut plant = t.plant(duration_s);
    let mut a = t.controller("a", "hold-controller", a_args);
    wait_for_log(&plant, "connected", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(kill_after));
    a.signal(libc::SIGKILL);
    a.expect_exit(Duration::from_secs(5));
    let seed = (run + 1).to_string();
    let offset = OFFSET_NM.to_string();
    let mut c = t.controller("c", "hold-controller", &["--offset-nm", &offset, "--answer-after-us", "200:300", "--seed", &seed]);
    let ps = plant.expect_exit(Duration::from_secs(120));
    assert!(ps.success(), "{mode} run {run}: plant failed ({ps}):\n{}", plant.stderr());
    let cs = c.expect_exit(Duration::from_secs(10));
    assert!(cs.success(), "{mode} run {run}: controller C failed ({cs}):\n{}\nplant:\n{}", c.stderr(), plant.stderr());

    let first = first_answer(&c);
    let rec = Recording::open_complete(t.recording()).expect("complete recording");
    // The arbiter's switch (one per take-over) and the gate's blend, both at the take-over tick.
    let changes: Vec<_> = rec.events.iter().filter(|e| e.kind == Some(EventKind::ControllerChange)).collect();
    let switches: Vec<_> = changes.iter().filter(|e| e.text.contains(": publisher ") && e.text.contains(" takes over from ")).collect();
    assert_eq!(switches.len(), 1, "{mode} run {run}: one switch from A to C: {changes:?}");
    let takeover = switches[0].tick;
    assert!(
        changes.iter().any(|e| e.tick == takeover && e.text.contains("(blended in)")),
        "{mode} run {run}: C is not blended in at tick {takeover}: {changes:?}"
    );
    assert!(
        takeover >= first && takeover - first <= WITHIN_TICKS,
        "{mode} run {run}: C answered tick {first} first but took over at tick {takeover} (at most {WITHIN_TICKS} later): {:?}",
        rec.events
    );
    // The blend: C's first command carries the whole offset; the plant applies a blend step of it.
    let tau1 = |tick: u64| rec.joint_torque.iter().find(|r| r.tick == tick).map(|r| r.torque.tau[0]).unwrap();
    let step = (tau1(takeover) - tau1(takeover - 1)).abs();
    assert!(step < 0.1 * OFFSET_NM, "{mode} run {run}: joint 1 torque steps {step} N m at the take-over (tick {takeover})");
    assert_no_jump(&rec, takeover);
    (first, takeover)
}

fn takeover_runs(mode: &str) {
    let _g = serial();
    let n = runs();
    let mut lags = Vec::with_capacity(n);
    for run in 0..n {
        let (first, takeover) = one_run(mode, run);
        lags.push(takeover - first);
    }
    eprintln!("{mode}: {n} runs, take-over this many ticks after the first answer: {lags:?}");
}

#[test]
fn a_late_answering_controller_takes_over_a_realtime_plant_within_25_ticks() {
    takeover_runs("realtime");
}

#[test]
fn a_late_answering_controller_takes_over_a_lockstep_plant_within_25_ticks() {
    takeover_runs("lockstep");
}
