//! The `rig study` commands. Exit statuses: 0 every case finished and passed; 4 every case
//! finished, some failed a criterion; 5 cases are missing (a study submitted to Slurm and not
//! yet done, or cases whose task failed); 1 an error; 130/143 interrupted (finished cases kept).

use std::path::{Path, PathBuf};

use super::{report, scan, slurm, Keep, Study};

#[derive(Debug, clap::Subcommand)]
pub enum StudyCmd {
    /// Plan and run a study: every case's scenario written and checked, then the cases on every
    /// core (or as a Slurm job array with --slurm), then the table, summary and plots.
    Run(RunArgs),
    /// Run cases of a planned study: those of a Slurm task (`--task T`, what the job array runs),
    /// or one case again (`--case N`: keeps its recording and checks its result bit for bit).
    Case(CaseArgs),
    /// Which cases are finished and which are missing, and what became of their Slurm tasks.
    Status { dir: PathBuf },
    /// The table, summary and plots from the case results in the directory.
    Collect { dir: PathBuf },
}

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The study file (studies/README.md describes it).
    file: PathBuf,
    /// The study directory (default: runs/study-<UTC time>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Finish the study in --out: run (or submit) only the cases without a result.
    #[arg(long, requires = "out")]
    resume: bool,
    /// Which recordings to keep (default: the study file's `recordings`, else `failing`).
    #[arg(long, value_enum)]
    recordings: Option<Keep>,
    #[command(flatten)]
    slurm: slurm::SlurmArgs,
}

#[derive(Debug, clap::Args)]
pub struct CaseArgs {
    dir: PathBuf,
    /// The Slurm array task whose cases to run.
    #[arg(long, conflicts_with = "case", required_unless_present = "case")]
    task: Option<usize>,
    /// One case to run again.
    #[arg(long)]
    case: Option<usize>,
}

/// The exit status of a study from its results.
fn exit_status(records: &[super::CaseRecord], missing: &[usize]) -> i32 {
    if !missing.is_empty() {
        5
    } else if records.iter().all(|r| r.passed) {
        0
    } else {
        4
    }
}

fn collect(study: &Study, dir: &Path) -> anyhow::Result<i32> {
    let (records, missing) = scan(dir, study.cases);
    let text = report::write_all(study, dir, &records, &missing)?;
    print!("{text}");
    println!("study directory: {}", dir.display());
    Ok(exit_status(&records, &missing))
}

pub fn run(cmd: StudyCmd, stamp: impl FnOnce() -> String) -> anyhow::Result<i32> {
    match cmd {
        StudyCmd::Run(a) => {
            let study = Study::load(&a.file)?;
            let dir = a.out.unwrap_or_else(|| Path::new("runs").join(format!("study-{}", stamp())));
            super::plan(&study, &dir, a.resume)?;
            let (_, missing) = scan(&dir, study.cases);
            if a.slurm.slurm {
                if missing.is_empty() {
                    return collect(&study, &dir);
                }
                let job = slurm::submit(&dir, study.cases, &a.slurm, a.resume, &missing)?;
                println!(
                    "rig study: {} case(s) submitted to Slurm as job {job}; follow with `rig study status {d}`, then `rig study collect {d}`",
                    missing.len(),
                    d = dir.display()
                );
                return Ok(5);
            }
            let signals = plant_sim::signals::Signals::install_stop_only();
            let keep = a.recordings.unwrap_or(study.recordings);
            super::run_cases(&study, &dir, &missing, keep, signals)?;
            if signals.stop_requested() {
                eprintln!(
                    "rig study: interrupted; finished cases are kept: `rig study run {} --out {} --resume` runs the rest",
                    a.file.display(),
                    dir.display()
                );
                return Ok(130);
            }
            collect(&study, &dir)
        }
        StudyCmd::Case(a) => {
            let study = super::load_from_dir(&a.dir)?;
            let keep = study.recordings;
            let signals = plant_sim::signals::Signals::install_stop_only();
            if let Some(t) = a.task {
                let plan =
                    slurm::read_plan(&a.dir).ok_or_else(|| anyhow::anyhow!("{} has no Slurm plan (slurm/slurm.json)", a.dir.display()))?;
                anyhow::ensure!(t < plan.tasks, "--task {t}: the study has tasks 0..{}", plan.tasks);
                let sdir = a.dir.join("slurm");
                super::write_atomic(&sdir.join(format!("task-{t}.started")), b"")?;
                let cases: Vec<usize> = slurm::task_cases(&plan, study.cases, t).collect();
                let ran = super::run_cases(&study, &a.dir, &cases, keep, signals)?;
                if signals.stop_requested() {
                    return Ok(143);
                }
                super::write_atomic(&sdir.join(format!("task-{t}.done")), format!("{ran}\n").as_bytes())?;
                println!(
                    "rig study: task {t}: {ran} case(s) run, cases {}..{}",
                    cases.first().unwrap_or(&0),
                    cases.last().map_or(0, |c| c + 1)
                );
                return Ok(0);
            }
            let n = a.case.unwrap_or(0);
            anyhow::ensure!(n < study.cases, "--case {n}: the study has cases 0..{}", study.cases);
            let stored = super::read_result(&a.dir, n);
            let out = a.dir.join("repro").join(format!("{n:06}"));
            std::fs::create_dir_all(&out)?;
            let recording = out.join("run.mcap");
            let strips = crate::sweep::SharedStrips::new(&strip::cache::cache_dir());
            let point = &study.points()[n];
            let scenario = super::case_dir(&a.dir, n).join("scenario.toml");
            let Some(r) = super::run_case(&study, (&scenario, &recording), n, point, Keep::All, &strips, signals)? else { return Ok(130) };
            println!("rig study: case {n} run again from {}; recording {}", scenario.display(), recording.display());
            println!("{}", serde_json::to_string_pretty(&r)?);
            match stored {
                Some(s) if s == r => {
                    println!("rig study: case {n}: the result equals the study's bit for bit");
                    Ok(0)
                }
                Some(_) => {
                    println!(
                        "rig study: case {n}: the result DIFFERS from the study's ({})",
                        super::case_dir(&a.dir, n).join("result.json").display()
                    );
                    Ok(1)
                }
                None => {
                    println!("rig study: case {n} had no result in the study yet");
                    Ok(0)
                }
            }
        }
        StudyCmd::Status { dir } => {
            let study = super::load_from_dir(&dir)?;
            let (records, missing) = scan(&dir, study.cases);
            let passed = records.iter().filter(|r| r.passed).count();
            println!("{}: {} of {} cases finished, {passed} passed, {} missing", dir.display(), records.len(), study.cases, missing.len());
            if let Some(plan) = slurm::read_plan(&dir) {
                let active = slurm::active_tasks(&plan);
                let mut tasks: Vec<usize> = missing.iter().map(|n| n / plan.cases_per_task).collect();
                tasks.dedup();
                for t in tasks {
                    let cases: Vec<String> = missing.iter().filter(|n| *n / plan.cases_per_task == t).map(usize::to_string).collect();
                    println!("task {t}: {}; missing cases {}", slurm::task_state(&dir, t, active.as_deref()), cases.join(","));
                }
            } else if !missing.is_empty() {
                let shown: Vec<String> = missing.iter().take(20).map(usize::to_string).collect();
                println!("missing cases: {}{}", shown.join(","), if missing.len() > 20 { ", ..." } else { "" });
            }
            Ok(exit_status(&records, &missing))
        }
        StudyCmd::Collect { dir } => collect(&super::load_from_dir(&dir)?, &dir),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exit_status_says_missing_then_failing() {
        let r = |passed| super::super::CaseRecord {
            case: 0,
            parameters: vec![],
            seeds: vec![],
            exit_code: 0,
            status: String::new(),
            misses: None,
            safe_stops: None,
            force_error_max_n: None,
            force_error_rms_n: None,
            bond_share: None,
            bond_weakest_pa: None,
            passed,
            failed: vec![],
        };
        assert_eq!(exit_status(&[r(true)], &[]), 0);
        assert_eq!(exit_status(&[r(true), r(false)], &[]), 4);
        assert_eq!(exit_status(&[r(true)], &[3]), 5);
    }
}
