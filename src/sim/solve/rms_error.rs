//! The standard error of a fitted row's RMS.
//!
//! A per-path strategy's RMS gets the delta method on its power sums Σ C^k, k ≤ 4 ([`super::row`]):
//! stable, and calibrated over seeds (docs/results.md §10). A fitted row's C_s = ⟨Y_s|v⟩ are linear
//! in its weights, so the moments give its variance exactly but not its fourth moment, and the only
//! direct estimate is the delete-a-fold jackknife of its cross-fitted RMS — with K = 10 folds, nine
//! degrees of freedom, and on heavy-tailed values (one bright-spot event can hold percents of
//! Σ(C − L)²) it scatters by a factor of two from run to run and is most often too small.
//!
//! Most of a fitted row's noise is shared with a per-path strategy it resembles (the stacked
//! optimum is mostly β·`correlation_aware_planes23`), so we split it: RMS_F = q·RMS_P for the
//! per-path row P whose ratio q is best determined (the smallest relative jackknife SE of q over
//! the folds, both scored on the same iterations), and
//!
//!   SE(RMS_F)² ≈ (q·SE_δ(RMS_P))² + (RMS_P·SE_J(q))²,
//!
//! the delta method carrying the common noise and the paired jackknife the (small) difference. The
//! covariance of the two terms is left out: a heavy event that inflates RMS_P inflates RMS_F too
//! and so moves q the other way, which makes the sum an upper bound in that case. Without a per-path
//! row with a delta-method SE (predicted sums), the jackknife alone is used.

use super::row::{NoiseRow, central_3_4, power_sums};
use super::strategy::Strategy;
use crate::sim::stats::moments::Moments;

/// Per used fold f: (f, [M_f, Σ C, Σ C²]) of a row's scored values.
pub type FoldSums = Vec<(usize, [f64; 3])>;

/// A per-path row as a reference for fitted rows' standard errors: its sums per fold, its RMS and
/// the delta-method SE of its RMS.
#[derive(Debug, Clone)]
pub struct RmsReference {
    /// The per-path strategy.
    pub strategy: Strategy,
    /// Its (M_f, Σ C, Σ C²) per used fold.
    pub folds: FoldSums,
    /// Its RMS% over all iterations.
    pub rms_percent: f64,
    /// The delta-method standard error of that RMS%.
    pub rms_percent_stderr: f64,
}

/// Every per-path strategy of `moments` with a delta-method SE of its RMS.
pub fn references(moments: &Moments) -> Vec<RmsReference> {
    let pooled = moments.pooled();
    let m = pooled.iterations as f64;
    moments
        .layout()
        .strategies()
        .iter()
        .filter_map(|&p| {
            let s = power_sums(&pooled, p)?;
            let row = NoiseRow::from_sums(Strategy::of_path(p), m, s[0], s[1], (m > 0.0).then(|| central_3_4(m, s)));
            let folds = moments
                .folds
                .iter()
                .enumerate()
                .filter(|(_, f)| f.iterations > 0)
                .filter_map(|(i, f)| power_sums(f, p).map(|x| (i, [f.iterations as f64, x[0], x[1]])))
                .collect();
            Some(RmsReference {
                strategy: row.strategy,
                folds,
                rms_percent: row.rms_percent?,
                rms_percent_stderr: row.rms_percent_stderr.filter(|s| s.is_finite())?,
            })
        })
        .collect()
}

/// (M, Σ C, Σ C²) of `sums` over the folds in `folds`, leaving out `left_out`.
pub(crate) fn total(sums: &FoldSums, folds: &[usize], left_out: Option<usize>) -> [f64; 3] {
    sums.iter()
        .filter(|(f, _)| folds.contains(f) && Some(*f) != left_out)
        .fold([0.0; 3], |t, (_, s)| [t[0] + s[0], t[1] + s[1], t[2] + s[2]])
}

/// The jackknife SE of the RMS% of `own` over its folds.
pub fn jackknife_rms_stderr(own: &FoldSums) -> Option<f64> {
    let folds: Vec<usize> = own.iter().map(|(f, _)| *f).collect();
    if folds.len() < 2 {
        return None;
    }
    let replicates: Option<Vec<f64>> = folds.iter().map(|&f| rms_percent(total(own, &folds, Some(f)))).collect();
    replicates.map(|r| jackknife_se(r.into_iter()))
}

/// The SE of the RMS% of the scored sums `own` (module docs): through the best-determined
/// reference, else the jackknife alone.
pub fn rms_stderr(own: &FoldSums, references: &[RmsReference]) -> Option<f64> {
    let best = references
        .iter()
        .filter_map(|r| {
            let folds: Vec<usize> =
                own.iter().map(|(f, _)| *f).filter(|f| r.folds.iter().any(|(g, _)| g == f)).collect();
            if folds.len() < 2 || folds.len() != own.len() {
                return None;
            }
            let ratio = |left_out: Option<usize>| {
                Some(rms_percent(total(own, &folds, left_out))? / rms_percent(total(&r.folds, &folds, left_out))?)
            };
            let q = ratio(None)?;
            let replicates: Option<Vec<f64>> = folds.iter().map(|&f| ratio(Some(f))).collect();
            let q_se = jackknife_se(replicates?.into_iter());
            (q.is_finite() && q_se.is_finite()).then_some((q_se / q, q, q_se, r))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    match best {
        Some((_, q, q_se, r)) => Some(((q * r.rms_percent_stderr).powi(2) + (r.rms_percent * q_se).powi(2)).sqrt()),
        None => jackknife_rms_stderr(own),
    }
}

/// RMS% of pooled sums (M, Σ C, Σ C²), if there is a mean.
pub fn rms_percent([m, s1, s2]: [f64; 3]) -> Option<f64> {
    relative_noise([m, s1, s2]).map(|r| 100.0 * (r * m / (m - 1.0)).sqrt())
}

/// The jackknife standard error of leave-one-group-out replicates: √((K − 1)/K · Σ (θ₋f − θ̄)²).
pub fn jackknife_se(replicates: impl Iterator<Item = f64> + Clone) -> f64 {
    let k = replicates.clone().count() as f64;
    let mean = replicates.clone().sum::<f64>() / k;
    ((k - 1.0) / k * replicates.map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt()
}

/// Var/mean² of pooled sums (M, Σ C, Σ C²): the squared relative RMS, for ranking.
pub(crate) fn relative_noise([m, s1, s2]: [f64; 3]) -> Option<f64> {
    let mean = s1 / m;
    (m >= 2.0 && mean != 0.0).then(|| (s2 / m - mean * mean).max(0.0) / (mean * mean))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scored sums proportional to a reference's in every fold (q constant): the SE is the
    /// reference's, scaled by q, whatever the jackknife of either alone says.
    #[test]
    fn a_row_proportional_to_a_reference_inherits_its_delta_method_error() {
        let folds: FoldSums = (0..6).map(|f| (f, [100.0, 50.0 + f as f64, 40.0 + 3.0 * f as f64])).collect();
        // The same values scaled by 3 have the same RMS: q = 1.
        let scaled: FoldSums = folds.iter().map(|&(f, [m, s1, s2])| (f, [m, 3.0 * s1, 9.0 * s2])).collect();
        let reference = RmsReference { strategy: Strategy::Switch, folds, rms_percent: 80.0, rms_percent_stderr: 2.5 };
        let se = rms_stderr(&scaled, std::slice::from_ref(&reference)).unwrap();
        assert!((se - 2.5).abs() < 1e-9, "{se}");
        assert!(rms_stderr(&scaled, &[]).is_some_and(|j| (j - 2.5).abs() > 1e-3), "the jackknife alone differs");
    }
}
