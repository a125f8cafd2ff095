//! Handlers of `/v1/jobs/{id}/predict` (a job's noise table at another ray budget) and
//! `/v1/jobs/{id}/budget` (the budget that reaches a target noise soonest). They only translate
//! between HTTP and the predictions handle (`State<Predictions>`).

use axum::Json;
use axum::extract::State;

use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody, typed};
use super::responses::{NoSuchJob, NotJson, ServerFailure, TooLarge};
use crate::jobs::prediction::Predictions;
use crate::jobs::prediction::{BudgetRequest, JobBudget, JobPrediction, PredictRequest};

/// Predict the noise table at another ray budget (N_F, N_B) from the job's latest checkpoint, and
/// re-fit the optimal weights for it; needs a job run with `"noise_components": true`. Nothing is
/// run or stored.
#[utoipa::path(
    post, operation_id = "predict_job", path = "/v1/jobs/{id}/predict", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = PredictRequest, description = "The budget to predict for, and solver options to change"),
    responses(
        (status = 200, description = "The predicted noise table and re-fitted weights", body = JobPrediction),
        NotJson,
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or the job keeps no noise components", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "A field is invalid; `field` names it", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn predict(
    State(predictions): State<Predictions>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobPrediction>, ApiError> {
    let request: PredictRequest = typed(&body)?;
    Ok(Json(predictions.predict(id, &request).await?))
}

/// The ray budget (N_F, N_B) that reaches a target RMS soonest, per strategy, for a renderer of
/// the given costs, from the job's latest checkpoint; needs a job run with
/// `"noise_components": true`. Each speed-up over the paper's configuration carries a standard
/// error; the search widens while the best lies on its edge. Nothing is run or stored.
#[utoipa::path(
    post, operation_id = "budget_job", path = "/v1/jobs/{id}/budget", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = BudgetRequest, description = "The target RMS and the renderer's costs"),
    responses(
        (status = 200, description = "The plan: per strategy the fastest budget, its time and speed-up with SEs", body = JobBudget),
        NotJson,
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or the job keeps no noise components", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "A field is invalid; `field` names it", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "The server's heavy work is at its limit; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn budget(
    State(predictions): State<Predictions>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobBudget>, ApiError> {
    let request: BudgetRequest = typed(&body)?;
    Ok(Json(predictions.budget(id, &request).await?))
}
