//! A study's table (`results.csv`), summary (`summary.md`: the pass rate with its Wilson
//! interval, percentiles, the worst cases with the command that reproduces each, rank
//! correlations) and plots (`plots/*.svg`: a histogram of each metric, each metric against each
//! parameter), all from the case records alone.

use std::fmt::Write as _;
use std::path::Path;

use super::file::{Study, METRICS};
use super::stats;
use super::CaseRecord;

/// How many worst cases the summary lists.
pub const WORST_LISTED: usize = 5;

/// The metrics a study reports (`exit_code` is in the pass count and the table, not plotted).
fn plotted() -> impl Iterator<Item = &'static str> {
    METRICS.iter().map(|(m, _)| *m).filter(|m| *m != "exit_code")
}

fn cell(x: Option<f64>) -> String {
    x.map_or(String::new(), |x| format!("{x}"))
}

/// `results.csv`: one row per finished case (shortest round-trip decimal of every number, so
/// the file carries the records' exact values).
pub fn csv(study: &Study, records: &[CaseRecord]) -> String {
    let mut s = String::from("case,passed");
    for p in &study.parameters {
        s += &format!(",{}", p.field);
    }
    for k in &study.vary_seeds {
        s += &format!(",{k}");
    }
    for (m, _) in METRICS {
        s += &format!(",{m}");
    }
    s += ",failed,status\n";
    for r in records {
        s += &format!("{},{}", r.case, r.passed);
        for (_, x) in &r.parameters {
            s += &format!(",{x}");
        }
        for (_, x) in &r.seeds {
            s += &format!(",{x}");
        }
        for (m, _) in METRICS {
            s += &format!(",{}", cell(r.metric(m)));
        }
        let quote = |t: &str| format!("\"{}\"", t.replace('"', "\"\""));
        s += &format!(",{},{}\n", quote(&r.failed.join("; ")), quote(&r.status));
    }
    s
}

/// The summary (markdown). `dir` names the study directory in the reproduce commands.
pub fn summary(study: &Study, dir: &Path, records: &[CaseRecord], missing: &[usize]) -> String {
    let mut s = String::new();
    let n = records.len();
    let passed = records.iter().filter(|r| r.passed).count();
    let _ = writeln!(
        s,
        "# Study: {}\n",
        if study.description.is_empty() { study.path.display().to_string() } else { study.description.clone() }
    );
    let _ = writeln!(
        s,
        "{} cases of {} ({}, seed {}), {} of them finished{}.",
        study.cases,
        study.base.display(),
        match study.sampling {
            super::file::Sampling::Random => "random sampling",
            super::file::Sampling::LatinHypercube => "Latin hypercube sampling",
        },
        study.seed,
        n,
        if missing.is_empty() {
            String::new()
        } else {
            format!("; {} missing (rig study status {} lists them)", missing.len(), dir.display())
        }
    );
    let criteria: Vec<String> = study.criteria.iter().map(|c| c.text()).collect();
    let _ = writeln!(s, "Pass criteria: {}.\n", if criteria.is_empty() { "none (every case passes)".into() } else { criteria.join(", ") });
    let (lo, hi) = stats::wilson_95(passed, n);
    let _ = writeln!(
        s,
        "**Pass rate: {passed} of {n} ({:.2} %), 95 % confidence interval {:.2} % to {:.2} % (Wilson).**\n",
        100.0 * passed as f64 / n.max(1) as f64,
        100.0 * lo,
        100.0 * hi
    );
    let _ = writeln!(s, "| metric | min | p5 | p50 | p95 | max |\n| --- | --- | --- | --- | --- | --- |");
    for m in plotted() {
        let x: Vec<f64> = records.iter().filter_map(|r| r.metric(m)).collect();
        let q = |p: f64| format!("{:.4}", stats::percentile(&x, p));
        let _ = writeln!(s, "| {m} | {} | {} | {} | {} | {} |", q(0.0), q(0.05), q(0.5), q(0.95), q(1.0));
    }
    // the worst: the failing ones first, then by the first criterion's metric (or the force error)
    let key = study.criteria.first().map_or("force_error_max_n", |c| c.metric.as_str());
    let mut worst: Vec<&CaseRecord> = records.iter().collect();
    worst.sort_by(|a, b| {
        a.passed.cmp(&b.passed).then(b.metric(key).unwrap_or(f64::INFINITY).total_cmp(&a.metric(key).unwrap_or(f64::INFINITY)))
    });
    let _ = writeln!(s, "\nWorst cases (failing first, then by {key}); each command reruns the case bit for bit, keeps its recording and checks its result against the study's:\n");
    let _ = writeln!(s, "| case | {key} | parameters | failed | reproduce |\n| --- | --- | --- | --- | --- |");
    for r in worst.iter().take(WORST_LISTED) {
        let params: Vec<String> = r.parameters.iter().map(|(k, x)| format!("{k}={x:.6}")).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | `rig study case {} --case {}` |",
            r.case,
            cell(r.metric(key)),
            params.join(" "),
            if r.passed { "—".into() } else { r.failed.join("; ") },
            dir.display(),
            r.case
        );
    }
    if !study.parameters.is_empty() {
        let _ = writeln!(s, "\nSpearman rank correlation of each parameter with each metric:\n");
        let metrics: Vec<&str> = plotted().collect();
        let _ = writeln!(s, "| parameter | {} |\n| --- |{}", metrics.join(" | "), " --- |".repeat(metrics.len()));
        for (j, p) in study.parameters.iter().enumerate() {
            let x: Vec<f64> = records.iter().map(|r| r.parameters[j].1).collect();
            let cells: Vec<String> = metrics
                .iter()
                .map(|m| {
                    let y: Vec<f64> = records.iter().map(|r| r.metric(m).unwrap_or(f64::NAN)).collect();
                    let rho = stats::spearman(&x, &y);
                    if rho.is_nan() {
                        "—".into()
                    } else {
                        format!("{rho:+.2}")
                    }
                })
                .collect();
            let _ = writeln!(s, "| {} | {} |", p.field, cells.join(" | "));
        }
    }
    let _ = writeln!(s, "\nTable: results.csv; plots: plots/ (a histogram of each metric, each metric against each parameter).");
    s
}

/// Writes `results.csv`, `summary.md` and the plots into `dir`; returns the summary.
pub fn write_all(study: &Study, dir: &Path, records: &[CaseRecord], missing: &[usize]) -> anyhow::Result<String> {
    super::write_atomic(&dir.join("results.csv"), csv(study, records).as_bytes())?;
    let text = summary(study, dir, records, missing);
    super::write_atomic(&dir.join("summary.md"), text.as_bytes())?;
    let plots = dir.join("plots");
    std::fs::create_dir_all(&plots)?;
    for m in plotted() {
        let y: Vec<f64> = records.iter().filter_map(|r| r.metric(m)).collect();
        super::write_atomic(&plots.join(format!("hist-{m}.svg")), histogram_svg(m, &y).as_bytes())?;
        for (j, p) in study.parameters.iter().enumerate() {
            let pts: Vec<(f64, f64, bool)> = records.iter().filter_map(|r| r.metric(m).map(|y| (r.parameters[j].1, y, r.passed))).collect();
            super::write_atomic(&plots.join(format!("{m}-vs-{}.svg", p.field)), scatter_svg(&p.field, m, &pts).as_bytes())?;
        }
    }
    Ok(text)
}

const W: f64 = 480.0;
const H: f64 = 320.0;
const M: f64 = 50.0;

/// The frame of a plot: axes, the two ends of each axis as numbers, the labels.
fn frame(xlabel: &str, ylabel: &str, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> String {
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" font-family=\"sans-serif\" font-size=\"11\">\
         <rect width=\"{W}\" height=\"{H}\" fill=\"white\"/>\
         <line x1=\"{M}\" y1=\"{b}\" x2=\"{r}\" y2=\"{b}\" stroke=\"black\"/><line x1=\"{M}\" y1=\"{t}\" x2=\"{M}\" y2=\"{b}\" stroke=\"black\"/>\
         <text x=\"{M}\" y=\"{tb}\">{x0:.4}</text><text x=\"{r}\" y=\"{tb}\" text-anchor=\"end\">{x1:.4}</text>\
         <text x=\"{xc}\" y=\"{xl}\" text-anchor=\"middle\">{xlabel}</text>\
         <text x=\"{yl}\" y=\"{b}\" text-anchor=\"end\">{y0:.4}</text><text x=\"{yl}\" y=\"{ty}\" text-anchor=\"end\">{y1:.4}</text>\
         <text x=\"{M}\" y=\"20\">{ylabel}</text>",
        b = H - M,
        r = W - 10.0,
        t = 30.0,
        tb = H - M + 14.0,
        xc = (M + W - 10.0) / 2.0,
        xl = H - 12.0,
        yl = M - 4.0,
        ty = 34.0,
    )
}

fn span(x: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let lo = x.clone().fold(f64::INFINITY, f64::min);
    let hi = x.fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() {
        (0.0, 1.0)
    } else if hi > lo {
        (lo, hi)
    } else {
        (lo - 0.5, lo + 0.5)
    }
}

/// A histogram of `y` in 20 bins.
pub fn histogram_svg(metric: &str, y: &[f64]) -> String {
    const BINS: usize = 20;
    let (lo, hi) = span(y.iter().copied());
    let mut counts = [0usize; BINS];
    for &v in y {
        counts[(((v - lo) / (hi - lo) * BINS as f64) as usize).min(BINS - 1)] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1);
    let mut s = frame(metric, "cases", (lo, hi), (0.0, top as f64));
    let bw = (W - 10.0 - M) / BINS as f64;
    for (i, &c) in counts.iter().enumerate() {
        let h = c as f64 / top as f64 * (H - M - 30.0);
        let _ = write!(
            s,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{h:.1}\" fill=\"steelblue\"/>",
            M + i as f64 * bw,
            H - M - h,
            bw - 1.0
        );
    }
    s + "</svg>\n"
}

/// `metric` against `parameter`, passing cases blue, failing red.
pub fn scatter_svg(parameter: &str, metric: &str, pts: &[(f64, f64, bool)]) -> String {
    let (x0, x1) = span(pts.iter().map(|p| p.0));
    let (y0, y1) = span(pts.iter().map(|p| p.1));
    let mut s = frame(parameter, metric, (x0, x1), (y0, y1));
    for &(x, y, ok) in pts {
        let px = M + (x - x0) / (x1 - x0) * (W - 10.0 - M);
        let py = H - M - (y - y0) / (y1 - y0) * (H - M - 30.0);
        let _ = write!(s, "<circle cx=\"{px:.1}\" cy=\"{py:.1}\" r=\"2.5\" fill=\"{}\"/>", if ok { "steelblue" } else { "crimson" });
    }
    s + "</svg>\n"
}
