//! A contour run's figures per segment (issue 26): for each piece of the scenario's `[contour]`
//! (and the closed contour's overlap past its start), the rolling ticks with the wheel on it and
//! their true bottom force error, the wheel's lateral offset from the contour and its heading
//! error, and the bond map's coverage over the piece.
//!
//! The lateral and heading errors are measured from the plant's recorded joint angles, not taken
//! from the controller's diagnostics: the TCP by the arm's forward kinematics, projected on the
//! contour (`Contour::project`, on the lap of the wheel's recorded arc length); the heading error
//! is the angle about the substrate normal from the contour's lateral direction to the wheel's
//! axis (the tool's y axis, which points to the right of the path in the tool-down pose), positive
//! counter-clockwise seen from above.

use nalgebra::Vector3;
use scenarios::contour::{Contour, Piece};
use scenarios::path::StripPath;
use serde::Serialize;

use crate::bond_map::{BondMap, BOND_PRESSURE_PA};
use crate::read::Recording;
use crate::tracking_input::tracking_ticks;

/// One segment's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Segment {
    /// `line 150 mm`, `arc R 50 mm 90°`, or `overlap` (a closed contour's strip past its start).
    pub what: String,
    /// The segment along the strip (arc length), m.
    pub from_m: f64,
    pub to_m: f64,
    /// Rolling ticks with the wheel on the segment.
    pub ticks: usize,
    /// True bottom force error |bottom| − |set-point|: max |e| and RMS, N.
    pub force_error_max_abs_n: Option<f64>,
    pub force_error_rms_n: Option<f64>,
    /// Lateral offset of the TCP from the contour: max |·| and RMS, m.
    pub lateral_max_abs_m: Option<f64>,
    pub lateral_rms_m: Option<f64>,
    /// Heading error of the wheel's axis: max |·| and RMS, rad.
    pub heading_max_abs_rad: Option<f64>,
    pub heading_rms_rad: Option<f64>,
    /// Share (0..1) of the bond map's grid points on the segment at or above 100 kPa (None
    /// without a bond map).
    pub bond_coverage: Option<f64>,
}

/// max |x| and RMS of `x` (None when empty).
fn max_rms(x: &[f64]) -> (Option<f64>, Option<f64>) {
    if x.is_empty() {
        return (None, None);
    }
    let max = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (Some(max), Some((x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()))
}

/// The wheel's lateral offset (m, positive to the left) and heading error (rad) at joint angles
/// `q` over `path`, the arc length counted on the lap nearest `s_hint_m`.
pub fn tracking_errors(robot: &robot::Robot, path: &StripPath, q: &[f64; 6], s_hint_m: f64) -> (f64, f64) {
    let pose = robot.tcp_pose(&robot::Vec6::from(*q));
    let p = path.to_path(&pose.translation.vector, s_hint_m);
    let (heading, _) = path.heading_at(p.z);
    let axis = pose.rotation * Vector3::y();
    // The wheel's axis should point to the right of the path: (sin h, −cos h).
    let want = [heading.sin(), -heading.cos()];
    let err = (want[0] * axis.y - want[1] * axis.x).atan2(want[0] * axis.x + want[1] * axis.y);
    (p.x, err)
}

/// The per-segment figures of a contour run (None unless the recording's scenario has a contour).
pub fn contour_figures(rec: &Recording, bond: Option<&BondMap>) -> Option<Vec<Segment>> {
    let s: scenarios::Scenario = toml::from_str(&rec.run_metadata().ok()?.scenario?.toml).ok()?;
    if !s.contour.is_given() {
        return None;
    }
    let contour = Contour::from_scenario(&s).ok()?;
    let path = StripPath::from_scenario(&s);
    let robot = scenarios::geometry::nominal_robot(&s);
    let ticks = tracking_ticks(rec);
    let roll = crate::tracking::rolling_ticks(&ticks);
    // (z, force error, lateral, heading) of every rolling tick.
    let rows: Vec<(f64, Option<f64>, f64, f64)> = roll
        .iter()
        .map(|&i| {
            let z = ticks[i].wheel_z_m;
            let (lat, head) = tracking_errors(&robot, &path, &rec.joint_state[i].q, z);
            (z, ticks[i].force_error_n(), lat, head)
        })
        .collect();
    let mut bounds: Vec<(String, f64, f64)> = contour
        .pieces()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let what = match *p {
                Piece::Line { length_m } => format!("line {:.0} mm", length_m * 1e3),
                Piece::Arc { radius_m, turn_rad } => format!("arc R {:.0} mm {:+.0}°", radius_m * 1e3, turn_rad.to_degrees()),
            };
            let from = contour.piece_start_m(k);
            (format!("{k}: {what}"), from, from + p.length_m())
        })
        .collect();
    let length_m = s.strip.length_mm * 1e-3;
    if contour.is_closed() && length_m > contour.length_m() {
        bounds.push(("overlap".into(), contour.length_m(), length_m));
    }
    let coverage = |from: f64, to: f64| {
        bond.map(|b| {
            let a = (from / b.step_m).ceil().max(0.0) as usize;
            let e = ((to / b.step_m).floor() as usize).min(b.peak_pa.len().saturating_sub(1));
            let n = (a..=e).count().max(1);
            (a..=e).filter(|&g| b.peak_pa.get(g).copied().flatten().is_some_and(|p| p >= BOND_PRESSURE_PA)).count() as f64 / n as f64
        })
    };
    Some(
        bounds
            .into_iter()
            .map(|(what, from_m, to_m)| {
                let on: Vec<_> = rows.iter().filter(|r| r.0 >= from_m && r.0 < to_m).collect();
                let force: Vec<f64> = on.iter().filter_map(|r| r.1).collect();
                let lat: Vec<f64> = on.iter().map(|r| r.2).collect();
                let head: Vec<f64> = on.iter().map(|r| r.3).collect();
                let (fm, fr) = max_rms(&force);
                let (lm, lr) = max_rms(&lat);
                let (hm, hr) = max_rms(&head);
                Segment {
                    what,
                    from_m,
                    to_m,
                    ticks: on.len(),
                    force_error_max_abs_n: fm,
                    force_error_rms_n: fr,
                    lateral_max_abs_m: lm,
                    lateral_rms_m: lr,
                    heading_max_abs_rad: hm,
                    heading_rms_rad: hr,
                    bond_coverage: coverage(from_m, to_m),
                }
            })
            .collect(),
    )
}

/// The segments' lines of `rig report` and `rig run`.
pub fn format_text(segments: &[Segment], s: &mut String) {
    use std::fmt::Write;
    let f = |x: Option<f64>, scale: f64, w: usize, p: usize| x.map_or(format!("{:>w$}", "-"), |v| format!("{:>w$.p$}", v * scale));
    let _ = writeln!(
        s,
        "contour     per segment while rolling: force error |e| max / RMS [N], lateral offset max / RMS [µm], heading error max / RMS [°], bond coverage"
    );
    for g in segments {
        let _ = writeln!(
            s,
            "  {:<22} z {:6.1}..{:6.1} mm: force {} / {} N, lateral {} / {} µm, heading {} / {} °, bond {} % ({} ticks)",
            g.what,
            g.from_m * 1e3,
            g.to_m * 1e3,
            f(g.force_error_max_abs_n, 1.0, 5, 3),
            f(g.force_error_rms_n, 1.0, 5, 3),
            f(g.lateral_max_abs_m, 1e6, 6, 3),
            f(g.lateral_rms_m, 1e6, 6, 3),
            f(g.heading_max_abs_rad, 180.0 / std::f64::consts::PI, 5, 2),
            f(g.heading_rms_rad, 180.0 / std::f64::consts::PI, 5, 2),
            f(g.bond_coverage, 100.0, 5, 1),
            g.ticks
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The errors of a TCP put by IK where the test says: on the contour with the heading, zero;
    /// 2 mm to the left and turned 3° counter-clockwise, +2 mm and +3°.
    #[test]
    fn lateral_and_heading_errors_are_the_ones_the_pose_was_built_with() {
        let mut s = scenarios::Scenario::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/sunroof.toml")).unwrap();
        s.contour.closed = true;
        let path = StripPath::from_scenario(&s);
        let c = path.contour().unwrap().clone();
        let robot = scenarios::geometry::nominal_robot(&s);
        let mut seed = robot::Vec6::from(robot::pose::IK_SEED_TOOL_DOWN);
        for s_m in [0.05, 0.19, 0.30, 0.80] {
            let p = c.at(s_m);
            let pose = c.tcp_pose(s_m, 0.718);
            let q = robot.ik_tcp(&pose, &seed).unwrap();
            let (lat, head) = tracking_errors(&robot, &path, &q.into(), s_m);
            assert!(lat.abs() < 1e-9 && head.abs() < 1e-9, "s {s_m}: {lat} {head}");
            let [lx, ly] = p.left();
            let moved = nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(p.xy_base_m[0] + 0.002 * lx, p.xy_base_m[1] + 0.002 * ly, 0.718),
                nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3f64.to_radians()) * pose.rotation,
            );
            let q = robot.ik_tcp(&moved, &q).unwrap();
            let (lat, head) = tracking_errors(&robot, &path, &q.into(), s_m);
            assert!((lat - 0.002).abs() < 1e-9 && (head - 3f64.to_radians()).abs() < 1e-9, "s {s_m}: {lat} {head}");
            seed = q;
        }
    }
}
