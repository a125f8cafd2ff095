//! Tests of the brute force: the block loop against a scalar reference, the near filters, the pixel
//! tests, and the AVX2 build against the portable one.

use super::near_filter::NearFilter32;
use super::*;
use crate::sim::math::rng::stream;
use crate::sim::spec::parse_job_spec;
use std::f64::consts::PI;

/// The near filter must hold every point within R of a vertex (the exact test of the merges
/// is the reference), near the origin, far out, and at huge coordinates, both with cells of
/// side 2R and with the wider cells of a huge reach; and it must reject most points far from
/// every vertex.
#[test]
fn near_filter_never_misses_a_vertex() {
    let r = 0.003;
    let mut rng = stream(2, 3, 4);
    let mut u = || crate::sim::math::rng::uniform(&mut rng) * 2.0 - 1.0;
    let vertices: Vec<[f64; 2]> = (0..300)
        .map(|j| {
            let scale = [0.05, 3.0, 1e3, 1e9, 1e17][j % 5];
            [u() * scale, u() * scale]
        })
        .collect();
    let modest = |c: &&[f64; 2]| c[0].abs().max(c[1].abs()) <= 1e3;
    // Cells of side 2R, queried within 2·10³ (vertices beyond it are out of reach)…
    let near_filter = NearFilter::new(vertices.iter().copied(), r, 2e3);
    // …and cells of side 10¹⁸·2⁻⁴⁸ ≈ 3553, for queries anywhere within 10¹⁸.
    let far_filter = NearFilter::new(vertices.iter().copied(), r, 1e18);
    let mut near = 0;
    for (j, c) in vertices.iter().enumerate() {
        for _ in 0..2000 {
            // Points in and around the vertex's disc, some exactly on its rim.
            let (a, s) = (u() * PI, if j % 2 == 0 { 1.0 } else { u().abs() * 1.2 });
            let p = [c[0] + r * s * a.cos(), c[1] + r * s * a.sin()];
            if crate::sim::engines::merge::within(p, *c, r) {
                near += 1;
                let far = far_filter.holds(far_filter.cell(p[0], p[1]));
                assert_eq!(far, 1, "missed {p:?} near vertex {j} at {c:?} (wide cells)");
                if modest(&c) {
                    let near = near_filter.holds(near_filter.cell(p[0], p[1]));
                    assert_eq!(near, 1, "missed {p:?} near vertex {j} at {c:?}");
                }
            }
        }
    }
    assert!(near > 300_000, "the test must exercise near points ({near})");
    let mut false_positives = 0;
    for _ in 0..100_000 {
        let p = [u() * 20.0, u() * 20.0];
        if vertices.iter().all(|c| !crate::sim::engines::merge::within(p, *c, 10.0 * r)) {
            false_positives += near_filter.holds(near_filter.cell(p[0], p[1]));
        }
    }
    assert!(false_positives < 5_000, "{false_positives} false positives in 10⁵");
}

/// The AVX2 build of the loop and the portable one give the same tally, bit for bit, on
/// chunks with merges at every plane (when the CPU has AVX2; otherwise both are portable).
#[test]
fn simd_and_portable_loops_agree() {
    let mut merges = [0; 3];
    // The spot (with a partial last chunk), and a uniform disc with a wide R for plane-1 hits.
    for doc in [
        serde_json::json!({
            "preset": "paper-table1", "light_paths": 140_000, "camera_paths": 300, "merge_radius": 0.02
        }),
        serde_json::json!({
            "preset": "uniform-illumination", "light_paths": 131_072, "camera_paths": 100, "merge_radius": 0.05
        }),
    ] {
        let job = parse_job_spec(&doc).unwrap().validate().unwrap();
        let config = &job.config();
        let mut scratch = ChunkScratch::new(config.cells.len());
        for iteration in 0..4 {
            let cameras = CameraSet::generate(config, 7, iteration);
            for chunk in 0..config.chunks() {
                let simd = trace_chunk_with(config, &cameras, 7, iteration, chunk, &mut scratch, true);
                let portable = trace_chunk_with(config, &cameras, 7, iteration, chunk, &mut scratch, false);
                assert_eq!(format!("{simd:?}"), format!("{portable:?}"), "{doc}: iteration {iteration}, chunk {chunk}");
                for (total, m) in merges.iter_mut().zip(simd.merges) {
                    *total += m;
                }
            }
        }
    }
    assert!(merges.iter().all(|&m| m > 0), "the test must exercise every plane: {merges:?}");
}

/// Configurations for the filter tests: the paper's scene at its R and at a wide R with many
/// cameras, uniform light with a wide R (plane-1 hits), a wide lobe (every path may reach the
/// pixel), a close plane 2 (the f32 cone margin gives up: e > 0.03) and a deep, wide scene with a
/// tiny R (large f32 errors relative to R).
fn filter_configs() -> Vec<std::sync::Arc<SimConfig>> {
    [
        serde_json::json!({ "preset": "paper-table1", "light_paths": 131_072 }),
        serde_json::json!({ "preset": "paper-table1", "light_paths": 140_000, "camera_paths": 300, "merge_radius": 0.02 }),
        serde_json::json!({ "preset": "uniform-illumination", "light_paths": 131_072, "camera_paths": 100, "merge_radius": 0.05 }),
        serde_json::json!({ "preset": "paper-table1", "light_paths": 65_536, "scene": { "beta_deg": 45 } }),
        serde_json::json!({ "preset": "paper-table1", "light_paths": 65_536, "scene": { "l2": 0.004 }, "merge_radius": 0.001 }),
        serde_json::json!({
            "preset": "paper-table1", "light_paths": 65_536, "camera_paths": 200, "merge_radius": 1e-4,
            "scene": { "l3": 40, "illumination": { "kind": "uniform", "r_ls": 300 } }
        }),
    ]
    .into_iter()
    .map(|doc| parse_job_spec(&doc).unwrap().validate().unwrap().config().clone())
    .collect()
}

/// Whether the f32 filter makes the path of the words `w` a candidate (as the block loop does).
fn is_candidate(setup: &Chunk<'_>, w: [u64; 3]) -> bool {
    let mut r2 = [0.0; 1];
    setup.config.scene.illumination.radius2_block(&[w[0]], &mut r2);
    let (cell3, cell2, candidate) = setup.filter.path(Filter32::inputs(r2[0], w[1], w[2]));
    candidate || setup.filter.near3.holds(cell3) == 1 || setup.filter.near2.holds(cell2) == 1
}

/// What the exact tests need of a path: it may reach the pixel (the f64 cone test, which decides
/// the lobe draws), or it merges at plane 3 or plane 2 (the merge functions' exact distance test,
/// against every camera vertex).
fn needs_work(setup: &Chunk<'_>, path: &ExactPath) -> bool {
    let within = |a: [f64; 2], b: [f64; 2]| crate::sim::engines::merge::within(a, b, setup.config.merge_radius);
    path.flags(setup) & MAY_REACH_PIXEL != 0
        || setup.cameras.paths.iter().any(|c| c.x3.is_some_and(|x3| within(path.x3, x3)) || within(path.x2, c.x2))
}

/// The f32 filter never drops a path the exact tests need, on random blocks of every filter
/// configuration; the portable and AVX2 candidate lookups agree; and the filter is selective (at
/// the paper's parameters, under 4 candidates in 100 paths).
#[test]
fn f32_filter_keeps_every_path_the_exact_tests_need() {
    for (k, config) in filter_configs().iter().enumerate() {
        let mut needed = 0;
        let mut kept = 0;
        for iteration in 0..2 {
            let cameras = CameraSet::generate(config, 5, iteration);
            let setup = Chunk::new(config, &cameras);
            let mut lanes = LaneRng::new(5, iteration, 0);
            let mut b = Block::new();
            for _ in 0..2000 {
                lanes.fill(b.bits.as_flattened_mut());
                filter_block(&setup, &mut b);
                let mask = candidates(&setup.filter, &b);
                #[cfg(target_arch = "x86_64")]
                if std::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2 (checked).
                    assert_eq!(mask, unsafe { candidates_avx2(&setup.filter, &b) });
                }
                kept += mask.count_ones();
                for i in 0..BLOCK {
                    let w = [b.bits[0][i], b.bits[1][i], b.bits[2][i]];
                    assert_eq!(mask >> i & 1 == 1, is_candidate(&setup, w), "config {k}: block and single path differ");
                    let path = ExactPath::new(&config.scene, w);
                    // The f64 near filters are conservative: no merge outside them.
                    if path.flags(&setup) != 0 && needs_work(&setup, &path) {
                        needed += 1;
                        assert!(mask >> i & 1 == 1, "config {k}: dropped the path of {w:?}");
                    }
                }
            }
        }
        assert!(needed > 0, "config {k}: the test must exercise needed paths");
        if k == 0 {
            let share = f64::from(kept) / (2.0 * 2000.0 * BLOCK as f64);
            assert!(share < 0.04, "config {k}: {share} of the paths are candidates");
        }
    }
}

/// Adjacent words (on the 2⁻⁵² grid of `unit52`) around each change of `exact` between
/// consecutive `points` (in increasing order): the words at which `exact` holds, right at its
/// boundary.
fn boundaries(exact: impl Fn(u64) -> bool, points: &[u64]) -> Vec<u64> {
    let mut found = Vec::new();
    for pair in points.windows(2) {
        let (mut a, mut b) = (pair[0], pair[1]);
        let (pa, pb) = (exact(a), exact(b));
        if pa == pb {
            continue;
        }
        while b - a > 1 {
            let m = a + (b - a) / 2;
            if exact(m) == pa {
                a = m;
            } else {
                b = m;
            }
        }
        found.push(if pa { a } else { b });
    }
    found
}

/// The smallest word v in [0, 2⁵²) with `above(v)`, for a monotone `above` (2⁵² − 1 if none).
fn first_above(above: impl Fn(u64) -> bool) -> u64 {
    let (mut a, mut b) = (0, (1u64 << 52) - 1);
    while a < b {
        let m = a + (b - a) / 2;
        if above(m) { b = m } else { a = m + 1 }
    }
    a
}

/// The f32 filter's margins at their edges: light paths right on the rim of a camera vertex's
/// merge disc at plane 3 and at plane 2, and right on the exact pixel cone's boundary (found by
/// bisection over one random word, the others fixed, to the last bit the word resolves), are all
/// candidates; and so are the steepest paths, whose hits the filter does not bound.
///
/// The rims: a ray (from the origin for starts, whose radius grows with the ring word; from a start
/// in a direction of growing tan θ for hits) passes the vertex at an offset of up to R; the word
/// of closest approach is found by bisection on the distance along the ray, and each rim by
/// bisection between it and the ray's ends.
#[test]
fn f32_filter_is_conservative_at_the_edges() {
    use std::f64::consts::TAU;
    const TOP: u64 = (1 << 52) - 1;
    let turn = |angle: f64| (angle.rem_euclid(TAU) / TAU * 4_294_967_296.0) as u64 & 0xffff_ffff;
    let mut rng = stream(8, 8, 8);
    let mut word = move || rand::Rng::next_u64(&mut rng);
    for (k, config) in filter_configs().iter().enumerate() {
        let cameras = CameraSet::generate(config, 9, 1);
        let setup = Chunk::new(config, &cameras);
        let (r, l3) = (config.merge_radius, config.scene.l3);
        let mut edges = [0usize; 3];
        for (j, camera) in cameras.paths.iter().enumerate() {
            let share = [0.0, 0.5, 0.97, 1.0][j % 4];
            // Plane 3: the start radius grows with the ring word.
            if let Some(c) = camera.x3 {
                let distance = c[0].hypot(c[1]);
                let offset = (r / distance.max(r) * share).asin();
                let az = turn(c[1].atan2(c[0]) + offset) << 32 | (word() & 0xffff_ffff);
                let w = |v: u64| [v << 12, 0, az];
                let closest = first_above(|v| {
                    let mut r2 = [0.0];
                    config.scene.illumination.radius2_block(&[v << 12], &mut r2);
                    r2[0].sqrt() >= distance * offset.cos()
                });
                let exact = |v: u64| crate::sim::engines::merge::within(ExactPath::new(&config.scene, w(v)).x3, c, r);
                for v in boundaries(exact, &[0, closest, TOP]) {
                    edges[0] += 1;
                    assert!(is_candidate(&setup, w(v)), "config {k}: plane-3 rim of camera {j} dropped");
                }
            }
            // Plane 2: from a random start, the hit moves along the direction's ray as sin² θ
            // grows.
            let (w0, hi) = (word(), word() & !0xffff_ffff);
            let x3 = ExactPath::new(&config.scene, [w0, 0, hi]).x3;
            let c = camera.x2;
            let distance = (c[0] - x3[0]).hypot(c[1] - x3[1]);
            let offset = (r / distance.max(r) * share).asin();
            let az = hi | turn((c[1] - x3[1]).atan2(c[0] - x3[0]) + offset);
            let w = |v: u64| [w0, v << 12, az];
            let closest = first_above(|v| ExactPath::new(&config.scene, w(v)).tan * l3 >= distance * offset.cos());
            let exact = |v: u64| crate::sim::engines::merge::within(ExactPath::new(&config.scene, w(v)).x2, c, r);
            for v in boundaries(exact, &[0, closest, TOP]) {
                edges[1] += 1;
                assert!(is_candidate(&setup, w(v)), "config {k}: plane-2 rim of camera {j} dropped");
            }
        }
        // The pixel cone: random starts, directions towards the pixel's axis at various offsets,
        // sin² θ on a grid of 4096 (the cone's crossings are wide).
        let grid: Vec<u64> = (0..=4096).map(|g| TOP / 4096 * g).collect();
        for j in 0..300 {
            let (w0, hi) = (word(), word() & !0xffff_ffff);
            let x3 = ExactPath::new(&config.scene, [w0, 0, hi]).x3;
            let az = hi | turn((-x3[1]).atan2(-x3[0]) + (f64::from(j % 7) - 3.0) * 0.05);
            let w = |v: u64| [w0, v << 12, az];
            let exact = |v: u64| ExactPath::new(&config.scene, w(v)).flags(&setup) & MAY_REACH_PIXEL != 0;
            for v in boundaries(exact, &grid) {
                edges[2] += 1;
                assert!(is_candidate(&setup, w(v)), "config {k}: a path on the pixel cone's boundary dropped");
            }
            assert!(is_candidate(&setup, [w0, TOP << 12, az]), "config {k}: the steepest path dropped");
        }
        // (A lobe of 45° reaches the pixel from every direction: its exact cone has no edge.)
        let cone_edges = edges[2] > 20 || setup.cone.c_abs_c() < -1.0;
        let enough = edges[0] > 50 && edges[1] > 50 && cone_edges;
        assert!(enough, "config {k}: the test must find edges of each kind: {edges:?}");
    }
}

/// The block loop gives exactly the tally of the plain exact loop (every path computed in f64,
/// tested exactly, and traced if flagged — the brute force before the f32 filter), in both
/// builds and in both modes (the f32 screen, and every path in f64 where the screen would pass
/// them all): the filter only changes which paths are looked at.
#[test]
fn block_loop_matches_the_exact_loop() {
    let mut modes = Vec::new();
    for (k, config) in filter_configs().iter().enumerate() {
        modes.push(Chunk::new(config, &CameraSet::generate(config, 3, 2)).screen);
        let mut scratch = ChunkScratch::new(config.cells.len());
        let cameras = CameraSet::generate(config, 3, 2);
        for chunk in 0..config.chunks() {
            let setup = Chunk::new(config, &cameras);
            let mut lanes = LaneRng::new(3, 2, chunk);
            let mut rng = stream(3, 2, chunk);
            let mut bits = [[0u64; BLOCK]; 3];
            let mut remaining = config.chunk_len(chunk) as usize;
            while remaining > 0 {
                let n = remaining.min(BLOCK);
                remaining -= n;
                lanes.fill(bits.as_flattened_mut());
                for (i, ((&w0, &w1), &w2)) in bits[0].iter().zip(&bits[1]).zip(&bits[2]).enumerate().take(n) {
                    let path = ExactPath::new(&config.scene, [w0, w1, w2]);
                    let flags = path.flags(&setup);
                    if flags != 0 {
                        scratch.set_light_half(i);
                        let dir = [path.sin2, path.cos_phi, path.sin_phi];
                        trace_flagged(&setup, flags, path.x3, path.x2, dir, &mut rng, &mut scratch);
                    }
                }
            }
            let exact = format!("{:?}", scratch.take());
            for simd in [true, false] {
                let block = trace_chunk_with(config, &cameras, 3, 2, chunk, &mut scratch, simd);
                assert_eq!(format!("{block:?}"), exact, "config {k}, chunk {chunk}, simd {simd}");
            }
        }
    }
    // The wide lobe and the close plane 2 take the f64 mode; the others screen in f32.
    assert_eq!(modes, [true, true, true, false, false, true]);
}

/// [`NearFilter32`] holds every query within its error band, at the worst place: a vertex set so
/// that the edge of its disc (c ± R) lies a hair inside a cell boundary, and queries up to the full
/// error E beyond that edge, across the boundary — in the cells that only the margin E marks. On
/// both sides, on both axes, near the origin and far out (with E proportional to the coordinates,
/// as the block loop's errors are), with cells of side 2R and with the wider cells of a large
/// reach. One vertex per filter, so that no other vertex marks the cells in question.
#[test]
fn near_filter32_covers_its_error_band() {
    use super::near_filter::{round_down_f32, round_up_f32};
    let r = 0.003;
    let mut rng = stream(6, 6, 6);
    let mut u = move || crate::sim::math::rng::uniform(&mut rng);
    for reach in [50.0, 1e7] {
        // The cell boundaries: where the filter's cell index steps, found by bisection on f32
        // values around (k + 1/2)·h; `b` is the first f32 of the cell k + 1.
        let probe = NearFilter32::new(std::iter::empty(), r, 0.0, reach);
        let h = 1.0 / f64::from(probe.inv_cell);
        let axis = |x: f32| probe.cell(x, 0.0) & 0xff;
        let boundary = |k: f64| {
            let (mut a, mut b) = (((k + 0.25) * h) as f32, ((k + 0.75) * h) as f32);
            while b.next_down() > a {
                let m = ((f64::from(a) + f64::from(b)) / 2.0) as f32;
                let m = if m <= a {
                    a.next_up()
                } else if m >= b {
                    b.next_down()
                } else {
                    m
                };
                if axis(m) == axis(a) { a = m } else { b = m }
            }
            f64::from(b)
        };
        let (mut queries, mut only_the_margin) = (0, 0);
        for j in 0..240 {
            let scale = [1.0, 10.0, reach * 0.4][j % 3];
            let e = 1e-4f64.max(scale * 2f64.powi(-19));
            let b = boundary(((u() * 2.0 - 1.0) * scale / h).round());
            // The disc's left (side 1) or right (side −1) edge just inside the boundary, on the x
            // or the y axis.
            // (Side −1 measures from the last f32 of the cell k, as the rounded-up bound of the
            // disc may equal an f32 bound exactly.)
            let side = if j % 4 < 2 { 1.0 } else { -1.0 };
            let anchor = if side > 0.0 { b } else { f64::from((b as f32).next_down()) };
            let c_main = anchor + side * (r * (1.0 + 1e-9) + b.abs() * 2f64.powi(-40));
            let c_other = (u() * 2.0 - 1.0) * scale;
            let on_x = j % 8 < 4;
            let c = if on_x { [c_main, c_other] } else { [c_other, c_main] };
            let filter = NearFilter32::new([c].into_iter(), r, e, reach);
            let without_margin = NearFilter32::new([c].into_iter(), r, 0.0, reach);
            for t in [0.25, 0.5, 0.75, 0.999] {
                // A point on the rim, then an f32 query up to E beyond it (rounded towards the
                // vertex, so that it stays within E).
                let v = c_main - side * (r + e * t);
                let q_main = if side > 0.0 { round_up_f32(v) } else { round_down_f32(v) };
                let q = if on_x { [q_main, c_other as f32] } else { [c_other as f32, q_main] };
                assert_eq!(filter.holds(filter.cell(q[0], q[1])), 1, "missed {q:?} of vertex {c:?}, E = {e}");
                queries += 1;
                only_the_margin += 1 - without_margin.holds(without_margin.cell(q[0], q[1]));
            }
        }
        assert!(
            only_the_margin * 2 > queries,
            "the queries must lie in cells only the margin marks ({only_the_margin})"
        );
    }
}
