//! Inertia bookkeeping for the link-frame algorithms: a body about its COM, a body (or a
//! composite of bodies) about a frame origin, and symmetric 3x3 matrices rotated about the DH
//! axes. Motion `(w, v)`: `v` is the velocity of the body point at the origin; momentum/force
//! `(n, f)`: `n` is the moment about the origin.

use nalgebra::{Matrix3, Vector3};

pub(crate) type V3 = Vector3<f64>;
pub(crate) type M3 = Matrix3<f64>;

/// Inertia of one body in its own frame, ready to be rotated into the base frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BodyInertia {
    pub mass: f64,
    pub com: V3,
    pub inertia_com: M3,
}

/// Symmetric 3x3 matrix by its six entries.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sym3 {
    pub xx: f64,
    pub yy: f64,
    pub zz: f64,
    pub xy: f64,
    pub xz: f64,
    pub yz: f64,
}

impl Sym3 {
    pub fn from_matrix(m: &M3) -> Self {
        Sym3 { xx: m[(0, 0)], yy: m[(1, 1)], zz: m[(2, 2)], xy: m[(0, 1)], xz: m[(0, 2)], yz: m[(1, 2)] }
    }

    #[inline(always)]
    pub fn mul(&self, v: &V3) -> V3 {
        V3::new(
            self.xx * v.x + self.xy * v.y + self.xz * v.z,
            self.xy * v.x + self.yy * v.y + self.yz * v.z,
            self.xz * v.x + self.yz * v.y + self.zz * v.z,
        )
    }

    /// `Rx I Rx^T` for a rotation about x with cosine `c`, sine `s`.
    #[inline(always)]
    pub fn rotated_x(&self, c: f64, s: f64) -> Sym3 {
        let (cc, ss, cs) = (c * c, s * s, c * s);
        Sym3 {
            xx: self.xx,
            yy: cc * self.yy - 2.0 * cs * self.yz + ss * self.zz,
            zz: ss * self.yy + 2.0 * cs * self.yz + cc * self.zz,
            yz: cs * (self.yy - self.zz) + (cc - ss) * self.yz,
            xy: c * self.xy - s * self.xz,
            xz: s * self.xy + c * self.xz,
        }
    }

    /// `Rz I Rz^T` for a rotation about z with cosine `c`, sine `s`.
    #[inline(always)]
    pub fn rotated_z(&self, c: f64, s: f64) -> Sym3 {
        let (cc, ss, cs) = (c * c, s * s, c * s);
        Sym3 {
            xx: cc * self.xx - 2.0 * cs * self.xy + ss * self.yy,
            yy: ss * self.xx + 2.0 * cs * self.xy + cc * self.yy,
            xy: cs * (self.xx - self.yy) + (cc - ss) * self.xy,
            xz: c * self.xz - s * self.yz,
            yz: s * self.xz + c * self.yz,
            zz: self.zz,
        }
    }

    #[inline(always)]
    pub fn add(&self, o: &Sym3) -> Sym3 {
        Sym3 { xx: self.xx + o.xx, yy: self.yy + o.yy, zz: self.zz + o.zz, xy: self.xy + o.xy, xz: self.xz + o.xz, yz: self.yz + o.yz }
    }

    /// `k E + a b^T + b a^T` (symmetric by construction) added to `self`.
    #[inline(always)]
    pub fn add_shift(&self, k: f64, a: &V3, b: &V3) -> Sym3 {
        Sym3 {
            xx: self.xx + k + 2.0 * a.x * b.x,
            yy: self.yy + k + 2.0 * a.y * b.y,
            zz: self.zz + k + 2.0 * a.z * b.z,
            xy: self.xy + a.x * b.y + b.x * a.y,
            xz: self.xz + a.x * b.z + b.x * a.z,
            yz: self.yz + a.y * b.z + b.y * a.z,
        }
    }
}

/// Spatial inertia in a link's own frame about the frame origin: mass, first moment `m c`,
/// rotational inertia about the origin.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct OriginInertia {
    pub m: f64,
    pub h: V3,
    pub i: Sym3,
}

impl OriginInertia {
    pub fn from_body(b: &BodyInertia) -> Self {
        let c = b.com;
        let i = b.inertia_com + (M3::from_diagonal_element(c.norm_squared()) - c * c.transpose()) * b.mass;
        OriginInertia { m: b.mass, h: c * b.mass, i: Sym3::from_matrix(&i) }
    }

    /// Momentum `(n, f)` of motion `(w, v)` (`v` of the body point at the origin).
    #[inline(always)]
    pub fn apply(&self, w: &V3, v: &V3) -> (V3, V3) {
        (self.i.mul(w) + self.h.cross(v), v * self.m - self.h.cross(w))
    }

    /// Re-express about a parent origin, given this inertia and first moment already rotated
    /// into parent axes (`i_rot = R I R^T`, `h_rot = R h`) and `p`, this origin in the parent
    /// frame. Parallel-axis shift:
    /// `I' = R I R^T + 2 (h.p) E - p h^T - h p^T + m (|p|^2 E - p p^T)`, `h' = h + m p`.
    #[inline(always)]
    pub fn shifted_to_parent(&self, i_rot: Sym3, h_rot: V3, p: &V3) -> OriginInertia {
        let m = self.m;
        let k = 2.0 * h_rot.dot(p) + m * p.norm_squared();
        // -p h^T - h p^T - m p p^T = -(p (h + m p / 2)^T + (h + m p / 2) p^T)
        let g = -(h_rot + p * (0.5 * m));
        OriginInertia { m, h: h_rot + p * m, i: i_rot.add_shift(k, p, &g) }
    }

    #[inline(always)]
    pub fn add(&self, o: &OriginInertia) -> OriginInertia {
        OriginInertia { m: self.m + o.m, h: self.h + o.h, i: self.i.add(&o.i) }
    }
}
