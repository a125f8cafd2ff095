//! Handlers of the jobs' lifecycle under `/v1/jobs`: submit, list, inspect, cancel, extend,
//! delete. Each only translates between HTTP and the job manager (`State<JobManager>`).

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};

use super::AppState;
use super::bodies::JobSubmission;
use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody, page, query_problem, typed};
use super::responses::{BadQuery, NoSuchJob, NotJson, ServerFailure, TooLarge};
use super::wait::WaitQuery;
use crate::jobs::JobManager;
use crate::jobs::core::documents::JobList;
use crate::jobs::core::resource::{JobResource, JobState};
use crate::sim::spec::Label;
use crate::store::JobFilter;

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
    /// Only the runs of this sweep.
    #[param(minimum = 1)]
    sweep: Option<i64>,
    /// Only jobs with this label: `KEY=VALUE` (the job document's `labels`).
    #[param(pattern = "^[A-Za-z0-9_.-]{1,64}=.{0,200}$")]
    label: Option<String>,
    /// Page size, 1 to 500 (default 50).
    #[param(minimum = 1, maximum = 500)]
    limit: Option<u32>,
    /// `next_cursor` of the previous page.
    #[param(pattern = "^[1-9][0-9]{0,18}$")]
    cursor: Option<String>,
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
        NotJson,
        TooLarge,
        (status = 422, description = "A field is invalid, or the job exceeds a limit of this server (job budget, cells, the expected work of one iteration); the detail states the limit", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down, or the database cannot store the job (disk full; nothing was created; retry after Retry-After seconds)", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn submit(
    State(jobs): State<JobManager>,
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
    let (resource, replayed) = jobs.submit(doc, key).await?;
    let mut response = accepted(&resource);
    if replayed {
        response.headers_mut().insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    Ok(response)
}

/// List jobs, newest first.
#[utoipa::path(
    get, operation_id = "list_jobs", path = "/v1/jobs", tag = "jobs", params(ListQuery),
    responses(
        (status = 200, description = "A page of jobs", body = JobList),
        (status = 422, description = "A parameter is invalid", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn list(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<JobList>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let (limit, cursor) = page(q.limit, q.cursor, 50, 500)?;
    let label = q
        .label
        .as_deref()
        .map(Label::parse)
        .transpose()
        .map_err(|e| ApiError::Invalid { field: "label".into(), message: e.message })?;
    if q.sweep.is_some_and(|s| s < 1) {
        return Err(ApiError::Invalid { field: "sweep".into(), message: "must be a sweep id (≥ 1)".into() });
    }
    let filter = JobFilter { state: q.state, sweep: q.sweep, label };
    Ok(Json(state.services.jobs.list(&filter, cursor, limit).await?))
}

/// A job: state, spec and progress.
#[utoipa::path(
    get, operation_id = "get_job", path = "/v1/jobs/{id}", tag = "jobs", params(("id" = i64, Path, description = "Job id"), WaitQuery),
    responses(
        (status = 200, description = "The job (with `wait`: once it has ended, or when the seconds have passed)", body = JobResource),
        NoSuchJob,
        BadQuery,
        (status = 429, description = "`wait`: too many requests are waiting (they share --max-event-streams); retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn get(
    State(state): State<AppState>,
    JobId(id): JobId,
    query: Result<Query<WaitQuery>, QueryRejection>,
) -> Result<Json<JobResource>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    // A job that is not in memory has ended (or waits in the database for a restart's queue):
    // nothing to wait for.
    if let Some(wait) = q.duration()?
        && let Some(mut rx) = state.services.jobs.subscribe(id)
    {
        let _slot = state.streams.acquire()?;
        let mut shutdown = state.services.jobs.shutdown_signal();
        tokio::select! {
            _ = tokio::time::timeout(wait, rx.wait_for(|job| job.state.is_terminal())) => {}
            _ = shutdown.wait_for(|stopping| *stopping) => {}
        }
    }
    Ok(Json(state.services.jobs.get(id).await?))
}

/// Cancel a queued job, or stop a running one within one chunk of light paths.
#[utoipa::path(
    post, operation_id = "cancel_job", path = "/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 202, description = "Cancelled, or stopping", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        NoSuchJob,
        (status = 409, description = "Already finished", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn cancel(State(jobs): State<JobManager>, JobId(id): JobId) -> Result<Response, ApiError> {
    Ok(accepted(&jobs.cancel(id).await?))
}

/// Add iterations to a job; they continue the same deterministic sequence.
#[utoipa::path(
    post, operation_id = "extend_job", path = "/v1/jobs/{id}/extend", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = ExtendRequest),
    responses(
        (status = 202, description = "Extended (and queued again if it had finished)", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        NotJson,
        NoSuchJob,
        (status = 409, description = "The job failed", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "Invalid iteration count", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn extend(
    State(jobs): State<JobManager>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let request: ExtendRequest = typed(&body)?;
    Ok(accepted(&jobs.extend(id, request.iterations, request.total).await?))
}

/// Delete a job that is not running, with its checkpoint.
#[utoipa::path(
    delete, operation_id = "delete_job", path = "/v1/jobs/{id}", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 204, description = "Deleted"),
        NoSuchJob,
        (status = 409, description = "The job is running", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn delete(State(jobs): State<JobManager>, JobId(id): JobId) -> Result<StatusCode, ApiError> {
    jobs.delete(id).await?;
    Ok(StatusCode::NO_CONTENT)
}
