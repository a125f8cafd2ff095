//! TLS for the server (`--tls-cert`, `--tls-key`): rustls with the ring provider, PEM files read
//! once at start. With TLS, peers can pull from this server over https the way the README tells
//! people to expose it, without a reverse proxy in between.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use tokio_rustls::TlsAcceptor;

use super::pins::install_crypto_provider;
use super::secrets::read_config_file;

/// Why the certificate or key cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// The certificate file cannot be read, is not PEM, or holds no certificate.
    #[error("--tls-cert {path}: {message}")]
    Certificate {
        /// The `--tls-cert` file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The key file cannot be read or holds no private key in PEM.
    #[error("--tls-key {path}: {message}")]
    Key {
        /// The `--tls-key` file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// rustls refused the pair (e.g. a key of an unsupported type, or not the certificate's).
    #[error("the certificate and key do not form a TLS configuration: {0}")]
    Config(String),
}

/// An acceptor for the certificate chain in `cert` and the private key in `key` (PEM).
pub fn acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, TlsError> {
    install_crypto_provider();
    let cert_error = |message: String| TlsError::Certificate { path: cert.to_path_buf(), message };
    let pem = read_config_file(cert).map_err(|e| cert_error(e.to_string()))?;
    let chain: Vec<CertificateDer<'static>> =
        CertificateDer::pem_slice_iter(&pem).collect::<Result<_, _>>().map_err(|e| cert_error(e.to_string()))?;
    if chain.is_empty() {
        return Err(cert_error("holds no certificate".into()));
    }
    let key_error = |message: String| TlsError::Key { path: key.to_path_buf(), message };
    let pem = read_config_file(key).map_err(|e| key_error(e.to_string()))?;
    let key = PrivateKeyDer::from_pem_slice(&pem).map_err(|e| key_error(e.to_string()))?;
    let config = rustls::ServerConfig::builder()
        .with_no_client_auth()
        .with_single_cert(chain, key)
        .map_err(|e| TlsError::Config(e.to_string()))?;
    Ok(TlsAcceptor::from(Arc::new(config)))
}
