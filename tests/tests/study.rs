//! `rig study` end to end on this machine: a small Monte Carlo of the default scenario, its
//! table and summary against the case records and the Wilson interval's closed form, its worst
//! case rerun bit for bit, a study killed with SIGKILL and resumed without losing a finished
//! case (and equal, case by case, to the same study run whole), and bad study files refused
//! with file, line and field before anything runs.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use harness::*;

const LONG: Duration = Duration::from_secs(600);

/// A study of the default scenario: bump height and set-point uncertain, two strip stiffnesses.
fn study_file(dir: &Path, cases: usize, criterion_max_n: f64) -> PathBuf {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let text = format!(
        "description = \"test study\"\nbase = {:?}\ncases = {cases}\nseed = 11\nrecordings = \"failing\"\n\
         [[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"uniform\"\nmin = 0.1\nmax = 0.4\n\
         [[parameter]]\nfield = \"trajectory.force_ref_n\"\ndistribution = \"uniform\"\nmin = -11.0\nmax = -9.0\n\
         [[parameter]]\nfield = \"strip.youngs_modulus_pa\"\ndistribution = \"values\"\nvalues = [3.46e6, 3.806e6]\n\
         [[criterion]]\nmetric = \"force_error_max_n\"\nmax = {criterion_max_n}\n[[criterion]]\nmetric = \"exit_code\"\nmax = 0\n",
        base.display().to_string()
    );
    let path = dir.join(format!("study-{cases}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

fn results(dir: &Path, cases: usize) -> Vec<Option<String>> {
    (0..cases).map(|n| std::fs::read_to_string(dir.join(format!("cases/{n:06}/result.json"))).ok()).collect()
}

fn wilson(k: f64, n: f64) -> (f64, f64) {
    // Wilson (1927): (p + z²/2n ± z sqrt(p(1-p)/n + z²/4n²)) / (1 + z²/n), z = 1.96
    let (z, p) = (1.959964, k / n);
    let c = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let h = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt() / (1.0 + z * z / n);
    (c - h, c + h)
}

#[test]
fn a_study_tabulates_its_cases_keeps_the_failing_recordings_and_reproduces_its_worst() {
    let rig = unique_rig("study");
    let dir = temp_dir(&rig);
    // The criterion sits inside the cases' spread (the default's force error max grows with the
    // bump: about 0.024 N at 0.1 mm to 0.055 N at 0.4 mm), so some pass and some fail.
    let file = study_file(&dir, 8, 0.04);
    let out = dir.join("st");
    let mut st = Daemon::start("rig study", &bin("rig"), &["study", "run", file.to_str().unwrap(), "--out", out.to_str().unwrap()], &dir);
    let status = st.expect_exit(LONG);
    let records: Vec<serde_json::Value> =
        results(&out, 8).into_iter().map(|r| serde_json::from_str(&r.expect("every case has a result")).unwrap()).collect();
    let passed = records.iter().filter(|r| r["passed"] == true).count();
    assert!(passed > 0 && passed < 8, "the criterion should split the cases: {passed} of 8 passed\n{}", st.stdout());
    assert_eq!(status.code(), Some(4), "every case finished, some failed: exit 4\n{}\n{}", st.stdout(), st.stderr());
    for r in &records {
        let n = r["case"].as_u64().unwrap();
        let err = r["force_error_max_n"].as_f64().unwrap();
        assert_eq!(r["passed"] == true, err <= 0.04 && r["exit_code"] == 0, "case {n}: {r}");
        // the case's scenario holds its parameters, exactly
        let s: toml::Table = std::fs::read_to_string(out.join(format!("cases/{n:06}/scenario.toml"))).unwrap().parse().unwrap();
        let h = r["parameters"][0][1].as_f64().unwrap();
        assert_eq!(s["bulge"]["height_mm"].as_float(), Some(h), "case {n}");
        assert!((0.1..0.4).contains(&h));
        // a recording is kept exactly for the failing cases
        assert_eq!(out.join(format!("cases/{n:06}/run.mcap")).exists(), r["passed"] == false, "case {n}");
    }
    // Latin hypercube: one case in each eighth of the bump's range
    let mut strata: Vec<usize> = records.iter().map(|r| ((r["parameters"][0][1].as_f64().unwrap() - 0.1) / 0.3 * 8.0) as usize).collect();
    strata.sort();
    assert_eq!(strata, (0..8).collect::<Vec<_>>());
    // the summary: the pass count and the Wilson interval's closed form
    let (lo, hi) = wilson(passed as f64, 8.0);
    let line = format!(
        "Pass rate: {passed} of 8 ({:.2} %), 95 % confidence interval {:.2} % to {:.2} % (Wilson)",
        100.0 * passed as f64 / 8.0,
        100.0 * lo,
        100.0 * hi.min(1.0)
    );
    assert!(st.stdout().contains(&line), "{line}\n{}", st.stdout());
    assert_eq!(std::fs::read_to_string(out.join("summary.md")).unwrap(), st.stdout().split("study directory:").next().unwrap());
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 9, "{csv}");
    assert!(csv.starts_with("case,passed,bulge.height_mm,trajectory.force_ref_n,strip.youngs_modulus_pa,exit_code,"), "{csv}");
    for plot in ["hist-force_error_max_n.svg", "force_error_max_n-vs-bulge.height_mm.svg"] {
        assert!(std::fs::read_to_string(out.join("plots").join(plot)).unwrap().starts_with("<svg"), "{plot}");
    }
    // the worst case by its listed command: bit for bit
    let worst = records
        .iter()
        .max_by(|a, b| a["force_error_max_n"].as_f64().unwrap().total_cmp(&b["force_error_max_n"].as_f64().unwrap()))
        .unwrap();
    let n = worst["case"].as_u64().unwrap().to_string();
    let cmd = format!("`rig study case {} --case {n}`", out.display());
    assert!(st.stdout().contains(&cmd), "{cmd}\n{}", st.stdout());
    let mut again = Daemon::start("rig study case", &bin("rig"), &["study", "case", out.to_str().unwrap(), "--case", &n], &dir);
    assert!(again.expect_exit(LONG).success(), "{}\n{}", again.stdout(), again.stderr());
    assert!(again.stdout().contains(&format!("case {n}: the result equals the study's bit for bit")), "{}", again.stdout());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_study_killed_and_resumed_loses_no_finished_case_and_equals_the_whole_run() {
    let rig = unique_rig("study-kill");
    let dir = temp_dir(&rig);
    let file = study_file(&dir, 12, 0.45);
    let out = dir.join("killed");
    let mut st = Daemon::start("rig study", &bin("rig"), &["study", "run", file.to_str().unwrap(), "--out", out.to_str().unwrap()], &dir);
    let t0 = Instant::now();
    let finished = loop {
        let f: Vec<usize> = results(&out, 12).iter().enumerate().filter(|(_, r)| r.is_some()).map(|(n, _)| n).collect();
        if f.len() >= 3 || t0.elapsed() > LONG {
            break f;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    st.signal(libc::SIGKILL);
    st.expect_exit(LONG);
    assert!(finished.len() >= 3 && finished.len() < 12, "killed after {} finished cases", finished.len());
    let before = results(&out, 12);
    let mtimes: Vec<_> =
        finished.iter().map(|n| std::fs::metadata(out.join(format!("cases/{n:06}/result.json"))).unwrap().modified().unwrap()).collect();
    let mut resumed = Daemon::start(
        "rig study --resume",
        &bin("rig"),
        &["study", "run", file.to_str().unwrap(), "--out", out.to_str().unwrap(), "--resume"],
        &dir,
    );
    assert!(resumed.expect_exit(LONG).success(), "{}\n{}", resumed.stdout(), resumed.stderr());
    let after = results(&out, 12);
    for (i, n) in finished.iter().enumerate() {
        assert_eq!(after[*n], before[*n], "case {n} changed");
        let m = std::fs::metadata(out.join(format!("cases/{n:06}/result.json"))).unwrap().modified().unwrap();
        assert_eq!(m, mtimes[i], "case {n} was run again");
    }
    // the same study run whole gives the same bytes, case by case
    let whole = dir.join("whole");
    let mut w = Daemon::start("rig study", &bin("rig"), &["study", "run", file.to_str().unwrap(), "--out", whole.to_str().unwrap()], &dir);
    assert!(w.expect_exit(LONG).success(), "{}", w.stderr());
    assert_eq!(results(&whole, 12), after);
    assert!(after.iter().all(Option::is_some));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_study_files_are_refused_with_file_line_and_field_before_anything_runs() {
    let rig = unique_rig("study-bad");
    let dir = temp_dir(&rig);
    let good = std::fs::read_to_string(study_file(&dir, 4, 0.45)).unwrap();
    for (name, from, to, says) in [
        (
            "unknown parameter",
            "field = \"bulge.height_mm\"",
            "field = \"bulge.hieght_mm\"",
            "line 7: parameter[0].field: \"bulge.hieght_mm\": no such scenario field",
        ),
        ("bad bounds", "min = 0.1\nmax = 0.4", "min = 0.4\nmax = 0.1", "line 10: parameter[0].max: 0.1: must be greater than min = 0.4"),
        ("zero cases", "cases = 4", "cases = 0", "line 3: cases: 0: must be at least 1"),
        (
            "no such metric",
            "metric = \"force_error_max_n\"",
            "metric = \"force_error_p99_n\"",
            "line 21: criterion[0].metric: \"force_error_p99_n\": no such metric",
        ),
    ] {
        assert!(good.contains(from), "{name}");
        let path = dir.join(format!("{}.toml", name.replace(' ', "-")));
        std::fs::write(&path, good.replace(from, to)).unwrap();
        let out = dir.join(format!("out-{}", name.replace(' ', "-")));
        let mut st =
            Daemon::start("rig study", &bin("rig"), &["study", "run", path.to_str().unwrap(), "--out", out.to_str().unwrap()], &dir);
        assert_eq!(st.expect_exit(LONG).code(), Some(1), "{name}");
        let want = format!("rig: error: study file {}, {says}", path.display());
        assert!(st.stderr().contains(&want), "{name}: want {want}\n{}", st.stderr());
        assert!(!out.exists(), "{name}: nothing is written before the file is checked");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
