//! The noise table (the paper's Table 1, and more) computed from the moments alone.
//!
//! For a strategy with per-iteration values C_s: L = mean C_s, its standard error std/√M, and
//! RMS% = 100·std(C_s)/|mean(C_s)| with the sample standard deviation (M − 1). The standard error
//! of RMS% is the delta method on (mean, variance): with central moments m2, m3, m4,
//! Var(R̂) ≈ R²/M · [m2/μ² − m3/(μ·m2) + (m4 − m2²)/(4·m2²)]; it needs Σ C_s³ and Σ C_s⁴, which the
//! moments carry for every per-path strategy. For the fitted strategies, whose C_s are linear in
//! the weights, the moments give L and RMS exactly but not the third and fourth moments, so their
//! `rms_percent_stderr` is null.
//!
//! Rows, in order: `plane1`, `plane2`, `plane3`, `switch` (the paper's cases 1–4), `optimal` (case
//! 5: fitted and evaluated on all iterations, as in the paper — optimistic), `optimal_holdout`
//! (2-fold cross-fitting: weights fitted on even iterations evaluated on odd ones and vice versa,
//! pooled — the honest figure), `optimal_cv` (λ chosen on a grid by the hold-out variance, then
//! fitted on all iterations), `balance` and `power` (Veach's heuristics).

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use super::solver::{Fit, SolveError, YStats, fit};
use super::strategy::Strategy;
use crate::sim::engines::tally::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::solve::options::SolverOptions;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// One row of the noise table. Keys are stable (dashboards depend on them); a value that cannot be
/// computed is null, with the reason in `error`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct NoiseRow {
    pub strategy: Strategy,
    pub luminance: Option<f64>,
    pub luminance_stderr: Option<f64>,
    pub rms_percent: Option<f64>,
    pub rms_percent_stderr: Option<f64>,
    /// λ of a fitted strategy (`optimal_cv`: the λ it chose).
    pub lambda: Option<f64>,
    /// `optimal_cv`: the hold-out RMS% of the chosen λ.
    pub holdout_rms_percent: Option<f64>,
    pub error: Option<String>,
}

impl NoiseRow {
    fn failed(strategy: Strategy, error: String) -> Self {
        Self {
            strategy,
            luminance: None,
            luminance_stderr: None,
            rms_percent: None,
            rms_percent_stderr: None,
            lambda: None,
            holdout_rms_percent: None,
            error: Some(error),
        }
    }

    /// A row from M, Σ C and Σ C² (and, if known, the central moments for the RMS error).
    fn from_sums(strategy: Strategy, m: f64, s1: f64, s2: f64, higher: Option<(f64, f64)>) -> Self {
        if m < 2.0 {
            return Self::failed(strategy, format!("at least 2 iterations are needed, got {m}"));
        }
        let mean = s1 / m;
        let m2 = (s2 / m - mean * mean).max(0.0);
        let var = m2 * m / (m - 1.0);
        let std = var.sqrt();
        // Relative to |mean|: a wildly overfitted hold-out estimate can have a negative mean, and
        // its noise is still a size, not a sign.
        let rms = (mean != 0.0).then(|| 100.0 * std / mean.abs());
        let rms_se = match (rms, higher) {
            (Some(r), Some((m3, m4))) if m2 > 0.0 => {
                let r = r / 100.0;
                let bracket = m2 / (mean * mean) - m3 / (mean * m2) + (m4 - m2 * m2) / (4.0 * m2 * m2);
                Some(100.0 * r.abs() * (bracket.max(0.0) / m).sqrt())
            }
            _ => None,
        };
        Self {
            strategy,
            luminance: Some(mean),
            luminance_stderr: Some(std / m.sqrt()),
            rms_percent: rms,
            rms_percent_stderr: rms_se,
            lambda: None,
            holdout_rms_percent: None,
            error: (mean == 0.0).then(|| "the mean is zero: no merge events for this strategy".to_string()),
        }
    }
}

/// Central moments m3, m4 from power sums (population normalisation).
fn central_3_4(m: f64, s: [f64; 4]) -> (f64, f64) {
    let mu = s[0] / m;
    let (e2, e3, e4) = (s[1] / m, s[2] / m, s[3] / m);
    let m3 = e3 - 3.0 * mu * e2 + 2.0 * mu.powi(3);
    let m4 = e4 - 4.0 * mu * e3 + 6.0 * mu * mu * e2 - 3.0 * mu.powi(4);
    (m3, m4)
}

/// The row of a per-path strategy from its power sums.
fn path_row(fold: &FoldMoments, strategy: PathStrategy) -> NoiseRow {
    let i = PathStrategy::ALL.iter().position(|&s| s == strategy).expect("strategy listed");
    let s = fold.strategies[i].clone().map(|x| x.value());
    let m = fold.iterations as f64;
    NoiseRow::from_sums(Strategy::of_path(strategy), m, s[0], s[1], (m > 0.0).then(|| central_3_4(m, s)))
}

/// The rows of the per-path strategies alone (cheap: no fit), for progress reports.
pub fn path_rows(moments: &Moments) -> Vec<NoiseRow> {
    let [even, odd] = &moments.folds;
    let m = (even.iterations + odd.iterations) as f64;
    PathStrategy::ALL
        .iter()
        .enumerate()
        .map(|(i, &strategy)| {
            let s: [f64; 4] = std::array::from_fn(|k| {
                let mut sum = even.strategies[i][k].clone();
                sum.add_sum(&odd.strategies[i][k]);
                sum.value()
            });
            NoiseRow::from_sums(Strategy::of_path(strategy), m, s[0], s[1], (m > 0.0).then(|| central_3_4(m, s)))
        })
        .collect()
}

/// The noise table and the fit behind the `optimal` row.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    pub rows: Vec<NoiseRow>,
    /// The in-sample fit (the weights table of the result).
    pub optimal: Result<Fit, SolveError>,
}

/// Hold-out sums: weights fitted on one fold, Σ C and Σ C² evaluated on the other, both ways.
fn holdout_sums(
    folds: &[YStats; 2],
    grid: &CellGrid,
    solver: &SolverOptions,
    lambda: f64,
) -> Result<(f64, f64, f64), SolveError> {
    let mut total = (0.0, 0.0, 0.0);
    for (train, test) in [(0, 1), (1, 0)] {
        let w = fit(&folds[train], grid, &solver.fixed, lambda)?.vector();
        let (s1, s2) = folds[test].evaluate(&w);
        total = (total.0 + folds[test].m, total.1 + s1, total.2 + s2);
    }
    Ok(total)
}

/// The hold-out RMS% of pooled hold-out sums.
fn rms_of(m: f64, s1: f64, s2: f64) -> Option<f64> {
    NoiseRow::from_sums(Strategy::OptimalHoldout, m, s1, s2, None).rms_percent
}

/// Computes the noise table of `moments` with the given solver options.
pub fn noise_table(moments: &Moments, grid: &CellGrid, solver: &SolverOptions) -> NoiseTable {
    let pooled_fold = moments.pooled();
    let row = |s| path_row(&pooled_fold, s);
    let mut rows = vec![
        row(PathStrategy::Plane1),
        row(PathStrategy::Plane2),
        row(PathStrategy::Plane3),
        row(PathStrategy::Switch),
    ];

    let k = grid.len();
    let pooled = YStats::from_fold(&pooled_fold, k);
    let folds = [YStats::from_fold(&moments.folds[0], k), YStats::from_fold(&moments.folds[1], k)];
    let fitted_row = |name: Strategy, f: &Fit, stats: &YStats| {
        let (s1, s2) = stats.evaluate(&f.vector());
        NoiseRow { lambda: Some(f.lambda), ..NoiseRow::from_sums(name, stats.m, s1, s2, None) }
    };

    // Case 5: fitted and evaluated on all iterations.
    let optimal = fit(&pooled, grid, &solver.fixed, solver.lambda);
    rows.push(match &optimal {
        Ok(f) => fitted_row(Strategy::Optimal, f, &pooled),
        Err(e) => NoiseRow::failed(Strategy::Optimal, e.to_string()),
    });

    // 2-fold cross-fitting with the requested λ.
    rows.push(match holdout_sums(&folds, grid, solver, solver.lambda) {
        Ok((m, s1, s2)) => {
            NoiseRow { lambda: Some(solver.lambda), ..NoiseRow::from_sums(Strategy::OptimalHoldout, m, s1, s2, None) }
        }
        Err(e) => NoiseRow::failed(Strategy::OptimalHoldout, format!("a hold-out fit failed: {e}")),
    });

    // λ by hold-out variance, then fitted on everything.
    rows.push(cross_validated(&pooled, &folds, grid, solver, fitted_row));

    rows.push(row(PathStrategy::Balance));
    rows.push(row(PathStrategy::Power));
    rows.push(row(PathStrategy::CorrelationAware));
    NoiseTable { rows, optimal }
}

fn cross_validated(
    pooled: &YStats,
    folds: &[YStats; 2],
    grid: &CellGrid,
    solver: &SolverOptions,
    fitted_row: impl Fn(Strategy, &Fit, &YStats) -> NoiseRow,
) -> NoiseRow {
    let mut best: Option<(f64, f64)> = None; // (hold-out RMS%, λ)
    let mut failures = Vec::new();
    for &lambda in &solver.cv_lambdas {
        match holdout_sums(folds, grid, solver, lambda).map(|(m, s1, s2)| rms_of(m, s1, s2)) {
            Ok(Some(rms)) if best.is_none_or(|(b, _)| rms.abs() < b.abs()) => best = Some((rms, lambda)),
            Ok(_) => {}
            Err(e) => failures.push(format!("λ = {lambda}: {e}")),
        }
    }
    let Some((holdout_rms, lambda)) = best else {
        return NoiseRow::failed(
            Strategy::OptimalCv,
            format!("no λ of the grid could be evaluated ({})", failures.join("; ")),
        );
    };
    match fit(pooled, grid, &solver.fixed, lambda) {
        Ok(f) => NoiseRow { holdout_rms_percent: Some(holdout_rms), ..fitted_row(Strategy::OptimalCv, &f, pooled) },
        Err(e) => NoiseRow::failed(Strategy::OptimalCv, format!("the final fit with λ = {lambda} failed: {e}")),
    }
}

/// Mean and standard error of merge events per iteration, per plane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct MergeRate {
    pub mean: f64,
    pub stderr: f64,
}

/// Merge events per iteration at planes 1, 2, 3.
pub fn merge_rates(moments: &Moments) -> [MergeRate; 3] {
    let f = moments.pooled();
    let m = f.iterations as f64;
    std::array::from_fn(|p| {
        let mean = f.merges[p] as f64 / m;
        let var = (f.merges_sq[p] as f64 / m - mean * mean).max(0.0) * m / (m - 1.0).max(1.0);
        MergeRate { mean, stderr: (var / m).sqrt() }
    })
}

/// Evaluates weights `w` (length 2K) on the pooled moments: (M, Σ C, Σ C²).
pub fn evaluate_weights(moments: &Moments, w: &DVector<f64>) -> (f64, f64, f64) {
    let stats = YStats::from_fold(&moments.pooled(), moments.cells);
    let (s1, s2) = stats.evaluate(w);
    (stats.m, s1, s2)
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
            let mf = m as f64;
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
    fn rows_need_two_iterations() {
        let row = NoiseRow::from_sums(Strategy::Plane1, 1.0, 1.0, 1.0, None);
        assert!(row.luminance.is_none() && row.error.is_some());
    }
}
