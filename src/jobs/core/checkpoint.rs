//! The stored forms of a job: its spec as JSON, and its checkpoint — the moments' bytes and
//! checksum with the result document computed from them — encoded, and decoded with every check
//! that keeps a corrupted or foreign checkpoint from being resumed or served; and the memory of
//! which checkpoints were verified lately (`Verified`, `verified_checkpoint`), so that a
//! result polled many times a second is not re-hashed each time.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::compute::Pools;

use super::documents::StrategyPoint;
use super::error::JobError;
use super::references::expected_luminances;
use super::resource::best_strategy;
use crate::sim::math::digest::sha256_hex;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::radius_reports::radius_reports;
use crate::sim::solve::report::{ReportInputs, build_report};
use crate::sim::spec::{JobSpec, ValidJob};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;
use crate::sim::stats::well_formed::{belongs_to, check_well_formed};
use crate::store::{Checkpoint, Store, StoreError};

/// How long a verification of a job's stored moments stands: a result read after it hashes them
/// again. One hash (milliseconds for a paper-sized checkpoint) per job per second, however many
/// reads a dashboard or a load makes, and a checkpoint corrupted under a running server is
/// reported within a second rather than never.
pub const REVERIFY_AFTER: Duration = Duration::from_secs(1);

/// Most jobs whose verified checkpoint checksum is remembered (beyond it the memory starts over).
const MAX_VERIFIED: usize = 100_000;

/// The checkpoint checksum of each job whose stored moments were last verified against it, and
/// when: a result request re-hashes the moments only when the checkpoint changed since or
/// [`REVERIFY_AFTER`] passed (the stored bytes can still rot or be edited under a running server).
#[derive(Default)]
pub(crate) struct Verified {
    /// std Mutex: map operations only, never held across an `.await`.
    map: Mutex<HashMap<i64, (String, Instant)>>,
}

impl Verified {
    /// Records that job `id`'s stored moments match `checksum`.
    pub(crate) fn remember(&self, id: i64, checksum: &str) {
        let mut map = self.map.lock().expect("verified map");
        if map.len() >= MAX_VERIFIED {
            map.clear();
        }
        map.insert(id, (checksum.to_string(), Instant::now()));
    }

    /// Whether job `id`'s stored moments were verified against `checksum` less than
    /// [`REVERIFY_AFTER`] ago.
    pub(crate) fn recently(&self, id: i64, checksum: &str) -> bool {
        let map = self.map.lock().expect("verified map");
        map.get(&id).is_some_and(|(c, at)| c == checksum && at.elapsed() < REVERIFY_AFTER)
    }
}

/// Job `id`'s latest checkpoint, its checksum verified on the request pool (and remembered in
/// `verified`): a corrupted checkpoint is reported (409), never served or resumed from.
pub(crate) async fn verified_checkpoint(
    store: &Store,
    pools: &Pools,
    verified: &Verified,
    id: i64,
) -> Result<Checkpoint, JobError> {
    let checkpoint = store.checkpoints().load(id).await?.ok_or_else(|| no_checkpoint(id))?;
    let checkpoint = pools
        .light(move || {
            let actual = sha256_hex(&checkpoint.moments);
            if actual == checkpoint.checksum {
                Ok(checkpoint)
            } else {
                Err(JobError::Store(StoreError::Corrupt {
                    job: id,
                    detail: format!("checkpoint checksum mismatch (stored {}, computed {actual})", checkpoint.checksum),
                }))
            }
        })
        .await??;
    verified.remember(id, &checkpoint.checksum);
    Ok(checkpoint)
}

/// A stored result document, checked against its own checksum (a row written before that was
/// kept has none until the start that fills it in) and parsed: an edited or garbled one is
/// reported corrupted (409), never served. CPU work: on the request pool.
pub(crate) fn checked_result<T: serde::de::DeserializeOwned>(
    id: i64,
    result: &str,
    result_checksum: Option<&str>,
) -> Result<T, JobError> {
    let corrupt = |detail: String| JobError::Store(StoreError::Corrupt { job: id, detail });
    if let Some(stored) = result_checksum {
        let actual = sha256_hex(result.as_bytes());
        if actual != stored {
            return Err(corrupt(format!("result checksum mismatch (stored {stored}, computed {actual})")));
        }
    }
    serde_json::from_str(result).map_err(|e| corrupt(format!("stored result unreadable: {e}")))
}

/// The refusal of a job that has no checkpoint yet.
pub(crate) fn no_checkpoint(id: i64) -> JobError {
    JobError::Conflict(format!("job {id} has no checkpoint yet: results appear after its first checkpoint"))
}

/// A spec as the JSON text the store keeps.
pub(crate) fn spec_json(spec: &JobSpec) -> Result<String, JobError> {
    serde_json::to_string(spec).map_err(|e| JobError::Internal(e.to_string()))
}

/// The moments of a checkpoint, verified: checksum, format and configuration must match the job,
/// and for a job's own run (`own_run`) the coverage must lie within its range — or the
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
    check_well_formed(&moments).map_err(|e| corrupt(format!("checkpoint moments: {e}")))?;
    // A job an earlier build started keeps its checkpoint's format (and resumes in it).
    if !belongs_to(&moments, job.config()) {
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
        // Within the job's range: its start for a run on the local pool, any of its iterations
        // for one on a cluster (whose tasks finish in any order).
        let range = job.spec().iteration_range();
        let expected = Coverage::range(job.spec().seed, range.start, range.end);
        if !moments.coverage.is_within(&expected) {
            return Err(corrupt(format!("checkpoint covers {:?}, outside {expected:?}", moments.coverage)));
        }
    }
    Ok(moments)
}

/// A checkpoint of `moments`: their bytes and checksum, and the result document computed from
/// them with the job's solver options.
pub(crate) fn checkpoint_of(moments: &Moments, job: &ValidJob, reference: Option<f64>) -> Result<Checkpoint, JobError> {
    let expected = expected_luminances(job.config());
    let inputs = ReportInputs { reference, expected: Some(&expected), weights: None };
    let mut report = build_report(moments, &job.config().cells, &job.spec().solver, &inputs);
    if !job.config().radii().is_empty() {
        let at = |c: &SimConfig| expected_luminances(c).to_vec();
        report.radii = radius_reports(job.config(), moments, &job.spec().solver, reference, &at, Some(&report));
    }
    let best = best_strategy(&report.noise_table, report.recommended.as_ref().map(|r| r.strategy));
    let bytes = serde_json::to_vec(moments).map_err(|e| JobError::Internal(e.to_string()))?;
    let history: Vec<StrategyPoint> = report
        .noise_table
        .iter()
        .map(|r| StrategyPoint { strategy: r.strategy, luminance: r.luminance, rms_percent: r.rms_percent })
        .collect();
    let internal = |e: serde_json::Error| JobError::Internal(e.to_string());
    let result = serde_json::to_string(&report).map_err(internal)?;
    Ok(Checkpoint {
        iterations_done: moments.iterations(),
        checksum: sha256_hex(&bytes),
        moments: bytes,
        result_checksum: Some(sha256_hex(result.as_bytes())),
        result,
        best: best.as_ref().and_then(|b| serde_json::to_string(b).ok()),
        warnings: Some(serde_json::to_string(&report.warnings).map_err(internal)?),
        history: serde_json::to_string(&history).map_err(internal)?,
        between: Vec::new(),
    })
}
