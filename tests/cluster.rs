//! The Slurm executor (`--executor slurm`) against stand-ins of sbatch, squeue and scancel
//! (`tests/cluster/`: each task runs at once as a local process), so that `cargo test` exercises
//! submission, following, merging, retries and failure without a cluster. The real thing — Slurm
//! itself, kill -9, scancel, sweeps — is `.ci/slurm/server`, on CI's single-node cluster.

use std::path::{Path, PathBuf};
use std::time::Duration;

use optimis::jobs::cluster::{BatchSystemKind, ClusterOptions, SlurmOptions};
use serde_json::{Value, json};

use crate::common::{TestServer, small_job, uninterrupted_moments};

/// The same executor on a second batch system: the stand-in of `jobs::cluster::fake`.
mod fake;

/// A copy of the stand-ins in `dir/bin` (their state beside them) and the executor's options.
fn options(dir: &Path, binary: PathBuf, retries: u32) -> ClusterOptions {
    let bin = dir.join("bin");
    std::fs::create_dir_all(bin.join("state")).unwrap();
    for name in ["sbatch", "squeue", "scancel"] {
        let to = bin.join(name);
        std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cluster").join(name), &to).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&to, std::fs::Permissions::from_mode(0o755)).unwrap();
        }
    }
    let slurm = SlurmOptions {
        bin_dir: Some(bin),
        partition: None,
        account: None,
        time_limit: None,
        sbatch_options: vec!["--qos=test".into()],
        command_timeout: Duration::from_secs(20),
    };
    ClusterOptions {
        system: BatchSystemKind::Slurm(slurm),
        cluster_dir: dir.join("cluster"),
        binary,
        cpus_per_task: 1,
        default_tasks: 1,
        max_tasks: 8,
        retries,
        poll_interval: Duration::from_millis(200),
        missing_grace: Duration::from_secs(30),
        task_checkpoint_seconds: 0.2,
    }
}

async fn start(retries: u32, binary: PathBuf) -> TestServer {
    let dir = tempfile::tempdir().unwrap();
    let slurm = options(dir.path(), binary, retries);
    TestServer::start_in(dir, move |c| c.cluster = Some(slurm)).await
}

fn optimis() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_optimis"))
}

/// Waits for a final state (the executor looks every 200 ms; a task takes well under a second).
async fn settle(server: &TestServer, id: i64) -> Value {
    for _ in 0..600 {
        let job = server.job(id).await;
        if ["succeeded", "failed", "cancelled"].contains(&job["state"].as_str().unwrap()) {
            return job;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("job {id} did not finish: {}", server.job(id).await);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_cut_into_tasks_merges_into_exactly_the_uninterrupted_run() {
    let server = start(1, optimis()).await;
    let mut spec = small_job(30, 5);
    spec["execution"] = json!({ "tasks": 3 });
    let id = server.submit(&spec).await;
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let document = server.moments(id).await;
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(document["moments"], uninterrupted_moments(&plain), "merged tasks = one run, bit for bit");
    assert!(document["spec"].get("execution").is_none(), "documents do not carry the division");
    // The record says one array of 3 tasks; sbatch got argv (no shell), a clean environment, the
    // operator's options and the task command.
    let record: Value = serde_json::from_slice(
        &std::fs::read(server.dir.path().join(format!("cluster/job-{id}/record.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(record["rounds"][0]["tasks"], 3);
    // Extended: the added iterations run as a second array, and the whole is still exact.
    assert_eq!(server.extend(id, &json!({ "iterations": 10 })).await.status, 202);
    assert_eq!(settle(&server, id).await["state"], "succeeded");
    let mut longer = plain.clone();
    longer["iterations"] = json!(40);
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&longer));
    let record: Value = serde_json::from_slice(
        &std::fs::read(server.dir.path().join(format!("cluster/job-{id}/record.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(record["rounds"][1]["first"], 30);
    // Too many tasks for this server: refused at submission, naming the field.
    let mut many = small_job(30, 5);
    many["execution"] = json!({ "tasks": 9 });
    let refused = server.post("/v1/jobs", &many).await;
    assert_eq!(refused.status, 422);
    assert!(refused.text().contains("execution.tasks"), "{}", refused.text());
    // Deleted: its files go too.
    assert_eq!(server.request(reqwest::Method::DELETE, &format!("/v1/jobs/{id}"), None).await.status, 204);
    for _ in 0..100 {
        if !server.dir.path().join(format!("cluster/job-{id}")).exists() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the job's cluster files were not removed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_task_that_cannot_start_fails_the_job_after_its_retries_naming_its_log() {
    let server = start(1, PathBuf::from("/nonexistent/optimis")).await;
    let mut spec = small_job(4, 5);
    spec["execution"] = json!({ "tasks": 2 });
    let id = server.submit(&spec).await;
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "failed", "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(error.contains("after 2 attempts") && error.contains("ended FAILED"), "{error}");
    let log = error.rsplit("its log: ").next().unwrap();
    assert!(log.ends_with(".log") && std::fs::read_to_string(log).unwrap().contains("/nonexistent/optimis"), "{error}");
}

/// Waits until job `id` has a task in `state`.
async fn until_a_task_is(server: &TestServer, id: i64, state: &str) {
    for _ in 0..600 {
        let job = server.job(id).await;
        let tasks = job["execution"]["tasks"].as_array().cloned().unwrap_or_default();
        if tasks.iter().any(|t| t["state"] == state) {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {id} never had a task {state}: {}", server.job(id).await);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restarted_server_adopts_the_running_tasks_and_a_cancel_stops_them() {
    let server = start(1, optimis()).await;
    let mut spec = small_job(2000, 6);
    spec["execution"] = json!({ "tasks": 2 });
    // The tasks are held until the server is down: they run (a few tenths of a second each) while
    // it is, whatever the machine's speed, and a task is surely seen running before the shutdown.
    let hold = server.dir.path().join("bin/state/hold");
    std::fs::write(&hold, "").unwrap();
    let id = server.submit(&spec).await;
    until_a_task_is(&server, id, "running").await;
    // A shutdown leaves the tasks running; the next start finds them and merges what they wrote.
    let dir = server.stop().await;
    std::fs::remove_file(&hold).unwrap();
    let slurm = options(dir.path(), optimis(), 1);
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(slurm)).await;
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&plain));
    let state = server.dir.path().join("bin/state");
    let submitted = std::fs::read_dir(&state)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension() == Some("name".as_ref()))
        .count();
    assert_eq!(submitted, 2, "the restart submitted nothing again");

    // A cancel through the API stops the tasks (scancel) and ends the job cancelled.
    let mut long = small_job(1_000_000, 7);
    long["execution"] = json!({ "tasks": 2 });
    let id = server.submit(&long).await;
    until_a_task_is(&server, id, "running").await;
    assert_eq!(server.cancel(id).await.status, 202);
    assert_eq!(settle(&server, id).await["state"], "cancelled");
    let cancelled = std::fs::read_dir(&state)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension() == Some("cancelled".as_ref()))
        .count();
    assert_eq!(cancelled, 2, "both tasks were stopped");
}

/// Issue 39, item 1: the cluster directory holds nothing that is run (the command goes to Slurm
/// as `--wrap`), and a link planted where a task writes its document is replaced, not followed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nothing_in_the_cluster_directory_is_run_and_a_planted_link_is_not_followed() {
    let server = start(1, optimis()).await;
    let hold = server.dir.path().join("bin/state/hold");
    std::fs::write(&hold, "").unwrap();
    let mut spec = small_job(12, 8);
    spec["execution"] = json!({ "tasks": 2 });
    let id = server.submit(&spec).await;
    until_a_task_is(&server, id, "running").await;
    let cluster = server.dir.path().join("cluster");
    let decoy = server.dir.path().join("decoy");
    std::fs::write(&decoy, "not the server's to write").unwrap();
    std::os::unix::fs::symlink(&decoy, cluster.join(format!("job-{id}/round-0/task-0.json"))).unwrap();
    std::fs::remove_file(&hold).unwrap();
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    assert_eq!(std::fs::read_to_string(&decoy).unwrap(), "not the server's to write");
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&plain));
    // No script in the directory: sbatch got the command itself.
    let names: Vec<String> =
        std::fs::read_dir(&cluster).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(!names.iter().any(|n| n.ends_with(".sh")), "{names:?}");
    let argv = std::fs::read_to_string(server.dir.path().join("bin/state/argv")).unwrap();
    let wrap = argv.lines().find(|l| l.starts_with("--wrap=")).expect("sbatch got --wrap");
    assert!(wrap.starts_with(&format!("--wrap=exec {} cluster-task --cluster-dir ", optimis().display())), "{wrap}");
    // The directory and every folder in it are the server's user's alone.
    use std::os::unix::fs::PermissionsExt;
    for folder in [cluster.clone(), cluster.join(format!("job-{id}")), cluster.join(format!("job-{id}/round-0"))] {
        let mode = std::fs::metadata(&folder).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o700, "{}", folder.display());
    }
}

/// Issue 39, item 8: a finished task's document that is corrupted while the server is down is
/// run again from its shard at the next start, not fatal to the job.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupted_document_of_a_finished_task_is_run_again_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let mut slurm = options(dir.path(), optimis(), 1);
    slurm.missing_grace = Duration::from_millis(500);
    let again = slurm.clone();
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(slurm)).await;
    let hold = server.dir.path().join("bin/state/hold");
    std::fs::write(&hold, "").unwrap();
    let mut spec = small_job(20, 11);
    spec["execution"] = json!({ "tasks": 2 });
    let id = server.submit(&spec).await;
    until_a_task_is(&server, id, "running").await;
    let dir = server.stop().await;
    // The tasks finish while the server is down; then task 0's document is truncated.
    std::fs::remove_file(dir.path().join("bin/state/hold")).unwrap();
    let document = dir.path().join(format!("cluster/job-{id}/round-0/task-0.json"));
    for _ in 0..600 {
        let exits = std::fs::read_dir(dir.path().join("bin/state"))
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().extension() == Some("exit".as_ref()))
            .count();
        if exits == 2 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let bytes = std::fs::read(&document).unwrap();
    std::fs::write(&document, &bytes[..bytes.len() / 2]).unwrap();
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(again)).await;
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&plain));
    // Task 0 ran again (a resubmission of its own), task 1 did not.
    let mut names: Vec<String> = std::fs::read_dir(server.dir.path().join("bin/state"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension() == Some("name".as_ref()))
        .map(|p| std::fs::read_to_string(p).unwrap().trim().rsplit('-').next().unwrap().to_string())
        .collect();
    names.sort();
    assert_eq!(names, ["r0", "r0", "t0"]);
}

/// A tmpfs of `bytes` mounted on `at` (root only), unmounted when dropped.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(at: &Path, bytes: u64) -> Option<Self> {
        std::fs::create_dir_all(at).unwrap();
        let status = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={bytes},mode=0700"), "tmpfs"])
            .arg(at)
            .status()
            .ok()?;
        status.success().then(|| Self(at.to_path_buf()))
    }

    /// Fills it (a file `filler`) until the filesystem is full.
    fn fill(&self) {
        use std::io::Write;
        let mut file = std::fs::File::create(self.0.join("filler")).unwrap();
        while file.write_all(&[0u8; 4096]).is_ok() {}
    }

    fn free(&self) {
        std::fs::remove_file(self.0.join("filler")).unwrap();
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Issue 39, item 9: a full cluster directory makes a job wait — the server for its files, the
/// tasks for their documents — as a local job waits for its database; it then ends exact.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_cluster_directory_makes_the_job_wait_not_fail() {
    let dir = tempfile::tempdir().unwrap();
    let Some(disk) = Tmpfs::mount(&dir.path().join("cluster"), 8 << 20) else {
        assert!(std::env::var_os("OPTIMIS_REQUIRE_MOUNT").is_none(), "cannot mount a tmpfs");
        eprintln!("skipped: cannot mount a tmpfs here (needs root); the task's retries are unit-tested");
        return;
    };
    let slurm = options(dir.path(), optimis(), 1);
    let server = TestServer::start_in(dir, move |c| c.cluster = Some(slurm)).await;
    let hold = server.dir.path().join("bin/state/hold");
    std::fs::write(&hold, "").unwrap();
    // Full before the job: the server cannot write the tasks' specification, and waits.
    disk.fill();
    let mut spec = small_job(20, 12);
    spec["execution"] = json!({ "tasks": 2 });
    let id = server.submit(&spec).await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let job = server.job(id).await;
    assert_eq!(job["state"], "running", "{job}");
    assert!(!server.dir.path().join("bin/state/argv").exists(), "nothing was submitted without its files");
    disk.free();
    until_a_task_is(&server, id, "running").await;
    // Full again while the tasks run: they keep their iterations and wait to write them.
    disk.fill();
    std::fs::remove_file(&hold).unwrap();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let job = server.job(id).await;
    assert_eq!(job["state"], "running", "{job}");
    disk.free();
    let job = settle(&server, id).await;
    assert_eq!(job["state"], "succeeded", "{job}");
    let mut plain = spec.clone();
    plain.as_object_mut().unwrap().remove("execution");
    assert_eq!(server.moments(id).await["moments"], uninterrupted_moments(&plain));
    let submitted = std::fs::read_to_string(server.dir.path().join("bin/state/argv")).unwrap();
    assert_eq!(submitted.lines().filter(|l| l.starts_with("--wrap=")).count(), 1, "one array, no resubmission");
}
