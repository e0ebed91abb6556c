//! A study on a Slurm cluster: one job array whose task T runs the cases
//! `T * cases_per_task .. (T + 1) * cases_per_task` (`rig study case DIR --task T`), all cores of
//! its allocation at once, each result written to the study directory as on a local run. The
//! directory must be on a path every node sees (a shared file system); nothing else is shared.
//!
//! What happened is read from the files, never from Slurm's accounting (a cluster may have
//! none): a task writes `slurm/task-T.started` when it starts and `slurm/task-T.done` when it
//! ends; its output is `slurm/task-T.out`, where slurmstepd writes `CANCELLED` or
//! `DUE TO TIME LIMIT` when it ends a task. `squeue` is asked only whether the job still runs.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::Context;
use serde::{Deserialize, Serialize};

/// `slurm/slurm.json`: how the cases are cut into tasks, and the jobs submitted so far.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plan {
    pub cases_per_task: usize,
    pub tasks: usize,
    /// Job ids, the first submission first (a `--resume` adds one).
    pub jobs: Vec<String>,
}

/// The options of `rig study run --slurm`.
#[derive(Debug, Clone, clap::Args)]
pub struct SlurmArgs {
    /// Submit the study as a Slurm job array instead of running it here (the study directory
    /// must be on a path every node sees).
    #[arg(long)]
    pub slurm: bool,
    /// Slurm partition (default: the cluster's default).
    #[arg(long, requires = "slurm")]
    pub partition: Option<String>,
    /// Time limit of each task, as sbatch takes it (`MM`, `HH:MM:SS`, `D-HH`).
    #[arg(long, requires = "slurm")]
    pub time_limit: Option<String>,
    /// How many tasks may run at once (the array's `%` throttle).
    #[arg(long, default_value_t = 4, requires = "slurm")]
    pub max_running: usize,
    /// Cases per task: Slurm starts about one task per slot per second, so a task should run
    /// many cases.
    #[arg(long, default_value_t = 50, requires = "slurm")]
    pub cases_per_task: usize,
}

pub fn plan_path(dir: &Path) -> PathBuf {
    dir.join("slurm").join("slurm.json")
}

pub fn read_plan(dir: &Path) -> Option<Plan> {
    serde_json::from_str(&std::fs::read_to_string(plan_path(dir)).ok()?).ok()
}

/// The cases of task `t`.
pub fn task_cases(plan: &Plan, cases: usize, t: usize) -> std::ops::Range<usize> {
    (t * plan.cases_per_task).min(cases)..((t + 1) * plan.cases_per_task).min(cases)
}

/// Submits the tasks `tasks` (all of them on a first run, those with missing cases on a resume)
/// and records the job id. Returns it.
pub fn submit(dir: &Path, cases: usize, args: &SlurmArgs, resume: bool, missing: &[usize]) -> anyhow::Result<String> {
    anyhow::ensure!(args.cases_per_task > 0 && args.max_running > 0, "--cases-per-task and --max-running must be at least 1");
    let sdir = dir.join("slurm");
    std::fs::create_dir_all(&sdir).with_context(|| format!("creating {}", sdir.display()))?;
    let mut plan = match (resume, read_plan(dir)) {
        (true, Some(p)) => p,
        _ => Plan { cases_per_task: args.cases_per_task, tasks: cases.div_ceil(args.cases_per_task), jobs: Vec::new() },
    };
    let mut tasks: Vec<usize> = missing.iter().map(|n| n / plan.cases_per_task).collect();
    tasks.dedup();
    anyhow::ensure!(!tasks.is_empty(), "every case of {} is finished; nothing to submit", dir.display());
    for t in &tasks {
        // a resubmitted task starts afresh in the files
        let _ = std::fs::remove_file(sdir.join(format!("task-{t}.started")));
        let _ = std::fs::remove_file(sdir.join(format!("task-{t}.done")));
    }
    let dir_abs = std::fs::canonicalize(dir)?;
    let rig = std::env::current_exe().context("finding the rig executable")?;
    let list: Vec<String> = tasks.iter().map(usize::to_string).collect();
    let mut script = format!(
        "#!/bin/bash\n#SBATCH --job-name=rig-study\n#SBATCH --array={}%{}\n#SBATCH --output={}/slurm/task-%a.out\n#SBATCH --cpus-per-task=1\n",
        list.join(","),
        args.max_running,
        dir_abs.display()
    );
    if let Some(p) = &args.partition {
        script += &format!("#SBATCH --partition={p}\n");
    }
    if let Some(t) = &args.time_limit {
        script += &format!("#SBATCH --time={t}\n");
    }
    script += &format!("exec {} study case {} --task \"$SLURM_ARRAY_TASK_ID\"\n", rig.display(), dir_abs.display());
    let script_path = sdir.join(format!("job-{}.sh", plan.jobs.len()));
    std::fs::write(&script_path, script).with_context(|| format!("writing {}", script_path.display()))?;
    let out = Command::new("sbatch")
        .arg("--parsable")
        .arg(&script_path)
        .output()
        .context("running sbatch (is Slurm's client installed and on PATH?)")?;
    anyhow::ensure!(
        out.status.success(),
        "sbatch {} refused the job: {}",
        script_path.display(),
        String::from_utf8_lossy(&out.stderr).trim()
    );
    let job = String::from_utf8_lossy(&out.stdout).trim().split(';').next().unwrap_or("").to_string();
    anyhow::ensure!(!job.is_empty(), "sbatch printed no job id");
    plan.jobs.push(job.clone());
    super::write_atomic(&plan_path(dir), serde_json::to_string_pretty(&plan)?.as_bytes())?;
    Ok(job)
}

/// The array tasks of the study's jobs that Slurm still has pending or running (`squeue`), or
/// None when squeue cannot be asked.
pub fn active_tasks(plan: &Plan) -> Option<Vec<(usize, String)>> {
    let jobs = plan.jobs.join(",");
    let out = Command::new("squeue").args(["-h", "-r", "-j", &jobs, "-o", "%K %T"]).output().ok()?;
    if !out.status.success() {
        // squeue refuses ids it has forgotten: none of them is active
        return Some(Vec::new());
    }
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| {
                let (k, state) = l.trim().split_once(' ')?;
                Some((k.parse().ok()?, state.to_string()))
            })
            .collect(),
    )
}

/// What became of a task with missing cases, from its files (and squeue, when it answers).
pub fn task_state(dir: &Path, t: usize, active: Option<&[(usize, String)]>) -> String {
    let sdir = dir.join("slurm");
    if let Some((_, state)) = active.and_then(|a| a.iter().find(|(k, _)| *k == t)) {
        return format!("{} in Slurm", state.to_lowercase());
    }
    let out = std::fs::read_to_string(sdir.join(format!("task-{t}.out"))).unwrap_or_default();
    let started = sdir.join(format!("task-{t}.started")).exists();
    let done = sdir.join(format!("task-{t}.done")).exists();
    let log = format!("slurm/task-{t}.out");
    if out.contains("DUE TO TIME LIMIT") {
        format!("timed out (Slurm's time limit; {log})")
    } else if out.contains("CANCELLED") {
        format!("cancelled ({log})")
    } else if done {
        format!("ended with cases unfinished ({log})")
    } else if started {
        format!("failed or was killed before it finished ({log})")
    } else if active.is_none() {
        "not started (squeue could not be asked whether it is still queued)".into()
    } else {
        "never started (cancelled while pending, or its job was lost)".into()
    }
}
