//! The cell grid over join paths: which cell α a join path (x2, x3) falls in, and each cell's
//! bounds and neighbours.
//!
//! Axes (docs/model.md §7): r2 = |x2|, r3 = |x3|, and φ = the angle between the vectors x2 and x3,
//! folded to [0, π] (φ and 2π − φ give the same cell). Each radial axis is a list of edges starting
//! at 0; cell k covers [e_k, e_{k+1}) and the last covers [e_last, ∞) (the tail cell). φ has equal
//! bins. Cells are numbered α = (i2·n3 + i3)·nφ + iφ.

/// Most cells a grid may have: the moments hold a dense (2K+1)² matrix per fold.
pub const MAX_CELLS: usize = 256;

use std::f64::consts::PI;

use serde::Serialize;

use crate::sim::math::plane::radius;

/// The grid of tabulated-weight cells.
#[derive(Debug, Clone, PartialEq)]
pub struct CellGrid {
    r2_edges: Vec<f64>,
    r3_edges: Vec<f64>,
    phi_bins: u32,
    /// 1/step of each radial axis whose edges are equally spaced (0 when they are not).
    inv_steps: [f64; 2],
}

/// Bounds of one cell, as reported in results (`hi = None` for a tail cell).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CellBounds {
    /// [lo, hi) of r2 = |x2|, in the scene's length unit (that of L2 and L3); hi = None: the tail.
    pub r2: [Option<f64>; 2],
    /// [lo, hi) of r3 = |x3|, likewise.
    pub r3: [Option<f64>; 2],
    /// [lo, hi) of φ, the angle between x2 and x3, in radians within [0, π] (always bounded).
    pub phi: [Option<f64>; 2],
}

/// Index of the cell of axis `edges` containing `r` (edges[0] = 0 ≤ r): the last k with
/// edges[k] ≤ r (0 for NaN).
///
/// With equally spaced edges (`inv_step` > 0, the paper's r3 axis) the index is guessed as
/// ⌊r/step⌋ and then moved to the exact answer by comparing with the edges themselves — one or two
/// comparisons instead of a binary search, and the same result whatever the rounding of the guess.
#[inline]
fn axis_index(edges: &[f64], inv_step: f64, r: f64) -> usize {
    if inv_step > 0.0 {
        let mut i = ((r * inv_step) as usize).min(edges.len() - 1);
        while i > 0 && edges[i] > r {
            i -= 1;
        }
        while i + 1 < edges.len() && edges[i + 1] <= r {
            i += 1;
        }
        return i;
    }
    edges.partition_point(|&e| e <= r).saturating_sub(1)
}

/// 1/step of `edges` if they are equally spaced (within 10⁻⁹ of a step), else 0.
fn uniform_inv_step(edges: &[f64]) -> f64 {
    let Some(&step) = edges.get(1) else { return 0.0 };
    let uniform = step > 0.0 && edges.iter().enumerate().all(|(k, &e)| (e - k as f64 * step).abs() <= 1e-9 * step);
    if uniform { 1.0 / step } else { 0.0 }
}

impl CellGrid {
    /// A grid from validated edges (starting at 0, strictly increasing) and φ bins ≥ 1.
    pub fn new(r2_edges: Vec<f64>, r3_edges: Vec<f64>, phi_bins: u32) -> Self {
        debug_assert!(r2_edges.first() == Some(&0.0) && r3_edges.first() == Some(&0.0) && phi_bins >= 1);
        let inv_steps = [uniform_inv_step(&r2_edges), uniform_inv_step(&r3_edges)];
        Self { r2_edges, r3_edges, phi_bins, inv_steps }
    }

    /// Number of cells K.
    pub fn len(&self) -> usize {
        self.r2_edges.len() * self.r3_edges.len() * self.phi_bins as usize
    }

    /// Always false: a grid has at least one cell.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The edges of the r2 = |x2| axis: 0 first, strictly increasing; the last opens the tail cell.
    pub fn r2_edges(&self) -> &[f64] {
        &self.r2_edges
    }

    /// The edges of the r3 = |x3| axis, like [`CellGrid::r2_edges`].
    pub fn r3_edges(&self) -> &[f64] {
        &self.r3_edges
    }

    /// The number of equal bins of φ over [0, π] (at least 1).
    pub fn phi_bins(&self) -> u32 {
        self.phi_bins
    }

    /// The cell of the join path (x2, x3).
    #[inline]
    pub fn index(&self, x2: [f64; 2], x3: [f64; 2]) -> usize {
        let (r2, r3) = (radius(x2), radius(x3));
        let i2 = axis_index(&self.r2_edges, self.inv_steps[0], r2);
        let i3 = axis_index(&self.r3_edges, self.inv_steps[1], r3);
        let iphi = if self.phi_bins == 1 {
            0
        } else {
            // φ = angle between x2 and x3 in [0, π]; undefined (taken as 0) at a zero vector.
            let cross = x2[0] * x3[1] - x2[1] * x3[0];
            let dot = x2[0] * x3[0] + x2[1] * x3[1];
            let phi = libm::atan2(cross.abs(), dot);
            ((phi / PI * f64::from(self.phi_bins)) as usize).min(self.phi_bins as usize - 1)
        };
        (i2 * self.r3_edges.len() + i3) * self.phi_bins as usize + iphi
    }

    /// (i2, i3, iφ) of cell α.
    pub fn coordinates(&self, alpha: usize) -> (usize, usize, usize) {
        let nphi = self.phi_bins as usize;
        let n3 = self.r3_edges.len();
        (alpha / (n3 * nphi), (alpha / nphi) % n3, alpha % nphi)
    }

    /// Bounds of cell α.
    pub fn bounds(&self, alpha: usize) -> CellBounds {
        let (i2, i3, iphi) = self.coordinates(alpha);
        let span = |edges: &[f64], i: usize| [Some(edges[i]), edges.get(i + 1).copied()];
        let width = PI / f64::from(self.phi_bins);
        CellBounds {
            r2: span(&self.r2_edges, i2),
            r3: span(&self.r3_edges, i3),
            phi: [Some(iphi as f64 * width), Some((iphi + 1) as f64 * width)],
        }
    }

    /// Pairs of neighbouring cells (differing by one step along one axis), each pair once, for the
    /// gradient penalty. φ does not wrap: bins at φ = 0 and φ = π are not adjacent.
    pub fn neighbours(&self) -> Vec<(usize, usize)> {
        let (n2, n3, nphi) = (self.r2_edges.len(), self.r3_edges.len(), self.phi_bins as usize);
        let at = |i2: usize, i3: usize, ip: usize| (i2 * n3 + i3) * nphi + ip;
        let mut pairs = Vec::new();
        for i2 in 0..n2 {
            for i3 in 0..n3 {
                for ip in 0..nphi {
                    let here = at(i2, i3, ip);
                    if i2 + 1 < n2 {
                        pairs.push((here, at(i2 + 1, i3, ip)));
                    }
                    if i3 + 1 < n3 {
                        pairs.push((here, at(i2, i3 + 1, ip)));
                    }
                    if ip + 1 < nphi {
                        pairs.push((here, at(i2, i3, ip + 1)));
                    }
                }
            }
        }
        pairs
    }
}

#[cfg(test)]
mod tests {

    /// The arithmetic index of an equally spaced axis is the bisection's, at and next to every
    /// edge, in the tail, at 0 and for NaN; unequal edges keep the bisection.
    #[test]
    fn equally_spaced_axes_index_as_the_bisection_does() {
        let edges: Vec<f64> = (0..26).map(|k| f64::from(k) * 0.002).collect();
        let inv = uniform_inv_step(&edges);
        assert!(inv > 0.0);
        let bisect = |r: f64| edges.partition_point(|&e| e <= r).saturating_sub(1);
        let mut probes = vec![0.0, 1e-300, 0.051, 1.0, 1e300, f64::INFINITY, f64::NAN];
        for &e in &edges {
            probes.extend([e, f64::from_bits(e.to_bits().saturating_sub(1)), f64::from_bits(e.to_bits() + 1)]);
        }
        probes.extend((0..10_000).map(|k| f64::from(k) * 0.000_005_3));
        for r in probes {
            assert_eq!(axis_index(&edges, inv, r), bisect(r), "r = {r:e}");
        }
        assert_eq!(uniform_inv_step(&[0.0, 0.5, 0.7]), 0.0);
        assert_eq!(uniform_inv_step(&[0.0]), 0.0);
    }

    use super::*;

    fn paper() -> CellGrid {
        CellGrid::new(vec![0.0, 0.5], (0..=25).map(|i| f64::from(i) * 0.002).collect(), 1)
    }

    #[test]
    fn paper_grid_has_52_cells_and_tails() {
        let g = paper();
        assert_eq!(g.len(), 52);
        assert_eq!(g.index([0.1, 0.0], [0.001, 0.0]), 0);
        assert_eq!(g.index([0.1, 0.0], [0.0031, 0.0]), 1);
        assert_eq!(g.index([0.1, 0.0], [0.2, 0.0]), 25, "r3 tail");
        assert_eq!(g.index([0.7, 0.0], [0.0, 0.0]), 26, "r2 tail");
        assert_eq!(g.index([1e9, 0.0], [1e9, 1e9]), 51);
        let b = g.bounds(25);
        assert_eq!(b.r3, [Some(0.05), None]);
        assert_eq!(b.r2, [Some(0.0), Some(0.5)]);
        // 2 × 26 grid: 26 r2-neighbour pairs and 2 × 25 r3-neighbour pairs.
        assert_eq!(g.neighbours().len(), 26 + 50);
    }

    #[test]
    fn phi_is_folded_to_zero_pi() {
        let g = CellGrid::new(vec![0.0], vec![0.0], 4);
        assert_eq!(g.len(), 4);
        let at = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            g.index([1.0, 0.0], [c, s])
        };
        assert_eq!(at(10.0), 0);
        assert_eq!(at(-10.0), 0, "φ and 2π − φ share a cell");
        assert_eq!(at(100.0), 2);
        assert_eq!(at(179.9), 3);
        assert_eq!(at(180.0), 3);
        assert_eq!(g.index([0.0, 0.0], [1.0, 0.0]), 0, "undefined φ goes to the first bin");
        let (i2, i3, ip) = g.coordinates(3);
        assert_eq!((i2, i3, ip), (0, 0, 3));
        assert_eq!(g.neighbours(), vec![(0, 1), (1, 2), (2, 3)]);
    }
}
