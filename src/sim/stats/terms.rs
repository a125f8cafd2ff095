//! What one iteration adds to the sums of its fold: every term of ΣY, ΣYYᵀ, the per-path
//! strategies' power sums and the noise components' block products, as (index, value) pairs over
//! the fold's sums in the order of `FoldMoments::sums` (ΣY, ΣYYᵀ packed, the power sums, then the
//! component sums).
//!
//! Both accumulators of the moments add exactly these terms: the documents' [`ExactSum`]s
//! (`moments`) and the runner's fast per-worker [`WindowSum`]s (`accumulator`). One list of terms
//! for both is what makes their sums equal to the last bit.
//!
//! [`ExactSum`]: crate::sim::math::exact_sum::ExactSum
//! [`WindowSum`]: crate::sim::math::window_sum::WindowSum

use crate::sim::engines::layout::Layout;
use crate::sim::engines::tally::{BLOCKS, IterationTally};
use crate::sim::model::config::{packed_index, packed_len};

/// Where each kind of sum starts in a fold's flat list of sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SumIndex {
    /// Dimension n of Y.
    pub n: usize,
    /// Sums of ΣYYᵀ, packed: n(n + 1)/2.
    pub packed: usize,
    /// Leading entries of Y the noise components cover ([`Layout::component_dimension`]).
    pub n_components: usize,
    /// Sums of each component matrix, packed: n_c(n_c + 1)/2.
    pub packed_components: usize,
    /// Per-path strategies the format keeps.
    pub strategies: usize,
    /// Whether the fold keeps the noise components.
    pub components: bool,
}

impl SumIndex {
    /// The flat list of a fold of `layout`, with or without the noise components.
    pub fn new(layout: Layout, components: bool) -> Self {
        let (n, n_components) = (layout.dimension(), layout.component_dimension());
        Self {
            n,
            packed: packed_len(n),
            n_components,
            packed_components: packed_len(n_components),
            strategies: layout.strategies().len(),
            components,
        }
    }

    /// ΣY_i.
    #[inline]
    pub fn y(&self, i: usize) -> usize {
        i
    }

    /// ΣY_iY_j at packed position `p`.
    #[inline]
    pub fn yy(&self, p: usize) -> usize {
        self.n + p
    }

    /// Σ C_s^(k+1) of strategy `s`.
    #[inline]
    pub fn power(&self, s: usize, k: usize) -> usize {
        self.n + self.packed + 4 * s + k
    }

    /// The component matrix `kind` (`components::LIGHT`, `CAMERA`, `CROSS`) at packed position `p`.
    #[inline]
    pub fn component(&self, kind: usize, p: usize) -> usize {
        self.n + self.packed + 4 * self.strategies + kind * self.packed_components + p
    }

    /// The component `kind` of strategy `s`.
    #[inline]
    pub fn component_strategy(&self, s: usize, kind: usize) -> usize {
        self.n + self.packed + 3 * self.packed_components + 4 * self.strategies + 3 * s + kind
    }

    /// How many sums a fold has.
    pub fn len(&self) -> usize {
        let base = self.n + self.packed + 4 * self.strategies;
        if self.components { base + 3 * self.packed_components + 3 * self.strategies } else { base }
    }

    /// Whether a fold has no sums (never: n ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The pairs of blocks (block = 2·L + K) behind each kind of noise component (`LIGHT`, `CAMERA`,
/// `CROSS`), each weighted ½.
pub const PAIRS: [[(usize, usize); 2]; 3] = [[(0, 1), (2, 3)], [(0, 2), (1, 3)], [(0, 3), (1, 2)]];

/// Buffers [`for_each_term`] reuses from iteration to iteration, so that it allocates nothing once
/// they have grown.
#[derive(Debug, Clone, Default)]
pub struct TermBuffers {
    y: Vec<(usize, f64)>,
    blocks: [Vec<(usize, f64)>; BLOCKS],
}

/// Calls `add(index, value)` for every term `tally` adds to a fold laid out by `index` (values
/// that are zero may be skipped by the sums; they are passed on as computed).
pub fn for_each_term(
    layout: Layout,
    index: &SumIndex,
    tally: &IterationTally,
    buffers: &mut TermBuffers,
    mut add: impl FnMut(usize, f64),
) {
    let n = index.n;
    tally.moment_vector_into(layout, &mut buffers.y);
    let y = &buffers.y;
    for (a, &(i, yi)) in y.iter().enumerate() {
        add(index.y(i), yi);
        for &(j, yj) in &y[a..] {
            add(index.yy(packed_index(n, i, j)), yi * yj);
        }
    }
    for (s, &c) in tally.strategies[..index.strategies].iter().enumerate() {
        let mut power = c;
        for k in 0..4 {
            add(index.power(s, k), power);
            power *= c;
        }
    }
    if !index.components {
        return;
    }
    let n_c = index.n_components;
    for (b, v) in buffers.blocks.iter_mut().enumerate() {
        tally.block_moment_vector(b, layout, v);
        // The components cover Y's first n_c entries only (the vector is in index order).
        let kept = v.partition_point(|&(i, _)| i < n_c);
        v.truncate(kept);
    }
    for (kind, pairs) in PAIRS.iter().enumerate() {
        for &(p, q) in pairs {
            // ½·sym(u vᵀ) = ¼(u vᵀ + v uᵀ): (i, j) and (j, i) both occur when both vectors hold
            // both indices, ¼ each; a diagonal entry occurs once and gets ½ u_i v_i.
            for &(i, ui) in &buffers.blocks[p] {
                for &(j, vj) in &buffers.blocks[q] {
                    let weight = if i == j { 0.5 } else { 0.25 };
                    add(index.component(kind, packed_index(n_c, i.min(j), i.max(j))), weight * ui * vj);
                }
            }
        }
        for s in 0..index.strategies {
            let value: f64 =
                pairs.iter().map(|&(p, q)| tally.block_strategies[p][s] * tally.block_strategies[q][s]).sum();
            add(index.component_strategy(s, kind), 0.5 * value);
        }
    }
}
