//! Exact expectations the engines' merge counts are checked against.
//!
//! A light path starts at x3l with the density I(|x|)/Φ of plane 3 (`sim::illumination`), and it
//! merges at plane 3 with camera path j exactly when |x3l − x3c_j| ≤ R. Given the camera paths of
//! an iteration, its plane-3 merges therefore have the exact expectation
//!
//!   N_F · Σ_j P(x3l ∈ D(x3c_j, R)),  P(x3l ∈ D(c, R)) = Σ_k (level_k/Φ) · |D(c, R) ∩ ring_k|,
//!
//! where the area of a disc within the annulus r_in ≤ r < r_out is the difference of its overlaps
//! with the discs of radii r_out and r_in — closed forms, no sampling. This is an analytic
//! reference for both engines on any profile, independent of how either one draws its paths.

use std::f64::consts::PI;

use super::camera::CameraSet;
use super::config::SimConfig;
use super::illumination::Illumination;

/// Area of the intersection of a disc of radius `r` with a disc of radius `big` whose centre is at
/// distance `c` from it (the circular "lens"; both radii ≥ 0).
pub fn disc_overlap_area(r: f64, big: f64, c: f64) -> f64 {
    let (small, large) = if r <= big { (r, big) } else { (big, r) };
    if c + small <= large {
        return PI * small * small;
    }
    if c >= r + big {
        return 0.0;
    }
    // Two circular segments: each disc's sector minus the triangle, by the law of cosines; the
    // clamp guards the arccosines against rounding at tangency.
    let angle = |a: f64, b: f64| ((c * c + a * a - b * b) / (2.0 * c * a)).clamp(-1.0, 1.0).acos();
    let kite = 0.5 * ((-c + r + big) * (c + r - big) * (c - r + big) * (c + r + big)).max(0.0).sqrt();
    r * r * angle(r, big) + big * big * angle(big, r) - kite
}

/// Probability that a light path starts in the disc of radius `radius` around `centre` (plane 3).
pub fn start_probability_in_disc(illumination: &Illumination, centre: [f64; 2], radius: f64) -> f64 {
    let c = centre[0].hypot(centre[1]);
    let flux = illumination.flux();
    illumination
        .rings()
        .iter()
        .map(|ring| {
            let area = disc_overlap_area(radius, ring.r_out, c) - disc_overlap_area(radius, ring.r_in, c);
            ring.level / flux * area.max(0.0)
        })
        .sum()
}

/// The exact mean of a merge count and a bound on its variance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CountExpectation {
    pub mean: f64,
    /// An upper bound on the variance (see [`plane3_merges_given`]).
    pub variance_bound: f64,
}

impl CountExpectation {
    /// How many standard deviations (at the variance bound: a conservative z) `observed` is from
    /// the mean.
    pub fn z(&self, observed: f64) -> f64 {
        (observed - self.mean) / self.variance_bound.sqrt()
    }
}

/// Exact expectation of the plane-3 merge events of one iteration given its camera paths, with a
/// bound on their variance.
///
/// A light path merges with K = Σ_j 1[x3l ∈ D_j] cameras (D_j = D(x3c_j, R)), so the count is a sum
/// of N_F independent copies of K (brute force) or a compound Poisson sum with intensity N_F
/// (restricted engine): its variance is at most N_F·E[K²] = N_F·(Σ_j p_j + Σ_{j≠k} p_jk), with
/// p_j = P(x3l ∈ D_j) and p_jk = P(x3l ∈ D_j ∩ D_k). The pair terms vanish unless the two camera
/// vertices are closer than 2R, and p_jk ≤ min(p_j, p_k); hence the bound
/// N_F·(Σ_j p_j + Σ_{j≠k, |x3c_j − x3c_k| < 2R} min(p_j, p_k)).
pub fn plane3_merges_given(config: &SimConfig, cameras: &CameraSet) -> CountExpectation {
    let illumination = &config.scene.illumination;
    let radius = config.merge_radius;
    let vertices: Vec<([f64; 2], f64)> = cameras
        .paths
        .iter()
        .filter_map(|path| path.x3)
        .map(|x3| (x3, start_probability_in_disc(illumination, x3, radius)))
        .collect();
    let singles: f64 = vertices.iter().map(|v| v.1).sum();
    // N_B² pairs per iteration: negligible beside the light paths this checks.
    let mut pairs = 0.0;
    for (j, (a, pa)) in vertices.iter().enumerate() {
        for (b, pb) in &vertices[j + 1..] {
            if (a[0] - b[0]).hypot(a[1] - b[1]) < 2.0 * radius {
                pairs += 2.0 * pa.min(*pb);
            }
        }
    }
    let n = config.light_paths as f64;
    CountExpectation { mean: n * singles, variance_bound: n * (singles + pairs) }
}

/// [`plane3_merges_given`] summed over iterations `iterations` of `seed` (independent given their
/// camera paths, which depend on the seed and the iteration only, not on the engine).
pub fn plane3_merges(config: &SimConfig, seed: u64, iterations: std::ops::Range<u64>) -> CountExpectation {
    iterations.map(|s| plane3_merges_given(config, &CameraSet::generate(config, seed, s))).fold(
        CountExpectation::default(),
        |acc, e| CountExpectation { mean: acc.mean + e.mean, variance_bound: acc.variance_bound + e.variance_bound },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::spec::IlluminationSpec;

    #[test]
    fn overlap_of_discs_in_every_configuration() {
        // Inside, apart, tangent and symmetric, either argument order.
        assert_eq!(disc_overlap_area(1.0, 3.0, 1.5), PI);
        assert_eq!(disc_overlap_area(3.0, 1.0, 1.5), PI);
        assert_eq!(disc_overlap_area(1.0, 1.0, 2.0), 0.0);
        // Two unit discs one radius apart: 2π/3 − √3/2.
        let expected = 2.0 * PI / 3.0 - 3f64.sqrt() / 2.0;
        assert!((disc_overlap_area(1.0, 1.0, 1.0) - expected).abs() < 1e-14);
        // A small disc centred on a large one's rim covers half its area, up to the rim's curvature
        // (O(r/big) of it).
        let half = disc_overlap_area(0.001, 20.0, 20.0) / (PI * 1e-6);
        assert!((half - 0.5).abs() < 1e-4, "{half}");
        // Continuity at internal tangency.
        let inside = disc_overlap_area(1.0, 3.0, 2.0);
        assert!((disc_overlap_area(1.0, 3.0, 2.0 + 1e-9) - inside).abs() < 1e-6);
    }

    #[test]
    fn start_probability_integrates_the_profile() {
        // The paper's spot: a disc around the centre smaller than the spot sees the spot's level.
        let spot = Illumination::from_spec(&IlluminationSpec::Spot { a: 0.02, r_ls: 20.0, contrast: 1e6 / 300.0 });
        let p = start_probability_in_disc(&spot, [0.001, 0.0], 0.003);
        assert!((p - spot.density(0.0) * PI * 9e-6).abs() < 1e-15 * p.max(1.0));
        // A disc straddling the spot's edge sees a level between the two; the disc of radius r_ls
        // around the centre holds all the flux, and one beyond it none.
        let straddling = start_probability_in_disc(&spot, [0.02, 0.0], 0.003) / (PI * 9e-6);
        assert!(straddling < spot.density(0.0) && straddling > spot.density(1.0));
        assert!((start_probability_in_disc(&spot, [0.0, 0.0], 20.0) - 1.0).abs() < 1e-12);
        assert_eq!(start_probability_in_disc(&spot, [30.0, 0.0], 1.0), 0.0);
    }
}
