//! A job's weight function as a portable artifact (`GET /v1/jobs/{id}/weights`, `sim::weights`):
//! its recommended row's (or any row's) weights from the latest checkpoint, with the scene and the
//! heuristics' definitions, signed where this server signs (over the artifact's canonical bytes,
//! vouching exactly as its moments export does); and the same row's effective weights per (r2, r3)
//! bin (`GET /v1/jobs/{id}/effective`, what Fig. 2 draws).

use super::core::error::JobError;
use super::core::references::{expected_luminances, scene_reference};
use super::statistics::{Latest, Statistics};
use crate::sim::solve::effective::EffectiveWeights;
use crate::sim::solve::report::ReportInputs;
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::{SpecError, ValidJob};
use crate::sim::weights::artifact::WeightsArtifact;
use crate::sim::weights::build::artifact_of_moments;
use crate::sim::weights::effective::effective_of_moments;

/// The weights artifacts and effective weights of stored jobs; cheap to clone.
#[derive(Clone)]
pub struct Artifacts {
    statistics: Statistics,
}

impl Artifacts {
    /// The artifacts of the jobs `statistics` reads.
    pub fn new(statistics: Statistics) -> Self {
        Self { statistics }
    }

    /// The artifact of job `id`'s row `strategy` (none: its recommended row) from its latest
    /// checkpoint. CPU work (a report, maybe a refit): on the heavy pool.
    pub async fn weights(&self, id: i64, strategy: Option<Strategy>) -> Result<WeightsArtifact, JobError> {
        let attests = self.statistics.attestation(id).await?;
        let Latest { job, moments, .. } = self.statistics.latest(id).await?;
        let provenance = self.statistics.provenance.clone();
        self.statistics
            .jobs
            .compute_heavy(move |_| -> Result<WeightsArtifact, JobError> {
                let mut artifact = as_result(&job, |inputs| artifact_of_moments(&moments, &job, inputs, strategy))?;
                artifact.provenance.job_id = Some(id);
                if let Some(attests) = attests {
                    artifact = provenance.sign_artifact(artifact, attests);
                }
                Ok(artifact)
            })
            .await?
    }

    /// The effective weights per (r2, r3) bin of job `id`'s row `strategy` (none: its recommended
    /// row) over `paths` paths per side, from its latest checkpoint (Fig. 2 of any recommendation,
    /// `sim::weights::effective`). CPU work (a report, maybe a refit, the paths): on the heavy
    /// pool, bounded by `paths` ≤ `MAX_EFFECTIVE_PATHS`.
    pub async fn effective(
        &self,
        id: i64,
        strategy: Option<Strategy>,
        paths: usize,
    ) -> Result<EffectiveWeights, JobError> {
        let Latest { job, moments, .. } = self.statistics.latest(id).await?;
        self.statistics
            .jobs
            .compute_heavy(move |_| -> Result<EffectiveWeights, JobError> {
                as_result(&job, |inputs| effective_of_moments(&moments, &job, inputs, strategy, paths))
            })
            .await?
    }
}

/// `make` given the report inputs a job's result is built with (its scene's reference and each
/// per-path row's expectation), so that the row chosen is the result's; its error names the
/// strategy asked for.
fn as_result<T>(job: &ValidJob, make: impl FnOnce(&ReportInputs<'_>) -> Result<T, String>) -> Result<T, JobError> {
    let config = job.config();
    let expected = expected_luminances(config);
    let inputs = ReportInputs { reference: scene_reference(&config.scene), expected: Some(&expected), weights: None };
    make(&inputs).map_err(|e| JobError::from(SpecError::new("strategy", e)))
}
