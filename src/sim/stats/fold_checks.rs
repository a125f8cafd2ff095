//! The checks of one fold's sums that a parser cannot make (see `moments`, "Moments read from
//! outside"): that the sums agree with their counts; and [`Moments::check_well_formed`], which
//! runs them on every fold (here, so that `moments.rs` calls nothing of this file).

use super::moments::{FoldMoments, MergeError, Moments, packed_index};
use crate::sim::engines::layout::Layout;
use crate::sim::math::exact_sum::{ExactSum, MAX_MAGNITUDE};

impl Moments {
    /// Every check for moments read from outside (a file, a peer, a database row): the structure
    /// and that the sums agree with their counts (see the module documentation of `moments`).
    pub fn check_well_formed(&self) -> Result<(), MergeError> {
        self.check_shape()?;
        for (f, fold) in self.folds.iter().enumerate() {
            fold.check_consistent(self.layout()).map_err(|e| MergeError::Malformed(format!("fold {f}: {e}")))?;
        }
        Ok(())
    }
}

impl FoldMoments {
    /// What a parser cannot check: that the sums agree with their counts. Fails with the first
    /// contradiction found.
    fn check_consistent(&self, layout: Layout) -> Result<(), String> {
        let (cells, n) = (layout.cells, layout.dimension());
        if let Some(bad) = self.sums().position(|s| !(s.is_finite() && s.value().abs() <= MAX_MAGNITUDE)) {
            return Err(format!("sum #{bad} is not finite or exceeds 2^1000"));
        }
        for m in 0..3 {
            let per_cell = self.cell_counts[m * cells..(m + 1) * cells]
                .iter()
                .try_fold(0u64, |acc, &c| acc.checked_add(c))
                .ok_or("cell event counts overflow")?;
            if per_cell != self.merges[m] {
                return Err(format!(
                    "plane {} has {} merge events but its cells count {per_cell}",
                    m + 1,
                    self.merges[m]
                ));
            }
            // For counts c_s ≥ 0: Σc ≤ Σc² ≤ (Σc)².
            let (total, squares) = (u128::from(self.merges[m]), self.merges_sq[m]);
            if squares < total || squares > total * total {
                return Err(format!(
                    "plane {}'s sum of squared merge counts {squares} contradicts its total {total}",
                    m + 1
                ));
            }
        }
        if self.iterations == 0 {
            if self.sums().any(|s| s.value() != 0.0) || self.merges != [0; 3] {
                return Err("a fold without iterations holds non-zero sums".into());
            }
            return Ok(());
        }
        // Sums of squares and fourth powers are ≥ 0, and (Σx)² ≤ M·Σx² (Cauchy–Schwarz; a relative
        // slack of 10⁻⁹ covers the rounding of the values compared).
        let m = self.iterations as f64;
        let cauchy = |sum: &ExactSum, squares: &ExactSum| {
            let (a, q) = (sum.value(), squares.value());
            q >= 0.0 && a * a <= m * q * (1.0 + 1e-9) + f64::MIN_POSITIVE
        };
        for i in 0..n {
            if !cauchy(&self.sum_y[i], &self.sum_yy[packed_index(n, i, i)]) {
                return Err(format!("ΣY[{i}] and ΣY[{i}]² contradict each other over {} iterations", self.iterations));
            }
        }
        for (k, powers) in self.strategies.iter().enumerate() {
            let name = layout.strategies()[k].name();
            if !cauchy(&powers[0], &powers[1]) || !cauchy(&powers[1], &powers[3]) {
                return Err(format!("the power sums of strategy {name} contradict each other"));
            }
        }
        Ok(())
    }
}
