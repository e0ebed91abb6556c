//! `rig compare A.mcap B.mcap ...`: several runs side by side — your controller against ours, a
//! sweep's cases, a real-time run against its lockstep twin. The report's numbers in one table
//! (a column per recording) and the rolling phase overlaid: the force error and the bottom
//! pressure under the wheel against the wheel position.

use crate::plots::{self, LinePlot, Series};
use crate::read::{open_for, Recording};
use crate::report::{self, interpolate, ReportNumbers, BOND_PRESSURE_PA};
use crate::tracking;
use anyhow::Context;
use std::path::{Path, PathBuf};

/// What `compare` wrote.
#[derive(Debug, Clone)]
pub struct CompareFiles {
    pub table: PathBuf,
    pub figures: Vec<PathBuf>,
}

/// Short names for the columns: the recording's folder (sweep cases and `rig run` folders are
/// named for what they are) or file stem, with more of the path while two names collide, then
/// numbered.
pub fn column_names(paths: &[PathBuf]) -> Vec<String> {
    let name = |p: &PathBuf, depth: usize| {
        let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let mut parts = vec![stem];
        let mut dir = p.parent();
        // `run.mcap` says nothing: its folder always goes in
        let want = depth + usize::from(parts[0] == "run");
        while parts.len() <= want {
            match dir.and_then(Path::file_name) {
                Some(d) => parts.insert(0, d.to_string_lossy().into_owned()),
                None => break,
            }
            dir = dir.and_then(Path::parent);
        }
        if parts.len() > 1 && parts[parts.len() - 1] == "run" {
            parts.pop();
        }
        parts.join("/")
    };
    for depth in 0..3 {
        let names: Vec<String> = paths.iter().map(|p| name(p, depth)).collect();
        if names.iter().enumerate().all(|(i, n)| !names[..i].contains(n)) {
            return names;
        }
    }
    paths.iter().enumerate().map(|(i, p)| format!("{} ({})", name(p, 2), i + 1)).collect()
}

/// The numbers of several recordings as one markdown table, a column per recording.
pub fn table(names: &[String], numbers: &[ReportNumbers]) -> String {
    let row = |label: &str, cell: &dyn Fn(&ReportNumbers) -> String| {
        format!("| {label} | {} |\n", numbers.iter().map(cell).collect::<Vec<_>>().join(" | "))
    };
    let opt = |v: Option<f64>, scale: f64, digits: usize| v.map_or("—".to_string(), |x| format!("{:.*}", digits, x * scale));
    let roll = |n: &ReportNumbers| n.rolling.clone();
    let mut s = format!("| | {} |\n|---|{}\n", names.join(" | "), "---|".repeat(names.len()));
    s += &row("ticks", &|n| n.ticks.to_string());
    s += &row("misses", &|n| n.misses.to_string());
    s += &row("safe stops", &|n| n.safe_stops.to_string());
    s += &row("recorder drops", &|n| n.dropped.to_string());
    s += &row("force err max (N)", &|n| opt(roll(n).and_then(|r| r.force_error_max_abs_n), 1.0, 3));
    s += &row("force err RMS (N)", &|n| opt(roll(n).and_then(|r| r.force_error_rms_n), 1.0, 3));
    s += &row("force err mean (N)", &|n| opt(roll(n).and_then(|r| r.force_error_mean_n), 1.0, 3));
    s += &row("bond ≥ 100 kPa (% of roll)", &|n| opt(roll(n).and_then(|r| r.bond_pressure_share), 100.0, 1));
    s += &row("weakest under the wheel (kPa)", &|n| opt(roll(n).and_then(|r| r.bond_weakest_pa_at_z_m).map(|w| w[0]), 1e-3, 1));
    s += &row("round trip p50 (µs)", &|n| opt(n.latency_us.as_ref().map(|p| p.p50), 1.0, 1));
    s += &row("round trip p99 (µs)", &|n| opt(n.latency_us.as_ref().map(|p| p.p99), 1.0, 1));
    s += &row("plant compute p99 (µs)", &|n| opt(n.plant_compute_us.as_ref().map(|p| p.p99), 1.0, 1));
    s
}

/// Opens every recording (naming the one that fails), writes `compare.md` and the overlays into
/// `out_dir`, and returns the table with the files.
pub fn compare(paths: &[PathBuf], out_dir: &Path, allow_truncated: bool) -> anyhow::Result<(String, CompareFiles)> {
    anyhow::ensure!(paths.len() >= 2, "rig compare needs at least two recordings, got {}", paths.len());
    let recs: Vec<Recording> = paths
        .iter()
        .map(|p| open_for(p, allow_truncated).with_context(|| format!("opening {}", p.display())))
        .collect::<anyhow::Result<_>>()?;
    let names = column_names(paths);
    let numbers: Vec<ReportNumbers> = recs.iter().map(report::numbers).collect();
    let text = table(&names, &numbers);
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let mut files = CompareFiles { table: out_dir.join("compare.md"), figures: Vec::new() };
    let list: String = names.iter().zip(paths).map(|(n, p)| format!("- {n}: {}\n", p.display())).collect();
    std::fs::write(&files.table, format!("{text}\n{list}")).with_context(|| format!("writing {}", files.table.display()))?;

    let mut error = LinePlot {
        title: "Force error while rolling: |bottom force| − |force set-point|".into(),
        x_label: "wheel position along the strip z [mm]".into(),
        y_label: "force error [N]".into(),
        ..Default::default()
    };
    let mut pressure = LinePlot {
        title: "Bottom pressure on the centre line under the wheel while rolling".into(),
        x_label: "wheel position along the strip z [mm]".into(),
        y_label: "pressure under the wheel [kPa]".into(),
        hlines: vec![(BOND_PRESSURE_PA * 1e-3, "100 kPa bond pressure".into())],
        ..Default::default()
    };
    for (rec, name) in recs.iter().zip(&names) {
        let ticks = report::tracking_ticks(rec);
        let roll = tracking::rolling_ticks(&ticks);
        let z_nodes = rec.centreline_z_m();
        let z_mm = |i: usize| rec.strip[i].wheel_z_m * 1e3;
        error.series.push(Series {
            label: name.clone(),
            points: roll.iter().filter_map(|&i| ticks[i].force_error_n().map(|e| (z_mm(i), e))).collect(),
        });
        pressure.series.push(Series {
            label: name.clone(),
            points: roll
                .iter()
                .filter_map(|&i| {
                    interpolate(&z_nodes, &rec.strip[i].centreline_pressure_pa, rec.strip[i].wheel_z_m).map(|p| (z_mm(i), p * 1e-3))
                })
                .collect(),
        });
    }
    for (plot, stem) in [(&error, "force_error"), (&pressure, "pressure_under_wheel")] {
        if plot.series.iter().any(|s| !s.points.is_empty()) {
            files.figures.extend(plots::save_lines(plot, &out_dir.join(stem))?);
        }
    }
    Ok((text, files))
}
