//! Exact, order-independent sums of `f64` values.
//!
//! Floating-point addition is not associative, so `(a + b) + c` and `a + (b + c)` can differ in the
//! last bit. Moments must be bit-identical whether a job ran `[0, M)` at once, or `[0, k)` and
//! `[k, M)` merged, or shards from several machines merged in any order (see rayon issue #663 on
//! why float reductions must be ordered). An [`ExactSum`] therefore keeps the *exact* real sum of
//! everything added, as a Shewchuk expansion: a short list of non-overlapping doubles of increasing
//! magnitude whose real sum is the exact sum (J. R. Shewchuk, "Adaptive precision floating-point
//! arithmetic", 1997; the same algorithm as Python's `math.fsum`). Adding a value or another sum is
//! exact, so any order and grouping gives the same real number.
//!
//! The expansion itself is not unique, so comparison and serialisation go through the
//! [canonical form](ExactSum::canonical): c₁ = round(S), c₂ = round(S − c₁), …, which is unique for
//! a given exact sum S. Reading the value gives c₁, the correctly rounded sum.
//!
//! # Sums read from outside
//!
//! A document may hold any list of parts, so parsing is where hostile input is stopped: at most
//! [`MAX_PARTS`] parts (a canonical form never needs more), each finite, and an exact total whose
//! magnitude stays below [`MAX_MAGNITUDE`]. Finite parts can have an infinite sum
//! (`[1.8e308, 1.8e308]`): the expansion arithmetic then overflows, and before these checks the
//! canonical form of such a sum looped forever. Two sums below `MAX_MAGNITUDE` add without overflow
//! (see [`ExactSum::can_add`]), which is how merges check before they change anything.

use serde::de::{self, Error as _};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Most parts of a canonical form, and so of any sum a document may hold.
///
/// Each canonical part is the rounded remainder of the one before, so |c_{k+1}| ≤ ulp(c_k)/2 and
/// its binary exponent is at least 53 below c_k's. Exponents run from 1023 down to −1074 (the
/// subnormals, where the remainder below ulp/2 = 2⁻¹⁰⁷⁵ is exactly zero as every part is a
/// multiple of 2⁻¹⁰⁷⁴): at most ⌊2097/53⌋ + 1 = 40 parts.
pub const MAX_PARTS: usize = 40;

/// Largest magnitude (2¹⁰⁰⁰ ≈ 1.07·10³⁰¹) of a sum read from outside. Real statistics are
/// hundreds of orders of magnitude smaller; the margin below f64::MAX lets two such sums be added
/// without overflow.
pub const MAX_MAGNITUDE: f64 = f64::from_bits((1023 + 1000) << 52);

/// Largest part magnitude (2¹⁰¹⁵) for which [`ExactSum::can_add`] guarantees an exact addition.
const MERGE_PART_LIMIT: f64 = f64::from_bits((1023 + 1015) << 52);

/// Why a list of parts is not an acceptable sum.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SumError {
    /// More than [`MAX_PARTS`] parts (a canonical sum never needs more).
    #[error("a sum has more than {MAX_PARTS} parts (a canonical sum never needs more)")]
    TooManyParts,
    /// A part is infinite or NaN.
    #[error("a sum part is not finite")]
    NotFinite,
    /// A part, or the sum, exceeds [`MAX_MAGNITUDE`] (2¹⁰⁰⁰) in magnitude.
    #[error("a sum exceeds 2^1000 in magnitude (its parts overflow when added)")]
    TooLarge,
}

/// The exact sum of the finite `f64` values added to it.
#[derive(Clone, Debug, Default)]
pub struct ExactSum {
    /// Non-overlapping partial sums in increasing magnitude; their real sum is the exact total.
    parts: Vec<f64>,
}

impl ExactSum {
    /// The empty sum (zero).
    pub const fn new() -> Self {
        Self { parts: Vec::new() }
    }

    /// Adds `x` exactly.
    ///
    /// `x` must be finite; a non-finite value is a bug of the caller (every tallied quantity is a
    /// product of finite factors), so it is rejected in debug builds and poisons the sum otherwise.
    pub fn add(&mut self, mut x: f64) {
        debug_assert!(x.is_finite(), "ExactSum::add({x})");
        if x == 0.0 {
            return;
        }
        // Shewchuk's GROW-EXPANSION with zero elimination: TwoSum x into every part.
        let mut kept = 0;
        for j in 0..self.parts.len() {
            let mut y = self.parts[j];
            if x.abs() < y.abs() {
                std::mem::swap(&mut x, &mut y);
            }
            let hi = x + y;
            let lo = y - (hi - x);
            if lo != 0.0 {
                self.parts[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        self.parts.truncate(kept);
        if x != 0.0 {
            self.parts.push(x);
        }
    }

    /// Back to zero, keeping the buffer (the runner's accumulators reuse theirs).
    pub fn clear(&mut self) {
        self.parts.clear();
    }

    /// Adds another exact sum, exactly.
    pub fn add_sum(&mut self, other: &ExactSum) {
        for &p in &other.parts {
            self.add(p);
        }
    }

    /// The correctly rounded (round-half-even) value of the exact sum.
    pub fn value(&self) -> f64 {
        // The final step of Python's fsum: sum from the top until the rounding is exact, then
        // correct a half-way case using the sign of the remaining parts.
        let p = &self.parts;
        let mut n = p.len();
        if n == 0 {
            return 0.0;
        }
        n -= 1;
        let mut hi = p[n];
        let mut lo = 0.0;
        while n > 0 {
            let x = hi;
            n -= 1;
            let y = p[n];
            hi = x + y;
            let yr = hi - x;
            lo = y - yr;
            if lo != 0.0 {
                break;
            }
        }
        if n > 0 && ((lo < 0.0 && p[n - 1] < 0.0) || (lo > 0.0 && p[n - 1] > 0.0)) {
            let y = lo * 2.0;
            let x = hi + y;
            let yr = x - hi;
            if y == yr {
                hi = x;
            }
        }
        hi
    }

    /// The unique representation of the exact sum S: c₁ = round(S), c₂ = round(S − c₁), … until
    /// the remainder is zero. Empty for a zero sum.
    ///
    /// Bounded: at most [`MAX_PARTS`] steps for a finite sum (see there). A sum whose expansion
    /// overflowed (only possible when it was not checked with [`ExactSum::is_finite`]) gives its
    /// non-finite value alone instead of looping.
    pub fn canonical(&self) -> Vec<f64> {
        if !self.is_finite() {
            return vec![self.value()];
        }
        let mut rest = self.clone();
        let mut out = Vec::with_capacity(self.parts.len().min(MAX_PARTS));
        for _ in 0..MAX_PARTS {
            let c = rest.value();
            if c == 0.0 {
                return out;
            }
            out.push(c);
            rest.add(-c);
        }
        debug_assert_eq!(rest.value(), 0.0, "a finite sum has at most {MAX_PARTS} canonical parts");
        out
    }

    /// Whether every part and the rounded value are finite (false once an addition overflowed).
    pub fn is_finite(&self) -> bool {
        self.parts.iter().all(|p| p.is_finite()) && self.value().is_finite()
    }

    /// Whether adding `self` and `other` is certainly exact and free of overflow: the largest part
    /// of each is finite and at most 2¹⁰¹⁵ in magnitude. One comparison per sum, for the merges of
    /// every batch.
    ///
    /// [`ExactSum::add`] keeps the parts in increasing magnitude, non-overlapping, so the last is
    /// the largest and the others sum to less than it: every intermediate value of the addition is
    /// below 2·2·2¹⁰¹⁵ = 2¹⁰¹⁷ ≪ f64::MAX. An addition that overflowed leaves its infinite or NaN
    /// result as the last part, so a poisoned sum fails the test too. (Sums read from outside are
    /// far below: |S| ≤ 2¹⁰⁰⁰.)
    pub fn can_add(&self, other: &ExactSum) -> bool {
        // NaN fails the comparison, as it must.
        let small = |s: &ExactSum| s.parts.last().is_none_or(|p| p.abs() <= MERGE_PART_LIMIT);
        small(self) && small(other)
    }

    /// Finite, with a magnitude of at most [`MAX_MAGNITUDE`].
    pub fn is_bounded(&self) -> bool {
        self.is_finite() && self.value().abs() <= MAX_MAGNITUDE
    }

    /// Rebuilds a sum from a list of parts read from outside (for example a canonical form):
    /// at most [`MAX_PARTS`] finite parts whose exact sum is below [`MAX_MAGNITUDE`].
    pub fn from_parts(parts: &[f64]) -> Result<Self, SumError> {
        if parts.len() > MAX_PARTS {
            return Err(SumError::TooManyParts);
        }
        let mut sum = Self::new();
        for &p in parts {
            if !p.is_finite() {
                return Err(SumError::NotFinite);
            }
            if p.abs() > MAX_MAGNITUDE {
                return Err(SumError::TooLarge);
            }
            sum.add(p);
        }
        // Each part is below 2¹⁰⁰⁰, so at most 40 of them cannot overflow the expansion; only the
        // total can exceed the bound.
        if !sum.is_bounded() {
            return Err(SumError::TooLarge);
        }
        Ok(sum)
    }
}

impl PartialEq for ExactSum {
    fn eq(&self, other: &Self) -> bool {
        // Same exact real sum ⇔ the difference is exactly zero.
        let mut diff = self.clone();
        for &p in &other.parts {
            diff.add(-p);
        }
        diff.parts.is_empty()
    }
}

impl Eq for ExactSum {}

/// Serialised as the canonical form: a plain number when one double holds the sum exactly (the
/// usual case), else the list `[c₁, c₂, …]`.
impl Serialize for ExactSum {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let canonical = self.canonical();
        match canonical.as_slice() {
            [] => serializer.serialize_f64(0.0),
            [single] => serializer.serialize_f64(*single),
            parts => parts.serialize(serializer),
        }
    }
}

/// Read as a number or a list of at most [`MAX_PARTS`] numbers, without buffering: a visitor
/// (not an untagged enum, which would first copy the whole list into serde's generic `Content`)
/// that stops at the first part too many.
impl<'de> Deserialize<'de> for ExactSum {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct SumVisitor;

        impl<'de> de::Visitor<'de> for SumVisitor {
            type Value = ExactSum;

            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "a number or a list of at most {MAX_PARTS} numbers")
            }

            fn visit_f64<E: de::Error>(self, x: f64) -> Result<ExactSum, E> {
                ExactSum::from_parts(&[x]).map_err(E::custom)
            }

            // Integers are accepted where a double holds them exactly (this module writes floats,
            // but people write `0`); anything else would be silently rounded.
            fn visit_u64<E: de::Error>(self, x: u64) -> Result<ExactSum, E> {
                let y = x as f64;
                if y >= 18_446_744_073_709_551_616.0 || y as u64 != x {
                    return Err(E::custom(format!("{x} is not exactly a double; write it as a float")));
                }
                self.visit_f64(y)
            }

            fn visit_i64<E: de::Error>(self, x: i64) -> Result<ExactSum, E> {
                let y = x as f64;
                if y >= 9_223_372_036_854_775_808.0 || y as i64 != x {
                    return Err(E::custom(format!("{x} is not exactly a double; write it as a float")));
                }
                self.visit_f64(y)
            }

            fn visit_seq<A: de::SeqAccess<'de>>(self, mut seq: A) -> Result<ExactSum, A::Error> {
                let mut parts = [0.0; MAX_PARTS];
                let mut n = 0;
                while let Some(x) = seq.next_element::<f64>()? {
                    if n == MAX_PARTS {
                        return Err(A::Error::custom(SumError::TooManyParts));
                    }
                    parts[n] = x;
                    n += 1;
                }
                ExactSum::from_parts(&parts[..n]).map_err(A::Error::custom)
            }
        }

        deserializer.deserialize_any(SumVisitor)
    }
}

/// OpenAPI schema: a number, or the list of its canonical parts.
#[cfg(feature = "server")]
mod schema {
    use utoipa::openapi::RefOr;
    use utoipa::openapi::schema::{ArrayBuilder, ObjectBuilder, OneOfBuilder, Schema, Type};

    impl utoipa::PartialSchema for super::ExactSum {
        fn schema() -> RefOr<Schema> {
            let number = || ObjectBuilder::new().schema_type(Type::Number);
            OneOfBuilder::new()
                .item(number())
                .item(ArrayBuilder::new().items(number()).min_items(Some(2)))
                .description(Some("An exact sum: its value, or the canonical parts c1, c2, … whose real sum it is"))
                .into()
        }
    }

    impl utoipa::ToSchema for super::ExactSum {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sum_of(values: &[f64]) -> ExactSum {
        let mut s = ExactSum::new();
        for &v in values {
            s.add(v);
        }
        s
    }

    #[test]
    fn catastrophic_cancellation_is_exact() {
        let s = sum_of(&[1e100, 1.0, -1e100, 1e-100]);
        assert_eq!(s.value(), 1.0);
        assert_eq!(s.canonical(), vec![1.0, 1e-100]);
    }

    #[test]
    fn naive_summation_differs_but_exact_does_not() {
        let values = [0.1, 0.2, 0.3, 1e16, -1e16, 0.7];
        let forward: f64 = values.iter().sum();
        let backward: f64 = values.iter().rev().sum();
        assert_ne!(forward, backward, "the example must show non-associativity");
        let mut reversed = values;
        reversed.reverse();
        assert_eq!(sum_of(&values), sum_of(&reversed));
        assert_eq!(sum_of(&values).canonical(), sum_of(&reversed).canonical());
    }

    #[test]
    fn half_way_rounds_to_even() {
        // 1 + 2⁻⁵³ lies half-way between 1 and the next double; ties go to even (1.0), but any
        // extra positive bit below must push it up.
        let tie = sum_of(&[1.0, 2f64.powi(-53)]);
        assert_eq!(tie.value(), 1.0);
        let above = sum_of(&[1.0, 2f64.powi(-53), 2f64.powi(-80)]);
        assert_eq!(above.value(), 1.0 + f64::EPSILON);
    }

    #[test]
    fn serde_round_trip_keeps_the_exact_value() {
        let s = sum_of(&[1.0, 1e-30, 3e-60]);
        let json = serde_json::to_string(&s).unwrap();
        let back: ExactSum = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
        assert_eq!(serde_json::to_string(&sum_of(&[2.5])).unwrap(), "2.5");
    }

    /// Finite parts with an infinite sum once made `canonical` loop forever; they are refused at
    /// parse time, and `canonical` is bounded even for a sum that overflowed.
    #[test]
    fn poisoned_sums_are_refused_and_canonical_is_bounded() {
        let max = f64::MAX;
        assert_eq!(ExactSum::from_parts(&[max, max]).unwrap_err(), SumError::TooLarge);
        assert_eq!(ExactSum::from_parts(&[1e301, 1e301]).unwrap_err(), SumError::TooLarge);
        assert_eq!(ExactSum::from_parts(&[1.0; MAX_PARTS + 1]).unwrap_err(), SumError::TooManyParts);
        assert!(ExactSum::from_parts(&[1.0; MAX_PARTS]).is_ok());
        for text in [
            "[1.7976931348623157e308, 1.7976931348623157e308]",
            "[1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300]",
            "1e400",
            "null",
            "[1, \"2\"]",
            "18446744073709551615",
        ] {
            assert!(serde_json::from_str::<ExactSum>(text).is_err(), "{text} must be refused");
        }
        let many = format!("[{}]", vec!["1e-300"; MAX_PARTS + 1].join(","));
        let e = serde_json::from_str::<ExactSum>(&many).unwrap_err().to_string();
        assert!(e.contains("more than 40 parts"), "{e}");
        // An overflowed expansion (only reachable by adding unchecked values) has a bounded,
        // non-finite canonical form instead of a loop.
        let mut overflowed = ExactSum::new();
        overflowed.add(max);
        overflowed.add(max);
        assert!(!overflowed.is_finite() && !overflowed.can_add(&ExactSum::new()));
        let c = overflowed.canonical();
        assert!(c.len() == 1 && !c[0].is_finite(), "{c:?}");
    }

    /// One of the widest sums: a part every 54 binary orders of magnitude from 2¹⁰⁰⁰ down to the
    /// subnormals (each below half an ulp of the one before, so they are their own canonical form).
    /// Its 39 parts are within the bound, and it reads back.
    #[test]
    fn the_widest_canonical_form_reads_back() {
        // 2^e built from its bits: `powi` rounds its way down to the subnormals differently in a
        // debug build (2^-1052 came out 0).
        let pow2 = |e: i32| {
            if e >= -1022 { f64::from_bits(((e + 1023) as u64) << 52) } else { f64::from_bits(1 << (e + 1074)) }
        };
        let parts: Vec<f64> = (0..39).map(|k| pow2(1000 - 54 * k)).rev().collect();
        assert!(parts.iter().all(|p| *p > 0.0));
        let sum = ExactSum::from_parts(&parts).unwrap();
        let mut canonical = sum.canonical();
        canonical.reverse();
        assert_eq!(canonical, parts);
        let back: ExactSum = serde_json::from_str(&serde_json::to_string(&sum).unwrap()).unwrap();
        assert_eq!(back, sum);
    }

    #[test]
    fn sums_below_the_bound_add_without_overflow() {
        let big = ExactSum::from_parts(&[MAX_MAGNITUDE]).unwrap();
        assert!(big.can_add(&big));
        let mut twice = big.clone();
        twice.add_sum(&big);
        assert!(twice.is_finite() && twice.value() == 2.0 * MAX_MAGNITUDE);
        assert!(ExactSum::from_parts(&[MAX_MAGNITUDE * 2.0]).is_err());
    }

    proptest! {
        /// Any order and any grouping gives the same canonical sum, and its value is the
        /// correctly rounded sum (checked against i128 arithmetic on integer-valued doubles).
        #[test]
        fn order_and_grouping_do_not_matter(
            values in prop::collection::vec(-1e12f64..1e12, 1..40),
            split in 0usize..40,
            seed in any::<u64>(),
        ) {
            let values: Vec<f64> = values.iter().map(|v| v.round()).collect();
            let mut shuffled = values.clone();
            // A deterministic shuffle driven by the seed.
            let mut state = seed;
            for i in (1..shuffled.len()).rev() {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                shuffled.swap(i, (state >> 33) as usize % (i + 1));
            }
            let k = split.min(values.len());
            let mut grouped = sum_of(&shuffled[..k]);
            grouped.add_sum(&sum_of(&shuffled[k..]));
            let whole = sum_of(&values);
            prop_assert_eq!(&grouped, &whole);
            prop_assert_eq!(grouped.canonical(), whole.canonical());
            let exact: i128 = values.iter().map(|&v| v as i128).sum();
            prop_assert_eq!(whole.value(), exact as f64);
        }
    }
}
