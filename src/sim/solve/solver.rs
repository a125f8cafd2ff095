//! Optimal tabulated weights from the moments (model.md, "moments, optimum").
//!
//! For cell-wise weights W = (w0_α, w1_α) (w2 = 1 − w0 − w1), one iteration's pixel value is
//! C_s(W) = ⟨A_s|W⟩ + B_s, and its sample variance over the iterations is
//! Var(W) = WᵀS_AA W + 2 S_ABᵀW + S_BB with S the sample covariance of Y = (A, B) — model.md's
//! (D − ĀĀᵀ), (F − B̄Ā) and mean(B²) − B̄². We minimise the dimensionless objective
//!
//!   J(W) = Var(W)/μ² + λ Σ_{neighbouring cells α~β} Σ_{m=0,1,2} (w_m,α − w_m,β)²
//!
//! where μ is a fixed luminance scale (the mean of the three single-plane estimates, which does not
//! depend on W), so that λ is comparable across scenes: Var/μ² is the squared relative RMS.
//! Fixed weights are constraints: W = W₀ + P·z with z the free weights, and the normal equations
//! (PᵀS_AA P/μ² + λPᵀΛP) z = −Pᵀ(S_AA W₀ + S_AB)/μ² − λPᵀΛW₀ (Λ the penalty's graph Laplacian)
//! are solved by Cholesky after Jacobi scaling — no explicit inverse.
//!
//! Failures are values: too few iterations, no signal, and singular systems (with the cells that
//! span the undetermined directions) are reported as [`SolveError`]s. With λ = 0, cells without
//! samples do not enter the variance at all; they are left out of the fit, reported as `empty`, and
//! given the weights of their nearest fitted cell (which matters only for evaluation on other data).

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use super::options::FixedWeights;
use super::ystats::YStats;
use crate::sim::model::cells::CellGrid;

/// How a cell's weights were determined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum CellStatus {
    /// Fitted to the data.
    Fitted,
    /// Every component is fixed by the constraints.
    Fixed,
    /// No samples and λ = 0: weights copied from the nearest fitted cell; they do not change the
    /// fitted variance.
    Empty,
    /// Samples whose contributions are negligible (they move the variance by < 10⁻¹⁴ of the most
    /// informative weight), λ = 0: treated like an empty cell.
    Uninformative,
    /// No samples, λ > 0: weights set by the gradient penalty alone.
    Smoothed,
}

/// Weights of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CellWeights {
    pub w: [f64; 3],
    /// Merge events in the cell, all planes, over the fitted iterations.
    pub samples: u64,
    pub status: CellStatus,
}

/// A solution of the weight problem.
#[derive(Debug, Clone)]
pub struct Fit {
    pub cells: Vec<CellWeights>,
    /// λ used.
    pub lambda: f64,
    /// Number of free weights solved for.
    pub free: usize,
}

impl Fit {
    /// The full weight vector W = (w0_α, w1_α) of length 2K.
    pub fn vector(&self) -> DVector<f64> {
        let k = self.cells.len();
        DVector::from_fn(2 * k, |i, _| self.cells[i % k].w[i / k])
    }
}

/// Why no optimal weights could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("at least 2 iterations are needed to estimate a variance, got {0}")]
    TooFewIterations(u64),
    #[error("no merge events: every contribution is zero, there is nothing to weight")]
    NoSignal,
    #[error(
        "the weight system is singular (rank {rank} of {dimension}): the data do not determine the weights of cells {cells:?}; add a gradient penalty (solver.lambda > 0), fix a weight, use coarser cells or run more iterations"
    )]
    Singular { dimension: usize, rank: usize, cells: Vec<usize> },
}

/// Free parameterisation of one cell: (w0, w1) = base + Σ_k z_k·coef_k.
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

/// Fits the optimal weights to `stats` with fixed weights `fixed` and penalty `lambda`.
pub fn fit(stats: &YStats, grid: &CellGrid, fixed: &FixedWeights, lambda: f64) -> Result<Fit, SolveError> {
    let k = grid.len();
    if stats.m < 2.0 {
        return Err(SolveError::TooFewIterations(stats.m as u64));
    }
    let mu = stats.scale();
    if stats.cell_samples.iter().all(|&c| c == 0) || mu.is_nan() || mu <= 0.0 {
        return Err(SolveError::NoSignal);
    }
    let (base, coefs) = cell_parameters(fixed);
    let w0 = DVector::from_fn(2 * k, |i, _| base[i / k]);
    // Cells that carry free weights: all of them under a penalty, else those with samples.
    let mut active: Vec<usize> =
        (0..k).filter(|&a| !coefs.is_empty() && (lambda > 0.0 || stats.cell_samples[a] > 0)).collect();
    let mut uninformative = vec![false; k];
    let system = |cells: &[usize]| NormalSystem::new(stats, grid, &w0, &coefs, cells, mu, lambda);
    let mut sys = system(&active);
    if lambda == 0.0 && !active.is_empty() {
        // A cell whose every free weight moves the variance by < 10⁻¹⁴ of the most informative one
        // carries no information (e.g. plane-2 merges at deflections where g(ϑ) underflows): leave
        // it out like an empty cell rather than call the system singular.
        let max_diag = sys.h.diagonal().iter().copied().fold(0.0, f64::max);
        let per_cell = coefs.len();
        for (i, &a) in active.iter().enumerate() {
            let informative = (0..per_cell).any(|c| sys.h[(i * per_cell + c, i * per_cell + c)] > 1e-14 * max_diag);
            uninformative[a] = !informative;
        }
        if uninformative.iter().any(|&u| u) {
            active.retain(|&a| !uninformative[a]);
            if active.is_empty() {
                return Err(SolveError::NoSignal);
            }
            sys = system(&active);
        }
    }
    let z = if sys.columns.is_empty() { DVector::zeros(0) } else { solve_spd(sys.h, sys.g, &sys.columns)? };
    let p = sys.p;
    let nfree = sys.columns.len();
    let w = &w0 + &p * &z;
    let mut cells: Vec<CellWeights> = (0..k)
        .map(|a| {
            let (x0, x1) = (w[a], w[k + a]);
            let status = if coefs.is_empty() {
                CellStatus::Fixed
            } else if uninformative[a] {
                CellStatus::Uninformative
            } else if stats.cell_samples[a] > 0 {
                CellStatus::Fitted
            } else if lambda > 0.0 {
                CellStatus::Smoothed
            } else {
                CellStatus::Empty
            };
            CellWeights { w: [x0, x1, 1.0 - x0 - x1], samples: stats.cell_samples[a], status }
        })
        .collect();
    fill_empty_cells(&mut cells, grid);
    Ok(Fit { cells, lambda, free: nfree })
}

/// The normal equations H z = g of the free weights of `cells`, with W = W₀ + P z.
struct NormalSystem {
    p: DMatrix<f64>,
    h: DMatrix<f64>,
    g: DVector<f64>,
    /// (cell, coefficient on (w0, w1)) of each free weight.
    columns: Vec<(usize, [f64; 2])>,
}

impl NormalSystem {
    fn new(
        stats: &YStats,
        grid: &CellGrid,
        w0: &DVector<f64>,
        coefs: &[[f64; 2]],
        cells: &[usize],
        mu: f64,
        lambda: f64,
    ) -> Self {
        let k = grid.len();
        let columns: Vec<(usize, [f64; 2])> = cells.iter().flat_map(|&a| coefs.iter().map(move |&c| (a, c))).collect();
        let mut p = DMatrix::zeros(2 * k, columns.len());
        for (col, &(a, c)) in columns.iter().enumerate() {
            p[(a, col)] = c[0];
            p[(k + a, col)] = c[1];
        }
        // Covariances (1/M normalisation; the minimiser does not depend on it).
        let mean = &stats.sum_y / stats.m;
        let cov = &stats.sum_yy / stats.m - &mean * mean.transpose();
        let s_aa = cov.view((0, 0), (2 * k, 2 * k)).into_owned();
        let s_ab = cov.view((0, 2 * k), (2 * k, 1)).column(0).into_owned();
        let inv_mu2 = 1.0 / (mu * mu);
        let (h, g) = if lambda > 0.0 {
            let laplacian = penalty_laplacian(grid);
            (
                p.transpose() * (&s_aa * inv_mu2 + &laplacian * lambda) * &p,
                -(p.transpose() * ((&s_aa * w0 + &s_ab) * inv_mu2 + &laplacian * w0 * lambda)),
            )
        } else {
            (p.transpose() * &s_aa * &p * inv_mu2, -(p.transpose() * (&s_aa * w0 + &s_ab) * inv_mu2))
        };
        Self { p, h, g, columns }
    }
}

/// The graph Laplacian of the penalty Σ_edges Σ_m (Δw_m)² on W = (w0, w1): per edge, with
/// Δw2 = −(Δw0 + Δw1), the quadratic form [[2, 1], [1, 2]] on (Δw0, Δw1).
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
/// cells spanning its null space.
fn solve_spd(h: DMatrix<f64>, g: DVector<f64>, columns: &[(usize, [f64; 2])]) -> Result<DVector<f64>, SolveError> {
    let n = h.nrows();
    let max_diag = h.diagonal().iter().copied().fold(0.0, f64::max);
    let singular = |rank: usize, cells: Vec<usize>| {
        let mut cells = cells;
        cells.sort_unstable();
        cells.dedup();
        SolveError::Singular { dimension: n, rank, cells }
    };
    // A free weight no sample and no penalty touches is undetermined outright.
    let dead: Vec<usize> =
        (0..n).filter(|&i| h[(i, i)].is_nan() || h[(i, i)] <= max_diag * 1e-300).map(|i| columns[i].0).collect();
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
    let mut cells = Vec::new();
    let mut rank = 0;
    for (i, &lam) in eig.eigenvalues.iter().enumerate() {
        if lam > max_eig * PIVOT_TOLERANCE {
            rank += 1;
            continue;
        }
        let v = eig.eigenvectors.column(i);
        cells.extend((0..n).filter(|&j| v[j].abs() > 0.1).map(|j| columns[j].0));
    }
    Err(singular(rank, cells))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::rng::{stream, uniform};

    /// Synthetic statistics from explicit per-iteration vectors Y_s.
    fn stats_from(ys: &[DVector<f64>], samples: Vec<u64>) -> YStats {
        let n = ys[0].len();
        let mut sum_y = DVector::zeros(n);
        let mut sum_yy = DMatrix::zeros(n, n);
        for y in ys {
            sum_y += y;
            sum_yy += y * y.transpose();
        }
        YStats { m: ys.len() as f64, sum_y, sum_yy, cell_samples: samples }
    }

    /// A problem whose optimum is known: B_s = −⟨A_s|W*⟩ + L + small noise, so W* makes C_s nearly
    /// constant. The fit must recover W*, and no perturbation may lower the sample variance.
    fn synthetic(k: usize, w_star: &DVector<f64>, iterations: usize) -> YStats {
        let mut rng = stream(42, 0, 0);
        let ys: Vec<DVector<f64>> = (0..iterations)
            .map(|_| {
                let a = DVector::from_fn(2 * k, |_, _| uniform(&mut rng) - 0.5);
                let noise = 1e-3 * (uniform(&mut rng) - 0.5);
                let b = 1.0 - a.dot(w_star) + noise;
                let mut y = DVector::zeros(2 * k + 1);
                y.rows_mut(0, 2 * k).copy_from(&a);
                y[2 * k] = b;
                y
            })
            .collect();
        stats_from(&ys, vec![10; k])
    }

    fn variance(stats: &YStats, w: &DVector<f64>) -> f64 {
        let (s1, s2) = stats.evaluate(w);
        s2 / stats.m - (s1 / stats.m).powi(2)
    }

    #[test]
    fn recovers_known_weights_and_beats_every_perturbation() {
        let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
        let k = grid.len();
        let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
        let stats = synthetic(k, &w_star, 2000);
        let fit = fit(&stats, &grid, &FixedWeights::default(), 0.0).unwrap();
        let w = fit.vector();
        assert!((&w - &w_star).amax() < 1e-3, "fitted {w} vs {w_star}");
        assert!(
            fit.cells.iter().all(|c| c.status == CellStatus::Fitted && (c.w.iter().sum::<f64>() - 1.0).abs() < 1e-12)
        );
        let best = variance(&stats, &w);
        let mut rng = stream(43, 0, 0);
        for _ in 0..500 {
            let dir = DVector::from_fn(2 * k, |_, _| uniform(&mut rng) - 0.5);
            for eps in [1e-4, 1e-2, 1.0] {
                let v = variance(&stats, &(&w + &dir * eps));
                assert!(v >= best, "perturbation {eps} lowered the variance: {v} < {best}");
            }
        }
    }

    #[test]
    fn fixed_weights_are_respected() {
        let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
        let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
        let stats = synthetic(3, &w_star, 500);
        let fixed = FixedWeights { w0: Some(0.0), ..Default::default() };
        let f = fit(&stats, &grid, &fixed, 0.0).unwrap();
        assert!(f.cells.iter().all(|c| c.w[0] == 0.0 && (c.w.iter().sum::<f64>() - 1.0).abs() < 1e-12));
        assert_eq!(f.free, 3);
        let fixed2 = FixedWeights { w2: Some(0.25), ..Default::default() };
        let f2 = fit(&stats, &grid, &fixed2, 0.0).unwrap();
        assert!(f2.cells.iter().all(|c| (c.w[2] - 0.25).abs() < 1e-12));
        let all = FixedWeights { w0: Some(0.0), w1: Some(1.0), w2: None };
        let f3 = fit(&stats, &grid, &all, 0.0).unwrap();
        assert!(f3.cells.iter().all(|c| c.status == CellStatus::Fixed && c.w == [0.0, 1.0, 0.0]));
    }

    #[test]
    fn penalty_smooths_towards_neighbours() {
        let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
        let w_star = DVector::from_vec(vec![0.1, -0.3, 0.7, 0.5, 0.2, 0.9]);
        let stats = synthetic(3, &w_star, 500);
        let spread = |f: &Fit| {
            f.cells.iter().map(|c| c.w[1]).fold(f64::NEG_INFINITY, f64::max)
                - f.cells.iter().map(|c| c.w[1]).fold(f64::INFINITY, f64::min)
        };
        let free = fit(&stats, &grid, &FixedWeights::default(), 0.0).unwrap();
        let smooth = fit(&stats, &grid, &FixedWeights::default(), 1e6).unwrap();
        assert!(spread(&smooth) < 1e-3 && spread(&free) > 0.5, "{} vs {}", spread(&smooth), spread(&free));
    }

    #[test]
    fn empty_cells_and_singular_systems_are_reported() {
        let grid = CellGrid::new(vec![0.0], vec![0.0, 1.0, 2.0], 1);
        // Cell 2 never sees a sample: A is zero there.
        let mut rng = stream(44, 0, 0);
        let ys: Vec<DVector<f64>> = (0..200)
            .map(|_| {
                let mut y = DVector::zeros(7);
                for i in [0, 1, 3, 4] {
                    y[i] = uniform(&mut rng) - 0.5;
                }
                y[6] = 1.0 + uniform(&mut rng);
                y
            })
            .collect();
        let stats = stats_from(&ys, vec![5, 5, 0]);
        let f = fit(&stats, &grid, &FixedWeights::default(), 0.0).unwrap();
        assert_eq!(f.cells[2].status, CellStatus::Empty);
        assert_eq!(f.cells[2].w, f.cells[1].w, "empty cells take their nearest fitted neighbour's weights");
        let smoothed = fit(&stats, &grid, &FixedWeights::default(), 1e-3).unwrap();
        assert_eq!(smoothed.cells[2].status, CellStatus::Smoothed);

        // Cells 0 and 1 always move together: their weights are not separately determined.
        let ys: Vec<DVector<f64>> = (0..200)
            .map(|_| {
                let x = uniform(&mut rng) - 0.5;
                DVector::from_vec(vec![x, x, 0.0, 0.0, 0.0, 0.0, 1.0 + uniform(&mut rng)])
            })
            .collect();
        let stats = stats_from(&ys, vec![5, 5, 0]);
        let fixed = FixedWeights { w1: Some(0.0), ..Default::default() };
        match fit(&stats, &grid, &fixed, 0.0) {
            Err(SolveError::Singular { cells, rank, dimension }) => {
                assert_eq!(cells, vec![0, 1]);
                assert_eq!((rank, dimension), (1, 2));
            }
            other => panic!("expected a singular system, got {other:?}"),
        }
        assert!(fit(&stats, &grid, &fixed, 1e-3).is_ok(), "a penalty resolves it");
        let one = stats_from(&ys[..1], vec![1, 1, 0]);
        assert_eq!(fit(&one, &grid, &fixed, 0.0).unwrap_err(), SolveError::TooFewIterations(1));
        let zero = stats_from(&vec![DVector::zeros(7); 10], vec![0, 0, 0]);
        assert_eq!(fit(&zero, &grid, &fixed, 0.0).unwrap_err(), SolveError::NoSignal);
    }
}
