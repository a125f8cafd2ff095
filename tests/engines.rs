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

use optimis::sim::config::{Engine, SimConfig};
use optimis::sim::moments::Moments;
use optimis::sim::noise::{merge_rates, path_rows};
use optimis::sim::restricted::Proposals;
use optimis::sim::runner::run;
use optimis::sim::spec::parse_job_spec;
use serde_json::json;

const BLOCKS: u64 = 40;
const BLOCK_LEN: u64 = 50;
const SEED: u64 = 2026;

/// Mean and standard error of a sample.
fn mean_se(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// What one engine measured.
struct Measured {
    name: &'static str,
    /// (mean, SE) of the merge events per iteration at planes 1, 2, 3.
    merges: Vec<(f64, f64)>,
    /// Per strategy: (name, L as (mean, SE) over blocks, RMS% as (mean, SE) over blocks).
    rows: Vec<(String, (f64, f64), (f64, f64))>,
}

fn measure(name: &'static str, config: &SimConfig) -> Measured {
    let mut total = Moments::new(config);
    let mut per_block: Vec<Vec<(String, f64, f64)>> = Vec::new();
    for b in 0..BLOCKS {
        let block = run(config, SEED, b * BLOCK_LEN..(b + 1) * BLOCK_LEN);
        per_block.push(
            path_rows(&block).into_iter().map(|r| (r.strategy, r.luminance.unwrap(), r.rms_percent.unwrap())).collect(),
        );
        total.merge(&block).unwrap();
    }
    let merges = merge_rates(&total).iter().map(|r| (r.mean, r.stderr)).collect();
    let rows = (0..per_block[0].len())
        .map(|s| {
            let l: Vec<f64> = per_block.iter().map(|rows| rows[s].1).collect();
            let rms: Vec<f64> = per_block.iter().map(|rows| rows[s].2).collect();
            (per_block[0][s].0.clone(), mean_se(&l), mean_se(&rms))
        })
        .collect();
    Measured { name, merges, rows }
}

/// Asserts that every figure of `a` and `b` agrees within 3 combined standard errors, and that the
/// comparison has power (standard errors small against the values).
fn assert_equivalent(scene: &str, a: &Measured, b: &Measured) {
    let agree = |what: String, (ma, sa): (f64, f64), (mb, sb): (f64, f64)| {
        let combined = (sa * sa + sb * sb).sqrt();
        let z = (ma - mb) / combined;
        println!("{scene}: {what}: {} {ma:.6e} ± {sa:.2e} vs {} {mb:.6e} ± {sb:.2e} (z = {z:+.2})", a.name, b.name);
        assert!(z.abs() <= 3.0, "{scene}: {what} differs between {} and {} by {z:.2} standard errors", a.name, b.name);
    };
    for plane in 0..3 {
        agree(format!("merges/iteration at plane {}", plane + 1), a.merges[plane], b.merges[plane]);
    }
    for ((name, la, ra), (name_b, lb, rb)) in a.rows.iter().zip(&b.rows) {
        assert_eq!(name, name_b);
        agree(format!("L of {name}"), *la, *lb);
        agree(format!("RMS% of {name}"), *ra, *rb);
        assert!(la.1 < 0.2 * la.0.abs(), "{scene}: L of {name} is too noisy to compare: {la:?}");
    }
}

fn check_scene(scene: &str, doc: serde_json::Value) {
    let job = parse_job_spec(&doc).unwrap().validate().unwrap();
    let brute = job.config.with_engine(Engine::Brute);
    let auto = job.config.with_engine(Engine::Restricted(Proposals::Auto));
    let reverse = job.config.with_engine(Engine::Restricted(Proposals::Reverse));
    let brute = measure("brute", &brute);
    let auto = measure("restricted", &auto);
    let reverse = measure("restricted-reverse", &reverse);
    for merges in [&brute.merges, &auto.merges] {
        assert!(merges.iter().all(|&(m, _)| m > 0.1), "{scene}: every plane must see merges: {merges:?}");
    }
    assert_equivalent(scene, &brute, &auto);
    assert_equivalent(scene, &brute, &reverse);
    assert_equivalent(scene, &auto, &reverse);
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
