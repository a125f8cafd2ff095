//! The job manager: accepts jobs, queues them in submission order, runs a bounded number at once,
//! and owns every change of a job's state.
//!
//! Shared state is one `Arc<Inner>` behind a cheap `Clone` handle. Its parts:
//! * `active` — the queued and running jobs, each with a watch channel holding its current
//!   resource, so polls and event streams read memory, not the database;
//! * `queue` — job ids waiting for a worker, oldest first;
//! * `lifecycle` — one async mutex that serialises state transitions (submit, start, cancel,
//!   extend, delete, finish), so that "check the state, write the database, update memory" is
//!   atomic with respect to every other transition. Transitions are rare; the CPU work is not
//!   under it.
//!
//! CPU work never runs on tokio's workers: jobs run on a blocking thread that drives the dedicated
//! rayon pool (see `driver`), and one-off computations a request waits for (reference luminance,
//! re-solves) go to a small second rayon pool through a oneshot channel, so that they never queue
//! behind a running job's chunks.

use std::collections::{HashMap, VecDeque};
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;
use tokio::runtime::Handle;
use tokio::sync::{Notify, watch};

use super::documents::{HistoryPoint, JobHistory, JobList, JobResult, MAX_HISTORY_POINTS, thin};
use super::driver;
use super::error::JobError;
use super::peers::{Source, parse_source, pull};
use super::resource::{BestStrategy, JobResource, JobState, Progress, now_ms, rfc3339};
use crate::metrics::{JobSample, Metrics};
use crate::sim::config::sha256_hex;
use crate::sim::document::{MomentsDocument, merge_documents};
use crate::sim::moments::Moments;
use crate::sim::quadrature::reference_luminance;
use crate::sim::report::{RunReport, build_report};
use crate::sim::spec::{JobSpec, SpecError, ValidJob, merge_patch, parse_job_spec, validate_solver};
use crate::store::{Checkpoint, Inserted, JobRow, NewJob, Store, StoreError};

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
    /// Most cells of a job's grid.
    pub max_cells: usize,
    /// Most jobs waiting in the queue.
    pub max_queued_jobs: usize,
}

/// Why a running job was asked to stop.
pub(crate) const STOP_CANCEL: u8 = 1;
pub(crate) const STOP_SHUTDOWN: u8 = 2;

/// A queued or running job, in memory.
pub(crate) struct ActiveJob {
    pub id: i64,
    pub job: ValidJob,
    /// First iteration index of the job's range (see `JobSpec::iteration_range`).
    pub start: u64,
    /// Checked by the simulation before every chunk.
    pub stop: AtomicBool,
    /// STOP_CANCEL or STOP_SHUTDOWN once `stop` is set.
    pub stop_reason: AtomicU8,
    /// Iterations to reach (extend raises it while the job runs).
    pub total: AtomicU64,
    /// The job's current resource; GET and the event stream read it.
    pub view: watch::Sender<JobResource>,
}

impl ActiveJob {
    pub fn request_stop(&self, reason: u8) {
        self.stop_reason.store(reason, Ordering::SeqCst);
        self.stop.store(true, Ordering::SeqCst);
    }

    pub fn state(&self) -> JobState {
        self.view.borrow().state
    }
}

pub(crate) struct Inner {
    pub store: Store,
    /// The simulation pool, shared by the running jobs.
    pub pool: Arc<rayon::ThreadPool>,
    /// A small pool for computations a request waits for (reference luminance, re-solves): on the
    /// simulation pool they would queue behind thousands of chunks of the running jobs.
    requests: rayon::ThreadPool,
    /// HTTP client for pulling moments from peers.
    http: reqwest::Client,
    pub metrics: Arc<Metrics>,
    pub policy: RunPolicy,
    pub runtime: Handle,
    /// std Mutex: held only for map operations, never across an `.await`.
    active: Mutex<HashMap<i64, Arc<ActiveJob>>>,
    /// std Mutex, same reason.
    queue: Mutex<VecDeque<i64>>,
    /// Serialises state transitions; async because it is held across database writes.
    lifecycle: tokio::sync::Mutex<()>,
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
    inner: Arc<Inner>,
}

fn parse_stored_spec(row: &JobRow) -> Result<JobSpec, JobError> {
    serde_json::from_str(&row.spec)
        .map_err(|e| JobError::Internal(format!("stored spec of job {} is unreadable: {e}", row.id)))
}

/// The resource of a job that is not active, from its row.
fn resource_from_row(row: &JobRow) -> Result<JobResource, JobError> {
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
pub(crate) fn best_strategy(rows: &[crate::sim::noise::NoiseRow]) -> Option<BestStrategy> {
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

impl JobManager {
    /// Starts the manager on `store`: re-queues the jobs a previous server left running or queued
    /// (running ones first, each to resume from its last checkpoint) and starts the scheduler.
    ///
    /// `pool` runs the jobs; `requests` runs the computations requests wait for.
    pub async fn start(
        store: Store,
        policy: RunPolicy,
        pool: Arc<rayon::ThreadPool>,
        requests: rayon::ThreadPool,
        metrics: Arc<Metrics>,
    ) -> Result<Self, StoreError> {
        let (shutdown, _) = watch::channel(false);
        let inner = Arc::new(Inner {
            store,
            pool,
            requests,
            http: super::peers::client(),
            metrics,
            policy,
            runtime: Handle::current(),
            active: Mutex::new(HashMap::new()),
            queue: Mutex::new(VecDeque::new()),
            lifecycle: tokio::sync::Mutex::new(()),
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

    fn active(&self, id: i64) -> Option<Arc<ActiveJob>> {
        self.inner.active.lock().expect("active map").get(&id).cloned()
    }

    /// Runs `f` on the request pool and awaits its result (CPU work stays off tokio's workers).
    async fn compute<T: Send + 'static>(&self, f: impl FnOnce() -> T + Send + 'static) -> Result<T, JobError> {
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
    /// returns the original job (`true` in the result) instead of creating a second one.
    pub async fn submit(
        &self,
        document: &Value,
        idempotency_key: Option<String>,
    ) -> Result<(JobResource, bool), JobError> {
        if *self.inner.shutdown.borrow() {
            return Err(JobError::ShuttingDown);
        }
        let job = parse_job_spec(document)?.validate()?;
        self.check_budget(&job.spec, range_len(&job.spec))?;
        self.check_queue()?;
        let config = job.config.clone();
        let reference = self.compute(move || reference_luminance(&config.scene)).await?;
        let spec_json = spec_json(&job.spec)?;
        let request_hash = idempotency_key.as_ref().map(|_| sha256_hex(document.to_string().as_bytes()));
        let new = NewJob {
            spec: spec_json,
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

    /// Refuses jobs beyond this server's budget: N_F · N_B · `iterations` and the cell count.
    fn check_budget(&self, spec: &JobSpec, iterations: u64) -> Result<(), JobError> {
        let policy = &self.inner.policy;
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
    pub async fn list(&self, state: Option<JobState>, cursor: Option<i64>, limit: u32) -> Result<JobList, JobError> {
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
        Ok(JobList { jobs, next_cursor })
    }

    /// Cancels a queued job at once, or asks a running one to stop (it stops within one chunk of
    /// light paths and keeps the iterations it completed).
    pub async fn cancel(&self, id: i64) -> Result<JobResource, JobError> {
        let _guard = self.inner.lifecycle.lock().await;
        let Some(job) = self.active(id) else {
            let row = self.inner.store.get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
            return Err(JobError::Conflict(format!(
                "job {id} is already {}; only queued or running jobs can be cancelled",
                row.state
            )));
        };
        let waiting = {
            let mut queue = self.inner.queue.lock().expect("queue");
            let before = queue.len();
            queue.retain(|&q| q != id);
            queue.len() < before
        };
        if waiting {
            self.inner.store.set_state(id, "cancelled", None, now_ms()).await?;
            self.inner.active.lock().expect("active map").remove(&id);
            job.view.send_modify(|r| {
                r.state = JobState::Cancelled;
                r.updated_at = rfc3339(now_ms());
            });
        } else {
            job.request_stop(STOP_CANCEL);
        }
        let resource = job.view.borrow().clone();
        Ok(resource)
    }

    /// Adds `iterations` to a job; they continue the same deterministic sequence. A succeeded or
    /// cancelled job is queued again; a queued or running one just runs longer.
    pub async fn extend(&self, id: i64, iterations: u64) -> Result<JobResource, JobError> {
        let _guard = self.inner.lifecycle.lock().await;
        let now = now_ms();
        if let Some(job) = self.active(id) {
            refuse_shard_extension(id, &job.job.spec)?;
            let total = job.total.load(Ordering::SeqCst);
            let new_total = checked_total(total, iterations)?;
            self.check_budget(&job.job.spec, new_total)?;
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
        let new_total = checked_total(row.iterations_total, iterations)?;
        let mut spec = parse_stored_spec(&row)?;
        refuse_shard_extension(id, &spec)?;
        self.check_budget(&spec, new_total)?;
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
        if let Some(job) = self.active(id) {
            let mut queue = self.inner.queue.lock().expect("queue");
            if !queue.contains(&id) {
                return Err(JobError::Conflict(format!("job {id} is running; cancel it before deleting it")));
            }
            queue.retain(|&q| q != id);
            drop(queue);
            self.inner.active.lock().expect("active map").remove(&id);
            job.view.send_modify(|r| r.state = JobState::Cancelled);
        }
        if self.inner.store.delete_job(id).await? { Ok(()) } else { Err(JobError::NotFound(id.to_string())) }
    }

    async fn state_and_total(&self, id: i64) -> Result<(JobState, u64, JobSpec, bool), JobError> {
        let resource = self.get(id).await?;
        Ok((resource.state, resource.progress.iterations_total, resource.spec, resource.merged))
    }

    /// The results of the latest checkpoint.
    pub async fn result(&self, id: i64) -> Result<JobResult, JobError> {
        let (state, total, _, _) = self.state_and_total(id).await?;
        let (done, json) = self.inner.store.load_result(id).await?.ok_or_else(|| no_checkpoint(id))?;
        let report: RunReport = serde_json::from_str(&json)
            .map_err(|e| JobError::Internal(format!("stored result of job {id} is unreadable: {e}")))?;
        Ok(JobResult { job_id: id, partial: !(state == JobState::Succeeded && done >= total), state, report })
    }

    /// Each strategy's figures at every checkpoint (thinned to at most 1,000 points).
    pub async fn history(&self, id: i64) -> Result<JobHistory, JobError> {
        self.get(id).await?;
        let rows = self.inner.store.load_history(id).await?;
        let points = thin(rows, MAX_HISTORY_POINTS)
            .into_iter()
            .map(|(iterations, json)| {
                serde_json::from_str(&json)
                    .map(|strategies| HistoryPoint { iterations, strategies })
                    .map_err(|e| JobError::Internal(format!("stored history of job {id} is unreadable: {e}")))
            })
            .collect::<Result<_, _>>()?;
        Ok(JobHistory { job_id: id, points })
    }

    /// The latest checkpoint's moments, verified against their checksum (and, for a job's own
    /// run, against the range it ran).
    async fn checkpoint_moments(
        &self,
        id: i64,
        spec: &JobSpec,
        merged: bool,
    ) -> Result<(Moments, Checkpoint), JobError> {
        let checkpoint = self.inner.store.load_checkpoint(id).await?.ok_or_else(|| no_checkpoint(id))?;
        let job = spec.validate()?;
        let moments = driver::decode_checkpoint(id, &checkpoint, &job, !merged)?;
        Ok((moments, checkpoint))
    }

    /// Re-solves the latest checkpoint with other solver options (a merge patch on the job's
    /// `solver`), without running anything or storing anything.
    pub async fn solve(&self, id: i64, patch: &Value) -> Result<JobResult, JobError> {
        if !patch.is_object() {
            return Err(SpecError::new("", "the body must be a JSON object of solver options").into());
        }
        let (state, total, spec, merged) = self.state_and_total(id).await?;
        let (moments, checkpoint) = self.checkpoint_moments(id, &spec, merged).await?;
        let mut solver = serde_json::to_value(&spec.solver).map_err(|e| JobError::Internal(e.to_string()))?;
        merge_patch(&mut solver, patch);
        let solver = serde_path_to_error::deserialize(&solver).map_err(|e| {
            let path = e.path().to_string();
            SpecError::new(if path == "." { String::new() } else { path }, e.into_inner().to_string())
        })?;
        validate_solver(&solver)?;
        let job = spec.validate()?;
        let reference = self.get(id).await?.reference_luminance;
        let report = self.compute(move || build_report(&moments, &job.config.cells, &solver, reference)).await?;
        let partial = !(state == JobState::Succeeded && checkpoint.iterations_done >= total);
        Ok(JobResult { job_id: id, partial, state, report })
    }

    /// The latest checkpoint's moments as a portable, checksummed document.
    pub async fn moments(&self, id: i64) -> Result<MomentsDocument, JobError> {
        let (_, _, spec, merged) = self.state_and_total(id).await?;
        let (moments, _) = self.checkpoint_moments(id, &spec, merged).await?;
        Ok(MomentsDocument::new(spec, moments))
    }

    /// The verified document of a source (pulled from the peer if it names one).
    async fn fetch(&self, source: Source) -> Result<MomentsDocument, JobError> {
        match source {
            Source::Document(doc) => Ok(*doc),
            Source::Peer(url) => {
                let bytes = pull(&self.inner.http, &url).await?;
                let doc = self.compute(move || MomentsDocument::from_json(&bytes)).await?;
                doc.map_err(|e| JobError::Peer(format!("the peer {url} sent an unusable document: {e}")))
            }
        }
    }

    /// Merges a moments document (inline, or pulled from a peer's job) into a finished job's
    /// statistics and recomputes its results. Refused, with nothing changed, if the job is active,
    /// the configuration differs, or any iteration would be counted twice.
    pub async fn merge_into(&self, id: i64, body: &Value) -> Result<JobResult, JobError> {
        let doc = self.fetch(parse_source(body, "")?).await?;
        {
            let _guard = self.inner.lifecycle.lock().await;
            if self.active(id).is_some() {
                return Err(JobError::Conflict(format!(
                    "job {id} is queued or running; merge into it once it has finished, or cancel it first"
                )));
            }
            let row = self.inner.store.get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
            if !matches!(row.state.as_str(), "succeeded" | "cancelled") {
                return Err(JobError::Conflict(format!(
                    "job {id} is {}; only a succeeded or cancelled job takes merges",
                    row.state
                )));
            }
            let job = parse_stored_spec(&row)?.validate()?;
            let mut moments = match self.inner.store.load_checkpoint(id).await? {
                Some(checkpoint) => driver::decode_checkpoint(id, &checkpoint, &job, !row.merged)?,
                None => Moments::new(&job.config),
            };
            moments.merge(&doc.moments).map_err(crate::sim::document::DocumentError::from)?;
            let reference = row.reference_luminance;
            let checkpoint = self.compute(move || driver::checkpoint_of(&moments, &job, reference)).await??;
            self.inner.store.write_merged(id, &checkpoint, now_ms()).await?;
        }
        self.result(id).await
    }

    /// Creates a finished job from several moments documents or peer jobs (a study): their
    /// statistics merged, their results computed. `solver` optionally patches the solver options
    /// of the first source's spec.
    pub async fn create_study(&self, sources: &[Value], solver: Option<&Value>) -> Result<JobResource, JobError> {
        if *self.inner.shutdown.borrow() {
            return Err(JobError::ShuttingDown);
        }
        if !(1..=256).contains(&sources.len()) {
            return Err(SpecError::new("sources", format!("must list 1 to 256 sources, got {}", sources.len())).into());
        }
        let parsed = sources
            .iter()
            .enumerate()
            .map(|(i, s)| parse_source(s, &format!("sources[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
        let mut documents = Vec::with_capacity(parsed.len());
        for source in parsed {
            documents.push(self.fetch(source).await?);
        }
        let mut merged = self.compute(move || merge_documents(&documents)).await??;
        if let Some(patch) = solver {
            let mut options =
                serde_json::to_value(&merged.spec.solver).map_err(|e| JobError::Internal(e.to_string()))?;
            merge_patch(&mut options, patch);
            merged.spec.solver = serde_path_to_error::deserialize(&options).map_err(|e| {
                SpecError::new(
                    format!("solver.{}", e.path()).trim_end_matches('.').to_string(),
                    e.into_inner().to_string(),
                )
            })?;
        }
        let job = merged.spec.validate()?;
        let config = job.config.clone();
        let fingerprint = config.fingerprint().to_string();
        let spec = spec_json(&job.spec)?;
        let (reference, checkpoint) = self
            .compute(move || {
                let reference = reference_luminance(&config.scene);
                (reference, driver::checkpoint_of(&merged.moments, &job, reference))
            })
            .await?;
        let new = NewJob {
            spec,
            fingerprint,
            iterations_total: checkpoint.as_ref().map_or(0, |c| c.iterations_done),
            reference_luminance: reference,
            idempotency_key: None,
            request_hash: None,
            now: now_ms(),
        };
        let row = self.inner.store.insert_study(&new, &checkpoint?).await?;
        resource_from_row(&row)
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
            job.request_stop(STOP_SHUTDOWN);
        }
    }

    /// Stops accepting work, asks every running job to checkpoint and stop, and waits for them.
    /// Interrupted jobs stay `queued` in the database and resume when a server starts again.
    pub async fn shutdown(&self) {
        self.inner.shutdown.send_replace(true);
        let jobs: Vec<Arc<ActiveJob>> = self.inner.active.lock().expect("active map").values().cloned().collect();
        for job in jobs {
            job.request_stop(STOP_SHUTDOWN);
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

/// Iterations a job runs (its range's length).
fn range_len(spec: &JobSpec) -> u64 {
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

fn spec_json(spec: &JobSpec) -> Result<String, JobError> {
    serde_json::to_string(spec).map_err(|e| JobError::Internal(e.to_string()))
}

fn checked_total(total: u64, add: u64) -> Result<u64, JobError> {
    match total.checked_add(add) {
        Some(t) if add >= 1 && t <= 1_000_000_000 => Ok(t),
        _ => Err(SpecError::new(
            "iterations",
            format!("must be ≥ 1 and bring the total ({total}) to at most 10^9, got {add}"),
        )
        .into()),
    }
}

fn no_checkpoint(id: i64) -> JobError {
    JobError::Conflict(format!("job {id} has no checkpoint yet: results appear after its first checkpoint"))
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
