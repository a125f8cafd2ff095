//! The second-order sums of the moment vector Y over a set of iterations, as doubles: what a fit
//! and an evaluation of weights read (model.md, "moments, optimum").

use nalgebra::{DMatrix, DVector};

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
    /// Reads the sums of a fold (or of pooled folds).
    pub fn from_fold(fold: &FoldMoments, cells: usize) -> Self {
        let n = 2 * cells + 1;
        let sum_y = DVector::from_iterator(n, fold.sum_y.iter().map(|s| s.value()));
        let sum_yy = unpack(&fold.sum_yy, n);
        let cell_samples = (0..cells).map(|a| (0..3).map(|m| fold.cell_counts[m * cells + a]).sum()).collect();
        Self { m: fold.iterations as f64, sum_y, sum_yy, cell_samples }
    }

    /// These sums without those of `part` (a subset of the same iterations).
    pub fn without(&self, part: &YStats) -> Self {
        Self {
            m: self.m - part.m,
            sum_y: &self.sum_y - &part.sum_y,
            sum_yy: &self.sum_yy - &part.sum_yy,
            cell_samples: self.cell_samples.iter().zip(&part.cell_samples).map(|(a, b)| a - b).collect(),
        }
    }

    fn cells(&self) -> usize {
        self.cell_samples.len()
    }

    /// Σ C_s(W) and Σ C_s(W)² for full weights `w` (length 2K).
    pub fn evaluate(&self, w: &DVector<f64>) -> (f64, f64) {
        let k2 = 2 * self.cells();
        let sum_a = self.sum_y.rows(0, k2);
        let sum_b = self.sum_y[k2];
        let s_aa = self.sum_yy.view((0, 0), (k2, k2));
        let s_ab = self.sum_yy.view((0, k2), (k2, 1));
        let s_bb = self.sum_yy[(k2, k2)];
        let sum_c = sum_a.dot(w) + sum_b;
        let sum_c2 = (w.transpose() * s_aa * w)[(0, 0)] + 2.0 * s_ab.column(0).dot(w) + s_bb;
        (sum_c, sum_c2)
    }

    /// The luminance scale μ: mean of the plane-1, plane-2 and plane-3 estimates.
    pub(crate) fn scale(&self) -> f64 {
        let k = self.cells();
        let sum_b = self.sum_y[2 * k];
        let sum_a0: f64 = self.sum_y.rows(0, k).sum();
        let sum_a1: f64 = self.sum_y.rows(k, k).sum();
        // plane1 = ΣA⁽⁰⁾ + B, plane2 = ΣA⁽¹⁾ + B, plane3 = B.
        (sum_a0 + sum_a1 + 3.0 * sum_b) / (3.0 * self.m)
    }
}
