//! End to end: a controller that never connects is named within seconds (issue 27, item 4).
//! `rig run` with `loop.connect_timeout_s` = 2 and a controller process that stays alive but
//! answers no state: one that creates its node with iceoryx2's default configuration, one that
//! opens another rig's name, one of contract version 1, one that sleeps past the timeout. Each
//! gets one sentence naming the program, its pid, what rig saw and the fix within the timeout
//! plus 1 s, an `/events` entry, both daemons stopped and exit 3; one that sleeps less than the
//! timeout runs as usual. The misbehaving controller is `hold-controller` with its
//! never-connecting flags (tests/src/bin/hold_controller.rs), through a wrapper script.
//! Build first: `cargo build --release --workspace --bins`.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const CONNECT_TIMEOUT_S: f64 = 2.0;

/// `rig run` of a robot-only scenario with the connect timeout, `mode`, `duration_s`, `flags`.
fn run(tag: &str, mode: &str, duration_s: &str, flags: &[&str]) -> (Daemon, PathBuf, PathBuf, Instant) {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, mode, &format!("connect_timeout_s = {CONNECT_TIMEOUT_S}\n"));
    let ctrl = exec_wrapper(&dir, &format!("{tag}.sh"), &bin("hold-controller"), flags);
    let out = dir.join("out");
    let started = Instant::now();
    let args = [
        "run",
        scenario.to_str().unwrap(),
        "--mode",
        mode,
        "--duration",
        duration_s,
        "--controller",
        ctrl.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    (Daemon::start("rig", &bin("rig"), &args, &dir), ctrl, out, started)
}

/// The never-connected sentence: said within the timeout plus 1 s of `rig run`'s start, naming
/// the program and its pid and containing `seen`; then exit 3 with both daemons stopped and the
/// plant's `/events` entry.
fn never_connected(tag: &str, mode: &str, flags: &[&str], seen: &str) {
    let (mut rig, ctrl, out, started) = run(tag, mode, "600", flags);
    let said = loop {
        let err = rig.stderr();
        if let Some(line) = err.lines().find(|l| l.starts_with("rig: CONTROLLER NEVER CONNECTED: ")) {
            break (started.elapsed(), line.to_string());
        }
        assert!(started.elapsed() < Duration::from_secs(30), "{tag}: no sentence within 30 s:\n{err}");
        std::thread::sleep(Duration::from_millis(10));
    };
    eprintln!("{tag}: after {:.2} s: {}", said.0.as_secs_f64(), said.1);
    let st = rig.expect_exit(Duration::from_secs(20));
    let done = started.elapsed();
    let logs = format!("stdout:\n{}\nstderr:\n{}", rig.stdout(), rig.stderr());
    assert!(said.0.as_secs_f64() <= CONNECT_TIMEOUT_S + 1.0, "{tag}: said after {:.2} s\n{logs}", said.0.as_secs_f64());
    let line = &said.1;
    assert!(line.contains(&format!("the controller {} (pid ", ctrl.display())), "{tag}: names the program: {line}");
    assert!(line.contains(seen), "{tag}: says what was seen ({seen:?}): {line}");
    assert_eq!(line.matches(". ").count(), 0, "{tag}: one sentence: {line}");
    assert_eq!(st.code(), Some(3), "{tag}: {logs}");
    eprintln!("{tag}: exit 3 after {:.2} s", done.as_secs_f64());
    let last = rig.stdout().lines().last().unwrap_or_default().to_string();
    assert!(last.starts_with("rig: exit 3: controller never connected: "), "{tag}: {last}");
    let rec = Recording::open_complete(out.join("run.mcap")).expect("a complete recording");
    assert!(
        rec.events_of(EventKind::ControllerEnded).any(|e| e.text.contains("never connected")),
        "{tag}: an /events entry: {:?}",
        rec.events
    );
}

#[test]
fn a_controller_on_iceoryx2s_default_configuration_is_named_with_the_rigs_configuration_file() {
    let _g = serial();
    let cfg = rig_process::host::config_path();
    never_connected("nc-defaults", "lockstep", &["--iceoryx2-defaults"], &format!("load that configuration, {}", cfg.display()));
}

#[test]
fn a_controller_on_iceoryx2s_default_configuration_is_named_in_real_time_too() {
    let _g = serial();
    never_connected("nc-defaults-rt", "realtime", &["--iceoryx2-defaults"], "has no iceoryx2 node of rig");
}

#[test]
fn a_controller_that_opens_another_rigs_name_is_named_with_that_rig() {
    let _g = serial();
    never_connected("nc-other-rig", "lockstep", &["--open-rig", "somebody-elses-rig"], "is on rig \"somebody-elses-rig\"");
}

#[test]
fn a_controller_of_another_contract_version_is_named_with_its_version() {
    let _g = serial();
    never_connected("nc-version", "lockstep", &["--contract-version", "1"], "torques of contract version 1");
}

#[test]
fn a_controller_that_sleeps_past_the_connect_timeout_is_named() {
    let _g = serial();
    never_connected("nc-sleeps", "lockstep", &["--sleep-before-open-s", "60"], "has no iceoryx2 node of rig");
}

/// One that connects after 1 s, within the 2 s timeout, runs its second to the end: exit 0.
#[test]
fn a_controller_that_connects_late_within_the_timeout_runs_normally() {
    let _g = serial();
    let (mut rig, _, out, _) = run("nc-late", "lockstep", "1", &["--sleep-before-open-s", "1"]);
    let st = rig.expect_exit(Duration::from_secs(60));
    let logs = format!("stdout:\n{}\nstderr:\n{}", rig.stdout(), rig.stderr());
    assert_eq!(st.code(), Some(0), "{logs}");
    assert!(!logs.contains("NEVER CONNECTED"), "{logs}");
    let rec = Recording::open_complete(out.join("run.mcap")).expect("a complete recording");
    assert_eq!(rec.joint_state.len(), 1000);
    assert!(rec.joint_torque.iter().all(|r| !r.held), "every tick answered");
}
