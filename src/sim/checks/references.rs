//! What a report is checked against: each per-path strategy's expected luminance at the
//! configuration's merge radius ([`super::expected`]), as the report's rows take it
//! ([`ExpectedLuminance`]).

use super::expected::expected_luminances as at_radius;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::report::ExpectedLuminance;
use crate::sim::solve::strategy::Strategy;

/// Every per-path strategy's expected luminance at `config`'s R (bounded work: about a second at
/// most on one core), or why it is not available.
pub fn expected_luminances(config: &SimConfig) -> Vec<ExpectedLuminance> {
    at_radius(config)
        .into_iter()
        .map(|e| ExpectedLuminance {
            strategy: Strategy::of_path(e.strategy),
            luminance: e.luminance.as_ref().ok().copied(),
            error: e.luminance.err().map(|e| e.to_string()),
        })
        .collect()
}
