//! The vertex densities of the model scene's join paths (docs/model.md §9), from the artifact's own
//! scene parameters: what a renderer of that scene passes to the evaluator, and a worked example of
//! what a renderer of another scene computes from its own sub-path samplers. The C and Python
//! helpers compute the same.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::artifact::ArtifactScene;
use super::function::{PathDensities, PathInputs};

/// The lobe's solid-angle pdf q(ϑ) = g(ϑ)·ϑ/sin ϑ, g(ϑ) = exp(−ϑ²/2β²)/(2πβ²) (docs/model.md §1, §9).
pub fn lobe_pdf(beta: f64, theta: f64) -> f64 {
    let g = libm::exp(-theta * theta / (2.0 * beta * beta)) / (2.0 * PI * beta * beta);
    let ratio = if theta < 1e-4 { 1.0 + theta * theta / 6.0 } else { theta / libm::sin(theta) };
    g * ratio
}

/// The light's start density I(r)/Φ at radius `r` on plane 3.
pub fn start_density(scene: &ArtifactScene, r: f64) -> f64 {
    scene.rings.iter().find(|ring| r >= ring.inner && r < ring.outer).map_or(0.0, |ring| ring.level / scene.flux)
}

fn norm(p: [f64; 2]) -> f64 {
    (p[0] * p[0] + p[1] * p[1]).sqrt()
}

/// The evaluator's inputs for the model scene's join path (0, x2, x3) whose light path starts at
/// `x3_light` (x3 itself, except for a plane-3 merge: there the join path takes the camera's x3c and
/// the light path starts at x3l, within R of it).
pub fn model_path(scene: &ArtifactScene, x2: [f64; 2], x3: [f64; 2], x3_light: [f64; 2]) -> PathInputs {
    let u = Vector3::new(x2[0], x2[1], scene.l2);
    let v = Vector3::new(x3[0] - x2[0], x3[1] - x2[1], scene.l3);
    let (d1, d2) = (u.norm(), v.norm());
    let (a, b) = (u / d1, v / d2);
    let theta = libm::atan2(a.cross(&b).norm(), a.dot(&b));
    let q = lobe_pdf(scene.beta_rad, theta);
    let (d1_2, d2_2) = (d1 * d1, d2 * d2);
    let densities = PathDensities {
        camera_x2: scene.l2 * scene.l2 / (PI * d1_2 * d1_2),
        camera_x3: q * scene.l3 / (d2_2 * d2),
        light_start: start_density(scene, norm(x3_light)),
        light_x2: scene.l3 * scene.l3 / (PI * d2_2 * d2_2),
        light_x1: q * scene.l2 / (d1_2 * d1),
    };
    let cross = x2[0] * x3[1] - x2[1] * x3[0];
    let dot = x2[0] * x3[0] + x2[1] * x3[1];
    PathInputs { r2: norm(x2), r3: norm(x3), phi: libm::atan2(cross.abs(), dot), densities }
}
