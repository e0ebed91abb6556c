//! Every bad value given to `rig run`, `rig timing` and `rig sweep` is refused by `rig` itself
//! before any daemon starts. The real binary runs as a process with a controller that is a
//! script leaving a marker file when it starts; for each bad value `rig` must exit non-zero
//! within a second, name the flag (and the file, line and field of a scenario value), print no
//! start line, write no recording and start no controller.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const RIG: &str = env!("CARGO_BIN_EXE_rig");
/// Refusing a value is parsing and checking only: far below what starting a daemon takes.
const REFUSED_WITHIN: Duration = Duration::from_secs(1);

struct Sandbox {
    dir: PathBuf,
    controller: PathBuf,
    marker: PathBuf,
}

fn sandbox(tag: &str) -> Sandbox {
    use std::os::unix::fs::PermissionsExt;
    let dir = std::env::temp_dir().join(format!("rig-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let marker = dir.join("controller-started");
    let controller = dir.join("controller.sh");
    // exits at once: where a run does start, rig then stops the plant at once too
    std::fs::write(&controller, format!("#!/bin/sh\ntouch '{}'\nexit 3\n", marker.display())).unwrap();
    std::fs::set_permissions(&controller, std::fs::Permissions::from_mode(0o755)).unwrap();
    Sandbox { dir, controller, marker }
}

struct Ran {
    code: Option<i32>,
    stderr: String,
    took: Duration,
}

/// Runs `rig args...`, adding `--out` (a fresh directory) and `--controller` (the marker script)
/// unless `args` give them; kills it after 30 s.
fn rig(sb: &Sandbox, n: usize, args: &[String]) -> Ran {
    let mut cmd = Command::new(RIG);
    cmd.args(args).current_dir(&sb.dir).stdin(Stdio::null());
    if !args.iter().any(|a| a.starts_with("--out")) {
        cmd.arg("--out").arg(sb.dir.join(format!("out-{n}")));
    }
    if !args.iter().any(|a| a.starts_with("--controller")) {
        cmd.arg("--controller").arg(&sb.controller);
    }
    let err_path = sb.dir.join(format!("stderr-{n}"));
    cmd.stdout(Stdio::null()).stderr(std::fs::File::create(&err_path).unwrap());
    let t0 = Instant::now();
    let mut child = cmd.spawn().expect("start rig");
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            break child.wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let took = t0.elapsed();
    Ran { code: status.code(), stderr: std::fs::read_to_string(&err_path).unwrap(), took }
}

/// Recordings anywhere below `dir`.
fn recordings(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(recordings(&p));
        } else if p.extension().is_some_and(|x| x == "mcap") {
            out.push(p);
        }
    }
    out
}

/// `rig args` is refused before anything starts, and its message holds every piece of `says`.
fn assert_refused(sb: &Sandbox, n: usize, args: &[String], says: &[String]) {
    let r = rig(sb, n, args);
    let what = format!("rig {}", args.join(" "));
    assert!(matches!(r.code, Some(c) if c != 0), "{what}: exit {:?}, stderr:\n{}", r.code, r.stderr);
    assert!(r.took < REFUSED_WITHIN, "{what}: took {:?}, stderr:\n{}", r.took, r.stderr);
    // the launcher's start line: "rig <name>: plant <bin> + controller <bin>, scenario <file>"
    assert!(!r.stderr.contains(" + controller "), "{what}: started the daemons:\n{}", r.stderr);
    assert!(!sb.marker.exists(), "{what}: the controller was started");
    assert!(recordings(&sb.dir).is_empty(), "{what}: wrote {:?}", recordings(&sb.dir));
    for s in says {
        assert!(r.stderr.contains(s.as_str()), "{what}: does not say {s:?}:\n{}", r.stderr);
    }
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

#[test]
fn bad_flag_values_are_refused_before_any_daemon_starts_naming_the_flag() {
    let sb = sandbox("flags");
    let not_a_dir = sb.dir.join("a-file");
    std::fs::write(&not_a_dir, "").unwrap();
    let under_a_file = not_a_dir.join("out").display().to_string();
    let missing_dir_json = sb.dir.join("no-such-dir").join("t.json").display().to_string();
    let seconds = ["-5", "0", "-0", "nan", "inf", "-inf", "abc", ""];
    let mut cases: Vec<(Vec<&str>, Vec<&str>)> = Vec::new();
    for cmd in [&["run"][..], &["sweep", "--set", "bulge.height_mm=0.1"][..]] {
        for v in seconds {
            cases.push(([cmd, &["--duration", v]].concat(), vec!["'--duration <DURATION>'"]));
        }
        cases.push(([cmd, &["--duration=-5"]].concat(), vec!["'--duration <DURATION>'", "> 0"]));
        // shorter than one 1 ms tick
        cases.push((
            [cmd, &["--duration", "0.0004"]].concat(),
            vec!["--duration 0.0004: shorter than one control period (loop.period_s = 0.001 s"],
        ));
        cases.push((
            [cmd, &["--controller", "/nonexistent/controller"]].concat(),
            vec!["--controller /nonexistent/controller: No such file or directory (os error 2)"],
        ));
        cases.push(([cmd, &["--controller", "/"]].concat(), vec!["--controller /: not a file"]));
        cases.push(([cmd, &["--out", under_a_file.as_str()]].concat(), vec!["--out ", "a-file/out"]));
    }
    cases.push((vec!["run", "--mode", "fast"], vec!["'--mode <MODE>'"]));
    cases.push((vec!["run", "--set", "bulge.heigth_mm=1"], vec!["--set", "no scenario field bulge.heigth_mm; [bulge] has height_mm"]));
    cases.push((vec!["run", "--set", "loop.period_s"], vec!["--set", "expected section.field=v1,v2,..."]));
    cases.push((vec!["run", "--set", "loop.period_s=0.001,0.002"], vec!["--set loop.period_s: rig run takes one value"]));
    cases.push((vec!["sweep", "--set", "bulge.nope=1,2"], vec!["--set", "no scenario field bulge.nope"]));
    for v in seconds {
        cases.push((vec!["timing", "--seconds", v], vec!["'--seconds <SECONDS>'"]));
    }
    cases.push((vec!["timing", "--seconds", "0.0001"], vec!["--seconds 0.0001: shorter than one control period"]));
    for v in ["-1", "nan", "inf", "x"] {
        cases.push((vec!["timing", "--spin-us", v], vec!["'--spin-us <SPIN_US>'"]));
        cases.push((vec!["timing", "--controller-spin-us", v], vec!["'--controller-spin-us <CONTROLLER_SPIN_US>'"]));
    }
    // in range for the flag, out of range for the scenario field it sets
    cases.push((
        vec!["timing", "--spin-us", "600"],
        vec![
            "--spin-us 600: scenario file ",
            "timing.toml, line ",
            ": field loop.spin_wait_us = 600: must be in [0, loop.torque_budget_us] = [0, 500] µs",
        ],
    ));
    cases.push((
        vec!["timing", "--controller-spin-us", "500"],
        vec![
            "--controller-spin-us 500: scenario file ",
            ": field loop.controller_spin_us = 500: must be in [0, 5e5 loop.period_s) = [0, 500) µs",
        ],
    ));
    cases.push((vec!["timing", "--json", missing_dir_json.as_str()], vec!["--json ", "no-such-dir does not exist"]));
    cases.push((vec!["timing", "--json", "/"], vec!["--json /: is a directory"]));
    for (n, (args, says)) in cases.iter().enumerate() {
        assert_refused(&sb, n, &strings(args), &strings(says));
    }
    let _ = std::fs::remove_dir_all(&sb.dir);
}

#[test]
fn set_overrides_are_checked_like_file_values_and_name_the_flag() {
    let sb = sandbox("set");
    let out = |n: usize| sb.dir.join(format!("out-{n}"));
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        // the findings of issue 12
        (
            strings(&["run", "--set", "trajectory.force_ref_n=nan"]),
            vec![
                format!("--set trajectory.force_ref_n=nan: scenario file {}, line ", out(0).join("scenario.toml").display()),
                ": field trajectory.force_ref_n = NaN: must be a finite number in (-safety.max_contact_force_n, 0) N".into(),
            ],
        ),
        (
            strings(&["run", "--set", "bulge.height_mm=100"]),
            vec![
                format!("--set bulge.height_mm=100: scenario file {}, line ", out(1).join("scenario.toml").display()),
                ": field bulge.height_mm = 100: must be in (-8, 8) mm".into(),
            ],
        ),
        (strings(&["run", "--set", "trajectory.force_ref_n=-50"]), strings(&["--set trajectory.force_ref_n=-50: ", "= (-40, 0) N"])),
        (
            strings(&["run", "--set", "loop.substeps=0"]),
            strings(&["--set loop.substeps=0: ", "field loop.substeps = 0: must be in [1, 1000]"]),
        ),
        (
            strings(&["run", "--set", "loop.substeps=2.5"]),
            strings(&["--set loop.substeps=2.5: ", "field loop.substeps = 2.5: must be a whole number, not a float"]),
        ),
        (
            strings(&["run", "--set", "trajectory.roll_s=fast"]),
            strings(&["--set trajectory.roll_s=\"fast\": ", "field trajectory.roll_s = \"fast\": must be a number (s), not a string"]),
        ),
        (
            strings(&["run", "--set", "loop.period_s=-1"]),
            strings(&["--set loop.period_s=-1: ", "field loop.period_s = -1: must be in (0, 0.1] s"]),
        ),
        // another field made invalid: both named
        (
            strings(&["run", "--set", "strip.length_mm=20"]),
            strings(&[
                "the scenario with --set strip.length_mm=20: ",
                "field trajectory.z_end_mm = 38: must be in (trajectory.z_start_mm, strip.length_mm] = (2, 20] mm",
            ]),
        ),
        // a sweep: the bad case is named, and nothing runs before it is checked
        (
            strings(&["sweep", "--set", "bulge.height_mm=0.1,100"]),
            vec![
                format!("--set bulge.height_mm=100: scenario file {}, line ", out(8).join("case-01").join("scenario.toml").display()),
                ": field bulge.height_mm = 100: must be in (-8, 8) mm".into(),
            ],
        ),
        (
            strings(&["sweep", "--set", "trajectory.force_ref_n=-10,nan", "--grid"]),
            strings(&["--set trajectory.force_ref_n=nan: ", "case-01", "field trajectory.force_ref_n = NaN"]),
        ),
    ];
    for (n, (args, says)) in cases.iter().enumerate() {
        assert_refused(&sb, n, args, says);
    }
    let _ = std::fs::remove_dir_all(&sb.dir);
}

#[test]
fn bad_scenario_files_are_refused_naming_file_line_and_field() {
    let sb = sandbox("files");
    let write = |name: &str, text: &str| {
        let p = sb.dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let bulge = write("bulge.toml", "description = \"too high\"\n[bulge]\nheight_mm = 100\n");
    let nan = write("nan.toml", "[trajectory]\nforce_ref_n = nan\n");
    let typed = write("typed.toml", "[loop]\n\nsubsteps = \"ten\"\n");
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        (
            vec!["run".into(), bulge.clone()],
            vec![format!("rig: error: scenario file {bulge}, line 3: field bulge.height_mm = 100: must be in (-8, 8) mm")],
        ),
        (
            vec!["run".into(), nan.clone()],
            vec![format!("scenario file {nan}, line 2: field trajectory.force_ref_n = NaN: must be a finite number")],
        ),
        (
            vec!["run".into(), typed.clone()],
            vec![format!("scenario file {typed}, line 3: field loop.substeps = \"ten\": must be a whole number, not a string")],
        ),
        (vec!["timing".into(), "--scenario".into(), bulge.clone()], vec![format!("scenario file {bulge}, line 3: field bulge.height_mm")]),
        (
            vec!["sweep".into(), nan.clone(), "--set".into(), "bulge.height_mm=0.1".into()],
            vec![format!("scenario file {nan}, line 2: field trajectory.force_ref_n")],
        ),
    ];
    for (n, (args, says)) in cases.iter().enumerate() {
        assert_refused(&sb, n, args, says);
    }
    let _ = std::fs::remove_dir_all(&sb.dir);
}

#[test]
fn a_missing_scenario_file_prints_its_os_error_once() {
    let sb = sandbox("missing");
    for (n, args) in [
        strings(&["run", "/nonexistent/scenario.toml"]),
        strings(&["sweep", "/nonexistent/scenario.toml", "--set", "bulge.height_mm=0.1"]),
        strings(&["timing", "--scenario", "/nonexistent/scenario.toml"]),
    ]
    .iter()
    .enumerate()
    {
        assert_refused(
            &sb,
            n,
            args,
            &strings(&["rig: error: cannot read scenario file /nonexistent/scenario.toml: No such file or directory (os error 2)\n"]),
        );
        let r = rig(&sb, 100 + n, args);
        assert_eq!(r.stderr.matches("os error 2").count(), 1, "{}", r.stderr);
        assert_eq!(r.stderr.matches("No such file or directory").count(), 1, "{}", r.stderr);
    }
    let _ = std::fs::remove_dir_all(&sb.dir);
}

#[test]
fn the_harness_sees_a_start_when_the_values_are_good() {
    // The same run with good values starts the daemons: the start line and the controller's
    // marker appear, so their absence in the tests above means that nothing started.
    let sb = sandbox("good");
    let plant = Path::new(RIG).with_file_name("plant-sim");
    if !plant.is_file() {
        println!("SKIPPED: {} is not built (cargo build --release -p plant-sim)", plant.display());
        return;
    }
    let scenario = sb.dir.join("robot-only.toml");
    std::fs::write(&scenario, "[strip]\nenabled = false\n[loop]\nmode = \"lockstep\"\n").unwrap();
    let r = rig(&sb, 0, &strings(&["run", scenario.to_str().unwrap(), "--duration", "0.01"]));
    assert!(r.stderr.contains(" + controller "), "no start line:\n{}", r.stderr);
    assert!(sb.marker.exists(), "the controller did not start:\n{}", r.stderr);
    let _ = std::fs::remove_dir_all(&sb.dir);
}

/// The recording tools say a missing file's OS error once too (`rig report`, `rig replay`,
/// `rig compare`).
#[test]
fn a_missing_recording_prints_its_os_error_once() {
    let sb = sandbox("missing-rec");
    for args in [strings(&["report", "/nonexistent/run.mcap"]), strings(&["compare", "/nonexistent/a.mcap", "/nonexistent/b.mcap"])] {
        let out = Command::new(RIG).args(&args).current_dir(&sb.dir).stdin(Stdio::null()).output().expect("start rig");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}: {err}");
        assert_eq!(err.matches("os error 2").count(), 1, "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&sb.dir);
}
