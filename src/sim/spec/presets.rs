//! The presets a job document starts from, and [`parse_job_spec`]: a submitted document (a preset
//! and overrides, merged by JSON Merge Patch) resolved into a [`JobSpec`].

use serde_json::{Value, json};

use super::document::JobSpec;
use crate::sim::model::params::{SpecError, merge_patch};

/// The preset used when a document names none.
pub const DEFAULT_PRESET: &str = "paper-table1";

/// The names of the presets.
pub const PRESETS: &[&str] = &["paper-table1", "uniform-illumination"];

/// A preset as a complete JSON document.
pub fn preset(name: &str) -> Option<Value> {
    // The paper's grid: r2 ∈ [0, ½] + tail; r3: 25 cells of 0.002 on [0, 0.05] + tail; one φ bin.
    let r3_edges: Vec<f64> = (0..=25).map(|i| f64::from(i) / 500.0).collect();
    let (a, r_ls) = (0.02, 20.0);
    let paper = json!({
        "preset": "paper-table1",
        "scene": {
            "l2": 1.0, "l3": 3.0, "beta_deg": 3.0,
            "illumination": { "kind": "spot", "a": a, "r_ls": r_ls, "contrast": (r_ls / a) * (r_ls / a) / 300.0 }
        },
        "merge_radius": 0.003,
        // The restricted engine: the same estimates thousands of times faster (see
        // `sim::engines::restricted`; tests/engines.rs checks the equivalence with the brute force).
        "engine": "restricted",
        "light_paths": 10_000_000u64,
        "camera_paths": 100,
        "iterations": 10_000,
        "seed": 1,
        "cells": { "r2_edges": [0.0, 0.5], "r3_edges": r3_edges, "phi_bins": 1 },
        "solver": {
            "fixed": { "w0": 0.0 },
            "lambda": 0.0,
            "cv_lambdas": [0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0]
        }
    });
    match name {
        "paper-table1" => Some(paper),
        // The paper's closing comparison: the same scene under uniform illumination.
        "uniform-illumination" => {
            let mut doc = paper;
            doc["preset"] = json!("uniform-illumination");
            doc["scene"]["illumination"] = json!({ "kind": "uniform", "r_ls": r_ls });
            Some(doc)
        }
        _ => None,
    }
}

/// Parses a submitted document (preset + overrides) into a resolved [`JobSpec`].
///
/// Only structure is checked here (types, unknown fields, the preset name); values are checked by
/// [`JobSpec::validate`].
pub fn parse_job_spec(document: &Value) -> Result<JobSpec, SpecError> {
    let Value::Object(fields) = document else {
        return Err(SpecError::new("", "the job specification must be a JSON object"));
    };
    let name = match fields.get("preset") {
        None | Some(Value::Null) => DEFAULT_PRESET,
        Some(Value::String(s)) => s.as_str(),
        Some(other) => return Err(SpecError::new("preset", format!("must be a string, got {other}"))),
    };
    let mut resolved = preset(name).ok_or_else(|| {
        SpecError::new("preset", format!("unknown preset {name:?}; known presets: {}", PRESETS.join(", ")))
    })?;
    merge_patch(&mut resolved, document);
    resolved["preset"] = json!(name);
    serde_path_to_error::deserialize::<_, JobSpec>(&resolved).map_err(|e| {
        let path = e.path().to_string();
        let field = if path == "." { String::new() } else { path };
        SpecError::new(field, e.into_inner().to_string())
    })
}
