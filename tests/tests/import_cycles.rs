//! No file-level import cycles (issue 13): within every workspace crate, the modules that are
//! siblings (children of one parent module) reference each other without a cycle, so each file can
//! be read after the files it uses. Parsed from the sources, not from the compiler: every
//! `crate::a::…`, `super::a::…` and `self::a::…` path (`use` groups included, comments and string
//! literals left out) is resolved to the file that defines module `a`; a reference from file
//! `x/y.rs` to `z.rs` counts as an edge between the siblings `x` and `z` (both ends lifted to the
//! children of their common parent); references between a module and its own parent or children
//! do not count (the crate root declares every module). A cycle is printed with the first line of
//! each reference on it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module path inside one crate: `[]` is the crate root, `["egm", "servo"]` is `egm/servo.rs`.
type ModPath = Vec<String>;

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    PathSep,
    Open,
    Close,
    Comma,
    Other,
}

/// Tokens of a Rust source with their line numbers: comments, string, char and byte literals are
/// dropped; only identifiers, `::`, braces and commas are kept apart, the rest is `Other`.
fn tokens(src: &str) -> Vec<(Tok, usize)> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    let ident_start = |ch: char| ch.is_alphabetic() || ch == '_';
    let ident_char = |ch: char| ch.is_alphanumeric() || ch == '_';
    while i < c.len() {
        let ch = c[i];
        let next = c.get(i + 1).copied().unwrap_or('\0');
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && next == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && next == '*' {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    line += usize::from(c[i] == '\n');
                    i += 1;
                }
            }
        } else if (ch == 'r' || (ch == 'b' && next == 'r')) && raw_string_at(&c, i).is_some() {
            let (end, lines) = raw_string_at(&c, i).unwrap();
            line += lines;
            i = end;
        } else if ch == '"' || (ch == 'b' && next == '"') {
            i += if ch == 'b' { 2 } else { 1 };
            while i < c.len() && c[i] != '"' {
                line += usize::from(c[i] == '\n');
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
        } else if ch == '\'' || (ch == 'b' && next == '\'') {
            // a char literal ('x', '\n', '\u{..}') or a lifetime ('a)
            let j = if ch == 'b' { i + 1 } else { i };
            if c.get(j + 1) == Some(&'\\') {
                let mut k = j + 2;
                while k < c.len() && c[k] != '\'' {
                    k += 1;
                }
                i = k + 1;
            } else if c.get(j + 2) == Some(&'\'') {
                i = j + 3;
            } else {
                i = j + 1;
            }
        } else if ident_start(ch) {
            let s = i;
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
            out.push((Tok::Ident(c[s..i].iter().collect()), line));
        } else if ch == ':' && next == ':' {
            out.push((Tok::PathSep, line));
            i += 2;
        } else {
            out.push((
                match ch {
                    '{' => Tok::Open,
                    '}' => Tok::Close,
                    ',' => Tok::Comma,
                    _ => Tok::Other,
                },
                line,
            ));
            i += 1;
        }
    }
    out
}

/// A raw (byte) string starting at `i` (`r"…"`, `r#"…"#`, `br"…"`): where it ends and how many
/// newlines it holds.
fn raw_string_at(c: &[char], i: usize) -> Option<(usize, usize)> {
    if i > 0 && (c[i - 1].is_alphanumeric() || c[i - 1] == '_') {
        return None;
    }
    let mut j = i + if c[i] == 'b' { 2 } else { 1 };
    let mut hashes = 0;
    while c.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    if c.get(j) != Some(&'"') {
        return None;
    }
    j += 1;
    let mut lines = 0;
    while j < c.len() {
        if c[j] == '"' && (0..hashes).all(|h| c.get(j + 1 + h) == Some(&'#')) {
            return Some((j + 1 + hashes, lines));
        }
        lines += usize::from(c[j] == '\n');
        j += 1;
    }
    Some((j, lines))
}

/// Every module path a file's source names through `crate::`, `super::` or `self::`, resolved
/// against the file's module `here` and the inline modules (`mod tests { … }`) around each path.
fn references(src: &str, here: &[String]) -> Vec<(ModPath, usize)> {
    let toks = tokens(src);
    let mut out = Vec::new();
    // inline modules: (name, brace depth inside them)
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < toks.len() {
        match &toks[i].0 {
            Tok::Open => depth += 1,
            Tok::Close => {
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
            }
            Tok::Ident(m) if m == "mod" => {
                if let (Some((Tok::Ident(name), _)), Some((Tok::Open, _))) = (toks.get(i + 1), toks.get(i + 2)) {
                    inline.push((name.clone(), depth + 1));
                }
            }
            Tok::Ident(kw) if (kw == "crate" || kw == "super" || kw == "self") && toks.get(i + 1).map(|t| &t.0) == Some(&Tok::PathSep) => {
                // a path in the middle of another (`a::self::b` does not occur; `$crate` is a crate path)
                let starts_path = i == 0 || toks[i - 1].0 != Tok::PathSep;
                if starts_path {
                    let mut scope: ModPath = here.to_vec();
                    scope.extend(inline.iter().map(|(n, _)| n.clone()));
                    let line = toks[i].1;
                    let end = path_at(&toks, i, &scope, line, &mut out);
                    i = end;
                    continue;
                }
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Reads the path starting at token `i` (`crate::a::{b, c::d}` …), pushes every module path it
/// names, and returns the index after it.
fn path_at(toks: &[(Tok, usize)], mut i: usize, scope: &[String], line: usize, out: &mut Vec<(ModPath, usize)>) -> usize {
    let mut base: ModPath = Vec::new();
    let mut first = true;
    loop {
        match toks.get(i).map(|t| &t.0) {
            Some(Tok::Ident(s)) if first && s == "crate" => base.clear(),
            Some(Tok::Ident(s)) if first && s == "self" => base = scope.to_vec(),
            Some(Tok::Ident(s)) if s == "super" => {
                if first {
                    base = scope.to_vec();
                }
                base.pop();
            }
            Some(Tok::Ident(s)) => base.push(s.clone()),
            Some(Tok::Open) => return group_at(toks, i, &base, line, out),
            _ => break,
        }
        first = false;
        i += 1;
        if toks.get(i).map(|t| &t.0) == Some(&Tok::PathSep) {
            i += 1;
        } else {
            break;
        }
    }
    out.push((base, line));
    i
}

/// A `{ … }` group of a `use` after `base::`: every item in it, nested groups included.
fn group_at(toks: &[(Tok, usize)], open: usize, base: &ModPath, line: usize, out: &mut Vec<(ModPath, usize)>) -> usize {
    let mut i = open + 1;
    let mut item = base.clone();
    let mut named = false;
    while let Some((t, _)) = toks.get(i) {
        match t {
            Tok::Ident(s) if s == "self" => named = true,
            Tok::Ident(s) if s == "as" => {
                // `x as y`: the alias names nothing new
                out.push((item.clone(), line));
                named = false;
                i += 1;
            }
            Tok::Ident(s) => {
                item.push(s.clone());
                named = true;
            }
            Tok::PathSep => {}
            Tok::Open => {
                i = group_at(toks, i, &item, line, out);
                item = base.clone();
                named = false;
                continue;
            }
            Tok::Comma | Tok::Close => {
                if named {
                    out.push((item.clone(), line));
                }
                item = base.clone();
                named = false;
                if *t == Tok::Close {
                    return i + 1;
                }
            }
            Tok::Other => {}
        }
        i += 1;
    }
    i
}

/// The module files of a crate's `src/` (binaries under `src/bin/` are crates of their own):
/// module path -> file.
fn module_files(src: &Path) -> BTreeMap<ModPath, PathBuf> {
    fn walk(dir: &Path, prefix: &ModPath, out: &mut BTreeMap<ModPath, PathBuf>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
        entries.sort();
        for p in entries {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                if prefix.is_empty() && name == "bin" {
                    continue;
                }
                let mut sub = prefix.clone();
                sub.push(name);
                walk(&p, &sub, out);
            } else if let Some(stem) = name.strip_suffix(".rs") {
                // generated code pulled in with include! (e.g. `abb.egm.rs`) is not a module
                if stem.contains('.') {
                    continue;
                }
                let mut m = prefix.clone();
                if !(stem == "mod" || (prefix.is_empty() && (stem == "lib" || stem == "main"))) {
                    m.push(stem.to_string());
                }
                out.insert(m, p);
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(src, &Vec::new(), &mut out);
    out
}

/// Sibling edges of one crate: (parent module, from, to) -> the references that make it.
type Edges = BTreeMap<(ModPath, String, String), Vec<(PathBuf, usize)>>;

fn sibling_edges(src: &Path) -> Edges {
    let files = module_files(src);
    let mut edges = Edges::new();
    for (here, file) in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (path, line) in references(&text, here) {
            // the file defining the longest prefix of the path
            let Some(target) = (0..=path.len()).rev().map(|n| path[..n].to_vec()).find(|p| files.contains_key(p)) else { continue };
            let common = here.iter().zip(&target).take_while(|(a, b)| a == b).count();
            if common == here.len() || common == target.len() {
                continue; // itself, its parent or its child
            }
            let parent = here[..common].to_vec();
            let key = (parent, here[common].clone(), target[common].clone());
            edges.entry(key).or_default().push((file.clone(), line));
        }
    }
    edges
}

/// The cycles among siblings (one per strongly connected group of more than one module), each as
/// the modules in order, the first repeated at the end.
fn cycles(edges: &Edges) -> Vec<(ModPath, Vec<String>)> {
    let parents: BTreeSet<&ModPath> = edges.keys().map(|(p, _, _)| p).collect();
    let mut found = Vec::new();
    for parent in parents {
        let graph: BTreeMap<&str, Vec<&str>> = edges.keys().filter(|(p, _, _)| p == parent).fold(BTreeMap::new(), |mut g, (_, a, b)| {
            g.entry(a.as_str()).or_insert_with(Vec::new).push(b.as_str());
            g
        });
        let mut done: BTreeSet<&str> = BTreeSet::new();
        for &start in graph.keys() {
            if done.contains(start) {
                continue;
            }
            // depth-first search from `start`, the path kept: a back edge closes a cycle
            let mut stack: Vec<(&str, usize)> = vec![(start, 0)];
            let mut on_path: Vec<&str> = vec![start];
            while let Some((node, k)) = stack.pop() {
                let next = graph.get(node).and_then(|v| v.get(k)).copied();
                match next {
                    Some(n) => {
                        stack.push((node, k + 1));
                        if let Some(at) = on_path.iter().position(|&x| x == n) {
                            let mut cyc: Vec<String> = on_path[at..].iter().map(|s| s.to_string()).collect();
                            cyc.push(n.to_string());
                            if !found.iter().any(|(p, c): &(ModPath, Vec<String>)| p == parent && same_cycle(c, &cyc)) {
                                found.push((parent.clone(), cyc));
                            }
                        } else if !done.contains(n) {
                            stack.push((n, 0));
                            on_path.push(n);
                        }
                    }
                    None => {
                        done.insert(node);
                        on_path.pop();
                    }
                }
            }
        }
    }
    found
}

/// The same cycle read from another start.
fn same_cycle(a: &[String], b: &[String]) -> bool {
    let (a, b) = (&a[..a.len() - 1], &b[..b.len() - 1]);
    a.len() == b.len() && (0..a.len()).any(|r| a.iter().cycle().skip(r).take(a.len()).eq(b.iter()))
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The workspace members of the root Cargo.toml.
fn members() -> Vec<String> {
    let text = std::fs::read_to_string(workspace_root().join("Cargo.toml")).unwrap();
    let list = text.split("members = [").nth(1).and_then(|t| t.split(']').next()).expect("[workspace] members");
    list.split(',').map(|m| m.trim().trim_matches('"').to_string()).filter(|m| !m.is_empty()).collect()
}

fn describe(krate: &str, parent: &ModPath, cycle: &[String], edges: &Edges) -> String {
    let mut s = format!("{krate}: {}", cycle.join(" -> "));
    if !parent.is_empty() {
        s += &format!(" (in module {})", parent.join("::"));
    }
    for w in cycle.windows(2) {
        let refs = &edges[&(parent.clone(), w[0].clone(), w[1].clone())];
        let (file, line) = &refs[0];
        let rel = file.strip_prefix(workspace_root()).unwrap_or(file);
        s += &format!("\n    {} -> {}: {}:{line} (and {} more)", w[0], w[1], rel.display(), refs.len() - 1);
    }
    s
}

#[test]
fn no_workspace_crate_has_a_file_level_import_cycle() {
    let crates = members();
    assert!(crates.len() >= 10, "members of the workspace: {crates:?}");
    let mut report = Vec::new();
    let mut files = 0;
    for krate in &crates {
        let src = workspace_root().join(krate).join("src");
        files += module_files(&src).len();
        let edges = sibling_edges(&src);
        for (parent, cycle) in cycles(&edges) {
            report.push(describe(krate, &parent, &cycle, &edges));
        }
    }
    eprintln!("{} crates, {files} module files", crates.len());
    assert!(report.is_empty(), "file-level import cycles:\n{}", report.join("\n"));
}

#[test]
fn the_parser_finds_paths_groups_and_inline_modules() {
    let here = vec!["a".to_string()];
    let src = r#"
        use crate::b::Thing; // crate::commented::Out
        use crate::{c::{self, D}, e as f};
        use super::g::*;
        /* crate::h */ const S: &str = "crate::i::j";
        fn x<'a>(c: char) -> bool { c == '{' || crate::k::call() }
        mod tests { use super::*; use super::super::l; }
    "#;
    let got: Vec<String> = references(src, &here).into_iter().map(|(p, _)| p.join("::")).collect();
    assert_eq!(got, ["b::Thing", "c", "c::D", "e", "g", "k::call", "a", "l"]);
}

#[test]
fn a_cycle_between_two_siblings_is_found_and_a_parent_reference_is_not_one() {
    let mut edges = Edges::new();
    let e = |a: &str, b: &str| ((Vec::new(), a.to_string(), b.to_string()), vec![(PathBuf::from("x.rs"), 1)]);
    edges.extend([e("x", "y"), e("y", "z"), e("z", "x"), e("w", "x")]);
    let found = cycles(&edges);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(same_cycle(&found[0].1, &["x".into(), "y".into(), "z".into(), "x".into()]), "{found:?}");
    edges.remove(&(Vec::new(), "z".to_string(), "x".to_string()));
    assert!(cycles(&edges).is_empty());
}
