//! The stored forms of a job: its spec as JSON, and its checkpoint — the moments' bytes and
//! checksum with the result document computed from them — encoded, and decoded with every check
//! that keeps a corrupted or foreign checkpoint from being resumed or served.

use super::documents::StrategyPoint;
use super::error::JobError;
use super::references::expected_luminances;
use super::resource::best_strategy;
use crate::sim::math::digest::sha256_hex;
use crate::sim::solve::report::{ReportInputs, build_report};
use crate::sim::spec::{JobSpec, ValidJob};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;
use crate::store::{Checkpoint, StoreError};

pub(crate) fn spec_json(spec: &JobSpec) -> Result<String, JobError> {
    serde_json::to_string(spec).map_err(|e| JobError::Internal(e.to_string()))
}

/// The moments of a checkpoint, verified: checksum, format and configuration must match the job,
/// and for a job's own run (`own_run`) the coverage must be the start of its range — or the
/// checkpoint is reported corrupted (never silently resumed from).
pub(crate) fn decode_checkpoint(
    id: i64,
    checkpoint: &Checkpoint,
    job: &ValidJob,
    own_run: bool,
) -> Result<Moments, JobError> {
    let corrupt = |detail: String| JobError::Store(StoreError::Corrupt { job: id, detail });
    let actual = sha256_hex(&checkpoint.moments);
    if actual != checkpoint.checksum {
        return Err(corrupt(format!(
            "checkpoint checksum mismatch (stored {}, computed {actual})",
            checkpoint.checksum
        )));
    }
    let moments: Moments = serde_json::from_slice(&checkpoint.moments)
        .map_err(|e| corrupt(format!("checkpoint moments unreadable: {e}")))?;
    moments.check_well_formed().map_err(|e| corrupt(format!("checkpoint moments: {e}")))?;
    // A job an earlier build started keeps its checkpoint's format (and resumes in it).
    if moments.fingerprint != job.config.fingerprint_of_format(moments.format_version) {
        return Err(corrupt("checkpoint moments belong to another configuration".into()));
    }
    if moments.iterations() != checkpoint.iterations_done {
        return Err(corrupt(format!(
            "checkpoint holds {} iterations, its row says {}",
            moments.iterations(),
            checkpoint.iterations_done
        )));
    }
    if own_run {
        let start = job.spec.iteration_range().start;
        let expected = Coverage::range(job.spec.seed, start, start + checkpoint.iterations_done);
        if moments.coverage != expected {
            return Err(corrupt(format!("checkpoint covers {:?}, expected {expected:?}", moments.coverage)));
        }
    }
    Ok(moments)
}

/// A checkpoint of `moments`: their bytes and checksum, and the result document computed from
/// them with the job's solver options.
pub(crate) fn checkpoint_of(moments: &Moments, job: &ValidJob, reference: Option<f64>) -> Result<Checkpoint, JobError> {
    let expected = expected_luminances(&job.config);
    let inputs = ReportInputs { reference, expected: Some(&expected), weights: None };
    let report = build_report(moments, &job.config.cells, &job.spec.solver, &inputs);
    let best = best_strategy(&report.noise_table, report.recommended.as_ref().map(|r| r.strategy));
    let bytes = serde_json::to_vec(moments).map_err(|e| JobError::Internal(e.to_string()))?;
    let history: Vec<StrategyPoint> = report
        .noise_table
        .iter()
        .map(|r| StrategyPoint { strategy: r.strategy, luminance: r.luminance, rms_percent: r.rms_percent })
        .collect();
    let internal = |e: serde_json::Error| JobError::Internal(e.to_string());
    Ok(Checkpoint {
        iterations_done: moments.iterations(),
        checksum: sha256_hex(&bytes),
        moments: bytes,
        result: serde_json::to_string(&report).map_err(internal)?,
        best: best.as_ref().and_then(|b| serde_json::to_string(b).ok()),
        warnings: Some(serde_json::to_string(&report.warnings).map_err(internal)?),
        history: serde_json::to_string(&history).map_err(internal)?,
    })
}
