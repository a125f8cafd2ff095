//! Noise components (issue 14): one run predicts the noise at other ray budgets.
//!
//! The predictions of `solve::predict` are compared with direct runs at those budgets (other
//! seeds) within 3 combined standard errors: the jackknife SE of the predicted RMS and the delta-
//! method SE of the measured one. Scene: the paper's, at N_F = 10⁶ so that a run of 40,000
//! iterations takes about a second with the restricted engine.

use optimis::sim::runner::run;
use optimis::sim::solve::noise::{NoiseRow, noise_table};
use optimis::sim::solve::predict::{Budget, predict};
use optimis::sim::spec::{ValidJob, parse_job_spec};
use optimis::sim::stats::moments::Moments;
use serde_json::json;

fn job(light_paths: u64, camera_paths: u64, components: bool, seed: u64, iterations: u64) -> ValidJob {
    let doc = json!({ "preset": "paper-table1", "light_paths": light_paths, "camera_paths": camera_paths,
        "noise_components": components, "iterations": iterations, "seed": seed });
    parse_job_spec(&doc).expect("valid document").validate().expect("valid spec")
}

fn run_job(job: &ValidJob) -> Moments {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    pool.install(|| run(job.config(), job.spec().seed, 0..job.spec().iterations))
}

fn row<'a>(rows: &'a [NoiseRow], name: &str) -> &'a NoiseRow {
    rows.iter().find(|r| r.strategy.name() == name).unwrap()
}

const FIXED: [&str; 6] = ["plane1", "plane2", "plane3", "switch", "balance", "power"];

#[test]
fn at_the_measured_budget_the_prediction_is_the_measured_table() {
    for engine in ["restricted", "brute"] {
        let (light, camera, iterations) = if engine == "brute" { (20_000, 50, 30) } else { (1_000_000, 20, 2000) };
        let mut doc = json!({ "preset": "paper-table1", "light_paths": light, "camera_paths": camera,
            "merge_radius": 0.02, "noise_components": true, "iterations": iterations, "seed": 4, "engine": engine });
        if engine == "restricted" {
            doc["merge_radius"] = json!(0.003);
        }
        let job = parse_job_spec(&doc).unwrap().validate().unwrap();
        let moments = run_job(&job);
        assert!(moments.has_components());
        let budget = Budget { light_paths: light, camera_paths: camera };
        let p = predict(&moments, job.config().cells(), &job.spec().solver, budget, budget).unwrap();
        let measured = noise_table(&moments, job.config().cells(), &job.spec().solver).rows;
        for name in FIXED.iter().chain(&["correlation_aware"]) {
            let (a, b) = (row(&p.noise_table, name).rms_percent, row(&measured, name).rms_percent);
            match (a, b) {
                (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-9 * b, "{engine} {name}: {a} vs {b}"),
                _ => assert_eq!(a, b, "{engine} {name}"),
            }
        }
    }
}

#[test]
fn the_components_leave_the_run_unchanged() {
    let with = run_job(&job(1_000_000, 20, true, 9, 500));
    let without = run_job(&job(1_000_000, 20, false, 9, 500));
    for (a, b) in with.folds.iter().zip(&without.folds) {
        assert_eq!(a.sum_yy, b.sum_yy);
        assert_eq!(a.strategies, b.strategies);
    }
    assert_ne!(with.fingerprint, without.fingerprint, "the components are part of the configuration");
}

#[test]
fn predictions_match_direct_runs_at_other_budgets() {
    let source = job(1_000_000, 20, true, 3, 40_000);
    let moments = run_job(&source);
    let from = Budget { light_paths: 1_000_000, camera_paths: 20 };
    for (seed, (light_paths, camera_paths)) in [(5, (2_000_000, 10)), (6, (500_000, 40)), (7, (1_000_000, 100))] {
        let to = Budget { light_paths, camera_paths };
        let p = predict(&moments, source.config().cells(), &source.spec().solver, from, to).unwrap();
        let direct_job = job(light_paths, camera_paths, false, seed, 40_000);
        let direct = noise_table(&run_job(&direct_job), direct_job.config().cells(), &direct_job.spec().solver).rows;
        for name in FIXED {
            let (pr, dr) = (row(&p.noise_table, name), row(&direct, name));
            let (a, sa) = (pr.rms_percent.unwrap(), pr.rms_percent_stderr.unwrap());
            let (b, sb) = (dr.rms_percent.unwrap(), dr.rms_percent_stderr.unwrap());
            let z = (a - b) / (sa * sa + sb * sb).sqrt();
            eprintln!(
                "({light_paths}, {camera_paths}) {name:>8}: predicted {a:7.1} ± {sa:5.1}, direct {b:7.1} ± {sb:5.1}, z = {z:+.2}"
            );
            assert!(z.abs() < 3.0, "{name} at ({light_paths}, {camera_paths}): z = {z:.2}");
        }
        let ca = row(&p.noise_table, "correlation_aware");
        assert!(ca.rms_percent.is_none() && ca.error.as_deref().unwrap().contains("N_F and N_B"));
        let optimum = row(&p.noise_table, "optimal_cv");
        let (a, b) = (optimum.rms_percent.unwrap(), row(&direct, "optimal_cv").rms_percent.unwrap());
        eprintln!("({light_paths}, {camera_paths}) optimal_cv: predicted {a:.1}, direct {b:.1}");
        // The re-fitted table of the recommended row, for every cell — or none when the guard
        // recommends a per-path strategy at that budget (no fitted row beat it beyond 1.645 SE).
        let recommended = p.recommended.as_ref().expect("a recommendation");
        let expected = if recommended.lambda.is_some() { source.config().cells().len() } else { 0 };
        eprintln!("({light_paths}, {camera_paths}) recommended {}", recommended.strategy);
        assert_eq!(p.weights.len(), expected, "re-fitted weights for every cell of a fitted recommendation");
        // Only supported predictions compete: the listed rows are exactly those whose RMS SE
        // exceeds the limit, and the recommendation is none of them.
        for r in &p.noise_table {
            let listed = p.unsupported.contains(&r.strategy);
            let over = r.error.is_none()
                && r.rms_percent.is_some_and(|v| r.rms_percent_stderr.is_none_or(|se| se > p.support_relative_se * v));
            assert_eq!(listed, over, "{} listed as unsupported: {listed}", r.strategy);
        }
        assert!(!p.unsupported.contains(&recommended.strategy));
    }
    let same = predict(&moments, source.config().cells(), &source.spec().solver, from, from).unwrap();
    assert!(same.unsupported.is_empty(), "nothing is extrapolated at the measured budget");
}
