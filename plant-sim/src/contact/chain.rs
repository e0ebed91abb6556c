//! The long strip in the loop (issue 25): a chain of windows (`strip::chain`), each the reduced
//! model the plant steps for the 40 mm strip ([`StripTables`] of one window, shared), carried
//! along a straight strip of any length with the wheel.
//!
//! Per substep, with the wheel's lowest point at z_a along the strip and the (at most two)
//! windows around it sharing its load by the chain's smooth weights φ_k (summing to one):
//! - the free surface under the wheel is the substrate's static offset there plus the sum of the
//!   free responses of every window that covers z_a (at its local position z_a − o_k), so a
//!   window that has just handed over keeps contributing while it relaxes;
//! - the one-substep compliance under the wheel is Σ φ_k d_h,k: window k carries φ_k f;
//! - the scalar contact force is solved implicitly as in [`StripContact`] and each sharing
//!   window is stepped with its share, `x_k ← Z x_k + γ V⁻¹ B w_k φ_k f`.
//!
//! Windows live in a fixed pool of [`POOL`] slots allocated at start: when the wheel needs a
//! window no slot holds, the slot of the window farthest from the wheel is reset to rest and
//! reused (by then the wheel is at that window's far end and the window has relaxed for at least
//! the time the wheel took to cross one spacing). Nothing allocates after construction.
//!
//! The substrate's bumps, dips and seams are static offsets of the linear model solved once at
//! start on the window's full FE model and blended along the strip (`strip::chain::substrate_offsets`):
//! the surface offset under the wheel (tabulated along the whole strip on the wheel table's
//! grid) and the centre-line bottom reactions. Their total bottom force is zero by equilibrium
//! (the bottom's prescribed shape is the only load), so the recorded bottom force is the
//! windows' dynamic reactions alone.

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};
use recordings::StripRecord;
use robot::Vec6;
use scenarios::geometry::STRIP_TOP_HEIGHT_M;
use strip::chain::{Feature, SubstrateProfile, WindowChain, WINDOW_END_ZONE_M};

use super::{dot, dot2, dot4, ContactGeometry, StripContact, StripTables, WrenchOnTool, TABLE_STEP_M};

/// Window slots of the pool: two share the wheel's load, one relaxes behind them.
pub const POOL: usize = 3;

/// One slot of the pool: the window it holds (`usize::MAX`: none) and its modal state.
#[derive(Clone, Debug)]
struct Slot {
    window: usize,
    /// Modal state as a real row `[Re x, Im x]`.
    x: Vec<f64>,
    /// False while the state is exactly zero (fresh): its free motion is not stepped.
    live: bool,
}

/// The substrate of a windowed strip, as the chain contact needs it.
#[derive(Clone, Debug, Default)]
pub struct ChainSubstrate {
    /// Static top offset under the wheel (Gaussian-weighted top u_y, m) on the grid z = g TABLE_STEP_M.
    surface_m: Vec<f64>,
    /// Static centre-line bottom reaction (N) per layer of the whole strip.
    centre_reaction_n: Vec<f64>,
}

/// The long strip, its windows, its substrate and the wheel contact (see the module docs).
pub struct ChainContact {
    geo: ContactGeometry,
    /// One window's tables (its bump removed: `bump` holds the substrate).
    tables: Arc<StripTables>,
    chain: WindowChain,
    substrate: ChainSubstrate,
    slots: [Slot; POOL],
    /// Element length along the strip (layer spacing), m.
    element_m: f64,
    /// Centre-line tributary area of an interior layer and of the strip's end layers, m².
    area_mid_m2: f64,
    area_end_m2: f64,
    /// The windows' shares of the last substep.
    share: strip::chain::Share,
    z_a_m: f64,
    delta_prev_m: f64,
    force_y_n: f64,
    wrench: WrenchOnTool,
}

/// The substrate profile of a scenario's windowed strip: every `[substrate]` bump and seam, and
/// the `[bulge]` when its height is not zero (it lies on the strip like any other bump).
pub fn substrate_profile(s: &scenarios::Scenario) -> SubstrateProfile {
    let mm = 1e-3;
    let mut features: Vec<Feature> =
        s.substrate.bumps.iter().map(|&[c, hw, h]| Feature::Bump { center_m: c * mm, half_width_m: hw * mm, height_m: h * mm }).collect();
    if s.bulge.height_mm != 0.0 {
        features.push(Feature::Bump {
            center_m: s.bulge.center_mm * mm,
            half_width_m: s.bulge.half_width_mm * mm,
            height_m: s.bulge.height_mm * mm,
        });
    }
    features.extend(s.substrate.seams.iter().map(|&[p, st, sm]| Feature::Seam {
        position_m: p * mm,
        step_m: st * mm,
        smoothing_m: sm * mm,
    }));
    SubstrateProfile { features }
}

impl ChainSubstrate {
    /// The static offsets of `profile` under `chain`, solved on the window's full FE model
    /// (`window_full`, built with the window's parameters) and tabulated for the contact.
    pub fn new(
        tables: &StripTables,
        chain: &WindowChain,
        window_full: &strip::chain::FullStatics,
        profile: &SubstrateProfile,
    ) -> ChainSubstrate {
        let element_m = tables.params.element_m;
        let layers = (chain.strip_length_m / element_m).round() as usize + 1;
        let layers_w = (chain.window_length_m / element_m).round() as usize + 1;
        let off = strip::chain::substrate_offsets(chain, element_m, window_full, profile);
        let top = &tables.top_xyz_m;
        let (top_per, bot_per) = (top.len() / layers_w, off.bottom_reaction_n.len() / layers);
        let centre = (tables.cl_rows[0] - top.len()) % bot_per;
        let centre_reaction_n = (0..layers).map(|j| off.bottom_reaction_n[j * bot_per + centre]).collect();
        let n = (chain.strip_length_m / TABLE_STEP_M).round() as usize + 1;
        let mut w = vec![0.0; top.len()];
        let surface_m = (0..n)
            .map(|g| {
                let z = g as f64 * TABLE_STEP_M;
                let o = chain.offsets_m[chain.share(z).first];
                strip::gaussian_weights(top, z - o, &mut w);
                let first = (o / element_m).round() as usize * top_per;
                w.iter().zip(&off.top_uy_m[first..first + top.len()]).map(|(a, b)| a * b).sum()
            })
            .collect();
        ChainSubstrate { surface_m, centre_reaction_n }
    }

    /// The two tables as plain vectors, for the on-disk cache (`substrate_cache`).
    pub(crate) fn to_vecs(&self) -> Vec<Vec<f64>> {
        vec![self.surface_m.clone(), self.centre_reaction_n.clone()]
    }

    /// [`Self::to_vecs`] back, for a chain of `chain`'s length with `element_m` layers; None when
    /// the sizes do not fit it.
    pub(crate) fn from_vecs(mut v: Vec<Vec<f64>>, chain: &WindowChain, element_m: f64) -> Option<ChainSubstrate> {
        let flat = ChainSubstrate::flat(chain, element_m);
        let (centre_reaction_n, surface_m) = (v.pop()?, v.pop()?);
        let fits = v.is_empty() && surface_m.len() == flat.surface_m.len() && centre_reaction_n.len() == flat.centre_reaction_n.len();
        fits.then_some(ChainSubstrate { surface_m, centre_reaction_n })
    }

    /// A flat substrate (no offsets) for a strip of `layers` layers and `n` grid points.
    pub fn flat(chain: &WindowChain, element_m: f64) -> ChainSubstrate {
        let layers = (chain.strip_length_m / element_m).round() as usize + 1;
        let n = (chain.strip_length_m / TABLE_STEP_M).round() as usize + 1;
        ChainSubstrate { surface_m: vec![0.0; n], centre_reaction_n: vec![0.0; layers] }
    }
}

impl ChainContact {
    /// Contact on the window `tables` (of the window's parameters; their bump is not used) for
    /// `chain`, with the substrate `substrate`: strip at rest, no contact.
    pub fn new(
        tables: Arc<StripTables>,
        chain: WindowChain,
        substrate: ChainSubstrate,
        geo: ContactGeometry,
    ) -> anyhow::Result<ChainContact> {
        let element_m = tables.params.element_m;
        anyhow::ensure!(
            (tables.params.length_m - chain.window_length_m).abs() < 1e-12,
            "the window tables are not the chain's window length"
        );
        let layers_w = (chain.window_length_m / element_m).round() as usize + 1;
        anyhow::ensure!(
            tables.cl_rows.len() == layers_w,
            "the window's centre line must have one node per layer ({layers_w}), has {}",
            tables.cl_rows.len()
        );
        let span = chain.window_length_m + 2.0 * chain.offsets_m.get(1).copied().unwrap_or(0.0);
        // the pool's centre line goes through the record's per-tick buffer (`fill_record`)
        anyhow::ensure!(((span / element_m).round() as usize) < recordings::MAX_CENTRELINE, "window span too long for the pressure buffer");
        let slot = Slot { window: usize::MAX, x: vec![0.0; 2 * tables.modes], live: false };
        Ok(ChainContact {
            geo,
            area_mid_m2: tables.cl_area_m2[layers_w / 2],
            area_end_m2: tables.cl_area_m2[0],
            slots: [slot.clone(), slot.clone(), slot],
            tables,
            chain,
            substrate,
            element_m,
            share: strip::chain::Share { first: 0, weight: [1.0, 0.0] },
            z_a_m: 0.0,
            delta_prev_m: f64::NEG_INFINITY,
            force_y_n: 0.0,
            wrench: WrenchOnTool::default(),
        })
    }

    /// Rest coordinates of one window's top nodes (window-local z), layer by layer: the layer
    /// pattern the Foxglove scene repeats along the strip.
    pub fn window_top_xyz_m(&self) -> &[[f64; 3]] {
        &self.tables.top_xyz_m
    }

    /// The chain of windows.
    pub fn chain(&self) -> &WindowChain {
        &self.chain
    }

    /// The slot holding window k, taking one (the farthest window's, reset to rest) if none does.
    fn slot_of(&mut self, k: usize, keep: usize) -> usize {
        if let Some(i) = self.slots.iter().position(|s| s.window == k) {
            return i;
        }
        let z = self.z_a_m;
        let distance = |s: &Slot| if s.window == usize::MAX { f64::INFINITY } else { (self.chain.centre_m(s.window) - z).abs() };
        let mut best = usize::MAX;
        for (i, s) in self.slots.iter().enumerate() {
            if s.window != keep && (best == usize::MAX || distance(s) > distance(&self.slots[best])) {
                best = i;
            }
        }
        let s = &mut self.slots[best];
        s.window = k;
        s.x.fill(0.0);
        s.live = false;
        best
    }

    /// One substep, as [`StripContact::substep`]: the contact force from the wheel state at the
    /// substep start, every window advanced by h; returns the wrench on the tool.
    pub fn substep(&mut self, tcp_pos_base: &Vector3<f64>, rot_base_tool: &Matrix3<f64>, twist_base: &Vec6) -> WrenchOnTool {
        let h = self.tables.h_s;
        let (p_low, d) = StripContact::lowest_point_of(&self.geo, tcp_pos_base, rot_base_tool);
        let v = Vector3::new(twist_base[0], twist_base[1], twist_base[2]);
        let w = Vector3::new(twist_base[3], twist_base[4], twist_base[5]);
        let v_low = v + w.cross(&(d * self.geo.wheel_radius_m));
        let p_low_task = self.geo.path.to_path(&p_low, self.z_a_m);
        self.z_a_m = p_low_task.z;
        let y_wheel_end = p_low_task.y + self.geo.path.normal_velocity(&v_low) * h;

        self.share = self.chain.share(self.z_a_m);
        let first = self.share.first;
        let second = (first + 1).min(self.chain.len() - 1);
        let s0 = self.slot_of(first, second);
        let s1 = self.slot_of(second, first);
        let tables = &*self.tables;
        let t = &tables.table;
        let m = tables.modes;
        let lw = self.chain.window_length_m;
        // Free motion of every live window, and its surface under the wheel where it covers it.
        let mut u_free = 0.0;
        for s in self.slots.iter_mut().filter(|s| s.live) {
            super::rotate(&mut s.x[..2 * m], &tables.z_re, &tables.z_im);
            let local = self.z_a_m - self.chain.offsets_m[s.window];
            if (0.0..=lw).contains(&local) {
                let (g, f) = t.locate(local);
                let [a, b] = dot2([t.c_row(g), t.c_row(g + 1)], &s.x);
                u_free += (1.0 - f) * a + f * b;
            }
        }
        // One-substep compliance under the wheel: window k carries φ_k of the force.
        let mut d_h = 0.0;
        let mut at = [(0usize, 0.0f64); 2];
        for (j, &phi) in self.share.weight.iter().enumerate() {
            let k = first + j;
            if phi == 0.0 || k >= self.chain.len() {
                continue;
            }
            let (g, f) = t.locate(self.z_a_m - self.chain.offsets_m[k]);
            at[j] = (g, f);
            let lerp = |a: &[f64]| (1.0 - f) * a[g] + f * a[g + 1];
            d_h += phi
                * (lerp(&t.d_ww) + (1.0 - f) * (1.0 - f) * t.cgb_point[g] + f * (1.0 - f) * t.cgb_cross[g] + f * f * t.cgb_point[g + 1]);
        }
        let surface = STRIP_TOP_HEIGHT_M + self.substrate_surface_m() + u_free;
        let delta0 = surface - y_wheel_end;
        let (k_c, c_c) = (self.geo.stiffness_n_per_m, self.geo.damping_ns_per_m);
        let delta_prev = if self.delta_prev_m.is_finite() { self.delta_prev_m } else { delta0 };
        let kk = k_c + c_c / h;
        let p = ((kk * delta0 - c_c / h * delta_prev) / (1.0 + kk * d_h)).max(0.0);
        self.delta_prev_m = delta0 - d_h * p;
        let f = -p;
        self.force_y_n = f;
        if p > 0.0 {
            for (j, slot) in [s0, s1].into_iter().enumerate() {
                let phi = self.share.weight[j];
                if phi == 0.0 || (j == 1 && second == first) {
                    continue;
                }
                let (g, s) = at[j];
                let (a0, a1) = ((1.0 - s) * phi * f, s * phi * f);
                let sl = &mut self.slots[slot];
                for ((x, b0), b1) in sl.x.iter_mut().zip(t.gb_row(g)).zip(t.gb_row(g + 1)) {
                    *x += a0 * b0 + a1 * b1;
                }
                sl.live = true;
            }
        }
        let force = Vector3::new(0.0, 0.0, p);
        self.wrench = WrenchOnTool { force_base_n: force, torque_base_nm: (d * self.geo.wheel_radius_m).cross(&force) };
        self.wrench
    }

    /// The substrate's static top offset under the wheel, m.
    fn substrate_surface_m(&self) -> f64 {
        let v = &self.substrate.surface_m;
        let x = (self.z_a_m / TABLE_STEP_M).clamp(0.0, (v.len() - 1) as f64);
        let g = (x.floor() as usize).min(v.len() - 2);
        let s = x - g as f64;
        (1.0 - s) * v[g] + s * v[g + 1]
    }

    /// Window `k`'s share of the wheel's load (the chain's smooth weight; 0 for a window the
    /// wheel is not over).
    fn weight_of(&self, k: usize) -> f64 {
        if k == self.share.first {
            self.share.weight[0]
        } else if k == self.share.first + 1 {
            self.share.weight[1]
        } else {
            0.0
        }
    }

    /// Wrench of the last substep on the tool as the sensor reports it (see [`StripContact`]).
    pub fn wrench_on_tool_sensor(&self, rot_base_tool: &Matrix3<f64>) -> ([f64; 3], [f64; 3]) {
        let rt = rot_base_tool.transpose();
        ((rt * self.wrench.force_base_n).into(), (rt * self.wrench.torque_base_nm).into())
    }

    /// Last substep's wrench on the tool (base axes, about the TCP), −F_e.
    pub fn wrench_on_tool(&self) -> WrenchOnTool {
        self.wrench
    }

    pub fn in_contact(&self) -> bool {
        self.force_y_n < 0.0
    }

    /// Force of the wheel on the strip along task y, N (negative when pressing).
    pub fn contact_force_n(&self) -> f64 {
        self.force_y_n
    }

    /// The centre-line bottom pressure (Pa) along the strip around the wheel, summed over the
    /// pool's windows and the substrate's offsets, into `out` (layer `first + i` at `out[i]`);
    /// returns `(first, count)`. A window's reactions within `WINDOW_END_ZONE_M` of its ends inside
    /// the strip are dropped (`strip::chain`: the window's end face is not the long strip's).
    pub fn centreline_pressure_pa(&self, out: &mut [f64]) -> (usize, usize) {
        let tables = &*self.tables;
        let t = &tables.table;
        let n_cl = tables.cl_rows.len();
        let m2 = 2 * tables.modes;
        let layer_of = |o: f64| (o / self.element_m).round() as usize;
        let used = self.slots.iter().filter(|s| s.window != usize::MAX);
        let lo = used.clone().map(|s| layer_of(self.chain.offsets_m[s.window])).min().unwrap_or(0);
        let hi = used.map(|s| layer_of(self.chain.offsets_m[s.window]) + n_cl).max().unwrap_or(0);
        let count = (hi - lo).min(out.len());
        let out = &mut out[..count];
        out.fill(0.0);
        let f = self.force_y_n;
        let last = self.chain.len() - 1;
        for s in self.slots.iter().filter(|s| s.window != usize::MAX) {
            let k = s.window;
            let first = layer_of(self.chain.offsets_m[k]) - lo;
            let phi = self.weight_of(k);
            let (g, sf) = t.locate(self.z_a_m - self.chain.offsets_m[k]);
            let (d0, d1) = (&t.d_cl[g * n_cl..(g + 1) * n_cl], &t.d_cl[(g + 1) * n_cl..(g + 2) * n_cl]);
            let kept = |c: usize| {
                let z = c as f64 * self.element_m;
                let dropped = (k > 0 && z < WINDOW_END_ZONE_M) || (k < last && z > self.chain.window_length_m - WINDOW_END_ZONE_M);
                !dropped && first + c < count
            };
            let mut add = |c: usize, from_state: f64| {
                let mut reaction = from_state;
                if phi != 0.0 {
                    reaction += ((1.0 - sf) * d0[c] + sf * d1[c]) * phi * f;
                }
                out[first + c] += reaction;
            };
            if !s.live {
                (0..n_cl).filter(|&c| kept(c)).for_each(|c| add(c, 0.0));
                continue;
            }
            // The layers' reactions from the state, four rows per pass over x (`dot4`: each bit
            // for bit its `dot`): two thirds of the chain's per-tick dot products are here.
            let row = |c: usize| &tables.ccl[c * m2..(c + 1) * m2];
            let (mut batch, mut n) = ([0usize; 4], 0);
            for c in (0..n_cl).filter(|&c| kept(c)) {
                batch[n] = c;
                n += 1;
                if n == 4 {
                    let y = dot4(batch.map(row), &s.x);
                    batch.iter().zip(y).for_each(|(&c, y)| add(c, y));
                    n = 0;
                }
            }
            batch[..n].iter().for_each(|&c| add(c, dot(row(c), &s.x)));
        }
        let layers = self.substrate.centre_reaction_n.len();
        for (i, p) in out.iter_mut().enumerate() {
            let j = lo + i;
            let area = if j == 0 || j + 1 == layers { self.area_end_m2 } else { self.area_mid_m2 };
            *p = (*p + self.substrate.centre_reaction_n[j]) / area;
        }
        (lo, count)
    }

    /// Strip outputs at the current state for the recording (as [`StripContact::fill_record`]):
    /// the centre-line bottom pressure of the layers the pool's windows cover (about 60 mm
    /// around the wheel for 40 mm windows 10 mm apart), at their strip positions
    /// (`centreline_z0_m`, `centreline_dz_m`: one element apart); the top's centre line is not
    /// computed (zeros).
    pub fn fill_record(&self, r: &mut StripRecord) {
        let tables = &*self.tables;
        let t = &tables.table;
        let f = self.force_y_n;
        let lw = self.chain.window_length_m;
        let (mut u_w, mut reaction_sum) = (self.substrate_surface_m(), 0.0);
        for s in self.slots.iter().filter(|s| s.window != usize::MAX) {
            let k = s.window;
            let local = self.z_a_m - self.chain.offsets_m[k];
            let (g, sf) = t.locate(local);
            let lerp = |a: &[f64]| (1.0 - sf) * a[g] + sf * a[g + 1];
            let phi = self.weight_of(k);
            if s.live {
                reaction_sum += dot(&tables.csum, &s.x);
                if (0.0..=lw).contains(&local) {
                    u_w += (1.0 - sf) * dot(t.c_row(g), &s.x) + sf * dot(t.c_row(g + 1), &s.x);
                }
            }
            if phi != 0.0 {
                reaction_sum += lerp(&t.d_sum) * phi * f;
                u_w += lerp(&t.d_ww) * phi * f;
            }
        }
        r.wheel_z_m = self.z_a_m;
        r.contact_force_n = f;
        r.bottom_force_n = -reaction_sum;
        r.top_displacement_m = u_w;
        let (first, count) = self.centreline_pressure_pa(&mut r.centreline_pressure_pa);
        r.max_bottom_pressure_pa = r.centreline_pressure_pa[..count].iter().copied().fold(0.0, f64::max);
        // The layers around the wheel in strip coordinates (the bond map's samples): their z as
        // two scalars, expanded by the recorder's writer thread.
        r.n_centreline = count as u32;
        r.centreline_z0_m = first as f64 * self.element_m;
        r.centreline_dz_m = self.element_m;
        r.top_centreline_uy_m[..count].fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::tests::coarse;
    use scenarios::Scenario;

    /// TCP (wheel centre) position and tool-down orientation for the wheel's lowest point at task (z, y).
    fn tcp_at(g: &ContactGeometry, z: f64, y_low: f64) -> (Vector3<f64>, Matrix3<f64>) {
        let p = g.path.point_to_base(&Vector3::new(0.0, y_low + g.wheel_radius_m, z));
        let pose = robot::tool_down_pose(p.x, p.y, p.z);
        (pose.translation.vector, pose.rotation.to_rotation_matrix().into_inner())
    }

    /// The wheel held at a fixed depth on a 60 mm chain of 20 mm windows, at a hand-over point,
    /// halfway between two and just before one: the steady force solves p = k (depth − C_s p)
    /// with C_s the chain's static compliance under the wheel from `strip::chain::ChainStatics`
    /// (the window model's DC gain, independent of the contact's tables); the bottom force
    /// balances the wheel's and the surface sits where the penalty spring says.
    #[test]
    fn static_press_on_the_chain_matches_the_chain_statics() {
        let model = coarse();
        let (ls, lw, sp, el) = (0.06, 0.02, 0.004, 0.002);
        let chain = WindowChain::new(ls, lw, sp, el).unwrap();
        let statics = strip::chain::ChainStatics::new(coarse(), chain.clone()).unwrap();
        let tables = Arc::new(StripTables::new(&model, 1e-4));
        let g = ContactGeometry::from_scenario(&Scenario::default());
        let depth = 0.2e-3;
        for z in [chain.centre_m(3), 0.5 * (chain.centre_m(3) + chain.centre_m(4)), chain.centre_m(5) - 0.0013] {
            let mut c = ChainContact::new(tables.clone(), chain.clone(), ChainSubstrate::flat(&chain, el), g.clone()).unwrap();
            let (pos, rot) = tcp_at(&g, z, STRIP_TOP_HEIGHT_M - depth);
            for _ in 0..6000 {
                c.substep(&pos, &rot, &Vec6::zeros());
            }
            let c_s = statics.wheel(z, 1.0).wheel_uy_m;
            let k = g.stiffness_n_per_m;
            let p_expect = k * depth / (1.0 + k * c_s);
            let p = -c.contact_force_n();
            let mut r = StripRecord::default();
            c.fill_record(&mut r);
            eprintln!("z {:.2} mm: p {p:.5} N, statics {p_expect:.5} N, bottom {:.5} N", z * 1e3, r.bottom_force_n);
            assert!((p - p_expect).abs() < 1e-4 * p_expect, "z {z}: p = {p}, expected {p_expect}");
            assert!((r.bottom_force_n + p).abs() < 1e-4 * p, "bottom {} vs contact {}", r.bottom_force_n, -p);
            assert!((k * (STRIP_TOP_HEIGHT_M + r.top_displacement_m - (STRIP_TOP_HEIGHT_M - depth)) - p).abs() < 1e-6 * p);
            assert!(r.max_bottom_pressure_pa > 0.0);
        }
    }
}
