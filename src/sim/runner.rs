//! Runs a range of iterations on the current rayon pool and adds them to a [`Moments`] value.
//!
//! Work is split into (iteration, chunk) items so that even a single huge iteration keeps every
//! core busy. Items run in any order on any thread, but each draws from its own stream
//! (seed, iteration, chunk) and the results are reduced per iteration in chunk order and added to
//! the moments in iteration order — so the moments are bit-identical for any thread count. (They
//! would be even without the ordering, as the moments' sums are exact; the per-iteration floating
//! sums are what the ordering protects.) The restricted engine's iterations are one item each and
//! take tens of microseconds, so there the workers also add them to moments of their own, which
//! are merged — adding them one by one on the calling thread would be the serial bottleneck.
//!
//! Iterations are processed in batches; between batches the caller sees the moments (for progress
//! and checkpoints) and may end the run there, and cancellation is checked before every chunk (and,
//! inside a restricted iteration, every 1,024 candidates). A cancelled batch is dropped whole, so the
//! moments only ever hold complete iterations.

use std::ops::{ControlFlow, Range};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::sim::engines::brute::trace_chunk;
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::restricted::{RestrictedPlan, RestrictedScratch, trace_restricted};
use crate::sim::engines::tally::{ChunkScratch, ChunkTally, IterationTally};
use crate::sim::model::config::{Engine, SimConfig};
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
fn batch_len(config: &SimConfig, threads: usize) -> u64 {
    if let Engine::Restricted(_) = config.engine {
        // Tens of microseconds per iteration: batches of 1024 still report many times a second
        // (about 30 ms each on two cores), and each batch's pieces cost a fresh moments value and
        // an exact merge of its K folds — with K = 10 at 256 iterations a batch that overhead was
        // a third of the run (docs/results.md §6).
        return 1024;
    }
    let chunks = config.chunks().max(1);
    let wanted = (4 * threads as u64).div_ceil(chunks);
    // Small iterations: batch more of them so per-batch overhead stays negligible.
    let light_per_batch_floor = (1u64 << 20).div_ceil(config.light_paths);
    let memory_cap = (MAX_BATCH_CAMERAS / config.camera_paths.max(1)).max(1);
    wanted.max(light_per_batch_floor).clamp(1, 256).min(memory_cap)
}

/// Fewest iterations of a restricted batch one rayon piece runs: every piece costs a fresh moments
/// value and an exact merge of its K folds (≈ 6·10⁴ sums at the paper's grid with the stacked
/// columns), so a batch of 1024 is cut into at most four pieces — enough to balance two or four
/// workers, whose iterations cost alike.
const RESTRICTED_PIECE: usize = 256;

/// Runs iterations `range` of `seed`, adding each to `moments` in index order and calling
/// `on_batch(&moments, next_iteration)` after every batch; `ControlFlow::Break` ends the run after
/// that batch. Returns the next iteration to run (`range.end` when all ran).
pub fn run_iterations(
    config: &SimConfig,
    seed: u64,
    range: Range<u64>,
    moments: &mut Moments,
    cancel: &AtomicBool,
    mut on_batch: impl FnMut(&Moments, u64) -> ControlFlow<()>,
) -> Result<u64, RunError> {
    let per_batch = batch_len(config, rayon::current_num_threads());
    let plan = match config.engine {
        Engine::Brute => None,
        Engine::Restricted(proposals) => Some(RestrictedPlan::new(config, proposals)),
    };
    let mut start = range.start;
    while start < range.end {
        if cancel.load(Ordering::Relaxed) {
            return Err(RunError::Cancelled);
        }
        let end = (start + per_batch).min(range.end);
        match &plan {
            None => {
                let tallies = brute_batch(config, seed, start..end, cancel).ok_or(RunError::Cancelled)?;
                for tally in &tallies {
                    moments.add_iteration(seed, tally)?;
                }
            }
            Some(plan) => {
                let batch = restricted_batch(config, plan, seed, start..end, moments, cancel)?;
                moments.absorb(&batch)?;
            }
        }
        start = end;
        if on_batch(moments, end).is_break() {
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
/// iteration allocates nothing once the buffers have grown.
struct RestrictedWorker {
    scratch: ChunkScratch,
    buffers: RestrictedScratch,
    cameras: CameraSet,
    chunk: ChunkTally,
    tally: IterationTally,
}

/// The restricted engine's iterations `batch` as moments of their own. An iteration takes tens of
/// microseconds, so adding it to the moments (exact sums) would be a serial bottleneck: each
/// worker adds its iterations to moments of their own and those are merged. The sums are exact, so
/// the grouping does not change a bit. `Cancelled` if cancelled.
fn restricted_batch(
    config: &SimConfig,
    plan: &RestrictedPlan,
    seed: u64,
    batch: Range<u64>,
    like: &Moments,
    cancel: &AtomicBool,
) -> Result<Moments, RunError> {
    let (k, norm) = (config.cells.len(), tally_norm(config));
    let worker = || RestrictedWorker {
        scratch: ChunkScratch::for_config(config),
        buffers: RestrictedScratch::default(),
        cameras: CameraSet::default(),
        chunk: ChunkTally::default(),
        tally: IterationTally::from_chunks(0, k, norm, []),
    };
    // Indexed (usize) so that the pieces can be kept long: each split costs a fresh moments value
    // and a fresh worker.
    (0..(batch.end - batch.start) as usize)
        .into_par_iter()
        .with_min_len(RESTRICTED_PIECE)
        .try_fold(
            || (like.empty_like(), worker()),
            |(mut moments, mut w), i| {
                let s = batch.start + i as u64;
                if cancel.load(Ordering::Relaxed) {
                    return Err(RunError::Cancelled);
                }
                w.cameras.regenerate(config, seed, s);
                let RestrictedWorker { scratch, buffers, cameras, chunk, tally } = &mut w;
                if !trace_restricted(config, plan, cameras, seed, s, scratch, buffers, cancel, chunk) {
                    return Err(RunError::Cancelled);
                }
                tally.set_from_chunks(s, k, norm, std::iter::once(&*chunk));
                moments.add_iteration(seed, tally)?;
                Ok((moments, w))
            },
        )
        .map(|piece| piece.map(|(moments, _)| moments))
        .try_reduce(
            || like.empty_like(),
            |mut a, b| {
                a.absorb(&b)?;
                Ok(a)
            },
        )
}

/// Runs iterations `range` of `seed` into fresh moments.
pub fn run(config: &SimConfig, seed: u64, range: Range<u64>) -> Moments {
    let mut moments = Moments::new(config);
    let never = AtomicBool::new(false);
    run_iterations(config, seed, range, &mut moments, &never, |_, _| ControlFlow::Continue(()))
        .expect("a fresh moments value cannot overlap and the run is never cancelled");
    moments
}
