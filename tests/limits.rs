//! Every configurable limit, and bearer authentication (missing, wrong and right token).

use std::time::Duration;

use crate::common::{Client, TestServer, assert_problem, small_job};
use reqwest::Method;
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn request_bodies_are_limited() {
    let server = TestServer::start_with(|c| c.http.body_bytes = 4096).await;
    let padding = "x".repeat(8000);
    let body = json!({ "iterations": 1, "padding": padding });
    let problem = assert_problem(server.post("/v1/jobs", &body).await, 413);
    assert!(problem["detail"].as_str().unwrap().contains("too large"), "{problem}");
    assert!(server.list("").await.is_empty(), "nothing was created");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_budgets_and_cell_counts_are_limited() {
    let server = TestServer::start_with(|c| {
        c.policy.job_budget = 1e9;
        c.policy.max_cells = 30;
    })
    .await;
    // 20,000 × 200 × 300 = 1.2·10⁹ pairs > 10⁹.
    let problem = assert_problem(
        server
            .post(
                "/v1/jobs",
                &json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 200, "iterations": 300,
        "cells": { "r3_edges": [0, 0.01, 0.02] } }),
            )
            .await,
        422,
    );
    assert_eq!(problem["field"], "iterations");
    assert!(problem["detail"].as_str().unwrap().contains("1.000e9"), "the limit is stated: {problem}");
    // The paper's 52 cells > 30.
    let problem = assert_problem(server.post("/v1/jobs", &small_job(2, 1)).await, 422);
    assert_eq!(problem["field"], "cells");
    assert!(problem["detail"].as_str().unwrap().contains("at most 30"), "{problem}");
    // Within both limits: accepted; extending past the budget is refused.
    let ok = json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 200, "iterations": 200, "cells": { "r3_edges": [0, 0.01, 0.02] } });
    let id = server.submit_and_wait(&ok).await;
    let problem = assert_problem(server.extend(id, &json!({ "iterations": 100 })).await, 422);
    assert_eq!(problem["field"], "iterations");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_queue_is_limited_with_retry_after() {
    let server = TestServer::start_with(|c| c.policy.max_queued_jobs = 2).await;
    let running = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1_000_000_000u64 })).await;
    server.wait_for_state(running, "running").await;
    let queued = [server.submit(&small_job(1, 1)).await, server.submit(&small_job(1, 2)).await];
    let response = server.post("/v1/jobs", &small_job(1, 3)).await;
    assert_eq!(response.header("retry-after"), Some("30"));
    let problem = assert_problem(response, 429);
    assert!(problem["detail"].as_str().unwrap().contains("2 jobs are already waiting"), "{problem}");
    server.cancel(running).await;
    for id in queued {
        server.wait_for_state(id, "succeeded").await;
    }
    server.submit(&small_job(1, 3)).await; // room again
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_streams_are_limited_with_retry_after() {
    let server = TestServer::start_with(|c| c.http.max_event_streams = 1).await;
    let id = server.submit(&json!({ "engine": "brute", "iterations": 1, "light_paths": 1_000_000_000u64 })).await;
    server.wait_for_state(id, "running").await;
    let first = server.open(&format!("/v1/jobs/{id}/events")).await;
    assert_eq!(first.status(), 200);
    let second = server.get(&format!("/v1/jobs/{id}/events")).await;
    assert_eq!(second.header("retry-after"), Some("5"));
    assert_problem(second, 429);
    drop(first); // the client goes away: its slot frees
    let started = std::time::Instant::now();
    loop {
        let again = server.open(&format!("/v1/jobs/{id}/events")).await;
        if again.status() == 200 {
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "the slot was never freed");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    server.cancel(id).await;
    server.wait_for_state(id, "cancelled").await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_token_guards_every_route_but_health_and_the_dashboard_files() {
    const TOKEN: &str = "correct-horse-battery-staple-42";
    let server = TestServer::start_with(|c| c.token = Some(optimis::api::BearerToken(TOKEN.into()))).await;
    let anonymous = &server.api;
    let wrong = Client::new(&server.base).with_token("correct-horse-battery-staple-43");
    let authorised = Client::new(&server.base).with_token(TOKEN);
    for path in ["/v1/jobs", "/v1/jobs/1", "/metrics", "/openapi.yaml", "/v1/jobs/1/events", "/no/such/route"] {
        let missing = anonymous.get(path).await;
        assert_eq!(missing.header("www-authenticate"), Some("Bearer realm=\"optimis\""));
        assert_problem(missing, 401);
        assert_problem(wrong.get(path).await, 401);
    }
    let wrong_scheme = anonymous.send(anonymous.builder(Method::GET, "/v1/jobs").basic_auth("user", Some(TOKEN))).await;
    assert_problem(wrong_scheme, 401);
    assert_problem(anonymous.post("/v1/jobs", &small_job(1, 1)).await, 401);

    authorised.submit(&small_job(1, 1)).await;
    assert_eq!(authorised.list("").await.len(), 1, "only the authenticated submission was created");
    for path in ["/healthz", "/readyz", "/", "/assets/app.js"] {
        assert_eq!(anonymous.get(path).await.status, 200, "{path} is open");
    }
    server.stop().await;
}
