//! In-process 6-DOF servo simulation: the plant's tick ([`plant_sim::PlantTick`]: physics,
//! torque gate, limits) and the controller's step ([`controller::Controller::process`]) in one
//! thread, no IPC. The same two values the daemons drive, so a servo run equals the lockstep run
//! of its scenario tick for tick (tests/tests/tick_identity.rs proves that of `rig run
//! --in-process`, which drives them the same way) and tracking studies (robustness table,
//! substep convergence) run in seconds.

use std::path::Path;

use controller::reference::Phase;
use controller::Controller;
use plant_sim::tick::FirstTicks;
use plant_sim::PlantTick;
use recording_tools::tracking::{rolling_force_tracking, ForceTracking, TrackingTick};
use scenarios::{Mode, Scenario};

/// One sample of the servo run per tick, as a lockstep recording has it: the state's time, the
/// controller's phase and force reference after answering it, and the strip after the tick was
/// integrated with that answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoSample {
    pub t_s: f64,
    pub phase: Phase,
    pub force_ref_n: f64,
    pub contact_force_n: f64,
    pub bottom_force_n: f64,
    pub wheel_z_m: f64,
    /// The reference along the strip (task z), m.
    pub z_ref_m: f64,
}

/// Tracking figures over the rolling phase (issue 6 acceptance metric):
/// e = | |bottom force| − |force reference| |.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tracking {
    pub max_n: f64,
    pub rms_n: f64,
    pub samples: usize,
}

impl From<ForceTracking> for Tracking {
    fn from(t: ForceTracking) -> Self {
        Tracking { max_n: t.max_abs_n, rms_n: t.rms_n, samples: t.samples }
    }
}

/// Tracking figures of the rolling phase of `samples`: the recordings' rule
/// (`recording_tools::tracking`), zero without a rolling phase.
pub fn tracking(samples: &[ServoSample]) -> Tracking {
    let ticks: Vec<TrackingTick> = samples
        .iter()
        .map(|s| TrackingTick {
            in_contact: s.contact_force_n != 0.0,
            z_ref_m: Some(s.z_ref_m),
            wheel_z_m: s.wheel_z_m,
            force_ref_n: Some(s.force_ref_n),
            bottom_force_n: s.bottom_force_n,
        })
        .collect();
    rolling_force_tracking(&ticks).map_or_else(Tracking::default, Tracking::from)
}

/// A whole in-process run: per-tick samples plus, per centre-line node, the largest bottom
/// pressure it saw (the bond check of issue 6).
#[derive(Clone, Debug, Default)]
pub struct ServoRun {
    pub samples: Vec<ServoSample>,
    pub centreline_z_m: Vec<f64>,
    pub peak_pressure_pa: Vec<f64>,
    /// The first tick of a safe stop, a reflex or a refused torque, if any: a run with one is
    /// not the servo run its scenario describes (the gate and limits apply as in the daemons).
    pub first: FirstTicks,
}

impl ServoRun {
    /// Lowest peak pressure over the nodes with z in [z_from, z_to]: (z, Pa).
    pub fn weakest_bond(&self, z_from_m: f64, z_to_m: f64) -> Option<(f64, f64)> {
        self.centreline_z_m
            .iter()
            .zip(&self.peak_pressure_pa)
            .filter(|(z, _)| **z >= z_from_m - 1e-9 && **z <= z_to_m + 1e-9)
            .map(|(z, p)| (*z, *p))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// Run the scenario's servo run in-process for `duration_s` (0 = until the reference is done
/// plus 0.1 s, at most 60 s). `cache_dir`: the strip model cache.
pub fn run_servo(s: &Scenario, cache_dir: &Path, duration_s: f64) -> anyhow::Result<Vec<ServoSample>> {
    Ok(run_servo_full(s, cache_dir, duration_s)?.samples)
}

/// [`run_servo`] with the bond data.
pub fn run_servo_full(s: &Scenario, cache_dir: &Path, duration_s: f64) -> anyhow::Result<ServoRun> {
    let mut plant = PlantTick::from_scenario(s, cache_dir, Mode::Lockstep)?;
    let mut controller = Controller::from_scenario(s);
    let period = s.loop_.period_s;
    let max_ticks = if duration_s > 0.0 { (duration_s / period).round() as u64 } else { (60.0 / period) as u64 };
    let mut done_at: Option<u64> = None;
    let centreline_z_m: Vec<f64> = plant.physics().contact().map_or(Vec::new(), |c| c.centreline_z_m().to_vec());
    let mut peak = vec![f64::NEG_INFINITY; centreline_z_m.len()];
    let mut out = Vec::new();
    while plant.tick() < max_ticks {
        let tick = plant.tick();
        let (state, wrench) = plant.outputs();
        let (torque, diag) = controller.process(&state, &wrench);
        if !torque.tau.iter().all(|x| x.is_finite()) {
            anyhow::bail!("non-finite torque at tick {tick}");
        }
        let strip = plant.advance(Some(&torque)).strip;
        for (p, &x) in peak.iter_mut().zip(&strip.centreline_pressure_pa[..strip.n_centreline as usize]) {
            *p = p.max(x);
        }
        let phase = controller.reference().phase();
        out.push(ServoSample {
            t_s: state.sim_time_s,
            phase,
            force_ref_n: diag.force_ref_n,
            contact_force_n: strip.contact_force_n,
            bottom_force_n: strip.bottom_force_n,
            wheel_z_m: strip.wheel_z_m,
            z_ref_m: diag.pos_ref_task_m[2],
        });
        if duration_s <= 0.0 && phase == Phase::Done {
            let d = *done_at.get_or_insert(tick);
            if tick - d >= (0.1 / period) as u64 {
                break;
            }
        }
    }
    Ok(ServoRun { samples: out, centreline_z_m, peak_pressure_pa: peak, first: plant.first_ticks() })
}
