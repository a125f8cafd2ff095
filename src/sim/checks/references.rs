//! What a report is checked against: each per-path strategy's expected luminance at the
//! configuration's merge radius, as the report's rows take it ([`ExpectedLuminance`]).

use crate::sim::engines::tally::PathStrategy;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::report::ExpectedLuminance;
use crate::sim::solve::strategy::Strategy;

/// Every per-path strategy's expected luminance at `config`'s R (bounded work: about a second at
/// most on one core), or why it is not available.
pub fn expected_luminances(config: &SimConfig) -> Vec<ExpectedLuminance> {
    let _ = config;
    PathStrategy::ALL
        .iter()
        .map(|&s| ExpectedLuminance {
            strategy: Strategy::of_path(s),
            luminance: None,
            error: Some("not computed".into()),
        })
        .collect()
}
