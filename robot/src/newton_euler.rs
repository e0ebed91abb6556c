//! Recursive Newton-Euler (Luh-Walker-Paul form, e.g. Siciliano et al. (7.107)-(7.111)) and the
//! composite rigid body algorithm, both in the links' own DH frames: no per-call inertia
//! rotations into the base, only the structured rotations `Rz(q) Rx(alpha)` between
//! neighbouring frames. The fastest way here to evaluate (7.1) and (7.2).

use crate::model::{DhConst, Robot};
use crate::spatial::{BodyInertia, OriginInertia, V3};
use crate::{Mat6, Vec6};

/// `(sin q_i, cos q_i)` of all joints, computed once per call and shared.
pub type SinCos = [(f64, f64); 6];

#[inline(always)]
pub fn sin_cos(q: &Vec6) -> SinCos {
    let mut sc = [(0.0, 0.0); 6];
    for i in 0..6 {
        sc[i] = q[i].sin_cos();
    }
    sc
}

/// `R_i^T v`: a vector from frame `i-1` into frame `i`, `R_i = Rz(q_i) Rx(alpha_i)`.
#[inline(always)]
fn to_child(dh: &DhConst, (s, c): (f64, f64), v: &V3) -> V3 {
    let x = c * v.x + s * v.y;
    let y = -s * v.x + c * v.y;
    V3::new(x, dh.cos_alpha * y + dh.sin_alpha * v.z, -dh.sin_alpha * y + dh.cos_alpha * v.z)
}

/// `R_i v`: a vector from frame `i` into frame `i-1`.
#[inline(always)]
fn to_parent(dh: &DhConst, (s, c): (f64, f64), v: &V3) -> V3 {
    let y = dh.cos_alpha * v.y - dh.sin_alpha * v.z;
    let z = dh.sin_alpha * v.y + dh.cos_alpha * v.z;
    V3::new(c * v.x - s * y, s * v.x + c * y, z)
}

impl Robot {
    /// Rigid-body joint torques for `(q, qd, qdd)` with the base accelerating upwards at
    /// `gravity_mps2` (gravity); no armature, no friction.
    #[inline(always)]
    pub(crate) fn rnea_local(&self, sc: &SinCos, qd: &Vec6, qdd: &Vec6, gravity_mps2: f64) -> Vec6 {
        let (mut w, mut wd, mut a) = (V3::zeros(), V3::zeros(), V3::new(0.0, 0.0, gravity_mps2));
        // Per link, in its own frame: the force m a_c and the moment about its origin of
        // everything but the child's reaction.
        let mut force = [V3::zeros(); 6];
        let mut moment = [V3::zeros(); 6];
        for i in 0..6 {
            let dh = &self.dh[i];
            let body: &BodyInertia = &self.bodies[i];
            // w_{i-1} x (qd_i z) with z = (0, 0, 1) in frame i-1.
            let w_cross_z = V3::new(w.y, -w.x, 0.0) * qd[i];
            let w_parent = w + V3::new(0.0, 0.0, qd[i]);
            let wd_parent = wd + V3::new(0.0, 0.0, qdd[i]) + w_cross_z;
            w = to_child(dh, sc[i], &w_parent);
            wd = to_child(dh, sc[i], &wd_parent);
            // Origin offset p* of frame i from frame i-1, in frame i.
            let p = V3::new(dh.a, dh.d * dh.sin_alpha, dh.d * dh.cos_alpha);
            a = to_child(dh, sc[i], &a) + wd.cross(&p) + w.cross(&w.cross(&p));
            let a_com = a + wd.cross(&body.com) + w.cross(&w.cross(&body.com));
            let f = a_com * body.mass;
            let iw = body.inertia_com * w;
            force[i] = f;
            moment[i] = body.inertia_com * wd + w.cross(&iw) + body.com.cross(&f);
        }
        let mut tau = Vec6::zeros();
        let (mut f_child, mut n_child) = (V3::zeros(), V3::zeros());
        for i in (0..6).rev() {
            let dh = &self.dh[i];
            // f_i = R_{i+1} f_{i+1} + m a_c; n_i (about origin i) = R_{i+1} n_{i+1}
            // + P_{i+1} x R_{i+1} f_{i+1} + own terms, P_{i+1} = origin i+1 in frame i.
            let (f_in, n_in) = if i < 5 {
                let dh_child = &self.dh[i + 1];
                let sc_child = sc[i + 1];
                let f_r = to_parent(dh_child, sc_child, &f_child);
                let n_r = to_parent(dh_child, sc_child, &n_child);
                let offset = V3::new(dh_child.a * sc_child.1, dh_child.a * sc_child.0, dh_child.d);
                (f_r, n_r + offset.cross(&f_r))
            } else {
                (V3::zeros(), V3::zeros())
            };
            f_child = f_in + force[i];
            n_child = n_in + moment[i];
            // Torque about joint i's axis (z of frame i-1, through origin i-1), in frame i.
            let p = V3::new(dh.a, dh.d * dh.sin_alpha, dh.d * dh.cos_alpha);
            let n_prev = n_child + p.cross(&f_child);
            tau[i] = dh.sin_alpha * n_prev.y + dh.cos_alpha * n_prev.z;
        }
        tau
    }

    /// Composite rigid body algorithm in link frames: composite inertias of links `i..6` about
    /// origin `i`, then each column's momentum carried down the chain like the RNEA's forces.
    /// Armature included.
    #[inline(always)]
    pub(crate) fn crba_local(&self, sc: &SinCos) -> Mat6 {
        let mut composite = [OriginInertia::default(); 6];
        composite[5] = self.origin_inertias[5];
        for i in (0..5).rev() {
            let dh = &self.dh[i + 1];
            let (s, c) = sc[i + 1];
            let child = &composite[i + 1];
            let i_rot = child.i.rotated_x(dh.cos_alpha, dh.sin_alpha).rotated_z(c, s);
            let h_rot = to_parent(dh, sc[i + 1], &child.h);
            let offset = V3::new(dh.a * c, dh.a * s, dh.d);
            composite[i] = self.origin_inertias[i].add(&child.shifted_to_parent(i_rot, h_rot, &offset));
        }
        let mut m = Mat6::zeros();
        for j in 0..6 {
            let dh = &self.dh[j];
            // Unit rate of joint j: w = z (joint axis in frame j), origin j moves at z x p*.
            let (z, p) = axis_and_offset(dh);
            let (mut n, mut f) = composite[j].apply(&z, &z.cross(&p));
            m[(j, j)] = z.dot(&(n + p.cross(&f))) + self.armature[j];
            for i in (0..j).rev() {
                let dh_child = &self.dh[i + 1];
                let sc_child = sc[i + 1];
                f = to_parent(dh_child, sc_child, &f);
                let offset = V3::new(dh_child.a * sc_child.1, dh_child.a * sc_child.0, dh_child.d);
                n = to_parent(dh_child, sc_child, &n) + offset.cross(&f);
                let (z_i, p_i) = axis_and_offset(&self.dh[i]);
                let mij = z_i.dot(&(n + p_i.cross(&f)));
                m[(i, j)] = mij;
                m[(j, i)] = mij;
            }
        }
        m
    }
}

/// Joint `i`'s axis and the offset `p*` of origin `i` from origin `i-1`, both in frame `i`.
#[inline(always)]
fn axis_and_offset(dh: &DhConst) -> (V3, V3) {
    (V3::new(0.0, dh.sin_alpha, dh.cos_alpha), V3::new(dh.a, dh.d * dh.sin_alpha, dh.d * dh.cos_alpha))
}
