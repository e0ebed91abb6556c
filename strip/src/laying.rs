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

/// How the bottom face is held while the wheel is at z_a.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BottomSupport {
    /// Every bottom node bonded to the bulged substrate (the plant model's assumption).
    BondedEverywhere,
    /// Bonded behind the wheel (z < z_a), resting unilaterally and without friction ahead of it.
    BondFront,
}

/// The full model's stiffness and the bottom-face geometry, built once for many solves.
pub struct LayingModel {
    params: StripParams,
    mesh: Mesh,
    k: Csc,
    bottom_nodes: Vec<usize>,
    bottom_areas_m2: Vec<f64>,
    top_nodes: Vec<usize>,
    top_xyz_m: Vec<[f64; 3]>,
}

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
    pub fn build(p: &StripParams) -> LayingModel {
        let mesh = Mesh::build(p.length_m, p.element_m);
        let mat = Material { youngs_pa: p.youngs_pa, poisson: p.poisson, density_kg_m3: p.density_kg_m3 };
        let k = assemble(&mesh, &mat).k;
        let bottom_nodes = mesh.bottom_nodes();
        let bottom_areas_m2 = mesh.bottom_tributary_areas();
        let top_nodes = mesh.top_nodes();
        let top_xyz_m = top_nodes.iter().map(|&n| mesh.coords[n]).collect();
        LayingModel { params: p.clone(), mesh, k, bottom_nodes, bottom_areas_m2, top_nodes, top_xyz_m }
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
        let n = self.mesh.node_count();
        let ndof = 3 * n;
        let mut f = vec![0.0; ndof];
        let mut w = vec![0.0; self.top_nodes.len()];
        gaussian_weights(&self.top_xyz_m, z_a_m, &mut w);
        for (&node, wi) in self.top_nodes.iter().zip(&w) {
            f[3 * node + 1] += force_y_n * wi;
        }
        // a small tolerance keeps the node under the wheel's centre on the resting side
        let bonded = |z: f64| support == BottomSupport::BondedEverywhere || z < z_a_m - 1e-9;
        let bump: Vec<f64> = self.bottom_nodes.iter().map(|&b| self.params.bulge_height_m(self.mesh.coords[b][2])).collect();
        // every resting node starts in contact
        let mut touching = vec![true; self.bottom_nodes.len()];
        for iteration in 1..=200 {
            // prescribed DOFs and their values
            let mut prescribed = vec![None; ndof];
            for (i, &b) in self.bottom_nodes.iter().enumerate() {
                if bonded(self.mesh.coords[b][2]) {
                    prescribed[3 * b] = Some(0.0);
                    prescribed[3 * b + 2] = Some(0.0);
                    prescribed[3 * b + 1] = Some(bump[i]);
                } else if touching[i] {
                    prescribed[3 * b + 1] = Some(bump[i]);
                }
            }
            let u = self.solve_prescribed(&f, &prescribed)?;
            // reactions on the strip: r = K u - f at the bottom y DOFs
            let mut ku = vec![0.0; ndof];
            self.k.mul_vec(&u, &mut ku);
            let reaction: Vec<f64> = self.bottom_nodes.iter().map(|&b| ku[3 * b + 1] - f[3 * b + 1]).collect();
            let mut changed = false;
            for (i, &b) in self.bottom_nodes.iter().enumerate() {
                if bonded(self.mesh.coords[b][2]) {
                    continue;
                }
                // tolerances far below the pressures and gaps of interest (1 Pa on a 1 mm^2 node,
                // 1 nm), so the active set cannot chatter on round-off
                if touching[i] && reaction[i] / self.bottom_areas_m2[i] < -1.0 {
                    touching[i] = false;
                    changed = true;
                } else if !touching[i] && u[3 * b + 1] < bump[i] - 1e-9 {
                    touching[i] = true;
                    changed = true;
                }
            }
            if !changed {
                let lifted = touching.iter().enumerate().filter(|&(i, &t)| !t && !bonded(self.mesh.coords[self.bottom_nodes[i]][2])).count();
                let pressure_pa = reaction.iter().zip(&self.bottom_areas_m2).map(|(r, a)| r / a).collect();
                let gap_m = self.bottom_nodes.iter().zip(&bump).map(|(&b, h)| u[3 * b + 1] - h).collect();
                return Ok(LayingSolution { pressure_pa, gap_m, lifted, iterations: iteration });
            }
        }
        Err(numeric("laying contact", format!("active set did not settle in 200 iterations at z_a = {z_a_m} m")))
    }

    /// Solves K u = f with the DOFs in `prescribed` held at their values (exact elimination).
    fn solve_prescribed(&self, f: &[f64], prescribed: &[Option<f64>]) -> Result<Vec<f64>> {
        let ndof = f.len();
        let free: Vec<usize> = (0..ndof).filter(|&d| prescribed[d].is_none()).collect();
        let mut free_of = vec![usize::MAX; ndof];
        free.iter().enumerate().for_each(|(i, &d)| free_of[d] = i);
        let u_c: Vec<f64> = prescribed.iter().map(|p| p.unwrap_or(0.0)).collect();
        // rhs = f_f - K_fc u_c  (K u_c has zeros in the free entries of u_c)
        let mut k_uc = vec![0.0; ndof];
        self.k.mul_vec(&u_c, &mut k_uc);
        let mut rhs: Vec<f64> = free.iter().map(|&d| f[d] - k_uc[d]).collect();
        let k_ff = self.k.submatrix(&free_of, free.len(), &free);
        Cholesky::new(&k_ff, "laying statics")?.solve_vec(&mut rhs);
        let mut u = u_c;
        free.iter().zip(&rhs).for_each(|(&d, v)| u[d] = *v);
        Ok(u)
    }
}

/// The bond check for a roll from `z_from_m` to `z_to_m` in steps of `step_m`: for every
/// centre-line node in that range, the largest pressure it saw during the roll (the plant's bond
/// check, on the full model). Returns (z, peak Pa) pairs and the largest number of lifted nodes.
pub fn bond_check(model: &LayingModel, force_y_n: f64, support: BottomSupport, z_from_m: f64, z_to_m: f64, step_m: f64) -> Result<(Vec<(f64, f64)>, usize)> {
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
    Ok((line.iter().zip(&peak).filter(|(l, p)| p.is_finite() && l.1 >= z_from_m - 1e-9 && l.1 <= z_to_m + 1e-9).map(|(l, p)| (l.1, *p)).collect(), lifted))
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
