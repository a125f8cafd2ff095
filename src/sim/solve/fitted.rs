//! The fitted rows of the noise table: the paper's table cross-fitted at the spec's λ
//! (`optimal_holdout`) and at a λ chosen by cross-validation (`optimal_cv`), the stacked optimum —
//! the table with the switch and the correlation-aware heuristics that keep the fixed weights
//! stacked on it (`optimal_stacked`, docs/model.md §7) — and, for insight, each heuristic that
//! keeps them corrected by a table alone
//! (`…_corrected`, at the stacked optimum's λ, so that they cost one cross-fit each instead of a λ
//! search). Every figure is cross-fitted; the rows chosen by cross-validation also carry their
//! in-sample figures, labelled as such.

use super::crossfit::{CrossFitting, Scored, Selection, score, select_lambda};
use super::options::SolverOptions;
use super::row::{HeuristicWeight, LambdaScore, NoiseRow};
use super::solver::{stack_family, stackable};
use super::strategy::Strategy;
use crate::sim::model::cells::CellGrid;

/// A cross-fitted row and the λ it was scored at: its figures, its all-data weights and their
/// stability, for the recommendation and the warnings.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The fitted row's strategy (`optimal_holdout`, `optimal_cv`, `optimal_stacked`, a corrected
    /// heuristic).
    pub strategy: Strategy,
    /// Its cross-fit at the chosen (or the spec's) λ and the all-data fit.
    pub scored: Scored,
}

/// The fitted rows in table order, and the fits behind those that could be computed.
#[derive(Debug, Clone)]
pub struct FittedRows {
    /// One row per fitted strategy, in table order; a fit that failed is a row with its error.
    pub rows: Vec<NoiseRow>,
    /// The fits of the rows that could be computed.
    pub fitted: Vec<Fitted>,
}

/// Computes every fitted row but the in-sample `optimal`.
pub fn fitted_rows(cf: &CrossFitting, grid: &CellGrid, solver: &SolverOptions) -> FittedRows {
    let fixed = &solver.fixed;
    let mut out = FittedRows { rows: Vec::new(), fitted: Vec::new() };
    out.push(Strategy::OptimalHoldout, score(cf, grid, fixed, solver.lambda, &[]), cf, false);
    let cv = select_lambda(cf, grid, fixed, &solver.cv_lambdas, &[]);
    out.push_selection(Strategy::OptimalCv, cv.map_err(no_lambda), cf);

    let family = stackable(cf.all.layout, fixed);
    if family.is_empty() {
        let why = if cf.all.layout.heuristics().is_empty() {
            "these moments (format 2, written by an earlier optimis) keep no heuristic columns to stack"
        } else {
            "no heuristic keeps the solver's fixed weights (only w0 = 0, or none fixed, admits them)"
        };
        out.rows.push(NoiseRow::failed(Strategy::OptimalStacked, why.to_string()));
        return out;
    }
    let stacked =
        select_lambda(cf, grid, fixed, &solver.cv_lambdas, &stack_family(cf.all.layout, fixed)).map_err(no_lambda);
    let lambda = stacked.as_ref().ok().map(|s| s.chosen.cross_fit.lambda);
    out.push_selection(Strategy::OptimalStacked, stacked, cf);
    for &h in &family {
        let name = Strategy::corrected(h).expect("stackable strategies have a corrected row");
        let scored = match lambda {
            Some(l) => score(cf, grid, fixed, l, &[h]),
            None => Err("the stacked optimum, whose λ it uses, could not be fitted".to_string()),
        };
        out.push(name, scored, cf, false);
    }
    out
}

/// Every scored λ as the row shows it.
pub(crate) fn cv_path(scored: &[Scored]) -> Vec<LambdaScore> {
    scored
        .iter()
        .map(|s| LambdaScore {
            lambda: s.cross_fit.lambda,
            rms_percent: s.rms_percent,
            rms_percent_stderr: s.rms_stderr,
            stable: s.is_stable(),
        })
        .collect()
}

fn no_lambda(failures: Vec<String>) -> String {
    format!("no λ of the grid could be cross-fitted ({})", failures.join("; "))
}

impl FittedRows {
    /// A row chosen by cross-validation: the chosen λ's row with its in-sample figures and the
    /// whole λ path.
    fn push_selection(&mut self, strategy: Strategy, selection: Result<Selection, String>, cf: &CrossFitting) {
        let path = selection.as_ref().map(|s| cv_path(&s.scored)).unwrap_or_default();
        self.push(strategy, selection.map(|s| s.chosen), cf, true);
        if let Some(row) = self.rows.last_mut() {
            row.cv_path = path;
        }
    }

    fn push(&mut self, strategy: Strategy, scored: Result<Scored, String>, cf: &CrossFitting, in_sample: bool) {
        match scored {
            Ok(s) => {
                self.rows.push(scored_row(strategy, &s, cf, in_sample));
                self.fitted.push(Fitted { strategy, scored: s });
            }
            Err(e) => self.rows.push(NoiseRow::failed(strategy, e)),
        }
    }
}

/// The row of a scored fit: its cross-fitted figures with the jackknife SE of the RMS, λ, β with
/// their SEs, its stability, and (`in_sample`) the all-data fit's in-sample figures beside them.
pub(crate) fn scored_row(strategy: Strategy, s: &Scored, cf: &CrossFitting, in_sample: bool) -> NoiseRow {
    let [m, s1, s2] = s.cross_fit.totals();
    let row = NoiseRow::from_sums(strategy, m, s1, s2, None);
    let beta_se = s.cross_fit.beta_stderr();
    let heuristics = s
        .all
        .heuristics
        .iter()
        .enumerate()
        .map(|(i, &(h, beta))| HeuristicWeight {
            strategy: Strategy::of_path(h),
            beta,
            beta_stderr: beta_se.as_ref().map(|se| se[i]),
        })
        .collect();
    let inner = in_sample.then(|| {
        let (a1, a2) = cf.all.evaluate(&s.all.coefficients(cf.all.layout));
        NoiseRow::from_sums(strategy, cf.all.m, a1, a2, None)
    });
    NoiseRow {
        lambda: Some(s.cross_fit.lambda),
        rms_percent_stderr: s.rms_stderr,
        heuristics,
        unstable: !s.is_stable(),
        in_sample_luminance: inner.as_ref().and_then(|r| r.luminance),
        in_sample_luminance_stderr: inner.as_ref().and_then(|r| r.luminance_stderr),
        in_sample_rms_percent: inner.as_ref().and_then(|r| r.rms_percent),
        ..row
    }
}
