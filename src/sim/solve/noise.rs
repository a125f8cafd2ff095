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
//! 5: fitted and scored on all iterations, as in the paper — labelled `in_sample`, optimistic),
//! `optimal_holdout` (K-fold cross-fitted at the spec's λ, [`super::crossfit`]), `optimal_cv` (λ
//! chosen on the grid by the cross-fitted RMS; its figures are the cross-fitted ones at that λ, the
//! in-sample ones are kept beside them), then the per-path heuristics (`balance`, `power`,
//! `correlation_aware`).
//!
//! The *recommended* weights are those of `optimal_cv`'s λ fitted on all iterations (what a user
//! takes into a renderer), with jackknife standard errors; the *gain* compares them with the best
//! per-path strategy.

use serde::{Deserialize, Serialize};

use super::crossfit::{CrossFit, CrossFitting, cross_fit, jackknife_se, select_lambda};
use super::solver::{Fit, SolveError, fit};
use super::strategy::Strategy;
use super::ystats::YStats;
use crate::sim::engines::tally::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::solve::options::{FixedWeights, SolverOptions};
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
    /// Whether the figures are scored on the iterations the weights were fitted to (`optimal`, the
    /// paper's procedure): then they are optimistic — L biased, its standard error and the RMS too
    /// small — and the row is never "best".
    #[serde(default)]
    pub in_sample: bool,
    /// `optimal_cv`: L of its weights fitted and scored on all iterations (in-sample, optimistic);
    /// its `luminance` is the cross-fitted figure.
    #[serde(default)]
    pub in_sample_luminance: Option<f64>,
    /// `optimal_cv`: the in-sample standard error of L (too small).
    #[serde(default)]
    pub in_sample_luminance_stderr: Option<f64>,
    /// `optimal_cv`: the in-sample RMS% (too small).
    #[serde(default)]
    pub in_sample_rms_percent: Option<f64>,
    /// Whether the row's weights keep the solver's fixed weights (`solver.fixed`). A per-path
    /// strategy that does not — e.g. `balance`, which merges at the pixel while the paper fixes
    /// w0 = 0 — is shown for comparison but is neither "best" nor the gain's reference: it answers
    /// another question than the one the fixed weights ask (a `fixed_weights_cost` warning says when
    /// it is less noisy). Fitted rows keep them by construction.
    #[serde(default = "keeps")]
    pub respects_fixed: bool,
    pub error: Option<String>,
}

fn keeps() -> bool {
    true
}

/// Whether `strategy` gives every join path the weights `fixed` fixes.
pub fn respects_fixed(strategy: PathStrategy, fixed: &FixedWeights) -> bool {
    let constant = strategy.constant_weights();
    [fixed.w0, fixed.w1, fixed.w2].iter().zip(constant).all(|(want, has)| want.is_none() || *want == has)
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
            in_sample: strategy.is_in_sample(),
            in_sample_luminance: None,
            in_sample_luminance_stderr: None,
            in_sample_rms_percent: None,
            respects_fixed: true,
            error: Some(error),
        }
    }

    /// A row from M, Σ C and Σ C² (and, if known, the central moments for the RMS error).
    pub fn from_sums(strategy: Strategy, m: f64, s1: f64, s2: f64, higher: Option<(f64, f64)>) -> Self {
        if m < 2.0 {
            return Self::failed(strategy, format!("at least 2 iterations are needed, got {m}"));
        }
        let mean = s1 / m;
        let var = sample_variance(m, s1, s2);
        let m2 = var * (m - 1.0) / m;
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
            in_sample: strategy.is_in_sample(),
            in_sample_luminance: None,
            in_sample_luminance_stderr: None,
            in_sample_rms_percent: None,
            respects_fixed: true,
            error: (mean == 0.0).then(|| "the mean is zero: no merge events for this strategy".to_string()),
        }
    }
}

/// The sample variance (M − 1 normalisation) from M, Σ C and Σ C², never negative.
pub(crate) fn sample_variance(m: f64, s1: f64, s2: f64) -> f64 {
    let mean = s1 / m;
    (s2 / m - mean * mean).max(0.0) * m / (m - 1.0)
}

/// Central moments m3, m4 from power sums (population normalisation).
pub(crate) fn central_3_4(m: f64, s: [f64; 4]) -> (f64, f64) {
    let mu = s[0] / m;
    let (e2, e3, e4) = (s[1] / m, s[2] / m, s[3] / m);
    let m3 = e3 - 3.0 * mu * e2 + 2.0 * mu.powi(3);
    let m4 = e4 - 4.0 * mu * e3 + 6.0 * mu * mu * e2 - 3.0 * mu.powi(4);
    (m3, m4)
}

/// Position of a per-path strategy in the moments' lists.
pub(crate) fn path_index(strategy: PathStrategy) -> usize {
    PathStrategy::ALL.iter().position(|&s| s == strategy).expect("strategy listed")
}

/// Power sums Σ C^k, k = 1…4, of a per-path strategy in `fold`.
pub(crate) fn power_sums(fold: &FoldMoments, strategy: PathStrategy) -> [f64; 4] {
    fold.strategies[path_index(strategy)].clone().map(|x| x.value())
}

/// The row of a per-path strategy from its power sums.
fn path_row(fold: &FoldMoments, strategy: PathStrategy, fixed: &FixedWeights) -> NoiseRow {
    let s = power_sums(fold, strategy);
    let m = fold.iterations as f64;
    NoiseRow {
        respects_fixed: respects_fixed(strategy, fixed),
        ..NoiseRow::from_sums(Strategy::of_path(strategy), m, s[0], s[1], (m > 0.0).then(|| central_3_4(m, s)))
    }
}

/// The rows of the per-path strategies alone (cheap: no fit), for progress reports.
pub fn path_rows(moments: &Moments, fixed: &FixedWeights) -> Vec<NoiseRow> {
    let pooled = moments.pooled();
    PathStrategy::ALL.iter().map(|&s| path_row(&pooled, s, fixed)).collect()
}

/// Jackknife standard errors of each cell's (w0, w1, w2).
pub type WeightErrors = Vec<[f64; 3]>;

/// The weights a result recommends: `optimal_cv`'s λ, fitted on all iterations.
#[derive(Debug, Clone)]
pub struct Recommended {
    pub strategy: Strategy,
    pub lambda: f64,
    pub fit: Fit,
    /// Jackknife standard error of each cell's (w0, w1, w2) (see [`super::crossfit`]).
    pub stderr: Option<WeightErrors>,
    /// The cross-fit at λ whose pooled sums are the strategy's honest figures.
    pub cross_fit: CrossFit,
}

/// Variance of the best per-path strategy (of those keeping the solver's fixed weights) over the
/// recommended weights' cross-fitted variance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Gain {
    /// Var(best per-path strategy) / Var(recommended, cross-fitted): how many times fewer
    /// iterations the recommended weights need for the same noise.
    pub value: f64,
    /// Jackknife over the folds: each replicate leaves one fold out of *both* variances, so the
    /// two stay paired on the same iterations (a fold of unusual iterations moves numerator and
    /// denominator together). Null with fewer than two folds holding iterations.
    pub stderr: Option<f64>,
    /// The per-path strategy compared against (lowest RMS among those that keep the solver's fixed
    /// weights, `respects_fixed` in the noise table).
    pub versus: Strategy,
    /// The fitted strategy whose weights are recommended.
    pub strategy: Strategy,
}

/// The noise table, the fits behind it and the recommendation.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    pub rows: Vec<NoiseRow>,
    /// The in-sample fit at the spec's λ (the paper's procedure; `?lambda=` weights tables).
    pub optimal: Result<Fit, SolveError>,
    /// The recommended weights, or why there are none.
    pub recommended: Result<Recommended, String>,
    /// Against the best per-path strategy that keeps the solver's fixed weights.
    pub gain: Option<Gain>,
    /// Against the best per-path strategy that does not (what the fixed weights cost).
    pub unconstrained: Option<Gain>,
    /// All folds added together, and the cross-fitting sets: kept for the report's warnings, merge
    /// rates and `?lambda=` weights, so that nothing pools the folds twice.
    pub pooled: FoldMoments,
    pub cross_fitting: CrossFitting,
}

/// Computes the noise table of `moments` with the given solver options.
pub fn noise_table(moments: &Moments, grid: &CellGrid, solver: &SolverOptions) -> NoiseTable {
    let pooled = moments.pooled();
    let row = |s| path_row(&pooled, s, &solver.fixed);
    let mut rows = vec![
        row(PathStrategy::Plane1),
        row(PathStrategy::Plane2),
        row(PathStrategy::Plane3),
        row(PathStrategy::Switch),
    ];
    let cf = CrossFitting::new(moments, &pooled);

    // Case 5: fitted and evaluated on all iterations.
    let optimal = fit(&cf.all, grid, &solver.fixed, solver.lambda);
    rows.push(match &optimal {
        Ok(f) => in_sample_row(Strategy::Optimal, f, &cf.all),
        Err(e) => NoiseRow::failed(Strategy::Optimal, e.to_string()),
    });

    // K-fold cross-fitting at the spec's λ.
    rows.push(match cross_fit(&cf, grid, &solver.fixed, solver.lambda) {
        Ok(c) => cross_fitted_row(Strategy::OptimalHoldout, &c),
        Err(e) => NoiseRow::failed(Strategy::OptimalHoldout, format!("a cross-fit failed: {e}")),
    });

    // λ by cross-fitted RMS; its cross-fitted figures, and the all-data fit recommended.
    let recommended = recommend(&cf, grid, solver);
    rows.push(match &recommended {
        Ok(r) => {
            let inner = in_sample_row(Strategy::OptimalCv, &r.fit, &cf.all);
            NoiseRow {
                in_sample_luminance: inner.luminance,
                in_sample_luminance_stderr: inner.luminance_stderr,
                in_sample_rms_percent: inner.rms_percent,
                ..cross_fitted_row(Strategy::OptimalCv, &r.cross_fit)
            }
        }
        Err(e) => NoiseRow::failed(Strategy::OptimalCv, e.clone()),
    });

    rows.extend(PathStrategy::ALL.iter().filter(|s| !s.is_case()).map(|&s| row(s)));
    let keeps = |s: PathStrategy| respects_fixed(s, &solver.fixed);
    let against = |inside: bool| recommended.as_ref().ok().and_then(|r| gain(moments, r, |s| keeps(s) == inside));
    let (gain, unconstrained) = (against(true), against(false));
    NoiseTable { rows, optimal, recommended, gain, unconstrained, pooled, cross_fitting: cf }
}

/// The row of weights `f` scored on the iterations they were fitted to.
fn in_sample_row(name: Strategy, f: &Fit, stats: &YStats) -> NoiseRow {
    let (s1, s2) = stats.evaluate(&f.vector());
    NoiseRow { lambda: Some(f.lambda), ..NoiseRow::from_sums(name, stats.m, s1, s2, None) }
}

/// The row of a cross-fit's pooled sums.
fn cross_fitted_row(name: Strategy, c: &CrossFit) -> NoiseRow {
    let [m, s1, s2] = c.totals();
    NoiseRow { lambda: Some(c.lambda), ..NoiseRow::from_sums(name, m, s1, s2, None) }
}

/// Chooses λ on the grid by cross-fitted RMS and fits the recommended weights on all iterations.
fn recommend(cf: &CrossFitting, grid: &CellGrid, solver: &SolverOptions) -> Result<Recommended, String> {
    let cross_fit = select_lambda(cf, grid, &solver.fixed, &solver.cv_lambdas)
        .map_err(|failures| format!("no λ of the grid could be cross-fitted ({})", failures.join("; ")))?;
    let lambda = cross_fit.lambda;
    let fit = fit(&cf.all, grid, &solver.fixed, lambda)
        .map_err(|e| format!("the final fit with λ = {lambda} failed: {e}"))?;
    Ok(Recommended { strategy: Strategy::OptimalCv, lambda, fit, stderr: cross_fit.weight_stderr(), cross_fit })
}

/// The in-sample fit of all iterations at λ with jackknife standard errors (the weights table a
/// `?lambda=` query asks for).
pub fn weights_at(
    cf: &CrossFitting,
    grid: &CellGrid,
    solver: &SolverOptions,
    lambda: f64,
) -> Result<(Fit, Option<WeightErrors>), SolveError> {
    let all = fit(&cf.all, grid, &solver.fixed, lambda)?;
    let stderr = cross_fit(cf, grid, &solver.fixed, lambda).ok().and_then(|c| c.weight_stderr());
    Ok((all, stderr))
}

/// The gain of the recommended weights over the best per-path strategy among `candidates`, with its
/// jackknife SE.
fn gain(moments: &Moments, r: &Recommended, candidates: impl Fn(PathStrategy) -> bool) -> Option<Gain> {
    let variance = |[m, s1, s2]: [f64; 3]| (m >= 2.0).then(|| sample_variance(m, s1, s2));
    let fixed_sums = |s: PathStrategy, left_out: Option<usize>| {
        let mut t = [0.0; 3];
        for (f, fold) in moments.folds.iter().enumerate() {
            if Some(f) != left_out {
                let p = power_sums(fold, s);
                t = [t[0] + fold.iterations as f64, t[1] + p[0], t[2] + p[1]];
            }
        }
        t
    };
    // The best per-path strategy: the lowest relative noise on all iterations.
    let relative = |s: PathStrategy| {
        let t = fixed_sums(s, None);
        variance(t).filter(|_| t[1] != 0.0).map(|v| v / (t[1] / t[0]).powi(2))
    };
    let versus = PathStrategy::ALL
        .iter()
        .filter(|&&s| candidates(s))
        .filter_map(|&s| relative(s).filter(|v| v.is_finite()).map(|v| (s, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?
        .0;
    let ratio = |left_out: Option<usize>| {
        let opt = variance(r.cross_fit.totals_except(left_out))?;
        let fixed = variance(fixed_sums(versus, left_out))?;
        (opt > 0.0).then(|| fixed / opt)
    };
    let value = ratio(None)?;
    let replicates: Option<Vec<f64>> = r.cross_fit.folds.iter().map(|(f, _, _)| ratio(Some(*f))).collect();
    let stderr = replicates.filter(|x| x.len() >= 2).map(|x| jackknife_se(x.iter().copied()));
    Some(Gain { value, stderr, versus: Strategy::of_path(versus), strategy: r.strategy })
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
    fn a_strategy_keeps_fixed_weights_only_if_it_gives_them_to_every_path() {
        let paper = FixedWeights { w0: Some(0.0), w1: None, w2: None };
        let keeps: Vec<&str> =
            PathStrategy::ALL.iter().filter(|&&s| respects_fixed(s, &paper)).map(|s| s.name()).collect();
        assert_eq!(keeps, ["plane2", "plane3", "switch"]);
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
