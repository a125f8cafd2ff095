//! The job runner: queued jobs, run a bounded number at a time by an executor (the local rayon
//! pool, or a Slurm cluster), with progress in memory and checkpoints in the store; and the features built on
//! them — statistics, named solves, predictions, sweeps — each a handle of its own.
//!
//! Imports: crate::sim, crate::store, crate::metrics
//!
//! Layout, top down (each module imports only those below it):
//! * [`services`] — every handle, built once; the HTTP state holds them;
//! * [`sweeps`] — sweeps: their runs queued as jobs, their figures and table;
//! * [`solves`] — named re-solves kept with a job; [`prediction`] — a job's noise table predicted
//!   at another ray budget;
//! * [`merges`], [`evaluation`] — merges and studies, given weights scored: operations of the
//!   [`statistics`] handle — results, histories, re-solves, the moments export;
//! * [`manager`] — the lifecycle core: start and recovery, submit, get, list, cancel, extend,
//!   delete, shutdown;
//! * [`toolbox`] — the manager's handle and what the features may do with the core;
//! * [`scheduler`] — starts queued jobs in submission order while workers are free;
//! * [`driver`] — runs one job segment by segment and writes its checkpoints;
//! * [`state`] — the jobs in memory (`ActiveJob`, `StopReason`) and the transitions of their state;
//! * [`cluster`] — the Slurm executor: a job's iterations as job arrays, followed and merged;
//! * [`executor`] — where the iterations of a segment run: the seam, and the local pool;
//! * [`checkpoint`] — the stored forms: spec JSON, checkpoint encoding, verified decoding, and the
//!   memory of verified checkpoints;
//! * [`compute`] — the pools a request's CPU work runs on: light work, and bounded heavy work;
//! * [`references`] — each configuration's expected luminances, computed once;
//! * [`policy`] — what this server accepts: budgets, the work of an iteration, extension targets;
//! * [`peers`] — moments documents pulled from allowed peer servers, for merges; [`peer_tls`] —
//!   how https peers' certificates are verified (roots, and `--peer-ca` pins);
//! * [`signing`] — provenance: this server's signature on exports, the keys merges require;
//! * [`shares`] — who a request comes from, and each client's share of a shared budget;
//! * [`resource`], [`documents`] — what the API shows of a job; [`lineage`] — where a merged
//!   job's statistics come from; [`error`] — what job operations
//!   fail with.

pub mod artifacts;
pub mod checkpoint;
pub mod cluster;
pub mod compute;
pub mod documents;
pub mod driver;
pub mod error;
pub mod evaluation;
pub mod executor;
pub mod lineage;
pub mod manager;
pub mod merges;
pub mod peer_tls;
pub mod peers;
pub mod policy;
pub mod prediction;
pub mod references;
pub mod resource;
pub mod scheduler;
pub mod services;
pub mod shares;
pub mod signing;
pub mod solves;
pub mod state;
pub mod statistics;
pub mod sweeps;
pub mod toolbox;

pub use error::JobError;
pub use executor::{Executor, LocalPool};
pub use policy::RunPolicy;
pub use services::Services;
pub use toolbox::JobManager;
