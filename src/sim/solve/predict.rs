//! The noise table and the optimal weights at another ray budget (N_F', N_B'), predicted from one
//! run's noise components (`stats::components`, docs/model.md §12).
//!
//! For every entry of the moment vector's covariance and every per-path strategy's variance, the
//! run gives unbiased estimates of the three components α (scaled by 1/(N_F N_B)), β (1/N_F) and
//! δ (1/N_B); the prediction is V' = α/(N_F' N_B') + β/N_F' + δ/N_B'. The means do not depend on the
//! budget (every strategy is unbiased for L). The predicted sums are handed to the same solver and
//! cross-fitting as a measured noise table: the optimum is *re-fitted* for the new budget (its
//! weights change with it — the paper's point), λ chosen by cross-validation, and its figure is
//! cross-fitted (weights fitted on the other folds' predicted sums, scored on each fold's).
//!
//! Standard errors: a per-path strategy's predicted RMS gets the jackknife over the folds (each
//! replicate predicts from all folds but one); `luminance_stderr` is the standard error of L that
//! as many iterations as the run had would give at the new budget. Strategies whose weights
//! depend on N_F and N_B (`correlation_aware`) cannot be predicted at another budget: their row
//! says so.
//!
//! The row recommended at another budget is chosen, by the same guard as a job's result, among the
//! rows whose prediction the run supports ([`supported`]: the predicted RMS known within
//! [`SUPPORT_RELATIVE_SE`] of itself). Far from the measured budget a predicted variance can come
//! out near zero, and the lowest of several rows would be chosen for its noise: measured on 30
//! paper runs (docs/results.md §10), one recommended switch on 13.4 ± 4.4% that delivers 20.3%.
//! The other rows stay in the table, listed in [`Prediction::unsupported`].

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::crossfit::{CrossFitting, Scored, jackknife_se, select_lambda};
use super::fitted::{Fitted, scored_row};
use super::noise::{NoiseRow, respects_fixed};
use super::options::SolverOptions;
use super::recommend::{FoldSums, recommend};
use super::report::{RecommendedWeights, WeightRow, weight_rows};
use super::solver::stack_family;
use super::strategy::Strategy;
use super::ystats::{YStats, unpack};
use crate::sim::engines::layout::Layout;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::components::{CAMERA, CROSS, LIGHT};
use crate::sim::stats::moments::{FoldMoments, Moments};

/// Light and camera paths per iteration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Budget {
    /// N_F: light paths per iteration.
    pub light_paths: u64,
    /// N_B: camera paths per iteration.
    pub camera_paths: u64,
}

/// A predicted RMS whose standard error exceeds this fraction of it is not supported by the run:
/// it is shown but not recommended, and a budget plan does not count it. A time to a target goes
/// as R², so such a figure's time is uncertain by more than ±50% at one SE, where the first-order
/// (delta-method or jackknife) SE no longer describes it — one SE low, R gives 1/0.75² = 1.8× the
/// speed-up, one SE high 1/1.25² = 0.64× — and the lowest of several such figures is picked mostly
/// for its noise (the winner's curse). Measured on 30 paper runs of 2·10⁴ iterations
/// (docs/results.md §10): without the limit, 2 of 30 budget plans headlined 200–750× ±
/// 1,000–4,800 where the rest cluster at 19 ± 8, and one prediction at (10⁷, 1000) recommended
/// switch on 13.4 ± 4.4% where it delivers 20.3%.
pub const SUPPORT_RELATIVE_SE: f64 = 0.25;

/// Whether a predicted RMS `rms` (in %) with standard error `stderr` is supported by the run: the
/// SE is at most [`SUPPORT_RELATIVE_SE`] of the RMS (a figure without an SE is not supported).
pub fn supported(rms: f64, stderr: Option<f64>) -> bool {
    stderr.is_some_and(|se| se <= SUPPORT_RELATIVE_SE * rms)
}

/// Why no prediction can be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PredictError {
    /// The moments were run without `noise_components`: nothing to predict from.
    #[error(
        "these moments keep no noise components: run the job with \"noise_components\": true (even light_paths and camera_paths) to predict other budgets"
    )]
    NoComponents,
    /// Fewer than two iterations: the components' variances cannot be estimated.
    #[error("at least 2 iterations are needed, got {0}")]
    TooFewIterations(u64),
}

/// The predicted noise table and re-fitted weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Prediction {
    /// The budget predicted for.
    pub budget: Budget,
    /// The budget the run measured.
    pub measured: Budget,
    /// Iterations of the run (the standard errors of L are for as many at the new budget).
    pub iterations: u64,
    /// The run's cross-fitting folds K.
    pub folds: usize,
    /// Rows as in a job's noise table: the per-path strategies, then `optimal_cv` and
    /// `optimal_stacked` re-fitted for the new budget (cross-fitted, with the jackknife SE of
    /// their RMS over the folds; the stacked family without the heuristics whose weights depend
    /// on the budget).
    pub noise_table: Vec<NoiseRow>,
    /// The row recommended at the new budget, by the same guard as a job's result.
    pub recommended: Option<RecommendedWeights>,
    /// Its re-fitted table (fitted on all folds' predicted sums), with jackknife standard errors;
    /// empty when a per-path strategy is recommended.
    pub weights: Vec<WeightRow>,
    /// Why there are no re-fitted weights, if there are none.
    pub solve_error: Option<String>,
    /// The rows with a figure that this run does not support at the new budget (their RMS SE
    /// above `support_relative_se` of the RMS): shown in the table, never recommended. Empty at
    /// the measured budget, where nothing is extrapolated.
    #[serde(default)]
    pub unsupported: Vec<Strategy>,
    /// The fraction of its RMS that a row's RMS SE may reach for the row to be supported
    /// (`SUPPORT_RELATIVE_SE`).
    #[serde(default = "support_limit")]
    pub support_relative_se: f64,
}

fn support_limit() -> f64 {
    SUPPORT_RELATIVE_SE
}

/// The rows a recommendation at `to` may choose from, and the strategies left out: at the
/// measured budget every row; at another, the rows whose figure the run supports ([`supported`]).
/// Rows without a figure (an error, or no RMS) are kept: the guard already passes them by.
fn recommendable(rows: &[NoiseRow], from: Budget, to: Budget) -> (Vec<NoiseRow>, Vec<Strategy>) {
    if from == to {
        return (rows.to_vec(), Vec::new());
    }
    let (mut kept, mut left) = (Vec::new(), Vec::new());
    for row in rows {
        match row.rms_percent {
            Some(rms) if row.error.is_none() && rms.is_finite() && !supported(rms, row.rms_percent_stderr) => {
                left.push(row.strategy)
            }
            _ => kept.push(row.clone()),
        }
    }
    (kept, left)
}

/// " — not considered …" for a recommendation's reason when `left` were left out of `rows`.
fn left_out_note(rows: &[NoiseRow], left: &[Strategy]) -> String {
    if left.is_empty() {
        return String::new();
    }
    let named: Vec<String> = left
        .iter()
        .filter_map(|s| rows.iter().find(|r| r.strategy == *s))
        .map(|r| match (r.rms_percent, r.rms_percent_stderr) {
            (Some(v), Some(se)) => format!("{} ({v:.1} ± {se:.1}%)", r.strategy),
            (Some(v), None) => format!("{} ({v:.1}%, no SE)", r.strategy),
            _ => r.strategy.to_string(),
        })
        .collect();
    format!(
        "; not considered, their predictions not supported by this run (SE above {:.0}% of the RMS): {}",
        SUPPORT_RELATIVE_SE * 100.0,
        named.join(", ")
    )
}

/// Second-order and component sums of a set of iterations, as doubles.
#[derive(Debug, Clone)]
struct ComponentStats {
    y: YStats,
    /// ΣU_L, ΣU_C, ΣU_0 (full symmetric).
    parts: [DMatrix<f64>; 3],
    /// Per path strategy: Σ C, Σ C², and ΣU_L, ΣU_C, ΣU_0 of its C_s.
    strategies: Vec<[f64; 5]>,
}

/// One covariance entry at `to` from its estimate `v` at `from` and the means of the block
/// products `u` = (Ū_L, Ū_C, Ū_0) (module documentation of `stats::components`).
fn rescale(v: f64, [ul, uc, u0]: [f64; 3], from: Budget, to: Budget) -> f64 {
    let (f, b) = (from.light_paths as f64, from.camera_paths as f64);
    let (f2, b2) = (to.light_paths as f64, to.camera_paths as f64);
    let beta = 0.5 * f * (ul - u0);
    let delta = 0.5 * b * (uc - u0);
    let alpha = f * b * (v - beta / f - delta / b);
    alpha / (f2 * b2) + beta / f2 + delta / b2
}

impl ComponentStats {
    fn from_fold(fold: &FoldMoments, layout: Layout) -> Option<Self> {
        let c = fold.components.as_ref()?;
        // The components cover Y's first n_c entries (engines::layout): the rest stay zero, and
        // `predict` keeps those entries as measured.
        let (n, n_c) = (layout.dimension(), layout.component_dimension());
        let parts = [LIGHT, CAMERA, CROSS].map(|k| {
            let mut full = DMatrix::zeros(n, n);
            full.view_mut((0, 0), (n_c, n_c)).copy_from(&unpack(c.matrix(k), n_c));
            full
        });
        let strategies = fold
            .strategies
            .iter()
            .zip(&c.strategies)
            .map(|(p, u)| [p[0].value(), p[1].value(), u[0].value(), u[1].value(), u[2].value()])
            .collect();
        Some(Self { y: YStats::from_fold(fold, layout), parts, strategies })
    }

    fn without(&self, part: &Self) -> Self {
        Self {
            y: self.y.without(&part.y),
            parts: std::array::from_fn(|k| &self.parts[k] - &part.parts[k]),
            strategies: self
                .strategies
                .iter()
                .zip(&part.strategies)
                .map(|(a, b)| std::array::from_fn(|i| a[i] - b[i]))
                .collect(),
        }
    }

    /// The sums a measured run at `to` would be expected to have (same M and ΣY; ΣYYᵀ from the
    /// predicted covariance), for the solver. None with fewer than 2 iterations. Entries beyond
    /// the components' n_c (the H columns of heuristics no prediction stacks, format 4) keep
    /// their measured value: finite, so that products with the zero weights of those columns
    /// stay zero, and never read for another budget.
    fn predict(&self, from: Budget, to: Budget) -> Option<YStats> {
        let m = self.y.m;
        if m < 2.0 {
            return None;
        }
        let outer = &self.y.sum_y * self.y.sum_y.transpose() / m;
        let n_c = self.y.layout.component_dimension();
        let mut sum_yy = self.y.sum_yy.clone();
        for i in 0..n_c {
            for j in 0..n_c {
                let v = (self.y.sum_yy[(i, j)] - outer[(i, j)]) / (m - 1.0);
                let u = [0, 1, 2].map(|k| self.parts[k][(i, j)] / m);
                sum_yy[(i, j)] = (m - 1.0) * rescale(v, u, from, to) + outer[(i, j)];
            }
        }
        Some(YStats { sum_yy, ..self.y.clone() })
    }

    /// (M, Σ C, predicted Σ C²) of per-path strategy `k` at `to`.
    fn strategy_sums(&self, k: usize, from: Budget, to: Budget) -> Option<[f64; 3]> {
        let m = self.y.m;
        let [s1, s2, ul, uc, u0] = *self.strategies.get(k)?;
        (m >= 2.0).then(|| {
            let v = (s2 - s1 * s1 / m) / (m - 1.0);
            let predicted = rescale(v, [ul / m, uc / m, u0 / m], from, to);
            [m, s1, (m - 1.0) * predicted + s1 * s1 / m]
        })
    }
}

/// RMS% of (M, Σ C, Σ C²), if the mean is not zero.
fn rms([m, s1, s2]: [f64; 3]) -> Option<f64> {
    let mean = s1 / m;
    (mean != 0.0).then(|| 100.0 * ((s2 / m - mean * mean).max(0.0) * m / (m - 1.0)).sqrt() / mean.abs())
}

/// One run's component sums, read once: predictions at any number of budgets
/// ([`Predictor::at`]) share them.
#[derive(Debug, Clone)]
pub struct Predictor {
    measured: Budget,
    iterations: u64,
    folds: usize,
    all: ComponentStats,
    /// The folds that hold iterations, and their complements.
    test: Vec<ComponentStats>,
    train: Vec<ComponentStats>,
    /// The fold index of each `test` entry.
    fold_index: Vec<usize>,
}

impl Predictor {
    /// Reads `moments`, drawn at `measured`.
    pub fn new(moments: &Moments, measured: Budget) -> Result<Self, PredictError> {
        let layout = moments.layout();
        let all = ComponentStats::from_fold(&moments.pooled(), layout).ok_or(PredictError::NoComponents)?;
        if all.y.m < 2.0 {
            return Err(PredictError::TooFewIterations(moments.iterations()));
        }
        let used: Vec<(usize, &FoldMoments)> =
            moments.folds.iter().enumerate().filter(|(_, f)| f.iterations > 0).collect();
        let fold_index = used.iter().map(|(f, _)| *f).collect();
        let test: Vec<ComponentStats> = used
            .iter()
            .map(|(_, f)| ComponentStats::from_fold(f, layout).expect("every fold keeps components"))
            .collect();
        let train = test.iter().map(|f| all.without(f)).collect();
        Ok(Self {
            measured,
            iterations: moments.iterations(),
            folds: moments.fold_count(),
            all,
            test,
            train,
            fold_index,
        })
    }

    /// The noise table and the re-fitted optimum at `to`.
    pub fn at(&self, grid: &CellGrid, solver: &SolverOptions, to: Budget) -> Prediction {
        let (from, all) = (self.measured, &self.all);
        let mut rows: Vec<NoiseRow> = PathStrategy::ALL
            .iter()
            .enumerate()
            .map(|(k, &s)| path_row(s, k, all, &self.train, solver, from, to))
            .collect();
        let predicted = |c: &ComponentStats| c.predict(from, to);
        let cf = (|| {
            Some(CrossFitting {
                all: predicted(all)?,
                test: self.test.iter().map(predicted).collect::<Option<_>>()?,
                train: self.train.iter().map(predicted).collect::<Option<_>>()?,
                references: Vec::new(),
            })
        })();
        let mut fitted: Vec<Fitted> = Vec::new();
        match &cf {
            None => rows.push(NoiseRow::failed(Strategy::OptimalCv, "every fold needs at least 2 iterations".into())),
            Some(cf) => {
                // Heuristics whose weights depend on N_F and N_B have no column at another budget.
                let family: Vec<PathStrategy> = stack_family(cf.all.layout, &solver.fixed)
                    .into_iter()
                    .filter(|h| from == to || !h.depends_on_budget())
                    .collect();
                let mut families = vec![(Strategy::OptimalCv, Vec::new())];
                if !family.is_empty() {
                    families.push((Strategy::OptimalStacked, family));
                }
                for (name, family) in families {
                    match select_lambda(cf, grid, &solver.fixed, &solver.cv_lambdas, &family, &Scored::is_stable) {
                        Ok(selection) => {
                            rows.push(scored_row(name, &selection.chosen, cf, false));
                            fitted.push(Fitted { strategy: name, scored: selection.chosen });
                        }
                        Err(f) => rows.push(NoiseRow::failed(
                            name,
                            format!("no λ of the grid could be cross-fitted ({})", f.join("; ")),
                        )),
                    }
                }
            }
        }
        let path_sums = |p: PathStrategy| -> FoldSums {
            if p.depends_on_budget() && from != to {
                return Vec::new();
            }
            let used = (0..self.test.len()).map(|i| (self.fold_index[i], &self.test[i]));
            used.filter_map(|(f, t)| t.strategy_sums(p.index(), from, to).map(|s| (f, s))).collect()
        };
        let (eligible, unsupported) = recommendable(&rows, from, to);
        let mut choice = recommend(&eligible, &fitted, &path_sums);
        let mut note = left_out_note(&rows, &unsupported);
        if choice.recommended.is_err() && !unsupported.is_empty() {
            // Nothing supported is recommendable: choose among all rows, and say so.
            choice = recommend(&rows, &fitted, &path_sums);
            note = format!(
                "; no recommendable row's prediction is supported by this run (every RMS SE above {:.0}% of the RMS): a longer run is needed to act on it",
                SUPPORT_RELATIVE_SE * 100.0
            );
        }
        let (mut recommended, mut weights, mut solve_error) = (None, Vec::new(), None);
        match &choice.recommended {
            Ok(r) => {
                recommended = Some(RecommendedWeights {
                    strategy: r.strategy,
                    lambda: r.lambda(),
                    heuristics: rows
                        .iter()
                        .find(|x| x.strategy == r.strategy)
                        .map(|x| x.heuristics.clone())
                        .unwrap_or_default(),
                    reason: format!("{}{note}", r.reason),
                    margin: Some(choice.margin()),
                });
                if let Some(fit) = r.fit() {
                    weights = weight_rows(grid, fit, r.weight_stderr().as_deref());
                }
            }
            Err(e) => solve_error = Some(e.clone()),
        }
        Prediction {
            budget: to,
            measured: from,
            iterations: self.iterations,
            folds: self.folds,
            noise_table: rows,
            recommended,
            weights,
            solve_error,
            unsupported,
            support_relative_se: SUPPORT_RELATIVE_SE,
        }
    }
}

/// Predicts the noise table and re-fits the optimum at `to` from `moments` drawn at `from`.
pub fn predict(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    from: Budget,
    to: Budget,
) -> Result<Prediction, PredictError> {
    Ok(Predictor::new(moments, from)?.at(grid, solver, to))
}

/// The predicted row of per-path strategy `s` (index `k`), with the jackknife SE of its RMS.
fn path_row(
    s: PathStrategy,
    k: usize,
    all: &ComponentStats,
    complements: &[ComponentStats],
    solver: &SolverOptions,
    from: Budget,
    to: Budget,
) -> NoiseRow {
    let name = Strategy::of_path(s);
    if s.depends_on_budget() && from != to {
        let mut row = NoiseRow::from_sums(name, 0.0, 0.0, 0.0, None);
        row.error = Some(format!(
            "{} weighs each merge by N_F and N_B: its weights, and so its noise, at another budget cannot be predicted from this run",
            s.name()
        ));
        return row;
    }
    if k >= all.strategies.len() {
        return NoiseRow::failed(name, "not in these moments: format 2 does not keep this strategy".into());
    }
    let Some([m, s1, s2]) = all.strategy_sums(k, from, to) else {
        return NoiseRow::from_sums(name, all.y.m, 0.0, 0.0, None);
    };
    let replicates: Option<Vec<f64>> = complements.iter().map(|c| c.strategy_sums(k, from, to).and_then(rms)).collect();
    NoiseRow {
        rms_percent_stderr: replicates.filter(|r| r.len() >= 2).map(|r| jackknife_se(r.iter().copied())),
        respects_fixed: respects_fixed(s, &solver.fixed),
        ..NoiseRow::from_sums(name, m, s1, s2, None)
    }
}

#[cfg(test)]
mod tests;
