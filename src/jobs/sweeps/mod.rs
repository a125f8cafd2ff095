//! Sweeps on the server: a sweep document planned (`sim::sweep`), its runs inserted as ordinary
//! queued jobs in one transaction, and its figures and table read back from their checkpoints.
//!
//! Bounds: a sweep has at most `--max-sweep-points` points and runs and is refused whole (429)
//! when its runs would not fit in the queue (checked before any quadrature); every run passes the
//! same budget and work checks as a submitted job. Planning, validation and the reference
//! quadratures (once per distinct scene, stopped when the client leaves or the server stops) run
//! on the request pool; predicted points are computed there too, once per checkpoint of their run
//! (a small cache keyed by the checkpoint's checksum) and one re-fit at a time (concurrent readers
//! wait for it, up to a timeout, then read the cache), so neither a dashboard polling a sweep nor
//! several readers at once re-fit every point each. `wait`: the long-poll of a sweep.
//!
//! Imports: crate::jobs, crate::sim, crate::store

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

mod wait;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use utoipa::ToSchema;

use super::core::checkpoint::spec_json;
use super::core::error::JobError;
use super::core::manager::JobManager;
use super::core::policy::{check_budget, check_iteration_work, range_len};
use super::core::references::cached_scene_reference;
use super::core::resource::{JobState, now_ms, resource_from_row, rfc3339};
use super::statistics::Statistics;
use crate::sim::spec::SpecError;
use crate::sim::sweep::{
    PointFigures, PointResults, SweepPlan, SweepSpec, SweepTable, figures_of_report, plan, point_figures,
};
use crate::store::{JobRow, NewJob, SweepRow};

/// Most sweeps' predicted figures kept in memory (beyond it the cache starts over).
const MAX_CACHED_RUNS: usize = 1024;

/// One point of a sweep as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SweepPointView {
    /// The point's position in the sweep, from 0 (with `grid`, the last axis varies fastest); the
    /// `point` column of the sweep's table.
    pub index: usize,
    /// The swept fields' values.
    #[schema(value_type = Object)]
    pub values: Map<String, Value>,
    /// The run (job) that answers the point: measured by it, or predicted from it.
    pub run: usize,
    /// The run's job; null if it was deleted.
    pub job_id: Option<i64>,
    /// The state of the run's job; null if it was deleted.
    pub state: Option<JobState>,
    /// Its honest noise table and recommended weights, once the run has a checkpoint (predicted,
    /// for a point on an axis by prediction).
    pub figures: Option<PointFigures>,
    /// With `measure_predictions`: the direct run's job, and its figures beside the prediction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_job_id: Option<i64>,
    /// With `measure_predictions`: the direct run's figures, to compare with the predicted
    /// `figures`; absent until that run has a checkpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured: Option<PointFigures>,
}

/// How far a sweep has come.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SweepProgress {
    /// Runs (jobs) the sweep queued: one per distinct run, plus the direct runs of
    /// `measure_predictions`; points on an axis by prediction share their run.
    pub runs: usize,
    /// Runs per job state (a run whose job was deleted counts as `deleted`).
    pub runs_by_state: BTreeMap<String, usize>,
    /// Iterations done, summed over the runs whose jobs still exist.
    pub iterations_done: u64,
    /// Iterations planned (each job's `iterations_total`), summed over the runs whose jobs still
    /// exist.
    pub iterations_total: u64,
}

/// A sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SweepResource {
    /// The sweep's id, as in `/v1/sweeps/{id}` and its runs' `sweep_id`.
    pub id: i64,
    /// RFC 3339, UTC.
    pub created_at: String,
    /// `running` while any run runs, else `queued` while any waits, else `succeeded` if all did,
    /// else `failed` if any failed, else `cancelled`.
    pub state: JobState,
    /// The sweep document (base job document, axes, mode), its defaults filled in.
    pub spec: SweepSpec,
    /// The swept fields, in the axes' order.
    pub fields: Vec<String>,
    /// Runs, runs per state and iterations, over the sweep's jobs.
    pub progress: SweepProgress,
    /// Every point; `figures` only in `GET /v1/sweeps/{id}` (not in lists or acknowledgements).
    pub points: Vec<SweepPointView>,
}

/// One page of sweeps, newest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SweepList {
    /// The sweeps of this page (at most `limit`), newest (highest id) first, without their
    /// points' figures.
    pub sweeps: Vec<SweepResource>,
    /// Pass as `cursor` to get the next page; null on the last page.
    pub next_cursor: Option<String>,
}

/// Predicted figures of a run's points at one checkpoint (its checksum).
type PredictionCache = std::sync::Mutex<BTreeMap<i64, CachedPredictions>>;

/// A run's predicted figures, the checksum of the checkpoint they come from and when they were made.
struct CachedPredictions {
    checksum: String,
    made: Instant,
    figures: Arc<Vec<(usize, PointFigures)>>,
}

/// While a run is still running, its predictions are re-fitted at most this often (each of its
/// checkpoints changes the moments, and a re-fit of every predicted point is real work).
const REFIT_INTERVAL: Duration = Duration::from_secs(10);

/// The longest a read of a sweep waits for another request's re-fit before it is answered 429.
const REFIT_WAIT: Duration = Duration::from_secs(20);

/// Sweeps: their runs queued as jobs of the lifecycle, their figures read from the runs'
/// statistics; cheap to clone. It owns the predicted figures of the runs' points (a cache per
/// checkpoint) and the lock that keeps their re-fits one at a time.
#[derive(Clone)]
pub struct Sweeps {
    jobs: JobManager,
    statistics: Statistics,
    /// Predicted figures of sweep runs, per (job, checkpoint checksum).
    predictions: Arc<PredictionCache>,
    /// One re-fit of predicted sweep points at a time: concurrent reads of a sweep wait for it and
    /// then read its result from `predictions` instead of each re-fitting every point.
    refit: Arc<tokio::sync::Mutex<()>>,
}

impl Sweeps {
    /// Sweeps whose runs are jobs of `statistics`' lifecycle.
    pub fn new(statistics: Statistics) -> Self {
        Self { jobs: statistics.jobs().clone(), statistics, predictions: Default::default(), refit: Default::default() }
    }

    /// Plans a sweep, checks every run as a job, and queues the runs; acknowledged once stored.
    pub async fn create_sweep(&self, document: Value) -> Result<SweepResource, JobError> {
        if self.jobs.is_shutting_down() {
            return Err(JobError::ShuttingDown);
        }
        let policy = self.jobs.policy().clone();
        // Planning and the checks of every run first (cheap), then the queue's room, and only then
        // the reference quadratures — once per distinct scene, cached across requests, stopped
        // when the client goes away, the server shuts down or the deadline passes.
        let (plan, valid) = self
            .jobs
            .compute(move || -> Result<_, JobError> {
                let plan = plan(&document, policy.max_sweep_points)?;
                let mut valid = Vec::with_capacity(plan.runs.len());
                for run in &plan.runs {
                    let job = run.spec.validate()?;
                    let at_run = |e: JobError| match e {
                        JobError::Invalid(e) => JobError::Invalid(SpecError::new(
                            "axes",
                            format!("run {} ({}): {}: {}", run.index, plan.describe_run(run.index), e.field, e.message),
                        )),
                        other => other,
                    };
                    check_budget(&policy, job.spec(), range_len(job.spec())).map_err(at_run)?;
                    check_iteration_work(&policy, &job).map_err(at_run)?;
                    valid.push(job);
                }
                Ok((plan, valid))
            })
            .await??;
        self.check_room_for(valid.len())?;
        // Each run's R → 0 reference from the cache, or computed by the run itself when it starts
        // (`driver`): creating a sweep of many scenes costs no quadrature.
        let references: Vec<Option<f64>> =
            valid.iter().map(|job| cached_scene_reference(&job.config().scene).flatten()).collect();
        let new_jobs = valid
            .iter()
            .zip(references)
            .map(|(job, reference)| -> Result<NewJob, JobError> {
                Ok(NewJob {
                    spec: spec_json(job.spec())?,
                    fingerprint: job.config().fingerprint().to_string(),
                    iterations_total: range_len(job.spec()),
                    reference_luminance: reference,
                    idempotency_key: None,
                    request_hash: None,
                    now: 0,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        // Again: other requests may have filled the queue while the quadratures ran.
        self.check_room_for(new_jobs.len())?;
        let spec_text = serde_json::to_string(&plan.spec).map_err(|e| JobError::Internal(e.to_string()))?;
        let _guard = self.jobs.transition().await;
        // Nothing is acknowledged once the server is stopping.
        if self.jobs.is_shutting_down() {
            return Err(JobError::ShuttingDown);
        }
        let now = now_ms();
        let (id, rows) = self.jobs.store().sweeps().insert(&spec_text, &new_jobs, now).await?;
        for (row, job) in rows.iter().zip(valid) {
            self.jobs.enqueue(row.id, job, resource_from_row(row)?);
        }
        drop(_guard);
        let row = SweepRow { id, spec: spec_text, created_at: now };
        self.sweep_resource(&row, &plan, false).await
    }

    /// 429 unless `runs` more jobs fit in the queue.
    fn check_room_for(&self, runs: usize) -> Result<(), JobError> {
        let queued = self.jobs.queued();
        if queued + runs > self.jobs.policy().max_queued_jobs {
            return Err(JobError::Busy {
                detail: format!(
                    "the sweep's {runs} runs do not fit in the queue ({queued} jobs waiting, at most {} queued: --max-queued-jobs)",
                    self.jobs.policy().max_queued_jobs
                ),
                retry_after_seconds: 30,
            });
        }
        Ok(())
    }

    /// Returns once every run of sweep `id` has ended, `wait` has passed or the server stops
    /// (`?wait=` of `GET /v1/sweeps/{id}`; see `wait`).
    pub async fn wait_for_end(&self, id: i64, wait: Duration) -> Result<(), JobError> {
        wait::until_ended(&self.jobs, id, wait).await
    }

    /// A sweep with every point's figures.
    pub async fn get_sweep(&self, id: i64) -> Result<SweepResource, JobError> {
        let (row, plan) = self.sweep_plan(id).await?;
        self.sweep_resource(&row, &plan, true).await
    }

    /// A page of sweeps, newest first (without figures).
    pub async fn list_sweeps(&self, cursor: Option<i64>, limit: u32) -> Result<SweepList, JobError> {
        let mut rows = self.jobs.store().sweeps().list(cursor, limit + 1).await?;
        let more = rows.len() > limit as usize;
        rows.truncate(limit as usize);
        let next_cursor = if more { rows.last().map(|r| r.id.to_string()) } else { None };
        let mut sweeps = Vec::with_capacity(rows.len());
        for row in rows {
            let plan = self.replan(&row).await?;
            sweeps.push(self.sweep_resource(&row, &plan, false).await?);
        }
        Ok(SweepList { sweeps, next_cursor })
    }

    /// The table of a sweep: one row per point with figures and strategy.
    pub async fn sweep_table(&self, id: i64) -> Result<SweepTable, JobError> {
        let (row, plan) = self.sweep_plan(id).await?;
        let resource = self.sweep_resource(&row, &plan, true).await?;
        let results: Vec<PointResults> =
            resource.points.into_iter().map(|p| PointResults { figures: p.figures, measured: p.measured }).collect();
        self.jobs.compute(move || SweepTable::build(&plan, &results)).await
    }

    /// Cancels every queued or running run of a sweep (each keeps the iterations it completed).
    pub async fn cancel_sweep(&self, id: i64) -> Result<SweepResource, JobError> {
        let (row, plan) = self.sweep_plan(id).await?;
        for (_, job) in self.jobs.store().sweeps().runs(id).await? {
            if matches!(job.state, JobState::Queued | JobState::Running) {
                match self.jobs.cancel(job.id).await {
                    // It ended meanwhile: nothing to cancel.
                    Ok(_) | Err(JobError::Conflict(_)) => {}
                    Err(e) => return Err(e),
                }
            }
        }
        self.sweep_resource(&row, &plan, false).await
    }

    /// Deletes a sweep and its jobs; refused while one of them runs (cancel the sweep first).
    pub async fn delete_sweep(&self, id: i64) -> Result<(), JobError> {
        let jobs = self.jobs.store().sweeps().runs(id).await?;
        let _guard = self.jobs.transition().await;
        if self.jobs.store().sweeps().get(id).await?.is_none() {
            return Err(no_sweep(id));
        }
        for (_, job) in &jobs {
            if self.jobs.active(job.id).is_some() && !self.jobs.is_queued(job.id) {
                return Err(JobError::Conflict(format!(
                    "job {} of sweep {id} is running; cancel the sweep (POST /v1/sweeps/{id}/cancel) before deleting it",
                    job.id
                )));
            }
            if self.jobs.is_held(job.id) {
                return Err(JobError::Conflict(format!("job {} of sweep {id} is taking a merge; retry", job.id)));
            }
        }
        if !self.jobs.store().sweeps().delete(id).await? {
            return Err(no_sweep(id));
        }
        for (_, job) in &jobs {
            self.jobs.discard_queued(job.id);
        }
        Ok(())
    }

    async fn sweep_plan(&self, id: i64) -> Result<(SweepRow, SweepPlan), JobError> {
        let row = self.jobs.store().sweeps().get(id).await?.ok_or_else(|| no_sweep(id))?;
        let plan = self.replan(&row).await?;
        Ok((row, plan))
    }

    /// The stored sweep planned again (on the request pool; it was validated when created, and
    /// may have more points than a restarted server's limit).
    async fn replan(&self, row: &SweepRow) -> Result<SweepPlan, JobError> {
        let text = row.spec.clone();
        let id = row.id;
        self.jobs
            .compute(move || {
                let document: Value = serde_json::from_str(&text)
                    .map_err(|e| JobError::Internal(format!("stored sweep {id} is unreadable: {e}")))?;
                plan(&document, usize::MAX)
                    .map_err(|e| JobError::Internal(format!("stored sweep {id} is no longer valid: {e}")))
            })
            .await?
    }

    async fn sweep_resource(&self, row: &SweepRow, plan: &SweepPlan, figures: bool) -> Result<SweepResource, JobError> {
        let jobs: BTreeMap<usize, JobRow> = self.jobs.store().sweeps().runs(row.id).await?.into_iter().collect();
        let mut by_state: BTreeMap<String, usize> = BTreeMap::new();
        let (mut done, mut total) = (0, 0);
        let mut states = Vec::new();
        let mut run_views = Vec::with_capacity(plan.runs.len());
        for r in 0..plan.runs.len() {
            let view = match jobs.get(&r) {
                Some(job) => Some(match self.jobs.active(job.id) {
                    Some(active) => active.view.borrow().clone(),
                    None => resource_from_row(job)?,
                }),
                None => None,
            };
            let state = view.as_ref().map(|v| v.state);
            *by_state.entry(state.map_or("deleted".to_string(), |s| s.as_str().to_string())).or_default() += 1;
            if let Some(v) = &view {
                done += v.progress.iterations_done;
                total += v.progress.iterations_total;
                states.push(v.state);
            }
            run_views.push(view);
        }
        let mut all = Vec::new();
        if figures {
            for (r, view) in run_views.iter().enumerate() {
                if let Some(v) = view {
                    all.extend(self.run_figures(plan, r, v.id, v.progress.iterations_checkpointed > 0).await?);
                }
            }
        }
        let mut results = PointResults::collect(plan, all);
        let fields = plan.fields();
        let points = plan
            .points
            .iter()
            .map(|p| SweepPointView {
                index: p.index,
                values: fields.iter().cloned().zip(p.values.iter().cloned()).collect(),
                run: p.run,
                job_id: run_views[p.run].as_ref().map(|v| v.id),
                state: run_views[p.run].as_ref().map(|v| v.state),
                figures: results[p.index].figures.take(),
                measured_job_id: p.measured_run.and_then(|r| run_views[r].as_ref().map(|v| v.id)),
                measured: results[p.index].measured.take(),
            })
            .collect();
        Ok(SweepResource {
            id: row.id,
            created_at: rfc3339(row.created_at),
            state: overall_state(&states),
            spec: plan.spec.clone(),
            fields,
            progress: SweepProgress {
                runs: plan.runs.len(),
                runs_by_state: by_state,
                iterations_done: done,
                iterations_total: total,
            },
            points,
        })
    }

    /// The figures of run `r`'s points from its job's latest checkpoint (none before the first):
    /// its stored result for measured points; for predicted ones a prediction from its moments,
    /// cached per checkpoint so that a poll reads only the result's checksum.
    async fn run_figures(
        &self,
        plan: &SweepPlan,
        r: usize,
        job: i64,
        checkpointed: bool,
    ) -> Result<Vec<(usize, PointFigures)>, JobError> {
        if !checkpointed {
            return Ok(Vec::new());
        }
        let predicted = plan.points.iter().any(|p| p.run == r && p.predicted.is_some());
        if !predicted {
            let result = self.statistics.result(job).await?;
            let spec = &plan.runs[r].spec;
            let budget =
                crate::sim::solve::predict::Budget { light_paths: spec.light_paths, camera_paths: spec.camera_paths };
            let f = figures_of_report(&result.report, budget, result.partial);
            let answered = |p: &&crate::sim::sweep::PlannedPoint| p.run == r || p.measured_run == Some(r);
            return Ok(plan.points.iter().filter(answered).map(|p| (p.index, f.clone())).collect());
        }
        let Some(stored) = self.jobs.store().checkpoints().load_result(job).await? else { return Ok(Vec::new()) };
        let checksum = stored.checksum;
        let running = self.jobs.active(job).is_some();
        let cached = || {
            let cache = self.predictions.lock().expect("prediction cache");
            let hit = cache.get(&job)?;
            (hit.checksum == checksum || (running && hit.made.elapsed() < REFIT_INTERVAL))
                .then(|| hit.figures.as_ref().clone())
        };
        if let Some(hit) = cached() {
            return Ok(hit);
        }
        // Single flight: one re-fit at a time, and a reader that waited finds its run re-fitted.
        let Ok(_refit) = tokio::time::timeout(REFIT_WAIT, self.refit.lock()).await else {
            return Err(JobError::Busy {
                detail: "other sweeps' predicted points are being re-fitted; retry".into(),
                retry_after_seconds: 5,
            });
        };
        if let Some(hit) = cached() {
            return Ok(hit);
        }
        self.jobs.metrics().count_sweep_refit();
        let result = self.statistics.result(job).await?;
        let latest = self.statistics.latest(job).await?;
        let plan = plan.clone();
        let partial = result.partial || latest.state != JobState::Succeeded;
        let figures = self
            .jobs
            .compute_heavy(move |_| {
                point_figures(&plan, r, &latest.moments, &latest.job.config().cells, &result.report, partial)
            })
            .await?;
        let mut cache = self.predictions.lock().expect("prediction cache");
        if cache.len() >= MAX_CACHED_RUNS {
            cache.clear();
        }
        cache.insert(job, CachedPredictions { checksum, made: Instant::now(), figures: Arc::new(figures.clone()) });
        Ok(figures)
    }
}

fn no_sweep(id: i64) -> JobError {
    JobError::SweepNotFound(id)
}

/// The state a sweep's runs add up to.
fn overall_state(states: &[JobState]) -> JobState {
    let any = |s: JobState| states.contains(&s);
    if any(JobState::Running) {
        JobState::Running
    } else if any(JobState::Queued) {
        JobState::Queued
    } else if !states.is_empty() && states.iter().all(|&s| s == JobState::Succeeded) {
        JobState::Succeeded
    } else if any(JobState::Failed) {
        JobState::Failed
    } else {
        JobState::Cancelled
    }
}
