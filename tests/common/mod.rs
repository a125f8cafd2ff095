//! Test helpers: a real server on 127.0.0.1 (port 0) with a SQLite file in a temporary directory,
//! and a small JSON client.
#![allow(dead_code)] // each test binary uses a different subset

pub mod process;

use std::time::{Duration, Instant};

use optimis::api::HttpLimits;
use optimis::jobs::RunPolicy;
use optimis::server::{ConnectionLimits, RunningServer, ServerConfig, spawn};
use serde_json::Value;

/// An HTTP client for tests (rustls needs its crypto provider installed once per process).
pub fn client() -> reqwest::Client {
    optimis::jobs::peers::install_crypto_provider();
    reqwest::Client::new()
}

/// A server for one test.
pub struct TestServer {
    pub base: String,
    pub client: reqwest::Client,
    server: Option<RunningServer>,
    pub dir: tempfile::TempDir,
}

/// Settings for tests: 2 simulation threads, frequent checkpoints.
pub fn config(dir: &tempfile::TempDir) -> ServerConfig {
    ServerConfig {
        bind: "127.0.0.1:0".parse().unwrap(),
        database: format!("sqlite://{}", dir.path().join("optimis.db").display()),
        threads: 2,
        policy: RunPolicy {
            workers: 1,
            checkpoint_iterations: 5,
            checkpoint_interval: Duration::from_millis(300),
            ..RunPolicy::default()
        },
        http: HttpLimits::default(),
        connections: ConnectionLimits::default(),
        token: None,
        tls: None,
        peers: Vec::new(),
        peer_ca: None,
        allowed_hosts: Vec::new(),
    }
}

impl TestServer {
    pub async fn start() -> Self {
        Self::start_with(|_| {}).await
    }

    pub async fn start_with(tweak: impl FnOnce(&mut ServerConfig)) -> Self {
        Self::start_in(tempfile::tempdir().unwrap(), tweak).await
    }

    /// Starts on the database of `dir` (to restart after `stop`).
    pub async fn start_in(dir: tempfile::TempDir, tweak: impl FnOnce(&mut ServerConfig)) -> Self {
        let mut cfg = config(&dir);
        tweak(&mut cfg);
        let server = spawn(cfg).await.expect("server starts");
        Self { base: format!("http://{}", server.addr), client: client(), server: Some(server), dir }
    }

    /// The server's store (for fault injection).
    pub fn store(&self) -> optimis::store::Store {
        self.server.as_ref().expect("the server runs").jobs.store().clone()
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    pub async fn post(&self, path: &str, body: &Value) -> reqwest::Response {
        self.client.post(self.url(path)).json(body).send().await.unwrap()
    }

    /// Posts `body` as it is, declared as JSON.
    pub async fn post_raw(&self, path: &str, body: &'static str) -> reqwest::Response {
        self.client.post(self.url(path)).header("content-type", "application/json").body(body).send().await.unwrap()
    }

    pub async fn get(&self, path: &str) -> reqwest::Response {
        self.client.get(self.url(path)).send().await.unwrap()
    }

    pub async fn get_json(&self, path: &str) -> Value {
        let response = self.get(path).await;
        assert_eq!(response.status(), 200, "GET {path}");
        response.json().await.unwrap()
    }

    /// Submits a job and returns its id.
    pub async fn submit(&self, spec: &Value) -> i64 {
        let response = self.post("/v1/jobs", spec).await;
        assert_eq!(response.status(), 202, "submit {spec}");
        response.json::<Value>().await.unwrap()["id"].as_i64().unwrap()
    }

    /// Polls the job until `done` holds (a hang guard of 10 minutes, not a performance limit).
    pub async fn wait_for(&self, id: i64, done: impl Fn(&Value) -> bool) -> Value {
        let started = Instant::now();
        loop {
            let job = self.get_json(&format!("/v1/jobs/{id}")).await;
            if done(&job) {
                return job;
            }
            assert!(started.elapsed() < Duration::from_secs(240), "job {id} never reached the expected state: {job}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    pub async fn wait_for_state(&self, id: i64, state: &str) -> Value {
        self.wait_for(id, |j| j["state"] == state).await
    }

    /// Stops the server as on SIGTERM.
    pub async fn stop(mut self) -> tempfile::TempDir {
        self.graceful().await;
        std::mem::replace(&mut self.dir, tempfile::tempdir().unwrap())
    }

    async fn graceful(&mut self) {
        if let Some(server) = self.server.take() {
            server.shutdown().await.unwrap();
        }
    }
}

impl Drop for TestServer {
    /// A test that failed before `stop` must not leave its jobs computing while the other tests run.
    fn drop(&mut self) {
        if let Some(server) = &self.server {
            server.jobs.stop_all_now();
        }
    }
}

/// Asserts that `response` is an RFC 9457 problem with `status`, and returns it.
pub async fn assert_problem(response: reqwest::Response, status: u16) -> Value {
    assert_eq!(response.status(), status, "status");
    let content_type = response.headers().get("content-type").map(|v| v.to_str().unwrap().to_string());
    assert_eq!(content_type.as_deref(), Some("application/problem+json"));
    let problem: Value = response.json().await.unwrap();
    assert_eq!(problem["status"], status);
    assert!(problem["type"].as_str().unwrap().starts_with("urn:problem-type:optimis:"), "{problem}");
    assert!(!problem["title"].as_str().unwrap().is_empty());
    assert!(!problem["detail"].as_str().unwrap().is_empty());
    problem
}

/// The moments (as JSON) of an uninterrupted in-process run of `spec`'s iterations on two
/// threads: what a job that was killed, stopped or split must end with, bit for bit.
pub fn uninterrupted_moments(spec: &Value) -> Value {
    let job = optimis::sim::spec::parse_job_spec(spec).unwrap().validate().unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let moments = pool.install(|| optimis::sim::runner::run(&job.config, job.spec.seed, job.spec.iteration_range()));
    serde_json::to_value(&moments).unwrap()
}

/// A small, fast job (a few ms per iteration).
pub fn small_job(iterations: u64, seed: u64) -> Value {
    serde_json::json!({ "engine": "brute",
        "light_paths": 20_000, "camera_paths": 200, "merge_radius": 0.02,
        "iterations": iterations, "seed": seed
    })
}
