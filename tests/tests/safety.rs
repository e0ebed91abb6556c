//! End-to-end tests of issue 11 (DESIGN section 10, safety and faults) with the real daemons:
//! reflexes, end stops, one controller at a time, strangers on the torque service, `rig run`'s
//! exit status and a dead controller under `rig run`. Build first:
//! `cargo build --release --workspace --bins`.
//!
//! The misbehaving controller is `fault-controller` (tests/src/bin/fault_controller.rs). `rig run
//! --controller` takes a path without arguments, so its faults are given through a wrapper script
//! (`exec fault-controller FAULTS "$@"`).
//!
//! The tests run one at a time (a process-wide lock): real-time runs on a 2-core machine must not
//! compete with each other.

use std::path::{Path, PathBuf};
use std::process::ExitStatus;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use harness::*;
use messages::{state_flags, PlantStatus};
use recording_tools::read::Recording;
use recordings::EventKind;
use robot::params::{POSITION_LIMIT_RAD, TORQUE_LIMIT_NM, VELOCITY_LIMIT_RADPS};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const LONG: Duration = Duration::from_secs(120);

fn events(rec: &Recording, kind: EventKind) -> Vec<(u64, String)> {
    rec.events.iter().filter(|e| e.kind == Some(kind)).map(|e| (e.tick, e.text.clone())).collect()
}

/// A script that runs `fault-controller` with `faults` and the arguments `rig` passes.
fn fault_wrapper(dir: &Path, name: &str, faults: &[&str]) -> PathBuf {
    exec_wrapper(dir, name, &bin("fault-controller"), faults)
}

/// `rig run` as a user types it; `out` receives run.mcap.
struct RigRun {
    daemon: Daemon,
    out: PathBuf,
}

impl RigRun {
    fn start(dir: &Path, scenario: &Path, args: &[&str]) -> RigRun {
        let out = dir.join("out");
        let mut all = vec!["run", scenario.to_str().unwrap(), "--out", out.to_str().unwrap()];
        all.extend_from_slice(args);
        RigRun { daemon: Daemon::start("rig", &bin("rig"), &all, dir), out }
    }

    fn finish(&mut self) -> ExitStatus {
        self.daemon.expect_exit(LONG)
    }

    fn recording(&self) -> Recording {
        Recording::open_complete(self.out.join("run.mcap")).expect("a complete recording")
    }

    /// The summary's last line (stdout).
    fn last_line(&self) -> String {
        self.daemon.stdout().lines().last().unwrap_or_default().to_string()
    }

    fn logs(&self) -> String {
        format!("stdout:\n{}\nstderr:\n{}", self.daemon.stdout(), self.daemon.stderr())
    }
}

/// Checks that all run, then fail together: one e2e run says everything it measured.
#[derive(Default)]
struct Checks(Vec<String>);

impl Checks {
    fn check(&mut self, ok: bool, what: impl FnOnce() -> String) {
        if !ok {
            let w = what();
            eprintln!("CHECK FAILED: {w}");
            self.0.push(w);
        }
    }

    fn done(self) {
        assert!(self.0.is_empty(), "{} check(s) failed:\n{}", self.0.len(), self.0.join("\n"));
    }
}

/// A real-time test rig on which a take-over needs 20 missed ticks in a row (the default is 3):
/// these tests are about controllers that answer. On this 2-core host, shared with builds (load
/// average 5), a controller that answers misses 3 ticks in a row now and then (418 misses in
/// 2.5 s measured), and by the rule the other publisher then takes over: a stranger included,
/// which then moves the arm (seen: 0.28 rad on joint 1 and a TCP-speed reflex). The rule itself
/// is unit-tested in plant-sim/src/arbiter.rs.
fn arbitration_rig(tag: &str) -> TestRig {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "takeover_after_misses = 20\n");
    TestRig { rig, dir, scenario }
}

/// Largest per-tick change of the applied torque over the rows `from..=to` (ticks), with where.
fn largest_step(rec: &Recording, from: u64, to: u64) -> (f64, u64, usize) {
    largest_step_where(rec, from, to, |_| true)
}

/// [`largest_step`] over the pairs of ticks for which `keep(first tick)` holds.
fn largest_step_where(rec: &Recording, from: u64, to: u64, keep: impl Fn(u64) -> bool) -> (f64, u64, usize) {
    let rows: Vec<_> = rec.joint_torque.iter().filter(|t| t.tick >= from && t.tick <= to).collect();
    let mut worst = (0.0, from, 0);
    for w in rows.windows(2).filter(|w| keep(w[0].tick)) {
        for j in 0..6 {
            let d = (w[1].torque.tau[j] - w[0].torque.tau[j]).abs();
            if d > worst.0 {
                worst = (d, w[1].tick, j + 1);
            }
        }
    }
    worst
}

// ---------------------------------------------------------------------------------------------
// Reflex, end stop

/// Lockstep, robot only (the strip is not involved, and no model build): deterministic, so the
/// reflex tick and the speeds are the same in every run; the drive limit and the reflex act
/// inside the plant's tick, so pacing changes nothing about them.
#[test]
fn a_valid_45_nm_on_joint_6_ends_in_a_velocity_reflex_at_rest_and_exit_status_4() {
    let _g = serial();
    let rig = unique_rig("reflex");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let ctrl = fault_wrapper(&dir, "spin6.sh", &["--add-torque", "6:45@200"]);
    let mut run = RigRun::start(&dir, &scenario, &["--mode", "lockstep", "--duration", "1.0", "--controller", ctrl.to_str().unwrap()]);
    let st = run.finish();
    let rec = run.recording();
    let mut c = Checks::default();

    let limit = VELOCITY_LIMIT_RADPS[5];
    let reflexes = events(&rec, EventKind::Reflex);
    eprintln!("reflex events: {reflexes:?}");
    assert_eq!(reflexes.len(), 1, "one reflex, latched to the end: {:?}", rec.events);
    let (k, text) = &reflexes[0];
    let k = *k;
    c.check(text.contains("joint 6") && text.contains(&format!("{limit:.3} rad/s")), || {
        format!("the event names joint 6 and its limit: {text}")
    });
    let value: f64 = text.split("speed ").nth(1).and_then(|s| s.split(' ').next()).and_then(|v| v.parse().ok()).unwrap_or(f64::NAN);
    c.check(value.abs() > limit, || format!("the event names the value: {text}"));
    c.check(k > 200 && k < 260, || format!("reflex at tick {k}, the torque is added from tick 200"));
    let flagged: Vec<u64> =
        rec.joint_state.iter().filter(|s| (s.flags & state_flags::REFLEX != 0) != (s.tick >= k)).map(|s| s.tick).collect();
    c.check(flagged.is_empty(), || format!("REFLEX flag set exactly from tick {k} on; wrong at ticks {flagged:?}"));
    let not_stopped = rec.joint_state.iter().filter(|s| s.tick >= k && s.plant_status != PlantStatus::SafeStop as u32).count();
    c.check(not_stopped == 0, || format!("{not_stopped} states after the reflex not in safe stop"));

    let trace: Vec<String> =
        rec.joint_state.iter().filter(|s| s.tick + 2 >= k && s.tick <= k + 8).map(|s| format!("{}: {:.4}", s.tick, s.qd[5])).collect();
    eprintln!("joint 6 speed around the reflex (tick: rad/s): {}", trace.join(", "));
    let qd6_max = rec.joint_state.iter().map(|s| s.qd[5].abs()).fold(0.0, f64::max);
    eprintln!("joint 6: peak speed {qd6_max:.4} rad/s = {:.2} % of its axis speed {limit:.4} rad/s", 100.0 * qd6_max / limit);
    c.check(qd6_max <= 1.1 * limit, || format!("joint 6 reached {qd6_max:.4} rad/s, more than 10 % above its axis speed {limit:.4} rad/s"));
    // At rest within 200 ms of the reflex: from then on |q̇6| < 1 % of the axis speed.
    let rest = rec.joint_state.iter().rev().take_while(|s| s.qd[5].abs() < 0.01 * limit).last().map(|s| s.tick);
    eprintln!(
        "joint 6 at rest (< 1 % of the axis speed) from tick {rest:?}, {} ms after the reflex",
        rest.map_or(-1, |r| r as i64 - k as i64)
    );
    c.check(rest.is_some_and(|r| r <= k + 200), || {
        format!("joint 6 not at rest within 200 ms of the reflex at tick {k} (rest from {rest:?})")
    });

    let last = run.last_line();
    eprintln!("{last}");
    c.check(st.code() == Some(4), || format!("rig run exit status {st}, expected 4\n{}", run.logs()));
    c.check(
        last.starts_with("rig: exit 4:") && last.contains(&format!("1 reflex (first at tick {k})")) && last.contains("1 safe stop"),
        || format!("summary's last line: {last}"),
    );
    c.done();
}

/// Lockstep, robot only: `fault-controller --drive-joint 5:3.4` moves joint 5's hold target at
/// 10 % of its axis speed to 3.4 rad, 75 degrees past its range (+120 degrees = 2.094 rad), so
/// that its PD torque, saturated at `--drive-torque` = 90 % of the joint's 100 N m limit, presses
/// the joint into its stop (sized for 0.25 degree at the torque limit).
#[test]
fn an_end_stop_holds_a_joint_driven_into_it() {
    let _g = serial();
    let t = TestRig::new("endstop", "lockstep");
    let j = 4;
    let press = 0.9 * TORQUE_LIMIT_NM[j];
    let mut plant = t.plant(5.0);
    let mut ctrl = t.controller("fault", "fault-controller", &["--drive-joint", "5:3.4", "--drive-torque", &press.to_string()]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "fault-controller: {}", ctrl.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    let mut c = Checks::default();

    let [_, hi] = POSITION_LIMIT_RAD[j];
    let q0 = rec.joint_state[0].q[j];
    let past = |s: &messages::JointState| (s.q[j] - hi).to_degrees();
    let worst = rec.joint_state.iter().map(past).fold(f64::NEG_INFINITY, f64::max);
    let last = rec.joint_state.last().unwrap();
    let top_speed = rec.joint_state.iter().map(|s| s.qd[j].abs()).fold(0.0, f64::max);
    // What the joint pushes the stop with at the end: the applied torque less gravity.
    let s = scenarios::Scenario::load(&t.scenario).unwrap();
    let arm = robot::Robot::irb2400_with_tool(robot::Tool::wheel_on_bracket(
        s.robot.tool_mass_kg,
        s.robot.tool_offset_m,
        s.robot.wheel_radius_mm * 1e-3,
    ));
    let tau_last = rec.joint_torque.last().unwrap().torque.tau[j];
    let pushing = tau_last - arm.gravity_torque(&robot::Vec6::from(last.q))[j];
    let expected_deg = pushing / (TORQUE_LIMIT_NM[j] / 0.25);
    eprintln!(
        "joint 5: from {q0:.4} rad to its stop at {hi:.4} rad; deepest {worst:.4} deg past the range; at the end {:.4} deg at {:.1e} rad/s, \
         pushing with {pushing:.2} N m (spring alone: {expected_deg:.4} deg); top speed {top_speed:.3} rad/s ({:.1} % of the axis speed)",
        past(last),
        last.qd[j],
        100.0 * top_speed / VELOCITY_LIMIT_RADPS[j]
    );
    c.check(worst > 0.0, || format!("joint 5 never reached its stop (deepest {worst} deg)"));
    c.check(worst < 2.0, || format!("joint 5 {worst:.3} deg past its range"));
    c.check(past(last) > 0.0 && last.qd[j].abs() < 1e-3, || {
        format!("held in the stop at the end: {:.4} deg past, {} rad/s", past(last), last.qd[j])
    });
    c.check((pushing - press).abs() < 0.05 * press, || {
        format!("the controller pushes with {pushing:.2} N m at the end, not about its saturation {press} N m")
    });
    c.check((past(last) - expected_deg).abs() < 0.05 * expected_deg, || {
        format!("held at {:.4} deg, the stop's spring says {expected_deg:.4} deg", past(last))
    });
    let stops = events(&rec, EventKind::EndStop);
    eprintln!("end-stop events: {stops:?}");
    c.check(stops.len() == 1 && stops[0].1.contains("joint 5"), || format!("one end_stop event naming joint 5: {stops:?}"));
    let wrong: Vec<u64> =
        rec.joint_state.iter().filter(|s| (s.flags & state_flags::END_STOP != 0) != (s.q[j] > hi)).map(|s| s.tick).collect();
    c.check(wrong.is_empty(), || format!("END_STOP flag exactly while beyond the range; wrong at ticks {wrong:?}"));
    c.check(events(&rec, EventKind::Reflex).is_empty(), || format!("no reflex at this speed: {:?}", events(&rec, EventKind::Reflex)));
    c.done();
}

// ---------------------------------------------------------------------------------------------
// One controller at a time

/// The arbiter's take-over events ("publisher ... takes over from ...") and the gate's
/// ("controller ... takes over from ...") of one recording.
fn takeovers(rec: &Recording) -> Vec<(u64, String)> {
    events(rec, EventKind::ControllerChange).into_iter().filter(|(_, t)| t.contains("takes over")).collect()
}

/// Real time (two controllers answering one plant is a real-time situation), robot only, a
/// take-over after 20 misses (see [`arbitration_rig`]). `hold-controller` A holds the start pose; B, the
/// same binary with 100 N m more on joint 1, joins 200 ms later and is ignored (recorded once);
/// 500 ms later A is killed: B takes over, once, blended in.
#[test]
fn two_controllers_one_active_and_exactly_one_take_over_when_it_is_killed() {
    let _g = serial();
    let t = arbitration_rig("two");
    let mut plant = t.plant(2.5);
    let mut a = t.controller("hold-a", "hold-controller", &[]);
    wait_for_log(&plant, "connected", Duration::from_secs(10));
    std::thread::sleep(Duration::from_millis(200));
    let mut b = t.controller("hold-b", "hold-controller", &["--offset-nm", "100"]);
    std::thread::sleep(Duration::from_millis(500));
    let kill_ns = wall_ns();
    a.signal(libc::SIGKILL);
    a.expect_exit(Duration::from_secs(5));
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(b.expect_exit(Duration::from_secs(10)).success(), "hold-controller B: {}", b.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    let mut c = Checks::default();

    let kill_tick = tick_at_wall_ns(&rec, kill_ns).expect("the kill happened during the run");
    let all = takeovers(&rec);
    eprintln!("A killed at about tick {kill_tick}; take-over events: {all:?}");
    eprintln!("foreign torque events: {:?}", events(&rec, EventKind::ForeignTorque));
    let before: Vec<_> = all.iter().filter(|(k, _)| *k < kill_tick).collect();
    c.check(before.is_empty(), || format!("no take-over while both run: {before:?}"));
    let ticks: std::collections::BTreeSet<u64> = all.iter().map(|(k, _)| *k).collect();
    c.check(ticks.len() == 1, || format!("exactly one take-over after the kill: {all:?}"));
    let by_arbiter = all.iter().filter(|(_, t)| t.contains("publisher")).count();
    c.check(by_arbiter == 1, || format!("one switch of publisher: {all:?}"));
    let foreign = events(&rec, EventKind::ForeignTorque);
    c.check(foreign.len() == 1 && foreign[0].0 < kill_tick, || format!("B ignored and recorded once while A runs: {foreign:?}"));
    if let Some(&takeover) = ticks.iter().next() {
        let after_ms = takeover as i64 - kill_tick as i64;
        eprintln!("B took over at tick {takeover}, {after_ms} ms after the kill");
        c.check((0..=100).contains(&after_ms), || format!("take-over {after_ms} ms after the kill (a dead node is seen within 100 ms)"));
        // While both ran, the plant applied A's torques only (one controller_id).
        let ids: std::collections::BTreeSet<u64> =
            rec.joint_torque.iter().filter(|r| r.tick < takeover && r.torque.controller_id != 0).map(|r| r.torque.controller_id).collect();
        c.check(ids.len() == 1, || format!("one controller applied before the take-over, saw ids {ids:x?}"));
        let (step, at, j) = largest_step(&rec, takeover.saturating_sub(5), takeover + 100);
        eprintln!("largest applied-torque step around the take-over: {step:.3} N m on joint {j} at tick {at}");
        assert_no_jump(&rec, takeover);
    }
    c.done();
}

/// Real time, robot only, a take-over after 20 misses (see [`arbitration_rig`]):
/// `hold-controller` holds the start pose; after 200 ms a stranger
/// (`fault-controller --stranger`) answers every state with g(q) plus 40 N m on joint 1. The plant
/// applies the active controller's answers only: the applied `/joint_torque` equals the commanded
/// (the active controller's own answer, recorded by the plant) wherever it was not held or
/// blended, joint 1 never sees the stranger's 40 N m and does not move; one foreign_torque event.
#[test]
fn a_stranger_on_the_torque_service_moves_nothing_and_is_recorded_once() {
    let _g = serial();
    let t = arbitration_rig("stranger");
    let mut plant = t.plant(2.0);
    let mut hold = t.controller("hold", "hold-controller", &[]);
    wait_for_log(&plant, "connected", Duration::from_secs(10));
    std::thread::sleep(Duration::from_millis(200));
    let mut stranger = t.controller("stranger", "fault-controller", &["--stranger", "--stranger-after", "100", "--stranger-nm", "40"]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(hold.expect_exit(Duration::from_secs(10)).success(), "hold-controller: {}", hold.stderr());
    assert!(stranger.expect_exit(Duration::from_secs(10)).success(), "stranger: {}", stranger.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    let summary = plant_summary(&plant);
    let mut c = Checks::default();

    let sent: u64 =
        stranger.stderr().split("published ").nth(1).and_then(|s| s.split(' ').next()).and_then(|n| n.parse().ok()).unwrap_or(0);
    eprintln!("stranger published {sent} torques; the plant ignored {} foreign answers", summary["foreign_answers"]);
    c.check(sent > 500, || format!("the stranger published only {sent} torques: {}", stranger.stderr()));
    // The plant sees a stranger's answer only when it comes in before the active controller's
    // (then the tick is settled): a share of them that depends on scheduling (34-962 of about
    // 1650 seen). One applied would put 40 N m on joint 1 for a tick, which the checks below see;
    // so what matters is that the stranger was seen at all, and never more often than it sent.
    let foreign_answers = summary["foreign_answers"].as_u64().unwrap_or(0);
    c.check(foreign_answers > 0 && foreign_answers <= sent, || format!("foreign answers ignored: {foreign_answers} of {sent} sent"));
    let foreign = events(&rec, EventKind::ForeignTorque);
    eprintln!("foreign torque events: {foreign:?}");
    c.check(foreign.len() == 1, || format!("one foreign_torque event: {foreign:?}"));
    let changes = events(&rec, EventKind::ControllerChange);
    c.check(changes.len() == 1, || format!("one controller, connected once: {changes:?}"));
    let connected = changes.first().map_or(0, |e| e.0);
    // Applied = commanded wherever the plant neither held nor blended (blend: 50 ms after connect).
    let (mut compared, mut differ) = (0, Vec::new());
    for r in rec.joint_torque.iter().filter(|r| r.tick > connected + 60 && !r.held) {
        if let Some(cmd) = r.commanded {
            compared += 1;
            if cmd != r.torque.tau {
                differ.push(r.tick);
            }
        }
    }
    eprintln!("applied torque equals the active controller's answer bit for bit on {} of {compared} ticks", compared - differ.len());
    c.check(compared > 1000 && differ.is_empty(), || {
        format!("applied differs from commanded at {} of {compared} ticks: {:?}", differ.len(), &differ[..differ.len().min(10)])
    });
    let ids: std::collections::BTreeSet<u64> =
        rec.joint_torque.iter().filter(|r| r.torque.controller_id != 0).map(|r| r.torque.controller_id).collect();
    c.check(ids.len() == 1, || format!("one controller_id applied: {ids:x?}"));
    let tau1 = rec.joint_torque.iter().map(|r| r.torque.tau[0].abs()).fold(0.0, f64::max);
    let q1_0 = rec.joint_state[0].q[0];
    let drift = rec.joint_state.iter().map(|s| (s.q[0] - q1_0).abs()).fold(0.0, f64::max);
    eprintln!("joint 1: largest applied torque {tau1:.4} N m (the stranger sends 40 N m), largest drift {drift:.2e} rad");
    c.check(tau1 < 5.0, || format!("joint 1 got {tau1} N m"));
    c.check(drift < 1e-3, || format!("joint 1 moved {drift} rad"));
    c.done();
}

/// Lockstep, robot only: the same hold run with and without a stranger. The lockstep plant waits
/// for the active controller's answer each tick and ignores the stranger's, so the stranger moves
/// nothing at all: the two recordings' states and applied torques are bit-identical, and the
/// stranger, whose answers the plant did see, is recorded once.
///
/// Fails on this host (1 in 10 runs alone, 2 of 2 in the whole file), from a defect below the test: now and then, mid-run, no
/// torque publisher's `torque_ready` notification reaches the lockstep plant any more (the
/// notifiers send nothing, a freshly started one neither, while the plant's listener socket and
/// port tag still exist), so every tick waits the 2 s watchdog and `hold-controller` gives up after
/// 100 ms of silence. Seen with `hold-controller` + `fault-controller` (with or without its peer
/// watch), not in 30 runs of two `hold-controller`s.
#[test]
fn in_lockstep_a_stranger_changes_not_one_bit() {
    let _g = serial();
    let run = |tag: &str, with_stranger: bool| {
        let t = TestRig::new(tag, "lockstep");
        let mut plant = t.plant(10.0);
        let mut hold = t.controller("hold", "hold-controller", &[]);
        let mut stranger = with_stranger.then(|| t.controller("stranger", "fault-controller", &["--stranger", "--stranger-after", "100"]));
        // 10 simulated seconds take about 0.3 s in lockstep; the defect above makes it 2 s a tick.
        assert!(plant.expect_exit(Duration::from_secs(30)).success(), "plant: {}", plant.stderr());
        assert!(hold.expect_exit(Duration::from_secs(10)).success(), "hold-controller: {}", hold.stderr());
        if let Some(s) = stranger.as_mut() {
            s.expect_exit(Duration::from_secs(10));
        }
        (Recording::open_complete(t.recording()).unwrap(), plant_summary(&plant))
    };
    let (alone, _) = run("lone", false);
    let (with, summary) = run("crowd", true);
    let foreign = events(&with, EventKind::ForeignTorque);
    eprintln!("the plant ignored {} of the stranger's answers; foreign torque events {foreign:?}", summary["foreign_answers"]);
    assert_eq!(alone.joint_state.len(), with.joint_state.len());
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for (a, b) in alone.joint_state.iter().zip(&with.joint_state) {
        assert_eq!((bits(&a.q), bits(&a.qd)), (bits(&b.q), bits(&b.qd)), "state of tick {} differs", a.tick);
    }
    for (a, b) in alone.joint_torque.iter().zip(&with.joint_torque) {
        assert_eq!(bits(&a.torque.tau), bits(&b.torque.tau), "applied torque of tick {} differs", a.tick);
    }
    assert!(
        summary["foreign_answers"].as_u64().unwrap_or(0) > 0,
        "the stranger's answers never reached the plant: {}",
        summary["foreign_answers"]
    );
    assert_eq!(foreign.len(), 1, "{foreign:?}");
}

// ---------------------------------------------------------------------------------------------
// rig run's exit status

/// The default scenario in lockstep (what `rig run --mode lockstep` runs): exit 0 and says so.
#[test]
fn the_default_lockstep_run_exits_0() {
    let _g = serial();
    let rig = unique_rig("exit0");
    let dir = temp_dir(&rig);
    let default = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let mut run = RigRun::start(&dir, &default, &["--mode", "lockstep"]);
    let st = run.finish();
    let last = run.last_line();
    eprintln!("{last}");
    assert_eq!(st.code(), Some(0), "{}", run.logs());
    assert!(last.starts_with("rig: exit 0: reached the end"), "{last}");
    run.recording();
}

/// Lockstep, deterministic: `hold-controller --nan-from-tick 100` sends NaN from tick 100 on; the
/// plant refuses every one (200 in 0.3 s), holds, and enters the safe stop at the 20th miss
/// (tick 119). The run reaches its end: exit 4, with the counts and first ticks.
#[test]
fn refused_torques_and_a_safe_stop_give_exit_4_with_counts_and_first_ticks() {
    let _g = serial();
    let rig = unique_rig("exit4");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let ctrl = dir.join("nan.sh");
    std::fs::write(&ctrl, format!("#!/bin/sh\nexec '{}' --nan-from-tick 100 \"$@\"\n", bin("hold-controller").display())).unwrap();
    std::process::Command::new("chmod").arg("+x").arg(&ctrl).status().unwrap();
    let mut run = RigRun::start(&dir, &scenario, &["--mode", "lockstep", "--duration", "0.3", "--controller", ctrl.to_str().unwrap()]);
    let st = run.finish();
    let last = run.last_line();
    eprintln!("{last}");
    assert_eq!(st.code(), Some(4), "{}", run.logs());
    assert_eq!(last, "rig: exit 4: 1 safe stop (first at tick 119), 200 refused torques (first at tick 100)");
    // The applied torque names the answer it came from: this tick's before the refusals, the
    // last accepted one (tick 99) while the plant holds or stops; a refused answer still came,
    // so its own status is recorded.
    let rec = run.recording();
    assert_eq!(rec.joint_torque.len(), 300);
    for r in &rec.joint_torque {
        let (answered, status) = (r.torque.tick, r.torque.controller_status);
        if r.tick < 100 {
            assert!(!r.held && answered == r.tick && status == 0, "tick {}: held {}, answered {answered}, status {status}", r.tick, r.held);
        } else {
            assert!(r.held && answered == 99 && status == 0, "tick {}: held {}, answered {answered}, status {status}", r.tick, r.held);
        }
    }
}

/// Real time: `fault-controller --sleep-us 30000 --every 1 --sleep-from 300` answers every tick
/// 30 ms late from tick 300 on (60 times the 500 µs budget: every tick a miss, deterministic
/// however noisy the host), so the plant holds and enters the safe stop at the 20th miss, and the
/// run reaches its end: exit 4 for the safe stop; the misses alone would not change the status.
#[test]
fn a_slow_controller_s_safe_stop_gives_exit_4() {
    let _g = serial();
    let rig = unique_rig("slow");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "max_consecutive_misses = 20\n");
    let ctrl = fault_wrapper(&dir, "slow.sh", &["--sleep-us", "30000", "--every", "1", "--sleep-from", "300"]);
    let mut run = RigRun::start(&dir, &scenario, &["--mode", "realtime", "--duration", "1.0", "--controller", ctrl.to_str().unwrap()]);
    let st = run.finish();
    let last = run.last_line();
    eprintln!("{last}");
    assert_eq!(st.code(), Some(4), "{}", run.logs());
    let first: u64 = last.split("first at tick ").nth(1).and_then(|s| s.trim_end_matches(')').parse().ok()).unwrap_or(0);
    assert!(
        last.starts_with("rig: exit 4: 1 safe stop (first at tick ") && !last.contains("refused") && !last.contains("reflex"),
        "{last}"
    );
    // Every tick from 300 on misses, so the 20th miss in a row comes at tick 319 at the latest;
    // a host stall just before 300 may bring it earlier. Either way it is the first tick that
    // ends 20 held (missed) ticks in a row in the recording.
    let rec = run.recording();
    let mut in_a_row = 0;
    let twentieth = rec.joint_torque.iter().find_map(|r| {
        in_a_row = if r.held { in_a_row + 1 } else { 0 };
        (in_a_row == 20).then_some(r.tick)
    });
    assert_eq!(Some(first), twentieth, "safe stop at the 20th miss in a row: {last}");
    assert!(first <= 319, "every tick from 300 on misses, yet the safe stop came at tick {first}: {last}");
    assert!(
        rec.joint_state.iter().all(|s| s.tick <= 300 || s.total_misses + 300 >= s.tick),
        "every tick from 300 on is a miss (the state of tick k counts the misses before k)"
    );
    // No answer came in time for those ticks: the applied torque is recorded as no answer's,
    // held from (or, in the safe stop, after) an answer to an earlier state.
    let late: Vec<_> = rec.joint_torque.iter().filter(|r| r.tick > 300).collect();
    assert!(!late.is_empty());
    for r in late {
        let (answered, status) = (r.torque.tick, r.torque.controller_status);
        assert!(
            r.held && answered < r.tick && status == recordings::STATUS_NO_ANSWER,
            "tick {}: held {}, answered {answered}, status {status}",
            r.tick,
            r.held
        );
    }
}

/// `rig sweep` with a controller that trips a reflex (lockstep, robot only, two cases): each case
/// reached its end with a reflex, so the table says `4: 1 reflex (first at tick ...)` and the sweep
/// exits 4.
#[test]
fn a_sweep_reports_a_case_with_exit_4_as_such() {
    let _g = serial();
    let rig = unique_rig("sweep4");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let ctrl = fault_wrapper(&dir, "spin6.sh", &["--add-torque", "6:45@200"]);
    let out = dir.join("sweep");
    let mut sweep = Daemon::start(
        "rig sweep",
        &bin("rig"),
        &[
            "sweep",
            scenario.to_str().unwrap(),
            "--set",
            "loop.substeps=10,20",
            "--duration",
            "0.4",
            "--controller",
            ctrl.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    let st = sweep.expect_exit(LONG);
    let table = sweep.stdout();
    eprintln!("{table}");
    assert_eq!(st.code(), Some(4), "{table}\n{}", sweep.stderr());
    for case in ["loop.substeps=10", "loop.substeps=20"] {
        let row = table.lines().find(|l| l.starts_with(&format!("| {case} |"))).unwrap_or_default();
        assert!(row.contains("| 4: 1 reflex (first at tick 20") && row.contains("1 safe stop"), "{row}");
    }
    let cases: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    assert!(cases.as_array().unwrap().iter().all(|c| c["exit_code"] == 4 && c["status"].as_str().unwrap().contains("reflex")), "{cases}");
}

/// `rig run` stopped by SIGTERM (real time, robot only): both daemons stopped cleanly, the
/// recording finalised, exit 143; by SIGINT (Ctrl-C): 130.
#[test]
fn rig_run_exits_143_on_sigterm_and_130_on_sigint() {
    let _g = serial();
    for (sig, code, word) in [(libc::SIGTERM, 143, "terminated (SIGTERM)"), (libc::SIGINT, 130, "interrupted (SIGINT)")] {
        let rig = unique_rig(&format!("sig{sig}"));
        let dir = temp_dir(&rig);
        let scenario = write_scenario(&dir, "realtime", "");
        let mut run = RigRun::start(&dir, &scenario, &["--mode", "realtime", "--duration", "30"]);
        wait_for_log(&run.daemon, "connected", Duration::from_secs(20));
        std::thread::sleep(Duration::from_millis(300));
        let t0 = Instant::now();
        run.daemon.signal(sig);
        let st = run.finish();
        let last = run.last_line();
        eprintln!("signal {sig}: exit {st} after {:?}: {last}", t0.elapsed());
        assert_eq!(st.code(), Some(code), "{}", run.logs());
        assert!(last.contains(word), "{last}");
        let rec = run.recording();
        assert!(rec.joint_state.len() > 200, "{} ticks recorded", rec.joint_state.len());
    }
}

// ---------------------------------------------------------------------------------------------
// A dead controller under rig run

/// Real time, robot only, the default `controller` under `rig run`, killed with SIGKILL after
/// 300 ms: rig reports it to the plant (SIGUSR1), which records "controller process ended (killed
/// by signal 9)" and enters the safe stop; 100 ms later rig stops the plant, which finalises its
/// recording, and exits 3.
#[test]
fn a_dead_controller_under_rig_run_is_recorded_puts_the_plant_into_safe_stop_and_gives_exit_3() {
    let _g = serial();
    dead_controller_under_rig_run("realtime");
}

/// The same in lockstep. Needs a plant fix: the lockstep plant waits for the torque up to its
/// watchdog (2 s) without looking at signals (`rig_process::ports::wait_readable` resumes `ppoll`
/// after EINTR), and when rig's SIGTERM has arrived by then, the loop breaks on
/// `stop_requested()` before it reads the controller-end report: no controller_ended entry, no
/// safe stop, and the plant stops 2 s after the kill instead of 100 ms.
#[test]
fn a_dead_controller_under_rig_run_in_lockstep_is_recorded_and_puts_the_plant_into_safe_stop() {
    let _g = serial();
    dead_controller_under_rig_run("lockstep");
}

fn dead_controller_under_rig_run(mode: &str) {
    let rig = unique_rig(&format!("deadctl-{mode}"));
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, mode, "");
    let mut run = RigRun::start(&dir, &scenario, &["--mode", mode, "--duration", "600"]);
    wait_for_log(&run.daemon, "connected", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(300));
    let pid = child_pid(run.daemon.pid(), "controller").expect("rig's controller process");
    let kill_ns = wall_ns();
    // SAFETY: signalling the controller process rig started for this test.
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let st = run.finish();
    let rec = run.recording();
    let last = run.last_line();
    eprintln!("{last}");
    let mut c = Checks::default();
    c.check(st.code() == Some(3), || format!("exit {st}, expected 3\n{}", run.logs()));
    c.check(run.daemon.stderr().contains("CONTROLLER FAILED") && run.daemon.stderr().contains("killed by signal 9"), || run.logs());
    c.check(last.starts_with("rig: exit 3: controller failed") && last.contains("1 safe stop"), || format!("last line: {last}"));

    let kill_tick = tick_at_wall_ns(&rec, kill_ns).unwrap_or(0);
    let ended = events(&rec, EventKind::ControllerEnded);
    let stop_pos = rec.events.iter().position(|e| e.kind == Some(EventKind::Stop));
    let ended_pos = rec
        .events
        .iter()
        .position(|e| e.kind == Some(EventKind::ControllerEnded) && e.text.contains("controller process ended (killed by signal 9)"));
    eprintln!(
        "controller killed at about tick {kill_tick}; controller_ended events {ended:?}; events: {:?}",
        rec.events.iter().map(|e| (e.tick, e.kind_name.as_str())).collect::<Vec<_>>()
    );
    c.check(ended_pos.is_some() && stop_pos.is_some() && ended_pos < stop_pos, || {
        format!("a controller_ended entry naming the signal before the plant's stop: {:?}", rec.events)
    });
    let safe = events(&rec, EventKind::SafeStop);
    // `kill_tick` is the first tick published after the kill; the tick published just before it,
    // whose answer the killed controller never sent, is the first that can end in a safe stop.
    c.check(!safe.is_empty() && safe[0].0 + 1 >= kill_tick, || format!("the plant entered the safe stop after the kill: {safe:?}"));
    if let (Some(e), Some(s)) =
        (ended.iter().find(|e| e.1.contains("process ended")), rec.events.iter().find(|e| e.kind == Some(EventKind::Stop)))
    {
        eprintln!(
            "reported {} ms after the kill; the safe stop at tick {:?}; the plant stopped {} ms after the report",
            e.0 as i64 - kill_tick as i64,
            safe.first().map(|s| s.0),
            s.tick as i64 - e.0 as i64
        );
        c.check(e.0 <= kill_tick + 50, || format!("reported at tick {}, killed at {kill_tick}", e.0));
        // The plant's own clock: its 1 ms deadlines from the report to the stop, the ticks and
        // the periods it skipped after host stalls (each recorded as "... skipped N periods").
        let skipped: i64 = rec
            .events
            .iter()
            .filter(|ev| ev.tick > e.0 && ev.tick <= s.tick)
            .filter_map(|ev| ev.text.split("skipped ").nth(1)?.split(' ').next()?.parse::<i64>().ok())
            .sum();
        let stop_after = s.tick as i64 - e.0 as i64 + skipped;
        c.check(mode == "lockstep" || (90..=250).contains(&stop_after), || {
            format!("the plant stopped {stop_after} ms after the report ({skipped} periods skipped), rig waits 100 ms")
        });
        let status = rec.joint_state.iter().filter(|st| st.tick > e.0).map(|st| st.plant_status).collect::<std::collections::BTreeSet<_>>();
        c.check(status == [PlantStatus::SafeStop as u32].into(), || format!("states after the report: statuses {status:?}"));
    }
    c.done();
}

// ---------------------------------------------------------------------------------------------
// Tests that need the controller changes (liveness, anti-windup, bumpless onset and
// re-engagement; the lead's work on controller/). They may fail until main has them.

/// Wait until the recording being written at `path` shows the wheel at `z_mm` or more along the
/// strip (its last whole chunk's strip record); returns that record's z, mm.
fn wait_for_wheel_z(path: &Path, z_mm: f64, timeout: Duration) -> f64 {
    let t0 = Instant::now();
    loop {
        let z = Recording::open(path).ok().and_then(|r| r.strip.last().map(|s| s.wheel_z_m * 1e3));
        if let Some(z) = z.filter(|z| *z >= z_mm) {
            return z;
        }
        assert!(t0.elapsed() < timeout, "the wheel did not reach z = {z_mm} mm within {timeout:?} (last seen {z:?} mm)");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn default_scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml")
}

/// Needs the controller changes. Real time, the default scenario (strip, force control): the
/// `controller` is stopped (SIGSTOP) for 200 ms during the roll, then continued. The plant holds,
/// then safe-stops; when the controller answers again it must re-engage from the measured state
/// without its force law wound up: the safe stop clears within 50 ms of the first good answer,
/// no torque is refused, and the applied torque steps by at most 5 N m per tick from then on
/// (over the 300 ms after the safe stop clears).
// needs the controller changes
#[test]
fn a_controller_stopped_for_200_ms_during_the_roll_resumes_bumplessly() {
    let _g = serial();
    let rig = unique_rig("sigstop-ctl");
    let dir = temp_dir(&rig);
    let scenario = default_scenario();
    let mut plant = start_plant(&rig, &scenario, &dir, 4.0, &[]);
    let mut ctrl = start_controller("controller", "controller", &rig, &scenario, &dir, &[]);
    wait_for_log(&plant, "connected", Duration::from_secs(60));
    // Stop the controller in the roll (z from 2 to 38 mm). The roll runs from about 0.8 s to
    // 2.8 s of an undisturbed run, but the host's misses hold the reference and delay it (1,000
    // misses in 3.6 s seen on 2026-12-06), so watch the recording: its chunks close at least once
    // a second, and the file read so far is read up to its last whole chunk.
    let wheel_z_mm = wait_for_wheel_z(&dir.join("run.mcap"), 6.0, Duration::from_secs(20));
    eprintln!("the recording so far shows the wheel at z = {wheel_z_mm:.2} mm");
    let stop_ns = wall_ns();
    ctrl.signal(libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(200));
    ctrl.signal(libc::SIGCONT);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller: {}", ctrl.stderr());
    let rec = Recording::open_complete(dir.join("run.mcap")).unwrap();
    let summary = plant_summary(&plant);
    let mut c = Checks::default();

    let stop_tick = tick_at_wall_ns(&rec, stop_ns).expect("stopped during the run");
    let z = rec.strip.iter().find(|s| s.tick == stop_tick).map_or(f64::NAN, |s| s.wheel_z_m * 1e3);
    eprintln!("controller stopped at tick {stop_tick}, wheel at z = {z:.2} mm");
    c.check(z > 4.0 && z < 36.0, || format!("the stop should fall in the roll (z from 2 to 38 mm), wheel at {z} mm"));
    let stopped = events(&rec, EventKind::SafeStop);
    let cleared = events(&rec, EventKind::SafeStopCleared);
    eprintln!("safe stops {stopped:?}; cleared {cleared:?}");
    c.check(summary["refusals"] == 0, || format!("refused torques: {}", summary["refusals"]));
    // The first good answer after the stall: a torque that arrived in time (not held).
    let first_good = rec.joint_torque.iter().find(|r| r.tick > stop_tick + 20 && !r.held && r.commanded.is_some()).map(|r| r.tick);
    match (first_good, cleared.iter().find(|(k, _)| *k > stop_tick)) {
        (Some(g), Some((k, _))) => {
            eprintln!("first good answer at tick {g}, safe stop cleared at tick {k} ({} ms later)", *k as i64 - g as i64);
            c.check(*k >= g && *k <= g + 50, || format!("safe stop cleared at tick {k}, first good answer at {g}"));
            // A tick the host made the controller miss while the plant ran (the plant held the last
            // torque: HoldingTorque in the next state) steps by what the law did meanwhile; that
            // is the host's, not the re-engagement's, and is counted apart.
            let host_held: std::collections::HashSet<u64> = rec
                .joint_state
                .iter()
                .filter(|s| s.plant_status == messages::PlantStatus::HoldingTorque as u32)
                .map(|s| s.tick - 1)
                .collect();
            let (all, all_at, _) = largest_step(&rec, g, k + 300);
            eprintln!("largest step including those after host misses ({} held ticks): {all:.3} N m at tick {all_at}", host_held.len());
            let (step, at, j) = largest_step_where(&rec, g, k + 300, |t| !host_held.contains(&t));
            eprintln!(
                "largest applied-torque step from the first good answer to 300 ms after the clear: {step:.3} N m on joint {j} at tick {at}"
            );
            // Where it happens: the torque on that joint, the contact, force control.
            for k in at.saturating_sub(3)..=at + 2 {
                let tau = rec.joint_torque.iter().find(|r| r.tick == k).map_or(f64::NAN, |r| r.torque.tau[j - 1]);
                let st = rec.joint_state.iter().find(|s| s.tick == k);
                let contact = st.is_some_and(|s| s.flags & state_flags::IN_CONTACT != 0);
                let strip = rec.strip.iter().find(|s| s.tick == k);
                let fc = rec.controller.iter().find(|d| d.tick == k).map(|d| d.force_control_active);
                eprintln!(
                    "  tick {k}: tau{j} {tau:.2} N m, in contact {contact}, contact force {:.2} N, wheel z {:.2} mm, force control {fc:?}",
                    strip.map_or(f64::NAN, |s| s.contact_force_n),
                    strip.map_or(f64::NAN, |s| s.wheel_z_m * 1e3)
                );
            }
            c.check(step <= 5.0, || format!("applied torque steps {step:.3} N m on joint {j} at tick {at} after resumption"));
        }
        other => c.check(false, || format!("no resumption after the stall (first good answer, clear): {other:?}")),
    }
    c.done();
}

/// Real time, the default scenario under `rig run`: the `controller` is stopped (SIGSTOP) for 1 s
/// early in the roll, then continued. The plant holds the torque, safe-stops and takes the
/// controller back; the shipped controller's plan waits for every tick the plant held or stopped
/// the arm, and the run's duration is fixed, so the roll ends short of its plan. The summary
/// must say so with its figures (`recording_tools::roll_end`), and they must agree with the
/// undisturbed lockstep run of the same scenario: the reference stopped where that run's was at
/// least the held time before the end, and at most 0.1 s more. The safe stop is the plant's
/// position hold: the wheel stops where the stop began (within the closed form) and stays on the
/// strip, pressing, so nothing has to be found again.
#[test]
fn a_roll_cut_short_by_a_stalled_controller_says_how_short_and_why() {
    let _g = serial();
    let rig = unique_rig("roll-short");
    let dir = temp_dir(&rig);
    let (ideal_dir, stall_dir) = (dir.join("ideal"), dir.join("stall"));
    for d in [&ideal_dir, &stall_dir] {
        std::fs::create_dir_all(d).unwrap();
    }
    let mut ideal = RigRun::start(&ideal_dir, &default_scenario(), &["--mode", "lockstep"]);
    assert_eq!(ideal.finish().code(), Some(0), "{}", ideal.logs());
    assert!(!ideal.daemon.stdout().contains("roll end"), "an undisturbed run reaches its plan's end: {}", ideal.logs());
    let ideal_rec = ideal.recording();

    let mut run = RigRun::start(&stall_dir, &default_scenario(), &[]);
    let wheel_z_mm = wait_for_wheel_z(&run.out.join("run.mcap"), 6.0, Duration::from_secs(20));
    let ctrl = child_pid(run.daemon.pid(), "controller").expect("rig's controller");
    eprintln!("the recording so far shows the wheel at z = {wheel_z_mm:.2} mm: stopping controller {ctrl} for 1 s");
    let stall = Duration::from_millis(1000);
    let stop_ns = wall_ns();
    // SAFETY: plain kill(2) on a child of rig's that this test found.
    unsafe { libc::kill(ctrl, libc::SIGSTOP) };
    std::thread::sleep(stall);
    // SAFETY: as above.
    unsafe { libc::kill(ctrl, libc::SIGCONT) };
    let st = run.finish();
    assert_eq!(st.code(), Some(4), "a safe stop gives exit 4: {}", run.logs());
    let rec = run.recording();
    let e = recording_tools::report::numbers(&rec).roll_end.expect("a scenario run with controller diagnostics has a roll end");
    eprintln!("{e:?}\n{}", e.line());
    let mut c = Checks::default();
    c.check(run.daemon.stdout().contains(&e.line()), || format!("the summary prints the roll-end line: {}", run.logs()));
    c.check(e.is_short() && e.short_m > 1e-3, || format!("a 1 s stall ends the roll short by more than 1 mm: {e:?}"));
    c.check((e.planned_end_m - 0.038).abs() < 1e-12, || format!("the plan ends at the scenario's z_end_mm: {e:?}"));
    // The plant keeps its 1 kHz clock while the controller is stopped: at least 0.9 s of ticks.
    c.check(e.held_or_stopped_ticks >= 900, || format!("held or stopped ticks {} for a 1 s stall", e.held_or_stopped_ticks));
    // The plan's delay: when the undisturbed run's reference was where this one stopped.
    let t_last = rec.controller.last().map(|d| d.tick as f64 * rec.period_s()).unwrap();
    let t_ideal = ideal_rec.controller.iter().find(|d| d.pos_ref_task_m[2] >= e.reached_m).map(|d| d.tick as f64 * ideal_rec.period_s());
    let delay = t_ideal.map_or(f64::NAN, |t| t_last - t);
    eprintln!("the plan's delay against the undisturbed run: {delay:.3} s; held or stopped {:.3} s", e.held_or_stopped_s);
    // At least the held time: the plan waits for every held or stopped tick, less the held
    // ticks outside the stall whose state the controller never saw (a late controller answers
    // the newest state; its plan runs on for the ones it skipped). At most 0.1 s more: the
    // position hold keeps the wheel on the strip, so the plan waits little after the take-over
    // (2-16 ms in four runs on 2026-12-07; with the compliant stop it used to coast off the strip,
    // and pressing again took 0.30 s more).
    let stall_from = tick_at_wall_ns(&rec, stop_ns).expect("stopped during the run");
    let stall_to = events(&rec, EventKind::SafeStopCleared).iter().map(|(k, _)| *k).find(|k| *k > stall_from).unwrap_or(u64::MAX);
    let answered: std::collections::HashSet<u64> = rec.controller.iter().map(|d| d.tick).collect();
    let unseen = rec
        .joint_state
        .iter()
        .filter(|j| {
            j.plant_status == PlantStatus::HoldingTorque as u32 && !(stall_from..=stall_to).contains(&j.tick) && !answered.contains(&j.tick)
        })
        .count();
    let unseen_s = unseen as f64 * rec.period_s();
    eprintln!("held ticks outside the stall (ticks {stall_from}..={stall_to}) the controller never saw: {unseen}");
    c.check(delay >= e.held_or_stopped_s - unseen_s - 0.005 && delay <= e.held_or_stopped_s + 0.1, || {
        format!("the plan's delay {delay} s against {} s held or stopped, {unseen_s} s of them unseen", e.held_or_stopped_s)
    });
    // The safe stop is a position hold: from the wheel's speed along the strip on its first
    // tick, a joint critically damped at ω = 2π loop.hold_bandwidth_hz stops within v / (ω e)
    // (the closed form of x = v t e^(−ωt); 20 % and 20 µm more for the strip's push on the
    // wheel and the torque held over each tick: 0.85-0.87 of it in four runs on 2026-12-07),
    // and the wheel stays on the strip, pressing (about 4 N of the 10).
    let stop = events(&rec, EventKind::SafeStop).iter().map(|(k, _)| *k).find(|k| *k >= stall_from).expect("a safe stop in the stall");
    let row = |k: u64| rec.strip.iter().find(|r| r.tick == k).expect("a strip row");
    let (z0, v0) = (row(stop).wheel_z_m, (row(stop).wheel_z_m - row(stop - 1).wheel_z_m) / rec.period_s());
    let held: Vec<_> = rec.strip.iter().filter(|r| r.tick >= stop && r.tick < stall_to).collect();
    let reach = held.iter().map(|r| (r.wheel_z_m - z0).abs()).fold(0.0, f64::max);
    let weakest = held.iter().map(|r| -r.contact_force_n).fold(f64::INFINITY, f64::min);
    let w = 2.0 * std::f64::consts::PI * scenarios::Scenario::default().loop_.hold_bandwidth_hz;
    let bound = v0.abs() / (w * std::f64::consts::E);
    eprintln!(
        "safe stop at tick {stop}: wheel at {:.3} mm, {:.2} mm/s; over {} held ticks it went at most {:.3} mm from there (closed form {:.3} mm); weakest press {weakest:.2} N",
        z0 * 1e3, v0 * 1e3, held.len(), reach * 1e3, bound * 1e3
    );
    c.check(held.len() >= 900, || format!("{} ticks of the safe stop inside a 1 s stall", held.len()));
    c.check(reach <= 1.2 * bound + 20e-6, || {
        format!("the hold let the wheel go {reach} m from where the stop began (closed form {bound} m)")
    });
    c.check(weakest > 1.0, || format!("the wheel stays on the strip through the hold: weakest press {weakest} N"));
    // The summary says the same of the stop (`recording_tools::stop_holds`).
    let holds = recording_tools::stop_holds::stop_holds(&rec);
    eprintln!("{holds:?}");
    c.check(holds.len() == 1, || format!("one safe stop, one stop hold: {holds:?}"));
    if let Some(h) = holds.first() {
        c.check(run.daemon.stdout().contains(&h.line(rec.period_s())), || {
            format!("the summary prints the stop hold's line: {}", run.logs())
        });
        // Measured from the same row (the tick before the first state in safe stop is the safe
        // stop event's); the ticks it spans may differ from this test's by one at either end.
        c.check((h.wheel_reach_m - reach).abs() <= 50e-6, || format!("the stop hold's reach {} m against {reach} m", h.wheel_reach_m));
        c.check((h.weakest_press_n - weakest).abs() <= 0.05, || {
            format!("the stop hold's press {} N against {weakest} N", h.weakest_press_n)
        });
    }
    c.done();
}

/// Needs the controller changes (bumpless entry into force control). The default scenario in
/// lockstep: the largest per-tick change of any applied joint torque over the whole run is at
/// most 15 N m (issue 11: 404 N m at force-control onset before).
// needs the controller changes
#[test]
fn the_default_lockstep_run_has_no_torque_step_above_15_nm() {
    let _g = serial();
    let rig = unique_rig("steps");
    let dir = temp_dir(&rig);
    let mut run = RigRun::start(&dir, &default_scenario(), &["--mode", "lockstep"]);
    let st = run.finish();
    assert!(matches!(st.code(), Some(0 | 4)), "{}", run.logs());
    let rec = run.recording();
    let last = rec.joint_torque.last().map_or(0, |r| r.tick);
    let (step, at, j) = largest_step(&rec, 0, last);
    let onset = rec.controller.iter().find(|d| d.force_control_active != 0).map(|d| d.tick);
    eprintln!(
        "largest per-tick torque step {step:.3} N m on joint {j} at tick {at} (force control from tick {onset:?}), {} ticks",
        rec.joint_torque.len()
    );
    assert!(step <= 15.0, "joint {j} steps {step:.3} N m at tick {at} (force control from tick {onset:?})");
}

/// Needs the controller changes (liveness without false alarms). Real time, robot only: the plant
/// is stopped (SIGSTOP) for 300 ms, then continued. The controller must wait for it (a silent
/// living peer is waited for up to `loop.peer_stall_timeout_s`, 5 s) and the run completes: the
/// plant reaches its end and the controller exits 0 after the plant's goodbye.
// needs the controller changes
#[test]
fn a_plant_stopped_for_300_ms_does_not_end_the_controller() {
    let _g = serial();
    let t = TestRig::new("sigstop-plant", "realtime");
    let (mut plant, mut ctrl) = t.running(2.0);
    std::thread::sleep(Duration::from_millis(500));
    plant.signal(libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(300));
    plant.signal(libc::SIGCONT);
    let ps = plant.expect_exit(LONG);
    let cs = ctrl.expect_exit(Duration::from_secs(10));
    eprintln!(
        "plant {ps}, controller {cs}; controller's log:\n{}",
        ctrl.stderr().lines().filter(|l| !l.contains("INFO")).collect::<Vec<_>>().join("\n")
    );
    assert!(ps.success(), "plant: {}", plant.stderr());
    let summary = plant_summary(&plant);
    assert_eq!(summary["stopped_by_signal"], false, "{summary}");
    assert!(cs.success(), "the controller ended ({cs}) although the plant was only stopped for 300 ms:\n{}", ctrl.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    assert_eq!(rec.joint_state.len(), 2000);
}

/// Real time, robot only: the plant is stopped for 5 ms every 20 ms for 1 s (about 50 stalls,
/// each an overrun). Every overrun is recorded in `/events`, but the plant's SCHED_FIFO thread
/// writes at most one log line about them per second of ticks (it wrote one per overrun).
#[test]
fn a_stalling_host_s_overruns_are_all_recorded_but_logged_once_a_second() {
    let _g = serial();
    let t = TestRig::new("overrun-log", "realtime");
    let (mut plant, mut ctrl) = t.running(3.0);
    std::thread::sleep(Duration::from_millis(500));
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(1) {
        plant.signal(libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(5));
        plant.signal(libc::SIGCONT);
        std::thread::sleep(Duration::from_millis(15));
    }
    let ps = plant.expect_exit(LONG);
    let _ = ctrl.expect_exit(Duration::from_secs(10));
    assert!(ps.success(), "plant: {}", plant.stderr());
    let rec = Recording::open_complete(t.recording()).unwrap();
    let recorded = rec.events.iter().filter(|e| e.text.contains("periods") && e.text.contains("skipped")).count();
    let logged = plant.stderr().lines().filter(|l| l.contains("skipped") && l.contains("periods")).count();
    eprintln!("{recorded} overrun events recorded, {logged} log lines");
    assert!(recorded >= 20, "about 50 stalls of 5 ms should give as many overruns, recorded {recorded}");
    // 3 s of ticks: at most one line per second, and a line for the first overrun.
    assert!((1..=3).contains(&logged), "{logged} overrun log lines for {recorded} overruns:\n{}", plant.stderr());
}
