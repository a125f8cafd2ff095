//! The one HTTP client of the integration tests: a base URL, an optional bearer token, the job
//! routes, raw requests for the error-mapping tests, and the one way to wait for a job.

use std::time::{Duration, Instant};

use reqwest::Method;
use reqwest::header::HeaderMap;
use serde_json::Value;

/// How long [`Client::wait_until`] polls before it fails the test with the job's last state: a
/// guard against a test that would otherwise hang forever, not a performance limit (the slowest
/// job of the suite needs well under a minute on a free machine).
pub const HANG_GUARD: Duration = Duration::from_secs(600);

/// Pause between two polls of a job.
const POLL: Duration = Duration::from_millis(20);

/// A client of one server (a base URL such as `http://127.0.0.1:4242`), with an optional token.
#[derive(Clone)]
pub struct Client {
    base: String,
    http: reqwest::Client,
    token: Option<String>,
}

/// A whole answer: status, headers and the body read to its end.
#[derive(Debug)]
pub struct Reply {
    pub status: u16,
    pub headers: HeaderMap,
    pub body: Vec<u8>,
}

impl Reply {
    /// Reads `response` to its end.
    pub async fn read(response: reqwest::Response) -> Self {
        let status = response.status().as_u16();
        let headers = response.headers().clone();
        let body = response.bytes().await.expect("the body arrives").to_vec();
        Self { status, headers, body }
    }

    /// The body as JSON (panics with the status and the text when it is not).
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("a {} answer that is not JSON ({e}): {}", self.status, self.text()))
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// A header as text, if present.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).map(|v| v.to_str().expect("a text header"))
    }
}

/// Asserts that `reply` is an RFC 9457 problem with `status`, and returns it.
pub fn assert_problem(reply: Reply, status: u16) -> Value {
    assert_eq!(reply.status, status, "status of {}", reply.text());
    assert_eq!(reply.header("content-type"), Some("application/problem+json"));
    let problem = reply.json();
    assert_eq!(problem["status"], status);
    assert!(problem["type"].as_str().unwrap().starts_with("urn:problem-type:optimis:"), "{problem}");
    assert!(!problem["title"].as_str().unwrap().is_empty());
    assert!(!problem["detail"].as_str().unwrap().is_empty());
    problem
}

/// An HTTP client for tests (rustls needs its crypto provider installed once per process).
pub fn http() -> reqwest::Client {
    optimis::trust::pins::install_crypto_provider();
    reqwest::Client::new()
}

impl Client {
    pub fn new(base: impl Into<String>) -> Self {
        Self { base: base.into(), http: http(), token: None }
    }

    /// Sends `Authorization: Bearer <token>` with every request.
    pub fn with_token(mut self, token: &str) -> Self {
        self.token = Some(token.to_string());
        self
    }

    /// Uses `http` (e.g. one that trusts a test certificate) instead of a plain client.
    pub fn with_http(mut self, http: reqwest::Client) -> Self {
        self.http = http;
        self
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// A request to `path` (with the token), for headers or bodies the helpers below do not set.
    pub fn builder(&self, method: Method, path: &str) -> reqwest::RequestBuilder {
        let builder = self.http.request(method, self.url(path));
        match &self.token {
            Some(token) => builder.bearer_auth(token),
            None => builder,
        }
    }

    /// Sends `builder` and reads the whole answer.
    pub async fn send(&self, builder: reqwest::RequestBuilder) -> Reply {
        Reply::read(builder.send().await.expect("the request is answered")).await
    }

    /// `method path` with an optional JSON body.
    pub async fn request(&self, method: Method, path: &str, body: Option<&Value>) -> Reply {
        let builder = self.builder(method, path);
        self.send(match body {
            Some(body) => builder.json(body),
            None => builder,
        })
        .await
    }

    pub async fn get(&self, path: &str) -> Reply {
        self.request(Method::GET, path, None).await
    }

    pub async fn post(&self, path: &str, body: &Value) -> Reply {
        self.request(Method::POST, path, Some(body)).await
    }

    /// Posts `body` as it is, declared as JSON.
    pub async fn post_raw(&self, path: &str, body: impl Into<reqwest::Body>) -> Reply {
        self.send(self.builder(Method::POST, path).header("content-type", "application/json").body(body)).await
    }

    /// A GET whose body is left unread: an event stream that stays open while the response lives.
    pub async fn open(&self, path: &str) -> reqwest::Response {
        self.builder(Method::GET, path).send().await.expect("the request is answered")
    }

    /// GET `path`, which must answer 200, as JSON.
    pub async fn get_json(&self, path: &str) -> Value {
        let reply = self.get(path).await;
        assert_eq!(reply.status, 200, "GET {path}: {}", reply.text());
        reply.json()
    }

    /// Submits a job (202) and returns it.
    pub async fn submit_job(&self, spec: &Value) -> Value {
        let reply = self.post("/v1/jobs", spec).await;
        assert_eq!(reply.status, 202, "submit {spec}: {}", reply.text());
        reply.json()
    }

    /// Submits a job (202) and returns its id.
    pub async fn submit(&self, spec: &Value) -> i64 {
        self.submit_job(spec).await["id"].as_i64().unwrap()
    }

    /// Submits a job and waits until it succeeded; its id.
    pub async fn submit_and_wait(&self, spec: &Value) -> i64 {
        let id = self.submit(spec).await;
        self.wait_for_state(id, "succeeded").await;
        id
    }

    /// The job (200).
    pub async fn job(&self, id: i64) -> Value {
        self.get_json(&format!("/v1/jobs/{id}")).await
    }

    /// The job's result (200).
    pub async fn result(&self, id: i64) -> Value {
        self.get_json(&format!("/v1/jobs/{id}/result")).await
    }

    /// The job's moments document (200).
    pub async fn moments(&self, id: i64) -> Value {
        self.get_json(&format!("/v1/jobs/{id}/moments")).await
    }

    /// The job's checkpoint history (200).
    pub async fn history(&self, id: i64) -> Value {
        self.get_json(&format!("/v1/jobs/{id}/history")).await
    }

    /// The jobs of the list `/v1/jobs{query}` (one page).
    pub async fn list(&self, query: &str) -> Vec<Value> {
        self.get_json(&format!("/v1/jobs{query}")).await["jobs"].as_array().unwrap().clone()
    }

    pub async fn cancel(&self, id: i64) -> Reply {
        self.request(Method::POST, &format!("/v1/jobs/{id}/cancel"), None).await
    }

    pub async fn extend(&self, id: i64, body: &Value) -> Reply {
        self.post(&format!("/v1/jobs/{id}/extend"), body).await
    }

    pub async fn solve(&self, id: i64, body: &Value) -> Reply {
        self.post(&format!("/v1/jobs/{id}/solve"), body).await
    }

    /// Merges a moments document (or `{"from": url}`) into job `id`.
    pub async fn merge(&self, id: i64, body: &Value) -> Reply {
        self.post(&format!("/v1/jobs/{id}/merge"), body).await
    }

    /// Creates a study from `{"sources": [...]}`.
    pub async fn study(&self, body: &Value) -> Reply {
        self.post("/v1/studies", body).await
    }

    pub async fn delete(&self, id: i64) -> Reply {
        self.request(Method::DELETE, &format!("/v1/jobs/{id}"), None).await
    }

    /// Polls the job until `done` holds, and returns it. Fails the test with the job's last state
    /// after [`HANG_GUARD`].
    pub async fn wait_until(&self, id: i64, done: impl Fn(&Value) -> bool) -> Value {
        let started = Instant::now();
        loop {
            let job = self.job(id).await;
            if done(&job) {
                return job;
            }
            assert!(
                started.elapsed() < HANG_GUARD,
                "hang guard: job {id} did not reach the expected state within {HANG_GUARD:?}; last seen: {job}"
            );
            tokio::time::sleep(POLL).await;
        }
    }

    pub async fn wait_for_state(&self, id: i64, state: &str) -> Value {
        self.wait_until(id, |j| j["state"] == state).await
    }

    /// Waits until the job is in a final state (succeeded, failed or cancelled).
    pub async fn wait_finished(&self, id: i64) -> Value {
        self.wait_until(id, |j| matches!(j["state"].as_str(), Some("succeeded" | "failed" | "cancelled"))).await
    }
}
