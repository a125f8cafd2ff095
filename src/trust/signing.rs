//! Provenance of moments documents: this server's signature on what it exports
//! (`--signing-key`), and the keys whose signatures it requires of what it merges (`--trust`).
//!
//! A document's checksum is integrity only — anyone can recompute it — so without signatures a
//! server trusts a document's origin only through the transport (an allowed peer, its token,
//! https). With `--trust`, a merge or a study accepts only documents signed by one of the trusted
//! keys; with none given, nothing changes. Keys are Ed25519 (ring, the crypto library already in
//! the tree through rustls) in the PEM files OpenSSL writes:
//!
//! ```text
//! openssl genpkey -algorithm ed25519 -out signing.pem        # --signing-key signing.pem
//! openssl pkey -in signing.pem -pubout -out signing.pub.pem  # --trust signing.pub.pem
//! ```
//!
//! The signature covers the document's checksum and what it attests behind a domain tag
//! ([`MomentsDocument::signed_message`]); a reader recomputes the checksum from the content
//! before it checks the signature, so the signature vouches for the content. A server signs only
//! what it can vouch for ([`Attestation`]): statistics it computed, or merged from sources each of
//! which it computed or a trusted key signed ([`Provenance::vouch`] records which key at the
//! merge); anything else is exported unsigned, so that a signing server cannot be used to launder
//! a document sent to it. The key file must be readable by its owner only.

use std::path::{Path, PathBuf};

use ring::signature::{ED25519, Ed25519KeyPair, KeyPair, UnparsedPublicKey};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{PrivatePkcs8KeyDer, SubjectPublicKeyInfoDer};

use super::secrets::{SecretError, check_owner_only, read_config_file};
use crate::sim::document::{Attestation, DocumentSignature, MomentsDocument};
use crate::sim::math::digest::sha256_hex;
use crate::sim::spec::SpecError;
use crate::sim::weights::artifact::WeightsArtifact;

/// The DER prefix of an Ed25519 SubjectPublicKeyInfo (RFC 8410): the raw 32-byte key follows.
const ED25519_SPKI_PREFIX: [u8; 12] = [0x30, 0x2a, 0x30, 0x05, 0x06, 0x03, 0x2b, 0x65, 0x70, 0x03, 0x21, 0x00];

/// Why a key file cannot be used (reported at start).
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The `--signing-key` file is not an Ed25519 private key in PKCS#8 PEM.
    #[error("--signing-key {path}: {message}")]
    Signing {
        /// The `--signing-key` file.
        path: PathBuf,
        /// Why it cannot be used (for a file that is not PKCS#8 PEM, with how to make one).
        message: String,
    },
    /// A `--trust` file is not an Ed25519 public key in SubjectPublicKeyInfo PEM.
    #[error("--trust {path}: {message}")]
    Trust {
        /// The `--trust` file.
        path: PathBuf,
        /// Why it cannot be used.
        message: String,
    },
}

/// What this server signs with and whose signatures it requires.
#[derive(Debug, Default)]
pub struct Provenance {
    /// The `--signing-key` that signs every moments document this server exports; none: they go
    /// out unsigned.
    pub key: Option<SigningKey>,
    /// The `--trust` keys; merges and studies accept only documents signed by one of them (none
    /// given: signatures are neither required nor checked).
    pub trust: TrustedKeys,
}

impl Provenance {
    /// Reads `--signing-key` and every `--trust` file.
    pub fn load(key: Option<&Path>, trust: &[PathBuf]) -> Result<Self, KeyError> {
        Ok(Self { key: key.map(SigningKey::load).transpose()?, trust: TrustedKeys::load(trust)? })
    }

    /// `doc` signed with this server's key vouching for `attests`, if it has a key.
    pub fn sign(&self, doc: MomentsDocument, attests: Attestation) -> MomentsDocument {
        match &self.key {
            Some(key) => key.sign(doc, attests),
            None => doc,
        }
    }

    /// `artifact` signed with this server's key vouching for `attests`, if it has a key.
    pub fn sign_artifact(&self, mut artifact: WeightsArtifact, attests: Attestation) -> WeightsArtifact {
        if let Some(key) = &self.key {
            artifact.signature = None;
            let signature = key.pair.sign(&artifact.signed_message(&attests));
            artifact.signature = Some(DocumentSignature {
                algorithm: "ed25519".into(),
                key_id: key.key_id.clone(),
                value: hex(signature.as_ref()),
                attests: Some(attests),
            });
        }
        artifact
    }

    /// Whether `artifact` carries a valid signature of a trusted key (or this server's own), and
    /// whose.
    pub fn artifact_signer(&self, artifact: &WeightsArtifact) -> Option<String> {
        let signature = artifact.signature.as_ref()?;
        let attests = signature.attests.as_ref()?;
        let value = unhex(&signature.value).filter(|v| v.len() == 64)?;
        let message = artifact.signed_message(attests);
        let own = self.key.as_ref().map(|k| (k.key_id.clone(), k.pair.public_key().as_ref().to_vec()));
        own.into_iter()
            .chain(self.trust.keys.iter().cloned())
            .find(|(id, public)| {
                *id == signature.key_id && UnparsedPublicKey::new(&ED25519, public).verify(&message, &value).is_ok()
            })
            .map(|(id, _)| id)
    }

    /// Who vouches for a document about to be merged (already verified: its checksum matches its
    /// content): the id of a trusted key — or this server's own — whose signature it carries, or
    /// none. With `--trust`, a document without a trusted signature is refused (`at` is its JSON
    /// path in the request, named in the error with `.signature`).
    pub fn vouch(&self, doc: &MomentsDocument, at: &str) -> Result<Option<String>, SpecError> {
        if self.trust.required() {
            return self.trust.check(doc, at).map(Some);
        }
        let own = self.key.as_ref().filter(|k| k.verifies(doc)).map(|k| k.key_id.clone());
        Ok(own.or_else(|| self.trust.signer(doc)))
    }
}

/// This server's signing key.
pub struct SigningKey {
    pair: Ed25519KeyPair,
    key_id: String,
}

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SigningKey").field("key_id", &self.key_id).finish()
    }
}

/// The id of a raw Ed25519 public key: 16 hex digits of its SHA-256.
pub fn key_id(public: &[u8]) -> String {
    sha256_hex(public)[..16].to_string()
}

impl SigningKey {
    /// Reads an Ed25519 private key (PKCS#8 PEM, `-----BEGIN PRIVATE KEY-----`) from a file only
    /// its owner can read (as `--token-file` and `--tls-key`: whoever reads the key can sign as
    /// this server).
    pub fn load(path: &Path) -> Result<Self, KeyError> {
        let err = |message: String| KeyError::Signing { path: path.to_path_buf(), message };
        check_owner_only(path).map_err(|e| match e {
            SecretError::Read { source, .. } => err(source.to_string()),
            other => err(other.to_string()),
        })?;
        let pem = read_config_file(path).map_err(|e| err(e.to_string()))?;
        let der = PrivatePkcs8KeyDer::from_pem_slice(&pem).map_err(|e| {
            err(format!("not a PKCS#8 PEM private key ({e}); make one with `openssl genpkey -algorithm ed25519`"))
        })?;
        let pair = Ed25519KeyPair::from_pkcs8_maybe_unchecked(der.secret_pkcs8_der())
            .map_err(|e| err(format!("not an Ed25519 private key: {e}")))?;
        let key_id = key_id(pair.public_key().as_ref());
        Ok(Self { pair, key_id })
    }

    /// The key's id (16 hex digits of the SHA-256 of its raw public key), written into every
    /// signature it makes; a server that trusts the public key knows it by the same id.
    pub fn key_id(&self) -> &str {
        &self.key_id
    }

    /// `doc` signed with this key, vouching for `attests` (any earlier signature replaced).
    pub fn sign(&self, mut doc: MomentsDocument, attests: Attestation) -> MomentsDocument {
        let signature = self.pair.sign(&doc.signed_message_with(Some(&attests)));
        doc.signature = Some(DocumentSignature {
            algorithm: "ed25519".into(),
            key_id: self.key_id.clone(),
            value: hex(signature.as_ref()),
            attests: Some(attests),
        });
        doc
    }

    /// Whether `doc` carries a valid signature of this key.
    fn verifies(&self, doc: &MomentsDocument) -> bool {
        let public = self.pair.public_key().as_ref();
        doc.signature.as_ref().is_some_and(|s| s.key_id == self.key_id && valid(doc, s, public))
    }
}

/// Whether `signature` is a valid Ed25519 signature of `doc` (its message with its attestation)
/// by the raw public key `public`.
fn valid(doc: &MomentsDocument, signature: &DocumentSignature, public: &[u8]) -> bool {
    signature.algorithm == "ed25519"
        && well_formed(signature.attests.as_ref())
        && unhex(&signature.value)
            .filter(|v| v.len() == 64)
            .is_some_and(|value| UnparsedPublicKey::new(&ED25519, public).verify(&doc.signed_message(), &value).is_ok())
}

/// An attestation names at most [`MAX_ATTESTED_KEYS`] keys, each a key id.
fn well_formed(attests: Option<&Attestation>) -> bool {
    attests.is_none_or(|a| a.keys.len() <= MAX_ATTESTED_KEYS && a.keys.iter().all(|k| is_key_id(k)))
}

/// Most keys one attestation names (a study has at most 256 sources).
const MAX_ATTESTED_KEYS: usize = 256;

/// Whether `text` has the form of a key id (16 lower-case hex digits).
fn is_key_id(text: &str) -> bool {
    text.len() == 16 && text.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// A value from a document, quoted for a message: whole if short, else its start and its length
/// (a 5 MB key id was once quoted whole in a 422).
fn quoted(text: &str) -> String {
    if text.len() <= 40 {
        format!("{text:?}")
    } else {
        let start: String = text.chars().take(32).collect();
        format!("{start:?}… ({} bytes)", text.len())
    }
}

/// The public keys whose signatures merges and studies require (none: signatures are not
/// required, and not checked).
#[derive(Debug, Default, Clone)]
pub struct TrustedKeys {
    keys: Vec<(String, Vec<u8>)>,
}

impl TrustedKeys {
    /// Reads Ed25519 public keys (SubjectPublicKeyInfo PEM, `-----BEGIN PUBLIC KEY-----`).
    pub fn load(paths: &[PathBuf]) -> Result<Self, KeyError> {
        let mut keys = Vec::with_capacity(paths.len());
        for path in paths {
            let err = |message: String| KeyError::Trust { path: path.to_path_buf(), message };
            let pem = read_config_file(path).map_err(|e| err(e.to_string()))?;
            let der = SubjectPublicKeyInfoDer::from_pem_slice(&pem).map_err(|e| {
                err(format!("not a PEM public key ({e}); make one with `openssl pkey -in KEY -pubout`"))
            })?;
            let raw = der
                .as_ref()
                .strip_prefix(&ED25519_SPKI_PREFIX[..])
                .filter(|raw| raw.len() == 32)
                .ok_or_else(|| err("not an Ed25519 public key".into()))?;
            keys.push((key_id(raw), raw.to_vec()));
        }
        Ok(Self { keys })
    }

    /// Whether signatures are required.
    pub fn required(&self) -> bool {
        !self.keys.is_empty()
    }

    /// The ids of the trusted keys.
    pub fn ids(&self) -> Vec<&str> {
        self.keys.iter().map(|(id, _)| id.as_str()).collect()
    }

    /// The id of the trusted key whose valid signature `doc` carries, if any (never an error).
    pub fn signer(&self, doc: &MomentsDocument) -> Option<String> {
        let signature = doc.signature.as_ref()?;
        let (id, public) = self.keys.iter().find(|(id, _)| *id == signature.key_id)?;
        valid(doc, signature, public).then(|| id.clone())
    }

    /// Checks that `doc` (already verified: its checksum matches its content) is signed by a
    /// trusted key, and says which; `at` is the JSON path of the document in the request (a
    /// peer's URL field for a pulled one), named in the error with `.signature`.
    pub fn check(&self, doc: &MomentsDocument, at: &str) -> Result<String, SpecError> {
        let field = if at.is_empty() { "signature".to_string() } else { format!("{at}.signature") };
        let refuse = |message: String| -> SpecError { SpecError::new(field.clone(), message) };
        let Some(signature) = &doc.signature else {
            return Err(refuse(format!(
                "this server accepts only documents signed by a trusted key ({}); the document is unsigned — export it \
                 from a server started with --signing-key, and trust that key here with --trust PUBLIC_KEY_FILE",
                self.ids().join(", ")
            )));
        };
        if signature.algorithm != "ed25519" {
            return Err(refuse(format!(
                "unsupported algorithm {}; expected \"ed25519\"",
                quoted(&signature.algorithm)
            )));
        }
        if !is_key_id(&signature.key_id) {
            return Err(refuse(format!(
                "the key id {} is not a key id (16 hex digits of the SHA-256 of a public key)",
                quoted(&signature.key_id)
            )));
        }
        let Some((id, public)) = self.keys.iter().find(|(id, _)| *id == signature.key_id) else {
            return Err(refuse(format!(
                "signed by key {}, which this server does not trust (it trusts {}); to trust it, start this server \
                 with --trust and that key's public key file",
                quoted(&signature.key_id),
                self.ids().join(", ")
            )));
        };
        if !well_formed(signature.attests.as_ref()) {
            return Err(refuse(format!("its attestation names more than {MAX_ATTESTED_KEYS} keys, or not key ids")));
        }
        if unhex(&signature.value).filter(|v| v.len() == 64).is_none() {
            return Err(refuse("the signature value is not 128 hex digits".into()));
        }
        if !valid(doc, signature, public) {
            return Err(refuse(format!(
                "the signature of key {id} does not match the document: it was edited after it was signed"
            )));
        }
        Ok(id.clone())
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) || text.len() > 256 {
        return None;
    }
    (0..text.len()).step_by(2).map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::document::AttestationBasis;

    /// An Ed25519 key pair in the PEM files OpenSSL writes (made by rcgen).
    fn keypair(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
        use std::os::unix::fs::PermissionsExt;
        let pair = rcgen::KeyPair::generate_for(&rcgen::PKCS_ED25519).unwrap();
        let (private, public) = (dir.join(format!("{name}.pem")), dir.join(format!("{name}.pub.pem")));
        std::fs::write(&private, pair.serialize_pem()).unwrap();
        std::fs::set_permissions(&private, std::fs::Permissions::from_mode(0o600)).unwrap();
        std::fs::write(&public, pair.public_key_pem()).unwrap();
        (private, public)
    }

    fn document() -> MomentsDocument {
        let doc = serde_json::json!({ "iterations": 3, "light_paths": 1000, "camera_paths": 10 });
        let job = crate::sim::spec::parse_job_spec(&doc).unwrap().validate().unwrap();
        let moments = crate::sim::runner::run(job.config(), job.spec().seed, 0..3);
        MomentsDocument::new(job.spec().clone(), moments)
    }

    fn computed() -> Attestation {
        Attestation { basis: AttestationBasis::Computed, keys: Vec::new() }
    }

    #[test]
    fn signed_documents_verify_and_edits_unsigned_or_unknown_keys_are_refused_naming_the_signature() {
        let dir = tempfile::tempdir().unwrap();
        let (private, public) = keypair(dir.path(), "a");
        let (other, _) = keypair(dir.path(), "b");
        let key = SigningKey::load(&private).unwrap();
        let trust = TrustedKeys::load(&[public]).unwrap();
        assert_eq!(trust.ids(), [key.key_id()]);
        let signed = key.sign(document(), computed());
        assert_eq!(trust.check(&signed, "sources[0]").unwrap(), key.key_id());
        // Through JSON and back: the signature survives (it is outside the checksummed body).
        let read = MomentsDocument::from_json(&signed.to_json()).unwrap();
        trust.check(&read, "").unwrap();

        let field = |e: SpecError| (e.field, e.message);
        // Edited and re-sealed (a valid checksum): the signature no longer matches.
        let mut edited = signed.clone();
        edited.spec.seed += 1;
        let (f, m) = field(trust.check(&edited.sealed(), "sources[1]").unwrap_err());
        assert_eq!(f, "sources[1].signature");
        assert!(m.contains("edited after it was signed"), "{m}");
        // The attestation is signed too: a "computed" turned into "merged" no longer verifies.
        let mut claimed = signed.clone();
        claimed.signature.as_mut().unwrap().attests =
            Some(Attestation { basis: AttestationBasis::Merged, keys: Vec::new() });
        assert!(field(trust.check(&claimed, "").unwrap_err()).1.contains("edited after it was signed"));
        let (f, m) = field(trust.check(&document(), "").unwrap_err());
        assert_eq!(f, "signature");
        assert!(m.contains("unsigned") && m.contains("--trust"), "{m}");
        let stranger = SigningKey::load(&other).unwrap().sign(document(), computed());
        let (_, m) = field(trust.check(&stranger, "").unwrap_err());
        assert!(m.contains("does not trust"), "{m}");
        // Without trusted keys nothing is required, and the signer is named only if trusted (or
        // this server's own).
        let open = Provenance::default();
        assert_eq!(open.vouch(&document(), "").unwrap(), None);
        assert_eq!(open.vouch(&stranger, "").unwrap(), None);
        let own = Provenance { key: Some(SigningKey::load(&private).unwrap()), trust: TrustedKeys::default() };
        assert_eq!(own.vouch(&signed, "").unwrap().as_deref(), Some(key.key_id()));
        assert_eq!(own.vouch(&stranger, "").unwrap(), None);
    }

    /// Issue 39, item 11: a key id of megabytes is refused without being quoted whole.
    #[test]
    fn a_huge_key_id_is_refused_and_quoted_short() {
        let dir = tempfile::tempdir().unwrap();
        let (private, public) = keypair(dir.path(), "a");
        let trust = TrustedKeys::load(&[public]).unwrap();
        let mut doc = SigningKey::load(&private).unwrap().sign(document(), computed());
        doc.signature.as_mut().unwrap().key_id = "f".repeat(5_000_000);
        let e = trust.check(&doc, "").unwrap_err();
        assert!(e.message.len() < 200 && e.message.contains("(5000000 bytes)"), "{}", &e.message[..200]);
        doc.signature.as_mut().unwrap().algorithm = "x".repeat(1_000_000);
        let e = trust.check(&doc, "").unwrap_err();
        assert!(e.message.len() < 200, "{}", &e.message[..200]);
    }

    /// Issue 39, item 7: a signing key others can read is refused (as a token or a TLS key is),
    /// and a key file that never ends (`/dev/zero`) is read only up to a bound (issue 39, item 13).
    #[test]
    fn a_signing_key_readable_by_others_and_an_endless_file_are_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let (private, _) = keypair(dir.path(), "a");
        std::fs::set_permissions(&private, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = SigningKey::load(&private).unwrap_err().to_string();
        assert!(e.contains("chmod 600"), "{e}");
        std::fs::set_permissions(&private, std::fs::Permissions::from_mode(0o600)).unwrap();
        SigningKey::load(&private).unwrap();
        let e = TrustedKeys::load(&[PathBuf::from("/dev/zero")]).unwrap_err().to_string();
        assert!(e.contains("larger than"), "{e}");
    }

    #[test]
    fn key_files_of_the_wrong_kind_are_refused_at_start() {
        let dir = tempfile::tempdir().unwrap();
        let (private, public) = keypair(dir.path(), "a");
        assert!(matches!(SigningKey::load(&public), Err(KeyError::Signing { .. })));
        assert!(matches!(TrustedKeys::load(&[private]), Err(KeyError::Trust { .. })));
    }
}
