//! Exact expectations the engines' merge counts are checked against (the densities behind them are
//! in [`crate::sim::model::densities`]).
//!
//! Given the camera paths of an iteration, a light path merges at plane p with camera path j
//! exactly when its vertex x_pl falls in the disc D(x_pc_j, R), so the merges at plane p have the
//! expectation N_F · Σ_j P(x_pl ∈ D(x_pc_j, R)). Both probabilities have closed forms that no
//! engine uses, which makes them an analytic reference for either one on any light profile:
//!
//! * plane 3: x3l has the density I(|x|)/Φ (`sim::model::illumination`), piecewise constant on rings, so
//!   P(x3l ∈ D(c, R)) = Σ_k (level_k/Φ)·|D(c, R) ∩ ring_k|, and the area of a disc within the
//!   annulus r_in ≤ r < r_out is the difference of its overlaps with the discs of radii r_out and
//!   r_in;
//! * plane 2: x2l is x3l displaced by a cosine-distributed direction over the distance L3, whose
//!   density on plane 2 is the Lambert kernel q(d) = L3²/(π(L3² + |d|²)²). Its integral over a disc
//!   of sources of radius r, seen from c, is the configuration factor of a parallel disc,
//!   G(r, c) = ½[1 − (L3² + c² − r²)/√((L3² + c² + r²)² − 4r²c²)], so x2l has the density
//!   p2(c) = Σ_k (level_k/Φ)·(G(r_out_k, c) − G(r_in_k, c)). As a convolution with q, p2 is smooth
//!   on the scale L3, so P(x2l ∈ D(c, R)) = πR²·p2(c)·(1 + O(R²/L3²)) (midpoint rule on the disc:
//!   the relative error is about R²/8·|∇²p2|/p2 ≈ 10⁻⁷ at the paper's R and L3, tested below).

use crate::sim::engines::camera::CameraSet;
use crate::sim::model::config::SimConfig;
use crate::sim::model::densities::{arrival_density, start_probability_in_disc};

use std::f64::consts::PI;

/// The exact mean of a merge count and a bound on its variance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CountExpectation {
    /// The exact expected count.
    pub mean: f64,
    /// An upper bound on the variance (see `count_given`).
    pub variance_bound: f64,
}

impl CountExpectation {
    /// How many standard deviations (at the variance bound: a conservative z) `observed` is from
    /// the mean.
    pub fn z(&self, observed: f64) -> f64 {
        (observed - self.mean) / self.variance_bound.sqrt()
    }
}

/// Expected plane-2 and plane-3 merge events (with variance bounds).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MergeExpectation {
    /// Plane-2 merge events of the iteration.
    pub plane2: CountExpectation,
    /// Plane-3 merge events of the iteration.
    pub plane3: CountExpectation,
}

/// Exact expectation of the plane-2 and plane-3 merge events of one iteration given its camera
/// paths, with bounds on their variance (see `count_given`).
pub fn merges_given(config: &SimConfig, cameras: &CameraSet) -> MergeExpectation {
    let scene = &config.scene;
    let radius = config.merge_radius;
    let plane2: Vec<([f64; 2], f64)> = cameras
        .paths
        .iter()
        .map(|path| (path.x2, PI * radius * radius * arrival_density(&scene.illumination, scene.l3, path.x2)))
        .collect();
    let plane3: Vec<([f64; 2], f64)> = cameras
        .paths
        .iter()
        .filter_map(|path| path.x3)
        .map(|x3| (x3, start_probability_in_disc(&scene.illumination, x3, radius)))
        .collect();
    MergeExpectation {
        plane2: count_given(&plane2, radius, config.light_paths),
        plane3: count_given(&plane3, radius, config.light_paths),
    }
}

/// The merges at one plane from the camera vertices there and the probabilities p_j that a light
/// path's vertex falls within R of each.
///
/// A light path merges with K = Σ_j 1[x_l ∈ D_j] cameras (D_j = D(x_c_j, R)), so the count is a sum
/// of N_F independent copies of K (brute force) or a compound Poisson sum with intensity N_F
/// (restricted engine): its mean is N_F·Σ_j p_j and its variance at most N_F·E[K²] =
/// N_F·(Σ_j p_j + Σ_{j≠k} p_jk), with p_jk = P(x_l ∈ D_j ∩ D_k). The pair terms vanish unless the two
/// camera vertices are closer than 2R, and p_jk ≤ min(p_j, p_k); hence the bound
/// N_F·(Σ_j p_j + Σ_{j≠k, |x_c_j − x_c_k| < 2R} min(p_j, p_k)).
fn count_given(vertices: &[([f64; 2], f64)], radius: f64, light_paths: u64) -> CountExpectation {
    let singles: f64 = vertices.iter().map(|v| v.1).sum();
    // N_B² pairs per iteration: negligible beside the light paths this checks.
    let mut pairs = 0.0;
    for (j, (a, pa)) in vertices.iter().enumerate() {
        for (b, pb) in &vertices[j + 1..] {
            if (a[0] - b[0]).hypot(a[1] - b[1]) < 2.0 * radius {
                pairs += 2.0 * pa.min(*pb);
            }
        }
    }
    let n = light_paths as f64;
    CountExpectation { mean: n * singles, variance_bound: n * (singles + pairs) }
}

/// [`merges_given`] summed over iterations `iterations` of `seed` (independent given their camera
/// paths, which depend on the seed and the iteration only, not on the engine).
pub fn merges(config: &SimConfig, seed: u64, iterations: std::ops::Range<u64>) -> MergeExpectation {
    let add = |a: CountExpectation, b: CountExpectation| CountExpectation {
        mean: a.mean + b.mean,
        variance_bound: a.variance_bound + b.variance_bound,
    };
    iterations.map(|s| merges_given(config, &CameraSet::generate(config, seed, s))).fold(
        MergeExpectation::default(),
        |acc, e| MergeExpectation { plane2: add(acc.plane2, e.plane2), plane3: add(acc.plane3, e.plane3) },
    )
}
