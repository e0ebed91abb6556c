//! What one plant run reports: the loop's counters, the recording's fate, the real-time set-up,
//! the live view, the host probe and EGM's counters, and the typed line `plant-sim` prints.

use std::path::PathBuf;

use recordings::PlantSummary;
use scenarios::Mode;

use crate::stats::LoopStats;
use rig_process::rt;

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
