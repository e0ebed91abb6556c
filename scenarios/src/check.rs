//! Checks a scenario against the field table (`fields::FIELDS`) in two steps:
//! - `walk`: the file as written: unknown sections and fields, wrong types, whole numbers out of
//!   range, array lengths; it also notes the line of every field (and array element) it sets.
//! - `values`: the parsed scenario: finite numbers within their ranges, first every constant end
//!   of every range, then the ends that depend on other fields and the rules across fields, so
//!   that a message never quotes a limit computed from a bad value.
//!
//! Every error names the file, the line (or that the value is a default) and the field.

use std::collections::HashMap;
use std::path::Path;

use toml::de::{DeTable, DeValue};
use toml::Spanned;

use crate::fields::{self, fmt_num, fmt_value, lookup, Field, Kind, Range};
use crate::{Place, Scenario, ScenarioError, MAX_FORCE_POINTS};

/// Where each field (and array element, `key[i]`) a file sets stands: its line and the byte
/// range of its value.
#[derive(Debug, Default)]
pub(crate) struct Spans {
    at: HashMap<String, (usize, std::ops::Range<usize>)>,
}

impl Spans {
    /// The line of `name` (`loop.period_s`, `robot.armature_kgm2[2]`,
    /// `trajectory.force_ref_along_z[1] z_mm`): its own, else its array's, else a default.
    pub(crate) fn place(&self, name: &str) -> Place {
        let element = name.split(' ').next().unwrap_or(name);
        let array = name.split('[').next().unwrap_or(name);
        [name, element, array].iter().find_map(|k| self.at.get(*k)).map_or(Place::Default, |(line, _)| Place::Line(*line))
    }

    /// Makes `name` (a field the file does not set) be found on `other`'s line.
    pub(crate) fn alias(&mut self, name: &str, other: &str) {
        if let Some(&(line, _)) = self.at.get(other) {
            self.at.insert(name.to_string(), (line, 0..0));
        }
    }

    /// The innermost field or element whose value holds byte `pos` (the longest such key).
    pub(crate) fn field_at(&self, pos: usize) -> Option<(&str, usize)> {
        self.at.iter().filter(|(_, (_, r))| r.contains(&pos)).max_by_key(|(k, _)| k.len()).map(|(k, (line, _))| (k.as_str(), *line))
    }
}

/// 1-based line and column of byte `pos` of `text`.
pub(crate) fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let before = &text[..pos.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rfind('\n').map_or(before.chars().count() + 1, |i| before[i + 1..].chars().count() + 1);
    (line, column)
}

fn as_f64(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// The file's syntax error as a `Parse` error, naming the field whose line it is on when there
/// is one (found in the parser's best-effort reading of the rest of the file).
pub(crate) fn syntax_error(text: &str, path: &Path, e: &toml::de::Error) -> ScenarioError {
    let (line, column) = e.span().map_or((0, 0), |sp| line_col(text, sp.start));
    let mut message = e.message().trim().to_string();
    let (doc, _) = DeTable::parse_recoverable(text);
    if let Some(key) = key_on_line(text, doc.get_ref(), "", line) {
        message = format!("field {key}: {message}");
    } else if let Some(at) =
        e.span().and_then(|sp| text.get(sp)).map(str::trim).filter(|t| !t.is_empty() && t.len() <= 40 && !t.contains('\n'))
    {
        // what stands there (the key of "duplicate key"), when it is a short piece of one line
        message += &format!(": `{at}`");
    }
    ScenarioError::Parse { path: path.to_path_buf(), line, column, message }
}

/// The dotted key of the innermost entry of `table` whose key stands on `line`.
fn key_on_line(text: &str, table: &DeTable<'_>, prefix: &str, line: usize) -> Option<String> {
    table.iter().find_map(|(k, v)| {
        let key = if prefix.is_empty() { k.get_ref().to_string() } else { format!("{prefix}.{}", k.get_ref()) };
        let inner = v.get_ref().as_table().and_then(|t| key_on_line(text, t, &key, line));
        inner.or_else(|| (line_col(text, k.span().start).0 == line && !v.get_ref().is_table()).then_some(key))
    })
}

/// What the file wrote for a value, short enough for one message line.
fn shown(text: &str, v: &Spanned<DeValue<'_>>) -> String {
    if v.get_ref().is_table() {
        return "a table".into();
    }
    let s = text.get(v.span()).unwrap_or("?").split_whitespace().collect::<Vec<_>>().join(" ");
    if s.chars().count() > 60 {
        format!("{}…", s.chars().take(59).collect::<String>())
    } else {
        s
    }
}

fn is_number(v: &DeValue<'_>) -> bool {
    v.is_float() || v.is_integer()
}

/// "a string", "an integer", ...: the TOML type of a value for messages.
fn a_type(v: &DeValue<'_>) -> String {
    let t = v.type_str();
    let article = if t.starts_with(['a', 'e', 'i', 'o', 'u']) { "an" } else { "a" };
    format!("{article} {t}")
}

/// " s" after a range, or " (s)" after "must be a number" (`parens`): the field's unit.
fn unit_text(f: &Field, parens: bool) -> String {
    match (f.unit.is_empty(), parens) {
        (true, _) => String::new(),
        (false, false) => format!(" {}", f.unit),
        (false, true) => format!(" ({})", f.unit),
    }
}

/// Walks the file as written (see the module doc). Returns the lines of what it sets.
pub(crate) fn walk(text: &str, path: &Path) -> Result<Spans, ScenarioError> {
    let doc = DeTable::parse(text).map_err(|e| syntax_error(text, path, &e))?;
    let mut w = Walker { text, path, spans: Spans::default(), errors: Vec::new() };
    let sections = fields::sections();
    for (k, v) in doc.get_ref().iter() {
        let name: &str = k.get_ref();
        let line = line_col(text, k.span().start).0;
        if let Some(f) = fields::field(name).filter(|f| f.section().is_empty()) {
            w.value(f, name.to_string(), line, v);
        } else if !name.is_empty() && sections.contains(&name) {
            match v.get_ref().as_table() {
                Some(t) => {
                    for (fk, fv) in t.iter() {
                        let key = format!("{name}.{}", fk.get_ref());
                        let line = line_col(text, fk.span().start).0;
                        match fields::field(&key) {
                            Some(f) => w.value(f, key, line, fv),
                            None => w.errors.push(ScenarioError::Unknown {
                                path: path.to_path_buf(),
                                line,
                                what: "field",
                                key,
                                known: format!("[{name}] has {}", fields::names_in(name).join(", ")),
                            }),
                        }
                    }
                }
                None => w.bad(name.to_string(), line, v, format!("must be a section, [{name}]")),
            }
        } else {
            let known = sections.iter().filter(|s| !s.is_empty()).map(|s| format!("[{s}]")).collect::<Vec<_>>().join(", ");
            let top = fields::names_in("").join(", ");
            w.errors.push(ScenarioError::Unknown {
                path: path.to_path_buf(),
                line,
                what: if v.get_ref().is_table() { "section" } else { "field" },
                key: name.to_string(),
                known: format!("the sections are {known}, the top-level fields {top}"),
            });
        }
    }
    // The first in the file is reported (the table iterates in key order, not file order).
    match w.errors.into_iter().min_by_key(|e| match e.place() {
        Some(Place::Line(l)) => l,
        _ => usize::MAX,
    }) {
        Some(e) => Err(e),
        None => Ok(w.spans),
    }
}

struct Walker<'t> {
    text: &'t str,
    path: &'t Path,
    spans: Spans,
    errors: Vec<ScenarioError>,
}

impl Walker<'_> {
    fn bad(&mut self, field: String, line: usize, v: &Spanned<DeValue<'_>>, why: String) {
        let value = shown(self.text, v);
        self.errors.push(ScenarioError::Field { path: self.path.to_path_buf(), place: Place::Line(line), field, value, why });
    }

    fn note(&mut self, key: &str, line: usize, v: &Spanned<DeValue<'_>>) {
        self.spans.at.insert(key.to_string(), (line, v.span()));
    }

    /// Type (and, for whole numbers, range) of one field's value.
    fn value(&mut self, f: &Field, key: String, line: usize, v: &Spanned<DeValue<'_>>) {
        self.note(&key, line, v);
        let val = v.get_ref();
        match f.kind {
            Kind::Float if !is_number(val) => {
                self.bad(key, line, v, format!("must be a number{}, not {}", unit_text(f, true), a_type(val)))
            }
            Kind::Int => match val.as_integer() {
                None => self.bad(key, line, v, format!("must be a whole number{}, not {}", unit_text(f, true), a_type(val))),
                Some(i) => {
                    // as i128 so that a negative or huge count is named as out of range, not as a
                    // serde overflow
                    let n = i128::from_str_radix(i.as_str(), i.radix()).map_or(f64::INFINITY, |n| n as f64);
                    if !f.range.contains(n, None) {
                        self.bad(key, line, v, format!("must be in {}{}", f.range.text(), unit_text(f, false)));
                    }
                }
            },
            Kind::Bool if val.as_bool().is_none() => self.bad(key, line, v, format!("must be true or false, not {}", a_type(val))),
            Kind::Text if !val.is_str() => self.bad(key, line, v, format!("must be a string, not {}", a_type(val))),
            Kind::Choice(names) if !val.as_str().is_some_and(|s| names.contains(&s)) => {
                self.bad(key, line, v, format!("must be one of {}", names.iter().map(|n| format!("{n:?}")).collect::<Vec<_>>().join(", ")))
            }
            Kind::Floats(n) => match val.as_array() {
                Some(a) if a.len() == n => {
                    for (i, e) in a.iter().enumerate() {
                        let ek = format!("{key}[{i}]");
                        let el = line_col(self.text, e.span().start).0;
                        self.note(&ek, el, e);
                        if !is_number(e.get_ref()) {
                            self.bad(ek, el, e, format!("must be a number{}, not {}", unit_text(f, true), a_type(e.get_ref())));
                        }
                    }
                }
                Some(a) => self.bad(key, line, v, format!("must be an array of {n} numbers, not {}", a.len())),
                None => self.bad(key, line, v, format!("must be an array of {n} numbers, not {}", a_type(val))),
            },
            Kind::Points { .. } => match val.as_array() {
                Some(a) if a.len() > MAX_FORCE_POINTS => {
                    self.bad(key, line, v, format!("must have at most {MAX_FORCE_POINTS} points, not {}", a.len()))
                }
                Some(a) => {
                    for (i, e) in a.iter().enumerate() {
                        let ek = format!("{key}[{i}]");
                        let el = line_col(self.text, e.span().start).0;
                        self.note(&ek, el, e);
                        let pair = e.get_ref().as_array().is_some_and(|p| p.len() == 2 && p.iter().all(|x| is_number(x.get_ref())));
                        if !pair {
                            self.bad(ek, el, e, "must be a pair of numbers [z_mm, force_n]".into());
                        }
                    }
                }
                None => self.bad(key, line, v, format!("must be an array of [z_mm, force_n] pairs, not {}", a_type(val))),
            },
            Kind::Rows { max_rows, cols, .. } => {
                let shape = format!("[{}]", cols.join(", "));
                match val.as_array() {
                    Some(a) if a.len() > max_rows => self.bad(key, line, v, format!("must have at most {max_rows} rows, not {}", a.len())),
                    Some(a) => {
                        for (i, e) in a.iter().enumerate() {
                            let ek = format!("{key}[{i}]");
                            let el = line_col(self.text, e.span().start).0;
                            self.note(&ek, el, e);
                            let row =
                                e.get_ref().as_array().is_some_and(|p| p.len() == cols.len() && p.iter().all(|x| is_number(x.get_ref())));
                            if !row {
                                self.bad(ek, el, e, format!("must be a row of {} numbers {shape}", cols.len()));
                            }
                        }
                    }
                    None => self.bad(key, line, v, format!("must be an array of {shape} rows, not {}", a_type(val))),
                }
            }
            _ => {}
        }
    }
}

/// Which ends of the ranges a pass checks.
#[derive(Clone, Copy, PartialEq)]
enum Pass {
    /// Finite numbers and the constant ends.
    Constant,
    /// The ends that depend on other fields, and the rules.
    Relative,
}

/// Checks every value of a parsed scenario (see the module doc); `spans` gives the lines of a
/// file's values, None for a scenario that comes from no file text.
pub(crate) fn values(s: &Scenario, path: &Path, spans: Option<&Spans>) -> Result<(), ScenarioError> {
    // Only a count beyond i64 (set in code: files are bounded by the walk) fails to serialise.
    let doc = toml::Table::try_from(s).map_err(|e| ScenarioError::Field {
        path: path.to_path_buf(),
        place: Place::Unstated,
        field: "(a whole number)".into(),
        value: "?".into(),
        why: e.to_string(),
    })?;
    let number = |k: &str| lookup(&doc, k).and_then(as_f64).unwrap_or(f64::NAN);
    let bad = |field: String, value: String, why: String| ScenarioError::Field {
        path: path.to_path_buf(),
        place: spans.map_or(Place::Unstated, |sp| sp.place(&field)),
        field,
        value,
        why,
    };
    let in_range = |name: String, x: f64, range: &Range, unit: &str, pass: Pass| -> Result<(), ScenarioError> {
        let ok = match pass {
            Pass::Constant => range.contains(x, None),
            Pass::Relative => !range.is_relative() || range.contains(x, Some(&number)),
        };
        if ok {
            return Ok(());
        }
        let finite = if x.is_finite() { "" } else { "a finite number " };
        let now = if pass == Pass::Relative { format!(" = {}", range.resolved_text(&number)) } else { String::new() };
        Err(bad(name, fmt_num(x), format!("must be {finite}in {}{now}{unit}", range.text())))
    };
    let check = |f: &Field, pass: Pass| -> Result<(), ScenarioError> {
        let unit = unit_text(f, false);
        let v = lookup(&doc, f.key);
        match f.kind {
            Kind::Float | Kind::Int => in_range(f.key.into(), v.and_then(as_f64).unwrap_or(f64::NAN), &f.range, &unit, pass)?,
            Kind::Floats(_) => {
                for (i, x) in v.and_then(|v| v.as_array()).into_iter().flatten().enumerate() {
                    in_range(format!("{}[{i}]", f.key), as_f64(x).unwrap_or(f64::NAN), &f.range, &unit, pass)?;
                }
            }
            Kind::Points { z, force } => {
                let points = v.and_then(|v| v.as_array()).map_or(&[][..], |a| a.as_slice());
                if points.len() > MAX_FORCE_POINTS {
                    return Err(bad(
                        f.key.into(),
                        format!("{} points", points.len()),
                        format!("must have at most {MAX_FORCE_POINTS} points"),
                    ));
                }
                let mut previous_z = f64::NEG_INFINITY;
                for (i, p) in points.iter().enumerate() {
                    let pair: Vec<f64> = p.as_array().into_iter().flatten().map(|x| as_f64(x).unwrap_or(f64::NAN)).collect();
                    let (z_mm, force_n) = (pair.first().copied().unwrap_or(f64::NAN), pair.get(1).copied().unwrap_or(f64::NAN));
                    in_range(format!("{}[{i}] z_mm", f.key), z_mm, &z, " mm", pass)?;
                    if pass == Pass::Constant && z_mm.partial_cmp(&previous_z) != Some(std::cmp::Ordering::Greater) {
                        return Err(bad(
                            format!("{}[{i}] z_mm", f.key),
                            fmt_num(z_mm),
                            format!("must be strictly ascending (point {} has z_mm = {})", i - 1, fmt_num(previous_z)),
                        ));
                    }
                    previous_z = z_mm;
                    in_range(format!("{}[{i}] force_n", f.key), force_n, &force, " N", pass)?;
                }
            }
            Kind::Rows { max_rows, cols, ranges, rows } => {
                let all = v.and_then(|v| v.as_array()).map_or(&[][..], |a| a.as_slice());
                if all.len() > max_rows {
                    return Err(bad(f.key.into(), format!("{} rows", all.len()), format!("must have at most {max_rows} rows")));
                }
                for (i, r) in all.iter().enumerate() {
                    let vals: Vec<f64> = r.as_array().into_iter().flatten().map(|x| as_f64(x).unwrap_or(f64::NAN)).collect();
                    for (c, (col, range)) in cols.iter().zip(ranges.iter()).enumerate() {
                        in_range(format!("{}[{i}] {col}", f.key), vals.get(c).copied().unwrap_or(f64::NAN), range, &unit, pass)?;
                    }
                }
                if pass == Pass::Relative {
                    if let Err(e) = (rows.check)(s) {
                        let value = if e.value.is_nan() { format!("{} rows", all.len()) } else { fmt_num(e.value) };
                        let name = if e.value.is_nan() { f.key.to_string() } else { format!("{}[{}] {}", f.key, e.row, cols[e.col]) };
                        return Err(bad(name, value, e.why));
                    }
                }
            }
            Kind::Choice(names) => {
                let s = v.and_then(|v| v.as_str()).unwrap_or("");
                if pass == Pass::Constant && !names.contains(&s) {
                    let one_of = names.iter().map(|n| format!("{n:?}")).collect::<Vec<_>>().join(", ");
                    return Err(bad(f.key.into(), format!("{s:?}"), format!("must be one of {one_of}")));
                }
            }
            Kind::Bool | Kind::Text => {}
        }
        if let (Pass::Relative, Some(rule)) = (pass, f.rule) {
            if let Err(instead) = (rule.check)(s) {
                return Err(bad(f.key.into(), v.map_or_else(|| "?".into(), fmt_value), format!("must be {} ({instead})", rule.text)));
            }
        }
        Ok(())
    };
    for pass in [Pass::Constant, Pass::Relative] {
        let mut errors: Vec<ScenarioError> = fields::FIELDS.iter().filter_map(|f| check(f, pass).err()).collect();
        // Where two fields disagree (z_start_mm and z_end_mm), blame the one the file sets
        // rather than a default.
        if let Some(i) = errors.iter().position(|e| matches!(e.place(), Some(Place::Line(_)))).or((!errors.is_empty()).then_some(0)) {
            return Err(errors.swap_remove(i));
        }
    }
    Ok(())
}
