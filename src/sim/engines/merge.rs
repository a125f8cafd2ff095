//! The merges of one light path with the camera paths of its iteration, shared by every engine.
//!
//! Given a light path's vertices, each function tests the camera vertices the spatial grid offers
//! with the exact distance test and records every merge's contribution and per-path strategy
//! weights (docs/model.md §4):
//!
//! * plane 3: C2 = E_c(x3c)·E_l·K/π, join path (x2c, x3c);
//! * plane 2: C1 = E_l·K·f2(x3l→x2l, x2c→x1c), join path (x2c, x3l);
//! * plane 1: C0 = E_l(x1l)·K/π with each of the N_B camera paths, join path (x2l, x3l);
//!
//! with K = 1/(πR²). Keeping them in one place is what makes the engines estimate the same thing:
//! they differ only in which light paths they generate, never in what a path contributes.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::camera::CameraSet;
use super::grid::Candidates;
use super::strategies::{Technique, light_start, strategy_weights, strategy_weights_with};
use super::tally::{CameraPaths, ChunkScratch};
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::{angle_between, theta_over_sin};

/// K = 1/(πR²).
#[inline]
pub(crate) fn kernel(config: &SimConfig) -> f64 {
    1.0 / (PI * config.merge_radius * config.merge_radius)
}

#[inline]
pub(crate) fn within(a: [f64; 2], b: [f64; 2], r: f64) -> bool {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    dx * dx + dy * dy <= r * r
}

pub(crate) fn merge_plane3(
    config: &SimConfig,
    cameras: &CameraSet,
    near: Candidates<'_>,
    x3l: [f64; 2],
    scratch: &mut ChunkScratch,
) {
    let k = config.cells.len();
    for j in near {
        let cam = &cameras.paths[j as usize];
        let Some(x3c) = cam.x3 else { continue };
        if within(x3l, x3c, config.merge_radius) {
            let c = cam.energy3 * kernel(config) / PI;
            let start = light_start(config, x3l);
            let (cell, weights) = scratch.plane3_weights(cameras.generation, j, start, || {
                (config.cells.index(cam.x2, x3c), strategy_weights_with(config, Technique::Plane3, cam.x2, x3c, start))
            });
            scratch.record(Technique::Plane3, cell, k, c, &weights, CameraPaths::One(j));
            scratch.count_merge(Technique::Plane3);
        }
    }
}

pub(crate) fn merge_plane2(
    config: &SimConfig,
    cameras: &CameraSet,
    near: Candidates<'_>,
    x2l: [f64; 2],
    x3l: [f64; 2],
    d: &Vector3<f64>,
    scratch: &mut ChunkScratch,
) {
    let k = config.cells.len();
    for j in near {
        let cam = &cameras.paths[j as usize];
        if within(x2l, cam.x2, config.merge_radius) {
            // f2(dir x3l→x2l, dir x2c→x1c): deflection between the light's incident direction and
            // the direction to the pixel; γ is that direction's angle to the normal.
            let theta = angle_between(d, &cam.to_pixel);
            let c = kernel(config) * config.scene.lobe.bdf(theta, cam.cos1);
            let weights = strategy_weights(config, Technique::Plane2, cam.x2, x3l, x3l);
            scratch.record(Technique::Plane2, config.cells.index(cam.x2, x3l), k, c, &weights, CameraPaths::One(j));
            scratch.count_merge(Technique::Plane2);
        }
    }
}

pub(crate) fn merge_plane1(config: &SimConfig, theta: f64, x2l: [f64; 2], x3l: [f64; 2], scratch: &mut ChunkScratch) {
    // Energy after the lobe: sin ϑ/ϑ. The merge happens with all N_B camera paths at the shared
    // pixel, so the pair sum over j is N_B times one contribution.
    let energy = 1.0 / theta_over_sin(theta);
    let c = energy * kernel(config) / PI * config.camera_paths as f64;
    let weights = strategy_weights(config, Technique::Plane1, x2l, x3l, x3l);
    scratch.record(Technique::Plane1, config.cells.index(x2l, x3l), config.cells.len(), c, &weights, CameraPaths::All);
    scratch.count_merge(Technique::Plane1);
}
