//! The receiver's clock: a two-state random process for its bias and drift, and the
//! inter-system biases of the systems it tracks besides GPS.
//!
//! # Model
//!
//! The oscillator's fractional frequency y has the power-law spectrum
//! `S_y(f) = h₀ + h₋₂ f⁻²` (white FM and random-walk FM; flicker FM is left out, as in the
//! two-state model). Following Brown & Hwang (*Introduction to Random Signals and Applied
//! Kalman Filtering*, 4th ed., §9.3, and the clock model of their GPS examples), the clock
//! bias b (s) and drift d (s/s) obey
//!
//! ```text
//! ḃ = d + w_b,   ḋ = w_d,   S_b = h₀/2,   S_d = 2π² h₋₂,
//! ```
//!
//! with w_b, w_d independent white noises of spectral densities S_b, S_d. Over a step T the
//! exact discrete model is
//!
//! ```text
//! ┌b┐        ┌1 T┐┌b┐       ,        ┌ S_b T + S_d T³/3   S_d T²/2 ┐
//! └d┘_{k+1} = └0 1┘└d┘_k + u_k,   Q = │                            │ .
//!                                     └ S_d T²/2           S_d T    ┘
//! ```
//!
//! The Allan variance of the resulting phase is `σ_y²(τ) = h₀/(2τ) + (2π²/3) h₋₂ τ`
//! (the white-FM and random-walk-FM terms of the power-law table), which the tests check.
//!
//! Presets (h₀ in s, h₋₂ in 1/s), from Brown & Hwang's Table 9.1 of typical oscillators:
//!
//! | oscillator | h₀       | h₋₂      |
//! |------------|----------|----------|
//! | `tcxo`     | 2·10⁻¹⁹  | 2·10⁻²⁰  |
//! | `ocxo`     | 2·10⁻²⁵  | 6·10⁻²⁵  |
//!
//! # Inter-system biases
//!
//! GPS time as the receiver sees it is the reference; every other system s has an
//! inter-system bias ISB_s (the receiver's hardware delay difference plus the offset of the
//! system's time scale as broadcast), a constant `inter_system_bias_ns[s]` plus an optional
//! random walk of intensity `isb_random_walk_ns_per_sqrt_s[s]`
//! (ISB(t + T) = ISB(t) + q √T n, n ~ N(0, 1)). [`ReceiverClock::isb_s`] returns it in
//! seconds; it is 0 for GPS and for systems not listed.

use crate::core::config::check;
use crate::core::{ConfigIssue, System};
use nalgebra::{Matrix2, Vector2};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// The oscillator class of a receiver clock.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Oscillator {
    /// Temperature-compensated crystal: h₀ = 2e-19 s, h₋₂ = 2e-20 /s.
    #[default]
    Tcxo,
    /// Oven-controlled crystal: h₀ = 2e-25 s, h₋₂ = 6e-25 /s.
    Ocxo,
    /// The `h0_s` and `h_minus2_hz` of the configuration.
    Custom,
}

impl Oscillator {
    /// (h₀ in s, h₋₂ in 1/s) of a preset; `None` for [`Oscillator::Custom`].
    pub fn preset(self) -> Option<(f64, f64)> {
        match self {
            Oscillator::Tcxo => Some((2e-19, 2e-20)),
            Oscillator::Ocxo => Some((2e-25, 6e-25)),
            Oscillator::Custom => None,
        }
    }
}

/// `[receiver.clock]` in a world file. Every field has a default: a TCXO starting with zero
/// bias and drift and no inter-system biases.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ClockConfig {
    /// `"tcxo"` (default), `"ocxo"` or `"custom"`.
    pub oscillator: Oscillator,
    /// White-FM coefficient h₀ (s); required with `oscillator = "custom"`, refused otherwise.
    pub h0_s: Option<f64>,
    /// Random-walk-FM coefficient h₋₂ (1/s); required with `oscillator = "custom"`.
    pub h_minus2_hz: Option<f64>,
    /// Mean initial bias (s).
    pub initial_bias_s: f64,
    /// Mean initial drift (s/s).
    pub initial_drift_s_per_s: f64,
    /// 1-σ of a Gaussian spread of the initial bias around its mean (s); 0: none.
    pub initial_bias_sigma_s: f64,
    /// 1-σ of a Gaussian spread of the initial drift (s/s); 0: none.
    pub initial_drift_sigma_s_per_s: f64,
    /// Constant inter-system bias per system other than GPS (ns), e.g. `{ bds = 12.0 }`.
    pub inter_system_bias_ns: BTreeMap<System, f64>,
    /// Random-walk intensity of the inter-system bias per system (ns/√s); 0 or absent: constant.
    pub isb_random_walk_ns_per_sqrt_s: BTreeMap<System, f64>,
}

impl ClockConfig {
    /// The power-law coefficients (h₀ in s, h₋₂ in 1/s) this configuration selects.
    /// A custom oscillator with a missing coefficient reads it as 0 (validation refuses it).
    pub fn h_coefficients(&self) -> (f64, f64) {
        self.oscillator
            .preset()
            .unwrap_or((self.h0_s.unwrap_or(0.0), self.h_minus2_hz.unwrap_or(0.0)))
    }

    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the field: missing or refused h-coefficients, negative or
    /// non-finite values, an initial bias over one second, a drift over 1e-3, or an entry
    /// for GPS (the reference) among the inter-system biases.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let custom = self.oscillator == Oscillator::Custom;
        for (key, v) in [("h0_s", self.h0_s), ("h_minus2_hz", self.h_minus2_hz)] {
            match (custom, v) {
                (true, None) => return Err(ConfigIssue::new(key, format!("expected {key} with oscillator = \"custom\""))),
                (false, Some(_)) => {
                    return Err(ConfigIssue::new(
                        key,
                        format!("{key} is only read with oscillator = \"custom\"; remove it or set oscillator = \"custom\""),
                    ))
                }
                (true, Some(h)) => check(key, h.is_finite() && (0.0..=1e-10).contains(&h), || {
                    format!("expected a non-negative power-law coefficient of at most 1e-10, got {h}")
                })?,
                (false, None) => {}
            }
        }
        let b = self.initial_bias_s;
        check("initial_bias_s", b.is_finite() && b.abs() <= 1.0, || {
            format!("expected an initial bias in s within ±1, got {b}")
        })?;
        let d = self.initial_drift_s_per_s;
        check(
            "initial_drift_s_per_s",
            d.is_finite() && d.abs() <= 1e-3,
            || format!("expected an initial drift in s/s within ±1e-3, got {d}"),
        )?;
        let s = self.initial_bias_sigma_s;
        check(
            "initial_bias_sigma_s",
            s.is_finite() && (0.0..=1.0).contains(&s),
            || format!("expected a non-negative 1-σ in s of at most 1, got {s}"),
        )?;
        let s = self.initial_drift_sigma_s_per_s;
        check(
            "initial_drift_sigma_s_per_s",
            s.is_finite() && (0.0..=1e-3).contains(&s),
            || format!("expected a non-negative 1-σ in s/s of at most 1e-3, got {s}"),
        )?;
        for (key, map, lo) in [
            ("inter_system_bias_ns", &self.inter_system_bias_ns, -1e6),
            (
                "isb_random_walk_ns_per_sqrt_s",
                &self.isb_random_walk_ns_per_sqrt_s,
                0.0,
            ),
        ] {
            for (sys, v) in map {
                check(key, *sys != System::Gps, || {
                    format!("GPS is the receiver's reference time scale, so it has no inter-system bias; remove the \"gps\" entry of {key}")
                })?;
                check(key, v.is_finite() && *v >= lo && v.abs() <= 1e6, || {
                    format!(
                        "expected a finite value within [{lo}, 1e6] for {}, got {v}",
                        sys.name()
                    )
                })?;
            }
        }
        Ok(())
    }
}

/// The exact discrete process noise covariance of the two-state clock over `dt_s`
/// (Brown & Hwang): `S_b = h₀/2`, `S_d = 2π²h₋₂`.
pub fn clock_process_noise(h0_s: f64, h_minus2_hz: f64, dt_s: f64) -> Matrix2<f64> {
    let sb = h0_s / 2.0;
    let sd = 2.0 * PI * PI * h_minus2_hz;
    let t = dt_s;
    Matrix2::new(
        sb * t + sd * t.powi(3) / 3.0,
        sd * t * t / 2.0,
        sd * t * t / 2.0,
        sd * t,
    )
}

/// The Allan variance `h₀/(2τ) + (2π²/3) h₋₂ τ` of the two-state clock at averaging time τ.
pub fn allan_variance_model(h0_s: f64, h_minus2_hz: f64, tau_s: f64) -> f64 {
    h0_s / (2.0 * tau_s) + 2.0 * PI * PI / 3.0 * h_minus2_hz * tau_s
}

/// The overlapping Allan variance at τ = m·τ₀ of phase samples `x` (s) taken every `tau0_s`:
/// `σ_y²(τ) = Σ (x_{i+2m} − 2x_{i+m} + x_i)² / (2τ²(N − 2m))`. `None` when there are fewer
/// than 2m + 1 samples or m is 0.
pub fn overlapping_allan_variance(x: &[f64], tau0_s: f64, m: usize) -> Option<f64> {
    if m == 0 || x.len() < 2 * m + 1 {
        return None;
    }
    let n = x.len() - 2 * m;
    let tau = m as f64 * tau0_s;
    let sum: f64 = (0..n)
        .map(|i| (x[i + 2 * m] - 2.0 * x[i + m] + x[i]).powi(2))
        .sum();
    Some(sum / (2.0 * tau * tau * n as f64))
}

/// The receiver clock of one trial.
#[derive(Clone, Debug, PartialEq)]
pub struct ReceiverClock {
    h0_s: f64,
    h_minus2_hz: f64,
    state: Vector2<f64>,
    /// (system, ISB in s, random-walk intensity in s/√s).
    isb: Vec<(System, f64, f64)>,
}

/// Zero for non-finite or negative values: the infallible constructor's sanitiser.
fn non_negative(v: f64) -> f64 {
    if v.is_finite() && v > 0.0 {
        v
    } else {
        0.0
    }
}

fn finite_or_zero(v: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

impl ReceiverClock {
    /// A clock at its initial state: the configured mean bias and drift plus, when the
    /// sigmas are positive, Gaussian spreads drawn from `rng` (two standard normals, always
    /// drawn so that the stream's use does not depend on the sigmas).
    ///
    /// This constructor never fails: call [`ClockConfig::validate`] first; values it would
    /// refuse are read defensively (non-finite or negative magnitudes as 0).
    pub fn new(cfg: &ClockConfig, rng: &mut impl Rng) -> Self {
        let (h0, hm2) = cfg.h_coefficients();
        let n_b: f64 = rng.sample(StandardNormal);
        let n_d: f64 = rng.sample(StandardNormal);
        let bias =
            finite_or_zero(cfg.initial_bias_s) + non_negative(cfg.initial_bias_sigma_s) * n_b;
        let drift = finite_or_zero(cfg.initial_drift_s_per_s)
            + non_negative(cfg.initial_drift_sigma_s_per_s) * n_d;
        let mut systems: Vec<System> = cfg
            .inter_system_bias_ns
            .keys()
            .chain(cfg.isb_random_walk_ns_per_sqrt_s.keys())
            .copied()
            .collect();
        systems.sort();
        systems.dedup();
        let isb = systems
            .into_iter()
            .filter(|s| *s != System::Gps)
            .map(|s| {
                let b =
                    finite_or_zero(cfg.inter_system_bias_ns.get(&s).copied().unwrap_or(0.0)) * 1e-9;
                let q = non_negative(
                    cfg.isb_random_walk_ns_per_sqrt_s
                        .get(&s)
                        .copied()
                        .unwrap_or(0.0),
                ) * 1e-9;
                (s, b, q)
            })
            .collect();
        Self {
            h0_s: non_negative(h0),
            h_minus2_hz: non_negative(hm2),
            state: Vector2::new(bias, drift),
            isb,
        }
    }

    /// Validates the configuration, then builds the clock.
    ///
    /// # Errors
    /// The [`ConfigIssue`] of [`ClockConfig::validate`].
    pub fn try_new(cfg: &ClockConfig, rng: &mut impl Rng) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        Ok(Self::new(cfg, rng))
    }

    /// Advances the clock by `dt_s` seconds with the exact discrete model (two standard
    /// normals, plus one per inter-system bias with a random walk). A non-positive or
    /// non-finite step leaves the clock unchanged: the clock only moves forward.
    pub fn step(&mut self, dt_s: f64, rng: &mut impl Rng) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let q = clock_process_noise(self.h0_s, self.h_minus2_hz, dt_s);
        // Cholesky factor of the 2×2 Q, written out; Q is positive semi-definite by
        // construction, the clamps only absorb rounding.
        let l11 = q[(0, 0)].max(0.0).sqrt();
        let l21 = if l11 > 0.0 { q[(1, 0)] / l11 } else { 0.0 };
        let l22 = (q[(1, 1)] - l21 * l21).max(0.0).sqrt();
        let n1: f64 = rng.sample(StandardNormal);
        let n2: f64 = rng.sample(StandardNormal);
        let (b, d) = (self.state.x, self.state.y);
        self.state = Vector2::new(b + d * dt_s + l11 * n1, d + l21 * n1 + l22 * n2);
        for (_, isb, q) in &mut self.isb {
            if *q > 0.0 {
                let n: f64 = rng.sample(StandardNormal);
                *isb += *q * dt_s.sqrt() * n;
            }
        }
    }

    /// Clock bias (s): receiver time minus GPS time.
    pub fn bias_s(&self) -> f64 {
        self.state.x
    }

    /// Clock drift (s/s).
    pub fn drift_s_per_s(&self) -> f64 {
        self.state.y
    }

    /// The inter-system bias of `sys` (s): 0 for GPS and for systems not configured.
    pub fn isb_s(&self, sys: System) -> f64 {
        self.isb
            .iter()
            .find(|(s, _, _)| *s == sys)
            .map_or(0.0, |(_, b, _)| *b)
    }

    /// The power-law coefficients (h₀ in s, h₋₂ in 1/s) in use.
    pub fn h_coefficients(&self) -> (f64, f64) {
        (self.h0_s, self.h_minus2_hz)
    }

    /// The process noise covariance of a step of `dt_s`, for filters modelling this clock.
    pub fn process_noise(&self, dt_s: f64) -> Matrix2<f64> {
        clock_process_noise(self.h0_s, self.h_minus2_hz, dt_s)
    }
}

/// The receiver clock of one trial, sampled once on a fixed grid so that every source of
/// the receiver (GNSS, DTMB, TC-OFDM) reads the *same* clock without sharing mutable
/// state: a source asks for the bias at its own sample time and gets the grid state
/// propagated by its drift, `b(t) = b_k + d_k (t − t_k)` for `t_k ≤ t < t_{k+1}`.
///
/// The grid step (0.1 s by default) is far below the clock's correlation times, so the
/// noise the interpolation leaves out (the diffusion within one step) is at the 1e-12 s
/// level for a TCXO. The random draws depend only on the stream and the duration, never on
/// which sources ask or when.
#[derive(Clone, Debug, PartialEq)]
pub struct ClockTrack {
    step_s: f64,
    /// (bias s, drift s/s) at `k·step_s`.
    states: Vec<(f64, f64)>,
    /// Inter-system biases (s) at `k·step_s`, one row per grid point, in `systems` order.
    systems: Vec<System>,
    isb: Vec<f64>,
}

impl ClockTrack {
    /// Runs `clock` forward over `[0, duration_s]` on a grid of `step_s`, drawing from `rng`.
    pub fn record(
        mut clock: ReceiverClock,
        duration_s: f64,
        step_s: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let step_s = if step_s.is_finite() && step_s > 0.0 {
            step_s
        } else {
            0.1
        };
        let n = if duration_s.is_finite() && duration_s > 0.0 {
            (duration_s / step_s).ceil() as usize + 2
        } else {
            2
        };
        let systems: Vec<System> = clock.isb.iter().map(|(s, _, _)| *s).collect();
        let mut states = Vec::with_capacity(n);
        let mut isb = Vec::with_capacity(n * systems.len());
        for k in 0..n {
            if k > 0 {
                clock.step(step_s, rng);
            }
            states.push((clock.bias_s(), clock.drift_s_per_s()));
            isb.extend(clock.isb.iter().map(|(_, b, _)| *b));
        }
        Self {
            step_s,
            states,
            systems,
            isb,
        }
    }

    fn index(&self, t_s: f64) -> (usize, f64) {
        let x = (t_s / self.step_s).max(0.0);
        let k = (x.floor() as usize).min(self.states.len() - 1);
        (k, t_s - k as f64 * self.step_s)
    }

    /// Clock bias (s) at `t_s` seconds into the trial: receiver time minus GPS time.
    pub fn bias_s(&self, t_s: f64) -> f64 {
        let (k, dt) = self.index(t_s);
        let (b, d) = self.states[k];
        b + d * dt
    }

    /// Clock drift (s/s) at `t_s`.
    pub fn drift_s_per_s(&self, t_s: f64) -> f64 {
        self.states[self.index(t_s).0].1
    }

    /// The inter-system bias of `sys` (s) at `t_s`: 0 for GPS and unconfigured systems.
    pub fn isb_s(&self, sys: System, t_s: f64) -> f64 {
        let Some(j) = self.systems.iter().position(|s| *s == sys) else {
            return 0.0;
        };
        let (k, _) = self.index(t_s);
        self.isb[k * self.systems.len() + j]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn presets_and_q() {
        let cfg = ClockConfig::default();
        assert_eq!(cfg.h_coefficients(), (2e-19, 2e-20));
        assert!(cfg.validate().is_ok());
        // Hand values for the TCXO at T = 1 s: S_b = 1e-19, S_d = 2π²·2e-20 = 3.9478e-19.
        let q = clock_process_noise(2e-19, 2e-20, 1.0);
        let sd = 2.0 * PI * PI * 2e-20;
        assert!((q[(0, 0)] - (1e-19 + sd / 3.0)).abs() < 1e-32);
        assert!((q[(0, 1)] - sd / 2.0).abs() < 1e-32 && (q[(1, 1)] - sd).abs() < 1e-32);
        assert!((sd - 3.947_841_760_435_743e-19).abs() < 1e-30);
    }

    #[test]
    fn validation_names_keys() {
        let mut c = ClockConfig {
            oscillator: Oscillator::Custom,
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "h0_s");
        c.h0_s = Some(1e-20);
        assert_eq!(c.validate().unwrap_err().key, "h_minus2_hz");
        c.h_minus2_hz = Some(-1.0);
        assert_eq!(c.validate().unwrap_err().key, "h_minus2_hz");
        c.h_minus2_hz = Some(1e-22);
        assert!(c.validate().is_ok());
        let c = ClockConfig {
            h0_s: Some(1e-20),
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "h0_s");
        let c = ClockConfig {
            initial_bias_sigma_s: -1.0,
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "initial_bias_sigma_s");
        let c = ClockConfig {
            initial_drift_s_per_s: f64::NAN,
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "initial_drift_s_per_s");
        let c = ClockConfig {
            inter_system_bias_ns: [(System::Gps, 3.0)].into(),
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "inter_system_bias_ns");
        let c = ClockConfig {
            isb_random_walk_ns_per_sqrt_s: [(System::Bds, -3.0)].into(),
            ..Default::default()
        };
        assert_eq!(
            c.validate().unwrap_err().key,
            "isb_random_walk_ns_per_sqrt_s"
        );
    }

    #[test]
    fn parses_from_toml() {
        let c: ClockConfig = toml::from_str(
            "oscillator = \"ocxo\"\ninitial_bias_s = 1e-4\ninter_system_bias_ns = { bds = 12.5 }\nisb_random_walk_ns_per_sqrt_s = { bds = 0.01 }\n",
        )
        .unwrap();
        assert_eq!(c.oscillator, Oscillator::Ocxo);
        assert_eq!(c.inter_system_bias_ns.get(&System::Bds), Some(&12.5));
        assert!(c.validate().is_ok());
        assert!(toml::from_str::<ClockConfig>("oscilator = \"ocxo\"").is_err());
        let clock = ReceiverClock::new(&c, &mut TrialRng::new(1, 0).stream("receiver/clock/init"));
        assert_eq!(clock.bias_s(), 1e-4);
        assert!((clock.isb_s(System::Bds) - 12.5e-9).abs() < 1e-20);
        assert_eq!(clock.isb_s(System::Gps), 0.0);
        assert_eq!(clock.isb_s(System::Dtmb), 0.0);
    }

    #[test]
    fn deterministic_drift_and_random_initial_state() {
        // With h = 0 the bias grows exactly with the drift.
        let c = ClockConfig {
            oscillator: Oscillator::Custom,
            h0_s: Some(0.0),
            h_minus2_hz: Some(0.0),
            initial_bias_s: 1e-3,
            initial_drift_s_per_s: 2e-7,
            ..Default::default()
        };
        let mut rng = TrialRng::new(4, 0).stream("c");
        let mut clock = ReceiverClock::new(&c, &mut rng);
        for _ in 0..10 {
            clock.step(0.5, &mut rng);
        }
        assert!((clock.bias_s() - (1e-3 + 5.0 * 2e-7)).abs() < 1e-18);
        clock.step(-1.0, &mut rng);
        clock.step(f64::NAN, &mut rng);
        assert!((clock.drift_s_per_s() - 2e-7).abs() < 1e-22);
        // Random initial bias: its spread across trials matches the configured σ.
        let c = ClockConfig {
            initial_bias_sigma_s: 1e-6,
            ..Default::default()
        };
        let b: Vec<f64> = (0..4000)
            .map(|i| ReceiverClock::new(&c, &mut TrialRng::new(5, i).stream("c")).bias_s())
            .collect();
        let var = b.iter().map(|x| x * x).sum::<f64>() / b.len() as f64;
        assert!((var.sqrt() / 1e-6 - 1.0).abs() < 0.05, "{}", var.sqrt());
    }

    #[test]
    fn isb_random_walk_spreads_as_sqrt_t() {
        let c = ClockConfig {
            isb_random_walk_ns_per_sqrt_s: [(System::Bds, 0.1)].into(),
            ..Default::default()
        };
        let n = 2000;
        let mut acc = 0.0;
        for i in 0..n {
            let mut rng = TrialRng::new(6, i).stream("c");
            let mut clock = ReceiverClock::new(&c, &mut rng);
            for _ in 0..100 {
                clock.step(1.0, &mut rng);
            }
            acc += clock.isb_s(System::Bds).powi(2);
        }
        // After 100 s: σ = 0.1 ns × √100 = 1 ns.
        let sigma_ns = (acc / n as f64).sqrt() * 1e9;
        assert!((sigma_ns - 1.0).abs() < 0.06, "{sigma_ns}");
    }

    /// Simulates `runs` independent TCXO clocks of `n` steps of `dt` and returns the mean
    /// overlapping Allan variance at each τ = m·dt.
    fn simulated_avar(cfg: &ClockConfig, dt: f64, n: usize, runs: u64, ms: &[usize]) -> Vec<f64> {
        let mut out = vec![0.0; ms.len()];
        for r in 0..runs {
            let mut rng = TrialRng::new(11, r).stream("gnss/receiver_clock");
            let mut clock = ReceiverClock::new(cfg, &mut rng);
            let mut x = Vec::with_capacity(n + 1);
            x.push(clock.bias_s());
            for _ in 0..n {
                clock.step(dt, &mut rng);
                x.push(clock.bias_s());
            }
            for (o, &m) in out.iter_mut().zip(ms) {
                *o += overlapping_allan_variance(&x, dt, m).unwrap() / runs as f64;
            }
        }
        out
    }

    #[test]
    fn allan_variance_matches_the_power_law() {
        // τ = 0.1 s is dominated by white FM (h₀/2τ), τ = 10 s by random-walk FM
        // ((2π²/3) h₋₂ τ); both must match the model within 10 %.
        for osc in [Oscillator::Tcxo, Oscillator::Ocxo] {
            let cfg = ClockConfig {
                oscillator: osc,
                ..Default::default()
            };
            let (h0, hm2) = cfg.h_coefficients();
            let ms = [1usize, 100];
            let got = simulated_avar(&cfg, 0.1, 1_000_000, 4, &ms);
            for (g, m) in got.iter().zip(ms) {
                let tau = m as f64 * 0.1;
                let want = allan_variance_model(h0, hm2, tau);
                eprintln!(
                    "{osc:?} τ = {tau} s: simulated σ_y² = {g:.4e}, model {want:.4e} ({:+.2} %)",
                    100.0 * (g / want - 1.0)
                );
                assert!(
                    (g / want - 1.0).abs() < 0.10,
                    "{osc:?} τ = {tau} s: simulated {g:e}, model {want:e}"
                );
            }
        }
    }

    #[test]
    fn allan_variance_of_white_phase_steps() {
        // Check the estimator on a deterministic ramp (zero) and a quadratic.
        let ramp: Vec<f64> = (0..100).map(|i| 3.0 + 0.5 * i as f64).collect();
        assert!(overlapping_allan_variance(&ramp, 1.0, 3).unwrap().abs() < 1e-20);
        // x = c t² gives second differences 2c τ², so σ² = (2cτ²)²/(2τ²) = 2c²τ².
        let quad: Vec<f64> = (0..100).map(|i| 0.25 * (i as f64).powi(2)).collect();
        let a = overlapping_allan_variance(&quad, 1.0, 4).unwrap();
        assert!((a - 2.0 * 0.0625 * 16.0).abs() < 1e-9, "{a}");
        assert!(overlapping_allan_variance(&quad, 1.0, 50).is_none());
    }
}
