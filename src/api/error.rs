//! The one place where failures become HTTP responses: RFC 9457 problem details
//! (`application/problem+json`), each variant documented with its status.
//!
//! Client errors carry a `detail` naming the offending field; infrastructure errors are logged in
//! full and answered with a generic 500 (or 503) whose text never leaks internals.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::jobs::JobError;
use crate::sim::document::DocumentError;
use crate::sim::spec::SpecError;
use crate::sim::stats::moments::MergeError;
use crate::store::StoreError;

/// Media type of every error body.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// An RFC 9457 problem document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Problem {
    /// A URI identifying the kind of problem (`urn:problem-type:optimis:…`).
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary of the kind of problem.
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What went wrong in this request, naming the offending field where there is one.
    pub detail: String,
    /// JSON path of the offending field or parameter, when the problem is about one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

/// Every error the API answers with.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// 400: the body is not JSON (or not readable).
    #[error("{0}")]
    MalformedJson(String),
    /// 422: a field or parameter is invalid; `field` names it.
    #[error("{field}: {message}")]
    Invalid {
        /// JSON path of the offending field or parameter (`scene.l3`, `axes[1].values[2]`); empty
        /// when the problem is the body as a whole (the problem then has no `field`).
        field: String,
        /// What is wrong with the value; the problem's `detail` is `field: message`.
        message: String,
    },
    /// 404: no such job or route.
    #[error("{0}")]
    NotFound(String),
    /// 405: the route exists, the method does not.
    #[error("method not allowed on this route")]
    MethodNotAllowed,
    /// 409: the job's state does not allow the operation.
    #[error("{0}")]
    Conflict(String),
    /// 413: the body is larger than the server accepts.
    #[error("{0}")]
    PayloadTooLarge(String),
    /// 401: the route needs `Authorization: Bearer <token>` and none or a wrong one came.
    #[error("{0}")]
    Unauthorized(String),
    /// 403: a cross-origin request (another site's page), or a `Host` this server does not answer
    /// to (DNS rebinding).
    #[error("{0}")]
    Forbidden(String),
    /// 408: the request body did not arrive in time.
    #[error("{0}")]
    RequestTimeout(String),
    /// 415: a body that is not `application/json`.
    #[error("{0}")]
    UnsupportedMediaType(String),
    /// 429: a limit is reached (queue, event streams); retry after the given seconds.
    #[error("{detail}")]
    TooManyRequests {
        /// Which limit was reached (the queue, the heavy computations, the pulls from peers); the
        /// problem's `detail`.
        detail: String,
        /// Seconds to wait before retrying, sent as the `Retry-After` header.
        retry_after_seconds: u64,
    },
    /// 503: shutting down, or the database is busy; retry later.
    #[error("{0}")]
    Unavailable(String),
    /// 503 with Retry-After: the database cannot store anything right now (disk full, I/O error);
    /// nothing was acknowledged.
    #[error("{detail}")]
    StorageUnavailable {
        /// What failed, in general terms (never the database's own message); the problem's
        /// `detail`.
        detail: String,
        /// Seconds to wait before retrying, sent as the `Retry-After` header.
        retry_after_seconds: u64,
    },
    /// 500: a bug or an infrastructure failure; logged, never described to the client.
    #[error("internal error: {0}")]
    Internal(String),
}

impl From<SpecError> for ApiError {
    fn from(e: SpecError) -> Self {
        ApiError::Invalid { field: e.field, message: e.message }
    }
}

impl From<JobError> for ApiError {
    fn from(e: JobError) -> Self {
        match e {
            JobError::Invalid(s) => s.into(),
            JobError::Malformed(m) => ApiError::MalformedJson(m),
            JobError::NotFound(id) => ApiError::NotFound(format!("no job with id {id}")),
            JobError::SweepNotFound(id) => ApiError::NotFound(format!("no sweep with id {id}")),
            JobError::Conflict(m) => ApiError::Conflict(m),
            JobError::Document(
                e @ DocumentError::Merge(
                    MergeError::Overlap(_) | MergeError::Fingerprint { .. } | MergeError::FormatMix { .. },
                ),
            ) => ApiError::Conflict(format!("the statistics cannot be merged: {e}")),
            JobError::Document(e) => ApiError::Invalid { field: String::new(), message: e.to_string() },
            JobError::Peer { field, message } => ApiError::Invalid { field, message },
            JobError::PeerNotAllowed { field, message } => ApiError::Forbidden(format!("{field}: {message}")),
            JobError::Busy { detail, retry_after_seconds } => ApiError::TooManyRequests { detail, retry_after_seconds },
            JobError::ShuttingDown => {
                ApiError::Unavailable("the server is shutting down; retry on its successor".into())
            }
            JobError::Store(e) if e.is_storage_failure() => ApiError::StorageUnavailable {
                detail: "the database cannot store anything right now (disk full or an I/O error); nothing was \
                         changed; retry later"
                    .into(),
                retry_after_seconds: 30,
            },
            JobError::Store(e) if e.is_transient() => {
                ApiError::Unavailable(format!("the database is busy; retry ({e})"))
            }
            // A corrupted checkpoint is reported for that job; it says nothing about internals.
            JobError::Store(e @ StoreError::Corrupt { .. }) => ApiError::Conflict(e.to_string()),
            JobError::Store(e) => ApiError::Internal(e.to_string()),
            JobError::Internal(m) | JobError::Simulation(m) | JobError::Execution(m) => ApiError::Internal(m),
        }
    }
}

impl ApiError {
    fn status(&self) -> StatusCode {
        match self {
            ApiError::MalformedJson(_) => StatusCode::BAD_REQUEST,
            ApiError::Invalid { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::NotFound(_) => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::Conflict(_) => StatusCode::CONFLICT,
            ApiError::PayloadTooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::Forbidden(_) => StatusCode::FORBIDDEN,
            ApiError::RequestTimeout(_) => StatusCode::REQUEST_TIMEOUT,
            ApiError::UnsupportedMediaType(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::TooManyRequests { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::Unavailable(_) | ApiError::StorageUnavailable { .. } => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    fn slug(&self) -> &'static str {
        match self {
            ApiError::MalformedJson(_) => "malformed-json",
            ApiError::Invalid { .. } => "invalid-field",
            ApiError::NotFound(_) => "not-found",
            ApiError::MethodNotAllowed => "method-not-allowed",
            ApiError::Conflict(_) => "conflict",
            ApiError::PayloadTooLarge(_) => "payload-too-large",
            ApiError::Unauthorized(_) => "unauthorized",
            ApiError::Forbidden(_) => "forbidden",
            ApiError::RequestTimeout(_) => "request-timeout",
            ApiError::UnsupportedMediaType(_) => "unsupported-media-type",
            ApiError::TooManyRequests { .. } => "too-many-requests",
            ApiError::Unavailable(_) => "unavailable",
            ApiError::StorageUnavailable { .. } => "storage-unavailable",
            ApiError::Internal(_) => "internal",
        }
    }

    /// The problem document of this error.
    pub fn problem(&self) -> Problem {
        let status = self.status();
        let (detail, field) = match self {
            ApiError::Invalid { field, message } => {
                let detail = if field.is_empty() { message.clone() } else { format!("{field}: {message}") };
                (detail, Some(field.clone()).filter(|f| !f.is_empty()))
            }
            ApiError::Internal(_) => {
                ("the server failed to handle the request; the failure has been logged".into(), None)
            }
            other => (other.to_string(), None),
        };
        Problem {
            kind: format!("urn:problem-type:optimis:{}", self.slug()),
            title: status.canonical_reason().unwrap_or("Error").to_string(),
            status: status.as_u16(),
            detail,
            field,
        }
    }
}

/// A problem document as a response.
pub fn problem_response(problem: &Problem) -> Response {
    let status = StatusCode::from_u16(problem.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
    let body = serde_json::to_vec(problem).unwrap_or_default();
    let mut response = (status, body).into_response();
    response.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
    response
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if let ApiError::Internal(reason) = &self {
            tracing::error!(%reason, "internal error");
        }
        let mut response = problem_response(&self.problem());
        match &self {
            ApiError::TooManyRequests { retry_after_seconds, .. }
            | ApiError::StorageUnavailable { retry_after_seconds, .. } => {
                response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(*retry_after_seconds));
            }
            ApiError::Unauthorized(_) => {
                response
                    .headers_mut()
                    .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer realm=\"optimis\""));
            }
            _ => {}
        }
        response
    }
}

#[cfg(test)]
mod tests;
