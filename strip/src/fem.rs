//! Linear elastic 8-node hexahedra with the mean-dilatation B-bar treatment (Hughes' B-bar with a
//! constant element pressure), consistent mass, and sparse assembly.
//!
//! Only the element-mean volumetric strain carries the bulk modulus, so nearly incompressible
//! rubber (nu = 0.49 ... 0.4999) does not lock; 2x2x2 Gauss integration of the deviatoric part
//! leaves no hourglass modes.

use crate::mesh::Mesh;
use crate::sparse::Csc;

/// Isotropic linear elastic material (SI).
#[derive(Clone, Copy, Debug)]
pub struct Material {
    pub youngs_pa: f64,
    pub poisson: f64,
    pub density_kg_m3: f64,
}

impl Material {
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.youngs_pa, self.poisson);
        (e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)))
    }
}

const XI: [[f64; 3]; 8] =
    [[-1., -1., -1.], [1., -1., -1.], [1., 1., -1.], [-1., 1., -1.], [-1., -1., 1.], [1., -1., 1.], [1., 1., 1.], [-1., 1., 1.]];

/// Shape functions and their natural derivatives at (r, s, t).
fn shape(p: [f64; 3]) -> ([f64; 8], [[f64; 3]; 8]) {
    let mut n = [0.0; 8];
    let mut d = [[0.0; 3]; 8];
    for a in 0..8 {
        let [xa, ya, za] = XI[a];
        let (fx, fy, fz) = (1.0 + xa * p[0], 1.0 + ya * p[1], 1.0 + za * p[2]);
        n[a] = 0.125 * fx * fy * fz;
        d[a] = [0.125 * xa * fy * fz, 0.125 * ya * fx * fz, 0.125 * za * fx * fy];
    }
    (n, d)
}

/// Gauss points (2x2x2) of the unit cube [-1, 1]^3, all with weight 1.
fn gauss() -> [[f64; 3]; 8] {
    let g = 1.0 / 3f64.sqrt();
    let mut out = [[0.0; 3]; 8];
    for (k, o) in out.iter_mut().enumerate() {
        *o = [XI[k][0] * g, XI[k][1] * g, XI[k][2] * g];
    }
    out
}

/// Physical shape-function gradients and det J at a Gauss point.
fn gradients(xyz: &[[f64; 3]; 8], p: [f64; 3]) -> ([f64; 8], [[f64; 3]; 8], f64) {
    let (n, dn) = shape(p);
    let mut j = [[0.0; 3]; 3]; // j[r][c] = d x_c / d xi_r
    for a in 0..8 {
        for r in 0..3 {
            for c in 0..3 {
                j[r][c] += dn[a][r] * xyz[a][c];
            }
        }
    }
    let det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1]) - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
        + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
    let inv = [
        [
            (j[1][1] * j[2][2] - j[1][2] * j[2][1]) / det,
            (j[0][2] * j[2][1] - j[0][1] * j[2][2]) / det,
            (j[0][1] * j[1][2] - j[0][2] * j[1][1]) / det,
        ],
        [
            (j[1][2] * j[2][0] - j[1][0] * j[2][2]) / det,
            (j[0][0] * j[2][2] - j[0][2] * j[2][0]) / det,
            (j[0][2] * j[1][0] - j[0][0] * j[1][2]) / det,
        ],
        [
            (j[1][0] * j[2][1] - j[1][1] * j[2][0]) / det,
            (j[0][1] * j[2][0] - j[0][0] * j[2][1]) / det,
            (j[0][0] * j[1][1] - j[0][1] * j[1][0]) / det,
        ],
    ];
    // dN/dx_c = sum_r dN/dxi_r * dxi_r/dx_c, with dxi/dx = J^{-1} (inv[c][r] layout: inv = J^-1)
    let mut g = [[0.0; 3]; 8];
    for a in 0..8 {
        for c in 0..3 {
            g[a][c] = (0..3).map(|r| inv[c][r] * dn[a][r]).sum();
        }
    }
    (n, g, det)
}

/// B-bar strain-displacement matrix (Voigt xx, yy, zz, xy, yz, zx) at a Gauss point, given the
/// element-mean gradients `gbar`.
fn bbar(g: &[[f64; 3]; 8], gbar: &[[f64; 3]; 8]) -> [[f64; 24]; 6] {
    let mut b = [[0.0; 24]; 6];
    for a in 0..8 {
        for j in 0..3 {
            let col = 3 * a + j;
            for i in 0..3 {
                b[i][col] += (gbar[a][j] - g[a][j]) / 3.0;
            }
            b[j][col] += g[a][j];
        }
        let (c0, c1, c2) = (3 * a, 3 * a + 1, 3 * a + 2);
        b[3][c0] = g[a][1];
        b[3][c1] = g[a][0];
        b[4][c1] = g[a][2];
        b[4][c2] = g[a][1];
        b[5][c0] = g[a][2];
        b[5][c2] = g[a][0];
    }
    b
}

/// Element stiffness and consistent mass (24 x 24, row-major, DOF order 3a + direction).
pub fn hex8(xyz: &[[f64; 3]; 8], mat: &Material) -> (Vec<f64>, Vec<f64>) {
    let (lam, mu) = mat.lame();
    let gp = gauss();
    let mut gbar = [[0.0; 3]; 8];
    let mut vol = 0.0;
    let mut cache = Vec::with_capacity(8);
    for &p in &gp {
        let (n, g, det) = gradients(xyz, p);
        assert!(det > 0.0, "inverted hexahedron (det J = {det})");
        vol += det;
        for a in 0..8 {
            for c in 0..3 {
                gbar[a][c] += g[a][c] * det;
            }
        }
        cache.push((n, g, det));
    }
    for row in gbar.iter_mut() {
        for v in row.iter_mut() {
            *v /= vol;
        }
    }
    let mut d = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            d[i][j] = lam;
        }
        d[i][i] += 2.0 * mu;
        d[i + 3][i + 3] = mu;
    }
    let mut ke = vec![0.0; 576];
    let mut me = vec![0.0; 576];
    for (n, g, det) in &cache {
        let b = bbar(g, &gbar);
        // db = D B (6 x 24)
        let mut db = [[0.0; 24]; 6];
        for i in 0..6 {
            for k in 0..6 {
                if d[i][k] != 0.0 {
                    for c in 0..24 {
                        db[i][c] += d[i][k] * b[k][c];
                    }
                }
            }
        }
        for r in 0..24 {
            for c in 0..24 {
                let mut s = 0.0;
                for i in 0..6 {
                    s += b[i][r] * db[i][c];
                }
                ke[r * 24 + c] += s * det;
            }
        }
        for a in 0..8 {
            for bb in 0..8 {
                let m = mat.density_kg_m3 * n[a] * n[bb] * det;
                for j in 0..3 {
                    me[(3 * a + j) * 24 + 3 * bb + j] += m;
                }
            }
        }
    }
    (ke, me)
}

/// Assembled global stiffness and mass over all 3 * nodes DOFs (DOF = 3 node + direction).
pub struct Assembled {
    pub k: Csc,
    pub m: Csc,
}

/// Assembles K and M. Every layer of an extruded mesh has the same element geometry, so each
/// section quad's element matrices are computed once and scattered into all layers; a bent mesh
/// (`Mesh::bent`) has each hexahedron's computed from its own nodes.
pub fn assemble(mesh: &Mesh, mat: &Material) -> Assembled {
    let n_nodes = mesh.node_count();
    // node adjacency (sorted neighbour lists incl. self)
    let mut adj: Vec<Vec<usize>> = vec![Vec::with_capacity(27); n_nodes];
    for h in &mesh.hexes {
        for &a in h {
            for &b in h {
                adj[a].push(b);
            }
        }
    }
    for l in adj.iter_mut() {
        l.sort_unstable();
        l.dedup();
    }
    let ndof = 3 * n_nodes;
    let mut col_ptr = Vec::with_capacity(ndof + 1);
    col_ptr.push(0usize);
    for n in 0..n_nodes {
        for _ in 0..3 {
            let last = *col_ptr.last().unwrap();
            col_ptr.push(last + 3 * adj[n].len());
        }
    }
    let nnz = *col_ptr.last().unwrap();
    let mut row_idx = vec![0usize; nnz];
    for n in 0..n_nodes {
        for j in 0..3 {
            let base = col_ptr[3 * n + j];
            for (p, &m) in adj[n].iter().enumerate() {
                for i in 0..3 {
                    row_idx[base + 3 * p + i] = 3 * m + i;
                }
            }
        }
    }
    let mut kv = vec![0.0; nnz];
    let mut mv = vec![0.0; nnz];
    let dz = mesh.z_layers[1] - mesh.z_layers[0];
    let nq = mesh.section_quads.len();
    let elem: Vec<(Vec<f64>, Vec<f64>)> = if mesh.extruded {
        mesh.section_quads
            .iter()
            .map(|q| {
                let mut xyz = [[0.0; 3]; 8];
                for a in 0..4 {
                    let [x, y] = mesh.section_xy[q[a]];
                    xyz[a] = [x, y, 0.0];
                    xyz[a + 4] = [x, y, dz];
                }
                hex8(&xyz, mat)
            })
            .collect()
    } else {
        mesh.hexes.iter().map(|h| hex8(&h.map(|n| mesh.coords[n]), mat)).collect()
    };
    for (e, h) in mesh.hexes.iter().enumerate() {
        let (ke, me) = &elem[if mesh.extruded { e % nq } else { e }];
        for b in 0..8 {
            let nb = h[b];
            for a in 0..8 {
                let p = adj[nb].binary_search(&h[a]).unwrap();
                for j in 0..3 {
                    let base = col_ptr[3 * nb + j] + 3 * p;
                    for i in 0..3 {
                        kv[base + i] += ke[(3 * a + i) * 24 + 3 * b + j];
                        mv[base + i] += me[(3 * a + i) * 24 + 3 * b + j];
                    }
                }
            }
        }
    }
    let k = Csc { nrows: ndof, ncols: ndof, col_ptr: col_ptr.clone(), row_idx: row_idx.clone(), val: kv };
    let m = Csc { nrows: ndof, ncols: ndof, col_ptr, row_idx, val: mv };
    Assembled { k, m }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each hexahedron's own matrices (the bent mesh's path) on a straight mesh give the shared
    /// per-layer matrices' K to round-off; a rigid rotation of the bent strip about its normal
    /// is a zero-energy motion of the bent K.
    #[test]
    fn per_element_assembly_matches_the_extruded_one_and_the_bent_k_has_no_rigid_energy() {
        let mat = Material { youngs_pa: 4e6, poisson: 0.49, density_kg_m3: 1200.0 };
        let mesh = Mesh::build(8e-3, 2e-3);
        let shared = assemble(&mesh, &mat).k;
        let own = assemble(&Mesh { extruded: false, ..mesh.clone() }, &mat).k;
        let scale = shared.val.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(shared.val.iter().zip(&own.val).all(|(a, b)| (a - b).abs() < 1e-9 * scale));
        let bent = mesh.bent(0.05);
        let k = assemble(&bent, &mat).k;
        // rotation about the bend's centre axis (x = R, z = 0, along y): u = ω × (p − c)
        let u: Vec<f64> = bent.coords.iter().flat_map(|p| [p[2], 0.0, -(p[0] - 0.05)]).collect();
        let ku = k.mul_t_dense(faer::MatRef::from_column_major_slice(&u, u.len(), 1));
        let ku_max = (0..u.len()).fold(0.0f64, |m, i| m.max(ku[(i, 0)].abs()));
        assert!(ku_max < 1e-9 * scale * 1e-3, "{ku_max}");
        // and the bend is felt: the bent K is not the straight one
        assert!(k.val.iter().zip(&shared.val).any(|(a, b)| (a - b).abs() > 1e-3 * scale));
    }

    fn distorted_hex() -> [[f64; 3]; 8] {
        let mut x = [[0.0; 3]; 8];
        for a in 0..8 {
            let [r, s, t] = XI[a];
            x[a] = [
                1e-3 * (0.5 * r + 0.5 + 0.07 * s * t + 0.03 * r * s),
                1e-3 * (0.6 * s + 0.6 + 0.05 * r - 0.04 * r * t),
                1e-3 * (0.45 * t + 0.45 + 0.06 * r * s + 0.02 * s),
            ];
        }
        x
    }

    /// Patch test: a linear displacement field gives zero out-of-balance forces for the element
    /// energy only through its constant strain, so K u equals the consistent nodal forces of the
    /// constant stress: f_a = integral of B_a^T sigma over the element (computed here by
    /// divergence theorem: the surface tractions). Equivalent check used: the strain energy
    /// u^T K u equals V sigma:eps, and K applied to a rigid motion is zero.
    #[test]
    fn patch_test_constant_strain_and_rigid_modes() {
        for nu in [0.3, 0.49, 0.4999] {
            let mat = Material { youngs_pa: 3.46e6, poisson: nu, density_kg_m3: 1080.0 };
            let x = distorted_hex();
            let (ke, _) = hex8(&x, &mat);
            let (lam, mu) = mat.lame();
            let eps = [1e-3, -2e-3, 0.5e-3, 0.7e-3, -0.3e-3, 0.2e-3]; // engineering shear
                                                                      // linear field u = E x with symmetric E from eps
            let e = [[eps[0], 0.5 * eps[3], 0.5 * eps[5]], [0.5 * eps[3], eps[1], 0.5 * eps[4]], [0.5 * eps[5], 0.5 * eps[4], eps[2]]];
            let mut u = [0.0; 24];
            for a in 0..8 {
                for i in 0..3 {
                    u[3 * a + i] = (0..3).map(|j| e[i][j] * x[a][j]).sum();
                }
            }
            let tr = eps[0] + eps[1] + eps[2];
            let sigma = [
                lam * tr + 2.0 * mu * eps[0],
                lam * tr + 2.0 * mu * eps[1],
                lam * tr + 2.0 * mu * eps[2],
                mu * eps[3],
                mu * eps[4],
                mu * eps[5],
            ];
            // element volume
            let vol: f64 = gauss().iter().map(|&p| gradients(&x, p).2).sum();
            let energy: f64 = (0..24).map(|r| (0..24).map(|c| u[r] * ke[r * 24 + c] * u[c]).sum::<f64>()).sum();
            let exact = vol * (0..6).map(|k| sigma[k] * eps[k]).sum::<f64>();
            assert!((energy - exact).abs() < 1e-10 * exact.abs(), "nu {nu}: {energy} vs {exact}");
            // nodal forces of the constant stress: f_a = sigma . integral grad N_a dV
            let mut fint = [0.0; 24];
            for &p in &gauss() {
                let (_, g, det) = gradients(&x, p);
                let s = [[sigma[0], sigma[3], sigma[5]], [sigma[3], sigma[1], sigma[4]], [sigma[5], sigma[4], sigma[2]]];
                for a in 0..8 {
                    for i in 0..3 {
                        fint[3 * a + i] += (0..3).map(|j| s[i][j] * g[a][j]).sum::<f64>() * det;
                    }
                }
            }
            let scale = fint.iter().map(|v| v.abs()).fold(0.0, f64::max);
            for r in 0..24 {
                let ku: f64 = (0..24).map(|c| ke[r * 24 + c] * u[c]).sum();
                assert!((ku - fint[r]).abs() < 1e-9 * scale, "nu {nu} row {r}: {ku} vs {}", fint[r]);
            }
        }
    }

    #[test]
    fn consistent_mass_sums_to_element_mass() {
        let mat = Material { youngs_pa: 3.46e6, poisson: 0.49, density_kg_m3: 1080.0 };
        let x = distorted_hex();
        let (_, me) = hex8(&x, &mat);
        let vol: f64 = gauss().iter().map(|&p| gradients(&x, p).2).sum();
        // rigid translation in y: total inertia force = rho V
        let total: f64 = (0..8).flat_map(|a| (0..8).map(move |b| (a, b))).map(|(a, b)| me[(3 * a + 1) * 24 + 3 * b + 1]).sum();
        assert!((total - 1080.0 * vol).abs() < 1e-12 * total);
    }
}
