//! Which fields of a job specification make its configuration — the statistics' fingerprint —
//! and how two specifications differ in them: what a refused merge names (`scene.l3: 9.0 vs 3.0`)
//! instead of two fingerprints.

use std::collections::BTreeMap;

use serde_json::Value;

use super::spec::JobSpec;
use crate::sim::stats::moments::MergeError;

/// The fields of a spec that make the configuration fingerprint (docs/model.md: scene, R, N_F,
/// N_B, cells, engine, folds, noise components, the smaller radii tallied); the rest — seed, iterations, shard, solver,
/// execution, preset — may differ between runs that merge.
const CONFIGURATION_FIELDS: [&str; 9] =
    ["scene", "merge_radius", "light_paths", "camera_paths", "cells", "engine", "folds", "noise_components", "radii"];

/// The configuration fields in which `other` differs from `base`, as `path: other's vs base's`
/// (e.g. `scene.l3: 9 vs 3`): what a refused merge names instead of two fingerprints.
pub fn configuration_differences(base: &JobSpec, other: &JobSpec) -> Vec<String> {
    fn leaves(prefix: &str, value: &Value, out: &mut BTreeMap<String, String>) {
        match value {
            Value::Object(map) => {
                for (key, v) in map {
                    leaves(&format!("{prefix}.{key}"), v, out);
                }
            }
            other => {
                out.insert(prefix.to_string(), other.to_string());
            }
        }
    }
    let flatten = |spec: &JobSpec| {
        let value = serde_json::to_value(spec).unwrap_or(Value::Null);
        let mut out = BTreeMap::new();
        for field in CONFIGURATION_FIELDS {
            leaves(field, value.get(field).unwrap_or(&Value::Null), &mut out);
        }
        out
    };
    let (mine, theirs) = (flatten(base), flatten(other));
    let absent = "absent".to_string();
    let mut paths: Vec<&String> = mine.keys().chain(theirs.keys()).collect();
    paths.sort();
    paths.dedup();
    paths
        .into_iter()
        .filter_map(|path| {
            let (a, b) = (theirs.get(path).unwrap_or(&absent), mine.get(path).unwrap_or(&absent));
            (a != b).then(|| format!("{path}: {a} vs {b}"))
        })
        .collect()
}

/// `error` with the configuration fields that differ named, when it is a fingerprint mismatch
/// between the statistics of `merged_in` and `into` (the moments know only their fingerprints).
pub fn explained(error: MergeError, merged_in: &JobSpec, into: &JobSpec) -> MergeError {
    match error {
        MergeError::Fingerprint { found, expected, .. } => {
            MergeError::Fingerprint { found, expected, differences: configuration_differences(into, merged_in) }
        }
        other => other,
    }
}
