//! The HTTP API against a real server on 127.0.0.1 with a SQLite file in a temporary directory.

use std::time::Duration;

use crate::common::{TestServer, assert_problem, small_job};
use futures_util::StreamExt;
use reqwest::Method;
use serde_json::{Value, json};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_poll_and_read_the_result() {
    let server = TestServer::start().await;
    let response = server.post("/v1/jobs", &small_job(12, 3)).await;
    assert_eq!(response.status, 202);
    let job = response.json();
    assert_eq!(response.header("location"), Some(format!("/v1/jobs/{}", job["id"]).as_str()));
    assert_eq!(job["state"], "queued");
    assert_eq!(job["spec"]["preset"], "paper-table1");
    assert_eq!(job["spec"]["light_paths"], 20_000);
    assert_eq!(job["progress"]["iterations_total"], 12);
    assert!(job["reference_luminance"].as_f64().unwrap() > 2.6e-4);

    let id = job["id"].as_i64().unwrap();
    let done = server.wait_for_state(id, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], 12);
    assert_eq!(done["progress"]["iterations_checkpointed"], 12);
    assert!(done["progress"]["best"]["rms_percent"].as_f64().unwrap() > 0.0);

    let result = server.result(id).await;
    assert_eq!(result["partial"], false);
    assert_eq!(result["iterations"], 12);
    let names: Vec<&str> =
        result["noise_table"].as_array().unwrap().iter().map(|r| r["strategy"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "plane1",
            "plane2",
            "plane3",
            "switch",
            "optimal",
            "optimal_holdout",
            "optimal_cv",
            "balance",
            "power",
            "correlation_aware",
            "balance_planes23",
            "power_planes23",
            "correlation_aware_planes23",
            "optimal_stacked",
            "switch_corrected",
            "balance_planes23_corrected",
            "power_planes23_corrected",
            "correlation_aware_planes23_corrected"
        ]
    );
    for row in result["noise_table"].as_array().unwrap() {
        for key in [
            "heuristics",
            "cv_path",
            "unstable",
            "expected_luminance",
            "z",
            "expected_error",
            "luminance",
            "luminance_stderr",
            "rms_percent",
            "rms_percent_stderr",
            "lambda",
            "in_sample",
            "in_sample_luminance",
            "in_sample_luminance_stderr",
            "in_sample_rms_percent",
            "error",
        ] {
            assert!(row.get(key).is_some(), "row {row} lacks {key}");
        }
        assert_eq!(row["in_sample"], row["strategy"] == "optimal", "only the paper's procedure is in-sample");
    }
    // Per-path rows carry their expectation at R and z; fitted rows say why they have none.
    let row = |name: &str| result["noise_table"].as_array().unwrap().iter().find(|r| r["strategy"] == name).unwrap();
    assert!(
        row("switch")["expected_luminance"].as_f64().unwrap() > row("plane1")["expected_luminance"].as_f64().unwrap()
    );
    assert!(row("optimal_cv")["expected_luminance"].is_null() && row("optimal_cv")["expected_error"].is_string());
    // Twelve iterations support no fit: the guard recommends a per-path strategy that keeps the
    // fixed weights, says why, and there is no table.
    let recommended = &result["recommended"];
    assert!(row(recommended["strategy"].as_str().unwrap())["respects_fixed"].as_bool().unwrap());
    assert!(recommended["reason"].as_str().unwrap().len() > 20, "{recommended}");
    if recommended["lambda"].is_null() {
        assert!(result["weights"].as_array().unwrap().is_empty() && result["weights_fit"].is_null());
    } else {
        assert_eq!(result["weights_fit"]["strategy"], recommended["strategy"]);
    }
    assert_eq!(result["folds"], 10);
    // The paper's λ = 0 in-sample table on request, and a bad λ named.
    let in_sample = server.get_json(&format!("/v1/jobs/{id}/result?lambda=0")).await;
    assert_eq!(
        in_sample["weights_fit"],
        json!({ "strategy": "optimal", "lambda": 0.0, "fitted_on_all_iterations": true })
    );
    assert_eq!(in_sample["noise_table"], result["noise_table"], "the noise table does not depend on the weights shown");
    let bad = assert_problem(server.get(&format!("/v1/jobs/{id}/result?lambda=-1")).await, 422);
    assert!(bad.to_string().contains("lambda"), "{bad}");
    let unparsable = assert_problem(server.get(&format!("/v1/jobs/{id}/result?lambda=abc")).await, 422);
    assert_eq!(unparsable["field"], "lambda", "{unparsable}");
    let unknown = assert_problem(server.get(&format!("/v1/jobs/{id}/result?lamda=1")).await, 422);
    assert!(unknown["detail"].as_str().unwrap().contains("lamda"), "{unknown}");
    let job = server.job(id).await;
    assert_eq!(job["warnings"], result["warnings"], "the job resource carries the latest checkpoint's warnings");
    assert_eq!(job["progress"]["best"]["strategy"], recommended["strategy"], "best follows the recommendation");
    let weights = in_sample["weights"].as_array().unwrap();
    assert!(weights[0].get("w1_stderr").is_some());
    assert_eq!(weights.len(), 52);
    assert_eq!(weights[25]["r3"], json!([0.05, null]), "the tail cell's upper bound is null");
    for w in weights {
        let sum = w["w0"].as_f64().unwrap() + w["w1"].as_f64().unwrap() + w["w2"].as_f64().unwrap();
        assert!((sum - 1.0).abs() < 1e-9);
        assert_eq!(w["w0"], 0.0, "the paper preset fixes w0 = 0");
    }
    assert!(result["reference_luminance"].as_f64().unwrap() > 0.0);
    server.stop().await;
}

/// A submission that names no engine runs the restricted one (the presets' default): the paper's
/// full N_F = 10⁷ per iteration, 300 iterations, in well under a second of simulation.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_default_engine_is_the_restricted_one() {
    let server = TestServer::start().await;
    let id = server.submit(&json!({ "iterations": 300, "seed": 4 })).await;
    let done = server.wait_for_state(id, "succeeded").await;
    assert_eq!(done["spec"]["engine"], "restricted");
    assert_eq!(done["spec"]["light_paths"], 10_000_000);
    let result = server.result(id).await;
    // The statistics are checked against the brute force in tests/engines.rs; here: it merged.
    let plane2 = &result["merges_per_iteration"]["plane2"];
    assert!(plane2["mean"].as_f64().unwrap() > 10.0 * plane2["stderr"].as_f64().unwrap(), "{plane2}");
    let brute = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1000 })).await;
    assert_eq!(server.job(brute).await["spec"]["engine"], "brute");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_error_is_a_problem_document_with_the_right_status() {
    let server = TestServer::start().await;
    // 400: malformed JSON, empty body.
    assert_problem(server.post_raw("/v1/jobs", "{\"iterations\": ").await, 400);
    assert_problem(server.post_raw("/v1/jobs", "").await, 400);
    // 422: invalid fields, named in the detail and in `field`.
    for (body, field) in [
        (json!({ "merge_radius": -0.1 }), "merge_radius"),
        (json!({ "scene": { "beta_deg": 60 } }), "scene.beta_deg"),
        (json!({ "light_paths": 0 }), "light_paths"),
        (json!({ "cells": { "r3_edges": [0, 0.2, 0.1] } }), "cells.r3_edges[2]"),
        (json!({ "bogus": 1 }), "bogus"),
        (json!({ "preset": "unknown" }), "preset"),
        (json!([1, 2]), ""),
    ] {
        let problem = assert_problem(server.post("/v1/jobs", &body).await, 422);
        if !field.is_empty() {
            assert_eq!(problem["field"], field, "{body}");
            assert!(problem["detail"].as_str().unwrap().contains(field), "{problem}");
        }
    }
    let problem = assert_problem(server.get("/v1/jobs?limit=9999").await, 422);
    assert_eq!(problem["field"], "limit");
    let problem = assert_problem(server.get("/v1/jobs?state=paused").await, 422);
    assert_eq!(problem["field"], "state");
    assert_problem(server.get("/v1/jobs?cursor=xyz").await, 422);
    assert_problem(server.get("/v1/jobs?unknown=1").await, 422);
    // 404: unknown jobs and routes.
    assert_problem(server.get("/v1/jobs/424242").await, 404);
    assert_problem(server.get("/v1/jobs/not-a-number").await, 404);
    assert_problem(server.get("/v1/jobs/424242/result").await, 404);
    assert_problem(server.cancel(424242).await, 404);
    assert_problem(server.delete(424242).await, 404);
    assert_problem(server.get("/v2/nothing").await, 404);
    // 405.
    assert_problem(server.request(Method::PUT, "/v1/jobs", None).await, 405);

    // 409: results before the first checkpoint (a queued job behind a long one), cancel of a
    // finished job, delete of a running one, extend of a failed one is covered elsewhere.
    let long = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1_000_000_000u64 })).await;
    server.wait_for_state(long, "running").await;
    let waiting = server.submit(&small_job(2, 1)).await;
    assert_problem(server.get(&format!("/v1/jobs/{waiting}/result")).await, 409);
    assert_problem(server.solve(waiting, &json!({})).await, 409);
    assert_problem(server.delete(long).await, 409);
    server.cancel(long).await;
    server.wait_for_state(long, "cancelled").await;
    server.wait_for_state(waiting, "succeeded").await;
    assert_problem(server.cancel(waiting).await, 409);

    // 422 on the job sub-resources.
    let problem = assert_problem(server.extend(waiting, &json!({ "iterations": 0 })).await, 422);
    assert_eq!(problem["field"], "iterations");
    let problem = assert_problem(server.extend(waiting, &json!({ "more": 2 })).await, 422);
    assert_eq!(problem["field"], "more");
    let problem = assert_problem(server.solve(waiting, &json!({ "lambda": -1 })).await, 422);
    assert_eq!(problem["field"], "solver.lambda");
    assert_problem(server.solve(waiting, &json!({ "fixed": { "w3": 1 } })).await, 422);
    server.stop().await;
}

/// A single iteration of 10⁹ light paths (about 15,000 chunks) is cancelled while running: the job
/// ends cancelled with no iteration completed, so it stopped inside the iteration — between chunks —
/// and not at the iteration's end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_stops_a_running_job_within_a_chunk() {
    let server = TestServer::start().await;
    let id = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1_000_000_000u64 })).await;
    server.wait_for_state(id, "running").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let response = server.cancel(id).await;
    assert_eq!(response.status, 202);
    let job = server.wait_for_state(id, "cancelled").await;
    assert_eq!(job["progress"]["iterations_done"], 0, "the iteration was interrupted, not completed");
    assert_problem(server.get(&format!("/v1/jobs/{id}/result")).await, 409);

    // A queued job is cancelled at once.
    let blocker = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1_000_000_000u64 })).await;
    server.wait_for_state(blocker, "running").await;
    let queued = server.submit(&small_job(3, 2)).await;
    let cancelled = server.cancel(queued).await.json();
    assert_eq!(cancelled["state"], "cancelled");
    server.cancel(blocker).await;
    server.wait_for_state(blocker, "cancelled").await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_list_paginates_newest_first() {
    let server = TestServer::start().await;
    let mut ids = Vec::new();
    for seed in 0..7 {
        ids.push(server.submit(&small_job(1, seed)).await);
    }
    for &id in &ids {
        server.wait_for_state(id, "succeeded").await;
    }
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    let mut pages = 0;
    loop {
        let path = match &cursor {
            Some(c) => format!("/v1/jobs?limit=3&cursor={c}"),
            None => "/v1/jobs?limit=3".to_string(),
        };
        let page = server.get_json(&path).await;
        pages += 1;
        seen.extend(page["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()));
        match page["next_cursor"].as_str() {
            Some(c) => cursor = Some(c.to_string()),
            None => break,
        }
    }
    assert_eq!(pages, 3);
    let mut newest_first = ids.clone();
    newest_first.reverse();
    assert_eq!(seen, newest_first);

    assert!(server.list("?state=cancelled").await.is_empty());
    assert_eq!(server.list("?state=succeeded&limit=500").await.len(), 7);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idempotency_keys_replay_the_original_job() {
    let server = TestServer::start().await;
    let send = |body: Value, key: &'static str| {
        server.send(server.builder(Method::POST, "/v1/jobs").header("Idempotency-Key", key).json(&body))
    };
    let first = send(small_job(2, 9), "abc-1").await;
    assert_eq!(first.status, 202);
    let first = first.json();
    let again = send(small_job(2, 9), "abc-1").await;
    assert_eq!(again.status, 202);
    assert_eq!(again.header("idempotent-replayed"), Some("true"));
    let again = again.json();
    assert_eq!(first["id"], again["id"]);
    let problem = assert_problem(send(small_job(3, 9), "abc-1").await, 422);
    assert_eq!(problem["field"], "Idempotency-Key");
    let other = send(small_job(2, 9), "abc-2").await.json();
    assert_ne!(other["id"], first["id"]);
    assert_eq!(server.list("").await.len(), 2);
    server.stop().await;
}

/// Extending a finished job continues the same deterministic sequence: its moments then equal
/// those of a job that ran all iterations at once, bit for bit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extend_continues_the_sequence_and_delete_removes() {
    let server = TestServer::start().await;
    let id = server.submit(&small_job(6, 4)).await;
    server.wait_for_state(id, "succeeded").await;
    let response = server.extend(id, &json!({ "iterations": 5 })).await;
    assert_eq!(response.status, 202);
    let extended = response.json();
    assert_eq!(extended["progress"]["iterations_total"], 11);
    let done = server.wait_until(id, |j| j["state"] == "succeeded" && j["progress"]["iterations_done"] == 11).await;
    assert_eq!(done["spec"]["iterations"], 11);
    let whole = server.submit_and_wait(&small_job(11, 4)).await;
    let a = server.moments(id).await;
    let b = server.moments(whole).await;
    assert_eq!(a["moments"], b["moments"]);
    assert_eq!(a["checksum"], b["checksum"]);

    assert_eq!(server.delete(id).await.status, 204);
    assert_problem(server.get(&format!("/v1/jobs/{id}")).await, 404);
    assert_problem(server.get(&format!("/v1/jobs/{id}/result")).await, 404);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn solve_recomputes_from_the_stored_moments() {
    let server = TestServer::start().await;
    let id = server
        .submit(
            &json!({ "engine": "brute", "light_paths": 100_000, "camera_paths": 1000, "merge_radius": 0.02, "iterations": 40, "seed": 5 }),
        )
        .await;
    server.wait_for_state(id, "succeeded").await;
    let stored = server.result(id).await;
    let same = server.solve(id, &json!({})).await.json();
    assert_eq!(same, stored, "an empty patch reproduces the stored result");
    let smooth = server.solve(id, &json!({ "lambda": 10 })).await.json();
    assert_eq!(smooth["noise_table"][0], stored["noise_table"][0], "fixed strategies do not change");
    assert_eq!(smooth["weights"], stored["weights"], "the recommended weights come from the λ grid, not from λ");
    assert_ne!(smooth["noise_table"][4], stored["noise_table"][4]);
    let optimal = |r: &Value| r["noise_table"][4]["lambda"].clone();
    assert_eq!(optimal(&smooth), 10.0);
    let grid = server.solve(id, &json!({ "cv_lambdas": [10] })).await.json();
    let cv = |r: &Value| r["noise_table"].as_array().unwrap().iter().find(|x| x["strategy"] == "optimal_cv").cloned();
    assert_eq!(cv(&grid).unwrap()["lambda"], 10.0, "the cross-validation chooses from the grid given");
    assert_ne!(cv(&grid), cv(&stored));
    // A fitted recommendation (if the guard lets one through) is at a λ of that grid.
    assert!(
        grid["recommended"]["lambda"].is_null() || grid["recommended"]["lambda"] == 10.0,
        "{}",
        grid["recommended"]
    );
    let free = server.solve(id, &json!({ "fixed": { "w0": null }, "lambda": 1e-3 })).await.json();
    let optimal = |r: &Value| r["noise_table"].as_array().unwrap().iter().find(|x| x["strategy"] == "optimal").cloned();
    assert_ne!(optimal(&free), optimal(&stored), "the table is re-fitted with w0 free");
    // The weights table is the recommended fitted row's (none when a per-path strategy wins).
    let weights = free["weights"].as_array().unwrap();
    assert_eq!(weights.is_empty(), free["recommended"]["lambda"].is_null(), "{}", free["recommended"]);
    assert!(weights.is_empty() || weights.iter().any(|w| w["w0"] != 0.0), "w0 is fitted once freed");
    let unchanged = server.result(id).await;
    assert_eq!(unchanged, stored, "solve stores nothing");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn events_stream_progress_until_the_end() {
    let server = TestServer::start().await;
    let id = server.submit(&small_job(30, 6)).await;
    let response = server.open(&format!("/v1/jobs/{id}/events")).await;
    assert_eq!(response.status(), 200);
    assert!(response.headers()["content-type"].to_str().unwrap().starts_with("text/event-stream"));
    let mut body = String::new();
    let mut stream = response.bytes_stream();
    while let Some(chunk) = stream.next().await {
        body.push_str(std::str::from_utf8(&chunk.unwrap()).unwrap());
    }
    let events: Vec<Value> =
        body.lines().filter_map(|l| l.strip_prefix("data: ")).map(|d| serde_json::from_str(d).unwrap()).collect();
    assert!(events.len() >= 2, "{body}");
    assert!(body.lines().filter(|l| l.starts_with("event: ")).all(|l| l == "event: job"));
    assert_eq!(events.last().unwrap()["state"], "succeeded", "the stream ends at the terminal state");
    let done: Vec<u64> = events.iter().map(|e| e["progress"]["iterations_done"].as_u64().unwrap()).collect();
    assert!(done.windows(2).all(|w| w[0] <= w[1]), "progress never goes back: {done:?}");
    // Every event has an id (its iterations; the last one its state too), the first a retry.
    let ids: Vec<&str> = body.lines().filter_map(|l| l.strip_prefix("id: ")).collect();
    assert_eq!(ids.len(), events.len(), "{body}");
    assert_eq!(*ids.last().unwrap(), "30-succeeded");
    assert_eq!(body.lines().filter(|l| l.starts_with("retry: ")).collect::<Vec<_>>(), ["retry: 5000"]);
    // A finished job has nothing to stream: 204, which ends a browser's EventSource.
    let finished = server.get(&format!("/v1/jobs/{id}/events")).await;
    assert_eq!((finished.status, finished.text().as_str()), (204, ""));
    assert_problem(server.get("/v1/jobs/999/events").await, 404);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_readiness_and_openapi() {
    let server = TestServer::start().await;
    assert_eq!(server.get_json("/healthz").await["status"], "ok");
    assert_eq!(server.get_json("/readyz").await["status"], "ok");
    let served = server.get("/openapi.yaml").await.text();
    let committed = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml")).unwrap();
    assert_eq!(
        served, committed,
        "openapi.yaml is stale: regenerate it with `cargo run --release -- openapi > openapi.yaml`"
    );
    server.stop().await;
}

/// The value of the sample `name{labels}` in an OpenMetrics exposition.
fn sample(text: &str, series: &str) -> Option<f64> {
    text.lines().find_map(|l| l.strip_prefix(series).and_then(|rest| rest.trim().parse().ok()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_show_a_running_job_progressing() {
    let server = TestServer::start().await;
    let id = server
        .submit(&json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 400, "seed": 1 }))
        .await;
    server.wait_for_state(id, "running").await;
    let series = format!("optimis_job_iterations_done{{job_id=\"{id}\"}}");
    let mut seen = Vec::new();
    let started = std::time::Instant::now();
    let text = loop {
        let response = server.get("/metrics").await;
        assert_eq!(response.status, 200);
        assert!(response.header("content-type").unwrap().starts_with("application/openmetrics-text"));
        let text = response.text();
        if let Some(v) = sample(&text, &series)
            && seen.last() != Some(&v)
        {
            seen.push(v);
        }
        // Two increases, and a checkpoint written (the histogram has a count).
        if seen.len() >= 3 && sample(&text, "optimis_checkpoint_duration_seconds_count").unwrap_or(0.0) >= 1.0 {
            break text;
        }
        assert!(started.elapsed() < Duration::from_secs(240), "hang guard: iterations seen {seen:?}\n{text}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "the iteration counter only grows: {seen:?}");
    assert_eq!(sample(&text, "optimis_jobs{state=\"running\"}"), Some(1.0));
    assert!(sample(&text, &format!("optimis_job_light_paths_per_second{{job_id=\"{id}\"}}")).unwrap() > 0.0);
    // The server-wide counters: at least the iterations the job shows, N_F light paths each.
    let iterations = sample(&text, "optimis_iterations_total").unwrap();
    assert!(iterations >= *seen.last().unwrap(), "{iterations} < {seen:?}");
    assert_eq!(sample(&text, "optimis_light_paths_total"), Some(iterations * 2e6));
    let build = format!("optimis_build_info{{version=\"{}\"}}", env!("CARGO_PKG_VERSION"));
    assert_eq!(sample(&text, &build), Some(1.0), "{text}");
    assert!(sample(&text, "process_resident_memory_bytes").unwrap() > 1e6, "{text}");
    assert!(
        text.contains(r#"optimis_http_requests_total{method="GET",route="/v1/jobs/{id}",status="200"}"#),
        "requests are counted by route template:\n{text}"
    );
    server.cancel(id).await;
    server.wait_for_state(id, "cancelled").await;
    let text = server.get("/metrics").await.text();
    assert_eq!(sample(&text, &series), None, "a job that stopped leaves the gauges");
    assert_eq!(sample(&text, "optimis_jobs{state=\"cancelled\"}"), Some(1.0));
    server.stop().await;
}

/// Issue 14: `POST /v1/jobs/{id}/predict` answers the noise table at another budget from a job with
/// noise components, in the shape of a job's noise table; a job without components is a 409 that
/// says how to get them, and a bad budget a 422 naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn predict_answers_another_budget_from_the_noise_components() {
    let server = TestServer::start().await;
    let mut spec = small_job(40, 5);
    spec["noise_components"] = json!(true);
    let id = server.submit_and_wait(&spec).await;
    let reply =
        server.post(&format!("/v1/jobs/{id}/predict"), &json!({ "light_paths": 40_000, "camera_paths": 100 })).await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let p = reply.json();
    assert_eq!(p["job_id"], id);
    assert_eq!(p["budget"], json!({ "light_paths": 40_000, "camera_paths": 100 }));
    assert_eq!(p["measured"], json!({ "light_paths": 20_000, "camera_paths": 200 }));
    let names: Vec<&str> =
        p["noise_table"].as_array().unwrap().iter().map(|r| r["strategy"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "plane1",
            "plane2",
            "plane3",
            "switch",
            "balance",
            "power",
            "correlation_aware",
            "balance_planes23",
            "power_planes23",
            "correlation_aware_planes23",
            "optimal_cv",
            "optimal_stacked"
        ]
    );
    assert!(p["noise_table"][0]["rms_percent"].as_f64().unwrap() > 0.0);
    assert!(p["noise_table"][6]["error"].as_str().unwrap().contains("N_F and N_B"));
    assert!(p["noise_table"][9]["error"].as_str().unwrap().contains("N_F and N_B"));
    let stacked = &p["noise_table"][11];
    let heuristics: Vec<&str> =
        stacked["heuristics"].as_array().unwrap().iter().map(|h| h["strategy"].as_str().unwrap()).collect();
    assert_eq!(
        heuristics,
        ["switch"],
        "of the stacked heuristics (switch, correlation_aware_planes23), none that depends on the budget"
    );
    assert!(p["recommended"]["reason"].is_string());

    let plain = server.submit_and_wait(&small_job(4, 6)).await;
    let refused = assert_problem(
        server.post(&format!("/v1/jobs/{plain}/predict"), &json!({ "light_paths": 2, "camera_paths": 2 })).await,
        409,
    );
    assert!(refused["detail"].as_str().unwrap().contains("noise_components"), "{refused}");
    let bad = assert_problem(
        server.post(&format!("/v1/jobs/{id}/predict"), &json!({ "light_paths": 0, "camera_paths": 2 })).await,
        422,
    );
    assert_eq!(bad["field"], "light_paths", "{bad}");
    let unknown =
        assert_problem(server.post(&format!("/v1/jobs/{id}/predict"), &json!({ "camera_paths": 2 })).await, 422);
    assert_eq!(unknown["field"], "light_paths", "{unknown}");
}

/// Issue 25, item 6: `POST /v1/jobs/{id}/budget` is `optimis budget --json` on the job's moments
/// (the same plan, bit for bit, for the same costs), with its fields validated.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn budget_plans_the_ray_budget_as_the_cli_does() {
    let server = TestServer::start().await;
    let id = server
        .submit_and_wait(&json!({ "preset": "paper-table1", "light_paths": 1_000_000, "iterations": 2000,
            "seed": 5, "noise_components": true }))
        .await;
    let costs =
        json!({ "target_rms": 1.0, "light_cost": 2e-8, "camera_cost": 1e-7, "iteration_cost": 1e-3, "pixels": 1e6 });
    let reply = server.post(&format!("/v1/jobs/{id}/budget"), &costs).await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let plan = reply.json();
    assert_eq!(plan["job_id"], id);
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.json"), server.get(&format!("/v1/jobs/{id}/moments")).await.text()).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir.path())
        .args(["budget", "m.json", "--target-rms", "1", "--light-cost", "2e-8", "--camera-cost", "1e-7"])
        .args(["--iteration-cost", "1e-3", "--pixels", "1e6", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let cli: Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["best", "headline", "search", "costs", "recommended"] {
        assert_eq!(plan[key], cli[key], "{key}");
    }
    let best = plan["best"].as_array().unwrap();
    assert!(best.iter().any(|b| b["speedup"].is_number() && b["speedup_stderr"].is_number()), "{plan}");
    assert_eq!(plan["costs"]["source"], "given");

    // Issue 42, item 4: with no costs given, the API, the CLI (and the dashboard, whose blank costs
    // send none: tests/browser/budget.mjs) take the same reference costs and give the same plan;
    // the CLI times this machine only when asked (--measure-costs).
    let reply = server.post(&format!("/v1/jobs/{id}/budget"), &json!({ "target_rms": 1.0 })).await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let api_default = reply.json();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir.path())
        .args(["budget", "m.json", "--target-rms", "1", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    assert!(!String::from_utf8_lossy(&out.stderr).contains("measuring"), "no timing unless asked: {out:?}");
    let cli_default: Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["best", "headline", "headline_note", "search", "costs", "recommended", "paper", "points", "fixed_time"]
    {
        assert_eq!(api_default[key], cli_default[key], "{key}");
    }
    assert_eq!(
        api_default["costs"],
        json!({ "light_path": 7.3e-9, "camera_path": 4.1e-6, "iteration": 1.9e-4, "pixels": 1e6, "merge": 8e-8,
            "source": "reference" })
    );
    let mixed = server.post(&format!("/v1/jobs/{id}/budget"), &json!({ "target_rms": 1.0, "light_cost": 2e-8 })).await;
    assert_eq!(mixed.json()["costs"]["source"], "mixed", "{}", mixed.text());

    for (body, field) in [
        (json!({ "target_rms": 0, "light_cost": 0, "camera_cost": 0, "iteration_cost": 0 }), "target_rms"),
        (json!({ "target_rms": 1, "light_cost": -1, "camera_cost": 0, "iteration_cost": 0 }), "light_cost"),
        (json!({ "target_rms": 1, "light_cost": 0, "camera_cost": 0, "iteration_cost": 0, "pixels": 0.5 }), "pixels"),
        (json!({ "target_rms": 1, "iteration_cost": 1e7 }), "iteration_cost"),
    ] {
        let problem = assert_problem(server.post(&format!("/v1/jobs/{id}/budget"), &body).await, 422);
        assert_eq!(problem["field"], field, "{problem}");
    }
    let plain = server.submit_and_wait(&small_job(4, 6)).await;
    let refused = server.post(&format!("/v1/jobs/{plain}/budget"), &costs).await;
    assert_problem(refused, 409);
    server.stop().await;
}

/// Another run's result scored on a job's statistics: the recommended strategy's figures on these
/// iterations beside the job's per-path strategies; a table of another grid, a heuristic without a
/// column or cells that do not sum to 1 − Σβ are named.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evaluate_scores_another_runs_weights_on_a_job() {
    let server = TestServer::start().await;
    let first = server.submit_and_wait(&small_job(40, 7)).await;
    let second = server.submit_and_wait(&small_job(40, 8)).await;
    let result = server.result(first).await;
    let reply = server.post(&format!("/v1/jobs/{second}/evaluate"), &result).await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    let e = reply.json();
    assert_eq!(e["job_id"], second);
    assert_eq!(e["iterations"], 40);
    assert_eq!(e["source"], result["recommended"]["strategy"]);
    assert_eq!(e["evaluated"]["in_sample"], false, "another seed's iterations");
    assert!(e["evaluated"]["rms_percent"].as_f64().unwrap() > 0.0);
    assert!(e["evaluated"]["rms_percent_stderr"].as_f64().unwrap() > 0.0);
    assert!(e["versus"].as_array().unwrap().len() >= 7, "the per-path strategies beside");
    // Scored on its own job, the weights are in sample and say so.
    let own = server.post(&format!("/v1/jobs/{first}/evaluate"), &result).await.json();
    assert_eq!(own["evaluated"]["in_sample"], true);

    // A hand-made table: the in-sample λ = 0 table of the first job, its 52 cells.
    let table = server.get_json(&format!("/v1/jobs/{first}/result?lambda=0")).await;
    let given = json!({ "weights": table["weights"] });
    let scored = server.post(&format!("/v1/jobs/{second}/evaluate"), &given).await;
    assert_eq!(scored.status, 200, "{}", scored.text());
    let mut short = given.clone();
    short["weights"].as_array_mut().unwrap().pop();
    let refused = assert_problem(server.post(&format!("/v1/jobs/{second}/evaluate"), &short).await, 422);
    assert_eq!(refused["field"], "weights", "{refused}");
    let mut skewed = given.clone();
    skewed["weights"][3]["w1"] = json!(5.0);
    let refused = assert_problem(server.post(&format!("/v1/jobs/{second}/evaluate"), &skewed).await, 422);
    assert_eq!(refused["field"], "weights[3]", "{refused}");
    let mut foreign = given.clone();
    foreign["heuristics"] = json!([{ "strategy": "optimal_cv", "beta": 0.5 }]);
    let refused = assert_problem(server.post(&format!("/v1/jobs/{second}/evaluate"), &foreign).await, 422);
    assert_eq!(refused["field"], "heuristics[0]", "{refused}");
    let garbled =
        assert_problem(server.post(&format!("/v1/jobs/{second}/evaluate"), &json!({ "weights": 3 })).await, 422);
    assert_eq!(garbled["field"], "weights", "{garbled}");
    assert_problem(server.post("/v1/jobs/999/evaluate", &given).await, 404);
    server.stop().await;
}

/// Issue 42, item 7: the paper's run (10⁴ iterations of the restricted engine, whose batches are
/// 4,096 long) has a point of history every `--checkpoint-iterations` (50 by default) — not only
/// at its 3 checkpoints: between them the per-path rows (sums, no fit), at a checkpoint every row.
/// The points wait for their own cost twice over, so at least 50 come on this run (about 80 on an
/// idle 2-core machine, docs/results.md §20).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_paper_runs_history_has_a_point_every_checkpoint_interval() {
    let server =
        TestServer::start_with(|c| c.policy = optimis::jobs::RunPolicy { workers: 1, ..Default::default() }).await;
    let id = server.submit_and_wait(&json!({ "preset": "paper-table1", "iterations": 10_000, "seed": 4 })).await;
    let history = server.get(&format!("/v1/jobs/{id}/history")).await.json();
    let points = history["points"].as_array().unwrap();
    let at: Vec<u64> = points.iter().map(|p| p["iterations"].as_u64().unwrap()).collect();
    assert!(points.len() >= 50, "{} points: {at:?}", points.len());
    assert!(at.windows(2).all(|w| w[0] < w[1]) && *at.last().unwrap() == 10_000, "{at:?}");
    assert!(at.iter().all(|i| i % 50 == 0), "at the stated interval: {at:?}");
    let rows = |p: &Value| p["strategies"].as_array().unwrap().len();
    let full = points.iter().filter(|p| rows(p) > 10).count();
    assert!(full >= 1 && rows(points.last().unwrap()) > 10, "the last point is the final checkpoint's full table");
    assert!(points.iter().all(|p| rows(p) == 10 || rows(p) > 10), "per-path rows, or the whole table");
    // The per-path figures of the final point are the result's own.
    let result = server.result(id).await;
    let last = points.last().unwrap()["strategies"].as_array().unwrap();
    let switch = last.iter().find(|s| s["strategy"] == "switch").unwrap();
    let table = result["noise_table"].as_array().unwrap().iter().find(|r| r["strategy"] == "switch").unwrap();
    assert_eq!(switch["rms_percent"], table["rms_percent"]);
    server.stop().await;
}
