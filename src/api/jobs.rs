//! Handlers of `/v1/jobs`: submit, list, inspect, results, re-solve, cancel, extend, delete, and
//! the moments export. Each only translates between HTTP and the job manager.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};

use super::AppState;
use super::bodies::{JobSubmission, SolverPatch};
use super::csv::{csv_response, wants_csv};
use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody, page, typed};
use crate::jobs::documents::{JobHistory, JobList, JobResult};
use crate::jobs::evaluation::JobEvaluation;
use crate::jobs::prediction::{JobPrediction, PredictRequest};
use crate::jobs::resource::{JobResource, JobState};
use crate::sim::document::MomentsDocument;
use crate::sim::solve::evaluate::GivenWeights;
use crate::sim::solve::export::{noise_table_csv, weights_csv};
/// Longest accepted `Idempotency-Key`.
const MAX_KEY_LEN: usize = 255;

/// Iterations to add to a job: exactly one of `iterations` and `total`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ExtendRequest {
    /// How many more iterations to run beyond what the job would otherwise reach: its
    /// `iterations_total` while it is queued or running, the iterations it holds
    /// (`iterations_done`) once it succeeded or was cancelled. At least 1; the new total may not
    /// exceed 10^9.
    #[schema(minimum = 1, maximum = 1_000_000_000)]
    #[serde(default, deserialize_with = "crate::sim::model::params::optional_count")]
    pub iterations: Option<u64>,
    /// The new target instead: run until the job holds this many iterations (resume a cancelled
    /// job to its original target with `total` = its `iterations_total`). Above the iterations it
    /// holds, at most 10^9.
    #[schema(minimum = 1, maximum = 1_000_000_000)]
    #[serde(default, deserialize_with = "crate::sim::model::params::optional_count")]
    pub total: Option<u64>,
}

/// Query of the job list.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Only jobs in this state.
    state: Option<JobState>,
    /// Page size, 1 to 500 (default 50).
    #[param(minimum = 1, maximum = 500)]
    limit: Option<u32>,
    /// `next_cursor` of the previous page.
    #[param(pattern = "^[1-9][0-9]{0,18}$")]
    cursor: Option<String>,
}

/// Query of a job's result.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ResultQuery {
    /// Show the weights fitted in-sample on all iterations at this λ (e.g. `0`, the paper's
    /// procedure) instead of the recommended weights; the noise table is the same.
    #[param(minimum = 0.0, maximum = 1e12)]
    lambda: Option<f64>,
    /// `csv` or `json`; without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json)$")]
    format: Option<String>,
    /// With CSV: `noise` (default; one row per strategy) or `weights` (one row per cell).
    #[param(pattern = "^(noise|weights)$")]
    table: Option<String>,
}

/// Query of a job's history.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct HistoryQuery {
    /// `csv` or `json`; without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json)$")]
    format: Option<String>,
}

fn location(id: i64) -> HeaderValue {
    HeaderValue::from_str(&format!("/v1/jobs/{id}")).expect("an ASCII path")
}

fn accepted(resource: &JobResource) -> Response {
    let mut response = (StatusCode::ACCEPTED, Json(resource)).into_response();
    response.headers_mut().insert(header::LOCATION, location(resource.id));
    response
}

/// Submit a job.
#[utoipa::path(
    post, operation_id = "submit_job", path = "/v1/jobs", tag = "jobs",
    request_body(content = JobSubmission, description = "Preset and overrides"),
    params(("Idempotency-Key" = Option<String>, Header,
        description = "Repeat a submission safely: the same key and body return the original job")),
    responses(
        (status = 202, description = "Queued", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A field is invalid, or the job exceeds a limit of this server (job budget, cells, the expected work of one iteration); the detail states the limit", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down, or the database cannot store the job (disk full; nothing was created; retry after Retry-After seconds)", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn submit(
    State(state): State<AppState>,
    headers: HeaderMap,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    let key = match headers.get("idempotency-key") {
        None => None,
        Some(v) => {
            let key = v
                .to_str()
                .ok()
                .filter(|k| !k.is_empty() && k.len() <= MAX_KEY_LEN && k.bytes().all(|b| b.is_ascii_graphic()));
            Some(
                key.ok_or_else(|| ApiError::Invalid {
                    field: "Idempotency-Key".into(),
                    message: format!("must be 1 to {MAX_KEY_LEN} visible ASCII characters"),
                })?
                .to_string(),
            )
        }
    };
    let (resource, replayed) = state.jobs.submit(doc, key).await?;
    let mut response = accepted(&resource);
    if replayed {
        response.headers_mut().insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    Ok(response)
}

/// A query-string rejection as a 422 naming the parameter (axum reports `name: reason`).
pub(super) fn query_problem(rejection: QueryRejection) -> ApiError {
    let text = rejection.body_text();
    let reason = text.strip_prefix("Failed to deserialize query string: ").unwrap_or(&text);
    match reason.split_once(": ") {
        Some((name, message)) if ["state", "limit", "cursor", "lambda", "format", "table"].contains(&name) => {
            ApiError::Invalid { field: name.into(), message: message.into() }
        }
        _ => ApiError::Invalid { field: "query".into(), message: reason.into() },
    }
}

/// List jobs, newest first.
#[utoipa::path(
    get, operation_id = "list_jobs", path = "/v1/jobs", tag = "jobs", params(ListQuery),
    responses(
        (status = 200, description = "A page of jobs", body = JobList),
        (status = 422, description = "A parameter is invalid", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<JobList>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let (limit, cursor) = page(q.limit, q.cursor, 50, 500)?;
    Ok(Json(state.jobs.list(q.state, cursor, limit).await?))
}

/// A job: state, spec and progress.
#[utoipa::path(
    get, operation_id = "get_job", path = "/v1/jobs/{id}", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = JobResource),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get(State(state): State<AppState>, JobId(id): JobId) -> Result<Json<JobResource>, ApiError> {
    Ok(Json(state.jobs.get(id).await?))
}

/// The job's noise and weights tables from its latest checkpoint (`partial` until it succeeded).
#[utoipa::path(
    get, operation_id = "get_result", path = "/v1/jobs/{id}/result", tag = "jobs", params(("id" = i64, Path, description = "Job id"), ResultQuery),
    responses(
        (status = 200, description = "Results: the result document, or with format=csv one of its tables (noise: one row per strategy, luminance in model units, rms_percent of one iteration; weights: one row per cell)", content(
            (JobResult = "application/json"),
            (String = "text/csv"))),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A query parameter is invalid or unknown; `field` names it", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn result(
    State(state): State<AppState>,
    JobId(id): JobId,
    headers: HeaderMap,
    query: Result<Query<ResultQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let csv = wants_csv(&headers, q.format.as_deref())?;
    let result = match q.lambda {
        None => state.jobs.result(id).await?,
        Some(lambda) => state.jobs.solve(id, &serde_json::json!({}), Some(lambda)).await?,
    };
    match (csv, q.table.as_deref()) {
        (false, None) => Ok(Json(result).into_response()),
        (false, Some(_)) => {
            Err(ApiError::Invalid { field: "table".into(), message: "applies to CSV only (format=csv)".into() })
        }
        (true, None | Some("noise")) => {
            Ok(csv_response(noise_table_csv(&result.report.noise_table), &format!("optimis-job-{id}-noise.csv")))
        }
        (true, Some("weights")) => {
            Ok(csv_response(weights_csv(&result.report.weights), &format!("optimis-job-{id}-weights.csv")))
        }
        (true, Some(other)) => Err(ApiError::Invalid {
            field: "table".into(),
            message: format!("must be noise or weights, got {other:?}"),
        }),
    }
}

/// Re-solve the stored moments with other solver options; nothing is re-run or stored.
#[utoipa::path(
    post, operation_id = "solve_job", path = "/v1/jobs/{id}/solve", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = SolverPatch, description = "Solver options to change"),
    responses(
        (status = 200, description = "Results with these options", body = JobResult),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "An option is invalid", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn solve(
    State(state): State<AppState>,
    JobId(id): JobId,
    JsonBody(patch): JsonBody,
) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(state.jobs.solve(id, &patch, None).await?))
}

/// Predict the noise table at another ray budget (N_F, N_B) from the job's latest checkpoint, and
/// re-fit the optimal weights for it; needs a job run with `"noise_components": true`. Nothing is
/// run or stored.
#[utoipa::path(
    post, operation_id = "predict_job", path = "/v1/jobs/{id}/predict", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = PredictRequest, description = "The budget to predict for, and solver options to change"),
    responses(
        (status = 200, description = "The predicted noise table and re-fitted weights", body = JobPrediction),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet, or the job keeps no noise components", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A field is invalid; `field` names it", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn predict(
    State(state): State<AppState>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobPrediction>, ApiError> {
    let request: PredictRequest = typed(&body)?;
    Ok(Json(state.jobs.predict(id, &request).await?))
}

/// Score given weights on the job's latest checkpoint: another run's `/result` (its recommended
/// table, heuristics stacked on it included) or a table of one's own (`weights`, `heuristics`);
/// L, RMS and their standard errors beside the job's per-path strategies, each with the paired
/// variance ratio. Nothing is run or stored.
#[utoipa::path(
    post, operation_id = "evaluate_weights", path = "/v1/jobs/{id}/evaluate", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = GivenWeights, description = "The weights: a result document, or `weights` (one entry per cell of the job's grid) and `heuristics`"),
    responses(
        (status = 200, description = "The weights' figures on this job's iterations", body = JobEvaluation),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "The weights do not fit this job (another grid, a heuristic without a column, cells that do not sum to 1 − Σβ); `field` names the part", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn evaluate(
    State(state): State<AppState>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobEvaluation>, ApiError> {
    let given: GivenWeights = typed(&body)?;
    Ok(Json(state.jobs.evaluate(id, given).await?))
}

/// Cancel a queued job, or stop a running one within one chunk of light paths.
#[utoipa::path(
    post, operation_id = "cancel_job", path = "/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 202, description = "Cancelled, or stopping", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Already finished", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn cancel(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, ApiError> {
    Ok(accepted(&state.jobs.cancel(id).await?))
}

/// Add iterations to a job; they continue the same deterministic sequence.
#[utoipa::path(
    post, operation_id = "extend_job", path = "/v1/jobs/{id}/extend", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = ExtendRequest),
    responses(
        (status = 202, description = "Extended (and queued again if it had finished)", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job failed", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid iteration count", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn extend(
    State(state): State<AppState>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let request: ExtendRequest = typed(&body)?;
    Ok(accepted(&state.jobs.extend(id, request.iterations, request.total).await?))
}

/// Delete a job that is not running, with its checkpoint.
#[utoipa::path(
    delete, operation_id = "delete_job", path = "/v1/jobs/{id}", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job is running", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete(State(state): State<AppState>, JobId(id): JobId) -> Result<StatusCode, ApiError> {
    state.jobs.delete(id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// The job's moments (additive statistics) from its latest checkpoint, as a checksummed document.
#[utoipa::path(
    get, operation_id = "get_moments", path = "/v1/jobs/{id}/moments", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The moments document (with a Content-Disposition naming the file)", body = MomentsDocument,
            headers(("Content-Disposition" = String, description = "attachment; filename=\"optimis-job-ID-moments.json\""))),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn moments(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, ApiError> {
    // Serialised on the job layer's request pool (a document can be megabytes), sent as is.
    let bytes = state.jobs.moments_json(id).await?;
    let disposition = HeaderValue::from_str(&format!("attachment; filename=\"optimis-job-{id}-moments.json\""))
        .expect("an ASCII header");
    Ok((
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("application/json")),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        bytes,
    )
        .into_response())
}

/// Each strategy's luminance and RMS at every checkpoint (at most 1,000 points, evenly thinned).
#[utoipa::path(
    get, operation_id = "get_history", path = "/v1/jobs/{id}/history", tag = "jobs", params(("id" = i64, Path, description = "Job id"), HistoryQuery),
    responses(
        (status = 200, description = "The history, oldest checkpoint first (CSV with format=csv: iterations, strategy, luminance, rms_percent)", content(
            (JobHistory = "application/json"),
            (String = "text/csv"))),
        (status = 422, description = "A query parameter is invalid or unknown; `field` names it", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn history(
    State(state): State<AppState>,
    JobId(id): JobId,
    headers: HeaderMap,
    query: Result<Query<HistoryQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let csv = wants_csv(&headers, q.format.as_deref())?;
    let history = state.jobs.history(id).await?;
    if csv {
        return Ok(csv_response(history.to_csv(), &format!("optimis-job-{id}-history.csv")));
    }
    Ok(Json(history).into_response())
}
