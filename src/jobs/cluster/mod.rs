//! Running jobs on a Slurm cluster (`optimis serve --executor slurm`): each job as Slurm job
//! arrays whose tasks run `optimis run` on shards of its iterations and write moments documents
//! to a directory the server and the nodes share; the server follows them with `squeue` and the
//! files, merges the documents exactly, resubmits failed tasks and adopts running ones after a
//! restart. Slurm schedules; nothing here is a scheduler of its own.
//!
//! Imports: crate::jobs::core::executor, crate::sim, crate::metrics
//!
//! * [`executor`] — the executor: rounds submitted, tasks followed, failures retried, merges;
//! * [`tracking`] — one job's tasks between two looks: documents read, states judged;
//! * [`files`] — the cluster directory: the job's record, specifications, documents, logs;
//! * [`private`] — a directory only this user can change, used without following links;
//! * [`task`] — one task on a node (`optimis cluster-task`): its shard run, its document written;
//! * [`slurm`] — sbatch, squeue and scancel: argv, timeouts, parsing;
//! * [`command`] — external commands with a deadline and bounded output;
//! * [`options`] — the executor's settings, validated at start-up.

pub mod command;
pub mod executor;
pub mod files;
pub mod options;
pub mod private;
pub mod slurm;
pub mod task;
pub mod tracking;

pub use executor::SlurmExecutor;
pub use options::SlurmOptions;
