//! `rig`: the user's front door to the weatherstrip rig.
//!
//! - `rig run [SCENARIO.toml] [--mode realtime|lockstep] [--controller PATH] [--duration S] [--out DIR]
//!   [--live [ADDR]] [--live-rate HZ]` starts `plant-sim` and a controller on a fresh rig name,
//!   supervises them and prints a summary; `--live` serves the run to Foxglove as it goes.
//! - `rig timing [--seconds N] [--no-host-probe] [--live [ADDR]]`: a real-time timing run with latency and jitter distributions.
//! - `rig sweep [SCENARIO.toml] --set section.field=v1,v2,... [--grid]`: a parameter study, one
//!   in-process lockstep run per case, several at once across the cores, tabulated from the
//!   recordings.
//! - `rig study run|case|status|collect`: a Monte Carlo study from a study file, in process on
//!   every core or as a Slurm job array (`study/`).
//! - `rig robot ...`, `rig model ...`, `rig replay`, `rig report`, `rig compare`, `rig design`: the tools of the
//!   robot, strip, recording-tools and design crates.
//!
//! `run`, `timing` and `sweep` check every flag and every scenario value before any daemon starts;
//! a refusal names the flag (and the file, line and field of a scenario value).

mod in_process;
mod study;
mod summary;
mod supervise;
mod sweep;

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};
use scenarios::Mode;
use supervise::{Controller, Ending, RigLaunch};

#[derive(Debug, Parser)]
#[command(name = "rig", about = "Hardware-in-the-loop rig for weatherstrip force control: plant + controller over iceoryx2 at 1 kHz")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run a scenario: start plant-sim and the controller, supervise them, print a summary.
    Run(RunArgs),
    /// Real-time timing run: round-trip latency, tick-period jitter, misses, compute times.
    Timing(TimingArgs),
    /// Parameter study: one lockstep run per case (scenario fields overridden), one table.
    Sweep(SweepArgs),
    /// Monte Carlo robustness study from a study file: pass rate, percentiles, worst cases, on
    /// this machine's cores or a Slurm cluster.
    Study {
        #[command(subcommand)]
        cmd: study::cli::StudyCmd,
    },
    /// Robot model tools.
    Robot {
        #[command(subcommand)]
        cmd: robot::cli::Command,
    },
    /// Weatherstrip model: build (cached), verify (Table D.1, static response), export (.npz).
    Model {
        #[command(subcommand)]
        cmd: strip::cli::Command,
    },
    /// Republish a recording onto a rig (optionally driving a controller open-loop and comparing).
    Replay(recording_tools::cli::ReplayArgs),
    /// Figures and numbers from a recording.
    Report(recording_tools::cli::ReportArgs),
    /// Several recordings side by side: one table, the rolling phase overlaid.
    Compare(recording_tools::cli::CompareArgs),
    /// Force-loop design from the actual models (thesis Chapter 6).
    Design(design::cli::DesignArgs),
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// Scenario file (default: scenarios/default.toml).
    scenario: Option<PathBuf>,
    /// Loop mode, overriding the scenario's.
    #[arg(long, value_parser = mode_flag())]
    mode: Option<Mode>,
    /// Override one scenario field, `section.field=value` (repeatable); the scenario actually run
    /// is written to <DIR>/scenario.toml and checked like any scenario file before anything starts.
    #[arg(long = "set", value_parser = sweep::parse_set)]
    set: Vec<sweep::Axis>,
    /// Lockstep only: run the plant's tick and the controller's step in this process, one
    /// thread, no daemons and no iceoryx2 (bit-identical to the daemons' lockstep run).
    #[arg(long)]
    in_process: bool,
    #[command(flatten)]
    launch: LaunchArgs,
    #[command(flatten)]
    live: LiveArgs,
}

/// The live view of `rig run` and `rig timing` (recordings/README.md, "Live view").
#[derive(Debug, clap::Args)]
struct LiveArgs {
    /// Serve the run's channels over the Foxglove WebSocket protocol while it runs, on ADDR
    /// (IP:PORT; default 127.0.0.1:8765, loopback only). Give the scenario before this flag.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = recordings::live::DEFAULT_ADDR)]
    live: Option<std::net::SocketAddr>,
    /// Per-tick channels of the live view at this rate, Hz of simulated time; 0 sends every tick.
    #[arg(long, value_name = "HZ", allow_hyphen_values = true, default_value_t = recordings::live::DEFAULT_RATE_HZ, value_parser = hertz, requires = "live")]
    live_rate: f64,
}

impl LiveArgs {
    fn config(&self) -> Option<recordings::LiveConfig> {
        self.live.map(|addr| recordings::LiveConfig { addr, rate_hz: self.live_rate, ..Default::default() })
    }
}

/// What `rig run` and `rig sweep` start and where they write.
#[derive(Debug, clap::Args)]
struct LaunchArgs {
    /// Controller executable (default: `controller` next to `rig`; `egm-controller` for a
    /// scenario with `[egm] enabled`). Any program that takes `--rig NAME --scenario FILE` and
    /// speaks the contract of messages/README.md (or EGM). `none` with an EGM scenario: start no
    /// controller, the plant waits for an external EGM client at `egm.sensor_address`.
    #[arg(long, value_parser = Controller::from_flag)]
    controller: Option<Controller>,
    /// Simulated seconds to run, per case for a sweep (default: the scenario's).
    #[arg(long, allow_hyphen_values = true, value_parser = seconds)]
    duration: Option<f64>,
    /// Output directory (run: runs/<UTC time>-<rig>/, the recording is <DIR>/run.mcap; sweep:
    /// runs/sweep-<UTC time>/ with case-NN/{scenario.toml,run.mcap} and sweep.json).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct TimingArgs {
    /// Length of the timing run, s.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true, value_parser = seconds)]
    seconds: f64,
    /// Scenario (default: the default scenario without the strip, holding its start pose).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Controller executable (default: `controller` next to `rig`).
    #[arg(long, value_parser = Controller::from_flag)]
    controller: Option<Controller>,
    /// Output directory (default: runs/<UTC time>-<rig>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write the plant's summary JSON (all distributions) to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Let the plant busy-poll for the torque this long before sleeping, µs (scenario
    /// `loop.spin_wait_us`; default: the default scenario's).
    #[arg(long, allow_hyphen_values = true, value_parser = microseconds)]
    spin_us: Option<f64>,
    /// Let the controller busy-poll from this long before the state is due until this long
    /// after, µs (scenario `loop.controller_spin_us`; default: the default scenario's).
    #[arg(long, allow_hyphen_values = true, value_parser = microseconds)]
    controller_spin_us: Option<f64>,
    /// Let idle CPUs halt (do not hold /dev/cpu_dma_latency at 0; scenario `loop.idle_poll`).
    #[arg(long)]
    no_idle_poll: bool,
    /// The host-floor probe's period, µs (default: plant-sim's, 250; at most the loop's period)
    #[arg(long, conflicts_with = "no_host_probe")]
    probe_period_us: Option<u64>,
    /// Run without the host-floor probe (its threads wake every 250 µs on every CPU): for an A/B
    /// comparison of the loop alone (`tests/ab-timing.sh`). The miss attribution then has
    /// no host stalls to blame.
    #[arg(long)]
    no_host_probe: bool,
    #[command(flatten)]
    live: LiveArgs,
}

#[derive(Debug, clap::Args)]
struct SweepArgs {
    /// Base scenario (default: scenarios/default.toml).
    scenario: Option<PathBuf>,
    /// An axis: `section.field=v1,v2,...` (scenario field, TOML scalar values). Repeat for more.
    #[arg(long = "set", required = true, value_parser = sweep::parse_set)]
    axes: Vec<sweep::Axis>,
    /// Every combination of the axes' values (default: each axis varied alone around the base).
    #[arg(long)]
    grid: bool,
    /// Each case's rate of the Foxglove scene and transforms (`recording.scene_rate_hz`), Hz
    /// (default: 10, or the base scenario's own). Every per-tick channel is recorded whatever it is.
    #[arg(long, allow_hyphen_values = true, value_parser = positive_hertz)]
    scene_rate: Option<f64>,
    /// Which case recordings to write (the built-in controller's in-process cases), as
    /// `rig study`'s flag: `failing` (the default: a case with a non-zero exit status, recorded by
    /// running it again, bit for bit), `all` or `none`. The table's figures come from each case's
    /// ticks in memory either way. Cases with `--controller` always record.
    #[arg(long, value_enum, default_value = "failing")]
    recordings: study::file::Keep,
    #[command(flatten)]
    launch: LaunchArgs,
}

/// A flag's number in `unit`: finite, and > 0, or >= 0 where `zero_ok` (clap names the flag
/// when it refuses one, before anything starts).
fn flag_number(s: &str, zero_ok: bool, unit: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && (x > 0.0 || (zero_ok && x == 0.0)) => Ok(x),
        Ok(_) => Err(format!("must be a finite number of {unit} {}", if zero_ok { ">= 0" } else { "> 0" })),
        Err(_) => Err(format!("must be a number of {unit}")),
    }
}

/// A flag's rate, Hz, > 0 (`--scene-rate`).
fn positive_hertz(s: &str) -> Result<f64, String> {
    flag_number(s, false, "Hz")
}

/// A flag's length of time, s (`--duration`, `--seconds`).
/// `--mode`: one of the scenario's loop modes, by the name scenario files use (the help lists them).
fn mode_flag() -> impl clap::builder::TypedValueParser<Value = Mode> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Mode::ALL.map(Mode::name)).try_map(|s| s.parse::<Mode>())
}

fn seconds(s: &str) -> Result<f64, String> {
    flag_number(s, false, "seconds")
}

/// A flag's busy-poll time, µs (the scenario's range then bounds it by the period and the
/// torque budget).
fn microseconds(s: &str) -> Result<f64, String> {
    flag_number(s, true, "µs")
}

/// The live view's rate, Hz (0: every tick).
fn hertz(s: &str) -> Result<f64, String> {
    flag_number(s, true, "Hz")
}

/// `--live ADDR` must be free to listen on before anything starts (the plant binds it again
/// itself; a port taken in between fails the plant with the same message).
fn check_live(live: &recordings::LiveConfig, s: &scenarios::Scenario, path: &Path) -> anyhow::Result<()> {
    anyhow::ensure!(
        s.recording.enabled,
        "--live: the live view is fed by the recorder, and {} disables the recording (recording.enabled = false)",
        path.display()
    );
    std::net::TcpListener::bind(live.addr).map(drop).with_context(|| format!("--live {}: cannot listen there", live.addr))
}

/// A run length from the command line must give the plant at least one tick of the scenario's
/// period (`flag` names it in the message).
fn check_duration(flag: &str, duration_s: Option<f64>, s: &scenarios::Scenario, path: &Path) -> anyhow::Result<()> {
    if let Some(d) = duration_s {
        let period = s.loop_.period_s;
        anyhow::ensure!(d >= period, "{flag} {d}: shorter than one control period (loop.period_s = {period} s in {})", path.display());
    }
    Ok(())
}

/// `--controller PATH` must name an executable file.
fn check_controller(p: &Path) -> anyhow::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    let meta = std::fs::metadata(p).with_context(|| format!("--controller {}", p.display()))?;
    anyhow::ensure!(meta.is_file(), "--controller {}: not a file", p.display());
    anyhow::ensure!(meta.permissions().mode() & 0o111 != 0, "--controller {}: not executable", p.display());
    Ok(())
}

/// `--json FILE` is written after the run: its directory must exist before the run starts.
fn check_output_file(flag: &str, p: &Path) -> anyhow::Result<()> {
    anyhow::ensure!(!p.is_dir(), "{flag} {}: is a directory", p.display());
    let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    anyhow::ensure!(dir.is_dir(), "{flag} {}: directory {} does not exist", p.display(), dir.display());
    Ok(())
}

/// UTC time as `YYYYmmdd-HHMMSS`.
fn utc_stamp() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()) as libc::time_t;
    // SAFETY: gmtime_r writes into the tm we own.
    let tm = unsafe {
        let mut tm: libc::tm = std::mem::zeroed();
        libc::gmtime_r(&secs, &mut tm);
        tm
    };
    format!("{:04}{:02}{:02}-{:02}{:02}{:02}", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec)
}

/// Everything a run needs, every flag checked: nothing is started here.
fn prepare(
    rig: String,
    scenario: PathBuf,
    mode: Option<Mode>,
    (duration_flag, duration_s): (&str, Option<f64>),
    out: Option<PathBuf>,
    controller: Option<Controller>,
    live: Option<recordings::LiveConfig>,
) -> anyhow::Result<RigLaunch> {
    // Fail early, with file/line/field, before any process starts.
    let parsed = scenarios::Scenario::load(&scenario)?;
    check_duration(duration_flag, duration_s, &parsed, &scenario)?;
    if let Some(l) = &live {
        check_live(l, &parsed, &scenario)?;
    }
    match &controller {
        Some(Controller::ExternalEgm) => anyhow::ensure!(
            parsed.egm.enabled,
            "--controller none needs a scenario with [egm] enabled (an external EGM client answers the plant); {} has none",
            scenario.display()
        ),
        Some(Controller::Program(p)) => check_controller(p)?,
        None => {}
    }
    let lockstep = mode.unwrap_or(parsed.loop_.mode) == Mode::Lockstep;
    let dir = out.unwrap_or_else(|| Path::new("runs").join(format!("{}-{rig}", utc_stamp())));
    std::fs::create_dir_all(&dir).with_context(|| format!("--out {}: creating the output directory", dir.display()))?;
    let plant_bin = supervise::sibling_binary("plant-sim")?;
    let controller = match controller {
        Some(c) => c,
        None if parsed.egm.enabled => Controller::Program(supervise::sibling_binary("egm-controller")?),
        None => Controller::Program(supervise::sibling_binary("controller")?),
    };
    // The one strip-model cache `rig model build` fills too.
    let cache_dir = strip::cache::cache_dir();
    Ok(RigLaunch {
        rig,
        scenario,
        mode,
        duration_s,
        recording: dir.join("run.mcap"),
        plant_bin,
        controller,
        cache_dir,
        // Same CPU as plant-sim's lockstep loop.
        controller_cpu: lockstep.then(rig_process::rt::lockstep_cpu),
        quiet: false,
        live,
        host_probe: false,
        host_probe_period_us: None,
        connect_timeout: std::time::Duration::from_secs_f64(parsed.loop_.connect_timeout_s),
    })
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread().enable_all().build().context("starting the tokio runtime")
}

/// Supervise, print the summary (or the failure), return the exit code.
fn launch_and_report(l: &RigLaunch, timing: bool, json_out: Option<&Path>) -> anyhow::Result<i32> {
    eprintln!("rig {}: plant {} + controller {}, scenario {}", l.rig, l.plant_bin.display(), l.controller, l.scenario.display());
    // The summary's read-back overlaps the plant's teardown (not for `rig timing`, which prints
    // no recording summary).
    let (outcome, read_back) = runtime()?.block_on(supervise::supervise_reading_back(l, !timing))?;
    match &outcome.plant_summary {
        Some(v) => {
            if timing {
                // The targets hold on an otherwise idle machine: say how idle it was.
                let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
                let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
                println!("host: {cpus} CPUs, load average (1/5/15 min) {}", load.split_whitespace().take(3).collect::<Vec<_>>().join(" "));
                print!("{}", summary::timing_report(v));
                // Whose fault each miss is, from the recording's stage stamps (the one attribution
                // `rig report` uses too).
                if let Some(path) = &v.recording {
                    match recording_tools::read::Recording::open(Path::new(path)) {
                        Ok(rec) => {
                            print!("{}", recording_tools::attribution::format_table(&recording_tools::attribution::attribute(&rec.timing)))
                        }
                        Err(e) => eprintln!("rig: could not read back {path} for the miss attribution: {e:#}"),
                    }
                }
            }
            print!("{}", summary::run_summary(v));
            let path = v.recording.as_deref().filter(|_| !timing);
            let numbers = path.and_then(|path| match read_back.unwrap_or_else(|| recording_tools::cli::summary_numbers(Path::new(path))) {
                Ok(n) => Some(n),
                Err(e) => {
                    eprintln!("rig: could not read back {path}: {e:#}");
                    None
                }
            });
            print!("{}", summary::recording_summary(v, numbers.as_ref()));
            if let Some(p) = json_out {
                // Keys sorted at every level, as the plant's line.
                std::fs::write(p, serde_json::to_string_pretty(&v.to_value())?).with_context(|| format!("writing {}", p.display()))?;
            }
        }
        None => eprintln!("rig: the plant printed no summary"),
    }
    match &outcome.ending {
        Ending::Completed => {}
        Ending::Interrupted => eprintln!("rig: interrupted; both daemons stopped"),
        Ending::Terminated => eprintln!("rig: terminated; both daemons stopped"),
        Ending::PlantFailed(why) => eprintln!("rig: PLANT FAILED: {why}"),
        Ending::ControllerFailed(why) => eprintln!("rig: CONTROLLER FAILED: {why}"),
        // Said when it was found.
        Ending::NeverConnected(_) => {}
    }
    // The summary's last line: the exit status and why (README, "Exit status").
    let code = outcome.exit_code();
    println!("{}", summary::status_line(code, &outcome.ending, outcome.plant_summary.as_ref()));
    Ok(code)
}

/// The timing scenario: the default one without the strip, holding the start pose (no approach),
/// in real-time mode, written next to the recording.
fn timing_scenario(dir: &Path, a: &TimingArgs) -> anyhow::Result<PathBuf> {
    let default = scenarios::Scenario::default_file();
    let text = std::fs::read_to_string(&default).with_context(|| format!("reading {}", default.display()))?;
    let mut doc: toml::Table = text.parse().with_context(|| format!("parsing {}", default.display()))?;
    let table = |doc: &mut toml::Table, k: &str| -> toml::Table { doc.remove(k).and_then(|v| v.as_table().cloned()).unwrap_or_default() };
    let mut strip = table(&mut doc, "strip");
    strip.insert("enabled".into(), false.into());
    doc.insert("strip".into(), strip.into());
    let mut lp = table(&mut doc, "loop");
    lp.insert("mode".into(), "realtime".into());
    if let Some(us) = a.spin_us {
        lp.insert("spin_wait_us".into(), us.into());
    }
    if let Some(us) = a.controller_spin_us {
        lp.insert("controller_spin_us".into(), us.into());
    }
    if a.no_idle_poll {
        lp.insert("idle_poll".into(), false.into());
    }
    doc.insert("loop".into(), lp.into());
    let mut tr = table(&mut doc, "trajectory");
    // Hold the start pose for the whole run: the loop's timing, not the task, is under test.
    tr.insert("settle_s".into(), 1.0e6.into());
    doc.insert("trajectory".into(), tr.into());
    doc.insert("description".into(), "rig timing: default robot and controller, no strip, holding the start pose".into());
    std::fs::create_dir_all(dir)?;
    let path = dir.join("timing.toml");
    std::fs::write(&path, toml::to_string(&doc)?).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// `rig run --mode lockstep --in-process`: the run in this process, summarised as `rig run` does.
fn run_in_process(rig: &str, scenario: &Path, duration_s: Option<f64>, dir: &Path) -> anyhow::Result<i32> {
    let parsed = scenarios::Scenario::load(scenario)?;
    check_duration("--duration", duration_s, &parsed, scenario)?;
    std::fs::create_dir_all(dir).with_context(|| format!("--out {}: creating the output directory", dir.display()))?;
    let signals = plant_sim::signals::Signals::install_stop_only();
    let cache_dir = strip::cache::cache_dir();
    eprintln!("rig {rig}: plant tick + controller step in process (lockstep, no daemons), scenario {}", scenario.display());
    let recording = dir.join("run.mcap");
    let tuning = recordings::RecorderTuning::for_mode(scenarios::Mode::Lockstep);
    let keep = in_process::Keep { recording: Some(&recording), rows: false, quiet: false };
    let (v, _) = in_process::run(rig, scenario, duration_s, keep, tuning, |s| plant_sim::physics::Physics::new(s, &cache_dir), signals)?;
    print!("{}", summary::run_summary(&v));
    let numbers = match recording_tools::cli::summary_numbers(&recording) {
        Ok(n) => Some(n),
        Err(e) => {
            eprintln!("rig: could not read back {}: {e:#}", recording.display());
            None
        }
    };
    print!("{}", summary::recording_summary(&v, numbers.as_ref()));
    let ending = if v.stopped_by_signal { Ending::Interrupted } else { Ending::Completed };
    let outcome = supervise::Outcome { ending, plant_summary: Some(v) };
    let code = outcome.exit_code();
    println!("{}", summary::status_line(code, &outcome.ending, outcome.plant_summary.as_ref()));
    Ok(code)
}

/// `rig sweep`: every case in lockstep (in process, one per core at a time; with `--controller`, with both daemons, one after the other), then the table; exit 0 only if every case is clean, 4 if
/// every case reached its end but some with a safe stop, reflex, refused torque or an incomplete
/// recording, 1 if a case failed, 130/143 if the sweep was interrupted.
fn run_sweep(a: SweepArgs) -> anyhow::Result<i32> {
    let base_path = a.scenario.unwrap_or_else(scenarios::Scenario::default_file);
    let base = sweep::load_base(&base_path)?;
    let dir = a.launch.out.unwrap_or_else(|| Path::new("runs").join(format!("sweep-{}", utc_stamp())));
    let cases = sweep::cases(&a.axes, a.grid);
    // Every case's scenario is written and checked before the first run starts.
    let mut planned = Vec::with_capacity(cases.len());
    for (n, case) in cases.iter().enumerate() {
        let case_dir = dir.join(format!("case-{n:02}"));
        std::fs::create_dir_all(&case_dir).with_context(|| format!("--out {}: creating {}", dir.display(), case_dir.display()))?;
        let path = case_dir.join("scenario.toml");
        let label = sweep::label(&a.axes, case);
        let mut doc = sweep::case_scenario(&base, &a.axes, case);
        doc.insert("description".into(), format!("rig sweep case {n}: {} with {label}", base_path.display()).into());
        let mut flags = sweep::set_flags(&a.axes, case);
        flags.extend(sweep::set_scene_rate(&mut doc, &a.axes, a.scene_rate));
        std::fs::write(&path, toml::to_string(&doc)?).with_context(|| format!("writing {}", path.display()))?;
        let s = scenarios::Scenario::load(&path).map_err(|e| sweep::blame_flags(e, &flags))?;
        check_duration("--duration", a.launch.duration, &s, &path)?;
        planned.push((case_dir, path, label));
    }
    let n_cases = planned.len();
    let done: Vec<(sweep::CaseResult, bool)> = if let Some(controller) = &a.launch.controller {
        // A controller of the user's: each case with both daemons over iceoryx2, one after the
        // other (a Ctrl-C or SIGTERM stops the sweep, not just the case).
        let rt = runtime()?;
        let mut done = Vec::with_capacity(n_cases);
        for (n, (case_dir, path, label)) in planned.iter().enumerate() {
            let mut l = prepare(
                supervise::unique_rig_name(),
                path.clone(),
                Some(Mode::Lockstep),
                ("--duration", a.launch.duration),
                Some(case_dir.clone()),
                Some(controller.clone()),
                None,
            )?;
            l.quiet = true;
            let outcome = rt.block_on(supervise::supervise(&l))?;
            let rolling = recording_tools::cli::summary_numbers(&l.recording).ok().and_then(|n| n.rolling);
            let (result, stopped) = case_result(n, n_cases, label, path, Some(&l.recording), rolling, outcome);
            done.push((result, stopped));
            if stopped {
                break;
            }
        }
        done
    } else {
        // The built-in controller: every case in process, one per core at a time.
        let signals = plant_sim::signals::Signals::install_stop_only();
        let cache_dir = strip::cache::cache_dir();
        let strips = sweep::SharedStrips::new(&cache_dir);
        sweep::run_cases(&planned, |n, (case_dir, path, label)| {
            let recording = case_dir.join("run.mcap");
            let rig = format!("sweep-case-{n:02}");
            let tuning = recordings::RecorderTuning::for_mode(scenarios::Mode::Lockstep);
            let all = a.recordings == study::file::Keep::All;
            let keep = in_process::Keep { recording: all.then_some(recording.as_path()), rows: true, quiet: true };
            let ran = in_process::run(&rig, path, a.launch.duration, keep, tuning.clone(), |s| strips.physics(s), signals);
            let (ending, summary, rows) = match ran {
                Ok((v, rows)) if v.stopped_by_signal => (Ending::Interrupted, Some(v), rows),
                Ok((v, rows)) => (Ending::Completed, Some(v), rows),
                Err(e) => (Ending::PlantFailed(format!("{e:#}")), None, None),
            };
            let outcome = supervise::Outcome { ending, plant_summary: summary };
            let failing = outcome.exit_code() != 0 && outcome.plant_summary.is_some() && matches!(outcome.ending, Ending::Completed);
            // A failing case kept by `--recordings failing` runs again with its recorder: lockstep in
            // process is deterministic, the file is that very run.
            let recorded = if all {
                true
            } else if failing && a.recordings == study::file::Keep::Failing {
                let again = in_process::Keep { recording: Some(&recording), rows: false, quiet: true };
                in_process::run(&rig, path, a.launch.duration, again, tuning, |s| strips.physics(s), signals).is_ok()
            } else {
                false
            };
            let rolling = rows.as_ref().and_then(|r| r.rolling_numbers());
            let recording = (recorded && recording.exists()).then_some(recording.as_path());
            case_result(n, n_cases, label, path, recording, rolling, outcome)
        })
    };
    let interrupted = done.iter().any(|(_, stopped)| *stopped).then_some(130);
    if interrupted.is_some() {
        eprintln!("rig sweep: interrupted");
    }
    let results: Vec<sweep::CaseResult> = done.into_iter().map(|(r, _)| r).collect();
    print!("{}", sweep::table(&results));
    let json = dir.join("sweep.json");
    std::fs::write(&json, serde_json::to_string_pretty(&results)?).with_context(|| format!("writing {}", json.display()))?;
    let kept = results.iter().filter(|r| r.recording.is_some()).count();
    println!("cases, {kept} recording(s) and {} in {}", json.file_name().unwrap_or_default().to_string_lossy(), dir.display());
    Ok(interrupted.unwrap_or_else(|| sweep::sweep_exit_code(&results)))
}

/// One sweep case's row from how it ended, its rolling-phase figures and its recording if written;
/// true if it was stopped by a signal.
fn case_result(
    n: usize,
    n_cases: usize,
    label: &str,
    path: &Path,
    recording: Option<&Path>,
    rolling: Option<recording_tools::report::RollingNumbers>,
    outcome: supervise::Outcome,
) -> (sweep::CaseResult, bool) {
    let exit_code = outcome.exit_code();
    let line = summary::status_line(exit_code, &outcome.ending, outcome.plant_summary.as_ref());
    let status = line.split_once(": ").and_then(|(_, rest)| rest.split_once(": ")).map_or(line.clone(), |(_, why)| why.to_string());
    eprintln!("rig sweep: case {}/{n_cases}: {label}: {line}", n + 1);
    let summary = outcome.plant_summary.as_ref();
    let stopped = matches!(outcome.ending, Ending::Interrupted | Ending::Terminated);
    let result = sweep::CaseResult {
        label: label.to_string(),
        scenario: path.to_path_buf(),
        recording: recording.map(Path::to_path_buf),
        exit_code,
        status,
        misses: summary.map(|v| v.misses),
        safe_stops: summary.map(|v| v.safe_stops),
        force_error_max_n: rolling.as_ref().and_then(|r| r.force_error_max_abs_n),
        force_error_rms_n: rolling.as_ref().and_then(|r| r.force_error_rms_n),
        bond_share: rolling.as_ref().and_then(|r| r.bond_pressure_share),
        bond_weakest_pa: rolling.as_ref().and_then(|r| r.bond_weakest_pa_at_z_m).map(|w| w[0]),
        bond_weakest_z_m: rolling.as_ref().and_then(|r| r.bond_weakest_pa_at_z_m).map(|w| w[1]),
    };
    (result, stopped)
}

fn main() {
    rig_process::logging::init_stderr();
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Run(a) => (|| {
            let rig = supervise::unique_rig_name();
            let mut scenario = a.scenario.unwrap_or_else(scenarios::Scenario::default_file);
            let dir = a.launch.out.unwrap_or_else(|| Path::new("runs").join(format!("{}-{rig}", utc_stamp())));
            if !a.set.is_empty() {
                scenario = sweep::write_overridden(&scenario, &a.set, &dir.join("scenario.toml"))?;
            }
            if a.in_process {
                anyhow::ensure!(a.mode == Some(Mode::Lockstep), "--in-process runs lockstep only: give --mode lockstep");
                anyhow::ensure!(a.launch.controller.is_none(), "--in-process runs the built-in controller; --controller needs the daemons");
                anyhow::ensure!(a.live.live.is_none(), "--in-process has no live view (the live view needs the plant daemon)");
                return run_in_process(&rig, &scenario, a.launch.duration, &dir);
            }
            let l = prepare(rig, scenario, a.mode, ("--duration", a.launch.duration), Some(dir), a.launch.controller, a.live.config())?;
            launch_and_report(&l, false, None)
        })(),
        Cmd::Timing(a) => (|| {
            if let Some(j) = &a.json {
                check_output_file("--json", j)?;
            }
            let rig = supervise::unique_rig_name();
            let dir = a.out.clone().unwrap_or_else(|| Path::new("runs").join(format!("{}-{rig}", utc_stamp())));
            let scenario = match a.scenario.clone() {
                Some(s) => {
                    if a.spin_us.is_some() || a.controller_spin_us.is_some() || a.no_idle_poll {
                        tracing::warn!("--spin-us/--controller-spin-us/--no-idle-poll apply to the built-in timing scenario only; {} keeps its own [loop] settings", s.display());
                    }
                    s
                }
                None => {
                    let path = timing_scenario(&dir, &a)?;
                    // the spin flags go into the scenario: its ranges bound them, named as flags
                    let flags: Vec<(String, String)> = [
                        ("loop.spin_wait_us", "--spin-us", a.spin_us),
                        ("loop.controller_spin_us", "--controller-spin-us", a.controller_spin_us),
                    ]
                    .into_iter()
                    .filter_map(|(key, flag, v)| v.map(|us| (key.to_string(), format!("{flag} {us}"))))
                    .collect();
                    scenarios::Scenario::load(&path).map_err(|e| sweep::blame_flags(e, &flags))?;
                    path
                }
            };
            let live = a.live.config();
            let mut l = prepare(rig, scenario, Some(Mode::Realtime), ("--seconds", Some(a.seconds)), Some(dir), a.controller, live)?;
            l.host_probe = !a.no_host_probe;
            l.host_probe_period_us = a.probe_period_us;
            launch_and_report(&l, true, a.json.as_deref())
        })(),
        Cmd::Sweep(a) => run_sweep(a),
        Cmd::Study { cmd } => study::cli::run(cmd, utc_stamp),
        Cmd::Robot { cmd } => robot::cli::run(cmd).map(|_| 0),
        Cmd::Model { cmd } => strip::cli::run(cmd).map(|_| 0),
        Cmd::Replay(a) => recording_tools::cli::replay(a).map(|_| 0),
        Cmd::Report(a) => recording_tools::cli::report(a).map(|_| 0),
        Cmd::Compare(a) => recording_tools::cli::compare(a).map(|_| 0),
        Cmd::Design(a) => design::cli::run(a).map(|_| 0),
    };
    match result {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("rig: error: {e:#}");
            // `rig replay` as a plant: the daemons' statuses for a taken rig name or unusable shared memory.
            std::process::exit(e.downcast_ref::<rig_process::host::HostError>().map_or(1, rig_process::host::HostError::exit_code));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_args(args: &[&str]) -> Result<RunArgs, clap::Error> {
        match Cli::try_parse_from([&["rig", "run"][..], args].concat())?.cmd {
            Cmd::Run(a) => Ok(a),
            other => panic!("not a run: {other:?}"),
        }
    }

    #[test]
    fn the_mode_is_parsed_once_into_the_scenarios_enum_and_a_bad_one_names_the_choices() {
        assert_eq!(run_args(&["--mode", "lockstep"]).unwrap().mode, Some(Mode::Lockstep));
        assert_eq!(run_args(&["--mode", "realtime"]).unwrap().mode, Some(Mode::Realtime));
        assert_eq!(run_args(&[]).unwrap().mode, None);
        let e = run_args(&["--mode", "fast"]).unwrap_err().to_string();
        assert!(e.contains("'fast'") && e.contains("[possible values: realtime, lockstep]"), "{e}");
    }

    #[test]
    fn controller_none_is_the_external_egm_client_and_anything_else_a_program() {
        assert_eq!(run_args(&["--controller", "none"]).unwrap().launch.controller, Some(Controller::ExternalEgm));
        assert_eq!(run_args(&["--controller", "./none"]).unwrap().launch.controller, Some(Controller::Program(PathBuf::from("./none"))));
        assert_eq!(run_args(&[]).unwrap().launch.controller, None);
    }
}
