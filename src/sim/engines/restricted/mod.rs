//! The restricted engine: per iteration, only the light paths that can contribute, drawn exactly.
//!
//! # What it replaces
//!
//! Given the camera paths of an iteration, a light path η contributes only if it lies in
//! S = S1 ∪ ⋃_j S2_j ∪ ⋃_j S3_j, where S1 = {|x1l| ≤ R}, S2_j = {|x2l − x2c_j| ≤ R} and
//! S3_j = {|x3l − x3c_j| ≤ R}. The brute force draws N_F paths and discards the ≈ 99.9995% outside
//! S; the paths in S form a binomial process. This engine draws instead the Poisson process with
//! intensity μ(η) = N_F·p(η) restricted to S. Consequences:
//!
//! * every expectation that is a sum over paths (L, the tallies, the merge counts, Ā, B̄, …) is
//!   unchanged exactly (Campbell's theorem: E Σ f(η) = ∫ f μ for both processes);
//! * the law of one whole iteration differs from the brute force's in total variation by at most
//!   p_S = P(η ∈ S | cameras) (Le Cam's inequality for the count, Barbour & Hall 1984: the
//!   binomial(N_F, p_S) and Poisson(N_F·p_S) counts differ by ≤ p_S, and given the count the paths
//!   are i.i.d. with the same law on S in both). For the paper, N_F·p_S ≈ 48, so p_S ≈ 5·10⁻⁶:
//!   second moments (the variances the solver minimises) differ by a relative O(p_S).
//!
//! # How the process is drawn
//!
//! S is split into disjoint parts T_k = S_k ∖ (S_1 ∪ … ∪ S_{k−1}) in the fixed order S1, S2_1…S2_NB,
//! S3_1…S3_NB. The restriction of a Poisson process to disjoint sets gives independent processes,
//! and the emission splits into the light's rings (independent processes by superposition, each
//! with a constant level ℓ, i.e. path-start intensity ν = N_F·ℓ/Φ per unit area). For every
//! (component, ring) pair: draw a Poisson number of candidates from a dominating intensity λ̄ ≥ μ
//! on S_k with known mass and an exact sampler; keep each with probability μ/λ̄ (thinning); keep
//! it only if k is the first component that contains it (the membership tests are the brute
//! force's merge tests). Each kept path is tallied with all its merges, by [`super::merge`], with
//! exactly the brute force's energies and contributions. The (component, ring) pairs of one plane
//! are drawn as one bundle: a Poisson count for their total mass, then a pair per candidate in
//! proportion to its mass.
//!
//! # Proposals (each with its thinning ratio μ/λ̄ ≤ 1)
//!
//! Densities are per unit area of each vertex; a Lambert direction from plane 3 lands on plane 2
//! with density cos²θ/(π d²) = L3²/(π d⁴), d = |x2 − x3|.
//!
//! * **S3_j**: x3 uniform in the disc D(x3c_j, R) (λ̄ = ν there, mass νπR²), kept if it lies in the
//!   ring; then the path continues forwards exactly (Lambert to x2, lobe to x1).
//! * **S2_j, reverse** (wide rings): x2 uniform in D(x2c_j, R); a Lambert direction *up* from x2
//!   gives x3 with exactly the forward density L3²/(π d⁴), so μ/λ̄ = 1 on the ring (mass νπR²).
//! * **S2_j, forward** (small rings): x3 uniform in the ring (area A), x2 uniform in D(x2c_j, R),
//!   λ̄ = ν·L3²/(π d_min⁴) with d_min² = L3² + max(0, |x2c_j| − R − r_out)² ≤ d² (triangle
//!   inequality), so μ/λ̄ = (d_min/d)⁴ ≤ 1 (mass ν·A·R²·L3²/d_min⁴).
//! * **S1, reverse** (wide rings): x1 uniform in D(0, R); a direction up from x1, uniform on the
//!   hemisphere (pdf 1/2π), gives x2; the incident direction at x2 is drawn by the lobe sampler
//!   around the outgoing one, giving x3. The lobe's kernel depends only on the angle between its two
//!   directions (uniform azimuth), so it is symmetric and cancels exactly in μ/λ̄ — whatever ϑ, and
//!   with no bound needed on the solid-angle pdf g(ϑ)ϑ/sin ϑ (unbounded as ϑ → π), which matters for
//!   wide lobes. What remains is μ/λ̄ = cos θ3 / (π · 1/2π) / 2 = cos θ3 ≤ 1 with λ̄ carrying a
//!   factor 2 (mass 2νπR²); θ3 is the incident direction's angle to the normal, and a direction
//!   that points up (no light path travels that way) has μ = 0. The sampled ϑ is the path's ϑ: by
//!   the same symmetry its conditional law given the vertices matches the forward draw's.
//! * **S1, forward** (small rings near the axis): split by the lobe's deflection ϑ into the bulk
//!   ϑ ≤ ϑ_c = 3β and the tail ϑ > ϑ_c (disjoint sets of paths, so independent processes). For
//!   each part: x3 uniform in the ring, x2 uniform in D(0, ρ(ϑ's bound)), ϑ from the Rayleigh law
//!   truncated to the part (mass × the part's probability), azimuth uniform; λ̄ = ν/(π L3²)·(ϑ's
//!   law), μ/λ̄ = (L3/d)⁴; kept if x1 lands in D(0, R). See [`forward_reach`] for the proof that no
//!   path deflected by at most ϑ_max through |x2| > ρ(ϑ_max) reaches D(0, R); the split makes the
//!   bulk's disc ≈ 8× smaller than one disc for the sampler's largest ϑ (8.57β) would be.
//!
//! With `Proposals::Auto` every pair uses whichever valid proposal has the smaller mass (for the
//! paper's spot: forward for the bright core, reverse for the dim disc); `Proposals::Reverse`
//! uses the reverse proposals throughout — a second, independent scheme with the same law, which
//! the equivalence tests compare against.
//!
//! Imports: crate::sim::engines, crate::sim::math, crate::sim::model

mod bundles;
mod plan;

use std::sync::atomic::AtomicBool;

use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::tally::{ChunkScratch, ChunkTally};
use crate::sim::math::rng::stream;
use crate::sim::model::config::SimConfig;
use bundles::{Iteration, build_plane2, build_plane3, plane1_bundle, plane2_bundle, plane3_bundle};
pub use plan::{RestrictedPlan, RestrictedScratch, forward_reach};

/// Stream index of the restricted engine's draws in an iteration (cameras use `u64::MAX`, the
/// brute force's chunks 0, 1, 2, …).
pub const RESTRICTED_STREAM: u64 = u64::MAX - 1;

/// Stream index of the coins that split an iteration's kept light paths in halves (noise
/// components only): a stream of its own, so the paths drawn do not depend on whether components
/// are kept.
pub const COIN_STREAM: u64 = u64::MAX - 2;

/// Candidates drawn between two looks at the stop flag: an iteration of a huge configuration
/// (millions of candidates) stops within milliseconds of a cancel, and the paper's ~50 candidates
/// never look at it.
pub(crate) const CANCEL_CHECK_INTERVAL: u64 = 1024;

/// Traces iteration `iteration` with the restricted engine into `tally` (its buffer reused) and
/// returns true, or false if `cancel` was set while it ran (the partial iteration is dropped whole).
#[allow(clippy::too_many_arguments)]
pub fn trace_restricted(
    config: &SimConfig,
    plan: &RestrictedPlan,
    cameras: &CameraSet,
    seed: u64,
    iteration: u64,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
    cancel: &AtomicBool,
    tally: &mut ChunkTally,
) -> bool {
    let mut rng = stream(seed, iteration, RESTRICTED_STREAM);
    scratch.set_coins(scratch.keeps_blocks().then(|| stream(seed, iteration, COIN_STREAM)));
    let it = Iteration { config, plan, cameras, cancel };
    let complete = plane1_bundle(&it, &mut rng, scratch, buffers)
        && plane2_bundle(&it, &mut rng, scratch, buffers)
        && plane3_bundle(&it, &mut rng, scratch, buffers);
    // Taken either way: the scratch must be clean for the next iteration.
    scratch.take_into(tally);
    complete
}

/// The expected number of candidates the restricted engine draws in an iteration with these
/// camera paths: the total proposal mass of its three bundles (what [`trace_restricted`] passes
/// to the Poisson draws).
pub fn expected_candidates(config: &SimConfig, plan: &RestrictedPlan, cameras: &CameraSet) -> f64 {
    let mut buffers = RestrictedScratch::default();
    let mut total = plan.plane1_mass();
    for build in [build_plane2, build_plane3] {
        build(config, plan, cameras, &mut buffers);
        total += buffers.total();
    }
    total
}
