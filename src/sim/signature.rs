//! Who vouches for a moments document: its detached signature ([`DocumentSignature`], Ed25519 over
//! the document's checksum behind a domain tag) and what the signature attests ([`Attestation`]:
//! how the signer came by the statistics). The keys and the signing live in the server
//! (`trust::signing`); the core only defines the format and the bytes a signature covers
//! (`MomentsDocument::signed_message`).

use serde::{Deserialize, Serialize};

/// A detached signature of a document's checksum
/// ([`MomentsDocument::signed_message`](crate::sim::document::MomentsDocument::signed_message)).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct DocumentSignature {
    /// Always `ed25519`.
    pub algorithm: String,
    /// The signing key's id: the first 16 hex digits of the SHA-256 of its raw public key.
    pub key_id: String,
    /// The 64-byte signature, hex.
    pub value: String,
    /// What the signer vouches for (covered by the signature). Absent in signatures made before
    /// attestations existed, which vouch only that the signer exported the document.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attests: Option<Attestation>,
}

/// What a signature vouches for: how the signer came by the statistics.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Attestation {
    /// `computed`: the signer ran every iteration itself. `merged`: merged from statistics each
    /// either computed by the signer or signed by a key it trusts (`keys`). `asserted`: merged by
    /// the key's holder with `optimis merge` from files of which some carried no signature it
    /// could check — the holder's word for them (a server never signs such statistics).
    pub basis: AttestationBasis,
    /// The trusted keys whose signed documents the statistics were merged from, sorted.
    #[serde(default)]
    #[cfg_attr(feature = "server", schema(max_items = 256))]
    pub keys: Vec<String>,
}

/// How the signer came by the statistics ([`Attestation::basis`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum AttestationBasis {
    /// Every iteration run by the signer.
    Computed,
    /// Merged from statistics computed by the signer or signed by keys it trusts.
    Merged,
    /// Merged by the key's holder from files it could not all check.
    Asserted,
}

/// What a signature's message starts with, so that it cannot be taken for a signature of anything
/// else made with the same key.
pub const SIGNATURE_DOMAIN: &[u8] = b"optimis-moments-signature-v1\n";

/// The domain of a signature with an attestation: the checksum, then the attestation's JSON.
pub const ATTESTED_SIGNATURE_DOMAIN: &[u8] = b"optimis-moments-signature-v2\n";
