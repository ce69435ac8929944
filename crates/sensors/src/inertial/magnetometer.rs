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
//! and the magnetometer reads m̃^b = S C_n^b B^n + b_hard + w, w ~ N(0, σ²) per axis, with
//! a constant hard-iron offset b_hard and a soft-iron matrix S (identity by default).
//! [`Magnetometer::measure_in_field`] reads a field that varies with position (the Earth's
//! field plus ferromagnetic anomalies, `crate::magnetic`); [`Magnetometer::measure`] reads
//! the constant field of the configuration.

use crate::core::{ConfigIssue, StreamRng};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// Soft-iron matrix S in body axes (rows), dimensionless; default the identity. Real
    /// phones show a few per cent of scale and cross-axis coupling.
    #[serde(default = "d_soft_iron")]
    pub soft_iron: [[f64; 3]; 3],
}

fn d_soft_iron() -> [[f64; 3]; 3] {
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

impl Default for MagnetometerConfig {
    fn default() -> Self {
        Self {
            total_ut: d_total(),
            inclination_deg: d_incl(),
            declination_deg: d_decl(),
            noise_ut: d_noise(),
            hard_iron_ut: [0.0; 3],
            soft_iron: d_soft_iron(),
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
        if !self
            .hard_iron_ut
            .iter()
            .all(|v| v.is_finite() && v.abs() <= 1000.0)
        {
            return Err(ConfigIssue::new(
                "hard_iron_ut",
                format!(
                    "expected finite offsets up to 1000 µT, got {:?}",
                    self.hard_iron_ut
                ),
            ));
        }
        // A soft-iron matrix far from the identity, or one that flips or collapses an
        // axis, is a typo rather than a phone; the bounds are generous.
        let s = self.soft_iron_matrix();
        let det = s.determinant();
        if !self
            .soft_iron
            .iter()
            .flatten()
            .all(|v| v.is_finite() && v.abs() <= 3.0)
            || det.is_nan()
            || det <= 0.1
        {
            return Err(ConfigIssue::new(
                "soft_iron",
                format!(
                    "expected a finite 3×3 matrix with elements within [−3, 3] and \
                     determinant above 0.1, got {:?}",
                    self.soft_iron
                ),
            ));
        }
        Ok(())
    }

    /// The soft-iron matrix S.
    pub fn soft_iron_matrix(&self) -> Matrix3<f64> {
        let r = &self.soft_iron;
        Matrix3::new(
            r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
        )
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
    soft_iron: Matrix3<f64>,
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
            soft_iron: cfg.soft_iron_matrix(),
            noise_ut: cfg.noise_ut,
            rng,
        })
    }

    /// The reading m̃^b (µT) of a body with attitude `q_nb`. Does not allocate.
    pub fn measure(&mut self, q_nb: &UnitQuaternion<f64>) -> Vector3<f64> {
        let field = self.field_enu_ut;
        self.measure_in_field(q_nb, &field)
    }

    /// The reading m̃^b (µT) of a body with attitude `q_nb` in the field `field_enu_ut`
    /// (ENU, µT) at its position, e.g. from `crate::magnetic::MagneticScene`. Draws the
    /// same three normal variates as [`Magnetometer::measure`]. Does not allocate.
    pub fn measure_in_field(
        &mut self,
        q_nb: &UnitQuaternion<f64>,
        field_enu_ut: &Vector3<f64>,
    ) -> Vector3<f64> {
        let n = Vector3::new(
            self.rng.sample::<f64, _>(StandardNormal),
            self.rng.sample::<f64, _>(StandardNormal),
            self.rng.sample::<f64, _>(StandardNormal),
        );
        self.soft_iron * (q_nb.inverse() * field_enu_ut) + self.hard_iron_ut + n * self.noise_ut
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn soft_and_hard_iron_apply_in_body_axes() {
        let cfg = MagnetometerConfig {
            noise_ut: 0.0,
            hard_iron_ut: [1.0, -2.0, 0.5],
            soft_iron: [[2.0, 0.0, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 1.0]],
            ..MagnetometerConfig::default()
        };
        let mut m = Magnetometer::new(&cfg, TrialRng::new(1, 0).stream("test/mag")).unwrap();
        let field = Vector3::new(3.0, 20.0, -40.0);
        // With the identity attitude body axes are ENU: S·B + b by hand.
        let r = m.measure_in_field(&UnitQuaternion::identity(), &field);
        let expect = Vector3::new(2.0 * 3.0 + 1.0, 20.0 + 0.1 * -40.0 - 2.0, -40.0 + 0.5);
        assert!((r - expect).norm() < 1e-12, "{r:?}");
        // The default (identity S, no offset) reads the configured field exactly.
        let plain = MagnetometerConfig {
            noise_ut: 0.0,
            ..MagnetometerConfig::default()
        };
        let mut p = Magnetometer::new(&plain, TrialRng::new(1, 0).stream("test/mag")).unwrap();
        assert_eq!(p.measure(&UnitQuaternion::identity()), plain.field_enu_ut());
    }
}
