//! The plant-facing reduced model and the build pipeline that makes it:
//! mesh -> FEM (K, M) -> Craig-Bampton -> modal state space (5.22) -> balanced truncation with
//! matched DC (5.31) -> modal (diagonal) form for exact ZOH stepping.
//!
//! Sign and unit conventions (task frame of DESIGN section 3, SI):
//! - inputs u: nodal forces on the top-surface nodes along +y (N). Pressing down is NEGATIVE.
//! - outputs y = [top u_y (m, +y; pressing moves them negative); bottom reactions (N)], where a
//!   bottom reaction is the substrate's force on the strip along +y: positive = compression, and
//!   the bottom contact pressure is reaction / tributary area (Pa, positive = compressive).
//! - in static equilibrium the reactions sum to minus the applied top forces.

use std::time::Instant;

use faer::{c64, Mat};
use serde::{Deserialize, Serialize};

use crate::bt::{balanced_matched_dc, generalized_eigen, ModalSystem};
use crate::cb::CraigBampton;
use crate::error::{numeric, Result};
use crate::params::StripParams;
use crate::system::FullSystem;

/// Gaussian wheel-force map constants (5.34); x, z in mm in the exponent.
pub const GAUSS_A: f64 = 0.424;
pub const GAUSS_B: f64 = 2.403e-6;
pub const GAUSS_C: f64 = 0.123;

/// Facts about a build, for reports.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct BuildInfo {
    pub dof_free: usize,
    pub cb_boundary_dofs: usize,
    pub cb_modes: usize,
    pub cb_states: usize,
    /// (stage, seconds) in pipeline order.
    pub timings_s: Vec<(String, f64)>,
    pub code_version: String,
    /// Relative DC mismatch of the matched-DC formulas from rounding (folded into D).
    pub dc_residual_rel: f64,
}

/// Diagonal (complex-modal) form of the reduced model: x = sum_k w_k Re(v_k xi_k), one entry per
/// real eigenvalue (w = 1) or per complex-conjugate pair (w = 2, Im lambda > 0).
#[derive(Clone, Debug, Default)]
pub struct ModalForm {
    pub lam: Vec<c64>,
    pub weight: Vec<f64>,
    /// Rows of V^-1 B, stored input-major: b[j * modes + k].
    pub b: Vec<c64>,
    /// Columns of C V times the weight, stored output-major: c[i * modes + k].
    pub c: Vec<c64>,
}

impl ModalForm {
    pub fn modes(&self) -> usize {
        self.lam.len()
    }
}

/// The reduced weatherstrip model (cached on disk, see `cache`).
#[derive(Clone, Debug)]
pub struct StripModel {
    pub params: StripParams,
    /// Reduced state space in balanced coordinates (order x order, order x m, p x order, p x m).
    pub a: Mat<f64>,
    pub b: Mat<f64>,
    pub c: Mat<f64>,
    pub d: Mat<f64>,
    /// Top-surface node coordinates [x, y, z] (m): input j and output j belong to node j.
    pub top_xyz_m: Vec<[f64; 3]>,
    /// Bottom node coordinates [x, z] (m): output n_top + i belongs to bottom node i.
    pub bottom_xz_m: Vec<[f64; 2]>,
    pub bottom_area_m2: Vec<f64>,
    /// Indices (into the bottom nodes) of the centre line x = 0, ascending z.
    pub centre_bottom: Vec<usize>,
    /// Static output offsets of the substrate bulge (full model): top u_y (m), bottom reactions (N).
    pub bulge_top_uy_m: Vec<f64>,
    pub bulge_bottom_reaction_n: Vec<f64>,
    /// Hankel singular values of the (output-weighted) CB system.
    pub hsv: Vec<f64>,
    pub modal: ModalForm,
    pub info: BuildInfo,
}

/// Intermediate results kept for verification reports.
pub struct Artifacts {
    pub sys: FullSystem,
    pub cb: CraigBampton,
    pub cb_modal: ModalSystem,
}

struct Timer {
    t: Instant,
    out: Vec<(String, f64)>,
}

impl Timer {
    fn lap(&mut self, name: &str) {
        let now = Instant::now();
        self.out.push((name.to_string(), (now - self.t).as_secs_f64()));
        self.t = now;
    }
}

impl StripModel {
    /// Builds the model from scratch (no cache).
    pub fn build(p: &StripParams) -> Result<StripModel> {
        Ok(Self::build_detailed(p)?.0)
    }

    /// Builds the model and returns the intermediate full and CB systems too.
    pub fn build_detailed(p: &StripParams) -> Result<(StripModel, Artifacts)> {
        p.validate()?;
        crate::fix_build_parallelism();
        let mut tm = Timer { t: Instant::now(), out: Vec::new() };
        crate::progress::stage("mesh and assembly");
        let sys = FullSystem::build(p);
        tm.lap("mesh_assembly");
        crate::progress::stage("Craig-Bampton (factorisation, constraint modes)");
        let cb = CraigBampton::build(&sys, p)?;
        tm.lap("craig_bampton");
        let cb_sub = cb.timings.clone();
        // the bulge statics need only the CB factor: solved beside the modal form and the
        // balanced truncation (its own wall time is recorded)
        let (cb_modal, red, (bulge_top_uy_m, bulge_bottom_reaction_n, bulge_s)) = std::thread::scope(|s| -> Result<_> {
            let bulge = s.spawn(|| {
                let t = Instant::now();
                let (top, bottom) = bulge_statics(&sys, &cb, &p.with_reference_bulge());
                (top, bottom, t.elapsed().as_secs_f64())
            });
            crate::progress::stage("CB modal form");
            let cb_modal = cb_modal_system(&cb, p)?;
            tm.lap("cb_modal");
            // weight the two output groups alike for balancing: equal DC-gain Frobenius norms
            let n_top = sys.top_nodes.len();
            let (mut nt, mut nbm) = (0.0, 0.0);
            {
                let g0 = cb_modal.dc_gain();
                for i in 0..g0.nrows() {
                    let s: f64 = g0.row(i).iter().map(|v| v * v).sum();
                    if i < n_top {
                        nt += s;
                    } else {
                        nbm += s;
                    }
                }
            }
            let w_bottom = if nbm > 0.0 { (nt / nbm).sqrt() } else { 1.0 };
            let out_weight: Vec<f64> = (0..cb_modal.h.nrows()).map(|i| if i < n_top { 1.0 } else { w_bottom }).collect();
            let red = balanced_matched_dc(&cb_modal, p.order, &out_weight)?;
            tm.lap("balanced_truncation");
            Ok((cb_modal, red, bulge.join().expect("bulge thread panicked")))
        })?;
        tm.out.push(("bulge".to_string(), bulge_s));
        crate::progress::stage("modal form of the reduced model");
        let modal = modal_form(&red.a, &red.b, &red.c)?;
        tm.lap("reduced_modal_form");

        let mesh = &sys.mesh;
        let top_xyz_m = sys.top_nodes.iter().map(|&n| mesh.coords[n]).collect();
        let bottom_xz_m: Vec<[f64; 2]> = sys.bottom_nodes.iter().map(|&n| [mesh.coords[n][0], mesh.coords[n][2]]).collect();
        let centre_bottom = (0..bottom_xz_m.len()).filter(|&i| bottom_xz_m[i][0].abs() < 1e-9).collect();
        let info = BuildInfo {
            dof_free: sys.n_free(),
            cb_boundary_dofs: cb.nb(),
            cb_modes: cb.nm(),
            cb_states: 2 * (cb.nb() + cb.nm()),
            timings_s: tm.out.into_iter().chain(cb_sub).chain(red.timings.iter().cloned()).collect(),
            code_version: crate::CODE_VERSION.to_string(),
            dc_residual_rel: red.dc_residual_rel,
        };
        let model = StripModel {
            params: p.with_reference_bulge(),
            a: red.a,
            b: red.b,
            c: red.c,
            d: red.d,
            top_xyz_m,
            bottom_xz_m,
            bottom_area_m2: sys.bottom_areas_m2.clone(),
            centre_bottom,
            bulge_top_uy_m,
            bulge_bottom_reaction_n,
            hsv: red.hsv.clone(),
            modal,
            info,
        };
        Ok((model.with_bulge_of(p), Artifacts { sys, cb, cb_modal }))
    }

    /// This model (built at the reference bump, `params == p.with_reference_bulge()`) with the
    /// bump of `p`: the bump's static offsets scaled by [`StripParams::bulge_scale`]. They are
    /// linear in the bump's height; everything else does not depend on it.
    pub fn with_bulge_of(mut self, p: &StripParams) -> StripModel {
        assert_eq!(self.params, p.with_reference_bulge(), "with_bulge_of: the model must be the reference bump's of the same strip");
        let k = p.bulge_scale();
        self.bulge_top_uy_m.iter_mut().chain(&mut self.bulge_bottom_reaction_n).for_each(|v| *v *= k);
        self.params = p.clone();
        self
    }

    pub fn order(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs = number of top-surface nodes.
    pub fn n_top(&self) -> usize {
        self.top_xyz_m.len()
    }
    pub fn n_bottom(&self) -> usize {
        self.bottom_xz_m.len()
    }

    /// Gaussian force map (5.33)-(5.34): weights of the top nodes for a wheel at z_a (m),
    /// normalised to sum 1 (x, z in mm inside the exponent, as fitted in the thesis). The nodal
    /// forces for a wheel force f_y (N, +y; pressing is negative) are f_y * w.
    pub fn gaussian_weights(&self, z_a_m: f64, out: &mut [f64]) {
        gaussian_weights(&self.top_xyz_m, z_a_m, out);
    }

    /// Bottom-node indices of the centre line with their z (m) and tributary area (m^2).
    pub fn centre_line(&self) -> impl Iterator<Item = (usize, f64, f64)> + '_ {
        self.centre_bottom.iter().map(move |&i| (i, self.bottom_xz_m[i][1], self.bottom_area_m2[i]))
    }

    /// Static response y(0) = (D - C A^-1 B) u of the reduced model (allocates; not for the loop).
    pub fn static_response(&self, u: &[f64]) -> Vec<f64> {
        use faer::linalg::solvers::Solve;
        let uu = Mat::from_fn(u.len(), 1, |i, _| u[i]);
        let mut x = &self.b * &uu;
        self.a.partial_piv_lu().solve_in_place(x.as_mut());
        let y = &self.d * &uu - &self.c * &x;
        (0..y.nrows()).map(|i| y[(i, 0)]).collect()
    }
}

/// Static offsets of the substrate bump of `p` on the full model (through the CB factor): top u_y
/// (m) and bottom reactions (N), solved directly at `p`'s height. Linear in the height; the
/// models solve it once, at [`StripParams::BULGE_REFERENCE_M`], and scale it.
pub fn bulge_statics(sys: &FullSystem, cb: &CraigBampton, p: &StripParams) -> (Vec<f64>, Vec<f64>) {
    let q_r: Vec<f64> = sys.bottom_nodes.iter().map(|&n| p.bulge_height_m(sys.mesh.coords[n][2])).collect();
    let q_f = cb.static_prescribed(&q_r, sys.n_free());
    let top: Vec<f64> = sys.top_y_free.iter().map(|&f| q_f[f]).collect();
    let mut bottom = vec![0.0; sys.bottom_nodes.len()];
    sys.reactions(&q_f, Some(&q_r), &mut bottom);
    (top, bottom)
}

/// Gaussian weights (5.33)-(5.34) for top nodes at `top_xyz_m`; see [`StripModel::gaussian_weights`].
pub fn gaussian_weights(top_xyz_m: &[[f64; 3]], z_a_m: f64, out: &mut [f64]) {
    assert_eq!(out.len(), top_xyz_m.len(), "weights buffer length must equal the number of top nodes");
    let za = z_a_m * 1e3;
    let mut sum = 0.0;
    for (w, p) in out.iter_mut().zip(top_xyz_m) {
        let (x, dz) = (p[0] * 1e3, p[2] * 1e3 - za);
        *w = (-GAUSS_A * x * x - 2.0 * GAUSS_B * x * dz - GAUSS_C * dz * dz).exp();
        sum += *w;
    }
    if sum > 0.0 {
        out.iter_mut().for_each(|w| *w /= sum);
    }
}

/// Modal second-order form of the CB model with inputs = top y forces and outputs = [top u_y;
/// bottom reactions].
pub fn cb_modal_system(cb: &CraigBampton, p: &StripParams) -> Result<ModalSystem> {
    let (lam, phi) = generalized_eigen(cb.k.as_ref(), cb.m.as_ref())?;
    if lam[0] <= 0.0 {
        return Err(numeric("CB modal form", format!("non-positive CB eigenvalue {}", lam[0])));
    }
    let n = lam.len();
    let m = cb.input_coord.len();
    let g = Mat::from_fn(n, m, |i, k| phi[(cb.input_coord[k], i)]);
    let nr = cb.c_react.nrows();
    let react = &cb.c_react * &phi;
    let h = Mat::from_fn(m + nr, n, |i, j| if i < m { phi[(cb.input_coord[i], j)] } else { react[(i - m, j)] });
    let damp = lam.iter().map(|&l| p.damping_alpha_per_s + p.damping_beta_s * l).collect();
    Ok(ModalSystem { omega2: lam, damp, g, h })
}

/// Diagonalises the reduced A: A = V diag(lambda) V^-1, keeping one member of each conjugate
/// pair. Fails if the reduced model is unstable.
pub fn modal_form(a: &Mat<f64>, b: &Mat<f64>, c: &Mat<f64>) -> Result<ModalForm> {
    use faer::linalg::solvers::Solve;
    let evd = a.eigen().map_err(|e| numeric("reduced eigen", format!("{e:?}")))?;
    let n = a.nrows();
    let s = evd.S().column_vector();
    let v = evd.U();
    let mut keep = Vec::new();
    for k in 0..n {
        let l = s[k];
        if l.re >= 0.0 {
            return Err(numeric("reduced model", format!("unstable eigenvalue {} + {}i", l.re, l.im)));
        }
        if l.im.abs() <= 1e-12 * l.norm() {
            keep.push((k, 1.0));
        } else if l.im > 0.0 {
            keep.push((k, 2.0));
        }
    }
    // V^-1 B
    let bc = Mat::<c64>::from_fn(n, b.ncols(), |i, j| c64::new(b[(i, j)], 0.0));
    let mut vib = bc;
    v.partial_piv_lu().solve_in_place(vib.as_mut());
    let cc = Mat::<c64>::from_fn(c.nrows(), n, |i, j| c64::new(c[(i, j)], 0.0));
    let cv = &cc * v;
    let modes = keep.len();
    let mut out = ModalForm {
        lam: keep
            .iter()
            .map(|&(k, _)| {
                let l = s[k];
                if l.im.abs() <= 1e-12 * l.norm() {
                    c64::new(l.re, 0.0)
                } else {
                    l
                }
            })
            .collect(),
        weight: keep.iter().map(|&(_, w)| w).collect(),
        b: vec![c64::new(0.0, 0.0); b.ncols() * modes],
        c: vec![c64::new(0.0, 0.0); c.nrows() * modes],
    };
    for (m, &(k, w)) in keep.iter().enumerate() {
        for j in 0..b.ncols() {
            out.b[j * modes + m] = vib[(k, j)];
        }
        for i in 0..c.nrows() {
            out.c[i * modes + m] = cv[(i, k)] * w;
        }
    }
    Ok(out)
}
