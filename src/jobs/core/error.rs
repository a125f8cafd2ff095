//! Everything a job operation can fail with. The API maps each variant to an HTTP status in one
//! place (`api::error`).

use crate::sim::document::DocumentError;
use crate::sim::spec::SpecError;
use crate::store::StoreError;

/// Why a job operation failed; each variant names the HTTP status the API answers it with.
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
    Peer {
        /// JSON path of the source's `from` (`sources[2].from`, or `from` for a merge), or
        /// `sources` when a study's sources did not all arrive within its deadline.
        field: String,
        /// What went wrong: the peer unreachable, its answer unusable, or the deadline passed.
        message: String,
    },
    /// The source names a server that is not on this server's allow-list (HTTP 403); nothing was
    /// sent to it.
    #[error("{field}: {message}")]
    PeerNotAllowed {
        /// JSON path of the `from` that names the server (`sources[2].from`, or `from`).
        field: String,
        /// The refused origin, this server's allowed peers and the `--peer` that would allow it.
        message: String,
    },
    /// The server is at a limit; retry later (HTTP 429 with Retry-After).
    #[error("{detail}")]
    Busy {
        /// Which limit was reached (the queue, the heavy computations, the pulls from peers, a
        /// sweep's re-fits), for the client.
        detail: String,
        /// Seconds to wait before retrying, sent as the `Retry-After` header.
        retry_after_seconds: u64,
    },
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
    /// The job's work elsewhere (a cluster's tasks) failed for good.
    #[error("{0}")]
    Execution(String),
    /// A bug or an impossible state (HTTP 500).
    #[error("internal error: {0}")]
    Internal(String),
}
