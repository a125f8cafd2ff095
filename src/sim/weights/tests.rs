//! The reference evaluator against the engine: on 10⁵ join paths drawn with the engine's samplers,
//! the artifact of a table, a heuristic and a stack gives the engine's weight of every merge.

use super::build::{RowWeights, artifact, recommended_row};
use super::densities::model_path;
use super::function::WeightFunction;
use super::samples::{engine_artifact_weight, join_paths};
use crate::sim::runner::run;
use crate::sim::solve::report::{ReportInputs, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::{ValidJob, parse_job_spec};

fn job(doc: serde_json::Value) -> ValidJob {
    parse_job_spec(&doc).unwrap().validate().unwrap()
}

/// Every kind of artifact of a run of `job`: its recommendation, `optimal_cv`'s table and
/// `optimal_stacked`'s stack (at their λ), and the plain switch.
fn artifacts(job: &ValidJob, iterations: u64) -> Vec<super::artifact::WeightsArtifact> {
    let config = job.config();
    let moments = run(config, 5, 0..iterations);
    let solver = &job.spec().solver;
    let report = build_report(&moments, config.cells(), solver, &ReportInputs::default());
    let mut out = vec![artifact(config, &report, &recommended_row(&report).unwrap()).unwrap()];
    for strategy in [Strategy::OptimalCv, Strategy::OptimalStacked] {
        let row = report.noise_table.iter().find(|r| r.strategy == strategy).unwrap();
        let Some(lambda) = row.lambda else { continue };
        let query = WeightsQuery {
            lambda,
            strategy: if strategy == Strategy::OptimalCv { Strategy::Optimal } else { strategy },
        };
        let fitted = build_report(
            &moments,
            config.cells(),
            solver,
            &ReportInputs { weights: Some(query), ..Default::default() },
        );
        assert!(fitted.solve_error.is_none(), "{strategy} at λ = {lambda}: {:?}", fitted.solve_error);
        let weights = RowWeights {
            strategy,
            recommended: false,
            table: &fitted.weights,
            heuristics: row.heuristics.iter().filter_map(|h| h.strategy.path().map(|p| (p, h.beta))).collect(),
            lambda: Some(lambda),
        };
        out.push(artifact(config, &report, &weights).unwrap());
    }
    let switch =
        RowWeights { strategy: Strategy::Switch, recommended: false, table: &[], heuristics: Vec::new(), lambda: None };
    out.push(artifact(config, &report, &switch).unwrap());
    out
}

#[test]
fn the_reference_evaluator_gives_the_engines_weight_of_every_merge() {
    for doc in [
        serde_json::json!({ "preset": "paper-table1" }),
        serde_json::json!({ "preset": "paper-table1", "merge_radius": 0.01, "scene": { "beta_deg": 8.0, "l3": 2.0 } }),
        serde_json::json!({ "preset": "uniform-illumination", "camera_paths": 30 }),
    ] {
        let job = job(doc);
        let config = job.config();
        let samples = join_paths(config, 11, 100_000);
        let kinds: Vec<_> = artifacts(&job, 3000).into_iter().map(|a| (a.kind, a.strategy.clone(), a)).collect();
        assert!(kinds.iter().any(|k| k.0 == super::artifact::WeightsKind::Stack), "a stack among {kinds:?}");
        for (kind, strategy, a) in kinds {
            let f = WeightFunction::new(a.clone()).unwrap();
            let mut worst: f64 = 0.0;
            for s in &samples {
                let path = model_path(&a.scene, s.x2, s.x3, s.x3_light);
                let ours = f.weight(s.technique, &path);
                let engine = engine_artifact_weight(config, &a, s);
                // Relative to the size of the terms (a stack's table and β·w_h may cancel).
                let scale = 1.0f64.max(engine.abs()) * (1.0 + a.heuristics.iter().map(|h| h.beta.abs()).sum::<f64>());
                worst = worst.max((ours - engine).abs() / scale);
            }
            eprintln!("{kind:?} {strategy}: worst relative error {worst:e} on {} merges", samples.len());
            assert!(worst <= 1e-12, "{kind:?} {strategy}: worst relative error {worst:e} on {} merges", samples.len());
        }
    }
}
