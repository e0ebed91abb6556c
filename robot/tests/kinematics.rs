//! Kinematics against closed forms and finite differences of FK.

mod common;

use common::{robots, Rng};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use robot::{Robot, Tool, Vec6};

#[test]
fn abb_zero_pose_matches_datasheet_geometry() {
    // ABB IRB 2400 datasheet: wrist centre 855 mm ahead of and 1455 mm above the base,
    // flange a further 85 mm forward.
    let robot = Robot::irb2400();
    let q = Vec6::from(Robot::ABB_ZERO_Q);
    let frames = robot.frames(&q);
    assert!((frames.pos[4] - Vector3::new(0.855, 0.0, 1.455)).norm() < 1e-12, "wrist {}", frames.pos[4]);
    assert!((frames.pos[5] - Vector3::new(0.855, 0.0, 1.455)).norm() < 1e-12);
    let flange = robot.flange_pose(&q);
    assert!((flange.translation.vector - Vector3::new(0.94, 0.0, 1.455)).norm() < 1e-12, "flange {}", flange.translation.vector);
    // Flange z points forward along base x at ABB's zero.
    let z6 = flange.rotation * Vector3::z();
    assert!((z6 - Vector3::x()).norm() < 1e-12);
}

#[test]
fn tcp_is_flange_moved_by_tool_offset() {
    let tool = Tool::default();
    let robot = Robot::irb2400_with_tool(tool);
    let mut rng = Rng::new(1);
    for _ in 0..20 {
        let q = rng.vec6(2.5);
        let flange = robot.flange_pose(&q);
        let tcp = robot.tcp_pose(&q);
        let expected = flange.translation.vector + flange.rotation * tool.tcp_offset_flange_m;
        assert!((tcp.translation.vector - expected).norm() < 1e-14);
        assert!(tcp.rotation.angle_to(&flange.rotation) < 1e-14);
        // Without a tool the TCP is the flange.
        let bare = Robot::irb2400();
        assert!((bare.tcp_pose(&q).translation.vector - bare.flange_pose(&q).translation.vector).norm() == 0.0);
    }
}

fn rotation_of(robot: &Robot, q: &Vec6) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(robot.frames(q).rot[6])
}

/// Central-difference Jacobian of the TCP pose: linear rows from positions, angular rows
/// from the rotation vector of `R(q + h e_j) R(q - h e_j)^T`.
fn numeric_jacobian_tcp(robot: &Robot, q: &Vec6, h: f64) -> robot::Mat6 {
    let mut jac = robot::Mat6::zeros();
    for j in 0..6 {
        let mut qp = *q;
        let mut qm = *q;
        qp[j] += h;
        qm[j] -= h;
        let dp = (robot.tcp_pose(&qp).translation.vector - robot.tcp_pose(&qm).translation.vector) / (2.0 * h);
        let dr = rotation_of(robot, &qp) * rotation_of(robot, &qm).transpose();
        let w = UnitQuaternion::from_rotation_matrix(&dr).scaled_axis() / (2.0 * h);
        for r in 0..3 {
            jac[(r, j)] = dp[r];
            jac[(r + 3, j)] = w[r];
        }
    }
    jac
}

#[test]
fn jacobians_match_finite_differences_of_fk() {
    let mut rng = Rng::new(2);
    for (name, robot) in robots() {
        for _ in 0..20 {
            let q = rng.vec6(2.5);
            let numeric = numeric_jacobian_tcp(&robot, &q, 1e-6);
            let analytic = robot.jacobian_tcp(&q);
            let err = (numeric - analytic).amax();
            assert!(err < 1e-8, "{name}: TCP Jacobian error {err:e} at q = {q:?}");
        }
    }
    // The flange Jacobian is the bare arm's TCP Jacobian.
    let bare = Robot::irb2400();
    let tooled = Robot::irb2400_with_tool(Tool::default());
    let q = Rng::new(3).vec6(2.0);
    assert_eq!(bare.jacobian_tcp(&q), tooled.jacobian_flange(&q));
    assert!((bare.jacobian_flange(&q) - numeric_jacobian_tcp(&bare, &q, 1e-6)).amax() < 1e-8);
}

#[test]
fn jdot_qdot_matches_finite_differences_of_jacobian() {
    let mut rng = Rng::new(4);
    for (name, robot) in robots() {
        for _ in 0..20 {
            let q = rng.vec6(2.5);
            let qd = rng.vec6(2.0);
            let h = 1e-6;
            // d/dt (J(q) qd) at constant qd, along q(t) = q + t qd.
            let numeric = (robot.jacobian_tcp(&(q + qd * h)) * qd - robot.jacobian_tcp(&(q - qd * h)) * qd) / (2.0 * h);
            let analytic = robot.jdot_qdot_tcp(&q, &qd);
            let err = (numeric - analytic).norm() / analytic.norm().max(1.0);
            assert!(err < 1e-7, "{name}: J-dot q-dot error {err:e}");
        }
    }
}

#[test]
fn frames_are_proper_rotations() {
    let robot = Robot::irb2400();
    let q = Rng::new(5).vec6(3.0);
    let frames = robot.frames(&q);
    for r in frames.rot.iter() {
        assert!((r.transpose() * r - Matrix3::identity()).amax() < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
    }
}
