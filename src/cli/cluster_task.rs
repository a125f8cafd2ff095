//! `optimis cluster-task`: one task of a job the server runs on Slurm (`serve --executor slurm`);
//! the server hands this command to `sbatch --wrap`, nobody types it. A thin shell around
//! `jobs::cluster::task`: the task index from `--task`, or from `SLURM_ARRAY_TASK_ID` for an
//! array's tasks.

use std::collections::HashMap;
use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::CliError;
use super::shard::task_index;
use crate::jobs::cluster::task::{TaskOptions, run_task};
use crate::sim::spec::SpecError;

#[derive(Debug, Args)]
pub struct ClusterTaskArgs {
    /// The cluster directory (the server's `--cluster-dir`, as the nodes see it).
    #[arg(long)]
    pub cluster_dir: PathBuf,
    /// The server's job id.
    #[arg(long)]
    pub job: i64,
    /// The round (the job's first iterations are round 0, each extension the next).
    #[arg(long)]
    pub round: usize,
    /// Tasks in the round.
    #[arg(long)]
    pub tasks: u64,
    /// This task's index; default: SLURM_ARRAY_TASK_ID (minus SLURM_ARRAY_TASK_MIN).
    #[arg(long)]
    pub task: Option<u64>,
    /// Worker threads.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Seconds between two partial documents.
    #[arg(long, default_value_t = 10.0)]
    pub checkpoint_seconds: f64,
}

pub fn cluster_task(args: ClusterTaskArgs) -> Result<(), CliError> {
    let task = match args.task {
        Some(k) => k,
        None => {
            let environment: HashMap<String, String> = std::env::vars().collect();
            task_index(&environment)?
                .ok_or_else(|| SpecError::new("SLURM_ARRAY_TASK_ID", "is not set; give --task"))?
                .index
        }
    };
    let options = TaskOptions {
        cluster_dir: args.cluster_dir,
        job: args.job,
        round: args.round,
        task,
        tasks: args.tasks,
        threads: args.threads,
        checkpoint_seconds: args.checkpoint_seconds.clamp(0.1, 86_400.0),
    };
    let iterations = run_task(&options).map_err(|e| CliError::Config(format!("cluster task: {e}")))?;
    // Not eprintln!: a log on a full disk must not fail a task whose document is written.
    let _ = writeln!(std::io::stderr(), "optimis cluster-task: task {task} wrote its {iterations} iterations");
    Ok(())
}
