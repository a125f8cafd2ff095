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
//! from the multi-lane generator ([`LaneRng`]); then, in single precision (eight paths to a
//! 256-bit vector), the start points and directions in polar form (one square root each, a
//! polynomial sine and cosine from [`fastmath`], no rejection loop, so no unpredictable branch),
//! the hit on plane 2, a pixel-cone test and the cells of the two near filters — the conservative
//! filter of `filter32`, whose margins cover every f32 rounding. Then the near-filter bits are
//! looked up, eight paths at a time, and the few candidates (about 2 paths in 100) are handled out
//! of line, in path order: each is recomputed in f64 from its random words by the original
//! expressions (`ExactPath`), the exact tests decide (the pixel cone, and the f64 near filters,
//! `NearFilter`, which replace the merge grids' occupancy test), and the paths they flag are
//! traced. So the f32 stage only decides which paths are looked at; every value that reaches a
//! tally, and every draw of the scalar stream, is that of the exact path.
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

mod filter32;
mod near_filter;

use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::merge::{merge_plane1, merge_plane2, merge_plane3};
use crate::sim::engines::pixel::{PixelCone, deflect_onto_pixel, lobe_draw_below};
use crate::sim::engines::tally::{ChunkScratch, ChunkTally};
use crate::sim::math::fastmath::sincos_turn;
use crate::sim::math::rng::{LaneRng, StreamRng, stream, uniform_open0, unit52};
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::Scene;
use filter32::{Filter32, Inputs};
use near_filter::{NEAR_WORDS, NearFilter};

/// The bits of a path's flags: which work it needs beyond its draws. Near a camera vertex at
/// plane 3 (bit 0) or plane 2 (bit 1), or deflected by the lobe, possibly onto the pixel (bit 2).
const NEAR_PLANE3: u32 = 1;
const NEAR_PLANE2: u32 = 1 << 1;
const MAY_REACH_PIXEL: u32 = 1 << 2;

/// The bit of [`Block::candidate`] that marks a candidate (the sign bit, which the AVX2 lookup
/// collects with one `movemask`).
const CANDIDATE: u32 = 1 << 31;

/// Light paths per block of the chunk loop.
const BLOCK: usize = 64;
const _: () =
    assert!(BLOCK <= 64 && BLOCK.is_multiple_of(8), "the block's candidates are the bits of a u64, set 8 at a time");

/// One block of light paths, as arrays (structure of arrays), reused from block to block.
struct Block {
    /// Random words of each path: [0] ring and radius, [1] sin² θ of the direction, [2] the
    /// azimuths (high half: the start point's, low half: the direction's).
    bits: [[u64; BLOCK]; 3],
    /// Squared start radii r², exact (the f64 sampler's).
    r2: [f64; BLOCK],
    /// The f32 filter's inputs, as arrays: fl₃₂(r²), fl₃₂(sin² θ), fl₃₂(cos² θ), the azimuths.
    r2_32: [f32; BLOCK],
    sin2: [f32; BLOCK],
    cos2: [f32; BLOCK],
    azimuths: [[u32; BLOCK]; 2],
    /// Cells of the f32 start and plane-2 hit in the f32 near filters.
    cells: [[u32; BLOCK]; 2],
    /// [`CANDIDATE`] if the f32 filter passes the path without the near filters (pixel cone, or
    /// too steep to bound), else 0.
    candidate: [u32; BLOCK],
    /// Every path in f64, for chunks whose f32 filter cannot screen ([`exact_block`]).
    exact: ExactBlock,
}

/// A whole block's paths in f64 (the fields of [`ExactPath`] that the merges read, as arrays, so
/// that the loop filling them vectorises) and their exact flags.
struct ExactBlock {
    x3: [[f64; BLOCK]; 2],
    x2: [[f64; BLOCK]; 2],
    /// sin² θ, cos φ, sin φ.
    dir: [[f64; BLOCK]; 3],
    flags: [u32; BLOCK],
}

/// Everything the loop reads, fixed for the chunk.
struct Chunk<'a> {
    config: &'a SimConfig,
    cameras: &'a CameraSet,
    /// The exact tests of the candidates.
    cone: PixelCone,
    near3: NearFilter,
    near2: NearFilter,
    /// The block loop's conservative f32 filter.
    filter: Filter32,
    /// Whether the f32 filter is used at all: not when its cone test passes every path (see
    /// [`Filter32::screens`]), where computing each path in f32 and then again in f64, one at a
    /// time, would cost more than computing every path in f64, a vector at a time ([`exact_block`]).
    screen: bool,
}

impl<'a> Chunk<'a> {
    /// The tests and filters of a chunk of `config` with the camera paths `cameras`.
    fn new(config: &'a SimConfig, cameras: &'a CameraSet) -> Self {
        let scene = &config.scene;
        let radius = config.merge_radius;
        // Bounds on the query coordinates: starts lie within the outer radius r (up to a relative
        // 2⁻⁵¹), and tan θ ≤ 2²⁶ (sin² θ ≤ 1 − 2⁻⁵², so cos² θ ≥ 2⁻⁵²), so plane-2 hits lie within
        // r + L3·2²⁶ (up to rounding). Twice these leave room for every rounding.
        let reach3 = 2.0 * scene.illumination.outer_radius();
        let reach2 = 2.0 * (scene.illumination.outer_radius() + scene.l3 * 2f64.powi(26));
        let cone = PixelCone::new(scene.lobe.beta, scene.l2, radius);
        let filter = Filter32::new(config, cameras, &cone);
        Chunk {
            config,
            cameras,
            cone,
            near3: NearFilter::new(cameras.paths.iter().filter_map(|p| p.x3), radius, reach3),
            near2: NearFilter::new(cameras.paths.iter().map(|p| p.x2), radius, reach2),
            screen: filter.screens(),
            filter,
        }
    }
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
    let setup = Chunk::new(config, cameras);
    let mut lanes = LaneRng::new(seed, iteration, chunk);
    let mut rng = stream(seed, iteration, chunk);
    let mut block = Block::new();
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
    trace_blocks::<false>(&setup, &mut block, |out| lanes.fill(out), &mut rng, scratch, paths);
    scratch.take()
}

/// The block loop compiled for AVX2 (selected at run time; the same bits as the portable build).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2")]
fn trace_blocks_avx2(
    setup: &Chunk<'_>,
    b: &mut Block,
    lanes: &mut LaneRng,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    paths: usize,
) {
    // The generator's fill is handed in as a closure made here (which has this function's target
    // features, so the call is safe): called directly from inside `trace_blocks`, rustc inlines it
    // despite its `#[inline(never)]`, and its state then competes for registers with the f32
    // filter's constants (and was spilled to the stack, step by step).
    trace_blocks::<true>(setup, b, |out| lanes.fill_avx2(out), rng, scratch, paths);
}

/// Traces `paths` light paths, block by block: random words (from `fill`, the chunk's
/// [`LaneRng`]), then the f32 filter (starts, directions, plane-2 hits, pixel cone and near-filter
/// cells, all vectorised), the near-filter bits and the list of candidates, then those candidates,
/// exactly. `AVX2` selects the AVX2 intrinsics of the bit lookups: it must be true only where the
/// CPU has AVX2 (in [`trace_blocks_avx2`]).
#[inline(always)]
fn trace_blocks<const AVX2: bool>(
    setup: &Chunk<'_>,
    b: &mut Block,
    mut fill: impl FnMut(&mut [u64]),
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    paths: usize,
) {
    let scene = &setup.config.scene;
    let filter = &setup.filter;
    let mut remaining = paths;
    while remaining > 0 {
        let n = remaining.min(BLOCK);
        remaining -= n;

        // The block's paths in use (a chunk's last block may be partial).
        let in_use = if n < BLOCK { (1 << n) - 1 } else { u64::MAX };

        fill(b.bits.as_flattened_mut());
        if !setup.screen {
            let mut flagged = exact_block(setup, b) & in_use;
            while flagged != 0 {
                let i = flagged.trailing_zeros() as usize;
                flagged &= flagged - 1;
                let e = &b.exact;
                let (x3, x2) = ([e.x3[0][i], e.x3[1][i]], [e.x2[0][i], e.x2[1][i]]);
                scratch.set_light_half(i);
                trace_flagged(setup, e.flags[i], x3, x2, [e.dir[0][i], e.dir[1][i], e.dir[2][i]], rng, scratch);
            }
            continue;
        }
        filter_block(setup, b);

        // Camera vertices nearby? Then the few candidates, in path order.
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX2 is true only in `trace_blocks_avx2`, which runs only with AVX2.
        let mut candidates = if AVX2 { unsafe { candidates_avx2(filter, b) } } else { candidates(filter, b) };
        #[cfg(not(target_arch = "x86_64"))]
        let mut candidates = candidates(filter, b);
        candidates &= in_use;
        while candidates != 0 {
            let i = candidates.trailing_zeros() as usize;
            candidates &= candidates - 1;
            let path = ExactPath::new(scene, [b.bits[0][i], b.bits[1][i], b.bits[2][i]]);
            let flags = path.flags(setup);
            if flags != 0 {
                // Noise components: light path k is in half k mod 2 (chunks and blocks have even
                // lengths, so i's parity is the path's), N_F/2 paths each (in both modes).
                scratch.set_light_half(i);
                trace_flagged(setup, flags, path.x3, path.x2, [path.sin2, path.cos_phi, path.sin_phi], rng, scratch);
            }
        }
    }
}

/// The f32 filter of the block's paths: starts x3l with density I/Φ (their r² exactly, the rest
/// in f32), cosine directions and plane-2 hits, the pixel-cone test and the near-filter cells (see
/// [`Filter32::path`]).
#[inline(always)]
fn filter_block(setup: &Chunk<'_>, b: &mut Block) {
    setup.config.scene.illumination.radius2_block(&b.bits[0], &mut b.r2);
    for i in 0..BLOCK {
        let p = Filter32::inputs(b.r2[i], b.bits[1][i], b.bits[2][i]);
        (b.r2_32[i], b.sin2[i], b.cos2[i]) = (p.r2, p.sin2, p.cos2);
        (b.azimuths[0][i], b.azimuths[1][i]) = (p.azimuth3, p.azimuth2);
    }
    let [cell3, cell2] = &mut b.cells;
    for i in 0..BLOCK {
        let p = Inputs {
            r2: b.r2_32[i],
            sin2: b.sin2[i],
            cos2: b.cos2[i],
            azimuth3: b.azimuths[0][i],
            azimuth2: b.azimuths[1][i],
        };
        let (c3, c2, candidate) = setup.filter.path(p);
        cell3[i] = c3;
        cell2[i] = c2;
        b.candidate[i] = u32::from(candidate) * CANDIDATE;
    }
}

/// Every path of the block in f64 ([`ExactPath`], its starts drawn for the whole block at once)
/// with its exact flags; returns the mask of the flagged paths (bit i for path i). For chunks
/// whose f32 filter would pass every path ([`Chunk::screen`] false).
#[inline(always)]
fn exact_block(setup: &Chunk<'_>, b: &mut Block) -> u64 {
    let scene = &setup.config.scene;
    let e = &mut b.exact;
    scene.illumination.sample_block(&b.bits[0], &b.bits[2], &mut e.x3);
    for i in 0..BLOCK {
        let p = ExactPath::from_start(scene, [e.x3[0][i], e.x3[1][i]], b.bits[1][i], b.bits[2][i]);
        e.flags[i] = p.flags(setup);
        [e.x2[0][i], e.x2[1][i]] = p.x2;
        [e.dir[0][i], e.dir[1][i], e.dir[2][i]] = [p.sin2, p.cos_phi, p.sin_phi];
    }
    let mut mask = 0;
    for (i, &flags) in e.flags.iter().enumerate() {
        mask |= u64::from(flags != 0) << i;
    }
    mask
}

impl Block {
    fn new() -> Self {
        Self {
            bits: [[0; BLOCK]; 3],
            r2: [0.0; BLOCK],
            r2_32: [0.0; BLOCK],
            sin2: [0.0; BLOCK],
            cos2: [0.0; BLOCK],
            azimuths: [[0; BLOCK]; 2],
            cells: [[0; BLOCK]; 2],
            candidate: [0; BLOCK],
            exact: ExactBlock {
                x3: [[0.0; BLOCK]; 2],
                x2: [[0.0; BLOCK]; 2],
                dir: [[0.0; BLOCK]; 3],
                flags: [0; BLOCK],
            },
        }
    }
}

/// One light path in f64, from its random words (ring and radius, sin² θ, the azimuths): the
/// values that reach the merges, by the expressions the brute force has always used.
struct ExactPath {
    /// Start x3l.
    x3: [f64; 2],
    /// Hit x2l on plane 2.
    x2: [f64; 2],
    /// The direction as sin² θ, cos φ, sin φ, with tan θ and cos² θ for the cone test.
    sin2: f64,
    cos_phi: f64,
    sin_phi: f64,
    tan: f64,
    cos2: f64,
}

impl ExactPath {
    /// The path of the words `bits`.
    ///
    /// Starts x3l on plane 3, density I/Φ ([`Illumination::sample_block`]). Cosine directions
    /// (Malley's method in polar form): sin² θ uniform, φ uniform. Travel is downwards, d = (sin θ
    /// cos φ, sin θ sin φ, −cos θ), and reaches plane 2 after a lateral L3·tan θ
    /// (`advance(x3, d, −L3)` in polar form). cos² θ = 1 − sin² θ is exact and ≥ 2⁻⁵², so tan θ is
    /// finite.
    ///
    /// [`Illumination::sample_block`]: crate::sim::model::illumination::Illumination::sample_block
    #[inline(always)]
    fn new(scene: &Scene, bits: [u64; 3]) -> Self {
        let mut start = [[0.0; 1]; 2];
        scene.illumination.sample_block(&[bits[0]], &[bits[2]], &mut start);
        Self::from_start(scene, [start[0][0], start[1][0]], bits[1], bits[2])
    }

    /// The path from its start `x3` (drawn from the ring word and the azimuth word's high half),
    /// its direction word `dir_bits` (sin² θ) and its azimuth word (low half: φ).
    #[inline(always)]
    fn from_start(scene: &Scene, x3: [f64; 2], dir_bits: u64, azimuth_bits: u64) -> Self {
        let sin2 = unit52(dir_bits);
        let cos2 = 1.0 - sin2;
        let tan = (sin2 / cos2).sqrt();
        let (sin_phi, cos_phi) = sincos_turn(azimuth_bits as u32);
        let lateral = scene.l3 * tan;
        let x2 = [lateral.mul_add(cos_phi, x3[0]), lateral.mul_add(sin_phi, x3[1])];
        Self { x3, x2, sin2, cos_phi, sin_phi, tan, cos2 }
    }

    /// The exact tests: may it reach the pixel, is a camera vertex near its start or its hit.
    #[inline(always)]
    fn flags(&self, setup: &Chunk<'_>) -> u32 {
        let l2 = setup.config.scene.l2;
        let [x2, y2] = self.x2;
        let reach = setup.cone.may_reach_polar(x2, y2, self.cos_phi, self.sin_phi, self.tan, self.cos2, l2);
        (u32::from(reach) * MAY_REACH_PIXEL)
            | (setup.near3.holds(setup.near3.cell(self.x3[0], self.x3[1])) * NEAR_PLANE3)
            | (setup.near2.holds(setup.near2.cell(x2, y2)) * NEAR_PLANE2)
    }
}

/// The mask of the block's candidates (bit i for path i): the f32 filter's own verdict, or a
/// camera vertex possibly near the f32 start or hit.
#[inline(always)]
fn candidates(filter: &Filter32, b: &Block) -> u64 {
    let mut mask = 0;
    for i in 0..BLOCK {
        let near = filter.near3.holds(b.cells[0][i]) | filter.near2.holds(b.cells[1][i]);
        mask |= u64::from((b.candidate[i] >> 31) | near) << i;
    }
    mask
}

/// [`candidates`] with AVX2 gathers for the bit lookups (the compiler does not use gathers by
/// itself), eight paths at a time; the same mask. Each gathered word is shifted left so that the
/// cell's bit lands in the sign bit (by 31 − cell mod 32, i.e. !cell mod 32), where the candidate
/// flag already is, and one `movemask` collects the eight paths: no shift back, no compare.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn candidates_avx2(filter: &Filter32, b: &Block) -> u64 {
    use std::arch::x86_64::{
        __m256i, _mm256_andnot_si256, _mm256_castsi256_ps, _mm256_i32gather_epi32, _mm256_loadu_si256,
        _mm256_movemask_ps, _mm256_or_si256, _mm256_set1_epi32, _mm256_sllv_epi32, _mm256_srli_epi32,
    };
    let bit_mask = _mm256_set1_epi32(31);
    // The bits of `words` at `cells`, in the sign bits: word cells/32 (< NEAR_WORDS, as cells are
    // below 2¹⁶), shifted left by 31 − cells mod 32.
    let holds = |words: &[u32; NEAR_WORDS], cells: __m256i| {
        // SAFETY: every index is < 2¹¹ = NEAR_WORDS, the length of `words`, and the scale is 4 bytes.
        let words = unsafe { _mm256_i32gather_epi32::<4>(words.as_ptr().cast(), _mm256_srli_epi32::<5>(cells)) };
        _mm256_sllv_epi32(words, _mm256_andnot_si256(cells, bit_mask))
    };
    let mut mask = 0;
    for j in (0..BLOCK).step_by(8) {
        // SAFETY: loads of 8 u32 at j ≤ BLOCK − 8 of arrays of BLOCK.
        unsafe {
            let load = |a: &[u32; BLOCK]| _mm256_loadu_si256(a.as_ptr().add(j).cast());
            let near3 = holds(&filter.near3.words, load(&b.cells[0]));
            let near2 = holds(&filter.near2.words, load(&b.cells[1]));
            let any = _mm256_or_si256(load(&b.candidate), _mm256_or_si256(near3, near2));
            mask |= u64::from(_mm256_movemask_ps(_mm256_castsi256_ps(any)) as u8) << j;
        }
    }
    mask
}

/// Merges of one flagged path: candidates from the grids, exact distance tests, and, if the path
/// may reach the pixel, its lobe deflection to plane 1.
#[cold]
#[inline(never)]
fn trace_flagged(
    setup: &Chunk<'_>,
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
        if let Some(x1) = deflect_onto_pixel(config, &d, x2, theta, rng) {
            merge_plane1(config, theta, x1, x2, x3, scratch);
        }
    }
}

#[cfg(test)]
mod tests;
