//! The light's radial profile on plane 3: its density, its sampling, and its bright core.
//!
//! Every profile (spot, uniform, rings) is stored as rings: level `level` for r_in ≤ r < r_out.
//! The emitted flux is normalised to Φ = 1 (model.md), so a light path's start x3l has the
//! density `I(|x3|)/Φ` and carries energy 1.

use std::f64::consts::PI;

use super::rng::{StreamRng, symmetric_pair, uniform};
use super::spec::IlluminationSpec;

/// One annulus of constant level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ring {
    pub r_in: f64,
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
        Self { samplers: rings.iter().map(RingSampler::new).collect(), rings, flux, cumulative, switch_radius }
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
    /// uniform in its area (see [`RingSampler`]).
    pub fn sample(&self, rng: &mut StreamRng) -> [f64; 2] {
        let k = self.choose_ring(rng);
        self.samplers[k].sample(rng)
    }

    /// Fills `out[..][..n]` with start points, block-wise for the light-path loop: first every
    /// ring choice, then unit-disc points for all (branch-free rejection, into `disc`), then the
    /// per-ring mapping; the rare point that falls in a rejection sampler's hole is redrawn on the
    /// spot. Same law as [`Illumination::sample`], different (but fixed) order of draws.
    #[inline(always)]
    pub fn sample_block<const B: usize>(
        &self,
        rng: &mut StreamRng,
        rings: &mut [u8],
        disc: &mut [[f64; B]; 3],
        out: &mut [[f64; B]; 2],
        n: usize,
    ) {
        for r in rings[..n].iter_mut() {
            *r = self.choose_ring(rng) as u8;
        }
        let [u, v, rho2] = disc;
        fill_unit_disc(rng, &mut u[..n], &mut v[..n], &mut rho2[..n]);
        let [ox, oy] = out;
        for i in 0..n {
            let p = match self.samplers[rings[i] as usize] {
                RingSampler::Reject { r_out, hole2 } if rho2[i] >= hole2 => [u[i] * r_out, v[i] * r_out],
                RingSampler::Map { r_in2, span2 } => {
                    let scale = ((r_in2 + rho2[i] * span2) / rho2[i]).sqrt();
                    [u[i] * scale, v[i] * scale]
                }
                sampler => sampler.sample(rng),
            };
            ox[i] = p[0];
            oy[i] = p[1];
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

/// Fills `u`, `v`, `rho2` (of equal length) with points uniform in the open unit disc minus its
/// centre and their squared radii, by rejection from the square without a data-dependent branch:
/// every candidate is written, and the write position advances only when it is accepted.
#[inline(always)]
pub fn fill_unit_disc(rng: &mut StreamRng, u: &mut [f64], v: &mut [f64], rho2: &mut [f64]) {
    let n = u.len().min(v.len()).min(rho2.len());
    let mut i = 0;
    while i < n {
        let (a, b) = symmetric_pair(rng);
        let r2 = a * a + b * b;
        u[i] = a;
        v[i] = b;
        rho2[i] = r2;
        i += usize::from((r2 < 1.0) & (r2 > 0.0));
    }
}

/// A point uniform in the open unit disc minus its centre, by rejection from the square (accepted
/// with probability π/4), with its squared radius.
#[inline(always)]
pub fn unit_disc_point(rng: &mut StreamRng) -> (f64, f64, f64) {
    loop {
        let (u, v) = symmetric_pair(rng);
        let rho2 = u * u + v * v;
        if rho2 < 1.0 && rho2 > 0.0 {
            return (u, v, rho2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::stream;

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

    /// The block sampler draws from the same law as the single-point sampler: spot share and
    /// E[r²] over many blocks, within 4 standard errors.
    #[test]
    fn block_sampling_follows_the_profile() {
        let ill = paper();
        let mut rng = stream(12, 0, 0);
        let (mut rings, mut disc, mut out) = ([0u8; 100], [[0.0; 100]; 3], [[0.0; 100]; 2]);
        let (mut n, mut in_spot) = (0u32, 0u32);
        for _ in 0..20_000 {
            ill.sample_block(&mut rng, &mut rings, &mut disc, &mut out, 100);
            for (x, y) in out[0].iter().zip(&out[1]) {
                let r = x.hypot(*y);
                n += 1;
                in_spot += u32::from(r <= 0.02);
                assert!(r < 20.0);
            }
        }
        let p = 1e6 / 300.0 * PI * 0.0004 / ill.flux();
        let se = (f64::from(n) * p * (1.0 - p)).sqrt();
        assert!((f64::from(in_spot) - f64::from(n) * p).abs() < 4.0 * se);
    }

    #[test]
    fn zero_level_rings_never_emit() {
        let ill = Illumination::from_spec(&IlluminationSpec::Rings {
            rings: vec![
                crate::sim::spec::RingSpec { outer_radius: 1.0, level: 0.0 },
                crate::sim::spec::RingSpec { outer_radius: 2.0, level: 3.0 },
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
