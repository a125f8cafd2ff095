//! Cross-site protection for a server that browsers can reach.
//!
//! The default setup (loopback, no token) is reachable by every web page open on the machine. A
//! page cannot read our answers (no CORS headers are ever sent), but without these checks it could
//! still *send* requests — submit, cancel, merge — as "simple" cross-site requests. Three rules
//! close that, in the spirit of the Fetch standard's CORS-safelisted requests:
//!
//! * a request that carries a body must say `Content-Type: application/json` (or `…+json`), else
//!   415: a page can only send JSON cross-site after a CORS preflight, which this server never
//!   grants (body-less POSTs such as cancel are covered by the next rule); a body with a
//!   `Content-Encoding` other than `identity` is 415 too (bodies are not decoded);
//! * a request with an `Origin` header must come from this server's own origin (the `Origin`'s
//!   host and port equal the `Host` header) or a host named with `--allowed-host`, else 403 —
//!   browsers send `Origin` on every cross-origin request and on every POST;
//! * when the server is bound to loopback, the `Host` header must name a loopback host (or an
//!   `--allowed-host`), else 403: a DNS-rebinding page (`evil.example` re-resolved to 127.0.0.1)
//!   sends its own name as `Host`, and its `Origin` would otherwise match it.
//!
//! Clients that are not browsers (curl, scripts, peers) send no `Origin` and are unaffected.

use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, Method, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::AppState;
use super::error::ApiError;

/// What the guard accepts.
#[derive(Debug, Clone, Default)]
pub struct Guard {
    /// Bound to a loopback address: `Host` must name a loopback host or an allowed host.
    pub loopback: bool,
    /// Host names (lower case, without port) this server also answers to (`--allowed-host`).
    pub allowed_hosts: Arc<[String]>,
}

/// The host of a `Host` header value or an origin's authority, lower case, without the port.
fn host_only(authority: &str) -> String {
    let authority = authority.trim().to_ascii_lowercase();
    if let Some(rest) = authority.strip_prefix('[') {
        // `[v6]` or `[v6]:port` and nothing else: `[::1].evil.example` is not a loopback host but
        // an unparsable one (kept whole, so that no check accepts it).
        let Some((v6, after)) = rest.split_once(']') else { return authority };
        let port = after.strip_prefix(':').map(is_port);
        return if after.is_empty() || port == Some(true) { v6.to_string() } else { authority };
    }
    match authority.rsplit_once(':') {
        Some((host, port)) if is_port(port) => host.to_string(),
        _ => authority,
    }
}

/// A TCP port: 1 to 65535 in decimal (`127.0.0.1:99999` names no host this server answers to).
fn is_port(text: &str) -> bool {
    !text.is_empty()
        && text.len() <= 5
        && text.bytes().all(|b| b.is_ascii_digit())
        && text.parse::<u16>().is_ok_and(|p| p > 0)
}

fn is_loopback_host(host: &str) -> bool {
    host == "localhost"
        || host.ends_with(".localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

fn is_json(headers: &HeaderMap) -> bool {
    let Some(value) = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()) else { return false };
    let essence = value.split(';').next().unwrap_or_default().trim().to_ascii_lowercase();
    essence == "application/json" || (essence.starts_with("application/") && essence.ends_with("+json"))
}

/// Whether the request carries a body (a non-zero length, or a chunked one).
fn has_body(headers: &HeaderMap) -> bool {
    headers.contains_key(header::TRANSFER_ENCODING)
        || headers
            .get(header::CONTENT_LENGTH)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|n| n.trim().parse::<u64>().map_or(true, |n| n > 0))
}

impl Guard {
    fn allowed(&self, host: &str) -> bool {
        self.allowed_hosts.iter().any(|h| h == host)
    }

    /// Checks a request's headers; the problem to answer if it is refused.
    pub fn check(&self, method: &Method, headers: &HeaderMap) -> Result<(), ApiError> {
        let host_header = headers.get(header::HOST).and_then(|v| v.to_str().ok());
        if self.loopback
            && let Some(host_header) = host_header
        {
            let host = host_only(host_header);
            if !is_loopback_host(&host) && !self.allowed(&host) {
                return Err(ApiError::Forbidden(format!(
                    "this server is bound to loopback and does not answer to the host {host:?} (a DNS-rebinding \
                     page?); behind a proxy that forwards another Host, start it with --allowed-host {host}"
                )));
            }
        }
        if let Some(origin) = headers.get(header::ORIGIN) {
            let origin = origin.to_str().unwrap_or_default().trim();
            let authority = origin.split_once("://").map(|(_, rest)| rest.trim_end_matches('/'));
            let same = match (authority, host_header) {
                (Some(a), Some(h)) => a.eq_ignore_ascii_case(h.trim()),
                _ => false,
            };
            let listed = authority.is_some_and(|a| self.allowed(&host_only(a)));
            if !(same || listed) {
                return Err(ApiError::Forbidden(format!(
                    "cross-origin requests are refused (Origin {origin:?} is not this server's own origin); use the \
                     dashboard this server serves, or a client that is not a browser"
                )));
            }
        }
        let writes = matches!(*method, Method::POST | Method::PUT | Method::PATCH | Method::DELETE);
        if writes && has_body(headers) && !is_json(headers) {
            return Err(ApiError::UnsupportedMediaType(
                "a request body must be JSON: send `Content-Type: application/json`".into(),
            ));
        }
        // Request bodies are not decoded: an encoded one would be read as if it were plain JSON.
        if let Some(encoding) = headers.get(header::CONTENT_ENCODING) {
            let encoding = encoding.to_str().unwrap_or("?").trim();
            if writes && has_body(headers) && !encoding.eq_ignore_ascii_case("identity") {
                return Err(ApiError::UnsupportedMediaType(format!(
                    "this server does not decode request bodies (Content-Encoding: {encoding}); send the body \
                     uncompressed"
                )));
            }
        }
        Ok(())
    }
}

/// Middleware: applies the [`Guard`].
pub async fn guard(State(state): State<AppState>, request: Request, next: Next) -> Response {
    match state.guard.check(request.method(), request.headers()) {
        Ok(()) => next.run(request).await,
        Err(e) => e.into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(pairs: &[(&'static str, &'static str)]) -> HeaderMap {
        let mut map = HeaderMap::new();
        for (k, v) in pairs {
            map.insert(*k, HeaderValue::from_static(v));
        }
        map
    }

    #[test]
    fn cross_site_requests_are_refused() {
        let guard = Guard { loopback: true, allowed_hosts: Arc::from(vec!["optimis.example.org".to_string()]) };
        let ok = |m: Method, h: &[(&'static str, &'static str)]| guard.check(&m, &headers(h)).is_ok();
        // curl: no Origin.
        assert!(ok(
            Method::POST,
            &[("host", "127.0.0.1:8080"), ("content-type", "application/json"), ("content-length", "2")]
        ));
        assert!(ok(Method::POST, &[("host", "localhost:8080"), ("content-length", "0")]), "a body-less cancel");
        assert!(ok(Method::GET, &[("host", "[::1]:8080")]));
        // The dashboard: same origin.
        assert!(ok(
            Method::POST,
            &[
                ("host", "127.0.0.1:8080"),
                ("origin", "http://127.0.0.1:8080"),
                ("content-type", "application/json; charset=utf-8"),
                ("content-length", "2")
            ]
        ));
        // Another site's page.
        assert!(!ok(Method::POST, &[("host", "127.0.0.1:8080"), ("origin", "http://evil.example")]));
        assert!(!ok(Method::GET, &[("host", "127.0.0.1:8080"), ("origin", "null")]));
        assert!(!ok(Method::POST, &[("host", "127.0.0.1:8080"), ("origin", "http://127.0.0.1:9999")]), "another port");
        // DNS rebinding: Origin and Host agree, but the host is not ours.
        assert!(!ok(Method::POST, &[("host", "evil.example:8080"), ("origin", "http://evil.example:8080")]));
        // A proxy's public name.
        assert!(ok(
            Method::POST,
            &[
                ("host", "optimis.example.org"),
                ("origin", "https://optimis.example.org"),
                ("content-type", "application/json"),
                ("content-length", "2")
            ]
        ));
        // Bodies that are not JSON: the simple requests a form can send.
        for ct in ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x"] {
            let h = [("host", "127.0.0.1:8080"), ("content-type", ct), ("content-length", "5")];
            assert!(matches!(guard.check(&Method::POST, &headers(&h)), Err(ApiError::UnsupportedMediaType(_))), "{ct}");
        }
        assert!(!ok(Method::POST, &[("host", "127.0.0.1:8080"), ("content-length", "5")]), "a body without a type");
        // Issue 22, item 10: an encoded body is refused (415), not read as if it were plain.
        for encoding in ["br", "gzip", "deflate"] {
            let h = [
                ("host", "127.0.0.1:8080"),
                ("content-type", "application/json"),
                ("content-length", "9"),
                ("content-encoding", encoding),
            ];
            assert!(matches!(guard.check(&Method::POST, &headers(&h)), Err(ApiError::UnsupportedMediaType(_))));
        }
        let identity = [
            ("host", "127.0.0.1:8080"),
            ("content-type", "application/json"),
            ("content-length", "2"),
            ("content-encoding", "identity"),
        ];
        assert!(ok(Method::POST, &identity));
        assert!(ok(
            Method::POST,
            &[("host", "127.0.0.1:8080"), ("content-type", "application/merge-patch+json"), ("content-length", "2")]
        ));
        // Not bound to loopback: any Host (a token guards the server), Origin still checked.
        let open = Guard::default();
        assert!(open.check(&Method::GET, &headers(&[("host", "node2:8080")])).is_ok());
        assert!(
            open.check(&Method::GET, &headers(&[("host", "node2:8080"), ("origin", "http://evil.example")])).is_err()
        );
    }

    #[test]
    fn hosts_are_compared_without_ports() {
        assert_eq!(host_only("LOCALHOST:8080"), "localhost");
        assert_eq!(host_only("[::1]:80"), "::1");
        assert_eq!(host_only("[::1]"), "::1");
        for spoof in ["[::1].evil.example", "[::1]:80.evil.example", "[::1]:", "[::1"] {
            assert!(!is_loopback_host(&host_only(spoof)), "{spoof}");
        }
        // Issue 39, item 13: a port that is no port names no host.
        for bad in ["127.0.0.1:99999", "127.0.0.1:0", "localhost:", "[::1]:65536", "127.0.0.1:0080808"] {
            assert!(!is_loopback_host(&host_only(bad)), "{bad}");
        }
        assert!(is_loopback_host(&host_only("127.0.0.1:65535")) && is_loopback_host(&host_only("localhost:08080")));
        assert_eq!(host_only("example.org"), "example.org");
        assert!(is_loopback_host("127.3.4.5") && is_loopback_host("::1") && !is_loopback_host("10.0.0.1"));
    }
}
