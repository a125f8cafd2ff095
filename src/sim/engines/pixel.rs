//! Can a light path at plane 2 still reach the pixel? The exact tests both engines use to skip
//! lobe draws that cannot matter, with their proofs, and the one final step of a draw that can:
//!
//! * [`PixelCone`] — the cone of incident directions from which any lobe deflection can reach the
//!   merge disc about the pixel, and the smallest deflection a given path needs;
//! * [`lobe_draw_below`] — whether a lobe draw is certainly too small, without a logarithm;
//! * [`pixel_hit`], [`land_on_pixel`] — the restricted engine's draw with its skips;
//! * [`deflect_onto_pixel`] — the azimuth, the deflection and the hit test, shared by the engines.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;

use crate::sim::engines::merge::within;
use crate::sim::math::rng::{StreamRng, uniform, uniform_open0};
use crate::sim::math::sampling::deflect;
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::{LOBE_MAX_SIGMAS, advance};

/// Constants of the light-path loop's pixel tests, derived once per configuration.
#[derive(Debug, Clone, Copy)]
pub struct PixelCone {
    /// c·|c| for c = cos of the widest angle between a path's incident direction at x2l and the
    /// direction to the pixel for which the path can still land within R of the pixel (c = −2,
    /// below any cosine, when that angle reaches π and every path must sample the lobe).
    c_abs_c: f64,
    /// δ = asin(R/L2): the largest angle between the direction to the pixel and a direction from
    /// plane 2 into the merge disc.
    delta: f64,
}

/// Relative margin on the angles of the pixel tests, far larger than any rounding error.
const CONE_MARGIN: f64 = 1e-6;

impl PixelCone {
    /// The cone for lobe width `beta`, plane distance `l2` and merge radius `radius` < l2.
    ///
    /// Proof of the bound: the lobe deflects the incident direction d by ϑ ≤ ϑ_max =
    /// LOBE_MAX_SIGMAS·β into d'. If d' hits plane 1 within R of the pixel, d' points into the ball
    /// of radius R about the pixel, which from x2l (at distance ≥ L2 > R) subtends a half-angle
    /// ≤ δ = asin(R/L2); so angle(d', t) ≤ δ for t the direction to the pixel. By the triangle
    /// inequality on the sphere, angle(d, t) ≤ ϑ_max + δ. A relative margin of 10⁻⁶ covers rounding.
    pub fn new(beta: f64, l2: f64, radius: f64) -> Self {
        assert!(radius < l2, "the merge radius must be smaller than L2 for the pixel cone bound");
        let delta = (radius / l2).asin();
        let reach = (LOBE_MAX_SIGMAS * beta + delta) * (1.0 + CONE_MARGIN);
        let c = if reach >= PI { -2.0 } else { reach.cos() };
        Self { c_abs_c: c * c.abs(), delta }
    }

    /// The threshold C = c·|c| of [`PixelCone::may_reach`]'s test (−4 when every path passes), for
    /// tests that bound it from outside (the brute force's single-precision filter).
    pub fn c_abs_c(&self) -> f64 {
        self.c_abs_c
    }

    /// Whether a path at (`x`, `y`) on plane 2 travelling along the unit direction (`u`, `v`, −`z`)
    /// can reach the pixel's merge disc.
    ///
    /// With t = pixel − x2l, the test is d·t ≥ c·|t|. Because s ↦ s·|s| is strictly increasing it
    /// equals (d·t)·|d·t| ≥ c·|c|·|t|², which needs neither a square root nor a branch, and holds
    /// for every path when c = −2 (as |d·t| ≤ |t|).
    #[inline(always)]
    pub fn may_reach(&self, x: f64, y: f64, u: f64, v: f64, z: f64, l2: f64) -> bool {
        let dot = -u * x - v * y + z * l2;
        let t2 = x * x + y * y + l2 * l2;
        dot * dot.abs() >= self.c_abs_c * t2
    }

    /// [`PixelCone::may_reach`] for the direction d = (sin θ cos φ, sin θ sin φ, −cos θ) given as
    /// cos φ, sin φ, tan θ and cos² θ, as the loop has it (so it needs no square root).
    ///
    /// With D = L2 − tan θ·(x cos φ + y sin φ), d·t = cos θ·D, so (d·t)|d·t| = cos² θ·D|D| and the
    /// test is the same inequality scaled by a positive factor. Its rounding differs from
    /// `may_reach`'s by a few ulps of |t|², far inside the cone's 10⁻⁶ margin.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn may_reach_polar(&self, x: f64, y: f64, cos_phi: f64, sin_phi: f64, tan: f64, cos2: f64, l2: f64) -> bool {
        let dot = (-tan).mul_add(x.mul_add(cos_phi, y * sin_phi), l2);
        let t2 = x.mul_add(x, y.mul_add(y, l2 * l2));
        cos2 * (dot * dot.abs()) >= self.c_abs_c * t2
    }

    /// Whether a path at (`x`, `y`) on plane 2 with unit incident direction `d` (d.z < 0) can land
    /// within R of the pixel after a lobe deflection of exactly `theta`, whatever its azimuth: iff
    /// `theta` ≥ [`PixelCone::min_deflection`].
    #[inline]
    pub fn may_deflect_to_pixel(&self, x: f64, y: f64, d: &Vector3<f64>, theta: f64, l2: f64) -> bool {
        theta >= self.min_deflection(x, y, d, l2)
    }

    /// A lower bound on the lobe deflection a path at (`x`, `y`) on plane 2 with unit incident
    /// direction `d` (d.z < 0) needs to land within R of the pixel (≤ 0 when it may need none).
    ///
    /// Proof: landing within R needs angle(d', t) ≤ δ (see [`PixelCone::new`]) and angle(d, d') = ϑ,
    /// so α = angle(d, t) ≤ ϑ + δ =: A. As 1 − cos α = 2 sin²(α/2) ≤ α²/2 for all α, a hit needs
    /// A ≥ α ≥ √(2(1 − cos α)), i.e. ϑ ≥ √(2(1 − d·t/|t|)) − δ. The bound returned is smaller: 10⁻¹²
    /// is taken off 1 − cos α (whose rounding error is a few 10⁻¹⁶) and the result is divided by
    /// 1 + 10⁻⁶, the cone's margin.
    #[inline]
    pub fn min_deflection(&self, x: f64, y: f64, d: &Vector3<f64>, l2: f64) -> f64 {
        let cos_alpha = (-d.x * x - d.y * y - d.z * l2) / (x * x + y * y + l2 * l2).sqrt();
        let one_minus_cos = (1.0 - cos_alpha - 1e-12).max(0.0);
        (2.0 * one_minus_cos).sqrt() / (1.0 + CONE_MARGIN) - self.delta
    }
}

/// Whether the lobe draw ϑ = β·√(−2 ln u₁) is certainly below `theta_min`, decided without a
/// logarithm (a necessary test before the exact one, which settles most paths cheaply).
///
/// ϑ ≥ ϑ_min needs u₁ ≤ e^(−y) with y = (ϑ_min/β)²/2. Since e^y > 1 + y + y²/2 + y³/6 + y⁴/24 =: p(y)
/// for y > 0, u₁·p(y) > 1 implies u₁ > e^(−y), so ϑ < ϑ_min; the threshold 1 + 10⁻⁹ absorbs the
/// rounding of u₁·p(y).
#[inline]
pub fn lobe_draw_below(u1: f64, theta_min: f64, beta: f64) -> bool {
    if theta_min <= 0.0 {
        return false;
    }
    let y = 0.5 * (theta_min / beta) * (theta_min / beta);
    let p = 1.0 + y * (1.0 + y / 2.0 * (1.0 + y / 3.0 * (1.0 + y / 4.0)));
    u1 * p > 1.0 + 1e-9
}

/// δ = asin(R/L2) with a relative margin of 10⁻⁶, with its sine and cosine: a direction from
/// plane 2 into the merge disc is within δ of the direction to the pixel (see [`PixelCone::new`]).
#[derive(Debug, Clone, Copy)]
pub struct DiscAngle {
    /// δ in radians, margin included.
    pub delta: f64,
    /// sin δ.
    pub sin: f64,
    /// cos δ.
    pub cos: f64,
}

impl DiscAngle {
    /// The angle of a disc of radius `radius` on plane 1 seen from distance `l2` (L2).
    pub fn new(radius: f64, l2: f64) -> Self {
        let delta = (radius / l2).asin() * (1.0 + 1e-6);
        Self { delta, sin: delta.sin(), cos: delta.cos() }
    }
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
pub fn pixel_hit(
    config: &SimConfig,
    cone: &PixelCone,
    angle: &DiscAngle,
    d: &Vector3<f64>,
    x2: [f64; 2],
    rng: &mut StreamRng,
) -> Option<([f64; 2], f64)> {
    let l2 = config.scene.l2;
    if !cone.may_reach(x2[0], x2[1], d.x, d.y, -d.z, l2) {
        return None;
    }
    let theta = config.scene.lobe.beta * (-2.0 * libm::log(uniform_open0(rng))).sqrt();
    land_on_pixel(config, angle, d, x2, theta, rng)
}

/// The rest of the lobe draw once ϑ is drawn: `Some((x1, ϑ))` if the path lands in D(0, R).
pub fn land_on_pixel(
    config: &SimConfig,
    angle: &DiscAngle,
    d: &Vector3<f64>,
    x2: [f64; 2],
    theta: f64,
    rng: &mut StreamRng,
) -> Option<([f64; 2], f64)> {
    let l2 = config.scene.l2;
    let DiscAngle { delta, sin: sin_d, cos: cos_d } = *angle;
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
    deflect_onto_pixel(config, d, x2, theta, rng).map(|x1| (x1, theta))
}

/// The last step of every lobe draw that may reach the pixel, shared by both engines: the azimuth
/// 2πu₂, the deflection of `d` by ϑ = `theta`, and where the deflected path meets plane 1 — `Some`
/// if within R of the pixel.
#[inline]
pub fn deflect_onto_pixel(
    config: &SimConfig,
    d: &Vector3<f64>,
    x2: [f64; 2],
    theta: f64,
    rng: &mut StreamRng,
) -> Option<[f64; 2]> {
    let l2 = config.scene.l2;
    let out = deflect(d, theta, TAU * uniform(rng));
    if out.z >= 0.0 {
        return None;
    }
    let x1 = advance(x2, &out, -l2);
    within(x1, [0.0, 0.0], config.merge_radius).then_some(x1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::rng::stream;

    /// The cone tests must never skip a path that can hit the pixel disc: for random x2 near the
    /// axis and directions aimed near the pixel, any deflection within the lobe's bound that lands
    /// in the disc must come from a direction the cone admits (in both forms), and its deflection
    /// angle must pass `may_deflect_to_pixel`.
    #[test]
    fn pixel_cone_never_rejects_a_possible_hit() {
        let beta = 3f64.to_radians();
        let (l2, r) = (1.0, 0.05);
        let cone = PixelCone::new(beta, l2, r);
        let mut rng = stream(9, 9, 9);
        let (mut hits, mut skipped) = (0, 0);
        for _ in 0..200_000 {
            let u = |rng: &mut _| uniform(rng);
            let x2 = [u(&mut rng) * 2.0 - 1.0, u(&mut rng) * 2.0 - 1.0];
            let (t, _) = crate::sim::model::scene::Scene::from_spec(&crate::sim::model::params::SceneSpec {
                l2,
                l3: 3.0,
                beta_deg: 3.0,
                illumination: crate::sim::model::params::IlluminationSpec::Uniform { r_ls: 1.0 },
            })
            .towards_pixel(x2);
            // An incident direction up to 10β away from the pixel direction…
            let d = deflect(&t, u(&mut rng) * 10.0 * beta, u(&mut rng) * TAU);
            if d.z >= 0.0 {
                continue;
            }
            // …deflected by up to the lobe's largest angle.
            let theta = u(&mut rng) * LOBE_MAX_SIGMAS * beta;
            let out = deflect(&d, theta, u(&mut rng) * TAU);
            let deflect_ok = cone.may_deflect_to_pixel(x2[0], x2[1], &d, theta, l2);
            skipped += usize::from(!deflect_ok);
            if out.z >= 0.0 {
                continue;
            }
            let x1 = advance(x2, &out, -l2);
            if x1[0].hypot(x1[1]) <= r {
                hits += 1;
                assert!(cone.may_reach(x2[0], x2[1], d.x, d.y, -d.z, l2), "cone rejected a hit at {x2:?}");
                let sin_t = d.x.hypot(d.y);
                let (cos_phi, sin_phi) = (d.x / sin_t, d.y / sin_t);
                let (tan, cos2) = (sin_t / -d.z, d.z * d.z);
                assert!(cone.may_reach_polar(x2[0], x2[1], cos_phi, sin_phi, tan, cos2, l2), "polar cone, {x2:?}");
                assert!(deflect_ok, "deflection test rejected a hit at {x2:?}, ϑ = {theta}");
            }
        }
        assert!(hits > 100, "the test must exercise hits ({hits})");
        assert!(skipped > 10_000, "the deflection test must also reject ({skipped})");
        // And it does reject: a direction pointing away from the pixel.
        let away = Vector3::new(0.9, 0.0, -0.1).normalize();
        assert!(!cone.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
        assert!(!cone.may_reach_polar(0.0, 0.0, 1.0, 0.0, 9.0, away.z * away.z, l2));
        // A lobe so wide that every path may reach the pixel.
        let wide = PixelCone::new(45f64.to_radians(), l2, r);
        assert!(wide.may_reach(0.0, 0.0, away.x, away.y, -away.z, l2));
        assert!(wide.may_reach_polar(0.0, 0.0, 1.0, 0.0, 9.0, away.z * away.z, l2));
        assert!(wide.may_deflect_to_pixel(0.0, 0.0, &away, 3.0, l2));
    }

    /// The logarithm-free test never rejects a draw that reaches the bound, and settles most draws
    /// that do not.
    #[test]
    fn lobe_draw_below_is_conservative() {
        let beta = 3f64.to_radians();
        let mut rng = stream(5, 6, 7);
        let (mut below, mut settled) = (0, 0);
        for _ in 0..1_000_000 {
            let u1 = uniform_open0(&mut rng);
            let theta_min = (uniform(&mut rng) * 10.0 - 1.0) * beta;
            let theta = beta * (-2.0 * libm::log(u1)).sqrt();
            if lobe_draw_below(u1, theta_min, beta) {
                assert!(theta < theta_min, "u₁ = {u1}, ϑ = {theta} ≥ ϑ_min = {theta_min}");
                settled += 1;
            }
            below += usize::from(theta < theta_min);
        }
        assert!(settled > below * 7 / 10, "{settled} of {below} settled without a logarithm");
    }
}
