//! One row of the noise table: a strategy's L and RMS with their standard errors, from its sums;
//! and the rows of the per-path strategies, from their power sums (see [`super::noise`] for the
//! table).
//!
//! For a strategy with per-iteration values C_s: L = mean C_s, its standard error std/√M, and
//! RMS% = 100·std(C_s)/|mean(C_s)| with the sample standard deviation (M − 1). The standard error
//! of a per-path strategy's RMS% is the delta method on (mean, variance): with central moments m2,
//! m3, m4, Var(R̂) ≈ R²/M · [m2/μ² − m3/(μ·m2) + (m4 − m2²)/(4·m2²)], from Σ C_s³ and Σ C_s⁴,
//! which the moments carry for every per-path strategy.

use serde::{Deserialize, Serialize};

use super::options::FixedWeights;
use super::strategy::Strategy;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::math::exact_sum::ExactSum;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// A stacked heuristic's coefficient in a fitted row: per-path weights are the table's plus
/// β·(the heuristic's weights).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct HeuristicWeight {
    /// The per-path heuristic.
    pub strategy: Strategy,
    /// β, fitted on all iterations.
    pub beta: f64,
    /// Jackknife standard error of β over the fold fits.
    pub beta_stderr: Option<f64>,
}

/// One λ of a cross-validation: the cross-fitted RMS% of the fit at λ, its jackknife SE, and
/// whether the fit was stable.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct LambdaScore {
    /// The gradient penalty λ.
    pub lambda: f64,
    /// The cross-fitted RMS% of the fit at λ.
    pub rms_percent: f64,
    /// Its standard error; null when none can be given.
    pub rms_percent_stderr: Option<f64>,
    /// Whether no data-fitted table weight changes from fold to fold by more than 0.25
    /// (jackknife SE): an unstable λ is never chosen while a stable one exists.
    pub stable: bool,
}

/// One row of the noise table. Keys are stable (dashboards depend on them); a value that cannot be
/// computed is null, with the reason in `error`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct NoiseRow {
    /// The row's strategy.
    pub strategy: Strategy,
    /// L: the mean of the strategy's per-iteration estimates C_s (cross-fitted for fitted rows).
    pub luminance: Option<f64>,
    /// The standard error of L: std(C_s)/√M.
    pub luminance_stderr: Option<f64>,
    /// The relative noise of one iteration: 100·std(C_s)/|L|.
    pub rms_percent: Option<f64>,
    /// Per-path rows: the delta method on the power sums; fitted rows: the jackknife over the
    /// cross-fitting folds (null for the in-sample `optimal`, whose RMS is optimistic).
    pub rms_percent_stderr: Option<f64>,
    /// λ of a fitted strategy (`optimal_cv`, `optimal_stacked`: the λ chosen).
    pub lambda: Option<f64>,
    /// Whether the figures are scored on the iterations the weights were fitted to (`optimal`, the
    /// paper's procedure): then they are optimistic — L biased, its standard error and the RMS too
    /// small — and the row is never recommended.
    #[serde(default)]
    pub in_sample: bool,
    /// Fitted rows chosen by cross-validation: L of their weights fitted and scored on all
    /// iterations (in-sample, optimistic); `luminance` is the cross-fitted figure.
    #[serde(default)]
    pub in_sample_luminance: Option<f64>,
    /// The in-sample standard error of L (too small).
    #[serde(default)]
    pub in_sample_luminance_stderr: Option<f64>,
    /// The in-sample RMS% (too small).
    #[serde(default)]
    pub in_sample_rms_percent: Option<f64>,
    /// Whether the row's weights keep the solver's fixed weights (`solver.fixed`). A per-path
    /// strategy that does not — e.g. `balance`, which merges at the pixel while the paper fixes
    /// w0 = 0 — is shown for comparison but is neither recommended nor the gain's reference: it
    /// answers another question than the one the fixed weights ask (a `fixed_weights_cost` warning
    /// says when it is less noisy). Fitted rows keep them by construction.
    #[serde(default = "keeps")]
    pub respects_fixed: bool,
    /// Fitted rows with heuristics stacked on the table: each heuristic's β.
    #[serde(default)]
    pub heuristics: Vec<HeuristicWeight>,
    /// Rows whose λ was chosen by cross-validation: every λ of the grid with its cross-fitted RMS,
    /// the jackknife SE and whether its fit was stable (the curve the one-SE rule read).
    #[serde(default)]
    pub cv_path: Vec<LambdaScore>,
    /// A fitted row whose data-fitted table weights change from fold to fold by more than 0.25
    /// (jackknife SE): never recommended.
    #[serde(default)]
    pub unstable: bool,
    /// A fitted row's bound on how far its per-path weights move from those of the best per-path
    /// row that keeps the fixed weights (`solver.trust_region`; docs/model.md §10); null for
    /// per-path rows and for fits that cannot represent that row (a table alone against a
    /// heuristic).
    #[serde(default)]
    pub deviation: Option<f64>,
    /// A per-path row whose L lies more than 3 SE below its exact expectation at R
    /// (`solve::expectation`): the run lacks the rare large contributions that dominate its
    /// variance, so its RMS is far too small; it is neither recommended nor the trust region's
    /// anchor.
    #[serde(default)]
    pub tail_missing: bool,
    /// A fitted row beyond the trust region (its `deviation` above `solver.trust_region`, or none):
    /// its advantage may rest on events the run did not draw, so it is never recommended.
    #[serde(default)]
    pub beyond_trust_region: bool,
    /// The row's expected luminance at the job's merge radius R by quadrature (docs/model.md §11);
    /// null for fitted rows (their expectation depends on weights fitted to these data) and where
    /// the quadrature could not resolve it (`expected_error`).
    #[serde(default)]
    pub expected_luminance: Option<f64>,
    /// (luminance − expected_luminance)/luminance_stderr.
    #[serde(default)]
    pub z: Option<f64>,
    /// Why the row has no expected luminance.
    #[serde(default)]
    pub expected_error: Option<String>,
    /// Why the row's figures could not be computed (its values are then null).
    pub error: Option<String>,
    /// How a fitted row's figures were made when it differs from its name's promise (e.g. a
    /// heuristic left out of the stack because on these data it adds nothing to the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
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
    pub(crate) fn failed(strategy: Strategy, error: String) -> Self {
        Self { error: Some(error), ..Self::from_sums(strategy, 0.0, 0.0, 0.0, None) }
    }

    /// A row from M, Σ C and Σ C² (and, if known, the central moments for the RMS error).
    pub fn from_sums(strategy: Strategy, m: f64, s1: f64, s2: f64, higher: Option<(f64, f64)>) -> Self {
        let empty = Self {
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
            heuristics: Vec::new(),
            cv_path: Vec::new(),
            unstable: false,
            deviation: None,
            beyond_trust_region: false,
            tail_missing: false,
            expected_luminance: None,
            z: None,
            expected_error: None,
            error: None,
            note: None,
        };
        if m < 2.0 {
            return Self { error: Some(format!("at least 2 iterations are needed, got {m}")), ..empty };
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
            luminance: Some(mean),
            luminance_stderr: Some(std / m.sqrt()),
            rms_percent: rms,
            rms_percent_stderr: rms_se,
            error: (mean == 0.0).then(|| "the mean is zero: no merge events for this strategy".to_string()),
            ..empty
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

/// Power sums Σ C^k, k = 1…4, of a per-path strategy in `fold`; `None` if the fold's format does
/// not keep that strategy (format 2 lacks the planes-2–3 heuristics).
pub(crate) fn power_sums(fold: &FoldMoments, strategy: PathStrategy) -> Option<[f64; 4]> {
    fold.strategies.get(strategy.index()).map(|s| s.clone().map(|x| x.value()))
}

/// (fold, [M_f, Σ C, Σ C²]) of per-path strategy `s` in every fold that holds iterations: what the
/// paired jackknife of a variance ratio needs.
pub(crate) fn path_fold_sums(moments: &Moments, s: PathStrategy) -> Vec<(usize, [f64; 3])> {
    moments
        .folds
        .iter()
        .enumerate()
        .filter(|(_, fold)| fold.iterations > 0)
        .filter_map(|(f, fold)| power_sums(fold, s).map(|p| (f, [fold.iterations as f64, p[0], p[1]])))
        .collect()
}

/// The row of a per-path strategy from its power sums.
pub(crate) fn path_row(fold: &FoldMoments, strategy: PathStrategy, fixed: &FixedWeights) -> NoiseRow {
    path_row_of(strategy, fold.iterations, power_sums(fold, strategy), fixed)
}

/// The row of per-path strategy `strategy` from `iterations` and its power sums, if kept.
fn path_row_of(strategy: PathStrategy, iterations: u64, sums: Option<[f64; 4]>, fixed: &FixedWeights) -> NoiseRow {
    let name = Strategy::of_path(strategy);
    let Some(s) = sums else {
        return NoiseRow {
            respects_fixed: respects_fixed(strategy, fixed),
            ..NoiseRow::failed(
                name,
                "not in these moments: format 2 (written by an earlier optimis) does not keep this strategy".into(),
            )
        };
    };
    let m = iterations as f64;
    NoiseRow {
        respects_fixed: respects_fixed(strategy, fixed),
        ..NoiseRow::from_sums(name, m, s[0], s[1], (m > 0.0).then(|| central_3_4(m, s)))
    }
}

/// The rows of the per-path strategies alone (cheap: no fit), for progress reports and the points
/// of a job's history between checkpoints. Only these strategies' power sums are added over the
/// folds — exactly, so the rows equal the noise table's — not every sum of the moments (the cells'
/// second moments among them), which took milliseconds at every point.
pub fn path_rows(moments: &Moments, fixed: &FixedWeights) -> Vec<NoiseRow> {
    let iterations = moments.folds.iter().map(|f| f.iterations).sum();
    PathStrategy::ALL
        .iter()
        .map(|&s| {
            let mut pooled: [ExactSum; 4] = std::array::from_fn(|_| ExactSum::new());
            let kept = moments.folds.iter().all(|fold| match fold.strategies.get(s.index()) {
                Some(sums) => {
                    pooled.iter_mut().zip(sums).for_each(|(p, x)| p.add_sum(x));
                    true
                }
                None => false,
            });
            path_row_of(s, iterations, kept.then(|| pooled.map(|x| x.value())), fixed)
        })
        .collect()
}

/// Jackknife standard errors of each cell's (w0, w1, w2).
pub type WeightErrors = Vec<[f64; 3]>;
