//! The bond map of a long seal (issue 25 item 3): the peak centre-line bottom pressure the wheel
//! produced at each millimetre along the whole strip, from the recorded `/strip` rows.
//!
//! A windowed strip's plant records, every tick, the centre-line bottom pressure of the layers
//! its windows cover (about 60 mm around the wheel for 40 mm windows 10 mm apart) at their strip
//! positions (`/strip.centreline_z`, which then moves with the wheel). The map is the running
//! maximum of those pressures per millimetre, taken here, after the run: the 1 kHz path does no
//! more than fill its fixed-size record. Where the samples are not on the millimetre grid they
//! are interpolated linearly between the nodes (the long seal's 1 mm elements put them on it).
//!
//! The figures against the position along the strip: the map's least and largest peak per
//! [`ALONG_BIN_M`], the force error of the rolling ticks with the wheel in that bin, and the
//! same per substrate feature (each bump, dip and seam of the scenario).

use serde::Serialize;

use crate::read::Recording;
use crate::tracking_input::tracking_ticks;

/// The bond needs at least this bottom pressure under the wheel (thesis Section 4.2, Appendix C).
pub const BOND_PRESSURE_PA: f64 = 100e3;

/// Grid of the bond map along the strip, m.
pub const BOND_MAP_STEP_M: f64 = 1e-3;
/// Width of the bins of the pressure and force error against the position along the strip, m.
pub const ALONG_BIN_M: f64 = 20e-3;
/// The force error "near" a feature: rolling ticks with the wheel within the feature's extent
/// widened by this on each side, m (the wheel's contact patch and the 25 Hz force loop's lag at
/// 100 mm/s are both under 1 mm; 5 mm also takes in the strip's own spread of the load).
pub const FEATURE_MARGIN_M: f64 = 5e-3;

/// A substrate feature's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FeatureBond {
    /// `bump`, `dip` (a bump of negative height) or `seam`.
    pub kind: &'static str,
    /// Centre of the bump or dip, position of the seam, m.
    pub at_m: f64,
    /// Height (bump, dip) or step (seam), m.
    pub height_m: f64,
    /// The feature's extent on the strip: a bump's centre ± half width, a seam's position ±
    /// half its smoothing length, m.
    pub from_m: f64,
    pub to_m: f64,
    /// Least and largest peak centre-line pressure of the bond map over the extent, Pa (None:
    /// the wheel never came near).
    pub min_peak_pa: Option<f64>,
    pub max_peak_pa: Option<f64>,
    /// Force error e = |bottom| − |set-point| of the rolling ticks with the wheel within the
    /// extent ± [`FEATURE_MARGIN_M`]: max |e| and RMS, N; and how many ticks.
    pub force_error_max_abs_n: Option<f64>,
    pub force_error_rms_n: Option<f64>,
    pub ticks: usize,
}

/// One bin along the strip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlongBin {
    pub from_m: f64,
    pub to_m: f64,
    /// Least and largest peak of the bond map in the bin, Pa.
    pub min_peak_pa: Option<f64>,
    pub max_peak_pa: Option<f64>,
    /// Force error of the rolling ticks with the wheel in the bin (as [`FeatureBond`]).
    pub force_error_max_abs_n: Option<f64>,
    pub force_error_rms_n: Option<f64>,
    pub ticks: usize,
}

/// The bond map and its figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BondMap {
    /// Grid step, m: `peak_pa[i]` is at z = i step along the strip.
    pub step_m: f64,
    pub strip_length_m: f64,
    /// Peak centre-line bottom pressure seen at each grid point over the whole run, Pa (None:
    /// never inside the recorded span).
    pub peak_pa: Vec<Option<f64>>,
    /// The bond threshold of the coverage: the thesis' 100 kPa (Section 4.2, Appendix C; the
    /// pressure the adhesive needs to bond, the same line as the report's rolled-length share).
    pub threshold_pa: f64,
    /// The wheel's rolled range (first to last rolling tick), m.
    pub rolled_from_m: f64,
    pub rolled_to_m: f64,
    /// Share (0..1) of the grid points within the rolled range whose peak reached the threshold.
    pub coverage_rolled: f64,
    /// The same over the whole strip (its ends, where the wheel set down and lifted off, count).
    pub coverage_strip: f64,
    /// The weakest peak within the rolled range and where: [Pa, m].
    pub weakest_rolled_pa_at_m: Option<[f64; 2]>,
    pub features: Vec<FeatureBond>,
    pub along: Vec<AlongBin>,
}

/// The running maximum of every row's centre-line pressures on the grid `step_m` over
/// `[0, length_m]`. `rows`: (node z ascending, pressures), any number of nodes each.
pub fn peak_on_grid<'a>(rows: impl IntoIterator<Item = (&'a [f32], &'a [f32])>, length_m: f64, step_m: f64) -> Vec<Option<f64>> {
    let n = (length_m / step_m).round() as usize + 1;
    let mut peak: Vec<Option<f64>> = vec![None; n];
    for (z, p) in rows {
        let m = z.len().min(p.len());
        if m == 0 {
            continue;
        }
        let (z, p) = (&z[..m], &p[..m]);
        let (lo, hi) = (z[0] as f64, z[m - 1] as f64);
        // grid points inside the nodes' span (a 1e-6 step tolerance: f32 node positions)
        let first = ((lo / step_m) - 1e-6).ceil().max(0.0) as usize;
        let last = (((hi / step_m) + 1e-6).floor().max(0.0) as usize).min(n - 1);
        let mut j = 0;
        for (g, slot) in peak.iter_mut().enumerate().take(last + 1).skip(first) {
            let zg = g as f64 * step_m;
            while j + 1 < m && (z[j + 1] as f64) < zg - 1e-9 {
                j += 1;
            }
            let v = if j + 1 >= m {
                p[m - 1] as f64
            } else {
                let (z0, z1) = (z[j] as f64, z[j + 1] as f64);
                let w = if z1 > z0 { ((zg - z0) / (z1 - z0)).clamp(0.0, 1.0) } else { 0.0 };
                p[j] as f64 * (1.0 - w) + p[j + 1] as f64 * w
            };
            *slot = Some(slot.map_or(v, |s: f64| s.max(v)));
        }
    }
    peak
}

/// Least and largest of the map's defined values on grid points in `[from, to]`.
fn min_max(peak: &[Option<f64>], step_m: f64, from_m: f64, to_m: f64) -> (Option<f64>, Option<f64>) {
    let a = (from_m / step_m).ceil().max(0.0) as usize;
    let b = ((to_m / step_m).floor().max(0.0) as usize).min(peak.len().saturating_sub(1));
    let mut lo: Option<f64> = None;
    let mut hi: Option<f64> = None;
    for v in peak.iter().take(b + 1).skip(a).flatten() {
        lo = Some(lo.map_or(*v, |l| l.min(*v)));
        hi = Some(hi.map_or(*v, |h| h.max(*v)));
    }
    (lo, hi)
}

/// max |e| and RMS of the errors `(z, e)` with z in `[from, to)`.
fn errors_in(errors: &[(f64, f64)], from_m: f64, to_m: f64) -> (Option<f64>, Option<f64>, usize) {
    let e: Vec<f64> = errors.iter().filter(|(z, _)| *z >= from_m && *z < to_m).map(|(_, e)| *e).collect();
    if e.is_empty() {
        return (None, None, 0);
    }
    let max = e.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    (Some(max), Some(rms), e.len())
}

/// The bond map of a windowed strip's recording (its scenario has `strip.window_mm` > 0, or its
/// centre-line nodes move with the wheel); None for any other (the single model's fixed nodes have the report's rolled-length share).
pub fn bond_map(rec: &Recording) -> Option<BondMap> {
    let scenario: Option<scenarios::Scenario> =
        rec.run_metadata().ok().and_then(|m| m.scenario).and_then(|src| toml::from_str(&src.toml).ok());
    // a chain of one window (the strip's own length) records fixed nodes, but no metadata z
    let windowed = scenario.as_ref().is_some_and(|s| s.strip.window_mm > 0.0);
    if !(rec.strip_nodes_move() || windowed && !rec.strip_centreline_z_m.is_empty()) {
        return None;
    }
    let z_max = (0..rec.strip.len()).filter_map(|i| rec.strip_row_z(i).last().copied()).fold(0.0f32, f32::max) as f64;
    let length_m = scenario.as_ref().map_or(z_max, |s| s.strip.length_mm * 1e-3);
    let step = BOND_MAP_STEP_M;
    let peak = peak_on_grid((0..rec.strip.len()).map(|i| (rec.strip_row_z(i), &rec.strip[i].centreline_pressure_pa[..])), length_m, step);

    let ticks = tracking_ticks(rec);
    let roll = crate::tracking::rolling_ticks(&ticks);
    let errors: Vec<(f64, f64)> = roll.iter().filter_map(|&i| ticks[i].force_error_n().map(|e| (ticks[i].wheel_z_m, e))).collect();
    let (rolled_from_m, rolled_to_m) = match (roll.first(), roll.last()) {
        (Some(&a), Some(&b)) => {
            let (z0, z1) = (rec.strip[a - 1].wheel_z_m, rec.strip[b].wheel_z_m);
            (z0.min(z1), z0.max(z1))
        }
        _ => (0.0, 0.0),
    };
    let share = |from: f64, to: f64| {
        let a = (from / step).ceil().max(0.0) as usize;
        let b = ((to / step).floor().max(0.0) as usize).min(peak.len() - 1);
        if b < a {
            return 0.0;
        }
        peak[a..=b].iter().filter(|p| p.is_some_and(|p| p >= BOND_PRESSURE_PA)).count() as f64 / (b - a + 1) as f64
    };
    let weakest = {
        let a = (rolled_from_m / step).ceil() as usize;
        let b = ((rolled_to_m / step).floor() as usize).min(peak.len() - 1);
        (a..=b).filter_map(|g| peak.get(g).copied().flatten().map(|p| [p, g as f64 * step])).min_by(|x, y| x[0].total_cmp(&y[0]))
    };

    let mut features = Vec::new();
    if let Some(s) = &scenario {
        let mm = 1e-3;
        let mut bumps: Vec<[f64; 3]> = s.substrate.bumps.clone();
        if s.bulge.height_mm != 0.0 {
            bumps.push([s.bulge.center_mm, s.bulge.half_width_mm, s.bulge.height_mm]);
        }
        let mut feature = |kind, at_m: f64, height_m, from_m: f64, to_m: f64| {
            let (min_peak_pa, max_peak_pa) = min_max(&peak, step, from_m, to_m);
            let (fmax, frms, n) = errors_in(&errors, from_m - FEATURE_MARGIN_M, to_m + FEATURE_MARGIN_M);
            features.push(FeatureBond {
                kind,
                at_m,
                height_m,
                from_m,
                to_m,
                min_peak_pa,
                max_peak_pa,
                force_error_max_abs_n: fmax,
                force_error_rms_n: frms,
                ticks: n,
            });
        };
        for [c, hw, h] in bumps {
            feature(if h < 0.0 { "dip" } else { "bump" }, c * mm, h * mm, (c - hw) * mm, (c + hw) * mm);
        }
        for &[p, st, sm] in &s.substrate.seams {
            feature("seam", p * mm, st * mm, (p - 0.5 * sm) * mm, (p + 0.5 * sm) * mm);
        }
        features.sort_by(|a, b| a.at_m.total_cmp(&b.at_m));
    }

    let bins = (length_m / ALONG_BIN_M).ceil().max(1.0) as usize;
    let along = (0..bins)
        .map(|k| {
            let (from_m, to_m) = (k as f64 * ALONG_BIN_M, ((k + 1) as f64 * ALONG_BIN_M).min(length_m));
            // grid points [from, to): the bin's upper edge is the next bin's (the strip's end in the last)
            let upper = if k + 1 == bins { to_m } else { to_m - 0.5 * step };
            let (min_peak_pa, max_peak_pa) = min_max(&peak, step, from_m, upper);
            let (fmax, frms, n) = errors_in(&errors, from_m, if k + 1 == bins { to_m + 1e-9 } else { to_m });
            AlongBin { from_m, to_m, min_peak_pa, max_peak_pa, force_error_max_abs_n: fmax, force_error_rms_n: frms, ticks: n }
        })
        .collect();

    Some(BondMap {
        step_m: step,
        strip_length_m: length_m,
        threshold_pa: BOND_PRESSURE_PA,
        rolled_from_m,
        rolled_to_m,
        coverage_rolled: share(rolled_from_m, rolled_to_m),
        coverage_strip: share(0.0, length_m),
        weakest_rolled_pa_at_m: weakest,
        peak_pa: peak,
        features,
        along,
    })
}

/// The bond map's lines of `rig report`.
pub fn format_text(b: &BondMap, s: &mut String) {
    use std::fmt::Write;
    let kpa = |p: Option<f64>| p.map_or("   -  ".to_string(), |p| format!("{:6.1}", p * 1e-3));
    let n = |p: Option<f64>| p.map_or("  -  ".to_string(), |p| format!("{p:5.3}"));
    let _ = writeln!(
        s,
        "bond map    peak centre-line bottom pressure per {:.0} mm of the {:.0} mm strip; >= {:.0} kPa (the thesis' bond pressure): {:.1} % of the rolled {:.1}..{:.1} mm, {:.1} % of the whole strip",
        b.step_m * 1e3,
        b.strip_length_m * 1e3,
        b.threshold_pa * 1e-3,
        b.coverage_rolled * 100.0,
        b.rolled_from_m * 1e3,
        b.rolled_to_m * 1e3,
        b.coverage_strip * 100.0
    );
    if let Some([p, z]) = b.weakest_rolled_pa_at_m {
        let _ = writeln!(s, "            weakest peak in the rolled range {:.1} kPa at z = {:.0} mm", p * 1e-3, z * 1e3);
    }
    if !b.features.is_empty() {
        let _ = writeln!(
            s,
            "features    peak pressure over the feature [kPa] least/largest; force error |e| max / RMS [N] with the wheel within {:.0} mm of it",
            FEATURE_MARGIN_M * 1e3
        );
        for f in &b.features {
            let _ = writeln!(
                s,
                "  {:<5} at {:6.1} mm, {:+.2} mm, z {:6.1}..{:6.1} mm: peak {} / {} kPa, error {} / {} N ({} ticks)",
                f.kind,
                f.at_m * 1e3,
                f.height_m * 1e3,
                f.from_m * 1e3,
                f.to_m * 1e3,
                kpa(f.min_peak_pa),
                kpa(f.max_peak_pa),
                n(f.force_error_max_abs_n),
                n(f.force_error_rms_n),
                f.ticks
            );
        }
    }
    let _ = writeln!(
        s,
        "along       per {:.0} mm: peak pressure least/largest [kPa], force error |e| max / RMS [N] while rolling",
        ALONG_BIN_M * 1e3
    );
    for a in &b.along {
        let _ = writeln!(
            s,
            "  z {:6.1}..{:6.1} mm: peak {} / {} kPa, error {} / {} N ({} ticks)",
            a.from_m * 1e3,
            a.to_m * 1e3,
            kpa(a.min_peak_pa),
            kpa(a.max_peak_pa),
            n(a.force_error_max_abs_n),
            n(a.force_error_rms_n),
            a.ticks
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two rows of moving nodes: the map is the running maximum per grid point, interpolated
    /// between nodes that are off the grid, undefined where no row reached.
    #[test]
    fn the_peak_is_the_running_maximum_on_the_grid() {
        let z1 = [0.0f32, 0.002, 0.004];
        let p1 = [10.0f32, 30.0, 20.0];
        let z2 = [0.003f32, 0.005];
        let p2 = [25.0f32, 5.0];
        let peak = peak_on_grid([(&z1[..], &p1[..]), (&z2[..], &p2[..])], 0.008, 1e-3);
        let want = [Some(10.0), Some(20.0), Some(30.0), Some(25.0), Some(20.0), Some(5.0), None, None, None];
        assert_eq!(peak.len(), want.len());
        for (g, (a, b)) in peak.iter().zip(want).enumerate() {
            match (a, b) {
                (Some(a), Some(b)) => assert!((a - b).abs() < 1e-4, "grid {g}: {a} vs {b}"),
                _ => assert_eq!(*a, b, "grid {g}"),
            }
        }
        let (lo, hi) = min_max(&peak, 1e-3, 0.001, 0.003);
        assert!((lo.unwrap() - 20.0).abs() < 1e-4 && (hi.unwrap() - 30.0).abs() < 1e-4, "{lo:?} {hi:?}");
        let (max, rms, n) = errors_in(&[(0.001, 0.3), (0.002, -0.4), (0.01, 9.0)], 0.0, 0.005);
        assert_eq!((max, n), (Some(0.4), 2));
        assert!((rms.unwrap() - (0.125f64).sqrt()).abs() < 1e-12);
    }
}
