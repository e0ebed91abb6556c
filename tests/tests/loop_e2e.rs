//! End-to-end tests of issue 2: the real `plant-sim`, `controller`, `hold-controller` and `rig`
//! processes on their own rigs. Build first: `cargo build --release --workspace --bins`.
//!
//! The tests run one at a time (a process-wide lock): real-time runs on a 2-core machine must
//! not compete with each other.

use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use harness::*;
use messages::{PlantStatus, CONTRACT_VERSION};
use recording_tools::read::Recording;
use recordings::EventKind;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const LONG: Duration = Duration::from_secs(60);

fn events(rec: &Recording, kind: EventKind) -> Vec<(u64, String)> {
    rec.events.iter().filter(|e| e.kind == Some(kind)).map(|e| (e.tick, e.text.clone())).collect()
}

/// One lockstep run of plant + controller; returns the recording.
fn lockstep_run(tag: &str, duration_s: f64) -> Recording {
    let t = TestRig::new(tag, "lockstep");
    let mut plant = t.plant(duration_s);
    let mut ctrl = t.controller("controller", "controller", &[]);
    let ps = plant.expect_exit(LONG);
    assert!(ps.success(), "plant failed: {}", plant.stderr());
    let cs = ctrl.expect_exit(Duration::from_secs(10));
    assert!(cs.success(), "controller failed: {}", ctrl.stderr());
    let summary = plant_summary(&plant);
    assert_eq!(summary["misses"], 0, "{summary}");
    Recording::open_complete(t.recording()).expect("complete recording")
}

#[test]
fn lockstep_run_twice_gives_bit_identical_torques_and_states() {
    let _g = serial();
    let a = lockstep_run("det-a", 0.4);
    let b = lockstep_run("det-b", 0.4);
    assert_eq!(a.joint_state.len(), 400);
    assert_eq!(a.joint_state.len(), b.joint_state.len());
    assert_eq!(a.joint_torque.len(), b.joint_torque.len());
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for (k, (sa, sb)) in a.joint_state.iter().zip(&b.joint_state).enumerate() {
        assert_eq!(sa.tick, sb.tick);
        assert_eq!(bits(&sa.q), bits(&sb.q), "q differs at row {k}");
        assert_eq!(bits(&sa.qd), bits(&sb.qd), "qd differs at row {k}");
    }
    for (k, (ta, tb)) in a.joint_torque.iter().zip(&b.joint_torque).enumerate() {
        assert_eq!(bits(&ta.torque.tau), bits(&tb.torque.tau), "torque differs at row {k}");
        assert!(!ta.held, "lockstep never holds a torque (row {k})");
    }
    // The runs moved: the controller's torques are not all equal (a non-trivial comparison).
    let first = a.joint_torque.first().unwrap().torque.tau;
    assert!(a.joint_torque.iter().any(|t| t.torque.tau != first));
}

/// `rig run SCENARIO --mode MODE --duration S --out OUT`, which must exit 0; its stdout.
fn rig_run(dir: &std::path::Path, scenario: &std::path::Path, mode: &str, duration_s: &str, out: &std::path::Path) -> String {
    let args = ["run", scenario.to_str().unwrap(), "--mode", mode, "--duration", duration_s, "--out", out.to_str().unwrap()];
    let mut run = Daemon::start("rig", &bin("rig"), &args, dir);
    let st = run.expect_exit(LONG);
    let (stdout, stderr) = (run.stdout(), run.stderr());
    assert!(st.success(), "rig run failed ({st}):\n{stdout}\n{stderr}");
    stdout
}

#[test]
fn short_realtime_run_completes_with_its_summary() {
    let _g = serial();
    let rig = unique_rig("rt");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    let out = dir.join("out");
    let stdout = rig_run(&dir, &scenario, "realtime", "0.5", &out);
    for needle in ["ticks 500", "misses", "safe stops", "round trip", "p50", "p99", "max", "run.mcap"] {
        assert!(stdout.contains(needle), "{needle:?} missing from the summary:\n{stdout}");
    }
    let rec = Recording::open_complete(out.join("run.mcap")).expect("complete recording");
    assert_eq!(rec.joint_state.len(), 500);
    rec.check_continuity().expect("every tick recorded once, in order");
}

/// `rig run` in lockstep reads its recording for the summary while the plant writes it; a run
/// into the same `--out` as a longer one before must summarise its own file, not the last one's.
#[test]
fn a_lockstep_run_into_the_last_runs_directory_summarises_its_own_recording() {
    let _g = serial();
    let rig = unique_rig("again");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let out = dir.join("out");
    let mut last = String::new();
    for (duration, ticks) in [("0.6", 600), ("0.3", 300)] {
        let stdout = rig_run(&dir, &scenario, "lockstep", duration, &out);
        // the read-back's line (the plant's own is "ticks N  misses ...")
        let line = format!("ticks       {ticks} (0..={})", ticks - 1);
        assert!(stdout.contains(&line), "{line:?} missing from the summary (after {last:?}):\n{stdout}");
        assert!(stdout.contains("recording complete"), "{stdout}");
        last = line;
    }
    let rec = Recording::open_complete(out.join("run.mcap")).expect("complete recording");
    assert_eq!(rec.joint_state.len(), 300);
}

#[test]
fn killed_controller_puts_the_plant_into_safe_stop_and_a_restarted_one_resumes_without_jump() {
    let _g = serial();
    let t = TestRig::new("kill", "realtime");
    let (mut plant, mut first) = t.running(2.5);
    std::thread::sleep(Duration::from_millis(400));
    first.signal(libc::SIGKILL);
    first.expect_exit(Duration::from_secs(5));
    // The plant safe-stops when it sees the controller's node dead (logged as such), or after
    // loop.max_consecutive_misses misses if it has not seen that yet.
    let t0 = Instant::now();
    while !(plant.stderr().contains("safe stop after") || plant.stderr().contains("controller's node is dead")) {
        assert!(t0.elapsed() < Duration::from_secs(5), "no safe stop within 5 s:\n{}", plant.stderr());
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(200));
    let mut second = t.controller("controller-2", "controller", &[]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(second.expect_exit(Duration::from_secs(10)).success(), "controller 2: {}", second.stderr());

    let summary = plant_summary(&plant);
    assert!(summary["safe_stops"].as_u64().unwrap() >= 1, "{summary}");
    let rec = Recording::open_complete(t.recording()).unwrap();
    let stops = events(&rec, EventKind::SafeStop);
    assert!(!stops.is_empty(), "no SafeStop event: {:?}", rec.events);
    let stop_tick = stops[0].0;
    // The states published after the safe stop say so.
    assert!(rec.joint_state.iter().any(|s| s.tick > stop_tick && s.plant_status == PlantStatus::SafeStop as u32));
    let cleared = events(&rec, EventKind::SafeStopCleared);
    assert!(!cleared.is_empty(), "the restarted controller did not clear the safe stop: {:?}", rec.events);
    let resume = cleared[0].0;
    assert!(events(&rec, EventKind::ControllerChange).iter().any(|(k, _)| *k == resume));
    assert_eq!(rec.joint_state.last().unwrap().plant_status, PlantStatus::Running as u32);
    assert_no_jump(&rec, resume);
}

#[test]
fn a_different_controller_binary_takes_over_with_a_blend() {
    let _g = serial();
    let t = TestRig::new("swap", "realtime");
    let (mut plant, mut a) = t.running(2.0);
    std::thread::sleep(Duration::from_millis(300));
    a.signal(libc::SIGTERM);
    a.expect_exit(Duration::from_secs(5));
    // The new binary adds 100 N m on joint 1: without the blend the applied torque would jump by that.
    let offset = 100.0;
    let mut b = t.controller("hold", "hold-controller", &["--offset-nm", "100"]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(b.expect_exit(Duration::from_secs(10)).success(), "hold-controller: {}", b.stderr());

    let rec = Recording::open_complete(t.recording()).unwrap();
    let changes = events(&rec, EventKind::ControllerChange);
    assert!(changes.len() >= 2, "expected two controllers: {changes:?}");
    let takeover = changes[1].0;
    let tau1 = |tick: u64| rec.joint_torque.iter().find(|t| t.tick == tick).unwrap().torque.tau[0];
    // The new controller's first command carries the full offset (its PD has not reacted yet); the
    // plant applies only a blend step of it (1/50 of the way over the default 50 ms).
    let first_step = (tau1(takeover) - tau1(takeover - 1)).abs();
    assert!(first_step < 0.1 * offset, "joint 1 torque steps {first_step} N m at the takeover (offset {offset})");
    assert_no_jump(&rec, takeover);
}

#[test]
fn controller_of_another_contract_version_is_refused_with_both_versions() {
    let _g = serial();
    let t = TestRig::new("ver", "realtime");
    let mut plant = t.plant(1.5);
    let other = (CONTRACT_VERSION + 98).to_string();
    // The real controller refuses the plant's states itself.
    let mut c = t.controller("controller", "controller", &["--contract-version", &other]);
    let st = c.expect_exit(Duration::from_secs(20));
    assert!(!st.success());
    let msg = c.stderr();
    assert!(msg.contains(&format!("version {other}")) && msg.contains(&format!("version {CONTRACT_VERSION}")), "{msg}");
    // A controller that sends anyway is refused by the plant, which says so in the recording.
    let mut h = t.controller("hold", "hold-controller", &["--contract-version", &other]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    h.expect_exit(Duration::from_secs(10));
    let rec = Recording::open_complete(t.recording()).unwrap();
    let mism = events(&rec, EventKind::VersionMismatch);
    assert!(!mism.is_empty(), "no VersionMismatch event: {:?}", rec.events);
    let text = &mism[0].1;
    assert!(text.contains(&format!("version {other}")) && text.contains(&format!("version {CONTRACT_VERSION}")), "{text}");
    assert!(rec.joint_torque.iter().all(|t| t.held), "a refused torque must never be applied");
    assert!(plant_summary(&plant)["refusals"].as_u64().unwrap() > 0);
}

#[test]
fn non_finite_torques_are_refused_counted_and_lead_to_the_safe_stop() {
    let _g = serial();
    let t = TestRig::new("nan", "lockstep");
    let mut plant = t.plant(0.3);
    let mut h = t.controller("hold", "hold-controller", &["--nan-from-tick", "100"]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(h.expect_exit(Duration::from_secs(10)).success(), "hold-controller: {}", h.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    let refused = events(&rec, EventKind::TorqueRefused);
    assert_eq!(refused.len(), 1, "one event per refusal streak: {refused:?}");
    assert_eq!(refused[0].0, 100);
    assert!(refused[0].1.contains("joint 1") && refused[0].1.contains("not finite"), "{}", refused[0].1);
    // Every tick from 100 on holds (then safe-stops) instead of applying the NaN.
    for row in &rec.joint_torque {
        assert_eq!(row.held, row.tick >= 100, "tick {}", row.tick);
        assert!(row.torque.tau.iter().all(|x| x.is_finite()), "tick {}", row.tick);
    }
    let stops = events(&rec, EventKind::SafeStop);
    assert_eq!(stops.first().map(|s| s.0), Some(119), "safe stop at the 20th consecutive miss: {stops:?}");
    let s = plant_summary(&plant);
    assert_eq!(s["refusals"], 200, "{s}");
    assert_eq!(s["misses"], 200, "{s}");
}

#[test]
fn killed_plant_makes_the_controller_exit_and_a_new_plant_starts_clean() {
    let _g = serial();
    let t = TestRig::new("deadplant", "realtime");
    let (mut plant, mut ctrl) = t.running(10.0);
    std::thread::sleep(Duration::from_millis(300));
    plant.signal(libc::SIGKILL);
    let t0 = Instant::now();
    plant.expect_exit(Duration::from_secs(5));
    let st = ctrl.expect_exit(Duration::from_secs(5));
    let waited = t0.elapsed();
    assert!(!st.success(), "a dead plant is an error for the controller");
    assert!(ctrl.stderr().contains("plant"), "the message should name the plant: {}", ctrl.stderr());
    // 100 ms of silence plus process exit; generous bound for a loaded machine.
    assert!(waited < Duration::from_millis(1000), "controller took {waited:?} to exit");
    // The killed plant left dead iceoryx2 nodes; a new plant on the same rig cleans them and runs.
    let dir2 = t.dir.join("again");
    std::fs::create_dir_all(&dir2).unwrap();
    let mut plant2 = start_plant(&t.rig, &t.scenario, &dir2, 0.3, &[]);
    let mut ctrl2 = start_controller("controller", "controller", &t.rig, &t.scenario, &dir2, &[]);
    assert!(plant2.expect_exit(LONG).success(), "second plant: {}", plant2.stderr());
    assert!(ctrl2.expect_exit(Duration::from_secs(10)).success(), "second controller: {}", ctrl2.stderr());
}

#[test]
fn two_rigs_run_side_by_side() {
    let _g = serial();
    let rig = unique_rig("pair");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let start = |name: &str| {
        let out = dir.join(name);
        Daemon::start(
            name,
            &bin("rig"),
            &["run", scenario.to_str().unwrap(), "--mode", "lockstep", "--duration", "0.6", "--out", out.to_str().unwrap()],
            &dir,
        )
    };
    let (mut a, mut b) = (start("a"), start("b"));
    for r in [&mut a, &mut b] {
        let st = r.expect_exit(LONG);
        assert!(st.success(), "{} failed:\n{}\n{}", r.name, r.stdout(), r.stderr());
        assert!(r.stdout().contains("ticks 600  misses 0"), "{}", r.stdout());
    }
    for name in ["a", "b"] {
        let rec = Recording::open_complete(dir.join(name).join("run.mcap")).unwrap();
        assert_eq!(rec.joint_state.len(), 600);
        // Each rig heard only its own controller.
        assert_eq!(events(&rec, EventKind::ControllerChange).len(), 1, "{:?}", rec.events);
    }
}

#[test]
fn rig_reports_which_daemon_died_and_why() {
    let _g = serial();
    let rig = unique_rig("sup");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    // A "controller" that gives up after 0.3 s with status 7.
    let script = dir.join("quitter.sh");
    std::fs::write(&script, "#!/bin/sh\nsleep 0.3\necho 'quitter: giving up' >&2\nexit 7\n").unwrap();
    std::process::Command::new("chmod").arg("+x").arg(&script).status().unwrap();
    let out = dir.join("out");
    let mut run = Daemon::start(
        "rig",
        &bin("rig"),
        &["run", scenario.to_str().unwrap(), "--duration", "30", "--controller", script.to_str().unwrap(), "--out", out.to_str().unwrap()],
        &dir,
    );
    let st = run.expect_exit(Duration::from_secs(30));
    assert_eq!(st.code(), Some(3), "exit status names the controller:\n{}", run.stderr());
    let err = run.stderr();
    assert!(err.contains("CONTROLLER FAILED") && err.contains("exit status 7"), "{err}");
    // The plant was stopped cleanly: summary printed and the recording finalised.
    assert!(run.stdout().contains("ticks"), "{}", run.stdout());
    Recording::open_complete(out.join("run.mcap")).expect("finalised recording");
}
