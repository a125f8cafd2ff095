//! optimis: optimal multiple-importance-sampling weights for bidirectional photon mapping, by direct
//! minimisation of the pixel variance (Ershov, Voloboy, Zhdanov et al. 2020).
//!
//! # Layout
//!
//! * [`sim`] — the pure simulation core: scene, sampling, iterations, moments, solver, reference.
//! * [`cli`] — the command line (`run`, `bench`), a thin shell around the core.
//!
//! `main.rs` only parses the command line and calls into this library.

pub mod cli;
pub mod sim;
