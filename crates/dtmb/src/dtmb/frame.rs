//! The DTMB frame body: system information, data constellations, the C = 3780 frequency
//! interleaver and the 3780-point IDFT (GB 20600-2006 §4.4–4.6).
//!
//! A body is 3780 symbols: 36 system-information symbols followed by 3744 data symbols
//! (forward error correction is not modelled: the data bits are a random payload, which
//! is what a ranging receiver sees). For C = 3780 the 3780-symbol block goes through the
//! frequency interleaver and the body is its unitary inverse DFT,
//!
//! ```text
//! x[n] = (1/√N) Σ_{k=0}^{N−1} X[k] e^{+j2πkn/N},   N = 3780,
//! ```
//!
//! so the time-domain body has the same unit mean power as the symbols (the subcarrier
//! spacing is 7.56 MHz / 3780 = 2 kHz). For C = 1 the symbols are sent directly.
//!
//! The interleaver (facts.md §1, from the `dtmb-sdr` receiver, not cross-checked against
//! the standard's text) maps the logical index `i·1260 + j·420 + k·140 + l·70 + m·35 +
//! n·7 + o` to the physical subcarrier `o·540 + n·108 + m·54 + l·27 + k·9 + j·3 + i` with
//! `i, j, k ∈ 0..=2`, `l, m ∈ 0..=1`, `n ∈ 0..=4`, `o ∈ 0..=6`: a mixed-radix digit
//! reversal, hence a permutation (tested).

// The one kind of unsafe code hybridnav has: its AVX2 and AVX-512 builds of the subcarrier fill, `#[target_feature]`
// functions called only after run-time CPU detection, each with a same-bits test against
// the portable code.
#![allow(unsafe_code)]

use super::pn::BODY_LEN;
use super::DtmbError;
use crate::core::noise::mix;
use num_complex::Complex32;
use rand::Rng;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// System-information symbols at the start of each body.
pub const SI_LEN: usize = 36;
/// Data symbols in each body.
pub const DATA_LEN: usize = BODY_LEN - SI_LEN;

/// Carrier mode of the frame body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CarrierMode {
    /// C = 3780: multi-carrier (TDS-OFDM), 2 kHz subcarriers.
    Multi3780,
    /// C = 1: single-carrier, symbols sent directly.
    Single,
}

/// Data constellation (square Gray-mapped QAM, unit mean power).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Qam {
    /// 4QAM (QPSK).
    Qam4,
    /// 16QAM.
    Qam16,
    /// 64QAM.
    Qam64,
}

impl Qam {
    /// Bits carried per symbol.
    pub fn bits_per_symbol(self) -> u32 {
        match self {
            Qam::Qam4 => 2,
            Qam::Qam16 => 4,
            Qam::Qam64 => 6,
        }
    }

    /// The amplitude of level 1: `1/√(2(M−1)/3)`, which gives unit mean power.
    pub fn level_scale(self) -> f32 {
        let m = (1u32 << self.bits_per_symbol()) as f64;
        (1.0 / (2.0 * (m - 1.0) / 3.0).sqrt()) as f32
    }

    /// Maps the low `bits_per_symbol` bits of `bits` to a constellation point: the upper
    /// half of the bits Gray-selects the I level, the lower half the Q level; levels are
    /// `±1, ±3, …` scaled by `1/√(2(M−1)/3)` for unit mean power.
    pub fn map(self, bits: u32) -> Complex32 {
        let half = self.bits_per_symbol() / 2;
        let mask = (1u32 << half) - 1;
        let levels = 1u32 << half;
        let scale = self.level_scale();
        let pam = |g: u32| {
            // Gray → binary, then binary index → odd level.
            let mut b = g;
            let mut s = g >> 1;
            while s != 0 {
                b ^= s;
                s >>= 1;
            }
            (2 * b as i32 - (levels as i32 - 1)) as f32 * scale
        };
        Complex32::new(pam((bits >> half) & mask), pam(bits & mask))
    }
}

/// Physical subcarrier of logical index `logical` (< 3780) in the C = 3780 interleaver.
pub fn interleave_index(logical: usize) -> usize {
    let o = logical % 7;
    let n = (logical / 7) % 5;
    let m = (logical / 35) % 2;
    let l = (logical / 70) % 2;
    let k = (logical / 140) % 3;
    let j = (logical / 420) % 3;
    let i = (logical / 1260) % 3;
    o * 540 + n * 108 + m * 54 + l * 27 + k * 9 + j * 3 + i
}

/// The 36 system-information symbols: 4 carrier-mode bits (1111 for C = 3780, 0000 for
/// C = 1) then the 32-bit vector, most significant bit first, each bit mapped
/// `0 → +(1+j)/√2`, `1 → −(1+j)/√2` (unit power, like the data).
pub fn system_info_symbols(carrier: CarrierMode, vector: u32, out: &mut [Complex32; SI_LEN]) {
    let mode_bit = u8::from(carrier == CarrierMode::Multi3780);
    let a = std::f32::consts::FRAC_1_SQRT_2;
    for (idx, o) in out.iter_mut().enumerate() {
        let bit = if idx < 4 {
            mode_bit
        } else {
            ((vector >> (31 - (idx - 4))) & 1) as u8
        };
        let v = if bit == 0 { a } else { -a };
        *o = Complex32::new(v, v);
    }
}

/// The unitary transform's scale `1/√3780`.
fn idft_scale() -> f32 {
    1.0 / (BODY_LEN as f32).sqrt()
}

/// Fills every subcarrier of a C = 3780 body with a uniform random point of `qam` times
/// `1/√N` (see [`BodyModulator::modulate`]) and its constellation bits, choosing at run
/// time a build for the widest vector unit the CPU has. The arithmetic is integer hashing
/// and element-wise f32 products, so every build gives the same bits.
fn fill_subcarriers(physical: &mut [Complex32], bits: &mut [u8], qam: Qam, key: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F, checked just above.
            unsafe { fill_subcarriers_avx512(physical, bits, qam, key) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe { fill_subcarriers_avx2(physical, bits, qam, key) };
            return;
        }
    }
    fill_subcarriers_kernel(physical, bits, qam, key);
}

/// [`fill_subcarriers_kernel`] compiled for AVX2 (a native 32-bit vector multiply).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fill_subcarriers_avx2(physical: &mut [Complex32], bits: &mut [u8], qam: Qam, key: u32) {
    fill_subcarriers_kernel(physical, bits, qam, key);
}

/// [`fill_subcarriers_kernel`] compiled for AVX-512F.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn fill_subcarriers_avx512(physical: &mut [Complex32], bits: &mut [u8], qam: Qam, key: u32) {
    fill_subcarriers_kernel(physical, bits, qam, key);
}

/// Subcarrier `i` takes the top bits of the counter hash `mix(i ⊕ key)` as its I and Q
/// level indices; its constellation bits are their Gray codes, so `Qam::map` of them is
/// the same point.
#[inline(always)]
fn fill_subcarriers_kernel(physical: &mut [Complex32], bits: &mut [u8], qam: Qam, key: u32) {
    let bps = qam.bits_per_symbol();
    let half = bps / 2;
    let levels = 1u32 << half;
    let amp = qam.level_scale();
    let s = idft_scale();
    let offset = (levels - 1) as i32;
    for (i, (x, b)) in physical.iter_mut().zip(bits.iter_mut()).enumerate() {
        let v = mix(i as u32 ^ key) >> (32 - bps);
        let (vi, vq) = (v >> half, v & (levels - 1));
        let level = |u: u32| (2 * u as i32 - offset) as f32 * amp * s;
        *x = Complex32::new(level(vi), level(vq));
        *b = (((vi ^ (vi >> 1)) << half) | (vq ^ (vq >> 1))) as u8;
    }
}

/// Builds frame bodies with planned transforms and reusable buffers.
pub struct BodyModulator {
    ifft: Arc<dyn Fft<f32>>,
    fft: Arc<dyn Fft<f32>>,
    scratch: Vec<Complex32>,
    logical: Vec<Complex32>,
    /// Whether `logical` holds the last body's symbols (a C = 3780 body is drawn in
    /// physical order and de-interleaved only when [`BodyModulator::symbols`] asks).
    logical_current: bool,
    /// The interleaved (physical-order) symbols of the body being built, times `1/√N`.
    physical: Vec<Complex32>,
    /// The constellation index of each physical subcarrier of the last C = 3780 body.
    physical_bits: Vec<u8>,
    /// The constellation and system information of the last body.
    last: (Qam, [Complex32; SI_LEN]),
    table: Vec<u16>,
    /// Constellation lookup tables (4, 16, 64 points), so mapping costs one load.
    qam_lut: [Vec<Complex32>; 3],
}

impl std::fmt::Debug for BodyModulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BodyModulator").finish_non_exhaustive()
    }
}

impl Default for BodyModulator {
    fn default() -> Self {
        Self::new()
    }
}

impl BodyModulator {
    /// Plans the 3780-point transforms once.
    pub fn new() -> Self {
        let mut planner = FftPlanner::<f32>::new();
        let ifft = planner.plan_fft_inverse(BODY_LEN);
        let fft = planner.plan_fft_forward(BODY_LEN);
        let scratch_len = ifft
            .get_inplace_scratch_len()
            .max(ifft.get_outofplace_scratch_len())
            .max(fft.get_inplace_scratch_len());
        Self {
            ifft,
            fft,
            scratch: vec![Complex32::default(); scratch_len],
            logical: vec![Complex32::default(); BODY_LEN],
            logical_current: true,
            physical_bits: vec![0; BODY_LEN],
            last: (Qam::Qam4, [Complex32::default(); SI_LEN]),
            physical: vec![Complex32::default(); BODY_LEN],
            table: (0..BODY_LEN).map(|i| interleave_index(i) as u16).collect(),
            qam_lut: [Qam::Qam4, Qam::Qam16, Qam::Qam64]
                .map(|q| (0..1u32 << q.bits_per_symbol()).map(|b| q.map(b)).collect()),
        }
    }

    /// Writes one body into `out` (length 3780): system information with `si_vector`, then
    /// 3744 random data symbols drawn from `rng`, interleaved and inverse-transformed for
    /// C = 3780 (where the symbols are drawn in subcarrier order, which gives the logical
    /// sequence the same i.i.d. uniform law). The logical (pre-interleaver) symbols are
    /// in `self.symbols()`.
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] when `out` is not 3780 samples long.
    pub fn modulate<R: Rng + ?Sized>(
        &mut self,
        carrier: CarrierMode,
        qam: Qam,
        si_vector: u32,
        rng: &mut R,
        out: &mut [Complex32],
    ) -> Result<(), DtmbError> {
        if out.len() != BODY_LEN {
            return Err(DtmbError::BufferLength {
                what: "frame body",
                expected: BODY_LEN,
                got: out.len(),
            });
        }
        let mut si = [Complex32::default(); SI_LEN];
        system_info_symbols(carrier, si_vector, &mut si);
        match carrier {
            CarrierMode::Single => {
                // One 64-bit draw serves several symbols: ten 6-bit, sixteen 4-bit or
                // thirty-two 2-bit symbols, which keeps the random stream cheap.
                let bps = qam.bits_per_symbol();
                let mask = (1u64 << bps) - 1;
                let per_word = (64 / bps) as usize;
                self.logical[..SI_LEN].copy_from_slice(&si);
                let lut = &self.qam_lut[(bps / 2 - 1) as usize];
                for chunk in self.logical[SI_LEN..].chunks_mut(per_word) {
                    let mut w = rng.next_u64();
                    for s in chunk {
                        *s = lut[(w & mask) as usize];
                        w >>= bps;
                    }
                }
                self.logical_current = true;
                out.copy_from_slice(&self.logical);
            }
            CarrierMode::Multi3780 => {
                // The data symbols are independent and uniform, so drawing them in
                // physical (subcarrier) order gives the logical sequence the same law as
                // drawing it in logical order and interleaving, without the scattered
                // writes: fill every subcarrier sequentially, then put the system
                // information on its 36 interleaved positions. Subcarrier `i` takes the
                // top bits of a counter hash `mix(i ⊕ k)` (the noise generator's, with a
                // fresh key per body) as its I and Q level indices, and its constellation
                // bits are their Gray codes, so `Qam::map` of the stored bits is the same
                // point; the loop has no table lookups and vectorises.
                let key = rng.next_u64() as u32;
                fill_subcarriers(&mut self.physical, &mut self.physical_bits, qam, key);
                let scale = idft_scale();
                for (&x, &p) in si.iter().zip(&self.table) {
                    self.physical[p as usize] = x * scale;
                }
                self.last = (qam, si);
                self.logical_current = false;
                self.ifft.process_outofplace_with_scratch(
                    &mut self.physical,
                    out,
                    &mut self.scratch,
                );
            }
        }
        Ok(())
    }

    /// Writes one body built from given logical symbols (3780: system information and data
    /// in their positions, from [`super::data_layer::DataLayer`]): for C = 3780 logical
    /// symbol `l` goes to subcarrier `interleave_index(l)` and the body is the unitary
    /// inverse DFT; for C = 1 the symbols are the body.
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] when `logical` or `out` is not 3780 samples long.
    pub fn modulate_logical(
        &mut self,
        carrier: CarrierMode,
        logical: &[Complex32],
        out: &mut [Complex32],
    ) -> Result<(), DtmbError> {
        if out.len() != BODY_LEN || logical.len() != BODY_LEN {
            return Err(DtmbError::BufferLength {
                what: "frame body",
                expected: BODY_LEN,
                got: out.len().min(logical.len()),
            });
        }
        self.logical.copy_from_slice(logical);
        self.logical_current = true;
        match carrier {
            CarrierMode::Single => out.copy_from_slice(logical),
            CarrierMode::Multi3780 => {
                let scale = idft_scale();
                for (&x, &p) in logical.iter().zip(&self.table) {
                    self.physical[p as usize] = x * scale;
                }
                self.ifft.process_outofplace_with_scratch(
                    &mut self.physical,
                    out,
                    &mut self.scratch,
                );
            }
        }
        Ok(())
    }

    /// The logical symbols (system information then data) of the last body.
    pub fn symbols(&mut self) -> &[Complex32] {
        if !self.logical_current {
            let (qam, si) = self.last;
            let lut = &self.qam_lut[(qam.bits_per_symbol() / 2 - 1) as usize];
            self.logical[..SI_LEN].copy_from_slice(&si);
            for (l, &p) in self.logical.iter_mut().zip(&self.table).skip(SI_LEN) {
                *l = lut[self.physical_bits[p as usize] as usize];
            }
            self.logical_current = true;
        }
        &self.logical
    }

    /// Recovers the logical symbols of a C = 3780 body in place: unitary forward DFT,
    /// then de-interleaving into `symbols` (length 3780).
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] on wrong lengths.
    pub fn demodulate(
        &mut self,
        body: &mut [Complex32],
        symbols: &mut [Complex32],
    ) -> Result<(), DtmbError> {
        if body.len() != BODY_LEN || symbols.len() != BODY_LEN {
            return Err(DtmbError::BufferLength {
                what: "frame body",
                expected: BODY_LEN,
                got: body.len().min(symbols.len()),
            });
        }
        self.fft.process_with_scratch(body, &mut self.scratch);
        let s = idft_scale();
        for (l, &p) in self.table.iter().enumerate() {
            symbols[l] = body[p as usize] * s;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn interleaver_is_a_permutation_and_inverts() {
        let mut seen = vec![false; BODY_LEN];
        for l in 0..BODY_LEN {
            let p = interleave_index(l);
            assert!(p < BODY_LEN && !seen[p], "index {l} → {p}");
            seen[p] = true;
        }
        let mut inverse = vec![0usize; BODY_LEN];
        for l in 0..BODY_LEN {
            inverse[interleave_index(l)] = l;
        }
        for l in 0..BODY_LEN {
            assert_eq!(inverse[interleave_index(l)], l);
        }
    }

    #[test]
    fn qam_has_unit_power_and_gray_neighbours() {
        for qam in [Qam::Qam4, Qam::Qam16, Qam::Qam64] {
            let m = 1u32 << qam.bits_per_symbol();
            let p: f64 = (0..m).map(|b| qam.map(b).norm_sqr() as f64).sum::<f64>() / m as f64;
            assert!((p - 1.0).abs() < 1e-6, "{qam:?}: {p}");
            // Points one level apart on I differ in exactly one bit (Gray mapping).
            let d = qam.map(0).re - qam.map(1 << (qam.bits_per_symbol() / 2)).re;
            assert!(d.abs() > 0.0);
        }
    }

    #[test]
    fn fft_of_a_body_returns_its_symbols() {
        let mut m = BodyModulator::new();
        let mut rng = TrialRng::new(3, 0).stream("dtmb/test");
        let mut body = vec![Complex32::default(); BODY_LEN];
        m.modulate(CarrierMode::Multi3780, Qam::Qam64, 2, &mut rng, &mut body)
            .unwrap();
        let sent = m.symbols().to_vec();
        let power: f32 = body.iter().map(|x| x.norm_sqr()).sum::<f32>() / BODY_LEN as f32;
        assert!((power - 1.0).abs() < 0.05, "body power {power}");
        let mut got = vec![Complex32::default(); BODY_LEN];
        m.demodulate(&mut body, &mut got).unwrap();
        let err = sent
            .iter()
            .zip(&got)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0f32, f32::max);
        assert!(err < 1e-4, "max symbol error {err}");
        // The data symbols are uniform over the 64 points: each of the 3744 falls on a
        // point with probability 1/64 (58.5 expected per point, σ ≈ 7.6).
        let mut counts = std::collections::HashMap::new();
        for s in &sent[SI_LEN..] {
            *counts
                .entry((s.re.to_bits(), s.im.to_bits()))
                .or_insert(0usize) += 1;
        }
        assert_eq!(counts.len(), 64);
        assert!(
            counts.values().all(|&c| (25..=95).contains(&c)),
            "{counts:?}"
        );
        // The system information reads back as mode 1111 and vector 2.
        assert!(got[..4].iter().all(|s| s.re < 0.0));
        assert!(got[4 + 30].re < 0.0 && got[4 + 31].re > 0.0);
    }

    /// The portable, AVX2 and AVX-512 builds of the subcarrier fill give the same bits.
    #[test]
    fn every_build_of_the_subcarrier_fill_gives_the_same_bits() {
        for qam in [Qam::Qam4, Qam::Qam16, Qam::Qam64] {
            let mut x0 = vec![Complex32::default(); BODY_LEN];
            let mut b0 = vec![0u8; BODY_LEN];
            fill_subcarriers_kernel(&mut x0, &mut b0, qam, 0xdead_beef);
            // The stored bits map to the stored points.
            let s = idft_scale();
            assert!(x0
                .iter()
                .zip(&b0)
                .all(|(x, &b)| (*x - qam.map(b as u32) * s).norm() < 1e-7));
            #[cfg(target_arch = "x86_64")]
            {
                type Build = unsafe fn(&mut [Complex32], &mut [u8], Qam, u32);
                let builds: [(&str, bool, Build); 2] = [
                    (
                        "avx2",
                        std::arch::is_x86_feature_detected!("avx2"),
                        fill_subcarriers_avx2,
                    ),
                    (
                        "avx512f",
                        std::arch::is_x86_feature_detected!("avx512f"),
                        fill_subcarriers_avx512,
                    ),
                ];
                for (name, supported, build) in builds {
                    if !supported {
                        eprintln!("subcarrier fill build {name}: not supported here");
                        continue;
                    }
                    let mut x = vec![Complex32::default(); BODY_LEN];
                    let mut b = vec![0u8; BODY_LEN];
                    // SAFETY: the CPU supports the build's features, checked just above.
                    unsafe { build(&mut x, &mut b, qam, 0xdead_beef) };
                    assert_eq!(b, b0, "{name}");
                    assert!(crate::dtmb::same_bits(&x, &x0), "{name}");
                }
            }
        }
    }

    #[test]
    fn wrong_body_length_is_an_error() {
        let mut m = BodyModulator::new();
        let mut rng = TrialRng::new(3, 0).stream("dtmb/test");
        let mut body = vec![Complex32::default(); 10];
        assert!(m
            .modulate(CarrierMode::Single, Qam::Qam4, 0, &mut rng, &mut body)
            .is_err());
    }
}
