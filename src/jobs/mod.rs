//! The job runner: queued jobs, run a bounded number at a time on a dedicated rayon pool, with
//! progress in memory and checkpoints in the store.
//!
//! * [`manager`] — the queue, the worker slots and every change of a job's state;
//! * [`statistics`] — results, re-solves, the moments export, merges and studies;
//! * [`driver`] — runs one job segment by segment and writes its checkpoints;
//! * [`peers`] — moments documents pulled from allowed peer servers, for merges;
//! * [`resource`], [`documents`] — what the API shows of a job;
//! * [`error`] — what job operations fail with.

pub mod documents;
pub mod driver;
pub mod error;
pub mod manager;
pub mod peers;
pub mod resource;
pub mod statistics;

pub use error::JobError;
pub use manager::{JobManager, RunPolicy};
