//! One engine's plane-2 and plane-3 merge events against their exact expectation given the camera
//! paths (`sim::expectation`), over many iterations — a check of an engine against an analytic
//! value rather than against the other engine.
//!
//! cargo run --release --example exact_merges -- uniform-illumination restricted 1000000
//!
//! Arguments: preset (default paper-table1), engine (`restricted` or `brute`, default restricted),
//! iterations (default 10⁵); seed 1.

use optimis::sim::checks::expectation::merges;
use optimis::sim::model::config::Engine;
use optimis::sim::model::config::Proposals;
use optimis::sim::runner::run;
use optimis::sim::spec::parse_job_spec;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let preset = args.get(1).cloned().unwrap_or_else(|| "paper-table1".into());
    let engine = match args.get(2).map(String::as_str) {
        None | Some("restricted") => Engine::Restricted(Proposals::Auto),
        Some("brute") => Engine::Brute,
        Some(other) => panic!("unknown engine {other:?}: restricted or brute"),
    };
    let iterations: u64 = args.get(3).and_then(|n| n.parse().ok()).unwrap_or(100_000);
    let doc = serde_json::json!({ "preset": preset });
    let job = parse_job_spec(&doc).and_then(|s| s.validate()).expect("a valid preset");
    let config = job.config().with_engine(engine);
    let observed = run(&config, 1, 0..iterations).pooled().merges;
    let expected = merges(&config, 1, 0..iterations);
    println!("{preset}, {}, {iterations} iterations:", engine.id());
    for (plane, expected, observed) in [(2, expected.plane2, observed[1]), (3, expected.plane3, observed[2])] {
        let (mean, sd) = (expected.mean, expected.variance_bound.sqrt());
        let z = expected.z(observed as f64);
        println!("  plane-{plane} merges {observed} vs exact expectation {mean:.1} ± {sd:.1} (z = {z:+.2})");
    }
}
