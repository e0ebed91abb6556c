//! Wheel–strip contact (DESIGN sections 4-5, issue 6): the reduced strip model (with its bulge)
//! coupled to the robot's applicator wheel through a unilateral penalty contact.
//!
//! Per substep of length h (called at the substep start with the robot's TCP pose and twist):
//! 1. z_a = task z of the wheel's lowest point; Gaussian wheel direction w(z_a) (5.33)-(5.34).
//! 2. Strip surface under the wheel at the END of the substep, with the contact force f held over
//!    the substep (pressing: f < 0 along +y):
//!    `s = H + wᵀ u_bulge + wᵀ C_top (Z x) + d_h f`,   `d_h = wᵀ D_top w + Re Σ_k c_k γ_k b_k`,
//!    where Z = e^{Λh}, γ = (Z − 1)/Λ is the exact ZOH of the modal form, so d_h is the strip's
//!    compliance under the wheel over one substep (the matched-DC D term is its instantaneous part).
//! 3. Penetration δ = s − y_wheel (wheel height predicted to the substep end from its velocity);
//!    contact force p = max(0, k δ + c δ̇), δ̇ = (δ − δ_prev)/h. With δ = δ0 − d_h p this scalar
//!    algebraic loop has the closed form p = max(0, ((k + c/h) δ0 − (c/h) δ_prev) / (1 + (k + c/h) d_h)).
//!    Solving it implicitly (not lagging it) keeps the stiff penalty stable for any h.
//! 4. Step the strip exactly with u = f w (f = −p); the wheel gets +p along +y_task (= +z_base),
//!    applied at the wheel's lowest point, reported as the wrench about the TCP.
//!
//! Speed: the wheel direction enters only through wᵀ C_top, V⁻¹ B w, wᵀ D w and D_bottom w. These
//! are linear in w, so they are tabulated once on a fine z_a grid (0.05 mm; linear interpolation
//! of the Gaussian is exact to ~1e-4 relative and still sums to 1) and each substep costs O(modes).
//! The table holds γ V⁻¹ B w (h is fixed per contact), and since the compliance d_h is bilinear in
//! the interpolated rows, Σ Re(c γ b) is tabulated too as the quadratic in the interpolation
//! fraction it is (per grid point and per interval), so d_h costs O(1). Complex rows are stored
//! real: `[Re c, −Im c]` against the state `[Re x, Im x]`, so Re(c x) is one real dot product
//! (8 independent partial sums in a fixed order: vectorized, and still bit-reproducible).
//! Nothing allocates after construction.
//!
//! Sharing: the tables depend on the strip model and the substep only ([`StripTables`]), the
//! bump's terms on its height only linearly, so a contact holds an `Arc` of the tables and the
//! bump terms scaled to its height (`StripParams::bulge_scale` of the model at
//! `StripParams::BULGE_REFERENCE_M`). A sweep over bump heights builds one table for all cases.

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};
use recordings::{StripRecord, MAX_CENTRELINE, MAX_MODAL_STATE};
use robot::Vec6;
use scenarios::{Boundary, Scenario};
use strip::{CbBoundary, StripModel, StripParams, Substrate};

use scenarios::geometry::STRIP_TOP_HEIGHT_M;
use scenarios::path::StripPath;

pub mod chain;

/// z_a grid spacing of the wheel-direction table, m.
pub const TABLE_STEP_M: f64 = 0.05e-3;

/// The strip model parameters of a scenario (`[strip]` and `[bulge]`; the bulge's `half_width_mm`
/// is half the raised cosine's full width).
pub fn strip_params(s: &Scenario) -> StripParams {
    let st = &s.strip;
    let b = &s.bulge;
    StripParams {
        length_m: st.length_mm * 1e-3,
        element_m: st.element_mm * 1e-3,
        youngs_pa: st.youngs_modulus_pa,
        poisson: st.poisson,
        density_kg_m3: st.density_kg_m3,
        damping_alpha_per_s: st.damping_alpha,
        damping_beta_s: st.damping_beta,
        substrate: match st.boundary {
            Boundary::Bonded => Substrate::Bonded,
            Boundary::Sliding => Substrate::Sliding,
        },
        cb_boundary: CbBoundary::Y,
        cb_cutoff_hz: st.cutoff_hz,
        order: st.order,
        bulge_amplitude_m: b.height_mm * 1e-3,
        bulge_width_m: 2.0 * b.half_width_mm * 1e-3,
        bulge_center_m: b.center_mm * 1e-3,
    }
}

/// Where the strip lies and how the wheel touches it (SI, DESIGN section 3).
#[derive(Clone, Debug, PartialEq)]
pub struct ContactGeometry {
    /// Where the strip lies in the base (`scenarios::path`): its task frame, or along a contour.
    pub path: StripPath,
    pub wheel_radius_m: f64,
    /// Penalty stiffness (N/m) and damping (N s/m).
    pub stiffness_n_per_m: f64,
    pub damping_ns_per_m: f64,
}

impl ContactGeometry {
    pub fn from_scenario(s: &Scenario) -> Self {
        ContactGeometry {
            path: StripPath::from_scenario(s),
            wheel_radius_m: s.robot.wheel_radius_mm * 1e-3,
            stiffness_n_per_m: s.contact.stiffness_n_per_m,
            damping_ns_per_m: s.contact.damping_ns_per_m,
        }
    }
}

/// Wheel-direction quantities tabulated over z_a (see the module docs), flattened grid-major.
/// A "real row" of a complex vector v over the modes is `[Re v, Im v]` (2 × modes values); a
/// row multiplied with a state real row as `[Re c, −Im c] · [Re x, Im x]` gives Re(c x).
#[derive(Debug, Default)]
struct WheelTable {
    z0_m: f64,
    n: usize,
    /// γ V⁻¹ B w as real rows `[Re, Im]`, [g * 2 modes ..].
    gb: Vec<f64>,
    /// wᵀ C_top V (weighted) as real rows `[Re, −Im]`, [g * 2 modes ..].
    c: Vec<f64>,
    /// Σ_k Re(c_k γ b_k) at grid point g, and Σ_k Re(c_k(g) γ b_k(g+1) + c_k(g+1) γ b_k(g)) of
    /// interval g: the one-substep compliance between grid points is
    /// (1−s)² p(g) + s(1−s) x(g) + s² p(g+1) exactly (bilinear in the interpolated rows).
    cgb_point: Vec<f64>,
    cgb_cross: Vec<f64>,
    /// wᵀ D_top w, Σ_bottom D w, wᵀ u_bulge (the model's bump) per grid point.
    d_ww: Vec<f64>,
    d_sum: Vec<f64>,
    bulge_w: Vec<f64>,
    /// D_centreline w, [g * n_cl + c].
    d_cl: Vec<f64>,
    /// D_top-centreline w, [g * n_cl + c] (the top nodes of the centre line, for the scene).
    d_tcl: Vec<f64>,
}

/// A function with a baseline body (`$portable`, `#[inline(always)]`) and an AVX2 copy of it,
/// chosen at run time. Each body here is element-wise or keeps its partial sums in a fixed order,
/// and AVX2 brings no fused multiply-add: both paths give the same bits.
macro_rules! avx2_dispatch {
    ($(#[$doc:meta])* $vis:vis fn $name:ident / $avx2:ident ($($arg:ident: $ty:ty),*) $(-> $ret:ty)? = $portable:ident) => {
        $(#[$doc])*
        #[inline]
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above).
                return unsafe { $avx2($($arg),*) };
            }
            $portable($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        unsafe fn $avx2($($arg: $ty),*) $(-> $ret)? {
            $portable($($arg),*)
        }
    };
}

avx2_dispatch! {
    /// Real dot product with 8 independent partial sums combined in a fixed order: vectorized
    /// (AVX2 where the CPU has it), and the result does not depend on the vector width (no FMA,
    /// same order of operations), so runs stay bit-reproducible across the two code paths.
    fn dot / dot_avx2 (a: &[f64], b: &[f64]) -> f64 = dot_portable
}

avx2_dispatch! {
    /// [`dot`] of four rows of equal length with one `x`: each row's result is bit-identical to
    /// `dot(row, x)` (same partial sums, same order); `x` is loaded once for the four rows.
    fn dot4 / dot4_avx2 (rows: [&[f64]; 4], x: &[f64]) -> [f64; 4] = dot_rows_portable
}

avx2_dispatch! {
    /// [`dot`] of two rows with one `x` (the wheel's two grid rows each substep), as [`dot4`].
    fn dot2 / dot2_avx2 (rows: [&[f64]; 2], x: &[f64]) -> [f64; 2] = dot_rows_portable
}

/// N rows' [`dot_portable`] with one `x`: per row the same partial sums in the same order.
#[inline(always)]
fn dot_rows_portable<const N: usize>(rows: [&[f64]; N], x: &[f64]) -> [f64; N] {
    let n = rows.iter().map(|r| r.len()).fold(x.len(), usize::min);
    let full = n / 8 * 8;
    let mut acc = [[0.0f64; 8]; N];
    for c in (0..full).step_by(8) {
        let xs = &x[c..c + 8];
        for (a, row) in acc.iter_mut().zip(rows) {
            let rs = &row[c..c + 8];
            for l in 0..8 {
                a[l] += rs[l] * xs[l];
            }
        }
    }
    for (a, row) in acc.iter_mut().zip(rows) {
        for (l, (r, xv)) in row[full..n].iter().zip(&x[full..n]).enumerate() {
            a[l] += r * xv;
        }
    }
    acc.map(|a| ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7])))
}

/// A modal coordinate smaller than this is set to zero by the free step ([`rotate`]). Left
/// alone, a mode that decays after lift-off (or behind a window of the long strip) reaches the
/// subnormal range below 2.2e-308, where every multiply and add costs the CPU tens of times more:
/// by tick 3500 of the default run 60 of its 264 coordinates were subnormal, and flushing them
/// cut the 20-case bulge sweep's CPU time by a quarter (0.973 s to 0.742 s, median of 7, issue
/// 24), with every output bit unchanged (`tick_identity`, `sweep.json`). A coordinate of 1e-200 moves no
/// output by more than ~1e-190 (the rows' entries are far below 1e10), far under one ulp of
/// any nonzero output.
pub(crate) const MODE_FLOOR: f64 = 1e-200;

avx2_dispatch! {
    /// The modal state's free step `x ← Z x` (diagonal complex `Z`), on `x` as `[Re x, Im x]`,
    /// each coordinate below [`MODE_FLOOR`] in magnitude set to zero. Element by element, so the
    /// 4-wide AVX2 path gives the same bits as the 2-wide baseline one.
    pub(crate) fn rotate / rotate_avx2 (x: &mut [f64], z_re: &[f64], z_im: &[f64]) = rotate_portable
}

#[inline(always)]
fn rotate_portable(x: &mut [f64], z_re: &[f64], z_im: &[f64]) {
    let (x_re, x_im) = x.split_at_mut(z_re.len());
    let floor = |v: f64| if v.abs() < MODE_FLOOR { 0.0 } else { v };
    for (((xr, xi), zr), zi) in x_re.iter_mut().zip(x_im.iter_mut()).zip(z_re).zip(z_im) {
        (*xr, *xi) = (floor(zr * *xr - zi * *xi), floor(zr * *xi + zi * *xr));
    }
}

avx2_dispatch! {
    /// `x += a0 r0 + a1 r1`, element by element (bit-identical on either path, as [`rotate`]).
    fn add_two_rows / add_two_rows_avx2 (x: &mut [f64], r0: (f64, &[f64]), r1: (f64, &[f64])) = add_two_rows_portable
}

#[inline(always)]
fn add_two_rows_portable(x: &mut [f64], (a0, r0): (f64, &[f64]), (a1, r1): (f64, &[f64])) {
    for ((x, b0), b1) in x.iter_mut().zip(r0).zip(r1) {
        *x += a0 * b0 + a1 * b1;
    }
}

#[inline(always)]
fn dot_portable(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let (ac, bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    for (l, (x, y)) in ar.iter().zip(br).enumerate() {
        acc[l] += x * y;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]))
}

/// Grid points per block of the table build: a column of D and a row of the modal B and C are
/// read once for the whole block while its accumulators stay in cache.
const BUILD_BLOCK: usize = 16;

/// The table rows of the grid points `g0..g1` (`WheelTable::build`).
struct TableBlock {
    g0: usize,
    gb: Vec<f64>,
    c: Vec<f64>,
    d_ww: Vec<f64>,
    d_sum: Vec<f64>,
    bulge_w: Vec<f64>,
    d_cl: Vec<f64>,
    d_tcl: Vec<f64>,
}

impl WheelTable {
    /// A table of `n` grid points of zeros: rows of `row` values, `n_cl` centre-line and `n_tcl`
    /// top centre-line values per point, starting at z = 0.
    fn zeroed(n: usize, row: usize, n_cl: usize, n_tcl: usize) -> WheelTable {
        let v = |len: usize| vec![0.0; n * len];
        WheelTable {
            z0_m: 0.0,
            n,
            gb: v(row),
            c: v(row),
            cgb_point: v(1),
            cgb_cross: v(1),
            d_ww: v(1),
            d_sum: v(1),
            bulge_w: v(1),
            d_cl: v(n_cl),
            d_tcl: v(n_tcl),
        }
    }

    /// Table for `model` with the substep's ZOH factors γ = (e^{λh} − 1)/λ per mode.
    ///
    /// Every entry is the plain formula's, bit for bit (the test `fast_table_build_is_the_plain_one_bit_for_bit`
    /// keeps the plain loops): each sum runs over the same terms in the same order from the same
    /// start. Only the loop nest differs: by blocks of grid points, each column of D read once per
    /// block (contiguous) instead of once per row and grid point, and the blocks spread over the
    /// cores. That is most of a run's start-up (about 10⁹ multiply-adds for the 1 mm strip).
    fn build(model: &StripModel, cl_rows: &[usize], tcl_rows: &[usize], g_re: &[f64], g_im: &[f64]) -> WheelTable {
        let modes = model.modal.modes();
        let n_cl = cl_rows.len();
        let n = (model.params.length_m / TABLE_STEP_M).round() as usize + 1;
        let row = 2 * modes;
        let mut t = WheelTable::zeroed(n, row, n_cl, tcl_rows.len());
        let n_top = model.n_top();
        // Column sums of D over the bottom rows (total bottom reaction per unit top force).
        let d_colsum: Vec<f64> = (0..n_top).map(|j| (0..model.n_bottom()).map(|r| model.d[(n_top + r, j)]).sum()).collect();
        let starts: Vec<usize> = (0..n).step_by(BUILD_BLOCK).collect();
        let threads = std::thread::available_parallelism().map_or(1, |c| c.get()).min(starts.len()).max(1);
        let blocks: Vec<TableBlock> = std::thread::scope(|scope| {
            let (starts, d_colsum, z0) = (&starts, &d_colsum, t.z0_m);
            let workers: Vec<_> = (0..threads)
                .map(|w| {
                    scope.spawn(move || {
                        let mine = starts.iter().skip(w).step_by(threads);
                        let blocks = mine.map(|&g0| {
                            Self::build_block(model, cl_rows, tcl_rows, g_re, g_im, d_colsum, z0, g0..(g0 + BUILD_BLOCK).min(n))
                        });
                        blocks.collect::<Vec<_>>()
                    })
                })
                .collect();
            workers.into_iter().flat_map(|h| h.join().expect("wheel table thread panicked")).collect()
        });
        let n_tcl = tcl_rows.len();
        for b in blocks {
            let (g0, nb) = (b.g0, b.d_ww.len());
            t.gb[g0 * row..(g0 + nb) * row].copy_from_slice(&b.gb);
            t.c[g0 * row..(g0 + nb) * row].copy_from_slice(&b.c);
            t.d_ww[g0..g0 + nb].copy_from_slice(&b.d_ww);
            t.d_sum[g0..g0 + nb].copy_from_slice(&b.d_sum);
            t.bulge_w[g0..g0 + nb].copy_from_slice(&b.bulge_w);
            t.d_cl[g0 * n_cl..(g0 + nb) * n_cl].copy_from_slice(&b.d_cl);
            t.d_tcl[g0 * n_tcl..(g0 + nb) * n_tcl].copy_from_slice(&b.d_tcl);
        }
        t.finish_compliance();
        t
    }

    /// The compliance terms from the finished `c` and `gb` rows.
    fn finish_compliance(&mut self) {
        for g in 0..self.n {
            self.cgb_point[g] = dot(self.c_row(g), self.gb_row(g));
            if g + 1 < self.n {
                self.cgb_cross[g] = dot(self.c_row(g), self.gb_row(g + 1)) + dot(self.c_row(g + 1), self.gb_row(g));
            }
        }
    }

    /// Rows `gs` of the table (see [`WheelTable::build`]). Per grid point g the plain formulas
    /// are, over the top nodes j of non-negligible weight w_j (nz, ascending):
    /// b = Σ_j B_j w_j, c = Σ_j C_j w_j (from 0), (D w)_i = Σ_j D_ij w_j for every top row i and
    /// centre-line row, then wᵀ D w = Σ_{i ∈ nz} w_i (D w)_i, Σ_bottom D w and wᵀ u_bulge (the
    /// sums from the neutral element `Iterator::sum` starts from).
    #[allow(clippy::too_many_arguments)]
    fn build_block(
        model: &StripModel,
        cl_rows: &[usize],
        tcl_rows: &[usize],
        g_re: &[f64],
        g_im: &[f64],
        d_colsum: &[f64],
        z0_m: f64,
        gs: std::ops::Range<usize>,
    ) -> TableBlock {
        let mf = &model.modal;
        let modes = mf.modes();
        let n_top = model.n_top();
        let (n_cl, n_tcl, row) = (cl_rows.len(), tcl_rows.len(), 2 * modes);
        let nb = gs.len();
        // Weights and their support per grid point of the block.
        let mut w = vec![0.0; nb * n_top];
        let mut nz: Vec<Vec<usize>> = Vec::with_capacity(nb);
        let mut live = vec![false; nb * n_top];
        for (b, g) in gs.clone().enumerate() {
            let z = z0_m + g as f64 * TABLE_STEP_M;
            let wb = &mut w[b * n_top..(b + 1) * n_top];
            model.gaussian_weights(z, wb);
            let wmax = wb.iter().cloned().fold(0.0, f64::max);
            let support: Vec<usize> = (0..n_top).filter(|&j| wb[j] > 1e-15 * wmax).collect();
            support.iter().for_each(|&j| live[b * n_top + j] = true);
            nz.push(support);
        }
        let zero: f64 = std::iter::empty::<f64>().sum();
        let (mut b_re, mut b_im) = (vec![0.0; nb * modes], vec![0.0; nb * modes]);
        let mut c = vec![0.0; nb * row];
        let mut dw = vec![zero; nb * n_top];
        let mut d_cl = vec![zero; nb * n_cl];
        for j in 0..n_top {
            let (bj, cj) = (&mf.b[j * modes..(j + 1) * modes], &mf.c[j * modes..(j + 1) * modes]);
            let col = model.d.col_as_slice(j);
            for b in (0..nb).filter(|&b| live[b * n_top + j]) {
                let wj = w[b * n_top + j];
                let (br, bi) = (&mut b_re[b * modes..(b + 1) * modes], &mut b_im[b * modes..(b + 1) * modes]);
                let (cr, ci) = c[b * row..(b + 1) * row].split_at_mut(modes);
                for k in 0..modes {
                    br[k] += bj[k].re * wj;
                    bi[k] += bj[k].im * wj;
                    cr[k] += cj[k].re * wj;
                    ci[k] -= cj[k].im * wj;
                }
                for (acc, d) in dw[b * n_top..(b + 1) * n_top].iter_mut().zip(&col[..n_top]) {
                    *acc += d * wj;
                }
                for (acc, &r) in d_cl[b * n_cl..(b + 1) * n_cl].iter_mut().zip(cl_rows) {
                    *acc += col[r] * wj;
                }
            }
        }
        let mut gb = vec![0.0; nb * row];
        let (mut d_ww, mut d_sum, mut bulge_w) = (vec![0.0; nb], vec![0.0; nb], vec![0.0; nb]);
        let mut d_tcl = vec![0.0; nb * n_tcl];
        for b in 0..nb {
            let (wb, dwb, s) = (&w[b * n_top..(b + 1) * n_top], &dw[b * n_top..(b + 1) * n_top], &nz[b]);
            let gbb = &mut gb[b * row..(b + 1) * row];
            let (br, bi) = (&b_re[b * modes..(b + 1) * modes], &b_im[b * modes..(b + 1) * modes]);
            for k in 0..modes {
                gbb[k] = g_re[k] * br[k] - g_im[k] * bi[k];
                gbb[modes + k] = g_re[k] * bi[k] + g_im[k] * br[k];
            }
            d_ww[b] = s.iter().map(|&i| wb[i] * dwb[i]).sum();
            d_sum[b] = s.iter().map(|&j| d_colsum[j] * wb[j]).sum();
            bulge_w[b] = s.iter().map(|&i| wb[i] * model.bulge_top_uy_m[i]).sum();
            for (c, &r) in tcl_rows.iter().enumerate() {
                d_tcl[b * n_tcl + c] = dwb[r];
            }
        }
        TableBlock { g0: gs.start, gb, c, d_ww, d_sum, bulge_w, d_cl, d_tcl }
    }

    #[inline]
    fn c_row(&self, g: usize) -> &[f64] {
        let row = self.c.len() / self.n;
        &self.c[g * row..(g + 1) * row]
    }

    #[inline]
    fn gb_row(&self, g: usize) -> &[f64] {
        let row = self.gb.len() / self.n;
        &self.gb[g * row..(g + 1) * row]
    }

    /// Grid index and interpolation fraction of z (clamped to the strip).
    #[inline]
    fn locate(&self, z_m: f64) -> (usize, f64) {
        let x = ((z_m - self.z0_m) / TABLE_STEP_M).clamp(0.0, (self.n - 1) as f64);
        let g = (x.floor() as usize).min(self.n - 2);
        (g, x - g as f64)
    }
}

/// Contact of one substep, as the robot sees it: the wrench the strip exerts ON the tool, −F_e
/// (messages/README.md, "Frames and signs").
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WrenchOnTool {
    /// Force and torque ON the tool about the TCP, base axes.
    pub force_base_n: Vector3<f64>,
    pub torque_base_nm: Vector3<f64>,
}

impl WrenchOnTool {
    /// As a 6-vector (force, torque) for `Jᵀ W` = `−Jᵀ F_e` with the TCP Jacobian.
    pub fn as_vec6(&self) -> Vec6 {
        let (f, m) = (self.force_base_n, self.torque_base_nm);
        Vec6::new(f.x, f.y, f.z, m.x, m.y, m.z)
    }
}

/// [`StripTables`] as plain vectors in a fixed order (`table_cache`); counts as f64 (exact).
pub(crate) struct TableParts(Vec<Vec<f64>>);

impl TableParts {
    pub(crate) fn vecs(&self) -> &[Vec<f64>] {
        &self.0
    }
    pub(crate) fn from_vecs(v: Vec<Vec<f64>>) -> Option<TableParts> {
        Some(TableParts(v))
    }
}

/// The [`StripTables`]' `f64` vectors of `$t` in the cache file's order, as references (`mut`:
/// mutable): the one list both [`StripTables::parts`] and [`StripTables::from_parts`] read.
macro_rules! table_vecs {
    ($t:ident $(, $m:ident)?) => {
        [
            &$($m)? $t.table.gb,
            &$($m)? $t.table.c,
            &$($m)? $t.table.cgb_point,
            &$($m)? $t.table.cgb_cross,
            &$($m)? $t.table.d_ww,
            &$($m)? $t.table.d_sum,
            &$($m)? $t.table.bulge_w,
            &$($m)? $t.table.d_cl,
            &$($m)? $t.table.d_tcl,
            &$($m)? $t.z_re,
            &$($m)? $t.z_im,
            &$($m)? $t.csum,
            &$($m)? $t.cl_z_m,
            &$($m)? $t.cl_area_m2,
            &$($m)? $t.cl_bulge_n,
            &$($m)? $t.ccl,
            &$($m)? $t.ctcl,
            &$($m)? $t.tcl_bulge_m,
        ]
    };
}

/// What the contact needs of a strip model and a substep, computed once: the wheel table (most of
/// a run's start-up) and the modal rows of the recorded outputs. It holds the bump of the model
/// it was built from; a contact scales that bump to its own height (the bump's offsets are linear
/// in it), so every case of a sweep over bump heights shares one `Arc` of it.
#[derive(Debug, Default)]
pub struct StripTables {
    /// The model's parameters (its bump: the one the bump terms below hold).
    params: StripParams,
    table: WheelTable,
    h_s: f64,
    modes: usize,
    /// e^{λh} per mode (re, im).
    z_re: Vec<f64>,
    z_im: Vec<f64>,
    /// Σ_bottom C V (weighted) as a real row `[Re, −Im]`: total bottom reaction from the state.
    csum: Vec<f64>,
    /// Bottom output rows of the centre line, their z, tributary area and bump reaction.
    cl_rows: Vec<usize>,
    cl_z_m: Vec<f64>,
    cl_area_m2: Vec<f64>,
    cl_bulge_n: Vec<f64>,
    bulge_sum_n: f64,
    /// Output rows of C (weighted) for the centre line, real rows `[Re, −Im]`, [c * 2 modes ..].
    ccl: Vec<f64>,
    /// The same for the top nodes on the centre line (x = 0, by z; one per bottom centre-line
    /// node when the mesh has them), with their static bump displacement; empty otherwise.
    ctcl: Vec<f64>,
    tcl_bulge_m: Vec<f64>,
    /// Rest coordinates of every top-surface node (task frame, m), layer by layer, then by x.
    top_xyz_m: Vec<[f64; 3]>,
}

impl StripTables {
    /// Tables of `model` for substep `h_s` (s).
    pub fn new(model: &StripModel, h_s: f64) -> StripTables {
        assert!(h_s > 0.0 && h_s.is_finite(), "substep must be positive, got {h_s}");
        let mf = &model.modal;
        let modes = mf.modes();
        let n_top = model.n_top();
        let mut z_re = vec![0.0; modes];
        let mut z_im = vec![0.0; modes];
        let mut g_re = vec![0.0; modes];
        let mut g_im = vec![0.0; modes];
        for k in 0..modes {
            let (a, b) = (mf.lam[k].re * h_s, mf.lam[k].im * h_s);
            let e = a.exp();
            let (zr, zi) = (e * b.cos(), e * b.sin());
            z_re[k] = zr;
            z_im[k] = zi;
            // γ = (z − 1)/λ
            let (lr, li) = (mf.lam[k].re, mf.lam[k].im);
            let den = lr * lr + li * li;
            let (nr, ni) = (zr - 1.0, zi);
            g_re[k] = (nr * lr + ni * li) / den;
            g_im[k] = (ni * lr - nr * li) / den;
        }
        let n_bottom = model.n_bottom();
        let mut csum = vec![0.0; 2 * modes];
        for r in 0..n_bottom {
            for k in 0..modes {
                let c = mf.c[(n_top + r) * modes + k];
                csum[k] += c.re;
                csum[modes + k] -= c.im;
            }
        }
        let cl: Vec<(usize, f64, f64)> = model.centre_line().take(MAX_CENTRELINE).collect();
        let cl_rows: Vec<usize> = cl.iter().map(|&(i, _, _)| n_top + i).collect();
        let mut ccl = vec![0.0; cl.len() * 2 * modes];
        for (c, &row) in cl_rows.iter().enumerate() {
            for k in 0..modes {
                ccl[c * 2 * modes + k] = mf.c[row * modes + k].re;
                ccl[c * 2 * modes + modes + k] = -mf.c[row * modes + k].im;
            }
        }
        // Top centre-line nodes (the crest, x = 0) at the bottom centre line's z.
        let mut tcl: Vec<usize> = (0..n_top).filter(|&j| model.top_xyz_m[j][0].abs() < 1e-9).collect();
        tcl.sort_by(|&a, &b| model.top_xyz_m[a][2].total_cmp(&model.top_xyz_m[b][2]));
        let same_z = tcl.len() == cl.len() && tcl.iter().zip(&cl).all(|(&j, &(_, z, _))| (model.top_xyz_m[j][2] - z).abs() < 1e-9);
        if !same_z {
            tcl.clear();
        }
        let mut ctcl = vec![0.0; tcl.len() * 2 * modes];
        for (c, &row) in tcl.iter().enumerate() {
            for k in 0..modes {
                ctcl[c * 2 * modes + k] = mf.c[row * modes + k].re;
                ctcl[c * 2 * modes + modes + k] = -mf.c[row * modes + k].im;
            }
        }
        let table = WheelTable::build(model, &cl_rows, &tcl, &g_re, &g_im);
        StripTables {
            params: model.params.clone(),
            table,
            h_s,
            modes,
            z_re,
            z_im,
            csum,
            cl_z_m: cl.iter().map(|&(_, z, _)| z).collect(),
            cl_area_m2: cl.iter().map(|&(_, _, a)| a).collect(),
            cl_bulge_n: cl.iter().map(|&(i, _, _)| model.bulge_bottom_reaction_n[i]).collect(),
            bulge_sum_n: model.bulge_bottom_reaction_n.iter().sum(),
            cl_rows,
            ccl,
            ctcl,
            tcl_bulge_m: tcl.iter().map(|&j| model.bulge_top_uy_m[j]).collect(),
            top_xyz_m: model.top_xyz_m.clone(),
        }
    }

    /// The tables as plain vectors in a fixed order, for the on-disk cache (`table_cache`): the
    /// scalars, the centre-line rows, the top nodes, then [`table_vecs!`]'s vectors.
    pub(crate) fn parts(&self) -> TableParts {
        let t = self;
        let scalars = vec![t.table.z0_m, t.table.n as f64, t.h_s, t.modes as f64, t.bulge_sum_n];
        let rows = t.cl_rows.iter().map(|&r| r as f64).collect();
        let top = t.top_xyz_m.iter().flatten().copied().collect();
        TableParts([scalars, rows, top].into_iter().chain(table_vecs!(t).into_iter().cloned()).collect())
    }

    /// Tables from [`StripTables::parts`] of a model with parameters `params` and substep `h_s`;
    /// None when the parts do not fit together.
    pub(crate) fn from_parts(params: StripParams, h_s: f64, parts: TableParts) -> Option<StripTables> {
        let mut it = parts.0.into_iter();
        let (sc, rows, top) = (it.next()?, it.next()?, it.next()?);
        let &[z0_m, n, h, modes, bulge_sum_n] = sc.as_slice() else { return None };
        let (n, modes) = (n as usize, modes as usize);
        if h.to_bits() != h_s.to_bits() {
            return None;
        }
        let mut t = StripTables {
            params,
            table: WheelTable { z0_m, n, ..WheelTable::default() },
            h_s,
            modes,
            bulge_sum_n,
            cl_rows: rows.iter().map(|&r| r as usize).collect(),
            top_xyz_m: top.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            ..StripTables::default()
        };
        for v in table_vecs!(t, mut) {
            *v = it.next()?;
        }
        let row = 2 * modes;
        let ok = it.next().is_none()
            && t.table.gb.len() == n * row
            && t.table.c.len() == n * row
            && [&t.table.cgb_point, &t.table.cgb_cross, &t.table.d_ww, &t.table.d_sum, &t.table.bulge_w].iter().all(|v| v.len() == n)
            && t.z_re.len() == modes
            && t.z_im.len() == modes
            && t.csum.len() == row
            && t.ccl.len() == t.cl_rows.len() * row
            && t.table.d_cl.len() == n * t.cl_rows.len()
            && [&t.cl_z_m, &t.cl_area_m2, &t.cl_bulge_n].iter().all(|v| v.len() == t.cl_rows.len())
            && t.ctcl.len() == t.tcl_bulge_m.len() * row
            && t.table.d_tcl.len() == n * t.tcl_bulge_m.len();
        ok.then_some(t)
    }

    /// Parameters of the model the tables were built from (its bump is the one they hold).
    pub fn params(&self) -> &StripParams {
        &self.params
    }

    /// Substep length, s.
    pub fn substep_s(&self) -> f64 {
        self.h_s
    }
}

/// How much of the strip's state a tick's record carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StripDetail {
    /// Everything the recording and the 3D scene draw: every centre-line node's pressure, the
    /// top line's displacement, the maximum pressure (O(nodes × modes) per tick).
    #[default]
    Full,
    /// [`StripDetail::Full`] without the top line (zero): a tick the recording draws no scene
    /// for; every pressure and the maximum as in the full record, bit for bit.
    NoTopLine,
    /// The scalars (wheel z, contact and bottom force, top displacement under the wheel) and the
    /// centre-line pressure at the two nodes around the wheel only, the rest zero and the maximum
    /// NaN: what the rolling-phase figures read (`recording_tools::report::interpolate`), bit for
    /// bit, for a sweep or study case that writes no recording. The single-model strip only; a
    /// windowed strip's record stays full.
    UnderWheel,
    /// The scalars and the strip's state (O(modes)), the centre line and the maximum left to the
    /// recorder's writer thread, which computes them with [`StripContact::centre_line`]: the
    /// recording bit for bit the full one's (the top line on the scene's ticks only, as
    /// `NoTopLine` otherwise). A state longer than a record holds gets the full record.
    Modal,
}

/// The strip, its bulge and the unilateral wheel contact (see the module docs).
pub struct StripContact {
    geo: ContactGeometry,
    tables: Arc<StripTables>,
    /// The bump terms of this contact: the tables' scaled to its height (`bulge_scale`).
    bulge_w: Vec<f64>,
    cl_bulge_n: Vec<f64>,
    bulge_sum_n: f64,
    tcl_bulge_m: Vec<f64>,
    /// Modal state as a real row `[Re x, Im x]`.
    x: Vec<f64>,
    // Last substep's results.
    z_a_m: f64,
    delta_prev_m: f64,
    force_y_n: f64,
    wrench: WrenchOnTool,
}

impl StripContact {
    /// Contact for `model` with substep `h_s` (s), its bump as the model has it: strip at rest,
    /// no contact.
    pub fn new(model: &StripModel, geo: ContactGeometry, h_s: f64) -> StripContact {
        StripContact::with_tables(Arc::new(StripTables::new(model, h_s)), geo, 1.0)
    }

    /// Contact on shared `tables` with their bump scaled by `bulge_scale` (the height over the
    /// tables' model's height; exactly 1 keeps the model's bump bit for bit): strip at rest, no
    /// contact.
    pub fn with_tables(tables: Arc<StripTables>, geo: ContactGeometry, bulge_scale: f64) -> StripContact {
        let scaled = |v: &[f64]| v.iter().map(|x| x * bulge_scale).collect::<Vec<f64>>();
        StripContact {
            geo,
            bulge_w: scaled(&tables.table.bulge_w),
            cl_bulge_n: scaled(&tables.cl_bulge_n),
            bulge_sum_n: tables.bulge_sum_n * bulge_scale,
            tcl_bulge_m: scaled(&tables.tcl_bulge_m),
            x: vec![0.0; 2 * tables.modes],
            tables,
            z_a_m: 0.0,
            delta_prev_m: f64::NEG_INFINITY,
            force_y_n: 0.0,
            wrench: WrenchOnTool::default(),
        }
    }

    /// Substep length, s.
    pub fn substep_s(&self) -> f64 {
        self.tables.h_s
    }

    /// z of the centre-line bottom nodes (m), in the order of `StripRecord::centreline_pressure_pa`.
    pub fn centreline_z_m(&self) -> &[f64] {
        &self.tables.cl_z_m
    }

    /// Rest coordinates of the top-surface nodes (task frame, m), for the recording's scene.
    pub fn top_xyz_m(&self) -> &[[f64; 3]] {
        &self.tables.top_xyz_m
    }

    /// Wheel's lowest point (base) and the direction to it from the wheel centre, for a TCP (the
    /// wheel centre) at `tcp_pos` with tool orientation `rot`; the wheel axis is the tool y axis.
    #[inline]
    fn lowest_point(&self, tcp_pos: &Vector3<f64>, rot: &Matrix3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        Self::lowest_point_of(&self.geo, tcp_pos, rot)
    }

    /// [`StripContact::lowest_point`] for a wheel of geometry `geo` (the chain's contact too).
    #[inline]
    fn lowest_point_of(geo: &ContactGeometry, tcp_pos: &Vector3<f64>, rot: &Matrix3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let axis = rot.column(1).into_owned();
        let down = -Vector3::z();
        let in_plane = down - axis * axis.dot(&down);
        let n = in_plane.norm();
        let d = if n > 1e-9 { in_plane / n } else { down };
        (tcp_pos + d * geo.wheel_radius_m, d)
    }

    /// One substep: contact force from the wheel state at the substep start (TCP = wheel centre
    /// position, tool orientation and TCP twist (v, ω), base frame), strip advanced by h. Returns
    /// the wrench on the tool to hold over the substep.
    pub fn substep(&mut self, tcp_pos_base: &Vector3<f64>, rot_base_tool: &Matrix3<f64>, twist_base: &Vec6) -> WrenchOnTool {
        let h = self.tables.h_s;
        let (p_low, d) = self.lowest_point(tcp_pos_base, rot_base_tool);
        let v = Vector3::new(twist_base[0], twist_base[1], twist_base[2]);
        let w = Vector3::new(twist_base[3], twist_base[4], twist_base[5]);
        let v_low = v + w.cross(&(d * self.geo.wheel_radius_m));
        // Path coordinates: z along the strip (a contour's arc length), y up (the strip normal).
        let p_low_task = self.geo.path.to_path(&p_low, self.z_a_m);
        self.z_a_m = p_low_task.z;
        let y_wheel_end = p_low_task.y + self.geo.path.normal_velocity(&v_low) * h;

        let t = &self.tables.table;
        let (g, s) = t.locate(self.z_a_m);
        let lerp = |a: &[f64]| (1.0 - s) * a[g] + s * a[g + 1];
        // Free strip state at the substep end, Z x, in place; the surface under the wheel is
        // linear in the interpolated row, so it interpolates the two grid rows' outputs.
        rotate(&mut self.x, &self.tables.z_re, &self.tables.z_im);
        let [c0, c1] = dot2([t.c_row(g), t.c_row(g + 1)], &self.x);
        let u_free = (1.0 - s) * c0 + s * c1;
        // One-substep compliance under the wheel (the tabulated quadratic in s).
        let d_h = lerp(&t.d_ww) + (1.0 - s) * (1.0 - s) * t.cgb_point[g] + s * (1.0 - s) * t.cgb_cross[g] + s * s * t.cgb_point[g + 1];
        let surface = STRIP_TOP_HEIGHT_M + lerp(&self.bulge_w) + u_free;
        let delta0 = surface - y_wheel_end;
        let (k_c, c_c) = (self.geo.stiffness_n_per_m, self.geo.damping_ns_per_m);
        let delta_prev = if self.delta_prev_m.is_finite() { self.delta_prev_m } else { delta0 };
        let kk = k_c + c_c / h;
        let p = ((kk * delta0 - c_c / h * delta_prev) / (1.0 + kk * d_h)).max(0.0);
        self.delta_prev_m = delta0 - d_h * p;
        let f = -p;
        self.force_y_n = f;
        // Step the strip: x ← Z x + γ (V⁻¹ B w) f (Z x is already in place).
        if p > 0.0 {
            add_two_rows(&mut self.x, ((1.0 - s) * f, t.gb_row(g)), (s * f, t.gb_row(g + 1)));
        }
        // The wheel gets +p along base z at its lowest point.
        let force = Vector3::new(0.0, 0.0, p);
        self.wrench = WrenchOnTool { force_base_n: force, torque_base_nm: (d * self.geo.wheel_radius_m).cross(&force) };
        self.wrench
    }

    /// Wrench of the last substep on the tool as a flange-mounted sensor reports it
    /// (`messages::WrenchFrame::SensorAtTcp`: tool/flange axes, about the TCP), −F_e.
    pub fn wrench_on_tool_sensor(&self, rot_base_tool: &Matrix3<f64>) -> ([f64; 3], [f64; 3]) {
        let rt = rot_base_tool.transpose();
        ((rt * self.wrench.force_base_n).into(), (rt * self.wrench.torque_base_nm).into())
    }

    /// Last substep's wrench on the tool (base axes, about the TCP), −F_e.
    pub fn wrench_on_tool(&self) -> WrenchOnTool {
        self.wrench
    }

    /// True if the wheel pressed on the strip in the last substep.
    pub fn in_contact(&self) -> bool {
        self.force_y_n < 0.0
    }

    /// Force of the wheel on the strip along task y of the last substep, N: F_e's task-y
    /// component, negative when pressing (messages/README.md, "Frames and signs").
    pub fn contact_force_n(&self) -> f64 {
        self.force_y_n
    }

    /// Strip outputs at the current state (end of the last substep) for the recording:
    /// O(centre-line nodes × modes), once per tick.
    pub fn fill_record(&self, r: &mut StripRecord) {
        self.fill_record_with(r, StripDetail::Full);
    }

    /// [`StripContact::fill_record`] to the given detail: with [`StripDetail::UnderWheel`] the
    /// centre line's pressure at the two nodes around the wheel only, O(modes); with
    /// [`StripDetail::Modal`] the scalars and the strip's state, O(modes), the centre line left
    /// to the recorder's writer thread ([`StripContact::centre_line`]).
    pub fn fill_record_with(&self, r: &mut StripRecord, detail: StripDetail) {
        let tables = &*self.tables;
        let t = &tables.table;
        let (g, s) = t.locate(self.z_a_m);
        let lerp = |a: &[f64]| (1.0 - s) * a[g] + s * a[g + 1];
        let (f, x) = (self.force_y_n, &self.x[..]);
        // Top displacement under the wheel (dynamic + bulge), total bottom reaction.
        let [c0, c1] = dot2([t.c_row(g), t.c_row(g + 1)], x);
        let u_w = lerp(&t.d_ww) * f + lerp(&self.bulge_w) + ((1.0 - s) * c0 + s * c1);
        let reaction_sum = dot(&tables.csum, x) + lerp(&t.d_sum) * f + self.bulge_sum_n;
        r.wheel_z_m = self.z_a_m;
        r.contact_force_n = f;
        // Force of the strip on the substrate along +y (thesis sign: −10 N when pressing 10 N).
        r.bottom_force_n = -reaction_sum;
        r.top_displacement_m = u_w;
        let n_cl = tables.cl_rows.len();
        r.n_centreline = n_cl as u32;
        r.modal_len = 0;
        match detail {
            StripDetail::UnderWheel => {
                // The nodes the pressure under the wheel interpolates between (the first node
                // at or after the wheel's z and the one before it), each bit for bit the full
                // record's (`dot4` is `dot` row by row); the others, the top line and the maximum
                // are not computed.
                let m2 = 2 * tables.modes;
                let (d0, d1) = (&t.d_cl[g * n_cl..(g + 1) * n_cl], &t.d_cl[(g + 1) * n_cl..(g + 2) * n_cl]);
                let row = |c: usize| &tables.ccl[c * m2..(c + 1) * m2];
                let j = tables.cl_z_m.partition_point(|&zn| zn <= self.z_a_m);
                r.centreline_pressure_pa[..n_cl].fill(0.0);
                r.top_centreline_uy_m[..n_cl].fill(0.0);
                for c in j.saturating_sub(1)..(j + 1).min(n_cl) {
                    let reaction = dot(row(c), x) + ((1.0 - s) * d0[c] + s * d1[c]) * f + self.cl_bulge_n[c];
                    r.centreline_pressure_pa[c] = reaction / tables.cl_area_m2[c];
                }
                r.max_bottom_pressure_pa = f64::NAN;
            }
            StripDetail::Modal if x.len() <= MAX_MODAL_STATE => {
                r.modal_state[..x.len()].copy_from_slice(x);
                r.modal_len = x.len() as u32;
                // The writer thread's to fill in, with the centre line.
                r.max_bottom_pressure_pa = f64::NAN;
            }
            StripDetail::Full | StripDetail::Modal => self.centre_line_parts().expand(x, true, r),
            StripDetail::NoTopLine => self.centre_line_parts().expand(x, false, r),
        }
    }

    /// What the centre line is computed from besides the state: the tables and this contact's
    /// bump terms (borrowed: the loop's own expansion).
    fn centre_line_parts(&self) -> CentreLineParts<'_> {
        CentreLineParts { tables: &self.tables, cl_bulge_n: &self.cl_bulge_n, tcl_bulge_m: &self.tcl_bulge_m }
    }

    /// The centre line from the strip's state, for the recorder's writer thread: records made
    /// with [`StripDetail::Modal`] carry the state, and this fills in their centre line with the
    /// same code, so the recording is bit for bit the one the loop would have written. None when
    /// the state is longer than a record holds (`recordings::MAX_MODAL_STATE`): the loop keeps
    /// computing it then.
    pub fn centre_line(&self) -> Option<CentreLine> {
        (self.x.len() <= MAX_MODAL_STATE).then(|| CentreLine {
            tables: self.tables.clone(),
            cl_bulge_n: self.cl_bulge_n.clone(),
            tcl_bulge_m: self.tcl_bulge_m.clone(),
        })
    }
}

/// A contact's centre line from its state, off the loop ([`StripContact::centre_line`]).
#[derive(Debug)]
pub struct CentreLine {
    tables: Arc<StripTables>,
    cl_bulge_n: Vec<f64>,
    tcl_bulge_m: Vec<f64>,
}

impl recordings::CentreLineFromState for CentreLine {
    fn expand(&self, state: &[f64], top_line: bool, r: &mut StripRecord) {
        CentreLineParts { tables: &self.tables, cl_bulge_n: &self.cl_bulge_n, tcl_bulge_m: &self.tcl_bulge_m }.expand(state, top_line, r);
    }
}

/// The tables and bump terms the centre line needs, wherever it is computed.
struct CentreLineParts<'a> {
    tables: &'a StripTables,
    cl_bulge_n: &'a [f64],
    tcl_bulge_m: &'a [f64],
}

impl CentreLineParts<'_> {
    /// Every centre-line node's bottom pressure and their maximum, and with `top_line` the top
    /// line's displacement (else zeros), from the state `x` and `r`'s wheel z and contact force:
    /// O(centre-line nodes × modes).
    fn expand(&self, x: &[f64], top_line: bool, r: &mut StripRecord) {
        let tables = self.tables;
        let t = &tables.table;
        let (g, s) = t.locate(r.wheel_z_m);
        let (m2, f) = (2 * tables.modes, r.contact_force_n);
        let n_cl = tables.cl_rows.len();
        let (d0, d1) = (&t.d_cl[g * n_cl..(g + 1) * n_cl], &t.d_cl[(g + 1) * n_cl..(g + 2) * n_cl]);
        // Centre-line reactions from the state, four rows per pass over x.
        let row = |c: usize| &tables.ccl[c * m2..(c + 1) * m2];
        let mut c = 0;
        while c + 4 <= n_cl {
            let y = dot4([row(c), row(c + 1), row(c + 2), row(c + 3)], x);
            r.centreline_pressure_pa[c..c + 4].copy_from_slice(&y);
            c += 4;
        }
        for c in c..n_cl {
            r.centreline_pressure_pa[c] = dot(row(c), x);
        }
        let mut pmax = f64::NEG_INFINITY;
        for c in 0..n_cl {
            let reaction = r.centreline_pressure_pa[c] + ((1.0 - s) * d0[c] + s * d1[c]) * f + self.cl_bulge_n[c];
            let p = reaction / tables.cl_area_m2[c];
            r.centreline_pressure_pa[c] = p;
            pmax = pmax.max(p);
        }
        r.max_bottom_pressure_pa = if n_cl > 0 { pmax } else { 0.0 };
        if !top_line {
            r.top_centreline_uy_m[..n_cl].fill(0.0);
            return;
        }
        // Top centre-line displacement (same z), for the decimated 3D scene.
        let n_tcl = self.tcl_bulge_m.len();
        let (e0, e1) = (&t.d_tcl[g * n_tcl..(g + 1) * n_tcl], &t.d_tcl[(g + 1) * n_tcl..(g + 2) * n_tcl]);
        // Four rows per pass over x here too (each bit for bit its single dot).
        let trow = |c: usize| &tables.ctcl[c * m2..(c + 1) * m2];
        let mut c = 0;
        while c + 4 <= n_tcl {
            let y = dot4([trow(c), trow(c + 1), trow(c + 2), trow(c + 3)], x);
            r.top_centreline_uy_m[c..c + 4].copy_from_slice(&y);
            c += 4;
        }
        for c in c..n_tcl {
            r.top_centreline_uy_m[c] = dot(trow(c), x);
        }
        for c in 0..n_tcl {
            let u = r.top_centreline_uy_m[c];
            r.top_centreline_uy_m[c] = u + ((1.0 - s) * e0[c] + s * e1[c]) * f + self.tcl_bulge_m[c];
        }
        r.top_centreline_uy_m[n_tcl..n_cl].fill(0.0);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// `rig model build`/`bond` without flags must describe the strip `rig run` simulates (the
    /// shipped default scenario), so they share a cache entry and their figures apply.
    #[test]
    fn default_scenario_strip_is_the_strip_model_default() {
        let s = Scenario::load(&Scenario::default_file()).unwrap();
        assert_eq!(strip_params(&s), StripParams::default());
        assert_eq!(strip_params(&s).cache_key(), StripParams::default().cache_key());
    }

    /// A small model (20 mm, 2 mm elements, 40 states, 0.2 mm bulge at 10 mm), cached.
    /// A small strip model, quick to build, for the table tests (here and in `table_cache`).
    pub(crate) fn coarse() -> StripModel {
        let p = StripParams {
            length_m: 0.02,
            element_m: 0.002,
            order: 40,
            bulge_amplitude_m: 0.2e-3,
            bulge_width_m: 0.01,
            bulge_center_m: 0.01,
            ..StripParams::default()
        };
        StripModel::load_or_build(&p).expect("coarse strip model")
    }

    fn geo() -> ContactGeometry {
        ContactGeometry::from_scenario(&Scenario::default())
    }

    /// TCP (wheel centre) position and tool-down orientation for the wheel's lowest point at task (z, y).
    fn tcp_at(g: &ContactGeometry, z: f64, y_low: f64) -> (Vector3<f64>, Matrix3<f64>) {
        let p = g.path.point_to_base(&Vector3::new(0.0, y_low + g.wheel_radius_m, z));
        let pose = robot::tool_down_pose(p.x, p.y, p.z);
        (pose.translation.vector, pose.rotation.to_rotation_matrix().into_inner())
    }

    fn run_hold(model: &StripModel, h: f64, z: f64, y_low: f64, t_end: f64) -> StripContact {
        let g = geo();
        let mut c = StripContact::new(model, g.clone(), h);
        let (pos, rot) = tcp_at(&g, z, y_low);
        for _ in 0..(t_end / h).round() as usize {
            c.substep(&pos, &rot, &Vec6::zeros());
        }
        c
    }

    /// The under-the-wheel record is the full record's scalars and its pressure at the two nodes
    /// around the wheel, bit for bit (what a sweep case without a recording reads), at a node,
    /// between two, and before the first and past the last node.
    #[test]
    fn the_under_wheel_record_is_the_full_records_at_the_nodes_around_the_wheel() {
        let model = coarse();
        let c0 = run_hold(&model, 1e-4, 0.010, STRIP_TOP_HEIGHT_M - 0.2e-3, 0.05);
        let z_nodes = c0.centreline_z_m().to_vec();
        let (first, last) = (z_nodes[0], z_nodes[z_nodes.len() - 1]);
        for z in [first - 1e-3, first, 0.010, 0.010 + 0.37 * TABLE_STEP_M, z_nodes[z_nodes.len() / 2], last, last + 1e-3] {
            let c = run_hold(&model, 1e-4, z, STRIP_TOP_HEIGHT_M - 0.2e-3, 0.02);
            let (mut full, mut under) = (StripRecord::default(), StripRecord::default());
            c.fill_record(&mut full);
            c.fill_record_with(&mut under, StripDetail::UnderWheel);
            let bits = |r: &StripRecord| [r.wheel_z_m, r.contact_force_n, r.bottom_force_n, r.top_displacement_m].map(f64::to_bits);
            assert_eq!((bits(&under), under.n_centreline), (bits(&full), full.n_centreline), "z = {z}");
            let j = z_nodes.partition_point(|&zn| zn <= full.wheel_z_m);
            let around: Vec<usize> = (j.saturating_sub(1)..(j + 1).min(z_nodes.len())).collect();
            assert!(!around.is_empty() && around.len() <= 2, "z = {z}: {around:?}");
            for &k in &around {
                assert_eq!(under.centreline_pressure_pa[k].to_bits(), full.centreline_pressure_pa[k].to_bits(), "z = {z}, node {k}");
                assert!(full.centreline_pressure_pa[k] != 0.0, "z = {z}, node {k}: a pressed node");
            }
            let others = (0..z_nodes.len()).filter(|k| !around.contains(k));
            assert!(others.clone().all(|k| under.centreline_pressure_pa[k] == 0.0), "z = {z}");
            assert!(under.max_bottom_pressure_pa.is_nan() && full.max_bottom_pressure_pa.is_finite());
            // Without the top line: everything else as the full record, bit for bit.
            let mut no_top = StripRecord::default();
            c.fill_record_with(&mut no_top, StripDetail::NoTopLine);
            let n = full.n_centreline as usize;
            let p = |r: &StripRecord| r.centreline_pressure_pa[..n].iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!((bits(&no_top), no_top.n_centreline, p(&no_top)), (bits(&full), full.n_centreline, p(&full)), "z = {z}");
            assert_eq!(no_top.max_bottom_pressure_pa.to_bits(), full.max_bottom_pressure_pa.to_bits(), "z = {z}");
            assert!(no_top.top_centreline_uy_m[..n].iter().all(|&u| u == 0.0) && full.top_centreline_uy_m[..n].iter().any(|&u| u != 0.0));
        }
    }

    /// A modal record carries the full record's scalars and the strip's state, and the writer
    /// thread's expansion of it ([`StripContact::centre_line`]) gives the full record's centre
    /// line, maximum and top line bit for bit, or the no-top-line record's without the top line;
    /// a state longer than a record holds gets the full record instead.
    #[test]
    fn the_writer_threads_centre_line_from_the_modal_record_is_the_loops_bit_for_bit() {
        use recordings::CentreLineFromState;
        let model = coarse();
        for z in [0.010, 0.010 + 0.37 * TABLE_STEP_M, 0.02] {
            let c = run_hold(&model, 1e-4, z, STRIP_TOP_HEIGHT_M - 0.2e-3, 0.05);
            let (mut full, mut no_top, mut modal) = (StripRecord::default(), StripRecord::default(), StripRecord::default());
            c.fill_record(&mut full);
            c.fill_record_with(&mut no_top, StripDetail::NoTopLine);
            c.fill_record_with(&mut modal, StripDetail::Modal);
            let bits = |r: &StripRecord| [r.wheel_z_m, r.contact_force_n, r.bottom_force_n, r.top_displacement_m].map(f64::to_bits);
            assert_eq!((bits(&modal), modal.n_centreline), (bits(&full), full.n_centreline), "z = {z}");
            assert_eq!(modal.modal_len as usize, c.x.len(), "z = {z}: the whole state");
            assert_eq!(modal.modal_state[..c.x.len()], c.x[..], "z = {z}");
            assert!(modal.max_bottom_pressure_pa.is_nan(), "z = {z}: the maximum is the writer's");
            assert_eq!((full.modal_len, no_top.modal_len), (0, 0));
            let line = c.centre_line().expect("the coarse model's state fits a record");
            let n = full.n_centreline as usize;
            let p = |r: &StripRecord| r.centreline_pressure_pa[..n].iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let u = |r: &StripRecord| r.top_centreline_uy_m[..n].iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            for (top_line, want) in [(true, &full), (false, &no_top)] {
                let mut r = modal;
                line.expand(&modal.modal_state[..modal.modal_len as usize], top_line, &mut r);
                assert_eq!((p(&r), u(&r)), (p(want), u(want)), "z = {z}, top line {top_line}");
                assert_eq!(r.max_bottom_pressure_pa.to_bits(), want.max_bottom_pressure_pa.to_bits(), "z = {z}");
            }
            assert!(full.centreline_pressure_pa[..n].iter().any(|&x| x != 0.0) && full.top_centreline_uy_m[..n].iter().any(|&x| x != 0.0));
        }
        // A state a record cannot hold: no writer-side centre line, and the full record.
        let mut c = run_hold(&model, 1e-4, 0.010, STRIP_TOP_HEIGHT_M - 0.2e-3, 0.05);
        c.x.resize(MAX_MODAL_STATE + 2, 0.0);
        assert!(c.centre_line().is_none());
        let mut r = StripRecord::default();
        c.fill_record_with(&mut r, StripDetail::Modal);
        assert_eq!(r.modal_len, 0);
        assert!(r.max_bottom_pressure_pa.is_finite());
    }

    /// Wheel held at a fixed depth: the steady force solves p = k (H + w·u_bulge − y − C_s p)
    /// with C_s = wᵀ G(0) w the reduced model's static compliance (independent evaluation via
    /// `StripModel::static_response`); the bottom reactions balance the wheel force.
    #[test]
    fn static_press_matches_the_static_compliance_and_equilibrium() {
        // On a table grid point and between two (the tabulated wheel direction is interpolated).
        for z in [0.010, 0.010 + 0.37 * TABLE_STEP_M] {
            static_press_at(z);
        }
    }

    fn static_press_at(z: f64) {
        let model = coarse();
        let g = geo();
        let depth = 0.2e-3;
        let y_low = STRIP_TOP_HEIGHT_M - depth;
        let c = run_hold(&model, 1e-4, z, y_low, 0.6);
        let mut w = vec![0.0; model.n_top()];
        model.gaussian_weights(z, &mut w);
        let y = model.static_response(&w);
        let c_s: f64 = w.iter().zip(&y).map(|(a, b)| a * b).sum::<f64>().abs();
        let bulge_w: f64 = w.iter().zip(&model.bulge_top_uy_m).map(|(a, b)| a * b).sum();
        let k = g.stiffness_n_per_m;
        let p_expect = k * (depth + bulge_w) / (1.0 + k * c_s);
        let p = -c.contact_force_n();
        assert!((p - p_expect).abs() < 1e-4 * p_expect, "p = {p}, expected {p_expect}");
        assert!(c.in_contact());
        let mut r = StripRecord::default();
        c.fill_record(&mut r);
        assert!(
            (r.bottom_force_n - c.contact_force_n()).abs() < 1e-4 * p,
            "bottom {} vs contact {}",
            r.bottom_force_n,
            c.contact_force_n()
        );
        assert!((r.wheel_z_m - z).abs() < 1e-12);
        // The surface under the wheel sits where the penalty spring says.
        let surface = STRIP_TOP_HEIGHT_M + r.top_displacement_m;
        assert!((k * (surface - y_low) - p).abs() < 1e-6 * p, "{surface}");
        assert!(r.n_centreline as usize == model.centre_bottom.len() && r.max_bottom_pressure_pa > 0.0);
        // The top centre line (the crest, x = 0) displaced as the static response to the wheel's
        // force says, the bulge's static displacement added.
        let mut crest: Vec<usize> = (0..model.n_top()).filter(|&j| model.top_xyz_m[j][0].abs() < 1e-9).collect();
        crest.sort_by(|&a, &b| model.top_xyz_m[a][2].total_cmp(&model.top_xyz_m[b][2]));
        assert_eq!(crest.len(), r.n_centreline as usize);
        let f = c.contact_force_n();
        let scale = crest.iter().map(|&j| (y[j] * f).abs()).fold(0.0, f64::max);
        assert!(scale > 1e-6, "the wheel presses the crest: {scale} m");
        for (k, &j) in crest.iter().enumerate() {
            let want = y[j] * f + model.bulge_top_uy_m[j];
            assert!((r.top_centreline_uy_m[k] - want).abs() < 1e-4 * scale, "crest node {k}: {} vs {want}", r.top_centreline_uy_m[k]);
        }
        // The wrench on the tool: +p along base z, no moment about the wheel centre.
        let wr = c.wrench_on_tool();
        assert!((wr.force_base_n.z - p).abs() < 1e-12 && wr.torque_base_nm.norm() < 1e-12 * p);
    }

    /// The table as the plain formulas give it, one grid point at a time (the build before its
    /// loops were blocked; kept as the reference of the fast build).
    fn plain_table(model: &StripModel, cl_rows: &[usize], tcl_rows: &[usize], g_re: &[f64], g_im: &[f64]) -> WheelTable {
        let mf = &model.modal;
        let modes = mf.modes();
        let n_top = model.n_top();
        let n_bottom = model.n_bottom();
        let n_cl = cl_rows.len();
        let n = (model.params.length_m / TABLE_STEP_M).round() as usize + 1;
        let row = 2 * modes;
        let mut t = WheelTable::zeroed(n, row, n_cl, tcl_rows.len());
        let d_colsum: Vec<f64> = (0..n_top).map(|j| (0..n_bottom).map(|r| model.d[(n_top + r, j)]).sum()).collect();
        let mut w = vec![0.0; n_top];
        let mut dw = vec![0.0; n_top];
        let (mut b_re, mut b_im) = (vec![0.0; modes], vec![0.0; modes]);
        for g in 0..n {
            let z = t.z0_m + g as f64 * TABLE_STEP_M;
            model.gaussian_weights(z, &mut w);
            let wmax = w.iter().cloned().fold(0.0, f64::max);
            let nz: Vec<usize> = (0..n_top).filter(|&j| w[j] > 1e-15 * wmax).collect();
            b_re.fill(0.0);
            b_im.fill(0.0);
            let c = &mut t.c[g * row..(g + 1) * row];
            for &j in &nz {
                let wj = w[j];
                for k in 0..modes {
                    let b = mf.b[j * modes + k];
                    b_re[k] += b.re * wj;
                    b_im[k] += b.im * wj;
                    let cc = mf.c[j * modes + k];
                    c[k] += cc.re * wj;
                    c[modes + k] -= cc.im * wj;
                }
            }
            let gb = &mut t.gb[g * row..(g + 1) * row];
            for k in 0..modes {
                gb[k] = g_re[k] * b_re[k] - g_im[k] * b_im[k];
                gb[modes + k] = g_re[k] * b_im[k] + g_im[k] * b_re[k];
            }
            for (i, dwi) in dw.iter_mut().enumerate() {
                *dwi = nz.iter().map(|&j| model.d[(i, j)] * w[j]).sum();
            }
            t.d_ww[g] = nz.iter().map(|&i| w[i] * dw[i]).sum();
            t.d_sum[g] = nz.iter().map(|&j| d_colsum[j] * w[j]).sum();
            t.bulge_w[g] = nz.iter().map(|&i| w[i] * model.bulge_top_uy_m[i]).sum();
            for (c, &row) in cl_rows.iter().enumerate() {
                t.d_cl[g * n_cl + c] = nz.iter().map(|&j| model.d[(row, j)] * w[j]).sum();
            }
            for (c, &row) in tcl_rows.iter().enumerate() {
                t.d_tcl[g * tcl_rows.len() + c] = nz.iter().map(|&j| model.d[(row, j)] * w[j]).sum();
            }
        }
        t.finish_compliance();
        t
    }

    /// Every number of a table, as bits (`{:?}` of an f64 prints it exactly, the sign of zero too).
    fn table_bits(t: &WheelTable) -> Vec<u64> {
        let v = [&t.gb, &t.c, &t.cgb_point, &t.cgb_cross, &t.d_ww, &t.d_sum, &t.bulge_w, &t.d_cl, &t.d_tcl];
        v.iter().flat_map(|v| v.iter().map(|x| x.to_bits())).chain([t.n as u64, t.z0_m.to_bits()]).collect()
    }

    /// The blocked, multi-threaded table build gives the plain formulas' table bit for bit (the
    /// physics digests of the tick-identity test rest on it), on a grid whose length is not a
    /// multiple of the block.
    #[test]
    fn fast_table_build_is_the_plain_one_bit_for_bit() {
        let model = coarse();
        let tables = StripTables::new(&model, 1e-4);
        assert_ne!(tables.table.n % BUILD_BLOCK, 0, "the last block is a short one");
        let modes = model.modal.modes();
        let (mut g_re, mut g_im) = (vec![0.0; modes], vec![0.0; modes]);
        for k in 0..modes {
            let (lr, li) = (model.modal.lam[k].re, model.modal.lam[k].im);
            let (zr, zi) = (tables.z_re[k], tables.z_im[k]);
            let den = lr * lr + li * li;
            g_re[k] = ((zr - 1.0) * lr + zi * li) / den;
            g_im[k] = (zi * lr - (zr - 1.0) * li) / den;
        }
        let mut tcl: Vec<usize> = (0..model.n_top()).filter(|&j| model.top_xyz_m[j][0].abs() < 1e-9).collect();
        tcl.sort_by(|&a, &b| model.top_xyz_m[a][2].total_cmp(&model.top_xyz_m[b][2]));
        assert_eq!(tcl.len(), tables.cl_rows.len(), "the coarse mesh has a top centre line");
        let plain = plain_table(&model, &tables.cl_rows, &tcl, &g_re, &g_im);
        assert!(table_bits(&tables.table) == table_bits(&plain), "fast and plain tables differ");
        assert!(tables.table.d_ww.iter().all(|v| *v != 0.0) && tables.table.d_tcl.iter().any(|v| *v != 0.0), "a table of something");
    }

    /// Wheel history on a contact: press at 0.2 mm depth while rolling along, then the record.
    fn roll(c: &mut StripContact) -> Vec<u64> {
        let g = geo();
        let mut out = Vec::new();
        let mut r = StripRecord::default();
        for i in 0..400 {
            let z = 0.004 + 0.03e-3 * i as f64;
            let (pos, rot) = tcp_at(&g, z, STRIP_TOP_HEIGHT_M - 0.2e-3);
            c.substep(&pos, &rot, &Vec6::new(3e-3, 0.0, 0.0, 0.0, 0.0, 0.0));
            c.fill_record(&mut r);
            out.extend([c.contact_force_n(), r.bottom_force_n, r.top_displacement_m, r.max_bottom_pressure_pa].map(f64::to_bits));
            out.extend(r.centreline_pressure_pa[..r.n_centreline as usize].iter().map(|p| p.to_bits()));
        }
        out
    }

    /// Contacts on one shared table (a sweep's cases) run bit for bit as contacts on tables of
    /// their own (their daemon runs), at the reference bump and scaled to other heights; a scale
    /// of 1 is the model's bump exactly, and the bump does change the run.
    #[test]
    fn contacts_on_shared_tables_run_as_contacts_built_alone() {
        let model = coarse();
        let shared = Arc::new(StripTables::new(&model, 1e-4));
        let mut histories = Vec::new();
        for scale in [1.0, 0.5, 1.85, 0.0] {
            let mut on_shared = StripContact::with_tables(shared.clone(), geo(), scale);
            let mut alone = StripContact::with_tables(Arc::new(StripTables::new(&model, 1e-4)), geo(), scale);
            let h = roll(&mut on_shared);
            assert!(h == roll(&mut alone), "scale {scale}: the shared table's contact differs");
            histories.push(h);
        }
        assert!(histories[0] == roll(&mut StripContact::new(&model, geo(), 1e-4)), "scale 1 is the model's bump");
        assert!(histories[1] != histories[0] && histories[3] != histories[0], "the bump's height changes the run");
    }

    /// The four- and two-row dot products give each row bit for bit what the single one does
    /// (the recorded pressures must not depend on how the rows were grouped), on the AVX2 path and
    /// the portable one, for lengths with and without a remainder; the substep's element-wise
    /// steps give the same bits on both paths.
    #[test]
    fn four_row_dot_equals_the_single_row_dot_bit_for_bit() {
        for n in [0, 5, 8, 264, 267] {
            let v = |seed: f64| -> Vec<f64> { (0..n).map(|i| ((i as f64 + seed) * 0.7).sin() * 10f64.powi(i % 7 - 3)).collect() };
            let (x, r0, r1, r2, r3) = (v(0.1), v(1.3), v(2.9), v(4.4), v(5.5));
            let rows = [&r0[..], &r1[..], &r2[..], &r3[..]];
            for (got, want) in
                [(dot4(rows, &x), rows.map(|r| dot(r, &x))), (dot_rows_portable(rows, &x), rows.map(|r| dot_portable(r, &x)))]
            {
                assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "n = {n}: {got:?} vs {want:?}");
            }
            let pair = [&r0[..], &r1[..]];
            for got in [dot2(pair, &x), dot_rows_portable(pair, &x)] {
                assert_eq!(got.map(f64::to_bits), pair.map(|r| dot(r, &x).to_bits()), "n = {n}");
            }
            // The element-wise steps: the dispatched path gives the portable path's bits.
            let (mut a, mut b) = (x.clone(), x.clone());
            let half = n as usize / 2;
            rotate(&mut a, &r0[..half], &r1[..half]);
            rotate_portable(&mut b, &r0[..half], &r1[..half]);
            add_two_rows(&mut a, (0.3, &r2), (-1.7, &r3));
            add_two_rows_portable(&mut b, (0.3, &r2), (-1.7, &r3));
            assert_eq!(a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), b.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), "n = {n}");
            let direct: f64 = r2.iter().zip(&x).map(|(a, b)| a * b).sum();
            assert!((dot(&r2, &x) - direct).abs() <= 1e-12 * r2.iter().zip(&x).map(|(a, b)| (a * b).abs()).sum::<f64>());
        }
    }

    /// After lift-off the strip's modes decay freely: with the floor, every coordinate ends at
    /// a normal number or exactly zero, never a subnormal one (whose arithmetic is slow), and the
    /// floor is where the rotation flushes: 1e-199 stays, its product under the floor goes.
    #[test]
    fn decaying_modes_reach_zero_without_passing_through_subnormal_numbers() {
        let model = coarse();
        let g = geo();
        let h = 1e-4;
        let mut c = run_hold(&model, h, 0.01, STRIP_TOP_HEIGHT_M - 0.2e-3, 0.01);
        assert!(c.in_contact() && c.x.iter().any(|&v| v != 0.0));
        let (pos, rot) = tcp_at(&g, 0.01, STRIP_TOP_HEIGHT_M + 1e-3);
        let (mut zeros, mut max_seen) = (0, 0.0f64);
        for _ in 0..200_000 {
            c.substep(&pos, &rot, &Vec6::zeros());
            assert!(!c.in_contact());
            assert!(c.x.iter().all(|v| !v.is_subnormal()), "a subnormal modal coordinate");
            zeros = c.x.iter().filter(|&&v| v == 0.0).count();
            max_seen = c.x.iter().fold(0.0, |m, v| m.max(v.abs()));
        }
        eprintln!("after 20 s of free decay: {zeros} of {} coordinates zero, largest {max_seen:e}", c.x.len());
        assert!(zeros > 0, "no mode decayed to the floor in 20 s");
        let mut x = vec![1e-199, 1e-199, 1.0, 0.0];
        rotate(&mut x, &[1.0, 1e-2], &[0.0, 0.0]);
        assert_eq!(x, vec![1e-199, 0.0, 1.0, 0.0]);
    }

    #[test]
    fn wheel_above_the_strip_feels_nothing() {
        let model = coarse();
        let c = run_hold(&model, 1e-4, 0.004, STRIP_TOP_HEIGHT_M + 0.5e-3, 0.05);
        assert_eq!(c.contact_force_n(), 0.0);
        assert!(!c.in_contact());
        assert_eq!(c.wrench_on_tool().force_base_n, Vector3::zeros());
    }

    /// Approach at 10 mm/s, touch, press 0.3 mm, lift off again; halving the substep changes the
    /// force history by well under the 1% and never by more than the previous halving.
    /// (The asymptotic O(h) regime only starts below the time constants of the highest retained
    /// strip modes, ~60 µs for the 2500 Hz cut-off, so the change does not halve yet at 100 µs.)
    #[test]
    fn touch_and_lift_off_converge_with_the_substep() {
        let model = coarse();
        let g = geo();
        let traj = |t: f64| -> (f64, f64) {
            // lowest point height and velocity: down 10 mm/s from +0.5 mm for 80 ms, then back up
            let (y0, v) = (STRIP_TOP_HEIGHT_M + 0.5e-3, 0.01);
            if t < 0.08 {
                (y0 - v * t, -v)
            } else {
                (y0 - v * 0.08 + v * (t - 0.08), v)
            }
        };
        let history = |h: f64| -> Vec<f64> {
            let mut c = StripContact::new(&model, g.clone(), h);
            let n = (0.2 / h).round() as usize;
            let every = (1e-3 / h).round() as usize;
            let mut out = Vec::new();
            for i in 0..n {
                let t = i as f64 * h;
                let (y, v) = traj(t);
                let (pos, rot) = tcp_at(&g, 0.008, y);
                c.substep(&pos, &rot, &Vec6::new(0.0, 0.0, v, 0.0, 0.0, 0.0));
                if (i + 1) % every == 0 {
                    out.push(c.contact_force_n());
                }
            }
            out
        };
        let (a, b, c) = (history(2e-4), history(1e-4), history(5e-5));
        let peak = b.iter().cloned().fold(0.0, f64::min).abs();
        assert!(peak > 1.0, "the wheel never pressed: {peak}");
        assert_eq!(*b.last().unwrap(), 0.0, "no lift-off");
        let diff = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
        let (d1, d2) = (diff(&a, &b), diff(&b, &c));
        assert!(d2 < 0.01 * peak, "h=1e-4 vs 5e-5 differ by {d2} N (peak {peak} N)");
        assert!(d2 <= d1, "no convergence: {d1} then {d2}");
    }
}
