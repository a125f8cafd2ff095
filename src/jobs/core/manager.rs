//! The job manager: the lifecycle core. It accepts jobs, queues them in submission order, runs a
//! bounded number at once through the executor, and owns every change of a job's state (start and
//! recovery, submit, get, list, cancel, extend, delete, shutdown).
//!
//! Shared state is one `Arc<Inner>` (`state`) behind a cheap `Clone` handle. Its parts:
//! * `active` — the queued and running jobs, each with a watch channel holding its current
//!   resource, so polls and event streams read memory, not the database;
//! * `queue` — job ids waiting for a worker, oldest first;
//! * `lifecycle` — one async mutex that serialises state transitions (submit, start, cancel,
//!   extend, delete, finish), so that "check the state, write the database, update memory" is
//!   atomic with respect to every other transition. It is held across database writes only, never
//!   across computation: work whose length depends on the input (verifying and merging documents,
//!   solving) runs before it is taken or after it is released;
//! * `held` — finished jobs an operation is changing (a merge), which extend and delete refuse to
//!   touch meanwhile;
//! * `verified` — which checkpoints were hashed lately (`checkpoint::Verified`).
//!
//! CPU work never runs on tokio's workers: jobs run on a blocking thread that drives the executor
//! (see `driver`, `executor`), and one-off computations a request waits for (validation with the
//! reference luminance and the iteration's expected work, verification of documents, re-solves)
//! go to the request pools (`compute`), so that they never queue behind a running job's chunks.
//! Each of them is bounded (see `sim::checks::quadrature`, `sim::engines::cost`,
//! `sim::math::exact_sum`).
//!
//! The features built on the lifecycle — statistics, merges, solves, predictions, sweeps — are
//! handles of their own (outside this folder) that use the handle's small toolbox (the first
//! `impl` block below); none of them is a method of the manager.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use serde_json::Value;
use tokio::runtime::Handle;
use tokio::sync::{MutexGuard, Notify, watch};

use super::checkpoint::{self, spec_json};
use super::compute::{Pools, Stop};
use super::documents::JobList;
use super::error::JobError;
use super::executor::Executor;
use super::policy::{RunPolicy, check_budget, check_iteration_work, range_len, refuse_shard_extension, target_total};
use super::recovery::recover;
use super::references::cached_scene_reference;
use super::resource::{JobResource, JobState, now_ms, parse_stored_spec, resource_from_row, rfc3339};
use super::scheduler::scheduler;
use super::state::{ActiveJob, Hold, Inner, StopReason};
use crate::metrics::{JobSample, Metrics};
use crate::sim::math::digest::sha256_hex;
use crate::sim::spec::ValidJob;
use crate::sim::spec::{SpecError, parse_job_spec};
use crate::store::{Checkpoint, Inserted, JobFilter, NewJob, Store, StoreError};

/// Handle to the job manager; cheap to clone.
#[derive(Clone)]
pub struct JobManager {
    inner: Arc<Inner>,
}

/// What the features (statistics, merges, solves, predictions, sweeps) may do with the core: run
/// work on the request pools, read the store and the policy, look at and queue active jobs under
/// the lifecycle lock, hold a finished job for an operation, verify a checkpoint.
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
        self.inner.shutting_down()
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
        self.inner.active(id)
    }

    /// Jobs waiting for a worker.
    pub(crate) fn queued(&self) -> usize {
        self.inner.queued()
    }

    /// Whether job `id` waits for a worker (queued, not running).
    pub(crate) fn is_queued(&self, id: i64) -> bool {
        self.inner.is_queued(id)
    }

    /// Queues job `id` (whose row is committed) behind the others (call under the lifecycle lock).
    pub(crate) fn enqueue(&self, id: i64, job: ValidJob, resource: JobResource) {
        self.inner.enqueue(id, job, resource)
    }

    /// Forgets a queued job whose row is gone or cancelled (call under the lifecycle lock).
    pub(crate) fn discard_queued(&self, id: i64) {
        self.inner.discard_queued(id)
    }

    /// Holds the finished job `id` for an operation (a merge; call under the lifecycle lock), or
    /// says that another operation holds it. Extend and delete refuse a held job.
    pub(crate) fn hold(&self, id: i64) -> Result<Hold, JobError> {
        self.inner.hold(id)
    }

    /// Whether an operation holds job `id`.
    pub(crate) fn is_held(&self, id: i64) -> bool {
        self.inner.is_held(id)
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

/// The lifecycle.
impl JobManager {
    /// Starts the manager on `store`: re-queues the jobs a previous server left running or queued
    /// (running ones first, each to resume from its last checkpoint; a job whose cancel was
    /// acknowledged ends cancelled instead) and starts the scheduler.
    ///
    /// `executor` runs the jobs' iterations; `pools` run the computations requests wait for.
    pub async fn start(
        store: Store,
        policy: RunPolicy,
        executor: Arc<dyn Executor>,
        pools: Pools,
        metrics: Arc<Metrics>,
    ) -> Result<Self, StoreError> {
        let (shutdown, _) = watch::channel(false);
        let inner = Arc::new(Inner {
            store,
            executor,
            pools,
            metrics,
            policy,
            runtime: Handle::current(),
            active: Mutex::new(HashMap::new()),
            queue: Mutex::new(VecDeque::new()),
            lifecycle: tokio::sync::Mutex::new(()),
            held: Mutex::new(HashSet::new()),
            verified: Default::default(),
            wake: Notify::new(),
            running: AtomicUsize::new(0),
            driver_ended: Notify::new(),
            shutdown,
        });
        recover(&inner).await?;
        let manager = Self { inner };
        tokio::spawn(scheduler(manager.inner.clone()));
        Ok(manager)
    }

    /// Iterations and throughput of every running job, from memory.
    pub fn running_samples(&self) -> Vec<JobSample> {
        let active = self.inner.active.lock().expect("active map");
        let mut samples: Vec<JobSample> = active
            .values()
            .filter_map(|job| {
                let view = job.view.borrow();
                (view.state == JobState::Running).then(|| JobSample {
                    id: job.id,
                    iterations_done: view.progress.iterations_done,
                    light_paths_per_second: view.progress.light_paths_per_second.unwrap_or(0.0),
                })
            })
            .collect();
        samples.sort_by_key(|s| s.id);
        samples
    }

    /// Validates and queues a job. With an idempotency key, a repeated request with the same body
    /// returns the original job (`true` in the result) instead of creating a second one. The job
    /// is acknowledged only once its row is committed.
    pub async fn submit(
        &self,
        document: Value,
        idempotency_key: Option<String>,
    ) -> Result<(JobResource, bool), JobError> {
        if self.is_shutting_down() {
            return Err(JobError::ShuttingDown);
        }
        self.check_queue()?;
        let policy = self.inner.policy.clone();
        let executor = self.inner.executor.clone();
        let hash_body = idempotency_key.is_some();
        // Validation and the expected work of an iteration: CPU work, each bounded to
        // milliseconds, on the request pool. The scene's reference quadrature (up to seconds) is
        // not computed here: a submission takes it from the cache, or its job's run computes it
        // on the job's own thread (`driver`), so that abandoned submissions of hard scenes cannot
        // hold the request pool.
        let (job, reference, request_hash) = self
            .compute(move || -> Result<_, JobError> {
                let job = parse_job_spec(&document)?.validate()?;
                executor.admit(job.spec())?;
                check_budget(&policy, job.spec(), range_len(job.spec()))?;
                check_iteration_work(&policy, &job)?;
                let reference = cached_scene_reference(&job.config().scene).flatten();
                let hash = hash_body.then(|| sha256_hex(document.to_string().as_bytes()));
                Ok((job, reference, hash))
            })
            .await??;
        let new = NewJob {
            spec: spec_json(job.spec())?,
            fingerprint: job.config().fingerprint().to_string(),
            iterations_total: range_len(job.spec()),
            reference_luminance: reference,
            idempotency_key,
            request_hash,
            now: now_ms(),
        };
        let _guard = self.inner.lifecycle.lock().await;
        // Nothing is acknowledged once the server is stopping (the shutdown took the lock to
        // set its flag, or sets it before the next transition).
        if self.is_shutting_down() {
            return Err(JobError::ShuttingDown);
        }
        match self.inner.store.jobs().insert(&new).await? {
            Inserted::Created(row) => {
                let resource = resource_from_row(&row)?;
                self.enqueue(row.id, job, resource.clone());
                Ok((resource, false))
            }
            Inserted::Replayed(row) => {
                drop(_guard);
                Ok((self.get(row.id).await?, true))
            }
            Inserted::KeyReused => Err(JobError::Invalid(SpecError::new(
                "Idempotency-Key",
                "this key was already used with a different request body; use a new key for a new job",
            ))),
        }
    }

    /// Refuses a new job when the queue is full.
    fn check_queue(&self) -> Result<(), JobError> {
        let queued = self.queued();
        if queued >= self.inner.policy.max_queued_jobs {
            return Err(JobError::Busy {
                detail: format!("{queued} jobs are already waiting, the most this server queues (--max-queued-jobs)"),
                retry_after_seconds: 30,
            });
        }
        Ok(())
    }

    /// Refuses to change a job an operation holds (a merge).
    fn refuse_while_held(&self, id: i64) -> Result<(), JobError> {
        if self.is_held(id) {
            return Err(JobError::Conflict(format!("job {id} is taking a merge; retry when it has finished")));
        }
        Ok(())
    }

    /// The current resource of a job.
    pub async fn get(&self, id: i64) -> Result<JobResource, JobError> {
        if let Some(job) = self.active(id) {
            return Ok(job.view.borrow().clone());
        }
        let row = self.inner.store.jobs().get(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
        resource_from_row(&row)
    }

    /// A page of jobs, newest first, optionally in one state, after `cursor` (the last id seen).
    pub async fn list(&self, filter: &JobFilter, cursor: Option<i64>, limit: u32) -> Result<JobList, JobError> {
        let mut rows = self.inner.store.jobs().list(filter, cursor, limit + 1).await?;
        let more = rows.len() > limit as usize;
        rows.truncate(limit as usize);
        let next_cursor = if more { rows.last().map(|r| r.id.to_string()) } else { None };
        let jobs = rows
            .iter()
            .map(|row| match self.active(row.id) {
                Some(job) => Ok(job.view.borrow().clone()),
                None => resource_from_row(row),
            })
            .collect::<Result<_, _>>()?;
        Ok(JobList { jobs, next_cursor })
    }

    /// Cancels a queued job at once, or asks a running one to stop (within one chunk of light
    /// paths, or 1,024 candidates of a restricted iteration; it keeps the iterations it
    /// completed). The cancel is stored before it is acknowledged, so a restart does not run the
    /// job again.
    pub async fn cancel(&self, id: i64) -> Result<JobResource, JobError> {
        let _guard = self.inner.lifecycle.lock().await;
        let Some(job) = self.active(id) else {
            let row = self.inner.store.jobs().get(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
            return Err(JobError::Conflict(format!(
                "job {id} is already {}; only queued or running jobs can be cancelled",
                row.state
            )));
        };
        let waiting = self.inner.queue.lock().expect("queue").contains(&id);
        if waiting {
            self.inner.store.jobs().set_state(id, JobState::Cancelled, None, now_ms()).await?;
            self.inner.queue.lock().expect("queue").retain(|&q| q != id);
            self.inner.active.lock().expect("active map").remove(&id);
            job.view.send_modify(|r| {
                r.state = JobState::Cancelled;
                r.updated_at = rfc3339(now_ms());
            });
            // A queued job may still have work elsewhere (a cluster's tasks adopted at restart):
            // stopped in the background, with the executor's own timeouts.
            let executor = self.inner.executor.clone();
            tokio::task::spawn_blocking(move || executor.cancel(id));
        } else {
            self.inner.store.jobs().request_cancel(id, now_ms()).await?;
            job.request_stop(StopReason::Cancel);
        }
        let resource = job.view.borrow().clone();
        Ok(resource)
    }

    /// Adds iterations to a job; they continue the same deterministic sequence. `iterations` more
    /// than the job would otherwise reach: its total if it is queued or running, the iterations it
    /// holds if it succeeded or was cancelled. Or `total`: run until the job holds that many
    /// (resuming a cancelled job to its original target is `total` = its `iterations_total`). A
    /// succeeded or cancelled job is queued again; a queued or running one just runs longer.
    pub async fn extend(&self, id: i64, more: Option<u64>, total: Option<u64>) -> Result<JobResource, JobError> {
        // A finished job resumes from its checkpoint: refuse now, with nothing changed, if it is
        // corrupted rather than queue a job that can only fail. Verified before the lifecycle
        // lock (hashing the moments is work); only a merge could change the checkpoint meanwhile,
        // and it writes a verified one.
        if self.active(id).is_none() && self.inner.store.checkpoints().load_result(id).await?.is_some() {
            self.verified_checkpoint(id).await?;
        }
        let _guard = self.inner.lifecycle.lock().await;
        self.refuse_while_held(id)?;
        let now = now_ms();
        if let Some(job) = self.active(id) {
            refuse_shard_extension(id, job.job.spec())?;
            let current = job.total.load(Ordering::SeqCst);
            let new_total = target_total(current, current, more, total)?;
            check_budget(&self.inner.policy, job.job.spec(), new_total)?;
            let mut spec = job.view.borrow().spec.clone();
            spec.iterations = new_total;
            self.inner.store.jobs().set_total(id, new_total, &spec_json(&spec)?, job.state(), now).await?;
            job.total.store(new_total, Ordering::SeqCst);
            job.view.send_modify(|r| {
                r.progress.iterations_total = new_total;
                r.spec.iterations = new_total;
                r.updated_at = rfc3339(now);
            });
            let resource = job.view.borrow().clone();
            return Ok(resource);
        }
        let row = self.inner.store.jobs().get(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
        if row.merged {
            return Err(JobError::Conflict(format!(
                "job {id} holds merged statistics and cannot run more iterations; extend one of its sources instead"
            )));
        }
        if !matches!(row.state, JobState::Succeeded | JobState::Cancelled) {
            return Err(JobError::Conflict(format!(
                "job {id} is {}; only a running, queued, succeeded or cancelled job can be extended",
                row.state
            )));
        }
        // `total` is checked against what the job holds, not the target it had: a job cancelled at 34
        // of 500 resumes to 500 with `total` = 500 (issue 42).
        let new_total = target_total(row.iterations_done, row.iterations_done, more, total)?;
        let mut spec = parse_stored_spec(&row)?;
        refuse_shard_extension(id, &spec)?;
        check_budget(&self.inner.policy, &spec, new_total)?;
        self.check_queue()?;
        spec.iterations = new_total;
        let job = spec.validate()?;
        self.inner.store.jobs().set_total(id, new_total, &spec_json(&spec)?, JobState::Queued, now).await?;
        let mut resource = resource_from_row(&row)?;
        resource.state = JobState::Queued;
        resource.spec.iterations = new_total;
        resource.progress.iterations_total = new_total;
        resource.updated_at = rfc3339(now);
        resource.error = None;
        self.enqueue(id, job, resource.clone());
        Ok(resource)
    }

    /// Deletes a job that is not running, with its checkpoint.
    pub async fn delete(&self, id: i64) -> Result<(), JobError> {
        let deleted = self.delete_row(id).await;
        if deleted.is_ok() {
            // What the executor keeps for the job (a cluster's task files), removed in the
            // background.
            let executor = self.inner.executor.clone();
            tokio::task::spawn_blocking(move || executor.forget(id));
        }
        deleted
    }

    async fn delete_row(&self, id: i64) -> Result<(), JobError> {
        let _guard = self.inner.lifecycle.lock().await;
        self.refuse_while_held(id)?;
        if self.active(id).is_some() {
            if !self.is_queued(id) {
                return Err(JobError::Conflict(format!("job {id} is running; cancel it before deleting it")));
            }
            if !self.inner.store.jobs().delete(id).await? {
                return Err(JobError::NotFound(id.to_string()));
            }
            self.discard_queued(id);
            return Ok(());
        }
        if self.inner.store.jobs().delete(id).await? { Ok(()) } else { Err(JobError::NotFound(id.to_string())) }
    }

    /// A receiver of the job's resource as it changes, for active jobs.
    pub fn subscribe(&self, id: i64) -> Option<watch::Receiver<JobResource>> {
        self.active(id).map(|job| job.view.subscribe())
    }

    /// Asks every active job to stop at its next chunk, without waiting (for use where nothing can
    /// be awaited, such as a destructor). [`JobManager::shutdown`] is the graceful path.
    pub fn stop_all_now(&self) {
        self.inner.shutdown.send_replace(true);
        for job in self.inner.active.lock().expect("active map").values() {
            job.request_stop(StopReason::Shutdown);
        }
    }

    /// Stops accepting work, asks every running job to checkpoint and stop, and waits for them.
    /// Interrupted jobs stay `queued` in the database and resume when a server starts again;
    /// cancelled ones end cancelled.
    pub async fn shutdown(&self) {
        {
            // Under the lifecycle lock: a submission either committed before (and is recovered
            // at the next start) or sees the flag and is refused — none is acknowledged after.
            let _guard = self.inner.lifecycle.lock().await;
            self.inner.shutdown.send_replace(true);
        }
        let jobs: Vec<Arc<ActiveJob>> = self.inner.active.lock().expect("active map").values().cloned().collect();
        for job in jobs {
            job.request_stop(StopReason::Shutdown);
        }
        while self.inner.running.load(Ordering::SeqCst) > 0 {
            let ended = self.inner.driver_ended.notified();
            if self.inner.running.load(Ordering::SeqCst) == 0 {
                break;
            }
            let _ = tokio::time::timeout(Duration::from_millis(200), ended).await;
        }
    }
}
