//! The second-order sums of the moment vector Y over a set of iterations, as doubles: what a fit
//! and an evaluation of weights read (docs/model.md §7). Every weighting the solver knows — a
//! table, a table with heuristics stacked on it — makes the pixel value a linear form C_s = ⟨Y_s|v⟩
//! in a coefficient vector v, so Σ C_s = ⟨ΣY|v⟩ and Σ C_s² = vᵀΣYYᵀv.

use nalgebra::{DMatrix, DVector};

use crate::sim::engines::layout::Layout;
use crate::sim::math::exact_sum::ExactSum;
use crate::sim::stats::moments::{FoldMoments, packed_index};

/// A packed upper triangle of exact sums (side n) as a full symmetric matrix of doubles.
pub(crate) fn unpack(sums: &[ExactSum], n: usize) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(n, n);
    for i in 0..n {
        for j in i..n {
            let v = sums[packed_index(n, i, j)].value();
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
    m
}

/// Second-order sums of Y over a set of iterations, as plain doubles.
#[derive(Debug, Clone)]
pub struct YStats {
    /// What Y holds (its H columns).
    pub layout: Layout,
    /// Number of iterations.
    pub m: f64,
    /// ΣY.
    pub sum_y: DVector<f64>,
    /// ΣYYᵀ (full symmetric).
    pub sum_yy: DMatrix<f64>,
    /// Merge events per cell (all planes).
    pub cell_samples: Vec<u64>,
}

impl YStats {
    /// Reads the sums of a fold (or of pooled folds) of moments in `layout`.
    pub fn from_fold(fold: &FoldMoments, layout: Layout) -> Self {
        let (cells, n) = (layout.cells, layout.dimension());
        let sum_y = DVector::from_iterator(n, fold.sum_y.iter().map(|s| s.value()));
        let sum_yy = unpack(&fold.sum_yy, n);
        let cell_samples = (0..cells).map(|a| (0..3).map(|m| fold.cell_counts[m * cells + a]).sum()).collect();
        Self { layout, m: fold.iterations as f64, sum_y, sum_yy, cell_samples }
    }

    /// These sums without those of `part` (a subset of the same iterations).
    pub fn without(&self, part: &YStats) -> Self {
        Self {
            layout: self.layout,
            m: self.m - part.m,
            sum_y: &self.sum_y - &part.sum_y,
            sum_yy: &self.sum_yy - &part.sum_yy,
            cell_samples: self.cell_samples.iter().zip(&part.cell_samples).map(|(a, b)| a - b).collect(),
        }
    }

    /// Σ C_s and Σ C_s² of the pixel value C_s = ⟨Y_s|v⟩ for a coefficient vector `v` on Y
    /// (length n; [`super::solver::Fit::coefficients`] gives it for fitted weights).
    pub fn evaluate(&self, v: &DVector<f64>) -> (f64, f64) {
        let sum_c = self.sum_y.dot(v);
        let sum_c2 = v.dot(&(&self.sum_yy * v));
        (sum_c, sum_c2)
    }

    /// The sample covariance of Y with 1/M normalisation (what the solver minimises over; the
    /// minimiser does not depend on the normalisation).
    pub(crate) fn covariance(&self) -> DMatrix<f64> {
        let mean = &self.sum_y / self.m;
        &self.sum_yy / self.m - &mean * mean.transpose()
    }

    /// The luminance scale μ: mean of the plane-1, plane-2 and plane-3 estimates.
    pub(crate) fn scale(&self) -> f64 {
        let k = self.layout.cells;
        let sum_b = self.sum_y[2 * k];
        let sum_a0: f64 = self.sum_y.rows(0, k).sum();
        let sum_a1: f64 = self.sum_y.rows(k, k).sum();
        // plane1 = ΣA⁽⁰⁾ + B, plane2 = ΣA⁽¹⁾ + B, plane3 = B.
        (sum_a0 + sum_a1 + 3.0 * sum_b) / (3.0 * self.m)
    }
}
