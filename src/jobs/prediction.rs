//! `POST /v1/jobs/{id}/predict`: the noise table and re-fitted weights of a job's latest
//! checkpoint at another ray budget (`sim::solve::predict`), computed on the request pool; and
//! `POST /v1/jobs/{id}/budget`: the budget that reaches a target noise soonest
//! (`sim::solve::budget`), on the heavy pool (it predicts at every point of its grid).

use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::core::error::JobError;
use super::core::references::{expected_luminances, scene_reference};
use super::core::resource::JobState;
use super::statistics::{Latest, Statistics};
use crate::sim::model::params::SpecError;
use crate::sim::model::params::{check, check_path_counts};
use crate::sim::solve::budget::error::{ErrorPlan, error_plan_of};
use crate::sim::solve::budget::{BudgetPlan, Costs, plan};
use crate::sim::solve::predict::{Budget, PredictError, Prediction, predict};
use crate::sim::solve::radius_reports::radius_reports;

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

/// The ray budget to plan for: the target noise and the renderer's costs (the client's renderer:
/// the server does not time one). A cost left out is the reference's (`Costs::REFERENCE`, the same
/// as `optimis budget` and the dashboard take), and the plan's `costs.source` says which were given.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BudgetRequest {
    /// The RMS to reach, in percent (e.g. 1); absent with `target_rmse`: that value.
    #[serde(default)]
    pub target_rms: Option<f64>,
    /// Also plan to a relative RMSE about the true pixel value, in percent — the noise and the
    /// merge radius's bias together — over the job's own R and every radius it tallied
    /// (`radii`): the fastest (N_F, N_B, R′, strategy), the best at the job's own R, the paper's
    /// setup and a progressive schedule (`error_plan`, docs/model.md §13).
    #[serde(default)]
    pub target_rmse: Option<f64>,
    /// t_M: seconds per merge event and pixel, for `target_rmse` (≥ 0; default: the reference's,
    /// 8·10⁻⁸).
    #[serde(default)]
    pub merge_cost: Option<f64>,
    /// t_F: the renderer's seconds per light path (≥ 0; default: the reference's, 7.3·10⁻⁹).
    #[serde(default)]
    pub light_cost: Option<f64>,
    /// t_B: seconds per camera path and pixel (≥ 0; default: the reference's, 4.1·10⁻⁶).
    #[serde(default)]
    pub camera_cost: Option<f64>,
    /// t_0: seconds per iteration besides the paths (≥ 0; default: the reference's, 1.9·10⁻⁴).
    #[serde(default)]
    pub iteration_cost: Option<f64>,
    /// P: pixels of the image the light paths serve (≥ 1; default 10^6).
    #[serde(default)]
    pub pixels: Option<f64>,
    /// Solver options to change (a merge patch, as for `POST /v1/jobs/{id}/solve`).
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub solver: Option<Value>,
}

/// A job's budget plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobBudget {
    /// Id of the job whose latest checkpoint the plan is made from.
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations.
    pub partial: bool,
    /// The job's state when the plan was computed.
    pub state: JobState,
    /// Per strategy the (N_F, N_B) that reaches the target soonest, with the time and its
    /// speed-up over the paper's configuration (each with a standard error), the search range
    /// and whether the best lies on its edge — as `optimis budget --json` prints it.
    #[serde(flatten)]
    pub plan: BudgetPlan,
    /// With `target_rmse`: the plan to that error, the bias of every radius counted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_plan: Option<ErrorPlan>,
}

impl Predictions {
    /// Plans the ray budget that reaches `request.target_rms` soonest, per strategy, from the
    /// job's latest checkpoint (needs noise components); on the heavy pool, nothing stored.
    pub async fn budget(&self, id: i64, request: &BudgetRequest) -> Result<JobBudget, JobError> {
        let costs = Costs::REFERENCE
            .with_given(request.light_cost, request.camera_cost, request.iteration_cost, request.pixels)
            .with_merge(request.merge_cost);
        let positive = |field: &str, v: f64| {
            check(v.is_finite() && v > 0.0, field, || format!("must be a positive percentage, got {v}"))
        };
        if let Some(p) = request.target_rmse {
            positive("target_rmse", p)?;
        }
        let Some(target) = request.target_rms.or(request.target_rmse) else {
            return Err(JobError::from(SpecError::new("target_rms", "give target_rms, target_rmse or both")));
        };
        positive("target_rms", target)?;
        check(costs.pixels.is_finite() && (1.0..=1e10).contains(&costs.pixels), "pixels", || {
            format!("must be in [1, 10^10], got {}", costs.pixels)
        })?;
        for (field, v) in [
            ("light_cost", costs.light_path),
            ("camera_cost", costs.camera_path),
            ("iteration_cost", costs.iteration),
            ("merge_cost", costs.merge),
        ] {
            check(v.is_finite() && (0.0..=1e6).contains(&v), field, || {
                format!("must be in [0, 10^6] seconds, got {v}")
            })?;
        }
        let Latest { state, partial, job, moments, .. } = self.statistics.latest(id).await?;
        let solver = match &request.solver {
            Some(patch) => job.spec().solver.patched(patch)?,
            None => job.spec().solver.clone(),
        };
        let measured = Budget { light_paths: job.spec().light_paths, camera_paths: job.spec().camera_paths };
        let target_rmse = request.target_rmse;
        let (plan, error_plan) = self
            .statistics
            .jobs
            .compute_heavy(move |_| -> Result<(BudgetPlan, Option<ErrorPlan>), JobError> {
                let conflict = |e: PredictError| JobError::Conflict(e.to_string());
                let plan = plan(&moments, &job.config().cells, &solver, measured, costs, target).map_err(conflict)?;
                let error_plan = match target_rmse {
                    // The quadratures behind the biases are bounded (about a second each) and
                    // cached by configuration.
                    Some(p) => {
                        let config = job.config();
                        let reference = scene_reference(config.scene());
                        let reports = radius_reports(
                            config,
                            &moments,
                            &solver,
                            reference,
                            &|c| expected_luminances(c).to_vec(),
                            None,
                        );
                        Some(error_plan_of(config, &moments, &reports, &solver, costs, p).map_err(conflict)?)
                    }
                    None => None,
                };
                Ok((plan, error_plan))
            })
            .await??;
        Ok(JobBudget { job_id: id, partial, state, plan, error_plan })
    }
}
