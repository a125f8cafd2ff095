//! The model of the paper's scene (docs/model.md): its parameters as documents spell them, the
//! light's profile, the planes and the lobe, the cell grid of the weights, the per-path MIS
//! heuristics, the closed-form densities of light vertices, and the validated configuration with
//! its fingerprint.
//!
//! * [`params`] — the plain parameter types and their validation (the ranges, named per field);
//! * [`illumination`] — the radial light profile and its samplers;
//! * [`scene`] — the three planes and the lobe, with the lobe's sampler;
//! * [`cells`] — the cell grid over the join path's (r2, r3, φ);
//! * [`heuristics`] — Veach's balance and power heuristics with VCM pdfs, and the
//!   correlation-aware heuristic derived for the iteration's N_F × N_B pairs;
//! * [`densities`] — where light vertices fall, in closed form (light start and plane-2 arrival);
//! * [`config`] — everything that changes the law of an iteration, and its fingerprint.
//!
//! Imports: crate::sim::math

pub mod cells;
pub mod config;
pub mod densities;
pub mod heuristics;
pub mod illumination;
pub mod params;
pub mod scene;
