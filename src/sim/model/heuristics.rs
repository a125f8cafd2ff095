//! Veach's balance and power heuristics for the three merge techniques, with vertex-merging path
//! pdfs as in Georgiev et al. 2012 (VCM).
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
//! bright spot — the paper's point.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::scene::{Scene, angle_between};

/// Relative technique densities (p₀, p₁, p₂) of the join path (0, x2, x3), up to a common factor.
pub fn technique_densities(scene: &Scene, x2: [f64; 2], x3: [f64; 2]) -> [f64; 3] {
    let u = Vector3::new(x2[0], x2[1], scene.l2);
    let v = Vector3::new(x3[0] - x2[0], x3[1] - x2[1], scene.l3);
    let (d1, d2) = (u.norm(), v.norm());
    let theta = angle_between(&(u / d1), &(v / d2));
    let q = scene.lobe.pdf_w(theta);
    [q * d1 / scene.l2, 1.0 / PI, q * d2 / scene.l3]
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::model::params::IlluminationSpec;
    use crate::sim::model::params::SceneSpec;
    fn scene() -> Scene {
        Scene::from_spec(&SceneSpec {
            l2: 1.0,
            l3: 3.0,
            beta_deg: 3.0,
            illumination: IlluminationSpec::Uniform { r_ls: 20.0 },
        })
    }

    #[test]
    fn weights_sum_to_one_and_follow_the_lobe() {
        let s = scene();
        // A straight path (ϑ = 0): the lobe is at its peak, so planes 1 and 3 dominate plane 2.
        let straight = technique_densities(&s, [0.1, 0.0], [0.4, 0.0]);
        let b = balance(straight);
        assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!(b[1] < 0.01 && b[0] > 0.2 && b[2] > 0.2, "{b:?}");
        // A strongly kinked path (ϑ ≫ β): the lobe pdf vanishes, plane 2 takes everything.
        let kinked = balance(technique_densities(&s, [0.0, 0.0], [3.0, 0.0]));
        assert!(kinked[1] > 0.999, "{kinked:?}");
        let p = power(straight);
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!(p[1] < b[1], "the power heuristic sharpens the balance heuristic");
    }

    #[test]
    fn densities_match_the_closed_form_on_axis() {
        // x2 = x3 = 0: d1 = L2, d2 = L3, ϑ = 0, q = 1/(2πβ²).
        let s = scene();
        let p = technique_densities(&s, [0.0, 0.0], [0.0, 0.0]);
        let q0 = 1.0 / (2.0 * PI * s.lobe.beta.powi(2));
        assert!((p[0] - q0).abs() < 1e-9 * q0 && (p[2] - q0).abs() < 1e-9 * q0);
        assert_eq!(p[1], 1.0 / PI);
    }
}
