//! A spiking neural network of Tempotron neurons for landmark images (seed 002 §2.2; Gütig
//! & Sompolinsky, "The tempotron: a neuron that learns spike timing-based decisions",
//! Nature Neuroscience 9:420–428, 2006).
//!
//! **Neuron.** A leaky integrate-and-fire neuron's membrane potential is
//!
//! ```text
//! V(t) = Σ_i w_i Σ_{t_i < t} K(t − t_i) + V_rest,    K(t) = V0 (e^(−t/τ) − e^(−t/τs)), t ≥ 0
//! ```
//!
//! with τ the membrane and τs the synaptic time constant. K peaks at
//! t* = τ τs ln(τ/τs) / (τ − τs), and V0 = 1 / (e^(−t*/τ) − e^(−t*/τs)) normalises that peak
//! to 1. The neuron fires when max_t V(t) ≥ V_th. V_rest is 0 and V_th is 1.
//!
//! **Encoding.** A landmark image has one lit pixel per row (see
//! [`super::landmark::LandmarkFeature::image`]). Each row i is an input afferent with an
//! oscillation of phase φ_i = φ0 + i Δφ (seed 002 eq. 2–3); its pixel's column c_i shifts
//! the firing phase, and the afferent fires once per cycle T at
//!
//! ```text
//! t_i = T · ( i/(2N) + c_i/(2(M − 1)) ),    i = 0..N−1, c_i ∈ 0..M−1
//! ```
//!
//! i.e. Δφ = π/N over the rows and up to π for the intensity. The paper's Δφ is 2π/N_RF;
//! halving both spans keeps every spike inside one cycle without wrapping, so a small
//! change of intensity never moves a spike from the end of the cycle to its start.
//!
//! The paper's text also admits a per-pixel reading ("ϕ_i represents the phase of the i-th
//! pixel"), offered as [`SnnEncoding::Pixel`]: one afferent per pixel, the lit pixel of
//! each row (and `pixel_spread` neighbours either side) firing at the row's phase
//! T (r + ½)/N; silent afferents carry +∞. In `tests/it/landmark.rs` it fits the survey
//! better than the row-phase code but generalises worse to other walks
//! (docs/validation.md, "Magnetic landmarks").
//!
//! **Learning.** On an error trial — a positive pattern that did not fire, or a negative
//! pattern that did — every weight moves along the gradient of V(t_max):
//! Δw_i = ±λ Σ_{t_i < t_max} K(t_max − t_i), with t_max the time of the potential's maximum
//! (positive sign for a missed positive pattern, negative for a false alarm). Correct
//! trials leave the weights alone.
//!
//! **Classifier.** One neuron per landmark, trained one-vs-rest on the survey's windows
//! (windows of the other landmarks and windows near no landmark are negatives). A query's
//! candidates are the neurons that fire, best (largest V_max − V_th) first.
//!
//! V(t) is evaluated on a uniform grid over [0, T + 3τ] with two exponentially decaying
//! running sums (one per time constant), so one neuron costs O(grid + afferents) and no
//! allocation once the caller's scratch has grown.

use super::landmark::{Candidate, FEATURE_LEN, IMAGE_COLUMNS};
use super::MagneticError;
use crate::core::config::check_range;
use crate::core::{ConfigIssue, StreamRng};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

fn d_tau() -> f64 {
    10.0
}
fn d_tau_s() -> f64 {
    2.5
}
fn d_cycle() -> f64 {
    100.0
}
fn d_lambda() -> f64 {
    0.02
}
fn d_epochs() -> usize {
    300
}
fn d_grid() -> usize {
    256
}
fn d_init() -> f64 {
    0.05
}
fn d_margin() -> f64 {
    0.2
}
fn d_spread() -> usize {
    1
}

/// How an image becomes spikes (see the module docs).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum SnnEncoding {
    /// One afferent per image row, firing once at a time set by the row's phase and its
    /// lit column ([`phase_encode`]).
    #[default]
    RowPhase,
    /// One afferent per pixel; the lit pixel of each row and its `pixel_spread`
    /// neighbours on either side fire at the row's phase ([`pixel_encode`]).
    Pixel,
}

/// The Tempotron's constants and training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SnnConfig {
    /// Membrane time constant τ (ms); default 10.
    #[serde(default = "d_tau")]
    pub tau_ms: f64,
    /// Synaptic time constant τs (ms), below τ; default 2.5 (Gütig & Sompolinsky's τ/4).
    #[serde(default = "d_tau_s")]
    pub tau_s_ms: f64,
    /// The encoding cycle T (ms); default 100.
    #[serde(default = "d_cycle")]
    pub cycle_ms: f64,
    /// Learning rate λ; default 0.02.
    #[serde(default = "d_lambda")]
    pub learning_rate: f64,
    /// Passes over the training set at most; default 300.
    #[serde(default = "d_epochs")]
    pub max_epochs: usize,
    /// Points of the time grid V(t) is evaluated on; default 256.
    #[serde(default = "d_grid")]
    pub grid_points: usize,
    /// σ of the normal initial weights; default 0.05.
    #[serde(default = "d_init")]
    pub init_weight_sigma: f64,
    /// Learning margin κ: during training a positive pattern counts as an error unless
    /// V_max ≥ 1 + κ, a negative one unless V_max < 1 − κ; default 0.2. With κ = 0 the rule
    /// stops at the first weights that separate the training set, often with every
    /// pattern a hair from the threshold, and new patterns fall either side by chance.
    #[serde(default = "d_margin")]
    pub margin: f64,
    /// `row_phase` (default) or `pixel`.
    #[serde(default)]
    pub encoding: SnnEncoding,
    /// With the pixel encoding, the neighbouring columns on either side of the lit pixel
    /// that fire with it (a population code, so that a one-column shift between walks
    /// still reaches trained synapses); default 1.
    #[serde(default = "d_spread")]
    pub pixel_spread: usize,
}

impl Default for SnnConfig {
    fn default() -> Self {
        Self {
            tau_ms: d_tau(),
            tau_s_ms: d_tau_s(),
            cycle_ms: d_cycle(),
            learning_rate: d_lambda(),
            max_epochs: d_epochs(),
            grid_points: d_grid(),
            init_weight_sigma: d_init(),
            margin: d_margin(),
            encoding: SnnEncoding::RowPhase,
            pixel_spread: d_spread(),
        }
    }
}

impl SnnConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field (τs must be below τ; the grid needs at
    /// least 16 points).
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check_range("tau_ms", self.tau_ms, 0.0, 1.0e4, true, "a finite value")?;
        check_range(
            "tau_s_ms",
            self.tau_s_ms,
            0.0,
            1.0e4,
            true,
            "a finite value",
        )?;
        if self.tau_s_ms >= self.tau_ms {
            return Err(ConfigIssue::new(
                "tau_s_ms",
                format!(
                    "expected a synaptic time constant below tau_ms = {} ms, got {} ms",
                    self.tau_ms, self.tau_s_ms
                ),
            ));
        }
        check_range(
            "cycle_ms",
            self.cycle_ms,
            0.0,
            1.0e5,
            true,
            "a finite value",
        )?;
        check_range(
            "learning_rate",
            self.learning_rate,
            0.0,
            10.0,
            true,
            "a finite value",
        )?;
        if self.max_epochs == 0 || self.max_epochs > 100_000 {
            return Err(ConfigIssue::new(
                "max_epochs",
                format!("expected 1..=100000 epochs, got {}", self.max_epochs),
            ));
        }
        if self.grid_points < 16 || self.grid_points > 1_000_000 {
            return Err(ConfigIssue::new(
                "grid_points",
                format!(
                    "expected 16..=1000000 grid points, got {}",
                    self.grid_points
                ),
            ));
        }
        if !(self.init_weight_sigma.is_finite() && self.init_weight_sigma >= 0.0) {
            return Err(ConfigIssue::new(
                "init_weight_sigma",
                format!(
                    "expected a finite non-negative σ, got {}",
                    self.init_weight_sigma
                ),
            ));
        }
        if self.pixel_spread > IMAGE_COLUMNS {
            return Err(ConfigIssue::new(
                "pixel_spread",
                format!(
                    "expected at most {IMAGE_COLUMNS} columns, got {}",
                    self.pixel_spread
                ),
            ));
        }
        if !(self.margin.is_finite() && (0.0..1.0).contains(&self.margin)) {
            return Err(ConfigIssue::new(
                "margin",
                format!("expected a margin within [0, 1), got {}", self.margin),
            ));
        }
        Ok(())
    }
}

/// The postsynaptic-potential kernel K(t) = V0 (e^(−t/τ) − e^(−t/τs)) with its peak
/// normalised to 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LifKernel {
    tau_ms: f64,
    tau_s_ms: f64,
    v0: f64,
}

impl LifKernel {
    /// The kernel for τ > τs > 0.
    ///
    /// # Errors
    /// [`MagneticError::Config`] when the constants are not finite, positive and ordered.
    pub fn new(tau_ms: f64, tau_s_ms: f64) -> Result<Self, MagneticError> {
        check_range("tau_ms", tau_ms, 0.0, 1.0e4, true, "a finite value")?;
        check_range("tau_s_ms", tau_s_ms, 0.0, 1.0e4, true, "a finite value")?;
        if tau_s_ms >= tau_ms {
            return Err(ConfigIssue::new("tau_s_ms", "expected τs < τ").into());
        }
        let t_peak = Self::peak_time(tau_ms, tau_s_ms);
        let v0 = 1.0 / ((-t_peak / tau_ms).exp() - (-t_peak / tau_s_ms).exp());
        Ok(Self {
            tau_ms,
            tau_s_ms,
            v0,
        })
    }

    fn peak_time(tau: f64, tau_s: f64) -> f64 {
        tau * tau_s * (tau / tau_s).ln() / (tau - tau_s)
    }

    /// The time of the kernel's peak t* (ms).
    pub fn peak_time_ms(&self) -> f64 {
        Self::peak_time(self.tau_ms, self.tau_s_ms)
    }

    /// The normalisation V0.
    pub fn v0(&self) -> f64 {
        self.v0
    }

    /// K(t) (0 for t < 0).
    pub fn eval(&self, t_ms: f64) -> f64 {
        if t_ms < 0.0 {
            0.0
        } else {
            self.v0 * ((-t_ms / self.tau_ms).exp() - (-t_ms / self.tau_s_ms).exp())
        }
    }
}

/// Phase encoding of an image (one lit column per row) into one spike time per row (ms);
/// see the module docs for the formula.
pub fn phase_encode(image: &[u8; FEATURE_LEN], cycle_ms: f64) -> [f64; FEATURE_LEN] {
    let n = FEATURE_LEN as f64;
    let m1 = (IMAGE_COLUMNS - 1) as f64;
    std::array::from_fn(|i| {
        let c = f64::from(image[i]).min(m1);
        cycle_ms * (i as f64 / (2.0 * n) + c / (2.0 * m1))
    })
}

/// Pixel encoding: afferent r·M + c is pixel (row r, column c). The lit pixel of row r and
/// its `spread` neighbours on either side fire at the row's phase time T (r + ½)/N
/// (φ_r = φ0 + r Δφ with Δφ = 2π/N, seed 002 eqs. 2–3); every other afferent is silent
/// (+∞). `out` is resized to N·M.
pub fn pixel_encode(image: &[u8; FEATURE_LEN], cycle_ms: f64, spread: usize, out: &mut Vec<f64>) {
    out.clear();
    out.resize(FEATURE_LEN * IMAGE_COLUMNS, f64::INFINITY);
    for (r, &c) in image.iter().enumerate() {
        let c = usize::from(c).min(IMAGE_COLUMNS - 1);
        let t = cycle_ms * (r as f64 + 0.5) / FEATURE_LEN as f64;
        for col in c.saturating_sub(spread)..=(c + spread).min(IMAGE_COLUMNS - 1) {
            out[r * IMAGE_COLUMNS + col] = t;
        }
    }
}

/// The afferent count of an encoding.
pub fn afferents_of(encoding: SnnEncoding) -> usize {
    match encoding {
        SnnEncoding::RowPhase => FEATURE_LEN,
        SnnEncoding::Pixel => FEATURE_LEN * IMAGE_COLUMNS,
    }
}

/// Encodes `image` as `cfg` says into `out` (one time per afferent, +∞ when silent).
pub fn encode(image: &[u8; FEATURE_LEN], cfg: &SnnConfig, out: &mut Vec<f64>) {
    match cfg.encoding {
        SnnEncoding::RowPhase => {
            out.clear();
            out.extend_from_slice(&phase_encode(image, cfg.cycle_ms));
        }
        SnnEncoding::Pixel => pixel_encode(image, cfg.cycle_ms, cfg.pixel_spread, out),
    }
}

/// Caller-owned buffers for the forward pass (spike order, encoded spikes).
#[derive(Clone, Debug, Default)]
pub struct SnnScratch {
    order: Vec<usize>,
    spikes: Vec<f64>,
}

/// One Tempotron neuron over a fixed number of afferents, each firing once per pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct Tempotron {
    weights: Vec<f64>,
    kernel: LifKernel,
    cycle_ms: f64,
    grid_points: usize,
    horizon_ms: f64,
}

impl Tempotron {
    /// A neuron with `n_afferents` inputs and normal initial weights N(0, σ²) drawn from
    /// `rng` (a named stream).
    ///
    /// # Errors
    /// [`MagneticError::Config`] for a bad configuration or zero afferents.
    pub fn new(
        n_afferents: usize,
        cfg: &SnnConfig,
        rng: &mut StreamRng,
    ) -> Result<Self, MagneticError> {
        cfg.validate()?;
        if n_afferents == 0 {
            return Err(ConfigIssue::new("n_afferents", "expected at least one afferent").into());
        }
        let kernel = LifKernel::new(cfg.tau_ms, cfg.tau_s_ms)?;
        let weights = (0..n_afferents)
            .map(|_| cfg.init_weight_sigma * rng.sample::<f64, _>(StandardNormal))
            .collect();
        Ok(Self {
            weights,
            kernel,
            cycle_ms: cfg.cycle_ms,
            grid_points: cfg.grid_points,
            horizon_ms: cfg.cycle_ms + 3.0 * cfg.tau_ms,
        })
    }

    /// The synaptic weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The kernel.
    pub fn kernel(&self) -> &LifKernel {
        &self.kernel
    }

    /// The encoding cycle T (ms).
    pub fn cycle_ms(&self) -> f64 {
        self.cycle_ms
    }

    /// (V_max, t_max) of the pattern `spike_times_ms` (one spike per afferent, the times
    /// already ordered by `order`, an index permutation sorting them ascending).
    fn forward_sorted(&self, spike_times_ms: &[f64], order: &[usize]) -> (f64, f64) {
        let dt = self.horizon_ms / (self.grid_points - 1) as f64;
        let (tau, tau_s) = (self.kernel.tau_ms, self.kernel.tau_s_ms);
        let (da, db) = ((-dt / tau).exp(), (-dt / tau_s).exp());
        let (mut a, mut b) = (0.0, 0.0);
        let mut next = 0;
        let (mut v_max, mut t_max) = (f64::NEG_INFINITY, 0.0);
        for k in 0..self.grid_points {
            let t = k as f64 * dt;
            if k > 0 {
                a *= da;
                b *= db;
            }
            // Spikes strictly before t start contributing (K(0) = 0, so a spike exactly at
            // t adds nothing yet).
            while next < order.len() && spike_times_ms[order[next]] < t {
                let i = order[next];
                let s = t - spike_times_ms[i];
                a += self.weights[i] * (-s / tau).exp();
                b += self.weights[i] * (-s / tau_s).exp();
                next += 1;
            }
            let v = self.kernel.v0 * (a - b);
            if v > v_max {
                v_max = v;
                t_max = t;
            }
        }
        (v_max, t_max)
    }

    fn sort_order(spike_times_ms: &[f64], scratch: &mut SnnScratch) {
        scratch.order.clear();
        scratch.order.extend(0..spike_times_ms.len());
        // Unstable sort: it never allocates (the stable one takes a buffer), and ties are
        // broken by index so the order is still fully determined.
        scratch.order.sort_unstable_by(|&x, &y| {
            spike_times_ms[x]
                .total_cmp(&spike_times_ms[y])
                .then(x.cmp(&y))
        });
    }

    /// The maximum of the membrane potential over the pattern and its time (V_max, t_max ms).
    ///
    /// # Errors
    /// [`MagneticError::Input`] when the pattern's length differs from the afferent count
    /// or a spike time is not finite.
    pub fn v_max(
        &self,
        spike_times_ms: &[f64],
        scratch: &mut SnnScratch,
    ) -> Result<(f64, f64), MagneticError> {
        self.check_pattern(spike_times_ms)?;
        Self::sort_order(spike_times_ms, scratch);
        Ok(self.forward_sorted(spike_times_ms, &scratch.order))
    }

    fn check_pattern(&self, spike_times_ms: &[f64]) -> Result<(), MagneticError> {
        if spike_times_ms.len() != self.weights.len() {
            return Err(MagneticError::Input(format!(
                "expected {} spike times, got {}",
                self.weights.len(),
                spike_times_ms.len()
            )));
        }
        // +∞ marks a silent afferent (it never reaches t_max, so it neither contributes
        // nor learns); NaN and −∞ are errors.
        if spike_times_ms
            .iter()
            .any(|t| t.is_nan() || *t == f64::NEG_INFINITY)
        {
            return Err(MagneticError::Input(
                "expected spike times that are finite or +∞ (silent)".into(),
            ));
        }
        Ok(())
    }

    /// One learning trial: if the neuron's decision (fire iff V_max ≥ 1 + κ for a positive
    /// `target`, stay below 1 − κ for a negative one; κ = `margin`) is wrong, the weights
    /// move by ±λ K(t_max − t_i). Returns whether the trial was an error.
    ///
    /// # Errors
    /// As [`Tempotron::v_max`].
    pub fn learn(
        &mut self,
        spike_times_ms: &[f64],
        target: bool,
        learning_rate: f64,
        margin: f64,
        scratch: &mut SnnScratch,
    ) -> Result<bool, MagneticError> {
        let (v_max, t_max) = self.v_max(spike_times_ms, scratch)?;
        let ok = if target {
            v_max >= 1.0 + margin
        } else {
            v_max < 1.0 - margin
        };
        if ok {
            return Ok(false);
        }
        let sign = if target { 1.0 } else { -1.0 };
        for (w, &t_i) in self.weights.iter_mut().zip(spike_times_ms) {
            if t_i < t_max {
                *w += sign * learning_rate * self.kernel.eval(t_max - t_i);
            }
        }
        Ok(true)
    }

    /// Trains on `patterns` (spike times, target) for at most `cfg.max_epochs` passes in an
    /// order shuffled by `rng`, stopping after a pass without error (margin included).
    /// Returns the errors of the last pass.
    ///
    /// # Errors
    /// As [`Tempotron::v_max`], or [`MagneticError::Input`] for no patterns.
    pub fn train(
        &mut self,
        patterns: &[(Vec<f64>, bool)],
        cfg: &SnnConfig,
        rng: &mut StreamRng,
        scratch: &mut SnnScratch,
    ) -> Result<usize, MagneticError> {
        if patterns.is_empty() {
            return Err(MagneticError::Input(
                "expected at least one training pattern".into(),
            ));
        }
        let mut idx: Vec<usize> = (0..patterns.len()).collect();
        let mut errors = 0;
        for _ in 0..cfg.max_epochs {
            shuffle(&mut idx, rng);
            errors = 0;
            for &k in &idx {
                let (p, target) = &patterns[k];
                if self.learn(p, *target, cfg.learning_rate, cfg.margin, scratch)? {
                    errors += 1;
                }
            }
            if errors == 0 {
                break;
            }
        }
        Ok(errors)
    }
}

/// Fisher–Yates with the caller's stream, so the training order is part of the named
/// randomness and not of any global state.
fn shuffle(idx: &mut [usize], rng: &mut StreamRng) {
    for i in (1..idx.len()).rev() {
        let j = rng.random_range(0..=i);
        idx.swap(i, j);
    }
}

/// One Tempotron per landmark, trained one-vs-rest.
#[derive(Clone, Debug, PartialEq)]
pub struct SnnClassifier {
    neurons: Vec<Tempotron>,
    cfg: SnnConfig,
    /// Training errors left in each neuron's last epoch.
    pub residual_errors: Vec<usize>,
}

impl SnnClassifier {
    /// Trains a classifier for labels `0..n_labels` on `samples`: each an image and its
    /// label (`None` for a window near no landmark, a negative for every neuron). Neuron k's
    /// weights are drawn and its training order shuffled from `rng`, in label order.
    ///
    /// # Errors
    /// [`MagneticError::Config`] for a bad configuration or zero labels;
    /// [`MagneticError::Input`] for no samples or a label out of range.
    pub fn train(
        samples: &[(Option<usize>, [u8; FEATURE_LEN])],
        n_labels: usize,
        cfg: &SnnConfig,
        rng: &mut StreamRng,
    ) -> Result<Self, MagneticError> {
        cfg.validate()?;
        if n_labels == 0 {
            return Err(ConfigIssue::new("n_labels", "expected at least one landmark").into());
        }
        if samples.is_empty() {
            return Err(MagneticError::Input("expected training samples".into()));
        }
        if let Some((l, _)) = samples
            .iter()
            .find(|(l, _)| l.is_some_and(|l| l >= n_labels))
        {
            return Err(MagneticError::Input(format!(
                "label {l:?} is not below the classifier's {n_labels} labels"
            )));
        }
        let encoded: Vec<(Option<usize>, Vec<f64>)> = samples
            .iter()
            .map(|(l, img)| {
                let mut v = Vec::new();
                encode(img, cfg, &mut v);
                (*l, v)
            })
            .collect();
        let mut scratch = SnnScratch::default();
        let mut neurons = Vec::with_capacity(n_labels);
        let mut residual_errors = Vec::with_capacity(n_labels);
        for k in 0..n_labels {
            let mut neuron = Tempotron::new(afferents_of(cfg.encoding), cfg, rng)?;
            let patterns: Vec<(Vec<f64>, bool)> = encoded
                .iter()
                .map(|(l, p)| (p.clone(), *l == Some(k)))
                .collect();
            residual_errors.push(neuron.train(&patterns, cfg, rng, &mut scratch)?);
            neurons.push(neuron);
        }
        Ok(Self {
            neurons,
            cfg: cfg.clone(),
            residual_errors,
        })
    }

    /// The neurons, one per label.
    pub fn neurons(&self) -> &[Tempotron] {
        &self.neurons
    }

    /// The labels whose neuron fires on `image`, best (largest V_max − 1) first, into `out`
    /// (cleared first). Allocates nothing once `scratch` and `out` have grown.
    pub fn candidates(
        &self,
        image: &[u8; FEATURE_LEN],
        scratch: &mut SnnScratch,
        out: &mut Vec<Candidate>,
    ) {
        out.clear();
        let mut spikes = std::mem::take(&mut scratch.spikes);
        encode(image, &self.cfg, &mut spikes);
        Tempotron::sort_order(&spikes, scratch);
        for (label, n) in self.neurons.iter().enumerate() {
            let (v_max, _) = n.forward_sorted(&spikes, &scratch.order);
            if v_max >= 1.0 {
                out.push(Candidate {
                    label,
                    score: v_max - 1.0,
                });
            }
        }
        out.sort_unstable_by(|a, b| b.score.total_cmp(&a.score).then(a.label.cmp(&b.label)));
        scratch.spikes = spikes;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn kernel_peaks_at_one_at_the_analytic_time() {
        let k = LifKernel::new(15.0, 3.75).unwrap();
        let t = k.peak_time_ms();
        assert!((k.eval(t) - 1.0).abs() < 1e-12);
        // The derivative vanishes there: neighbours are lower.
        assert!(k.eval(t - 0.01) < 1.0 && k.eval(t + 0.01) < 1.0);
        // A fine scan finds no larger value.
        let max = (0..100_000)
            .map(|i| k.eval(i as f64 * 1e-3))
            .fold(0.0, f64::max);
        assert!(max <= 1.0 + 1e-12 && max > 1.0 - 1e-6);
        assert_eq!(k.eval(-1.0), 0.0);
        assert!(LifKernel::new(2.0, 3.0).is_err());
    }

    #[test]
    fn grid_forward_pass_matches_the_direct_sum() {
        let cfg = SnnConfig::default();
        let mut rng = TrialRng::new(7, 0).stream("magnetic/snn/test");
        let mut n = Tempotron::new(FEATURE_LEN, &cfg, &mut rng).unwrap();
        for w in &mut n.weights {
            *w = 0.3;
        }
        let img: [u8; FEATURE_LEN] = std::array::from_fn(|i| ((i * 5) % IMAGE_COLUMNS) as u8);
        let spikes = phase_encode(&img, cfg.cycle_ms);
        let mut s = SnnScratch::default();
        let (v_max, t_max) = n.v_max(&spikes, &mut s).unwrap();
        let direct: f64 = spikes
            .iter()
            .map(|&ti| 0.3 * n.kernel.eval(t_max - ti))
            .sum();
        assert!((v_max - direct).abs() < 1e-9 * direct.abs().max(1.0));
    }

    #[test]
    fn pixel_encoding_lights_the_row_and_its_neighbours_and_silence_is_inert() {
        let mut img = [5u8; FEATURE_LEN];
        img[0] = 0; // the left neighbour is clipped
        img[1] = (IMAGE_COLUMNS - 1) as u8; // the right neighbour is clipped
        let mut out = Vec::new();
        pixel_encode(&img, 100.0, 1, &mut out);
        assert_eq!(out.len(), FEATURE_LEN * IMAGE_COLUMNS);
        let firing = out.iter().filter(|t| t.is_finite()).count();
        assert_eq!(firing, 3 * FEATURE_LEN - 2);
        // Row 2's three pixels fire together at T (2 + ½)/N.
        let t2 = 100.0 * 2.5 / FEATURE_LEN as f64;
        for col in 4..=6 {
            assert_eq!(out[2 * IMAGE_COLUMNS + col], t2);
        }
        assert!(out[2 * IMAGE_COLUMNS + 7].is_infinite());
        // A pattern of silent afferents leaves the potential at rest.
        let cfg = SnnConfig::default();
        let mut rng = TrialRng::new(7, 0).stream("magnetic/snn/test");
        let n = Tempotron::new(4, &cfg, &mut rng).unwrap();
        let mut s = SnnScratch::default();
        let (v, _) = n.v_max(&[f64::INFINITY; 4], &mut s).unwrap();
        assert_eq!(v, 0.0);
        assert!(n
            .v_max(&[f64::NEG_INFINITY, 1.0, 2.0, 3.0], &mut s)
            .is_err());
    }
}
