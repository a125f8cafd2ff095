//! Merges and studies: moments documents (sent, or pulled from allowed peers) added exactly to a
//! finished job's statistics, or gathered into a new finished job.
//!
//! Imports: crate::jobs::core, crate::jobs::statistics, crate::sim, crate::store, crate::trust
//!
//! Documents arrive as bytes and are parsed straight into typed values on the request pool
//! ([`sources`]), never through a generic JSON value and never on a tokio worker; peers are pulled
//! through the allow-list of [`peers`], each client within its share ([`shares`]). A merge holds
//! its target (`JobManager::hold`: extend and delete refuse it meanwhile) under the lifecycle
//! lock, then verifies and adds the statistics with the lock released, and takes the lock again
//! only to write: no other transition waits for its computation. Everything a merge computes goes
//! into a copy of the target's statistics, so a refused merge changes nothing.

pub mod peers;
pub mod shares;
pub mod sources;

use std::sync::Arc;
use std::time::Duration;

use futures_util::stream::{self, StreamExt, TryStreamExt};

use self::peers::{PULLS_PER_CLIENT, Peers};
use self::shares::ClientKey;
use self::sources::{Source, StudyBody, parse_merge_body, parse_study_body};
use super::core::checkpoint::{checkpoint_of, decode_checkpoint, spec_json};
use super::core::documents::JobResult;
use super::core::error::JobError;
use super::core::lineage::{MergeProvenance, SourceRecord};
use super::core::policy::check_budget;
use super::core::references::scene_reference;
use super::core::resource::{JobResource, JobState, now_ms, parse_stored_spec, resource_from_row};
use super::statistics::Statistics;
use crate::sim::configuration::explained;
use crate::sim::document::{DocumentError, MomentsDocument, merged_spec};
use crate::sim::spec::{JobSpec, SpecError};
use crate::sim::stats::moments::Moments;
use crate::store::{Checkpoint, NewJob};

/// Merges and studies; cheap to clone. It owns what only merges need: the peers they may pull
/// from, the keys merged documents are checked against, and the processing slots.
#[derive(Clone)]
pub struct Merges {
    /// The merged job's results, and the lifecycle (`Statistics::jobs`).
    statistics: Statistics,
    /// The allowed peers and the client that pulls from them.
    peers: Arc<Peers>,
    /// Merges and studies parsing or merging documents at once (`--max-document-requests`): each
    /// holds parsed documents. Taken only for that, never while a request waits on a peer.
    processing: Arc<tokio::sync::Semaphore>,
}

/// How long a merge or a study waits for a processing slot before it is told to retry.
const PROCESSING_WAIT: Duration = Duration::from_secs(10);

impl Merges {
    /// Merges and studies of the jobs `statistics` reads: they pull from `peers`, check
    /// documents with the statistics' keys (this server's and the `--trust` ones), and at most
    /// `processing` of them parse or merge documents at once.
    pub fn new(statistics: Statistics, peers: Peers, processing: usize) -> Self {
        Self {
            statistics,
            peers: Arc::new(peers),
            processing: Arc::new(tokio::sync::Semaphore::new(processing.max(1))),
        }
    }

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
        self.statistics.jobs().compute(f).await
    }

    /// The verified document of a source (pulled from its peer for `client` if it names one), and
    /// the trusted key that signed it, if one did.
    async fn fetch(&self, source: Source, client: ClientKey) -> Result<(MomentsDocument, Option<String>), JobError> {
        let (doc, field) = match source {
            Source::Document { doc, field } => (*doc, field),
            Source::Peer { url, field } => {
                // A pull waits on the network: a stopping server answers 503 at once instead of
                // holding the request (and its own exit) until the pull's deadline.
                let mut stopping = self.statistics.jobs().shutdown_signal();
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
        let signed_by = self.statistics.provenance.vouch(&doc, at)?;
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
            let _guard = self.statistics.jobs().transition().await;
            if self.statistics.jobs().active(id).is_some() {
                return Err(JobError::Conflict(format!(
                    "job {id} is queued or running; merge into it once it has finished, or cancel it first"
                )));
            }
            let row = self
                .statistics
                .jobs()
                .store()
                .jobs()
                .get(id)
                .await?
                .ok_or_else(|| JobError::NotFound(id.to_string()))?;
            if !matches!(row.state, JobState::Succeeded | JobState::Cancelled) {
                return Err(JobError::Conflict(format!(
                    "job {id} is {}; only a succeeded or cancelled job takes merges",
                    row.state
                )));
            }
            let reservation = self.statistics.jobs().hold(id)?;
            (row, reservation)
        };
        // Verify, merge and summarise with the lock released (the reservation keeps extend and
        // delete away), on the heavy pool (the summary re-fits), into a copy of the target's
        // statistics.
        let checkpoint = self.statistics.jobs().store().checkpoints().load(id).await?;
        let policy = self.statistics.jobs().policy().clone();
        let _slot = self.processing_slot().await?;
        let (checkpoint, spec, provenance) = self
            .statistics
            .jobs()
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
            let _guard = self.statistics.jobs().transition().await;
            self.statistics
                .jobs()
                .store()
                .checkpoints()
                .write_merged(id, &checkpoint, &spec, &provenance, now_ms())
                .await?;
        }
        self.statistics.result(id).await
    }

    /// Creates a finished job from several moments documents or peer jobs (a study, its body as
    /// bytes): their statistics merged, their results computed. `solver` optionally patches the
    /// solver options of the first source's spec. Peers are pulled at most [`PULLS_PER_CLIENT`]
    /// at a time (`client`'s share of the pulls) and each document is merged as it arrives (exact
    /// sums: the order does not change a bit), so memory holds a few documents, not all of them.
    /// A processing slot is held only while a document is parsed or merged.
    pub async fn create_study(&self, body: bytes::Bytes, client: ClientKey) -> Result<JobResource, JobError> {
        if self.statistics.jobs().is_shutting_down() {
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
        let deadline = self.statistics.jobs().policy().study_deadline;
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
        let policy = self.statistics.jobs().policy().clone();
        let _slot = self.processing_slot().await?;
        let (new, checkpoint) = self
            .statistics
            .jobs()
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
        let row = self.statistics.jobs().store().checkpoints().insert_study(&new, &checkpoint, &provenance).await?;
        resource_from_row(&row)
    }
}
