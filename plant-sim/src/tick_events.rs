//! What one plant tick raised (a refused torque, a miss streak, a safe stop, a take-over, a
//! saturated sensor, a reflex, an end stop) as a fixed-size value: [`crate::PlantTick::advance`]
//! returns it and records, logs and waits for nothing (copper-rs keeps that work out of
//! `process`); every driver hands the events on with one [`EventHandOn`].

use crate::gate::Refusal;
use crate::limits::Reflex;
use crate::recording::{EventKind, EventRecord, Recorder};
use crate::stack_text::StackText;

/// Why the plant entered its safe stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SafeStopCause {
    /// The controller reported a fault of its own.
    ControllerFault,
    /// This many consecutive misses (`loop.max_consecutive_misses`).
    Misses(u32),
    /// The active controller's process ended or its node is dead, and nobody took over.
    ControllerGone,
}

/// One rare event of the plant's tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantEvent {
    /// The first refused torque of a streak (a bad controller refuses every tick).
    Refused(Refusal),
    /// The first miss after a good tick; the gate's total misses after it.
    MissStreak {
        total_misses: u64,
    },
    SafeStop(SafeStopCause),
    SafeStopCleared,
    /// A controller took over (`old` None: the first controller connected).
    ControllerChange {
        old: Option<u64>,
        new: u64,
    },
    /// The force/torque sensor's reading at its range (sensor frame, N and N m).
    SensorSaturated {
        reading: [f64; 6],
    },
    SensorWithinRange,
    /// A reflex: safe stop until the controller acknowledges.
    Reflex(Reflex),
    /// A joint entered its end stop at `q_rad` (its range `range_rad`); `joint` counts from 0.
    EndStop {
        joint: usize,
        q_rad: f64,
        range_rad: [f64; 2],
    },
}

/// How loudly an event is logged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Level {
    /// Recorded in `/events` only.
    None,
    Info,
    Warn,
    Error,
}

impl PlantEvent {
    /// Its `/events` kind.
    pub fn kind(&self) -> EventKind {
        match self {
            PlantEvent::Refused(Refusal::Version(_)) => EventKind::VersionMismatch,
            PlantEvent::Refused(_) => EventKind::TorqueRefused,
            PlantEvent::MissStreak { .. } => EventKind::Miss,
            PlantEvent::SafeStop(_) => EventKind::SafeStop,
            PlantEvent::SafeStopCleared => EventKind::SafeStopCleared,
            PlantEvent::ControllerChange { .. } => EventKind::ControllerChange,
            PlantEvent::SensorSaturated { .. } | PlantEvent::SensorWithinRange => EventKind::Info,
            PlantEvent::Reflex(_) => EventKind::Reflex,
            PlantEvent::EndStop { .. } => EventKind::EndStop,
        }
    }

    /// Its one-sentence `/events` text, raised at `tick`.
    pub fn write_text(&self, tick: u64, s: &mut impl std::fmt::Write) -> std::fmt::Result {
        match *self {
            PlantEvent::Refused(r) => write!(s, "tick {tick}: {r}"),
            PlantEvent::MissStreak { .. } => write!(s, "tick {tick}: no valid torque in time, holding the last one"),
            PlantEvent::SafeStop(SafeStopCause::ControllerFault) => {
                write!(s, "tick {tick}: safe stop requested by the controller (fault)")
            }
            PlantEvent::SafeStop(SafeStopCause::Misses(n)) => {
                write!(s, "tick {tick}: safe stop after {n} consecutive misses (the plant's hold)")
            }
            PlantEvent::SafeStop(SafeStopCause::ControllerGone) => {
                write!(s, "tick {tick}: safe stop: the controller is gone (the plant's hold)")
            }
            PlantEvent::SafeStopCleared => write!(s, "tick {tick}: safe stop cleared, controller resumes (blended in)"),
            PlantEvent::ControllerChange { old: Some(old), new } => {
                write!(s, "tick {tick}: controller {new:#x} takes over from {old:#x} (blended in)")
            }
            PlantEvent::ControllerChange { old: None, new } => write!(s, "tick {tick}: controller {new:#x} connected"),
            PlantEvent::SensorSaturated { reading: r } => write!(
                s,
                "tick {tick}: force/torque sensor saturated: reads ({:.3}, {:.3}, {:.3}) N, ({:.4}, {:.4}, {:.4}) N m at its range",
                r[0], r[1], r[2], r[3], r[4], r[5]
            ),
            PlantEvent::SensorWithinRange => write!(s, "tick {tick}: force/torque sensor back within its range"),
            PlantEvent::Reflex(r) => write!(s, "tick {tick}: {r}: safe stop until the controller acknowledges"),
            PlantEvent::EndStop { joint, q_rad, range_rad: [lo, hi] } => {
                write!(s, "tick {tick}: joint {} in its end stop at {q_rad:.4} rad (range {lo:.4} .. {hi:.4} rad)", joint + 1)
            }
        }
    }

    fn level(&self) -> Level {
        match self {
            PlantEvent::Refused(_) | PlantEvent::MissStreak { .. } => Level::Warn,
            PlantEvent::SafeStop(SafeStopCause::ControllerGone) | PlantEvent::SensorWithinRange => Level::None,
            PlantEvent::SafeStop(_) | PlantEvent::Reflex(_) => Level::Error,
            PlantEvent::SafeStopCleared | PlantEvent::ControllerChange { .. } => Level::Info,
            PlantEvent::SensorSaturated { .. } | PlantEvent::EndStop { .. } => Level::Warn,
        }
    }

    /// A flapping controller starts a miss or refusal streak every few ticks: each is recorded,
    /// but these are logged at most once per second of ticks.
    fn rate_limited(&self) -> bool {
        matches!(self, PlantEvent::Refused(_) | PlantEvent::MissStreak { .. })
    }
}

/// An event with the tick (and its simulated time) it belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Raised {
    pub tick: u64,
    pub sim_time_s: f64,
    pub event: PlantEvent,
}

/// The most events one tick raises: the gate's five, the sensor's, a reflex and an end stop.
pub const TICK_EVENTS_MAX: usize = 8;

/// The events of one tick, in the order they happened; fixed size, no heap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickEvents {
    items: [Option<Raised>; TICK_EVENTS_MAX],
    len: usize,
}

impl Default for TickEvents {
    fn default() -> Self {
        TickEvents { items: [None; TICK_EVENTS_MAX], len: 0 }
    }
}

impl TickEvents {
    /// Add an event; one past [`TICK_EVENTS_MAX`] is a bug of the tick's code, not of the input.
    pub(crate) fn push(&mut self, tick: u64, sim_time_s: f64, event: PlantEvent) {
        debug_assert!(self.len < TICK_EVENTS_MAX, "more than {TICK_EVENTS_MAX} events in one tick");
        if let Some(slot) = self.items.get_mut(self.len) {
            *slot = Some(Raised { tick, sim_time_s, event });
            self.len += 1;
        }
    }

    pub fn iter(&self) -> impl Iterator<Item = &Raised> {
        self.items[..self.len].iter().flatten()
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The reflex raised this tick, if any.
    pub fn reflex(&self) -> Option<Reflex> {
        self.iter().find_map(|r| match r.event {
            PlantEvent::Reflex(x) => Some(x),
            _ => None,
        })
    }
}

/// Hands a driver's tick events on: each to the recorder's `/events`, and to the log (rate-
/// limited streaks at most once per second of ticks). Allocation-free; it formats on the stack.
#[derive(Debug, Clone, Copy)]
pub struct EventHandOn {
    ticks_per_s: u64,
    /// Tick of the last rate-limited log line.
    last_log_tick: Option<u64>,
    /// Log Info-level events too (false: warnings and errors only; every event is recorded).
    log_info: bool,
}

impl EventHandOn {
    pub fn new(period_ns: u64) -> EventHandOn {
        EventHandOn { ticks_per_s: 1_000_000_000 / period_ns.max(1), last_log_tick: None, log_info: true }
    }

    /// Log only the warnings and errors (the cases of a sweep or study: each would otherwise log
    /// its "controller connected"); the recording gets every event all the same.
    pub fn quiet(self) -> EventHandOn {
        EventHandOn { log_info: false, ..self }
    }

    /// Record and log every event of `events`.
    pub fn hand_on(&mut self, events: &TickEvents, mut recorder: Option<&mut Recorder>) {
        for r in events.iter() {
            self.one(r, recorder.as_deref_mut());
        }
    }

    /// Record and log one event.
    pub fn one(&mut self, r: &Raised, recorder: Option<&mut Recorder>) {
        let mut s = StackText::new();
        let _ = r.event.write_text(r.tick, &mut s);
        let log = !r.event.rate_limited() || {
            // Every rate-limited event of the tick that opened a log second is logged.
            let may = self.last_log_tick.is_none_or(|l| r.tick == l || r.tick >= l + self.ticks_per_s);
            if may {
                self.last_log_tick = Some(r.tick);
            }
            may
        };
        if log {
            match (r.event.level(), r.event) {
                (Level::None, _) => {}
                (_, PlantEvent::MissStreak { total_misses }) => tracing::warn!("{} (total misses {total_misses})", s.as_str()),
                (Level::Info, _) if self.log_info => tracing::info!("{}", s.as_str()),
                (Level::Info, _) => {}
                (Level::Warn, _) => tracing::warn!("{}", s.as_str()),
                (Level::Error, _) => tracing::error!("{}", s.as_str()),
            }
        }
        record_event(recorder, r.tick, r.sim_time_s, r.event.kind(), s.as_str());
    }
}

/// Record a rare event, if there is a recorder.
pub fn record_event(recorder: Option<&mut Recorder>, tick: u64, sim_time_s: f64, kind: EventKind, text: &str) {
    if let Some(r) = recorder {
        r.record_event(&EventRecord::new(tick, sim_time_s, kind, text));
    }
}

/// Queue slots a lockstep tick waits for before it advances: its tick record and the events one
/// tick can raise ([`crate::tick_events::TICK_EVENTS_MAX`] and the driver's own) with room to spare.
const LOCKSTEP_RECORD_SLOTS: usize = 16;
/// The longest a lockstep tick waits for the writer; after that the record is a counted drop
/// (a writer that no longer drains its queue must not hang the run).
const LOCKSTEP_RECORD_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// Lockstep has no deadline: before a tick advances, wait for the writer (on a loaded host it
/// falls behind a plant running 30x real time) instead of dropping the tick's record and events.
/// Every lockstep driver (torque loop, EGM, in process) calls it; real time never waits.
pub fn make_room_for_tick(recorder: Option<&mut Recorder>) {
    if let Some(r) = recorder {
        r.wait_for_room(LOCKSTEP_RECORD_SLOTS, LOCKSTEP_RECORD_WAIT);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_keep_their_order_and_the_reflex_is_found() {
        let mut e = TickEvents::default();
        assert!(e.is_empty() && e.reflex().is_none());
        e.push(3, 0.003, PlantEvent::MissStreak { total_misses: 1 });
        let reflex = Reflex::ContactForce { value_n: 80.0, limit_n: 60.0 };
        e.push(4, 0.004, PlantEvent::Reflex(reflex));
        e.push(4, 0.004, PlantEvent::EndStop { joint: 5, q_rad: 3.5, range_rad: [-3.49, 3.49] });
        let ticks: Vec<u64> = e.iter().map(|r| r.tick).collect();
        assert_eq!(ticks, [3, 4, 4]);
        assert_eq!(e.reflex(), Some(reflex));
    }

    #[test]
    fn texts_name_the_tick_and_the_joint_from_one() {
        let mut s = String::new();
        PlantEvent::EndStop { joint: 5, q_rad: 3.5, range_rad: [-3.49, 3.49] }.write_text(7, &mut s).unwrap();
        assert_eq!(s, "tick 7: joint 6 in its end stop at 3.5000 rad (range -3.4900 .. 3.4900 rad)");
        s.clear();
        PlantEvent::ControllerChange { old: Some(1), new: 2 }.write_text(9, &mut s).unwrap();
        assert_eq!(s, "tick 9: controller 0x2 takes over from 0x1 (blended in)");
    }

    #[test]
    fn streaks_are_logged_once_per_second_of_ticks_but_all_recorded() {
        let mut h = EventHandOn::new(1_000_000);
        let miss = |tick| Raised { tick, sim_time_s: 0.0, event: PlantEvent::MissStreak { total_misses: tick } };
        // The rate limit's state: a tick opens a log second; streaks within it are not logged.
        h.one(&miss(10), None);
        assert_eq!(h.last_log_tick, Some(10));
        h.one(&miss(10), None);
        h.one(&miss(500), None);
        assert_eq!(h.last_log_tick, Some(10));
        h.one(&miss(1010), None);
        assert_eq!(h.last_log_tick, Some(1010));
    }
}
