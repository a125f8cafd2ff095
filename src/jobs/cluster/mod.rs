//! Running jobs on a cluster's batch system (`optimis serve --executor slurm`): each job as
//! arrays of the system whose tasks run `optimis cluster-task` on shards of its iterations and
//! write moments documents to a directory the server and the nodes share; the server follows them
//! through the system's queue and the files, merges the documents exactly, resubmits failed tasks
//! and adopts running ones after a restart. The batch system schedules; nothing here is a
//! scheduler of its own.
//!
//! Everything but the system's own commands is the same for every system: a second one (PBS,
//! Kubernetes indexed Jobs) is one file implementing [`system::BatchSystem`] and one arm of
//! [`options::BatchSystemKind`].
//!
//! Imports: crate::jobs::core::executor, crate::sim, crate::metrics
//!
//! * [`executor`] — the executor: rounds submitted, tasks followed, failures retried, merges;
//! * [`tracking`] — one job's tasks between two looks: documents read, states judged;
//! * [`system`] — the seam: what the executor asks of a batch system;
//! * [`slurm`] — Slurm: its settings, sbatch, squeue and scancel (argv, timeouts, parsing);
//! * `fake` — the tests' stand-in batch system: tasks as local processes;
//! * [`files`] — the cluster directory: the job's record, specifications, documents, logs;
//! * [`private`] — a directory only this user can change, used without following links;
//! * [`task`] — one task on a node (`optimis cluster-task`): its shard run, its document written;
//! * [`command`] — external commands with a deadline and bounded output;
//! * [`options`] — the executor's settings and the batch system named once, validated at start-up.

pub mod command;
pub mod executor;
#[doc(hidden)]
pub mod fake;
pub mod files;
pub mod options;
pub mod private;
pub mod slurm;
pub mod system;
pub mod task;
pub mod tracking;

pub use executor::ClusterExecutor;
pub use options::{BatchSystemKind, ClusterOptions};
pub use slurm::SlurmOptions;
