//! The lifecycle core: jobs accepted, queued in submission order, run a bounded number at a time
//! by an executor, checkpointed, recovered at start, cancelled, extended and deleted — and what
//! the API shows of them. Nothing here knows a feature: statistics, merges, solves, predictions,
//! sweeps and the cluster executor are built on this folder in `jobs/`, never the other way round
//! (tests/architecture.rs holds the folder to it).
//!
//! Imports: crate::sim, crate::store, crate::metrics
//!
//! Layout, top down (each module imports only those below it):
//! * [`manager`] — the handle: start, submit, get, list, cancel, extend, delete, shutdown, and the
//!   small toolbox the features use; `recovery` — what a previous server left unfinished;
//! * [`scheduler`] — starts queued jobs in submission order while workers are free;
//! * [`driver`] — runs one job segment by segment and writes its checkpoints;
//! * [`state`] — the jobs in memory (`ActiveJob`, `StopReason`, `Hold`) and the transitions of
//!   their state;
//! * [`executor`] — where the iterations of a segment run: the seam, and the local pool;
//! * [`checkpoint`] — the stored forms: spec JSON, checkpoint encoding, verified decoding, and the
//!   memory of verified checkpoints;
//! * [`compute`] — the pools a request's CPU work runs on: light work, and bounded heavy work;
//! * [`references`] — each configuration's expected luminances, computed once;
//! * [`policy`] — what this server accepts: budgets, the work of an iteration, extension targets;
//! * [`resource`], [`documents`] — what the API shows of a job; [`lineage`] — where a merged
//!   job's statistics come from (a field of the job's resource);
//! * [`error`] — what job operations fail with.

pub mod checkpoint;
pub mod compute;
pub mod documents;
pub mod driver;
pub mod error;
pub mod executor;
pub mod lineage;
pub mod manager;
pub mod policy;
mod recovery;
pub mod references;
pub mod resource;
pub mod scheduler;
pub mod state;
