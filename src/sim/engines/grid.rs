//! A spatial hash grid of camera vertices on one plane, for the light paths to find the vertices
//! within the merge radius R of their hit point.
//!
//! Cells have side 2R (8R for small sets, see [`MergeGrid::rebuild`]) and each vertex is entered
//! into every cell its R-disc overlaps (at most 2×2), so a query looks at the single cell
//! containing the light point. Cells are hashed into a table of buckets a few times larger than
//! the entries, each bucket the head of a linked list of entries: a rebuild is a hash and two
//! stores per entry (the restricted engine rebuilds two grids every iteration, to answer a few
//! dozen queries), and clearing touches only the buckets in use. Nearly every query finds its
//! bucket empty: one multiply, one shift and one load. The grid only proposes candidates; the exact
//! distance test |x_l − x_c| ≤ R is done by the caller, so hash collisions (two cells in one
//! bucket) cost time, never results.

/// Camera vertices of one plane, hashed by cells of side 2R or 8R.
///
/// Rebuilt once per iteration into the same buffers ([`MergeGrid::rebuild`]): after the first
/// iterations it allocates nothing.
#[derive(Debug, Clone, Default)]
pub struct MergeGrid {
    inv_cell: f64,
    /// Per bucket, its first entry ([`NONE`] when empty).
    heads: Vec<u32>,
    bucket_shift: u32,
    /// (vertex, next entry of the same bucket): each bucket lists its vertices in index order,
    /// each once.
    entries: Vec<(u32, u32)>,
    /// Buckets with entries, to clear them (and only them) at the next rebuild.
    used: Vec<u32>,
}

/// The end of a bucket's list.
const NONE: u32 = u32::MAX;

/// Most points of a grid built with wide cells (see [`MergeGrid::rebuild`]).
const SMALL_SET: usize = 1024;

/// Buckets per vertex (at least): few enough to stay in L1 for the paper's hundred vertices (4 KiB
/// of heads), many enough that a query rarely meets another cell's vertices (a vertex has 1.6
/// entries on average with the wide cells).
const BUCKETS_PER_VERTEX: usize = 8;

/// The cell coordinate of `x` (in units of the cell side): truncation towards zero, one
/// instruction (baseline x86-64 has no floor instruction, and libm's is a call). Cells are
/// [k, k+1) for k > 0, (k−1, k] for k < 0 and (−1, 1) for k = 0: the zero cell is twice as wide,
/// which is harmless, because insertion and query use the same function and the function is
/// monotone — a 2R-wide disc still spans at most two cells per axis. Out-of-range values saturate,
/// consistently on both sides.
#[inline(always)]
fn cell_of(x: f64) -> i64 {
    x as i64
}

#[inline(always)]
fn hash(ix: i64, iy: i64) -> u64 {
    ((ix as u64) ^ (iy as u64).rotate_left(32)).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// The vertices a query may merge with, in index order (an iterator over a bucket's list).
#[derive(Debug, Clone)]
pub struct Candidates<'a> {
    entries: &'a [(u32, u32)],
    next: u32,
}

impl Iterator for Candidates<'_> {
    type Item = u32;

    #[inline(always)]
    fn next(&mut self) -> Option<u32> {
        if self.next == NONE {
            return None;
        }
        let (vertex, next) = self.entries[self.next as usize];
        self.next = next;
        Some(vertex)
    }
}

impl MergeGrid {
    /// Builds the grid of `points` (vertex `j` at `points[j]`) for merge radius `radius`.
    pub fn new<P>(points: P, radius: f64) -> Self
    where
        P: IntoIterator<Item = (u32, [f64; 2])>,
        P::IntoIter: DoubleEndedIterator + Clone,
    {
        let mut grid = Self::default();
        grid.rebuild(points, radius);
        grid
    }

    /// Replaces the grid's contents by `points` (in increasing vertex order), as
    /// [`MergeGrid::new`] would build them, reusing the buffers. (What a query returns does not
    /// depend on the table's size or history: the vertices of its bucket, in index order.) The
    /// points are read twice — counted, then entered back to front — rather than copied: copying
    /// them was a quarter of a rebuild.
    pub fn rebuild<P>(&mut self, points: P, radius: f64)
    where
        P: IntoIterator<Item = (u32, [f64; 2])>,
        P::IntoIter: DoubleEndedIterator + Clone,
    {
        let points = points.into_iter();
        let count = points.clone().count();
        debug_assert!(points.clone().is_sorted_by(|a, b| a.0 < b.0), "points in increasing vertex order");
        // Cells of side 2R·s: a vertex's R-disc meets (1 + 1/s)² cells on average, and a query
        // offers the vertices of a (2Rs)² cell. Any superset in index order gives the callers the
        // same merges (they test the exact distance), so s only trades build work against false
        // candidates. A small set (the paper's hundred camera vertices, rebuilt every iteration)
        // takes s = 4: 1.6 entries per vertex instead of 4, and ~0.06 extra candidates a query for
        // vertices spread over a unit disc; a large one keeps s = 1, where dense vertices would make
        // wide cells crowded.
        let scale = if count <= SMALL_SET { 4.0 } else { 1.0 };
        self.inv_cell = 1.0 / (2.0 * radius * scale);
        let wanted = (BUCKETS_PER_VERTEX * count).next_power_of_two().max(64);
        if self.heads.len() < wanted {
            self.heads = vec![NONE; wanted];
            self.used.clear();
        }
        for &b in &self.used {
            self.heads[b as usize] = NONE;
        }
        self.used.clear();
        self.entries.clear();
        self.bucket_shift = 64 - self.heads.len().trailing_zeros();
        let inv_cell = self.inv_cell;
        // Back to front, each entry at the head of its bucket's list, so that every list is in
        // increasing vertex order; a vertex whose cells share a bucket is entered there once (its
        // own earlier entry is then the head).
        for (j, [x, y]) in points.rev() {
            let (x0, x1) = (cell_of((x - radius) * inv_cell), cell_of((x + radius) * inv_cell));
            let (y0, y1) = (cell_of((y - radius) * inv_cell), cell_of((y + radius) * inv_cell));
            for ix in x0..=x1 {
                for iy in y0..=y1 {
                    let b = (hash(ix, iy) >> self.bucket_shift) as usize;
                    let head = self.heads[b];
                    if head == NONE {
                        self.used.push(b as u32);
                    } else if self.entries[head as usize].0 == j {
                        continue;
                    }
                    self.heads[b] = self.entries.len() as u32;
                    self.entries.push((j, head));
                }
            }
        }
    }

    /// Indices of the vertices that may lie within R of `p` (a superset of those that do), in
    /// increasing order.
    #[inline(always)]
    pub fn candidates(&self, p: [f64; 2]) -> Candidates<'_> {
        let next = match self.heads.len() {
            0 => NONE,
            _ => {
                let h = hash(cell_of(p[0] * self.inv_cell), cell_of(p[1] * self.inv_cell));
                self.heads[(h >> self.bucket_shift) as usize]
            }
        };
        Candidates { entries: &self.entries, next }
    }
}

#[cfg(test)]
mod tests {

    /// However many cells share a bucket, a query lists each vertex once, in index order: points
    /// on a lattice of the cell size put every vertex in four cells, and a wide radius crowds the
    /// buckets.
    #[test]
    fn crowded_buckets_list_each_vertex_once_in_order() {
        let r = 0.01;
        let points: Vec<(u32, [f64; 2])> =
            (0..900u32).map(|k| (k, [f64::from(k % 30) * 0.08 - 1.2, f64::from(k / 30) * 0.08 - 1.2])).collect();
        let grid = MergeGrid::new(points.iter().copied(), r);
        let mut rng = stream(8, 8, 8);
        for _ in 0..20_000 {
            let q = [uniform(&mut rng) * 2.6 - 1.3, uniform(&mut rng) * 2.6 - 1.3];
            let cands: Vec<u32> = grid.candidates(q).collect();
            assert!(cands.windows(2).all(|w| w[0] < w[1]), "sorted and distinct at {q:?}: {cands:?}");
            for &(j, p) in &points {
                if (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) <= r * r {
                    assert!(cands.contains(&j), "missed vertex {j} near {q:?}");
                }
            }
        }
    }

    use super::*;
    use crate::sim::math::rng::{stream, uniform};

    /// The grid must propose every vertex within R of a query (brute force is the reference).
    #[test]
    fn finds_every_vertex_within_the_radius() {
        for n in [300, 3000] {
            finds_every_vertex(n);
        }
    }

    /// With `n` points: 300 take the wide cells of small sets, 3000 the 2R cells.
    fn finds_every_vertex(n: usize) {
        let r = 0.01;
        let mut rng = stream(1, 2, 3);
        let points: Vec<[f64; 2]> =
            (0..n).map(|_| [uniform(&mut rng) * 0.5 - 0.25, uniform(&mut rng) * 0.5 - 0.25]).collect();
        let grid = MergeGrid::new(points.iter().enumerate().map(|(j, &p)| (j as u32, p)), r);
        let mut found = 0;
        for _ in 0..60_000_000 / n {
            let q = [uniform(&mut rng) * 0.6 - 0.3, uniform(&mut rng) * 0.6 - 0.3];
            let cands: Vec<u32> = grid.candidates(q).collect();
            for (j, p) in points.iter().enumerate() {
                let near = (p[0] - q[0]).hypot(p[1] - q[1]) <= r;
                if near {
                    found += 1;
                    assert!(cands.contains(&(j as u32)), "missed vertex {j} near {q:?}");
                }
            }
        }
        assert!(found > 1000, "the test must exercise real hits ({found})");
        assert!(cands_sorted(&grid, &points), "candidates in index order");
    }

    /// Every query's candidates are in index order (what makes the merges' order, hence their
    /// floating-point sums, independent of the cell size).
    fn cands_sorted(grid: &MergeGrid, points: &[[f64; 2]]) -> bool {
        points.iter().all(|&p| grid.candidates(p).is_sorted_by(|a, b| a < b))
    }

    #[test]
    fn far_and_huge_queries_are_empty() {
        let grid = MergeGrid::new([(0, [0.0, 0.0])], 0.003);
        assert_eq!(grid.candidates([1e12, -1e12]).count(), 0);
        assert_eq!(grid.candidates([f64::MAX, 3.0]).count(), 0);
        assert_eq!(grid.candidates([0.001, 0.001]).collect::<Vec<_>>(), [0]);
        let empty = MergeGrid::new([], 0.003);
        assert_eq!(empty.candidates([0.0, 0.0]).count(), 0);
        assert_eq!(MergeGrid::default().candidates([0.0, 0.0]).count(), 0);
    }
}
