//! Where a job's iterations run: the executor seam.
//!
//! The driver (`driver`) owns a job's life — its checkpoints, progress, stop requests and storage
//! retries — and asks an [`Executor`] for the work itself: "run these iterations of this job into
//! these moments, and give control back after each batch". The local rayon pool
//! ([`LocalPool`]) is the executor today; one that runs the iterations elsewhere (a cluster's
//! job array, whose tasks write checkpoint documents the executor merges) implements the same
//! trait, and the driver, the scheduler and the lifecycle do not change.
//!
//! Because iteration s draws only from the streams of (seed, s), any executor that runs the same
//! iterations returns bit-identical moments, however it divides them.

use std::ops::{ControlFlow, Range};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use crate::sim::model::config::SimConfig;
use crate::sim::runner::{RunError, run_iterations};
use crate::sim::stats::moments::Moments;

/// What the driver calls after each batch: the moments so far and the next iteration index;
/// [`ControlFlow::Break`] ends the segment (a checkpoint is due).
pub type OnBatch<'a> = dyn FnMut(&Moments, u64) -> ControlFlow<()> + Send + 'a;

/// Runs iterations of a job. Called on a blocking thread (never a tokio worker); one call is one
/// segment between two checkpoints, so its dynamic dispatch costs nothing per iteration.
pub trait Executor: Send + Sync {
    /// Runs iterations `range` of the configuration `config` with `seed` into `moments`, calling
    /// `on_batch` after every batch, until the range is done, `on_batch` breaks or `stop` is set
    /// (then `Err(RunError::Cancelled)`, with the completed batches kept in `moments`). Returns
    /// the next iteration index.
    fn run_segment(
        &self,
        config: &SimConfig,
        seed: u64,
        range: Range<u64>,
        moments: &mut Moments,
        stop: &AtomicBool,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, RunError>;
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
    fn run_segment(
        &self,
        config: &SimConfig,
        seed: u64,
        range: Range<u64>,
        moments: &mut Moments,
        stop: &AtomicBool,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, RunError> {
        self.pool.install(|| run_iterations(config, seed, range, moments, stop, on_batch))
    }
}
