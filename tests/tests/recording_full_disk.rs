//! The real plant filling a real disk: `plant-sim` + `controller` in lockstep record onto an
//! 80 MiB tmpfs in a private mount namespace (`unshare`), and another file takes every free byte
//! in the middle of the run (the plant held with SIGSTOP meanwhile, so that the disk goes from
//! roomy to full between two of its chunks). The full disk must end the recording the clean way:
//! the plant runs to its end, its summary JSON says `recording_stopped_early` = "disk full
//! (ENOSPC) at tick N ..." or "disk almost full: 0 MiB free ...", and the file reads back
//! complete, stopped early for that same reason, with every tick up to the stop. The inner test runs inside the namespace, started by the outer one.

use harness::{bin, plant_summary, start_controller, temp_dir, unique_rig, write_scenario, Daemon};
use recording_tools::read::{Integrity, Recording};
use recording_tools::tmpfs_test::run_inner_on_private_tmpfs;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const DIR_ENV: &str = "RIG_TESTS_FULL_DISK_DIR";
const TMPFS_MIB: u64 = 80;

#[test]
fn a_disk_filling_up_mid_run_ends_the_recording_cleanly_and_the_plant_says_why() {
    let dir = std::env::temp_dir().join(format!("rig-tests-enospc-{}", std::process::id()));
    let Some(stdout) = run_inner_on_private_tmpfs(DIR_ENV, &dir, &format!("{TMPFS_MIB}m"), "inner_plant_on_a_filling_disk") else { return };
    print!("{}", stdout.lines().filter(|l| l.starts_with("recording_stopped_early")).map(|l| format!("{l}\n")).collect::<String>());
}

/// Takes every free byte of the file system holding `dir` (tmpfs: fallocate allocates, and an
/// allocation that does not fit fails whole, so the steps shrink down to a page).
fn fill(dir: &Path) {
    let f = std::fs::File::create(dir.join("filler")).unwrap();
    let mut at = 0i64;
    for step in [1i64 << 20, 64 << 10, 4 << 10] {
        // SAFETY: fallocate(2) on an fd we own; no memory is touched.
        while unsafe { libc::fallocate(f.as_raw_fd(), 0, at, step) } == 0 {
            at += step;
        }
    }
}

#[test]
#[ignore = "started by a_disk_filling_up_mid_run_ends_the_recording_cleanly_and_the_plant_says_why"]
fn inner_plant_on_a_filling_disk() {
    let disk = PathBuf::from(std::env::var(DIR_ENV).expect("started by the outer test"));
    let rig = unique_rig("enospc");
    let logs = temp_dir(&rig); // logs and scenario off the full disk: the summary must get out
    let scenario = write_scenario(&logs, "lockstep", "");
    let out = disk.join("run.mcap");
    let args = ["--rig", &rig, "--scenario", scenario.to_str().unwrap(), "--duration", "60", "--out", out.to_str().unwrap()];
    let mut plant = Daemon::start("plant", &bin("plant-sim"), &args, &logs);
    let mut ctrl = start_controller("controller", "controller", &rig, &scenario, &logs, &[]);
    let t0 = Instant::now();
    while std::fs::metadata(&out).map_or(0, |m| m.len()) < 512 << 10 {
        assert!(t0.elapsed() < Duration::from_secs(60), "the recording did not grow: {}", plant.stderr());
        std::thread::sleep(Duration::from_millis(5));
    }
    plant.signal(libc::SIGSTOP);
    fill(&disk);
    plant.signal(libc::SIGCONT);
    let ps = plant.expect_exit(Duration::from_secs(120));
    assert!(ps.success(), "plant failed: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller failed: {}", ctrl.stderr());

    let summary = plant_summary(&plant);
    assert_eq!((summary["ticks"].as_u64(), summary["drops"].as_u64()), (Some(60_000), Some(0)), "the loop never noticed: {summary}");
    let why = summary["recording_stopped_early"].as_str().unwrap_or_else(|| panic!("no reason in {summary}"));
    println!("recording_stopped_early: {why}");
    let rec = Recording::open_complete(&out).unwrap();
    assert_eq!(rec.integrity, Integrity::StoppedEarly(why.to_string()));
    let last = rec.joint_state.last().unwrap().tick;
    // Two clean endings, both finalised with the reason: the next chunk's write fails (ENOSPC), or
    // it still fits in the room kept past the file's end (a short chunk, flushed by age right after
    // the SIGCONT) and the free-space check after it ends the recording. Which one comes first
    // depends on how long the plant was held.
    if why.starts_with("disk full (ENOSPC) at tick ") {
        assert!(why.contains("No space left on device"), "{why}");
        assert!(why.contains(&format!("the file keeps the ticks up to {last}")), "{why}");
    } else {
        assert!(why.starts_with("disk almost full: 0 MiB free, below the 64 MiB reserve; recording stopped at tick "), "{why}");
        assert!(why.ends_with(&format!("stopped at tick {last}")), "{why}");
    }
    assert_eq!(*rec.check_continuity().unwrap().start(), 0);
    assert!(last > 0 && last < 59_999, "stopped in the middle: {last}");
}
