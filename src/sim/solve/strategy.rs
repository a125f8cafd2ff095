//! The strategies of a noise table: the per-path ones, whose weights the engines apply to every
//! merge (`PathStrategy`), and the fitted ones, whose weights come from the moments.
//!
//! Results name them in snake case (`plane1` … `optimal_cv`); code compares the enum, never the
//! names.

use serde::{Deserialize, Serialize};

use crate::sim::engines::tally::PathStrategy;

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
        }
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
        ] {
            assert_eq!(serde_json::to_value(s).unwrap(), s.name());
        }
        for p in PathStrategy::ALL {
            assert_eq!(Strategy::of_path(p).name(), p.name());
        }
    }
}
