//! What the restricted engine works out once per run: the emission's rings with their path-start
//! intensity, the proposal of every plane-1 part, and the bounds the forward proposals rely on
//! (proofs beside each).

use std::f64::consts::PI;

use crate::sim::engines::pixel::{DiscAngle, PixelCone};
use crate::sim::model::config::{Proposals, SimConfig};
use crate::sim::model::illumination::Ring;
use crate::sim::model::scene::LOBE_MAX_SIGMAS;

/// One ring of the emission, with what its proposals need.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layer {
    pub(super) ring: Ring,
    /// ν: expected light-path starts per unit area, N_F·ℓ/Φ.
    pub(super) nu: f64,
    /// Area of the ring.
    pub(super) area: f64,
    /// The forward plane-1 proposal's (ρ for the bulk ϑ ≤ ϑ_c, ρ for the tail), if both exist.
    pub(super) reach: Option<(f64, f64)>,
}

/// How a candidate of the plane-1 or plane-2 bundle is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
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
pub(super) fn tail_probability() -> f64 {
    (-0.5 * BULK_SIGMAS * BULK_SIGMAS).exp()
}

/// What an iteration of the restricted engine needs of the configuration, computed once per run.
#[derive(Debug, Clone)]
pub struct RestrictedPlan {
    proposals: Proposals,
    pub(super) layers: Vec<Layer>,
    /// The plane-1 bundle: it does not depend on the cameras, so it is worked out once per run.
    pub(super) plane1: Vec<Plane1Part>,
    pub(super) cone: PixelCone,
    pub(super) angle: DiscAngle,
}

/// One part of the plane-1 bundle: the expected candidates of one layer drawn one way.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plane1Part {
    pub(super) mass: f64,
    pub(super) layer: usize,
    pub(super) kind: Kind,
}

/// One (layer, camera) pair of a bundle, with the bundle's mass up to and including it.
#[derive(Debug, Clone, Copy)]
pub(super) struct BundleEntry {
    /// Σ of the masses of this entry and every entry before it (drawn by bisection).
    pub(super) cumulative: f64,
    pub(super) layer: u32,
    pub(super) camera: u32,
    pub(super) kind: Kind,
}

/// Per-thread buffers reused across iterations (the bundles' cumulative masses).
#[derive(Debug, Default)]
pub struct RestrictedScratch {
    /// The current bundle.
    pub(super) bundle: Vec<BundleEntry>,
    /// |x2c| (plane-2 bundle) or |x3c| (plane-3 bundle) of each camera path of the iteration.
    pub(super) radii: Vec<f64>,
    /// The current bundle's guide table, when it has one ([`RestrictedScratch::prepare_draws`]).
    guide: Vec<u32>,
}

impl RestrictedScratch {
    /// Adds a (layer, camera) pair of mass `mass` to the current bundle.
    pub(super) fn push(&mut self, mass: f64, layer: usize, camera: usize, kind: Kind) {
        let cumulative = self.total() + mass;
        self.bundle.push(BundleEntry { cumulative, layer: layer as u32, camera: camera as u32, kind });
    }

    /// Prepares [`RestrictedScratch::find`] for `draws` draws from the current bundle: a guide
    /// table (the cutpoint method of Chen and Asau, 1974) when it pays — entry `g` is the first
    /// entry whose cumulative mass exceeds g/G of the total — else plain bisection.
    pub(super) fn prepare_draws(&mut self, draws: u64) {
        self.guide.clear();
        let n = self.bundle.len();
        // A guide costs ~2n cheap, predictable steps to build and ~1–2 a draw; a bisection's
        // log₂ n steps each wait for a load and a comparison (measured: ~190 cycles a draw in the
        // paper's 200-entry plane-2 bundle, where building the guide costs ~400).
        if draws < 2 || n <= 8 {
            return;
        }
        // Any thresholds give the same draws (`find` steps to the exact entry); these cost a
        // multiplication each.
        let step = self.total() / n as f64;
        let mut i = 0;
        for g in 0..n {
            let threshold = g as f64 * step;
            while i + 1 < n && self.bundle[i].cumulative <= threshold {
                i += 1;
            }
            self.guide.push(i as u32);
        }
    }

    /// The entry a uniform `u` in [0, total) selects: the first whose cumulative mass exceeds `u`
    /// (the last for `u` ≥ every cumulative mass) — `partition_point`'s answer. With a guide the
    /// search starts at the guide's entry for `u` and steps to that same entry (both ways, so that
    /// the rounding of the guide's thresholds cannot matter).
    #[inline]
    pub(super) fn find(&self, u: f64) -> usize {
        let bundle = &self.bundle;
        let last = bundle.len() - 1;
        if self.guide.is_empty() {
            return bundle.partition_point(|e| e.cumulative <= u).min(last);
        }
        let g = ((u / self.total() * bundle.len() as f64) as usize).min(last);
        let mut i = self.guide[g] as usize;
        while i > 0 && bundle[i - 1].cumulative > u {
            i -= 1;
        }
        while i < last && bundle[i].cumulative <= u {
            i += 1;
        }
        i
    }

    /// The current bundle's total mass (its expected number of candidates).
    pub(super) fn total(&self) -> f64 {
        self.bundle.last().map_or(0.0, |e| e.cumulative)
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
    /// The plan of `config` with `proposals` (`Auto`: the cheaper valid proposal per pair): the
    /// emission's layers with their reach, the pixel cone and the plane-1 bundle.
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
        let angle = DiscAngle::new(config.merge_radius, scene.l2);
        let mut plan = Self { proposals, layers, plane1: Vec::new(), cone, angle };
        plan.plane1 = (0..plan.layers.len())
            .flat_map(|layer| {
                plan.plane1_parts(&plan.layers[layer], config).into_iter().map(move |(mass, kind)| Plane1Part {
                    mass,
                    layer,
                    kind,
                })
            })
            .collect();
        plan
    }

    /// The expected number of plane-1 candidates of an iteration (it does not depend on the
    /// cameras).
    pub fn plane1_mass(&self) -> f64 {
        self.plane1.iter().map(|part| part.mass).sum()
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

    /// Mass and kind of the plane-2 proposal for `layer` around a camera vertex at distance
    /// `x2c_radius` from the axis.
    pub(super) fn plane2(&self, layer: &Layer, config: &SimConfig, x2c_radius: f64) -> (f64, Kind) {
        let r = config.merge_radius;
        let reverse = layer.nu * PI * r * r;
        if self.proposals == Proposals::Reverse {
            return (reverse, Kind::Reverse);
        }
        let d_min2 = d_min_squared(config, layer, x2c_radius);
        let l3 = config.scene.l3;
        let forward = layer.nu * layer.area * r * r * l3 * l3 / (d_min2 * d_min2);
        if forward < reverse { (forward, Kind::Forward) } else { (reverse, Kind::Reverse) }
    }
}

/// d_min² = L3² + max(0, |x2c| − R − r_out)²: no point of the ring is closer to D(x2c, R), for a
/// camera vertex at |x2c| = `x2c_radius`.
pub(super) fn d_min_squared(config: &SimConfig, layer: &Layer, x2c_radius: f64) -> f64 {
    let gap = (x2c_radius - config.merge_radius - layer.ring.r_out).max(0.0);
    config.scene.l3 * config.scene.l3 + gap * gap
}

#[cfg(test)]
mod tests {
    /// The guide table finds the entry the bisection finds, for skewed and equal masses, zero
    /// masses, and draws at the cumulative masses themselves (where `<=` decides).
    #[test]
    fn guided_draws_pick_the_bisections_entry() {
        let mut rng = stream(4, 5, 6);
        for case in 0..200 {
            let mut scratch = RestrictedScratch::default();
            let n = 1 + case % 40;
            for k in 0..n {
                let u = crate::sim::math::rng::uniform(&mut rng);
                let mass = match case % 4 {
                    0 => 1.0,
                    1 => 1e-6 + u.powi(8) * 1e3,
                    2 => {
                        if k % 3 == 0 {
                            0.0
                        } else {
                            u
                        }
                    }
                    _ => {
                        if k < n / 2 {
                            1e4
                        } else {
                            1e-4
                        }
                    }
                };
                scratch.push(mass, 0, k, Kind::Reverse);
            }
            let total = scratch.total();
            if total == 0.0 {
                continue;
            }
            let bisect = |u: f64| scratch.bundle.partition_point(|e| e.cumulative <= u).min(n - 1);
            let mut draws: Vec<f64> = (0..50).map(|_| crate::sim::math::rng::uniform(&mut rng) * total).collect();
            draws.extend(scratch.bundle.iter().map(|e| e.cumulative).filter(|&c| c < total));
            let wanted: Vec<usize> = draws.iter().map(|&u| bisect(u)).collect();
            scratch.prepare_draws(draws.len() as u64);
            assert_eq!(scratch.guide.is_empty(), n <= 8, "case {case}: a guide for n = {n}");
            let found: Vec<usize> = draws.iter().map(|&u| scratch.find(u)).collect();
            assert_eq!(found, wanted, "case {case}");
        }
    }

    use super::*;
    use crate::sim::engines::merge::within;
    use crate::sim::math::rng::stream;
    use crate::sim::math::sampling::disc_point;
    use crate::sim::model::scene::{advance, sample_lobe};
    use nalgebra::Vector3;

    /// The forward reach bound is conservative: lobe-free straight rays (ϑ = 0 is within every
    /// bound) from the ring edge through points just inside ρ_max may still be far off, but no
    /// simulated deflected path through |x2| > ρ_max reaches the pixel disc.
    #[test]
    fn forward_reach_contains_every_hit() {
        let (beta, l2, l3, r, r_out) = (3f64.to_radians(), 1.0, 3.0, 0.05, 0.2);
        let rho = forward_reach(LOBE_MAX_SIGMAS * beta, l2, l3, r, r_out).unwrap();
        let lobe = crate::sim::model::scene::Lobe::new(beta);
        let mut rng = stream(1, 2, 3);
        let mut hits = 0;
        let mut max_hit: f64 = 0.0;
        for _ in 0..2_000_000 {
            let x3 = disc_point(&mut rng, [0.0, 0.0], r_out);
            let x2 = disc_point(&mut rng, [0.0, 0.0], 1.5 * rho);
            let d = Vector3::new(x2[0] - x3[0], x2[1] - x3[1], -l3).normalize();
            let (out, _) = sample_lobe(&lobe, &d, &mut rng);
            if out.z < 0.0 {
                let x1 = advance(x2, &out, -l2);
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
