//! The weights artifact (format `optimis-weights`, version 1): everything a renderer needs to
//! evaluate a run's weight function — a table on cells, a per-path heuristic, or a table with
//! heuristics stacked on it — for every technique of any join path, in quantities a renderer has
//! (docs/weights-lookup.md): the join path's cell coordinates (r2, r3, φ), the merging technique,
//! and each sub-path vertex's sampling density.
//!
//! The weight of a merge by technique m (0: plane 1, the pixel; 1: plane 2; 2: plane 3) is
//!
//!   w_m = T_m(cell(r2, r3, φ)) + Σ_h β_h · w_h,m(path)
//!
//! with T the table (0 where the artifact has none) and w_h each heuristic's weight, defined by its
//! `formula` (docs/model.md §9). Everything a formula reads is stated here: the technique densities
//! are products of the vertex densities — p₀ = p_l(x2|x3)·p_l(x1|x2,x3), p₁ = p_c(x2)·p_l(x2|x3),
//! p₂ = p_c(x2)·p_c(x3|x2) (the light's start density, common to all three, cancels) — and the
//! correlation-aware counts read the footprint A = πR², N_F and N_B given in the formula itself.

use serde::{Deserialize, Serialize};

use crate::sim::math::digest::sha256_hex;
use crate::sim::signature::{Attestation, DocumentSignature};
use crate::sim::stats::coverage::Coverage;

/// The artifact's `format`.
pub const WEIGHTS_FORMAT: &str = "optimis-weights";

/// The artifact's `version`: readers refuse another.
pub const WEIGHTS_VERSION: u32 = 1;

/// Most cells, heuristics and rings an artifact may hold (bounds for a reader).
pub const MAX_TABLE_CELLS: usize = 256;
/// Most stacked heuristics.
pub const MAX_HEURISTICS: usize = 16;
/// Most illumination rings.
pub const MAX_RINGS: usize = 64;

/// A portable weight function.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct WeightsArtifact {
    /// Always `optimis-weights`.
    pub format: String,
    /// Always 1.
    pub version: u32,
    /// The noise-table row whose weights these are (`optimal_stacked`, `correlation_aware_planes23`…).
    pub strategy: String,
    /// Whether the run recommended this row.
    pub recommended: bool,
    /// `table` (cells only), `heuristic` (one per-path heuristic, β = 1) or `stack` (a table plus
    /// heuristics).
    pub kind: WeightsKind,
    /// The scene the coordinates and densities refer to (lengths in the scene's unit, angles in
    /// radians): the model scene of docs/model.md, camera pixel at the origin of plane 1.
    pub scene: ArtifactScene,
    /// The table's cells: null for a heuristic alone.
    pub cells: Option<CellAxes>,
    /// The table, one entry per cell (every cell listed once, in cell order); empty for a
    /// heuristic alone. Each cell's three weights sum to 1 − Σβ.
    #[serde(default)]
    pub table: Vec<TableCell>,
    /// The per-path heuristics and their coefficients β (a heuristic alone: one, β = 1).
    #[serde(default)]
    pub heuristics: Vec<ArtifactHeuristic>,
    /// Where the weights come from.
    pub provenance: ArtifactProvenance,
    /// The signature of the server that made it, where it signs (`--signing-key`): Ed25519 over
    /// [`WeightsArtifact::signed_message`], vouching for the statistics the weights were fitted to
    /// exactly as its moments export does (`attests`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signature: Option<DocumentSignature>,
}

/// What an artifact's signature's message starts with.
pub const ARTIFACT_SIGNATURE_DOMAIN: &[u8] = b"optimis-weights-signature-v1\n";

impl WeightsArtifact {
    /// The bytes its signature covers: a domain tag, the SHA-256 of the artifact's canonical JSON
    /// without its signature (the field order of this type; numbers in shortest round-trip form),
    /// and the attestation's JSON. A reader parses the artifact, sets the signature aside and
    /// serialises it again to check.
    pub fn signed_message(&self, attests: &Attestation) -> Vec<u8> {
        let unsigned = Self { signature: None, ..self.clone() };
        let digest = sha256_hex(&serde_json::to_vec(&unsigned).expect("an artifact serialises"));
        let attests = serde_json::to_vec(attests).expect("an attestation serialises");
        [ARTIFACT_SIGNATURE_DOMAIN, digest.as_bytes(), b"\n", &attests].concat()
    }
}

/// What an artifact holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum WeightsKind {
    /// A table on cells.
    Table,
    /// One per-path strategy.
    Heuristic,
    /// A table with heuristics stacked on it.
    Stack,
}

/// The model scene's parameters (docs/model.md §1–§4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ArtifactScene {
    /// Distance from plane 1 (the pixel's plane, z = 0) to plane 2.
    pub l2: f64,
    /// Distance from plane 2 to plane 3.
    pub l3: f64,
    /// The lobe's width β of plane 2, radians.
    pub beta_rad: f64,
    /// The merge radius R.
    pub merge_radius: f64,
    /// N_F, light paths per iteration.
    pub light_paths: f64,
    /// N_B, camera paths per iteration.
    pub camera_paths: f64,
    /// The light's radial profile on plane 3: rings [inner, outer) with their levels, innermost
    /// first; the start density is level/flux inside a ring, 0 outside every ring.
    pub rings: Vec<ArtifactRing>,
    /// Φ, the total flux of the levels (Σ level × ring area).
    pub flux: f64,
}

/// One ring of the light's profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ArtifactRing {
    /// Inner radius (inclusive).
    pub inner: f64,
    /// Outer radius (exclusive).
    pub outer: f64,
    /// Level (unnormalised).
    pub level: f64,
}

/// The table's axes (docs/model.md §7): r2 = |x2|, r3 = |x3| (radii on planes 2 and 3 from the
/// axis through the pixel), φ the angle between the vectors x2 and x3 folded to [0, π].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct CellAxes {
    /// Edges of r2 from 0: bin k is [e_k, e_{k+1}), the last [e_last, ∞).
    pub r2_edges: Vec<f64>,
    /// Edges of r3, likewise.
    pub r3_edges: Vec<f64>,
    /// Equal bins of φ over [0, π]: bin ⌊φ/π·n⌋ (the last includes π).
    pub phi_bins: u32,
}

/// One cell of the table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct TableCell {
    /// Its r2 bin.
    pub r2: usize,
    /// Its r3 bin.
    pub r3: usize,
    /// Its φ bin.
    pub phi: usize,
    /// (T₀, T₁, T₂): the table's weights of techniques 0, 1, 2.
    pub w: [f64; 3],
}

/// One per-path heuristic of the function.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ArtifactHeuristic {
    /// Its name in results (`correlation_aware_planes23`).
    pub name: String,
    /// Its coefficient β.
    pub beta: f64,
    /// What it computes.
    pub formula: Formula,
    /// Which techniques it weighs (the planes-2–3 variants: [false, true, true]); the others get 0
    /// and those it weighs are renormalised among themselves.
    pub techniques: [bool; 3],
}

/// A heuristic's formula (docs/model.md §9).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Formula {
    /// Weight 1 on one technique.
    OneTechnique {
        /// The technique (0, 1 or 2).
        technique: usize,
    },
    /// The paper's case 4: technique 1 if r3 ≤ radius, else technique 2 (technique 0 never).
    Switch {
        /// The switch's radius a on plane 3.
        radius: f64,
    },
    /// Veach's balance heuristic: w_m = p_m / Σ p_k.
    Balance,
    /// The power heuristic: w_m = p_m^e / Σ p_k^e.
    Power {
        /// The exponent e (2).
        exponent: f64,
    },
    /// The correlation-aware balance heuristic: w_m = n_m p_m / Σ n_k p_k with effective counts
    /// n_m from the surrogate probabilities of the footprint `area` (docs/model.md §9).
    CorrelationAware {
        /// The footprint A = πR².
        area: f64,
        /// N_F.
        light_paths: f64,
        /// N_B.
        camera_paths: f64,
    },
}

/// Where an artifact's weights come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ArtifactProvenance {
    /// The configuration fingerprint of the moments the weights were fitted to.
    pub fingerprint: String,
    /// Iterations of those moments.
    pub iterations: u64,
    /// The (seed, iteration range) pairs they cover: scoring the weights on iterations they were
    /// fitted to is in-sample, and `optimis evaluate` says so.
    pub coverage: Coverage,
    /// λ of a fitted row (null for a per-path row).
    pub lambda: Option<f64>,
    /// The row's cross-fitted (fitted rows) or measured RMS%, and its SE, on those iterations.
    pub rms_percent: Option<f64>,
    /// The SE of `rms_percent`.
    pub rms_percent_stderr: Option<f64>,
    /// The server's job, when it came from one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job_id: Option<i64>,
    /// What made it: `optimis <version>`.
    pub generator: String,
}
