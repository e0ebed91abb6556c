//! Where the strip lies, straight or along a contour (issue 26), in one place for the plant and
//! the controller: the strip's own coordinates ("path coordinates": x across the strip to the
//! left, y its normal up from the table, z the arc length along it) to and from the base frame.
//! A straight strip's path coordinates are its task frame's (`geometry::TaskFrame`, the same
//! bits); a contour's moving frame at arc length s is the task frame of a straight strip laid
//! along its tangent there (`contour.rs`, "Frames").

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};

use crate::contour::{Contour, ReachError};
use crate::geometry::TaskFrame;
use crate::Scenario;

/// The strip's path in the base frame.
#[derive(Debug, Clone, PartialEq)]
pub enum StripPath {
    /// Along base +x from `[placement]`'s start: path coordinates are task coordinates.
    Straight(TaskFrame),
    /// Along a contour on the table at base z `table_z_m`, its arc length the strip's z.
    Contour { contour: Arc<Contour>, table_z_m: f64 },
}

impl StripPath {
    /// The scenario's path. A contour is checked when the scenario loads (`fields.rs`), so one
    /// that fails to build here is a scenario made in code without that check: a bug.
    pub fn from_scenario(s: &Scenario) -> StripPath {
        if s.contour.is_given() {
            let contour = Contour::from_scenario(s).unwrap_or_else(|e| panic!("[contour] was not checked: {e}"));
            StripPath::Contour { contour: Arc::new(contour), table_z_m: s.placement.table_z_m }
        } else {
            StripPath::Straight(TaskFrame::from_scenario(s))
        }
    }

    /// The contour, if the strip follows one.
    pub fn contour(&self) -> Option<&Contour> {
        match self {
            StripPath::Straight(_) => None,
            StripPath::Contour { contour, .. } => Some(contour),
        }
    }

    /// The frame of the strip at arc length `s_m`: the fixed task frame of a straight strip, the
    /// moving frame of a contour (origin on the contour at table height, task z its tangent, task x
    /// to the left, task y up).
    pub fn frame_at(&self, s_m: f64) -> TaskFrame {
        match self {
            StripPath::Straight(task) => *task,
            StripPath::Contour { contour, table_z_m } => {
                let p = contour.at(s_m);
                let ([tx, ty], [lx, ly]) = (p.tangent(), p.left());
                #[rustfmt::skip]
                let rot_base_task = Matrix3::new(
                    lx,  0.0, tx,
                    ly,  0.0, ty,
                    0.0, 1.0, 0.0,
                );
                TaskFrame { rot_base_task, origin_base_m: Vector3::new(p.xy_base_m[0], p.xy_base_m[1], *table_z_m) }
            }
        }
    }

    /// Path coordinates of the base point `p_base_m`: (lateral offset, height over the table, arc
    /// length). On a closed contour the arc length is the lap nearest `s_hint_m` (the previous
    /// tick's: a strip that overlaps its start goes on past the contour's length).
    pub fn to_path(&self, p_base_m: &Vector3<f64>, s_hint_m: f64) -> Vector3<f64> {
        match self {
            StripPath::Straight(task) => task.point_to_task(p_base_m),
            StripPath::Contour { contour, table_z_m } => {
                let (mut s, lateral) = contour.project_near([p_base_m.x, p_base_m.y], s_hint_m);
                if contour.is_closed() {
                    let l = contour.length_m();
                    s += ((s_hint_m - s) / l).round() * l;
                }
                Vector3::new(lateral, p_base_m.z - table_z_m, s)
            }
        }
    }

    /// The base point of path coordinates `p_path_m` (lateral, height, arc length).
    pub fn point_to_base(&self, p_path_m: &Vector3<f64>) -> Vector3<f64> {
        match self {
            StripPath::Straight(task) => task.point_to_base(p_path_m),
            StripPath::Contour { .. } => self.frame_at(p_path_m.z).point_to_base(&Vector3::new(p_path_m.x, p_path_m.y, 0.0)),
        }
    }

    /// The strip-normal (task y, up) component of the base vector `v_base`.
    #[inline]
    pub fn normal_velocity(&self, v_base: &Vector3<f64>) -> f64 {
        match self {
            StripPath::Straight(task) => task.vector_to_task(v_base).y,
            StripPath::Contour { .. } => v_base.z,
        }
    }

    /// Heading of the strip's tangent at `s_m` (rad, from base +x towards +y) and its signed
    /// curvature (1/m): 0 and 0 on a straight strip.
    pub fn heading_at(&self, s_m: f64) -> (f64, f64) {
        match self {
            StripPath::Straight(_) => (0.0, 0.0),
            StripPath::Contour { contour, .. } => {
                let p = contour.at(s_m);
                (p.heading_rad, p.curvature_per_m)
            }
        }
    }
}

/// The scenario's reach check along its contour: the roll from `trajectory.z_start_mm` to
/// `z_end_mm` with the wheel on the undeformed strip, the arm the scenario's, seeded from the IK of
/// the start pose as the plant seeds it.
pub fn reach_along(s: &Scenario, contour: &Contour) -> Result<(), ReachError> {
    let robot = crate::geometry::nominal_robot(s);
    let tcp_z = s.placement.table_z_m + crate::geometry::STRIP_TOP_HEIGHT_M + s.robot.wheel_radius_mm * 1e-3;
    let (from, to) = (s.trajectory.z_start_mm * 1e-3, s.trajectory.z_end_mm * 1e-3);
    let seed = robot
        .ik_tcp(&contour.tcp_pose(from, tcp_z), &robot::ik_seed_tool_down())
        .map_err(|e| ReachError { s_m: from, why: format!("the start pose: {e}") })?;
    contour.joints_along(&robot, tcp_z, from, to, &seed).map(|_| ())
}

/// The start pose of the TCP in the base frame: [`crate::geometry::start_tcp_pose`] on a straight
/// strip; over a contour, [`crate::geometry::start_tcp_task_m`]'s point in path coordinates with
/// the tool turned about the normal by the heading there ([`Contour::tcp_pose`]). The plant starts
/// at rest in its IK.
pub fn start_tcp_pose(s: &Scenario) -> nalgebra::Isometry3<f64> {
    if !s.contour.is_given() {
        return crate::geometry::start_tcp_pose(s);
    }
    let path = StripPath::from_scenario(s);
    let c = path.contour().expect("a contour");
    let p = path.point_to_base(&crate::geometry::start_tcp_task_m(s));
    c.tcp_pose(s.trajectory.z_start_mm * 1e-3, p.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sunroof() -> Scenario {
        let mut s = Scenario::default();
        s.placement.strip_start_x_m = 0.9;
        s.placement.strip_y_m = -0.125;
        s.contour.closed = true;
        s.contour.pieces = vec![
            [150.0, 0.0, 0.0],
            [0.0, 50.0, 90.0],
            [150.0, 0.0, 0.0],
            [0.0, 50.0, 90.0],
            [300.0, 0.0, 0.0],
            [0.0, 50.0, 90.0],
            [150.0, 0.0, 0.0],
            [0.0, 50.0, 90.0],
            [150.0, 0.0, 0.0],
        ];
        s
    }

    /// A straight strip's path coordinates are the task frame's, bit for bit.
    #[test]
    fn a_straight_path_is_the_task_frame() {
        let s = Scenario::default();
        let (path, task) = (StripPath::from_scenario(&s), TaskFrame::from_scenario(&s));
        let p = Vector3::new(0.91, 0.003, 0.72);
        assert_eq!(path.to_path(&p, 0.0), task.point_to_task(&p));
        assert_eq!(path.frame_at(0.3), task);
        assert_eq!(path.point_to_base(&Vector3::new(0.001, 0.01, 0.02)), task.point_to_base(&Vector3::new(0.001, 0.01, 0.02)));
    }

    /// On the contour: at heading 0 the moving frame is the straight task frame at that point;
    /// everywhere it is a proper rotation; path coordinates round-trip through the base, and a
    /// point past the start of a closed contour keeps counting from the lap the hint says.
    #[test]
    fn contour_path_coordinates_round_trip_and_unwrap_past_the_start() {
        let s = sunroof();
        let path = StripPath::from_scenario(&s);
        let f0 = path.frame_at(0.05);
        let straight = TaskFrame::from_scenario(&s);
        assert!((f0.rot_base_task - straight.rot_base_task).norm() < 1e-15);
        assert!((f0.origin_base_m - Vector3::new(0.95, -0.125, 0.70)).norm() < 1e-12);
        let l = path.contour().unwrap().length_m();
        for k in 0..200 {
            let z = k as f64 * l / 200.0 + 1e-4;
            let f = path.frame_at(z);
            assert!((f.rot_base_task.determinant() - 1.0).abs() < 1e-12);
            let p = Vector3::new(0.003, 0.012, z);
            let back = path.to_path(&path.point_to_base(&p), z);
            assert!((back - p).norm() < 1e-9, "z {z}: {back} vs {p}");
        }
        // 4 mm past the start, one lap on: z = L + 4 mm, not 4 mm.
        let p = path.point_to_base(&Vector3::new(0.0, 0.008, l + 0.004));
        assert!((path.to_path(&p, l).z - (l + 0.004)).abs() < 1e-9);
        assert!((path.to_path(&p, 0.0).z - 0.004).abs() < 1e-9);
    }
}
