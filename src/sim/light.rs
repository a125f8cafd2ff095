//! The streamed light paths of one chunk: the hot loop of optimis.
//!
//! Each light path (model.md) starts at x3l with density I/Φ, leaves plane 3 in a cosine-distributed
//! direction to x2l, is deflected by the plane-2 lobe and reaches plane 1 at x1l. Its energy is 1
//! up to x2l, and sin ϑ/ϑ after the lobe (the exact-pdf throughput, see [`super::scene::Lobe`]).
//! It merges with every camera vertex within R (the contributions are in [`super::merge`]). Paths
//! are never stored: each is generated, tested and dropped.
//!
//! Speed: the loop allocates nothing, takes no lock and dispatches nothing dynamically. The common
//! path (no merge at all, > 99.99%) costs two disc samples by rejection, one square root, one
//! division and two bitset probes, in blocks laid out as arrays (see [`trace_chunk`]). Plane 1 needs the lobe sample, but a path whose direction
//! misses the pixel by more than the lobe can ever deflect (8.57β, see
//! [`super::sampling::LOBE_MAX_SIGMAS`]) plus the angular radius of the merge disc cannot hit it;
//! that exact cone test skips the logarithm and trigonometry for most paths. Merges are rare and
//! handled out of line.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::camera::CameraSet;
use super::config::SimConfig;
use super::illumination::fill_unit_disc;
use super::merge::{merge_plane1, merge_plane2, merge_plane3};
use super::rng::{StreamRng, stream};
use super::sampling::{LOBE_MAX_SIGMAS, sample_lobe};
use super::tally::{ChunkScratch, ChunkTally};

/// Constants of the light-path loop, derived once per configuration.
#[derive(Debug, Clone, Copy)]
pub struct PixelCone {
    /// c·|c| for c = cos of the widest angle between a path's incident direction at x2l and the
    /// direction to the pixel for which the path can still land within R of the pixel (c = −2,
    /// below any cosine, when that angle reaches π and every path must sample the lobe).
    c_abs_c: f64,
}

impl PixelCone {
    /// The cone for lobe width `beta`, plane distance `l2` and merge radius `radius` < l2.
    ///
    /// Proof of the bound: the lobe deflects the incident direction d by ϑ ≤ ϑ_max =
    /// LOBE_MAX_SIGMAS·β into d'. If d' hits plane 1 within R of the pixel, d' points into the ball
    /// of radius R about the pixel, which from x2l (at distance ≥ L2 > R) subtends a half-angle
    /// ≤ δ = asin(R/L2); so angle(d', t) ≤ δ for t the direction to the pixel. By the triangle
    /// inequality on the sphere, angle(d, t) ≤ ϑ_max + δ. A relative margin of 10⁻⁶ covers rounding.
    pub fn new(beta: f64, l2: f64, radius: f64) -> Self {
        assert!(radius < l2, "the merge radius must be smaller than L2 for the pixel cone bound");
        let reach = (LOBE_MAX_SIGMAS * beta + (radius / l2).asin()) * (1.0 + 1e-6);
        let c = if reach >= PI { -2.0 } else { reach.cos() };
        Self { c_abs_c: c * c.abs() }
    }

    /// Whether a path at (`x`, `y`) on plane 2 travelling along the unit direction (`u`, `v`, −`z`)
    /// can reach the pixel's merge disc.
    ///
    /// With t = pixel − x2l, the test is d·t ≥ c·|t|. Because s ↦ s·|s| is strictly increasing it
    /// equals (d·t)·|d·t| ≥ c·|c|·|t|², which needs neither a square root nor a branch, and holds
    /// for every path when c = −2 (as |d·t| ≤ |t|).
    #[inline(always)]
    pub fn may_reach(&self, x: f64, y: f64, u: f64, v: f64, z: f64, l2: f64) -> bool {
        let dot = -u * x - v * y + z * l2;
        let t2 = x * x + y * y + l2 * l2;
        dot * dot.abs() >= self.c_abs_c * t2
    }
}

/// Light paths per block of the chunk loop.
const BLOCK: usize = 128;

/// One block of light paths, as arrays (structure of arrays), reused from block to block.
struct Block {
    rings: [u8; BLOCK],
    /// Start points x3l.
    x3: [[f64; BLOCK]; 2],
    /// Direction disc points (u, v) and ρ², then z = √(1 − ρ²) in place of ρ².
    dir: [[f64; BLOCK]; 3],
    /// Hits x2l on plane 2.
    x2: [[f64; BLOCK]; 2],
    /// Bit 0: may merge at plane 3; bit 1: at plane 2; bit 2: may reach the pixel.
    flags: [u8; BLOCK],
}

/// Traces chunk `chunk` of iteration `iteration` and returns its tally.
///
/// Paths go through in blocks of [`BLOCK`], stage by stage over arrays: start points, directions
/// (both by branch-free rejection), a straight-line pass that projects to plane 2 and runs the pixel
/// cone test (free of branches and memory lookups, so the compiler can vectorise it), a pass of
/// occupancy-bit probes, and last the few flagged paths, in path order. The order of draws is
/// therefore: a block's ring choices, its start discs, its direction discs, then the lobe draws of
/// its flagged paths — fixed for a given (seed, iteration, chunk), so results stay deterministic.
pub fn trace_chunk(
    config: &SimConfig,
    cameras: &CameraSet,
    seed: u64,
    iteration: u64,
    chunk: u64,
    scratch: &mut ChunkScratch,
) -> ChunkTally {
    let scene = &config.scene;
    let (l2, l3) = (scene.l2, scene.l3);
    let cone = PixelCone::new(scene.lobe.beta, l2, config.merge_radius);
    let mut rng = stream(seed, iteration, chunk);
    let mut b = Block {
        rings: [0; BLOCK],
        x3: [[0.0; BLOCK]; 2],
        dir: [[0.0; BLOCK]; 3],
        x2: [[0.0; BLOCK]; 2],
        flags: [0; BLOCK],
    };
    let mut remaining = config.chunk_len(chunk) as usize;
    while remaining > 0 {
        let n = remaining.min(BLOCK);
        remaining -= n;

        // Starts x3l on plane 3, density I/Φ.
        scene.illumination.sample_block(&mut rng, &mut b.rings[..n], &mut b.dir, &mut b.x3, n);

        // Cosine directions by Malley's method: disc points (u, v), lifted to z = √(1 − ρ²).
        let [du, dv, dz] = &mut b.dir;
        fill_unit_disc(&mut rng, &mut du[..n], &mut dv[..n], &mut dz[..n]);

        // Plane 2 and the pixel cone. Travel is downwards: d = (u, v, −z).
        let [x3x, x3y] = &b.x3;
        let [x2x, x2y] = &mut b.x2;
        for i in 0..n {
            let z = (1.0 - dz[i]).sqrt();
            let reach = l3 / z;
            x2x[i] = x3x[i] + reach * du[i];
            x2y[i] = x3y[i] + reach * dv[i];
            dz[i] = z;
            b.flags[i] = u8::from(cone.may_reach(x2x[i], x2y[i], du[i], dv[i], z, l2)) << 2;
        }

        // Camera vertices nearby?
        for i in 0..n {
            b.flags[i] |= u8::from(cameras.plane3.may_hold([x3x[i], x3y[i]]))
                | (u8::from(cameras.plane2.may_hold([x2x[i], x2y[i]])) << 1);
        }

        // The rare paths that may merge.
        for i in 0..n {
            if b.flags[i] != 0 {
                let d = Vector3::new(du[i], dv[i], -dz[i]);
                trace_flagged(config, cameras, b.flags[i], [x3x[i], x3y[i]], [x2x[i], x2y[i]], &d, &mut rng, scratch);
            }
        }
    }
    scratch.take()
}

/// Merges of one flagged path: candidates from the grids, exact distance tests, and, if the path
/// may reach the pixel, its lobe deflection to plane 1.
#[cold]
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn trace_flagged(
    config: &SimConfig,
    cameras: &CameraSet,
    flags: u8,
    x3: [f64; 2],
    x2: [f64; 2],
    d: &Vector3<f64>,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
) {
    if flags & 1 != 0 {
        merge_plane3(config, cameras, cameras.plane3.candidates(x3), x3, scratch);
    }
    if flags & 2 != 0 {
        merge_plane2(config, cameras, cameras.plane2.candidates(x2), x2, x3, d, scratch);
    }
    if flags & 4 != 0 {
        let l2 = config.scene.l2;
        let (out, theta) = sample_lobe(&config.scene.lobe, d, rng);
        if out.z < 0.0 {
            let x1 = [x2[0] - l2 * out.x / out.z, x2[1] - l2 * out.y / out.z];
            let r = config.merge_radius;
            if x1[0] * x1[0] + x1[1] * x1[1] <= r * r {
                merge_plane1(config, theta, x2, x3, scratch);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::stream;
    use crate::sim::sampling::deflect;

    /// The cone test must never skip a path that can hit the pixel disc: for random x2 near the
    /// axis and directions aimed near the pixel, any deflection within the lobe's bound that lands
    /// in the disc must come from a direction the cone admits.
    #[test]
    fn pixel_cone_never_rejects_a_possible_hit() {
        let beta = 3f64.to_radians();
        let (l2, r) = (1.0, 0.05);
        let cone = PixelCone::new(beta, l2, r);
        let mut rng = stream(9, 9, 9);
        let mut hits = 0;
        for _ in 0..200_000 {
            let u = |rng: &mut _| crate::sim::rng::uniform(rng);
            let x2 = [u(&mut rng) * 2.0 - 1.0, u(&mut rng) * 2.0 - 1.0];
            let (t, _) = crate::sim::scene::Scene::from_spec(&crate::sim::spec::SceneSpec {
                l2,
                l3: 3.0,
                beta_deg: 3.0,
                illumination: crate::sim::spec::IlluminationSpec::Uniform { r_ls: 1.0 },
            })
            .towards_pixel(x2);
            // An incident direction up to 10β away from the pixel direction…
            let d = deflect(&t, u(&mut rng) * 10.0 * beta, u(&mut rng) * std::f64::consts::TAU);
            if d.z >= 0.0 {
                continue;
            }
            // …deflected by up to the lobe's largest angle.
            let out = deflect(&d, u(&mut rng) * LOBE_MAX_SIGMAS * beta, u(&mut rng) * std::f64::consts::TAU);
            if out.z >= 0.0 {
                continue;
            }
            let x1 = [x2[0] - l2 * out.x / out.z, x2[1] - l2 * out.y / out.z];
            if x1[0].hypot(x1[1]) <= r {
                hits += 1;
                assert!(cone.may_reach(x2[0], x2[1], d.x, d.y, -d.z, l2), "cone rejected a hit at {x2:?}");
            }
        }
        assert!(hits > 100, "the test must exercise hits ({hits})");
        // And it does reject: a direction pointing away from the pixel.
        let away = Vector3::new(0.9, 0.0, -0.1).normalize();
        assert!(!cone.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
        // A lobe so wide that every path may reach the pixel.
        let wide = PixelCone::new(45f64.to_radians(), l2, r);
        assert!(wide.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
    }
}
