//! The engines' equivalence at full scale: brute force against the restricted engine, block-wise.
//!
//! cargo run --release --example equivalence -- paper-table1 100 100
//!
//! Arguments: preset (default paper-table1), blocks (default 100), iterations per block (default
//! 100); seed 1 for both engines (the same camera paths, different light-path streams). Prints
//! every compared figure, the mean block difference with its standard error, its z-score (see
//! `sim::equivalence`: blocks are compared pairwise) and the largest |z|; then each engine's
//! plane-2 and plane-3 merges against their exact expectation given the camera paths
//! (`sim::expectation`). The small-scale version of this comparison is the test suite's
//! tests/engines.rs; this is the documented long run (docs/results.md).

use optimis::sim::checks::equivalence::{compare, measure};
use optimis::sim::checks::expectation::merges;
use optimis::sim::model::config::Engine;
use optimis::sim::model::config::Proposals;
use optimis::sim::spec::parse_job_spec;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let preset = args.get(1).cloned().unwrap_or_else(|| "paper-table1".into());
    let blocks: u64 = args.get(2).and_then(|n| n.parse().ok()).unwrap_or(100);
    let block_len: u64 = args.get(3).and_then(|n| n.parse().ok()).unwrap_or(100);
    let doc = serde_json::json!({ "preset": preset });
    let job = parse_job_spec(&doc).and_then(|s| s.validate()).expect("a valid preset");
    let started = std::time::Instant::now();
    let brute = measure(&job.config().with_engine(Engine::Brute), 1, 0, blocks, block_len);
    let brute_seconds = started.elapsed().as_secs_f64();
    let started = std::time::Instant::now();
    let restricted = measure(&job.config().with_engine(Engine::Restricted(Proposals::Auto)), 1, 0, blocks, block_len);
    let restricted_seconds = started.elapsed().as_secs_f64();
    println!(
        "{preset}: {blocks} blocks of {block_len} iterations; brute {brute_seconds:.0} s, restricted {restricted_seconds:.1} s"
    );
    println!("| figure | brute | restricted | brute − restricted | z |\n|---|---|---|---|---|");
    let mut worst: f64 = 0.0;
    for c in compare(&brute, &restricted) {
        println!(
            "| {} | {:.5e} ± {:.2e} | {:.5e} ± {:.2e} | {:+.2e} ± {:.2e} | {:+.2} |",
            c.what, c.a.mean, c.a.stderr, c.b.mean, c.b.stderr, c.difference.mean, c.difference.stderr, c.z
        );
        worst = worst.max(c.z.abs());
    }
    println!("largest |z|: {worst:.2}");
    // Each engine's plane-2 and plane-3 merges against their exact expectation given the cameras.
    let expected = merges(job.config(), 1, 0..blocks * block_len);
    for (name, figures) in [("brute", &brute), ("restricted", &restricted)] {
        for (plane, expected) in [(2, expected.plane2), (3, expected.plane3)] {
            let observed = (figures.merges[plane - 1].mean * (blocks * block_len) as f64).round();
            let (mean, sd) = (expected.mean, expected.variance_bound.sqrt());
            let z = expected.z(observed);
            println!("{name}: plane-{plane} merges {observed} vs exact expectation {mean:.1} ± {sd:.1} (z = {z:+.2})");
        }
    }
}
