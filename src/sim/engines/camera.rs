//! The N_B camera paths of one iteration and the merge grids of their vertices on planes 2 and 3.
//!
//! A camera path (model.md) starts at the pixel x1c = 0, leaves plane 1 in a cosine-distributed
//! direction (Lambert transmission) to x2c, is deflected by the plane-2 lobe around its continuing
//! direction and reaches x3c — or not, if the deflection turned it back towards plane 1 (ϑ can reach
//! 8.6β, so a grazing path can be lost; its x3c merges with nothing).
//!
//! Importance (camera energy): E_c(x1c) = E_c(x2c) = 1 (the cosine pdf cancels plane 1's BDF and
//! the cosine of the pixel's measurement). At x3c: f2·cos θ_in / pdf_w(ω) = (cos θ_in / cos γ_out)
//! · (sin ϑ/ϑ), where cos γ_out = cos θ1 of the first segment and cos θ_in that of the second
//! (see [`crate::sim::model::scene::Lobe`] for the exact pdf).

use nalgebra::Vector3;

use super::grid::MergeGrid;
use crate::sim::math::rng::{CAMERA_STREAM, stream};
use crate::sim::math::sampling::cosine_direction;
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::sample_lobe;
use crate::sim::model::scene::theta_over_sin;

/// One camera path's vertices and what merging with them needs.
#[derive(Debug, Clone, Copy)]
pub struct CameraPath {
    /// x2c.
    pub x2: [f64; 2],
    /// cos θ1 = cos γ of the direction from x2c to the pixel.
    pub cos1: f64,
    /// Unit direction of travel from x2c to the pixel (light-flow direction at a plane-2 merge).
    pub to_pixel: Vector3<f64>,
    /// x3c, if the path reached plane 3.
    pub x3: Option<[f64; 2]>,
    /// E_c(x3c).
    pub energy3: f64,
}

/// The camera paths of one iteration with their merge grids.
#[derive(Debug, Clone)]
pub struct CameraSet {
    pub paths: Vec<CameraPath>,
    /// Vertices x2c.
    pub plane2: MergeGrid,
    /// Vertices x3c (of the paths that reached plane 3).
    pub plane3: MergeGrid,
}

impl CameraSet {
    /// Traces the N_B camera paths of iteration `iteration` from its camera stream.
    pub fn generate(config: &SimConfig, seed: u64, iteration: u64) -> Self {
        let scene = &config.scene;
        let mut rng = stream(seed, iteration, CAMERA_STREAM);
        let paths: Vec<CameraPath> = (0..config.camera_paths)
            .map(|_| {
                let d1 = cosine_direction(&mut rng);
                let x2 = [scene.l2 * d1.x / d1.z, scene.l2 * d1.y / d1.z];
                let (d2, theta) = sample_lobe(&scene.lobe, &d1, &mut rng);
                let (x3, energy3) = if d2.z > 0.0 {
                    let x3 = [x2[0] + scene.l3 * d2.x / d2.z, x2[1] + scene.l3 * d2.y / d2.z];
                    (Some(x3), d2.z / d1.z / theta_over_sin(theta))
                } else {
                    (None, 0.0)
                };
                CameraPath { x2, cos1: d1.z, to_pixel: -d1, x3, energy3 }
            })
            .collect();
        let radius = config.merge_radius;
        let plane2 = MergeGrid::new(paths.iter().enumerate().map(|(j, p)| (j as u32, p.x2)), radius);
        let plane3 =
            MergeGrid::new(paths.iter().enumerate().filter_map(|(j, p)| p.x3.map(|x3| (j as u32, x3))), radius);
        Self { paths, plane2, plane3 }
    }
}
