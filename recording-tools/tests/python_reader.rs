//! The official MCAP Python readers (`mcap` + `mcap-ros2-support`, every CRC checked) against the
//! project's reader: every channel of a complete recording decodes and every tick is found, and
//! damaged copies of it (one byte flipped in chunk 3, cuts at 5, 33, 50 and 90 %) read the same
//! ticks and messages in both, with the same kind of damage. Skips with a clear line when the
//! packages are not installed (CI installs them: `pip install mcap mcap-ros2-support`).

mod common;

use common::{assert_same_as_python, check, python_read, python_ready};
use recording_tools::read::{Integrity, ReadError, Recording};
use recordings::synthetic::SyntheticRun;
use recordings::RecorderConfig;
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("recordings-py-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A complete lockstep recording by the project's writer (a synthetic run, 64 KiB chunks).
fn complete_recording(name: &str, ticks: u64) -> (PathBuf, Vec<u8>) {
    let run = SyntheticRun { ticks, ..Default::default() };
    let path = tmp(name);
    let mut cfg = RecorderConfig::new(&path, run.metadata());
    cfg.chunk_size_bytes = 64 << 10;
    assert!(run.record(cfg).unwrap().finalised);
    let bytes = std::fs::read(&path).unwrap();
    (path, bytes)
}

#[test]
fn python_reads_every_tick_of_a_complete_and_of_a_cut_file() {
    if !python_ready() {
        return;
    }
    let (path, bytes) = complete_recording("py.mcap", 2500);
    let (code, text) = check(&path, &["--expect-ticks", "2500"]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("OK: 2500 ticks (0..2499)") && text.contains("dropped 0"), "{text}");
    let (py, _) = python_read(&path);
    assert_same_as_python(&Recording::open_complete(&path).unwrap(), &py);

    // A file cut like a SIGKILL leaves it: the complete chunks decode, the cut is reported.
    let cut = tmp("py-cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let (code, text) = check(&cut, &[]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("TRUNCATED"), "{text}");
    let (code, text) = check(&cut, &["--allow-truncated"]);
    assert_eq!(code, 0, "{text}");
    let rust = Recording::open(&cut).unwrap();
    let want = format!("OK: {} ticks", rust.joint_state.len());
    assert!(rust.joint_state.len() > 1000 && text.contains(&want), "rust read {} ticks; python: {text}", rust.joint_state.len());

    let junk = tmp("junk.mcap");
    std::fs::write(&junk, b"this is not a recording").unwrap();
    let (code, text) = check(&junk, &[]);
    assert_eq!(code, 3, "{text}");
    assert!(text.contains("not an MCAP file"), "{text}");
}

#[test]
fn a_flipped_byte_in_chunk_3_stops_both_readers_at_the_same_tick_and_is_called_corrupt() {
    if !python_ready() {
        return;
    }
    let (path, mut bytes) = complete_recording("flip-source.mcap", 3000);
    let full = Recording::open_complete(&path).unwrap();
    // Where chunk 3 is, from the file's own chunk index (the mcap crate's summary reader).
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a complete file has a summary");
    let mut chunks = summary.chunk_indexes.clone();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    assert!(chunks.len() >= 8, "{} chunks: too few to damage the middle", chunks.len());
    let c3 = &chunks[3];
    let data_end = c3.chunk_start_offset + c3.chunk_length;
    let flip = (data_end - c3.compressed_size / 2) as usize;
    bytes[flip] ^= 0x20;
    let bad = tmp("flipped.mcap");
    std::fs::write(&bad, &bytes).unwrap();

    let (code, text) = check(&bad, &[]);
    assert_eq!(code, 4, "{text}");
    assert!(text.contains("CORRUPT") && !text.contains("TRUNCATED"), "{text}");
    let (py, _) = python_read(&bad);
    assert_eq!(py["chunks_read"], 3, "python read chunks 0..=2 only: {}", py["detail"]);

    let rec = Recording::open(&bad).unwrap();
    assert_same_as_python(&rec, &py);
    let Integrity::Corrupt(d) = &rec.integrity else { panic!("{:?}", rec.integrity) };
    let n = rec.joint_state.len();
    assert!(n > 0 && n < full.joint_state.len());
    assert_eq!((d.chunk, d.offset, d.first_tick_lost), (Some(3), c3.chunk_start_offset, Some(n as u64)), "{d:?}");
    assert_eq!(rec.joint_state[..], full.joint_state[..n], "the ticks before the bad chunk are the original ones");
    // The first tick lost is chunk 3's first: its log time opens that chunk.
    assert_eq!(full.log_time_ns[n], c3.message_start_time);
    let err = Recording::open_complete(&bad).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ReadError::Corrupt { .. }), "{msg}");
    for needle in ["is corrupt", "flipped.mcap", "chunk 3 at byte", "fails its CRC", &format!("first tick lost is {n}")] {
        assert!(msg.contains(needle) || (needle == "fails its CRC" && msg.contains("does not decompress")), "{needle:?} missing: {msg}");
    }
    assert!(!msg.contains("truncated") && !msg.contains("killed"), "a complete file is not truncated: {msg}");
    let numbers = recording_tools::report::numbers(&rec);
    let report = recording_tools::report::format_text(&numbers);
    assert!(report.contains("corrupt (damaged after it was written)") && !report.contains("truncated"), "{report}");
    let json = serde_json::to_value(&numbers).unwrap();
    assert_eq!((json["integrity"].as_str(), json["damage"]["chunk"].as_u64()), (Some("corrupt"), Some(3)), "{json}");
    assert_eq!(json["damage"]["first_tick_lost"].as_u64(), Some(n as u64));
    let err = format!("{:#}", recording_tools::cli::open_for(&bad, false).unwrap_err());
    assert!(err.contains("--allow-damaged") && !err.contains("truncated"), "{err}");
}

#[test]
fn cuts_at_5_33_50_and_90_percent_read_the_same_ticks_as_python_and_are_called_cut() {
    if !python_ready() {
        return;
    }
    let (path, bytes) = complete_recording("cut-source.mcap", 3000);
    let full = Recording::open_complete(&path).unwrap();
    let mut read = Vec::new();
    for pct in [5, 33, 50, 90] {
        let len = bytes.len() * pct / 100;
        let cut = tmp(&format!("cut-{pct}.mcap"));
        std::fs::write(&cut, &bytes[..len]).unwrap();
        let (py, _) = python_read(&cut);
        let rec = Recording::open(&cut).unwrap();
        assert_same_as_python(&rec, &py);
        let Integrity::Cut(d) = &rec.integrity else { panic!("{pct} %: {:?}", rec.integrity) };
        assert!(d.offset <= len as u64, "{pct} %: {d:?}");
        let n = rec.joint_state.len();
        assert_eq!(rec.joint_state[..], full.joint_state[..n], "{pct} %");
        let (code, text) = check(&cut, &[]);
        assert_eq!(code, 2, "{pct} %: {text}");
        read.push(n);
    }
    // Longer prefixes keep more, and the 90 % cut keeps most of the run.
    assert!(read.windows(2).all(|w| w[0] <= w[1]) && read[3] > 2000, "{read:?}");
}
