//! The three bundles of an iteration — the candidates that may merge at plane 1, 2 and 3 — each a
//! Poisson count for its total mass and a (ring, camera, proposal) per candidate, thinned to the
//! exact intensity and kept only by the first component that contains it (see the module
//! documentation of [`super`] for the construction and its proofs).

use std::f64::consts::{PI, TAU};
use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;

use super::CANCEL_CHECK_INTERVAL;
use super::plan::{BundleEntry, Kind, RestrictedPlan, RestrictedScratch, d_min_squared, tail_probability};
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::merge::{merge_plane1, merge_plane2, merge_plane3, within};
use crate::sim::engines::pixel::{land_on_pixel, pixel_hit};
use crate::sim::engines::tally::ChunkScratch;
use crate::sim::math::plane::radius;
use crate::sim::math::poisson::poisson_until;
use crate::sim::math::rng::{StreamRng, uniform, uniform_open0};
use crate::sim::math::sampling::{cosine_direction, disc_point};
use crate::sim::model::config::SimConfig;
use crate::sim::model::illumination::Ring;
use crate::sim::model::scene::{advance, sample_lobe};

/// A light path being drawn: its vertices, its direction into x2, and (once known) x1 and ϑ.
struct Candidate {
    x3: [f64; 2],
    x2: [f64; 2],
    d: Vector3<f64>,
    /// `Some((x1, ϑ))` when the path lands in D(0, R) on plane 1, `None` when it does not.
    x1: Option<([f64; 2], f64)>,
}

/// What the bundles of one iteration read: the configuration, the plan, the camera paths and the
/// stop flag.
#[derive(Clone, Copy)]
pub(super) struct Iteration<'a> {
    pub config: &'a SimConfig,
    pub plan: &'a RestrictedPlan,
    pub cameras: &'a CameraSet,
    pub cancel: &'a AtomicBool,
}

/// The component of S whose bundle drew a candidate (S1's bundle needs no test: it is first).
#[derive(Clone, Copy)]
enum Component {
    Plane2(u32),
    Plane3(u32),
}

impl Iteration<'_> {
    /// Whether a component before `own` in the fixed order S1, S2_1…S2_NB, S3_1…S3_NB contains the
    /// candidate: the parts T_k are disjoint because a candidate is kept only by the first
    /// component that contains it (the membership tests are the brute force's merge tests).
    fn in_earlier_component(&self, c: &Candidate, own: Component) -> bool {
        let (r, paths) = (self.config.merge_radius, &self.cameras.paths);
        let plane2_before = match own {
            Component::Plane2(j) => j,
            Component::Plane3(_) => u32::MAX,
        };
        let in_plane2 = || {
            let near = self.cameras.plane2.candidates(c.x2);
            near.take_while(|&i| i < plane2_before).any(|i| within(c.x2, paths[i as usize].x2, r))
        };
        let in_plane3 = || match own {
            Component::Plane2(_) => false,
            Component::Plane3(j) => self
                .cameras
                .plane3
                .candidates(c.x3)
                .take_while(|&i| i < j)
                .any(|i| paths[i as usize].x3.is_some_and(|x3c| within(c.x3, x3c, r))),
        };
        c.x1.is_some() || in_plane2() || in_plane3()
    }
}

/// Draws the bundle in `buffers.bundle`: a Poisson count for the total mass, then a pair per
/// candidate in proportion to its mass. False if `cancel` was set meanwhile (looked at every
/// [`CANCEL_CHECK_INTERVAL`] candidates, and while drawing a huge count).
fn for_each_candidate(
    rng: &mut StreamRng,
    buffers: &mut RestrictedScratch,
    cancel: &AtomicBool,
    mut draw: impl FnMut(&mut StreamRng, u32, u32, Kind),
) -> bool {
    if buffers.bundle.is_empty() {
        return true;
    }
    let total = buffers.total();
    let Some(count) = poisson_until(rng, total, cancel) else { return false };
    buffers.prepare_draws(count);
    for k in 0..count {
        if k % CANCEL_CHECK_INTERVAL == CANCEL_CHECK_INTERVAL - 1 && cancel.load(Ordering::Relaxed) {
            return false;
        }
        let u = uniform(rng) * total;
        let i = buffers.find(u);
        let BundleEntry { layer, camera, kind, .. } = buffers.bundle[i];
        draw(rng, layer, camera, kind);
    }
    true
}

pub(super) fn plane1_bundle(
    it: &Iteration<'_>,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    buffers.bundle.clear();
    for part in &plan.plane1 {
        buffers.push(part.mass, part.layer, 0, part.kind);
    }
    let r = config.merge_radius;
    let (l2, l3) = (config.scene.l2, config.scene.l3);
    for_each_candidate(rng, buffers, cancel, |rng, l, _, kind| {
        let layer = &plan.layers[l as usize];
        let candidate = match kind {
            Kind::Reverse => {
                let x1 = disc_point(rng, [0.0, 0.0], r);
                // A direction up from x1, uniform on the hemisphere: cos γ uniform in (0, 1].
                let cos_g = 1.0 - uniform(rng);
                let sin_g = (1.0 - cos_g * cos_g).sqrt();
                let (sin_p, cos_p) = libm::sincos(TAU * uniform(rng));
                let out = Vector3::new(-sin_g * cos_p, -sin_g * sin_p, -cos_g);
                let x2 = advance(x1, &out, l2);
                let (d, theta) = sample_lobe(&config.scene.lobe, &out, rng);
                // μ = 0 for a direction that does not point down; otherwise thin by cos θ3.
                if d.z >= 0.0 || uniform(rng) >= -d.z {
                    return;
                }
                let x3 = advance(x2, &d, l3);
                if !in_ring(&layer.ring, x3) {
                    return;
                }
                Candidate { x3, x2, d, x1: Some((x1, theta)) }
            }
            Kind::ForwardBulk | Kind::ForwardTail => {
                let (bulk, tail) = layer.reach.expect("forward plane-1 proposals exist only with a bound");
                let x3 = ring_point(rng, &layer.ring);
                let x2 = disc_point(rng, [0.0, 0.0], if kind == Kind::ForwardBulk { bulk } else { tail });
                let Some(d) = thin_by_distance(rng, x3, x2, l3, l3 * l3) else { return };
                // ϑ = β√(−2 ln u) with u restricted to the part: u ≥ P(tail) for the bulk, u < it
                // for the tail (u = P(tail)·u' with u' in (0, 1], as the sampler's u).
                let p_tail = tail_probability();
                let u = if kind == Kind::ForwardBulk {
                    p_tail + (1.0 - p_tail) * (1.0 - uniform(rng))
                } else {
                    p_tail * uniform_open0(rng)
                };
                let theta = config.scene.lobe.beta * (-2.0 * libm::log(u)).sqrt();
                let x1 = land_on_pixel(config, &plan.angle, &d, x2, theta, rng);
                if x1.is_none() {
                    return;
                }
                Candidate { x3, x2, d, x1 }
            }
            Kind::Forward => unreachable!("plane 1 uses the bulk and tail proposals"),
        };
        // S1 is the first component: nothing to exclude.
        tally(config, cameras, &candidate, scratch);
    })
}

/// The plane-2 bundle: a (ring, camera) pair per camera vertex and ring, with its proposal.
pub(super) fn build_plane2(
    config: &SimConfig,
    plan: &RestrictedPlan,
    cameras: &CameraSet,
    buffers: &mut RestrictedScratch,
) {
    buffers.bundle.clear();
    // |x2c| of every camera once, not once per layer (the same expression, so the same bits).
    buffers.radii.clear();
    buffers.radii.extend(cameras.paths.iter().map(|cam| radius(cam.x2)));
    for (l, layer) in plan.layers.iter().enumerate() {
        for j in 0..cameras.paths.len() {
            let (mass, kind) = plan.plane2(layer, config, buffers.radii[j]);
            buffers.push(mass, l, j, kind);
        }
    }
}

pub(super) fn plane2_bundle(
    it: &Iteration<'_>,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    build_plane2(config, plan, cameras, buffers);
    let r = config.merge_radius;
    let l3 = config.scene.l3;
    for_each_candidate(rng, buffers, cancel, |rng, l, j, kind| {
        let layer = &plan.layers[l as usize];
        let x2c = cameras.paths[j as usize].x2;
        let x2 = disc_point(rng, x2c, r);
        let (x3, d) = match kind {
            Kind::Reverse => {
                let up = cosine_direction(rng);
                let d = Vector3::new(up.x, up.y, -up.z);
                let x3 = advance(x2, &d, l3);
                if !in_ring(&layer.ring, x3) {
                    return;
                }
                (x3, d)
            }
            Kind::Forward | Kind::ForwardBulk | Kind::ForwardTail => {
                let x3 = ring_point(rng, &layer.ring);
                let d_min2 = d_min_squared(config, layer, radius(x2c));
                let Some(d) = thin_by_distance(rng, x3, x2, l3, d_min2) else { return };
                (x3, d)
            }
        };
        let candidate = Candidate { x3, x2, d, x1: pixel_hit(config, &plan.cone, &plan.angle, &d, x2, rng) };
        if !it.in_earlier_component(&candidate, Component::Plane2(j)) {
            tally(config, cameras, &candidate, scratch);
        }
    })
}

/// The plane-3 bundle: a (ring, camera) pair per camera vertex on plane 3 whose disc meets the
/// ring.
pub(super) fn build_plane3(
    config: &SimConfig,
    plan: &RestrictedPlan,
    cameras: &CameraSet,
    buffers: &mut RestrictedScratch,
) {
    let r = config.merge_radius;
    buffers.bundle.clear();
    // |x3c| of every camera once, not once per layer (NaN, which no test admits, for a path that
    // did not reach plane 3).
    buffers.radii.clear();
    buffers.radii.extend(cameras.paths.iter().map(|cam| cam.x3.map_or(f64::NAN, radius)));
    for (l, layer) in plan.layers.iter().enumerate() {
        for j in 0..cameras.paths.len() {
            let dist = buffers.radii[j];
            // A disc that misses the ring holds no start point: no candidates (nor a camera path
            // that did not reach plane 3: every comparison with NaN is false).
            if !(dist + r >= layer.ring.r_in && dist - r < layer.ring.r_out) {
                continue;
            }
            buffers.push(layer.nu * PI * r * r, l, j, Kind::Forward);
        }
    }
}

pub(super) fn plane3_bundle(
    it: &Iteration<'_>,
    rng: &mut StreamRng,
    scratch: &mut ChunkScratch,
    buffers: &mut RestrictedScratch,
) -> bool {
    let Iteration { config, plan, cameras, cancel } = *it;
    build_plane3(config, plan, cameras, buffers);
    let r = config.merge_radius;
    let l3 = config.scene.l3;
    for_each_candidate(rng, buffers, cancel, |rng, l, j, _| {
        let layer = &plan.layers[l as usize];
        let x3c = cameras.paths[j as usize].x3.expect("only reached cameras are in the bundle");
        let x3 = disc_point(rng, x3c, r);
        if !in_ring(&layer.ring, x3) {
            return;
        }
        let dir = cosine_direction(rng);
        let d = Vector3::new(dir.x, dir.y, -dir.z);
        let x2 = advance(x3, &d, -l3);
        let candidate = Candidate { x3, x2, d, x1: pixel_hit(config, &plan.cone, &plan.angle, &d, x2, rng) };
        if !it.in_earlier_component(&candidate, Component::Plane3(j)) {
            tally(config, cameras, &candidate, scratch);
        }
    })
}

/// Thinning of the forward proposals, whose λ̄ uses the density bound L3²/(π d_min⁴) of a Lambert
/// direction from x3 landing at x2: keeps the candidate with probability (d_min/d)⁴ and returns
/// its unit direction x3 → x2, or `None`.
fn thin_by_distance(rng: &mut StreamRng, x3: [f64; 2], x2: [f64; 2], l3: f64, d_min2: f64) -> Option<Vector3<f64>> {
    let (dx, dy) = (x2[0] - x3[0], x2[1] - x3[1]);
    let d2 = l3 * l3 + dx * dx + dy * dy;
    let ratio = d_min2 / d2;
    (uniform(rng) < ratio * ratio).then(|| Vector3::new(dx, dy, -l3) / d2.sqrt())
}

/// Every merge of a kept path, exactly as the brute force records them.
fn tally(config: &SimConfig, cameras: &CameraSet, c: &Candidate, scratch: &mut ChunkScratch) {
    scratch.toss_light_half();
    merge_plane3(config, cameras, cameras.plane3.candidates(c.x3), c.x3, scratch);
    merge_plane2(config, cameras, cameras.plane2.candidates(c.x2), c.x2, c.x3, &c.d, scratch);
    if let Some((x1, theta)) = c.x1 {
        merge_plane1(config, theta, x1, c.x2, c.x3, scratch);
    }
}

fn in_ring(ring: &Ring, x: [f64; 2]) -> bool {
    let r2 = x[0] * x[0] + x[1] * x[1];
    r2 >= ring.r_in * ring.r_in && r2 < ring.r_out * ring.r_out
}

/// A point uniform in the ring (r² uniform between the radii, azimuth uniform).
fn ring_point(rng: &mut StreamRng, ring: &Ring) -> [f64; 2] {
    if ring.r_in == 0.0 {
        return disc_point(rng, [0.0, 0.0], ring.r_out);
    }
    let (a, b) = (ring.r_in * ring.r_in, ring.r_out * ring.r_out);
    let r = (a + uniform(rng) * (b - a)).sqrt();
    let (s, c) = libm::sincos(TAU * uniform(rng));
    [r * c, r * s]
}
