//! `GET /v1/jobs/{id}/weights`: the job's weight function as a portable artifact for renderers
//! (`sim::weights`, docs/weights-lookup.md) — the recommended row's, or any row's by name; and
//! `GET /v1/jobs/{id}/effective`: the same row's effective weights per (r2, r3) bin, what Fig. 2
//! draws for a table, a heuristic or a stack alike.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use serde::Deserialize;
use utoipa::IntoParams;

use super::error::{ApiError, Problem};
use super::extract::{JobId, query_problem};
use super::responses::{BadQuery, NoSuchJob, ServerFailure};
use crate::jobs::artifacts::Artifacts;
use crate::sim::solve::effective::EffectiveWeights;
use crate::sim::solve::strategy::Strategy;
use crate::sim::weights::artifact::WeightsArtifact;
use crate::sim::weights::effective::{EFFECTIVE_PATHS, MAX_EFFECTIVE_PATHS};

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
    State(artifacts): State<Artifacts>,
    JobId(id): JobId,
    query: Result<Query<WeightsParams>, QueryRejection>,
) -> Result<Json<WeightsArtifact>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    Ok(Json(artifacts.weights(id, parse_strategy(q.strategy)?).await?))
}

/// A strategy named in a query, as a noise-table row.
fn parse_strategy(name: Option<String>) -> Result<Option<Strategy>, ApiError> {
    let Some(name) = name else { return Ok(None) };
    serde_json::from_value::<Strategy>(serde_json::Value::String(name.clone()))
        .map(Some)
        .map_err(|_| ApiError::Invalid { field: "strategy".into(), message: format!("no strategy named {name:?}") })
}

/// Query of a job's effective weights.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct EffectiveParams {
    /// The noise-table row whose weights to average; default: the recommended row.
    #[param(pattern = "^[a-z0-9_]{1,64}$")]
    strategy: Option<String>,
    /// Paths each side draws (default 50 000; 1 000 to 1 000 000 — the work is linear in it).
    #[param(minimum = 1000, maximum = 1000000)]
    paths: Option<u64>,
}

/// The effective weights (w̄₀, w̄₁, w̄₂) of a row's weight function per (r2, r3) bin — the
/// contribution-weighted average over the bin's full paths, with sampling and fit standard errors
/// (docs/model.md §9): Fig. 2 of a table, a heuristic or a stack alike.
#[utoipa::path(
    get, operation_id = "get_effective_weights", path = "/v1/jobs/{id}/effective", tag = "jobs",
    params(("id" = i64, Path, description = "Job id"), EffectiveParams),
    responses(
        (status = 200, description = "The effective weights per (r2, r3) bin", body = EffectiveWeights),
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        BadQuery,
        (status = 429, description = "The server is busy with other long computations; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn effective(
    State(artifacts): State<Artifacts>,
    JobId(id): JobId,
    query: Result<Query<EffectiveParams>, QueryRejection>,
) -> Result<Json<EffectiveWeights>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let paths = q.paths.unwrap_or(EFFECTIVE_PATHS as u64);
    if !(1000..=MAX_EFFECTIVE_PATHS as u64).contains(&paths) {
        return Err(ApiError::Invalid {
            field: "paths".into(),
            message: format!("must be between 1000 and {MAX_EFFECTIVE_PATHS}"),
        });
    }
    let strategy = parse_strategy(q.strategy)?;
    Ok(Json(artifacts.effective(id, strategy, paths as usize).await?))
}
