//! The result document's tables as CSV (`GET /v1/jobs/{id}/result?format=csv`, `optimis report
//! --csv`): the noise table, one row per strategy (with the paper's figures where its Table 1
//! applies), the weights table, one row per cell, and the effective weights, one row per (r2, r3)
//! bin (what a per-path recommendation, which has no table, gives instead).
//!
//! Column names and units follow docs/csv.md, one vocabulary for every table: `luminance` (and its
//! standard error) in the model's units (docs/model.md: the light's radiance scale, as in the
//! JSON); `rms_percent` in percent of L for one iteration; cell bounds in the scene's lengths (r2,
//! r3) and radians (φ); an open bound (the tail cell) is empty.

use super::effective::EffectiveWeights;
use super::report::RunReport;
use super::strategy::Strategy;
use crate::sim::math::csv::{Csv, json_cell, number, quoted};

/// The noise table's columns, in the vocabulary of docs/csv.md (the dashboard writes the same).
const NOISE_COLUMNS: [&str; 25] = [
    "strategy",
    "paper_case",
    "luminance",
    "luminance_stderr",
    "expected_luminance",
    "z",
    "tail_missing",
    "expected_error",
    "reference_luminance",
    "rms_percent",
    "rms_percent_stderr",
    "lambda",
    "in_sample",
    "respects_fixed",
    "unstable",
    "deviation",
    "beyond_trust_region",
    "recommended",
    "heuristics",
    "in_sample_luminance",
    "in_sample_luminance_stderr",
    "in_sample_rms_percent",
    "paper_luminance",
    "paper_rms_percent",
    "error",
];

/// A row's columns from a published table (`sim::checks::published`): its case number in the
/// paper, and the published (L, RMS %) where the table applies to the job.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PaperColumns {
    /// The paper's case number of the row (whether or not its figures apply to this job).
    pub case: Option<u32>,
    /// The published L and RMS%, where the table applies.
    pub figures: Option<(f64, f64)>,
}

/// The report's noise table as CSV, one row per strategy; `paper` gives a row's published columns.
pub fn noise_table_csv(report: &RunReport, paper: impl Fn(&Strategy) -> PaperColumns) -> String {
    let mut csv = Csv::new(NOISE_COLUMNS);
    for row in noise_rows(report, paper) {
        csv.row(row);
    }
    csv.finish()
}

/// The columns that say which job a row of a comparison is (docs/csv.md, "compare").
pub const JOB_COLUMNS: [&str; 10] = [
    "job_id",
    "preset",
    "illumination",
    "spot_a",
    "engine",
    "light_paths",
    "camera_paths",
    "merge_radius",
    "iterations",
    "seed",
];

/// Jobs' noise tables as one CSV, one row per job and strategy, each job's [`JOB_COLUMNS`] cells
/// (already formatted) in front: the dashboard's compare table, from the server.
pub fn compare_csv<'a>(
    jobs: impl IntoIterator<Item = ([String; 10], &'a RunReport, Box<dyn Fn(&Strategy) -> PaperColumns + 'a>)>,
) -> String {
    let mut csv = Csv::new(JOB_COLUMNS.into_iter().chain(NOISE_COLUMNS));
    for (job, report, paper) in jobs {
        for row in noise_rows(report, paper) {
            csv.row(job.iter().cloned().chain(row));
        }
    }
    csv.finish()
}

/// The cells of each row of the report's noise table, in [`NOISE_COLUMNS`]' order.
fn noise_rows(report: &RunReport, paper: impl Fn(&Strategy) -> PaperColumns) -> Vec<Vec<String>> {
    let mut rows = Vec::with_capacity(report.noise_table.len());
    let chosen = report.recommended.as_ref().map(|r| r.strategy);
    for r in &report.noise_table {
        let published = paper(&r.strategy);
        // β of a stacked row as JSON: one cell, so that the table keeps one row per strategy.
        let heuristics = if r.heuristics.is_empty() {
            String::new()
        } else {
            serde_json::to_string(&r.heuristics).map(|s| quoted(&s)).unwrap_or_default()
        };
        rows.push(vec![
            json_cell(&r.strategy),
            published.case.map(|c| c.to_string()).unwrap_or_default(),
            number(r.luminance),
            number(r.luminance_stderr),
            number(r.expected_luminance),
            number(r.z),
            r.tail_missing.to_string(),
            r.expected_error.as_deref().map(quoted).unwrap_or_default(),
            number(report.reference_luminance),
            number(r.rms_percent),
            number(r.rms_percent_stderr),
            number(r.lambda),
            r.in_sample.to_string(),
            r.respects_fixed.to_string(),
            r.unstable.to_string(),
            number(r.deviation),
            r.beyond_trust_region.to_string(),
            (Some(r.strategy) == chosen).to_string(),
            heuristics,
            number(r.in_sample_luminance),
            number(r.in_sample_luminance_stderr),
            number(r.in_sample_rms_percent),
            number(published.figures.map(|p| p.0)),
            number(published.figures.map(|p| p.1)),
            r.error.as_deref().map(quoted).unwrap_or_default(),
        ]);
    }
    rows
}

/// The weights table's columns: which table it is first (as the dashboard writes them), then the
/// cell.
const WEIGHT_COLUMNS: [&str; 18] = [
    "table",
    "strategy",
    "lambda",
    "cell",
    "r2_lo",
    "r2_hi",
    "r3_lo",
    "r3_hi",
    "phi_lo_rad",
    "phi_hi_rad",
    "w0",
    "w0_stderr",
    "w1",
    "w1_stderr",
    "w2",
    "w2_stderr",
    "samples",
    "status",
];

/// Which table a report's `weights` are, for the `table` column: `recommended` (a table alone),
/// `recommended_table_part` (the table of a stack: a path's weights add Σ β · heuristic, the β in
/// the JSON and the weights artifact), or `fit_at_lambda_not_recommended` (a table asked for at a
/// λ, fitted in-sample).
pub fn weights_table_label(report: &RunReport) -> &'static str {
    let recommended = report.recommended.as_ref();
    match (&report.weights_fit, recommended) {
        (Some(fit), Some(r)) if fit.strategy == r.strategy && Some(fit.lambda) == r.lambda => {
            if r.heuristics.is_empty() { "recommended" } else { "recommended_table_part" }
        }
        _ => "fit_at_lambda_not_recommended",
    }
}

/// The weights table as CSV, one row per cell in the document's order (empty of rows when the
/// report has no table: a per-path recommendation — [`effective_csv`] is its CSV).
pub fn weights_csv(report: &RunReport) -> String {
    let mut csv = Csv::new(WEIGHT_COLUMNS);
    let table = weights_table_label(report);
    let strategy = report.weights_fit.as_ref().map(|f| f.strategy.name().to_string()).unwrap_or_default();
    let lambda = number(report.weights_fit.as_ref().map(|f| f.lambda));
    for (alpha, w) in report.weights.iter().enumerate() {
        csv.row([
            table.to_string(),
            strategy.clone(),
            lambda.clone(),
            alpha.to_string(),
            number(w.r2[0]),
            number(w.r2[1]),
            number(w.r3[0]),
            number(w.r3[1]),
            number(w.phi[0]),
            number(w.phi[1]),
            w.w0.to_string(),
            number(w.w0_stderr),
            w.w1.to_string(),
            number(w.w1_stderr),
            w.w2.to_string(),
            number(w.w2_stderr),
            w.samples.to_string(),
            json_cell(&w.status),
        ]);
    }
    csv.finish()
}

/// The effective weights' columns (docs/csv.md).
const EFFECTIVE_COLUMNS: [&str; 23] = [
    "table",
    "strategy",
    "kind",
    "paths_per_side",
    "r2_lo",
    "r2_hi",
    "r3_lo",
    "r3_hi",
    "paths",
    "luminance_share",
    "w0",
    "w0_stderr",
    "w1",
    "w1_stderr",
    "w2",
    "w2_stderr",
    "w0_sampling_stderr",
    "w1_sampling_stderr",
    "w2_sampling_stderr",
    "w0_fit_stderr",
    "w1_fit_stderr",
    "w2_fit_stderr",
    "note",
];

/// Effective weights as CSV, one row per (r2, r3) bin: `table` is `effective`, the weights are
/// averages over the bin's paths (not a lookup table: the weight function itself is the weights
/// artifact), empty where no sampled path of the bin carries light.
pub fn effective_csv(effective: &EffectiveWeights) -> String {
    let mut csv = Csv::new(EFFECTIVE_COLUMNS);
    let at = |v: Option<[f64; 3]>, m: usize| number(v.map(|v| v[m]));
    for b in &effective.bins {
        let note = if b.w.is_none() { "no sampled path of this bin carries light" } else { "" };
        csv.row([
            "effective".to_string(),
            effective.strategy.clone(),
            effective.kind.clone(),
            effective.paths_per_side.to_string(),
            number(b.r2[0]),
            number(b.r2[1]),
            number(b.r3[0]),
            number(b.r3[1]),
            b.paths.to_string(),
            b.luminance_share.to_string(),
            at(b.w, 0),
            at(b.stderr, 0),
            at(b.w, 1),
            at(b.stderr, 1),
            at(b.w, 2),
            at(b.stderr, 2),
            at(b.sampling_stderr, 0),
            at(b.sampling_stderr, 1),
            at(b.sampling_stderr, 2),
            at(b.fit_stderr, 0),
            at(b.fit_stderr, 1),
            at(b.fit_stderr, 2),
            quoted(note),
        ]);
    }
    csv.finish()
}
