//! The seam between the cluster executor and a batch system: what rounds, retries and adoption
//! need from one, and nothing of how it is driven. The executor submits a round's tasks as one
//! array (or one task again, alone), lists the job's tasks by the names it gave them, and cancels;
//! everything else — the record, the documents, the merges, the judging of states, the retries —
//! is the executor's and the same for every system.
//!
//! A batch system is one file implementing [`BatchSystem`] (Slurm's is `slurm`; the tests'
//! stand-in is `fake`) and one arm of [`super::options::BatchSystemKind`] carrying its settings.

use std::path::PathBuf;

/// What one submission asks for.
pub struct Submission<'a> {
    /// The name the system files it under. A restart finds a submission whose id was never
    /// recorded by this name ([`QueueEntry::name`] must give it back as it was given).
    pub name: &'a str,
    /// A round's tasks as one array, or one task alone.
    pub tasks: Tasks,
    /// The task command (argv), to run as it is: nothing of it may be written into a script
    /// another user could replace. An array's command lacks the task's index: see [`Tasks::Array`].
    pub command: &'a [String],
    /// CPUs each task gets (the command's `--threads`).
    pub cpus: u32,
    /// Task `k`'s log (its stdout and stderr, every attempt appended), `k` given as text: for an
    /// array, the system's own placeholder for "this task's index" may be passed (Slurm's `%a`).
    pub log: &'a dyn Fn(&str) -> PathBuf,
}

/// Which tasks a submission runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tasks {
    /// Tasks `0..count`, as one array. Each task learns its index from its environment (the
    /// variables `optimis cluster-task` reads: `SLURM_ARRAY_TASK_ID`, `JOB_COMPLETION_INDEX`), or
    /// from `--task K` that the system appends to its command.
    Array(u64),
    /// Task `k` alone (a resubmission): its command already says `--task K`.
    One(u64),
}

/// What a task's state means to the executor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Waiting, running, suspended, requeued…: it may yet write its document.
    Active,
    /// Ended as the system counts success: its document is expected (after a grace, since shared
    /// filesystems lag).
    Completed,
    /// Ended otherwise (failed, cancelled, timed out, its node lost): it runs again if its
    /// document is incomplete.
    Ended,
}

/// One task the system knows: a task of an array, or one submitted alone.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueueEntry {
    /// The task's id: [`BatchSystem::array_task_id`] for a task of an array, else the id
    /// [`BatchSystem::submit`] returned.
    pub id: String,
    /// The id [`BatchSystem::submit`] returned for what the task belongs to (its array's, or its
    /// own): what a restart adopts.
    pub submission: String,
    /// The system's word for the task's state, as it writes it (Slurm's `RUNNING`, `FAILED`…):
    /// shown, lower case, in the job resource, and in a failed job's message.
    pub state: String,
    /// What that state means here.
    pub phase: Phase,
    /// The name it was submitted with.
    pub name: String,
}

/// Why the batch system gave no usable answer, sorted by what the executor does next.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// Trying again later may succeed (a timeout, a controller busy or unreachable): a submission
    /// is tried again at the next look.
    #[error(transparent)]
    Transient(Box<dyn std::error::Error + Send + Sync>),
    /// Asking again will not help (a refused account, partition or limit; an answer not
    /// understood): a submission fails the job with the system's message.
    #[error(transparent)]
    Refused(Box<dyn std::error::Error + Send + Sync>),
}

impl BatchError {
    /// Whether trying again later may succeed.
    pub fn is_transient(&self) -> bool {
        matches!(self, BatchError::Transient(_))
    }
}

/// A batch system the cluster executor runs tasks on. Its calls block (the executor makes them on
/// a job's driver thread, never a tokio worker) and must end within a deadline of their own.
pub trait BatchSystem: Send + Sync {
    /// The system's name as people write it (`Slurm`): in messages, and in lower case as the job
    /// resource's `execution.executor` and as `--executor` names it.
    fn name(&self) -> &'static str;

    /// That the system is there and answers, checked once at start-up: its version, for the log.
    fn check(&self) -> Result<String, BatchError>;

    /// Submits `submission`; the system's id for it (an array's, or the task's).
    fn submit(&self, submission: &Submission<'_>) -> Result<String, BatchError>;

    /// This user's tasks whose names start with `prefix`, one entry per task of an array, finished
    /// ones included while the system remembers them (a forgotten task counts as gone).
    fn queue(&self, prefix: &str) -> Result<Vec<QueueEntry>, BatchError>;

    /// The id of task `k` of the array `array` (as `submit` returned it), as `queue` reports it
    /// and the job resource shows it.
    fn array_task_id(&self, array: &str, k: u64) -> String;

    /// Stops submissions (an array's id stops all its tasks) and tasks by id. Ids the system has
    /// forgotten are not an error.
    fn cancel(&self, ids: &[String]) -> Result<(), BatchError>;
}
