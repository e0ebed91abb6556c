//! The rig's tool-down pose (DESIGN section 3): the tool points straight down with the wheel axis
//! along base y, across a strip that runs along base +x, and the IK seed of that branch. Where
//! the strip lies is the scenario's (`scenarios::geometry`).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::Vec6;

/// TCP pose with the tool pointing straight down at base point `(x_m, y_m, z_m)`.
///
/// Orientation: TCP/flange z = base -z (the tool axis, pointing down), x = base +x (along the
/// strip), y = base -y (the wheel axis, across the strip); i.e. a rotation by pi about base x.
/// This is the orientation reached from ABB's zero pose by tilting joint 5 forward, with joints
/// 1, 4, 6 at zero (the non-flipped wrist).
pub fn tool_down_pose(x_m: f64, y_m: f64, z_m: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x_m, y_m, z_m), UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI))
}

/// Seed for [`crate::Robot::ik_tcp`] near the tool-down pose over the strip: elbow up, wrist not flipped,
/// joints 1, 4, 6 at zero.
pub const IK_SEED_TOOL_DOWN: [f64; 6] = [0.0, -1.3, 0.5, 0.0, 0.8, 0.0];

/// [`IK_SEED_TOOL_DOWN`] as a vector.
pub fn ik_seed_tool_down() -> Vec6 {
    Vec6::from(IK_SEED_TOOL_DOWN)
}
