//! One plant run from start to summary: scenario, ports, recorder, real-time set-up, the loop,
//! shutdown. `main.rs` only parses arguments and prints.

use std::path::{Path, PathBuf};

use anyhow::Context;
use recordings::PlantSummary;
use scenarios::{Mode, Scenario};

use crate::driver::realtime::{LoopParams, PlantLoop};
use crate::physics::Physics;
use crate::recording::{EventKind, EventRecord, Recorder, RecorderConfig};
use crate::stats::LoopStats;
use rig_process::rt;

/// Nice value of the lockstep loop thread: CFS weight ~9.3x a nice-0 thread, so a CPU-bound job
/// sharing the lockstep CPU takes ~10 % of it instead of ~50 % (measured with a concurrent rustc
/// on the 2-vCPU VM: lockstep default scenario median 21.9x -> 26.5x real time, 5 runs each).
const LOCKSTEP_NICE: i32 = -10;

/// Options of one plant run (the command line of `plant-sim`).
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub rig: String,
    pub scenario_path: PathBuf,
    pub mode: Option<Mode>,
    /// Simulated seconds to run; None = the scenario's `loop.duration_s`, or the trajectory's length.
    pub duration_s: Option<f64>,
    /// MCAP file; None = `runs/<unix time>-<rig>/run.mcap`.
    pub out: Option<PathBuf>,
    pub cache_dir: PathBuf,
    /// Serve the recording's channels live (Foxglove WebSocket); needs the recording enabled.
    pub live: Option<recordings::LiveConfig>,
    /// Run the host-floor probe beside the loop (real time only; `rig timing` asks for it).
    pub host_probe: bool,
    /// Its period, ns (at most the loop's; [`crate::probe::DEFAULT_PERIOD_NS`]).
    pub host_probe_period_ns: u64,
}

/// Run length when neither the command line nor the scenario sets one: the nominal trajectory
/// (settle, approach from `approach_height_mm` at `approach_speed_mm_s`, force ramp, dwell, roll,
/// ramp-down, lift) plus 0.2 s; the roll along a contour takes its time law's time.
pub fn nominal_duration_s(s: &Scenario) -> f64 {
    let t = &s.trajectory;
    let approach = if t.approach_speed_mm_s > 0.0 { t.approach_height_mm / t.approach_speed_mm_s } else { 0.0 };
    let roll_s = scenarios::contour::TimeLaw::roll_s(s);
    t.settle_s + approach + t.force_ramp_s + t.dwell_s + roll_s + t.ramp_down_s + t.lift_s + 0.2
}

/// How long a run lasts: its simulated seconds and the whole control ticks they round to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunLength {
    /// Simulated time, s.
    pub duration_s: f64,
    /// Ticks of `loop.period_s`: round(duration_s / period_s).
    pub n_ticks: u64,
}

/// A run length that is not a positive, finite time.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("duration {0} s must be positive")]
pub struct RunLengthError(pub f64);

/// The run-length rule of every driver (the `plant-sim` daemon, `rig run --in-process`, `rig
/// sweep`'s cases): `duration_s` when given (the command line), else the scenario's
/// `loop.duration_s` when it is positive, else [`nominal_duration_s`]; the ticks are the nearest
/// whole number of `loop.period_s` (a run never ends mid-tick).
pub fn run_length(s: &Scenario, duration_s: Option<f64>) -> Result<RunLength, RunLengthError> {
    let l = &s.loop_;
    let duration_s = duration_s.or((l.duration_s > 0.0).then_some(l.duration_s)).unwrap_or_else(|| nominal_duration_s(s));
    if !(duration_s.is_finite() && duration_s > 0.0) {
        return Err(RunLengthError(duration_s));
    }
    Ok(RunLength { duration_s, n_ticks: (duration_s / l.period_s).round() as u64 })
}

/// Default recording path of a rig.
pub fn default_recording_path(rig: &str) -> PathBuf {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    Path::new("runs").join(format!("{secs}-{rig}")).join("run.mcap")
}

/// Result of a run, printed by `plant-sim` as one JSON line.
pub struct RunSummary {
    pub stats: LoopStats,
    pub recording: Option<PathBuf>,
    pub drops: u64,
    /// Why the recorder ended the recording before the run ended (disk full, write error), as
    /// its `finish` reports it; the file then ends after its last complete chunk.
    pub recording_stopped_early: Option<String>,
    pub mode: Mode,
    pub rt: rt::RtSetup,
    /// The live view's address and what it sent and dropped, if it ran.
    pub live: Option<(std::net::SocketAddr, recordings::LiveSummary)>,
    /// What the host-floor probe measured, per CPU (None: it did not run).
    pub probe: Option<Vec<crate::probe::CpuReport>>,
    /// The EGM counters, when the scenario's `[egm]` is enabled.
    pub egm: Option<crate::driver::egm::EgmStats>,
}

impl RunSummary {
    /// The typed summary `plant-sim` prints as its last line ([`PlantSummary::to_line`]).
    pub fn to_summary(&self, rig: &str) -> PlantSummary {
        use recordings::plant_summary::{EgmCounters, HostProbe, LiveReport};
        let s = &self.stats;
        let us = |ns: u64| ns as f64 * 1e-3;
        let edges = [0.0, 10.0, 20.0, 30.0, 50.0, 75.0, 100.0, 150.0, 200.0, 300.0, 500.0, 1000.0, 2000.0];
        PlantSummary {
            rig: rig.to_string(),
            mode: self.mode,
            ticks: s.ticks,
            misses: s.misses,
            safe_stops: s.safe_stops,
            refusals: s.refusals,
            reflexes: s.reflexes,
            foreign_answers: s.foreign_answers,
            first_safe_stop_tick: s.first_safe_stop_tick,
            first_reflex_tick: s.first_reflex_tick,
            first_refusal_tick: s.first_refusal_tick,
            controller_ended: s.controller_ended,
            overruns: s.overruns,
            lost_wakeups: s.lost_wakeups,
            lost_wakeups_in_a_row: s.lost_wakeups_in_a_row,
            rt_p50_us: us(s.round_trip.quantile_ns(0.5)),
            rt_p99_us: us(s.round_trip.quantile_ns(0.99)),
            rt_max_us: us(s.round_trip.max_ns()),
            recording: self.recording.as_ref().map(|p| p.display().to_string()),
            drops: self.drops,
            recording_stopped_early: self.recording_stopped_early.clone(),
            live: self.live.map(|(addr, l)| LiveReport { addr: addr.to_string(), sent: l.sent, dropped: l.dropped }),
            wall_s: s.wall_s,
            sim_s: s.sim_s,
            speed_factor: if s.active_wall_s > 0.0 { s.active_sim_s / s.active_wall_s } else { 0.0 },
            stopped_by_signal: s.stopped_by_signal,
            sched_fifo: self.rt.sched_fifo,
            mlockall: self.rt.mlockall,
            round_trip: s.round_trip.distribution(&edges),
            jitter: s.jitter.distribution(&edges),
            plant_compute: s.plant_compute.distribution(&edges),
            controller_compute: s.controller_compute.distribution(&edges),
            host_probe: self.probe.as_ref().map(|cpus| HostProbe {
                stall_threshold_us: crate::probe::HOST_STALL_NS as f64 * 1e-3,
                cpus: cpus.iter().map(|c| c.report(&edges)).collect(),
            }),
            egm: self.egm.map(|e| EgmCounters {
                accepted: e.accepted,
                refused: e.refused,
                cycles: e.cycles,
                session_ended_tick: e.session_ended_tick,
            }),
        }
    }
}

/// What a recording's metadata says about the run besides the scenario.
pub struct RecordingAbout<'a> {
    pub rig: &'a str,
    pub mode: Mode,
    pub scenario_path: &'a Path,
    /// The scenario file's text as read (recorded whole).
    pub scenario_text: String,
    /// `Some("in-process")` for a run without daemons; None: the plant's own (iceoryx2 or EGM).
    pub transport: Option<&'a str>,
}

/// Start the recorder on `path` (its directory created) with the run's metadata and scene, as
/// every driver of the plant records.
pub fn open_recorder(
    path: &Path,
    about: &RecordingAbout,
    scenario: &Scenario,
    physics: &Physics,
    live: Option<recordings::LiveConfig>,
) -> anyhow::Result<Recorder> {
    open_recorder_with(path, about, scenario, physics, live, recordings::RecorderTuning::for_mode(about.mode))
}

/// Largest recorder queue in lockstep, records. Lockstep has no deadline: the loop waits for
/// room (`tick.rs`) instead of dropping, so the queue need not absorb a stalled writer, and the
/// start need not touch `recording.queue_capacity` slots of about 3.5 kB each (8192 by default:
/// 28 MB, 17-25 ms of the start on the idle VM, 2026-12-04).
const LOCKSTEP_QUEUE_CAPACITY: usize = 1024;

/// [`open_recorder`] with the writer's `tuning`.
pub fn open_recorder_with(
    path: &Path,
    about: &RecordingAbout,
    scenario: &Scenario,
    physics: &Physics,
    live: Option<recordings::LiveConfig>,
    tuning: recordings::RecorderTuning,
) -> anyhow::Result<Recorder> {
    let l = &scenario.loop_;
    let mode = about.mode;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let metadata = recordings::RunMetadata {
        rig: about.rig.to_string(),
        mode,
        scenario: Some(recordings::run_metadata::ScenarioSource {
            path: about.scenario_path.display().to_string(),
            toml: about.scenario_text.clone(),
        }),
        period_s: l.period_s,
        substeps: l.substeps,
        integrator: l.integrator,
        transport: about.transport.map(str::to_string),
        egm: scenario.egm.enabled.then(|| recordings::run_metadata::EgmRun {
            servo_lag_s: crate::driver::egm::servo::ServoParams::from_scenario(scenario).lag_s(),
        }),
        // z of the centre-line bottom nodes, in the order of the recorded pressures (contact.rs).
        centreline_z_m: physics.contact().map(|c| c.centreline_z_m().to_vec()),
    };
    let cfg = RecorderConfig {
        path: path.to_path_buf(),
        queue_capacity: match mode {
            Mode::Lockstep => scenario.recording.queue_capacity.min(LOCKSTEP_QUEUE_CAPACITY),
            Mode::Realtime => scenario.recording.queue_capacity,
        },
        chunk_size_bytes: scenario.recording.chunk_size_bytes,
        metadata,
        live,
        scene: Some(scene_config(scenario, physics.contact(), physics.chain())),
        period_s: l.period_s,
    };
    Recorder::start_with(cfg, tuning).with_context(|| format!("starting the recorder on {}", path.display()))
}

/// How long a plant stopped by a signal waits for its launcher's last thread to end before it
/// decides the launcher lives on (a stop `rig` asked for pays it once, at the end).
const LAUNCHER_EXIT_GRACE: std::time::Duration = std::time::Duration::from_millis(200);

/// Run the plant until the duration is reached or SIGINT/SIGTERM arrives.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunSummary> {
    run_reporting(opts, |_| {})
}

/// [`run`], handing the summary to `report` as soon as the recording is finished, before the
/// plant lets go of its iceoryx2 ports, its liveness watch and its claim on the rig name (on an
/// ext4 state directory that teardown took 10-40 ms, 2026-12-06: each iceoryx2 file removed frees
/// blocks). `plant-sim` prints its summary line there and closes its stdout, so `rig` reads the
/// recording back meanwhile.
pub fn run_reporting(opts: &RunOptions, report: impl FnOnce(&RunSummary)) -> anyhow::Result<RunSummary> {
    let t_run = std::time::Instant::now();
    let launcher = crate::launcher::Launcher::now();
    messages::services::validate_rig_name(&opts.rig)?;
    let scenario = Scenario::load(&opts.scenario_path)?;
    // The recording's copy needs no other file (a contour's pieces file inlined).
    let scenario_text = scenarios::pieces_file::self_contained(&opts.scenario_path)?;
    let mode = opts.mode.unwrap_or(scenario.loop_.mode);
    let l = &scenario.loop_;
    let length = run_length(&scenario, opts.duration_s)?;
    let period_ns = (l.period_s * 1e9).round() as u64;
    let params = LoopParams {
        mode,
        period_ns,
        budget_ns: (l.torque_budget_us * 1e3).round() as u64,
        watchdog_ns: (l.lockstep_watchdog_s * 1e9).round() as u64,
        n_ticks: length.n_ticks,
        spin_ns: if mode == Mode::Realtime { (l.spin_wait_us * 1e3).round() as u64 } else { 0 },
    };

    // Before any node: the rig's iceoryx2 configuration, room in /dev/shm, and this rig name for
    // this plant alone (held until the recording is finished).
    let iox_config = rig_process::host::prepare()?;
    let _claim = rig_process::host::claim_plant(&opts.rig, iox_config)?;
    let cleaned = rig_process::ports::clean_dead_nodes();
    if cleaned > 0 {
        tracing::info!("removed the shared-memory leftovers of {cleaned} dead iceoryx2 node(s)");
    }
    let signals = crate::signals::Signals::install();

    let t_setup = std::time::Instant::now();
    // Lockstep: the recorder's writer thread inherits the affinity of the thread that spawns it;
    // the set-up thread below keeps itself off the CPU the loop and the controller are pinned to
    // before it starts the recorder (ZSTD compression costs ~10 µs per tick, which would
    // otherwise come out of the lockstep tick whenever the scheduler places the writer there).
    // (The CPU is chosen here: lockstep_cpu counts this thread's allowed CPUs.)
    let lockstep_cpu = rt::lockstep_cpu();
    anyhow::ensure!(
        opts.live.is_none() || scenario.recording.enabled,
        "--live: the live view is fed by the recorder, and {} disables the recording (recording.enabled = false)",
        opts.scenario_path.display()
    );
    let recording = scenario.recording.enabled.then(|| opts.out.clone().unwrap_or_else(|| default_recording_path(&opts.rig)));
    // The strip model and contact tables, then the recorder (whose scene needs the model), on a
    // set-up thread while this one opens the iceoryx2 ports and the liveness watch: neither
    // needs the other, and each took about half of the plant's start-up (README, "Lockstep
    // start-up"). Without a thread, one after the other.
    let physics_then_recorder = || -> anyhow::Result<(Physics, Option<Recorder>, std::time::Duration, std::time::Duration)> {
        let t0 = std::time::Instant::now();
        // With every CPU, as on the main thread: a strip model built on a cache miss uses faer's
        // pool, which takes its size from the affinity of the thread that first uses it (the
        // bits do not depend on that size: the build's task count is fixed, strip::BUILD_TASKS).
        let physics = Physics::new(&scenario, &opts.cache_dir)?;
        let t_physics = t0.elapsed();
        if mode == Mode::Lockstep && !rt::keep_thread_off_cpu(lockstep_cpu) {
            tracing::warn!("could not keep the recorder off the lockstep CPU {lockstep_cpu}");
        }
        let recorder = match &recording {
            Some(path) => {
                let about = RecordingAbout {
                    rig: &opts.rig,
                    mode,
                    scenario_path: &opts.scenario_path,
                    scenario_text: scenario_text.clone(),
                    transport: None,
                };
                Some(open_recorder(path, &about, &scenario, &physics, opts.live.clone())?)
            }
            None => None,
        };
        Ok((physics, recorder, t_physics, t0.elapsed() - t_physics))
    };
    let ports_and_watch = || -> anyhow::Result<(rig_process::ports::PlantPorts, rig_process::liveness::PeerWatch, std::time::Duration)> {
        let t0 = std::time::Instant::now();
        // Liveness of the controllers' nodes, on its own thread (started before the loop's
        // real-time set-up, so it keeps the normal scheduling policy), setting up while this
        // thread opens the ports.
        let watch = rig_process::liveness::PeerWatch::start(&opts.rig, "plant-sim-watch", rig_process::liveness::Watched::Controllers)?;
        let ports = rig_process::ports::PlantPorts::open(&opts.rig, "plant-sim")?;
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
    // The model's refusal first, as when the two ran one after the other.
    let (physics, mut recorder, t_physics, t_recorder) = set_up?;
    let (ports, watch, t_ports) = opened?;
    let mut arbiter = crate::arbiter::Arbiter::new(l.takeover_after_misses);

    // Real-time set-up after the recorder's writer thread exists (it keeps the normal policy).
    // Lockstep keeps the normal policy: nothing there is time-critical, and a SCHED_FIFO waker
    // hands over to the controller across CPUs (waking a halted vCPU) instead of on its own CPU,
    // which measured 50 µs instead of 15 µs per round trip on a 2-vCPU VM.
    // Memory is locked in real time only: a lockstep run has no deadline a page fault could
    // miss, and locking populates every mapping at once (each thread's whole stack among them),
    // about 5 ms of the lockstep start-up's critical path in the kernel (perf, 2026-12-06).
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
    if l.idle_poll {
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
    // The start-up's parts (README, "Lockstep start-up"): scenario and host checks, strip model
    // and contact tables, then the recorder (set-up thread), beside ports and liveness watch
    // (this thread), and the whole set-up to here.
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    tracing::info!(
        rig = %opts.rig,
        mode = ?mode,
        ticks = params.n_ticks,
        recording = ?recording,
        host_ms = ms(t_setup - t_run),
        physics_ms = ms(t_physics),
        ports_ms = ms(t_ports),
        recorder_ms = ms(t_recorder),
        setup_ms = ms(t_setup.elapsed()),
        "plant running"
    );
    if let Some(r) = recorder.as_mut() {
        let text = format!("plant started: rig {}, mode {mode:?}, {} ticks", opts.rig, params.n_ticks);
        r.record_event(&EventRecord::new(0, 0.0, EventKind::Start, &text));
    }

    // The host-floor probe, one thread per CPU this process may use (README, "Timing").
    let probe = match (opts.host_probe, mode) {
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
            Some(p)
        }
        (true, Mode::Lockstep) => {
            tracing::warn!("--host-probe applies to real-time runs only; not started in lockstep");
            None
        }
        _ => None,
    };
    // The strip record's top line only on the ticks the recording draws its scene for.
    let top_line_every = recorder.as_ref().and_then(|r| r.scene_every());
    // [egm] enabled: the plant is an ABB robot controller speaking EGM over UDP (`egm/`),
    // instead of taking torques over iceoryx2.
    let (stats, egm) = if scenario.egm.enabled {
        let ep = crate::driver::egm::EgmParams::from_scenario(&scenario, mode, params.n_ticks)?;
        tracing::info!(sensor = %ep.sensor, "EGM: sending EgmRobot every {} s", scenario.egm.cycle_s);
        let mut plant = crate::tick::PlantTick::new(&scenario, physics, mode).with_top_line_every(top_line_every);
        let (stats, es) = crate::driver::egm::EgmLoop::new(&scenario, &mut plant, recorder.as_mut(), ep, signals)?.run();
        (stats, Some(es))
    } else {
        let mut plant = crate::tick::PlantTick::new(&scenario, physics, mode).with_top_line_every(top_line_every);
        let mut plant_loop = PlantLoop {
            ports: &ports,
            plant: &mut plant,
            recorder: recorder.as_mut(),
            params,
            arbiter: &mut arbiter,
            watch: Some(&watch),
            probe: probe.as_ref().map(|p| &*p.latest),
            signals,
        };
        let stats = match mode {
            Mode::Realtime => plant_loop.run_realtime(),
            Mode::Lockstep => plant_loop.run_lockstep(),
        };
        (stats, None)
    };
    let probe = probe.map(crate::probe::Probe::finish);
    if let (Some(r), Some(cpus)) = (recorder.as_mut(), probe.as_ref()) {
        r.record_event(&EventRecord::new(stats.ticks, stats.sim_s, EventKind::Info, &crate::probe::summary_text(cpus)));
    }
    if let Some(r) = recorder.as_mut().filter(|_| stats.stopped_by_signal && launcher.gone_within(LAUNCHER_EXIT_GRACE)) {
        r.record_event(&EventRecord::new(stats.ticks, stats.sim_s, EventKind::Fault, &launcher.death_note()));
    }
    let t_end = std::time::Instant::now();
    let drops = recorder.as_ref().map_or(0, |r| r.dropped());
    let live_addr = recorder.as_ref().and_then(|r| r.live_addr());
    let (recording_stopped_early, live) = match recorder {
        Some(r) => {
            let s = r.finish().context("finishing the recording")?;
            (s.stopped_early, live_addr.zip(s.live))
        }
        None => (None, None),
    };
    tracing::info!(
        ticks = stats.ticks,
        misses = stats.misses,
        safe_stops = stats.safe_stops,
        finish_ms = ms(t_end.elapsed()),
        "plant stopped"
    );
    let summary = RunSummary { stats, recording, drops, recording_stopped_early, mode, rt: rt_setup, live, probe, egm };
    report(&summary);
    // The teardown: the watch's node (on its thread) and the ports' go side by side (each file
    // removed from an ext4 state directory waits for its blocks to be freed), then the claim.
    watch.stop_soon();
    drop(ports);
    drop(watch);
    Ok(summary)
}

/// What the recording's Foxglove channels draw: the scenario's tool and placement, and the strip
/// model's top surface (`recordings::scene`).
fn scene_config(
    s: &scenarios::Scenario,
    contact: Option<&crate::contact::StripContact>,
    chain: Option<&crate::contact::chain::ChainContact>,
) -> recordings::scene::SceneConfig {
    use recordings::scene::{SceneConfig, StripGeometry};
    let params = crate::contact::strip_params(s);
    // A windowed long strip: one window's layer pattern repeated along the whole strip (the scene
    // draws the layers around the wheel) and the substrate's profile at every element.
    let long = chain.map(|c| {
        let top = c.window_top_xyz_m();
        let nodes_per_layer = top.iter().take_while(|n| (n[2] - top[0][2]).abs() < 1e-12).count();
        let (length_m, element_m) = (c.chain().strip_length_m, params.element_m);
        let layers = (length_m / element_m).round() as usize + 1;
        let top_xyz_m = (0..layers).flat_map(|k| top[..nodes_per_layer].iter().map(move |n| [n[0], n[1], k as f64 * element_m])).collect();
        let profile = crate::contact::chain::substrate_profile(s);
        StripGeometry {
            top_xyz_m,
            nodes_per_layer,
            substrate_zy_m: (0..layers).map(|k| [k as f64 * element_m, profile.height_m(k as f64 * element_m)]).collect(),
            length_m,
            half_width_m: strip::mesh::HALF_WIDTH_M,
            windowed: true,
        }
    });
    let strip = long.or_else(|| {
        contact.map(|c| {
            let top = c.top_xyz_m();
            let nodes_per_layer = top.iter().take_while(|n| (n[2] - top[0][2]).abs() < 1e-12).count();
            StripGeometry {
                top_xyz_m: top.to_vec(),
                nodes_per_layer,
                substrate_zy_m: (0..=200)
                    .map(|i| {
                        let z = params.length_m * i as f64 / 200.0;
                        [z, params.bulge_height_m(z)]
                    })
                    .collect(),
                length_m: params.length_m,
                half_width_m: strip::mesh::HALF_WIDTH_M,
                windowed: false,
            }
        })
    });
    SceneConfig {
        rate_hz: s.recording.scene_rate_hz,
        tool: scenarios::geometry::tool(s),
        task_in_base: scenarios::geometry::TaskFrame::from_scenario(s).pose_in_base(),
        strip,
        path: None,
        band_base: Vec::new(),
    }
    .along(s.contour.is_given().then(|| scenarios::path::StripPath::from_scenario(s)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default scenario sets no length: its nominal trajectory, settle 0.1 + approach
    /// 3 mm / 10 mm/s + ramp 0.3 + dwell 0.2 + roll 2.0 + ramp down 0.2 + lift 0.3 + 0.2 = 3.6 s,
    /// 3600 ticks of 1 ms.
    #[test]
    fn without_a_length_the_run_is_the_nominal_trajectory() {
        let s = Scenario::default();
        let r = run_length(&s, None).unwrap();
        assert!((r.duration_s - 3.6).abs() < 1e-12, "{}", r.duration_s);
        assert_eq!(r.n_ticks, 3600);
        // No approach speed: no approach term (3.3 s).
        let mut s = Scenario::default();
        s.trajectory.approach_speed_mm_s = 0.0;
        assert_eq!(run_length(&s, None).unwrap().n_ticks, 3300);
    }

    /// The command line before the scenario's `loop.duration_s`, that before the nominal.
    #[test]
    fn the_command_line_wins_over_the_scenario_and_the_scenario_over_the_nominal() {
        let mut s = Scenario::default();
        s.loop_.duration_s = 1.5;
        assert_eq!(run_length(&s, None).unwrap(), RunLength { duration_s: 1.5, n_ticks: 1500 });
        assert_eq!(run_length(&s, Some(0.25)).unwrap(), RunLength { duration_s: 0.25, n_ticks: 250 });
    }

    /// Ticks are the nearest whole number of periods: 2 ms periods, 5.1 ms → 2.55 → 3 ticks,
    /// 4.9 ms → 2.45 → 2 ticks.
    #[test]
    fn ticks_round_to_the_nearest_period() {
        let mut s = Scenario::default();
        s.loop_.period_s = 2e-3;
        assert_eq!(run_length(&s, Some(5.1e-3)).unwrap().n_ticks, 3);
        assert_eq!(run_length(&s, Some(4.9e-3)).unwrap().n_ticks, 2);
        assert_eq!(run_length(&s, None).unwrap().n_ticks, 1800);
    }

    #[test]
    fn a_length_that_is_not_a_positive_finite_time_is_refused() {
        let s = Scenario::default();
        for d in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = run_length(&s, Some(d)).unwrap_err();
            assert_eq!(e.to_string(), format!("duration {d} s must be positive"));
        }
    }
}
