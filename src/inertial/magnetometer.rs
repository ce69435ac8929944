//! A constant Earth magnetic field and a three-axis magnetometer, enough for the AHRS of
//! the PDR (a later issue brings a proper field model, e.g. the IGRF or WMM).
//!
//! The field in ENU for total intensity F, inclination I (positive down) and declination D
//! (positive east of true north) is
//!
//! ```text
//! B^n = (F cos I sin D, F cos I cos D, −F sin I)
//! ```
//!
//! and the magnetometer reads m̃^b = C_n^b B^n + b_hard + w, w ~ N(0, σ²) per axis
//! (hard-iron offset b_hard constant; soft iron is not modelled).

use crate::core::StreamRng;
use crate::motion::ConfigIssue;
use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

fn d_total() -> f64 {
    54.0
}
fn d_incl() -> f64 {
    59.0
}
fn d_decl() -> f64 {
    -7.0
}
fn d_noise() -> f64 {
    0.5
}

/// The local field and the sensor (defaults: Beijing-like field, 0.5 µT noise).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MagnetometerConfig {
    /// Total intensity F (µT); default 54.
    #[serde(default = "d_total")]
    pub total_ut: f64,
    /// Inclination I, positive down (°); default 59.
    #[serde(default = "d_incl")]
    pub inclination_deg: f64,
    /// Declination D, positive east (°); default −7.
    #[serde(default = "d_decl")]
    pub declination_deg: f64,
    /// White noise σ per axis (µT); default 0.5.
    #[serde(default = "d_noise")]
    pub noise_ut: f64,
    /// Hard-iron offset in body axes (µT); default 0.
    #[serde(default)]
    pub hard_iron_ut: [f64; 3],
}

impl Default for MagnetometerConfig {
    fn default() -> Self {
        Self {
            total_ut: d_total(),
            inclination_deg: d_incl(),
            declination_deg: d_decl(),
            noise_ut: d_noise(),
            hard_iron_ut: [0.0; 3],
        }
    }
}

impl MagnetometerConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let chk = |key: &str, v: f64, lo: f64, hi: f64, what: &str| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(ConfigIssue::new(
                    key,
                    format!("expected {what} within [{lo}, {hi}], got {v}"),
                ))
            }
        };
        chk(
            "total_ut",
            self.total_ut,
            1.0,
            1000.0,
            "a field intensity in µT",
        )?;
        chk(
            "inclination_deg",
            self.inclination_deg,
            -90.0,
            90.0,
            "an inclination in degrees",
        )?;
        chk(
            "declination_deg",
            self.declination_deg,
            -180.0,
            180.0,
            "a declination in degrees",
        )?;
        chk(
            "noise_ut",
            self.noise_ut,
            0.0,
            100.0,
            "a noise σ in µT (non-negative)",
        )?;
        if self
            .hard_iron_ut
            .iter()
            .all(|v| v.is_finite() && v.abs() <= 1000.0)
        {
            Ok(())
        } else {
            Err(ConfigIssue::new(
                "hard_iron_ut",
                format!(
                    "expected finite offsets up to 1000 µT, got {:?}",
                    self.hard_iron_ut
                ),
            ))
        }
    }

    /// The field B^n in ENU (µT).
    pub fn field_enu_ut(&self) -> Vector3<f64> {
        let (si, ci) = self.inclination_deg.to_radians().sin_cos();
        let (sd, cd) = self.declination_deg.to_radians().sin_cos();
        let f = self.total_ut;
        Vector3::new(f * ci * sd, f * ci * cd, -f * si)
    }
}

/// A noisy magnetometer in a constant field.
#[derive(Clone, Debug)]
pub struct Magnetometer {
    field_enu_ut: Vector3<f64>,
    hard_iron_ut: Vector3<f64>,
    noise_ut: f64,
    rng: StreamRng,
}

impl Magnetometer {
    /// A magnetometer drawing its noise from `rng` (e.g. the stream `"inertial/mag"`).
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`MagnetometerConfig::validate`].
    pub fn new(cfg: &MagnetometerConfig, rng: StreamRng) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        Ok(Self {
            field_enu_ut: cfg.field_enu_ut(),
            hard_iron_ut: Vector3::from(cfg.hard_iron_ut),
            noise_ut: cfg.noise_ut,
            rng,
        })
    }

    /// The reading m̃^b (µT) of a body with attitude `q_nb`. Does not allocate.
    pub fn measure(&mut self, q_nb: &UnitQuaternion<f64>) -> Vector3<f64> {
        let n = Vector3::new(
            self.rng.sample::<f64, _>(StandardNormal),
            self.rng.sample::<f64, _>(StandardNormal),
            self.rng.sample::<f64, _>(StandardNormal),
        );
        q_nb.inverse() * self.field_enu_ut + self.hard_iron_ut + n * self.noise_ut
    }
}
