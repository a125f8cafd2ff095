//! Runs compared strategy by strategy (`GET /v1/compare`, `optimis compare`): each run's L and
//! RMS with their standard errors, and against the first run (the baseline) the ratio and the
//! difference of L and the ratio of RMS, each with its standard error, and z = ΔL / SE(ΔL).
//!
//! The runs are taken as independent (other seeds, or other configurations): the standard error
//! of a difference is √(SE_a² + SE_b²) and that of a ratio a/b by the delta method,
//! (a/b)·√((SE_a/a)² + (SE_b/b)²). Runs of one configuration that share iterations are not
//! independent; [`compare`] says so in `notes` instead of printing standard errors that would be
//! wrong.

use serde::{Deserialize, Serialize};

use super::row::NoiseRow;
use super::strategy::Strategy;
use crate::sim::stats::coverage::Coverage;

/// Most runs one comparison takes.
pub const MAX_COMPARED: usize = 8;

/// One run to compare: a label (a job id, a file name), its noise table and what it holds.
#[derive(Debug, Clone, Copy)]
pub struct Compared<'a> {
    /// How the run is named in the comparison.
    pub label: &'a str,
    /// Its noise table.
    pub rows: &'a [NoiseRow],
    /// Its configuration fingerprint.
    pub fingerprint: &'a str,
    /// The iterations it holds.
    pub coverage: &'a Coverage,
}

/// Runs compared strategy by strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Comparison {
    /// The runs, in the order given; the first is the baseline of every ratio and difference.
    pub runs: Vec<ComparedRun>,
    /// One entry per strategy every run has, in the first run's order.
    pub strategies: Vec<StrategyComparison>,
    /// What the standard errors assume, and where they do not hold.
    pub notes: Vec<String>,
}

/// A compared run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ComparedRun {
    /// Its label (`job 3`, a file name).
    pub label: String,
    /// Its configuration fingerprint (equal fingerprints: the same scene, R, N_F, N_B, cells).
    pub fingerprint: String,
    /// Iterations it holds.
    pub iterations: u64,
}

/// One strategy across the runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct StrategyComparison {
    /// The noise-table row.
    pub strategy: Strategy,
    /// True for the in-sample `optimal` row: its figures are optimistic, so are their ratios.
    pub in_sample: bool,
    /// Its figures in each run, in the runs' order.
    pub runs: Vec<ComparedFigures>,
}

/// A strategy's figures in one run, and against the baseline's (null for the baseline itself and
/// where a figure is missing).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct ComparedFigures {
    /// L, model units.
    pub luminance: Option<f64>,
    /// Its standard error.
    pub luminance_stderr: Option<f64>,
    /// RMS of one iteration, percent of L.
    pub rms_percent: Option<f64>,
    /// Its standard error.
    pub rms_percent_stderr: Option<f64>,
    /// L / L of the baseline.
    pub luminance_ratio: Option<f64>,
    /// Its standard error (delta method, independent runs).
    pub luminance_ratio_stderr: Option<f64>,
    /// L − L of the baseline, model units.
    pub luminance_difference: Option<f64>,
    /// Its standard error.
    pub luminance_difference_stderr: Option<f64>,
    /// The difference over its standard error.
    pub z: Option<f64>,
    /// RMS / RMS of the baseline (below 1: less noisy than the baseline).
    pub rms_ratio: Option<f64>,
    /// Its standard error (delta method, independent runs).
    pub rms_ratio_stderr: Option<f64>,
}

/// Compares `runs` (the first is the baseline). Strategies missing from a run are left out.
pub fn compare(runs: &[Compared<'_>]) -> Comparison {
    let mut notes = vec![
        "Ratios and differences are against the first run; their standard errors take the runs as independent \
         (other seeds or other configurations)."
            .to_string(),
    ];
    for (i, a) in runs.iter().enumerate() {
        for b in &runs[i + 1..] {
            if a.fingerprint == b.fingerprint && !a.coverage.overlaps(b.coverage).is_empty() {
                notes.push(format!(
                    "{} and {} share iterations of one configuration: their differences are not independent and \
                     the standard errors between them are wrong (compare runs of other seeds)",
                    a.label, b.label
                ));
            }
        }
    }
    let strategies = match runs.first() {
        None => Vec::new(),
        Some(base) => base
            .rows
            .iter()
            .filter_map(|b| {
                let rows: Option<Vec<&NoiseRow>> =
                    runs.iter().map(|r| r.rows.iter().find(|x| x.strategy == b.strategy)).collect();
                let rows = rows?;
                Some(StrategyComparison {
                    strategy: b.strategy,
                    in_sample: b.in_sample,
                    runs: rows.iter().enumerate().map(|(i, r)| figures(r, (i > 0).then_some(b))).collect(),
                })
            })
            .collect(),
    };
    Comparison {
        runs: runs
            .iter()
            .map(|r| ComparedRun {
                label: r.label.to_string(),
                fingerprint: r.fingerprint.to_string(),
                iterations: u64::try_from(r.coverage.iterations()).unwrap_or(u64::MAX),
            })
            .collect(),
        strategies,
        notes,
    }
}

fn figures(row: &NoiseRow, base: Option<&NoiseRow>) -> ComparedFigures {
    let l = row.luminance.zip(row.luminance_stderr);
    let rms = row.rms_percent.zip(row.rms_percent_stderr);
    let base_l = base.and_then(|b| b.luminance.zip(b.luminance_stderr));
    let base_rms = base.and_then(|b| b.rms_percent.zip(b.rms_percent_stderr));
    let difference = l.zip(base_l).map(|((a, sa), (b, sb))| (a - b, sa.hypot(sb)));
    let l_ratio = l.zip(base_l).and_then(|(a, b)| ratio(a, b));
    let rms_ratio = rms.zip(base_rms).and_then(|(a, b)| ratio(a, b));
    ComparedFigures {
        luminance: row.luminance,
        luminance_stderr: row.luminance_stderr,
        rms_percent: row.rms_percent,
        rms_percent_stderr: row.rms_percent_stderr,
        luminance_ratio: l_ratio.map(|r| r.0),
        luminance_ratio_stderr: l_ratio.map(|r| r.1),
        luminance_difference: difference.map(|d| d.0),
        luminance_difference_stderr: difference.map(|d| d.1),
        z: difference.and_then(|(d, se)| (se > 0.0).then(|| d / se)),
        rms_ratio: rms_ratio.map(|r| r.0),
        rms_ratio_stderr: rms_ratio.map(|r| r.1),
    }
}

/// a/b and its delta-method standard error, for (value, SE) pairs; none when b is 0.
fn ratio((a, sa): (f64, f64), (b, sb): (f64, f64)) -> Option<(f64, f64)> {
    if b == 0.0 || !(a / b).is_finite() {
        return None;
    }
    let r = a / b;
    let rel_a = if a == 0.0 { 0.0 } else { sa / a };
    Some((r, r.abs() * rel_a.hypot(sb / b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(strategy: Strategy, l: f64, sl: f64, rms: f64, srms: f64) -> NoiseRow {
        let mut r = NoiseRow::from_sums(strategy, 0.0, 0.0, 0.0, None);
        (r.luminance, r.luminance_stderr, r.rms_percent, r.rms_percent_stderr) =
            (Some(l), Some(sl), Some(rms), Some(srms));
        r
    }

    #[test]
    fn ratios_and_differences_carry_their_standard_errors() {
        let a = [row(Strategy::Switch, 2.0, 0.03, 60.0, 3.0), row(Strategy::Plane1, 2.0, 0.1, 200.0, 20.0)];
        let b = [row(Strategy::Switch, 2.2, 0.04, 30.0, 1.5)];
        let (ca, cb) = (Coverage::range(1, 0, 100), Coverage::range(2, 0, 100));
        let c = compare(&[
            Compared { label: "a", rows: &a, fingerprint: "f", coverage: &ca },
            Compared { label: "b", rows: &b, fingerprint: "f", coverage: &cb },
        ]);
        assert_eq!(c.strategies.len(), 1, "only the strategies both runs have");
        let [base, other] = &c.strategies[0].runs[..] else { panic!() };
        assert_eq!(base.rms_ratio, None);
        assert!((other.luminance_difference.unwrap() - 0.2).abs() < 1e-12);
        assert!((other.luminance_difference_stderr.unwrap() - 0.05).abs() < 1e-12);
        assert!((other.z.unwrap() - 4.0).abs() < 1e-9);
        assert!((other.rms_ratio.unwrap() - 0.5).abs() < 1e-12);
        // 0.5 · √(0.05² + 0.05²)
        assert!((other.rms_ratio_stderr.unwrap() - 0.5 * 0.05f64.hypot(0.05)).abs() < 1e-12);
        assert!((other.luminance_ratio.unwrap() - 1.1).abs() < 1e-12);
        assert_eq!(c.notes.len(), 1, "independent seeds: no warning");
        // The same seed's iterations twice: said, not hidden.
        let c = compare(&[
            Compared { label: "a", rows: &a, fingerprint: "f", coverage: &ca },
            Compared { label: "a again", rows: &a, fingerprint: "f", coverage: &ca },
        ]);
        assert!(c.notes[1].contains("share iterations"), "{:?}", c.notes);
    }
}
