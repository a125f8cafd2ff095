//! Runs a range of iterations on the current rayon pool and adds them to a [`Moments`] value.
//!
//! Work is split into (iteration, chunk) items so that even a single huge iteration keeps every
//! core busy. Items run in any order on any thread, but each draws from its own stream
//! (seed, iteration, chunk) and the results are reduced per iteration in chunk order — so the
//! moments are bit-identical for any thread count. (The moments' sums are exact, so the order in
//! which iterations are added changes nothing; the per-iteration floating sums are what the
//! ordering protects.)
//!
//! The restricted engine's iterations are one item each and take microseconds, so there every
//! worker claims iterations a few at a time and adds them to fast exact sums of its own
//! ([`MomentsAccumulator`]), kept for the whole run and handed to the moments only when someone
//! looks at them ([`BatchMoments::moments`]) and at the end: adding each iteration, or each batch,
//! to the moments' exact sums was the serial part that kept two threads from scaling (issue 26).
//!
//! Iterations are processed in batches; between batches the caller sees how far the run came and,
//! on demand, the moments (for progress and checkpoints), and may end the run there.
//! Cancellation is checked before every chunk (and, inside a restricted iteration, every 1,024
//! candidates). A cancelled run drops what was not yet handed over, so the moments only ever hold
//! complete iterations, a contiguous range of them from this run.

use std::ops::{ControlFlow, Range};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use rayon::prelude::*;

use crate::sim::engines::brute::trace_chunk;
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::restricted::{RestrictedPlan, RestrictedScratch, trace_restricted};
use crate::sim::engines::tally::{ChunkScratch, ChunkTally, IterationTally};
use crate::sim::model::config::{Engine, SimConfig};
use crate::sim::stats::accumulator::{MomentsAccumulator, hand_over};
use crate::sim::stats::moments::{MergeError, Moments};

/// Why a run stopped early.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RunError {
    /// The cancel flag was raised; the moments hold every batch finished before it.
    #[error("cancelled")]
    Cancelled,
    /// An iteration could not be added to the moments: it was already counted, or a sum would
    /// overflow.
    #[error(transparent)]
    Moments(#[from] MergeError),
}

/// Most camera paths a brute-force batch holds at once (their sets are generated up front):
/// N_B = 10⁶ with a batch of 256 iterations would otherwise hold 25 GB.
const MAX_BATCH_CAMERAS: u64 = 1 << 20;

/// Iterations per batch: enough (iteration, chunk) items to balance `threads` workers, few enough
/// to report progress and honour cancellation promptly, and few enough camera paths in memory.
/// (The server checkpoints no more often than this: a checkpoint costs a full report.)
pub fn batch_len(config: &SimConfig, threads: usize) -> u64 {
    if let Engine::Restricted(_) = config.engine {
        // Microseconds per iteration: batches of 4096 still report several times a second, and
        // cost nothing of their own (the workers' sums live across batches).
        return 4096;
    }
    let chunks = config.chunks().max(1);
    let wanted = (4 * threads as u64).div_ceil(chunks);
    // Small iterations: batch more of them so per-batch overhead stays negligible.
    let light_per_batch_floor = (1u64 << 20).div_ceil(config.light_paths);
    let memory_cap = (MAX_BATCH_CAMERAS / config.camera_paths.max(1)).max(1);
    wanted.max(light_per_batch_floor).clamp(1, 256).min(memory_cap)
}

/// Iterations a restricted worker claims at a time, all of one fold: a few microseconds each, so
/// that claiming (one atomic addition) costs nothing beside them while the workers still share a
/// batch's end.
const RESTRICTED_CLAIM: u64 = 16;

/// What `on_batch` sees of the moments after a batch: they are brought up to date only when asked
/// for, as that costs an exact addition per touched sum.
pub trait BatchMoments {
    /// The moments with every iteration run so far.
    fn moments(&mut self) -> &Moments;
}

/// Moments that are always up to date (the brute force's, or those an executor reads from files).
impl BatchMoments for &Moments {
    fn moments(&mut self) -> &Moments {
        self
    }
}

/// Runs iterations `range` of `seed`, adding each to `moments` and calling
/// `on_batch(&mut view, next_iteration)` after every batch (`view.moments()` gives the moments
/// with every iteration before `next_iteration`); `ControlFlow::Break` ends the run after that
/// batch. Returns the next iteration to run (`range.end` when all ran).
pub fn run_iterations(
    config: &SimConfig,
    seed: u64,
    range: Range<u64>,
    moments: &mut Moments,
    cancel: &AtomicBool,
    on_batch: impl FnMut(&mut dyn BatchMoments, u64) -> ControlFlow<()>,
) -> Result<u64, RunError> {
    run_iterations_within(config, seed, range, moments, cancel, u64::MAX, on_batch)
}

/// [`run_iterations`] with batches of at most `max_batch` iterations, so that `on_batch` can act
/// every `max_batch` iterations: the server's checkpoints (and so a job's history) come at its
/// `--checkpoint-iterations` even on the restricted engine, whose own batches are 4,096 long.
pub fn run_iterations_within(
    config: &SimConfig,
    seed: u64,
    range: Range<u64>,
    moments: &mut Moments,
    cancel: &AtomicBool,
    max_batch: u64,
    mut on_batch: impl FnMut(&mut dyn BatchMoments, u64) -> ControlFlow<()>,
) -> Result<u64, RunError> {
    let per_batch = batch_len(config, rayon::current_num_threads()).min(max_batch.max(1));
    if let Engine::Restricted(proposals) = config.engine {
        let plan = RestrictedPlan::new(config, proposals);
        let run = RestrictedRun { config, plan: &plan, seed, cancel };
        return run.iterations(range, per_batch, moments, on_batch);
    }
    let mut start = range.start;
    while start < range.end {
        if cancel.load(Ordering::Relaxed) {
            return Err(RunError::Cancelled);
        }
        let end = (start + per_batch).min(range.end);
        let tallies = brute_batch(config, seed, start..end, cancel).ok_or(RunError::Cancelled)?;
        for tally in &tallies {
            moments.add_iteration(seed, tally)?;
        }
        start = end;
        if on_batch(&mut &*moments, end).is_break() {
            break;
        }
    }
    Ok(start)
}

/// The 1/(N_F·N_B) that turns a tally's sums into the estimator's per-pixel values.
fn tally_norm(config: &SimConfig) -> f64 {
    1.0 / (config.light_paths as f64 * config.camera_paths as f64)
}

/// The brute force's iterations `batch`: (iteration, chunk) items in parallel, then each
/// iteration's chunks reduced in chunk order. None if cancelled.
fn brute_batch(config: &SimConfig, seed: u64, batch: Range<u64>, cancel: &AtomicBool) -> Option<Vec<IterationTally>> {
    let (k, chunks, norm) = (config.cells.len(), config.chunks(), tally_norm(config));
    let cameras: Vec<CameraSet> = batch.clone().into_par_iter().map(|s| CameraSet::generate(config, seed, s)).collect();
    let items = (batch.end - batch.start) * chunks;
    let tallies: Vec<Option<ChunkTally>> = (0..items)
        .into_par_iter()
        .map_init(
            || ChunkScratch::for_config(config),
            |scratch, item| {
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let (i, c) = (item / chunks, item % chunks);
                Some(trace_chunk(config, &cameras[i as usize], seed, batch.start + i, c, scratch))
            },
        )
        .collect();
    if tallies.iter().any(Option::is_none) {
        return None;
    }
    let per_iteration = tallies.chunks(chunks as usize).enumerate();
    Some(
        per_iteration
            .map(|(i, chunks)| IterationTally::from_chunks(batch.start + i as u64, k, norm, chunks.iter().flatten()))
            .collect(),
    )
}

/// What a worker of the restricted engine reuses from iteration to iteration: with these, an
/// iteration allocates nothing once the buffers have grown. Aligned to two cache lines, so that
/// neighbouring workers in their vector never write to one line (false sharing).
#[repr(align(128))]
struct RestrictedWorker {
    scratch: ChunkScratch,
    buffers: RestrictedScratch,
    cameras: CameraSet,
    chunk: ChunkTally,
    tally: IterationTally,
}

/// One call's restricted run: what every worker reads.
struct RestrictedRun<'a> {
    config: &'a SimConfig,
    plan: &'a RestrictedPlan,
    seed: u64,
    cancel: &'a AtomicBool,
}

impl RestrictedRun<'_> {
    /// [`run_iterations`] for the restricted engine: one worker and one [`MomentsAccumulator`]
    /// per thread for the whole call, handed over to `moments` when `on_batch` asks and at the
    /// end.
    fn iterations(
        &self,
        range: Range<u64>,
        per_batch: u64,
        moments: &mut Moments,
        mut on_batch: impl FnMut(&mut dyn BatchMoments, u64) -> ControlFlow<()>,
    ) -> Result<u64, RunError> {
        let threads = rayon::current_num_threads();
        let (k, norm) = (self.config.cells.len(), tally_norm(self.config));
        let mut workers: Vec<RestrictedWorker> = (0..threads)
            .map(|_| RestrictedWorker {
                scratch: ChunkScratch::for_config(self.config),
                buffers: RestrictedScratch::default(),
                cameras: CameraSet::default(),
                chunk: ChunkTally::default(),
                tally: IterationTally::from_chunks(0, k, norm, []),
            })
            .collect();
        let mut sums = vec![MomentsAccumulator::like(moments); threads];
        let (mut start, mut handed) = (range.start, range.start);
        while start < range.end {
            let end = (start + per_batch).min(range.end);
            if let Err(e) = self.batch(start..end, &mut workers, &mut sums) {
                // What was not handed over is dropped whole: the moments keep a contiguous range.
                sums.iter_mut().for_each(MomentsAccumulator::clear);
                return Err(e);
            }
            start = end;
            let mut view =
                Pending { moments, sums: &mut sums, seed: self.seed, handed: &mut handed, upto: end, error: None };
            let flow = on_batch(&mut view, end);
            if let Some(e) = view.error {
                return Err(e.into());
            }
            if flow.is_break() {
                break;
            }
        }
        hand_over(&mut sums, moments, self.seed, handed..start)?;
        Ok(start)
    }

    /// Runs iterations `batch`: every worker claims [`RESTRICTED_CLAIM`] of them at a time and adds
    /// them to its own sums, until none is left.
    ///
    /// A claim is [`RESTRICTED_CLAIM`] iterations of one fold (s, s + K, s + 2K, …), and the claims
    /// go fold by fold: a worker's sums of one fold (~0.6 MB at the paper's grid) stay in its core's
    /// cache while it adds to them, where iterations in index order would walk all K folds' sums
    /// (~6 MB) and make the two cores contend for the shared cache (issue 26: the parallel
    /// efficiency).
    fn batch(
        &self,
        batch: Range<u64>,
        workers: &mut [RestrictedWorker],
        sums: &mut [MomentsAccumulator],
    ) -> Result<(), RunError> {
        let (config, k, norm) = (self.config, self.config.cells.len(), tally_norm(self.config));
        let folds = sums.first().map_or(1, MomentsAccumulator::fold_count) as u64;
        let per_fold = (batch.end - batch.start).div_ceil(folds).div_ceil(RESTRICTED_CLAIM);
        let next = AtomicU64::new(0);
        // Raised by a worker that fails, so that the others stop too.
        let failed = AtomicBool::new(false);
        workers.par_iter_mut().zip(sums.par_iter_mut()).try_for_each(|(w, acc)| {
            let result = (|| loop {
                let claim = next.fetch_add(1, Ordering::Relaxed);
                if claim >= folds * per_fold {
                    return Ok(());
                }
                // Claim → (fold f, its piece p): the first iteration of fold f in the batch, then
                // every K-th from piece p's start.
                let (f, p) = (claim / per_fold, claim % per_fold);
                let first = batch.start + (f + folds - batch.start % folds) % folds + folds * RESTRICTED_CLAIM * p;
                for s in (first..batch.end).step_by(folds as usize).take(RESTRICTED_CLAIM as usize) {
                    if self.cancel.load(Ordering::Relaxed) || failed.load(Ordering::Relaxed) {
                        return Err(RunError::Cancelled);
                    }
                    w.cameras.regenerate(config, self.seed, s);
                    let RestrictedWorker { scratch, buffers, cameras, chunk, tally } = w;
                    if !trace_restricted(config, self.plan, cameras, self.seed, s, scratch, buffers, self.cancel, chunk)
                    {
                        return Err(RunError::Cancelled);
                    }
                    tally.set_from_chunks(s, k, norm, std::iter::once(&*chunk));
                    acc.add_iteration(tally)?;
                }
            })();
            if result.is_err() {
                failed.store(true, Ordering::Relaxed);
            }
            result
        })
    }
}

/// The view `on_batch` gets of a restricted run: the moments, brought up to date on demand.
struct Pending<'a> {
    moments: &'a mut Moments,
    sums: &'a mut [MomentsAccumulator],
    seed: u64,
    /// The moments hold this run's iterations before `handed`.
    handed: &'a mut u64,
    /// Every iteration before `upto` ran.
    upto: u64,
    /// A hand-over that was refused (the run ends with it).
    error: Option<MergeError>,
}

impl BatchMoments for Pending<'_> {
    fn moments(&mut self) -> &Moments {
        if *self.handed < self.upto && self.error.is_none() {
            match hand_over(self.sums, self.moments, self.seed, *self.handed..self.upto) {
                Ok(()) => *self.handed = self.upto,
                Err(e) => self.error = Some(e),
            }
        }
        self.moments
    }
}

/// Runs iterations `range` of `seed` into fresh moments.
pub fn run(config: &SimConfig, seed: u64, range: Range<u64>) -> Moments {
    let mut moments = Moments::new(config);
    let never = AtomicBool::new(false);
    run_iterations(config, seed, range, &mut moments, &never, |_, _| ControlFlow::Continue(()))
        .expect("a fresh moments value cannot overlap and the run is never cancelled");
    moments
}
