//! End-to-end with the real daemons: a lockstep run of `plant-sim` + `hold-controller` recorded,
//! then replayed into the same controller (torques bit-identical after the plant's blend-in) and
//! into a changed one (a known 0.5 N m offset on joint 1); a SIGKILLed and a SIGINTed plant leave
//! readable files.
//!
//! Needs the binaries in the target folder (`cargo build --release -p plant-sim -p tests`);
//! skips with a `SKIP:` line when they are missing.

use recording_tools::cli::ReplayArgs;
use recording_tools::read::{Integrity, Recording};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn bin_dir() -> PathBuf {
    // target/release/deps/replay_e2e-<hash> -> target/release
    std::env::current_exe().unwrap().parent().unwrap().parent().unwrap().to_path_buf()
}

fn binaries() -> Option<(PathBuf, PathBuf)> {
    let d = bin_dir();
    let (plant, hold) = (d.join("plant-sim"), d.join("hold-controller"));
    if plant.is_file() && hold.is_file() {
        Some((plant, hold))
    } else {
        println!("SKIP: {} or {} not built (cargo build --release -p plant-sim -p tests)", plant.display(), hold.display());
        None
    }
}

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("recordings-e2e-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn start_plant(plant: &Path, rig: &str, mode: &str, duration: f64, out: &Path) -> Child {
    Command::new(plant)
        .args(["--rig", rig, "--mode", mode, "--duration", &duration.to_string()])
        .arg("--scenario")
        .arg(scenario())
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

fn start_controller(exe: &Path, rig: &str, extra: &[&str]) -> Child {
    Command::new(exe)
        .args(["--rig", rig])
        .arg("--scenario")
        .arg(scenario())
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

fn wait(mut c: Child, limit: Duration) -> std::process::ExitStatus {
    let until = Instant::now() + limit;
    loop {
        if let Some(s) = c.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > until {
            let _ = c.kill();
            panic!("process did not finish within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Wait until the recording at `path` holds at least `bytes` (its first chunks are on disk).
fn wait_for_recording(path: &Path, bytes: u64, limit: Duration) {
    let until = Instant::now() + limit;
    while std::fs::metadata(path).map_or(0, |m| m.len()) < bytes {
        assert!(Instant::now() < until, "{} did not reach {bytes} bytes within {limit:?}", path.display());
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A lockstep recording of `seconds` with the given controller.
fn record_lockstep(plant: &Path, controller: &Path, extra: &[&str], name: &str, seconds: f64) -> PathBuf {
    let out = tmp(name);
    let rig = format!("e2e-{}-{name}", std::process::id()).replace(".mcap", "");
    let p = start_plant(plant, &rig, "lockstep", seconds, &out);
    let c = start_controller(controller, &rig, extra);
    assert!(wait(p, Duration::from_secs(120)).success(), "plant-sim failed");
    let _ = wait(c, Duration::from_secs(10));
    out
}

/// Replay `file` into `controller` in lockstep (the recording's own scenario and a fresh rig).
fn lockstep_replay(file: &Path, controller: PathBuf, json: Option<PathBuf>) -> ReplayArgs {
    ReplayArgs {
        file: file.to_path_buf(),
        speed: None,
        controller: Some(controller),
        scenario: None,
        rig: None,
        watchdog: 2.0,
        json,
        allow_truncated: false,
    }
}

#[test]
fn replay_into_the_same_controller_reproduces_its_torques_and_a_changed_one_shows_its_change() {
    let Some((plant, hold)) = binaries() else { return };
    // hold-controller takes a plant silent for 100 ms for dead by default; a loaded CI host
    // stalled this test's plant for 365 ms once (2026-12-06), and the run then ended in a safe
    // stop. This test is not about stalls: 5 s.
    let file = record_lockstep(&plant, &hold, &["--silence-ms", "5000"], "lockstep.mcap", 0.3);
    let rec = Recording::open_complete(&file).unwrap();
    let ticks = rec.check_continuity().unwrap();
    assert_eq!(rec.joint_state.len(), 300, "{ticks:?}");
    assert_eq!(rec.dropped(), 0);
    // The official Python reader finds the same 300 ticks on every channel (when installed).
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../recordings/python/check_recording.py");
    match Command::new("python3").arg(&script).arg(&file).args(["--expect-ticks", "300"]).output() {
        Ok(o) if o.status.code() == Some(0) => {}
        Ok(o) if String::from_utf8_lossy(&o.stderr).contains("ModuleNotFoundError") => {
            println!("SKIP (python part): pip install mcap mcap-ros2-support")
        }
        Ok(o) => panic!("python check failed: {}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr)),
        Err(e) => println!("SKIP (python part): no python3: {e}"),
    }

    let args = |controller: PathBuf| lockstep_replay(&file, controller, None);
    let same = recording_tools::replay::run(&args(hold.clone())).unwrap();
    assert!(same.lockstep);
    let c = same.comparison.expect("the controller answered");
    assert_eq!(c.ticks_compared + c.ticks_blending + c.ticks_held + c.ticks_unanswered, 300);
    assert!(c.ticks_compared >= 200, "{c:?}");
    assert_eq!(c.ticks_unanswered, 0);
    assert!(c.identical, "same controller, same states: bit-identical torques expected, {c:?}");

    // A changed controller: the same law plus 0.5 N m on joint 1 (hold-controller --offset-nm).
    let wrapper = tmp("offset-controller.sh");
    std::fs::write(&wrapper, format!("#!/bin/sh\nexec '{}' --offset-nm 0.5 \"$@\"\n", hold.display())).unwrap();
    std::process::Command::new("chmod").arg("+x").arg(&wrapper).status().unwrap();
    let changed = recording_tools::replay::run(&args(wrapper)).unwrap();
    let c = changed.comparison.unwrap();
    assert!(!c.identical);
    assert!((c.max_abs_nm[0] - 0.5).abs() < 1e-9 && (c.rms_nm[0] - 0.5).abs() < 1e-9, "{c:?}");
    assert!(c.max_abs_nm[1..].iter().all(|&d| d == 0.0), "{c:?}");
}

#[test]
fn a_killed_and_an_interrupted_plant_leave_readable_files() {
    let Some((plant, hold)) = binaries() else { return };
    for (signal, name) in [(libc::SIGKILL, "killed.mcap"), (libc::SIGINT, "interrupted.mcap")] {
        let out = tmp(name);
        let rig = format!("e2e-{}-{}", std::process::id(), name.replace(".mcap", ""));
        let p = start_plant(&plant, &rig, "realtime", 60.0, &out);
        let c = start_controller(&hold, &rig, &[]);
        // Run until the file holds a few complete chunks (1 s flush interval). The plant may first
        // build the strip model (a fresh clone, a loaded machine), so wait for the recording to
        // grow rather than for a fixed time.
        wait_for_recording(&out, 256 * 1024, Duration::from_secs(120));
        std::thread::sleep(Duration::from_millis(2500));
        // SAFETY: kill(2) on a pid we spawned; no memory is touched.
        unsafe { libc::kill(p.id() as i32, signal) };
        let status = wait(p, Duration::from_secs(20));
        let _ = wait(c, Duration::from_secs(10));
        let rec = Recording::open(&out).unwrap();
        assert!(rec.joint_state.len() > 500, "{name}: only {} ticks recovered", rec.joint_state.len());
        rec.check_continuity().unwrap();
        if signal == libc::SIGKILL {
            assert!(matches!(rec.integrity, Integrity::Cut(_)), "a SIGKILLed plant cannot have written the footer: {:?}", rec.integrity);
            rig_process::ports::clean_dead_nodes();
        } else {
            assert_eq!(rec.integrity, Integrity::Complete, "SIGINT must finalise the file ({status})");
            assert!(rec.summary_metadata("ticks_written").is_some());
        }
    }
}

#[test]
fn replay_into_the_force_controller_reproduces_its_torques() {
    let Some((plant, _)) = binaries() else { return };
    let controller = bin_dir().join("controller");
    if !controller.is_file() {
        println!("SKIP: {} not built (cargo build --release -p controller)", controller.display());
        return;
    }
    let file = record_lockstep(&plant, &controller, &[], "force.mcap", 1.5);
    let rec = Recording::open_complete(&file).unwrap();
    rec.check_continuity().unwrap();
    let out = recording_tools::replay::run(&lockstep_replay(&file, controller, Some(tmp("force-replay.json")))).unwrap();
    let c = out.comparison.unwrap();
    assert_eq!(c.ticks_compared + c.ticks_blending + c.ticks_held + c.ticks_unanswered, rec.joint_state.len());
    assert!(c.ticks_compared >= 1000 && c.identical, "{c:?}");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(tmp("force-replay.json")).unwrap()).unwrap();
    assert_eq!(json["comparison"]["identical"], true);
}
