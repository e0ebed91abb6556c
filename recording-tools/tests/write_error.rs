//! A hard write error in the middle of a run (here EFBIG from a file-size limit; disk_full.rs has
//! a real ENOSPC): the writer stops with a clear reason, keeps draining so the loop never blocks,
//! and cuts the file back to its last complete chunk. A size limit 100 bytes past a chunk
//! boundary leaves no room for the footer (unlike ENOSPC, where disk_full.rs shows the file ended cleanly), so the file ends there and
//! reads as cut, exactly at the chunk boundary. Own test binary: the limit applies to the process.

use recording_tools::read::{Integrity, Recording};
use recordings::synthetic::SyntheticRun;
use recordings::{Recorder, RecorderConfig};

#[test]
fn a_write_error_mid_run_stops_the_recording_and_keeps_the_complete_chunks() {
    let dir = std::env::temp_dir().join(format!("recordings-werr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("limited.mcap");
    let run = SyntheticRun { ticks: 4000, ..Default::default() };
    let config = |path: &std::path::Path| {
        let mut cfg = RecorderConfig::new(path, run.metadata());
        cfg.chunk_size_bytes = 64 << 10;
        cfg
    };
    // The limit falls 64 bytes past the start of a chunk (the last one starting before 400 KiB
    // in the same recording made without a limit): the file is cut back to where that chunk
    // starts (the one before it complete with its message indexes) and has no room for its end.
    // The writer closes chunks by size here, so both runs put the same ticks in each chunk; their
    // compressed sizes, though, depend on the log times (the wall clock at the start) by some
    // tens of bytes a chunk, so in about 1 pair of runs in 20 the limited run's chunk boundary
    // before the limit lies a whole chunk earlier. The premise (the last complete chunk of the
    // limited run ends within 256 bytes below the limit, too close for the file's end) is read
    // from the limited file itself, and both runs are made again when it does not hold.
    let end_of_chunks = |bytes: &[u8]| -> u64 {
        // where the records after the header, metadata, chunks and message indexes end
        let mut at = recordings::MCAP_MAGIC.len();
        while at + 9 <= bytes.len() && matches!(bytes[at], 0x01 | 0x06 | 0x07 | 0x09 | 0x0C) {
            let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
            if at + 9 + len > bytes.len() {
                break;
            }
            at += 9 + len;
        }
        at as u64
    };
    let set_file_size_limit = |limit: u64| {
        // SAFETY: plain syscalls; SIGXFSZ ignored so the write returns EFBIG instead of killing us.
        unsafe {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let lim = libc::rlimit { rlim_cur: limit, rlim_max: libc::RLIM_INFINITY };
            assert_eq!(libc::setrlimit(libc::RLIMIT_FSIZE, &lim), 0);
        }
    };
    let mut attempt = 0;
    let (s, limit, accepted, stopped) = loop {
        attempt += 1;
        set_file_size_limit(libc::RLIM_INFINITY);
        let dry = dir.join("unlimited.mcap");
        run.record(config(&dry)).unwrap();
        let bytes = std::fs::read(&dry).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let chunk_start = summary.chunk_indexes.iter().map(|c| c.chunk_start_offset).filter(|&e| e < 400 << 10).max().unwrap();
        let limit: u64 = chunk_start + 64;
        set_file_size_limit(limit);
        let mut rec = Recorder::start(config(&path)).unwrap();
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
        let kept = end_of_chunks(&std::fs::read(&path).unwrap());
        let premise = kept + 256 > limit && kept <= limit;
        assert!(premise || attempt < 10, "in 10 pairs of runs the limited run's last complete chunk never ended within 256 bytes below the limit: {kept} against {limit}");
        if premise {
            break (s, limit, accepted, stopped);
        }
    };
    assert_eq!(accepted, run.ticks, "the loop side never noticed");
    assert!(stopped, "is_stopped() reports the stop");
    assert_eq!(s.dropped_ticks, 0);
    assert!(!s.finalised, "{s:?}");
    let why = s.stopped_early.clone().unwrap();
    assert!(why.starts_with("file too large (EFBIG) at tick ") && why.contains("write failed"), "{why}");
    assert!(why.ends_with("no room for the footer (File too large (os error 27)): the file ends after its last complete chunk"), "{why}");
    assert_eq!(s.ticks_written + s.lost_after_stop, run.ticks, "{s:?}");
    assert!(s.bytes <= limit);

    let back = Recording::open(&path).unwrap();
    let Integrity::Cut(d) = &back.integrity else { panic!("{:?}", back.integrity) };
    assert_eq!((d.offset, d.chunk), (s.bytes, None), "the file ends exactly after a complete record: {d:?}");
    assert!(!back.joint_state.is_empty() && back.joint_state.len() as u64 == s.ticks_written, "{} {s:?}", back.joint_state.len());
    assert!(why.contains(&format!("the file keeps the ticks up to {};", back.joint_state.last().unwrap().tick)), "{why}");
    back.check_continuity().unwrap();
}
