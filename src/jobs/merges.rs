//! Merges and studies: moments documents (sent, or pulled from allowed peers) added exactly to a
//! finished job's statistics, or gathered into a new finished job.
//!
//! Documents arrive as bytes and are parsed straight into typed values on the request pool
//! ([`parse_merge_body`], [`parse_study_body`]), never through a generic JSON value and never on a
//! tokio worker; peers are pulled through the allow-list of [`super::peers`]. A merge holds its
//! target (`toolbox`: extend and delete refuse it meanwhile) under the lifecycle lock, then
//! verifies and adds the statistics with the lock released, and takes the lock again only to
//! write: no other transition waits for its computation. Everything a merge computes goes into a
//! copy of the target's statistics, so a refused merge changes nothing.

use std::time::Duration;

use futures_util::stream::{self, StreamExt, TryStreamExt};
use serde::Deserialize;
use serde_json::Value;

use super::checkpoint::{checkpoint_of, decode_checkpoint, spec_json};
use super::documents::JobResult;
use super::error::JobError;
use super::lineage::{MergeProvenance, SourceRecord};
use super::peers::PULLS_PER_CLIENT;
use super::policy::check_budget;
use super::references::scene_reference;
use super::resource::{JobResource, JobState, now_ms, parse_stored_spec, resource_from_row};
use super::shares::ClientKey;
use super::statistics::Statistics;
use crate::sim::configuration::explained;
use crate::sim::document::{DocumentError, DocumentSignature, MomentsDocument, merged_spec, parse_json};
use crate::sim::spec::{JobSpec, SpecError};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;
use crate::store::{Checkpoint, NewJob};

/// Most sources of one study.
pub const MAX_STUDY_SOURCES: usize = 256;

/// A merge source as sent: `{"from": URL}` or the fields of a moments document. Deserialised
/// field by field (an untagged enum would first copy the whole document into a generic value).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SourceFields {
    from: Option<String>,
    kind: Option<String>,
    format_version: Option<u32>,
    fingerprint: Option<String>,
    coverage: Option<Coverage>,
    spec: Option<JobSpec>,
    moments: Option<Moments>,
    checksum: Option<String>,
    signature: Option<DocumentSignature>,
}

/// Where merged statistics come from.
pub enum Source {
    /// A document in the request, verified; `field` is its JSON path (empty for a merge's body).
    Document {
        /// The moments document, its checksum and consistency already verified (its signature is
        /// checked against `--trust` when it is merged).
        doc: Box<MomentsDocument>,
        /// JSON path of the document in the request (`sources[2]`; empty for a merge's body).
        field: String,
    },
    /// The job at this URL on a peer server; `field` is the JSON path of the URL.
    Peer {
        /// The job's URL on the peer, as sent in `from`; it must lie under an allowed `--peer`.
        url: String,
        /// JSON path of the `from` that named it (`sources[2].from`, or `from` for a merge).
        field: String,
    },
}

impl Source {
    /// How the source is recorded in the merged job's provenance: the peer job's URL, or
    /// `document` (or `document sources[2]` in a study).
    pub fn label(&self) -> String {
        match self {
            Source::Peer { url, .. } => url.clone(),
            Source::Document { field, .. } if field.is_empty() => "document".to_string(),
            Source::Document { field, .. } => format!("document {field}"),
        }
    }
}

impl SourceFields {
    /// The source, with an inline document verified. `at` is the JSON path of the source.
    fn into_source(self, at: &str) -> Result<Source, JobError> {
        let field = |name: &str| if at.is_empty() { name.to_string() } else { format!("{at}.{name}") };
        if let Some(url) = self.from {
            let others = [
                self.kind.is_some(),
                self.format_version.is_some(),
                self.fingerprint.is_some(),
                self.coverage.is_some(),
                self.spec.is_some(),
                self.moments.is_some(),
                self.checksum.is_some(),
                self.signature.is_some(),
            ];
            if others.iter().any(|&x| x) {
                return Err(SpecError::new(at, "a peer source has exactly one field, `from`").into());
            }
            return Ok(Source::Peer { url, field: field("from") });
        }
        let missing = |name: &str| SpecError::new(field(name), "missing field of a moments document (or give `from`)");
        let doc = MomentsDocument {
            kind: self.kind.ok_or_else(|| missing("kind"))?,
            format_version: self.format_version.ok_or_else(|| missing("format_version"))?,
            fingerprint: self.fingerprint.ok_or_else(|| missing("fingerprint"))?,
            coverage: self.coverage.ok_or_else(|| missing("coverage"))?,
            spec: self.spec.ok_or_else(|| missing("spec"))?,
            moments: self.moments.ok_or_else(|| missing("moments"))?,
            checksum: self.checksum.ok_or_else(|| missing("checksum"))?,
            signature: self.signature,
        };
        doc.verify()?;
        Ok(Source::Document { doc: Box::new(doc), field: at.to_string() })
    }
}

/// A JSON parse error: 400 for text that is not JSON, 422 naming the field for JSON of the wrong
/// shape.
fn parse_error(bytes: &[u8], message: String) -> JobError {
    match serde_json::from_slice::<serde::de::IgnoredAny>(bytes) {
        Err(e) if e.is_syntax() || e.is_eof() => {
            JobError::Malformed(format!("the request body is not valid JSON: {e}"))
        }
        _ => {
            let (field, message) = match message.split_once(": ") {
                Some((path, rest)) if !path.contains(' ') => (path.to_string(), rest.to_string()),
                _ => (String::new(), message),
            };
            SpecError::new(field, message).into()
        }
    }
}

/// Parses the body of `POST /v1/jobs/{id}/merge` (CPU work: on the request pool).
pub fn parse_merge_body(bytes: &[u8]) -> Result<Source, JobError> {
    let fields: SourceFields = parse_json(bytes).map_err(|m| parse_error(bytes, m))?;
    fields.into_source("")
}

/// The body of `POST /v1/studies`, parsed.
pub struct StudyBody {
    /// The sources to merge, 1 to [`MAX_STUDY_SOURCES`], inline documents already verified.
    pub sources: Vec<Source>,
    /// A merge patch on the solver options of the first source's spec; none keeps them.
    pub solver: Option<Value>,
}

/// Parses the body of `POST /v1/studies` (CPU work: on the request pool).
pub fn parse_study_body(bytes: &[u8]) -> Result<StudyBody, JobError> {
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Raw {
        sources: Vec<SourceFields>,
        solver: Option<Value>,
    }
    let raw: Raw = parse_json(bytes).map_err(|m| parse_error(bytes, m))?;
    if !(1..=MAX_STUDY_SOURCES).contains(&raw.sources.len()) {
        return Err(SpecError::new(
            "sources",
            format!("must list 1 to {MAX_STUDY_SOURCES} sources, got {}", raw.sources.len()),
        )
        .into());
    }
    let sources = raw
        .sources
        .into_iter()
        .enumerate()
        .map(|(i, s)| s.into_source(&format!("sources[{i}]")))
        .collect::<Result<_, _>>()?;
    Ok(StudyBody { sources, solver: raw.solver })
}

/// How long a merge or a study waits for a processing slot before it is told to retry.
const PROCESSING_WAIT: Duration = Duration::from_secs(10);

impl Statistics {
    /// One of the few processing slots (`--max-document-requests`), for parsing or merging: 429
    /// after [`PROCESSING_WAIT`].
    async fn processing_slot(&self) -> Result<tokio::sync::SemaphorePermit<'_>, JobError> {
        match tokio::time::timeout(PROCESSING_WAIT, self.processing.acquire()).await {
            Ok(permit) => permit.map_err(|_| JobError::ShuttingDown),
            Err(_) => Err(JobError::Busy {
                detail: "the server is busy with other documents (--max-document-requests); retry".into(),
                retry_after_seconds: 5,
            }),
        }
    }

    /// Light work on parsed documents, under a processing slot.
    async fn process<T: Send + 'static>(&self, f: impl FnOnce() -> T + Send + 'static) -> Result<T, JobError> {
        let _slot = self.processing_slot().await?;
        self.jobs.compute(f).await
    }

    /// The verified document of a source (pulled from its peer for `client` if it names one), and
    /// the trusted key that signed it, if one did.
    async fn fetch(&self, source: Source, client: ClientKey) -> Result<(MomentsDocument, Option<String>), JobError> {
        let (doc, field) = match source {
            Source::Document { doc, field } => (*doc, field),
            Source::Peer { url, field } => {
                // A pull waits on the network: a stopping server answers 503 at once instead of
                // holding the request (and its own exit) until the pull's deadline.
                let mut stopping = self.jobs.shutdown_signal();
                let bytes = tokio::select! {
                    pulled = self.peers.pull(&url, &field, client) => pulled?,
                    _ = stopping.wait_for(|&s| s) => return Err(JobError::ShuttingDown),
                };
                let doc = self.process(move || MomentsDocument::from_json(&bytes)).await?;
                let doc = doc.map_err(|e| JobError::Peer {
                    field: field.clone(),
                    message: format!("the peer {url} sent an unusable document: {e}"),
                })?;
                (doc, field)
            }
        };
        // With --trust, only documents signed by a trusted key (checked after the checksum, which
        // the signature covers, was recomputed from the content).
        let at = field.strip_suffix(".from").or_else(|| field.strip_suffix("from")).unwrap_or(&field);
        let signed_by = self.provenance.vouch(&doc, at)?;
        Ok((doc, signed_by))
    }

    /// Checks, without a connection, that every peer source is allowed (so that a study with one
    /// forbidden source pulls nothing).
    fn check_peers(&self, sources: &[Source]) -> Result<(), JobError> {
        for source in sources {
            if let Source::Peer { url, field } = source {
                self.peers.resolve(url, field)?;
            }
        }
        Ok(())
    }

    /// Merges a moments document (its bytes: a document, or `{"from": URL}` of a peer's job) into
    /// a finished job's statistics and recomputes its results. Refused, with nothing changed, if
    /// the job is active or taking another merge, the configuration differs, any iteration would be
    /// counted twice, a sum would overflow, or the result exceeds the server's job budget.
    pub async fn merge_into(&self, id: i64, body: bytes::Bytes, client: ClientKey) -> Result<JobResult, JobError> {
        let source = self.process(move || parse_merge_body(&body)).await??;
        self.check_peers(std::slice::from_ref(&source))?;
        let from = source.label();
        let (doc, signed_by) = self.fetch(source, client).await?;
        // Reserve the job: a short critical section (state checks only).
        let (row, _reservation) = {
            let _guard = self.jobs.transition().await;
            if self.jobs.active(id).is_some() {
                return Err(JobError::Conflict(format!(
                    "job {id} is queued or running; merge into it once it has finished, or cancel it first"
                )));
            }
            let row = self.jobs.store().get_job(id).await?.ok_or_else(|| JobError::NotFound(id.to_string()))?;
            if !matches!(row.state, JobState::Succeeded | JobState::Cancelled) {
                return Err(JobError::Conflict(format!(
                    "job {id} is {}; only a succeeded or cancelled job takes merges",
                    row.state
                )));
            }
            let reservation = self.jobs.hold(id)?;
            (row, reservation)
        };
        // Verify, merge and summarise with the lock released (the reservation keeps extend and
        // delete away), on the heavy pool (the summary re-fits), into a copy of the target's
        // statistics.
        let checkpoint = self.jobs.store().load_checkpoint(id).await?;
        let policy = self.jobs.policy().clone();
        let _slot = self.processing_slot().await?;
        let (checkpoint, spec, provenance) = self
            .jobs
            .compute_heavy(move |_| -> Result<(Checkpoint, String, String), JobError> {
                let spec = parse_stored_spec(&row)?;
                let job = spec.validate()?;
                let mut moments = match checkpoint {
                    Some(checkpoint) => decode_checkpoint(id, &checkpoint, &job, !row.merged)?,
                    None => Moments::new(job.config()),
                };
                // The sources so far (the job's own iterations, before its first merge), then this one.
                let earlier: Option<MergeProvenance> =
                    row.provenance.as_deref().and_then(|p| serde_json::from_str(p).ok());
                let mut sources = match earlier {
                    Some(p) => p.sources,
                    None if moments.iterations() > 0 => vec![SourceRecord::own(id, &moments.coverage)],
                    None => Vec::new(),
                };
                sources.push(SourceRecord::new(from, &doc.moments.coverage, signed_by));
                moments.merge(&doc.moments).map_err(|e| DocumentError::from(explained(e, &doc.spec, &spec)))?;
                moments.check_bounded().map_err(DocumentError::from)?;
                let spec = merged_spec(&spec, &moments);
                check_budget(&policy, &spec, moments.iterations())?;
                let checkpoint = checkpoint_of(&moments, &job, row.reference_luminance)?;
                Ok((checkpoint, spec_json(&spec)?, MergeProvenance::of(sources).to_json()))
            })
            .await??;
        {
            let _guard = self.jobs.transition().await;
            self.jobs.store().write_merged(id, &checkpoint, &spec, &provenance, now_ms()).await?;
        }
        self.result(id).await
    }

    /// Creates a finished job from several moments documents or peer jobs (a study, its body as
    /// bytes): their statistics merged, their results computed. `solver` optionally patches the
    /// solver options of the first source's spec. Peers are pulled at most [`PULLS_PER_CLIENT`]
    /// at a time (`client`'s share of the pulls) and each document is merged as it arrives (exact
    /// sums: the order does not change a bit), so memory holds a few documents, not all of them.
    /// A processing slot is held only while a document is parsed or merged.
    pub async fn create_study(&self, body: bytes::Bytes, client: ClientKey) -> Result<JobResource, JobError> {
        if self.jobs.is_shutting_down() {
            return Err(JobError::ShuttingDown);
        }
        let StudyBody { sources, solver } = self.process(move || parse_study_body(&body)).await??;
        self.check_peers(&sources)?;
        let labels: Vec<String> = sources.iter().map(Source::label).collect();
        let arrivals = stream::iter(sources.into_iter().enumerate())
            .map(|(i, source)| async move { self.fetch(source, client).await.map(|(doc, by)| (i, doc, by)) })
            .buffer_unordered(PULLS_PER_CLIENT);
        let gather = async {
            let mut first: Option<(usize, JobSpec)> = None;
            // The spec of the first document to arrive: what a refused merge names differences
            // against (the sum so far is of its configuration).
            let mut arrived: Option<JobSpec> = None;
            let mut total: Option<Moments> = None;
            let mut records: Vec<(usize, SourceRecord)> = Vec::new();
            let mut arrivals = std::pin::pin!(arrivals);
            while let Some((i, doc, signed_by)) = arrivals.try_next().await? {
                records.push((i, SourceRecord::new(labels[i].clone(), &doc.moments.coverage, signed_by)));
                if first.as_ref().is_none_or(|(j, _)| i < *j) {
                    first = Some((i, doc.spec.clone()));
                }
                total = Some(match total {
                    None => {
                        arrived = Some(doc.spec.clone());
                        doc.moments
                    }
                    Some(mut acc) => {
                        let into = arrived.clone().unwrap_or_else(|| doc.spec.clone());
                        self.process(move || {
                            acc.merge(&doc.moments).map_err(|e| explained(e, &doc.spec, &into))?;
                            Ok::<_, crate::sim::stats::moments::MergeError>(acc)
                        })
                        .await?
                        .map_err(DocumentError::from)?
                    }
                });
            }
            records.sort_by_key(|(i, _)| *i);
            Ok::<_, JobError>((first, total, records))
        };
        // The whole gathering is bounded (each pull is too, but a study of many slow sources
        // would otherwise hold its request for the sum of their deadlines).
        let deadline = self.jobs.policy().study_deadline;
        let (first, total, records) = tokio::time::timeout(deadline, gather).await.map_err(|_| JobError::Peer {
            field: "sources".into(),
            message: format!(
                "the sources did not all arrive and merge within the study deadline of {} s (--study-deadline); \
                 nothing was created",
                deadline.as_secs_f64()
            ),
        })??;
        let (Some((_, base)), Some(moments)) = (first, total) else {
            return Err(SpecError::new("sources", "must list at least one source").into());
        };
        let policy = self.jobs.policy().clone();
        let _slot = self.processing_slot().await?;
        let (new, checkpoint) = self
            .jobs
            .compute_heavy(move |_| -> Result<(NewJob, Checkpoint), JobError> {
                moments.check_bounded().map_err(DocumentError::from)?;
                let mut spec = merged_spec(&base, &moments);
                if let Some(patch) = &solver {
                    spec.solver = spec.solver.patched(patch)?;
                }
                let job = spec.validate()?;
                check_budget(&policy, job.spec(), moments.iterations())?;
                let reference = scene_reference(&job.config().scene);
                let checkpoint = checkpoint_of(&moments, &job, reference)?;
                let new = NewJob {
                    spec: spec_json(job.spec())?,
                    fingerprint: job.config().fingerprint().to_string(),
                    iterations_total: checkpoint.iterations_done,
                    reference_luminance: reference,
                    idempotency_key: None,
                    request_hash: None,
                    now: now_ms(),
                };
                Ok((new, checkpoint))
            })
            .await??;
        let provenance = MergeProvenance::of(records.into_iter().map(|(_, r)| r).collect()).to_json();
        let row = self.jobs.store().insert_study(&new, &checkpoint, &provenance).await?;
        resource_from_row(&row)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_are_parsed_field_by_field() {
        let peer = parse_merge_body(br#"{"from": "http://h:1/v1/jobs/2"}"#).unwrap();
        assert!(matches!(peer, Source::Peer { url, field } if url == "http://h:1/v1/jobs/2" && field == "from"));
        let mixed = parse_merge_body(br#"{"from": "http://h:1/v1/jobs/2", "kind": "optimis-moments"}"#);
        assert!(matches!(mixed, Err(JobError::Invalid(e)) if e.message.contains("exactly one field")));
        assert!(matches!(parse_merge_body(b"{\"from\": "), Err(JobError::Malformed(_))));
        assert!(matches!(parse_merge_body(b"[1, 2]"), Err(JobError::Invalid(_))));
        let missing = parse_merge_body(br#"{"kind": "optimis-moments"}"#);
        assert!(matches!(missing, Err(JobError::Invalid(e)) if e.field == "format_version"), "names the field");
        let unknown = parse_merge_body(br#"{"fromm": 1}"#);
        assert!(matches!(unknown, Err(JobError::Invalid(e)) if e.message.contains("fromm")));
        let study = parse_study_body(br#"{"sources": [{"from": "http://h:1/v1/jobs/2"}, {"kind": "x"}]}"#);
        assert!(matches!(study, Err(JobError::Invalid(e)) if e.field == "sources[1].format_version"));
        let empty = parse_study_body(br#"{"sources": []}"#);
        assert!(matches!(empty, Err(JobError::Invalid(e)) if e.field == "sources"));
    }
}
