//! The URDF against the robot's forward kinematics, and the committed file against the generator.

use robot::urdf::{chain, chain_from_fk, urdf};
use robot::{Robot, Tool, Vec6};

const POSES: [[f64; 6]; 3] = [[0.0, -1.3, 0.5, 0.0, 0.8, 0.0], [0.4, -1.0, 0.2, 0.7, -0.6, 1.1], [-1.2, -2.0, -0.5, -2.5, 1.3, -3.0]];

#[test]
fn the_urdf_chain_is_the_forward_kinematics_at_three_poses() {
    let tool = Tool::default();
    let robot = Robot::irb2400_with_tool(tool);
    for q in POSES {
        let q = Vec6::from(q);
        let (urdf_edges, fk_edges) = (chain(&q, &tool), chain_from_fk(&robot, &q));
        let mut world = nalgebra::Isometry3::identity();
        for (k, (u, f)) in urdf_edges.iter().zip(&fk_edges).enumerate() {
            assert!((u.translation.vector - f.translation.vector).norm() < 1e-12, "edge {k} at {q:?}");
            assert!(u.rotation.angle_to(&f.rotation) < 1e-12, "edge {k} at {q:?}");
            world *= u;
        }
        let tcp = robot.tcp_pose(&q);
        assert!((world.translation.vector - tcp.translation.vector).norm() < 1e-12);
        assert!(world.rotation.angle_to(&tcp.rotation) < 1e-12);
        // DH frame 6 (the flange) is the chain up to `flange`.
        let flange = urdf_edges[..7].iter().fold(nalgebra::Isometry3::identity(), |a, b| a * b);
        assert!((flange.translation.vector - robot.frames(&q).pos[6]).norm() < 1e-12);
    }
}

#[test]
fn the_committed_urdf_is_the_generated_one() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/urdf/irb2400_wheel.urdf");
    let text = urdf(&Tool::default());
    if std::env::var_os("UPDATE_URDF").is_some() {
        std::fs::write(path, &text).unwrap();
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(committed == text, "{path} is out of date: UPDATE_URDF=1 cargo test -p robot --test urdf");
}
