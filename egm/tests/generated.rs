//! `src/abb.egm.rs` is prost's output for `proto/egm.proto`: this test compiles the .proto again
//! (protox, a pure-Rust protobuf compiler, so no `protoc` on the machine) and compares.
//! `UPDATE_EGM_PROTO=1 cargo test -p egm --test generated` rewrites the file.

use std::path::Path;

#[test]
fn generated_rust_is_prost_output_for_the_proto() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let fds = protox::compile([dir.join("proto/egm.proto")], [dir.join("proto")]).expect("compiling egm.proto");
    let out = std::env::temp_dir().join(format!("egm-gen-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    prost_build::Config::new().out_dir(&out).compile_fds(fds).expect("prost-build");
    let fresh = std::fs::read_to_string(out.join("abb.egm.rs")).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    let committed_path = dir.join("src/abb.egm.rs");
    if std::env::var_os("UPDATE_EGM_PROTO").is_some() {
        std::fs::write(&committed_path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&committed_path).unwrap_or_default();
    assert!(
        committed == fresh,
        "src/abb.egm.rs is not prost's output for proto/egm.proto: run UPDATE_EGM_PROTO=1 cargo test -p egm --test generated"
    );
}
