//! Lowest generalized eigenpairs K phi = lambda M phi of large sparse symmetric pencils:
//! block shift-invert Lanczos (shift 0, operator K^-1 M, self-adjoint in the M inner product)
//! with full re-orthogonalisation. K must be positive definite (held structure).
//!
//! A block of right-hand sides per solve: the sparse triangular solves are memory-bound, a block
//! of 8 columns costs about two single-column solves (one pass over the factor), and the Krylov
//! space grows 8 vectors per pass. Convergence is judged on the Ritz pairs of the projection
//! T = Q^T M K^-1 M Q with the residual norm ||B s_last|| of the block recurrence.

use faer::{Mat, MatRef, Par, Side};

use crate::error::{numeric, Result};
use crate::sparse::{Cholesky, Csc};

/// What to compute.
#[derive(Clone, Copy, Debug)]
pub enum Want {
    /// Every eigenvalue lambda = omega^2 below this bound.
    Below(f64),
    /// The lowest `n` eigenpairs.
    Count(usize),
}

/// Eigenvalues (ascending) and M-orthonormal eigenvectors (columns).
pub struct Modes {
    pub lambda: Vec<f64>,
    pub vectors: Mat<f64>,
}

/// Relative residual bound ||K^-1 M x - theta x||_M <= TOL theta of a converged Ritz pair.
const TOL: f64 = 1e-11;
/// Residual bound of the first Ritz pair beyond a `Want::Below` cut-off (it only closes the
/// count of wanted pairs).
const TOL_COUNT: f64 = 1e-6;

/// Columns per Lanczos block: 8 right-hand sides cost about two single-vector solves (one pass
/// over the memory-bound factor), and the step count to convergence drops only slowly with the
/// block size (measured on the 1 mm strip: 41 steps of 1, 17 of 8, 16 of 16 for the CB modes).
const BLOCK: usize = 8;

/// M-orthonormalises the columns of `w` in place (Cholesky QR, twice), returning M w and the
/// factor R with w_in = w_out R (p x p, upper triangular). One sparse product: M w is carried
/// through the same small right-hand transformations as w.
fn m_orthonormalise(w: &mut Mat<f64>, m: &Csc) -> Result<(Mat<f64>, Mat<f64>)> {
    let p = w.ncols();
    let mut r_total = Mat::<f64>::identity(p, p);
    let mut mw = m.mul_dense(w.as_ref());
    for _ in 0..2 {
        let g = mul_seq(w.transpose(), mw.as_ref());
        let g = Mat::from_fn(p, p, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
        let llt =
            g.llt(Side::Lower).map_err(|_| numeric("lanczos", "Krylov block lost rank (invariant subspace reached before convergence)"))?;
        let l = llt.L();
        let mut l_inv_t = Mat::<f64>::identity(p, p); // L^-T = (L^-1 I)^T
        l.solve_lower_triangular_in_place(l_inv_t.as_mut());
        let l_inv_t = l_inv_t.transpose().to_owned();
        *w = mul_seq(w.as_ref(), l_inv_t.as_ref());
        mw = mul_seq(mw.as_ref(), l_inv_t.as_ref());
        r_total = l.transpose() * &r_total;
    }
    Ok((mw, r_total))
}

/// A B on the calling thread (the Lanczos run shares the machine with the constraint-mode solves).
fn mul_seq(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut c = Mat::<f64>::zeros(a.nrows(), b.ncols());
    faer::linalg::matmul::matmul(c.as_mut(), faer::Accum::Replace, a, b, 1.0, Par::Seq);
    c
}

/// W -= A B on the calling thread.
fn sub_mul_seq(w: &mut Mat<f64>, a: MatRef<'_, f64>, b: MatRef<'_, f64>) {
    faer::linalg::matmul::matmul(w.as_mut(), faer::Accum::Add, a, b, -1.0, Par::Seq);
}

/// Column storage that grows by doubling (Krylov basis and its M image).
struct Basis {
    cols: Mat<f64>,
    len: usize,
}

impl Basis {
    fn new(n: usize, cap: usize) -> Basis {
        Basis { cols: Mat::zeros(n, cap), len: 0 }
    }
    fn view(&self) -> MatRef<'_, f64> {
        self.cols.as_ref().subcols(0, self.len)
    }
    fn push(&mut self, block: MatRef<'_, f64>) {
        let (n, p) = (self.cols.nrows(), block.ncols());
        if self.len + p > self.cols.ncols() {
            let mut bigger = Mat::<f64>::zeros(n, (2 * self.cols.ncols()).max(self.len + p));
            bigger.as_mut().subcols_mut(0, self.len).copy_from(self.view());
            self.cols = bigger;
        }
        self.cols.as_mut().subcols_mut(self.len, p).copy_from(block);
        self.len += p;
    }
}

/// Deterministic pseudo-random start block.
fn start_block(n: usize, p: usize) -> Mat<f64> {
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut out = Mat::<f64>::zeros(n, p);
    for j in 0..p {
        for i in 0..n {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            out[(i, j)] = (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        }
    }
    out
}

/// Block Lanczos on K^-1 M. `k_fact` factors K, `m` is M (same size). Single-threaded (the
/// caller may run it beside other work).
pub fn lowest_modes(k_fact: &Cholesky, _k: &Csc, m: &Csc, want: Want) -> Result<Modes> {
    lowest_modes_block(k_fact, m, want, BLOCK)
}

/// [`lowest_modes`] with an explicit block size `p` (columns per solve).
pub fn lowest_modes_block(k_fact: &Cholesky, m: &Csc, want: Want, p: usize) -> Result<Modes> {
    let n = m.nrows;
    let p = p.clamp(1, n);
    // the step count (polynomial degree) sets convergence, whatever the block size
    let max_vecs = n.min(match want {
        Want::Count(c) => p * (c + 60),
        Want::Below(_) => 4000,
    });
    // M-orthonormal Krylov basis Q (blocks of p), M Q, and the projection T = Q^T M K^-1 M Q
    let cap = (16 * p).min(max_vecs.max(p));
    let (mut q, mut mq) = (Basis::new(n, cap), Basis::new(n, cap));
    let mut t_cols: Vec<Mat<f64>> = Vec::new(); // block column j of T, rows 0..(j + 1) p
    let mut w = start_block(n, p);
    let (mw, _) = m_orthonormalise(&mut w, m)?;
    q.push(w.as_ref());
    mq.push(mw.as_ref());
    loop {
        let j = q.len / p - 1;
        let mut w = mq.view().subcols(j * p, p).to_owned();
        k_fact.solve_in_place_par(w.as_mut(), Par::Seq);
        // classical Gram-Schmidt against the whole basis: the first-pass coefficients are the
        // entries of T; a second pass removes the rounding left by the first
        let coef = mul_seq(mq.view().transpose(), w.as_ref());
        sub_mul_seq(&mut w, q.view(), coef.as_ref());
        let c2 = mul_seq(mq.view().transpose(), w.as_ref());
        sub_mul_seq(&mut w, q.view(), c2.as_ref());
        t_cols.push(coef);
        let k = q.len;
        let exhausted = k + p > max_vecs;
        let (mw, b) = match m_orthonormalise(&mut w, m) {
            Ok(x) => x,
            Err(_) if !exhausted => return Err(numeric("lanczos", "invariant subspace reached before convergence")),
            Err(_) => (Mat::zeros(n, p), Mat::zeros(p, p)),
        };
        // Ritz pairs of the projection, residual ||B s_last|| for Ritz vector Q s
        // T_ab (block row a, block column b) = t_cols[b] rows of block a, for a <= b; symmetric
        let t = Mat::from_fn(k, k, |r, c| {
            let (r, c) = if r / p <= c / p { (r, c) } else { (c, r) };
            if r / p == c / p {
                0.5 * (t_cols[c / p][(r, c % p)] + t_cols[r / p][(c, r % p)])
            } else {
                t_cols[c / p][(r, c % p)]
            }
        });
        let evd = t.self_adjoint_eigen(Side::Lower).map_err(|e| numeric("lanczos", format!("{e:?}")))?;
        let s = evd.S().column_vector();
        let u = evd.U();
        // theta descending = lambda ascending
        let mut idx: Vec<usize> = (0..k).collect();
        idx.sort_by(|&x, &y| s[y].total_cmp(&s[x]));
        let residual = |col: usize| {
            let last = u.subrows(k - p, p).col(col).to_owned();
            (&b * &last).norm_l2()
        };
        let converged = |col: usize| s[col] > 0.0 && residual(col) <= TOL * s[col];
        let (done, take): (bool, Vec<usize>) = match want {
            Want::Count(c) => (idx.iter().take(c).all(|&x| converged(x)) && k >= c, idx.iter().take(c).copied().collect()),
            Want::Below(lmax) => {
                // all Ritz values below the bound converged, and one beyond it settled well
                // enough (TOL_COUNT) to close the count; that one is not kept
                let below: Vec<usize> = idx.iter().copied().filter(|&x| s[x] > 0.0 && 1.0 / s[x] <= lmax).collect();
                let beyond = idx.iter().any(|&x| s[x] > 0.0 && 1.0 / s[x] > lmax && residual(x) <= TOL_COUNT * s[x]);
                (beyond && below.iter().all(|&x| converged(x)), below)
            }
        };
        if done || exhausted {
            if !done {
                tracing::warn!(vectors = k, "lanczos stopped before every wanted eigenpair converged");
            }
            let lambda: Vec<f64> = take.iter().map(|&x| 1.0 / s[x]).collect();
            let sel = Mat::from_fn(k, take.len(), |r, c| u[(r, take[c])]);
            let vectors = mul_seq(q.view(), sel.as_ref());
            return Ok(Modes { lambda, vectors });
        }
        q.push(w.as_ref());
        mq.push(mw.as_ref());
    }
}
