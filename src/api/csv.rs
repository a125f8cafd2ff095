//! CSV answers: whether a request asks for CSV (`?format=csv`, or `Accept: text/csv` before any
//! JSON type), and the response that carries a CSV document as a download.

use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};

use super::error::ApiError;

/// Whether the answer is CSV: `format` (`csv` or `json`) decides, else `Accept`.
pub fn wants_csv(headers: &HeaderMap, format: Option<&str>) -> Result<bool, ApiError> {
    match format {
        Some("csv") => Ok(true),
        Some("json") => Ok(false),
        Some(other) => {
            Err(ApiError::Invalid { field: "format".into(), message: format!("must be csv or json, got {other:?}") })
        }
        None => Ok(accepts_csv(headers)),
    }
}

/// Whether `Accept` names text/csv before any JSON type (or `*/*`).
fn accepts_csv(headers: &HeaderMap) -> bool {
    let Some(accept) = headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()) else { return false };
    for part in accept.split(',') {
        let media = part.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
        match media.as_str() {
            "text/csv" => return true,
            "application/json" | "*/*" => return false,
            _ => {}
        }
    }
    false
}

/// A CSV document as a download named `filename` (ASCII).
pub fn csv_response(text: String, filename: &str) -> Response {
    let disposition = HeaderValue::from_str(&format!("attachment; filename=\"{filename}\"")).expect("an ASCII name");
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("text/csv; charset=utf-8; header=present")),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        text,
    )
        .into_response()
}
