//! `rig study run --slurm` through a real one-node Slurm cluster (slurmctld, slurmd and munge
//! from Debian's packages, started without systemd by `tests/slurm/single-node.sh`, stopped
//! by PID at the end): every case's result bit-identical to the same study run locally; a task
//! cancelled with `scancel` while it runs shows as missing cases and what became of its task,
//! and `--resume --slurm` resubmits only those and completes the study. Needs root (CI is).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use harness::*;

const LONG: Duration = Duration::from_secs(600);

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("slurm/single-node.sh")
}

/// Stops the cluster when the test ends, passed or not.
struct Cluster;

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash").arg(script()).arg("stop").status();
    }
}

fn results(dir: &Path, cases: usize) -> Vec<Option<String>> {
    (0..cases).map(|n| std::fs::read_to_string(dir.join(format!("cases/{n:06}/result.json"))).ok()).collect()
}

/// Runs `rig` with `args` to its end: the process (for its output) and its exit status.
fn rig_study(dir: &Path, args: &[&str]) -> (Daemon, Option<i32>) {
    let mut d = Daemon::start("rig study", &bin("rig"), args, dir);
    let code = d.expect_exit(LONG).code();
    (d, code)
}

/// Polls `squeue` until none of the study's tasks is pending or running.
fn wait_idle(plan_jobs: impl Fn() -> Vec<String>) {
    let t0 = Instant::now();
    loop {
        let jobs = plan_jobs().join(",");
        let q = Command::new("squeue").args(["-h", "-r", "-j", &jobs, "-o", "%K %T"]).output().unwrap();
        if String::from_utf8_lossy(&q.stdout).trim().is_empty() {
            return;
        }
        assert!(t0.elapsed() < LONG, "the study's Slurm tasks did not end: {}", String::from_utf8_lossy(&q.stdout));
        std::thread::sleep(Duration::from_millis(250));
    }
}

#[test]
fn a_study_through_slurm_equals_the_local_run_and_a_cancelled_task_is_resumed() {
    // SAFETY: geteuid has no preconditions.
    assert_eq!(unsafe { libc::geteuid() }, 0, "the Slurm test starts slurmctld, slurmd and munged: run it as root (CI does)");
    let rig = unique_rig("study-slurm");
    let dir = temp_dir(&rig);
    let st = Command::new("bash").arg(script()).arg("start").status().unwrap();
    assert!(st.success(), "starting the one-node Slurm cluster failed");
    let _cluster = Cluster;

    // 24 cases in 3 tasks of 8; a base with 30 s simulated per case so that a task runs long
    // enough to be cancelled in the middle.
    let base = dir.join("base.toml");
    let mut doc: toml::Table =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml")).unwrap().parse().unwrap();
    doc.entry("loop").or_insert(toml::Value::Table(Default::default())).as_table_mut().unwrap().insert("duration_s".into(), 30.0.into());
    std::fs::write(&base, toml::to_string(&doc).unwrap()).unwrap();
    let file = dir.join("study.toml");
    std::fs::write(
        &file,
        "base = \"base.toml\"\ncases = 24\nseed = 5\nrecordings = \"none\"\n\
         [[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"uniform\"\nmin = 0.1\nmax = 0.4\n\
         [[parameter]]\nfield = \"robot.tool_mass_kg\"\ndistribution = \"normal\"\nmean = 1.0\nsd = 0.033\nmin = 0.9\nmax = 1.1\n\
         [[criterion]]\nmetric = \"force_error_max_n\"\nmax = 0.45\n",
    )
    .unwrap();
    let (f, local, slurm) = (file.to_str().unwrap(), dir.join("local"), dir.join("slurm"));
    let (l, _) = rig_study(&dir, &["study", "run", f, "--out", local.to_str().unwrap()]);
    assert!(l.stdout().contains("Pass rate: 24 of 24"), "{}\n{}", l.stdout(), l.stderr());

    let s = slurm.to_str().unwrap();
    let (sub, _) = rig_study(&dir, &["study", "run", f, "--out", s, "--slurm", "--cases-per-task", "8", "--max-running", "2"]);
    assert!(sub.stdout().contains("24 case(s) submitted to Slurm as job"), "{}\n{}", sub.stdout(), sub.stderr());
    let jobs = || {
        let plan: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(slurm.join("slurm/slurm.json")).unwrap()).unwrap();
        plan["jobs"].as_array().unwrap().iter().map(|j| j.as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    let job = jobs()[0].clone();
    // cancel task 1 as soon as it has started and before it has finished its cases
    let t0 = Instant::now();
    while !slurm.join("slurm/task-1.started").exists() {
        assert!(t0.elapsed() < LONG, "task 1 never started");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(Command::new("scancel").arg(format!("{job}_1")).status().unwrap().success());
    wait_idle(jobs);
    let (st, code) = rig_study(&dir, &["study", "status", s]);
    let out = st.stdout();
    let missing: Vec<usize> = results(&slurm, 24).iter().enumerate().filter(|(_, r)| r.is_none()).map(|(n, _)| n).collect();
    assert!(!missing.is_empty() && missing.iter().all(|n| (8..16).contains(n)), "only task 1's cases are missing: {missing:?}\n{out}");
    assert_eq!(code, Some(5), "{out}");
    assert!(out.contains("task 1: cancelled (slurm/task-1.out); missing cases "), "{out}");
    assert!(!out.contains("task 0:") && !out.contains("task 2:"), "{out}");

    // resume: only task 1 again
    let (re, _) = rig_study(&dir, &["study", "run", f, "--out", s, "--resume", "--slurm"]);
    assert!(re.stdout().contains(&format!("{} case(s) submitted to Slurm", missing.len())), "{}\n{}", re.stdout(), re.stderr());
    let script = std::fs::read_to_string(slurm.join("slurm/job-1.sh")).unwrap();
    assert!(script.contains("#SBATCH --array=1%4"), "{script}");
    wait_idle(jobs);
    let (c, code) = rig_study(&dir, &["study", "collect", s]);
    assert_eq!(code, Some(0), "{}\n{}", c.stdout(), c.stderr());
    assert_eq!(results(&slurm, 24), results(&local, 24), "every case through Slurm is bit-identical to the local run's");
    assert_eq!(std::fs::read_to_string(slurm.join("results.csv")).unwrap(), std::fs::read_to_string(local.join("results.csv")).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}
