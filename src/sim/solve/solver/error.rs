//! Why a fit fails: too few iterations, no signal, a singular system (naming what the data leave
//! undetermined, and what would determine it), or a heuristic that cannot be stacked.

use crate::sim::engines::strategies::PathStrategy;

/// Why no optimal weights could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Fewer than two iterations: no variance to minimise.
    #[error("at least 2 iterations are needed to estimate a variance, got {0}")]
    TooFewIterations(u64),
    /// Every contribution is zero.
    #[error("no merge events: every contribution is zero, there is nothing to weight")]
    NoSignal,
    /// The normal equations are rank-deficient: the data do not determine the listed cells'
    /// weights, or the stacked heuristics' coefficients β (`rank` of `dimension` free weights).
    #[error(
        "the weight system is singular (rank {rank} of {dimension}): the data do not determine {}; {}",
        undetermined(.cells, *.heuristic_terms),
        remedy(.cells)
    )]
    Singular {
        /// Free weights in the system.
        dimension: usize,
        /// The rank the data give it.
        rank: usize,
        /// The cells α whose weights are undetermined.
        cells: Vec<usize>,
        /// How many stacked heuristics' coefficients β take part in the undetermined directions
        /// (then their per-iteration values are collinear with each other or with the table's).
        heuristic_terms: usize,
    },
    /// A heuristic that cannot be stacked: its weights break the fixed weights, or the moments'
    /// format has no column for it.
    #[error(
        "{} cannot be stacked: its weights break the solver's fixed weights, or these moments (an older format) do not keep its column",
        .0.name()
    )]
    NotStackable(PathStrategy),
}

/// What a singular system leaves undetermined, for [`SolveError::Singular`]'s message: the cells,
/// the heuristics' coefficients, or both (never an empty list of cells).
fn undetermined(cells: &[usize], heuristic_terms: usize) -> String {
    let betas = match heuristic_terms {
        0 => None,
        1 => Some("the coefficient β of one stacked heuristic".to_string()),
        n => Some(format!("the coefficients β of {n} stacked heuristics")),
    };
    match (cells.is_empty(), betas) {
        (false, None) => format!("the weights of cells {cells:?}"),
        (false, Some(b)) => format!("the weights of cells {cells:?} and {b}"),
        (true, Some(b)) => b,
        (true, None) => "the weights (no single cell: a combination of them)".to_string(),
    }
}

/// What resolves a singular system: the penalty, a fixed weight or coarser cells act on the
/// cells; only more data determine the heuristics' coefficients.
fn remedy(cells: &[usize]) -> &'static str {
    if cells.is_empty() {
        "run more iterations"
    } else {
        "add a gradient penalty (solver.lambda > 0), fix a weight, use coarser cells or run more iterations"
    }
}
