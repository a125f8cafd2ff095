//! The job manager's handle and its toolbox for the feature handles (statistics, solves,
//! predictions, sweeps): the few things they may do with the core — run work on the request pools, read the store and the
//! policy, look at and queue active jobs under the lifecycle lock, hold a finished job for an
//! operation, verify a checkpoint. The lifecycle itself (start, submit, cancel, extend, delete,
//! shutdown) is implemented on the same handle in `manager`, which builds on these.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64};

use tokio::sync::{MutexGuard, watch};

use super::checkpoint;
use super::compute::Stop;
use super::error::JobError;
use super::policy::RunPolicy;
use super::resource::{JobResource, JobState};
use super::state::{ActiveJob, Hold, Inner};
use crate::metrics::Metrics;
use crate::sim::spec::ValidJob;
use crate::store::{Checkpoint, Store};

/// Handle to the job manager; cheap to clone.
#[derive(Clone)]
pub struct JobManager {
    pub(super) inner: Arc<Inner>,
}

impl JobManager {
    /// Runs light work `f` (parsing, validation, checksums) on the request pool and awaits it.
    pub(crate) async fn compute<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, JobError> {
        self.inner.pools.light(f).await
    }

    /// Runs heavy work `f` (quadratures, re-fits, re-solves, predictions) on the bounded heavy
    /// pool (`compute`): 429 when it stays full; `f` can see that its request went away.
    pub(crate) async fn compute_heavy<T: Send + 'static>(
        &self,
        f: impl FnOnce(&Stop) -> T + Send + 'static,
    ) -> Result<T, JobError> {
        self.inner.pools.heavy(self.shutdown_signal(), f).await
    }

    /// Receives shutdown: true once the server is stopping.
    pub fn shutdown_signal(&self) -> watch::Receiver<bool> {
        self.inner.shutdown.subscribe()
    }

    /// Whether the server is stopping (new work is refused).
    pub(crate) fn is_shutting_down(&self) -> bool {
        *self.inner.shutdown.borrow()
    }

    /// The store behind the manager.
    pub fn store(&self) -> &Store {
        &self.inner.store
    }

    /// The server's metrics.
    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.inner.metrics
    }

    /// What this server accepts.
    pub(crate) fn policy(&self) -> &RunPolicy {
        &self.inner.policy
    }

    /// Takes the lifecycle lock: state checks and the database writes they decide are atomic with
    /// respect to every other transition while the guard lives. Never hold it across computation.
    pub(crate) async fn transition(&self) -> MutexGuard<'_, ()> {
        self.inner.lifecycle.lock().await
    }

    /// The queued or running job `id`, if it is one.
    pub(crate) fn active(&self, id: i64) -> Option<Arc<ActiveJob>> {
        self.inner.active.lock().expect("active map").get(&id).cloned()
    }

    /// Jobs waiting for a worker.
    pub(crate) fn queued(&self) -> usize {
        self.inner.queue.lock().expect("queue").len()
    }

    /// Whether job `id` waits for a worker (queued, not running).
    pub(crate) fn is_queued(&self, id: i64) -> bool {
        self.inner.queue.lock().expect("queue").contains(&id)
    }

    /// Queues job `id` (whose row is committed) behind the others (call under the lifecycle lock).
    pub(crate) fn enqueue(&self, id: i64, job: ValidJob, resource: JobResource) {
        let total = resource.progress.iterations_total;
        let active = Arc::new(ActiveJob {
            id,
            start: job.spec().iteration_range().start,
            job,
            stop: AtomicBool::new(false),
            stop_reason: AtomicU8::new(0),
            total: AtomicU64::new(total),
            view: watch::channel(resource).0,
        });
        self.inner.active.lock().expect("active map").insert(id, active);
        self.inner.queue.lock().expect("queue").push_back(id);
        self.inner.wake.notify_one();
    }

    /// Forgets a queued job whose row is gone or cancelled (call under the lifecycle lock): out of
    /// the queue and memory, its watchers told it is cancelled.
    pub(crate) fn discard_queued(&self, id: i64) {
        self.inner.queue.lock().expect("queue").retain(|&q| q != id);
        if let Some(job) = self.inner.active.lock().expect("active map").remove(&id) {
            job.view.send_modify(|r| r.state = JobState::Cancelled);
        }
    }

    /// Holds the finished job `id` for an operation (a merge; call under the lifecycle lock), or
    /// says that another operation holds it. Extend and delete refuse a held job.
    pub(crate) fn hold(&self, id: i64) -> Result<Hold, JobError> {
        if !self.inner.held.lock().expect("held set").insert(id) {
            return Err(JobError::Conflict(format!("job {id} is taking another merge; retry when it has finished")));
        }
        Ok(Hold { inner: self.inner.clone(), id })
    }

    /// Whether an operation holds job `id`.
    pub(crate) fn is_held(&self, id: i64) -> bool {
        self.inner.held.lock().expect("held set").contains(&id)
    }

    /// The latest checkpoint of job `id`, its checksum verified (`checkpoint::verified_checkpoint`).
    pub(crate) async fn verified_checkpoint(&self, id: i64) -> Result<Checkpoint, JobError> {
        checkpoint::verified_checkpoint(&self.inner.store, &self.inner.pools, &self.inner.verified, id).await
    }

    /// Whether job `id`'s stored moments were verified against `checksum` lately
    /// (`checkpoint::REVERIFY_AFTER`).
    pub(crate) fn recently_verified(&self, id: i64, checksum: &str) -> bool {
        self.inner.verified.recently(id, checksum)
    }
}
