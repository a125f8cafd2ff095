//! The error → HTTP mapping through a real axum router (`tower::ServiceExt::oneshot`), without a
//! database, a simulation pool or a socket: each handler fails with one error the API can meet,
//! and the answer is checked as a client sees it — status, `application/problem+json`, the
//! problem's fields (the offending field named where there is one) and the headers that tell a
//! client what to do (Retry-After, WWW-Authenticate).

use std::borrow::Cow;

use axum::Router;
use axum::body::Body;
use axum::http::{HeaderMap, Request};
use axum::routing::get;
use serde_json::Value;
use tower::ServiceExt;

use super::*;
use crate::sim::stats::coverage::Overlap;

/// What a client receives.
struct Answer {
    status: u16,
    headers: HeaderMap,
    problem: Value,
}

impl Answer {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).map(|v| v.to_str().unwrap())
    }

    fn detail(&self) -> &str {
        self.problem["detail"].as_str().unwrap()
    }
}

/// GET / on a router whose only handler fails with `make()` (converted as the API's handlers
/// convert it, through `?`), and checks what every problem answer shares: `status`, the problem
/// media type, the type `urn:problem-type:optimis:{slug}`, the reason phrase as the title, the
/// status repeated in the body, and a detail.
async fn answer<E>(make: impl Fn() -> E + Clone + Send + Sync + 'static, status: u16, slug: &str) -> Answer
where
    E: Send + 'static,
    ApiError: From<E>,
{
    let handler = move || {
        let error = make();
        async move {
            Err::<(), E>(error)?;
            Ok::<&'static str, ApiError>("unreachable")
        }
    };
    let router = Router::new().route("/", get(handler));
    let response = router.oneshot(Request::get("/").body(Body::empty()).unwrap()).await.unwrap();
    let headers = response.headers().clone();
    let received = response.status().as_u16();
    let body = axum::body::to_bytes(response.into_body(), 1 << 20).await.unwrap();
    let problem: Value = serde_json::from_slice(&body).expect("a JSON body");
    assert_eq!(received, status, "{problem}");
    assert_eq!(headers.get(header::CONTENT_TYPE).unwrap(), "application/problem+json");
    assert_eq!(problem["type"], format!("urn:problem-type:optimis:{slug}"), "{problem}");
    let reason = StatusCode::from_u16(status).unwrap().canonical_reason().unwrap();
    assert_eq!(problem["title"], reason, "{problem}");
    assert_eq!(problem["status"], status, "{problem}");
    assert!(!problem["detail"].as_str().unwrap().is_empty(), "{problem}");
    Answer { status: received, headers, problem }
}

/// A SQLite error with an extended result `code`, as the driver reports it.
#[derive(Debug)]
struct SqliteCode(&'static str);

impl std::fmt::Display for SqliteCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "sqlite error {}", self.0)
    }
}

impl std::error::Error for SqliteCode {}

impl sqlx::error::DatabaseError for SqliteCode {
    fn message(&self) -> &str {
        "sqlite error"
    }

    fn code(&self) -> Option<Cow<'_, str>> {
        Some(Cow::Borrowed(self.0))
    }

    fn as_error(&self) -> &(dyn std::error::Error + Send + Sync + 'static) {
        self
    }

    fn as_error_mut(&mut self) -> &mut (dyn std::error::Error + Send + Sync + 'static) {
        self
    }

    fn into_error(self: Box<Self>) -> Box<dyn std::error::Error + Send + Sync + 'static> {
        self
    }

    fn kind(&self) -> sqlx::error::ErrorKind {
        sqlx::error::ErrorKind::Other
    }
}

fn sqlite(code: &'static str) -> JobError {
    JobError::Store(StoreError::Database(sqlx::Error::Database(Box::new(SqliteCode(code)))))
}

#[tokio::test]
async fn a_body_that_is_not_json_is_400() {
    let a = answer(|| JobError::Malformed("expected value at line 1 column 1".into()), 400, "malformed-json").await;
    assert_eq!(a.detail(), "expected value at line 1 column 1");
    assert!(a.problem.get("field").is_none(), "{}", a.problem);
    assert_eq!(a.header("retry-after"), None);
}

#[tokio::test]
async fn an_invalid_field_is_422_naming_the_field() {
    let spec = || SpecError::new("scene.beta_deg", "must be in (0, 90) degrees");
    for a in [
        answer(spec, 422, "invalid-field").await,
        answer(move || JobError::Invalid(spec()), 422, "invalid-field").await,
    ] {
        assert_eq!(a.problem["field"], "scene.beta_deg");
        assert_eq!(a.detail(), "scene.beta_deg: must be in (0, 90) degrees");
    }
    // The document itself (no field): the message alone, and no `field` member.
    let a = answer(|| SpecError::new("", "expected an object"), 422, "invalid-field").await;
    assert_eq!(a.detail(), "expected an object");
    assert!(a.problem.get("field").is_none(), "{}", a.problem);
    // A peer that yields no statistics names the source it came from.
    let peer = || JobError::Peer { field: "sources[1].from".into(), message: "could not be reached".into() };
    let a = answer(peer, 422, "invalid-field").await;
    assert_eq!(a.problem["field"], "sources[1].from");
    assert_eq!(a.detail(), "sources[1].from: could not be reached");
}

#[tokio::test]
async fn unusable_documents_are_422_and_conflicting_ones_409() {
    let a = answer(|| JobError::Document(DocumentError::Checksum), 422, "invalid-field").await;
    assert!(a.detail().contains("checksum"), "{}", a.problem);
    assert!(a.problem.get("field").is_none(), "{}", a.problem);
    let overflow = || JobError::Document(DocumentError::Merge(MergeError::Overflow("sum_yy of cell 3".into())));
    let a = answer(overflow, 422, "invalid-field").await;
    assert!(a.detail().contains("overflow") && a.detail().contains("sum_yy of cell 3"), "{}", a.problem);

    let overlap =
        || JobError::Document(DocumentError::Merge(MergeError::Overlap(vec![Overlap { seed: 21, range: [15, 30] }])));
    let a = answer(overlap, 409, "conflict").await;
    assert!(a.detail().contains("seed 21 iterations [15, 30)"), "{}", a.problem);
    let foreign = || {
        JobError::Document(DocumentError::Merge(MergeError::Fingerprint {
            found: "abc".into(),
            expected: "def".into(),
            differences: Vec::new(),
        }))
    };
    let a = answer(foreign, 409, "conflict").await;
    assert!(a.detail().contains("fingerprint"), "{}", a.problem);
}

#[tokio::test]
async fn unknown_jobs_are_404_and_state_conflicts_409() {
    let a = answer(|| JobError::NotFound("424242".into()), 404, "not-found").await;
    assert_eq!(a.detail(), "no job with id 424242");
    let a = answer(|| JobError::Conflict("the job is running; cancel it first".into()), 409, "conflict").await;
    assert_eq!(a.detail(), "the job is running; cancel it first");
    // A corrupted checkpoint is that job's conflict, not a server failure.
    let corrupt = || JobError::Store(StoreError::Corrupt { job: 7, detail: "checksum mismatch".into() });
    let a = answer(corrupt, 409, "conflict").await;
    assert!(a.detail().contains("job 7") && a.detail().contains("checksum mismatch"), "{}", a.problem);
}

#[tokio::test]
async fn a_peer_off_the_allow_list_is_403() {
    let refused = || JobError::PeerNotAllowed {
        field: "sources[0].from".into(),
        message: "not an allowed peer (add it with --peer)".into(),
    };
    let a = answer(refused, 403, "forbidden").await;
    assert_eq!(a.detail(), "sources[0].from: not an allowed peer (add it with --peer)");
}

#[tokio::test]
async fn request_level_errors_have_their_own_statuses() {
    let a = answer(|| ApiError::PayloadTooLarge("the body is too large".into()), 413, "payload-too-large").await;
    assert_eq!(a.detail(), "the body is too large");
    let media = || ApiError::UnsupportedMediaType("expected application/json".into());
    let a = answer(media, 415, "unsupported-media-type").await;
    assert_eq!(a.detail(), "expected application/json");
    let a = answer(|| ApiError::MethodNotAllowed, 405, "method-not-allowed").await;
    assert_eq!(a.detail(), "method not allowed on this route");
    let a = answer(|| ApiError::RequestTimeout("the body did not arrive".into()), 408, "request-timeout").await;
    assert_eq!(a.detail(), "the body did not arrive");
    // 401 tells the client which scheme to use.
    let a = answer(|| ApiError::Unauthorized("a bearer token is required".into()), 401, "unauthorized").await;
    assert_eq!(a.header("www-authenticate"), Some("Bearer realm=\"optimis\""));
    assert_eq!(a.detail(), "a bearer token is required");
}

#[tokio::test]
async fn a_limit_is_429_with_retry_after() {
    let busy = || JobError::Busy { detail: "2 jobs are already waiting".into(), retry_after_seconds: 30 };
    let a = answer(busy, 429, "too-many-requests").await;
    assert_eq!(a.header("retry-after"), Some("30"));
    assert_eq!(a.detail(), "2 jobs are already waiting");
}

#[tokio::test]
async fn storage_that_cannot_write_is_503_with_retry_after() {
    // An I/O error, a full disk (SQLITE_FULL = 13) and an extended I/O code (SQLITE_IOERR_WRITE =
    // 778 = 10 | 3 << 8): nothing was stored, retry later.
    let io = || JobError::Store(StoreError::Database(sqlx::Error::Io(std::io::Error::other("No space left"))));
    for a in [
        answer(io, 503, "storage-unavailable").await,
        answer(|| sqlite("13"), 503, "storage-unavailable").await,
        answer(|| sqlite("778"), 503, "storage-unavailable").await,
    ] {
        assert_eq!(a.header("retry-after"), Some("30"));
        assert!(a.detail().contains("nothing was changed"), "{}", a.problem);
        assert!(!a.detail().contains("No space left"), "internals are not described: {}", a.problem);
    }
}

#[tokio::test]
async fn a_busy_database_or_a_shutdown_is_503() {
    // SQLITE_BUSY (5) and SQLITE_BUSY_SNAPSHOT (517 = 5 | 2 << 8), SQLITE_LOCKED (6).
    for code in ["5", "517", "6"] {
        let a = answer(move || sqlite(code), 503, "unavailable").await;
        assert!(a.detail().contains("the database is busy; retry"), "{}", a.problem);
        assert_eq!(a.header("retry-after"), None);
    }
    let a = answer(|| JobError::ShuttingDown, 503, "unavailable").await;
    assert!(a.detail().contains("shutting down"), "{}", a.problem);
    assert_eq!(a.header("retry-after"), None);
}

#[tokio::test]
async fn failures_are_500_without_their_internals() {
    let secret = "/var/lib/optimis/optimis.db: constraint jobs_pk";
    let store = || JobError::Store(StoreError::Database(sqlx::Error::RowNotFound));
    let constraint = || sqlite("19"); // SQLITE_CONSTRAINT: neither busy nor a storage failure
    for a in [
        answer(move || JobError::Internal(secret.into()), 500, "internal").await,
        answer(move || JobError::Simulation(secret.into()), 500, "internal").await,
        answer(store, 500, "internal").await,
        answer(constraint, 500, "internal").await,
    ] {
        assert_eq!(a.status, 500);
        assert_eq!(a.detail(), "the server failed to handle the request; the failure has been logged");
        assert!(a.problem.get("field").is_none(), "{}", a.problem);
        assert_eq!(a.header("retry-after"), None);
    }
}
