//! The expected luminance of every per-path strategy *at the configuration's merge radius R*, by
//! deterministic quadrature: E\[C_s\] of the estimator exactly as the engines define it
//! (docs/model.md §4, §5, §8, §9), kernel averages included. [`super::quadrature`] gives the
//! R → 0 limit that all strategies share (§11); at a finite R their expectations differ from it,
//! and from each other, so a Monte-Carlo mean is judged against this module's value, not the limit.
//! Nothing here is used to compute a result, and nothing is shared with the sampling but the
//! weights: they come from [`PathWeights`], what the engines' [`strategy_weights`] computes, so
//! every strategy of [`PathStrategy::ALL`] is covered, including strategies added to it later.
//!
//! # Derivation
//!
//! One iteration averages all N_F·N_B pairs (§5); pairs are identically distributed (their
//! correlation changes the variance, not the mean), and a plane-1 merge is tallied once per light
//! path as N_B·C0, so E\[C_s\] = Σ_m E[w_m^s·C_m] over one pair (camera path ξ, light path η) with
//! independent sub-paths. The restricted engine draws a Poisson process with the same intensity,
//! which keeps every such sum's expectation (§6), so both engines estimate this value. Densities
//! per unit area (§9), d1 = |x2 − x1| and d2 = |x3 − x2| in 3-D, ϑ the deflection at x2,
//! q = g·ϑ/sin ϑ the sampled lobe's pdf, and energies (§3):
//!
//! * camera: p_c(x2) = L2²/(π d1⁴), p_c(x3 | x2) = q·L3/d2³, E_c(x3) = (L3/d2)/(L2/d1)·sin ϑ/ϑ;
//! * light: p_l(x3) = I(x3)/Φ, p_l(x2 | x3) = L3²/(π d2⁴), then the lobe (pdf q, energy sin ϑ/ϑ).
//!
//! In every product below the lobe's ϑ/sin ϑ cancels against the energy, leaving g. With
//! K = 1/(πR²) on the disc D(·, R), ⟨h⟩_D its average of h, and
//! F(x2, x3) = (L2/d1³)(L3²/d2⁴)·g(ϑ(x2, x3)) (the integrand of §11):
//!
//! * **Plane 3** (C2 = E_c(x3c)·K/π, weight w2(x2c, x3c; x3l)): p_c(x2)p_c(x3|x2)E_c(x3) =
//!   (1/π)·F, and the light's start is averaged over the disc around the camera's x3c. The weight
//!   reads x3l only through the light's start density I(x3l)/Φ (the correlation-aware heuristic's
//!   P_l,2; checked for every strategy, see below), which is constant on each ring k of the
//!   profile, so the disc splits by ring:
//!   E2 = (1/π²)∫dA3 ∫dA2 F(x2, x3)·Σ_k (I_k/Φ)·(|D(x3, R) ∩ ring_k|/πR²)·w2(x2, x3; ring k).
//! * **Plane 2** (C1 = K·f2(x3l→x2l, x2c→0), weight w1(x2c, x3l)): p_c(x2c)·f2 = (1/π)(L2/d1³)·g
//!   (f2 = g/cos θ1, cos θ1 = L2/d1), the light's x2l is averaged over the disc around x2c, and
//!   the deflection is the one between the light's incident direction x3→x2l and the camera's
//!   x2c→0:
//!   E1 = (1/π²)∫dA3 (I(x3)/Φ) ∫dA2 (L2/d1³)·w1(x2, x3)·⟨(L3²/|x2′ − x3|⁴)·g(ϑ(x3→x2′, x2→0))⟩_{x2′ ∈ D(x2, R)}.
//! * **Plane 1** (C0 = (sin ϑ/ϑ)·K/π, weight w0(x2l, x3l)): the light's lobe, dω = (L2/|x2 − x1|³)dA1,
//!   is averaged over the pixel's disc D(0, R):
//!   E0 = (1/π²)∫dA3 (I(x3)/Φ) ∫dA2 (L3²/d2⁴)·w0(x2, x3)·⟨(L2/|x2 − x1|³)·g(ϑ(x3→x2, x2→x1))⟩_{x1 ∈ D(0, R)}.
//!
//! As R → 0 every average becomes the value at its centre, every integrand becomes F·I/Φ, and
//! Σ_m w_m = 1 on every join path makes every strategy's sum the reference of §11 (tested to
//! 10⁻⁶). At finite R:
//!
//! * **A single plane** (w_m = 1) estimates the limit L averaged over pixel positions in D(0, R),
//!   whichever the plane: E_m = ∫∫K(x − y)·(camera side at x)·(light side at y), and transport
//!   between infinite parallel planes commutes with shifts, so offsetting the light's vertex by
//!   δ = y − x is offsetting the pixel by −δ (K is even). The three planes reach this value by
//!   different rules here (ring areas; disc rules on plane 2; on plane 1) and agree to 10⁻⁹
//!   (tested): a check of both. It is second order, L·(1 − 5·10⁻⁸) at the paper's R.
//! * **`switch`** is off by first order in R (§8): its rule reads the join path's x3 — x3c in E2,
//!   x3l in E1. A camera vertex just outside the spot's edge (plane 3 chosen) gathers the bright
//!   light inside through the disc; that light, started inside, is counted again at plane 2.
//!   E2's ring areas at r3 ∈ (a, a + R) hold exactly this: ≈ (4/3π)·(R/a)·G(a)/G(0) of the spot's
//!   share of L to first order; +0.507% at the paper's R (docs/results.md §1 measured +0.55% ±
//!   0.065% over 10⁶ iterations), +3.30% at R = a = 0.02.
//! * **The heuristics** (weights smooth across the disc) move by second order:
//!   −0.0005% (`balance`), −0.0003% (`power`), −0.0007% (`correlation_aware`) at the paper's R.
//!
//! Outside the spot the integrals reach r3 = r_out + R (plane 3: camera vertices outside the
//! emitting disc still merge with light inside it).
//!
//! # Numerics
//!
//! * **Outer integral over r3 = |x3|** (the scene is radially symmetric; x3 is put on the x axis):
//!   panels between the breakpoints {every ring edge e, |e − R|, e + R, the switch radius}, where
//!   I jumps, the ring areas have their (r − r0)^{3/2} tangency points and `switch` jumps. Each
//!   panel is mapped by r = r0 + (r1 − r0)(1 − cos πt)/2, which turns the tangencies into smooth
//!   t³ terms, and all panels are refined together by a global adaptive Gauss–Kronrod (7/15)
//!   bisection of the vector of all strategies until the summed |Kronrod − Gauss| is below 10⁻⁷
//!   of the largest strategy's value (an estimate that overstates the error of smooth integrands
//!   by orders of magnitude).
//! * **Inner integral over x2** as in [`super::quadrature`]: stretched polar coordinates around the
//!   straight-line point x2*, in which the lobe is round; 12-point Gauss–Legendre panels in s up to
//!   ϑ = (10 + κ)β (and a mapped tail where that deflection is capped at 3 rad); the trapezoidal rule in ψ,
//!   doubled until every strategy is stable to 10⁻⁷. Nodes where the lobe is below 10⁻¹⁸ of its
//!   peak are skipped.
//! * **Ring areas**: |D(x3, R) ∩ ring| in closed form (two circular segments, with a series for
//!   thin ones, so that R ≪ a loses no digits).
//! * **Disc averages** (planes 1 and 2): product rules on the disc, Gauss–Radau in t = ρ²/R² with a
//!   node at the centre (shared with F) and 4n − 2 equally spaced angles on each of the n − 1
//!   rings, exact for polynomials of degree 4n − 3; n grows with κ = R/(β·L) (L = L2 at plane 1,
//!   L3 at plane 2; the lobe's footprint on the plane is at least β·L wide): the centre alone for
//!   κ ≤ 10⁻⁵, 7 points to κ = 0.13, 21 to 0.55, 43 to 1, 73 to [`MAX_KERNEL_RATIO`]; beyond,
//!   [`ReferenceError::KernelTooWide`]. Their error on a Gaussian lobe is ≤ 3·10⁻⁹ of the lobe's
//!   value node by node (tested), and far less in the integral, where a disc average preserves
//!   the lobe's mass.
//!
//! **Approximations kept**: the lobe sampler's cap ϑ ≤ 8.57β (a missing mass of 2⁻⁵³, §3) is not
//! modelled. Quadrature and disc-rule errors, measured against far tighter settings: ≤ 2·10⁻¹⁰
//! of L on the paper's configuration, ≤ 6·10⁻⁹ at R = a = 0.02 (the `power` heuristic, whose
//! weights turn fastest across the lobe; see `ACCURACY`) — against standard errors of 10⁻³. The
//! paper's configuration takes 6.8·10⁶ evaluations, 0.34 s on one core (measured with the two
//! cores shared with another build), all strategies together.
//!
//! **Assumptions checked, not trusted**: a strategy's plane-3 weight reads the light's start only
//! through its ring, and every weight is a function of distances and angles (invariant under
//! rotations and reflections about the axis, which the radial outer integral and the ψ ↔ −ψ
//! symmetry use; the cells of §7 are). [`expected_luminances`] compares every strategy's weights
//! on a few join paths near each ring, for other starts across the ring and with the path rotated
//! and reflected; a strategy whose weights differ gets [`ReferenceError::UnsupportedWeights`]
//! instead of a wrong number.
//!
//! # Bounded work
//!
//! Like the reference, a call evaluates at most [`EVALUATION_BUDGET`] lobe integrands (a
//! strategy-weights call counts as [`WEIGHTS_COST`] of them): about a second on one core. A
//! configuration the rules cannot resolve within it reports [`ReferenceError::NotConverged`].
//!
//! Imports: crate::sim::checks::quadrature, crate::sim::engines, crate::sim::model

use std::f64::consts::PI;

pub use super::quadrature::MAX_KERNEL_RATIO;
use super::quadrature::{Budget, EVALUATION_BUDGET, ReferenceError, legendre_nodes, solve_monotone};
use crate::sim::engines::strategies::{PathStrategy, PathWeights, Technique, light_start, strategy_weights};
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::Lobe;
use rules::{DiscRule, adaptive_gk, deflection, disc_fraction_inside, dot};

/// One value per strategy of [`PathStrategy::ALL`], in its order.
pub(super) type Values = [f64; PathStrategy::COUNT];

/// The quadrature's accuracy settings.
#[derive(Debug, Clone, Copy)]
struct Accuracy {
    /// Relative tolerance of the outer integral: the summed Gauss–Kronrod error estimates (which
    /// overstate the error of smooth integrands by orders of magnitude).
    outer: f64,
    /// Relative tolerance of the ψ doubling of the inner integral.
    inner: f64,
    /// Gauss–Legendre points per panel in s.
    order: usize,
}

/// What every call uses: within 2·10⁻¹⁰ of far tighter settings on the paper's configuration,
/// 6·10⁻⁹ at R = a = 0.02 (`default_accuracy_is_far_below_the_statistics`). Both tolerances
/// are met with a wide margin: the error is that of the Gauss–Legendre order, set by the
/// `power` heuristic's weights, which turn fastest across the lobe.
const ACCURACY: Accuracy = Accuracy { outer: 1e-7, inner: 1e-7, order: 12 };

/// Budget units charged per call of [`strategy_weights`] (measured: about the cost of four lobe
/// integrands; it evaluates the geometry, a lobe pdf and every heuristic).
pub const WEIGHTS_COST: u64 = 4;

/// A node whose lobe factors are below this fraction of the lobe's peak is skipped (with its
/// weights): at most 10⁻¹⁷ of L from the whole tail.
const NEGLIGIBLE: f64 = 1e-18;

/// One strategy's expected luminance at the configuration's R, or why it is not available.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrategyExpectation {
    /// The per-path strategy.
    pub strategy: PathStrategy,
    /// Its expected luminance at the merge radius (the kernel's bias included), or why the
    /// quadrature could not give it.
    pub luminance: Result<f64, ReferenceError>,
}

/// The expected luminance E\[C_s\] of every strategy of [`PathStrategy::ALL`] (in that order) at
/// `config`'s merge radius, within [`EVALUATION_BUDGET`].
pub fn expected_luminances(config: &SimConfig) -> Vec<StrategyExpectation> {
    expected_within(config, EVALUATION_BUDGET).0
}

/// [`expected_luminances`] within `limit` evaluations, and the evaluations it used.
pub fn expected_within(config: &SimConfig, limit: u64) -> (Vec<StrategyExpectation>, u64) {
    expected_with(config, limit, ACCURACY)
}

fn expected_with(config: &SimConfig, limit: u64, accuracy: Accuracy) -> (Vec<StrategyExpectation>, u64) {
    let budget = Budget::new(limit);
    let values = Setup::new(config, accuracy).and_then(|setup| setup.integrate(&budget));
    let unsupported = unsupported_weights(config);
    let rows = PathStrategy::ALL
        .iter()
        .enumerate()
        .map(|(i, &strategy)| {
            let luminance = match values {
                Err(e) => Err(e),
                _ if unsupported[i] => Err(ReferenceError::UnsupportedWeights),
                Ok(v) if !v[i].is_finite() => Err(ReferenceError::NotFinite),
                Ok(v) => Ok(v[i]),
            };
            StrategyExpectation { strategy, luminance }
        })
        .collect();
    (rows, budget.used())
}

/// An emitting ring of the profile, as the plane-3 light side needs it.
#[derive(Debug, Clone, Copy)]
struct LightRing {
    r_in: f64,
    r_out: f64,
    /// I_k/Φ.
    density: f64,
    /// A start point inside the ring, for the plane-3 weights.
    start: [f64; 2],
}

/// What the light side contributes at one r3: I(r3)/Φ for planes 1 and 2, and for plane 3 the
/// disc's share of each ring, (I_k/Φ)·|D ∩ ring_k|/(πR²), with the ring's start point.
struct Outer {
    light: f64,
    rings: Vec<(f64, [f64; 2])>,
}

/// The configuration's constants for the integrals.
struct Setup<'a> {
    config: &'a SimConfig,
    accuracy: Accuracy,
    l2: f64,
    l3: f64,
    lobe: Lobe,
    radius: f64,
    rings: Vec<LightRing>,
    /// Offsets of the pixel x1 (plane 1) and of the light's x2′ (plane 2).
    disc0: DiscRule,
    disc1: DiscRule,
    /// Deflection where the Gauss–Legendre panels in s end.
    target: f64,
    /// Gauss–Legendre nodes and weights on [−1, 1] for the panels in s.
    legendre: Vec<(f64, f64)>,
}

impl<'a> Setup<'a> {
    fn new(config: &'a SimConfig, accuracy: Accuracy) -> Result<Self, ReferenceError> {
        let scene = &config.scene;
        let (l2, l3, beta, radius) = (scene.l2, scene.l3, scene.lobe.beta, config.merge_radius);
        let (kappa0, kappa1) = (radius / (beta * l2), radius / (beta * l3));
        let disc0 = DiscRule::for_ratio(kappa0, radius).ok_or(ReferenceError::KernelTooWide)?;
        let disc1 = DiscRule::for_ratio(kappa1, radius).ok_or(ReferenceError::KernelTooWide)?;
        let flux = scene.illumination.flux();
        let rings = scene
            .illumination
            .rings()
            .iter()
            .map(|r| LightRing {
                r_in: r.r_in,
                r_out: r.r_out,
                density: r.level / flux,
                start: [0.5 * (r.r_in + r.r_out), 0.0],
            })
            .collect();
        let target = ((10.0 + kappa0.max(kappa1)) * beta).min(3.0);
        let legendre = legendre_nodes(accuracy.order);
        Ok(Self { config, accuracy, l2, l3, lobe: scene.lobe, radius, rings, disc0, disc1, target, legendre })
    }

    /// Σ_m E_m for every strategy (module doc), or why not.
    fn integrate(&self, budget: &Budget<'_>) -> Result<Values, ReferenceError> {
        let panels = self.breakpoints();
        let f = |panel: usize, t: f64| -> Values {
            let (r0, r1) = (panels[panel], panels[panel + 1]);
            let (sin, cos) = (PI * t).sin_cos();
            let r = r0 + (r1 - r0) * 0.5 * (1.0 - cos);
            let jacobian = (r1 - r0) * 0.5 * PI * sin;
            // ∫dA3 = 2π∫r dr; with the 1/π² of every technique: 2r/π.
            self.inner(r, budget).map(|v| v * 2.0 * r / PI * jacobian)
        };
        let value = adaptive_gk(&f, panels.len() - 1, self.accuracy.outer, budget)?;
        Ok(value)
    }

    /// Panel edges of the outer integral: 0, every ring edge e with |e − R| and e + R, the switch
    /// radius, up to r_out + R.
    fn breakpoints(&self) -> Vec<f64> {
        let r = self.radius;
        let mut points = vec![0.0];
        for ring in &self.rings {
            for e in [ring.r_in, ring.r_out] {
                if e > 0.0 {
                    points.extend([e, (e - r).abs(), e + r]);
                }
            }
        }
        points.push(self.config.scene.illumination.switch_radius());
        let end = self.rings.last().map_or(0.0, |g| g.r_out) + r;
        points.retain(|&p| p <= end);
        points.sort_by(f64::total_cmp);
        points.dedup();
        points
    }

    /// The light side at r3 (see [`Outer`]).
    fn outer(&self, r3: f64) -> Outer {
        let r = self.radius;
        let light = self.config.scene.illumination.density(r3);
        let rings = self
            .rings
            .iter()
            .filter_map(|g| {
                let share = disc_fraction_inside(r3, r, g.r_out) - disc_fraction_inside(r3, r, g.r_in);
                (share > 0.0).then_some((g.density * share, g.start))
            })
            .collect();
        Outer { light, rings }
    }

    /// ∫dA2 of every strategy's Σ_m (light side)·(integrand)·w_m at x3 = (r3, 0), without the
    /// 1/π² (module doc), in the stretched polar coordinates of [`super::quadrature`].
    fn inner(&self, r3: f64, budget: &Budget<'_>) -> Values {
        let outer = self.outer(r3);
        if outer.light == 0.0 && outer.rings.is_empty() || budget.spent() {
            return [0.0; PathStrategy::COUNT];
        }
        let (l2, l3) = (self.l2, self.l3);
        let x3 = [r3, 0.0];
        let r2_star = r3 * l2 / (l2 + l3);
        let u_len = r2_star.hypot(l2);
        let cos_t = l2 / u_len;
        let c = (1.0 + l3 / l2) / (l3 / l2 * u_len);
        let point = |s: f64, psi: f64| [r2_star + s * psi.cos() / cos_t, s * psi.sin()];
        let deflection_at = |x2: [f64; 2]| deflection([x2[0], x2[1], l2], [x3[0] - x2[0], x3[1] - x2[1], l3]);
        let peak = self.lobe.g(0.0) * l2 / u_len.powi(3) * l3 * l3 / ((r3 - r2_star).hypot(l3)).powi(4);
        let weight_calls = if outer.light > 0.0 { 2 } else { 0 } + outer.rings.len() as u64;
        let node_cost = 1 + (self.disc0.points.len() + self.disc1.points.len()) as u64 + WEIGHTS_COST * weight_calls;
        let tail = self.target >= 3.0;
        let nodes = self.legendre.len() as u64 * if tail { 5 } else { 4 };
        let radial = |psi: f64| -> Values {
            let mut acc = [0.0; PathStrategy::COUNT];
            if !budget.charge(nodes * node_cost) {
                return acc;
            }
            let s_c = solve_monotone(|s| deflection_at(point(s, psi)), self.target, self.target / c, budget);
            let mut add = |s: f64, jacobian: f64| {
                self.node(point(s, psi), x3, &outer, s / cos_t * jacobian, peak * NEGLIGIBLE, &mut acc);
            };
            for w in [0.0, 0.125, 0.25, 0.5, 1.0].windows(2) {
                let (a, b) = (w[0] * s_c, w[1] * s_c);
                let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
                for &(x, wt) in &self.legendre {
                    add(mid + half * x, half * wt);
                }
            }
            // Tail s ∈ [s_c, ∞) with s = s_c/t, where the panels end before the lobe does.
            if tail {
                for &(x, wt) in &self.legendre {
                    let t = 0.5 * (1.0 + x);
                    add(s_c / t, 0.5 * wt * s_c / (t * t));
                }
            }
            acc
        };
        // Symmetric in ψ ↔ −ψ (x3 on the x axis, every weight a function of distances and
        // angles): the trapezoid on [0, π], doubled until every strategy is stable.
        let trapezoid = |v: &[Values]| -> Values {
            let n = v.len() - 1;
            std::array::from_fn(|s| {
                (v[1..n].iter().map(|x| x[s]).sum::<f64>() + 0.5 * (v[0][s] + v[n][s])) * 2.0 * PI / n as f64
            })
        };
        let mut n = 16;
        let mut values: Vec<Values> = (0..=n).map(|i| radial(PI * i as f64 / n as f64)).collect();
        let mut estimate = trapezoid(&values);
        while n < 1024 && !budget.spent() {
            let mut refined = Vec::with_capacity(2 * n + 1);
            for (i, v) in values.iter().take(n).enumerate() {
                refined.push(*v);
                refined.push(radial(PI * (2 * i + 1) as f64 / (2 * n) as f64));
            }
            refined.push(values[n]);
            n *= 2;
            values = refined;
            let next = trapezoid(&values);
            let scale = next.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let change = next.iter().zip(&estimate).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            estimate = next;
            if change <= self.accuracy.inner * scale {
                break;
            }
        }
        estimate
    }

    /// Adds one node x2 of the inner integral, with quadrature weight `jacobian`: the three
    /// techniques' integrands times each strategy's weights (module doc). Nodes whose lobe
    /// factors are all below `negligible` are skipped.
    #[inline]
    fn node(&self, x2: [f64; 2], x3: [f64; 2], outer: &Outer, jacobian: f64, negligible: f64, acc: &mut Values) {
        let (l2, l3, lobe) = (self.l2, self.l3, &self.lobe);
        let u = [x2[0], x2[1], l2];
        let v = [x3[0] - x2[0], x3[1] - x2[1], l3];
        let g = lobe.g(deflection(u, v));
        let (uu, vv) = (dot(u, u), dot(v, v));
        let camera = l2 / (uu * uu.sqrt()); // L2/d1³
        let light = l3 * l3 / (vv * vv); // L3²/d2⁴
        let plane3 = camera * light * g;
        let (mut plane2, mut plane1) = (0.0, 0.0);
        if outer.light > 0.0 {
            // Plane 2: the light's x2′ = x2 + δ over D(x2, R), deflected towards the pixel from x2.
            let mut h1 = self.disc1.centre * light * g;
            for &(d, w) in &self.disc1.points {
                let v1 = [v[0] - d[0], v[1] - d[1], l3];
                let vv1 = dot(v1, v1);
                h1 += w * l3 * l3 / (vv1 * vv1) * lobe.g(deflection(u, v1));
            }
            // Plane 1: the pixel x1 = δ over D(0, R), reached from x2.
            let mut h0 = self.disc0.centre * camera * g;
            for &(d, w) in &self.disc0.points {
                let u0 = [u[0] - d[0], u[1] - d[1], l2];
                let uu0 = dot(u0, u0);
                h0 += w * l2 / (uu0 * uu0.sqrt()) * lobe.g(deflection(u0, v));
            }
            plane2 = camera * h1;
            plane1 = light * h0;
        }
        if plane3.max(plane2).max(plane1) < negligible {
            return;
        }
        let config = self.config;
        let mut add = |scale: f64, weights: &Values| {
            for (a, w) in acc.iter_mut().zip(weights) {
                *a += scale * w;
            }
        };
        // One join path, weighed by every technique and light start that reaches it.
        let path = PathWeights::new(config, x2, x3);
        if outer.light > 0.0 {
            let scale = jacobian * outer.light;
            let start = light_start(config, x3);
            add(scale * plane2, &path.of(Technique::Plane2, start));
            add(scale * plane1, &path.of(Technique::Plane1, start));
        }
        for &(share, start) in &outer.rings {
            add(jacobian * share * plane3, &path.of(Technique::Plane3, light_start(config, start)));
        }
    }
}

/// Strategies whose weights depend on more than the integrals resolve (module doc): compared on a
/// few join paths near each ring, a plane-3 weight for other starts across the ring, and every
/// technique's weights with the join path rotated and reflected about the axis.
fn unsupported_weights(config: &SimConfig) -> [bool; PathStrategy::COUNT] {
    let scene = &config.scene;
    let (l2, l3, beta) = (scene.l2, scene.l3, scene.lobe.beta);
    let mut unsupported = [false; PathStrategy::COUNT];
    // Weights lie in [0, 1]; a dependence shows as a difference of order 1, rounding (amplified in
    // the deflection of a very narrow lobe) as far less than 10⁻⁶.
    let mut compare = |a: &Values, b: &Values| {
        for (flag, (a, b)) in unsupported.iter_mut().zip(a.iter().zip(b)) {
            *flag |= (a - b).abs() > 1e-6;
        }
    };
    // Exact in floating point: the quarter turn and the reflection y → −y.
    let turns: [fn([f64; 2]) -> [f64; 2]; 2] = [|p| [-p[1], p[0]], |p| [p[0], -p[1]]];
    for ring in scene.illumination.rings() {
        let width = ring.r_out - ring.r_in;
        let start = [0.5 * (ring.r_in + ring.r_out), 0.0];
        let others = [[ring.r_in + 0.1 * width, 0.0], [0.0, ring.r_out - 0.1 * width], {
            let r = ring.r_in + 0.7 * width;
            [r * 0.6, -r * 0.8]
        }];
        for r3 in [ring.r_in, start[0], ring.r_out] {
            for (i, offset) in [[0.0, 0.0], [0.5, 0.3], [-1.0, 2.0]].iter().enumerate() {
                let x3 = [r3, 0.1 * i as f64 * r3];
                let shift = beta * l2;
                let x2 = [x3[0] * l2 / (l2 + l3) + offset[0] * shift, x3[1] * l2 / (l2 + l3) + offset[1] * shift];
                let base = strategy_weights(config, Technique::Plane3, x2, x3, start);
                for other in others {
                    compare(&base, &strategy_weights(config, Technique::Plane3, x2, x3, other));
                }
                for technique in [Technique::Plane1, Technique::Plane2, Technique::Plane3] {
                    let base = strategy_weights(config, technique, x2, x3, start);
                    for turn in turns {
                        let [x2, x3, start] = [x2, x3, start].map(turn);
                        compare(&base, &strategy_weights(config, technique, x2, x3, start));
                    }
                }
            }
        }
    }
    unsupported
}

mod rules;

#[cfg(test)]
mod tests;
