//! The official MCAP Python reader as the reference for the project's reader: runs
//! `python/check_recording.py` (StreamReader with every CRC checked) and compares what it read
//! with a [`Recording`] tick for tick, message for message, on every channel.

#![allow(dead_code)] // each test binary uses its own part

use recording_tools::read::Recording;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// Whether python3 has `mcap` and `mcap-ros2-support`; prints `SKIP:` with the fix if not.
pub fn python_ready() -> bool {
    let ok = Command::new("python3").args(["-c", "import mcap, mcap_ros2.decoder"]).output().map(|o| o.status.success()).unwrap_or(false);
    if !ok {
        println!("SKIP: python3 with the `mcap` and `mcap-ros2-support` packages is not available (pip install mcap mcap-ros2-support)");
    }
    ok
}

/// Runs check_recording.py on `file` with `extra` flags: exit code and its output.
pub fn check(file: &Path, extra: &[&str]) -> (i32, String) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../recordings/python/check_recording.py");
    let out = Command::new("python3").arg(script).arg(file).args(extra).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), text)
}

/// What the Python reader read from `file` (check_recording.py --dump), and its output.
pub fn python_read(file: &Path) -> (Value, String) {
    // not next to the file: that may be the full disk of disk_full.rs
    let name = format!("{}-{}.python.json", file.file_stem().unwrap().to_string_lossy(), std::process::id());
    let dump = std::env::temp_dir().join(name);
    let (code, text) = check(file, &["--allow-truncated", "--allow-damaged", "--dump", dump.to_str().unwrap()]);
    assert_eq!(code, 0, "the Python check failed on {}: {text}", file.display());
    let v: Value = serde_json::from_slice(&std::fs::read(&dump).unwrap()).unwrap();
    (v, text)
}

/// Asserts that `rec` holds exactly what the Python reader read: the same kind of ending, and on
/// every channel the same messages (tick, and log time, publish wall time or text where the
/// rows keep them) in the same order. So the project's reader yields no tick Python rejects.
pub fn assert_same_as_python(rec: &Recording, py: &Value) {
    let what = rec.path.display();
    assert_eq!(rec.integrity.kind(), py["kind"].as_str().unwrap(), "{what}: kind; python says {}", py["detail"]);
    let rows =
        |topic: &str, col: usize| -> Vec<u64> { py["rows"][topic].as_array().unwrap().iter().map(|r| r[col].as_u64().unwrap()).collect() };
    let same = |topic: &str, ours: Vec<u64>, col: usize| {
        let theirs = rows(topic, col);
        assert_eq!(ours.len(), theirs.len(), "{what}: {topic} message count (column {col}), python {}", py["detail"]);
        assert!(ours == theirs, "{what}: {topic} column {col} differs from the Python reader's");
    };
    same("/joint_state", rec.joint_state.iter().map(|r| r.tick).collect(), 0);
    same("/joint_state", rec.log_time_ns.clone(), 1);
    same("/joint_torque", rec.joint_torque.iter().map(|r| r.tick).collect(), 0);
    same("/wrench", rec.wrench.iter().map(|r| r.tick).collect(), 0);
    same("/strip", rec.strip.iter().map(|r| r.tick).collect(), 0);
    same("/controller", rec.controller.iter().map(|r| r.tick).collect(), 0);
    same("/timing", rec.timing.iter().map(|r| r.tick).collect(), 0);
    same("/events", rec.events.iter().map(|r| r.tick).collect(), 0);
    same("/events", rec.events.iter().map(|r| r.wall_ns).collect(), 2);
    let wall: Vec<u64> = py["timing_publish_wall_ns"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert!(rec.timing.iter().map(|t| t.timing.publish_wall_ns).eq(wall.iter().copied()), "{what}: /timing publish_wall_ns differs");
    let texts: Vec<&str> = py["event_texts"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert!(rec.events.iter().map(|e| e.text.as_str()).eq(texts.iter().copied()), "{what}: /events texts differ");
}
