//! The near filters of the block loop: which light points may lie within R of a camera vertex on
//! one plane, as a bitmap the vectorised loop can query (see [`NearFilter`] for the proof that it
//! is conservative).

/// Bits per axis of a [`NearFilter`]'s cell index: 2⁸ × 2⁸ cells, periodic.
const NEAR_AXIS_BITS: u32 = 8;
const NEAR_AXIS_MASK: u64 = (1 << NEAR_AXIS_BITS) - 1;
/// The filter's 2¹⁶ bits as 32-bit words (the width AVX2 gathers): 8 KiB, so both planes' filters
/// stay in L1.
pub(super) const NEAR_WORDS: usize = 1 << (2 * NEAR_AXIS_BITS - 5);

/// Which light points may lie within R of a camera vertex on one plane: a bitmap over cells of
/// side 2R (or more, see below), folded periodically onto 2⁸ × 2⁸ cells, built per chunk from the
/// camera vertices.
///
/// It answers the question of [`crate::sim::engines::grid::MergeGrid::may_hold`], but its cell index is computed
/// with floating-point operations and integer masks only (no 64-bit multiply or float → integer
/// conversion, which AVX2 lacks), so it vectorises with the rest of the block, and the bit lookups
/// are AVX2 gathers where available. False positives (≈ 0.6% per plane at the paper's parameters,
/// from the folding) cost a look at the grid, never a result: the merge functions do the exact
/// distance test on the grid's candidates.
///
/// Why it is conservative: with h the cell side, the cell coordinate of x is n(x) =
/// round(clamp(x/h, ±2⁵⁰)), a non-decreasing function of x. A camera vertex c marks every cell from
/// n(c − m) to n(c + m), with m = R(1 + 10⁻⁹) + |c|·2⁻⁵⁰ (the exact test |x − c| ≤ R passes in
/// floating point only for |x − c| ≤ R(1 + 3·2⁻⁵³), and m also absorbs the rounding of c ± m), so
/// every x within R of c falls in a marked cell; folding maps query and vertex cells alike. Queries
/// skip the clamp, which saves two instructions per coordinate: every query coordinate is bounded
/// by the filter's `reach`, and h ≥ reach·2⁻⁴⁸, so |x/h| ≤ 2⁴⁸ and the clamp would change nothing.
pub(super) struct NearFilter {
    inv_cell: f64,
    pub(super) words: [u32; NEAR_WORDS],
}

/// x/h rounded to an integer n, as the bits of n + 1.5·2⁵² (whose low 51 bits are n in two's
/// complement for |n| ≤ 2⁵⁰): adding 1.5·2⁵² rounds to an integer without a conversion instruction.
/// For |x/h| ≤ 2⁵⁰ only; [`near_axis_clamped`] takes any x.
#[inline(always)]
fn near_axis(x: f64, inv_cell: f64) -> u64 {
    (x * inv_cell + NEAR_ROUNDER).to_bits()
}

/// [`near_axis`] of x/h clamped to ±2⁵⁰ (equal to it wherever it applies).
fn near_axis_clamped(x: f64, inv_cell: f64) -> u64 {
    const LIMIT: f64 = (1u64 << 50) as f64;
    ((x * inv_cell).clamp(-LIMIT, LIMIT) + NEAR_ROUNDER).to_bits()
}

const NEAR_ROUNDER: f64 = 1.5 * (1u64 << 52) as f64;

impl NearFilter {
    /// The filter of the vertices `points` for merge radius `radius`, to be queried only at
    /// points whose coordinates are at most `reach` in absolute value.
    pub(super) fn new(points: impl Iterator<Item = [f64; 2]>, radius: f64, reach: f64) -> Self {
        let inv_cell = 1.0 / (2.0 * radius).max(reach * 2f64.powi(-48));
        let mut words = [0; NEAR_WORDS];
        // The unfolded cell range [n(c − m), n(c + m)] of one coordinate, capped at one period.
        let range = |c: f64| {
            let m = radius * (1.0 + 1e-9) + c.abs() * 2f64.powi(-50);
            let cell = |x: f64| near_axis_clamped(x, inv_cell).wrapping_sub(NEAR_ROUNDER.to_bits());
            let (lo, hi) = (cell(c - m), cell(c + m));
            let len = hi.wrapping_sub(lo).min(NEAR_AXIS_MASK);
            (0..=len).map(move |k| lo.wrapping_add(k) & NEAR_AXIS_MASK)
        };
        for [x, y] in points {
            for ix in range(x) {
                for iy in range(y) {
                    let cell = ix | (iy << NEAR_AXIS_BITS);
                    words[(cell >> 5) as usize] |= 1 << (cell & 31);
                }
            }
        }
        Self { inv_cell, words }
    }

    /// The folded cell of (`x`, `y`), in [0, 2¹⁶).
    #[inline(always)]
    pub(super) fn cell(&self, x: f64, y: f64) -> u32 {
        let (ix, iy) = (near_axis(x, self.inv_cell), near_axis(y, self.inv_cell));
        ((ix & NEAR_AXIS_MASK) | ((iy & NEAR_AXIS_MASK) << NEAR_AXIS_BITS)) as u32
    }

    /// 1 if a camera vertex may lie within R of a point of `cell`, else 0.
    #[inline(always)]
    pub(super) fn holds(&self, cell: u32) -> u32 {
        let word = self.words[(cell as usize >> 5) & (NEAR_WORDS - 1)];
        (word >> (cell & 31)) & 1
    }
}
