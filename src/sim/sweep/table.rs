//! A sweep's figures: per point, the honest noise table and the recommended weights (measured by
//! its run, or predicted from it), and the table of all points, as JSON rows or CSV.
//!
//! "Honest" rows only: the in-sample `optimal` row (the paper's procedure, optimistic) is left
//! out; `optimal_cv` is the cross-fitted figure of the recommended weights. Units are the model's:
//! `luminance` in the units of docs/model.md (the light's radiance scale), `rms_percent` in percent
//! of L for one iteration.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::plan::SweepPlan;
use crate::sim::math::csv::{Csv, cell, json_cell, number};
use crate::sim::model::cells::CellGrid;
use crate::sim::solve::noise::NoiseRow;
use crate::sim::solve::predict::{Budget, Prediction, Predictor};
use crate::sim::solve::report::{RecommendedWeights, RunReport, WeightRow};
use crate::sim::solve::strategy::Strategy;
use crate::sim::stats::moments::Moments;

/// Whether a point's figures were run or predicted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum FigureSource {
    /// From a run at the point's own budget.
    Measured,
    /// Predicted from the noise components of a run at another budget.
    Predicted,
}

/// One point's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct PointFigures {
    /// Whether the figures were measured or predicted.
    pub source: FigureSource,
    /// The point's ray budget.
    pub budget: Budget,
    /// Iterations of the run behind the figures.
    pub iterations: u64,
    /// True until the point's run has succeeded with all its iterations.
    pub partial: bool,
    /// The honest rows of the noise table (the in-sample `optimal` row left out).
    pub noise_table: Vec<NoiseRow>,
    /// The recommended row at this point, if one could be recommended.
    pub recommended: Option<RecommendedWeights>,
    /// The recommended weights with their standard errors.
    pub weights: Vec<WeightRow>,
    /// Why there are no figures or no weights, if so.
    pub error: Option<String>,
    /// The rows of a predicted point whose figure its run does not support (RMS SE above
    /// `solve::predict::SUPPORT_RELATIVE_SE` of the RMS): never recommended, and not drawn by the
    /// dashboard. Empty for a measured point.
    #[serde(default)]
    pub unsupported: Vec<Strategy>,
}

/// The figures of a measured point from its run's report.
pub fn figures_of_report(report: &RunReport, budget: Budget, partial: bool) -> PointFigures {
    PointFigures {
        source: FigureSource::Measured,
        budget,
        iterations: report.iterations,
        partial,
        noise_table: report.noise_table.iter().filter(|r| !r.in_sample).cloned().collect(),
        recommended: report.recommended.clone(),
        weights: report.weights.clone(),
        error: report.solve_error.clone(),
        unsupported: Vec::new(),
    }
}

/// The figures of a predicted point.
pub fn figures_of_prediction(p: &Prediction, partial: bool) -> PointFigures {
    PointFigures {
        source: FigureSource::Predicted,
        budget: p.budget,
        iterations: p.iterations,
        partial,
        noise_table: p.noise_table.iter().filter(|r| !r.in_sample).cloned().collect(),
        recommended: p.recommended.clone(),
        weights: p.weights.clone(),
        error: p.solve_error.clone(),
        unsupported: p.unsupported.clone(),
    }
}

/// The figures of every point run `run` answers: its report for a measured point (or the direct
/// measurement of a predicted one, with `measure_predictions`), a prediction from its moments (one
/// [`Predictor`] for all of them) for a predicted one.
pub fn point_figures(
    plan: &SweepPlan,
    run: usize,
    moments: &Moments,
    grid: &CellGrid,
    report: &RunReport,
    partial: bool,
) -> Vec<(usize, PointFigures)> {
    let spec = &plan.runs[run].spec;
    let measured = Budget { light_paths: spec.light_paths, camera_paths: spec.camera_paths };
    let needs_predictor = plan.points.iter().any(|p| p.run == run && p.predicted.is_some());
    let predictor = needs_predictor.then(|| Predictor::new(moments, measured));
    let mut out = Vec::new();
    for p in &plan.points {
        if p.measured_run == Some(run) {
            out.push((p.index, figures_of_report(report, measured, partial)));
        }
        if p.run != run {
            continue;
        }
        let figures = match (p.predicted, &predictor) {
            (Some(to), Some(Ok(predictor))) => figures_of_prediction(&predictor.at(grid, &spec.solver, to), partial),
            (Some(to), Some(Err(e))) => PointFigures {
                source: FigureSource::Predicted,
                budget: to,
                iterations: moments.iterations(),
                partial,
                noise_table: Vec::new(),
                recommended: None,
                weights: Vec::new(),
                error: Some(e.to_string()),
                unsupported: Vec::new(),
            },
            _ => figures_of_report(report, measured, partial),
        };
        out.push((p.index, figures));
    }
    out
}

/// A point's figures: measured or predicted, and with `measure_predictions` the direct measurement
/// of a predicted point beside its prediction.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointResults {
    /// The point's figures (the prediction, for a predicted point); None until its run has some.
    pub figures: Option<PointFigures>,
    /// With `measure_predictions`, a predicted point's direct measurement.
    pub measured: Option<PointFigures>,
}

impl PointResults {
    /// Per point, the figures of [`point_figures`] calls (in any order).
    pub fn collect(plan: &SweepPlan, figures: impl IntoIterator<Item = (usize, PointFigures)>) -> Vec<Self> {
        let mut out = vec![Self::default(); plan.points.len()];
        for (p, f) in figures {
            let slot = &mut out[p];
            if plan.points[p].predicted.is_some() && f.source == FigureSource::Measured {
                slot.measured = Some(f);
            } else {
                slot.figures = Some(f);
            }
        }
        out
    }
}

/// One point and strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct SweepRow {
    /// The point's index in the sweep's expansion.
    pub point: usize,
    /// The swept fields' values at this point.
    #[cfg_attr(feature = "server", schema(value_type = Object))]
    pub values: Map<String, Value>,
    /// Whether the figures were measured or predicted.
    pub source: FigureSource,
    /// N_F of the point.
    pub light_paths: u64,
    /// N_B of the point.
    pub camera_paths: u64,
    /// Iterations behind the figures (fewer than the point's planned iterations while its run is
    /// partial) — the CSV's `iterations` column, by the same name (`iterations_done` is read too).
    #[serde(alias = "iterations_done")]
    pub iterations: u64,
    /// True until the point's run has succeeded with all its iterations.
    pub partial: bool,
    /// The noise-table row's strategy.
    pub strategy: Strategy,
    /// L in the model's units (docs/model.md).
    pub luminance: Option<f64>,
    /// The standard error of L.
    pub luminance_stderr: Option<f64>,
    /// RMS of one iteration, percent of L.
    pub rms_percent: Option<f64>,
    /// The standard error of the RMS%.
    pub rms_percent_stderr: Option<f64>,
    /// Whether the strategy keeps the solver's fixed weights (else it is shown for comparison).
    pub respects_fixed: bool,
    /// Whether this is the strategy whose weights the point recommends.
    pub recommended: bool,
    /// False for a predicted figure its run does not support (listed in the point's
    /// `unsupported`: RMS SE above `solve::predict::SUPPORT_RELATIVE_SE` of the RMS); always true
    /// for a measured one. A reader plotting the table leaves the unsupported figures out, as the
    /// dashboard does.
    #[serde(default = "supported_by_default")]
    pub supported: bool,
}

/// Tables written before the column existed held no unsupported rows' flag: a row was drawn.
fn supported_by_default() -> bool {
    true
}

/// The table of a sweep: one row per point (with figures) and strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct SweepTable {
    /// The swept fields, in the axes' order.
    pub fields: Vec<String>,
    /// Per point with figures, one row per noise-table row, in point order (a predicted point
    /// measured directly: its predicted rows, then its measured ones).
    pub rows: Vec<SweepRow>,
}

/// Columns every table has after the swept fields (a swept `light_paths` or `camera_paths` is
/// this column, not a second one).
const COLUMNS: [&str; 13] = [
    "source",
    "light_paths",
    "camera_paths",
    "iterations",
    "partial",
    "strategy",
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "respects_fixed",
    "recommended",
    "supported",
];

impl SweepTable {
    /// The table of `plan` from its points' figures (a point without any has no rows yet; a
    /// predicted point measured directly has its predicted rows, then its measured ones).
    pub fn build(plan: &SweepPlan, results: &[PointResults]) -> Self {
        let fields = plan.fields();
        let mut rows = Vec::new();
        let each = plan.points.iter().zip(results).flat_map(|(p, r)| [(p, &r.figures), (p, &r.measured)]);
        for (point, f) in each {
            let Some(f) = f else { continue };
            let values: Map<String, Value> = fields.iter().cloned().zip(point.values.iter().cloned()).collect();
            let chosen = f.recommended.as_ref().map(|r| r.strategy);
            for r in &f.noise_table {
                rows.push(SweepRow {
                    point: point.index,
                    values: values.clone(),
                    source: f.source,
                    light_paths: f.budget.light_paths,
                    camera_paths: f.budget.camera_paths,
                    iterations: f.iterations,
                    partial: f.partial,
                    strategy: r.strategy,
                    luminance: r.luminance,
                    luminance_stderr: r.luminance_stderr,
                    rms_percent: r.rms_percent,
                    rms_percent_stderr: r.rms_percent_stderr,
                    respects_fixed: r.respects_fixed,
                    recommended: Some(r.strategy) == chosen,
                    supported: !f.unsupported.contains(&r.strategy),
                });
            }
        }
        Self { fields, rows }
    }

    /// RFC 4180 CSV: `point`, one column per swept field (named by its path), then `COLUMNS`.
    /// Numbers in shortest round-trip form, empty for null; a swept value that is an object or an
    /// array is its JSON text.
    pub fn to_csv(&self) -> String {
        let swept: Vec<&String> = self.fields.iter().filter(|f| !COLUMNS.contains(&f.as_str())).collect();
        let mut csv = Csv::new(std::iter::once("point").chain(swept.iter().map(|s| s.as_str())).chain(COLUMNS));
        for r in &self.rows {
            let mut cells = vec![r.point.to_string()];
            cells.extend(swept.iter().map(|f| cell(r.values.get(f.as_str()).unwrap_or(&Value::Null))));
            cells.extend([
                json_cell(&r.source),
                r.light_paths.to_string(),
                r.camera_paths.to_string(),
                r.iterations.to_string(),
                r.partial.to_string(),
                json_cell(&r.strategy),
                number(r.luminance),
                number(r.luminance_stderr),
                number(r.rms_percent),
                number(r.rms_percent_stderr),
                r.respects_fixed.to_string(),
                r.recommended.to_string(),
                r.supported.to_string(),
            ]);
            csv.row(cells);
        }
        csv.finish()
    }
}
