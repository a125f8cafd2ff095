//! Fetching moments documents: given inline, or pulled from a peer server's job.
//!
//! A peer is named by the URL of a job on another optimis server (`http://host:port/v1/jobs/7`);
//! its `/moments` document is fetched over plain HTTP with timeouts and a size limit, then parsed
//! and verified (checksum, configuration) like an inline document.

use std::time::Duration;

use serde_json::Value;

use super::error::JobError;
use crate::sim::document::MomentsDocument;
use crate::sim::spec::SpecError;

/// Largest document accepted from a peer.
pub const MAX_PEER_DOCUMENT: usize = 1 << 30;

/// Where merged statistics come from.
pub enum Source {
    /// A document in the request, already verified.
    Document(Box<MomentsDocument>),
    /// The job at this URL on a peer server.
    Peer(String),
}

/// Reads a source: `{"from": "http://host:port/v1/jobs/ID"}` or a moments document. `field` is
/// the JSON path of the value, for error messages.
pub fn parse_source(value: &Value, field: &str) -> Result<Source, JobError> {
    let at = |name: &str| if field.is_empty() { name.to_string() } else { format!("{field}.{name}") };
    match value.as_object() {
        Some(object) if object.contains_key("from") => {
            if object.len() != 1 {
                return Err(SpecError::new(field, "a peer source has exactly one field, `from`").into());
            }
            let url = object["from"].as_str().ok_or_else(|| SpecError::new(at("from"), "must be a URL string"))?;
            peer_moments_url(url).map_err(|m| SpecError::new(at("from"), m))?;
            Ok(Source::Peer(url.to_string()))
        }
        Some(_) => Ok(Source::Document(Box::new(MomentsDocument::from_value(value)?))),
        None => Err(SpecError::new(field, "must be a moments document or {\"from\": URL}").into()),
    }
}

/// The `/moments` URL of a peer job URL, or why it is not one.
pub fn peer_moments_url(url: &str) -> Result<String, String> {
    let parsed = reqwest::Url::parse(url).map_err(|e| format!("not a URL ({e}): {url:?}"))?;
    match parsed.scheme() {
        "http" => {}
        "https" => return Err("https peers are not supported: this server speaks plain HTTP to peers".into()),
        other => return Err(format!("unsupported scheme {other:?}; expected http://host:port/v1/jobs/ID")),
    }
    if parsed.host_str().is_none() {
        return Err(format!("no host in {url:?}"));
    }
    let path = parsed.path().trim_end_matches('/');
    let segments: Vec<&str> = path.split('/').collect();
    let job_path = match segments.as_slice() {
        ["", "v1", "jobs", id] if id.parse::<i64>().is_ok() => format!("{path}/moments"),
        ["", "v1", "jobs", id, "moments"] if id.parse::<i64>().is_ok() => path.to_string(),
        _ => return Err(format!("expected the URL of a job, http://host:port/v1/jobs/ID, got {url:?}")),
    };
    let mut target = parsed.clone();
    target.set_path(&job_path);
    target.set_query(None);
    Ok(target.to_string())
}

/// An HTTP client for peers.
pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .connect_timeout(Duration::from_secs(10))
        .timeout(Duration::from_secs(600))
        .build()
        .expect("an HTTP client without TLS always builds")
}

/// Fetches the moments document of the job at `url` on a peer (unparsed bytes).
pub async fn pull(client: &reqwest::Client, url: &str) -> Result<Vec<u8>, JobError> {
    let target = peer_moments_url(url).map_err(|m| SpecError::new("from", m))?;
    let mut response =
        client.get(&target).send().await.map_err(|e| JobError::Peer(format!("cannot reach the peer {target}: {e}")))?;
    let status = response.status();
    if !status.is_success() {
        let body = response.text().await.unwrap_or_default();
        let detail = serde_json::from_str::<Value>(&body)
            .ok()
            .and_then(|p| p["detail"].as_str().map(str::to_string))
            .unwrap_or_else(|| body.chars().take(300).collect());
        return Err(JobError::Peer(format!("the peer {target} answered {status}: {detail}")));
    }
    let mut bytes = Vec::new();
    while let Some(chunk) =
        response.chunk().await.map_err(|e| JobError::Peer(format!("reading {target} failed: {e}")))?
    {
        if bytes.len() + chunk.len() > MAX_PEER_DOCUMENT {
            return Err(JobError::Peer(format!("the document at {target} exceeds {MAX_PEER_DOCUMENT} bytes")));
        }
        bytes.extend_from_slice(&chunk);
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peer_urls_point_at_a_jobs_moments() {
        assert_eq!(
            peer_moments_url("http://10.0.0.2:8080/v1/jobs/7").unwrap(),
            "http://10.0.0.2:8080/v1/jobs/7/moments"
        );
        assert_eq!(peer_moments_url("http://h:1/v1/jobs/7/").unwrap(), "http://h:1/v1/jobs/7/moments");
        assert_eq!(peer_moments_url("http://h/v1/jobs/7/moments").unwrap(), "http://h/v1/jobs/7/moments");
        for bad in
            ["https://h/v1/jobs/7", "ftp://h/v1/jobs/7", "http://h/v1/jobs", "http://h/v1/jobs/x", "h:1/v1/jobs/7", ""]
        {
            assert!(peer_moments_url(bad).is_err(), "{bad}");
        }
    }
}
