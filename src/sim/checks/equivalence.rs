//! Block-wise comparison of two engines (or two runs): the figures the equivalence suite checks.
//!
//! A run of `blocks` blocks of equal length gives, per block, the merge events per plane and
//! iteration, and the luminance L and the RMS% of every per-path strategy. Each figure is reported
//! as a mean with its standard error (per-iteration errors for the merge counts, the spread of the
//! block values for L and RMS% — RMS% estimates are heavy-tailed, and independent blocks of equal
//! length measure their error honestly where a bootstrap would understate it).
//!
//! Two runs are compared *block by block*: the camera paths of iteration s depend only on (seed, s),
//! not on the engine, so block b of two engines run from the same seed sees the same cameras and
//! the two blocks' figures are correlated. Blocks are independent of each other, so the differences
//! d_b = a_b − b_b are independent and identically distributed whether or not the runs share
//! cameras, and z = mean(d) / (sd(d)/√blocks) is the difference in its own standard errors. Treating
//! the runs as independent (z from the sum of the two variances) would overstate the error wherever
//! the cameras dominate the spread (plane 3 of the spot-lit scene) and let real differences hide.

use std::ops::Range;

use crate::sim::model::config::SimConfig;
use crate::sim::runner::run;
use crate::sim::solve::noise::{merge_rates, path_rows};
use crate::sim::stats::moments::Moments;

/// A mean and its standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The mean of the sample.
    pub mean: f64,
    /// The standard error of that mean (the sample's standard deviation over √n).
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
    /// Every block's values, in the order of [`Figures::names`]: merges per iteration at the three
    /// planes, then L and RMS% of each strategy.
    pub blocks: Vec<Vec<f64>>,
}

impl Figures {
    /// The names of a block's values, in order.
    pub fn names(&self) -> Vec<String> {
        let merges = (1..=3).map(|p| format!("merges/iteration at plane {p}"));
        let strategies =
            self.strategies.iter().flat_map(|(name, _, _)| [format!("L of {name}"), format!("RMS% of {name}")]);
        merges.chain(strategies).collect()
    }

    /// The whole-run estimates, in the order of [`Figures::names`].
    fn estimates(&self) -> Vec<Estimate> {
        let strategies = self.strategies.iter().flat_map(|(_, l, r)| [*l, *r]);
        self.merges.iter().copied().chain(strategies).collect()
    }
}

/// One compared figure.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The figure's name ([`Figures::names`]), e.g. "L of balance".
    pub what: String,
    /// The figure in the first run (block mean and standard error).
    pub a: Estimate,
    /// The figure in the second run.
    pub b: Estimate,
    /// Mean and standard error of the block differences a_b − b_b.
    pub difference: Estimate,
    /// The difference in its standard errors.
    pub z: f64,
}

/// Runs `blocks` blocks of `block_len` iterations from iteration `first` and measures them.
pub fn measure(config: &SimConfig, seed: u64, first: u64, blocks: u64, block_len: u64) -> Figures {
    assert!(blocks >= 2, "block standard errors need at least two blocks");
    let mut total = Moments::new(config);
    let mut per_block = Vec::new();
    let mut block_merges = Vec::new();
    for b in 0..blocks {
        let range: Range<u64> = first + b * block_len..first + (b + 1) * block_len;
        let block = run(config, seed, range);
        per_block.push(path_rows(&block, &Default::default()));
        block_merges.push(merge_rates(&block).map(|r| r.mean));
        total.merge(&block).expect("consecutive blocks of one run merge");
    }
    let merges = merge_rates(&total).map(|r| Estimate { mean: r.mean, stderr: r.stderr });
    let strategies = (0..per_block[0].len())
        .map(|s| {
            let values = |f: fn(&crate::sim::solve::noise::NoiseRow) -> Option<f64>| -> Vec<f64> {
                per_block.iter().map(|rows| f(&rows[s]).unwrap_or(f64::NAN)).collect()
            };
            (
                per_block[0][s].strategy.name().to_string(),
                Estimate::of(&values(|r| r.luminance)),
                Estimate::of(&values(|r| r.rms_percent)),
            )
        })
        .collect();
    let blocks = per_block
        .iter()
        .zip(&block_merges)
        .map(|(rows, merges)| {
            let strategies = rows.iter().flat_map(|r| [r.luminance, r.rms_percent].map(|v| v.unwrap_or(f64::NAN)));
            merges.iter().copied().chain(strategies).collect()
        })
        .collect();
    Figures { merges, strategies, blocks }
}

/// Every figure of `a` against `b`, block by block (see the module doc): both must have the same
/// number of blocks, of equal length, and the same strategies.
pub fn compare(a: &Figures, b: &Figures) -> Vec<Comparison> {
    assert_eq!(a.blocks.len(), b.blocks.len(), "block-wise comparison needs as many blocks on both sides");
    let names = a.names();
    assert_eq!(names, b.names(), "both runs must report the same figures");
    let (ea, eb) = (a.estimates(), b.estimates());
    names
        .into_iter()
        .enumerate()
        .map(|(i, what)| {
            let d: Vec<f64> = a.blocks.iter().zip(&b.blocks).map(|(x, y)| x[i] - y[i]).collect();
            let difference = Estimate::of(&d);
            // Bit-identical blocks (no spread at all) agree exactly rather than by 0/0.
            let z = if difference.mean == 0.0 && difference.stderr == 0.0 {
                0.0
            } else {
                difference.mean / difference.stderr
            };
            Comparison { what, a: ea[i], b: eb[i], difference, z }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_and_z_scores() {
        let e = Estimate::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(e.mean, 2.5);
        assert!((e.stderr - (5.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-15);
        let unused = Estimate { mean: 0.0, stderr: 0.0 };
        let f = |blocks: Vec<Vec<f64>>| Figures {
            merges: [unused; 3],
            strategies: vec![("plane1".into(), unused, unused)],
            blocks,
        };
        // Noise shared by both runs (10·b, as from the cameras of block b) cancels in the block
        // differences: the first figure differs by 1 or 1.5 per block, the second not at all.
        let a = f((0..4).map(|b| vec![10.0 * b as f64 + [1.0, 1.5, 1.0, 1.5][b], 5.0, 0.0, 1.0, 2.0]).collect());
        let b = f((0..4).map(|b| vec![10.0 * f64::from(b), 5.0, 0.0, 1.0, 2.0]).collect());
        let c = compare(&a, &b);
        assert_eq!(
            c.iter().map(|c| c.what.as_str()).collect::<Vec<_>>()[..4],
            [
                "merges/iteration at plane 1",
                "merges/iteration at plane 2",
                "merges/iteration at plane 3",
                "L of plane1"
            ]
        );
        let d = Estimate::of(&[1.0, 1.5, 1.0, 1.5]);
        assert_eq!(c[0].difference, d);
        assert!((c[0].z - 1.25 / d.stderr).abs() < 1e-12);
        assert_eq!(c[1].z, 0.0, "identical blocks agree exactly");
    }
}
