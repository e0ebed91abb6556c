//! A hard write error in the middle of a run (here EFBIG from a file-size limit, standing in for
//! ENOSPC/EIO): the writer stops with a clear reason, keeps draining so the loop never blocks,
//! and the file keeps its complete chunks. Own test binary: the limit applies to the process.

use recordings::read::Recording;
use recordings::synthetic::SyntheticRun;
use recordings::{Recorder, RecorderConfig};

#[test]
fn a_write_error_mid_run_stops_the_recording_and_keeps_the_complete_chunks() {
    let dir = std::env::temp_dir().join(format!("recordings-werr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("limited.mcap");
    let limit: u64 = 400 << 10;
    // SAFETY: plain syscalls; SIGXFSZ ignored so the write returns EFBIG instead of killing us.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        let lim = libc::rlimit { rlim_cur: limit, rlim_max: libc::RLIM_INFINITY };
        assert_eq!(libc::setrlimit(libc::RLIMIT_FSIZE, &lim), 0);
    }
    let run = SyntheticRun { ticks: 4000, ..Default::default() };
    let mut cfg = RecorderConfig::new(&path);
    cfg.chunk_size_bytes = 64 << 10;
    cfg.metadata = run.metadata();
    let mut rec = Recorder::start(cfg).unwrap();
    let mut accepted = 0u64;
    for k in 0..run.ticks {
        while rec.queue_free() == 0 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        accepted += rec.record_tick(&run.tick(k)) as u64;
    }
    let stopped = {
        std::thread::sleep(std::time::Duration::from_millis(100));
        rec.is_stopped()
    };
    let s = rec.finish().unwrap();
    assert_eq!(accepted, run.ticks, "the loop side never noticed");
    assert!(stopped, "is_stopped() reports the stop");
    assert_eq!(s.dropped_ticks, 0);
    assert!(!s.finalised);
    let why = s.stopped_early.clone().unwrap();
    assert!(why.contains("write failed") && why.to_lowercase().contains("file too large"), "{why}");
    assert_eq!(s.ticks_written + s.lost_after_stop, run.ticks, "{s:?}");
    assert!(s.bytes <= limit);

    let back = Recording::open(&path).unwrap();
    assert!(back.truncated.is_some());
    assert!(!back.joint_state.is_empty() && back.joint_state.len() as u64 <= s.ticks_written, "{}", back.joint_state.len());
    back.check_continuity().unwrap();
}
