//! `optimis serve`: the HTTP job server on its embedded SQLite database.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, ValueEnum};

use super::{CliError, cores};
use crate::api::{BearerToken, HttpLimits};
use crate::jobs::RunPolicy;
use crate::jobs::cluster::{BatchSystemKind, ClusterOptions, SlurmOptions};
use crate::jobs::merges::peers::Peer;
use crate::server::{ConnectionLimits, ServerConfig, TlsFiles, serve, termination_signal};
use crate::trust::secrets::{check_owner_only, read_secret};

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Address to listen on. Keep 127.0.0.1 unless the server is behind an authenticating proxy.
    #[arg(long, default_value = "127.0.0.1:8080", env = "OPTIMIS_BIND")]
    pub bind: SocketAddr,
    /// Database URL: sqlite://PATH (created if missing) or sqlite::memory:.
    #[arg(long, default_value = "sqlite://optimis.db", env = "OPTIMIS_DATABASE")]
    pub database: String,
    /// Jobs running at once; the others wait in submission order.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub workers: u32,
    /// Simulation threads shared by the running jobs (default: one per core).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// A point of a running job's history every this many iterations, and a checkpoint too (but
    /// no more often than the engine's batch: 4,096 iterations of the restricted engine).
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_iterations: u64,
    /// …and at least every this many seconds.
    #[arg(long, default_value_t = 15.0, value_parser = positive_seconds)]
    pub checkpoint_seconds: f64,
    /// Largest accepted request body, in bytes.
    #[arg(long, default_value_t = 1 << 20, value_parser = clap::value_parser!(u64).range(1024..=(1 << 30)))]
    pub body_limit: u64,
    /// Largest body of the routes that take moments documents (merge, studies), in bytes.
    #[arg(long, default_value_t = crate::api::DEFAULT_DOCUMENT_LIMIT as u64, value_parser = clap::value_parser!(u64).range(1024..=(1 << 34)))]
    pub document_limit: u64,
    /// Largest light_paths × camera_paths × iterations of one job (also of merged statistics).
    #[arg(long, default_value_t = 1e16, value_parser = positive_number)]
    pub max_job_budget: f64,
    /// Largest expected work of one iteration, in light-path equivalents (a merge counts 50).
    #[arg(long, default_value_t = crate::jobs::core::policy::DEFAULT_MAX_ITERATION_WORK, value_parser = positive_number)]
    pub max_iteration_work: f64,
    /// Most cells of a job's weight grid.
    #[arg(long, default_value_t = crate::sim::model::cells::MAX_CELLS as u64, value_parser = clap::value_parser!(u64).range(1..=crate::sim::model::cells::MAX_CELLS as u64))]
    pub max_cells: u64,
    /// Most jobs waiting in the queue (beyond: 429 with Retry-After).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub max_queued_jobs: u64,
    /// Most points, and most runs, of one sweep (`POST /v1/sweeps`; each run is a queued job).
    #[arg(long, default_value_t = crate::jobs::core::policy::DEFAULT_MAX_SWEEP_POINTS as u64, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub max_sweep_points: u64,
    /// Seconds a study (`POST /v1/studies`) may take to gather and merge its sources.
    #[arg(long, default_value_t = crate::jobs::core::policy::DEFAULT_STUDY_DEADLINE.as_secs_f64(), value_parser = positive_seconds)]
    pub study_deadline: f64,
    /// Most event streams open at once (beyond: 429 with Retry-After).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub max_event_streams: u64,
    /// Most merge and study requests (which carry moments documents) handled at once.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub max_document_requests: u64,
    /// Most connections open at once (further ones wait to be accepted).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub max_connections: u64,
    /// Most connections open at once from one client address (further ones: 429, closed).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub max_connections_per_client: u64,
    /// Seconds for a request head (or a TLS handshake) to arrive; also how long a keep-alive
    /// connection may sit idle between requests.
    #[arg(long, default_value_t = 10.0, value_parser = positive_seconds)]
    pub header_timeout: f64,
    /// Seconds for a whole request body to arrive.
    #[arg(long, default_value_t = 60.0, value_parser = positive_seconds)]
    pub body_timeout: f64,
    /// Seconds a response may wait for the client to read it; a client that stops reading (an
    /// abandoned event stream) is disconnected.
    #[arg(long, default_value_t = 60.0, value_parser = positive_seconds)]
    pub send_timeout: f64,
    /// Serve https with this PEM certificate chain (with --tls-key).
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The PEM private key of --tls-cert (readable by its owner only).
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// A server merges and studies may pull statistics from: BASE_URL[,token-file=PATH], e.g.
    /// https://node2:8443,token-file=/etc/optimis/node2.token. Repeatable; nothing else is pulled.
    #[arg(long = "peer", value_name = "BASE_URL[,token-file=PATH]")]
    pub peers: Vec<String>,
    /// PEM certificates trusted for https peers besides the system's (e.g. a self-signed one).
    #[arg(long, value_name = "FILE")]
    pub peer_ca: Option<PathBuf>,
    /// Sign exported moments documents with this Ed25519 private key (PKCS#8 PEM, e.g. from
    /// `openssl genpkey -algorithm ed25519`).
    #[arg(long, value_name = "FILE")]
    pub signing_key: Option<PathBuf>,
    /// Accept in merges and studies only documents signed by this Ed25519 public key (PEM, e.g. from
    /// `openssl pkey -in KEY -pubout`); repeatable. Without it signatures are not required.
    #[arg(long, value_name = "FILE")]
    pub trust: Vec<PathBuf>,
    /// A host name this server also answers to when bound to loopback (a proxy's public name).
    /// Repeatable.
    #[arg(long = "allowed-host", value_name = "NAME")]
    pub allowed_hosts: Vec<String>,
    /// A file holding the bearer token every request must carry, readable by its owner only (see
    /// also OPTIMIS_TOKEN).
    #[arg(long, value_name = "FILE", conflicts_with = "token")]
    pub token_file: Option<PathBuf>,
    /// The bearer token every request must carry. Prefer the environment variable or a file:
    /// command lines are visible to other users of the machine.
    #[arg(long, env = "OPTIMIS_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Log format on stderr.
    #[arg(long, value_enum, default_value = "text")]
    pub log_format: LogFormat,
    #[command(flatten)]
    pub cluster: ClusterArgs,
}

/// Where jobs run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExecutorName {
    /// The server's own simulation pool (--threads).
    Local,
    /// A Slurm cluster: each job as job arrays (see --cluster-dir).
    Slurm,
}

/// The flags of `--executor slurm`.
#[derive(Debug, Args)]
pub struct ClusterArgs {
    /// Where jobs run: `local` (the server's own pool) or `slurm` (a job array per job; then
    /// --workers is how many jobs are followed on the cluster at once).
    #[arg(long, value_enum, default_value = "local")]
    pub executor: ExecutorName,
    /// With --executor slurm: a directory the server and the nodes share (task specifications,
    /// documents and logs); created (mode 0700) if missing; it must be this user's, and neither it
    /// nor a parent writable by anyone else (a sticky parent such as /tmp excepted).
    #[arg(long, value_name = "DIR", required_if_eq("executor", "slurm"))]
    pub cluster_dir: Option<PathBuf>,
    /// The optimis binary the tasks run, as a path on the nodes (default: this server's own).
    #[arg(long, value_name = "PATH")]
    pub slurm_binary: Option<PathBuf>,
    /// The directory of sbatch, squeue and scancel (default: found on the PATH).
    #[arg(long, value_name = "DIR")]
    pub slurm_bin_dir: Option<PathBuf>,
    /// sbatch --partition of the tasks.
    #[arg(long, value_name = "NAME")]
    pub slurm_partition: Option<String>,
    /// sbatch --account of the tasks.
    #[arg(long, value_name = "NAME")]
    pub slurm_account: Option<String>,
    /// sbatch --cpus-per-task (also each task's --threads).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub slurm_cpus_per_task: u32,
    /// sbatch --time of each task (e.g. 02:00:00).
    #[arg(long, value_name = "TIME")]
    pub slurm_time: Option<String>,
    /// A further sbatch option for every task, one argument (e.g. --sbatch-option=--qos=long);
    /// repeatable. Passed as an argument, never through a shell.
    #[arg(long = "sbatch-option", value_name = "OPTION", allow_hyphen_values = true)]
    pub sbatch_options: Vec<String>,
    /// Tasks of a job whose document gives no `execution.tasks`.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=crate::sim::spec::MAX_TASKS))]
    pub default_tasks: u64,
    /// Most tasks of one job (`execution.tasks` above it: 422).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..=crate::sim::spec::MAX_TASKS))]
    pub max_tasks: u64,
    /// Resubmissions of a failed task before its job fails.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub task_retries: u32,
    /// Seconds between two looks at a job's tasks (one squeue per job per look).
    #[arg(long, default_value_t = 2.0, value_parser = positive_seconds)]
    pub slurm_poll_seconds: f64,
    /// Seconds each Slurm command (sbatch, squeue, scancel) may take.
    #[arg(long, default_value_t = 30.0, value_parser = positive_seconds)]
    pub slurm_command_timeout: f64,
    /// Seconds a task may be gone from the queue without a complete document before it counts
    /// as failed (shared filesystems lag).
    #[arg(long, default_value_t = 60.0, value_parser = positive_seconds)]
    pub task_grace_seconds: f64,
    /// Seconds between two partial documents of a task (what a restart or a retry resumes from).
    #[arg(long, default_value_t = 10.0, value_parser = positive_seconds)]
    pub task_checkpoint_seconds: f64,
}

impl ClusterArgs {
    /// The cluster executor's options, if it is asked for: the batch system named once, here.
    fn cluster_options(&self) -> Result<Option<ClusterOptions>, CliError> {
        let system = match self.executor {
            ExecutorName::Local => return Ok(None),
            ExecutorName::Slurm => BatchSystemKind::Slurm(SlurmOptions {
                bin_dir: self.slurm_bin_dir.clone(),
                partition: self.slurm_partition.clone(),
                account: self.slurm_account.clone(),
                time_limit: self.slurm_time.clone(),
                sbatch_options: self.sbatch_options.clone(),
                command_timeout: Duration::from_secs_f64(self.slurm_command_timeout),
            }),
        };
        let binary = match &self.slurm_binary {
            Some(path) => path.clone(),
            None => std::env::current_exe().map_err(|e| {
                CliError::Config(format!("--slurm-binary: this server's own path is unknown ({e}); give it"))
            })?,
        };
        let dir =
            self.cluster_dir.clone().ok_or_else(|| CliError::Config("--executor slurm needs --cluster-dir".into()))?;
        let cluster_dir = std::path::absolute(&dir).map_err(|e| CliError::Config(format!("--cluster-dir: {e}")))?;
        let options = ClusterOptions {
            system,
            cluster_dir,
            binary,
            cpus_per_task: self.slurm_cpus_per_task,
            default_tasks: self.default_tasks,
            max_tasks: self.max_tasks,
            retries: self.task_retries,
            poll_interval: Duration::from_secs_f64(self.slurm_poll_seconds),
            missing_grace: Duration::from_secs_f64(self.task_grace_seconds),
            task_checkpoint_seconds: self.task_checkpoint_seconds,
        };
        options.validate().map_err(CliError::Config)?;
        Ok(Some(options))
    }
}

fn positive_number(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("expected a positive number, got {s:?}")),
    }
}

/// The configured token: from the file (which must be readable by its owner only) or the
/// flag/environment; empty or short tokens are refused.
fn token(args: &ServeArgs) -> Result<Option<BearerToken>, CliError> {
    match (&args.token_file, &args.token) {
        (Some(path), _) => {
            let token = read_secret(path).map_err(|e| CliError::Config(format!("--token-file: {e}")))?;
            Ok(Some(BearerToken(token.into())))
        }
        (None, Some(t)) => {
            let t = t.trim();
            if t.len() >= 16 && t.chars().all(|c| c.is_ascii_graphic()) {
                Ok(Some(BearerToken(t.into())))
            } else {
                Err(CliError::Config(
                    "--token (or OPTIMIS_TOKEN) must be at least 16 visible ASCII characters (e.g. `openssl rand -hex 32`)"
                        .into(),
                ))
            }
        }
        (None, None) => Ok(None),
    }
}

pub(super) fn positive_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x <= 86_400.0 => Ok(x),
        _ => Err(format!("expected seconds in (0, 86400], got {s:?}")),
    }
}

fn init_logging(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,tower_http=info,sqlx=warn"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    match format {
        LogFormat::Text => builder.init(),
        LogFormat::Json => builder.json().init(),
    }
}

pub fn serve_command(args: ServeArgs) -> Result<(), CliError> {
    init_logging(args.log_format);
    let token = token(&args)?;
    let peers = args
        .peers
        .iter()
        .map(|p| Peer::parse(p))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| CliError::Config(e.to_string()))?;
    if let Some(key) = &args.tls_key {
        // The key is a secret like the token: refuse one that other users can read.
        check_owner_only(key).map_err(|e| CliError::Config(format!("--tls-key: {e}")))?;
    }
    let cluster = args.cluster.cluster_options()?;
    let config = ServerConfig {
        bind: args.bind,
        database: args.database,
        threads: args.threads.map_or_else(cores, |t| t as usize),
        policy: RunPolicy {
            workers: args.workers as usize,
            checkpoint_iterations: args.checkpoint_iterations,
            checkpoint_interval: Duration::from_secs_f64(args.checkpoint_seconds),
            job_budget: args.max_job_budget,
            max_iteration_work: args.max_iteration_work,
            max_cells: args.max_cells as usize,
            max_queued_jobs: args.max_queued_jobs as usize,
            max_sweep_points: args.max_sweep_points as usize,
            study_deadline: Duration::from_secs_f64(args.study_deadline),
        },
        http: HttpLimits {
            body_bytes: args.body_limit as usize,
            document_bytes: args.document_limit as usize,
            max_event_streams: args.max_event_streams as usize,
            max_document_requests: args.max_document_requests as usize,
            body_timeout: Duration::from_secs_f64(args.body_timeout),
        },
        connections: ConnectionLimits {
            max_connections: args.max_connections as usize,
            max_per_client: args.max_connections_per_client as usize,
            header_timeout: Duration::from_secs_f64(args.header_timeout),
            send_timeout: Duration::from_secs_f64(args.send_timeout),
        },
        token,
        tls: args.tls_cert.zip(args.tls_key).map(|(cert, key)| TlsFiles { cert, key }),
        peers,
        peer_ca: args.peer_ca,
        signing_key: args.signing_key,
        trust: args.trust,
        allowed_hosts: args.allowed_hosts,
        cluster,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(config.bind)
            .await
            .map_err(|source| crate::server::ServerError::Bind { addr: config.bind, source })?;
        if config.token.is_none() && !config.bind.ip().is_loopback() {
            tracing::warn!("listening beyond loopback without a token: anyone who can reach this port can submit jobs");
        }
        serve(listener, &config, termination_signal()).await
    })?;
    Ok(())
}
