//! Equivalence of the engines: the brute force, the restricted engine, and the restricted engine
//! with reverse proposals only must estimate the same things.
//!
//! On the paper's scene and on a uniformly lit one (both scaled down: N_F = 2·10⁵, N_B = 20,
//! R = 0.02, so that the brute force runs in seconds), each engine runs 40 blocks of 50 iterations
//! from a fixed seed. For every pair of engines the test compares, within 3 combined standard
//! errors: the mean merge events per iteration at each plane (per-iteration standard errors), and
//! the luminance L and the RMS% of every per-path strategy, as means over the blocks with the
//! standard error of the block means — RMS% estimates are heavy-tailed, and the spread of
//! independent blocks of equal length measures their error honestly where a bootstrap would
//! understate it.

use optimis::sim::config::Engine;
use optimis::sim::equivalence::{Figures, compare, measure};
use optimis::sim::restricted::Proposals;
use optimis::sim::runner::run;
use optimis::sim::spec::parse_job_spec;
use serde_json::json;

const BLOCKS: u64 = 40;
const BLOCK_LEN: u64 = 50;
const SEED: u64 = 2026;

/// Asserts that every figure of `a` and `b` agrees within 3 combined standard errors, and that the
/// comparison has power (the luminances' standard errors are small against their values).
fn assert_equivalent(scene: &str, (name_a, a): (&str, &Figures), (name_b, b): (&str, &Figures)) {
    for c in compare(a, b) {
        println!(
            "{scene}: {}: {name_a} {:.6e} ± {:.2e} vs {name_b} {:.6e} ± {:.2e} (z = {:+.2})",
            c.what, c.a.mean, c.a.stderr, c.b.mean, c.b.stderr, c.z
        );
        assert!(
            c.z.abs() <= 3.0,
            "{scene}: {} differs between {name_a} and {name_b} by {:.2} standard errors",
            c.what,
            c.z
        );
    }
    for (name, l, _) in &a.strategies {
        assert!(l.stderr < 0.2 * l.mean.abs(), "{scene}: L of {name} is too noisy to compare: {l:?}");
    }
}

fn check_scene(scene: &str, doc: serde_json::Value) {
    let job = parse_job_spec(&doc).unwrap().validate().unwrap();
    let figures = |engine| measure(&job.config.with_engine(engine), SEED, 0, BLOCKS, BLOCK_LEN);
    let brute = figures(Engine::Brute);
    let auto = figures(Engine::Restricted(Proposals::Auto));
    let reverse = figures(Engine::Restricted(Proposals::Reverse));
    for f in [&brute, &auto] {
        assert!(f.merges.iter().all(|m| m.mean > 0.1), "{scene}: every plane must see merges: {:?}", f.merges);
    }
    assert_equivalent(scene, ("brute", &brute), ("restricted", &auto));
    assert_equivalent(scene, ("brute", &brute), ("restricted-reverse", &reverse));
    assert_equivalent(scene, ("restricted", &auto), ("restricted-reverse", &reverse));
}

fn small(preset: &str) -> serde_json::Value {
    json!({ "preset": preset, "light_paths": 200_000, "camera_paths": 20, "merge_radius": 0.02 })
}

#[test]
fn engines_agree_on_the_paper_scene() {
    check_scene("paper", small("paper-table1"));
}

#[test]
fn engines_agree_under_uniform_illumination() {
    check_scene("uniform", small("uniform-illumination"));
}

/// Area of the intersection of discs of radii `r` and `big` whose centres are `c` apart.
fn lens_area(r: f64, big: f64, c: f64) -> f64 {
    if c + r <= big {
        return std::f64::consts::PI * r * r;
    }
    if c >= r + big {
        return 0.0;
    }
    let a = r * r * ((c * c + r * r - big * big) / (2.0 * c * r)).acos();
    let b = big * big * ((c * c + big * big - r * r) / (2.0 * c * big)).acos();
    let k = 0.5 * ((-c + r + big) * (c + r - big) * (c - r + big) * (c + r + big)).sqrt();
    a + b - k
}

/// Under uniform illumination the plane-3 merges of an iteration have, given its camera paths, the
/// exact expectation N_F·Σ_j |D(x3c_j, R) ∩ D(0, r_LS)| / (π r_LS²): each engine's total over many
/// iterations must match the sum of these within 3 standard errors (the count is binomial given
/// the cameras, so its variance is at most its mean).
#[test]
fn plane3_merges_match_their_exact_expectation() {
    use optimis::sim::camera::CameraSet;
    let doc =
        json!({ "preset": "uniform-illumination", "light_paths": 200_000, "camera_paths": 20, "merge_radius": 0.02 });
    let job = parse_job_spec(&doc).unwrap().validate().unwrap();
    let r_ls = match job.spec.scene.illumination {
        optimis::sim::spec::IlluminationSpec::Uniform { r_ls } => r_ls,
        _ => unreachable!("the preset is uniform"),
    };
    let iterations = 1000;
    for engine in [Engine::Brute, Engine::Restricted(Proposals::Auto)] {
        let config = job.config.with_engine(engine);
        let moments = run(&config, SEED, 0..iterations);
        let expected: f64 = (0..iterations)
            .map(|s| {
                let cameras = CameraSet::generate(&config, SEED, s);
                let area: f64 = cameras
                    .paths
                    .iter()
                    .filter_map(|p| p.x3)
                    .map(|x3| lens_area(config.merge_radius, r_ls, x3[0].hypot(x3[1])))
                    .sum();
                config.light_paths as f64 * area / (std::f64::consts::PI * r_ls * r_ls)
            })
            .sum();
        let observed = moments.pooled().merges[2] as f64;
        let z = (observed - expected) / expected.sqrt();
        println!("{}: plane-3 merges {observed} vs exact expectation {expected:.1} (z = {z:+.2})", engine.id());
        assert!(z.abs() <= 3.0, "{}: plane-3 merges {observed} vs expected {expected:.1}: z = {z:.2}", engine.id());
    }
}
