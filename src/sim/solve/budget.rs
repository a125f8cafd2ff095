//! The ray budget: which (N_F, N_B) reaches a target noise soonest, per strategy, from one run's
//! noise components (docs/model.md §12).
//!
//! In the paper N_F light paths serve every pixel of the image while N_B camera paths go through
//! *this* pixel, so an iteration of a renderer with P pixels costs t = t_F·N_F + t_B·N_B·P + t_0.
//! A strategy whose per-iteration relative noise at (N_F, N_B) is R (the predicted RMS%) needs
//! max(1, (R/target)²) iterations for a target RMS, so the time to the target is T = (R/target)²·t. Each
//! strategy's T is evaluated on a grid of budgets — the optimum *re-fitted* at every point — and the
//! best point reported, beside the paper's configuration (10⁷, 100, switch).
//!
//! The same points also give the other view of the trade-off (`FixedTime`): the RMS each budget
//! reaches in a fixed wall time — the time the paper's configuration takes to the target — as a
//! curve against the ratio N_F/N_B.

use serde::{Deserialize, Serialize};

use super::options::SolverOptions;
use super::predict::{Budget, PredictError, Predictor};
use super::strategy::Strategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::stats::moments::Moments;

/// Seconds per light path, per camera path and pixel, and per iteration, and the pixel count P.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Costs {
    pub light_path: f64,
    pub camera_path: f64,
    pub iteration: f64,
    pub pixels: f64,
}

impl Costs {
    /// Seconds of one renderer iteration at `b`.
    pub fn iteration_seconds(&self, b: Budget) -> f64 {
        self.light_path * b.light_paths as f64 + self.camera_path * b.camera_paths as f64 * self.pixels + self.iteration
    }
}

/// One strategy at one budget.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BudgetPoint {
    pub strategy: Strategy,
    pub budget: Budget,
    /// Predicted RMS% of one iteration.
    pub rms_percent: f64,
    pub seconds_per_iteration: f64,
    /// Seconds to the target RMS: max(1, (rms/target)²) iterations.
    pub seconds_to_target: f64,
}

/// The best budget of every strategy, the paper's configuration, and every point evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BudgetPlan {
    pub target_rms_percent: f64,
    pub costs: Costs,
    /// Per strategy (that could be predicted), its fastest point on the grid.
    pub best: Vec<BudgetPoint>,
    /// `switch` at (10⁷, 100): the paper's configuration.
    pub paper: Option<BudgetPoint>,
    /// Every (strategy, budget) evaluated.
    pub points: Vec<BudgetPoint>,
    /// The RMS at the paper configuration's time against N_F/N_B (absent if the paper's
    /// configuration could not be predicted).
    pub fixed_time: Option<FixedTime>,
}

/// The RMS every budget reaches in a fixed wall time T, as a curve against N_F/N_B
/// (docs/model.md §12).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
pub struct FixedTimePoint {
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

/// Evaluates every strategy on the grid `light × camera` (and the paper's budget) for `target`.
#[allow(clippy::too_many_arguments)]
pub fn plan(
    moments: &Moments,
    grid: &CellGrid,
    solver: &SolverOptions,
    measured: Budget,
    costs: Costs,
    target: f64,
    light: &[u64],
    camera: &[u64],
) -> Result<BudgetPlan, PredictError> {
    let predictor = Predictor::new(moments, measured)?;
    let mut points = Vec::new();
    let evaluate = |b: Budget, points: &mut Vec<BudgetPoint>| {
        let p = predictor.at(grid, solver, b);
        let seconds = costs.iteration_seconds(b);
        for row in &p.noise_table {
            if let Some(r) = row.rms_percent.filter(|r| r.is_finite() && *r > 0.0) {
                // At least one iteration: a budget whose single iteration beats the target still
                // costs that iteration.
                let iterations = (r / target).powi(2).max(1.0);
                points.push(BudgetPoint {
                    strategy: row.strategy,
                    budget: b,
                    rms_percent: r,
                    seconds_per_iteration: seconds,
                    seconds_to_target: iterations * seconds,
                });
            }
        }
    };
    for &l in light {
        for &c in camera {
            evaluate(Budget { light_paths: l, camera_paths: c }, &mut points);
        }
    }
    let mut at_paper = Vec::new();
    evaluate(PAPER_BUDGET, &mut at_paper);
    let paper = at_paper.iter().find(|p| p.strategy == Strategy::Switch).copied();
    let mut best: Vec<BudgetPoint> = Vec::new();
    for p in &points {
        match best.iter_mut().find(|b| b.strategy == p.strategy) {
            Some(b) if p.seconds_to_target < b.seconds_to_target => *b = *p,
            Some(_) => {}
            None => best.push(*p),
        }
    }
    best.sort_by(|a, b| a.seconds_to_target.total_cmp(&b.seconds_to_target));
    let order: Vec<Strategy> = best.iter().map(|b| b.strategy).collect();
    let fixed_time = paper.map(|p| fixed_time(&points, p.seconds_to_target, &order));
    Ok(BudgetPlan { target_rms_percent: target, costs, best, paper, points, fixed_time })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_grid_spans_its_ends_in_even_steps() {
        assert_eq!(log_grid(1, 100, 2), vec![1, 3, 10, 32, 100]);
        assert_eq!(log_grid(1_000_000, 100_000_000, 1), vec![1_000_000, 10_000_000, 100_000_000]);
    }

    #[test]
    fn an_iteration_costs_its_light_paths_and_its_camera_paths_in_every_pixel() {
        let c = Costs { light_path: 1e-8, camera_path: 1e-7, iteration: 0.5, pixels: 1e6 };
        let t = c.iteration_seconds(Budget { light_paths: 10_000_000, camera_paths: 100 });
        assert!((t - (0.1 + 10.0 + 0.5)).abs() < 1e-12);
    }

    fn point(strategy: Strategy, light_paths: u64, camera_paths: u64, rms_percent: f64, seconds: f64) -> BudgetPoint {
        BudgetPoint {
            strategy,
            budget: Budget { light_paths, camera_paths },
            rms_percent,
            seconds_per_iteration: seconds,
            seconds_to_target: rms_percent.powi(2) * seconds,
        }
    }

    #[test]
    fn the_fixed_time_curve_keeps_the_lowest_rms_after_t_at_each_ratio() {
        let points = [
            // Ratio 10⁵ twice (the second rounded as on the grid): 20%·√(4/100) = 4% and
            // 10%·√(25/100) = 5%; the first is kept.
            point(Strategy::Switch, 1_000_000, 10, 20.0, 4.0),
            point(Strategy::Switch, 3_162_278, 32, 10.0, 25.0),
            // Ratio 10⁴, slower than T: a quarter of an iteration, 3%·√(400/100) = 6%.
            point(Strategy::Switch, 1_000_000, 100, 3.0, 400.0),
            point(Strategy::Plane1, 1_000_000, 10, 8.0, 1.0),
        ];
        let f = fixed_time(&points, 100.0, &[Strategy::Switch]);
        assert_eq!(f.seconds, 100.0);
        assert_eq!(f.curve.len(), 2, "two ratios of one strategy: {:?}", f.curve);
        let (low, high) = (f.curve[0], f.curve[1]);
        assert_eq!(low.budget, Budget { light_paths: 1_000_000, camera_paths: 100 });
        assert!((low.ratio - 1e4).abs() < 1e-6 && (low.iterations - 0.25).abs() < 1e-12);
        assert!((low.rms_percent - 6.0).abs() < 1e-12);
        assert_eq!(high.budget, Budget { light_paths: 1_000_000, camera_paths: 10 });
        assert!((high.iterations - 25.0).abs() < 1e-12 && (high.rms_percent - 4.0).abs() < 1e-12);
        // The group's ratio: the geometric mean of 10⁵ and 3162278/32 = 98821.2.
        assert!((high.ratio - (1e5f64 * 3_162_278.0 / 32.0).sqrt()).abs() < 1e-6, "{}", high.ratio);
    }
}
