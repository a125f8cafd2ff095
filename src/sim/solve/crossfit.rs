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
//! the standard error optimis gives for every recommended weight (and β), and for the gain
//! ([`super::noise`]): K = 10 gives 9 degrees of freedom. The cross-fitted RMS gets its standard
//! error from [`super::rms_error`]: a per-path row's delta method for the noise they share, the
//! paired jackknife over the folds for the difference.
//!
//! **Choosing λ** ([`select_lambda`]) follows the one-standard-error rule (Hastie, Tibshirani &
//! Friedman 2009, §7.10): among the λ whose cross-fitted RMS is within one jackknife SE of the
//! lowest, the largest — the smoothest weights the data cannot tell from the best — and never a
//! fit whose table weights change from fold to fold by more than [`UNSTABLE_STDERR`] (an *unstable* fit:
//! one seed in thirty once chose λ = 10⁻⁵ with weights from −0.9 to 2.1 that delivered more noise
//! than the switch).

use super::effective::FitReplicates;
use super::options::FixedWeights;
use super::rms_error::{FoldSums, RmsReference, references, rms_stderr};
pub use super::rms_error::{jackknife_se, rms_percent};
use super::solver::{Fit, SolveError, fit};
use super::ystats::YStats;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::moments::{FoldMoments, Moments};

/// Jackknife standard error of a table weight above which a fit is *unstable* from fold to fold
/// (the weights of a cell sum to one, so an error of 0.25 is a quarter of the whole range of
/// sensible weights). Only cells fitted to their own samples count: a smoothed cell's spread is
/// its neighbours'.
pub const UNSTABLE_STDERR: f64 = 0.25;

/// The moments as the cross-fits need them: all iterations, each fold, and each fold's complement.
#[derive(Debug, Clone)]
pub struct CrossFitting {
    /// The sums of all iterations (the all-data fit's).
    pub all: YStats,
    /// Fold f's sums (the test set of fit f).
    pub test: Vec<YStats>,
    /// All folds but f (the training set of fit f).
    pub train: Vec<YStats>,
    /// The per-path rows a fitted row's RMS error is taken through ([`super::rms_error`]); empty
    /// for predicted sums.
    pub references: Vec<RmsReference>,
}

impl CrossFitting {
    /// From `moments` and their folds added together (`pooled`, which the caller has anyway).
    pub fn new(moments: &Moments, pooled: &FoldMoments) -> Self {
        let layout = moments.layout();
        let all = YStats::from_fold(pooled, layout);
        let test: Vec<YStats> = moments.folds.iter().map(|f| YStats::from_fold(f, layout)).collect();
        // The complements in floating point: each is ≥ (K − 1)/K of the total, so the subtraction
        // loses nothing the covariance's own cancellation does not.
        let train = test.iter().map(|t| all.without(t)).collect();
        Self { all, test, train, references: references(moments) }
    }

    /// The cross-fitting of `all` split into the folds `test` (a subset of one run's folds).
    fn from_parts(all: YStats, test: Vec<YStats>) -> Self {
        let train = test.iter().map(|t| all.without(t)).collect();
        Self { all, test, train, references: Vec::new() }
    }

    /// The folds that hold iterations (an empty fold neither tests nor jackknifes anything).
    fn used(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.test.len()).filter(|&f| self.test[f].m > 0.0)
    }
}

/// One fitted strategy cross-fitted at one λ.
#[derive(Debug, Clone)]
pub struct CrossFit {
    /// The smoothness penalty λ every fold was fitted at.
    pub lambda: f64,
    /// The heuristics stacked on the table (empty: the table alone).
    pub family: Vec<PathStrategy>,
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

    /// Jackknife standard error of each stacked heuristic's β, in `family` order; `None` with
    /// fewer than two used folds.
    pub fn beta_stderr(&self) -> Option<Vec<f64>> {
        (self.folds.len() >= 2).then(|| {
            (0..self.family.len())
                .map(|i| jackknife_se(self.folds.iter().map(|(_, fit, _)| fit.heuristics[i].1)))
                .collect()
        })
    }

    /// The fold fits as jackknife replicates of the weight function.
    pub fn replicates(&self) -> FitReplicates {
        FitReplicates::of(self.folds.iter().map(|(_, fit, _)| fit))
    }

    /// The cross-fitted RMS% (of all scored folds).
    pub fn rms_percent(&self) -> Option<f64> {
        rms_percent(self.totals())
    }

    /// The scored sums per fold.
    pub fn fold_sums(&self) -> FoldSums {
        self.folds.iter().map(|(f, _, s)| (*f, *s)).collect()
    }

    /// Standard error of the cross-fitted RMS% ([`super::rms_error`]: through the best-determined
    /// per-path reference of `references`, else the jackknife over the scored folds); `None` with
    /// fewer than two folds or a replicate without a mean.
    pub fn rms_stderr(&self, references: &[RmsReference]) -> Option<f64> {
        rms_stderr(&self.fold_sums(), references)
    }

    /// The cells whose weights, fitted to their own samples (status `fitted` in `all`, the
    /// all-data fit at this λ), have a jackknife SE above [`UNSTABLE_STDERR`]. Only table cells can
    /// make a fit unstable: a cell's few events can hide from every test fold, so wild weights there
    /// pass the cross-validation and strike on new data; β multiplies a heuristic on every path,
    /// so a β that does not carry over shows in every fold's score (and near-collinear heuristics
    /// may trade β from fold to fold without changing the weights they make).
    pub fn instability(&self, all: &Fit) -> Vec<usize> {
        self.weight_stderr().map_or_else(Vec::new, |se| {
            (0..se.len())
                .filter(|&a| all.cells[a].status.from_data())
                .filter(|&a| se[a].iter().any(|&s| s > UNSTABLE_STDERR || s.is_nan()))
                .collect()
        })
    }
}

/// Cross-fits the optimal weights with `fixed`, penalty `lambda` and the heuristics `family`
/// stacked on the table.
pub fn cross_fit(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambda: f64,
    family: &[PathStrategy],
) -> Result<CrossFit, SolveError> {
    let layout = cf.all.layout;
    let folds = cf
        .used()
        .map(|f| {
            let fit = fit(&cf.train[f], grid, fixed, lambda, family)?;
            let (s1, s2) = cf.test[f].evaluate(&fit.coefficients(layout));
            Ok((f, fit, [cf.test[f].m, s1, s2]))
        })
        .collect::<Result<Vec<_>, SolveError>>()?;
    Ok(CrossFit { lambda, family: family.to_vec(), folds })
}

/// One λ of a selection: its cross-fit, the all-data fit, and how it scored.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The λ's cross-fit: the fold fits and their scored sums.
    pub cross_fit: CrossFit,
    /// The fit on all iterations at this λ (the weights a result recommends).
    pub all: Fit,
    /// The cross-fitted RMS% (finite).
    pub rms_percent: f64,
    /// Its standard error ([`super::rms_error`]), when one can be given.
    pub rms_stderr: Option<f64>,
    /// Cells whose data-fitted weights change from fold to fold by more than [`UNSTABLE_STDERR`].
    pub unstable_cells: Vec<usize>,
}

impl Scored {
    /// Whether no cell is unstable: only a stable fit may be recommended.
    pub fn is_stable(&self) -> bool {
        self.unstable_cells.is_empty()
    }
}

/// Cross-fits `family` at `lambda`, fits it on all iterations and scores it: the row of one λ.
pub fn score(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambda: f64,
    family: &[PathStrategy],
) -> Result<Scored, String> {
    let cross_fit = cross_fit(cf, grid, fixed, lambda, family).map_err(|e| e.to_string())?;
    let all =
        fit(&cf.all, grid, fixed, lambda, family).map_err(|e| format!("the fit on all iterations failed: {e}"))?;
    let rms_percent =
        cross_fit.rms_percent().filter(|r| r.is_finite()).ok_or("the cross-fitted mean is zero".to_string())?;
    let unstable_cells = cross_fit.instability(&all);
    let rms_stderr = cross_fit.rms_stderr(&cf.references);
    Ok(Scored { cross_fit, all, rms_percent, rms_stderr, unstable_cells })
}

/// The λ a selection chose, and every λ it scored (in grid order).
#[derive(Debug, Clone)]
pub struct Selection {
    /// The chosen λ's row (check [`Scored::is_stable`] before recommending it).
    pub chosen: Scored,
    /// Every λ that could be scored, in grid order.
    pub scored: Vec<Scored>,
}

/// Cross-fits every λ of `lambdas` and chooses one by the one-standard-error rule among the
/// eligible fits (stable, and within the trust region where the caller has one: `eligible`; module
/// docs): the largest λ whose cross-fitted RMS is within one jackknife SE of the lowest; if none
/// of those is eligible, the eligible λ with the lowest RMS; if no λ is eligible, the rule's λ
/// anyway (the caller sees that and must not recommend it). The failures of the λ that could not
/// be scored come back when none could.
pub fn select_lambda(
    cf: &CrossFitting,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambdas: &[f64],
    family: &[PathStrategy],
    eligible: &dyn Fn(&Scored) -> bool,
) -> Result<Selection, Vec<String>> {
    let mut scored: Vec<Scored> = Vec::new();
    let mut failures = Vec::new();
    for &lambda in lambdas {
        match score(cf, grid, fixed, lambda, family) {
            Ok(s) => scored.push(s),
            Err(e) => failures.push(format!("λ = {lambda}: {e}")),
        }
    }
    let best = scored.iter().min_by(|a, b| a.rms_percent.total_cmp(&b.rms_percent)).ok_or(failures)?;
    let threshold = best.rms_percent + best.rms_stderr.unwrap_or(0.0);
    let largest = |s: &&Scored| s.cross_fit.lambda;
    let within = || scored.iter().filter(|s| s.rms_percent <= threshold);
    let chosen = within()
        .filter(|s| eligible(s))
        .max_by(|a, b| largest(a).total_cmp(&largest(b)))
        .or_else(|| scored.iter().filter(|s| eligible(s)).min_by(|a, b| a.rms_percent.total_cmp(&b.rms_percent)))
        .or_else(|| within().max_by(|a, b| largest(a).total_cmp(&largest(b))))
        .expect("the best λ is within its own threshold")
        .clone();
    Ok(Selection { chosen, scored })
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
    family: &[PathStrategy],
) -> Result<[f64; 3], String> {
    let mut total = [0.0; 3];
    for f in cf.used() {
        let inner = CrossFitting::from_parts(
            cf.train[f].clone(),
            cf.used().filter(|&g| g != f).map(|g| cf.test[g].clone()).collect(),
        );
        let chosen =
            select_lambda(&inner, grid, fixed, lambdas, family, &Scored::is_stable).map_err(|e| e.join("; "))?;
        let (s1, s2) = cf.test[f].evaluate(&chosen.chosen.all.coefficients(cf.all.layout));
        total = [total[0] + cf.test[f].m, total[1] + s1, total[2] + s2];
    }
    Ok(total)
}

#[cfg(test)]
mod tests;
