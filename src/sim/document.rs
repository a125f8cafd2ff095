//! The portable moments document: a run's statistics as one versioned, checksummed JSON value that
//! can travel between machines (files, HTTP) and be merged without double counting.
//!
//! ```json
//! { "kind": "optimis-moments", "format_version": 1, "fingerprint": "…", "coverage": […],
//!   "spec": {…}, "moments": {…}, "checksum": "sha256 hex" }
//! ```
//!
//! `checksum` is the SHA-256 of the canonical JSON of every other field, in the order above.
//! Canonical JSON is what this module writes: fields in declaration order, no whitespace, floats
//! in shortest round-trip form, exact sums in canonical form; and parsing is exact
//! (serde_json's `float_roundtrip`), so a document re-serialises to the very bytes it was written
//! from and any change of content — one digit — breaks the checksum. `fingerprint` and `coverage`
//! repeat the moments' own, for people and tools reading the file; they must agree.

use serde::{Deserialize, Serialize};

use super::config::sha256_hex;
use super::coverage::Coverage;
use super::moments::{MergeError, Moments};
use super::spec::JobSpec;

/// The `kind` of every moments document.
pub const DOCUMENT_KIND: &str = "optimis-moments";

/// Version of the document layout.
pub const DOCUMENT_VERSION: u32 = 1;

/// A moments document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct MomentsDocument {
    /// Always `optimis-moments`.
    pub kind: String,
    /// Layout version (1).
    pub format_version: u32,
    /// Configuration fingerprint of the moments.
    pub fingerprint: String,
    /// The (seed, iteration range) pairs the moments hold.
    pub coverage: Coverage,
    /// The job specification the iterations were drawn under (for a merge, the first document's
    /// with `iterations` set to the total covered and no shard).
    pub spec: JobSpec,
    pub moments: Moments,
    /// SHA-256 (hex) of the canonical JSON of all other fields.
    pub checksum: String,
}

/// The checksummed part, in document order.
#[derive(Serialize)]
struct Body<'a> {
    kind: &'a str,
    format_version: u32,
    fingerprint: &'a str,
    coverage: &'a Coverage,
    spec: &'a JobSpec,
    moments: &'a Moments,
}

/// Why a document cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DocumentError {
    #[error("not a moments document: {0}")]
    Unreadable(String),
    #[error("not a moments document: kind {0:?}, expected \"optimis-moments\"")]
    Kind(String),
    #[error("moments document version {0} is not supported (this build reads version {DOCUMENT_VERSION})")]
    Version(u32),
    #[error("the document's checksum does not match its content: it was corrupted or edited")]
    Checksum,
    #[error("the document is inconsistent: {0}")]
    Inconsistent(String),
    #[error(transparent)]
    Merge(#[from] MergeError),
}

fn checksum_of(body: &Body<'_>) -> String {
    sha256_hex(&serde_json::to_vec(body).expect("a document body always serialises"))
}

impl MomentsDocument {
    /// Wraps moments drawn under `spec`.
    pub fn new(spec: JobSpec, moments: Moments) -> Self {
        let mut doc = Self {
            kind: DOCUMENT_KIND.into(),
            format_version: DOCUMENT_VERSION,
            fingerprint: moments.fingerprint.clone(),
            coverage: moments.coverage.clone(),
            spec,
            moments,
            checksum: String::new(),
        };
        doc.checksum = checksum_of(&doc.body());
        doc
    }

    fn body(&self) -> Body<'_> {
        Body {
            kind: &self.kind,
            format_version: self.format_version,
            fingerprint: &self.fingerprint,
            coverage: &self.coverage,
            spec: &self.spec,
            moments: &self.moments,
        }
    }

    /// Checks kind, version, checksum and internal consistency (moments well formed, matching the
    /// spec's configuration, the repeated fingerprint and coverage).
    pub fn verify(&self) -> Result<(), DocumentError> {
        if self.kind != DOCUMENT_KIND {
            return Err(DocumentError::Kind(self.kind.clone()));
        }
        if self.format_version != DOCUMENT_VERSION {
            return Err(DocumentError::Version(self.format_version));
        }
        if checksum_of(&self.body()) != self.checksum {
            return Err(DocumentError::Checksum);
        }
        self.moments.check_well_formed()?;
        if self.fingerprint != self.moments.fingerprint || self.coverage != self.moments.coverage {
            return Err(DocumentError::Inconsistent("fingerprint or coverage differ from the moments'".into()));
        }
        let job = self.spec.validate().map_err(|e| DocumentError::Inconsistent(format!("invalid spec: {e}")))?;
        if job.config.fingerprint() != self.fingerprint {
            return Err(DocumentError::Inconsistent("the spec does not describe the moments' configuration".into()));
        }
        Ok(())
    }

    /// Parses and verifies a document from JSON text.
    pub fn from_json(bytes: &[u8]) -> Result<Self, DocumentError> {
        let doc: Self = serde_json::from_slice(bytes).map_err(|e| DocumentError::Unreadable(e.to_string()))?;
        doc.verify()?;
        Ok(doc)
    }

    /// Parses and verifies a document from a JSON value.
    pub fn from_value(value: &serde_json::Value) -> Result<Self, DocumentError> {
        let doc: Self = serde_path_to_error::deserialize(value)
            .map_err(|e| DocumentError::Unreadable(format!("{}: {}", e.path(), e.inner())))?;
        doc.verify()?;
        Ok(doc)
    }

    /// The canonical JSON text of the document.
    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec(self).expect("a document always serialises")
    }
}

/// Merges verified documents: one configuration, disjoint coverage, exact sums. The result's spec
/// is the first document's with `iterations` set to the total covered and no shard or first
/// iteration; nothing is merged if any document conflicts with the others.
pub fn merge_documents(documents: &[MomentsDocument]) -> Result<MomentsDocument, DocumentError> {
    let (first, rest) =
        documents.split_first().ok_or_else(|| DocumentError::Inconsistent("nothing to merge".into()))?;
    let mut moments = first.moments.clone();
    for doc in rest {
        moments.merge(&doc.moments)?;
    }
    let mut spec = first.spec.clone();
    spec.iterations = moments.iterations().max(1);
    spec.shard = None;
    spec.first_iteration = None;
    Ok(MomentsDocument::new(spec, moments))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::runner::run;
    use crate::sim::spec::parse_job_spec;
    use serde_json::json;

    fn shard(k: u64, n: u64) -> MomentsDocument {
        let spec = parse_job_spec(&json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": 0.02,
            "iterations": 6, "seed": 2, "shard": { "index": k, "count": n } }))
        .unwrap();
        let job = spec.validate().unwrap();
        let moments = run(&job.config, spec.seed, spec.iteration_range());
        MomentsDocument::new(spec, moments)
    }

    #[test]
    fn documents_round_trip_and_detect_changes() {
        let doc = shard(0, 2);
        let bytes = doc.to_json();
        let back = MomentsDocument::from_json(&bytes).unwrap();
        assert_eq!(back, doc);
        assert_eq!(back.to_json(), bytes, "re-serialisation is byte for byte");
        // Change one digit of a number inside the moments.
        let text = String::from_utf8(bytes.clone()).unwrap();
        let at = text.find("\"sum_y\":[").unwrap() + 200;
        let pos = text[at..].find(|c: char| c.is_ascii_digit() && c != '0').unwrap() + at;
        let mut corrupted = bytes.clone();
        corrupted[pos] = if corrupted[pos] == b'9' { b'8' } else { corrupted[pos] + 1 };
        assert!(matches!(
            MomentsDocument::from_json(&corrupted),
            Err(DocumentError::Checksum | DocumentError::Unreadable(_))
        ));
        assert!(matches!(MomentsDocument::from_json(&bytes[..bytes.len() / 2]), Err(DocumentError::Unreadable(_))));
        let mut wrong_kind = doc.clone();
        wrong_kind.kind = "something".into();
        assert!(matches!(wrong_kind.verify(), Err(DocumentError::Kind(_))));
    }

    #[test]
    fn shards_merge_into_the_whole_run() {
        let whole = {
            let spec = parse_job_spec(&json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": 0.02,
                "iterations": 6, "seed": 2 }))
            .unwrap();
            run(&spec.validate().unwrap().config, 2, 0..6)
        };
        let merged = merge_documents(&[shard(1, 3), shard(0, 3), shard(2, 3)]).unwrap();
        merged.verify().unwrap();
        assert_eq!(merged.moments, whole);
        assert_eq!(merged.spec.iterations, 6);
        assert_eq!(merged.spec.shard, None);
        assert!(matches!(
            merge_documents(&[shard(0, 2), shard(0, 2)]),
            Err(DocumentError::Merge(MergeError::Overlap(_)))
        ));
    }
}
