//! The sweep document and its expansion into validated runs and points.
//!
//! Every bound is checked before anything is expanded: at most [`MAX_AXES`] axes of at most
//! [`MAX_AXIS_VALUES`] values, a path of at most [`MAX_PATH_SEGMENTS`] identifiers, and the number
//! of points (the product of the axes' lengths for a grid) at most the caller's limit — computed
//! with checked arithmetic, so a hostile document cannot make the expansion itself the cost.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::sim::model::params::{MAX_PATH_SEGMENTS, SpecError, merge_patch, path_patch};
use crate::sim::solve::predict::Budget;
use crate::sim::spec::{JobSpec, parse_job_spec};

/// Most axes of a sweep.
pub const MAX_AXES: usize = 4;
/// Most values of one axis.
pub const MAX_AXIS_VALUES: usize = 256;

/// A sweep: a base job document varied along axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    /// A job document (preset and overrides, as `POST /v1/jobs` takes); every point starts from it.
    #[cfg_attr(feature = "server", schema(value_type = Object))]
    pub base: Value,
    /// 1 to 4 axes; each names a field of the job document and its values.
    pub axes: Vec<Axis>,
    /// `grid` (default): every combination of the axes' values, the last axis varying fastest;
    /// `zip`: the i-th values of all axes together (the axes must have equal lengths).
    #[serde(default)]
    pub mode: SweepMode,
    /// With axes by prediction: also run every predicted point directly, so that its predicted and
    /// measured figures stand side by side (one more job per point).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub measure_predictions: bool,
}

/// One swept field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Dotted path of the field in the job document: `merge_radius`, `scene.l3`,
    /// `scene.illumination.a`, `solver.fixed.w0` (a value replaces the field, merged like an
    /// override: `null` removes it, an object merges into it).
    #[cfg_attr(feature = "server", schema(example = "scene.l3"))]
    pub field: String,
    /// 1 to 256 values.
    #[cfg_attr(feature = "server", schema(value_type = Vec<Object>))]
    pub values: Vec<Value>,
    /// `run` (default): each value is run. `prediction` (only `light_paths` and `camera_paths`):
    /// the values are predicted from one run with noise components at the base's budget.
    #[serde(default)]
    pub by: AxisSource,
}

/// How a sweep combines its axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum SweepMode {
    /// Every combination of the axes' values, the last axis varying fastest.
    #[default]
    Grid,
    /// The i-th values of all axes together (the axes have equal lengths).
    Zip,
}

/// Whether an axis's values are run or predicted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum AxisSource {
    /// Each value is a job of its own.
    #[default]
    Run,
    /// The values are predicted from one run with noise components (budget axes only).
    Prediction,
}

/// A job the sweep runs.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedRun {
    /// The run's number in the sweep (its jobs are stored in this order).
    pub index: usize,
    /// The resolved, validated specification.
    pub spec: JobSpec,
}

/// A point of the sweep: one row group of its table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct PlannedPoint {
    /// The point's number: its place in the expansion of the axes.
    pub index: usize,
    /// The value of every axis, in the axes' order.
    #[cfg_attr(feature = "server", schema(value_type = Vec<Object>))]
    pub values: Vec<Value>,
    /// The run whose moments answer it.
    pub run: usize,
    /// Set when the point is predicted: the budget to predict (the run measured another).
    pub predicted: Option<Budget>,
    /// With `measure_predictions`: the run that measures a predicted point directly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_run: Option<usize>,
}

/// A validated sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepPlan {
    /// The sweep document as validated.
    pub spec: SweepSpec,
    /// The jobs to run, in run order (fewer than the points when values are predicted).
    pub runs: Vec<PlannedRun>,
    /// The table's points, in expansion order.
    pub points: Vec<PlannedPoint>,
}

impl SweepPlan {
    /// The swept fields, in the axes' order.
    pub fn fields(&self) -> Vec<String> {
        self.spec.axes.iter().map(|a| a.field.clone()).collect()
    }

    /// Run `r`'s swept values (`field=value, …`, without the predicted axes), for messages.
    pub fn describe_run(&self, r: usize) -> String {
        let Some(point) = self.points.iter().find(|p| p.run == r) else { return String::new() };
        let parts: Vec<String> = self
            .spec
            .axes
            .iter()
            .zip(&point.values)
            .filter(|(a, _)| a.by == AxisSource::Run)
            .map(|(a, v)| format!("{}={}", a.field, truncate(&v.to_string())))
            .collect();
        parts.join(", ")
    }
}

/// Parses and expands a sweep document with at most `max_points` points.
pub fn plan(document: &Value, max_points: usize) -> Result<SweepPlan, SpecError> {
    let spec: SweepSpec = serde_path_to_error::deserialize(document).map_err(|e| {
        let path = e.path().to_string();
        SpecError::new(if path == "." { String::new() } else { path }, e.into_inner().to_string())
    })?;
    check_axes(&spec)?;
    if spec.measure_predictions && !spec.axes.iter().any(|a| a.by == AxisSource::Prediction) {
        return Err(SpecError::new("measure_predictions", "needs an axis with \"by\": \"prediction\""));
    }
    let count = point_count(&spec, max_points)?;
    let predicted_axes = spec.axes.iter().any(|a| a.by == AxisSource::Prediction);
    if !spec.base.is_object() {
        return Err(SpecError::new("base", "must be a job document (a JSON object)"));
    }
    for field in ["shard", "first_iteration"] {
        if spec.base.get(field).is_some_and(|v| !v.is_null()) {
            return Err(SpecError::new(format!("base.{field}"), "a sweep point runs all its iterations: remove it"));
        }
    }
    let mut base = spec.base.clone();
    if predicted_axes {
        // The one run of every predicted point keeps the components that predict it.
        merge_patch(&mut base, &serde_json::json!({ "noise_components": true }));
    }
    parse_job_spec(&base)
        .and_then(|s| s.validate().map(|_| ()))
        .map_err(|e| SpecError::new(prefixed("base", &e.field), e.message))?;

    let mut runs: Vec<PlannedRun> = Vec::new();
    let mut run_keys: Vec<Vec<Value>> = Vec::new();
    let mut points = Vec::with_capacity(count);
    for index in 0..count {
        let picks = picks(&spec, index);
        let values: Vec<Value> = picks.iter().enumerate().map(|(a, &v)| spec.axes[a].values[v].clone()).collect();
        let describe = || describe_point(&spec, index, &values);
        // The run: the base with the run axes' values.
        let mut run_doc = base.clone();
        let mut run_key = Vec::new();
        for (a, axis) in spec.axes.iter().enumerate() {
            if axis.by == AxisSource::Run {
                merge_patch(&mut run_doc, &patch(&axis.field, &values[a]));
                run_key.push(values[a].clone());
            }
        }
        let run = match run_keys.iter().position(|k| *k == run_key) {
            Some(r) => r,
            None => {
                let job = parse_job_spec(&run_doc)
                    .and_then(|s| s.validate())
                    .map_err(|e| blame(&spec, &picks, &e, &describe()))?;
                runs.push(PlannedRun { index: runs.len(), spec: job.into_spec() });
                run_keys.push(run_key);
                runs.len() - 1
            }
        };
        let mut measured_run = None;
        let predicted = if predicted_axes {
            // The point's own document, checked like a job at that budget (without components:
            // a predicted budget need not be even).
            let mut point_doc = run_doc.clone();
            for (a, axis) in spec.axes.iter().enumerate() {
                if axis.by == AxisSource::Prediction {
                    merge_patch(&mut point_doc, &patch(&axis.field, &values[a]));
                }
            }
            merge_patch(&mut point_doc, &serde_json::json!({ "noise_components": null }));
            let job = parse_job_spec(&point_doc)
                .and_then(|s| s.validate())
                .map_err(|e| blame(&spec, &picks, &e, &describe()))?;
            let budget = Budget { light_paths: job.spec().light_paths, camera_paths: job.spec().camera_paths };
            if spec.measure_predictions {
                measured_run = Some(runs.len());
                runs.push(PlannedRun { index: runs.len(), spec: job.into_spec() });
                // Never shared: no other point's run key can name it.
                run_keys.push(vec![Value::String(format!("measure point {index}"))]);
            }
            Some(budget)
        } else {
            None
        };
        points.push(PlannedPoint { index, values, run, predicted, measured_run });
    }
    // The limit bounds what a sweep queues: its runs, direct ones for measured predictions included.
    if runs.len() > max_points {
        return Err(SpecError::new(
            if spec.measure_predictions { "measure_predictions" } else { "axes" },
            format!(
                "the sweep queues {} runs for its {} points; this server runs at most {max_points} per sweep",
                runs.len(),
                points.len()
            ),
        ));
    }
    let mut plan = SweepPlan { spec, runs, points };
    name_runs(&mut plan);
    Ok(plan)
}

/// Names each run after its swept values (`NAME: merge_radius=0.003, scene.l3=1`, NAME the base
/// job's name or `sweep`), so that a job list tells a sweep's runs apart; at most 200 characters,
/// as a job's name.
fn name_runs(plan: &mut SweepPlan) {
    for r in 0..plan.runs.len() {
        let values = plan.describe_run(r);
        let spec = &mut plan.runs[r].spec;
        let base = spec.name.clone().unwrap_or_else(|| "sweep".to_string());
        let name = if values.is_empty() { base } else { format!("{base}: {values}") };
        spec.name = Some(if name.chars().count() <= 200 {
            name
        } else {
            format!("{}…", name.chars().take(199).collect::<String>())
        });
    }
}

/// The axes' paths and values within bounds, no axis twice or inside another, predictions only
/// over the ray counts.
fn check_axes(spec: &SweepSpec) -> Result<(), SpecError> {
    if spec.axes.is_empty() || spec.axes.len() > MAX_AXES {
        return Err(SpecError::new("axes", format!("must hold 1 to {MAX_AXES} axes, got {}", spec.axes.len())));
    }
    for (a, axis) in spec.axes.iter().enumerate() {
        let at = |what: &str| format!("axes[{a}].{what}");
        let segments: Vec<&str> = axis.field.split('.').collect();
        if path_patch(&axis.field, &Value::Null).is_none() {
            return Err(SpecError::new(
                at("field"),
                format!(
                    "must be a dotted path of at most {MAX_PATH_SEGMENTS} lower-case identifiers (e.g. scene.l3), got {:?}",
                    truncate(&axis.field)
                ),
            ));
        }
        if matches!(segments[0], "shard" | "first_iteration") {
            return Err(SpecError::new(at("field"), "a sweep point runs all its iterations: shards cannot be swept"));
        }
        if axis.values.is_empty() || axis.values.len() > MAX_AXIS_VALUES {
            return Err(SpecError::new(
                at("values"),
                format!("must hold 1 to {MAX_AXIS_VALUES} values, got {}", axis.values.len()),
            ));
        }
        if axis.by == AxisSource::Prediction && !matches!(axis.field.as_str(), "light_paths" | "camera_paths") {
            return Err(SpecError::new(
                at("by"),
                "only light_paths and camera_paths can be answered by prediction (docs/model.md §12)",
            ));
        }
        for (b, other) in spec.axes.iter().enumerate().take(a) {
            let nested = |x: &str, y: &str| x == y || x.starts_with(&format!("{y}."));
            if nested(&axis.field, &other.field) || nested(&other.field, &axis.field) {
                return Err(SpecError::new(
                    at("field"),
                    format!("{:?} overlaps axes[{b}] ({:?}): each field is swept by one axis", axis.field, other.field),
                ));
            }
        }
    }
    Ok(())
}

/// The number of points, at most `max_points`.
fn point_count(spec: &SweepSpec, max_points: usize) -> Result<usize, SpecError> {
    let mut lengths = spec.axes.iter().map(|a| a.values.len());
    let count = match spec.mode {
        SweepMode::Grid => lengths.try_fold(1usize, |n, l| n.checked_mul(l)).unwrap_or(usize::MAX),
        SweepMode::Zip => {
            let first = spec.axes[0].values.len();
            if let Some((a, axis)) = spec.axes.iter().enumerate().find(|(_, x)| x.values.len() != first) {
                return Err(SpecError::new(
                    format!("axes[{a}].values"),
                    format!(
                        "zip needs axes of equal length: axes[0] has {first} values, this one {}",
                        axis.values.len()
                    ),
                ));
            }
            first
        }
    };
    if count > max_points {
        return Err(SpecError::new(
            "axes",
            format!("the sweep has {count} points; this server runs at most {max_points} per sweep"),
        ));
    }
    Ok(count)
}

/// Which value of every axis point `index` takes.
fn picks(spec: &SweepSpec, index: usize) -> Vec<usize> {
    match spec.mode {
        SweepMode::Zip => vec![index; spec.axes.len()],
        SweepMode::Grid => {
            let mut rest = index;
            let mut out = vec![0; spec.axes.len()];
            for (a, axis) in spec.axes.iter().enumerate().rev() {
                out[a] = rest % axis.values.len();
                rest /= axis.values.len();
            }
            out
        }
    }
}

/// The patch of a checked axis path.
fn patch(path: &str, value: &Value) -> Value {
    path_patch(path, value).expect("axis paths are checked first")
}

/// The error of a point's job, named after the axis whose field it concerns (else the point's last
/// axis: a combination is at fault), with the point's values in the message.
fn blame(spec: &SweepSpec, picks: &[usize], e: &SpecError, point: &str) -> SpecError {
    let concerns = |field: &str| {
        e.field == field || e.field.starts_with(&format!("{field}.")) || {
            // A field inside an axis's value (`scene.illumination` swept, `scene.illumination.a` wrong).
            e.field.starts_with(&format!("{field}["))
        }
    };
    let a = spec.axes.iter().position(|x| concerns(&x.field)).unwrap_or(spec.axes.len() - 1);
    SpecError::new(format!("axes[{a}].values[{}]", picks[a]), format!("{point}: {}: {}", e.field, e.message))
}

fn describe_point(spec: &SweepSpec, index: usize, values: &[Value]) -> String {
    let parts: Vec<String> =
        spec.axes.iter().zip(values).map(|(a, v)| format!("{}={}", a.field, truncate(&v.to_string()))).collect();
    format!("point {index} ({})", parts.join(", "))
}

fn prefixed(prefix: &str, field: &str) -> String {
    if field.is_empty() { prefix.to_string() } else { format!("{prefix}.{field}") }
}

fn truncate(text: &str) -> String {
    if text.len() <= 80 { text.to_string() } else { format!("{}…", &text[..text.floor_char_boundary(77)]) }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn sweep(axes: Value, mode: &str) -> Value {
        json!({ "base": { "iterations": 10, "light_paths": 1000 }, "axes": axes, "mode": mode })
    }

    #[test]
    fn a_grid_varies_the_last_axis_fastest_and_a_zip_pairs_values() {
        let axes = json!([
            { "field": "merge_radius", "values": [0.001, 0.003, 0.01] },
            { "field": "scene.l3", "values": [1, 3] }
        ]);
        let p = plan(&sweep(axes.clone(), "grid"), 64).unwrap();
        assert_eq!((p.points.len(), p.runs.len()), (6, 6));
        assert_eq!(p.points[1].values, vec![json!(0.001), json!(3)]);
        assert_eq!(p.runs[3].spec.merge_radius, 0.003);
        assert_eq!(p.runs[3].spec.scene.l3, 3.0);
        assert_eq!(p.runs[3].spec.scene.l2, 1.0, "the rest of the scene is the base's");
        assert!(p.points.iter().all(|pt| pt.run == pt.index && pt.predicted.is_none()));
        let e = plan(&sweep(axes, "zip"), 64).unwrap_err();
        assert_eq!(e.field, "axes[1].values");
        let zip = json!([{ "field": "seed", "values": [1, 2] }, { "field": "scene.l3", "values": [1, 3] }]);
        let p = plan(&sweep(zip, "zip"), 64).unwrap();
        assert_eq!((p.runs[1].spec.seed, p.runs[1].spec.scene.l3), (2, 3.0));
    }

    #[test]
    fn bad_paths_values_and_sizes_name_the_axis_and_point() {
        let e = plan(&sweep(json!([{ "field": "scene.l4", "values": [1] }]), "grid"), 64).unwrap_err();
        assert_eq!(e.field, "axes[0].values[0]");
        assert!(e.message.contains("point 0 (scene.l4=1)") && e.message.contains("unknown field"), "{e}");
        let axes = json!([{ "field": "merge_radius", "values": [0.003, 5] }, { "field": "seed", "values": [1, 2] }]);
        let e = plan(&sweep(axes, "grid"), 64).unwrap_err();
        assert_eq!(e.field, "axes[0].values[1]");
        assert!(e.message.starts_with("point 2 (merge_radius=5, seed=1): merge_radius: must be in"), "{e}");
        for (axes, field) in [
            (json!([{ "field": "Scene..l3", "values": [1] }]), "axes[0].field"),
            (json!([{ "field": "shard.index", "values": [1] }]), "axes[0].field"),
            (json!([{ "field": "seed", "values": [] }]), "axes[0].values"),
            (json!([{ "field": "seed", "values": [1], "by": "prediction" }]), "axes[0].by"),
            (json!([{ "field": "scene", "values": [{}] }, { "field": "scene.l3", "values": [1] }]), "axes[1].field"),
            (json!([]), "axes"),
        ] {
            assert_eq!(plan(&sweep(axes.clone(), "grid"), 64).unwrap_err().field, field, "{axes}");
        }
        let big = json!([
            { "field": "seed", "values": (1..=256).collect::<Vec<_>>() },
            { "field": "iterations", "values": (1..=256).collect::<Vec<_>>() },
            { "field": "merge_radius", "values": vec![0.003; 256] },
            { "field": "light_paths", "values": vec![1000; 256] }
        ]);
        let e = plan(&sweep(big, "grid"), 64).unwrap_err();
        assert_eq!(e.field, "axes");
        assert!(e.message.contains("4294967296 points"), "{e}");
        let e = plan(
            &json!({ "base": { "shard": { "index": 0, "count": 2 } }, "axes": [{ "field": "seed", "values": [1] }] }),
            9,
        )
        .unwrap_err();
        assert_eq!(e.field, "base.shard");
        let e = plan(&json!({ "base": { "merge_radius": -1 }, "axes": [{ "field": "seed", "values": [1] }] }), 9)
            .unwrap_err();
        assert_eq!(e.field, "base.merge_radius");
    }

    #[test]
    fn predicted_axes_share_one_run_with_components() {
        let mut doc = json!({
            "base": { "iterations": 10, "light_paths": 1000 },
            "axes": [
                { "field": "scene.l3", "values": [1, 3] },
                { "field": "light_paths", "values": [1000, 3001, 100000], "by": "prediction" }
            ]
        });
        let p = plan(&doc, 64).unwrap();
        assert_eq!((p.points.len(), p.runs.len()), (6, 2));
        assert!(p.runs.iter().all(|r| r.spec.noise_components && r.spec.light_paths == 1000));
        assert_eq!(p.points[4].run, 1);
        assert_eq!(p.points[4].predicted, Some(Budget { light_paths: 3001, camera_paths: 100 }));
        let mut bad = doc.clone();
        bad["axes"][1]["values"][1] = json!(0);
        assert_eq!(plan(&bad, 64).unwrap_err().field, "axes[1].values[1]");
        let mut measured = doc.clone();
        measured["measure_predictions"] = json!(true);
        let p = plan(&measured, 64).unwrap();
        assert_eq!(p.runs.len(), 2 + 6, "one direct run per predicted point");
        let over = plan(&measured, 7).unwrap_err();
        assert_eq!(over.field, "measure_predictions", "6 points but 8 runs: {over}");
        assert_eq!(p.points[4].measured_run, Some(6));
        assert!(!p.runs[6].spec.noise_components);
        assert_eq!((p.runs[6].spec.light_paths, p.runs[6].spec.scene.l3), (3001, 3.0));
        doc["measure_predictions"] = json!(false);
        measured["axes"][1]["by"] = json!("run");
        assert_eq!(plan(&measured, 64).unwrap_err().field, "measure_predictions");
    }
}
