//! End-to-end: the Python template controller `examples/python_controller/hold_controller.py`
//! (iceoryx2 Python bindings + Pinocchio) drives the real `plant-sim`. Build first:
//! `cargo build --release --workspace --bins`; needs `pip install iceoryx2==0.10.0 pin numpy`
//! (the tests fail without them; `.ci/deps` installs them).

use std::path::PathBuf;
use std::sync::MutexGuard;
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;
use robot::Vec6;

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/python_controller/hold_controller.py")
}

/// A lockstep rig running `duration_s` with the Python hold controller on it (see
/// [`harness::python_rig`]); `None` without the Python modules.
fn python_rig(test: &str, tag: &str, duration_s: f64) -> Option<(MutexGuard<'static, ()>, TestRig, Daemon, Daemon)> {
    harness::python_rig(test, tag, duration_s, &script(), "iceoryx2, pinocchio, numpy", "iceoryx2==0.10.0 pin numpy", "")
}

#[test]
fn python_controller_holds_the_arm_in_lockstep_with_gravity_equal_to_the_rust_model() {
    let Some((_g, t, mut plant, mut py)) = python_rig("python_controller_holds_the_arm", "py-hold", 1.0) else { return };
    assert!(plant.expect_exit(Duration::from_secs(60)).success(), "plant: {}", plant.stderr());
    assert!(py.expect_exit(Duration::from_secs(10)).success(), "python controller: {}", py.stderr());

    let summary = plant_summary(&plant);
    assert_eq!(summary["misses"], 0, "{summary}");
    assert_eq!(summary["safe_stops"], 0, "{summary}");
    let rec = Recording::open_complete(t.recording()).expect("complete recording");
    assert_eq!(rec.joint_state.len(), 1000);
    rec.check_continuity().expect("every tick recorded once, in order");
    assert_eq!(rec.events_of(EventKind::SafeStop).count(), 0, "{:?}", rec.events);
    assert_eq!(rec.events_of(EventKind::ControllerChange).count(), 1, "one controller: {:?}", rec.events);
    assert!(rec.joint_torque.iter().all(|r| !r.held), "lockstep applies every answer");

    // Hold: the model matches the plant's (tool included), so the arm stays put. A model without
    // the 1 kg tool would leave a static error of ~1e-3 rad (9e-4 measured).
    let q0 = Vec6::from(rec.joint_state[0].q);
    let drift = rec.joint_state.iter().map(|s| (Vec6::from(s.q) - q0).amax()).fold(0.0, f64::max);
    assert!(drift < 1e-6, "joints drift {drift:.3e} rad from the start pose");

    // Independent check of the Python model: at tick 0, qd = 0 and e = 0, so tau = g(q0), which
    // must equal the Rust `robot` crate's gravity torque of the plant's tool-equipped arm.
    assert_eq!(rec.joint_state[0].qd, [0.0; 6], "the plant starts at rest");
    let s = scenarios::Scenario::load(&t.scenario).unwrap();
    let robot = scenarios::geometry::nominal_robot(&s);
    let g = robot.gravity_torque(&q0);
    let first = rec.joint_torque.iter().find(|r| r.tick == 0).and_then(|r| r.commanded).expect("tick 0 answer recorded");
    let rel = (Vec6::from(first) - g).norm() / g.norm();
    assert!(rel < 1e-9, "Python tau(tick 0) {first:?} vs Rust g(q0) {g:?}: relative difference {rel:.2e}");
    // Compared with the bare arm the tool's gravity torque is visible (the check above can fail).
    let bare = (robot::Robot::irb2400().gravity_torque(&q0) - g).norm() / g.norm();
    assert!(bare > 1e-3, "the tool changes g(q0) by only {bare:.2e}");

    // Its stage stamps (contract version 2) arrive with every answer and sit, on the plant's own
    // clock, between the plant's wake-up and its receipt, in the order taken (the controller may
    // wake before the plant's "published" stamp: the notification goes out inside the publish).
    for r in &rec.timing {
        let s = r.timing.stages.expect("stage stamps on /timing");
        let c = s.controller.unwrap_or_else(|| panic!("tick {}: no controller stamps", r.tick));
        assert!(
            s.plant_woke_ns <= c.woke_ns
                && c.woke_ns <= c.computed_ns
                && c.computed_ns <= c.published_ns
                && c.published_ns <= s.torque_received_ns,
            "tick {}: plant woke {} controller woke {} computed {} handed over {} received {}",
            r.tick,
            s.plant_woke_ns,
            c.woke_ns,
            c.computed_ns,
            c.published_ns,
            s.torque_received_ns
        );
    }

    let mut compute: Vec<u64> = rec.controller.iter().map(|d| d.compute_time_ns).collect();
    compute.sort_unstable();
    println!(
        "python controller: {} ticks, compute p50 {:.1} us, max {:.1} us; tau(0) vs Rust g(q0) {rel:.1e}; drift {drift:.1e} rad",
        compute.len(),
        compute[compute.len() / 2] as f64 * 1e-3,
        compute[compute.len() - 1] as f64 * 1e-3
    );
}

#[test]
fn python_controller_exits_with_an_error_when_the_plant_dies() {
    let Some((_g, _t, mut plant, mut py)) = python_rig("python_controller_exits_when_the_plant_dies", "py-dead", 600.0) else { return };
    wait_for_log(&plant, "connected", Duration::from_secs(20));
    plant.signal(libc::SIGKILL);
    plant.expect_exit(Duration::from_secs(5));
    let st = py.expect_exit(Duration::from_secs(5));
    assert!(!st.success(), "a dead plant is an error for the controller");
    assert!(py.stderr().contains("plant") && py.stderr().contains("silent"), "{}", py.stderr());
}

/// A controller of contract version 1 is refused with both versions named: the template as it was
/// at version 1 (version 1, 120-byte diagnostics on `controller_diagnostics`), derived from the
/// current file by undoing version 2's four changes. It opens its services (its diagnostics'
/// service is its own: iceoryx2 would refuse a 120-byte payload on the plant's
/// `controller_diagnostics_v2`) and exits 1 on the first state, naming both versions.
#[test]
fn a_version_1_controller_is_refused_with_both_versions_named() {
    let v2 = std::fs::read_to_string(script()).unwrap();
    let mut v1 = v2.clone();
    for (from, to) in [
        ("CONTRACT_VERSION = 2\n", "CONTRACT_VERSION = 1\n"),
        ("(ControllerDiagnostics, 144)", "(ControllerDiagnostics, 120)"),
        ("\"controller_diagnostics_v2\"", "\"controller_diagnostics\""),
        (
            ", woke_mono_ns=woke,\n                                     computed_mono_ns=computed, published_mono_ns=time.monotonic_ns())",
            ")",
        ),
    ] {
        assert_eq!(v1.matches(from).count(), 1, "hold_controller.py changed: {from:?} not found once; update this test");
        v1 = v1.replace(from, to);
    }
    // The three stamp fields (and their comment) go: the record ends at compute_time_ns again.
    let (from, to) = ("(\"compute_time_ns\", u64),", "(\"published_mono_ns\", u64)]");
    let (a, b) = (v1.find(from).expect("compute_time_ns field"), v1.find(to).expect("published_mono_ns field"));
    assert!(a < b && v1[a..b].matches("_fields_").count() == 0, "hold_controller.py changed: update this test");
    v1.replace_range(a..b + to.len(), "(\"compute_time_ns\", u64)]");
    let dir = std::env::temp_dir().join(unique_rig("py-v1"));
    std::fs::create_dir_all(&dir).unwrap();
    let old = dir.join("hold_controller_v1.py");
    std::fs::write(&old, v1).unwrap();
    std::fs::set_permissions(&old, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let Some((_g, _t, mut plant, mut py)) = harness::python_rig(
        "a_version_1_controller_is_refused",
        "py-v1",
        1.0,
        &old,
        "iceoryx2, pinocchio, numpy",
        "iceoryx2==0.10.0 pin numpy",
        "",
    ) else {
        return;
    };
    let st = py.expect_exit(Duration::from_secs(60));
    let err = py.stderr();
    assert!(!st.success(), "a version-1 controller ran: {err}");
    assert!(
        err.contains("contract version mismatch on joint state: peer speaks version 2, this process speaks version 1"),
        "not refused by version (an iceoryx2 error instead?): {err}"
    );
    plant.signal(libc::SIGTERM);
    plant.expect_exit(Duration::from_secs(10));
}
