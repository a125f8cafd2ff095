//! `POST /v1/jobs/{id}/predict`: the noise table and re-fitted weights of a job's latest
//! checkpoint at another ray budget (`sim::solve::predict`), computed on the request pool.

use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::error::JobError;
use super::resource::JobState;
use super::statistics::{Latest, Statistics};
use crate::sim::model::params::check_path_counts;
use crate::sim::solve::predict::{Budget, Prediction, predict};

/// What to predict.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PredictRequest {
    /// N_F to predict for, in [1, 10^12].
    pub light_paths: u64,
    /// N_B to predict for, in [1, 10^6].
    pub camera_paths: u64,
    /// Solver options to change (a merge patch, as for `POST /v1/jobs/{id}/solve`).
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub solver: Option<Value>,
}

/// A job's prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobPrediction {
    /// Id of the job whose latest checkpoint the prediction is made from.
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations.
    pub partial: bool,
    /// The job's state when the prediction was computed.
    pub state: JobState,
    /// The predicted noise table and re-fitted weights at the requested budget, its fields
    /// inlined into this object.
    #[serde(flatten)]
    pub prediction: Prediction,
}

/// Predictions of jobs' noise at other ray budgets; cheap to clone.
#[derive(Clone)]
pub struct Predictions {
    statistics: Statistics,
}

impl Predictions {
    /// Predictions from the statistics of `statistics`' jobs.
    pub fn new(statistics: Statistics) -> Self {
        Self { statistics }
    }

    /// Predicts the job's noise table at the budget of `request` from its latest checkpoint;
    /// nothing is run or stored.
    pub async fn predict(&self, id: i64, request: &PredictRequest) -> Result<JobPrediction, JobError> {
        check_path_counts(request.light_paths, request.camera_paths, ["light_paths", "camera_paths"])?;
        let Latest { state, partial, job, moments, .. } = self.statistics.latest(id).await?;
        let solver = match &request.solver {
            Some(patch) => job.spec().solver.patched(patch)?,
            None => job.spec().solver.clone(),
        };
        let measured = Budget { light_paths: job.spec().light_paths, camera_paths: job.spec().camera_paths };
        let to = Budget { light_paths: request.light_paths, camera_paths: request.camera_paths };
        let prediction = self
            .statistics
            .jobs
            .compute_heavy(move |_| -> Result<Prediction, JobError> {
                predict(&moments, &job.config().cells, &solver, measured, to)
                    .map_err(|e| JobError::Conflict(e.to_string()))
            })
            .await??;
        Ok(JobPrediction { job_id: id, partial, state, prediction })
    }
}
