//! Structured hexahedral mesh of the weatherstrip (DESIGN section 4): the cross-section
//! (rectangle x in [-4, 4] mm, y in [0, 4] mm plus a half-disc of radius 4 mm on top) is meshed
//! with five mapped quad patches and extruded along task z.
//!
//! Cross-section patches: the rectangle; in the bulb an O-grid made of a core rectangle
//! [-2, 2] x [4, 6] mm and three transfinite (Coons) patches joining it to the arc (left 180..135
//! degrees, top 135..45 degrees, right 45..0 degrees). Divisions for an element edge h:
//! n_side = round(2 mm / h), n_core = 2 round(2.5 mm / h) (even, so x = 0 is a node line),
//! n_arc_side = round(2.5 mm / h), rectangle height round(4 mm / h); the arc keeps at least
//! 8 segments (n_core >= 4, n_arc_side >= 2).

use std::collections::HashMap;

/// Rectangle half-width (m).
pub const HALF_WIDTH_M: f64 = 4e-3;
/// Rectangle height = bulb centre height (m).
pub const BASE_HEIGHT_M: f64 = 4e-3;
/// Bulb radius (m).
pub const BULB_RADIUS_M: f64 = 4e-3;
const CORE_HALF_M: f64 = 2e-3;
const CORE_HEIGHT_M: f64 = 2e-3;

/// A mesh of 8-node hexahedra. Node n has coordinates `coords[n] = [x, y, z]` (m, task frame);
/// node index = layer * nodes_per_section + section index.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub coords: Vec<[f64; 3]>,
    /// Hex connectivity: nodes 0-3 counter-clockwise (seen from +z) at the lower z, 4-7 above.
    pub hexes: Vec<[usize; 8]>,
    pub nodes_per_section: usize,
    pub layers: usize,
    /// Section nodes on the bulb arc (the surface the wheel touches), sorted by x.
    pub section_top: Vec<usize>,
    /// Section nodes on the bottom (y = 0), sorted by x.
    pub section_bottom: Vec<usize>,
    /// Section index of the bottom node at x = 0.
    pub section_bottom_centre: usize,
    /// The section's quads (section node indices, counter-clockwise).
    pub section_quads: Vec<[usize; 4]>,
    pub section_xy: Vec<[f64; 2]>,
    pub z_layers: Vec<f64>,
    /// True when every layer is the section extruded straight along z (so `fem::assemble`
    /// computes one layer's element matrices and reuses them); false once [`Mesh::bent`] moved
    /// the nodes, and the assembly reads each hexahedron's own coordinates.
    pub extruded: bool,
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

fn arc(deg: f64) -> [f64; 2] {
    let t = deg.to_radians();
    [BULB_RADIUS_M * t.cos(), BASE_HEIGHT_M + BULB_RADIUS_M * t.sin()]
}

/// Coons patch on four parametrised edges: bottom(u), top(u), left(v), right(v), u, v in [0, 1].
fn coons(
    nu: usize,
    nv: usize,
    bottom: &dyn Fn(f64) -> [f64; 2],
    top: &dyn Fn(f64) -> [f64; 2],
    left: &dyn Fn(f64) -> [f64; 2],
    right: &dyn Fn(f64) -> [f64; 2],
) -> Vec<Vec<[f64; 2]>> {
    let (p00, p10, p01, p11) = (bottom(0.0), bottom(1.0), top(0.0), top(1.0));
    (0..=nv)
        .map(|j| {
            let v = j as f64 / nv as f64;
            (0..=nu)
                .map(|i| {
                    let u = i as f64 / nu as f64;
                    let (b, t, l, r) = (bottom(u), top(u), left(v), right(v));
                    let mut p = [0.0; 2];
                    for k in 0..2 {
                        p[k] = (1.0 - v) * b[k] + v * t[k] + (1.0 - u) * l[k] + u * r[k]
                            - ((1.0 - u) * (1.0 - v) * p00[k] + u * (1.0 - v) * p10[k] + (1.0 - u) * v * p01[k] + u * v * p11[k]);
                    }
                    p
                })
                .collect()
        })
        .collect()
}

struct SectionBuilder {
    xy: Vec<[f64; 2]>,
    index: HashMap<(i64, i64), usize>,
    quads: Vec<[usize; 4]>,
}

impl SectionBuilder {
    fn node(&mut self, p: [f64; 2]) -> usize {
        // merge coincident patch nodes on a 1 nm grid
        let key = ((p[0] * 1e9).round() as i64, (p[1] * 1e9).round() as i64);
        if let Some(&i) = self.index.get(&key) {
            return i;
        }
        self.xy.push(p);
        self.index.insert(key, self.xy.len() - 1);
        self.xy.len() - 1
    }

    fn add_grid(&mut self, grid: &[Vec<[f64; 2]>]) {
        let ids: Vec<Vec<usize>> = grid.iter().map(|row| row.iter().map(|&p| self.node(p)).collect()).collect();
        for j in 0..ids.len() - 1 {
            for i in 0..ids[j].len() - 1 {
                let mut q = [ids[j][i], ids[j][i + 1], ids[j + 1][i + 1], ids[j + 1][i]];
                let a = |k: usize| self.xy[q[k]];
                let area2: f64 = (0..4)
                    .map(|k| {
                        let (p, n) = (a(k), a((k + 1) % 4));
                        p[0] * n[1] - n[0] * p[1]
                    })
                    .sum();
                if area2 < 0.0 {
                    q.swap(1, 3);
                }
                self.quads.push(q);
            }
        }
    }
}

impl Mesh {
    /// Builds the mesh for strip length `length_m` and element edge `element_m`.
    pub fn build(length_m: f64, element_m: f64) -> Mesh {
        let h = element_m;
        let r = |len: f64| ((len / h).round() as usize).max(1);
        let n_side = r(HALF_WIDTH_M - CORE_HALF_M);
        // the arc keeps at least 8 segments so coarse meshes still resolve the wheel patch
        let n_core = (2 * r(2.5e-3)).max(4);
        let n_arc = r(2.5e-3).max(2);
        let n_rect_y = r(BASE_HEIGHT_M);
        let mut sb = SectionBuilder { xy: Vec::new(), index: HashMap::new(), quads: Vec::new() };

        // rectangle: x nodes graded like the bulb's diameter so the patches conform
        let mut xs = Vec::new();
        for i in 0..n_side {
            xs.push(-HALF_WIDTH_M + (HALF_WIDTH_M - CORE_HALF_M) * i as f64 / n_side as f64);
        }
        for i in 0..n_core {
            xs.push(-CORE_HALF_M + 2.0 * CORE_HALF_M * i as f64 / n_core as f64);
        }
        for i in 0..=n_side {
            xs.push(CORE_HALF_M + (HALF_WIDTH_M - CORE_HALF_M) * i as f64 / n_side as f64);
        }
        let rect: Vec<Vec<[f64; 2]>> = (0..=n_rect_y)
            .map(|j| {
                let y = BASE_HEIGHT_M * j as f64 / n_rect_y as f64;
                xs.iter().map(|&x| [x, y]).collect()
            })
            .collect();
        sb.add_grid(&rect);

        let (cl, cr, ct) = (-CORE_HALF_M, CORE_HALF_M, BASE_HEIGHT_M + CORE_HEIGHT_M);
        let b = BASE_HEIGHT_M;
        // core
        let core =
            coons(n_core, n_arc, &|u| lerp([cl, b], [cr, b], u), &|u| lerp([cl, ct], [cr, ct], u), &|v| lerp([cl, b], [cl, ct], v), &|v| {
                lerp([cr, b], [cr, ct], v)
            });
        sb.add_grid(&core);
        // left patch: arc 180 -> 135 on u = 0, core edge on u = 1
        let left = coons(
            n_side,
            n_arc,
            &|u| lerp([-HALF_WIDTH_M, b], [cl, b], u),
            &|u| lerp(arc(135.0), [cl, ct], u),
            &|v| arc(180.0 - 45.0 * v),
            &|v| lerp([cl, b], [cl, ct], v),
        );
        sb.add_grid(&left);
        let right = coons(
            n_side,
            n_arc,
            &|u| lerp([cr, b], [HALF_WIDTH_M, b], u),
            &|u| lerp([cr, ct], arc(45.0), u),
            &|v| lerp([cr, b], [cr, ct], v),
            &|v| arc(45.0 * v),
        );
        sb.add_grid(&right);
        let top =
            coons(n_core, n_side, &|u| lerp([cl, ct], [cr, ct], u), &|u| arc(135.0 - 90.0 * u), &|v| lerp([cl, ct], arc(135.0), v), &|v| {
                lerp([cr, ct], arc(45.0), v)
            });
        sb.add_grid(&top);

        let nps = sb.xy.len();
        let tol = 1e-9;
        let mut section_top: Vec<usize> = (0..nps)
            .filter(|&i| {
                let [x, y] = sb.xy[i];
                y >= BASE_HEIGHT_M - tol && ((x * x + (y - BASE_HEIGHT_M).powi(2)).sqrt() - BULB_RADIUS_M).abs() < tol
            })
            .collect();
        section_top.sort_by(|&a, &b| sb.xy[a][0].total_cmp(&sb.xy[b][0]));
        let mut section_bottom: Vec<usize> = (0..nps).filter(|&i| sb.xy[i][1].abs() < tol).collect();
        section_bottom.sort_by(|&a, &b| sb.xy[a][0].total_cmp(&sb.xy[b][0]));
        let section_bottom_centre = *section_bottom.iter().find(|&&i| sb.xy[i][0].abs() < tol).expect("x = 0 bottom node");

        let n_z = ((length_m / h).round() as usize).max(2);
        let z_layers: Vec<f64> = (0..=n_z).map(|k| length_m * k as f64 / n_z as f64).collect();
        let layers = z_layers.len();
        let mut coords = Vec::with_capacity(nps * layers);
        for &z in &z_layers {
            for p in &sb.xy {
                coords.push([p[0], p[1], z]);
            }
        }
        let mut hexes = Vec::with_capacity(sb.quads.len() * n_z);
        for k in 0..n_z {
            let (lo, hi) = (k * nps, (k + 1) * nps);
            for q in &sb.quads {
                hexes.push([lo + q[0], lo + q[1], lo + q[2], lo + q[3], hi + q[0], hi + q[1], hi + q[2], hi + q[3]]);
            }
        }
        Mesh {
            coords,
            hexes,
            nodes_per_section: nps,
            layers,
            section_top,
            section_bottom,
            section_bottom_centre,
            section_quads: sb.quads,
            section_xy: sb.xy,
            z_layers,
            extruded: true,
        }
    }

    pub fn node_count(&self) -> usize {
        self.coords.len()
    }

    /// All top-surface nodes, ordered layer by layer (z), then by x.
    pub fn top_nodes(&self) -> Vec<usize> {
        (0..self.layers).flat_map(|k| self.section_top.iter().map(move |&s| k * self.nodes_per_section + s)).collect()
    }

    /// All bottom nodes, ordered layer by layer (z), then by x.
    pub fn bottom_nodes(&self) -> Vec<usize> {
        (0..self.layers).flat_map(|k| self.section_bottom.iter().map(move |&s| k * self.nodes_per_section + s)).collect()
    }

    /// Tributary (consistent, integral of the shape function) area of each bottom node (m^2),
    /// in the order of `bottom_nodes`.
    /// This mesh bent about the strip normal (task y) so that its centre line (x = 0) follows a
    /// circle of radius `radius_m` with its centre at x = +radius_m, z = 0 (the strip turning
    /// towards +x, the inside of the bend): a node at (x, y, z) goes to the radius R − x at the
    /// angle z / R. The nodes' numbering, the sections and `z_layers` (the centre line's arc
    /// length) stay; only `coords` move. Issue 26 measures what the loop's neglect of a contour's
    /// curvature costs with it.
    pub fn bent(&self, radius_m: f64) -> Mesh {
        let mut m = self.clone();
        m.extruded = false;
        for c in &mut m.coords {
            let (rho, theta) = (radius_m - c[0], c[2] / radius_m);
            *c = [radius_m - rho * theta.cos(), c[1], rho * theta.sin()];
        }
        m
    }

    pub fn bottom_tributary_areas(&self) -> Vec<f64> {
        let xs: Vec<f64> = self.section_bottom.iter().map(|&s| self.section_xy[s][0]).collect();
        let half = |v: &[f64], i: usize| {
            let l = if i > 0 { v[i] - v[i - 1] } else { 0.0 };
            let r = if i + 1 < v.len() { v[i + 1] - v[i] } else { 0.0 };
            0.5 * (l + r)
        };
        let mut out = Vec::with_capacity(xs.len() * self.layers);
        for k in 0..self.layers {
            for i in 0..xs.len() {
                out.push(half(&self.z_layers, k) * half(&xs, i));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bending keeps the centre line's arc length: its nodes lie on the circle of radius R
    /// about (R, ·, 0) at the angle z / R, neighbours a chord 2R sin(Δz / 2R) apart; a node at
    /// lateral x lies at R − x from the centre; heights do not move.
    #[test]
    fn the_bent_mesh_lays_the_centre_line_along_the_circle() {
        let (m, r) = (Mesh::build(40e-3, 2e-3), 0.05);
        let b = m.bent(r);
        for (a, c) in m.coords.iter().zip(&b.coords) {
            let rho = (c[0] - r).hypot(c[2]);
            assert!((rho - (r - a[0])).abs() < 1e-15 && c[1] == a[1], "{a:?} -> {c:?}");
            assert!(((r - c[0]).atan2(c[2]) - (std::f64::consts::FRAC_PI_2 - a[2] / r)).abs() < 1e-12, "{a:?} -> {c:?}");
        }
        let centre: Vec<usize> = (0..m.layers).map(|k| k * m.nodes_per_section + m.section_bottom_centre).collect();
        for w in centre.windows(2) {
            let (p, q, dz) = (b.coords[w[0]], b.coords[w[1]], m.coords[w[1]][2] - m.coords[w[0]][2]);
            let chord = (p[0] - q[0]).hypot(p[2] - q[2]);
            assert!((chord - 2.0 * r * (dz / (2.0 * r)).sin()).abs() < 1e-15);
        }
    }

    #[test]
    fn one_millimetre_mesh_has_design_dof_count() {
        let m = Mesh::build(40e-3, 1e-3);
        let bottom = m.section_bottom.len() * m.layers;
        // DESIGN section 4 quotes ~10,700 free DOF for the bonded 1 mm mesh
        let free = 3 * (m.node_count() - bottom);
        assert!((10_000..11_500).contains(&free), "free dof {free}");
    }

    #[test]
    fn cross_section_area_matches_geometry() {
        for h in [2e-3, 1e-3, 0.5e-3] {
            let m = Mesh::build(10e-3, h);
            let area: f64 = m
                .section_quads
                .iter()
                .map(|q| {
                    let a = |k: usize| m.section_xy[q[k]];
                    0.5 * (0..4).map(|k| a(k)[0] * a((k + 1) % 4)[1] - a((k + 1) % 4)[0] * a(k)[1]).sum::<f64>()
                })
                .sum();
            // polygonal approximation of the half-disc: area is below the exact value by the
            // chord segments, which shrink with h^2
            let exact = 8e-3 * 4e-3 + 0.5 * std::f64::consts::PI * 16e-6;
            let n_arc = m.section_top.len() - 1;
            let chord_loss =
                0.5 * 16e-6 * (n_arc as f64) * ((std::f64::consts::PI / n_arc as f64) - (std::f64::consts::PI / n_arc as f64).sin());
            assert!(((area + chord_loss) - exact).abs() < 1e-6 * exact, "h {h}: area {area}");
            assert!(
                m.section_quads.iter().all(|q| {
                    let a = |k: usize| m.section_xy[q[k]];
                    (0..4).all(|k| {
                        let (p, c, n) = (a((k + 3) % 4), a(k), a((k + 1) % 4));
                        (c[0] - p[0]) * (n[1] - c[1]) - (c[1] - p[1]) * (n[0] - c[0]) > 0.0
                    })
                }),
                "all quads convex and counter-clockwise"
            );
        }
    }

    #[test]
    fn tributary_areas_sum_to_bottom_area() {
        let m = Mesh::build(40e-3, 1e-3);
        let s: f64 = m.bottom_tributary_areas().iter().sum();
        assert!((s - 8e-3 * 40e-3).abs() < 1e-12);
    }
}
