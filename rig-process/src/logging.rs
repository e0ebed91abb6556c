//! The log setup the rig's binaries share: `tracing` to stderr (stdout stays for results), level
//! from `RUST_LOG` (default `info`), colours only on a terminal.

/// Installs the global subscriber; call once at the start of `main`. A failed write (stderr
/// closed because the launcher died) is dropped: tracing-subscriber would otherwise report it
/// with `eprintln!`, which panics on that same closed stderr.
pub fn init_stderr() {
    tracing_subscriber::fmt()
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .log_internal_errors(false)
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()))
        .init();
}
