//! `GET /v1/compare?ids=…`: jobs compared strategy by strategy from their latest results — each
//! job's L and RMS, and against the first job the ratio and the difference of L and the ratio of
//! RMS with their standard errors and z (`sim::solve::compare`). Bounded: 2 to 8 jobs, each a
//! stored result read.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use serde::Deserialize;
use utoipa::IntoParams;

use super::AppState;
use super::error::{ApiError, Problem};
use super::extract::query_problem;
use super::responses::{BadQuery, ServerFailure};
use crate::sim::solve::compare::{Compared, Comparison, MAX_COMPARED, compare as compare_runs};

/// Query of a comparison.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct CompareQuery {
    /// Job ids, comma-separated, 2 to 8; the first is the baseline (`ids=3,5`).
    #[param(pattern = "^[1-9][0-9]{0,18}(,[1-9][0-9]{0,18}){1,7}$")]
    ids: String,
}

/// Compare jobs.
#[utoipa::path(
    get, operation_id = "compare_jobs", path = "/v1/compare", tag = "jobs", params(CompareQuery),
    responses(
        (status = 200, description = "Per strategy, each job's figures and their ratios and differences against the first job's, with standard errors", body = Comparison),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "A job has no checkpoint yet", body = Problem, content_type = "application/problem+json"),
        BadQuery,
        ServerFailure,
    )
)]
pub async fn compare(
    State(state): State<AppState>,
    query: Result<Query<CompareQuery>, QueryRejection>,
) -> Result<Json<Comparison>, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let ids = parse_ids(&q.ids)?;
    let mut results = Vec::with_capacity(ids.len());
    for &id in &ids {
        results.push(state.statistics.result(id).await?);
    }
    let labels: Vec<String> = ids.iter().map(|id| format!("job {id}")).collect();
    let runs: Vec<Compared<'_>> = results
        .iter()
        .zip(&labels)
        .map(|(r, label)| Compared {
            label,
            rows: &r.report.noise_table,
            fingerprint: &r.report.fingerprint,
            coverage: &r.report.coverage,
        })
        .collect();
    Ok(Json(compare_runs(&runs)))
}

fn parse_ids(text: &str) -> Result<Vec<i64>, ApiError> {
    let invalid = |message: String| ApiError::Invalid { field: "ids".into(), message };
    let ids = text
        .split(',')
        .map(|s| s.trim().parse::<i64>().ok().filter(|&id| id > 0))
        .collect::<Option<Vec<i64>>>()
        .ok_or_else(|| invalid(format!("must be job ids separated by commas, got {text:?}")))?;
    if !(2..=MAX_COMPARED).contains(&ids.len()) {
        return Err(invalid(format!("compares 2 to {MAX_COMPARED} jobs, got {}", ids.len())));
    }
    Ok(ids)
}
