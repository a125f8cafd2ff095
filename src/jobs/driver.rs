//! Runs one job: on a blocking thread (never a tokio worker), driving the rayon pool segment by
//! segment, with a checkpoint after every segment.
//!
//! A segment ends when a checkpoint is due (every K iterations or T seconds), when the job is
//! asked to stop (cancel or shutdown: within one chunk of light paths), or at the last iteration.
//! A checkpoint writes the moments, their checksum and the result document computed from them in
//! one transaction. Because iteration s draws only from the streams of (seed, s), a job resumed from
//! a checkpoint ends with moments bit-identical to an uninterrupted run.

use std::ops::ControlFlow;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::documents::StrategyPoint;
use super::error::JobError;
use super::manager::{ActiveJob, Inner, STOP_CANCEL, best_strategy};
use super::resource::{now_ms, rfc3339};
use crate::sim::config::sha256_hex;
use crate::sim::coverage::Coverage;
use crate::sim::moments::Moments;
use crate::sim::noise::path_rows;
use crate::sim::report::build_report;
use crate::sim::runner::{RunError, run_iterations};
use crate::sim::spec::ValidJob;
use crate::store::{Checkpoint, StoreError};

/// How often progress is published to the job's watchers.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(250);

/// Attempts for a database write that failed transiently (busy, locked).
const WRITE_ATTEMPTS: u32 = 5;

/// Runs `job` to its end (or until stopped) and records the outcome.
pub(crate) fn drive(inner: &Inner, job: &ActiveJob) {
    // Everything this thread logs for the job carries its id.
    let span = tracing::info_span!("job", id = job.id);
    let _entered = span.enter();
    tracing::info!(first_iteration = job.start, iterations = job.total.load(Ordering::SeqCst), "job started");
    let outcome = run(inner, job);
    if let Err(e) = outcome {
        tracing::error!(job = job.id, error = %e, "job failed");
        let reason = e.to_string();
        if let Err(e) = inner.runtime.block_on(inner.fail(job.id, &reason)) {
            tracing::error!(job = job.id, error = %e, "could not record the failure");
        }
    }
}

/// The moments of a checkpoint, verified: checksum, format and configuration must match the job,
/// and for a job's own run (`own_run`) the coverage must be the start of its range — or the
/// checkpoint is reported corrupted (never silently resumed from).
pub(crate) fn decode_checkpoint(
    id: i64,
    checkpoint: &Checkpoint,
    job: &ValidJob,
    own_run: bool,
) -> Result<Moments, JobError> {
    let corrupt = |detail: String| JobError::Store(StoreError::Corrupt { job: id, detail });
    let actual = sha256_hex(&checkpoint.moments);
    if actual != checkpoint.checksum {
        return Err(corrupt(format!(
            "checkpoint checksum mismatch (stored {}, computed {actual})",
            checkpoint.checksum
        )));
    }
    let moments: Moments = serde_json::from_slice(&checkpoint.moments)
        .map_err(|e| corrupt(format!("checkpoint moments unreadable: {e}")))?;
    moments.check_well_formed().map_err(|e| corrupt(format!("checkpoint moments: {e}")))?;
    if moments.fingerprint != job.config.fingerprint() {
        return Err(corrupt("checkpoint moments belong to another configuration".into()));
    }
    if moments.iterations() != checkpoint.iterations_done {
        return Err(corrupt(format!(
            "checkpoint holds {} iterations, its row says {}",
            moments.iterations(),
            checkpoint.iterations_done
        )));
    }
    if own_run {
        let start = job.spec.iteration_range().start;
        let expected = Coverage::range(job.spec.seed, start, start + checkpoint.iterations_done);
        if moments.coverage != expected {
            return Err(corrupt(format!("checkpoint covers {:?}, expected {expected:?}", moments.coverage)));
        }
    }
    Ok(moments)
}

fn run(inner: &Inner, job: &ActiveJob) -> Result<(), JobError> {
    let rt = &inner.runtime;
    let valid = &job.job;
    let config = &valid.config;
    let seed = valid.spec.seed;
    let mut moments = match rt.block_on(inner.store.load_checkpoint(job.id))? {
        Some(checkpoint) => decode_checkpoint(job.id, &checkpoint, valid, true)?,
        None => Moments::new(config),
    };
    rt.block_on(inner.mark_running(job))?;
    let reference = job.view.borrow().reference_luminance;
    let mut checkpointed = moments.iterations();
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
            if rt.block_on(inner.finish(job, done))? {
                return Ok(());
            }
            continue; // extended while finishing
        }
        let segment_start = Instant::now();
        // Publish after the first batch already, then at most every PROGRESS_INTERVAL.
        let mut last_publish = segment_start.checked_sub(PROGRESS_INTERVAL).unwrap_or(segment_start);
        let policy = &inner.policy;
        let outcome = inner.pool.install(|| {
            run_iterations(config, seed, start + done..start + total, &mut moments, &job.stop, |m, next| {
                let next = next - start;
                if last_publish.elapsed() >= PROGRESS_INTERVAL {
                    last_publish = Instant::now();
                    publish_progress(job, m, next, done, segment_start, config.light_paths);
                }
                let due = next - checkpointed >= policy.checkpoint_iterations
                    || segment_start.elapsed() >= policy.checkpoint_interval;
                if due { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
            })
        });
        if moments.iterations() > checkpointed {
            write_checkpoint(inner, job, &moments, reference)?;
            checkpointed = moments.iterations();
        }
        match outcome {
            Ok(_) => {}
            Err(RunError::Cancelled) => return stopped(inner, job),
            Err(e @ RunError::Moments(_)) => return Err(JobError::Internal(e.to_string())),
        }
    }
}

/// Records a stopped job: cancelled on request, interrupted (to resume later) on shutdown.
fn stopped(inner: &Inner, job: &ActiveJob) -> Result<(), JobError> {
    if job.stop_reason.load(Ordering::SeqCst) == STOP_CANCEL {
        inner.runtime.block_on(inner.mark_cancelled(job))
    } else {
        inner.runtime.block_on(inner.mark_interrupted(job))
    }
}

/// Publishes in-memory progress: iterations, throughput, ETA and the best per-path strategy.
fn publish_progress(job: &ActiveJob, moments: &Moments, next: u64, start: u64, started: Instant, light_paths: u64) {
    let elapsed = started.elapsed().as_secs_f64();
    let per_second = (next - start) as f64 / elapsed.max(1e-9);
    let total = job.total.load(Ordering::SeqCst);
    let best = best_strategy(&path_rows(moments));
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

/// A checkpoint of `moments`: their bytes and checksum, and the result document computed from
/// them with the job's solver options.
pub(crate) fn checkpoint_of(moments: &Moments, job: &ValidJob, reference: f64) -> Result<Checkpoint, JobError> {
    let report = build_report(moments, &job.config.cells, &job.spec.solver, reference);
    let best = best_strategy(&report.noise_table);
    let bytes = serde_json::to_vec(moments).map_err(|e| JobError::Internal(e.to_string()))?;
    let history: Vec<StrategyPoint> = report
        .noise_table
        .iter()
        .map(|r| StrategyPoint { strategy: r.strategy.clone(), luminance: r.luminance, rms_percent: r.rms_percent })
        .collect();
    let internal = |e: serde_json::Error| JobError::Internal(e.to_string());
    Ok(Checkpoint {
        iterations_done: moments.iterations(),
        checksum: sha256_hex(&bytes),
        moments: bytes,
        result: serde_json::to_string(&report).map_err(internal)?,
        best: best.as_ref().and_then(|b| serde_json::to_string(b).ok()),
        history: serde_json::to_string(&history).map_err(internal)?,
    })
}

/// Writes a checkpoint (retrying transient database errors) and publishes it.
fn write_checkpoint(inner: &Inner, job: &ActiveJob, moments: &Moments, reference: f64) -> Result<(), JobError> {
    let started = Instant::now();
    let checkpoint = checkpoint_of(moments, &job.job, reference)?;
    let best = checkpoint.best.as_deref().and_then(|b| serde_json::from_str::<super::resource::BestStrategy>(b).ok());
    let mut attempt = 0;
    loop {
        attempt += 1;
        let now = now_ms();
        match inner.runtime.block_on(inner.store.write_checkpoint(job.id, &checkpoint, now)) {
            Ok(()) => {
                inner.metrics.observe_checkpoint(started.elapsed());
                job.view.send_modify(|r| {
                    r.progress.iterations_checkpointed = checkpoint.iterations_done;
                    r.progress.iterations_done = r.progress.iterations_done.max(checkpoint.iterations_done);
                    r.progress.best = best.clone();
                    r.updated_at = rfc3339(now);
                });
                tracing::debug!(
                    job = job.id,
                    iterations = checkpoint.iterations_done,
                    seconds = started.elapsed().as_secs_f64(),
                    "checkpoint written"
                );
                return Ok(());
            }
            Err(e) if e.is_transient() && attempt < WRITE_ATTEMPTS => {
                tracing::warn!(job = job.id, attempt, error = %e, "checkpoint write failed, retrying");
                std::thread::sleep(Duration::from_millis(100 << attempt));
            }
            Err(e) => return Err(e.into()),
        }
    }
}
