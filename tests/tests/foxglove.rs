//! A real lockstep run of the default scenario (plant-sim + controller over iceoryx2) read with
//! Foxglove's own TypeScript libraries (`recordings/ts/check_foxglove.ts`: `@mcap/core` with
//! `@mcap/support`'s zstd, `@foxglove/rosmsg2-serialization`, the protobuf definitions of
//! `@foxglove/schemas` through protobufjs). This test makes the expectations independently: the
//! run's wall-clock window, the robot crate's forward kinematics of the recorded q, the strip
//! mesh's top node count. `.ci/deps` installs the npm packages (`npm ci` in `recordings/ts`);
//! without them the test fails.

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use harness::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use recording_tools::read::Recording;

fn pose_json(p: &Isometry3<f64>) -> serde_json::Value {
    let (t, r) = (p.translation.vector, p.rotation);
    serde_json::json!([t.x, t.y, t.z, r.i, r.j, r.k, r.w])
}

#[test]
fn foxglove_libraries_read_the_robot_the_strip_and_the_timeline_of_a_real_run() {
    let ts_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../recordings/ts");
    let tsx = ts_dir.join("node_modules/.bin/tsx");
    // .ci/run installs them; a check that skipped itself would pass without checking anything.
    assert!(tsx.is_file(), "{} missing: run `npm ci --prefix recordings/ts` (as .ci/run does)", tsx.display());
    let rig = unique_rig("fox");
    let dir = temp_dir(&rig);
    let scenario_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let scenario = scenarios::Scenario::load(&scenario_path).unwrap();
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
    let tool = scenarios::geometry::tool(&scenario);
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

    // Lockstep determinism: a second run gives the same payload bytes on every channel, the
    // Foxglove ones once their timestamps (the run's start + simulated time) are taken out.
    let rig2 = unique_rig("fox2");
    let dir2 = temp_dir(&rig2);
    let mut plant = start_plant(&rig2, &scenario_path, &dir2, 3.6, &["--mode", "lockstep"]);
    let mut ctrl = start_controller("controller", "controller", &rig2, &scenario_path, &dir2, &[]);
    assert!(plant.expect_exit(Duration::from_secs(300)).success(), "plant failed: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller failed: {}", ctrl.stderr());
    let (a, b) = (payloads(&path), payloads(&dir2.join("run.mcap")));
    assert_eq!(a.len(), b.len());
    assert!(a.iter().any(|(t, _)| t == "/strip_scene") && a.iter().any(|(t, _)| t == "/tf"));
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(x == y, "message {k} on {} differs between two lockstep runs", x.0);
    }

    let out = Command::new(&tsx).current_dir(&ts_dir).arg("check_foxglove.ts").arg(&path).arg(&expect_path).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{stdout}{stderr}");
    assert!(out.status.success(), "the Foxglove check failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains(" passed, 0 failed"), "{stdout}");
}

/// (topic, payload) of every message, in file order; the Foxglove messages with their
/// timestamps zeroed, `/joint_torque` without the controller's process id, `/controller` without
/// its compute time; left out: `/timing`
/// (wall clocks), `/events` and `/log` (their texts name the controller's process id).
fn payloads(path: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    use foxglove::messages::{FrameTransforms, SceneUpdate};
    use foxglove::{Decode, Encode};
    let bytes = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        let mut data = Vec::new();
        match topic.as_str() {
            "/timing" | "/robot_description" | "/events" | "/log" => continue,
            "/joint_torque" => {
                let mut row = recordings::schema::decode_joint_torque(&m.data).unwrap();
                row.torque.controller_id = 0;
                data = format!("{row:?}").into_bytes();
            }
            "/controller" => {
                let mut d = recordings::schema::decode_controller(&m.data).unwrap();
                d.compute_time_ns = 0;
                data = format!("{d:?}").into_bytes();
            }
            "/tf" => {
                let mut msg = FrameTransforms::decode(&m.data[..]).unwrap();
                msg.transforms.iter_mut().for_each(|t| t.timestamp = None);
                msg.encode(&mut data).unwrap();
            }
            "/strip_scene" => {
                let mut msg = SceneUpdate::decode(&m.data[..]).unwrap();
                msg.entities.iter_mut().for_each(|e| e.timestamp = None);
                msg.encode(&mut data).unwrap();
            }
            _ => data = m.data.into_owned(),
        }
        out.push((topic, data));
    }
    out
}
