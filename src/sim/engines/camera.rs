//! The N_B camera paths of one iteration and the merge grids of their vertices on planes 2 and 3.
//!
//! A camera path (docs/model.md §3) starts at the pixel x1c = 0, leaves plane 1 in a
//! cosine-distributed direction (Lambert transmission) to x2c, is deflected by the plane-2 lobe
//! around its continuing direction and reaches x3c — or not, if the deflection turned it back
//! towards plane 1 (ϑ can reach 8.5β, so a grazing path can be lost; its x3c merges with nothing).
//!
//! Importance (camera energy): E_c(x1c) = E_c(x2c) = 1 (the cosine pdf cancels plane 1's BDF and
//! the cosine of the pixel's measurement). At x3c: f2·cos θ_in / pdf_w(ω) = (cos θ_in / cos γ_out)
//! · (sin ϑ/ϑ), where cos γ_out = cos θ1 of the first segment and cos θ_in that of the second
//! (see [`crate::sim::model::scene::Lobe`] for the exact pdf).
//!
//! Speed: the restricted engine generates a camera set per iteration (tens of microseconds of
//! budget in all), so the paths are traced in blocks as arrays with branch-free arithmetic that
//! the compiler turns into SIMD code — the polar form of the cosine direction (as the light paths
//! of [`super::brute`]), the vectorisable logarithm, sine and cosine of
//! [`crate::sim::math::fastmath`] instead of `libm`'s calls — and compiled a second time for
//! AVX2 and FMA, chosen at run time. Only exactly rounded IEEE operations are used, so both builds
//! give the same bits. A [`CameraSet`] is reused from iteration to iteration by
//! [`CameraSet::regenerate`]: no allocation once its buffers have grown.

use std::sync::atomic::{AtomicU64, Ordering};

use nalgebra::Vector3;
use rand::Rng;

use super::grid::MergeGrid;
use crate::sim::math::fastmath::{ln, sincos, sincos_turn};
use crate::sim::math::rng::{CAMERA_STREAM, StreamRng, stream, unit52};
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::advance;

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
#[derive(Debug, Clone, Default)]
pub struct CameraSet {
    /// The N_B camera paths, in index order j (a path's half for the noise components is j mod 2).
    pub paths: Vec<CameraPath>,
    /// Vertices x2c.
    pub plane2: MergeGrid,
    /// Vertices x3c (of the paths that reached plane 3).
    pub plane3: MergeGrid,
    /// A number no other camera set of this process has had (each [`CameraSet::regenerate`] takes
    /// a new one): what a cache of per-camera values is keyed by (`tally::ChunkScratch`).
    pub generation: u64,
}

/// The next [`CameraSet::generation`].
static NEXT_GENERATION: AtomicU64 = AtomicU64::new(1);

/// Camera paths per block of the tracing loop.
const BLOCK: usize = 64;

/// Random words per camera path: sin² θ1, the two azimuths (high and low half), the lobe's u.
const WORDS: usize = 3;

/// One block of camera paths as arrays (structure of arrays), so that the loop vectorises.
struct Block {
    /// Random words of each path, path-major: words WORDS·i.. of path i.
    bits: [[u64; WORDS]; BLOCK],
    x2: [[f64; BLOCK]; 2],
    /// The first segment's direction d1 (unit, up from the pixel).
    d1: [[f64; BLOCK]; 3],
    x3: [[f64; BLOCK]; 2],
    energy3: [f64; BLOCK],
    reached: [bool; BLOCK],
}

impl Block {
    fn empty() -> Self {
        Self {
            bits: [[0; WORDS]; BLOCK],
            x2: [[0.0; BLOCK]; 2],
            d1: [[0.0; BLOCK]; 3],
            x3: [[0.0; BLOCK]; 2],
            energy3: [0.0; BLOCK],
            reached: [false; BLOCK],
        }
    }
}

impl CameraSet {
    /// Traces the N_B camera paths of iteration `iteration` from its camera stream.
    pub fn generate(config: &SimConfig, seed: u64, iteration: u64) -> Self {
        let mut set = Self::default();
        set.regenerate(config, seed, iteration);
        set
    }

    /// [`CameraSet::generate`] into this set, reusing its buffers (the result is the same).
    ///
    /// Random numbers: path j takes words 3j, 3j + 1, 3j + 2 of the scalar camera stream of
    /// (seed, iteration) — one stream, not the multi-lane generator, whose eight jumps (2,048
    /// generator steps) would cost more than the hundred paths of the paper; drawing three words a
    /// path in order is a few hundred nanoseconds.
    pub fn regenerate(&mut self, config: &SimConfig, seed: u64, iteration: u64) {
        self.generation = NEXT_GENERATION.fetch_add(1, Ordering::Relaxed);
        let mut rng = stream(seed, iteration, CAMERA_STREAM);
        let mut block = Block::empty();
        let total = config.camera_paths as usize;
        self.paths.clear();
        self.paths.reserve(total);
        while self.paths.len() < total {
            let n = (total - self.paths.len()).min(BLOCK);
            trace(config, &mut rng, &mut block, n);
            self.paths.extend((0..n).map(|i| {
                let [dx, dy, dz] = [block.d1[0][i], block.d1[1][i], block.d1[2][i]];
                CameraPath {
                    x2: [block.x2[0][i], block.x2[1][i]],
                    cos1: dz,
                    to_pixel: Vector3::new(-dx, -dy, -dz),
                    x3: block.reached[i].then_some([block.x3[0][i], block.x3[1][i]]),
                    energy3: block.energy3[i],
                }
            }));
        }
        let radius = config.merge_radius;
        let paths = &self.paths;
        self.plane2.rebuild(paths.iter().enumerate().map(|(j, p)| (j as u32, p.x2)), radius);
        self.plane3.rebuild(paths.iter().enumerate().filter_map(|(j, p)| p.x3.map(|x3| (j as u32, x3))), radius);
    }
}

/// Draws the words of `n` paths and traces them into `b` (the AVX2 + FMA build where the CPU has
/// it: the same bits).
fn trace(config: &SimConfig, rng: &mut StreamRng, b: &mut Block, n: usize) {
    for words in &mut b.bits[..n] {
        for w in words {
            *w = rng.next_u64();
        }
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has every feature `trace_block_avx2` is compiled for.
        unsafe { trace_block_avx2(config, b) };
        return;
    }
    trace_block(config, b);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn trace_block_avx2(config: &SimConfig, b: &mut Block) {
    trace_block(config, b);
}

/// Traces the whole block (the words past the paths in use are stale and their results unused:
/// cheaper than a variable trip count, which would stop the loop from vectorising cleanly).
#[inline(always)]
fn trace_block(config: &SimConfig, b: &mut Block) {
    let scene = &config.scene;
    let (l2, l3, beta) = (scene.l2, scene.l3, scene.lobe.beta);
    for i in 0..BLOCK {
        let [w0, w1, w2] = b.bits[i];
        // d1: a cosine direction by Malley's method in polar form, sin² θ1 uniform in [0, 1) and
        // the azimuth uniform; cos² θ1 = 1 − sin² θ1 is exact and ≥ 2⁻⁵², so tan θ1 is finite.
        let s2 = unit52(w0);
        let c2 = 1.0 - s2;
        let (sin1, cos1) = (s2.sqrt(), c2.sqrt());
        let (sp, cp) = sincos_turn((w1 >> 32) as u32);
        let (dx, dy, dz) = (sin1 * cp, sin1 * sp, cos1);
        // x2c = L2·tan θ1·(cos φ, sin φ): `advance` from the pixel by L2, in polar form.
        let lateral = l2 * (s2 / c2).sqrt();
        let (x2x, x2y) = (lateral * cp, lateral * sp);
        // The lobe (`sample_lobe`): ϑ = β√(−2 ln u) with u = 1 − unit52 in (0, 1] (so ϑ ≤ 8.5β),
        // azimuth ψ uniform, about d1 in the basis of `orthonormal_basis` (Duff et al. 2017).
        let u = 1.0 - unit52(w2);
        let theta = beta * (-2.0 * ln(u)).sqrt();
        let (st, ct) = sincos(theta);
        let (spsi, cpsi) = sincos_turn(w1 as u32);
        let sign = 1f64.copysign(dz);
        let a = -1.0 / (sign + dz);
        let bb = dx * dy * a;
        let (tx, ty, tz) = (1.0 + sign * dx * dx * a, sign * bb, -sign * dx);
        let (ux, uy, uz) = (bb, sign + dy * dy * a, -dy);
        let ex = dx * ct + (tx * cpsi + ux * spsi) * st;
        let ey = dy * ct + (ty * cpsi + uy * spsi) * st;
        let ez = dz * ct + (tz * cpsi + uz * spsi) * st;
        // x3c and E_c(x3c) = (cos θ_in / cos γ_out)·(sin ϑ/ϑ) (module documentation); ϑ/sin ϑ as
        // `theta_over_sin`, continuous at 0. Both sides of every select are computed (no branch).
        let reached = ez > 0.0;
        let over_sin = if theta < 1e-4 { 1.0 + theta * theta / 6.0 } else { theta / st };
        b.x2[0][i] = x2x;
        b.x2[1][i] = x2y;
        b.d1[0][i] = dx;
        b.d1[1][i] = dy;
        b.d1[2][i] = dz;
        [b.x3[0][i], b.x3[1][i]] = advance([x2x, x2y], &Vector3::new(ex, ey, ez), l3);
        b.energy3[i] = if reached { ez / dz / over_sin } else { 0.0 };
        b.reached[i] = reached;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::spec::parse_job_spec;

    /// The AVX2 build gives the same bits as the portable one, and regenerating into a used set
    /// gives the set a fresh one would have.
    #[test]
    fn builds_agree_and_reuse_is_clean() {
        let job = parse_job_spec(&serde_json::json!({ "preset": "paper-table1", "camera_paths": 150 }))
            .unwrap()
            .validate()
            .unwrap();
        let config = job.config();
        let mut a = CameraSet::generate(config, 3, 4);
        let fresh = CameraSet::generate(config, 3, 5);
        a.regenerate(config, 3, 5);
        let bits = |s: &CameraSet| {
            s.paths.iter().map(|p| (p.x2, p.cos1, p.to_pixel, p.x3, p.energy3.to_bits())).collect::<Vec<_>>()
        };
        assert_eq!(bits(&a), bits(&fresh));
        let mut rng = stream(3, 5, CAMERA_STREAM);
        let mut block = Block::empty();
        trace(config, &mut rng, &mut block, BLOCK);
        let x3 = block.x3;
        trace_block(config, &mut block);
        assert_eq!(x3.map(|r| r.map(f64::to_bits)), block.x3.map(|r| r.map(f64::to_bits)));
    }
}
