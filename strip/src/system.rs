//! The assembled full model with its boundary conditions: free DOFs, the substrate constraints,
//! the top-surface input DOFs and the bottom reaction rows.

use crate::fem::{assemble, Material};
use crate::mesh::Mesh;
use crate::params::{StripParams, Substrate};
use crate::sparse::Csc;

/// Full FE model restricted to the free DOFs.
pub struct FullSystem {
    pub mesh: Mesh,
    /// Global DOF (3 node + direction) of each free DOF.
    pub free: Vec<usize>,
    /// Global DOF -> free index (usize::MAX if constrained).
    pub free_of: Vec<usize>,
    pub k_ff: Csc,
    pub m_ff: Csc,
    /// Bottom-node y reaction rows: K restricted to (bottom y DOFs, free DOFs).
    pub k_rf: Csc,
    /// K restricted to (bottom y DOFs, bottom y DOFs), for prescribed substrate motion.
    pub k_rr: Csc,
    /// Top-surface nodes (mesh order: layer, then x).
    pub top_nodes: Vec<usize>,
    /// Free index of each top node's y DOF (the model inputs and first outputs).
    pub top_y_free: Vec<usize>,
    /// Bottom nodes (mesh order) whose y reactions are outputs.
    pub bottom_nodes: Vec<usize>,
    pub bottom_areas_m2: Vec<f64>,
}

impl FullSystem {
    pub fn build(p: &StripParams) -> FullSystem {
        let mesh = Mesh::build(p.length_m, p.element_m);
        let mat = Material { youngs_pa: p.youngs_pa, poisson: p.poisson, density_kg_m3: p.density_kg_m3 };
        let asm = assemble(&mesh, &mat);
        let ndof = 3 * mesh.node_count();
        let bottom_nodes = mesh.bottom_nodes();
        let mut fixed = vec![false; ndof];
        let tol = 1e-9;
        for &n in &bottom_nodes {
            match p.substrate {
                Substrate::Bonded => (0..3).for_each(|d| fixed[3 * n + d] = true),
                Substrate::Sliding => fixed[3 * n + 1] = true,
            }
        }
        if p.substrate == Substrate::Sliding {
            // Appendix A.5: z = 0 face u_z = 0; z = 0, x = 0 line u_x = 0
            for s in 0..mesh.nodes_per_section {
                fixed[3 * s + 2] = true;
                if mesh.section_xy[s][0].abs() < tol {
                    fixed[3 * s] = true;
                }
            }
        }
        let free: Vec<usize> = (0..ndof).filter(|&d| !fixed[d]).collect();
        let mut free_of = vec![usize::MAX; ndof];
        for (i, &d) in free.iter().enumerate() {
            free_of[d] = i;
        }
        let k_ff = asm.k.submatrix(&free_of, free.len(), &free);
        let m_ff = asm.m.submatrix(&free_of, free.len(), &free).without_zeros();
        let react: Vec<usize> = bottom_nodes.iter().map(|&n| 3 * n + 1).collect();
        let mut react_of = vec![usize::MAX; ndof];
        for (i, &d) in react.iter().enumerate() {
            react_of[d] = i;
        }
        // K symmetric: rows (reaction) x cols (free) = transpose of the (free x reaction) block;
        // build it column-wise directly from the symmetric storage.
        let k_rf = asm.k.submatrix(&react_of, react.len(), &free);
        let k_rr = asm.k.submatrix(&react_of, react.len(), &react);
        let top_nodes = mesh.top_nodes();
        let top_y_free = top_nodes.iter().map(|&n| free_of[3 * n + 1]).collect();
        let bottom_areas_m2 = mesh.bottom_tributary_areas();
        FullSystem { mesh, free, free_of, k_ff, m_ff, k_rf, k_rr, top_nodes, top_y_free, bottom_nodes, bottom_areas_m2 }
    }

    pub fn n_free(&self) -> usize {
        self.free.len()
    }

    /// Bottom-y reaction (N, on the strip, +y) for a free displacement vector and prescribed
    /// bottom-y displacements `q_r` (None = zero).
    pub fn reactions(&self, q_f: &[f64], q_r: Option<&[f64]>, out: &mut [f64]) {
        self.k_rf.mul_vec(q_f, out);
        if let Some(qr) = q_r {
            let mut tmp = vec![0.0; out.len()];
            self.k_rr.mul_vec(qr, &mut tmp);
            out.iter_mut().zip(&tmp).for_each(|(o, t)| *o += t);
        }
    }
}
