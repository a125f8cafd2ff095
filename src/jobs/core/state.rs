//! The jobs in memory and the transitions of their state.
//!
//! `Inner` is the manager's shared state (see `manager` for what each part is for); the
//! transitions a running job goes through (running, succeeded, cancelled, interrupted, failed) are
//! methods on it, called by the job's driver, so that the driver needs nothing of the manager.
//! Every transition takes the lifecycle lock, writes the store and then updates memory.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use tokio::runtime::Handle;
use tokio::sync::{Notify, watch};

use super::checkpoint::Verified;
use super::compute::Pools;
use super::error::JobError;
use super::executor::Executor;
use super::policy::RunPolicy;
use super::resource::{JobResource, JobState, now_ms, rfc3339};
use crate::metrics::Metrics;
use crate::sim::spec::ValidJob;
use crate::store::Store;

/// Why a running job was asked to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum StopReason {
    /// The user cancelled it: it ends `cancelled` (the request is also stored).
    Cancel = 1,
    /// The server is stopping: it stays `queued` and resumes at the next start.
    Shutdown = 2,
}

/// A queued or running job, in memory.
pub(crate) struct ActiveJob {
    pub id: i64,
    pub job: ValidJob,
    /// First iteration index of the job's range (see `JobSpec::iteration_range`).
    pub start: u64,
    /// Checked by the simulation before every chunk (and inside restricted iterations).
    pub stop: AtomicBool,
    /// A `StopReason` once `stop` is set (0 before).
    pub(super) stop_reason: AtomicU8,
    /// Iterations to reach (extend raises it while the job runs).
    pub total: AtomicU64,
    /// The job's current resource; GET and the event stream read it.
    pub view: watch::Sender<JobResource>,
}

impl ActiveJob {
    /// Asks the job to stop. A cancel wins over a shutdown (a shutdown never turns an
    /// acknowledged cancel into "resume later").
    pub fn request_stop(&self, reason: StopReason) {
        match reason {
            StopReason::Cancel => self.stop_reason.store(reason as u8, Ordering::SeqCst),
            StopReason::Shutdown => {
                let _ = self.stop_reason.compare_exchange(0, reason as u8, Ordering::SeqCst, Ordering::SeqCst);
            }
        }
        self.stop.store(true, Ordering::SeqCst);
    }

    pub fn stop_reason(&self) -> Option<StopReason> {
        match self.stop_reason.load(Ordering::SeqCst) {
            1 => Some(StopReason::Cancel),
            2 => Some(StopReason::Shutdown),
            _ => None,
        }
    }

    pub fn state(&self) -> JobState {
        self.view.borrow().state
    }
}

/// The lifecycle's shared state (see `manager` for what each part is for). Feature state (peers,
/// signing keys, sweep predictions) lives in the feature handles, not here.
pub(crate) struct Inner {
    pub store: Store,
    /// Where the jobs' iterations run (the local simulation pool today).
    pub executor: Arc<dyn Executor>,
    /// The pools for computations a request waits for (`compute`): on the simulation pool they
    /// would queue behind thousands of chunks of the running jobs.
    pub(super) pools: Pools,
    pub metrics: Arc<Metrics>,
    pub policy: RunPolicy,
    pub runtime: Handle,
    /// std Mutex: held only for map operations, never across an `.await`.
    pub(super) active: Mutex<HashMap<i64, Arc<ActiveJob>>>,
    /// std Mutex, same reason.
    pub(super) queue: Mutex<VecDeque<i64>>,
    /// Serialises state transitions; async because it is held across database writes.
    pub(super) lifecycle: tokio::sync::Mutex<()>,
    /// Finished jobs an operation is changing (a merge: `Hold`), which extend and delete refuse
    /// to touch meanwhile; std Mutex, held for set operations only.
    pub(super) held: Mutex<HashSet<i64>>,
    /// Which checkpoints were verified lately (`checkpoint::Verified`).
    pub(super) verified: Verified,
    /// Wakes the scheduler: a job was queued or a worker became free.
    pub(super) wake: Notify,
    pub(super) running: AtomicUsize,
    /// Signalled whenever a driver ends (shutdown waits for all of them).
    pub(super) driver_ended: Notify,
    pub(super) shutdown: watch::Sender<bool>,
}

/// A finished job held by an operation (a merge): released (and the job open to extend and
/// delete again) on drop.
pub(crate) struct Hold {
    pub(super) inner: Arc<Inner>,
    pub(super) id: i64,
}

impl Drop for Hold {
    fn drop(&mut self) {
        self.inner.held.lock().expect("held set").remove(&self.id);
    }
}

/// The queue and the jobs in memory (each call takes its std mutex for a map operation only).
impl Inner {
    /// The queued or running job `id`, if it is one.
    pub(crate) fn active(&self, id: i64) -> Option<Arc<ActiveJob>> {
        self.active.lock().expect("active map").get(&id).cloned()
    }

    /// Jobs waiting for a worker.
    pub(crate) fn queued(&self) -> usize {
        self.queue.lock().expect("queue").len()
    }

    /// Whether job `id` waits for a worker (queued, not running).
    pub(crate) fn is_queued(&self, id: i64) -> bool {
        self.queue.lock().expect("queue").contains(&id)
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
        self.active.lock().expect("active map").insert(id, active);
        self.queue.lock().expect("queue").push_back(id);
        self.wake.notify_one();
    }

    /// Forgets a queued job whose row is gone or cancelled (call under the lifecycle lock): out of
    /// the queue and memory, its watchers told it is cancelled.
    pub(crate) fn discard_queued(&self, id: i64) {
        self.queue.lock().expect("queue").retain(|&q| q != id);
        if let Some(job) = self.active.lock().expect("active map").remove(&id) {
            job.view.send_modify(|r| r.state = JobState::Cancelled);
        }
    }

    /// Whether an operation holds job `id` (see [`Hold`]).
    pub(crate) fn is_held(&self, id: i64) -> bool {
        self.held.lock().expect("held set").contains(&id)
    }

    /// Holds the finished job `id` for an operation (a merge; call under the lifecycle lock), or
    /// says that another operation holds it. Extend and delete refuse a held job.
    pub(crate) fn hold(self: &Arc<Self>, id: i64) -> Result<Hold, JobError> {
        if !self.held.lock().expect("held set").insert(id) {
            return Err(JobError::Conflict(format!("job {id} is taking another merge; retry when it has finished")));
        }
        Ok(Hold { inner: self.clone(), id })
    }
}

/// State transitions of a running job, called by its driver (through `block_on`).
impl Inner {
    pub(crate) async fn mark_running(&self, job: &ActiveJob) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        let now = now_ms();
        self.store.jobs().set_state(job.id, JobState::Running, None, now).await?;
        job.view.send_modify(|r| {
            r.state = JobState::Running;
            r.updated_at = rfc3339(now);
        });
        Ok(())
    }

    /// Marks the job succeeded if it has all its iterations; false if it was extended meanwhile.
    pub(crate) async fn finish(&self, job: &ActiveJob, done: u64) -> Result<bool, JobError> {
        let _guard = self.lifecycle.lock().await;
        if job.total.load(Ordering::SeqCst) > done {
            return Ok(false);
        }
        self.end(job, JobState::Succeeded, None).await?;
        Ok(true)
    }

    pub(crate) async fn mark_cancelled(&self, job: &ActiveJob) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        self.end(job, JobState::Cancelled, None).await
    }

    /// Leaves a job interrupted by shutdown as queued (it resumes at the next start).
    pub(crate) async fn mark_interrupted(&self, job: &ActiveJob) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        self.store.jobs().set_state(job.id, JobState::Queued, None, now_ms()).await?;
        self.active.lock().expect("active map").remove(&job.id);
        job.view.send_modify(|r| r.state = JobState::Queued);
        Ok(())
    }

    pub(crate) async fn fail(&self, id: i64, reason: &str) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        let job = self.active.lock().expect("active map").get(&id).cloned();
        match job {
            Some(job) => self.end(&job, JobState::Failed, Some(reason)).await,
            None => self
                .store
                .jobs()
                .set_state(id, JobState::Failed, Some(reason), now_ms())
                .await
                .map(|_| ())
                .map_err(Into::into),
        }
    }

    /// Whether the server is stopping.
    pub(crate) fn shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    async fn end(&self, job: &ActiveJob, state: JobState, error: Option<&str>) -> Result<(), JobError> {
        let now = now_ms();
        self.store.jobs().set_state(job.id, state, error, now).await?;
        self.active.lock().expect("active map").remove(&job.id);
        job.view.send_modify(|r| {
            r.state = state;
            r.error = error.map(str::to_string);
            r.updated_at = rfc3339(now);
            r.progress.light_paths_per_second = None;
            r.progress.eta_seconds = None;
        });
        Ok(())
    }
}
