//! Elementary functions for the light-path loop that the compiler can vectorise.
//!
//! The hot loop evaluates a sine and a cosine for every light path; `libm`'s are out-of-line calls
//! with branches on the argument, which stop a loop from being turned into SIMD code. What is here
//! is branch-free straight-line arithmetic (polynomials, integer bit operations and selects), to be
//! inlined into such loops. Each function states its error bound, and a test checks it against
//! `libm` over the function's whole input domain. Results never depend on the instruction set:
//! only correctly rounded IEEE operations are used — including fused multiply-adds, written out as
//! `mul_add`, which are one exactly rounded operation everywhere (an FMA instruction where the CPU
//! has one, else a software `fma`) — so SIMD and scalar code give the same bits.

use std::f64::consts::TAU;

// The minimax polynomials of fdlibm (Sun, 1993), as in musl and the `libm` crate: on |x| ≤ π/4,
// |sin x/x − (1 + S1x² + … + S6x¹²)| ≤ 2⁻⁵⁸ and |cos x − (1 − x²/2 + C1x⁴ + … + C6x¹⁴)| ≤ 2⁻⁵⁸.
// Evaluated here by Horner's rule with fused multiply-adds: half the instructions of fdlibm's
// evaluation (which trades instructions for shorter dependency chains, while the light-path loop
// is bound by instruction throughput), and the results stay within one ulp (tested below). The
// coefficients are given by their bits, as in fdlibm.
const S1: f64 = f64::from_bits(0xBFC5_5555_5555_5549); // -0.16666666666666632
const S2: f64 = f64::from_bits(0x3F81_1111_1110_F8A6); // 0.00833333333332249
const S3: f64 = f64::from_bits(0xBF2A_01A0_19C1_61D5); // -0.0001984126982985795
const S4: f64 = f64::from_bits(0x3EC7_1DE3_57B1_FE7D); // 2.7557313707070068e-06
const S5: f64 = f64::from_bits(0xBE5A_E5E6_8A2B_9CEB); // -2.5050760253406863e-08
const S6: f64 = f64::from_bits(0x3DE5_D93A_5ACF_D57C); // 1.58969099521155e-10
const C1: f64 = f64::from_bits(0x3FA5_5555_5555_554C); // 0.0416666666666666
const C2: f64 = f64::from_bits(0xBF56_C16C_16C1_5177); // -0.001388888888887411
const C3: f64 = f64::from_bits(0x3EFA_01A0_19CB_1590); // 2.480158728947673e-05
const C4: f64 = f64::from_bits(0xBE92_7E4F_809C_52AD); // -2.7557314351390663e-07
const C5: f64 = f64::from_bits(0x3E21_EE9E_BDB4_B1C4); // 2.087572321298175e-09
const C6: f64 = f64::from_bits(0xBDA8_FAE9_BE88_38D4); // -1.1359647557788195e-11

/// sin x for |x| ≤ π/4, given z = x²: fdlibm's `__kernel_sin` polynomial, x + x³(S1 + … + S6x¹⁰).
#[inline(always)]
fn kernel_sin(x: f64, z: f64) -> f64 {
    let p = z.mul_add(z.mul_add(z.mul_add(z.mul_add(z.mul_add(S6, S5), S4), S3), S2), S1);
    (z * x).mul_add(p, x)
}

/// cos x for |x| ≤ π/4, given z = x²: fdlibm's `__kernel_cos` polynomial, 1 − x²/2 + C1x⁴ + … +
/// C6x¹⁴, with the constant term added last so that it is rounded once.
#[inline(always)]
fn kernel_cos(z: f64) -> f64 {
    let p = z.mul_add(z.mul_add(z.mul_add(z.mul_add(z.mul_add(C6, C5), C4), C3), C2), C1);
    z.mul_add(z.mul_add(p, -0.5), 1.0)
}

/// `(sin, cos)` of the angle 2π·k/2³², for every `k: u32` (k is a fraction of a turn).
///
/// The reduction to the nearest quarter turn is exact integer arithmetic: k = q·2³⁰ + m with
/// |m| ≤ 2²⁹, so the kernel's argument x = m·(2π/2³²) satisfies |x| ≤ π/4 and is within
/// 1.2·10⁻¹⁶ of its exact value (one rounding of the product and the 4·10⁻¹⁷ relative error of the
/// f64 2π). The kernels add less than one ulp, and the quadrant only swaps and negates.
///
/// Error bound (tested): each result is within 3·10⁻¹⁶ of the exact sin/cos(2πk/2³²), and within
/// one ulp of `libm::sin`/`libm::cos` of the reduced argument with the quadrant applied.
#[inline(always)]
pub fn sincos_turn(k: u32) -> (f64, f64) {
    const ANGLE_PER_STEP: f64 = TAU / (1u64 << 32) as f64;
    // 1.5·2⁵²: adding an integer j < 2⁵¹ to its bit pattern gives the double 1.5·2⁵² + j.
    const ROUNDER: f64 = 1.5 * (1u64 << 52) as f64;
    const SIGN: u64 = 1 << 63;
    // Everything in 64-bit lanes, the width of the doubles, so that SIMD code needs no packing:
    // kk = k + 2²⁹ = q·2³⁰ + (m + 2²⁹), with q the nearest quarter turn (bits 30 and 31 of kk give
    // q mod 4) and m + 2²⁹ ∈ [0, 2³⁰).
    let kk = u64::from(k) + (1 << 29);
    let m = f64::from_bits(ROUNDER.to_bits() | (kk & ((1 << 30) - 1))) - (ROUNDER + (1u64 << 29) as f64);
    let x = m * ANGLE_PER_STEP;
    let z = x * x;
    let (s, c) = (kernel_sin(x, z), kernel_cos(z));
    // Quadrant q adds q·π/2: odd quadrants swap sine and cosine (bit 30 of kk, tested as the sign
    // of kk << 33, which is what a SIMD blend reads); the sine is negative in quadrants 2 and 3
    // (bit 31 of kk), the cosine in 1 and 2 (bit 31 of kk + 2³⁰). Selects and sign-bit flips, so
    // loops stay branch-free.
    let swap = ((kk << 33) as i64) < 0;
    let (sin, cos) = if swap { (c, s) } else { (s, c) };
    let sin_sign = (kk << 32) & SIGN;
    let cos_sign = ((kk + (1 << 30)) << 32) & SIGN;
    (f64::from_bits(sin.to_bits() ^ sin_sign), f64::from_bits(cos.to_bits() ^ cos_sign))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reduced argument and quadrant, as `sincos_turn` computes them (the reference side of
    /// the tests recomputes them independently from k with wide integers).
    fn reduce(k: u32) -> (u32, f64) {
        let k = i64::from(k);
        let q = ((k + (1 << 29)) >> 30) & 3;
        let mut m = k - (q << 30);
        if m >= 1 << 31 {
            m -= 1 << 32;
        }
        assert!(m.abs() <= 1 << 29);
        (q as u32, m as f64 * (TAU / 4_294_967_296.0))
    }

    /// libm's sin and cos of the reduced argument, moved to quadrant q.
    fn libm_turn(k: u32) -> (f64, f64) {
        let (q, x) = reduce(k);
        let (s, c) = (libm::sin(x), libm::cos(x));
        match q {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }

    /// Inputs covering the whole u32 domain: a stride through all of it, every quadrant and octant
    /// boundary with its neighbours, and the extremes.
    fn inputs() -> impl Iterator<Item = u32> {
        let stride = (0..=u32::MAX / 1021).map(|i| i * 1021 + (i % 1019));
        let edges = (0..16u32).flat_map(|e| (0..9u32).map(move |d| (e << 28).wrapping_add(d).wrapping_sub(4)));
        stride.chain(edges).chain([0, 1, u32::MAX, u32::MAX - 1, 1 << 31])
    }

    /// Distance in units in the last place (of the larger magnitude; signs must agree).
    fn ulps(a: f64, b: f64) -> u64 {
        if a == b {
            return 0;
        }
        assert_eq!(a.is_sign_negative(), b.is_sign_negative(), "{a} vs {b}");
        a.abs().to_bits().abs_diff(b.abs().to_bits())
    }

    #[test]
    fn sincos_turn_is_within_one_ulp_of_libm_on_the_reduced_argument() {
        let (mut n, mut worst, mut exact) = (0, 0, 0);
        for k in inputs() {
            let (s, c) = sincos_turn(k);
            let (ls, lc) = libm_turn(k);
            let e = ulps(s, ls).max(ulps(c, lc));
            assert!(e <= 1, "k = {k}: ({s}, {c}) vs libm ({ls}, {lc})");
            worst = worst.max(e);
            exact += usize::from(e == 0);
            n += 1;
        }
        assert!(n > 4_000_000);
        assert!(exact > n * 9 / 10, "mostly bit-identical ({exact} of {n}, worst {worst} ulp)");
    }

    /// Against the exact angle: the reference is libm at 2πk/2³² corrected to first order for the
    /// rounding of that argument (computed exactly with a fused multiply-add), so its own error is
    /// about one ulp (≤ 1.2·10⁻¹⁶ for values ≤ 1); the bound 3·10⁻¹⁶ then leaves room for it.
    #[test]
    fn sincos_turn_is_within_3e_16_of_the_exact_angle() {
        let mut worst: f64 = 0.0;
        for k in inputs() {
            // 2πk/2³² = a + e exactly up to 2π's own 2.4·10⁻¹⁶ (TAU_LO), with a = fl(k·2π/2³²).
            const TAU_LO: f64 = 2.449_293_598_294_706_4e-16;
            let t = f64::from(k) / 4_294_967_296.0;
            let a = TAU * t;
            let e = TAU.mul_add(t, -a) + TAU_LO * t;
            let (ls, lc) = libm::sincos(a);
            let (rs, rc) = (ls + lc * e, lc - ls * e);
            let (s, c) = sincos_turn(k);
            worst = worst.max((s - rs).abs()).max((c - rc).abs());
        }
        assert!(worst <= 3e-16, "worst absolute error {worst:e}");
    }

    #[test]
    fn sincos_turn_hits_the_axes_exactly() {
        assert_eq!(sincos_turn(0), (0.0, 1.0));
        assert_eq!(sincos_turn(1 << 30), (1.0, 0.0));
        assert_eq!(sincos_turn(1 << 31), (0.0, -1.0));
        assert_eq!(sincos_turn(3 << 30), (-1.0, 0.0));
        for k in inputs().step_by(97) {
            let (s, c) = sincos_turn(k);
            assert!((s * s + c * c - 1.0).abs() < 5e-16);
        }
    }
}
