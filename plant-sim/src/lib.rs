//! `plant-sim`: the clock master of the rig (DESIGN sections 5 and 6). It integrates the robot
//! (and, with the strip model, the weatherstrip contact), publishes joint state and wrench each
//! tick over iceoryx2, applies the controller's torque through the [`gate::Gate`] (misses, safe
//! stop, takeover blending, refusals) and records every tick.

pub mod arbiter;
pub mod contact;
pub mod driver;
pub mod drives;
pub mod gate;
pub mod histogram;
pub mod launcher;
pub mod limits;
pub mod physics;
pub mod probe;
pub mod rng;
pub mod run;
pub mod sensor;
pub mod signals;
mod stack_text;
pub mod stats;
pub mod substrate_cache;
pub mod table_cache;
pub mod tick;
pub mod tick_events;

pub use tick::PlantTick;

/// The recorder API the loop writes to.
pub use recordings as recording;
