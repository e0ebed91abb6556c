//! FE-level acceptance tests: patch test on the real (distorted) strip mesh, symmetry and
//! definiteness of K and M, a compressed block against closed forms.

use faer::Side;
use strip::fem::{assemble, Material};
use strip::mesh::Mesh;
use strip::sparse::{Cholesky, Csc};

fn mat(nu: f64) -> Material {
    Material { youngs_pa: 3.46e6, poisson: nu, density_kg_m3: 1080.0 }
}

/// Solves K_ii u_i = -K_ib u_b for the DOFs `fixed` prescribed to `u`.
fn solve_with_prescribed(k: &Csc, fixed: &[bool], u: &mut [f64], f_ext: &[f64]) {
    let n = k.nrows;
    let free: Vec<usize> = (0..n).filter(|&d| !fixed[d]).collect();
    let mut map = vec![usize::MAX; n];
    for (i, &d) in free.iter().enumerate() {
        map[d] = i;
    }
    let kii = k.submatrix(&map, free.len(), &free);
    let mut ub = u.to_vec();
    for &d in &free {
        ub[d] = 0.0;
    }
    let mut ku = vec![0.0; n];
    k.mul_vec(&ub, &mut ku);
    let mut rhs: Vec<f64> = free.iter().map(|&d| f_ext[d] - ku[d]).collect();
    Cholesky::new(&kii, "test").unwrap().solve_vec(&mut rhs);
    for (i, &d) in free.iter().enumerate() {
        u[d] = rhs[i];
    }
}

#[test]
fn patch_test_on_strip_mesh_reproduces_linear_field() {
    // the Coons-mapped bulb elements are distorted: a linear field must still be exact
    for nu in [0.49, 0.4999] {
        let mesh = Mesh::build(4e-3, 1e-3);
        let k = assemble(&mesh, &mat(nu)).k;
        let n = mesh.node_count();
        let top: std::collections::HashSet<usize> = mesh.top_nodes().into_iter().collect();
        let lz = *mesh.z_layers.last().unwrap();
        let on_surface = |i: usize| {
            let [x, y, z] = mesh.coords[i];
            z.abs() < 1e-12 || (z - lz).abs() < 1e-12 || y.abs() < 1e-12 || (x.abs() - 4e-3).abs() < 1e-12 || top.contains(&i)
        };
        let field = |p: [f64; 3]| {
            [
                1e-3 * p[0] - 2e-3 * p[1] + 0.5e-3 * p[2] + 1e-6,
                0.7e-3 * p[0] + 1.5e-3 * p[1] - 0.3e-3 * p[2],
                -0.4e-3 * p[0] + 0.2e-3 * p[1] + 0.9e-3 * p[2] - 2e-6,
            ]
        };
        let mut fixed = vec![false; 3 * n];
        let mut u = vec![0.0; 3 * n];
        let mut interior = 0;
        for i in 0..n {
            if on_surface(i) {
                let f = field(mesh.coords[i]);
                for d in 0..3 {
                    fixed[3 * i + d] = true;
                    u[3 * i + d] = f[d];
                }
            } else {
                interior += 1;
            }
        }
        assert!(interior > 20, "mesh needs interior nodes for a patch test");
        solve_with_prescribed(&k, &fixed, &mut u, &vec![0.0; 3 * n]);
        let mut err: f64 = 0.0;
        for i in 0..n {
            let f = field(mesh.coords[i]);
            for d in 0..3 {
                err = err.max((u[3 * i + d] - f[d]).abs());
            }
        }
        assert!(err < 1e-9 * 1e-5, "nu {nu}: patch test error {err:e} m");
    }
}

#[test]
fn stiffness_and_mass_symmetric_definite() {
    let mesh = Mesh::build(10e-3, 1e-3);
    let asm = assemble(&mesh, &mat(0.49));
    for (name, a) in [("K", &asm.k), ("M", &asm.m)] {
        let d = a.to_dense();
        let scale = d.norm_max();
        let asym = (&d - d.transpose()).norm_max();
        assert!(asym <= 1e-14 * scale, "{name} asymmetry {asym:e}");
    }
    // M positive definite (full, unconstrained)
    assert!(asm.m.to_dense().llt(Side::Lower).is_ok(), "M must be positive definite");
    // K has exactly the rigid-body null space without supports: translations and rotations
    let n = mesh.node_count();
    let mut rigid = vec![0.0; 3 * n];
    let mut out = vec![0.0; 3 * n];
    for i in 0..n {
        let [x, y, z] = mesh.coords[i];
        // rotation about z plus a translation
        rigid[3 * i] = -y + 1e-3;
        rigid[3 * i + 1] = x;
        rigid[3 * i + 2] = 0.5e-3 + 0.0 * z;
    }
    asm.k.mul_vec(&rigid, &mut out);
    let kscale = asm.k.val.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(out.iter().all(|v| v.abs() < 1e-9 * kscale * 1e-3), "rigid motion must be stress-free");
    assert!(Cholesky::new(&asm.k, "unsupported").is_err(), "unsupported K must not be positive definite");
    // once the bottom is held, K is positive definite
    let p = strip::StripParams { length_m: 10e-3, ..Default::default() };
    let sys = strip::system::FullSystem::build(&p);
    assert!(Cholesky::new(&sys.k_ff, "held").is_ok());
}

/// Structured block mesh W x H x L of n^3 hexes (built through the public Mesh fields).
fn block(w: f64, h: f64, l: f64, n: usize) -> Mesh {
    let mut xy = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            xy.push([w * i as f64 / n as f64, h * j as f64 / n as f64]);
        }
    }
    let mut quads = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            quads.push([a, a + 1, a + n + 2, a + n + 1]);
        }
    }
    let z_layers: Vec<f64> = (0..=n).map(|k| l * k as f64 / n as f64).collect();
    let nps = xy.len();
    let mut coords = Vec::new();
    for &z in &z_layers {
        for p in &xy {
            coords.push([p[0], p[1], z]);
        }
    }
    let mut hexes = Vec::new();
    for k in 0..n {
        for q in &quads {
            let (lo, hi) = (k * nps, (k + 1) * nps);
            hexes.push([lo + q[0], lo + q[1], lo + q[2], lo + q[3], hi + q[0], hi + q[1], hi + q[2], hi + q[3]]);
        }
    }
    Mesh {
        coords,
        hexes,
        nodes_per_section: nps,
        layers: n + 1,
        section_top: vec![],
        section_bottom: vec![],
        section_bottom_centre: 0,
        section_quads: quads,
        section_xy: xy,
        z_layers,
        extruded: true,
    }
}

#[test]
fn compressed_block_matches_closed_forms() {
    let (w, h, l, n) = (4e-3, 3e-3, 5e-3, 4);
    let p = 50e3; // Pa on the top face
    for nu in [0.3, 0.49, 0.4999] {
        let m = mat(nu);
        let mesh = block(w, h, l, n);
        let k = assemble(&mesh, &m).k;
        let nn = mesh.node_count();
        // consistent nodal forces of uniform pressure on the top face y = h (pressing: -y)
        let mut f = vec![0.0; 3 * nn];
        let (dx, dz) = (w / n as f64, l / n as f64);
        for i in 0..nn {
            let [x, y, z] = mesh.coords[i];
            if (y - h).abs() < 1e-12 {
                let ex = if x.abs() < 1e-12 || (x - w).abs() < 1e-12 { 0.5 } else { 1.0 };
                let ez = if z.abs() < 1e-12 || (z - l).abs() < 1e-12 { 0.5 } else { 1.0 };
                f[3 * i + 1] = -p * dx * dz * ex * ez;
            }
        }
        // (a) uniaxial stress: symmetry planes x = 0, y = 0, z = 0
        let mut fixed = vec![false; 3 * nn];
        for i in 0..nn {
            let [x, y, z] = mesh.coords[i];
            fixed[3 * i] |= x.abs() < 1e-12;
            fixed[3 * i + 1] |= y.abs() < 1e-12;
            fixed[3 * i + 2] |= z.abs() < 1e-12;
        }
        let mut u = vec![0.0; 3 * nn];
        solve_with_prescribed(&k, &fixed, &mut u, &f);
        let e = m.youngs_pa;
        for i in 0..nn {
            let [x, y, z] = mesh.coords[i];
            let exact = [nu * p / e * x, -p / e * y, nu * p / e * z];
            for d in 0..3 {
                assert!((u[3 * i + d] - exact[d]).abs() < 1e-8 * p / e * h, "uniaxial nu {nu}: node {i} dir {d}");
            }
        }
        // (b) confined compression: lateral faces held normal, bottom held in y
        let mut fixed = vec![false; 3 * nn];
        for i in 0..nn {
            let [x, y, z] = mesh.coords[i];
            fixed[3 * i] |= x.abs() < 1e-12 || (x - w).abs() < 1e-12;
            fixed[3 * i + 1] |= y.abs() < 1e-12;
            fixed[3 * i + 2] |= z.abs() < 1e-12 || (z - l).abs() < 1e-12;
        }
        let mut u = vec![0.0; 3 * nn];
        solve_with_prescribed(&k, &fixed, &mut u, &f);
        let m_oed = e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
        for i in 0..nn {
            let y = mesh.coords[i][1];
            let exact = -p / m_oed * y;
            assert!((u[3 * i + 1] - exact).abs() < 1e-8 * p / m_oed * h, "confined nu {nu}");
        }
    }
}
