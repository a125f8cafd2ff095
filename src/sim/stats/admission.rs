//! What one iteration's tally must be before any of it is added to a moments value or a worker's
//! sums: tallied at as many smaller radii as they keep, and every value small enough that no sum
//! of products of up to four of them can leave the doubles.

use super::merge_error::MergeError;
use crate::sim::engines::tally::IterationTally;

/// Largest magnitude of one iteration's normalised values: products of up to four of them enter the
/// sums, and beyond 10⁷⁰ they would leave the doubles.
pub const MAX_TALLY_VALUE: f64 = 1e70;

/// Refuses an iteration whose values could overflow a sum: products of up to four values enter
/// the sums (ΣYYᵀ, Σ C⁴), and beyond 10⁷⁰ they would leave the doubles. No valid scene comes near
/// (its values are below 10⁴⁰), so this only stops a configuration the validation did not foresee,
/// as an error instead of a poisoned sum.
pub(super) fn check_representable(tally: &IterationTally) -> Result<(), MergeError> {
    let representable = |v: f64| v.is_finite() && v.abs() <= MAX_TALLY_VALUE;
    if tally.cell_values.iter().all(|&v| representable(v)) && tally.strategies.iter().all(|&v| representable(v)) {
        Ok(())
    } else {
        Err(MergeError::Overflow(format!(
            "iteration {} produced a contribution beyond {MAX_TALLY_VALUE:e} (an extreme scene)",
            tally.iteration
        )))
    }
}

/// What an iteration must be before anything of it is added to moments (or a worker's sums) that
/// keep `radii` smaller radii: tallied at as many radii, and every value representable — checked
/// first, so that an iteration is refused whole (only a counter overflow, beyond 2^64 merges,
/// could still stop it part-way).
pub(super) fn check_iteration(tally: &IterationTally, radii: usize) -> Result<(), MergeError> {
    if tally.radii.len() != radii {
        return Err(MergeError::Malformed(format!(
            "an iteration tallied at {} smaller radii for moments that keep {radii}",
            tally.radii.len()
        )));
    }
    check_representable(tally)?;
    tally.radii.iter().try_for_each(check_representable)
}
