//! A three-axis magnetometer with hard and soft iron, and a constant field given by its
//! elements (the world's PDR reads the IGRF-14 field plus the scene's anomalies instead,
//! `crate::magnetic`).
//!
//! The field in ENU for total intensity F, inclination I (positive down) and declination D
//! (positive east of true north) is
//!
//! ```text
//! B^n = (F cos I sin D, F cos I cos D, −F sin I)
//! ```
//!
//! and the magnetometer reads m̃^b = S C_n^b B^n + b_hard + w, w ~ N(0, σ²) per axis, with
//! a constant hard-iron offset b_hard and a soft-iron matrix S (identity by default). A phone
//! calibrates both in the field (the figure-of-eight of AN4246), and what the calibration
//! leaves is drawn per trial: b_hard += N(0, σ_h² I), S += [N(0, σ_s²)] elementwise.
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
    /// σ per axis of the hard-iron offset left after the phone's in-field calibration
    /// (µT), drawn once per trial and added to `hard_iron_ut`; default 0.
    #[serde(default)]
    pub hard_iron_residual_ut: f64,
    /// σ of each element of the soft-iron matrix left after the in-field calibration
    /// (dimensionless: 0.02 = 2 % scale and cross-axis), drawn once per trial and added to
    /// `soft_iron`; default 0.
    #[serde(default)]
    pub soft_iron_residual: f64,
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
            hard_iron_residual_ut: 0.0,
            soft_iron_residual: 0.0,
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
        chk(
            "hard_iron_residual_ut",
            self.hard_iron_residual_ut,
            0.0,
            100.0,
            "a residual σ in µT (non-negative)",
        )?;
        chk(
            "soft_iron_residual",
            self.soft_iron_residual,
            0.0,
            0.2,
            "a residual σ (non-negative, 0.2 = 20 %)",
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
    /// When the configuration has calibration residuals, this trial's phone is drawn first
    /// from the same stream: three N(0, σ_h²) hard-iron offsets, then nine N(0, σ_s²)
    /// soft-iron elements (row by row), added to the configured `hard_iron_ut` and
    /// `soft_iron`. Without residuals nothing is drawn, so the noise sequence is as before.
    /// A drawn soft-iron matrix whose determinant is not above 0.1 is refused (it would
    /// take a residual σ far above the 0.2 the validation allows).
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`MagnetometerConfig::validate`].
    pub fn new(cfg: &MagnetometerConfig, mut rng: StreamRng) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let mut hard_iron_ut = Vector3::from(cfg.hard_iron_ut);
        let mut soft_iron = cfg.soft_iron_matrix();
        if cfg.hard_iron_residual_ut > 0.0 {
            for k in 0..3 {
                hard_iron_ut[k] += cfg.hard_iron_residual_ut * rng.sample::<f64, _>(StandardNormal);
            }
        }
        if cfg.soft_iron_residual > 0.0 {
            for i in 0..3 {
                for j in 0..3 {
                    soft_iron[(i, j)] +=
                        cfg.soft_iron_residual * rng.sample::<f64, _>(StandardNormal);
                }
            }
            if soft_iron.determinant().is_nan() || soft_iron.determinant() <= 0.1 {
                return Err(ConfigIssue::new(
                    "soft_iron_residual",
                    format!("the drawn soft-iron matrix {soft_iron:?} is degenerate"),
                ));
            }
        }
        Ok(Self {
            field_enu_ut: cfg.field_enu_ut(),
            hard_iron_ut,
            soft_iron,
            noise_ut: cfg.noise_ut,
            rng,
        })
    }

    /// This phone's hard-iron offset (µT, body axes), configured plus drawn residual.
    pub fn hard_iron_ut(&self) -> Vector3<f64> {
        self.hard_iron_ut
    }

    /// This phone's soft-iron matrix, configured plus drawn residual.
    pub fn soft_iron(&self) -> Matrix3<f64> {
        self.soft_iron
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
    fn distorted_field_on_a_full_rotation_lies_on_the_ellipsoid() {
        // With m = S C B + b, every reading satisfies (m − b)ᵀ (S Sᵀ)⁻¹ (m − b) = |B|², the
        // ellipsoid of AN4246 §4, whatever the attitude. Rotate the phone through a grid of
        // yaw, pitch and roll (a "figure of eight" covering the sphere) and check it, with
        // residuals drawn per trial; then check the ellipsoid is not the sphere (the drawn
        // phone really is distorted) and that the drawn offset has the configured spread.
        use crate::inertial::attitude::attitude_from_euler;
        let cfg = MagnetometerConfig {
            noise_ut: 0.0,
            hard_iron_ut: [3.0, -1.0, 2.0],
            hard_iron_residual_ut: 2.0,
            soft_iron_residual: 0.03,
            ..MagnetometerConfig::default()
        };
        let field = cfg.field_enu_ut();
        let f2 = field.norm_squared();
        let mut spread = 0.0;
        let n_phones = 400;
        for seed in 0..n_phones {
            let mut m = Magnetometer::new(&cfg, TrialRng::new(seed, 0).stream("t")).unwrap();
            let (b, s) = (m.hard_iron_ut(), m.soft_iron());
            let a = (s * s.transpose()).try_inverse().unwrap();
            let mut off_sphere = 0.0f64;
            for i in 0..12 {
                for j in 0..7 {
                    for k in 0..4 {
                        let q = attitude_from_euler(
                            0.5 * f64::from(k),
                            -1.4 + 0.45 * f64::from(j),
                            f64::from(i) * std::f64::consts::TAU / 12.0,
                        );
                        let r = m.measure_in_field(&q, &field) - b;
                        let e = (r.transpose() * a * r)[(0, 0)];
                        assert!((e - f2).abs() < 1e-9 * f2, "{e} vs {f2}");
                        off_sphere = off_sphere.max((r.norm() - field.norm()).abs());
                    }
                }
            }
            assert!(off_sphere > 0.05, "seed {seed}: {off_sphere}");
            spread += (b - Vector3::new(3.0, -1.0, 2.0)).norm_squared();
        }
        // E|Δb|² = 3σ² = 12 µT²; 400 draws: the sample mean is within ±0.85 µT² (1σ).
        let mean = spread / n_phones as f64;
        assert!((mean - 12.0).abs() < 3.0, "{mean}");
    }

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
