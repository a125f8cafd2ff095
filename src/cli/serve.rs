//! `optimis serve`: the HTTP job server on its embedded SQLite database.

use std::net::SocketAddr;
use std::time::Duration;

use clap::{Args, ValueEnum};

use super::{CliError, cores};
use crate::server::{BearerToken, Limits, ServerConfig, serve, termination_signal};
use crate::sim::spec::SpecError;

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
    /// Checkpoint a running job at least every this many iterations.
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
    /// Largest light_paths × camera_paths × iterations of one job.
    #[arg(long, default_value_t = 1e16, value_parser = positive_number)]
    pub max_job_budget: f64,
    /// Most cells of a job's weight grid.
    #[arg(long, default_value_t = crate::sim::spec::MAX_CELLS as u64, value_parser = clap::value_parser!(u64).range(1..=crate::sim::spec::MAX_CELLS as u64))]
    pub max_cells: u64,
    /// Most jobs waiting in the queue (beyond: 429 with Retry-After).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub max_queued_jobs: u64,
    /// Most event streams open at once (beyond: 429 with Retry-After).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub max_event_streams: u64,
    /// A file holding the bearer token every request must carry (see also OPTIMIS_TOKEN).
    #[arg(long, value_name = "FILE", conflicts_with = "token")]
    pub token_file: Option<std::path::PathBuf>,
    /// The bearer token every request must carry. Prefer the environment variable or a file:
    /// command lines are visible to other users of the machine.
    #[arg(long, env = "OPTIMIS_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Log format on stderr.
    #[arg(long, value_enum, default_value = "text")]
    pub log_format: LogFormat,
}

fn positive_number(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("expected a positive number, got {s:?}")),
    }
}

/// The configured token: from the file or the flag/environment; empty or short tokens are refused.
fn token(args: &ServeArgs) -> Result<Option<BearerToken>, CliError> {
    let raw = match (&args.token_file, &args.token) {
        (Some(path), _) => Some(
            std::fs::read_to_string(path)
                .map_err(|source| CliError::Read { path: path.clone(), source })?
                .trim()
                .to_string(),
        ),
        (None, Some(t)) => Some(t.trim().to_string()),
        (None, None) => None,
    };
    match raw {
        None => Ok(None),
        Some(t) if t.len() >= 16 && t.chars().all(|c| c.is_ascii_graphic()) => Ok(Some(BearerToken(t.into()))),
        Some(_) => {
            Err(SpecError::new("token", "must be at least 16 visible ASCII characters (e.g. `openssl rand -hex 32`)")
                .into())
        }
    }
}

fn positive_seconds(s: &str) -> Result<f64, String> {
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
    let config = ServerConfig {
        bind: args.bind,
        database: args.database,
        workers: args.workers as usize,
        threads: args.threads.map_or_else(cores, |t| t as usize),
        checkpoint_iterations: args.checkpoint_iterations,
        checkpoint_interval: Duration::from_secs_f64(args.checkpoint_seconds),
        limits: Limits {
            body_bytes: args.body_limit as usize,
            document_bytes: args.document_limit as usize,
            job_budget: args.max_job_budget,
            max_cells: args.max_cells as usize,
            max_queued_jobs: args.max_queued_jobs as usize,
            max_event_streams: args.max_event_streams as usize,
        },
        token,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(config.bind)
            .await
            .map_err(|source| crate::server::ServerError::Bind { addr: config.bind, source })?;
        tracing::info!(address = %listener.local_addr()?, database = %config.database, workers = config.workers,
            threads = config.threads, authentication = config.token.is_some(), "optimis listening");
        if config.token.is_none() && !config.bind.ip().is_loopback() {
            tracing::warn!("listening beyond loopback without a token: anyone who can reach this port can submit jobs");
        }
        serve(listener, &config, termination_signal()).await
    })?;
    Ok(())
}
