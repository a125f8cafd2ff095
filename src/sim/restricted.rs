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

use std::f64::consts::{PI, TAU};
use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;

use super::camera::CameraSet;
use super::config::SimConfig;
use super::illumination::{Ring, unit_disc_point};
use super::light::PixelCone;
use super::merge::{merge_plane1, merge_plane2, merge_plane3, within};
use super::rng::{StreamRng, stream, uniform, uniform_open0};
use super::sampling::{LOBE_MAX_SIGMAS, cosine_direction, deflect, sample_lobe};
use super::tally::{ChunkScratch, ChunkTally};

/// Stream index of the restricted engine's draws in an iteration (cameras use `u64::MAX`, the
/// brute force's chunks 0, 1, 2, …).
pub const RESTRICTED_STREAM: u64 = u64::MAX - 1;

/// Which proposals the restricted engine uses (both draw the same process exactly).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Proposals {
    /// The tighter valid proposal of every (component, ring) pair.
    Auto,
    /// Reverse proposals only (plane-3 components are always drawn directly).
    Reverse,
}

/// One ring of the emission, with what its proposals need.
#[derive(Debug, Clone, Copy)]
struct Layer {
    ring: Ring,
    /// ν: expected light-path starts per unit area, N_F·ℓ/Φ.
    nu: f64,
    /// Area of the ring.
    area: f64,
    /// The forward plane-1 proposal's (ρ for the bulk ϑ ≤ ϑ_c, ρ for the tail), if both exist.
    reach: Option<(f64, f64)>,
}

/// How a candidate of the plane-1 or plane-2 bundle is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Forward,
    Reverse,
    /// Plane 1, forward, ϑ ≤ ϑ_c.
    ForwardBulk,
    /// Plane 1, forward, ϑ > ϑ_c.
    ForwardTail,
}

/// ϑ_c/β: where the forward plane-1 proposal splits the lobe's deflections into bulk and tail.
const BULK_SIGMAS: f64 = 3.0;

/// P(ϑ > ϑ_c) = exp(−ϑ_c²/2β²) for the Rayleigh law of ϑ.
fn tail_probability() -> f64 {
    (-0.5 * BULK_SIGMAS * BULK_SIGMAS).exp()
}

/// What an iteration of the restricted engine needs of the configuration, computed once per run.
#[derive(Debug, Clone)]
pub struct RestrictedPlan {
    proposals: Proposals,
    layers: Vec<Layer>,
    /// The plane-1 bundle, (mass, layer, kind) per part: it does not depend on the cameras, so it
    /// is worked out once per run.
    plane1: Vec<(f64, usize, Kind)>,
    cone: PixelCone,
    /// (δ, sin δ, cos δ) for δ = asin(R/L2) (with a relative margin of 10⁻⁶): a direction from x2
    /// that hits D(0, R) is within δ of the direction to the pixel (see [`PixelCone::new`]).
    delta: (f64, f64, f64),
}

/// Per-thread buffers reused across iterations (the bundles' cumulative masses).
#[derive(Debug, Default)]
pub struct RestrictedScratch {
    /// (cumulative mass, layer, camera, kind) of the current bundle.
    bundle: Vec<(f64, u32, u32, Kind)>,
}

impl RestrictedScratch {
    /// Adds a (layer, camera) pair of mass `mass` to the current bundle.
    fn push(&mut self, mass: f64, layer: usize, camera: usize, kind: Kind) {
        let total = self.bundle.last().map_or(0.0, |&(c, ..)| c) + mass;
        self.bundle.push((total, layer as u32, camera as u32, kind));
    }
}

/// The largest |x2| from which a light path that started at |x3| < `r_out` and is deflected by at
/// most `theta_max` can land in D(0, R) on plane 1, or `None` when no such bound exists
/// (`r_out` ≥ L3, or the deflection too wide).
///
/// Proof. Let t be the unit direction from x2 (at |x2| = ρ) to the pixel and d the path's direction
/// into x2. The lobe deflects d by at most ϑ_max, and a direction from x2 that hits D(0, R) makes an angle ≤ δ = asin(R/L2) with t (the disc lies
/// in the ball of radius R about the pixel, at distance ≥ L2 > R; see [`PixelCone::new`]); so a hit
/// needs angle(d, t) ≤ ϑ_max + δ. Let d* be the direction from the axis point of plane 3 to x2: d*
/// and t lie in one vertical plane on opposite sides of the vertical, so angle(d*, t) =
/// f(ρ) = atan(ρ/L3) + atan(ρ/L2). The angle between d* and d is the angle at x2 of the triangle
/// (x2, axis point, x3), whose opposite side is |x3| < r_out and whose other sides are ≥ L3 > r_out;
/// that angle is therefore not the largest of the triangle, hence acute, and its sine is ≤ r_out/L3
/// (law of sines), so it is ≤ asin(r_out/L3). By the triangle inequality on the sphere a hit needs
/// f(ρ) ≤ Ψ = ϑ_max + δ + asin(r_out/L3). f increases from 0 towards π, so for Ψ < π the hits have
/// ρ ≤ f⁻¹(Ψ). Both Ψ and the root get a relative margin of 10⁻⁶ for rounding.
pub fn forward_reach(theta_max: f64, l2: f64, l3: f64, radius: f64, r_out: f64) -> Option<f64> {
    assert!(radius < l2, "the merge radius must be smaller than L2");
    if r_out >= l3 {
        return None;
    }
    let psi = (theta_max + (radius / l2).asin() + (r_out / l3).asin()) * (1.0 + 1e-6);
    if psi >= PI - 1e-9 {
        return None;
    }
    let f = |rho: f64| (rho / l3).atan() + (rho / l2).atan();
    let mut hi = l2.min(l3);
    while f(hi) < psi {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < psi { lo = mid } else { hi = mid }
    }
    Some(hi * (1.0 + 1e-6))
}

impl RestrictedPlan {
    pub fn new(config: &SimConfig, proposals: Proposals) -> Self {
        let scene = &config.scene;
        let flux = scene.illumination.flux();
        let layers = scene
            .illumination
            .rings()
            .iter()
            .map(|&ring| Layer {
                ring,
                nu: config.light_paths as f64 * ring.level / flux,
                area: PI * (ring.r_out * ring.r_out - ring.r_in * ring.r_in),
                reach: {
                    let reach =
                        |theta_max| forward_reach(theta_max, scene.l2, scene.l3, config.merge_radius, ring.r_out);
                    // The tail's u = P(tail)·u' with u' ≥ 2⁻⁵³ gives ϑ ≤ β·√(ϑ_c²/β² + LOBE_MAX_SIGMAS²).
                    let tail_max = scene.lobe.beta * BULK_SIGMAS.hypot(LOBE_MAX_SIGMAS);
                    reach(BULK_SIGMAS * scene.lobe.beta).zip(reach(tail_max))
                },
            })
            .collect();
        let cone = PixelCone::new(scene.lobe.beta, scene.l2, config.merge_radius);
        let delta = (config.merge_radius / scene.l2).asin() * (1.0 + 1e-6);
        let mut plan = Self { proposals, layers, plane1: Vec::new(), cone, delta: (delta, delta.sin(), delta.cos()) };
        plan.plane1 = (0..plan.layers.len())
            .flat_map(|l| plan.plane1_parts(&plan.layers[l], config).into_iter().map(move |(m, k)| (m, l, k)))
            .collect();
        plan
    }

    /// The expected number of plane-1 candidates of an iteration (it does not depend on the
    /// cameras).
    pub fn plane1_mass(&self) -> f64 {
        self.plane1.iter().map(|&(mass, ..)| mass).sum()
    }

    /// The plane-1 proposals for `layer`: (mass, kind) of each part.
    fn plane1_parts(&self, layer: &Layer, config: &SimConfig) -> Vec<(f64, Kind)> {
        let r = config.merge_radius;
        let reverse = 2.0 * layer.nu * PI * r * r;
        match (self.proposals, layer.reach) {
            (Proposals::Auto, Some((bulk, tail))) => {
                let l3 = config.scene.l3;
                let disc = |rho: f64| layer.nu * layer.area * rho * rho / (l3 * l3);
                let p_tail = tail_probability();
                let parts =
                    [(disc(bulk) * (1.0 - p_tail), Kind::ForwardBulk), (disc(tail) * p_tail, Kind::ForwardTail)];
                if parts[0].0 + parts[1].0 < reverse { parts.to_vec() } else { vec![(reverse, Kind::Reverse)] }
            }
            _ => vec![(reverse, Kind::Reverse)],
        }
    }

    /// Mass and kind of the plane-2 proposal for `layer` around camera vertex `x2c`.
    fn plane2(&self, layer: &Layer, config: &SimConfig, x2c: [f64; 2]) -> (f64, Kind) {
        let r = config.merge_radius;
        let reverse = layer.nu * PI * r * r;
        if self.proposals == Proposals::Reverse {
            return (reverse, Kind::Reverse);
        }
        let d_min2 = d_min_squared(config, layer, x2c);
        let l3 = config.scene.l3;
        let forward = layer.nu * layer.area * r * r * l3 * l3 / (d_min2 * d_min2);
        if forward < reverse { (forward, Kind::Forward) } else { (reverse, Kind::Reverse) }
    }
}

/// d_min² = L3² + max(0, |x2c| − R − r_out)²: no point of the ring is closer to D(x2c, R).
fn d_min_squared(config: &SimConfig, layer: &Layer, x2c: [f64; 2]) -> f64 {
    let gap = ((x2c[0] * x2c[0] + x2c[1] * x2c[1]).sqrt() - config.merge_radius - layer.ring.r_out).max(0.0);
    config.scene.l3 * config.scene.l3 + gap * gap
}

/// A light path being drawn: its vertices, its direction into x2, and (once known) x1 and ϑ.
struct Candidate {
    x3: [f64; 2],
    x2: [f64; 2],
    d: Vector3<f64>,
    /// `Some((x1, ϑ))` when the path lands in D(0, R) on plane 1, `None` when it does not.
    x1: Option<([f64; 2], f64)>,
}

/// Candidates drawn between two looks at the stop flag: an iteration of a huge configuration
/// (millions of candidates) stops within milliseconds of a cancel, and the paper's ~50 candidates
/// never look at it.
const CANCEL_CHECK_INTERVAL: u64 = 1024;

/// Traces iteration `iteration` with the restricted engine and returns its tally, or `None` if
/// `cancel` was set while it ran (the partial iteration is dropped whole).
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
) -> Option<ChunkTally> {
    let mut rng = stream(seed, iteration, RESTRICTED_STREAM);
    let it = Iteration { config, plan, cameras, cancel };
    let complete = plane1_bundle(&it, &mut rng, scratch, buffers)
        && plane2_bundle(&it, &mut rng, scratch, buffers)
        && plane3_bundle(&it, &mut rng, scratch, buffers);
    // Taken either way: the scratch must be clean for the next iteration.
    let tally = scratch.take();
    complete.then_some(tally)
}

/// The expected number of candidates the restricted engine draws in an iteration with these
/// camera paths: the total proposal mass of its three bundles (what [`trace_restricted`] passes
/// to the Poisson draws).
pub fn expected_candidates(config: &SimConfig, plan: &RestrictedPlan, cameras: &CameraSet) -> f64 {
    let mut buffers = RestrictedScratch::default();
    let mut total = plan.plane1_mass();
    for build in [build_plane2, build_plane3] {
        build(config, plan, cameras, &mut buffers);
        total += buffers.bundle.last().map_or(0.0, |&(c, ..)| c);
    }
    total
}

/// What the bundles of one iteration read: the configuration, the plan, the camera paths and the
/// stop flag.
#[derive(Clone, Copy)]
struct Iteration<'a> {
    config: &'a SimConfig,
    plan: &'a RestrictedPlan,
    cameras: &'a CameraSet,
    cancel: &'a AtomicBool,
}

/// The component of S whose bundle drew a candidate (S1's bundle needs no test: it is first).
#[derive(Clone, Copy)]
enum Component {
    Plane2(u32),
    Plane3(u32),
}

impl Iteration<'_> {
    /// Whether a component before `own` in the fixed order S1, S2_1…S2_NB, S3_1…S3_NB contains the
    /// candidate: the parts T_k are disjoint because a candidate is kept only by the first
    /// component that contains it (the membership tests are the brute force's merge tests).
    fn in_earlier_component(&self, c: &Candidate, own: Component) -> bool {
        let (r, paths) = (self.config.merge_radius, &self.cameras.paths);
        let plane2_before = match own {
            Component::Plane2(j) => j,
            Component::Plane3(_) => u32::MAX,
        };
        let in_plane2 = || {
            let near = self.cameras.plane2.candidates(c.x2);
            near.iter().any(|&i| i < plane2_before && within(c.x2, paths[i as usize].x2, r))
        };
        let in_plane3 = || match own {
            Component::Plane2(_) => false,
            Component::Plane3(j) => self
                .cameras
                .plane3
                .candidates(c.x3)
                .iter()
                .any(|&i| i < j && paths[i as usize].x3.is_some_and(|x3c| within(c.x3, x3c, r))),
        };
        c.x1.is_some() || in_plane2() || in_plane3()
    }
}

/// Draws the bundle in `buffers.bundle`: a Poisson count for the total mass, then a pair per
/// candidate in proportion to its mass. False if `cancel` was set meanwhile (looked at every
/// [`CANCEL_CHECK_INTERVAL`] candidates, and while drawing a huge count).
fn for_each_candidate(
    rng: &mut StreamRng,
    buffers: &RestrictedScratch,
    cancel: &AtomicBool,
    mut draw: impl FnMut(&mut StreamRng, u32, u32, Kind),
) -> bool {
    let Some(&(total, ..)) = buffers.bundle.last() else { return true };
    let Some(count) = poisson_until(rng, total, cancel) else { return false };
    for k in 0..count {
        if k % CANCEL_CHECK_INTERVAL == CANCEL_CHECK_INTERVAL - 1 && cancel.load(Ordering::Relaxed) {
            return false;
        }
        let u = uniform(rng) * total;
        let i = buffers.bundle.partition_point(|&(c, ..)| c <= u).min(buffers.bundle.len() - 1);
        let (_, layer, camera, kind) = buffers.bundle[i];
        draw(rng, layer, camera, kind);
    }
    true
}

fn plane1_bundle(
    it: &Iteration,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    buffers.bundle.clear();
    for &(mass, l, kind) in &plan.plane1 {
        buffers.push(mass, l, 0, kind);
    }
    let r = config.merge_radius;
    let (l2, l3) = (config.scene.l2, config.scene.l3);
    for_each_candidate(rng, buffers, cancel, |rng, l, _, kind| {
        let layer = &plan.layers[l as usize];
        let candidate = match kind {
            Kind::Reverse => {
                let x1 = disc_point(rng, [0.0, 0.0], r);
                // A direction up from x1, uniform on the hemisphere: cos γ uniform in (0, 1].
                let cos_g = 1.0 - uniform(rng);
                let sin_g = (1.0 - cos_g * cos_g).sqrt();
                let (sin_p, cos_p) = libm::sincos(TAU * uniform(rng));
                let x2 = [x1[0] + l2 * sin_g / cos_g * cos_p, x1[1] + l2 * sin_g / cos_g * sin_p];
                let out = Vector3::new(-sin_g * cos_p, -sin_g * sin_p, -cos_g);
                let (d, theta) = sample_lobe(&config.scene.lobe, &out, rng);
                // μ = 0 for a direction that does not point down; otherwise thin by cos θ3.
                if d.z >= 0.0 || uniform(rng) >= -d.z {
                    return;
                }
                let x3 = [x2[0] - l3 * d.x / -d.z, x2[1] - l3 * d.y / -d.z];
                if !in_ring(&layer.ring, x3) {
                    return;
                }
                Candidate { x3, x2, d, x1: Some((x1, theta)) }
            }
            Kind::ForwardBulk | Kind::ForwardTail => {
                let (bulk, tail) = layer.reach.expect("forward plane-1 proposals exist only with a bound");
                let x3 = ring_point(rng, &layer.ring);
                let x2 = disc_point(rng, [0.0, 0.0], if kind == Kind::ForwardBulk { bulk } else { tail });
                let Some(d) = thin_by_distance(rng, x3, x2, l3, l3 * l3) else { return };
                // ϑ = β√(−2 ln u) with u restricted to the part: u ≥ P(tail) for the bulk, u < it
                // for the tail (u = P(tail)·u' with u' in (0, 1], as the sampler's u).
                let p_tail = tail_probability();
                let u = if kind == Kind::ForwardBulk {
                    p_tail + (1.0 - p_tail) * (1.0 - uniform(rng))
                } else {
                    p_tail * uniform_open0(rng)
                };
                let theta = config.scene.lobe.beta * (-2.0 * libm::log(u)).sqrt();
                let x1 = land_on_pixel(config, plan, &d, x2, theta, rng);
                if x1.is_none() {
                    return;
                }
                Candidate { x3, x2, d, x1 }
            }
            Kind::Forward => unreachable!("plane 1 uses the bulk and tail proposals"),
        };
        // S1 is the first component: nothing to exclude.
        tally(config, cameras, &candidate, scratch);
    })
}

/// The plane-2 bundle: a (ring, camera) pair per camera vertex and ring, with its proposal.
fn build_plane2(config: &SimConfig, plan: &RestrictedPlan, cameras: &CameraSet, buffers: &mut RestrictedScratch) {
    buffers.bundle.clear();
    for (l, layer) in plan.layers.iter().enumerate() {
        for (j, cam) in cameras.paths.iter().enumerate() {
            let (mass, kind) = plan.plane2(layer, config, cam.x2);
            buffers.push(mass, l, j, kind);
        }
    }
}

fn plane2_bundle(
    it: &Iteration,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    build_plane2(config, plan, cameras, buffers);
    let r = config.merge_radius;
    let l3 = config.scene.l3;
    for_each_candidate(rng, buffers, cancel, |rng, l, j, kind| {
        let layer = &plan.layers[l as usize];
        let x2c = cameras.paths[j as usize].x2;
        let x2 = disc_point(rng, x2c, r);
        let (x3, d) = match kind {
            Kind::Reverse => {
                let up = cosine_direction(rng);
                let x3 = [x2[0] - l3 / up.z * up.x, x2[1] - l3 / up.z * up.y];
                if !in_ring(&layer.ring, x3) {
                    return;
                }
                (x3, Vector3::new(up.x, up.y, -up.z))
            }
            Kind::Forward | Kind::ForwardBulk | Kind::ForwardTail => {
                let x3 = ring_point(rng, &layer.ring);
                let Some(d) = thin_by_distance(rng, x3, x2, l3, d_min_squared(config, layer, x2c)) else { return };
                (x3, d)
            }
        };
        let candidate = Candidate { x3, x2, d, x1: pixel_hit(config, plan, &d, x2, rng) };
        if !it.in_earlier_component(&candidate, Component::Plane2(j)) {
            tally(config, cameras, &candidate, scratch);
        }
    })
}

/// The plane-3 bundle: a (ring, camera) pair per camera vertex on plane 3 whose disc meets the
/// ring.
fn build_plane3(config: &SimConfig, plan: &RestrictedPlan, cameras: &CameraSet, buffers: &mut RestrictedScratch) {
    let r = config.merge_radius;
    buffers.bundle.clear();
    for (l, layer) in plan.layers.iter().enumerate() {
        for (j, cam) in cameras.paths.iter().enumerate() {
            let Some(x3c) = cam.x3 else { continue };
            // A disc that misses the ring holds no start point: no candidates.
            let dist = (x3c[0] * x3c[0] + x3c[1] * x3c[1]).sqrt();
            if dist + r < layer.ring.r_in || dist - r >= layer.ring.r_out {
                continue;
            }
            buffers.push(layer.nu * PI * r * r, l, j, Kind::Forward);
        }
    }
}

fn plane3_bundle(
    it: &Iteration,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    build_plane3(config, plan, cameras, buffers);
    let r = config.merge_radius;
    let l3 = config.scene.l3;
    for_each_candidate(rng, buffers, cancel, |rng, l, j, _| {
        let layer = &plan.layers[l as usize];
        let x3c = cameras.paths[j as usize].x3.expect("only reached cameras are in the bundle");
        let x3 = disc_point(rng, x3c, r);
        if !in_ring(&layer.ring, x3) {
            return;
        }
        let dir = cosine_direction(rng);
        let x2 = [x3[0] + l3 / dir.z * dir.x, x3[1] + l3 / dir.z * dir.y];
        let d = Vector3::new(dir.x, dir.y, -dir.z);
        let candidate = Candidate { x3, x2, d, x1: pixel_hit(config, plan, &d, x2, rng) };
        if !it.in_earlier_component(&candidate, Component::Plane3(j)) {
            tally(config, cameras, &candidate, scratch);
        }
    })
}

/// Thinning of the forward proposals, whose λ̄ uses the density bound L3²/(π d_min⁴) of a Lambert
/// direction from x3 landing at x2: keeps the candidate with probability (d_min/d)⁴ and returns
/// its unit direction x3 → x2, or `None`.
fn thin_by_distance(rng: &mut StreamRng, x3: [f64; 2], x2: [f64; 2], l3: f64, d_min2: f64) -> Option<Vector3<f64>> {
    let (dx, dy) = (x2[0] - x3[0], x2[1] - x3[1]);
    let d2 = l3 * l3 + dx * dx + dy * dy;
    let ratio = d_min2 / d2;
    (uniform(rng) < ratio * ratio).then(|| Vector3::new(dx, dy, -l3) / d2.sqrt())
}

/// The forward lobe draw at x2 for a path travelling along `d`: `Some((x1, ϑ))` if it lands in
/// D(0, R) on plane 1, else `None`.
///
/// Draws are skipped only where they cannot matter: for a path outside the pixel cone (no
/// deflection reaches the disc), and, once ϑ is drawn, when the angle ψ between `d` and the
/// direction t to the pixel is outside [ϑ − δ, ϑ + δ] — a direction at angle ϑ from `d` that hits
/// the disc is within δ of t, so |ψ − ϑ| ≤ δ by the triangle inequality on the sphere. (Only
/// applied for ϑ + δ < π, where the deflected direction's angle to `d` is ϑ itself.) The law of
/// every path's vertices and ϑ is the lobe sampler's: ϑ = β√(−2 ln u₁), azimuth 2πu₂.
fn pixel_hit(
    config: &SimConfig,
    plan: &RestrictedPlan,
    d: &Vector3<f64>,
    x2: [f64; 2],
    rng: &mut StreamRng,
) -> Option<([f64; 2], f64)> {
    let l2 = config.scene.l2;
    if !plan.cone.may_reach(x2[0], x2[1], d.x, d.y, -d.z, l2) {
        return None;
    }
    let theta = config.scene.lobe.beta * (-2.0 * libm::log(uniform_open0(rng))).sqrt();
    land_on_pixel(config, plan, d, x2, theta, rng)
}

/// The rest of the lobe draw once ϑ is drawn: `Some((x1, ϑ))` if the path lands in D(0, R).
fn land_on_pixel(
    config: &SimConfig,
    plan: &RestrictedPlan,
    d: &Vector3<f64>,
    x2: [f64; 2],
    theta: f64,
    rng: &mut StreamRng,
) -> Option<([f64; 2], f64)> {
    let l2 = config.scene.l2;
    let (delta, sin_d, cos_d) = plan.delta;
    if theta * (1.0 + 1e-9) + delta < PI {
        let t_len = (x2[0] * x2[0] + x2[1] * x2[1] + l2 * l2).sqrt();
        let cos_psi = (-d.x * x2[0] - d.y * x2[1] - d.z * l2) / t_len;
        let (sin_t, cos_t) = libm::sincos(theta);
        // cos(ϑ + δ) and cos(ϑ − δ), with a margin of 10⁻¹² for rounding.
        if cos_psi < cos_t * cos_d - sin_t * sin_d - 1e-12 {
            return None;
        }
        if theta > delta && cos_psi > cos_t * cos_d + sin_t * sin_d + 1e-12 {
            return None;
        }
    }
    let out = deflect(d, theta, TAU * uniform(rng));
    if out.z >= 0.0 {
        return None;
    }
    let x1 = [x2[0] - l2 * out.x / out.z, x2[1] - l2 * out.y / out.z];
    within(x1, [0.0, 0.0], config.merge_radius).then_some((x1, theta))
}

/// Every merge of a kept path, exactly as the brute force records them.
fn tally(config: &SimConfig, cameras: &CameraSet, c: &Candidate, scratch: &mut ChunkScratch) {
    merge_plane3(config, cameras, cameras.plane3.candidates(c.x3), c.x3, scratch);
    merge_plane2(config, cameras, cameras.plane2.candidates(c.x2), c.x2, c.x3, &c.d, scratch);
    if let Some((_, theta)) = c.x1 {
        merge_plane1(config, theta, c.x2, c.x3, scratch);
    }
}

fn in_ring(ring: &Ring, x: [f64; 2]) -> bool {
    let r2 = x[0] * x[0] + x[1] * x[1];
    r2 >= ring.r_in * ring.r_in && r2 < ring.r_out * ring.r_out
}

/// A point uniform in the disc D(`center`, `radius`).
fn disc_point(rng: &mut StreamRng, center: [f64; 2], radius: f64) -> [f64; 2] {
    let (u, v, _) = unit_disc_point(rng);
    [center[0] + radius * u, center[1] + radius * v]
}

/// A point uniform in the ring (r² uniform between the radii, azimuth uniform).
fn ring_point(rng: &mut StreamRng, ring: &Ring) -> [f64; 2] {
    if ring.r_in == 0.0 {
        return disc_point(rng, [0.0, 0.0], ring.r_out);
    }
    let (a, b) = (ring.r_in * ring.r_in, ring.r_out * ring.r_out);
    let r = (a + uniform(rng) * (b - a)).sqrt();
    let (s, c) = libm::sincos(TAU * uniform(rng));
    [r * c, r * s]
}

/// A Poisson variate of mean `mean`: sums of inversion draws of mean ≤ 16 (a sum of independent
/// Poisson variates is Poisson), so exp(−mean) never underflows and the search stays short.
pub fn poisson(rng: &mut StreamRng, mean: f64) -> u64 {
    poisson_until(rng, mean, &AtomicBool::new(false)).expect("never cancelled")
}

/// [`poisson`] that looks at `cancel` every 4,096 pieces (a mean of 10¹⁰ takes 6·10⁸ of them) and
/// gives up with `None` once it is set. The draws are those of [`poisson`], so a run that is not
/// cancelled is bit-identical.
fn poisson_until(rng: &mut StreamRng, mut mean: f64, cancel: &AtomicBool) -> Option<u64> {
    let mut count = 0;
    let mut pieces = 0u64;
    while mean > 16.0 {
        count += poisson_inversion(rng, 16.0);
        mean -= 16.0;
        pieces += 1;
        if pieces.is_multiple_of(4096) && cancel.load(Ordering::Relaxed) {
            return None;
        }
    }
    Some(count + poisson_inversion(rng, mean))
}

fn poisson_inversion(rng: &mut StreamRng, mean: f64) -> u64 {
    if mean <= 0.0 {
        return 0;
    }
    let u = uniform(rng);
    let mut p = (-mean).exp();
    let mut cdf = p;
    let mut k = 0;
    // The guard ends the search once the terms underflow (a u above the rounded total mass).
    while u >= cdf && p > f64::MIN_POSITIVE {
        k += 1;
        p *= mean / k as f64;
        cdf += p;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_has_the_right_mean_and_variance() {
        let mut rng = stream(3, 1, 4);
        for mean in [0.05, 2.5, 40.0] {
            let n = 200_000;
            let draws: Vec<f64> = (0..n).map(|_| poisson(&mut rng, mean) as f64).collect();
            let m = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n as f64 - 1.0);
            // Mean: standard error √(mean/n); variance: standard error ≈ mean·√(2/n) (+ tail).
            assert!((m - mean).abs() < 4.0 * (mean / n as f64).sqrt(), "mean {m} vs {mean}");
            assert!((var - mean).abs() < 5.0 * mean * (2.0 / n as f64).sqrt() + 0.01 * mean, "var {var} vs {mean}");
        }
    }

    /// The forward reach bound is conservative: lobe-free straight rays (ϑ = 0 is within every
    /// bound) from the ring edge through points just inside ρ_max may still be far off, but no
    /// simulated deflected path through |x2| > ρ_max reaches the pixel disc.
    #[test]
    fn forward_reach_contains_every_hit() {
        let (beta, l2, l3, r, r_out) = (3f64.to_radians(), 1.0, 3.0, 0.05, 0.2);
        let rho = forward_reach(LOBE_MAX_SIGMAS * beta, l2, l3, r, r_out).unwrap();
        let lobe = crate::sim::scene::Lobe::new(beta);
        let mut rng = stream(1, 2, 3);
        let mut hits = 0;
        let mut max_hit: f64 = 0.0;
        for _ in 0..2_000_000 {
            let x3 = disc_point(&mut rng, [0.0, 0.0], r_out);
            let x2 = disc_point(&mut rng, [0.0, 0.0], 1.5 * rho);
            let d = Vector3::new(x2[0] - x3[0], x2[1] - x3[1], -l3).normalize();
            let (out, _) = sample_lobe(&lobe, &d, &mut rng);
            if out.z < 0.0 {
                let x1 = [x2[0] - l2 * out.x / out.z, x2[1] - l2 * out.y / out.z];
                if within(x1, [0.0, 0.0], r) {
                    hits += 1;
                    max_hit = max_hit.max(x2[0].hypot(x2[1]));
                }
            }
        }
        assert!(hits > 100, "the test must exercise hits ({hits})");
        assert!(max_hit <= rho, "a hit through |x2| = {max_hit} > ρ_max = {rho}");
        // And the bound is not vacuous: hits come within a factor 5 of it.
        assert!(max_hit > 0.2 * rho, "ρ_max = {rho} is loose (largest hit {max_hit})");
        assert!(forward_reach(LOBE_MAX_SIGMAS * 40f64.to_radians(), l2, l3, r, r_out).is_none());
        assert!(forward_reach(LOBE_MAX_SIGMAS * beta, l2, l3, r, 3.5).is_none());
    }
}
