//! The plant's start, in the order `run` takes it: the strip model, contact tables and recorder
//! on a set-up thread beside the iceoryx2 ports and the liveness watch on this one; then this
//! thread's scheduling for the loop (pinning, nice value, SCHED_FIFO, locked memory, idle
//! polling); then the host probe of a real-time run.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use scenarios::{Mode, Scenario};

use super::recording::{open_recorder, RecordingAbout};
use super::RunOptions;
use crate::physics::Physics;
use crate::recording::Recorder;
use rig_process::liveness::PeerWatch;
use rig_process::ports::PlantPorts;
use rig_process::rt;

/// Nice value of the lockstep loop thread: CFS weight ~9.3x a nice-0 thread, so a CPU-bound job
/// sharing the lockstep CPU takes ~10 % of it instead of ~50 % (measured with a concurrent rustc
/// on the 2-vCPU VM: lockstep default scenario median 21.9x -> 26.5x real time, 5 runs each).
const LOCKSTEP_NICE: i32 = -10;

/// Everything the loop needs that takes time to make, and how long each part took.
pub(super) struct SetUp {
    pub physics: Physics,
    pub recorder: Option<Recorder>,
    pub ports: PlantPorts,
    pub watch: PeerWatch,
    pub t_physics: Duration,
    pub t_recorder: Duration,
    pub t_ports: Duration,
}

/// What the set-up reads: the run's options and scenario, the mode it runs in, where it records
/// (None: not at all) and the CPU a lockstep loop will be pinned to.
pub(super) struct SetUpInputs<'a> {
    pub opts: &'a RunOptions,
    pub scenario: &'a Scenario,
    pub scenario_text: &'a str,
    pub mode: Mode,
    pub recording: &'a Option<PathBuf>,
    pub lockstep_cpu: usize,
}

/// The strip model and contact tables, then the recorder (whose scene needs the model), on a
/// set-up thread while this one opens the iceoryx2 ports and the liveness watch: neither needs
/// the other, and each took about half of the plant's start-up (README, "Lockstep start-up").
/// Without a thread, one after the other. The model's refusal comes first, as when the two ran
/// one after the other.
///
/// Lockstep: the recorder's writer thread inherits the affinity of the thread that spawns it; the
/// set-up thread keeps itself off the CPU the loop and the controller are pinned to before it
/// starts the recorder (ZSTD compression costs ~10 µs per tick, which would otherwise come out of
/// the lockstep tick whenever the scheduler places the writer there).
pub(super) fn set_up_side_by_side(i: &SetUpInputs) -> anyhow::Result<SetUp> {
    let physics_then_recorder = || -> anyhow::Result<(Physics, Option<Recorder>, Duration, Duration)> {
        let t0 = std::time::Instant::now();
        // With every CPU, as on the main thread: a strip model built on a cache miss uses faer's
        // pool, which takes its size from the affinity of the thread that first uses it (the
        // bits do not depend on that size: the build's task count is fixed, strip::BUILD_TASKS).
        let physics = Physics::new(i.scenario, &i.opts.cache_dir)?;
        let t_physics = t0.elapsed();
        if i.mode == Mode::Lockstep && !rt::keep_thread_off_cpu(i.lockstep_cpu) {
            tracing::warn!("could not keep the recorder off the lockstep CPU {}", i.lockstep_cpu);
        }
        let recorder = match i.recording {
            Some(path) => {
                let about = RecordingAbout {
                    rig: &i.opts.rig,
                    mode: i.mode,
                    scenario_path: &i.opts.scenario_path,
                    scenario_text: i.scenario_text.to_string(),
                    transport: None,
                };
                Some(open_recorder(path, &about, i.scenario, &physics, i.opts.live.clone())?)
            }
            None => None,
        };
        Ok((physics, recorder, t_physics, t0.elapsed() - t_physics))
    };
    let ports_and_watch = || -> anyhow::Result<(PlantPorts, PeerWatch, Duration)> {
        let t0 = std::time::Instant::now();
        // Liveness of the controllers' nodes, on its own thread (started before the loop's
        // real-time set-up, so it keeps the normal scheduling policy), setting up while this
        // thread opens the ports.
        let watch = PeerWatch::start(&i.opts.rig, "plant-sim-watch", rig_process::liveness::Watched::Controllers)?;
        let ports = PlantPorts::open(&i.opts.rig, "plant-sim")?;
        let watch = watch.ready()?;
        Ok((ports, watch, t0.elapsed()))
    };
    let (set_up, opened) = std::thread::scope(|scope| {
        match std::thread::Builder::new().name("plant-setup".into()).spawn_scoped(scope, physics_then_recorder) {
            Ok(helper) => {
                let opened = ports_and_watch();
                (helper.join().unwrap_or_else(|_| Err(anyhow::anyhow!("the plant's set-up thread panicked"))), opened)
            }
            Err(_) => (physics_then_recorder(), ports_and_watch()),
        }
    });
    let (physics, recorder, t_physics, t_recorder) = set_up?;
    let (ports, watch, t_ports) = opened?;
    Ok(SetUp { physics, recorder, ports, watch, t_physics, t_recorder, t_ports })
}

/// This thread's scheduling for the loop, after the recorder's writer thread exists (it keeps
/// the normal policy). Real time: SCHED_FIFO 80 and locked memory. Lockstep keeps the normal
/// policy: nothing there is time-critical, and a SCHED_FIFO waker hands over to the controller
/// across CPUs (waking a halted vCPU) instead of on its own CPU, which measured 50 µs instead of
/// 15 µs per round trip on a 2-vCPU VM; it is pinned to `lockstep_cpu` at [`LOCKSTEP_NICE`].
/// Memory is locked in real time only: a lockstep run has no deadline a page fault could miss,
/// and locking populates every mapping at once (each thread's whole stack among them), about
/// 5 ms of the lockstep start-up's critical path in the kernel (perf, 2026-12-06).
pub(super) fn schedule_loop_thread(mode: Mode, lockstep_cpu: usize, idle_poll: bool) -> rt::RtSetup {
    let rt_setup = rt::setup_thread((mode == Mode::Realtime).then_some(80), mode == Mode::Realtime);
    if mode == Mode::Lockstep {
        let cpu = lockstep_cpu;
        if !rt::pin_thread_to_cpu(cpu) {
            tracing::warn!("could not pin the lockstep loop to CPU {cpu}");
        }
        // A lockstep run is CPU-bound on its one CPU; at nice 0 a compiler or test job scheduled
        // there takes half of it. The controller already runs SCHED_FIFO; the loop gets a larger
        // CFS weight instead (no real-time hand-over semantics, see above).
        if !rt::set_thread_nice(LOCKSTEP_NICE) {
            tracing::debug!("could not set the lockstep loop's nice value to {LOCKSTEP_NICE} (needs CAP_SYS_NICE)");
        }
    }
    // Both modes: lockstep hands over twice a tick too, and each hand-over to a halted vCPU
    // costs its wake-up.
    if idle_poll {
        match (rt::hold_idle_poll(), rt::cpuidle_driver()) {
            (Ok(()), Some(driver)) => tracing::info!(
                "idle CPUs poll while the plant runs (PM QoS /dev/cpu_dma_latency = 0 µs, cpuidle driver {driver}; loop.idle_poll)"
            ),
            (Ok(()), None) => tracing::info!(
                "PM QoS /dev/cpu_dma_latency held at 0 µs (loop.idle_poll), but this kernel has no cpuidle driver to read it: idle CPUs halt anyway (only loop.spin_wait_us and loop.controller_spin_us shorten wake-ups)"
            ),
            (Err(e), _) => tracing::warn!("could not hold /dev/cpu_dma_latency at 0 µs ({e}): idle CPUs may halt, wake-ups cost more"),
        }
    }
    if mode == Mode::Realtime && (!rt_setup.sched_fifo || !rt_setup.mlockall) {
        tracing::warn!(
            "real-time set-up incomplete: SCHED_FIFO {}, mlockall {} (needs CAP_SYS_NICE/rtprio and memlock limits); running best-effort",
            if rt_setup.sched_fifo { "on" } else { "refused" },
            if rt_setup.mlockall { "on" } else { "refused" }
        );
    }
    rt_setup
}

/// The host-floor probe, one thread per CPU this process may use (README, "Timing"): real-time
/// runs that ask for it only (a lockstep run has no host floor to measure; it says so).
pub(super) fn start_probe(opts: &RunOptions, mode: Mode, period_ns: u64) -> anyhow::Result<Option<crate::probe::Probe>> {
    match (opts.host_probe, mode) {
        (true, Mode::Realtime) => {
            let cpus = crate::probe::allowed_cpus();
            let probe_period_ns = opts.host_probe_period_ns.clamp(10_000, period_ns);
            let p = crate::probe::Probe::start(&cpus, probe_period_ns).context("starting the host probe")?;
            tracing::info!(
                ?cpus,
                probe_period_us = probe_period_ns / 1000,
                "host probe running (SCHED_FIFO {} when permitted)",
                crate::probe::PROBE_PRIORITY
            );
            Ok(Some(p))
        }
        (true, Mode::Lockstep) => {
            tracing::warn!("--host-probe applies to real-time runs only; not started in lockstep");
            Ok(None)
        }
        _ => Ok(None),
    }
}
