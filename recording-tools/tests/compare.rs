//! `rig compare` on synthetic recordings whose numbers are known in closed form: each column
//! carries its own run's numbers, the overlays are written, and bad input names the file.

use recording_tools::compare::{column_names, compare};
use recordings::synthetic::SyntheticRun;
use recordings::RecorderConfig;
use std::path::PathBuf;

fn record(dir: &std::path::Path, name: &str, run: &SyntheticRun) -> PathBuf {
    let path = dir.join(name).join("run.mcap");
    run.record(RecorderConfig::new(&path, run.metadata())).unwrap();
    path
}

#[test]
fn each_column_is_its_own_run_and_the_overlays_are_written() {
    let dir = std::env::temp_dir().join(format!("recordings-compare-{}", std::process::id()));
    // Two runs that differ in their force error amplitude A (max A, RMS A/sqrt 2) and coverage.
    let a = SyntheticRun { force_error_n: 0.05, ..Default::default() };
    let b = SyntheticRun { force_error_n: 0.2, coverage_z_m: 0.011, ..Default::default() };
    let paths = vec![record(&dir, "ours", &a), record(&dir, "yours", &b)];
    let out = dir.join("cmp");
    let (text, files) = compare(&paths, &out, false).unwrap();
    let row = |label: &str| -> Vec<String> {
        let line = text.lines().find(|l| l.starts_with(&format!("| {label} |"))).unwrap_or_else(|| panic!("no {label} row:\n{text}"));
        line.split('|').map(|c| c.trim().to_string()).filter(|c| !c.is_empty()).skip(1).collect()
    };
    assert!(text.starts_with("| | ours | yours |"), "{text}");
    assert_eq!(row("force err max (N)"), [format!("{:.3}", a.force_error_n), format!("{:.3}", b.force_error_n)]);
    assert_eq!(
        row("force err RMS (N)"),
        [format!("{:.3}", a.force_error_n / 2f64.sqrt()), format!("{:.3}", b.force_error_n / 2f64.sqrt())]
    );
    assert_eq!(row("misses"), ["3", "3"]);
    // coverage (29 - 2)/36 = 75 % for the first, (11 - 2)/36 = 25 % for the second
    let share: Vec<f64> = row("bond ≥ 100 kPa (% of roll)").iter().map(|c| c.parse().unwrap()).collect();
    assert!((share[0] - 75.0).abs() < 0.2 && (share[1] - 25.0).abs() < 0.2, "{share:?}");
    assert!(std::fs::read_to_string(&files.table).unwrap().contains(&paths[1].display().to_string()));
    for stem in ["force_error", "pressure_under_wheel"] {
        for ext in ["png", "svg"] {
            let f = out.join(format!("{stem}.{ext}"));
            assert!(files.figures.contains(&f) && std::fs::metadata(&f).unwrap().len() > 1000, "{}", f.display());
        }
    }
    let svg = std::fs::read_to_string(out.join("force_error.svg")).unwrap();
    assert!(svg.contains("ours") && svg.contains("yours"), "legend names the runs");
}

#[test]
fn bad_input_names_the_file() {
    let dir = std::env::temp_dir().join(format!("recordings-compare-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = record(&dir, "good", &SyntheticRun { ticks: 1200, ..Default::default() });
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let e = format!("{:#}", compare(&[good.clone(), junk.clone()], &dir.join("o"), false).unwrap_err());
    assert!(e.contains(&junk.display().to_string()), "{e}");
    let e = compare(&[good], &dir.join("o"), false).unwrap_err().to_string();
    assert!(e.contains("at least two"), "{e}");
}

#[test]
fn column_names_say_which_run() {
    let p = |s: &str| PathBuf::from(s);
    assert_eq!(column_names(&[p("runs/a/run.mcap"), p("runs/b/run.mcap")]), ["a", "b"]);
    assert_eq!(column_names(&[p("x/case-01/run.mcap"), p("y/case-01/run.mcap")]), ["x/case-01", "y/case-01"]);
    assert_eq!(column_names(&[p("one.mcap"), p("two.mcap")]), ["one", "two"]);
    assert_eq!(column_names(&[p("one.mcap"), p("one.mcap")]), ["one (1)", "one (2)"]);
}
