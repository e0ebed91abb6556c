//! A real lockstep run of the default scenario (plant-sim + controller over iceoryx2) read with
//! Foxglove's own TypeScript libraries (`recordings/ts/check_foxglove.ts`: `@mcap/core` with
//! `@mcap/support`'s zstd, `@foxglove/rosmsg2-serialization`, the protobuf definitions of
//! `@foxglove/schemas` through protobufjs). This test makes the expectations independently: the
//! run's wall-clock window, the robot crate's forward kinematics of the recorded q, the strip
//! mesh's top node count. `.ci/run` installs the npm packages (`npm ci` in `recordings/ts`);
//! without them the test prints `SKIP:`.

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use recordings::read::Recording;
use rig_tests::*;

fn pose_json(p: &Isometry3<f64>) -> serde_json::Value {
    let (t, r) = (p.translation.vector, p.rotation);
    serde_json::json!([t.x, t.y, t.z, r.i, r.j, r.k, r.w])
}

#[test]
fn foxglove_libraries_read_the_robot_the_strip_and_the_timeline_of_a_real_run() {
    let ts_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../recordings/ts");
    let tsx = ts_dir.join("node_modules/.bin/tsx");
    if !tsx.is_file() {
        println!("SKIP: foxglove: {} missing (cd recordings/ts && npm ci)", tsx.display());
        return;
    }
    let rig = unique_rig("fox");
    let dir = temp_dir(&rig);
    let scenario_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let scenario = scenario::Scenario::load(&scenario_path).unwrap();
    let before = wall_ns();
    let mut plant = start_plant(&rig, &scenario_path, &dir, 3.6, &["--mode", "lockstep"]);
    let mut ctrl = start_controller("controller", "controller", &rig, &scenario_path, &dir, &[]);
    assert!(plant.expect_exit(Duration::from_secs(300)).success(), "plant failed: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller failed: {}", ctrl.stderr());
    let after = wall_ns();
    let path = dir.join("run.mcap");
    let rec = Recording::open_complete(&path).unwrap();
    assert_eq!(rec.joint_state.len(), 3600);

    // The robot crate's FK of the recorded q at every scene tick (every 10th at 100 Hz).
    let tool = plant_sim::physics::tool_from_scenario(&scenario);
    let robot = robot::Robot::irb2400_with_tool(tool);
    let every = (1.0 / (scenario.recording.scene_rate_hz * scenario.loop_.period_s)).round() as u64;
    let mut tcp = serde_json::Map::new();
    let scene_ticks: Vec<&messages::JointState> = rec.joint_state.iter().filter(|s| s.tick % every == 0).collect();
    for s in &scene_ticks {
        tcp.insert(s.tick.to_string(), pose_json(&robot.tcp_pose(&robot::Vec6::from(s.q))));
    }
    // Every URDF link frame at three poses: link i is DH frame i-1 turned by q_i (robot::urdf).
    let poses: Vec<serde_json::Value> = [0, scene_ticks.len() / 2, scene_ticks.len() - 1]
        .iter()
        .map(|&k| {
            let s = scene_ticks[k];
            let q = robot::Vec6::from(s.q);
            let f = robot.frames(&q);
            let mut frames = serde_json::Map::new();
            for i in 1..=6 {
                let link = f.pose(i - 1) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), q[i - 1]);
                frames.insert(format!("link{i}"), pose_json(&link));
            }
            frames.insert("flange".into(), pose_json(&f.pose(6)));
            frames.insert("tcp".into(), pose_json(&robot.tcp_pose(&q)));
            serde_json::json!({ "tick": s.tick, "q": s.q.to_vec(), "frames": frames })
        })
        .collect();
    // Joint 1 and the wrist moved between the poses checked (not one pose thrice).
    assert_ne!(poses[0]["q"], poses[2]["q"]);
    let mesh = strip::mesh::Mesh::build(scenario.strip.length_mm * 1e-3, scenario.strip.element_mm * 1e-3);
    let expect = serde_json::json!({
        "start_window_ns": [before.to_string(), after.to_string()],
        "strip_top_nodes": mesh.top_nodes().len(),
        "events": rec.events.len(),
        "tcp": tcp,
        "poses": poses,
    });
    let expect_path = dir.join("expect.json");
    std::fs::write(&expect_path, serde_json::to_string(&expect).unwrap()).unwrap();

    let out = Command::new(&tsx).current_dir(&ts_dir).arg("check_foxglove.ts").arg(&path).arg(&expect_path).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{stdout}{stderr}");
    assert!(out.status.success(), "the Foxglove check failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains(" passed, 0 failed"), "{stdout}");
}
