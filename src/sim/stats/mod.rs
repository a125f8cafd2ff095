//! The statistics of a run: exact, mergeable sums over iterations and which iterations they hold.
//!
//! * [`bounded`] — list deserialisation bounded by the largest valid value;
//! * [`terms`] — what one iteration adds to which sum, for every accumulator;
//! * [`admission`] — what an iteration's tally must be before any of it is summed;
//! * [`accumulator`] — the runner's per-worker fast exact sums, handed to the moments in one go;
//! * [`coverage`] — the (seed, iteration range) pairs a moments value holds;
//! * [`moments`] — the additive sufficient statistics, their checks and merges; [`merge_error`] —
//!   why two of them cannot be merged.
//!
//! Imports: crate::sim::engines, crate::sim::math, crate::sim::model

pub mod accumulator;
pub mod admission;
pub mod bounded;
pub mod components;
pub mod coverage;
pub mod merge_error;
pub mod moments;
pub mod terms;
pub mod well_formed;
