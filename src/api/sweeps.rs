//! Handlers of `/v1/sweeps`: create a sweep (its runs queued as jobs), list, inspect with every
//! point's figures, its table as JSON or CSV, cancel and delete (both cascade to the runs).

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::IntoParams;

use super::AppState;
use super::csv::{csv_response, wants_csv};
use super::error::{ApiError, Problem};
use super::extract::query_problem;
use super::extract::{JsonBody, SweepId, page};
use super::responses::{BadQuery, NoSuchSweep, NotJson, ServerFailure, TooLarge};
use super::wait::WaitQuery;
use crate::jobs::sweeps::Sweeps;
use crate::jobs::sweeps::{SweepList, SweepResource};
use crate::sim::sweep::{SweepSpec, SweepTable};

/// Query of the sweep list.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct SweepListQuery {
    /// Page size, 1 to 100 (default 20).
    #[param(minimum = 1, maximum = 100)]
    limit: Option<u32>,
    /// `next_cursor` of the previous page.
    #[param(pattern = "^[1-9][0-9]{0,18}$")]
    cursor: Option<String>,
}

/// Query of a sweep's table.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct TableQuery {
    /// `csv` or `json`; without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json)$")]
    format: Option<String>,
}

/// Create a sweep: the base job varied along the axes; every run is queued as a job.
#[utoipa::path(
    post, operation_id = "create_sweep", path = "/v1/sweeps", tag = "sweeps",
    request_body(content = SweepSpec, description = "The base job document, the axes and the mode"),
    responses(
        (status = 201, description = "Created; its runs are queued", body = SweepResource,
            headers(("Location" = String, description = "URL of the sweep"))),
        NotJson,
        TooLarge,
        (status = 422, description = "A field is invalid: `field` names the axis and value (`axes[1].values[2]`) and the detail the point; or a run exceeds a limit of this server (points per sweep: --max-sweep-points, job budget, the work of an iteration)", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "The runs do not fit in the queue; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down, or the database cannot store the sweep (nothing was created)", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn create(State(sweeps): State<Sweeps>, JsonBody(doc): JsonBody) -> Result<Response, ApiError> {
    let resource = sweeps.create_sweep(doc).await?;
    let mut response = (StatusCode::CREATED, Json(&resource)).into_response();
    let location = HeaderValue::from_str(&format!("/v1/sweeps/{}", resource.id)).expect("an ASCII path");
    response.headers_mut().insert(header::LOCATION, location);
    Ok(response)
}

/// List sweeps, newest first (without figures).
#[utoipa::path(
    get, operation_id = "list_sweeps", path = "/v1/sweeps", tag = "sweeps", params(SweepListQuery),
    responses(
        (status = 200, description = "A page of sweeps", body = SweepList),
        (status = 422, description = "A parameter is invalid", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn list(
    State(sweeps): State<Sweeps>,
    query: Result<Query<SweepListQuery>, QueryRejection>,
) -> Result<Json<SweepList>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let (limit, cursor) = page(q.limit, q.cursor, 20, 100)?;
    Ok(Json(sweeps.list_sweeps(cursor, limit).await?))
}

/// A sweep: progress, and per point the swept values, its job, its honest noise table and
/// recommended weights (measured, or predicted from its run).
#[utoipa::path(
    get, operation_id = "get_sweep", path = "/v1/sweeps/{id}", tag = "sweeps", params(("id" = i64, Path, description = "Sweep id"), WaitQuery),
    responses(
        (status = 200, description = "The sweep (with `wait`: once every run has ended, or when the seconds have passed)", body = SweepResource),
        NoSuchSweep,
        BadQuery,
        (status = 429, description = "`wait`: too many requests are waiting (they share --max-event-streams); retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn get(
    State(state): State<AppState>,
    SweepId(id): SweepId,
    query: Result<Query<WaitQuery>, QueryRejection>,
) -> Result<Json<SweepResource>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    if let Some(wait) = q.duration()? {
        let _slot = state.streams.acquire()?;
        state.services.sweeps.wait_for_end(id, wait).await?;
    }
    Ok(Json(state.services.sweeps.get_sweep(id).await?))
}

/// The sweep's table: one row per point (with figures) and strategy, as JSON or CSV (columns:
/// `point`, one per swept field, then `source`, `light_paths`, `camera_paths`, `iterations` (docs/csv.md),
/// `partial`, `strategy`, `luminance` (model units), `luminance_stderr`, `rms_percent` (percent of
/// L, one iteration), `rms_percent_stderr`, `respects_fixed`, `recommended`).
#[utoipa::path(
    get, operation_id = "get_sweep_table", path = "/v1/sweeps/{id}/table", tag = "sweeps",
    params(("id" = i64, Path, description = "Sweep id"), TableQuery),
    responses(
        (status = 200, description = "The table", content(
            (SweepTable = "application/json"),
            (String = "text/csv"))),
        NoSuchSweep,
        BadQuery,
        ServerFailure,
    )
)]
pub async fn table(
    State(sweeps): State<Sweeps>,
    SweepId(id): SweepId,
    headers: HeaderMap,
    query: Result<Query<TableQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let csv = wants_csv(&headers, q.format.as_deref())?;
    let table = sweeps.sweep_table(id).await?;
    if !csv {
        return Ok(Json(table).into_response());
    }
    Ok(csv_response(table.to_csv(), &format!("sweep-{id}.csv")))
}

/// Cancel every queued or running run of the sweep (each keeps the iterations it completed).
#[utoipa::path(
    post, operation_id = "cancel_sweep", path = "/v1/sweeps/{id}/cancel", tag = "sweeps", params(("id" = i64, Path, description = "Sweep id")),
    responses(
        (status = 200, description = "Cancel requested for every active run", body = SweepResource),
        NoSuchSweep,
        ServerFailure,
    )
)]
pub async fn cancel(State(sweeps): State<Sweeps>, SweepId(id): SweepId) -> Result<Json<SweepResource>, ApiError> {
    Ok(Json(sweeps.cancel_sweep(id).await?))
}

/// Delete a sweep and its jobs (refused while one runs: cancel the sweep first).
#[utoipa::path(
    delete, operation_id = "delete_sweep", path = "/v1/sweeps/{id}", tag = "sweeps", params(("id" = i64, Path, description = "Sweep id")),
    responses(
        (status = 204, description = "Deleted with its jobs"),
        NoSuchSweep,
        (status = 409, description = "A run is running or taking a merge", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn delete(State(sweeps): State<Sweeps>, SweepId(id): SweepId) -> Result<StatusCode, ApiError> {
    sweeps.delete_sweep(id).await?;
    Ok(StatusCode::NO_CONTENT)
}
