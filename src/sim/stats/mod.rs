//! The statistics of a run: exact, mergeable sums over iterations and which iterations they hold.
//!
//! * [`coverage`] — the (seed, iteration range) pairs a moments value holds;
//! * [`moments`] — the additive sufficient statistics, their checks and merges.

pub mod coverage;
pub mod moments;
