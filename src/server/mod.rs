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
    /// Largest request body, bytes.
    pub body_limit: usize,
    /// Largest request body of the routes that take moments documents, bytes.
    pub document_limit: usize,
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
    };
    // Requests that compute (reference luminance, re-solves) get their own two threads, so they
    // never wait behind a running job's chunks.
    let requests =
        rayon::ThreadPoolBuilder::new().num_threads(2).thread_name(|i| format!("optimis-requests-{i}")).build()?;
    let metrics = Arc::new(crate::metrics::Metrics::new());
    let jobs = JobManager::start(store, policy, pool, requests, metrics).await?;
    let app = crate::api::router(jobs.clone(), config.body_limit, config.document_limit);
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
