//! `rig study`: Monte Carlo robustness studies of a scenario (issue 24).
//!
//! A study directory holds everything: `study.toml` (the study file as given), `cases/NNNNNN/`
//! with each case's `scenario.toml` (written and checked before the first case runs), its
//! `result.json` (written atomically when the case ends: a killed study loses only the cases
//! that were running) and, when kept, its `run.mcap`; then `results.csv`, `summary.md` and
//! `plots/`. `rig study status` and `rig study collect` read the files alone, so a study run by
//! Slurm tasks on other machines (`slurm.rs`) is collected exactly as a local one.

pub mod cli;
pub mod file;
pub mod report;
pub mod slurm;
pub mod stats;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use serde::{Deserialize, Serialize};

pub use file::{Keep, Study};

/// What one case measured, as `result.json` holds it. Only what the simulation decides is in it
/// (no wall time), so the same case gives the same bytes on any run, machine or Slurm task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseRecord {
    pub case: usize,
    /// The uncertain parameters' values, in the study file's order.
    pub parameters: Vec<(String, f64)>,
    /// The realism seeds the case was given.
    pub seeds: Vec<(String, i64)>,
    pub exit_code: i32,
    /// Why, when not 0: the summary's last line without its `rig: exit N: ` prefix.
    pub status: String,
    pub misses: Option<u64>,
    pub safe_stops: Option<u64>,
    pub force_error_max_n: Option<f64>,
    pub force_error_rms_n: Option<f64>,
    pub bond_share: Option<f64>,
    pub bond_weakest_pa: Option<f64>,
    pub passed: bool,
    /// The criteria the case failed, as text (`force_error_max_n <= 0.45`).
    pub failed: Vec<String>,
}

impl CaseRecord {
    /// A metric by its name in `file::METRICS`.
    pub fn metric(&self, name: &str) -> Option<f64> {
        match name {
            "exit_code" => Some(self.exit_code as f64),
            "misses" => self.misses.map(|x| x as f64),
            "safe_stops" => self.safe_stops.map(|x| x as f64),
            "force_error_max_n" => self.force_error_max_n,
            "force_error_rms_n" => self.force_error_rms_n,
            "bond_share" => self.bond_share,
            "bond_weakest_pa" => self.bond_weakest_pa,
            _ => None,
        }
    }
}

/// Case `n`'s directory.
pub fn case_dir(dir: &Path, n: usize) -> PathBuf {
    dir.join("cases").join(format!("{n:06}"))
}

/// Writes `bytes` to `path` atomically (a temporary file in the same directory, then rename), so
/// that a reader, or a study killed mid-write, sees the whole file or none.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension(format!("tmp.{}", std::process::id()));
    let mut f = std::fs::File::create(&tmp).with_context(|| format!("writing {}", tmp.display()))?;
    f.write_all(bytes).and_then(|_| f.sync_data()).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
}

/// The finished case's record, if `result.json` is there.
pub fn read_result(dir: &Path, n: usize) -> Option<CaseRecord> {
    let text = std::fs::read_to_string(case_dir(dir, n).join("result.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// Plans the study into `dir`: copies the study file, writes and checks every case's scenario.
/// With `resume`, `dir` must hold the same study; its finished cases stay.
pub fn plan(study: &Study, dir: &Path, resume: bool) -> anyhow::Result<()> {
    let copy = dir.join("study.toml");
    match (resume, std::fs::read_to_string(&copy)) {
        (true, Ok(text)) => anyhow::ensure!(
            text == study.text,
            "--resume: {} holds another study ({} differs from {}); resume it with the study file it was started with",
            dir.display(),
            copy.display(),
            study.path.display()
        ),
        (true, Err(_)) => anyhow::bail!("--resume: {} holds no study (no study.toml); start it without --resume", dir.display()),
        (false, Ok(_)) => anyhow::bail!("{} already holds a study; give --resume to finish it, or another --out", dir.display()),
        (false, Err(_)) => {}
    }
    std::fs::create_dir_all(dir.join("cases")).with_context(|| format!("creating {}", dir.display()))?;
    // Cases are written elsewhere: a contour's pieces file goes inline.
    let base_text = scenarios::pieces_file::self_contained(&study.base)?;
    let base: toml::Table = base_text.parse().with_context(|| format!("parsing {}", study.base.display()))?;
    for (n, point) in study.points().iter().enumerate() {
        let cdir = case_dir(dir, n);
        let path = cdir.join("scenario.toml");
        if resume && path.exists() {
            continue;
        }
        std::fs::create_dir_all(&cdir).with_context(|| format!("creating {}", cdir.display()))?;
        let mut doc = base.clone();
        let mut set = |key: &str, v: toml::Value| {
            let (section, field) = key.split_once('.').unwrap_or(("", key));
            if let toml::Value::Table(t) = doc.entry(section).or_insert_with(|| toml::Value::Table(toml::Table::new())) {
                t.insert(field.into(), v);
            }
        };
        for (p, &x) in study.parameters.iter().zip(point) {
            set(&p.field, if p.integer { toml::Value::Integer(x as i64) } else { toml::Value::Float(x) });
        }
        for key in &study.vary_seeds {
            set(key, toml::Value::Integer(study.case_seed(key, n)));
        }
        // the sweep's scene rate unless the base sets one: a study is read as numbers
        crate::sweep::set_scene_rate(&mut doc, &[], None);
        doc.insert("description".into(), format!("rig study case {n} of {}: {}", study.path.display(), study.base.display()).into());
        std::fs::write(&path, toml::to_string(&doc)?).with_context(|| format!("writing {}", path.display()))?;
        let s = scenarios::Scenario::load(&path).with_context(|| {
            let values: Vec<String> = study.parameters.iter().zip(point).map(|(p, x)| format!("{}={x}", p.field)).collect();
            format!("study file {}: case {n} ({}) is not a valid scenario", study.path.display(), values.join(" "))
        })?;
        anyhow::ensure!(!s.egm.enabled, "study file {}: the base scenario enables [egm]; a study runs in process", study.path.display());
    }
    if !resume {
        let original = std::fs::canonicalize(&study.path).unwrap_or(study.path.clone());
        write_atomic(&dir.join("study-path"), original.as_os_str().as_encoded_bytes())?;
        write_atomic(&copy, study.text.as_bytes())?;
    }
    Ok(())
}

/// Runs case `n` of the study in `dir` in process (lockstep, the built-in controller) and
/// returns its record. Its figures come from its tick rows in memory (no file written and read
/// back); with `Keep::All` the same run records, and a failing case that `Keep::Failing` keeps
/// runs again with its recorder: lockstep in process is deterministic, so the file is that very
/// run, bit for bit.
pub fn run_case(
    study: &Study,
    (scenario, recording): (&Path, &Path),
    n: usize,
    point: &[f64],
    keep: Keep,
    strips: &crate::sweep::SharedStrips,
    signals: plant_sim::signals::Signals,
) -> anyhow::Result<Option<CaseRecord>> {
    use crate::in_process::Keep as Sink;
    use crate::supervise::{Ending, Outcome};
    let tuning = recordings::RecorderTuning::for_mode(scenarios::Mode::Lockstep);
    let rig = format!("study-case-{n}");
    // Every case's recording is wanted: written in the one run.
    let first = Sink { recording: (keep == Keep::All).then_some(recording), rows: true, quiet: true };
    let ran = crate::in_process::run(&rig, scenario, None, first, tuning.clone(), |s| strips.physics(s), signals);
    let (ending, summary, rows) = match ran {
        Ok((v, _)) if v.stopped_by_signal => return Ok(None),
        Ok((v, rows)) => (Ending::Completed, Some(v), rows),
        Err(e) => (Ending::PlantFailed(format!("{e:#}")), None, None),
    };
    let outcome = Outcome { ending, plant_summary: summary };
    let exit_code = outcome.exit_code();
    let line = crate::summary::status_line(exit_code, &outcome.ending, outcome.plant_summary.as_ref());
    let status = line.split_once(": ").and_then(|(_, rest)| rest.split_once(": ")).map_or(line.clone(), |(_, why)| why.to_string());
    let rolling = rows.as_ref().and_then(|r| r.rolling_numbers());
    let s = outcome.plant_summary.as_ref();
    let mut r = CaseRecord {
        case: n,
        parameters: study.parameters.iter().zip(point).map(|(p, &x)| (p.field.clone(), x)).collect(),
        seeds: study.vary_seeds.iter().map(|k| (k.clone(), study.case_seed(k, n))).collect(),
        exit_code,
        status: if exit_code == 0 { String::new() } else { status },
        misses: s.map(|v| v.misses),
        safe_stops: s.map(|v| v.safe_stops),
        force_error_max_n: rolling.as_ref().and_then(|r| r.force_error_max_abs_n),
        force_error_rms_n: rolling.as_ref().and_then(|r| r.force_error_rms_n),
        bond_share: rolling.as_ref().and_then(|r| r.bond_pressure_share),
        bond_weakest_pa: rolling.as_ref().and_then(|r| r.bond_weakest_pa_at_z_m).map(|w| w[0]),
        passed: false,
        failed: Vec::new(),
    };
    r.failed = study.criteria.iter().filter(|c| !c.holds(r.metric(&c.metric))).map(|c| c.text()).collect();
    r.passed = r.failed.is_empty();
    let kept = match keep {
        Keep::All => true,
        Keep::Failing => !r.passed,
        Keep::None => false,
    };
    // A case the plant refused to run has no recording to keep.
    if kept && keep != Keep::All && outcome.plant_summary.is_some() {
        let again = crate::in_process::run(
            &rig,
            scenario,
            None,
            Sink { recording: Some(recording), rows: false, quiet: true },
            tuning,
            |s| strips.physics(s),
            signals,
        );
        match again {
            Ok((v, _)) if v.stopped_by_signal => {
                let _ = std::fs::remove_file(recording);
                return Ok(None);
            }
            Ok(_) => {}
            Err(e) => anyhow::bail!("case {n}: recording it again: {e:#}"),
        }
    }
    Ok(Some(r))
}

/// Runs the given cases (skipping finished ones) on one thread per core, each result written
/// atomically as it ends; a progress line on a terminal; a stop (`signals`) lets the running
/// cases end and starts no more. Returns how many ran.
pub fn run_cases(study: &Study, dir: &Path, cases: &[usize], keep: Keep, signals: plant_sim::signals::Signals) -> anyhow::Result<usize> {
    let todo: Vec<usize> = cases.iter().copied().filter(|&n| !case_dir(dir, n).join("result.json").exists()).collect();
    let strips = crate::sweep::SharedStrips::new(&strip::cache::cache_dir());
    let points = study.points();
    let progress = Progress::new(todo.len(), cases.len() - todo.len());
    let errors = std::sync::Mutex::new(Vec::new());
    crate::sweep::run_cases(&todo, |_, &n| {
        if signals.stop_requested() {
            return;
        }
        let cdir = case_dir(dir, n);
        let files = (cdir.join("scenario.toml"), cdir.join("run.mcap"));
        match run_case(study, (&files.0, &files.1), n, &points[n], keep, &strips, signals).and_then(|r| match r {
            Some(r) => write_atomic(&case_dir(dir, n).join("result.json"), serde_json::to_string_pretty(&r)?.as_bytes()),
            None => Ok(()),
        }) {
            Ok(()) => progress.tick(),
            Err(e) => errors.lock().unwrap_or_else(|e| e.into_inner()).push(format!("case {n}: {e:#}")),
        }
    });
    progress.finish();
    let errors = errors.into_inner().unwrap_or_else(|e| e.into_inner());
    anyhow::ensure!(errors.is_empty(), "{} case(s) could not be run: {}", errors.len(), errors.join("; "));
    Ok(progress.done.load(Ordering::Relaxed))
}

/// The progress bar: cases done, rate and time left, redrawn on stderr when it is a terminal
/// (at most 4 times a second); one line per tenth of the cases otherwise.
struct Progress {
    total: usize,
    before: usize,
    done: AtomicUsize,
    started: std::time::Instant,
    last_ms: AtomicUsize,
    tty: bool,
}

impl Progress {
    fn new(total: usize, before: usize) -> Progress {
        // SAFETY: isatty only inspects the descriptor.
        let tty = unsafe { libc::isatty(2) } == 1;
        Progress { total, before, done: AtomicUsize::new(0), started: std::time::Instant::now(), last_ms: AtomicUsize::new(0), tty }
    }

    fn line(&self, done: usize) -> String {
        let t = self.started.elapsed().as_secs_f64();
        let rate = done as f64 / t.max(1e-9);
        let left = (self.total - done) as f64 / rate.max(1e-9);
        let width = 30;
        let filled = (done * width).checked_div(self.total).unwrap_or(width);
        format!(
            "rig study: [{}{}] {}/{} cases ({} finished before), {:.2} cases/s, {:.0} s left",
            "#".repeat(filled),
            ".".repeat(width - filled),
            done,
            self.total,
            self.before,
            rate,
            left
        )
    }

    fn tick(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let ms = self.started.elapsed().as_millis() as usize;
        if self.tty {
            let last = self.last_ms.load(Ordering::Relaxed);
            if (ms >= last + 250 || done == self.total)
                && self.last_ms.compare_exchange(last, ms, Ordering::Relaxed, Ordering::Relaxed).is_ok()
            {
                eprint!("\r{}", self.line(done));
            }
        } else if self.total >= 10 && done.is_multiple_of(self.total / 10) {
            eprintln!("{}", self.line(done));
        }
    }

    fn finish(&self) {
        if self.tty && self.total > 0 {
            eprintln!();
        }
    }
}

/// Which cases are finished and which are missing, from the files.
pub fn scan(dir: &Path, cases: usize) -> (Vec<CaseRecord>, Vec<usize>) {
    let mut done = Vec::new();
    let mut missing = Vec::new();
    for n in 0..cases {
        match read_result(dir, n) {
            Some(r) => done.push(r),
            None => missing.push(n),
        }
    }
    (done, missing)
}

/// The study of a study directory (its copy of the study file; relative paths as in the original).
pub fn load_from_dir(dir: &Path) -> anyhow::Result<Study> {
    let copy = dir.join("study.toml");
    let text = std::fs::read_to_string(&copy).with_context(|| format!("{} holds no study (no study.toml)", dir.display()))?;
    let original = std::fs::read_to_string(dir.join("study-path")).map(PathBuf::from).unwrap_or(copy.clone());
    Ok(Study::parse(&original, &text)?)
}
