//! The block loop's first filter, in single precision: for every light path, from its random
//! words, a conservative answer to "may this path need work beyond its draws?".
//!
//! Why: the exact path (docs/model.md §3: the start x3l, the cosine direction, the hit x2l on
//! plane 2) costs two square roots, a division and two sines and cosines per path, and it was most
//! of the loop's time, while all but about 2 paths in 100 needed it only to learn that they have
//! nothing to do. In f32 a 256-bit vector holds eight paths instead of four, and square roots and
//! divisions are several times cheaper, so the loop now computes every path in f32, and only the
//! paths this filter passes (the candidates) are recomputed in f64 by the very expressions the
//! merges always used (`ExactPath`). The exact tests then run on exact values, so the tallies are
//! bit for bit those of an all-f64 loop — provided the filter never drops a path that an exact
//! test would flag. [`Filter32`] gives the proof; `tests.rs` checks it on random and edge-case
//! paths.

use super::near_filter::{NearFilter32, round_down_f32};
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::pixel::PixelCone;
use crate::sim::math::fastmath::{SINCOS_TURN_F32_ERROR, sincos_turn_f32};
use crate::sim::math::rng::unit52;
use crate::sim::model::config::SimConfig;

/// The largest tan θ of a path whose plane-2 hit the filter tests; steeper paths are always
/// candidates (sin² θ is uniform, so that is 1 path in 1 + 64² ≈ 4100), which keeps the f32
/// error of the plane-2 hit bounded (see [`Filter32`]).
pub(super) const TAN_MAX: f32 = 64.0;

/// 2⁻²⁴, the unit roundoff of f32.
const EPS: f64 = 1.0 / (1u64 << 24) as f64;

/// 2⁻²⁰ = 16·2⁻²⁴: the relative bound of the f32 starts and plane-2 hits (see [`Filter32`]).
const POINT_ERROR: f64 = 1.0 / (1u64 << 20) as f64;

/// The single-precision filter of one chunk: the constants of [`Filter32::path`] and the two near
/// filters it queries.
///
/// What it computes for a path with random words (w₀, w₁, w₂): r² exactly as the f64 sampler
/// ([`Illumination::radius2_block`](crate::sim::model::illumination::Illumination::radius2_block)),
/// then in f32 with ε = 2⁻²⁴: r = √fl₃₂(r²), the start x3 = r·(cos, sin) of the azimuth (high half
/// of w₂, [`sincos_turn_f32`], error ≤ η = 2⁻²¹ = 8ε), tan θ = √(fl₃₂(sin² θ)/fl₃₂(cos² θ)) from the
/// exact f64 sin² θ = unit52(w₁) and cos² θ = 1 − sin² θ, the direction's azimuth (low half of w₂),
/// and x2 = x3 + L3·tan θ·(cos φ, sin φ) with fused multiply-adds — the f64 loop's formulas.
///
/// **Starts.** With r the exact root of the f64 r², the f32 root is r(1 + θ₁), |θ₁| ≤ 1.5ε + ε²,
/// the f64 one r(1 + ρ), |ρ| ≤ 2⁻⁵³; the f64 cosine is within 3·10⁻¹⁶ of the exact one, the f32
/// one within η, and each product rounds once. So each coordinate of the f32 start is within
/// r·(2.6ε + 1.0001η + 7·10⁻¹⁶) < r·11ε ≤ E3 := r_max·2⁻²⁰ of the f64 start, r_max = r_out(1 + 2⁻⁵⁰)
/// bounding every r.
///
/// **Plane-2 hits.** tan θ in f32 is tan_e(1 + θ₂) with tan_e = √(sin² θ/cos² θ) exact, |θ₂| ≤
/// 2.6ε (three roundings in the quotient, halved by the root, and the root's own); the f64 tan is
/// within 1.5·2⁻⁵² of tan_e. So a path with f32 tan θ ≤ T = [`TAN_MAX`] has tan_e ≤ T(1 + 2⁻²¹),
/// and its lateral travel L = L3·tan_e is computed as L(1 + θ₃), |θ₃| ≤ 4.7ε (L3 rounded to f32,
/// θ₂, the product). The f32 hit x2 = fl(L₃₂·cos φ₃₂ + x3₃₂) then differs from the f64 one by at
/// most the sum of L(4.8ε + 1.001η) (the lateral term), r·11ε (the start), ε(L + r)·1.0001 (its
/// rounding) and 2⁻⁵³(L + r) (the f64 rounding), which is ≤ (L + r)·14.1ε, so by E2 :=
/// (L3·T·(1 + 2⁻²⁰) + r_max)·2⁻²⁰. The bounds keep room over the derivation (16ε against ≤ 14.1ε),
/// which absorbs the rounding of their own f64 evaluation and of the near filters' margins.
///
/// **Near filters.** With those errors, [`NearFilter32`] (its proof) is conservative at plane 3
/// with error E3 and reach 2r_max ≥ r_max + E3, and at plane 2, for paths with tan θ ≤ T, with
/// error E2 and reach 2(r_max + L3·T) ≥ r_max + L3·T(1 + 2⁻²¹) + E2.
///
/// **Pixel cone.** The exact test ([`PixelCone::may_reach_polar`]) passes when, in f64,
/// cos² θ·D|D| ≥ C·|t|², with D = L2 − tan θ·(x cos φ + y sin φ), |t|² = x² + y² + L2² at the hit
/// (x, y), and C = c|c|. Write τ = |t| and u = cos θ·D/τ (the cosine of the angle between the
/// direction and the pixel, so |u| ≤ 1 up to 10⁻¹⁵), and Q = u|u|: every term of D and τ² is
/// bounded by τ and τ² (cos θ·tan θ = sin θ ≤ 1, |(x, y)| ≤ τ), so the f64 test's roundings move Q
/// by less than ω = 2⁻⁴⁰, and an f64 pass implies Q ≥ C − ω. The f32 test compares Q₃₂ = u₃₂|u₃₂|,
/// u₃₂ = √fl₃₂(cos² θ)·D₃₂/τ₃₂, from the f32 hit (within E2 per coordinate) and direction. With
/// e = E2/L2 (τ ≥ L2): the f32 D, times cos θ, is within τ(1.51e + √2·1.01η + 6.8ε) of cos θ·D (the
/// hit's error enters through tan θ·cos φ, of weight sin θ ≤ 1; the cosines' through |(x, y)|; the
/// roundings through τ), the root of fl₃₂(cos² θ) adds 0.51ε, and τ₃₂² = τ²(1 + κ) with κ ≤
/// 2√2e + 2e² + 5.1ε. For e ≤ 0.03, κ ≤ 0.1, and |u₃₂ − u| ≤ β := 4e + 2e² + 2η + 16ε (the derivation
/// gives 3.3e + 1.2e² + 1.5η + 11ε), so |Q₃₂ − Q| ≤ (2.0001 + β)β. The f32 comparison
/// fl(fl₃₂(cos² θ)·fl(D₃₂|D₃₂|)) ≥ fl(C_μ·τ₃₂²) rounds each side once or twice (2.01ε of |Q₃₂| ≤ 1.3
/// and ε of |C_μ| ≤ 1.3, relative to τ₃₂²), so it passes whenever Q ≥ C − ω and C_μ ≤ C − μ with
/// μ = ω + (2.0001 + β)β + 4ε. C_μ is C − μ rounded down to f32; for e > 0.03 it is −∞ (every path
/// passes the f32 cone test, and the exact test decides). (For C = −4, a lobe that can reach the
/// pixel from anywhere, |C_μ| is about 4, and every path passes both tests: Q₃₂ ≥ −1.3.)
pub(super) struct Filter32 {
    l2: f32,
    l2_sq: f32,
    l3: f32,
    /// C_μ: the cone test's threshold, lowered by the f32 error (see above).
    c_mu: f32,
    /// Near filters of the camera vertices at plane 3 and plane 2.
    pub(super) near3: NearFilter32,
    pub(super) near2: NearFilter32,
}

impl Filter32 {
    /// The filter for `config`'s scene and merge radius, the camera vertices of `cameras` and the
    /// exact pixel cone `cone`.
    pub(super) fn new(config: &SimConfig, cameras: &CameraSet, cone: &PixelCone) -> Self {
        let scene = &config.scene;
        let radius = config.merge_radius;
        let tan_max = f64::from(TAN_MAX);
        let r_max = scene.illumination.outer_radius() * (1.0 + 2f64.powi(-50));
        let e3 = r_max * POINT_ERROR;
        let e2 = (scene.l3 * tan_max * (1.0 + POINT_ERROR) + r_max) * POINT_ERROR;
        let near3 = NearFilter32::new(cameras.paths.iter().filter_map(|p| p.x3), radius, e3, 2.0 * r_max);
        let near2 =
            NearFilter32::new(cameras.paths.iter().map(|p| p.x2), radius, e2, 2.0 * (r_max + scene.l3 * tan_max));
        let e = e2 / scene.l2;
        let c_mu = if e > 0.03 {
            f32::NEG_INFINITY
        } else {
            let beta = 4.0 * e + 2.0 * e * e + 2.0 * SINCOS_TURN_F32_ERROR + 16.0 * EPS;
            let mu = 2f64.powi(-40) + (2.0001 + beta) * beta + 4.0 * EPS;
            // −2⁻⁵⁰ covers the rounding of the subtraction (|C − μ| ≤ 5).
            round_down_f32(cone.c_abs_c() - mu - 2f64.powi(-50))
        };
        Self {
            l2: scene.l2 as f32,
            l2_sq: (scene.l2 as f32) * (scene.l2 as f32),
            l3: scene.l3 as f32,
            c_mu,
            near3,
            near2,
        }
    }

    /// The f32 inputs of [`Filter32::path`] from a path's exact squared start radius `r2` (as the
    /// f64 sampler has it), its direction word `dir_bits` (sin² θ) and its azimuth word
    /// `azimuth_bits`: fl₃₂(r²), fl₃₂(sin² θ), fl₃₂(cos² θ) and the two azimuths (high half: the
    /// start's, low half: the direction's). cos² θ = 1 − sin² θ is taken exactly in f64 (≥ 2⁻⁵²)
    /// and then rounded: a small relative error even for grazing paths, where 1 − sin² θ in f32
    /// would lose every digit. (A loop of its own: with 64-bit inputs, the compiler vectorises
    /// four lanes at a time, and the f32 loop after it gets eight.)
    #[inline(always)]
    pub(super) fn inputs(r2: f64, dir_bits: u64, azimuth_bits: u64) -> Inputs {
        let sin2 = unit52(dir_bits);
        Inputs {
            r2: r2 as f32,
            sin2: sin2 as f32,
            cos2: (1.0 - sin2) as f32,
            azimuth3: (azimuth_bits >> 32) as u32,
            azimuth2: azimuth_bits as u32,
        }
    }

    /// Whether the filter can pass fewer paths than all: not when C_μ is below −1.3, which every
    /// path's Q₃₂ exceeds (|u₃₂| ≤ 1 + β with β ≤ 0.13 for e ≤ 0.03), nor when C_μ = −∞ (e > 0.03).
    /// Then the near filters do not matter either: every path is a candidate. (A wide lobe, or a
    /// pixel close to plane 2, reaches the pixel from anywhere.) Only the block loop's speed
    /// depends on this, never its results.
    pub(super) fn screens(&self) -> bool {
        self.c_mu >= -1.3
    }

    /// One path from its [`Filter32::inputs`]: the near-filter cells of its f32 start and plane-2
    /// hit, and whether it is a candidate without them (it may reach the pixel, or it is steeper
    /// than [`TAN_MAX`]). Branch-free, so that the block loop vectorises.
    #[inline(always)]
    pub(super) fn path(&self, p: Inputs) -> (u32, u32, bool) {
        let r = p.r2.sqrt();
        let (s3, c3) = sincos_turn_f32(p.azimuth3);
        let (x3, y3) = (r * c3, r * s3);
        let tan = (p.sin2 / p.cos2).sqrt();
        let (sp, cp) = sincos_turn_f32(p.azimuth2);
        let lateral = self.l3 * tan;
        let (x2, y2) = (lateral.mul_add(cp, x3), lateral.mul_add(sp, y3));
        let dot = (-tan).mul_add(x2.mul_add(cp, y2 * sp), self.l2);
        let t2 = x2.mul_add(x2, y2.mul_add(y2, self.l2_sq));
        let may_reach = p.cos2 * (dot * dot.abs()) >= self.c_mu * t2;
        (self.near3.cell(x3, y3), self.near2.cell(x2, y2), may_reach | (tan > TAN_MAX))
    }
}

/// The f32 inputs of one path (see [`Filter32::inputs`]).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Inputs {
    pub(super) r2: f32,
    pub(super) sin2: f32,
    pub(super) cos2: f32,
    pub(super) azimuth3: u32,
    pub(super) azimuth2: u32,
}
