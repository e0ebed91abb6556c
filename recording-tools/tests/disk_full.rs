//! A really full disk (ENOSPC from a 384 KiB tmpfs) in the middle of a recording: the writer stops
//! with a reason naming the error, the loop side never blocks, and the file is cut back to its
//! complete chunks and ended there, finalised, with the same story as the 64 MiB reserve. The tmpfs lives in a private mount namespace (`unshare`), so the inner test runs in a
//! child process: the outer test starts it there and checks that it ran and passed.

mod common;

use std::path::{Path, PathBuf};

use recording_tools::read::{Integrity, Recording};
use recording_tools::tmpfs_test::run_inner_on_private_tmpfs;
use recordings::synthetic::SyntheticRun;
use recordings::{EventKind, Recorder, RecorderConfig, RecorderTuning, RecordingSummary};

const DIR_ENV: &str = "RECORDINGS_FULL_DISK_DIR";
const TMPFS_BYTES: u64 = 384 << 10;

#[test]
fn a_full_disk_mid_run_stops_the_recording_and_keeps_the_complete_chunks() {
    let dir = std::env::temp_dir().join(format!("recordings-enospc-{}", std::process::id()));
    // Where no mount namespace is allowed (unprivileged CI without user namespaces) it prints
    // SKIPPED: the EFBIG test in write_error.rs covers the same path with a file-size limit.
    let _ = run_inner_on_private_tmpfs(DIR_ENV, &dir, &format!("{}k", TMPFS_BYTES >> 10), "inner_full_disk");
}

/// Records 4000 synthetic ticks into `path` with `tuning`; returns the summary.
fn record(path: &std::path::Path, tuning: RecorderTuning) -> RecordingSummary {
    let run = SyntheticRun { ticks: 4000, ..Default::default() };
    let mut cfg = RecorderConfig::new(path, run.metadata());
    cfg.chunk_size_bytes = 64 << 10;
    let mut rec = Recorder::start_with(cfg, tuning).unwrap();
    let mut accepted = 0u64;
    for k in 0..run.ticks {
        while rec.queue_free() == 0 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        accepted += rec.record_tick(&run.tick(k)) as u64;
    }
    std::thread::sleep(std::time::Duration::from_millis(100));
    assert!(rec.is_stopped(), "is_stopped() reports the stop");
    let s = rec.finish().unwrap();
    assert_eq!(accepted, run.ticks, "the loop side never noticed");
    assert_eq!(s.dropped_ticks, 0);
    assert_eq!(s.ticks_written + s.lost_after_stop, run.ticks, "{s:?}");
    s
}

/// Runs only inside the private tmpfs set up by the test above.
#[test]
#[ignore = "started by a_full_disk_mid_run_stops_the_recording_and_keeps_the_complete_chunks"]
fn inner_full_disk() {
    let dir = PathBuf::from(std::env::var(DIR_ENV).expect("started by the outer test"));
    // 1. No free-space reserve: the disk really fills. With the tail reserve (the default),
    //    fallocate meets ENOSPC between chunks; without it (0), write(2) fails with ENOSPC in
    //    the middle of a chunk and the file is cut back to its last complete chunk (the pages
    //    of the half-written chunk, freed again, hold the end). Either way the file keeps its
    //    complete chunks, ends with the stop event, summary metadata and a footer, and reads
    //    back complete, as stopped early, with exactly the ticks the writer says it kept.
    for (reserve, what) in [(None, "no room to keep 192 KiB allocated past the end of the file"), (Some(0), "write failed")] {
        let path = dir.join("full.mcap");
        let s = record(&path, RecorderTuning { min_free_bytes: 0, tail_reserve_bytes: reserve, ..Default::default() });
        assert!(s.finalised, "{s:?}");
        let why = s.stopped_early.clone().unwrap();
        assert!(why.starts_with("disk full (ENOSPC) at tick ") && why.contains(what) && why.contains("No space left on device"), "{why}");
        assert!(s.lost_after_stop > 0 && s.bytes <= TMPFS_BYTES, "{s:?}");
        let back = Recording::open_complete(&path).unwrap();
        assert_eq!(back.integrity, Integrity::StoppedEarly(why.clone()));
        assert_eq!(back.joint_state.len() as u64, s.ticks_written);
        assert!(why.contains(&format!("the file keeps the ticks up to {}", back.joint_state.last().unwrap().tick)), "{why}");
        back.check_continuity().unwrap();
        let ev: Vec<_> = back.events_of(EventKind::RecordingError).collect();
        assert_eq!(ev.len(), 1);
        assert!(why.starts_with(&ev[0].text), "{:?}", ev[0].text);
        assert_eq!(back.summary_metadata("ticks_written"), Some(s.ticks_written.to_string().as_str()));
        // The end written after the error carries the data section's CRC (the reader checked it).
        let bytes = std::fs::read(&path).unwrap();
        let data_end = &bytes[bytes.len() - 50..bytes.len() - 37];
        assert_eq!(data_end[0], 0x0f, "data-end record before footer and magic");
        assert_ne!(data_end[9..13], [0; 4], "a data section CRC, not 0");
        same_as_python(&path, &back);
        std::fs::remove_file(&path).unwrap();
    }
    // 2. The default reserve (64 MiB) on the same small disk: the first chunk close finds too
    //    little space, the writer records why and finalises a complete file.
    let path = dir.join("reserve.mcap");
    let s = record(&path, RecorderTuning::default());
    assert!(s.finalised, "{s:?}");
    assert!(s.stopped_early.clone().unwrap().contains("disk almost full"), "{s:?}");
    let back = Recording::open_complete(&path).unwrap();
    assert_eq!(back.joint_state.len() as u64, s.ticks_written);
    back.check_continuity().unwrap();
    assert_eq!(back.events_of(EventKind::RecordingError).count(), 1);
    assert_eq!(back.integrity, Integrity::StoppedEarly(s.stopped_early.clone().unwrap()));
    same_as_python(&path, &back);
}

/// The official Python reader (every CRC checked) reads the same, and calls it stopped early.
fn same_as_python(path: &Path, back: &Recording) {
    if !common::python_ready() {
        return;
    }
    let (py, text) = common::python_read(path);
    assert!(text.contains("STOPPED EARLY: the plant ended the recording on purpose"), "{text}");
    common::assert_same_as_python(back, &py);
}
