//! The per-path strategies — the MIS weights the engines apply to every merge, as functions of its
//! whole join path — and the three merge techniques they weigh: the catalogue the tallies sum
//! per strategy, the moments keep (`engines::layout`) and the noise table names.

use serde::{Deserialize, Serialize};

use std::f64::consts::PI;

use crate::sim::math::plane::radius;
use crate::sim::model::config::SimConfig;
use crate::sim::model::heuristics::{JoinGeometry, Sharing, VertexDensities, balance, correlation_aware, power};

/// The strategies whose weights are functions of the whole join path, tallied per iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum PathStrategy {
    /// w0 = 1.
    Plane1,
    /// w1 = 1.
    Plane2,
    /// w2 = 1.
    Plane3,
    /// w1 = 1 if the join path's r3 ≤ a (exactly, not by cell), else w2 = 1.
    Switch,
    /// Veach's balance heuristic with VCM pdfs.
    Balance,
    /// Veach's power heuristic (exponent 2) with VCM pdfs.
    Power,
    /// The correlation-aware balance heuristic (Grittmann et al. 2021), its effective sample counts
    /// derived for the N_F × N_B pairs of an iteration (`model::heuristics`).
    CorrelationAware,
    /// The balance heuristic over planes 2 and 3 only (w0 = 0, the other two renormalised): the
    /// variant that keeps the paper's fixed weight, so the stacked optimum can contain it.
    BalancePlanes23,
    /// The power heuristic over planes 2 and 3 only (w0 = 0).
    PowerPlanes23,
    /// The correlation-aware heuristic over planes 2 and 3 only (w0 = 0).
    CorrelationAwarePlanes23,
}

impl PathStrategy {
    /// Every per-path strategy, in the order the moments keep their sums. Strategies are only
    /// ever appended: a moments format keeps a prefix of this list (`stats::layout`).
    pub const ALL: [PathStrategy; 10] = [
        Self::Plane1,
        Self::Plane2,
        Self::Plane3,
        Self::Switch,
        Self::Balance,
        Self::Power,
        Self::CorrelationAware,
        Self::BalancePlanes23,
        Self::PowerPlanes23,
        Self::CorrelationAwarePlanes23,
    ];
    /// How many per-path strategies there are: the length of every per-strategy array.
    pub const COUNT: usize = Self::ALL.len();

    /// The strategies whose weights are not constant per cell, and so can widen the tabulated
    /// weights (docs/model.md §7, the stacked optimum): every per-path strategy but the three
    /// single-plane cases, which a table already contains.
    pub const STACKABLE: [PathStrategy; 7] = [
        Self::Switch,
        Self::Balance,
        Self::Power,
        Self::CorrelationAware,
        Self::BalancePlanes23,
        Self::PowerPlanes23,
        Self::CorrelationAwarePlanes23,
    ];

    /// The heuristics the stacked optimum puts on its table together (docs/model.md §7): the
    /// switch and the correlation-aware heuristic (over all planes, and renormalised over planes
    /// 2–3). The balance and power heuristics weigh paths by the same densities as the
    /// correlation-aware one, so their columns differ from its column by little: stacked together,
    /// their coefficients trade off against one another (β of ±3 with SEs as large at 10⁴
    /// iterations, docs/results.md §10) and the fit pays for that noise. Each of them is still
    /// corrected by a table on its own (the `…_corrected` rows).
    pub const STACKED: [PathStrategy; 3] = [Self::Switch, Self::CorrelationAware, Self::CorrelationAwarePlanes23];

    /// Position in [`PathStrategy::ALL`] (the index of its sums in the moments).
    pub fn index(self) -> usize {
        self as usize
    }

    /// Whether this is one of the paper's fixed cases 1–4 (a weight of one on a plane, or the
    /// switch), as opposed to a heuristic that weighs each merge by its path densities.
    pub fn is_case(self) -> bool {
        matches!(self, Self::Plane1 | Self::Plane2 | Self::Plane3 | Self::Switch)
    }

    /// The weights (w0, w1, w2) this strategy gives every join path, where they do not depend on
    /// the path (`None` where they do): what decides whether it keeps a solver's fixed weights.
    /// The switch never merges at the pixel (w0 = 0) but chooses w1 or w2 by r3; the heuristics
    /// give every technique a share that depends on the path.
    pub fn constant_weights(self) -> [Option<f64>; 3] {
        match self {
            Self::Plane1 => [Some(1.0), Some(0.0), Some(0.0)],
            Self::Plane2 => [Some(0.0), Some(1.0), Some(0.0)],
            Self::Plane3 => [Some(0.0), Some(0.0), Some(1.0)],
            Self::Switch | Self::BalancePlanes23 | Self::PowerPlanes23 | Self::CorrelationAwarePlanes23 => {
                [Some(0.0), None, None]
            }
            Self::Balance | Self::Power | Self::CorrelationAware => [None, None, None],
        }
    }

    /// Whether its weights depend on N_F and N_B (so its noise at another budget cannot be
    /// predicted from the components of a run at this one): the correlation-aware heuristic's
    /// effective sample counts do; the cases and the VCM balance and power heuristics (whose pdfs
    /// are the techniques' relative densities) do not.
    pub const fn depends_on_budget(self) -> bool {
        matches!(self, Self::CorrelationAware | Self::CorrelationAwarePlanes23)
    }

    /// The name used in results.
    pub fn name(self) -> &'static str {
        match self {
            Self::Plane1 => "plane1",
            Self::Plane2 => "plane2",
            Self::Plane3 => "plane3",
            Self::Switch => "switch",
            Self::Balance => "balance",
            Self::Power => "power",
            Self::CorrelationAware => "correlation_aware",
            Self::BalancePlanes23 => "balance_planes23",
            Self::PowerPlanes23 => "power_planes23",
            Self::CorrelationAwarePlanes23 => "correlation_aware_planes23",
        }
    }
}

/// The three merge techniques, by the plane where the merge happens (docs/model.md: the weights w0,
/// w1, w2 and the contributions C0, C1, C2 are indexed the same way).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Technique {
    /// Merge at the pixel (plane 1): C0, weight w0.
    Plane1 = 0,
    /// Merge at plane 2: C1, weight w1.
    Plane2 = 1,
    /// Merge at plane 3: C2, weight w2.
    Plane3 = 2,
}

impl Technique {
    /// The index m of w_m and C_m.
    #[inline]
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Weights every per-path strategy gives a merge by `technique` on the join path (x2, x3), whose
/// light path starts at `x3_light` (x3 itself, except for a plane-3 merge, whose join path takes
/// the camera's x3c: the correlation-aware weights read the light's density where its path starts,
/// see `model::heuristics`).
#[inline]
pub fn strategy_weights(
    config: &SimConfig,
    technique: Technique,
    x2: [f64; 2],
    x3: [f64; 2],
    x3_light: [f64; 2],
) -> [f64; PathStrategy::COUNT] {
    strategy_weights_with(config, technique, x2, x3, light_start(config, x3_light))
}

/// The light's start density p_l(x3l) = I(x3l)/Φ where the light path starts: the one input of
/// the weights that a plane-3 merge takes from the light path rather than the camera's (see
/// `model::heuristics`), so the engine can reuse a camera's weights for every light path with the
/// same start density.
#[inline]
pub fn light_start(config: &SimConfig, x3_light: [f64; 2]) -> f64 {
    config.scene.illumination.density(radius(x3_light))
}

/// [`strategy_weights`] given the light's start density (see [`light_start`]).
#[inline]
pub fn strategy_weights_with(
    config: &SimConfig,
    technique: Technique,
    x2: [f64; 2],
    x3: [f64; 2],
    light_start: f64,
) -> [f64; PathStrategy::COUNT] {
    PathWeights::new(config, x2, x3).of(technique, light_start)
}

/// What every strategy's weights on one join path (x2, x3) share, whichever technique merged it
/// and wherever its light path started: the geometry's densities (an angle, an `exp`) and the
/// switch's side. The expected-luminance quadrature weighs one join path by all three techniques
/// and several light starts, so it computes these once; the engines weigh a merge by one.
#[derive(Debug, Clone, Copy)]
pub struct PathWeights<'a> {
    config: &'a SimConfig,
    inside: bool,
    densities: [f64; 3],
    vertices: VertexDensities,
}

impl<'a> PathWeights<'a> {
    /// The shared part of the weights of the join path (x2, x3).
    #[inline]
    pub fn new(config: &'a SimConfig, x2: [f64; 2], x3: [f64; 2]) -> Self {
        let scene = &config.scene;
        let geometry = JoinGeometry::new(scene, x2, x3);
        Self {
            config,
            inside: radius(x3) <= scene.illumination.switch_radius(),
            densities: geometry.technique_densities(scene),
            vertices: geometry.vertex_densities(scene),
        }
    }

    /// Every per-path strategy's weight of a merge by `technique` on this join path, whose light
    /// path starts where its density is `light_start` (see [`light_start`]).
    #[inline]
    pub fn of(&self, technique: Technique, light_start: f64) -> [f64; PathStrategy::COUNT] {
        self.of_at(technique, light_start, self.config)
    }

    /// [`PathWeights::of`] under `config`, the same scene at another merge radius (a smaller
    /// radius a run tallies): only the correlation-aware heuristics read R (the footprint area
    /// πR² of their sharing probabilities), so the geometry is computed once for every radius.
    #[inline]
    pub fn of_at(&self, technique: Technique, light_start: f64, config: &SimConfig) -> [f64; PathStrategy::COUNT] {
        let plane = technique.index();
        let one_hot = |m: usize| if plane == m { 1.0 } else { 0.0 };
        let switch = match plane {
            1 if self.inside => 1.0,
            2 if !self.inside => 1.0,
            _ => 0.0,
        };
        let p = self.densities;
        let area = PI * config.merge_radius * config.merge_radius;
        let sharing = Sharing::new(&self.vertices, light_start, area);
        let (nf, nb) = (config.light_paths as f64, config.camera_paths as f64);
        let correlated = correlation_aware(p, &sharing, nf, nb);
        // The w0 = 0 variants: the same heuristics with technique 0 removed (p₀ = 0), i.e.
        // renormalised over planes 2 and 3 — what the paper's fixed weights allow.
        let p23 = [0.0, p[1], p[2]];
        [
            one_hot(0),
            one_hot(1),
            one_hot(2),
            switch,
            balance(p)[plane],
            power(p)[plane],
            correlated[plane],
            balance(p23)[plane],
            power(p23)[plane],
            correlation_aware(p23, &sharing, nf, nb)[plane],
        ]
    }
}
