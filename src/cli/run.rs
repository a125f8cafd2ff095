//! `optimis run`: one job, locally, from a spec file and/or a preset with flag overrides.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use clap::Args;

use crate::sim::model::params::parse_count;
use serde_json::{Value, json};

use super::progress::{Progress, ProgressArgs};
use super::shard::{parse_shard, resolve_shard};
use super::{CliError, table, thread_pool};
use crate::sim::checks::published::{applicable, paper_columns};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::MomentsDocument;
use crate::sim::model::config::SimConfig;
use crate::sim::model::params::{merge_patch, path_patch};
use crate::sim::runner::run_iterations;
use crate::sim::solve::export::{effective_csv, noise_table_csv, weights_csv};
use crate::sim::solve::report::{ReportInputs, RunReport, build_report};
use crate::sim::spec::{JobSpec, Shard, SpecError, ValidJob, parse_job_spec};
use crate::sim::stats::moments::Moments;
use crate::sim::weights::effective::{EFFECTIVE_PATHS, recommended_effective};

#[derive(Debug, Args)]
pub struct RunArgs {
    /// A JSON job specification (the document `POST /v1/jobs` accepts); flags override it.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Preset to start from (paper-table1, uniform-illumination); overrides the spec's preset.
    #[arg(long)]
    pub preset: Option<String>,
    /// Iterations M.
    #[arg(long, value_parser = parse_count, allow_hyphen_values = true)]
    pub iterations: Option<u64>,
    /// Light paths per iteration N_F.
    #[arg(long, value_parser = parse_count, allow_hyphen_values = true)]
    pub light_paths: Option<u64>,
    /// Camera paths per iteration N_B.
    #[arg(long, value_parser = parse_count, allow_hyphen_values = true)]
    pub camera_paths: Option<u64>,
    /// Seed of the random streams.
    #[arg(long, value_parser = parse_count, allow_hyphen_values = true)]
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
    /// Show the paper's published figures (Table 1) beside the noise table when the run's
    /// configuration is the paper's; otherwise say in which fields it differs.
    #[arg(long, conflicts_with = "json")]
    pub paper: bool,
    /// Write the run's statistics as a moments document (for `optimis merge`, `optimis report`
    /// or `POST /v1/jobs/{id}/merge`). `{shard}` in the name is replaced by the shard index (one
    /// file per task of a job array).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// With `--out`: also write the document every S seconds while the run goes on (each write
    /// atomic), so that a crash or a cluster's preemption loses at most S seconds of work.
    #[arg(long, value_name = "S", requires = "out", value_parser = checkpoint_seconds)]
    pub checkpoint_seconds: Option<f64>,
    /// With `--out`: if the file already holds the first iterations of this run (a run of the
    /// same configuration and seed, interrupted), continue from them instead of starting over.
    /// The result is bit-identical to an uninterrupted run.
    #[arg(long, requires = "out")]
    pub resume: bool,
    /// Set any field of the job document, by its dotted path (repeatable; applied after the spec
    /// file and the flags). VALUE is JSON if it parses (`0.01`, `true`, `null`, `{"w0": null}`),
    /// else a string: `--set scene.l3=9 --set solver.fixed.w0=null --set engine=brute`.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub set: Vec<String>,
    /// Write the noise table as CSV (one row per strategy).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the weights table as CSV (one row per cell; for a per-path recommendation, which has
    /// no table, its effective weights per (r2, r3) bin).
    #[arg(long, value_name = "FILE")]
    pub weights_csv: Option<PathBuf>,
    #[command(flatten)]
    pub progress: ProgressArgs,
}

/// Writes the report's tables as CSV where asked.
pub(super) fn write_csv(
    spec: &JobSpec,
    config: &SimConfig,
    report: &RunReport,
    noise: Option<&Path>,
    weights: Option<&Path>,
) -> Result<(), CliError> {
    if let Some(path) = noise {
        let published = applicable(spec);
        let csv = noise_table_csv(report, |s| paper_columns(&published, s.name()));
        write_atomically(path, csv.as_bytes())?;
    }
    if let Some(path) = weights {
        // A per-path recommendation has no table: its effective weights, labelled, rather than an
        // empty file a renderer would read as "no weights".
        let effective =
            report.weights.is_empty().then(|| recommended_effective(report, config, EFFECTIVE_PATHS)).flatten();
        let csv = match effective {
            Some(effective) => {
                eprintln!(
                    "{}: {} is a per-path weight function with no table: wrote its effective weights per (r2, r3) bin \
                     (`optimis weights` writes the function itself)",
                    path.display(),
                    effective.strategy
                );
                effective_csv(&effective)
            }
            None => weights_csv(report),
        };
        write_atomically(path, csv.as_bytes())?;
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
    Ok(spec.validate()?)
}

/// Writes `bytes` to `path`, through a synced temporary file and a rename so that a reader (or a
/// crashed run) never sees a partial file. The temporary name holds the process id: the tasks of a
/// job array write the same `sweep.json` at once, and a shared temporary file would be renamed
/// away under another task.
///
/// Only a regular file (or a new one) is replaced that way. A device, a pipe or a socket
/// (`--out /dev/null`, `--out /dev/stdout`) is written to: a rename would replace the device node
/// itself — run as root, `--out /dev/null` turned /dev/null into a regular file. A symbolic link
/// to a file keeps being a link: the file it points to is replaced. A path that names this
/// process's own standard output or error (`--out /dev/stdout > file`) is written through that
/// stream: replaced by a rename, the file would lose everything else the run prints there.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), CliError> {
    let fail = |source| CliError::Write { path: path.to_path_buf(), source };
    if let Some(mut stream) = own_stream(path) {
        return stream.write_all(bytes).and_then(|()| stream.flush()).map_err(fail);
    }
    let target = match std::fs::metadata(path) {
        Ok(m) if !m.is_file() && !m.is_dir() => return std::fs::write(path, bytes).map_err(fail),
        Ok(_) if path.is_symlink() => std::fs::canonicalize(path).map_err(fail)?,
        _ => path.to_path_buf(),
    };
    let tmp = target.with_extension(format!("partial-{}", std::process::id()));
    // Synced before the rename: after a crash or a power cut the name holds the old document or
    // the new one, never an empty file (a `--resume` reads it back).
    let written = std::fs::File::create(&tmp)
        .and_then(|mut file| file.write_all(bytes).and_then(|()| file.sync_all()))
        .and_then(|()| std::fs::rename(&tmp, &target));
    if written.is_err() {
        // Best effort: a temporary file left behind is only litter, the error is what counts.
        let _ = std::fs::remove_file(&tmp);
    }
    written.map_err(fail)
}

/// This process's standard output or error if `path` is the same file (device and inode), by
/// whatever name (`/dev/stdout`, `/proc/self/fd/1`, the redirected file's own path).
#[cfg(unix)]
fn own_stream(path: &Path) -> Option<Box<dyn Write>> {
    use std::os::fd::AsFd;
    use std::os::unix::fs::MetadataExt;
    let target = std::fs::metadata(path).ok()?;
    let same = |fd: std::os::fd::BorrowedFd<'_>| {
        let stream = std::fs::File::from(fd.try_clone_to_owned().ok()?).metadata().ok()?;
        Some((stream.dev(), stream.ino()) == (target.dev(), target.ino()))
    };
    if same(std::io::stdout().as_fd()) == Some(true) {
        Some(Box::new(std::io::stdout().lock()))
    } else if same(std::io::stderr().as_fd()) == Some(true) {
        Some(Box::new(std::io::stderr().lock()))
    } else {
        None
    }
}

#[cfg(not(unix))]
fn own_stream(_: &Path) -> Option<Box<dyn Write>> {
    None
}

/// Runs every iteration of `job` on `pool` into fresh moments, reporting progress on stderr.
pub(super) fn run_moments(job: &ValidJob, pool: &rayon::ThreadPool, progress: &ProgressArgs, label: &str) -> Moments {
    let never = AtomicBool::new(false);
    run_moments_from(job, pool, progress, label, Moments::new(job.config()), None, &never)
        .expect("a fresh run writes no checkpoints")
        .0
}

/// A flag the first SIGINT or SIGTERM sets (the run then stops after its batch and keeps what it
/// did); a second one ends the process at once, as the signal would without a handler.
pub(super) fn interruption() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    #[cfg(all(unix, feature = "server"))]
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // Best effort: without the handlers the signal ends the run as it always did.
        let _ = signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&flag));
        let _ = signal_hook::flag::register(signal, Arc::clone(&flag));
    }
    flag
}

/// A document written while the run goes on: where, and how often.
struct Checkpoints<'a> {
    path: &'a Path,
    every: Duration,
}

/// Runs the iterations of `job` that `moments` (the first ones, or none) does not hold, writing
/// the partial document every so often when asked; until `stop` is set, and then with whether it
/// was (the moments hold a prefix of the iterations either way).
fn run_moments_from(
    job: &ValidJob,
    pool: &rayon::ThreadPool,
    progress: &ProgressArgs,
    label: &str,
    mut moments: Moments,
    checkpoints: Option<Checkpoints<'_>>,
    stop: &AtomicBool,
) -> Result<(Moments, bool), CliError> {
    let config = &job.config();
    let range = job.spec().iteration_range();
    let total = range.end - range.start;
    let resumed = moments.iterations();
    // Progress and throughput count this run's own iterations (a resumed run's are not redone).
    let mut shown = Progress::new(progress, label, total - resumed, config.light_paths);
    let started = Instant::now();
    let mut last_write = Instant::now();
    let mut written = Ok(());
    // The engine is never cancelled mid-batch (a cancelled batch's iterations are dropped, and the
    // restricted engine hands its sums over only when asked): `stop` is read between batches.
    let never = AtomicBool::new(false);
    let outcome = pool.install(|| {
        run_iterations(config, job.spec().seed, range.start + resumed..range.end, &mut moments, &never, |m, next| {
            shown.update(next - range.start - resumed, started, config.light_paths);
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return std::ops::ControlFlow::Break(());
            }
            if let Some(c) = &checkpoints
                && last_write.elapsed() >= c.every
            {
                last_write = Instant::now();
                written =
                    write_atomically(c.path, &MomentsDocument::new(job.spec().clone(), m.moments().clone()).to_json());
                if written.is_err() {
                    return std::ops::ControlFlow::Break(());
                }
            }
            std::ops::ControlFlow::Continue(())
        })
    });
    let done = outcome
        .expect("the run is neither cancelled nor overlapping (a resumed document holds only its first iterations)");
    let interrupted = done < range.end;
    written?;
    if !interrupted {
        shown.finish();
    }
    Ok((moments, interrupted))
}

fn checkpoint_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && (0.1..=86_400.0).contains(&s) => Ok(s),
        _ => Err(format!("expected seconds in [0.1, 86400], got {text:?}")),
    }
}

/// `--out` with `{shard}` replaced by the shard's index.
fn out_path(out: &Path, spec: &JobSpec) -> PathBuf {
    match (out.to_str(), spec.shard) {
        (Some(text), Some(shard)) if text.contains("{shard}") => {
            PathBuf::from(text.replace("{shard}", &shard.index.to_string()))
        }
        _ => out.to_path_buf(),
    }
}

/// The moments of an interrupted run of `job` in `path` (`--resume`): none if the file does not
/// exist; refused unless it holds exactly the first iterations of this run's range, drawn under the
/// same configuration and seed.
fn resume_from(path: &Path, job: &ValidJob) -> Result<Moments, CliError> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Moments::new(job.config())),
        Err(source) => return Err(CliError::Read { path: path.to_path_buf(), source }),
    };
    let doc =
        MomentsDocument::from_json(&bytes).map_err(|source| CliError::Document { path: path.to_path_buf(), source })?;
    let range = job.spec().iteration_range();
    let held = doc.moments.iterations();
    let prefix = crate::sim::stats::coverage::Coverage::range(job.spec().seed, range.start, range.start + held);
    if doc.fingerprint != job.config().fingerprint() || doc.coverage != prefix || held > range.end - range.start {
        return Err(CliError::Config(format!(
            "--resume: {} does not hold the first iterations of this run (seed {}, iterations [{}, {})) under its configuration; remove it to start over",
            path.display(),
            job.spec().seed,
            range.start,
            range.end
        )));
    }
    Ok(doc.moments)
}

pub fn run(args: RunArgs) -> Result<(), CliError> {
    let job = job_from_args(&args)?;
    let pool = thread_pool(args.threads)?;
    let config = &job.config();
    let started = Instant::now();
    let out = args.out.as_deref().map(|p| out_path(p, job.spec()));
    let resumed = match &out {
        Some(path) if args.resume => resume_from(path, &job)?,
        _ => Moments::new(config),
    };
    let checkpoints = out
        .as_deref()
        .zip(args.checkpoint_seconds)
        .map(|(path, s)| Checkpoints { path, every: Duration::from_secs_f64(s) });
    let stop = interruption();
    let (moments, interrupted) = run_moments_from(&job, &pool, &args.progress, "", resumed, checkpoints, &stop)?;
    let seconds = started.elapsed().as_secs_f64();
    if let Some(path) = &out {
        write_atomically(path, &MomentsDocument::new(job.spec().clone(), moments.clone()).to_json())?;
    }
    if interrupted {
        let what = match &out {
            Some(path) => format!(
                "they are in {}: run the same command with --resume to continue (bit-identical to an uninterrupted run)",
                path.display()
            ),
            None => "nothing was kept (with --out FILE a run keeps its iterations, and --resume continues it)".into(),
        };
        let range = job.spec().iteration_range();
        return Err(CliError::Interrupted { done: moments.iterations(), total: range.end - range.start, what });
    }
    // On the run's pool: the quadrature evaluates its nodes in parallel there.
    let expected = pool.install(|| expected_luminances(config));
    let inputs =
        ReportInputs { reference: reference_luminance(&config.scene).ok(), expected: Some(&expected), weights: None };
    let mut report = build_report(&moments, &config.cells, &job.spec().solver, &inputs);
    report.radii = pool.install(|| super::radii::tallied(config, &moments, &job.spec().solver, &report));
    write_csv(job.spec(), config, &report, args.csv.as_deref(), args.weights_csv.as_deref())?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &report).map_err(std::io::Error::from)?;
        writeln!(out)?;
    } else {
        table::write_report(&mut out, job.spec(), &report, Some((seconds, pool.current_num_threads())), args.paper)?;
        super::radii::write_radii(&mut out, &report.radii)?;
    }
    Ok(())
}
