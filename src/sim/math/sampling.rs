//! Pure samplers on uniform random numbers: points of the unit disc, cosine-distributed
//! directions, and rotations of a direction about an axis. They know nothing of the scene (the
//! lobe's sampler, which needs its width, is in [`crate::sim::model::scene`]).
//!
//! The cosine sampler is an exact draw from pdf_w = cos θ/π by Malley's method: a uniform disc
//! point lifted to the hemisphere.

use nalgebra::Vector3;

use super::rng::{StreamRng, symmetric_pair};

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

/// A point uniform in the disc D(`center`, `radius`).
pub fn disc_point(rng: &mut StreamRng, center: [f64; 2], radius: f64) -> [f64; 2] {
    let (u, v, _) = unit_disc_point(rng);
    [center[0] + radius * u, center[1] + radius * v]
}

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
pub(crate) mod tests {
    use super::*;
    use crate::sim::math::rng::stream;

    /// Mean and standard error of f over n samples (also used by the scene's sampler tests).
    pub(crate) fn mean_se(n: usize, mut f: impl FnMut() -> f64) -> (f64, f64) {
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let x = f();
            s1 += x;
            s2 += x * x;
        }
        let m = s1 / n as f64;
        (m, ((s2 / n as f64 - m * m) / n as f64).sqrt())
    }

    /// Asserts that an estimate is within 4 standard errors of the exact value.
    pub(crate) fn assert_close(what: &str, (m, se): (f64, f64), exact: f64) {
        assert!((m - exact).abs() < 4.0 * se, "{what}: {m} ± {se} vs exact {exact}");
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
