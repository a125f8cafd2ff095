//! The server process: configuration, wiring (store → pool → job manager → router) and graceful
//! shutdown.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;

use crate::jobs::{JobManager, RunPolicy};
use crate::store::{Store, StoreError};

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
    /// Most cells of a job's grid.
    pub max_cells: usize,
    /// Most jobs waiting in the queue; beyond it submissions get 429 with Retry-After.
    pub max_queued_jobs: usize,
    /// Most event streams open at once; beyond it 429 with Retry-After.
    pub max_event_streams: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            body_bytes: 1 << 20,
            document_bytes: crate::api::DEFAULT_DOCUMENT_LIMIT,
            job_budget: 1e16,
            max_cells: crate::sim::spec::MAX_CELLS,
            max_queued_jobs: 1000,
            max_event_streams: 256,
        }
    }
}

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
/// then stops accepting requests, checkpoints and stops running jobs, and returns.
pub async fn serve(
    listener: TcpListener,
    config: &ServerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let (jobs, app) = build(config).await?;
    run_app(listener, jobs, app, shutdown).await
}

async fn build(config: &ServerConfig) -> Result<(JobManager, axum::Router), ServerError> {
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
        max_cells: config.limits.max_cells,
        max_queued_jobs: config.limits.max_queued_jobs,
    };
    // Requests that compute (reference luminance, re-solves) get their own two threads, so they
    // never wait behind a running job's chunks.
    let requests =
        rayon::ThreadPoolBuilder::new().num_threads(2).thread_name(|i| format!("optimis-requests-{i}")).build()?;
    let metrics = Arc::new(crate::metrics::Metrics::new());
    let jobs = JobManager::start(store, policy, pool, requests, metrics).await?;
    let app = crate::api::router(jobs.clone(), &config.limits, config.token.clone());
    Ok((jobs, app))
}

async fn run_app(
    listener: TcpListener,
    jobs: JobManager,
    app: axum::Router,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let stopping = jobs.clone();
    let graceful = async move {
        shutdown.await;
        tracing::info!("shutting down: checkpointing running jobs");
        // Jobs stop first, so that event streams end and the HTTP server can drain.
        stopping.shutdown().await;
    };
    axum::serve(listener, app).with_graceful_shutdown(graceful).await?;
    jobs.shutdown().await;
    Ok(())
}

/// Starts a server in the background on `config.bind` (port 0 picks a free port), for tests and
/// embedding.
pub async fn spawn(config: ServerConfig) -> Result<RunningServer, ServerError> {
    let listener =
        TcpListener::bind(config.bind).await.map_err(|source| ServerError::Bind { addr: config.bind, source })?;
    let addr = listener.local_addr()?;
    let (jobs, app) = build(&config).await?;
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(run_app(listener, jobs.clone(), app, async move {
        let _ = stopped.await;
    }));
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
