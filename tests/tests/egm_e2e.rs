//! End-to-end over EGM: the real `plant-sim` as an ABB robot controller (`[egm] enabled`) and a
//! real third-party EGM client, `abb-robot-client`'s `abb_robot_client.egm.EGM` (Python, unchanged;
//! `tests/python/egm_client.py` drives it), over UDP on a port of each test's own. Build first:
//! `cargo build --release --workspace --bins`; needs `pip install abb-robot-client` (the tests
//! fail without it; `.ci/deps` installs it).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;
use robot::Vec6;

/// One Python EGM pair at a time (two lockstep pairs would slow each other on a 2-CPU host).
static SERIAL: Mutex<()> = Mutex::new(());

fn client_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("python/egm_client.py")
}

struct EgmRun {
    rig: TestRig,
    plant: Daemon,
    client_log: PathBuf,
    client: Daemon,
}

/// A lockstep EGM plant (robot only) and the Python client in `mode`; None without the package.
fn egm_run(test: &str, tag: &str, mode: &str, duration_s: f64, egm_extra: &str) -> Option<EgmRun> {
    if !python_has(test, "abb_robot_client.egm, numpy", "abb-robot-client numpy") {
        return None;
    }
    let mut rig = TestRig::new(tag, "lockstep");
    let port = free_port();
    rig.scenario =
        write_scenario(&rig.dir, "lockstep", &format!("[egm]\nenabled = true\nsensor_address = \"127.0.0.1:{port}\"\n{egm_extra}"));
    let client_log = rig.dir.join("client.json");
    let port_s = port.to_string();
    let mut client = Daemon::start(
        "egm-client",
        Path::new("python3"),
        &[client_script().to_str().unwrap(), &port_s, client_log.to_str().unwrap(), mode],
        &rig.dir,
    );
    wait_bound(port, &mut client);
    let plant = rig.plant(duration_s);
    Some(EgmRun { rig, plant, client_log, client })
}

impl EgmRun {
    /// Wait for both to end; the plant's summary, its recording and the client's log.
    fn finish(mut self) -> (TestRig, serde_json::Value, Recording, Vec<serde_json::Value>) {
        assert!(self.plant.expect_exit(Duration::from_secs(60)).success(), "plant: {}", self.plant.stderr());
        assert!(self.client.expect_exit(Duration::from_secs(20)).success(), "EGM client: {}", self.client.stderr());
        let summary = plant_summary(&self.plant);
        let rec = Recording::open_complete(self.rig.recording()).expect("complete recording");
        let egm = rec.run_metadata().expect("the run's description").egm.expect("an EGM run's metadata says so");
        assert!(egm.servo_lag_s > 0.0, "{egm:?}");
        let log: Vec<serde_json::Value> = serde_json::from_str(&std::fs::read_to_string(&self.client_log).unwrap()).unwrap();
        (self.rig, summary, rec, log)
    }
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

#[test]
fn abb_robot_client_reads_the_rigs_joints_holds_then_steps_axis_6_with_the_documented_lag() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(run) = egm_run("abb_robot_client_steps_axis_6", "egm-step", "step", 0.5, "") else { return };
    let (rig, summary, rec, log) = run.finish();
    assert_eq!(summary["ticks"], 500, "{summary}");
    assert_eq!(summary["refusals"], 0, "{summary}");
    assert_eq!(summary["safe_stops"], 0, "{summary}");
    assert_eq!(summary["egm"]["accepted"], 125, "{summary}");
    assert_eq!(log.len(), 126, "one EgmRobot per 4 ms cycle and the MCI_STOPPED of the run's end");
    assert_eq!(log[125]["mci"], 2, "MCI_STOPPED at the end");
    let log = &log[..125];
    rec.check_continuity().unwrap();
    assert_eq!(rec.events_of(EventKind::EgmSession).count(), 1, "{:?}", rec.events);
    // /egm: one row per cycle with the reference the client sent (its seqno stepping by 2)
    assert_eq!(rec.egm.len(), 125);
    for (c, e) in rec.egm.iter().zip(log.iter()) {
        assert_eq!(c.tick, e["tm"].as_u64().unwrap());
        assert_eq!((c.replies, c.accepted, c.session_state), (1, 1, 1), "tick {}", c.tick);
        assert_eq!(c.sensor_seqno, 2 * (c.tick as u32 / 4) + 1, "tick {}", c.tick);
        // (serde_json parses to within an ulp of Python's repr)
        let sent = floats(&e["sent"]);
        assert!((0..6).all(|i| (c.joints_ref_deg[i] - sent[i]).abs() < 1e-12), "tick {}: {:?} vs {sent:?}", c.tick, c.joints_ref_deg);
        assert!((c.servo_lag_s - 0.012).abs() < 1e-12);
    }

    // What the client reads is the rig's state in ABB's convention: joints against the recorded
    // q of the same tick, the TCP position against forward kinematics of it.
    let s = scenarios::Scenario::load(&rig.scenario).unwrap();
    let model = plant_sim::physics::plant_robot(&s);
    for e in log {
        let tick = e["tm"].as_u64().unwrap();
        let q = rec.joint_state.iter().find(|j| j.tick == tick).expect("the tick of the message").q;
        let abb = egm::axes::abb_deg_from_dh(&q);
        let joints = floats(&e["joints"]);
        for i in 0..6 {
            assert!((joints[i] - abb[i]).abs() < 1e-9, "tick {tick} axis {}: client {} deg, rig {} deg", i + 1, joints[i], abb[i]);
        }
        let p = model.tcp_pose(&Vec6::from(q)).translation.vector * 1e3;
        let pos = floats(&e["pos_mm"]);
        assert!((p.x - pos[0]).abs() < 1e-9 && (p.y - pos[1]).abs() < 1e-9 && (p.z - pos[2]).abs() < 1e-9, "tick {tick}: {pos:?} vs {p:?}");
        assert_eq!(e["mci"], 3, "MCI_RUNNING");
        assert_eq!(e["motors_on"], true);
    }
    // Hold: echoing the planned joints keeps the arm where it started.
    let j0 = floats(&log[0]["joints"]);
    for e in &log[..=50] {
        let j = floats(&e["joints"]);
        assert!((0..6).all(|i| (j[i] - j0[i]).abs() < 1e-6), "hold drifts at tm {}: {j:?}", e["tm"]);
    }
    // The step: +1 degree on axis 6 sent in answer to the message of tm = 200 ms. The joint
    // reaches 63.2 % of it after the servo's lag (emulated motion controller, plant-sim
    // README "EGM"): within half a tick of it (the torque is held over a tick).
    let t_cmd = log[50]["tm"].as_f64().unwrap();
    let lag = plant_sim::driver::egm::servo::ServoParams::from_scenario(&s).lag_s() * 1e3;
    assert!((lag - 12.0).abs() < 1e-9, "default lag {lag} ms");
    let a6: Vec<(f64, f64)> = log.iter().map(|e| (e["tm"].as_f64().unwrap(), floats(&e["joints"])[5] - j0[5])).collect();
    let k = a6.iter().position(|&(_, x)| x >= 1.0 - (-1.0f64).exp()).expect("axis 6 reaches 63 % of the step");
    // exponential interpolation between the samples around the crossing
    let ((t0, x0), (t1, x1)) = (a6[k - 1], a6[k]);
    let (l0, l1) = ((1.0 - x0).ln(), (1.0 - x1).ln());
    let t63 = t0 + (t1 - t0) * (-1.0 - l0) / (l1 - l0);
    let measured = t63 - t_cmd;
    println!("EGM step on axis 6: 63 % after {measured:.3} ms (servo lag {lag:.3} ms)");
    assert!((measured - lag).abs() < 0.5, "63 % after {measured:.3} ms, the servo's lag is {lag:.3} ms");
    let last = a6.last().unwrap().1;
    assert!((last - 1.0).abs() < 1e-3, "axis 6 settles at +1 degree: {last}");
}

fn events_text(rec: &Recording, kind: EventKind) -> Vec<String> {
    rec.events_of(kind).map(|e| e.text.clone()).collect()
}

#[test]
fn a_silent_sensor_ends_the_egm_session_after_comm_timeout_and_the_robot_holds() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(run) = egm_run("egm_comm_timeout", "egm-timeout", "silent", 0.5, "comm_timeout_s = 0.2\n") else { return };
    let (_rig, summary, rec, log) = run.finish();
    assert_eq!(summary["ticks"], 500, "the run goes on to its end: {summary}");
    assert_eq!(summary["safe_stops"], 1, "{summary}");
    let ended = summary["egm"]["session_ended_tick"].as_u64().expect("session ended");
    // 50 answers (cycles 0..49), then silence: the reply to cycle 50 (tick 200) never comes
    assert_eq!(ended, 200, "{summary}");
    let texts = events_text(&rec, EventKind::EgmSession);
    assert_eq!(texts.len(), 2, "started and ended: {texts:?}");
    assert!(texts[1].contains("tick 200: EGM session ended: no valid sensor message for 0.2 s (egm.comm_timeout_s)"), "{texts:?}");
    // the last message the client got says MCI_STOPPED, and none came after it
    assert_eq!(log.last().unwrap()["mci"], 2, "MCI_STOPPED");
    assert_eq!(log.len(), 52);
    // the robot holds: still at the end
    let qd = rec.joint_state.last().unwrap().qd;
    assert!(qd.iter().all(|v| v.abs() < 1e-9), "{qd:?}");
    assert_eq!(rec.joint_state.last().unwrap().plant_status, messages::PlantStatus::SafeStop as u32);
}

#[test]
fn a_repeated_sequence_number_is_refused_with_an_event() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(run) = egm_run("egm_wrong_sequence", "egm-seq", "repeat_seq", 0.3, "") else { return };
    let (_rig, summary, rec, _log) = run.finish();
    assert_eq!(summary["refusals"], 1, "{summary}");
    assert_eq!(summary["safe_stops"], 0, "{summary}");
    let texts = events_text(&rec, EventKind::EgmRefused);
    // abb-robot-client numbers its messages 1, 3, 5, ...: message 51 carries 101, the repeat 99
    assert_eq!(
        texts,
        vec!["tick 200: EGM sensor message refused: wrong sequence: seqno 99 after 99 (must increase)".to_string()],
        "{:?}",
        rec.events
    );
}

/// Runs the client in `mode` (a bad message at its 50th cycle, tick 200): the plant refuses exactly
/// one message, with one `/events` entry starting `expected`, and the arm does not move. Returns
/// the client's log (None without the Python package).
fn refused_once_and_the_arm_stays(test: &str, tag: &str, mode: &str, expected: &str) -> Option<Vec<serde_json::Value>> {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let run = egm_run(test, tag, mode, 0.3, "")?;
    let (_rig, summary, rec, log) = run.finish();
    assert_eq!(summary["refusals"], 1, "{summary}");
    let texts = events_text(&rec, EventKind::EgmRefused);
    assert_eq!(texts.len(), 1, "{:?}", rec.events);
    assert!(texts[0].starts_with(expected), "{texts:?}");
    let q0 = rec.joint_state[0].q;
    let drift = rec.joint_state.iter().map(|s| (Vec6::from(s.q) - Vec6::from(q0)).amax()).fold(0.0, f64::max);
    assert!(drift < 1e-6, "the refused reference moved the arm by {drift} rad");
    Some(log)
}

#[test]
fn an_out_of_range_reference_is_refused_with_an_event_and_the_arm_stays() {
    let expected = "tick 200: EGM sensor message refused: axis 3 reference 70.000 deg beyond its range -60 .. 65 deg";
    refused_once_and_the_arm_stays("egm_out_of_limit", "egm-limit", "out_of_limit", expected);
}

#[test]
fn a_reference_faster_than_the_axis_is_refused_with_an_event_and_the_arm_stays() {
    // 3 degrees in one 4 ms cycle is 750 deg/s; IRB 2400's axis 6 makes 450 deg/s.
    let expected = "tick 200: EGM sensor message refused: axis 6 reference needs 750.0 deg/s within one cycle, the axis speed is 450 deg/s";
    let Some(log) = refused_once_and_the_arm_stays("egm_too_fast", "egm-fast", "too_fast", expected) else { return };
    // The client went back to holding after the refused step, and those messages were taken.
    assert!(log.len() > 60, "{} cycles", log.len());
}

/// [`physics_digest`] of the EGM thesis run in lockstep.
const EGM_THESIS_DIGEST: &str = "3ae44cd5689b1748 (3600 states, 3600 wrenches, 3600 torques, 3600 strip records)";

/// The thesis run over EGM in lockstep: `egm-controller` bound first, then the plant.
fn egm_thesis_run(tag: &str) -> (PathBuf, Recording) {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let port = free_port();
    let sc = egm_scenario_on(&dir, port);
    let mut ctrl = Daemon::start("egm-controller", &bin("egm-controller"), &["--scenario", sc.to_str().unwrap()], &dir);
    wait_bound(port, &mut ctrl);
    let out = dir.join("run.mcap");
    let mut plant = Daemon::start(
        "plant",
        &bin("plant-sim"),
        &["--rig", &rig, "--scenario", sc.to_str().unwrap(), "--mode", "lockstep", "--out", out.to_str().unwrap()],
        &dir,
    );
    // The first run may build and cache the strip model.
    assert!(plant.expect_exit(Duration::from_secs(300)).success(), "plant: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "egm-controller: {}", ctrl.stderr());
    let summary = plant_summary(&plant);
    assert_eq!(summary["safe_stops"], 0, "{summary}");
    assert_eq!(summary["refusals"], 0, "{summary}");
    assert_eq!(summary["drops"], 0, "{summary}");
    (sc, Recording::open_complete(&out).expect("complete recording"))
}

#[test]
fn egm_thesis_run_in_lockstep_is_bit_identical_and_within_the_designs_bound() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (sc, a) = egm_thesis_run("egm-thesis-a");
    let (_, b) = egm_thesis_run("egm-thesis-b");
    // Pinned before the EGM driver moved onto the plant's one tick core (issue 28; main at
    // 5c9378a gave this digest): the refactor changed nothing, bit for bit.
    let digest = physics_digest(&a);
    assert_eq!(digest, physics_digest(&b));
    assert_eq!(digest, EGM_THESIS_DIGEST, "the EGM thesis run's physics changed");
    assert_eq!(a.joint_state.len(), b.joint_state.len());
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for k in 0..a.joint_state.len() {
        let (sa, sb) = (&a.joint_state[k], &b.joint_state[k]);
        assert_eq!(sa.tick, sb.tick);
        assert_eq!(bits(&sa.q), bits(&sb.q), "q differs at row {k}");
        assert_eq!(bits(&sa.qd), bits(&sb.qd), "qd differs at row {k}");
        assert_eq!(bits(&a.joint_torque[k].torque.tau), bits(&b.joint_torque[k].torque.tau), "torque differs at row {k}");
        assert_eq!(bits(&a.wrench[k].force), bits(&b.wrench[k].force), "wrench differs at row {k}");
        assert_eq!(a.strip[k].bottom_force_n.to_bits(), b.strip[k].bottom_force_n.to_bits(), "bottom force differs at row {k}");
    }
    let s = scenarios::Scenario::load(&sc).unwrap();
    let roll = recording_tools::report::numbers(&a).rolling.expect("the wheel rolled");
    let (max, rms) = (roll.force_error_max_abs_n.unwrap(), roll.force_error_rms_n.unwrap());
    assert!(roll.rolled_length_m > 0.0359, "rolled {} m", roll.rolled_length_m);
    let model = strip::StripModel::load_or_build(&plant_sim::contact::strip_params(&s)).unwrap();
    let d = design::egm::design_egm(&s, &model, 0.020);
    println!(
        "EGM thesis run (lockstep): force error max {max:.3} N, RMS {rms:.3} N, bond {:.1} % of the rolled length; design bound {:.3} N, margins {:?}",
        100.0 * roll.bond_pressure_share.unwrap_or(0.0),
        d.force_error_bound_n,
        d.margins
    );
    assert!(max <= d.force_error_bound_n, "max force error {max:.3} N beyond the design's bound {:.3} N", d.force_error_bound_n);
    let m = d.margins.expect("the loop crosses over");
    assert!(m.phase_margin_deg > 45.0, "{m:?}");
}

#[test]
fn rig_run_with_controller_none_waits_for_an_external_egm_client() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    if !python_has("rig_run_controller_none", "abb_robot_client.egm, numpy", "abb-robot-client numpy") {
        return;
    }
    let t = TestRig::new("egm-none", "lockstep");
    let port = free_port();
    let sc = write_scenario(&t.dir, "lockstep", &format!("[egm]\nenabled = true\nsensor_address = \"127.0.0.1:{port}\"\n"));
    let log = t.dir.join("client.json");
    let mut client = Daemon::start(
        "egm-client",
        Path::new("python3"),
        &[client_script().to_str().unwrap(), &port.to_string(), log.to_str().unwrap(), "step"],
        &t.dir,
    );
    wait_bound(port, &mut client);
    let out = t.dir.join("out");
    let mut rig = Daemon::start(
        "rig",
        &bin("rig"),
        &["run", sc.to_str().unwrap(), "--controller", "none", "--duration", "0.3", "--out", out.to_str().unwrap()],
        &t.dir,
    );
    let st = rig.expect_exit(Duration::from_secs(60));
    assert_eq!(st.code(), Some(0), "rig run: {}\n{}", rig.stdout(), rig.stderr());
    assert!(client.expect_exit(Duration::from_secs(20)).success(), "{}", client.stderr());
    let rec = Recording::open_complete(out.join("run.mcap")).unwrap();
    assert_eq!(rec.joint_state.len(), 300);
    assert_eq!(rec.events_of(EventKind::EgmSession).count(), 1, "{:?}", rec.events);
    let answered: Vec<serde_json::Value> = serde_json::from_str(&std::fs::read_to_string(&log).unwrap()).unwrap();
    assert_eq!(answered.len(), 76, "75 cycles and the end's MCI_STOPPED");
    // no controller of the rig ran: `--controller none` with a torque scenario is refused
    let plain = write_scenario(&t.dir, "lockstep", "");
    let mut refused = Daemon::start("rig-refused", &bin("rig"), &["run", plain.to_str().unwrap(), "--controller", "none"], &t.dir);
    let st = refused.expect_exit(Duration::from_secs(20));
    assert_ne!(st.code(), Some(0));
    assert!(refused.stderr().contains("--controller none needs a scenario with [egm] enabled"), "{}", refused.stderr());
}
