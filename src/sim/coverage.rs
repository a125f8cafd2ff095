//! Which iterations a moments value holds: per seed, a set of disjoint half-open index ranges.
//!
//! Iteration s of seed σ is a deterministic draw, so counting it twice would bias every statistic.
//! Coverage lets a merge refuse exactly that, naming the overlap.

use serde::{Deserialize, Serialize};

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
    pub seed: u64,
    /// Sorted, disjoint, non-adjacent `[start, end)` pairs.
    pub ranges: Vec<[u64; 2]>,
}

/// An iteration range covered twice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Overlap {
    pub seed: u64,
    pub range: [u64; 2],
}

impl std::fmt::Display for Overlap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "seed {} iterations [{}, {})", self.seed, self.range[0], self.range[1])
    }
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

    /// Total number of iterations covered.
    pub fn iterations(&self) -> u64 {
        self.0.iter().flat_map(|s| &s.ranges).map(|r| r[1] - r[0]).sum()
    }

    /// Whether iteration `s` of `seed` is covered.
    pub fn contains(&self, seed: u64, s: u64) -> bool {
        self.0.iter().find(|x| x.seed == seed).is_some_and(|x| x.ranges.iter().any(|r| r[0] <= s && s < r[1]))
    }

    /// The ranges covered by both `self` and `other`.
    pub fn overlaps(&self, other: &Coverage) -> Vec<Overlap> {
        let mut out = Vec::new();
        for a in &self.0 {
            let Some(b) = other.0.iter().find(|b| b.seed == a.seed) else { continue };
            for ra in &a.ranges {
                for rb in &b.ranges {
                    let (lo, hi) = (ra[0].max(rb[0]), ra[1].min(rb[1]));
                    if lo < hi {
                        out.push(Overlap { seed: a.seed, range: [lo, hi] });
                    }
                }
            }
        }
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
        ranges.push([start, end]);
        ranges.sort_unstable();
        let mut merged: Vec<[u64; 2]> = Vec::with_capacity(ranges.len());
        for r in ranges.drain(..) {
            match merged.last_mut() {
                Some(last) if last[1] >= r[0] => last[1] = last[1].max(r[1]),
                _ => merged.push(r),
            }
        }
        *ranges = merged;
    }

    /// Adds everything `other` covers.
    pub fn union(&mut self, other: &Coverage) {
        for s in &other.0 {
            for r in &s.ranges {
                self.insert(s.seed, r[0], r[1]);
            }
        }
    }

    /// Checks the invariants (for documents read from outside).
    pub fn is_well_formed(&self) -> bool {
        self.0.windows(2).all(|w| w[0].seed < w[1].seed)
            && self
                .0
                .iter()
                .all(|s| s.ranges.iter().all(|r| r[0] < r[1]) && s.ranges.windows(2).all(|w| w[0][1] < w[1][0]))
    }
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
        let bad: Coverage = serde_json::from_str(r#"[{"seed":1,"ranges":[[5,3]]}]"#).unwrap();
        assert!(!bad.is_well_formed());
        let overlapping: Coverage = serde_json::from_str(r#"[{"seed":1,"ranges":[[0,5],[4,8]]}]"#).unwrap();
        assert!(!overlapping.is_well_formed());
    }
}
