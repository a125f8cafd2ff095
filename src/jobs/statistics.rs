//! Statistics of stored jobs: results and histories, re-solves with other solver options, and the
//! moments export — each read from the latest checkpoint, verified against its checksum. The
//! weights artifacts (`artifacts`), evaluations of given weights (`evaluation`), solves and
//! predictions are services of their own that read through this one.

use std::sync::Arc;

use serde_json::Value;

use super::core::checkpoint::{checked_result, decode_checkpoint, no_checkpoint};
use super::core::documents::{HistoryPoint, JobHistory, JobResult, MAX_HISTORY_POINTS};
use super::core::error::JobError;
use super::core::manager::JobManager;
use super::core::references::expected_luminances;
use super::core::resource::JobState;
use crate::sim::checks::published::applicable;
use crate::sim::document::{Attestation, AttestationBasis, MomentsDocument, merged_spec};
use crate::sim::model::config::SimConfig;
use crate::sim::model::params::check;
use crate::sim::solve::options::MAX_LAMBDA;
use crate::sim::solve::radius_reports::radius_reports;
use crate::sim::solve::report::{ReportInputs, RunReport, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::ValidJob;
use crate::sim::stats::moments::Moments;
use crate::trust::signing::Provenance;

/// A job's latest statistics, read once through [`Statistics::latest`].
pub(super) struct Latest {
    /// The job's state when read.
    pub state: JobState,
    /// True unless the job succeeded with all its iterations (`JobResult::partial`).
    pub partial: bool,
    /// Whether the job holds merged statistics (its spec then says how many iterations).
    pub merged: bool,
    /// The job's R → 0 reference luminance, when its quadrature converged.
    pub reference: Option<f64>,
    /// The job's specification, validated.
    pub job: ValidJob,
    /// The latest checkpoint's moments, verified.
    pub moments: Moments,
}

/// The statistics of stored jobs; cheap to clone.
#[derive(Clone)]
pub struct Statistics {
    pub(super) jobs: JobManager,
    /// The signing key for exports and the keys merges require (`crate::trust::signing`).
    pub(super) provenance: Arc<Provenance>,
}

impl Statistics {
    /// The statistics of `jobs`' jobs; exports are signed with `provenance`.
    pub fn new(jobs: JobManager, provenance: Arc<Provenance>) -> Self {
        Self { jobs, provenance }
    }

    /// The lifecycle these statistics belong to.
    pub fn jobs(&self) -> &JobManager {
        &self.jobs
    }

    /// The results of the latest checkpoint. Its moments are verified against their checksum when
    /// this checkpoint is first served and again once the last verification is older than
    /// [`REVERIFY_AFTER`](super::core::checkpoint::REVERIFY_AFTER) (a corrupted checkpoint answers 409, not a stale result); the reads in
    /// between read the result alone, as a dashboard or a load polls it many times a second.
    pub async fn result(&self, id: i64) -> Result<JobResult, JobError> {
        let resource = self.jobs.get(id).await?;
        let (state, total) = (resource.state, resource.progress.iterations_total);
        let stored = self.jobs.store().checkpoints().load_result(id).await?.ok_or_else(|| no_checkpoint(id))?;
        let known = self.jobs.recently_verified(id, &stored.checksum);
        let (done, json, result_checksum) = if known {
            (stored.iterations_done, stored.result, stored.result_checksum)
        } else {
            let checkpoint = self.jobs.verified_checkpoint(id).await?;
            (checkpoint.iterations_done, checkpoint.result, checkpoint.result_checksum)
        };
        let report: RunReport =
            self.jobs.compute(move || checked_result(id, &json, result_checksum.as_deref())).await??;
        let references = applicable(&resource.spec);
        Ok(JobResult {
            job_id: id,
            partial: !(state == JobState::Succeeded && done >= total),
            state,
            references,
            report,
        })
    }

    /// Each strategy's figures at every checkpoint (thinned to at most 1,000 points; the store
    /// keeps at most ~2,000 per job).
    pub async fn history(&self, id: i64) -> Result<JobHistory, JobError> {
        self.jobs.get(id).await?;
        let rows = self.jobs.store().history().load(id, MAX_HISTORY_POINTS).await?;
        let points = self
            .jobs
            .compute(move || {
                rows.into_iter()
                    .map(|(iterations, json)| {
                        serde_json::from_str(&json)
                            .map(|strategies| HistoryPoint { iterations, strategies })
                            .map_err(|e| JobError::Internal(format!("stored history of job {id} is unreadable: {e}")))
                    })
                    .collect::<Result<Vec<_>, _>>()
            })
            .await??;
        Ok(JobHistory { job_id: id, points })
    }

    /// The one door from a stored job to its statistics: the job's state, its specification
    /// validated once, and its latest checkpoint's moments verified against their checksum (and,
    /// for a job's own run, against the range it ran) — decoded on the request pool. Everything
    /// that computes on a job's statistics (re-solves, evaluations, predictions, exports, sweep
    /// figures) starts here.
    pub(super) async fn latest(&self, id: i64) -> Result<Latest, JobError> {
        let resource = self.jobs.get(id).await?;
        let checkpoint = self.jobs.store().checkpoints().load(id).await?.ok_or_else(|| no_checkpoint(id))?;
        let (spec, merged) = (resource.spec, resource.merged);
        let (job, moments, iterations) = self
            .jobs
            .compute(move || -> Result<_, JobError> {
                let job = spec.validate()?;
                let moments = decode_checkpoint(id, &checkpoint, &job, !merged)?;
                Ok((job, moments, checkpoint.iterations_done))
            })
            .await??;
        let partial = !(resource.state == JobState::Succeeded && iterations >= resource.progress.iterations_total);
        Ok(Latest { state: resource.state, partial, merged, reference: resource.reference_luminance, job, moments })
    }

    /// Re-solves the latest checkpoint with other solver options (a merge patch on the job's
    /// `solver`), without running anything or storing anything; with `weights_lambda`, the weights
    /// table is the in-sample fit at that λ instead of the recommended weights.
    pub async fn solve(&self, id: i64, patch: &Value, weights_lambda: Option<f64>) -> Result<JobResult, JobError> {
        if let Some(l) = weights_lambda {
            check(l.is_finite() && (0.0..=MAX_LAMBDA).contains(&l), "lambda", || {
                format!("must be in [0, {MAX_LAMBDA:e}], got {l}")
            })?;
        }
        let resource = self.jobs.get(id).await?;
        let solver = resource.spec.solver.patched(patch)?;
        // The published rows that apply to the options solved with (the optimum's needs w0 = 0).
        let mut spec = resource.spec;
        spec.solver = solver.clone();
        let references = applicable(&spec);
        let Latest { state, partial, reference, job, moments, .. } = self.latest(id).await?;
        let report = self
            .jobs
            .compute_heavy(move |_| -> RunReport {
                let weights = weights_lambda.map(|lambda| WeightsQuery { lambda, strategy: Strategy::Optimal });
                let expected = expected_luminances(job.config());
                let inputs = ReportInputs { reference, expected: Some(&expected), weights };
                let mut report = build_report(&moments, &job.config().cells, &solver, &inputs);
                if !job.config().radii().is_empty() {
                    let expected = |c: &SimConfig| expected_luminances(c).to_vec();
                    report.radii = radius_reports(job.config(), &moments, &solver, reference, &expected, Some(&report));
                }
                report
            })
            .await?;
        Ok(JobResult { job_id: id, partial, state, references, report })
    }

    /// What this server's signature on job `id`'s statistics may vouch for: a job that merged
    /// nothing was computed here; a merged one only if every source was computed here or signed by
    /// a trusted key (`MergeProvenance::attestation`). None: exports go unsigned.
    pub(super) async fn attestation(&self, id: i64) -> Result<Option<Attestation>, JobError> {
        let resource = self.jobs.get(id).await?;
        let attests = match &resource.provenance {
            None if !resource.merged => Some(Attestation { basis: AttestationBasis::Computed, keys: Vec::new() }),
            None => None,
            Some(lineage) => lineage.attestation(),
        };
        if attests.is_none() && self.provenance.key.is_some() {
            tracing::info!(
                job = id,
                "exported unsigned: it holds statistics merged from sources no trusted key signed"
            );
        }
        Ok(attests)
    }

    /// The latest checkpoint's moments as a portable, checksummed document (its canonical JSON
    /// text, made on the request pool), signed if this server has a signing key. A merged job's
    /// spec says how many iterations it holds (and no shard), so that its document verifies.
    pub async fn moments_json(&self, id: i64) -> Result<Vec<u8>, JobError> {
        let attests = self.attestation(id).await?;
        let Latest { merged, job, moments, .. } = self.latest(id).await?;
        let provenance = self.provenance.clone();
        self.jobs
            .compute(move || {
                let spec = if merged { merged_spec(job.spec(), &moments) } else { job.spec().clone() };
                let doc = MomentsDocument::new(spec, moments);
                match attests {
                    Some(attests) => provenance.sign(doc, attests),
                    None => doc,
                }
                .to_json()
            })
            .await
    }
}
