use super::*;
use crate::sim::math::rng::{stream, uniform};
use crate::sim::model::params::{IlluminationSpec, SceneSpec};

fn scene(illumination: IlluminationSpec) -> Scene {
    Scene::from_spec(&SceneSpec { l2: 1.0, l3: 3.0, beta_deg: 3.0, illumination })
}

fn uniform_scene() -> Scene {
    scene(IlluminationSpec::Uniform { r_ls: 20.0 })
}

/// The paper's scene and counts: N_F = 10⁷, N_B = 100, R = 0.003.
fn paper() -> (Scene, f64, f64, f64) {
    (scene(IlluminationSpec::Spot { a: 0.02, r_ls: 20.0, contrast: 10_000.0 / 3.0 }), 1e7, 100.0, 0.003)
}

/// Surrogate probabilities of the join path (x2, x3) whose light path starts at x3.
fn sharing_at(scene: &Scene, x2: [f64; 2], x3: [f64; 2], r: f64) -> Sharing {
    let v = JoinGeometry::new(scene, x2, x3).vertex_densities(scene);
    Sharing::new(&v, scene.illumination.density(x3[0].hypot(x3[1])), PI * r * r)
}

/// A join path spread over the region merges happen in (x2 within 1.5, x3 within 0.6 of it).
fn join_path(rng: &mut crate::sim::math::rng::StreamRng) -> ([f64; 2], [f64; 2]) {
    let x2 = [3.0 * uniform(rng) - 1.5, 3.0 * uniform(rng) - 1.5];
    (x2, [x2[0] + 1.2 * uniform(rng) - 0.6, x2[1] + 1.2 * uniform(rng) - 0.6])
}

fn assert_rel(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol * b.abs(), "{what}: {a:e} vs {b:e}");
}

#[test]
fn weights_sum_to_one_and_follow_the_lobe() {
    let s = uniform_scene();
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
    let s = uniform_scene();
    let p = technique_densities(&s, [0.0, 0.0], [0.0, 0.0]);
    let q0 = 1.0 / (2.0 * PI * s.lobe.beta.powi(2));
    assert!((p[0] - q0).abs() < 1e-9 * q0 && (p[2] - q0).abs() < 1e-9 * q0);
    assert_eq!(p[1], 1.0 / PI);
    let v = JoinGeometry::new(&s, [0.0, 0.0], [0.0, 0.0]).vertex_densities(&s);
    let expected =
        VertexDensities { camera_x2: 1.0 / PI, camera_x3: q0 / 9.0, light_x2: 1.0 / (9.0 * PI), light_x1: q0 };
    for (a, b) in [
        (v.camera_x2, expected.camera_x2),
        (v.camera_x3, expected.camera_x3),
        (v.light_x2, expected.light_x2),
        (v.light_x1, expected.light_x1),
    ] {
        assert_rel(a, b, 1e-9, "vertex density on the axis");
    }
}

/// The relative technique densities are the ratios of the products of vertex densities of the
/// module doc (the common light start cancels), anywhere.
#[test]
fn technique_densities_are_products_of_vertex_densities() {
    let s = uniform_scene();
    let mut rng = stream(13, 0, 0);
    for _ in 0..1000 {
        let (x2, x3) = join_path(&mut rng);
        let g = JoinGeometry::new(&s, x2, x3);
        let (p, v) = (g.technique_densities(&s), g.vertex_densities(&s));
        let products = [v.light_x1 * v.light_x2, v.camera_x2 * v.light_x2, v.camera_x2 * v.camera_x3];
        assert_rel(p[0] / p[1], products[0] / products[1], 1e-12, "p0/p1");
        assert_rel(p[2] / p[1], products[2] / products[1], 1e-12, "p2/p1");
    }
}

/// With one light path and one camera path nothing is re-used: every count is 1 and the weights
/// are the balance heuristic's, bit for bit, whatever the surrogate probabilities.
#[test]
fn without_reuse_it_is_the_balance_heuristic() {
    let (s, _, _, r) = paper();
    let mut rng = stream(13, 1, 0);
    for _ in 0..1000 {
        let (x2, x3) = join_path(&mut rng);
        let p = technique_densities(&s, x2, x3);
        let sharing = sharing_at(&s, x2, x3, 10.0 * r);
        assert_eq!(effective_counts(&sharing, 1.0, 1.0), [1.0; 3]);
        assert_eq!(correlation_aware(p, &sharing, 1.0, 1.0), balance(p));
    }
}

/// As the merge disc shrinks no vertex is shared: the weights become the balance heuristic with
/// the true sample counts, N_F for plane 1 (one pixel) and N_F·N_B for planes 2 and 3.
#[test]
fn without_correlation_it_is_the_balance_heuristic_with_the_true_counts() {
    let (s, n_f, n_b, _) = paper();
    let mut rng = stream(13, 2, 0);
    for _ in 0..1000 {
        let (x2, x3) = join_path(&mut rng);
        let p = technique_densities(&s, x2, x3);
        let w = correlation_aware(p, &sharing_at(&s, x2, x3, 1e-9), n_f, n_b);
        let expected = balance_with_counts(p, [1.0 / n_b, 1.0, 1.0]);
        for m in 0..3 {
            assert!((w[m] - expected[m]).abs() < 1e-9, "{w:?} vs {expected:?}");
        }
        // Which differs from the equal-count balance heuristic wherever plane 1 matters.
        let b = balance(p);
        if b[0] > 0.1 {
            assert!(w[0] < b[0] / 5.0, "plane 1 keeps a hundredth of its count: {w:?} vs {b:?}");
        }
    }
}

/// Plane 1 merges at the pixel, the prefix every camera path shares: its count is N_F exactly
/// (n_0/(N_F N_B) = 1/N_B), however likely its light sub-path is.
#[test]
fn plane1_counts_its_light_paths_once() {
    for (n_f, n_b) in [(1e7, 100.0), (50.0, 7.0), (1.0, 3.0)] {
        for pl in [0.0, 1e-9, 0.3, 0.999] {
            let sharing = Sharing { camera: [1.0, 0.5, 0.5], light: [pl, 0.5, 0.5] };
            assert_rel(effective_counts(&sharing, n_f, n_b)[0], 1.0 / n_b, 1e-12, "n_0/(N_F N_B)");
        }
    }
}

/// Bounds and limits of the counts over a grid of sharing probabilities, and their direction: with
/// one camera path (no light sub-path re-used) a likelier prefix carries less of the variance and a
/// likelier light sub-path is re-used more, so n rises with P_c and falls with P_l, as CAMIS's
/// ratio P_c/(P_c + P_l − P_c P_l) does; with one light path, the mirror image. With both re-used
/// neither direction holds in general (P_c → 1 ends the prefix's share but makes the light
/// sub-path's re-use by the camera paths total).
#[test]
fn counts_are_bounded_and_move_with_sharing() {
    let grid = [0.0, 1e-9, 1e-4, 0.01, 0.3, 0.9, 1.0];
    for (n_f, n_b) in [(1e7, 100.0), (40.0, 3.0), (1.0, 10.0), (2.0, 2.0), (1e7, 1.0), (1.0, 100.0)] {
        let count = |pc: f64, pl: f64| effective_counts(&Sharing { camera: [pc; 3], light: [pl; 3] }, n_f, n_b)[0];
        let lower = 1.0 / (n_f + n_b - 1.0);
        for &pc in &grid {
            for &pl in &grid {
                let n = count(pc, pl);
                if pc == 1.0 && pl == 1.0 {
                    assert_rel(n, 1.0 / (n_f * n_b), 1e-15, "every pair the same: one sample");
                    continue;
                }
                assert!(n <= 1.0 && n >= lower * (1.0 - 1e-12), "n = {n} outside [{lower}, 1] at {pc}, {pl}");
                if pl == 1.0 {
                    assert_rel(n, 1.0 / n_f, 1e-12, "one light sub-path: N_B samples");
                }
                if pc == 1.0 {
                    assert_rel(n, 1.0 / n_b, 1e-12, "one camera prefix: N_F samples");
                }
                if n_b != 1.0 && n_f != 1.0 {
                    continue;
                }
                // One camera path: n rises with P_c and falls with P_l; one light path: the mirror.
                let camera_rises = n_b == 1.0;
                let no_less = |m: f64| m >= n * (1.0 - 1e-12);
                let no_more = |m: f64| m <= n * (1.0 + 1e-12);
                for &more in grid.iter().filter(|&&x| x > pc) {
                    let m = count(more, pl);
                    assert!(if camera_rises { no_less(m) } else { no_more(m) }, "P_c {pc} → {more} at {pl}: {n} → {m}");
                }
                for &more in grid.iter().filter(|&&x| x > pl) {
                    let m = count(pc, more);
                    assert!(if camera_rises { no_more(m) } else { no_less(m) }, "P_l {pl} → {more} at {pc}: {n} → {m}");
                }
            }
        }
    }
}

/// The count is the hit-or-miss model's, exactly: with g = 1[ξ ∈ S_c]·1[η ∈ S_l]/(P_c P_l), the
/// iteration's mean is B_c·B_l/(N_F N_B P_c P_l) for independent binomials B_c ~ (N_B, P_c) and
/// B_l ~ (N_F, P_l), whose variance (from the binomials' moments, not from the covariance count
/// of the module doc) must be σ²/n with σ² = 1/(P_c P_l) − 1.
#[test]
fn count_is_the_variance_ratio_of_the_crossed_design() {
    for (n_f, n_b) in [(1e7, 100.0), (30.0, 8.0), (1.0, 5.0), (12.0, 1.0)] {
        for (pc, pl) in [(0.2, 0.05), (1e-9, 7.5e-5), (0.9, 0.9), (0.5, 1e-6), (1e-3, 1e-3)] {
            let second = |n: f64, p: f64| n * p * (1.0 - p + n * p);
            let mean = n_b * pc * n_f * pl;
            let var = (second(n_b, pc) * second(n_f, pl) - mean * mean) / (mean * mean);
            let n = n_f * n_b * effective_counts(&Sharing { camera: [pc; 3], light: [pl; 3] }, n_f, n_b)[0];
            assert_rel((1.0 / (pc * pl) - 1.0) / n, var, 1e-9, "σ²/n vs the binomials' variance");
        }
    }
}

/// The weights sum to 1 and lie in [0, 1] everywhere, in and out of the spot.
#[test]
fn correlation_aware_weights_sum_to_one() {
    let (s, n_f, n_b, r) = paper();
    let mut rng = stream(13, 3, 0);
    for i in 0..20_000 {
        let (mut x2, mut x3) = join_path(&mut rng);
        if i % 2 == 0 {
            // Half of the paths start in the spot.
            x3 = [0.04 * uniform(&mut rng) - 0.02, 0.04 * uniform(&mut rng) - 0.02];
            x2 = [x3[0] + 0.4 * uniform(&mut rng) - 0.2, x3[1] + 0.4 * uniform(&mut rng) - 0.2];
        }
        let w = correlation_aware(technique_densities(&s, x2, x3), &sharing_at(&s, x2, x3, r), n_f, n_b);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-14, "{w:?}");
        assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)), "{w:?}");
    }
}

/// At the paper's values: inside the spot the plane-3 count falls by about the number of light
/// paths merging with one camera vertex (N_F·πR²·I/Φ ≈ 750), so weight moves from plane 3 to
/// plane 2; outside it the counts stay within a factor 1.3 of N_F·N_B; the plane-2 count barely
/// moves. The figures the module doc quotes.
#[test]
fn in_the_spot_plane3_gives_way_to_plane2() {
    let (s, n_f, n_b, r) = paper();
    let straight = |x3: [f64; 2]| [x3[0] / 4.0, x3[1] / 4.0];
    let inside = [0.01, 0.0];
    let outside = [0.5, 0.0];
    let n_in = effective_counts(&sharing_at(&s, straight(inside), inside, r), n_f, n_b);
    let n_out = effective_counts(&sharing_at(&s, straight(outside), outside, r), n_f, n_b);
    let merging = n_f * PI * r * r * s.illumination.density(0.01);
    eprintln!(
        "inside: 1/n = {:?}, N_F·A·I/Φ = {merging:.1}; outside: 1/n = {:?}",
        n_in.map(|n| 1.0 / n),
        n_out.map(|n| 1.0 / n)
    );
    assert_rel(1.0 / n_in[2], 1.0 + merging, 0.01, "the plane-3 count in the spot");
    assert!(1.0 / n_out[2] > 1.1 && 1.0 / n_out[2] < 1.3, "{n_out:?}");
    assert!(1.0 / n_in[1] < 1.002 && 1.0 / n_out[1] < 1.002, "{n_in:?} {n_out:?}");
    assert_rel(n_in[0], 1.0 / n_b, 1e-12, "plane 1");
    let p = technique_densities(&s, straight(inside), inside);
    let (w, b) = (correlation_aware(p, &sharing_at(&s, straight(inside), inside, r), n_f, n_b), balance(p));
    eprintln!("inside, straight: balance {b:?}, correlation-aware {w:?}");
    assert!(w[1] > b[1] && w[2] < b[2], "{w:?} vs {b:?}");
}
