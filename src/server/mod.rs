//! The server process: configuration, wiring (store → pool → peers → job manager → router →
//! listener) and graceful shutdown.
//!
//! * [`listener`] — the accept loop: connection limit, timeouts, TLS, graceful shutdown;
//! * [`tls`] — the server's certificate and key.

pub mod listener;
pub mod tls;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;

use crate::api::guard::Guard;
use crate::jobs::peers::{Peer, PeerConfigError, Peers};
use crate::jobs::{JobManager, RunPolicy};
use crate::store::{Store, StoreError};
use listener::ConnectionLimits;

/// Everything `optimis serve` can be told, validated.
#[derive(Debug, Clone)]
pub struct ServerConfig {
    pub bind: SocketAddr,
    /// `sqlite://path` (created if missing) or `sqlite::memory:`.
    pub database: String,
    /// Jobs running at once.
    pub workers: usize,
    /// Threads of the simulation pool.
    pub threads: usize,
    pub checkpoint_iterations: u64,
    pub checkpoint_interval: Duration,
    pub limits: Limits,
    /// When set, every route but `/healthz`, `/readyz` and the dashboard's static files requires
    /// `Authorization: Bearer <token>`.
    pub token: Option<BearerToken>,
    /// Serve https with this certificate chain and key (PEM files).
    pub tls: Option<TlsFiles>,
    /// The servers merges and studies may pull statistics from (nothing else is ever contacted).
    pub peers: Vec<Peer>,
    /// Extra roots (PEM) trusted for https peers, besides the system's.
    pub peer_ca: Option<PathBuf>,
    /// Host names this server also answers to, besides loopback ones (a proxy's public name).
    pub allowed_hosts: Vec<String>,
}

/// The PEM files of the server's TLS certificate chain and private key.
#[derive(Debug, Clone)]
pub struct TlsFiles {
    pub cert: PathBuf,
    pub key: PathBuf,
}

/// What one client may ask of the server; every limit is configurable, the defaults are safe.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Largest request body, bytes.
    pub body_bytes: usize,
    /// Largest body of the routes that take moments documents, bytes.
    pub document_bytes: usize,
    /// Largest N_F · N_B · iterations of one job (the number of light–camera path pairs).
    pub job_budget: f64,
    /// Largest expected work of one iteration, in light-path equivalents (`sim::engines::cost`).
    pub max_iteration_work: f64,
    /// Most cells of a job's grid.
    pub max_cells: usize,
    /// Most jobs waiting in the queue; beyond it submissions get 429 with Retry-After.
    pub max_queued_jobs: usize,
    /// Most event streams open at once; beyond it 429 with Retry-After.
    pub max_event_streams: usize,
    /// Most requests carrying moments documents (merges, studies) read or processed at once.
    pub max_document_requests: usize,
    /// Most connections open at once.
    pub max_connections: usize,
    /// A request head (and a TLS handshake) must arrive within this; keep-alive connections idle
    /// this long are closed.
    pub header_timeout: Duration,
    /// A whole request body must arrive within this.
    pub body_timeout: Duration,
    /// A response the client does not read for this long closes its connection.
    pub send_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            body_bytes: 1 << 20,
            document_bytes: crate::api::DEFAULT_DOCUMENT_LIMIT,
            job_budget: 1e16,
            max_iteration_work: DEFAULT_MAX_ITERATION_WORK,
            max_cells: crate::sim::model::cells::MAX_CELLS,
            max_queued_jobs: 1000,
            max_event_streams: 256,
            max_document_requests: 2,
            max_connections: 512,
            header_timeout: Duration::from_secs(10),
            body_timeout: Duration::from_secs(60),
            send_timeout: Duration::from_secs(60),
        }
    }
}

/// Default per-iteration work limit: 10¹⁰ light-path equivalents, about 45 s of the brute force
/// on 2 cores (the paper's brute-force iteration is 10⁷, its restricted one ~3·10³).
pub const DEFAULT_MAX_ITERATION_WORK: f64 = 1e10;

/// A shared secret for bearer authentication; never printed.
#[derive(Clone)]
pub struct BearerToken(pub std::sync::Arc<str>);

impl std::fmt::Debug for BearerToken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BearerToken(…)")
    }
}

/// Why the server could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("cannot listen on {addr}: {source}")]
    Bind { addr: SocketAddr, source: std::io::Error },
    #[error("cannot start the simulation threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
    #[error(transparent)]
    Peers(#[from] PeerConfigError),
    #[error(transparent)]
    Tls(#[from] tls::TlsError),
    #[error("server error: {0}")]
    Io(#[from] std::io::Error),
}

/// A started server: its address, and a way to stop it and wait.
pub struct RunningServer {
    pub addr: SocketAddr,
    pub jobs: JobManager,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<Result<(), ServerError>>,
}

impl RunningServer {
    /// Stops like on SIGTERM (running jobs checkpoint and stay queued) and waits.
    pub async fn shutdown(self) -> Result<(), ServerError> {
        let _ = self.stop.send(());
        self.task.await.unwrap_or(Ok(()))
    }
}

/// Opens the store, recovers unfinished jobs and serves on `listener` until `shutdown` resolves;
/// then stops accepting requests, checkpoints and stops running jobs, and returns. Logs
/// "optimis listening" (with the address) once the database is open and the server accepts
/// requests.
pub async fn serve(
    listener: TcpListener,
    config: &ServerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let app = build(config, listener.local_addr()?).await?;
    tracing::info!(address = %listener.local_addr()?, database = %config.database, workers = config.workers,
        threads = config.threads, authentication = config.token.is_some(), tls = config.tls.is_some(),
        peers = config.peers.len(), "optimis listening");
    run_app(listener, app, config, shutdown).await
}

/// What `build` wires together.
struct App {
    jobs: JobManager,
    router: axum::Router,
    tls: Option<tokio_rustls::TlsAcceptor>,
}

async fn build(config: &ServerConfig, bound: SocketAddr) -> Result<App, ServerError> {
    // Everything that can be refused is checked before the database is touched.
    let tls = config.tls.as_ref().map(|f| tls::acceptor(&f.cert, &f.key)).transpose()?;
    let peers = Peers::new(config.peers.clone(), config.peer_ca.as_deref(), config.limits.document_bytes)?;
    let store = Store::open(&config.database).await?;
    let pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .thread_name(|i| format!("optimis-sim-{i}"))
            .build()?,
    );
    let policy = RunPolicy {
        workers: config.workers,
        checkpoint_iterations: config.checkpoint_iterations,
        checkpoint_interval: config.checkpoint_interval,
        job_budget: config.limits.job_budget,
        max_iteration_work: config.limits.max_iteration_work,
        max_cells: config.limits.max_cells,
        max_queued_jobs: config.limits.max_queued_jobs,
    };
    // Requests that compute (validation, references, documents, re-solves) get their own two
    // threads, so they never wait behind a running job's chunks.
    let requests =
        rayon::ThreadPoolBuilder::new().num_threads(2).thread_name(|i| format!("optimis-requests-{i}")).build()?;
    let metrics = Arc::new(crate::metrics::Metrics::new());
    let jobs = JobManager::start(store, policy, pool, requests, metrics, peers).await?;
    let guard = Guard {
        loopback: bound.ip().is_loopback(),
        allowed_hosts: config.allowed_hosts.iter().map(|h| h.to_ascii_lowercase()).collect::<Vec<_>>().into(),
    };
    let router = crate::api::router(jobs.clone(), &config.limits, config.token.clone(), guard);
    Ok(App { jobs, router, tls })
}

async fn run_app(
    listener: TcpListener,
    app: App,
    config: &ServerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let App { jobs, router, tls } = app;
    let stopping = jobs.clone();
    let graceful = async move {
        shutdown.await;
        tracing::info!("shutting down: checkpointing running jobs");
        // Jobs stop first, so that event streams end and connections can drain.
        stopping.shutdown().await;
    };
    let limits = ConnectionLimits {
        max_connections: config.limits.max_connections,
        header_timeout: config.limits.header_timeout,
        send_timeout: config.limits.send_timeout,
    };
    listener::serve(listener, router, tls, limits, graceful).await;
    jobs.shutdown().await;
    Ok(())
}

/// Starts a server in the background on `config.bind` (port 0 picks a free port), for tests and
/// embedding.
pub async fn spawn(config: ServerConfig) -> Result<RunningServer, ServerError> {
    let listener =
        TcpListener::bind(config.bind).await.map_err(|source| ServerError::Bind { addr: config.bind, source })?;
    let addr = listener.local_addr()?;
    let app = build(&config, addr).await?;
    let jobs = app.jobs.clone();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        run_app(listener, app, &config, async move {
            let _ = stopped.await;
        })
        .await
    });
    Ok(RunningServer { addr, jobs, stop, task })
}

/// Resolves on SIGINT or SIGTERM.
pub async fn termination_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = interrupt => {}
        _ = terminate => {}
    }
}
