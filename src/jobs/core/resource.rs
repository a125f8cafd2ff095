//! What a job looks like from outside: its state machine, its progress and the job resource that the
//! API returns and the event stream sends.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::JobError;
use super::executor::ExecutionView;
use crate::sim::solve::noise::NoiseRow;
use crate::sim::solve::strategy::Strategy;
use crate::sim::solve::warnings::Warning;
use crate::sim::spec::JobSpec;
use crate::store::JobRow;

pub use crate::store::JobState;

/// The strategy to show as "best" so far: at a checkpoint, the recommended row; between
/// checkpoints, the per-path strategy with the lowest RMS among those that keep the fixed weights
/// (the in-sample `optimal` row is optimistic and never shown).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct BestStrategy {
    /// The noise-table row: the recommended one when the checkpoint names one, otherwise the
    /// honest row with the lowest RMS that keeps the solver's fixed weights.
    pub strategy: Strategy,
    /// Its luminance estimate L, the mean per-iteration pixel value in the model's units (the
    /// paper's scene: about 26·10⁻⁵).
    pub luminance: f64,
    /// Its RMS noise of one iteration in percent of L, 100·std(C_s)/|L| (cross-fitted for a
    /// fitted row); always positive.
    pub rms_percent: f64,
}

/// How far a job has come.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Progress {
    /// Iterations computed (in memory while running).
    pub iterations_done: u64,
    /// Iterations the job runs to: its `iterations` (the shard's range for a shard), raised by
    /// `extend`; for a merged job, the iterations it holds.
    pub iterations_total: u64,
    /// Iterations held by the latest checkpoint (what `result` reports and a restart resumes from).
    pub iterations_checkpointed: u64,
    /// Recent throughput while running.
    pub light_paths_per_second: Option<f64>,
    /// Estimated seconds to completion while running.
    pub eta_seconds: Option<f64>,
    /// The best strategy so far: at a checkpoint the recommended row; between checkpoints while
    /// running, the best per-path row of the iterations in memory. Null before any figures.
    pub best: Option<BestStrategy>,
}

/// A job as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobResource {
    /// The job's id, as in `/v1/jobs/{id}`.
    pub id: i64,
    /// Where the job is in its life cycle: `queued → running → succeeded | failed | cancelled`
    /// (`extend` queues a succeeded or cancelled job again).
    pub state: JobState,
    /// The job's specification, fully resolved: the preset applied and every field explicit
    /// (`iterations` raised by `extend`).
    pub spec: JobSpec,
    /// RFC 3339, UTC.
    pub created_at: String,
    /// RFC 3339, UTC.
    pub updated_at: String,
    /// Iterations done, checkpointed and planned, throughput, ETA and the best strategy so far.
    pub progress: Progress,
    /// Why the job failed.
    pub error: Option<String>,
    /// Configuration fingerprint (moments merge only between equal fingerprints).
    pub fingerprint: String,
    /// Quadrature value of the expected luminance; null when the quadrature did not converge
    /// within its evaluation budget (extreme geometry).
    pub reference_luminance: Option<f64>,
    /// True when the job holds statistics merged from other runs (shards, peers, documents);
    /// such a job is complete and cannot be extended.
    pub merged: bool,
    /// The sweep this job is a run of (`GET /v1/sweeps/{id}`), if any.
    pub sweep_id: Option<i64>,
    /// What the data of the latest checkpoint cannot support (see the result's `warnings`).
    pub warnings: Vec<Warning>,
    /// On a server that runs jobs on a cluster (`--executor slurm`), while the job runs: its
    /// tasks, each with its id in the batch system, state, iterations and log. Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub execution: Option<ExecutionView>,
    /// For a job holding merged statistics (a study, or a job that took merges): each source —
    /// a peer URL, a document, the job's own iterations — with the seeds and iterations it
    /// brought, and every seed held. Absent for a job that merged nothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<super::lineage::MergeProvenance>,
}

/// Unix milliseconds now.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}

/// RFC 3339 (UTC, milliseconds) of unix milliseconds.
pub fn rfc3339(ms: i64) -> String {
    let t = time::OffsetDateTime::from_unix_timestamp_nanos(i128::from(ms) * 1_000_000)
        .unwrap_or(time::OffsetDateTime::UNIX_EPOCH);
    let format =
        time::macros::format_description!("[year]-[month]-[day]T[hour]:[minute]:[second].[subsecond digits:3]Z");
    t.format(&format).unwrap_or_default()
}

/// The spec stored with a job.
pub(in crate::jobs) fn parse_stored_spec(row: &JobRow) -> Result<JobSpec, JobError> {
    serde_json::from_str(&row.spec)
        .map_err(|e| JobError::Internal(format!("stored spec of job {} is unreadable: {e}", row.id)))
}

/// The resource of a job that is not active, from its row.
pub(in crate::jobs) fn resource_from_row(row: &JobRow) -> Result<JobResource, JobError> {
    Ok(JobResource {
        id: row.id,
        state: row.state,
        spec: parse_stored_spec(row)?,
        created_at: rfc3339(row.created_at),
        updated_at: rfc3339(row.updated_at),
        progress: Progress {
            iterations_done: row.iterations_done,
            iterations_total: row.iterations_total,
            iterations_checkpointed: row.iterations_done,
            light_paths_per_second: None,
            eta_seconds: None,
            best: row.best.as_deref().and_then(|b| serde_json::from_str(b).ok()),
        },
        error: row.error.clone(),
        fingerprint: row.fingerprint.clone(),
        reference_luminance: row.reference_luminance,
        merged: row.merged,
        sweep_id: row.sweep_id,
        warnings: row.warnings.as_deref().and_then(|w| serde_json::from_str(w).ok()).unwrap_or_default(),
        execution: None,
        provenance: row.provenance.as_deref().and_then(|p| serde_json::from_str(p).ok()),
    })
}

/// The recommended row's figures when the report names one (`recommended`, chosen with its guard:
/// docs/model.md §10); otherwise — between checkpoints, where only the per-path rows are computed
/// — the row with the lowest RMS among `rows` whose figures are honest and whose weights keep the
/// solver's fixed weights (the in-sample `optimal` row and heuristics that use merges the fixed
/// weights exclude are left out).
pub(crate) fn best_strategy(rows: &[NoiseRow], recommended: Option<Strategy>) -> Option<BestStrategy> {
    rows.iter()
        .filter(|r| recommended.is_none_or(|s| r.strategy == s))
        .filter(|r| !r.in_sample && r.respects_fixed)
        .filter_map(|r| match (r.luminance, r.rms_percent) {
            (Some(l), Some(rms)) if rms > 0.0 => {
                Some(BestStrategy { strategy: r.strategy, luminance: l, rms_percent: rms })
            }
            _ => None,
        })
        .min_by(|a, b| a.rms_percent.total_cmp(&b.rms_percent))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_follows_the_recommendation_or_leaves_out_in_sample_and_outside_rows() {
        use crate::sim::solve::strategy::Strategy;
        let row = |strategy, rms, in_sample, respects_fixed| NoiseRow {
            in_sample,
            respects_fixed,
            ..NoiseRow::from_sums(strategy, 4.0, 4.0, 4.0 * (1.0 + 0.75 * rms * rms), None)
        };
        let rows = [
            row(Strategy::Switch, 3.0, false, true),
            row(Strategy::Optimal, 1.0, true, true),
            row(Strategy::OptimalCv, 2.0, false, true),
            row(Strategy::CorrelationAware, 0.5, false, false),
        ];
        assert!(rows[3].rms_percent < rows[2].rms_percent && rows[1].rms_percent < rows[2].rms_percent);
        assert_eq!(best_strategy(&rows, None).unwrap().strategy, Strategy::OptimalCv);
        assert_eq!(
            best_strategy(&rows, Some(Strategy::Switch)).unwrap().strategy,
            Strategy::Switch,
            "the recommendation"
        );
    }

    #[test]
    fn timestamps_are_rfc3339_utc() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(rfc3339(1_795_000_000_123), "2026-11-18T11:06:40.123Z"); // checked with Python's datetime
    }
}
