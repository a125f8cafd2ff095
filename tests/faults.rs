//! Faults: a corrupted checkpoint fails only its job; a failed solve still reports the fixed
//! strategies; and twenty SIGKILLs at random moments (many during checkpoint writes) never lose or
//! corrupt work.

use crate::common::process::Process;
use crate::common::{TestServer, assert_problem, small_job};
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupted_checkpoint_fails_only_its_job() {
    let server = TestServer::start().await;
    let finished = server.submit_and_wait(&small_job(4, 1)).await;
    let finished_result = server.result(finished).await;
    let victim = server.submit(&json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 400, "seed": 2 })).await;
    server.wait_until(victim, |j| j["progress"]["iterations_checkpointed"].as_u64().unwrap() >= 5).await;
    let dir = server.stop().await; // the victim checkpoints and waits, queued

    // Change one digit of the victim's stored moments (its checksum no longer matches).
    let url = format!("sqlite://{}", dir.path().join("optimis.db").display());
    let db = sqlx::SqlitePool::connect(&url).await.unwrap();
    let mut moments: Vec<u8> = sqlx::query_scalar("SELECT moments FROM checkpoints WHERE job_id = ?")
        .bind(victim)
        .fetch_one(&db)
        .await
        .unwrap();
    let at = moments.windows(9).position(|w| w == b"\"sum_yy\":").unwrap() + 40;
    let pos = at + moments[at..].iter().position(|b| (b'1'..=b'8').contains(b)).unwrap();
    moments[pos] += 1;
    sqlx::query("UPDATE checkpoints SET moments = ? WHERE job_id = ?")
        .bind(&moments)
        .bind(victim)
        .execute(&db)
        .await
        .unwrap();
    db.close().await;

    let server = TestServer::start_in(dir, |_| {}).await;
    let failed = server.wait_for_state(victim, "failed").await;
    let error = failed["error"].as_str().unwrap();
    assert!(error.contains("checksum mismatch"), "a clear error: {error}");
    // The other jobs are untouched and the server keeps working.
    assert_eq!(server.result(finished).await, finished_result);
    server.submit_and_wait(&small_job(3, 9)).await;
    let problem = assert_problem(server.get(&format!("/v1/jobs/{victim}/moments")).await, 409);
    assert!(problem["detail"].as_str().unwrap().contains("checksum"), "{problem}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_solve_still_reports_the_fixed_strategies() {
    let server = TestServer::start().await;
    // Both w0 and w1 free in 52 cells, λ = 0 (also the only λ of the grid) and 10 iterations:
    // more unknowns than iterations, so neither the in-sample fit nor any cross-fit exists.
    let id = server
        .submit(&json!({ "engine": "brute", "light_paths": 1_000_000, "camera_paths": 1000, "merge_radius": 0.02, "iterations": 10,
            "solver": { "fixed": { "w0": null }, "cv_lambdas": [0] } }))
        .await;
    server.wait_for_state(id, "succeeded").await;
    let result = server.result(id).await;
    let reason = result["solve_error"].as_str().expect("the reason is reported");
    assert!(reason.contains("singular"), "{reason}");
    assert!(result["weights"].as_array().unwrap().is_empty());
    let rows = result["noise_table"].as_array().unwrap();
    for name in ["plane1", "plane2", "plane3", "switch", "balance", "power", "correlation_aware"] {
        let row = rows.iter().find(|r| r["strategy"] == name).unwrap();
        assert!(row["luminance"].as_f64().is_some() && row["rms_percent"].as_f64().is_some(), "{row}");
    }
    let optimal = rows.iter().find(|r| r["strategy"] == "optimal").unwrap();
    assert!(optimal["luminance"].is_null() && optimal["error"].as_str().unwrap().contains("singular"), "{optimal}");
    server.stop().await;
}

/// Deterministic pseudo-random numbers in `lo..=hi` (a fixed LCG, so the test is reproducible).
fn draws(count: usize, seed: u64, lo: u64, hi: u64) -> Vec<u64> {
    let mut state = seed;
    (0..count)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            lo + (state >> 33) % (hi - lo + 1)
        })
        .collect()
}

/// Twenty SIGKILLs while a job runs, with a checkpoint after every iteration so that many kills
/// land inside a checkpoint write. The kills are driven by progress, not by the clock: each
/// server lives until it has stored 1 to 3 new checkpoints (plus a jitter of 0–5 ms), so the job
/// cannot finish before the twentieth kill on any machine (20 lives of at most a few iterations
/// each, of 300). The job always finishes, with moments equal to an uninterrupted run's; a
/// finished job's data never changes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn twenty_kills_never_lose_or_corrupt_work() {
    let dir = tempfile::tempdir().unwrap();
    let database = format!("sqlite://{}", dir.path().join("faults.db").display());
    let flags = ["--checkpoint-iterations", "1", "--checkpoint-seconds", "0.05"];
    let server = Process::start_with(&database, &flags);
    let bystander = server.submit_and_wait(&small_job(6, 3)).await;
    let snapshot = |process: &Process| {
        let api = process.api.clone();
        async move { (api.job(bystander).await, api.result(bystander).await, api.moments(bystander).await) }
    };
    let before = snapshot(&server).await;

    // A 128-cell grid makes every checkpoint a few hundred kilobytes: writes take a real share
    // of the time, so kills land in them.
    let r3_edges: Vec<f64> = (0..=63).map(|i| f64::from(i) / 1000.0).collect();
    let spec = json!({ "engine": "brute", "light_paths": 1_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 300, "seed": 31,
        "cells": { "r3_edges": r3_edges } });
    let id = server.submit(&spec).await;
    let mut server = Some(server);
    let mut progress = Vec::new();
    let mut stored = 0;
    let steps = draws(20, 7, 1, 3);
    let jitters = draws(20, 11, 0, 5);
    for (step, jitter) in steps.into_iter().zip(jitters) {
        let process = server.take().unwrap_or_else(|| Process::start_with(&database, &flags));
        let job = process
            .wait_until(id, |j| j["progress"]["iterations_checkpointed"].as_u64().unwrap() >= stored + step)
            .await;
        tokio::time::sleep(std::time::Duration::from_millis(jitter)).await;
        stored = job["progress"]["iterations_checkpointed"].as_u64().unwrap();
        progress.push(stored);
        process.kill();
    }
    assert!(progress.windows(2).all(|w| w[0] < w[1]), "every life stored new work, none was lost: {progress:?}");
    assert!(*progress.last().unwrap() < 300, "the kills interrupted a running job: {progress:?}");

    let last = Process::start_with(&database, &flags);
    let done = last.wait_for_state(id, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], 300);
    let document = last.moments(id).await;
    assert_eq!(
        document["moments"],
        crate::common::uninterrupted_moments(&spec),
        "moments equal an uninterrupted run's"
    );
    let history = last.history(id).await;
    assert!(history["points"].as_array().unwrap().len() >= 20);
    assert_eq!(snapshot(&last).await, before, "the finished job's data did not change");
    last.kill();
}
