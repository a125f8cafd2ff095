//! Runs a range of iterations on the current rayon pool and adds them to a [`Moments`] value.
//!
//! Work is split into (iteration, chunk) items so that even a single huge iteration keeps every
//! core busy. Items run in any order on any thread, but each draws from its own stream
//! (seed, iteration, chunk) and the results are reduced per iteration in chunk order and added to
//! the moments in iteration order — so the moments are bit-identical for any thread count. (They
//! would be even without the ordering, as the moments' sums are exact; the per-iteration floating
//! sums are what the ordering protects.)
//!
//! Iterations are processed in batches; between batches the caller sees the moments (for progress
//! and checkpoints) and may end the run there, and cancellation is checked before every chunk. A
//! cancelled batch is dropped whole, so the moments only ever hold complete iterations.

use std::ops::{ControlFlow, Range};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::camera::CameraSet;
use super::config::{Engine, SimConfig};
use super::light::trace_chunk;
use super::moments::{MergeError, Moments};
use super::restricted::{RestrictedPlan, RestrictedScratch, trace_restricted};
use super::tally::{ChunkScratch, ChunkTally, IterationTally};

/// Why a run stopped early.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RunError {
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Moments(#[from] MergeError),
}

/// Iterations per batch: enough (iteration, chunk) items to balance `threads` workers, few enough
/// to report progress and honour cancellation promptly.
fn batch_len(config: &SimConfig, threads: usize) -> u64 {
    if let Engine::Restricted(_) = config.engine {
        // Tens of microseconds per iteration: batches of 256 still report many times a second.
        return 256;
    }
    let chunks = config.chunks().max(1);
    let wanted = (4 * threads as u64).div_ceil(chunks);
    // Small iterations: batch more of them so per-batch overhead stays negligible.
    let light_per_batch_floor = (1u64 << 20).div_ceil(config.light_paths);
    wanted.max(light_per_batch_floor).clamp(1, 256)
}

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
    let k = config.cells.len();
    let chunks = config.chunks();
    let norm = 1.0 / (config.light_paths as f64 * config.camera_paths as f64);
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
        let cameras: Vec<CameraSet> =
            (start..end).into_par_iter().map(|s| CameraSet::generate(config, seed, s)).collect();
        let items = (end - start) * chunks;
        let tallies: Vec<Option<ChunkTally>> = (0..items)
            .into_par_iter()
            .map_init(
                || (ChunkScratch::new(k), RestrictedScratch::default()),
                |(scratch, buffers), item| {
                    if cancel.load(Ordering::Relaxed) {
                        return None;
                    }
                    let (i, c) = (item / chunks, item % chunks);
                    let cameras = &cameras[i as usize];
                    Some(match &plan {
                        None => trace_chunk(config, cameras, seed, start + i, c, scratch),
                        Some(plan) => trace_restricted(config, plan, cameras, seed, start + i, scratch, buffers),
                    })
                },
            )
            .collect();
        if tallies.iter().any(Option::is_none) {
            return Err(RunError::Cancelled);
        }
        for (i, per_iteration) in tallies.chunks(chunks as usize).enumerate() {
            let tally = IterationTally::from_chunks(start + i as u64, k, norm, per_iteration.iter().flatten());
            moments.add_iteration(seed, &tally)?;
        }
        start = end;
        if on_batch(moments, end).is_break() {
            break;
        }
    }
    Ok(start)
}

/// Runs iterations `range` of `seed` into fresh moments.
pub fn run(config: &SimConfig, seed: u64, range: Range<u64>) -> Moments {
    let mut moments = Moments::new(config);
    let never = AtomicBool::new(false);
    run_iterations(config, seed, range, &mut moments, &never, |_, _| ControlFlow::Continue(()))
        .expect("a fresh moments value cannot overlap and the run is never cancelled");
    moments
}
