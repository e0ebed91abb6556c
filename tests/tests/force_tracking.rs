//! End-to-end force tracking of issue 6: the real `plant-sim` (robot + strip + contact) and the
//! real `controller` in LOCKSTEP mode (deterministic), the thesis servo run read back from the
//! MCAP recording. Build first: `cargo build --release --workspace --bins`.
//!
//! Metric (issue 6, `recording_tools::tracking`, what `rig run` prints): over the rolling phase —
//! the ticks in contact whose position reference along the strip (controller diagnostics, task z)
//! changed since the previous tick — the error |bottom force| − |force reference|.
//!   default scenario (integral action): max ≤ 0.10 N, RMS ≤ 0.03 N
//!   thesis scenario (no integral action): max ≤ 0.45 N (the thesis' Figure 6.7 result)

use std::path::{Path, PathBuf};
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use scenarios::Scenario;

fn scenario_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenarios").join(name)
}

/// Max and RMS tracking error over the rolling phase, and the number of rolling ticks: the
/// numbers `rig report` and `rig run` print (`recording_tools::tracking`, one rule for all).
fn rolling_tracking(rec: &Recording) -> (f64, f64, usize) {
    let t = recording_tools::report::force_tracking(rec).expect("a rolling phase with force set-points");
    (t.max_abs_n, t.rms_n, t.samples)
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
    let (max, rms, n) = rolling_tracking(&rec);
    eprintln!("default (integral), lockstep: max {max:.4} N, RMS {rms:.4} N over {n} rolling ticks");
    // The roll lasts roll_s at the control period: the reference moves on each of those ticks (the
    // one that reaches z_end included), up to two fewer if the roll does not start on a tick.
    let expected = (s.trajectory.roll_s / s.loop_.period_s).round() as usize;
    assert!(n + 2 >= expected && n <= expected, "{n} rolling ticks, expected about {expected}");
    assert!(max <= 0.10, "max tracking error {max} N > 0.10 N");
    assert!(rms <= 0.03, "RMS tracking error {rms} N > 0.03 N");
    // Figure 7.4: with the wheel at z = 8 mm the recorded centre-line bottom pressure (the
    // reduced dynamic model under the controlled wheel) matches the static FULL finite-element
    // solution for that tick's wheel force, bulge included. The roll is slow against the strip's
    // dynamics, so "within a few percent" (the issue) is in fact well under 1 %.
    let model = strip::StripModel::load_or_build(&plant_sim::contact::strip_params(&s)).unwrap();
    let c = design::stress::compare_at(&rec, &model, 8e-3).unwrap();
    eprintln!(
        "Figure 7.4 at z = {:.3} mm, {:.3} N: max |recorded - full static| / peak {:.3} %",
        c.wheel_z_m * 1e3,
        c.wheel_force_n,
        100.0 * c.max_rel_diff
    );
    assert!(c.profile.len() >= 30 && (c.wheel_force_n + 10.0).abs() < 0.1, "{c:?}");
    assert!(c.max_rel_diff < 0.01, "recorded vs full static bottom pressure differ by {:.2} % of the peak", 100.0 * c.max_rel_diff);
}

/// Issue 6 and issue 24 item 4: halving the plant's integration substep changes the
/// force-tracking numbers by less than 1 % (default scenario, its 8 against 16 substeps per tick,
/// both in lockstep): the figures are converged in the substep.
#[test]
fn halving_the_substep_changes_the_tracking_numbers_by_less_than_one_percent() {
    let path = scenario_file("default.toml");
    let s = Scenario::load(&path).unwrap();
    let n = s.loop_.substeps;
    assert_eq!(n, 8);
    let text = std::fs::read_to_string(&path).unwrap();
    let line = format!("\nsubsteps = {n}\n");
    assert!(text.contains(&line));
    let dir = temp_dir(&unique_rig("substeps"));
    let fine = dir.join(format!("substeps{}.toml", 2 * n));
    std::fs::write(&fine, text.replace(&line, &format!("\nsubsteps = {}\n", 2 * n))).unwrap();
    assert_eq!(Scenario::load(&fine).unwrap().loop_.substeps, 2 * n);
    let (m1, r1, _) = rolling_tracking(&lockstep_servo_run("sub1", &path));
    let (m2, r2, _) = rolling_tracking(&lockstep_servo_run("sub2", &fine));
    let (dm, dr) = ((m2 - m1).abs() / m2, (r2 - r1).abs() / r2);
    eprintln!("substeps {n} -> {}: max {m1:.6} -> {m2:.6} N ({:.3} %), RMS {r1:.6} -> {r2:.6} N ({:.3} %)", 2 * n, 100.0 * dm, 100.0 * dr);
    assert!(dm < 0.01 && dr < 0.01, "max changes {:.3} %, RMS {:.3} %", 100.0 * dm, 100.0 * dr);
}

/// Issue 24 item 4: the speed work (8 substeps instead of 10, the midpoint's first stage on the
/// previous midpoint's mass matrix factor and bias) moves the default run's force-tracking
/// figures by less than 1 % from the tree before it (dc912d3: 10 substeps, every stage in full;
/// its `rig sweep` case of the default scenario read back max 0.028866270314262366 N, RMS
/// 0.01638362755103625 N, the bond share 0.5968498699223171).
#[test]
fn the_speed_work_moves_the_default_tracking_figures_by_less_than_one_percent() {
    let (max_before, rms_before, bond_before) = (0.028866270314262366, 0.01638362755103625, 0.5968498699223171);
    let rec = lockstep_servo_run("speed-figures", &scenario_file("default.toml"));
    let (max, rms, _) = rolling_tracking(&rec);
    let bond = recording_tools::report::numbers(&rec).rolling.and_then(|r| r.bond_pressure_share).unwrap();
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    eprintln!(
        "default, before -> now: max {max_before:.6} -> {max:.6} N ({:+.3} %), RMS {rms_before:.6} -> {rms:.6} N ({:+.3} %), bond share {bond_before:.6} -> {bond:.6}",
        100.0 * (max / max_before - 1.0),
        100.0 * (rms / rms_before - 1.0)
    );
    assert!(rel(max, max_before) < 0.01 && rel(rms, rms_before) < 0.01, "max {max} N, RMS {rms} N");
    assert!(rel(bond, bond_before) < 0.01, "bond share {bond}");
}

#[test]
fn thesis_controller_without_integral_action_stays_within_the_thesis_result() {
    let path = scenario_file("thesis.toml");
    let s = Scenario::load(&path).unwrap();
    assert!(!s.controller.force_integral);
    let rec = lockstep_servo_run("track-thesis", &path);
    let (max, rms, n) = rolling_tracking(&rec);
    eprintln!("thesis (no integral), lockstep: max {max:.4} N, RMS {rms:.4} N over {n} rolling ticks");
    assert!(n > 0, "no rolling phase in the recording");
    assert!(max <= 0.45, "max tracking error {max} N > 0.45 N (thesis Figure 6.7)");
}

/// Highest centre-line bottom pressure each node saw while the wheel was over it (within half a
/// node spacing), for the nodes from `z_from` to `z_to`: (node z, pressure) pairs.
fn pressure_under_the_wheel(rec: &Recording, z_from: f64, z_to: f64) -> Vec<(f64, f64)> {
    let z_nodes = rec.centreline_z_m();
    assert!(z_nodes.len() >= 2, "no centre-line node positions in the recording");
    let half = 0.5 * (z_nodes[1] - z_nodes[0]);
    let in_contact: Vec<&recordings::schema::StripRow> = rec.strip.iter().filter(|s| s.contact_force_n.abs() > 1.0).collect();
    z_nodes
        .iter()
        .enumerate()
        .filter(|(_, &z)| z >= z_from - 1e-9 && z <= z_to + 1e-9)
        .map(|(k, &z)| {
            let p = in_contact
                .iter()
                .filter(|s| (s.wheel_z_m - z).abs() <= half)
                .map(|s| s.centreline_pressure_pa[k] as f64)
                .fold(f64::NEG_INFINITY, f64::max);
            (z, p)
        })
        .collect()
}

/// The bond (Section 4.2, Appendix C) needs 100 kPa on the centre line under the wheel. At -10 N
/// the bonded strip's tension over the bulge's flanks keeps some positions short of it (see the
/// README): every node of the rolled length from z = 4 to 36 mm must see 100 kPa while the wheel
/// is over it, and the force must still track, in `file`.
fn bonds_the_whole_rolled_length(file: &str) {
    let path = scenario_file(file);
    let rec = lockstep_servo_run(file.trim_end_matches(".toml"), &path);
    let (max, rms, _) = rolling_tracking(&rec);
    assert!(max <= 0.10 && rms <= 0.03, "{file}: tracking max {max} N, RMS {rms} N");
    let under = pressure_under_the_wheel(&rec, 4e-3, 36e-3);
    assert!(under.len() >= 30, "only {} centre-line nodes between 4 and 36 mm", under.len());
    let weakest = under.iter().cloned().fold((0.0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    eprintln!("{file}: weakest centre-line pressure under the wheel {:.1} kPa at z = {:.1} mm", weakest.1 * 1e-3, weakest.0 * 1e3);
    assert!(weakest.1 >= 100e3, "{file}: z = {} mm saw only {} Pa under the wheel", weakest.0 * 1e3, weakest.1);
    // The report's share over the whole roll agrees.
    let share = recording_tools::report::numbers(&rec).rolling.and_then(|r| r.bond_pressure_share).unwrap();
    assert!(share >= 0.999, "{file}: report: {share}");
}

/// `scenarios/bond.toml` presses with a constant -14 N.
#[test]
fn pressing_with_14_n_bonds_the_whole_rolled_length() {
    bonds_the_whole_rolled_length("bond.toml");
}

/// `scenarios/bond_scheduled.toml` presses with -10 N where the substrate is flat and up to
/// -13.5 N over the flanks (`trajectory.force_ref_along_z`, with the rate fed forward); the
/// set-point actually varies along the roll.
#[test]
fn a_force_set_point_along_the_strip_bonds_the_whole_rolled_length() {
    let s = Scenario::load(&scenario_file("bond_scheduled.toml")).unwrap();
    let forces: Vec<f64> = s.trajectory.force_ref_along_z.iter().map(|k| k[1]).collect();
    assert!(forces.iter().any(|&f| f == -10.0) && forces.iter().any(|&f| f < -13.0), "{forces:?}");
    bonds_the_whole_rolled_length("bond_scheduled.toml");
}
