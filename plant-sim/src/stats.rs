//! What a plant run counts, for the summary `plant-sim` prints: every driver (the real-time and
//! lockstep loops, the EGM loop, in-process runs) fills one [`LoopStats`].

use crate::histogram::Histogram;
use crate::tick::PlantTick;

/// Statistics of a run, kept in fixed-size histograms.
#[derive(Debug, Clone)]
pub struct LoopStats {
    pub ticks: u64,
    pub misses: u64,
    pub safe_stops: u64,
    pub refusals: u64,
    pub overruns: u64,
    /// Publish → torque received, for ticks answered in time.
    pub round_trip: Histogram,
    /// |actual period − nominal period| between consecutive publishes (real-time pacing only).
    pub jitter: Histogram,
    /// Plant work per tick: wake → publish plus torque received → tick integrated and recorded.
    pub plant_compute: Histogram,
    /// Controller compute as it reports it in its diagnostics.
    pub controller_compute: Histogram,
    pub wall_s: f64,
    pub sim_s: f64,
    /// Wall and simulated time from the first controller answer to the end (the speed factor's
    /// basis: start-up waits for the controller are excluded).
    pub active_wall_s: f64,
    pub active_sim_s: f64,
    pub stopped_by_signal: bool,
    pub reflexes: u64,
    /// Answers from publishers other than the active controller, ignored.
    pub foreign_answers: u64,
    /// First tick of a safe stop, a reflex, a refused torque (the exit status' story).
    pub first_safe_stop_tick: Option<u64>,
    pub first_reflex_tick: Option<u64>,
    pub first_refusal_tick: Option<u64>,
    /// The launcher reported the controller process ended, or its node was seen dead.
    pub controller_ended: bool,
    /// Torque wait slices that ran out although a notification had come, each costing up to
    /// 1 ms: a wake-up iceoryx2 lost (`rig_process::ports`), or a controller preempted inside its
    /// `notify` (its event activated, its datagram not yet sent) for the rest of the slice.
    pub lost_wakeups: u64,
    /// The most ticks in a row that lost a wake-up. iceoryx2's lost wake-up, left alone, lasts
    /// until the listener is drained: every later tick (the waits before issue 22).
    pub lost_wakeups_in_a_row: u64,
    lost_streak: u64,
}

impl LoopStats {
    /// The plant's counters at the end of a run (misses, safe stops, refusals, reflexes, their
    /// first ticks, simulated time).
    pub fn count_plant(&mut self, plant: &PlantTick) {
        let g = plant.gate();
        self.misses = g.total_misses();
        self.safe_stops = g.safe_stops();
        self.refusals = g.refusals();
        self.reflexes = g.reflexes();
        let f = plant.first_ticks();
        self.first_safe_stop_tick = f.safe_stop;
        self.first_reflex_tick = f.reflex;
        self.first_refusal_tick = f.refusal;
        self.sim_s = plant.physics().time_s();
    }

    /// A run's statistics before its first tick.
    pub fn empty() -> LoopStats {
        LoopStats {
            ticks: 0,
            misses: 0,
            safe_stops: 0,
            refusals: 0,
            overruns: 0,
            round_trip: Histogram::for_latency(),
            jitter: Histogram::for_latency(),
            plant_compute: Histogram::for_latency(),
            controller_compute: Histogram::for_latency(),
            wall_s: 0.0,
            sim_s: 0.0,
            active_wall_s: 0.0,
            active_sim_s: 0.0,
            stopped_by_signal: false,
            reflexes: 0,
            foreign_answers: 0,
            first_safe_stop_tick: None,
            first_reflex_tick: None,
            first_refusal_tick: None,
            controller_ended: false,
            lost_wakeups: 0,
            lost_wakeups_in_a_row: 0,
            lost_streak: 0,
        }
    }

    /// Count one tick's lost wake-ups (`PlantLoop::wait_for_answers`).
    pub(crate) fn note_lost_wakeups(&mut self, lost: u64) {
        self.lost_wakeups += lost;
        self.lost_streak = if lost > 0 { self.lost_streak + 1 } else { 0 };
        self.lost_wakeups_in_a_row = self.lost_wakeups_in_a_row.max(self.lost_streak);
    }
}
