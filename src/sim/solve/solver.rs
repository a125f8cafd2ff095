//! Optimal weights from the moments (docs/model.md §7): a table, or a table with heuristics stacked
//! on it.
//!
//! **The family.** Per-path weights w_m(path) = T_m,α + Σ_h β_h·w_h,m(path): a table T constant on
//! the cells α of the join path plus β_h times the weights of each stacked per-path heuristic h.
//! The weights sum to one on every path when every cell's T sums to 1 − Σβ. β = 0 is the paper's
//! tabulated optimum; T = 0 with β_h = 1 is heuristic h itself; β_h = 1 with T free is "h corrected
//! by a table"; and every heuristic of the family is contained in its optimum. With the moment
//! vector Y = (A⁽⁰⁾, A⁽¹⁾, B, H) (§7: A⁽ᵐ⁾_α = C⁽ᵐ⁾_α − C⁽²⁾_α, B = Σ_α C⁽²⁾_α, H_h = heuristic h's
//! per-iteration value), the pixel value is
//!
//!   C_s = ⟨A_s|T⟩ + B_s + Σ_h β_h (H_h,s − B_s) = ⟨Y_s|v⟩,   v = (T₀, T₁, 1 − Σβ, β),
//!
//! linear in (T, β), so its sample variance is the quadratic form vᵀS v (S the sample covariance
//! of Y) and the optimum is a least-squares problem like the paper's. We minimise
//!
//!   J = vᵀS v/μ² + λ Σ_{neighbouring cells α~β} Σ_{m=0,1,2} (T_m,α − T_m,β)²
//!
//! with μ a fixed luminance scale (the mean of the three single-plane estimates, independent of
//! the weights), so that Var/μ² is the squared relative RMS and λ compares across scenes. β is not
//! penalised (it is one number per heuristic, not a surface).
//!
//! **Fixed weights** are constraints: with T₀ the table of the fixed values (free components 0),
//! T = (1 − Σβ)·T₀ + P z keeps every fixed component at its value when each stacked heuristic gives
//! every path exactly those values ([`admits`]: with the paper's w0 = 0, the switch and the
//! heuristics renormalised over planes 2–3). So v = v₀ + D x with v₀ = (T₀, 1, 0), x = (z, β),
//! table columns of D on A and one column per heuristic, e_{H_h} − e_B − T₀. The normal equations
//! (DᵀSD/μ² + λDᵀΛD) x = −Dᵀ(S v₀/μ² + λΛv₀) (Λ the penalty's graph Laplacian on T) are built
//! from the sparse columns of D and solved by Cholesky after Jacobi scaling — no explicit inverse.
//! A heuristic the table can represent exactly (the switch on a grid with an edge at its radius)
//! would leave a direction undetermined at λ = 0; a ridge of [`BETA_RIDGE`] of β's own curvature
//! settles it on the table without changing the variance measurably.
//!
//! **Cells.** Failures are values: too few iterations, no signal, singular systems (with the cells
//! that span the undetermined directions). With λ = 0, cells without samples do not enter the
//! variance at all; they are left out of the fit, reported as `empty`, and take the weights of
//! their nearest fitted cell. With λ > 0 a cell with fewer than [`MIN_CELL_EVENTS`] merge events is
//! `smoothed`: the penalty, i.e. its neighbours, sets its weights, and their spread from fold to
//! fold is not a data standard error (the folds that happen to hold its few events are all the
//! jackknife sees; another run's events move it by more).
//!
//! Imports: crate::sim::engines, crate::sim::model, crate::sim::solve

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use super::options::FixedWeights;
use super::ystats::YStats;
use crate::sim::engines::layout::Layout;
use crate::sim::engines::strategies::PathStrategy;
use crate::sim::model::cells::CellGrid;

/// How a cell's weights were determined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum CellStatus {
    /// Fitted to the cell's own samples.
    Fitted,
    /// Every component is fixed by the constraints.
    Fixed,
    /// No samples and λ = 0: weights copied from the nearest fitted cell; they do not change the
    /// fitted variance.
    Empty,
    /// Samples whose contributions are negligible (they move the variance by < 10⁻¹⁴ of the most
    /// informative weight), λ = 0: treated like an empty cell.
    Uninformative,
    /// λ > 0 and fewer than [`MIN_CELL_EVENTS`] merge events: the gradient penalty — its
    /// neighbours — sets the weights. No data standard error.
    Smoothed,
}

impl CellStatus {
    /// Whether the cell's weights are estimated from its own samples, so that a standard error
    /// over the fold fits measures them.
    pub fn from_data(self) -> bool {
        self == Self::Fitted
    }
}

/// Weights of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CellWeights {
    /// The table's (T₀, T₁, T₂); they sum to 1 − Σβ.
    pub w: [f64; 3],
    /// Merge events in the cell, all planes, over the fitted iterations.
    pub samples: u64,
    /// How the weights were set.
    pub status: CellStatus,
}

/// A solution of the weight problem.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The table: each cell α's weights, in cell order.
    pub cells: Vec<CellWeights>,
    /// β_h of each stacked heuristic (empty for a plain table).
    pub heuristics: Vec<(PathStrategy, f64)>,
    /// λ used.
    pub lambda: f64,
    /// Number of free weights solved for (table weights and β).
    pub free: usize,
}

impl Fit {
    /// The coefficient vector v on Y (length `layout.dimension()`), C_s = ⟨Y_s|v⟩ (module docs).
    pub fn coefficients(&self, layout: Layout) -> DVector<f64> {
        let k = self.cells.len();
        let mut v = DVector::zeros(layout.dimension());
        for (a, c) in self.cells.iter().enumerate() {
            v[a] = c.w[0];
            v[k + a] = c.w[1];
        }
        v[layout.b_index()] = 1.0 - self.beta_sum();
        for &(h, beta) in &self.heuristics {
            v[layout.heuristic_index(h).expect("a fit stacks only columns its layout has")] = beta;
        }
        v
    }

    /// Σ_h β_h.
    pub fn beta_sum(&self) -> f64 {
        self.heuristics.iter().map(|(_, b)| b).sum()
    }
}

/// Whether heuristic `h` gives every path the weights `fixed` fixes, so that the family with
/// `h` stacked keeps them (module docs).
pub fn admits(fixed: &FixedWeights, h: PathStrategy) -> bool {
    let constant = h.constant_weights();
    (0..3).all(|m| fixed.get(m).is_none_or(|f| constant[m] == Some(f)))
}

/// The heuristics that can be stacked on a table of moments in `layout` under `fixed`.
pub fn stackable(layout: Layout, fixed: &FixedWeights) -> Vec<PathStrategy> {
    layout.heuristics().iter().copied().filter(|&h| admits(fixed, h)).collect()
}

/// The heuristics the stacked optimum stacks together on a table of moments in `layout` under
/// `fixed`: those of [`PathStrategy::STACKED`] that can be stacked.
pub fn stack_family(layout: Layout, fixed: &FixedWeights) -> Vec<PathStrategy> {
    stackable(layout, fixed).into_iter().filter(|h| PathStrategy::STACKED.contains(h)).collect()
}

/// Variance, relative to the plane-3 estimate's, below which a stacked heuristic's column counts
/// as zero (its sums differ from the table base's only by rounding).
const NOTHING_ADDED: f64 = 1e-12;

/// Whether stacking heuristic `h` adds nothing on these data: its per-iteration value differs from
/// the table base's (the fixed weights' table, e.g. plane 3 alone with w0 = 0) by a constant — the
/// switch under a uniform light, which has no spot, gives every path plane 3's weights. Its β would
/// be undetermined however many iterations ran, so the family leaves it out (and says so).
pub fn adds_nothing(stats: &YStats, fixed: &FixedWeights, h: PathStrategy) -> bool {
    let layout = stats.layout;
    let Some(hi) = layout.heuristic_index(h) else { return false };
    let (base, _) = cell_parameters(fixed);
    let k = layout.cells;
    let mut d = DVector::zeros(layout.dimension());
    d[hi] = 1.0;
    d[layout.b_index()] = -1.0;
    for a in 0..k {
        d[a] -= base[0];
        d[k + a] -= base[1];
    }
    let s = stats.covariance();
    let variance = d.dot(&(&s * &d));
    let plane3 = s[(layout.b_index(), layout.b_index())];
    variance <= NOTHING_ADDED * plane3.abs() || !variance.is_finite()
}

/// Free parameterisation of one cell: (T₀, T₁) = base + Σ_k z_k·coef_k.
fn cell_parameters(fixed: &FixedWeights) -> ([f64; 2], Vec<[f64; 2]>) {
    match (fixed.w0, fixed.w1, fixed.w2) {
        (None, None, None) => ([0.0, 0.0], vec![[1.0, 0.0], [0.0, 1.0]]),
        (Some(a), None, None) => ([a, 0.0], vec![[0.0, 1.0]]),
        (None, Some(b), None) => ([0.0, b], vec![[1.0, 0.0]]),
        (None, None, Some(c)) => ([0.0, 1.0 - c], vec![[1.0, -1.0]]),
        (Some(a), Some(b), _) => ([a, b], vec![]),
        (Some(a), None, Some(c)) => ([a, 1.0 - a - c], vec![]),
        (None, Some(b), Some(c)) => ([1.0 - b - c, b], vec![]),
    }
}

/// Relative pivot below which the Jacobi-scaled system counts as singular.
const PIVOT_TOLERANCE: f64 = 1e-11;

/// Ridge on each β, relative to its own curvature (module docs): far above `PIVOT_TOLERANCE`,
/// far below anything that moves the variance (it shrinks a determined β by ~10⁻⁷ of itself).
pub const BETA_RIDGE: f64 = 1e-7;

/// Merge events below which a cell's weights rest on too few samples: with n events the relative
/// error of a cell's second moments is of order 1/√n, above 18% for n < 30; and K = 10 folds then
/// hold three or fewer each, too few for their spread to measure the cell's noise. Under a penalty
/// such a cell is `smoothed` (no data standard error); the `sparse_cells` warning counts them.
pub const MIN_CELL_EVENTS: u64 = 30;

/// Fits the optimal weights to `stats` with fixed weights `fixed`, penalty `lambda` and the
/// heuristics `family` stacked on the table (empty: the paper's table alone).
pub fn fit(
    stats: &YStats,
    grid: &CellGrid,
    fixed: &FixedWeights,
    lambda: f64,
    family: &[PathStrategy],
) -> Result<Fit, SolveError> {
    let k = grid.len();
    if stats.m < 2.0 {
        return Err(SolveError::TooFewIterations(stats.m as u64));
    }
    let mu = stats.scale();
    if stats.cell_samples.iter().all(|&c| c == 0) || mu.is_nan() || mu <= 0.0 {
        return Err(SolveError::NoSignal);
    }
    let layout = stats.layout;
    if let Some(&h) = family.iter().find(|&&h| !admits(fixed, h) || layout.heuristic_index(h).is_none()) {
        return Err(SolveError::NotStackable(h));
    }
    let (base, coefs) = cell_parameters(fixed);
    let mut v0 = DVector::zeros(layout.dimension());
    for a in 0..k {
        v0[a] = base[0];
        v0[k + a] = base[1];
    }
    v0[layout.b_index()] = 1.0;
    // Cells that carry free weights: all of them under a penalty, else those with samples.
    let mut active: Vec<usize> =
        (0..k).filter(|&a| !coefs.is_empty() && (lambda > 0.0 || stats.cell_samples[a] > 0)).collect();
    let mut uninformative = vec![false; k];
    let columns = |cells: &[usize]| Columns::new(layout, base, &coefs, cells, family);
    let system = |c: &Columns| NormalSystem::new(stats, grid, &v0, c, mu, lambda);
    let mut cols = columns(&active);
    let mut sys = system(&cols);
    if lambda == 0.0 && !active.is_empty() {
        // A cell whose every free weight moves the variance by < 10⁻¹⁴ of the most informative one
        // carries no information (e.g. plane-2 merges at deflections where g(ϑ) underflows): leave
        // it out like an empty cell rather than call the system singular.
        let table = cols.table_columns;
        let max_diag = (0..table).map(|i| sys.data_diag[i]).fold(0.0, f64::max);
        let per_cell = coefs.len();
        for (i, &a) in active.iter().enumerate() {
            let informative = (0..per_cell).any(|c| sys.data_diag[i * per_cell + c] > 1e-14 * max_diag);
            uninformative[a] = !informative;
        }
        if uninformative.iter().any(|&u| u) {
            active.retain(|&a| !uninformative[a]);
            if active.is_empty() {
                return Err(SolveError::NoSignal);
            }
            cols = columns(&active);
            sys = system(&cols);
        }
    }
    let z = if cols.entries.is_empty() { DVector::zeros(0) } else { solve_spd(sys.h, sys.g, &cols.cells)? };
    let mut v = v0.clone();
    for (zi, entries) in z.iter().zip(&cols.entries) {
        for &(index, coef) in entries {
            v[index] += zi * coef;
        }
    }
    let heuristics: Vec<(PathStrategy, f64)> =
        family.iter().enumerate().map(|(i, &h)| (h, z[cols.table_columns + i])).collect();
    let beta_sum: f64 = heuristics.iter().map(|(_, b)| b).sum();
    let mut cells: Vec<CellWeights> = (0..k)
        .map(|a| {
            let (x0, x1) = (v[a], v[k + a]);
            let status = if coefs.is_empty() {
                CellStatus::Fixed
            } else if uninformative[a] {
                CellStatus::Uninformative
            } else if lambda > 0.0 && stats.cell_samples[a] < MIN_CELL_EVENTS {
                CellStatus::Smoothed
            } else if stats.cell_samples[a] > 0 {
                CellStatus::Fitted
            } else {
                CellStatus::Empty
            };
            CellWeights { w: [x0, x1, 1.0 - beta_sum - x0 - x1], samples: stats.cell_samples[a], status }
        })
        .collect();
    fill_empty_cells(&mut cells, grid);
    Ok(Fit { cells, heuristics, lambda, free: cols.entries.len() })
}

/// The columns of D (module docs), sparse: the free table weights of the active cells, then one
/// per stacked heuristic.
struct Columns {
    /// (index on Y, coefficient) pairs of each column.
    entries: Vec<Vec<(usize, f64)>>,
    /// The cell of each table column (`usize::MAX` for a β column), for reports of singular systems.
    cells: Vec<usize>,
    table_columns: usize,
}

impl Columns {
    fn new(layout: Layout, base: [f64; 2], coefs: &[[f64; 2]], active: &[usize], family: &[PathStrategy]) -> Self {
        let k = layout.cells;
        let (mut entries, mut cells) = (Vec::new(), Vec::new());
        for &a in active {
            for c in coefs {
                entries.push([(a, c[0]), (k + a, c[1])].into_iter().filter(|&(_, x)| x != 0.0).collect());
                cells.push(a);
            }
        }
        let table_columns = entries.len();
        for &h in family {
            let mut column = vec![(layout.heuristic_index(h).expect("checked by fit"), 1.0), (layout.b_index(), -1.0)];
            for a in 0..k {
                column.extend([(a, -base[0]), (k + a, -base[1])].into_iter().filter(|&(_, x)| x != 0.0));
            }
            entries.push(column);
            cells.push(usize::MAX);
        }
        Self { entries, cells, table_columns }
    }
}

/// The normal equations H x = g of the free weights, and the data part of H's diagonal.
struct NormalSystem {
    h: DMatrix<f64>,
    g: DVector<f64>,
    data_diag: Vec<f64>,
}

impl NormalSystem {
    fn new(stats: &YStats, grid: &CellGrid, v0: &DVector<f64>, cols: &Columns, mu: f64, lambda: f64) -> Self {
        let k2 = 2 * grid.len();
        let s = stats.covariance();
        let inv_mu2 = 1.0 / (mu * mu);
        let s_v0 = &s * v0;
        let laplacian = (lambda > 0.0).then(|| penalty_laplacian(grid));
        let l_v0 = laplacian.as_ref().map(|l| l * v0.rows(0, k2));
        let c = cols.entries.len();
        let mut h = DMatrix::zeros(c, c);
        let mut data_diag = vec![0.0; c];
        let form = |m: &dyn Fn(usize, usize) -> f64, x: &[(usize, f64)], y: &[(usize, f64)]| {
            x.iter().map(|&(a, p)| y.iter().map(|&(b, q)| p * q * m(a, b)).sum::<f64>()).sum::<f64>()
        };
        for i in 0..c {
            for j in i..c {
                let (x, y) = (&cols.entries[i], &cols.entries[j]);
                let data = form(&|a, b| s[(a, b)], x, y) * inv_mu2;
                let penalty = match &laplacian {
                    Some(l) => lambda * form(&|a, b| if a < k2 && b < k2 { l[(a, b)] } else { 0.0 }, x, y),
                    None => 0.0,
                };
                h[(i, j)] = data + penalty;
                h[(j, i)] = data + penalty;
                if i == j {
                    data_diag[i] = data;
                }
            }
        }
        for i in cols.table_columns..c {
            h[(i, i)] += BETA_RIDGE * h[(i, i)];
        }
        let g = DVector::from_fn(c, |i, _| {
            let x = &cols.entries[i];
            let data: f64 = x.iter().map(|&(a, p)| p * s_v0[a]).sum::<f64>() * inv_mu2;
            let penalty = l_v0
                .as_ref()
                .map_or(0.0, |lv| lambda * x.iter().filter(|&&(a, _)| a < k2).map(|&(a, p)| p * lv[a]).sum::<f64>());
            -(data + penalty)
        });
        Self { h, g, data_diag }
    }
}

/// The graph Laplacian of the penalty Σ_edges Σ_m (ΔT_m)² on T = (T₀, T₁): per edge, with
/// ΔT₂ = −(ΔT₀ + ΔT₁) (Σβ is the same in every cell), the quadratic form [[2, 1], [1, 2]] on
/// (ΔT₀, ΔT₁).
fn penalty_laplacian(grid: &CellGrid) -> DMatrix<f64> {
    let k = grid.len();
    let mut l = DMatrix::zeros(2 * k, 2 * k);
    let q = [[2.0, 1.0], [1.0, 2.0]];
    for (a, b) in grid.neighbours() {
        for (mi, row) in q.iter().enumerate() {
            for (mj, &v) in row.iter().enumerate() {
                let (ia, ib, ja, jb) = (mi * k + a, mi * k + b, mj * k + a, mj * k + b);
                l[(ia, ja)] += v;
                l[(ib, jb)] += v;
                l[(ia, jb)] -= v;
                l[(ib, ja)] -= v;
            }
        }
    }
    l
}

/// Solves H z = g for symmetric positive definite H by Jacobi-scaled Cholesky, or reports the
/// cells spanning its null space (`column_cells`: the cell of each column, `usize::MAX` for β).
fn solve_spd(h: DMatrix<f64>, g: DVector<f64>, column_cells: &[usize]) -> Result<DVector<f64>, SolveError> {
    let n = h.nrows();
    let max_diag = h.diagonal().iter().copied().fold(0.0, f64::max);
    let singular = |rank: usize, columns: Vec<usize>| {
        let heuristic_terms = columns.iter().filter(|&&c| c == usize::MAX).count();
        let mut cells: Vec<usize> = columns.into_iter().filter(|&c| c != usize::MAX).collect();
        cells.sort_unstable();
        cells.dedup();
        SolveError::Singular { dimension: n, rank, cells, heuristic_terms }
    };
    // A free weight no sample and no penalty touches is undetermined outright.
    let dead: Vec<usize> =
        (0..n).filter(|&i| h[(i, i)].is_nan() || h[(i, i)] <= max_diag * 1e-300).map(|i| column_cells[i]).collect();
    if !dead.is_empty() || max_diag <= 0.0 {
        return Err(singular(n - dead.len(), dead));
    }
    let d = DVector::from_fn(n, |i, _| 1.0 / h[(i, i)].sqrt());
    let scaled = DMatrix::from_fn(n, n, |i, j| h[(i, j)] * d[i] * d[j]);
    let rhs = g.component_mul(&d);
    if let Some(chol) = scaled.clone().cholesky() {
        let min_pivot = chol.l_dirty().diagonal().iter().map(|x| x * x).fold(f64::INFINITY, f64::min);
        if min_pivot > PIVOT_TOLERANCE {
            return Ok(chol.solve(&rhs).component_mul(&d));
        }
    }
    // Name the cells of the (numerical) null space.
    let eig = SymmetricEigen::new(scaled);
    let max_eig = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let mut columns = Vec::new();
    let mut rank = 0;
    for (i, &lam) in eig.eigenvalues.iter().enumerate() {
        if lam > max_eig * PIVOT_TOLERANCE {
            rank += 1;
            continue;
        }
        let v = eig.eigenvectors.column(i);
        columns.extend((0..n).filter(|&j| v[j].abs() > 0.1));
    }
    // Each column once (it may take part in several null directions), then its cell or β.
    columns.sort_unstable();
    columns.dedup();
    Err(singular(rank, columns.into_iter().map(|j| column_cells[j]).collect()))
}

/// Gives every `Empty` cell the weights of its nearest fitted cell (breadth-first over the grid's
/// neighbours, lowest index first), so that weights evaluated on other data are defined.
fn fill_empty_cells(cells: &mut [CellWeights], grid: &CellGrid) {
    let k = cells.len();
    let mut adjacency = vec![Vec::new(); k];
    for (a, b) in grid.neighbours() {
        adjacency[a].push(b);
        adjacency[b].push(a);
    }
    let unfitted = |s: CellStatus| matches!(s, CellStatus::Empty | CellStatus::Uninformative);
    let mut source: Vec<Option<usize>> = (0..k).map(|a| (!unfitted(cells[a].status)).then_some(a)).collect();
    let mut frontier: Vec<usize> = (0..k).filter(|&a| source[a].is_some()).collect();
    while !frontier.is_empty() {
        let mut next = Vec::new();
        for &a in &frontier {
            for &b in &adjacency[a] {
                if source[b].is_none() {
                    source[b] = source[a];
                    next.push(b);
                }
            }
        }
        next.sort_unstable();
        frontier = next;
    }
    for a in 0..k {
        if let (true, Some(s)) = (unfitted(cells[a].status), source[a]) {
            cells[a].w = cells[s].w;
        }
    }
}

mod error;
#[cfg(test)]
mod tests;

pub use error::SolveError;
