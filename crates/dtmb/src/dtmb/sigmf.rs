//! SigMF recordings of generated DTMB baseband (SigMF specification v1.0.0): a
//! `BASE.sigmf-data` file of interleaved little-endian I/Q samples and a
//! `BASE.sigmf-meta` JSON file with the `global`, `captures` and `annotations` objects.
//!
//! Both files are written atomically (temporary file, fsync, rename). `ci8` samples are
//! scaled so the largest component maps to ±127; the scale is recorded under the
//! non-core key `hybridnav:ci8_scale` so the reader can restore the amplitude.

use super::channel::Channel;
use super::frame::{CarrierMode, Qam};
use super::pn::{PnMode, SAMPLE_RATE_HZ};
use super::transmitter::{FrameSchedule, SrrcInterpolator, Transmitter, TxConfig};
use super::DtmbError;
use crate::core::{GpsTime, TrialRng};
use crate::dtmb::multipath::{ChannelConfig, Path as ChannelPath};
use crate::io::atomic::AtomicFile;
use num_complex::Complex32;
use serde_json::{json, Map, Value};
use std::io::Write;
use std::path::Path;

/// Sample format of the data file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleFormat {
    /// 32-bit float I and Q, little-endian (`cf32_le`).
    Cf32,
    /// 8-bit signed I and Q (`ci8`).
    Ci8,
}

impl SampleFormat {
    /// The SigMF `core:datatype` string.
    pub fn datatype(self) -> &'static str {
        match self {
            SampleFormat::Cf32 => "cf32_le",
            SampleFormat::Ci8 => "ci8",
        }
    }
}

/// A SigMF annotation: a labelled span of samples.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Annotation {
    /// First sample of the span.
    pub sample_start: u64,
    /// Number of samples.
    pub sample_count: u64,
    /// Label, e.g. `frame 12 PN945 phase 5`.
    pub label: String,
}

/// A recording read back by [`read_sigmf`].
#[derive(Clone, Debug, PartialEq)]
pub struct SigmfRecording {
    /// The samples (ci8 rescaled by the recorded scale).
    pub samples: Vec<Complex32>,
    /// The data format.
    pub format: SampleFormat,
    /// `core:sample_rate`.
    pub sample_rate_hz: f64,
    /// `core:frequency` of the first capture.
    pub center_freq_hz: f64,
    /// The annotations.
    pub annotations: Vec<Annotation>,
}

fn with_ext(base: &Path, ext: &str) -> std::path::PathBuf {
    let mut s = base.as_os_str().to_owned();
    s.push(ext);
    s.into()
}

/// Writes `BASE.sigmf-data` and `BASE.sigmf-meta`.
///
/// # Errors
/// [`DtmbError::InvalidParameter`] for a non-positive or non-finite rate or frequency, or
/// non-finite samples; [`DtmbError::Io`] when a file cannot be written.
pub fn write_sigmf(
    base: &Path,
    samples: &[Complex32],
    format: SampleFormat,
    sample_rate_hz: f64,
    center_freq_hz: f64,
    annotations: &[Annotation],
) -> Result<(), DtmbError> {
    write_sigmf_with(
        base,
        samples,
        format,
        sample_rate_hz,
        center_freq_hz,
        annotations,
        &Map::new(),
        &[],
    )
}

/// As [`write_sigmf`], with extra keys: `global_extra` is merged into the `global` object
/// (overriding the defaults, e.g. `core:description`), and `annotation_extra[i]` into
/// annotation `i` (namespaced keys such as `hybridnav:frame`; missing entries add nothing).
///
/// # Errors
/// As [`write_sigmf`].
#[allow(clippy::too_many_arguments)]
pub fn write_sigmf_with(
    base: &Path,
    samples: &[Complex32],
    format: SampleFormat,
    sample_rate_hz: f64,
    center_freq_hz: f64,
    annotations: &[Annotation],
    global_extra: &Map<String, Value>,
    annotation_extra: &[Map<String, Value>],
) -> Result<(), DtmbError> {
    let mut w = SigmfWriter::create(
        base,
        format,
        sample_rate_hz,
        center_freq_hz,
        peak_component(samples),
    )?;
    w.write(samples)?;
    w.finish(annotations.iter().cloned(), annotation_extra, global_extra)
}

/// The largest `|I|` or `|Q|` of `samples` (0 for none): what a `ci8` recording's scale
/// maps to ±127. The maximum does not depend on the order, so a recording's peak is the
/// maximum of its blocks' peaks.
pub fn peak_component(samples: &[Complex32]) -> f32 {
    samples
        .iter()
        .fold(0.0f32, |m, s| m.max(s.re.abs()).max(s.im.abs()))
}

/// The `ci8` scale of a recording whose peak component is `peak`: `127 / peak`, or 1 for
/// a silent recording.
fn ci8_scale(peak: f32) -> f32 {
    if peak > 0.0 {
        127.0 / peak
    } else {
        1.0
    }
}

/// A SigMF recording written as a stream: the samples go block by block to a temporary
/// `BASE.sigmf-data` (through a reused byte buffer, so memory stays flat whatever the
/// length), and [`SigmfWriter::finish`] publishes it atomically (fsync, rename), then
/// writes `BASE.sigmf-meta` atomically, streaming the annotations into the JSON. Data
/// first: a reader that finds the metadata finds complete data beside it. Dropped before
/// `finish` (an error), it removes the temporary file and leaves no recording.
///
/// The files are byte-identical to the ones an in-memory writer makes of the same
/// samples (the `ci8` scale needs the whole recording's peak up front: a caller makes
/// two passes, the first only for [`peak_component`]).
#[derive(Debug)]
pub struct SigmfWriter {
    base: std::path::PathBuf,
    format: SampleFormat,
    sample_rate_hz: f64,
    center_freq_hz: f64,
    scale: f32,
    data: AtomicFile,
    bytes: Vec<u8>,
    samples: u64,
}

impl SigmfWriter {
    /// Starts `BASE.sigmf-data`; `peak` is the whole recording's [`peak_component`] (used by
    /// `ci8` only; pass 0 for `cf32`).
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] for a non-positive or non-finite rate or frequency;
    /// [`DtmbError::Io`] when the temporary file cannot be created.
    pub fn create(
        base: &Path,
        format: SampleFormat,
        sample_rate_hz: f64,
        center_freq_hz: f64,
        peak: f32,
    ) -> Result<Self, DtmbError> {
        if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0 && center_freq_hz.is_finite()) {
            return Err(DtmbError::InvalidParameter {
                name: "sample_rate_hz/center_freq_hz",
                reason: format!(
                    "rate must be positive and both finite, got {sample_rate_hz} and {center_freq_hz}"
                ),
            });
        }
        let p = with_ext(base, ".sigmf-data");
        let data = AtomicFile::create(&p).map_err(|e| DtmbError::Io {
            path: p.display().to_string(),
            source: e,
        })?;
        Ok(Self {
            base: base.to_path_buf(),
            format,
            sample_rate_hz,
            center_freq_hz,
            scale: ci8_scale(peak),
            data,
            bytes: Vec::new(),
            samples: 0,
        })
    }

    /// Samples written so far.
    pub fn samples_written(&self) -> u64 {
        self.samples
    }

    /// Appends `samples` to the data file.
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] for a NaN or infinite sample (the recording is then
    /// abandoned: nothing is published), [`DtmbError::Io`] when the write fails.
    pub fn write(&mut self, samples: &[Complex32]) -> Result<(), DtmbError> {
        if samples
            .iter()
            .any(|s| !s.re.is_finite() || !s.im.is_finite())
        {
            return Err(DtmbError::InvalidParameter {
                name: "samples",
                reason: "contain NaN or infinity".into(),
            });
        }
        self.bytes.clear();
        match self.format {
            SampleFormat::Cf32 => {
                for s in samples {
                    self.bytes.extend_from_slice(&s.re.to_le_bytes());
                    self.bytes.extend_from_slice(&s.im.to_le_bytes());
                }
            }
            SampleFormat::Ci8 => {
                let scale = self.scale;
                let q = |x: f32| (x * scale).round().clamp(-127.0, 127.0) as i8 as u8;
                for s in samples {
                    self.bytes.push(q(s.re));
                    self.bytes.push(q(s.im));
                }
            }
        }
        self.data
            .write_all(&self.bytes)
            .map_err(|e| DtmbError::Io {
                path: self.data.path().display().to_string(),
                source: self.data.error(e),
            })?;
        self.samples += samples.len() as u64;
        Ok(())
    }

    /// Publishes the data file, then writes the metadata: `annotations` (sorted by sample,
    /// as SigMF lists them) with `annotation_extra[i]` merged into annotation `i`, and
    /// `global_extra` into the `global` object (as [`write_sigmf_with`]).
    ///
    /// # Errors
    /// [`DtmbError::Io`] when a file cannot be written, [`DtmbError::Sigmf`] when the
    /// metadata cannot be serialised.
    pub fn finish<I: Iterator<Item = Annotation>>(
        self,
        annotations: I,
        annotation_extra: &[Map<String, Value>],
        global_extra: &Map<String, Value>,
    ) -> Result<(), DtmbError> {
        let mut global = json!({
            "core:datatype": self.format.datatype(),
            "core:sample_rate": self.sample_rate_hz,
            "core:version": "1.0.0",
            "core:description": "DTMB (GB 20600-2006) baseband generated by hybridnav",
            "core:recorder": "hybridnav",
        });
        if self.format == SampleFormat::Ci8 {
            global["hybridnav:ci8_scale"] = json!(self.scale);
        }
        for (k, v) in global_extra {
            global[k] = v.clone();
        }
        let captures = json!([{"core:sample_start": 0, "core:frequency": self.center_freq_hz}]);
        let data_path = self.data.path().display().to_string();
        self.data.commit().map_err(|e| DtmbError::Io {
            path: data_path,
            source: e,
        })?;
        let meta_path = with_ext(&self.base, ".sigmf-meta");
        let io = |e: std::io::Error| DtmbError::Io {
            path: meta_path.display().to_string(),
            source: e,
        };
        let mut f = AtomicFile::create(&meta_path).map_err(io)?;
        let doc = MetaDocument {
            global: &global,
            captures: &captures,
            annotations: std::cell::RefCell::new(Some(annotations.enumerate().map(|(i, a)| {
                let mut v = json!({"core:sample_start": a.sample_start, "core:sample_count": a.sample_count, "core:label": a.label});
                for (k, x) in annotation_extra.get(i).into_iter().flatten() {
                    v[k] = x.clone();
                }
                v
            }))),
        };
        let mut ser =
            serde_json::Serializer::with_formatter(&mut f, serde_json::ser::PrettyFormatter::new());
        serde::Serialize::serialize(&doc, &mut ser).map_err(|e| DtmbError::Sigmf {
            path: self.base.display().to_string(),
            reason: e.to_string(),
        })?;
        f.commit().map_err(io)
    }
}

/// The metadata document `{"annotations": [...], "captures": [...], "global": {...}}`,
/// its keys in the order `serde_json` sorts a map's (so the text is the same as the
/// pretty-printed `Value`), the annotations serialised one at a time from an iterator
/// rather than held as one JSON tree (a long recording has one per frame).
struct MetaDocument<'a, I> {
    global: &'a Value,
    captures: &'a Value,
    annotations: std::cell::RefCell<Option<I>>,
}

/// The annotation array, drawn from the iterator (once).
struct AnnotationSeq<'a, I>(&'a std::cell::RefCell<Option<I>>);

impl<I: Iterator<Item = Value>> serde::Serialize for AnnotationSeq<'_, I> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = s.serialize_seq(None)?;
        if let Some(it) = self.0.borrow_mut().take() {
            for v in it {
                seq.serialize_element(&v)?;
            }
        }
        seq.end()
    }
}

impl<I: Iterator<Item = Value>> serde::Serialize for MetaDocument<'_, I> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(3))?;
        m.serialize_entry("annotations", &AnnotationSeq(&self.annotations))?;
        m.serialize_entry("captures", self.captures)?;
        m.serialize_entry("global", self.global)?;
        m.end()
    }
}

/// Reads a recording written by [`write_sigmf`] (or any SigMF v1 recording in `cf32_le`
/// or `ci8` with one capture).
///
/// # Errors
/// [`DtmbError::Io`] for unreadable files, [`DtmbError::Sigmf`] for missing or malformed
/// fields, an unsupported datatype or a data file whose size is not whole samples.
pub fn read_sigmf(base: &Path) -> Result<SigmfRecording, DtmbError> {
    let meta_path = with_ext(base, ".sigmf-meta");
    let data_path = with_ext(base, ".sigmf-data");
    let mp = meta_path.display().to_string();
    let bad = |reason: String| DtmbError::Sigmf {
        path: mp.clone(),
        reason,
    };
    let text =
        crate::io::read::read_bytes(&meta_path, crate::io::read::SIGMF_META).map_err(|e| {
            DtmbError::Io {
                path: mp.clone(),
                source: e,
            }
        })?;
    let meta: Value = serde_json::from_slice(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let global = meta
        .get("global")
        .ok_or_else(|| bad("no \"global\" object".into()))?;
    let dt = global
        .get("core:datatype")
        .and_then(Value::as_str)
        .ok_or_else(|| bad("no core:datatype".into()))?;
    let format = match dt {
        "cf32_le" => SampleFormat::Cf32,
        "ci8" => SampleFormat::Ci8,
        other => {
            return Err(bad(format!(
                "datatype {other:?} not supported (cf32_le, ci8)"
            )))
        }
    };
    let sample_rate_hz = global
        .get("core:sample_rate")
        .and_then(Value::as_f64)
        .ok_or_else(|| bad("no core:sample_rate".into()))?;
    let center_freq_hz = meta
        .get("captures")
        .and_then(|c| c.get(0))
        .and_then(|c| c.get("core:frequency"))
        .and_then(Value::as_f64)
        .ok_or_else(|| bad("no captures[0].core:frequency".into()))?;
    let mut annotations = Vec::new();
    if let Some(list) = meta.get("annotations").and_then(Value::as_array) {
        for (i, a) in list.iter().enumerate() {
            let field = |k: &str| {
                a.get(k)
                    .and_then(Value::as_u64)
                    .ok_or_else(|| bad(format!("annotation {i}: no {k}")))
            };
            annotations.push(Annotation {
                sample_start: field("core:sample_start")?,
                sample_count: field("core:sample_count")?,
                label: a
                    .get("core:label")
                    .and_then(Value::as_str)
                    .unwrap_or("")
                    .to_string(),
            });
        }
    }
    let bytes =
        crate::io::read::read_bytes(&data_path, crate::io::read::SIGMF_DATA).map_err(|e| {
            DtmbError::Io {
                path: data_path.display().to_string(),
                source: e,
            }
        })?;
    let samples = match format {
        SampleFormat::Cf32 => {
            if bytes.len() % 8 != 0 {
                return Err(bad(format!(
                    "data file has {} bytes, not whole cf32 samples",
                    bytes.len()
                )));
            }
            bytes
                .chunks_exact(8)
                .map(|c| {
                    Complex32::new(
                        f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                        f32::from_le_bytes([c[4], c[5], c[6], c[7]]),
                    )
                })
                .collect()
        }
        SampleFormat::Ci8 => {
            if bytes.len() % 2 != 0 {
                return Err(bad(format!(
                    "data file has {} bytes, not whole ci8 samples",
                    bytes.len()
                )));
            }
            let scale = global
                .get("hybridnav:ci8_scale")
                .and_then(Value::as_f64)
                .unwrap_or(1.0) as f32;
            bytes
                .chunks_exact(2)
                .map(|c| Complex32::new(c[0] as i8 as f32 / scale, c[1] as i8 as f32 / scale))
                .collect()
        }
    };
    Ok(SigmfRecording {
        samples,
        format,
        sample_rate_hz,
        center_freq_hz,
        annotations,
    })
}

/// Generates `frames` DTMB frames (C = 3780, 64QAM, superframe 0 from frame 0) in AWGN
/// at `snr_db` over the 7.56 MHz band, optionally SRRC-shaped (roll-off 0.05,
/// UNCONFIRMED) at `oversampling` samples per symbol, with one annotation per frame.
/// The randomness comes from the named streams `dtmb/payload` and `dtmb/noise` of
/// `TrialRng::new(seed, 0)`. With oversampling the filter's group delay is removed, so
/// frame `k` starts at output sample `k · N · L`.
///
/// # Errors
/// [`DtmbError::InvalidParameter`] for zero frames, more than 10⁶ frames, a non-finite
/// SNR or an oversampling factor outside 1..=16.
pub fn generate_iq(
    mode: PnMode,
    frames: usize,
    snr_db: f64,
    oversampling: usize,
    seed: u64,
) -> Result<(Vec<Complex32>, Vec<Annotation>), DtmbError> {
    generate_iq_with(mode, frames, snr_db, oversampling, seed, None)
}

/// [`generate_iq`] with the frame bodies of a GB 20600 data layer (a transport stream
/// through the whole transmitter) when `data` is given: frame `k` of the recording carries
/// the layer's `k`-th body, and every annotation names the profile. The whole recording
/// is held in memory: [`write_iq_sigmf`] streams it to a file instead.
///
/// # Errors
/// As [`generate_iq`], and the data layer's errors (a payload that fails to read).
pub fn generate_iq_with(
    mode: PnMode,
    frames: usize,
    snr_db: f64,
    oversampling: usize,
    seed: u64,
    data: Option<super::data_layer::DataLayer>,
) -> Result<(Vec<Complex32>, Vec<Annotation>), DtmbError> {
    let profile = data.as_ref().map(|d| *d.profile());
    let rec = AwgnRecording::new(mode, frames, snr_db, oversampling, seed);
    let mut samples = Vec::new();
    stream_iq(&rec, data, &mut |b| {
        samples.extend_from_slice(b);
        Ok(())
    })?;
    let annotations = iq_annotations(&rec, profile.as_ref()).collect();
    Ok((samples, annotations))
}

/// What [`stream_iq`] records: `frames` frames of `mode` through white noise at `snr_db`
/// over the 7.56 MHz band, `oversampling` samples a symbol, the named random streams of
/// `seed`, heard by a receiver whose oscillator is off by `rx_oscillator_ppm`.
///
/// **The receiver's oscillator.** One oscillator error `ε = rx_oscillator_ppm·10⁻⁶`
/// drives both the mixer and the sampling clock of a receiver: it mixes down with
/// `f_c(1 + ε)` and samples at `f_s(1 + ε)`. The recording then carries the carrier
/// offset `Δf = −ε f_c` and takes transmitter sample `m` at receiver sample `m(1 + ε)`
/// ([`ChannelConfig::from_oscillators`] with a perfect transmitter, the channel's
/// `x(n/(1 + ε))`), so frame `k` starts at receiver sample `k N (1 + ε)`: `ε N`
/// samples later each frame (Speth, Fechtel, Fock & Meyr, "Optimum receiver design for
/// wireless broad-band systems using OFDM — Part I", IEEE Trans. Commun. 47(11), 1999,
/// §III: the carrier and sampling offsets of one oscillator). A ±2 ppm TCXO is the
/// common grade (IQD, "Specifying TCXOs", stability code G): −964 Hz and 0.0095 samples
/// a PN945 frame at 482 MHz. With `ε = 0` the recording is the one without an
/// oscillator, sample for sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AwgnRecording {
    /// Frame header mode.
    pub mode: PnMode,
    /// Number of frames.
    pub frames: usize,
    /// SNR over the 7.56 MHz band (dB).
    pub snr_db: f64,
    /// Output samples a symbol (SRRC shaping when > 1).
    pub oversampling: usize,
    /// Seed of the named streams `dtmb/payload` and `dtmb/noise`.
    pub seed: u64,
    /// The receiver oscillator's error ε in ppm (|ε| ≤ 100).
    pub rx_oscillator_ppm: f64,
    /// The carrier the recording is centred on (Hz), which the oscillator's carrier
    /// offset `−ε f_c` is taken at.
    pub center_freq_hz: f64,
}

impl AwgnRecording {
    /// A recording with a perfect receiver oscillator (the carrier is then irrelevant).
    pub fn new(mode: PnMode, frames: usize, snr_db: f64, oversampling: usize, seed: u64) -> Self {
        Self {
            mode,
            frames,
            snr_db,
            oversampling,
            seed,
            rx_oscillator_ppm: 0.0,
            center_freq_hz: 0.0,
        }
    }

    /// The same recording heard through an oscillator `ppm` off, at carrier `center_freq_hz`.
    pub fn with_oscillator(self, ppm: f64, center_freq_hz: f64) -> Self {
        Self {
            rx_oscillator_ppm: ppm,
            center_freq_hz,
            ..self
        }
    }

    /// The (fractional) receiver sample at which frame `k` starts, before oversampling.
    pub fn frame_start_sample(&self, k: usize) -> f64 {
        (k * self.mode.frame_len()) as f64 * (1.0 + self.rx_oscillator_ppm * 1e-6)
    }

    /// The recording's length in output samples: `frames · N · L`, as without an offset
    /// (the receiver records for as many of its own sample periods).
    pub fn samples(&self) -> u64 {
        (self.frames * self.mode.frame_len() * self.oversampling) as u64
    }

    fn validate(&self) -> Result<(), DtmbError> {
        let (frames, snr_db, oversampling) = (self.frames, self.snr_db, self.oversampling);
        if frames == 0 || frames > MAX_IQ_FRAMES {
            return Err(DtmbError::InvalidParameter {
                name: "frames",
                reason: format!("must lie in 1..={MAX_IQ_FRAMES}, got {frames}"),
            });
        }
        if !snr_db.is_finite() {
            return Err(DtmbError::InvalidParameter {
                name: "snr_db",
                reason: format!("must be finite, got {snr_db}"),
            });
        }
        if !(1..=16).contains(&oversampling) {
            return Err(DtmbError::InvalidParameter {
                name: "oversampling",
                reason: format!("must lie in 1..=16, got {oversampling}"),
            });
        }
        let (ppm, f_c) = (self.rx_oscillator_ppm, self.center_freq_hz);
        if !crate::dtmb::multipath::rx_oscillator_ppm_valid(ppm) {
            return Err(DtmbError::InvalidParameter {
                name: "rx_oscillator_ppm",
                reason: format!("must be a finite error of at most 100 ppm, got {ppm}"),
            });
        }
        if ppm != 0.0 && !(f_c.is_finite() && f_c > 0.0) {
            return Err(DtmbError::InvalidParameter {
                name: "center_freq_hz",
                reason: format!("an oscillator offset needs the carrier, got {f_c} Hz"),
            });
        }
        Ok(())
    }
}

/// Most frames [`stream_iq`] makes: 10⁶ frames, 555 to 625 s of signal (≤ 38 GB of
/// `cf32` at 7.56 Msps). The bound is on the output file, not on memory, which stays
/// flat.
pub const MAX_IQ_FRAMES: usize = 1_000_000;

/// The samples of `rec` (as [`generate_iq_with`] makes them) handed to `sink` frame by
/// frame (with oversampling, `N · L` output samples a call, the filter's delay removed),
/// in order, so memory stays flat whatever the length. The frame `k` starts at output
/// sample `k · N · L` (`k N (1 + ε) L` through an oscillator off by `ε`), as in the
/// in-memory form, and the samples are bit-identical to it.
///
/// # Errors
/// As [`generate_iq_with`] (at most [`MAX_IQ_FRAMES`] frames), and the first error of
/// `sink`, which stops the stream.
pub fn stream_iq(
    rec: &AwgnRecording,
    data: Option<super::data_layer::DataLayer>,
    sink: &mut dyn FnMut(&[Complex32]) -> Result<(), DtmbError>,
) -> Result<(), DtmbError> {
    rec.validate()?;
    let (mode, frames, snr_db, oversampling) = (rec.mode, rec.frames, rec.snr_db, rec.oversampling);
    let streams = TrialRng::new(rec.seed, 0);
    let cfg = TxConfig {
        schedule: FrameSchedule {
            mode,
            t0: GpsTime::from_ns(0),
            tower_clock_offset_s: 0.0,
        },
        carrier: CarrierMode::Multi3780,
        qam: Qam::Qam64,
        si_vector: 0,
    };
    let mut tx = match data {
        Some(layer) => {
            Transmitter::with_data_layer(cfg, layer, &mut streams.stream("dtmb/payload"))
        }
        None => Transmitter::new(cfg, &mut streams.stream("dtmb/payload")),
    };
    let n = mode.frame_len();
    // A perfect transmitter and the receiver's oscillator (zero: no offset at all).
    let ch_cfg = ChannelConfig::from_oscillators(
        vec![ChannelPath::new(0.0, 1.0, 0.0, 0.0)],
        0.0,
        rec.rx_oscillator_ppm,
        rec.center_freq_hz,
        Some(snr_db),
    );
    let mut ch = Channel::new(ch_cfg, mode, n)?;
    let mut noise = streams.stream("dtmb/noise");
    let mut block = vec![Complex32::default(); n];
    // With oversampling: the interpolator runs on as one stream; its first `delay`
    // outputs (the group delay) are dropped and `pad` zero symbols after the last frame
    // flush the recording's tail out of it, as filtering the whole recording at once.
    let mut shaping = if oversampling == 1 {
        None
    } else {
        let f = SrrcInterpolator::new(oversampling, 0.05, 32)?;
        let delay = f.delay_samples();
        Some((f, delay, vec![Complex32::default(); n * oversampling]))
    };
    let wanted = rec.samples();
    let mut emitted = 0u64;
    let mut to_skip = shaping.as_ref().map_or(0, |s| s.1);
    let mut emit = |out: &[Complex32],
                    emitted: &mut u64,
                    sink: &mut dyn FnMut(&[Complex32]) -> Result<(), DtmbError>|
     -> Result<(), DtmbError> {
        let skip = to_skip.min(out.len());
        to_skip -= skip;
        let take = ((out.len() - skip) as u64).min(wanted - *emitted) as usize;
        if take > 0 {
            sink(&out[skip..skip + take])?;
            *emitted += take as u64;
        }
        Ok(())
    };
    for k in 0..frames {
        ch.process(&mut tx, (k * n) as i64, &mut block, &mut noise)?;
        if let Some(e) = tx.take_error() {
            return Err(e);
        }
        match shaping.as_mut() {
            None => emit(&block, &mut emitted, sink)?,
            Some((f, _, out)) => {
                f.process(&block, out)?;
                emit(out, &mut emitted, sink)?;
            }
        }
    }
    if let Some((mut f, delay, _)) = shaping {
        let pad = delay.div_ceil(oversampling);
        let zeros = vec![Complex32::default(); pad];
        let mut out = vec![Complex32::default(); pad * oversampling];
        f.process(&zeros, &mut out)?;
        emit(&out, &mut emitted, sink)?;
    }
    Ok(())
}

/// The annotations of [`stream_iq`]'s recording, one per frame, made on demand:
/// `frame k PNxxx phase p` (and the profile's name with a data layer), starting at
/// sample `k · N · L` (the nearest to `k N (1 + ε) L` through an oscillator off by `ε`).
pub fn iq_annotations<'a>(
    rec: &AwgnRecording,
    profile: Option<&'a super::data_layer::Profile>,
) -> impl Iterator<Item = Annotation> + 'a {
    let rec = *rec;
    let (mode, l) = (rec.mode, rec.oversampling as f64);
    // Through an oscillator off by ε the frames start at fractional receiver samples;
    // each annotation starts at the nearest one and runs to the next frame's.
    let start = move |k: usize| (rec.frame_start_sample(k) * l).round() as u64;
    (0..rec.frames).map(move |k| Annotation {
        sample_start: start(k),
        sample_count: start(k + 1) - start(k),
        label: match profile {
            Some(p) => format!(
                "frame {k} {} phase {} {}",
                mode.name(),
                mode.phase_of_frame(k),
                p.name()
            ),
            None => format!("frame {k} {} phase {}", mode.name(), mode.phase_of_frame(k)),
        },
    })
}

/// Writes the recording `rec` (as [`generate_iq_with`] makes it) as SigMF
/// (`BASE.sigmf-data`, `.sigmf-meta`, centred on `rec.center_freq_hz`) frame by frame,
/// with flat memory: the output is byte-identical to [`write_sigmf`] of the in-memory
/// recording. `data` makes the data layer (or `None` for random bodies); a `ci8`
/// recording is generated twice, first for its peak (the scale) and then for the file,
/// the same samples both times (named random streams). An oscillator error is recorded
/// under `hybridnav:rx_oscillator_ppm`. Returns the number of samples written.
///
/// # Errors
/// As [`stream_iq`] and [`SigmfWriter`]; the data layer's errors from `data`.
pub fn write_iq_sigmf(
    base: &Path,
    format: SampleFormat,
    rec: &AwgnRecording,
    data: &dyn Fn() -> Result<Option<super::data_layer::DataLayer>, DtmbError>,
) -> Result<u64, DtmbError> {
    rec.validate()?;
    let peak = match format {
        SampleFormat::Cf32 => 0.0,
        SampleFormat::Ci8 => {
            let mut peak = 0.0f32;
            stream_iq(rec, data()?, &mut |b| {
                peak = peak.max(peak_component(b));
                Ok(())
            })?;
            peak
        }
    };
    let layer = data()?;
    let profile = layer.as_ref().map(|d| *d.profile());
    let mut w = SigmfWriter::create(
        base,
        format,
        iq_sample_rate_hz(rec.oversampling),
        rec.center_freq_hz,
        peak,
    )?;
    stream_iq(rec, layer, &mut |b| w.write(b))?;
    let written = w.samples_written();
    // The oscillator's error is part of what was recorded; a perfect one is not named.
    let mut global = Map::new();
    if rec.rx_oscillator_ppm != 0.0 {
        global.insert(
            "hybridnav:rx_oscillator_ppm".into(),
            json!(rec.rx_oscillator_ppm),
        );
    }
    w.finish(iq_annotations(rec, profile.as_ref()), &[], &global)?;
    Ok(written)
}

/// The sample rate of [`generate_iq`]'s output.
pub fn iq_sample_rate_hz(oversampling: usize) -> f64 {
    SAMPLE_RATE_HZ * oversampling as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("hybridnav-sigmf-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join("rec")
    }

    #[test]
    fn round_trips_cf32_and_ci8() {
        let (s, a) = generate_iq(PnMode::Pn420, 3, 20.0, 1, 5).unwrap();
        assert_eq!(s.len(), 3 * 4200);
        assert_eq!(a[2].label, "frame 2 PN420 phase 254");
        let base = tmp("rt");
        write_sigmf(&base, &s, SampleFormat::Cf32, 7.56e6, 482e6, &a).unwrap();
        let r = read_sigmf(&base).unwrap();
        assert_eq!(r.samples, s);
        assert_eq!(
            (r.sample_rate_hz, r.center_freq_hz, r.format),
            (7.56e6, 482e6, SampleFormat::Cf32)
        );
        assert_eq!(r.annotations, a);
        let meta: Value =
            serde_json::from_str(&std::fs::read_to_string(with_ext(&base, ".sigmf-meta")).unwrap())
                .unwrap();
        assert_eq!(meta["global"]["core:version"], "1.0.0");
        assert_eq!(meta["annotations"][1]["core:sample_start"], 4200);
        write_sigmf(&base, &s, SampleFormat::Ci8, 7.56e6, 482e6, &a).unwrap();
        let r = read_sigmf(&base).unwrap();
        let peak = s
            .iter()
            .fold(0.0f32, |m, x| m.max(x.re.abs()).max(x.im.abs()));
        let err = r
            .samples
            .iter()
            .zip(&s)
            .map(|(a, b)| (a - b).re.abs().max((a - b).im.abs()))
            .fold(0.0f32, f32::max);
        assert!(err <= peak / 127.0 * 0.5 + 1e-6, "ci8 error {err}");
        std::fs::remove_dir_all(base.parent().unwrap()).unwrap();
    }

    #[test]
    fn generate_iq_validates_and_oversamples() {
        assert!(generate_iq(PnMode::Pn945, 0, 10.0, 1, 1).is_err());
        assert!(generate_iq(PnMode::Pn945, 1, f64::NAN, 1, 1).is_err());
        assert!(generate_iq(PnMode::Pn945, 1, 10.0, 0, 1).is_err());
        let (s, a) = generate_iq(PnMode::Pn945, 2, 30.0, 2, 1).unwrap();
        assert_eq!(s.len(), 2 * 4725 * 2);
        assert_eq!(a[1].sample_start, 9450);
        let p: f32 = s.iter().map(|x| x.norm_sqr()).sum::<f32>() / s.len() as f32;
        assert!((p - 1.2).abs() < 0.1, "power {p}");
    }

    #[test]
    fn malformed_meta_is_a_clear_error() {
        let base = tmp("bad");
        std::fs::write(
            with_ext(&base, ".sigmf-meta"),
            "{\"global\": {\"core:datatype\": \"ri16_le\"}}",
        )
        .unwrap();
        std::fs::write(with_ext(&base, ".sigmf-data"), [0u8; 4]).unwrap();
        let e = read_sigmf(&base).unwrap_err().to_string();
        assert!(e.contains("ri16_le") && e.contains("sigmf-meta"), "{e}");
        std::fs::remove_dir_all(base.parent().unwrap()).unwrap();
    }
}
