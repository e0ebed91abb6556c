//! Minimal compressed-sparse-column storage with the few operations the pipeline needs, and a
//! bridge to faer's sparse Cholesky (AMD ordering, supernodal when worthwhile).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::reborrow::Reborrow;
use faer::reborrow::ReborrowMut;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::error::{numeric, Result};

/// Square or rectangular CSC matrix; row indices sorted within each column.
#[derive(Clone, Debug, Default)]
pub struct Csc {
    pub nrows: usize,
    pub ncols: usize,
    pub col_ptr: Vec<usize>,
    pub row_idx: Vec<usize>,
    pub val: Vec<f64>,
}

impl Csc {
    pub fn nnz(&self) -> usize {
        self.val.len()
    }

    /// faer view of this matrix.
    pub fn as_faer(&self) -> SparseColMatRef<'_, usize, f64> {
        SparseColMatRef::new(SymbolicSparseColMatRef::new_checked(self.nrows, self.ncols, &self.col_ptr, None, &self.row_idx), &self.val)
    }

    /// Submatrix: rows through `row_map` (old row -> new row or `usize::MAX` to drop), columns
    /// `cols` (old column indices, in new order).
    pub fn submatrix(&self, row_map: &[usize], new_nrows: usize, cols: &[usize]) -> Csc {
        let mut col_ptr = Vec::with_capacity(cols.len() + 1);
        let mut row_idx = Vec::new();
        let mut val = Vec::new();
        col_ptr.push(0);
        let mut buf: Vec<(usize, f64)> = Vec::new();
        for &c in cols {
            buf.clear();
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                let r = row_map[self.row_idx[p]];
                if r != usize::MAX {
                    buf.push((r, self.val[p]));
                }
            }
            if buf.windows(2).any(|w| w[0].0 > w[1].0) {
                buf.sort_unstable_by_key(|e| e.0);
            }
            for &(r, v) in &buf {
                row_idx.push(r);
                val.push(v);
            }
            col_ptr.push(row_idx.len());
        }
        Csc { nrows: new_nrows, ncols: cols.len(), col_ptr, row_idx, val }
    }

    /// Copy without the stored zeros (the consistent mass shares the stiffness pattern, whose
    /// 3x3 node blocks are dense, but couples only equal directions: two thirds are zeros).
    pub fn without_zeros(&self) -> Csc {
        let mut col_ptr = Vec::with_capacity(self.ncols + 1);
        let (mut row_idx, mut val) = (Vec::new(), Vec::new());
        col_ptr.push(0);
        for c in 0..self.ncols {
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                if self.val[p] != 0.0 {
                    row_idx.push(self.row_idx[p]);
                    val.push(self.val[p]);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Csc { nrows: self.nrows, ncols: self.ncols, col_ptr, row_idx, val }
    }

    /// y = A x
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        for c in 0..self.ncols {
            let xc = x[c];
            if xc == 0.0 {
                continue;
            }
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                y[self.row_idx[p]] += self.val[p] * xc;
            }
        }
    }

    /// Y = A X for a dense X (ncols x k), returned as nrows x k.
    pub fn mul_dense(&self, x: faer::MatRef<'_, f64>) -> faer::Mat<f64> {
        let mut y = faer::Mat::<f64>::zeros(self.nrows, x.ncols());
        self.mul_dense_to(x, y.as_mut());
        y
    }

    /// Y = A X into `y` (overwritten). Panels of `PANEL` columns of X and Y are packed row-major,
    /// so each stored entry of A does one contiguous multiply-add over the panel instead of
    /// `PANEL` strided ones (single-threaded; callers split columns over threads).
    pub fn mul_dense_to(&self, x: faer::MatRef<'_, f64>, y: faer::MatMut<'_, f64>) {
        self.panel_product(x, y, false);
    }

    /// Y = A X into `y` for a symmetric A (a stiffness or mass block): column i of A is used as
    /// row i, so each output row is summed in registers (a gather, no scattered stores).
    pub fn sym_mul_dense_to(&self, x: faer::MatRef<'_, f64>, y: faer::MatMut<'_, f64>) {
        assert!(self.nrows == self.ncols, "symmetric product needs a square matrix");
        self.panel_product(x, y, true);
    }

    fn panel_product(&self, x: faer::MatRef<'_, f64>, mut y: faer::MatMut<'_, f64>, symmetric: bool) {
        const PANEL: usize = 8;
        assert!(x.nrows() == self.ncols && y.nrows() == self.nrows && y.ncols() == x.ncols(), "shape mismatch");
        let k = x.ncols();
        let mut xb = vec![0.0; self.ncols * PANEL];
        let mut yb = vec![0.0; self.nrows * PANEL];
        for c0 in (0..k).step_by(PANEL) {
            let w = PANEL.min(k - c0);
            if w < PANEL {
                xb.fill(0.0);
            }
            for j in 0..w {
                for (i, v) in x.col(c0 + j).iter().enumerate() {
                    xb[i * PANEL + j] = *v;
                }
            }
            if !symmetric {
                yb.fill(0.0);
            }
            for c in 0..self.ncols {
                let (s, e) = (self.col_ptr[c], self.col_ptr[c + 1]);
                if symmetric {
                    let mut acc = [0.0; PANEL];
                    for (&r, &v) in self.row_idx[s..e].iter().zip(&self.val[s..e]) {
                        let xr: &[f64; PANEL] = xb[r * PANEL..(r + 1) * PANEL].try_into().expect("panel width");
                        for j in 0..PANEL {
                            acc[j] += v * xr[j];
                        }
                    }
                    yb[c * PANEL..(c + 1) * PANEL].copy_from_slice(&acc);
                } else {
                    let xc: [f64; PANEL] = xb[c * PANEL..(c + 1) * PANEL].try_into().expect("panel width");
                    for (&r, &v) in self.row_idx[s..e].iter().zip(&self.val[s..e]) {
                        let yr = &mut yb[r * PANEL..(r + 1) * PANEL];
                        for j in 0..PANEL {
                            yr[j] += v * xc[j];
                        }
                    }
                }
            }
            for j in 0..w {
                for (i, v) in y.rb_mut().col_mut(c0 + j).iter_mut().enumerate() {
                    *v = yb[i * PANEL + j];
                }
            }
        }
    }

    /// Y = A^T X for a dense X (nrows x k), returned as ncols x k.
    pub fn mul_t_dense(&self, x: faer::MatRef<'_, f64>) -> faer::Mat<f64> {
        let mut y = faer::Mat::<f64>::zeros(self.ncols, x.ncols());
        faer::sparse::linalg::matmul::sparse_dense_matmul(
            y.as_mut(),
            faer::Accum::Replace,
            self.as_faer().transpose(),
            x,
            1.0,
            faer::get_global_parallelism(),
        );
        y
    }

    /// Dense copy (for small matrices and tests).
    pub fn to_dense(&self) -> faer::Mat<f64> {
        let mut m = faer::Mat::<f64>::zeros(self.nrows, self.ncols);
        for c in 0..self.ncols {
            for p in self.col_ptr[c]..self.col_ptr[c + 1] {
                m[(self.row_idx[p], c)] += self.val[p];
            }
        }
        m
    }
}

/// Matrix size from which the numeric factorisation uses faer's parallelism.
const PARALLEL_FACTOR_MIN_N: usize = 20_000;

/// Sparse Cholesky factor of a symmetric positive definite matrix (lower triangle used).
/// Owns faer's symbolic structure and values so that solves can choose their parallelism (the
/// many-right-hand-side solves run on the caller's own threads).
pub struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    pub n: usize,
}

impl Cholesky {
    pub fn new(a: &Csc, stage: &'static str) -> Result<Cholesky> {
        let symbolic = factorize_symbolic_cholesky(a.as_faer().symbolic(), Side::Lower, Default::default(), Default::default())
            .map_err(|e| numeric(stage, format!("symbolic Cholesky: {e:?}")))?;
        let mut values = vec![0.0; symbolic.len_val()];
        // faer's fork-join costs more than it gains on the supernodes of the 1 mm strip (10,168
        // unknowns: 105 ms single-threaded against 120-140 ms on two threads)
        let par = if a.nrows < PARALLEL_FACTOR_MIN_N { Par::Seq } else { faer::get_global_parallelism() };
        let mut mem = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        symbolic
            .factorize_numeric_llt(
                &mut values,
                a.as_faer(),
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| numeric(stage, format!("matrix not positive definite ({e:?})")))?;
        Ok(Cholesky { symbolic, values, n: a.nrows })
    }

    /// Stored values of the factor (its size).
    pub fn factor_len(&self) -> usize {
        self.values.len()
    }

    /// Solves in place with the given parallelism for the dense kernels.
    pub fn solve_in_place_par(&self, rhs: MatMut<'_, f64>, par: Par) {
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), par));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(Conj::No, rhs, par, MemStack::new(&mut mem));
    }

    /// Solves in place on the calling thread for right-hand sides with few nonzero rows (the
    /// constraint-mode loads K_ib): the forward substitution skips every supernode that no
    /// nonzero can reach (in the elimination tree), which is more than half of them for a chunk
    /// of neighbouring top nodes. Skipped supernodes would only add exact zeros, so the result
    /// equals the dense solve's.
    pub fn solve_sparse_rhs_in_place(&self, rhs: MatMut<'_, f64>) {
        let (SymbolicCholeskyRaw::Supernodal(sn), Some(perm)) = (self.symbolic.raw(), self.symbolic.perm()) else {
            return self.solve_in_place_par(rhs, Par::Seq);
        };
        let (fwd, inv) = perm.arrays();
        let (n, k) = (self.n, rhs.ncols());
        let mut rhs = rhs;
        let mut x = faer::Mat::<f64>::zeros(n, k);
        for j in 0..k {
            for i in 0..n {
                x[(i, j)] = rhs[(fwd[i], j)];
            }
        }
        let l = SupernodalLltRef::new(sn, &self.values);
        let ns = sn.n_supernodes();
        let mut row_sn = vec![0usize; n];
        for s in 0..ns {
            let sup = l.supernode(s);
            let size = sup.val().ncols();
            row_sn[sup.start()..sup.start() + size].iter_mut().for_each(|v| *v = s);
        }
        let mut reached = vec![false; ns];
        for i in 0..n {
            if (0..k).any(|j| x[(i, j)] != 0.0) {
                reached[row_sn[i]] = true;
            }
        }
        for s in 0..ns {
            if !reached[s] {
                continue;
            }
            let sup = l.supernode(s);
            let (ls, pattern) = (sup.val(), sup.pattern());
            let size = ls.ncols();
            let (ls_top, ls_bot) = ls.split_at_row(size);
            let mut x_top = x.as_mut().subrows_mut(sup.start(), size);
            faer::linalg::triangular_solve::solve_lower_triangular_in_place(ls_top, x_top.rb_mut(), Par::Seq);
            let mut tmp = faer::Mat::<f64>::zeros(pattern.len(), k);
            faer::linalg::matmul::matmul(tmp.as_mut(), faer::Accum::Replace, ls_bot, x_top.rb(), 1.0, Par::Seq);
            for j in 0..k {
                for (idx, &i) in pattern.iter().enumerate() {
                    x[(i, j)] -= tmp[(idx, j)];
                }
            }
            for &i in pattern {
                reached[row_sn[i]] = true;
            }
        }
        for s in (0..ns).rev() {
            let sup = l.supernode(s);
            let (ls, pattern) = (sup.val(), sup.pattern());
            let size = ls.ncols();
            let (ls_top, ls_bot) = ls.split_at_row(size);
            let tmp = faer::Mat::<f64>::from_fn(pattern.len(), k, |idx, j| x[(pattern[idx], j)]);
            let mut x_top = x.as_mut().subrows_mut(sup.start(), size);
            faer::linalg::matmul::matmul(x_top.rb_mut(), faer::Accum::Add, ls_bot.transpose(), tmp.as_ref(), -1.0, Par::Seq);
            faer::linalg::triangular_solve::solve_upper_triangular_in_place(ls_top.transpose(), x_top.rb_mut(), Par::Seq);
        }
        for j in 0..k {
            for i in 0..n {
                rhs[(i, j)] = x[(inv[i], j)];
            }
        }
    }

    pub fn solve_vec(&self, rhs: &mut [f64]) {
        let n = rhs.len();
        self.solve_in_place_par(faer::MatMut::from_column_major_slice_mut(rhs, n, 1), Par::Seq);
    }
}
