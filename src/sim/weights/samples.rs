//! Join paths drawn with the engine's own samplers — camera paths as an iteration traces them, light
//! paths from the light's profile through the lobe — and the engine's weights on them: what the
//! evaluators of a weights artifact are checked against (each must give the engine's weight of
//! every merge), and what the figures of a per-path or stacked weight function average over.

use super::artifact::WeightsArtifact;
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::strategies::{PathStrategy, PathWeights, Technique, light_start};
use crate::sim::math::rng::stream;
use crate::sim::math::sampling::{cosine_direction, disc_point};
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::{advance, sample_lobe};

/// The stream of the light paths drawn here (no engine uses it: these draws never mix with a
/// run's).
const SAMPLE_STREAM: u64 = u64::MAX - 16;

/// One merge's join path: the technique, the join path (0, x2, x3) and where its light path starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoinSample {
    /// The merging technique (0: plane 1, 1: plane 2, 2: plane 3).
    pub technique: usize,
    /// x2 on plane 2.
    pub x2: [f64; 2],
    /// x3 on plane 3 (the camera's x3c for a plane-3 merge).
    pub x3: [f64; 2],
    /// The light path's start x3l.
    pub x3_light: [f64; 2],
}

/// At least `count` join paths of `config`'s scene, three per camera path that reaches plane 3
/// (one per technique): its camera path with a light path drawn for it — plane 3: (x2c, x3c), the
/// light starting within R of x3c; plane 2: (x2c, x3l); plane 1: (x2l, x3l). Deterministic in
/// `seed`.
pub fn join_paths(config: &SimConfig, seed: u64, count: usize) -> Vec<JoinSample> {
    let scene = &config.scene;
    let mut out = Vec::with_capacity(count + 3 * config.camera_paths as usize);
    let mut iteration = 0;
    while out.len() < count {
        let cameras = CameraSet::generate(config, seed, iteration);
        let mut rng = stream(seed, iteration, SAMPLE_STREAM);
        for camera in &cameras.paths {
            let Some(x3c) = camera.x3 else { continue };
            let x3l = scene.illumination.sample(&mut rng);
            let down = cosine_direction(&mut rng);
            let x2l = advance(x3l, &down, -scene.l3);
            let near = disc_point(&mut rng, x3c, config.merge_radius);
            out.push(JoinSample { technique: 2, x2: camera.x2, x3: x3c, x3_light: near });
            out.push(JoinSample { technique: 1, x2: camera.x2, x3: x3l, x3_light: x3l });
            out.push(JoinSample { technique: 0, x2: x2l, x3: x3l, x3_light: x3l });
            // The lobe's draw keeps the stream's use the same whatever a path's geometry.
            let _ = sample_lobe(&scene.lobe, &down, &mut rng);
        }
        iteration += 1;
    }
    out
}

/// The engine's weight of `sample`'s merge under per-path strategy `p`.
pub fn engine_weight(config: &SimConfig, p: PathStrategy, sample: &JoinSample) -> f64 {
    let technique = [Technique::Plane1, Technique::Plane2, Technique::Plane3][sample.technique];
    PathWeights::new(config, sample.x2, sample.x3).of(technique, light_start(config, sample.x3_light))[p.index()]
}

/// The weight of `sample`'s merge under `artifact` as the engine computes it: its table's weight in
/// the engine's cell of the join path plus Σ β_h times the engine's weight of each heuristic.
pub fn engine_artifact_weight(config: &SimConfig, artifact: &WeightsArtifact, sample: &JoinSample) -> f64 {
    let table = if artifact.table.is_empty() {
        0.0
    } else {
        let alpha = config.cells().index(sample.x2, sample.x3);
        let (r2, r3, phi) = config.cells().coordinates(alpha);
        artifact.table.iter().find(|c| (c.r2, c.r3, c.phi) == (r2, r3, phi)).map_or(f64::NAN, |c| c.w[sample.technique])
    };
    let technique = [Technique::Plane1, Technique::Plane2, Technique::Plane3][sample.technique];
    let all = PathWeights::new(config, sample.x2, sample.x3).of(technique, light_start(config, sample.x3_light));
    let heuristic =
        |name: &str| PathStrategy::ALL.iter().find(|p| p.name() == name).map_or(f64::NAN, |p| all[p.index()]);
    table + artifact.heuristics.iter().map(|h| h.beta * heuristic(&h.name)).sum::<f64>()
}
