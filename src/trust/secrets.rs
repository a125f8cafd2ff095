//! Secret files read at start (tokens, keys, certificates): bounded in size, and a secret that
//! other users can read is refused, as ssh does.

use std::path::{Path, PathBuf};

/// Why a secret or configuration file cannot be used (reported at start).
#[derive(Debug, thiserror::Error)]
pub enum SecretError {
    /// The file cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file that cannot be read.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A secret file is readable by other users than its owner, or holds no acceptable token (at
    /// least 16 visible ASCII characters); the message says which and how to fix it.
    #[error("{0}")]
    Insecure(String),
}

/// Refuses a secret file (a token, a TLS key) that users other than its owner can read.
pub fn check_owner_only(path: &Path) -> Result<(), SecretError> {
    let metadata = std::fs::metadata(path).map_err(|source| SecretError::Read { path: path.to_path_buf(), source })?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = metadata.permissions().mode();
        if mode & 0o077 != 0 {
            return Err(SecretError::Insecure(format!(
                "{} is readable by other users (mode {:o}); make it readable by its owner only: chmod 600 {}",
                path.display(),
                mode & 0o777,
                path.display()
            )));
        }
    }
    #[cfg(not(unix))]
    let _ = metadata;
    Ok(())
}

/// Largest key, token or certificate file read at start: far more than any PEM key or chain, and
/// a bound for a path such as `/dev/zero` that would never end.
pub const MAX_CONFIG_FILE: u64 = 1 << 20;

/// Reads a configuration file (a key, a token, certificates) of at most [`MAX_CONFIG_FILE`] bytes.
pub fn read_config_file(path: &Path) -> Result<Vec<u8>, std::io::Error> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(MAX_CONFIG_FILE + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_CONFIG_FILE {
        return Err(std::io::Error::other(format!(
            "larger than {MAX_CONFIG_FILE} bytes: not a key, token or certificate file"
        )));
    }
    Ok(bytes)
}

/// Reads a secret from a file that only its owner may read (a group- or world-readable secret is
/// refused, as ssh does): the trimmed first line, at least 16 visible ASCII characters.
pub fn read_secret(path: &Path) -> Result<String, SecretError> {
    check_owner_only(path)?;
    let bytes = read_config_file(path).map_err(|source| SecretError::Read { path: path.to_path_buf(), source })?;
    let text = String::from_utf8_lossy(&bytes);
    let token = text.trim().to_string();
    if token.len() < 16 || !token.chars().all(|c| c.is_ascii_graphic()) {
        return Err(SecretError::Insecure(format!(
            "{} must hold a token of at least 16 visible ASCII characters (e.g. `openssl rand -hex 32`)",
            path.display()
        )));
    }
    Ok(token)
}
