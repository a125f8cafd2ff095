//! The near filters of the block loop: which light points may lie within R of a camera vertex on
//! one plane, as a bitmap the vectorised loop can query. [`NearFilter32`] is queried with the
//! single-precision points of the block loop, [`NearFilter`] with the exact points of the few
//! paths that pass it (see each for the proof that it is conservative).

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
            (lo, hi.wrapping_sub(lo))
        };
        for [x, y] in points {
            mark(&mut words, range(x), range(y));
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
        bit(&self.words, cell)
    }
}

/// The bit of folded cell `cell` in a filter's bitmap (both filters share the layout).
#[inline(always)]
fn bit(words: &[u32; NEAR_WORDS], cell: u32) -> u32 {
    (words[(cell as usize >> 5) & (NEAR_WORDS - 1)] >> (cell & 31)) & 1
}

/// Sets the bits of the cells whose folded coordinates are lo + k (mod 2⁸), k ≤ len, on each axis
/// (an unfolded range `(lo, len)` per axis; a range of a period or more covers every cell).
fn mark(words: &mut [u32; NEAR_WORDS], (x_lo, x_len): (u64, u64), (y_lo, y_len): (u64, u64)) {
    let folded = |lo: u64, len: u64| (0..=len.min(NEAR_AXIS_MASK)).map(move |k| lo.wrapping_add(k) & NEAR_AXIS_MASK);
    for ix in folded(x_lo, x_len) {
        for iy in folded(y_lo, y_len) {
            let cell = ix | (iy << NEAR_AXIS_BITS);
            words[(cell >> 5) as usize] |= 1 << (cell & 31);
        }
    }
}

/// 1.5·2²³: adding it to a float v with |v| ≤ 2²¹ rounds v to an integer n and leaves 2²² + n in
/// the low bits, so the low 8 bits are n mod 2⁸ ([`near_axis`]'s trick in single precision).
const NEAR_ROUNDER32: f32 = 1.5 * (1u32 << 23) as f32;

/// [`NearFilter`] for single-precision query points that are only known to lie within `error` of
/// the exact (f64) points: the block loop's first, eight-lane filter. The same 2⁸ × 2⁸ folded
/// bitmap, queried with [`NearFilter32::cell`] and looked up as [`NearFilter`]'s bits.
///
/// Why it is conservative. Let E be `error` and `reach` a bound on the query coordinates. The
/// cell side is h ≥ max(2R, reach·2⁻²⁰) and `inv_cell` = fl₃₂(1/h) ≤ 2²⁰(1 + 2⁻²⁴)/reach, so for a
/// query |x·inv_cell| < 2²¹ and the cell coordinate n(x) = fl₃₂(x·inv_cell + 1.5·2²³) (one fused,
/// exactly rounded operation) is 1.5·2²³ plus the integer nearest x·inv_cell; n is non-decreasing
/// in x. The marking uses N(v) = n(clamp(v, ±L)) with the f32 L ≥ reach, which is also
/// non-decreasing and equals n on every query. A merge needs the exact point x to pass the merge
/// functions' test against a vertex c, so |x − c| ≤ R(1 + 3·2⁻⁵³) per coordinate, and the query
/// x₃₂ has |x₃₂ − x| ≤ E. The vertex marks every cell from N(lo) to N(hi), with lo the largest f32
/// ≤ c − m and hi the smallest f32 ≥ c + m, m = R(1 + 10⁻⁹) + E + |c|·2⁻⁵⁰ (in f64; the last term
/// absorbs the rounding of c ± m, and the callers' E has more room than the rounding of m takes
/// from it). Then lo ≤ x₃₂ ≤ hi, so N(lo) ≤ n(x₃₂) ≤ N(hi): the query's cell is marked, and folding
/// maps query and vertex cells alike. (A query beyond `reach` gets an unspecified cell, still a
/// valid index: the block loop sends such paths to the exact tests anyway.)
pub(super) struct NearFilter32 {
    pub(super) inv_cell: f32,
    pub(super) words: [u32; NEAR_WORDS],
}

impl NearFilter32 {
    /// The filter of the vertices `points` for merge radius `radius`, to be queried at points
    /// within `error` of the exact points and with coordinates at most `reach` in absolute value.
    pub(super) fn new(points: impl Iterator<Item = [f64; 2]>, radius: f64, error: f64, reach: f64) -> Self {
        let inv_cell = (1.0 / (2.0 * radius).max(reach * 2f64.powi(-20))) as f32;
        let limit = round_up_f32(reach);
        let mut words = [0; NEAR_WORDS];
        let cell = |v: f32| u64::from(v.clamp(-limit, limit).mul_add(inv_cell, NEAR_ROUNDER32).to_bits());
        let range = |c: f64| {
            let m = radius * (1.0 + 1e-9) + error + c.abs() * 2f64.powi(-50);
            let (lo, hi) = (cell(round_down_f32(c - m)), cell(round_up_f32(c + m)));
            (lo, hi - lo)
        };
        for [x, y] in points {
            mark(&mut words, range(x), range(y));
        }
        Self { inv_cell, words }
    }

    /// The folded cell of (`x`, `y`), in [0, 2¹⁶).
    #[inline(always)]
    pub(super) fn cell(&self, x: f32, y: f32) -> u32 {
        let ix = x.mul_add(self.inv_cell, NEAR_ROUNDER32).to_bits();
        let iy = y.mul_add(self.inv_cell, NEAR_ROUNDER32).to_bits();
        (ix & NEAR_AXIS_MASK as u32) | ((iy & NEAR_AXIS_MASK as u32) << NEAR_AXIS_BITS)
    }

    /// 1 if a camera vertex may lie within R of a point of `cell`, else 0.
    #[inline(always)]
    pub(super) fn holds(&self, cell: u32) -> u32 {
        bit(&self.words, cell)
    }
}

/// The largest f32 ≤ `v` (−∞ below the f32 range).
pub(super) fn round_down_f32(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) > v { f.next_down() } else { f }
}

/// The smallest f32 ≥ `v` (+∞ above the f32 range).
pub(super) fn round_up_f32(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) < v { f.next_up() } else { f }
}
