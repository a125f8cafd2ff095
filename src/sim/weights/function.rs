//! The reference evaluator of a weights artifact in Rust: the weight of a merge by technique m on a
//! join path, from the artifact alone and what a renderer knows of the path (its cell coordinates
//! and its vertex densities). It depends on no engine; the heuristics' formulas are the model's
//! (`model::heuristics`), read through the artifact's own parameters. The C and Python evaluators
//! (`clients/c/optimis_weights.h`, `clients/python/src/optimis_client/weights.py`) implement the
//! same arithmetic.

use super::artifact::{ArtifactHeuristic, CellAxes, Formula, MAX_HEURISTICS, MAX_RINGS, MAX_TABLE_CELLS};
use super::artifact::{WEIGHTS_FORMAT, WEIGHTS_VERSION, WeightsArtifact, WeightsKind};
use crate::sim::model::heuristics::{Sharing, VertexDensities, balance, balance_with_counts, effective_counts};

/// The join path as a renderer sees it at a merge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathInputs {
    /// r2 = |x2|: the radius of the plane-2 vertex.
    pub r2: f64,
    /// r3 = |x3|: the radius of the plane-3 vertex of the join path (the camera's for a plane-3
    /// merge, the light's otherwise).
    pub r3: f64,
    /// φ: the angle between x2 and x3, in [0, π].
    pub phi: f64,
    /// Each sub-path vertex's sampling density, per unit area.
    pub densities: PathDensities,
}

/// The vertex densities of a join path (0, x2, x3), per unit area (docs/model.md §9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathDensities {
    /// p_c(x2): the camera sub-path's density of x2.
    pub camera_x2: f64,
    /// p_c(x3 | x2): its density of x3 given x2.
    pub camera_x3: f64,
    /// p_l(x3l): the light's density of its own start x3l (I(x3l)/Φ).
    pub light_start: f64,
    /// p_l(x2 | x3): the light sub-path's density of x2.
    pub light_x2: f64,
    /// p_l(x1 | x2, x3): its density of the pixel.
    pub light_x1: f64,
}

impl PathDensities {
    /// The techniques' relative path densities: p₀ = p_l(x2|x3)·p_l(x1|x2,x3),
    /// p₁ = p_c(x2)·p_l(x2|x3), p₂ = p_c(x2)·p_c(x3|x2) (the light's start density, common to all
    /// three, left out).
    pub fn techniques(&self) -> [f64; 3] {
        [self.light_x2 * self.light_x1, self.camera_x2 * self.light_x2, self.camera_x2 * self.camera_x3]
    }
}

/// Why an artifact cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("weights artifact: {0}")]
pub struct ArtifactError(pub String);

/// A weights artifact ready to evaluate.
#[derive(Debug, Clone)]
pub struct WeightFunction {
    artifact: WeightsArtifact,
    /// The table by cell index (i2·n3 + i3)·nφ + iφ; empty without one.
    table: Vec<[f64; 3]>,
}

impl WeightFunction {
    /// Checks `artifact` (format, version, a complete table on valid axes, bounded sizes) and
    /// prepares it.
    pub fn new(artifact: WeightsArtifact) -> Result<Self, ArtifactError> {
        let bad = |m: String| Err(ArtifactError(m));
        if artifact.format != WEIGHTS_FORMAT || artifact.version != WEIGHTS_VERSION {
            return bad(format!(
                "format {:?} version {}, expected {WEIGHTS_FORMAT:?} version {WEIGHTS_VERSION}",
                artifact.format, artifact.version
            ));
        }
        if artifact.heuristics.len() > MAX_HEURISTICS || artifact.scene.rings.len() > MAX_RINGS {
            return bad("too many heuristics or rings".into());
        }
        let table = match &artifact.cells {
            None if artifact.table.is_empty() => Vec::new(),
            None => return bad("a table without cells".into()),
            Some(axes) => table_by_cell(axes, &artifact)?,
        };
        let (n, has_table) = (artifact.heuristics.len(), !table.is_empty());
        let consistent = match artifact.kind {
            WeightsKind::Heuristic => n == 1 && !has_table && artifact.heuristics[0].beta == 1.0,
            WeightsKind::Table => n == 0 && has_table,
            WeightsKind::Stack => n >= 1 && has_table,
        };
        if !consistent {
            return bad(format!(
                "kind {:?} with {n} heuristics and {} table: a heuristic is one heuristic with β = 1 and no table, a table has no heuristics, a stack has both",
                artifact.kind,
                if has_table { "a" } else { "no" }
            ));
        }
        check_scene(&artifact)?;
        for h in &artifact.heuristics {
            check_heuristic(&artifact, h)?;
        }
        let beta: f64 = artifact.heuristics.iter().map(|h| h.beta).sum();
        if let Some(w) = table.iter().find(|w| (w.iter().sum::<f64>() - (1.0 - beta)).abs() > 1e-6) {
            return bad(format!(
                "a cell's weights {w:?} do not sum to 1 − Σβ = {} (the estimate would be biased)",
                1.0 - beta
            ));
        }
        Ok(Self { artifact, table })
    }

    /// The artifact.
    pub fn artifact(&self) -> &WeightsArtifact {
        &self.artifact
    }

    /// The weight of a merge by `technique` (0, 1, 2) on the join path `path` (NaN for another
    /// technique).
    pub fn weight(&self, technique: usize, path: &PathInputs) -> f64 {
        if technique > 2 {
            return f64::NAN;
        }
        let table = match &self.artifact.cells {
            Some(axes) if !self.table.is_empty() => self.table[cell_index(axes, path.r2, path.r3, path.phi)][technique],
            _ => 0.0,
        };
        table + self.artifact.heuristics.iter().map(|h| h.beta * heuristic_weight(h, technique, path)).sum::<f64>()
    }
}

/// The scene must be one: positive lengths, a lobe, N_F and N_B ≥ 1, rings in order with a
/// positive flux.
fn check_scene(artifact: &WeightsArtifact) -> Result<(), ArtifactError> {
    let s = &artifact.scene;
    let positive = [s.l2, s.l3, s.beta_rad, s.merge_radius, s.flux].iter().all(|x| x.is_finite() && *x > 0.0);
    let counts = s.light_paths >= 1.0 && s.camera_paths >= 1.0;
    let rings = s.rings.windows(2).all(|w| w[1].inner >= w[0].outer)
        && s.rings.iter().all(|r| r.inner >= 0.0 && r.outer > r.inner && r.level.is_finite() && r.level >= 0.0);
    if positive && counts && rings {
        Ok(())
    } else {
        Err(ArtifactError(
            "the scene needs positive lengths, β, R and flux, N_F and N_B ≥ 1, and rings in order".into(),
        ))
    }
}

/// A heuristic must be the per-path strategy its name says, defined as optimis defines it for
/// the artifact's scene: evaluators read the formula, `optimis evaluate` the name, and the two
/// must not disagree.
fn check_heuristic(artifact: &WeightsArtifact, h: &ArtifactHeuristic) -> Result<(), ArtifactError> {
    let s = &artifact.scene;
    let area = std::f64::consts::PI * s.merge_radius * s.merge_radius;
    let correlation = Formula::CorrelationAware { area, light_paths: s.light_paths, camera_paths: s.camera_paths };
    let (all, planes23) = ([true; 3], [false, true, true]);
    let expected = match h.name.as_str() {
        "plane1" => Some((Formula::OneTechnique { technique: 0 }, all)),
        "plane2" => Some((Formula::OneTechnique { technique: 1 }, all)),
        "plane3" => Some((Formula::OneTechnique { technique: 2 }, all)),
        "switch" => match h.formula {
            Formula::Switch { radius } if radius.is_finite() && radius >= 0.0 => Some((h.formula, planes23)),
            _ => None,
        },
        "balance" => Some((Formula::Balance, all)),
        "power" => Some((Formula::Power { exponent: 2.0 }, all)),
        "correlation_aware" => Some((correlation, all)),
        "balance_planes23" => Some((Formula::Balance, planes23)),
        "power_planes23" => Some((Formula::Power { exponent: 2.0 }, planes23)),
        "correlation_aware_planes23" => Some((correlation, planes23)),
        _ => None,
    };
    match expected {
        Some((formula, techniques))
            if same_formula(formula, h.formula) && techniques == h.techniques && h.beta.is_finite() =>
        {
            Ok(())
        }
        _ => Err(ArtifactError(format!(
            "heuristic {:?}: its formula or techniques are not those of a per-path strategy of that name for this scene",
            h.name
        ))),
    }
}

/// Formulas equal up to rounding of their derived parameters (A = πR² as written by another tool).
fn same_formula(a: Formula, b: Formula) -> bool {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs());
    match (a, b) {
        (
            Formula::CorrelationAware { area: a1, light_paths: n1, camera_paths: m1 },
            Formula::CorrelationAware { area: a2, light_paths: n2, camera_paths: m2 },
        ) => close(a1, a2) && n1 == n2 && m1 == m2,
        (x, y) => x == y,
    }
}

/// The table by cell index, every cell exactly once.
fn table_by_cell(axes: &CellAxes, artifact: &WeightsArtifact) -> Result<Vec<[f64; 3]>, ArtifactError> {
    let valid =
        |e: &[f64]| e.first() == Some(&0.0) && e.windows(2).all(|w| w[1] > w[0]) && e.iter().all(|x| x.is_finite());
    if !valid(&axes.r2_edges) || !valid(&axes.r3_edges) || axes.phi_bins == 0 {
        return Err(ArtifactError("cell edges must start at 0 and increase; phi_bins ≥ 1".into()));
    }
    let (n2, n3, nphi) = (axes.r2_edges.len(), axes.r3_edges.len(), axes.phi_bins as usize);
    let cells = n2 * n3 * nphi;
    if cells > MAX_TABLE_CELLS || artifact.table.len() != cells {
        return Err(ArtifactError(format!("the table has {} cells, its axes {cells}", artifact.table.len())));
    }
    let mut table = vec![None; cells];
    for c in &artifact.table {
        if c.r2 >= n2 || c.r3 >= n3 || c.phi >= nphi || c.w.iter().any(|w| !w.is_finite()) {
            return Err(ArtifactError(format!(
                "cell ({}, {}, {}) is outside the axes or not finite",
                c.r2, c.r3, c.phi
            )));
        }
        let index = (c.r2 * n3 + c.r3) * nphi + c.phi;
        if table[index].replace(c.w).is_some() {
            return Err(ArtifactError(format!("cell ({}, {}, {}) is listed twice", c.r2, c.r3, c.phi)));
        }
    }
    Ok(table.into_iter().map(|w| w.expect("every cell listed once")).collect())
}

/// The last k with edges[k] ≤ r (0 for r < 0 or NaN).
fn bin(edges: &[f64], r: f64) -> usize {
    edges.partition_point(|&e| e <= r).saturating_sub(1)
}

/// The cell index of (r2, r3, φ) on `axes`: (i2·n3 + i3)·nφ + iφ.
pub fn cell_index(axes: &CellAxes, r2: f64, r3: f64, phi: f64) -> usize {
    let nphi = axes.phi_bins as usize;
    let iphi = if nphi == 1 { 0 } else { ((phi / std::f64::consts::PI * nphi as f64) as usize).min(nphi - 1) };
    (bin(&axes.r2_edges, r2) * axes.r3_edges.len() + bin(&axes.r3_edges, r3)) * nphi + iphi
}

/// Heuristic `h`'s weight of a merge by `technique` on `path`.
pub fn heuristic_weight(h: &ArtifactHeuristic, technique: usize, path: &PathInputs) -> f64 {
    if !h.techniques[technique] {
        return 0.0;
    }
    let masked = |p: [f64; 3]| std::array::from_fn(|k| if h.techniques[k] { p[k] } else { 0.0 });
    match h.formula {
        Formula::OneTechnique { technique: t } => f64::from(u8::from(t == technique)),
        Formula::Switch { radius } => {
            let chosen = if path.r3 <= radius { 1 } else { 2 };
            f64::from(u8::from(chosen == technique))
        }
        Formula::Balance => balance(masked(path.densities.techniques()))[technique],
        Formula::Power { exponent } => {
            let p: [f64; 3] = masked(path.densities.techniques());
            balance(p.map(|x| x.powf(exponent)))[technique]
        }
        Formula::CorrelationAware { area, light_paths, camera_paths } => {
            let d = &path.densities;
            let vertices = VertexDensities {
                camera_x2: d.camera_x2,
                camera_x3: d.camera_x3,
                light_x2: d.light_x2,
                light_x1: d.light_x1,
            };
            let counts = effective_counts(&Sharing::new(&vertices, d.light_start, area), light_paths, camera_paths);
            balance_with_counts(masked(d.techniques()), counts)[technique]
        }
    }
}
