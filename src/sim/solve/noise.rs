//! The noise table (the paper's Table 1, and more) computed from the moments alone.
//!
//! Every row has L, RMS% and their standard errors ([`super::row`]). A per-path row's RMS error is
//! the delta method on its power sums; a fitted row's C_s are linear in its weights, so the
//! moments give its L and RMS exactly but not its higher moments: its RMS gets the jackknife over
//! the cross-fitting folds instead ([`super::crossfit`]).
//!
//! Rows, in order: `plane1`, `plane2`, `plane3`, `switch` (the paper's cases 1–4); `optimal` (case
//! 5: fitted and scored on all iterations, as in the paper — labelled `in_sample`, optimistic),
//! `optimal_holdout` (K-fold cross-fitted at the spec's λ), `optimal_cv` (λ by cross-validation);
//! the per-path heuristics (`balance`, `power`, `correlation_aware` and their planes-2–3 variants);
//! then the wider family ([`super::fitted`]): `optimal_stacked` and each heuristic corrected by a
//! table. [`super::recommend`] chooses the recommended row among them and computes the gain.

use serde::{Deserialize, Serialize};

use super::anchor::anchor_of;
use super::crossfit::{CrossFitting, Scored, cross_fit, score};
use super::effective::FitReplicates;
use super::expectation::{ExpectedLuminance, apply_expectation, tail_missing};
use super::fitted::{Fitted, fitted_rows};
use super::options::{FixedWeights, SolverOptions};
use super::recommend::{Gain, Margin, Recommended, recommend};
use super::row::path_fold_sums;
use super::row::path_row;
pub use super::row::{HeuristicWeight, NoiseRow, WeightErrors, path_rows, respects_fixed};
pub(crate) use super::row::{central_3_4, power_sums};
use super::solver::{Fit, SolveError, adds_nothing, fit, stack_family};
use super::strategy::Strategy;
use super::trust::TrustRegion;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// The noise table, the fits behind it and the recommendation.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    /// The table's rows, in the order of the module doc.
    pub rows: Vec<NoiseRow>,
    /// The in-sample fit at the spec's λ (the paper's procedure; `?lambda=` weights tables).
    pub optimal: Result<Fit, SolveError>,
    /// Every cross-fitted row with the λ it chose (or the spec's), for the recommendation and the
    /// warnings.
    pub fitted: Vec<Fitted>,
    /// The recommended row, or why there is none.
    pub recommended: Result<Recommended, String>,
    /// The recommended row against the best per-path strategy (other than itself) that keeps the
    /// solver's fixed weights.
    pub gain: Option<Gain>,
    /// Against the best per-path strategy that does not (what the fixed weights cost).
    pub unconstrained: Option<Gain>,
    /// The guard's test: the best per-path row against the best stable fitted row.
    pub guard: Option<Gain>,
    /// The recommendation's margin (the guard as a verdict).
    pub margin: Margin,
    /// When that strategy is measurably better: the stacked optimum with the fixed weights freed
    /// (which contains it), cross-fitted at the stacked optimum's λ.
    pub free_stacked: Option<Scored>,
    /// All folds added together, and the cross-fitting sets: kept for the report's warnings, merge
    /// rates and `?lambda=` weights, so that nothing pools the folds twice.
    pub pooled: FoldMoments,
    /// The sums of all iterations, of each fold and of each fold's complement.
    pub cross_fitting: CrossFitting,
}

/// Computes the noise table of `moments` with the given solver options.
pub fn noise_table(moments: &Moments, grid: &CellGrid, solver: &SolverOptions) -> NoiseTable {
    noise_table_with(moments, grid, solver, None)
}

/// The noise table, with each per-path row's exact expectation at R where known (`expected`): a row
/// whose L lies far below it is missing its tail (`expectation`), and neither recommended nor the
/// trust region's anchor.
pub fn noise_table_with(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    expected: Option<&[ExpectedLuminance]>,
) -> NoiseTable {
    let pooled = moments.pooled();
    let path = |s| path_row(&pooled, s, &solver.fixed);
    let cf = CrossFitting::new(moments, &pooled);
    let mut per_path: Vec<NoiseRow> = PathStrategy::ALL.iter().map(|&s| path(s)).collect();
    if let Some(expected) = expected {
        for row in &mut per_path {
            apply_expectation(row, expected);
            row.tail_missing = tail_missing(row);
        }
    }
    let is_case = |r: &NoiseRow| r.strategy.path().is_some_and(|s| s.is_case());
    // The paper's cases 1–4 first (PathStrategy::ALL lists them first, in that order).
    let mut rows: Vec<NoiseRow> = per_path.iter().filter(|r| is_case(r)).cloned().collect();
    // Case 5: fitted and evaluated on all iterations (the paper's procedure).
    let optimal = fit(&cf.all, grid, &solver.fixed, solver.lambda, &[]);
    rows.push(match &optimal {
        Ok(f) => in_sample_row(Strategy::Optimal, f, &cf),
        Err(e) => NoiseRow::failed(Strategy::Optimal, e.to_string()),
    });
    // Fitted rows are trusted only as corrections of the best per-path row (`trust`).
    let path_sums = |p| path_fold_sums(moments, p);
    let anchor = anchor_of(&per_path, &path_sums).map(|a| a.strategy);
    let region = solver.trust_region.zip(anchor).map(|(radius, anchor)| TrustRegion { anchor, radius });
    let fitted = fitted_rows(&cf, grid, solver, region);
    let table_rows = [Strategy::OptimalHoldout, Strategy::OptimalCv];
    let row_of = |s: Strategy| fitted.rows.iter().find(|r| r.strategy == s).cloned();
    rows.extend(table_rows.iter().filter_map(|&s| row_of(s)));
    rows.extend(per_path.into_iter().filter(|r| !is_case(r)));
    rows.extend(fitted.rows.iter().filter(|r| !table_rows.contains(&r.strategy)).cloned());
    let choice = recommend(&rows, &fitted.fitted, &path_sums);
    let free_stacked = choice
        .unconstrained
        .filter(|g| g.stderr.is_some_and(|se| g.value + 2.0 * se < 1.0))
        .and_then(|_| unconstrained_optimum(&cf, grid, solver, &fitted.fitted));
    let margin = choice.margin();
    NoiseTable {
        rows,
        optimal,
        fitted: fitted.fitted,
        recommended: choice.recommended,
        gain: choice.gain,
        unconstrained: choice.unconstrained,
        guard: choice.guard,
        margin,
        free_stacked,
        pooled,
        cross_fitting: cf,
    }
}

/// The stacked optimum with the fixed weights freed (all its heuristics admitted, but those that
/// add nothing), at the λ the stacked (or else the table's) optimum chose: what freeing the fixed
/// weights would give.
fn unconstrained_optimum(
    cf: &CrossFitting,
    grid: &CellGrid,
    solver: &SolverOptions,
    fitted: &[Fitted],
) -> Option<Scored> {
    let free = FixedWeights::default();
    // As the stacked optimum, without the heuristics that add nothing on these data.
    let family: Vec<PathStrategy> =
        stack_family(cf.all.layout, &free).into_iter().filter(|&h| !adds_nothing(&cf.all, &free, h)).collect();
    // The stacked (or else the table's) optimum's λ; where the wider free family cannot be fitted
    // there (a short run at λ = 0), the grid's largest, the most regularised.
    let chosen = [Strategy::OptimalStacked, Strategy::OptimalCv]
        .iter()
        .find_map(|s| fitted.iter().find(|f| f.strategy == *s))
        .map_or(solver.lambda, |f| f.scored.cross_fit.lambda);
    let largest = solver.cv_lambdas.iter().copied().fold(chosen, f64::max);
    [chosen, largest].into_iter().find_map(|lambda| score(cf, grid, &free, lambda, &family).ok())
}

/// The row of weights `f` scored on the iterations they were fitted to.
pub(crate) fn in_sample_row(name: Strategy, f: &Fit, cf: &CrossFitting) -> NoiseRow {
    let stats = &cf.all;
    let (s1, s2) = stats.evaluate(&f.coefficients(stats.layout));
    NoiseRow { lambda: Some(f.lambda), ..NoiseRow::from_sums(name, stats.m, s1, s2, None) }
}

/// The in-sample fit of all iterations at λ with the heuristics `family` stacked on the table, with
/// jackknife standard errors and the fold fits (the weights table a `?lambda=` query asks for: the
/// table alone).
pub fn weights_at(
    cf: &CrossFitting,
    grid: &CellGrid,
    solver: &SolverOptions,
    lambda: f64,
    family: &[PathStrategy],
) -> Result<(Fit, Option<WeightErrors>, Option<FitReplicates>), SolveError> {
    let all = fit(&cf.all, grid, &solver.fixed, lambda, family)?;
    let folds = cross_fit(cf, grid, &solver.fixed, lambda, family).ok();
    let stderr = folds.as_ref().and_then(|c| c.weight_stderr());
    Ok((all, stderr, folds.map(|c| c.replicates())))
}

/// Mean and standard error of merge events per iteration, per plane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct MergeRate {
    /// Mean merge events per iteration.
    pub mean: f64,
    /// Its standard error (the per-iteration counts' standard deviation over √iterations).
    pub stderr: f64,
}

/// Merge events per iteration at planes 1, 2, 3.
pub fn merge_rates(moments: &Moments) -> [MergeRate; 3] {
    merge_rates_of(&moments.pooled())
}

/// Merge events per iteration at planes 1, 2, 3 of pooled folds.
pub fn merge_rates_of(f: &FoldMoments) -> [MergeRate; 3] {
    let m = f.iterations as f64;
    std::array::from_fn(|p| {
        let mean = f.merges[p] as f64 / m;
        let var = (f.merges_sq[p] as f64 / m - mean * mean).max(0.0) * m / (m - 1.0).max(1.0);
        MergeRate { mean, stderr: (var / m).sqrt() }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The delta-method standard error of the RMS must match the spread of RMS estimates over
    /// independent replications (exponential data: RMS = 100%, heavy enough to matter).
    #[test]
    fn rms_standard_error_matches_replications() {
        use crate::sim::math::rng::{stream, uniform_open0};
        let (reps, m) = (400, 2000);
        let mut rms_values = Vec::new();
        let mut ses = Vec::new();
        for r in 0..reps {
            let mut rng = stream(77, r, 0);
            let mut s = [0.0; 4];
            for _ in 0..m {
                let x = -uniform_open0(&mut rng).ln();
                s[0] += x;
                s[1] += x * x;
                s[2] += x * x * x;
                s[3] += x * x * x * x;
            }
            let mf = f64::from(m);
            let row = NoiseRow::from_sums(Strategy::Plane1, mf, s[0], s[1], Some(central_3_4(mf, s)));
            rms_values.push(row.rms_percent.unwrap());
            ses.push(row.rms_percent_stderr.unwrap());
        }
        let mean_rms = rms_values.iter().sum::<f64>() / reps as f64;
        let spread = (rms_values.iter().map(|r| (r - mean_rms).powi(2)).sum::<f64>() / (reps as f64 - 1.0)).sqrt();
        let mean_se = ses.iter().sum::<f64>() / reps as f64;
        // Exponential: RMS = 100%; the replication spread estimates the true SE with a relative
        // error of about 1/√(2·reps) = 3.5%; allow 4 of those.
        assert!((mean_rms - 100.0).abs() < 4.0 * spread / (reps as f64).sqrt(), "mean RMS {mean_rms}");
        assert!(
            (mean_se / spread - 1.0).abs() < 4.0 / (2.0 * reps as f64).sqrt(),
            "delta SE {mean_se} vs spread {spread}"
        );
    }

    #[test]
    fn a_strategy_keeps_fixed_weights_only_if_it_gives_them_to_every_path() {
        let paper = FixedWeights { w0: Some(0.0), w1: None, w2: None };
        let keeps: Vec<&str> =
            PathStrategy::ALL.iter().filter(|&&s| respects_fixed(s, &paper)).map(|s| s.name()).collect();
        assert_eq!(
            keeps,
            ["plane2", "plane3", "switch", "balance_planes23", "power_planes23", "correlation_aware_planes23"]
        );
        assert!(PathStrategy::ALL.iter().all(|&s| respects_fixed(s, &FixedWeights::default())));
        let half = FixedWeights { w0: None, w1: None, w2: Some(0.5) };
        assert!(PathStrategy::ALL.iter().all(|&s| !respects_fixed(s, &half)));
        let plane2 = FixedWeights { w0: Some(0.0), w1: Some(1.0), w2: None };
        let keeps: Vec<&str> =
            PathStrategy::ALL.iter().filter(|&&s| respects_fixed(s, &plane2)).map(|s| s.name()).collect();
        assert_eq!(keeps, ["plane2"]);
    }

    #[test]
    fn rows_need_two_iterations() {
        let row = NoiseRow::from_sums(Strategy::Plane1, 1.0, 1.0, 1.0, None);
        assert!(row.luminance.is_none() && row.error.is_some());
    }
}
