//! The checks of moments read from outside that a parser cannot make (see `moments`, "Moments
//! read from outside"): [`check_well_formed`] — the shape, and on every fold that the sums agree
//! with their counts — and [`belongs_to`], whether they are a configuration's, radii included.
//! Free functions beside the types, so that `moments.rs` calls nothing here.

use super::moments::{FoldMoments, MergeError, Moments, packed_index};
use crate::sim::engines::layout::Layout;
use crate::sim::math::exact_sum::{ExactSum, MAX_MAGNITUDE};
use crate::sim::model::config::SimConfig;

/// Every check for moments read from outside (a file, a peer, a database row): the structure
/// and that the sums agree with their counts (see the module documentation of `moments`).
pub fn check_well_formed(moments: &Moments) -> Result<(), MergeError> {
    moments.check_shape()?;
    for (f, fold) in moments.folds.iter().enumerate() {
        check_consistent(fold, moments.layout()).map_err(|e| MergeError::Malformed(format!("fold {f}: {e}")))?;
    }
    // The shapes of the radii were checked with the run's; their sums here.
    for (i, sub) in moments.radii.iter().enumerate() {
        for (f, fold) in sub.folds.iter().enumerate() {
            check_consistent(fold, sub.layout())
                .map_err(|e| MergeError::Malformed(format!("radius #{i}, fold {f}: {e}")))?;
        }
    }
    Ok(())
}

/// Whether `moments` are `config`'s: its fingerprint (as their format spells it) and, radius by
/// radius, its smaller radii's — so that a document or checkpoint whose radii were dropped, added
/// or swapped is refused where its configuration is checked.
pub fn belongs_to(moments: &Moments, config: &SimConfig) -> bool {
    let of = |m: &Moments, c: &SimConfig| m.fingerprint == c.fingerprint_of_format(m.format_version);
    of(moments, config)
        && moments.radii.len() == config.radii().len()
        && moments.radii.iter().zip(config.radii()).all(|(m, c)| of(m, c))
}

/// What a parser cannot check of one fold: that the sums agree with their counts. Fails with the
/// first contradiction found.
fn check_consistent(fold: &FoldMoments, layout: Layout) -> Result<(), String> {
    let (cells, n) = (layout.cells, layout.dimension());
    if let Some(bad) = fold.sums().position(|s| !(s.is_finite() && s.value().abs() <= MAX_MAGNITUDE)) {
        return Err(format!("sum #{bad} is not finite or exceeds 2^1000"));
    }
    for m in 0..3 {
        let per_cell = fold.cell_counts[m * cells..(m + 1) * cells]
            .iter()
            .try_fold(0u64, |acc, &c| acc.checked_add(c))
            .ok_or("cell event counts overflow")?;
        if per_cell != fold.merges[m] {
            return Err(format!("plane {} has {} merge events but its cells count {per_cell}", m + 1, fold.merges[m]));
        }
        // For counts c_s ≥ 0: Σc ≤ Σc² ≤ (Σc)².
        let (total, squares) = (u128::from(fold.merges[m]), fold.merges_sq[m]);
        if squares < total || squares > total * total {
            return Err(format!(
                "plane {}'s sum of squared merge counts {squares} contradicts its total {total}",
                m + 1
            ));
        }
    }
    if fold.iterations == 0 {
        if fold.sums().any(|s| s.value() != 0.0) || fold.merges != [0; 3] {
            return Err("a fold without iterations holds non-zero sums".into());
        }
        return Ok(());
    }
    // Sums of squares and fourth powers are ≥ 0, and (Σx)² ≤ M·Σx² (Cauchy–Schwarz; a relative
    // slack of 10⁻⁹ covers the rounding of the values compared).
    let m = fold.iterations as f64;
    let cauchy = |sum: &ExactSum, squares: &ExactSum| {
        let (a, q) = (sum.value(), squares.value());
        q >= 0.0 && a * a <= m * q * (1.0 + 1e-9) + f64::MIN_POSITIVE
    };
    for i in 0..n {
        if !cauchy(&fold.sum_y[i], &fold.sum_yy[packed_index(n, i, i)]) {
            return Err(format!("ΣY[{i}] and ΣY[{i}]² contradict each other over {} iterations", fold.iterations));
        }
    }
    for (k, powers) in fold.strategies.iter().enumerate() {
        let name = layout.strategies()[k].name();
        if !cauchy(&powers[0], &powers[1]) || !cauchy(&powers[1], &powers[3]) {
            return Err(format!("the power sums of strategy {name} contradict each other"));
        }
    }
    Ok(())
}
