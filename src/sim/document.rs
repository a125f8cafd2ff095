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
//!
//! The checksum is *integrity*, not *authenticity*: it is a plain SHA-256 that anyone can
//! recompute, so it catches corruption and accidental edits, never a forgery. A document is
//! therefore treated as hostile input whatever its checksum says: it is parsed straight into typed
//! values with bounded lists ([`MomentsDocument::from_json`]) and [`MomentsDocument::verify`]
//! checks that its spec, coverage and sums agree with each other before anything uses it. Trust
//! in where a document comes from belongs to the transport (a bearer token to an allowed peer over
//! https).

use serde::{Deserialize, Serialize};

pub use super::signature::{
    ATTESTED_SIGNATURE_DOMAIN, Attestation, AttestationBasis, DocumentSignature, SIGNATURE_DOMAIN,
};

use super::configuration::explained;
use super::spec::JobSpec;
use crate::sim::math::digest::sha256_hex;
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::{MergeError, Moments};
use crate::sim::stats::well_formed::{belongs_to, check_well_formed};

/// The `kind` of every moments document.
pub const DOCUMENT_KIND: &str = "optimis-moments";

/// Version of the document layout.
pub const DOCUMENT_VERSION: u32 = 1;

/// A moments document: a run's statistics, their configuration and coverage, with a SHA-256
/// checksum. The checksum is integrity, not authenticity — anyone can recompute it — so a server
/// checks every document's internal consistency whatever its checksum, and trusts where a document
/// comes from only through the transport (an allowed peer, its token, https).
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
    /// The statistics themselves: the exact sums of the moment vectors over the covered iterations.
    pub moments: Moments,
    /// SHA-256 (hex) of the canonical JSON of the fields above: detects corruption, not forgery.
    pub checksum: String,
    /// Who vouches for the document: a signature over its checksum by a server's signing key
    /// (`--signing-key`), if the server that exported it has one. Outside the checksummed body by
    /// construction; it binds the content through the checksum, which a reader recomputes from the
    /// content before it checks the signature.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signature: Option<DocumentSignature>,
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
    /// The bytes do not parse as a document (not JSON, a missing or unknown field, a list too
    /// long); the text names the JSON path of the first error.
    #[error("not a moments document: {0}")]
    Unreadable(String),
    /// The `kind` is not [`DOCUMENT_KIND`].
    #[error("not a moments document: kind {0:?}, expected \"optimis-moments\"")]
    Kind(String),
    /// The `format_version` is not [`DOCUMENT_VERSION`].
    #[error("moments document version {0} is not supported (this build reads version {DOCUMENT_VERSION})")]
    Version(u32),
    /// The checksum is not that of the document's body.
    #[error("the document's checksum does not match its content: it was corrupted or edited")]
    Checksum,
    /// The parts disagree: the fingerprint or coverage with the moments', the spec with the
    /// configuration or the coverage, or the spec is invalid; or there is nothing to merge.
    #[error("the document is inconsistent: {0}")]
    Inconsistent(String),
    /// The moments cover no iteration.
    #[error("the document holds no iterations")]
    Empty,
    /// The moments are malformed, or cannot be merged with another document's.
    #[error(transparent)]
    Merge(#[from] MergeError),
}

/// Parses JSON text straight into `T`, naming the path of the first error (`moments.folds[0]…`)
/// and refusing trailing text.
pub fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let mut deserializer = serde_json::Deserializer::from_slice(bytes);
    let value: T = serde_path_to_error::deserialize(&mut deserializer).map_err(|e| {
        let path = e.path().to_string();
        if path == "." { e.inner().to_string() } else { format!("{path}: {}", e.inner()) }
    })?;
    deserializer.end().map_err(|e| e.to_string())?;
    Ok(value)
}

fn checksum_of(body: &Body<'_>) -> String {
    sha256_hex(&serde_json::to_vec(body).expect("a document body always serialises"))
}

impl MomentsDocument {
    /// Wraps moments drawn under `spec`. The spec's `execution` (how a server divided the work)
    /// is dropped: the statistics do not depend on it, so documents of one job run any way are
    /// the same bytes.
    pub fn new(mut spec: JobSpec, moments: Moments) -> Self {
        spec.execution = None;
        let mut doc = Self {
            kind: DOCUMENT_KIND.into(),
            format_version: DOCUMENT_VERSION,
            fingerprint: moments.fingerprint.clone(),
            coverage: moments.coverage.clone(),
            spec,
            moments,
            checksum: String::new(),
            signature: None,
        };
        doc.checksum = checksum_of(&doc.body());
        doc
    }

    /// The bytes a signature covers: a domain tag and the checksum. The checksum is recomputed
    /// from the content whenever a document is read ([`MomentsDocument::verify`]), so a signature
    /// over it vouches for the content, and any edit — re-sealed or not — breaks it.
    pub fn signed_message(&self) -> Vec<u8> {
        self.signed_message_with(self.signature.as_ref().and_then(|s| s.attests.as_ref()))
    }

    /// The bytes a signature with the attestation `attests` covers: with one, the checksum and
    /// the attestation's JSON behind their own domain tag, so that neither can be changed alone.
    pub fn signed_message_with(&self, attests: Option<&Attestation>) -> Vec<u8> {
        match attests {
            None => [SIGNATURE_DOMAIN, self.checksum.as_bytes()].concat(),
            Some(a) => {
                let json = serde_json::to_vec(a).expect("an attestation serialises");
                [ATTESTED_SIGNATURE_DOMAIN, self.checksum.as_bytes(), b"\n", &json].concat()
            }
        }
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
        check_well_formed(&self.moments)?;
        if self.fingerprint != self.moments.fingerprint || self.coverage != self.moments.coverage {
            return Err(DocumentError::Inconsistent("fingerprint or coverage differ from the moments'".into()));
        }
        let job = self.spec.validate().map_err(|e| DocumentError::Inconsistent(format!("invalid spec: {e}")))?;
        // A document an earlier build wrote carries its format's fingerprint.
        if !belongs_to(&self.moments, job.config()) {
            return Err(DocumentError::Inconsistent("the spec does not describe the moments' configuration".into()));
        }
        self.check_spec_covers()?;
        if self.moments.iterations() == 0 {
            return Err(DocumentError::Empty);
        }
        Ok(())
    }

    /// The spec says which iterations the document can hold: never more than `iterations`, and for
    /// one job's own run (a shard or a `first_iteration`) only that run's range of its seed.
    fn check_spec_covers(&self) -> Result<(), DocumentError> {
        let covered = self.coverage.iterations();
        if covered > u128::from(self.spec.iterations) {
            return Err(DocumentError::Inconsistent(format!(
                "the coverage holds {covered} iterations but the spec only {}",
                self.spec.iterations
            )));
        }
        if self.spec.shard.is_some() || self.spec.first_iteration.is_some() {
            let range = self.spec.iteration_range();
            if !self.coverage.is_within(&Coverage::range(self.spec.seed, range.start, range.end)) {
                return Err(DocumentError::Inconsistent(format!(
                    "the coverage lies outside the spec's iterations [{}, {}) of seed {}",
                    range.start, range.end, self.spec.seed
                )));
            }
        }
        Ok(())
    }

    /// Parses and verifies a document from JSON text: straight into the typed document (every list
    /// bounded, see [`crate::sim::stats::moments`]), so memory stays within a few times the text's size.
    pub fn from_json(bytes: &[u8]) -> Result<Self, DocumentError> {
        let doc: Self = parse_json(bytes).map_err(DocumentError::Unreadable)?;
        doc.verify()?;
        Ok(doc)
    }

    /// The document with its checksum recomputed for its current content. Anyone can do this (the
    /// checksum is integrity, not authenticity), which is why [`MomentsDocument::verify`] checks
    /// everything else on its own; tests use it to forge documents.
    pub fn sealed(mut self) -> Self {
        self.checksum = checksum_of(&self.body());
        self
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
    merge_documents_at(documents).map_err(|(_, e)| e)
}

/// [`merge_documents`], saying which document (its index) the merge failed at: the first one
/// that conflicts with those before it, or the last for a total that would leave the bounds.
pub fn merge_documents_at(documents: &[MomentsDocument]) -> Result<MomentsDocument, (usize, DocumentError)> {
    let (first, rest) =
        documents.split_first().ok_or_else(|| (0, DocumentError::Inconsistent("nothing to merge".into())))?;
    let mut moments = first.moments.clone();
    for (i, doc) in rest.iter().enumerate() {
        moments.merge(&doc.moments).map_err(|e| (i + 1, explained(e, &doc.spec, &first.spec).into()))?;
    }
    moments.check_bounded().map_err(|e| (documents.len() - 1, e.into()))?;
    Ok(MomentsDocument::new(merged_spec(&first.spec, &moments), moments))
}

/// The spec of merged statistics: `base` with `iterations` set to the total covered and no shard
/// or first iteration (the coverage says which iterations they are).
pub fn merged_spec(base: &JobSpec, moments: &Moments) -> JobSpec {
    let mut spec = base.clone();
    spec.iterations = moments.iterations().max(1);
    spec.shard = None;
    spec.first_iteration = None;
    spec
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::exact_sum::ExactSum;
    use crate::sim::runner::run;
    use crate::sim::spec::parse_job_spec;
    use serde_json::json;

    fn shard(k: u64, n: u64) -> MomentsDocument {
        shard_with_folds(k, n, None)
    }

    fn shard_with_folds(k: u64, n: u64, folds: Option<usize>) -> MomentsDocument {
        let spec = parse_job_spec(&json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": 0.02,
            "iterations": 6, "seed": 2, "shard": { "index": k, "count": n }, "folds": folds }))
        .unwrap();
        let job = spec.validate().unwrap();
        let moments = run(job.config(), spec.seed, spec.iteration_range());
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

    /// Recomputes the checksum after an edit: anyone can, so every check below must hold on its
    /// own, whatever the checksum says.
    fn reseal(doc: MomentsDocument) -> MomentsDocument {
        doc.sealed()
    }

    fn refused(doc: MomentsDocument) -> DocumentError {
        let bytes = reseal(doc).to_json();
        MomentsDocument::from_json(&bytes).expect_err("a forged document must be refused")
    }

    #[test]
    fn forged_documents_that_contradict_themselves_are_refused() {
        let doc = shard(0, 2);
        let mut negative = doc.clone();
        negative.moments.folds[0].strategies[2][1] = ExactSum::from_parts(&[-1.0]).unwrap();
        assert!(matches!(refused(negative), DocumentError::Merge(MergeError::Malformed(m)) if m.contains("plane3")));
        let mut counts = doc.clone();
        counts.moments.folds[1].cell_counts[0] += 1;
        assert!(matches!(refused(counts), DocumentError::Merge(MergeError::Malformed(m)) if m.contains("cells count")));
        let mut squares = doc.clone();
        squares.moments.folds[0].merges_sq[1] = 0;
        assert!(matches!(refused(squares), DocumentError::Merge(MergeError::Malformed(_))));
        // The spec of a shard names its range: a coverage elsewhere is a forgery.
        let mut elsewhere = doc.clone();
        elsewhere.spec.shard = Some(crate::sim::spec::Shard { index: 1, count: 2 });
        assert!(matches!(refused(elsewhere), DocumentError::Inconsistent(m) if m.contains("outside")));
        // More iterations than the spec allows.
        let mut short = doc.clone();
        short.spec.shard = None;
        short.spec.iterations = 2;
        assert!(matches!(refused(short), DocumentError::Inconsistent(m) if m.contains("only 2")));
        // No iterations at all (once a 500 from the database's CHECK constraint).
        let spec = doc.spec.clone();
        let empty = MomentsDocument::new(spec.clone(), Moments::new(spec.validate().unwrap().config()));
        assert_eq!(MomentsDocument::from_json(&empty.to_json()), Err(DocumentError::Empty));
        // A coverage whose counts once wrapped: four ranges [0, 2^63).
        let mut wrapped = serde_json::to_value(&doc).unwrap();
        let huge = serde_json::json!([
            { "seed": 1, "ranges": [[0u64, 1u64 << 63]] }, { "seed": 2, "ranges": [[0u64, 1u64 << 63]] },
            { "seed": 3, "ranges": [[0u64, 1u64 << 63]] }, { "seed": 4, "ranges": [[0u64, 1u64 << 63]] }]);
        wrapped["coverage"] = huge.clone();
        wrapped["moments"]["coverage"] = huge;
        let wrapped: MomentsDocument = serde_json::from_value(wrapped).unwrap();
        assert!(matches!(refused(wrapped), DocumentError::Merge(MergeError::Malformed(_))));
    }

    #[test]
    fn oversized_lists_stop_the_parser() {
        let doc = shard(0, 2);
        let mut value = serde_json::to_value(&doc).unwrap();
        value["moments"]["folds"][0]["sum_y"] = serde_json::json!(vec![0.0; 600]);
        let e = MomentsDocument::from_json(value.to_string().as_bytes()).unwrap_err();
        assert!(
            matches!(&e, DocumentError::Unreadable(m) if m.contains("more than 520 entries") && m.contains("sum_y")),
            "{e}"
        );
    }

    /// Squared merge counts are u128: a document holding one ≥ 2⁶⁴ reads back (through JSON text,
    /// not an intermediate value that cannot hold it).
    #[test]
    fn wide_counters_round_trip() {
        let mut doc = shard(0, 2);
        let fold = &mut doc.moments.folds[0];
        let k = doc.moments.cells;
        let big = 1u64 << 33;
        fold.cell_counts[2 * k] += big - fold.merges[2];
        fold.merges[2] = big;
        fold.merges_sq[2] = u128::from(big) * u128::from(big) / 2;
        let doc = reseal(doc);
        let back = MomentsDocument::from_json(&doc.to_json()).unwrap();
        assert_eq!(back.moments.folds[0].merges_sq[2], 1u128 << 65);
    }

    /// Two documents whose sums are each within bounds but whose total is not: the merge is
    /// refused (its canonical form could not be read back), and nothing is returned.
    #[test]
    fn merges_that_leave_the_bounds_are_refused() {
        // Two folds, so that both shards ([0, 3) and [3, 6)) hold iterations of fold 0.
        let a = shard_with_folds(0, 2, Some(2));
        let b = shard_with_folds(1, 2, Some(2));
        let n = 2 * a.moments.cells + 1;
        let huge = |mut doc: MomentsDocument| {
            // An off-diagonal entry of ΣYYᵀ: no Cauchy–Schwarz check applies to it.
            doc.moments.folds[0].sum_yy[crate::sim::stats::moments::packed_index(n, 0, 1)] =
                ExactSum::from_parts(&[1e301]).unwrap();
            MomentsDocument::from_json(&reseal(doc).to_json()).unwrap()
        };
        let e = merge_documents(&[huge(a), huge(b)]).unwrap_err();
        assert!(matches!(e, DocumentError::Merge(MergeError::Overflow(_))), "{e}");
    }

    #[test]
    fn shards_merge_into_the_whole_run() {
        let whole = {
            let spec = parse_job_spec(&json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": 0.02,
                "iterations": 6, "seed": 2 }))
            .unwrap();
            run(spec.validate().unwrap().config(), 2, 0..6)
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

    /// Issue 25, item 8: a refused merge named two fingerprints; it names the fields that differ.
    #[test]
    fn a_merge_of_two_configurations_names_the_fields_that_differ() {
        let doc = |l3: f64, radius: f64, seed: u64| {
            let spec = parse_job_spec(&json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": radius,
                "iterations": 2, "seed": seed, "scene": { "l3": l3 } }))
            .unwrap();
            let moments = run(spec.validate().unwrap().config(), seed, 0..2);
            MomentsDocument::new(spec, moments)
        };
        let e = merge_documents(&[doc(3.0, 0.02, 1), doc(9.0, 0.01, 2)]).unwrap_err().to_string();
        assert!(e.contains("merge_radius: 0.01 vs 0.02"), "{e}");
        assert!(e.contains("scene.l3: 9.0 vs 3.0"), "{e}");
        assert!(!e.contains("seed"), "the seed may differ: {e}");
        // Same configuration, other seed: merges.
        merge_documents(&[doc(3.0, 0.02, 1), doc(3.0, 0.02, 2)]).unwrap();
    }
}
