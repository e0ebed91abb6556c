//! The rig's processes and their host, beside the wire contract (`messages`): what the rig's own
//! daemons, launchers and tools share to run, and what a third-party peer of the contract does
//! not need.
//!
//! - [`ports`]: the plant's and the controller's ends of a rig's services (iceoryx2, with the
//!   contract's QoS), allocation-free after `open`;
//! - [`host`]: the rig's iceoryx2 configuration, shared memory checks, one plant per rig name;
//! - [`liveness`], [`connect`]: is a peer dead, did a started controller ever connect;
//! - [`child`]: spawning, stopping and describing the daemons;
//! - [`rt`]: the real-time thread set-up (timer slack, SCHED_FIFO, mlockall, CPU affinity);
//! - [`clock`]: CLOCK_MONOTONIC and CLOCK_REALTIME in ns, absolute sleeps;
//! - `logging` (feature `logging`): the binaries' stderr log set-up.

pub mod child;
pub mod clock;
pub mod connect;
pub mod host;
pub mod liveness;
#[cfg(feature = "logging")]
pub mod logging;
pub mod ports;
pub mod rt;
