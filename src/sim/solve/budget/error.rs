//! The fastest setup to a target *error*: (N_F, N_B, R′, strategy) that reaches a relative RMSE P
//! about the true pixel value soonest, the bias of each radius included (docs/model.md §13).
//!
//! After n iterations the relative error is √(σ²/n + b²), σ the per-iteration RMS% at the budget
//! and radius and b the strategy's bias there, so a point needs n = σ²/(P² − b²) iterations
//! (at least one), and none if |b| ≥ P. Each radius the run tallied is planned as
//! [`super::plan_with`] plans a fixed one — the same half-decade grid of budgets, fitted rows
//! re-fitted at every point — with two changes: the noise allowance √(P² − b²) per strategy, and an
//! iteration's time that includes its merges, t = t_F·N_F + t_B·N_B·P + t_0 + t_M·m(N_F, N_B, R′)·P,
//! where the merges per pixel m are the run's at R′ scaled to the budget (plane-2 and plane-3
//! merges pair light with camera paths, ∝ N_F·N_B; a plane-1 merge is one per light path, ∝ N_F).
//!
//! Beside the fastest point: the fastest at the run's own R (today's plan with the bias counted),
//! the paper's setup (switch at (10⁷, 100), R = 0.003, when the run tallied that radius), and a
//! progressive schedule R_i = R₁·i^((α−1)/2) (progressive photon mapping, α = 2/3) at the fastest
//! point's strategy and budget, predicted from the same radii by interpolation in log R — floored
//! at the smallest radius tallied, which the run cannot see below.

use serde::{Deserialize, Serialize};

use super::{BudgetPoint, Costs, SUPPORT_RELATIVE_SE, Timing, plan_with};
use crate::sim::model::cells::CellGrid;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::predict::{Budget, PredictError, Predictor};
use crate::sim::solve::radii::RadiusReport;
use crate::sim::solve::strategy::Strategy;
use crate::sim::stats::moments::Moments;

/// The paper's merge radius (its Table 1).
pub const PAPER_RADIUS: f64 = 0.003;

/// Progressive photon mapping's α (Hachisuka & Jensen 2009 use 2/3): R_i² ∝ i^(α−1).
pub const PROGRESSIVE_ALPHA: f64 = 2.0 / 3.0;

/// One (strategy, budget, radius) with its time to the target error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ErrorPoint {
    /// The strategy.
    pub strategy: Strategy,
    /// R′.
    pub merge_radius: f64,
    /// (N_F, N_B).
    pub budget: Budget,
    /// Predicted RMS% of one iteration at this budget and radius.
    pub rms_percent: f64,
    /// Its standard error (jackknife over the folds; delta method for per-path rows).
    pub rms_percent_stderr: Option<f64>,
    /// The strategy's bias at R′, % of L.
    pub bias_percent: f64,
    /// Its error.
    pub bias_percent_stderr: Option<f64>,
    /// Iterations to the target: max(1, σ²/(P² − b²)).
    pub iterations: f64,
    /// Seconds of one iteration, merges included.
    pub seconds_per_iteration: f64,
    /// Seconds to the target error.
    pub seconds_to_target: f64,
    /// Its standard error: the delta method on σ and b.
    pub seconds_to_target_stderr: Option<f64>,
    /// Whether the run supports the prediction: its RMS SE within the plan's limit of itself
    /// (`support_relative_se`, 25%) and its time's SE — the bias's error included — within twice
    /// that (a fitted row's Monte-Carlo bias can be too uncertain to rank a time on).
    pub supported: bool,
    /// Whether the strategy keeps the solver's fixed weights.
    pub respects_fixed: bool,
}

/// A strategy whose bias at a radius alone reaches the target: no number of iterations gets there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct OutOfReach {
    /// The strategy.
    pub strategy: Strategy,
    /// R′.
    pub merge_radius: f64,
    /// Its bias, % of L.
    pub bias_percent: f64,
    /// Its error (a fitted row's Monte-Carlo bias may be out of reach by its noise only: then
    /// the bias minus twice its error is below the target).
    pub bias_percent_stderr: Option<f64>,
}

/// The progressive schedule's prediction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ProgressiveRow {
    /// The strategy (the fastest point's).
    pub strategy: Strategy,
    /// (N_F, N_B) of every iteration (the fastest point's).
    pub budget: Budget,
    /// α: R_i² = R₁²·i^(α−1).
    pub alpha: f64,
    /// R₁, the first iteration's radius (the tallied radius that reaches the target soonest).
    pub first_radius: f64,
    /// The radius of the last iteration (floored at the smallest radius tallied).
    pub last_radius: f64,
    /// Whether the schedule reached the smallest radius tallied and was held there (the run
    /// cannot predict below it).
    pub floored: bool,
    /// Iterations to the target error (none if it is not reached within 10¹² iterations).
    pub iterations: Option<f64>,
    /// Seconds to the target error.
    pub seconds_to_target: Option<f64>,
    /// Its standard error: the largest relative RMS error of the radii interpolated, by the
    /// delta method (an approximation: the radii's noise is interpolated in log R).
    pub seconds_to_target_stderr: Option<f64>,
}

/// The plan to a target error over the radii a run tallied.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ErrorPlan {
    /// P: the relative RMSE (% of L) about the true pixel value.
    pub target_rmse_percent: f64,
    /// The costs, t_M included.
    pub costs: Costs,
    /// The radii searched, ascending (the run's own R last).
    pub radii: Vec<f64>,
    /// The fastest supported point that keeps the fixed weights, over every radius and strategy.
    pub best: Option<ErrorPoint>,
    /// The fastest such point at the run's own R.
    pub at_own_radius: Option<ErrorPoint>,
    /// The paper's setup: switch at (10⁷, 100), R = 0.003 — when the run tallied that radius.
    pub paper: Option<ErrorPoint>,
    /// best's speed-up over the paper's setup, and its standard error.
    pub speedup_over_paper: Option<f64>,
    /// Its standard error (delta method, both times' errors treated as independent).
    pub speedup_over_paper_stderr: Option<f64>,
    /// best's speed-up over at_own_radius, and its standard error.
    pub speedup_over_own_radius: Option<f64>,
    /// Its standard error.
    pub speedup_over_own_radius_stderr: Option<f64>,
    /// Per (radius, strategy) that can reach the target, its fastest point (supported first), by
    /// time.
    pub candidates: Vec<ErrorPoint>,
    /// Every point evaluated of best's strategy, at every radius: its curve over budgets and
    /// radii (what a confirmation by direct runs picks neighbours from).
    pub best_strategy_points: Vec<ErrorPoint>,
    /// The (strategy, radius) pairs whose bias alone reaches the target.
    pub out_of_reach: Vec<OutOfReach>,
    /// The progressive schedule at best's strategy and budget.
    pub progressive: Option<ProgressiveRow>,
    /// What the plan could not do, in words.
    pub notes: Vec<String>,
}

/// [`error_plan`] of a run of `config` from its moments and its reports per radius
/// ([`crate::sim::solve::radius_reports::radius_reports`], in the configuration's order: its radii, then R).
pub fn error_plan_of(
    config: &SimConfig,
    moments: &Moments,
    reports: &[RadiusReport],
    solver: &SolverOptions,
    costs: Costs,
    target: f64,
) -> Result<ErrorPlan, PredictError> {
    let all: Vec<&Moments> = moments.radii.iter().chain(std::iter::once(moments)).collect();
    let data: Vec<RadiusData<'_>> =
        all.into_iter().zip(reports).map(|(moments, report)| RadiusData { moments, report }).collect();
    let measured = Budget { light_paths: config.light_paths(), camera_paths: config.camera_paths() };
    error_plan(&data, config.cells(), solver, measured, costs, target)
}

/// One radius's data for the plan: its moments, its report (biases, merges) and its config's
/// radius.
pub struct RadiusData<'a> {
    /// The moments at R′.
    pub moments: &'a Moments,
    /// The report at R′ (`solve::radii`).
    pub report: &'a RadiusReport,
}

/// The plan to `target` (relative RMSE, %) over `radii`, planned from budgets around `measured`.
pub fn error_plan(
    radii: &[RadiusData<'_>],
    grid: &CellGrid,
    solver: &SolverOptions,
    measured: Budget,
    costs: Costs,
    target: f64,
) -> Result<ErrorPlan, PredictError> {
    let mut candidates = Vec::new();
    let mut out_of_reach = Vec::new();
    let mut paper = None;
    let mut notes = Vec::new();
    let mut per_radius_points: Vec<(f64, Vec<BudgetPoint>)> = Vec::new();
    for data in radii {
        let report = data.report;
        let r = report.merge_radius;
        let bias = |s: Strategy| report.rows.iter().find(|x| x.strategy == s).and_then(|x| x.bias_percent);
        for row in &report.rows {
            if let Some(b) = row.bias_percent.filter(|b| b.abs() >= target) {
                let bias_percent_stderr = row.bias_percent_stderr;
                out_of_reach.push(OutOfReach {
                    strategy: row.strategy,
                    merge_radius: r,
                    bias_percent: b,
                    bias_percent_stderr,
                });
            }
        }
        let merges = report.merges_per_iteration;
        let seconds = |b: Budget| costs.iteration_seconds_with_merges(b, merges_at(merges, measured, b));
        let allowance = |s: Strategy| bias(s).filter(|b| b.abs() < target).map(|b| (target * target - b * b).sqrt());
        let timing = Timing { seconds: &seconds, allowance: &allowance };
        let plan = plan_with(data.moments, grid, solver, measured, costs, target, &timing)?;
        let point = |p: &BudgetPoint| error_point(p, r, report);
        for best in &plan.best {
            candidates.push(point(&best.point));
        }
        if (r - PAPER_RADIUS).abs() <= 1e-12 {
            paper = plan.paper.as_ref().map(point);
        }
        per_radius_points.push((r, plan.points));
    }
    candidates.sort_by(|a, b| {
        (!a.respects_fixed, !a.supported, a.seconds_to_target)
            .partial_cmp(&(!b.respects_fixed, !b.supported, b.seconds_to_target))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let eligible = |p: &&ErrorPoint| p.respects_fixed && p.supported;
    let best = candidates.iter().find(eligible).copied();
    let own_radius = radii.iter().find(|d| d.report.own).map(|d| d.report.merge_radius);
    let at_own_radius = candidates.iter().filter(eligible).find(|p| Some(p.merge_radius) == own_radius).copied();
    if paper.is_none() {
        notes.push(format!(
            "the paper's setup (switch at N_F = 10^7, N_B = 100, R = {PAPER_RADIUS}) needs the radius {PAPER_RADIUS} among the run's radii"
        ));
    }
    match (&best, own_radius) {
        (None, _) => notes.push("no supported point that keeps the fixed weights reaches the target".to_string()),
        (Some(b), Some(r)) if b.merge_radius == r && radii.len() > 1 => notes.push(format!(
            "the fastest radius is the run's own R = {r}, the largest it can see: a run at a larger R (with this one among its radii) may plan faster still"
        )),
        _ => {}
    }
    let (speedup_over_paper, speedup_over_paper_stderr) = speedup(best.as_ref(), paper.as_ref());
    let (speedup_over_own_radius, speedup_over_own_radius_stderr) = speedup(best.as_ref(), at_own_radius.as_ref());
    let best_strategy_points = best
        .as_ref()
        .map(|b| {
            radii
                .iter()
                .zip(&per_radius_points)
                .flat_map(|(data, (r, pts))| {
                    pts.iter().filter(|p| p.strategy == b.strategy).map(|p| error_point(p, *r, data.report))
                })
                .collect()
        })
        .unwrap_or_default();
    let progressive =
        best.as_ref().and_then(|b| progressive(b, radii, &per_radius_points, grid, solver, measured, costs, target));
    Ok(ErrorPlan {
        target_rmse_percent: target,
        costs,
        radii: radii.iter().map(|d| d.report.merge_radius).collect(),
        best,
        at_own_radius,
        paper,
        speedup_over_paper,
        speedup_over_paper_stderr,
        speedup_over_own_radius,
        speedup_over_own_radius_stderr,
        candidates,
        best_strategy_points,
        out_of_reach,
        progressive,
        notes,
    })
}

/// Merge events per pixel and iteration at `to`, from those at `measured`: plane 1 ∝ N_F, planes 2
/// and 3 ∝ N_F·N_B.
pub fn merges_at(merges: [f64; 3], measured: Budget, to: Budget) -> f64 {
    let light = to.light_paths as f64 / measured.light_paths as f64;
    let pairs = light * to.camera_paths as f64 / measured.camera_paths as f64;
    merges[0] * light + (merges[1] + merges[2]) * pairs
}

fn error_point(p: &BudgetPoint, radius: f64, report: &RadiusReport) -> ErrorPoint {
    let row = report.rows.iter().find(|x| x.strategy == p.strategy);
    let bias = row.and_then(|x| x.bias_percent).unwrap_or(0.0);
    let bias_se = row.and_then(|x| x.bias_percent_stderr);
    let iterations = p.seconds_to_target / p.seconds_per_iteration;
    // T = t·σ²/(P² − b²) while more than one iteration is needed: d ln T = 2 dσ/σ + 2b db/(P² − b²).
    let stderr = if iterations <= 1.0 {
        Some(0.0)
    } else {
        let allowance2 = p.rms_percent * p.rms_percent / iterations;
        p.rms_percent_stderr.map(|se| {
            let a = 2.0 * se / p.rms_percent;
            let b = bias_se.map_or(0.0, |sb| 2.0 * bias.abs() * sb / allowance2);
            p.seconds_to_target * (a * a + b * b).sqrt()
        })
    };
    ErrorPoint {
        strategy: p.strategy,
        merge_radius: radius,
        budget: p.budget,
        rms_percent: p.rms_percent,
        rms_percent_stderr: p.rms_percent_stderr,
        bias_percent: bias,
        bias_percent_stderr: bias_se,
        iterations,
        seconds_per_iteration: p.seconds_per_iteration,
        seconds_to_target: p.seconds_to_target,
        seconds_to_target_stderr: stderr,
        supported: p.supported() && stderr.is_some_and(|se| se <= 2.0 * SUPPORT_RELATIVE_SE * p.seconds_to_target),
        respects_fixed: p.respects_fixed,
    }
}

/// `of` sooner than `than` by how many times, with the delta-method SE (relative errors added in
/// quadrature, as if independent).
fn speedup(of: Option<&ErrorPoint>, than: Option<&ErrorPoint>) -> (Option<f64>, Option<f64>) {
    let (Some(a), Some(b)) = (of, than) else { return (None, None) };
    let value = b.seconds_to_target / a.seconds_to_target;
    let rel = |p: &ErrorPoint| p.seconds_to_target_stderr.map(|se| se / p.seconds_to_target);
    let se = rel(a).zip(rel(b)).map(|(x, y)| value * (x * x + y * y).sqrt());
    (Some(value), se)
}

/// One radius's figures at the progressive row's budget.
struct Knot {
    radius: f64,
    variance: f64,
    relative_se: f64,
    bias: f64,
    seconds: f64,
}

/// The progressive schedule at `best`'s strategy and budget, from each radius's prediction there
/// (the plan's point where its grid holds that budget, else predicted for it).
#[allow(clippy::too_many_arguments)]
fn progressive(
    best: &ErrorPoint,
    radii: &[RadiusData<'_>],
    points: &[(f64, Vec<BudgetPoint>)],
    grid: &CellGrid,
    solver: &SolverOptions,
    measured: Budget,
    costs: Costs,
    target: f64,
) -> Option<ProgressiveRow> {
    let mut knots: Vec<Knot> = Vec::new();
    for (data, (r, pts)) in radii.iter().zip(points) {
        let rms = match pts.iter().find(|p| p.strategy == best.strategy && p.budget == best.budget) {
            Some(p) => (p.rms_percent, p.rms_percent_stderr),
            None => {
                let predicted = Predictor::new(data.moments, measured).ok()?.at(grid, solver, best.budget);
                let row = predicted.noise_table.into_iter().find(|x| x.strategy == best.strategy)?;
                (row.rms_percent?, row.rms_percent_stderr)
            }
        };
        let bias = data.report.rows.iter().find(|x| x.strategy == best.strategy).and_then(|x| x.bias_percent)?;
        knots.push(Knot {
            radius: *r,
            variance: rms.0 * rms.0,
            relative_se: rms.1.map_or(f64::NAN, |se| se / rms.0),
            bias,
            seconds: costs.iteration_seconds_with_merges(
                best.budget,
                merges_at(data.report.merges_per_iteration, measured, best.budget),
            ),
        });
    }
    knots.sort_by(|a, b| a.radius.total_cmp(&b.radius));
    if knots.len() < 2 {
        return None;
    }
    let floor = knots[0].radius;
    // The fastest first radius among the tallied ones (above the smallest).
    let time = |run: &Schedule| run.reached.map_or(f64::INFINITY, |(_, seconds)| seconds);
    let fastest =
        knots.iter().skip(1).map(|k| schedule(&knots, k.radius, target)).min_by(|a, b| time(a).total_cmp(&time(b)))?;
    let Schedule { first, reached, last } = fastest;
    let relative = knots.iter().map(|k| k.relative_se).fold(0.0, f64::max);
    Some(ProgressiveRow {
        strategy: best.strategy,
        budget: best.budget,
        alpha: PROGRESSIVE_ALPHA,
        first_radius: first,
        last_radius: last,
        floored: last <= floor,
        iterations: reached.map(|(n, _)| n),
        seconds_to_target: reached.map(|(_, s)| s),
        seconds_to_target_stderr: reached.filter(|_| relative.is_finite()).map(|(_, s)| s * 2.0 * relative),
    })
}

/// A schedule's outcome: its first radius, (iterations, seconds) to the target if reached, and its
/// last radius.
struct Schedule {
    first: f64,
    reached: Option<(f64, f64)>,
    last: f64,
}

/// The schedule from `first` to `target`.
fn schedule(knots: &[Knot], first: f64, target: f64) -> Schedule {
    let floor = knots[0].radius;
    let radius = |i: f64| (first * i.powf((PROGRESSIVE_ALPHA - 1.0) / 2.0)).max(floor);
    // Σ over iterations 1..=n of (σ², b, t) at R_i, in geometric blocks (the summands vary slowly
    // with i): within 10⁻³ relative.
    let sums = |n: f64| {
        let (mut var, mut bias, mut secs, mut i) = (0.0, 0.0, 0.0, 1.0);
        while i <= n {
            let len = (i * 1e-3).floor().max(1.0).min(n - i + 1.0);
            let k = interpolate(knots, radius(i + (len - 1.0) / 2.0));
            var += k.variance * len;
            bias += k.bias * len;
            secs += k.seconds * len;
            i += len;
        }
        (var, bias, secs)
    };
    let error = |n: f64| {
        let (var, bias, _) = sums(n);
        ((var / (n * n)) + (bias / n).powi(2)).sqrt()
    };
    let mut hi = 1.0;
    while error(hi) > target {
        hi *= 2.0;
        if hi > 1e12 {
            return Schedule { first, reached: None, last: radius(1e12) };
        }
    }
    let mut lo = (hi / 2.0).max(1.0);
    if error(lo) <= target {
        hi = lo;
    }
    while hi - lo > 1.0 && hi / lo > 1.0 + 1e-4 {
        let mid = ((lo + hi) / 2.0).round();
        if error(mid) <= target { hi = mid } else { lo = mid }
    }
    let (_, _, secs) = sums(hi);
    Schedule { first, reached: Some((hi, secs)), last: radius(hi) }
}

/// The figures at radius `r` between the knots: σ² and t linear in R² (merges and the kernel's
/// footprint grow as R²), b linear in R (the switch's bias is first order in R; the heuristics',
/// second order and tiny, are bounded by it).
fn interpolate(knots: &[Knot], r: f64) -> Knot {
    let i = knots.iter().position(|k| k.radius >= r).unwrap_or(knots.len() - 1).max(1);
    let (a, b) = (&knots[i - 1], &knots[i]);
    let t2 = ((r * r - a.radius * a.radius) / (b.radius * b.radius - a.radius * a.radius)).clamp(0.0, 1.0);
    let t1 = ((r - a.radius) / (b.radius - a.radius)).clamp(0.0, 1.0);
    Knot {
        radius: r,
        variance: a.variance + (b.variance - a.variance) * t2,
        relative_se: a.relative_se.max(b.relative_se),
        bias: a.bias + (b.bias - a.bias) * t1,
        seconds: a.seconds + (b.seconds - a.seconds) * t2,
    }
}

#[cfg(test)]
mod tests;
