//! Liveness, readiness and the API description.

use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::AppState;
use super::error::{ApiError, Problem};
use super::responses::ServerFailure;
use crate::jobs::JobManager;

/// Health status.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct Health {
    /// `ok`.
    pub status: String,
}

/// The process is alive.
#[utoipa::path(get, operation_id = "healthz", path = "/healthz", tag = "operations", responses((status = 200, description = "Alive", body = Health)))]
pub async fn healthz() -> Json<Health> {
    Json(Health { status: "ok".into() })
}

/// The database answers, every migration is applied, a write commits and 1 MiB of room is left
/// (under the database's page limit and on its filesystem).
#[utoipa::path(
    get, operation_id = "readyz", path = "/readyz", tag = "operations",
    responses(
        (status = 200, description = "Ready", body = Health),
        (status = 503, description = "Not ready, and why", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn readyz(State(jobs): State<JobManager>) -> Result<Json<Health>, ApiError> {
    jobs.store().ready().await.map_err(ApiError::Unavailable)?;
    Ok(Json(Health { status: "ok".into() }))
}

/// Prometheus metrics: requests by route template and status, request latency, checkpoint
/// duration, jobs by state, and iterations and throughput of each running job.
#[utoipa::path(
    get, operation_id = "get_metrics", path = "/metrics", tag = "operations",
    responses(
        (status = 200, description = "OpenMetrics text exposition", content_type = "application/openmetrics-text", body = String),
        ServerFailure,
    )
)]
pub async fn metrics(State(jobs): State<JobManager>) -> Result<impl IntoResponse, ApiError> {
    let states = jobs.store().jobs().count_by_state().await.map_err(|e| ApiError::Internal(e.to_string()))?;
    let text = jobs.metrics().render(&states, &jobs.running_samples());
    Ok(([(header::CONTENT_TYPE, crate::metrics::CONTENT_TYPE)], text))
}

/// This API's OpenAPI description.
#[utoipa::path(
    get, operation_id = "get_openapi", path = "/openapi.yaml", tag = "operations",
    responses((status = 200, description = "OpenAPI 3.1 document", content_type = "application/yaml", body = String))
)]
pub async fn openapi_yaml(State(state): State<AppState>) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/yaml")], state.openapi_yaml.to_string())
}
