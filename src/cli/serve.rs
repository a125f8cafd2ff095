//! `optimis serve`: the HTTP job server on its embedded SQLite database.

use std::net::SocketAddr;
use std::time::Duration;

use clap::{Args, ValueEnum};

use super::{CliError, cores};
use crate::server::{ServerConfig, serve, termination_signal};

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
    /// Log format on stderr.
    #[arg(long, value_enum, default_value = "text")]
    pub log_format: LogFormat,
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
    let config = ServerConfig {
        bind: args.bind,
        database: args.database,
        workers: args.workers as usize,
        threads: args.threads.map_or_else(cores, |t| t as usize),
        checkpoint_iterations: args.checkpoint_iterations,
        checkpoint_interval: Duration::from_secs_f64(args.checkpoint_seconds),
        body_limit: args.body_limit as usize,
        document_limit: args.document_limit as usize,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(config.bind)
            .await
            .map_err(|source| crate::server::ServerError::Bind { addr: config.bind, source })?;
        tracing::info!(address = %listener.local_addr()?, database = %config.database, workers = config.workers,
            threads = config.threads, "optimis listening");
        serve(listener, &config, termination_signal()).await
    })?;
    Ok(())
}
