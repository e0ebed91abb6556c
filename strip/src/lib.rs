//! Weatherstrip model of the rig (DESIGN section 4, thesis Chapters 4-5), built in Rust from
//! geometry and material: structured hex mesh -> linear FEM with mean-dilatation B-bar ->
//! Craig-Bampton -> state space (5.22) -> balanced truncation with matched DC gain (5.31) ->
//! exact ZOH stepper for the plant. See README.md for conventions and the API.

// The numerical kernels index several arrays with one index, as the formulas they implement do.
#![allow(clippy::needless_range_loop)]

pub mod bt;
pub mod cache;
pub mod cb;
pub mod chain;
pub mod cli;
pub mod eig;
pub mod error;
pub mod export;
pub mod fem;
pub mod laying;
pub mod mesh;
pub mod model;
pub mod params;
pub mod progress;
pub mod report;
pub mod sparse;
pub mod stepper;
pub mod system;

pub use error::StripError;
pub use model::{gaussian_weights, StripModel};
pub use params::{CbBoundary, StripParams, Substrate};
pub use stepper::StripStepper;

/// How many tasks faer splits the model build's dense and sparse kernels into, on every machine.
/// Its default is one per CPU, and the split decides the order of floating-point sums: a model
/// built with 1, 2 or 4 tasks differs in nearly every bit, so a scenario's physics digest would
/// depend on the machine. 2 is the count the pinned digests were made with.
pub const BUILD_TASKS: usize = 2;

/// Fixes faer's global parallelism at [`BUILD_TASKS`] tasks (process-wide: faer's high-level
/// decompositions read only the global setting). Called by every model build; the plant's
/// per-tick code uses `Par::Seq` and is unaffected.
pub fn fix_build_parallelism() {
    faer::set_global_parallelism(faer::Par::rayon(BUILD_TASKS));
}

/// Bumped whenever a code change alters built models; part of the cache key.
pub const CODE_VERSION: &str = "strip-4";
