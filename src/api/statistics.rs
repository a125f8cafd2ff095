//! Handlers of a job's statistics: its result (JSON or CSV tables), re-solves, evaluations of
//! given weights, the moments export and the history. Each only translates between HTTP and the
//! handles it takes (`State<Statistics>`, `State<Evaluations>`).

use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::IntoParams;

use super::AppState;
use super::bodies::SolverPatch;
use super::csv::{csv_response, wants_csv};
use super::error::{ApiError, Problem};
use super::extract::{JobId, JsonBody, query_problem, typed};
use super::responses::{BadQuery, NoSuchJob, NotJson, ServerFailure, TooLarge};
use crate::jobs::core::documents::{JobHistory, JobResult};
use crate::jobs::evaluation::Evaluations;
use crate::jobs::evaluation::JobEvaluation;
use crate::jobs::statistics::Statistics;
use crate::sim::checks::published::{figures, paper_columns};
use crate::sim::document::MomentsDocument;
use crate::sim::solve::evaluate::GivenWeights;
use crate::sim::solve::export::{effective_csv, noise_table_csv, weights_csv};
use crate::sim::solve::strategy::Strategy;
use crate::sim::solve::tables::{TextTable, noise_table_latex, noise_table_markdown, parse_rows};
use crate::sim::weights::effective::EFFECTIVE_PATHS;

/// Query of a job's result.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ResultQuery {
    /// Show the weights fitted in-sample on all iterations at this λ (e.g. `0`, the paper's
    /// procedure) instead of the recommended weights; the noise table is the same.
    #[param(minimum = 0.0, maximum = 1e12)]
    lambda: Option<f64>,
    /// `csv`, `json`, or the noise table as `markdown` or `latex` (a plain `tabular`, for a paper);
    /// without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json|markdown|latex)$")]
    format: Option<String>,
    /// With CSV: `noise` (default; one row per strategy), `weights` (the weights table, one row
    /// per cell, its `table` column saying which table it is; for a per-path recommendation, which
    /// has no table, the effective weights) or `effective` (the recommended row's effective
    /// weights, one row per (r2, r3) bin; its weight function itself: `GET /v1/jobs/{id}/weights`).
    #[param(pattern = "^(noise|weights|effective)$")]
    table: Option<String>,
    /// With `markdown` or `latex`: the rows to show, in this order (`switch,optimal_cv`; default:
    /// every row). The recommended row is marked either way.
    #[param(max_length = 1000, pattern = "^[a-z0-9_, ]+$")]
    rows: Option<String>,
    /// With `markdown` or `latex`: the caption (default: one that says the units and the marks);
    /// LaTeX's special characters are escaped.
    #[param(max_length = 500)]
    caption: Option<String>,
    /// With `latex`: the bare `tabular`, without the `table` float and its caption.
    bare: Option<bool>,
}

/// Query of a job's history.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct HistoryQuery {
    /// `csv` or `json`; without it, `Accept: text/csv` asks for CSV.
    #[param(pattern = "^(csv|json)$")]
    format: Option<String>,
}

/// The job's noise and weights tables from its latest checkpoint (`partial` until it succeeded).
#[utoipa::path(
    get, operation_id = "get_result", path = "/v1/jobs/{id}/result", tag = "jobs", params(("id" = i64, Path, description = "Job id"), ResultQuery),
    responses(
        (status = 200, description = "Results: the result document, or with format=csv one of its tables (noise: one row per strategy; weights: one row per cell, or for a per-path recommendation the effective weights; effective: one row per (r2, r3) bin; the columns and units of docs/csv.md)", content(
            (JobResult = "application/json"),
            (String = "text/csv"),
            (String = "text/markdown"),
            (String = "application/x-latex"))),
        NoSuchJob,
        (status = 409, description = "No checkpoint yet", body = Problem, content_type = "application/problem+json"),
        BadQuery,
        ServerFailure,
    )
)]
pub async fn result(
    State(state): State<AppState>,
    JobId(id): JobId,
    headers: HeaderMap,
    query: Result<Query<ResultQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let text = match q.format.as_deref() {
        Some(f @ ("markdown" | "latex")) => Some(f.to_string()),
        _ => None,
    };
    if text.is_none() {
        let given = [("rows", q.rows.is_some()), ("caption", q.caption.is_some()), ("bare", q.bare.is_some())];
        if let Some((field, _)) = given.into_iter().find(|(_, given)| *given) {
            return Err(ApiError::Invalid {
                field: field.into(),
                message: "applies to the text tables only (format=markdown or format=latex)".into(),
            });
        }
    }
    let csv = text.is_none() && wants_csv(&headers, q.format.as_deref())?;
    let result = match q.lambda {
        None => state.services.statistics.result(id).await?,
        Some(lambda) => state.services.statistics.solve(id, &serde_json::json!({}), Some(lambda)).await?,
    };
    if let Some(format) = text {
        if q.table.as_deref().is_some_and(|t| t != "noise") {
            return Err(ApiError::Invalid {
                field: "table".into(),
                message: format!("{format} has the noise table only"),
            });
        }
        let paper = |s: &Strategy| figures(&result.references, s.name());
        let table = &result.report.noise_table;
        let rows = match q.rows.as_deref() {
            Some(list) => Some(
                parse_rows(list, table)
                    .map_err(|e| ApiError::Invalid { field: "rows".into(), message: e.to_string() })?,
            ),
            None => None,
        };
        if let Some(caption) = q.caption.as_deref().filter(|c| c.chars().count() > 500) {
            return Err(ApiError::Invalid {
                field: "caption".into(),
                message: format!("at most 500 characters, got {}", caption.chars().count()),
            });
        }
        let opts = TextTable {
            rows,
            recommended: result.report.recommended.as_ref().map(|r| r.strategy),
            caption: q.caption.clone(),
            bare: q.bare.unwrap_or(false),
        };
        let (body, media) = if format == "latex" {
            (noise_table_latex(table, paper, &opts), "application/x-latex; charset=utf-8")
        } else {
            (noise_table_markdown(table, paper, &opts), "text/markdown; charset=utf-8")
        };
        return Ok(([(header::CONTENT_TYPE, HeaderValue::from_static(media))], body).into_response());
    }
    match (csv, q.table.as_deref()) {
        (false, None) => Ok(Json(result).into_response()),
        (false, Some(_)) => {
            Err(ApiError::Invalid { field: "table".into(), message: "applies to CSV only (format=csv)".into() })
        }
        (true, None | Some("noise")) => {
            let csv = noise_table_csv(&result.report, |s| paper_columns(&result.references, s.name()));
            Ok(csv_response(csv, &format!("optimis-job-{id}-noise.csv")))
        }
        // A per-path recommendation has no table: its effective weights, labelled, rather than an
        // empty file a renderer would read as "no weights".
        (true, Some("weights")) if !result.report.weights.is_empty() => {
            Ok(csv_response(weights_csv(&result.report), &format!("optimis-job-{id}-weights.csv")))
        }
        (true, Some("weights" | "effective")) => {
            let effective = state.services.artifacts.effective(id, None, EFFECTIVE_PATHS).await?;
            Ok(csv_response(effective_csv(&effective), &format!("optimis-job-{id}-effective.csv")))
        }
        (true, Some(other)) => Err(ApiError::Invalid {
            field: "table".into(),
            message: format!("must be noise, weights or effective, got {other:?}"),
        }),
    }
}

/// Re-solve the stored moments with other solver options; nothing is re-run or stored.
#[utoipa::path(
    post, operation_id = "solve_job", path = "/v1/jobs/{id}/solve", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = SolverPatch, description = "Solver options to change"),
    responses(
        (status = 200, description = "Results with these options", body = JobResult),
        NotJson,
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "An option is invalid", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn solve(
    State(statistics): State<Statistics>,
    JobId(id): JobId,
    JsonBody(patch): JsonBody,
) -> Result<Json<JobResult>, ApiError> {
    Ok(Json(statistics.solve(id, &patch, None).await?))
}

/// Score given weights on the job's latest checkpoint: another run's `/result` (its recommended
/// table, heuristics stacked on it included) or a table of one's own (`weights`, `heuristics`);
/// L, RMS and their standard errors beside the job's per-path strategies, each with the paired
/// variance ratio. Nothing is run or stored.
#[utoipa::path(
    post, operation_id = "evaluate_weights", path = "/v1/jobs/{id}/evaluate", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    request_body(content = GivenWeights, description = "The weights: a result document, or `weights` (one entry per cell of the job's grid) and `heuristics`"),
    responses(
        (status = 200, description = "The weights' figures on this job's iterations", body = JobEvaluation),
        NotJson,
        NoSuchJob,
        (status = 409, description = "No checkpoint yet", body = Problem, content_type = "application/problem+json"),
        TooLarge,
        (status = 422, description = "The weights do not fit this job (another grid, a heuristic without a column, cells that do not sum to 1 − Σβ); `field` names the part", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn evaluate(
    State(evaluations): State<Evaluations>,
    JobId(id): JobId,
    JsonBody(body): JsonBody,
) -> Result<Json<JobEvaluation>, ApiError> {
    let given: GivenWeights = typed(&body)?;
    Ok(Json(evaluations.evaluate(id, given).await?))
}

/// The job's moments (additive statistics) from its latest checkpoint, as a checksummed document.
#[utoipa::path(
    get, operation_id = "get_moments", path = "/v1/jobs/{id}/moments", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The moments document (with a Content-Disposition naming the file)", body = MomentsDocument,
            headers(("Content-Disposition" = String, description = "attachment; filename=\"optimis-job-ID-moments.json\""))),
        NoSuchJob,
        (status = 409, description = "No checkpoint yet, or it is corrupted", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn moments(State(statistics): State<Statistics>, JobId(id): JobId) -> Result<Response, ApiError> {
    // Serialised on the job layer's request pool (a document can be megabytes), sent as is.
    let bytes = statistics.moments_json(id).await?;
    let disposition = HeaderValue::from_str(&format!("attachment; filename=\"optimis-job-{id}-moments.json\""))
        .expect("an ASCII header");
    Ok((
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("application/json")),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        bytes,
    )
        .into_response())
}

/// Each strategy's luminance and RMS at every checkpoint (at most 1,000 points, evenly thinned).
#[utoipa::path(
    get, operation_id = "get_history", path = "/v1/jobs/{id}/history", tag = "jobs", params(("id" = i64, Path, description = "Job id"), HistoryQuery),
    responses(
        (status = 200, description = "The history, oldest checkpoint first (CSV with format=csv: iterations, strategy, luminance, rms_percent)", content(
            (JobHistory = "application/json"),
            (String = "text/csv"))),
        BadQuery,
        NoSuchJob,
        ServerFailure,
    )
)]
pub async fn history(
    State(statistics): State<Statistics>,
    JobId(id): JobId,
    headers: HeaderMap,
    query: Result<Query<HistoryQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(query_problem)?;
    let csv = wants_csv(&headers, q.format.as_deref())?;
    let history = statistics.history(id).await?;
    if csv {
        return Ok(csv_response(history.to_csv(), &format!("optimis-job-{id}-history.csv")));
    }
    Ok(Json(history).into_response())
}
