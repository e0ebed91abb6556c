//! Inverse kinematics of the TCP pose: damped Newton (Levenberg-Marquardt) on the 6D pose
//! error, started from a seed that picks the branch (elbow up, wrist not flipped for the
//! scenario seed). Fixed-size and allocation-free.

use nalgebra::{Cholesky, Isometry3, UnitQuaternion, Vector3};

use crate::model::Robot;
use crate::{Mat6, Vec6};

/// Why [`Robot::ik_tcp`] found no solution.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IkError {
    #[error("IK target or seed is not finite")]
    NotFinite,
    #[error(
        "IK did not converge in {iterations} iterations: position error {position_error_m:.3e} m, \
         orientation error {orientation_error_rad:.3e} rad (target out of reach or seed on another branch?)"
    )]
    NotConverged { iterations: usize, position_error_m: f64, orientation_error_rad: f64 },
    #[error("IK solution puts joint {joint} at {value_rad:.4} rad, outside its limits [{lower_rad:.4}, {upper_rad:.4}] rad")]
    OutsideLimits { joint: usize, value_rad: f64, lower_rad: f64, upper_rad: f64 },
}

/// Position tolerance of the IK solution (m).
pub const IK_POSITION_TOL_M: f64 = 1e-10;
/// Orientation tolerance of the IK solution (rad).
pub const IK_ORIENTATION_TOL_RAD: f64 = 1e-10;
const IK_MAX_ITERATIONS: usize = 200;

impl Robot {
    /// Pose error `(target - current)` as `(position, rotation vector)` in base axes.
    fn pose_error(&self, target: &Isometry3<f64>, q: &Vec6) -> (Vec6, Mat6) {
        let frames = self.frames(q);
        let p = self.tcp_position(&frames);
        let e_p = target.translation.vector - p;
        let r_current = nalgebra::Rotation3::from_matrix_unchecked(frames.rot[6]);
        let r_err = target.rotation.to_rotation_matrix() * r_current.transpose();
        let e_r: Vector3<f64> = UnitQuaternion::from_rotation_matrix(&r_err).scaled_axis();
        let e = Vec6::new(e_p.x, e_p.y, e_p.z, e_r.x, e_r.y, e_r.z);
        (e, self.jacobian_point(&frames, &p))
    }

    /// Joint angles putting the TCP at `target` (base frame), found by damped Newton from
    /// `seed`; the result is the solution on the seed's branch.
    pub fn ik_tcp(&self, target: &Isometry3<f64>, seed: &Vec6) -> Result<Vec6, IkError> {
        let finite = target.translation.vector.iter().chain(target.rotation.coords.iter()).all(|x| x.is_finite());
        if !finite || !seed.iter().all(|x| x.is_finite()) {
            return Err(IkError::NotFinite);
        }
        let weighted_norm = |e: &Vec6| e.norm();
        let mut q = *seed;
        let (mut e, mut jac) = self.pose_error(target, &q);
        let mut lambda = 1e-3;
        for _ in 0..IK_MAX_ITERATIONS {
            if e.fixed_rows::<3>(0).norm() < IK_POSITION_TOL_M && e.fixed_rows::<3>(3).norm() < IK_ORIENTATION_TOL_RAD {
                return self.check_limits(q);
            }
            // dq = J^T (J J^T + lambda^2 I)^-1 e, step length capped at 0.3 rad.
            let jjt = jac * jac.transpose() + Mat6::from_diagonal_element(lambda * lambda);
            let Some(chol) = Cholesky::new(jjt) else {
                lambda *= 10.0;
                continue;
            };
            let mut dq = jac.transpose() * chol.solve(&e);
            let step = dq.amax();
            if step > 0.3 {
                dq *= 0.3 / step;
            }
            let q_try = q + dq;
            let (e_try, jac_try) = self.pose_error(target, &q_try);
            if weighted_norm(&e_try) < weighted_norm(&e) {
                q = q_try;
                e = e_try;
                jac = jac_try;
                lambda = (lambda * 0.1).max(1e-12);
            } else {
                lambda = (lambda * 10.0).min(1e3);
            }
        }
        Err(IkError::NotConverged {
            iterations: IK_MAX_ITERATIONS,
            position_error_m: e.fixed_rows::<3>(0).norm(),
            orientation_error_rad: e.fixed_rows::<3>(3).norm(),
        })
    }

    fn check_limits(&self, q: Vec6) -> Result<Vec6, IkError> {
        for (j, [lower_rad, upper_rad]) in Self::POSITION_LIMIT_RAD.iter().copied().enumerate() {
            if q[j] < lower_rad || q[j] > upper_rad {
                return Err(IkError::OutsideLimits { joint: j + 1, value_rad: q[j], lower_rad, upper_rad });
            }
        }
        Ok(q)
    }
}
