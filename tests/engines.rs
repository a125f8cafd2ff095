//! Equivalence of the engines: the brute force, the restricted engine, and the restricted engine
//! with reverse proposals only must estimate the same things.
//!
//! On the paper's scene and on a uniformly lit one (both scaled down: N_F = 2·10⁵, N_B = 20,
//! R = 0.02, so that the brute force runs in seconds), each engine runs 40 blocks of 50 iterations
//! from a fixed seed. For every pair of engines the test compares, within 3 standard errors: the
//! merge events per iteration at each plane, and the luminance L and the RMS% of every per-path
//! strategy. Blocks are compared pairwise (`sim::equivalence`): block b of both engines sees the
//! same camera paths, so the standard error of the difference comes from the spread of the block
//! differences — RMS% estimates are heavy-tailed, and independent blocks of equal length measure
//! their error honestly where a bootstrap would understate it, while the shared cameras cancel
//! instead of inflating the error.

use optimis::sim::checks::equivalence::{Figures, compare, measure};
use optimis::sim::checks::expectation::merges;
use optimis::sim::model::config::Engine;
use optimis::sim::model::config::Proposals;
use optimis::sim::runner::run;
use optimis::sim::spec::parse_job_spec;
use serde_json::json;

const BLOCKS: u64 = 40;
const BLOCK_LEN: u64 = 50;
const SEED: u64 = 2026;

/// Asserts that every figure of `a` and `b` agrees within 3 standard errors of the difference, and that the
/// comparison has power (the luminances' standard errors are small against their values).
fn assert_equivalent(scene: &str, (name_a, a): (&str, &Figures), (name_b, b): (&str, &Figures)) {
    for c in compare(a, b) {
        println!(
            "{scene}: {}: {name_a} {:.6e} ± {:.2e} vs {name_b} {:.6e} ± {:.2e}: difference {:+.2e} ± {:.2e} (z = {:+.2})",
            c.what, c.a.mean, c.a.stderr, c.b.mean, c.b.stderr, c.difference.mean, c.difference.stderr, c.z
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
    let figures = |engine| measure(&job.config().with_engine(engine), SEED, 0, BLOCKS, BLOCK_LEN);
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

/// Given its camera paths, an iteration's plane-2 and plane-3 merges have exact expectations
/// (`sim::expectation`: N_F·Σ_j P(x_pl ∈ D(x_pc_j, R)), in closed form from the light's profile):
/// each engine's totals over many iterations must match the sums of these within 3 standard
/// deviations (at the variance bound of `sim::expectation`, so the test is conservative), on the
/// spot-lit and the uniform scene.
#[test]
fn plane2_and_plane3_merges_match_their_exact_expectation() {
    let iterations = 1000;
    for preset in ["paper-table1", "uniform-illumination"] {
        let job = parse_job_spec(&small(preset)).unwrap().validate().unwrap();
        let expected = merges(job.config(), SEED, 0..iterations);
        for engine in [Engine::Brute, Engine::Restricted(Proposals::Auto)] {
            let config = job.config().with_engine(engine);
            let observed = run(&config, SEED, 0..iterations).pooled().merges;
            for (plane, expected, observed) in [(2, expected.plane2, observed[1]), (3, expected.plane3, observed[2])] {
                let (mean, sd) = (expected.mean, expected.variance_bound.sqrt());
                let z = expected.z(observed as f64);
                let what = format!("{preset}, {}: plane-{plane} merges", engine.id());
                println!("{what} {observed} vs exact expectation {mean:.1} ± {sd:.1} (z = {z:+.2})");
                assert!(mean > 1000.0, "{what}: too few to test: {mean:.1}");
                // The bound must stay close to the mean, or the test would lose its power.
                assert!(
                    expected.variance_bound < 1.1 * mean,
                    "{what}: variance bound {:.1} ≫ mean",
                    expected.variance_bound
                );
                assert!(z.abs() <= 3.0, "{what}: {observed} vs expected {mean:.1}: z = {z:.2}");
            }
        }
    }
}
