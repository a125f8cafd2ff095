//! The command line: `optimis run`, `bench`, `merge`, `report`, `predict`, `evaluate`, `budget`,
//! `compare`, `figure`, `sweep`, `serve`, `wait` and `openapi`, thin shells around the library.
//!
//! Imports: crate::api, crate::jobs, crate::server, crate::sim, crate::trust

mod bench;
mod budget;
#[cfg(feature = "server")]
mod cluster_task;
mod compare;
mod documents;
mod evaluate;
mod figure;
mod predict;
mod progress;
mod radii;
#[cfg(feature = "server")]
mod remote;
mod run;
#[cfg(feature = "server")]
mod serve;
mod shard;
mod sweep;
mod table;
#[cfg(feature = "server")]
mod wait;
mod weights;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::sim::spec::SpecError;

/// optimis — optimal MIS weights for bidirectional photon mapping by direct variance minimisation.
#[derive(Debug, Parser)]
#[command(
    name = "optimis",
    version,
    about,
    after_help = "Exit status: 0 success; 2 usage (a flag or argument); 3 invalid input (a job or sweep \
                  specification, a JSON file, a moments document, the configuration); 4 conflict (documents \
                  of other configurations or with iterations already counted); 5 I/O (a file that cannot \
                  be read or written); 130 interrupted (`optimis run` keeps its iterations in --out: \
                  --resume continues); 1 anything else."
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands of `optimis` (`serve` and `openapi` with feature `server` only).
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a simulation job locally and print its noise and weights tables.
    Run(run::RunArgs),
    /// Measure light paths per second at the paper's parameters.
    Bench(bench::BenchArgs),
    /// Merge moments documents (shards, runs of other seeds) into one.
    Merge(documents::MergeArgs),
    /// Print the noise and weights tables of a moments document.
    Report(documents::ReportArgs),
    /// Predict the noise table and re-fit the optimal weights at another N_F and N_B, from a moments
    /// document with noise components.
    Predict(predict::PredictArgs),
    /// Score given weights (another run's result, or a table) on a moments document: L, RMS and
    /// their standard errors beside the document's per-path strategies.
    Evaluate(evaluate::EvaluateArgs),
    /// The ray budget (N_F, N_B) that reaches a target RMS soonest, per strategy, from a moments
    /// document with noise components.
    Budget(budget::BudgetArgs),
    /// Draw a figure without a browser, as SVG, PNG or PDF: `fig2` (w₁ against r₃ of the weights
    /// table, ± 1 SE, the paper's Fig. 2) and `table1` (RMS ± SE beside the paper's) from a moments
    /// document, `convergence` (L ± SE and RMS against iterations) from a job's history.
    Figure(figure::FigureArgs),
    /// Compare runs strategy by strategy: moments documents, or jobs of a server with --server;
    /// ratios and differences against the first, with standard errors.
    Compare(compare::CompareArgs),
    /// The weight function of a run as a portable artifact for renderers (the recommended row's
    /// by default), with test vectors to check an evaluator against the engine.
    Weights(weights::WeightsArgs),
    /// Run a sweep (a job varied along axes) locally or one run per cluster task, and collect its
    /// table (`optimis sweep collect DIR`).
    Sweep(sweep::SweepArgs),
    /// Run the HTTP job server.
    #[cfg(feature = "server")]
    Serve(Box<serve::ServeArgs>),
    /// Wait for a job or a sweep on a server to end: exit status 0 if it succeeded, 1 if it
    /// failed or was cancelled, 5 if the server does not answer.
    #[cfg(feature = "server")]
    Wait(wait::WaitArgs),
    /// Print the server's OpenAPI description (YAML).
    #[cfg(feature = "server")]
    Openapi,
    /// One task of a job the server runs on Slurm (`serve --executor slurm` submits it).
    #[cfg(feature = "server")]
    #[command(hide = true)]
    ClusterTask(cluster_task::ClusterTaskArgs),
}

/// Everything the command line can fail with.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// An input file could not be read (exit status 5).
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// An input file is not JSON (exit status 3).
    #[error("{path} is not valid JSON: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The parse error, with its line and column.
        source: serde_json::Error,
    },
    /// A job specification, a flag or an environment variable is invalid (exit status 3); the
    /// message says which of them by the field it names.
    #[error("{}", labelled(.0))]
    Spec(#[from] SpecError),
    /// A moments document was read but cannot serve the command: its job specification is no
    /// longer valid, or it lacks what the command needs (e.g. noise components; exit status 3).
    #[error("{path}: {detail}")]
    Unusable {
        /// The document's file.
        path: PathBuf,
        /// Why.
        detail: String,
    },
    /// An input other than a job specification names a bad field.
    #[error("invalid {what}: {source}")]
    Invalid {
        /// What the input is (e.g. "weights").
        what: &'static str,
        /// The field at fault and why.
        source: SpecError,
    },
    /// A flag or the environment is misconfigured (not a job specification).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A moments document is unreadable or invalid (exit status 3), or cannot be merged with the
    /// others: another configuration, or iterations counted twice (exit status 4).
    #[error("{path}: {source}")]
    Document {
        /// The document's file.
        path: PathBuf,
        /// What is wrong with it.
        source: crate::sim::document::DocumentError,
    },
    /// The worker thread pool could not be built.
    #[error("cannot start the worker threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
    /// An output file (or directory) could not be written (exit status 5).
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The run was interrupted (SIGINT, SIGTERM; exit status 130): what it did is kept where it
    /// says, and how to continue.
    #[error("interrupted at {done} of {total} iterations; {what}")]
    Interrupted {
        /// Iterations done.
        done: u64,
        /// Iterations asked for.
        total: u64,
        /// Where the iterations are and how to continue, or that nothing was kept.
        what: String,
    },
    /// Standard output could not be written (exit status 5; a closed pipe is not an error).
    #[error("cannot write the output: {0}")]
    Output(#[from] std::io::Error),
    /// `optimis wait`: the server did not answer (exit status 5).
    #[cfg(feature = "server")]
    #[error("{url}: the server does not answer: {detail}")]
    Unreachable {
        /// The resource's URL.
        url: String,
        /// The connection's error.
        detail: String,
    },
    /// `optimis wait`: the server refused the request (exit status 3 for 4xx, else 1).
    #[cfg(feature = "server")]
    #[error("{url}: {status}: {detail}")]
    Refused {
        /// The resource's URL.
        url: String,
        /// The HTTP status.
        status: u16,
        /// The problem document's detail.
        detail: String,
    },
    /// `optimis wait`: the job or sweep ended without succeeding, or the timeout passed (exit
    /// status 1).
    #[cfg(feature = "server")]
    #[error("{0}")]
    Ended(String),
    /// The server failed to start or to run.
    #[cfg(feature = "server")]
    #[error(transparent)]
    Server(#[from] crate::server::ServerError),
}

/// A spec error labelled by what it is about: a flag (`--target-rms`), an environment variable
/// (`SLURM_ARRAY_TASK_ID`) or a field of the job specification.
fn labelled(e: &SpecError) -> String {
    let field = e.field.as_str();
    if field.starts_with("--") {
        format!("invalid argument {e}")
    } else if !field.is_empty() && field.bytes().all(|b| b.is_ascii_uppercase() || b == b'_') {
        format!("invalid environment variable {e}")
    } else {
        format!("invalid job specification: {e}")
    }
}

/// A rayon pool of `threads` workers (default: one per available core).
pub(crate) fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, CliError> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(t) = threads {
        builder = builder.num_threads(t.max(1));
    }
    Ok(builder.build()?)
}

/// The machine's core count as the OS reports it.
pub(crate) fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Parses the command line and runs it; errors go to stderr with the exit status of
/// [`CliError::exit_code`] (2 for usage, from clap).
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run::run(args),
        Command::Bench(args) => bench::bench(args),
        Command::Merge(args) => documents::merge(args),
        Command::Report(args) => documents::report(args),
        Command::Predict(args) => predict::predict(args),
        Command::Evaluate(args) => evaluate::evaluate(args),
        Command::Budget(args) => budget::budget(args),
        Command::Sweep(args) => sweep::sweep(args),
        Command::Weights(args) => weights::weights(args),
        Command::Compare(args) => compare::compare(args),
        Command::Figure(args) => figure::figure(args),
        #[cfg(feature = "server")]
        Command::Serve(args) => serve::serve_command(*args),
        #[cfg(feature = "server")]
        Command::Wait(args) => wait::wait(args),
        #[cfg(feature = "server")]
        Command::ClusterTask(args) => cluster_task::cluster_task(args),
        #[cfg(feature = "server")]
        Command::Openapi => {
            use std::io::Write;
            std::io::stdout().lock().write_all(crate::api::openapi_yaml().as_bytes()).map_err(CliError::from)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // The reader went away (`optimis report … | head`): not an error of ours.
        Err(CliError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("optimis: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}

impl CliError {
    /// The exit status (documented in `optimis --help`): scripts and schedulers tell bad input,
    /// conflicts and I/O apart without parsing the message.
    pub fn exit_code(&self) -> u8 {
        use crate::sim::document::DocumentError;
        use crate::sim::stats::moments::MergeError;
        match self {
            CliError::Document {
                source:
                    DocumentError::Merge(
                        MergeError::Fingerprint { .. } | MergeError::FormatMix { .. } | MergeError::Overlap(_),
                    ),
                ..
            } => 4,
            CliError::Spec(_)
            | CliError::Invalid { .. }
            | CliError::Json { .. }
            | CliError::Document { .. }
            | CliError::Unusable { .. }
            | CliError::Config(_) => 3,
            CliError::Read { .. } | CliError::Write { .. } | CliError::Output(_) => 5,
            CliError::Interrupted { .. } => 130,
            #[cfg(feature = "server")]
            CliError::Unreachable { .. } => 5,
            #[cfg(feature = "server")]
            CliError::Refused { status: 400..=499, .. } => 3,
            _ => 1,
        }
    }
}
