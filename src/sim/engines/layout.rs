//! What a moments format holds: which per-path strategies it tallies, which of them are columns of
//! the moment vector, and so the vector's dimension — and the size bounds that follow (the most
//! folds a grid may have).
//!
//! Format 3 (issue 21) widens the moment vector Y = (A⁽⁰⁾, A⁽¹⁾, B) of docs/model.md §7 by one
//! column per *stackable* per-path strategy h — its per-iteration value H_h — so that the optimum
//! can be fitted over w = table + Σ_h β_h·w_h (the stacked optimum, model.md §7), and tallies the
//! w0 = 0 variants of the heuristics. Format 2 documents and checkpoints are still read: they hold
//! the first seven strategies and no H columns, and everything that needs what they lack says so.
//! Strategies are only ever appended to [`PathStrategy::ALL`], so a format keeps a prefix of it.
//!
//! Format 4 (issue 26) keeps the same sums, except that the noise components' block products cover
//! only the entries of Y a prediction at another budget can use (docs/model.md §12): A, B and the
//! H columns of the stacked heuristics whose weights do not depend on the budget — the switch,
//! Y's first H column, so the components cover a prefix of Y. The other H columns (the
//! correlation-aware heuristics, whose weights change with N_F and N_B, and the balance and power
//! heuristics, which no predicted row stacks) took three quarters of the components' products
//! and no prediction read them. Format 3 documents and checkpoints are still read.

use super::strategies::PathStrategy;
use crate::sim::model::cells::MAX_CELLS;
use crate::sim::model::config::{MAX_FOLDS, MIN_FOLDS, MOMENTS_FORMAT_VERSION, SimConfig, packed_len};

/// The oldest format this build reads: the first seven strategies, no H columns.
pub const FORMAT_WITHOUT_HEURISTICS: u32 = 2;
/// The format with the stackable strategies' H columns and the w0 = 0 variants (issue 21): the
/// one this build wrote before issue 26: its noise components cover all of Y.
pub const FORMAT_WITH_HEURISTICS: u32 = 3;
/// Format 3 with noise components over the predictable prefix of Y only (issue 26): the one this
/// build writes ([`MOMENTS_FORMAT_VERSION`]).
pub const FORMAT_WITH_PREDICTABLE_COMPONENTS: u32 = 4;
const _: () = assert!(MOMENTS_FORMAT_VERSION == FORMAT_WITH_PREDICTABLE_COMPONENTS);

/// The H columns format 4's noise components keep: a prefix of [`PathStrategy::STACKABLE`], the
/// stacked heuristics whose weights do not depend on the budget (the only ones a prediction at
/// another budget stacks, `solve::predict`).
pub const COMPONENT_HEURISTICS: [PathStrategy; 1] = [PathStrategy::Switch];
const _: () = {
    assert!(matches!(PathStrategy::STACKABLE[0], PathStrategy::Switch));
    assert!(!PathStrategy::Switch.depends_on_budget());
};

/// Most H columns any format has.
pub const MAX_HEURISTIC_COLUMNS: usize = PathStrategy::STACKABLE.len();

/// Longest moment vector: n = 2K + 1 + H for the largest grid.
pub const MAX_DIMENSION: usize = 2 * MAX_CELLS + 1 + MAX_HEURISTIC_COLUMNS;

/// Longest packed ΣYYᵀ.
pub const MAX_PACKED: usize = packed_len(MAX_DIMENSION);

/// Most exact sums all folds' ΣYYᵀ may hold together: what two folds of the largest grid need (the
/// bound before K-fold moments), so documents, checkpoints and their parsers stay as large as they
/// were; finer grids get fewer folds (see [`folds_allowed`]).
pub const MAX_FOLD_SUMS: usize = 2 * MAX_PACKED;

/// Most folds a grid of `cells` cells may have (at least [`MIN_FOLDS`]); with noise components
/// every fold holds four packed matrices instead of one (ΣYYᵀ and the three component sums of
/// `stats::components`), so a quarter as many. Format 4's component matrices are a little smaller,
/// but the bound is counted as in format 3 so that every configuration keeps the folds (and so the
/// fingerprint and the results) it had. The bound is per moments value: a run that tallies smaller
/// radii keeps one value per radius beside its own (at most `MAX_RADII` + 1 of them, each this
/// size), and keeps its folds — fewer folds would make every radius's standard errors coarser.
pub fn folds_allowed(cells: usize, noise_components: bool) -> usize {
    let n = Layout::new(cells, MOMENTS_FORMAT_VERSION).dimension();
    let per_fold = packed_len(n) * if noise_components { 4 } else { 1 };
    (MAX_FOLD_SUMS / per_fold).clamp(MIN_FOLDS, MAX_FOLDS)
}

/// The shape of one format's sums for a grid of `cells` cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// K, the cells of the grid.
    pub cells: usize,
    /// The moments format (a supported one, see [`Layout::supports`]).
    pub format: u32,
}

impl Layout {
    /// The layout of the moments this build writes for `config`.
    pub fn of(config: &SimConfig) -> Self {
        Self::new(config.cells.len(), config.moments_format())
    }

    /// The layout of `format` (a supported one: see [`Layout::supports`]).
    pub fn new(cells: usize, format: u32) -> Self {
        debug_assert!(Self::supports(format));
        Self { cells, format }
    }

    /// Whether this build reads moments of `format`.
    pub fn supports(format: u32) -> bool {
        (FORMAT_WITHOUT_HEURISTICS..=FORMAT_WITH_PREDICTABLE_COMPONENTS).contains(&format)
    }

    /// The per-path strategies whose power sums the format keeps, in [`PathStrategy::ALL`] order.
    pub fn strategies(&self) -> &'static [PathStrategy] {
        match self.format {
            FORMAT_WITHOUT_HEURISTICS => &PathStrategy::ALL[..7],
            _ => &PathStrategy::ALL,
        }
    }

    /// Whether the format keeps `strategy`'s sums.
    pub fn keeps(&self, strategy: PathStrategy) -> bool {
        strategy.index() < self.strategies().len()
    }

    /// The strategies that are columns H_h of the moment vector, in column order.
    pub fn heuristics(&self) -> &'static [PathStrategy] {
        match self.format {
            FORMAT_WITHOUT_HEURISTICS => &[],
            _ => &PathStrategy::STACKABLE,
        }
    }

    /// Index of B in Y: 2K.
    pub fn b_index(&self) -> usize {
        2 * self.cells
    }

    /// Index of H_h in Y, if the format has that column.
    pub fn heuristic_index(&self, h: PathStrategy) -> Option<usize> {
        self.heuristics().iter().position(|&x| x == h).map(|i| 2 * self.cells + 1 + i)
    }

    /// Dimension of Y: 2K + 1 + (number of H columns).
    pub fn dimension(&self) -> usize {
        2 * self.cells + 1 + self.heuristics().len()
    }

    /// How many leading entries of Y the noise components' block products cover: all of Y before
    /// format 4, then A, B and the [`COMPONENT_HEURISTICS`] columns.
    pub fn component_dimension(&self) -> usize {
        if self.format >= FORMAT_WITH_PREDICTABLE_COMPONENTS {
            2 * self.cells + 1 + COMPONENT_HEURISTICS.len()
        } else {
            self.dimension()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_2_is_the_old_prefix_and_format_3_adds_the_stackable_columns() {
        let old = Layout::new(52, 2);
        assert_eq!(old.dimension(), 105);
        assert_eq!(old.strategies().len(), 7);
        assert!(old.heuristics().is_empty() && !old.keeps(PathStrategy::CorrelationAwarePlanes23));
        let new = Layout::new(52, 3);
        assert_eq!(new.dimension(), 105 + 7);
        assert_eq!(new.heuristic_index(PathStrategy::Switch), Some(105));
        assert_eq!(new.heuristic_index(PathStrategy::CorrelationAwarePlanes23), Some(111));
        assert_eq!(new.heuristic_index(PathStrategy::Plane1), None);
        assert!(PathStrategy::ALL.iter().enumerate().all(|(i, s)| s.index() == i));
        assert_eq!((old.component_dimension(), new.component_dimension()), (105, 112));
    }

    #[test]
    fn format_4_keeps_the_sums_of_format_3_and_components_over_a_predictable_prefix() {
        let (three, four) = (Layout::new(52, 3), Layout::new(52, 4));
        assert_eq!(four.dimension(), three.dimension());
        assert_eq!(four.strategies(), three.strategies());
        assert_eq!(four.heuristics(), three.heuristics());
        assert_eq!(four.component_dimension(), 2 * 52 + 2);
        // The prefix ends with the H columns of COMPONENT_HEURISTICS, which are Y's first.
        for (i, h) in COMPONENT_HEURISTICS.iter().enumerate() {
            assert_eq!(four.heuristic_index(*h), Some(2 * 52 + 1 + i));
        }
        // Every heuristic a prediction at another budget stacks has its column in the prefix.
        for h in PathStrategy::STACKED.iter().filter(|h| !h.depends_on_budget()) {
            assert!(four.heuristic_index(*h).is_some_and(|i| i < four.component_dimension()), "{h:?}");
        }
    }
}
