//! Tests of the brute force: the block loop against a scalar reference, the near filters, the pixel
//! tests, and the AVX2 build against the portable one.

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
