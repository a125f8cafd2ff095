//! Merging statistics: into an existing job (`POST /v1/jobs/{id}/merge`) or into a new study job
//! (`POST /v1/studies`), from moments documents or from jobs on peer servers.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::AppState;
use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody};
use super::jobs::SolverPatch;
use crate::jobs::documents::JobResult;
use crate::jobs::resource::JobResource;
use crate::sim::document::MomentsDocument;

/// A job on a peer optimis server whose moments are pulled over HTTP.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // documents the body; sources are parsed by `jobs::peers::parse_source`
pub struct PeerSource {
    /// URL of the job: `http://host:port/v1/jobs/ID` (plain HTTP).
    #[schema(
        example = "http://10.0.0.2:8080/v1/jobs/7",
        pattern = r"^http://[^/?#\s]+/v1/jobs/[1-9][0-9]{0,18}(/moments)?/?$"
    )]
    pub from: String,
}

/// Statistics to merge: a moments document, or a peer's job.
#[derive(Deserialize, ToSchema)]
#[serde(untagged)]
#[allow(clippy::large_enum_variant, dead_code)]
pub enum MergeSource {
    Peer(PeerSource),
    Document(MomentsDocument),
}

/// A study: statistics from several sources merged into a new finished job.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct StudyRequest {
    /// 1 to 256 sources of one configuration with disjoint iterations.
    pub sources: Vec<MergeSource>,
    /// Solver options to change from the first source's.
    pub solver: Option<SolverPatch>,
}

/// Merge statistics into a finished job and recompute its results.
#[utoipa::path(
    post, path = "/v1/jobs/{id}/merge", tag = "statistics", params(("id" = i64, Path, description = "Job id")),
    request_body(content = MergeSource, description = "A moments document, or {\"from\": URL of a peer's job}"),
    responses(
        (status = 200, description = "Merged; the results recomputed", body = JobResult),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Another configuration, iterations already counted, or the job is active", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Not a valid moments document (corrupted, truncated, foreign), or a peer that could not be reached or sent no usable document", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn merge(
    State(state): State<AppState>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(state.jobs.merge_into(id, &body).await?))
}

/// Create a finished job from merged statistics of several documents or peer jobs.
#[utoipa::path(
    post, path = "/v1/studies", tag = "statistics",
    request_body(content = StudyRequest),
    responses(
        (status = 201, description = "The study's job, with its results computed", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        (status = 400, description = "The body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The sources have different configurations or overlapping iterations", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A source is invalid, or a peer could not be reached or sent no usable document", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create(State(state): State<AppState>, JsonBody(body): JsonBody) -> Result<Response, ApiError> {
    let object = body.as_object().ok_or_else(|| ApiError::Invalid {
        field: String::new(),
        message: "the body must be an object with `sources`".into(),
    })?;
    if let Some(unknown) = object.keys().find(|k| !["sources", "solver"].contains(&k.as_str())) {
        return Err(ApiError::Invalid {
            field: unknown.clone(),
            message: "unknown field; expected `sources` and `solver`".into(),
        });
    }
    let sources = object.get("sources").and_then(Value::as_array).ok_or_else(|| ApiError::Invalid {
        field: "sources".into(),
        message: "a list of moments documents or {\"from\": URL} is required".into(),
    })?;
    let resource = state.jobs.create_study(sources, object.get("solver")).await?;
    let mut response = (StatusCode::CREATED, Json(&resource)).into_response();
    let location = HeaderValue::from_str(&format!("/v1/jobs/{}", resource.id)).expect("an ASCII path");
    response.headers_mut().insert(header::LOCATION, location);
    Ok(response)
}
