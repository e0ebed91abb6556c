//! The `[contour]` section (issue 26): the shipped sunroof loads and is the closed-form rounded
//! rectangle; bad paths are refused with file, line and field (a tangent jump, a radius the wheel
//! cannot follow, a piece of no length); a path the arm cannot follow is refused when the scenario
//! loads (before any daemon starts), naming the arc length; the time law keeps its rules.

use std::path::Path;

use scenarios::contour::{Contour, TimeLaw, MIN_RADIUS_M};
use scenarios::{Place, Scenario};

fn sunroof_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sunroof.toml")
}

/// The shipped file is issue 26's opening: 400 x 250 mm with 50 mm corners, closed, the strip
/// 1226 mm along its 1214.16 mm (2 (300 + 150) + 2π 50), started mid long side.
#[test]
fn the_sunroof_is_the_rounded_rectangle_of_the_issue() {
    let s = Scenario::load(&sunroof_path()).unwrap();
    let c = Contour::from_scenario(&s).unwrap();
    let want = Contour::rounded_rectangle([0.9, -0.125], 0.0, 0.4, 0.25, 0.05, MIN_RADIUS_M).unwrap();
    assert!((c.length_m() - (0.9 + 0.1 * std::f64::consts::PI)).abs() < 1e-12, "{}", c.length_m());
    assert_eq!(c.pieces().len(), want.pieces().len());
    for k in 0..=100 {
        let s_m = k as f64 * c.length_m() / 100.0;
        let (a, b) = (c.at(s_m), want.at(s_m));
        assert!((a.xy_base_m[0] - b.xy_base_m[0]).abs() < 1e-12 && (a.xy_base_m[1] - b.xy_base_m[1]).abs() < 1e-12, "s {s_m}");
    }
    assert!(c.is_closed());
    let overlap_mm = s.strip.length_mm - c.length_m() * 1e3;
    assert!(overlap_mm > 0.0 && overlap_mm < 20.0, "overlap {overlap_mm} mm");
    assert!(s.trajectory.z_end_mm > c.length_m() * 1e3, "the lap passes the start");
}

/// Each bad path is refused on the line of its row, naming the field and column.
#[test]
fn bad_paths_are_refused_with_file_line_and_field() {
    let head = "[strip]\nlength_mm = 600\nwindow_mm = 40\nwindow_spacing_mm = 10\n\n[trajectory]\nz_end_mm = 500\n\n[contour]\n";
    for (body, line, field, why) in [
        // a closed contour whose end turns by 80° where it meets its start
        (
            "closed = true\npieces = [\n  [100, 0, 0],\n  [0, 50, 90],\n  [100, 0, 0],\n  [0, 50, 80],\n]\n",
            15,
            "contour.pieces[3] line_mm",
            "the contour: is closed but its end is",
        ),
        // a corner tighter than the wheel follows
        (
            "pieces = [\n  [100, 0, 0],\n  [0, 10, 90],\n  [400, 0, 0],\n]\n",
            12,
            "contour.pieces[1] radius_mm",
            "an arc of radius 10.0 mm: the wheel follows 20.0 mm or more",
        ),
        // a piece of no length
        ("pieces = [\n  [100, 0, 0],\n  [0, 0, 0],\n]\n", 12, "contour.pieces[1] line_mm", "must be a line [length_mm, 0, 0] or an arc"),
        // both a line and an arc
        ("pieces = [[500, 30, 10]]\n", 10, "contour.pieces[0] radius_mm", "must be a line [length_mm, 0, 0] or an arc"),
    ] {
        let e = Scenario::from_toml_str(&format!("{head}{body}"), Path::new("x/c.toml")).unwrap_err();
        let msg = e.to_string();
        assert_eq!(e.field(), Some(field), "{msg}");
        assert_eq!(e.place(), Some(Place::Line(line)), "{msg}");
        assert!(msg.starts_with("scenario file x/c.toml") && msg.contains(why), "{msg}");
    }
    // A tangent jump: a teardrop whose end meets its start at a heading 135° off (a line, an arc
    // of 50 mm turning 225°, and a line back to the start: 50 (1 + √2) mm each).
    let teardrop = "closed = true\npieces = [\n  [120.7106781, 0, 0],\n  [0, 50, 225],\n  [120.7106781, 0, 0],\n]\n";
    let e = Scenario::from_toml_str(&format!("{head}{teardrop}"), Path::new("x/c.toml")).unwrap_err();
    let msg = e.to_string();
    assert_eq!((e.field(), e.place()), (Some("contour.pieces[2] line_mm"), Some(Place::Line(14))), "{msg}");
    assert!(msg.contains("the contour: is closed but its tangent jumps by -135.000° where it meets its start"), "{msg}");
}

/// A path the arm cannot follow fails to load: the refusal names the arc length and the row of
/// the piece holding it. A line from x = 0.9 m away from the base leaves the IRB 2400's reach
/// (joint 3 at its limit) 622 mm out, as the contour module's own test finds it.
#[test]
fn a_path_out_of_reach_is_refused_at_its_arc_length() {
    let text = "[strip]\nlength_mm = 1500\nwindow_mm = 40\nwindow_spacing_mm = 10\n\n[placement]\nstrip_start_x_m = 0.9\n\n\
                [trajectory]\nz_end_mm = 1400\n\n[contour]\npieces = [\n  [100, 0, 0],\n  [1400, 0, 0],\n]\n";
    let e = Scenario::from_toml_str(text, Path::new("x/far.toml")).unwrap_err();
    let msg = e.to_string();
    assert_eq!((e.field(), e.place()), (Some("contour.pieces[1] line_mm"), Some(Place::Line(15))), "{msg}");
    assert!(msg.contains("must stay where the arm can follow it: at arc length 622.0 mm"), "{msg}");
}

/// The time law: at rest at both ends, never above the cruise speed or sqrt(a_lat R) in an arc,
/// its acceleration within the limit; s, v and a are each other's integrals (finite
/// differences), and the covered distance is the roll's.
#[test]
fn the_time_law_slows_in_arcs_and_integrates_consistently() {
    let s = Scenario::load(&sunroof_path()).unwrap();
    let c = Contour::from_scenario(&s).unwrap();
    let (from, to) = (s.trajectory.z_start_mm * 1e-3, s.trajectory.z_end_mm * 1e-3);
    let (v_max, a_max, a_lat) = (0.08, 0.1, 0.05);
    let law = TimeLaw::new(&c, from, to, v_max, a_max, a_lat);
    let t_end = law.duration_s();
    assert_eq!(law.at(0.0), (0.0, 0.0, 0.0));
    assert!((law.at(t_end).0 - (to - from)).abs() < 1e-12);
    let dt = 1e-4;
    let mut corner_speed: f64 = 0.0;
    let mut k = 1;
    while (k as f64) * dt < t_end - dt {
        let t = k as f64 * dt;
        let (x, v, a) = law.at(t);
        assert!(v <= v_max + 1e-12 && a.abs() <= a_max + 1e-9, "t {t}: v {v} a {a}");
        let kappa = c.at(from + x).curvature_per_m.abs();
        if kappa > 0.0 {
            assert!(v * v * kappa <= a_lat * (1.0 + 1e-9), "t {t}: {v} m/s in an arc");
            corner_speed = corner_speed.max(v);
        }
        let (xp, vp, _) = law.at(t + dt);
        let (xm, vm, _) = law.at(t - dt);
        // Piecewise quadratic: the central difference is exact but where the acceleration
        // steps inside [t − dt, t + dt], off by at most |Δa| dt / 4 ≤ a_max dt / 2.
        assert!(((xp - xm) / (2.0 * dt) - v).abs() <= a_max * dt / 2.0 + 1e-12, "t {t}");
        if law.at(t - dt).2 == a && law.at(t + dt).2 == a {
            assert!(((vp - vm) / (2.0 * dt) - a).abs() < 1e-6, "t {t}");
        }
        k += 1;
    }
    // The corners are taken at sqrt(a_lat R) = 50 mm/s (to the sampling of the limit).
    assert!((corner_speed - (a_lat * 0.05f64).sqrt()).abs() < 1e-3, "{corner_speed}");
    eprintln!("sunroof roll: {t_end:.3} s for {:.1} mm", (to - from) * 1e3);
    // Lower bound: the whole distance at the cruise speed.
    assert!(t_end > (to - from) / v_max);
}

/// `sunroof.toml` with its pieces replaced by `contour.pieces_file = file` (written in `dir`).
fn sunroof_with_pieces_file(dir: &Path, file: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(sunroof_path()).unwrap();
    let start = text.find("pieces = [").unwrap();
    let end = start + text[start..].find("\n]\n").unwrap() + 3;
    let out = dir.join("sunroof_from_file.toml");
    std::fs::write(&out, format!("{}pieces_file = {file:?}\n{}", &text[..start], &text[end..])).unwrap();
    out
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("pieces-file-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The shipped file of segments is the sunroof's nine pieces: the scenario that names it loads
/// to the same scenario as the one that lists them, bit for bit.
#[test]
fn the_shipped_pieces_file_is_the_sunroofs_contour() {
    let dir = temp_dir("shipped");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("sunroof_pieces.txt");
    let from_file = Scenario::load(&sunroof_with_pieces_file(&dir, shipped.to_str().unwrap())).unwrap();
    let mut inline = Scenario::load(&sunroof_path()).unwrap();
    inline.contour.pieces_file = shipped.to_str().unwrap().to_string();
    assert_eq!(from_file, inline);
    std::fs::remove_dir_all(dir).unwrap();
}

/// A long contour from a file: the sunroof with its lines cut into 3 mm pieces and its corners
/// into 10° arcs (154 pieces, more than a scenario's substrate lists hold) is the same curve as
/// the nine-piece one: same length and the same points to a nanometre. Its self-contained copy
/// (as recordings and sweep cases carry it) loads without the file to the same scenario.
#[test]
fn a_long_pieces_file_is_the_same_curve_and_copies_inline() {
    let dir = temp_dir("long");
    let s9 = Scenario::load(&sunroof_path()).unwrap();
    let mut rows = String::from("# the sunroof, finely cut\n");
    let mut n = 0;
    for &[line, radius, turn] in &s9.contour.pieces {
        if line > 0.0 {
            let k = (line / 3.0).round() as usize;
            for _ in 0..k {
                rows += &format!("{}, 0, 0\n", line / k as f64);
            }
            n += k;
        } else {
            for _ in 0..9 {
                rows += &format!("0, {radius}, {}\n\n", turn / 9.0);
            }
            n += 9;
        }
    }
    assert!(n > scenarios::MAX_SUBSTRATE_FEATURES, "{n} pieces");
    std::fs::write(dir.join("fine.txt"), rows).unwrap();
    let path = sunroof_with_pieces_file(&dir, "fine.txt");
    let fine = Scenario::load(&path).unwrap();
    assert_eq!(fine.contour.pieces.len(), n);
    let (a, b) = (Contour::from_scenario(&s9).unwrap(), Contour::from_scenario(&fine).unwrap());
    assert!((a.length_m() - b.length_m()).abs() < 1e-9, "{} vs {}", a.length_m(), b.length_m());
    for k in 0..=1000 {
        let s_m = k as f64 * a.length_m() / 1000.0;
        let (p, q) = (a.at(s_m), b.at(s_m));
        let d = (p.xy_base_m[0] - q.xy_base_m[0]).hypot(p.xy_base_m[1] - q.xy_base_m[1]);
        assert!(d < 1e-9, "s = {s_m} m: {d} m apart");
        assert!((p.curvature_per_m - q.curvature_per_m).abs() < 1e-9 || (s_m - b.at(s_m).s_m).abs() < 1e-12);
    }
    let copy = scenarios::pieces_file::self_contained(&path).unwrap();
    assert!(!copy.lines().any(|l| l.starts_with("pieces_file")) && copy.contains("[contour]"), "{copy}");
    let elsewhere = temp_dir("elsewhere").join("scenario.toml");
    std::fs::write(&elsewhere, &copy).unwrap();
    let mut again = Scenario::load(&elsewhere).unwrap();
    again.contour.pieces_file = "fine.txt".into();
    assert_eq!(again, fine);
    // A file that names none is copied as written.
    assert_eq!(scenarios::pieces_file::self_contained(&sunroof_path()).unwrap(), std::fs::read_to_string(sunroof_path()).unwrap());
    std::fs::remove_dir_all(dir).unwrap();
    std::fs::remove_dir_all(elsewhere.parent().unwrap()).unwrap();
}

/// A bad row in a pieces file is refused naming the pieces file, its line and the column; a
/// scenario that gives both lists, or a file that is not there, is refused at the scenario's
/// `pieces_file` line.
#[test]
fn pieces_file_refusals_name_the_file_and_line() {
    let dir = temp_dir("bad");
    let shipped = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("sunroof_pieces.txt")).unwrap();
    // The second corner tighter than the wheel follows: file line 8 holds row 3.
    let tight = shipped.replacen("0, 50, 90\n", "0, 10, 90\n", 1);
    std::fs::write(dir.join("tight.txt"), &tight).unwrap();
    let e = Scenario::load(&sunroof_with_pieces_file(&dir, "tight.txt")).unwrap_err();
    assert_eq!(e.place(), Some(Place::Line(8)), "{e}");
    assert_eq!(e.field(), Some("contour.pieces[3] radius_mm"), "{e}");
    assert!(e.to_string().contains(&format!("{}", dir.join("tight.txt").display())), "{e}");
    assert!(e.to_string().contains("the wheel follows 20.0 mm or more"), "{e}");

    let p = sunroof_with_pieces_file(&dir, "missing.txt");
    let e = Scenario::load(&p).unwrap_err();
    let line = std::fs::read_to_string(&p).unwrap().lines().position(|l| l.starts_with("pieces_file")).unwrap() + 1;
    assert_eq!((e.place(), e.field()), (Some(Place::Line(line)), Some("contour.pieces_file")), "{e}");
    assert!(e.to_string().contains("must name a readable file of pieces"), "{e}");

    let both = std::fs::read_to_string(&p).unwrap().replace("\npieces_file = ", "\npieces = [[1226, 0, 0]]\npieces_file = ");
    std::fs::write(&p, both).unwrap();
    let e = Scenario::load(&p).unwrap_err();
    assert_eq!((e.place(), e.field()), (Some(Place::Line(line + 1)), Some("contour.pieces_file")), "{e}");
    assert!(e.to_string().contains("must be left out when contour.pieces is given"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}
