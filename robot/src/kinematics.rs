//! Forward kinematics, geometric Jacobians and the J-dot q-dot term, all in base axes.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

use crate::model::Robot;
use crate::newton_euler::{sin_cos, SinCos};
use crate::spatial::{M3, V3};
use crate::{Mat6, Vec6};

/// Every DH frame in the base frame: index 0 is the base, index `i` is DH frame `i` (the
/// distal frame of link `i`), index 6 is the flange. Joint `i` (1-based) turns about the z axis
/// of frame `i - 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frames {
    pub rot: [Matrix3<f64>; 7],
    pub pos: [Vector3<f64>; 7],
}

impl Frames {
    /// Frame `i` as an isometry (base frame).
    pub fn pose(&self, i: usize) -> Isometry3<f64> {
        to_isometry(&self.rot[i], &self.pos[i])
    }

    /// Axis of joint `j` (0-based), unit vector in base axes.
    #[inline(always)]
    pub fn joint_axis(&self, j: usize) -> V3 {
        self.rot[j].column(2).into_owned()
    }
}

pub(crate) fn to_isometry(rot: &M3, pos: &V3) -> Isometry3<f64> {
    let rotation = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(*rot));
    Isometry3::from_parts(Translation3::from(*pos), rotation)
}

impl Robot {
    /// Forward kinematics of every link frame (thesis Table 7.1, `A_i = Rz Tz Tx Rx`).
    #[inline(always)]
    pub fn frames(&self, q: &Vec6) -> Frames {
        self.frames_from_sin_cos(&sin_cos(q))
    }

    /// [`Robot::frames`] from the joints' `(sin, cos)` ([`crate::sin_cos`]), for a caller that
    /// evaluates several algorithms at one q (the same numbers as `frames(q)`).
    #[inline(always)]
    pub fn frames_from_sin_cos(&self, sc: &SinCos) -> Frames {
        let mut rot = [M3::identity(); 7];
        let mut pos = [V3::zeros(); 7];
        for i in 0..6 {
            let dh = &self.dh[i];
            let (st, ct) = sc[i];
            let (ca, sa) = (dh.cos_alpha, dh.sin_alpha);
            // R_i = R_{i-1} Rz(q_i) Rx(alpha_i), by columns; origin moves by R_{i-1} (a c, a s, d).
            let prev = &rot[i];
            let (x, y, z) = (prev.column(0), prev.column(1), prev.column(2));
            let x_new = x * ct + y * st;
            let y_rz = y * ct - x * st;
            pos[i + 1] = pos[i] + x_new * dh.a + z * dh.d;
            let y_new = y_rz * ca + z * sa;
            let z_new = z * ca - y_rz * sa;
            rot[i + 1] = M3::from_columns(&[x_new, y_new, z_new]);
        }
        Frames { rot, pos }
    }

    /// Pose of the flange (DH frame 6) in the base frame.
    pub fn flange_pose(&self, q: &Vec6) -> Isometry3<f64> {
        self.frames(q).pose(6)
    }

    /// Pose of the tool centre point in the base frame: the flange frame moved by the tool's TCP
    /// offset (the flange itself without a tool).
    pub fn tcp_pose(&self, q: &Vec6) -> Isometry3<f64> {
        let f = self.frames(q);
        to_isometry(&f.rot[6], &self.tcp_position(&f))
    }

    /// TCP position (base frame) for already computed frames.
    #[inline(always)]
    pub fn tcp_position(&self, frames: &Frames) -> V3 {
        frames.pos[6] + frames.rot[6] * self.tcp_flange_m
    }

    /// Geometric Jacobian of a point `p` (base frame) rigidly attached to link 6: rows
    /// `vx vy vz wx wy wz`, base axes.
    #[inline]
    pub fn jacobian_point(&self, frames: &Frames, p: &V3) -> Mat6 {
        let mut jac = Mat6::zeros();
        for j in 0..6 {
            let z = frames.joint_axis(j);
            let v = z.cross(&(p - frames.pos[j]));
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&v);
            jac.fixed_view_mut::<3, 1>(3, j).copy_from(&z);
        }
        jac
    }

    /// Geometric Jacobian of the flange origin, base axes, rows v then w.
    pub fn jacobian_flange(&self, q: &Vec6) -> Mat6 {
        let f = self.frames(q);
        self.jacobian_point(&f, &f.pos[6])
    }

    /// Geometric Jacobian of the TCP, base axes, rows v then w.
    pub fn jacobian_tcp(&self, q: &Vec6) -> Mat6 {
        let f = self.frames(q);
        self.jacobian_point(&f, &self.tcp_position(&f))
    }

    /// `J-dot q-dot` of a point rigidly attached to link 6: its classical (linear) acceleration
    /// and the link's angular acceleration at `qdd = 0`, base axes.
    pub fn jdot_qdot_point(&self, frames: &Frames, p: &V3, qd: &Vec6) -> Vec6 {
        // Spatial velocity and (qdd = 0) spatial acceleration of link 6 about the base origin.
        let (mut vw, mut vv, mut aw, mut av) = (V3::zeros(), V3::zeros(), V3::zeros(), V3::zeros());
        for j in 0..6 {
            let z = frames.joint_axis(j);
            let sv = frames.pos[j].cross(&z);
            vw += z * qd[j];
            vv += sv * qd[j];
            // a += v x (S qd): the derivative of the joint's motion subspace.
            aw += vw.cross(&z) * qd[j];
            av += (vw.cross(&sv) + vv.cross(&z)) * qd[j];
        }
        let vel_p = vv + vw.cross(p);
        let acc_p = av + aw.cross(p) + vw.cross(&vel_p);
        Vec6::new(acc_p.x, acc_p.y, acc_p.z, aw.x, aw.y, aw.z)
    }

    /// `J-dot(q, qd) qd` of the TCP (rows v then w, base axes), for (7.6).
    pub fn jdot_qdot_tcp(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        let f = self.frames(q);
        self.jdot_qdot_point(&f, &self.tcp_position(&f), qd)
    }

    /// `J-dot(q, qd) qd` of the flange origin (rows v then w, base axes).
    pub fn jdot_qdot_flange(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        let f = self.frames(q);
        self.jdot_qdot_point(&f, &f.pos[6], qd)
    }
}
