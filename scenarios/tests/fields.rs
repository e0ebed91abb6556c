//! The field table against the scenario type, the validation and the README: every field is in
//! the table, every field refuses bad values with a message naming file, line and field, the
//! ranges end where the table says, and `scenarios/README.md` prints the table as it is.
//!
//! `UPDATE_README=1 cargo test -p scenarios --test fields` rewrites the README's field table.

use std::collections::BTreeSet;
use std::path::Path;

use scenarios::fields::{self, Field, Kind, Limit, Range, FIELDS};
use scenarios::{Place, Scenario, ScenarioError, MAX_FORCE_POINTS};

const FILE: &str = "walk/bad.toml";

fn load(text: &str) -> Result<Scenario, ScenarioError> {
    Scenario::from_toml_str(text, Path::new(FILE))
}

/// The default scenario's value of a numeric field (what a file that sets only one field has).
fn default_number(key: &str) -> f64 {
    let doc = toml::Table::try_from(Scenario::default()).unwrap();
    let (section, name) = key.split_once('.').unwrap();
    let v = &doc[section][name];
    v.as_float().or(v.as_integer().map(|i| i as f64)).unwrap_or_else(|| panic!("{key} is not a number"))
}

fn limit(l: Limit) -> f64 {
    match l {
        Limit::Num(x) => x,
        Limit::Times(f, k) => f * default_number(k),
        Limit::Over(f, k) => f / default_number(k),
    }
}

/// A TOML number that reads back as exactly `x`.
fn toml_num(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else {
        format!("{x:?}")
    }
}

/// Just outside and just inside each end of a range (with the defaults of the fields it
/// depends on): (outside, inside) pairs.
fn around_ends(r: &Range, whole: bool) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let step = |b: f64| if whole { 1.0 } else { b.abs() * 1e-9 + 1e-12 };
    if let Some(e) = r.lo {
        let b = limit(e.limit);
        out.push(if e.inclusive { (b - step(b), b) } else { (b, b + step(b)) });
    }
    if let Some(e) = r.hi {
        let b = limit(e.limit);
        out.push(if e.inclusive { (b + step(b), b) } else { (b, b - step(b)) });
    }
    out
}

/// One file that sets `f` to `value`; the line `f`'s key stands on.
fn file_setting(f: &Field, value: &str) -> (String, usize) {
    if f.section().is_empty() {
        (format!("# field walk: {}\n\n{} = {value}\n", f.key, f.name()), 3)
    } else {
        (format!("# field walk: {}\ndescription = \"walk\"\n\n[{}]\n{} = {value}\n", f.key, f.section(), f.name()), 5)
    }
}

/// Bad values of one field: (TOML value, the field the message must name, the line offset of
/// the bad element from the key's line).
fn bad_values(f: &Field) -> Vec<(String, String, usize)> {
    let key = f.key.to_string();
    let plain = |v: &str| (v.to_string(), key.clone(), 0);
    let mut out = Vec::new();
    match f.kind {
        Kind::Float => {
            out.extend(["nan", "inf", "-inf", "\"x\"", "true", "[1]", "{ a = 1 }"].map(plain));
            out.extend(around_ends(&f.range, false).into_iter().map(|(bad, _)| plain(&toml_num(bad))));
        }
        Kind::Int => {
            out.extend(["1.5", "nan", "\"x\"", "true", "-1", "99999999999999999999"].map(plain));
            out.extend(around_ends(&f.range, true).into_iter().map(|(bad, _)| plain(&format!("{}", bad as i128))));
        }
        Kind::Bool => out.extend(["1", "\"yes\"", "nan"].map(plain)),
        Kind::Text => out.extend(["3", "true", "[\"a\"]"].map(plain)),
        Kind::Choice(_) => out.extend(["\"nope\"", "3", "true"].map(plain)),
        Kind::Floats(n) => {
            out.extend(["\"x\"", "1", "[0, 0]"].map(plain));
            out.push((format!("[{}]", vec!["0"; n + 1].join(", ")), key.clone(), 0));
            // the other elements at a valid value (0 where the range has it); indices wrap for
            // arrays shorter than six
            let fill = if f.range.contains(0.0, None) { "0" } else { "1" };
            let with = |i: usize, x: &str| {
                let i = i % n;
                let mut v = vec![fill.to_string(); n];
                v[i] = x.into();
                (format!("[{}]", v.join(", ")), format!("{key}[{i}]"), 0)
            };
            out.extend([with(2, "nan"), with(5, "inf"), with(0, "-inf"), with(3, "\"x\""), with(1, "true")]);
            for (bad, _) in around_ends(&f.range, false) {
                out.push(with(4, &toml_num(bad)));
            }
        }
        Kind::Points { z, force } => {
            out.extend(["3", "\"x\""].map(plain));
            out.push(("[1, 2]".into(), format!("{key}[0]"), 0));
            let many: Vec<String> = (0..=MAX_FORCE_POINTS).map(|i| format!("[{i}, -10]")).collect();
            out.push((format!("[{}]", many.join(", ")), key.clone(), 0));
            // the bad point on a line of its own, two lines below the key
            let second = |p: &str, which: &str| {
                let name = if which.is_empty() { format!("{key}[1]") } else { format!("{key}[1] {which}") };
                (format!("[\n  [2, -10],\n  {p},\n]"), name, 2)
            };
            out.extend([second("[4, nan]", "force_n"), second("[nan, -10]", "z_mm"), second("[4, inf]", "force_n")]);
            out.extend([second("[2, -10]", "z_mm"), second("[1, -10]", "z_mm")]);
            out.extend([second("\"x\"", ""), second("[4]", ""), second("[4, -10, 1]", ""), second("[4, \"x\"]", "")]);
            for (bad, _) in around_ends(&z, false) {
                // alone, on the line below the key
                out.push((format!("[\n  [{}, -10],\n]", toml_num(bad)), format!("{key}[0] z_mm"), 1));
            }
            for (bad, _) in around_ends(&force, false) {
                out.push(second(&format!("[4, {}]", toml_num(bad)), "force_n"));
            }
        }
        Kind::Rows { cols, ranges, .. } => {
            out.extend(["3", "\"x\""].map(plain));
            out.push(("[1, 2]".into(), format!("{key}[0]"), 0));
            // a valid first row, the bad one on a line of its own two lines below the key
            let second = |row: &str, which: &str| {
                let name = if which.is_empty() { format!("{key}[1]") } else { format!("{key}[1] {which}") };
                (format!("[\n  [1, 1, 1],\n  {row},\n]"), name, 2)
            };
            out.extend([second("\"x\"", ""), second("[4]", ""), second("[1, 1, 1, 1]", ""), second("[1, \"x\", 1]", "")]);
            for (c, col) in cols.iter().enumerate() {
                for bad in ["nan", "inf"] {
                    let mut row = vec!["1"; cols.len()];
                    row[c] = bad;
                    out.push(second(&format!("[{}]", row.join(", ")), col));
                }
                for (bad, _) in around_ends(&ranges[c], false) {
                    let mut row = vec!["1".to_string(); cols.len()];
                    row[c] = toml_num(bad);
                    out.push(second(&format!("[{}]", row.join(", ")), col));
                }
            }
        }
    }
    out
}

#[test]
fn the_table_lists_every_field_of_the_scenario_once() {
    let doc = toml::Table::try_from(Scenario::default()).unwrap();
    let mut keys = BTreeSet::new();
    for (k, v) in &doc {
        match v.as_table() {
            Some(t) => keys.extend(t.keys().map(|n| format!("{k}.{n}"))),
            None => {
                keys.insert(k.clone());
            }
        }
    }
    let table: Vec<&str> = FIELDS.iter().map(|f| f.key).collect();
    let unique: BTreeSet<String> = table.iter().map(|k| k.to_string()).collect();
    assert_eq!(unique.len(), table.len(), "a field is listed twice");
    assert_eq!(unique, keys, "the table and the Scenario type list different fields");
    // every limit that depends on another field names a numeric field
    for f in FIELDS {
        let ranges: Vec<Range> = match f.kind {
            Kind::Points { z, force } => vec![z, force],
            Kind::Rows { ranges, .. } => ranges.to_vec(),
            _ => vec![f.range],
        };
        for r in ranges {
            for e in [r.lo, r.hi].into_iter().flatten() {
                if let Some(k) = e.limit.depends_on() {
                    let d = fields::field(k).unwrap_or_else(|| panic!("{}: limit names unknown field {k}", f.key));
                    assert!(matches!(d.kind, Kind::Float | Kind::Int), "{}: limit names {k}, not a number", f.key);
                }
            }
        }
    }
}

#[test]
fn the_defaults_are_valid_and_an_empty_file_gets_them() {
    Scenario::default().validate(Path::new("(defaults)")).unwrap();
    assert_eq!(load("").unwrap(), Scenario::default());
}

#[test]
fn a_scenario_written_out_in_full_loads_back() {
    // sweeps and `--set` write whole tables; every shipped scenario survives that round trip
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    for name in ["default.toml", "thesis.toml", "bond.toml", "bond_scheduled.toml", "cell.toml"] {
        let s = Scenario::load(&dir.join(name)).unwrap();
        let text = toml::to_string(&s).unwrap();
        assert_eq!(load(&text).unwrap_or_else(|e| panic!("{name}: {e}")), s, "{name}");
    }
}

#[test]
fn every_field_refuses_bad_values_naming_file_line_and_field() {
    let mut checked = 0;
    for f in FIELDS {
        let bad = bad_values(f);
        assert!(bad.len() >= 3, "{}: too few bad values", f.key);
        for (value, named, offset) in bad {
            let (text, line) = file_setting(f, &value);
            let e = match load(&text) {
                Ok(_) => panic!("{} = {value} was accepted", f.key),
                Err(e) => e,
            };
            let msg = e.to_string();
            let line = line + offset;
            assert!(msg.starts_with(&format!("scenario file {FILE}, line {line}")), "{} = {value}: wrong file or line: {msg}", f.key);
            assert!(
                msg.contains(&format!("field {named}: ")) || msg.contains(&format!("field {named} = ")),
                "{} = {value}: field {named} not named: {msg}",
                f.key
            );
            assert_eq!(e.field(), Some(named.as_str()), "{msg}");
            assert_eq!(e.place(), Some(Place::Line(line)), "{msg}");
            assert!(msg.contains(": must "), "{} = {value}: no reason given: {msg}", f.key);
            checked += 1;
        }
    }
    assert!(checked > 5 * FIELDS.len(), "{checked} bad values for {} fields", FIELDS.len());
}

#[test]
fn ranges_end_where_the_table_says() {
    for f in FIELDS {
        let ends = match f.kind {
            Kind::Float => around_ends(&f.range, false),
            Kind::Int => around_ends(&f.range, true),
            _ => continue,
        };
        for (outside, inside) in ends {
            let value = |x: f64| if matches!(f.kind, Kind::Int) { format!("{}", x as i128) } else { toml_num(x) };
            let (text, line) = file_setting(f, &value(outside));
            let e = load(&text).expect_err(&text).to_string();
            assert!(e.contains(&format!("line {line}: field {} = ", f.key)) && e.contains(&f.range.text()), "{}: {e}", f.key);
            // just inside, the range accepts it (another field, or this field's rule, may not)
            let (text, _) = file_setting(f, &value(inside));
            if let Err(e) = load(&text) {
                let why_rule = f.rule.is_some_and(|r| e.to_string().contains(r.text));
                assert!(e.field() != Some(f.key) || why_rule, "{} = {}: refused inside its range: {e}", f.key, value(inside));
            }
        }
    }
}

#[test]
fn a_default_that_another_field_makes_invalid_is_named_as_the_default() {
    // a 0.4 ms period leaves the default 500 µs torque budget longer than the period
    let e = load("[loop]\nperiod_s = 0.0004\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, default value (not set in the file): field loop.torque_budget_us = 500: must be in (0, 1e6 loop.period_s) = (0, 400) µs");
    // a 5 N contact force limit leaves the default -10 N set-point beyond it
    let e = load("[safety]\nmax_contact_force_n = 5\n").unwrap_err().to_string();
    assert!(e.contains("default value") && e.contains("field trajectory.force_ref_n = -10") && e.contains("(-5, 0) N"), "{e}");
}

#[test]
fn the_findings_of_issue_12_are_refused() {
    let e = load("[trajectory]\n\nforce_ref_n = nan\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, line 3: field trajectory.force_ref_n = NaN: must be a finite number in (-safety.max_contact_force_n, 0) N");
    // higher than the strip (8 mm at its centre)
    let e = load("[bulge]\nheight_mm = 100\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, line 2: field bulge.height_mm = 100: must be in (-8, 8) mm");
    assert!(load("[bulge]\nheight_mm = 8\n").is_err() && load("[bulge]\nheight_mm = 7.9\n").is_ok());
    // a type error names the field too
    let e = load("[trajectory]\nroll_s = \"fast\"\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, line 2: field trajectory.roll_s = \"fast\": must be a number (s), not a string");
    // beyond the contact force reflex, at the reflex, inside it
    for (f, ok) in [(-41.0, false), (-40.0, false), (-39.0, true)] {
        assert_eq!(load(&format!("[trajectory]\nforce_ref_n = {f:?}\n")).is_ok(), ok, "{f}");
    }
    let e = load("[loop]\nperiod_s = -1\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, line 2: field loop.period_s = -1: must be in (0, 0.1] s");
}

#[test]
fn rules_across_fields_are_checked_and_named() {
    for (text, field, line) in [
        // 36 mm in 0.1 s: 720 mm/s peak, over the 250 mm/s TCP speed reflex
        ("[trajectory]\nroll_s = 0.1\n", "trajectory.roll_s", 2),
        // 3 mm in 10 ms: 471 mm/s peak
        ("[trajectory]\nlift_s = 0.01\n", "trajectory.lift_s", 2),
        ("[strip]\ndamping_alpha = 0\ndamping_beta = 0\n", "strip.damping_beta", 3),
        ("[loop]\nduration_s = 0.0001\n", "loop.duration_s", 2),
        // the strip shorter than where the roll ends: z_end_mm (a default) is named
        ("[strip]\nlength_mm = 20\n", "trajectory.z_end_mm", 0),
        ("[trajectory]\nz_start_mm = 38\n", "trajectory.z_start_mm", 2),
    ] {
        let e = load(text).unwrap_err();
        assert_eq!(e.field(), Some(field), "{text}: {e}");
        let place = if line == 0 { Place::Default } else { Place::Line(line) };
        assert_eq!(e.place(), Some(place), "{text}: {e}");
    }
    let e = load("[trajectory]\nroll_s = 0.1\n").unwrap_err().to_string();
    assert!(e.ends_with("(mm/s) (the roll peaks at 720 mm/s, the limit is 250 mm/s)"), "{e}");
    assert!(load("[trajectory]\nroll_s = 0.1\n[safety]\nmax_tcp_speed_mps = 1\n").is_ok());
    assert!(load("[strip]\ndamping_alpha = 0\n").is_ok());
    assert!(load("[loop]\nduration_s = 0.001\n").is_ok());
}

#[test]
fn unknown_sections_and_fields_say_what_there_is() {
    let e = load("[loop]\nperiod_s = 0.001\nbudget_typo = 3\n").unwrap_err().to_string();
    assert!(
        e.starts_with("scenario file walk/bad.toml, line 3: unknown field loop.budget_typo; [loop] has mode, period_s, torque_budget_us"),
        "{e}"
    );
    let e = load("description = \"x\"\n[loops]\nperiod_s = 1\n").unwrap_err().to_string();
    assert!(e.starts_with("scenario file walk/bad.toml, line 2: unknown section loops; the sections are [loop],"), "{e}");
    let e = load("loop = 3\n").unwrap_err().to_string();
    assert_eq!(e, "scenario file walk/bad.toml, line 1: field loop = 3: must be a section, [loop]");
    // several errors: the first in the file is reported
    let e = load("[trajectory]\nroll_s = \"a\"\n[bulge]\nheight_mm = \"b\"\n").unwrap_err();
    assert_eq!(e.field(), Some("trajectory.roll_s"), "{e}");
}

#[test]
fn syntax_errors_name_the_line_and_the_field_they_are_in() {
    let e = load("[loop]\nmode = \"lockstep\"\nperiod_s = \n").unwrap_err().to_string();
    assert!(e.starts_with("scenario file walk/bad.toml, line 3, column 12: field loop.period_s: "), "{e}");
    let e = load("[trajectory]\nroll_s = fast\n").unwrap_err().to_string();
    assert!(e.starts_with("scenario file walk/bad.toml, line 2, column 10: field trajectory.roll_s: "), "{e}");
}

#[test]
fn a_scenario_built_in_code_is_checked_without_lines() {
    let mut s = Scenario::default();
    s.robot.armature_kgm2[3] = f64::NAN;
    let e = s.validate(Path::new("built.toml")).unwrap_err().to_string();
    assert_eq!(e, "scenario file built.toml: field robot.armature_kgm2[3] = NaN: must be a finite number in [0, ∞) kg m²");
    // (A closed choice such as strip.boundary is an enum: code cannot build a value outside it.)
}

#[test]
fn a_missing_file_names_the_file_and_leaves_the_os_error_to_the_chain() {
    let e = Scenario::load(Path::new("/nonexistent/scenario.toml")).unwrap_err();
    assert_eq!(e.to_string(), "cannot read scenario file /nonexistent/scenario.toml");
    let cause = std::error::Error::source(&e).expect("the OS error is the source").to_string();
    assert!(cause.contains("os error 2"), "{cause}");
}

const BEGIN: &str = "<!-- fields: generated from scenarios/src/fields.rs; UPDATE_README=1 cargo test -p scenarios --test fields -->\n";
const END: &str = "<!-- end of fields -->\n";

#[test]
fn the_readme_lists_every_field_as_the_table_says() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md");
    let readme = std::fs::read_to_string(&path).unwrap();
    let (start, end) = match (readme.find(BEGIN), readme.find(END)) {
        (Some(s), Some(e)) if s < e => (s + BEGIN.len(), e),
        _ => panic!("{} lacks the markers {BEGIN:?} ... {END:?}", path.display()),
    };
    let table = fields::markdown_table();
    for row in table.lines() {
        // a '|' in a meaning or range would split its cell
        assert_eq!(row.matches('|').count(), 7, "not six cells: {row}");
    }
    assert_eq!(table.lines().count(), 2 + FIELDS.len());
    if std::env::var_os("UPDATE_README").is_some() {
        std::fs::write(&path, format!("{}{table}{}", &readme[..start], &readme[end..])).unwrap();
        return;
    }
    let current = &readme[start..end];
    if current != table {
        let diff: Vec<String> = table
            .lines()
            .zip(current.lines().chain(std::iter::repeat("")))
            .filter(|(want, have)| want != have)
            .map(|(want, have)| format!("- {have}\n+ {want}"))
            .collect();
        panic!(
            "scenarios/README.md's field table is stale ({} lines differ, or the length); regenerate it with UPDATE_README=1 cargo test -p scenarios --test fields\n{}",
            diff.len(),
            diff.join("\n")
        );
    }
}
