//! Landmark windows in a field-magnitude sequence, their fixed-size images, dynamic time
//! warping against a landmark library, and the DTMB-ranging consistency check (seed 002,
//! §2.1 and §4.1).
//!
//! The detector follows §2.1 step by step:
//!
//! 1. The magnitude sequence is smoothed (a centred moving average of half-width
//!    `smooth_half_width_s`; the paper uses a Butterworth filter — both remove the sensor
//!    noise and the step-frequency ripple a hand-held phone adds).
//! 2. Every peak and valley of the smoothed sequence is a starting point. From a peak the
//!    window grows in each direction while the signal keeps falling, and stops at the first
//!    point where it starts to rise again (for a valley: to fall). A rise smaller than
//!    `hysteresis_ut` above the running minimum does not stop it, so that the residual
//!    noise of the smoothed signal does not cut a window short.
//!    A flat tail (within `hysteresis_ut` of the lowest value) is trimmed off, and an
//!    extremum that does not fall by at least `hysteresis_ut` on both sides is a ripple on
//!    a flank, not a starting point.
//! 3. The window's change rate (max − min) / (half its duration) is compared with
//!    `min_change_rate_ut_per_s`; only windows above it are landmarks.
//! 4. Overlapping windows are merged into their union, so one bipolar dipole signature (a
//!    peak beside a valley) gives one window, not two, centred on the signature.
//!
//! Each window is mapped to a [`LandmarkFeature`]: the smoothed window resampled by linear
//! interpolation to [`FEATURE_LEN`] points with its minimum subtracted (§2.1's image
//! mapping steps 1–2, which remove the offset that differs between phones), and from it an
//! image of [`FEATURE_LEN`] rows by [`IMAGE_COLUMNS`] columns with one lit pixel per row at
//! column round(v / full scale · (M − 1)) (step 3). Resampling every window to the same
//! length also removes most of the difference in walking speed.
//!
//! Dynamic time warping (Sakoe & Chiba 1978) with the absolute difference as local cost
//! and a Sakoe–Chiba band is the baseline matcher (seed 002 ref. \[32\]); the library keeps
//! every survey template with its landmark label and reports, per label, the best distance
//! under a threshold. Candidates are then filtered by §4.1:
//!
//! ```text
//! keep P_i  iff  | ‖P_i − P_base‖ − r_dtmb | < δr
//! ```
//!
//! where P_base is the DTMB transmitter and r_dtmb the range measured at the detection.

use super::MagneticError;
use crate::core::config::check_range;
use crate::core::ConfigIssue;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Points in a resampled landmark window (the rows of its image).
pub const FEATURE_LEN: usize = 32;
/// Columns of a landmark image (the intensity levels).
pub const IMAGE_COLUMNS: usize = 32;

fn d_smooth() -> f64 {
    0.3
}
fn d_hyst() -> f64 {
    0.3
}
fn d_rate() -> f64 {
    1.5
}
fn d_min_window() -> f64 {
    0.8
}
fn d_max_window() -> f64 {
    8.0
}
fn d_full_scale() -> f64 {
    24.0
}

/// How landmark windows are found and imaged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LandmarkDetectorConfig {
    /// Half-width of the centred moving average (s); default 0.3 (about one step).
    #[serde(default = "d_smooth")]
    pub smooth_half_width_s: f64,
    /// A rise (fall) smaller than this above the running extremum does not end a window
    /// (µT); default 0.3.
    #[serde(default = "d_hyst")]
    pub hysteresis_ut: f64,
    /// Windows whose change rate (max − min) / (half the duration) is below this are not
    /// landmarks (µT/s); default 1.5 (at 2 the survey walk of `tests/it/landmark.rs` missed
    /// its two weakest landmarks, ≈ 3 µT bumps at walking speed). The rate is per second,
    /// so a faster walker passes the same landmark with a higher rate.
    #[serde(default = "d_rate")]
    pub min_change_rate_ut_per_s: f64,
    /// Shortest window (s); default 0.8.
    #[serde(default = "d_min_window")]
    pub min_window_s: f64,
    /// Longest window (s); default 8.
    #[serde(default = "d_max_window")]
    pub max_window_s: f64,
    /// The intensity mapped to the last image column (µT); default 24.
    #[serde(default = "d_full_scale")]
    pub image_full_scale_ut: f64,
}

impl Default for LandmarkDetectorConfig {
    fn default() -> Self {
        Self {
            smooth_half_width_s: d_smooth(),
            hysteresis_ut: d_hyst(),
            min_change_rate_ut_per_s: d_rate(),
            min_window_s: d_min_window(),
            max_window_s: d_max_window(),
            image_full_scale_ut: d_full_scale(),
        }
    }
}

impl LandmarkDetectorConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field (non-finite, negative, or a shortest
    /// window longer than the longest).
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check_range(
            "smooth_half_width_s",
            self.smooth_half_width_s,
            0.0,
            10.0,
            false,
            "a half-width in s",
        )?;
        check_range(
            "hysteresis_ut",
            self.hysteresis_ut,
            0.0,
            100.0,
            false,
            "a hysteresis in µT",
        )?;
        check_range(
            "min_change_rate_ut_per_s",
            self.min_change_rate_ut_per_s,
            0.0,
            1000.0,
            true,
            "a change-rate threshold in µT/s",
        )?;
        check_range(
            "min_window_s",
            self.min_window_s,
            0.0,
            60.0,
            true,
            "a window length in s",
        )?;
        check_range(
            "max_window_s",
            self.max_window_s,
            0.0,
            600.0,
            true,
            "a window length in s",
        )?;
        if self.min_window_s > self.max_window_s {
            return Err(ConfigIssue::new(
                "min_window_s",
                format!(
                    "expected at most max_window_s = {} s, got {} s",
                    self.max_window_s, self.min_window_s
                ),
            ));
        }
        check_range(
            "image_full_scale_ut",
            self.image_full_scale_ut,
            0.0,
            10_000.0,
            true,
            "a full-scale intensity in µT",
        )?;
        Ok(())
    }
}

/// One landmark window in a sequence: sample indices (inclusive) and what it looked like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandmarkWindow {
    /// First sample.
    pub start: usize,
    /// Last sample (inclusive).
    pub end: usize,
    /// The peak or valley the window grew from.
    pub extremum: usize,
    /// True for a peak, false for a valley.
    pub is_peak: bool,
    /// max − min of the smoothed signal in the window (µT).
    pub amplitude_ut: f64,
    /// amplitude / (half the duration) (µT/s). Each window passed the threshold before
    /// overlapping ones were merged; a merged window's rate, recomputed over the union,
    /// may be lower.
    pub change_rate_ut_per_s: f64,
}

impl LandmarkWindow {
    /// The middle sample, where the walker is taken to be at the landmark.
    pub fn centre(&self) -> usize {
        (self.start + self.end) / 2
    }
}

/// A centred moving average of half-width `half_width` samples; near the ends the average
/// runs over the samples that exist. `out` is resized to `input.len()`.
///
/// # Errors
/// [`MagneticError::Input`] for an empty or non-finite input.
pub fn moving_average(
    input: &[f64],
    half_width: usize,
    out: &mut Vec<f64>,
) -> Result<(), MagneticError> {
    if input.is_empty() {
        return Err(MagneticError::Input("expected a non-empty sequence".into()));
    }
    if let Some(i) = input.iter().position(|v| !v.is_finite()) {
        return Err(MagneticError::Input(format!(
            "expected finite samples, sample {i} is {}",
            input[i]
        )));
    }
    let n = input.len();
    out.clear();
    out.resize(n, 0.0);
    // A sliding sum costs O(n) whatever the width; it is kept in compensated (Kahan) form
    // so that adding and removing thousands of ~50 µT samples does not drift.
    let mut sum = 0.0;
    let mut comp = 0.0;
    fn add(sum: &mut f64, comp: &mut f64, v: f64) {
        let y = v - *comp;
        let t = *sum + y;
        *comp = (t - *sum) - y;
        *sum = t;
    }
    let hi0 = half_width.min(n - 1);
    for &v in &input[..=hi0] {
        add(&mut sum, &mut comp, v);
    }
    for (i, o) in out.iter_mut().enumerate() {
        let lo = i.saturating_sub(half_width);
        let hi = (i + half_width).min(n - 1);
        *o = sum / (hi - lo + 1) as f64;
        // Slide: the next window gains i + 1 + w and loses i − w.
        if i + 1 + half_width < n {
            add(&mut sum, &mut comp, input[i + 1 + half_width]);
        }
        if i >= half_width {
            add(&mut sum, &mut comp, -input[i - half_width]);
        }
    }
    Ok(())
}

/// Finds the landmark windows of `magnitude_ut` sampled at `rate_hz` (see the module docs).
/// `smoothed` receives the smoothed sequence (the windows index into it) and `out` the
/// windows in time order; both are cleared first and reused by the caller.
///
/// # Errors
/// [`MagneticError::Config`] for a bad configuration; [`MagneticError::Input`] for an
/// empty or non-finite sequence, a bad rate, or a smoothing window or shortest landmark
/// window longer than the sequence.
pub fn extract_windows(
    magnitude_ut: &[f64],
    rate_hz: f64,
    cfg: &LandmarkDetectorConfig,
    smoothed: &mut Vec<f64>,
    out: &mut Vec<LandmarkWindow>,
) -> Result<(), MagneticError> {
    cfg.validate()?;
    out.clear();
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 10_000.0) {
        return Err(MagneticError::Input(format!(
            "expected a sampling rate within (0, 10000] Hz, got {rate_hz}"
        )));
    }
    let n = magnitude_ut.len();
    if n == 0 {
        return Err(MagneticError::Input("expected a non-empty sequence".into()));
    }
    let half = (cfg.smooth_half_width_s * rate_hz).round() as usize;
    if 2 * half + 1 > n {
        return Err(MagneticError::Input(format!(
            "the smoothing window ({} samples) is longer than the sequence ({n} samples)",
            2 * half + 1
        )));
    }
    let min_len = ((cfg.min_window_s * rate_hz).ceil() as usize).max(3);
    if min_len > n {
        return Err(MagneticError::Input(format!(
            "the shortest landmark window ({min_len} samples) is longer than the sequence \
             ({n} samples)"
        )));
    }
    let max_len = ((cfg.max_window_s * rate_hz).floor() as usize).max(min_len);
    moving_average(magnitude_ut, half, smoothed)?;
    let s = &smoothed[..];
    for i in 1..n.saturating_sub(1) {
        let is_peak = s[i] > s[i - 1] && s[i] >= s[i + 1];
        let is_valley = s[i] < s[i - 1] && s[i] <= s[i + 1];
        if !(is_peak || is_valley) {
            continue;
        }
        // Orient the signal so that the starting point is a peak: sign · s.
        let sign = if is_peak { 1.0 } else { -1.0 };
        let reach = max_len / 2;
        // Grows one side; returns the edge and the side's prominence (how far the signal
        // falls from the starting point to the edge).
        let grow = |dir: isize| -> (usize, f64) {
            let mut edge = i;
            let top = sign * s[i];
            let mut run_min = top;
            let mut j = i as isize;
            for _ in 0..reach {
                j += dir;
                if j < 0 || j >= n as isize {
                    break;
                }
                let v = sign * s[j as usize];
                if v < run_min {
                    run_min = v;
                    edge = j as usize;
                } else if v > run_min + cfg.hysteresis_ut {
                    break;
                }
            }
            // A flat tail (the signal within the hysteresis of its lowest value) is not
            // part of the landmark: the edge moves in to the first point that is already
            // that low.
            let mut k = i;
            while k != edge && sign * s[k] > run_min + cfg.hysteresis_ut {
                k = (k as isize + dir) as usize;
            }
            (k, top - run_min)
        };
        let ((start, prom_l), (end, prom_r)) = (grow(-1), grow(1));
        // A real peak or valley stands out on both sides; an extremum that does not is a
        // ripple on a flank or in a flat stretch.
        if prom_l < cfg.hysteresis_ut || prom_r < cfg.hysteresis_ut {
            continue;
        }
        let len = end - start + 1;
        if len < min_len {
            continue;
        }
        let (lo, hi) = s[start..=end]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let amplitude_ut = hi - lo;
        let half_duration_s = 0.5 * (len - 1) as f64 / rate_hz;
        let change_rate_ut_per_s = amplitude_ut / half_duration_s;
        if change_rate_ut_per_s < cfg.min_change_rate_ut_per_s {
            continue;
        }
        out.push(LandmarkWindow {
            start,
            end,
            extremum: i,
            is_peak,
            amplitude_ut,
            change_rate_ut_per_s,
        });
    }
    // A dipole's signature is usually a peak beside a valley, and a broad extremum can
    // carry ripples that start windows of their own; overlapping windows are therefore one
    // landmark, and are merged into their union (so its centre is the signature's centre).
    out.sort_by_key(|w| (w.start, w.end));
    let mut merged = 0;
    for k in 0..out.len() {
        let w = out[k];
        if merged > 0 && w.start <= out[merged - 1].end {
            let m = &mut out[merged - 1];
            if w.amplitude_ut > m.amplitude_ut {
                m.extremum = w.extremum;
                m.is_peak = w.is_peak;
            }
            m.end = m.end.max(w.end);
        } else {
            out[merged] = w;
            merged += 1;
        }
    }
    out.truncate(merged);
    for w in out.iter_mut() {
        let (lo, hi) = s[w.start..=w.end]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        w.amplitude_ut = hi - lo;
        w.change_rate_ut_per_s = w.amplitude_ut / (0.5 * (w.end - w.start) as f64 / rate_hz);
    }
    Ok(())
}

/// A landmark window resampled to [`FEATURE_LEN`] points with its minimum subtracted (µT).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandmarkFeature {
    /// The resampled curve, minimum 0 (µT).
    pub curve_ut: [f64; FEATURE_LEN],
}

impl LandmarkFeature {
    /// The feature of `samples` (e.g. `smoothed[w.start..=w.end]`): linear interpolation to
    /// [`FEATURE_LEN`] equally spaced points, then the minimum subtracted.
    ///
    /// # Errors
    /// [`MagneticError::Input`] for fewer than two samples or a non-finite one.
    pub fn from_samples(samples: &[f64]) -> Result<Self, MagneticError> {
        if samples.len() < 2 {
            return Err(MagneticError::Input(format!(
                "expected at least two samples in a landmark window, got {}",
                samples.len()
            )));
        }
        if samples.iter().any(|v| !v.is_finite()) {
            return Err(MagneticError::Input(
                "expected finite samples in a landmark window".into(),
            ));
        }
        let last = (samples.len() - 1) as f64;
        let mut curve_ut = [0.0; FEATURE_LEN];
        for (k, c) in curve_ut.iter_mut().enumerate() {
            let x = k as f64 * last / (FEATURE_LEN - 1) as f64;
            let i = (x.floor() as usize).min(samples.len() - 2);
            let f = x - i as f64;
            *c = samples[i] + f * (samples[i + 1] - samples[i]);
        }
        let min = curve_ut.iter().copied().fold(f64::INFINITY, f64::min);
        for c in &mut curve_ut {
            *c -= min;
        }
        Ok(Self { curve_ut })
    }

    /// The feature of `window` in the smoothed sequence it was found in.
    ///
    /// # Errors
    /// [`MagneticError::Input`] when the window does not fit in `smoothed`.
    pub fn from_window(smoothed: &[f64], window: &LandmarkWindow) -> Result<Self, MagneticError> {
        if window.start >= window.end || window.end >= smoothed.len() {
            return Err(MagneticError::Input(format!(
                "window {}..={} does not fit a sequence of {} samples",
                window.start,
                window.end,
                smoothed.len()
            )));
        }
        Self::from_samples(&smoothed[window.start..=window.end])
    }

    /// The image: for each of the [`FEATURE_LEN`] rows, the column of its lit pixel,
    /// round(v / full scale · (M − 1)) clamped to the last column.
    pub fn image(&self, full_scale_ut: f64) -> [u8; FEATURE_LEN] {
        let top = (IMAGE_COLUMNS - 1) as f64;
        let scale = if full_scale_ut > 0.0 {
            top / full_scale_ut
        } else {
            0.0
        };
        std::array::from_fn(|i| (self.curve_ut[i] * scale).round().clamp(0.0, top) as u8)
    }
}

/// Seed 002 §2.1 expands its landmark database by stretching the images (factors 0.5–1.5)
/// so that a walk at another speed still matches. Here every window is already resampled
/// to a fixed length, so speed alone changes little; what differs between walks is where
/// the window's edges fall. The expansion therefore moves each edge by −f, 0 and +f of the
/// window's length (f = `edge_jitter_frac`), nine features per window, clipped to the
/// sequence.
///
/// # Errors
/// [`MagneticError::Input`] for a window that does not fit `smoothed` or a fraction outside
/// [0, 0.45].
pub fn augmented_features(
    smoothed: &[f64],
    window: &LandmarkWindow,
    edge_jitter_frac: f64,
) -> Result<Vec<LandmarkFeature>, MagneticError> {
    if !(edge_jitter_frac.is_finite() && (0.0..=0.45).contains(&edge_jitter_frac)) {
        return Err(MagneticError::Input(format!(
            "expected an edge jitter within [0, 0.45] of the window, got {edge_jitter_frac}"
        )));
    }
    let base = LandmarkFeature::from_window(smoothed, window)?;
    let len = (window.end - window.start + 1) as f64;
    let d = (edge_jitter_frac * len).round() as isize;
    let last = smoothed.len() as isize - 1;
    let mut out = Vec::with_capacity(9);
    for ds in [-d, 0, d] {
        for de in [-d, 0, d] {
            let s0 = (window.start as isize + ds).clamp(0, last);
            let e0 = (window.end as isize + de).clamp(0, last);
            if e0 - s0 < 2 {
                out.push(base);
                continue;
            }
            out.push(LandmarkFeature::from_samples(
                &smoothed[s0 as usize..=e0 as usize],
            )?);
        }
    }
    Ok(out)
}

/// Caller-owned buffers for [`dtw_distance`] and [`DtwLibrary::candidates`]; they grow to
/// the largest size used and are then reused without allocating.
#[derive(Clone, Debug, Default)]
pub struct DtwScratch {
    prev: Vec<f64>,
    cur: Vec<f64>,
    best: Vec<f64>,
}

/// The dynamic-time-warping distance between `a` and `b`: the least sum of |a_i − b_j|
/// over monotone, continuous warping paths from (0, 0) to (n − 1, m − 1), steps
/// (1, 0), (0, 1), (1, 1). With `band = Some(w)` the path stays within w cells of the
/// diagonal j = i (m − 1)/(n − 1) (Sakoe–Chiba); a band too narrow to connect the corners
/// gives +∞.
///
/// # Errors
/// [`MagneticError::Input`] for an empty or non-finite sequence.
pub fn dtw_distance(
    a: &[f64],
    b: &[f64],
    band: Option<usize>,
    scratch: &mut DtwScratch,
) -> Result<f64, MagneticError> {
    if a.is_empty() || b.is_empty() {
        return Err(MagneticError::Input(
            "expected two non-empty sequences for DTW".into(),
        ));
    }
    if a.iter().chain(b).any(|v| !v.is_finite()) {
        return Err(MagneticError::Input(
            "expected finite samples for DTW".into(),
        ));
    }
    Ok(dtw_unchecked(a, b, band, scratch))
}

fn dtw_unchecked(a: &[f64], b: &[f64], band: Option<usize>, scratch: &mut DtwScratch) -> f64 {
    let (n, m) = (a.len(), b.len());
    let inf = f64::INFINITY;
    if scratch.prev.len() < m {
        scratch.prev.resize(m, inf);
        scratch.cur.resize(m, inf);
    }
    let slope = if n > 1 {
        (m - 1) as f64 / (n - 1) as f64
    } else {
        0.0
    };
    let range = |i: usize| -> (usize, usize) {
        match band {
            None => (0, m - 1),
            Some(w) => {
                let c = i as f64 * slope;
                let lo = (c - w as f64).ceil().max(0.0) as usize;
                let hi = ((c + w as f64).floor() as usize).min(m - 1);
                (lo, hi)
            }
        }
    };
    let (prev, cur) = (&mut scratch.prev, &mut scratch.cur);
    prev[..m].fill(inf);
    let (lo0, hi0) = range(0);
    if lo0 == 0 {
        let mut acc = 0.0;
        for j in 0..=hi0 {
            acc += (a[0] - b[j]).abs();
            prev[j] = acc;
        }
    }
    for (i, &ai) in a.iter().enumerate().skip(1) {
        cur[..m].fill(inf);
        let (lo, hi) = range(i);
        for j in lo..=hi.min(m - 1) {
            let mut best = prev[j];
            if j > 0 {
                best = best.min(prev[j - 1]).min(cur[j - 1]);
            }
            cur[j] = best + (ai - b[j]).abs();
        }
        std::mem::swap(prev, cur);
    }
    prev[m - 1]
}

/// A matching candidate: a landmark label and a score, higher is better (for DTW the
/// negated mean distance in µT, for the SNN the margin V_max − V_th).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The landmark's label (index into the landmark list).
    pub label: usize,
    /// Higher is better.
    pub score: f64,
}

/// The DTW baseline: every survey template with its landmark label.
#[derive(Clone, Debug, PartialEq)]
pub struct DtwLibrary {
    templates: Vec<(usize, [f64; FEATURE_LEN])>,
    n_labels: usize,
    band: usize,
    threshold_ut: f64,
}

impl DtwLibrary {
    /// An empty library for labels `0..n_labels`, matching within a Sakoe–Chiba band of
    /// `band` cells and accepting a label when its best mean DTW distance (the DTW cost
    /// divided by [`FEATURE_LEN`]) is below `threshold_ut`.
    ///
    /// # Errors
    /// [`MagneticError::Config`] for zero labels, a band of zero, or a threshold that is
    /// not finite and positive.
    pub fn new(n_labels: usize, band: usize, threshold_ut: f64) -> Result<Self, MagneticError> {
        if n_labels == 0 {
            return Err(ConfigIssue::new("n_labels", "expected at least one landmark").into());
        }
        if band == 0 {
            return Err(ConfigIssue::new("band", "expected a band of at least one cell").into());
        }
        check_range(
            "threshold_ut",
            threshold_ut,
            0.0,
            1000.0,
            true,
            "a DTW threshold in µT",
        )?;
        Ok(Self {
            templates: Vec::new(),
            n_labels,
            band,
            threshold_ut,
        })
    }

    /// Adds a template of landmark `label`.
    ///
    /// # Errors
    /// [`MagneticError::Input`] for a label outside `0..n_labels`.
    pub fn add(&mut self, label: usize, feature: &LandmarkFeature) -> Result<(), MagneticError> {
        if label >= self.n_labels {
            return Err(MagneticError::Input(format!(
                "label {label} is not below the library's {} labels",
                self.n_labels
            )));
        }
        self.templates.push((label, feature.curve_ut));
        Ok(())
    }

    /// How many templates the library holds.
    pub fn len(&self) -> usize {
        self.templates.len()
    }

    /// True when the library holds no template.
    pub fn is_empty(&self) -> bool {
        self.templates.is_empty()
    }

    /// The labels whose best template is within the threshold, best first, into `out`
    /// (cleared first). Allocates nothing once `scratch` and `out` have grown.
    pub fn candidates(
        &self,
        feature: &LandmarkFeature,
        scratch: &mut DtwScratch,
        out: &mut Vec<Candidate>,
    ) {
        out.clear();
        let mut best = std::mem::take(&mut scratch.best);
        best.clear();
        best.resize(self.n_labels, f64::INFINITY);
        for (label, t) in &self.templates {
            let d =
                dtw_unchecked(&feature.curve_ut, t, Some(self.band), scratch) / FEATURE_LEN as f64;
            if d < best[*label] {
                best[*label] = d;
            }
        }
        for (label, &d) in best.iter().enumerate() {
            if d < self.threshold_ut {
                out.push(Candidate { label, score: -d });
            }
        }
        out.sort_unstable_by(|a, b| b.score.total_cmp(&a.score).then(a.label.cmp(&b.label)));
        scratch.best = best;
    }
}

/// Seed 002 §4.1: is a landmark at `p_candidate_enu_m` consistent with a DTMB range
/// `r_dtmb_m` to the transmitter at `p_base_enu_m`, | ‖P_i − P_base‖ − r_dtmb | < δr?
pub fn dtmb_consistent(
    p_candidate_enu_m: &Vector3<f64>,
    p_base_enu_m: &Vector3<f64>,
    r_dtmb_m: f64,
    delta_r_m: f64,
) -> bool {
    ((p_candidate_enu_m - p_base_enu_m).norm() - r_dtmb_m).abs() < delta_r_m
}

/// The best of `candidates` (best first, as the matchers give them) whose landmark
/// position passes [`dtmb_consistent`]; `None` when none does.
///
/// # Errors
/// [`MagneticError::Config`] for a δr or range that is not finite and positive (key
/// `delta_r_m` or `r_dtmb_m`); [`MagneticError::Input`] for a candidate label without a
/// position.
pub fn select_by_dtmb(
    candidates: &[Candidate],
    landmark_positions_enu_m: &[Vector3<f64>],
    p_base_enu_m: &Vector3<f64>,
    r_dtmb_m: f64,
    delta_r_m: f64,
) -> Result<Option<Candidate>, MagneticError> {
    check_range(
        "delta_r_m",
        delta_r_m,
        0.0,
        1.0e6,
        true,
        "a range threshold in m",
    )?;
    check_range("r_dtmb_m", r_dtmb_m, 0.0, 1.0e8, false, "a range in m")?;
    for c in candidates {
        let p = landmark_positions_enu_m.get(c.label).ok_or_else(|| {
            MagneticError::Input(format!("candidate label {} has no position", c.label))
        })?;
        if dtmb_consistent(p, p_base_enu_m, r_dtmb_m, delta_r_m) {
            return Ok(Some(*c));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_average_matches_a_direct_sum() {
        let x: Vec<f64> = (0..40).map(|i| ((i * 7919) % 13) as f64 * 0.37).collect();
        let mut out = Vec::new();
        moving_average(&x, 3, &mut out).unwrap();
        for (i, o) in out.iter().enumerate() {
            let lo = i.saturating_sub(3);
            let hi = (i + 3).min(x.len() - 1);
            let direct: f64 = x[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64;
            assert!((o - direct).abs() < 1e-12, "{i}");
        }
    }

    #[test]
    fn a_gaussian_bump_gives_one_window_around_it() {
        let rate = 50.0;
        let x: Vec<f64> = (0..1000)
            .map(|k| {
                let t = k as f64 / rate - 10.0;
                45.0 + 8.0 * (-t * t / 0.5).exp()
            })
            .collect();
        let (mut s, mut w) = (Vec::new(), Vec::new());
        extract_windows(&x, rate, &LandmarkDetectorConfig::default(), &mut s, &mut w).unwrap();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].is_peak);
        assert!((w[0].extremum as f64 / rate - 10.0).abs() < 0.05);
        // The bump is symmetric, so is the window.
        let c = w[0].centre() as f64 / rate;
        assert!((c - 10.0).abs() < 0.1, "centre {c}");
    }

    #[test]
    fn dtw_of_hand_computed_cases() {
        let mut s = DtwScratch::default();
        assert_eq!(
            dtw_distance(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0], None, &mut s).unwrap(),
            0.0
        );
        // A repeated sample is absorbed by warping.
        assert_eq!(
            dtw_distance(&[0.0, 1.0, 2.0], &[0.0, 1.0, 1.0, 2.0], None, &mut s).unwrap(),
            0.0
        );
        // Both corners are on every path: |1 − 2| + |3 − 2| = 2, and the middle costs 0.
        assert_eq!(
            dtw_distance(&[1.0, 2.0, 3.0], &[2.0, 2.0, 2.0], None, &mut s).unwrap(),
            2.0
        );
        // [0, 2] vs [1]: both samples must pair with the only one: 1 + 1.
        assert_eq!(
            dtw_distance(&[0.0, 2.0], &[1.0], None, &mut s).unwrap(),
            2.0
        );
        assert!(dtw_distance(&[], &[1.0], None, &mut s).is_err());
        assert!(dtw_distance(&[f64::NAN], &[1.0], None, &mut s).is_err());
    }

    #[test]
    fn dtmb_check_is_the_papers_inequality() {
        let base = Vector3::new(300.0, 400.0, 0.0);
        let p = Vector3::zeros();
        assert!(dtmb_consistent(&p, &base, 503.0, 5.0));
        assert!(!dtmb_consistent(&p, &base, 506.0, 5.0));
        assert!(select_by_dtmb(&[], &[p], &base, 500.0, f64::NAN).is_err());
        assert!(select_by_dtmb(&[], &[p], &base, 500.0, 0.0).is_err());
    }
}
