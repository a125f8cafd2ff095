//! A fast exact accumulator for the runner's hot path: fixed-point limbs over a sliding window of
//! binary exponents, with an [`ExactSum`] for whatever falls outside it.
//!
//! An [`ExactSum`] adds a value by walking every part of its expansion — about twenty for the
//! moments' sums, whose values span hundreds of orders of magnitude (a contribution deep in the
//! lobe's tail, squared, is subnormal) — so that the exact sums of ΣYYᵀ cost more than tracing the
//! iteration (issue 26). A [`WindowSum`] keeps the same exact real sum as a long accumulator
//! (M. Neal, "Fast exact summation using small and large superaccumulators", 2015): a double
//! m·2^q, m < 2⁵³, is split into three 32-bit chunks added to 64-bit limbs, each limb holding
//! multiples of 2^(32·L − 1074) for its global index L. Adding is three integer additions, whatever
//! the magnitudes seen before. Only a window of [`WINDOW`] limbs (256 bits, 77 decimal orders)
//! below the largest value seen so far is kept as limbs: a value below the window, and every limb
//! the window leaves behind when a larger value moves it up, goes to the [`ExactSum`] `rest`
//! exactly (a limb is split into two 32-bit halves, each an exact double). So the memory is ~100
//! bytes a sum, and the slow path is taken only by values ≥ 10⁷⁷ times smaller than the largest.
//!
//! Exactness: chunks and halves are integers below 2³² times powers of two within the double range,
//! so every conversion is exact, and integer addition is exact while no limb overflows: a limb
//! gains less than 2³² a value, so [`WindowSum::add`] carries every limb into the next after
//! [`CARRY_EVERY`] additions. The real sum is therefore the exact sum of the values added, and
//! [`WindowSum::add_to`] hands it to an [`ExactSum`] exactly: which accumulator summed what, and
//! in what order, changes no bit of the canonical form.
//!
//! Range: values up to 2⁹⁷⁰ and sums up to 2¹⁰⁰⁵ in magnitude (a limb's upper half is read at
//! 2^(32(L+1) − 1074)); the moments' values are at most 10²⁸⁰ (fourth powers of tallies bounded by
//! 10⁷⁰, `stats::moments::MAX_TALLY_VALUE`) summed over at most 2⁶² iterations, below 2⁹⁹³.

use super::exact_sum::ExactSum;

/// Limbs kept as integers: a window of 256 bits below the top of the largest value added.
pub const WINDOW: usize = 8;

/// Additions after which every limb is carried into the next: each adds less than 2³² to a limb,
/// so limbs stay below 2⁶² in magnitude (far from i64's 2⁶³).
pub const CARRY_EVERY: u32 = 1 << 30;

const LOW_32: u64 = (1 << 32) - 1;

/// No value added yet (the window has no position).
const UNPLACED: i32 = i32::MIN;

/// The exact sum of the finite doubles added to it; see the module documentation.
#[derive(Clone, Debug)]
pub struct WindowSum {
    /// `limbs[k]` counts multiples of 2^(32·(top − WINDOW + 1 + k) − 1074).
    limbs: [i64; WINDOW],
    /// Global index of the window's highest limb, [`UNPLACED`] before the first value.
    top: i32,
    /// Additions since the last carry.
    since_carry: u32,
    /// Values below the window and limbs the window left behind, exactly.
    rest: ExactSum,
}

impl Default for WindowSum {
    fn default() -> Self {
        Self::new()
    }
}

/// 2^k as a double, for −1074 ≤ k ≤ 1023.
#[inline]
fn pow2(k: i32) -> f64 {
    debug_assert!((-1074..=1023).contains(&k));
    if k >= -1022 { f64::from_bits(((k + 1023) as u64) << 52) } else { f64::from_bits(1u64 << (k + 1074)) }
}

impl WindowSum {
    /// The empty sum.
    pub const fn new() -> Self {
        Self { limbs: [0; WINDOW], top: UNPLACED, since_carry: 0, rest: ExactSum::new() }
    }

    /// Whether nothing but zeros was added since the last [`WindowSum::clear`].
    pub fn is_untouched(&self) -> bool {
        self.top == UNPLACED
    }

    /// Adds the finite value `x` exactly (see the module documentation for the range).
    #[inline]
    pub fn add(&mut self, x: f64) {
        debug_assert!(x.is_finite() && x.abs() < pow2(970), "WindowSum::add({x})");
        if x == 0.0 {
            return;
        }
        let bits = x.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i32;
        let fraction = bits & ((1 << 52) - 1);
        // x = ±m·2^(p − 1074): subnormals have p = 0 and no hidden bit.
        let (m, p) = if biased == 0 { (fraction, 0) } else { (fraction | (1 << 52), biased - 1) };
        let low = p >> 5;
        if low + 2 > self.top {
            self.raise(low + 2);
        }
        let bottom = self.top - (WINDOW as i32 - 1);
        if low < bottom {
            self.rest.add(x);
            return;
        }
        let k = (low - bottom) as usize;
        let v = u128::from(m) << (p & 31);
        let chunks = [(v as u64 & LOW_32) as i64, ((v >> 32) as u64 & LOW_32) as i64, (v >> 64) as i64];
        let limbs = &mut self.limbs[k..k + 3];
        if bits >> 63 == 0 {
            for (l, c) in limbs.iter_mut().zip(chunks) {
                *l += c;
            }
        } else {
            for (l, c) in limbs.iter_mut().zip(chunks) {
                *l -= c;
            }
        }
        self.since_carry += 1;
        if self.since_carry >= CARRY_EVERY {
            self.carry();
        }
    }

    /// Moves the window up so that its highest limb is `top`, handing the limbs it leaves behind
    /// to `rest`.
    fn raise(&mut self, top: i32) {
        if self.top == UNPLACED {
            self.top = top;
            return;
        }
        let shift = (top - self.top) as usize;
        let bottom = self.top - (WINDOW as i32 - 1);
        for k in 0..shift.min(WINDOW) {
            spill(&mut self.rest, self.limbs[k], bottom + k as i32);
        }
        if shift < WINDOW {
            self.limbs.copy_within(shift.., 0);
            self.limbs[WINDOW - shift..].fill(0);
        } else {
            self.limbs = [0; WINDOW];
        }
        self.top = top;
    }

    /// Carries every limb into the next, leaving each in [0, 2³²); a carry out of the highest limb
    /// moves the window up by one.
    fn carry(&mut self) {
        for k in 0..WINDOW - 1 {
            let c = self.limbs[k] >> 32;
            self.limbs[k] -= c << 32;
            self.limbs[k + 1] += c;
        }
        let c = self.limbs[WINDOW - 1] >> 32;
        if c != 0 {
            self.limbs[WINDOW - 1] -= c << 32;
            self.raise(self.top + 1);
            self.limbs[WINDOW - 1] = c;
        }
        self.since_carry = 0;
    }

    /// Adds this sum to `target`, exactly.
    pub fn add_to(&self, target: &mut ExactSum) {
        if self.top == UNPLACED {
            return;
        }
        let bottom = self.top - (WINDOW as i32 - 1);
        for (k, &limb) in self.limbs.iter().enumerate() {
            spill(target, limb, bottom + k as i32);
        }
        target.add_sum(&self.rest);
    }

    /// Back to the empty sum, keeping `rest`'s buffer.
    pub fn clear(&mut self) {
        self.limbs = [0; WINDOW];
        self.top = UNPLACED;
        self.since_carry = 0;
        self.rest.clear();
    }
}

/// Adds limb `limb` of global index `index` to `target` exactly: its low and high 32-bit halves
/// are integers below 2³² (in magnitude) times powers of two, so each is an exact double.
#[inline]
fn spill(target: &mut ExactSum, limb: i64, index: i32) {
    if limb == 0 {
        return;
    }
    let scale = 32 * index - 1074;
    let (low, high) = ((limb as u64 & LOW_32) as f64, (limb >> 32) as f64);
    if low != 0.0 {
        target.add(low * pow2(scale));
    }
    if high != 0.0 {
        target.add(high * pow2(scale + 32));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn both(values: &[f64]) -> (ExactSum, ExactSum) {
        let mut exact = ExactSum::new();
        let mut window = WindowSum::new();
        for &v in values {
            exact.add(v);
            window.add(v);
        }
        let mut via = ExactSum::new();
        window.add_to(&mut via);
        (exact, via)
    }

    #[test]
    fn values_across_the_whole_range_sum_exactly() {
        let tiny = f64::from_bits(1); // 2⁻¹⁰⁷⁴, the smallest subnormal
        let values = [1e-3, -3e-300, tiny, 5e250, -5e250, 1e-320, 0.1, 0.2, 0.3, -1e-3, 7.0, 2.5e-310];
        let (exact, via) = both(&values);
        assert_eq!(exact.canonical(), via.canonical());
        // The large values cancel: what remains is the small ones', exactly.
        assert_eq!(via.value(), exact.value());
    }

    #[test]
    fn the_window_moves_up_and_keeps_what_it_leaves() {
        let mut values = vec![1e-200, 3e-150, -2e-100];
        values.extend((0..50).map(|k| 10f64.powi(k - 20)));
        values.extend([-1e29, 4e-100, 1e-12]);
        let (exact, via) = both(&values);
        assert_eq!(exact.canonical(), via.canonical());
    }

    #[test]
    fn carries_keep_the_sum_exact() {
        // Many equal additions push the limbs towards a carry; a smaller limit is tested by
        // carrying by hand every few additions.
        let mut window = WindowSum::new();
        let mut exact = ExactSum::new();
        for k in 0..10_000 {
            let v = (f64::from(k) + 0.5) * 1.000_000_1e7;
            window.add(v);
            exact.add(v);
            if k % 7 == 0 {
                window.carry();
            }
        }
        let mut via = ExactSum::new();
        window.add_to(&mut via);
        assert_eq!(via, exact);
    }

    #[test]
    fn cleared_sums_start_again() {
        let mut w = WindowSum::new();
        w.add(1e300 / 1e10);
        w.add(1e-310);
        w.clear();
        assert!(w.is_untouched());
        w.add(2.0);
        let mut via = ExactSum::new();
        w.add_to(&mut via);
        assert_eq!(via.canonical(), vec![2.0]);
    }

    proptest! {
        /// Any values, of any sign and magnitude in range (subnormals included), sum to the same
        /// canonical form as an [`ExactSum`] — also when the sum is handed over in two parts.
        #[test]
        fn agrees_with_exact_sum(
            raw in prop::collection::vec((any::<bool>(), 0u64..(1 << 52), 0u64..1950), 1..200),
            split in 0usize..200,
        ) {
            let values: Vec<f64> = raw
                .iter()
                .map(|&(neg, frac, exp)| f64::from_bits((u64::from(neg) << 63) | (exp << 52) | frac))
                .collect();
            let (exact, via) = both(&values);
            prop_assert_eq!(exact.canonical(), via.canonical());
            let k = split.min(values.len());
            let (a, _) = both(&values[..k]);
            let mut first = WindowSum::new();
            for &v in &values[k..] {
                first.add(v);
            }
            let mut total = a;
            first.add_to(&mut total);
            prop_assert_eq!(total.canonical(), exact.canonical());
        }
    }
}
