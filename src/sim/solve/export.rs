//! The result document's tables as CSV (`GET /v1/jobs/{id}/result?format=csv`, `optimis report
//! --csv`): the noise table, one row per strategy (with the paper's figures where its Table 1
//! applies), and the weights table, one row per cell.
//!
//! Units: `luminance` (and its standard error) in the model's units (docs/model.md: the light's
//! radiance scale, as in the JSON); `rms_percent` in percent of L for one iteration; cell bounds in
//! the scene's lengths (r2, r3) and radians (φ); an open bound (the tail cell) is empty.

use super::noise::NoiseRow;
use super::report::WeightRow;
use super::strategy::Strategy;
use crate::sim::math::csv::{Csv, json_cell, number, quoted};

/// The noise table's columns.
const NOISE_COLUMNS: [&str; 14] = [
    "strategy",
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "lambda",
    "in_sample",
    "respects_fixed",
    "in_sample_luminance",
    "in_sample_luminance_stderr",
    "in_sample_rms_percent",
    "error",
    "paper_luminance",
    "paper_rms_percent",
];

/// The noise table as CSV; `paper` gives a row's published (L, RMS %) where a published table
/// applies to the job (`sim::checks::published`; empty cells otherwise).
pub fn noise_table_csv(rows: &[NoiseRow], paper: impl Fn(&Strategy) -> Option<(f64, f64)>) -> String {
    let mut csv = Csv::new(NOISE_COLUMNS);
    for r in rows {
        let published = paper(&r.strategy);
        csv.row([
            json_cell(&r.strategy),
            number(r.luminance),
            number(r.luminance_stderr),
            number(r.rms_percent),
            number(r.rms_percent_stderr),
            number(r.lambda),
            r.in_sample.to_string(),
            r.respects_fixed.to_string(),
            number(r.in_sample_luminance),
            number(r.in_sample_luminance_stderr),
            number(r.in_sample_rms_percent),
            r.error.as_deref().map(quoted).unwrap_or_default(),
            number(published.map(|p| p.0)),
            number(published.map(|p| p.1)),
        ]);
    }
    csv.finish()
}

/// The weights table's columns.
const WEIGHT_COLUMNS: [&str; 15] = [
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

/// The weights table as CSV, one row per cell in the document's order.
pub fn weights_csv(rows: &[WeightRow]) -> String {
    let mut csv = Csv::new(WEIGHT_COLUMNS);
    for (alpha, w) in rows.iter().enumerate() {
        csv.row([
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
