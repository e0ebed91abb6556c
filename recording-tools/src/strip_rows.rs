//! The `/strip` rows the rolling-phase numbers ([`crate::report::rolling_numbers_of`]) read: a
//! recording's ([`RecordedRows`]), or a case's kept in memory as the writer would have recorded
//! them ([`CaseRows`]: pressures and moving node z rounded to f32 as `/strip` stores them). A sweep
//! or study case that writes no file gets the figures its recording would have given, bit for
//! bit, without the writer's and the reader's CPU (a third of a sweep's).

use crate::read::Recording;
use crate::tracking::TrackingTick;
use recordings::{TickRecord, MAX_CENTRELINE};

/// One `/strip` row per tick: the wheel's z, and the centre-line nodes' z and bottom pressure.
pub trait StripRows {
    /// Wheel position along the strip (task z) of row `i`, m.
    fn wheel_z_m(&self, i: usize) -> f64;
    /// Bottom pressure at row `i`'s centre-line nodes, Pa, as recorded (f32).
    fn centreline_pressure_pa(&self, i: usize) -> &[f32];
    /// z of row `i`'s centre-line nodes, m (into `scratch` when they move with the wheel).
    fn centreline_z_m<'s>(&'s self, i: usize, scratch: &'s mut Vec<f64>) -> &'s [f64];
}

/// A recording's `/strip` rows.
pub struct RecordedRows<'r> {
    rec: &'r Recording,
    fixed_z_m: Vec<f64>,
    moving: bool,
}

impl<'r> RecordedRows<'r> {
    pub fn of(rec: &'r Recording) -> Self {
        Self { rec, fixed_z_m: rec.centreline_z_m(), moving: rec.strip_nodes_move() }
    }
}

impl StripRows for RecordedRows<'_> {
    fn wheel_z_m(&self, i: usize) -> f64 {
        self.rec.strip[i].wheel_z_m
    }

    fn centreline_pressure_pa(&self, i: usize) -> &[f32] {
        &self.rec.strip[i].centreline_pressure_pa
    }

    fn centreline_z_m<'s>(&'s self, i: usize, scratch: &'s mut Vec<f64>) -> &'s [f64] {
        if !self.moving {
            return &self.fixed_z_m;
        }
        // a windowed strip's nodes move with the wheel: this row's own
        scratch.clear();
        scratch.extend(self.rec.strip_row_z(i).iter().map(|&z| z as f64));
        scratch
    }
}

/// A case's tick rows kept in memory, as the recording would hold them: what
/// [`crate::tracking_input::tracking_ticks`] and [`RecordedRows`] would read back.
pub struct CaseRows {
    ticks: Vec<TrackingTick>,
    wheel_z_m: Vec<f64>,
    /// Every row's pressures, one after the other; row `i` is `row_start[i]..row_start[i + 1]`.
    pressure_pa: Vec<f32>,
    row_start: Vec<usize>,
    /// Per row, its first node's z and the node spacing when the nodes move (spacing > 0), m.
    moving_z_m: Vec<(f64, f64)>,
    /// The fixed nodes' z (the recording's metadata `centreline_z_m`), m; empty without a strip.
    fixed_z_m: Vec<f64>,
}

impl CaseRows {
    /// `fixed_centreline_z_m`: the plant's centre-line node z (what the recording's metadata
    /// would hold), empty without a strip; `ticks`: the run's length, reserved.
    pub fn new(fixed_centreline_z_m: Vec<f64>, ticks: usize) -> Self {
        Self {
            ticks: Vec::with_capacity(ticks),
            wheel_z_m: Vec::with_capacity(ticks),
            pressure_pa: Vec::with_capacity(ticks * fixed_centreline_z_m.len()),
            row_start: {
                let mut v = Vec::with_capacity(ticks + 1);
                v.push(0);
                v
            },
            moving_z_m: Vec::with_capacity(ticks),
            fixed_z_m: fixed_centreline_z_m,
        }
    }

    /// One tick as the writer records it (`/joint_state`, `/strip`, and `/controller` when the
    /// tick has diagnostics).
    pub fn push(&mut self, r: &TickRecord) {
        let s = &r.strip;
        self.ticks.push(TrackingTick {
            in_contact: r.state.flags & messages::state_flags::IN_CONTACT != 0 || s.contact_force_n != 0.0,
            z_ref_m: r.has_diag.then_some(r.diag.pos_ref_task_m[2]),
            wheel_z_m: s.wheel_z_m,
            force_ref_n: r.has_diag.then_some(r.diag.force_ref_n),
            bottom_force_n: s.bottom_force_n,
        });
        self.wheel_z_m.push(s.wheel_z_m);
        let n = (s.n_centreline as usize).min(MAX_CENTRELINE);
        self.pressure_pa.extend(s.centreline_pressure_pa[..n].iter().map(|&p| p as f32));
        self.row_start.push(self.pressure_pa.len());
        self.moving_z_m.push((s.centreline_z0_m, s.centreline_dz_m));
    }

    /// The tick rows as the rolling-phase metric takes them (their figures:
    /// `CaseRows::rolling_numbers`, in `report.rs`, which reads these rows and not the reverse).
    pub fn ticks(&self) -> &[TrackingTick] {
        &self.ticks
    }
}

impl StripRows for CaseRows {
    fn wheel_z_m(&self, i: usize) -> f64 {
        self.wheel_z_m[i]
    }

    fn centreline_pressure_pa(&self, i: usize) -> &[f32] {
        &self.pressure_pa[self.row_start[i]..self.row_start[i + 1]]
    }

    fn centreline_z_m<'s>(&'s self, i: usize, scratch: &'s mut Vec<f64>) -> &'s [f64] {
        let (z0, dz) = self.moving_z_m[i];
        if dz <= 0.0 {
            return &self.fixed_z_m;
        }
        // the writer's expansion of a moving row, rounded to f32 as `/strip` stores it
        let n = self.row_start[i + 1] - self.row_start[i];
        scratch.clear();
        scratch.extend((0..n).map(|k| (z0 + k as f64 * dz) as f32 as f64));
        scratch
    }
}
