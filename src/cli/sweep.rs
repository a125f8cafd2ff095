//! `optimis sweep`: a sweep run locally, or one of its runs per task of a cluster job array, and
//! `optimis sweep collect` to build the table from the runs' moments documents.
//!
//! With `--out DIR` every run writes `DIR/run-K.json` (its moments document) and `DIR/sweep.json`
//! (the sweep document, identical from every task), so `collect` needs nothing but the directory.
//! A task's index comes from `--task K`, else from `SLURM_ARRAY_TASK_ID` (minus
//! `SLURM_ARRAY_TASK_MIN`) or `JOB_COMPLETION_INDEX`, like `run --shard`; `--runs` prints how many
//! tasks the array needs. The table is the one `GET /v1/sweeps/{id}/table` answers for the same
//! sweep, byte for byte.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};

use super::documents::read_document;
use super::progress::ProgressArgs;
use super::run::{read_json, run_moments, write_atomically};
use super::shard::task_index;
use super::{CliError, table, thread_pool};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::MomentsDocument;
use crate::sim::solve::report::{ReportInputs, build_report};
use crate::sim::spec::SpecError;
use crate::sim::stats::moments::Moments;
use crate::sim::sweep::{PointFigures, PointResults, SweepPlan, SweepTable, plan, point_figures};

/// Most points of a sweep run from the command line.
const DEFAULT_MAX_POINTS: usize = 4096;

#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: Option<SweepCommand>,
    #[command(flatten)]
    pub run: SweepRunArgs,
}

#[derive(Debug, Subcommand)]
pub enum SweepCommand {
    /// Build the table of a sweep whose runs wrote their moments into DIR (`--out DIR`).
    Collect(CollectArgs),
}

#[derive(Debug, Args)]
pub struct SweepRunArgs {
    /// The sweep document (`{"base": {…}, "axes": […], "mode": "grid" | "zip"}`, as `POST /v1/sweeps`).
    #[arg(long, required = true)]
    pub spec: Option<PathBuf>,
    /// Write every run's moments to DIR/run-K.json and the sweep to DIR/sweep.json.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Run only run K (from 0) into --out; default from SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "K")]
    pub task: Option<usize>,
    /// Print the number of runs (the tasks of a job array) and exit.
    #[arg(long)]
    pub runs: bool,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the table as CSV.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Worker threads (default: one per core). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Most points the sweep may have.
    #[arg(long, default_value_t = DEFAULT_MAX_POINTS)]
    pub max_points: usize,
    #[command(flatten)]
    pub progress: ProgressArgs,
}

#[derive(Debug, Args)]
pub struct CollectArgs {
    /// The directory the runs wrote into.
    pub dir: PathBuf,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the table as CSV.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
}

pub fn sweep(args: SweepArgs) -> Result<(), CliError> {
    match args.command {
        Some(SweepCommand::Collect(c)) => collect(c),
        None => run_sweep(args.run),
    }
}

fn plan_of(path: &PathBuf, max_points: usize) -> Result<SweepPlan, CliError> {
    let document = read_json(path)?;
    Ok(plan(&document, max_points)?)
}

fn run_file(dir: &Path, run: usize) -> PathBuf {
    dir.join(format!("run-{run}.json"))
}

fn run_sweep(args: SweepRunArgs) -> Result<(), CliError> {
    let spec_path = args.spec.clone().expect("clap requires --spec");
    let plan = plan_of(&spec_path, args.max_points)?;
    if args.runs {
        println!("{}", plan.runs.len());
        return Ok(());
    }
    let task = match (&args.out, args.task) {
        (None, Some(_)) => return Err(SpecError::new("--task", "needs --out DIR for the run's moments").into()),
        (None, None) => None,
        (Some(_), Some(k)) => Some(k),
        (Some(_), None) => scheduler_index()?,
    };
    if let Some(k) = task
        && k >= plan.runs.len()
    {
        return Err(
            SpecError::new("--task", format!("must be below the sweep's {} runs, got {k}", plan.runs.len())).into()
        );
    }
    let pool = thread_pool(args.threads)?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).map_err(|source| CliError::Write { path: dir.clone(), source })?;
        let text = serde_json::to_vec_pretty(&plan.spec).map_err(std::io::Error::from)?;
        write_atomically(&dir.join("sweep.json"), &text)?;
    }
    let selected: Vec<usize> = match task {
        Some(k) => vec![k],
        None => (0..plan.runs.len()).collect(),
    };
    let mut figures = Vec::new();
    for &r in &selected {
        let job = plan.runs[r].spec.validate()?;
        let label = format!("run {r} of {} ({}): ", plan.runs.len(), plan.describe_run(r));
        let moments = run_moments(&job, &pool, &args.progress, &label);
        if let Some(dir) = &args.out {
            write_atomically(&run_file(dir, r), &MomentsDocument::new(job.spec().clone(), moments.clone()).to_json())?;
        }
        figures.extend(run_figures(&plan, r, &moments)?);
    }
    if task.is_some() && !args.progress.quiet {
        eprintln!("run {} written; `optimis sweep collect DIR` builds the table once every run has", selected[0]);
        return Ok(());
    }
    write_table(&plan, &PointResults::collect(&plan, figures), args.json, args.csv.as_deref())
}

/// The figures of every point run `r` answers, from its moments.
fn run_figures(plan: &SweepPlan, r: usize, moments: &Moments) -> Result<Vec<(usize, PointFigures)>, CliError> {
    let job = plan.runs[r].spec.validate()?;
    let reference = reference_luminance(&job.config().scene).ok();
    let expected = expected_luminances(job.config());
    let inputs = ReportInputs { reference, expected: Some(&expected), weights: None };
    let report = build_report(moments, &job.config().cells, &job.spec().solver, &inputs);
    Ok(point_figures(plan, r, moments, &job.config().cells, &report, false))
}

fn collect(args: CollectArgs) -> Result<(), CliError> {
    let plan = plan_of(&args.dir.join("sweep.json"), usize::MAX)?;
    let mut figures = Vec::new();
    for r in 0..plan.runs.len() {
        let path = run_file(&args.dir, r);
        if !path.exists() {
            return Err(CliError::Config(format!(
                "{} is missing: run {r} of the sweep's {} has not finished (optimis sweep --spec … --task {r} --out {})",
                path.display(),
                plan.runs.len(),
                args.dir.display()
            )));
        }
        let doc = read_document(&path)?;
        if doc.spec != plan.runs[r].spec {
            return Err(CliError::Config(format!(
                "{} holds another job than run {r} of {}: the sweep document changed since it ran",
                path.display(),
                args.dir.join("sweep.json").display()
            )));
        }
        figures.extend(run_figures(&plan, r, &doc.moments)?);
    }
    write_table(&plan, &PointResults::collect(&plan, figures), args.json, args.csv.as_deref())
}

fn write_table(plan: &SweepPlan, results: &[PointResults], json: bool, csv: Option<&Path>) -> Result<(), CliError> {
    let table = SweepTable::build(plan, results);
    if let Some(path) = csv {
        write_atomically(path, table.to_csv().as_bytes())?;
    }
    let mut out = std::io::stdout().lock();
    if json {
        serde_json::to_writer_pretty(&mut out, &table).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    let each = plan.points.iter().zip(results).flat_map(|(p, r)| [(p, &r.figures), (p, &r.measured)]);
    for (point, f) in each {
        let Some(f) = f else { continue };
        let values: Vec<String> =
            plan.spec.axes.iter().zip(&point.values).map(|(a, v)| format!("{} = {v}", a.field)).collect();
        let source = serde_json::to_value(f.source).map_err(std::io::Error::from)?;
        writeln!(
            out,
            "point {}: {} ({}, N_F = {}, N_B = {}, {} iterations)",
            point.index,
            values.join(", "),
            source.as_str().unwrap_or_default(),
            f.budget.light_paths,
            f.budget.camera_paths,
            f.iterations
        )?;
        let folds = plan.runs[point.run].spec.folds.unwrap_or(10);
        table::write_noise_rows(&mut out, &f.noise_table, folds, f.recommended.as_ref())?;
        if let Some(e) = &f.error {
            writeln!(out, "  {e}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The task index a batch scheduler gives this process, if any.
fn scheduler_index() -> Result<Option<usize>, CliError> {
    let environment: std::collections::HashMap<String, String> = std::env::vars().collect();
    Ok(task_index(&environment)?.map(|t| t.index as usize))
}
