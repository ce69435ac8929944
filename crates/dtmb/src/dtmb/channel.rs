//! A multipath channel for DTMB: paths with exact fractional delays, per-path Doppler,
//! carrier and sampling-frequency offsets, and complex white Gaussian noise at an SNR.
//!
//! **Waveform.** The transmitted samples define a continuous-time signal through the
//! Kaiser-windowed sinc of [`super::kernel`], evaluated exactly at any real delay.
//!
//! **Paths and clocks.** With receiver sample-clock offset `ε` (`sfo_ppm·10⁻⁶`, the
//! receiver samples at `f_s(1 + ε)`), receiver sample `n` is taken at true time
//! `t_n = n / (f_s(1 + ε))` and path `p` contributes
//!
//! ```text
//! y_p[n] = g_p · exp(j2π (f_D,p + Δf) t_n) · x(n/(1 + ε) − τ_p f_s),
//! ```
//!
//! with `Δf` the carrier frequency offset. Receiver sample 0 is at the instant transmitter
//! sample 0 leaves the antenna (a path's `delay_s` includes any receiver clock offset).
//! The fractional delay is evaluated once per 256-sample sub-block at its centre; the
//! SFO drift inside a sub-block (`ε · 128` samples, 0.17 ns at 10 ppm) is the only
//! approximation. Doppler is applied as a carrier rotation. The delay rate of a moving
//! receiver is modelled either by updating the paths between calls
//! ([`Channel::set_paths`]) or by each path's own rate `τ̇_p` ([`Path::delay_rate`]): its
//! delay at `t_n` is `τ_p + τ̇_p t_n`, so it reads the transmitter at
//! `u = n(1 − τ̇_p)/(1 + ε) − τ_p f_s` — a sample-clock offset of its own, evaluated per
//! sub-block as the SFO is. Paths with a rate are run by the time-domain reference (the
//! frequency-domain engine holds one filter for every path, whose span a spread of rates
//! would stretch without bound).
//!
//! **Noise.** Complex white Gaussian noise of variance `σ² = P / 10^(SNR/10)` per sample,
//! where `P = P_frame · Σ|g_p|²` is the nominal received power (the frame's mean power
//! [`PnMode::nominal_frame_power`] times the path power): SNR is over the 7.56 MHz band.
//! Single-frequency networks are more paths, each with its tower's extra delay.

use super::fd_channel::FdChannel;
use super::kernel::KERNEL_HALF_WIDTH;
use super::multipath::{ChannelConfig, MAX_DELAY_RATE};
use super::pn::{PnMode, SAMPLE_RATE_HZ};
use super::transmitter::SampleSource;
use super::DtmbError;
use crate::dtmb::kernel::kernel;
use crate::dtmb::Path;
use num_complex::{Complex32, Complex64};
use rand::Rng;
use rand_distr::StandardNormal;

/// Sub-block over which a path's fractional delay is held.
pub const SUB_BLOCK: usize = 256;

/// A channel instance with its caller-independent work buffers.
#[derive(Clone, Debug)]
pub struct Channel {
    cfg: ChannelConfig,
    noise_sigma: f32,
    max_block: usize,
    /// Transmitter samples for the current call, split into re/im for vectorised FIRs.
    tx: Vec<Complex32>,
    xr: Vec<f32>,
    xi: Vec<f32>,
    acc_r: Vec<f32>,
    acc_i: Vec<f32>,
    /// Per path: the fractional delay of its cached taps and the taps.
    taps: Vec<(f64, Vec<f32>)>,
    /// The frequency-domain engine, when the configuration suits it.
    fd: Option<FdChannel>,
}

impl Channel {
    /// Builds a channel for signals of `mode`, processing up to `max_block` samples a call.
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] for no paths, non-finite values, negative delays or
    /// an SFO beyond ±1000 ppm.
    pub fn new(cfg: ChannelConfig, mode: PnMode, max_block: usize) -> Result<Self, DtmbError> {
        let mut ch = Self {
            cfg: cfg.clone(),
            noise_sigma: 0.0,
            max_block,
            tx: Vec::new(),
            xr: Vec::new(),
            xi: Vec::new(),
            acc_r: vec![0.0; SUB_BLOCK],
            acc_i: vec![0.0; SUB_BLOCK],
            taps: Vec::new(),
            fd: None,
        };
        ch.set_config(cfg, mode)?;
        Ok(ch)
    }

    /// Replaces the paths (e.g. each block for a moving receiver); keeps CFO, SFO, SNR.
    ///
    /// # Errors
    /// As [`Channel::new`].
    pub fn set_paths(&mut self, paths: Vec<Path>, mode: PnMode) -> Result<(), DtmbError> {
        let mut cfg = self.cfg.clone();
        cfg.paths = paths;
        self.set_config(cfg, mode)
    }

    fn set_config(&mut self, cfg: ChannelConfig, mode: PnMode) -> Result<(), DtmbError> {
        let bad =
            |name: &'static str, reason: String| Err(DtmbError::InvalidParameter { name, reason });
        if cfg.paths.is_empty() {
            return bad("paths", "a channel needs at least one path".into());
        }
        for (i, p) in cfg.paths.iter().enumerate() {
            if !(p.delay_s.is_finite() && p.delay_s >= 0.0 && p.delay_s < 1.0) {
                return bad(
                    "delay_s",
                    format!(
                        "path {i}: delay must be finite, in [0, 1) s, got {}",
                        p.delay_s
                    ),
                );
            }
            if !(p.gain.re.is_finite() && p.gain.im.is_finite() && p.doppler_hz.is_finite()) {
                return bad("gain", format!("path {i}: gain and Doppler must be finite"));
            }
            if !(p.delay_rate.is_finite() && p.delay_rate.abs() <= MAX_DELAY_RATE) {
                return bad(
                    "delay_rate",
                    format!(
                        "path {i}: the delay rate must be finite and within ±{MAX_DELAY_RATE} \
                         s/s, got {}",
                        p.delay_rate
                    ),
                );
            }
        }
        if !(cfg.cfo_hz.is_finite() && cfg.sfo_ppm.is_finite() && cfg.sfo_ppm.abs() <= 1000.0) {
            return bad(
                "cfo_hz/sfo_ppm",
                format!(
                    "CFO must be finite and |SFO| ≤ 1000 ppm, got {} Hz, {} ppm",
                    cfg.cfo_hz, cfg.sfo_ppm
                ),
            );
        }
        self.noise_sigma = match cfg.snr_db {
            None => 0.0,
            Some(s) if s.is_finite() => {
                let p: f64 = mode.nominal_frame_power()
                    * cfg.paths.iter().map(|p| p.gain.norm_sqr()).sum::<f64>();
                (p / 10f64.powf(s / 10.0)).sqrt() as f32
            }
            Some(s) => return bad("snr_db", format!("must be finite, got {s}")),
        };
        let (dmin, dmax) = cfg.paths.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(p.delay_s), b.max(p.delay_s))
        });
        let span = ((dmax - dmin) * SAMPLE_RATE_HZ).ceil() as usize;
        let need = self.max_block + span + 2 * KERNEL_HALF_WIDTH + SUB_BLOCK + 8;
        self.tx.resize(need, Complex32::default());
        self.xr.resize(need, 0.0);
        self.xi.resize(need, 0.0);
        self.taps = cfg
            .paths
            .iter()
            .map(|_| (f64::NAN, vec![0.0; 2 * KERNEL_HALF_WIDTH]))
            .collect();
        let keep = match self.fd.as_mut() {
            Some(fd) => fd.reconfigure(&cfg),
            None => false,
        };
        if !keep {
            self.fd = FdChannel::new(&cfg);
        }
        self.cfg = cfg;
        Ok(())
    }

    /// The configuration.
    pub fn config(&self) -> &ChannelConfig {
        &self.cfg
    }

    /// Noise standard deviation per complex sample (`σ`, so `E|w|² = σ²`).
    pub fn noise_sigma(&self) -> f32 {
        self.noise_sigma
    }

    /// Writes receiver samples `rx_start .. rx_start + out.len()` into `out`, pulling the
    /// transmitter samples it needs from `src` and noise from `rng`.
    ///
    /// The paths are applied in the frequency domain (overlap-save with the exact DFTs of
    /// each path's fractional-delay taps; the derivation and its error bounds are in the
    /// private module `fd_channel`) and the noise comes
    /// from [`super::noise::add_awgn`]. When the paths' Doppler spread or the SFO is too
    /// large for that (residual Doppler phase above 0.05 rad over 16 samples), the
    /// time-domain reference [`Channel::process_exact`] is used.
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] when `out` is longer than the channel's `max_block`.
    pub fn process<S: SampleSource + ?Sized, R: Rng + ?Sized>(
        &mut self,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
        rng: &mut R,
    ) -> Result<(), DtmbError> {
        self.check_block(out.len())?;
        match self.fd.as_mut() {
            Some(fd) => {
                fd.process(&self.cfg, src, rx_start, out);
                super::noise::add_awgn(out, self.noise_sigma, rng);
                Ok(())
            }
            None => self.process_exact(src, rx_start, out, rng),
        }
    }

    fn check_block(&self, len: usize) -> Result<(), DtmbError> {
        if len > self.max_block {
            return Err(DtmbError::BufferLength {
                what: "channel output",
                expected: self.max_block,
                got: len,
            });
        }
        Ok(())
    }

    /// Whether [`Channel::process`] uses the frequency-domain engine for this
    /// configuration.
    pub fn is_frequency_domain(&self) -> bool {
        self.fd.is_some()
    }

    /// The reference time-domain implementation of [`Channel::process`]: a 32-tap
    /// windowed-sinc FIR per path and sub-block, the carrier rotation per sample, and
    /// Gaussian noise from `rand_distr`'s ziggurat. Several times slower than the
    /// frequency-domain path (about 10× per 6-path frame in `docs/performance.md`); kept as the
    /// second implementation the fast path is tested against.
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] when `out` is longer than the channel's `max_block`.
    pub fn process_exact<S: SampleSource + ?Sized, R: Rng + ?Sized>(
        &mut self,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
        rng: &mut R,
    ) -> Result<(), DtmbError> {
        self.check_block(out.len())?;
        let k = KERNEL_HALF_WIDTH as i64;
        let r = 1.0 / (1.0 + self.cfg.sfo_ppm * 1e-6);
        // Path p reads the transmitter at u = n r_p − τ_p f_s, r_p = r (1 − τ̇_p) (module
        // documentation); with no delay rate r_p is r, bit for bit.
        let ratio = |p: &Path| r * (1.0 - p.delay_rate);
        let len = out.len() as i64;
        // The transmitter span every path needs, with margin for the kernel and the
        // sub-block centring.
        let (u_lo, u_hi) = self
            .cfg
            .paths
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), p| {
                let d = p.delay_s * SAMPLE_RATE_HZ;
                (
                    a.min((rx_start as f64) * ratio(p) - d),
                    b.max(((rx_start + len) as f64) * ratio(p) - d),
                )
            });
        let lo = u_lo.floor() as i64 - k - SUB_BLOCK as i64 - 2;
        let hi = u_hi.floor() as i64 + k + SUB_BLOCK as i64 + 2;
        let n_tx = (hi - lo) as usize;
        if n_tx > self.tx.len() {
            // Paths whose delays drift apart need more transmitter samples as the stream
            // goes on: the buffers grow once to the span reached, never shrink.
            self.tx.resize(n_tx, Complex32::default());
            self.xr.resize(n_tx, 0.0);
            self.xi.resize(n_tx, 0.0);
        }
        src.generate(lo, &mut self.tx[..n_tx]);
        for (i, x) in self.tx[..n_tx].iter().enumerate() {
            self.xr[i] = x.re;
            self.xi[i] = x.im;
        }
        out.iter_mut().for_each(|o| *o = Complex32::default());
        let two_pi = 2.0 * std::f64::consts::PI;
        for (pi, path) in self.cfg.paths.iter().enumerate() {
            let r_p = ratio(path);
            let f_tot = path.doppler_hz + self.cfg.cfo_hz;
            let step = Complex64::from_polar(1.0, two_pi * f_tot * r / SAMPLE_RATE_HZ);
            let step32 = Complex32::new(step.re as f32, step.im as f32);
            let mut s = 0usize;
            while s < out.len() {
                let b = SUB_BLOCK.min(out.len() - s);
                let n_s = rx_start + s as i64;
                let u_centre = (n_s as f64 + b as f64 / 2.0) * r_p - path.delay_s * SAMPLE_RATE_HZ;
                let u_first = u_centre - b as f64 / 2.0;
                let i_first = u_first.floor();
                let frac = u_first - i_first;
                let (cached_frac, taps) = &mut self.taps[pi];
                if *cached_frac != frac {
                    // h[j] = φ(frac − t) for t = j − K + 1.
                    for (j, h) in taps.iter_mut().enumerate() {
                        *h = kernel(frac - (j as f64 - k as f64 + 1.0)) as f32;
                    }
                    *cached_frac = frac;
                }
                let base = (i_first as i64 - k + 1 - lo) as usize;
                let acc_r = &mut self.acc_r[..b];
                let acc_i = &mut self.acc_i[..b];
                acc_r.iter_mut().for_each(|a| *a = 0.0);
                acc_i.iter_mut().for_each(|a| *a = 0.0);
                // Tap-outer, sample-inner: each pass is an axpy over contiguous memory,
                // which the compiler vectorises.
                for (j, &h) in taps.iter().enumerate() {
                    let xr = &self.xr[base + j..base + j + b];
                    let xi = &self.xi[base + j..base + j + b];
                    for ((a, &x), (c, &y)) in acc_r.iter_mut().zip(xr).zip(acc_i.iter_mut().zip(xi))
                    {
                        *a += h * x;
                        *c += h * y;
                    }
                }
                // The carrier phase at the sub-block start is computed afresh in f64 so
                // the f32 recursion below never runs longer than one sub-block.
                let t_s = n_s as f64 * r / SAMPLE_RATE_HZ;
                let cycles = (f_tot * t_s).fract();
                let ph0 = path.gain * Complex64::from_polar(1.0, two_pi * cycles);
                let mut ph = Complex32::new(ph0.re as f32, ph0.im as f32);
                for (i, o) in out[s..s + b].iter_mut().enumerate() {
                    *o += ph * Complex32::new(acc_r[i], acc_i[i]);
                    ph *= step32;
                }
                s += b;
            }
        }
        if self.noise_sigma > 0.0 {
            let sd = self.noise_sigma * std::f32::consts::FRAC_1_SQRT_2;
            for o in out.iter_mut() {
                let a: f32 = rng.sample(StandardNormal);
                let b: f32 = rng.sample(StandardNormal);
                *o += Complex32::new(a * sd, b * sd);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use crate::dtmb::link_snr_db;

    /// A test source: a known band-limited tone sum, so `x(u)` has a closed form.
    struct Tones;
    const FREQS: [f64; 3] = [0.013, -0.071, 0.2];
    impl SampleSource for Tones {
        fn generate(&mut self, start: i64, out: &mut [Complex32]) {
            for (i, o) in out.iter_mut().enumerate() {
                *o = tone((start + i as i64) as f64);
            }
        }
    }
    fn tone(u: f64) -> Complex32 {
        let z: Complex64 = FREQS
            .iter()
            .map(|f| Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f * u))
            .sum();
        Complex32::new(z.re as f32, z.im as f32)
    }

    #[test]
    fn fractional_delay_matches_the_analytic_signal() {
        // In-band tones are reproduced by the kernel to its passband accuracy, so the
        // delayed output equals the tone evaluated at the exact delayed time.
        let tau_samples = 1234.3717;
        let cfg = ChannelConfig {
            paths: vec![Path::new(tau_samples / SAMPLE_RATE_HZ, 1.0, 0.0, 0.0)],
            cfo_hz: 0.0,
            sfo_ppm: 0.0,
            snr_db: None,
        };
        let mut ch = Channel::new(cfg, PnMode::Pn945, 4096).unwrap();
        let mut out = vec![Complex32::default(); 1000];
        let mut rng = TrialRng::new(1, 0).stream("t");
        ch.process(&mut Tones, 5000, &mut out, &mut rng).unwrap();
        let err = out
            .iter()
            .enumerate()
            .map(|(i, y)| (y - tone(5000.0 + i as f64 - tau_samples)).norm())
            .fold(0.0f32, f32::max);
        assert!(err < 2e-3 * 3.0, "max error {err}");
    }

    #[test]
    fn sfo_and_cfo_follow_their_definitions() {
        let cfg = ChannelConfig {
            paths: vec![Path::new(0.0, 1.0, 0.0, 100.0)],
            cfo_hz: 400.0,
            sfo_ppm: 50.0,
            snr_db: None,
        };
        let mut ch = Channel::new(cfg, PnMode::Pn945, 4096).unwrap();
        let mut out = vec![Complex32::default(); 2000];
        let mut rng = TrialRng::new(1, 0).stream("t");
        let start = 3_000_000i64;
        ch.process(&mut Tones, start, &mut out, &mut rng).unwrap();
        let r = 1.0 / (1.0 + 50e-6);
        let mut worst = 0.0f32;
        for (i, y) in out.iter().enumerate() {
            let n = (start + i as i64) as f64;
            let rot = Complex64::from_polar(
                1.0,
                2.0 * std::f64::consts::PI * 500.0 * n * r / SAMPLE_RATE_HZ,
            );
            let want = tone(n * r);
            let want = Complex32::new(rot.re as f32, rot.im as f32) * want;
            worst = worst.max((y - want).norm());
        }
        // 50 ppm over a 128-sample half sub-block is 0.0064 samples of delay error.
        assert!(worst < 0.03, "worst {worst}");
    }

    /// Two paths whose delays drift apart at their own rates (±2·10⁻⁶ s/s, 600 m/s; the
    /// extreme makes the drift several samples within the test) read the transmitter at
    /// `u = n r (1 − τ̇_p) − τ_p f_s` on top of a 20 ppm sample clock: the output equals
    /// the tones evaluated there, two million samples in, where the paths have moved
    /// ±4.2 samples from their starting delays; the time-domain reference runs them, and
    /// a rate out of range is refused.
    #[test]
    fn each_path_drifts_at_its_own_delay_rate() {
        let (tau_a, tau_b) = (310.25, 352.6);
        let (rate_a, rate_b) = (2e-6, -2e-6);
        let fs = SAMPLE_RATE_HZ;
        let cfg = ChannelConfig {
            paths: vec![
                Path::new(tau_a / fs, 1.0, 0.0, 0.0).with_delay_rate(rate_a),
                Path::new(tau_b / fs, 0.5, 1.0, 0.0).with_delay_rate(rate_b),
            ],
            cfo_hz: 0.0,
            sfo_ppm: 20.0,
            snr_db: None,
        };
        let mut ch = Channel::new(cfg.clone(), PnMode::Pn945, 4096).unwrap();
        assert!(!ch.is_frequency_domain());
        let mut rng = TrialRng::new(1, 0).stream("t");
        let r = 1.0 / (1.0 + 20e-6);
        let g_b = Complex64::from_polar(0.5, 1.0);
        let mut out = vec![Complex32::default(); 3000];
        for start in [0i64, 2_100_000] {
            ch.process(&mut Tones, start, &mut out, &mut rng).unwrap();
            let mut worst = 0.0f32;
            for (i, y) in out.iter().enumerate() {
                let n = (start + i as i64) as f64;
                let a = tone(n * r * (1.0 - rate_a) - tau_a);
                let b = tone(n * r * (1.0 - rate_b) - tau_b);
                let b = Complex32::new(g_b.re as f32, g_b.im as f32) * b;
                worst = worst.max((y - (a + b)).norm());
            }
            // Within a sub-block a path's delay moves by (ε + τ̇)·128 ≈ 0.003 samples at
            // most, against the SFO test's 0.0064.
            assert!(worst < 0.03, "at {start}: worst {worst}");
        }
        // Held delays give something else once they have drifted: the test can fail.
        let held = ChannelConfig {
            paths: cfg.paths.iter().map(|p| p.with_delay_rate(0.0)).collect(),
            ..cfg.clone()
        };
        let mut still = Channel::new(held, PnMode::Pn945, 4096).unwrap();
        let mut out_held = vec![Complex32::default(); 3000];
        still
            .process(&mut Tones, 2_100_000, &mut out_held, &mut rng)
            .unwrap();
        let apart = out
            .iter()
            .zip(&out_held)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0f32, f32::max);
        assert!(apart > 0.5, "held and drifting agree to {apart}");
        let too_fast = ChannelConfig {
            paths: vec![Path::new(0.0, 1.0, 0.0, 0.0).with_delay_rate(2e-5)],
            ..cfg
        };
        assert!(matches!(
            Channel::new(too_fast, PnMode::Pn945, 4096),
            Err(DtmbError::InvalidParameter {
                name: "delay_rate",
                ..
            })
        ));
    }

    /// The bench's six paths: distinct Dopplers, CFO and SFO, an SFN copy 30 µs late.
    fn six_paths(sfo_ppm: f64) -> ChannelConfig {
        let us = 1e-6;
        ChannelConfig {
            paths: vec![
                Path::new(5.0 * us, 1.0, 0.0, 40.0),
                Path::new(5.3 * us, 0.6, 1.0, -25.0),
                Path::new(6.1 * us, 0.4, 2.0, 12.0),
                Path::new(7.9 * us, 0.3, 3.0, -38.0),
                Path::new(12.0 * us, 0.2, 4.0, 5.0),
                Path::new(35.0 * us, 0.5, 5.0, -15.0),
            ],
            cfo_hz: 250.0,
            sfo_ppm,
            snr_db: None,
        }
    }

    #[test]
    fn frequency_domain_matches_the_time_domain_reference() {
        // A real DTMB signal, several frames, crossing sub-block and rebuild boundaries;
        // the error floor of the first-order expansion is about −60 dB (module docs of
        // fd_channel), the f32 FFTs about −120 dB.
        use crate::core::GpsTime;
        use crate::dtmb::frame::{CarrierMode, Qam};
        use crate::dtmb::transmitter::{FrameSchedule, Transmitter, TxConfig};
        for sfo in [0.0, 1.5, 40.0] {
            let mode = PnMode::Pn945;
            let tx_cfg = TxConfig {
                schedule: FrameSchedule {
                    mode,
                    t0: GpsTime::from_ns(0),
                    tower_clock_offset_s: 0.0,
                },
                carrier: CarrierMode::Multi3780,
                qam: Qam::Qam64,
                si_vector: 0,
            };
            let mut tx = Transmitter::new(tx_cfg, &mut TrialRng::new(4, 0).stream("tx"));
            let len = 3 * mode.frame_len();
            let mut fast = Channel::new(six_paths(sfo), mode, len).unwrap();
            assert!(fast.is_frequency_domain());
            let mut exact = fast.clone();
            let mut a = vec![Complex32::default(); len];
            let mut b = vec![Complex32::default(); len];
            let mut rng = TrialRng::new(1, 0).stream("n");
            for start in [1_000_000i64, 1_000_000 + len as i64] {
                fast.process(&mut tx, start, &mut a, &mut rng).unwrap();
                exact
                    .process_exact(&mut tx, start, &mut b, &mut rng)
                    .unwrap();
                let err: f64 = a
                    .iter()
                    .zip(&b)
                    .map(|(x, y)| (x - y).norm_sqr() as f64)
                    .sum();
                let pow: f64 = b.iter().map(|y| y.norm_sqr() as f64).sum();
                let db = 10.0 * (err / pow).log10();
                // The reference holds each path's delay over 256-sample sub-blocks, an
                // error of up to ε·128 samples (0.005 at 40 ppm), i.e. about
                // 20 log10(2π·0.29·ε·128/√3) dB; allow the larger of that and −50 dB.
                let hold_db = 20.0
                    * (2.0 * std::f64::consts::PI * 0.29 * sfo * 1e-6 * 128.0 / 3f64.sqrt())
                        .max(1e-9)
                        .log10();
                println!(
                    "SFO {sfo} ppm: fast vs reference {db:.1} dB (reference hold {hold_db:.1} dB)"
                );
                assert!(
                    db < (-50f64).max(hold_db + 6.0),
                    "SFO {sfo} ppm: error {db:.1} dB"
                );
            }
        }
    }

    #[test]
    fn noise_has_the_requested_snr() {
        let cfg = ChannelConfig {
            paths: vec![Path::new(0.0, 0.5, 0.0, 0.0)],
            cfo_hz: 0.0,
            sfo_ppm: 0.0,
            snr_db: Some(-3.0),
        };
        let mut ch = Channel::new(cfg, PnMode::Pn420, 50_000).unwrap();
        struct Zero;
        impl SampleSource for Zero {
            fn generate(&mut self, _: i64, out: &mut [Complex32]) {
                out.iter_mut().for_each(|o| *o = Complex32::default());
            }
        }
        let mut out = vec![Complex32::default(); 50_000];
        ch.process(&mut Zero, 0, &mut out, &mut TrialRng::new(1, 0).stream("n"))
            .unwrap();
        let p: f64 = out.iter().map(|x| x.norm_sqr() as f64).sum::<f64>() / out.len() as f64;
        let want = 0.25 * PnMode::Pn420.nominal_frame_power() / 10f64.powf(-0.3);
        assert!((p / want - 1.0).abs() < 0.03, "{p} vs {want}");
    }

    #[test]
    fn bad_configurations_are_errors() {
        let ok = Path::new(0.0, 1.0, 0.0, 0.0);
        let mk = |paths: Vec<Path>, snr: Option<f64>| {
            Channel::new(
                ChannelConfig {
                    paths,
                    cfo_hz: 0.0,
                    sfo_ppm: 0.0,
                    snr_db: snr,
                },
                PnMode::Pn945,
                100,
            )
        };
        assert!(mk(vec![], None).is_err());
        assert!(mk(vec![Path::new(-1.0, 1.0, 0.0, 0.0)], None).is_err());
        assert!(mk(vec![ok], Some(f64::NAN)).is_err());
        assert!(mk(vec![ok], Some(10.0)).is_ok());
    }

    #[test]
    fn link_budget_uses_ktb() {
        // kTB over 7.56 MHz is −135.2 dBW; 50 dBW EIRP (with the receive gain), 120 dB
        // loss, 5 dB NF → 60.2 dB.
        let snr = link_snr_db(50.0, 120.0, 5.0, 7.56e6);
        assert!((snr - 60.18).abs() < 0.05, "{snr}");
    }
}
