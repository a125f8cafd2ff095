//! Random streams: one portable generator per (job seed, iteration, stream).
//!
//! Determinism is a contract of optimis: iteration `s` of a job draws only from streams that depend
//! on `(seed, s, stream)`, where `stream` is the light-path chunk index or [`CAMERA_STREAM`]. No
//! stream depends on the thread that runs it or on what ran before, so an iteration gives the same
//! bits on 1 or 8 threads and after any number of interruptions.
//!
//! The generator is xoshiro256++ (Blackman & Vigna), named and portable (not `StdRng`, whose
//! algorithm may change between rand versions). Its 256-bit state is derived from the triple by
//! SplitMix64, the seeding recommended by the xoshiro authors; the derivation is pinned by a
//! value-stability test, and any change to it must bump [`GENERATOR_ID`], which is part of every
//! configuration fingerprint.
//!
//! The light-path loop draws its bulk uniforms from [`LaneRng`]: [`LANES`] xoshiro256++ generators
//! stepped side by side, so that a block of draws costs about one instruction per output word
//! with AVX2 (where the portable code does one generator step at a time). Lane k is the chunk's
//! stream advanced by k + 1 jumps of 2¹²⁸ steps (the authors' recipe for non-overlapping parallel
//! subsequences); the chunk's stream itself, unjumped, stays scalar for the rare draws of
//! individual paths. [`unit52`] turns a word into a uniform without a conversion instruction.

use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The generator type of every stream.
pub type StreamRng = Xoshiro256PlusPlus;

/// Stream index of the camera paths of an iteration (light-path chunks use 0, 1, 2, …).
pub const CAMERA_STREAM: u64 = u64::MAX;

/// Names the generator, the stream derivation and the chunking; part of the fingerprint, so moments
/// drawn by a different scheme never merge.
///
/// v2: light paths draw their starts and directions from a [`LaneRng`] (8 jumped lanes) in polar
/// form, and their lobe deflections from the unjumped stream.
/// v3: camera paths take three words each of the camera stream, in path order: the direction in
/// polar form (sin² θ and the azimuth) and the lobe's u and azimuth, evaluated with the
/// vectorisable logarithm, sine and cosine of [`super::fastmath`].
pub const GENERATOR_ID: &str = "xoshiro256++/splitmix64(seed,iteration,stream)/chunk65536/v3";

/// SplitMix64 output function (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// The stream for `(seed, iteration, stream)`.
///
/// The triple is folded into one 64-bit key by chained SplitMix64 mixing (each step is a bijection
/// of the running key xor the next word, so distinct triples collide only by a 64-bit accident);
/// the key then seeds a SplitMix64 sequence whose first four outputs form the xoshiro state.
pub fn stream(seed: u64, iteration: u64, stream: u64) -> StreamRng {
    let mut bytes = [0u8; 32];
    for (bytes, word) in bytes.chunks_exact_mut(8).zip(stream_state(seed, iteration, stream)) {
        bytes.copy_from_slice(&word.to_le_bytes());
    }
    StreamRng::from_seed(bytes)
}

/// The xoshiro256++ state words of [`stream`]`(seed, iteration, stream)` (its seed bytes are these
/// words in little-endian order).
fn stream_state(seed: u64, iteration: u64, stream: u64) -> [u64; 4] {
    let mut key = mix64(seed ^ 0x6f70_7469_6d69_7321); // "optimis!"
    key = mix64(key ^ iteration.wrapping_mul(GOLDEN_GAMMA));
    key = mix64(key ^ stream.wrapping_mul(0xd1b5_4a32_d192_ed03));
    let mut state = key;
    [(); 4].map(|()| {
        state = state.wrapping_add(GOLDEN_GAMMA);
        mix64(state)
    })
}

/// One xoshiro256++ step (Blackman & Vigna's reference code): returns the output, advances `s`.
#[inline(always)]
fn xoshiro_step(s: &mut [u64; 4]) -> u64 {
    let out = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
    let t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = s[3].rotate_left(45);
    out
}

/// Advances `s` by 2¹²⁸ steps (the reference `jump`).
fn xoshiro_jump(s: &mut [u64; 4]) {
    const JUMP: [u64; 4] = [0x180e_c6d3_3cfd_0aba, 0xd5a6_1266_f0c9_392c, 0xa958_2618_e03f_c9aa, 0x39ab_dc45_29b1_661c];
    let mut acc = [0u64; 4];
    for word in JUMP {
        for bit in 0..64 {
            if word >> bit & 1 != 0 {
                for (a, x) in acc.iter_mut().zip(s.iter()) {
                    *a ^= x;
                }
            }
            xoshiro_step(s);
        }
    }
    *s = acc;
}

/// Lanes of a [`LaneRng`]: two 256-bit vectors of state words with AVX2, enough independent
/// work per step to hide the latency of each operation.
pub const LANES: usize = 8;

/// [`LANES`] independent xoshiro256++ generators stepped together, state as structure of arrays.
#[derive(Debug, Clone)]
pub struct LaneRng {
    /// `s[w][k]`: state word w of lane k.
    s: [[u64; LANES]; 4],
}

impl LaneRng {
    /// The lanes for `(seed, iteration, stream)`: lane k is [`stream`]`(seed, iteration, stream)`
    /// jumped k + 1 times, so the lanes and the unjumped stream are 2¹²⁸-step-apart, disjoint
    /// segments of one xoshiro256++ sequence.
    pub fn new(seed: u64, iteration: u64, stream: u64) -> Self {
        let mut state = stream_state(seed, iteration, stream);
        let lanes: [[u64; 4]; LANES] = std::array::from_fn(|_| {
            xoshiro_jump(&mut state);
            state
        });
        Self { s: std::array::from_fn(|w| std::array::from_fn(|k| lanes[k][w])) }
    }

    /// Fills `out` with the next `out.len() / LANES` outputs of every lane, interleaved: `out[j·LANES
    /// + k]` is output j of lane k. `out.len()` must be a multiple of [`LANES`].
    ///
    /// Portable code; [`LaneRng::fill_avx2`] gives the same outputs with AVX2.
    #[inline(always)]
    pub fn fill(&mut self, out: &mut [u64]) {
        let (rows, rest) = out.as_chunks_mut::<LANES>();
        assert!(rest.is_empty(), "LaneRng::fill needs a multiple of {LANES} outputs");
        let [s0, s1, s2, s3] = &mut self.s;
        for row in rows {
            for (k, out) in row.iter_mut().enumerate() {
                let mut s = [s0[k], s1[k], s2[k], s3[k]];
                *out = xoshiro_step(&mut s);
                [s0[k], s1[k], s2[k], s3[k]] = s;
            }
        }
    }

    /// [`LaneRng::fill`] with AVX2 instructions: each state word of the 8 lanes is two 256-bit
    /// vectors. (Written with intrinsics because LLVM's cost model keeps 64-bit rotations scalar,
    /// which splits every step between vector and scalar registers.) Integer operations only, so
    /// the outputs are exactly those of `fill`.
    ///
    /// Not inlined: the state lives in eight vector registers during the fill, and a caller's own
    /// vector code would otherwise keep it in registers across its loops too, or spill it there.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2 (`is_x86_feature_detected!("avx2")`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    pub fn fill_avx2(&mut self, out: &mut [u64]) {
        use std::arch::x86_64::{
            __m256i, _mm256_add_epi64, _mm256_loadu_si256, _mm256_or_si256, _mm256_slli_epi64, _mm256_srli_epi64,
            _mm256_storeu_si256, _mm256_xor_si256,
        };
        const _: () = assert!(LANES == 8, "two vectors of four lanes");
        let (rows, rest) = out.as_chunks_mut::<LANES>();
        assert!(rest.is_empty(), "LaneRng::fill needs a multiple of {LANES} outputs");
        // `halves[h][w]`: state word w of lanes 4h..4h + 4.
        // SAFETY: every load and store is of 4 u64 at offset 0 or 4 of an array of 8 (unaligned
        // access is what loadu/storeu are for).
        let mut halves: [[__m256i; 4]; 2] =
            std::array::from_fn(|h| self.s.map(|w| unsafe { _mm256_loadu_si256(w.as_ptr().add(4 * h).cast()) }));
        for row in rows {
            for (h, [s0, s1, s2, s3]) in halves.iter_mut().enumerate() {
                let sum = _mm256_add_epi64(*s0, *s3);
                let rot = _mm256_or_si256(_mm256_slli_epi64::<23>(sum), _mm256_srli_epi64::<41>(sum));
                // SAFETY: as above.
                unsafe { _mm256_storeu_si256(row.as_mut_ptr().add(4 * h).cast(), _mm256_add_epi64(rot, *s0)) };
                let t = _mm256_slli_epi64::<17>(*s1);
                *s2 = _mm256_xor_si256(*s2, *s0);
                *s3 = _mm256_xor_si256(*s3, *s1);
                *s1 = _mm256_xor_si256(*s1, *s2);
                *s0 = _mm256_xor_si256(*s0, *s3);
                *s2 = _mm256_xor_si256(*s2, t);
                *s3 = _mm256_or_si256(_mm256_slli_epi64::<45>(*s3), _mm256_srli_epi64::<19>(*s3));
            }
        }
        for (h, half) in halves.iter().enumerate() {
            for (word, v) in self.s.iter_mut().zip(half) {
                // SAFETY: as above.
                unsafe { _mm256_storeu_si256(word.as_mut_ptr().add(4 * h).cast(), *v) };
            }
        }
    }
}

/// A uniform in [0, 1) with 52 random bits (the top 52 of `bits`), by filling the mantissa of a
/// number in [1, 2): integer operations and one subtraction, which vectorise (x86-64 has no
/// vector u64 → f64 conversion before AVX-512).
#[inline(always)]
pub fn unit52(bits: u64) -> f64 {
    f64::from_bits(0x3ff0_0000_0000_0000 | (bits >> 12)) - 1.0
}

/// 2⁻⁵³: the spacing of the uniforms below.
const TWO_POW_M53: f64 = 1.0 / (1u64 << 53) as f64;

/// A uniform in [0, 1) with 53 random bits.
#[inline(always)]
pub fn uniform(rng: &mut StreamRng) -> f64 {
    (rng.next_u64() >> 11) as f64 * TWO_POW_M53
}

/// A uniform in (0, 1] with 53 random bits: safe to take the logarithm of.
///
/// Its smallest value is 2⁻⁵³, which bounds every inverse-CDF tail drawn from it (see
/// [`crate::sim::model::scene::LOBE_MAX_SIGMAS`]).
#[inline(always)]
pub fn uniform_open0(rng: &mut StreamRng) -> f64 {
    ((rng.next_u64() >> 11) + 1) as f64 * TWO_POW_M53
}

/// Two independent uniforms in [-1, 1) from one 64-bit draw (32 bits each).
///
/// Used for rejection sampling of discs, where 32 bits (a spacing of 4.7·10⁻¹⁰) are far finer than
/// any length or angle of the model, and halve the generator calls on the hot path.
#[inline(always)]
pub fn symmetric_pair(rng: &mut StreamRng) -> (f64, f64) {
    const TWO_POW_M31: f64 = 1.0 / (1u64 << 31) as f64;
    let bits = rng.next_u64();
    let a = (bits >> 32) as f64 * TWO_POW_M31 - 1.0;
    let b = (bits & 0xffff_ffff) as f64 * TWO_POW_M31 - 1.0;
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pins the stream derivation: if this changes, GENERATOR_ID must change too, because old
    /// moments would no longer be reproducible.
    #[test]
    fn value_stability() {
        let mut rng = stream(1, 0, CAMERA_STREAM);
        let first: Vec<u64> = (0..3).map(|_| rng.next_u64()).collect();
        let mut again = stream(1, 0, CAMERA_STREAM);
        let second: Vec<u64> = (0..3).map(|_| again.next_u64()).collect();
        assert_eq!(first, second);
        assert_eq!(
            first,
            vec![1_253_137_843_998_676_952, 9_077_043_681_107_605_159, 12_130_764_643_244_232_868],
            "stream derivation changed: bump GENERATOR_ID"
        );
    }

    /// The hand-written step and jump are the reference xoshiro256++ (as in rand_xoshiro), and lane
    /// k of a [`LaneRng`] is the stream jumped k + 1 times.
    #[test]
    fn lanes_are_jumped_copies_of_the_stream() {
        let mut state = stream_state(4, 5, 6);
        let mut reference = stream(4, 5, 6);
        for _ in 0..5 {
            assert_eq!(xoshiro_step(&mut state), reference.next_u64());
        }
        let mut lanes = LaneRng::new(4, 5, 6);
        let mut out = [0u64; 3 * LANES];
        lanes.fill(&mut out);
        let mut jumped = stream(4, 5, 6);
        for k in 0..LANES {
            jumped.jump();
            let mut lane = jumped.clone();
            for j in 0..3 {
                assert_eq!(out[j * LANES + k], lane.next_u64(), "lane {k}, output {j}");
            }
        }
        lanes.fill(&mut out[..LANES]);
        let mut lane0 = stream(4, 5, 6);
        lane0.jump();
        for _ in 0..3 {
            lane0.next_u64();
        }
        assert_eq!(out[0], lane0.next_u64(), "fill continues the lanes");
    }

    /// The AVX2 fill continues the same sequences as the portable one.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_fill_matches_the_portable_fill() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let (mut a, mut b) = (LaneRng::new(1, 2, 3), LaneRng::new(1, 2, 3));
        let (mut out_a, mut out_b) = ([0u64; 5 * LANES], [0u64; 5 * LANES]);
        for _ in 0..3 {
            a.fill(&mut out_a);
            // SAFETY: the CPU has AVX2 (checked above).
            unsafe { b.fill_avx2(&mut out_b) };
            assert_eq!(out_a, out_b);
        }
    }

    #[test]
    fn unit52_spans_the_unit_interval() {
        assert_eq!(unit52(0), 0.0);
        assert_eq!(unit52(u64::MAX), 1.0 - 2f64.powi(-52));
        assert_eq!(unit52(1 << 63), 0.5);
        assert_eq!(unit52(0xfff), 0.0, "the low 12 bits are dropped");
    }

    #[test]
    fn neighbouring_streams_differ() {
        let draws = |s: u64, c: u64| stream(7, s, c).next_u64();
        let values = [draws(0, 0), draws(0, 1), draws(1, 0), draws(1, 1), stream(8, 0, 0).next_u64()];
        for i in 0..values.len() {
            for j in 0..i {
                assert_ne!(values[i], values[j]);
            }
        }
    }

    #[test]
    fn uniforms_stay_in_range() {
        let mut rng = stream(3, 4, 5);
        for _ in 0..10_000 {
            let u = uniform(&mut rng);
            assert!((0.0..1.0).contains(&u));
            let v = uniform_open0(&mut rng);
            assert!(v > 0.0 && v <= 1.0);
            let (a, b) = symmetric_pair(&mut rng);
            assert!((-1.0..1.0).contains(&a) && (-1.0..1.0).contains(&b));
        }
    }
}
