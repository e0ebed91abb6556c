//! The `rig replay`, `rig report` and `rig compare` subcommands (the `rig` binary of crate `rig` wires
//! them) and the numbers `rig run` prints at its end. The arguments of `rig replay` live with the
//! replay ([`ReplayArgs`]), the opening rule of every command with the reader ([`open_for`]).

pub use crate::read::open_for;
use crate::read::Recording;
use crate::replay;
pub use crate::replay::ReplayArgs;
use crate::report::{self, ReportNumbers};
use anyhow::Context;
use std::path::{Path, PathBuf};

/// `rig report FILE [--out DIR]`: numbers as text and JSON, figures as PNG and SVG.
#[derive(Debug, Clone, clap::Args)]
pub struct ReportArgs {
    /// The recording (.mcap).
    pub file: PathBuf,
    /// Folder for report.txt, report.json and the figures (default: `<FILE without .mcap>-report/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Simulated times (s) of the bottom-pressure figure, comma-separated
    /// (default: the wheel at 10, 30, 50, 70 and 90 % of its roll).
    #[arg(long, value_delimiter = ',')]
    pub instants: Vec<f64>,
    /// Report a cut (killed run) or corrupt file from its intact ticks, up to the first bad chunk,
    /// instead of refusing it.
    #[arg(long, visible_alias = "allow-damaged")]
    pub allow_truncated: bool,
}

/// `rig compare A.mcap B.mcap ... [--out DIR]`: runs side by side.
#[derive(Debug, Clone, clap::Args)]
pub struct CompareArgs {
    /// Two or more recordings (.mcap).
    #[arg(required = true, num_args = 2..)]
    pub files: Vec<PathBuf>,
    /// Folder for compare.md and the overlaid figures.
    #[arg(long, default_value = "runs/compare")]
    pub out: PathBuf,
    /// Use a cut or corrupt file's intact ticks, up to the first bad chunk, instead of refusing it.
    #[arg(long, visible_alias = "allow-damaged")]
    pub allow_truncated: bool,
}

pub fn compare(args: CompareArgs) -> anyhow::Result<()> {
    let (text, files) = crate::compare::compare(&args.files, &args.out, args.allow_truncated)?;
    print!("{text}");
    println!("table       {}", files.table.display());
    for f in &files.figures {
        println!("figure      {}", f.display());
    }
    Ok(())
}

pub fn report(args: ReportArgs) -> anyhow::Result<()> {
    let rec = open_for(&args.file, args.allow_truncated)?;
    let out = args.out.clone().unwrap_or_else(|| default_report_dir(&args.file));
    let (numbers, files) =
        report::write_report(&rec, &out, &args.instants).with_context(|| format!("writing the report of {}", args.file.display()))?;
    print!("{}", report::format_text(&numbers));
    println!("report      {} and {}", files.text.display(), files.json.display());
    for f in &files.figures {
        println!("figure      {}", f.display());
    }
    Ok(())
}

/// `<dir>/<stem>-report/` next to the recording.
pub fn default_report_dir(file: &Path) -> PathBuf {
    let stem = file.file_stem().map_or("recording".into(), |s| s.to_string_lossy().into_owned());
    file.with_file_name(format!("{stem}-report"))
}

/// The report's numbers of a recording, for `rig run` to print at its end (with
/// [`report::format_text`]). A cut or corrupt file is read up to its first bad chunk; the numbers'
/// `integrity` field says so.
pub fn summary_numbers(path: &Path) -> anyhow::Result<ReportNumbers> {
    // Only the channels the numbers read (same numbers, same integrity verdict).
    let rec = Recording::open_channels(path, report::NUMBERS_CHANNELS)?;
    Ok(report::numbers(&rec))
}

/// [`summary_numbers`] of a recording a plant of rig `rig` is still writing, read as it grows
/// ([`Recording::follow_channels`]): the same numbers and verdict once `progress` says the file is
/// finished, most of the reading done by then. None if `progress` abandoned it.
pub fn summary_numbers_following(
    path: &Path,
    rig: &str,
    progress: &dyn Fn() -> crate::read::Writing,
) -> Option<anyhow::Result<ReportNumbers>> {
    let rec = Recording::follow_channels(path, report::NUMBERS_CHANNELS, rig, FOLLOW_POLL, progress)?;
    Some(rec.map(|rec| report::numbers(&rec)).map_err(Into::into))
}

/// How often a followed recording is looked at for new bytes: a few chunks of a lockstep run
/// (512 KiB uncompressed each, about 3 ms of its loop apiece), and a read that finds nothing
/// costs a system call.
const FOLLOW_POLL: std::time::Duration = std::time::Duration::from_millis(5);

pub fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    replay::run(&args).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Rig {
        #[command(subcommand)]
        cmd: Cmd,
    }
    #[derive(clap::Subcommand)]
    enum Cmd {
        Replay(ReplayArgs),
        Report(ReportArgs),
    }

    #[test]
    fn replay_and_report_flags_parse() {
        let Cmd::Replay(a) = Rig::parse_from(["rig", "replay", "run.mcap", "--controller"]).cmd else { panic!() };
        assert_eq!(a.controller, Some(PathBuf::from("auto")), "--controller alone = the default controller");
        assert_eq!(a.speed, None);
        let Cmd::Replay(a) = Rig::parse_from(["rig", "replay", "run.mcap", "--speed", "4", "--controller", "./mine"]).cmd else { panic!() };
        assert_eq!((a.speed, a.controller), (Some(4.0), Some(PathBuf::from("./mine"))));
        let Cmd::Report(r) = Rig::parse_from(["rig", "report", "a/run.mcap", "--instants", "0.5,1.25"]).cmd else { panic!() };
        assert_eq!(r.instants, vec![0.5, 1.25]);
        assert_eq!(default_report_dir(&r.file), PathBuf::from("a/run-report"));
    }
}
