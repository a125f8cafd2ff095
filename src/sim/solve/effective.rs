//! What a weight function does on average where it matters: its *effective weights* per
//! (r2, r3) bin of the cell grid — the share of the bin's luminance each technique carries — with
//! standard errors, the data behind the paper's Fig. 2 for any kind of recommendation (a table, a
//! per-path heuristic, a table with heuristics stacked on it). The values are computed by
//! `sim::weights::effective` (it samples join paths with the engine); this module owns the result's
//! shape and the fold fits its fit errors come from.
//!
//! For technique m and bin b, over the full paths x̄ = (pixel, x2, x3, light) with (r2, r3) in b,
//!
//!   w̄_m(b) = ∫_b w_m(x̄) f(x̄) dx̄ / ∫_b f(x̄) dx̄,
//!
//! f the path's contribution to the pixel (docs/model.md §10): the fraction of the bin's luminance
//! that merges by technique m deliver. For a table alone it is the contribution-weighted mean of
//! the bin's cells (one cell per bin when φ has one bin); for a heuristic it depends on each path's
//! vertex densities, so it is an average over paths; the three sum to 1 in every bin (1 − Σβ + Σβ
//! for a stack).

use serde::{Deserialize, Serialize};

use super::solver::Fit;
use crate::sim::engines::strategies::PathStrategy;

/// The fold fits of a fitted row at its λ, as the jackknife reads them: per fold, the table's
/// weights in cell order and each stacked heuristic's β.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FitReplicates {
    /// Per fold: (T₀, T₁, T₂) of every cell, in cell order.
    pub tables: Vec<Vec<[f64; 3]>>,
    /// Per fold: each stacked heuristic with its β.
    pub betas: Vec<Vec<(PathStrategy, f64)>>,
}

impl FitReplicates {
    /// The replicates of the fold fits `fits`.
    pub fn of<'a>(fits: impl Iterator<Item = &'a Fit>) -> Self {
        let mut out = Self::default();
        for fit in fits {
            out.tables.push(fit.cells.iter().map(|c| c.w).collect());
            out.betas.push(fit.heuristics.clone());
        }
        out
    }
}

/// The effective weights of one weight function (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct EffectiveWeights {
    /// The noise-table row whose weights these are (the recommended row).
    pub strategy: String,
    /// `table`, `heuristic` or `stack`.
    pub kind: String,
    /// Full paths each side drew (camera paths that reach plane 3, light paths joined to the
    /// pixel; from streams of their own), combined by the balance heuristic over the two samplers.
    pub paths_per_side: u64,
    /// Of the `paths_per_side` camera paths, those that reached plane 3 (the others were deflected
    /// past the horizontal at x2 and carry no light).
    pub camera_paths_reaching_plane3: u64,
    /// The paths' estimate of the pixel's luminance L (a check against the reference quadrature).
    pub luminance: f64,
    /// The bins, r2-major then r3, as the cell grid's (φ merged).
    pub bins: Vec<EffectiveBin>,
}

/// One (r2, r3) bin of [`EffectiveWeights`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct EffectiveBin {
    /// [lo, hi] on r2; hi is null for the tail bin.
    pub r2: [Option<f64>; 2],
    /// [lo, hi] on r3; hi is null for the tail bin.
    pub r3: [Option<f64>; 2],
    /// Sampled paths in the bin.
    pub paths: u64,
    /// The bin's estimated share of the pixel's luminance (0 where no sampled path carries light).
    pub luminance_share: f64,
    /// (w̄₀, w̄₁, w̄₂); null where no sampled path of the bin carries light (no weight matters
    /// there).
    pub w: Option<[f64; 3]>,
    /// Their standard errors: the sampling error of the average and the fit's jackknife error
    /// combined (√(sampling² + fit²)).
    pub stderr: Option<[f64; 3]>,
    /// The sampling part: the ratio estimator's error over the sampled paths.
    pub sampling_stderr: Option<[f64; 3]>,
    /// The fit's part: the jackknife over the K fold fits of the effective weight (table and β
    /// together, so their correlation counts); null for a per-path heuristic (nothing fitted) or
    /// when the fold fits are not at hand.
    pub fit_stderr: Option<[f64; 3]>,
}
