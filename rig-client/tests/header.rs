//! The committed C header `include/rig_client.h` is what cbindgen makes of `src/lib.rs` today,
//! with static assertions on every size and offset of the record tables in `messages/README.md`;
//! it compiles with the system's C compiler (C11) and C++ compiler (C++17), which check them.
//! `RIG_CLIENT_BLESS=1 cargo test --release -p rig-client --test header` rewrites the header.

use std::path::{Path, PathBuf};
use std::process::Command;

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// One record table: C struct name, size in bytes, `(offset, field)` rows.
type Table = (String, usize, Vec<(usize, String)>);

/// Each record table in messages/README.md ("Records").
fn readme_tables() -> Vec<Table> {
    let readme = std::fs::read_to_string(crate_dir().join("../messages/README.md")).unwrap();
    let mut tables: Vec<Table> = Vec::new();
    for line in readme.lines() {
        // "### `rig::JointState` (192 bytes)"
        if let Some(rest) = line.strip_prefix("### `rig::") {
            let (name, rest) = rest.split_once('`').unwrap();
            let size = rest.trim().trim_start_matches('(').split_whitespace().next().unwrap().parse().unwrap();
            tables.push((format!("Rig{name}"), size, Vec::new()));
        } else if line.starts_with("## ") {
            // a new section ends the last table
            if let Some(t) = tables.last() {
                if !t.2.is_empty() {
                    tables.push((String::new(), 0, Vec::new()));
                }
            }
        } else if let (Some(t), Some(row)) = (tables.last_mut(), line.strip_prefix("| ")) {
            let cells: Vec<&str> = row.split('|').map(str::trim).collect();
            if let (Ok(off), Some(field)) = (cells[0].parse::<usize>(), cells.get(1)) {
                t.2.push((off, field.to_string()));
            }
        }
    }
    tables.retain(|t| !t.0.is_empty());
    tables
}

fn asserts() -> String {
    let tables = readme_tables();
    let names: Vec<&str> = tables.iter().map(|t| t.0.as_str()).collect();
    assert_eq!(names, ["RigJointState", "RigWrench", "RigJointTorque", "RigControllerDiagnostics"], "messages/README.md's record tables");
    let mut s = String::new();
    for (name, size, rows) in &tables {
        s += &format!("RIG_CLIENT_STATIC_ASSERT(sizeof({name}) == {size}, \"{name} is {size} bytes\");\n");
        for (off, field) in rows {
            s += &format!("RIG_CLIENT_STATIC_ASSERT(offsetof({name}, {field}) == {off}, \"{name}.{field} at byte {off}\");\n");
        }
    }
    s.trim_end().to_string()
}

fn generate() -> String {
    let dir = crate_dir();
    let mut cfg = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    cfg.trailer = cfg.trailer.map(|t| t.replace("@ASSERTS@", &asserts()));
    let mut out = Vec::new();
    cbindgen::Builder::new().with_crate(&dir).with_config(cfg).generate().expect("cbindgen").write(&mut out);
    String::from_utf8(out).unwrap()
}

fn header_path() -> PathBuf {
    crate_dir().join("include/rig_client.h")
}

#[test]
fn the_committed_header_is_generated_from_the_source() {
    let fresh = generate();
    let path = header_path();
    if std::env::var_os("RIG_CLIENT_BLESS").is_some() {
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "{} is stale: regenerate it with `RIG_CLIENT_BLESS=1 cargo test --release -p rig-client --test header` and commit it",
        path.display()
    );
    // Every row of the four tables is pinned: 11 + 5 + 5 + 13 offsets.
    assert_eq!(committed.matches("RIG_CLIENT_STATIC_ASSERT(offsetof(").count(), 34);
}

fn compile(compiler: &str, std: &str, src: &Path, dir: &Path) {
    let out = dir.join(format!("{}.o", src.file_stem().unwrap().to_string_lossy()));
    let o = Command::new(compiler)
        .args([std, "-Wall", "-Wextra", "-Werror", "-pedantic", "-c", "-I"])
        .arg(crate_dir().join("include"))
        .arg(src)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap_or_else(|e| panic!("running {compiler}: {e} (install it: bash .ci/deps)"));
    assert!(o.status.success(), "{compiler} {std} refused the header:\n{}", String::from_utf8_lossy(&o.stderr));
}

/// The system's compilers accept the header and its layout assertions hold; a wrong offset in
/// the header's assertions (as a README table that no longer matches) is refused.
#[test]
fn the_header_compiles_and_its_layout_assertions_hold_in_c_and_cpp() {
    let dir = std::env::temp_dir().join(format!("rig-client-header-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let c = dir.join("use_header.c");
    std::fs::write(&c, "#include \"rig_client.h\"\nint main(void) { RigJointState s = {0}; return (int)s.tick; }\n").unwrap();
    compile("cc", "-std=c11", &c, &dir);
    let cpp = dir.join("use_header_cpp.cpp");
    std::fs::write(&cpp, "#include \"rig_client.h\"\nint main() { RigJointState s{}; return static_cast<int>(s.tick); }\n").unwrap();
    compile("c++", "-std=c++17", &cpp, &dir);

    // The assertions bite: the same header with one offset wrong does not compile.
    let header = std::fs::read_to_string(header_path()).unwrap();
    let wrong = header.replace("offsetof(RigJointState, q) == 24", "offsetof(RigJointState, q) == 32");
    assert_ne!(wrong, header);
    let bad_dir = dir.join("bad");
    std::fs::create_dir_all(&bad_dir).unwrap();
    std::fs::write(bad_dir.join("rig_client.h"), wrong).unwrap();
    let o = Command::new("cc").args(["-std=c11", "-c", "-I"]).arg(&bad_dir).arg(&c).arg("-o").arg(dir.join("bad.o")).output().unwrap();
    assert!(!o.status.success(), "a wrong offset compiled");
    assert!(String::from_utf8_lossy(&o.stderr).contains("offsetof(RigJointState, q) == 32"), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}
