//! Everything a job operation can fail with. The API maps each variant to an HTTP status in one
//! place (`api::error`).

use crate::sim::document::DocumentError;
use crate::sim::spec::SpecError;
use crate::store::StoreError;

#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// A field of the request is invalid (HTTP 422).
    #[error(transparent)]
    Invalid(#[from] SpecError),
    /// The body is not JSON at all (HTTP 400).
    #[error("{0}")]
    Malformed(String),
    /// No such job (HTTP 404).
    #[error("no job with id {0}")]
    NotFound(String),
    /// No such sweep (HTTP 404).
    #[error("no sweep with id {0}")]
    SweepNotFound(i64),
    /// The job's state does not allow the operation (HTTP 409).
    #[error("{0}")]
    Conflict(String),
    /// A moments document is unusable (HTTP 422), or conflicts with the target's statistics:
    /// another configuration or iterations already counted (HTTP 409).
    #[error(transparent)]
    Document(#[from] DocumentError),
    /// A peer could not be reached or did not answer with a moments document (HTTP 422: the
    /// request names a source that yields no statistics). `field` is the JSON path of its `from`.
    #[error("{field}: {message}")]
    Peer { field: String, message: String },
    /// The source names a server that is not on this server's allow-list (HTTP 403); nothing was
    /// sent to it.
    #[error("{field}: {message}")]
    PeerNotAllowed { field: String, message: String },
    /// The server is at a limit; retry later (HTTP 429 with Retry-After).
    #[error("{detail}")]
    Busy { detail: String, retry_after_seconds: u64 },
    /// The server is shutting down and accepts no new work (HTTP 503).
    #[error("the server is shutting down")]
    ShuttingDown,
    /// The database failed (HTTP 500, or 503 if it was only busy).
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A running job's simulation could not go on (its statistics would leave the representable
    /// range); recorded as the job's error.
    #[error("the simulation stopped: {0}")]
    Simulation(String),
    /// A bug or an impossible state (HTTP 500).
    #[error("internal error: {0}")]
    Internal(String),
}
