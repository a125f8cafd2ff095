//! What a merge or a study is sent: its sources (documents, or the peers to pull them from),
//! parsed from bytes straight into typed values, field by field, naming the field that is wrong.

use serde::Deserialize;
use serde_json::Value;

use crate::jobs::core::error::JobError;
use crate::sim::document::{DocumentSignature, MomentsDocument, parse_json};
use crate::sim::spec::{JobSpec, SpecError};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;

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
