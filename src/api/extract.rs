//! Request extractors whose failures are problem documents, like every other error.
//!
//! Bodies are read as JSON whatever their Content-Type (curl's `-d` sends a form type), and a
//! syntax error is a 400 that says where; what the JSON means is checked by the handlers (422).

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use serde_json::Value;

use super::error::ApiError;

/// A JSON request body, parsed but not interpreted.
pub struct JsonBody(pub Value);

impl<S: Send + Sync> FromRequest<S> for JsonBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let bytes = Bytes::from_request(req, state).await.map_err(|e: BytesRejection| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::PayloadTooLarge(format!("the request body is too large: {e}"))
            } else {
                ApiError::MalformedJson(format!("the request body could not be read: {e}"))
            }
        })?;
        if bytes.iter().all(u8::is_ascii_whitespace) {
            return Err(ApiError::MalformedJson("the request body is empty; expected a JSON object".into()));
        }
        serde_json::from_slice(&bytes)
            .map(JsonBody)
            .map_err(|e| ApiError::MalformedJson(format!("the request body is not valid JSON: {e}")))
    }
}

/// The `{id}` of a job route. Anything that is not a job id names no job: 404.
pub struct JobId(pub i64);

impl<S: Send + Sync> FromRequestParts<S> for JobId {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let Path(raw): Path<String> = Path::from_request_parts(parts, state)
            .await
            .map_err(|e| ApiError::NotFound(format!("no such job: {e}")))?;
        raw.parse::<i64>()
            .ok()
            .filter(|id| *id > 0)
            .map(JobId)
            .ok_or_else(|| ApiError::NotFound(format!("no job with id {raw:?}")))
    }
}

/// Deserialises a typed request from a JSON value, naming the offending field on failure.
pub fn typed<T: serde::de::DeserializeOwned>(value: &Value) -> Result<T, ApiError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        ApiError::Invalid { field: if path == "." { String::new() } else { path }, message: e.into_inner().to_string() }
    })
}
