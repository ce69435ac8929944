//! A DTMB transmitter: the frame schedule tied to GPS time and sample generation at
//! 7.56 Msps, with optional square-root raised-cosine shaping.
//!
//! Timing assumption (UNCONFIRMED, facts.md §1): superframe 0 of a tower starts at a GPS
//! second boundary `t0` (SFN adapters align a second-frame initialisation packet to the
//! GPS 1PPS edge), and a superframe is exactly 125 ms = 945 000 samples, so eight
//! superframes fill each GPS second. Transmitter sample `m` (frame `k = ⌊m/N⌋`, `N` the
//! frame length) is emitted at
//!
//! ```text
//! t_emit(m) = t0 + m / 7.56 MHz + δ_tower,
//! ```
//!
//! with `δ_tower` the tower's clock offset from GPS time. Frame `k` of the transmitter
//! starts at `t0 + k·T_frame + δ_tower`; its index in the superframe is `k mod F` and its
//! header phase follows the schedule of [`PnMode::phase_of_frame`].

use super::data_layer::DataLayer;
use super::frame::{BodyModulator, CarrierMode, Qam};
use super::pn::{PnMode, BODY_LEN, SAMPLE_RATE_HZ, SAMPLE_RATE_HZ_INT};
use super::DtmbError;
use crate::core::GpsTime;
use num_complex::Complex32;
use rand::Rng;

/// Anything that can produce transmitter samples by absolute sample index.
pub trait SampleSource {
    /// Writes samples `start_sample .. start_sample + out.len()` into `out`.
    fn generate(&mut self, start_sample: i64, out: &mut [Complex32]);
}

/// The frame timing of one tower against GPS time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSchedule {
    /// Header mode, which fixes the frame length and the superframe.
    pub mode: PnMode,
    /// GPS time at which transmitter sample 0 (superframe 0, frame 0) would be emitted by
    /// a perfect clock; assumed to be a GPS second boundary.
    pub t0: GpsTime,
    /// The tower clock's offset from GPS time, in seconds (added to every emission time).
    pub tower_clock_offset_s: f64,
}

impl FrameSchedule {
    /// The transmitter sample at which frame `k` starts.
    pub fn frame_start_sample(&self, frame: i64) -> i64 {
        frame * self.mode.frame_len() as i64
    }

    /// Index of frame `k` within its superframe (`k mod F`).
    pub fn frame_in_superframe(&self, frame: i64) -> usize {
        frame.rem_euclid(self.mode.frames_per_superframe() as i64) as usize
    }

    /// Header phase of frame `k`.
    pub fn pn_phase(&self, frame: i64) -> usize {
        self.mode.phase_of_frame(self.frame_in_superframe(frame))
    }

    /// Emission time of sample `m` as whole nanoseconds since `t0` plus the fraction of a
    /// nanosecond, by exact integer arithmetic (`m·10⁹/7 560 000 = m·25 000/189` ns), plus
    /// the tower clock offset.
    pub fn emission_offset_ns(&self, sample: i64) -> (i64, f64) {
        let num = i128::from(sample) * 25_000;
        let whole = num.div_euclid(189);
        let frac = num.rem_euclid(189) as f64 / 189.0;
        let off_ns = self.tower_clock_offset_s * 1e9;
        let off_whole = off_ns.floor();
        let f = frac + (off_ns - off_whole);
        let carry = f.floor();
        (whole as i64 + off_whole as i64 + carry as i64, f - carry)
    }

    /// Emission time of sample `m`, rounded to the nanosecond.
    pub fn emission_time(&self, sample: i64) -> GpsTime {
        let (ns, frac) = self.emission_offset_ns(sample);
        GpsTime::from_ns(self.t0.ns() + ns + frac.round() as i64)
    }

    /// The absolute frame number whose index in the superframe is `frame_in_superframe`
    /// and whose start is closest to `approx_emission` (a receiver's estimate of the
    /// emission time, good to better than half a superframe, 62.5 ms).
    pub fn nearest_frame(&self, frame_in_superframe: usize, approx_emission: GpsTime) -> i64 {
        let f = self.mode.frames_per_superframe() as i64;
        let n = self.mode.frame_len() as i64;
        let dt_ns =
            approx_emission.ns() - self.t0.ns() - (self.tower_clock_offset_s * 1e9).round() as i64;
        // Samples since t0 (rounded), then frames.
        let samples = (i128::from(dt_ns) * i128::from(SAMPLE_RATE_HZ_INT) / 1_000_000_000) as i64;
        let k_approx = samples.div_euclid(n);
        let base = k_approx - k_approx.rem_euclid(f) + frame_in_superframe as i64;
        [base - f, base, base + f]
            .into_iter()
            .min_by_key(|&k| (k - k_approx).abs())
            .unwrap_or(base)
    }
}

/// Configuration of a transmitter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TxConfig {
    /// Frame schedule (mode, GPS tie, tower clock offset).
    pub schedule: FrameSchedule,
    /// Body carrier mode.
    pub carrier: CarrierMode,
    /// Data constellation.
    pub qam: Qam,
    /// The 32-bit system-information vector of ordinary frames. The first frame of each
    /// superframe carries vector 1 (odd superframe) or 2 (even), as the standard marks it.
    pub si_vector: u32,
}

/// Frames kept ready, so that a channel with a delay spread across frame boundaries does
/// not rebuild the same body twice.
const CACHE_FRAMES: usize = 4;

/// The random payload of one frame: SplitMix64 (G. Steele, D. Lea, C. Flood, *Fast
/// splittable pseudorandom number generators*, OOPSLA 2014; it passes BigCrush) started
/// from `mix(key ⊕ mix(k))` for frame `k`, with `mix` its output function and `key`
/// drawn once from the transmitter's named stream. The start is a hash of the frame
/// number, so the frames' sequences are unrelated and any frame can be regenerated in any
/// order with identical content. Data bits are a payload, not a secret: a cryptographic
/// generator cost a third of the frame's generation time for nothing.
struct PayloadRng(u64);

/// SplitMix64's increment (the golden ratio in 64-bit fixed point).
const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;

/// SplitMix64's output function (a bijection with full avalanche).
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl PayloadRng {
    fn for_frame(key: u64, frame: i64) -> Self {
        Self(mix64(key ^ mix64(frame as u64)))
    }
}

impl rand::RngCore for PayloadRng {
    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN);
        mix64(self.0)
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for chunk in dst.chunks_mut(8) {
            let w = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&w[..chunk.len()]);
        }
    }
}

/// A DTMB transmitter producing baseband samples at 7.56 Msps by absolute sample index.
///
/// The payload of frame `k` comes from a SplitMix64 sequence keyed by a seed drawn once
/// from the caller's stream and started at a hash of `k` (`PayloadRng`; a C = 3780 body
/// takes one word of it as the key of its per-subcarrier counter hash, see
/// [`super::frame::BodyModulator::modulate`]), so any frame
/// can be regenerated in any order with identical content.
pub struct Transmitter {
    cfg: TxConfig,
    payload_key: u64,
    body: BodyModulator,
    headers: Vec<Vec<Complex32>>,
    cache: Vec<(i64, Vec<Complex32>)>,
    next_slot: usize,
    /// The GB 20600 data layer when the bodies carry a transport stream, the next frame
    /// it encodes, its logical-symbol buffer and the first error it met.
    data: Option<DataBodies>,
}

/// Frame bodies from a [`DataLayer`]: frame `k ≥ 0` carries the layer's `k`-th body.
struct DataBodies {
    layer: Box<DataLayer>,
    next_frame: i64,
    first: bool,
    logical: Vec<Complex32>,
    error: Option<DtmbError>,
}

impl std::fmt::Debug for Transmitter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transmitter")
            .field("cfg", &self.cfg)
            .finish_non_exhaustive()
    }
}

impl Transmitter {
    /// Builds a transmitter; the payload seed is drawn from `rng`.
    pub fn new<R: Rng + ?Sized>(cfg: TxConfig, rng: &mut R) -> Self {
        let mode = cfg.schedule.mode;
        let payload_key: u64 = rng.random();
        let headers = (0..mode.period())
            .map(|p| {
                let mut h = vec![Complex32::default(); mode.header_len()];
                // Phases below the period are always valid for the cyclic modes; PN595
                // only ever asks for phase 0, so an error leaves an unused zero header.
                if mode.header_samples(p, &mut h).is_err() {
                    h.clear();
                }
                h
            })
            .collect();
        Self {
            cfg,
            payload_key,
            body: BodyModulator::new(),
            headers,
            cache: (0..CACHE_FRAMES)
                .map(|_| (i64::MIN, vec![Complex32::default(); mode.frame_len()]))
                .collect(),
            next_slot: 0,
            data: None,
        }
    }

    /// A transmitter whose frames `0, 1, …` carry the bodies of `layer` (a transport
    /// stream through the GB 20600 data layer) instead of random payloads. The data layer
    /// is sequential: frames must be asked for in increasing order, apart from the few
    /// frames the cache keeps; a frame before the first data frame (a channel's
    /// look-back) or one asked for again after it left the cache gets a random body. The
    /// carrier mode is the layer's.
    pub fn with_data_layer<R: Rng + ?Sized>(cfg: TxConfig, layer: DataLayer, rng: &mut R) -> Self {
        Self::with_data_layer_from(cfg, layer, Some(0), rng)
    }

    /// [`Transmitter::with_data_layer`] whose first data frame is `start`, or with `None`
    /// the first frame asked for (a world recording starts anywhere in the schedule).
    pub fn with_data_layer_from<R: Rng + ?Sized>(
        cfg: TxConfig,
        layer: DataLayer,
        start: Option<i64>,
        rng: &mut R,
    ) -> Self {
        let mut cfg = cfg;
        cfg.carrier = layer.profile().carrier;
        let mut t = Self::new(cfg, rng);
        t.data = Some(DataBodies {
            layer: Box::new(layer),
            next_frame: start.unwrap_or(0),
            first: start.is_none(),
            logical: vec![Complex32::default(); BODY_LEN],
            error: None,
        });
        t
    }

    /// The data layer, when the transmitter has one.
    pub fn data_layer(&self) -> Option<&DataLayer> {
        self.data.as_ref().map(|d| &*d.layer)
    }

    /// The first error of the data layer (a payload that failed to read), taken.
    pub fn take_error(&mut self) -> Option<DtmbError> {
        self.data.as_mut().and_then(|d| d.error.take())
    }

    /// The configuration.
    pub fn config(&self) -> &TxConfig {
        &self.cfg
    }

    /// The frame schedule.
    pub fn schedule(&self) -> &FrameSchedule {
        &self.cfg.schedule
    }

    fn frame_slot(&mut self, frame: i64) -> usize {
        if let Some(i) = self.cache.iter().position(|(k, _)| *k == frame) {
            return i;
        }
        let slot = self.next_slot;
        self.next_slot = (self.next_slot + 1) % CACHE_FRAMES;
        let sched = self.cfg.schedule;
        let mode = sched.mode;
        let h = mode.header_len();
        let phase = sched.pn_phase(frame);
        let f = mode.frames_per_superframe() as i64;
        let si = if frame.rem_euclid(f) == 0 {
            if frame.div_euclid(f).rem_euclid(2) == 1 {
                1
            } else {
                2
            }
        } else {
            self.cfg.si_vector
        };
        let buf = &mut self.cache[slot].1;
        buf[..h].copy_from_slice(&self.headers[phase]);
        let data_frame = match &mut self.data {
            Some(d) if frame >= d.next_frame || d.first => {
                if d.first {
                    // The layer's first body goes to the first frame asked for (a world
                    // recording starts anywhere in the tower's schedule).
                    d.first = false;
                    d.next_frame = frame;
                }
                // Frames skipped over are encoded and dropped, so the stream stays whole.
                let si_index = d.layer.profile().si_index();
                while d.next_frame <= frame {
                    let k = d.next_frame;
                    let si = if k.rem_euclid(f) == 0 {
                        if k.div_euclid(f).rem_euclid(2) == 1 {
                            1
                        } else {
                            2
                        }
                    } else {
                        si_index
                    };
                    if let Err(e) = d.layer.next_frame(si, &mut d.logical) {
                        d.error.get_or_insert(e);
                        d.logical.fill(Complex32::default());
                    }
                    d.next_frame += 1;
                }
                // The body length is fixed by construction, so this cannot fail.
                let _ = self.body.modulate_logical(
                    self.cfg.carrier,
                    &d.logical,
                    &mut buf[h..h + BODY_LEN],
                );
                true
            }
            _ => false,
        };
        if !data_frame {
            let mut rng = PayloadRng::for_frame(self.payload_key, frame);
            // The body length is fixed by construction, so modulate cannot fail here.
            let _ = self.body.modulate(
                self.cfg.carrier,
                self.cfg.qam,
                si,
                &mut rng,
                &mut buf[h..h + BODY_LEN],
            );
        }
        self.cache[slot].0 = frame;
        slot
    }
}

impl SampleSource for Transmitter {
    /// Writes transmitter samples `start_sample ..` into `out` (7.56 Msps, unit-power body).
    fn generate(&mut self, start_sample: i64, out: &mut [Complex32]) {
        let n = self.cfg.schedule.mode.frame_len() as i64;
        let mut pos = 0usize;
        while pos < out.len() {
            let m = start_sample + pos as i64;
            let frame = m.div_euclid(n);
            let off = m.rem_euclid(n) as usize;
            let take = (n as usize - off).min(out.len() - pos);
            let slot = self.frame_slot(frame);
            out[pos..pos + take].copy_from_slice(&self.cache[slot].1[off..off + take]);
            pos += take;
        }
    }
}

/// Square-root raised-cosine pulse at `oversampling` samples per symbol, roll-off
/// `rolloff` (GB 20600-2006 uses 0.05 — UNCONFIRMED), truncated to `span_symbols` symbols
/// and scaled to unit energy per symbol (`Σ h² = L`), so an interpolated unit-power
/// symbol stream keeps unit power:
///
/// ```text
/// h(t) = [sin(π t(1−α)) + 4α t cos(π t(1+α))] / [π t (1 − (4α t)²)],  t in symbols.
/// ```
pub fn srrc_taps(oversampling: usize, rolloff: f64, span_symbols: usize) -> Vec<f64> {
    let l = oversampling as f64;
    let len = span_symbols * oversampling + 1;
    let mid = (len / 2) as f64;
    let a = rolloff;
    let mut h: Vec<f64> = (0..len)
        .map(|i| {
            let t = (i as f64 - mid) / l;
            if t.abs() < 1e-12 {
                1.0 - a + 4.0 * a / std::f64::consts::PI
            } else if a > 0.0 && ((4.0 * a * t).abs() - 1.0).abs() < 1e-9 {
                let pi = std::f64::consts::PI;
                a / 2f64.sqrt()
                    * ((1.0 + 2.0 / pi) * (pi / (4.0 * a)).sin()
                        + (1.0 - 2.0 / pi) * (pi / (4.0 * a)).cos())
            } else {
                let pi = std::f64::consts::PI;
                ((pi * t * (1.0 - a)).sin() + 4.0 * a * t * (pi * t * (1.0 + a)).cos())
                    / (pi * t * (1.0 - (4.0 * a * t).powi(2)))
            }
        })
        .collect();
    let e: f64 = h.iter().map(|x| x * x).sum();
    let s = (l / e).sqrt();
    h.iter_mut().for_each(|x| *x *= s);
    h
}

/// A streaming polyphase SRRC interpolator (7.56 Msps → L × 7.56 Msps). Its group delay
/// is `span_symbols/2` symbols, i.e. output sample `L·m + L·span/2` carries input `m`.
#[derive(Clone, Debug)]
pub struct SrrcInterpolator {
    oversampling: usize,
    /// Polyphase taps: `phases[q][j] = h[j·L + q]`.
    phases: Vec<Vec<f32>>,
    history: Vec<Complex32>,
}

impl SrrcInterpolator {
    /// Builds the interpolator.
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] for a zero oversampling factor or span, or a
    /// roll-off outside (0, 1].
    pub fn new(oversampling: usize, rolloff: f64, span_symbols: usize) -> Result<Self, DtmbError> {
        if oversampling == 0 || span_symbols == 0 {
            return Err(DtmbError::InvalidParameter {
                name: "oversampling",
                reason: "oversampling factor and filter span must be at least 1".into(),
            });
        }
        if !(rolloff > 0.0 && rolloff <= 1.0) {
            return Err(DtmbError::InvalidParameter {
                name: "rolloff",
                reason: format!("must lie in (0, 1], got {rolloff}"),
            });
        }
        let h = srrc_taps(oversampling, rolloff, span_symbols);
        let per_phase = h.len().div_ceil(oversampling);
        let phases = (0..oversampling)
            .map(|q| {
                (0..per_phase)
                    .map(|j| h.get(j * oversampling + q).copied().unwrap_or(0.0) as f32)
                    .collect()
            })
            .collect();
        Ok(Self {
            oversampling,
            phases,
            history: vec![Complex32::default(); per_phase],
        })
    }

    /// Group delay in output samples.
    pub fn delay_samples(&self) -> usize {
        (self.phases[0].len() - 1) * self.oversampling / 2
    }

    /// Interpolates `input` into `out` (length `input.len() · L`), continuing the stream
    /// from the previous call.
    ///
    /// # Errors
    /// [`DtmbError::BufferLength`] when `out` has the wrong length.
    pub fn process(&mut self, input: &[Complex32], out: &mut [Complex32]) -> Result<(), DtmbError> {
        let l = self.oversampling;
        if out.len() != input.len() * l {
            return Err(DtmbError::BufferLength {
                what: "SRRC output",
                expected: input.len() * l,
                got: out.len(),
            });
        }
        for (m, &x) in input.iter().enumerate() {
            // The history is a short delay line (span + 1 symbols); rotating it is cheaper
            // than indexing a ring buffer in the inner loop.
            self.history.rotate_right(1);
            self.history[0] = x;
            for q in 0..l {
                let ph = &self.phases[q];
                let mut acc = Complex32::default();
                for (hj, pj) in self.history.iter().zip(ph) {
                    acc += hj * pj;
                }
                out[m * l + q] = acc;
            }
        }
        Ok(())
    }
}

/// The emission rate helper: samples per second of a transmitter at oversampling `l`.
pub fn output_rate_hz(oversampling: usize) -> f64 {
    SAMPLE_RATE_HZ * oversampling as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    fn tx(mode: PnMode) -> Transmitter {
        let cfg = TxConfig {
            schedule: FrameSchedule {
                mode,
                t0: GpsTime::from_ns(1_000_000_000_000_000_000),
                tower_clock_offset_s: 0.0,
            },
            carrier: CarrierMode::Multi3780,
            qam: Qam::Qam16,
            si_vector: 0,
        };
        Transmitter::new(cfg, &mut TrialRng::new(1, 0).stream("dtmb/tx"))
    }

    #[test]
    fn superframe_is_125_ms_in_every_mode() {
        for mode in PnMode::ALL {
            assert_eq!(
                mode.frame_len() * mode.frames_per_superframe(),
                super::super::pn::SUPERFRAME_SAMPLES
            );
            let s = FrameSchedule {
                mode,
                t0: GpsTime::from_ns(0),
                tower_clock_offset_s: 0.0,
            };
            let k = mode.frames_per_superframe() as i64;
            assert_eq!(s.emission_time(s.frame_start_sample(k)).ns(), 125_000_000);
        }
    }

    #[test]
    fn generation_is_random_access_and_frames_carry_their_headers() {
        let mut t = tx(PnMode::Pn945);
        let n = PnMode::Pn945.frame_len();
        let mut a = vec![Complex32::default(); 3 * n];
        t.generate(0, &mut a);
        // Regenerate the middle in a different order and through an evicted cache.
        let mut b = vec![Complex32::default(); n + 100];
        t.generate(10 * n as i64, &mut b);
        t.generate(n as i64 - 50, &mut b);
        assert_eq!(&a[n - 50..2 * n + 50], &b[..]);
        let mut h = vec![Complex32::default(); 945];
        PnMode::Pn945
            .header_samples(PnMode::Pn945.phase_of_frame(2), &mut h)
            .unwrap();
        assert_eq!(&a[2 * n..2 * n + 945], &h[..]);
    }

    #[test]
    fn nearest_frame_finds_the_absolute_number() {
        let s = FrameSchedule {
            mode: PnMode::Pn420,
            t0: GpsTime::from_ns(0),
            tower_clock_offset_s: 3e-6,
        };
        let k = 225 * 17 + 40;
        let t = s.emission_time(s.frame_start_sample(k)).add_seconds(0.02);
        assert_eq!(s.nearest_frame(40, t), k);
    }

    #[test]
    fn srrc_keeps_power_and_delays_by_half_the_span() {
        let mut f = SrrcInterpolator::new(4, 0.05, 32).unwrap();
        let mut rng = TrialRng::new(2, 0).stream("dtmb/srrc");
        let x: Vec<Complex32> = (0..4000)
            .map(|_| Complex32::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5))
            .collect();
        let mut y = vec![Complex32::default(); 16000];
        f.process(&x, &mut y).unwrap();
        let px: f32 = x.iter().map(|v| v.norm_sqr()).sum::<f32>() / 4000.0;
        let py: f32 = y[400..].iter().map(|v| v.norm_sqr()).sum::<f32>() / (y.len() - 400) as f32;
        assert!((py / px - 1.0).abs() < 0.05, "power ratio {}", py / px);
        assert_eq!(f.delay_samples(), 64);
        assert!(SrrcInterpolator::new(0, 0.05, 8).is_err());
        assert!(SrrcInterpolator::new(2, 1.5, 8).is_err());
    }
}
