//! End-to-end tests of the live view (issue 14): `rig run --live` on a loopback port, and a
//! Foxglove WebSocket client built from Foxglove's own npm libraries (`tests/live/live_client.mjs`:
//! `@foxglove/ws-protocol`, `@foxglove/rosmsg2-serialization`) that subscribes while the run goes
//! on. What the client received is checked against the run's own recording, read back with the
//! `mcap` crate: the advertised channels are the file's channels, the decoded joint states are the
//! recorded ones, at the requested rate.
//!
//! Needs `node` and `npm ci` in `tests/live` (`.ci/run` does it); without them the tests fail.
//! Build first: `cargo build --release --workspace --bins`. The tests run one at a time (real
//! time on a 2-core machine).

use std::collections::BTreeSet;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use harness::*;
use recording_tools::read::Recording;
use serde_json::Value;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// `tests/live`, with its npm packages installed (fails, not skips, without them).
fn live_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("live");
    let node = Command::new("node").arg("--version").output();
    assert!(node.is_ok_and(|o| o.status.success()), "node is missing: install Node 20+ (.ci/run expects it)");
    for pkg in ["@foxglove/ws-protocol", "@foxglove/rosmsg2-serialization", "@foxglove/rosmsg", "ws"] {
        assert!(dir.join("node_modules").join(pkg).is_dir(), "{pkg} is missing: run `npm ci` in {}", dir.display());
    }
    dir
}

/// A loopback port free a moment ago.
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Waits until something listens on `addr` (the plant's live view), while `rig` still runs.
fn wait_listening(addr: SocketAddr, rig: &mut Daemon) {
    let t0 = Instant::now();
    while TcpStream::connect_timeout(&addr, Duration::from_millis(100)).is_err() {
        assert!(rig.wait_timeout(Duration::ZERO).is_none(), "rig ended before the live view listened:\n{}", rig.stderr());
        assert!(t0.elapsed() < Duration::from_secs(30), "nothing listens on {addr} after 30 s:\n{}", rig.stderr());
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Runs the Node client against `addr` until it has `seconds` of /joint_state; its JSON report.
fn run_client(addr: SocketAddr, seconds: f64) -> Value {
    let out = Command::new("node")
        .current_dir(live_dir())
        .args(["live_client.mjs", &format!("ws://{addr}"), &seconds.to_string(), "40"])
        .output()
        .expect("running node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "live client failed ({}):\n{}\n{stdout}", out.status, String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("live client printed no JSON ({e}): {stdout}"))
}

/// `rig run --live ADDR` of a strip-less real-time scenario for `duration_s`, with `extra` flags.
fn start_live_run(tag: &str, duration_s: f64, extra: &[&str]) -> (String, PathBuf, SocketAddr, Daemon) {
    let rig_tag = unique_rig(tag);
    let dir = temp_dir(&rig_tag);
    // The live view is under test, not the miss safety: the scenario tolerates host stalls
    // (`harness::HOST_STALLS_TOLERATED`).
    let scenario = write_scenario(&dir, "realtime", "");
    let addr: SocketAddr = format!("127.0.0.1:{}", free_port()).parse().unwrap();
    let out = dir.join("out");
    let mut args = vec![
        "run".to_string(),
        scenario.display().to_string(),
        "--duration".into(),
        duration_s.to_string(),
        "--out".into(),
        out.display().to_string(),
        "--live".into(),
        addr.to_string(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let rig = Daemon::start("rig", &bin("rig"), &args, &dir);
    (rig_tag, out.join("run.mcap"), addr, rig)
}

/// The recording's channels as (topic, schema name, schema encoding, message encoding), read
/// with the `mcap` crate.
fn recorded_channels(path: &Path) -> BTreeSet<(String, String, String, String)> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().expect("a summary section");
    summary
        .channels
        .values()
        .map(|c| {
            let s = c.schema.as_ref().expect("every channel has a schema");
            (c.topic.clone(), s.name.clone(), s.encoding.clone(), c.message_encoding.clone())
        })
        .collect()
}

/// Messages the recording holds per topic (its summary's statistics).
fn recorded_counts(path: &Path) -> std::collections::BTreeMap<String, u64> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().expect("a summary section");
    let counts = summary.stats.expect("statistics").channel_message_counts;
    summary.channels.iter().map(|(id, c)| (c.topic.clone(), counts.get(id).copied().unwrap_or(0))).collect()
}

/// How many 10 ms slots of log time (the live view's 100 Hz grid) in `first_ns..=last_ns` hold
/// at least one recorded message on `topic`, read with the mcap crate.
fn recorded_slots(path: &Path, topic: &str, first_ns: u64, last_ns: u64) -> u64 {
    const SLOT_NS: u64 = 10_000_000;
    let bytes = std::fs::read(path).unwrap();
    let mut slots = BTreeSet::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == topic && (first_ns..=last_ns).contains(&m.log_time) {
            slots.insert(m.log_time / SLOT_NS);
        }
    }
    slots.len() as u64
}

fn advertised(report: &Value) -> BTreeSet<(String, String, String, String)> {
    let s = |c: &Value, k: &str| c[k].as_str().unwrap_or_default().to_string();
    report["advertised"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (s(c, "topic"), s(c, "schemaName"), s(c, "schemaEncoding"), s(c, "encoding")))
        .collect()
}

/// The client's decoded joint states are the recorded ones, tick for tick.
fn assert_samples_recorded(report: &Value, rec: &Recording) {
    let samples = report["samples"].as_array().unwrap();
    assert!(!samples.is_empty(), "no /joint_state samples: {report}");
    for s in samples {
        let tick = s["tick"].as_u64().unwrap();
        let row = rec.joint_state.iter().find(|j| j.tick == tick).unwrap_or_else(|| panic!("tick {tick} is not in the recording"));
        let q: Vec<f64> = s["q"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(q.len(), 6);
        for (j, (live, recorded)) in q.iter().zip(row.q.iter()).enumerate() {
            // equal up to the last digit serde_json's float parser may round (JSON text, not CDR)
            assert!(
                (live - recorded).abs() <= 4.0 * f64::EPSILON * recorded.abs().max(1e-300),
                "tick {tick} q[{j}]: live {live}, recorded {recorded}"
            );
        }
        assert!(
            (s["sim_time"].as_f64().unwrap() - row.sim_time_s).abs() <= 4.0 * f64::EPSILON * row.sim_time_s.abs(),
            "tick {tick}: sim_time"
        );
    }
}

#[test]
fn rig_run_live_serves_the_recorded_channels_at_100_hz_to_a_foxglove_client_while_the_run_goes_on() {
    let _g = serial();
    live_dir();
    let (_, recording, addr, mut rig) = start_live_run("live", 10.0, &[]);
    wait_listening(addr, &mut rig);
    let report = run_client(addr, 1.0);
    assert!(
        rig.wait_timeout(Duration::ZERO).is_none(),
        "the run ended before the client had 1 s of it; raise the duration:\n{}",
        rig.stdout()
    );
    let status = rig.expect_exit(Duration::from_secs(60));
    assert_eq!(status.code(), Some(0), "rig run:\n{}\n{}", rig.stdout(), rig.stderr());

    let rec = Recording::open_complete(&recording).expect("complete recording");
    let channels = recorded_channels(&recording);
    let recorded = recorded_counts(&recording);
    let live_dropped: u64 = rec.summary_metadata("live_dropped").expect("live_dropped").parse().unwrap();
    assert_eq!(advertised(&report), channels, "advertised channels vs the recording's");
    assert!(report["serverName"].as_str().unwrap().starts_with("rig "), "{}", report["serverName"]);
    let topics = report["topics"].as_object().unwrap();
    for (topic, ..) in &channels {
        let t = &topics[topic.as_str()];
        match topic.as_str() {
            // events whole (and their foxglove.Log copy); the URDF once a second
            "/events" | "/log" | "/robot_description" => continue,
            // a channel this run wrote nothing on (the pressure under the wheel without a strip)
            _ if recorded[topic.as_str()] == 0 => {
                assert_eq!(t["count"].as_u64(), Some(0), "{topic}: {t}");
                continue;
            }
            // only the ticks the controller sent diagnostics for: the first of each 10 ms slot
            "/controller" => {
                assert!(t["count"].as_u64().unwrap() > 0, "{topic}: {t}");
                continue;
            }
            _ => {}
        }
        // every tick recorded: 1 s at 100 Hz of 1 kHz ticks is every 10th tick (the queue or a
        // slow socket may drop some, never send more often). The rule, exactly: one message per
        // 10 ms slot of log time the recording has a message of this topic in, over the span the
        // client saw (a run that fell behind the wall clock or skipped ticks on a stalled host
        // has fewer slots in the client's second, never a gap the file does not have).
        let count = t["count"].as_u64().unwrap();
        let ns = |k: &str| t[k].as_str().unwrap().parse::<u64>().unwrap();
        let slots = recorded_slots(&recording, topic, ns("firstLogNs"), ns("lastLogNs"));
        assert!(slots >= 50, "{topic}: the client saw {slots} slots of 10 ms of the run: {t}");
        assert!(count <= slots && count + live_dropped >= slots, "{topic}: {count} received, {slots} slots, {live_dropped} dropped: {t}");
        if t["minTickStep"].is_null() {
            // Foxglove messages carry no tick: at most one per 10 ms of log time
            assert!(ns("lastLogNs") - ns("firstLogNs") >= (count - 1) * 10_000_000, "{topic}: {t}");
            continue;
        }
        assert_eq!(t["minTickStep"].as_u64(), Some(10), "{topic}: {t}");
        assert_eq!(t["maxTickStep"].as_u64().unwrap() % 10, 0, "{topic}: {t}");
    }
    assert_samples_recorded(&report, &rec);
    // what the live view sent, in the file's summary and rig's
    let sent: u64 = rec.summary_metadata("live_sent").expect("live_sent").parse().unwrap();
    let dropped: u64 = rec.summary_metadata("live_dropped").expect("live_dropped").parse().unwrap();
    let received: u64 = topics.values().map(|t| t["count"].as_u64().unwrap()).sum();
    assert!(sent >= received, "sent {sent}, the client received {received}");
    let line = format!("live view   ws://{addr}  {sent} messages sent, {dropped} dropped");
    assert!(rig.stdout().contains(&line), "no `{line}` in:\n{}", rig.stdout());
}

#[test]
fn live_rate_0_sends_every_tick() {
    let _g = serial();
    live_dir();
    let (_, recording, addr, mut rig) = start_live_run("live0", 8.0, &["--live-rate", "0"]);
    wait_listening(addr, &mut rig);
    let report = run_client(addr, 1.0);
    let status = rig.expect_exit(Duration::from_secs(60));
    assert_eq!(status.code(), Some(0), "rig run:\n{}\n{}", rig.stdout(), rig.stderr());
    let t = &report["topics"]["/joint_state"];
    assert_eq!(t["minTickStep"].as_u64(), Some(1), "{t}");
    assert_samples_recorded(&report, &Recording::open_complete(&recording).unwrap());
}

#[test]
fn a_taken_live_port_is_refused_before_anything_starts_and_by_the_plant() {
    let _g = serial();
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap();
    let rig = unique_rig("livetaken");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    // rig: one sentence naming the flag, exit 1, no output directory's recording
    let out = dir.join("out");
    let o = Command::new(bin("rig"))
        .args(["run", scenario.to_str().unwrap(), "--duration", "1", "--out", out.to_str().unwrap(), "--live", &addr.to_string()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&format!("rig: error: --live {addr}: cannot listen there: ")), "{stderr}");
    assert!(!out.join("run.mcap").exists());
    // the plant itself (a port taken after rig's check): exit 1, one sentence, no recording file
    let mcap = dir.join("plant.mcap");
    let o = Command::new(bin("plant-sim"))
        .args([
            "--rig",
            &rig,
            "--scenario",
            scenario.to_str().unwrap(),
            "--duration",
            "1",
            "--out",
            mcap.to_str().unwrap(),
            "--live",
            &addr.to_string(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&format!("live view: cannot serve on {addr}: ")), "{stderr}");
    assert!(!mcap.exists(), "a recording was created");
    drop(taken);
}

#[test]
fn live_without_a_recording_is_refused_naming_the_flag() {
    let _g = serial();
    let rig = unique_rig("livenorec");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "[recording]\nenabled = false\n");
    let o = Command::new(bin("rig"))
        .args([
            "run",
            scenario.to_str().unwrap(),
            "--duration",
            "1",
            "--out",
            dir.join("out").to_str().unwrap(),
            "--live",
            &format!("127.0.0.1:{}", free_port()),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("rig: error: --live: the live view is fed by the recorder"), "{stderr}");
}

#[test]
fn live_rate_without_live_is_refused() {
    let o = Command::new(bin("rig")).args(["run", "--live-rate", "50"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--live"), "{stderr}");
}
