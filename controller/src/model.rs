//! The controller's view of the rig: the robot model built from the scenario (without the plant's
//! inertia scale) and the task frame of DESIGN section 3.

use nalgebra::{Matrix3, Vector3};
use robot::{Robot, Tool, Vec6};
use scenario::Scenario;

pub use scenario::STRIP_TOP_HEIGHT_M;

/// The tool of the scenario: mass, TCP offset and wheel radius from `scenario.robot`; inertia of
/// the documented default tool scaled with the mass. As the scenario field says and the plant
/// does (`plant_sim::physics::tool_from_scenario`, the same rule: both sides must agree), the TCP
/// is the wheel centre, `robot.tool_offset_m` along flange z; the wheel's lowest point lies one
/// radius below it when the tool points down.
pub fn tool_from_scenario(s: &Scenario) -> Tool {
    Tool::wheel_on_bracket(s.robot.tool_mass_kg, s.robot.tool_offset_m, s.robot.wheel_radius_mm * 1e-3)
}

/// The controller's robot model: the scenario's arm and tool with armature and viscous friction,
/// deliberately WITHOUT `robot.plant_inertia_scale` (that is the plant's mismatch).
pub fn controller_robot(s: &Scenario) -> Robot {
    Robot::irb2400_with_tool(tool_from_scenario(s))
        .with_armature(Vec6::from(s.robot.armature_kgm2))
        .with_viscous(Vec6::from(s.robot.viscous_nms))
}

/// Task frame (DESIGN section 3): origin at the strip's start, bottom centre; x across the strip,
/// y the strip normal (up), z along the strip. With the default placement task z = base x,
/// task y = base z, task x = base y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskFrame {
    /// Columns: the task axes x, y, z in base coordinates.
    pub rot_base_task: Matrix3<f64>,
    /// Task origin in the base frame, m.
    pub origin_base_m: Vector3<f64>,
}

impl TaskFrame {
    /// The task frame of `scenario.placement`.
    pub fn from_scenario(s: &Scenario) -> TaskFrame {
        let p = &s.placement;
        #[rustfmt::skip]
        let rot_base_task = Matrix3::new(
            0.0, 0.0, 1.0,
            1.0, 0.0, 0.0,
            0.0, 1.0, 0.0,
        );
        TaskFrame { rot_base_task, origin_base_m: Vector3::new(p.strip_start_x_m, p.strip_y_m, p.table_z_m) }
    }

    /// A point given in task coordinates, in base coordinates.
    #[inline]
    pub fn point_to_base(&self, p_task: &Vector3<f64>) -> Vector3<f64> {
        self.origin_base_m + self.rot_base_task * p_task
    }

    /// A point given in base coordinates, in task coordinates.
    #[inline]
    pub fn point_to_task(&self, p_base: &Vector3<f64>) -> Vector3<f64> {
        self.rot_base_task.transpose() * (p_base - self.origin_base_m)
    }

    /// A free vector (velocity, force) from base to task axes.
    #[inline]
    pub fn vector_to_task(&self, v_base: &Vector3<f64>) -> Vector3<f64> {
        self.rot_base_task.transpose() * v_base
    }

    /// A free vector from task to base axes.
    #[inline]
    pub fn vector_to_base(&self, v_task: &Vector3<f64>) -> Vector3<f64> {
        self.rot_base_task * v_task
    }
}

/// Tool orientation of the whole run: pointing straight down, wheel axis across the strip
/// (`robot::scenario_tcp_pose`'s rotation by pi about base x).
pub fn tool_down_rotation() -> Matrix3<f64> {
    robot::scenario_tcp_pose(0.0, 0.0, 0.0).rotation.to_rotation_matrix().into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn task_frame_is_a_proper_rotation_and_round_trips() {
        let f = TaskFrame::from_scenario(&Scenario::default());
        assert!((f.rot_base_task.determinant() - 1.0).abs() < 1e-15);
        let p = Vector3::new(0.001, 0.002, 0.03);
        assert!((f.point_to_task(&f.point_to_base(&p)) - p).norm() < 1e-15);
        // Task z runs along base x from the strip start; task y is base z (up).
        let b = f.point_to_base(&Vector3::new(0.0, 0.01, 0.02));
        assert!((b - Vector3::new(0.90, 0.0, 0.71)).norm() < 1e-12, "{b}");
    }

    #[test]
    fn controller_robot_ignores_plant_inertia_scale() {
        let mut s = Scenario::default();
        let a = controller_robot(&s).total_mass_kg();
        s.robot.plant_inertia_scale = 1.1;
        assert_eq!(controller_robot(&s).total_mass_kg(), a);
    }
}
