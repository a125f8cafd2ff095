//! Regression tests of the adversarial review (issue 11): no request, document or setting can
//! freeze, exhaust or fool the server. Each test names the item it covers; each failed (hung,
//! answered wrongly, or lost data) before the fix. Hangs are caught by hang guards of a minute —
//! guards against a freeze, not performance limits: every request here answers in milliseconds.

use std::future::Future;
use std::time::Duration;

use crate::common::{TestServer, assert_problem};
use futures_util::StreamExt;
use optimis::sim::document::MomentsDocument;
use optimis::sim::engines::strategies::PathStrategy;
use optimis::sim::math::exact_sum::ExactSum;
use optimis::sim::stats::moments::packed_index;
use reqwest::Method;
use serde_json::{Value, json};

/// Fails the test if `f` does not complete within a minute (a freeze, not a slow machine).
async fn hang_guard<T>(what: &str, f: impl Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(60), f).await.unwrap_or_else(|_| panic!("{what} did not answer (hang)"))
}

/// A small, fast job of the paper's scene on a 6-cell grid (small documents).
fn small(seed: u64) -> Value {
    json!({ "light_paths": 200_000, "camera_paths": 100, "merge_radius": 0.02, "iterations": 40, "seed": seed,
        "cells": { "r2_edges": [0, 0.5], "r3_edges": [0, 0.01, 0.02] } })
}

/// A finished job of `small(seed)` and its moments document.
async fn finished(server: &TestServer, seed: u64) -> (i64, Value) {
    let id = server.submit_and_wait(&small(seed)).await;
    (id, server.moments(id).await)
}

/// `doc` edited as a typed document and re-sealed (anyone can recompute the checksum).
fn forge(doc: &Value, edit: impl FnOnce(&mut MomentsDocument)) -> Value {
    let mut typed: MomentsDocument = serde_json::from_value(doc.clone()).unwrap();
    edit(&mut typed);
    serde_json::from_slice(&typed.sealed().to_json()).unwrap()
}

/// Item 1: finite parts with an infinite sum looped forever on a tokio worker; eight such requests
/// at once stopped every route. Now each is a 4xx and /healthz answers throughout.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn poisoned_documents_are_refused_while_the_server_keeps_answering() {
    let server = TestServer::start().await;
    let (target, doc) = finished(&server, 1).await;
    let mut poisoned = doc.clone();
    poisoned["moments"]["folds"][0]["sum_y"][0] = json!([1.7976931348623157e308, 1.7976931348623157e308]);
    let requests = (0..8).map(|k| {
        let (server, poisoned) = (&server, poisoned.clone());
        async move {
            let response = if k % 2 == 0 {
                server.study(&json!({ "sources": [poisoned] })).await
            } else {
                server.merge(target, &poisoned).await
            };
            (response.status, response.json())
        }
    });
    let health = async {
        for _ in 0..20 {
            assert_eq!(server.get("/healthz").await.status, 200);
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    };
    let (answers, ()) = hang_guard(
        "eight poisoned documents",
        futures_util::future::join(futures_util::future::join_all(requests), health),
    )
    .await;
    for (status, problem) in answers {
        assert_eq!(status, 422, "{problem}");
        assert!(problem["detail"].as_str().unwrap().contains("2^1000"), "{problem}");
    }
    assert!(server.list("").await.len() == 1, "no study was created");
    server.stop().await;
}

/// Item 2: two documents valid alone whose sum overflows: the merge is refused, the target keeps
/// its statistics byte for byte, and the lifecycle is free (extend, delete, submit answer).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn merges_that_would_overflow_change_nothing() {
    let server = TestServer::start().await;
    let (target, _) = finished(&server, 1).await;
    let (_, two) = finished(&server, 2).await;
    let (_, three) = finished(&server, 3).await;
    let huge = |doc: &Value| {
        forge(doc, |d| {
            let n = 2 * d.moments.cells + 1;
            d.moments.folds[0].sum_yy[packed_index(n, 0, 1)] = ExactSum::from_parts(&[1e301]).unwrap();
        })
    };
    let response = hang_guard("a merge", server.merge(target, &huge(&two))).await;
    assert_eq!(response.status, 200, "within bounds, one merge is accepted");
    let before = server.moments(target).await;
    let response = hang_guard("a merge", server.merge(target, &huge(&three))).await;
    let problem = assert_problem(response, 422);
    assert!(problem["detail"].as_str().unwrap().contains("overflow"), "{problem}");
    assert_eq!(server.moments(target).await, before, "nothing changed");
    // The lifecycle is not held: other transitions answer.
    let other = server.submit_and_wait(&small(4)).await;
    let extended = server.extend(other, &json!({ "iterations": 2 })).await;
    assert_eq!(extended.status, 202);
    server.wait_for_state(other, "succeeded").await;
    assert_eq!(server.delete(other).await.status, 204);
    server.stop().await;
}

/// Item 3: submissions inside the validated ranges whose reference quadrature never converged
/// never answered. Now they answer (202 with no reference, or 422) at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extreme_geometries_answer_with_or_without_a_reference() {
    let server = TestServer::start().await;
    for spec in [
        json!({ "scene": { "beta_deg": 1e-9 }, "iterations": 1 }),
        json!({ "scene": { "beta_deg": 1e-300 }, "iterations": 1 }),
        json!({ "scene": { "l2": 1e-6 }, "merge_radius": 1e-7, "iterations": 1 }),
    ] {
        let response = hang_guard("an extreme submission", server.post("/v1/jobs", &spec)).await;
        let (status, body) = (response.status, response.json());
        assert!(status == 202 || status == 422, "{spec}: {status} {body}");
        if status == 202 {
            assert!(body["reference_luminance"].is_null(), "no converged reference for {spec}: {body}");
            let id = body["id"].as_i64().unwrap();
            let done = server.wait_finished(id).await;
            assert_eq!(done["state"], "succeeded", "{done}");
        }
    }
    // A normal scene still has its reference.
    let job = server.post("/v1/jobs", &small(1)).await.json();
    assert!(job["reference_luminance"].as_f64().unwrap() > 2.6e-4);
    server.stop().await;
}

/// Item 4: a job whose iterations never end is refused with the bound stated; one whose
/// iterations take seconds stops within a fraction of one after a cancel, and can be deleted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn huge_iterations_are_refused_and_long_ones_cancel_inside_an_iteration() {
    let server = TestServer::start().await;
    let huge =
        json!({ "scene": { "l2": 1e6, "l3": 1e6 }, "merge_radius": 9e5, "light_paths": 100_000, "iterations": 2 });
    let problem = assert_problem(hang_guard("a huge submission", server.post("/v1/jobs", &huge)).await, 422);
    assert_eq!(problem["field"], "merge_radius", "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("--max-iteration-work") && detail.contains("1.000e10"), "the bound is stated: {detail}");
    // ~5·10⁶ candidates and merges per iteration: seconds each, inside the limit.
    let wide = json!({ "merge_radius": 0.99, "light_paths": 10_000_000, "iterations": 2 });
    let id = server.submit(&wide).await;
    server.wait_for_state(id, "running").await;
    tokio::time::sleep(Duration::from_millis(300)).await; // well inside the first iteration
    assert_eq!(server.cancel(id).await.status, 202);
    let cancelled = hang_guard("the cancel", server.wait_for_state(id, "cancelled")).await;
    assert_eq!(cancelled["progress"]["iterations_checkpointed"], 0, "the partial iteration was dropped");
    assert_eq!(server.delete(id).await.status, 204);
    // The graceful stop (SIGTERM's path) ends too.
    let again = server.submit(&wide).await;
    server.wait_for_state(again, "running").await;
    hang_guard("the shutdown", server.stop()).await;
}

/// Item 5: on a full disk, submissions were acknowledged (202, id 1) without a stored row, and the
/// id was handed out again later. Now a refused write is a 503 with Retry-After, /readyz fails,
/// nothing is acknowledged that was not stored, and a running job whose checkpoints cannot be
/// written waits for the storage and then finishes with every iteration.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_acknowledges_nothing_and_loses_nothing() {
    let server = TestServer::start().await;
    let store = server.store();
    let (first, _) = finished(&server, 1).await;
    // A brute-force job that checkpoints every iteration, then the disk fills.
    let running_spec = json!({ "engine": "brute", "light_paths": 200_000, "camera_paths": 100, "merge_radius": 0.02,
        "iterations": 400, "seed": 5, "cells": { "r2_edges": [0, 0.5], "r3_edges": [0, 0.01, 0.02] } });
    let running = server.submit(&running_spec).await;
    server.wait_until(running, |j| j["progress"]["iterations_checkpointed"].as_u64().unwrap() >= 1).await;
    // Free pages would take writes beyond the limit: compact the file first (from a connection of
    // the test's own; the running job's writes may make it busy for a moment).
    let url = format!("sqlite://{}", server.dir.path().join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    while sqlx::query("VACUUM").execute(&db).await.is_err() {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    db.close().await;
    store.limit_pages(Some(store.page_count().await.unwrap()));

    let mut refused = 0;
    // Submissions until three are refused: the first ones may fit in pages the running job's
    // checkpoint rewrites freed between the VACUUM and the limit — more of them on a loaded
    // machine, where more checkpoints land in between (60 fixed submissions once all fitted).
    // Bounded well below the queue's limit (1,000).
    for seed in 10..600 {
        if refused >= 3 {
            break;
        }
        let response = server.post("/v1/jobs", &small(seed)).await;
        if response.status == 503 {
            assert!(response.headers.contains_key("retry-after"), "{:?}", response.text());
            let problem = assert_problem(response, 503);
            assert!(problem["detail"].as_str().unwrap().contains("nothing was changed"), "{problem}");
            refused += 1;
        } else {
            // A write that still fit (free pages of the file): it must then really be stored.
            assert_eq!(response.status, 202);
            let id = response.json()["id"].as_i64().unwrap();
            assert_eq!(server.get(&format!("/v1/jobs/{id}")).await.status, 200);
        }
    }
    assert!(refused > 0, "the page limit must refuse a write");
    assert_problem(server.get("/readyz").await, 503);
    let checkpointed = server.job(running).await["progress"]["iterations_checkpointed"].clone();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let job = server.job(running).await;
    assert_eq!(job["state"], "running", "a storage failure does not fail the job: {job}");

    // Space comes back: new ids follow the highest one ever handed out, and the job finishes.
    store.limit_pages(None);
    let listed: Vec<i64> = server.list("?limit=500").await.iter().map(|j| j["id"].as_i64().unwrap()).collect();
    let next = server.submit(&small(20)).await;
    assert!(listed.iter().all(|&id| id < next), "id {next} is new (listed {listed:?})");
    let done = server.wait_for_state(running, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], 400);
    assert!(checkpointed.as_u64().unwrap() < 400);
    let document = server.moments(running).await;
    assert_eq!(document["moments"], crate::common::uninterrupted_moments(&running_spec), "every iteration, once");
    assert_eq!(server.get("/readyz").await.status, 200);
    assert_eq!(server.job(first).await["state"], "succeeded");
    server.stop().await;
}

/// Item 7: every odd method string once became a label set of its own, before authentication.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn odd_methods_do_not_grow_the_metrics() {
    let server = TestServer::start().await;
    for i in 0..3000 {
        let method = Method::from_bytes(format!("ODD{i:05}{}", "X".repeat(40)).as_bytes()).unwrap();
        server.request(method, &format!("/v1/jobs/{i}"), None).await;
    }
    let metrics = server.get("/metrics").await.text();
    assert!(metrics.len() < 100_000, "/metrics is {} bytes", metrics.len());
    assert!(metrics.contains(r#"method="other""#), "odd methods share one label");
    server.stop().await;
}

/// Item 8: another site's page could submit, cancel and merge on a loopback server without a
/// token.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cross_site_requests_are_refused() {
    let server = TestServer::start().await;
    let body = serde_json::to_string(&small(1)).unwrap();
    let post = || server.builder(Method::POST, "/v1/jobs");
    let text = server.send(post().header("content-type", "text/plain").body(body.clone())).await;
    assert_problem(text, 415);
    let evil = server.send(post().header("origin", "http://evil.example").json(&small(1))).await;
    assert_problem(evil, 403);
    let rebinding = post().header("host", "evil.example:8080").header("origin", "http://evil.example:8080");
    assert_problem(server.send(rebinding.json(&small(1))).await, 403);
    // A Host that only starts like a loopback address is not one.
    let spoofed = post().header("host", "[::1].evil.example");
    assert_problem(server.send(spoofed.json(&small(1))).await, 403);
    assert!(server.list("").await.is_empty(), "nothing was created");
    // The dashboard's own requests (same origin) and curl's (no origin) pass.
    let own = format!("http://{}", server.base.trim_start_matches("http://"));
    let same = server.send(post().header("origin", own).json(&small(1))).await;
    assert_eq!(same.status, 202);
    let id = server.submit(&small(2)).await;
    let cancel = server.builder(Method::POST, &format!("/v1/jobs/{id}/cancel")).header("origin", "http://evil.example");
    assert_problem(server.send(cancel).await, 403);
    server.stop().await;
}

/// Item 11 (and 14: a counter ≥ 2⁶⁴ could not be posted back): documents are read straight into
/// typed values with bounded lists, so an oversized list stops the parser at once, and the wide
/// counters a server exports read back.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn documents_are_parsed_bounded_and_exactly() {
    let server = TestServer::start().await;
    let (target, doc) = finished(&server, 1).await;
    let mut long = doc.clone();
    long["moments"]["folds"][0]["sum_yy"] = json!(vec![0.5; 200_000]);
    let problem = assert_problem(server.merge(target, &long).await, 422);
    // The bound: the packed upper triangle of the largest grid's moment vector (format 3: w0 and w1
    // per cell of the 256 allowed, the base, one column per stackable heuristic).
    let dimension = 2 * 256 + 1 + PathStrategy::STACKABLE.len();
    let bound = dimension * (dimension + 1) / 2;
    assert!(problem["detail"].as_str().unwrap().contains(&format!("more than {bound} entries")), "{problem}");
    // A u128 counter beyond 2^64 (Σ m² of 2^33 merge events), as the server itself would export it.
    let (_, other) = finished(&server, 2).await;
    let mut typed: MomentsDocument = serde_json::from_value(other).unwrap();
    let cells = typed.moments.cells;
    let fold = &mut typed.moments.folds[0];
    let big = 1u64 << 33;
    fold.cell_counts[2 * cells] += big - fold.merges[2];
    fold.merges[2] = big;
    fold.merges_sq[2] = 1u128 << 65;
    let text = typed.sealed().to_json();
    assert!(String::from_utf8_lossy(&text).contains("36893488147419103232"), "2^65 in the text");
    let response = server.post_raw(&format!("/v1/jobs/{target}/merge"), text).await;
    assert_eq!(response.status, 200, "{}", response.text());
    server.stop().await;
}

/// Item 13 and 14: forged documents that contradict themselves, an empty document (once a 500
/// from a CHECK constraint), studies and merges beyond the job budget or the cell limit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_empty_and_oversized_statistics_are_refused() {
    let server = TestServer::start_with(|c| {
        c.policy.job_budget = 200_000.0 * 100.0 * 60.0;
        c.policy.max_cells = 6;
    })
    .await;
    let (target, doc) = finished(&server, 1).await;
    let negative = forge(&doc, |d| d.moments.folds[1].strategies[0][1] = ExactSum::from_parts(&[-1.0]).unwrap());
    let problem = assert_problem(server.study(&json!({ "sources": [negative] })).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("contradict"), "{problem}");
    let wrapped = forge(&doc, |d| {
        let huge: optimis::sim::stats::coverage::Coverage = serde_json::from_value(json!([
            { "seed": 1, "ranges": [[0u64, 1u64 << 63]] }, { "seed": 2, "ranges": [[0u64, 1u64 << 63]] },
            { "seed": 3, "ranges": [[0u64, 1u64 << 63]] }, { "seed": 4, "ranges": [[0u64, 1u64 << 63]] }]))
        .unwrap();
        d.coverage = huge.clone();
        d.moments.coverage = huge;
    });
    assert_problem(server.merge(target, &wrapped).await, 422);
    let empty = forge(&doc, |d| {
        let spec = d.spec.clone();
        *d = MomentsDocument::new(
            spec.clone(),
            optimis::sim::stats::moments::Moments::new(spec.validate().unwrap().config()),
        );
    });
    let problem = assert_problem(server.study(&json!({ "sources": [empty] })).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("no iterations"), "{problem}");
    // 40 + 40 iterations of 2·10⁷ pairs exceed a budget of 60 iterations' worth.
    let (_, second) = finished(&server, 2).await;
    let problem = assert_problem(server.study(&json!({ "sources": [doc.clone(), second.clone()] })).await, 422);
    assert_eq!(problem["field"], "iterations", "{problem}");
    let problem = assert_problem(server.merge(target, &second).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("--max-job-budget"), "{problem}");
    server.stop().await;
}

/// Item 14: a merged job's spec says how many iterations it holds, and its document verifies
/// and merges elsewhere.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_merged_job_describes_what_it_holds() {
    let server = TestServer::start().await;
    let (target, _) = finished(&server, 1).await;
    let (_, other) = finished(&server, 2).await;
    assert_eq!(server.merge(target, &other).await.status, 200);
    let job = server.job(target).await;
    assert_eq!(job["spec"]["iterations"], 80, "{job}");
    assert_eq!(job["progress"]["iterations_done"], 80);
    let document = server.moments(target).await;
    assert_eq!(document["spec"]["iterations"], 80);
    let study = server.study(&json!({ "sources": [document] })).await;
    assert_eq!(study.status, 201);
    server.stop().await;
}

/// Item 14: extending a cancelled job counted from its original total; now from what it holds,
/// or to an explicit target.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extending_a_cancelled_job_counts_from_what_it_holds() {
    let server = TestServer::start().await;
    let spec = json!({ "engine": "brute", "light_paths": 200_000, "camera_paths": 100, "merge_radius": 0.02, "iterations": 100_000 });
    let id = server.submit(&spec).await;
    server.wait_until(id, |j| j["progress"]["iterations_checkpointed"].as_u64().unwrap() >= 5).await;
    server.cancel(id).await;
    let cancelled = server.wait_for_state(id, "cancelled").await;
    let held = cancelled["progress"]["iterations_done"].as_u64().unwrap();
    assert!(held + 3 < 100_000);
    // Issue 42: `total` resumes a cancelled job to a target below the one it had (it was refused:
    // "must exceed the iterations the job holds (100000)").
    let resumed = server.extend(id, &json!({ "total": held + 3 })).await.json();
    assert_eq!(resumed["progress"]["iterations_total"], held + 3, "{resumed}");
    let done = server.wait_for_state(id, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], held + 3);
    let extended = server.extend(id, &json!({ "iterations": 2 })).await.json();
    assert_eq!(extended["progress"]["iterations_total"], held + 5, "{extended}");
    let done = server.wait_for_state(id, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], held + 5);
    let problem = assert_problem(server.extend(id, &json!({ "total": 2 })).await, 422);
    assert_eq!(problem["field"], "total");
    server.stop().await;
}

/// Item 14: a subnormal ring flux passed `flux > 0` and made the reference NaN.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vanishing_ring_flux_is_refused() {
    let server = TestServer::start().await;
    let spec = json!({ "scene": { "illumination": { "kind": "rings", "rings": [{ "outer_radius": 1.0, "level": 1e-320 }] } } });
    let problem = assert_problem(server.post("/v1/jobs", &spec).await, 422);
    assert_eq!(problem["field"], "scene.illumination", "{problem}");
    server.stop().await;
}

/// Item 14: /events sent ~125 events a second; now at most one per 250 ms. A finished job's
/// one-event stream does not take a stream slot.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_streams_are_paced_and_finished_jobs_take_no_slot() {
    let server = TestServer::start_with(|c| {
        c.http.max_event_streams = 1;
        c.policy.checkpoint_iterations = 1;
    })
    .await;
    let (done, _) = finished(&server, 1).await;
    // Thousands of changes a second: a restricted job checkpointing every batch.
    let id = server.submit(&json!({ "iterations": 400_000, "seed": 2 })).await;
    server.wait_for_state(id, "running").await;
    let started = std::time::Instant::now();
    let mut stream = server.open(&format!("/v1/jobs/{id}/events")).await.bytes_stream();
    let mut events = 0;
    let mut text = String::new();
    while started.elapsed() < Duration::from_secs(2) {
        let Ok(Some(chunk)) = tokio::time::timeout(Duration::from_millis(500), stream.next()).await else { continue };
        text.push_str(&String::from_utf8_lossy(&chunk.unwrap()));
        events = text.matches("event: job").count();
    }
    let elapsed = started.elapsed().as_secs_f64();
    assert!(events >= 2, "the stream follows the job ({events} events)");
    assert!(events as f64 <= elapsed / 0.25 + 2.0, "{events} events in {elapsed:.2} s");
    // The one slot is taken by the live stream; a finished job still answers (204: nothing to stream).
    let finished_stream = server.get(&format!("/v1/jobs/{done}/events")).await;
    assert_eq!(finished_stream.status, 204);
    drop(stream);
    server.cancel(id).await;
    server.wait_for_state(id, "cancelled").await;
    server.stop().await;
}

/// Item 12: a job checkpointed at every iteration kept one history row per checkpoint, all loaded
/// by every history request. Rows beyond the bound are thinned when the next checkpoint lands (and
/// by the migration for databases written before the bound).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn histories_stay_bounded() {
    let server = TestServer::start().await;
    let id = server
        .submit(&json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 50, "merge_radius": 0.02,
        "iterations": 3, "cells": { "r2_edges": [0, 0.5], "r3_edges": [0, 0.01] } }))
        .await;
    server.wait_for_state(id, "succeeded").await;
    let dir = server.stop().await;
    let url = format!("sqlite://{}", dir.path().join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let strategies: String = sqlx::query_scalar(
        "SELECT strategies FROM checkpoint_history WHERE job_id = ? ORDER BY iterations DESC LIMIT 1",
    )
    .bind(id)
    .fetch_one(&db)
    .await
    .unwrap();
    for k in 100..20_100i64 {
        sqlx::query("INSERT INTO checkpoint_history (job_id, iterations, strategies, written_at) VALUES (?, ?, ?, 0)")
            .bind(id)
            .bind(k)
            .bind(&strategies)
            .execute(&db)
            .await
            .unwrap();
    }
    db.close().await;
    let server = TestServer::start_in(dir, |_| {}).await;
    let url = format!("sqlite://{}", server.dir.path().join("optimis.db").display());
    // Issue 22, item 11: the read path thins as it reads (20,000 injected rows, 1,000 read).
    let history = server.history(id).await;
    let points = history["points"].as_array().unwrap();
    assert_eq!(points.len(), 1000);
    assert_eq!(points.last().unwrap()["iterations"], 20_099, "the latest point is kept");
    // One more checkpoint thins the job's history.
    assert_eq!(server.extend(id, &json!({ "iterations": 1 })).await.status, 202);
    server.wait_for_state(id, "succeeded").await;
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let rows: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM checkpoint_history WHERE job_id = ?")
        .bind(id)
        .fetch_one(&db)
        .await
        .unwrap();
    db.close().await;
    assert!(rows <= 2000, "{rows} history rows kept");
    let history = server.history(id).await;
    assert!(history["points"].as_array().unwrap().len() <= 1000);
    server.stop().await;
}

/// Changes one digit of a job's stored moments (inside `sum_yy`, past its first entries) directly
/// in the database under `dir`, so that the checkpoint no longer matches its checksum.
async fn corrupt_checkpoint(dir: &std::path::Path, id: i64) {
    let url = format!("sqlite://{}", dir.join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let mut moments: Vec<u8> =
        sqlx::query_scalar("SELECT moments FROM checkpoints WHERE job_id = ?").bind(id).fetch_one(&db).await.unwrap();
    let at = moments.windows(9).position(|w| w == b"\"sum_yy\":").unwrap() + 40;
    let pos = at + moments[at..].iter().position(|b| (b'1'..=b'8').contains(b)).unwrap();
    moments[pos] += 1;
    sqlx::query("UPDATE checkpoints SET moments = ? WHERE job_id = ?")
        .bind(&moments)
        .bind(id)
        .execute(&db)
        .await
        .unwrap();
    db.close().await;
}

/// Item 14: a corrupted checkpoint still served its stored result, and `extend` turned the
/// succeeded job into a failed one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupted_checkpoint_is_reported_not_served() {
    let server = TestServer::start().await;
    let (id, _) = finished(&server, 1).await;
    let dir = server.stop().await;
    corrupt_checkpoint(dir.path(), id).await;
    let server = TestServer::start_in(dir, |_| {}).await;
    let problem = assert_problem(server.get(&format!("/v1/jobs/{id}/result")).await, 409);
    assert!(problem["detail"].as_str().unwrap().contains("checksum"), "{problem}");
    assert_problem(server.extend(id, &json!({ "iterations": 2 })).await, 409);
    assert_eq!(server.job(id).await["state"], "succeeded", "the job is unchanged");
    server.stop().await;
}

/// Issue 22, item 6: a checkpoint corrupted under a running server, after its result was served
/// (and its moments verified), is reported by the next result read once the verification has
/// aged (`REVERIFY_AFTER`, 1 s) — not served unflagged for as long as the server runs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_checkpoint_corrupted_under_a_running_server_is_reported() {
    let server = TestServer::start().await;
    let (id, _) = finished(&server, 2).await;
    assert_eq!(server.get(&format!("/v1/jobs/{id}/result")).await.status, 200);
    corrupt_checkpoint(server.dir.path(), id).await;
    // Past the verification's age (an ordering, not a limit on how fast the server is).
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let problem = assert_problem(server.get(&format!("/v1/jobs/{id}/result")).await, 409);
    assert!(problem["detail"].as_str().unwrap().contains("checksum"), "{problem}");
    server.stop().await;
}

/// Sets job `id`'s stored result (the `result` column only) in the database under `dir`.
async fn set_stored_result(dir: &std::path::Path, id: i64, edit: impl FnOnce(String) -> String) {
    let url = format!("sqlite://{}", dir.join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let result: String =
        sqlx::query_scalar("SELECT result FROM checkpoints WHERE job_id = ?").bind(id).fetch_one(&db).await.unwrap();
    sqlx::query("UPDATE checkpoints SET result = ? WHERE job_id = ?")
        .bind(edit(result))
        .bind(id)
        .execute(&db)
        .await
        .unwrap();
    db.close().await;
}

/// Issue 39, item 12: the stored result was outside every checksum — an edited one was served
/// (200), a garbled one answered 500. Both are now reported corrupted (409), as corrupted moments
/// are.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_edited_or_garbled_stored_result_is_reported_not_served() {
    let server = TestServer::start().await;
    let (edited, _) = finished(&server, 3).await;
    let (garbled, _) = finished(&server, 4).await;
    let dir = server.stop().await;
    // A valid document with one figure changed, and text that is not JSON.
    set_stored_result(dir.path(), edited, |r| r.replacen("\"rms_percent\":", "\"rms_percent\":1", 1)).await;
    set_stored_result(dir.path(), garbled, |_| "{ not json".to_string()).await;
    let server = TestServer::start_in(dir, |_| {}).await;
    for id in [edited, garbled] {
        let problem = assert_problem(server.get(&format!("/v1/jobs/{id}/result")).await, 409);
        assert!(problem["detail"].as_str().unwrap().contains("result checksum mismatch"), "{problem}");
    }
    // A row written before results had a checksum gets one at the next start, and is served.
    let (old, _) = finished(&server, 5).await;
    let dir = server.stop().await;
    let url = format!("sqlite://{}", dir.path().join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    sqlx::query("UPDATE checkpoints SET result_checksum = NULL WHERE job_id = ?").bind(old).execute(&db).await.unwrap();
    db.close().await;
    let server = TestServer::start_in(dir, |_| {}).await;
    assert_eq!(server.get(&format!("/v1/jobs/{old}/result")).await.status, 200);
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let filled: Option<String> = sqlx::query_scalar("SELECT result_checksum FROM checkpoints WHERE job_id = ?")
        .bind(old)
        .fetch_one(&db)
        .await
        .unwrap();
    assert_eq!(filled.map(|c| c.len()), Some(64));
    db.close().await;
    server.stop().await;
}
