//! Stand-alone front of `rig model` (same subcommands), handy while `rig` is being built.
use clap::Parser;

#[derive(Parser)]
#[command(name = "strip-model", about = "Weatherstrip reduced model: build, report, export")]
struct Cli {
    #[command(subcommand)]
    cmd: strip::cli::Command,
}

fn main() -> anyhow::Result<()> {
    strip::cli::run(Cli::parse().cmd)
}
