//! The result document of a run: noise table, weights table, merge rates and the analytic reference.
//!
//! Its field names are a stable interface (scripts and dashboards read them): `iterations`,
//! `reference_luminance`, `noise_table` (rows of [`NoiseRow`]), `weights` (rows of [`WeightRow`]),
//! `solve_error`, `merges_per_iteration`, `fingerprint`, `coverage`.

use serde::{Deserialize, Serialize};

use super::noise::{MergeRate, NoiseRow, merge_rates, noise_table};
use super::solver::CellStatus;
use crate::sim::model::cells::CellGrid;
use crate::sim::solve::options::SolverOptions;
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;
/// One cell of the weights table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct WeightRow {
    /// [lo, hi] on r2; hi is null for the tail cell.
    pub r2: [Option<f64>; 2],
    pub r3: [Option<f64>; 2],
    /// [lo, hi] on φ, radians in [0, π].
    pub phi: [Option<f64>; 2],
    pub w0: f64,
    pub w1: f64,
    pub w2: f64,
    /// Merge events in the cell (all planes) over all iterations.
    pub samples: u64,
    pub status: CellStatus,
}

/// Merge events per iteration at each plane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct MergesPerIteration {
    pub plane1: MergeRate,
    pub plane2: MergeRate,
    pub plane3: MergeRate,
}

/// The result of a run (or of a re-solve of stored moments).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct RunReport {
    pub iterations: u64,
    /// The quadrature value of L (R → 0); null when the quadrature did not converge within its
    /// evaluation budget (extreme geometry).
    pub reference_luminance: Option<f64>,
    pub noise_table: Vec<NoiseRow>,
    /// Weights of the `optimal` fit; empty when it failed (see `solve_error`).
    pub weights: Vec<WeightRow>,
    pub solve_error: Option<String>,
    pub merges_per_iteration: MergesPerIteration,
    pub fingerprint: String,
    pub coverage: Coverage,
}

/// Builds the report of `moments` with the given solver options.
pub fn build_report(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    reference_luminance: Option<f64>,
) -> RunReport {
    let table = noise_table(moments, grid, solver);
    let (weights, solve_error) = match &table.optimal {
        Ok(fit) => (
            fit.cells
                .iter()
                .enumerate()
                .map(|(alpha, c)| {
                    let b = grid.bounds(alpha);
                    WeightRow {
                        r2: b.r2,
                        r3: b.r3,
                        phi: b.phi,
                        w0: c.w[0],
                        w1: c.w[1],
                        w2: c.w[2],
                        samples: c.samples,
                        status: c.status,
                    }
                })
                .collect(),
            None,
        ),
        Err(e) => (Vec::new(), Some(e.to_string())),
    };
    let [plane1, plane2, plane3] = merge_rates(moments);
    RunReport {
        iterations: moments.iterations(),
        reference_luminance,
        noise_table: table.rows,
        weights,
        solve_error,
        merges_per_iteration: MergesPerIteration { plane1, plane2, plane3 },
        fingerprint: moments.fingerprint.clone(),
        coverage: moments.coverage.clone(),
    }
}
