//! The accumulators against the moments' own exact sums: the same iterations, summed by several
//! workers in any order and handed over in parts, give moments equal to the last bit.

use serde_json::json;

use super::*;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::engines::tally::{BLOCKS, IterationTally};
use crate::sim::math::rng::{StreamRng, stream, uniform};
use crate::sim::model::config::SimConfig;
use crate::sim::spec::parse_job_spec;

fn config(components: bool) -> SimConfig {
    let spec = parse_job_spec(&json!({
        "cells": { "r2_edges": [0.0], "r3_edges": [0.0, 0.01, 0.02], "phi_bins": 1 },
        "folds": 4,
        "noise_components": components
    }))
    .unwrap();
    (**spec.validate().unwrap().config()).clone()
}

/// A value of random sign whose magnitude spans 10⁻¹⁷⁰ … 10⁰ (their products reach the
/// subnormals, as the tails of real contributions do), or zero.
fn value(rng: &mut StreamRng) -> f64 {
    let u = uniform(rng);
    if u < 0.3 {
        return 0.0;
    }
    let magnitude = 10f64.powf(-170.0 * uniform(rng).powi(4));
    if uniform(rng) < 0.2 { -magnitude } else { magnitude }
}

fn tally(cells: usize, s: u64, components: bool) -> IterationTally {
    let mut rng = stream(77, s, 0);
    let cell_values: Vec<f64> = (0..3 * cells).map(|_| value(&mut rng)).collect();
    let cell_counts = cell_values.iter().map(|&v| u64::from(v != 0.0) * (1 + s % 5)).collect();
    let mut strategies = [0.0; PathStrategy::COUNT];
    strategies.iter_mut().for_each(|x| *x = value(&mut rng));
    let (mut block_values, mut block_strategies) = (Vec::new(), [[0.0; PathStrategy::COUNT]; BLOCKS]);
    if components {
        block_values = (0..BLOCKS * 3 * cells).map(|_| value(&mut rng)).collect();
        block_strategies.iter_mut().flatten().for_each(|x| *x = value(&mut rng));
    }
    IterationTally {
        iteration: s,
        cell_values,
        cell_counts,
        strategies,
        merges: [s % 3, 1, s % 7],
        block_values,
        block_strategies,
        radii: Vec::new(),
    }
}

#[test]
fn workers_and_hand_overs_give_the_moments_of_one_exact_sum() {
    for components in [false, true] {
        let config = config(components);
        let cells = config.cells.len();
        let mut exact = Moments::new(&config);
        for s in 0..300 {
            exact.add_iteration(9, &tally(cells, s, components)).unwrap();
        }
        let mut fast = Moments::new(&config);
        let mut workers = vec![MomentsAccumulator::like(&fast); 3];
        // Iterations 0..120 by three workers in a scrambled order, handed over; then 120..300.
        for (range, stride) in [(0..120u64, 7u64), (120..300, 11)] {
            let n = range.end - range.start;
            for k in 0..n {
                let s = range.start + (k * stride) % n;
                workers[(s % 3) as usize].add_iteration(&tally(cells, s, components)).unwrap();
            }
            hand_over(&mut workers, &mut fast, 9, range).unwrap();
        }
        assert_eq!(fast, exact, "components: {components}");
        assert!(workers.iter().all(|w| w.iterations() == 0), "handed-over workers are empty");
    }
}

#[test]
fn a_refused_hand_over_changes_nothing() {
    let config = config(false);
    let cells = config.cells.len();
    let mut moments = Moments::new(&config);
    moments.add_iteration(9, &tally(cells, 5, false)).unwrap();
    let before = moments.clone();
    let mut workers = vec![MomentsAccumulator::like(&moments)];
    for s in 0..10 {
        workers[0].add_iteration(&tally(cells, s, false)).unwrap();
    }
    let e = hand_over(&mut workers, &mut moments, 9, 0..10).unwrap_err();
    assert!(matches!(e, MergeError::Overlap(_)), "{e}");
    assert_eq!(moments, before);
    // A cleared worker starts again from nothing.
    workers[0].clear();
    assert_eq!(workers[0].iterations(), 0);
    let mut extreme = tally(cells, 11, false);
    extreme.cell_values[0] = 1e80;
    assert!(matches!(workers[0].add_iteration(&extreme), Err(MergeError::Overflow(_))));
    assert_eq!(workers[0].iterations(), 0, "a refused iteration is not counted");
}
