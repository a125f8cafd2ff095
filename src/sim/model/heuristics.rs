//! The per-path MIS heuristics for the three merge techniques: Veach's balance and power
//! heuristics with vertex-merging path pdfs as in Georgiev et al. 2012 (VCM), and the
//! correlation-aware heuristic of Grittmann, Georgiev and Slusallek 2021 (CAMIS), derived for this
//! scene's estimator.
//!
//! # Path densities
//!
//! A merge at plane m generates the join-path vertex x_m from both sides, so (VCM, §4) the path pdf
//! of technique m is the product of the camera sub-path's vertex densities up to m and the light
//! sub-path's down to m, times πR² and the number of light paths merged. The last two factors and
//! the pixel's own density are the same for all three techniques and cancel in the weights. For the
//! join path (x1 = 0, x2, x3), with d1 = |x2 − x1| and d2 = |x3 − x2| in 3-D, ϑ the deflection at x2
//! (the angle between the directions x1→x2 and x2→x3), q(ϑ) = g(ϑ)·ϑ/sin ϑ the lobe's solid-angle
//! pdf, and area-measure densities:
//!
//! * camera: p_c(x2) = (cos θ1/π)·cos θ1/d1² = L2²/(π d1⁴);  p_c(x3 | x2) = q(ϑ)·L3/d2³
//! * light:  p_l(x3) = I(x3)/Φ;  p_l(x2 | x3) = L3²/(π d2⁴);  p_l(x1 | x2, x3) = q(ϑ)·L2/d1³
//!
//! technique 0 (plane 1): p_l(x3) p_l(x2|x3) p_l(x1|x2,x3)
//! technique 1 (plane 2): p_c(x2) · p_l(x3) p_l(x2|x3)
//! technique 2 (plane 3): p_c(x2) p_c(x3|x2) · p_l(x3)
//!
//! Dividing all three by the common p_l(x3)·L2²L3²/(π d1⁴ d2⁴) leaves
//! p₀ ∝ q(ϑ)·d1/L2, p₁ ∝ 1/π, p₂ ∝ q(ϑ)·d2/L3. The balance heuristic is w_m = p_m/Σp, the power
//! heuristic (exponent 2) w_m = p_m²/Σp². Note that I(x3) cancels: these weights know nothing of the
//! bright spot — the paper's point. Both give every technique the same sample count, N_F·N_B pairs
//! per iteration, as if the pairs were independent.
//!
//! # Which merges are correlated
//!
//! An iteration averages *all* N_F·N_B pairs (η_i, ξ_j): C_s = 1/(N_F N_B) Σ_i Σ_j C(ξ_j, η_i). The
//! pairs share sub-paths:
//!
//! * a camera path ξ_j merges its prefix — the pixel x1 for plane 1, (x1, x2c) for plane 2,
//!   (x1, x2c, x3c) for plane 3 — with every one of the N_F light paths;
//! * a light path η_i merges its sub-path — (x3l, x2l, x1l) for plane 1, (x3l, x2l) for plane 2,
//!   x3l for plane 3 — with every one of the N_B camera paths.
//!
//! Plane 1 is the extreme: the camera prefix is the pixel, the same point for all camera paths, so
//! the N_B merges of a light path at the pixel are one sample counted N_B times (`merge.rs`
//! tallies C0·N_B): technique 0 has N_F samples per iteration, not N_F·N_B. Plane 3 is the other
//! case the paper describes: a camera vertex x3c in the bright spot merges with N_F·πR²·I(x3)/Φ
//! light paths (≈ 750 at the paper's values), all of them re-using the one camera prefix.
//!
//! # The correlation-aware heuristic, for this estimator
//!
//! For one technique alone, with pair contributions g_ij = g(ξ_j, η_i), the variance of the
//! iteration's mean over the crossed N_F × N_B design is exactly
//!
//! Var = [σ² + (N_B − 1)·σ_L² + (N_F − 1)·σ_C²] / (N_F N_B),
//!
//! σ² = Var g, σ_L² = Var_η E[g | η] (what a light sub-path shared by the camera paths carries),
//! σ_C² = Var_ξ E[g | ξ] (what a camera prefix shared by the light paths carries). Independent pairs
//! would give σ²/(N_F N_B), so the technique's *effective sample count* is
//! n = N_F N_B·σ² / [σ² + (N_B − 1)σ_L² + (N_F − 1)σ_C²]. The balance heuristic with sample counts
//! (Veach's w_m = n_m p_m / Σ_k n_k p_k) is CAMIS's principle: keep the balance heuristic, but count
//! a technique's samples as what they are worth, with the count estimated from sampling densities
//! alone (no variance estimates). CAMIS does so with *surrogate probabilities*: the probability that
//! a sub-path is sampled again within a footprint of area A around each of its vertices,
//! P = Π_vertices min(1, A·p(vertex)). Here A = πR², the merge disc — two vertices closer than R
//! are the same vertex to the estimator. Per technique m, with ⌊x⌋ = min(1, x):
//!
//! * camera prefix (its merge vertex included; the pixel is a point both sides share, factor 1):
//!   P_c,0 = 1,  P_c,1 = ⌊A p_c(x2)⌋,  P_c,2 = ⌊A p_c(x2)⌋·⌊A p_c(x3|x2)⌋;
//! * light sub-path (its merge vertex included):
//!   P_l,2 = ⌊A p_l(x3)⌋,  P_l,1 = P_l,2·⌊A p_l(x2|x3)⌋,  P_l,0 = P_l,1·⌊A p_l(x1|x2,x3)⌋.
//!
//! In CAMIS's hit-or-miss model a technique's contribution is f·1[ξ ∈ S_c]·1[η ∈ S_l]/(P_c P_l),
//! S_c and S_l the footprints of probabilities P_c and P_l: then σ² = f²(1/(P_c P_l) − 1),
//! σ_L² = f²(1/P_l − 1), σ_C² = f²(1/P_c − 1), and the count above becomes
//!
//! n_m = N_F N_B·(1 − P_c P_l) / [(1 − P_c P_l) + (N_B − 1)·P_c (1 − P_l) + (N_F − 1)·P_l (1 − P_c)]
//!
//! (P_c = P_c,m, P_l = P_l,m), and the weights are w_m = n_m p_m / Σ_k n_k p_k. For plane 3,
//! (N_F − 1)·P_l,2 is the expected number of *other* light paths merging with the camera vertex
//! x3c — the light paths that re-use its prefix. Properties (tested below):
//!
//! * N_F = N_B = 1 (nothing re-used): every n_m = 1, the balance heuristic;
//! * plane 1: P_c,0 = 1 gives n_0 = N_F exactly, whatever P_l,0;
//! * no correlation (P → 0, e.g. R → 0): n = (N_F, N_F N_B, N_F N_B), the balance heuristic with
//!   the true sample counts;
//! * P_l = 1 (every light path the same) gives n = N_B, P_c = 1 gives n = N_F, and in general
//!   N_F N_B/(N_F + N_B − 1) ≤ n ≤ N_F N_B; P_c = P_l = 1 (every pair the same) is taken as n = 1;
//! * with one camera path (N_B = 1) n rises with P_c and falls with P_l, as CAMIS's ratio does: a
//!   likelier prefix carries less of the variance, a likelier light sub-path is re-used by more
//!   merges of the prefix; with one light path, the mirror image. With both re-used neither holds
//!   in general: the (N_B − 1) term is the same effect seen from the light sub-path;
//! * the weights sum to 1.
//!
//! At the paper's values (N_F = 10⁷, N_B = 100, R = 0.003) the plane-3 count falls ≈ 750× inside
//! the spot and ≈ 1.2× outside it, the plane-2 count by < 0.2%, and plane 1 keeps N_F = N_F N_B/N_B:
//! inside the spot the heuristic moves weight from plane 3 to plane 2, as the paper's case 4 does.
//!
//! Where this differs from the published heuristic, and why:
//!
//! * CAMIS's ratio, c = P_c/(P_c + P_l − P_c P_l) with count N·c, is a heuristic for one camera
//!   prefix merged with N light paths (one camera path per pixel). Here N_B camera paths through
//!   one pixel share every light path as well, and the count above is the hit-or-miss model's own
//!   for the crossed design. With N_B = 1 it is
//!   N_F(1 − P_c P_l)/[(1 − P_c P_l) + (N_F − 1)P_l(1 − P_c)], which moves as c does (up with P_c,
//!   down with P_l) and equals CAMIS's N_F·c where N_F − 1 = (1 − P_c P_l)/P_c.
//! * CAMIS treats merges at the primary hit as uncorrelated (c = 1); here the primary hit is the
//!   pixel itself, and plane 1 is the most correlated technique.
//! * Footprint: SeeSharp's surrogate radius is the primary-hit distance × tan 1°; the pixel here is
//!   a point with no distance, and the merge disc is the scene's own footprint. One A per vertex:
//!   every vertex here has exactly one area density (SeeSharp uses A² at an area light's vertex).
//! * The light's density p_l(x3) = I(x3)/Φ is evaluated at the light path's *own* start x3l. For
//!   planes 1 and 2 that is the join path's x3; for a plane-3 merge the join path takes the
//!   camera's x3c, up to R away. I(x3) jumps at the spot's edge, and with it the plane-3 count (by
//!   ≈ 600×): evaluated at x3c, the weights of the plane-2 and plane-3 merges of light paths near the
//!   edge would not sum to 1 and the estimate would be biased by O(R/a), as `switch` is
//!   (docs/results.md). Evaluated at x3l, the jump sits where the emission's own jump is, which the
//!   kernel blurs only on the smooth camera side. Measured on the paper scene of
//!   `tests/simulation.rs` (R = a = 0.02): +2.6% off the quadrature at x3c (6.3 SE), +0.04% at x3l.
//! * The count assumes N_F light paths, as the brute force draws them; the restricted engine's
//!   Poisson number of paths would give N_F N_B/[1 + (N_B − 1)P_c + N_F P_l (1 − P_c)], which differs
//!   by a relative O(P). Both engines apply the same function of the path, so they estimate the
//!   same quantity.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::scene::{Scene, angle_between};

/// The join path (0, x2, x3) as the densities need it: d1 = |x2 − x1|, d2 = |x3 − x2| (3-D) and
/// the lobe's solid-angle pdf q(ϑ) at its deflection.
#[derive(Debug, Clone, Copy)]
pub struct JoinGeometry {
    d1: f64,
    d2: f64,
    theta: f64,
    q: f64,
}

/// A full path (pixel, x2, x3, light)'s measure: its contribution f to the pixel's luminance per
/// unit area of x2 and of x3, f = (L2/d1³)(L3²/d2⁴)·g(ϑ)·p_l(x3)/π² (the integrand of
/// `checks::quadrature`, whose integral is L), and the area density with which the camera draws
/// the pair (x2, x3), p_c(x2)·p_c(x3|x2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathMeasure {
    /// f(x2, x3).
    pub contribution: f64,
    /// The camera's density of (x2, x3).
    pub camera: f64,
}

/// Area densities of the join path's vertices as each side samples them (module doc); the light's
/// start density p_l(x3) comes from the illumination.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexDensities {
    /// p_c(x2) = L2²/(π d1⁴).
    pub camera_x2: f64,
    /// p_c(x3 | x2) = q(ϑ)·L3/d2³.
    pub camera_x3: f64,
    /// p_l(x2 | x3) = L3²/(π d2⁴).
    pub light_x2: f64,
    /// p_l(x1 | x2, x3) = q(ϑ)·L2/d1³.
    pub light_x1: f64,
}

impl JoinGeometry {
    /// The geometry of the join path through `x2` on plane 2 and `x3` on plane 3 in `scene`.
    pub fn new(scene: &Scene, x2: [f64; 2], x3: [f64; 2]) -> Self {
        let u = Vector3::new(x2[0], x2[1], scene.l2);
        let v = Vector3::new(x3[0] - x2[0], x3[1] - x2[1], scene.l3);
        let (d1, d2) = (u.norm(), v.norm());
        let theta = angle_between(&(u / d1), &(v / d2));
        Self { d1, d2, theta, q: scene.lobe.pdf_w(theta) }
    }

    /// The full path's measure ([`PathMeasure`]) with the light's start density `light_start` =
    /// p_l(x3).
    pub fn path_measure(&self, scene: &Scene, light_start: f64) -> PathMeasure {
        let v = self.vertex_densities(scene);
        let (d1_3, d2_4) = (self.d1 * self.d1 * self.d1, (self.d2 * self.d2) * (self.d2 * self.d2));
        let g = scene.lobe.g(self.theta);
        PathMeasure {
            contribution: (scene.l2 / d1_3) * (scene.l3 * scene.l3 / d2_4) * g * light_start / (PI * PI),
            camera: v.camera_x2 * v.camera_x3,
        }
    }

    /// Relative technique densities (p₀, p₁, p₂), up to a common factor.
    pub fn technique_densities(&self, scene: &Scene) -> [f64; 3] {
        [self.q * self.d1 / scene.l2, 1.0 / PI, self.q * self.d2 / scene.l3]
    }

    /// The vertex densities in absolute terms (per unit area).
    pub fn vertex_densities(&self, scene: &Scene) -> VertexDensities {
        let (d1_2, d2_2) = (self.d1 * self.d1, self.d2 * self.d2);
        VertexDensities {
            camera_x2: scene.l2 * scene.l2 / (PI * d1_2 * d1_2),
            camera_x3: self.q * scene.l3 / (d2_2 * self.d2),
            light_x2: scene.l3 * scene.l3 / (PI * d2_2 * d2_2),
            light_x1: self.q * scene.l2 / (d1_2 * self.d1),
        }
    }
}

/// Relative technique densities (p₀, p₁, p₂) of the join path (0, x2, x3), up to a common factor.
pub fn technique_densities(scene: &Scene, x2: [f64; 2], x3: [f64; 2]) -> [f64; 3] {
    JoinGeometry::new(scene, x2, x3).technique_densities(scene)
}

/// Balance-heuristic weights from technique densities.
pub fn balance(p: [f64; 3]) -> [f64; 3] {
    let total = p[0] + p[1] + p[2];
    [p[0] / total, p[1] / total, p[2] / total]
}

/// Power-heuristic (β = 2) weights from technique densities.
pub fn power(p: [f64; 3]) -> [f64; 3] {
    balance([p[0] * p[0], p[1] * p[1], p[2] * p[2]])
}

/// Balance-heuristic weights with sample counts: w_m = n_m p_m / Σ_k n_k p_k (counts in any common
/// unit).
pub fn balance_with_counts(p: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    balance([n[0] * p[0], n[1] * p[1], n[2] * p[2]])
}

/// CAMIS's surrogate probabilities of technique m's two sub-paths (module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sharing {
    /// P_c,m: the camera prefix, up to and including the merge vertex.
    pub camera: [f64; 3],
    /// P_l,m: the light sub-path, from its start down to and including the merge vertex.
    pub light: [f64; 3],
}

impl Sharing {
    /// The surrogate probabilities for footprint area `area` (πR²), from the vertex densities and
    /// the light's start density p_l(x3l) = I(x3l)/Φ.
    pub fn new(v: &VertexDensities, light_start: f64, area: f64) -> Self {
        let hit = |p: f64| (area * p).min(1.0);
        let camera_x2 = hit(v.camera_x2);
        let light_x3 = hit(light_start);
        let light_x2 = light_x3 * hit(v.light_x2);
        Self {
            camera: [1.0, camera_x2, camera_x2 * hit(v.camera_x3)],
            light: [light_x2 * hit(v.light_x1), light_x2, light_x3],
        }
    }
}

/// Effective sample counts n_m / (N_F N_B) of the three techniques (module doc), for
/// `light_paths` = N_F and `camera_paths` = N_B (both ≥ 1).
pub fn effective_counts(sharing: &Sharing, light_paths: f64, camera_paths: f64) -> [f64; 3] {
    std::array::from_fn(|m| {
        let (pc, pl) = (sharing.camera[m], sharing.light[m]);
        let own = 1.0 - pc * pl;
        let shared = own + (camera_paths - 1.0) * pc * (1.0 - pl) + (light_paths - 1.0) * pl * (1.0 - pc);
        // shared = 0 only if P_c = P_l = 1: every pair is the same sample, n = 1.
        if shared > 0.0 { own / shared } else { 1.0 / (light_paths * camera_paths) }
    })
}

/// Correlation-aware weights: the balance heuristic over the relative technique densities `p`,
/// with the effective sample counts of `sharing` for N_F = `light_paths`, N_B = `camera_paths`.
pub fn correlation_aware(p: [f64; 3], sharing: &Sharing, light_paths: f64, camera_paths: f64) -> [f64; 3] {
    balance_with_counts(p, effective_counts(sharing, light_paths, camera_paths))
}

#[cfg(test)]
mod tests;
