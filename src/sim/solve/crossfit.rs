//! K-fold cross-fitting: honest figures for fitted weights, and the jackknife over the fold fits.
//!
//! The moments keep the sums of each fold f (the iterations s ≡ f mod K) apart. For a fitted
//! strategy at penalty λ, cross-fitting fits the weights W₋f on the other K − 1 folds and evaluates
//! them on fold f, whose iterations did not shape them: given W₋f, every C_s(W₋f) of fold f is an
//! unbiased estimate of L (the weights of each cell sum to one, model.md), and its spread is the
//! noise of weights fitted on (K − 1)/K of the data. Pooling Σ C and Σ C² over the folds gives L, its
//! standard error and the RMS% as for any strategy ([`super::noise`]). In-sample figures (weights
//! fitted and scored on the same iterations) are biased: the fit follows the noise of the very
//! iterations it is scored on, so their variance is too small and L leans towards whatever lowers it
//! (`tests::cross_fitting_is_unbiased_where_the_in_sample_fit_is_not` measures both).
//!
//! The K fits W₋f are also a delete-a-group jackknife (Efron & Stein; Shao & Tu 1995, §2.3) of the
//! all-data fit: Var̂(W) = (K − 1)/K · Σ_f (W₋f − W̄)², over the folds that hold iterations. It is
//! the standard error optimis gives for every recommended weight, and for the gain
//! ([`super::noise`]): K = 10 gives 9 degrees of freedom.

use super::options::FixedWeights;
use super::solver::{Fit, SolveError, fit};
use super::ystats::YStats;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// The moments as the cross-fits need them: all iterations, each fold, and each fold's complement.
#[derive(Debug, Clone)]
pub struct CrossFitting {
    pub all: YStats,
    /// Fold f's sums (the test set of fit f).
    pub test: Vec<YStats>,
    /// All folds but f (the training set of fit f).
    pub train: Vec<YStats>,
}

impl CrossFitting {
    /// From `moments` and their folds added together (`pooled`, which the caller has anyway).
    pub fn new(moments: &Moments, pooled: &FoldMoments) -> Self {
        let cells = moments.cells;
        let all = YStats::from_fold(pooled, cells);
        let test: Vec<YStats> = moments.folds.iter().map(|f| YStats::from_fold(f, cells)).collect();
        // The complements in floating point: each is ≥ (K − 1)/K of the total, so the subtraction
        // loses nothing the covariance's own cancellation does not.
        let train = test.iter().map(|t| all.without(t)).collect();
        Self { all, test, train }
    }

    /// The cross-fitting of `all` split into the folds `test` (a subset of one run's folds).
    fn from_parts(all: YStats, test: Vec<YStats>) -> Self {
        let train = test.iter().map(|t| all.without(t)).collect();
        Self { all, test, train }
    }

    /// The folds that hold iterations (an empty fold neither tests nor jackknifes anything).
    fn used(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.test.len()).filter(|&f| self.test[f].m > 0.0)
    }
}

/// One fitted strategy cross-fitted at one λ.
#[derive(Debug, Clone)]
pub struct CrossFit {
    pub lambda: f64,
    /// Per used fold f: f, the weights fitted without it, and (M_f, Σ C, Σ C²) of its iterations
    /// under those weights.
    pub folds: Vec<(usize, Fit, [f64; 3])>,
}

impl CrossFit {
    /// (M, Σ C, Σ C²) pooled over the folds, leaving out fold `left_out`.
    pub fn totals_except(&self, left_out: Option<usize>) -> [f64; 3] {
        let mut t = [0.0; 3];
        for (f, _, s) in &self.folds {
            if Some(*f) != left_out {
                for (a, b) in t.iter_mut().zip(s) {
                    *a += b;
                }
            }
        }
        t
    }

    /// (M, Σ C, Σ C²) pooled over every fold: the cross-fitted sums.
    pub fn totals(&self) -> [f64; 3] {
        self.totals_except(None)
    }

    /// Jackknife standard errors of each cell's (w0, w1, w2) from the fold fits (module docs);
    /// `None` with fewer than two used folds.
    pub fn weight_stderr(&self) -> Option<Vec<[f64; 3]>> {
        let k = self.folds.len();
        if k < 2 {
            return None;
        }
        let cells = self.folds[0].1.cells.len();
        Some(
            (0..cells)
                .map(|a| std::array::from_fn(|m| jackknife_se(self.folds.iter().map(|(_, fit, _)| fit.cells[a].w[m]))))
                .collect(),
        )
    }
}

/// The jackknife standard error of leave-one-group-out replicates: √((K − 1)/K · Σ (θ₋f − θ̄)²).
pub fn jackknife_se(replicates: impl Iterator<Item = f64> + Clone) -> f64 {
    let k = replicates.clone().count() as f64;
    let mean = replicates.clone().sum::<f64>() / k;
    ((k - 1.0) / k * replicates.map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt()
}

/// Cross-fits the optimal weights with `fixed` and penalty `lambda`.
pub fn cross_fit(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambda: f64,
) -> Result<CrossFit, SolveError> {
    let folds = cf
        .used()
        .map(|f| {
            let fit = fit(&cf.train[f], grid, fixed, lambda)?;
            let (s1, s2) = cf.test[f].evaluate(&fit.vector());
            Ok((f, fit, [cf.test[f].m, s1, s2]))
        })
        .collect::<Result<Vec<_>, SolveError>>()?;
    Ok(CrossFit { lambda, folds })
}

/// The λ of `lambdas` with the lowest cross-fitted RMS, with its cross-fit.
pub fn select_lambda(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambdas: &[f64],
) -> Result<CrossFit, Vec<String>> {
    let mut best: Option<(f64, CrossFit)> = None;
    let mut failures = Vec::new();
    for &lambda in lambdas {
        match cross_fit(cf, grid, fixed, lambda) {
            Ok(c) => match relative_noise(c.totals()) {
                Some(r) if best.as_ref().is_none_or(|(b, _)| r < *b) => best = Some((r, c)),
                Some(_) => {}
                None => failures.push(format!("λ = {lambda}: the cross-fitted mean is zero")),
            },
            Err(e) => failures.push(format!("λ = {lambda}: {e}")),
        }
    }
    best.map(|(_, c)| c).ok_or(failures)
}

/// Var/mean² of pooled sums (M, Σ C, Σ C²): the squared relative RMS, for ranking.
fn relative_noise([m, s1, s2]: [f64; 3]) -> Option<f64> {
    let mean = s1 / m;
    (m >= 2.0 && mean != 0.0).then(|| (s2 / m - mean * mean).max(0.0) / (mean * mean))
}

/// Nested cross-validation of the whole `optimal_cv` procedure, λ selection included: for each
/// outer fold f, λ is chosen by cross-fitting on the other folds alone, the weights are fitted on
/// them at that λ and scored on fold f. The pooled (M, Σ C, Σ C²) are honest for the procedure; the
/// gap to `optimal_cv`'s cross-fitted figure (whose folds also chose λ) measures how optimistic
/// the selection is. Costs K times a λ search: an on-demand measurement (`optimis report
/// --nested-cv`), not part of every result.
pub fn nested_selection(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambdas: &[f64],
) -> Result<[f64; 3], String> {
    let mut total = [0.0; 3];
    for f in cf.used() {
        let inner = CrossFitting::from_parts(
            cf.train[f].clone(),
            cf.used().filter(|&g| g != f).map(|g| cf.test[g].clone()).collect(),
        );
        let chosen = select_lambda(&inner, grid, fixed, lambdas).map_err(|e| e.join("; "))?;
        let w = fit(&inner.all, grid, fixed, chosen.lambda).map_err(|e| e.to_string())?.vector();
        let (s1, s2) = cf.test[f].evaluate(&w);
        total = [total[0] + cf.test[f].m, total[1] + s1, total[2] + s2];
    }
    Ok(total)
}

#[cfg(test)]
#[path = "crossfit_tests.rs"]
mod tests;
