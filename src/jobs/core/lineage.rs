//! Where a merged job's statistics come from (`provenance` on the job resource): each source
//! merged — a peer job's URL, a document sent in the request, the job's own iterations — with the
//! seeds and iterations it brought, and every seed held. Written by merges and studies
//! (`merges`), stored with the job, shown by the API and the dashboard's list. (Not the signing
//! `Provenance` of `signing`, which is about whose key vouches for a document.)

use serde::{Deserialize, Serialize};

use crate::sim::document::{Attestation, AttestationBasis};
use utoipa::ToSchema;

/// Where a merged job's statistics come from: each source merged, in the order given (for a merge
/// into a job, its own iterations first), and every seed the statistics hold — so that a study
/// of seeds 1 and 2 says so, not only the first source's seed its spec keeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct MergeProvenance {
    /// Every source, in order.
    pub sources: Vec<SourceRecord>,
    /// Every seed the merged statistics hold, ascending.
    pub seeds: Vec<u64>,
}

/// One merged source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SourceRecord {
    /// Where it came from: a peer job's URL, `document` (sent in the request), or `job N` (the
    /// merged job's own iterations, before its first merge).
    pub from: String,
    /// The seeds it brought, ascending.
    pub seeds: Vec<u64>,
    /// The iterations it brought.
    pub iterations: u64,
    /// Whether this server computed them (the job's own iterations).
    #[serde(default)]
    pub computed_here: bool,
    /// The key — one this server trusts, or its own — whose valid signature the source carried
    /// when it was merged; none for an unsigned source or one no trusted key signed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signed_by: Option<String>,
}

impl SourceRecord {
    /// A source that brought the iterations of `coverage`, signed by `signed_by` (a trusted key).
    pub fn new(
        from: impl Into<String>,
        coverage: &crate::sim::stats::coverage::Coverage,
        signed_by: Option<String>,
    ) -> Self {
        Self {
            from: from.into(),
            seeds: coverage.seeds().iter().map(|s| s.seed).collect(),
            iterations: u64::try_from(coverage.iterations()).unwrap_or(u64::MAX),
            computed_here: false,
            signed_by,
        }
    }

    /// Job `id`'s own iterations, computed by this server.
    pub fn own(id: i64, coverage: &crate::sim::stats::coverage::Coverage) -> Self {
        Self { computed_here: true, ..Self::new(format!("job {id}"), coverage, None) }
    }

    /// Whether this server can vouch for the source: it computed it, or a key it trusts signed
    /// it. (A record stored before these fields existed vouches for the job's own iterations,
    /// `job N`, only.)
    fn vouched(&self) -> bool {
        self.computed_here || self.signed_by.is_some() || self.from.starts_with("job ")
    }
}

impl MergeProvenance {
    /// The record of `sources` (in order), with every seed among them.
    pub fn of(sources: Vec<SourceRecord>) -> Self {
        let mut seeds: Vec<u64> = sources.iter().flat_map(|s| s.seeds.iter().copied()).collect();
        seeds.sort_unstable();
        seeds.dedup();
        Self { sources, seeds }
    }

    /// What this server's signature on the merged statistics may vouch for: merged from sources
    /// it computed or trusted keys signed (those keys); none if any source is neither — such
    /// statistics are exported unsigned, so that a signature never launders a document sent to
    /// the server.
    pub fn attestation(&self) -> Option<Attestation> {
        if !self.sources.iter().all(SourceRecord::vouched) {
            return None;
        }
        let mut keys: Vec<String> = self.sources.iter().filter_map(|s| s.signed_by.clone()).collect();
        keys.sort_unstable();
        keys.dedup();
        Some(Attestation { basis: AttestationBasis::Merged, keys })
    }

    /// As stored (JSON).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a provenance always serialises")
    }
}
