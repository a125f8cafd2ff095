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
    /// Smaller merge radii R′ to tally as well: at most 6, ascending, each in [1e-9,
    /// merge_radius). One run then holds the moments at every R′ (the merges within R′ of the same
    /// iterations), each radius's noise table and bias in the result, and the budget can plan the
    /// radius (`target_rmse`). Part of the fingerprint.
    #[schema(nullable = false, max_items = 6)]
    radii: Option<Vec<f64>>,
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
    //! validator's constants are the one declaration, and this test holds the served OpenAPI
    //! document to them: every range keyword of every schema a submission or an extension reaches
    //! (following `$ref`s), and the label rule in the job list's `label` parameter.
    use std::collections::{BTreeMap, BTreeSet};

    use serde_json::Value;

    use crate::api::{DEFAULT_DOCUMENT_LIMIT, routes_and_document};
    use crate::sim::model::params::{
        MAX_BETA_DEG, MAX_CAMERA_PATHS, MAX_LENGTH, MAX_LEVEL, MAX_LIGHT_PATHS, MAX_PHI_BINS, MAX_RINGS, MIN_BETA_DEG,
        MIN_LENGTH,
    };
    use crate::sim::solve::options::{MAX_CV_LAMBDAS, MAX_LAMBDA};
    use crate::sim::spec::{
        MAX_ITERATIONS, MAX_LABEL_KEY, MAX_LABEL_VALUE, MAX_LABELS, MAX_NAME, MAX_NOTES, MAX_TASKS,
    };

    /// The JSON Schema keywords that bound a value, an array, a string or an object.
    const RANGE_KEYWORDS: [&str; 10] = [
        "minimum",
        "maximum",
        "exclusiveMinimum",
        "exclusiveMaximum",
        "minItems",
        "maxItems",
        "minLength",
        "maxLength",
        "minProperties",
        "maxProperties",
    ];

    /// (schema, property, keyword): a property's items are `property[]`.
    type Bounds = BTreeMap<(String, String, String), f64>;

    /// A property's bounds as the validator states them: (schema, property, [(keyword, bound)]).
    type Row<'a> = (&'a str, &'a str, &'a [(&'a str, f64)]);

    /// The OpenAPI document as served (and as `openapi.yaml` is written), as JSON.
    fn served() -> Value {
        serde_json::to_value(routes_and_document(DEFAULT_DOCUMENT_LIMIT).1).unwrap()
    }

    /// Every `$ref`'d schema name inside `value`.
    fn refs(value: &Value, out: &mut Vec<String>) {
        match value {
            Value::Object(map) => {
                if let Some(name) = map.get("$ref").and_then(Value::as_str) {
                    out.push(name.trim_start_matches("#/components/schemas/").to_string());
                }
                map.values().for_each(|v| refs(v, out));
            }
            Value::Array(items) => items.iter().for_each(|v| refs(v, out)),
            _ => {}
        }
    }

    /// Every range keyword of the properties (and their items) of `roots` and of every schema they
    /// reach.
    fn published(doc: &Value, roots: &[&str]) -> Bounds {
        let mut bounds = Bounds::new();
        let mut todo: Vec<String> = roots.iter().map(|r| r.to_string()).collect();
        let mut seen = BTreeSet::new();
        while let Some(name) = todo.pop() {
            if !seen.insert(name.clone()) {
                continue;
            }
            let schema = &doc["components"]["schemas"][&name];
            assert!(schema.is_object(), "the document has no schema {name}");
            refs(schema, &mut todo);
            for (property, value) in schema["properties"].as_object().into_iter().flatten() {
                for (path, value) in [(property.clone(), value), (format!("{property}[]"), &value["items"])] {
                    for keyword in RANGE_KEYWORDS {
                        if let Some(bound) = value[keyword].as_f64() {
                            bounds.insert((name.clone(), path.clone(), keyword.to_string()), bound);
                        }
                    }
                }
            }
        }
        bounds
    }

    #[test]
    fn the_published_ranges_are_the_validators() {
        let doc = served();
        let both = |lo: f64, hi: f64| [("minimum", lo), ("maximum", hi)];
        let lengths = both(MIN_LENGTH, MAX_LENGTH);
        let counts = |hi: u64| both(1.0, hi as f64);
        let iterations = counts(MAX_ITERATIONS);
        let rows: &[Row<'_>] = &[
            ("JobSubmission", "merge_radius", &lengths),
            ("JobSubmission", "light_paths", &counts(MAX_LIGHT_PATHS)),
            ("JobSubmission", "camera_paths", &counts(MAX_CAMERA_PATHS)),
            ("JobSubmission", "iterations", &iterations),
            // Unsigned integers: utoipa's own bound, the validator's too.
            ("JobSubmission", "seed", &[("minimum", 0.0)]),
            ("JobSubmission", "first_iteration", &[("minimum", 0.0)]),
            ("JobSubmission", "name", &[("minLength", 1.0), ("maxLength", MAX_NAME as f64)]),
            ("JobSubmission", "notes", &[("maxLength", MAX_NOTES as f64)]),
            ("JobSubmission", "radii", &[("maxItems", crate::sim::model::config::MAX_RADII as f64)]),
            ("ScenePatch", "l2", &lengths),
            ("ScenePatch", "l3", &lengths),
            ("ScenePatch", "beta_deg", &both(MIN_BETA_DEG, MAX_BETA_DEG)),
            ("IlluminationPatch", "a", &lengths),
            ("IlluminationPatch", "r_ls", &lengths),
            ("IlluminationPatch", "contrast", &[("exclusiveMinimum", 0.0), ("maximum", MAX_LEVEL)]),
            ("IlluminationPatch", "rings", &[("minItems", 1.0), ("maxItems", MAX_RINGS as f64)]),
            ("RingSpec", "outer_radius", &lengths),
            ("RingSpec", "level", &both(0.0, MAX_LEVEL)),
            ("CellPatch", "r2_edges", &[("minItems", 1.0)]),
            ("CellPatch", "r3_edges", &[("minItems", 1.0)]),
            ("CellPatch", "phi_bins", &both(1.0, f64::from(MAX_PHI_BINS))),
            ("SolverPatch", "lambda", &both(0.0, MAX_LAMBDA)),
            ("SolverPatch", "cv_lambdas", &[("minItems", 1.0), ("maxItems", MAX_CV_LAMBDAS as f64)]),
            ("Shard", "index", &[("minimum", 0.0)]),
            ("Shard", "count", &[("minimum", 1.0)]),
            ("Execution", "tasks", &counts(MAX_TASKS)),
            ("ExtendRequest", "iterations", &iterations),
            ("ExtendRequest", "total", &iterations),
        ];
        let expected: Bounds = rows
            .iter()
            .flat_map(|(schema, property, bounds)| {
                bounds
                    .iter()
                    .map(|(keyword, bound)| ((schema.to_string(), property.to_string(), keyword.to_string()), *bound))
            })
            .collect();
        let found = published(&doc, &["JobSubmission", "ExtendRequest"]);
        let differ: Vec<String> = expected
            .keys()
            .chain(found.keys())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .filter(|k| expected.get(*k) != found.get(*k))
            .map(|k| format!("{}.{} {}: validator {:?}, published {:?}", k.0, k.1, k.2, expected.get(k), found.get(k)))
            .collect();
        assert!(differ.is_empty(), "published ranges that are not the validator's:\n{}", differ.join("\n"));
    }

    #[test]
    fn the_published_label_rule_is_the_labels() {
        let doc = served();
        let parameters = doc["paths"]["/v1/jobs"]["get"]["parameters"].as_array().unwrap();
        let label = parameters.iter().find(|p| p["name"] == "label").expect("the list has a label parameter");
        assert_eq!(
            label["schema"]["pattern"],
            format!("^[A-Za-z0-9_.-]{{1,{MAX_LABEL_KEY}}}=.{{0,{MAX_LABEL_VALUE}}}$"),
            "the list's label pattern"
        );
        for schema in ["JobSubmission", "JobSpec"] {
            let text = doc["components"]["schemas"][schema]["properties"]["labels"]["description"].as_str().unwrap();
            for limit in
                [format!("at most {MAX_LABELS}"), format!("1–{MAX_LABEL_KEY}"), format!("at most {MAX_LABEL_VALUE}")]
            {
                assert!(text.contains(&limit), "{schema}.labels says {limit:?}: {text}");
            }
        }
    }
}
