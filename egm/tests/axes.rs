//! The ABB axis <-> DH joint mapping (`egm::axes`) against the robot model and ABB's data.

use egm::axes::{abb_deg_from_dh, dh_from_abb_deg};
use robot::{Robot, Vec6};

#[test]
fn abb_zero_is_the_dh_zero_pose_of_design_section_3() {
    assert_eq!(dh_from_abb_deg(&[0.0; 6]), Robot::ABB_ZERO_Q);
}

#[test]
fn dh_joint_axes_at_abb_zero_are_abbs_axes_with_their_signs() {
    // ABB's axes at its zero pose, positive by the right-hand rule (product specification; the
    // ROS-Industrial irb2400 description: z, y, y, x, y, x).
    let abb_axes = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];
    let f = Robot::irb2400().frames(&Vec6::from(dh_from_abb_deg(&[0.0; 6])));
    for (j, a) in abb_axes.iter().enumerate() {
        let z = f.joint_axis(j);
        let d = z.x * a[0] + z.y * a[1] + z.z * a[2];
        assert!((d - egm::axes::SIGN[j]).abs() < 1e-12, "axis {}: DH axis {z:?}, ABB axis {a:?}", j + 1);
    }
}

#[test]
fn wrist_centre_and_flange_at_abb_zero_are_the_datasheet_positions() {
    // IRB 2400 product specification, working range figure: wrist centre (axis 5) at
    // x = 855 mm, z = 1455 mm at the zero pose; the flange 85 mm further along x.
    let r = Robot::irb2400();
    let q = Vec6::from(dh_from_abb_deg(&[0.0; 6]));
    let f = r.frames(&q);
    let wc = f.pose(5).translation.vector;
    assert!((wc - nalgebra::Vector3::new(0.855, 0.0, 1.455)).norm() < 1e-9, "wrist centre {wc:?}");
    let fl = r.flange_pose(&q);
    assert!((fl.translation.vector - nalgebra::Vector3::new(0.940, 0.0, 1.455)).norm() < 1e-9, "flange {:?}", fl.translation);
    // the flange's z axis (axis 6) points along base +x at ABB's zero
    assert!((fl.rotation * nalgebra::Vector3::z() - nalgebra::Vector3::x()).norm() < 1e-12);
    // axis 3 at +90 deg turns the upper arm straight down: the wrist centre 755 mm below the
    // elbow, x = 100 + 135 mm
    let q = Vec6::from(dh_from_abb_deg(&[0.0, 0.0, 90.0, 0.0, 0.0, 0.0]));
    let wc = r.frames(&q).pose(5).translation.vector;
    assert!((wc - nalgebra::Vector3::new(0.100 + 0.135, 0.0, 0.615 + 0.705 - 0.755)).norm() < 1e-9, "axis 3 at 90 deg: {wc:?}");
}

#[test]
fn dh_position_limits_are_abbs_axis_ranges() {
    // product specification: axis 1 +-180, axis 2 -100..+110, axis 3 -60..+65, axis 4 +-200,
    // axis 5 +-120, axis 6 +-400 degrees
    let abb = [[-180.0, 180.0], [-100.0, 110.0], [-60.0, 65.0], [-200.0, 200.0], [-120.0, 120.0], [-400.0, 400.0]];
    let lo = abb_deg_from_dh(&std::array::from_fn(|i| Robot::POSITION_LIMIT_RAD[i][0]));
    let hi = abb_deg_from_dh(&std::array::from_fn(|i| Robot::POSITION_LIMIT_RAD[i][1]));
    for i in 0..6 {
        assert!((lo[i] - abb[i][0]).abs() < 1e-9 && (hi[i] - abb[i][1]).abs() < 1e-9, "axis {}: {} .. {}", i + 1, lo[i], hi[i]);
    }
}

#[test]
fn mapping_round_trips() {
    let th = [12.5, -33.0, 40.25, 170.0, -95.0, 301.0];
    let back = abb_deg_from_dh(&dh_from_abb_deg(&th));
    for i in 0..6 {
        assert!((back[i] - th[i]).abs() < 1e-12);
    }
}
