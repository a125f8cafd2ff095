//! The effective weights of a weight function (`solve::effective` defines them): the
//! contribution-weighted average of each technique's weight over the full paths of each (r2, r3)
//! bin, from camera paths drawn with the engine's own sampler, and their errors — the sampling
//! error of the ratio estimator and the jackknife over the fit's fold fits.
//!
//! **The paths.** Full paths (pixel, x2, x3, light) are drawn two ways: camera paths that reach
//! plane 3 (x2c, x3c, the engine's camera sampler), and *aimed paths* — x3 uniform over the area of
//! each finite r3 bin in turn (stratified: the same number per bin), x2 by a lobe around the
//! straight line from x3 to the pixel (width 1.5·β·L2/(L2 + L3): the deflection at x2 is
//! ≈ (L2 + L3)/L2 times the angle at x3). Each alone covers the bins badly: camera paths rarely
//! reach the narrow bins near the axis that carry much of a spot's light, and the aimed paths
//! never reach the open tail bin. They are combined by the balance heuristic over the two
//! samplers (Veach's one-sample mixture): with n of each, a path's weight is
//! c = f / (n·p_camera + n·p_aimed), f its contribution and p each sampler's density of it
//! (`model::heuristics::PathMeasure`), so c ≤ f/(n·p_camera) stays bounded; Σ c v / Σ c over a
//! bin's paths estimates w̄ for any per-path value v, and Σ c over all paths estimates L itself
//! (`luminance`, checked against the quadrature). A heuristic's weight of the path is the engine's
//! (`PathWeights`), the light path starting at the path's own x3.
//!
//! **The errors.** Sampling: the ratio estimator's delta-method variance,
//! Σ c_i² (v_i − w̄)² / (Σ c_i)², with v_i the function's weight of path i. Fit: w̄ is linear in the
//! fit's coefficients (the table's cells and β), so each fold fit gives a replicate
//! w̄_f = Σ_α s_α T_f(α) + Σ_h β_f,h H̄_h with the same path averages (s_α the cell's share of the
//! bin's contribution, H̄_h heuristic h's average), and the jackknife over the replicates
//! (`solve::crossfit`) is the fit's error, correlations between cells and β included. The two are
//! independent (different draws), so their variances add.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;

use super::artifact::{WeightsArtifact, WeightsKind};
use super::build::{artifact, artifact_and_replicates, recommended_row};
use crate::sim::engines::camera::CameraSet;
use crate::sim::engines::strategies::{PathStrategy, PathWeights, Technique, light_start};
use crate::sim::math::rng::{stream, uniform};
use crate::sim::model::config::SimConfig;
use crate::sim::model::heuristics::JoinGeometry;
use crate::sim::model::scene::{Lobe, Scene, advance, angle_between, sample_lobe};
use crate::sim::solve::crossfit::jackknife_se;
use crate::sim::solve::effective::{EffectiveBin, EffectiveWeights, FitReplicates};
use crate::sim::solve::report::{ReportInputs, RunReport};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::ValidJob;
use crate::sim::stats::moments::Moments;

/// Paths each side draws for a figure by default: the sampling error of a bin holding 1% of the
/// light is then ≈ 0.03 × the spread of the weights within it.
pub const EFFECTIVE_PATHS: usize = 50_000;

/// The most paths per side a request may ask for (the work is linear in it, docs/results.md §19).
pub const MAX_EFFECTIVE_PATHS: usize = 1_000_000;

/// The seed of the paths (their own, so that every figure of a scene averages over the same
/// paths, whatever run the weights came from).
pub const EFFECTIVE_SEED: u64 = 0x0e11_ec71_0e00_0001;

/// The stream of the aimed light paths (no engine uses it).
const LIGHT_STREAM: u64 = u64::MAX - 17;

/// Aimed paths per stream (so that the draws depend only on the seed and the path's index).
const LIGHT_BLOCK: u64 = 4096;

/// How much wider than the deflection it maps to the aimed paths' lobe is: a proposal narrower
/// than the integrand's peak has unbounded weights in its tails (the camera's density bounds them
/// here, but the variance would come back).
const AIM_WIDENING: f64 = 1.5;

/// Sums of one bin.
#[derive(Debug, Clone, Default)]
struct BinSums {
    paths: u64,
    c: f64,
    c2: f64,
    /// The first path's weights: the sums below are of d_m = v_m − shift_m, so that a bin whose
    /// weights barely vary (a table's cell: not at all) loses no digits to cancellation.
    shift: Option<[f64; 3]>,
    /// Σ c·d_m, Σ c²·d_m, Σ c²·d_m².
    cv: [f64; 3],
    c2v: [f64; 3],
    c2v2: [f64; 3],
    /// Σ c·w_h,m per heuristic (the replicates' H̄).
    ch: Vec<[f64; 3]>,
}

/// The effective weights of `artifact` in `config`'s scene over `paths` paths from each side (at
/// most [`MAX_EFFECTIVE_PATHS`]), with the fit errors from `replicates` (the fold fits of the row,
/// in the artifact's cell order; none for a heuristic). Deterministic.
pub fn effective_weights(
    config: &SimConfig,
    artifact: &WeightsArtifact,
    replicates: Option<&FitReplicates>,
    paths: usize,
) -> Result<EffectiveWeights, String> {
    effective_weights_from(config, artifact, replicates, paths, EFFECTIVE_SEED)
}

/// [`effective_weights`] from the paths of another `seed` (the calibration of their errors).
pub fn effective_weights_from(
    config: &SimConfig,
    artifact: &WeightsArtifact,
    replicates: Option<&FitReplicates>,
    paths: usize,
    seed: u64,
) -> Result<EffectiveWeights, String> {
    let grid = config.cells();
    let nphi = grid.phi_bins() as usize;
    let table = table_by_cell(config, artifact)?;
    let heuristics: Vec<(usize, f64)> = artifact
        .heuristics
        .iter()
        .map(|h| {
            PathStrategy::ALL
                .iter()
                .find(|p| p.name() == h.name)
                .map(|p| (p.index(), h.beta))
                .ok_or_else(|| format!("heuristic {:?} is not a strategy of this optimis", h.name))
        })
        .collect::<Result<_, _>>()?;
    let n = paths.clamp(1, MAX_EFFECTIVE_PATHS);
    let mut sums = Sums::new(config, table, heuristics, n as f64);
    let mut cameras = CameraSet::default();
    // Exactly n camera paths, those that never reach plane 3 (deflected past the horizontal at
    // x2) included: the mixture's density n·p_camera counts every draw, and leaving such paths
    // out biased L up by the fraction they are (0.1% in the paper's scene, 0.8% with β = 8°).
    let (mut drawn, mut reached, mut iteration) = (0usize, 0usize, 0u64);
    while drawn < n {
        cameras.regenerate(config, seed, iteration);
        iteration += 1;
        for camera in cameras.paths.iter().take(n - drawn) {
            drawn += 1;
            if let Some(x3) = camera.x3 {
                reached += 1;
                sums.add(camera.x2, x3);
            }
        }
    }
    let scene = &config.scene;
    let edges = grid.r3_edges();
    if edges.len() > 1 {
        for block in 0..(n as u64).div_ceil(LIGHT_BLOCK) {
            let mut rng = stream(seed, block, LIGHT_STREAM);
            for i in block * LIGHT_BLOCK..((block + 1) * LIGHT_BLOCK).min(n as u64) {
                let k = (i % (edges.len() as u64 - 1)) as usize;
                let (lo2, hi2) = (edges[k] * edges[k], edges[k + 1] * edges[k + 1]);
                let r = (lo2 + uniform(&mut rng) * (hi2 - lo2)).sqrt();
                let (sin, cos) = (TAU * uniform(&mut rng)).sin_cos();
                let x3 = [r * cos, r * sin];
                let (d, _) = sample_lobe(&sums.aim, &aim_axis(scene, x3), &mut rng);
                // A deflection past the horizontal never reaches plane 2 (β of degrees: never).
                if d.z > 0.0 {
                    sums.add(advance(x3, &d, -scene.l3), x3);
                }
            }
        }
    }
    let bins = (0..grid.len() / nphi).map(|b| sums.bin(b, replicates, artifact)).collect();
    let kind = match artifact.kind {
        WeightsKind::Table => "table",
        WeightsKind::Heuristic => "heuristic",
        WeightsKind::Stack => "stack",
    };
    Ok(EffectiveWeights {
        strategy: artifact.strategy.clone(),
        kind: kind.into(),
        paths_per_side: n as u64,
        camera_paths_reaching_plane3: reached as u64,
        luminance: sums.total.iter().sum(),
        bins,
    })
}

/// The sums of every bin as the paths are added.
struct Sums<'a> {
    config: &'a SimConfig,
    table: Option<Vec<[f64; 3]>>,
    /// Each heuristic's index among the per-path strategies, and its β.
    heuristics: Vec<(usize, f64)>,
    /// Paths per side.
    n: f64,
    /// The aimed light paths' lobe.
    aim: Lobe,
    bins: Vec<BinSums>,
    /// Σ c per cell (the cells' shares of their bin, for the fit's replicates).
    cell_c: Vec<f64>,
    /// Σ c per bin, again, in the order added (for the total).
    total: Vec<f64>,
}

impl<'a> Sums<'a> {
    fn new(config: &'a SimConfig, table: Option<Vec<[f64; 3]>>, heuristics: Vec<(usize, f64)>, n: f64) -> Self {
        let grid = config.cells();
        let bins = grid.len() / grid.phi_bins() as usize;
        let empty = BinSums { ch: vec![[0.0; 3]; heuristics.len()], ..BinSums::default() };
        let scene = &config.scene;
        let aim = Lobe::new(scene.lobe.beta * scene.l2 / (scene.l2 + scene.l3) * AIM_WIDENING);
        let (cell_c, total) = (vec![0.0; grid.len()], vec![0.0; bins]);
        Self { config, table, heuristics, n, aim, bins: vec![empty; bins], cell_c, total }
    }

    /// One full path (pixel, x2, x3, light), drawn by either sampler.
    fn add(&mut self, x2: [f64; 2], x3: [f64; 2]) {
        let config = self.config;
        let scene = &config.scene;
        let grid = config.cells();
        let alpha = grid.index(x2, x3);
        let b = alpha / grid.phi_bins() as usize;
        self.bins[b].paths += 1;
        let start = light_start(config, x3);
        let measure = JoinGeometry::new(scene, x2, x3).path_measure(scene, start);
        // The aimed sampler's density of (x3, x2): its density of x3 × its lobe's solid-angle pdf
        // at x3 × the solid angle per unit area of plane 2 seen from x3, L3/d2³.
        let up = Vector3::new(x3[0] - x2[0], x3[1] - x2[1], scene.l3);
        let d2 = up.norm();
        let aimed =
            self.stratum_density(x3) * self.aim.pdf_w(angle_between(&(up / d2), &aim_axis(scene, x3))) * scene.l3
                / (d2 * d2 * d2);
        let density = self.n * (measure.camera + aimed);
        if measure.contribution == 0.0 || density == 0.0 {
            return;
        }
        let c = measure.contribution / density;
        let mut v = self.table.as_ref().map_or([0.0; 3], |t| t[alpha]);
        let bin = &mut self.bins[b];
        if !self.heuristics.is_empty() {
            let shared = PathWeights::new(config, x2, x3);
            let all = [Technique::Plane1, Technique::Plane2, Technique::Plane3].map(|t| shared.of(t, start));
            for (&(index, beta), sums) in self.heuristics.iter().zip(bin.ch.iter_mut()) {
                for ((v, sum), weights) in v.iter_mut().zip(sums.iter_mut()).zip(&all) {
                    *v += beta * weights[index];
                    *sum += c * weights[index];
                }
            }
        }
        bin.c += c;
        bin.c2 += c * c;
        let shift = *bin.shift.get_or_insert(v);
        for (m, v) in v.into_iter().enumerate() {
            let v = v - shift[m];
            bin.cv[m] += c * v;
            bin.c2v[m] += c * c * v;
            bin.c2v2[m] += c * c * v * v;
        }
        self.cell_c[alpha] += c;
        self.total[b] += c;
    }

    /// The aimed sampler's density of x3, per path: 1/(K·area) of the finite r3 bin it lies in
    /// (K bins, each drawn as often), 0 in the open tail bin.
    fn stratum_density(&self, x3: [f64; 2]) -> f64 {
        let edges = self.config.cells().r3_edges();
        let r = (x3[0] * x3[0] + x3[1] * x3[1]).sqrt();
        match edges.windows(2).position(|e| r >= e[0] && r < e[1]) {
            Some(k) => 1.0 / ((edges.len() - 1) as f64 * PI * (edges[k + 1] * edges[k + 1] - edges[k] * edges[k])),
            None => 0.0,
        }
    }

    /// Bin `b`'s effective weights and errors (module docs).
    fn bin(&self, b: usize, replicates: Option<&FitReplicates>, artifact: &WeightsArtifact) -> EffectiveBin {
        let grid = self.config.cells();
        let nphi = grid.phi_bins() as usize;
        let s = &self.bins[b];
        let bounds = grid.bounds(b * nphi);
        let all: f64 = self.total.iter().sum();
        let mut bin = EffectiveBin {
            r2: bounds.r2,
            r3: bounds.r3,
            paths: s.paths,
            luminance_share: if all > 0.0 { s.c / all } else { 0.0 },
            w: None,
            stderr: None,
            sampling_stderr: None,
            fit_stderr: None,
        };
        if s.c <= 0.0 {
            return bin;
        }
        let shift = s.shift.unwrap_or_default();
        let w: [f64; 3] = std::array::from_fn(|m| shift[m] + s.cv[m] / s.c);
        let sampling: [f64; 3] = std::array::from_fn(|m| {
            let r = s.cv[m] / s.c;
            (s.c2v2[m] - 2.0 * r * s.c2v[m] + r * r * s.c2).max(0.0).sqrt() / s.c
        });
        let fit = replicates.filter(|r| r.tables.len() >= 2).map(|r| {
            let cells = b * nphi..(b + 1) * nphi;
            std::array::from_fn(|m| {
                jackknife_se((0..r.tables.len()).map(|f| {
                    let table: f64 = cells.clone().map(|a| self.cell_c[a] / s.c * r.tables[f][a][m]).sum();
                    let stacked: f64 = artifact
                        .heuristics
                        .iter()
                        .enumerate()
                        .map(|(k, h)| {
                            let beta = r.betas[f].iter().find(|(p, _)| p.name() == h.name).map_or(0.0, |x| x.1);
                            beta * s.ch[k][m] / s.c
                        })
                        .sum();
                    table + stacked
                }))
            })
        });
        bin.w = Some(w);
        bin.sampling_stderr = Some(sampling);
        bin.fit_stderr = fit;
        bin.stderr = Some(std::array::from_fn(|m| {
            let f = fit.map_or(0.0, |f: [f64; 3]| f[m]);
            (sampling[m] * sampling[m] + f * f).sqrt()
        }));
        bin
    }
}

/// The unit direction from the pixel to x3: the aimed paths' lobe axis (followed backwards from x3,
/// it meets plane 2 at x2* = x3·L2/(L2 + L3), the undeflected path).
fn aim_axis(scene: &Scene, x3: [f64; 2]) -> Vector3<f64> {
    Vector3::new(x3[0], x3[1], scene.l2 + scene.l3).normalize()
}

/// The artifact's table in `config`'s cell order (none for a heuristic alone).
fn table_by_cell(config: &SimConfig, artifact: &WeightsArtifact) -> Result<Option<Vec<[f64; 3]>>, String> {
    if artifact.table.is_empty() {
        return Ok(None);
    }
    let grid = config.cells();
    let mut table = vec![None; grid.len()];
    let (n3, nphi) = (grid.r3_edges().len(), grid.phi_bins() as usize);
    for c in &artifact.table {
        let alpha = (c.r2 * n3 + c.r3) * nphi + c.phi;
        if c.r2 >= grid.r2_edges().len() || c.r3 >= n3 || c.phi >= nphi {
            return Err(format!("cell ({}, {}, {}) is outside the scene's grid", c.r2, c.r3, c.phi));
        }
        table[alpha] = Some(c.w);
    }
    table
        .into_iter()
        .enumerate()
        .map(|(a, w)| w.ok_or_else(|| format!("cell {a} is missing")))
        .collect::<Result<_, _>>()
        .map(Some)
}

/// The recommended row's effective weights over `paths` paths per side (none when the report
/// recommends nothing). The fit errors come from the report's fold fits when its weights table is
/// the recommended row's.
pub fn recommended_effective(report: &RunReport, config: &SimConfig, paths: usize) -> Option<EffectiveWeights> {
    let row = recommended_row(report)?;
    let own = report.weights_fit.as_ref().is_some_and(|f| Some(f.lambda) == row.lambda && f.strategy == row.strategy);
    let replicates = if own { report.replicates.as_ref() } else { None };
    artifact(config, report, &row).and_then(|a| effective_weights(config, &a, replicates, paths)).ok()
}

/// The effective weights of row `strategy` (none: the recommended row) of the run `moments` of
/// `job` (`build::artifact_and_replicates`), over `paths` paths per side.
pub fn effective_of_moments(
    moments: &Moments,
    job: &ValidJob,
    inputs: &ReportInputs<'_>,
    strategy: Option<Strategy>,
    paths: usize,
) -> Result<EffectiveWeights, String> {
    let (artifact, replicates) = artifact_and_replicates(moments, job, inputs, strategy)?;
    effective_weights(job.config(), &artifact, replicates.as_ref(), paths)
}
