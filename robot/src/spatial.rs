//! Minimal spatial (6D) algebra in the base frame, referenced to the base origin (Featherstone's
//! Plücker coordinates): motion vectors `(w, v)` with `v` the velocity of the body point at the
//! base origin, force vectors `(n, f)` with `n` the moment about the base origin.

use nalgebra::{Matrix3, Vector3};

use crate::model::LinkInertia;

pub(crate) type V3 = Vector3<f64>;
pub(crate) type M3 = Matrix3<f64>;

/// Inertia of one body in its own frame, ready to be rotated into the base frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BodyInertia {
    pub mass: f64,
    pub com: V3,
    pub inertia_com: M3,
}

impl BodyInertia {
    pub fn local(link: &LinkInertia) -> Self {
        BodyInertia { mass: link.mass_kg, com: link.com_m, inertia_com: link.inertia_com }
    }

    /// This body's spatial inertia about the base origin when its frame sits at `(rot, pos)`.
    #[inline(always)]
    pub fn in_base(&self, rot: &M3, pos: &V3) -> SpatialInertia {
        let c = pos + rot * self.com;
        let m = self.mass;
        // R I R^T + m (|c|^2 E - c c^T), symmetric: build the upper triangle only.
        let a = rot * self.inertia_com;
        let mut i = M3::zeros();
        let cc = c.norm_squared();
        for col in 0..3 {
            for row in 0..=col {
                let mut v = a.row(row).dot(&rot.row(col)) - m * c[row] * c[col];
                if row == col {
                    v += m * cc;
                }
                i[(row, col)] = v;
                i[(col, row)] = v;
            }
        }
        SpatialInertia { m, h: c * m, i }
    }
}

/// Spatial inertia about the base origin: mass `m`, first moment `h = m c`, rotational inertia
/// `i` about the base origin.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct SpatialInertia {
    pub m: f64,
    pub h: V3,
    pub i: M3,
}

impl SpatialInertia {
    /// Momentum `(n, f)` of motion `(w, v)`: `n = I w + h x v`, `f = m v - h x w`.
    #[inline(always)]
    pub fn apply(&self, w: &V3, v: &V3) -> (V3, V3) {
        (self.i * w + self.h.cross(v), v * self.m - self.h.cross(w))
    }

    #[inline(always)]
    pub fn add(&mut self, other: &SpatialInertia) {
        self.m += other.m;
        self.h += other.h;
        self.i += other.i;
    }
}
