//! The strategies of a noise table: the per-path ones, whose weights the engines apply to every
//! merge (`PathStrategy`), and the fitted ones, whose weights come from the moments — a table
//! alone (`optimal`, `optimal_holdout`, `optimal_cv`), a table with every admitted heuristic
//! stacked on it (`optimal_stacked`), or one heuristic corrected by a table (`…_corrected`).
//!
//! Results name them in snake case (`plane1` … `optimal_cv`); code compares the enum, never the
//! names.

use serde::{Deserialize, Serialize};

use crate::sim::engines::strategies::PathStrategy;

/// A row of the noise table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    /// Case 1: w0 = 1.
    Plane1,
    /// Case 2: w1 = 1.
    Plane2,
    /// Case 3: w2 = 1.
    Plane3,
    /// Case 4: plane 2 inside the spot (r3 ≤ a), plane 3 outside.
    Switch,
    /// Case 5: the optimal weights, fitted and scored on all iterations (the paper's procedure).
    Optimal,
    /// The optimal weights at the spec's λ, K-fold cross-fitted (each fold scored with the weights
    /// fitted on the others).
    OptimalHoldout,
    /// λ chosen on the grid by the cross-fitted RMS; cross-fitted figures at that λ (the
    /// recommended weights are this λ fitted on all iterations).
    OptimalCv,
    /// Veach's balance heuristic with VCM pdfs.
    Balance,
    /// Veach's power heuristic with VCM pdfs.
    Power,
    /// The correlation-aware balance heuristic (Grittmann et al. 2021) for this estimator.
    CorrelationAware,
    /// The balance heuristic over planes 2 and 3 (w0 = 0).
    BalancePlanes23,
    /// The power heuristic over planes 2 and 3 (w0 = 0).
    PowerPlanes23,
    /// The correlation-aware heuristic over planes 2 and 3 (w0 = 0).
    CorrelationAwarePlanes23,
    /// The stacked optimum: a table plus β_h times the switch and the correlation-aware
    /// heuristics that keep the fixed weights, λ chosen by cross-validation, cross-fitted figures
    /// (docs/model.md §7).
    OptimalStacked,
    /// The switch corrected by a table (β fitted too), at the stacked optimum's λ.
    SwitchCorrected,
    /// The balance heuristic corrected by a table.
    BalanceCorrected,
    /// The power heuristic corrected by a table.
    PowerCorrected,
    /// The correlation-aware heuristic corrected by a table.
    CorrelationAwareCorrected,
    /// The balance heuristic over planes 2–3 corrected by a table.
    BalancePlanes23Corrected,
    /// The power heuristic over planes 2–3 corrected by a table.
    PowerPlanes23Corrected,
    /// The correlation-aware heuristic over planes 2–3 corrected by a table.
    CorrelationAwarePlanes23Corrected,
}

impl Strategy {
    /// The noise-table row of a per-path strategy.
    pub fn of_path(strategy: PathStrategy) -> Self {
        match strategy {
            PathStrategy::Plane1 => Self::Plane1,
            PathStrategy::Plane2 => Self::Plane2,
            PathStrategy::Plane3 => Self::Plane3,
            PathStrategy::Switch => Self::Switch,
            PathStrategy::Balance => Self::Balance,
            PathStrategy::Power => Self::Power,
            PathStrategy::CorrelationAware => Self::CorrelationAware,
            PathStrategy::BalancePlanes23 => Self::BalancePlanes23,
            PathStrategy::PowerPlanes23 => Self::PowerPlanes23,
            PathStrategy::CorrelationAwarePlanes23 => Self::CorrelationAwarePlanes23,
        }
    }

    /// The per-path strategy of this row, if it is one.
    pub fn path(self) -> Option<PathStrategy> {
        PathStrategy::ALL.into_iter().find(|&p| Self::of_path(p) == self)
    }

    /// The row of heuristic `h` corrected by a table (`None` for the single-plane cases, which a
    /// table already contains).
    pub fn corrected(h: PathStrategy) -> Option<Self> {
        Some(match h {
            PathStrategy::Switch => Self::SwitchCorrected,
            PathStrategy::Balance => Self::BalanceCorrected,
            PathStrategy::Power => Self::PowerCorrected,
            PathStrategy::CorrelationAware => Self::CorrelationAwareCorrected,
            PathStrategy::BalancePlanes23 => Self::BalancePlanes23Corrected,
            PathStrategy::PowerPlanes23 => Self::PowerPlanes23Corrected,
            PathStrategy::CorrelationAwarePlanes23 => Self::CorrelationAwarePlanes23Corrected,
            PathStrategy::Plane1 | PathStrategy::Plane2 | PathStrategy::Plane3 => return None,
        })
    }

    /// Whether the row's weights are fitted to the moments (a table, with or without heuristics).
    pub fn is_fitted(self) -> bool {
        self.path().is_none()
    }

    /// Whether the row's figures are scored on the iterations its weights were fitted to, and so
    /// optimistic: such rows are labelled `in_sample` and never "best". Only `optimal` (the paper's
    /// procedure): every other fitted row is cross-fitted.
    pub fn is_in_sample(self) -> bool {
        matches!(self, Self::Optimal)
    }

    /// The name results use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Plane1 => "plane1",
            Self::Plane2 => "plane2",
            Self::Plane3 => "plane3",
            Self::Switch => "switch",
            Self::Optimal => "optimal",
            Self::OptimalHoldout => "optimal_holdout",
            Self::OptimalCv => "optimal_cv",
            Self::Balance => "balance",
            Self::Power => "power",
            Self::CorrelationAware => "correlation_aware",
            Self::BalancePlanes23 => "balance_planes23",
            Self::PowerPlanes23 => "power_planes23",
            Self::CorrelationAwarePlanes23 => "correlation_aware_planes23",
            Self::OptimalStacked => "optimal_stacked",
            Self::SwitchCorrected => "switch_corrected",
            Self::BalanceCorrected => "balance_corrected",
            Self::PowerCorrected => "power_corrected",
            Self::CorrelationAwareCorrected => "correlation_aware_corrected",
            Self::BalancePlanes23Corrected => "balance_planes23_corrected",
            Self::PowerPlanes23Corrected => "power_planes23_corrected",
            Self::CorrelationAwarePlanes23Corrected => "correlation_aware_planes23_corrected",
        }
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_serialised_names_and_path_strategies_keep_theirs() {
        for s in [
            Strategy::Plane1,
            Strategy::Switch,
            Strategy::OptimalHoldout,
            Strategy::OptimalCv,
            Strategy::Power,
            Strategy::CorrelationAware,
            Strategy::CorrelationAwarePlanes23,
            Strategy::OptimalStacked,
            Strategy::CorrelationAwarePlanes23Corrected,
        ] {
            assert_eq!(serde_json::to_value(s).unwrap(), s.name());
        }
        for p in PathStrategy::ALL {
            assert_eq!(Strategy::of_path(p).name(), p.name());
            assert_eq!(Strategy::of_path(p).path(), Some(p));
            if let Some(c) = Strategy::corrected(p) {
                assert_eq!(c.name(), format!("{}_corrected", p.name()));
                assert!(c.is_fitted());
            }
        }
        assert_eq!(PathStrategy::STACKABLE.iter().filter_map(|&h| Strategy::corrected(h)).count(), 7);
    }
}
