//! Any weights scored on any run: a weights table (with heuristics stacked on it, or none) given as
//! a result document's recommendation or as a table of its own, evaluated on the moments of another
//! run — how a researcher checks weights on independent iterations (docs/model.md §10).
//!
//! The weights define a coefficient vector v on the moment vector (C_s = ⟨Y_s|v⟩, see
//! [`super::solver`]), so the run's exact sums give Σ C_s and Σ C_s² per fold: L with its standard
//! error std/√M, the RMS% with the standard error of a fitted row ([`super::rms_error`]), and —
//! paired on the same iterations
//! — the variance ratio of every per-path strategy of the run against the weights, with its
//! jackknife SE. When the weights were fitted on iterations this run also holds (the coverages
//! overlap), the figures are in-sample and say so.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use super::options::FixedWeights;
use super::recommend::paired_ratio;
use super::rms_error::{references, rms_stderr};
use super::row::{NoiseRow, path_fold_sums, path_rows};
use super::strategy::Strategy;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::{CellGrid, MAX_CELLS};
use crate::sim::stats::bounded::bounded;
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;

/// Largest difference between a given cell bound and the run's grid that still counts as the same
/// edge (edges are printed and parsed as shortest round-trip decimals, so they match exactly; this
/// only forgives a table written by hand with fewer digits).
const EDGE_TOLERANCE: f64 = 1e-12;

/// One cell of a weights table to evaluate: its bounds (as in a result's `weights`) and weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct GivenCell {
    /// [lo, hi) of r2 = |x2| (hi null: the tail cell); must match the run's cell.
    pub r2: [Option<f64>; 2],
    /// [lo, hi) of r3 = |x3|, likewise.
    pub r3: [Option<f64>; 2],
    /// [lo, hi) of φ in radians, likewise.
    pub phi: [Option<f64>; 2],
    /// The weight of plane-1 merges (the pixel) in this cell.
    pub w0: f64,
    /// The weight of plane-2 merges.
    pub w1: f64,
    /// The weight of plane-3 merges.
    pub w2: f64,
}

/// A stacked heuristic's β in given weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct GivenHeuristic {
    /// The stacked heuristic (a stackable per-path strategy).
    pub strategy: Strategy,
    /// Its coefficient β in w = table + Σ β·w_h.
    pub beta: f64,
}

/// The weights to evaluate. A result document (`GET /v1/jobs/{id}/result`, `optimis run --json`)
/// is one: its `recommended` names the strategy and the heuristics, `weights` the table; unknown
/// fields are ignored. A hand-made table gives `weights` and, optionally, `heuristics`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct GivenWeights {
    /// The table, one entry per cell of the run's grid in its order (empty: a per-path strategy
    /// named by `recommended`).
    #[serde(default, deserialize_with = "bounded::<_, _, MAX_CELLS>")]
    pub weights: Vec<GivenCell>,
    /// Heuristics stacked on the table (when the document has no `recommended`).
    #[serde(default, deserialize_with = "bounded::<_, _, { PathStrategy::COUNT }>")]
    pub heuristics: Vec<GivenHeuristic>,
    /// A result document's recommendation.
    #[serde(default)]
    pub recommended: Option<GivenRecommendation>,
    /// A result document's coverage: the iterations the weights were fitted on.
    #[serde(default)]
    pub coverage: Option<Coverage>,
}

/// The part of a result's `recommended` that evaluation reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct GivenRecommendation {
    /// The recommended strategy: a per-path one is evaluated as it is, a fitted one through the
    /// document's `weights`.
    pub strategy: Strategy,
    /// The smoothness penalty the weights were fitted at (read, not needed to evaluate them).
    #[serde(default)]
    pub lambda: Option<f64>,
    /// The heuristics stacked on the table, with their β.
    #[serde(default, deserialize_with = "bounded::<_, _, { PathStrategy::COUNT }>")]
    pub heuristics: Vec<GivenHeuristic>,
}

/// Why given weights cannot be evaluated on a run; `field` names the offending part of the
/// weights document.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct EvaluateError {
    /// The JSON path of the offending part (e.g. `weights[3]`, `recommended.heuristics`).
    pub field: String,
    /// What is wrong with it.
    pub message: String,
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> EvaluateError {
    EvaluateError { field: field.into(), message: message.into() }
}

/// Given weights scored on a run, beside the run's per-path strategies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Evaluation {
    /// Iterations of the run scored on.
    pub iterations: u64,
    /// The run's cross-fitting folds K (the jackknife's groups).
    pub folds: usize,
    /// The strategy the weights came from (`recommended.strategy`), if named.
    pub source: Option<Strategy>,
    /// The given weights' figures on this run: L ± SE, RMS% ± jackknife SE over the folds;
    /// `in_sample` when the weights were fitted on iterations this run holds.
    pub evaluated: NoiseRow,
    /// The run's per-path strategies, each with the paired variance ratio against the weights.
    pub versus: Vec<Versus>,
}

/// One per-path strategy of the run against the evaluated weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Versus {
    /// The per-path strategy's own figures on the run.
    pub row: NoiseRow,
    /// Var(strategy)/Var(evaluated weights) on the same iterations (> 1: the weights are better).
    pub variance_ratio: Option<f64>,
    /// Paired jackknife SE of the ratio over the folds.
    pub variance_ratio_stderr: Option<f64>,
}

/// Scores `given` on `moments` (drawn on `grid`); the run's per-path rows say whether they keep the
/// run's `fixed` weights, as its result's rows do.
pub fn evaluate(
    moments: &Moments,
    grid: &CellGrid,
    given: &GivenWeights,
    fixed: &FixedWeights,
) -> Result<Evaluation, EvaluateError> {
    let layout = moments.layout();
    if let Some(c) = &given.coverage {
        c.check().map_err(|e| invalid("coverage", e.to_string()))?;
    }
    let (source, heuristics, named) = match &given.recommended {
        Some(r) => (Some(r.strategy), &r.heuristics, "recommended.heuristics"),
        None => (None, &given.heuristics, "heuristics"),
    };
    // A per-path recommendation has no table: its own row on this run is its evaluation.
    let folds_sums: Vec<(usize, [f64; 3])> = match source.and_then(Strategy::path).filter(|_| given.weights.is_empty())
    {
        Some(p) => {
            let sums = path_fold_sums(moments, p);
            if sums.is_empty() {
                return Err(invalid("recommended.strategy", format!("{p:?} is not kept by these moments (format 2)")));
            }
            sums
        }
        None => {
            let v = coefficients(moments, grid, given, heuristics, named)?;
            let stats =
                |f: &crate::sim::stats::moments::FoldMoments| crate::sim::solve::ystats::YStats::from_fold(f, layout);
            moments
                .folds
                .iter()
                .enumerate()
                .filter(|(_, f)| f.iterations > 0)
                .map(|(i, f)| {
                    let (s1, s2) = stats(f).evaluate(&v);
                    (i, [f.iterations as f64, s1, s2])
                })
                .collect()
        }
    };
    let total = folds_sums.iter().fold([0.0; 3], |t, (_, s)| [t[0] + s[0], t[1] + s[1], t[2] + s[2]]);
    let name = source.unwrap_or(Strategy::Optimal);
    let in_sample = given.coverage.as_ref().is_some_and(|c| !c.overlaps(&moments.coverage).is_empty());
    // A per-path strategy is its own reference (its delta-method SE); a table gets the fitted rows'
    // SE through the per-path row it is best determined against (`rms_error`).
    let own = NoiseRow::from_sums(name, total[0], total[1], total[2], None);
    let reference_rows = references(moments);
    let stderr = match source.and_then(Strategy::path).filter(|_| given.weights.is_empty()) {
        Some(p) => reference_rows.iter().find(|r| r.strategy == Strategy::of_path(p)).map(|r| r.rms_percent_stderr),
        None => rms_stderr(&folds_sums, &reference_rows),
    };
    let evaluated = NoiseRow { rms_percent_stderr: stderr, in_sample, ..own };
    let versus = path_rows(moments, fixed)
        .into_iter()
        .zip(PathStrategy::ALL)
        .filter(|(row, _)| row.error.is_none())
        .map(|(row, p)| {
            let ratio = paired_ratio(&path_fold_sums(moments, p), &folds_sums);
            Versus { row, variance_ratio: ratio.map(|r| r.0), variance_ratio_stderr: ratio.and_then(|r| r.1) }
        })
        .collect();
    Ok(Evaluation { iterations: moments.iterations(), folds: moments.fold_count(), source, evaluated, versus })
}

/// The coefficient vector v of a given table and heuristics on `moments`' layout, after checking
/// that the table is the run's grid and that every heuristic has a column.
fn coefficients(
    moments: &Moments,
    grid: &CellGrid,
    given: &GivenWeights,
    heuristics: &[GivenHeuristic],
    named: &str,
) -> Result<DVector<f64>, EvaluateError> {
    let layout = moments.layout();
    let k = grid.len();
    if given.weights.len() != k {
        return Err(invalid(
            "weights",
            format!(
                "has {} cells but this run's grid has {k}: the weights were fitted on another grid",
                given.weights.len()
            ),
        ));
    }
    let same = |a: [Option<f64>; 2], b: [Option<f64>; 2]| {
        a.iter().zip(&b).all(|(x, y)| match (x, y) {
            (Some(x), Some(y)) => (x - y).abs() <= EDGE_TOLERANCE * x.abs().max(1.0),
            (None, None) => true,
            _ => false,
        })
    };
    let mut v = DVector::zeros(layout.dimension());
    // The heuristics first: a table's sum is checked against their β.
    for (i, h) in heuristics.iter().enumerate() {
        let field = format!("{named}[{i}]");
        let index = h.strategy.path().and_then(|p| layout.heuristic_index(p)).ok_or_else(|| {
            invalid(
                &field,
                format!("{} has no column in these moments (a stackable heuristic of format 3)", h.strategy),
            )
        })?;
        if !h.beta.is_finite() || h.beta.abs() > 1e6 {
            return Err(invalid(&field, "β must be finite with |β| ≤ 1e6"));
        }
        v[index] += h.beta;
    }
    let beta_sum: f64 = heuristics.iter().map(|h| h.beta).sum();
    for (a, cell) in given.weights.iter().enumerate() {
        let b = grid.bounds(a);
        if !(same(cell.r2, b.r2) && same(cell.r3, b.r3) && same(cell.phi, b.phi)) {
            return Err(invalid(
                format!("weights[{a}]"),
                "its bounds are not this run's cell: the weights were fitted on another grid",
            ));
        }
        let w = [cell.w0, cell.w1, cell.w2];
        if !w.iter().all(|x| x.is_finite() && x.abs() <= 1e6) {
            return Err(invalid(format!("weights[{a}]"), "weights must be finite with |w| ≤ 1e6"));
        }
        if (w.iter().sum::<f64>() - (1.0 - beta_sum)).abs() > 1e-6 {
            return Err(invalid(
                format!("weights[{a}]"),
                format!(
                    "w0 + w1 + w2 = {} but must be 1 − Σβ = {} (or the estimate is biased)",
                    w.iter().sum::<f64>(),
                    1.0 - beta_sum
                ),
            ));
        }
        v[a] = cell.w0;
        v[k + a] = cell.w1;
    }
    v[layout.b_index()] = 1.0 - beta_sum;
    Ok(v)
}
