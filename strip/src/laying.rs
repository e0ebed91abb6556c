//! The laying process in statics: how much pressure the wheel puts on the tape of a strip that is
//! bonded only where the wheel has already passed.
//!
//! The plant's model (DESIGN 4) bonds the whole bottom face to the bulged substrate at once, so
//! the bulge pre-stresses the strip everywhere, ahead of the wheel too: on the bump's concave feet
//! the tape is then in tension before the wheel arrives (the bond check of issue 6 misses there).
//! In the real process the strip ahead of the wheel is not yet glued: it only rests on the
//! substrate. This module solves that case on the full finite-element model, for a wheel at z_a:
//! - bottom nodes with z < z_a are bonded, displaced onto the substrate (u = (0, bump(z), 0));
//! - bottom nodes with z >= z_a touch the substrate unilaterally and without friction
//!   (Signorini: u_y >= bump(z), reaction >= 0, one of the two tight), solved by an active set;
//! - the wheel force enters through the Gaussian map (5.33)-(5.34).
//!
//! The pressure a bottom node sees while it is still ahead of the wheel is the pressure that makes
//! its bond (Section 4.2: the tape needs 100 kPa). With every node bonded the solve reduces to the
//! plant model's statics (bulge offset + wheel response), which the tests use as a cross-check.

use crate::error::{numeric, Result};
use crate::fem::{assemble, Material};
use crate::mesh::Mesh;
use crate::model::gaussian_weights;
use crate::params::StripParams;
use crate::sparse::{Cholesky, Csc};
use faer::linalg::solvers::Solve;
use faer::Mat;

/// How the bottom face is held while the wheel is at z_a.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BottomSupport {
    /// Every bottom node bonded to the bulged substrate (the plant model's assumption).
    BondedEverywhere,
    /// Bonded behind the wheel (z < z_a), resting unilaterally and without friction ahead of it.
    BondFront,
}

/// The full model condensed onto the bottom face, built once for many solves.
///
/// Every support only holds bottom DOFs, so the interior (all other DOFs) is eliminated once:
/// with K_II factored, the bottom face sees the Schur complement S = K_BB − K_BI K_II⁻¹ K_IB and
/// the wheel's condensed load g_B = −K_BI K_II⁻¹ f_I; the reactions are r_B = S u_B − g_B. A solve
/// is then a dense one on the free bottom DOFs only (none at all when everything is bonded).
pub struct LayingModel {
    params: StripParams,
    mesh: Mesh,
    /// K restricted to (interior rows, bottom columns), and K_II's factor.
    k_ib: Csc,
    k_ii: Cholesky,
    /// Interior index of each global DOF (usize::MAX on the bottom face).
    interior_of: Vec<usize>,
    /// Bottom DOFs 3 i + d (node `bottom_nodes[i]`, direction d): the Schur complement.
    schur: Mat<f64>,
    bottom_nodes: Vec<usize>,
    bottom_areas_m2: Vec<f64>,
    top_nodes: Vec<usize>,
    top_xyz_m: Vec<[f64; 3]>,
}

/// Right-hand sides per solve while condensing (neighbouring bottom nodes, so the sparse
/// forward substitution skips most supernodes).
const SCHUR_CHUNK: usize = 48;

/// One static solve.
#[derive(Clone, Debug)]
pub struct LayingSolution {
    /// Bottom-node pressure (Pa, compression positive), in `bottom_nodes` order.
    pub pressure_pa: Vec<f64>,
    /// Bottom-node gap to the substrate, u_y - bump (m); zero where bonded or touching.
    pub gap_m: Vec<f64>,
    /// Bottom nodes that are ahead of the wheel and off the substrate (a gap opened).
    pub lifted: usize,
    /// Active-set iterations the contact needed.
    pub iterations: usize,
}

impl LayingModel {
    pub fn build(p: &StripParams) -> Result<LayingModel> {
        LayingModel::build_bent(p, None)
    }

    /// [`LayingModel::build`], or with `bend_radius_m` the strip bent about its normal along a
    /// circle of that radius ([`Mesh::bent`]; the inside of the bend at +x): the stiffness is
    /// the bent mesh's. Positions along the strip (the wheel's z_a, the bump, the centre line)
    /// stay arc lengths of the centre line, the wheel's Gaussian map is laid along it, and a
    /// bottom node's tributary area shrinks to the inside of the bend by (R − x) / R, so the
    /// centre line's pressures compare one to one with the straight strip's.
    pub fn build_bent(p: &StripParams, bend_radius_m: Option<f64>) -> Result<LayingModel> {
        crate::fix_build_parallelism();
        let mesh = Mesh::build(p.length_m, p.element_m);
        let mat = Material { youngs_pa: p.youngs_pa, poisson: p.poisson, density_kg_m3: p.density_kg_m3 };
        let k = match bend_radius_m {
            Some(r) => assemble(&mesh.bent(r), &mat).k,
            None => assemble(&mesh, &mat).k,
        };
        let bottom_nodes = mesh.bottom_nodes();
        let ndof = 3 * mesh.node_count();
        let bottom: Vec<usize> = bottom_nodes.iter().flat_map(|&b| (0..3).map(move |d| 3 * b + d)).collect();
        let mut bottom_of = vec![usize::MAX; ndof];
        bottom.iter().enumerate().for_each(|(i, &d)| bottom_of[d] = i);
        let interior: Vec<usize> = (0..ndof).filter(|&d| bottom_of[d] == usize::MAX).collect();
        let mut interior_of = vec![usize::MAX; ndof];
        interior.iter().enumerate().for_each(|(i, &d)| interior_of[d] = i);
        let (ni, nb) = (interior.len(), bottom.len());
        // K_II is the bonded strip's stiffness: positive definite
        let k_ii = Cholesky::new(&k.submatrix(&interior_of, ni, &interior), "laying K_II")?;
        let k_ib = k.submatrix(&interior_of, ni, &bottom);
        let k_bb = k.submatrix(&bottom_of, nb, &bottom).to_dense();
        // S = K_BB - K_IB^T K_II^-1 K_IB, column chunks shared by two threads
        let next = std::sync::atomic::AtomicUsize::new(0);
        let chunks: Vec<(usize, Mat<f64>)> = std::thread::scope(|scope| {
            let work = || {
                let mut done = Vec::new();
                loop {
                    let c0 = next.fetch_add(SCHUR_CHUNK, std::sync::atomic::Ordering::Relaxed);
                    if c0 >= nb {
                        break done;
                    }
                    let w = SCHUR_CHUNK.min(nb - c0);
                    let mut x = Mat::<f64>::zeros(ni, w);
                    for j in 0..w {
                        for q in k_ib.col_ptr[c0 + j]..k_ib.col_ptr[c0 + j + 1] {
                            x[(k_ib.row_idx[q], j)] = k_ib.val[q];
                        }
                    }
                    k_ii.solve_sparse_rhs_in_place(x.as_mut());
                    done.push((c0, k_ib.mul_t_dense(x.as_ref())));
                }
            };
            let other = scope.spawn(work);
            let mut mine = work();
            mine.extend(other.join().expect("Schur thread panicked"));
            mine
        });
        let mut schur = k_bb;
        for (c0, kx) in chunks {
            for j in 0..kx.ncols() {
                for i in 0..nb {
                    schur[(i, c0 + j)] -= kx[(i, j)];
                }
            }
        }
        let mut bottom_areas_m2 = mesh.bottom_tributary_areas();
        if let Some(r) = bend_radius_m {
            for (a, &b) in bottom_areas_m2.iter_mut().zip(&bottom_nodes) {
                *a *= (r - mesh.coords[b][0]) / r;
            }
        }
        let top_nodes = mesh.top_nodes();
        let top_xyz_m = top_nodes.iter().map(|&n| mesh.coords[n]).collect();
        Ok(LayingModel { params: p.clone(), mesh, k_ib, k_ii, interior_of, schur, bottom_nodes, bottom_areas_m2, top_nodes, top_xyz_m })
    }

    /// Tributary area of each bottom node (m^2), in `bottom_nodes` order.
    pub fn bottom_areas_m2(&self) -> &[f64] {
        &self.bottom_areas_m2
    }

    /// z (m) of each bottom node, in `bottom_nodes` order.
    pub fn bottom_z_m(&self) -> Vec<f64> {
        self.bottom_nodes.iter().map(|&b| self.mesh.coords[b][2]).collect()
    }

    /// Bottom nodes on the centre line x = 0 as (index into `bottom_nodes`, z in m).
    pub fn centre_line(&self) -> Vec<(usize, f64)> {
        let per = self.mesh.section_bottom.len();
        let i = self.mesh.section_bottom.iter().position(|&s| s == self.mesh.section_bottom_centre).expect("centre node");
        (0..self.mesh.layers).map(|k| (k * per + i, self.mesh.z_layers[k])).collect()
    }

    /// Static solve for a wheel at `z_a_m` pressing with `force_y_n` (N, +y; pressing is
    /// negative), with the bottom held as `support` says.
    pub fn solve(&self, z_a_m: f64, force_y_n: f64, support: BottomSupport) -> Result<LayingSolution> {
        let nb = self.schur.nrows();
        // condensed wheel load g_B = -K_BI K_II^-1 f_I (the wheel loads top nodes only)
        let mut y = vec![0.0; self.k_ib.nrows];
        let mut w = vec![0.0; self.top_nodes.len()];
        gaussian_weights(&self.top_xyz_m, z_a_m, &mut w);
        for (&node, wi) in self.top_nodes.iter().zip(&w) {
            y[self.interior_of[3 * node + 1]] += force_y_n * wi;
        }
        self.k_ii.solve_vec(&mut y);
        let g = -self.k_ib.mul_t_dense(faer::MatRef::from_column_major_slice(&y, y.len(), 1));
        // a small tolerance keeps the node under the wheel's centre on the resting side
        let bonded: Vec<bool> = self
            .bottom_nodes
            .iter()
            .map(|&b| support == BottomSupport::BondedEverywhere || self.mesh.coords[b][2] < z_a_m - 1e-9)
            .collect();
        let bump: Vec<f64> = self.bottom_nodes.iter().map(|&b| self.params.bulge_height_m(self.mesh.coords[b][2])).collect();
        // every resting node starts in contact
        let mut touching = vec![true; self.bottom_nodes.len()];
        for iteration in 1..=200 {
            // held bottom DOFs and their values; the rest are solved for
            let mut u = vec![0.0; nb];
            let mut free = Vec::new();
            for i in 0..self.bottom_nodes.len() {
                if bonded[i] || touching[i] {
                    u[3 * i + 1] = bump[i];
                }
                if !bonded[i] {
                    free.extend([3 * i, 3 * i + 2]);
                    if !touching[i] {
                        free.push(3 * i + 1);
                    }
                }
            }
            if !free.is_empty() {
                // S_ff u_f = g_f - S_fc u_c  (u_f is zero in u so far)
                let nf = free.len();
                let s_ff = Mat::<f64>::from_fn(nf, nf, |a, b| self.schur[(free[a], free[b])]);
                let mut rhs = Mat::<f64>::from_fn(nf, 1, |a, _| {
                    let r = free[a];
                    g[(r, 0)] - (0..nb).map(|c| self.schur[(r, c)] * u[c]).sum::<f64>()
                });
                s_ff.llt(faer::Side::Lower)
                    .map_err(|e| {
                        numeric("laying contact", format!("condensed stiffness not positive definite ({e:?}) at z_a = {z_a_m} m"))
                    })?
                    .solve_in_place(rhs.as_mut());
                free.iter().enumerate().for_each(|(a, &r)| u[r] = rhs[(a, 0)]);
            }
            // reactions on the strip at the bottom y DOFs: r = S u - g
            let reaction: Vec<f64> = (0..self.bottom_nodes.len())
                .map(|i| (0..nb).map(|c| self.schur[(3 * i + 1, c)] * u[c]).sum::<f64>() - g[(3 * i + 1, 0)])
                .collect();
            let mut changed = false;
            for i in 0..self.bottom_nodes.len() {
                if bonded[i] {
                    continue;
                }
                // tolerances far below the pressures and gaps of interest (1 Pa, 1 nm), so the
                // active set cannot chatter on round-off
                if touching[i] && reaction[i] / self.bottom_areas_m2[i] < -1.0 {
                    touching[i] = false;
                    changed = true;
                } else if !touching[i] && u[3 * i + 1] < bump[i] - 1e-9 {
                    touching[i] = true;
                    changed = true;
                }
            }
            if !changed {
                let lifted = (0..touching.len()).filter(|&i| !touching[i] && !bonded[i]).count();
                let pressure_pa = reaction.iter().zip(&self.bottom_areas_m2).map(|(r, a)| r / a).collect();
                let gap_m = (0..bump.len()).map(|i| u[3 * i + 1] - bump[i]).collect();
                return Ok(LayingSolution { pressure_pa, gap_m, lifted, iterations: iteration });
            }
        }
        Err(numeric("laying contact", format!("active set did not settle in 200 iterations at z_a = {z_a_m} m")))
    }
}

/// The bond check for a roll from `z_from_m` to `z_to_m` in steps of `step_m`: for every
/// centre-line node in that range, the largest pressure it saw during the roll (the plant's bond
/// check, on the full model). Returns (z, peak Pa) pairs and the largest number of lifted nodes.
pub fn bond_check(
    model: &LayingModel,
    force_y_n: f64,
    support: BottomSupport,
    z_from_m: f64,
    z_to_m: f64,
    step_m: f64,
) -> Result<(Vec<(f64, f64)>, usize)> {
    let line = model.centre_line();
    let mut peak: Vec<f64> = vec![f64::NEG_INFINITY; line.len()];
    let mut lifted = 0;
    let steps = ((z_to_m - z_from_m) / step_m).round() as usize;
    for s in 0..=steps {
        let z_a = z_from_m + s as f64 * step_m;
        let sol = model.solve(z_a, force_y_n, support)?;
        lifted = lifted.max(sol.lifted);
        for (k, &(i, z)) in line.iter().enumerate() {
            let _ = z;
            peak[k] = peak[k].max(sol.pressure_pa[i]);
        }
    }
    Ok((
        line.iter()
            .zip(&peak)
            .filter(|(l, p)| p.is_finite() && l.1 >= z_from_m - 1e-9 && l.1 <= z_to_m + 1e-9)
            .map(|(l, p)| (l.1, *p))
            .collect(),
        lifted,
    ))
}

/// For the strip bonded everywhere, the smallest constant wheel force (N, pressing magnitude)
/// that gives each centre-line node in [`z_from_m`, `z_to_m`] a peak of `level_pa` during a roll
/// sampled every `step_m`. Exact by superposition: the bump's pressure does not depend on the
/// wheel, and the wheel's is linear in its force.
pub fn bonded_min_force(model: &LayingModel, level_pa: f64, z_from_m: f64, z_to_m: f64, step_m: f64) -> Result<Vec<(f64, f64)>> {
    let line = model.centre_line();
    let bump = model.solve(z_from_m, 0.0, BottomSupport::BondedEverywhere)?.pressure_pa;
    let mut per_newton: Vec<f64> = vec![f64::NEG_INFINITY; line.len()];
    let steps = ((z_to_m - z_from_m) / step_m).round() as usize;
    for s in 0..=steps {
        let sol = model.solve(z_from_m + s as f64 * step_m, -1.0, BottomSupport::BondedEverywhere)?;
        for (k, &(i, _)) in line.iter().enumerate() {
            per_newton[k] = per_newton[k].max(sol.pressure_pa[i] - bump[i]);
        }
    }
    Ok(line
        .iter()
        .zip(&per_newton)
        .filter(|(l, _)| l.1 >= z_from_m - 1e-9 && l.1 <= z_to_m + 1e-9)
        .map(|(&(i, z), &pn)| (z, (level_pa - bump[i]) / pn))
        .collect())
}
