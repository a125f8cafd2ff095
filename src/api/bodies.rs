//! The request bodies of the job routes as the OpenAPI document describes them: a submission
//! (preset and overrides) and its parts, and the solver patch of re-solves. They document; the
//! bodies themselves are parsed by `sim::spec::parse_job_spec` and `SolverOptions::patched`, which
//! name the field at fault.

use serde::Deserialize;
use utoipa::ToSchema;

use crate::sim::model::params::RingSpec;
use crate::sim::solve::options::FixedWeights;

/// A job submission: a preset and any fields to override (JSON Merge Patch on the preset; an
/// object whose `kind` differs from the preset's replaces it whole). Omitted fields keep the
/// preset's values; unknown fields are rejected.
///
/// Every value inside the ranges below is accepted in bounded time. The reference luminance is a
/// quadrature with an evaluation budget (about a second): a geometry it cannot resolve within it
/// (a lobe of 10⁻⁹ degrees, a merge radius far below every other length) runs normally with
/// `reference_luminance: null`. A server also refuses (422, stating its limit) a job whose single
/// iteration is expected to cost more than its `--max-iteration-work`, and one beyond its job budget
/// or cell limit.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // documents the request body; the body is parsed by `sim::spec::parse_job_spec`
pub struct JobSubmission {
    /// `paper-table1` (default) or `uniform-illumination`.
    #[schema(example = "paper-table1", pattern = "^(paper-table1|uniform-illumination)$", nullable = false)]
    preset: Option<String>,
    #[schema(nullable = false)]
    scene: Option<ScenePatch>,
    /// Merge radius R, in [1e-9, min(l2, l3)).
    #[schema(minimum = 1e-9, maximum = 1e6, nullable = false)]
    merge_radius: Option<f64>,
    /// N_F: light paths per iteration, in [1, 10^12].
    #[schema(minimum = 1, maximum = 1_000_000_000_000u64, nullable = false)]
    light_paths: Option<u64>,
    /// N_B: camera paths per iteration, in [1, 10^6].
    #[schema(minimum = 1, maximum = 1_000_000, nullable = false)]
    camera_paths: Option<u64>,
    /// Iterations M, in [1, 10^9].
    #[schema(minimum = 1, maximum = 1_000_000_000, nullable = false)]
    iterations: Option<u64>,
    /// Seed of every random stream.
    #[schema(nullable = false)]
    seed: Option<u64>,
    /// Run only shard `index` of `count` of the iterations.
    #[schema(nullable = false)]
    shard: Option<crate::sim::spec::Shard>,
    /// Run iterations [first_iteration, first_iteration + iterations).
    #[schema(nullable = false)]
    first_iteration: Option<u64>,
    #[schema(nullable = false)]
    cells: Option<CellPatch>,
    #[schema(nullable = false)]
    solver: Option<SolverPatch>,
    /// `restricted` (the presets' default: only the light paths that can merge, drawn exactly as a
    /// Poisson process) or `brute` (all N_F light paths; the reference).
    #[schema(nullable = false)]
    engine: Option<crate::sim::spec::EngineName>,
    /// Only on a server started with `--executor slurm`: how many tasks (one Slurm array task
    /// each) the job's iterations are cut into; absent, the server's `--default-tasks`. A server
    /// that runs its jobs on its own pool refuses it (422). Not part of the computation.
    #[schema(nullable = false)]
    execution: Option<crate::sim::spec::Execution>,
    /// A name for people (1 to 200 printable characters), shown in the job list. Not part of the
    /// computation nor of the fingerprint.
    #[schema(nullable = false, min_length = 1, max_length = 200)]
    name: Option<String>,
    /// Labels to find the job by (`GET /v1/jobs?label=KEY=VALUE`): at most 32; keys of 1–64
    /// letters, digits, `_`, `-`, `.`; values of at most 200 printable characters.
    #[schema(nullable = false)]
    labels: Option<std::collections::BTreeMap<String, String>>,
    /// Free-form notes, at most 4,000 characters.
    #[schema(nullable = false, max_length = 4000)]
    notes: Option<String>,
}

/// Scene fields to override.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct ScenePatch {
    #[schema(minimum = 1e-9, maximum = 1e6, nullable = false)]
    l2: Option<f64>,
    #[schema(minimum = 1e-9, maximum = 1e6, nullable = false)]
    l3: Option<f64>,
    /// Lobe width β in degrees, in [1e-6, 45].
    #[schema(minimum = 1e-6, maximum = 45.0, nullable = false)]
    beta_deg: Option<f64>,
    #[schema(nullable = false)]
    illumination: Option<IlluminationPatch>,
}

/// Illumination fields to override; with another `kind`, the whole profile.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct IlluminationPatch {
    /// `spot`, `uniform` or `rings`.
    #[schema(pattern = "^(spot|uniform|rings)$", nullable = false)]
    kind: Option<String>,
    #[schema(minimum = 1e-9, maximum = 1e6, nullable = false)]
    a: Option<f64>,
    #[schema(minimum = 1e-9, maximum = 1e6, nullable = false)]
    r_ls: Option<f64>,
    #[schema(exclusive_minimum = 0.0, maximum = 1e12, nullable = false)]
    contrast: Option<f64>,
    #[schema(min_items = 1, max_items = 64, nullable = false)]
    rings: Option<Vec<RingSpec>>,
}

/// Cell-grid fields to override.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct CellPatch {
    /// Edges from 0, strictly increasing.
    #[schema(min_items = 1, nullable = false)]
    r2_edges: Option<Vec<f64>>,
    /// Edges from 0, strictly increasing.
    #[schema(min_items = 1, nullable = false)]
    r3_edges: Option<Vec<f64>>,
    #[schema(minimum = 1, maximum = 360, nullable = false)]
    phi_bins: Option<u32>,
}

/// Solver options to override (a merge patch on the job's `solver`; `null` frees a fixed weight).
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct SolverPatch {
    #[schema(nullable = false)]
    fixed: Option<FixedWeights>,
    /// Gradient penalty λ ≥ 0.
    #[schema(minimum = 0.0, maximum = 1e12, nullable = false)]
    lambda: Option<f64>,
    /// λ grid for `optimal_cv`.
    #[schema(min_items = 1, max_items = 32, nullable = false)]
    cv_lambdas: Option<Vec<f64>>,
}

#[cfg(test)]
mod tests {
    //! The ranges these schemas publish are literals (utoipa's attributes take no constants); the
    //! validator's constants are the one declaration, and this test holds the schemas to them.
    use serde_json::Value;
    use utoipa::PartialSchema;

    use super::*;
    use crate::api::jobs::ExtendRequest;
    use crate::sim::model::params::{
        MAX_BETA_DEG, MAX_CAMERA_PATHS, MAX_LENGTH, MAX_LEVEL, MAX_LIGHT_PATHS, MAX_PHI_BINS, MAX_RINGS, MIN_BETA_DEG,
        MIN_LENGTH,
    };
    use crate::sim::solve::options::{MAX_CV_LAMBDAS, MAX_LAMBDA};
    use crate::sim::spec::MAX_ITERATIONS;

    /// `keyword` of property `name` in the JSON form of `schema`.
    fn bound(schema: &Value, name: &str, keyword: &str) -> f64 {
        let property = &schema["properties"][name];
        property[keyword].as_f64().unwrap_or_else(|| panic!("{name} has no {keyword}: {property}"))
    }

    fn json<T: PartialSchema>() -> Value {
        serde_json::to_value(T::schema()).unwrap()
    }

    #[test]
    fn the_published_ranges_are_the_validators() {
        let job = json::<JobSubmission>();
        for (name, lo, hi) in [
            ("merge_radius", MIN_LENGTH, MAX_LENGTH),
            ("light_paths", 1.0, MAX_LIGHT_PATHS as f64),
            ("camera_paths", 1.0, MAX_CAMERA_PATHS as f64),
            ("iterations", 1.0, MAX_ITERATIONS as f64),
        ] {
            assert_eq!((bound(&job, name, "minimum"), bound(&job, name, "maximum")), (lo, hi), "{name}");
        }
        let scene = json::<ScenePatch>();
        for name in ["l2", "l3"] {
            assert_eq!((bound(&scene, name, "minimum"), bound(&scene, name, "maximum")), (MIN_LENGTH, MAX_LENGTH));
        }
        assert_eq!(
            (bound(&scene, "beta_deg", "minimum"), bound(&scene, "beta_deg", "maximum")),
            (MIN_BETA_DEG, MAX_BETA_DEG)
        );
        let light = json::<IlluminationPatch>();
        for name in ["a", "r_ls"] {
            assert_eq!((bound(&light, name, "minimum"), bound(&light, name, "maximum")), (MIN_LENGTH, MAX_LENGTH));
        }
        assert_eq!(bound(&light, "contrast", "exclusiveMinimum"), 0.0);
        assert_eq!(bound(&light, "contrast", "maximum"), MAX_LEVEL);
        assert_eq!(bound(&light, "rings", "maxItems"), MAX_RINGS as f64);
        let ring = json::<RingSpec>();
        assert_eq!(
            (bound(&ring, "outer_radius", "minimum"), bound(&ring, "outer_radius", "maximum")),
            (MIN_LENGTH, MAX_LENGTH)
        );
        assert_eq!((bound(&ring, "level", "minimum"), bound(&ring, "level", "maximum")), (0.0, MAX_LEVEL));
        let cells = json::<CellPatch>();
        assert_eq!(bound(&cells, "phi_bins", "maximum"), f64::from(MAX_PHI_BINS));
        let solver = json::<SolverPatch>();
        assert_eq!((bound(&solver, "lambda", "minimum"), bound(&solver, "lambda", "maximum")), (0.0, MAX_LAMBDA));
        assert_eq!(bound(&solver, "cv_lambdas", "maxItems"), MAX_CV_LAMBDAS as f64);
        let extend = json::<ExtendRequest>();
        for name in ["iterations", "total"] {
            assert_eq!(bound(&extend, name, "maximum"), MAX_ITERATIONS as f64, "{name}");
        }
    }
}
