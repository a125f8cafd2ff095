//! Where a merged job's statistics come from (`provenance` on the job resource): each source
//! merged — a peer job's URL, a document sent in the request, the job's own iterations — with the
//! seeds and iterations it brought, and every seed held. Written by merges and studies
//! (`merges`), stored with the job, shown by the API and the dashboard's list. (Not the signing
//! `Provenance` of `signing`, which is about whose key vouches for a document.)

use serde::{Deserialize, Serialize};
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
}

impl SourceRecord {
    /// A source that brought the iterations of `coverage`.
    pub fn new(from: impl Into<String>, coverage: &crate::sim::stats::coverage::Coverage) -> Self {
        Self {
            from: from.into(),
            seeds: coverage.seeds().iter().map(|s| s.seed).collect(),
            iterations: u64::try_from(coverage.iterations()).unwrap_or(u64::MAX),
        }
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

    /// As stored (JSON).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a provenance always serialises")
    }
}
