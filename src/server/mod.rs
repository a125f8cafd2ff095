//! The server process: configuration, wiring (store → pool → peers → job manager → router →
//! listener) and graceful shutdown.
//!
//! * [`listener`] — the accept loop: connection limit, timeouts, TLS, graceful shutdown;
//! * `crate::trust::acceptor` — the server's certificate and key.
//!
//! Imports: crate::api, crate::jobs, crate::metrics, crate::store, crate::trust

pub mod listener;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use tokio::net::TcpListener;

use crate::api::guard::Guard;
use crate::api::{BearerToken, HttpLimits};
use crate::jobs::cluster::{ClusterExecutor, ClusterOptions};
use crate::jobs::core::compute::Pools;
use crate::jobs::merges::peers::{Peer, PeerConfigError, Peers};
use crate::jobs::{Executor, JobManager, LocalPool, RunPolicy, Services};
use crate::store::{Store, StoreError};
use crate::trust::signing::{KeyError, Provenance};
pub use listener::ConnectionLimits;

/// Everything `optimis serve` can be told, validated.
#[derive(Debug, Clone)]
pub struct ServerConfig {
    /// The address to listen on (`--bind`; port 0 picks a free port).
    pub bind: SocketAddr,
    /// `sqlite://path` (created if missing) or `sqlite::memory:`.
    pub database: String,
    /// Threads of the simulation pool.
    pub threads: usize,
    /// How jobs run and which jobs this server accepts (handed to the job manager as it is).
    pub policy: RunPolicy,
    /// What one request may ask of the API (handed to the router as it is).
    pub http: HttpLimits,
    /// Connections open at once and their timeouts (handed to the listener as they are).
    pub connections: ConnectionLimits,
    /// When set, every route but `/healthz`, `/readyz` and the dashboard's static files requires
    /// `Authorization: Bearer <token>`.
    pub token: Option<BearerToken>,
    /// Serve https with this certificate chain and key (PEM files).
    pub tls: Option<TlsFiles>,
    /// The servers merges and studies may pull statistics from (nothing else is ever contacted).
    pub peers: Vec<Peer>,
    /// Extra roots (PEM) trusted for https peers, besides the system's; each also pinned.
    pub peer_ca: Option<PathBuf>,
    /// Sign exported moments documents with this Ed25519 private key (PKCS#8 PEM).
    pub signing_key: Option<PathBuf>,
    /// Merges and studies accept only documents signed by one of these Ed25519 public keys (PEM);
    /// none: signatures are neither required nor checked.
    pub trust: Vec<PathBuf>,
    /// Host names this server also answers to, besides loopback ones (a proxy's public name).
    pub allowed_hosts: Vec<String>,
    /// Where jobs run: the server's own pool (None, the default), or a cluster's batch system
    /// (Slurm), named in the options.
    pub cluster: Option<ClusterOptions>,
}

/// The PEM files of the server's TLS certificate chain and private key.
#[derive(Debug, Clone)]
pub struct TlsFiles {
    /// The certificate chain, leaf first (`--tls-cert`).
    pub cert: PathBuf,
    /// The private key of the leaf certificate (`--tls-key`).
    pub key: PathBuf,
}

/// Why the server could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The database could not be opened or migrated, or failed while recovering jobs.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The listening socket could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The I/O error (e.g. the address is in use).
        source: std::io::Error,
    },
    /// A thread pool (the simulation's, or the requests' compute pools) could not be built.
    #[error("cannot start the simulation threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
    /// A `--peer` or `--peer-ca` is unusable, or the peer client cannot be built.
    #[error(transparent)]
    Peers(#[from] PeerConfigError),
    /// The TLS certificate or key is unusable.
    #[error(transparent)]
    Tls(#[from] crate::trust::acceptor::TlsError),
    /// The signing key or a trusted public key is unusable.
    #[error(transparent)]
    Keys(#[from] KeyError),
    /// An I/O error of the listener (its local address, the accept loop).
    #[error("server error: {0}")]
    Io(#[from] std::io::Error),
    /// The executor could not start (`--executor slurm`: the cluster directory, the batch
    /// system's commands, its controller).
    #[error("{0}")]
    Executor(String),
    /// Anything else that stopped the start-up.
    #[error("server error: {0}")]
    Other(String),
}

/// A started server: its address, and a way to stop it and wait.
pub struct RunningServer {
    /// The address the server listens on (with the port picked when asked for port 0).
    pub addr: SocketAddr,
    /// The server's job manager, for tests that inspect or drive jobs directly.
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
    tracing::info!(address = %listener.local_addr()?, database = %config.database, workers = config.policy.workers,
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
    let tls = config.tls.as_ref().map(|f| crate::trust::acceptor::acceptor(&f.cert, &f.key)).transpose()?;
    let peers = Peers::new(config.peers.clone(), config.peer_ca.as_deref(), config.http.document_bytes)?;
    let provenance = Provenance::load(config.signing_key.as_deref(), &config.trust)?;
    let store = Store::open(&config.database).await?;
    let pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .thread_name(|i| format!("optimis-sim-{i}"))
            .build()?,
    );
    // Requests that compute get pools of their own (jobs::compute), so they never wait behind a
    // running job's chunks, and their light work never waits behind their heavy work.
    let pools = Pools::new()?;
    let metrics = Arc::new(crate::metrics::Metrics::new());
    let executor: Arc<dyn Executor> = match &config.cluster {
        None => Arc::new(LocalPool::new(pool)),
        Some(options) => {
            let (options, metrics) = (options.clone(), metrics.clone());
            // The batch system's commands answer within their timeouts; off the tokio workers all
            // the same.
            let started = tokio::task::spawn_blocking(move || ClusterExecutor::start(options, metrics))
                .await
                .map_err(|e| ServerError::Other(e.to_string()))?;
            Arc::new(started.map_err(ServerError::Executor)?)
        }
    };
    let jobs = JobManager::start(store, config.policy.clone(), executor, pools, metrics).await?;
    let services = Services::new(jobs.clone(), peers, provenance, config.http.max_document_requests);
    let guard = Guard {
        loopback: bound.ip().is_loopback(),
        allowed_hosts: config.allowed_hosts.iter().map(|h| h.to_ascii_lowercase()).collect::<Vec<_>>().into(),
    };
    let router = crate::api::router(services, &config.http, config.token.clone(), guard);
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
    listener::serve(listener, router, tls, config.connections, graceful).await;
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
