//! Compare everywhere (issue 25, item 4): `GET /v1/compare?ids=…` and `optimis compare` (moments
//! documents, or jobs with `--server`) give, per strategy, each run's L and RMS and against the
//! first run the ratios and differences with their standard errors — checked here against the
//! runs' own results (independent runs: SE of a difference √(SE_a² + SE_b²)).

use std::process::Command;

use crate::common::{TestServer, assert_problem};
use serde_json::{Value, json};

fn optimis(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir)
        .args(args)
        .env_remove("OPTIMIS_TOKEN")
        .output()
        .expect("optimis runs")
}

fn row<'a>(result: &'a Value, strategy: &str) -> &'a Value {
    result["noise_table"].as_array().unwrap().iter().find(|r| r["strategy"] == strategy).unwrap()
}

fn close(a: &Value, b: f64) -> bool {
    (a.as_f64().unwrap() - b).abs() <= 1e-12 * b.abs().max(1e-300)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn spot_against_uniform_with_standard_errors() {
    let server = TestServer::start().await;
    let spot = server.submit_and_wait(&json!({ "preset": "paper-table1", "iterations": 400, "seed": 1 })).await;
    let uniform =
        server.submit_and_wait(&json!({ "preset": "uniform-illumination", "iterations": 400, "seed": 2 })).await;
    let comparison = server.get_json(&format!("/v1/compare?ids={spot},{uniform}")).await;
    assert_eq!(comparison["runs"][0]["label"], format!("job {spot}"));
    assert_eq!(comparison["runs"][1]["iterations"], 400);
    let (a, b) = (server.result(spot).await, server.result(uniform).await);
    let switch = comparison["strategies"].as_array().unwrap().iter().find(|s| s["strategy"] == "switch").unwrap();
    let (ra, rb) = (row(&a, "switch"), row(&b, "switch"));
    let f = |r: &Value, k: &str| r[k].as_f64().unwrap();
    let other = &switch["runs"][1];
    assert!(close(&other["luminance"], f(rb, "luminance")));
    assert!(close(&other["luminance_difference"], f(rb, "luminance") - f(ra, "luminance")));
    assert!(close(&other["luminance_difference_stderr"], f(rb, "luminance_stderr").hypot(f(ra, "luminance_stderr"))));
    let ratio = f(rb, "rms_percent") / f(ra, "rms_percent");
    assert!(close(&other["rms_ratio"], ratio));
    let rel =
        (f(rb, "rms_percent_stderr") / f(rb, "rms_percent")).hypot(f(ra, "rms_percent_stderr") / f(ra, "rms_percent"));
    assert!(close(&other["rms_ratio_stderr"], ratio * rel));
    assert!(switch["runs"][0]["rms_ratio"].is_null(), "the baseline has no ratio against itself");
    // Bad requests are named.
    for bad in ["ids=1", "ids=a,b", "ids=1,2,3,4,5,6,7,8,9", ""] {
        let problem = assert_problem(server.get(&format!("/v1/compare?{bad}")).await, 422);
        assert!(problem.to_string().contains("ids"), "{bad}: {problem}");
    }
    assert_problem(server.get(&format!("/v1/compare?ids={spot},999")).await, 404);
    // Issue 42: the compare table as CSV from the API, as the dashboard writes it: each job's
    // parameters in front of its noise table's rows (docs/csv.md, "compare").
    let csv = server.get(&format!("/v1/compare?ids={spot},{uniform}&format=csv")).await.text();
    let lines: Vec<&str> = csv.lines().collect();
    let noise = server.get(&format!("/v1/jobs/{spot}/result?format=csv")).await.text();
    let job_columns = "job_id,preset,illumination,spot_a,engine,light_paths,camera_paths,merge_radius,iterations,seed";
    assert_eq!(lines[0], format!("{job_columns},{}", noise.lines().next().unwrap()));
    let (a, b) = (server.result(spot).await, server.result(uniform).await);
    let rows = |r: &Value| r["noise_table"].as_array().unwrap().len();
    assert_eq!(lines.len(), 1 + rows(&a) + rows(&b), "one row per job and strategy");
    assert!(lines[1].starts_with(&format!("{spot},")) && lines[1].contains(",spot,0.02,"), "{}", lines[1]);
    assert!(lines.last().unwrap().starts_with(&format!("{uniform},")) && lines.last().unwrap().contains(",uniform,,"));
    // Each job's rows are its own noise table's, after its parameters.
    for (line, own) in lines[1..].iter().zip(noise.lines().skip(1)) {
        assert!(line.ends_with(own), "{line} / {own}");
    }

    // The CLI: the server's comparison as a table, ratios with their SEs.
    let dir = tempfile::tempdir().unwrap();
    let base = server.base.clone();
    let (s, u) = (spot.to_string(), uniform.to_string());
    let out = tokio::task::spawn_blocking({
        let dir = dir.path().to_path_buf();
        move || optimis(&dir, &["compare", "--server", &base, &s, &u])
    })
    .await
    .unwrap();
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("RMS / base ± SE"), "{text}");
    let line = text.lines().find(|l| l.trim_start().starts_with(&format!("job {uniform}"))).unwrap();
    // L and RMS with their SE columns, then L ratio, ΔL and RMS ratio each "x ± se", and z.
    assert_eq!(line.matches('±').count(), 3, "ratios and the difference each with an SE: {line}");
    assert_eq!(line.split_whitespace().count(), 2 + 4 + 3 * 3 + 1, "every column filled: {line}");

    // From documents: the same comparison, computed here.
    for (id, file) in [(spot, "spot.json"), (uniform, "uniform.json")] {
        let moments = server.get(&format!("/v1/jobs/{id}/moments")).await.text();
        std::fs::write(dir.path().join(file), moments).unwrap();
    }
    let out = optimis(dir.path(), &["compare", "spot.json", "uniform.json", "--json"]);
    assert!(out.status.success(), "{out:?}");
    let local: Value = serde_json::from_slice(&out.stdout).unwrap();
    let local_switch = local["strategies"].as_array().unwrap().iter().find(|s| s["strategy"] == "switch").unwrap();
    assert_eq!(local_switch["runs"], switch["runs"], "the same figures from the documents as from the server");
    // Issue 42: what differs between the runs is named, not left to the reader.
    let notes = local["notes"].as_array().unwrap();
    let named =
        notes.iter().filter_map(Value::as_str).find(|n| n.starts_with("uniform.json differs from spot.json in "));
    assert!(named.is_some_and(|n| n.contains("scene.illumination")), "{notes:?}");
    server.stop().await;
}
