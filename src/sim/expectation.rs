//! Exact expectations the engines' merge counts are checked against.
//!
//! Given the camera paths of an iteration, a light path merges at plane p with camera path j
//! exactly when its vertex x_pl falls in the disc D(x_pc_j, R), so the merges at plane p have the
//! expectation N_F · Σ_j P(x_pl ∈ D(x_pc_j, R)). Both probabilities have closed forms that no
//! engine uses, which makes them an analytic reference for either one on any light profile:
//!
//! * plane 3: x3l has the density I(|x|)/Φ (`sim::illumination`), piecewise constant on rings, so
//!   P(x3l ∈ D(c, R)) = Σ_k (level_k/Φ)·|D(c, R) ∩ ring_k|, and the area of a disc within the
//!   annulus r_in ≤ r < r_out is the difference of its overlaps with the discs of radii r_out and
//!   r_in;
//! * plane 2: x2l is x3l displaced by a cosine-distributed direction over the distance L3, whose
//!   density on plane 2 is the Lambert kernel q(d) = L3²/(π(L3² + |d|²)²). Its integral over a disc
//!   of sources of radius r, seen from c, is the configuration factor of a parallel disc,
//!   G(r, c) = ½[1 − (L3² + c² − r²)/√((L3² + c² + r²)² − 4r²c²)], so x2l has the density
//!   p2(c) = Σ_k (level_k/Φ)·(G(r_out_k, c) − G(r_in_k, c)). As a convolution with q, p2 is smooth
//!   on the scale L3, so P(x2l ∈ D(c, R)) = πR²·p2(c)·(1 + O(R²/L3²)) (midpoint rule on the disc:
//!   the relative error is about R²/8·|∇²p2|/p2 ≈ 10⁻⁷ at the paper's R and L3, tested below).

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

/// Σ_k (level_k/Φ)·(F(r_out_k) − F(r_in_k)): the integral over the light's rings of a quantity
/// whose integral over the centred disc of radius r is F(r).
fn over_rings(illumination: &Illumination, disc: impl Fn(f64) -> f64) -> f64 {
    let flux = illumination.flux();
    illumination.rings().iter().map(|ring| ring.level / flux * (disc(ring.r_out) - disc(ring.r_in)).max(0.0)).sum()
}

/// Probability that a light path starts in the disc of radius `radius` around `centre` (plane 3).
pub fn start_probability_in_disc(illumination: &Illumination, centre: [f64; 2], radius: f64) -> f64 {
    let c = centre[0].hypot(centre[1]);
    over_rings(illumination, |r| disc_overlap_area(radius, r, c))
}

/// The exact mean of a merge count and a bound on its variance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CountExpectation {
    pub mean: f64,
    /// An upper bound on the variance (see [`count_given`]).
    pub variance_bound: f64,
}

impl CountExpectation {
    /// How many standard deviations (at the variance bound: a conservative z) `observed` is from
    /// the mean.
    pub fn z(&self, observed: f64) -> f64 {
        (observed - self.mean) / self.variance_bound.sqrt()
    }
}

/// Lambert configuration factor from a point of plane 2 at distance `c` from the axis to the disc
/// of radius `r` of plane 3 centred on the axis, at distance `l3` (see the module doc).
pub fn disc_configuration_factor(r: f64, c: f64, l3: f64) -> f64 {
    let (h2, c2, r2) = (l3 * l3, c * c, r * r);
    let root = ((h2 + c2 + r2).powi(2) - 4.0 * r2 * c2).sqrt();
    0.5 * (1.0 - (h2 + c2 - r2) / root)
}

/// Density of the light paths' plane-2 vertices x2l at `point`.
pub fn arrival_density(illumination: &Illumination, l3: f64, point: [f64; 2]) -> f64 {
    let c = point[0].hypot(point[1]);
    over_rings(illumination, |r| disc_configuration_factor(r, c, l3))
}

/// Expected plane-2 and plane-3 merge events (with variance bounds).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MergeExpectation {
    pub plane2: CountExpectation,
    pub plane3: CountExpectation,
}

/// Exact expectation of the plane-2 and plane-3 merge events of one iteration given its camera
/// paths, with bounds on their variance (see [`count_given`]).
pub fn merges_given(config: &SimConfig, cameras: &CameraSet) -> MergeExpectation {
    let scene = &config.scene;
    let radius = config.merge_radius;
    let plane2: Vec<([f64; 2], f64)> = cameras
        .paths
        .iter()
        .map(|path| (path.x2, PI * radius * radius * arrival_density(&scene.illumination, scene.l3, path.x2)))
        .collect();
    let plane3: Vec<([f64; 2], f64)> = cameras
        .paths
        .iter()
        .filter_map(|path| path.x3)
        .map(|x3| (x3, start_probability_in_disc(&scene.illumination, x3, radius)))
        .collect();
    MergeExpectation {
        plane2: count_given(&plane2, radius, config.light_paths),
        plane3: count_given(&plane3, radius, config.light_paths),
    }
}

/// The merges at one plane from the camera vertices there and the probabilities p_j that a light
/// path's vertex falls within R of each.
///
/// A light path merges with K = Σ_j 1[x_l ∈ D_j] cameras (D_j = D(x_c_j, R)), so the count is a sum
/// of N_F independent copies of K (brute force) or a compound Poisson sum with intensity N_F
/// (restricted engine): its mean is N_F·Σ_j p_j and its variance at most N_F·E[K²] =
/// N_F·(Σ_j p_j + Σ_{j≠k} p_jk), with p_jk = P(x_l ∈ D_j ∩ D_k). The pair terms vanish unless the two
/// camera vertices are closer than 2R, and p_jk ≤ min(p_j, p_k); hence the bound
/// N_F·(Σ_j p_j + Σ_{j≠k, |x_c_j − x_c_k| < 2R} min(p_j, p_k)).
fn count_given(vertices: &[([f64; 2], f64)], radius: f64, light_paths: u64) -> CountExpectation {
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
    let n = light_paths as f64;
    CountExpectation { mean: n * singles, variance_bound: n * (singles + pairs) }
}

/// [`merges_given`] summed over iterations `iterations` of `seed` (independent given their camera
/// paths, which depend on the seed and the iteration only, not on the engine).
pub fn merges(config: &SimConfig, seed: u64, iterations: std::ops::Range<u64>) -> MergeExpectation {
    let add = |a: CountExpectation, b: CountExpectation| CountExpectation {
        mean: a.mean + b.mean,
        variance_bound: a.variance_bound + b.variance_bound,
    };
    iterations.map(|s| merges_given(config, &CameraSet::generate(config, seed, s))).fold(
        MergeExpectation::default(),
        |acc, e| MergeExpectation { plane2: add(acc.plane2, e.plane2), plane3: add(acc.plane3, e.plane3) },
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

    /// ∫ f over the disc D(c, R) by a fine polar midpoint rule (an independent numerical check).
    fn disc_integral(f: impl Fn([f64; 2]) -> f64, c: [f64; 2], radius: f64) -> f64 {
        let (nr, na) = (200, 400);
        let mut sum = 0.0;
        for i in 0..nr {
            // Equal-area rings: r² uniform.
            let r = radius * ((i as f64 + 0.5) / nr as f64).sqrt();
            for k in 0..na {
                let phi = 2.0 * PI * (k as f64 + 0.5) / na as f64;
                sum += f([c[0] + r * phi.cos(), c[1] + r * phi.sin()]);
            }
        }
        sum * PI * radius * radius / (nr * na) as f64
    }

    #[test]
    fn configuration_factor_of_a_disc() {
        let l3 = 3.0;
        // On the axis: the fraction of a cosine distribution within the cone, r²/(L3² + r²).
        assert!((disc_configuration_factor(4.0, 0.0, l3) - 16.0 / 25.0).abs() < 1e-15);
        assert_eq!(disc_configuration_factor(0.0, 1.0, l3), 0.0);
        // Off the axis: against the Lambert kernel integrated numerically over the disc.
        let q = |c: [f64; 2]| {
            move |y: [f64; 2]| {
                let d2 = (c[0] - y[0]).powi(2) + (c[1] - y[1]).powi(2);
                l3 * l3 / (PI * (l3 * l3 + d2).powi(2))
            }
        };
        for (r, c) in [(0.5, 1.0), (2.0, 1.5), (0.02, 0.7)] {
            let numeric = disc_integral(q([c, 0.0]), [0.0, 0.0], r);
            let exact = disc_configuration_factor(r, c, l3);
            assert!((numeric - exact).abs() < 1e-5 * exact, "r {r}, c {c}: {numeric} vs {exact}");
        }
    }

    #[test]
    fn arrival_density_is_a_density_and_the_midpoint_rule_holds_at_the_merge_radius() {
        let spot = Illumination::from_spec(&IlluminationSpec::Spot { a: 0.02, r_ls: 20.0, contrast: 1e6 / 300.0 });
        let l3 = 3.0;
        // Total mass: ∫ p2 over a disc of radius ρ around the centre, by a radial integral of the
        // rotationally symmetric density, tends to 1 (the mass beyond ρ = 10⁴ is ~ (L3 + r_ls)²/ρ²).
        let (n, rho_max) = (200_000, 1e4_f64);
        let mass: f64 = (0..n)
            .map(|i| {
                // r = ρ_max·t², denser near the centre where the density lives.
                let t = (i as f64 + 0.5) / n as f64;
                let r = rho_max * t * t;
                arrival_density(&spot, l3, [r, 0.0]) * 2.0 * PI * r * 2.0 * rho_max * t / n as f64
            })
            .sum();
        assert!((mass - 1.0).abs() < 2e-5, "{mass}");
        // The midpoint rule on a merge disc of the paper's R, in the spot, at its edge and near r_ls.
        for c in [[0.0, 0.0], [0.02, 0.0], [1.0, 1.0], [19.5, 0.0], [21.0, 0.0]] {
            let numeric = disc_integral(|x| arrival_density(&spot, l3, x), c, 0.003);
            let midpoint = PI * 9e-6 * arrival_density(&spot, l3, c);
            assert!((numeric - midpoint).abs() < 1e-6 * midpoint, "c {c:?}: {numeric} vs {midpoint}");
        }
    }
}
