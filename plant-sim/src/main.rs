//! `plant-sim --rig NAME --scenario FILE [--mode realtime|lockstep] [--duration S] [--out FILE.mcap] [--cache-dir DIR]
//! [--live ADDR [--live-rate HZ]]`
//! `plant-sim --rig NAME --scenario FILE [--mode realtime|lockstep] [--duration S] [--out FILE.mcap] [--cache-dir DIR] [--host-probe [--host-probe-period-us US]]`
//!
//! Runs the plant daemon; once its recording is finished prints one line of JSON with the run's
//! summary on stdout and closes stdout, then releases its iceoryx2 ports and exits.
//! Exit status: 0 run completed, 1 error, 69 the rig name is held by a live plant, 71 shared
//! memory unusable (`rig_process::host`).

use std::path::PathBuf;

use clap::Parser;
use scenarios::Mode;

#[derive(Debug, Parser)]
#[command(name = "plant-sim", about = "Plant daemon of the weatherstrip rig: robot (+ strip) simulation, the 1 kHz clock master")]
struct Args {
    /// Rig name: the prefix of every iceoryx2 service (the controller must use the same).
    #[arg(long)]
    rig: String,
    /// Scenario TOML file.
    #[arg(long)]
    scenario: PathBuf,
    /// Override the scenario's loop mode.
    #[arg(long)]
    mode: Option<Mode>,
    /// Simulated seconds to run (default: scenario's loop.duration_s, else the trajectory's length).
    #[arg(long)]
    duration: Option<f64>,
    /// MCAP recording path (default runs/<time>-<rig>/run.mcap).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Cache directory for reduced strip models (default: `strip::cache::cache_dir()`, the one
    /// `rig model build` fills: `$RIG_CACHE_DIR/strip`, else `target/strip-cache` in a checkout,
    /// else `~/.cache/rig/strip`).
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Serve the recording's channels over the Foxglove WebSocket protocol on this address
    /// (`rig run --live` passes 127.0.0.1:8765 unless told otherwise).
    #[arg(long)]
    live: Option<std::net::SocketAddr>,
    /// Per-tick channels of the live view at this rate, Hz of simulated time; 0: every tick.
    #[arg(long, default_value_t = recordings::live::DEFAULT_RATE_HZ, requires = "live")]
    live_rate: f64,
    /// Run the host-floor probe beside the loop (a thread per CPU waking on absolute deadlines;
    /// real time only): its latency and stalls go into the summary and `/timing`.
    #[arg(long)]
    host_probe: bool,
    /// The probe's period, µs (at most the loop's period; 10 µs at least).
    #[arg(long, default_value_t = plant_sim::probe::DEFAULT_PERIOD_NS / 1000, requires = "host_probe")]
    host_probe_period_us: u64,
}

fn main() {
    rig_process::logging::init_stderr();
    rig_process::host::exit_on_sigbus("plant-sim");
    let a = Args::parse();
    let opts = plant_sim::run::RunOptions {
        rig: a.rig.clone(),
        scenario_path: a.scenario,
        mode: a.mode,
        duration_s: a.duration,
        out: a.out,
        cache_dir: a.cache_dir.unwrap_or_else(strip::cache::cache_dir),
        live: a.live.map(|addr| recordings::LiveConfig { addr, rate_hz: a.live_rate, ..Default::default() }),
        host_probe: a.host_probe,
        host_probe_period_ns: a.host_probe_period_us * 1000,
    };
    let printed = plant_sim::run::run_reporting(&opts, |summary| {
        // Both writes tolerate a closed pipe: a launcher killed with SIGKILL leaves its end closed.
        rig_process::host::print_stdout(&format!("{}\n", summary.to_summary(&a.rig).to_line()));
        // Its last line: the end of stdout tells rig that the summary is whole and the recording
        // finished, while the plant still tears down its ports (rig reads the recording back
        // meanwhile).
        close_stdout();
    });
    match printed {
        Ok(_) => {}
        Err(e) => {
            rig_process::host::print_stderr(&format!("plant-sim: error: {e:#}\n"));
            // A host problem (rig name taken, shared memory unusable) has its own status.
            let code = e.downcast_ref::<rig_process::host::HostError>().map_or(1, rig_process::host::HostError::exit_code);
            std::process::exit(code);
        }
    }
}

/// Points stdout at /dev/null: the pipe to rig ends (EOF) while the process lives on, and a stray
/// write later goes nowhere rather than failing.
fn close_stdout() {
    // SAFETY: open/dup2/close on descriptors this process owns; fd 1 stays valid throughout.
    unsafe {
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_WRONLY | libc::O_CLOEXEC);
        if null >= 0 {
            libc::dup2(null, libc::STDOUT_FILENO);
            libc::close(null);
        }
    }
}
