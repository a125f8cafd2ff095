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

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

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
    pub fn canonical(&self) -> Vec<f64> {
        let mut rest = self.clone();
        let mut out = Vec::with_capacity(self.parts.len());
        loop {
            let c = rest.value();
            if c == 0.0 {
                return out;
            }
            out.push(c);
            rest.add(-c);
        }
    }

    /// Rebuilds a sum from any list of finite parts (for example a canonical form).
    pub fn from_parts(parts: &[f64]) -> Option<Self> {
        let mut sum = Self::new();
        for &p in parts {
            if !p.is_finite() {
                return None;
            }
            sum.add(p);
        }
        Some(sum)
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

impl<'de> Deserialize<'de> for ExactSum {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            One(f64),
            Many(Vec<f64>),
        }
        let parts = match Repr::deserialize(deserializer)? {
            Repr::One(x) => vec![x],
            Repr::Many(v) => v,
        };
        ExactSum::from_parts(&parts).ok_or_else(|| D::Error::custom("a sum part is not finite"))
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
