//! `GET /v1/compare?ids=…`: jobs compared strategy by strategy from their latest results — each
//! job's L and RMS, and against the first job the ratio and the difference of L and the ratio of
//! RMS with their standard errors and z (`sim::solve::compare`); or, as CSV, their noise tables
//! one row per job and strategy with each job's parameters in front (the dashboard's compare table,
//! docs/csv.md). Bounded: 2 to 8 jobs, each a stored result read.

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::HeaderMap;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::IntoParams;

use super::AppState;
use super::csv::{csv_response, wants_csv};
use super::error::{ApiError, Problem};
use super::extract::query_problem;
use super::responses::{BadQuery, ServerFailure};
use crate::sim::checks::published::paper_columns;
use crate::sim::math::csv::quoted;
use crate::sim::model::params::IlluminationSpec;
use crate::sim::solve::compare::{Compared, Comparison, MAX_COMPARED, compare as compare_runs};
use crate::sim::solve::export::{PaperColumns, compare_csv};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::JobSpec;

/// Query of a comparison.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct CompareQuery {
    /// Job ids, comma-separated, 2 to 8; the first is the baseline (`ids=3,5`).
    #[param(pattern = "^[1-9][0-9]{0,18}(,[1-9][0-9]{0,18}){1,7}$")]
    ids: String,
    /// `json` (the comparison) or `csv` (the jobs' noise tables, one row per job and strategy, the
    /// job's parameters in front); without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json)$")]
    format: Option<String>,
}

/// Compare jobs.
#[utoipa::path(
    get, operation_id = "compare_jobs", path = "/v1/compare", tag = "jobs", params(CompareQuery),
    responses(
        (status = 200, description = "Per strategy, each job's figures and their ratios and differences against the first job's, with standard errors; with format=csv the jobs' noise tables, one row per job and strategy (docs/csv.md, compare)", content(
            (Comparison = "application/json"),
            (String = "text/csv"))),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "A job has no checkpoint yet", body = Problem, content_type = "application/problem+json"),
        BadQuery,
        ServerFailure,
    )
)]
pub async fn compare(
    State(state): State<AppState>,
    headers: HeaderMap,
    query: Result<Query<CompareQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let ids = parse_ids(&q.ids)?;
    let csv = wants_csv(&headers, q.format.as_deref())?;
    let mut results = Vec::with_capacity(ids.len());
    for &id in &ids {
        results.push(state.services.statistics.result(id).await?);
    }
    if csv {
        let mut specs = Vec::with_capacity(ids.len());
        for &id in &ids {
            specs.push(state.services.jobs.get(id).await?.spec);
        }
        let rows = results.iter().zip(&specs).map(|(r, spec)| {
            let paper: Box<dyn Fn(&Strategy) -> PaperColumns + '_> =
                Box::new(move |s: &Strategy| paper_columns(&r.references, s.name()));
            (job_columns(r.job_id, spec, r.report.iterations), &r.report, paper)
        });
        let name = format!("optimis-compare-{}.csv", ids.iter().map(i64::to_string).collect::<Vec<_>>().join("-"));
        return Ok(csv_response(compare_csv(rows), &name));
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
    Ok(Json(compare_runs(&runs)).into_response())
}

/// A job's cells of `JOB_COLUMNS`, as the dashboard's compare table writes them.
fn job_columns(id: i64, spec: &JobSpec, iterations: u64) -> [String; 10] {
    let (kind, spot) = match &spec.scene.illumination {
        IlluminationSpec::Spot { a, .. } => ("spot", a.to_string()),
        IlluminationSpec::Uniform { .. } => ("uniform", String::new()),
        IlluminationSpec::Rings { .. } => ("rings", String::new()),
    };
    let engine = serde_json::to_value(spec.engine).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default();
    [
        id.to_string(),
        quoted(&spec.preset),
        kind.to_string(),
        spot,
        engine,
        spec.light_paths.to_string(),
        spec.camera_paths.to_string(),
        spec.merge_radius.to_string(),
        iterations.to_string(),
        spec.seed.to_string(),
    ]
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
