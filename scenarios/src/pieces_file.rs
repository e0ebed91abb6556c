//! `contour.pieces_file`: a contour's pieces from a text file of segments (issue 26), for
//! contours too long to list in the scenario. One piece per line, `line_mm, radius_mm, turn_deg`
//! as in `contour.pieces` (commas or blanks between the three numbers); `#` starts a comment,
//! blank lines are skipped. The path is relative to the scenario file's directory.
//!
//! Loading puts the file's rows into `contour.pieces` and checks them like rows written in the
//! scenario; a refusal names the pieces file and its line. Copies of a scenario that leave its
//! directory (a recording's metadata, a sweep's or study's case) carry the pieces inline
//! (`self_contained`), so a recording replays without the file.

use crate::{Place, ScenarioError, MAX_CONTOUR_PIECES};
use std::path::{Path, PathBuf};

/// The column names of a row, as `contour.pieces` names them.
const COLS: [&str; 3] = ["line_mm", "radius_mm", "turn_deg"];

/// A read pieces file: where it is, its rows and each row's line (1-based).
#[derive(Debug, Clone, PartialEq)]
pub struct PiecesFile {
    pub path: PathBuf,
    pub rows: Vec<[f64; 3]>,
    pub lines: Vec<usize>,
}

impl PiecesFile {
    /// A refusal of `contour.pieces[i] ...` (the scenario's check of the rows), moved to the
    /// pieces file's line of row i; other errors unchanged.
    pub fn relocate(&self, e: ScenarioError) -> ScenarioError {
        let ScenarioError::Field { field, value, why, .. } = &e else {
            return e;
        };
        let row = field.strip_prefix("contour.pieces[").and_then(|r| r.split(']').next()).and_then(|i| i.parse::<usize>().ok());
        match row.and_then(|i| self.lines.get(i)) {
            Some(&line) => refused(&self.path, line, field.clone(), value, why.clone()),
            None => e,
        }
    }
}

/// `name` (as the scenario gives it) from the directory of `scenario_path`.
pub fn resolve(scenario_path: &Path, name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.is_absolute() {
        return p.to_path_buf();
    }
    scenario_path.parent().map_or_else(|| p.to_path_buf(), |d| d.join(p))
}

fn refused(path: &Path, line: usize, field: String, value: &str, why: String) -> ScenarioError {
    ScenarioError::Field { path: path.to_path_buf(), place: Place::Line(line), field, value: value.to_string(), why }
}

/// Reads and parses the pieces file at `path`. Each row must hold three finite numbers; what the
/// rows must be as a contour is checked by `contour.pieces`' rule once they are in the scenario.
pub fn read(path: &Path) -> Result<PiecesFile, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read { path: path.to_path_buf(), source })?;
    parse(&text, path)
}

/// `read`'s parsing of `text`, the file at `path`.
pub fn parse(text: &str, path: &Path) -> Result<PiecesFile, ScenarioError> {
    let mut out = PiecesFile { path: path.to_path_buf(), rows: Vec::new(), lines: Vec::new() };
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let body = raw.split('#').next().unwrap_or("").trim();
        if body.is_empty() {
            continue;
        }
        let i = out.rows.len();
        let row_name = format!("contour.pieces[{i}]");
        if i == MAX_CONTOUR_PIECES {
            return Err(refused(
                path,
                line,
                row_name,
                body,
                format!("must not be there: a contour has at most {MAX_CONTOUR_PIECES} pieces"),
            ));
        }
        let words: Vec<&str> = body.split(|c: char| c == ',' || c.is_whitespace()).filter(|w| !w.is_empty()).collect();
        if words.len() != 3 {
            return Err(refused(
                path,
                line,
                row_name,
                body,
                format!("must be a row of 3 numbers [{}], not {} values", COLS.join(", "), words.len()),
            ));
        }
        let mut row = [0.0; 3];
        for (c, w) in words.iter().enumerate() {
            row[c] = match w.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => return Err(refused(path, line, format!("{row_name} {}", COLS[c]), w, "must be a finite number".into())),
            };
        }
        out.rows.push(row);
        out.lines.push(line);
    }
    Ok(out)
}

/// The scenario file at `path` as text that needs no other file: unchanged when it names no
/// pieces file, else with `contour.pieces_file` replaced by the file's rows in `contour.pieces`
/// (written as TOML, comments dropped, a first comment line saying so).
pub fn self_contained(path: &Path) -> Result<String, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read { path: path.to_path_buf(), source })?;
    let Ok(mut doc) = text.parse::<toml::Table>() else {
        return Ok(text);
    };
    let Some(toml::Value::Table(contour)) = doc.get_mut("contour") else {
        return Ok(text);
    };
    let Some(toml::Value::String(name)) = contour.remove("pieces_file") else {
        return Ok(text);
    };
    let file = read(&resolve(path, &name))?;
    let rows = file.rows.iter().map(|r| toml::Value::Array(r.iter().map(|&x| toml::Value::Float(x)).collect())).collect();
    contour.insert("pieces".into(), toml::Value::Array(rows));
    let body = toml::to_string(&doc).map_err(|e| ScenarioError::Field {
        path: path.to_path_buf(),
        place: Place::Unstated,
        field: "contour.pieces_file".into(),
        value: format!("{name:?}"),
        why: e.to_string(),
    })?;
    Ok(format!("# {} with contour.pieces_file = {name:?} ({}) inlined\n{body}", path.display(), file.path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows come back as written, with their lines; comments, blank lines, commas or blanks.
    #[test]
    fn rows_and_their_lines() {
        let f = parse("# line_mm, radius_mm, turn_deg\n\n100, 0, 0\n0 50 90   # a corner\n  0,\t25, -45.5\n", Path::new("p.txt")).unwrap();
        assert_eq!(f.rows, vec![[100.0, 0.0, 0.0], [0.0, 50.0, 90.0], [0.0, 25.0, -45.5]]);
        assert_eq!(f.lines, vec![3, 4, 5]);
    }

    /// A bad row is refused naming the file, its line and the row's column.
    #[test]
    fn bad_rows_name_file_line_and_column() {
        let e = parse("100, 0, 0\n\n0, fifty, 90\n", Path::new("d/p.txt")).unwrap_err();
        assert_eq!(e.place(), Some(Place::Line(3)));
        assert_eq!(e.field(), Some("contour.pieces[1] radius_mm"));
        assert!(e.to_string().starts_with("scenario file d/p.txt, line 3: field contour.pieces[1] radius_mm = fifty"), "{e}");
        let e = parse("100, 0\n", Path::new("p.txt")).unwrap_err();
        assert!(e.to_string().contains("must be a row of 3 numbers [line_mm, radius_mm, turn_deg], not 2 values"), "{e}");
        let e = parse("1, 0, inf\n", Path::new("p.txt")).unwrap_err();
        assert_eq!(e.field(), Some("contour.pieces[0] turn_deg"));
        let many = "1, 0, 0\n".repeat(MAX_CONTOUR_PIECES + 1);
        let e = parse(&many, Path::new("p.txt")).unwrap_err();
        assert_eq!(e.place(), Some(Place::Line(MAX_CONTOUR_PIECES + 1)));
    }

    #[test]
    fn relative_to_the_scenario() {
        assert_eq!(resolve(Path::new("/a/b/s.toml"), "c.txt"), Path::new("/a/b/c.txt"));
        assert_eq!(resolve(Path::new("/a/b/s.toml"), "/x/c.txt"), Path::new("/x/c.txt"));
        assert_eq!(resolve(Path::new("s.toml"), "c.txt"), Path::new("c.txt"));
    }
}
