//! The ray budget: which (N_F, N_B) reaches a target noise soonest, per strategy, from one run's
//! noise components (docs/model.md §12).
//!
//! In the paper N_F light paths serve every pixel of the image while N_B camera paths go through
//! *this* pixel, so an iteration of a renderer with P pixels costs t = t_F·N_F + t_B·N_B·P + t_0.
//! A strategy whose per-iteration relative noise at (N_F, N_B) is R (the predicted RMS%) needs
//! max(1, (R/target)²) iterations for a target RMS, so the time to the target is T = (R/target)²·t. Each
//! strategy's T is evaluated on a grid of budgets — the optimum *re-fitted* at every point — and the
//! best point reported, beside the paper's configuration (10⁷, 100, switch).

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
    Ok(BudgetPlan { target_rms_percent: target, costs, best, paper, points })
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
}
