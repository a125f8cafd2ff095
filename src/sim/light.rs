//! The streamed light paths of one chunk: the hot loop of optimis.
//!
//! Each light path (model.md) starts at x3l with density I/Φ, leaves plane 3 in a cosine-distributed
//! direction to x2l, is deflected by the plane-2 lobe and reaches plane 1 at x1l. Its energy is 1
//! up to x2l, and sin ϑ/ϑ after the lobe (the exact-pdf throughput, see [`super::scene::Lobe`]).
//! It merges with every camera vertex within R (the contributions are in [`super::merge`]). Paths
//! are never stored: each is generated, tested and dropped.
//!
//! Speed: the loop allocates nothing, takes no lock and dispatches nothing dynamically. Paths go in
//! blocks of `BLOCK` laid out as arrays, and everything that every path needs is branch-free
//! arithmetic over those arrays, which the compiler turns into SIMD code: a block of random words
//! from the multi-lane generator ([`LaneRng`]); the start points and directions in polar form (one
//! square root each, a polynomial sine and cosine from [`super::fastmath`], no rejection loop, so
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
//! can ever deflect (8.57β, see [`super::sampling::LOBE_MAX_SIGMAS`]) plus the angular radius of the
//! merge disc cannot hit it: that exact cone test ([`PixelCone`]) skips the lobe for most paths.
//! Once u₁ is drawn, two more exact tests (the first without a logarithm) skip the logarithm, the
//! azimuth and the trigonometry unless ϑ can still bring the path within reach.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;

use super::camera::CameraSet;
use super::config::SimConfig;
use super::fastmath::sincos_turn;
use super::merge::{merge_plane1, merge_plane2, merge_plane3};
use super::rng::{LaneRng, StreamRng, stream, uniform, uniform_open0, unit52};
use super::sampling::{LOBE_MAX_SIGMAS, deflect};
use super::tally::{ChunkScratch, ChunkTally};

/// Constants of the light-path loop's pixel tests, derived once per configuration.
#[derive(Debug, Clone, Copy)]
pub struct PixelCone {
    /// c·|c| for c = cos of the widest angle between a path's incident direction at x2l and the
    /// direction to the pixel for which the path can still land within R of the pixel (c = −2,
    /// below any cosine, when that angle reaches π and every path must sample the lobe).
    c_abs_c: f64,
    /// δ = asin(R/L2): the largest angle between the direction to the pixel and a direction from
    /// plane 2 into the merge disc.
    delta: f64,
}

/// Relative margin on the angles of the pixel tests, far larger than any rounding error.
const CONE_MARGIN: f64 = 1e-6;

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
        let delta = (radius / l2).asin();
        let reach = (LOBE_MAX_SIGMAS * beta + delta) * (1.0 + CONE_MARGIN);
        let c = if reach >= PI { -2.0 } else { reach.cos() };
        Self { c_abs_c: c * c.abs(), delta }
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

    /// [`PixelCone::may_reach`] for the direction d = (sin θ cos φ, sin θ sin φ, −cos θ) given as
    /// cos φ, sin φ, tan θ and cos² θ, as the loop has it (so it needs no square root).
    ///
    /// With D = L2 − tan θ·(x cos φ + y sin φ), d·t = cos θ·D, so (d·t)|d·t| = cos² θ·D|D| and the
    /// test is the same inequality scaled by a positive factor. Its rounding differs from
    /// `may_reach`'s by a few ulps of |t|², far inside the cone's 10⁻⁶ margin.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn may_reach_polar(&self, x: f64, y: f64, cos_phi: f64, sin_phi: f64, tan: f64, cos2: f64, l2: f64) -> bool {
        let dot = (-tan).mul_add(x.mul_add(cos_phi, y * sin_phi), l2);
        let t2 = x.mul_add(x, y.mul_add(y, l2 * l2));
        cos2 * (dot * dot.abs()) >= self.c_abs_c * t2
    }

    /// Whether a path at (`x`, `y`) on plane 2 with unit incident direction `d` (d.z < 0) can land
    /// within R of the pixel after a lobe deflection of exactly `theta`, whatever its azimuth: iff
    /// `theta` ≥ [`PixelCone::min_deflection`].
    #[inline]
    pub fn may_deflect_to_pixel(&self, x: f64, y: f64, d: &Vector3<f64>, theta: f64, l2: f64) -> bool {
        theta >= self.min_deflection(x, y, d, l2)
    }

    /// A lower bound on the lobe deflection a path at (`x`, `y`) on plane 2 with unit incident
    /// direction `d` (d.z < 0) needs to land within R of the pixel (≤ 0 when it may need none).
    ///
    /// Proof: landing within R needs angle(d', t) ≤ δ (see [`PixelCone::new`]) and angle(d, d') = ϑ,
    /// so α = angle(d, t) ≤ ϑ + δ =: A. As 1 − cos α = 2 sin²(α/2) ≤ α²/2 for all α, a hit needs
    /// A ≥ α ≥ √(2(1 − cos α)), i.e. ϑ ≥ √(2(1 − d·t/|t|)) − δ. The bound returned is smaller: 10⁻¹²
    /// is taken off 1 − cos α (whose rounding error is a few 10⁻¹⁶) and the result is divided by
    /// 1 + 10⁻⁶, the cone's margin.
    #[inline]
    pub fn min_deflection(&self, x: f64, y: f64, d: &Vector3<f64>, l2: f64) -> f64 {
        let cos_alpha = (-d.x * x - d.y * y - d.z * l2) / (x * x + y * y + l2 * l2).sqrt();
        let one_minus_cos = (1.0 - cos_alpha - 1e-12).max(0.0);
        (2.0 * one_minus_cos).sqrt() / (1.0 + CONE_MARGIN) - self.delta
    }
}

/// Whether the lobe draw ϑ = β·√(−2 ln u₁) is certainly below `theta_min`, decided without a
/// logarithm (a necessary test before the exact one, which settles most paths cheaply).
///
/// ϑ ≥ ϑ_min needs u₁ ≤ e^(−y) with y = (ϑ_min/β)²/2. Since e^y > 1 + y + y²/2 + y³/6 + y⁴/24 =: p(y)
/// for y > 0, u₁·p(y) > 1 implies u₁ > e^(−y), so ϑ < ϑ_min; the threshold 1 + 10⁻⁹ absorbs the
/// rounding of u₁·p(y).
#[inline]
fn lobe_draw_below(u1: f64, theta_min: f64, beta: f64) -> bool {
    if theta_min <= 0.0 {
        return false;
    }
    let y = 0.5 * (theta_min / beta) * (theta_min / beta);
    let p = 1.0 + y * (1.0 + y / 2.0 * (1.0 + y / 3.0 * (1.0 + y / 4.0)));
    u1 * p > 1.0 + 1e-9
}

/// Bits per axis of a [`NearFilter`]'s cell index: 2⁸ × 2⁸ cells, periodic.
const NEAR_AXIS_BITS: u32 = 8;
const NEAR_AXIS_MASK: u64 = (1 << NEAR_AXIS_BITS) - 1;
/// The filter's 2¹⁶ bits as 32-bit words (the width AVX2 gathers): 8 KiB, so both planes' filters
/// stay in L1.
const NEAR_WORDS: usize = 1 << (2 * NEAR_AXIS_BITS - 5);

/// Which light points may lie within R of a camera vertex on one plane: a bitmap over cells of
/// side 2R (or more, see below), folded periodically onto 2⁸ × 2⁸ cells, built per chunk from the
/// camera vertices.
///
/// It answers the question of [`super::grid::MergeGrid::may_hold`], but its cell index is computed
/// with floating-point operations and integer masks only (no 64-bit multiply or float → integer
/// conversion, which AVX2 lacks), so it vectorises with the rest of the block, and the bit lookups
/// are AVX2 gathers where available. False positives (≈ 0.6% per plane at the paper's parameters,
/// from the folding) cost a look at the grid, never a result: the merge functions do the exact
/// distance test on the grid's candidates.
///
/// Why it is conservative: with h the cell side, the cell coordinate of x is n(x) =
/// round(clamp(x/h, ±2⁵⁰)), a non-decreasing function of x. A camera vertex c marks every cell from
/// n(c − m) to n(c + m), with m = R(1 + 10⁻⁹) + |c|·2⁻⁵⁰ (the exact test |x − c| ≤ R passes in
/// floating point only for |x − c| ≤ R(1 + 3·2⁻⁵³), and m also absorbs the rounding of c ± m), so
/// every x within R of c falls in a marked cell; folding maps query and vertex cells alike. Queries
/// skip the clamp, which saves two instructions per coordinate: every query coordinate is bounded
/// by the filter's `reach`, and h ≥ reach·2⁻⁴⁸, so |x/h| ≤ 2⁴⁸ and the clamp would change nothing.
struct NearFilter {
    inv_cell: f64,
    words: [u32; NEAR_WORDS],
}

/// x/h rounded to an integer n, as the bits of n + 1.5·2⁵² (whose low 51 bits are n in two's
/// complement for |n| ≤ 2⁵⁰): adding 1.5·2⁵² rounds to an integer without a conversion instruction.
/// For |x/h| ≤ 2⁵⁰ only; [`near_axis_clamped`] takes any x.
#[inline(always)]
fn near_axis(x: f64, inv_cell: f64) -> u64 {
    (x * inv_cell + NEAR_ROUNDER).to_bits()
}

/// [`near_axis`] of x/h clamped to ±2⁵⁰ (equal to it wherever it applies).
fn near_axis_clamped(x: f64, inv_cell: f64) -> u64 {
    const LIMIT: f64 = (1u64 << 50) as f64;
    ((x * inv_cell).clamp(-LIMIT, LIMIT) + NEAR_ROUNDER).to_bits()
}

const NEAR_ROUNDER: f64 = 1.5 * (1u64 << 52) as f64;

impl NearFilter {
    /// The filter of the vertices `points` for merge radius `radius`, to be queried only at
    /// points whose coordinates are at most `reach` in absolute value.
    fn new(points: impl Iterator<Item = [f64; 2]>, radius: f64, reach: f64) -> Self {
        let inv_cell = 1.0 / (2.0 * radius).max(reach * 2f64.powi(-48));
        let mut words = [0; NEAR_WORDS];
        // The unfolded cell range [n(c − m), n(c + m)] of one coordinate, capped at one period.
        let range = |c: f64| {
            let m = radius * (1.0 + 1e-9) + c.abs() * 2f64.powi(-50);
            let cell = |x: f64| near_axis_clamped(x, inv_cell).wrapping_sub(NEAR_ROUNDER.to_bits());
            let (lo, hi) = (cell(c - m), cell(c + m));
            let len = hi.wrapping_sub(lo).min(NEAR_AXIS_MASK);
            (0..=len).map(move |k| lo.wrapping_add(k) & NEAR_AXIS_MASK)
        };
        for [x, y] in points {
            for ix in range(x) {
                for iy in range(y) {
                    let cell = ix | (iy << NEAR_AXIS_BITS);
                    words[(cell >> 5) as usize] |= 1 << (cell & 31);
                }
            }
        }
        Self { inv_cell, words }
    }

    /// The folded cell of (`x`, `y`), in [0, 2¹⁶).
    #[inline(always)]
    fn cell(&self, x: f64, y: f64) -> u32 {
        let (ix, iy) = (near_axis(x, self.inv_cell), near_axis(y, self.inv_cell));
        ((ix & NEAR_AXIS_MASK) | ((iy & NEAR_AXIS_MASK) << NEAR_AXIS_BITS)) as u32
    }

    /// 1 if a camera vertex may lie within R of a point of `cell`, else 0.
    #[inline(always)]
    fn holds(&self, cell: u32) -> u32 {
        let word = self.words[(cell as usize >> 5) & (NEAR_WORDS - 1)];
        (word >> (cell & 31)) & 1
    }
}

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
        // L3·tan θ. cos² θ = 1 − sin² θ is exact and ≥ 2⁻⁵², so tan θ is finite.
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
            b.flags[i] = u32::from(setup.cone.may_reach_polar(x, y, cp, sp, tan, c2, l2)) << 2;
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
        let flags = b.flags[i] | setup.near3.holds(b.cells[0][i]) | (setup.near2.holds(b.cells[1][i]) << 1);
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
            let flags = _mm256_or_si256(load(&b.flags), _mm256_or_si256(near3, _mm256_slli_epi32::<1>(near2)));
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
    if flags & 1 != 0 {
        merge_plane3(config, cameras, cameras.plane3.candidates(x3), x3, scratch);
    }
    if flags & 2 != 0 {
        merge_plane2(config, cameras, cameras.plane2.candidates(x2), x2, x3, &d, scratch);
    }
    if flags & 4 != 0 {
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
        let out = deflect(&d, theta, TAU * uniform(rng));
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
    use crate::sim::spec::parse_job_spec;

    /// The cone tests must never skip a path that can hit the pixel disc: for random x2 near the
    /// axis and directions aimed near the pixel, any deflection within the lobe's bound that lands
    /// in the disc must come from a direction the cone admits (in both forms), and its deflection
    /// angle must pass `may_deflect_to_pixel`.
    #[test]
    fn pixel_cone_never_rejects_a_possible_hit() {
        let beta = 3f64.to_radians();
        let (l2, r) = (1.0, 0.05);
        let cone = PixelCone::new(beta, l2, r);
        let mut rng = stream(9, 9, 9);
        let (mut hits, mut skipped) = (0, 0);
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
            let theta = u(&mut rng) * LOBE_MAX_SIGMAS * beta;
            let out = deflect(&d, theta, u(&mut rng) * std::f64::consts::TAU);
            let deflect_ok = cone.may_deflect_to_pixel(x2[0], x2[1], &d, theta, l2);
            skipped += usize::from(!deflect_ok);
            if out.z >= 0.0 {
                continue;
            }
            let x1 = [x2[0] - l2 * out.x / out.z, x2[1] - l2 * out.y / out.z];
            if x1[0].hypot(x1[1]) <= r {
                hits += 1;
                assert!(cone.may_reach(x2[0], x2[1], d.x, d.y, -d.z, l2), "cone rejected a hit at {x2:?}");
                let sin_t = d.x.hypot(d.y);
                let (cos_phi, sin_phi) = (d.x / sin_t, d.y / sin_t);
                let (tan, cos2) = (sin_t / -d.z, d.z * d.z);
                assert!(cone.may_reach_polar(x2[0], x2[1], cos_phi, sin_phi, tan, cos2, l2), "polar cone, {x2:?}");
                assert!(deflect_ok, "deflection test rejected a hit at {x2:?}, ϑ = {theta}");
            }
        }
        assert!(hits > 100, "the test must exercise hits ({hits})");
        assert!(skipped > 10_000, "the deflection test must also reject ({skipped})");
        // And it does reject: a direction pointing away from the pixel.
        let away = Vector3::new(0.9, 0.0, -0.1).normalize();
        assert!(!cone.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
        assert!(!cone.may_reach_polar(0.0, 0.0, 1.0, 0.0, 9.0, away.z * away.z, l2));
        // A lobe so wide that every path may reach the pixel.
        let wide = PixelCone::new(45f64.to_radians(), l2, r);
        assert!(wide.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
        assert!(wide.may_reach_polar(0.0, 0.0, 1.0, 0.0, 9.0, away.z * away.z, l2));
        assert!(wide.may_deflect_to_pixel(0.0, 0.0, &away, 3.0, l2));
    }

    /// The logarithm-free test never rejects a draw that reaches the bound, and settles most draws
    /// that do not.
    #[test]
    fn lobe_draw_below_is_conservative() {
        let beta = 3f64.to_radians();
        let mut rng = stream(5, 6, 7);
        let (mut below, mut settled) = (0, 0);
        for _ in 0..1_000_000 {
            let u1 = uniform_open0(&mut rng);
            let theta_min = (uniform(&mut rng) * 10.0 - 1.0) * beta;
            let theta = beta * (-2.0 * libm::log(u1)).sqrt();
            if lobe_draw_below(u1, theta_min, beta) {
                assert!(theta < theta_min, "u₁ = {u1}, ϑ = {theta} ≥ ϑ_min = {theta_min}");
                settled += 1;
            }
            below += usize::from(theta < theta_min);
        }
        assert!(settled > below * 7 / 10, "{settled} of {below} settled without a logarithm");
    }

    /// The near filter must hold every point within R of a vertex (the exact test of the merges
    /// is the reference), near the origin, far out, and at huge coordinates, both with cells of
    /// side 2R and with the wider cells of a huge reach; and it must reject most points far from
    /// every vertex.
    #[test]
    fn near_filter_never_misses_a_vertex() {
        let r = 0.003;
        let mut rng = stream(2, 3, 4);
        let mut u = || crate::sim::rng::uniform(&mut rng) * 2.0 - 1.0;
        let vertices: Vec<[f64; 2]> = (0..300)
            .map(|j| {
                let scale = [0.05, 3.0, 1e3, 1e9, 1e17][j % 5];
                [u() * scale, u() * scale]
            })
            .collect();
        let modest = |c: &&[f64; 2]| c[0].abs().max(c[1].abs()) <= 1e3;
        // Cells of side 2R, queried within 2·10³ (vertices beyond it are out of reach)…
        let near_filter = NearFilter::new(vertices.iter().copied(), r, 2e3);
        // …and cells of side 10¹⁸·2⁻⁴⁸ ≈ 3553, for queries anywhere within 10¹⁸.
        let far_filter = NearFilter::new(vertices.iter().copied(), r, 1e18);
        let mut near = 0;
        for (j, c) in vertices.iter().enumerate() {
            for _ in 0..2000 {
                // Points in and around the vertex's disc, some exactly on its rim.
                let (a, s) = (u() * PI, if j % 2 == 0 { 1.0 } else { u().abs() * 1.2 });
                let p = [c[0] + r * s * a.cos(), c[1] + r * s * a.sin()];
                if crate::sim::merge::within(p, *c, r) {
                    near += 1;
                    let far = far_filter.holds(far_filter.cell(p[0], p[1]));
                    assert_eq!(far, 1, "missed {p:?} near vertex {j} at {c:?} (wide cells)");
                    if modest(&c) {
                        let near = near_filter.holds(near_filter.cell(p[0], p[1]));
                        assert_eq!(near, 1, "missed {p:?} near vertex {j} at {c:?}");
                    }
                }
            }
        }
        assert!(near > 300_000, "the test must exercise near points ({near})");
        let mut false_positives = 0;
        for _ in 0..100_000 {
            let p = [u() * 20.0, u() * 20.0];
            if vertices.iter().all(|c| !crate::sim::merge::within(p, *c, 10.0 * r)) {
                false_positives += near_filter.holds(near_filter.cell(p[0], p[1]));
            }
        }
        assert!(false_positives < 5_000, "{false_positives} false positives in 10⁵");
    }

    /// The AVX2 build of the loop and the portable one give the same tally, bit for bit, on
    /// chunks with merges at every plane (when the CPU has AVX2; otherwise both are portable).
    #[test]
    fn simd_and_portable_loops_agree() {
        let mut merges = [0; 3];
        // The spot (with a partial last chunk), and a uniform disc with a wide R for plane-1 hits.
        for doc in [
            serde_json::json!({
                "preset": "paper-table1", "light_paths": 140_000, "camera_paths": 300, "merge_radius": 0.02
            }),
            serde_json::json!({
                "preset": "uniform-illumination", "light_paths": 131_072, "camera_paths": 100, "merge_radius": 0.05
            }),
        ] {
            let job = parse_job_spec(&doc).unwrap().validate().unwrap();
            let config = &job.config;
            let mut scratch = ChunkScratch::new(config.cells.len());
            for iteration in 0..4 {
                let cameras = CameraSet::generate(config, 7, iteration);
                for chunk in 0..config.chunks() {
                    let simd = trace_chunk_with(config, &cameras, 7, iteration, chunk, &mut scratch, true);
                    let portable = trace_chunk_with(config, &cameras, 7, iteration, chunk, &mut scratch, false);
                    assert_eq!(
                        format!("{simd:?}"),
                        format!("{portable:?}"),
                        "{doc}: iteration {iteration}, chunk {chunk}"
                    );
                    for (total, m) in merges.iter_mut().zip(simd.merges) {
                        *total += m;
                    }
                }
            }
        }
        assert!(merges.iter().all(|&m| m > 0), "the test must exercise every plane: {merges:?}");
    }
}
