//! The runner's moments while they are being summed: one [`MomentsAccumulator`] per worker, fast
//! exact sums ([`WindowSum`]) that a worker adds its iterations to for as long as the run goes, and
//! that are handed to the [`Moments`] only when someone needs them (a checkpoint, a progress view,
//! the end of the run).
//!
//! [`ExactSum`]: crate::sim::math::exact_sum::ExactSum
//!
//! The moments' own [`ExactSum`]s cost a walk over ~20 parts per addition, and adding one moments
//! value to another costs that for each of their ~6·10⁴ sums — per rayon piece, it was a fifth of
//! the restricted engine's time and capped its parallel speed-up (issue 26). Here an iteration
//! costs three integer additions per term, and the hand-over one exact addition per *touched* sum
//! per worker. The sums are exact either way, so the result is the same to the last bit, whatever
//! worker summed which iteration and however often they were handed over.

use std::ops::Range;

use super::admission::check_iteration;
use super::coverage::Coverage;
use super::moments::{Counters, FoldMoments, MergeError, Moments, add_tally_counters, counters_fit};
use super::terms::{SumIndex, TermBuffers, for_each_term};
use crate::sim::engines::layout::Layout;
use crate::sim::engines::tally::IterationTally;
use crate::sim::math::window_sum::WindowSum;

/// One fold's sums and counters, as [`super::moments::FoldMoments`] has them.
#[derive(Debug, Clone)]
struct FoldAccumulator {
    iterations: u64,
    /// In [`super::moments::FoldMoments::sums`] order.
    sums: Vec<WindowSum>,
    /// The sums added to since the last hand-over (each once), so that a hand-over costs what was
    /// touched, not the whole fold.
    touched: Vec<u32>,
    merges: [u64; 3],
    merges_sq: [u128; 3],
    cell_counts: Vec<u64>,
}

/// One worker's sums of the iterations it ran since the last hand-over. Aligned to two cache lines:
/// the workers' accumulators sit side by side in a vector, and each writes its own buffers' headers
/// every iteration.
#[derive(Debug, Clone)]
#[repr(align(128))]
pub struct MomentsAccumulator {
    layout: Layout,
    index: SumIndex,
    folds: Vec<FoldAccumulator>,
    buffers: TermBuffers,
    /// The sums at each smaller radius of the moments (`Moments::radii`), in their order.
    radii: Vec<MomentsAccumulator>,
}

impl MomentsAccumulator {
    /// Empty sums shaped like `moments` (its format, folds and noise components).
    pub fn like(moments: &Moments) -> Self {
        let layout = moments.layout();
        let index = SumIndex::new(layout, moments.has_components());
        let fold = FoldAccumulator {
            iterations: 0,
            sums: vec![WindowSum::new(); index.len()],
            touched: Vec::new(),
            merges: [0; 3],
            merges_sq: [0; 3],
            cell_counts: vec![0; 3 * layout.cells],
        };
        Self {
            layout,
            index,
            folds: vec![fold; moments.fold_count()],
            buffers: TermBuffers::default(),
            radii: moments.radii.iter().map(Self::like).collect(),
        }
    }

    /// K, the folds (iteration s goes to fold s mod K).
    pub fn fold_count(&self) -> usize {
        self.folds.len()
    }

    /// Iterations summed since the last hand-over.
    pub fn iterations(&self) -> u64 {
        self.folds.iter().map(|f| f.iterations).sum()
    }

    /// Adds iteration `tally.iteration` to its fold (s mod K), with the checks of
    /// [`Moments::add_iteration`]: a value that could overflow a sum, or a counter that would
    /// overflow, is an error and changes nothing.
    pub fn add_iteration(&mut self, tally: &IterationTally) -> Result<(), MergeError> {
        check_iteration(tally, self.radii.len())?;
        self.add_own(tally)?;
        for (sub, sub_tally) in self.radii.iter_mut().zip(&tally.radii) {
            sub.add_own(sub_tally)?;
        }
        Ok(())
    }

    /// [`MomentsAccumulator::add_iteration`] without the radii, its values checked.
    fn add_own(&mut self, tally: &IterationTally) -> Result<(), MergeError> {
        let k = self.folds.len() as u64;
        let fold = &mut self.folds[(tally.iteration % k) as usize];
        let (merges, merges_sq) = add_tally_counters(fold.merges, fold.merges_sq, &fold.cell_counts, tally)?;
        let FoldAccumulator { sums, touched, .. } = fold;
        for_each_term(self.layout, &self.index, tally, &mut self.buffers, |i, v| {
            if v != 0.0 {
                let sum = &mut sums[i];
                if sum.is_untouched() {
                    touched.push(i as u32);
                }
                sum.add(v);
            }
        });
        fold.merges = merges;
        fold.merges_sq = merges_sq;
        for (acc, &c) in fold.cell_counts.iter_mut().zip(&tally.cell_counts) {
            *acc += c;
        }
        fold.iterations += 1;
        Ok(())
    }

    /// Forgets everything summed since the last hand-over (a cancelled run's partial work).
    pub fn clear(&mut self) {
        for fold in &mut self.folds {
            fold.clear();
        }
        self.radii.iter_mut().for_each(Self::clear);
    }
}

impl FoldAccumulator {
    fn clear(&mut self) {
        for &i in &self.touched {
            self.sums[i as usize].clear();
        }
        self.touched.clear();
        self.iterations = 0;
        self.merges = [0; 3];
        self.merges_sq = [0; 3];
        self.cell_counts.fill(0);
    }
}

/// Adds what `workers` summed — together, exactly iterations `range` of `seed` — to `moments`
/// (and each radius's to the moments of that radius), and empties them. Refused with nothing
/// changed if `moments` already holds one of those iterations or a counter would overflow. The
/// sums cannot: every value added is at most 10²⁸⁰ (fourth powers of tallies bounded by
/// `MAX_TALLY_VALUE`), so no sum over at most 2⁶² iterations comes near the 2¹⁰⁰⁰ a moments value
/// may hold.
pub fn hand_over(
    workers: &mut [MomentsAccumulator],
    moments: &mut Moments,
    seed: u64,
    range: Range<u64>,
) -> Result<(), MergeError> {
    if range.is_empty() {
        return Ok(());
    }
    debug_assert_eq!(workers.iter().map(MomentsAccumulator::iterations).sum::<u64>(), range.end - range.start);
    let mut added = Coverage::new();
    added.insert(seed, range.start, range.end);
    let overlaps = moments.coverage.overlaps(&added);
    if !overlaps.is_empty() {
        return Err(MergeError::Overlap(overlaps));
    }
    // Every check before any change: the run's counters, then each radius's.
    check_counters(workers.iter(), moments)?;
    for (r, sub) in moments.radii.iter().enumerate() {
        check_counters(workers.iter().map(|w| &w.radii[r]), sub)?;
    }
    add_to(workers.iter_mut(), moments);
    for (r, sub) in moments.radii.iter_mut().enumerate() {
        add_to(workers.iter_mut().map(|w| &mut w.radii[r]), sub);
        sub.coverage.insert(seed, range.start, range.end);
    }
    moments.coverage.insert(seed, range.start, range.end);
    Ok(())
}

/// Adds the workers' sums and counters to `moments`' folds (checked beforehand) and empties them.
fn add_to<'a>(workers: impl Iterator<Item = &'a mut MomentsAccumulator>, moments: &mut Moments) {
    let index = SumIndex::new(moments.layout(), moments.has_components());
    for worker in workers {
        for (target, fold) in moments.folds.iter_mut().zip(&mut worker.folds) {
            for &i in &fold.touched {
                fold.sums[i as usize].add_to(target.sum_mut(&index, i as usize));
            }
            target.iterations += fold.iterations;
            for m in 0..3 {
                target.merges[m] += fold.merges[m];
                target.merges_sq[m] += fold.merges_sq[m];
            }
            for (a, b) in target.cell_counts.iter_mut().zip(&fold.cell_counts) {
                *a += b;
            }
            fold.clear();
        }
    }
}

/// Whether every counter of `moments` plus `workers`' fits its type, pooled over the folds (what
/// the noise table adds), and so per fold.
fn check_counters<'a>(
    workers: impl Iterator<Item = &'a MomentsAccumulator>,
    moments: &Moments,
) -> Result<(), MergeError> {
    let worker_folds = workers.flat_map(|w| &w.folds).map(|f| Counters {
        merges: &f.merges,
        merges_sq: &f.merges_sq,
        cell_counts: &f.cell_counts,
    });
    let folds: Vec<Counters<'_>> = moments.folds.iter().map(FoldMoments::counters).chain(worker_folds).collect();
    if counters_fit(&folds) { Ok(()) } else { Err(MergeError::Overflow("pooled counts".to_string())) }
}

#[cfg(test)]
mod tests;
