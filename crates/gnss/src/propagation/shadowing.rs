//! Log-normal shadowing as a spatially consistent random field.
//!
//! # Model
//!
//! Shadowing S(x) in dB is a zero-mean Gaussian field over the horizontal plane with the
//! exponential correlation of Gudmundson (Electronics Letters 27(23), 1991):
//!
//! ```text
//! E[S(x) S(x + h)] = σ² exp(−|h| / d_c)
//! ```
//!
//! Typical values: σ = 4 dB, d_c = 37 m (3GPP TR 38.901 UMa LOS, the defaults here);
//! σ = 8 dB, d_c = 120 m (RMa NLOS). Along a path sampled every v Δt this is the AR(1)
//! process s_k = ρ s_{k−1} + σ √(1 − ρ²) n_k with ρ = exp(−v Δt / d_c); the field gives
//! the same statistics while being a function of place alone, so an offline survey and an
//! online walk through the same street see the same value (a recursion along the walk
//! cannot: its value depends on the path taken to reach a place).
//!
//! # Construction: random Fourier features
//!
//! By Bochner's theorem an isotropic covariance is the Fourier transform of a spectral
//! density. For exp(−r/d_c) in two dimensions the density is
//! `(d_c²/2π) (1 + k² d_c²)^{−3/2}`, a 2-D Cauchy-like law, whose radial distribution
//! function is `F(k) = 1 − (1 + k² d_c²)^{−1/2}`, inverted in closed form as
//! `k = √((1 − U)^{−2} − 1) / d_c`. With M wave vectors k_i of that law, uniform phases φ_i,
//!
//! ```text
//! S(x) = σ √(2/M) Σ_i cos(k_i · x + φ_i)
//! ```
//!
//! has exactly the variance σ² and, over realisations, exactly the covariance
//! σ² E[cos(k · h)] = σ² exp(−|h|/d_c). The sum of many independent terms is close to
//! Gaussian (central limit theorem). To make one realisation reproduce the covariance over
//! space as well (ergodicity at finite M), the radial quantiles U_i and the directions are
//! stratified: U_i = (i + ξ_i)/M and θ_i = 2π(π(i) + η_i)/M with ξ, η uniform and π a
//! random permutation. Each k_i is still marginally of the right law, so the ensemble
//! identities hold, and the per-realisation error of the correlation falls from
//! O(M^{−1/2}) to a few percent at M = 256 (see the tests and docs/validation.md).
//!
//! # Keys
//!
//! The field is a function of (place, seed, stream name): [`ShadowingField::from_key`]
//! draws the wave vectors from `TrialRng::new(seed, 0).stream(name)`, deliberately
//! independent of the trial index, so the same city has the same shadowing in every trial,
//! in the survey and in the walk. A study that wants a new city per trial passes a trial's
//! own stream to [`ShadowingField::new`].

use crate::core::{ConfigIssue, TrialRng};
use rand::seq::SliceRandom;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Shadowing field parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShadowingConfig {
    /// Standard deviation σ (dB), ≥ 0; default 4 dB.
    #[serde(default = "default_sigma")]
    pub sigma_db: f64,
    /// Decorrelation distance d_c (m), > 0; default 37 m.
    #[serde(default = "default_dc")]
    pub decorrelation_m: f64,
    /// Number of sinusoids M, 16–4096; default 256. The cost of one value is M cosines.
    #[serde(default = "default_m")]
    pub components: usize,
}

fn default_sigma() -> f64 {
    4.0
}
fn default_dc() -> f64 {
    37.0
}
fn default_m() -> usize {
    256
}

impl Default for ShadowingConfig {
    fn default() -> Self {
        Self {
            sigma_db: default_sigma(),
            decorrelation_m: default_dc(),
            components: default_m(),
        }
    }
}

impl ShadowingConfig {
    /// Checks the values; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if !(self.sigma_db.is_finite() && (0.0..=30.0).contains(&self.sigma_db)) {
            return Err(ConfigIssue::new(
                "sigma_db",
                format!(
                    "expected a shadowing σ within [0, 30] dB, got {}",
                    self.sigma_db
                ),
            ));
        }
        if !(self.decorrelation_m.is_finite()
            && self.decorrelation_m > 0.0
            && self.decorrelation_m <= 1e5)
        {
            return Err(ConfigIssue::new(
                "decorrelation_m",
                format!(
                    "expected a decorrelation distance within (0, 1e5] m, got {}",
                    self.decorrelation_m
                ),
            ));
        }
        if !(16..=4096).contains(&self.components) {
            return Err(ConfigIssue::new(
                "components",
                format!("expected 16 to 4096 components, got {}", self.components),
            ));
        }
        Ok(())
    }
}

/// One realisation of the shadowing field: an immutable, thread-safe function of place.
#[derive(Clone, Debug)]
pub struct ShadowingField {
    /// (k_east, k_north, phase) per component, rad/m and rad.
    waves: Vec<[f64; 3]>,
    amplitude_db: f64,
}

impl ShadowingField {
    /// Draws a realisation from `rng`. The configuration must be valid.
    pub fn new(cfg: &ShadowingConfig, rng: &mut impl Rng) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let m = cfg.components;
        let mut perm: Vec<usize> = (0..m).collect();
        perm.shuffle(rng);
        let waves = (0..m)
            .map(|i| {
                let u = ((i as f64 + rng.random::<f64>()) / m as f64).min(1.0 - 1e-12);
                let k = ((1.0 - u).powi(-2) - 1.0).sqrt() / cfg.decorrelation_m;
                let theta = TAU * (perm[i] as f64 + rng.random::<f64>()) / m as f64;
                let phase = TAU * rng.random::<f64>();
                [k * theta.cos(), k * theta.sin(), phase]
            })
            .collect();
        Ok(Self {
            waves,
            amplitude_db: cfg.sigma_db * (2.0 / m as f64).sqrt(),
        })
    }

    /// The realisation keyed by `(seed, name)` alone (see the module documentation).
    pub fn from_key(cfg: &ShadowingConfig, seed: u64, name: &str) -> Result<Self, ConfigIssue> {
        Self::new(cfg, &mut TrialRng::new(seed, 0).stream(name))
    }

    /// The shadowing (dB) at horizontal ENU position `(east_m, north_m)`.
    pub fn value_db(&self, east_m: f64, north_m: f64) -> f64 {
        self.amplitude_db
            * self
                .waves
                .iter()
                .map(|w| (w[0] * east_m + w[1] * north_m + w[2]).cos())
                .sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_key_same_value_and_bad_config() {
        let cfg = ShadowingConfig::default();
        let a = ShadowingField::from_key(&cfg, 9, "propagation/shadowing/D01").unwrap();
        let b = ShadowingField::from_key(&cfg, 9, "propagation/shadowing/D01").unwrap();
        let c = ShadowingField::from_key(&cfg, 9, "propagation/shadowing/D02").unwrap();
        assert_eq!(a.value_db(12.5, -40.0), b.value_db(12.5, -40.0));
        assert_ne!(a.value_db(12.5, -40.0), c.value_db(12.5, -40.0));
        let bad = ShadowingConfig {
            decorrelation_m: 0.0,
            ..cfg
        };
        assert_eq!(
            ShadowingField::from_key(&bad, 1, "x").unwrap_err().key,
            "decorrelation_m"
        );
    }
}
