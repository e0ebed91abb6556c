//! `rig robot ...`: command-line checks of the model against the user's own tools.

use std::path::PathBuf;

/// Subcommands of `rig robot`.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Evaluate kinematics and dynamics of the bare arm for states read from a JSON file.
    Dynamics {
        #[arg(long)]
        input: PathBuf,
        #[arg(long)]
        output: PathBuf,
    },
}

/// Run one `rig robot` subcommand.
pub fn run(cmd: Command) -> anyhow::Result<()> {
    match cmd {
        Command::Dynamics { input, output } => {
            let _ = (input, output);
            anyhow::bail!("not implemented yet")
        }
    }
}
