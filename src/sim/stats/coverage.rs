//! Which iterations a moments value holds: per seed, a set of disjoint half-open index ranges.
//!
//! Iteration s of seed σ is a deterministic draw, so counting it twice would bias every statistic.
//! Coverage lets a merge refuse exactly that, naming the overlap.
//!
//! Coverage read from outside is bounded before anything walks it: indices below
//! [`MAX_ITERATION_INDEX`], at most [`MAX_RANGES`] ranges in all, and counts added with checked
//! arithmetic (four ranges `[0, 2⁶³)` once wrapped to a small total). Overlaps and unions walk the
//! two sorted lists side by side, so they cost O(n + m), never O(n·m).

use serde::{Deserialize, Serialize};

/// Largest iteration index (exclusive) a coverage may name: the same bound as a job's range, far
/// from where index arithmetic overflows.
pub const MAX_ITERATION_INDEX: u64 = 1 << 62;

/// Most ranges (over all seeds) a coverage may hold. A study of shards of one seed is one range
/// and every further seed adds one; a hundred thousand leaves room for any real study.
pub const MAX_RANGES: usize = 100_000;

/// Half-open iteration ranges `[start, end)` per seed, sorted, disjoint and non-adjacent.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(transparent)]
pub struct Coverage(Vec<SeedRanges>);

/// The ranges covered for one seed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SeedRanges {
    /// The seed whose random streams drew the iterations.
    pub seed: u64,
    /// Sorted, disjoint, non-adjacent `[start, end)` pairs.
    pub ranges: Vec<[u64; 2]>,
}

/// An iteration range covered twice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Overlap {
    /// The seed both sides hold iterations of.
    pub seed: u64,
    /// The `[start, end)` iterations both hold.
    pub range: [u64; 2],
}

impl std::fmt::Display for Overlap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "seed {} iterations [{}, {})", self.seed, self.range[0], self.range[1])
    }
}

/// Why a coverage read from outside is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CoverageError {
    /// The seeds are not in increasing order, or one appears twice.
    #[error("coverage seeds are not sorted and distinct")]
    Seeds,
    /// A seed's ranges are empty, unsorted, overlapping or adjacent (adjacent ranges are one).
    #[error("coverage ranges of seed {0} are not sorted, non-empty and disjoint")]
    Ranges(u64),
    /// A range ends past [`MAX_ITERATION_INDEX`].
    #[error("coverage of seed {seed} names iteration {end}, beyond the largest index 2^62")]
    Index {
        /// The seed of the range.
        seed: u64,
        /// The range's end (exclusive).
        end: u64,
    },
    /// More than [`MAX_RANGES`] ranges in all.
    #[error("coverage holds more than {MAX_RANGES} ranges")]
    TooManyRanges,
}

impl Coverage {
    /// Nothing covered.
    pub fn new() -> Self {
        Self::default()
    }

    /// Iterations `[start, end)` of `seed`.
    pub fn range(seed: u64, start: u64, end: u64) -> Self {
        let mut c = Self::new();
        c.insert(seed, start, end);
        c
    }

    /// The per-seed ranges.
    pub fn seeds(&self) -> &[SeedRanges] {
        &self.0
    }

    /// Number of ranges over all seeds.
    pub fn range_count(&self) -> usize {
        self.0.iter().map(|s| s.ranges.len()).sum()
    }

    /// Total number of iterations covered (u128: a well-formed coverage of many seeds may exceed
    /// u64, and then no moments can match it).
    pub fn iterations(&self) -> u128 {
        self.0.iter().flat_map(|s| &s.ranges).map(|r| u128::from(r[1].saturating_sub(r[0]))).sum()
    }

    /// Iterations covered in each residue class of the index mod `k` (the folds of the moments):
    /// entry r counts the covered s with s ≡ r (mod k).
    pub fn residue_counts(&self, k: u64) -> Vec<u128> {
        assert!(k > 0, "at least one fold");
        // Indices s < x with s ≡ r (mod k): ⌈(x − r)/k⌉ for x ≥ r, i.e. ⌊(x + k − 1 − r)/k⌋.
        let below = |x: u64, r: u64| (u128::from(x) + u128::from(k - 1 - r)) / u128::from(k);
        (0..k)
            .map(|r| self.0.iter().flat_map(|s| &s.ranges).map(|g| below(g[1], r).saturating_sub(below(g[0], r))).sum())
            .collect()
    }

    /// Whether iteration `s` of `seed` is covered.
    pub fn contains(&self, seed: u64, s: u64) -> bool {
        let Ok(i) = self.0.binary_search_by_key(&seed, |x| x.seed) else { return false };
        let ranges = &self.0[i].ranges;
        // The last range starting at or before s.
        let after = ranges.partition_point(|r| r[0] <= s);
        after > 0 && s < ranges[after - 1][1]
    }

    /// The ranges covered by both `self` and `other`, in O(n + m) (both are sorted).
    pub fn overlaps(&self, other: &Coverage) -> Vec<Overlap> {
        let mut out = Vec::new();
        for_matching_seeds(&self.0, &other.0, |seed, a, b| {
            let (mut i, mut j) = (0, 0);
            while i < a.len() && j < b.len() {
                let (lo, hi) = (a[i][0].max(b[j][0]), a[i][1].min(b[j][1]));
                if lo < hi {
                    out.push(Overlap { seed, range: [lo, hi] });
                }
                if a[i][1] < b[j][1] { i += 1 } else { j += 1 }
            }
        });
        out
    }

    /// Adds `[start, end)` of `seed` (which must not overlap what is covered; callers check with
    /// [`Coverage::overlaps`] first), merging adjacent ranges.
    pub fn insert(&mut self, seed: u64, start: u64, end: u64) {
        if start >= end {
            return;
        }
        let pos = match self.0.binary_search_by_key(&seed, |s| s.seed) {
            Ok(p) => p,
            Err(p) => {
                self.0.insert(p, SeedRanges { seed, ranges: Vec::new() });
                p
            }
        };
        let ranges = &mut self.0[pos].ranges;
        // Fast path for the runner, which appends iteration after iteration.
        if let Some(last) = ranges.last_mut()
            && last[1] == start
        {
            last[1] = end;
            return;
        }
        let merged = union_ranges(ranges, &[[start, end]]);
        *ranges = merged;
    }

    /// Adds everything `other` covers, in O(n + m).
    pub fn union(&mut self, other: &Coverage) {
        let mut out = Vec::with_capacity(self.0.len() + other.0.len());
        let (mut i, mut j) = (0, 0);
        let (a, b) = (&self.0, &other.0);
        while i < a.len() || j < b.len() {
            match (a.get(i), b.get(j)) {
                (Some(x), Some(y)) if x.seed == y.seed => {
                    out.push(SeedRanges { seed: x.seed, ranges: union_ranges(&x.ranges, &y.ranges) });
                    i += 1;
                    j += 1;
                }
                (Some(x), Some(y)) if x.seed < y.seed => {
                    out.push(x.clone());
                    i += 1;
                }
                (Some(x), None) => {
                    out.push(x.clone());
                    i += 1;
                }
                (_, Some(y)) => {
                    out.push(y.clone());
                    j += 1;
                }
                (None, None) => unreachable!("the loop runs while either list has entries"),
            }
        }
        self.0 = out;
    }

    /// Checks the invariants of a coverage read from outside: seeds sorted and distinct, ranges
    /// sorted, non-empty, disjoint and non-adjacent, below [`MAX_ITERATION_INDEX`], and at most
    /// [`MAX_RANGES`] of them.
    pub fn check(&self) -> Result<(), CoverageError> {
        if !self.0.windows(2).all(|w| w[0].seed < w[1].seed) {
            return Err(CoverageError::Seeds);
        }
        if self.range_count() > MAX_RANGES {
            return Err(CoverageError::TooManyRanges);
        }
        for s in &self.0 {
            if !(s.ranges.iter().all(|r| r[0] < r[1]) && s.ranges.windows(2).all(|w| w[0][1] < w[1][0])) {
                return Err(CoverageError::Ranges(s.seed));
            }
            if let Some(last) = s.ranges.last()
                && last[1] > MAX_ITERATION_INDEX
            {
                return Err(CoverageError::Index { seed: s.seed, end: last[1] });
            }
        }
        Ok(())
    }

    /// Whether [`Coverage::check`] passes.
    pub fn is_well_formed(&self) -> bool {
        self.check().is_ok()
    }

    /// Whether every iteration of `self` is also in `other`.
    pub fn is_within(&self, other: &Coverage) -> bool {
        let inside: u128 = self.overlaps(other).iter().map(|o| u128::from(o.range[1] - o.range[0])).sum();
        inside == self.iterations()
    }
}

/// Calls `f(seed, a_ranges, b_ranges)` for every seed in both sorted lists.
fn for_matching_seeds(a: &[SeedRanges], b: &[SeedRanges], mut f: impl FnMut(u64, &[[u64; 2]], &[[u64; 2]])) {
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].seed.cmp(&b[j].seed) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                f(a[i].seed, &a[i].ranges, &b[j].ranges);
                i += 1;
                j += 1;
            }
        }
    }
}

/// The union of two sorted lists of ranges, with touching or overlapping ranges joined.
fn union_ranges(a: &[[u64; 2]], b: &[[u64; 2]]) -> Vec<[u64; 2]> {
    let mut out: Vec<[u64; 2]> = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        let next = match (a.get(i), b.get(j)) {
            (Some(x), Some(y)) if x[0] <= y[0] => {
                i += 1;
                *x
            }
            (Some(x), None) => {
                i += 1;
                *x
            }
            (_, Some(y)) => {
                j += 1;
                *y
            }
            (None, None) => unreachable!("the loop runs while either list has entries"),
        };
        match out.last_mut() {
            Some(last) if last[1] >= next[0] => last[1] = last[1].max(next[1]),
            _ => out.push(next),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inserts_merge_and_overlaps_are_named() {
        let mut c = Coverage::range(1, 0, 10);
        c.insert(1, 10, 20);
        c.insert(1, 30, 40);
        c.insert(2, 0, 5);
        assert_eq!(c.iterations(), 35);
        let counts = c.residue_counts(2);
        assert_eq!(counts, vec![18, 17]);
        // Against counting by hand, for several K (the folds of the moments).
        for k in [1u64, 3, 7, 10] {
            let mut by_hand = vec![0u128; k as usize];
            for seed in c.seeds() {
                for r in &seed.ranges {
                    for s in r[0]..r[1] {
                        by_hand[(s % k) as usize] += 1;
                    }
                }
            }
            assert_eq!(c.residue_counts(k), by_hand, "K = {k}");
        }
        assert_eq!(c.seeds()[0].ranges, vec![[0, 20], [30, 40]]);
        assert!(c.contains(1, 19) && !c.contains(1, 20) && c.contains(2, 4) && !c.contains(3, 0));
        let other = Coverage::range(1, 15, 35);
        assert_eq!(
            c.overlaps(&other),
            vec![Overlap { seed: 1, range: [15, 20] }, Overlap { seed: 1, range: [30, 35] }]
        );
        assert!(c.overlaps(&Coverage::range(3, 0, 100)).is_empty(), "other seeds are independent draws");
        c.insert(1, 20, 30);
        assert_eq!(c.seeds()[0].ranges, vec![[0, 40]]);
        assert!(c.is_well_formed());
        let json = serde_json::to_string(&c).unwrap();
        assert_eq!(json, r#"[{"seed":1,"ranges":[[0,40]]},{"seed":2,"ranges":[[0,5]]}]"#);
    }

    #[test]
    fn malformed_coverage_is_detected() {
        let parse = |text: &str| serde_json::from_str::<Coverage>(text).unwrap();
        assert_eq!(parse(r#"[{"seed":1,"ranges":[[5,3]]}]"#).check(), Err(CoverageError::Ranges(1)));
        assert_eq!(parse(r#"[{"seed":1,"ranges":[[0,5],[4,8]]}]"#).check(), Err(CoverageError::Ranges(1)));
        assert_eq!(parse(r#"[{"seed":2,"ranges":[]},{"seed":1,"ranges":[]}]"#).check(), Err(CoverageError::Seeds));
        // Four ranges [0, 2^63) once summed to a wrapped total; now the index bound refuses them
        // and the total is exact.
        let huge = parse(
            r#"[{"seed":1,"ranges":[[0,9223372036854775808]]},{"seed":2,"ranges":[[0,9223372036854775808]]},
                {"seed":3,"ranges":[[0,9223372036854775808]]},{"seed":4,"ranges":[[0,9223372036854775808]]}]"#,
        );
        assert!(matches!(huge.check(), Err(CoverageError::Index { seed: 1, .. })));
        assert_eq!(huge.iterations(), 1u128 << 65);
    }

    /// Overlaps and unions of long coverages agree with a per-iteration reference and take linear
    /// time (two lists of 50,000 ranges: quadratic would be 2.5·10⁹ steps).
    #[test]
    fn overlaps_and_unions_are_linear_and_exact() {
        let mut a = Coverage::new();
        let mut b = Coverage::new();
        for k in 0..50_000u64 {
            a.insert(7, 4 * k, 4 * k + 2);
            b.insert(7, 4 * k + 1, 4 * k + 3);
        }
        let overlaps = a.overlaps(&b);
        assert_eq!(overlaps.len(), 50_000);
        assert!(overlaps.iter().enumerate().all(|(k, o)| o.range == [4 * k as u64 + 1, 4 * k as u64 + 2]));
        let mut u = a.clone();
        u.union(&b);
        assert_eq!(u.range_count(), 50_000);
        assert_eq!(u.iterations(), 150_000);
        assert!(a.is_within(&u) && b.is_within(&u) && !u.is_within(&a));
        // A small case against brute force, with other seeds on either side.
        let mut x = Coverage::range(1, 0, 3);
        x.insert(5, 10, 20);
        let mut y = Coverage::range(5, 15, 25);
        y.insert(9, 0, 1);
        x.union(&y);
        assert_eq!(
            serde_json::to_string(&x).unwrap(),
            r#"[{"seed":1,"ranges":[[0,3]]},{"seed":5,"ranges":[[10,25]]},{"seed":9,"ranges":[[0,1]]}]"#
        );
        assert!((0..30).all(|s| x.contains(5, s) == (10..25).contains(&s)));
    }
}
