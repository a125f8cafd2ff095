//! The budget plan's grid, costs, fixed-time curve and support guard.

use super::*;

#[test]
fn the_log_grid_spans_its_ends_in_even_steps() {
    assert_eq!(log_grid(1, 100, 2), vec![1, 3, 10, 32, 100]);
    assert_eq!(log_grid(1_000_000, 100_000_000, 1), vec![1_000_000, 10_000_000, 100_000_000]);
}

#[test]
fn an_iteration_costs_its_light_paths_and_its_camera_paths_in_every_pixel() {
    let c = Costs {
        light_path: 1e-8,
        camera_path: 1e-7,
        iteration: 0.5,
        pixels: 1e6,
        merge: 0.0,
        source: CostSource::Given,
    };
    let t = c.iteration_seconds(Budget { light_paths: 10_000_000, camera_paths: 100 });
    assert!((t - (0.1 + 10.0 + 0.5)).abs() < 1e-12);
}

fn point(strategy: Strategy, light_paths: u64, camera_paths: u64, rms_percent: f64, seconds: f64) -> BudgetPoint {
    BudgetPoint {
        strategy,
        budget: Budget { light_paths, camera_paths },
        rms_percent,
        rms_percent_stderr: None,
        respects_fixed: true,
        seconds_per_iteration: seconds,
        seconds_to_target: rms_percent.powi(2) * seconds,
    }
}

/// The fastest point is taken among those the run supports; an unsupported faster one is
/// reported as such, and a strategy with no supported point keeps its fastest, marked.
#[test]
fn the_fastest_budget_is_the_fastest_the_run_supports() {
    let with_se = |p: BudgetPoint, se: f64| BudgetPoint { rms_percent_stderr: Some(se), ..p };
    let points = [
        // Supported (SE 10% and 25% of the RMS): 400·1 and 100·2 seconds.
        with_se(point(Strategy::Switch, 1_000_000, 10, 20.0, 1.0), 2.0),
        with_se(point(Strategy::Switch, 1_000_000, 100, 10.0, 2.0), 2.5),
        // Faster (4·3 seconds) but its SE is 150% of its RMS: noise, not a budget.
        with_se(point(Strategy::Switch, 100_000_000, 10, 2.0, 3.0), 3.0),
        // No SE at all, and the only point of its strategy.
        point(Strategy::Plane1, 1_000_000, 10, 8.0, 1.0),
    ];
    assert!(points[1].supported() && !points[2].supported() && !points[3].supported());
    let f = fastest(&points, Strategy::Switch).unwrap();
    assert_eq!(f.point.budget, Budget { light_paths: 1_000_000, camera_paths: 100 });
    assert!(f.supported && f.faster_unsupported);
    let only = fastest(&points[..2], Strategy::Switch).unwrap();
    assert!(only.supported && !only.faster_unsupported);
    let unsupported = fastest(&points, Strategy::Plane1).unwrap();
    assert!(!unsupported.supported && !unsupported.faster_unsupported);
    assert_eq!(unsupported.point.rms_percent, 8.0);
    assert!(fastest(&points, Strategy::Plane2).is_none());
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
