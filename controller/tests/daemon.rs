//! The daemon against an in-process fake plant (rig_process::ports::PlantPorts): it answers every
//! tick with the tick's number, exits cleanly on ShuttingDown, and exits with an error naming
//! both versions on a contract mismatch and when the plant falls silent.

use std::thread;
use std::time::{Duration, Instant};

use controller::daemon::{run, DaemonConfig};
use messages::{JointState, PlantStatus, Wrench, WrenchFrame, CONTRACT_VERSION};
use rig_process::ports::{PlantPorts, Wake};
use scenarios::Scenario;

fn unique_rig(tag: &str) -> String {
    let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos();
    format!("ctl-{tag}-{}-{}", std::process::id(), n % 1_000_000_000)
}

fn start_q() -> [f64; 6] {
    // IK of the scenario start pose with the controller's own model.
    let s = Scenario::default();
    let robot = controller::step::controller_robot(&s);
    robot.ik_tcp(&scenarios::geometry::start_tcp_pose(&s), &robot::ik_seed_tool_down()).unwrap().into()
}

fn state(tick: u64, status: PlantStatus, q: [f64; 6]) -> JointState {
    JointState::at_rest(tick, status, q)
}

fn wrench(tick: u64) -> Wrench {
    Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::SensorAtTcp as u32, tick, force: [0.0; 3], torque: [0.0; 3] }
}

fn spawn(rig: &str, version: u32, dead: Duration) -> thread::JoinHandle<anyhow::Result<controller::daemon::DaemonSummary>> {
    spawn_with(rig, version, dead, Scenario::default())
}

fn spawn_with(
    rig: &str,
    version: u32,
    dead: Duration,
    scenario: Scenario,
) -> thread::JoinHandle<anyhow::Result<controller::daemon::DaemonSummary>> {
    let mut cfg = DaemonConfig::new(rig, scenario);
    cfg.contract_version = version;
    cfg.startup_timeout = Duration::from_secs(5);
    cfg.dead_plant_timeout = dead;
    thread::spawn(move || run(&cfg))
}

/// Publish until the controller's ports exist and it answers tick 0.
fn lockstep_ticks(plant: &PlantPorts, n: u64, q: [f64; 6]) -> Vec<messages::JointTorque> {
    lockstep_range(plant, 0..n, q)
}

/// Publish each tick of `ticks` until the controller answers it.
fn lockstep_range(plant: &PlantPorts, ticks: std::ops::Range<u64>, q: [f64; 6]) -> Vec<messages::JointTorque> {
    let mut out = Vec::new();
    for tick in ticks {
        let t_end = Instant::now() + Duration::from_secs(5);
        loop {
            plant.publish(&state(tick, PlantStatus::Running, q), &wrench(tick)).unwrap();
            if plant.wait_torque(Instant::now() + Duration::from_millis(50)) == Wake::Notified {
                if let Some(t) = plant.receive_torque_for(tick) {
                    out.push(t);
                    break;
                }
            }
            assert!(Instant::now() < t_end, "no answer for tick {tick}");
        }
    }
    out
}

#[test]
fn answers_every_tick_and_exits_on_shutdown() {
    let rig = unique_rig("ok");
    let plant = PlantPorts::open(&rig, "fake-plant").unwrap();
    let h = spawn(&rig, CONTRACT_VERSION, Duration::from_secs(5));
    let q = start_q();
    let torques = lockstep_ticks(&plant, 20, q);
    assert_eq!(torques.len(), 20);
    // At rest at the start pose with no wrench: gravity compensation of the controller's model.
    let s = Scenario::default();
    let g = controller::step::controller_robot(&s).gravity_torque(&robot::Vec6::from(q));
    let tau = robot::Vec6::from(torques[0].tau);
    assert!((tau - g).norm() < 1e-6 * g.norm(), "{tau} vs {g}");
    assert!(plant.receive_diagnostics().is_some());
    plant.publish(&state(20, PlantStatus::ShuttingDown, q), &wrench(20)).unwrap();
    let summary = h.join().unwrap().expect("clean exit on ShuttingDown");
    assert_eq!(summary.ticks_answered, 20);
}

#[test]
fn version_mismatch_exits_with_both_versions() {
    let rig = unique_rig("ver");
    let plant = PlantPorts::open(&rig, "fake-plant").unwrap();
    let h = spawn(&rig, CONTRACT_VERSION + 7, Duration::from_secs(5));
    let t_end = Instant::now() + Duration::from_secs(5);
    while !h.is_finished() && Instant::now() < t_end {
        plant.publish(&state(0, PlantStatus::Running, start_q()), &wrench(0)).unwrap();
        thread::sleep(Duration::from_millis(20));
    }
    let e = h.join().unwrap().unwrap_err().to_string();
    assert!(e.contains(&format!("version {}", CONTRACT_VERSION)) && e.contains(&format!("version {}", CONTRACT_VERSION + 7)), "{e}");
}

/// A plant that falls silent but stays alive (its node lives: a stalled host, SIGSTOP) is waited
/// for up to `loop.peer_stall_timeout_s`, not declared dead after 100 ms of silence.
#[test]
fn silent_but_living_plant_is_waited_for_up_to_the_stall_timeout() {
    let rig = unique_rig("stall");
    let plant = PlantPorts::open(&rig, "fake-plant").unwrap();
    let mut s = Scenario::default();
    s.loop_.peer_stall_timeout_s = 0.6;
    let h = spawn_with(&rig, CONTRACT_VERSION, Duration::from_millis(100), s);
    lockstep_ticks(&plant, 3, start_q());
    let silent_from = Instant::now();
    // Then silence, with the plant's node alive.
    let e = h.join().unwrap().unwrap_err().to_string();
    let waited = silent_from.elapsed();
    assert!(e.contains("after tick 2: the plant is alive but stalled"), "{e}");
    assert!(waited >= Duration::from_millis(600), "gave up after {waited:?}, before the stall timeout");
    drop(plant);
}

/// A plant whose publisher is gone (its ports dropped; a killed process's node is dead) ends the
/// controller at the first silence, without waiting for the stall timeout.
#[test]
fn gone_plant_is_detected_at_the_first_silence() {
    let rig = unique_rig("dead");
    let plant = PlantPorts::open(&rig, "fake-plant").unwrap();
    let h = spawn(&rig, CONTRACT_VERSION, Duration::from_millis(100));
    lockstep_ticks(&plant, 3, start_q());
    let gone_at = Instant::now();
    drop(plant);
    let e = h.join().unwrap().unwrap_err().to_string();
    assert!(e.contains("after tick 2: the plant died"), "{e}");
    // Correctness, not timing: it did not wait for the default 5 s stall timeout.
    assert!(gone_at.elapsed() < Duration::from_secs(4), "{:?}", gone_at.elapsed());
}

/// A controller answers the plant it first connected to: another plant's states on the same rig
/// (a second plant-sim, a replay tool), its goodbye included, are not its own and do not end it.
#[test]
fn another_plants_goodbye_does_not_end_the_controller() {
    let rig = unique_rig("other");
    let plant = PlantPorts::open(&rig, "fake-plant").unwrap();
    let h = spawn(&rig, CONTRACT_VERSION, Duration::from_secs(5));
    let q = start_q();
    lockstep_ticks(&plant, 3, q);
    let other = PlantPorts::open(&rig, "other-plant").unwrap();
    for _ in 0..5 {
        other.publish(&state(3, PlantStatus::ShuttingDown, q), &wrench(3)).unwrap();
        thread::sleep(Duration::from_millis(20));
    }
    assert!(!h.is_finished(), "the other plant's goodbye ended the controller");
    // Its own plant goes on, and its own goodbye ends it cleanly.
    assert_eq!(lockstep_range(&plant, 3..6, q).len(), 3);
    let t_end = Instant::now() + Duration::from_secs(5);
    while !h.is_finished() && Instant::now() < t_end {
        plant.publish(&state(6, PlantStatus::ShuttingDown, q), &wrench(6)).unwrap();
        thread::sleep(Duration::from_millis(20));
    }
    let summary = h.join().unwrap().expect("exits Ok on its own plant's goodbye");
    assert_eq!(summary.last_tick, 5);
    drop(other);
}
