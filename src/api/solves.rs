//! Handlers of `/v1/jobs/{id}/solves`: named solver options kept with a job and re-solved from its
//! latest checkpoint when read (`default` is the job's own).

use axum::Json;
use axum::extract::{FromRequestParts, Path, State};
use axum::http::StatusCode;
use axum::http::request::Parts;

use super::bodies::SolverPatch;
use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody};
use super::responses::{NoSuchJob, NotJson, ServerFailure, TooLarge};
use crate::jobs::core::documents::JobResult;
use crate::jobs::solves::SolveList;
use crate::jobs::solves::Solves;

/// The `{id}` and `{name}` of a solve route; an id that names no job is a 404.
pub struct SolvePath(pub i64, pub String);

impl<S: Send + Sync> FromRequestParts<S> for SolvePath {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let Path((raw, name)): Path<(String, String)> = Path::from_request_parts(parts, state)
            .await
            .map_err(|e| ApiError::NotFound(format!("no such solve: {e}")))?;
        let id = raw
            .parse::<i64>()
            .ok()
            .filter(|id| *id > 0)
            .ok_or_else(|| ApiError::NotFound(format!("no job with id {raw:?}")))?;
        Ok(SolvePath(id, name))
    }
}

/// The job's solves: `default` (its own options, what `/result` shows) and the named ones.
#[utoipa::path(
    get, operation_id = "list_solves", path = "/v1/jobs/{id}/solves", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The solves, default first", body = SolveList),
        NoSuchJob,
        ServerFailure,
    )
)]
pub async fn list(State(solves): State<Solves>, JobId(id): JobId) -> Result<Json<SolveList>, ApiError> {
    Ok(Json(solves.list_solves(id).await?))
}

/// Keep solver options under a name (replacing any of that name; at most 32 per job) and answer
/// their result from the latest checkpoint.
#[utoipa::path(
    put, operation_id = "save_solve", path = "/v1/jobs/{id}/solves/{name}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id"),
           ("name" = String, Path, description = "1 to 64 characters of a-z, 0-9, '_', '-', '.'; not `default`")),
    request_body(content = SolverPatch, description = "Solver options to change from the job's"),
    responses(
        (status = 200, description = "Kept; the results with these options", body = JobResult),
        NotJson,
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or the job keeps 32 named solves already", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "The name or an option is invalid; `field` names it", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn save(
    State(solves): State<Solves>,
    SolvePath(id, name): SolvePath,
    JsonBody(patch): JsonBody,
) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(solves.save_solve(id, &name, &patch).await?))
}

/// The results of a kept solve, re-solved from the job's latest checkpoint.
#[utoipa::path(
    get, operation_id = "get_solve", path = "/v1/jobs/{id}/solves/{name}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id"), ("name" = String, Path, description = "The solve's name, or `default`")),
    responses(
        (status = 200, description = "The results with the solve's options", body = JobResult),
        (status = 404, description = "No such job or solve", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn get(State(solves): State<Solves>, SolvePath(id, name): SolvePath) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(solves.solve_result(id, &name).await?))
}

/// Forget a kept solve (`default` cannot be).
#[utoipa::path(
    delete, operation_id = "delete_solve", path = "/v1/jobs/{id}/solves/{name}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id"), ("name" = String, Path, description = "The solve's name")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such job or solve", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "The name is invalid (or `default`)", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn delete(State(solves): State<Solves>, SolvePath(id, name): SolvePath) -> Result<StatusCode, ApiError> {
    solves.delete_solve(id, &name).await?;
    Ok(StatusCode::NO_CONTENT)
}
