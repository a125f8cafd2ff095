//! Unit tests of the job specification: presets, overrides, unknown fields, the ranges of values
//! and the shards of a study.

use serde_json::{Value, json};

use super::*;
use crate::sim::model::params::IlluminationSpec;
use crate::sim::solve::options::FixedWeights;

fn parse(doc: Value) -> Result<JobSpec, SpecError> {
    parse_job_spec(&doc)
}

fn invalid(doc: Value) -> SpecError {
    match parse(doc) {
        Err(e) => e,
        Ok(spec) => spec.validate().expect_err("the spec should be rejected"),
    }
}

#[test]
fn paper_preset_is_valid_and_matches_the_paper() {
    let spec = parse(json!({})).unwrap();
    assert_eq!(spec.preset, "paper-table1");
    assert_eq!(spec.light_paths, 10_000_000);
    assert_eq!(spec.camera_paths, 100);
    assert_eq!(spec.merge_radius, 0.003);
    assert_eq!(spec.cells.r3_edges.len(), 26);
    let IlluminationSpec::Spot { contrast, .. } = spec.scene.illumination else { panic!() };
    assert!((contrast - 3333.333).abs() < 1e-3);
    let job = spec.validate().unwrap();
    assert_eq!(job.config().cells.len(), 52);
}

#[test]
fn overrides_merge_and_kind_changes_replace() {
    let spec = parse(json!({
        "scene": { "beta_deg": 5, "illumination": { "kind": "uniform", "r_ls": 7 } },
        "light_paths": 1e5,
        "solver": { "fixed": { "w0": null, "w2": 0.5 } }
    }))
    .unwrap();
    assert_eq!(spec.scene.beta_deg, 5.0);
    assert_eq!(spec.scene.l3, 3.0, "untouched fields keep the preset's value");
    assert_eq!(spec.scene.illumination, IlluminationSpec::Uniform { r_ls: 7.0 });
    assert_eq!(spec.light_paths, 100_000);
    assert_eq!(spec.solver.fixed, FixedWeights { w0: None, w1: None, w2: Some(0.5) });
    spec.validate().unwrap();
}

#[test]
fn unknown_fields_are_errors_with_their_path() {
    let e = parse(json!({ "scene": { "l4": 1 } })).unwrap_err();
    assert_eq!(e.field, "scene.l4");
    assert!(e.message.contains("unknown field `l4`"), "{e}");
    let e = parse(json!({ "scene": { "illumination": { "kind": "spot", "b": 1 } } })).unwrap_err();
    assert!(e.field.starts_with("scene.illumination"), "{e}");
    let e = parse(json!({ "iterationz": 3 })).unwrap_err();
    assert!(e.message.contains("iterationz"), "{e}");
    let e = parse(json!({ "preset": "nope" })).unwrap_err();
    assert_eq!(e.field, "preset");
    let e = parse(json!({ "light_paths": -3 })).unwrap_err();
    assert_eq!(e.field, "light_paths");
    let e = parse(json!({ "light_paths": 2.5 })).unwrap_err();
    assert_eq!(e.field, "light_paths");
}

#[test]
fn invalid_values_name_the_field_and_range() {
    let cases = [
        (json!({ "merge_radius": -1 }), "merge_radius"),
        (json!({ "merge_radius": 0 }), "merge_radius"),
        (json!({ "merge_radius": 2 }), "merge_radius"),
        (json!({ "scene": { "beta_deg": 50 } }), "scene.beta_deg"),
        (json!({ "scene": { "beta_deg": 0 } }), "scene.beta_deg"),
        (json!({ "scene": { "beta_deg": 1e-9 } }), "scene.beta_deg"),
        (json!({ "scene": { "l2": 1e-12 } }), "scene.l2"),
        (json!({ "merge_radius": 1e-10 }), "merge_radius"),
        (
            json!({ "scene": { "illumination": { "kind": "rings", "rings": [
            { "outer_radius": 1, "level": 1e-320 } ] } } }),
            "scene.illumination",
        ),
        (json!({ "scene": { "l2": 0 } }), "scene.l2"),
        (json!({ "scene": { "illumination": { "a": -0.1 } } }), "scene.illumination.a"),
        (json!({ "scene": { "illumination": { "r_ls": 0.01 } } }), "scene.illumination.r_ls"),
        (
            json!({ "scene": { "illumination": { "kind": "rings", "rings": [
            { "outer_radius": 1, "level": 1 }, { "outer_radius": 0.5, "level": 1 } ] } } }),
            "scene.illumination.rings[1].outer_radius",
        ),
        (
            json!({ "scene": { "illumination": { "kind": "rings", "rings": [
            { "outer_radius": 1, "level": 0 } ] } } }),
            "scene.illumination.rings",
        ),
        (json!({ "light_paths": 0 }), "light_paths"),
        (json!({ "camera_paths": 0 }), "camera_paths"),
        (json!({ "iterations": 0 }), "iterations"),
        (json!({ "cells": { "r3_edges": [0, 0.2, 0.1] } }), "cells.r3_edges[2]"),
        (json!({ "cells": { "r2_edges": [0.1, 0.2] } }), "cells.r2_edges"),
        (json!({ "cells": { "phi_bins": 0 } }), "cells.phi_bins"),
        (json!({ "cells": { "phi_bins": 10 } }), "cells"),
        (json!({ "solver": { "lambda": -1 } }), "solver.lambda"),
        (json!({ "solver": { "fixed": { "w0": 0.2, "w1": 0.2, "w2": 0.2 } } }), "solver.fixed"),
        (json!({ "solver": { "cv_lambdas": [] } }), "solver.cv_lambdas"),
    ];
    for (doc, field) in cases {
        let e = invalid(doc.clone());
        assert_eq!(e.field, field, "{doc} gave {e}");
        assert!(!e.message.is_empty());
    }
    let e = invalid(json!({ "scene": { "beta_deg": 50 } }));
    assert!(e.message.contains("[1e-6, 45]"), "the message states the range: {e}");
}

#[test]
fn nan_cannot_be_smuggled_in() {
    // JSON has no NaN; serde_json rejects the bare token at parse time, and infinity overflows
    // to a parse error too. A huge exponent is the closest a document can get.
    assert!(serde_json::from_str::<Value>("{\"merge_radius\": NaN}").is_err());
    let e = invalid(json!({ "merge_radius": 1e308 }));
    assert_eq!(e.field, "merge_radius");
}

#[test]
fn shards_partition_the_study() {
    for (m, n) in [(10, 3), (7, 7), (10_000, 2), (5, 1), (1_000_003, 64)] {
        let mut covered = 0;
        let mut next = 0;
        for k in 0..n {
            let spec = parse(json!({ "iterations": m, "shard": { "index": k, "count": n } })).unwrap();
            spec.validate().unwrap();
            let r = spec.iteration_range();
            assert_eq!(r.start, next, "shards are contiguous");
            assert!(!r.is_empty());
            covered += r.end - r.start;
            next = r.end;
        }
        assert_eq!((covered, next), (m, m));
    }
    let spec = parse(json!({ "iterations": 10, "first_iteration": 100 })).unwrap();
    assert_eq!(spec.iteration_range(), 100..110);
    assert_eq!(parse(json!({ "iterations": 10 })).unwrap().iteration_range(), 0..10);
    // A shard of [f, f + M): how a cluster's tasks cut a job's added iterations.
    let later = parse(json!({ "iterations": 10, "first_iteration": 100, "shard": { "index": 1, "count": 3 } }));
    assert_eq!(later.unwrap().iteration_range(), 103..106);
    for (doc, field) in [
        (json!({ "iterations": 3, "shard": { "index": 3, "count": 3 } }), "shard.index"),
        (json!({ "iterations": 3, "shard": { "index": 0, "count": 4 } }), "shard.count"),
        (json!({ "iterations": 3, "shard": { "index": 0, "count": 0 } }), "shard.count"),
        (json!({ "iterations": 3, "execution": { "tasks": 4 } }), "execution.tasks"),
        (json!({ "iterations": 3, "execution": { "tasks": 0 } }), "execution.tasks"),
        (json!({ "first_iteration": 4_611_686_018_427_387_904u64 }), "first_iteration"),
    ] {
        assert_eq!(invalid(doc.clone()).field, field, "{doc}");
    }
}

#[test]
fn resolved_spec_round_trips() {
    let spec = parse(json!({ "preset": "uniform-illumination", "seed": 42 })).unwrap();
    let again = parse(serde_json::to_value(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
}

#[test]
fn names_labels_and_notes_are_bounded_and_name_their_field() {
    let many: serde_json::Map<String, Value> = (0..=MAX_LABELS).map(|i| (format!("k{i}"), json!("v"))).collect();
    for (doc, field) in [
        (json!({ "name": " " }), "name"),
        (json!({ "name": "n".repeat(MAX_NAME + 1) }), "name"),
        (json!({ "labels": many }), "labels"),
        (json!({ "labels": { "bad key": "x" } }), "labels.bad key"),
        (json!({ "labels": { "k": "a\u{1b}b" } }), "labels.k"),
        (json!({ "notes": "n".repeat(MAX_NOTES + 1) }), "notes"),
    ] {
        assert_eq!(invalid(doc.clone()).field, field, "{doc}");
    }
    let fine = json!({ "name": "n".repeat(MAX_NAME), "labels": { "study": "radius" }, "notes": "a\nb" });
    let spec = parse(fine).unwrap();
    spec.validate().unwrap();
    assert_eq!(spec.labels["study"], "radius", "labels stay a map of strings in the document");
}
