//! End to end: controllers in C and C++ on rig-client (issue 27) against the real plant. The
//! library is installed with its install command into a fresh prefix and the examples are built
//! by cmake from clean build directories (`harness::client_examples`). Build first:
//! `cargo build --release --workspace --bins`; needs cmake, cc, g++, pkg-config (`.ci/deps`).
//!
//! One run at a time (a process-wide lock): real-time runs on a 2-core machine must not compete.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const LONG: Duration = Duration::from_secs(180);

/// `rig run SCENARIO --out DIR/out ARGS`, as a user types it.
fn rig_run(dir: &Path, scenario: Option<&Path>, args: &[&str]) -> Daemon {
    let out = dir.join("out");
    let mut all = vec!["run"];
    if let Some(s) = scenario {
        all.push(s.to_str().unwrap());
    }
    all.extend_from_slice(&["--out", out.to_str().unwrap()]);
    all.extend_from_slice(args);
    Daemon::start("rig", &bin("rig"), &all, dir)
}

fn logs(d: &Daemon) -> String {
    format!("stdout:\n{}\nstderr:\n{}", d.stdout(), d.stderr())
}

/// The C example completes `rig run --mode lockstep` of the default scenario (strip included)
/// with exit 0: every tick answered, no miss, no safe stop.
#[test]
fn the_c_example_completes_a_default_lockstep_run_with_exit_0() {
    let _g = serial();
    let ex = client_examples();
    let rig = unique_rig("c-default");
    let dir = temp_dir(&rig);
    let mut run = rig_run(&dir, None, &["--mode", "lockstep", "--controller", ex.c_controller.to_str().unwrap()]);
    let st = run.expect_exit(LONG);
    assert_eq!(st.code(), Some(0), "{}", logs(&run));
    let rec = Recording::open_complete(dir.join("out/run.mcap")).expect("a complete recording");
    rec.check_continuity().expect("every tick recorded once, in order");
    assert!(rec.joint_torque.iter().all(|r| !r.held), "lockstep applies every answer");
    assert_eq!(rec.events_of(EventKind::SafeStop).count(), 0, "{:?}", rec.events);
    // Its diagnostics carry the library's stage stamps.
    let stamped = rec.timing.iter().filter(|t| t.timing.stages.and_then(|s| s.controller).is_some()).count();
    assert_eq!(stamped, rec.timing.len(), "every tick's answer carries the stage stamps");
    eprintln!("{}", run.stdout().lines().last().unwrap_or_default());
}

/// One lockstep plant run (robot only, 1 s) with `controller` (a binary started with --rig and
/// --scenario): the torque each tick's answer asked for, by tick.
fn lockstep_answers(tag: &str, controller: &Path) -> Vec<(u64, [f64; 6])> {
    let t = TestRig::new(tag, "lockstep");
    let mut plant = t.plant(1.0);
    let args = ["--rig", t.rig.as_str(), "--scenario", t.scenario.to_str().unwrap()];
    let mut ctrl = Daemon::start("controller", controller, &args, &t.dir);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "{}: {}", controller.display(), ctrl.stderr());
    let rec = Recording::open_complete(t.recording()).expect("a complete recording");
    assert_eq!(rec.joint_state.len(), 1000);
    rec.joint_torque.iter().map(|r| (r.torque.tick, r.commanded.unwrap_or_else(|| panic!("tick {}: no answer recorded", r.tick)))).collect()
}

/// The C++ hold (examples/cpp, rig_client.hpp) and the Rust `hold-controller` on the same
/// lockstep run send the same torques, to 1e-9 N m, at every tick.
#[test]
fn the_cpp_hold_sends_the_rust_hold_controllers_torques_to_1e_9_nm_at_every_tick() {
    let _g = serial();
    let ex = client_examples();
    let rust = lockstep_answers("hold-rs", &bin("hold-controller"));
    let cpp = lockstep_answers("hold-cpp", &ex.cpp_hold);
    assert_eq!(rust.len(), 1000);
    assert_eq!(rust.iter().map(|r| r.0).collect::<Vec<_>>(), cpp.iter().map(|r| r.0).collect::<Vec<_>>(), "the same ticks answered");
    let mut worst = (0.0f64, 0u64, 0usize);
    for ((tick, a), (_, b)) in rust.iter().zip(&cpp) {
        for j in 0..6 {
            let d = (a[j] - b[j]).abs();
            if d > worst.0 {
                worst = (d, *tick, j + 1);
            }
        }
    }
    eprintln!(
        "C++ vs Rust hold: largest torque difference {:.3e} N m (tick {}, joint {}) over {} ticks",
        worst.0,
        worst.1,
        worst.2,
        rust.len()
    );
    assert!(worst.0 <= 1e-9, "the C++ hold differs by {:.3e} N m at tick {} joint {}", worst.0, worst.1, worst.2);
    // The torques are not trivially equal: gravity on joint 2 is hundreds of N m.
    assert!(rust[0].1[1].abs() > 10.0, "{:?}", rust[0].1);
}

fn robot_only(dir: &Path, mode: &str) -> PathBuf {
    write_scenario(dir, mode, "")
}

/// In real time both examples run their 1 s under `rig run` and end with exit 0 when the plant
/// shuts down.
#[test]
fn both_examples_run_in_real_time_and_exit_0_when_the_plant_shuts_down() {
    let _g = serial();
    let ex = client_examples();
    for (tag, ctrl) in [("c-rt", &ex.c_controller), ("cpp-rt", &ex.cpp_hold)] {
        let rig = unique_rig(tag);
        let dir = temp_dir(&rig);
        let scenario = robot_only(&dir, "realtime");
        let mut run = rig_run(&dir, Some(&scenario), &["--mode", "realtime", "--duration", "1", "--controller", ctrl.to_str().unwrap()]);
        let st = run.expect_exit(LONG);
        eprintln!("{tag}: {}", run.stdout().lines().last().unwrap_or_default());
        assert_eq!(st.code(), Some(0), "{tag}: {}", logs(&run));
    }
}

/// Killed mid-run (SIGKILL), each example gives the documented outcome: the plant records the
/// controller's end and enters the safe stop, `rig` exits 3.
#[test]
fn killed_mid_run_each_example_gives_a_safe_stop_and_exit_3() {
    let _g = serial();
    let ex = client_examples();
    for (tag, ctrl) in [("c-kill", &ex.c_controller), ("cpp-kill", &ex.cpp_hold)] {
        let rig = unique_rig(tag);
        let dir = temp_dir(&rig);
        let scenario = robot_only(&dir, "lockstep");
        let mut run = rig_run(&dir, Some(&scenario), &["--mode", "lockstep", "--duration", "600", "--controller", ctrl.to_str().unwrap()]);
        wait_for_log(&run, "connected", Duration::from_secs(30));
        std::thread::sleep(Duration::from_millis(300));
        // /proc/PID/comm holds the first 15 bytes of the name.
        let comm: String = ctrl.file_name().unwrap().to_string_lossy().chars().take(15).collect();
        let pid = child_pid(run.pid(), &comm).unwrap_or_else(|| panic!("{tag}: rig's controller process {comm}"));
        // SAFETY: signalling the controller process rig started for this test.
        unsafe { libc::kill(pid, libc::SIGKILL) };
        let st = run.expect_exit(LONG);
        assert_eq!(st.code(), Some(3), "{tag}: {}", logs(&run));
        assert!(run.stderr().contains("killed by signal 9"), "{tag}: {}", logs(&run));
        let rec = Recording::open_complete(dir.join("out/run.mcap")).expect("a complete recording");
        assert!(
            rec.events_of(EventKind::ControllerEnded).any(|e| e.text.contains("killed by signal 9")),
            "{tag}: the plant recorded the controller's end: {:?}",
            rec.events
        );
        assert!(rec.events_of(EventKind::SafeStop).count() >= 1, "{tag}: a safe stop: {:?}", rec.events);
    }
}

/// The documented install gives a pkg-config file that builds the C example too.
#[test]
fn the_installed_pkg_config_file_builds_the_c_example() {
    let ex = client_examples();
    let out = std::env::temp_dir().join(unique_rig("pkgconfig")).join("minimal_controller");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let flags = Command::new("pkg-config")
        .args(["--cflags", "--libs", "rig_client"])
        .env("PKG_CONFIG_PATH", ex.prefix.join("lib/pkgconfig"))
        .output()
        .expect("pkg-config (bash .ci/deps)");
    assert!(flags.status.success(), "{}", String::from_utf8_lossy(&flags.stderr));
    let flags = String::from_utf8(flags.stdout).unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../rig-client/examples/c/minimal_controller.c");
    let o = Command::new("cc").arg("-std=c11").arg(&src).arg("-o").arg(&out).args(flags.split_whitespace()).output().unwrap();
    assert!(o.status.success(), "cc with pkg-config's flags ({flags}): {}", String::from_utf8_lossy(&o.stderr));
    // It runs and explains its usage (it links the installed library at run time).
    let o = Command::new(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("usage"));
}

/// messages/README.md shows both examples whole, as their ```c and ```cpp blocks.
#[test]
fn the_readme_shows_the_c_and_cpp_examples_as_they_are() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("messages/README.md")).unwrap();
    for (fence, file) in
        [("```c\n", "rig-client/examples/c/minimal_controller.c"), ("```cpp\n", "rig-client/examples/cpp/hold_controller.cpp")]
    {
        let start = readme.find(fence).unwrap_or_else(|| panic!("a {fence:?} block in messages/README.md")) + fence.len();
        let len = readme[start..].find("```\n").expect("the block's end");
        let shipped = std::fs::read_to_string(root.join(file)).unwrap();
        assert!(
            readme[start..start + len] == shipped,
            "messages/README.md's {fence:?} block differs from {file}: copy the file into the block"
        );
    }
}
