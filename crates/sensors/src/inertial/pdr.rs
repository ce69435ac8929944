//! Pedestrian dead reckoning as in seed 002 §4.2 (Liu et al., DTMB + magnetic landmarks):
//! steps detected on the accelerometer, Weinberg step length, heading from an AHRS, and
//! step events a fusion filter consumes (seed 002's EKF state is [x, y, θ̇, θ, v]; its PDR
//! observations θ_pdr and v_pdr are `π/2 − heading_rad` and `length_m / interval_s`).
//!
//! # Step detection
//!
//! The specific-force magnitude |f̃| is low-passed by a second-order Butterworth filter
//! (`lowpass_hz`, bilinear transform) and referred to a slow running mean (gravity,
//! τ = 5 s) so scale-factor errors do not move the thresholds: a(t) = LP|f̃| − ḡ. A step
//! is a peak of a(t) above `peak_threshold_mps2`, closed when a(t) falls back below
//! `rearm_threshold_mps2` (hysteresis), at least `min_step_interval_s` after the previous
//! step; a peak too close to the previous step is dropped. The step's time is the peak's.
//!
//! # Step length (Weinberg 2002, Analog Devices AN-602)
//!
//! L = K (a_max − a_min)^{1/4}, with a_max the step's peak and a_min the lowest a(t)
//! since the previous step; K ≈ 0.364 (facts §4) is a per-user calibration.
//!
//! # Heading: a complementary-filter AHRS (Mahony, Hamel & Pflimlin 2008)
//!
//! The attitude quaternion integrates the gyro with the Earth rate removed and two
//! corrections: the accelerometer pulls the estimated "up" towards the measured specific
//! force, e_a = â × û (â the normalised specific force, û = Ĉ_n^b (0, 0, 1)), and the
//! magnetometer corrects heading only: the measured field mapped into ENU makes an angle
//! δ with the known field azimuth (the declination), and a rotation −k_m δ about up removes
//! it, so magnetic errors never tilt the estimate. A small integral term tracks the gyro
//! bias: ω = ω̃ − b̂ − Ĉ_n^b ω_ie + k_a e_a + k_m e_m, ḃ = −k_i (e_a + e_m).
//! The heading of a step is the circular mean of the AHRS heading over the step, which
//! averages the phone's sway.

use super::{heading_of_attitude, LocalEarth};
use crate::core::ConfigIssue;
use crate::measurement::ImuSample;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

fn d_lp() -> f64 {
    5.0
}
fn d_peak() -> f64 {
    1.5
}
fn d_rearm() -> f64 {
    0.0
}
fn d_min_int() -> f64 {
    0.3
}
fn d_k() -> f64 {
    0.364
}
fn d_ka() -> f64 {
    0.3
}
fn d_km() -> f64 {
    0.3
}
fn d_ki() -> f64 {
    0.002
}

/// Step detection, step length and AHRS settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PdrConfig {
    /// Low-pass cut-off on |f| (Hz); default 5.
    #[serde(default = "d_lp")]
    pub lowpass_hz: f64,
    /// Peak threshold above gravity (m/s²); default 1.5.
    #[serde(default = "d_peak")]
    pub peak_threshold_mps2: f64,
    /// Re-arm level above gravity (m/s²), below the peak threshold; default 0.
    #[serde(default = "d_rearm")]
    pub rearm_threshold_mps2: f64,
    /// Shortest time between steps (s); default 0.3.
    #[serde(default = "d_min_int")]
    pub min_step_interval_s: f64,
    /// Weinberg constant K (m / (m/s²)^¼); default 0.364.
    #[serde(default = "d_k")]
    pub weinberg_k: f64,
    /// Relative σ of the walker's calibration error of K: each trial's phone uses
    /// K (1 + ε), ε ~ N(0, σ²) drawn once (stream `imu/pdr/step`); default 0 (K exact).
    #[serde(default)]
    pub weinberg_k_error: f64,
    /// AHRS accelerometer gain k_a (rad/s per unit error); default 0.3.
    #[serde(default = "d_ka")]
    pub accel_gain: f64,
    /// AHRS magnetometer gain k_m (1/s); default 0.3; 0 = gyro-only heading.
    #[serde(default = "d_km")]
    pub mag_gain: f64,
    /// AHRS gyro-bias integral gain k_i (1/s²); default 0.002.
    #[serde(default = "d_ki")]
    pub bias_gain: f64,
}

impl Default for PdrConfig {
    fn default() -> Self {
        Self {
            lowpass_hz: d_lp(),
            peak_threshold_mps2: d_peak(),
            rearm_threshold_mps2: d_rearm(),
            min_step_interval_s: d_min_int(),
            weinberg_k: d_k(),
            weinberg_k_error: 0.0,
            accel_gain: d_ka(),
            mag_gain: d_km(),
            bias_gain: d_ki(),
        }
    }
}

impl PdrConfig {
    /// Checks every value, given the IMU rate (the low-pass must sit below Nyquist).
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field.
    pub fn validate(&self, imu_rate_hz: f64) -> Result<(), ConfigIssue> {
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
            "lowpass_hz",
            self.lowpass_hz,
            0.5,
            0.45 * imu_rate_hz,
            "a cut-off in Hz below 0.45 × the IMU rate",
        )?;
        chk(
            "peak_threshold_mps2",
            self.peak_threshold_mps2,
            0.05,
            50.0,
            "a threshold in m/s²",
        )?;
        chk(
            "rearm_threshold_mps2",
            self.rearm_threshold_mps2,
            -50.0,
            self.peak_threshold_mps2,
            "a level in m/s² not above peak_threshold_mps2",
        )?;
        chk(
            "min_step_interval_s",
            self.min_step_interval_s,
            0.05,
            5.0,
            "an interval in s",
        )?;
        chk(
            "weinberg_k",
            self.weinberg_k,
            0.01,
            2.0,
            "a Weinberg constant",
        )?;
        chk(
            "weinberg_k_error",
            self.weinberg_k_error,
            0.0,
            0.3,
            "a relative σ (non-negative, 0.3 = 30 %)",
        )?;
        chk(
            "accel_gain",
            self.accel_gain,
            0.0,
            100.0,
            "a gain (non-negative)",
        )?;
        chk(
            "mag_gain",
            self.mag_gain,
            0.0,
            100.0,
            "a gain (non-negative)",
        )?;
        chk(
            "bias_gain",
            self.bias_gain,
            0.0,
            10.0,
            "a gain (non-negative)",
        )
    }
}

/// One detected step, what a fusion engine consumes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepEvent {
    /// Time of the step (the acceleration peak), s since the trial start.
    pub t_s: f64,
    /// Weinberg step length (m).
    pub length_m: f64,
    /// Walking heading over the step, from north clockwise, in [0, 2π) (rad).
    pub heading_rad: f64,
    /// Time since the previous step (s); `length_m / interval_s` is seed 002's v_pdr.
    pub interval_s: f64,
}

/// A second-order Butterworth low-pass (bilinear transform, direct form II transposed).
#[derive(Clone, Copy, Debug)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
    z: [f64; 2],
}

impl Biquad {
    fn lowpass(cut_hz: f64, rate_hz: f64) -> Self {
        let k = (std::f64::consts::PI * cut_hz / rate_hz).tan();
        let q = std::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Self {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
            z: [0.0; 2],
        }
    }
    fn prime(&mut self, x: f64) {
        // Steady state for a constant input x (unit DC gain).
        self.z[1] = self.b[2] * x - self.a[1] * x;
        self.z[0] = self.b[1] * x - self.a[0] * x + self.z[1];
    }
    fn run(&mut self, x: f64) -> f64 {
        let y = self.b[0] * x + self.z[0];
        self.z[0] = self.b[1] * x - self.a[0] * y + self.z[1];
        self.z[1] = self.b[2] * x - self.a[1] * y;
        y
    }
}

/// The step detector and Weinberg length estimator.
#[derive(Clone, Debug)]
pub struct StepDetector {
    cfg: PdrConfig,
    lp: Biquad,
    g_mean: f64,
    gravity_alpha: f64,
    started: bool,
    in_peak: bool,
    peak_val: f64,
    peak_t: f64,
    valley: f64,
    last_step_t: Option<f64>,
    /// The valley as it was when the current peak began (the minimum since the last step).
    valley_at_peak: f64,
}

impl StepDetector {
    /// A detector for samples at `rate_hz`.
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`PdrConfig::validate`].
    pub fn new(cfg: &PdrConfig, rate_hz: f64) -> Result<Self, ConfigIssue> {
        cfg.validate(rate_hz)?;
        Ok(Self {
            cfg: cfg.clone(),
            lp: Biquad::lowpass(cfg.lowpass_hz, rate_hz),
            g_mean: 0.0,
            gravity_alpha: 1.0 - (-1.0 / (5.0 * rate_hz)).exp(),
            started: false,
            in_peak: false,
            peak_val: f64::NEG_INFINITY,
            peak_t: 0.0,
            valley: f64::INFINITY,
            last_step_t: None,
            valley_at_peak: f64::INFINITY,
        })
    }

    /// Feeds one specific-force sample; returns (time, length, interval) of a step that has
    /// just been confirmed.
    pub fn update(&mut self, t_s: f64, accel_mps2: &Vector3<f64>) -> Option<(f64, f64, f64)> {
        let mag = accel_mps2.norm();
        if !self.started {
            self.started = true;
            self.lp.prime(mag);
            self.g_mean = mag;
        }
        let y = self.lp.run(mag);
        self.g_mean += self.gravity_alpha * (y - self.g_mean);
        let a = y - self.g_mean;
        if self.in_peak {
            if a > self.peak_val {
                self.peak_val = a;
                self.peak_t = t_s;
            }
            if a < self.cfg.rearm_threshold_mps2 {
                self.in_peak = false;
                let ok = self
                    .last_step_t
                    .is_none_or(|t0| self.peak_t - t0 >= self.cfg.min_step_interval_s);
                if ok {
                    let interval = self.last_step_t.map_or(f64::NAN, |t0| self.peak_t - t0);
                    let a_min = if self.valley_at_peak.is_finite() {
                        self.valley_at_peak
                    } else {
                        -self.peak_val
                    };
                    let len = self.cfg.weinberg_k * (self.peak_val - a_min).max(0.0).powf(0.25);
                    self.last_step_t = Some(self.peak_t);
                    self.valley = a;
                    return Some((self.peak_t, len, interval));
                }
                // A peak too soon after the previous step: ignore it, keep the valley.
            }
        } else {
            self.valley = self.valley.min(a);
            if a > self.cfg.peak_threshold_mps2 {
                self.in_peak = true;
                self.peak_val = a;
                self.peak_t = t_s;
                self.valley_at_peak = self.valley;
            }
        }
        None
    }
}

/// The complementary-filter AHRS.
#[derive(Clone, Debug)]
pub struct Ahrs {
    q_nb: UnitQuaternion<f64>,
    gyro_bias_rps: Vector3<f64>,
    earth: LocalEarth,
    field_azimuth_rad: f64,
    accel_gain: f64,
    mag_gain: f64,
    bias_gain: f64,
    last_t: Option<f64>,
}

impl Ahrs {
    /// Aligns from one specific-force and one magnetometer reading (TRIAD: "up" from the
    /// accelerometer, north from the horizontal field turned by the declination).
    /// `field_enu` is the known field direction (only its azimuth is used).
    pub fn align(
        accel_mps2: &Vector3<f64>,
        mag_b: &Vector3<f64>,
        field_enu: &Vector3<f64>,
        earth: LocalEarth,
        cfg: &PdrConfig,
    ) -> Self {
        let up = accel_mps2.normalize();
        let north_m = (mag_b - up * mag_b.dot(&up)).normalize();
        let east_m = north_m.cross(&up);
        // The rows of C_b^n are the navigation axes written in body coordinates.
        let c_nb = Matrix3::from_rows(&[east_m.transpose(), north_m.transpose(), up.transpose()]);
        let q_mag = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(c_nb));
        let field_azimuth_rad = field_enu.x.atan2(field_enu.y);
        // Heading true = heading magnetic + declination: a rotation by −D about up.
        let q_nb = UnitQuaternion::from_scaled_axis(Vector3::z() * -field_azimuth_rad) * q_mag;
        Self {
            q_nb,
            gyro_bias_rps: Vector3::zeros(),
            earth,
            field_azimuth_rad,
            accel_gain: cfg.accel_gain,
            mag_gain: cfg.mag_gain,
            bias_gain: cfg.bias_gain,
            last_t: None,
        }
    }

    /// The attitude estimate.
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.q_nb
    }

    /// The heading of the body forward axis (rad, from north clockwise).
    pub fn heading_rad(&self) -> f64 {
        heading_of_attitude(&self.q_nb)
    }

    /// One update with a gyro/accelerometer sample and an optional magnetometer reading.
    pub fn update(&mut self, s: &ImuSample, mag_b: Option<&Vector3<f64>>) {
        let dt = match self.last_t {
            Some(t0) => s.t_s - t0,
            None => 0.0,
        };
        self.last_t = Some(s.t_s);
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        let q_bn = self.q_nb.inverse();
        let up_pred = q_bn * Vector3::z();
        let mut e = Vector3::zeros();
        let an = s.accel_mps2.norm();
        if an > 1e-6 {
            e += (s.accel_mps2 / an).cross(&up_pred) * self.accel_gain;
        }
        if let Some(m) = mag_b {
            let m_n = self.q_nb * m;
            if m_n.x.hypot(m_n.y) > 1e-9 {
                let delta = (m_n.x.atan2(m_n.y) - self.field_azimuth_rad + std::f64::consts::PI)
                    .rem_euclid(TAU)
                    - std::f64::consts::PI;
                e += q_bn * (Vector3::z() * (self.mag_gain * delta));
            }
        }
        self.gyro_bias_rps -= e * (self.bias_gain * dt);
        let w = s.gyro_rps - self.gyro_bias_rps - q_bn * self.earth.omega_ie_enu_rps + e;
        self.q_nb *= UnitQuaternion::from_scaled_axis(w * dt);
        self.q_nb.renormalize_fast();
    }
}

/// PDR: detector + AHRS + position.
#[derive(Clone, Debug)]
pub struct Pdr {
    detector: StepDetector,
    ahrs: Ahrs,
    pos_en_m: Vector2<f64>,
    heading_sum: Vector2<f64>,
}

impl Pdr {
    /// A PDR starting at `start_en_m` with an aligned AHRS.
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`PdrConfig::validate`].
    pub fn new(
        cfg: &PdrConfig,
        rate_hz: f64,
        ahrs: Ahrs,
        start_en_m: Vector2<f64>,
    ) -> Result<Self, ConfigIssue> {
        Ok(Self {
            detector: StepDetector::new(cfg, rate_hz)?,
            ahrs,
            pos_en_m: start_en_m,
            heading_sum: Vector2::zeros(),
        })
    }

    /// The dead-reckoned position (east, north m).
    pub fn position_en_m(&self) -> Vector2<f64> {
        self.pos_en_m
    }

    /// The AHRS.
    pub fn ahrs(&self) -> &Ahrs {
        &self.ahrs
    }

    /// Feeds one IMU sample (and a magnetometer reading when there is one); returns the step
    /// confirmed at this sample, if any, after moving the position by it. Does not allocate.
    pub fn update(&mut self, s: &ImuSample, mag_b: Option<&Vector3<f64>>) -> Option<StepEvent> {
        self.ahrs.update(s, mag_b);
        let h = self.ahrs.heading_rad();
        self.heading_sum += Vector2::new(h.sin(), h.cos());
        let (t, len, interval) = self.detector.update(s.t_s, &s.accel_mps2)?;
        let heading = self.heading_sum.x.atan2(self.heading_sum.y).rem_euclid(TAU);
        self.heading_sum = Vector2::zeros();
        self.pos_en_m += Vector2::new(heading.sin(), heading.cos()) * len;
        Some(StepEvent {
            t_s: t,
            length_m: len,
            heading_rad: heading,
            interval_s: interval,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn butterworth_has_unit_dc_gain_and_attenuates() {
        let mut f = Biquad::lowpass(5.0, 100.0);
        let mut y = 0.0;
        for _ in 0..500 {
            y = f.run(1.0);
        }
        assert!((y - 1.0).abs() < 1e-9);
        // Gain at the cut-off is 1/√2.
        let mut f = Biquad::lowpass(5.0, 100.0);
        let mut peak = 0.0f64;
        for k in 0..2000 {
            let v = f.run((TAU * 5.0 * k as f64 / 100.0).sin());
            if k > 1000 {
                peak = peak.max(v.abs());
            }
        }
        assert!(
            (peak - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01,
            "{peak}"
        );
    }

    /// A straight walk north of `len_m` at 1.2 m/s (seed 002's pace), handheld phone.
    fn straight_walk(seed: u64, len_m: f64) -> crate::inertial::attitude::PlatformTruth {
        use crate::core::TrialRng;
        use crate::inertial::attitude::{Platform, PlatformConfig, PlatformTruth};
        use crate::motion::TrajectoryConfig;
        let traj = TrajectoryConfig::Waypoints {
            points_enu_m: vec![vec![0.0, 0.0], vec![0.0, len_m]],
            speed_mps: 1.2,
            accel_mps2: Some(0.5),
            lateral_accel_mps2: None,
            dwell_s: None,
            leg_speeds_mps: None,
            stops: None,
            laps: None,
            height_m: None,
        }
        .build(&mut TrialRng::new(seed, 0).stream("motion/trajectory"))
        .unwrap();
        let cfg = PlatformConfig {
            platform: Platform::Handheld,
            ..Default::default()
        };
        PlatformTruth::new(traj, &cfg, &mut TrialRng::new(seed, 0).stream("gait")).unwrap()
    }

    /// Runs the detector with K = 1 on the ideal IMU of `walk`: each step's
    /// (a_max − a_min)^¼, in order.
    fn fourth_roots(walk: &crate::inertial::attitude::PlatformTruth) -> Vec<f64> {
        use crate::inertial::attitude::ideal_imu;
        let cfg = PdrConfig {
            weinberg_k: 1.0,
            ..PdrConfig::default()
        };
        let rate = 100.0;
        let mut det = StepDetector::new(&cfg, rate).unwrap();
        let earth = LocalEarth::new(0.53, 10.0);
        let n = (walk.duration_s() * rate) as usize;
        (0..=n)
            .filter_map(|k| {
                let t = k as f64 / rate;
                let (_, f) = ideal_imu(&walk.sample(t), &earth);
                det.update(t, &f).map(|(_, len, _)| len)
            })
            .collect()
    }

    #[test]
    fn weinberg_length_with_zero_calibration_error_matches_the_gait() {
        // The walker calibrates K once, as Weinberg (AN-602) prescribes: walk a known
        // distance, K = distance / Σ (a_max − a_min)^¼. With that K (zero calibration
        // error) the Weinberg steps of a second walk (other cadence and intensity draws)
        // must add up to its true length, and their mean must be the truth gait's mean
        // step (the walked distance over the true step count).
        let cal = straight_walk(1, 60.0);
        let k_cal = 60.0 / fourth_roots(&cal).iter().sum::<f64>();
        let walk = straight_walk(2, 90.0);
        let roots = fourth_roots(&walk);
        let true_steps = walk.true_step_times_s().len();
        let weinberg_total: f64 = roots.iter().map(|r| k_cal * r).sum();
        let true_mean = 90.0 / true_steps as f64;
        let weinberg_mean = weinberg_total / roots.len() as f64;
        println!(
            "K_cal {k_cal:.4}; {} detected / {true_steps} true steps; mean step {weinberg_mean:.4} m \
             vs truth {true_mean:.4} m; total {weinberg_total:.2} m vs 90 m",
            roots.len()
        );
        assert!(
            (weinberg_total - 90.0).abs() < 0.03 * 90.0,
            "{weinberg_total}"
        );
        assert!((weinberg_mean / true_mean - 1.0).abs() < 0.03);
        // A calibration error ε scales every step by exactly (1 + ε).
        let eps = 0.08;
        let off: f64 = roots.iter().map(|r| k_cal * (1.0 + eps) * r).sum();
        assert!((off / weinberg_total - (1.0 + eps)).abs() < 1e-12);
    }

    #[test]
    fn ahrs_heading_drift_with_a_constant_gyro_bias_is_bias_times_time() {
        // A phone held level and still, a constant gyro bias b about the vertical, no
        // magnetometer (mag_gain 0) and no bias estimation (bias_gain 0): the heading
        // drifts by exactly b·t (the accelerometer term only levels, it cannot see yaw).
        // The gyro reads the Earth rate plus the bias, as a real gyro does; the AHRS removes
        // the Earth rate it knows.
        use crate::inertial::attitude::attitude_from_euler;
        let earth = LocalEarth::new(0.53, 10.0);
        let cfg = PdrConfig {
            mag_gain: 0.0,
            bias_gain: 0.0,
            ..PdrConfig::default()
        };
        let q = attitude_from_euler(0.3, 0.0, 0.0);
        let g_up = Vector3::new(0.0, 0.0, 9.79);
        let f_b = q.inverse() * g_up;
        let field = Vector3::new(-2.6, 33.8, -36.5);
        let mut ahrs = Ahrs::align(&f_b, &(q.inverse() * field), &field, earth, &cfg);
        let bias_rps = (3.0f64).to_radians(); // BMI160's typical zero-rate offset, 3 °/s
        let w_b = q.inverse() * earth.omega_ie_enu_rps + Vector3::new(0.0, 0.0, bias_rps);
        let rate = 100.0;
        let t_end = 60.0;
        let h0 = ahrs.heading_rad();
        for k in 0..=(t_end * rate) as usize {
            let s = ImuSample {
                t_s: k as f64 / rate,
                gyro_rps: w_b,
                accel_mps2: f_b,
            };
            ahrs.update(&s, None);
        }
        // A positive rate about body z (up) turns the nose towards the west: the heading
        // (clockwise from north) falls by b·t.
        let drift = (h0 - ahrs.heading_rad()).rem_euclid(TAU);
        let expect = bias_rps * t_end;
        assert!(
            (drift - expect).abs() < 1e-6,
            "drift {drift} rad vs b·t {expect} rad"
        );
    }

    #[test]
    fn ahrs_aligns_to_the_true_attitude() {
        use crate::inertial::attitude::attitude_from_euler;
        use crate::inertial::magnetometer::MagnetometerConfig;
        let earth = LocalEarth::new(0.7, 0.0);
        let field = MagnetometerConfig::default().field_enu_ut();
        let q = attitude_from_euler(1.0, 0.4, -0.2);
        let f = q.inverse() * Vector3::new(0.0, 0.0, 9.8);
        let m = q.inverse() * field;
        let a = Ahrs::align(&f, &m, &field, earth, &PdrConfig::default());
        assert!(
            a.attitude().angle_to(&q) < 1e-9,
            "{}",
            a.attitude().angle_to(&q)
        );
    }
}
