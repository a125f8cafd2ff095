//! The built-in dashboard: one HTML page, its script (plain ES modules, no build step) and style,
//! and the vendored plotting library (uPlot), all compiled into the binary — no CDN, nothing
//! fetched from the internet.
//!
//! The page is a client of the public API (`/v1/jobs…`, Server-Sent Events); it has no routes of
//! its own beyond its files. A Content-Security-Policy keeps it to this origin.

use axum::extract::Path;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

use super::error::{ApiError, Problem};

const JS: &str = "text/javascript; charset=utf-8";

/// (name, media type, bytes) of every asset under `/assets/`.
const ASSETS: &[(&str, &str, &[u8])] = &[
    // The script: ES modules, app.js the entry, which imports the others by relative name.
    ("app.js", JS, include_bytes!("dashboard/app.js")),
    ("axes.js", JS, include_bytes!("dashboard/axes.js")),
    ("api.js", JS, include_bytes!("dashboard/api.js")),
    ("format.js", JS, include_bytes!("dashboard/format.js")),
    ("csv.js", JS, include_bytes!("dashboard/csv.js")),
    ("csvtables.js", JS, include_bytes!("dashboard/csvtables.js")),
    ("paper.js", JS, include_bytes!("dashboard/paper.js")),
    ("chartkit.js", JS, include_bytes!("dashboard/chartkit.js")),
    ("chartfiles.js", JS, include_bytes!("dashboard/chartfiles.js")),
    ("chartsvg.js", JS, include_bytes!("dashboard/chartsvg.js")),
    ("plots.js", JS, include_bytes!("dashboard/plots.js")),
    ("fig2.js", JS, include_bytes!("dashboard/fig2.js")),
    ("noisetable.js", JS, include_bytes!("dashboard/noisetable.js")),
    ("results.js", JS, include_bytes!("dashboard/results.js")),
    ("budget.js", JS, include_bytes!("dashboard/budget.js")),
    ("budgetplan.js", JS, include_bytes!("dashboard/budgetplan.js")),
    ("errorplan.js", JS, include_bytes!("dashboard/errorplan.js")),
    ("radiitable.js", JS, include_bytes!("dashboard/radiitable.js")),
    ("solves.js", JS, include_bytes!("dashboard/solves.js")),
    ("form.js", JS, include_bytes!("dashboard/form.js")),
    ("specfields.js", JS, include_bytes!("dashboard/specfields.js")),
    ("list.js", JS, include_bytes!("dashboard/list.js")),
    ("job.js", JS, include_bytes!("dashboard/job.js")),
    ("compare.js", JS, include_bytes!("dashboard/compare.js")),
    ("sweepdata.js", JS, include_bytes!("dashboard/sweepdata.js")),
    ("sweepplots.js", JS, include_bytes!("dashboard/sweepplots.js")),
    ("sweepw1.js", JS, include_bytes!("dashboard/sweepw1.js")),
    ("sweeps.js", JS, include_bytes!("dashboard/sweeps.js")),
    ("sweep.js", JS, include_bytes!("dashboard/sweep.js")),
    ("app.css", "text/css; charset=utf-8", include_bytes!("dashboard/app.css")),
    ("uPlot.iife.min.js", JS, include_bytes!("dashboard/vendor/uPlot.iife.min.js")),
    ("uPlot.min.css", "text/css; charset=utf-8", include_bytes!("dashboard/vendor/uPlot.min.css")),
];

const INDEX: &[u8] = include_bytes!("dashboard/index.html");

/// Everything from this origin only; inline styles are allowed for uPlot's sizing.
const CSP: &str = "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; object-src 'none'; \
                   base-uri 'none'; frame-ancestors 'none'";

fn asset_response(media_type: &'static str, body: &'static [u8]) -> Response {
    let mut response = body.into_response();
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(media_type));
    // The files change only with the binary; revalidation is cheap on loopback.
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(header::CONTENT_SECURITY_POLICY, HeaderValue::from_static(CSP));
    headers.insert(header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    response
}

/// The dashboard.
#[utoipa::path(
    get, operation_id = "dashboard", path = "/", tag = "dashboard",
    responses((status = 200, description = "The dashboard page", content_type = "text/html", body = String))
)]
pub async fn index() -> Response {
    asset_response("text/html; charset=utf-8", INDEX)
}

/// A file of the dashboard.
#[utoipa::path(
    get, operation_id = "dashboard_asset", path = "/assets/{name}", tag = "dashboard", params(("name" = String, Path, description = "File name")),
    responses(
        (status = 200, description = "The file", content_type = "text/plain", body = String),
        (status = 404, description = "No such file", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn asset(Path(name): Path<String>) -> Result<Response, ApiError> {
    ASSETS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, media_type, body)| asset_response(media_type, body))
        .ok_or_else(|| ApiError::NotFound(format!("no dashboard file {name:?}")))
}
