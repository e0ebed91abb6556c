//! Reading a recording while it is written (`Recording::follow_channels`, `rig run`'s summary in
//! lockstep): whatever the writer's pace, a stale file of another rig at the same path, or a
//! file left cut, the result is what a read of the finished file gives.

use recording_tools::read::{Channels, Recording, Writing};
use recordings::synthetic::SyntheticRun;
use recordings::RecorderConfig;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Duration;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("follow-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The bytes of a synthetic run's recording of `ticks` ticks by rig `rig`, in 64 KiB chunks.
fn recording(test: &str, rig: &str, ticks: u64) -> Vec<u8> {
    let run = SyntheticRun { ticks, ..Default::default() };
    let path = tmp(&format!("source-{test}-{rig}.mcap"));
    let mut cfg = RecorderConfig::new(&path, run.metadata());
    cfg.metadata.rig = rig.into();
    cfg.chunk_size_bytes = 64 << 10;
    run.record(cfg).unwrap();
    std::fs::read(path).unwrap()
}

const RUNNING: u8 = 0;
const FINISHED: u8 = 1;
const ABANDONED: u8 = 2;

/// Follows `path` while a thread truncates it and writes `bytes` into it `piece` bytes at a
/// time, then says `end` (Finished or Abandoned).
fn follow_while_written(path: &Path, bytes: &[u8], piece: usize, end: u8) -> Option<Result<Recording, recording_tools::read::ReadError>> {
    let state = AtomicU8::new(RUNNING);
    std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(Duration::from_millis(5));
            let mut f = std::fs::File::create(path).unwrap();
            for p in bytes.chunks(piece) {
                f.write_all(p).unwrap();
                std::thread::sleep(Duration::from_micros(300));
            }
            drop(f);
            state.store(end, Ordering::Release);
        });
        let progress = || match state.load(Ordering::Acquire) {
            RUNNING => Writing::Running,
            FINISHED => Writing::Finished,
            _ => Writing::Abandoned,
        };
        Recording::follow_channels(path, Channels::ALL, "followed", Duration::from_millis(1), &progress)
    })
}

fn assert_same(followed: &Recording, read: &Recording) {
    assert_eq!(followed.integrity, read.integrity);
    assert_eq!(followed.joint_state, read.joint_state);
    assert_eq!(followed.joint_torque, read.joint_torque);
    assert_eq!(followed.wrench, read.wrench);
    assert_eq!(followed.log_time_ns, read.log_time_ns);
    assert_eq!(followed.events.len(), read.events.len());
    assert_eq!(followed.rig_metadata("rig"), Some("followed"));
    assert_eq!(followed.summary_metadata("stopped_early"), read.summary_metadata("stopped_early"));
}

#[test]
fn a_file_read_as_it_is_written_over_another_rigs_reads_as_the_finished_file() {
    let ours = recording("over", "followed", 1500);
    let theirs = recording("over", "another", 900);
    for piece in [4099, 65_536, 1 << 20] {
        let path = tmp(&format!("followed-{piece}.mcap"));
        // the last run's file, of another rig, is there when the follow starts
        std::fs::write(&path, &theirs).unwrap();
        let followed = follow_while_written(&path, &ours, piece, FINISHED).expect("finished").unwrap();
        let read = Recording::open(&path).unwrap();
        assert_eq!(read.check_continuity().unwrap(), 0..=1499);
        assert_same(&followed, &read);
    }
}

#[test]
fn a_file_left_cut_is_judged_as_a_read_of_it_judges_it() {
    let ours = recording("cut", "followed", 1500);
    for frac in [0.3, 0.97] {
        let cut = &ours[..(ours.len() as f64 * frac) as usize];
        let path = tmp(&format!("cut-{frac}.mcap"));
        let followed = follow_while_written(&path, cut, 8191, FINISHED).expect("finished").unwrap();
        let read = Recording::open(&path).unwrap();
        assert!(matches!(read.integrity, recording_tools::read::Integrity::Cut(_)), "{:?}", read.integrity);
        assert_same(&followed, &read);
    }
}

#[test]
fn an_abandoned_follow_ends_without_a_result() {
    let ours = recording("abandoned", "followed", 300);
    let path = tmp("abandoned.mcap");
    assert!(follow_while_written(&path, &ours[..ours.len() / 2], 4096, ABANDONED).is_none());
}
