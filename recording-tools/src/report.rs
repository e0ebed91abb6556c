//! Numbers of a recording: ticks, misses, safe stops, drops, latency percentiles, and while the
//! wheel rolls the force tracking (thesis Figure 7.2, the 0.45 N band of Section 7.4) and the
//! share of the rolled length pressed with at least 100 kPa (the bond criterion, Section 4.2).

use crate::read::{Channels, Recording};
use recordings::schema::Channel;
use serde::Serialize;

pub use crate::bond_map::BOND_PRESSURE_PA;
use crate::strip_rows::StripRows;
pub use crate::tracking::ROLLING_MIN_STEP_M;
use crate::tracking::{self, ForceTracking, TrackingTick};
pub use crate::tracking_input::tracking_ticks;

/// Nearest-rank percentiles of a sample, in the sample's unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Percentiles {
    pub n: usize,
    pub mean: f64,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

impl Percentiles {
    /// None for an empty sample.
    pub fn of(mut v: Vec<f64>) -> Option<Self> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        // Nearest rank: the smallest value with at least p of the sample at or below it.
        let rank = |p: f64| v[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
        Some(Self {
            n,
            mean: v.iter().sum::<f64>() / n as f64,
            p50: rank(0.50),
            p90: rank(0.90),
            p99: rank(0.99),
            p999: rank(0.999),
            max: v[n - 1],
        })
    }
}

/// Numbers over the ticks where the wheel rolls along the strip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RollingNumbers {
    pub ticks: usize,
    pub z_from_m: f64,
    pub z_to_m: f64,
    /// Sum of |dz| over the rolling ticks, m.
    pub rolled_length_m: f64,
    /// max |(|bottom_force| - |force_ref|)|, N (ticks with controller diagnostics).
    pub force_error_max_abs_n: Option<f64>,
    /// RMS of |bottom_force| - |force_ref|, N.
    pub force_error_rms_n: Option<f64>,
    /// Mean of |bottom_force| - |force_ref|, N (the steady error of a controller without integral action).
    pub force_error_mean_n: Option<f64>,
    /// Share (0..1) of the rolled length where the centre-line bottom pressure under the wheel
    /// reached [`BOND_PRESSURE_PA`].
    pub bond_pressure_share: Option<f64>,
    /// Weakest centre-line pressure under the wheel over the roll and where: [Pa, wheel z m].
    pub bond_weakest_pa_at_z_m: Option<[f64; 2]>,
}

/// Events listed in the report (a run with more lists the first ones; the file has all).
pub const EVENTS_LISTED: usize = 30;

/// One event as the report lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventLine {
    pub tick: u64,
    pub sim_time_s: f64,
    pub kind: String,
    pub text: String,
}

/// Everything `rig report` prints and writes as JSON.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportNumbers {
    pub file: String,
    /// How the file ends: `complete`, `stopped_early` (the plant ended the recording on purpose:
    /// disk full, write error), `cut` (no footer: a killed run) or `corrupt` (a chunk fails its
    /// CRC or does not decompress); the numbers cover the intact ticks before any damage.
    pub integrity: &'static str,
    /// Why and, for a cut or corrupt file, where (chunk, byte offset, first tick lost).
    pub integrity_detail: Option<String>,
    /// The same where and why as fields, for a cut or corrupt file.
    pub damage: Option<crate::read::Damage>,
    pub ticks: usize,
    pub first_tick: u64,
    pub last_tick: u64,
    pub period_s: f64,
    /// ticks * period, s.
    pub duration_s: f64,
    /// Ticks whose torque was late, missing or refused.
    pub misses: u64,
    /// Entries into the safe stop (plant status transitions).
    pub safe_stops: u64,
    /// Records the recorder dropped (must be 0).
    pub dropped: u64,
    pub events: usize,
    /// The first [`EVENTS_LISTED`] events, in order.
    pub event_list: Vec<EventLine>,
    /// Round trip publish -> torque received, us, over ticks whose torque arrived in time.
    pub latency_us: Option<Percentiles>,
    /// Plant compute time per tick, us.
    pub plant_compute_us: Option<Percentiles>,
    pub rolling: Option<RollingNumbers>,
    /// Where the roll's reference ended against the scenario's plan (None without a recorded
    /// scenario or controller reference).
    pub roll_end: Option<crate::roll_end::RollEnd>,
    /// What each safe stop did to the wheel (recordings with `/strip` rows).
    pub stop_holds: Vec<crate::stop_holds::StopHold>,
    /// Real-time recordings: the control success rate (ticks answered in budget over periods),
    /// its worst 100-period window, and the misses per cause ([`crate::attribution`]).
    pub success_rate: Option<f64>,
    pub worst_window_success_rate: Option<f64>,
    pub misses_by_cause: Vec<(&'static str, u64)>,
    /// The rig's and controller's own misses (all but the host's) per period.
    pub own_miss_rate: Option<f64>,
    /// Every missed tick of a real-time recording and its cause, in tick order.
    pub missed_ticks: Vec<(u64, &'static str)>,
    #[serde(skip)]
    pub attribution: Option<crate::attribution::Attribution>,
    /// A windowed long strip's bond map (issue 25): the peak centre-line pressure per mm along
    /// the strip, its coverage, per feature and per bin along the strip ([`crate::bond_map`]).
    pub bond_map: Option<crate::bond_map::BondMap>,
    /// A contour run's figures per segment (issue 26, [`crate::contour_figures`]).
    pub contour: Option<Vec<crate::contour_figures::Segment>>,
}

/// Index i (into the tick rows) of every tick where the wheel rolls ([`crate::tracking`]'s rule).
pub fn rolling_ticks(rec: &Recording) -> Vec<usize> {
    tracking::rolling_ticks(&tracking_ticks(rec))
}

/// The force tracking of a recording over its rolling phase (the figures `rig report`, `rig run`
/// and `rig sweep` print); None without a rolling tick that has a set-point.
pub fn force_tracking(rec: &Recording) -> Option<ForceTracking> {
    tracking::rolling_force_tracking(&tracking_ticks(rec))
}

/// Linear interpolation of (z, p) samples at `z` (clamped to the ends). `z_nodes` ascending.
pub fn interpolate(z_nodes: &[f64], p: &[f32], z: f64) -> Option<f64> {
    let n = z_nodes.len().min(p.len());
    if n == 0 {
        return None;
    }
    let z_nodes = &z_nodes[..n];
    let j = z_nodes.partition_point(|&zn| zn <= z);
    Some(if j == 0 {
        p[0] as f64
    } else if j == n {
        p[n - 1] as f64
    } else {
        let (z0, z1) = (z_nodes[j - 1], z_nodes[j]);
        let w = (z - z0) / (z1 - z0);
        p[j - 1] as f64 * (1.0 - w) + p[j] as f64 * w
    })
}

/// The channels [`numbers`] reads: a recording opened with only these
/// ([`Recording::open_channels`]) gives the same numbers as one read whole
/// (`/joint_torque`, `/wrench` and `/egm` are not decoded: two of the six per-tick channels).
pub const NUMBERS_CHANNELS: Channels =
    Channels::of(&[Channel::JointState, Channel::Strip, Channel::Controller, Channel::Timing, Channel::Events]);

pub fn numbers(rec: &Recording) -> ReportNumbers {
    let bond_map = crate::bond_map::bond_map(rec);
    let tracking = tracking_ticks(rec);
    let ticks = rec.joint_state.len();
    let period_s = rec.period_s();
    let misses = rec.timing.iter().filter(|t| t.timing.missed).count() as u64;
    let safe = messages::PlantStatus::SafeStop as u32;
    let safe_stops = rec
        .joint_state
        .iter()
        .enumerate()
        .filter(|(i, s)| s.plant_status == safe && (*i == 0 || rec.joint_state[i - 1].plant_status != safe))
        .count() as u64;
    let latency = rec
        .timing
        .iter()
        .filter(|t| !t.timing.missed && t.timing.torque_receive_wall_ns != 0)
        .map(|t| t.timing.round_trip_ns as f64 * 1e-3)
        .collect();
    let plant = rec.timing.iter().map(|t| t.timing.plant_compute_ns as f64 * 1e-3).collect();
    // Misses and success rate mean something against a clock: real-time recordings only.
    let realtime = rec.run_metadata().is_ok_and(|m| m.mode == scenarios::Mode::Realtime);
    let attribution = realtime.then(|| crate::attribution::attribute(&rec.timing));
    let by_cause = attribution
        .as_ref()
        .filter(|a| a.stamped)
        .map_or(Vec::new(), |a| crate::attribution::Cause::ALL.iter().map(|&c| (c.name(), a.count(c))).collect());
    ReportNumbers {
        file: rec.path.display().to_string(),
        integrity: rec.integrity.kind(),
        integrity_detail: rec.integrity.describe(),
        damage: rec.integrity.damage().cloned(),
        ticks,
        first_tick: rec.joint_state.first().map_or(0, |s| s.tick),
        last_tick: rec.joint_state.last().map_or(0, |s| s.tick),
        period_s,
        duration_s: ticks as f64 * period_s,
        misses,
        safe_stops,
        dropped: rec.dropped(),
        events: rec.events.len(),
        event_list: rec
            .events
            .iter()
            .take(EVENTS_LISTED)
            .map(|e| EventLine { tick: e.tick, sim_time_s: e.sim_time_s, kind: e.kind_name.clone(), text: e.text.clone() })
            .collect(),
        latency_us: Percentiles::of(latency),
        plant_compute_us: Percentiles::of(plant),
        rolling: rolling_numbers_of(&tracking, &crate::strip_rows::RecordedRows::of(rec)),
        roll_end: crate::roll_end::roll_end(rec, &tracking),
        stop_holds: crate::stop_holds::stop_holds(rec),
        success_rate: attribution.as_ref().filter(|a| a.periods > 0).map(|a| a.success_rate),
        worst_window_success_rate: attribution.as_ref().and_then(|a| a.worst_window).map(|w| w.0),
        misses_by_cause: by_cause,
        own_miss_rate: attribution.as_ref().filter(|a| a.stamped && a.periods > 0).map(|a| a.own_miss_rate()),
        missed_ticks: attribution.as_ref().map_or_else(Vec::new, |a| a.missed_ticks.iter().map(|&(t, c)| (t, c.name())).collect()),
        attribution,
        contour: crate::contour_figures::contour_figures(rec, bond_map.as_ref()),
        bond_map,
    }
}

impl crate::strip_rows::CaseRows {
    /// The numbers `rig report` would print for the recording of these rows.
    pub fn rolling_numbers(&self) -> Option<RollingNumbers> {
        rolling_numbers_of(self.ticks(), self)
    }
}

/// The rolling-phase numbers of tick rows as [`tracking_ticks`] gives them and their `/strip`
/// rows (a recording's, or a case's kept in memory: [`crate::strip_rows::CaseRows`]); the same
/// figures from either, bit for bit, as long as the rows are the recorded ones (f32 pressures).
pub fn rolling_numbers_of(ticks: &[TrackingTick], rows: &impl StripRows) -> Option<RollingNumbers> {
    let roll = tracking::rolling_ticks(ticks);
    if roll.is_empty() {
        return None;
    }
    let force = tracking::force_tracking(ticks, &roll);
    let mut scratch = Vec::new();
    let mut rolled = 0.0;
    let mut pressed = 0.0;
    let mut have_pressure = true;
    let mut weakest: Option<[f64; 2]> = None;
    for &i in &roll {
        let dz = (rows.wheel_z_m(i) - rows.wheel_z_m(i - 1)).abs();
        rolled += dz;
        let z = rows.wheel_z_m(i);
        match interpolate(rows.centreline_z_m(i, &mut scratch), rows.centreline_pressure_pa(i), z) {
            Some(p) => {
                // Compression is positive (the plant's convention); tension never bonds.
                if p >= BOND_PRESSURE_PA {
                    pressed += dz;
                }
                if weakest.is_none_or(|w| p < w[0]) {
                    weakest = Some([p, z]);
                }
            }
            None => have_pressure = false,
        }
    }
    Some(RollingNumbers {
        ticks: roll.len(),
        z_from_m: rows.wheel_z_m(roll[0] - 1),
        z_to_m: rows.wheel_z_m(roll[roll.len() - 1]),
        rolled_length_m: rolled,
        force_error_max_abs_n: force.map(|f| f.max_abs_n),
        force_error_rms_n: force.map(|f| f.rms_n),
        force_error_mean_n: force.map(|f| f.mean_n),
        bond_pressure_share: (have_pressure && rolled > 0.0).then(|| pressed / rolled),
        bond_weakest_pa_at_z_m: weakest.filter(|_| have_pressure),
    })
}

/// The numbers as the text `rig report` and `rig run` print.
pub fn format_text(n: &ReportNumbers) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "recording   {}", n.file);
    if let Some(t) = &n.integrity_detail {
        let _ = writeln!(s, "WARNING     {t}");
    }
    if n.ticks == 0 {
        // Not "0 (0..=0), 0.000 s at 0 Hz": nothing was integrated (in lockstep: no controller
        // answered tick 0).
        let _ = writeln!(s, "ticks       0: no tick was integrated");
    } else {
        let _ = writeln!(
            s,
            "ticks       {} ({}..={}), {:.3} s at {:.0} Hz",
            n.ticks,
            n.first_tick,
            n.last_tick,
            n.duration_s,
            if n.period_s > 0.0 { 1.0 / n.period_s } else { 0.0 }
        );
    }
    let _ = writeln!(s, "misses      {}", n.misses);
    let _ = writeln!(s, "safe stops  {}", n.safe_stops);
    for h in n.stop_holds.iter().take(crate::stop_holds::STOPS_LISTED) {
        let _ = writeln!(s, "{}", h.line(n.period_s));
    }
    let _ = writeln!(s, "dropped     {}{}", n.dropped, if n.dropped > 0 { "  (RECORDING INCOMPLETE)" } else { "" });
    let _ = writeln!(s, "events      {}", n.events);
    for e in &n.event_list {
        let _ = writeln!(s, "  {:>9.3} s  tick {:<7} {:<18} {}", e.sim_time_s, e.tick, e.kind, e.text);
    }
    if n.events > n.event_list.len() {
        let _ = writeln!(s, "  ... {} more in /events", n.events - n.event_list.len());
    }
    let pct = |name: &str, p: &Option<Percentiles>, s: &mut String| {
        let _ = match p {
            Some(p) => writeln!(
                s,
                "{name:<11} p50 {:.1} us, p90 {:.1}, p99 {:.1}, p99.9 {:.1}, max {:.1} (n = {})",
                p.p50, p.p90, p.p99, p.p999, p.max, p.n
            ),
            None => writeln!(s, "{name:<11} none"),
        };
    };
    pct("latency", &n.latency_us, &mut s);
    pct("plant step", &n.plant_compute_us, &mut s);
    match &n.rolling {
        None => {
            let _ = writeln!(s, "rolling     the wheel did not roll along the strip");
        }
        Some(r) => {
            let _ = writeln!(
                s,
                "rolling     {} ticks, z {:.2} -> {:.2} mm ({:.2} mm rolled)",
                r.ticks,
                r.z_from_m * 1e3,
                r.z_to_m * 1e3,
                r.rolled_length_m * 1e3
            );
            if let Some(e) = n.roll_end.filter(crate::roll_end::RollEnd::is_short) {
                let _ = writeln!(s, "{}", e.line());
            }
            let _ = match (r.force_error_max_abs_n, r.force_error_rms_n, r.force_error_mean_n) {
                (Some(m), Some(rms), Some(mean)) => {
                    writeln!(s, "force err   |bottom| - |ref|: max {m:.3} N, RMS {rms:.3} N, mean {mean:+.3} N (thesis: within 0.45 N)")
                }
                _ => writeln!(s, "force err   no controller diagnostics (no force reference recorded)"),
            };
            let _ = match (r.bond_pressure_share, r.bond_weakest_pa_at_z_m) {
                (Some(share), Some([p, z])) => writeln!(
                    s,
                    "bond        {:.1} % of the rolled length saw >= {:.0} kPa on the centre line under the wheel (weakest {:.1} kPa at z = {:.1} mm)",
                    share * 100.0,
                    BOND_PRESSURE_PA * 1e-3,
                    p * 1e-3,
                    z * 1e3
                ),
                _ => writeln!(s, "bond        no centre-line pressure or node positions (metadata centreline_z_m) recorded"),
            };
        }
    }
    if let Some(b) = &n.bond_map {
        crate::bond_map::format_text(b, &mut s);
    }
    if let Some(c) = &n.contour {
        crate::contour_figures::format_text(c, &mut s);
    }
    if let Some(a) = &n.attribution {
        s += &crate::attribution::format_table(a);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let p = Percentiles::of((1..=1000).map(|v| v as f64).collect()).unwrap();
        assert_eq!((p.p50, p.p90, p.p99, p.p999, p.max), (500.0, 900.0, 990.0, 999.0, 1000.0));
        assert_eq!(p.mean, 500.5);
        let one = Percentiles::of(vec![7.0]).unwrap();
        assert_eq!((one.p50, one.p999), (7.0, 7.0));
        assert!(Percentiles::of(vec![]).is_none());
    }

    #[test]
    fn interpolation_is_linear_between_nodes_and_clamped_outside() {
        let z = [0.0, 1.0, 3.0];
        let p = [10.0f32, 20.0, 0.0];
        assert_eq!(interpolate(&z, &p, 0.5), Some(15.0));
        assert_eq!(interpolate(&z, &p, 2.0), Some(10.0));
        assert_eq!(interpolate(&z, &p, 1.0), Some(20.0));
        assert_eq!(interpolate(&z, &p, -1.0), Some(10.0));
        assert_eq!(interpolate(&z, &p, 9.0), Some(0.0));
        assert_eq!(interpolate(&[], &p, 0.0), None);
    }
}

/// Files `write_report` produced.
#[derive(Debug, Clone, Default)]
pub struct ReportFiles {
    pub text: std::path::PathBuf,
    pub json: std::path::PathBuf,
    pub figures: Vec<std::path::PathBuf>,
}

/// The default instants of the pressure figure: the wheel at 10, 30, 50, 70, 90 % of its roll
/// (or 5 evenly spaced ticks if it never rolls). Sim times, s.
pub fn default_instants(rec: &Recording) -> Vec<f64> {
    let roll = rolling_ticks(rec);
    let t = |i: usize| rec.joint_state[i].sim_time_s;
    if let (Some(&first), Some(&last)) = (roll.first(), roll.last()) {
        let (z0, z1) = (rec.strip[first - 1].wheel_z_m, rec.strip[last].wheel_z_m);
        return [0.1, 0.3, 0.5, 0.7, 0.9]
            .iter()
            .filter_map(|f| {
                let target = z0 + f * (z1 - z0);
                roll.iter().find(|&&i| (rec.strip[i].wheel_z_m - target) * (z1 - z0).signum() >= 0.0).map(|&i| t(i))
            })
            .collect();
    }
    let n = rec.joint_state.len();
    if n == 0 {
        return Vec::new();
    }
    (0..5).map(|k| t((n - 1) * (2 * k + 1) / 10)).collect()
}

/// Writes `report.txt`, `report.json` and the figures (PNG + SVG) into `out_dir`.
/// `instants`: sim times (s) of the pressure-profile figure; empty = [`default_instants`].
pub fn write_report(rec: &Recording, out_dir: &std::path::Path, instants: &[f64]) -> anyhow::Result<(ReportNumbers, ReportFiles)> {
    use crate::plots::{self, Histogram, LinePlot, Series};
    use anyhow::Context;
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating the report folder {}", out_dir.display()))?;
    let n = numbers(rec);
    let mut files = ReportFiles { text: out_dir.join("report.txt"), json: out_dir.join("report.json"), figures: Vec::new() };
    std::fs::write(&files.text, format_text(&n)).with_context(|| format!("writing {}", files.text.display()))?;
    std::fs::write(&files.json, serde_json::to_string_pretty(&n)? + "\n").with_context(|| format!("writing {}", files.json.display()))?;

    // Figure 7.2: set-point and realised bottom force against the wheel position.
    let ctrl = rec.controller_by_tick();
    let roll = rolling_ticks(rec);
    if !roll.is_empty() {
        let z_mm = |i: usize| rec.strip[i].wheel_z_m * 1e3;
        let mut plot = LinePlot {
            title: "Force set-point and bottom force while rolling (thesis Figure 7.2)".into(),
            x_label: "wheel position along the strip z [mm]".into(),
            y_label: "force magnitude [N]".into(),
            series: vec![Series {
                label: "|bottom force| (realised)".into(),
                points: roll.iter().map(|&i| (z_mm(i), rec.strip[i].bottom_force_n.abs())).collect(),
            }],
            hlines: Vec::new(),
            vlines: Vec::new(),
        };
        let refs: Vec<(f64, f64)> = roll.iter().filter_map(|&i| ctrl[i].map(|c| (z_mm(i), rec.controller[c].force_ref_n.abs()))).collect();
        if !refs.is_empty() {
            plot.series.insert(0, Series { label: "|force set-point|".into(), points: refs });
        }
        plot.series.push(Series {
            label: "|wheel contact force|".into(),
            points: roll.iter().map(|&i| (z_mm(i), rec.strip[i].contact_force_n.abs())).collect(),
        });
        files.figures.extend(plots::save_lines(&plot, &out_dir.join("force_tracking"))?);
    }

    // The bond check: the centre-line pressure under the wheel along the roll (the 100 kPa line).
    let z_nodes = rec.centreline_z_m();
    let moving = rec.strip_nodes_move();
    let nodes_of = |i: usize| -> std::borrow::Cow<'_, [f64]> {
        if moving {
            std::borrow::Cow::Owned(rec.strip_row_z(i).iter().map(|&z| z as f64).collect())
        } else {
            std::borrow::Cow::Borrowed(&z_nodes)
        }
    };
    if !roll.is_empty() && !z_nodes.is_empty() {
        let points: Vec<(f64, f64)> = roll
            .iter()
            .filter_map(|&i| {
                interpolate(&nodes_of(i), &rec.strip[i].centreline_pressure_pa, rec.strip[i].wheel_z_m)
                    .map(|p| (rec.strip[i].wheel_z_m * 1e3, p * 1e-3))
            })
            .collect();
        if !points.is_empty() {
            let plot = LinePlot {
                title: "Bond check: bottom pressure on the centre line under the wheel while rolling".into(),
                x_label: "wheel position along the strip z [mm]".into(),
                y_label: "pressure under the wheel [kPa]".into(),
                series: vec![Series { label: "under the wheel".into(), points }],
                hlines: vec![(BOND_PRESSURE_PA * 1e-3, "100 kPa bond pressure".into())],
                vlines: Vec::new(),
            };
            files.figures.extend(plots::save_lines(&plot, &out_dir.join("bond_pressure"))?);
        }
    }

    // Figure 7.4: bottom pressure along the centre line at chosen instants.
    let instants = if instants.is_empty() { default_instants(rec) } else { instants.to_vec() };
    if !z_nodes.is_empty() && !rec.strip.is_empty() {
        let mut series = Vec::new();
        for t in instants {
            let i = rec.joint_state.partition_point(|s| s.sim_time_s < t).min(rec.joint_state.len() - 1);
            let i = i.min(rec.strip.len() - 1);
            let s = &rec.strip[i];
            series.push(Series {
                label: format!("t = {:.3} s, wheel at {:.1} mm", rec.joint_state[i].sim_time_s, s.wheel_z_m * 1e3),
                points: nodes_of(i).iter().zip(&s.centreline_pressure_pa).map(|(z, p)| (z * 1e3, *p as f64 * 1e-3)).collect(),
            });
        }
        let plot = LinePlot {
            title: "Bottom pressure on the centre line x = 0 (thesis Figure 7.4)".into(),
            x_label: "z along the strip [mm]".into(),
            y_label: "bottom pressure [kPa]".into(),
            series,
            hlines: vec![(BOND_PRESSURE_PA * 1e-3, "100 kPa bond pressure".into())],
            vlines: Vec::new(),
        };
        files.figures.extend(plots::save_lines(&plot, &out_dir.join("bottom_pressure"))?);
    }

    // The long seal's bond map (issue 25): the peak centre-line pressure along the whole strip,
    // and the force error of the rolling ticks against the wheel's position.
    // A contour's segment ends, marked on the plots against the arc length.
    let segment_ends: Vec<(f64, String)> =
        n.contour.iter().flatten().map(|g| (g.from_m * 1e3, g.what.split(':').next().unwrap_or("").to_string())).collect();
    if let Some(b) = &n.bond_map {
        let peak: Vec<(f64, f64)> =
            b.peak_pa.iter().enumerate().filter_map(|(g, p)| p.map(|p| (g as f64 * b.step_m * 1e3, p * 1e-3))).collect();
        if !peak.is_empty() {
            let plot = LinePlot {
                title: "Bond map: peak centre-line bottom pressure along the strip".into(),
                x_label: "z along the strip [mm]".into(),
                y_label: "peak bottom pressure [kPa]".into(),
                series: vec![Series { label: "peak over the run".into(), points: peak }],
                hlines: vec![(BOND_PRESSURE_PA * 1e-3, "100 kPa bond pressure".into())],
                vlines: segment_ends.clone(),
            };
            files.figures.extend(plots::save_lines(&plot, &out_dir.join("bond_map"))?);
        }
        let ticks = tracking_ticks(rec);
        let errors: Vec<(f64, f64)> =
            roll.iter().filter_map(|&i| ticks[i].force_error_n().map(|e| (ticks[i].wheel_z_m * 1e3, e))).collect();
        if !errors.is_empty() {
            let plot = LinePlot {
                title: "Force error along the strip while rolling".into(),
                x_label: "wheel position along the strip z [mm]".into(),
                y_label: "|bottom force| - |set-point| [N]".into(),
                series: vec![Series { label: "force error".into(), points: errors }],
                hlines: vec![(0.45, "thesis bound +0.45 N".into()), (-0.45, "-0.45 N".into())],
                vlines: segment_ends.clone(),
            };
            files.figures.extend(plots::save_lines(&plot, &out_dir.join("force_error_along"))?);
        }
    }

    // Joint torques as applied.
    if !rec.joint_torque.is_empty() {
        let t = |i: usize| rec.joint_state.get(i).map_or(i as f64 * n.period_s, |s| s.sim_time_s);
        let plot = LinePlot {
            title: "Joint torques as applied".into(),
            x_label: "simulated time [s]".into(),
            y_label: "torque [N m]".into(),
            series: (0..messages::DOF)
                .map(|j| Series {
                    label: format!("joint {}", j + 1),
                    points: rec.joint_torque.iter().enumerate().map(|(i, r)| (t(i), r.torque.tau[j])).collect(),
                })
                .collect(),
            hlines: Vec::new(),
            vlines: Vec::new(),
        };
        files.figures.extend(plots::save_lines(&plot, &out_dir.join("joint_torques"))?);
    }

    // Latency histogram.
    let lat: Vec<f64> = rec
        .timing
        .iter()
        .filter(|t| !t.timing.missed && t.timing.torque_receive_wall_ns != 0)
        .map(|t| t.timing.round_trip_ns as f64 * 1e-3)
        .collect();
    if let Some(p) = n.latency_us {
        let h = Histogram {
            title: format!("Round-trip latency: p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} ticks)", p.p50, p.p99, p.max, p.n),
            x_label: "publish -> torque received [us]".into(),
            bins: plots::bin(&lat, 0.0, p.max * 1.02, 80),
        };
        files.figures.extend(plots::save_histogram(&h, &out_dir.join("latency_histogram"))?);
    }
    Ok((n, files))
}
