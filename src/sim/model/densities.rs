//! Where light vertices fall, in closed form: the density of light-path starts on plane 3 and of
//! their arrivals on plane 2, integrated over discs. No engine uses these: they are the analytic
//! references of the merge counts (`checks::expectation`) and the expected work of an iteration
//! (`engines::cost`).
//!
//! * plane 3: x3l has the density I(|x|)/Φ, piecewise constant on rings, so
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::model::params::IlluminationSpec;
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
            let r = radius * ((f64::from(i) + 0.5) / f64::from(nr)).sqrt();
            for k in 0..na {
                let phi = 2.0 * PI * (f64::from(k) + 0.5) / f64::from(na);
                sum += f([c[0] + r * phi.cos(), c[1] + r * phi.sin()]);
            }
        }
        sum * PI * radius * radius / f64::from(nr * na)
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
                let t = (f64::from(i) + 0.5) / f64::from(n);
                let r = rho_max * t * t;
                arrival_density(&spot, l3, [r, 0.0]) * 2.0 * PI * r * 2.0 * rho_max * t / f64::from(n)
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
