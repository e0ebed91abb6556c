//! `rig model curvature` as a user runs it (issue 26 item 3): the curved FE strip against the
//! straight one in statics. The README states its figures; this holds them to the command's
//! output, and holds the output to the physics the README draws from it.

use std::process::Command;

use harness::*;

/// The number after `key` in `text`, up to the first character that cannot be in it.
fn number_after(text: &str, key: &str) -> f64 {
    let rest = text.split(key).nth(1).unwrap_or_else(|| panic!("{key:?} not in:\n{text}"));
    let n: String = rest.trim_start().chars().take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+')).collect();
    n.parse().unwrap_or_else(|e| panic!("{key:?} followed by {n:?}: {e}"))
}

#[test]
fn the_bend_at_the_sunroof_corner_moves_the_centre_line_by_what_the_readme_says() {
    let out = Command::new(bin("rig")).args(["model", "curvature", "--radius-mm", "50"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let centre = number_after(&text, "centre line under the wheel");
    let edge = number_after(&text, "section maximum");
    // The loop neglects the curvature: on the centre line the bond figures read, that must cost
    // well under a percent; the bend shows at the edges (inside of the bend, shorter and stiffer).
    assert!(centre.abs() < 1.0, "{text}");
    assert!(edge > 1.0, "{text}");
    // Every row's two centre-line columns and its percentage agree (the table is the figures).
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter_map(|l| l.split_whitespace().map(str::parse::<f64>).collect::<Result<Vec<_>, _>>().ok())
        .filter(|r| r.len() == 7)
        .collect();
    assert_eq!(rows.len(), 33, "z = 4..36 mm every 1 mm:\n{text}");
    for r in &rows {
        assert!((100.0 * (r[2] - r[1]) / r[1] - r[3]).abs() < 0.02, "{r:?}");
    }
    // The README's figures are the command's.
    let readme = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md")).unwrap();
    let stated_centre = number_after(&readme, "the centre line's pressure under the wheel changes by at most");
    let stated_edge = number_after(&readme, "the\nsection's largest bottom pressure (at the strip's edges) by up to");
    assert_eq!(format!("{stated_centre:+.2}"), format!("{centre:+.2}"), "README vs {text}");
    assert_eq!(format!("{stated_edge:+.1}"), format!("{edge:+.1}"), "README vs {text}");
}

#[test]
fn a_bend_tighter_than_the_strip_is_refused_in_one_sentence() {
    let out = Command::new(bin("rig")).args(["model", "curvature", "--radius-mm", "3"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--radius-mm 3: give a radius larger than the strip's half width (4 mm)"), "{err}");
}
