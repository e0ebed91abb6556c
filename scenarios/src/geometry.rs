//! The rig's geometry as a scenario places it (DESIGN section 3), in one place: the strip's
//! height, the task frame, the tool, the robot models built with it, the tool-down orientation and
//! the start pose. The plant, the controller, the recorder's scene and the design tools all take
//! them from here, so the two sides of the rig cannot disagree about where the strip lies, what
//! the TCP is or what arm they move (the plant's mismatch is applied on top of the shared model).
//!
//! Frames and signs: messages/README.md, "Frames and signs".

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use robot::{Robot, Tool, Vec6};

use crate::Scenario;

/// Height of the strip's top at its centre line above its bottom (task y), m: the 4 mm
/// rectangle plus the 4 mm half-disc of DESIGN section 4. The plant's contact surface at rest.
pub const STRIP_TOP_HEIGHT_M: f64 = 0.008;

/// Task frame (DESIGN section 3): origin at the strip's start, bottom centre; x across the strip,
/// y the strip normal (up), z along the strip. The strip lies on a table along base +x, so
/// task z = base x, task y = base z, task x = base y; `scenario.placement` gives the origin.
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

    /// The task frame's pose in the base frame (the recording's `task` transform).
    pub fn pose_in_base(&self) -> Isometry3<f64> {
        let rot = nalgebra::Rotation3::from_matrix_unchecked(self.rot_base_task);
        Isometry3::from_parts(Translation3::from(self.origin_base_m), UnitQuaternion::from_rotation_matrix(&rot))
    }
}

/// The tool of the scenario: mass, TCP offset and wheel radius from `scenario.robot`, inertia of
/// the documented default tool scaled with the mass ([`Tool::wheel_on_bracket`]). As the
/// scenario field says, the TCP is the wheel centre, `robot.tool_offset_m` along flange z; the
/// wheel's lowest point lies one radius below it when the tool points down. Plant and controller
/// both build their robot with this tool.
pub fn tool(s: &Scenario) -> Tool {
    Tool::wheel_on_bracket(s.robot.tool_mass_kg, s.robot.tool_offset_m, s.robot.wheel_radius_mm * 1e-3)
}

/// The tool as the controller believes it: [`tool`] with `[mismatch]`'s errors of mass, centre
/// and inertia (the same tool when there are none).
pub fn controller_tool(s: &Scenario) -> Tool {
    let mut t = tool(s);
    let m = &s.mismatch;
    if !m.is_none() {
        t.mass_kg *= 1.0 + m.tool_mass_error;
        t.com_flange_m += Vector3::from(m.tool_com_error_m);
        t.inertia_com *= 1.0 + m.tool_inertia_error;
    }
    t
}

/// The scenario's arm carrying `tool`, with `[robot]`'s armature and viscous friction: the one
/// construction every model of the rig starts from ([`nominal_robot`], [`controller_robot`],
/// [`plant_robot`]).
pub fn robot_with_tool(s: &Scenario, tool: Tool) -> Robot {
    Robot::irb2400_with_tool(tool).with_armature(Vec6::from(s.robot.armature_kgm2)).with_viscous(Vec6::from(s.robot.viscous_nms))
}

/// The arm as the scenario describes it, with its true [`tool`] and no mismatch of any side: the
/// EGM servo's model (the robot controller of a real cell knows its arm, not the plant's errors).
pub fn nominal_robot(s: &Scenario) -> Robot {
    robot_with_tool(s, tool(s))
}

/// The force controller's robot model: the arm with the tool it believes ([`controller_tool`]),
/// deliberately WITHOUT `robot.plant_inertia_scale` and `[mismatch] link_inertia_scale` (the
/// plant's side of the mismatch, like `[drives]`).
pub fn controller_robot(s: &Scenario) -> Robot {
    robot_with_tool(s, controller_tool(s))
}

/// The plant's robot: [`nominal_robot`] with the plant's mismatch on top, every mass and inertia
/// scaled by `robot.plant_inertia_scale`, then each link's by `[mismatch] link_inertia_scale`.
pub fn plant_robot(s: &Scenario) -> Robot {
    let robot = nominal_robot(s).scaled_inertia(s.robot.plant_inertia_scale);
    if s.mismatch.link_inertia_scale == [1.0; 6] {
        robot
    } else {
        robot.scaled_links(&s.mismatch.link_inertia_scale)
    }
}

/// Tool orientation of the whole run, base frame: pointing straight down, wheel axis across the
/// strip ([`robot::tool_down_pose`]'s rotation by π about base x).
pub fn tool_down_rotation() -> Matrix3<f64> {
    robot::tool_down_pose(0.0, 0.0, 0.0).rotation.to_rotation_matrix().into_inner()
}

/// Start position of the TCP (wheel centre) in task coordinates: the wheel's lowest point
/// `trajectory.approach_height_mm` above the undeformed strip top at task z =
/// `trajectory.z_start_mm`, centred on the strip; the TCP one wheel radius higher.
pub fn start_tcp_task_m(s: &Scenario) -> Vector3<f64> {
    let t = &s.trajectory;
    Vector3::new(0.0, STRIP_TOP_HEIGHT_M + t.approach_height_mm * 1e-3 + s.robot.wheel_radius_mm * 1e-3, t.z_start_mm * 1e-3)
}

/// The start pose of the TCP in the base frame, tool pointing down: [`start_tcp_task_m`]'s
/// point (the plant starts at rest in its IK). A straight strip's: along a contour the plant
/// starts at `crate::path::start_tcp_pose`.
pub fn start_tcp_pose(s: &Scenario) -> Isometry3<f64> {
    let task = TaskFrame::from_scenario(s);
    let t = &s.trajectory;
    // On the strip top at z_start, then up by the approach height and the wheel radius, summed
    // in that order (the order the plant's start pose has always been computed in).
    let up = |d: f64| task.vector_to_base(&Vector3::new(0.0, d, 0.0));
    let p = task.point_to_base(&Vector3::new(0.0, STRIP_TOP_HEIGHT_M, t.z_start_mm * 1e-3))
        + up(t.approach_height_mm * 1e-3)
        + up(s.robot.wheel_radius_mm * 1e-3);
    robot::tool_down_pose(p.x, p.y, p.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix6;

    #[test]
    fn task_frame_is_a_proper_rotation_and_round_trips() {
        let f = TaskFrame::from_scenario(&Scenario::default());
        assert!((f.rot_base_task.determinant() - 1.0).abs() < 1e-15);
        let p = Vector3::new(0.001, 0.002, 0.03);
        assert!((f.point_to_task(&f.point_to_base(&p)) - p).norm() < 1e-15);
        // Task z runs along base x from the strip start; task y is base z (up).
        let b = f.point_to_base(&Vector3::new(0.0, 0.01, 0.02));
        assert!((b - Vector3::new(0.90, 0.0, 0.71)).norm() < 1e-12, "{b}");
        let pose = f.pose_in_base();
        assert!((pose * nalgebra::Point3::from(p)).coords.metric_distance(&f.point_to_base(&p)) < 1e-15);
    }

    /// The three models are one construction with each side's mismatch on top: without
    /// mismatch they are the same arm; `robot.plant_inertia_scale` moves only the plant's mass,
    /// `mismatch.tool_mass_error` only the controller's tool; armature sits on M's diagonal.
    #[test]
    fn plant_and_controller_models_differ_by_their_own_mismatch_only() {
        let mut s = Scenario::default();
        let q = Vec6::new(0.1, -1.2, 0.3, 0.2, -0.4, 0.5);
        let m0 = nominal_robot(&s).total_mass_kg();
        let g0 = nominal_robot(&s).gravity_torque(&q);
        assert_eq!(controller_robot(&s).gravity_torque(&q), g0);
        assert_eq!(plant_robot(&s).gravity_torque(&q), g0);
        s.robot.armature_kgm2 = [0.5, 0.4, 0.3, 0.02, 0.02, 0.01];
        let armature = Vec6::from(s.robot.armature_kgm2);
        let bare = Robot::irb2400_with_tool(tool(&s)).mass_matrix(&q);
        assert!((nominal_robot(&s).mass_matrix(&q) - bare - Matrix6::from_diagonal(&armature)).norm() < 1e-12);

        s.robot.plant_inertia_scale = 1.1;
        s.mismatch.tool_mass_error = 0.2;
        assert_eq!(nominal_robot(&s).total_mass_kg(), m0);
        assert!((plant_robot(&s).total_mass_kg() - 1.1 * m0).abs() < 1e-12 * m0);
        let want = m0 + 0.2 * s.robot.tool_mass_kg;
        assert!((controller_robot(&s).total_mass_kg() - want).abs() < 1e-12 * m0, "{} vs {want}", controller_robot(&s).total_mass_kg());
        s.mismatch.link_inertia_scale[1] = 1.5;
        assert!(plant_robot(&s).total_mass_kg() > 1.1 * m0 + 1.0, "the link's scale comes on top");
        assert!((controller_robot(&s).total_mass_kg() - want).abs() < 1e-12 * m0);
    }

    #[test]
    fn the_start_pose_is_the_start_point_with_the_tool_down() {
        let s = Scenario::default();
        let pose = start_tcp_pose(&s);
        let want = TaskFrame::from_scenario(&s).point_to_base(&start_tcp_task_m(&s));
        assert!((pose.translation.vector - want).norm() < 1e-15, "{pose} vs {want}");
        assert!((pose.rotation.to_rotation_matrix().into_inner() - tool_down_rotation()).norm() < 1e-15);
        // 3 mm above the 8 mm strip on the 0.70 m table, TCP one 10 mm radius higher.
        assert!((want - Vector3::new(0.882, 0.0, 0.721)).norm() < 1e-12, "{want}");
    }
}
