//! A spatial hash grid of camera vertices on one plane, for the streamed light paths to find the
//! vertices within the merge radius R of their hit point.
//!
//! Cells have side 2R and each vertex is inserted into every cell its R-disc overlaps (at most
//! 2×2), so a query looks at the single cell containing the light point. Because nearly every light
//! path misses every camera, the table is fronted by an occupancy bitset that fits in L1: the common
//! query is one multiply, one shift and one bit test. The grid only proposes candidates; the exact
//! distance test |x_l − x_c| ≤ R is done by the caller, so hash collisions cost time, never results.

/// Camera vertices of one plane, hashed by 2R cells.
#[derive(Debug, Clone)]
pub struct MergeGrid {
    inv_cell: f64,
    /// One bit per hashed cell: is any vertex there?
    occupancy: Vec<u64>,
    /// Open-addressing table of occupied cells.
    slots: Vec<Slot>,
    slot_shift: u32,
    /// Vertex indices grouped by cell; a slot's `start..start+len`.
    members: Vec<u32>,
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
        let cell = 2.0 * radius;
        let inv_cell = 1.0 / cell;
        let mut entries: Vec<(i64, i64, u32)> = Vec::new();
        for (j, [x, y]) in points {
            let (x0, x1) = (cell_of((x - radius) * inv_cell), cell_of((x + radius) * inv_cell));
            let (y0, y1) = (cell_of((y - radius) * inv_cell), cell_of((y + radius) * inv_cell));
            for ix in x0..=x1 {
                for iy in y0..=y1 {
                    entries.push((ix, iy, j));
                }
            }
        }
        // Counting placement instead of a sort (linear time; this runs once per iteration, which
        // matters for the restricted engine): count the entries of each cell in the open-addressing
        // table, turn the counts into ranges, then place the members back to front.
        let slot_bits = (4 * entries.len().max(1)).next_power_of_two().max(16).trailing_zeros();
        let mut grid = Self {
            inv_cell,
            occupancy: vec![0; 1 << (OCCUPANCY_BITS - 6)],
            slots: vec![EMPTY; 1 << slot_bits],
            slot_shift: 64 - slot_bits,
            members: vec![0; entries.len()],
        };
        for &(ix, iy, _) in &entries {
            let k = grid.find_or_insert(ix, iy);
            grid.slots[k].len += 1;
        }
        let mut end = 0;
        for slot in grid.slots.iter_mut().filter(|s| s.len != 0) {
            end += slot.len;
            slot.start = end;
        }
        // Back to front, so that each cell lists its vertices in insertion (index) order.
        for &(ix, iy, j) in entries.iter().rev() {
            let k = grid.find_or_insert(ix, iy);
            grid.slots[k].start -= 1;
            grid.members[grid.slots[k].start as usize] = j;
        }
        grid
    }

    /// The slot of cell (ix, iy); a new cell claims an empty slot (the caller then counts into its
    /// `len`, which marks it taken) and sets its occupancy bit.
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
        let r = 0.01;
        let mut rng = stream(1, 2, 3);
        let points: Vec<[f64; 2]> =
            (0..300).map(|_| [uniform(&mut rng) * 0.5 - 0.25, uniform(&mut rng) * 0.5 - 0.25]).collect();
        let grid = MergeGrid::new(points.iter().enumerate().map(|(j, &p)| (j as u32, p)), r);
        let mut found = 0;
        for _ in 0..200_000 {
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
