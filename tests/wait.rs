//! Waiting for a job or a sweep to end (issue 25, item 1): the `?wait=` long-poll of
//! `GET /v1/jobs/{id}` and `GET /v1/sweeps/{id}`, and `optimis wait URL`, which the README's wait
//! steps use — exit status 0 once the resource succeeded, 1 when it failed or was cancelled, 3
//! when the server refuses, 5 at once when no server answers (a loop that cannot spin for ever or
//! report success for a job that did not succeed).

use std::process::{Command, Stdio};
use std::time::Duration;

use crate::common::process::free_port;
use crate::common::{TestServer, assert_problem, small_job};
use serde_json::json;

fn optimis_wait(url: &str) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_optimis"))
        .args(["wait", url])
        .env_remove("OPTIMIS_TOKEN")
        .output()
        .expect("optimis runs")
}

/// A brute-force job that runs for minutes unless cancelled.
fn long_job() -> serde_json::Value {
    json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 100, "merge_radius": 0.02,
            "iterations": 100_000, "seed": 9 })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_long_poll_answers_when_the_job_or_the_sweep_ends() {
    let server = TestServer::start().await;
    let id = server.submit(&small_job(300, 1)).await;
    // One request, answered once the job has ended (the hang guard of the client bounds it).
    let job = server.get_json(&format!("/v1/jobs/{id}?wait=60")).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    assert_eq!(job["progress"]["iterations_done"], 300);
    // An ended job answers at once; out-of-range or odd values are named.
    assert_eq!(server.get(&format!("/v1/jobs/{id}?wait=5")).await.json()["state"], "succeeded");
    for bad in ["61", "-1", "soon"] {
        let problem = assert_problem(server.get(&format!("/v1/jobs/{id}?wait={bad}")).await, 422);
        assert!(problem.to_string().contains("wait"), "{bad}: {problem}");
    }
    assert_problem(server.get("/v1/jobs/999?wait=1").await, 404);

    // A running job: the poll answers after its seconds with the job still running.
    let running = server.submit(&long_job()).await;
    server.wait_for_state(running, "running").await;
    assert_eq!(server.get_json(&format!("/v1/jobs/{running}?wait=1")).await["state"], "running");
    assert_eq!(server.cancel(running).await.status, 202);
    assert_eq!(server.get_json(&format!("/v1/jobs/{running}?wait=60")).await["state"], "cancelled");

    // A sweep: answered when every run has ended, never on the first point's state.
    let created = server
        .post(
            "/v1/sweeps",
            &json!({ "base": { "iterations": 200, "light_paths": 1_000_000, "seed": 3 },
                     "axes": [{ "field": "merge_radius", "values": [0.003, 0.01, 0.02] }] }),
        )
        .await;
    assert_eq!(created.status, 201);
    let sweep_id = created.json()["id"].as_i64().unwrap();
    let sweep = server.get_json(&format!("/v1/sweeps/{sweep_id}?wait=60")).await;
    assert_eq!(sweep["state"], "succeeded", "{sweep}");
    assert!(sweep["points"].as_array().unwrap().iter().all(|p| p["state"] == "succeeded"), "{sweep}");
    assert_problem(server.get(&format!("/v1/sweeps/{sweep_id}?wait=61")).await, 422);
    assert_problem(server.get("/v1/sweeps/999?wait=1").await, 404);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn optimis_wait_succeeds_fails_and_gives_up_as_it_says() {
    let server = TestServer::start().await;
    let base = server.base.trim_start_matches("http://").to_string();

    // Follows a job to its end: exit 0 and the final line.
    let id = server.submit(&small_job(300, 2)).await;
    let url = format!("{base}/v1/jobs/{id}");
    let out = tokio::task::spawn_blocking(move || optimis_wait(&url)).await.unwrap();
    assert!(out.status.success(), "{out:?}");
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), format!("job {id}: succeeded, 300 of 300 iterations"));

    // A cancelled job: exit 1, saying so.
    let cancelled = server.submit(&long_job()).await;
    server.wait_for_state(cancelled, "running").await;
    assert_eq!(server.cancel(cancelled).await.status, 202);
    let url = format!("{base}/v1/jobs/{cancelled}");
    let out = tokio::task::spawn_blocking(move || optimis_wait(&url)).await.unwrap();
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("cancelled"), "{out:?}");

    // No such job: exit 3 with the server's detail.
    let url = format!("{}/v1/jobs/999", server.base);
    let out = tokio::task::spawn_blocking(move || optimis_wait(&url)).await.unwrap();
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("404"), "{out:?}");

    // The server stops while a job runs: the wait ends with exit 5, not a loop.
    let running = server.submit(&long_job()).await;
    server.wait_for_state(running, "running").await;
    let mut child = Command::new(env!("CARGO_BIN_EXE_optimis"))
        .args(["wait", &format!("{base}/v1/jobs/{running}")])
        .env_remove("OPTIMIS_TOKEN")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await; // it is long-polling now
    server.stop().await;
    let out = tokio::task::spawn_blocking(move || {
        // Bounded by the test's hang guard, not a timing claim: it must end at all.
        for _ in 0..1200 {
            if child.try_wait().unwrap().is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = child.kill();
        child.wait_with_output().unwrap()
    })
    .await
    .unwrap();
    assert_eq!(out.status.code(), Some(5), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not answer"), "{out:?}");
    // Issue 42: and says that the job is not lost.
    assert!(String::from_utf8_lossy(&out.stderr).contains("resumes them from their last checkpoint"), "{out:?}");

    // Nothing listens: exit 5 at once.
    let url = format!("127.0.0.1:{}/v1/jobs/1", free_port());
    let out = tokio::task::spawn_blocking(move || optimis_wait(&url)).await.unwrap();
    assert_eq!(out.status.code(), Some(5), "{out:?}");
}
