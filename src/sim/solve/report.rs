//! The result document of a run: noise table, weights table, merge rates and the analytic reference.
//!
//! Its field names are a stable interface (scripts and dashboards read them): `iterations`,
//! `reference_luminance`, `noise_table` (rows of [`NoiseRow`]), `recommended`, `weights` (rows of
//! [`WeightRow`]: the recommended table with standard errors unless a λ was asked for; empty when
//! a per-path strategy is recommended), `weights_fit`, `gain`, `warnings`, `solve_error`,
//! `merges_per_iteration`, `fingerprint`, `coverage`.
//!
//! A recommended fitted row's per-path weights are the cell's table weight plus
//! Σ_h β_h·w_h,m(path) over `recommended.heuristics` (docs/model.md §7): each cell's table
//! weights sum to 1 − Σβ.

use serde::{Deserialize, Serialize};

use super::effective::FitReplicates;
pub use super::expectation::ExpectedLuminance;
use super::expectation::apply_expectation;
use super::noise::{HeuristicWeight, MergeRate, NoiseRow, merge_rates_of, noise_table_with, weights_at};
use super::recommend::{Gain, Margin};
use super::solver::stack_family;
use super::solver::{CellStatus, Fit};
use super::strategy::Strategy;
use super::warnings::{Warning, warnings};
use crate::sim::engines::strategies::PathStrategy;
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
    /// [lo, hi] on r3; hi is null for the tail cell.
    pub r3: [Option<f64>; 2],
    /// [lo, hi] on φ, radians in [0, π].
    pub phi: [Option<f64>; 2],
    /// The weight of plane-1 merges (the pixel) in this cell.
    pub w0: f64,
    /// The weight of plane-2 merges.
    pub w1: f64,
    /// The weight of plane-3 merges; the three sum to 1 − Σβ of the stacked heuristics (1 for a
    /// table alone).
    pub w2: f64,
    /// Jackknife standard errors over the K fold fits, for cells fitted to their own samples (0
    /// for a fixed weight); null for a cell the penalty sets (`smoothed`), an empty one, or when
    /// fewer than two folds hold iterations or a fold fit failed.
    pub w0_stderr: Option<f64>,
    /// The standard error of `w1`, as `w0_stderr`.
    pub w1_stderr: Option<f64>,
    /// The standard error of `w2`, as `w0_stderr`.
    pub w2_stderr: Option<f64>,
    /// Merge events in the cell (all planes) over all iterations.
    pub samples: u64,
    /// How the cell's weights were set (fitted, fixed, smoothed, …).
    pub status: CellStatus,
}

/// Merge events per iteration at each plane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct MergesPerIteration {
    /// Plane-1 merges (at the pixel; counted once per light path).
    pub plane1: MergeRate,
    /// Plane-2 merges.
    pub plane2: MergeRate,
    /// Plane-3 merges.
    pub plane3: MergeRate,
}

/// Which fit a weights table shows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct WeightsFit {
    /// The recommended fitted row; `optimal` for a table asked for at a given λ.
    pub strategy: Strategy,
    /// The gradient penalty λ of the fit.
    pub lambda: f64,
    /// Always true: a weights table is fitted on all iterations (the figures that say how good
    /// the weights are, in the noise table, are the cross-fitted ones).
    pub fitted_on_all_iterations: bool,
}

/// The recommendation: which row's weights to take into a renderer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct RecommendedWeights {
    /// The recommended row's strategy.
    pub strategy: Strategy,
    /// The λ chosen by cross-validation (null when a per-path strategy is recommended).
    pub lambda: Option<f64>,
    /// β of each heuristic stacked on the table (per-path weights = table + Σ β_h·w_h).
    #[serde(default)]
    pub heuristics: Vec<HeuristicWeight>,
    /// Why this row: the guard's verdict in a sentence.
    #[serde(default)]
    pub reason: String,
    /// How sure the recommendation is: the best trusted fitted row against the best per-path row
    /// (variance ratio ± SE, z, and the verdict: `beats`, `within_noise`, `noisier`, `no_fit`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin: Option<Margin>,
}

/// The result of a run (or of a re-solve of stored moments).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct RunReport {
    /// Iterations the moments hold.
    pub iterations: u64,
    /// The cross-fitting folds K of the moments.
    pub folds: usize,
    /// The quadrature value of L in the limit R → 0, the same for every strategy; null when the
    /// quadrature did not converge within its evaluation budget (extreme geometry). Each per-path
    /// row's `expected_luminance` is its expectation at the job's R, which its `z` compares with.
    pub reference_luminance: Option<f64>,
    /// Every strategy's L and RMS% with their standard errors: the per-path strategies, then the
    /// fitted rows (the paper's Table 1, and more).
    pub noise_table: Vec<NoiseRow>,
    /// The recommended row (the honest row with the lowest RMS that keeps the fixed weights, a
    /// fitted one only if it beats the best per-path strategy beyond 1.645 standard errors, one-sided 95%); null
    /// when no row could be computed (see `solve_error`).
    pub recommended: Option<RecommendedWeights>,
    /// The weights table: the recommended fitted row's table (fitted on all iterations at its λ),
    /// or the in-sample fit at the λ asked for; empty when a per-path strategy is recommended or
    /// the fit failed (see `solve_error`).
    pub weights: Vec<WeightRow>,
    /// Which fit `weights` shows; null when it is empty.
    pub weights_fit: Option<WeightsFit>,
    /// Var(best other per-path strategy keeping the fixed weights) / Var(recommended row), with the
    /// paired jackknife SE.
    pub gain: Option<Gain>,
    /// The recommendation's guard: Var(best per-path row keeping the fixed weights)/Var(best stable
    /// fitted row) on the same iterations, with the paired jackknife SE; the fitted row
    /// (`strategy`) is recommended only if the ratio exceeds 1 by more than 1.645 SE, else the
    /// per-path row (`versus`).
    #[serde(default)]
    pub guard: Option<Gain>,
    /// What the data cannot support (empty when nothing is wrong).
    pub warnings: Vec<Warning>,
    /// Why the weights could not be fitted (every fitted row's `error` says so too), even when a
    /// per-path strategy is recommended in their place; null when the fit succeeded.
    pub solve_error: Option<String>,
    /// Mean merge events per iteration at each plane, with standard errors.
    pub merges_per_iteration: MergesPerIteration,
    /// The configuration fingerprint of the moments (hex SHA-256).
    pub fingerprint: String,
    /// The (seed, iteration range) pairs the moments hold.
    pub coverage: Coverage,
    /// The fold fits of the fitted row `weights` shows, for the fit errors of its effective
    /// weights (`solve::effective`, a document of its own); not part of the document.
    #[serde(skip)]
    pub replicates: Option<FitReplicates>,
    /// With `radii`: the figures at each smaller radius the run tallied and at its own R
    /// (ascending), each row with its bias against the R → 0 reference (`solve::radii`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub radii: Vec<super::radii::RadiusReport>,
}

/// The rows of a weights table.
pub fn weight_rows(grid: &CellGrid, fit: &Fit, stderr: Option<&[[f64; 3]]>) -> Vec<WeightRow> {
    fit.cells
        .iter()
        .enumerate()
        .map(|(alpha, c)| {
            let b = grid.bounds(alpha);
            // A data standard error only for weights estimated from the cell's own samples (or
            // fixed, 0): a smoothed cell's fold-to-fold spread is its neighbours'.
            let measured = c.status.from_data() || c.status == CellStatus::Fixed;
            let se = |m: usize| stderr.filter(|_| measured).map(|s| s[alpha][m]);
            WeightRow {
                r2: b.r2,
                r3: b.r3,
                phi: b.phi,
                w0: c.w[0],
                w1: c.w[1],
                w2: c.w[2],
                w0_stderr: se(0),
                w1_stderr: se(1),
                w2_stderr: se(2),
                samples: c.samples,
                status: c.status,
            }
        })
        .collect()
}

/// Which fitted weights a report's table shows instead of the recommended ones: a fitted row's
/// family (`optimal` — the table alone —, `optimal_stacked`, or a `…_corrected` row) fitted in
/// sample on all iterations at `lambda`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightsQuery {
    /// The gradient penalty λ to fit at.
    pub lambda: f64,
    /// The fitted family whose table to show.
    pub strategy: Strategy,
}

/// What a report is computed against besides the moments.
#[derive(Debug, Clone, Default)]
pub struct ReportInputs<'a> {
    /// The R → 0 quadrature value of L (`reference_luminance`).
    pub reference: Option<f64>,
    /// Each per-path strategy's expected luminance at the job's R; rows get their `z` from it.
    pub expected: Option<&'a [ExpectedLuminance]>,
    /// Show these weights instead of the recommended ones.
    pub weights: Option<WeightsQuery>,
}

/// Builds the report of `moments` with the given solver options. The weights table holds the
/// recommended weights, or with `inputs.weights` the in-sample fit of all iterations asked for.
pub fn build_report(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    inputs: &ReportInputs<'_>,
) -> RunReport {
    let mut table = noise_table_with(moments, grid, solver, inputs.expected);
    let warnings = warnings(moments, &table);
    if let Some(expected) = inputs.expected {
        for row in &mut table.rows {
            apply_expectation(row, expected);
        }
    }
    let recommended = table.recommended.as_ref().ok().map(|r| RecommendedWeights {
        strategy: r.strategy,
        lambda: r.lambda(),
        heuristics: table
            .rows
            .iter()
            .find(|x| x.strategy == r.strategy)
            .map(|x| x.heuristics.clone())
            .unwrap_or_default(),
        reason: r.reason.clone(),
        margin: Some(table.margin.clone()),
    });
    let (weights, weights_fit, solve_error, replicates) = match (inputs.weights, &table.recommended) {
        (Some(q), _) => {
            let family = match q.strategy {
                Strategy::Optimal => Ok(Vec::new()),
                // The heuristics the row itself stacked (a heuristic that adds nothing on these
                // data is left out, `fitted`); the whole family where the row has none to say.
                Strategy::OptimalStacked => Ok(table
                    .rows
                    .iter()
                    .find(|r| r.strategy == Strategy::OptimalStacked && !r.heuristics.is_empty())
                    .map(|r| r.heuristics.iter().filter_map(|h| h.strategy.path()).collect())
                    .unwrap_or_else(|| stack_family(moments.layout(), &solver.fixed))),
                s => PathStrategy::STACKABLE
                    .into_iter()
                    .find(|&h| Strategy::corrected(h) == Some(s))
                    .map(|h| vec![h])
                    .ok_or_else(|| {
                        format!("{s} is not a fitted row with weights to show (optimal, optimal_stacked, …_corrected)")
                    }),
            };
            match family
                .and_then(|f| weights_at(&table.cross_fitting, grid, solver, q.lambda, &f).map_err(|e| e.to_string()))
            {
                Ok((fit, se, folds)) => (
                    weight_rows(grid, &fit, se.as_deref()),
                    Some(WeightsFit { strategy: q.strategy, lambda: q.lambda, fitted_on_all_iterations: true }),
                    None,
                    folds,
                ),
                Err(e) => (Vec::new(), None, Some(e), None),
            }
        }
        (None, Ok(r)) => match (r.fit(), r.lambda()) {
            (Some(fit), Some(lambda)) => (
                weight_rows(grid, fit, r.weight_stderr().as_deref()),
                Some(WeightsFit { strategy: r.strategy, lambda, fitted_on_all_iterations: true }),
                None,
                r.replicates(),
            ),
            _ => (Vec::new(), None, None, None),
        },
        (None, Err(e)) => (Vec::new(), None, Some(e.clone()), None),
    };
    let fit_error = || table.rows.iter().find(|r| r.strategy == Strategy::OptimalCv).and_then(|r| r.error.clone());
    let solve_error = solve_error.or_else(fit_error);
    let [plane1, plane2, plane3] = merge_rates_of(&table.pooled);
    RunReport {
        iterations: moments.iterations(),
        folds: moments.fold_count(),
        reference_luminance: inputs.reference,
        noise_table: table.rows,
        recommended,
        weights,
        weights_fit,
        gain: table.gain,
        guard: table.guard,
        warnings,
        solve_error,
        merges_per_iteration: MergesPerIteration { plane1, plane2, plane3 },
        fingerprint: moments.fingerprint.clone(),
        coverage: moments.coverage.clone(),
        replicates,
        radii: Vec::new(),
    }
}
