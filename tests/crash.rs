//! Crash safety of the real `optimis serve` binary: SIGKILL while a job runs, restart on the same
//! database, and the job ends with moments bit-identical to an uninterrupted run, while finished
//! jobs and their results are untouched.

use crate::common::process::Process;

use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_server_resumes_jobs_bit_identically() {
    let dir = tempfile::tempdir().unwrap();
    let database = format!("sqlite://{}", dir.path().join("crash.db").display());

    let first = Process::start(&database);
    // A job that finishes before the crash.
    let finished_spec = json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 200, "merge_radius": 0.02, "iterations": 8, "seed": 3 });
    let finished = first.submit_and_wait(&finished_spec).await;
    let finished_before = first.job(finished).await;
    let result_before = first.result(finished).await;
    let moments_before = first.moments(finished).await;

    // The job that is killed: about 40 iterations of 2·10⁶ light paths.
    let spec = json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 40, "seed": 17 });
    let id = first.submit(&spec).await;
    let before_kill = first
        .wait_until(id, |j| j["state"] == "running" && j["progress"]["iterations_checkpointed"].as_u64().unwrap() >= 6)
        .await;
    let checkpointed = before_kill["progress"]["iterations_checkpointed"].as_u64().unwrap();
    first.kill();

    let second = Process::start(&database);
    let resumed = second.job(id).await;
    assert!(
        resumed["progress"]["iterations_checkpointed"].as_u64().unwrap() >= checkpointed,
        "the job resumes from its checkpoint, not from zero: {resumed}"
    );
    let done = second.wait_for_state(id, "succeeded").await;
    assert_eq!(done["progress"]["iterations_done"], 40);
    let document = second.moments(id).await;

    assert_eq!(
        document["moments"],
        crate::common::uninterrupted_moments(&spec),
        "moments differ from an uninterrupted run"
    );

    // The finished job is untouched.
    assert_eq!(second.job(finished).await, finished_before);
    assert_eq!(second.result(finished).await, result_before);
    assert_eq!(second.moments(finished).await, moments_before);
    second.kill();
}

/// SIGTERM checkpoints the running job before exiting: with periodic checkpoints made rare, the
/// iterations computed since the last one are saved anyway, and the job resumes from there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_checkpoints_running_jobs_before_exiting() {
    let dir = tempfile::tempdir().unwrap();
    let database = format!("sqlite://{}", dir.path().join("term.db").display());
    let first = Process::start_with(&database, &["--checkpoint-iterations", "1000000", "--checkpoint-seconds", "3600"]);
    let spec = json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 400, "seed": 5 });
    let id = first.submit(&spec).await;
    let running = first.wait_until(id, |j| j["progress"]["iterations_done"].as_u64().unwrap() >= 5).await;
    assert_eq!(running["progress"]["iterations_checkpointed"], 0, "no periodic checkpoint yet");
    let status = first.terminate();
    assert!(status.success(), "a clean exit on SIGTERM: {status}");

    let second =
        Process::start_with(&database, &["--checkpoint-iterations", "1000000", "--checkpoint-seconds", "3600"]);
    let resumed = second.job(id).await;
    assert!(
        resumed["progress"]["iterations_checkpointed"].as_u64().unwrap() >= 5,
        "the shutdown checkpoint kept the work: {resumed}"
    );
    assert!(matches!(resumed["state"].as_str(), Some("queued" | "running")), "{resumed}");
    second.kill();
}

/// Issue 11, item 10: a cancel followed by SIGTERM (or SIGKILL) ran the job again after the
/// restart — the shutdown overwrote the cancel, which lived only in memory. The cancel is stored
/// when it is acknowledged, and wins over a shutdown.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancel_survives_a_shutdown_and_a_kill() {
    let spec = json!({ "engine": "brute", "light_paths": 2_000_000, "camera_paths": 300, "merge_radius": 0.01, "iterations": 100_000, "seed": 5 });
    for stop in ["term", "kill"] {
        let dir = tempfile::tempdir().unwrap();
        let database = format!("sqlite://{}", dir.path().join("cancel.db").display());
        let first = Process::start(&database);
        let id = first.submit(&spec).await;
        first.wait_until(id, |j| j["progress"]["iterations_done"].as_u64().unwrap() >= 2).await;
        assert_eq!(first.cancel(id).await.status, 202);
        if stop == "term" {
            assert!(first.terminate().success());
        } else {
            first.kill();
        }
        let second = Process::start(&database);
        let job = second.job(id).await;
        assert_eq!(job["state"], "cancelled", "after SIG{}: {job}", stop.to_uppercase());
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        let later = second.job(id).await;
        assert_eq!(later["progress"]["iterations_done"], job["progress"]["iterations_done"], "it does not run again");
        second.kill();
    }
}
