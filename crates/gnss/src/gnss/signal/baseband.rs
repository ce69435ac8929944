//! The receiver front end at baseband: the satellites' replicas summed, thermal noise, the
//! AGC and the quantiser.
//!
//! A replica is one propagation path of one satellite over one segment of the recording
//! (see [`crate::gnss::signal::scenario`]): within the segment its code phase and its
//! carrier phase advance linearly with the sample index,
//!
//! ```text
//! s(n) = A · c(⌊χ(n)⌋ mod L) · (−1)^{d(ms(n))} · exp(j2π φ(n)),
//! χ(n) = χ0 + n·Δχ,   φ(n) = φ0 + n·Δφ
//! ```
//!
//! with `c` the ±1 ranging code of `L` chips per millisecond, `d` the navigation symbol of
//! the code period (data bit ⊕ overlay chip) and `A = √(C/N0 / f_s)`, so that with the
//! noise's unit power per complex sample (N0·f_s = 1) the path's carrier-to-noise density
//! is C/N0. The carrier phase is kept as a 32-bit fixed-point fraction of a cycle (2⁻³²
//! cycle resolution) and turned into cos/sin by a 1024-entry table (phase error ≤ 0.18°,
//! a correlation loss below 10⁻⁵ dB); the code phase is kept as a 64-bit fixed-point chip
//! count (2⁻⁴⁰ chip resolution), re-anchored from the geometry at every segment start so
//! rounding does not accumulate.
//!
//! Noise: complex white Gaussian, N(0, ½) per component. AGC: the gain follows the
//! measured input power of each block (a first-order loop with a 10-block time constant)
//! so the RMS per component sits at the format's target, as a receiver's AGC holds the
//! ADC's input range; the quantiser rounds and saturates (ci8: ±127 with σ = 32 LSB,
//! clipping beyond 4σ; ci16: ±32767 with σ = 2048 LSB; cf32: unit σ, not quantised).

use crate::core::rng::StreamRng;
use num_complex::Complex32;

/// The sample formats a recording can be written in (SigMF `core:datatype`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleFormat {
    /// Interleaved signed 8-bit I/Q (`ci8`; GNSS-SDR `ibyte`).
    Ci8,
    /// Interleaved little-endian signed 16-bit I/Q (`ci16_le`; GNSS-SDR `ishort`).
    Ci16,
    /// Interleaved little-endian 32-bit float I/Q (`cf32_le`; GNSS-SDR `gr_complex`).
    Cf32,
}

impl SampleFormat {
    /// Parses `ci8`, `ci16` or `cf32` (the `_le` spellings too).
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "ci8" => Some(Self::Ci8),
            "ci16" | "ci16_le" => Some(Self::Ci16),
            "cf32" | "cf32_le" => Some(Self::Cf32),
            _ => None,
        }
    }

    /// The SigMF `core:datatype`.
    pub fn datatype(self) -> &'static str {
        match self {
            Self::Ci8 => "ci8",
            Self::Ci16 => "ci16_le",
            Self::Cf32 => "cf32_le",
        }
    }

    /// Bytes per complex sample.
    pub fn bytes_per_sample(self) -> usize {
        match self {
            Self::Ci8 => 2,
            Self::Ci16 => 4,
            Self::Cf32 => 8,
        }
    }

    /// The RMS per component the AGC holds (in output units).
    pub fn target_rms(self) -> f32 {
        match self {
            Self::Ci8 => 32.0,
            Self::Ci16 => 2048.0,
            Self::Cf32 => 1.0,
        }
    }
}

/// The symbols a satellite's message puts on its code periods.
pub trait NavSymbols {
    /// The symbol (0/1) modulating code period `ms` (the number of whole milliseconds of
    /// the satellite's time since the GPS epoch): the data bit ⊕ the overlay code chip.
    fn symbol(&mut self, ms: i64) -> u8;
}

/// One replica over one segment: where its code and carrier start and how fast they run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Replica {
    /// Amplitude (√(C/N0/f_s) times the path's relative amplitude).
    pub amplitude: f32,
    /// The code period (ms since the GPS epoch, satellite time) at the first sample.
    pub ms: i64,
    /// Chip phase within that period at the first sample, in [0, L).
    pub chip: f64,
    /// Chips per sample.
    pub chips_per_sample: f64,
    /// Carrier phase at the first sample (cycles, any value; only its fraction is used).
    pub phase_cycles: f64,
    /// Carrier cycles per sample (the Doppler over the sample rate).
    pub cycles_per_sample: f64,
}

/// The cos/sin table of the carrier.
pub struct CarrierTable {
    table: Vec<(f32, f32)>,
}

const TABLE_BITS: u32 = 10;

impl Default for CarrierTable {
    fn default() -> Self {
        let n = 1usize << TABLE_BITS;
        let table = (0..n)
            .map(|k| {
                // Sample the middle of each phase bin so the table has no half-bin bias.
                let a = std::f64::consts::TAU * (k as f64 + 0.5) / n as f64;
                (a.cos() as f32, a.sin() as f32)
            })
            .collect();
        Self { table }
    }
}

/// The fraction of a cycle as a 32-bit fixed-point phase.
fn fixed_phase(cycles: f64) -> u32 {
    ((cycles - cycles.floor()) * 4_294_967_296.0) as u64 as u32
}

/// Fraction bits of the fixed-point code phase of a [`ReplicaCursor`]: chip indices below 2²³
/// fit above them, and a rate rounded to 2⁻⁴⁰ chip per sample drifts by less than 10⁻⁷
/// chip over a 10 ms segment at 40 Msps.
const CHIP_FRAC_BITS: u32 = 40;

/// Samples of a segment every replica is added to before the next piece: 2048 complex
/// f32 samples are 16 KiB, half of the smallest first-level data cache in use.
pub const PIECE_SAMPLES: usize = 2048;

/// A replica's running state: where its code, symbol and carrier stand at the next sample
/// it will add. [`ReplicaCursor::add`] can be called on consecutive pieces of a segment,
/// so a caller can add every replica to one cache-sized piece before moving to the next.
///
/// The code phase runs as a 64-bit fixed-point chip count (integer chips above
/// `CHIP_FRAC_BITS` fraction bits): an integer add and compare per sample instead of a
/// float add and a float-to-index conversion, and the chip's sign picks the signed
/// amplitude from a two-entry table.
#[derive(Clone, Copy, Debug)]
pub struct ReplicaCursor {
    chip: u64,
    rate: u64,
    len: u64,
    ms: i64,
    sym: u8,
    phase: u32,
    step: u32,
    signed: [f32; 2],
}

impl ReplicaCursor {
    /// The cursor at the first sample of `r`, for a code of `code_len` chips; `nav` gives
    /// the symbol of the starting period.
    pub fn new(r: &Replica, code_len: usize, nav: &mut dyn NavSymbols) -> Self {
        let one = (1u64 << CHIP_FRAC_BITS) as f64;
        let len = (code_len.max(1) as u64) << CHIP_FRAC_BITS;
        Self {
            // The segment's start is in [0, L) by construction; the clamp keeps a rounding
            // at the top end inside the code.
            chip: ((r.chip * one) as u64).min(len - 1),
            rate: (r.chips_per_sample * one).round() as u64,
            len,
            ms: r.ms,
            sym: nav.symbol(r.ms) & 1,
            phase: fixed_phase(r.phase_cycles),
            step: fixed_phase(r.cycles_per_sample),
            signed: [r.amplitude, -r.amplitude],
        }
    }

    /// Adds the replica to `out` (the next `out.len()` samples) and advances past them.
    /// `code` is the ranging code as 0/1 chips, `nav` the satellite's symbols.
    pub fn add(
        &mut self,
        out: &mut [Complex32],
        code: &[u8],
        nav: &mut dyn NavSymbols,
        carrier: &CarrierTable,
    ) {
        let Self {
            mut chip,
            rate,
            len,
            mut ms,
            mut sym,
            mut phase,
            step,
            signed,
        } = *self;
        let table = &carrier.table;
        let code = &code[..(len >> CHIP_FRAC_BITS) as usize];
        let mut rest = out;
        while !rest.is_empty() {
            // The samples before the code period ends: within them the chip index never
            // wraps, so the loop below has no branch but its own.
            let to_wrap = (len - chip).div_ceil(rate.max(1)) as usize;
            let (run, after) = rest.split_at_mut(to_wrap.min(rest.len()));
            let signed = [signed[usize::from(sym)], signed[usize::from(sym ^ 1)]];
            for o in run.iter_mut() {
                let a = signed[usize::from(code[(chip >> CHIP_FRAC_BITS) as usize] & 1)];
                let (co, si) = table[(phase >> (32 - TABLE_BITS)) as usize];
                o.re += a * co;
                o.im += a * si;
                phase = phase.wrapping_add(step);
                chip += rate;
            }
            if chip >= len {
                chip -= len;
                ms += 1;
                sym = nav.symbol(ms) & 1;
            }
            rest = after;
        }
        self.chip = chip;
        self.ms = ms;
        self.sym = sym;
        self.phase = phase;
    }
}

/// Adds one replica to `out` (code `code` of ±1 as 0/1 chips, `nav` its symbols): a
/// [`ReplicaCursor`] over the whole of `out`.
pub fn add_replica(
    out: &mut [Complex32],
    r: &Replica,
    code: &[u8],
    nav: &mut dyn NavSymbols,
    carrier: &CarrierTable,
) {
    ReplicaCursor::new(r, code.len(), nav).add(out, code, nav, carrier);
}

/// Adds complex white Gaussian noise of unit power (N(0, ½) per component), keyed by one
/// draw from `rng`: the counter-hash Box–Muller generator of [`crate::core::noise`],
/// vectorised (its tails are cut at 5.77σ per component).
pub fn add_noise(out: &mut [Complex32], rng: &mut StreamRng) {
    crate::core::noise::add_awgn(out, 1.0, rng);
}

/// `x` saturated to ±`limit` (at most 2²²) and rounded to the nearest integer, ties to
/// even. Adding and subtracting 1.5·2²³ leaves no fraction bits in an f32 of that size,
/// so the FPU's own round-to-nearest does the rounding: a baseline x86-64 build would
/// otherwise call `roundf` for every component.
fn nearest(x: f32, limit: f32) -> f32 {
    const SHIFT: f32 = 12_582_912.0;
    (x.clamp(-limit, limit) + SHIFT) - SHIFT
}

/// The AGC and quantiser: turns blocks of samples into the output format's bytes.
pub struct Quantiser {
    format: SampleFormat,
    /// Running estimate of the input power per complex sample.
    power: f64,
}

impl Quantiser {
    /// A quantiser whose AGC starts at the expected input power `power0` (noise plus the
    /// replicas' powers).
    pub fn new(format: SampleFormat, power0: f64) -> Self {
        Self {
            format,
            power: power0.max(1e-12),
        }
    }

    /// The current gain (output units per input unit).
    pub fn gain(&self) -> f32 {
        // Per component the RMS is √(P/2).
        (f64::from(self.format.target_rms()) / (self.power / 2.0).sqrt()) as f32
    }

    /// Appends `block` in the output format to `bytes`, then updates the AGC from the
    /// block's measured power (so the gain changes between blocks, never inside one).
    pub fn quantise(&mut self, block: &[Complex32], bytes: &mut Vec<u8>) {
        let g = self.gain();
        match self.format {
            SampleFormat::Ci8 => {
                bytes.reserve(2 * block.len());
                for s in block {
                    bytes.push(nearest(s.re * g, 127.0) as i8 as u8);
                    bytes.push(nearest(s.im * g, 127.0) as i8 as u8);
                }
            }
            SampleFormat::Ci16 => {
                for s in block {
                    let i = nearest(s.re * g, 32767.0) as i16;
                    let q = nearest(s.im * g, 32767.0) as i16;
                    bytes.extend_from_slice(&i.to_le_bytes());
                    bytes.extend_from_slice(&q.to_le_bytes());
                }
            }
            SampleFormat::Cf32 => {
                for s in block {
                    bytes.extend_from_slice(&(s.re * g).to_le_bytes());
                    bytes.extend_from_slice(&(s.im * g).to_le_bytes());
                }
            }
        }
        if !block.is_empty() {
            let p: f64 =
                block.iter().map(|s| f64::from(s.norm_sqr())).sum::<f64>() / block.len() as f64;
            self.power += 0.1 * (p - self.power);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::TrialRng;

    struct Ones;
    impl NavSymbols for Ones {
        fn symbol(&mut self, _ms: i64) -> u8 {
            0
        }
    }

    #[test]
    fn replica_tone_has_its_doppler_and_power() {
        // A code of all zeros leaves the carrier: its frequency and amplitude come back
        // from a single-bin DFT.
        let code = vec![0u8; 1023];
        let fs = 4.0e6;
        let f_d = 1234.5;
        let r = Replica {
            amplitude: 0.5,
            ms: 0,
            chip: 0.0,
            chips_per_sample: 1.023e6 / fs,
            phase_cycles: 0.25,
            cycles_per_sample: f_d / fs,
        };
        let mut out = vec![Complex32::default(); 40_000];
        add_replica(&mut out, &r, &code, &mut Ones, &CarrierTable::default());
        let dft: num_complex::Complex64 = out
            .iter()
            .enumerate()
            .map(|(n, s)| {
                let a = -std::f64::consts::TAU * f_d * n as f64 / fs;
                num_complex::Complex64::new(f64::from(s.re), f64::from(s.im))
                    * num_complex::Complex64::from_polar(1.0, a)
            })
            .sum::<num_complex::Complex64>()
            / out.len() as f64;
        assert!((dft.norm() - 0.5).abs() < 1e-3, "{}", dft.norm());
        // Phase 0.25 cycle → +90°, within the table's half-bin.
        assert!(
            (dft.arg() - std::f64::consts::FRAC_PI_2).abs() < 0.01,
            "{}",
            dft.arg()
        );
    }

    #[test]
    fn noise_has_unit_power_and_quantiser_holds_its_target() {
        let mut rng = TrialRng::new(1, 0).stream("test");
        let mut x = vec![Complex32::default(); 100_000];
        add_noise(&mut x, &mut rng);
        let p: f64 = x.iter().map(|s| f64::from(s.norm_sqr())).sum::<f64>() / x.len() as f64;
        assert!((p - 1.0).abs() < 0.02, "{p}");
        let mut q = Quantiser::new(SampleFormat::Ci8, 1.0);
        let mut bytes = Vec::new();
        q.quantise(&x, &mut bytes);
        let rms = (bytes
            .iter()
            .map(|&b| f64::from(b as i8).powi(2))
            .sum::<f64>()
            / bytes.len() as f64)
            .sqrt();
        assert!((rms - 32.0).abs() < 1.0, "{rms}");
        assert_eq!(bytes.len(), 2 * x.len());
    }

    #[test]
    fn a_delayed_replica_correlates_at_its_delay_with_its_amplitude() {
        // A direct path and a reflection 0.5 chip later at a third of the amplitude, as
        // `scenario` adds them: the correlation with the prompt code peaks at lag 0 and
        // at the reflection's delay with the ratio of their amplitudes.
        let code = crate::gnss::signal::ca_code::ca_code_bits(7)
            .expect("PRN 7")
            .to_vec();
        let fs = 4.092e6; // 4 samples per chip
        let rate = 1.023e6 / fs;
        let mut out = vec![Complex32::default(); 4092 * 4];
        let table = CarrierTable::default();
        for (delay_chips, amp) in [(0.0, 0.3f32), (0.5, 0.1f32)] {
            let r = Replica {
                amplitude: amp,
                ms: 0,
                chip: (1023.0 - delay_chips) % 1023.0,
                chips_per_sample: rate,
                phase_cycles: 0.0,
                cycles_per_sample: 0.0,
            };
            add_replica(&mut out, &r, &code, &mut Ones, &table);
        }
        // Correlate with the prompt replica at lags of whole samples (¼ chip).
        let corr = |lag: usize| -> f64 {
            out.iter()
                .enumerate()
                .map(|(n, s)| {
                    let chip = ((n + 4092 * 4 - lag) as f64 * rate) as usize % 1023;
                    f64::from(s.re) * (1.0 - 2.0 * f64::from(code[chip]))
                })
                .sum::<f64>()
                / out.len() as f64
        };
        // At lag 0 the direct path plus half of the reflection's triangle (0.5 chip off).
        assert!((corr(0) - (0.3 + 0.1 * 0.5)).abs() < 0.01, "{}", corr(0));
        // At the reflection's delay (2 samples) the reflection plus half the direct path's.
        assert!((corr(2) - (0.1 + 0.3 * 0.5)).abs() < 0.01, "{}", corr(2));
        // Beyond 1.5 chips both have gone.
        assert!(corr(8).abs() < 0.01, "{}", corr(8));
    }

    /// Symbols that record which code periods asked for one: period `ms` gets the parity
    /// of `ms`, so a wrong period count flips the sign of a whole millisecond.
    struct Parity;
    impl NavSymbols for Parity {
        fn symbol(&mut self, ms: i64) -> u8 {
            (ms & 1) as u8
        }
    }

    #[test]
    fn the_fixed_point_code_phase_follows_the_exact_chip_sequence() {
        // Over a 10 ms segment at 40 Msps and at 2.6 Msps with a Doppler-shifted chip
        // rate, every sample's chip and period equal the exact ones, computed in f64 from
        // the segment's start: χ(n) = χ0 + n·Δχ, chip ⌊χ(n)⌋ mod L, period ⌊χ(n)/L⌋.
        let code = crate::gnss::signal::ca_code::ca_code_bits(13)
            .expect("PRN 13")
            .to_vec();
        let len = code.len() as f64;
        for (fs, chip0) in [(40.0e6, 1022.37), (2.6e6, 0.0), (2.6e6, 511.999_999)] {
            let rate = 1.023e6 * (1.0 + 2.7e-6) / fs;
            let r = Replica {
                amplitude: 1.0,
                ms: 5,
                chip: chip0,
                chips_per_sample: rate,
                phase_cycles: 0.0,
                cycles_per_sample: 0.0,
            };
            let n = (0.01 * fs) as usize;
            let mut out = vec![Complex32::default(); n];
            add_replica(&mut out, &r, &code, &mut Parity, &CarrierTable::default());
            let mut differ = 0usize;
            for (k, o) in out.iter().enumerate() {
                let x = chip0 + k as f64 * rate;
                let period = 5 + (x / len).floor() as i64;
                let chip = (x % len).floor() as usize;
                let bit = code[chip] ^ (period & 1) as u8;
                // The carrier is at phase 0: the table's first entry, cos of half a bin.
                let expected = if bit == 0 { 1.0 } else { -1.0 };
                if (f64::from(o.re).signum() - expected).abs() > 0.0 {
                    differ += 1;
                }
            }
            // A sample may fall within 10⁻⁷ chip of a chip edge, where the two roundings can
            // disagree; none does in these segments.
            assert_eq!(differ, 0, "fs {fs}, chip0 {chip0}");
        }
    }

    #[test]
    fn the_quantiser_rounds_to_nearest_and_saturates() {
        for (x, limit, want) in [
            (0.49f32, 127.0f32, 0.0f32),
            (0.51, 127.0, 1.0),
            (-0.51, 127.0, -1.0),
            (126.6, 127.0, 127.0),
            (300.0, 127.0, 127.0),
            (-1.0e9, 127.0, -127.0),
            (2.5, 127.0, 2.0),
            (3.5, 127.0, 4.0),
            (-32_767.4, 32_767.0, -32_767.0),
            (40_000.0, 32_767.0, 32_767.0),
            (1234.49, 32_767.0, 1234.0),
        ] {
            assert_eq!(nearest(x, limit), want, "{x}");
        }
        // Away from ties, the same integer as f32::round for every value of a fine sweep.
        let mut x = -140.0f32;
        while x < 140.0 {
            if (x.fract().abs() - 0.5).abs() > 1e-4 {
                assert_eq!(nearest(x, 127.0), x.round().clamp(-127.0, 127.0), "{x}");
            }
            x += 0.001_7;
        }
    }
}
