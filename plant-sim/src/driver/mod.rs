//! The plant's drivers: what calls [`crate::PlantTick`] once a tick and hands its events on. Each
//! is named for what it drives, and none holds plant physics, limits, reflexes or stall handling
//! of its own (those are the tick's):
//! - [`realtime`]: the 1 kHz loop against a controller over iceoryx2, paced by the [`pacer`];
//! - [`lockstep`]: the same loop, each tick waiting for the controller's answer;
//! - [`egm`]: ABB's Externally Guided Motion over UDP, the plant as the robot's servo.
//!
//! `rig run --in-process`, the sweep and the design servo drive `PlantTick` directly (they have
//! no peer to wait for).

pub mod egm;
pub mod lockstep;
pub mod pacer;
pub mod realtime;
