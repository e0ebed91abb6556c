//! Minimal compressed-sparse-column storage with the few operations the pipeline needs, and a
//! bridge to faer's sparse Cholesky (AMD ordering, supernodal when worthwhile).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky};
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
        SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(self.nrows, self.ncols, &self.col_ptr, None, &self.row_idx),
            &self.val,
        )
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
        faer::sparse::linalg::matmul::sparse_dense_matmul(
            y.as_mut(),
            faer::Accum::Replace,
            self.as_faer(),
            x,
            1.0,
            faer::get_global_parallelism(),
        );
        y
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
        let par = faer::get_global_parallelism();
        let mut mem = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        symbolic
            .factorize_numeric_llt(&mut values, a.as_faer(), Side::Lower, Default::default(), par, MemStack::new(&mut mem), Default::default())
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

    pub fn solve_vec(&self, rhs: &mut [f64]) {
        let n = rhs.len();
        self.solve_in_place_par(faer::MatMut::from_column_major_slice_mut(rhs, n, 1), Par::Seq);
    }
}
