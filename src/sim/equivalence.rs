//! Block-wise comparison of two engines (or two runs): the figures the equivalence suite checks.
//!
//! A run of `blocks` blocks of equal length gives, per block, the luminance L and the RMS% of every
//! per-path strategy, and over all iterations the merge events per plane. Figures are compared as
//! means with standard errors: per-iteration errors for the merge counts, the spread of the block
//! values for L and RMS% — RMS% estimates are heavy-tailed, and independent blocks of equal length
//! measure their error honestly where a bootstrap would understate it.

use std::ops::Range;

use super::config::SimConfig;
use super::moments::Moments;
use super::noise::{merge_rates, path_rows};
use super::runner::run;

/// A mean and its standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub mean: f64,
    pub stderr: f64,
}

impl Estimate {
    /// Mean and standard error of the mean of a sample (at least two values).
    pub fn of(sample: &[f64]) -> Self {
        let n = sample.len() as f64;
        let mean = sample.iter().sum::<f64>() / n;
        let var = sample.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
        Self { mean, stderr: (var / n).sqrt() }
    }
}

/// What one run measured.
#[derive(Debug, Clone)]
pub struct Figures {
    /// Merge events per iteration at planes 1, 2, 3.
    pub merges: [Estimate; 3],
    /// Per per-path strategy: its name, L and RMS% (block means).
    pub strategies: Vec<(String, Estimate, Estimate)>,
}

/// One compared figure.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub what: String,
    pub a: Estimate,
    pub b: Estimate,
    /// (a − b) in combined standard errors.
    pub z: f64,
}

/// Runs `blocks` blocks of `block_len` iterations from iteration `first` and measures them.
pub fn measure(config: &SimConfig, seed: u64, first: u64, blocks: u64, block_len: u64) -> Figures {
    assert!(blocks >= 2, "block standard errors need at least two blocks");
    let mut total = Moments::new(config);
    let mut per_block = Vec::new();
    for b in 0..blocks {
        let range: Range<u64> = first + b * block_len..first + (b + 1) * block_len;
        let block = run(config, seed, range);
        per_block.push(path_rows(&block));
        total.merge(&block).expect("consecutive blocks of one run merge");
    }
    let merges = merge_rates(&total).map(|r| Estimate { mean: r.mean, stderr: r.stderr });
    let strategies = (0..per_block[0].len())
        .map(|s| {
            let values = |f: fn(&super::noise::NoiseRow) -> Option<f64>| -> Vec<f64> {
                per_block.iter().map(|rows| f(&rows[s]).unwrap_or(f64::NAN)).collect()
            };
            (
                per_block[0][s].strategy.clone(),
                Estimate::of(&values(|r| r.luminance)),
                Estimate::of(&values(|r| r.rms_percent)),
            )
        })
        .collect();
    Figures { merges, strategies }
}

/// Every figure of `a` against `b`.
pub fn compare(a: &Figures, b: &Figures) -> Vec<Comparison> {
    let pair = |what: String, a: Estimate, b: Estimate| {
        let z = (a.mean - b.mean) / (a.stderr * a.stderr + b.stderr * b.stderr).sqrt();
        Comparison { what, a, b, z }
    };
    let mut out: Vec<Comparison> =
        (0..3).map(|p| pair(format!("merges/iteration at plane {}", p + 1), a.merges[p], b.merges[p])).collect();
    for ((name, la, ra), (_, lb, rb)) in a.strategies.iter().zip(&b.strategies) {
        out.push(pair(format!("L of {name}"), *la, *lb));
        out.push(pair(format!("RMS% of {name}"), *ra, *rb));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_and_z_scores() {
        let e = Estimate::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(e.mean, 2.5);
        assert!((e.stderr - (5.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-15);
        let f = |m: f64| Figures {
            merges: [Estimate { mean: m, stderr: 0.3 }, Estimate { mean: 1.0, stderr: 0.4 }, e],
            strategies: vec![],
        };
        let z = compare(&f(1.0), &f(0.0));
        assert!((z[0].z - 1.0 / (0.18f64).sqrt()).abs() < 1e-12 && z[1].z == 0.0);
    }
}
