//! The additive sufficient statistics of a run: sums over iterations, exact and mergeable.
//!
//! Per iteration s, model.md's vector Y_s = (A⁽⁰⁾_s, A⁽¹⁾_s, B_s) of dimension n = 2K + 1 carries
//! everything the cell-wise weights need: C_s(W) = ⟨A_s|W⟩ + B_s. The moments hold ΣY and ΣYYᵀ
//! (which contain ΣA, ΣB, ΣB², ΣAAᵀ and ΣBA), the power sums Σ C_s^k, k = 1…4, of every per-path
//! strategy (for their noise and the standard error of their RMS), merge counts, and per-cell event
//! counts.
//!
//! Sums are kept separately for the K *folds* of iterations (iteration s in fold s mod K), so that
//! the optimal weights can be fitted on K − 1 folds and evaluated on the remaining one
//! (cross-fitting, `solve::noise`) without storing any iteration. Folding by the index, not by the
//! order of arrival, keeps shards and merges exact: a shard's iterations land in the same folds as
//! they would in one uninterrupted run.
//!
//! Every sum is an [`ExactSum`], so merging is addition in any order and grouping with a
//! bit-identical result; the [`Coverage`] records which (seed, iteration) pairs are included so that
//! a merge can refuse to count an iteration twice, and the fingerprint refuses moments of another
//! configuration.
//!
//! # Moments read from outside
//!
//! Documents and checkpoints are parsed straight into these types with every list bounded by what
//! the largest grid needs ([`crate::sim::model::cells::MAX_CELLS`]), so a hostile body cannot make the
//! parser allocate beyond a few times its size. [`check_well_formed`](super::well_formed::check_well_formed) then checks what a
//! parser cannot: the shapes, the coverage, and that the sums agree with their counts (no sum over
//! zero iterations, no negative sum of squares, events per cell adding up to events per plane).
//! Merges add counters with checked arithmetic and check, before changing anything, that no exact
//! sum can overflow: a refused merge leaves the target as it was.

use serde::{Deserialize, Serialize};

use super::admission::{check_iteration, check_representable};
use super::bounded::bounded;

use super::components::ComponentSums;
use super::coverage::{Coverage, MAX_ITERATION_INDEX, Overlap};
use super::terms::{SumIndex, TermBuffers, for_each_term};
use crate::sim::engines::layout::{Layout, MAX_DIMENSION, MAX_PACKED};
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::engines::tally::IterationTally;
use crate::sim::math::exact_sum::{ExactSum, MAX_MAGNITUDE};
use crate::sim::model::cells::MAX_CELLS;
pub use crate::sim::model::config::packed_index;
use crate::sim::model::config::{MAX_FOLDS, MAX_RADII, MIN_FOLDS, MOMENTS_FORMAT_VERSION, SimConfig, packed_len};

pub use super::admission::MAX_TALLY_VALUE;

/// Longest per-slot list (three planes per cell).
const MAX_SLOTS: usize = 3 * MAX_CELLS;

/// Sums over the iterations of one fold.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FoldMoments {
    /// Number of iterations M_f.
    pub iterations: u64,
    /// ΣY (length n).
    #[serde(deserialize_with = "bounded::<_, _, MAX_DIMENSION>")]
    pub sum_y: Vec<ExactSum>,
    /// ΣYYᵀ, upper triangle packed row by row: (0,0), (0,1), …, (0,n−1), (1,1), …
    #[serde(deserialize_with = "bounded::<_, _, MAX_PACKED>")]
    pub sum_yy: Vec<ExactSum>,
    /// Per path strategy the format keeps (a prefix of [`PathStrategy::ALL`], `engines::layout`):
    /// Σ C_s, Σ C_s², Σ C_s³, Σ C_s⁴.
    #[serde(deserialize_with = "bounded::<_, _, { PathStrategy::COUNT }>")]
    pub strategies: Vec<[ExactSum; 4]>,
    /// Merge events per plane, summed over iterations.
    pub merges: [u64; 3],
    /// Σ (merge events per plane)², for the spread of the counts.
    pub merges_sq: [u128; 3],
    /// Merge events per slot m·K + α (the samples behind each cell's weights).
    #[serde(deserialize_with = "bounded::<_, _, MAX_SLOTS>")]
    pub cell_counts: Vec<u64>,
    /// The noise components' sums, when the configuration keeps them (`noise_components`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub components: Option<ComponentSums>,
}

impl FoldMoments {
    fn empty(layout: Layout, components: bool) -> Self {
        let n = layout.dimension();
        Self {
            iterations: 0,
            sum_y: vec![ExactSum::new(); n],
            sum_yy: vec![ExactSum::new(); packed_len(n)],
            strategies: vec![Default::default(); layout.strategies().len()],
            merges: [0; 3],
            merges_sq: [0; 3],
            cell_counts: vec![0; 3 * layout.cells],
            components: components.then(|| ComponentSums::empty(layout)),
        }
    }

    fn add_iteration(&mut self, layout: Layout, tally: &IterationTally) -> Result<(), MergeError> {
        check_representable(tally)?;
        // Counters first, checked, so that an overflow leaves the fold unchanged.
        let (merges, merges_sq) = add_tally_counters(self.merges, self.merges_sq, &self.cell_counts, tally)?;
        let index = SumIndex::new(layout, self.components.is_some());
        let mut buffers = TermBuffers::default();
        for_each_term(layout, &index, tally, &mut buffers, |i, v| self.sum_mut(&index, i).add(v));
        self.merges = merges;
        self.merges_sq = merges_sq;
        for (acc, &c) in self.cell_counts.iter_mut().zip(&tally.cell_counts) {
            *acc += c;
        }
        self.iterations += 1;
        Ok(())
    }

    /// Sum `i` of [`FoldMoments::sums`], laid out by `index`.
    pub(super) fn sum_mut(&mut self, index: &SumIndex, i: usize) -> &mut ExactSum {
        let (n, packed, strategies) = (index.n, index.packed, index.strategies);
        if i < n {
            return &mut self.sum_y[i];
        }
        let i = i - n;
        if i < packed {
            return &mut self.sum_yy[i];
        }
        let i = i - packed;
        if i < 4 * strategies {
            return &mut self.strategies[i / 4][i % 4];
        }
        let components = self.components.as_mut().expect("component sums are indexed only when kept");
        let (i, packed) = (i - 4 * strategies, index.packed_components);
        match i / packed {
            0 => &mut components.light[i],
            1 => &mut components.camera[i - packed],
            2 => &mut components.cross[i - 2 * packed],
            _ => {
                let j = i - 3 * packed;
                &mut components.strategies[j / 3][j % 3]
            }
        }
    }

    /// The sums in one list, for checks that treat them alike.
    pub(super) fn sums(&self) -> impl Iterator<Item = &ExactSum> {
        self.sum_y
            .iter()
            .chain(&self.sum_yy)
            .chain(self.strategies.iter().flatten())
            .chain(self.components.iter().flat_map(ComponentSums::sums))
    }

    /// Checks, without changing anything, that [`FoldMoments::add`] of `other` cannot overflow:
    /// every counter fits its type and every pair of sums can be added exactly (see
    /// [`ExactSum::can_add`]).
    fn check_add(&self, other: &FoldMoments) -> Result<(), MergeError> {
        self.iterations.checked_add(other.iterations).ok_or_else(|| overflow("iteration count"))?;
        for m in 0..3 {
            self.merges[m].checked_add(other.merges[m]).ok_or_else(|| overflow("merge count"))?;
            self.merges_sq[m].checked_add(other.merges_sq[m]).ok_or_else(|| overflow("squared merge count"))?;
        }
        if self.cell_counts.iter().zip(&other.cell_counts).any(|(a, b)| a.checked_add(*b).is_none()) {
            return Err(overflow("cell event count"));
        }
        if !self.sums().zip(other.sums()).all(|(a, b)| a.can_add(b)) {
            return Err(overflow("exact sum"));
        }
        Ok(())
    }

    /// Adds `other` (checked beforehand with [`FoldMoments::check_add`]).
    fn add(&mut self, other: &FoldMoments) {
        self.iterations += other.iterations;
        for (a, b) in self.sum_y.iter_mut().zip(&other.sum_y) {
            a.add_sum(b);
        }
        for (a, b) in self.sum_yy.iter_mut().zip(&other.sum_yy) {
            a.add_sum(b);
        }
        for (a, b) in self.strategies.iter_mut().zip(&other.strategies) {
            for (x, y) in a.iter_mut().zip(b) {
                x.add_sum(y);
            }
        }
        for m in 0..3 {
            self.merges[m] += other.merges[m];
            self.merges_sq[m] += other.merges_sq[m];
        }
        for (a, b) in self.cell_counts.iter_mut().zip(&other.cell_counts) {
            *a += b;
        }
        if let (Some(a), Some(b)) = (&mut self.components, &other.components) {
            a.add(b);
        }
    }

    fn has_shape(&self, layout: Layout) -> bool {
        let n = layout.dimension();
        self.sum_y.len() == n
            && self.sum_yy.len() == packed_len(n)
            && self.components.as_ref().is_none_or(|c| c.has_shape(layout))
            && self.strategies.len() == layout.strategies().len()
            && self.cell_counts.len() == 3 * layout.cells
    }
}

/// The integer counters of one fold — a document's ([`FoldMoments`]) or a worker's
/// (`accumulator`) — for [`counters_fit`].
#[derive(Debug, Clone, Copy)]
pub(super) struct Counters<'a> {
    pub(super) merges: &'a [u64; 3],
    pub(super) merges_sq: &'a [u128; 3],
    pub(super) cell_counts: &'a [u64],
}

impl FoldMoments {
    pub(super) fn counters(&self) -> Counters<'_> {
        Counters { merges: &self.merges, merges_sq: &self.merges_sq, cell_counts: &self.cell_counts }
    }
}

/// Whether the counters of `folds` added together fit their types.
pub(super) fn counters_fit(folds: &[Counters<'_>]) -> bool {
    let fits = |total: u128| total <= u128::from(u64::MAX);
    (0..3).all(|m| {
        fits(folds.iter().map(|f| u128::from(f.merges[m])).sum())
            && folds.iter().try_fold(0u128, |acc, f| acc.checked_add(f.merges_sq[m])).is_some()
    }) && (0..folds[0].cell_counts.len()).all(|i| fits(folds.iter().map(|f| u128::from(f.cell_counts[i])).sum()))
}

fn overflow(what: &str) -> MergeError {
    MergeError::Overflow(what.to_string())
}

/// The merge counters with `tally`'s added (checked), and whether its cell counts fit beside
/// `cell_counts`: the first step of adding an iteration, which changes nothing when it fails.
pub(super) fn add_tally_counters(
    mut merges: [u64; 3],
    mut merges_sq: [u128; 3],
    cell_counts: &[u64],
    tally: &IterationTally,
) -> Result<([u64; 3], [u128; 3]), MergeError> {
    for m in 0..3 {
        merges[m] = merges[m].checked_add(tally.merges[m]).ok_or_else(|| overflow("merge count"))?;
        let sq = u128::from(tally.merges[m]) * u128::from(tally.merges[m]);
        merges_sq[m] = merges_sq[m].checked_add(sq).ok_or_else(|| overflow("squared merge count"))?;
    }
    if cell_counts.iter().zip(&tally.cell_counts).any(|(a, b)| a.checked_add(*b).is_none()) {
        return Err(overflow("cell event count"));
    }
    Ok((merges, merges_sq))
}

/// The moments of a set of iterations of one configuration.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Moments {
    /// Layout version (`engines::layout`): 4 for moments this build makes with noise components,
    /// 3 without (format 4 changed only the components); 2, or 3 with components, for those an
    /// earlier build made.
    pub format_version: u32,
    /// Fingerprint of the configuration the iterations were drawn under.
    pub fingerprint: String,
    /// Number of cells K.
    pub cells: usize,
    /// The (seed, iteration) pairs included.
    pub coverage: Coverage,
    /// Sums over the iterations of each fold: `folds[f]` holds the iterations s ≡ f (mod K).
    #[serde(deserialize_with = "bounded::<_, _, MAX_FOLDS>")]
    pub folds: Vec<FoldMoments>,
    /// With `radii`: the same iterations' moments at each smaller radius R′ of the configuration,
    /// in its order — each with R′'s configuration's fingerprint (what a direct run at R′ has),
    /// the same coverage, and no radii of its own (docs/model.md §13).
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "bounded::<_, _, MAX_RADII>")]
    #[cfg_attr(feature = "server", schema(no_recursion))]
    pub radii: Vec<Moments>,
}

pub use super::merge_error::MergeError;

impl Moments {
    /// No iterations yet, for `config`.
    pub fn new(config: &SimConfig) -> Self {
        let k = config.cells.len();
        Self {
            format_version: config.moments_format(),
            fingerprint: config.fingerprint().to_string(),
            cells: k,
            coverage: Coverage::new(),
            folds: vec![FoldMoments::empty(Layout::of(config), config.noise_components); config.folds],
            radii: config.radii.iter().map(Moments::new).collect(),
        }
    }

    /// No iterations, in the same format and configuration as `self` (a job an earlier build
    /// started resumes in its checkpoint's format).
    pub fn empty_like(&self) -> Self {
        let components = self.has_components();
        Self {
            format_version: self.format_version,
            fingerprint: self.fingerprint.clone(),
            cells: self.cells,
            coverage: Coverage::new(),
            folds: vec![FoldMoments::empty(self.layout(), components); self.folds.len()],
            radii: self.radii.iter().map(Moments::empty_like).collect(),
        }
    }

    /// What these moments' format holds (checked supported by [`check_well_formed`](super::well_formed::check_well_formed)).
    pub fn layout(&self) -> Layout {
        Layout { cells: self.cells, format: self.format_version }
    }

    /// Total iterations M.
    pub fn iterations(&self) -> u64 {
        self.folds.iter().map(|f| f.iterations).sum()
    }

    /// Whether these moments keep the noise components (`stats::components`).
    pub fn has_components(&self) -> bool {
        self.folds.first().is_some_and(|f| f.components.is_some())
    }

    /// The number of folds K.
    pub fn fold_count(&self) -> usize {
        self.folds.len()
    }

    /// Adds iteration `tally.iteration` of `seed`.
    pub fn add_iteration(&mut self, seed: u64, tally: &IterationTally) -> Result<(), MergeError> {
        let s = tally.iteration;
        if self.coverage.contains(seed, s) {
            return Err(MergeError::Overlap(vec![Overlap { seed, range: [s, s + 1] }]));
        }
        check_iteration(tally, self.radii.len())?;
        let k = self.folds.len() as u64;
        let layout = self.layout();
        self.folds[(s % k) as usize].add_iteration(layout, tally)?;
        self.coverage.insert(seed, s, s + 1);
        for (sub, sub_tally) in self.radii.iter_mut().zip(&tally.radii) {
            sub.add_iteration(seed, sub_tally)?;
        }
        Ok(())
    }

    /// Checks that `other` could be merged into `self`, without changing anything: the same
    /// configuration, no iteration counted twice, and nothing that overflows (in either fold, nor
    /// in the two folds pooled).
    pub fn check_mergeable(&self, other: &Moments) -> Result<(), MergeError> {
        other.check_shape()?;
        self.check_same_configuration_and_new(other)?;
        for (a, b) in self.folds.iter().zip(&other.folds) {
            a.check_add(b)?;
        }
        let total = self.coverage.iterations() + other.coverage.iterations();
        if total > u128::from(MAX_ITERATION_INDEX) {
            return Err(overflow("iteration count"));
        }
        // The pooled folds (what the noise table adds) must fit as well.
        if !counters_fit(&self.folds.iter().chain(&other.folds).map(FoldMoments::counters).collect::<Vec<_>>()) {
            return Err(overflow("pooled counts"));
        }
        // The radii's fingerprints are in the parent's, so equal fingerprints mean equal radii —
        // of moments made by this build; one from outside must hold as many.
        if other.radii.len() != self.radii.len() {
            return Err(MergeError::Malformed(format!(
                "{} smaller radii where these moments keep {}",
                other.radii.len(),
                self.radii.len()
            )));
        }
        self.radii.iter().zip(&other.radii).try_for_each(|(a, b)| a.check_mergeable(b))
    }

    /// Adds `other`'s iterations: exact addition, refused (with nothing changed) if the
    /// configurations differ, any iteration would be counted twice, or a counter or sum would
    /// overflow.
    pub fn merge(&mut self, other: &Moments) -> Result<(), MergeError> {
        self.check_mergeable(other)?;
        let mut coverage = self.coverage.clone();
        coverage.union(&other.coverage);
        coverage.check().map_err(|e| MergeError::Malformed(format!("merged coverage: {e}")))?;
        for (a, b) in self.folds.iter_mut().zip(&other.folds) {
            a.add(b);
        }
        self.coverage = coverage;
        for (a, b) in self.radii.iter_mut().zip(&other.radii) {
            a.merge(b)?;
        }
        Ok(())
    }

    /// What every merge needs: the same configuration, and no iteration of `other` counted here
    /// already.
    fn check_same_configuration_and_new(&self, other: &Moments) -> Result<(), MergeError> {
        if other.format_version != self.format_version {
            return Err(MergeError::FormatMix { found: other.format_version, expected: self.format_version });
        }
        if other.fingerprint != self.fingerprint || other.cells != self.cells || other.folds.len() != self.folds.len() {
            return Err(MergeError::Fingerprint {
                found: other.fingerprint.clone(),
                expected: self.fingerprint.clone(),
                differences: Vec::new(),
            });
        }
        let overlaps = self.coverage.overlaps(&other.coverage);
        if !overlaps.is_empty() {
            return Err(MergeError::Overlap(overlaps));
        }
        Ok(())
    }

    /// The cheap structural checks a merge needs: format, shapes, coverage, and coverage counts
    /// that match the folds.
    pub(super) fn check_shape(&self) -> Result<(), MergeError> {
        if !Layout::supports(self.format_version) {
            return Err(MergeError::Format { found: self.format_version, expected: MOMENTS_FORMAT_VERSION });
        }
        if self.cells == 0 || self.cells > MAX_CELLS {
            return Err(MergeError::Malformed(format!("{} cells; a grid has 1 to {MAX_CELLS}", self.cells)));
        }
        if !(MIN_FOLDS..=MAX_FOLDS).contains(&self.folds.len()) {
            return Err(MergeError::Malformed(format!(
                "{} folds; moments have {MIN_FOLDS} to {MAX_FOLDS}",
                self.folds.len()
            )));
        }
        if !self.folds.iter().all(|f| f.has_shape(self.layout())) {
            return Err(MergeError::Malformed(format!("array lengths do not match {} cells", self.cells)));
        }
        if !self.folds.iter().all(|f| f.components.is_some() == self.folds[0].components.is_some()) {
            return Err(MergeError::Malformed("some folds keep noise components and some do not".into()));
        }
        self.coverage.check().map_err(|e| MergeError::Malformed(e.to_string()))?;
        if self.coverage.iterations() > u128::from(MAX_ITERATION_INDEX) {
            return Err(MergeError::Malformed("the coverage holds more than 2^62 iterations".into()));
        }
        let k = self.folds.len();
        for (f, (covered, fold)) in self.coverage.residue_counts(k as u64).into_iter().zip(&self.folds).enumerate() {
            if covered != u128::from(fold.iterations) {
                return Err(MergeError::Malformed(format!(
                    "coverage has {covered} iterations s ≡ {f} (mod {k}) but fold {f} counts {}",
                    fold.iterations
                )));
            }
        }
        // The folds' counters must pool without overflow (the noise table adds them; their sums
        // pool safely: moments from outside are below 2^1000, merged ones are checked).
        if !counters_fit(&self.folds.iter().map(FoldMoments::counters).collect::<Vec<_>>()) {
            return Err(MergeError::Malformed("the folds' counts overflow when pooled".into()));
        }
        for (i, sub) in self.radii.iter().enumerate() {
            let what = |e: String| MergeError::Malformed(format!("radius #{i}: {e}"));
            if !sub.radii.is_empty() {
                return Err(what("a radius's moments hold radii of their own".into()));
            }
            if sub.coverage != self.coverage
                || sub.format_version != self.format_version
                || sub.cells != self.cells
                || sub.folds.len() != self.folds.len()
            {
                return Err(what("its coverage, format, cells or folds differ from the run's".into()));
            }
            sub.check_shape().map_err(|e| what(e.to_string()))?;
        }
        Ok(())
    }

    /// Checks that every sum is finite and at most 2¹⁰⁰⁰ in magnitude, so that its canonical form
    /// reads back (merges of documents check their result with this).
    pub fn check_bounded(&self) -> Result<(), MergeError> {
        for fold in &self.folds {
            if fold.sums().any(|s| !(s.is_finite() && s.value().abs() <= MAX_MAGNITUDE)) {
                return Err(overflow("a merged sum exceeds 2^1000"));
            }
        }
        self.radii.iter().try_for_each(Moments::check_bounded)
    }

    /// All folds added together (they always fit: moments from outside are checked for it, and
    /// merges check the pooled totals).
    pub fn pooled(&self) -> FoldMoments {
        self.pooled_except(None)
    }

    /// All folds but `left_out` added together: the training data of a cross-fit.
    pub fn pooled_except(&self, left_out: Option<usize>) -> FoldMoments {
        let mut all = FoldMoments::empty(self.layout(), self.has_components());
        for (f, fold) in self.folds.iter().enumerate() {
            if Some(f) != left_out {
                all.add(fold);
            }
        }
        all
    }
}

#[cfg(test)]
mod tests;
