//! `GET /v1/jobs/{id}/weights`: the job's weight function as a portable artifact for renderers
//! (`sim::weights`, docs/weights-lookup.md) — the recommended row's, or any row's by name.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use serde::Deserialize;
use utoipa::IntoParams;

use super::AppState;
use super::error::{ApiError, Problem};
use super::extract::{JobId, query_problem};
use super::responses::{BadQuery, NoSuchJob, ServerFailure};
use crate::sim::solve::strategy::Strategy;
use crate::sim::weights::artifact::WeightsArtifact;

/// Query of a job's weights.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct WeightsParams {
    /// The noise-table row whose weights to give (`optimal_stacked`, `switch`, …); default: the
    /// recommended row.
    #[param(pattern = "^[a-z0-9_]{1,64}$")]
    strategy: Option<String>,
}

/// The job's weight function as a portable artifact: a table, a heuristic or a stack, with the
/// scene its coordinates refer to, each heuristic's formula and parameters, provenance, and the
/// server's signature where it signs.
#[utoipa::path(
    get, operation_id = "get_weights", path = "/v1/jobs/{id}/weights", tag = "jobs",
    params(("id" = i64, Path, description = "Job id"), WeightsParams),
    responses(
        (status = 200, description = "The weights artifact (format optimis-weights, version 1)", body = WeightsArtifact),
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        BadQuery,
        (status = 429, description = "The server is busy with other long computations; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn weights(
    State(state): State<AppState>,
    JobId(id): JobId,
    query: Result<Query<WeightsParams>, QueryRejection>,
) -> Result<Json<WeightsArtifact>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let strategy = match q.strategy {
        None => None,
        Some(name) => {
            Some(serde_json::from_value::<Strategy>(serde_json::Value::String(name.clone())).map_err(|_| {
                ApiError::Invalid { field: "strategy".into(), message: format!("no strategy named {name:?}") }
            })?)
        }
    };
    Ok(Json(state.statistics.weights(id, strategy).await?))
}
