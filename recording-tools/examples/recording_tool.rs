//! The `rig report` / `rig replay` subcommands as a stand-alone program (the same code the `rig`
//! binary wires in): `cargo run --release -p recordings --example recording_tool -- report FILE`.

use clap::Parser;

#[derive(Parser)]
#[command(name = "recording_tool")]
enum Cmd {
    /// Numbers and figures of a recording.
    Report(recording_tools::cli::ReportArgs),
    /// Republish a recording; drive a controller open-loop and compare its torques.
    Replay(recording_tools::cli::ReplayArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt().with_writer(std::io::stderr).init();
    match Cmd::parse() {
        Cmd::Report(a) => recording_tools::cli::report(a),
        Cmd::Replay(a) => recording_tools::cli::replay(a),
    }
}
