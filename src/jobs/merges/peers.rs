//! Moments documents pulled from peer servers, for merges and studies — and only from peers this
//! server was told to trust.
//!
//! A source names a job on another optimis server (`https://node2:8443/v1/jobs/7`). It is pulled
//! only if its URL lies under one of the server's allowed peers (`--peer BASE_URL`, each with an
//! optional bearer token read from a file); anything else is refused before any connection is
//! made, so a request cannot make this server probe other hosts, ports or paths. Every pull is
//! bounded:
//!
//! * no redirects (a redirect could lead anywhere the allow-list does not);
//! * connect, read and overall timeouts ([`PEER_CONNECT_TIMEOUT`], [`PEER_READ_TIMEOUT`],
//!   [`PEER_DEADLINE`]);
//! * a 2xx body is read up to the document limit (`--document-limit`), an error body up to
//!   [`ERROR_BODY_LIMIT`] bytes and never echoed (a peer's error text could hold anything, and
//!   echoing it would make this server an oracle for what sits at a URL);
//! * at most [`PULLS_PER_CLIENT`] pulls in flight for one client (its studies' slow peers delay
//!   only its own requests) and [`CONCURRENT_PULLS`] server-wide, so that memory stays below that
//!   many document limits; a pull waits at most [`PULL_WAIT`] for its turn (then 429), and a
//!   study's pulls together at most its deadline (`--study-deadline`). A pull waiting on its peer
//!   holds a connection and nothing else: no processing slot, no other client's turn.
//!
//! https peers are verified against the system's roots plus any `--peer-ca` certificates, each of
//! which is also pinned (`crate::trust::pins`; rustls with the ring provider).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use reqwest::Url;
use tokio::sync::Semaphore;

use rustls::pki_types::CertificateDer;
use rustls::pki_types::pem::PemObject;

use super::shares::{ClientKey, Shares};
use crate::jobs::core::error::JobError;
use crate::trust::pins::{client_config, install_crypto_provider};
use crate::trust::secrets::{SecretError, read_config_file, read_secret};

/// Time to establish a connection to a peer.
pub const PEER_CONNECT_TIMEOUT: Duration = Duration::from_secs(10);
/// Longest wait for the next bytes of a peer's answer.
pub const PEER_READ_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest a whole pull may take.
pub const PEER_DEADLINE: Duration = Duration::from_secs(120);
/// Bytes of a peer's error answer that are read (and discarded) before the connection is dropped.
pub const ERROR_BODY_LIMIT: usize = 4096;
/// Pulls in flight at once, over all requests and clients.
pub const CONCURRENT_PULLS: usize = 16;
/// Pulls in flight at once for one client (and the most one study runs at once).
pub const PULLS_PER_CLIENT: usize = 4;
/// Longest a pull waits for one of the [`CONCURRENT_PULLS`] before its request is answered 429.
pub const PULL_WAIT: Duration = Duration::from_secs(30);

/// One allowed peer: a base URL (scheme, host, port and an optional path prefix) and the bearer
/// token this server presents to it.
#[derive(Clone)]
pub struct Peer {
    base: Url,
    token: Option<Arc<str>>,
}

impl std::fmt::Debug for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Peer")
            .field("base", &self.base.as_str())
            .field("token", &self.token.as_ref().map(|_| "…"))
            .finish()
    }
}

/// Why the peer configuration cannot be used (reported at start).
#[derive(Debug, thiserror::Error)]
pub enum PeerConfigError {
    /// A `--peer` argument (as given) is not a usable base URL, and why.
    #[error("--peer {0:?}: {1}")]
    Url(String, String),
    /// A peer's token file or the `--peer-ca` file cannot be read, or the token file is not
    /// secret (see [`SecretError`]).
    #[error(transparent)]
    Secret(#[from] SecretError),
    /// The `--peer-ca` file holds no PEM certificate, or one that cannot be parsed.
    #[error("--peer-ca {path}: {message}")]
    Ca {
        /// The `--peer-ca` file.
        path: PathBuf,
        /// Why its certificates cannot be used.
        message: String,
    },
    /// The HTTP client that pulls from peers cannot be built (its TLS verifier or the client
    /// itself), with the library's reason.
    #[error("cannot build the peer client: {0}")]
    Client(String),
}

impl Peer {
    /// Parses `BASE_URL[,token-file=PATH]`: an http(s) URL without query or fragment, and a file
    /// holding the bearer token for it (readable by its owner only).
    pub fn parse(text: &str) -> Result<Self, PeerConfigError> {
        let (url, token_file) = match text.split_once(",token-file=") {
            Some((url, path)) => (url, Some(PathBuf::from(path))),
            None => (text, None),
        };
        let bad = |m: &str| PeerConfigError::Url(text.to_string(), m.to_string());
        let mut base = Url::parse(url).map_err(|e| bad(&format!("not a URL: {e}")))?;
        if !matches!(base.scheme(), "http" | "https") {
            return Err(bad("must be an http:// or https:// URL"));
        }
        if base.host_str().is_none() || base.query().is_some() || base.fragment().is_some() {
            return Err(bad("must be scheme://host[:port][/prefix] without query or fragment"));
        }
        if !base.username().is_empty() || base.password().is_some() {
            return Err(bad("must not hold credentials; give the token in a file with ,token-file=PATH"));
        }
        let prefix = base.path().trim_end_matches('/').to_string();
        base.set_path(&prefix);
        let token = token_file.map(|path| read_secret(&path)).transpose()?;
        Ok(Self { base, token: token.map(Into::into) })
    }

    /// The base URL (for messages).
    pub fn base(&self) -> &str {
        self.base.as_str().trim_end_matches('/')
    }

    /// Whether `url` lies under this peer: same scheme, host and port, and the path continues the
    /// base's prefix.
    fn covers(&self, url: &Url) -> bool {
        let prefix = self.base.path().trim_end_matches('/');
        url.scheme() == self.base.scheme()
            && url.host_str().map(str::to_ascii_lowercase) == self.base.host_str().map(str::to_ascii_lowercase)
            && url.port_or_known_default() == self.base.port_or_known_default()
            && url.path().strip_prefix(prefix).is_some_and(|rest| rest.starts_with('/'))
    }
}

/// The peers this server may pull from, and the client it pulls with.
pub struct Peers {
    allowed: Vec<Peer>,
    client: reqwest::Client,
    /// Largest document accepted (the server's `--document-limit`).
    document_limit: usize,
    /// Connections to peers, server-wide.
    pulls: Semaphore,
    /// Pulls in flight per client.
    client_pulls: Arc<Shares>,
}

impl std::fmt::Debug for Peers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Peers").field("allowed", &self.allowed).field("document_limit", &self.document_limit).finish()
    }
}

impl Peers {
    /// The allow-list `allowed`, with extra trusted roots from the PEM file `ca` (for peers with
    /// self-signed or private certificates).
    pub fn new(allowed: Vec<Peer>, ca: Option<&Path>, document_limit: usize) -> Result<Self, PeerConfigError> {
        install_crypto_provider();
        let mut builder = reqwest::Client::builder()
            .redirect(reqwest::redirect::Policy::none())
            .no_proxy()
            .connect_timeout(PEER_CONNECT_TIMEOUT)
            .read_timeout(PEER_READ_TIMEOUT)
            .timeout(PEER_DEADLINE)
            .user_agent(concat!("optimis/", env!("CARGO_PKG_VERSION")));
        let mut extra = Vec::new();
        if let Some(path) = ca {
            let pem =
                read_config_file(path).map_err(|source| SecretError::Read { path: path.to_path_buf(), source })?;
            extra = CertificateDer::pem_slice_iter(&pem)
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| PeerConfigError::Ca { path: path.to_path_buf(), message: e.to_string() })?;
            if extra.is_empty() {
                return Err(PeerConfigError::Ca { path: path.to_path_buf(), message: "holds no certificate".into() });
            }
        }
        let tls = client_config(extra).map_err(|e| PeerConfigError::Client(e.to_string()))?;
        builder = builder.tls_backend_preconfigured(tls);
        let client = builder.build().map_err(|e| PeerConfigError::Client(e.to_string()))?;
        Ok(Self {
            allowed,
            client,
            document_limit,
            pulls: Semaphore::new(CONCURRENT_PULLS),
            client_pulls: Shares::new(PULLS_PER_CLIENT),
        })
    }

    /// No peers (every pull refused).
    pub fn none(document_limit: usize) -> Self {
        Self::new(Vec::new(), None, document_limit).expect("a client without extra roots builds")
    }

    /// The `/moments` URL of a peer job URL and the allowed peer it lies under, or why it may not
    /// be pulled. Makes no connection. `field` is the JSON path of the URL, for messages.
    pub fn resolve(&self, url: &str, field: &str) -> Result<(Url, &Peer), JobError> {
        let target = moments_url(url).map_err(|m| JobError::Invalid(crate::sim::spec::SpecError::new(field, m)))?;
        match self.allowed.iter().find(|p| p.covers(&target)) {
            Some(peer) => Ok((target, peer)),
            None => {
                let origin = target.origin().ascii_serialization();
                let hint = if self.allowed.is_empty() {
                    "this server allows no peers".to_string()
                } else {
                    let list: Vec<&str> = self.allowed.iter().map(Peer::base).collect();
                    format!("its allowed peers are {}", list.join(", "))
                };
                Err(JobError::PeerNotAllowed {
                    field: field.to_string(),
                    message: format!(
                        "{origin} is not an allowed peer of this server ({hint}); to pull from it, start this server \
                         with --peer {origin} (and ,token-file=PATH if it requires a token)"
                    ),
                })
            }
        }
    }

    /// Fetches the moments document of the job at `url` on an allowed peer for `client`'s request
    /// (unparsed bytes).
    pub async fn pull(&self, url: &str, field: &str, client: ClientKey) -> Result<Vec<u8>, JobError> {
        let (target, peer) = self.resolve(url, field)?;
        let busy = |detail: String| JobError::Busy { detail, retry_after_seconds: 10 };
        // The client's own turn first: its other pulls (a slow peer's among them) delay only it.
        let mut turn = self.client_pulls.open(client);
        let started = tokio::time::Instant::now();
        while !turn.grow(1) {
            if started.elapsed() >= PULL_WAIT {
                return Err(busy(format!(
                    "{field}: {client} already has {PULLS_PER_CLIENT} pulls from peers in flight; retry"
                )));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let left = PULL_WAIT.saturating_sub(started.elapsed());
        let _permit = match tokio::time::timeout(left, self.pulls.acquire()).await {
            Ok(permit) => permit.map_err(|_| JobError::ShuttingDown)?,
            Err(_) => return Err(busy(format!("{field}: {CONCURRENT_PULLS} pulls from peers are in flight; retry"))),
        };
        let peer_error = |message: String| JobError::Peer { field: field.to_string(), message };
        let fetch = async {
            let mut request = self.client.get(target.clone());
            if let Some(token) = &peer.token {
                request = request.bearer_auth(token);
            }
            let mut response = request.send().await.map_err(|e| peer_error(describe(&target, &e)))?;
            let status = response.status();
            if !status.is_success() {
                // Read a little (so the connection can be reused), never echo it.
                let mut read = 0;
                while read < ERROR_BODY_LIMIT {
                    match response.chunk().await {
                        Ok(Some(chunk)) => read += chunk.len(),
                        _ => break,
                    }
                }
                let hint = match status.as_u16() {
                    401 | 403 => " (check the token this server presents to it: --peer URL,token-file=PATH)",
                    300..=399 => " (redirects are not followed)",
                    404 => " (no such job there)",
                    409 => " (the job has no checkpoint yet, or it is corrupted)",
                    _ => "",
                };
                return Err(peer_error(format!("the peer {target} answered {status}{hint}")));
            }
            if response.content_length().is_some_and(|n| n > self.document_limit as u64) {
                return Err(peer_error(format!(
                    "the document at {target} is larger than this server's document limit of {} bytes (--document-limit)",
                    self.document_limit
                )));
            }
            let mut bytes = Vec::new();
            while let Some(chunk) = response.chunk().await.map_err(|e| peer_error(describe(&target, &e)))? {
                if bytes.len() + chunk.len() > self.document_limit {
                    return Err(peer_error(format!(
                        "the document at {target} exceeds this server's document limit of {} bytes (--document-limit)",
                        self.document_limit
                    )));
                }
                bytes.extend_from_slice(&chunk);
            }
            Ok(bytes)
        };
        tokio::time::timeout(PEER_DEADLINE, fetch)
            .await
            .map_err(|_| peer_error(format!("the peer {target} did not answer within {} s", PEER_DEADLINE.as_secs())))?
    }
}

/// A transport error in plain words, without the peer's own text.
fn describe(target: &Url, e: &reqwest::Error) -> String {
    let what = if e.is_timeout() {
        "timed out".to_string()
    } else if let Some(tls) = tls_error(e) {
        format!(
            "failed its TLS handshake: {tls} (trust a private CA or the peer's own certificate with --peer-ca \
             FILE)"
        )
    } else if e.is_connect() {
        "could not be reached (connection refused or failed)".to_string()
    } else if e.is_body() || e.is_decode() {
        "broke off while sending the document".to_string()
    } else {
        "failed".to_string()
    };
    format!("the request to the peer {target} {what}")
}

/// The TLS error under a failed request, if that is what failed: what rustls says is wrong with
/// the handshake (e.g. `invalid peer certificate: UnknownIssuer`), which names no content of the
/// peer's and so can be shown.
fn tls_error(e: &reqwest::Error) -> Option<String> {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = source {
        if let Some(tls) = err.downcast_ref::<rustls::Error>() {
            return Some(tls.to_string());
        }
        // An io::Error's source() skips the error it wraps (tokio-rustls wraps rustls' there, and
        // hyper wraps that io::Error in another): step into what it wraps instead.
        source = match err.downcast_ref::<std::io::Error>().and_then(|io| io.get_ref()) {
            Some(inner) => Some(inner as &(dyn std::error::Error + 'static)),
            None => err.source(),
        };
    }
    None
}

/// The `/moments` URL of a peer job URL, or why it is not one.
pub fn moments_url(url: &str) -> Result<Url, String> {
    let parsed = Url::parse(url).map_err(|e| format!("not a URL ({e}): {url:?}"))?;
    if !matches!(parsed.scheme(), "http" | "https") {
        return Err(format!("unsupported scheme {:?}; expected https://host:port/v1/jobs/ID", parsed.scheme()));
    }
    if parsed.host_str().is_none() {
        return Err(format!("no host in {url:?}"));
    }
    if !parsed.username().is_empty() || parsed.password().is_some() {
        return Err("a peer URL must not hold credentials; the server presents the peer's token".into());
    }
    let path = parsed.path().trim_end_matches('/');
    let segments: Vec<&str> = path.rsplit('/').take(4).collect();
    let job_path = match segments.as_slice() {
        [id, "jobs", "v1", ..] if is_id(id) => format!("{path}/moments"),
        ["moments", id, "jobs", "v1"] if is_id(id) => path.to_string(),
        _ => return Err(format!("expected the URL of a job, https://host:port/v1/jobs/ID, got {url:?}")),
    };
    let mut target = parsed.clone();
    target.set_path(&job_path);
    target.set_query(None);
    target.set_fragment(None);
    Ok(target)
}

fn is_id(s: &str) -> bool {
    s.parse::<i64>().is_ok_and(|id| id > 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peer_urls_point_at_a_jobs_moments() {
        let url = |u: &str| moments_url(u).map(|u| u.to_string());
        assert_eq!(url("http://10.0.0.2:8080/v1/jobs/7").unwrap(), "http://10.0.0.2:8080/v1/jobs/7/moments");
        assert_eq!(url("https://h:1/v1/jobs/7/").unwrap(), "https://h:1/v1/jobs/7/moments");
        assert_eq!(url("http://h/v1/jobs/7/moments").unwrap(), "http://h/v1/jobs/7/moments");
        assert_eq!(url("https://h/optimis/v1/jobs/7?x=1").unwrap(), "https://h/optimis/v1/jobs/7/moments");
        for bad in [
            "ftp://h/v1/jobs/7",
            "http://h/v1/jobs",
            "http://h/v1/jobs/x",
            "h:1/v1/jobs/7",
            "",
            "http://u:p@h/v1/jobs/7",
        ] {
            assert!(moments_url(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn only_urls_under_an_allowed_peer_resolve() {
        let peers = Peers::new(
            vec![Peer::parse("https://node2:8443").unwrap(), Peer::parse("http://127.0.0.1:9000/optimis/").unwrap()],
            None,
            1 << 20,
        )
        .unwrap();
        for ok in [
            "https://node2:8443/v1/jobs/7",
            "https://NODE2:8443/v1/jobs/7/moments",
            "http://127.0.0.1:9000/optimis/v1/jobs/1",
        ] {
            assert!(peers.resolve(ok, "from").is_ok(), "{ok}");
        }
        for refused in [
            "http://node2:8443/v1/jobs/7",     // another scheme
            "https://node2:8444/v1/jobs/7",    // another port
            "https://node2/v1/jobs/7",         // the default port is another port
            "https://node3:8443/v1/jobs/7",    // another host
            "http://127.0.0.1:9000/v1/jobs/1", // outside the prefix
            "http://127.0.0.1:9000/optimisx/v1/jobs/1",
        ] {
            assert!(matches!(peers.resolve(refused, "from"), Err(JobError::PeerNotAllowed { .. })), "{refused}");
        }
        let e = peers.resolve("https://evil.example/v1/jobs/1", "sources[2].from").unwrap_err();
        assert!(e.to_string().contains("--peer https://evil.example"), "{e}");
    }

    #[test]
    fn peer_specs_and_secrets_are_checked() {
        assert!(Peer::parse("ftp://h").is_err());
        assert!(Peer::parse("https://h/?q=1").is_err());
        assert!(Peer::parse("https://user:pw@h").is_err());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("token");
        std::fs::write(&path, "a-long-enough-peer-token\n").unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
            let e = Peer::parse(&format!("https://h:1,token-file={}", path.display())).unwrap_err();
            assert!(e.to_string().contains("chmod 600"), "{e}");
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        }
        let peer = Peer::parse(&format!("https://h:1,token-file={}", path.display())).unwrap();
        assert_eq!(peer.token.as_deref(), Some("a-long-enough-peer-token"));
        assert!(!format!("{peer:?}").contains("a-long-enough"), "the token never prints");
    }
}
