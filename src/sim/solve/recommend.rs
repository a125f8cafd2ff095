//! Which row of the noise table to recommend, and how much it gains.
//!
//! **The guard.** The recommendation is what a researcher takes into a renderer, so it must be the
//! best thing the run knows and never worse than it says:
//!
//! * candidates are the honest rows that keep the solver's fixed weights — every per-path strategy
//!   that keeps them, and every cross-fitted row whose fit is stable (the in-sample `optimal` row and
//!   unstable fits never are; each fitted row chose its λ by the one-standard-error rule,
//!   [`super::crossfit::select_lambda`]);
//! * the best fitted row (lowest cross-fitted RMS) is recommended only if it beats the best
//!   per-path row *beyond [`GUARD_SE`] standard errors*: the paired variance ratio
//!   Var(per-path)/Var(fitted), both on the same iterations, must exceed 1 by more than 1.645 times
//!   its jackknife SE over the folds (a one-sided test at the 5% level); otherwise the per-path row
//!   is recommended — its figures involve no fit at all.
//!
//! **The gain** compares the recommended row with the best per-path strategy other than itself that
//! keeps the fixed weights (the paper's reference is the switch, case 4), as a variance ratio with
//! the paired jackknife SE: each replicate leaves one fold out of both variances, so a fold of
//! unusual iterations moves numerator and denominator together. The same ratio against the best
//! per-path strategy that does *not* keep the fixed weights measures what the constraint costs.

use serde::{Deserialize, Serialize};

pub use super::anchor::GUARD_SE;

use super::anchor::anchor_of;
pub(crate) use super::anchor::paired_ratio;
use super::crossfit::Scored;
use super::effective::FitReplicates;
use super::fitted::Fitted;
use super::row::{NoiseRow, WeightErrors};
use super::solver::Fit;
use super::strategy::Strategy;
use crate::sim::engines::strategies::PathStrategy;

/// The recommended row.
#[derive(Debug, Clone)]
pub struct Recommended {
    /// The recommended row's strategy.
    pub strategy: Strategy,
    /// The fitted row's fit at its λ (None when a per-path strategy is recommended).
    pub fitted: Option<Scored>,
    /// Why this row, in a sentence.
    pub reason: String,
}

impl Recommended {
    /// λ of a fitted recommendation.
    pub fn lambda(&self) -> Option<f64> {
        self.fitted.as_ref().map(|s| s.cross_fit.lambda)
    }

    /// The weights to take into a renderer: the fit on all iterations at the row's λ.
    pub fn fit(&self) -> Option<&Fit> {
        self.fitted.as_ref().map(|s| &s.all)
    }

    /// The fold fits of a fitted recommendation (the jackknife replicates of its weights).
    pub fn replicates(&self) -> Option<FitReplicates> {
        self.fitted.as_ref().map(|s| s.cross_fit.replicates())
    }

    /// Jackknife standard errors of each cell's weights over the fold fits.
    pub fn weight_stderr(&self) -> Option<WeightErrors> {
        self.fitted.as_ref().and_then(|s| s.cross_fit.weight_stderr())
    }
}

/// Var(versus) / Var(strategy): how many times fewer iterations `strategy` needs than `versus` for
/// the same noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Gain {
    /// The ratio Var(versus)/Var(strategy) on the same iterations (> 1: `strategy` is better).
    pub value: f64,
    /// Paired jackknife over the folds (module docs); null with fewer than two folds holding
    /// iterations.
    pub stderr: Option<f64>,
    /// The per-path strategy compared against.
    pub versus: Strategy,
    /// The recommended strategy.
    pub strategy: Strategy,
}

/// How sure a recommendation is: the guard's comparison of the best trusted fitted row with the
/// best per-path row, as a verdict a reader can act on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Margin {
    /// `beats`: the fitted row is better beyond [`GUARD_SE`] standard errors, and recommended;
    /// `within_noise`: it is not measurably better, so the per-path row is recommended;
    /// `noisier`: the fitted row is the noisier one (ratio below 1); `no_fit`: no fitted row is
    /// stable and within the trust region, or none could be compared.
    pub verdict: MarginVerdict,
    /// The best per-path row that keeps the fixed weights.
    pub versus: Option<Strategy>,
    /// The best trusted fitted row it was compared with.
    pub fitted: Option<Strategy>,
    /// Var(versus)/Var(fitted) on the same iterations (> 1: the fit is better).
    pub variance_ratio: Option<f64>,
    /// Its paired jackknife SE over the folds.
    pub stderr: Option<f64>,
    /// (ratio − 1)/SE: how many standard errors the fit is better by.
    pub z: Option<f64>,
}

/// [`Margin::verdict`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum MarginVerdict {
    /// The fitted row beats the per-path row beyond the guard, and is recommended.
    Beats,
    /// Not measurably better: the per-path row is recommended.
    WithinNoise,
    /// The fitted row is noisier than the per-path row.
    Noisier,
    /// No trusted fitted row to compare.
    NoFit,
}

impl Choice {
    /// The margin of this choice (from its guard).
    pub fn margin(&self) -> Margin {
        let fitted_recommended = self.recommended.as_ref().is_ok_and(|r| r.fitted.is_some());
        match self.guard {
            Some(g) => {
                let z = g.stderr.filter(|s| *s > 0.0).map(|s| (g.value - 1.0) / s);
                let verdict = if fitted_recommended {
                    MarginVerdict::Beats
                } else if g.value < 1.0 {
                    MarginVerdict::Noisier
                } else {
                    MarginVerdict::WithinNoise
                };
                Margin {
                    verdict,
                    versus: Some(g.versus),
                    fitted: Some(g.strategy),
                    variance_ratio: Some(g.value),
                    stderr: g.stderr,
                    z,
                }
            }
            None => Margin {
                verdict: if fitted_recommended { MarginVerdict::Beats } else { MarginVerdict::NoFit },
                versus: None,
                fitted: None,
                variance_ratio: None,
                stderr: None,
                z: None,
            },
        }
    }
}

/// The recommendation and its gains.
#[derive(Debug, Clone)]
pub struct Choice {
    /// The recommended row, or why no row can be recommended.
    pub recommended: Result<Recommended, String>,
    /// Against the best other per-path strategy that keeps the fixed weights.
    pub gain: Option<Gain>,
    /// Against the best per-path strategy that does not.
    pub unconstrained: Option<Gain>,
    /// The guard's test: Var(best per-path row keeping the fixed weights)/Var(best stable fitted
    /// row), paired (`strategy` the fitted row, `versus` the per-path one).
    pub guard: Option<Gain>,
}

pub use super::rms_error::FoldSums;

/// Chooses the recommended row among `rows` (module docs); `fitted` holds the fits behind the
/// cross-fitted rows, `path_sums` gives a per-path strategy's sums per fold (measured, or
/// predicted at another budget).
pub fn recommend(rows: &[NoiseRow], fitted: &[Fitted], path_sums: &dyn Fn(PathStrategy) -> FoldSums) -> Choice {
    let usable = |r: &&NoiseRow| r.error.is_none() && r.rms_percent.is_some_and(|x| x.is_finite() && x > 0.0);
    let lowest = |it: &mut dyn Iterator<Item = &NoiseRow>| {
        it.min_by(|a, b| a.rms_percent.unwrap_or(f64::INFINITY).total_cmp(&b.rms_percent.unwrap_or(f64::INFINITY)))
            .map(|r| r.strategy)
    };
    let is_path = |r: &&NoiseRow| r.strategy.path().is_some();
    // The per-path row the run stands on: the correlation-aware prior unless another beats it
    // beyond the guard, never a row missing its tail while another keeps the fixed weights.
    let anchor = anchor_of(rows, path_sums);
    let best_path = anchor.as_ref().map(|a| Strategy::of_path(a.strategy));
    let anchor_note = anchor.and_then(|a| a.note).map_or_else(String::new, |n| format!("; {n}"));
    let best_fitted = lowest(
        &mut rows
            .iter()
            .filter(usable)
            .filter(|r| r.strategy.is_fitted() && !r.in_sample && !r.unstable && !r.beyond_trust_region)
            .filter(|r| fitted.iter().any(|f| f.strategy == r.strategy)),
    );
    let sums = |s: Strategy| fold_sums(path_sums, fitted, s);
    let rms = |s: Strategy| rows.iter().find(|r| r.strategy == s).and_then(|r| r.rms_percent).unwrap_or(f64::NAN);
    let guard = match (best_fitted, best_path) {
        (Some(f), Some(p)) => {
            paired_ratio(&sums(p), &sums(f)).map(|(value, stderr)| Gain { value, stderr, versus: p, strategy: f })
        }
        _ => None,
    };
    let recommended = match (best_fitted, best_path) {
        (Some(f), Some(p)) => {
            let ratio = guard.map(|g| (g.value, g.stderr));
            match ratio {
                Some((g, Some(se))) if g - 1.0 > GUARD_SE * se => Ok((
                    f,
                    format!(
                        "the lowest honest RMS ({:.1}%); it beats {p} ({:.1}%) by a variance ratio of {g:.3} ± {se:.3}, more than {GUARD_SE} standard errors (one-sided 95%)",
                        rms(f),
                        rms(p)
                    ),
                )),
                _ => {
                    let by = ratio.map_or_else(String::new, |(g, se)| {
                        format!(" (variance ratio {g:.3} ± {})", se.map_or("?".to_string(), |s| format!("{s:.3}")))
                    });
                    // A ratio below 1 is a fitted row noisier than the per-path one (a short run,
                    // where the fit's own noise dominates): "within noise" would understate that.
                    let relation = match ratio {
                        Some((g, _)) if g < 1.0 => "is noisier than",
                        _ => "is within noise of",
                    };
                    Ok((
                        p,
                        format!(
                            "no fitted row beats it beyond {GUARD_SE} standard errors (one-sided 95%): the best fitted row, {f} ({:.1}%), {relation} {p} ({:.1}%){by}{anchor_note}",
                            rms(f),
                            rms(p)
                        ),
                    ))
                }
            }
        }
        (Some(f), None) => {
            Ok((f, format!("the lowest honest RMS ({:.1}%); no per-path strategy keeps the fixed weights", rms(f))))
        }
        (None, Some(p)) => Ok((
            p,
            format!(
                "the per-path row the run stands on ({:.1}%); no fitted row is stable and within the trust region{anchor_note}",
                rms(p)
            ),
        )),
        (None, None) => Err("no honest row keeping the solver's fixed weights has a finite RMS".to_string()),
    };
    let recommended = recommended.map(|(strategy, reason)| Recommended {
        strategy,
        fitted: fitted.iter().find(|f| f.strategy == strategy).map(|f| f.scored.clone()),
        reason,
    });
    let against = |inside: bool| -> Option<Gain> {
        let r = recommended.as_ref().ok()?;
        let versus = lowest(
            &mut rows
                .iter()
                .filter(usable)
                .filter(is_path)
                .filter(|x| x.respects_fixed == inside && x.strategy != r.strategy),
        )?;
        let (value, stderr) = paired_ratio(&sums(versus), &sums(r.strategy))?;
        Some(Gain { value, stderr, versus, strategy: r.strategy })
    };
    let (gain, unconstrained) = (against(true), against(false));
    Choice { recommended, gain, unconstrained, guard }
}

/// The scored sums per fold of row `s`: a per-path strategy's power sums, or a fitted row's
/// cross-fitted sums.
fn fold_sums(path_sums: &dyn Fn(PathStrategy) -> FoldSums, fitted: &[Fitted], s: Strategy) -> FoldSums {
    match s.path() {
        Some(p) => path_sums(p),
        None => fitted
            .iter()
            .find(|f| f.strategy == s)
            .map(|f| f.scored.cross_fit.folds.iter().map(|(fold, _, sums)| (*fold, *sums)).collect())
            .unwrap_or_default(),
    }
}
