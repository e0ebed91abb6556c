//! `rig design` (issue 6): the thesis' Chapter 6 force-loop analysis from the actual strip and
//! robot models ([`cli`]), plus in-process servo simulations ([`servo`]: 6-DOF, [`sim1`]: 1-DOF)
//! and the acceptance figures measured from recordings ([`metrics`]).

// The numerical kernels index several arrays with one index, as the formulas they implement do.
#![allow(clippy::needless_range_loop)]

pub mod cli;
pub mod egm;
pub mod freq;
pub mod metrics;
pub mod plant1;
pub mod servo;
pub mod sim1;
pub mod stress;
