//! The tick's code, whatever drives it, gives the same physics bit for bit (issue 13).
//!
//! `EXPECTED` holds the physics digests ([`harness::physics_digest`]) of lockstep runs of the
//! default, thesis and bond_scheduled scenarios (`rig run <scenario> --mode lockstep`): a refactor
//! that changes any state, wrench, torque or strip record of any tick changes the digest. They were
//! made with the tree before the tick core was refactored (commit 92cd897) and re-based once, by
//! the plant's speed work of issue 24 item 4 (8 substeps instead of 10, the midpoint's first stage
//! on the previous midpoint's mass matrix factor and bias), which changes the numbers on purpose
//! (`force_tracking.rs` bounds how much). The realistic cell (`cell.toml`: the sensor's chain,
//! the drives' friction and encoders, the controller's mismatched model) was pinned at 45d91da,
//! before its sensor shared the tick's forward kinematics with the contact wrench.
//!
//! The in-process run (`rig run --mode lockstep --in-process`: plant tick and controller step in
//! one thread, no iceoryx2) must give the same digests: the transport is transparent.
//!
//! Build first: `cargo build --release --workspace --bins`.

use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;

const EXPECTED: [(&str, &str); 4] = [
    ("default", "f21387fcad1a39dd (3600 states, 3600 wrenches, 3600 torques, 3600 strip records)"),
    ("thesis", "4b41f2936126cfe4 (3600 states, 3600 wrenches, 3600 torques, 3600 strip records)"),
    ("bond_scheduled", "1cf94db8edb7b071 (3600 states, 3600 wrenches, 3600 torques, 3600 strip records)"),
    ("cell", "99891980c920e0de (3800 states, 3800 wrenches, 3800 torques, 3800 strip records)"),
];

fn scenario_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenarios").join(format!("{name}.toml"))
}

/// `rig run <scenario> --mode lockstep` as a user runs it; the recording it made.
fn lockstep(name: &str, extra: &[&str]) -> Recording {
    let rig = unique_rig(&format!("id-{name}"));
    let dir = temp_dir(&rig);
    let out = dir.join("out");
    let scenario = scenario_path(name);
    let mut args = vec!["run", scenario.to_str().unwrap(), "--mode", "lockstep", "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let mut run = Daemon::start("rig", &bin("rig"), &args, &dir);
    let st = run.expect_exit(Duration::from_secs(120));
    assert!(st.success(), "rig run {name} failed ({st}):\n{}\n{}", run.stdout(), run.stderr());
    Recording::open_complete(out.join("run.mcap")).expect("complete recording")
}

#[test]
fn lockstep_recordings_are_bit_identical_to_the_pinned_digests() {
    let mut got = Vec::new();
    for (name, _) in EXPECTED {
        let rec = lockstep(name, &[]);
        assert!(rec.joint_state.len() > 1000, "{name}: a real run");
        let d = physics_digest(&rec);
        eprintln!("{name}: {d}");
        got.push((name, d));
    }
    for ((name, want), (_, have)) in EXPECTED.iter().zip(&got) {
        assert_eq!(have, want, "{name}: the lockstep physics changed");
    }
}

#[test]
fn in_process_runs_are_bit_identical_to_the_pinned_lockstep_digests() {
    let mut got = Vec::new();
    for (name, _) in EXPECTED {
        let rec = lockstep(name, &["--in-process"]);
        assert!(rec.joint_state.len() > 1000, "{name}: a real run");
        assert_eq!(rec.run_metadata().unwrap().transport.as_deref(), Some("in-process"), "{name}: ran in process");
        let d = physics_digest(&rec);
        eprintln!("{name} in-process: {d}");
        got.push((name, d));
    }
    for ((name, want), (_, have)) in EXPECTED.iter().zip(&got) {
        assert_eq!(have, want, "{name}: the in-process run differs from the lockstep daemons");
    }
}
