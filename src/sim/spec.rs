//! The job specification: the JSON document users submit (CLI `--spec` and `POST /v1/jobs` alike),
//! its presets, and its validation.
//!
//! A document names a `preset` (default `paper-table1`) and overrides any of its fields. Overrides
//! follow JSON Merge Patch (RFC 7386): objects merge field by field, arrays and numbers replace, and
//! `null` removes a field (so `{"solver": {"fixed": {"w0": null}}}` frees w₀). One exception keeps
//! tagged objects sane: an object whose `kind` differs from the preset's replaces it whole, so
//! `{"scene": {"illumination": {"kind": "uniform", "r_ls": 20}}}` does not inherit the spot's `a`.
//!
//! Unknown fields are errors, never ignored. Parsing gives a [`JobSpec`]; [`JobSpec::validate`] is
//! the one place where values are checked, and yields the [`ValidJob`] everything else consumes.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::sim::engines::layout::{MAX_FOLD_SUMS, folds_allowed};
use crate::sim::model::config::{DEFAULT_FOLDS, Engine, MAX_FOLDS, MIN_FOLDS, Proposals, SimConfig};
use crate::sim::model::illumination::validate_flux;
pub use crate::sim::model::params::SpecError;
use crate::sim::model::params::{
    CellSpec, MIN_LENGTH, SceneSpec, check, check_path_counts, count, merge_patch, optional_count,
    validate_annotations, validate_cells, validate_scene,
};
use crate::sim::model::scene::Scene;
use crate::sim::solve::options::{SolverOptions, validate_solver};
use crate::sim::stats::coverage::MAX_ITERATION_INDEX;

/// The preset used when a document names none.
pub const DEFAULT_PRESET: &str = "paper-table1";

/// A fully resolved job specification (preset applied). Field names are the JSON API.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JobSpec {
    /// The preset the document started from (provenance; every field below is explicit).
    pub preset: String,
    /// The scene: distances, lobe width, illumination profile.
    pub scene: SceneSpec,
    /// Merge (kernel) radius R.
    pub merge_radius: f64,
    /// N_F: light paths per iteration.
    #[serde(deserialize_with = "count")]
    pub light_paths: u64,
    /// N_B: camera paths per iteration.
    #[serde(deserialize_with = "count")]
    pub camera_paths: u64,
    /// M: iterations to run (with `shard`: of the whole study).
    #[serde(deserialize_with = "count")]
    pub iterations: u64,
    /// Seed of every random stream of the job.
    #[serde(deserialize_with = "count")]
    pub seed: u64,
    /// Run only this shard of the study's `iterations` (see [`JobSpec::iteration_range`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// Run iterations [first_iteration, first_iteration + iterations) instead of [0, iterations)
    /// (with `shard`: shard k of those).
    #[serde(default, skip_serializing_if = "Option::is_none", deserialize_with = "optional_count")]
    pub first_iteration: Option<u64>,
    /// The grid of cells the weights are tabulated over.
    pub cells: CellSpec,
    /// K, the cross-fitting folds: iteration s is summed into fold s mod K, and every fitted figure
    /// that is not labelled in-sample is cross-fitted over them. Absent: 10, or the most the grid
    /// allows (K × the sums of one fold is bounded). Part of the fingerprint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub folds: Option<usize>,
    /// Keep the noise components of every iteration (its light and camera paths split in halves):
    /// the moments then predict the noise and the optimal weights at any other N_F and N_B
    /// (`optimis predict`, `POST /v1/jobs/{id}/predict`). Needs even `light_paths` and
    /// `camera_paths`; the moments hold four times the sums per fold. Part of the fingerprint.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub noise_components: bool,
    /// How the weights are fitted: fixed weights, the penalty λ and the cross-validation grid.
    pub solver: SolverOptions,
    /// How light paths are drawn. Absent in documents stored before engines existed: `brute`.
    #[serde(default)]
    pub engine: EngineName,
    /// How a server divides the job among a cluster's tasks (`optimis serve --executor slurm`).
    /// Not part of the computation: the results do not depend on it, moments documents do not
    /// carry it, and a local run ignores it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub execution: Option<Execution>,
    /// A name for people (the job list shows it; a sweep names each run after its swept values).
    /// Not part of the computation nor of the fingerprint: runs of other names merge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Labels, key → value, to find jobs by (`GET /v1/jobs?label=study=radius`): at most 32, keys
    /// of 1–64 letters, digits, `_`, `-`, `.`, values of at most 200 characters. Not part of the
    /// computation nor of the fingerprint.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub labels: BTreeMap<String, String>,
    /// Free-form notes (at most 4,000 characters). Not part of the computation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
}

/// Most tasks one job may be cut into (a server's `--max-tasks` may lower it).
pub const MAX_TASKS: u64 = 10_000;

/// How a server divides a job among a cluster's tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Execution {
    /// The number of tasks (shards of the job's iterations, one Slurm array task each): at least
    /// 1, at most the job's iterations and 10,000.
    #[serde(deserialize_with = "count")]
    pub tasks: u64,
}

/// The engine of a job: `restricted` draws only the light paths that can merge (an exact Poisson
/// process, thousands of times faster); `brute` streams all N_F of them (the reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum EngineName {
    /// Every light path, streamed (the reference).
    #[default]
    Brute,
    /// Only the light paths that can merge, as an exact Poisson process.
    Restricted,
}

impl EngineName {
    fn engine(self) -> Engine {
        match self {
            EngineName::Brute => Engine::Brute,
            EngineName::Restricted => Engine::Restricted(Proposals::Auto),
        }
    }
}

/// Shard `index` of `count` equal parts of a study's iterations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// 0-based, below `count`.
    #[serde(deserialize_with = "count")]
    pub index: u64,
    /// At least 1, at most the study's `iterations`.
    #[serde(deserialize_with = "count")]
    pub count: u64,
}

impl JobSpec {
    /// The iterations this job runs. Without `shard` or `first_iteration`: [0, M). With
    /// `first_iteration` f: [f, f + M). With shard k of n: [f + ⌊k·M/n⌋, f + ⌊(k+1)·M/n⌋) (f = 0
    /// without `first_iteration`), so that the n shards of one study are disjoint and together
    /// exactly [f, f + M) of the same deterministic sequence.
    pub fn iteration_range(&self) -> std::ops::Range<u64> {
        let m = self.iterations;
        let first = self.first_iteration.unwrap_or(0);
        match self.shard {
            Some(Shard { index, count }) => {
                let at = |k: u64| first + (u128::from(k) * u128::from(m) / u128::from(count)) as u64;
                at(index)..at(index + 1)
            }
            None => first..first + m,
        }
    }
}

/// The names of the presets.
pub const PRESETS: &[&str] = &["paper-table1", "uniform-illumination"];

/// A preset as a complete JSON document.
pub fn preset(name: &str) -> Option<Value> {
    // The paper's grid: r2 ∈ [0, ½] + tail; r3: 25 cells of 0.002 on [0, 0.05] + tail; one φ bin.
    let r3_edges: Vec<f64> = (0..=25).map(|i| f64::from(i) / 500.0).collect();
    let (a, r_ls) = (0.02, 20.0);
    let paper = json!({
        "preset": "paper-table1",
        "scene": {
            "l2": 1.0, "l3": 3.0, "beta_deg": 3.0,
            "illumination": { "kind": "spot", "a": a, "r_ls": r_ls, "contrast": (r_ls / a) * (r_ls / a) / 300.0 }
        },
        "merge_radius": 0.003,
        // The restricted engine: the same estimates thousands of times faster (see
        // `sim::engines::restricted`; tests/engines.rs checks the equivalence with the brute force).
        "engine": "restricted",
        "light_paths": 10_000_000u64,
        "camera_paths": 100,
        "iterations": 10_000,
        "seed": 1,
        "cells": { "r2_edges": [0.0, 0.5], "r3_edges": r3_edges, "phi_bins": 1 },
        "solver": {
            "fixed": { "w0": 0.0 },
            "lambda": 0.0,
            "cv_lambdas": [0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0]
        }
    });
    match name {
        "paper-table1" => Some(paper),
        // The paper's closing comparison: the same scene under uniform illumination.
        "uniform-illumination" => {
            let mut doc = paper;
            doc["preset"] = json!("uniform-illumination");
            doc["scene"]["illumination"] = json!({ "kind": "uniform", "r_ls": r_ls });
            Some(doc)
        }
        _ => None,
    }
}

/// Parses a submitted document (preset + overrides) into a resolved [`JobSpec`].
///
/// Only structure is checked here (types, unknown fields, the preset name); values are checked by
/// [`JobSpec::validate`].
pub fn parse_job_spec(document: &Value) -> Result<JobSpec, SpecError> {
    let Value::Object(fields) = document else {
        return Err(SpecError::new("", "the job specification must be a JSON object"));
    };
    let name = match fields.get("preset") {
        None | Some(Value::Null) => DEFAULT_PRESET,
        Some(Value::String(s)) => s.as_str(),
        Some(other) => return Err(SpecError::new("preset", format!("must be a string, got {other}"))),
    };
    let mut resolved = preset(name).ok_or_else(|| {
        SpecError::new("preset", format!("unknown preset {name:?}; known presets: {}", PRESETS.join(", ")))
    })?;
    merge_patch(&mut resolved, document);
    resolved["preset"] = json!(name);
    serde_path_to_error::deserialize::<_, JobSpec>(&resolved).map_err(|e| {
        let path = e.path().to_string();
        let field = if path == "." { String::new() } else { path };
        SpecError::new(field, e.into_inner().to_string())
    })
}

/// Most iterations of one job (the message of its check says 10^9).
pub const MAX_ITERATIONS: u64 = 1_000_000_000;

/// A specification that passed validation, with the simulation configuration built from it.
/// Only [`JobSpec::validate`] makes one, and its parts cannot be changed afterwards: holding a
/// `ValidJob` means holding values that were checked together.
#[derive(Debug, Clone)]
pub struct ValidJob {
    spec: JobSpec,
    config: Arc<SimConfig>,
}

impl ValidJob {
    /// The specification as validated.
    pub fn spec(&self) -> &JobSpec {
        &self.spec
    }

    /// The simulation configuration built from it, shared by every iteration.
    pub fn config(&self) -> &Arc<SimConfig> {
        &self.config
    }

    /// The specification as validated, the configuration dropped.
    pub fn into_spec(self) -> JobSpec {
        self.spec
    }
}

impl JobSpec {
    /// Checks every value and builds the simulation configuration. The one place values are
    /// validated: everything downstream trusts a [`ValidJob`].
    pub fn validate(&self) -> Result<ValidJob, SpecError> {
        let s = &self.scene;
        validate_scene(s)?;
        validate_flux(&s.illumination)?;
        let max_r = s.l2.min(s.l3);
        check(
            self.merge_radius.is_finite() && self.merge_radius >= MIN_LENGTH && self.merge_radius < max_r,
            "merge_radius",
            || format!("must be in [{MIN_LENGTH:e}, min(l2, l3) = {max_r}), got {}", self.merge_radius),
        )?;
        check_path_counts(self.light_paths, self.camera_paths, ["light_paths", "camera_paths"])?;
        check((1..=MAX_ITERATIONS).contains(&self.iterations), "iterations", || {
            format!("must be in [1, 10^9], got {}", self.iterations)
        })?;
        validate_range(self)?;
        let cells = validate_cells(&self.cells)?;
        validate_solver(&self.solver)?;
        validate_annotations(self.name.as_deref(), &self.labels, self.notes.as_deref())?;
        if let Some(Execution { tasks }) = self.execution {
            check((1..=self.iterations.min(MAX_TASKS)).contains(&tasks), "execution.tasks", || {
                format!("must be in [1, min(iterations, {MAX_TASKS})] so that every task has iterations, got {tasks}")
            })?;
        }
        if self.noise_components {
            for (field, n) in [("light_paths", self.light_paths), ("camera_paths", self.camera_paths)] {
                check(n % 2 == 0, field, || {
                    format!("must be even with noise_components (its paths are split in two halves), got {n}")
                })?;
            }
        }
        let allowed = folds_allowed(cells.len(), self.noise_components);
        let folds = self.folds.unwrap_or(DEFAULT_FOLDS.min(allowed));
        check((MIN_FOLDS..=allowed).contains(&folds), "folds", || {
            format!(
                "must be in [{MIN_FOLDS}, {allowed}] for a grid of {} cells (at most {MAX_FOLDS}, and K folds of ΣYYᵀ hold at most {MAX_FOLD_SUMS} sums), got {folds}",
                cells.len()
            )
        })?;
        let scene = Scene::from_spec(&self.scene);
        let config = SimConfig::new(
            scene,
            self.merge_radius,
            self.light_paths,
            self.camera_paths,
            cells,
            self.engine.engine(),
            folds,
        )
        .with_noise_components(self.noise_components);
        Ok(ValidJob { spec: self.clone(), config: Arc::new(config) })
    }
}

fn validate_range(spec: &JobSpec) -> Result<(), SpecError> {
    if let Some(Shard { index, count }) = spec.shard {
        check((1..=spec.iterations).contains(&count), "shard.count", || {
            format!("must be in [1, iterations = {}] so that every shard has iterations, got {count}", spec.iterations)
        })?;
        check(index < count, "shard.index", || {
            format!("must be in [0, shard.count - 1 = {}], got {index}", count - 1)
        })?;
    }
    if let Some(first) = spec.first_iteration {
        check(first <= MAX_ITERATION_INDEX - spec.iterations, "first_iteration", || {
            format!("must be at most 2^62 - iterations, got {first}")
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::model::params::IlluminationSpec;
    use crate::sim::solve::options::FixedWeights;

    fn parse(doc: Value) -> Result<JobSpec, SpecError> {
        parse_job_spec(&doc)
    }

    fn invalid(doc: Value) -> SpecError {
        match parse(doc) {
            Err(e) => e,
            Ok(spec) => spec.validate().expect_err("the spec should be rejected"),
        }
    }

    #[test]
    fn paper_preset_is_valid_and_matches_the_paper() {
        let spec = parse(json!({})).unwrap();
        assert_eq!(spec.preset, "paper-table1");
        assert_eq!(spec.light_paths, 10_000_000);
        assert_eq!(spec.camera_paths, 100);
        assert_eq!(spec.merge_radius, 0.003);
        assert_eq!(spec.cells.r3_edges.len(), 26);
        let IlluminationSpec::Spot { contrast, .. } = spec.scene.illumination else { panic!() };
        assert!((contrast - 3333.333).abs() < 1e-3);
        let job = spec.validate().unwrap();
        assert_eq!(job.config.cells.len(), 52);
    }

    #[test]
    fn overrides_merge_and_kind_changes_replace() {
        let spec = parse(json!({
            "scene": { "beta_deg": 5, "illumination": { "kind": "uniform", "r_ls": 7 } },
            "light_paths": 1e5,
            "solver": { "fixed": { "w0": null, "w2": 0.5 } }
        }))
        .unwrap();
        assert_eq!(spec.scene.beta_deg, 5.0);
        assert_eq!(spec.scene.l3, 3.0, "untouched fields keep the preset's value");
        assert_eq!(spec.scene.illumination, IlluminationSpec::Uniform { r_ls: 7.0 });
        assert_eq!(spec.light_paths, 100_000);
        assert_eq!(spec.solver.fixed, FixedWeights { w0: None, w1: None, w2: Some(0.5) });
        spec.validate().unwrap();
    }

    #[test]
    fn unknown_fields_are_errors_with_their_path() {
        let e = parse(json!({ "scene": { "l4": 1 } })).unwrap_err();
        assert_eq!(e.field, "scene.l4");
        assert!(e.message.contains("unknown field `l4`"), "{e}");
        let e = parse(json!({ "scene": { "illumination": { "kind": "spot", "b": 1 } } })).unwrap_err();
        assert!(e.field.starts_with("scene.illumination"), "{e}");
        let e = parse(json!({ "iterationz": 3 })).unwrap_err();
        assert!(e.message.contains("iterationz"), "{e}");
        let e = parse(json!({ "preset": "nope" })).unwrap_err();
        assert_eq!(e.field, "preset");
        let e = parse(json!({ "light_paths": -3 })).unwrap_err();
        assert_eq!(e.field, "light_paths");
        let e = parse(json!({ "light_paths": 2.5 })).unwrap_err();
        assert_eq!(e.field, "light_paths");
    }

    #[test]
    fn invalid_values_name_the_field_and_range() {
        let cases = [
            (json!({ "merge_radius": -1 }), "merge_radius"),
            (json!({ "merge_radius": 0 }), "merge_radius"),
            (json!({ "merge_radius": 2 }), "merge_radius"),
            (json!({ "scene": { "beta_deg": 50 } }), "scene.beta_deg"),
            (json!({ "scene": { "beta_deg": 0 } }), "scene.beta_deg"),
            (json!({ "scene": { "beta_deg": 1e-9 } }), "scene.beta_deg"),
            (json!({ "scene": { "l2": 1e-12 } }), "scene.l2"),
            (json!({ "merge_radius": 1e-10 }), "merge_radius"),
            (
                json!({ "scene": { "illumination": { "kind": "rings", "rings": [
                { "outer_radius": 1, "level": 1e-320 } ] } } }),
                "scene.illumination",
            ),
            (json!({ "scene": { "l2": 0 } }), "scene.l2"),
            (json!({ "scene": { "illumination": { "a": -0.1 } } }), "scene.illumination.a"),
            (json!({ "scene": { "illumination": { "r_ls": 0.01 } } }), "scene.illumination.r_ls"),
            (
                json!({ "scene": { "illumination": { "kind": "rings", "rings": [
                { "outer_radius": 1, "level": 1 }, { "outer_radius": 0.5, "level": 1 } ] } } }),
                "scene.illumination.rings[1].outer_radius",
            ),
            (
                json!({ "scene": { "illumination": { "kind": "rings", "rings": [
                { "outer_radius": 1, "level": 0 } ] } } }),
                "scene.illumination.rings",
            ),
            (json!({ "light_paths": 0 }), "light_paths"),
            (json!({ "camera_paths": 0 }), "camera_paths"),
            (json!({ "iterations": 0 }), "iterations"),
            (json!({ "cells": { "r3_edges": [0, 0.2, 0.1] } }), "cells.r3_edges[2]"),
            (json!({ "cells": { "r2_edges": [0.1, 0.2] } }), "cells.r2_edges"),
            (json!({ "cells": { "phi_bins": 0 } }), "cells.phi_bins"),
            (json!({ "cells": { "phi_bins": 10 } }), "cells"),
            (json!({ "solver": { "lambda": -1 } }), "solver.lambda"),
            (json!({ "solver": { "fixed": { "w0": 0.2, "w1": 0.2, "w2": 0.2 } } }), "solver.fixed"),
            (json!({ "solver": { "cv_lambdas": [] } }), "solver.cv_lambdas"),
        ];
        for (doc, field) in cases {
            let e = invalid(doc.clone());
            assert_eq!(e.field, field, "{doc} gave {e}");
            assert!(!e.message.is_empty());
        }
        let e = invalid(json!({ "scene": { "beta_deg": 50 } }));
        assert!(e.message.contains("[1e-6, 45]"), "the message states the range: {e}");
    }

    #[test]
    fn nan_cannot_be_smuggled_in() {
        // JSON has no NaN; serde_json rejects the bare token at parse time, and infinity overflows
        // to a parse error too. A huge exponent is the closest a document can get.
        assert!(serde_json::from_str::<Value>("{\"merge_radius\": NaN}").is_err());
        let e = invalid(json!({ "merge_radius": 1e308 }));
        assert_eq!(e.field, "merge_radius");
    }

    #[test]
    fn shards_partition_the_study() {
        for (m, n) in [(10, 3), (7, 7), (10_000, 2), (5, 1), (1_000_003, 64)] {
            let mut covered = 0;
            let mut next = 0;
            for k in 0..n {
                let spec = parse(json!({ "iterations": m, "shard": { "index": k, "count": n } })).unwrap();
                spec.validate().unwrap();
                let r = spec.iteration_range();
                assert_eq!(r.start, next, "shards are contiguous");
                assert!(!r.is_empty());
                covered += r.end - r.start;
                next = r.end;
            }
            assert_eq!((covered, next), (m, m));
        }
        let spec = parse(json!({ "iterations": 10, "first_iteration": 100 })).unwrap();
        assert_eq!(spec.iteration_range(), 100..110);
        assert_eq!(parse(json!({ "iterations": 10 })).unwrap().iteration_range(), 0..10);
        // A shard of [f, f + M): how a cluster's tasks cut a job's added iterations.
        let later = parse(json!({ "iterations": 10, "first_iteration": 100, "shard": { "index": 1, "count": 3 } }));
        assert_eq!(later.unwrap().iteration_range(), 103..106);
        for (doc, field) in [
            (json!({ "iterations": 3, "shard": { "index": 3, "count": 3 } }), "shard.index"),
            (json!({ "iterations": 3, "shard": { "index": 0, "count": 4 } }), "shard.count"),
            (json!({ "iterations": 3, "shard": { "index": 0, "count": 0 } }), "shard.count"),
            (json!({ "iterations": 3, "execution": { "tasks": 4 } }), "execution.tasks"),
            (json!({ "iterations": 3, "execution": { "tasks": 0 } }), "execution.tasks"),
            (json!({ "first_iteration": 4_611_686_018_427_387_904u64 }), "first_iteration"),
        ] {
            assert_eq!(invalid(doc.clone()).field, field, "{doc}");
        }
    }

    #[test]
    fn resolved_spec_round_trips() {
        let spec = parse(json!({ "preset": "uniform-illumination", "seed": 42 })).unwrap();
        let again = parse(serde_json::to_value(&spec).unwrap()).unwrap();
        assert_eq!(spec, again);
    }
}
