//! Bearer-token authentication and the limit on open event streams.
//!
//! With a token configured, every request needs `Authorization: Bearer <token>` except the
//! liveness and readiness probes and the dashboard's static files (which hold no data: the page
//! asks for the token and sends it with every API call). Tokens are compared as SHA-256 digests in
//! constant time, so neither the content nor the length of the secret leaks through timing.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use axum::extract::{Request, State};
use axum::http::{HeaderMap, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

use super::AppState;
use super::error::ApiError;

/// Paths open without a token.
pub fn is_public(path: &str) -> bool {
    matches!(path, "/healthz" | "/readyz" | "/") || path.starts_with("/assets/")
}

/// The SHA-256 digest of a token, what requests are compared against.
pub fn digest(token: &str) -> [u8; 32] {
    Sha256::digest(token.as_bytes()).into()
}

fn bearer(headers: &HeaderMap) -> Option<&str> {
    let value = headers.get(header::AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = value.split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
}

/// Middleware: refuses requests without the right bearer token (when one is configured).
pub async fn authenticate(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let Some(expected) = &state.token_digest else {
        return next.run(request).await;
    };
    if is_public(request.uri().path()) {
        return next.run(request).await;
    }
    match bearer(request.headers()) {
        Some(given) if bool::from(digest(given).ct_eq(expected)) => next.run(request).await,
        Some(_) => ApiError::Unauthorized("the bearer token is not valid".into()).into_response(),
        None => ApiError::Unauthorized("this server requires `Authorization: Bearer <token>`".into()).into_response(),
    }
}

/// A bounded number of open event streams.
#[derive(Debug)]
pub struct StreamSlots {
    open: AtomicUsize,
    max: usize,
}

/// One open stream; frees its slot when dropped (when the stream ends or the client leaves).
#[derive(Debug)]
pub struct StreamSlot(Arc<StreamSlots>);

impl StreamSlots {
    pub fn new(max: usize) -> Arc<Self> {
        Arc::new(Self { open: AtomicUsize::new(0), max })
    }

    /// A slot, or 429 with Retry-After when all are taken.
    pub fn acquire(self: &Arc<Self>) -> Result<StreamSlot, ApiError> {
        let taken = self.open.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| (n < self.max).then_some(n + 1));
        match taken {
            Ok(_) => Ok(StreamSlot(self.clone())),
            Err(n) => Err(ApiError::TooManyRequests {
                detail: format!(
                    "{n} event streams are open, the most this server allows (--max-event-streams); poll instead or retry"
                ),
                retry_after_seconds: 5,
            }),
        }
    }
}

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.open.fetch_sub(1, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_bounded_and_freed() {
        let slots = StreamSlots::new(2);
        let a = slots.acquire().unwrap();
        let _b = slots.acquire().unwrap();
        assert!(matches!(slots.acquire(), Err(ApiError::TooManyRequests { .. })));
        drop(a);
        assert!(slots.acquire().is_ok());
    }

    #[test]
    fn bearer_tokens_are_parsed_and_public_paths_known() {
        let mut headers = HeaderMap::new();
        headers.insert(header::AUTHORIZATION, "Bearer s3cret".parse().unwrap());
        assert_eq!(bearer(&headers), Some("s3cret"));
        headers.insert(header::AUTHORIZATION, "Basic s3cret".parse().unwrap());
        assert_eq!(bearer(&headers), None);
        assert!(
            is_public("/healthz") && is_public("/assets/app.js") && !is_public("/metrics") && !is_public("/v1/jobs")
        );
        assert!(bool::from(digest("a").ct_eq(&digest("a"))) && !bool::from(digest("a").ct_eq(&digest("b"))));
    }
}
