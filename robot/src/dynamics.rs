//! Rigid-body dynamics of (7.1), `M(q) qdd + C(q, qd) qd + g(q) = tau` (external wrench left to
//! the caller as `J^T F_e`): recursive Newton-Euler (in link frames, [`crate::newton_euler`]),
//! composite rigid body algorithm (spatial inertias in base axes about the base origin),
//! forward dynamics by CRBA + Cholesky.

use crate::kinematics::Frames;
use crate::model::Robot;
use crate::newton_euler::sin_cos;
use crate::spatial::{SpatialInertia, V3};
use crate::{Mat6, Vec6};

impl Robot {
    /// Spatial inertias of the six bodies (link 6 with the tool) about the base origin.
    #[inline(always)]
    fn body_inertias(&self, frames: &Frames) -> [SpatialInertia; 6] {
        let mut out = [SpatialInertia::default(); 6];
        for (i, body) in self.bodies.iter().enumerate() {
            out[i] = body.in_base(&frames.rot[i + 1], &frames.pos[i + 1]);
        }
        out
    }

    /// Inverse dynamics (7.1) without external wrench: `M qdd + C qd + g + armature qdd +
    /// viscous qd`.
    pub fn rnea(&self, q: &Vec6, qd: &Vec6, qdd: &Vec6) -> Vec6 {
        self.rnea_local(&sin_cos(q), qd, qdd, Self::GRAVITY_MPS2)
            + self.armature.component_mul(qdd)
            + self.viscous.component_mul(qd)
    }

    /// Gravity torque `g(q)` of (7.1).
    pub fn gravity_torque(&self, q: &Vec6) -> Vec6 {
        self.rnea_local(&sin_cos(q), &Vec6::zeros(), &Vec6::zeros(), Self::GRAVITY_MPS2)
    }

    /// Coriolis and centrifugal torque `C(q, qd) qd` of (7.1) (no friction).
    pub fn coriolis(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        self.rnea_local(&sin_cos(q), qd, &Vec6::zeros(), 0.0)
    }

    /// Viscous friction torque `viscous * qd` (zero by default).
    pub fn friction_torque(&self, qd: &Vec6) -> Vec6 {
        self.viscous.component_mul(qd)
    }

    /// Everything but `M qdd`: `C qd + g + viscous qd`.
    pub fn bias_torque(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
        self.rnea(q, qd, &Vec6::zeros())
    }

    /// Composite rigid body algorithm on given frames (armature included).
    #[inline(always)]
    fn crba_core(&self, frames: &Frames, inertias: &[SpatialInertia; 6]) -> Mat6 {
        let mut axes = [(V3::zeros(), V3::zeros()); 6];
        for (i, axis) in axes.iter_mut().enumerate() {
            let z = frames.joint_axis(i);
            *axis = (z, frames.pos[i].cross(&z));
        }
        let mut m = Mat6::zeros();
        let mut composite = SpatialInertia::default();
        for j in (0..6).rev() {
            composite.add(&inertias[j]);
            let (n, f) = composite.apply(&axes[j].0, &axes[j].1);
            for i in 0..=j {
                let mij = axes[i].0.dot(&n) + axes[i].1.dot(&f);
                m[(i, j)] = mij;
                m[(j, i)] = mij;
            }
            m[(j, j)] += self.armature[j];
        }
        m
    }

    /// Joint-space mass matrix `M(q)` by the composite rigid body algorithm, armature included.
    pub fn mass_matrix(&self, q: &Vec6) -> Mat6 {
        let frames = self.frames(q);
        let inertias = self.body_inertias(&frames);
        self.crba_core(&frames, &inertias)
    }

    /// Mass matrix and bias torque `C qd + g + viscous qd` from one kinematics pass; what a
    /// controller needs for (7.2).
    pub fn mass_matrix_and_bias(&self, q: &Vec6, qd: &Vec6) -> (Mat6, Vec6) {
        let sc = sin_cos(q);
        let frames = self.frames_from_sin_cos(&sc);
        let inertias = self.body_inertias(&frames);
        let m = self.crba_core(&frames, &inertias);
        let bias = self.rnea_local(&sc, qd, &Vec6::zeros(), Self::GRAVITY_MPS2) + self.viscous.component_mul(qd);
        (m, bias)
    }

    /// Forward dynamics: `qdd = M^-1 (tau - C qd - g - viscous qd)` by CRBA and a Cholesky
    /// solve (M is symmetric positive definite; condition number ~1e6 from the small wrist
    /// inertias, which Cholesky in f64 handles to ~1e-10 relative).
    pub fn forward_dynamics(&self, q: &Vec6, qd: &Vec6, tau: &Vec6) -> Vec6 {
        let (m, bias) = self.mass_matrix_and_bias(q, qd);
        cholesky_solve(m, tau - bias)
    }

    /// Kinetic energy `qd^T M qd / 2` (J), armature included.
    pub fn kinetic_energy(&self, q: &Vec6, qd: &Vec6) -> f64 {
        0.5 * qd.dot(&(self.mass_matrix(q) * qd))
    }

    /// Potential energy `sum m_i g z_ci` (J), zero at base height.
    pub fn potential_energy(&self, q: &Vec6) -> f64 {
        let frames = self.frames(q);
        (0..6)
            .map(|i| {
                let b = &self.bodies[i];
                let c = frames.pos[i + 1] + frames.rot[i + 1] * b.com;
                b.mass * Self::GRAVITY_MPS2 * c.z
            })
            .sum()
    }
}

/// Solve `M x = b` for symmetric positive definite `M` by an unrolled Cholesky factorisation
/// (`M = L L^T`, lower triangle of `M` read); NaN if `M` is not positive definite.
#[inline(always)]
pub fn cholesky_solve(m: Mat6, b: Vec6) -> Vec6 {
    // Plain arrays: constant loop bounds let the compiler drop every bounds check.
    let mut l = [[0.0f64; 6]; 6];
    let mut inv_diag = [0.0f64; 6];
    for j in 0..6 {
        let mut d = m[(j, j)];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if !(d > 0.0) {
            return Vec6::from_element(f64::NAN);
        }
        let inv = 1.0 / d.sqrt();
        inv_diag[j] = inv;
        for i in (j + 1)..6 {
            let mut v = m[(i, j)];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v * inv;
        }
    }
    let mut x = [0.0f64; 6];
    for i in 0..6 {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i][k] * x[k];
        }
        x[i] = v * inv_diag[i];
    }
    for i in (0..6).rev() {
        let mut v = x[i];
        for k in (i + 1)..6 {
            v -= l[k][i] * x[k];
        }
        x[i] = v * inv_diag[i];
    }
    Vec6::from(x)
}
