//! The force controller of the weatherstrip rig (DESIGN section 7, issue 6): references, the
//! hybrid impedance / inverse dynamics law, the gain design rule and the 1 kHz daemon loop.
//! It links the robot model but never the strip model or the plant.

pub mod daemon;
pub mod egm_force;
pub mod gains;
pub mod law;
pub mod reference;
pub mod sensing;
pub mod step;

pub use step::Controller;
