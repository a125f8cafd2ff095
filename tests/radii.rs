//! Smaller radii tallied in one run (issue 44): the merges of a run at R contain those at every
//! R′ < R, so a run with `radii` carries the moments of each R′ (docs/model.md §13).
//!
//! The brute force draws every light path's vertices x3, x2 whatever R (from words drawn per path
//! of a stream that depends only on the seed, the iteration and the chunk), so the plane-2 and
//! plane-3 merges at R′ of a run at R are a direct run at R′'s — up to the order in which a chunk
//! adds them (the grids' candidate orders differ with the cell size), i.e. to rounding: counts
//! equal, sums within 10⁻⁹. Plane-1 merges are not: the lobe draw that may reach the pixel skips
//! its azimuth when the deflection cannot land within R, so the chunk's stream advances
//! differently at another R; they are equal in law, as is the restricted engine's process on S(R)
//! restricted to S(R′) to its process on S(R′) — checked statistically by the acceptance study
//! (docs/results.md §22).

use crate::common::{TestServer, assert_problem};
use optimis::sim::runner::run;
use optimis::sim::solve::noise::noise_table;
use optimis::sim::spec::{ValidJob, parse_job_spec};
use optimis::sim::stats::moments::Moments;
use optimis::sim::stats::well_formed::{belongs_to, check_well_formed};
use serde_json::{Value, json};

fn job(doc: Value) -> ValidJob {
    parse_job_spec(&doc).expect("valid document").validate().expect("valid spec")
}

fn run_job(job: &ValidJob) -> Moments {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    pool.install(|| run(job.config(), job.spec().seed, job.spec().iteration_range()))
}

fn brute(radius: f64, radii: &[f64]) -> ValidJob {
    job(json!({ "preset": "paper-table1", "engine": "brute", "light_paths": 100_000, "camera_paths": 100,
        "merge_radius": radius, "radii": radii, "noise_components": true, "iterations": 60, "seed": 12 }))
}

#[test]
fn a_brute_run_at_r_holds_the_runs_at_each_smaller_radius() {
    let wide = run_job(&brute(0.02, &[0.005, 0.01]));
    check_well_formed(&wide).expect("well formed");
    assert_eq!(wide.radii.len(), 2);
    let plain = run_job(&brute(0.02, &[]));
    // The run's own moments do not change with the radii it also tallies.
    for (f, (a, b)) in wide.folds.iter().zip(&plain.folds).enumerate() {
        assert_eq!((a.iterations, a.merges, &a.cell_counts), (b.iterations, b.merges, &b.cell_counts), "fold {f}");
        assert!(a == b, "fold {f}: the moments at R are a plain run's");
    }
    for (sub, r) in wide.radii.iter().zip([0.005, 0.01]) {
        let direct_job = brute(r, &[]);
        let direct = run_job(&direct_job);
        assert_eq!(sub.fingerprint, direct.fingerprint, "R′ = {r}: a direct run's fingerprint");
        assert_eq!(sub.coverage, direct.coverage);
        let cells = direct_job.config().cells().len();
        for (a, b) in sub.folds.iter().zip(&direct.folds) {
            assert_eq!(a.merges[1..], b.merges[1..], "R′ = {r}: plane-2 and plane-3 merge counts");
            assert_eq!(a.cell_counts[cells..], b.cell_counts[cells..], "R′ = {r}: their cell counts");
        }
        assert!(sub.folds.iter().map(|f| f.merges.iter().sum::<u64>()).sum::<u64>() > 50, "R′ = {r}: merges");
        let (cells, solver) = (direct_job.config().cells(), &direct_job.spec().solver);
        let (a, b) = (noise_table(sub, cells, solver).rows, noise_table(&direct, cells, solver).rows);
        let single_planes: Vec<_> =
            a.iter().zip(&b).filter(|(x, _)| ["plane2", "plane3"].contains(&x.strategy.name())).collect();
        assert_eq!(single_planes.len(), 2);
        for (x, y) in single_planes {
            assert_eq!(x.strategy, y.strategy);
            match (x.rms_percent, y.rms_percent) {
                (Some(p), Some(q)) => assert!((p - q).abs() <= 1e-9 * q.abs(), "R′ = {r} {}: {p} vs {q}", x.strategy),
                (p, q) => assert_eq!(p, q, "R′ = {r} {}", x.strategy),
            }
        }
    }
}

#[test]
fn radii_are_validated_and_make_the_fingerprint() {
    let base = json!({ "preset": "paper-table1", "merge_radius": 0.02 });
    let with = |radii: Value| {
        let mut doc = base.clone();
        doc["radii"] = radii;
        parse_job_spec(&doc).and_then(|s| s.validate())
    };
    let plain = with(json!([])).unwrap();
    let two = with(json!([0.003, 0.01])).unwrap();
    assert_ne!(plain.config().fingerprint(), two.config().fingerprint());
    assert_eq!(two.config().radii().len(), 2);
    assert_eq!(two.config().radii()[0].fingerprint(), with(json!([])).unwrap().config().at_radius(0.003).fingerprint());
    for (bad, why) in [
        (json!([0.02]), "below merge_radius"),
        (json!([0.01, 0.005]), "ascending"),
        (json!([0.005, 0.005]), "ascending"),
        (json!([0.0]), "positive"),
        (json!([0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.007]), "at most 6"),
    ] {
        let e = with(bad.clone()).expect_err(why);
        assert!(e.to_string().contains("radii"), "{bad}: {e}");
    }
}

#[test]
fn moments_with_radii_merge_and_refuse_what_does_not_fit() {
    let job_a = job(json!({ "preset": "paper-table1", "merge_radius": 0.01, "radii": [0.005],
        "light_paths": 1_000_000, "camera_paths": 20, "iterations": 300, "seed": 3 }));
    let mut a = run_job(&job_a);
    let mut doc_b = job_a.spec().clone();
    doc_b.first_iteration = Some(300);
    let b = run_job(&doc_b.validate().unwrap());
    let whole = {
        let mut spec = job_a.spec().clone();
        spec.iterations = 600;
        run_job(&spec.validate().unwrap())
    };
    a.merge(&b).expect("disjoint iterations merge");
    assert_eq!(a, whole, "two halves merged are the whole run, radii included");
    // A moments value whose radius holds other iterations than the run's is refused.
    let mut bad = b.clone();
    bad.radii[0] = a.radii[0].clone();
    assert!(check_well_formed(&bad).is_err());
    // Radii dropped (or fewer than the configuration's) are not that configuration's moments, and
    // do not merge with moments that keep them.
    assert!(belongs_to(&whole, job_a.config()));
    let mut dropped = b.clone();
    dropped.radii.clear();
    check_well_formed(&dropped).expect("well formed on its own");
    assert!(!belongs_to(&dropped, job_a.config()), "a value without its radii is not the configuration's");
    let mut fresh = run_job(&job_a);
    assert!(fresh.merge(&dropped).is_err(), "moments without their radii do not merge");
    assert_eq!(fresh, run_job(&job_a), "a refused merge changes nothing");
}

/// The server: a job with radii reports each radius (bias beside the RMS), and `POST
/// /v1/jobs/{id}/budget` with `target_rmse` gives `optimis budget --target-rmse --json`'s plan.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_reports_each_radius_and_plans_to_a_target_error_as_the_cli_does() {
    let server = TestServer::start().await;
    let id = server
        .submit_and_wait(&json!({ "preset": "paper-table1", "merge_radius": 0.02, "radii": [0.005, 0.01],
            "light_paths": 1_000_000, "camera_paths": 20, "iterations": 3000, "seed": 5, "noise_components": true }))
        .await;
    let result = server.result(id).await;
    let radii = result["radii"].as_array().expect("the report lists the radii").clone();
    let at: Vec<f64> = radii.iter().map(|r| r["merge_radius"].as_f64().unwrap()).collect();
    assert_eq!(at, [0.005, 0.01, 0.02]);
    assert_eq!(radii.iter().map(|r| r["own"].as_bool().unwrap()).collect::<Vec<_>>(), [false, false, true]);
    // The switch's bias is first order in R (docs/model.md §11): +0.85%, +1.68%, +3.30% here.
    let switch: Vec<f64> = radii
        .iter()
        .map(|r| {
            let row = r["rows"].as_array().unwrap().iter().find(|x| x["strategy"] == "switch").unwrap().clone();
            assert_eq!(row["bias_source"], "quadrature");
            row["bias_percent"].as_f64().unwrap()
        })
        .collect();
    for (b, expected) in switch.iter().zip([0.845, 1.681, 3.297]) {
        assert!((b - expected).abs() < 0.01, "switch bias {switch:?}");
    }

    let body = json!({ "target_rmse": 1.0 });
    let reply = server.post(&format!("/v1/jobs/{id}/budget"), &body).await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let plan = reply.json();
    let error_plan = &plan["error_plan"];
    assert_eq!(error_plan["radii"], json!([0.005, 0.01, 0.02]));
    assert_eq!(plan["target_rms_percent"], 1.0, "target_rms defaults to target_rmse");
    let best = &error_plan["best"];
    assert!(best["seconds_to_target"].as_f64().unwrap() > 0.0 && best["seconds_to_target_stderr"].is_number());
    let out_of_reach = error_plan["out_of_reach"].as_array().unwrap();
    assert!(
        out_of_reach.iter().any(|o| o["strategy"] == "switch" && o["merge_radius"] == 0.02),
        "the switch's 3.3% bias at R = 0.02 is beyond a 1% target: {out_of_reach:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.json"), server.get(&format!("/v1/jobs/{id}/moments")).await.text()).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir.path())
        .args(["budget", "m.json", "--target-rmse", "1", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let cli: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(&cli, error_plan, "the API's error plan is the CLI's");

    for (body, field) in [
        (json!({ "target_rmse": -1 }), "target_rmse"),
        (json!({ "target_rmse": 1, "merge_cost": -1e-8 }), "merge_cost"),
        (json!({ "light_cost": 1e-8 }), "target_rms"),
    ] {
        let problem = assert_problem(server.post(&format!("/v1/jobs/{id}/budget"), &body).await, 422);
        assert_eq!(problem["field"], field, "{problem}");
    }
    server.stop().await;
}
