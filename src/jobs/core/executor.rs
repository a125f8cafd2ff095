//! Where a job's iterations run: the executor seam.
//!
//! The driver (`driver`) owns a job's life — its checkpoints, progress, stop requests and storage
//! retries — and asks an [`Executor`] for the work itself: "run these iterations of this job into
//! these moments, and give control back after each batch". The local rayon pool ([`LocalPool`])
//! is the default; `cluster::ClusterExecutor` runs them as arrays of a batch system (Slurm) whose
//! tasks write moments documents it merges. The driver, the scheduler and the lifecycle do not
//! change.
//!
//! Because iteration s draws only from the streams of (seed, s), any executor that runs the same
//! iterations returns bit-identical moments, however it divides them.

use std::ops::{ControlFlow, Range};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::sim::runner::{BatchMoments, RunError, run_iterations_within};
use crate::sim::spec::{JobSpec, SpecError, ValidJob};
use crate::sim::stats::moments::Moments;

/// What the driver calls after each batch: the moments so far and the next iteration index
/// (`first` + the iterations the moments hold, for an executor that runs them out of order);
/// [`ControlFlow::Break`] ends the segment (a checkpoint is due).
pub type OnBatch<'a> = dyn FnMut(&mut dyn BatchMoments, u64) -> ControlFlow<()> + Send + 'a;

/// One segment of a job, as the driver hands it to the executor.
pub struct Segment<'a> {
    /// The job's id.
    pub id: i64,
    /// The job, validated.
    pub job: &'a ValidJob,
    /// The job's first iteration (its whole range is `first..total`).
    pub first: u64,
    /// The iteration the job runs to (raised by extend while it runs).
    pub total: u64,
    /// Set when the job is asked to stop (cancel or shutdown).
    pub stop: &'a AtomicBool,
    /// Whether the stop is a cancel (work elsewhere is stopped too) rather than a shutdown (work
    /// elsewhere goes on, and is adopted at the next start).
    pub cancelled: &'a (dyn Fn() -> bool + Sync),
    /// Shows how the work is divided (the job resource's `execution`).
    pub report: &'a (dyn Fn(ExecutionView) + Sync),
    /// The most iterations between two calls of `on_batch` (the server's
    /// `--checkpoint-iterations`: a checkpoint, and a point of the job's history, can come no
    /// more often than `on_batch` is called).
    pub batch: u64,
}

/// Why a segment ended without all its iterations.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    /// Stopped, or the moments refused an iteration (see [`RunError`]).
    #[error(transparent)]
    Run(#[from] RunError),
    /// The work elsewhere failed for good (a cluster task out of retries, a refused submission):
    /// the job fails with this message, which names what failed and where its log is.
    #[error("{0}")]
    Failed(String),
}

/// Runs iterations of a job. Called on a blocking thread (never a tokio worker); one call is one
/// segment between two checkpoints, so its dynamic dispatch costs nothing per iteration.
pub trait Executor: Send + Sync {
    /// Refuses, at submission, a job this executor cannot run as asked (its `execution`).
    fn admit(&self, spec: &JobSpec) -> Result<(), SpecError>;

    /// Runs the iterations `range` (those the job still lacks: `moments` holds the others) into
    /// `moments`, calling `on_batch` after every batch, until the job has all its iterations,
    /// `on_batch` breaks or `segment.stop` is set (then `Err(RunError::Cancelled)`, with the
    /// completed batches kept in `moments`). Returns the next iteration index.
    fn run_segment(
        &self,
        segment: &Segment<'_>,
        range: Range<u64>,
        moments: &mut Moments,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, SegmentError>;

    /// Job `id` was cancelled while no driver followed it: stops what still runs for it
    /// elsewhere. Blocking (call on a blocking thread).
    fn cancel(&self, _id: i64) {}

    /// Threads a segment runs on in this process (what the engines' batch length depends on);
    /// none where the work runs elsewhere.
    fn threads(&self) -> Option<usize> {
        None
    }

    /// Job `id` was deleted: removes what the executor keeps for it. Blocking.
    fn forget(&self, _id: i64) {}
}

/// How a job's work is divided, as the job resource shows it (absent for the local pool).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ExecutionView {
    /// The batch system the tasks run on, as `--executor` names it: `slurm`.
    pub executor: String,
    /// The job's tasks, in the order of their iterations.
    pub tasks: Vec<TaskView>,
}

/// One task of a job on a cluster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TaskView {
    /// The task's number within the job, from 0 (an extension's tasks follow the earlier ones).
    pub index: u64,
    /// Its iterations: [first_iteration, first_iteration + iterations).
    pub first_iteration: u64,
    /// How many iterations it runs.
    pub iterations: u64,
    /// Iterations its latest document holds.
    pub iterations_done: u64,
    /// `submitting`, `pending`, `running`, `completed`, `failed` (being resubmitted) or the state
    /// the batch system reports (Slurm's `cancelled`, `timeout`, `node_fail`…), lower case.
    pub state: String,
    /// Its id in the batch system, once submitted: Slurm's job id (`ARRAY_TASK` for a task of an
    /// array). Named `slurm_job_id` until the executor could drive batch systems other than Slurm.
    pub batch_job_id: Option<String>,
    /// Submissions so far (1 + resubmissions).
    pub attempts: u32,
    /// The task's log file (stdout and stderr, every attempt appended).
    pub log: String,
}

/// The in-process executor: the server's own simulation pool, shared by the running jobs.
pub struct LocalPool {
    pool: Arc<rayon::ThreadPool>,
}

impl LocalPool {
    /// An executor on `pool`.
    pub fn new(pool: Arc<rayon::ThreadPool>) -> Self {
        Self { pool }
    }
}

impl Executor for LocalPool {
    fn threads(&self) -> Option<usize> {
        Some(self.pool.current_num_threads())
    }

    fn admit(&self, spec: &JobSpec) -> Result<(), SpecError> {
        match spec.execution {
            None => Ok(()),
            Some(_) => Err(SpecError::new(
                "execution",
                "this server runs jobs on its own pool; cutting a job into tasks needs a server started with --executor slurm",
            )),
        }
    }

    fn run_segment(
        &self,
        segment: &Segment<'_>,
        range: Range<u64>,
        moments: &mut Moments,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, SegmentError> {
        let (config, seed) = (segment.job.config(), segment.job.spec().seed);
        Ok(self
            .pool
            .install(|| run_iterations_within(config, seed, range, moments, segment.stop, segment.batch, on_batch))?)
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::sim::spec::parse_job_spec;

    #[test]
    fn the_local_pool_refuses_a_division_into_tasks() {
        let pool = LocalPool::new(Arc::new(rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap()));
        let plain = parse_job_spec(&json!({ "iterations": 10 })).unwrap();
        assert!(pool.admit(&plain).is_ok());
        let divided = parse_job_spec(&json!({ "iterations": 10, "execution": { "tasks": 2 } })).unwrap();
        let refused = pool.admit(&divided).unwrap_err();
        assert_eq!(refused.field, "execution");
        assert!(refused.message.contains("--executor slurm"), "{refused}");
    }
}
