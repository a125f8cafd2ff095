//! The job runner: its lifecycle core — jobs queued, run a bounded number at a time by an
//! executor (the local rayon pool, or a batch cluster), with progress in memory and checkpoints in
//! the store — and the features built on it, each a handle of its own.
//!
//! Imports: crate::sim, crate::store, crate::metrics, crate::trust
//!
//! Rooms, top down (each imports only those below it; `tests/architecture.rs` holds them to it):
//! * [`services`] — every handle, built once; the HTTP state holds them;
//! * [`sweeps`] — sweeps: their runs queued as jobs, their figures and table;
//! * [`solves`] — named re-solves kept with a job; [`prediction`] — a job's noise table predicted
//!   at another ray budget; [`artifacts`] — its weight function as a portable artifact;
//!   [`evaluation`] — given weights scored on it;
//! * [`statistics`] — results, histories, re-solves, the moments export;
//! * [`merges`] — merges and studies, with the peers they pull from and each client's share;
//! * [`cluster`] — the cluster executor: a job's iterations as batch-system job arrays, followed
//!   and merged;
//! * [`core`] — the lifecycle: manager, scheduler, drivers, job state, checkpoints, policy, the
//!   executor seam and the local pool. It knows no feature.

pub mod artifacts;
pub mod cluster;
pub mod core;
pub mod evaluation;
pub mod merges;
pub mod prediction;
pub mod services;
pub mod solves;
pub mod statistics;
pub mod sweeps;

pub use self::core::error::JobError;
pub use self::core::executor::{Executor, LocalPool};
pub use self::core::manager::JobManager;
pub use self::core::policy::RunPolicy;
pub use services::Services;
