//! `optimis run`: one job, locally, from a spec file and/or a preset with flag overrides.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use clap::Args;
use serde_json::{Value, json};

use super::progress::{Progress, ProgressArgs};
use super::shard::{parse_shard, resolve_shard};
use super::{CliError, table, thread_pool};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::MomentsDocument;
use crate::sim::model::params::{merge_patch, path_patch};
use crate::sim::runner::run_iterations;
use crate::sim::solve::export::{noise_table_csv, weights_csv};
use crate::sim::solve::report::{ReportInputs, RunReport, build_report};
use crate::sim::spec::{Shard, SpecError, ValidJob, parse_job_spec};
use crate::sim::stats::moments::Moments;

#[derive(Debug, Args)]
pub struct RunArgs {
    /// A JSON job specification (the document `POST /v1/jobs` accepts); flags override it.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Preset to start from (paper-table1, uniform-illumination); overrides the spec's preset.
    #[arg(long)]
    pub preset: Option<String>,
    /// Iterations M.
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Light paths per iteration N_F.
    #[arg(long)]
    pub light_paths: Option<u64>,
    /// Camera paths per iteration N_B.
    #[arg(long)]
    pub camera_paths: Option<u64>,
    /// Seed of the random streams.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Engine: `restricted` (the presets' default) or `brute` (all N_F light paths, the reference).
    #[arg(long, value_parser = ["restricted", "brute"])]
    pub engine: Option<String>,
    /// Worker threads (default: one per core). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Run shard K of N of the spec's iterations (K from 0). Without it, the index comes from
    /// SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX when set.
    #[arg(long, value_parser = parse_shard, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Number of shards, when the index comes from the scheduler's environment.
    #[arg(long)]
    pub shard_count: Option<u64>,
    /// Print the result as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Write the run's statistics as a moments document (for `optimis merge`, `optimis report`
    /// or `POST /v1/jobs/{id}/merge`).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Set any field of the job document, by its dotted path (repeatable; applied after the spec
    /// file and the flags). VALUE is JSON if it parses (`0.01`, `true`, `null`, `{"w0": null}`),
    /// else a string: `--set scene.l3=9 --set solver.fixed.w0=null --set engine=brute`.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub set: Vec<String>,
    /// Write the noise table as CSV (one row per strategy).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the weights table as CSV (one row per cell).
    #[arg(long, value_name = "FILE")]
    pub weights_csv: Option<PathBuf>,
    #[command(flatten)]
    pub progress: ProgressArgs,
}

/// Writes the report's tables as CSV where asked.
pub(super) fn write_csv(report: &RunReport, noise: Option<&Path>, weights: Option<&Path>) -> Result<(), CliError> {
    if let Some(path) = noise {
        write_atomically(path, noise_table_csv(&report.noise_table).as_bytes())?;
    }
    if let Some(path) = weights {
        write_atomically(path, weights_csv(&report.weights).as_bytes())?;
    }
    Ok(())
}

/// `--set PATH=VALUE` as a merge patch: `{"a": {"b": VALUE}}`.
fn set_patch(assignment: &str) -> Result<Value, SpecError> {
    let (path, text) = assignment
        .split_once('=')
        .ok_or_else(|| SpecError::new("--set", format!("expected PATH=VALUE, got {assignment:?}")))?;
    let value = serde_json::from_str(text).unwrap_or_else(|_| Value::String(text.to_string()));
    path_patch(path, &value)
        .ok_or_else(|| SpecError::new("--set", format!("{path:?} is not a dotted path of field names (e.g. scene.l3)")))
}

/// Reads a JSON file.
pub(crate) fn read_json(path: &PathBuf) -> Result<Value, CliError> {
    let text = std::fs::read_to_string(path).map_err(|source| CliError::Read { path: path.clone(), source })?;
    serde_json::from_str(&text).map_err(|source| CliError::Json { path: path.clone(), source })
}

/// The job of a spec file (or `{}`) with the flags applied, validated.
fn job_from_args(args: &RunArgs) -> Result<ValidJob, CliError> {
    let mut doc = match &args.spec {
        Some(path) => read_json(path)?,
        None => json!({}),
    };
    let mut overrides = serde_json::Map::new();
    let mut set = |key: &str, value: Option<Value>| {
        if let Some(v) = value {
            overrides.insert(key.to_string(), v);
        }
    };
    set("preset", args.preset.clone().map(Value::from));
    set("iterations", args.iterations.map(Value::from));
    set("light_paths", args.light_paths.map(Value::from));
    set("camera_paths", args.camera_paths.map(Value::from));
    set("seed", args.seed.map(Value::from));
    set("engine", args.engine.clone().map(Value::from));
    if args.preset.is_some() && doc.is_object() {
        // A preset flag starts over from that preset; the file's other fields still override it.
        doc["preset"] = Value::Null;
    }
    merge_patch(&mut doc, &Value::Object(overrides));
    for assignment in &args.set {
        merge_patch(&mut doc, &set_patch(assignment)?);
    }
    let mut spec = parse_job_spec(&doc)?;
    let environment: HashMap<String, String> = std::env::vars().collect();
    spec.shard = resolve_shard(args.shard, args.shard_count, spec.shard, &environment)?;
    if spec.shard.is_some() {
        spec.first_iteration = None;
    }
    Ok(spec.validate()?)
}

/// Writes `bytes` to `path`, through a temporary file and a rename so that a reader (or a
/// crashed run) never sees a partial file. The temporary name holds the process id: the tasks of a
/// job array write the same `sweep.json` at once, and a shared temporary file would be renamed
/// away under another task.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), CliError> {
    let fail = |source| CliError::Write { path: path.to_path_buf(), source };
    let tmp = path.with_extension(format!("partial-{}", std::process::id()));
    std::fs::write(&tmp, bytes).map_err(fail)?;
    std::fs::rename(&tmp, path).map_err(fail)
}

/// Runs every iteration of `job` on `pool` into fresh moments, reporting progress on stderr.
pub(super) fn run_moments(job: &ValidJob, pool: &rayon::ThreadPool, progress: &ProgressArgs, label: &str) -> Moments {
    let config = &job.config();
    let range = job.spec().iteration_range();
    let total = range.end - range.start;
    let mut shown = Progress::new(progress, label, total, config.light_paths);
    let started = Instant::now();
    let mut moments = Moments::new(config);
    let never = AtomicBool::new(false);
    pool.install(|| {
        run_iterations(config, job.spec().seed, range.clone(), &mut moments, &never, |_, next| {
            shown.update(next - range.start, started, config.light_paths);
            std::ops::ControlFlow::Continue(())
        })
    })
    .expect("a fresh run is neither cancelled nor overlapping");
    shown.finish();
    moments
}

pub fn run(args: RunArgs) -> Result<(), CliError> {
    let job = job_from_args(&args)?;
    let pool = thread_pool(args.threads)?;
    let config = &job.config();
    let started = Instant::now();
    let moments = run_moments(&job, &pool, &args.progress, "");
    let seconds = started.elapsed().as_secs_f64();
    if let Some(path) = &args.out {
        write_atomically(path, &MomentsDocument::new(job.spec().clone(), moments.clone()).to_json())?;
    }
    let expected = expected_luminances(config);
    let inputs =
        ReportInputs { reference: reference_luminance(&config.scene).ok(), expected: Some(&expected), weights: None };
    let report = build_report(&moments, &config.cells, &job.spec().solver, &inputs);
    write_csv(&report, args.csv.as_deref(), args.weights_csv.as_deref())?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &report).map_err(std::io::Error::from)?;
        writeln!(out)?;
    } else {
        table::write_report(&mut out, job.spec(), &report, Some((seconds, pool.current_num_threads())))?;
    }
    Ok(())
}
