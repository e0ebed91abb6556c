//! Rigid-body dynamics of (7.1), `M(q) qdd + C(q, qd) qd + g(q) = tau` (external wrench left to
//! the caller as `J^T F_e`): recursive Newton-Euler and composite rigid body algorithm, both in
//! the links' own frames (`newton_euler.rs`), forward dynamics by CRBA + L D L^T Cholesky.

use crate::model::Robot;
use crate::newton_euler::{sin_cos, SinCos};
use crate::{Mat6, Vec6};

impl Robot {
    /// Inverse dynamics (7.1) without external wrench: `M qdd + C qd + g + armature qdd +
    /// viscous qd`.
    pub fn rnea(&self, q: &Vec6, qd: &Vec6, qdd: &Vec6) -> Vec6 {
        self.rnea_local(&sin_cos(q), qd, qdd, Self::GRAVITY_MPS2) + self.armature.component_mul(qdd) + self.viscous.component_mul(qd)
    }

    /// Gravity torque `g(q)` of (7.1).
    pub fn gravity_torque(&self, q: &Vec6) -> Vec6 {
        self.rnea_local(&sin_cos(q), &Vec6::zeros(), &Vec6::zeros(), Self::GRAVITY_MPS2)
    }

    /// The Coriolis and centrifugal torque vector `C(q, q̇) q̇` of (7.1), not the matrix C: RNEA
    /// with zero acceleration and no gravity (no friction; Pinocchio's `nonLinearEffects` minus g).
    pub fn coriolis_times_qd(&self, q: &Vec6, qd: &Vec6) -> Vec6 {
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

    /// Joint-space mass matrix `M(q)` by the composite rigid body algorithm, armature included.
    pub fn mass_matrix(&self, q: &Vec6) -> Mat6 {
        self.crba_local(&sin_cos(q))
    }

    /// Mass matrix and bias torque `C qd + g + viscous qd` from one kinematics pass; what a
    /// controller needs for (7.2).
    pub fn mass_matrix_and_bias(&self, q: &Vec6, qd: &Vec6) -> (Mat6, Vec6) {
        let sc = sin_cos(q);
        let m = self.crba_local(&sc);
        let bias = self.rnea_local(&sc, qd, &Vec6::zeros(), Self::GRAVITY_MPS2) + self.viscous.component_mul(qd);
        (m, bias)
    }

    /// Forward dynamics: `qdd = M^-1 (tau - C qd - g - viscous qd)` by CRBA and a Cholesky
    /// solve. M is symmetric positive definite with condition number ~1e5-1e6 (the small wrist
    /// inertias); Cholesky is backward stable, so f64 keeps qdd to ~1e-10 relative (tested).
    pub fn forward_dynamics(&self, q: &Vec6, qd: &Vec6, tau: &Vec6) -> Vec6 {
        self.forward_dynamics_sc(&sin_cos(q), qd, tau)
    }

    /// [`Robot::forward_dynamics`] at the q of `sc` ([`crate::sin_cos`]): the same numbers, for a
    /// caller that already needed them (the plant takes the frames and the first stage's
    /// dynamics at one q in each substep).
    #[inline]
    pub fn forward_dynamics_sc(&self, sc: &SinCos, qd: &Vec6, tau: &Vec6) -> Vec6 {
        let m = self.crba_local(sc);
        let bias = self.rnea_local(sc, qd, &Vec6::zeros(), Self::GRAVITY_MPS2) + self.viscous.component_mul(qd);
        cholesky_solve(m, tau - bias)
    }

    /// The two halves of [`Robot::forward_dynamics_sc`] for an integrator that reuses them: the
    /// factor of `M(q)` and the rigid-body bias `C(q, q̇) q̇ + g(q)` (no viscous friction) at the
    /// q of `sc`. `factor.solve(&(tau - bias - self.friction_torque(qd)))` is the forward dynamics.
    #[inline]
    pub fn dynamics_parts_sc(&self, sc: &SinCos, qd: &Vec6) -> (MassFactor, Vec6) {
        (MassFactor::new(&self.crba_local(sc)), self.rnea_local(sc, qd, &Vec6::zeros(), Self::GRAVITY_MPS2))
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

/// Solve `M x = b` for symmetric positive definite `M` by an unrolled square-root-free
/// Cholesky factorisation `M = L D L^T` (lower triangle of `M` read); NaN if `M` is not
/// positive definite.
#[inline(always)]
pub fn cholesky_solve(m: Mat6, b: Vec6) -> Vec6 {
    MassFactor::new(&m).solve(&b)
}

/// The `L D L^T` factor of a mass matrix ([`cholesky_solve`] in two halves): factor once, solve
/// for several right-hand sides (the plant's integrator reuses one factor for a second stage).
#[derive(Debug, Clone, Copy)]
pub struct MassFactor {
    /// Unit lower triangle L (below the diagonal) and 1/D.
    l: [[f64; 6]; 6],
    inv_d: [f64; 6],
    /// False when `M` was not positive definite: every solve is NaN.
    ok: bool,
}

impl MassFactor {
    /// Factor symmetric positive definite `m` (its lower triangle is read).
    #[inline(always)]
    pub fn new(m: &Mat6) -> MassFactor {
        // Plain arrays: constant loop bounds let the compiler drop every bounds check.
        let mut l = [[0.0f64; 6]; 6];
        let mut inv_d = [0.0f64; 6];
        let mut diag = [0.0f64; 6];
        for j in 0..6 {
            // ld[k] = L_jk D_k
            let mut ld = [0.0f64; 6];
            let mut d = m[(j, j)];
            for k in 0..j {
                ld[k] = l[j][k] * diag[k];
                d -= l[j][k] * ld[k];
            }
            // Also catches NaN pivots.
            if d.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return MassFactor { l, inv_d, ok: false };
            }
            let inv = 1.0 / d;
            diag[j] = d;
            inv_d[j] = inv;
            for i in (j + 1)..6 {
                let mut v = m[(i, j)];
                for k in 0..j {
                    v -= l[i][k] * ld[k];
                }
                l[i][j] = v * inv;
            }
        }
        MassFactor { l, inv_d, ok: true }
    }

    /// `M^-1 b`; NaN if `M` was not positive definite.
    #[inline(always)]
    pub fn solve(&self, b: &Vec6) -> Vec6 {
        if !self.ok {
            return Vec6::from_element(f64::NAN);
        }
        let (l, inv_d) = (&self.l, &self.inv_d);
        let mut x = [0.0f64; 6];
        for i in 0..6 {
            let mut v = b[i];
            for k in 0..i {
                v -= l[i][k] * x[k];
            }
            x[i] = v;
        }
        for i in (0..6).rev() {
            let mut v = x[i] * inv_d[i];
            for k in (i + 1)..6 {
                v -= l[k][i] * x[k];
            }
            x[i] = v;
        }
        Vec6::from(x)
    }
}
