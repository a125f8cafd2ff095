//! The streamed light paths of one chunk: the hot loop of optimis.
//!
//! Each light path (docs/model.md §3) starts at x3l with density I/Φ, leaves plane 3 in a
//! cosine-distributed direction to x2l, is deflected by the plane-2 lobe and reaches plane 1 at
//! x1l. Its energy is 1 up to x2l, and sin ϑ/ϑ after the lobe (the exact-pdf throughput, see
//! [`Lobe`]). It merges with every camera vertex within R (the contributions are in
//! [`super::merge`]). Paths are never stored: each is generated, tested and dropped.
//!
//! Speed: the loop allocates nothing, takes no lock and dispatches nothing dynamically. Paths go in
//! blocks of `BLOCK` laid out as arrays, and everything that every path needs is branch-free
//! arithmetic over those arrays, which the compiler turns into SIMD code: a block of random words
//! from the multi-lane generator ([`LaneRng`]); the start points and directions in polar form (one
//! square root each, a polynomial sine and cosine from [`fastmath`], no rejection loop, so
//! no unpredictable branch); the hit on plane 2; the pixel-cone test; and the cells of the two near
//! filters (`NearFilter`, which replace the merge grids' occupancy test on the hot path). Then
//! the near-filter bits are looked up, eight paths at a time, and the few paths with any flag
//! (about 2 in 100) are handled out of line, in path order.
//!
//! On x86-64 with AVX2 and FMA the block loop is compiled a second time for those instructions
//! (with intrinsics for the generator and the bit lookups, where the compiler's own vector code is
//! poor) and chosen once per chunk. Both builds use only exactly rounded IEEE operations (fused
//! multiply-adds are written out as `mul_add`, which is exact in both), so they give the same bits:
//! results depend only on (seed, iteration, chunk), never on the machine or the thread count.
//!
//! Plane 1 needs the lobe sample, but a path whose direction misses the pixel by more than the lobe
//! can ever deflect (8.57β, see [`LOBE_MAX_SIGMAS`]) plus the angular radius of the
//! merge disc cannot hit it: that exact cone test ([`PixelCone`]) skips the lobe for most paths.
//! Once u₁ is drawn, two more exact tests (the first without a logarithm) skip the logarithm, the
//! azimuth and the trigonometry unless ϑ can still bring the path within reach.
//!
//! [`Lobe`]: crate::sim::model::scene::Lobe
//! [`fastmath`]: crate::sim::math::fastmath
//! [`LOBE_MAX_SIGMAS`]: crate::sim::model::scene::LOBE_MAX_SIGMAS
//!
//! Imports: crate::sim::engines, crate::sim::math, crate::sim::model

use nalgebra::Vector3;

mod near_filter;

use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::merge::{merge_plane1, merge_plane2, merge_plane3};
use crate::sim::engines::pixel::{PixelCone, deflect_onto_pixel, lobe_draw_below};
use crate::sim::engines::tally::{ChunkScratch, ChunkTally};
use crate::sim::math::fastmath::sincos_turn;
use crate::sim::math::rng::{LaneRng, StreamRng, stream, uniform_open0, unit52};
use crate::sim::model::config::SimConfig;
use near_filter::{NEAR_WORDS, NearFilter};

/// The bits of a path's flags: which work it needs beyond its draws. Near a camera vertex at
/// plane 3 (bit 0) or plane 2 (bit 1), or deflected by the lobe, possibly onto the pixel (bit 2).
/// The AVX2 near filter builds bits 0 and 1 as `near3 | near2 << 1`.
const NEAR_PLANE3: u32 = 1;
const NEAR_PLANE2: u32 = 1 << 1;
const MAY_REACH_PIXEL: u32 = 1 << 2;

/// Light paths per block of the chunk loop.
const BLOCK: usize = 64;
const _: () = assert!(
    BLOCK <= 128 && BLOCK.is_multiple_of(8),
    "the block's flagged paths are the bits of a u128, set 8 at a time"
);

/// One block of light paths, as arrays (structure of arrays), reused from block to block.
struct Block {
    /// Random words of each path: [0] ring and radius, [1] sin² θ of the direction, [2] the
    /// azimuths (high half: the start point's, low half: the direction's).
    bits: [[u64; BLOCK]; 3],
    /// Start points x3l.
    x3: [[f64; BLOCK]; 2],
    /// Hits x2l on plane 2.
    x2: [[f64; BLOCK]; 2],
    /// The direction as sin² θ, cos φ, sin φ.
    dir: [[f64; BLOCK]; 3],
    /// Near-filter cells of x3l and x2l.
    cells: [[u32; BLOCK]; 2],
    /// Bit 2 set if the path may reach the pixel; then, after [`flag_paths`], bit 0 if it may
    /// merge at plane 3 and bit 1 if at plane 2.
    flags: [u32; BLOCK],
}

/// Everything the loop reads, fixed for the chunk.
struct Chunk<'a> {
    config: &'a SimConfig,
    cameras: &'a CameraSet,
    cone: PixelCone,
    near3: NearFilter,
    near2: NearFilter,
}

/// Traces chunk `chunk` of iteration `iteration` and returns its tally.
///
/// Random numbers: the block words come from the [`LaneRng`] of (seed, iteration, chunk), filled
/// for a whole block at a time (also the unused tail of a chunk's last, partial block); the lobe
/// draws of the listed paths come, in path order, from the scalar stream of the same triple. So
/// the draws are fixed by (seed, iteration, chunk) and results stay deterministic.
pub fn trace_chunk(
    config: &SimConfig,
    cameras: &CameraSet,
    seed: u64,
    iteration: u64,
    chunk: u64,
    scratch: &mut ChunkScratch,
) -> ChunkTally {
    trace_chunk_with(config, cameras, seed, iteration, chunk, scratch, true)
}

/// [`trace_chunk`], with the AVX2 build of the block loop allowed or not (tests compare the two).
fn trace_chunk_with(
    config: &SimConfig,
    cameras: &CameraSet,
    seed: u64,
    iteration: u64,
    chunk: u64,
    scratch: &mut ChunkScratch,
    allow_simd: bool,
) -> ChunkTally {
    let scene = &config.scene;
    let radius = config.merge_radius;
    // Bounds on the query coordinates: starts lie within the outer radius r (up to a relative
    // 2⁻⁵¹), and tan θ ≤ 2²⁶ (sin² θ ≤ 1 − 2⁻⁵², so cos² θ ≥ 2⁻⁵²), so plane-2 hits lie within
    // r + L3·2²⁶ (up to rounding). Twice these leave room for every rounding.
    let reach3 = 2.0 * scene.illumination.outer_radius();
    let reach2 = 2.0 * (scene.illumination.outer_radius() + scene.l3 * 2f64.powi(26));
    let setup = Chunk {
        config,
        cameras,
        cone: PixelCone::new(scene.lobe.beta, scene.l2, radius),
        near3: NearFilter::new(cameras.paths.iter().filter_map(|p| p.x3), radius, reach3),
        near2: NearFilter::new(cameras.paths.iter().map(|p| p.x2), radius, reach2),
    };
    let mut lanes = LaneRng::new(seed, iteration, chunk);
    let mut rng = stream(seed, iteration, chunk);
    let mut block = Block {
        bits: [[0; BLOCK]; 3],
        x3: [[0.0; BLOCK]; 2],
        x2: [[0.0; BLOCK]; 2],
        dir: [[0.0; BLOCK]; 3],
        cells: [[0; BLOCK]; 2],
        flags: [0; BLOCK],
    };
    let paths = config.chunk_len(chunk) as usize;
    #[cfg(target_arch = "x86_64")]
    if allow_simd
        && std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("bmi1")
        && std::is_x86_feature_detected!("bmi2")
    {
        // SAFETY: the CPU has every feature `trace_blocks_avx2` is compiled for.
        unsafe { trace_blocks_avx2(&setup, &mut block, &mut lanes, &mut rng, scratch, paths) };
        return scratch.take();
    }
    let _ = allow_simd;
    trace_blocks::<false>(&setup, &mut block, &mut lanes, &mut rng, scratch, paths);
    scratch.take()
}

/// The block loop compiled for AVX2 (selected at run time; the same bits as the portable build).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2")]
fn trace_blocks_avx2(
    setup: &Chunk,
    b: &mut Block,
    lanes: &mut LaneRng,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    paths: usize,
) {
    trace_blocks::<true>(setup, b, lanes, rng, scratch, paths);
}

/// Traces `paths` light paths, block by block: random words, starts, directions and plane-2 hits
/// with the pixel-cone test and near-filter cells (all vectorised), then the near-filter bits and
/// the list of paths that may merge, then those paths. `AVX2` selects the AVX2 intrinsics of the
/// generator and of the bit lookups: it must be true only where the CPU has AVX2 (in
/// [`trace_blocks_avx2`]).
#[inline(always)]
fn trace_blocks<const AVX2: bool>(
    setup: &Chunk,
    b: &mut Block,
    lanes: &mut LaneRng,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    paths: usize,
) {
    let scene = &setup.config.scene;
    let (l2, l3) = (scene.l2, scene.l3);
    let mut remaining = paths;
    while remaining > 0 {
        let n = remaining.min(BLOCK);
        remaining -= n;

        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: AVX2 is true only in `trace_blocks_avx2`, which runs only with AVX2.
            unsafe { lanes.fill_avx2(b.bits.as_flattened_mut()) };
        } else {
            lanes.fill(b.bits.as_flattened_mut());
        }
        #[cfg(not(target_arch = "x86_64"))]
        lanes.fill(b.bits.as_flattened_mut());

        // Starts x3l on plane 3, density I/Φ.
        scene.illumination.sample_block(&b.bits[0], &b.bits[2], &mut b.x3);

        // Cosine directions (Malley's method in polar form): sin² θ uniform, φ uniform. Travel is
        // downwards, d = (sin θ cos φ, sin θ sin φ, −cos θ), and reaches plane 2 after a lateral
        // L3·tan θ (`advance(x3, d, −L3)` in polar form). cos² θ = 1 − sin² θ is exact and ≥ 2⁻⁵², so tan θ is finite.
        let [x3x, x3y] = &b.x3;
        let [x2x, x2y] = &mut b.x2;
        let [sin2, cos_phi, sin_phi] = &mut b.dir;
        let [cell3, cell2] = &mut b.cells;
        for i in 0..BLOCK {
            let s2 = unit52(b.bits[1][i]);
            let c2 = 1.0 - s2;
            let tan = (s2 / c2).sqrt();
            let (sp, cp) = sincos_turn(b.bits[2][i] as u32);
            let lateral = l3 * tan;
            let (x, y) = (lateral.mul_add(cp, x3x[i]), lateral.mul_add(sp, x3y[i]));
            x2x[i] = x;
            x2y[i] = y;
            sin2[i] = s2;
            cos_phi[i] = cp;
            sin_phi[i] = sp;
            b.flags[i] = u32::from(setup.cone.may_reach_polar(x, y, cp, sp, tan, c2, l2)) * MAY_REACH_PIXEL;
            cell3[i] = setup.near3.cell(x3x[i], x3y[i]);
            cell2[i] = setup.near2.cell(x, y);
        }

        // Camera vertices nearby? Then the few paths that may merge, in path order.
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX2 is true only in `trace_blocks_avx2`, which runs only with AVX2.
        let mut flagged = if AVX2 { unsafe { flag_paths_avx2(setup, b) } } else { flag_paths(setup, b) };
        #[cfg(not(target_arch = "x86_64"))]
        let mut flagged = flag_paths(setup, b);
        if n < BLOCK {
            flagged &= (1 << n) - 1;
        }
        let [x3x, x3y] = &b.x3;
        let [x2x, x2y] = &b.x2;
        let [sin2, cos_phi, sin_phi] = &b.dir;
        while flagged != 0 {
            let i = flagged.trailing_zeros() as usize;
            flagged &= flagged - 1;
            let (x3, x2) = ([x3x[i], x3y[i]], [x2x[i], x2y[i]]);
            // Noise components: light path k is in half k mod 2 (chunks and blocks have even
            // lengths, so i's parity is the path's), N_F/2 paths each.
            scratch.set_light_half(i);
            trace_flagged(setup, b.flags[i], x3, x2, [sin2[i], cos_phi[i], sin_phi[i]], rng, scratch);
        }
    }
}

/// Adds the near-filter bits to the block's flags and returns the mask of the paths with any flag
/// (bit i for path i).
#[inline(always)]
fn flag_paths(setup: &Chunk, b: &mut Block) -> u128 {
    let mut flagged = 0;
    for i in 0..BLOCK {
        let flags = b.flags[i]
            | (setup.near3.holds(b.cells[0][i]) * NEAR_PLANE3)
            | (setup.near2.holds(b.cells[1][i]) * NEAR_PLANE2);
        b.flags[i] = flags;
        flagged |= u128::from(flags != 0) << i;
    }
    flagged
}

/// [`flag_paths`] with AVX2 gathers for the bit lookups (the compiler does not use gathers by
/// itself), eight paths at a time; the same flags and mask.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn flag_paths_avx2(setup: &Chunk, b: &mut Block) -> u128 {
    use std::arch::x86_64::{
        __m256i, _mm256_and_si256, _mm256_castsi256_ps, _mm256_cmpgt_epi32, _mm256_i32gather_epi32, _mm256_loadu_si256,
        _mm256_movemask_ps, _mm256_or_si256, _mm256_set1_epi32, _mm256_setzero_si256, _mm256_slli_epi32,
        _mm256_srli_epi32, _mm256_srlv_epi32, _mm256_storeu_si256,
    };
    let word_mask = _mm256_set1_epi32((NEAR_WORDS - 1) as i32);
    let (bit_mask, one) = (_mm256_set1_epi32(31), _mm256_set1_epi32(1));
    // The bits of `filter` at `cells`: word cells/32, masked so the gather stays inside `words`.
    let holds = |filter: &NearFilter, cells: __m256i| {
        let index = _mm256_and_si256(_mm256_srli_epi32::<5>(cells), word_mask);
        // SAFETY: every index is < NEAR_WORDS, the length of `words`, and the scale is 4 bytes.
        let words = unsafe { _mm256_i32gather_epi32::<4>(filter.words.as_ptr().cast(), index) };
        _mm256_and_si256(_mm256_srlv_epi32(words, _mm256_and_si256(cells, bit_mask)), one)
    };
    let mut flagged = 0;
    for j in (0..BLOCK).step_by(8) {
        // SAFETY: loads and stores of 8 u32 at j ≤ BLOCK − 8 of arrays of BLOCK.
        unsafe {
            let load = |a: &[u32; BLOCK]| _mm256_loadu_si256(a.as_ptr().add(j).cast());
            let near3 = holds(&setup.near3, load(&b.cells[0]));
            let near2 = holds(&setup.near2, load(&b.cells[1]));
            let flags = _mm256_or_si256(
                load(&b.flags),
                _mm256_or_si256(near3, _mm256_slli_epi32::<1>(near2)), /* NEAR_PLANE3 | NEAR_PLANE2 */
            );
            _mm256_storeu_si256(b.flags.as_mut_ptr().add(j).cast(), flags);
            let any = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(flags, _mm256_setzero_si256())));
            flagged |= u128::from(any as u8) << j;
        }
    }
    flagged
}

/// Merges of one flagged path: candidates from the grids, exact distance tests, and, if the path
/// may reach the pixel, its lobe deflection to plane 1.
#[cold]
#[inline(never)]
fn trace_flagged(
    setup: &Chunk,
    flags: u32,
    x3: [f64; 2],
    x2: [f64; 2],
    [sin2, cos_phi, sin_phi]: [f64; 3],
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
) {
    let (config, cameras) = (setup.config, setup.cameras);
    let sin_theta = sin2.sqrt();
    let d = Vector3::new(sin_theta * cos_phi, sin_theta * sin_phi, -(1.0 - sin2).sqrt());
    if flags & NEAR_PLANE3 != 0 {
        merge_plane3(config, cameras, cameras.plane3.candidates(x3), x3, scratch);
    }
    if flags & NEAR_PLANE2 != 0 {
        merge_plane2(config, cameras, cameras.plane2.candidates(x2), x2, x3, &d, scratch);
    }
    if flags & MAY_REACH_PIXEL != 0 {
        // The lobe draw of `sample_lobe` (ϑ = β·√(−2 ln u₁), azimuth 2πu₂), with the logarithm,
        // the azimuth and the deflection skipped when ϑ cannot bring the path within R of the
        // pixel: the outcome (no merge) does not depend on them.
        let (l2, beta) = (config.scene.l2, config.scene.lobe.beta);
        let theta_min = setup.cone.min_deflection(x2[0], x2[1], &d, l2);
        let u1 = uniform_open0(rng);
        if lobe_draw_below(u1, theta_min, beta) {
            return;
        }
        let theta = beta * (-2.0 * libm::log(u1)).sqrt();
        if theta < theta_min {
            return;
        }
        if deflect_onto_pixel(config, &d, x2, theta, rng).is_some() {
            merge_plane1(config, theta, x2, x3, scratch);
        }
    }
}

#[cfg(test)]
mod tests;
