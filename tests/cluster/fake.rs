//! A second batch system through the cluster executor: the stand-in of `jobs::cluster::fake`
//! (tasks as child processes of the test), one file and one arm of `BatchSystemKind`. The rounds,
//! the retries, the adoption after a restart and the exact merges it goes through are the
//! executor's, the same as Slurm's.

use std::collections::BTreeSet;
use std::path::Path;
use std::time::Duration;

use optimis::jobs::cluster::fake::{FakeCluster, FakeOptions};
use optimis::jobs::cluster::{BatchSystemKind, ClusterOptions};
use serde_json::{Value, json};

use super::{optimis, settle};
use crate::common::{TestServer, small_job, uninterrupted_moments};

fn options(dir: &Path, fake: FakeOptions) -> ClusterOptions {
    ClusterOptions {
        system: BatchSystemKind::Fake(fake),
        cluster_dir: dir.join("cluster"),
        binary: optimis(),
        cpus_per_task: 1,
        default_tasks: 1,
        max_tasks: 8,
        retries: 1,
        poll_interval: Duration::from_millis(200),
        missing_grace: Duration::from_secs(30),
        task_checkpoint_seconds: 0.2,
    }
}

/// Waits until the job resource shows what `ready` looks for in its tasks; returns them.
async fn until_tasks(server: &TestServer, id: i64, ready: impl Fn(&[Value]) -> bool) -> Vec<Value> {
    for _ in 0..600 {
        let job = server.job(id).await;
        let tasks = job["execution"]["tasks"].as_array().cloned().unwrap_or_default();
        if ready(&tasks) {
            return tasks;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {id}'s tasks never were as expected: {}", server.job(id).await);
}

fn record(dir: &Path, id: i64) -> (std::path::PathBuf, Value) {
    let path = dir.join(format!("cluster/job-{id}/record.json"));
    let value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    (path, value)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_batch_system_runs_a_job_through_rounds_retries_and_adoption() {
    // Task 1 of every array fails its first attempt; the tasks are held until the server is gone.
    let fake = FakeOptions { fail_first: BTreeSet::from([1]), cluster: FakeCluster::default() };
    let cluster = fake.cluster.clone();
    cluster.hold(true);
    let dir = tempfile::tempdir().unwrap();
    let first = options(dir.path(), fake.clone());
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(first)).await;
    let mut spec = small_job(30, 21);
    spec["execution"] = json!({ "tasks": 3 });
    let id = server.submit(&spec).await;

    // Retries: task 1 failed, and was resubmitted alone (its own id, a second attempt).
    let tasks = until_tasks(&server, id, |tasks| {
        tasks.len() == 3 && tasks.iter().all(|t| t["batch_job_id"].is_string()) && tasks[1]["attempts"] == 2
    })
    .await;
    let array = tasks[0]["batch_job_id"].as_str().unwrap().split('.').next().unwrap().to_string();
    let ids: Vec<&str> = tasks.iter().map(|t| t["batch_job_id"].as_str().unwrap()).collect();
    assert_eq!(ids[0], format!("{array}.0"), "the system's own ids, through the seam: {tasks:?}");
    assert_eq!(ids[2], format!("{array}.2"));
    assert!(!ids[1].starts_with(&format!("{array}.")), "task 1 runs as a submission of its own: {tasks:?}");
    assert!(tasks.iter().all(|t| t.get("slurm_job_id").is_none()), "the old name is gone: {tasks:?}");
    assert_eq!(server.job(id).await["execution"]["executor"], "fake");

    // The server is lost while its tasks wait; as if it died between the system's answer and its
    // record, the record lacks the array's id. The tasks run while no server follows them.
    let dir = server.stop().await;
    let (path, mut written) = record(dir.path(), id);
    assert_eq!(written["rounds"][0]["array"], json!(array));
    written["rounds"][0]["array"] = Value::Null;
    std::fs::write(&path, serde_json::to_vec(&written).unwrap()).unwrap();
    cluster.hold(false);

    // Adoption: a new server (a new executor) finds the array by its name and the resubmission
    // by its id, merges what they wrote, and submits nothing again.
    let again = options(dir.path(), fake.clone());
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(again)).await;
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&plain), "bit for bit a local run");
    let names = |cluster: &FakeCluster| -> Vec<String> {
        cluster.submitted().iter().map(|n| n.rsplit_once(&format!("-{id}-")).unwrap().1.to_string()).collect()
    };
    assert_eq!(names(&cluster), ["r0", "r0-t1"], "the restart submitted nothing again");
    let (_, adopted) = record(server.dir.path(), id);
    assert_eq!(adopted["rounds"][0]["array"], json!(array), "the array adopted by its name");
    assert_eq!(adopted["rounds"][0]["resubmits"]["1"], json!([ids[1]]));

    // Rounds: an extension is an array of its own (its task 1 failing once again), merged exactly.
    assert_eq!(server.extend(id, &json!({ "iterations": 12 })).await.status, 202);
    assert_eq!(settle(&server, id).await["state"], "succeeded");
    let mut longer = plain.clone();
    longer["iterations"] = json!(42);
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&longer));
    assert_eq!(names(&cluster), ["r0", "r0-t1", "r1", "r1-t1"]);
    let (_, extended) = record(server.dir.path(), id);
    assert_eq!(extended["rounds"][1]["first"], 30);
}
