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
use super::solver::{adds_nothing, stack_family, stackable};
use super::strategy::Strategy;
use super::trust::TrustRegion;
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
    /// The trust region the rows were measured against, if any.
    region: Option<TrustRegion>,
}

/// Computes every fitted row but the in-sample `optimal`. With a trust `region`, the rows chosen by
/// cross-validation choose λ among the fits within it, and every row beyond it is marked so.
pub fn fitted_rows(
    cf: &CrossFitting,
    grid: &CellGrid,
    solver: &SolverOptions,
    region: Option<TrustRegion>,
) -> FittedRows {
    let fixed = &solver.fixed;
    let mut out = FittedRows { rows: Vec::new(), fitted: Vec::new(), region };
    let eligible = |s: &Scored| s.is_stable() && region.is_none_or(|r| r.admits(&s.all));
    out.push(Strategy::OptimalHoldout, score(cf, grid, fixed, solver.lambda, &[]), cf, false);
    let cv = select_lambda(cf, grid, fixed, &solver.cv_lambdas, &[], &eligible);
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
    // A heuristic that gives every path of these data the table base's weights adds nothing to
    // the stack (its β would be undetermined for ever): it is left out, and the rows say so.
    let nothing: Vec<_> = family.iter().copied().filter(|&h| adds_nothing(&cf.all, fixed, h)).collect();
    let stack: Vec<_> = stack_family(cf.all.layout, fixed).into_iter().filter(|h| !nothing.contains(h)).collect();
    let stacked = select_lambda(cf, grid, fixed, &solver.cv_lambdas, &stack, &eligible).map_err(no_lambda);
    let lambda = stacked.as_ref().ok().map(|s| s.chosen.cross_fit.lambda);
    out.push_selection(Strategy::OptimalStacked, stacked, cf);
    let left_out: Vec<_> = stack_family(cf.all.layout, fixed).into_iter().filter(|h| nothing.contains(h)).collect();
    if !left_out.is_empty()
        && let Some(row) = out.rows.last_mut()
    {
        let names: Vec<&str> = left_out.iter().map(|h| h.name()).collect();
        row.note = Some(if stack.is_empty() {
            format!(
                "{} left out: on these data every stacked heuristic gives every path the table's fixed weights \
                 (nothing to stack), so this is the table alone",
                names.join(", ")
            )
        } else {
            format!(
                "{} left out of the stack: on these data it gives every path the table's fixed weights (e.g. the \
                 switch under a light without a spot is plane 3), so its β would stay undetermined",
                names.join(", ")
            )
        });
    }
    for &h in &family {
        let name = Strategy::corrected(h).expect("stackable strategies have a corrected row");
        let adds = !nothing.contains(&h);
        let corrected: Vec<_> = if adds { vec![h] } else { Vec::new() };
        let scored = match lambda {
            Some(l) => score(cf, grid, fixed, l, &corrected),
            None => Err("the stacked optimum, whose λ it uses, could not be fitted".to_string()),
        };
        out.push(name, scored, cf, false);
        if !adds && let Some(row) = out.rows.last_mut() {
            row.note = Some(format!(
                "{} gives every path of these data the table's fixed weights, so corrected by a table it is the \
                 table alone at optimal_stacked's λ: these are the table's figures",
                h.name()
            ));
        }
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
                let mut row = scored_row(strategy, &s, cf, in_sample);
                if let Some(region) = self.region {
                    row.deviation = region.deviation(&s.all);
                    row.beyond_trust_region = !region.admits(&s.all);
                }
                self.rows.push(row);
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

#[cfg(test)]
mod tests {
    use crate::sim::runner::run;
    use crate::sim::solve::report::{ReportInputs, build_report};
    use crate::sim::solve::strategy::Strategy;
    use crate::sim::spec::parse_job_spec;

    /// Issue 40, item 2: under a uniform light the switch is plane 3 on every path, so its stacked
    /// column is zero; `optimal_stacked` and every `_corrected` row failed with "singular … run more
    /// iterations", which no run length cures. Now the switch is left out and every row has figures,
    /// the rows that changed saying why.
    #[test]
    fn a_heuristic_that_adds_nothing_is_left_out_and_every_row_has_figures() {
        let doc = serde_json::json!({ "preset": "uniform-illumination", "iterations": 2000, "seed": 3 });
        let job = parse_job_spec(&doc).unwrap().validate().unwrap();
        let moments = run(job.config(), 3, 0..2000);
        let report = build_report(&moments, &job.config().cells, &job.spec().solver, &ReportInputs::default());
        for row in &report.noise_table {
            assert!(row.error.is_none() && row.rms_percent.is_some(), "{:?}: {:?}", row.strategy, row.error);
        }
        let row = |s: Strategy| report.noise_table.iter().find(|r| r.strategy == s).unwrap();
        let stacked = row(Strategy::OptimalStacked);
        assert!(stacked.note.as_deref().is_some_and(|n| n.starts_with("switch left out")), "{:?}", stacked.note);
        assert!(stacked.heuristics.iter().all(|h| h.strategy != Strategy::Switch));
        let corrected = row(Strategy::corrected(crate::sim::engines::strategies::PathStrategy::Switch).unwrap());
        assert!(corrected.note.is_some() && corrected.heuristics.is_empty());
        assert!(row(Strategy::CorrelationAwarePlanes23Corrected).note.is_none());
    }
}
