//! The additive sufficient statistics of a run: sums over iterations, exact and mergeable.
//!
//! Per iteration s, model.md's vector Y_s = (A⁽⁰⁾_s, A⁽¹⁾_s, B_s) of dimension n = 2K + 1 carries
//! everything the cell-wise weights need: C_s(W) = ⟨A_s|W⟩ + B_s. The moments hold ΣY and ΣYYᵀ
//! (which contain ΣA, ΣB, ΣB², ΣAAᵀ and ΣBA), the power sums Σ C_s^k, k = 1…4, of every per-path
//! strategy (for their noise and the standard error of their RMS), merge counts, and per-cell event
//! counts.
//!
//! Sums are kept separately for even and odd iterations (two *folds*), so that the optimal weights
//! can be fitted on one half and evaluated on the other without storing any iteration.
//!
//! Every sum is an [`ExactSum`], so merging is addition in any order and grouping with a
//! bit-identical result; the [`Coverage`] records which (seed, iteration) pairs are included so that
//! a merge can refuse to count an iteration twice, and the fingerprint refuses moments of another
//! configuration.

use serde::{Deserialize, Serialize};

use super::config::{MOMENTS_FORMAT_VERSION, SimConfig};
use super::coverage::{Coverage, Overlap};
use super::exact_sum::ExactSum;
use super::tally::{IterationTally, PathStrategy};

/// Sums over the iterations of one parity.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FoldMoments {
    /// Number of iterations M_f.
    pub iterations: u64,
    /// ΣY (length n).
    pub sum_y: Vec<ExactSum>,
    /// ΣYYᵀ, upper triangle packed row by row: (0,0), (0,1), …, (0,n−1), (1,1), …
    pub sum_yy: Vec<ExactSum>,
    /// Per path strategy (in [`PathStrategy::ALL`] order): Σ C_s, Σ C_s², Σ C_s³, Σ C_s⁴.
    pub strategies: Vec<[ExactSum; 4]>,
    /// Merge events per plane, summed over iterations.
    pub merges: [u64; 3],
    /// Σ (merge events per plane)², for the spread of the counts.
    pub merges_sq: [u128; 3],
    /// Merge events per slot m·K + α (the samples behind each cell's weights).
    pub cell_counts: Vec<u64>,
}

/// Index of (i, j), i ≤ j, in a packed upper triangle of side n.
#[inline]
pub fn packed_index(n: usize, i: usize, j: usize) -> usize {
    debug_assert!(i <= j && j < n);
    // Rows 0..i hold n, n−1, …, n−i+1 entries: i·n − i(i−1)/2 in all; then j − i into row i.
    i * n - i * (i + 1) / 2 + j
}

fn packed_len(n: usize) -> usize {
    n * (n + 1) / 2
}

impl FoldMoments {
    fn empty(cells: usize) -> Self {
        let n = 2 * cells + 1;
        Self {
            iterations: 0,
            sum_y: vec![ExactSum::new(); n],
            sum_yy: vec![ExactSum::new(); packed_len(n)],
            strategies: vec![Default::default(); PathStrategy::COUNT],
            merges: [0; 3],
            merges_sq: [0; 3],
            cell_counts: vec![0; 3 * cells],
        }
    }

    fn add_iteration(&mut self, cells: usize, tally: &IterationTally) {
        let n = 2 * cells + 1;
        let y = tally.moment_vector(cells);
        for (a, &(i, yi)) in y.iter().enumerate() {
            self.sum_y[i].add(yi);
            for &(j, yj) in &y[a..] {
                self.sum_yy[packed_index(n, i, j)].add(yi * yj);
            }
        }
        for (sums, &c) in self.strategies.iter_mut().zip(&tally.strategies) {
            let mut power = c;
            for s in sums.iter_mut() {
                s.add(power);
                power *= c;
            }
        }
        for m in 0..3 {
            self.merges[m] += tally.merges[m];
            self.merges_sq[m] += u128::from(tally.merges[m]) * u128::from(tally.merges[m]);
        }
        for (acc, &c) in self.cell_counts.iter_mut().zip(&tally.cell_counts) {
            *acc += c;
        }
        self.iterations += 1;
    }

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
    }

    fn has_shape(&self, cells: usize) -> bool {
        let n = 2 * cells + 1;
        self.sum_y.len() == n
            && self.sum_yy.len() == packed_len(n)
            && self.strategies.len() == PathStrategy::COUNT
            && self.cell_counts.len() == 3 * cells
    }
}

/// The moments of a set of iterations of one configuration.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Moments {
    /// Layout version ([`MOMENTS_FORMAT_VERSION`]).
    pub format_version: u32,
    /// Fingerprint of the configuration the iterations were drawn under.
    pub fingerprint: String,
    /// Number of cells K.
    pub cells: usize,
    /// The (seed, iteration) pairs included.
    pub coverage: Coverage,
    /// Sums over even (index 0) and odd (index 1) iterations.
    pub folds: [FoldMoments; 2],
}

/// Why two moments values cannot be merged (or a document cannot be used).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    #[error("moments format {found} is not supported (this build reads format {expected})")]
    Format { found: u32, expected: u32 },
    #[error(
        "configuration fingerprints differ ({found} vs {expected}): the statistics were drawn under another scene, R, N_F, N_B, cell grid or generator"
    )]
    Fingerprint { found: String, expected: String },
    #[error("these iterations are already counted: {}", list(.0))]
    Overlap(Vec<Overlap>),
    #[error("malformed moments: {0}")]
    Malformed(String),
}

fn list(overlaps: &[Overlap]) -> String {
    overlaps.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
}

impl Moments {
    /// No iterations yet, for `config`.
    pub fn new(config: &SimConfig) -> Self {
        let k = config.cells.len();
        Self {
            format_version: MOMENTS_FORMAT_VERSION,
            fingerprint: config.fingerprint().to_string(),
            cells: k,
            coverage: Coverage::new(),
            folds: [FoldMoments::empty(k), FoldMoments::empty(k)],
        }
    }

    /// Total iterations M.
    pub fn iterations(&self) -> u64 {
        self.folds[0].iterations + self.folds[1].iterations
    }

    /// Adds iteration `tally.iteration` of `seed`.
    pub fn add_iteration(&mut self, seed: u64, tally: &IterationTally) -> Result<(), MergeError> {
        let s = tally.iteration;
        if self.coverage.contains(seed, s) {
            return Err(MergeError::Overlap(vec![Overlap { seed, range: [s, s + 1] }]));
        }
        self.folds[(s % 2) as usize].add_iteration(self.cells, tally);
        self.coverage.insert(seed, s, s + 1);
        Ok(())
    }

    /// Checks that `other` could be merged into `self`, without changing anything.
    pub fn check_mergeable(&self, other: &Moments) -> Result<(), MergeError> {
        other.check_well_formed()?;
        if other.fingerprint != self.fingerprint || other.cells != self.cells {
            return Err(MergeError::Fingerprint {
                found: other.fingerprint.clone(),
                expected: self.fingerprint.clone(),
            });
        }
        let overlaps = self.coverage.overlaps(&other.coverage);
        if !overlaps.is_empty() {
            return Err(MergeError::Overlap(overlaps));
        }
        Ok(())
    }

    /// Adds `other`'s iterations: exact addition, refused (with nothing changed) if the
    /// configurations differ or any iteration would be counted twice.
    pub fn merge(&mut self, other: &Moments) -> Result<(), MergeError> {
        self.check_mergeable(other)?;
        for (a, b) in self.folds.iter_mut().zip(&other.folds) {
            a.add(b);
        }
        self.coverage.union(&other.coverage);
        Ok(())
    }

    /// Structural checks for moments read from outside (a file, a peer, a database row).
    pub fn check_well_formed(&self) -> Result<(), MergeError> {
        if self.format_version != MOMENTS_FORMAT_VERSION {
            return Err(MergeError::Format { found: self.format_version, expected: MOMENTS_FORMAT_VERSION });
        }
        if !self.folds.iter().all(|f| f.has_shape(self.cells)) {
            return Err(MergeError::Malformed(format!("array lengths do not match {} cells", self.cells)));
        }
        if !self.coverage.is_well_formed() {
            return Err(MergeError::Malformed("coverage ranges are not sorted and disjoint".into()));
        }
        let (even, odd) = self.coverage.seeds().iter().flat_map(|s| &s.ranges).fold((0u64, 0u64), |(e, o), r| {
            let len = r[1] - r[0];
            let evens = len / 2 + u64::from(len % 2 == 1 && r[0] % 2 == 0);
            (e + evens, o + len - evens)
        });
        if even != self.folds[0].iterations || odd != self.folds[1].iterations {
            return Err(MergeError::Malformed(format!(
                "coverage has {even} even and {odd} odd iterations but the sums count {} and {}",
                self.folds[0].iterations, self.folds[1].iterations
            )));
        }
        Ok(())
    }

    /// Both folds added together.
    pub fn pooled(&self) -> FoldMoments {
        let mut all = self.folds[0].clone();
        all.add(&self.folds[1]);
        all
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_index_enumerates_the_upper_triangle() {
        for n in [1, 2, 5, 9] {
            let mut expected = 0;
            for i in 0..n {
                for j in i..n {
                    assert_eq!(packed_index(n, i, j), expected, "n={n} i={i} j={j}");
                    expected += 1;
                }
            }
            assert_eq!(expected, packed_len(n));
        }
    }
}
