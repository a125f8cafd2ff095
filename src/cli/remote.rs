//! The command line as a client of a running server (`optimis wait`, `optimis compare --server`):
//! one HTTP client (rustls, the platform's roots), the bearer token from `OPTIMIS_TOKEN`, and a
//! server's answers turned into the command line's errors (exit 5 when it does not answer, 3 when
//! it refuses the request, with its problem detail).

use std::time::Duration;

use serde_json::Value;

use super::CliError;

/// A server at `base` (`localhost:8080`, `https://host:8443`; http:// without a scheme).
pub struct Server {
    base: String,
    client: reqwest::Client,
    token: Option<String>,
}

/// A server's answer: its status and body.
pub struct Answer {
    pub status: reqwest::StatusCode,
    pub retry_after: Option<u64>,
    pub body: String,
}

impl Server {
    /// A client of `base`, each request given `timeout`.
    pub fn new(base: &str, timeout: Duration) -> Result<Self, CliError> {
        let base = if base.contains("://") { base.to_string() } else { format!("http://{base}") };
        crate::trust::pins::install_crypto_provider();
        let tls = crate::trust::pins::client_config(Vec::new())
            .map_err(|e| CliError::Config(format!("cannot set up TLS: {e}")))?;
        let client = reqwest::Client::builder()
            .tls_backend_preconfigured(tls)
            .connect_timeout(Duration::from_secs(10))
            .timeout(timeout)
            .user_agent(concat!("optimis/", env!("CARGO_PKG_VERSION")))
            .build()
            .map_err(|e| CliError::Config(format!("cannot start the HTTP client: {e}")))?;
        let token = std::env::var("OPTIMIS_TOKEN").ok().filter(|t| !t.is_empty());
        Ok(Self { base: base.trim_end_matches('/').to_string(), client, token })
    }

    /// The absolute URL of `path` (which starts with `/`), or `path` itself if it is one.
    pub fn url(&self, path: &str) -> String {
        if path.contains("://") { path.to_string() } else { format!("{}{path}", self.base) }
    }

    /// GETs `path`: any status, or [`CliError::Unreachable`].
    pub async fn get(&self, path: &str) -> Result<Answer, CliError> {
        let url = self.url(path);
        let mut request = self.client.get(&url);
        if let Some(token) = &self.token {
            request = request.bearer_auth(token);
        }
        let unreachable = |e: reqwest::Error| CliError::Unreachable { url: url.clone(), detail: chain(&e) };
        let response = request.send().await.map_err(unreachable)?;
        let status = response.status();
        let retry_after = response.headers().get("retry-after").and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
        let body = response.text().await.map_err(unreachable)?;
        Ok(Answer { status, retry_after, body })
    }

    /// GETs `path` as JSON; a status other than 2xx is [`CliError::Refused`] with its detail.
    pub async fn get_json(&self, path: &str) -> Result<Value, CliError> {
        let answer = self.get(path).await?;
        answer.json(&self.url(path))
    }
}

impl Answer {
    /// The body as JSON if the status is a success; otherwise the server's refusal.
    pub fn json(&self, url: &str) -> Result<Value, CliError> {
        let refused = |detail: String| CliError::Refused { url: url.to_string(), status: self.status.as_u16(), detail };
        if !self.status.is_success() {
            let detail = serde_json::from_str::<Value>(&self.body)
                .ok()
                .and_then(|p| p["detail"].as_str().map(str::to_string))
                .unwrap_or_else(|| self.body.chars().take(300).collect());
            return Err(refused(detail));
        }
        serde_json::from_str(&self.body).map_err(|e| refused(format!("not JSON: {e}")))
    }
}

/// A current-thread runtime for one command's requests.
pub fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::Config(format!("cannot start the HTTP client: {e}")))
}

/// An error with its causes (reqwest's own message omits the connection's reason).
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
