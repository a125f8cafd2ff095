//! The rules of the expected-luminance quadrature ([`super`]): the product rules for averages over
//! the merge disc, the disc–ring overlap areas in closed form, the deflection angle, and the
//! vector-valued adaptive Gauss–Kronrod over the outer panels.

use std::f64::consts::PI;

use rayon::prelude::*;

use super::super::quadrature::{Budget, ReferenceError, WG, WGK, XGK};
use super::{MAX_KERNEL_RATIO, Values};
use crate::sim::engines::strategies::PathStrategy;

/// A product rule for the average over a disc of radius R: the centre's weight and the other
/// nodes as offsets with weights (module doc).
#[derive(Debug, Clone)]
pub(super) struct DiscRule {
    pub(super) centre: f64,
    pub(super) points: Vec<([f64; 2], f64)>,
}

/// Gauss–Radau rules in t = ρ²/R² on [0, 1] with a node at t = 0 (weight 1/n²): the other nodes
/// and weights, for n = 1…5, and the largest κ each serves (module doc).
pub(super) const RADAU: [(f64, &[(f64, f64)]); 5] = [
    (1e-5, &[]),
    (0.13, &[(0.666_666_666_666_666_6, 0.75)]),
    (0.55, &[(0.355_051_025_721_682_2, 0.512_485_826_188_421_6), (0.844_948_974_278_317_8, 0.376_403_062_700_467_3)]),
    (
        1.0,
        &[
            (0.212_340_538_239_152_94, 0.328_844_319_980_059_75),
            (0.590_533_135_559_265_3, 0.388_193_468_843_171_9),
            (0.911_412_040_487_296_1, 0.220_462_211_176_768_37),
        ],
    ),
    (
        MAX_KERNEL_RATIO,
        &[
            (0.139_759_864_343_780_54, 0.223_103_901_083_570_76),
            (0.416_409_567_631_083_17, 0.311_826_522_975_741_26),
            (0.723_156_986_361_876_2, 0.281_356_015_149_462_07),
            (0.942_895_803_885_482_3, 0.143_713_560_791_225_94),
        ],
    ),
];

impl DiscRule {
    /// The smallest rule that averages a lobe of footprint `radius`/`kappa` over a disc of radius
    /// `radius` to ≤ 3·10⁻⁹ (None beyond [`MAX_KERNEL_RATIO`]).
    pub(super) fn for_ratio(kappa: f64, radius: f64) -> Option<Self> {
        let (n, &(_, rings)) = RADAU.iter().enumerate().find(|(_, (limit, _))| kappa <= *limit)?;
        let angles = 4 * n + 2;
        let mut points = Vec::with_capacity(n * angles);
        for &(t, w) in rings {
            let rho = radius * t.sqrt();
            for l in 0..angles {
                let (sin, cos) = (2.0 * PI * l as f64 / angles as f64).sin_cos();
                points.push(([rho * cos, rho * sin], w / angles as f64));
            }
        }
        Some(Self { centre: 1.0 / ((n + 1) * (n + 1)) as f64, points })
    }
}

#[inline(always)]
pub(super) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The angle between two (not necessarily unit) vectors, accurate near 0.
#[inline(always)]
pub(super) fn deflection(a: [f64; 3], b: [f64; 3]) -> f64 {
    let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    libm::atan2(dot(cross, cross).sqrt(), dot(a, b))
}

/// The share of the disc of radius `r` centred at distance `d` from the origin that lies within
/// radius `rho` of the origin: |D(p, r) ∩ D(0, ρ)|/(πr²), in closed form (two circular segments
/// cut by the common chord), without cancellation for r ≪ ρ.
pub(in crate::sim::checks) fn disc_fraction_inside(d: f64, r: f64, rho: f64) -> f64 {
    if rho <= 0.0 || d >= r + rho {
        return 0.0;
    }
    if d + r <= rho {
        return 1.0;
    }
    if d + rho <= r {
        return (rho / r).powi(2);
    }
    // The chord's distances from the origin (x_o) and from the disc's centre (x_p), signed
    // towards each other, and its half-length h, from differences that stay accurate for r ≪ ρ.
    let delta = d - rho;
    let x_p = (delta * (d + rho) + r * r) / (2.0 * d);
    let x_o = rho - (r - delta) * (r + delta) / (2.0 * d);
    let h = ((r - x_p) * (r + x_p)).max(0.0).sqrt();
    // A segment of half-angle α of a circle of radius c has the area c²(α − sin α cos α).
    let segment = |alpha: f64| {
        let x = 2.0 * alpha;
        if x < 0.1 {
            // (x − sin x)/2 by its series: no cancellation for thin segments.
            let x2 = x * x;
            x * x2 / 12.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0))))
        } else {
            0.5 * (x - x.sin())
        }
    };
    let share = (segment(h.atan2(x_p)) + (rho / r).powi(2) * segment(h.atan2(x_o))) / PI;
    share.clamp(0.0, 1.0)
}

/// Vector-valued global adaptive Gauss–Kronrod (7/15) over `panels` panels t ∈ [0, 1] of `f`:
/// the piece with the largest error estimate (max over strategies of |Kronrod − Gauss|) is
/// bisected until the summed estimates fall below `tol` of the largest strategy's value.
pub(super) fn adaptive_gk(
    f: &(dyn Fn(usize, f64) -> Values + Sync),
    panels: usize,
    tol: f64,
    budget: &Budget<'_>,
) -> Result<Values, ReferenceError> {
    struct Piece {
        panel: usize,
        a: f64,
        b: f64,
        value: Values,
        error: f64,
    }
    let rule = |panel: usize, a: f64, b: f64| -> Piece {
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        // The 15 nodes: the centre, then each ±XGK[i]. Every node is an inner integral of its own,
        // so when called on a rayon pool (the command line's, which is idle once the run is done)
        // they are evaluated in parallel — the same values, combined in the same order below.
        let node = |k: usize| match k {
            0 => mid,
            k if k % 2 == 1 => mid - half * XGK[k / 2],
            k => mid + half * XGK[k / 2 - 1],
        };
        let mut values = [[0.0; PathStrategy::COUNT]; 15];
        if rayon::current_thread_index().is_some() && rayon::current_num_threads() > 1 {
            values.par_iter_mut().enumerate().for_each(|(k, v)| *v = f(panel, node(k)));
        } else {
            values.iter_mut().enumerate().for_each(|(k, v)| *v = f(panel, node(k)));
        }
        let centre = values[0];
        let mut kronrod = centre.map(|c| WGK[7] * c);
        let mut gauss = centre.map(|c| WG[3] * c);
        for i in 0..7 {
            let (left, right) = (values[2 * i + 1], values[2 * i + 2]);
            for s in 0..PathStrategy::COUNT {
                let pair = left[s] + right[s];
                kronrod[s] += WGK[i] * pair;
                if i % 2 == 1 {
                    gauss[s] += WG[i / 2] * pair;
                }
            }
        }
        let error = kronrod.iter().zip(&gauss).fold(0.0f64, |m, (k, g)| m.max(half * (k - g).abs()));
        Piece { panel, a, b, value: kronrod.map(|k| half * k), error }
    };
    let mut pieces: Vec<Piece> = (0..panels).map(|p| rule(p, 0.0, 1.0)).collect();
    loop {
        if budget.spent() {
            return Err(ReferenceError::NotConverged);
        }
        let total: Values = std::array::from_fn(|s| pieces.iter().map(|p| p.value[s]).sum());
        let scale = total.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let error: f64 = pieces.iter().map(|p| p.error).sum();
        if error <= tol * scale {
            return Ok(total);
        }
        let worst = (0..pieces.len()).max_by(|&i, &j| pieces[i].error.total_cmp(&pieces[j].error)).expect("panels");
        let Piece { panel, a, b, .. } = pieces.swap_remove(worst);
        let mid = 0.5 * (a + b);
        if !(a < mid && mid < b) {
            return Err(ReferenceError::NotConverged);
        }
        pieces.push(rule(panel, a, mid));
        pieces.push(rule(panel, mid, b));
    }
}
