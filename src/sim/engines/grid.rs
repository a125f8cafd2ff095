//! A spatial hash grid of camera vertices on one plane, for the streamed light paths to find the
//! vertices within the merge radius R of their hit point.
//!
//! Cells have side 2R (8R for small sets, see [`MergeGrid::rebuild`]) and each vertex is inserted
//! into every cell its R-disc overlaps (at most 2×2), so a query looks at the single cell
//! containing the light point. Because nearly every light path misses every camera, the table is fronted by an occupancy bitset that fits in L1: the common
//! query is one multiply, one shift and one bit test. The grid only proposes candidates; the exact
//! distance test |x_l − x_c| ≤ R is done by the caller, so hash collisions cost time, never results.

/// Camera vertices of one plane, hashed by cells of side 2R or 8R.
///
/// Rebuilt once per iteration into the same buffers ([`MergeGrid::rebuild`]): after the first
/// iterations it allocates nothing, and it clears only the slots it used.
#[derive(Debug, Clone, Default)]
pub struct MergeGrid {
    inv_cell: f64,
    /// One bit per hashed cell: is any vertex there?
    occupancy: Vec<u64>,
    /// Open-addressing table of occupied cells.
    slots: Vec<Slot>,
    slot_shift: u32,
    /// Vertex indices grouped by cell; a slot's `start..start+len`.
    members: Vec<u32>,
    /// The points of the last rebuild (their number chooses the cell size), kept for reuse.
    points: Vec<(u32, [f64; 2])>,
    /// (cell x, cell y, vertex) of every insertion, kept for reuse.
    entries: Vec<(i64, i64, u32)>,
    /// The slot of each entry, found once (the placement pass needs no second lookup).
    entry_slots: Vec<u32>,
    /// Indices of the slots in use, to clear them (and only them) at the next rebuild.
    used: Vec<u32>,
}

#[derive(Debug, Clone, Copy)]
struct Slot {
    ix: i64,
    iy: i64,
    start: u32,
    /// 0 marks an empty slot.
    len: u32,
}

const EMPTY: Slot = Slot { ix: 0, iy: 0, start: 0, len: 0 };

/// Most points of a grid built with wide cells (see [`MergeGrid::rebuild`]).
const SMALL_SET: usize = 1024;

/// Bits of the occupancy hash: 2¹⁴ bits = 2 KiB.
const OCCUPANCY_BITS: u32 = 14;

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

impl MergeGrid {
    /// Builds the grid of `points` (vertex `j` at `points[j]`) for merge radius `radius`.
    pub fn new(points: impl IntoIterator<Item = (u32, [f64; 2])>, radius: f64) -> Self {
        let mut grid = Self::default();
        grid.rebuild(points, radius);
        grid
    }

    /// Replaces the grid's contents by `points`, as [`MergeGrid::new`] would build them, reusing
    /// the buffers. (What a query returns does not depend on the table's size or history: each
    /// cell lists its vertices in insertion order.)
    pub fn rebuild(&mut self, points: impl IntoIterator<Item = (u32, [f64; 2])>, radius: f64) {
        self.points.clear();
        self.points.extend(points);
        // Cells of side 2R·s: a vertex's R-disc meets (1 + 1/s)² cells on average, and a query
        // offers the vertices of a (2Rs)² cell. Any superset in index order gives the callers the
        // same merges (they test the exact distance), so s only trades build work against false
        // candidates. A small set (the paper's hundred camera vertices, rebuilt every iteration)
        // takes s = 4: 1.6 entries per vertex instead of 4, and ~0.06 extra candidates a query for
        // vertices spread over a unit disc; a large one keeps s = 1, where dense vertices would make
        // wide cells crowded.
        let scale = if self.points.len() <= SMALL_SET { 4.0 } else { 1.0 };
        let cell = 2.0 * radius * scale;
        self.inv_cell = 1.0 / cell;
        let inv_cell = self.inv_cell;
        self.entries.clear();
        for &(j, [x, y]) in &self.points {
            let (x0, x1) = (cell_of((x - radius) * inv_cell), cell_of((x + radius) * inv_cell));
            let (y0, y1) = (cell_of((y - radius) * inv_cell), cell_of((y + radius) * inv_cell));
            for ix in x0..=x1 {
                for iy in y0..=y1 {
                    self.entries.push((ix, iy, j));
                }
            }
        }
        // Counting placement instead of a sort (linear time; this runs once per iteration, which
        // matters for the restricted engine): count the entries of each cell in the open-addressing
        // table, turn the counts into ranges, then place the members back to front. The table has
        // at least 2 slots per entry (load ≤ 1/2, as entries ≥ cells; for scattered vertices ≈ 1/5),
        // small enough to stay in L1; it is reallocated only when it must grow.
        let slot_bits = (2 * self.entries.len().max(1)).next_power_of_two().max(16).trailing_zeros();
        if self.slots.len() < 1 << slot_bits || self.occupancy.is_empty() {
            self.slots = vec![EMPTY; 1 << slot_bits];
            self.occupancy = vec![0; 1 << (OCCUPANCY_BITS - 6)];
            self.used.clear();
        }
        for &k in &self.used {
            self.slots[k as usize] = EMPTY;
        }
        self.used.clear();
        self.occupancy.fill(0);
        self.slot_shift = 64 - self.slots.len().trailing_zeros();
        self.members.clear();
        self.members.resize(self.entries.len(), 0);
        self.entry_slots.clear();
        for i in 0..self.entries.len() {
            let (ix, iy, _) = self.entries[i];
            let k = self.find_or_insert(ix, iy);
            self.slots[k].len += 1;
            self.entry_slots.push(k as u32);
        }
        let mut end = 0;
        for &k in &self.used {
            let slot = &mut self.slots[k as usize];
            end += slot.len;
            slot.start = end;
        }
        // Back to front, so that each cell lists its vertices in insertion (index) order.
        for (&(_, _, j), &k) in self.entries.iter().zip(&self.entry_slots).rev() {
            let slot = &mut self.slots[k as usize];
            slot.start -= 1;
            self.members[slot.start as usize] = j;
        }
    }

    /// The slot of cell (ix, iy); a new cell claims an empty slot (the caller then counts into its
    /// `len`, which marks it taken) and sets its occupancy bit.
    #[inline(always)]
    fn find_or_insert(&mut self, ix: i64, iy: i64) -> usize {
        let h = hash(ix, iy);
        let mask = self.slots.len() - 1;
        let mut k = (h >> self.slot_shift) as usize;
        loop {
            let s = self.slots[k];
            if s.len == 0 {
                let bit = h >> (64 - OCCUPANCY_BITS);
                self.occupancy[(bit >> 6) as usize] |= 1 << (bit & 63);
                self.slots[k] = Slot { ix, iy, start: 0, len: 0 };
                self.used.push(k as u32);
                return k;
            }
            if s.ix == ix && s.iy == iy {
                return k;
            }
            k = (k + 1) & mask;
        }
    }

    /// Whether any vertex may lie within R of `p`: the occupancy bit of p's cell (false means
    /// certainly none).
    #[inline(always)]
    pub fn may_hold(&self, p: [f64; 2]) -> bool {
        let h = hash(cell_of(p[0] * self.inv_cell), cell_of(p[1] * self.inv_cell));
        let bit = h >> (64 - OCCUPANCY_BITS);
        self.occupancy[(bit >> 6) as usize] & (1 << (bit & 63)) != 0
    }

    /// Indices of the vertices that may lie within R of `p` (a superset of those that do).
    #[inline(always)]
    pub fn candidates(&self, p: [f64; 2]) -> &[u32] {
        let ix = cell_of(p[0] * self.inv_cell);
        let iy = cell_of(p[1] * self.inv_cell);
        let h = hash(ix, iy);
        let bit = h >> (64 - OCCUPANCY_BITS);
        if self.occupancy[(bit >> 6) as usize] & (1 << (bit & 63)) == 0 {
            return &[];
        }
        self.probe(ix, iy, h)
    }

    #[cold]
    fn probe(&self, ix: i64, iy: i64, h: u64) -> &[u32] {
        let mask = self.slots.len() - 1;
        let mut k = (h >> self.slot_shift) as usize;
        loop {
            let s = self.slots[k];
            if s.len == 0 {
                return &[];
            }
            if s.ix == ix && s.iy == iy {
                return &self.members[s.start as usize..(s.start + s.len) as usize];
            }
            k = (k + 1) & mask;
        }
    }
}

#[cfg(test)]
mod tests {
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
            let cands = grid.candidates(q);
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
        assert!(grid.candidates([1e12, -1e12]).is_empty());
        assert!(grid.candidates([f64::MAX, 3.0]).is_empty());
        assert_eq!(grid.candidates([0.001, 0.001]), &[0]);
        let empty = MergeGrid::new([], 0.003);
        assert!(empty.candidates([0.0, 0.0]).is_empty());
    }
}
