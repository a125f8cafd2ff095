//! An artifact from a run's result: the recommended row's weights (or any row's), the scene and
//! the heuristics' definitions written out, and the conversion back into the weights
//! `solve::evaluate` scores — so that an artifact evaluated on a long run gives the figures of the
//! result it came from.

use std::f64::consts::PI;

use super::artifact::{ArtifactHeuristic, ArtifactProvenance, ArtifactRing, ArtifactScene, CellAxes, Formula};
use super::artifact::{TableCell, WEIGHTS_FORMAT, WEIGHTS_VERSION, WeightsArtifact, WeightsKind};
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::CellGrid;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::effective::FitReplicates;
use crate::sim::solve::evaluate::{GivenCell, GivenHeuristic, GivenRecommendation, GivenWeights};
use crate::sim::solve::report::{ReportInputs, RunReport, WeightRow, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::ValidJob;
use crate::sim::stats::moments::Moments;

/// The scene of `config` as an artifact states it.
pub fn artifact_scene(config: &SimConfig) -> ArtifactScene {
    let scene = &config.scene;
    let illumination = &scene.illumination;
    ArtifactScene {
        l2: scene.l2,
        l3: scene.l3,
        beta_rad: scene.lobe.beta,
        merge_radius: config.merge_radius,
        light_paths: config.light_paths as f64,
        camera_paths: config.camera_paths as f64,
        rings: illumination
            .rings()
            .iter()
            .map(|r| ArtifactRing { inner: r.r_in, outer: r.r_out, level: r.level })
            .collect(),
        flux: illumination.flux(),
    }
}

/// The definition of per-path strategy `p` in `config` with coefficient `beta`.
pub fn heuristic(config: &SimConfig, p: PathStrategy, beta: f64) -> ArtifactHeuristic {
    let area = PI * config.merge_radius * config.merge_radius;
    let correlation = Formula::CorrelationAware {
        area,
        light_paths: config.light_paths as f64,
        camera_paths: config.camera_paths as f64,
    };
    let all = [true; 3];
    let planes23 = [false, true, true];
    let (formula, techniques) = match p {
        PathStrategy::Plane1 => (Formula::OneTechnique { technique: 0 }, all),
        PathStrategy::Plane2 => (Formula::OneTechnique { technique: 1 }, all),
        PathStrategy::Plane3 => (Formula::OneTechnique { technique: 2 }, all),
        PathStrategy::Switch => (Formula::Switch { radius: config.scene.illumination.switch_radius() }, planes23),
        PathStrategy::Balance => (Formula::Balance, all),
        PathStrategy::Power => (Formula::Power { exponent: 2.0 }, all),
        PathStrategy::CorrelationAware => (correlation, all),
        PathStrategy::BalancePlanes23 => (Formula::Balance, planes23),
        PathStrategy::PowerPlanes23 => (Formula::Power { exponent: 2.0 }, planes23),
        PathStrategy::CorrelationAwarePlanes23 => (correlation, planes23),
    };
    ArtifactHeuristic { name: p.name().to_string(), beta, formula, techniques }
}

/// Which row an artifact is made of, and the weights behind it.
pub struct RowWeights<'a> {
    /// The row.
    pub strategy: Strategy,
    /// Whether the run recommends it.
    pub recommended: bool,
    /// A fitted row's table (the all-data fit at its λ, in cell order); empty for a per-path row.
    pub table: &'a [WeightRow],
    /// A fitted row's stacked heuristics and their β.
    pub heuristics: Vec<(PathStrategy, f64)>,
    /// A fitted row's λ.
    pub lambda: Option<f64>,
}

/// The artifact of `row` of `report`, a run of `config`.
pub fn artifact(config: &SimConfig, report: &RunReport, row: &RowWeights<'_>) -> Result<WeightsArtifact, String> {
    let grid = config.cells();
    let noise = report.noise_table.iter().find(|r| r.strategy == row.strategy);
    let provenance = ArtifactProvenance {
        fingerprint: report.fingerprint.clone(),
        iterations: report.iterations,
        coverage: report.coverage.clone(),
        lambda: row.lambda,
        rms_percent: noise.and_then(|r| r.rms_percent),
        rms_percent_stderr: noise.and_then(|r| r.rms_percent_stderr),
        job_id: None,
        generator: concat!("optimis ", env!("CARGO_PKG_VERSION")).to_string(),
    };
    let base = |kind, cells, table, heuristics| WeightsArtifact {
        format: WEIGHTS_FORMAT.into(),
        version: WEIGHTS_VERSION,
        strategy: row.strategy.name().into(),
        recommended: row.recommended,
        kind,
        scene: artifact_scene(config),
        cells,
        table,
        heuristics,
        provenance: provenance.clone(),
        signature: None,
    };
    if let Some(p) = row.strategy.path() {
        return Ok(base(WeightsKind::Heuristic, None, Vec::new(), vec![heuristic(config, p, 1.0)]));
    }
    if row.table.len() != grid.len() {
        return Err(format!(
            "{} has no weights table here ({} cells, the grid has {})",
            row.strategy,
            row.table.len(),
            grid.len()
        ));
    }
    let table = row
        .table
        .iter()
        .enumerate()
        .map(|(a, w)| {
            let (r2, r3, phi) = grid.coordinates(a);
            TableCell { r2, r3, phi, w: [w.w0, w.w1, w.w2] }
        })
        .collect();
    let heuristics: Vec<ArtifactHeuristic> = row.heuristics.iter().map(|&(h, b)| heuristic(config, h, b)).collect();
    let kind = if heuristics.is_empty() { WeightsKind::Table } else { WeightsKind::Stack };
    Ok(base(kind, Some(axes(grid)), table, heuristics))
}

/// The axes of `grid`.
pub fn axes(grid: &CellGrid) -> CellAxes {
    CellAxes { r2_edges: grid.r2_edges().to_vec(), r3_edges: grid.r3_edges().to_vec(), phi_bins: grid.phi_bins() }
}

/// The artifact of row `strategy` (none: the recommended row) of a run's `moments` of `job`, its
/// report built with `inputs` (the expectations and reference the run's result has): the
/// recommended row and per-path rows from the report itself, another fitted row refitted on all
/// iterations at its λ.
pub fn artifact_of_moments(
    moments: &Moments,
    job: &ValidJob,
    inputs: &ReportInputs<'_>,
    strategy: Option<Strategy>,
) -> Result<WeightsArtifact, String> {
    artifact_and_replicates(moments, job, inputs, strategy).map(|(a, _)| a)
}

/// [`artifact_of_moments`] with the fold fits of its row at its λ (none for a per-path row), the
/// fit errors of its effective weights (`effective`).
pub fn artifact_and_replicates(
    moments: &Moments,
    job: &ValidJob,
    inputs: &ReportInputs<'_>,
    strategy: Option<Strategy>,
) -> Result<(WeightsArtifact, Option<FitReplicates>), String> {
    let config = job.config();
    let solver = &job.spec().solver;
    let report = build_report(moments, config.cells(), solver, inputs);
    let recommended = report.recommended.as_ref().map(|r| r.strategy);
    let chosen = strategy.or(recommended).ok_or("the run recommends no row")?;
    if Some(chosen) == recommended {
        let row = recommended_row(&report).expect("a recommendation");
        let own =
            report.weights_fit.as_ref().is_some_and(|f| Some(f.lambda) == row.lambda && f.strategy == row.strategy);
        let replicates = if own { report.replicates.clone() } else { None };
        return Ok((artifact(config, &report, &row)?, replicates));
    }
    if chosen.path().is_some() {
        let row = RowWeights { strategy: chosen, recommended: false, table: &[], heuristics: Vec::new(), lambda: None };
        return Ok((artifact(config, &report, &row)?, None));
    }
    let row = report.noise_table.iter().find(|r| r.strategy == chosen);
    let lambda = row.and_then(|r| r.lambda).ok_or_else(|| format!("{chosen} has no fit on this run"))?;
    let family = if matches!(chosen, Strategy::OptimalCv | Strategy::OptimalHoldout | Strategy::Optimal) {
        Strategy::Optimal
    } else {
        chosen
    };
    let query = ReportInputs { weights: Some(WeightsQuery { lambda, strategy: family }), ..inputs.clone() };
    let fitted = build_report(moments, config.cells(), solver, &query);
    if let Some(e) = &fitted.solve_error {
        return Err(format!("{chosen} could not be fitted at λ = {lambda}: {e}"));
    }
    let heuristics = row.map(|r| r.heuristics.iter().filter_map(|h| h.strategy.path().map(|p| (p, h.beta))).collect());
    let weights = RowWeights {
        strategy: chosen,
        recommended: false,
        table: &fitted.weights,
        heuristics: heuristics.unwrap_or_default(),
        lambda: Some(lambda),
    };
    Ok((artifact(config, &report, &weights)?, fitted.replicates.clone()))
}

/// The recommended row of `report` as [`RowWeights`].
pub fn recommended_row(report: &RunReport) -> Option<RowWeights<'_>> {
    let r = report.recommended.as_ref()?;
    Some(RowWeights {
        strategy: r.strategy,
        recommended: true,
        table: if r.strategy.path().is_some() { &[] } else { &report.weights },
        heuristics: r.heuristics.iter().filter_map(|h| h.strategy.path().map(|p| (p, h.beta))).collect(),
        lambda: r.lambda,
    })
}

/// The weights `solve::evaluate` scores from `artifact` (a table with its cell bounds, the
/// heuristics and their β, or the per-path strategy), with the coverage the weights were fitted on.
pub fn given_weights(artifact: &WeightsArtifact) -> Result<GivenWeights, String> {
    let strategy: Strategy = serde_json::from_value(serde_json::Value::String(artifact.strategy.clone()))
        .map_err(|_| format!("strategy {:?} is not a strategy of this optimis", artifact.strategy))?;
    let named = |h: &ArtifactHeuristic| -> Result<GivenHeuristic, String> {
        let strategy = serde_json::from_value(serde_json::Value::String(h.name.clone()))
            .map_err(|_| format!("heuristic {:?} is not a strategy of this optimis", h.name))?;
        Ok(GivenHeuristic { strategy, beta: h.beta })
    };
    let heuristics = artifact.heuristics.iter().map(named).collect::<Result<Vec<_>, _>>()?;
    let coverage = Some(artifact.provenance.coverage.clone());
    let lambda = artifact.provenance.lambda;
    let Some(axes) = &artifact.cells else {
        return Ok(GivenWeights {
            recommended: Some(GivenRecommendation { strategy, lambda, heuristics: Vec::new() }),
            coverage,
            ..GivenWeights::default()
        });
    };
    // In the run's cell order, whatever order the artifact lists them in.
    let (n3, nphi) = (axes.r3_edges.len(), axes.phi_bins as usize);
    let mut cells = artifact.table.clone();
    cells.sort_by_key(|c| (c.r2 * n3 + c.r3) * nphi + c.phi);
    let width = PI / f64::from(axes.phi_bins);
    let span = |edges: &[f64], i: usize| [edges.get(i).copied(), edges.get(i + 1).copied()];
    let weights = cells
        .iter()
        .map(|c| GivenCell {
            r2: span(&axes.r2_edges, c.r2),
            r3: span(&axes.r3_edges, c.r3),
            phi: [Some(c.phi as f64 * width), Some((c.phi + 1) as f64 * width)],
            w0: c.w[0],
            w1: c.w[1],
            w2: c.w[2],
        })
        .collect();
    Ok(GivenWeights {
        weights,
        heuristics: Vec::new(),
        recommended: Some(GivenRecommendation { strategy, lambda, heuristics }),
        coverage,
    })
}
