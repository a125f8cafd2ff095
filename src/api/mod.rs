//! The HTTP API (axum): routes, their OpenAPI description, and the mapping of errors to problem
//! documents.
//!
//! Every route is registered through utoipa's `OpenApiRouter` from handlers annotated with their
//! OpenAPI operation, so the served router and `openapi.yaml` come from the same code; a test
//! checks that the committed `openapi.yaml` equals [`openapi_yaml`]. Each route file translates
//! between HTTP and one handle of the job layer (`jobs::Services`).
//!
//! Imports: crate::jobs, crate::metrics, crate::sim, crate::store

mod auth;
mod bodies;
mod compare;
mod csv;
mod dashboard;
pub mod error;
mod events;
mod extract;
pub mod guard;
mod health;
mod jobs;
pub mod limits;
mod openapi;
mod predictions;
mod references;
mod responses;
mod solves;
mod statistics;
mod studies;
mod sweeps;
mod wait;
mod weights;

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{DefaultBodyLimit, FromRef, State};
use axum::response::Response;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::trace::TraceLayer;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::jobs::artifacts::Artifacts;
use crate::jobs::evaluation::Evaluations;
use crate::jobs::merges::Merges;
use crate::jobs::prediction::Predictions;
use crate::jobs::solves::Solves;
use crate::jobs::statistics::Statistics;
use crate::jobs::sweeps::Sweeps;
use crate::jobs::{JobManager, Services};
use error::ApiError;
use guard::Guard;
pub use limits::{BearerToken, DEFAULT_DOCUMENT_LIMIT, HttpLimits};

/// What every handler can reach; cheap to clone. A route file takes only the handle it needs
/// (`State<Statistics>`: axum's substates, see `substates!`); the rest is the HTTP layer's own.
#[derive(Clone)]
pub struct AppState {
    /// The job layer's handles: the lifecycle and the feature services.
    pub services: Services,
    /// The OpenAPI document, rendered once.
    pub openapi_yaml: Arc<str>,
    /// SHA-256 of the bearer token, when the server requires one.
    pub token_digest: Option<[u8; 32]>,
    /// Open event streams, bounded.
    pub streams: Arc<auth::StreamSlots>,
    /// Origin, Host and Content-Type rules.
    pub guard: Guard,
    /// The whole request body must arrive within this.
    pub body_timeout: Duration,
    /// Bytes of document bodies held at once, taken as they arrive (`extract`):
    /// `--max-document-requests` + [`DOCUMENT_MEMORY_BODIES`] times the document limit.
    pub document_memory: Arc<tokio::sync::Semaphore>,
    /// Each client's share of `document_memory`: one document limit.
    pub document_shares: Arc<crate::jobs::merges::shares::Shares>,
    /// The document routes' body limit, bytes.
    pub document_bytes: usize,
}

/// Each handle of [`Services`] as a substate of [`AppState`], so that a handler takes
/// `State<JobManager>` or `State<Statistics>` rather than the whole state.
macro_rules! substates {
    ($($field:ident: $handle:ty),* $(,)?) => {
        $(impl FromRef<AppState> for $handle {
            fn from_ref(state: &AppState) -> Self {
                state.services.$field.clone()
            }
        })*
    };
}

substates! {
    jobs: JobManager,
    statistics: Statistics,
    merges: Merges,
    artifacts: Artifacts,
    evaluations: Evaluations,
    solves: Solves,
    predictions: Predictions,
    sweeps: Sweeps,
}

/// Whole document bodies held beyond those being processed: room for a few uploads to arrive
/// while `--max-document-requests` are being merged, so that the budget bounds memory without
/// making an upload wait for another's processing.
pub const DOCUMENT_MEMORY_BODIES: usize = 2;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "optimis",
        description = "Optimal multiple-importance-sampling weights for bidirectional photon mapping, by direct \
                       minimisation of the pixel variance (Ershov, Voloboy, Zhdanov et al. 2020). Submit simulation \
                       jobs, follow their progress, and read the noise table and the optimal weights.\n\n\
                       Errors are RFC 9457 problem documents (`application/problem+json`).",
        license(name = "MIT OR Apache-2.0")
    ),
    tags(
        (name = "jobs", description = "Simulation jobs"),
        (name = "statistics", description = "Merging statistics of shards, peers and documents"),
        (name = "sweeps", description = "A job varied along axes: runs queued as jobs, one table"),
        (name = "operations", description = "Health, metrics and API description"),
        (name = "dashboard", description = "The built-in web dashboard")
    )
)]
struct ApiDoc;

fn api_router(document_limit: usize) -> OpenApiRouter<AppState> {
    let with_limit = |(schemas, paths, method_router): utoipa_axum::router::UtoipaMethodRouter<AppState>| {
        (schemas, paths, method_router.layer(DefaultBodyLimit::max(document_limit)))
    };
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(jobs::submit, jobs::list))
        .routes(routes!(jobs::get, jobs::delete))
        .routes(routes!(statistics::result))
        .routes(routes!(statistics::solve))
        .routes(routes!(predictions::predict))
        .routes(routes!(predictions::budget))
        .routes(routes!(statistics::evaluate))
        .routes(routes!(solves::list))
        .routes(routes!(solves::save, solves::get, solves::delete))
        .routes(routes!(jobs::cancel))
        .routes(routes!(jobs::extend))
        .routes(routes!(statistics::moments))
        .routes(routes!(statistics::history))
        .routes(routes!(weights::weights))
        .routes(routes!(weights::effective))
        .routes(with_limit(routes!(studies::merge)))
        .routes(with_limit(routes!(studies::create)))
        .routes(routes!(sweeps::create, sweeps::list))
        .routes(routes!(sweeps::get, sweeps::delete))
        .routes(routes!(sweeps::table))
        .routes(routes!(sweeps::cancel))
        .routes(routes!(references::list))
        .routes(routes!(compare::compare))
        .routes(routes!(events::events))
        .routes(routes!(health::healthz))
        .routes(routes!(health::readyz))
        .routes(routes!(health::openapi_yaml))
        .routes(routes!(health::metrics))
        .routes(routes!(dashboard::index))
        .routes(routes!(dashboard::asset))
}

/// The routes and their finished OpenAPI document (security scheme and common responses added).
fn routes_and_document(document_limit: usize) -> (Router<AppState>, utoipa::openapi::OpenApi) {
    let (router, mut api) = api_router(document_limit).split_for_parts();
    utoipa::Modify::modify(&openapi::Security, &mut api);
    utoipa::Modify::modify(&openapi::Links, &mut api);
    (router, api)
}

/// The OpenAPI document of this server, as YAML (what `/openapi.yaml` serves and the committed
/// `openapi.yaml` must equal).
pub fn openapi_yaml() -> String {
    routes_and_document(DEFAULT_DOCUMENT_LIMIT).1.to_yaml().expect("the OpenAPI document serialises")
}

/// Counts and times every request by its route template (`MatchedPath`: `/v1/jobs/{id}`, not the
/// raw path, so that the label set stays bounded).
async fn observe(
    State(state): State<AppState>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let route = request
        .extensions()
        .get::<axum::extract::MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let method = crate::metrics::method_label(request.method());
    let started = std::time::Instant::now();
    let response = next.run(request).await;
    state.services.jobs.metrics().observe_request(method, &route, response.status().as_u16(), started.elapsed());
    response
}

async fn not_found() -> ApiError {
    ApiError::NotFound("no such route; see /openapi.yaml".into())
}

async fn method_not_allowed() -> ApiError {
    ApiError::MethodNotAllowed
}

fn panic_response(_: Box<dyn std::any::Any + Send + 'static>) -> Response {
    axum::response::IntoResponse::into_response(ApiError::Internal("a request handler panicked".into()))
}

/// The application: every route, with request tracing, metrics, the cross-site guard,
/// authentication (when `token` is set), the body limits and timeout of `limits`, gzip for clients
/// that accept it, and panics answered as problem documents. Layers run outside in: trace →
/// metrics → guard → auth → panics → compression → the route (whose body limit applies as its body
/// is read).
pub fn router(services: Services, limits: &HttpLimits, token: Option<BearerToken>, guard: Guard) -> Router {
    let (router, api) = routes_and_document(limits.document_bytes);
    let state = AppState {
        services,
        openapi_yaml: api.to_yaml().expect("the OpenAPI document serialises").into(),
        token_digest: token.map(|t| auth::digest(&t.0)),
        streams: auth::StreamSlots::new(limits.max_event_streams),
        guard,
        body_timeout: limits.body_timeout,
        document_shares: crate::jobs::merges::shares::Shares::new(limits.document_bytes),
        document_memory: Arc::new(tokio::sync::Semaphore::new(
            (limits.max_document_requests + DOCUMENT_MEMORY_BODIES).saturating_mul(limits.document_bytes),
        )),
        document_bytes: limits.document_bytes,
    };
    let body_limit = limits.body_bytes;
    router
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(body_limit))
        // gzip for clients that ask (browsers do): result documents, moments and tables shrink
        // several-fold; tower-http's default predicate leaves event streams and tiny bodies alone.
        .layer(CompressionLayer::new())
        .layer(CatchPanicLayer::custom(panic_response))
        .layer(axum::middleware::from_fn_with_state(state.clone(), auth::authenticate))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard::guard))
        .layer(axum::middleware::from_fn_with_state(state.clone(), observe))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}
