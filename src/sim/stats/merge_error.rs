//! Why two moments values cannot be merged, or a document's moments cannot be used — each
//! variant naming what differs (the configuration's fields when the caller knows both specs, the
//! iterations counted twice, the sums that would leave their bounds).

use super::coverage::Overlap;

/// Why two moments values cannot be merged (or a document cannot be used).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    /// A moments format this build does not read (`expected`: the one it writes).
    #[error(
        "moments format {found} is not supported (this build reads formats 2 and {expected}; format 1, written before K-fold cross-fitting, holds two folds of even and odd iterations that cannot be split into K folds: run the iterations again with this build)"
    )]
    Format {
        /// The format of the moments refused.
        found: u32,
        /// The format this build writes.
        expected: u32,
    },
    /// Moments of two formats: their sums differ in shape, so they cannot be added.
    #[error(
        "moments of format {found} cannot be merged with moments of format {expected}: format 2 (written before optimis kept the w0 = 0 heuristics and the stacked optimum's columns) lacks sums that format 3 keeps, and format 3's noise components cover entries that format 4's do not (moments without noise components are format 3 in every build since); merge documents of one format with each other, or run the iterations again with this build"
    )]
    FormatMix {
        /// The format of the moments merged in.
        found: u32,
        /// The format of the moments merged into.
        expected: u32,
    },
    /// Moments of another configuration: their fingerprints (or cell or fold counts) differ.
    #[error("{}", fingerprint_message(found, expected, differences))]
    Fingerprint {
        /// The fingerprint of the moments merged in.
        found: String,
        /// The fingerprint of the moments merged into.
        expected: String,
        /// The configuration fields that differ (`scene.l3: 9 vs 3`, merged in vs into), when the
        /// caller knows both specs (`sim::document::explained`); empty otherwise.
        differences: Vec<String>,
    },
    /// Iterations of the same seed on both sides (listed): adding them would count them twice.
    #[error("these iterations are already counted: {}", list(.0))]
    Overlap(Vec<Overlap>),
    /// The moments contradict themselves or their layout (e.g. array lengths that do not match
    /// the grid, a negative sum of squares, a fold's count that disagrees with its coverage).
    #[error("malformed moments: {0}")]
    Malformed(String),
    /// A counter would wrap or an exact sum would leave the representable range; nothing changed.
    #[error("the merged statistics would overflow: {0}")]
    Overflow(String),
}

fn fingerprint_message(found: &str, expected: &str, differences: &[String]) -> String {
    if differences.is_empty() {
        format!(
            "configuration fingerprints differ ({found} vs {expected}): the statistics were drawn under another \
             scene, R, N_F, N_B, cell grid or generator"
        )
    } else {
        format!(
            "the statistics were drawn under another configuration — {} (merged in vs merged into); only runs \
             of one configuration merge",
            differences.join(", ")
        )
    }
}

fn list(overlaps: &[Overlap]) -> String {
    overlaps.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
}
