//! Runs one job: on a blocking thread (never a tokio worker), asking the executor (`executor`: the
//! local rayon pool, or a Slurm cluster) for one segment of iterations at a time, with a checkpoint after every
//! segment.
//!
//! A segment ends when a checkpoint is due (every K iterations or T seconds), when the job is
//! asked to stop (cancel or shutdown: within one chunk of light paths, or 1,024 candidates of a
//! restricted iteration), or at the last iteration. A checkpoint writes the moments, their
//! checksum and the result document computed from them in one transaction. Because iteration s
//! draws only from the streams of (seed, s), a job resumed from a checkpoint ends with moments
//! bit-identical to an uninterrupted run.
//!
//! A database that cannot store (disk full, I/O error, busy) does not fail the job: its writes are
//! retried with a growing pause (up to `STORAGE_RETRY_CAP`) for as long as the job is not asked
//! to stop, with the iterations kept in memory; once storage is back the job carries on. If the
//! server stops meanwhile, the job resumes at the next start from its last stored checkpoint.

use std::ops::ControlFlow;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::checkpoint::{checkpoint_of, decode_checkpoint};
use super::documents::StrategyPoint;
use super::error::JobError;
use super::executor::{ExecutionView, Segment, SegmentError};
use super::references::scene_reference_until;
use super::resource::{BestStrategy, best_strategy, now_ms, rfc3339};
use super::state::{ActiveJob, Inner, StopReason};
use crate::sim::model::config::SimConfig;
use crate::sim::runner::{BatchMoments, RunError, batch_len};
use crate::sim::solve::noise::path_rows;
use crate::sim::solve::warnings::Warning;
use crate::sim::spec::ValidJob;
use crate::sim::stats::moments::Moments;

/// How often progress is published to the job's watchers.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(250);

/// How often the published progress also names the best strategy so far: that reads the moments,
/// which the restricted engine's workers then hand over from their own sums (an exact addition per
/// touched sum, some milliseconds), so not at every progress step.
const BEST_INTERVAL: Duration = Duration::from_secs(4);

/// Iterations between two checkpoints: `--checkpoint-iterations`, but no fewer than the engine's
/// batch (4,096 iterations of the restricted engine: a checkpoint is a full report, ~35 ms on the
/// paper's grid, where an iteration takes microseconds) where they run in this process; the
/// history has its points every
/// `--checkpoint-iterations` in between (`history_between`).
fn policy_checkpoints(inner: &Inner, config: &SimConfig) -> u64 {
    let engine_batch = inner.executor.threads().map_or(1, |threads| batch_len(config, threads));
    inner.policy.checkpoint_iterations.max(engine_batch)
}

/// A point of the history between checkpoints waits at least this many times its predecessor's
/// cost (its share of the time at most a third).
const POINT_SHARE: u32 = 2;

/// A history point between checkpoints: each per-path strategy's L and RMS from the sums (no fit,
/// microseconds); the fitted rows have their points at the checkpoints.
fn history_between(moments: &Moments, job: &ValidJob) -> String {
    let points: Vec<StrategyPoint> = path_rows(moments, &job.spec().solver.fixed)
        .iter()
        .map(|r| StrategyPoint { strategy: r.strategy, luminance: r.luminance, rms_percent: r.rms_percent })
        .collect();
    serde_json::to_string(&points).unwrap_or_else(|_| "[]".into())
}

/// Longest pause between two attempts of a write that failed for lack of storage.
const STORAGE_RETRY_CAP: Duration = Duration::from_secs(30);

/// Runs `job` to its end (or until stopped) and records the outcome.
pub(crate) fn drive(inner: &Inner, job: &ActiveJob) {
    // Everything this thread logs for the job carries its id.
    let span = tracing::info_span!("job", id = job.id);
    let _entered = span.enter();
    tracing::info!(first_iteration = job.start, iterations = job.total.load(Ordering::SeqCst), "job started");
    let outcome = run(inner, job);
    if let Err(e) = outcome {
        tracing::error!(job = job.id, error = %e, "job failed");
        // Work elsewhere (a cluster's tasks) stops with the job.
        inner.executor.cancel(job.id);
        let reason = e.to_string();
        if let Err(e) = inner.runtime.block_on(inner.fail(job.id, &reason)) {
            tracing::error!(job = job.id, error = %e, "could not record the failure");
        }
    }
}

fn run(inner: &Inner, job: &ActiveJob) -> Result<(), JobError> {
    let rt = &inner.runtime;
    let valid = &job.job;
    let config = &valid.config();
    let mut moments = match rt.block_on(inner.store.checkpoints().load(job.id))? {
        Some(checkpoint) => decode_checkpoint(job.id, &checkpoint, valid, true)?,
        None => Moments::new(config),
    };
    if !persist(inner, job, "mark the job running", || rt.block_on(inner.mark_running(job)))? {
        return stopped(inner, job);
    }
    // The scene's R → 0 reference: computed here, on the job's own thread, when the submission
    // did not find it cached (a request never waits for a quadrature); stopped with the job.
    let mut reference = job.view.borrow().reference_luminance;
    if reference.is_none() {
        match scene_reference_until(&config.scene, &job.stop) {
            Err(_) => return stopped(inner, job),
            Ok(None) => {}
            Ok(value) => {
                reference = value;
                if !persist(inner, job, "store the reference luminance", || {
                    rt.block_on(inner.store.jobs().set_reference(job.id, value, now_ms()))?;
                    Ok(())
                })? {
                    return stopped(inner, job);
                }
                job.view.send_modify(|r| r.reference_luminance = value);
            }
        }
    }
    let mut checkpointed = moments.iterations();
    // Checkpoints (a full report each) come no more often than the engine's own batches, as they
    // did before the batches were cut at --checkpoint-iterations for the history's points.
    let checkpoint_every = policy_checkpoints(inner, config);
    let start = job.start;
    loop {
        let done = moments.iterations();
        let total = job.total.load(Ordering::SeqCst);
        // A stop request is honoured first, even when the last iteration is already done: an
        // empty segment would not look at the flag, and the loop would spin (a shutdown racing
        // the final iteration once hung the tests). The checkpoint holds every iteration, so a
        // job interrupted here finishes at once on the next start.
        if job.stop.load(Ordering::SeqCst) {
            return stopped(inner, job);
        }
        if done >= total {
            let mut finished = false;
            if !persist(inner, job, "mark the job succeeded", || {
                finished = rt.block_on(inner.finish(job, done))?;
                Ok(())
            })? {
                return stopped(inner, job);
            }
            if finished {
                return Ok(());
            }
            continue; // extended while finishing
        }
        let segment_start = Instant::now();
        // Publish after the first batch already, then at most every PROGRESS_INTERVAL.
        let mut last_publish = segment_start.checked_sub(PROGRESS_INTERVAL).unwrap_or(segment_start);
        let mut last_best = segment_start.checked_sub(BEST_INTERVAL).unwrap_or(segment_start);
        let policy = &inner.policy;
        let mut counted = done;
        // Points of the history between two checkpoints (every --checkpoint-iterations): the
        // per-path rows, sums without a fit, written with the next checkpoint.
        let mut between: Vec<(u64, String)> = Vec::new();
        let mut last_point = done;
        // A point costs a hand-over of the workers' sums and the per-path rows (milliseconds): the
        // next waits at least POINT_SHARE times as long, as checkpoints do.
        let (mut point_at, mut point_cost) = (segment_start, Duration::ZERO);
        let mut on_batch = |m: &mut dyn BatchMoments, next: u64| {
            let next = next - start;
            inner.metrics.add_iterations(next.saturating_sub(counted), config.light_paths);
            counted = counted.max(next);
            if last_publish.elapsed() >= PROGRESS_INTERVAL {
                last_publish = Instant::now();
                let moments = (last_best.elapsed() >= BEST_INTERVAL).then(|| {
                    last_best = Instant::now();
                    m.moments()
                });
                publish_progress(job, moments, next, done, segment_start, config.light_paths);
            }
            let elapsed = segment_start.elapsed();
            let due = next - checkpointed >= checkpoint_every || elapsed >= policy.checkpoint_interval;
            if due {
                return ControlFlow::Break(());
            }
            if next - last_point >= policy.checkpoint_iterations && point_at.elapsed() >= point_cost * POINT_SHARE {
                let started = Instant::now();
                last_point = next;
                let moments = m.moments();
                between.push((moments.iterations(), history_between(moments, valid)));
                (point_at, point_cost) = (Instant::now(), started.elapsed());
            }
            ControlFlow::Continue(())
        };
        let range = start + done..start + total;
        let cancelled = || job.stop_reason() == Some(StopReason::Cancel);
        let report = |view: ExecutionView| job.view.send_modify(|r| r.execution = Some(view));
        let segment = Segment {
            id: job.id,
            job: valid,
            first: start,
            total: start + total,
            stop: &job.stop,
            cancelled: &cancelled,
            report: &report,
            batch: policy.checkpoint_iterations,
        };
        let outcome = inner.executor.run_segment(&segment, range, &mut moments, &mut on_batch);
        if moments.iterations() > checkpointed {
            if !write_checkpoint(inner, job, &moments, reference, between)? {
                return stopped(inner, job);
            }
            checkpointed = moments.iterations();
        }
        match outcome {
            Ok(_) => {}
            Err(SegmentError::Run(RunError::Cancelled)) => return stopped(inner, job),
            Err(SegmentError::Run(RunError::Moments(e @ crate::sim::stats::moments::MergeError::Overflow(_)))) => {
                return Err(JobError::Simulation(e.to_string()));
            }
            Err(SegmentError::Run(e @ RunError::Moments(_))) => return Err(JobError::Internal(e.to_string())),
            Err(SegmentError::Failed(reason)) => return Err(JobError::Execution(reason)),
        }
    }
}

/// Records a stopped job: cancelled on request, interrupted (to resume later) on shutdown. While
/// the database cannot store, a cancel is retried until it can (or the server stops); the cancel
/// itself is already stored (`cancel_requested`), so a restart ends the job cancelled either way.
fn stopped(inner: &Inner, job: &ActiveJob) -> Result<(), JobError> {
    if job.stop_reason() == Some(StopReason::Cancel) {
        // The stop may have been seen between two segments, outside the executor: work elsewhere
        // (a cluster's tasks) is stopped here too (idempotent). A shutdown leaves it running.
        inner.executor.cancel(job.id);
    }
    let mut pause = Duration::from_millis(100);
    loop {
        let outcome = if job.stop_reason() == Some(StopReason::Cancel) {
            inner.runtime.block_on(inner.mark_cancelled(job))
        } else {
            inner.runtime.block_on(inner.mark_interrupted(job))
        };
        match outcome {
            Err(JobError::Store(e)) if e.is_storage_failure() || e.is_transient() => {
                if inner.shutting_down() {
                    tracing::warn!(job = job.id, error = %e, "could not record the stopped job; it is settled at the next start");
                    return Ok(());
                }
                tracing::warn!(job = job.id, error = %e, "could not record the stopped job: storage unavailable, retrying");
                wait(pause, || inner.shutting_down());
                pause = (pause * 2).min(STORAGE_RETRY_CAP);
            }
            other => return other,
        }
    }
}

/// Runs a database write of the running job, retrying for as long as the storage refuses it
/// (full, failing or busy) and the job is not asked to stop. `Ok(false)`: it was asked to stop
/// before the write succeeded.
fn persist(
    inner: &Inner,
    job: &ActiveJob,
    what: &str,
    mut write: impl FnMut() -> Result<(), JobError>,
) -> Result<bool, JobError> {
    let mut pause = Duration::from_millis(100);
    loop {
        match write() {
            Ok(()) => return Ok(true),
            Err(JobError::Store(e)) if e.is_storage_failure() || e.is_transient() => {
                tracing::warn!(job = job.id, error = %e, pause_ms = pause.as_millis() as u64,
                    "could not {what}: storage unavailable, retrying");
                if wait(pause, || job.stop.load(Ordering::SeqCst) || inner.shutting_down()) {
                    return Ok(false);
                }
                pause = (pause * 2).min(STORAGE_RETRY_CAP);
            }
            Err(e) => return Err(e),
        }
    }
}

/// Sleeps for `pause` in short steps, so that `interrupt` is honoured promptly; true if it was.
fn wait(pause: Duration, interrupt: impl Fn() -> bool) -> bool {
    let until = Instant::now() + pause;
    loop {
        if interrupt() {
            return true;
        }
        let now = Instant::now();
        if now >= until {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20).min(until - now));
    }
}

/// Publishes in-memory progress: iterations, throughput, ETA, and with `moments` the best per-path
/// strategy.
fn publish_progress(
    job: &ActiveJob,
    moments: Option<&Moments>,
    next: u64,
    start: u64,
    started: Instant,
    light_paths: u64,
) {
    let elapsed = started.elapsed().as_secs_f64();
    let per_second = (next - start) as f64 / elapsed.max(1e-9);
    let total = job.total.load(Ordering::SeqCst);
    let best = moments.and_then(|m| best_strategy(&path_rows(m, &job.job.spec().solver.fixed), None));
    job.view.send_modify(|r| {
        r.progress.iterations_done = next;
        r.progress.iterations_total = total;
        r.progress.light_paths_per_second = Some(per_second * light_paths as f64);
        r.progress.eta_seconds = Some(total.saturating_sub(next) as f64 / per_second.max(1e-12));
        if best.is_some() {
            r.progress.best = best;
        }
    });
}

/// Writes a checkpoint (retrying while storage is unavailable, see [`persist`]) and publishes it.
/// `Ok(false)`: the job was asked to stop before the checkpoint could be stored.
fn write_checkpoint(
    inner: &Inner,
    job: &ActiveJob,
    moments: &Moments,
    reference: Option<f64>,
    between: Vec<(u64, String)>,
) -> Result<bool, JobError> {
    let started = Instant::now();
    let mut checkpoint = checkpoint_of(moments, &job.job, reference)?;
    checkpoint.between = between;
    let best = checkpoint.best.as_deref().and_then(|b| serde_json::from_str::<BestStrategy>(b).ok());
    let warnings: Vec<Warning> =
        checkpoint.warnings.as_deref().and_then(|w| serde_json::from_str(w).ok()).unwrap_or_default();
    let mut now = now_ms();
    let stored = persist(inner, job, "write a checkpoint", || {
        now = now_ms();
        inner.runtime.block_on(inner.store.checkpoints().write(job.id, &checkpoint, now)).map_err(JobError::from)
    })?;
    if !stored {
        return Ok(false);
    }
    inner.metrics.observe_checkpoint(started.elapsed());
    // The bytes just written are the ones hashed: results may be served without re-hashing them.
    inner.verified.remember(job.id, &checkpoint.checksum);
    job.view.send_modify(|r| {
        r.progress.iterations_checkpointed = checkpoint.iterations_done;
        r.progress.iterations_done = r.progress.iterations_done.max(checkpoint.iterations_done);
        r.progress.best = best.clone();
        r.warnings = warnings.clone();
        r.updated_at = rfc3339(now);
    });
    tracing::debug!(
        job = job.id,
        iterations = checkpoint.iterations_done,
        seconds = started.elapsed().as_secs_f64(),
        "checkpoint written"
    );
    Ok(true)
}
