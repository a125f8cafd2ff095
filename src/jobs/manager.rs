//! The job manager: accepts jobs, queues them in submission order, runs a bounded number at once,
//! and owns every change of a job's state.
//!
//! Shared state is one `Arc<Inner>` behind a cheap `Clone` handle. Its parts:
//! * `active` — the queued and running jobs, each with a watch channel holding its current
//!   resource, so polls and event streams read memory, not the database;
//! * `queue` — job ids waiting for a worker, oldest first;
//! * `lifecycle` — one async mutex that serialises state transitions (submit, start, cancel,
//!   extend, delete, finish), so that "check the state, write the database, update memory" is
//!   atomic with respect to every other transition. It is held across database writes only, never
//!   across computation: work whose length depends on the input (verifying and merging documents,
//!   solving) runs before it is taken or after it is released;
//! * `merging` — jobs whose statistics a merge is changing (reserved under the lock, released when
//!   the merge ends), which extend and delete refuse to touch meanwhile.
//!
//! CPU work never runs on tokio's workers: jobs run on a blocking thread that drives the dedicated
//! rayon pool (see `driver`), and one-off computations a request waits for (validation with the
//! reference luminance and the iteration's expected work, verification of documents, re-solves)
//! go to a small second rayon pool through a oneshot channel, so that they never queue behind a
//! running job's chunks. Each of them is bounded (see `sim::checks::quadrature`, `sim::engines::cost`,
//! `sim::math::exact_sum`).
//!
//! The statistics operations (results, re-solves, merges, studies) live in `statistics`.

use std::collections::{HashMap, HashSet, VecDeque};
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;
use tokio::runtime::Handle;
use tokio::sync::{Notify, watch};

use super::driver;
use super::error::JobError;
use super::peers::Peers;
use super::resource::{BestStrategy, JobResource, JobState, Progress, now_ms, rfc3339};
use crate::metrics::{JobSample, Metrics};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::engines::cost::iteration_work;
use crate::sim::math::digest::sha256_hex;
use crate::sim::spec::{JobSpec, SpecError, ValidJob, parse_job_spec};
use crate::store::{Inserted, JobRow, NewJob, Store, StoreError};

/// How jobs are run.
#[derive(Debug, Clone)]
pub struct RunPolicy {
    /// Jobs running at once; the others wait in submission order.
    pub workers: usize,
    /// Checkpoint at least every this many iterations…
    pub checkpoint_iterations: u64,
    /// …and at least this often.
    pub checkpoint_interval: Duration,
    /// Largest N_F · N_B · iterations of one job.
    pub job_budget: f64,
    /// Largest expected work of one iteration, in light-path equivalents (`sim::engines::cost`).
    pub max_iteration_work: f64,
    /// Most cells of a job's grid.
    pub max_cells: usize,
    /// Most jobs waiting in the queue.
    pub max_queued_jobs: usize,
}

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
    stop_reason: AtomicU8,
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

pub(crate) struct Inner {
    pub store: Store,
    /// The simulation pool, shared by the running jobs.
    pub pool: Arc<rayon::ThreadPool>,
    /// A small pool for computations a request waits for (validation, verification, re-solves):
    /// on the simulation pool they would queue behind thousands of chunks of the running jobs.
    requests: rayon::ThreadPool,
    /// The allowed peers and the client that pulls from them.
    pub(super) peers: Peers,
    pub metrics: Arc<Metrics>,
    pub policy: RunPolicy,
    pub runtime: Handle,
    /// std Mutex: held only for map operations, never across an `.await`.
    active: Mutex<HashMap<i64, Arc<ActiveJob>>>,
    /// std Mutex, same reason.
    queue: Mutex<VecDeque<i64>>,
    /// Serialises state transitions; async because it is held across database writes.
    pub(super) lifecycle: tokio::sync::Mutex<()>,
    /// Jobs a merge is changing; std Mutex, held for set operations only.
    merging: Mutex<HashSet<i64>>,
    /// The checkpoint checksum of each job whose stored moments were last verified against it
    /// (`statistics::verified_checkpoint`): a result request re-hashes the moments only when the
    /// checkpoint changed since. std Mutex, map operations only.
    pub(super) verified: Mutex<HashMap<i64, String>>,
    /// Wakes the scheduler: a job was queued or a worker became free.
    wake: Notify,
    running: AtomicUsize,
    /// Signalled whenever a driver ends (shutdown waits for all of them).
    driver_ended: Notify,
    shutdown: watch::Sender<bool>,
}

/// Handle to the job manager; cheap to clone.
#[derive(Clone)]
pub struct JobManager {
    pub(super) inner: Arc<Inner>,
}

/// A job's merge in progress: released (and the job open to extend and delete again) on drop.
pub(super) struct MergeReservation {
    inner: Arc<Inner>,
    id: i64,
}

impl Drop for MergeReservation {
    fn drop(&mut self) {
        self.inner.merging.lock().expect("merging set").remove(&self.id);
    }
}

pub(super) fn parse_stored_spec(row: &JobRow) -> Result<JobSpec, JobError> {
    serde_json::from_str(&row.spec)
        .map_err(|e| JobError::Internal(format!("stored spec of job {} is unreadable: {e}", row.id)))
}

/// The resource of a job that is not active, from its row.
pub(super) fn resource_from_row(row: &JobRow) -> Result<JobResource, JobError> {
    let state = JobState::parse(&row.state)
        .ok_or_else(|| JobError::Internal(format!("job {} has an unknown state {:?}", row.id, row.state)))?;
    Ok(JobResource {
        id: row.id,
        state,
        spec: parse_stored_spec(row)?,
        created_at: rfc3339(row.created_at),
        updated_at: rfc3339(row.updated_at),
        progress: Progress {
            iterations_done: row.iterations_done,
            iterations_total: row.iterations_total,
            iterations_checkpointed: row.iterations_done,
            light_paths_per_second: None,
            eta_seconds: None,
            best: row.best.as_deref().and_then(|b| serde_json::from_str(b).ok()),
        },
        error: row.error.clone(),
        fingerprint: row.fingerprint.clone(),
        reference_luminance: row.reference_luminance,
        merged: row.merged,
    })
}

/// The strategy with the lowest RMS among `rows` whose figures are honest: the in-sample
/// `optimal` and `optimal_cv` rows are evaluated on the data they were fitted to, so they are left
/// out (`optimal_holdout` stays).
pub(crate) fn best_strategy(rows: &[crate::sim::solve::noise::NoiseRow]) -> Option<BestStrategy> {
    rows.iter()
        .filter(|r| r.strategy != "optimal" && r.strategy != "optimal_cv")
        .filter_map(|r| match (r.luminance, r.rms_percent) {
            (Some(l), Some(rms)) if rms > 0.0 => {
                Some(BestStrategy { strategy: r.strategy.clone(), luminance: l, rms_percent: rms })
            }
            _ => None,
        })
        .min_by(|a, b| a.rms_percent.total_cmp(&b.rms_percent))
}

/// Refuses jobs beyond this server's budget: N_F · N_B · `iterations` and the cell count.
pub(super) fn check_budget(policy: &RunPolicy, spec: &JobSpec, iterations: u64) -> Result<(), JobError> {
    let pairs = spec.light_paths as f64 * spec.camera_paths as f64 * iterations as f64;
    if pairs > policy.job_budget {
        return Err(SpecError::new(
            "iterations",
            format!(
                "light_paths × camera_paths × iterations = {pairs:.3e} exceeds this server's per-job budget of {:.3e} \
                 (--max-job-budget); run fewer iterations, or split the study into shards",
                policy.job_budget
            ),
        )
        .into());
    }
    let cells = spec.cells.r2_edges.len() * spec.cells.r3_edges.len() * spec.cells.phi_bins as usize;
    if cells > policy.max_cells {
        return Err(SpecError::new(
            "cells",
            format!("the grid has {cells} cells; this server accepts at most {} (--max-cells)", policy.max_cells),
        )
        .into());
    }
    Ok(())
}

/// Refuses a configuration whose single iteration is expected to cost more than the server
/// allows (the check behind "a job that cannot be cancelled": an iteration of 10¹⁷ light-path
/// equivalents once ran for ever). CPU work: call it on the request pool.
fn check_iteration_work(policy: &RunPolicy, job: &ValidJob) -> Result<(), JobError> {
    let work = iteration_work(&job.config);
    let total = work.total();
    if total.is_finite() && total <= policy.max_iteration_work {
        return Ok(());
    }
    // The brute force traces N_F paths; the restricted engine's candidates and every engine's merges
    // grow with the merge discs (R²).
    let traced_dominates = work.light_paths >= crate::sim::engines::cost::MERGE_WEIGHT * work.merges;
    let field = if job.spec.engine == crate::sim::spec::EngineName::Brute && traced_dominates {
        "light_paths"
    } else {
        "merge_radius"
    };
    Err(SpecError::new(
        field,
        format!(
            "one iteration is expected to cost {total:.3e} light-path equivalents ({:.3e} light paths drawn, {:.3e} \
             merges) — beyond this server's per-iteration limit of {:.3e} (--max-iteration-work); reduce merge_radius, \
             light_paths or camera_paths",
            work.light_paths, work.merges, policy.max_iteration_work
        ),
    )
    .into())
}

impl JobManager {
    /// Starts the manager on `store`: re-queues the jobs a previous server left running or queued
    /// (running ones first, each to resume from its last checkpoint; a job whose cancel was
    /// acknowledged ends cancelled instead) and starts the scheduler.
    ///
    /// `pool` runs the jobs; `requests` runs the computations requests wait for; `peers` are the
    /// servers merges may pull from.
    pub async fn start(
        store: Store,
        policy: RunPolicy,
        pool: Arc<rayon::ThreadPool>,
        requests: rayon::ThreadPool,
        metrics: Arc<Metrics>,
        peers: Peers,
    ) -> Result<Self, StoreError> {
        let (shutdown, _) = watch::channel(false);
        let inner = Arc::new(Inner {
            store,
            pool,
            requests,
            peers,
            metrics,
            policy,
            runtime: Handle::current(),
            active: Mutex::new(HashMap::new()),
            queue: Mutex::new(VecDeque::new()),
            lifecycle: tokio::sync::Mutex::new(()),
            merging: Mutex::new(HashSet::new()),
            verified: Mutex::new(HashMap::new()),
            wake: Notify::new(),
            running: AtomicUsize::new(0),
            driver_ended: Notify::new(),
            shutdown,
        });
        let manager = Self { inner };
        manager.recover().await?;
        tokio::spawn(scheduler(manager.inner.clone()));
        Ok(manager)
    }

    async fn recover(&self) -> Result<(), StoreError> {
        for row in self.inner.store.unfinished_jobs().await? {
            if row.cancel_requested {
                // The cancel was acknowledged before the server stopped: honour it.
                self.inner.store.set_state(row.id, "cancelled", None, now_ms()).await?;
                tracing::info!(job = row.id, iterations_done = row.iterations_done, "cancelled job stays cancelled");
                continue;
            }
            let valid = parse_stored_spec(&row)
                .map_err(|e| e.to_string())
                .and_then(|s| s.validate().map_err(|e| e.to_string()));
            match valid {
                Ok(job) => {
                    if row.state != "queued" {
                        self.inner.store.set_state(row.id, "queued", None, now_ms()).await?;
                    }
                    let mut resource = resource_from_row(&row)
                        .map_err(|e| StoreError::Corrupt { job: row.id, detail: e.to_string() })?;
                    resource.state = JobState::Queued;
                    self.enqueue(row.id, job, resource);
                    tracing::info!(job = row.id, iterations_done = row.iterations_done, "re-queued unfinished job");
                }
                Err(e) => {
                    let reason = format!("the stored specification is no longer valid: {e}");
                    self.inner.store.set_state(row.id, "failed", Some(&reason), now_ms()).await?;
                }
            }
        }
        Ok(())
    }

    fn enqueue(&self, id: i64, job: ValidJob, resource: JobResource) {
        let total = resource.progress.iterations_total;
        let active = Arc::new(ActiveJob {
            id,
            start: job.spec.iteration_range().start,
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

    pub(super) fn active(&self, id: i64) -> Option<Arc<ActiveJob>> {
        self.inner.active.lock().expect("active map").get(&id).cloned()
    }

    /// Reserves job `id` for a merge (call under the lifecycle lock), or says that another merge
    /// holds it.
    pub(super) fn reserve_for_merge(&self, id: i64) -> Result<MergeReservation, JobError> {
        if !self.inner.merging.lock().expect("merging set").insert(id) {
            return Err(JobError::Conflict(format!("job {id} is taking another merge; retry when it has finished")));
        }
        Ok(MergeReservation { inner: self.inner.clone(), id })
    }

    fn refuse_while_merging(&self, id: i64) -> Result<(), JobError> {
        if self.inner.merging.lock().expect("merging set").contains(&id) {
            return Err(JobError::Conflict(format!("job {id} is taking a merge; retry when it has finished")));
        }
        Ok(())
    }

    /// Runs `f` on the request pool and awaits its result (CPU work stays off tokio's workers).
    pub(super) async fn compute<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, JobError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.inner.requests.spawn(move || {
            // A panic must not abort the process (rayon's default for spawned work).
            let _ = tx.send(std::panic::catch_unwind(AssertUnwindSafe(f)));
        });
        match rx.await {
            Ok(Ok(value)) => Ok(value),
            _ => Err(JobError::Internal("a computation panicked".into())),
        }
    }

    /// Receives shutdown: true once the server is stopping.
    pub fn shutdown_signal(&self) -> watch::Receiver<bool> {
        self.inner.shutdown.subscribe()
    }

    pub(super) fn is_shutting_down(&self) -> bool {
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
        let hash_body = idempotency_key.is_some();
        // Validation, the reference quadrature and the expected work of an iteration: CPU work,
        // each bounded, on the request pool.
        let (job, reference, request_hash) = self
            .compute(move || -> Result<_, JobError> {
                let job = parse_job_spec(&document)?.validate()?;
                check_budget(&policy, &job.spec, range_len(&job.spec))?;
                check_iteration_work(&policy, &job)?;
                let reference = reference_luminance(&job.config.scene);
                if let Err(e) = &reference {
                    tracing::warn!(error = %e, "the job has no reference luminance");
                }
                let hash = hash_body.then(|| sha256_hex(document.to_string().as_bytes()));
                Ok((job, reference.ok(), hash))
            })
            .await??;
        let new = NewJob {
            spec: spec_json(&job.spec)?,
            fingerprint: job.config.fingerprint().to_string(),
            iterations_total: range_len(&job.spec),
            reference_luminance: reference,
            idempotency_key,
            request_hash,
            now: now_ms(),
        };
        let _guard = self.inner.lifecycle.lock().await;
        match self.inner.store.insert_job(&new).await? {
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
        let queued = self.inner.queue.lock().expect("queue").len();
        if queued >= self.inner.policy.max_queued_jobs {
            return Err(JobError::Busy {
                detail: format!("{queued} jobs are already waiting, the most this server queues (--max-queued-jobs)"),
                retry_after_seconds: 30,
            });
        }
        Ok(())
    }

    /// The current resource of a job.
    pub async fn get(&self, id: i64) -> Result<JobResource, JobError> {
        if let Some(job) = self.active(id) {
            return Ok(job.view.borrow().clone());
        }
        let row = self.inner.store.get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
        resource_from_row(&row)
    }

    /// A page of jobs, newest first, optionally in one state, after `cursor` (the last id seen).
    pub async fn list(
        &self,
        state: Option<JobState>,
        cursor: Option<i64>,
        limit: u32,
    ) -> Result<super::documents::JobList, JobError> {
        let mut rows = self.inner.store.list_jobs(state.map(JobState::as_str), cursor, limit + 1).await?;
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
        Ok(super::documents::JobList { jobs, next_cursor })
    }

    /// Cancels a queued job at once, or asks a running one to stop (within one chunk of light
    /// paths, or 1,024 candidates of a restricted iteration; it keeps the iterations it
    /// completed). The cancel is stored before it is acknowledged, so a restart does not run the
    /// job again.
    pub async fn cancel(&self, id: i64) -> Result<JobResource, JobError> {
        let _guard = self.inner.lifecycle.lock().await;
        let Some(job) = self.active(id) else {
            let row = self.inner.store.get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
            return Err(JobError::Conflict(format!(
                "job {id} is already {}; only queued or running jobs can be cancelled",
                row.state
            )));
        };
        let waiting = self.inner.queue.lock().expect("queue").contains(&id);
        if waiting {
            self.inner.store.set_state(id, "cancelled", None, now_ms()).await?;
            self.inner.queue.lock().expect("queue").retain(|&q| q != id);
            self.inner.active.lock().expect("active map").remove(&id);
            job.view.send_modify(|r| {
                r.state = JobState::Cancelled;
                r.updated_at = rfc3339(now_ms());
            });
        } else {
            self.inner.store.request_cancel(id, now_ms()).await?;
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
        if self.active(id).is_none() && self.inner.store.load_result(id).await?.is_some() {
            self.verified_checkpoint(id).await?;
        }
        let _guard = self.inner.lifecycle.lock().await;
        self.refuse_while_merging(id)?;
        let now = now_ms();
        if let Some(job) = self.active(id) {
            refuse_shard_extension(id, &job.job.spec)?;
            let current = job.total.load(Ordering::SeqCst);
            let new_total = target_total(current, current, more, total)?;
            check_budget(&self.inner.policy, &job.job.spec, new_total)?;
            let mut spec = job.view.borrow().spec.clone();
            spec.iterations = new_total;
            self.inner.store.set_total(id, new_total, &spec_json(&spec)?, job.state().as_str(), now).await?;
            job.total.store(new_total, Ordering::SeqCst);
            job.view.send_modify(|r| {
                r.progress.iterations_total = new_total;
                r.spec.iterations = new_total;
                r.updated_at = rfc3339(now);
            });
            let resource = job.view.borrow().clone();
            return Ok(resource);
        }
        let row = self.inner.store.get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
        if row.merged {
            return Err(JobError::Conflict(format!(
                "job {id} holds merged statistics and cannot run more iterations; extend one of its sources instead"
            )));
        }
        if !matches!(row.state.as_str(), "succeeded" | "cancelled") {
            return Err(JobError::Conflict(format!(
                "job {id} is {}; only a running, queued, succeeded or cancelled job can be extended",
                row.state
            )));
        }
        let new_total = target_total(row.iterations_done, row.iterations_total, more, total)?;
        let mut spec = parse_stored_spec(&row)?;
        refuse_shard_extension(id, &spec)?;
        check_budget(&self.inner.policy, &spec, new_total)?;
        self.check_queue()?;
        spec.iterations = new_total;
        let job = spec.validate()?;
        self.inner.store.set_total(id, new_total, &spec_json(&spec)?, "queued", now).await?;
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
        let _guard = self.inner.lifecycle.lock().await;
        self.refuse_while_merging(id)?;
        if let Some(job) = self.active(id) {
            if !self.inner.queue.lock().expect("queue").contains(&id) {
                return Err(JobError::Conflict(format!("job {id} is running; cancel it before deleting it")));
            }
            if !self.inner.store.delete_job(id).await? {
                return Err(JobError::NotFound(id.to_string()));
            }
            self.inner.queue.lock().expect("queue").retain(|&q| q != id);
            self.inner.active.lock().expect("active map").remove(&id);
            job.view.send_modify(|r| r.state = JobState::Cancelled);
            return Ok(());
        }
        if self.inner.store.delete_job(id).await? { Ok(()) } else { Err(JobError::NotFound(id.to_string())) }
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
        self.inner.shutdown.send_replace(true);
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

/// The new total of an extension: `more` beyond `base`, or `total` outright (which must exceed
/// `done`); at most 10⁹.
fn target_total(base: u64, done: u64, more: Option<u64>, total: Option<u64>) -> Result<u64, JobError> {
    const MAX: u64 = 1_000_000_000;
    match (more, total) {
        (Some(add), None) => match base.checked_add(add) {
            Some(t) if add >= 1 && t <= MAX => Ok(t),
            _ => Err(SpecError::new(
                "iterations",
                format!("must be ≥ 1 and bring the total ({base}) to at most 10^9, got {add}"),
            )
            .into()),
        },
        (None, Some(t)) if t > done && t <= MAX => Ok(t),
        (None, Some(t)) => Err(SpecError::new(
            "total",
            format!("must exceed the iterations the job holds ({done}) and be at most 10^9, got {t}"),
        )
        .into()),
        _ => {
            Err(SpecError::new("", "give exactly one of `iterations` (how many more) and `total` (the new target)")
                .into())
        }
    }
}

/// Iterations a job runs (its range's length).
pub(super) fn range_len(spec: &JobSpec) -> u64 {
    let r = spec.iteration_range();
    r.end - r.start
}

/// A shard's range is fixed by its study: running past it would overlap the next shard.
fn refuse_shard_extension(id: i64, spec: &JobSpec) -> Result<(), JobError> {
    match spec.shard {
        Some(_) => Err(JobError::Conflict(format!(
            "job {id} is a shard: its range is fixed by the study; add iterations with a new job using first_iteration"
        ))),
        None => Ok(()),
    }
}

pub(super) fn spec_json(spec: &JobSpec) -> Result<String, JobError> {
    serde_json::to_string(spec).map_err(|e| JobError::Internal(e.to_string()))
}

/// Starts queued jobs while workers are free; runs until shutdown.
async fn scheduler(inner: Arc<Inner>) {
    let mut shutdown = inner.shutdown.subscribe();
    loop {
        if *shutdown.borrow() {
            return;
        }
        start_ready_jobs(&inner).await;
        tokio::select! {
            _ = inner.wake.notified() => {}
            _ = shutdown.changed() => {}
        }
    }
}

async fn start_ready_jobs(inner: &Arc<Inner>) {
    while inner.running.load(Ordering::SeqCst) < inner.policy.workers {
        let _guard = inner.lifecycle.lock().await;
        let next = inner.queue.lock().expect("queue").pop_front();
        let Some(id) = next else { return };
        let Some(job) = inner.active.lock().expect("active map").get(&id).cloned() else { continue };
        inner.running.fetch_add(1, Ordering::SeqCst);
        let driver_inner = inner.clone();
        let handle = tokio::task::spawn_blocking(move || driver::drive(&driver_inner, &job));
        let done_inner = inner.clone();
        tokio::spawn(async move {
            if let Err(e) = handle.await {
                tracing::error!(job = id, error = %e, "job driver panicked");
                let _ = done_inner.fail(id, "internal error: the job's driver panicked").await;
            }
            done_inner.running.fetch_sub(1, Ordering::SeqCst);
            done_inner.driver_ended.notify_waiters();
            done_inner.wake.notify_one();
        });
    }
}

/// State transitions of a running job, called by its driver (through `block_on`).
impl Inner {
    pub(crate) async fn mark_running(&self, job: &ActiveJob) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        let now = now_ms();
        self.store.set_state(job.id, "running", None, now).await?;
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
        self.store.set_state(job.id, "queued", None, now_ms()).await?;
        self.active.lock().expect("active map").remove(&job.id);
        job.view.send_modify(|r| r.state = JobState::Queued);
        Ok(())
    }

    pub(crate) async fn fail(&self, id: i64, reason: &str) -> Result<(), JobError> {
        let _guard = self.lifecycle.lock().await;
        let job = self.active.lock().expect("active map").get(&id).cloned();
        match job {
            Some(job) => self.end(&job, JobState::Failed, Some(reason)).await,
            None => self.store.set_state(id, "failed", Some(reason), now_ms()).await.map(|_| ()).map_err(Into::into),
        }
    }

    /// Records that job `id`'s stored moments match `checksum` (see `verified`).
    pub(crate) fn remember_verified(&self, id: i64, checksum: &str) {
        let mut verified = self.verified.lock().expect("verified map");
        if verified.len() >= super::statistics::MAX_VERIFIED {
            verified.clear();
        }
        verified.insert(id, checksum.to_string());
    }

    /// Whether the server is stopping.
    pub(crate) fn shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    async fn end(&self, job: &ActiveJob, state: JobState, error: Option<&str>) -> Result<(), JobError> {
        let now = now_ms();
        self.store.set_state(job.id, state.as_str(), error, now).await?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_add_to_what_the_job_would_reach_or_set_the_target() {
        // A cancelled job holding 100 of 1,000: 50 more → 150; resume to its target → 1,000.
        assert_eq!(target_total(100, 100, Some(50), None).unwrap(), 150);
        assert_eq!(target_total(100, 100, None, Some(1000)).unwrap(), 1000);
        assert!(target_total(100, 100, None, Some(100)).is_err(), "the target must exceed what it holds");
        assert!(target_total(100, 100, Some(0), None).is_err());
        assert!(target_total(100, 100, Some(1), Some(200)).is_err(), "one of the two");
        assert!(target_total(100, 100, None, None).is_err());
        assert!(target_total(999_999_999, 0, Some(2), None).is_err());
    }
}
