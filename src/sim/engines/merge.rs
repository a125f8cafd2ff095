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
use super::strategies::{PathWeights, Technique, light_start, strategy_weights_with};
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
    distance2(a, b) <= r * r
}

#[inline]
fn distance2(a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    dx * dx + dy * dy
}

/// Records a merge at squared distance `d2` with `record(config, scratch)` at R and again at every
/// smaller radius R′ of the configuration that contains it (docs/model.md §13: the discs are
/// nested, so the merges within R′ are exactly a run at R′'s), each with its own configuration —
/// its kernel K′ = 1/(πR′²) and its weights — into its own scratch. The radii ascend, so the
/// loop stops at the first that does not contain the merge.
#[inline]
fn record_at_radii(
    config: &SimConfig,
    d2: f64,
    scratch: &mut ChunkScratch,
    mut record: impl FnMut(&SimConfig, &mut ChunkScratch),
) {
    record(config, scratch);
    for (sub, sub_scratch) in config.radii.iter().zip(&mut scratch.radii).rev() {
        if d2 > sub.merge_radius * sub.merge_radius {
            break;
        }
        record(sub, sub_scratch);
    }
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
        let d2 = distance2(x3l, x3c);
        if d2 <= config.merge_radius * config.merge_radius {
            let start = light_start(config, x3l);
            record_at_radii(config, d2, scratch, |config, scratch| {
                let c = cam.energy3 * kernel(config) / PI;
                let (cell, weights) = scratch.plane3_weights(cameras.generation, j, start, || {
                    (
                        config.cells.index(cam.x2, x3c),
                        strategy_weights_with(config, Technique::Plane3, cam.x2, x3c, start),
                    )
                });
                scratch.record(Technique::Plane3, cell, k, c, &weights, CameraPaths::One(j));
                scratch.count_merge(Technique::Plane3);
            });
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
        let d2 = distance2(x2l, cam.x2);
        if d2 <= config.merge_radius * config.merge_radius {
            // f2(dir x3l→x2l, dir x2c→x1c): deflection between the light's incident direction and
            // the direction to the pixel; γ is that direction's angle to the normal.
            let theta = angle_between(d, &cam.to_pixel);
            let f2 = config.scene.lobe.bdf(theta, cam.cos1);
            let cell = config.cells.index(cam.x2, x3l);
            let (path, start) = (PathWeights::new(config, cam.x2, x3l), light_start(config, x3l));
            record_at_radii(config, d2, scratch, |config, scratch| {
                let weights = path.of_at(Technique::Plane2, start, config);
                scratch.record(Technique::Plane2, cell, k, kernel(config) * f2, &weights, CameraPaths::One(j));
                scratch.count_merge(Technique::Plane2);
            });
        }
    }
}

/// A light path that lands at `x1` within R of the pixel: it merges there with all N_B camera
/// paths (and at every smaller radius that contains x1).
pub(crate) fn merge_plane1(
    config: &SimConfig,
    theta: f64,
    x1: [f64; 2],
    x2l: [f64; 2],
    x3l: [f64; 2],
    scratch: &mut ChunkScratch,
) {
    // Energy after the lobe: sin ϑ/ϑ. The merge happens with all N_B camera paths at the shared
    // pixel, so the pair sum over j is N_B times one contribution.
    let energy = 1.0 / theta_over_sin(theta);
    let cell = config.cells.index(x2l, x3l);
    let (path, start) = (PathWeights::new(config, x2l, x3l), light_start(config, x3l));
    record_at_radii(config, distance2(x1, [0.0, 0.0]), scratch, |config, scratch| {
        let c = energy * kernel(config) / PI * config.camera_paths as f64;
        let weights = path.of_at(Technique::Plane1, start, config);
        scratch.record(Technique::Plane1, cell, config.cells.len(), c, &weights, CameraPaths::All);
        scratch.count_merge(Technique::Plane1);
    });
}
