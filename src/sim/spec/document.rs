//! [`JobSpec`], the job document field by field as users write it (a preset resolved), the
//! iterations it runs, and its validation — the one place values are checked, calling the checks
//! of the scene, the cells and the solver (`sim::model`, `sim::solve`) and of this folder's other
//! files — which yields the [`ValidJob`] everything else consumes.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::annotations::validate_annotations;
use super::execution::{EngineName, Execution, Shard, validate_execution, validate_range};
use crate::sim::engines::layout::{MAX_FOLD_SUMS, folds_allowed};
use crate::sim::model::config::{DEFAULT_FOLDS, MAX_FOLDS, MAX_RADII, MIN_FOLDS, SimConfig};
use crate::sim::model::illumination::validate_flux;
use crate::sim::model::params::{
    CellSpec, MIN_LENGTH, SceneSpec, SpecError, check, check_path_counts, count, optional_count, validate_cells,
    validate_scene,
};
use crate::sim::model::scene::Scene;
use crate::sim::solve::options::{SolverOptions, validate_solver};

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
    /// Smaller merge radii R′ < `merge_radius` to tally as well (at most 6, ascending): the merges
    /// of a run at R contain those at every R′ ≤ R, so one run gives the moments (and, with
    /// `noise_components`, the noise at any N_F, N_B) at each R′ — what a direct run at R′ would
    /// give — and the budget can choose the radius with the ray counts (`optimis budget
    /// --target-rmse`, docs/model.md §13). Each radius costs a moments value of its own; the run
    /// time grows by the merges it re-weighs, about 1 + Σ(R′/R)² of a plain run's per iteration
    /// (measured 1.32–1.37× for [0.003, 0.005, 0.01] at R = 0.02, docs/results.md §22). Part of
    /// the fingerprint.
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "bounded_radii")]
    #[cfg_attr(feature = "server", schema(max_items = 6))]
    pub radii: Vec<f64>,
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
    /// of 1–64 letters, digits, `_`, `-`, `.`, values of at most 200 printable characters. Not part
    /// of the computation nor of the fingerprint.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub labels: BTreeMap<String, String>,
    /// Free-form notes (at most 4,000 characters). Not part of the computation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
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
        validate_range(self.iterations, self.shard, self.first_iteration)?;
        let cells = validate_cells(&self.cells)?;
        validate_solver(&self.solver)?;
        validate_annotations(self.name.as_deref(), &self.labels, self.notes.as_deref())?;
        validate_execution(self.iterations, self.execution)?;
        if self.noise_components {
            for (field, n) in [("light_paths", self.light_paths), ("camera_paths", self.camera_paths)] {
                check(n % 2 == 0, field, || {
                    format!("must be even with noise_components (its paths are split in two halves), got {n}")
                })?;
            }
        }
        validate_radii(&self.radii, self.merge_radius)?;
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
        .with_noise_components(self.noise_components)
        .with_radii(&self.radii);
        Ok(ValidJob { spec: self.clone(), config: Arc::new(config) })
    }
}

/// Reads `radii`, refusing a list longer than [`MAX_RADII`] before it is collected.
fn bounded_radii<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    crate::sim::stats::bounded::bounded::<_, _, MAX_RADII>(d)
}

/// The smaller radii: finite, at least [`MIN_LENGTH`], below R, strictly ascending.
fn validate_radii(radii: &[f64], merge_radius: f64) -> Result<(), SpecError> {
    for (i, &r) in radii.iter().enumerate() {
        check(r.is_finite() && r >= MIN_LENGTH && r < merge_radius, "radii", || {
            format!("radii[{i}] must be in [{MIN_LENGTH:e}, merge_radius = {merge_radius}), got {r}")
        })?;
        check(i == 0 || r > radii[i - 1], "radii", || {
            format!("radii must be strictly ascending, but radii[{i}] = {r} follows {}", radii[i - 1])
        })?;
    }
    Ok(())
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
