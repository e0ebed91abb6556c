//! `controller --rig NAME --scenario FILE`: the force controller daemon (see `controller::daemon`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

#[derive(Debug, Parser)]
#[command(name = "controller", about = "Hybrid impedance force controller daemon of the weatherstrip rig")]
struct Args {
    /// Rig name (the service prefix shared with plant-sim).
    #[arg(long)]
    rig: String,
    /// Scenario TOML file (references, gains, robot model).
    #[arg(long)]
    scenario: PathBuf,
    /// SCHED_FIFO priority of the control thread (1-99, when permitted); 0 keeps the default
    /// scheduler. On a VM whose vCPUs are themselves time-shared, FIFO can lengthen wake-ups.
    #[arg(long, default_value_t = 80)]
    rt_priority: i32,
    /// Testing only: pretend to speak this contract version.
    #[arg(long, hide = true)]
    contract_version: Option<u32>,
}

fn main() -> ExitCode {
    rig_process::logging::init_stderr();
    rig_process::host::exit_on_sigbus("controller");
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A host problem is said once, below; other errors also go to the log.
            if e.downcast_ref::<rig_process::host::HostError>().is_none() {
                tracing::error!("{e:#}");
            }
            // Tolerates a closed stderr (a launcher that died).
            rig_process::host::print_stderr(&format!("controller: error: {e:#}\n"));
            // Shared memory unusable has its own status (71, `rig_process::host`), other errors 1.
            let code = e.downcast_ref::<rig_process::host::HostError>().map_or(1, rig_process::host::HostError::exit_code);
            ExitCode::from(code as u8)
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    messages::services::validate_rig_name(&args.rig)?;
    let scenario = scenarios::Scenario::load(&args.scenario)?;
    // Before any node: the rig's iceoryx2 configuration and room in /dev/shm.
    rig_process::host::prepare()?;
    let mut cfg = controller::daemon::DaemonConfig::new(&args.rig, scenario);
    cfg.rt_priority = args.rt_priority;
    if let Some(v) = args.contract_version {
        cfg.contract_version = v;
    }
    controller::daemon::run(&cfg)?;
    Ok(())
}
