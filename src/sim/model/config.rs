//! The statistical configuration of a job — everything that changes the law of one iteration — and
//! its fingerprint.
//!
//! Two moments values may be merged only if they were drawn under the same configuration, so the
//! fingerprint hashes exactly that: the scene, R, N_F, N_B, the cell grid, the engine, the
//! generator scheme, the moments format and the number of cross-fitting folds K (the moments keep
//! one set of sums per fold). Not the seed (different seeds are independent draws of the same law), not
//! the iteration count, not the solver options.

use serde::Serialize;

use super::cells::CellGrid;
use super::params::{CellSpec, SceneSpec};
use super::scene::Scene;
use crate::sim::math::digest::sha256_hex;
use crate::sim::math::rng::GENERATOR_ID;

/// Which proposals the restricted engine uses (both draw the same process exactly).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Proposals {
    /// The tighter valid proposal of every (component, ring) pair.
    Auto,
    /// Reverse proposals only (plane-3 components are always drawn directly).
    Reverse,
}

/// Version of the moments layout this build writes; part of the fingerprint. Format 4 (issue 26)
/// keeps the noise components over the predictable prefix of the moment vector only
/// (`engines::layout`); format 3 (issue 21)
/// adds the w0 = 0 heuristics and one moment-vector column per stackable strategy
/// (`stats::layout`); format 2 (issue 13) keeps K folds by iteration index s mod K, for K-fold
/// cross-fitting, and is still read (its jobs even resume in it); format 1 kept two folds (even,
/// odd) that cannot be split into more, so its documents and checkpoints are refused with a message
/// that says so.
pub const MOMENTS_FORMAT_VERSION: u32 = 4;

/// The format of moments without noise components ([`SimConfig::moments_format`]): format 4
/// changed only the components.
pub const PLAIN_MOMENTS_FORMAT: u32 = 3;

/// Fewest cross-fitting folds K.
pub const MIN_FOLDS: usize = 2;
/// Most cross-fitting folds K (a fine grid may allow fewer: `engines::layout::folds_allowed`).
pub const MAX_FOLDS: usize = 20;
/// The default K: the weights of each cross-fit are fitted on 9/10 of the iterations (closer to the
/// all-data fit the result recommends than 2-fold's half), and the jackknife over 10 fold fits has
/// 9 degrees of freedom (2σ intervals cover ≈ 92% under normality, against 88% with K = 5).
pub const DEFAULT_FOLDS: usize = 10;
/// Most smaller radii one run tallies: each adds a moments value the size of the run's own, so a
/// run's sums are bounded by 7 times a plain run's (`engines::layout::folds_allowed`).
pub const MAX_RADII: usize = 6;

/// Length of a packed upper triangle of side n.
pub const fn packed_len(n: usize) -> usize {
    n * (n + 1) / 2
}

/// Index of (i, j), i ≤ j, in a packed upper triangle of side n.
#[inline]
pub fn packed_index(n: usize, i: usize, j: usize) -> usize {
    debug_assert!(i <= j && j < n);
    // Rows 0..i hold n, n−1, …, n−i+1 entries: i·n − i(i−1)/2 in all; then j − i into row i.
    i * n - i * (i + 1) / 2 + j
}

/// Light paths per chunk: the unit of parallel work and of random streams (stream c of an
/// iteration draws light paths [c·CHUNK, (c+1)·CHUNK)). Part of [`GENERATOR_ID`].
pub const LIGHT_CHUNK: u64 = 1 << 16;

/// How an iteration's light paths are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// All N_F light paths, streamed ([`crate::sim::engines::brute`]): the reference.
    Brute,
    /// Only the paths that can merge, as a Poisson process ([`crate::sim::engines::restricted`]).
    Restricted(Proposals),
}

impl Engine {
    /// The engine's name in the fingerprint. Two engines never merge: the restricted engine's law
    /// differs from the brute force's (by ≤ p_S in total variation), and so do their streams.
    pub fn id(self) -> &'static str {
        match self {
            Engine::Brute => "brute",
            Engine::Restricted(Proposals::Auto) => "restricted/auto/v1",
            Engine::Restricted(Proposals::Reverse) => "restricted/reverse/v1",
        }
    }
}

/// A validated configuration, shared read-only by every iteration. Its fields are readable through
/// the accessors below and writable only inside the core (built by `JobSpec::validate` through
/// `SimConfig::new`), so that the fingerprint always matches what it describes.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The scene: distances, lobe and illumination.
    pub(crate) scene: Scene,
    /// Merge radius R.
    pub(crate) merge_radius: f64,
    /// N_F.
    pub(crate) light_paths: u64,
    /// N_B.
    pub(crate) camera_paths: u64,
    /// The grid of cells α the weights are tabulated over.
    pub(crate) cells: CellGrid,
    /// How an iteration's light paths are drawn.
    pub(crate) engine: Engine,
    /// K: iteration s is summed into fold s mod K (cross-fitting, `solve::noise`).
    pub(crate) folds: usize,
    /// Whether the moments also keep the noise components of every iteration (light and camera
    /// paths split in halves, `stats::components`), from which `solve::predict` predicts the noise
    /// at any other N_F and N_B.
    pub(crate) noise_components: bool,
    /// The smaller radii R′ < R the run also tallies (`radii` of the job; empty by default): each
    /// this configuration at R′, with no radii of its own. The merges of a run at R contain those
    /// at every R′ ≤ R (nested discs, docs/model.md §13), so one run fills a moments value per
    /// radius, each exactly what a run at R′ would have summed from the same draws.
    pub(crate) radii: Vec<SimConfig>,
    fingerprint: String,
}

/// What the fingerprint hashes, serialised canonically (fixed field order, shortest float text).
#[derive(Serialize)]
struct FingerprintInput<'a> {
    format: u32,
    generator: &'a str,
    /// Absent for the brute force: its fingerprint changes only with the generator scheme.
    #[serde(skip_serializing_if = "Option::is_none")]
    engine: Option<&'a str>,
    scene: &'a SceneSpec,
    merge_radius: f64,
    light_paths: u64,
    camera_paths: u64,
    cells: CellSpec,
    folds: usize,
    /// Absent unless set, so the fingerprints of configurations without components are unchanged.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    noise_components: bool,
    /// Absent unless set, so the fingerprints of configurations without radii are unchanged.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    radii: Vec<f64>,
}

impl SimConfig {
    /// Builds the configuration from validated parts.
    pub(crate) fn new(
        scene: Scene,
        merge_radius: f64,
        light_paths: u64,
        camera_paths: u64,
        cells: CellGrid,
        engine: Engine,
        folds: usize,
    ) -> Self {
        let mut config = Self {
            scene,
            merge_radius,
            light_paths,
            camera_paths,
            cells,
            engine,
            folds,
            noise_components: false,
            radii: Vec::new(),
            fingerprint: String::new(),
        };
        config.fingerprint = config.compute_fingerprint();
        config
    }

    /// The scene: distances, lobe and illumination.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Merge radius R.
    pub fn merge_radius(&self) -> f64 {
        self.merge_radius
    }

    /// N_F: light paths per iteration.
    pub fn light_paths(&self) -> u64 {
        self.light_paths
    }

    /// N_B: camera paths per iteration.
    pub fn camera_paths(&self) -> u64 {
        self.camera_paths
    }

    /// The grid of cells α the weights are tabulated over.
    pub fn cells(&self) -> &CellGrid {
        &self.cells
    }

    /// How an iteration's light paths are drawn.
    pub fn engine(&self) -> Engine {
        self.engine
    }

    /// K, the cross-fitting folds.
    pub fn folds(&self) -> usize {
        self.folds
    }

    /// Whether the moments keep the noise components.
    pub fn noise_components(&self) -> bool {
        self.noise_components
    }

    /// This configuration with noise components kept (or not): another fingerprint.
    pub fn with_noise_components(mut self, on: bool) -> Self {
        self.noise_components = on;
        for sub in &mut self.radii {
            *sub = sub.clone().with_noise_components(on);
        }
        self.fingerprint = self.compute_fingerprint();
        self
    }

    /// The smaller radii this run also tallies, each as its own configuration (see
    /// [`SimConfig::with_radii`]).
    pub fn radii(&self) -> &[SimConfig] {
        &self.radii
    }

    /// This configuration also tallying the merges within each of `radii` (each < R, ascending,
    /// checked by the spec's validation): another fingerprint. Each radius's configuration is this
    /// one at R′ — the fingerprint a direct run at R′ has, so its moments merge with such a run's.
    pub fn with_radii(mut self, radii: &[f64]) -> Self {
        self.radii = radii.iter().map(|&r| self.at_radius(r)).collect();
        self.fingerprint = self.compute_fingerprint();
        self
    }

    /// This configuration at merge radius `r`, with no radii of its own.
    pub fn at_radius(&self, r: f64) -> SimConfig {
        SimConfig::new(
            self.scene.clone(),
            r,
            self.light_paths,
            self.camera_paths,
            self.cells.clone(),
            self.engine,
            self.folds,
        )
        .with_noise_components(self.noise_components)
    }

    fn compute_fingerprint(&self) -> String {
        self.fingerprint_of_format(self.moments_format())
    }

    /// The moments format this build writes for this configuration: [`MOMENTS_FORMAT_VERSION`]
    /// with noise components; without them format 3, whose sums format 4 did not change — so
    /// such moments, their fingerprints and documents stay what they were and merge with those of
    /// earlier builds.
    pub fn moments_format(&self) -> u32 {
        if self.noise_components { MOMENTS_FORMAT_VERSION } else { PLAIN_MOMENTS_FORMAT }
    }

    /// The fingerprint the same configuration had in moments `format` (a supported one): what a
    /// checkpoint or document written by an earlier build carries.
    pub fn fingerprint_of_format(&self, format: u32) -> String {
        let Self {
            scene, merge_radius, light_paths, camera_paths, cells, engine, folds, noise_components, radii, ..
        } = self.clone();
        let input = FingerprintInput {
            format,
            generator: GENERATOR_ID,
            engine: (engine != Engine::Brute).then(|| engine.id()),
            scene: &scene.spec,
            merge_radius,
            light_paths,
            camera_paths,
            cells: CellSpec {
                r2_edges: cells.r2_edges().to_vec(),
                r3_edges: cells.r3_edges().to_vec(),
                phi_bins: cells.phi_bins(),
            },
            folds,
            noise_components,
            radii: radii.iter().map(|c| c.merge_radius).collect(),
        };
        let canonical = serde_json::to_vec(&input).expect("a fingerprint input always serialises");
        sha256_hex(&canonical)
    }

    /// The same configuration drawn by another engine (its own fingerprint).
    pub fn with_engine(&self, engine: Engine) -> Self {
        Self::new(
            self.scene.clone(),
            self.merge_radius,
            self.light_paths,
            self.camera_paths,
            self.cells.clone(),
            engine,
            self.folds,
        )
        .with_noise_components(self.noise_components)
        .with_radii(&self.radii.iter().map(|c| c.merge_radius).collect::<Vec<_>>())
    }

    /// The configuration fingerprint (hex SHA-256).
    pub fn fingerprint(&self) -> &str {
        &self.fingerprint
    }

    /// Number of light-path chunks (random streams, units of parallel work) per iteration: one for
    /// the restricted engine, whose iterations are small.
    pub fn chunks(&self) -> u64 {
        match self.engine {
            Engine::Brute => self.light_paths.div_ceil(LIGHT_CHUNK),
            Engine::Restricted(_) => 1,
        }
    }

    /// Light paths in chunk `c`.
    pub fn chunk_len(&self, c: u64) -> u64 {
        (self.light_paths - c * LIGHT_CHUNK).min(LIGHT_CHUNK)
    }
}

#[cfg(test)]
mod tests {
    use crate::sim::spec::parse_job_spec;
    use serde_json::json;

    fn fp(doc: serde_json::Value) -> String {
        parse_job_spec(&doc).unwrap().validate().unwrap().config().fingerprint().to_string()
    }

    #[test]
    fn fingerprint_tracks_statistics_only() {
        let base = fp(json!({}));
        assert_eq!(base.len(), 64);
        assert_eq!(base, fp(json!({ "seed": 99, "iterations": 5, "solver": { "lambda": 1 } })));
        assert_ne!(base, fp(json!({ "merge_radius": 0.004 })));
        assert_ne!(base, fp(json!({ "light_paths": 1000 })));
        assert_ne!(base, fp(json!({ "camera_paths": 10 })));
        assert_ne!(base, fp(json!({ "scene": { "beta_deg": 4 } })));
        assert_ne!(base, fp(json!({ "cells": { "phi_bins": 2 } })));
        assert_ne!(fp(json!({ "engine": "brute" })), fp(json!({ "engine": "restricted" })));
    }
}
