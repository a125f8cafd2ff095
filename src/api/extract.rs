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
//! ([`super::AppState::document_memory`]) and its client's share of it
//! ([`super::AppState::document_shares`]), taken as its bytes arrive — so a client trickling a
//! body holds only what it sent, and no client more than one document's worth. The job layer
//! takes one of its few processing slots only while it parses or merges, never while it waits
//! for a client's bytes or a peer's.

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use futures_util::StreamExt;
use serde_json::Value;
use tokio::sync::{OwnedSemaphorePermit, TryAcquireError};

use super::AppState;
use super::error::ApiError;
use crate::jobs::merges::shares::{ClientKey, Share};

/// Bodies up to this size are parsed on the worker that read them (microseconds); larger ones on
/// the blocking pool.
const INLINE_PARSE_LIMIT: usize = 64 << 10;

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

/// The bytes of a moments document (merges and studies), read under the document size limit,
/// the shared byte budget and the client's share of it.
pub struct DocumentBody {
    pub bytes: Bytes,
    /// Whose request it is (for the shares of what its handling pulls or computes).
    pub client: ClientKey,
    /// The body's share of the byte budget, held as long as its bytes are.
    pub _memory: Vec<OwnedSemaphorePermit>,
    /// Its client's share of that budget, held as long.
    pub _share: Share,
}

/// Reads a document body chunk by chunk within the body timeout and the document size limit,
/// taking the byte budget for each chunk as it arrives — first from the client's share (one
/// document limit: a client that holds more is refused at once, so that five stalled uploads of
/// one client cannot hold what every other client needs), then from the server's budget (when it
/// is spent by other clients' bodies, 429 at once: waiting would let the body timeout blame the
/// client that waited).
async fn read_document(req: Request, state: &AppState) -> Result<DocumentBody, ApiError> {
    let (timeout, limit) = (state.body_timeout, state.document_bytes);
    let client = req.extensions().get::<ClientKey>().copied().unwrap_or_default();
    let read = async {
        let mut body = req.into_body().into_data_stream();
        let mut bytes = Vec::new();
        let mut memory = Vec::new();
        let mut share = state.document_shares.open(client);
        while let Some(chunk) = body.next().await {
            let chunk =
                chunk.map_err(|e| ApiError::MalformedJson(format!("the request body could not be read: {e}")))?;
            if bytes.len() + chunk.len() > limit {
                return Err(ApiError::PayloadTooLarge(format!(
                    "the request body is too large: more than {limit} bytes (--document-limit)"
                )));
            }
            if !share.grow(chunk.len()) {
                return Err(ApiError::TooManyRequests {
                    detail: format!(
                        "{client} is already sending {} bytes of other documents, its share of what this server \
                         reads at once (one --document-limit); send one document at a time",
                        state.document_shares.held_by(client)
                    ),
                    retry_after_seconds: 5,
                });
            }
            let n = u32::try_from(chunk.len()).expect("a chunk is at most the document limit");
            match state.document_memory.clone().try_acquire_many_owned(n) {
                Ok(permit) => memory.push(permit),
                Err(TryAcquireError::NoPermits) => {
                    return Err(ApiError::TooManyRequests {
                        detail: "the server is reading as many documents of other clients as it holds at once; retry"
                            .into(),
                        retry_after_seconds: 5,
                    });
                }
                Err(TryAcquireError::Closed) => {
                    return Err(ApiError::Unavailable("the server is shutting down".into()));
                }
            }
            bytes.extend_from_slice(&chunk);
        }
        Ok(DocumentBody { bytes: Bytes::from(bytes), client, _memory: memory, _share: share })
    };
    let body = tokio::time::timeout(timeout, read).await.map_err(|_| {
        ApiError::RequestTimeout(format!(
            "the request body did not arrive within {} s (--body-timeout)",
            timeout.as_secs_f64()
        ))
    })??;
    if body.bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(ApiError::MalformedJson("the request body is empty; expected a JSON object".into()));
    }
    Ok(body)
}

impl FromRequest<AppState> for DocumentBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Self::Rejection> {
        read_document(req, state).await
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
        Some((name, message))
            if ["state", "limit", "cursor", "lambda", "format", "table", "strategy"].contains(&name) =>
        {
            ApiError::Invalid { field: name.into(), message: message.into() }
        }
        _ => ApiError::Invalid { field: "query".into(), message: reason.into() },
    }
}
