//! The ray budget: which (N_F, N_B) reaches a target noise soonest, per strategy, from one run's
//! noise components (docs/model.md §12).
//!
//! In the paper N_F light paths serve every pixel of the image while N_B camera paths go through
//! *this* pixel, so an iteration of a renderer with P pixels costs t = t_F·N_F + t_B·N_B·P + t_0.
//! A strategy whose per-iteration relative noise at (N_F, N_B) is R (the predicted RMS%) needs
//! max(1, (R/target)²) iterations for a target RMS, so the time to the target is T = (R/target)²·t. Each
//! strategy's T is evaluated on a grid of budgets — the fitted rows *re-fitted* at every point — and
//! the best point reported with its speed-up over the paper's configuration (10⁷, 100, switch) and
//! that speed-up's standard error. Only strategies that keep the solver's fixed weights are ranked;
//! the plan headlines the strategy the run recommends (or, if its weights depend on the budget, the
//! best predictable one), and widens its grid while that strategy's best lies on the edge — up to
//! what the run can predict, where it says so.
//!
//! A point is used only where the run's noise supports it ([`BudgetPoint::supported`]: the
//! predicted RMS known within [`SUPPORT_RELATIVE_SE`] of itself): far from the measured budget a
//! predicted variance can come out near zero, and the fastest of many such points would be chosen
//! for its noise — a headline speed-up of hundreds with an SE of thousands (docs/results.md §10).
//! The fastest supported point is reported, and whether an unsupported one predicted faster.
//!
//! The same points also give the other view of the trade-off (`FixedTime`): the RMS each budget
//! reaches in a fixed wall time — the time the paper's configuration takes to the target — as a
//! curve against the ratio N_F/N_B.
//!
//! Imports: crate::sim::model, crate::sim::solve, crate::sim::stats

use serde::{Deserialize, Serialize};

use super::options::SolverOptions;
use super::predict::{Budget, PredictError, Prediction, Predictor, supported};
use super::strategy::Strategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::moments::Moments;

mod costs;
pub mod error;
pub use costs::{CostSource, Costs};

/// One strategy at one budget.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct BudgetPoint {
    /// The strategy whose noise was predicted.
    pub strategy: Strategy,
    /// (N_F, N_B) of the point.
    pub budget: Budget,
    /// Predicted RMS% of one iteration.
    pub rms_percent: f64,
    /// Its jackknife standard error over the folds.
    pub rms_percent_stderr: Option<f64>,
    /// Whether the strategy keeps the solver's fixed weights (only those are ranked).
    pub respects_fixed: bool,
    /// t = t_F·N_F + t_B·N_B·P + t_0 at this budget ([`Costs::iteration_seconds`]).
    pub seconds_per_iteration: f64,
    /// Seconds to the target RMS: max(1, (rms/target)²) iterations.
    pub seconds_to_target: f64,
}

/// The support limit, defined with the predictions it applies to (re-exported for the plan's users).
pub use super::predict::SUPPORT_RELATIVE_SE;

impl BudgetPoint {
    /// Whether the run's noise supports this prediction: its RMS has a standard error of at most
    /// [`SUPPORT_RELATIVE_SE`] of itself (a point without an SE is not supported).
    pub fn supported(&self) -> bool {
        supported(self.rms_percent, self.rms_percent_stderr)
    }
}

/// A strategy's fastest budget in the searched range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct BestBudget {
    /// The point itself (its fields appear at the top level of the JSON).
    #[serde(flatten)]
    pub point: BudgetPoint,
    /// How many times sooner than the paper's switch at (10⁷, 100) it reaches the target.
    pub speedup: Option<f64>,
    /// The speed-up's standard error: the delta method on both RMS standard errors
    /// (speed-up ∝ (R_paper/R)², treated as independent — conservative, as both are predicted from
    /// the same iterations and err together).
    pub speedup_stderr: Option<f64>,
    /// Whether the budget lies on the edge of the searched range: the optimum may lie beyond what
    /// this run can predict.
    pub at_edge: bool,
    /// Whether the run supports this point's prediction (its RMS SE is at most the plan's
    /// `support_relative_se` of the RMS); false only when no point of the strategy is supported,
    /// and this is its fastest unsupported one.
    pub supported: bool,
    /// Whether a point the run does not support predicted a shorter time than this one: the
    /// optimum may lie there, but this run cannot tell (a longer run, or one nearer that budget,
    /// can).
    pub faster_unsupported: bool,
}

/// The budgets searched: a grid in half-decade steps, widened from a decade around the measured
/// budget while the headline's best lies on its edge, up to [`MAX_DECADES`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct SearchRange {
    /// The smallest and largest N_F of the grid.
    pub light_paths: [u64; 2],
    /// The smallest and largest N_B of the grid.
    pub camera_paths: [u64; 2],
    /// Whether the range reached the limit of what the run can predict.
    pub at_limit: bool,
}

/// The best budget of every strategy, the paper's configuration, and every point evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct BudgetPlan {
    /// The target RMS% the times are measured to.
    pub target_rms_percent: f64,
    /// The costs the times are computed with.
    pub costs: Costs,
    /// What the run recommends at its own budget.
    pub recommended: Option<Strategy>,
    /// The strategy headlined: the recommended one, or — when its weights depend on the budget
    /// and cannot be predicted — the stacked optimum (else optimal_cv), the fitted family that
    /// contains the recommended weights' predictable kin and keeps the fixed weights.
    pub headline: Option<Strategy>,
    /// Why the headline is not the recommended strategy, if so.
    pub headline_note: Option<String>,
    /// The budgets searched, after widening.
    pub search: SearchRange,
    /// The largest RMS standard error, as a fraction of the RMS, of a point the plan uses (0.25,
    /// `SUPPORT_RELATIVE_SE`): what `supported` and `faster_unsupported` refer to.
    pub support_relative_se: f64,
    /// Per strategy (that could be predicted), its fastest supported point: those that keep the
    /// fixed weights first (ranked by time, strategies with no supported point last), then the
    /// others (shown, not ranked).
    pub best: Vec<BestBudget>,
    /// `switch` at (10⁷, 100): the paper's configuration.
    pub paper: Option<BudgetPoint>,
    /// Every (strategy, budget) evaluated.
    pub points: Vec<BudgetPoint>,
    /// The RMS at the paper configuration's time against N_F/N_B, from the supported points
    /// (absent if the paper's configuration could not be predicted).
    pub fixed_time: Option<FixedTime>,
}

/// The RMS every budget reaches in a fixed wall time T, as a curve against N_F/N_B
/// (docs/model.md §12).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct FixedTime {
    /// T: the paper configuration's `seconds_to_target`, so that the paper's own point reads the
    /// target RMS and every other point reads what it would reach in the same time.
    pub seconds: f64,
    /// Per strategy and distinct ratio N_F/N_B of the grid, the budget with the lowest RMS after T
    /// (a ratio is reached by several budgets along the grid's diagonal; the curve keeps the one a
    /// renderer fixed to that ratio would choose). Strategies in the order of `BudgetPlan::best`,
    /// ratios ascending.
    pub curve: Vec<FixedTimePoint>,
}

/// One strategy's best budget at one ratio N_F/N_B, after the fixed time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct FixedTimePoint {
    /// The strategy of the curve this point is on.
    pub strategy: Strategy,
    /// N_F/N_B of the ratio's group on the grid (the geometric mean of its budgets' ratios, which
    /// differ only by the grid's rounding to integers).
    pub ratio: f64,
    /// The budget of the group with the lowest RMS after T.
    pub budget: Budget,
    /// Iterations that fit in T, T/t. Below 1 not even one iteration fits and `rms_percent` is the
    /// formula's extrapolation, not a renderable result.
    pub iterations: f64,
    /// RMS% after T: the per-iteration RMS R averaged over T/t iterations, R·√(t/T).
    pub rms_percent: f64,
}

/// RMS% after `seconds` of iterations each `seconds_per_iteration` long with one-iteration RMS%
/// `rms_percent`: the variance falls as 1/iterations, iterations = T/t.
pub fn rms_after(rms_percent: f64, seconds_per_iteration: f64, seconds: f64) -> f64 {
    rms_percent * (seconds_per_iteration / seconds).sqrt()
}

/// Ratios N_F/N_B closer than this (in decades) are one ratio: the grid's integer rounding moves
/// a ratio by ≤ 0.023 decade (3 for 10^0.5), distinct ratios of a half-decade grid are 0.5 decade apart.
const SAME_RATIO_DECADES: f64 = 0.05;

/// The fixed-time curve of `points` at `seconds` (see `FixedTime`), strategies in `order`.
pub fn fixed_time(points: &[BudgetPoint], seconds: f64, order: &[Strategy]) -> FixedTime {
    let log_ratio = |p: &BudgetPoint| (p.budget.light_paths as f64 / p.budget.camera_paths as f64).log10();
    let mut curve = Vec::new();
    for &strategy in order {
        let mut mine: Vec<&BudgetPoint> = points.iter().filter(|p| p.strategy == strategy).collect();
        mine.sort_by(|a, b| log_ratio(a).total_cmp(&log_ratio(b)));
        // Groups of consecutive ratios within SAME_RATIO_DECADES of the group's first.
        let mut start = 0;
        while start < mine.len() {
            let first = log_ratio(mine[start]);
            let end = start + mine[start..].iter().take_while(|p| log_ratio(p) - first < SAME_RATIO_DECADES).count();
            let group = &mine[start..end];
            let mean = group.iter().map(|p| log_ratio(p)).sum::<f64>() / group.len() as f64;
            let rms = |p: &BudgetPoint| rms_after(p.rms_percent, p.seconds_per_iteration, seconds);
            let best = group.iter().min_by(|a, b| rms(a).total_cmp(&rms(b))).expect("a group is never empty");
            curve.push(FixedTimePoint {
                strategy,
                ratio: 10f64.powf(mean),
                budget: best.budget,
                iterations: seconds / best.seconds_per_iteration,
                rms_percent: rms(best),
            });
            start = end;
        }
    }
    FixedTime { seconds, curve }
}

/// The paper's budget.
pub const PAPER_BUDGET: Budget = Budget { light_paths: 10_000_000, camera_paths: 100 };

/// Budgets from `lo` to `hi` in steps of 10^(1/steps_per_decade), rounded to integers.
pub fn log_grid(lo: u64, hi: u64, steps_per_decade: u32) -> Vec<u64> {
    let (a, b) = ((lo.max(1) as f64).log10(), (hi.max(lo) as f64).log10());
    let n = ((b - a) * f64::from(steps_per_decade)).round() as u32;
    let mut out: Vec<u64> =
        (0..=n).map(|i| 10f64.powf(a + f64::from(i) / f64::from(steps_per_decade)).round() as u64).collect();
    out.dedup();
    out
}

/// Decades around the measured budget beyond which the plan does not predict: the components'
/// estimation noise is amplified with the distance (a slightly negative estimate of a component
/// can make a far budget look free; docs/results.md §7 checked predictions within a decade).
pub const MAX_DECADES: f64 = 2.0;

/// Largest N_B a plan considers (the spec's limit).
const MAX_CAMERA_PATHS: u64 = 1_000_000;

/// Evaluates every strategy on a half-decade grid around `measured` (and at the paper's budget)
/// for `target`: a decade each way first, widened by half-decade steps while the headline
/// strategy's fastest budget lies on the grid's edge, up to [`MAX_DECADES`].
pub fn plan(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    measured: Budget,
    costs: Costs,
    target: f64,
) -> Result<BudgetPlan, PredictError> {
    let timing = Timing { seconds: &|b| costs.iteration_seconds(b), allowance: &|_| Some(target) };
    plan_with(moments, grid, solver, measured, costs, target, &timing)
}

/// How [`plan_with`] times a budget: the seconds of one iteration, and each strategy's noise
/// allowance — the per-iteration RMS% that, averaged over iterations, reaches the target (the
/// target itself for [`plan`]; √(P² − bias²) for a target error that includes a bias, `None`
/// where the bias alone exceeds it).
pub struct Timing<'a> {
    /// Seconds of one iteration at a budget.
    pub seconds: &'a dyn Fn(Budget) -> f64,
    /// The RMS% of the average that a strategy may have.
    pub allowance: &'a dyn Fn(Strategy) -> Option<f64>,
}

/// [`plan`] with the times of `timing` (docs/model.md §13: a radius's merges cost time, and its
/// bias shrinks what the noise may be).
pub fn plan_with(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    measured: Budget,
    costs: Costs,
    target: f64,
    timing: &Timing<'_>,
) -> Result<BudgetPlan, PredictError> {
    let predictor = Predictor::new(moments, measured)?;
    let evaluate = |b: Budget, points: &mut Vec<BudgetPoint>| {
        let p = predictor.at(grid, solver, b);
        let seconds = (timing.seconds)(b);
        for row in p.noise_table.iter().filter(|r| !r.in_sample) {
            let Some(allowance) = (timing.allowance)(row.strategy) else { continue };
            if let Some(r) = row.rms_percent.filter(|r| r.is_finite() && *r > 0.0) {
                // At least one iteration: a budget whose single iteration beats the target still
                // costs that iteration.
                let iterations = (r / allowance).powi(2).max(1.0);
                points.push(BudgetPoint {
                    strategy: row.strategy,
                    budget: b,
                    rms_percent: r,
                    rms_percent_stderr: row.rms_percent_stderr,
                    respects_fixed: row.respects_fixed,
                    seconds_per_iteration: seconds,
                    seconds_to_target: iterations * seconds,
                });
            }
        }
        p
    };
    let own = evaluate(measured, &mut Vec::new());
    let recommended = own.recommended.as_ref().map(|r| r.strategy);
    let (headline, headline_note) = headline_of(&own, recommended);
    let (points, search) = search(measured, headline, |budget, points| {
        evaluate(budget, points);
    });
    let mut at_paper = Vec::new();
    evaluate(PAPER_BUDGET, &mut at_paper);
    let paper = at_paper.iter().find(|p| p.strategy == Strategy::Switch).copied();
    let best = ranked(&points, paper.as_ref(), &search);
    let order: Vec<Strategy> = best.iter().map(|b| b.point.strategy).collect();
    let supported: Vec<BudgetPoint> = points.iter().filter(|p| p.supported()).copied().collect();
    let fixed_time = paper.map(|p| fixed_time(&supported, p.seconds_to_target, &order));
    Ok(BudgetPlan {
        target_rms_percent: target,
        costs,
        recommended,
        headline,
        headline_note,
        search,
        support_relative_se: SUPPORT_RELATIVE_SE,
        best,
        paper,
        points,
        fixed_time,
    })
}

/// The strategy a plan headlines: the run's recommendation when its noise at other budgets can be
/// predicted, else the stacked or cross-fitted optimum (with a note saying why).
fn headline_of(own: &Prediction, recommended: Option<Strategy>) -> (Option<Strategy>, Option<String>) {
    let predictable = |s: Strategy| s.path().is_none_or(|p| !p.depends_on_budget());
    match recommended {
        Some(s) if predictable(s) => (Some(s), None),
        Some(s) => {
            let fallback = [Strategy::OptimalStacked, Strategy::OptimalCv]
                .into_iter()
                .find(|f| own.noise_table.iter().any(|r| r.strategy == *f && r.error.is_none()));
            let note = format!(
                "the run recommends {s}, whose weights depend on N_F and N_B, so its noise at other budgets cannot be predicted from this run; headlined instead: {}",
                fallback.map_or("none".to_string(), |f| f.to_string())
            );
            (fallback, Some(note))
        }
        None => (None, None),
    }
}

/// The half-decade grid around `measured`, every budget of it `evaluate`d: a decade each way
/// first, widened by half-decade steps while the `headline` strategy's fastest budget lies on the
/// grid's edge, up to [`MAX_DECADES`]. The points, and the range searched.
fn search(
    measured: Budget,
    headline: Option<Strategy>,
    mut evaluate: impl FnMut(Budget, &mut Vec<BudgetPoint>),
) -> (Vec<BudgetPoint>, SearchRange) {
    let (f, b) = (measured.light_paths as f64, measured.camera_paths as f64);
    let limit = 10f64.powf(MAX_DECADES);
    let light_limit = [(f / limit).max(1.0), (f * limit).min(1e12)];
    let camera_limit = [(b / limit).max(1.0), (b * limit).min(MAX_CAMERA_PATHS as f64)];
    // Exponents in half decades around the measured budget: [lo, hi] per axis.
    let mut range = [[-2i32, 2], [-2i32, 2]];
    let value = |axis: usize, e: i32| {
        let (base, [lo, hi]) = if axis == 0 { (f, light_limit) } else { (b, camera_limit) };
        (base * 10f64.powf(f64::from(e) / 2.0)).clamp(lo, hi).round() as u64
    };
    let axis_values = |axis: usize, r: [i32; 2]| {
        let mut v: Vec<u64> = (r[0]..=r[1]).map(|e| value(axis, e)).collect();
        v.dedup();
        v
    };
    let mut points = Vec::new();
    let mut done: Vec<Budget> = Vec::new();
    let at_limit = loop {
        for &l in &axis_values(0, range[0]) {
            for &c in &axis_values(1, range[1]) {
                let budget = Budget { light_paths: l, camera_paths: c };
                if !done.contains(&budget) {
                    evaluate(budget, &mut points);
                    done.push(budget);
                }
            }
        }
        let Some(Fastest { point: best, .. }) = headline.and_then(|h| fastest(&points, h)) else { break false };
        // Widen every side the headline's fastest budget touches, while that side can grow.
        let mut widened = false;
        for (axis, v) in [(0, best.budget.light_paths), (1, best.budget.camera_paths)] {
            let values = axis_values(axis, range[axis]);
            let max_steps = (2.0 * MAX_DECADES) as i32;
            if v == values[0] && value(axis, range[axis][0] - 1) < values[0] && range[axis][0] > -max_steps {
                range[axis][0] -= 1;
                widened = true;
            }
            if v == values[values.len() - 1] && value(axis, range[axis][1] + 1) > v && range[axis][1] < max_steps {
                range[axis][1] += 1;
                widened = true;
            }
        }
        if !widened {
            let light = axis_values(0, range[0]);
            let camera = axis_values(1, range[1]);
            let edge = |v: u64, axis: &[u64]| v == axis[0] || v == axis[axis.len() - 1];
            break edge(best.budget.light_paths, &light) || edge(best.budget.camera_paths, &camera);
        }
    };
    let (light, camera) = (axis_values(0, range[0]), axis_values(1, range[1]));
    let search = SearchRange {
        light_paths: [light[0], light[light.len() - 1]],
        camera_paths: [camera[0], camera[camera.len() - 1]],
        at_limit,
    };
    (points, search)
}

/// Each strategy's fastest supported budget with its speed-up over the paper's setup, ranked:
/// strategies that respect the fixed weights first, then the supported ones, then by time.
fn ranked(points: &[BudgetPoint], paper: Option<&BudgetPoint>, search: &SearchRange) -> Vec<BestBudget> {
    let mut strategies: Vec<Strategy> = Vec::new();
    for p in points {
        if !strategies.contains(&p.strategy) {
            strategies.push(p.strategy);
        }
    }
    let edge = |p: &BudgetPoint| {
        search.light_paths.contains(&p.budget.light_paths) || search.camera_paths.contains(&p.budget.camera_paths)
    };
    let mut best: Vec<BestBudget> = strategies
        .iter()
        .filter_map(|&s| fastest(points, s))
        .map(|Fastest { point, supported, faster_unsupported }| {
            let (speedup, speedup_stderr) = speedup(&point, paper);
            BestBudget { point, speedup, speedup_stderr, at_edge: edge(&point), supported, faster_unsupported }
        })
        .collect();
    best.sort_by(|a, b| {
        (!a.point.respects_fixed, !a.supported, a.point.seconds_to_target)
            .partial_cmp(&(!b.point.respects_fixed, !b.supported, b.point.seconds_to_target))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    best
}

/// A strategy's fastest point, and what the guard on support left aside.
struct Fastest {
    point: BudgetPoint,
    supported: bool,
    faster_unsupported: bool,
}

/// The supported point of `strategy` that reaches the target soonest — or, if none is supported,
/// its fastest point, marked so.
fn fastest(points: &[BudgetPoint], strategy: Strategy) -> Option<Fastest> {
    let soonest = |supported: Option<bool>| {
        points
            .iter()
            .filter(|p| p.strategy == strategy && supported.is_none_or(|s| p.supported() == s))
            .min_by(|a, b| a.seconds_to_target.total_cmp(&b.seconds_to_target))
            .copied()
    };
    let any = soonest(None)?;
    Some(match soonest(Some(true)) {
        Some(point) => {
            Fastest { point, supported: true, faster_unsupported: any.seconds_to_target < point.seconds_to_target }
        }
        None => Fastest { point: any, supported: false, faster_unsupported: false },
    })
}

/// The speed-up of `point` over the paper's configuration, with its delta-method SE: time to the
/// target ∝ R²·t while at least one iteration is needed, so the relative SE of the ratio is
/// 2·√((SE_R/R)² + (SE_R′/R′)²) (a point that needs a single iteration has no R-dependence).
fn speedup(point: &BudgetPoint, paper: Option<&BudgetPoint>) -> (Option<f64>, Option<f64>) {
    let Some(paper) = paper else { return (None, None) };
    let value = paper.seconds_to_target / point.seconds_to_target;
    let relative = |p: &BudgetPoint| {
        let one_iteration = p.seconds_to_target <= p.seconds_per_iteration;
        if one_iteration { Some(0.0) } else { p.rms_percent_stderr.map(|se| se / p.rms_percent) }
    };
    let se = match (relative(point), relative(paper)) {
        (Some(a), Some(b)) => Some(value * 2.0 * (a * a + b * b).sqrt()),
        _ => None,
    };
    (Some(value), se)
}

#[cfg(test)]
mod tests;
