//! Documents the job API returns besides the job resource: result envelopes, job lists and the
//! moments export.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::resource::{JobResource, JobState};
use crate::sim::checks::published::ReferenceTable;
use crate::sim::math::csv::{Csv, json_cell, number};
use crate::sim::solve::report::RunReport;
use crate::sim::solve::strategy::Strategy;

/// A job's results: the noise table and weights of the core's report, from the latest checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobResult {
    /// Id of the job these results belong to.
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations: the figures come from a
    /// checkpoint of a job that is still running, was cancelled or failed.
    pub partial: bool,
    /// The job's state when the results were read (a queued job may hold a checkpoint: an
    /// extended one).
    pub state: JobState,
    /// The published tables whose configuration this job has (the paper's Table 1 for the
    /// paper's scene, R, N_F and N_B; its optimum's row only with w0 fixed to 0), to read beside
    /// the noise table; empty otherwise. Also `GET /v1/references`.
    pub references: Vec<ReferenceTable>,
    /// The report of the latest checkpoint (noise table, recommendation, weights, gain,
    /// warnings), its fields inlined into this object.
    #[serde(flatten)]
    pub report: RunReport,
}

/// One page of the job list, newest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobList {
    /// The jobs of this page (at most `limit`, only those in `state` if it was given), newest
    /// (highest id) first.
    pub jobs: Vec<JobResource>,
    /// Pass as `cursor` to get the next page; null on the last page.
    pub next_cursor: Option<String>,
}

/// One strategy at one checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct StrategyPoint {
    /// The noise-table row (`plane1`, …, `optimal_cv`, …), as in the result's `noise_table`.
    pub strategy: Strategy,
    /// The row's luminance estimate L at this checkpoint: the mean per-iteration pixel value in
    /// the model's units (cross-fitted for fitted rows); null when the row could not be computed.
    pub luminance: Option<f64>,
    /// The row's RMS noise of one iteration at this checkpoint, in percent of L
    /// (100·std(C_s)/|L|); null when the row could not be computed.
    pub rms_percent: Option<f64>,
}

/// The strategies' figures at one point of a job's run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HistoryPoint {
    /// Iterations the figures are computed from.
    pub iterations: u64,
    /// At a checkpoint every row of its noise table, in the table's order; between checkpoints
    /// (a point every `--checkpoint-iterations`) the per-path rows only, whose figures are sums
    /// (a fitted row's figure needs a fit, made at the checkpoints).
    pub strategies: Vec<StrategyPoint>,
}

/// How a job's figures evolved: a point every `--checkpoint-iterations` (at most 1,000 points,
/// evenly thinned).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobHistory {
    /// Id of the job whose checkpoints these are.
    pub job_id: i64,
    /// The checkpoints' points, fewest iterations first (evenly thinned to at most 1,000); empty
    /// before the first checkpoint.
    pub points: Vec<HistoryPoint>,
}

impl JobHistory {
    /// The history as CSV: one row per checkpoint and strategy (`iterations`, `strategy`,
    /// `luminance` in the model's units, `luminance_stderr` = |L|·RMS/√M — the band the
    /// dashboard draws —, `rms_percent` of one iteration).
    pub fn to_csv(&self) -> String {
        let mut csv = Csv::new(["iterations", "strategy", "luminance", "luminance_stderr", "rms_percent"]);
        for p in &self.points {
            for s in &p.strategies {
                let stderr = s
                    .luminance
                    .zip(s.rms_percent)
                    .filter(|_| p.iterations > 0)
                    .map(|(l, rms)| l.abs() * rms / 100.0 / (p.iterations as f64).sqrt());
                csv.row([
                    p.iterations.to_string(),
                    json_cell(&s.strategy),
                    number(s.luminance),
                    number(stderr),
                    number(s.rms_percent),
                ]);
            }
        }
        csv.finish()
    }
}

/// Most points a history returns.
pub const MAX_HISTORY_POINTS: usize = 1000;
