//! The light's radial profile on plane 3: its density, its sampling, and its bright core.
//!
//! Every profile (spot, uniform, rings) is stored as rings: level `level` for r_in ≤ r < r_out.
//! The emitted flux is normalised to Φ = 1 (docs/model.md), so a light path's start x3l has the
//! density `I(|x3|)/Φ` and carries energy 1.
//!
//! Two samplers draw from that density: [`Illumination::sample`], one point at a time by
//! rejection (for tests and other engines), and [`Illumination::sample_block`], the light-path
//! loop's, which maps given random words to a whole block of points in polar form without a
//! branch, so that it vectorises.

use std::f64::consts::PI;

use super::params::{IlluminationSpec, MIN_RING_FLUX, SpecError, check};
use crate::sim::math::fastmath::sincos_turn;
use crate::sim::math::rng::{StreamRng, uniform, unit52};
use crate::sim::math::sampling::unit_disc_point;

/// One annulus of constant level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ring {
    /// Inner radius on plane 3 (the previous ring's outer radius; 0 for the first).
    pub r_in: f64,
    /// Outer radius on plane 3.
    pub r_out: f64,
    /// Unnormalised level (as in the spec).
    pub level: f64,
}

/// A piecewise-constant radial profile, ready to sample.
#[derive(Debug, Clone)]
pub struct Illumination {
    /// Rings with a positive level, innermost first (zero-level rings never emit).
    rings: Vec<Ring>,
    /// Total unnormalised flux Φ = Σ level·π(r_out² − r_in²).
    flux: f64,
    /// Cumulative probabilities of choosing each ring (the last is exactly 1).
    cumulative: Vec<f64>,
    /// How each ring is sampled.
    samplers: Vec<RingSampler>,
    /// Each ring's constants for [`Illumination::sample_block`].
    block: Vec<BlockRing>,
    /// Radius of the bright core used by the `switch` strategy.
    switch_radius: f64,
}

impl Illumination {
    /// Builds the profile from a validated specification.
    pub fn from_spec(spec: &IlluminationSpec) -> Self {
        let all: Vec<Ring> = match *spec {
            IlluminationSpec::Spot { a, r_ls, contrast } => {
                vec![Ring { r_in: 0.0, r_out: a, level: contrast }, Ring { r_in: a, r_out: r_ls, level: 1.0 }]
            }
            IlluminationSpec::Uniform { r_ls } => vec![Ring { r_in: 0.0, r_out: r_ls, level: 1.0 }],
            IlluminationSpec::Rings { ref rings } => {
                let mut inner = 0.0;
                rings
                    .iter()
                    .map(|r| {
                        let ring = Ring { r_in: inner, r_out: r.outer_radius, level: r.level };
                        inner = r.outer_radius;
                        ring
                    })
                    .collect()
            }
        };
        // The `switch` strategy of the paper uses plane 2 inside the bright spot (r3 ≤ a) and plane
        // 3 outside. Generalised: the spot's a; for rings, the outer radius of the innermost ring;
        // for a uniform disc there is no bright core and switch is plane 3 everywhere.
        let switch_radius = match *spec {
            IlluminationSpec::Spot { a, .. } => a,
            IlluminationSpec::Uniform { .. } => 0.0,
            IlluminationSpec::Rings { ref rings } => rings[0].outer_radius,
        };
        Self::from_rings(all, switch_radius)
    }

    fn from_rings(all: Vec<Ring>, switch_radius: f64) -> Self {
        let rings: Vec<Ring> = all.into_iter().filter(|r| r.level > 0.0).collect();
        let fluxes: Vec<f64> = rings.iter().map(|r| r.level * PI * (r.r_out * r.r_out - r.r_in * r.r_in)).collect();
        let flux: f64 = fluxes.iter().sum();
        let mut acc = 0.0;
        let mut cumulative: Vec<f64> = fluxes
            .iter()
            .map(|f| {
                acc += f;
                acc / flux
            })
            .collect();
        *cumulative.last_mut().expect("validation guarantees a ring with positive flux") = 1.0;
        let block = rings
            .iter()
            .zip(&cumulative)
            .scan(0.0, |below, (ring, &upto)| {
                let (lo, p) = (*below, upto - *below);
                *below = upto;
                let (r_in2, span2) = (ring.r_in * ring.r_in, ring.r_out * ring.r_out - ring.r_in * ring.r_in);
                // A ring of zero probability is never the last one chosen (its successor starts
                // at the same `lo`), so its gain is never used; 0 keeps it finite.
                Some(BlockRing { lo, r_in2, gain: if p > 0.0 { span2 / p } else { 0.0 } })
            })
            .collect();
        Self { samplers: rings.iter().map(RingSampler::new).collect(), block, rings, flux, cumulative, switch_radius }
    }

    /// The emitting rings, innermost first.
    pub fn rings(&self) -> &[Ring] {
        &self.rings
    }

    /// Total unnormalised flux Φ of the spec's levels.
    pub fn flux(&self) -> f64 {
        self.flux
    }

    /// Normalised density I(r)/Φ at radius r (the density of light-path starts per unit area).
    pub fn density(&self, r: f64) -> f64 {
        self.rings.iter().find(|ring| r >= ring.r_in && r < ring.r_out).map_or(0.0, |ring| ring.level / self.flux)
    }

    /// The bright-core radius of the `switch` strategy.
    pub fn switch_radius(&self) -> f64 {
        self.switch_radius
    }

    /// Largest radius that emits.
    pub fn outer_radius(&self) -> f64 {
        self.rings.last().map_or(0.0, |r| r.r_out)
    }

    /// A ring index drawn by the rings' shares of the flux (no draw for a single ring).
    #[inline(always)]
    fn choose_ring(&self, rng: &mut StreamRng) -> usize {
        if self.rings.len() == 1 {
            return 0;
        }
        let u = uniform(rng);
        // Few rings: a linear scan beats a binary search.
        let mut k = 0;
        while u >= self.cumulative[k] && k + 1 < self.cumulative.len() {
            k += 1;
        }
        k
    }

    /// Draws a start point x3l with density I/Φ: a ring by its share of the flux, then a point
    /// uniform in its area (see `RingSampler`).
    pub fn sample(&self, rng: &mut StreamRng) -> [f64; 2] {
        let k = self.choose_ring(rng);
        self.samplers[k].sample(rng)
    }

    /// Start points x3l for a block of light paths, with density I/Φ, from the paths' random words:
    /// point i uses the top 52 bits of `ring_bits[i]` for its ring and radius and the high 32 bits
    /// of `azimuth_bits[i]` for its azimuth. Branch-free over fixed-size arrays, so it vectorises.
    ///
    /// One uniform u picks the ring (u ∈ [c_{k−1}, c_k), c the cumulative flux shares) and, given
    /// the ring, (u − c_{k−1})/p_k is again uniform on [0, 1): it is reused as the ring's area
    /// fraction, r² = r_in² + (u − c_{k−1})/p_k·(r_out² − r_in²), so the point is uniform in the
    /// ring's area. Resolution and rounding: the ring probabilities are exact up to 2⁻⁵², the area
    /// fraction is on a grid of 2⁻⁵²/p_k with a rounding error of the same order, and r can
    /// exceed r_out by a relative 2⁻⁵¹ (all far below anything the statistics can resolve).
    #[inline(always)]
    pub fn sample_block<const B: usize>(&self, ring_bits: &[u64; B], azimuth_bits: &[u64; B], out: &mut [[f64; B]; 2]) {
        let mut r2 = [0.0; B];
        self.radius2_block(ring_bits, &mut r2);
        polar_block(|i| r2[i], azimuth_bits, out);
    }

    /// The squared radii r² of [`Illumination::sample_block`]'s start points, from the same words
    /// and by the same operations (`sample_block` takes their square roots): for the light-path
    /// loop's single-precision filter, which starts from r² rounded to f32.
    #[inline(always)]
    pub fn radius2_block<const B: usize>(&self, ring_bits: &[u64; B], out: &mut [f64; B]) {
        // The ring search is unrolled into selects for up to three rings (the paper's spot has
        // two); more rings take one pass over the block each.
        let u = |i: usize| unit52(ring_bits[i]);
        match self.block[..] {
            [a] => {
                for (i, r2) in out.iter_mut().enumerate() {
                    *r2 = a.radius2(u(i));
                }
            }
            [a, b] => {
                for (i, r2) in out.iter_mut().enumerate() {
                    let u = u(i);
                    *r2 = a.or_above(&b, u).radius2(u);
                }
            }
            [a, b, c] => {
                for (i, r2) in out.iter_mut().enumerate() {
                    let u = u(i);
                    *r2 = a.or_above(&b, u).or_above(&c, u).radius2(u);
                }
            }
            _ => {
                let first = &self.block[0];
                for (i, r2) in out.iter_mut().enumerate() {
                    *r2 = first.radius2(u(i));
                }
                for ring in &self.block[1..] {
                    for (i, r2) in out.iter_mut().enumerate() {
                        let u = u(i);
                        *r2 = if u >= ring.lo { ring.radius2(u) } else { *r2 };
                    }
                }
            }
        }
    }
}

/// Checks that every emitting ring of the profile `spec` describes emits at least
/// [`MIN_RING_FLUX`]; its ranges come first ([`validate_scene`](super::params::validate_scene)).
pub fn validate_flux(spec: &IlluminationSpec) -> Result<(), SpecError> {
    let f = "scene.illumination";
    let profile = Illumination::from_spec(spec);
    for ring in profile.rings() {
        let flux = ring.level * (ring.r_out * ring.r_out - ring.r_in * ring.r_in);
        check(flux >= MIN_RING_FLUX, f, || {
            format!(
                "the ring [{}, {}) with level {} emits a flux of {flux:e}; every emitting ring needs at least \
                 {MIN_RING_FLUX:e} (level × (r_out² − r_in²))",
                ring.r_in, ring.r_out, ring.level
            )
        })?;
    }
    Ok(())
}

/// Points at squared radius `radius2(i)` and the azimuth in the high half of `azimuth_bits[i]`.
#[inline(always)]
fn polar_block<const B: usize>(radius2: impl Fn(usize) -> f64, azimuth_bits: &[u64; B], out: &mut [[f64; B]; 2]) {
    let [ox, oy] = out;
    for i in 0..B {
        let r = radius2(i).sqrt();
        let (sin, cos) = sincos_turn((azimuth_bits[i] >> 32) as u32);
        ox[i] = r * cos;
        oy[i] = r * sin;
    }
}

/// One ring's constants for [`Illumination::sample_block`].
#[derive(Debug, Clone, Copy)]
struct BlockRing {
    /// Probability of the rings inside it, c_{k−1}.
    lo: f64,
    /// r_in².
    r_in2: f64,
    /// (r_out² − r_in²)/p_k: maps u − c_{k−1} ∈ [0, p_k) to r² − r_in².
    gain: f64,
}

impl BlockRing {
    /// r² for the uniform u, given that u chose this ring.
    #[inline(always)]
    fn radius2(&self, u: f64) -> f64 {
        (u - self.lo).mul_add(self.gain, self.r_in2)
    }

    /// `next` if u reaches it, else this ring: field by field, so that it compiles to selects.
    #[inline(always)]
    fn or_above(&self, next: &BlockRing, u: f64) -> BlockRing {
        let above = u >= next.lo;
        BlockRing {
            lo: if above { next.lo } else { self.lo },
            r_in2: if above { next.r_in2 } else { self.r_in2 },
            gain: if above { next.gain } else { self.gain },
        }
    }
}

/// Uniform sampling of one annulus r_in ≤ r < r_out, without trigonometry.
///
/// A point (u, v) uniform in the unit disc (by rejection) has a uniform direction (u, v)/ρ and an
/// independent ρ² ~ U(0, 1). A thin-holed annulus (hole area < ½ of the disc, like the paper's dim
/// ring [0.02, 20], which rejects 10⁻⁶ of its points) keeps r_out·(u, v) and redraws points in the
/// hole — no division or square root on the hot path. Otherwise ρ² is mapped to
/// r² = r_in² + ρ²(r_out² − r_in²), uniform in area over the annulus.
#[derive(Debug, Clone, Copy)]
enum RingSampler {
    Reject { r_out: f64, hole2: f64 },
    Map { r_in2: f64, span2: f64 },
}

impl RingSampler {
    fn new(ring: &Ring) -> Self {
        let hole2 = (ring.r_in / ring.r_out).powi(2);
        if hole2 < 0.5 {
            Self::Reject { r_out: ring.r_out, hole2 }
        } else {
            Self::Map { r_in2: ring.r_in * ring.r_in, span2: ring.r_out * ring.r_out - ring.r_in * ring.r_in }
        }
    }

    #[inline(always)]
    fn sample(&self, rng: &mut StreamRng) -> [f64; 2] {
        match *self {
            Self::Reject { r_out, hole2 } => loop {
                let (u, v, rho2) = unit_disc_point(rng);
                if rho2 >= hole2 {
                    return [u * r_out, v * r_out];
                }
            },
            Self::Map { r_in2, span2 } => {
                let (u, v, rho2) = unit_disc_point(rng);
                let scale = ((r_in2 + rho2 * span2) / rho2).sqrt();
                [u * scale, v * scale]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::rng::stream;

    fn paper() -> Illumination {
        Illumination::from_spec(&IlluminationSpec::Spot { a: 0.02, r_ls: 20.0, contrast: 1e6 / 300.0 })
    }

    #[test]
    fn flux_and_density() {
        let ill = paper();
        let expected = 1e6 / 300.0 * PI * 0.02f64.powi(2) + PI * (400.0 - 0.0004);
        assert!((ill.flux() - expected).abs() < 1e-9);
        assert!((ill.density(0.01) * expected - 1e6 / 300.0).abs() < 1e-9);
        assert!((ill.density(5.0) * expected - 1.0).abs() < 1e-12);
        assert_eq!(ill.density(25.0), 0.0);
        assert_eq!(ill.switch_radius(), 0.02);
    }

    /// Sampled starts: the share in the spot, and the share in an inner annulus of the dim part,
    /// against their exact probabilities, within 4 standard errors of a binomial count.
    #[test]
    fn samples_follow_the_profile() {
        let ill = paper();
        let n = 2_000_000u32;
        let mut rng = stream(11, 0, 0);
        let (mut in_spot, mut in_band, mut sum_r2) = (0u32, 0u32, 0.0);
        for _ in 0..n {
            let [x, y] = ill.sample(&mut rng);
            let r = (x * x + y * y).sqrt();
            assert!(r < 20.0);
            in_spot += u32::from(r <= 0.02);
            in_band += u32::from((5.0..10.0).contains(&r));
            sum_r2 += r * r;
        }
        let check = |count: u32, p: f64, what: &str| {
            let mean = f64::from(n) * p;
            let se = (f64::from(n) * p * (1.0 - p)).sqrt();
            assert!((f64::from(count) - mean).abs() < 4.0 * se, "{what}: {count} vs {mean} ± {se}");
        };
        check(in_spot, 1e6 / 300.0 * PI * 0.0004 / ill.flux(), "spot");
        check(in_band, PI * (100.0 - 25.0) / ill.flux(), "5 ≤ r < 10");
        // E[r²] = Σ level·π(r_out⁴ − r_in⁴)/2 / Φ; the SE uses E[r⁴] of the dim disc (≈ r_ls⁴/3).
        let e_r2 =
            (1e6 / 300.0 * PI * 0.02f64.powi(4) / 2.0 + PI * (20f64.powi(4) - 0.02f64.powi(4)) / 2.0) / ill.flux();
        let e_r4 = 20f64.powi(4) / 3.0 * (PI * 400.0 / ill.flux());
        let se = ((e_r4 - e_r2 * e_r2) / f64::from(n)).sqrt();
        assert!((sum_r2 / f64::from(n) - e_r2).abs() < 4.0 * se, "E[r²]");
    }

    /// A thick ring (rejection) and a thin ring (mapping) are both uniform in area: the share of
    /// points in the inner half of the area is ½ within 4 standard errors.
    #[test]
    fn both_ring_samplers_are_uniform_in_area() {
        for (r_in, r_out) in [(0.1, 1.0), (0.9, 1.0)] {
            let sampler = RingSampler::new(&Ring { r_in, r_out, level: 1.0 });
            assert_eq!(matches!(sampler, RingSampler::Reject { .. }), r_in < 0.5);
            let median2 = 0.5 * (r_in * r_in + r_out * r_out);
            let mut rng = stream(4, 5, 6);
            let n = 400_000;
            let mut inner = 0u32;
            for _ in 0..n {
                let [x, y] = sampler.sample(&mut rng);
                let r2 = x * x + y * y;
                assert!(r2 >= r_in * r_in * (1.0 - 1e-12) && r2 < r_out * r_out);
                inner += u32::from(r2 < median2);
            }
            let se = (0.25 / f64::from(n)).sqrt();
            assert!((f64::from(inner) / f64::from(n) - 0.5).abs() < 4.0 * se, "[{r_in}, {r_out})");
        }
    }

    /// The block sampler draws from the same law as the single-point sampler: the spot's share,
    /// an inner band's share and E[r²] within 4 standard errors, and uniform azimuths (E[cos φ],
    /// E[sin φ] ≈ 0), over many blocks of random words.
    #[test]
    fn block_sampling_follows_the_profile() {
        let ill = paper();
        let mut rng = crate::sim::math::rng::LaneRng::new(12, 0, 0);
        let mut bits = [[0u64; 128]; 2];
        let mut out = [[0.0; 128]; 2];
        let (mut n, mut in_spot, mut in_band, mut sum_r2, mut sum_cos, mut sum_sin) = (0u32, 0u32, 0u32, 0.0, 0.0, 0.0);
        for _ in 0..16_000 {
            rng.fill(bits.as_flattened_mut());
            ill.sample_block(&bits[0], &bits[1], &mut out);
            for (x, y) in out[0].iter().zip(&out[1]) {
                let r = x.hypot(*y);
                assert!(r <= 20.0 * (1.0 + 1e-15));
                n += 1;
                in_spot += u32::from(r <= 0.02);
                in_band += u32::from((5.0..10.0).contains(&r));
                sum_r2 += r * r;
                if r > 0.0 {
                    sum_cos += x / r;
                    sum_sin += y / r;
                }
            }
        }
        let nf = f64::from(n);
        let check = |count: u32, p: f64, what: &str| {
            let se = (nf * p * (1.0 - p)).sqrt();
            assert!((f64::from(count) - nf * p).abs() < 4.0 * se, "{what}: {count} vs {} ± {se}", nf * p);
        };
        check(in_spot, 1e6 / 300.0 * PI * 0.0004 / ill.flux(), "spot");
        check(in_band, PI * (100.0 - 25.0) / ill.flux(), "5 ≤ r < 10");
        let e_r2 =
            (1e6 / 300.0 * PI * 0.02f64.powi(4) / 2.0 + PI * (20f64.powi(4) - 0.02f64.powi(4)) / 2.0) / ill.flux();
        let e_r4 = 20f64.powi(4) / 3.0 * (PI * 400.0 / ill.flux());
        assert!((sum_r2 / nf - e_r2).abs() < 4.0 * ((e_r4 - e_r2 * e_r2) / nf).sqrt(), "E[r²]");
        let se = (0.5 / nf).sqrt();
        assert!((sum_cos / nf).abs() < 4.0 * se && (sum_sin / nf).abs() < 4.0 * se, "azimuth");
    }

    /// Rings chosen by the block sampler, for each way it selects them (one ring; two and three
    /// rings unrolled, with a zero-level ring in between; five rings pass by pass): every point
    /// lies in an emitting ring, each ring gets its flux share within 4 standard errors, and the
    /// points of each ring are uniform in its area (the share in its inner half-area is ½).
    #[test]
    fn block_sampling_of_many_rings() {
        use crate::sim::model::params::RingSpec;
        let specs: [&[(f64, f64)]; 4] = [
            &[(1.5, 1.0)],
            &[(1.0, 2.0), (2.0, 0.0), (2.1, 5.0)],
            &[(1.0, 2.0), (2.0, 0.0), (2.1, 5.0), (3.0, 1.0)],
            &[(0.5, 9.0), (1.0, 2.0), (1.2, 0.5), (2.0, 3.0), (2.1, 5.0), (3.0, 1.0)],
        ];
        for (seed, spec) in specs.into_iter().enumerate() {
            let rings = spec.iter().map(|&(outer_radius, level)| RingSpec { outer_radius, level }).collect();
            let ill = Illumination::from_spec(&IlluminationSpec::Rings { rings });
            let emitting = ill.rings().to_vec();
            let mut rng = crate::sim::math::rng::LaneRng::new(3, 1, seed as u64);
            let mut bits = [[0u64; 64]; 2];
            let mut out = [[0.0; 64]; 2];
            let (mut counts, mut inner) = (vec![0u32; emitting.len()], vec![0u32; emitting.len()]);
            for _ in 0..4000 {
                rng.fill(bits.as_flattened_mut());
                ill.sample_block(&bits[0], &bits[1], &mut out);
                for (x, y) in out[0].iter().zip(&out[1]) {
                    let r2 = x * x + y * y;
                    let slack = |r: f64| r * r * 1e-14;
                    let k = emitting
                        .iter()
                        .position(|g| r2 >= g.r_in * g.r_in - slack(g.r_in) && r2 <= g.r_out * g.r_out + slack(g.r_out))
                        .unwrap_or_else(|| panic!("r = {} in no emitting ring of {spec:?}", r2.sqrt()));
                    counts[k] += 1;
                    let ring = &emitting[k];
                    inner[k] += u32::from(r2 < 0.5 * (ring.r_in * ring.r_in + ring.r_out * ring.r_out));
                }
            }
            let n = f64::from(counts.iter().sum::<u32>());
            for (k, ring) in emitting.iter().enumerate() {
                let p = ring.level * PI * (ring.r_out.powi(2) - ring.r_in.powi(2)) / ill.flux();
                let se = (n * p * (1.0 - p)).sqrt();
                let what = format!("{spec:?}, ring {k}");
                assert!((f64::from(counts[k]) - n * p).abs() <= 4.0 * se, "{what}: {} vs {}", counts[k], n * p);
                let m = f64::from(counts[k]);
                assert!((f64::from(inner[k]) - m / 2.0).abs() < 4.0 * (m / 4.0).sqrt(), "{what}: inner half");
            }
        }
    }

    #[test]
    fn zero_level_rings_never_emit() {
        let ill = Illumination::from_spec(&IlluminationSpec::Rings {
            rings: vec![
                crate::sim::model::params::RingSpec { outer_radius: 1.0, level: 0.0 },
                crate::sim::model::params::RingSpec { outer_radius: 2.0, level: 3.0 },
            ],
        });
        let mut rng = stream(1, 2, 3);
        for _ in 0..10_000 {
            let [x, y] = ill.sample(&mut rng);
            let r = (x * x + y * y).sqrt();
            assert!((1.0..2.0).contains(&r), "{r}");
        }
        assert_eq!(ill.switch_radius(), 1.0);
    }
}
