//! What one client may ask of the HTTP API — body sizes, event streams, concurrent document
//! requests, the body timeout — and the bearer token that guards it. The server passes these
//! through unchanged; connection-level bounds live with the listener, job limits in the run policy.

use std::sync::Arc;
use std::time::Duration;

/// Body limit of the routes that take moments documents (which grow with the cell grid): 32 MiB,
/// several times the largest document a single job can export (docs/results.md), and what the
/// document parser may be asked to hold per request.
pub const DEFAULT_DOCUMENT_LIMIT: usize = 32 << 20;

/// The API's per-request bounds; every one is configurable, the defaults are safe.
#[derive(Debug, Clone)]
pub struct HttpLimits {
    /// Largest request body, bytes.
    pub body_bytes: usize,
    /// Largest body of the routes that take moments documents, bytes.
    pub document_bytes: usize,
    /// Most event streams open at once; beyond it 429 with Retry-After.
    pub max_event_streams: usize,
    /// Most requests carrying moments documents (merges, studies) read or processed at once.
    pub max_document_requests: usize,
    /// A whole request body must arrive within this.
    pub body_timeout: Duration,
}

impl Default for HttpLimits {
    fn default() -> Self {
        Self {
            body_bytes: 1 << 20,
            document_bytes: DEFAULT_DOCUMENT_LIMIT,
            max_event_streams: 256,
            max_document_requests: 2,
            body_timeout: Duration::from_secs(60),
        }
    }
}

/// A shared secret for bearer authentication; never printed.
#[derive(Clone)]
pub struct BearerToken(pub Arc<str>);

impl std::fmt::Debug for BearerToken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BearerToken(…)")
    }
}
