//! One controller at a time (DESIGN section 10): which of a tick's answers the plant obeys.
//!
//! The plant follows the *active* controller, identified by the iceoryx2 publisher id of its
//! torque publisher. Answers from any other publisher are ignored and reported once per
//! publisher. Another publisher takes over only when the active one has missed
//! `takeover_after_misses` ticks in a row (default 3) or is gone (its node is dead, see
//! `rig_process::liveness`), and then the newest candidate (the publisher first heard last) that
//! answered this tick: one switch per take-over; the gate blends it in.
//!
//! Pure, fixed-size logic: unit-tested here, driven by the plant loop.

use messages::JointTorque;
use rig_process::ports::{Answer, Answers};

/// Publishers remembered (first heard, reported); more than the torque service allows.
const SEEN: usize = 8;

/// Why a candidate took over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TakeoverReason {
    /// No controller was active yet.
    First,
    /// The active controller missed this many ticks in a row.
    Missed(u32),
    /// The active controller's node is dead or its publisher left.
    Gone,
}

/// The arbiter's rare events of one tick.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ArbiterEvents {
    /// A publisher that is not the active controller answered, reported the first time:
    /// `(publisher id, its controller_id)`. At most one per tick; others are reported later.
    pub ignored: Option<(u128, u64)>,
    /// A take-over: `(previous active publisher, new publisher, why)`.
    pub takeover: Option<(Option<u128>, u128, TakeoverReason)>,
}

#[derive(Debug, Clone, Copy)]
struct Seen {
    origin: u128,
    first_tick: u64,
    reported: bool,
}

/// The arbiter's state across ticks.
#[derive(Debug, Clone)]
pub struct Arbiter {
    takeover_after_misses: u32,
    active: Option<u128>,
    active_missed: u32,
    seen: [Option<Seen>; SEEN],
    ignored_answers: u64,
}

impl Arbiter {
    pub fn new(takeover_after_misses: u32) -> Arbiter {
        Arbiter {
            takeover_after_misses: takeover_after_misses.max(1),
            active: None,
            active_missed: 0,
            seen: [None; SEEN],
            ignored_answers: 0,
        }
    }

    /// The active controller's publisher id.
    pub fn active(&self) -> Option<u128> {
        self.active
    }

    /// Answers from other publishers that were ignored, in all.
    pub fn ignored_answers(&self) -> u64 {
        self.ignored_answers
    }

    /// True when this tick's answers settle the tick: the active controller answered, or there is
    /// none yet and someone answered, or the active one is `gone` and a candidate answered. The
    /// lockstep plant waits until then (or its watchdog).
    pub fn settled(&self, answers: &Answers, gone: bool) -> bool {
        match self.active {
            Some(a) => answers.from_origin(a).is_some() || (gone && !answers.is_empty()),
            None => !answers.is_empty(),
        }
    }

    fn note(&mut self, a: &Answer, tick: u64) {
        if self.seen.iter().flatten().any(|s| s.origin == a.origin) {
            return;
        }
        let slot = match self.seen.iter().position(Option::is_none) {
            Some(i) => i,
            // Forget the oldest-heard publisher.
            None => (0..SEEN).min_by_key(|&i| self.seen[i].map_or(0, |s| s.first_tick)).unwrap_or(0),
        };
        self.seen[slot] = Some(Seen { origin: a.origin, first_tick: tick, reported: false });
    }

    fn first_tick(&self, origin: u128) -> u64 {
        self.seen.iter().flatten().find(|s| s.origin == origin).map_or(0, |s| s.first_tick)
    }

    /// Choose the torque to obey for `tick` from its `answers`; `active_gone` is the liveness
    /// verdict on the active controller. Returns that torque (None = the active controller has not
    /// answered: a miss) and the events.
    pub fn choose(&mut self, answers: &Answers, active_gone: bool, tick: u64) -> (Option<JointTorque>, ArbiterEvents) {
        let mut ev = ArbiterEvents::default();
        for a in answers.iter() {
            self.note(a, tick);
        }
        let from_active = self.active.and_then(|id| answers.from_origin(id));
        let chosen = match from_active {
            Some(a) => {
                self.active_missed = 0;
                Some(*a)
            }
            None => {
                let active = self.active;
                if active.is_some() {
                    self.active_missed += 1;
                }
                let reason = match active {
                    None => Some(TakeoverReason::First),
                    Some(_) if active_gone => Some(TakeoverReason::Gone),
                    Some(_) if self.active_missed >= self.takeover_after_misses => Some(TakeoverReason::Missed(self.active_missed)),
                    Some(_) => None,
                };
                // The newest candidate: the publisher first heard last (ties: the larger id).
                let newest = answers.iter().max_by_key(|a| (self.first_tick(a.origin), a.origin)).copied();
                match (reason, newest) {
                    (Some(why), Some(n)) => {
                        ev.takeover = Some((active, n.origin, why));
                        self.active = Some(n.origin);
                        self.active_missed = 0;
                        Some(n)
                    }
                    _ => None,
                }
            }
        };
        for a in answers.iter() {
            if Some(a.origin) == self.active {
                continue;
            }
            self.ignored_answers += 1;
            if ev.ignored.is_none() {
                if let Some(s) = self.seen.iter_mut().flatten().find(|s| s.origin == a.origin && !s.reported) {
                    s.reported = true;
                    ev.ignored = Some((a.origin, a.torque.controller_id));
                }
            }
        }
        (chosen.map(|a| a.torque), ev)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use messages::{ControllerStatus, CONTRACT_VERSION};

    fn answer(origin: u128, tick: u64, tau: f64) -> Answer {
        Answer {
            origin,
            torque: JointTorque {
                contract_version: CONTRACT_VERSION,
                controller_status: ControllerStatus::Active as u32,
                tick,
                controller_id: origin as u64,
                tau: [tau; 6],
            },
        }
    }

    fn answers(list: &[Answer]) -> Answers {
        let mut a = Answers::default();
        for x in list {
            a.insert(*x);
        }
        a
    }

    #[test]
    fn the_first_answer_makes_the_active_controller_and_strangers_are_ignored_and_reported_once() {
        let mut arb = Arbiter::new(3);
        let (t, ev) = arb.choose(&answers(&[answer(7, 0, 1.0)]), false, 0);
        assert_eq!(t.unwrap().tau[0], 1.0);
        assert_eq!(ev.takeover, Some((None, 7, TakeoverReason::First)));
        // A stranger publishes every tick: never obeyed, reported once.
        let mut reports = 0;
        for k in 1..100 {
            let (t, ev) = arb.choose(&answers(&[answer(7, k, 1.0), answer(9, k, 500.0)]), false, k);
            assert_eq!(t.unwrap().tau[0], 1.0, "tick {k}");
            assert_eq!(ev.takeover, None);
            reports += usize::from(ev.ignored.is_some());
        }
        assert_eq!(reports, 1);
        assert_eq!(arb.ignored_answers(), 99);
        // Alone, the stranger still moves nothing until the active one has missed 3 ticks.
        for k in 100..102 {
            let (t, ev) = arb.choose(&answers(&[answer(9, k, 500.0)]), false, k);
            assert!(t.is_none() && ev.takeover.is_none(), "tick {k}");
        }
        let (t, ev) = arb.choose(&answers(&[answer(9, 102, 500.0)]), false, 102);
        assert_eq!(t.unwrap().tau[0], 500.0);
        assert_eq!(ev.takeover, Some((Some(7), 9, TakeoverReason::Missed(3))));
    }

    #[test]
    fn a_gone_controller_is_replaced_at_once_by_the_newest_candidate() {
        let mut arb = Arbiter::new(3);
        arb.choose(&answers(&[answer(1, 0, 1.0)]), false, 0);
        arb.choose(&answers(&[answer(1, 1, 1.0), answer(2, 1, 2.0)]), false, 1);
        arb.choose(&answers(&[answer(1, 2, 1.0), answer(2, 2, 2.0), answer(3, 2, 3.0)]), false, 2);
        let a = answers(&[answer(2, 3, 2.0), answer(3, 3, 3.0)]);
        assert!(arb.settled(&a, true) && !arb.settled(&a, false));
        let (t, ev) = arb.choose(&a, true, 3);
        assert_eq!(t.unwrap().tau[0], 3.0, "publisher 3 was heard last");
        assert_eq!(ev.takeover, Some((Some(1), 3, TakeoverReason::Gone)));
        // Exactly one switch: the next ticks stay with 3.
        for k in 4..10 {
            let (t, ev) = arb.choose(&answers(&[answer(2, k, 2.0), answer(3, k, 3.0)]), false, k);
            assert_eq!((t.unwrap().tau[0], ev.takeover), (3.0, None));
        }
    }

    #[test]
    fn a_late_tick_of_the_active_controller_resets_its_miss_count() {
        let mut arb = Arbiter::new(3);
        arb.choose(&answers(&[answer(1, 0, 1.0)]), false, 0);
        for k in 1..30 {
            // The active one misses every other tick: never 3 in a row, no take-over.
            let list = if k % 2 == 0 { vec![answer(1, k, 1.0), answer(2, k, 2.0)] } else { vec![answer(2, k, 2.0)] };
            let (_, ev) = arb.choose(&answers(&list), false, k);
            assert_eq!(ev.takeover, None, "tick {k}");
        }
    }
}
