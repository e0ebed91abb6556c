//! The recording every driver of the plant writes: its directory, metadata and Foxglove scene,
//! and the writer's queue for the run's mode.

use std::path::Path;

use anyhow::Context;
use scenarios::{Mode, Scenario};

use crate::physics::Physics;
use crate::recording::{Recorder, RecorderConfig};

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
/// start need not touch `recording.queue_capacity` slots of 5.2 kB each (8192 by default: 42 MB;
/// at 3.5 kB a slot, 28 MB took 17-25 ms of the start on the idle VM, 2026-12-04; the strip
/// state a slot may carry since 2026-12-07 added 2 kB).
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
        centre_line: physics.centre_line(),
    };
    Recorder::start_with(cfg, tuning).with_context(|| format!("starting the recorder on {}", path.display()))
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
