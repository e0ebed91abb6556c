//! `rig sweep` end to end: one in-process lockstep case per bump height (several at once), read
//! back. A case must be exactly the run the daemons give under `rig run --mode lockstep` for its
//! scenario (the transport is transparent), and the bump's effect on the bond must superpose linearly (the plant adds the
//! bulge as a static offset to a linear strip model, DESIGN 4).

use std::path::Path;
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;

const LONG: Duration = Duration::from_secs(120);

#[test]
fn a_sweep_over_bump_heights_is_the_runs_it_stands_for_and_the_bump_superposes() {
    let rig = unique_rig("sweep");
    let dir = temp_dir(&rig);
    let out = dir.join("sweep");
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let mut sweep = Daemon::start(
        "rig sweep",
        &bin("rig"),
        &["sweep", base.to_str().unwrap(), "--set", "bulge.height_mm=0,0.1,0.4", "--recordings", "all", "--out", out.to_str().unwrap()],
        &dir,
    );
    let st = sweep.expect_exit(LONG);
    assert!(st.success(), "rig sweep failed ({st}):\n{}\n{}", sweep.stdout(), sweep.stderr());
    assert!(sweep.stdout().contains("| bulge.height_mm=0.4 | 0 | 0 |"), "{}", sweep.stdout());
    let cases: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    let cases = cases.as_array().unwrap();
    assert_eq!(cases.len(), 3);
    let weakest: Vec<f64> = cases.iter().map(|c| c["bond_weakest_pa"].as_f64().unwrap()).collect();
    for c in cases {
        assert_eq!((c["exit_code"].as_i64(), c["misses"].as_u64(), c["safe_stops"].as_u64()), (Some(0), Some(0), Some(0)), "{c}");
        assert!(c["force_error_max_n"].as_f64().unwrap() <= 0.10, "{c}");
    }
    // Superposition: the bump takes 4x as much from the weakest pressure at 0.4 mm as at 0.1 mm.
    // The flat strip's weakest point is not the flanks' (its pressure varies by about 1 kPa along
    // the roll), hence the 10 % band.
    let ratio = (weakest[0] - weakest[2]) / (weakest[0] - weakest[1]);
    eprintln!("weakest under the wheel at bump 0 / 0.1 / 0.4 mm: {weakest:?} Pa; ratio {ratio}");
    assert!(weakest[1] < weakest[0] && (3.6..4.4).contains(&ratio), "weakest {weakest:?} Pa, ratio {ratio}");

    // Every case ran in process; each is bit for bit the daemons' lockstep run of its scenario,
    // and the table's figures (from the case's ticks in memory) are its recording's, bit for bit.
    for (n, c) in cases.iter().enumerate() {
        let case = out.join(format!("case-{n:02}"));
        let swept = Recording::open_complete(case.join("run.mcap")).unwrap();
        let read = recording_tools::report::numbers(&swept).rolling.unwrap();
        assert_eq!(c["recording"].as_str(), Some(case.join("run.mcap").to_str().unwrap()), "case {n}");
        let weakest = read.bond_weakest_pa_at_z_m.unwrap()[0];
        let from_file = [read.force_error_max_abs_n.unwrap(), read.force_error_rms_n.unwrap(), read.bond_pressure_share.unwrap(), weakest];
        let in_memory = ["force_error_max_n", "force_error_rms_n", "bond_share", "bond_weakest_pa"].map(|k| c[k].as_f64().unwrap());
        assert_eq!(in_memory.map(f64::to_bits), from_file.map(f64::to_bits), "case {n}: {in_memory:?} in memory, {from_file:?} read back");
        assert_eq!(swept.run_metadata().unwrap().transport.as_deref(), Some("in-process"), "case {n}");
        let again = dir.join(format!("daemons-{n:02}"));
        let mut run = Daemon::start(
            "rig run",
            &bin("rig"),
            &["run", case.join("scenario.toml").to_str().unwrap(), "--mode", "lockstep", "--out", again.to_str().unwrap()],
            &dir,
        );
        assert!(run.expect_exit(LONG).success(), "{}", run.stderr());
        let daemons = Recording::open_complete(again.join("run.mcap")).unwrap();
        assert_eq!(daemons.run_metadata().unwrap().transport, None, "case {n}: the daemons' run");
        assert_eq!(physics_digest(&swept), physics_digest(&daemons), "case {n}: in-process sweep case != daemons' lockstep run");
    }

    // Without recordings the plant fills only the strip's pressure under the wheel
    // (`StripDetail::UnderWheel`): the same figures, bit for bit.
    let bare = dir.join("bare");
    let mut sweep = Daemon::start(
        "rig sweep",
        &bin("rig"),
        &["sweep", base.to_str().unwrap(), "--set", "bulge.height_mm=0,0.1,0.4", "--recordings", "none", "--out", bare.to_str().unwrap()],
        &dir,
    );
    assert!(sweep.expect_exit(LONG).success(), "{}", sweep.stderr());
    let bare: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(bare.join("sweep.json")).unwrap()).unwrap();
    for (n, (a, b)) in cases.iter().zip(bare.as_array().unwrap()).enumerate() {
        for k in ["force_error_max_n", "force_error_rms_n", "bond_share", "bond_weakest_pa", "bond_weakest_z_m"] {
            assert_eq!(a[k].as_f64().map(f64::to_bits), b[k].as_f64().map(f64::to_bits), "case {n}: {k} recorded {a} vs not {b}");
        }
        assert!(b["recording"].is_null(), "case {n}: {b}");
    }

    // A case records every tick, and the Foxglove scene at the sweep's 10 Hz (its scenario says
    // so): 3.6 s of the default scenario are 3600 joint states and 36 scenes.
    let case = out.join("case-00");
    let text = std::fs::read_to_string(case.join("scenario.toml")).unwrap();
    let s: toml::Table = text.parse().unwrap();
    assert_eq!(s["recording"]["scene_rate_hz"].as_float(), Some(10.0), "{text}");
    let counts = topic_counts(&case.join("run.mcap"));
    assert_eq!((counts["/joint_state"], counts["/strip"], counts["/strip_scene"], counts["/tf"]), (3600, 3600, 36, 36), "{counts:?}");

    // The cases' Info events are recorded, not logged: no "controller connected" line per case
    // on the terminal, and each recording still has its controller-change event.
    let log = sweep.stderr();
    assert!(!log.contains("connected"), "a case logged its Info events:\n{log}");
    let rec = Recording::open_complete(case.join("run.mcap")).unwrap();
    assert!(rec.events.iter().any(|e| e.text.ends_with("connected")), "{:?}", rec.events);
}

/// Messages per topic, read with the mcap crate (not the rig's reader).
fn topic_counts(path: &Path) -> std::collections::BTreeMap<String, usize> {
    let bytes = std::fs::read(path).unwrap();
    let mut counts = std::collections::BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *counts.entry(m.unwrap().channel.topic.clone()).or_insert(0) += 1;
    }
    counts
}

#[test]
fn scene_rate_flag_and_a_base_scenarios_own_rate_are_kept() {
    let rig = unique_rig("sweep-scene");
    let dir = temp_dir(&rig);
    let base = dir.join("base.toml");
    let default = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    std::fs::write(&base, std::fs::read_to_string(default).unwrap() + "\n[recording]\nscene_rate_hz = 50.0\n").unwrap();
    for (flag, want) in [(None, 50.0), (Some("4"), 4.0)] {
        let out = dir.join(format!("out-{want}"));
        let mut args = vec![
            "sweep",
            base.to_str().unwrap(),
            "--set",
            "trajectory.roll_s=1",
            "--duration",
            "0.5",
            "--recordings",
            "all",
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(f) = flag {
            args.extend(["--scene-rate", f]);
        }
        let mut sweep = Daemon::start("rig sweep", &bin("rig"), &args, &dir);
        assert!(sweep.expect_exit(LONG).success(), "{}", sweep.stderr());
        let s: toml::Table = std::fs::read_to_string(out.join("case-00/scenario.toml")).unwrap().parse().unwrap();
        assert_eq!(s["recording"]["scene_rate_hz"].as_float(), Some(want), "--scene-rate {flag:?}");
        let counts = topic_counts(&out.join("case-00/run.mcap"));
        assert_eq!((counts["/joint_state"], counts["/strip_scene"]), (500, (0.5 * want) as usize), "--scene-rate {flag:?}: {counts:?}");
    }
}

#[test]
fn a_bad_case_is_refused_before_any_run_starts() {
    let rig = unique_rig("sweepbad");
    let dir = temp_dir(&rig);
    let out = dir.join("sweep");
    let mut sweep =
        Daemon::start("rig sweep", &bin("rig"), &["sweep", "--set", "bulge.height_mm=0.1,abc", "--out", out.to_str().unwrap()], &dir);
    let st = sweep.expect_exit(LONG);
    let err = sweep.stderr();
    assert!(!st.success());
    assert!(err.contains("case-01/scenario.toml") && err.contains("abc"), "{err}");
    assert!(!out.join("case-00").join("run.mcap").exists(), "case 0 ran before case 1 was checked");
}

/// By default (`--recordings failing`) a sweep writes the recording of a failing case only (exit 4: a
/// contact force reflex at a 10.01 N limit against the 10 N set-point), by running it again: that
/// file says why it failed; the clean case writes none, and `--recordings none` writes no file at all.
/// Both tables are the same figures.
#[test]
fn a_sweep_keeps_the_recordings_of_failing_cases_only() {
    let rig = unique_rig("sweepkeep");
    let dir = temp_dir(&rig);
    let mut tables = Vec::new();
    for keep in [None, Some("none")] {
        let out = dir.join(format!("out-{}", keep.unwrap_or("default")));
        let mut args = vec!["sweep", "--set", "safety.max_contact_force_n=10.01,40", "--out", out.to_str().unwrap()];
        if let Some(k) = keep {
            args.extend(["--recordings", k]);
        }
        let mut sweep = Daemon::start("rig sweep", &bin("rig"), &args, &dir);
        let st = sweep.expect_exit(LONG);
        let table = sweep.stdout();
        assert_eq!(st.code(), Some(4), "{table}\n{}", sweep.stderr());
        assert!(table.lines().any(|l| l.starts_with("| safety.max_contact_force_n=10.01 | 4: ") && l.contains("reflex")), "{table}");
        assert!(table.lines().any(|l| l.starts_with("| safety.max_contact_force_n=40 | 0 |")), "{table}");
        let cases: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
        let kept: Vec<bool> = (0..2).map(|n| out.join(format!("case-{n:02}/run.mcap")).exists()).collect();
        let listed: Vec<bool> = (0..2).map(|n| !cases[n]["recording"].is_null()).collect();
        if keep.is_none() {
            assert_eq!((kept.clone(), listed), (vec![true, false], vec![true, false]), "{cases}");
            let rec = Recording::open_complete(out.join("case-00/run.mcap")).unwrap();
            assert!(rec.events.iter().any(|e| e.kind_name == "reflex"), "the failing case's recording has its reflex: {:?}", rec.events);
        } else {
            assert_eq!((kept, listed), (vec![false, false], vec![false, false]), "{cases}");
        }
        tables.push(table.lines().filter(|l| l.starts_with('|')).collect::<Vec<_>>().join("\n"));
    }
    assert_eq!(tables[0], tables[1], "the figures do not depend on what is kept");
}
