//! Warnings: where the data cannot support a figure the result shows, machine-readable.
//!
//! Each warning has a stable `code`, a sentence for people, and the strategy or cells it concerns.
//! The thresholds are rules of thumb, stated beside each constant with the reason for its value;
//! a warning never changes a figure, it says how far to trust it.

use serde::{Deserialize, Serialize};

use super::noise::{NoiseRow, NoiseTable, central_3_4, power_sums};
use super::solver::CellStatus;
use super::strategy::Strategy;
use crate::sim::engines::tally::PathStrategy;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// What a warning is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum WarningCode {
    /// Fewer iterations than [`ITERATIONS_PER_FREE_WEIGHT`] per free weight.
    TooFewIterations,
    /// Fitted cells with fewer than [`MIN_CELL_EVENTS`] merge events.
    SparseCells,
    /// Recommended weights whose jackknife standard error exceeds [`UNSTABLE_STDERR`].
    UnstableFit,
    /// The recommended weights are not measurably better than the best per-path strategy.
    NoGain,
    /// A strategy's values are so heavy-tailed that its standard errors are unreliable.
    HeavyTail,
    /// The in-sample `optimal` row is far from its cross-fitted counterpart.
    InSampleOptimistic,
    /// A per-path strategy outside the solver's fixed weights is measurably less noisy than the
    /// recommended weights: the constraint costs noise.
    FixedWeightsCost,
}

/// One warning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Warning {
    pub code: WarningCode,
    pub message: String,
    /// The noise-table row concerned, if one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strategy: Option<Strategy>,
    /// The cells concerned (indices of the weights table), if any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cells: Vec<usize>,
}

/// Iterations per free weight below which a fit is mostly noise: a least-squares fit of p
/// parameters to M samples has its in-sample variance low by a factor ≈ (1 − p/M), so with M < 10p
/// the in-sample figure is optimistic by more than 10% and the weights' errors are large.
pub const ITERATIONS_PER_FREE_WEIGHT: f64 = 10.0;
/// Merge events below which a cell's weights rest on too few samples: with n events the relative
/// error of a cell's second moments is of order 1/√n, above 18% for n < 30.
pub const MIN_CELL_EVENTS: u64 = 30;
/// Jackknife standard error of a weight above which the fit is unstable from fold to fold (the
/// weights of a cell sum to one, so an error of 0.25 is a quarter of the whole range of sensible
/// weights).
pub const UNSTABLE_STDERR: f64 = 0.25;
/// Relative standard error of a per-path strategy's RMS above which its standard errors are
/// unreliable. The delta-method SE of the RMS grows with the kurtosis κ (≈ R·√((κ − 1)/4M)), and the
/// SE of L is proportional to the RMS: above 10% the SE of L is itself that uncertain, and with heavy
/// tails the sample κ — and so both SEs — are more likely too small than too large.
pub const HEAVY_TAIL_RELATIVE_ERROR: f64 = 0.1;
/// The in-sample `optimal` row is "far" from the cross-fitted `optimal_holdout` when its RMS is
/// lower by more than this fraction, or its L differs by more than two cross-fitted SE.
pub const IN_SAMPLE_RMS_GAP: f64 = 0.1;

/// The warnings of a noise table computed from `moments`.
pub fn warnings(moments: &Moments, table: &NoiseTable) -> Vec<Warning> {
    let mut out = Vec::new();
    let m = moments.iterations() as f64;
    if let Ok(r) = &table.recommended {
        let free = r.fit.free as f64;
        if free > 0.0 && m < ITERATIONS_PER_FREE_WEIGHT * free {
            out.push(Warning {
                code: WarningCode::TooFewIterations,
                message: format!(
                    "{m} iterations for {free} free weights (fewer than {ITERATIONS_PER_FREE_WEIGHT} per weight): the fitted weights are mostly noise and in-sample figures are optimistic; run more iterations, merge shards, fix weights or use coarser cells"
                ),
                strategy: Some(r.strategy),
                cells: Vec::new(),
            });
        }
        let sparse: Vec<usize> = (0..r.fit.cells.len())
            .filter(|&a| r.fit.cells[a].status == CellStatus::Fitted && r.fit.cells[a].samples < MIN_CELL_EVENTS)
            .collect();
        if !sparse.is_empty() {
            out.push(Warning {
                code: WarningCode::SparseCells,
                message: format!(
                    "{} fitted cells hold fewer than {MIN_CELL_EVENTS} merge events: their weights rest on too few samples (see the weights' standard errors)",
                    sparse.len()
                ),
                strategy: Some(r.strategy),
                cells: sparse,
            });
        }
        if let Some(se) = &r.stderr {
            let unstable: Vec<usize> =
                (0..se.len()).filter(|&a| se[a].iter().any(|&s| s > UNSTABLE_STDERR || s.is_nan())).collect();
            if !unstable.is_empty() {
                out.push(Warning {
                    code: WarningCode::UnstableFit,
                    message: format!(
                        "the weights of {} cells change from fold to fold by more than {UNSTABLE_STDERR} (jackknife standard error): they are not determined by these data",
                        unstable.len()
                    ),
                    strategy: Some(r.strategy),
                    cells: unstable,
                });
            }
        }
    }
    if let Some(g) = table.gain
        && g.value - 1.0 < 2.0 * g.stderr.unwrap_or(f64::INFINITY)
    {
        let se = g.stderr.map_or("unknown".to_string(), |s| format!("{s:.2}"));
        let verdict = if g.value + 2.0 * g.stderr.unwrap_or(f64::INFINITY) < 1.0 {
            "noisier than"
        } else {
            "not measurably better than"
        };
        out.push(Warning {
            code: WarningCode::NoGain,
            message: format!(
                "the recommended weights ({}) are {verdict} {}: variance ratio {:.2} ± {se}, not 2 standard errors above 1",
                g.strategy, g.versus, g.value
            ),
            strategy: Some(g.strategy),
            cells: Vec::new(),
        });
    }
    if let Some(g) = table.unconstrained
        && let Some(se) = g.stderr
        && g.value + 2.0 * se < 1.0
    {
        out.push(Warning {
            code: WarningCode::FixedWeightsCost,
            message: format!(
                "{} does not keep the solver's fixed weights but is less noisy than the recommended weights ({}): variance ratio {:.2} ± {se:.2}; if your renderer can use its merges, free the fixed weights (e.g. \"solver\": {{\"fixed\": {{\"w0\": null}}}})",
                g.versus, g.strategy, g.value
            ),
            strategy: Some(g.versus),
            cells: Vec::new(),
        });
    }
    out.extend(heavy_tails(&table.pooled, &table.rows));
    out.extend(in_sample_gap(&table.rows));
    out
}

/// A [`WarningCode::HeavyTail`] for every per-path strategy whose RMS (and so its SE) is too
/// uncertain.
fn heavy_tails(pooled: &FoldMoments, rows: &[NoiseRow]) -> Vec<Warning> {
    let m = pooled.iterations as f64;
    PathStrategy::ALL
        .iter()
        .filter_map(|&s| {
            let row = rows.iter().find(|r| r.strategy == Strategy::of_path(s))?;
            let relative = row.rms_percent_stderr? / row.rms_percent?;
            let sums = power_sums(pooled, s);
            let mean = sums[0] / m;
            let m2 = sums[1] / m - mean * mean;
            let (_, m4) = central_3_4(m, sums);
            let kurtosis = m4 / (m2 * m2);
            (relative > HEAVY_TAIL_RELATIVE_ERROR).then(|| Warning {
                code: WarningCode::HeavyTail,
                message: format!(
                    "{}: its RMS is uncertain by ±{:.0}% (sample kurtosis {kurtosis:.0} over {m} iterations; at least {:.1}% of Σ(C − L)² comes from a single iteration), and so is its standard error of L — heavy tails make both more likely too small than too large; run more iterations",
                    s.name(),
                    100.0 * relative,
                    100.0 * kurtosis / m
                ),
                strategy: Some(Strategy::of_path(s)),
                cells: Vec::new(),
            })
        })
        .collect()
}

/// A [`WarningCode::InSampleOptimistic`] when `optimal` is far from `optimal_holdout`.
fn in_sample_gap(rows: &[NoiseRow]) -> Option<Warning> {
    let find = |s: Strategy| rows.iter().find(|r| r.strategy == s);
    let (inner, honest) = (find(Strategy::Optimal)?, find(Strategy::OptimalHoldout)?);
    let (l_in, rms_in) = (inner.luminance?, inner.rms_percent?);
    let (l_cf, se_cf, rms_cf) = (honest.luminance?, honest.luminance_stderr?, honest.rms_percent?);
    let z = (l_in - l_cf) / se_cf;
    let far = rms_in < (1.0 - IN_SAMPLE_RMS_GAP) * rms_cf || z.abs() > 2.0;
    far.then(|| Warning {
        code: WarningCode::InSampleOptimistic,
        message: format!(
            "the in-sample optimal row (RMS {rms_in:.1}%) is far from its cross-fitted figure (RMS {rms_cf:.1}%, L differs by {z:.1} cross-fitted standard errors): trust optimal_holdout and optimal_cv, not optimal"
        ),
        strategy: Some(Strategy::Optimal),
        cells: Vec::new(),
    })
}
