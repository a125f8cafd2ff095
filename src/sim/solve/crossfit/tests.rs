//! Tests of cross-fitting on synthetic moments whose answer is known.

use std::f64::consts::TAU;

use serde_json::json;

use super::*;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::engines::tally::IterationTally;
use crate::sim::math::rng::{StreamRng, stream, uniform_open0};
use crate::sim::model::config::SimConfig;
use crate::sim::solve::noise::noise_table;
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::parse_job_spec;

/// Three cells (one r2 ring, r3 edges 0, 0.01, 0.02 and a tail), K = 10 folds.
fn config() -> SimConfig {
    let spec = parse_job_spec(&json!({
        "cells": { "r2_edges": [0.0], "r3_edges": [0.0, 0.01, 0.02], "phi_bins": 1 },
        "folds": 10
    }))
    .unwrap();
    (**spec.validate().unwrap().config()).clone()
}

/// The true luminance of each cell: every technique estimates it without bias.
const CELL_L: [f64; 3] = [1.0, 0.5, 0.25];
/// Log-normal spread σ of each technique: skewed, so that large values come with large
/// variance — the in-sample fit then down-weights whatever happened to come out large.
const SIGMA: [f64; 3] = [1.2, 0.6, 0.9];

fn normal(rng: &mut StreamRng) -> f64 {
    let (u, v) = (uniform_open0(rng), uniform_open0(rng));
    (-2.0 * u.ln()).sqrt() * (TAU * v).cos()
}

/// One synthetic iteration: C⁽ᵐ⁾_α = L_α·exp(σ_m Z − σ_m²/2), mean exactly L_α, with a shared
/// factor so the techniques are correlated (as merges of the same paths are).
fn iteration(cells: usize, s: u64, rng: &mut StreamRng) -> IterationTally {
    let mut cell_values = vec![0.0; 3 * cells];
    for a in 0..cells {
        let shared = normal(rng);
        for m in 0..3 {
            let z = 0.6 * shared + 0.8 * normal(rng);
            cell_values[m * cells + a] = CELL_L[a] * (SIGMA[m] * z - SIGMA[m] * SIGMA[m] / 2.0).exp();
        }
    }
    let plane3: f64 = (0..cells).map(|a| cell_values[2 * cells + a]).sum();
    IterationTally {
        iteration: s,
        cell_values,
        cell_counts: vec![1; 3 * cells],
        strategies: [plane3; PathStrategy::COUNT],
        merges: [1; 3],
        block_values: Vec::new(),
        block_strategies: Default::default(),
        radii: Vec::new(),
    }
}

fn run(config: &SimConfig, seed: u64, m: u64) -> Moments {
    let mut moments = Moments::new(config);
    for s in 0..m {
        let mut rng = stream(seed, s, 0);
        moments.add_iteration(seed, &iteration(config.cells.len(), s, &mut rng)).unwrap();
    }
    moments
}

/// Mean and its standard error over replications.
fn mean_se(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Over 300 independent runs of 60 iterations (6 free weights): the mean of the cross-fitted L is
/// within 3 standard errors of the truth, the in-sample L is biased by more than 3, and the
/// in-sample RMS is below the cross-fitted one.
#[test]
fn cross_fitting_is_unbiased_where_the_in_sample_fit_is_not() {
    let config = config();
    let truth: f64 = CELL_L.iter().sum();
    let solver = SolverOptions { fixed: Default::default(), lambda: 0.0, cv_lambdas: vec![0.0], trust_region: None };
    let (mut cross, mut inner, mut cv, mut rms_gap) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for seed in 0..300 {
        let moments = run(&config, 1000 + seed, 60);
        let table = noise_table(&moments, &config.cells, &solver);
        let row = |s: Strategy| table.rows.iter().find(|r| r.strategy == s).unwrap().clone();
        let (holdout, optimal) = (row(Strategy::OptimalHoldout), row(Strategy::Optimal));
        assert!(optimal.in_sample && !holdout.in_sample && !row(Strategy::OptimalCv).in_sample);
        cross.push(holdout.luminance.unwrap());
        inner.push(optimal.luminance.unwrap());
        cv.push(row(Strategy::OptimalCv).luminance.unwrap());
        rms_gap.push(holdout.rms_percent.unwrap() - optimal.rms_percent.unwrap());
    }
    let ((c, c_se), (i, i_se), (v, v_se), (g, g_se)) =
        (mean_se(&cross), mean_se(&inner), mean_se(&cv), mean_se(&rms_gap));
    println!(
        "truth {truth}: cross-fitted {c:.5} ± {c_se:.5} (z {:.2}), in-sample {i:.5} ± {i_se:.5} (z {:.2}), cv {v:.5} ± {v_se:.5}; RMS gap {g:.2} ± {g_se:.2} points",
        (c - truth) / c_se,
        (i - truth) / i_se
    );
    assert!((c - truth).abs() < 3.0 * c_se, "cross-fitted L is biased: {c} ± {c_se} vs {truth}");
    assert!((v - truth).abs() < 3.0 * v_se, "optimal_cv's L is biased: {v} ± {v_se} vs {truth}");
    assert!((i - truth).abs() > 3.0 * i_se, "the in-sample bias should show: {i} ± {i_se} vs {truth}");
    assert!(g > 3.0 * g_se, "the in-sample RMS should be optimistic: gap {g} ± {g_se}");
}

/// Folds follow the iteration index: a run split into shards and merged has the same folds, so
/// the cross-fitted figures are bit-identical.
#[test]
fn cross_fits_of_merged_shards_equal_the_whole_run() {
    let config = config();
    let whole = run(&config, 5, 57);
    let mut merged = Moments::new(&config);
    for range in [0..20u64, 20..41, 41..57] {
        let mut part = Moments::new(&config);
        for s in range {
            let mut rng = stream(5, s, 0);
            part.add_iteration(5, &iteration(config.cells.len(), s, &mut rng)).unwrap();
        }
        merged.merge(&part).unwrap();
    }
    let solver =
        SolverOptions { fixed: Default::default(), lambda: 0.0, cv_lambdas: vec![0.0, 0.1], trust_region: None };
    let (a, b) = (noise_table(&whole, &config.cells, &solver), noise_table(&merged, &config.cells, &solver));
    assert_eq!(a.rows, b.rows);
    assert_eq!(whole.folds.iter().map(|f| f.iterations).collect::<Vec<_>>(), vec![6, 6, 6, 6, 6, 6, 6, 5, 5, 5]);
}

/// The jackknife standard error of a mean over K equal groups is the usual σ/√M.
#[test]
fn jackknife_of_a_mean_is_the_standard_error() {
    // Groups of two values each; replicate f is the mean without group f.
    let groups = [[1.0, 3.0], [2.0, 2.5], [0.5, 4.0], [3.0, 1.5], [2.2, 2.8]];
    let all: Vec<f64> = groups.iter().flatten().copied().collect();
    let total: f64 = all.iter().sum();
    let replicates = groups.iter().map(|g| (total - g[0] - g[1]) / 8.0);
    // For group means ḡ_f the jackknife gives √(Σ(ḡ_f − ḡ)²/(K(K − 1))): the SE of the mean of
    // the K group means.
    let means: Vec<f64> = groups.iter().map(|g| (g[0] + g[1]) / 2.0).collect();
    let (_, se_of_group_means) = mean_se(&means);
    assert!((jackknife_se(replicates) - se_of_group_means).abs() < 1e-12);
}
