//! Merging statistics: into an existing job (`POST /v1/jobs/{id}/merge`) or into a new study job
//! (`POST /v1/studies`), from moments documents or from jobs on allowed peer servers.
//!
//! Both routes take their body as bytes ([`DocumentBody`]: the document size limit, the body
//! timeout, and a few requests at a time); the job layer parses it straight into typed values on
//! its request pool. The types below only describe the bodies for the OpenAPI document.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::ToSchema;

use super::bodies::SolverPatch;
use super::error::{ApiError, Problem};
use super::extract::{DocumentBody, JobId};
use super::responses::{NoSuchJob, NotJson, ServerFailure};
use crate::jobs::core::documents::JobResult;
use crate::jobs::core::resource::JobResource;
use crate::jobs::merges::Merges;
use crate::sim::document::MomentsDocument;

/// A job on a peer optimis server whose moments are pulled over http or https. The peer must be
/// on this server's allow-list (`optimis serve --peer BASE_URL`); any other URL is refused with
/// 403 before a connection is made.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // documents the body; sources are parsed by `jobs::statistics`
pub struct PeerSource {
    /// URL of the job: `https://host:port[/prefix]/v1/jobs/ID`.
    #[schema(
        example = "https://node2:8443/v1/jobs/7",
        pattern = r"^https?://[^/?#\s@]+(/[^?#\s]*)?/v1/jobs/[1-9][0-9]{0,18}(/moments)?/?$"
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
    post, operation_id = "merge_into_job", path = "/v1/jobs/{id}/merge", tag = "statistics", params(("id" = i64, Path, description = "Job id")),
    request_body(content = MergeSource, description = "A moments document, or {\"from\": URL of a peer's job}"),
    responses(
        (status = 200, description = "Merged; the results recomputed", body = JobResult),
        NotJson,
        (status = 403, description = "The source names a peer that is not on this server's allow-list (--peer)", body = Problem, content_type = "application/problem+json"),
        NoSuchJob,
        (status = 409, description = "Another configuration, iterations already counted, or the job is active or taking another merge", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large (--document-limit)", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Not a valid moments document (corrupted, truncated, inconsistent, foreign), statistics that would overflow or exceed the job budget, or a peer that could not be reached or sent no usable document", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many document requests at once; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn merge(
    State(merges): State<Merges>,
    JobId(id): JobId,
    body: DocumentBody,
) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(merges.merge_into(id, body.bytes.clone(), body.client).await?))
}

/// Create a finished job from merged statistics of several documents or peer jobs.
#[utoipa::path(
    post, operation_id = "create_study", path = "/v1/studies", tag = "statistics",
    request_body(content = StudyRequest),
    responses(
        (status = 201, description = "The study's job, with its results computed", body = JobResource,
            headers(("Location" = String, description = "URL of the job"))),
        NotJson,
        (status = 403, description = "A source names a peer that is not on this server's allow-list (--peer)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The sources have different configurations or overlapping iterations", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large (--document-limit)", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A source is invalid, statistics that would overflow or exceed the job budget, or a peer could not be reached or sent no usable document", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many document requests at once; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down, or the database cannot store the study (retry after Retry-After seconds)", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn create(State(merges): State<Merges>, body: DocumentBody) -> Result<Response, ApiError> {
    let resource = merges.create_study(body.bytes.clone(), body.client).await?;
    let mut response = (StatusCode::CREATED, Json(&resource)).into_response();
    let location = HeaderValue::from_str(&format!("/v1/jobs/{}", resource.id)).expect("an ASCII path");
    response.headers_mut().insert(header::LOCATION, location);
    Ok(response)
}
