//! Inverse kinematics and conditioning at the default scenario's task pose (DESIGN section 3).

use nalgebra::Vector3;
use robot::{ik_seed_tool_down, tool_down_pose, IkError, Robot, Tool, Vec6};

/// Wheel centre (the TCP) one wheel radius above the strip top (table at 0.70 m plus the 8 mm
/// strip), along base x from 0.88 m as the wheel rolls over task z = 2 .. 38 mm.
fn scenario_targets() -> impl Iterator<Item = (f64, f64, f64)> {
    let radius = Tool::default().wheel_radius_m;
    (0..=9).map(move |k| (0.88 + 0.002 + 0.004 * k as f64, 0.0, 0.708 + radius))
}

#[test]
fn contact_point_touches_the_strip_when_tcp_is_one_radius_above() {
    let tool = Tool::default();
    let robot = Robot::irb2400_with_tool(tool);
    let (x, y, z) = scenario_targets().next().unwrap();
    let q = robot.ik_tcp(&tool_down_pose(x, y, z), &ik_seed_tool_down()).unwrap();
    let flange = robot.flange_pose(&q);
    let contact = flange * nalgebra::Point3::from(tool.contact_point_flange_m());
    assert!((contact.coords - Vector3::new(x, y, 0.708)).norm() < 1e-9, "{contact}");
}

#[test]
fn ik_round_trips_fk_along_the_strip() {
    let robot = Robot::irb2400_with_tool(Tool::default());
    for (x, y, z) in scenario_targets() {
        let target = tool_down_pose(x, y, z);
        let q = robot.ik_tcp(&target, &ik_seed_tool_down()).expect("scenario pose reachable");
        let reached = robot.tcp_pose(&q);
        assert!((reached.translation.vector - target.translation.vector).norm() < 1e-9);
        assert!(reached.rotation.angle_to(&target.rotation) < 1e-9);
        // The branch of the DESIGN remark: joints 1, 4, 6 at zero, elbow up (upper arm leaning
        // forward from vertical by less than 90 deg), wrist not flipped (q5 > 0).
        for j in [0, 3, 5] {
            assert!(q[j].abs() < 1e-9, "joint {} = {}", j + 1, q[j]);
        }
        assert!(q[1] > -std::f64::consts::FRAC_PI_2 && q[1] < 0.0, "q2 = {}", q[1]);
        assert!(q[4] > 0.0, "q5 = {}", q[4]);
        // Tool axis straight down, wheel axis (flange y) across the strip (base y).
        let rot = reached.rotation;
        assert!((rot * Vector3::z() + Vector3::z()).norm() < 1e-9);
        assert!((rot * Vector3::y()).x.abs() < 1e-9 && (rot * Vector3::y()).z.abs() < 1e-9);
    }
}

#[test]
fn ik_round_trips_fk_from_perturbed_seeds() {
    // Any configuration near the scenario: FK, then IK from a perturbed seed, recovers it.
    let robot = Robot::irb2400_with_tool(Tool::default());
    let q_true = Vec6::new(0.1, -1.2, 0.4, 0.2, 0.9, -0.3);
    let target = robot.tcp_pose(&q_true);
    let seed = q_true + Vec6::new(0.05, -0.04, 0.03, -0.05, 0.04, 0.05);
    let q = robot.ik_tcp(&target, &seed).unwrap();
    assert!((q - q_true).amax() < 1e-8, "{q:?}");
}

#[test]
fn ik_reports_unreachable_targets() {
    let robot = Robot::irb2400_with_tool(Tool::default());
    let far = tool_down_pose(3.0, 0.0, 0.7);
    match robot.ik_tcp(&far, &ik_seed_tool_down()) {
        Err(IkError::NotConverged { position_error_m, .. }) => assert!(position_error_m > 0.5),
        other => panic!("expected NotConverged, got {other:?}"),
    }
    let nan = tool_down_pose(f64::NAN, 0.0, 0.7);
    assert_eq!(robot.ik_tcp(&nan, &ik_seed_tool_down()), Err(IkError::NotFinite));
}

#[test]
fn jacobian_is_well_conditioned_at_the_scenario_pose() {
    // DESIGN section 3: condition number about 4.4 there.
    let robot = Robot::irb2400_with_tool(Tool::default());
    for (x, y, z) in scenario_targets() {
        let q = robot.ik_tcp(&tool_down_pose(x, y, z), &ik_seed_tool_down()).unwrap();
        let sv = robot.jacobian_tcp(&q).singular_values();
        let cond = sv.max() / sv.min();
        assert!((cond - 4.4).abs() < 0.2, "cond(J_tcp) = {cond} at x = {x}");
    }
}
