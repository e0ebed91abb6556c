//! The offline tools for rig recordings, the ones `rig` fronts: reading a file back, the report,
//! plots, compare, replay, the miss attribution and their CLI. The plant links none of this: it
//! links `recordings` (record types, schema, encoder, writer, live view) only.
//!
//! - [`read::Recording`] reads a file back, checking every chunk's CRC (a cut or corrupt file up to
//!   its first bad chunk, saying where and why).
//! - [`report`] turns a recording into numbers and figures.
//! - [`tracking`] is the rolling-phase force-tracking metric, one rule for every caller;
//!   [`tracking_input`] reads a recording's ticks into it.
//! - [`strip_rows`] are the `/strip` rows the rolling numbers read: a recording's, or a case's
//!   kept in memory (a sweep or study case that writes no file).
//! - [`bond_map`] is a long seal's bond map: the peak pressure at each millimetre of the strip.
//! - [`roll_end`] says where the roll's reference ended against its plan, and why.
//! - [`stop_holds`] says what each safe stop did to the wheel (how far it went, how hard it pressed).
//! - [`contour_figures`] are a contour run's figures per segment (force, lateral, heading, bond).
//! - [`compare`] puts several recordings side by side.
//! - [`replay`] drives a controller open-loop from a recording and compares its torques.
//! - [`attribution`] says whose fault each missed tick of a real-time run is.
//! - [`cli`] holds the `rig replay` / `rig report` / `rig compare` subcommands the `rig` binary
//!   wires in.

pub mod attribution;
pub mod bond_map;
pub mod cli;
pub mod compare;
pub mod contour_figures;
pub mod plots;
pub mod read;
pub mod replay;
pub mod report;
pub mod roll_end;
pub mod stop_holds;
pub mod strip_rows;
pub mod tmpfs_test;
pub mod tracking;
pub mod tracking_input;
