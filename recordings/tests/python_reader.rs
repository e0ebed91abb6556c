//! The official MCAP Python readers (`mcap` + `mcap-ros2-support`) decode every channel of a
//! recording and find every tick. Skips with a clear line when the packages are not installed
//! (CI installs them: `pip install mcap mcap-ros2-support`).

use recordings::synthetic::SyntheticRun;
use recordings::RecorderConfig;
use std::path::{Path, PathBuf};
use std::process::Command;

fn python_ready() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import mcap, mcap_ros2.decoder"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        println!("SKIP: python3 with the `mcap` and `mcap-ros2-support` packages is not available (pip install mcap mcap-ros2-support)");
    }
    ok
}

fn check(file: &Path, extra: &[&str]) -> (i32, String) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/check_recording.py");
    let out = Command::new("python3").arg(script).arg(file).args(extra).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), text)
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("recordings-py-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn python_reads_every_tick_of_a_complete_and_of_a_cut_file() {
    if !python_ready() {
        return;
    }
    let run = SyntheticRun { ticks: 2500, ..Default::default() };
    let path = tmp("py.mcap");
    let mut cfg = RecorderConfig::new(&path);
    cfg.chunk_size_bytes = 128 << 10;
    cfg.metadata = run.metadata();
    run.record(cfg).unwrap();

    let (code, text) = check(&path, &["--expect-ticks", &run.ticks.to_string()]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("OK: 2500 ticks (0..2499)") && text.contains("dropped 0"), "{text}");

    // A file cut like a SIGKILL leaves it: the complete chunks decode, the cut is reported.
    let bytes = std::fs::read(&path).unwrap();
    let cut = tmp("py-cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let (code, text) = check(&cut, &[]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("TRUNCATED"), "{text}");
    let (code, text) = check(&cut, &["--allow-truncated"]);
    assert_eq!(code, 0, "{text}");
    let rust = recordings::read::Recording::open(&cut).unwrap();
    let want = format!("OK: {} ticks", rust.joint_state.len());
    assert!(rust.joint_state.len() > 1000 && text.contains(&want), "rust read {} ticks; python: {text}", rust.joint_state.len());

    let junk = tmp("junk.mcap");
    std::fs::write(&junk, b"this is not a recording").unwrap();
    let (code, text) = check(&junk, &[]);
    assert_eq!(code, 3, "{text}");
    assert!(text.contains("not an MCAP file"), "{text}");
}
