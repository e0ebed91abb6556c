//! In-process 6-DOF servo simulation: the plant's physics (`plant_sim::physics`, robot + strip
//! contact) and the controller's step (`controller::daemon::step`) in lockstep without IPC.
//! Same computations as the two daemons in lockstep mode, minus the torque gate (no misses can
//! occur in-process), so tracking studies (robustness table, substep convergence) run in seconds.

use std::path::Path;

use controller::gains::Gains;
use controller::law::ControlLaw;
use controller::model::{controller_robot, tool_down_rotation, TaskFrame};
use controller::reference::{Phase, ReferenceGenerator, ReferenceParams};
use messages::{JointState, PlantStatus, Wrench, WrenchFrame, CONTRACT_VERSION};
use plant_sim::physics::Physics;
use recording_tools::tracking::{rolling_force_tracking, ForceTracking, TrackingTick};
use recordings::StripRecord;
use scenario::Scenario;

/// One recorded sample of the servo run (per tick).
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
/// plus 0.1 s). `cache_dir`: the strip model cache.
pub fn run_servo(s: &Scenario, cache_dir: &Path, duration_s: f64) -> anyhow::Result<Vec<ServoSample>> {
    Ok(run_servo_full(s, cache_dir, duration_s)?.samples)
}

/// [`run_servo`] with the bond data.
pub fn run_servo_full(s: &Scenario, cache_dir: &Path, duration_s: f64) -> anyhow::Result<ServoRun> {
    let mut physics = Physics::new(s, cache_dir)?;
    let task = TaskFrame::from_scenario(s);
    let mut law = ControlLaw::new(controller_robot(s), task, Gains::from_scenario(s, f64::NAN), tool_down_rotation());
    let mut reference = ReferenceGenerator::new(ReferenceParams::from_scenario(s));
    let period = s.loop_.period_s;
    let mut out = Vec::new();
    let mut rec = StripRecord::default();
    let max_ticks = if duration_s > 0.0 { (duration_s / period).round() as u64 } else { (60.0 / period) as u64 };
    let mut done_at: Option<u64> = None;
    let centreline_z_m: Vec<f64> = physics.contact().map_or(Vec::new(), |c| c.centreline_z_m().to_vec());
    let mut peak = vec![f64::NEG_INFINITY; centreline_z_m.len()];
    for tick in 0..max_ticks {
        let (q, qd) = (physics.q(), physics.qd());
        let state = JointState {
            contract_version: CONTRACT_VERSION,
            plant_status: PlantStatus::Running as u32,
            tick,
            sim_time_s: tick as f64 * period,
            q: q.into(),
            qd: qd.into(),
            tau_applied: [0.0; 6],
            period_s: period,
            flags: 0,
            consecutive_misses: 0,
            total_misses: 0,
        };
        let (force, torque) = physics.wrench();
        let wrench = Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::SensorAtTcp as u32, tick, force, torque };
        let (tau, diag) = controller::daemon::step(&mut law, &mut reference, &state, &wrench, &q, &qd, CONTRACT_VERSION);
        physics.fill_strip_record(&mut rec);
        for (p, &x) in peak.iter_mut().zip(&rec.centreline_pressure_pa[..rec.n_centreline as usize]) {
            *p = p.max(x);
        }
        out.push(ServoSample {
            t_s: state.sim_time_s,
            phase: reference.phase(),
            force_ref_n: diag.force_ref_n,
            contact_force_n: rec.contact_force_n,
            bottom_force_n: rec.bottom_force_n,
            wheel_z_m: rec.wheel_z_m,
            z_ref_m: diag.pos_ref_task_m[2],
        });
        if !tau.iter().all(|x| x.is_finite()) {
            anyhow::bail!("non-finite torque at tick {tick}");
        }
        physics.step_tick(&tau);
        if duration_s <= 0.0 && reference.phase() == Phase::Done {
            let d = *done_at.get_or_insert(tick);
            if tick - d >= (0.1 / period) as u64 {
                break;
            }
        }
    }
    Ok(ServoRun { samples: out, centreline_z_m, peak_pressure_pa: peak })
}
