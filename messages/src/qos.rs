//! All quality-of-service settings of the contract in one place. Plant and controller open the
//! services with these values; iceoryx2 refuses a peer whose settings are incompatible.

/// Samples a subscriber keeps. The consumer always drains to the newest and matches by tick, so a
/// few slots absorb a stalled peer without blocking the publisher (safe overflow drops the oldest).
pub const SUBSCRIBER_BUFFER: usize = 4;
/// Samples delivered to a late-joining subscriber: none (a stale state must never be answered).
pub const HISTORY: usize = 0;
/// Overflow policy: the publisher never blocks on a slow subscriber; the oldest sample is dropped.
pub const SAFE_OVERFLOW: bool = true;
/// Publishers per service: one plant; for torque, two controllers may overlap briefly during a
/// hand-over (the old one exiting while the new one starts) plus one replay tool.
pub const MAX_PUBLISHERS: usize = 4;
/// Subscribers per service: controller, recorder-side tools, replay comparison.
pub const MAX_SUBSCRIBERS: usize = 4;
/// Nodes per service.
pub const MAX_NODES: usize = 8;
/// Samples a subscriber may hold at once.
pub const MAX_BORROWED_SAMPLES: usize = 2;
/// Event services: notifiers and listeners per event.
pub const MAX_NOTIFIERS: usize = 4;
pub const MAX_LISTENERS: usize = 4;
/// Largest event id of the event services: the contract notifies with id 0 only. iceoryx2 0.10
/// keeps one counter per id in the listener's shared state and a drain (`try_wait`) swaps every
/// one of them atomically: at iceoryx2's default (255) that is 256 swaps per drain, several
/// drains a tick on each side. A peer that does not ask for a value opens the service as
/// created; one that asks for more than the creator gave is refused by iceoryx2.
pub const EVENT_ID_MAX: usize = 0;
