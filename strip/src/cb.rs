//! Craig-Bampton reduction (5.12)-(5.20): boundary DOFs kept physically, interior represented by
//! static constraint modes Psi = -K_ii^-1 K_ib and fixed-interface normal modes Phi_ik up to a
//! cut-off frequency. T_CB = [[I, 0], [Psi, Phi]] (5.19); K_CB = diag(K_bb^S, Omega^2),
//! M_CB = T^T M T (5.16)-(5.17).

use faer::reborrow::{Reborrow, ReborrowMut};
use faer::Mat;

use crate::eig::{lowest_modes, Want};
use crate::error::Result;
use crate::params::{CbBoundary, StripParams};
use crate::sparse::{Cholesky, Csc};
use crate::system::FullSystem;

pub struct CraigBampton {
    /// Sub-stage wall times (s).
    pub timings: Vec<(String, f64)>,
    /// Free indices of the boundary and interior DOFs.
    pub boundary: Vec<usize>,
    pub interior: Vec<usize>,
    /// Reduced stiffness and mass, N = nb + nm.
    pub k: Mat<f64>,
    pub m: Mat<f64>,
    /// Fixed-interface eigenvalues omega^2 (rad^2/s^2).
    pub fixed_lambda: Vec<f64>,
    /// CB coordinate of each top node's y DOF (the inputs), in top-node order.
    pub input_coord: Vec<usize>,
    /// Bottom y reactions as a function of the CB coordinates: K_rf T_CB.
    pub c_react: Mat<f64>,
    pub psi: Mat<f64>,
    pub phi: Mat<f64>,
    k_ii: Cholesky,
    k_ic: Csc,
    k_bc: Csc,
}

fn sym(a: &mut Mat<f64>) {
    let n = a.nrows();
    for j in 0..n {
        for i in 0..j {
            let v = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// A^T B for a symmetric result (A^T B = B^T A, e.g. Psi^T (M Psi)): only the lower half is
/// multiplied, then mirrored.
fn sym_product(a: faer::MatRef<'_, f64>, b: faer::MatRef<'_, f64>) -> Mat<f64> {
    let par = faer::get_global_parallelism();
    use faer::linalg::matmul::triangular::{matmul, BlockStructure as Bs};
    let n = a.ncols();
    let mut c = Mat::<f64>::zeros(n, n);
    matmul(c.as_mut(), Bs::TriangularLower, faer::Accum::Replace, a.transpose(), Bs::Rectangular, b, Bs::Rectangular, 1.0, par);
    for j in 0..n {
        for i in 0..j {
            c[(i, j)] = c[(j, i)];
        }
    }
    c
}

/// Columns per chunk of the constraint-mode solve: neighbouring top nodes, so the forward
/// substitution reaches few supernodes, and the chunk stays cache-friendly (measured faster per
/// column than one 533-column block or chunks of 32 or 128).
const PSI_CHUNK: usize = 64;

/// Splits `x` into consecutive column chunks of at most `width`.
fn column_chunks(x: faer::MatMut<'_, f64>, width: usize) -> Vec<faer::MatMut<'_, f64>> {
    let mut out = Vec::new();
    let mut rest = x;
    while rest.ncols() > width {
        let (head, tail) = rest.split_at_col_mut(width);
        out.push(head);
        rest = tail;
    }
    out.push(rest);
    out
}

/// A^T X through the transposed storage and the packed panel product (the boundary blocks have
/// few entries per column; faer's transposed product is slower here).
fn sparse_t_dense(a: &Csc, x: faer::MatRef<'_, f64>) -> Mat<f64> {
    transpose(a).mul_dense(x)
}

impl CraigBampton {
    pub fn build(sys: &FullSystem, p: &StripParams) -> Result<CraigBampton> {
        crate::fix_build_parallelism();
        let mut t = std::time::Instant::now();
        let nf = sys.n_free();
        let mut boundary = Vec::new();
        let mut input_coord = Vec::new();
        for &n in &sys.top_nodes {
            match p.cb_boundary {
                CbBoundary::Y => {
                    input_coord.push(boundary.len());
                    boundary.push(sys.free_of[3 * n + 1]);
                }
                CbBoundary::Xyz => {
                    for d in 0..3 {
                        let f = sys.free_of[3 * n + d];
                        if f == usize::MAX {
                            continue;
                        }
                        if d == 1 {
                            input_coord.push(boundary.len());
                        }
                        boundary.push(f);
                    }
                }
            }
        }
        let mut bmap = vec![usize::MAX; nf];
        for (i, &f) in boundary.iter().enumerate() {
            bmap[f] = i;
        }
        let interior: Vec<usize> = (0..nf).filter(|&f| bmap[f] == usize::MAX).collect();
        let mut imap = vec![usize::MAX; nf];
        for (i, &f) in interior.iter().enumerate() {
            imap[f] = i;
        }
        let (nb, ni) = (boundary.len(), interior.len());
        let k_ii = sys.k_ff.submatrix(&imap, ni, &interior);
        let m_ii = sys.m_ff.submatrix(&imap, ni, &interior);
        let k_ib = sys.k_ff.submatrix(&imap, ni, &boundary);
        let m_ib = sys.m_ff.submatrix(&imap, ni, &boundary);
        let k_bb = sys.k_ff.submatrix(&bmap, nb, &boundary).to_dense();
        let m_bb = sys.m_ff.submatrix(&bmap, nb, &boundary).to_dense();
        let _span = tracing::debug_span!("cb", nb, ni).entered();
        let mut timings = Vec::new();
        let mut lap = |name: &str, timings: &mut Vec<(String, f64)>| {
            let now = std::time::Instant::now();
            timings.push((format!("cb_{name}"), (now - t).as_secs_f64()));
            t = now;
        };
        lap("partition", &mut timings);

        let chol = Cholesky::new(&k_ii, "Craig-Bampton K_ii factorisation")?;
        lap("factorisation", &mut timings);
        crate::progress::stage("constraint modes and fixed-interface modes");
        // Both only read the factor: the block Lanczos run (sequential steps) on one thread, the
        // many-right-hand-side solve for Psi in column chunks shared by both threads (the Lanczos
        // thread joins in when its eigenpairs have converged). Each chunk's M_ii Psi is formed
        // while the chunk is fresh in cache.
        let lmax = (2.0 * std::f64::consts::PI * p.cb_cutoff_hz).powi(2);
        let mut psi = k_ib.to_dense();
        let mut x = Mat::<f64>::zeros(ni, nb); // M_ii Psi
        let modes = {
            let work: Vec<_> = column_chunks(psi.as_mut(), PSI_CHUNK).into_iter().zip(column_chunks(x.as_mut(), PSI_CHUNK)).collect();
            let work = std::sync::Mutex::new(work);
            let solve_chunks = || loop {
                let next = work.lock().expect("chunk queue poisoned").pop();
                let Some((mut psi_c, x_c)) = next else { break };
                chol.solve_sparse_rhs_in_place(psi_c.rb_mut());
                for j in 0..psi_c.ncols() {
                    psi_c.rb_mut().col_mut(j).iter_mut().for_each(|v| *v = -*v);
                }
                m_ii.sym_mul_dense_to(psi_c.rb(), x_c);
            };
            std::thread::scope(|scope| {
                let lanczos = scope.spawn(|| {
                    let modes = lowest_modes(&chol, &k_ii, &m_ii, Want::Below(lmax));
                    solve_chunks();
                    modes
                });
                solve_chunks();
                lanczos.join().expect("Lanczos thread panicked")
            })
        };
        let modes = modes?;
        let phi = modes.vectors;
        let nm = phi.ncols();
        lap("constraint_and_fixed_interface_modes", &mut timings);
        crate::progress::stage("Craig-Bampton matrices");
        let kbs = &k_bb + sparse_t_dense(&k_ib, psi.as_ref()); // K_bb^S (5.17)
        let mibt_psi = sparse_t_dense(&m_ib, psi.as_ref()); // M_ib^T Psi
        let mbb = &m_bb + &mibt_psi + mibt_psi.transpose() + sym_product(psi.as_ref(), x.as_ref());
        let nr = sys.k_rf.nrows;
        let rmap: Vec<usize> = (0..nr).collect();
        let k_ri = sys.k_rf.submatrix(&rmap, nr, &interior);
        let kri_psi = k_ri.mul_dense(psi.as_ref());
        lap("psi_products", &mut timings);

        let n = nb + nm;
        let mut k = Mat::<f64>::zeros(n, n);
        k.as_mut().submatrix_mut(0, 0, nb, nb).copy_from(&kbs);
        // Galerkin projection of K_ii on the Ritz vectors (diagonal up to their accuracy)
        let kphi = k_ii.mul_dense(phi.as_ref());
        let kkk = phi.transpose() * &kphi;
        k.as_mut().submatrix_mut(nb, nb, nm, nm).copy_from(&kkk);
        let mbk = sparse_t_dense(&m_ib, phi.as_ref()) + x.transpose() * &phi;
        let mphi = m_ii.mul_dense(phi.as_ref());
        let mkk = phi.transpose() * &mphi;
        let mut m = Mat::<f64>::zeros(n, n);
        m.as_mut().submatrix_mut(0, 0, nb, nb).copy_from(&mbb);
        m.as_mut().submatrix_mut(0, nb, nb, nm).copy_from(&mbk);
        m.as_mut().submatrix_mut(nb, 0, nm, nb).copy_from(mbk.transpose());
        m.as_mut().submatrix_mut(nb, nb, nm, nm).copy_from(&mkk);
        sym(&mut k);
        sym(&mut m);

        lap("reduced_matrices", &mut timings);
        // reactions: K_rf T = [K_rb + K_ri Psi, K_ri Phi]
        let k_rb = sys.k_rf.submatrix(&rmap, nr, &boundary).to_dense();
        let mut c_react = Mat::<f64>::zeros(nr, n);
        c_react.as_mut().submatrix_mut(0, 0, nr, nb).copy_from(&(&k_rb + &kri_psi));
        c_react.as_mut().submatrix_mut(0, nb, nr, nm).copy_from(&k_ri.mul_dense(phi.as_ref()));

        // prescribed bottom motion couplings (free rows x reaction cols) for the bulge
        let k_fr = transpose(&sys.k_rf);
        let k_ic = k_fr.submatrix(&imap, ni, &rmap);
        let k_bc = k_fr.submatrix(&bmap, nb, &rmap);

        lap("reaction_map", &mut timings);
        Ok(CraigBampton {
            timings,
            boundary,
            interior,
            k,
            m,
            fixed_lambda: modes.lambda,
            input_coord,
            c_react,
            psi,
            phi,
            k_ii: chol,
            k_ic,
            k_bc,
        })
    }

    pub fn nb(&self) -> usize {
        self.boundary.len()
    }

    pub fn nm(&self) -> usize {
        self.phi.ncols()
    }

    /// Full free-DOF displacement from CB coordinates p (5.19).
    pub fn expand(&self, p: &[f64], n_free: usize) -> Vec<f64> {
        let nb = self.nb();
        let mut q = vec![0.0; n_free];
        for (i, &f) in self.boundary.iter().enumerate() {
            q[f] = p[i];
        }
        for (r, &f) in self.interior.iter().enumerate() {
            let mut s = 0.0;
            for j in 0..nb {
                s += self.psi[(r, j)] * p[j];
            }
            for j in 0..self.nm() {
                s += self.phi[(r, j)] * p[nb + j];
            }
            q[f] = s;
        }
        q
    }

    /// Exact static free-DOF displacement for prescribed bottom-y displacements `q_r`, by
    /// condensation on K_ii (the full model's static solution, no second factorisation).
    pub fn static_prescribed(&self, q_r: &[f64], n_free: usize) -> Vec<f64> {
        let nb = self.nb();
        let mut s = vec![0.0; self.interior.len()];
        self.k_ic.mul_vec(q_r, &mut s);
        s.iter_mut().for_each(|v| *v = -*v);
        self.k_ii.solve_vec(&mut s);
        // K_bb^S q_b = -K_bc q_r - K_bi s
        let mut rhs = vec![0.0; nb];
        self.k_bc.mul_vec(q_r, &mut rhs);
        rhs.iter_mut().for_each(|v| *v = -*v);
        // K_bi s with K_ii s = -K_ic q_r: K_bi s = -Psi^T K_ii s = Psi^T K_ic q_r
        let mut kic_q = vec![0.0; self.interior.len()];
        self.k_ic.mul_vec(q_r, &mut kic_q);
        for j in 0..nb {
            let mut acc = 0.0;
            for r in 0..self.interior.len() {
                acc += self.psi[(r, j)] * kic_q[r];
            }
            rhs[j] -= acc;
        }
        let kbb = self.k.as_ref().submatrix(0, 0, nb, nb).to_owned();
        let llt = kbb.llt(faer::Side::Lower).expect("condensed boundary stiffness is SPD");
        let mut qb = Mat::<f64>::from_fn(nb, 1, |i, _| rhs[i]);
        use faer::linalg::solvers::Solve;
        llt.solve_in_place(qb.as_mut());
        let mut q = vec![0.0; n_free];
        for (i, &f) in self.boundary.iter().enumerate() {
            q[f] = qb[(i, 0)];
        }
        for (r, &f) in self.interior.iter().enumerate() {
            let mut v = s[r];
            for j in 0..nb {
                v += self.psi[(r, j)] * qb[(j, 0)];
            }
            q[f] = v;
        }
        q
    }
}

/// Transpose of a CSC matrix.
pub fn transpose(a: &Csc) -> Csc {
    let mut cnt = vec![0usize; a.nrows + 1];
    for &r in &a.row_idx {
        cnt[r + 1] += 1;
    }
    for i in 0..a.nrows {
        cnt[i + 1] += cnt[i];
    }
    let col_ptr = cnt.clone();
    let mut next = cnt;
    let mut row_idx = vec![0; a.nnz()];
    let mut val = vec![0.0; a.nnz()];
    for c in 0..a.ncols {
        for p in a.col_ptr[c]..a.col_ptr[c + 1] {
            let r = a.row_idx[p];
            row_idx[next[r]] = c;
            val[next[r]] = a.val[p];
            next[r] += 1;
        }
    }
    Csc { nrows: a.ncols, ncols: a.nrows, col_ptr, row_idx, val }
}
