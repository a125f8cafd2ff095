//! Direction sampling: Lambert (cosine) transmission and the plane-2 Gaussian lobe.
//!
//! Both samplers are exact draws from the densities the estimators divide by: the cosine sampler
//! by Malley's method (a uniform disc point lifted to the hemisphere, pdf_w = cos θ/π), the lobe by
//! inverting the Rayleigh CDF of ϑ on the sphere (pdf_w = g(ϑ)·ϑ/sin ϑ, see [`super::scene::Lobe`]).

use nalgebra::Vector3;

use super::illumination::unit_disc_point;
use super::rng::{StreamRng, uniform, uniform_open0};
use super::scene::Lobe;

/// The largest deflection the lobe sampler can return, in units of β: the smallest uniform is
/// 2⁻⁵³, so ϑ ≤ β·√(−2 ln 2⁻⁵³) = β·√(106 ln 2) ≈ 8.57β. Beyond it the sampled density is zero
/// (the missing mass is 2⁻⁵³). The light-path loop uses this bound to skip lobe sampling for paths
/// that cannot reach the pixel's merge disc.
pub const LOBE_MAX_SIGMAS: f64 = 8.571_674_5;

/// A cosine-distributed direction about +z, as (x, y, z) with z = cos θ > 0 (Malley's method:
/// a uniform point of the unit disc projected up to the hemisphere).
#[inline(always)]
pub fn cosine_direction(rng: &mut StreamRng) -> Vector3<f64> {
    let (u, v, rho2) = unit_disc_point(rng);
    Vector3::new(u, v, (1.0 - rho2).sqrt())
}

/// Two unit vectors completing `n` to a right-handed orthonormal basis (Duff et al. 2017,
/// "Building an orthonormal basis, revisited": branch-free, no normalisation).
#[inline]
pub fn orthonormal_basis(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let sign = 1f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vector3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vector3::new(b, sign + n.y * n.y * a, -n.y))
}

/// Deflects the unit direction `axis` by the plane-2 lobe: ϑ = β·√(−2 ln u₁), azimuth 2πu₂.
/// Returns the new unit direction and ϑ.
#[inline]
pub fn sample_lobe(lobe: &Lobe, axis: &Vector3<f64>, rng: &mut StreamRng) -> (Vector3<f64>, f64) {
    let theta = lobe.beta * (-2.0 * libm::log(uniform_open0(rng))).sqrt();
    let psi = std::f64::consts::TAU * uniform(rng);
    (deflect(axis, theta, psi), theta)
}

/// The unit direction at angle `theta` from `axis`, at azimuth `psi` in the basis of
/// [`orthonormal_basis`].
#[inline]
pub fn deflect(axis: &Vector3<f64>, theta: f64, psi: f64) -> Vector3<f64> {
    let (t, b) = orthonormal_basis(axis);
    let (sin_t, cos_t) = libm::sincos(theta);
    let (sin_p, cos_p) = libm::sincos(psi);
    axis * cos_t + (t * cos_p + b * sin_p) * sin_t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::stream;
    use crate::sim::scene::angle_between;

    /// Mean and standard error of f over n samples.
    fn mean_se(n: usize, mut f: impl FnMut() -> f64) -> (f64, f64) {
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let x = f();
            s1 += x;
            s2 += x * x;
        }
        let m = s1 / n as f64;
        (m, ((s2 / n as f64 - m * m) / n as f64).sqrt())
    }

    fn assert_close(what: &str, (m, se): (f64, f64), exact: f64) {
        assert!((m - exact).abs() < 4.0 * se, "{what}: {m} ± {se} vs exact {exact}");
    }

    #[test]
    fn lobe_bound_matches_the_smallest_uniform() {
        let exact = (-2.0 * (2f64.powi(-53)).ln()).sqrt();
        assert!(LOBE_MAX_SIGMAS >= exact && LOBE_MAX_SIGMAS - exact < 1e-6);
    }

    /// Lambert directions: E[cos θ] = 2/3, E[cos² θ] = 1/2, E[x] = 0, and P(θ < 30°) = sin² 30°
    /// = 1/4, within 4 standard errors.
    #[test]
    fn cosine_directions_are_lambertian() {
        let n = 1_000_000;
        let mut rng = stream(5, 0, 0);
        let dirs: Vec<_> = (0..n).map(|_| cosine_direction(&mut rng)).collect();
        for d in &dirs {
            assert!((d.norm() - 1.0).abs() < 1e-12 && d.z > 0.0);
        }
        let mut it = dirs.iter();
        assert_close("E[cos θ]", mean_se(n, || it.next().unwrap().z), 2.0 / 3.0);
        let mut it = dirs.iter();
        assert_close("E[cos² θ]", mean_se(n, || it.next().unwrap().z.powi(2)), 0.5);
        let mut it = dirs.iter();
        assert_close("E[x]", mean_se(n, || it.next().unwrap().x), 0.0);
        let cos30 = 30f64.to_radians().cos();
        let mut it = dirs.iter();
        assert_close("P(θ < 30°)", mean_se(n, || f64::from(u8::from(it.next().unwrap().z > cos30))), 0.25);
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
        assert_close("E[ϑ]", mean_se(n, || it.next().unwrap().1), beta * (std::f64::consts::PI / 2.0).sqrt());
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
    fn basis_is_orthonormal_even_near_minus_z() {
        for n in [Vector3::z(), -Vector3::z(), Vector3::new(1e-9, 0.0, -1.0).normalize(), Vector3::new(0.6, 0.0, 0.8)] {
            let (t, b) = orthonormal_basis(&n);
            for (x, y) in [(t, b), (t, n), (b, n)] {
                assert!(x.dot(&y).abs() < 1e-12);
            }
            assert!((t.norm() - 1.0).abs() < 1e-12 && (b.norm() - 1.0).abs() < 1e-12);
            assert!((t.cross(&b) - n).norm() < 1e-12);
        }
    }
}
