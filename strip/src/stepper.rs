//! Exact zero-order-hold stepping of the reduced model in its diagonal (modal) form.
//!
//! For each mode k: xi_k <- z_k xi_k + gamma_k (b_k . u) with z_k = exp(lambda_k dt) and
//! gamma_k = (z_k - 1) / lambda_k, which is the exact ZOH discretisation of x' = A x + B u
//! (the matched-DC poles near 6e5 rad/s are no problem for any dt). Outputs: y = C x + D u.
//! Nothing here allocates after construction.

use faer::c64;

use crate::model::StripModel;

/// Discrete-time strip model for a fixed step `dt`. All forces along +y (pressing is negative),
/// see the conventions in [`crate::model`].
pub struct StripStepper {
    dt: f64,
    modes: usize,
    n_top: usize,
    n_out: usize,
    z: Vec<c64>,
    /// gamma_k b_kj, input-major (j * modes + k).
    bz: Vec<c64>,
    /// weighted C V, output-major.
    c: Vec<c64>,
    d: Vec<f64>, // row-major p x m
    xi: Vec<c64>,
    // wheel direction cache
    wheel_b: Vec<c64>,
    wheel_c: Vec<c64>,
    wheel_d: f64,
    wheel_cz: Vec<c64>,
    wheel_step_d: f64,
    wheel_d_bottom: Vec<f64>,
    /// Centre-line bottom output rows (indices into the bottom outputs).
    centre: Vec<usize>,
    table: WheelTable,
}

/// Wheel quantities tabulated over the wheel position z_a (uniform grid) for O(modes)
/// cubic interpolation in [`StripStepper::set_wheel_z`]. Entry g holds, for the Gaussian weights
/// w(z_g): B_d w (modes), w^T C_top (modes), w^T D_top w, w^T (C_top B_d + D_top) w and the
/// centre-line bottom feed-through D_centre w.
struct WheelTable {
    z0: f64,
    dz: f64,
    n: usize,
    b: Vec<c64>,
    c: Vec<c64>,
    d: Vec<f64>,
    step_d: Vec<f64>,
    d_centre: Vec<f64>,
}

/// Grid points per element length along z of the wheel table.
const TABLE_PER_ELEMENT: usize = 8;

impl StripStepper {
    /// Discretises `model` for step `dt` (s), state at rest (zero).
    pub fn new(model: &StripModel, dt: f64) -> StripStepper {
        assert!(dt > 0.0 && dt.is_finite(), "dt must be positive, got {dt}");
        let mf = &model.modal;
        let modes = mf.modes();
        let m = model.n_top();
        let p = model.c.nrows();
        let z: Vec<c64> = mf.lam.iter().map(|&l| (l * dt).exp()).collect();
        let gamma: Vec<c64> = mf.lam.iter().zip(&z).map(|(&l, &zz)| (zz - c64::new(1.0, 0.0)) / l).collect();
        let mut bz = vec![c64::new(0.0, 0.0); m * modes];
        for j in 0..m {
            for k in 0..modes {
                bz[j * modes + k] = gamma[k] * mf.b[j * modes + k];
            }
        }
        let d: Vec<f64> = (0..p).flat_map(|i| (0..m).map(move |j| (i, j))).map(|(i, j)| model.d[(i, j)]).collect();
        let centre = model.centre_bottom.clone();
        let table = WheelTable::build(model, &z, &bz, &mf.c, &d, &centre);
        StripStepper {
            dt,
            modes,
            n_top: m,
            n_out: p,
            z,
            bz,
            c: mf.c.clone(),
            d,
            xi: vec![c64::new(0.0, 0.0); modes],
            wheel_b: vec![c64::new(0.0, 0.0); modes],
            wheel_c: vec![c64::new(0.0, 0.0); modes],
            wheel_d: 0.0,
            wheel_cz: vec![c64::new(0.0, 0.0); modes],
            wheel_step_d: 0.0,
            wheel_d_bottom: vec![0.0; centre.len()],
            centre,
            table,
        }
    }

    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// Number of modal coordinates (complex pairs count once).
    pub fn modes(&self) -> usize {
        self.modes
    }

    /// Back to rest.
    pub fn reset(&mut self) {
        self.xi.iter_mut().for_each(|x| *x = c64::new(0.0, 0.0));
    }

    /// Advances one step with top nodal forces `top_forces` (N, +y) held over the step.
    /// Zero entries are skipped, so a Gaussian load costs O(nonzeros x modes).
    pub fn step(&mut self, top_forces: &[f64]) {
        assert_eq!(top_forces.len(), self.n_top);
        for x in self.xi.iter_mut().zip(&self.z) {
            *x.0 *= *x.1;
        }
        for (j, &u) in top_forces.iter().enumerate() {
            if u != 0.0 {
                let col = &self.bz[j * self.modes..(j + 1) * self.modes];
                for (x, b) in self.xi.iter_mut().zip(col) {
                    x.re += b.re * u;
                    x.im += b.im * u;
                }
            }
        }
    }

    /// y = C x + D u: top u_y (m) and bottom reactions (N, on the strip, +y) at the current state
    /// for the current input `top_forces`. Excludes the bulge offsets (add `StripModel::bulge_*`).
    pub fn outputs(&self, top_forces: &[f64], top_disp: &mut [f64], bottom_reaction: &mut [f64]) {
        assert_eq!(top_disp.len(), self.n_top);
        assert_eq!(bottom_reaction.len(), self.n_out - self.n_top);
        for i in 0..self.n_out {
            let row = &self.c[i * self.modes..(i + 1) * self.modes];
            let mut y: f64 = row.iter().zip(&self.xi).map(|(c, x)| c.re * x.re - c.im * x.im).sum();
            let drow = &self.d[i * self.n_top..(i + 1) * self.n_top];
            for (dv, &u) in drow.iter().zip(top_forces) {
                if u != 0.0 {
                    y += dv * u;
                }
            }
            if i < self.n_top {
                top_disp[i] = y;
            } else {
                bottom_reaction[i - self.n_top] = y;
            }
        }
    }

    /// Output `i` only (index into [top u_y; bottom reactions]).
    pub fn output(&self, i: usize, top_forces: &[f64]) -> f64 {
        let row = &self.c[i * self.modes..(i + 1) * self.modes];
        let mut y: f64 = row.iter().zip(&self.xi).map(|(c, x)| c.re * x.re - c.im * x.im).sum();
        let drow = &self.d[i * self.n_top..(i + 1) * self.n_top];
        for (dv, &u) in drow.iter().zip(top_forces) {
            y += dv * u;
        }
        y
    }

    /// Sets the wheel direction to the Gaussian map (5.33)-(5.34) at z_a (m) from the table
    /// built at construction: cubic interpolation, O(modes), about a microsecond, so it can run
    /// every substep (relative deviation from the exact `set_wheel(gaussian_weights(z_a))` is
    /// below 1e-5; tested). z_a is clamped to the strip.
    pub fn set_wheel_z(&mut self, z_a_m: f64) {
        let t = &self.table;
        let s = ((z_a_m - t.z0) / t.dz).clamp(0.0, (t.n - 1) as f64);
        let i = (s.floor() as usize).clamp(1, t.n.saturating_sub(3).max(1));
        let x = s - i as f64; // in [-1, 2] near the ends, [0, 1] inside
                              // cubic Lagrange weights on nodes i-1, i, i+1, i+2
        let l = [
            -x * (x - 1.0) * (x - 2.0) / 6.0,
            (x + 1.0) * (x - 1.0) * (x - 2.0) / 2.0,
            -(x + 1.0) * x * (x - 2.0) / 2.0,
            (x + 1.0) * x * (x - 1.0) / 6.0,
        ];
        let md = self.modes;
        for k in 0..md {
            let mut b = c64::new(0.0, 0.0);
            let mut c = c64::new(0.0, 0.0);
            for (q, &lq) in l.iter().enumerate() {
                let g = i - 1 + q;
                b += t.b[g * md + k] * lq;
                c += t.c[g * md + k] * lq;
            }
            self.wheel_b[k] = b;
            self.wheel_c[k] = c;
            self.wheel_cz[k] = c * self.z[k];
        }
        let nc = self.centre.len();
        self.wheel_d = 0.0;
        self.wheel_step_d = 0.0;
        self.wheel_d_bottom.iter_mut().for_each(|v| *v = 0.0);
        for (q, &lq) in l.iter().enumerate() {
            let g = i - 1 + q;
            self.wheel_d += t.d[g] * lq;
            self.wheel_step_d += t.step_d[g] * lq;
            for r in 0..nc {
                self.wheel_d_bottom[r] += t.d_centre[g * nc + r] * lq;
            }
        }
    }

    /// Caches the wheel direction for arbitrary weights `w` (e.g. from `gaussian_weights`, sum
    /// 1). Afterwards the input is u = f_y w and the scalar helpers below cost O(modes). Costs
    /// O(nonzeros x (modes + n_top)), a few hundred microseconds: prefer `set_wheel_z` per
    /// substep. Allocation-free.
    pub fn set_wheel(&mut self, w: &[f64]) {
        assert_eq!(w.len(), self.n_top);
        self.wheel_b.iter_mut().for_each(|v| *v = c64::new(0.0, 0.0));
        self.wheel_c.iter_mut().for_each(|v| *v = c64::new(0.0, 0.0));
        self.wheel_d_bottom.iter_mut().for_each(|v| *v = 0.0);
        let mut dww = 0.0;
        for (j, &wj) in w.iter().enumerate() {
            if wj == 0.0 {
                continue;
            }
            let col = &self.bz[j * self.modes..(j + 1) * self.modes];
            for (acc, b) in self.wheel_b.iter_mut().zip(col) {
                acc.re += b.re * wj;
                acc.im += b.im * wj;
            }
            let row = &self.c[j * self.modes..(j + 1) * self.modes];
            for (acc, c) in self.wheel_c.iter_mut().zip(row) {
                acc.re += c.re * wj;
                acc.im += c.im * wj;
            }
            for (i, &wi) in w.iter().enumerate() {
                if wi != 0.0 {
                    dww += wi * self.d[i * self.n_top + j] * wj;
                }
            }
            for (acc, &r) in self.wheel_d_bottom.iter_mut().zip(&self.centre) {
                *acc += self.d[(self.n_top + r) * self.n_top + j] * wj;
            }
        }
        self.wheel_d = dww;
        let mut cb = 0.0;
        for k in 0..self.modes {
            self.wheel_cz[k] = self.wheel_c[k] * self.z[k];
            let (c, b) = (self.wheel_c[k], self.wheel_b[k]);
            cb += c.re * b.re - c.im * b.im;
        }
        self.wheel_step_d = dww + cb;
    }

    /// Wheel-point displacement (m, +y) at the END of the coming step if no force acted:
    /// w^T C_top A_d x. Together with [`Self::wheel_step_compliance`]:
    /// u_y(end of step) = wheel_uy_predict() + wheel_step_compliance() * f_y for a force f_y held
    /// over the step (and still acting at its end). This implicit (end-of-step) form is the
    /// well-posed way to close a stiff penalty contact: see README, "algebraic loop".
    pub fn wheel_uy_predict(&self) -> f64 {
        self.wheel_cz.iter().zip(&self.xi).map(|(c, x)| c.re * x.re - c.im * x.im).sum()
    }

    /// End-of-step compliance w^T (C_top B_d + D_top) w (m/N) for this `dt`.
    pub fn wheel_step_compliance(&self) -> f64 {
        self.wheel_step_d
    }

    /// Wheel-point displacement w^T (C_top x) (m, +y) from the state alone.
    pub fn wheel_uy_free(&self) -> f64 {
        self.wheel_c.iter().zip(&self.xi).map(|(c, x)| c.re * x.re - c.im * x.im).sum()
    }

    /// Feed-through compliance w^T D_top w (m/N): the wheel-point displacement now is
    /// `wheel_uy_free() + wheel_compliance() * f_y`. Matched DC puts the static part of the
    /// truncated states here; it is small and NOT guaranteed positive (balanced coordinates), so
    /// a stiff penalty closed on it alone can be ill-posed: prefer the end-of-step pair
    /// `wheel_uy_predict` / `wheel_step_compliance`.
    pub fn wheel_compliance(&self) -> f64 {
        self.wheel_d
    }

    /// Advances one step with the wheel load u = f_y w (N, +y; pressing is negative), O(modes).
    pub fn step_wheel(&mut self, f_y: f64) {
        for ((x, z), b) in self.xi.iter_mut().zip(&self.z).zip(&self.wheel_b) {
            *x *= *z;
            x.re += b.re * f_y;
            x.im += b.im * f_y;
        }
    }

    /// Centre-line bottom reactions (N, +y on the strip; order of `StripModel::centre_line`)
    /// under the wheel load f_y (after `set_wheel*`). O(centre nodes x modes). Divide by the
    /// tributary areas for the contact pressure; add the bulge offsets.
    pub fn wheel_centre_reactions(&self, f_y: f64, out: &mut [f64]) {
        assert_eq!(out.len(), self.centre.len());
        for (k, (&r, o)) in self.centre.iter().zip(out.iter_mut()).enumerate() {
            let row = self.n_top + r;
            let crow = &self.c[row * self.modes..(row + 1) * self.modes];
            *o = crow.iter().zip(&self.xi).map(|(c, x)| c.re * x.re - c.im * x.im).sum::<f64>() + self.wheel_d_bottom[k] * f_y;
        }
    }
}

impl WheelTable {
    fn build(model: &StripModel, z: &[c64], bz: &[c64], c: &[c64], d: &[f64], centre: &[usize]) -> WheelTable {
        let layers = model.top_xyz_m.iter().map(|p| p[2]).fold(0.0f64, f64::max);
        let m = model.n_top();
        let modes = z.len();
        let n_layers = model.top_xyz_m.iter().filter(|p| p[0].abs() < 1e-12).count().max(2);
        let dz = layers / ((n_layers - 1) * TABLE_PER_ELEMENT) as f64;
        let n = (layers / dz).round() as usize + 1;
        let mut tb = vec![c64::new(0.0, 0.0); n * modes];
        let mut tc = vec![c64::new(0.0, 0.0); n * modes];
        let mut td = vec![0.0; n];
        let mut tsd = vec![0.0; n];
        let nc = centre.len();
        let mut tdc = vec![0.0; n * nc];
        let mut w = vec![0.0; m];
        let mut dw = vec![0.0; m];
        for g in 0..n {
            model.gaussian_weights(g as f64 * dz, &mut w);
            let (bg, cg) = (&mut tb[g * modes..(g + 1) * modes], &mut tc[g * modes..(g + 1) * modes]);
            for (j, &wj) in w.iter().enumerate() {
                if wj < 1e-14 {
                    continue;
                }
                for k in 0..modes {
                    bg[k] += bz[j * modes + k] * wj;
                    cg[k] += c[j * modes + k] * wj;
                }
            }
            dw.iter_mut().for_each(|v| *v = 0.0);
            for (j, &wj) in w.iter().enumerate() {
                if wj < 1e-14 {
                    continue;
                }
                for i in 0..m {
                    dw[i] += d[i * m + j] * wj;
                }
                for (r, &cr) in centre.iter().enumerate() {
                    tdc[g * nc + r] += d[(m + cr) * m + j] * wj;
                }
            }
            td[g] = w.iter().zip(&dw).map(|(a, b)| a * b).sum();
            let cb: f64 = cg.iter().zip(bg.iter()).map(|(c, b)| c.re * b.re - c.im * b.im).sum();
            tsd[g] = td[g] + cb;
        }
        WheelTable { z0: 0.0, dz, n, b: tb, c: tc, d: td, step_d: tsd, d_centre: tdc }
    }
}
