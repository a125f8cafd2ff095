//! Each per-path strategy's exact expectation at the run's merge radius (docs/model.md §11), the
//! z of its L against it, and what a z far below zero says: a row whose mean is more than
//! [`MISSING_TAIL_Z`] standard errors below its exact expectation is missing the rare large
//! contributions that dominate its variance — its RMS and SE, computed from the events the run
//! drew, are then far too small, however tight they look (issue 40: with N_B = 10 one run of 10⁴
//! iterations showed `balance_planes23` at 41.6 ± 0.3% RMS with z = −22.6; it delivers 446% on a
//! long run). Such a row is neither recommended nor the anchor of the trust region.

use serde::{Deserialize, Serialize};

use super::row::NoiseRow;
use super::strategy::Strategy;

/// How many standard errors below its exact expectation a per-path row's L may lie before the row
/// counts as missing its tail: −3 is a 0.13% event for an estimate whose errors are normal, and a
/// heavy-tailed estimate falls there when the run lacks the events that carry its mean and its
/// variance. (A z far *above* zero is a rare large event that the run did draw: its RMS is then,
/// if anything, too large, and it is not flagged.)
pub const MISSING_TAIL_Z: f64 = 3.0;

/// A per-path strategy's expected luminance at the configuration's merge radius R, by quadrature
/// (docs/model.md §11; computed by `checks::expected`), or why there is none.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ExpectedLuminance {
    /// The per-path strategy.
    pub strategy: Strategy,
    /// The strategy's expected luminance at R; null when the quadrature could not give it (see
    /// `error`).
    pub luminance: Option<f64>,
    /// Why there is no expected luminance; null when there is one.
    pub error: Option<String>,
}

/// Gives a per-path row its expectation and z (a fitted row gets why it has none).
pub(crate) fn apply_expectation(row: &mut NoiseRow, expected: &[ExpectedLuminance]) {
    if row.strategy.path().is_none() {
        row.expected_error =
            Some("fitted to these iterations: its expectation depends on the fitted weights (compare its L with the per-path rows')".into());
        return;
    }
    match expected.iter().find(|e| e.strategy == row.strategy) {
        Some(e) => {
            row.expected_luminance = e.luminance;
            row.expected_error = e.error.clone();
            row.z = match (row.luminance, row.luminance_stderr, e.luminance) {
                (Some(l), Some(se), Some(x)) if se > 0.0 => Some((l - x) / se),
                _ => None,
            };
        }
        None => row.expected_error = Some("no expectation was computed for this strategy".into()),
    }
}

/// Whether a per-path row's L lies so far below its exact expectation that its sample lacks the
/// rare contributions that dominate its variance ([`MISSING_TAIL_Z`]).
pub fn tail_missing(row: &NoiseRow) -> bool {
    row.z.is_some_and(|z| z < -MISSING_TAIL_Z)
}
