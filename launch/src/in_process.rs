//! `rig run --mode lockstep --in-process` and the cases of `rig sweep`: the plant's tick
//! ([`plant_sim::PlantTick`]) and the controller's step ([`controller::Controller`]) in one
//! thread, no daemons, no iceoryx2, recorded through the same writer as the plant's. Transport is
//! transparent: every state, wrench and torque is bit-identical to the daemons' lockstep run of
//! the same scenario (tests/tests/tick_identity.rs, sweep.rs).

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use plant_sim::contact::StripDetail;
use plant_sim::physics::Physics;
use plant_sim::recording::{EventKind, EventRecord};
use plant_sim::run::{open_recorder_with, run_length, RecordingAbout, RunSummary};
use plant_sim::stats::LoopStats;
use plant_sim::PlantTick;
use recording_tools::strip_rows::CaseRows;
use recordings::TimingRecord;
use scenarios::{Mode, Scenario};

/// `controller_id` of the in-process controller (no process to name it after).
const IN_PROCESS_CONTROLLER_ID: u64 = 1;

/// What a case keeps: its recording (when the scenario records), its tick rows in memory for the
/// rolling-phase numbers, or both. A sweep or study case that writes no file reads the same
/// figures from its rows ([`recording_tools::strip_rows::CaseRows`]) as from the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Keep<'p> {
    /// Where to record (None: no file, whatever the scenario says).
    pub recording: Option<&'p Path>,
    /// Keep the tick rows in memory.
    pub rows: bool,
    /// Log the run's warnings and errors only, not its Info events (a sweep's or study's cases:
    /// one "controller connected" line per case otherwise); the recording has them all.
    pub quiet: bool,
}

/// One in-process run of the scenario at `scenario_path` for `duration_s` (None: the scenario's,
/// or its nominal trajectory), recorded to `keep.recording` when the scenario records, with the
/// writer's `tuning`. `physics` builds the plant (a sweep shares the strip tables across its
/// cases). `signals`: a stop ends the run after the current tick. Returns the plant's summary,
/// the one `plant-sim` prints (the recording's metadata says the run was in process), and the
/// tick rows when `keep.rows`.
pub fn run(
    rig: &str,
    scenario_path: &Path,
    duration_s: Option<f64>,
    keep: Keep,
    tuning: recordings::RecorderTuning,
    physics: impl FnOnce(&Scenario) -> anyhow::Result<Physics>,
    signals: plant_sim::signals::Signals,
) -> anyhow::Result<(recordings::PlantSummary, Option<CaseRows>)> {
    let s = Scenario::load(scenario_path)?;
    anyhow::ensure!(!s.egm.enabled, "--in-process: {} enables [egm]; the EGM path runs with its daemons only", scenario_path.display());
    let text = scenarios::pieces_file::self_contained(scenario_path)?;
    let n_ticks = run_length(&s, duration_s)?.n_ticks;
    let physics = physics(&s)?;
    let path = keep.recording.filter(|_| s.recording.enabled).map(Path::to_path_buf);
    let mut rows = keep.rows.then(|| {
        let z = physics.contact().map_or(Vec::new(), |c| c.centreline_z_m().to_vec());
        CaseRows::new(z, usize::try_from(n_ticks).unwrap_or(0))
    });
    let mut recorder = match &path {
        Some(p) => {
            let about = RecordingAbout { rig, mode: Mode::Lockstep, scenario_path, scenario_text: text, transport: Some("in-process") };
            Some(open_recorder_with(p, &about, &s, &physics, None, tuning)?)
        }
        None => None,
    };
    // Without a recording only the figures read the strip: its pressure under the wheel; with
    // one, the scene's top line only on the ticks it is drawn, and the centre line computed on
    // the writer thread when nothing here reads it (no rows kept).
    let detail = match (&recorder, &rows) {
        (Some(r), None) if r.expands_centre_line() => StripDetail::Modal,
        (Some(_), _) => StripDetail::Full,
        (None, _) => StripDetail::UnderWheel,
    };
    let top_line_every = recorder.as_ref().and_then(|r| r.scene_every());
    let mut plant = PlantTick::new(&s, physics, Mode::Lockstep).with_strip_detail(detail).with_top_line_every(top_line_every);
    let mut controller = controller::Controller::from_scenario(&s).with_id(IN_PROCESS_CONTROLLER_ID);
    if let Some(r) = recorder.as_mut() {
        let text = format!("plant started: rig {rig}, mode Lockstep (in-process), {n_ticks} ticks");
        r.record_event(&EventRecord::new(0, 0.0, EventKind::Start, &text));
    }
    let started = Instant::now();
    let mut stats = LoopStats::empty();
    let hand_on = plant_sim::tick_events::EventHandOn::new(plant.period_ns());
    let mut hand_on = if keep.quiet { hand_on.quiet() } else { hand_on };
    while plant.tick() < n_ticks {
        if signals.stop_requested() {
            stats.stopped_by_signal = true;
            break;
        }
        let (state, wrench) = plant.outputs();
        let (torque, diag) = controller.process(&state, &wrench);
        plant_sim::tick_events::make_room_for_tick(recorder.as_mut());
        let outcome = plant.advance(Some(&torque));
        hand_on.hand_on(&outcome.events, recorder.as_mut());
        if recorder.is_some() || rows.is_some() {
            let timing = TimingRecord { missed: outcome.decision.missed, ..TimingRecord::default() };
            let record = plant_sim::tick::tick_record(state, wrench, &outcome, Some(diag), timing);
            if let Some(r) = recorder.as_mut() {
                r.record_tick_commanded(&record, Some(&torque));
            }
            if let Some(rows) = rows.as_mut() {
                rows.push(&record);
            }
        }
    }
    let tick = plant.tick();
    stats.ticks = tick;
    stats.count_plant(&plant);
    stats.wall_s = started.elapsed().as_secs_f64();
    (stats.active_wall_s, stats.active_sim_s) = (stats.wall_s, stats.sim_s);
    let drops = recorder.as_ref().map_or(0, |r| r.dropped());
    let recording_stopped_early = match recorder {
        Some(mut r) => {
            let why = if stats.stopped_by_signal { "signal" } else { "duration reached" };
            r.record_event(&EventRecord::new(tick, stats.sim_s, EventKind::Stop, &format!("plant stopped after {tick} ticks ({why})")));
            r.finish().context("finishing the recording")?.stopped_early
        }
        None => None,
    };
    let summary = RunSummary {
        stats,
        recording: path.clone(),
        drops,
        recording_stopped_early,
        mode: Mode::Lockstep,
        rt: rig_process::rt::RtSetup::default(),
        live: None,
        probe: None,
        egm: None,
    };
    Ok((summary.to_summary(rig), rows))
}
