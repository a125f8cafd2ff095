//! Warnings: where the data cannot support a figure the result shows, machine-readable.
//!
//! Each warning has a stable `code`, a sentence for people, and the strategy or cells it concerns.
//! The thresholds are rules of thumb, stated beside each constant with the reason for its value;
//! a warning never changes a figure, it says how far to trust it.

use serde::{Deserialize, Serialize};

use super::crossfit::UNSTABLE_STDERR;
use super::noise::{NoiseRow, NoiseTable, central_3_4, power_sums};
use super::recommend::GUARD_SE;
use super::solver::{CellStatus, Fit, MIN_CELL_EVENTS};
use super::strategy::Strategy;
use super::ystats::YStats;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// What a warning is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum WarningCode {
    /// Fewer iterations than [`ITERATIONS_PER_FREE_WEIGHT`] per free weight of the recommended fit.
    TooFewIterations,
    /// Cells of the recommended fit that its own samples cannot estimate, where they matter to the
    /// figure ([`SPARSE_SHARE`]).
    SparseCells,
    /// A fitted row reports a lower RMS than the recommended one, but its weights are unstable from
    /// fold to fold, so it is not recommended.
    UnstableFit,
    /// A fitted row reports a lower RMS than the recommended one, but its weights move further
    /// from the best per-path row's than the trust region allows (`solver.trust_region`): its
    /// advantage may rest on events the run did not draw, so it is not recommended.
    BeyondTrustRegion,
    /// The recommended row is not measurably better than the per-path strategy compared with
    /// (or no fitted row beat the recommended per-path strategy).
    NoGain,
    /// A strategy's values are so heavy-tailed that its standard errors are unreliable.
    HeavyTail,
    /// A per-path strategy's L lies far below its exact expectation: the run lacks the rare large
    /// contributions that carry its variance, so its RMS is far too small (`solve::expectation`).
    TailMissing,
    /// The in-sample `optimal` row is far from its cross-fitted counterpart.
    InSampleOptimistic,
    /// A per-path strategy outside the solver's fixed weights is measurably less noisy than the
    /// recommended row: the constraint costs noise.
    FixedWeightsCost,
}

/// One warning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Warning {
    /// What kind of problem (stable: scripts match on it).
    pub code: WarningCode,
    /// The problem in a sentence, with the figures behind it.
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
/// The sparse cells of the recommended fit (fewer than [`MIN_CELL_EVENTS`] merge events) matter to
/// its figure when they hold more than this share of
/// the merge events, or when moving their free weights by a whole unit would change the pixel
/// variance by more than this share (Σ of their Var(A) over Var(C)): below 1% their weights, however
/// uncertain, cannot move the RMS by more than half a percent.
pub const SPARSE_SHARE: f64 = 0.01;
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
        if let Some(fit) = r.fit() {
            let free = fit.free as f64;
            if free > 0.0 && m < ITERATIONS_PER_FREE_WEIGHT * free {
                out.push(Warning {
                    code: WarningCode::TooFewIterations,
                    message: format!(
                        "{m} iterations for {free} free weights (fewer than {ITERATIONS_PER_FREE_WEIGHT} per weight): the fitted weights are mostly noise; run more iterations, merge shards, fix weights or use coarser cells"
                    ),
                    strategy: Some(r.strategy),
                    cells: Vec::new(),
                });
            }
            out.extend(sparse_cells(&table.cross_fitting.all, fit, m, r.strategy));
        }
        if r.fitted.is_none() {
            out.push(Warning {
                code: WarningCode::NoGain,
                message: format!("{} is recommended: {}", r.strategy, r.reason),
                strategy: Some(r.strategy),
                cells: Vec::new(),
            });
        }
        let recommended_rms = table.rows.iter().find(|x| x.strategy == r.strategy).and_then(|x| x.rms_percent);
        out.extend(beyond_trust_region(&table.rows, r.strategy, recommended_rms, table.margin.versus));
        for row in table.rows.iter().filter(|x| x.unstable && x.error.is_none()) {
            if let (Some(a), Some(b)) = (row.rms_percent, recommended_rms)
                && a < b
            {
                out.push(Warning {
                    code: WarningCode::UnstableFit,
                    message: format!(
                        "{} reports a lower RMS ({a:.1}%) than the recommended {} ({b:.1}%), but its weights change from fold to fold by more than {UNSTABLE_STDERR} (jackknife standard error) at every λ of the grid: they are not determined by these data, so it is not recommended",
                        row.strategy, r.strategy
                    ),
                    strategy: Some(row.strategy),
                    cells: table
                        .fitted
                        .iter()
                        .find(|f| f.strategy == row.strategy)
                        .map(|f| f.scored.unstable_cells.clone())
                        .unwrap_or_default(),
                });
            }
        }
    }
    if let Some(g) = table.gain
        && table.recommended.as_ref().is_ok_and(|r| r.fitted.is_some())
        && g.value - 1.0 < GUARD_SE * g.stderr.unwrap_or(f64::INFINITY)
    {
        let se = g.stderr.map_or("unknown".to_string(), |s| format!("{s:.2}"));
        out.push(Warning {
            code: WarningCode::NoGain,
            message: format!(
                "the recommended weights ({}) are not measurably better than {}: variance ratio {:.2} ± {se}, not {GUARD_SE} standard errors above 1",
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
        let versus_rms = table.rows.iter().find(|x| x.strategy == g.versus).and_then(|x| x.rms_percent);
        let stacked = table.free_stacked.as_ref().map_or_else(String::new, |f| {
            let se = f.rms_stderr.map_or_else(String::new, |s| format!(" ± {s:.1}"));
            // The stacked optimum contains the heuristic, but its cross-fitted figure can still be
            // higher where the run is too short to fit its extra terms: then say so, rather than
            // let a reader take the stacked row for the better choice.
            let short = match versus_rms {
                Some(v) if f.rms_percent > v => {
                    format!(", not better than {} alone ({v:.1}%) with this run's data", g.versus)
                }
                _ => String::new(),
            };
            format!(
                "; with the fixed weights freed, the stacked optimum (which contains {}) reaches {:.1}%{se} (cross-fitted, λ = {}){short}",
                g.versus, f.rms_percent, f.cross_fit.lambda
            )
        });
        out.push(Warning {
            code: WarningCode::FixedWeightsCost,
            message: format!(
                "{} does not keep the solver's fixed weights but is less noisy than the recommended {}: variance ratio {:.2} ± {se:.2}{stacked}; if your renderer can use its merges, free the fixed weights (e.g. \"solver\": {{\"fixed\": {{\"w0\": null}}}})",
                g.versus, g.strategy, g.value
            ),
            strategy: Some(g.versus),
            cells: Vec::new(),
        });
    }
    out.extend(heavy_tails(&table.pooled, &table.rows));
    out.extend(table.rows.iter().filter(|r| r.tail_missing).map(|r| Warning {
        code: WarningCode::TailMissing,
        message: format!(
            "{}: its L lies {:.1} standard errors below its exact expectation at R (quadrature): this run lacks the rare large contributions that carry its mean and its variance, so its RMS ({:.1}%) is far too small, however small its standard error; it is neither recommended nor compared with — run more iterations to see its real noise",
            r.strategy,
            -r.z.unwrap_or(f64::NAN),
            r.rms_percent.unwrap_or(f64::NAN)
        ),
        strategy: Some(r.strategy),
        cells: Vec::new(),
    }));
    out.extend(in_sample_gap(&table.rows));
    out
}

/// A [`WarningCode::BeyondTrustRegion`] for the lowest-RMS fitted row beyond the trust region when
/// it reports a lower RMS than the recommended row.
fn beyond_trust_region(
    rows: &[NoiseRow],
    recommended: Strategy,
    recommended_rms: Option<f64>,
    anchor: Option<Strategy>,
) -> Option<Warning> {
    let row = rows
        .iter()
        .filter(|x| x.beyond_trust_region && !x.unstable && x.error.is_none())
        .filter(|x| x.rms_percent.zip(recommended_rms).is_some_and(|(a, b)| a < b))
        .min_by(|a, b| a.rms_percent.unwrap_or(f64::INFINITY).total_cmp(&b.rms_percent.unwrap_or(f64::INFINITY)))?;
    let anchor = anchor.map_or_else(|| "the best per-path row".to_string(), |a| a.to_string());
    let how_far = match row.deviation {
        Some(d) => format!("its weights move by up to {d:.2} from {anchor}'s on some path"),
        None => format!("its family cannot represent {anchor}, so nothing bounds how far its weights move from it"),
    };
    Some(Warning {
        code: WarningCode::BeyondTrustRegion,
        message: format!(
            "{} reports a lower RMS ({:.1}%) than the recommended {recommended} ({:.1}%), but {how_far}, more than the trust region (solver.trust_region) allows: an advantage that large may rest on rare events this run did not draw (a longer run would show them), so it is not recommended",
            row.strategy,
            row.rms_percent.unwrap_or(f64::NAN),
            recommended_rms.unwrap_or(f64::NAN),
        ),
        strategy: Some(row.strategy),
        cells: Vec::new(),
    })
}

/// A [`WarningCode::SparseCells`] when the cells of `fit` that its own samples cannot estimate
/// matter to its figure ([`SPARSE_SHARE`]), with how many more iterations would give each of them
/// [`MIN_CELL_EVENTS`] merge events.
fn sparse_cells(all: &YStats, fit: &Fit, m: f64, strategy: Strategy) -> Option<Warning> {
    let k = fit.cells.len();
    let sparse: Vec<usize> = (0..k)
        .filter(|&a| fit.cells[a].status != CellStatus::Fixed && fit.cells[a].samples < MIN_CELL_EVENTS)
        .collect();
    let events: u64 = fit.cells.iter().map(|c| c.samples).sum();
    let sparse_events: u64 = sparse.iter().map(|&a| fit.cells[a].samples).sum();
    let merge_share = if events > 0 { sparse_events as f64 / events as f64 } else { 0.0 };
    let cov = all.covariance();
    let v = fit.coefficients(all.layout);
    let variance = v.dot(&(&cov * &v));
    let sensitivity: f64 = sparse.iter().map(|&a| cov[(a, a)] + cov[(k + a, k + a)]).sum::<f64>() / variance;
    // A NaN sensitivity (no variance) does not make the cells matter.
    let matters = merge_share > SPARSE_SHARE || sensitivity.is_finite() && sensitivity > SPARSE_SHARE;
    if sparse.is_empty() || !matters {
        return None;
    }
    let factor = sparse
        .iter()
        .map(|&a| fit.cells[a].samples)
        .filter(|&n| n > 0 && n < MIN_CELL_EVENTS)
        .map(|n| MIN_CELL_EVENTS.div_ceil(n))
        .max();
    let empty = sparse.iter().filter(|&&a| fit.cells[a].samples == 0).count();
    let more = match factor {
        Some(f) if f > 1 => format!(
            "; about {f}× the iterations ({:.0}) would give each of those with events {MIN_CELL_EVENTS} or more",
            m * f as f64
        ),
        _ => String::new(),
    };
    let none = if empty > 0 { format!("; {empty} have no merge event at all") } else { String::new() };
    Some(Warning {
        code: WarningCode::SparseCells,
        message: format!(
            "{} cells hold fewer than {MIN_CELL_EVENTS} merge events, too few for their own samples to estimate their weights, and they matter: {:.1}% of the merge events, and a unit change of their weights would move the variance by {:.1}%{more}{none}",
            sparse.len(),
            100.0 * merge_share,
            100.0 * sensitivity
        ),
        strategy: Some(strategy),
        cells: sparse,
    })
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
            let sums = power_sums(pooled, s)?;
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
    let (Some(l_cf), Some(se_cf), Some(rms_cf)) = (honest.luminance, honest.luminance_stderr, honest.rms_percent)
    else {
        // Nothing to hold the in-sample figures against (the cross-fitted fit failed, e.g. on a
        // few iterations): they are the fit's own noise as much as the weights' quality.
        let why = honest.error.as_deref().unwrap_or("it has no figures");
        return Some(Warning {
            code: WarningCode::InSampleOptimistic,
            message: format!(
                "the in-sample optimal row (RMS {rms_in:.1}%) cannot be checked out of sample — optimal_holdout could not be computed ({why}): its figures measure the fit's own noise as much as the weights; do not use them"
            ),
            strategy: Some(Strategy::Optimal),
            cells: Vec::new(),
        });
    };
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
