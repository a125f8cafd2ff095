//! Elementary functions for the light-path and camera-path loops that the compiler can vectorise.
//!
//! The hot loops evaluate sines, cosines and (for the camera paths' lobe) a logarithm for every
//! path; `libm`'s are out-of-line calls with branches on the argument, which stop a loop from being
//! turned into SIMD code. What is here
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

// Single-precision minimax polynomials on |x| ≤ π/4 (Cephes' sinf and cosf, S. Moshier): their
// approximation error is below 2⁻²⁶ (tested against `libm` in f64 arithmetic below).
const SF1: f32 = -1.666_665_5e-1;
const SF2: f32 = 8.332_161e-3;
const SF3: f32 = -1.951_529_6e-4;
const CF1: f32 = 4.166_664_6e-2;
const CF2: f32 = -1.388_731_6e-3;
const CF3: f32 = 2.443_315_7e-5;

/// Bound on the error of [`sincos_turn_f32`]: each result is within 2⁻²¹ of the exact
/// sin/cos(2πk/2³²).
pub const SINCOS_TURN_F32_ERROR: f64 = 1.0 / (1u64 << 21) as f64;

/// `(sin, cos)` of the angle 2π·k/2³² in single precision, for every `k: u32`, with an error of at
/// most [`SINCOS_TURN_F32_ERROR`] = 2⁻²¹ = 8·2⁻²⁴ (for the conservative single-precision filters
/// of the light-path loop, which need a bound, not the last bit; eight lanes to a 256-bit vector).
///
/// The reduction is [`sincos_turn`]'s in 32-bit integers: kk = k + 2²⁹ (mod 2³²), the quadrant in
/// bits 30 and 31 of kk, and m = (kk mod 2³⁰) − 2²⁹ ∈ [−2²⁹, 2²⁹), so x = m·(2π/2³²) has |x| ≤ π/4.
/// Proof of the bound: m → f32, the f32 value of 2π/2³² and the product each have a relative
/// error ≤ 2⁻²⁴, so |x − x_exact| ≤ 3·2⁻²⁴·π/4 < 2.4·2⁻²⁴, which moves sin and cos (slopes ≤ 1) as
/// much; the polynomials approximate sin and cos on |x| ≤ π/4 within 2⁻²⁶ = 0.25·2⁻²⁴ (tested);
/// their Horner evaluation with fused multiply-adds adds less than 1.7·2⁻²⁴: the last fused
/// multiply-add rounds a value ≤ 1 (≤ 2⁻²⁴), and the term it adds to x or 1, of magnitude ≤ 0.31
/// (x²/2 at π/4), carries relative errors of about 2·2⁻²⁴ (z = x² and the inner Horner steps). The
/// total, < 4.4·2⁻²⁴, is within 2⁻²¹ = 8·2⁻²⁴ with room (tested on the whole domain). The quadrant
/// only swaps and negates. Exactly rounded operations only, so every build gives the same bits.
#[inline(always)]
pub fn sincos_turn_f32(k: u32) -> (f32, f32) {
    const ANGLE_PER_STEP: f32 = (TAU / (1u64 << 32) as f64) as f32;
    const SIGN: u32 = 1 << 31;
    let kk = k.wrapping_add(1 << 29);
    let m = (kk & ((1 << 30) - 1)) as i32 - (1 << 29);
    let x = m as f32 * ANGLE_PER_STEP;
    let z = x * x;
    let s = (z * x).mul_add(z.mul_add(z.mul_add(SF3, SF2), SF1), x);
    let c = z.mul_add(z.mul_add(z.mul_add(z.mul_add(CF3, CF2), CF1), -0.5), 1.0);
    // Odd quadrants swap sine and cosine (bit 30 of kk); the sine is negative in quadrants 2 and
    // 3 (bit 31 of kk), the cosine in 1 and 2 (bit 31 of kk + 2³⁰): selects and sign flips.
    let (sin, cos) = if kk & (1 << 30) != 0 { (c, s) } else { (s, c) };
    let sin_sign = kk & SIGN;
    let cos_sign = kk.wrapping_add(1 << 30) & SIGN;
    (f32::from_bits(sin.to_bits() ^ sin_sign), f32::from_bits(cos.to_bits() ^ cos_sign))
}

/// 1.5·2⁵²: adding it to a double of magnitude < 2⁵¹ rounds that double to an integer j and leaves
/// 2⁵¹ + j (two's complement in the low bits) in the mantissa; subtracting it again gives j as a
/// double. The vectorisable round-to-integer and integer → double conversion of this module.
const ROUNDER: f64 = 1.5 * (1u64 << 52) as f64;

/// π/2 as the nearest double and the rest (π/2 − PIO2_HI, rounded): Cody–Waite reduction.
const PIO2_HI: f64 = f64::from_bits(0x3FF9_21FB_5444_2D18); // 1.5707963267948966
const PIO2_LO: f64 = f64::from_bits(0x3C91_A626_3314_5C07); // 6.123233995736766e-17
const FRAC_2_PI: f64 = std::f64::consts::FRAC_2_PI;

/// `(sin x, cos x)` for |x| ≤ 2²⁰ (the camera paths need ϑ ≤ 8.57·45° < 7).
///
/// Reduction: n = round(x·2/π) by the `ROUNDER` trick, r = x − n·π/2 in two fused steps (the
/// first, x − n·PIO2_HI, is exact up to one rounding of the small result; the second adds
/// −n·PIO2_LO), so |r| ≤ π/4 + 2⁻⁴⁰ and r is within a few 10⁻¹⁷ (relative to max(|r|, |n|·10⁻³²))
/// of its exact value; then the fdlibm kernels and the quadrant n mod 4 as in [`sincos_turn`].
/// Error bound (tested against `libm` on [−100, 100] and densely on [0, 8]): within 2 ulps of
/// `libm::sin`/`libm::cos`, or 2⁻⁵⁷ absolute.
#[inline(always)]
pub fn sincos(x: f64) -> (f64, f64) {
    const SIGN: u64 = 1 << 63;
    let shifted = x.mul_add(FRAC_2_PI, ROUNDER);
    let n = shifted - ROUNDER;
    let q = shifted.to_bits();
    let r = (-n).mul_add(PIO2_LO, (-n).mul_add(PIO2_HI, x));
    let z = r * r;
    let (s, c) = (kernel_sin(r, z), kernel_cos(z));
    // Quadrant q = n mod 4: odd quadrants swap sine and cosine; the sine is negative in quadrants
    // 2 and 3, the cosine in 1 and 2. Selects and sign-bit flips, so loops stay branch-free.
    let (sin, cos) = if q & 1 != 0 { (c, s) } else { (s, c) };
    let sin_sign = (q << 62) & SIGN;
    let cos_sign = ((q + 1) << 62) & SIGN;
    (f64::from_bits(sin.to_bits() ^ sin_sign), f64::from_bits(cos.to_bits() ^ cos_sign))
}

// fdlibm's e_log.c (Sun, 1993), as in musl before 2018: on the reduced range,
// |log(1 + f) − (2s + s·R(s²))| ≤ 2⁻⁵⁸·⁴⁵ with s = f/(2 + f). Coefficients by their bits.
const LG1: f64 = f64::from_bits(0x3FE5_5555_5555_5593); // 6.666666666666735130e-01
const LG2: f64 = f64::from_bits(0x3FD9_9999_9997_FA04); // 3.999999999940941908e-01
const LG3: f64 = f64::from_bits(0x3FD2_4924_9422_9359); // 2.857142874366239149e-01
const LG4: f64 = f64::from_bits(0x3FCC_71C5_1D8E_78AF); // 2.222219843214978396e-01
const LG5: f64 = f64::from_bits(0x3FC7_4664_96CB_03DE); // 1.818357216161805012e-01
const LG6: f64 = f64::from_bits(0x3FC3_9A09_D078_C69F); // 1.531383769920937332e-01
const LG7: f64 = f64::from_bits(0x3FC2_F112_DF3E_5244); // 1.479819860511658591e-01
const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000); // 6.93147180369123816490e-01
const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76); // 1.90821492927058770002e-10

/// ln x for a positive, normal, finite x (what the lobe sampler takes the logarithm of: a
/// uniform in (0, 1]); anything else gives an unspecified value.
///
/// fdlibm's algorithm without its branches for special inputs: x = 2ᵏ·(1 + f) with 1 + f in
/// [√2/2, √2) (integer operations on the bits), ln x = k·ln 2 + f − f²/2 + s·(f²/2 + R(s²)), with
/// ln 2 split so that k·LN2_HI is exact. Error bound (tested): within one ulp of `libm::log` on
/// (0, 1] and beyond.
#[inline(always)]
pub fn ln(x: f64) -> f64 {
    let ix = x.to_bits();
    // Adding 1 − √2/2's worth to the high word carries into the exponent exactly when the
    // mantissa is ≥ √2/2·2, so k and 1 + f come out in range without a comparison.
    let hx = (ix >> 32) + (0x3ff0_0000 - 0x3fe6_a09e);
    let k = (hx >> 20).wrapping_sub(0x3ff);
    let m = f64::from_bits((((hx & 0x000f_ffff) + 0x3fe6_a09e) << 32) | (ix & 0xffff_ffff));
    // k as a double without a conversion instruction (k ≥ −1075, far below 2⁵¹ in magnitude).
    let dk = f64::from_bits(ROUNDER.to_bits().wrapping_add(k)) - ROUNDER;
    let f = m - 1.0;
    let hfsq = 0.5 * f * f;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * w.mul_add(w.mul_add(LG6, LG4), LG2);
    let t2 = z * w.mul_add(w.mul_add(w.mul_add(LG7, LG5), LG3), LG1);
    let r = t2 + t1;
    s.mul_add(hfsq + r, dk * LN2_LO) - hfsq + f + dk * LN2_HI
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
        // Wrapping: the last few strides pass u32::MAX and come round to small inputs (a debug
        // build would panic on the overflow).
        let stride = (0..=u32::MAX / 1021).map(|i| (i * 1021).wrapping_add(i % 1019));
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

    /// The single-precision sine and cosine of a turn fraction stay within their stated bound of
    /// the exact values (within 3·10⁻¹⁶ of [`sincos_turn`]'s), on the whole u32 domain (a stride
    /// and every octant edge), with room to spare; the axes are exact.
    #[test]
    fn sincos_turn_f32_is_within_its_bound() {
        let mut worst: f64 = 0.0;
        for k in inputs() {
            let (s, c) = sincos_turn_f32(k);
            let (rs, rc) = sincos_turn(k);
            worst = worst.max((f64::from(s) - rs).abs()).max((f64::from(c) - rc).abs());
        }
        assert!(worst + 3e-16 <= SINCOS_TURN_F32_ERROR / 4.0, "worst error {worst:e}");
        assert_eq!(sincos_turn_f32(0), (0.0, 1.0));
        assert_eq!(sincos_turn_f32(1 << 30), (1.0, 0.0));
        assert_eq!(sincos_turn_f32(1 << 31), (0.0, -1.0));
        assert_eq!(sincos_turn_f32(3 << 30), (-1.0, 0.0));
    }

    /// The polynomials of [`sincos_turn_f32`], evaluated in f64 (so without the f32 rounding),
    /// approximate sin and cos within 2⁻²⁶ on [−π/4, π/4], as its proof assumes: a dense grid (the
    /// error curves are smooth polynomials minus sin/cos, whose extrema the grid resolves).
    #[test]
    fn sincos_turn_f32_polynomials_are_within_2_pow_m26() {
        let (s1, s2, s3) = (f64::from(SF1), f64::from(SF2), f64::from(SF3));
        let (c1, c2, c3) = (f64::from(CF1), f64::from(CF2), f64::from(CF3));
        let mut worst: f64 = 0.0;
        let n = 1_000_000;
        for i in -n..=n {
            let x = std::f64::consts::FRAC_PI_4 * f64::from(i) / f64::from(n);
            let z = x * x;
            let s = x + x * z * (s1 + z * (s2 + z * s3));
            let c = 1.0 + z * (-0.5 + z * (c1 + z * (c2 + z * c3)));
            worst = worst.max((s - libm::sin(x)).abs()).max((c - libm::cos(x)).abs());
        }
        assert!(worst <= 2f64.powi(-26), "approximation error {worst:e}");
    }

    #[test]
    fn ln_is_within_one_ulp_of_libm() {
        use rand::Rng;
        let mut rng = crate::sim::math::rng::stream(9, 9, 9);
        let (mut n, mut exact) = (0usize, 0usize);
        let mut check = |x: f64| {
            let (a, b) = (ln(x), libm::log(x));
            let e = if a == b { 0 } else { a.to_bits().abs_diff(b.to_bits()) };
            assert!(e <= 1 && a.is_sign_negative() == b.is_sign_negative() || a == b, "ln({x:e}) = {a:e} vs {b:e}");
            exact += usize::from(e == 0);
            n += 1;
        };
        for _ in 0..2_000_000 {
            // Uniforms as the samplers draw them, and their full range of exponents.
            let u = 1.0 - crate::sim::math::rng::unit52(rng.next_u64());
            check(u);
            check(u * 2f64.powi(-((rng.next_u64() % 900) as i32)));
            check(1.0 + u * 1e-6);
            check(u * 1e300);
        }
        for x in [
            1.0,
            2.0,
            0.5,
            f64::MIN_POSITIVE,
            f64::MAX,
            2f64.powi(-52),
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::SQRT_2,
        ] {
            check(x);
        }
        assert_eq!(ln(1.0), 0.0);
        assert!(exact > n * 9 / 10, "mostly bit-identical ({exact} of {n})");
    }

    #[test]
    fn sincos_is_within_two_ulps_of_libm() {
        use rand::Rng;
        let mut rng = crate::sim::math::rng::stream(8, 8, 8);
        let check = |x: f64| {
            let (s, c) = sincos(x);
            let (ls, lc) = libm::sincos(x);
            let close = |a: f64, b: f64| (a - b).abs() <= 2f64.powi(-57) || ulps(a, b) <= 2;
            assert!(close(s, ls) && close(c, lc), "x = {x}: ({s}, {c}) vs libm ({ls}, {lc})");
        };
        for _ in 0..2_000_000 {
            let u = crate::sim::math::rng::unit52(rng.next_u64());
            check(8.0 * u);
            check(200.0 * u - 100.0);
            check(1e-3 * u);
        }
        for q in -64..64 {
            // Around multiples of π/4, where the quadrant changes or the reduction cancels.
            let x = f64::from(q) * std::f64::consts::FRAC_PI_4;
            for d in -4i64..=4 {
                // Neighbouring doubles of the same sign (below +0 the bits would wrap to a NaN).
                let y = f64::from_bits(x.to_bits().wrapping_add_signed(d));
                if y.is_finite() {
                    check(y);
                }
            }
        }
        assert_eq!(sincos(0.0), (0.0, 1.0));
    }
}
