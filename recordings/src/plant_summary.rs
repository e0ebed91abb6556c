//! The plant's summary of a run: the one JSON line `plant-sim` prints on stdout when it ends (and
//! the in-process run returns), read by `rig` for its summary, exit status and `rig timing`
//! report, and by the end-to-end tests.
//!
//! Every field is required when read: a line without one is refused with serde's error naming
//! the field (`missing field `safe_stops``), never read as 0, NaN or false. Values that may
//! legitimately be absent (a first safe-stop tick, the live view, the host probe, the EGM
//! counters) are `Option`s written as `null` and still required. Times in µs where the name
//! ends in `_us`, s where it ends in `_s`.

use serde::{Deserialize, Serialize};

/// The plant's summary of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantSummary {
    pub rig: String,
    pub mode: scenarios::Mode,
    /// Ticks integrated.
    pub ticks: u64,
    /// Ticks whose torque came too late (real time) and was held.
    pub misses: u64,
    pub safe_stops: u64,
    /// Torques the plant refused (out of range, non-finite).
    pub refusals: u64,
    pub reflexes: u64,
    /// Answers from a controller that is not the connected one, ignored.
    pub foreign_answers: u64,
    #[serde(deserialize_with = "required")]
    pub first_safe_stop_tick: Option<u64>,
    #[serde(deserialize_with = "required")]
    pub first_reflex_tick: Option<u64>,
    #[serde(deserialize_with = "required")]
    pub first_refusal_tick: Option<u64>,
    pub controller_ended: bool,
    /// Skipped periods (real time).
    pub overruns: u64,
    pub lost_wakeups: u64,
    pub lost_wakeups_in_a_row: u64,
    /// Round-trip latency quantiles, µs (as in `round_trip`).
    pub rt_p50_us: f64,
    pub rt_p99_us: f64,
    pub rt_max_us: f64,
    /// The MCAP file, None: not recorded.
    #[serde(deserialize_with = "required")]
    pub recording: Option<String>,
    /// Ticks and events the recorder's queue refused (must be 0).
    pub drops: u64,
    /// Why the recorder ended the recording before the run ended, None: it did not.
    #[serde(deserialize_with = "required")]
    pub recording_stopped_early: Option<String>,
    /// The live view's address and what it sent and dropped, None: it did not run.
    #[serde(deserialize_with = "required")]
    pub live: Option<LiveReport>,
    pub wall_s: f64,
    pub sim_s: f64,
    /// Simulated over wall time while the loop ran (0 when nothing ran).
    pub speed_factor: f64,
    pub stopped_by_signal: bool,
    pub sched_fifo: bool,
    /// Memory locked (real time only: a lockstep run locks none).
    pub mlockall: bool,
    pub round_trip: Distribution,
    /// |period - T|.
    pub jitter: Distribution,
    pub plant_compute: Distribution,
    pub controller_compute: Distribution,
    /// What the host-floor probe measured, None: it did not run.
    #[serde(deserialize_with = "required")]
    pub host_probe: Option<HostProbe>,
    /// The EGM counters, None: not an EGM run.
    #[serde(deserialize_with = "required")]
    pub egm: Option<EgmCounters>,
}

/// The live view of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveReport {
    /// `host:port` it served on.
    pub addr: String,
    pub sent: u64,
    pub dropped: u64,
}

/// A latency distribution: quantiles and maximum in µs, and a binned histogram.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Distribution {
    pub count: u64,
    pub mean_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub p9999_us: f64,
    pub max_us: f64,
    /// `[from µs, to µs (null: open-ended), count]` per bin.
    pub bins: Vec<(f64, Option<f64>, u64)>,
}

/// The host-floor probe's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HostProbe {
    /// A wake-up at least this late is a stall, µs.
    pub stall_threshold_us: f64,
    pub cpus: Vec<CpuProbe>,
}

/// What the host-floor probe saw on one CPU.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CpuProbe {
    pub cpu: usize,
    pub period_us: f64,
    pub pinned: bool,
    /// False: SCHED_FIFO was refused and the probe measured the normal scheduler.
    pub sched_fifo: bool,
    /// Wake-up latency.
    pub latency: Distribution,
    pub stalls: u64,
    /// The latest stalls, oldest first: `[ms after the plant's first deadline, µs late]`.
    pub recent_stalls: Vec<(f64, f64)>,
}

/// The counters of an EGM run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EgmCounters {
    pub accepted: u64,
    pub refused: u64,
    pub cycles: u64,
    #[serde(deserialize_with = "required")]
    pub session_ended_tick: Option<u64>,
}

/// An `Option` field that must be there (`null` when absent): serde's derive would read a
/// missing `Option` as None.
fn required<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    Option::<T>::deserialize(d)
}

/// A summary line that does not read as a [`PlantSummary`].
#[derive(Debug, thiserror::Error)]
#[error("the plant's summary does not read: {0}")]
pub struct SummaryError(#[from] pub serde_json::Error);

impl PlantSummary {
    /// The one line `plant-sim` prints: JSON with its keys in alphabetical order at every level
    /// (as the plant has always printed it), no newline.
    pub fn to_line(&self) -> String {
        self.to_value().to_string()
    }

    /// As a JSON value (keys sorted), for tests and `rig run --json`.
    pub fn to_value(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("a PlantSummary is plain data (string keys, no map to fail on)")
    }

    /// Reads a summary line; a missing field is an error naming it.
    pub fn from_line(line: &str) -> Result<Self, SummaryError> {
        Ok(serde_json::from_str(line)?)
    }

    /// Reads a summary from a JSON value; a missing field is an error naming it.
    pub fn from_value(v: serde_json::Value) -> Result<Self, SummaryError> {
        Ok(serde_json::from_value(v)?)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A complete summary with every optional part present.
    pub(crate) fn example() -> PlantSummary {
        let d = Distribution {
            count: 3,
            mean_us: 1.5,
            p50_us: 1.0,
            p90_us: 2.0,
            p99_us: 2.0,
            p999_us: 2.0,
            p9999_us: 2.0,
            max_us: 2.25,
            bins: vec![(0.0, Some(10.0), 3), (10.0, None, 0)],
        };
        PlantSummary {
            rig: "r".into(),
            mode: scenarios::Mode::Realtime,
            ticks: 3,
            misses: 1,
            safe_stops: 0,
            refusals: 0,
            reflexes: 0,
            foreign_answers: 0,
            first_safe_stop_tick: None,
            first_reflex_tick: None,
            first_refusal_tick: Some(2),
            controller_ended: false,
            overruns: 0,
            lost_wakeups: 0,
            lost_wakeups_in_a_row: 0,
            rt_p50_us: 1.0,
            rt_p99_us: 2.0,
            rt_max_us: 2.25,
            recording: Some("runs/x/run.mcap".into()),
            drops: 0,
            recording_stopped_early: None,
            live: Some(LiveReport { addr: "127.0.0.1:8765".into(), sent: 10, dropped: 1 }),
            wall_s: 0.003,
            sim_s: 0.003,
            speed_factor: 1.0,
            stopped_by_signal: false,
            sched_fifo: true,
            mlockall: true,
            round_trip: d.clone(),
            jitter: d.clone(),
            plant_compute: d.clone(),
            controller_compute: d.clone(),
            host_probe: Some(HostProbe {
                stall_threshold_us: 100.0,
                cpus: vec![CpuProbe {
                    cpu: 0,
                    period_us: 250.0,
                    pinned: true,
                    sched_fifo: true,
                    latency: d,
                    stalls: 1,
                    recent_stalls: vec![(1000.5, 150.0)],
                }],
            }),
            egm: Some(EgmCounters { accepted: 1, refused: 0, cycles: 1, session_ended_tick: None }),
        }
    }

    #[test]
    fn a_summary_reads_back_as_written_with_nulls_for_what_is_absent() {
        let s = example();
        assert_eq!(PlantSummary::from_line(&s.to_line()).unwrap(), s);
        let none = PlantSummary { live: None, host_probe: None, egm: None, recording: None, ..example() };
        let line = none.to_line();
        assert!(line.contains(r#""egm":null"#) && line.contains(r#""host_probe":null"#), "{line}");
        assert_eq!(PlantSummary::from_line(&line).unwrap(), none);
    }

    #[test]
    fn the_line_has_its_keys_in_alphabetical_order() {
        let line = example().to_line();
        let keys: Vec<&str> = line.split(r#",""#).map(|k| k.split('"').next().unwrap_or("")).collect();
        assert!(line.starts_with(r#"{"controller_compute":"#), "{line}");
        assert!(keys.len() > 30, "{keys:?}");
    }

    #[test]
    fn a_summary_without_a_field_is_refused_naming_it() {
        for (path, field) in
            [(&[][..], "safe_stops"), (&[][..], "first_reflex_tick"), (&["egm"][..], "session_ended_tick"), (&["jitter"][..], "p99_us")]
        {
            let mut v = example().to_value();
            let mut at = &mut v;
            for p in path {
                at = &mut at[*p];
            }
            at.as_object_mut().unwrap().remove(field);
            let e = PlantSummary::from_value(v).unwrap_err().to_string();
            assert!(e.contains(&format!("missing field `{field}`")), "{e}");
        }
    }
}
