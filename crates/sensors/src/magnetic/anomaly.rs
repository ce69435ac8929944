//! Ferromagnetic structures (lift shafts, steel doors, radiators, pillars, buried pipes) as
//! point magnetic dipoles, the total field they make with the Earth's, and the magnetometer
//! sampled along a walk through them.
//!
//! A dipole of moment m (A·m²) at p makes at x, with r = x − p, r = |r|, r̂ = r/r,
//!
//! ```text
//! B(x) = μ0/4π · (3 (m·r̂) r̂ − m) / r³,     μ0/4π = 100 nT·m³/(A·m²)
//! ```
//!
//! so on the dipole's axis B = μ0/4π · 2m/r³ and on its equator B = −μ0/4π · m/r³. The
//! formula is singular at the dipole; a real structure has a size, so r is held at no less
//! than the configured `min_distance_m` (the direction r̂ is kept). The field is a function
//! of position alone, so a survey walk and a later walk see the same anomaly at the same
//! place (spatial consistency). The total field is B_earth + Σ B_anomaly (seed 002 §2.1:
//! landmarks are "long-term stable distortion features").

use super::{EarthField, MagneticError, MU0_OVER_4PI_NT_M3_PER_AM2};
use crate::core::ConfigIssue;
use crate::inertial::attitude::PlatformTruth;
use crate::inertial::magnetometer::Magnetometer;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// The largest moment accepted (A·m²). A car is ~10²–10³ A·m², a lift car or a steel
/// tank a few 10³; 10⁶ is far beyond anything a pedestrian walks past.
pub const MAX_MOMENT_AM2: f64 = 1.0e6;
/// The largest coordinate accepted (m): the world's ENU frame is local.
pub const MAX_COORDINATE_M: f64 = 1.0e6;

fn d_min_distance() -> f64 {
    0.3
}

/// One anomaly as a world file would write it (e.g. a `[[scene.magnetic_anomaly]]` table).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MagneticAnomalyConfig {
    /// A name for reports (e.g. `"lift"`); optional.
    #[serde(default)]
    pub name: String,
    /// The dipole's position in the world's ENU frame (m), `[e, n, u]`.
    pub position_enu_m: [f64; 3],
    /// The dipole moment in ENU axes (A·m²); must not be zero.
    pub moment_am2: [f64; 3],
    /// The distance under which the field stops growing (m); default 0.3.
    #[serde(default = "d_min_distance")]
    pub min_distance_m: f64,
}

impl MagneticAnomalyConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field: a non-finite or far-away position, a
    /// non-finite, zero or enormous moment, a minimum distance outside (0, 100] m.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if !self
            .position_enu_m
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_COORDINATE_M)
        {
            return Err(ConfigIssue::new(
                "position_enu_m",
                format!(
                    "expected finite ENU coordinates within ±{MAX_COORDINATE_M} m, got {:?}",
                    self.position_enu_m
                ),
            ));
        }
        let m = Vector3::from(self.moment_am2);
        if !self.moment_am2.iter().all(|v| v.is_finite()) {
            return Err(ConfigIssue::new(
                "moment_am2",
                format!("expected a finite moment vector, got {:?}", self.moment_am2),
            ));
        }
        let norm = m.norm();
        if !(norm > 0.0 && norm <= MAX_MOMENT_AM2) {
            return Err(ConfigIssue::new(
                "moment_am2",
                format!(
                    "expected a non-zero moment of at most {MAX_MOMENT_AM2} A·m², got |m| = \
                     {norm} A·m²"
                ),
            ));
        }
        if !(self.min_distance_m.is_finite()
            && self.min_distance_m > 0.0
            && self.min_distance_m <= 100.0)
        {
            return Err(ConfigIssue::new(
                "min_distance_m",
                format!(
                    "expected a distance within (0, 100] m, got {}",
                    self.min_distance_m
                ),
            ));
        }
        Ok(())
    }
}

/// A point dipole, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct DipoleAnomaly {
    position_enu_m: Vector3<f64>,
    moment_am2: Vector3<f64>,
    min_distance_m: f64,
}

impl DipoleAnomaly {
    /// A dipole from its configuration.
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`MagneticAnomalyConfig::validate`].
    pub fn new(cfg: &MagneticAnomalyConfig) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        Ok(Self {
            position_enu_m: Vector3::from(cfg.position_enu_m),
            moment_am2: Vector3::from(cfg.moment_am2),
            min_distance_m: cfg.min_distance_m,
        })
    }

    /// The dipole's position (ENU m).
    pub fn position_enu_m(&self) -> Vector3<f64> {
        self.position_enu_m
    }

    /// The anomaly field at `x_enu_m` (ENU nT). Does not allocate.
    pub fn b_enu_nt(&self, x_enu_m: &Vector3<f64>) -> Vector3<f64> {
        let r = x_enu_m - self.position_enu_m;
        let d = r.norm();
        // At the dipole itself the direction is undefined; take the moment's axis, where
        // the (clamped) field is largest, so the value stays finite and deterministic.
        let r_hat = if d > 1e-12 {
            r / d
        } else {
            self.moment_am2.normalize()
        };
        let d = d.max(self.min_distance_m);
        let m = &self.moment_am2;
        (3.0 * m.dot(&r_hat) * r_hat - m) * (MU0_OVER_4PI_NT_M3_PER_AM2 / (d * d * d))
    }
}

/// The Earth's field plus every anomaly: the total field anywhere in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct MagneticScene {
    earth: EarthField,
    anomalies: Vec<DipoleAnomaly>,
}

impl crate::inertial::source::AmbientField for MagneticScene {
    fn earth_enu_ut(&self) -> Vector3<f64> {
        self.earth.b_enu_ut()
    }
    fn b_enu_ut(&self, x_enu_m: &Vector3<f64>) -> Vector3<f64> {
        MagneticScene::b_enu_ut(self, x_enu_m)
    }
}

impl MagneticScene {
    /// A scene from the Earth's field and the anomalies' configurations.
    ///
    /// # Errors
    /// [`MagneticError::Config`] with the key `magnetic_anomaly[i].<field>` of the first
    /// bad anomaly.
    pub fn new(
        earth: EarthField,
        anomalies: &[MagneticAnomalyConfig],
    ) -> Result<Self, MagneticError> {
        let anomalies = anomalies
            .iter()
            .enumerate()
            .map(|(i, c)| {
                DipoleAnomaly::new(c).map_err(|e| {
                    ConfigIssue::new(format!("magnetic_anomaly[{i}].{}", e.key), e.message)
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { earth, anomalies })
    }

    /// The Earth's field.
    pub fn earth(&self) -> &EarthField {
        &self.earth
    }

    /// The anomalies.
    pub fn anomalies(&self) -> &[DipoleAnomaly] {
        &self.anomalies
    }

    /// The total field at `x_enu_m` (ENU nT). Does not allocate.
    pub fn b_enu_nt(&self, x_enu_m: &Vector3<f64>) -> Vector3<f64> {
        self.anomalies
            .iter()
            .fold(self.earth.b_enu_nt(), |b, a| b + a.b_enu_nt(x_enu_m))
    }

    /// The total field at `x_enu_m` (ENU µT).
    pub fn b_enu_ut(&self, x_enu_m: &Vector3<f64>) -> Vector3<f64> {
        self.b_enu_nt(x_enu_m) * 1e-3
    }

    /// A magnetometer carried along `truth`, sampled at `rate_hz` from t = 0 to the end:
    /// the true position and attitude at each sample, the body-frame reading of the
    /// magnetometer (noise, hard and soft iron as its configuration says) in the total
    /// field there, and the reading's magnitude ‖m̃^b‖ (seed 002 §2.1 builds its database
    /// from this modulus because it does not depend on how the phone is held).
    ///
    /// # Errors
    /// [`MagneticError::Input`] for a rate outside (0, 1000] Hz or a walk of more than
    /// ten million samples.
    pub fn sample_walk(
        &self,
        truth: &PlatformTruth,
        magnetometer: &mut Magnetometer,
        rate_hz: f64,
    ) -> Result<MagneticWalk, MagneticError> {
        if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1000.0) {
            return Err(MagneticError::Input(format!(
                "expected a sampling rate within (0, 1000] Hz, got {rate_hz}"
            )));
        }
        let n_f = (truth.duration_s() * rate_hz).floor() + 1.0;
        if !(n_f.is_finite() && n_f <= 1.0e7) {
            return Err(MagneticError::Input(format!(
                "a walk of {n_f} samples is more than ten million"
            )));
        }
        let n = n_f as usize;
        let mut walk = MagneticWalk {
            rate_hz,
            t_s: Vec::with_capacity(n),
            pos_enu_m: Vec::with_capacity(n),
            b_body_ut: Vec::with_capacity(n),
            magnitude_ut: Vec::with_capacity(n),
        };
        for k in 0..n {
            let t_s = k as f64 / rate_hz;
            let s = truth.sample(t_s);
            let b_ut = self.b_enu_ut(&s.pos_enu_m);
            let m = magnetometer.measure_in_field(&s.q_nb, &b_ut);
            walk.t_s.push(t_s);
            walk.pos_enu_m.push(s.pos_enu_m);
            walk.b_body_ut.push(m);
            walk.magnitude_ut.push(m.norm());
        }
        Ok(walk)
    }
}

/// What a magnetometer recorded along a walk, with the truth beside it.
#[derive(Clone, Debug, PartialEq)]
pub struct MagneticWalk {
    /// The sampling rate (Hz).
    pub rate_hz: f64,
    /// Sample times (s since the walk's start).
    pub t_s: Vec<f64>,
    /// True positions (ENU m) — for labelling and scoring, not for the detector.
    pub pos_enu_m: Vec<Vector3<f64>>,
    /// Body-frame readings (µT).
    pub b_body_ut: Vec<Vector3<f64>>,
    /// Reading magnitudes (µT): the detector's input.
    pub magnitude_ut: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dipole(m: [f64; 3]) -> DipoleAnomaly {
        DipoleAnomaly::new(&MagneticAnomalyConfig {
            name: String::new(),
            position_enu_m: [1.0, 2.0, 3.0],
            moment_am2: m,
            min_distance_m: 0.1,
        })
        .unwrap()
    }

    #[test]
    fn axial_and_equatorial_fields_match_the_closed_forms() {
        let m_am2 = 150.0;
        let d = dipole([0.0, 0.0, m_am2]);
        let r_m = 2.0;
        let axial = d.b_enu_nt(&Vector3::new(1.0, 2.0, 3.0 + r_m));
        let expect_axial = 100.0 * 2.0 * m_am2 / r_m.powi(3);
        assert!((axial.z - expect_axial).abs() < 1e-9 * expect_axial);
        assert!(axial.x.abs() < 1e-9 && axial.y.abs() < 1e-9);
        // Below the dipole the axial field points the same way (along m).
        let below = d.b_enu_nt(&Vector3::new(1.0, 2.0, 3.0 - r_m));
        assert!((below.z - expect_axial).abs() < 1e-9 * expect_axial);
        let eq = d.b_enu_nt(&Vector3::new(1.0 + r_m, 2.0, 3.0));
        assert!((eq.z + 0.5 * expect_axial).abs() < 1e-9 * expect_axial);
        assert!(eq.x.abs() < 1e-9 && eq.y.abs() < 1e-9);
    }

    #[test]
    fn the_field_is_clamped_inside_the_minimum_distance() {
        let d = dipole([10.0, 0.0, 0.0]);
        let at = d.b_enu_nt(&Vector3::new(1.0, 2.0, 3.0));
        let near = d.b_enu_nt(&Vector3::new(1.05, 2.0, 3.0));
        assert!(at.iter().all(|v| v.is_finite()));
        assert!((at - near).norm() < 1e-9 * near.norm());
    }
}
