//! The figures of a run at each merge radius it tallied (`radii`, docs/model.md §13), as a result
//! document carries them: each radius's noise-table rows — exactly what a run at R′ would have
//! summed — with each row's bias against the R → 0 reference L (§11) and its error
//! ([`super::radius_reports`] computes them).
//!
//! A per-path strategy's bias is its expected luminance at R′ by quadrature (`checks::expected`,
//! to 10⁻⁷ of L) minus L: deterministic, its error the quadrature's tolerance. A fitted row's
//! expectation depends on weights fitted to these data, which the quadrature cannot integrate; its
//! bias is the Monte-Carlo estimate L̂(R′) − L (cross-fitted L̂), with L̂'s standard error — an
//! estimate with a large error at short runs, labelled as such (`bias_source`).

use serde::{Deserialize, Serialize};

use super::strategy::Strategy;

/// The relative accuracy the quadrature of `checks::expected` is refined to (its outer and inner
/// tolerances, each 10⁻⁷ of the largest strategy's value): the error of a quadrature bias.
pub const QUADRATURE_RELATIVE_ERROR: f64 = 2e-7;

/// Where a row's bias comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum BiasSource {
    /// The quadrature of the strategy's expected luminance at R′ (per-path strategies).
    Quadrature,
    /// The run's own estimate L̂(R′) − L with L̂'s standard error (fitted rows: their weights are
    /// fitted to these data).
    MonteCarlo,
}

/// One strategy at one radius.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct RadiusRow {
    /// The row's strategy.
    pub strategy: Strategy,
    /// L̂ at this radius (cross-fitted for fitted rows).
    pub luminance: Option<f64>,
    /// Its standard error.
    pub luminance_stderr: Option<f64>,
    /// RMS% of one iteration at this radius and the run's (N_F, N_B).
    pub rms_percent: Option<f64>,
    /// Its standard error.
    pub rms_percent_stderr: Option<f64>,
    /// 100·(E\[C_s\] at R′ − L)/L: the error that no number of iterations removes.
    pub bias_percent: Option<f64>,
    /// Its error (the quadrature's tolerance, or L̂'s standard error), in percent of L.
    pub bias_percent_stderr: Option<f64>,
    /// Where the bias comes from.
    pub bias_source: BiasSource,
    /// Whether the row keeps the solver's fixed weights.
    pub respects_fixed: bool,
}

/// A run's figures at one radius.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct RadiusReport {
    /// R′.
    pub merge_radius: f64,
    /// Whether this is the run's own radius R (else one of its `radii`).
    pub own: bool,
    /// Merge events per iteration at planes 1, 2, 3 (the time a radius costs grows with them).
    pub merges_per_iteration: [f64; 3],
    /// The row the noise table at R′ recommends, if any.
    pub recommended: Option<Strategy>,
    /// Every row of the noise table at R′ but the in-sample fit, with its bias.
    pub rows: Vec<RadiusRow>,
}
