//! How the optimal weights are fitted: the solver options of a job (fixed weights, the gradient
//! penalty λ, the cross-validation grid), their validation, and the one way to change them — a JSON
//! Merge Patch naming the offending field the same way wherever a patch comes from (a re-solve, a
//! study, the command line).

use serde::{Deserialize, Serialize};

use serde_json::Value;

use crate::sim::model::params::{SpecError, check, merge_patch};

/// Most λ values a cross-validation grid may try.
pub const MAX_CV_LAMBDAS: usize = 32;

/// Largest gradient penalty λ.
pub const MAX_LAMBDA: f64 = 1e12;

/// How the optimal weights are fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SolverOptions {
    /// Weights held fixed in every cell (the paper: w0 = 0).
    pub fixed: FixedWeights,
    /// Gradient penalty λ ≥ 0 between neighbouring cells (dimensionless; see the solver).
    pub lambda: f64,
    /// The λ grid searched by the `optimal_cv` strategy.
    pub cv_lambdas: Vec<f64>,
    /// How far a fitted row's per-path weights may move from the best per-path row's to be
    /// trusted (`solve::trust`): λ is chosen among the fits within it, and a fit beyond it is never
    /// recommended. `"off"` switches the region off (every stable fit is trusted, as before issue
    /// 40); `null` in a whole specification means the same.
    // Left out when it has its default, so that a spec (and a moments document, whose checksum
    // covers its spec) written before the option existed reads back to the same bytes. "Off" is
    // written as the word, not as null: in a merge patch (`patched`) null means "remove", which
    // would bring the default back — a patch could never switch the region off.
    #[serde(
        default = "default_trust_region",
        skip_serializing_if = "is_default_trust_region",
        with = "trust_region_json"
    )]
    #[cfg_attr(feature = "server", schema(value_type = Option<TrustRegionJson>))]
    pub trust_region: Option<f64>,
}

/// The default trust region: fitted weights may move by at most 0.25 on any path from the best
/// per-path row's (`solve::trust`; docs/results.md §18 for how it was chosen).
pub const DEFAULT_TRUST_REGION: f64 = 0.25;

fn default_trust_region() -> Option<f64> {
    Some(DEFAULT_TRUST_REGION)
}

fn is_default_trust_region(region: &Option<f64>) -> bool {
    *region == default_trust_region()
}

/// `solver.trust_region` as JSON: a radius, or the word `"off"`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(untagged)]
pub enum TrustRegionJson {
    /// The largest move of a per-path weight from the anchor's (≥ 0).
    Radius(f64),
    /// No trust region.
    Off(Off),
}

/// The word `"off"`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Off {
    /// Switched off.
    Off,
}

mod trust_region_json {
    use super::{Off, TrustRegionJson};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(region: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        match region {
            Some(r) => TrustRegionJson::Radius(*r),
            None => TrustRegionJson::Off(Off::Off),
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        Ok(match Option::<TrustRegionJson>::deserialize(d)? {
            Some(TrustRegionJson::Radius(r)) => Some(r),
            Some(TrustRegionJson::Off(_)) | None => None,
        })
    }
}

/// Per-component fixed weights; `None` means fitted.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FixedWeights {
    /// The weight of plane-1 merges (the pixel) in every cell, if fixed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub w0: Option<f64>,
    /// The weight of plane-2 merges in every cell, if fixed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub w1: Option<f64>,
    /// The weight of plane-3 merges in every cell, if fixed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub w2: Option<f64>,
}

impl SolverOptions {
    /// These options changed by `patch` (a JSON Merge Patch of solver options) and validated. Every
    /// caller — a re-solve, a study, the command line — names a bad field the same way: `solver.…`
    /// as in a job specification (`solver` alone when the patch is not an object).
    pub fn patched(&self, patch: &Value) -> Result<SolverOptions, SpecError> {
        if !patch.is_object() {
            return Err(SpecError::new("solver", "must be a JSON object of solver options"));
        }
        let mut options = serde_json::to_value(self).expect("solver options serialise");
        merge_patch(&mut options, patch);
        let options: SolverOptions = serde_path_to_error::deserialize(&options).map_err(|e| {
            let path = e.path().to_string();
            let field = if path == "." { "solver".to_string() } else { format!("solver.{path}") };
            SpecError::new(field, e.into_inner().to_string())
        })?;
        validate_solver(&options)?;
        Ok(options)
    }
}

impl FixedWeights {
    /// The fixed value of component m (0, 1, 2).
    pub fn get(&self, m: usize) -> Option<f64> {
        [self.w0, self.w1, self.w2][m]
    }
}

/// Checks solver options (also used alone when a stored job is re-solved with new options).
pub fn validate_solver(solver: &SolverOptions) -> Result<(), SpecError> {
    for (m, w) in [solver.fixed.w0, solver.fixed.w1, solver.fixed.w2].into_iter().enumerate() {
        if let Some(w) = w {
            check(w.is_finite() && w.abs() <= 1e6, &format!("solver.fixed.w{m}"), || {
                format!("must be a finite weight with |w| ≤ 1e6, got {w}")
            })?;
        }
    }
    if let (Some(a), Some(b), Some(c)) = (solver.fixed.w0, solver.fixed.w1, solver.fixed.w2) {
        check((a + b + c - 1.0).abs() <= 1e-9, "solver.fixed", || {
            format!("w0 + w1 + w2 must equal 1 when all three are fixed, got {}", a + b + c)
        })?;
    }
    check(solver.lambda.is_finite() && (0.0..=MAX_LAMBDA).contains(&solver.lambda), "solver.lambda", || {
        format!("must be in [0, {MAX_LAMBDA:e}], got {}", solver.lambda)
    })?;
    if let Some(r) = solver.trust_region {
        check(r.is_finite() && r >= 0.0, "solver.trust_region", || {
            format!("must be a finite radius ≥ 0 (or \"off\": no trust region), got {r}")
        })?;
    }
    check((1..=MAX_CV_LAMBDAS).contains(&solver.cv_lambdas.len()), "solver.cv_lambdas", || {
        format!("must list 1 to {MAX_CV_LAMBDAS} values, got {}", solver.cv_lambdas.len())
    })?;
    for (i, &l) in solver.cv_lambdas.iter().enumerate() {
        check(l.is_finite() && (0.0..=MAX_LAMBDA).contains(&l), &format!("solver.cv_lambdas[{i}]"), || {
            format!("must be in [0, {MAX_LAMBDA:e}], got {l}")
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn base() -> SolverOptions {
        SolverOptions {
            fixed: FixedWeights { w0: Some(0.0), ..FixedWeights::default() },
            lambda: 0.0,
            cv_lambdas: vec![0.1],
            trust_region: Some(0.25),
        }
    }

    #[test]
    fn a_patch_changes_only_what_it_names_and_null_frees_a_weight() {
        let patched = base().patched(&json!({ "lambda": 0.5, "fixed": { "w0": null } })).unwrap();
        assert_eq!(patched.lambda, 0.5);
        assert_eq!(patched.fixed, FixedWeights::default());
        assert_eq!(patched.cv_lambdas, vec![0.1]);
    }

    #[test]
    fn a_bad_patch_names_the_field_as_a_job_specification_does() {
        let field = |patch: Value| base().patched(&patch).unwrap_err().field;
        assert_eq!(field(json!({ "lambda": -1 })), "solver.lambda");
        assert_eq!(field(json!({ "lambda": "x" })), "solver.lambda");
        assert_eq!(field(json!({ "fixed": { "w1": 2e6 } })), "solver.fixed.w1");
        assert_eq!(field(json!({ "lamda": 1 })), "solver.lamda", "an unknown option is named");
        assert_eq!(field(json!(3)), "solver");
        assert_eq!(field(json!({ "trust_region": "of" })), "solver.trust_region");
        assert_eq!(field(json!({ "trust_region": -0.1 })), "solver.trust_region");
    }

    #[test]
    fn a_patch_switches_the_trust_region_off_and_null_brings_the_default_back() {
        // Merge-patch null removes the key; "off" is how a patch says "no region".
        let off = base().patched(&json!({ "trust_region": "off" })).unwrap();
        assert_eq!(off.trust_region, None);
        assert_eq!(serde_json::to_value(&off).unwrap()["trust_region"], "off");
        assert_eq!(off.patched(&json!({ "lambda": 1 })).unwrap().trust_region, None, "off survives another patch");
        assert_eq!(off.patched(&json!({ "trust_region": null })).unwrap().trust_region, Some(DEFAULT_TRUST_REGION));
        assert_eq!(base().patched(&json!({ "trust_region": 0.1 })).unwrap().trust_region, Some(0.1));
        let whole: SolverOptions =
            serde_json::from_value(json!({ "fixed": {}, "lambda": 0, "cv_lambdas": [0], "trust_region": null }))
                .unwrap();
        assert_eq!(whole.trust_region, None, "null in a whole specification is off");
    }
}
