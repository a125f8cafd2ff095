//! Test helpers: a real server on 127.0.0.1 (port 0) with a SQLite file in a temporary directory,
//! the one HTTP client of the tests ([`Client`]), and the uninterrupted reference run.
//!
//! A [`TestServer`] (and a [`process::Process`]) dereferences to a [`Client`] of its base URL:
//! `server.submit(&spec)`, `server.wait_for_state(id, "succeeded")`, `server.get("/healthz")`.

pub mod client;
pub mod process;

use std::time::Duration;

use optimis::api::HttpLimits;
use optimis::jobs::RunPolicy;
use optimis::server::{ConnectionLimits, RunningServer, ServerConfig, spawn};
use serde_json::Value;

pub use client::{Client, assert_problem};

/// A server for one test.
pub struct TestServer {
    pub base: String,
    /// A client of this server (without a token).
    pub api: Client,
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
        signing_key: None,
        trust: Vec::new(),
        allowed_hosts: Vec::new(),
        cluster: None,
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
        let base = format!("http://{}", server.addr);
        Self { api: Client::new(&base), base, server: Some(server), dir }
    }

    /// The server's store (for fault injection).
    pub fn store(&self) -> optimis::store::Store {
        self.server.as_ref().expect("the server runs").jobs.store().clone()
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

impl std::ops::Deref for TestServer {
    type Target = Client;

    fn deref(&self) -> &Client {
        &self.api
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

/// The moments (as JSON) of an uninterrupted in-process run of `spec`'s iterations on two
/// threads: what a job that was killed, stopped or split must end with, bit for bit.
pub fn uninterrupted_moments(spec: &Value) -> Value {
    let job = optimis::sim::spec::parse_job_spec(spec).unwrap().validate().unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let moments =
        pool.install(|| optimis::sim::runner::run(job.config(), job.spec().seed, job.spec().iteration_range()));
    serde_json::to_value(&moments).unwrap()
}

/// A small, fast job (a few ms per iteration).
pub fn small_job(iterations: u64, seed: u64) -> Value {
    serde_json::json!({ "engine": "brute",
        "light_paths": 20_000, "camera_paths": 200, "merge_radius": 0.02,
        "iterations": iterations, "seed": seed
    })
}
