//! Request extractors whose failures are problem documents, like every other error, and whose work
//! is bounded.
//!
//! A body must arrive whole within the server's body timeout (a client trickling bytes holds a
//! connection for at most that long) and within its size limit. [`JsonBody`] parses it as JSON —
//! inline for small bodies, on the blocking pool above [`INLINE_PARSE_LIMIT`] so that no tokio
//! worker spends milliseconds parsing; a syntax error is a 400 that says where, and what the JSON
//! means is checked by the handlers (422). [`DocumentBody`] hands the bytes of a moments document
//! to the job layer, which parses them straight into typed values on its request pool. A document
//! body is read against a byte budget shared by all document requests
//! ([`super::AppState::document_memory`]), taken as its bytes arrive — so a client trickling a
//! body holds only what it sent — and only once it is whole does the request take one of the few
//! processing slots ([`super::AppState::documents`]): a slot is never held while waiting for a
//! client's bytes.

use std::time::Duration;

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use futures_util::StreamExt;
use serde_json::Value;
use tokio::sync::OwnedSemaphorePermit;

use super::AppState;
use super::error::ApiError;

/// Bodies up to this size are parsed on the worker that read them (microseconds); larger ones on
/// the blocking pool.
const INLINE_PARSE_LIMIT: usize = 64 << 10;

/// How long a document request, its body read, waits for a free processing slot before it is
/// told to retry.
const DOCUMENT_SLOT_WAIT: Duration = Duration::from_secs(10);

/// Reads the whole body within `timeout`, honouring the route's size limit.
async fn read_body(req: Request, state: &AppState) -> Result<Bytes, ApiError> {
    let timeout = state.body_timeout;
    let read = Bytes::from_request(req, state);
    let bytes = tokio::time::timeout(timeout, read)
        .await
        .map_err(|_| {
            ApiError::RequestTimeout(format!(
                "the request body did not arrive within {} s (--body-timeout)",
                timeout.as_secs_f64()
            ))
        })?
        .map_err(|e: BytesRejection| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::PayloadTooLarge(format!("the request body is too large: {e}"))
            } else {
                ApiError::MalformedJson(format!("the request body could not be read: {e}"))
            }
        })?;
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(ApiError::MalformedJson("the request body is empty; expected a JSON object".into()));
    }
    Ok(bytes)
}

/// A JSON request body, parsed but not interpreted.
pub struct JsonBody(pub Value);

impl FromRequest<AppState> for JsonBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Self::Rejection> {
        let bytes = read_body(req, state).await?;
        let small = bytes.len() <= INLINE_PARSE_LIMIT;
        let parse = move || {
            serde_json::from_slice(&bytes)
                .map(JsonBody)
                .map_err(|e| ApiError::MalformedJson(format!("the request body is not valid JSON: {e}")))
        };
        if small {
            return parse();
        }
        tokio::task::spawn_blocking(parse)
            .await
            .map_err(|_| ApiError::Internal("parsing a request body panicked".into()))?
    }
}

/// The bytes of a moments document (merges and studies), read under the document size limit and
/// the shared byte budget, then given one of the few processing slots.
pub struct DocumentBody {
    pub bytes: Bytes,
    /// Held until the handler has finished with the document.
    pub _slot: OwnedSemaphorePermit,
    /// The body's share of the byte budget, held as long as its bytes are.
    pub _memory: Vec<OwnedSemaphorePermit>,
}

/// Reads a document body chunk by chunk within the body timeout and the document size limit,
/// taking the byte budget for each chunk as it arrives.
async fn read_document(req: Request, state: &AppState) -> Result<(Bytes, Vec<OwnedSemaphorePermit>), ApiError> {
    let (timeout, limit) = (state.body_timeout, state.document_bytes);
    let read = async {
        let mut body = req.into_body().into_data_stream();
        let mut bytes = Vec::new();
        let mut memory = Vec::new();
        while let Some(chunk) = body.next().await {
            let chunk =
                chunk.map_err(|e| ApiError::MalformedJson(format!("the request body could not be read: {e}")))?;
            if bytes.len() + chunk.len() > limit {
                return Err(ApiError::PayloadTooLarge(format!(
                    "the request body is too large: more than {limit} bytes (--document-limit)"
                )));
            }
            let n = u32::try_from(chunk.len()).expect("a chunk is at most the document limit");
            memory.push(
                state
                    .document_memory
                    .clone()
                    .acquire_many_owned(n)
                    .await
                    .map_err(|_| ApiError::Unavailable("the server is shutting down".into()))?,
            );
            bytes.extend_from_slice(&chunk);
        }
        Ok((Bytes::from(bytes), memory))
    };
    let (bytes, memory) = tokio::time::timeout(timeout, read).await.map_err(|_| {
        ApiError::RequestTimeout(format!(
            "the request body did not arrive within {} s (--body-timeout)",
            timeout.as_secs_f64()
        ))
    })??;
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(ApiError::MalformedJson("the request body is empty; expected a JSON object".into()));
    }
    Ok((bytes, memory))
}

impl FromRequest<AppState> for DocumentBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Self::Rejection> {
        let (bytes, memory) = read_document(req, state).await?;
        let slot = tokio::time::timeout(DOCUMENT_SLOT_WAIT, state.documents.clone().acquire_owned())
            .await
            .map_err(|_| ApiError::TooManyRequests {
                detail: "the server is busy with other documents (--max-document-requests); retry".into(),
                retry_after_seconds: 5,
            })?
            .map_err(|_| ApiError::Unavailable("the server is shutting down".into()))?;
        Ok(DocumentBody { bytes, _slot: slot, _memory: memory })
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

/// The `{id}` of a sweep route. Anything that is not a sweep id names no sweep: 404.
pub struct SweepId(pub i64);

impl<S: Send + Sync> FromRequestParts<S> for SweepId {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let Path(raw): Path<String> = Path::from_request_parts(parts, state)
            .await
            .map_err(|e| ApiError::NotFound(format!("no such sweep: {e}")))?;
        raw.parse::<i64>()
            .ok()
            .filter(|id| *id > 0)
            .map(SweepId)
            .ok_or_else(|| ApiError::NotFound(format!("no sweep with id {raw:?}")))
    }
}

/// A list's page: `limit` (default `default`, at most `max`) and the `cursor` a previous page
/// returned (an id), both named in a 422 when invalid.
pub fn page(
    limit: Option<u32>,
    cursor: Option<String>,
    default: u32,
    max: u32,
) -> Result<(u32, Option<i64>), ApiError> {
    let limit = limit.unwrap_or(default);
    if !(1..=max).contains(&limit) {
        return Err(ApiError::Invalid {
            field: "limit".into(),
            message: format!("must be in [1, {max}], got {limit}"),
        });
    }
    let cursor = match cursor {
        None => None,
        Some(c) => Some(c.parse::<i64>().ok().filter(|&c| c > 0).ok_or_else(|| ApiError::Invalid {
            field: "cursor".into(),
            message: format!("not a cursor returned by this list: {c:?}"),
        })?),
    };
    Ok((limit, cursor))
}

/// Deserialises a typed request from a JSON value, naming the offending field on failure.
pub fn typed<T: serde::de::DeserializeOwned>(value: &Value) -> Result<T, ApiError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let message = e.into_inner().to_string();
        // serde reports a missing field at its parent's path: name the field itself.
        let missing = message.strip_prefix("missing field `").and_then(|m| m.split('`').next());
        let field = match (path.as_str(), missing) {
            (".", Some(name)) => name.to_string(),
            (".", None) => String::new(),
            (parent, Some(name)) => format!("{parent}.{name}"),
            (parent, None) => parent.to_string(),
        };
        ApiError::Invalid { field, message }
    })
}

/// A query-string rejection as a 422 naming the parameter (axum reports `name: reason`).
pub(super) fn query_problem(rejection: QueryRejection) -> ApiError {
    let text = rejection.body_text();
    let reason = text.strip_prefix("Failed to deserialize query string: ").unwrap_or(&text);
    match reason.split_once(": ") {
        Some((name, message)) if ["state", "limit", "cursor", "lambda", "format", "table"].contains(&name) => {
            ApiError::Invalid { field: name.into(), message: message.into() }
        }
        _ => ApiError::Invalid { field: "query".into(), message: reason.into() },
    }
}
