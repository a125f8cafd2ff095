//! `POST /v1/jobs/{id}/evaluate`: given weights — another run's result, or a table of one's own —
//! scored on a job's latest checkpoint (`sim::solve::evaluate`), computed on the request pool.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::error::JobError;
use super::manager::JobManager;
use super::resource::JobState;
use crate::sim::model::params::SpecError;
use crate::sim::solve::evaluate::{Evaluation, GivenWeights, evaluate};

/// A job's evaluation of given weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobEvaluation {
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations.
    pub partial: bool,
    pub state: JobState,
    #[serde(flatten)]
    pub evaluation: Evaluation,
}

impl JobManager {
    /// Scores `given` on the job's latest checkpoint; nothing is run or stored.
    pub async fn evaluate(&self, id: i64, given: GivenWeights) -> Result<JobEvaluation, JobError> {
        let (state, total, spec, merged) = self.state_and_total(id).await?;
        let (moments, checkpoint) = self.checkpoint_moments(id, &spec, merged).await?;
        let done = checkpoint.iterations_done;
        let evaluation = self
            .compute_heavy(move |_| -> Result<Evaluation, JobError> {
                let job = spec.validate()?;
                evaluate(&moments, &job.config.cells, &given).map_err(|e| SpecError::new(e.field, e.message).into())
            })
            .await??;
        let partial = !(state == JobState::Succeeded && done >= total);
        Ok(JobEvaluation { job_id: id, partial, state, evaluation })
    }
}
