//! The model scene of docs/model.md: three parallel diffusely transmitting planes, the sharp
//! plane-2 lobe, and the light's profile on plane 3.
//!
//! Frames and units: plane 1 is z = 0, plane 2 is z = L2, plane 3 is z = L2 + L3; positions on a
//! plane are 2-D `(x, y)`; directions are unit 3-D vectors of *travel* (a light particle going from
//! plane 3 to plane 2 has a negative z component). Angles are in radians inside the core (the spec
//! gives β in degrees). Flux is normalised to Φ = 1 (docs/model.md §2, a decision).

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::illumination::Illumination;
use super::params::SceneSpec;
use crate::sim::math::rng::{StreamRng, uniform, uniform_open0};
use crate::sim::math::sampling::deflect;

/// The plane-2 transmission lobe.
///
/// BDF (docs/model.md §1): f2(ω_in, ω_out) = g(ϑ) / cos γ with g(ϑ) = exp(−ϑ²/2β²) / (2πβ²), ϑ the angle
/// between the incident and the scattered direction of travel, γ the angle between the scattered
/// direction and the normal.
///
/// Sampling (see [`crate::sim::model::scene::sample_lobe`]) draws ϑ = β·√(−2 ln u) and a uniform azimuth
/// around the incident direction: ϑ has the Rayleigh density (ϑ/β²)·exp(−ϑ²/2β²), so the exact
/// solid-angle pdf of the sampled direction is `pdf_w(ϑ) = g(ϑ)·ϑ/sin ϑ`. A particle scattered this
/// way carries the throughput f2·cos γ / pdf_w = sin ϑ/ϑ (≈ 1 − ϑ²/6): we keep this exact factor
/// rather than the "energy 1" of the model's first reading, its small-angle limit (docs/model.md §3).
#[derive(Debug, Clone, Copy)]
pub struct Lobe {
    /// β in radians.
    pub beta: f64,
    /// 1 / (2πβ²): the peak value g(0).
    norm: f64,
    /// 1 / (2β²).
    inv_two_beta2: f64,
}

impl Lobe {
    /// The lobe of width `beta` (radians, > 0).
    pub fn new(beta: f64) -> Self {
        Self { beta, norm: 1.0 / (2.0 * PI * beta * beta), inv_two_beta2: 1.0 / (2.0 * beta * beta) }
    }

    /// g(ϑ), the angular part of the BDF.
    #[inline]
    pub fn g(&self, theta: f64) -> f64 {
        self.norm * libm::exp(-theta * theta * self.inv_two_beta2)
    }

    /// The BDF f2 for a deflection ϑ and a scattered direction with cos γ = `cos_out`.
    #[inline]
    pub fn bdf(&self, theta: f64, cos_out: f64) -> f64 {
        self.g(theta) / cos_out
    }

    /// Solid-angle pdf of a direction at angle ϑ from the axis, as drawn by `sample_lobe`.
    #[inline]
    pub fn pdf_w(&self, theta: f64) -> f64 {
        self.g(theta) * theta_over_sin(theta)
    }
}

/// The largest deflection the lobe sampler can return, in units of β: the smallest uniform is
/// 2⁻⁵³, so ϑ ≤ β·√(−2 ln 2⁻⁵³) = β·√(106 ln 2) ≈ 8.57β. Beyond it the sampled density is zero
/// (the missing mass is 2⁻⁵³). The light-path loop uses this bound to skip lobe sampling for paths
/// that cannot reach the pixel's merge disc.
pub const LOBE_MAX_SIGMAS: f64 = 8.571_674_5;

/// Deflects the unit direction `axis` by the plane-2 lobe: ϑ = β·√(−2 ln u₁), azimuth 2πu₂.
/// Returns the new unit direction and ϑ.
#[inline]
pub fn sample_lobe(lobe: &Lobe, axis: &Vector3<f64>, rng: &mut StreamRng) -> (Vector3<f64>, f64) {
    let theta = lobe.beta * (-2.0 * libm::log(uniform_open0(rng))).sqrt();
    let psi = std::f64::consts::TAU * uniform(rng);
    (deflect(axis, theta, psi), theta)
}

/// ϑ / sin ϑ, continuous at 0 (where it is 1).
#[inline]
pub fn theta_over_sin(theta: f64) -> f64 {
    if theta < 1e-4 { 1.0 + theta * theta / 6.0 } else { theta / libm::sin(theta) }
}

/// The angle between two unit vectors, accurate for small angles (atan2 of |a×b| and a·b).
#[inline]
pub fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    libm::atan2(a.cross(b).norm(), a.dot(b))
}

/// Where the line through `x`, a point of one plane, with direction `d` meets the plane `dz`
/// higher: x + (dz / d.z)·(d.x, d.y), for `d.z ≠ 0`.
///
/// The one plane-to-plane step of both engines. Heights grow along +z in the frames above (plane 1
/// at 0, plane 2 at L2, plane 3 at L2 + L3) whatever the direction of travel, so every caller
/// names its target plane the same way: plane 2 → 3 is `dz = +L3`, 3 → 2 is `−L3`, 2 → 1 is `−L2`,
/// and the sign of `d.z` never enters the call. Evaluated as (dz·d_x)/d_z so that the forms the
/// engines used before (`x2 − L2·out_x/out_z`, `x2 + L3·e_x/e_z`) give the same bits. The two
/// vectorised loops that know tan θ and the azimuth already (the brute force's light paths, the
/// camera's first segment) use the polar form x + dz·tan θ·(cos φ, sin φ) of the same step;
/// `advance_matches_the_polar_form` checks that they agree.
#[inline(always)]
pub fn advance(x: [f64; 2], d: &Vector3<f64>, dz: f64) -> [f64; 2] {
    [x[0] + dz * d.x / d.z, x[1] + dz * d.y / d.z]
}

/// The scene with its derived constants.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The specification it was built from (kept for fingerprints and reports).
    pub spec: SceneSpec,
    /// Distance plane 1 → plane 2.
    pub l2: f64,
    /// Distance plane 2 → plane 3.
    pub l3: f64,
    /// The plane-2 lobe that deflects light paths.
    pub lobe: Lobe,
    /// The emission on plane 3: a piecewise-constant radial profile I(r), ready to sample.
    pub illumination: Illumination,
}

impl Scene {
    /// Builds the scene from a validated specification.
    pub fn from_spec(spec: &SceneSpec) -> Self {
        Self {
            spec: spec.clone(),
            l2: spec.l2,
            l3: spec.l3,
            lobe: Lobe::new(spec.beta_deg.to_radians()),
            illumination: Illumination::from_spec(&spec.illumination),
        }
    }

    /// The unit direction of travel from a point `x2` of plane 2 to the camera's pixel at the
    /// origin of plane 1, and cos γ of that direction.
    #[inline]
    pub fn towards_pixel(&self, x2: [f64; 2]) -> (Vector3<f64>, f64) {
        let d = Vector3::new(-x2[0], -x2[1], -self.l2);
        let len = d.norm();
        (d / len, self.l2 / len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::rng::{stream, uniform};
    use crate::sim::math::sampling::orthonormal_basis;
    use crate::sim::math::sampling::tests::{assert_close, mean_se};

    /// `advance` lands on the target plane (the point is on the line through x along d, `dz`
    /// higher), goes back where it came from, and agrees with the polar form the vectorised loops
    /// use, x + dz·tan θ·(cos φ, sin φ) for d = (sin θ cos φ, sin θ sin φ, ±cos θ), to rounding.
    #[test]
    fn advance_matches_the_polar_form() {
        let mut rng = stream(6, 1, 3);
        for _ in 0..100_000 {
            let (s2, turn) = (uniform(&mut rng), uniform(&mut rng));
            let (c2, (sp, cp)) = (1.0 - s2, libm::sincos(std::f64::consts::TAU * turn));
            let tan = (s2 / c2).sqrt();
            let (x, dz) = ([uniform(&mut rng) - 0.5, uniform(&mut rng) - 0.5], 3.0 * uniform(&mut rng) - 1.5);
            for z_sign in [1.0, -1.0] {
                let d = Vector3::new(s2.sqrt() * cp, s2.sqrt() * sp, z_sign * c2.sqrt());
                let y = advance(x, &d, dz);
                let polar = [x[0] + z_sign * dz * tan * cp, x[1] + z_sign * dz * tan * sp];
                let scale = 1.0 + (dz * tan).abs();
                assert!((y[0] - polar[0]).abs() <= 1e-14 * scale && (y[1] - polar[1]).abs() <= 1e-14 * scale);
                // On the line: (y − x) ∥ d_xy with the length dz/d.z along d.
                let t = dz / d.z;
                assert!((y[0] - x[0] - t * d.x).abs() <= 1e-14 * scale);
                let back = advance(y, &d, -dz);
                assert!((back[0] - x[0]).abs() <= 1e-13 * scale && (back[1] - x[1]).abs() <= 1e-13 * scale);
            }
        }
    }

    #[test]
    fn lobe_bound_matches_the_smallest_uniform() {
        let exact = (-2.0 * (2f64.powi(-53)).ln()).sqrt();
        assert!(LOBE_MAX_SIGMAS >= exact && LOBE_MAX_SIGMAS - exact < 1e-6);
    }

    /// The lobe: ϑ is Rayleigh(β): E[ϑ²] = 2β², E[ϑ] = β√(π/2); the azimuth is uniform; and the
    /// returned direction really is at angle ϑ from the axis, for an oblique axis.
    #[test]
    fn lobe_deflections_are_gaussian_on_the_sphere() {
        let beta = 3f64.to_radians();
        let lobe = Lobe::new(beta);
        let axis = Vector3::new(0.3, -0.5, -0.8).normalize();
        let (t, b) = orthonormal_basis(&axis);
        let n = 1_000_000;
        let mut rng = stream(6, 1, 2);
        let draws: Vec<(Vector3<f64>, f64)> = (0..n).map(|_| sample_lobe(&lobe, &axis, &mut rng)).collect();
        for (d, theta) in draws.iter().take(10_000) {
            assert!((d.norm() - 1.0).abs() < 1e-12);
            assert!((angle_between(d, &axis) - theta).abs() < 1e-9);
        }
        let mut it = draws.iter();
        assert_close("E[ϑ²]", mean_se(n, || it.next().unwrap().1.powi(2)), 2.0 * beta * beta);
        let mut it = draws.iter();
        assert_close("E[ϑ]", mean_se(n, || it.next().unwrap().1), beta * (PI / 2.0).sqrt());
        // Azimuth: the deflection's components along t and b have mean zero and equal spread.
        let mut it = draws.iter();
        assert_close(
            "E[cos ψ]",
            mean_se(n, || {
                let (d, th) = it.next().unwrap();
                d.dot(&t) / th.sin()
            }),
            0.0,
        );
        let mut it = draws.iter();
        assert_close(
            "E[sin ψ]",
            mean_se(n, || {
                let (d, th) = it.next().unwrap();
                d.dot(&b) / th.sin()
            }),
            0.0,
        );
        let mut it = draws.iter();
        assert_close(
            "E[cos 2ψ]",
            mean_se(n, || {
                let (d, th) = it.next().unwrap();
                let (c, s) = (d.dot(&t) / th.sin(), d.dot(&b) / th.sin());
                c * c - s * s
            }),
            0.0,
        );
    }

    #[test]
    fn lobe_is_normalised_on_the_sphere() {
        // ∫ g(ϑ)·(ϑ/sinϑ) dω = 1 exactly (it is the sampler's pdf), i.e. ∫₀^∞ g·ϑ·2π dϑ = 1.
        let lobe = Lobe::new(3f64.to_radians());
        let n = 200_000;
        let upper = 12.0 * lobe.beta;
        let h = upper / f64::from(n);
        let integral: f64 = (0..n)
            .map(|i| {
                let t = (f64::from(i) + 0.5) * h;
                lobe.pdf_w(t) * libm::sin(t) * 2.0 * PI * h
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-9, "{integral}");
    }

    #[test]
    fn bdf_conserves_energy_to_order_beta_squared() {
        // ∫ f2 cos γ dω = ∫ g dω ≈ 1 − β²/3 for a narrow lobe around the normal.
        let beta = 3f64.to_radians();
        let lobe = Lobe::new(beta);
        let n = 200_000;
        let upper = 12.0 * beta;
        let h = upper / f64::from(n);
        let integral: f64 = (0..n)
            .map(|i| {
                let t = (f64::from(i) + 0.5) * h;
                lobe.g(t) * libm::sin(t) * 2.0 * PI * h
            })
            .sum();
        let expected = 1.0 - beta * beta / 3.0;
        assert!((integral - expected).abs() < 1e-6, "{integral} vs {expected}");
    }

    #[test]
    fn angles_are_accurate_near_zero() {
        let a = Vector3::new(0.0, 0.0, 1.0);
        let b = Vector3::new(1e-9, 0.0, 1.0).normalize();
        assert!((angle_between(&a, &b) - 1e-9).abs() < 1e-20);
        assert!((theta_over_sin(1e-5) - 1.0).abs() < 1e-10);
        assert!((theta_over_sin(0.5) - 0.5 / 0.5f64.sin()).abs() < 1e-15);
    }
}
