//! `POST /v1/jobs/{id}/evaluate`: given weights — another run's result, or a table of one's own —
//! scored on a job's latest checkpoint (`sim::solve::evaluate`), computed on the request pool.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::core::error::JobError;
use super::core::resource::JobState;
use super::statistics::{Latest, Statistics};
use crate::sim::model::params::SpecError;
use crate::sim::solve::evaluate::{Evaluation, GivenWeights, evaluate};

/// A job's evaluation of given weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobEvaluation {
    /// Id of the job whose latest checkpoint the weights were scored on.
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations.
    pub partial: bool,
    /// The job's state when the evaluation was computed.
    pub state: JobState,
    /// The given weights' figures on the job's iterations beside its per-path strategies, its
    /// fields inlined into this object.
    #[serde(flatten)]
    pub evaluation: Evaluation,
}

/// Evaluations of given weights on stored jobs; cheap to clone.
#[derive(Clone)]
pub struct Evaluations {
    statistics: Statistics,
}

impl Evaluations {
    /// Evaluations on the jobs `statistics` reads.
    pub fn new(statistics: Statistics) -> Self {
        Self { statistics }
    }

    /// Scores `given` on the job's latest checkpoint; nothing is run or stored.
    pub async fn evaluate(&self, id: i64, given: GivenWeights) -> Result<JobEvaluation, JobError> {
        let Latest { state, partial, job, moments, .. } = self.statistics.latest(id).await?;
        let evaluation = self
            .statistics
            .jobs
            .compute_heavy(move |_| -> Result<Evaluation, JobError> {
                evaluate(&moments, &job.config().cells, &given, &job.spec().solver.fixed)
                    .map_err(|e| SpecError::new(e.field, e.message).into())
            })
            .await??;
        Ok(JobEvaluation { job_id: id, partial, state, evaluation })
    }
}
