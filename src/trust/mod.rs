//! Trust: who this server believes, and how it proves who it is — in one room, used by the CLI,
//! the server and the job runner alike.
//!
//! Imports: crate::sim
//!
//! * [`signing`] — provenance: this server's Ed25519 signature on exports, and the trusted keys
//!   (`--trust`) merges require;
//! * [`pins`] — how https peers' certificates are verified: the platform's roots plus the
//!   `--peer-ca` certificates, each also pinned;
//! * [`acceptor`] — this server's own TLS (`--tls-cert`, `--tls-key`);
//! * [`secrets`] — secret files (tokens, keys): bounded reads, and refused when other users can
//!   read them.

pub mod acceptor;
pub mod pins;
pub mod secrets;
pub mod signing;
