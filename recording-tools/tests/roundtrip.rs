//! Writer -> file -> reader, without daemons: every tick on every channel, truncated files,
//! foreign files, a disk running low.

use recording_tools::read::{Integrity, ReadError, Recording};
use recordings::synthetic::SyntheticRun;
use recordings::{EventKind, Recorder, RecorderConfig, RecorderTuning};
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("recordings-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn small_chunks(path: &PathBuf, run: &SyntheticRun) -> RecorderConfig {
    let mut cfg = RecorderConfig::new(path, run.metadata());
    cfg.chunk_size_bytes = 64 << 10;
    cfg
}

#[test]
fn every_tick_on_every_channel_reads_back_exactly() {
    let run = SyntheticRun::default();
    let path = tmp("full.mcap");
    let summary = run.record(small_chunks(&path, &run)).unwrap();
    assert!(summary.finalised, "{summary:?}");
    assert_eq!((summary.ticks_written, summary.events_written, summary.dropped_ticks), (run.ticks, 4, 0));
    assert_eq!(summary.bytes, std::fs::metadata(&path).unwrap().len());
    // The room kept past the end while writing (twice the chunk size) is given back.
    let allocated = std::os::unix::fs::MetadataExt::blocks(&std::fs::metadata(&path).unwrap()) * 512;
    assert!(allocated < summary.bytes + (64 << 10), "{allocated} bytes allocated for {}", summary.bytes);

    let rec = Recording::open_complete(&path).unwrap();
    assert_eq!(rec.check_continuity().unwrap(), 0..=run.ticks - 1);
    assert_eq!(rec.joint_state.len() as u64, run.ticks);
    assert_eq!(rec.controller.len() as u64, run.ticks);
    assert_eq!(rec.dropped(), 0);
    assert_eq!(rec.summary_metadata("ticks_written"), Some(run.ticks.to_string().as_str()));
    assert_eq!(rec.rig_metadata("rig"), Some("synthetic"));
    assert_eq!(rec.run_metadata().unwrap(), run.metadata(), "the run's description reads back as written");
    assert_eq!(rec.centreline_z_m(), run.centreline_z_m());
    for k in [0u64, 1, 777, run.ticks - 1] {
        let want = run.tick(k);
        let i = k as usize;
        assert_eq!(rec.joint_state[i], want.state);
        assert_eq!(rec.wrench[i], want.wrench);
        assert_eq!(rec.joint_torque[i].torque, want.torque);
        assert_eq!(rec.joint_torque[i].held, want.torque_held);
        assert_eq!(rec.controller[i], want.diag);
        assert_eq!(rec.timing[i].timing, want.timing);
        assert_eq!(rec.log_time_ns[i] - rec.start_wall_ns(), k * 1_000_000, "log time = start + simulated time in ns");
        let s = &rec.strip[i];
        assert_eq!(s.wheel_z_m, want.strip.wheel_z_m);
        assert_eq!(s.bottom_force_n, want.strip.bottom_force_n);
        let p: Vec<f32> = want.strip.centreline().iter().map(|&p| p as f32).collect();
        assert_eq!(s.centreline_pressure_pa, p);
    }
    let kinds: Vec<_> = rec.events.iter().map(|e| e.kind.unwrap()).collect();
    assert_eq!(kinds, [EventKind::Start, EventKind::SafeStop, EventKind::SafeStopCleared, EventKind::Stop]);
    assert_eq!(rec.events[1].text, "synthetic safe stop");
}

/// The lockstep level is one of zstd's negative (fast) ones, which reaches zstd through mcap's
/// u32 parameter: the file reads back whole, and the levels differ in size as zstd's do (a fast
/// level compresses less; had the -5 arrived as 2^32 - 5, zstd would have clamped it to its
/// strongest level and the file would be the smallest).
#[test]
fn a_negative_zstd_level_reaches_zstd_and_reads_back() {
    const { assert!(RecorderTuning::LOCKSTEP_COMPRESSION_LEVEL < 0) };
    let run = SyntheticRun { ticks: 3000, ..Default::default() };
    let bytes = |level: i32| {
        let path = tmp(&format!("level{level}.mcap"));
        let summary =
            run.record_with(small_chunks(&path, &run), RecorderTuning { compression_level: level, ..Default::default() }).unwrap();
        let rec = Recording::open_complete(&path).unwrap();
        assert_eq!(rec.check_continuity().unwrap(), 0..=run.ticks - 1, "level {level}");
        assert_eq!(rec.joint_state[1234], run.tick(1234).state, "level {level}");
        summary.bytes
    };
    let (fast5, lockstep, one, nineteen) = (bytes(-5), bytes(RecorderTuning::LOCKSTEP_COMPRESSION_LEVEL), bytes(1), bytes(19));
    assert!(fast5 > one && nineteen < one, "-5: {fast5} B, 1: {one} B, 19: {nineteen} B");
    assert!(lockstep > nineteen, "lockstep level: {lockstep} B, 19: {nineteen} B");
}

#[test]
fn a_cut_file_gives_its_complete_chunks_and_a_clear_error_when_strict() {
    let run = SyntheticRun { ticks: 2000, ..Default::default() };
    let path = tmp("cut-source.mcap");
    run.record(small_chunks(&path, &run)).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let full = Recording::open(&path).unwrap();
    let mut recovered = Vec::new();
    for frac in [0.02, 0.25, 0.5, 0.75, 0.97] {
        let cut = (bytes.len() as f64 * frac) as usize;
        let p = tmp(&format!("cut-{cut}.mcap"));
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let rec = Recording::open(&p).unwrap();
        let Integrity::Cut(damage) = &rec.integrity else { panic!("cut at {cut} reported as {:?}", rec.integrity) };
        assert!(damage.offset <= cut as u64 && !damage.reason.is_empty(), "{damage:?}");
        assert_eq!(damage.first_tick_lost, Some(rec.joint_state.last().map_or(0, |s| s.tick + 1)));
        if !rec.joint_state.is_empty() {
            // A prefix of the run, whole ticks only, identical to the uncut file.
            let range = rec.check_continuity().unwrap();
            assert_eq!(*range.start(), 0);
            let n = rec.joint_state.len();
            assert_eq!(rec.joint_state[..], full.joint_state[..n]);
            assert_eq!(rec.strip[n - 1], full.strip[n - 1]);
        }
        recovered.push(rec.joint_state.len());
        let err = Recording::open_complete(&p).unwrap_err();
        assert!(matches!(err, ReadError::Cut { .. }), "{err}");
        let msg = err.to_string();
        assert!(msg.contains("truncated") && msg.contains(&p.display().to_string()), "{msg}");
    }
    // Later cuts recover at least as much, and most of the run survives a cut near the end.
    assert!(recovered.windows(2).all(|w| w[0] <= w[1]), "{recovered:?}");
    assert!(recovered[3] > 0 && recovered[4] as u64 > run.ticks / 2, "{recovered:?}");
}

#[test]
fn a_non_mcap_file_is_refused_by_name() {
    let p = tmp("notes.txt");
    std::fs::write(&p, "time,force\n0,1\n").unwrap();
    let err = Recording::open(&p).unwrap_err();
    assert!(matches!(err, ReadError::NotMcap { .. }));
    let msg = err.to_string();
    assert!(msg.contains("not an MCAP recording") && msg.contains("notes.txt"), "{msg}");
    let empty = tmp("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(Recording::open(&empty), Err(ReadError::NotMcap { .. })));
    let msg = Recording::open(std::env::temp_dir()).unwrap_err().to_string();
    assert!(msg.contains("not a regular file"), "{msg}");
    let missing = tmp("does-not-exist.mcap");
    let msg = Recording::open(&missing).unwrap_err().to_string();
    assert!(msg.contains("does-not-exist.mcap"), "{msg}");
}

#[test]
fn an_mcap_file_of_someone_else_is_refused() {
    let p = tmp("foreign.mcap");
    let mut w = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&p).unwrap())).unwrap();
    let sid = w.add_schema("std_msgs/msg/String", "ros2msg", b"string data").unwrap();
    let cid = w.add_channel(sid, "/chatter", "cdr", &Default::default()).unwrap();
    let header = mcap::records::MessageHeader { channel_id: cid, sequence: 0, log_time: 0, publish_time: 0 };
    w.write_to_known_channel(&header, &[0, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0]).unwrap();
    w.finish().unwrap();
    drop(w);
    let msg = Recording::open(&p).unwrap_err().to_string();
    assert!(msg.contains("not a rig recording") && msg.contains("/joint_state"), "{msg}");
}

#[test]
fn a_disk_running_low_ends_the_recording_cleanly_and_the_loop_never_blocks() {
    let run = SyntheticRun { ticks: 1500, ..Default::default() };
    let path = tmp("low-disk.mcap");
    let cfg = small_chunks(&path, &run);
    // A reserve no disk has: the first chunk close finds the disk "full".
    let tuning = RecorderTuning { min_free_bytes: u64::MAX, ..Default::default() };
    let mut rec = Recorder::start_with(cfg, tuning).unwrap();
    let mut accepted = 0;
    for k in 0..run.ticks {
        while rec.queue_free() == 0 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        accepted += rec.record_tick(&run.tick(k)) as u64;
    }
    let summary = rec.finish().unwrap();
    assert_eq!(accepted, run.ticks, "the queue kept accepting after the stop");
    assert_eq!(summary.dropped_ticks, 0);
    let why = summary.stopped_early.clone().expect("stop reported");
    assert!(why.contains("disk almost full"), "{why}");
    assert!(summary.finalised, "a low disk still gets summary and footer");
    assert_eq!(summary.ticks_written + summary.lost_after_stop, run.ticks);
    assert!(summary.ticks_written > 0 && summary.lost_after_stop > 0, "{summary:?}");

    let back = Recording::open_complete(&path).unwrap();
    assert!(matches!(&back.integrity, Integrity::StoppedEarly(w) if *w == why), "{:?}", back.integrity);
    assert_eq!(back.joint_state.len() as u64, summary.ticks_written);
    back.check_continuity().unwrap();
    let ev: Vec<_> = back.events_of(EventKind::RecordingError).collect();
    assert_eq!(ev.len(), 1);
    assert!(ev[0].text.contains("disk almost full"), "{}", ev[0].text);
    assert_eq!(ev[0].tick, summary.ticks_written - 1);
}

#[test]
fn an_unwritable_target_is_a_clear_start_error() {
    // /dev/full answers every write with ENOSPC.
    let err = Recorder::start(RecorderConfig::new("/dev/full", recordings::synthetic::SyntheticRun::default().metadata()))
        .err()
        .expect("start must fail");
    let msg = err.to_string();
    assert!(msg.contains("/dev/full") && msg.to_lowercase().contains("no space"), "{msg}");
}

#[test]
fn commands_refuse_a_cut_file_unless_allowed_and_name_the_way_out() {
    let run = SyntheticRun { ticks: 1500, ..Default::default() };
    let path = tmp("cli-cut-source.mcap");
    run.record(small_chunks(&path, &run)).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let cut = tmp("cli-cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let err = format!("{:#}", recording_tools::cli::open_for(&cut, false).unwrap_err());
    assert!(err.contains("truncated") && err.contains("--allow-truncated") && err.contains("cli-cut.mcap"), "{err}");
    let rec = recording_tools::cli::open_for(&cut, true).unwrap();
    assert!(!rec.joint_state.is_empty());
    // `rig run` still gets numbers from a killed run, flagged as truncated.
    let n = recording_tools::cli::summary_numbers(&cut).unwrap();
    assert!(n.integrity == "cut" && n.integrity_detail.is_some() && n.ticks == rec.joint_state.len(), "{n:?}");
    let junk = tmp("cli-junk.mcap");
    std::fs::write(&junk, b"PK\x03\x04 a zip file").unwrap();
    let err = format!("{:#}", recording_tools::cli::summary_numbers(&junk).unwrap_err());
    assert!(err.contains("not an MCAP recording"), "{err}");
}

#[test]
fn the_controllers_own_answer_is_recorded_beside_the_applied_torque() {
    let run = SyntheticRun { ticks: 200, ..Default::default() };
    let path = tmp("commanded.mcap");
    let mut rec = Recorder::start(small_chunks(&path, &run)).unwrap();
    for k in 0..run.ticks {
        let r = run.tick(k);
        let mut answer = r.torque;
        answer.tau[2] += 1.0; // e.g. a blended-in tick: the answer differs from what was applied
        let cmd = (k % 3 != 0).then_some(&answer);
        assert!(rec.record_tick_commanded(&r, cmd));
    }
    rec.finish().unwrap();
    let back = Recording::open_complete(&path).unwrap();
    for (k, row) in back.joint_torque.iter().enumerate() {
        let applied = run.tick(k as u64).torque.tau;
        assert_eq!(row.torque.tau, applied);
        let want = (k % 3 != 0).then(|| {
            let mut a = applied;
            a[2] += 1.0;
            a
        });
        assert_eq!(row.commanded, want, "tick {k}");
    }
}

/// A plant's centre line from its strip state, as a test writes it: the state is the tick
/// number and then the pressures halved; the centre line is the pressures (twice the state) and,
/// with the top line, the tick number at every node. It notes which ticks it drew a top line for.
#[derive(Debug, Default)]
struct DoubleTheState {
    top_line_ticks: std::sync::Mutex<Vec<u64>>,
}

impl recordings::CentreLineFromState for DoubleTheState {
    fn expand(&self, state: &[f64], top_line: bool, r: &mut recordings::StripRecord) {
        let n = r.n_centreline as usize;
        let mut max = f64::NEG_INFINITY;
        for i in 0..n {
            r.centreline_pressure_pa[i] = 2.0 * state[1 + i];
            max = max.max(r.centreline_pressure_pa[i]);
        }
        r.max_bottom_pressure_pa = max;
        r.top_centreline_uy_m[..n].fill(if top_line { state[0] } else { 0.0 });
        if top_line {
            self.top_line_ticks.lock().unwrap().push(state[0] as u64);
        }
    }
}

/// Records whose centre line the loop left to the writer (`StripRecord::modal_len`): the writer
/// fills it in with the plant's `CentreLineFromState` (pressures, maximum; the top line only on
/// the scene's ticks, every 10th at 100 Hz), and reads back as the loop's own would have; a
/// writer without the means records them as not computed (NaN), never as zeros.
#[test]
fn the_writer_fills_in_the_centre_line_the_loop_left_to_it() {
    let run = SyntheticRun { ticks: 300, ..Default::default() };
    let modal = |k: u64| {
        let mut r = run.tick(k);
        let n = r.strip.n_centreline as usize;
        r.strip.modal_state[0] = k as f64;
        for i in 0..n {
            r.strip.modal_state[1 + i] = r.strip.centreline_pressure_pa[i] / 2.0;
        }
        r.strip.modal_len = 1 + n as u32;
        r.strip.centreline_pressure_pa = [0.0; recordings::MAX_CENTRELINE];
        r.strip.max_bottom_pressure_pa = f64::NAN;
        r
    };
    let from_state = std::sync::Arc::new(DoubleTheState::default());
    let path = tmp("centre-line-from-state.mcap");
    let mut cfg = small_chunks(&path, &run);
    cfg.centre_line = Some(from_state.clone());
    cfg.scene = Some(recordings::scene::SceneConfig {
        rate_hz: 100.0,
        tool: Default::default(),
        task_in_base: nalgebra::Isometry3::identity(),
        strip: None,
        path: None,
        band_base: Vec::new(),
    });
    let mut rec = Recorder::start(cfg).unwrap();
    assert!(rec.expands_centre_line());
    for k in 0..run.ticks {
        assert!(rec.record_tick(&modal(k)));
    }
    rec.finish().unwrap();
    let back = Recording::open_complete(&path).unwrap();
    assert_eq!(back.strip.len() as u64, run.ticks);
    for (k, row) in back.strip.iter().enumerate() {
        let want = run.tick(k as u64).strip;
        let n = want.n_centreline as usize;
        let p: Vec<f32> = want.centreline_pressure_pa[..n].iter().map(|&p| p as f32).collect();
        assert_eq!(row.centreline_pressure_pa, p, "tick {k}");
        assert_eq!(row.max_bottom_pressure_pa, want.max_bottom_pressure_pa, "tick {k}");
        assert_eq!(row.wheel_z_m, want.wheel_z_m, "tick {k}");
    }
    let drawn = from_state.top_line_ticks.lock().unwrap().clone();
    assert_eq!(drawn, (0..run.ticks).step_by(10).collect::<Vec<_>>(), "top lines only on the scene's ticks");

    // No means to compute it: NaN pressures and maximum, the rest as recorded.
    let path = tmp("centre-line-no-means.mcap");
    let mut rec = Recorder::start(small_chunks(&path, &run)).unwrap();
    assert!(!rec.expands_centre_line());
    for k in 0..20 {
        assert!(rec.record_tick(&modal(k)));
    }
    rec.finish().unwrap();
    let back = Recording::open_complete(&path).unwrap();
    assert_eq!(back.strip.len(), 20);
    for (k, row) in back.strip.iter().enumerate() {
        assert!(row.max_bottom_pressure_pa.is_nan() && row.centreline_pressure_pa.iter().all(|p| p.is_nan()), "tick {k}");
        assert_eq!(row.wheel_z_m, run.tick(k as u64).strip.wheel_z_m);
    }
}
