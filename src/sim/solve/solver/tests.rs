//! Tests of the solver on synthetic moments whose optimum is known.
use super::*;
use crate::sim::engines::layout::Layout;
use crate::sim::math::rng::{stream, uniform};

/// Synthetic statistics from explicit per-iteration vectors Y_s.
fn stats_from(ys: &[DVector<f64>], samples: Vec<u64>) -> YStats {
    let n = ys[0].len();
    let mut sum_y = DVector::zeros(n);
    let mut sum_yy = DMatrix::zeros(n, n);
    for y in ys {
        sum_y += y;
        sum_yy += y * y.transpose();
    }
    YStats { layout: Layout::new(samples.len(), 2), m: ys.len() as f64, sum_y, sum_yy, cell_samples: samples }
}

/// A problem whose optimum is known: B_s = −⟨A_s|W*⟩ + L + small noise, so W* makes C_s nearly
/// constant. The fit must recover W*, and no perturbation may lower the sample variance.
fn synthetic(k: usize, w_star: &DVector<f64>, iterations: usize) -> YStats {
    let mut rng = stream(42, 0, 0);
    let ys: Vec<DVector<f64>> = (0..iterations)
        .map(|_| {
            let a = DVector::from_fn(2 * k, |_, _| uniform(&mut rng) - 0.5);
            let noise = 1e-3 * (uniform(&mut rng) - 0.5);
            let b = 1.0 - a.dot(w_star) + noise;
            let mut y = DVector::zeros(2 * k + 1);
            y.rows_mut(0, 2 * k).copy_from(&a);
            y[2 * k] = b;
            y
        })
        .collect();
    stats_from(&ys, vec![10; k])
}

fn variance(stats: &YStats, v: &DVector<f64>) -> f64 {
    let (s1, s2) = stats.evaluate(v);
    s2 / stats.m - (s1 / stats.m).powi(2)
}

#[test]
fn recovers_known_weights_and_beats_every_perturbation() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    let k = grid.len();
    let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
    let stats = synthetic(k, &w_star, 2000);
    let fit = fit(&stats, &grid, &FixedWeights::default(), 0.0, &[]).unwrap();
    let v = fit.coefficients(stats.layout);
    let w = v.rows(0, 2 * k).into_owned();
    assert!((&w - &w_star).amax() < 1e-3, "fitted {w} vs {w_star}");
    assert!(fit.cells.iter().all(|c| c.status == CellStatus::Fitted && (c.w.iter().sum::<f64>() - 1.0).abs() < 1e-12));
    let best = variance(&stats, &v);
    let mut rng = stream(43, 0, 0);
    for _ in 0..500 {
        // Any other table (B's coefficient stays 1: every table's cells sum to one).
        let dir = DVector::from_fn(2 * k + 1, |i, _| if i < 2 * k { uniform(&mut rng) - 0.5 } else { 0.0 });
        for eps in [1e-4, 1e-2, 1.0] {
            let v = variance(&stats, &(&v + &dir * eps));
            assert!(v >= best, "perturbation {eps} lowered the variance: {v} < {best}");
        }
    }
}

#[test]
fn fixed_weights_are_respected() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
    let stats = synthetic(3, &w_star, 500);
    let fixed = FixedWeights { w0: Some(0.0), ..Default::default() };
    let f = fit(&stats, &grid, &fixed, 0.0, &[]).unwrap();
    assert!(f.cells.iter().all(|c| c.w[0] == 0.0 && (c.w.iter().sum::<f64>() - 1.0).abs() < 1e-12));
    assert_eq!(f.free, 3);
    let fixed2 = FixedWeights { w2: Some(0.25), ..Default::default() };
    let f2 = fit(&stats, &grid, &fixed2, 0.0, &[]).unwrap();
    assert!(f2.cells.iter().all(|c| (c.w[2] - 0.25).abs() < 1e-12));
    let all = FixedWeights { w0: Some(0.0), w1: Some(1.0), w2: None };
    let f3 = fit(&stats, &grid, &all, 0.0, &[]).unwrap();
    assert!(f3.cells.iter().all(|c| c.status == CellStatus::Fixed && c.w == [0.0, 1.0, 0.0]));
}

#[test]
fn penalty_smooths_towards_neighbours() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
    let stats = synthetic(3, &w_star, 500);
    let spread = |f: &Fit| {
        f.cells.iter().map(|c| c.w[1]).fold(f64::NEG_INFINITY, f64::max)
            - f.cells.iter().map(|c| c.w[1]).fold(f64::INFINITY, f64::min)
    };
    let free = fit(&stats, &grid, &FixedWeights::default(), 0.0, &[]).unwrap();
    let smooth = fit(&stats, &grid, &FixedWeights::default(), 1e6, &[]).unwrap();
    assert!(spread(&smooth) < 1e-3 && spread(&free) > 0.5, "{} vs {}", spread(&smooth), spread(&free));
}

#[test]
fn empty_cells_and_singular_systems_are_reported() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    // Cell 2 never sees a sample: A is zero there.
    let mut rng = stream(44, 0, 0);
    let ys: Vec<DVector<f64>> = (0..200)
        .map(|_| {
            let mut y = DVector::zeros(7);
            for i in [0, 1, 3, 4] {
                y[i] = uniform(&mut rng) - 0.5;
            }
            y[6] = 1.0 + uniform(&mut rng);
            y
        })
        .collect();
    let stats = stats_from(&ys, vec![5, 5, 0]);
    let f = fit(&stats, &grid, &FixedWeights::default(), 0.0, &[]).unwrap();
    assert_eq!(f.cells[2].status, CellStatus::Empty);
    assert_eq!(f.cells[2].w, f.cells[1].w, "empty cells take their nearest fitted neighbour's weights");
    let smoothed = fit(&stats, &grid, &FixedWeights::default(), 1e-3, &[]).unwrap();
    assert_eq!(smoothed.cells[2].status, CellStatus::Smoothed);

    // Cells 0 and 1 always move together: their weights are not separately determined.
    let ys: Vec<DVector<f64>> = (0..200)
        .map(|_| {
            let x = uniform(&mut rng) - 0.5;
            DVector::from_vec(vec![x, x, 0.0, 0.0, 0.0, 0.0, 1.0 + uniform(&mut rng)])
        })
        .collect();
    let stats = stats_from(&ys, vec![5, 5, 0]);
    let fixed = FixedWeights { w1: Some(0.0), ..Default::default() };
    let e = fit(&stats, &grid, &fixed, 0.0, &[]).expect_err("a singular system");
    assert_eq!(e, SolveError::Singular { dimension: 2, rank: 1, cells: vec![0, 1], heuristic_terms: 0 });
    assert!(e.to_string().contains("the weights of cells [0, 1];"), "{e}");
    assert!(fit(&stats, &grid, &fixed, 1e-3, &[]).is_ok(), "a penalty resolves it");
    let one = stats_from(&ys[..1], vec![1, 1, 0]);
    assert_eq!(fit(&one, &grid, &fixed, 0.0, &[]).unwrap_err(), SolveError::TooFewIterations(1));
    let zero = stats_from(&vec![DVector::zeros(7); 10], vec![0, 0, 0]);
    assert_eq!(fit(&zero, &grid, &fixed, 0.0, &[]).unwrap_err(), SolveError::NoSignal);
}

/// A heuristic whose per-iteration value is nearly constant (H = L + small noise) is the optimum
/// of the stacked family: β → 1 on it, 0 on a noisy one, and the table's cells sum to 1 − Σβ.
#[test]
fn the_stacked_family_finds_a_heuristic_that_beats_every_table() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    let k = grid.len();
    let layout = Layout::new(k, 3);
    let mut rng = stream(45, 0, 0);
    let (switch, noisy) = (
        layout.heuristic_index(PathStrategy::Switch).unwrap(),
        layout.heuristic_index(PathStrategy::BalancePlanes23).unwrap(),
    );
    let ys: Vec<DVector<f64>> = (0..3000)
        .map(|_| {
            let mut y = DVector::zeros(layout.dimension());
            for a in 0..k {
                y[k + a] = uniform(&mut rng) - 0.5;
            }
            y[2 * k] = 1.0 + (uniform(&mut rng) - 0.5);
            y[switch] = 1.0 + 1e-3 * (uniform(&mut rng) - 0.5);
            y[noisy] = 1.0 + 0.3 * (uniform(&mut rng) - 0.5);
            y
        })
        .collect();
    let mut stats = stats_from(&ys, vec![10; k]);
    stats.layout = layout;
    let fixed = FixedWeights { w0: Some(0.0), ..Default::default() };
    assert_eq!(
        stackable(layout, &fixed),
        [
            PathStrategy::Switch,
            PathStrategy::BalancePlanes23,
            PathStrategy::PowerPlanes23,
            PathStrategy::CorrelationAwarePlanes23
        ]
    );
    let family = [PathStrategy::Switch, PathStrategy::BalancePlanes23];
    let f = fit(&stats, &grid, &fixed, 0.0, &family).unwrap();
    let beta: Vec<f64> = f.heuristics.iter().map(|h| h.1).collect();
    assert!((beta[0] - 1.0).abs() < 0.01 && beta[1].abs() < 0.01, "β {beta:?}");
    for c in &f.cells {
        assert_eq!(c.w[0], 0.0);
        assert!((c.w.iter().sum::<f64>() - (1.0 - f.beta_sum())).abs() < 1e-12);
    }
    let table = fit(&stats, &grid, &fixed, 0.0, &[]).unwrap();
    let (vs, vt) = (variance(&stats, &f.coefficients(layout)), variance(&stats, &table.coefficients(layout)));
    assert!(vs < 1e-3 * vt, "stacked {vs} vs table {vt}");
    // Freeing nothing admits every column; the unrenormalised heuristics break w0 = 0.
    assert_eq!(
        fit(&stats, &grid, &fixed, 0.0, &[PathStrategy::Balance]).unwrap_err(),
        SolveError::NotStackable(PathStrategy::Balance)
    );
    assert_eq!(stackable(layout, &FixedWeights::default()).len(), 7);
    assert!(stackable(Layout::new(k, 2), &FixedWeights::default()).is_empty());
}

/// A singular system's message names what is undetermined — cells, stacked heuristics'
/// coefficients, or a combination spread over many cells — and never an empty list of cells.
#[test]
fn the_singular_error_names_what_is_undetermined() {
    let message = |cells: Vec<usize>, heuristic_terms| {
        SolveError::Singular { dimension: 54, rank: 53, cells, heuristic_terms }.to_string()
    };
    assert!(message(vec![3, 7], 0).contains("do not determine the weights of cells [3, 7];"));
    assert!(message(vec![3], 1).contains("the weights of cells [3] and the coefficient β of one stacked heuristic;"));
    assert!(
        message(vec![], 2).contains("do not determine the coefficients β of 2 stacked heuristics; run more iterations")
    );
    assert!(message(vec![3], 0).ends_with(
        "add a gradient penalty (solver.lambda > 0), fix a weight, use coarser cells or run more iterations"
    ));
    assert!(message(vec![], 0).contains("do not determine the weights (no single cell: a combination of them);"));
}

/// The stacked optimum stacks the switch and the correlation-aware heuristics that keep the fixed
/// weights (docs/model.md §7): not the balance and power ones, whose columns nearly repeat them.
#[test]
fn the_stack_is_the_switch_and_the_correlation_aware_heuristics_that_keep_the_fixed_weights() {
    use PathStrategy::*;
    let layout = Layout::new(4, 3);
    let paper = FixedWeights { w0: Some(0.0), ..Default::default() };
    assert_eq!(stack_family(layout, &paper), vec![Switch, CorrelationAwarePlanes23]);
    assert_eq!(
        stack_family(layout, &FixedWeights::default()),
        vec![Switch, CorrelationAware, CorrelationAwarePlanes23]
    );
    let w1 = FixedWeights { w1: Some(0.5), ..Default::default() };
    assert!(stack_family(layout, &w1).is_empty());
    assert!(stack_family(Layout::new(4, 2), &paper).is_empty());
    // Every stacked heuristic is one the moments keep a column of.
    assert!(PathStrategy::STACKED.iter().all(|h| PathStrategy::STACKABLE.contains(h)));
}

/// Under a penalty, a cell with fewer than 30 merge events is set by its neighbours and says so.
#[test]
fn penalty_dominated_cells_are_smoothed() {
    let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
    let mut rng = stream(46, 0, 0);
    let ys: Vec<DVector<f64>> = (0..500)
        .map(|_| {
            let mut y = DVector::zeros(7);
            for i in [0, 1, 3, 4] {
                y[i] = uniform(&mut rng) - 0.5;
            }
            // Cell 2 sees a tiny signal: a handful of small merges.
            y[5] = 1e-4 * (uniform(&mut rng) - 0.5);
            y[6] = 1.0 + uniform(&mut rng);
            y
        })
        .collect();
    let stats = stats_from(&ys, vec![500, 30, 29]);
    let f = fit(&stats, &grid, &FixedWeights { w0: Some(0.0), ..Default::default() }, 1e-3, &[]).unwrap();
    let status: Vec<CellStatus> = f.cells.iter().map(|c| c.status).collect();
    assert_eq!(status, [CellStatus::Fitted, CellStatus::Fitted, CellStatus::Smoothed]);
}
