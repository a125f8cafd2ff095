//! Issue 41: the weight function a run recommends, taken away as an artifact — served by the job
//! (`GET /v1/jobs/{id}/weights`), written by `optimis weights`, scored by `optimis evaluate` as
//! the result it came from; evaluated by the C99 header exactly as the engine weighs merges; and
//! `respects_fixed` the same in every route and the command line.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{TestServer, assert_problem};
use serde_json::{Value, json};

fn optimis(args: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_optimis")).args(args).output().unwrap();
    assert!(out.status.success(), "optimis {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or(Value::Null)
}

fn run_doc(dir: &Path, name: &str, seed: u64, iterations: u64, sets: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let (seed, iterations) = (seed.to_string(), iterations.to_string());
    let mut args = vec!["run", "--preset", "paper-table1", "--seed", &seed, "--iterations", &iterations, "--quiet"];
    for s in sets {
        args.extend(["--set", s]);
    }
    args.extend(["--out", path.to_str().unwrap()]);
    let _ = Command::new(env!("CARGO_BIN_EXE_optimis")).args(&args).output().unwrap();
    assert!(path.exists());
    path
}

/// `optimis evaluate LONG --weights X --json`'s evaluated row.
fn evaluated(long: &Path, weights: &Path) -> Value {
    optimis(&["evaluate", long.to_str().unwrap(), "--weights", weights.to_str().unwrap(), "--json"])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_jobs_weights_are_an_artifact_that_scores_as_its_result() {
    let server = TestServer::start().await;
    let spec = json!({ "preset": "paper-table1", "iterations": 3000, "seed": 4 });
    let id = server.submit_and_wait(&spec).await;
    let result = server.result(id).await;
    let recommended = server.get_json(&format!("/v1/jobs/{id}/weights")).await;
    assert_eq!(recommended["format"], "optimis-weights");
    assert_eq!(recommended["strategy"], result["recommended"]["strategy"]);
    assert_eq!(recommended["recommended"], true);
    assert_eq!(recommended["provenance"]["job_id"], id);
    let stack = server.get_json(&format!("/v1/jobs/{id}/weights?strategy=optimal_stacked")).await;
    assert_eq!(stack["kind"], "stack");
    assert!(stack["table"].as_array().unwrap().len() == 52 && !stack["heuristics"].as_array().unwrap().is_empty());
    let problem = assert_problem(server.get(&format!("/v1/jobs/{id}/weights?strategy=nope")).await, 422);
    assert_eq!(problem["field"], "strategy", "{problem}");
    // Scored on an independent long run, the artifacts give exactly the figures of the result
    // they came from (the recommended row), and of the table they hold (the stack).
    let dir = tempfile::tempdir().unwrap();
    let long = run_doc(dir.path(), "long.json", 9, 20_000, &[]);
    let write = |name: &str, v: &Value| {
        let p = dir.path().join(name);
        std::fs::write(&p, serde_json::to_vec(v).unwrap()).unwrap();
        p
    };
    let (from_result, from_artifact) =
        (evaluated(&long, &write("result.json", &result)), evaluated(&long, &write("artifact.json", &recommended)));
    assert_eq!(from_artifact["evaluated"], from_result["evaluated"]);
    let doc = write("moments.json", &server.moments(id).await);
    let cli = dir.path().join("stack.json");
    optimis(&["weights", doc.to_str().unwrap(), "--strategy", "optimal_stacked", "--out", cli.to_str().unwrap()]);
    let cli_stack: Value = serde_json::from_slice(&std::fs::read(&cli).unwrap()).unwrap();
    assert_eq!(cli_stack["table"], stack["table"], "the CLI and the server write the same artifact");
    assert_eq!(cli_stack["heuristics"], stack["heuristics"]);
    let stacked_rms = evaluated(&long, &cli)["evaluated"]["rms_percent"].as_f64().unwrap();
    assert!(stacked_rms.is_finite() && stacked_rms > 0.0);
    server.stop().await;
}

/// Issue 41, item 4: `/evaluate` said `respects_fixed: true` for plane1, balance, power and
/// correlation_aware, which `/result` marks `false` (the paper fixes w0 = 0 and they merge at the
/// pixel). Every route and the command line now say the same.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn respects_fixed_means_the_same_in_every_route_and_the_cli() {
    let server = TestServer::start().await;
    let id = server.submit_and_wait(&json!({ "preset": "paper-table1", "iterations": 2000, "seed": 5 })).await;
    let result = server.result(id).await;
    let of = |rows: &[Value]| -> Vec<(String, bool)> {
        let mut v: Vec<_> = rows
            .iter()
            .filter(|r| r["lambda"].is_null() && r["strategy"] != "optimal")
            .map(|r| (r["strategy"].as_str().unwrap().to_string(), r["respects_fixed"].as_bool().unwrap()))
            .collect();
        v.sort();
        v
    };
    let expected = of(result["noise_table"].as_array().unwrap());
    assert!(expected.contains(&("balance".into(), false)) && expected.contains(&("switch".into(), true)));
    let evaluation = server.post(&format!("/v1/jobs/{id}/evaluate"), &result).await;
    assert_eq!(evaluation.status, 200, "{}", evaluation.text());
    let versus: Vec<Value> = evaluation.json()["versus"].as_array().unwrap().iter().map(|v| v["row"].clone()).collect();
    assert_eq!(of(&versus), expected, "/evaluate");
    let dir = tempfile::tempdir().unwrap();
    let doc = dir.path().join("m.json");
    std::fs::write(&doc, serde_json::to_vec(&server.moments(id).await).unwrap()).unwrap();
    let weights = dir.path().join("r.json");
    std::fs::write(&weights, serde_json::to_vec(&result).unwrap()).unwrap();
    let cli = evaluated(&doc, &weights);
    let rows: Vec<Value> = cli["versus"].as_array().unwrap().iter().map(|v| v["row"].clone()).collect();
    assert_eq!(of(&rows), expected, "optimis evaluate");
    server.stop().await;
}

/// The C99 header (`clients/c/optimis_weights.h`), compiled with the system's C compiler, gives the
/// engine's weight of every merge of the test vectors `optimis weights` writes (≥ 10⁵ join paths
/// drawn with the engine's samplers) within 10⁻¹² — for a heuristic, a table and a stack, in the
/// paper's scene, a wider one and a uniform light. (The Python evaluator is checked the same way
/// by clients/python/tests/test_weights.py.)
#[test]
fn the_c_header_gives_the_engines_weights() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("clients/c");
    let check = dir.path().join("check");
    let compiled = Command::new("cc")
        .args(["-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-I"])
        .arg(&root)
        .arg("-o")
        .arg(&check)
        .arg(root.join("examples/check_vectors.c"))
        .arg("-lm")
        .output()
        .expect("a C compiler (cc) on the PATH");
    assert!(compiled.status.success(), "cc: {}", String::from_utf8_lossy(&compiled.stderr));
    let scenes: [(&str, &[&str]); 3] = [
        ("paper", &[]),
        ("wide", &["merge_radius=0.01", "scene.beta_deg=8", "scene.l3=2"]),
        ("uniform", &["scene.illumination={\"kind\": \"uniform\", \"r_ls\": 20}", "camera_paths=30"]),
    ];
    for (name, sets) in scenes {
        let doc = run_doc(dir.path(), &format!("{name}.json"), 2, 3000, sets);
        for strategy in [None, Some("optimal_stacked"), Some("optimal_cv"), Some("balance_planes23")] {
            let label = strategy.unwrap_or("recommended");
            let (artifact, vectors) =
                (dir.path().join(format!("{name}-{label}.json")), dir.path().join(format!("{name}-{label}.csv")));
            let mut args = vec!["weights", doc.to_str().unwrap(), "--out", artifact.to_str().unwrap()];
            args.extend(["--vectors", vectors.to_str().unwrap(), "--vector-count", "100000"]);
            if let Some(s) = strategy {
                args.extend(["--strategy", s]);
            }
            optimis(&args);
            let out = Command::new(&check).arg(&artifact).arg(&vectors).output().unwrap();
            let report = String::from_utf8_lossy(&out.stdout);
            eprintln!("{name} {label}: {}", report.trim());
            assert!(out.status.success(), "{name} {label}: {report} {}", String::from_utf8_lossy(&out.stderr));
        }
    }
}
