//! One plant run from start to summary: scenario, ports, recorder, real-time set-up, the loop,
//! shutdown. `main.rs` only parses arguments and prints.

use std::path::{Path, PathBuf};

use anyhow::Context;
use scenarios::{Mode, Scenario};

use crate::contact::StripDetail;
use crate::driver::realtime::{LoopParams, PlantLoop};
use crate::recording::{EventKind, EventRecord};
use rig_process::rt;

mod recording;
mod startup;
mod summary;

pub use recording::{open_recorder, open_recorder_with, RecordingAbout};
use startup::{schedule_loop_thread, set_up_side_by_side, start_probe, SetUp, SetUpInputs};
pub use summary::RunSummary;

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
    // (The CPU is chosen here: lockstep_cpu counts this thread's allowed CPUs.)
    let lockstep_cpu = rt::lockstep_cpu();
    anyhow::ensure!(
        opts.live.is_none() || scenario.recording.enabled,
        "--live: the live view is fed by the recorder, and {} disables the recording (recording.enabled = false)",
        opts.scenario_path.display()
    );
    let recording = scenario.recording.enabled.then(|| opts.out.clone().unwrap_or_else(|| default_recording_path(&opts.rig)));
    let inputs = SetUpInputs { opts, scenario: &scenario, scenario_text: &scenario_text, mode, recording: &recording, lockstep_cpu };
    let SetUp { physics, mut recorder, ports, watch, t_physics, t_recorder, t_ports } = set_up_side_by_side(&inputs)?;
    let mut arbiter = crate::arbiter::Arbiter::new(l.takeover_after_misses);
    let rt_setup = schedule_loop_thread(mode, lockstep_cpu, l.idle_poll);
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
    let probe = start_probe(opts, mode, period_ns)?;

    // The strip record's top line only on the ticks the recording draws its scene for; its
    // centre line on the writer thread when the recorder can compute it (nothing else here reads
    // it).
    let top_line_every = recorder.as_ref().and_then(|r| r.scene_every());
    let detail = if recorder.as_ref().is_some_and(|r| r.expands_centre_line()) { StripDetail::Modal } else { StripDetail::Full };
    let mut plant = crate::tick::PlantTick::new(&scenario, physics, mode).with_strip_detail(detail).with_top_line_every(top_line_every);
    // [egm] enabled: the plant is an ABB robot controller speaking EGM over UDP (`egm/`),
    // instead of taking torques over iceoryx2.
    let (stats, egm) = if scenario.egm.enabled {
        let ep = crate::driver::egm::EgmParams::from_scenario(&scenario, mode, params.n_ticks)?;
        tracing::info!(sensor = %ep.sensor, "EGM: sending EgmRobot every {} s", scenario.egm.cycle_s);
        let (stats, es) = crate::driver::egm::EgmLoop::new(&scenario, &mut plant, recorder.as_mut(), ep, signals)?.run();
        (stats, Some(es))
    } else {
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
