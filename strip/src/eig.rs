//! Lowest generalized eigenpairs K phi = lambda M phi of large sparse symmetric pencils:
//! shift-invert Lanczos (shift 0, operator K^-1 M, self-adjoint in the M inner product) with full
//! re-orthogonalisation. K must be positive definite (held structure).

use faer::{Mat, Side};

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

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Lanczos on K^-1 M. `k_fact` factors K, `m` is M (same size).
pub fn lowest_modes(k_fact: &Cholesky, _k: &Csc, m: &Csc, want: Want) -> Result<Modes> {
    let n = m.nrows;
    let max_steps = n.min(match want {
        Want::Count(c) => 3 * c + 60,
        Want::Below(_) => 4000,
    });
    let mut q: Vec<Vec<f64>> = Vec::new();
    let mut mq: Vec<Vec<f64>> = Vec::new();
    let mut alpha: Vec<f64> = Vec::new();
    let mut beta: Vec<f64> = Vec::new();
    // deterministic pseudo-random start
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut r: Vec<f64> = (0..n)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect();
    let mut mr = vec![0.0; n];
    m.mul_vec(&r, &mut mr);
    let nr = dot(&r, &mr).sqrt();
    r.iter_mut().for_each(|v| *v /= nr);
    mr.iter_mut().for_each(|v| *v /= nr);
    q.push(r);
    mq.push(mr);
    let mut w = vec![0.0; n];
    let mut mw = vec![0.0; n];
    let tol = 1e-11;
    let mut next_check = match want {
        Want::Count(c) => c + 10,
        Want::Below(_) => 20,
    };
    loop {
        let j = q.len() - 1;
        w.copy_from_slice(&mq[j]);
        k_fact.solve_vec(&mut w);
        let a = dot(&mq[j], &w);
        for (wi, qi) in w.iter_mut().zip(&q[j]) {
            *wi -= a * qi;
        }
        if j > 0 {
            let b = beta[j - 1];
            for (wi, qi) in w.iter_mut().zip(&q[j - 1]) {
                *wi -= b * qi;
            }
        }
        for _ in 0..2 {
            for i in 0..q.len() {
                let c = dot(&mq[i], &w);
                for (wi, qi) in w.iter_mut().zip(&q[i]) {
                    *wi -= c * qi;
                }
            }
        }
        alpha.push(a);
        m.mul_vec(&w, &mut mw);
        let b = dot(&w, &mw).max(0.0).sqrt();
        let steps = alpha.len();
        let exhausted = steps >= max_steps || b <= 1e-14 * a.abs();
        if steps >= next_check || exhausted {
            next_check = steps + 10;
            // Ritz values of T
            let mut t = Mat::<f64>::zeros(steps, steps);
            for i in 0..steps {
                t[(i, i)] = alpha[i];
                if i + 1 < steps {
                    t[(i + 1, i)] = beta[i];
                    t[(i, i + 1)] = beta[i];
                }
            }
            let evd = t.self_adjoint_eigen(Side::Lower).map_err(|e| numeric("lanczos", format!("{e:?}")))?;
            let s = evd.S().column_vector();
            let u = evd.U();
            // theta descending = lambda ascending
            let mut idx: Vec<usize> = (0..steps).collect();
            idx.sort_by(|&x, &y| s[y].total_cmp(&s[x]));
            let converged = |k: usize| {
                let th = s[k];
                th > 0.0 && (b * u[(steps - 1, k)]).abs() <= tol * th
            };
            let mut take = Vec::new();
            let done = match want {
                Want::Count(c) => {
                    let ok = idx.iter().take(c).all(|&k| converged(k));
                    if ok || exhausted {
                        take = idx.iter().take(c).copied().collect();
                    }
                    ok
                }
                Want::Below(lmax) => {
                    // all Ritz values below the bound converged, and a converged one beyond it
                    let below: Vec<usize> = idx.iter().copied().filter(|&k| s[k] > 0.0 && 1.0 / s[k] <= lmax).collect();
                    let beyond = idx.iter().any(|&k| s[k] > 0.0 && 1.0 / s[k] > lmax && converged(k));
                    let ok = beyond && below.iter().all(|&k| converged(k));
                    if ok || exhausted {
                        take = below;
                    }
                    ok
                }
            };
            if done || exhausted {
                if !done {
                    tracing::warn!(steps, "lanczos stopped before every wanted eigenpair converged");
                }
                let lambda: Vec<f64> = take.iter().map(|&k| 1.0 / s[k]).collect();
                let mut vectors = Mat::<f64>::zeros(n, take.len());
                for (c, &k) in take.iter().enumerate() {
                    let col = vectors.col_mut(c).try_as_col_major_mut().unwrap().as_slice_mut();
                    for (i, qi) in q.iter().enumerate() {
                        let coef = u[(i, k)];
                        for (v, x) in col.iter_mut().zip(qi) {
                            *v += coef * x;
                        }
                    }
                }
                return Ok(Modes { lambda, vectors });
            }
        }
        if b <= 1e-14 * a.abs() {
            return Err(numeric("lanczos", "invariant subspace reached before convergence"));
        }
        beta.push(b);
        q.push(w.iter().map(|v| v / b).collect());
        mq.push(mw.iter().map(|v| v / b).collect());
    }
}
