//! Published reference tables — the paper's Table 1 — as data (`references/*.json`, embedded at
//! build time), and whether a job's configuration is the one a table was measured under, so that
//! its values can be shown beside a run's (`/result`'s `references`, `GET /v1/references`,
//! `optimis run --paper`, the CSVs). Nothing here enters a computation.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::sim::solve::export::PaperColumns;
use crate::sim::spec::JobSpec;

/// The tables' JSON sources, in the order they are listed.
const SOURCES: [&str; 1] = [include_str!("../../../references/ershov2020-table1.json")];

/// A published table of figures for one configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ReferenceTable {
    /// Stable identifier (`ershov2020-table1`).
    pub id: String,
    /// What the table is.
    pub title: String,
    /// Where it was published.
    pub source: String,
    /// Iterations the published figures were measured on.
    pub iterations: u64,
    /// How to read and compare the figures.
    pub notes: String,
    /// The configuration the figures were measured under: dotted fields of the job specification
    /// and their values (numbers compared to 1 part in 10⁹). The figures apply to a job whose
    /// specification has every one of them.
    #[cfg_attr(feature = "server", schema(value_type = Object))]
    pub configuration: BTreeMap<String, Value>,
    /// One row per strategy that has a counterpart in optimis' noise table.
    pub rows: Vec<ReferenceRow>,
}

/// One published row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ReferenceRow {
    /// The noise-table row it corresponds to (`plane1`, …, `switch`, `optimal`).
    pub strategy: String,
    /// The paper's case number.
    pub case: u32,
    /// The weights, as the paper states them.
    pub weights: String,
    /// Published luminance L, in the model's units.
    pub luminance: f64,
    /// Published RMS noise of one iteration, in percent of L.
    pub rms_percent: f64,
    /// Further fields this row alone needs (the optimum's `solver.fixed.w0`: the paper's fit kept
    /// w0 = 0); a job without them gets the table without this row.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    #[cfg_attr(feature = "server", schema(value_type = Object))]
    pub requires: BTreeMap<String, Value>,
}

/// Every published table.
pub fn tables() -> &'static [ReferenceTable] {
    static TABLES: OnceLock<Vec<ReferenceTable>> = OnceLock::new();
    TABLES.get_or_init(|| {
        SOURCES.iter().map(|s| serde_json::from_str(s).expect("references/*.json are valid (tested)")).collect()
    })
}

/// The tables whose configuration `spec` has, each with only the rows that apply to it.
pub fn applicable(spec: &JobSpec) -> Vec<ReferenceTable> {
    let value = serde_json::to_value(spec).unwrap_or(Value::Null);
    tables()
        .iter()
        .filter(|t| mismatches(&t.configuration, &value).is_empty())
        .map(|t| ReferenceTable {
            rows: t.rows.iter().filter(|r| mismatches(&r.requires, &value).is_empty()).cloned().collect(),
            ..t.clone()
        })
        .collect()
}

/// A strategy's published (L, RMS %) in the first of `tables` that has a row for it.
pub fn figures(tables: &[ReferenceTable], strategy: &str) -> Option<(f64, f64)> {
    tables.iter().flat_map(|t| &t.rows).find(|r| r.strategy == strategy).map(|r| (r.luminance, r.rms_percent))
}

/// A noise-table row's CSV columns from the published tables: its case number in any of them,
/// and the figures of `applicable` (the tables that apply to the job) where it has them.
pub fn paper_columns(applicable: &[ReferenceTable], strategy: &str) -> PaperColumns {
    let case = tables().iter().flat_map(|t| &t.rows).find(|r| r.strategy == strategy).map(|r| r.case);
    PaperColumns { case, figures: figures(applicable, strategy) }
}

/// The fields of `table`'s configuration in which `spec` differs, as `field: the job's vs the
/// table's` (empty: the table applies).
pub fn differences(table: &ReferenceTable, spec: &JobSpec) -> Vec<String> {
    mismatches(&table.configuration, &serde_json::to_value(spec).unwrap_or(Value::Null))
}

fn mismatches(wanted: &BTreeMap<String, Value>, spec: &Value) -> Vec<String> {
    wanted
        .iter()
        .filter_map(|(path, want)| {
            let have = path.split('.').try_fold(spec, |v, key| v.get(key)).unwrap_or(&Value::Null);
            (!same(have, want)).then(|| format!("{path}: {have} vs {want}"))
        })
        .collect()
}

fn same(have: &Value, want: &Value) -> bool {
    match (have.as_f64(), want.as_f64()) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * b.abs().max(1.0),
        _ => have == want,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::spec::parse_job_spec;
    use serde_json::json;

    #[test]
    fn the_papers_table_applies_to_the_paper_preset_only() {
        assert_eq!(tables().len(), SOURCES.len());
        let paper = parse_job_spec(&json!({ "preset": "paper-table1", "iterations": 100, "seed": 7 })).unwrap();
        let applied = applicable(&paper);
        assert_eq!(applied.len(), 1);
        assert_eq!(applied[0].rows.len(), 5);
        assert_eq!(applied[0].rows[3].strategy, "switch");
        assert!((applied[0].rows[3].luminance - 26.352e-5).abs() < 1e-12);
        // The optimum's row needs w0 = 0; the fixed strategies' rows do not.
        let free = parse_job_spec(&json!({ "solver": { "fixed": { "w0": null } } })).unwrap();
        let rows: Vec<String> = applicable(&free)[0].rows.iter().map(|r| r.strategy.clone()).collect();
        assert_eq!(rows, ["plane1", "plane2", "plane3", "switch"]);
        // Another scene: not the paper's figures, and the fields that differ are named.
        let other = parse_job_spec(&json!({ "scene": { "l3": 9 }, "merge_radius": 0.01 })).unwrap();
        assert!(applicable(&other).is_empty());
        assert_eq!(differences(&tables()[0], &other), ["merge_radius: 0.01 vs 0.003", "scene.l3: 9.0 vs 3.0"]);
        // The uniform preset is not the paper's Table 1 either.
        let uniform = parse_job_spec(&json!({ "preset": "uniform-illumination" })).unwrap();
        assert!(applicable(&uniform).is_empty());
    }
}
