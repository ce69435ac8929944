//! Seed 002's DTMB ranging (Liu et al., Remote Sens. 15(13):3229, 2023, §3.2): the carrier
//! frequency offset from the phase rotation of the TPS (system-information) subcarriers
//! between consecutive frames, the Doppler velocity, and the accumulated range difference.
//!
//! ```text
//! Δf_m   = arg Σ_{k∈TPS} Y_{m+1}(k) Y_m*(k) / (2π N_s T)          (CFO of frame pair m)
//! Δv_m   = −(Δf_m − f_s) c / f_c                                   (radial velocity)
//! Δr_M   = Σ_{m<M} Δv_m N_s T                                      (range change)
//! ```
//!
//! `N_s T` is the frame duration, `f_s` the oscillator part of the CFO (estimated while the
//! receiver stands still, [`TpsRanging::calibrate_static`]), `f_c` the carrier. The sign
//! follows the Doppler convention: a receiver moving away (range growing) sees a lower
//! frequency, so `Δv > 0` when the range grows (seed 002 writes the magnitude). The TPS
//! symbols of this transmitter are constant except in the first frame of a superframe
//! (vectors 1/2 mark superframe parity), so pairs that touch such a frame are skipped and
//! the previous CFO is held ([`TpsRanging::update`]).

use super::frame::{interleave_index, SI_LEN};
use super::pn::{PnMode, BODY_LEN, SAMPLE_RATE_HZ};
use crate::core::C_MPS;
use num_complex::{Complex32, Complex64};

/// Physical subcarriers (FFT bins of the 3780-point body) carrying the 36 TPS symbols
/// (for receivers that read the spectrum before de-interleaving).
pub fn tps_bins() -> [usize; SI_LEN] {
    let mut b = [0usize; SI_LEN];
    for (l, x) in b.iter_mut().enumerate() {
        *x = interleave_index(l);
    }
    b
}

/// The CFO (Hz) between two consecutive frames from their de-interleaved body symbols
/// (as [`super::frame::BodyModulator::demodulate`] returns them; the TPS are the first 36):
/// `arg Σ_k Y₂(k) Y₁*(k) / (2π T_frame)`. Unambiguous for |Δf| < 1/(2 T_frame) (800 Hz for
/// PN945).
pub fn tps_cfo_hz(mode: PnMode, prev: &[Complex32], cur: &[Complex32]) -> f64 {
    let mut v = Complex64::default();
    for (a, b) in cur[..SI_LEN].iter().zip(&prev[..SI_LEN]) {
        v += Complex64::new(a.re as f64, a.im as f64) * Complex64::new(b.re as f64, -b.im as f64);
    }
    v.arg() / (2.0 * std::f64::consts::PI * mode.frame_duration_s())
}

/// Standard deviation (Hz) of [`tps_cfo_hz`] at per-subcarrier SNR `snr_db` (the body
/// SNR, since the body has unit power per subcarrier): the phase of a sum of P = 36
/// products of two noisy unit symbols has `σ_φ² = (2/γ + 1/γ²)/(2P)`.
pub fn tps_cfo_sigma_hz(mode: PnMode, snr_db: f64) -> f64 {
    let g = 10f64.powf(snr_db / 10.0);
    let p = SI_LEN as f64;
    ((2.0 / g + 1.0 / (g * g)) / (2.0 * p)).sqrt()
        / (2.0 * std::f64::consts::PI * mode.frame_duration_s())
}

/// Accumulates seed 002's range difference frame pair by frame pair.
#[derive(Clone, Debug, PartialEq)]
pub struct TpsRanging {
    mode: PnMode,
    carrier_hz: f64,
    /// Oscillator part of the CFO (Hz).
    static_cfo_hz: f64,
    last_cfo_hz: f64,
    delta_range_m: f64,
    pairs: u64,
}

impl TpsRanging {
    /// A new accumulator for `mode` at carrier `carrier_hz`.
    pub fn new(mode: PnMode, carrier_hz: f64) -> Self {
        Self {
            mode,
            carrier_hz,
            static_cfo_hz: 0.0,
            last_cfo_hz: 0.0,
            delta_range_m: 0.0,
            pairs: 0,
        }
    }

    /// Sets the oscillator CFO `f_s` to the mean of CFOs measured standing still.
    pub fn calibrate_static(&mut self, cfos_hz: &[f64]) {
        if !cfos_hz.is_empty() {
            self.static_cfo_hz = cfos_hz.iter().sum::<f64>() / cfos_hz.len() as f64;
        }
    }

    /// The oscillator CFO in use.
    pub fn static_cfo_hz(&self) -> f64 {
        self.static_cfo_hz
    }

    /// Adds one frame pair: `cfo_hz` from [`tps_cfo_hz`], or `None` for a pair that
    /// touches a superframe's first frame (the previous CFO is held). Returns the
    /// accumulated range difference (m).
    pub fn update(&mut self, cfo_hz: Option<f64>) -> f64 {
        let f = cfo_hz.unwrap_or(self.last_cfo_hz);
        self.last_cfo_hz = f;
        let v = -(f - self.static_cfo_hz) * C_MPS / self.carrier_hz;
        self.delta_range_m += v * self.mode.frame_duration_s();
        self.pairs += 1;
        self.delta_range_m
    }

    /// The accumulated range difference (m).
    pub fn delta_range_m(&self) -> f64 {
        self.delta_range_m
    }

    /// Frame pairs accumulated.
    pub fn pairs(&self) -> u64 {
        self.pairs
    }
}

/// The unitary 3780-point DFT window of frame body `k` in a block whose frame `k` header
/// starts at sample `header_start` (the body follows the header).
pub fn body_window(mode: PnMode, header_start: usize) -> std::ops::Range<usize> {
    let s = header_start + mode.header_len();
    s..s + BODY_LEN
}

/// Doppler (Hz) of a receiver whose range to the transmitter grows at `range_rate_mps`.
pub fn doppler_hz(range_rate_mps: f64, carrier_hz: f64) -> f64 {
    -range_rate_mps * carrier_hz / C_MPS
}

/// Sample rate re-exported for callers building body windows.
pub const TPS_SAMPLE_RATE_HZ: f64 = SAMPLE_RATE_HZ;
