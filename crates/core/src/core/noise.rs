//! Fast complex white Gaussian noise for the signal chains (DTMB, TC-OFDM, GNSS IQ).
//!
//! A signal-level simulation draws two normal variates per sample, 9450 per DTMB frame
//! and 5.2 million per second of a 2.6 Msps GNSS recording;
//! with a cryptographic stream generator and a ziggurat that alone costs about as much as
//! the whole real-time budget. This generator is built to vectorise instead:
//!
//! * **Uniforms** come from a counter-based hash: sample `i` of a block takes
//!   `mix(i ⊕ k₁)` and `mix(i ⊕ k₂)`, where `mix` is the "triple32" integer hash
//!   (C. Wellons, *Prospecting for hash functions*, 2018: three xorshift-multiply rounds,
//!   a bijection with full avalanche) and the 64-bit key `(k₁, k₂)` is drawn afresh from
//!   the caller's named random stream for every block. So the noise is a pure
//!   function of the stream and the block, bit-identical for the same seed, and no
//!   global state exists.
//! * **Gaussians** by the Box–Muller transform: with `u₁ ∈ (0, 1]`, `u₂ ∈ [0, 1)`,
//!   `r = √(−2 ln u₁)`, `w = r (cos 2πu₂ + j sin 2πu₂)` is a complex normal variate with
//!   `E|w|² = 2`. `ln`, `cos` and `sin` are evaluated by short polynomials (relative error
//!   below 2·10⁻⁶, checked against `std` in a test) so the loop has no library calls.
//!   The polynomials' Horner steps and the final `o + r·c` are explicit fused
//!   multiply–adds (`mul_add`, correctly rounded by IEEE 754 whatever computes it), which
//!   removes a third of the loop's floating-point operations and keeps every build's
//!   output the same bits: the AVX2 and AVX-512 builds enable FMA, the portable build
//!   (for CPUs without AVX2 and FMA) gets the same results from the C library's `fmaf`.
//!   `u₁` has 24 bits, so `r ≤ √(2 · 24 ln 2) = 5.77`: the tails are cut at 5.77σ per
//!   component (probability 8·10⁻⁹ per sample).

// The one kind of unsafe code hybridnav has: its AVX2 and AVX-512F builds of the Gaussian noise, `#[target_feature]`
// functions called only after run-time CPU detection, each with a same-bits test against
// the portable code.
#![allow(unsafe_code)]

use num_complex::Complex32;
use rand::Rng;

/// The "triple32" hash: a bijection on 32-bit words with full avalanche.
#[inline(always)]
pub fn mix(mut x: u32) -> u32 {
    x ^= x >> 17;
    x = x.wrapping_mul(0xed5a_d4bb);
    x ^= x >> 11;
    x = x.wrapping_mul(0xac4c_1b51);
    x ^= x >> 15;
    x = x.wrapping_mul(0x3184_8bab);
    x ^= x >> 14;
    x
}

/// Natural logarithm for `x` in (0, 1] (any positive normal float), by exponent
/// extraction and the series `ln m = 2 atanh s`, `s = (m − 1)/(m + 1)`, with the mantissa
/// `m` folded into [1/√2, √2) so `|s| < 0.172` and five odd terms reach 2·10⁻⁷ absolute.
#[inline(always)]
pub(crate) fn fast_ln(x: f32) -> f32 {
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    // Fold the mantissa into [1/√2, √2) without a branch the vectoriser cannot select.
    let big = m > std::f32::consts::SQRT_2;
    m = if big { m * 0.5 } else { m };
    e += i32::from(big);
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let q = s2
        .mul_add(1.0 / 9.0, 1.0 / 7.0)
        .mul_add(s2, 0.2)
        .mul_add(s2, 1.0 / 3.0)
        .mul_add(s2, 1.0);
    (e as f32).mul_add(std::f32::consts::LN_2, (2.0 * s) * q)
}

/// `(cos 2πu, sin 2πu)` for `u` in [0, 1): the turn is split into quadrants and the
/// remainder `φ ∈ [−π/4, π/4)` evaluated by Taylor polynomials (error below 4·10⁻⁷).
#[cfg(test)]
pub(crate) fn fast_cos_sin_turns(u: f32) -> (f32, f32) {
    fast_cos_sin_bits(((u as f64) * 16_777_216.0) as u32 & 0x00ff_ffff)
}

/// `(cos 2πu, sin 2πu)` for the turn `u = v / 2²⁴` given as its 24-bit integer `v`: the
/// quadrant and the remainder come from the integer bits exactly (integer shifts and
/// masks vectorise, a float-to-int conversion with Rust's saturating semantics does not),
/// then [`cos_sin_quadrant`].
#[inline(always)]
fn fast_cos_sin_bits(v: u32) -> (f32, f32) {
    // Shift by half a quadrant so the remainder is centred: t = v + 2²¹.
    let t = v + (1 << 21);
    let quadrant = (t >> 22) & 3;
    let rem = (t & 0x003f_ffff) as i32 - (1 << 21);
    let phi = rem as f32 * (std::f32::consts::FRAC_PI_2 / 4_194_304.0);
    cos_sin_quadrant(phi, quadrant)
}

/// `(cos, sin)` of `φ + quadrant·π/2` for `φ ∈ [−π/4, π/4]` by Taylor polynomials.
#[inline(always)]
fn cos_sin_quadrant(phi: f32, quadrant: u32) -> (f32, f32) {
    let p2 = phi * phi;
    let s = phi
        * p2.mul_add(-1.0 / 5040.0, 1.0 / 120.0)
            .mul_add(p2, -1.0 / 6.0)
            .mul_add(p2, 1.0);
    let c = p2
        .mul_add(1.0 / 40320.0, -1.0 / 720.0)
        .mul_add(p2, 1.0 / 24.0)
        .mul_add(p2, -0.5)
        .mul_add(p2, 1.0);
    // Rotate (c, s) by the quadrant: 0 → (c, s), 1 → (−s, c), 2 → (−c, −s), 3 → (s, −c).
    let (x, y) = if quadrant & 1 == 1 { (-s, c) } else { (c, s) };
    if quadrant & 2 == 2 {
        (-x, -y)
    } else {
        (x, y)
    }
}

/// Adds complex white Gaussian noise of variance `sigma²` per sample (`E|w|² = σ²`) to
/// `out`, keyed by one 64-bit draw from `rng` (see the module documentation).
pub fn add_awgn<R: Rng + ?Sized>(out: &mut [Complex32], sigma: f32, rng: &mut R) {
    if sigma <= 0.0 || out.is_empty() {
        return;
    }
    let key: u64 = rng.random();
    let (k1, k2) = (key as u32, (key >> 32) as u32);
    let sd = sigma * std::f32::consts::FRAC_1_SQRT_2;
    #[cfg(target_arch = "x86_64")]
    {
        let fma = std::arch::is_x86_feature_detected!("fma");
        if fma && std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F and FMA, checked just above.
            unsafe { awgn_avx512(out, sd, k1, k2) };
            return;
        }
        if fma && std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 and FMA, checked just above.
            unsafe { awgn_avx2(out, sd, k1, k2) };
            return;
        }
    }
    awgn_kernel(out, sd, k1, k2);
}

/// [`awgn_kernel`] compiled for AVX2 and FMA (eight lanes, a native 32-bit multiply and
/// the fused multiply–add in one instruction); the arithmetic is element-wise and every
/// fused operation is written out, so the result is bit-identical to the baseline build.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn awgn_avx2(out: &mut [Complex32], sd: f32, k1: u32, k2: u32) {
    awgn_kernel(out, sd, k1, k2);
}

/// [`awgn_kernel`] compiled for AVX-512F and FMA (sixteen lanes); bit-identical for the
/// same reason as the AVX2 build.
///
/// # Safety
/// The CPU must support AVX-512F and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
unsafe fn awgn_avx512(out: &mut [Complex32], sd: f32, k1: u32, k2: u32) {
    awgn_kernel(out, sd, k1, k2);
}

/// The noise loop: sample `i` takes its two uniforms from `mix(i ⊕ k₁)` and `mix(i ⊕ k₂)`.
#[inline(always)]
fn awgn_kernel(out: &mut [Complex32], sd: f32, k1: u32, k2: u32) {
    const INV24: f32 = 1.0 / 16_777_216.0;
    for (i, o) in out.iter_mut().enumerate() {
        let h1 = mix(i as u32 ^ k1);
        let h2 = mix(i as u32 ^ k2);
        // u1 in (0, 1] on a 2⁻²⁴ grid (through i32, which converts in vector registers);
        // u2 = (h2 >> 8)/2²⁴ in [0, 1), used as its integer bits.
        let u1 = ((h1 >> 8) as i32 + 1) as f32 * INV24;
        let r = (-2.0 * fast_ln(u1)).sqrt() * sd;
        let (c, s) = fast_cos_sin_bits(h2 >> 8);
        o.re = r.mul_add(c, o.re);
        o.im = r.mul_add(s, o.im);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    /// The portable, AVX2 and AVX-512 builds of the noise loop give the same bits (the
    /// arithmetic is element-wise and its fused operations are explicit), so the output
    /// does not depend on the machine a run lands on.
    #[test]
    fn every_build_of_the_noise_loop_gives_the_same_bits() {
        let n = 4725 + 13;
        let mut portable = vec![Complex32::new(0.25, -0.5); n];
        awgn_kernel(&mut portable, 0.7, 0x1234_5678, 0x9abc_def0);
        #[cfg(target_arch = "x86_64")]
        {
            type Build = unsafe fn(&mut [Complex32], f32, u32, u32);
            let builds: [(&str, bool, Build); 2] = [
                (
                    "avx2",
                    std::arch::is_x86_feature_detected!("avx2")
                        && std::arch::is_x86_feature_detected!("fma"),
                    awgn_avx2,
                ),
                (
                    "avx512f",
                    std::arch::is_x86_feature_detected!("avx512f")
                        && std::arch::is_x86_feature_detected!("fma"),
                    awgn_avx512,
                ),
            ];
            for (name, supported, build) in builds {
                if !supported {
                    eprintln!("noise build {name}: not supported here, not compared");
                    continue;
                }
                let mut v = vec![Complex32::new(0.25, -0.5); n];
                // SAFETY: the CPU supports the build's features, checked just above.
                unsafe { build(&mut v, 0.7, 0x1234_5678, 0x9abc_def0) };
                assert!(
                    v.len() == portable.len()
                        && v.iter().zip(&portable).all(|(x, y)| {
                            x.re.to_bits() == y.re.to_bits() && x.im.to_bits() == y.im.to_bits()
                        }),
                    "{name}"
                );
            }
        }
    }

    #[test]
    fn polynomials_match_std() {
        let mut worst_ln = 0.0f64;
        for k in 1..=100_000u32 {
            let x = k as f32 / 100_000.0;
            let err = (fast_ln(x) as f64 - (x as f64).ln()).abs();
            worst_ln = worst_ln.max(err);
        }
        assert!(worst_ln < 2e-6, "ln error {worst_ln}");
        let mut worst_trig = 0.0f64;
        for k in 0..100_000u32 {
            let u = k as f32 / 100_000.0;
            let (c, s) = fast_cos_sin_turns(u);
            let a = 2.0 * std::f64::consts::PI * u as f64;
            worst_trig = worst_trig
                .max((c as f64 - a.cos()).abs())
                .max((s as f64 - a.sin()).abs());
        }
        assert!(worst_trig < 2e-6, "trig error {worst_trig}");
    }

    #[test]
    fn noise_is_white_gaussian_with_the_requested_variance() {
        let n = 200_000;
        let mut v = vec![Complex32::default(); n];
        let sigma = 0.7f32;
        add_awgn(&mut v, sigma, &mut TrialRng::new(3, 0).stream("t"));
        let p: f64 = v.iter().map(|x| x.norm_sqr() as f64).sum::<f64>() / n as f64;
        // The sample variance of 2n squared normals has relative σ √(1/n) ≈ 0.0022.
        assert!((p / (sigma as f64).powi(2) - 1.0).abs() < 0.01, "power {p}");
        // Fourth moment of a real normal component: 3σ⁴ (kurtosis of a Gaussian).
        let s2 = (sigma as f64).powi(2) / 2.0;
        let m4: f64 = v.iter().map(|x| (x.re as f64).powi(4)).sum::<f64>() / n as f64;
        assert!((m4 / (3.0 * s2 * s2) - 1.0).abs() < 0.05, "kurtosis {m4}");
        // Lag-1 correlation and I/Q correlation vanish (σ of each estimate ≈ 1/√n).
        let lag1: f64 = v
            .windows(2)
            .map(|w| (w[0] * w[1].conj()).re as f64)
            .sum::<f64>()
            / (n as f64 * (sigma as f64).powi(2));
        let iq: f64 = v.iter().map(|x| (x.re * x.im) as f64).sum::<f64>() / (n as f64 * s2);
        assert!(lag1.abs() < 0.01 && iq.abs() < 0.01, "{lag1} {iq}");
        // The fraction beyond 2σ per component matches the normal law (4.55 %).
        let beyond = v
            .iter()
            .filter(|x| (x.re as f64).abs() > 2.0 * s2.sqrt())
            .count() as f64
            / n as f64;
        assert!((beyond - 0.0455).abs() < 0.002, "tail {beyond}");
        // A different stream gives different noise; the same stream the same noise.
        let mut w = vec![Complex32::default(); 16];
        let mut w2 = vec![Complex32::default(); 16];
        add_awgn(&mut w, 1.0, &mut TrialRng::new(3, 0).stream("t"));
        add_awgn(&mut w2, 1.0, &mut TrialRng::new(3, 0).stream("t"));
        assert_eq!(w, w2);
        assert_ne!(&w[..], &v[..16]);
    }
}
