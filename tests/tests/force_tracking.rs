//! End-to-end force tracking of issue 6: the real `plant-sim` (robot + strip + contact) and the
//! real `controller` in LOCKSTEP mode (deterministic), the thesis servo run read back from the
//! MCAP recording. Build first: `cargo build --release --workspace --bins`.
//!
//! Metric (issue 6): over the rolling phase — the ticks whose position reference along the strip
//! (controller diagnostics, task z) has left z_start and not yet reached z_end while the force
//! law is active — the error | |bottom force| − |force reference| |.
//!   default scenario (integral action): max ≤ 0.10 N, RMS ≤ 0.03 N
//!   thesis scenario (no integral action): max ≤ 0.45 N (the thesis' Figure 6.7 result)

use std::path::{Path, PathBuf};
use std::time::Duration;

use recordings::read::Recording;
use rig_tests::*;
use scenario::Scenario;

fn scenario_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenarios").join(name)
}

/// Max and RMS tracking error over the rolling phase, and the number of rolling ticks.
fn rolling_tracking(rec: &Recording, s: &Scenario) -> (f64, f64, usize) {
    let (z0, z1) = (s.trajectory.z_start_mm * 1e-3, s.trajectory.z_end_mm * 1e-3);
    let rows = rec.controller_by_tick();
    let errors: Vec<f64> = rows
        .iter()
        .zip(&rec.strip)
        .filter_map(|(c, strip)| {
            let c = &rec.controller[(*c)?];
            let z = c.pos_ref_task_m[2];
            (c.force_control_active == 1 && z > z0 && z < z1).then(|| (strip.bottom_force_n.abs() - c.force_ref_n.abs()).abs())
        })
        .collect();
    let n = errors.len();
    let max = errors.iter().cloned().fold(0.0, f64::max);
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n.max(1) as f64).sqrt();
    (max, rms, n)
}

/// One lockstep servo run of `scenario`: plant + controller, recording read back.
fn lockstep_servo_run(tag: &str, scenario: &Path) -> Recording {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let out = dir.join("run.mcap");
    let sc = scenario.to_str().unwrap();
    let mut plant = Daemon::start(
        "plant",
        &bin("plant-sim"),
        &["--rig", &rig, "--scenario", sc, "--mode", "lockstep", "--out", out.to_str().unwrap()],
        &dir,
    );
    let mut ctrl = start_controller("controller", "controller", &rig, scenario, &dir, &[]);
    // The first run may build and cache the strip model (seconds).
    let ps = plant.expect_exit(Duration::from_secs(300));
    assert!(ps.success(), "plant failed: {}", plant.stderr());
    let cs = ctrl.expect_exit(Duration::from_secs(10));
    assert!(cs.success(), "controller failed: {}", ctrl.stderr());
    let summary = plant_summary(&plant);
    assert_eq!(summary["misses"], 0, "{summary}");
    assert_eq!(summary["drops"], 0, "{summary}");
    Recording::open_complete(&out).expect("complete recording")
}

#[test]
fn default_scenario_with_integral_action_tracks_within_the_issue_bounds() {
    let path = scenario_file("default.toml");
    let s = Scenario::load(&path).unwrap();
    assert!(s.controller.force_integral, "the default scenario uses integral action");
    let rec = lockstep_servo_run("track-default", &path);
    let (max, rms, n) = rolling_tracking(&rec, &s);
    eprintln!("default (integral), lockstep: max {max:.4} N, RMS {rms:.4} N over {n} rolling ticks");
    // The roll lasts roll_s at the control period (minus its two end ticks).
    let expected = (s.trajectory.roll_s / s.loop_.period_s).round() as usize;
    assert!(n + 2 >= expected && n <= expected, "{n} rolling ticks, expected about {expected}");
    assert!(max <= 0.10, "max tracking error {max} N > 0.10 N");
    assert!(rms <= 0.03, "RMS tracking error {rms} N > 0.03 N");
}

#[test]
fn thesis_controller_without_integral_action_stays_within_the_thesis_result() {
    let path = scenario_file("thesis.toml");
    let s = Scenario::load(&path).unwrap();
    assert!(!s.controller.force_integral);
    let rec = lockstep_servo_run("track-thesis", &path);
    let (max, rms, n) = rolling_tracking(&rec, &s);
    eprintln!("thesis (no integral), lockstep: max {max:.4} N, RMS {rms:.4} N over {n} rolling ticks");
    assert!(n > 0, "no rolling phase in the recording");
    assert!(max <= 0.45, "max tracking error {max} N > 0.45 N (thesis Figure 6.7)");
}
