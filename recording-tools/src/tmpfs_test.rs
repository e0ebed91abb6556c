//! Test support: run one `#[ignore]`d inner test of the calling test binary again, as a child
//! process inside a private mount namespace with a size-limited tmpfs mounted at `dir` (a really
//! full disk, ENOSPC, without touching the host's file systems). Used by the recordings' and the
//! end-to-end full-disk tests.

use std::path::Path;
use std::process::Command;

/// Mount a tmpfs of `size` (mount's `size=` syntax, e.g. `384k`, `80m`) at `dir` in a new mount
/// namespace and run the calling test binary's `inner_test` there, with `dir_env` = `dir` in its
/// environment. Returns the inner run's stdout once it passed, or None (after printing
/// `SKIPPED:` with why) where this machine refuses the namespace or the mount. Panics when the
/// inner test fails or does not run.
pub fn run_inner_on_private_tmpfs(dir_env: &str, dir: &Path, size: &str, inner_test: &str) -> Option<String> {
    std::fs::create_dir_all(dir).expect("the mount point");
    let me = std::env::current_exe().expect("the test binary");
    // root may mount directly in a new mount namespace; others need a user namespace too
    // SAFETY: geteuid has no preconditions.
    let user_ns = if unsafe { libc::geteuid() } == 0 { "" } else { "--user --map-root-user" };
    let script = format!(
        "mount -t tmpfs -o size={size} tmpfs '{d}' || exit 77; exec '{me}' --exact {inner_test} --ignored --nocapture",
        d = dir.display(),
        me = me.display()
    );
    let out =
        Command::new("sh").arg("-c").arg(format!("unshare --mount {user_ns} sh -c \"{script}\"")).env(dir_env, dir).output().expect("sh");
    let _ = std::fs::remove_dir_all(dir);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(77) || stderr.contains("unshare failed") || stderr.contains("Operation not permitted") {
        eprintln!("SKIPPED: cannot mount a tmpfs in a private namespace on this machine: {stderr}");
        return None;
    }
    assert!(out.status.success(), "inner test failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains(&format!("test {inner_test} ... ok")), "inner test did not run:\n{stdout}\n{stderr}");
    Some(stdout)
}
