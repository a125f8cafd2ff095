//! Noise components: the sums that let one run predict the noise at any other N_F and N_B.
//!
//! # The decomposition (docs/model.md §12)
//!
//! An iteration's value is Y = (1/(N_F N_B)) Σ_i Σ_j c(η_i, ξ_j) over its light paths η_i and camera
//! paths ξ_j (each entry of the moment vector is such a sum, with its own c). For two entries a, b
//! let Q_same = E[c^a c^b] of one pair, Q_L = E[c^a(η, ξ) c^b(η, ξ')] of two pairs sharing their
//! light path, Q_C = E[c^a(η, ξ) c^b(η', ξ)] sharing their camera path, Q_0 = E c^a · E c^b. Counting
//! the pairs of pairs,
//!
//! * brute force (N_F paths): Cov(Y_a, Y_b) = α/(N_F N_B) + β/N_F + δ/N_B with α = Q_same − Q_L −
//!   Q_C + Q_0, β = Q_L − Q_0, δ = Q_C − Q_0;
//! * restricted engine (a Poisson process of intensity N_F, whose factorial moment measure makes
//!   E Σ_{i≠i'} f(η_i, η_i') = N_F² ∫∫ f): the same form with α = Q_same − Q_L, β = Q_L, δ = Q_C − Q_0
//!   (E c² and the second moment Q_L take the place of the covariances on the light side).
//!
//! # The estimators
//!
//! Split the light paths in halves L ∈ {0, 1} of N_F/2 paths (the brute force alternates; the
//! restricted engine tosses a fair coin per path, which leaves two independent Poisson processes
//! of intensity N_F/2) and the camera paths in halves K of N_B/2, and let y_LK be block LK's own
//! estimate of the pixel, (1/((N_F/2)(N_B/2))) Σ_{i∈L, j∈K} c. Blocks that share no half are
//! independent, so E[y_00 y_11ᵀ] = E[y_01 y_10ᵀ] = Q_0. Two blocks sharing light half L pair each of
//! its paths with two disjoint camera halves; counting as above, in both engines,
//! E[y_L0 y_L1ᵀ] = Q_0 + β/(N_F/2), and likewise E[y_0K y_1Kᵀ] = Q_0 + δ/(N_B/2). Hence, with
//! U_L, U_C, U_0 the per-iteration products below (averaged over their two instances and made
//! symmetric, which keeps the expectations),
//!
//!   β̂ = (N_F/2)·(Ū_L − Ū_0),   δ̂ = (N_B/2)·(Ū_C − Ū_0),
//!
//! unbiased as linear combinations of unbiased means. With V̂ the sample covariance of Y (unbiased),
//! α̂ = N_F N_B (V̂ − β̂/N_F − δ̂/N_B), and the prediction V̂' = α̂/(N_F' N_B') + β̂/N_F' + δ̂/N_B' is
//! unbiased for Cov(Y) at (N_F', N_B') — for every entry of ΣYYᵀ (so for the optimal weights'
//! objective) and for every per-path strategy whose weights do not depend on N_F or N_B.
//!
//! The sums are exact and kept per fold like the rest of the moments, so shards and merges stay
//! bit-identical and the prediction can be cross-fitted and jackknifed over folds.
//!
//! # Which entries
//!
//! The matrices cover the leading [`Layout::component_dimension`] entries of Y: since format 4,
//! A, B and the switch's H column — what a prediction at another budget can use. The other H
//! columns are those of the correlation-aware heuristics, whose weights change with N_F and N_B
//! (so no prediction of their rows exists), and of the balance and power heuristics, which no
//! predicted row stacks; with them the block products were four times as many (issue 26).

use serde::{Deserialize, Serialize};

use super::bounded::bounded;
use crate::sim::engines::layout::{Layout, MAX_PACKED};
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::math::exact_sum::ExactSum;
use crate::sim::model::config::packed_len;

/// The three kinds of block pairs, as indices of [`ComponentSums::matrix`]: blocks sharing a
/// light half (U_L).
pub const LIGHT: usize = 0;
/// Blocks sharing a camera half (U_C).
pub const CAMERA: usize = 1;
/// Blocks sharing nothing (U_0).
pub const CROSS: usize = 2;

/// Σ over a fold's iterations of the symmetrised block products.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ComponentSums {
    /// Σ_s U_L = ½ Σ_L sym(y_L0 y_L1ᵀ) (blocks sharing a light half), packed like ΣYYᵀ over the
    /// leading [`Layout::component_dimension`] entries of Y.
    #[serde(deserialize_with = "bounded::<_, _, MAX_PACKED>")]
    pub light: Vec<ExactSum>,
    /// Σ_s U_C = ½ Σ_K sym(y_0K y_1Kᵀ) (sharing a camera half).
    #[serde(deserialize_with = "bounded::<_, _, MAX_PACKED>")]
    pub camera: Vec<ExactSum>,
    /// Σ_s U_0 = ½ (sym(y_00 y_11ᵀ) + sym(y_01 y_10ᵀ)) (sharing nothing).
    #[serde(deserialize_with = "bounded::<_, _, MAX_PACKED>")]
    pub cross: Vec<ExactSum>,
    /// Per path strategy the format keeps (a prefix of [`PathStrategy::ALL`]): Σ U_L, Σ U_C, Σ U_0
    /// of its C_s.
    #[serde(deserialize_with = "bounded::<_, _, { PathStrategy::COUNT }>")]
    pub strategies: Vec<[ExactSum; 3]>,
}

impl ComponentSums {
    /// Zero sums for the moment vectors of `layout`.
    pub fn empty(layout: Layout) -> Self {
        let zeros = || vec![ExactSum::new(); packed_len(layout.component_dimension())];
        Self {
            light: zeros(),
            camera: zeros(),
            cross: zeros(),
            strategies: vec![Default::default(); layout.strategies().len()],
        }
    }

    /// Whether the lists have the lengths of `layout`.
    pub fn has_shape(&self, layout: Layout) -> bool {
        let n = layout.component_dimension();
        [&self.light, &self.camera, &self.cross].iter().all(|m| m.len() == packed_len(n))
            && self.strategies.len() == layout.strategies().len()
    }

    /// The packed sums of one kind.
    pub fn matrix(&self, kind: usize) -> &[ExactSum] {
        [&self.light, &self.camera, &self.cross][kind]
    }

    /// Every sum, for checks that treat them alike.
    pub fn sums(&self) -> impl Iterator<Item = &ExactSum> {
        self.light.iter().chain(&self.camera).chain(&self.cross).chain(self.strategies.iter().flatten())
    }

    /// Every sum, mutably, in the order of [`ComponentSums::sums`].
    fn sums_mut(&mut self) -> impl Iterator<Item = &mut ExactSum> {
        self.light
            .iter_mut()
            .chain(self.camera.iter_mut())
            .chain(self.cross.iter_mut())
            .chain(self.strategies.iter_mut().flatten())
    }

    /// Adds `other` (of the same shape; checked by the caller).
    pub fn add(&mut self, other: &ComponentSums) {
        for (a, b) in self.sums_mut().zip(other.sums()) {
            a.add_sum(b);
        }
    }
}
