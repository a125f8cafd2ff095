//! The job runner: queued jobs, run a bounded number at a time on a dedicated rayon pool, with
//! progress in memory and checkpoints in the store.
//!
//! * [`manager`] — the queue, the worker slots and every change of a job's state;
//! * [`driver`] — runs one job segment by segment and writes its checkpoints;
//! * [`peers`] — moments documents pulled from other servers, for merges;
//! * [`resource`], [`documents`] — what the API shows of a job;
//! * [`error`] — what job operations fail with.

pub mod documents;
pub mod driver;
pub mod error;
pub mod manager;
pub mod peers;
pub mod resource;

pub use error::JobError;
pub use manager::{JobManager, RunPolicy};
