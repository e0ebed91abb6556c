//! A synthetic run with closed-form contents, for tests, benchmarks and trying the report
//! without the daemons. Phases: press at `z_start`, roll to `z_end` with the cosine velocity
//! profile of the thesis (Figure 6.6), rest at `z_end`.
//!
//! Known by construction: over the rolling ticks |bottom_force| - |force_ref| =
//! A sin(2 pi m j / N) (j = 1..N), so its max is A and its RMS A / sqrt(2); the centre-line pressure
//! peak under the wheel is `peak_pressure_pa` while z_wheel < `coverage_z_m` and a third of it
//! beyond.

use crate::{EventKind, EventRecord, TickRecord, MAX_CENTRELINE};

#[derive(Debug, Clone)]
pub struct SyntheticRun {
    pub ticks: u64,
    pub period_s: f64,
    /// Ticks pressing before rolling starts.
    pub roll_start_tick: u64,
    /// Rolling ticks N.
    pub roll_ticks: u64,
    pub z_start_m: f64,
    pub z_end_m: f64,
    pub force_ref_n: f64,
    /// A: amplitude of the bottom-force error while rolling, N.
    pub force_error_n: f64,
    /// m: periods of the error over the roll.
    pub force_error_periods: u64,
    pub peak_pressure_pa: f64,
    pub coverage_z_m: f64,
    pub n_centreline: usize,
    pub strip_length_m: f64,
    /// Every `miss_every`-th tick is a miss (0: none).
    pub miss_every: u64,
}

impl Default for SyntheticRun {
    fn default() -> Self {
        Self {
            ticks: 3000,
            period_s: 1e-3,
            roll_start_tick: 500,
            roll_ticks: 2000,
            z_start_m: 0.002,
            z_end_m: 0.038,
            force_ref_n: -10.0,
            force_error_n: 0.4,
            force_error_periods: 5,
            peak_pressure_pa: 150e3,
            coverage_z_m: 0.029,
            n_centreline: 81,
            strip_length_m: 0.040,
            miss_every: 1000,
        }
    }
}

impl SyntheticRun {
    pub fn centreline_z_m(&self) -> Vec<f64> {
        let n = self.n_centreline.min(MAX_CENTRELINE);
        (0..n).map(|i| self.strip_length_m * i as f64 / (n - 1).max(1) as f64).collect()
    }

    /// Metadata as the plant would pass it (no scenario: the run is made here, not from one).
    pub fn metadata(&self) -> crate::RunMetadata {
        crate::RunMetadata {
            rig: "synthetic".into(),
            mode: scenarios::Mode::Lockstep,
            scenario: None,
            period_s: self.period_s,
            substeps: 1,
            integrator: scenarios::Integrator::default(),
            transport: None,
            egm: None,
            centreline_z_m: Some(self.centreline_z_m()),
        }
    }

    /// Wheel position at tick k (cosine velocity profile while rolling).
    pub fn wheel_z_m(&self, k: u64) -> f64 {
        let j = k.saturating_sub(self.roll_start_tick).min(self.roll_ticks);
        let s = j as f64 / self.roll_ticks as f64;
        self.z_start_m + (self.z_end_m - self.z_start_m) * 0.5 * (1.0 - (std::f64::consts::PI * s).cos())
    }

    /// Whether tick k is one of the N rolling ticks (the wheel moved since tick k - 1).
    pub fn is_rolling(&self, k: u64) -> bool {
        k > self.roll_start_tick && k <= self.roll_start_tick + self.roll_ticks
    }

    /// |bottom force| - |force ref| at tick k.
    pub fn force_error_n(&self, k: u64) -> f64 {
        if !self.is_rolling(k) {
            return 0.0;
        }
        let j = (k - self.roll_start_tick) as f64;
        self.force_error_n * (2.0 * std::f64::consts::PI * self.force_error_periods as f64 * j / self.roll_ticks as f64).sin()
    }

    /// Round trip of tick k, ns: 40 us + (k mod 100) us.
    pub fn round_trip_ns(&self, k: u64) -> u64 {
        40_000 + (k % 100) * 1_000
    }

    pub fn is_miss(&self, k: u64) -> bool {
        self.miss_every != 0 && k % self.miss_every == self.miss_every - 1
    }

    pub fn tick(&self, k: u64) -> TickRecord {
        let mut r = TickRecord::default();
        let t = k as f64 * self.period_s;
        let z = self.wheel_z_m(k);
        r.state.tick = k;
        r.state.sim_time_s = t;
        r.state.period_s = self.period_s;
        // One tick of safe stop in the middle (matching the events below).
        r.state.plant_status = if k == self.ticks / 2 { messages::PlantStatus::SafeStop } else { messages::PlantStatus::Running } as u32;
        r.state.flags = messages::state_flags::LOCKSTEP | messages::state_flags::IN_CONTACT;
        for j in 0..6 {
            r.state.q[j] = 0.1 * j as f64 + 1e-3 * (t * (j + 1) as f64).sin();
            r.state.qd[j] = 1e-3 * (j + 1) as f64 * (t * (j + 1) as f64).cos();
            r.torque.tau[j] = 10.0 * (j as f64 + 1.0) + (t * 3.0 + j as f64).sin();
        }
        r.state.tau_applied = if k == 0 { [0.0; 6] } else { self.tick_tau(k - 1) };
        r.torque.tick = k;
        r.torque.controller_id = 42;
        let miss = self.is_miss(k);
        r.torque_held = miss;
        r.wrench.tick = k;
        r.wrench.force = [0.0, 0.0, -self.force_ref_n];
        r.has_diag = true;
        r.diag.tick = k;
        r.diag.force_control_active = 1;
        r.diag.force_ref_n = self.force_ref_n;
        r.diag.force_meas_n = self.force_ref_n;
        r.diag.pos_ref_task_m = [0.0, 0.0042, z];
        r.diag.compute_time_ns = 20_000;
        let bottom = self.force_ref_n.abs() + self.force_error_n(k);
        r.strip.wheel_z_m = z;
        r.strip.contact_force_n = self.force_ref_n.abs();
        r.strip.bottom_force_n = -bottom;
        r.strip.top_displacement_m = -4e-4;
        let peak = if z < self.coverage_z_m { self.peak_pressure_pa } else { self.peak_pressure_pa / 3.0 };
        let zs = self.centreline_z_m();
        r.strip.n_centreline = zs.len() as u32;
        let mut max = 0.0f64;
        for (i, zi) in zs.iter().enumerate() {
            let p = peak * (-((zi - z) / 0.002).powi(2)).exp();
            r.strip.centreline_pressure_pa[i] = p;
            max = max.max(p);
        }
        r.strip.max_bottom_pressure_pa = max;
        r.timing.publish_wall_ns = 1_763_779_200_000_000_000 + k * 1_000_000;
        r.timing.period_ns = 1_000_000;
        r.timing.missed = miss;
        if !miss {
            r.timing.round_trip_ns = self.round_trip_ns(k);
            r.timing.torque_receive_wall_ns = r.timing.publish_wall_ns + r.timing.round_trip_ns;
        }
        r.timing.plant_compute_ns = 100_000;
        r.timing.controller_compute_ns = 20_000;
        r
    }

    fn tick_tau(&self, k: u64) -> [f64; 6] {
        let t = k as f64 * self.period_s;
        std::array::from_fn(|j| 10.0 * (j as f64 + 1.0) + (t * 3.0 + j as f64).sin())
    }

    /// Events of the run: start at tick 0, one safe stop and its clearing, stop at the end.
    pub fn events(&self) -> Vec<EventRecord> {
        let mid = self.ticks / 2;
        let t = |k: u64| k as f64 * self.period_s;
        vec![
            EventRecord::new(0, 0.0, EventKind::Start, "synthetic run"),
            EventRecord::new(mid, t(mid), EventKind::SafeStop, "synthetic safe stop"),
            EventRecord::new(mid + 1, t(mid + 1), EventKind::SafeStopCleared, "synthetic safe stop cleared"),
            EventRecord::new(self.ticks - 1, t(self.ticks - 1), EventKind::Stop, "end"),
        ]
    }

    /// Writes the whole run through a [`crate::Recorder`] (events at their ticks).
    pub fn record(&self, cfg: crate::RecorderConfig) -> Result<crate::RecordingSummary, crate::RecorderError> {
        self.record_with(cfg, crate::RecorderTuning::default())
    }

    /// [`SyntheticRun::record`] with the writer's knobs given.
    pub fn record_with(
        &self,
        cfg: crate::RecorderConfig,
        tuning: crate::RecorderTuning,
    ) -> Result<crate::RecordingSummary, crate::RecorderError> {
        let mut rec = crate::Recorder::start_with(cfg, tuning)?;
        let events = self.events();
        for k in 0..self.ticks {
            for e in events.iter().filter(|e| e.tick == k) {
                while rec.queue_free() == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
                rec.record_event(e);
            }
            let r = self.tick(k);
            // Tests want every tick: wait for the writer instead of dropping.
            while rec.queue_free() == 0 {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            rec.record_tick(&r);
        }
        rec.finish()
    }
}
