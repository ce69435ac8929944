//! The inertial estimators the engine drives: the loosely coupled INS ([`InsEstimator`],
//! seed 004 §2.1–2.3) and pedestrian dead reckoning from step events ([`PdrEstimator`],
//! seed 002 §4.2, PDR-only row, optionally reset by position fixes).
//!
//! Both work in the world's ENU frame (`EnuFrame`) and report ECEF estimates. Neither ever
//! panics on its input: a measurement it cannot use is counted as rejected, and a state
//! that stops being finite is reported as `numerical_failure` and reset (the INS
//! re-initialises from the next fixes; the PDR keeps its last finite position).

use super::imu::ImuConfig;
use super::ins_ekf::{InsEkf, InsEkfConfig};
use super::ins_family::{Cov6, InsFamilyFilter, InsKalmanConfig, InsKalmanKind};
use super::source::local_earth_of;
use super::strapdown::NavState;
use super::LocalEarth;
use crate::core::ConfigIssue;
use crate::core::{EnuFrame, GpsTime, System};
use crate::fusion::models::MeasurementModel;
use crate::fusion::wls::{self, WlsOptions};
use crate::measurement::ImuSample;
use crate::measurement::SourceKind;
use crate::measurement::{EpochOutcome, Estimate, Estimator};
use crate::measurement::{
    Measurement, MeasurementBatch, RangeDifference, RangeMeasurement, StepEvent,
};
use nalgebra::{
    Matrix2, Matrix3, Matrix4, Rotation3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3,
    Vector4,
};
use serde::{Deserialize, Serialize};

fn d_fix_sources() -> Vec<SourceKind> {
    vec![SourceKind::Gnss]
}
fn d_true() -> bool {
    true
}
fn d_min_speed() -> f64 {
    0.5
}
fn d_max_heading_sigma() -> f64 {
    10.0
}
fn d_tilt_sigma() -> f64 {
    2.0
}
fn d_noise_scale() -> f64 {
    1.0
}
fn d_max_lag() -> f64 {
    1.0
}
fn d_window() -> f64 {
    5.0
}
fn d_aleph() -> f64 {
    crate::fusion::kalman::DEFAULT_ALEPH_THRESHOLD
}
fn d_forgetting() -> f64 {
    0.95
}
fn d_builtin() -> InsKalmanKind {
    InsKalmanKind::Builtin
}
/// The longest interval between two fixes whose difference still gives a velocity (s).
const MAX_DIFFERENCE_INTERVAL_S: f64 = 2.0;

/// Fixes kept for the position-only initialisation.
const INIT_RING: usize = 16;

/// Weighted least-squares fit of p(τ) = p₀ + v τ + ½ a τ² to positions at times τ ≤ 0
/// relative to now (each with its variance), spanning at least `min_span_s`: returns
/// (v, a, var v, var a) at τ = 0, the same variances on every axis. Does not allocate.
fn quadratic_fit(
    pts: impl Iterator<Item = (f64, Vector3<f64>, f64)>,
    min_span_s: f64,
) -> Option<(Vector3<f64>, Vector3<f64>, f64, f64)> {
    let mut n = Matrix3::<f64>::zeros();
    let mut rhs = Matrix3::<f64>::zeros();
    let (mut count, mut earliest) = (0, 0.0f64);
    for (tau, p, var) in pts {
        if !(var.is_finite() && var > 0.0 && tau.is_finite()) {
            continue;
        }
        let h = Vector3::new(1.0, tau, 0.5 * tau * tau);
        n += h * h.transpose() / var;
        rhs += h * p.transpose() / var;
        count += 1;
        earliest = earliest.min(tau);
    }
    if count < 3 || -earliest < min_span_s {
        return None;
    }
    let chol = n.cholesky()?;
    let x = chol.solve(&rhs);
    let inv = chol.inverse();
    let v = x.row(1).transpose();
    let a = x.row(2).transpose();
    (inv[(1, 1)] > 0.0 && inv[(2, 2)] > 0.0 && v.iter().chain(a.iter()).all(|e| e.is_finite()))
        .then_some((v, a, inv[(1, 1)], inv[(2, 2)]))
}

/// `[estimator.ins]`: how the loosely coupled INS takes its fixes and initialises.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InsFilterConfig {
    /// Sources whose batches give fixes; default `["gnss"]`. A `"gnss"` batch gives one
    /// position fix by weighted least squares on its pseudoranges (the systems the
    /// estimator lists) and, with `use_gnss_velocity`, a velocity fix from the range rates;
    /// any other source gives its [`Measurement::Position`] items (e.g. `"tcofdm"`).
    #[serde(default = "d_fix_sources")]
    pub fix_sources: Vec<SourceKind>,
    /// Also use the velocity solved from GNSS range rates (eqs. 16–19 in full); default true.
    #[serde(default = "d_true")]
    pub use_gnss_velocity: bool,
    /// Initialisation waits for a horizontal speed of at least this (m/s); default 0.5.
    #[serde(default = "d_min_speed")]
    pub init_min_speed_mps: f64,
    /// ... and for a heading from the velocity with a 1-σ of at most this (°); default 10.
    #[serde(default = "d_max_heading_sigma")]
    pub init_max_heading_sigma_deg: f64,
    /// 1-σ of the initial roll and pitch from accelerometer levelling (°); default 2.
    #[serde(default = "d_tilt_sigma")]
    pub init_tilt_sigma_deg: f64,
    /// Multiplies the IMU noise densities and bias σ the filter assumes; default 1.
    #[serde(default = "d_noise_scale")]
    pub process_noise_scale: f64,
    /// Reject fixes whose NIS exceeds this (χ², 3 or 6 degrees of freedom); default none.
    #[serde(default)]
    pub nis_gate: Option<f64>,
    /// A fix more than this away from the INS time is rejected (s); default 1.
    #[serde(default = "d_max_lag")]
    pub max_fix_lag_s: f64,
    /// Position-only initialisation: the fixes of the last `init_window_s` seconds (at most
    /// 16) give the initial velocity and acceleration by a quadratic fit (s); default 5.
    #[serde(default = "d_window")]
    pub init_window_s: f64,
    /// The filter on the error state: `"builtin"` (default, [`InsEkf`]), or seed 004's
    /// comparison `"ekf"`, `"ckf"`, `"stf"`, `"rekf"` ([`InsFamilyFilter`]). The generic
    /// filters always update with the position and the velocity difference (eq. 17): the
    /// velocity from GNSS range rates when there are four, else the difference of this fix
    /// and the previous one (at most 2 s before); a fix with neither is only remembered.
    #[serde(default = "d_builtin")]
    pub kalman: InsKalmanKind,
    /// Seed 004's eq. 24 residual gate on each component of the difference, `C`
    /// (generic filters only); default none.
    #[serde(default)]
    pub residual_gate_c: Option<f64>,
    /// RE-KF: ℵ_threshold (eq. 38); default ½ ln 2.
    #[serde(default = "d_aleph")]
    pub aleph_threshold: f64,
    /// STF: forgetting factor ρ (default 0.95) and weakening factor β (default 1).
    #[serde(default = "d_forgetting")]
    pub stf_forgetting: f64,
    #[serde(default = "d_noise_scale")]
    pub stf_weakening: f64,
    /// Pool the pseudoranges of every fix source at one epoch (e.g. `"gnss"` and
    /// `"tcofdm"`) into one least-squares fix, seed 004's joint TC-OFDM/GNSS solution
    /// (eqs. 10–13); default false (one fix per GNSS batch, TC-OFDM ranges unused).
    #[serde(default)]
    pub joint_fix: bool,
    /// σ of what a fix velocity does not describe of the IMU's motion, `[horizontal,
    /// vertical]` (m/s), added in quadrature to the fix velocity's covariance; default
    /// `[0, 0]`. A walker's receiver reports the velocity of the walk, while a handheld
    /// or body-worn IMU also moves with the gait (`[platform.attitude]`'s bounce and
    /// surge: amplitudes B/ω₀ vertically and S/ω₀ forward, so σ = B/(√2 ω₀) ≈ 0.25 m/s
    /// and S/(√2 ω₀) ≈ 0.09 m/s for the default gait).
    #[serde(default)]
    pub fix_velocity_noise_mps: [f64; 2],
}

impl Default for InsFilterConfig {
    fn default() -> Self {
        Self {
            fix_sources: d_fix_sources(),
            use_gnss_velocity: true,
            init_min_speed_mps: d_min_speed(),
            init_max_heading_sigma_deg: d_max_heading_sigma(),
            init_tilt_sigma_deg: d_tilt_sigma(),
            process_noise_scale: d_noise_scale(),
            nis_gate: None,
            max_fix_lag_s: d_max_lag(),
            init_window_s: d_window(),
            kalman: InsKalmanKind::Builtin,
            residual_gate_c: None,
            aleph_threshold: d_aleph(),
            stf_forgetting: d_forgetting(),
            stf_weakening: 1.0,
            joint_fix: false,
            fix_velocity_noise_mps: [0.0, 0.0],
        }
    }
}

fn positive(key: &str, v: f64, hi: f64, what: &str) -> Result<(), ConfigIssue> {
    if v.is_finite() && v > 0.0 && v <= hi {
        Ok(())
    } else {
        Err(ConfigIssue::new(
            key,
            format!("expected {what} within (0, {hi}], got {v}"),
        ))
    }
}

impl InsFilterConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if self.fix_sources.contains(&SourceKind::Imu) {
            return Err(ConfigIssue::new(
                "fix_sources",
                format!(
                    "expected names of fix sources such as \"gnss\" or \"tcofdm\" (not \"imu\"), got {:?}",
                    self.fix_sources
                ),
            ));
        }
        if !(self.init_min_speed_mps.is_finite()
            && self.init_min_speed_mps >= 0.0
            && self.init_min_speed_mps <= 100.0)
        {
            return Err(ConfigIssue::new(
                "init_min_speed_mps",
                format!(
                    "expected a speed in m/s within [0, 100], got {}",
                    self.init_min_speed_mps
                ),
            ));
        }
        positive(
            "init_max_heading_sigma_deg",
            self.init_max_heading_sigma_deg,
            45.0,
            "a heading σ in degrees",
        )?;
        positive(
            "init_tilt_sigma_deg",
            self.init_tilt_sigma_deg,
            45.0,
            "a tilt σ in degrees",
        )?;
        positive(
            "process_noise_scale",
            self.process_noise_scale,
            1.0e3,
            "a noise scale",
        )?;
        if let Some(g) = self.nis_gate {
            positive("nis_gate", g, 1.0e6, "a χ² gate")?;
        }
        positive("max_fix_lag_s", self.max_fix_lag_s, 60.0, "a time lag in s")?;
        positive(
            "init_window_s",
            self.init_window_s,
            60.0,
            "a time window in s",
        )?;
        if let Some(c) = self.residual_gate_c {
            positive("residual_gate_c", c, 1.0e3, "a gate factor C")?;
        }
        positive(
            "aleph_threshold",
            self.aleph_threshold,
            1.0e3,
            "a coupling-degree threshold",
        )?;
        positive(
            "stf_forgetting",
            self.stf_forgetting,
            1.0,
            "a forgetting factor ρ",
        )?;
        if !(self.stf_weakening.is_finite() && (1.0..=1.0e3).contains(&self.stf_weakening)) {
            return Err(ConfigIssue::new(
                "stf_weakening",
                format!(
                    "expected a weakening factor β within [1, 1000], got {}",
                    self.stf_weakening
                ),
            ));
        }
        if self
            .fix_velocity_noise_mps
            .iter()
            .any(|v| !(v.is_finite() && (0.0..=100.0).contains(v)))
        {
            return Err(ConfigIssue::new(
                "fix_velocity_noise_mps",
                format!(
                    "expected [horizontal, vertical] σ in m/s within [0, 100], got {:?}",
                    self.fix_velocity_noise_mps
                ),
            ));
        }
        if self.kalman == InsKalmanKind::Builtin {
            for (key, set) in [
                ("residual_gate_c", self.residual_gate_c.is_some()),
                ("aleph_threshold", self.aleph_threshold != d_aleph()),
            ] {
                if set {
                    return Err(ConfigIssue::new(
                        key,
                        "applies to kalman = \"ekf\", \"ckf\", \"stf\" or \"rekf\", not to the builtin filter",
                    ));
                }
            }
        }
        Ok(())
    }

    fn kalman_config(&self) -> InsKalmanConfig {
        InsKalmanConfig {
            kind: self.kalman,
            residual_gate_c: self.residual_gate_c,
            aleph_threshold: self.aleph_threshold,
            stf_forgetting: self.stf_forgetting,
            stf_weakening: self.stf_weakening,
        }
    }
}

/// A velocity from pseudorange rates at a known receiver position, by weighted least
/// squares on the model of seed 000 eq. 16, `ρ̇ᵢ = uᵢ · (v − vᵢ) + ḃ`, with
/// `uᵢ = (r − rᵢ)/‖r − rᵢ‖` and one clock drift ḃ shared by all systems (one oscillator).
/// Rows are `[uᵢᵀ 1]`, observations `ρ̇ᵢ + uᵢ · vᵢ`, weights `1/σᵢ²`.
///
/// Returns (velocity ECEF m/s, its covariance (m/s)², rates used), or `None` with fewer
/// than four usable rates or a singular geometry. Does not allocate.
pub fn velocity_from_rates(
    ranges: &[RangeMeasurement],
    rx_ecef_m: &Vector3<f64>,
) -> Option<(Vector3<f64>, Matrix3<f64>, usize)> {
    let mut n = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    let mut used = 0;
    for m in ranges {
        let Some(rate) = m.range_rate_mps else {
            continue;
        };
        let s = m.sigma_rate_mps;
        let los = rx_ecef_m - m.emitter_pos_ecef_m;
        let d = los.norm();
        if !(rate.is_finite() && s.is_finite() && s > 0.0 && d > 1e-3 && d.is_finite()) {
            continue;
        }
        let u = los / d;
        let h = Vector4::new(u.x, u.y, u.z, 1.0);
        let w = 1.0 / (s * s);
        n += h * h.transpose() * w;
        rhs += h * (w * (rate + u.dot(&m.emitter_vel_ecef_mps)));
        used += 1;
    }
    if used < 4 {
        return None;
    }
    let chol = n.cholesky()?;
    let x = chol.solve(&rhs);
    let cov = chol.inverse();
    let v = Vector3::new(x[0], x[1], x[2]);
    let c: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
    (v.iter().chain(c.iter()).all(|e| e.is_finite()) && c[(0, 0)] > 0.0).then_some((v, c, used))
}

/// One fix in the world frame.
#[derive(Clone, Copy, Debug)]
struct Fix {
    t_s: f64,
    pos_enu_m: Vector3<f64>,
    pos_cov_m2: Matrix3<f64>,
    vel: Option<(Vector3<f64>, Matrix3<f64>)>,
    /// Measurements behind the fix.
    n: u32,
}

/// ENU covariance of an ECEF covariance: C P Cᵀ with C the ECEF → ENU rotation.
fn enu_cov(frame: &EnuFrame, cov_ecef: &Matrix3<f64>) -> Matrix3<f64> {
    let c = frame.rotation();
    c * cov_ecef * c.transpose()
}

/// ECEF covariance of an ENU covariance.
fn ecef_cov(frame: &EnuFrame, cov_enu: &Matrix3<f64>) -> Matrix3<f64> {
    let c = frame.rotation();
    c.transpose() * cov_enu * c
}

/// Collects the batch's fixes: one from the pseudoranges of a `"gnss"` batch (the
/// estimator's systems), plus every [`Measurement::Position`] item. Ranges that give no
/// fix are counted in `rejected`.
#[allow(clippy::too_many_arguments)]
fn fixes_of_batch(
    batch: &MeasurementBatch,
    t_s: f64,
    frame: &EnuFrame,
    systems: &[System],
    with_velocity: bool,
    near_ecef_m: Option<Vector3<f64>>,
    scratch: &mut Vec<RangeMeasurement>,
    fixes: &mut Vec<Fix>,
    rejected: &mut u32,
    gdop: &mut Option<f64>,
) {
    fixes.clear();
    if batch.source == SourceKind::Gnss {
        scratch.clear();
        scratch.extend(
            batch
                .ranges()
                .filter(|m| systems.is_empty() || systems.contains(&m.system()))
                .copied(),
        );
        if !scratch.is_empty() {
            let opts = WlsOptions {
                initial_pos_ecef_m: near_ecef_m,
                ..WlsOptions::default()
            };
            match wls::solve(scratch.iter(), &opts) {
                Ok(fix) => {
                    let vel = if with_velocity {
                        velocity_from_rates(scratch, &fix.pos_ecef_m)
                            .map(|(v, c, _)| (frame.enu_vector_of_ecef(&v), enu_cov(frame, &c)))
                    } else {
                        None
                    };
                    *gdop = Some(fix.dop.gdop);
                    fixes.push(Fix {
                        t_s,
                        pos_enu_m: frame.enu_of_ecef(&fix.pos_ecef_m),
                        pos_cov_m2: enu_cov(frame, &fix.cov_pos_ecef_m2),
                        vel,
                        n: fix.n_measurements as u32,
                    });
                }
                Err(_) => *rejected += scratch.len() as u32,
            }
        }
    }
    for m in &batch.items {
        if let Measurement::Position(p) = m {
            if p.pos_ecef_m
                .iter()
                .chain(p.cov_m2.iter())
                .all(|v| v.is_finite())
            {
                fixes.push(Fix {
                    t_s,
                    pos_enu_m: frame.enu_of_ecef(&p.pos_ecef_m),
                    pos_cov_m2: enu_cov(frame, &p.cov_m2),
                    vel: None,
                    n: 1,
                });
            } else {
                *rejected += 1;
            }
        }
    }
}

/// The attitude C_b^n that maps the body vectors (f^b, x^b) onto the navigation vectors
/// (f^n, v^n) by TRIAD (Shuster & Oh 1981): the specific force is matched exactly, and the
/// body forward axis is put in the vertical plane of the velocity. `None` when either pair
/// is (nearly) parallel.
fn triad(
    f_b: &Vector3<f64>,
    f_n: &Vector3<f64>,
    v_n: &Vector3<f64>,
) -> Option<UnitQuaternion<f64>> {
    let x_b = Vector3::x();
    let t1b = f_b.try_normalize(1e-9)?;
    let t2b = f_b.cross(&x_b).try_normalize(1e-6 * f_b.norm())?;
    let t1n = f_n.try_normalize(1e-9)?;
    let t2n = f_n
        .cross(v_n)
        .try_normalize(1e-6 * f_n.norm() * v_n.norm())?;
    let mb = Matrix3::from_columns(&[t1b, t2b, t1b.cross(&t2b)]);
    let mn = Matrix3::from_columns(&[t1n, t2n, t1n.cross(&t2n)]);
    let c = mn * mb.transpose();
    c.iter()
        .all(|v| v.is_finite())
        .then(|| UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(c)))
}

/// The loosely coupled INS of seed 004: strapdown mechanisation and the 15-state
/// error-state filter propagated with every `"imu"` sample and corrected with position
/// (and velocity) fixes, closed loop. The filter is [`InsEkf`] (`kalman = "builtin"`) or
/// one of seed 004's four on the same error model ([`InsFamilyFilter`]: `"ekf"`, `"ckf"`,
/// `"stf"`, `"rekf"`).
///
/// # Initialisation
///
/// The filter starts at the first fix at which the platform moves fast enough for a heading
/// (horizontal speed ≥ `init_min_speed_mps` and heading σ = atan(σ_v⊥ / |v_h|) ≤
/// `init_max_heading_sigma_deg`):
///
/// * position: the fix, moved to the last IMU sample time with the fix velocity;
/// * velocity: the GNSS velocity from range rates, or (position-only sources) a weighted
///   quadratic fit to the fixes of the last `init_window_s` (at least 3, spanning ≥ 20 % of
///   the window);
/// * attitude: TRIAD on the mean specific force f̄^b since the previous fix against
///   f^n = a^n − g^n + 2 ω_ie × v (a^n from the change of two consecutive GNSS velocities,
///   or from the quadratic fit), with the
///   body forward axis in the vertical plane of the velocity (heading along the track:
///   right for a car and for a phone pointing where its user walks).
/// * covariance: the fix covariances, a tilt σ of `init_tilt_sigma_deg` ⊕ σ(a^n)/g, the
///   heading σ above (at least 1°), and the IMU's bias σ ([`InsEkfConfig::from_imu`]).
///
/// Until then it has no estimate. The IMU noise model is the configured IMU's
/// (`process_noise_scale` × its densities).
///
/// # Fixes
///
/// With `joint_fix`, the pseudoranges of every fix source at one epoch (GNSS and TC-OFDM)
/// are pooled into one weighted least-squares fix with one clock per system (seed 004
/// eqs. 10–13 write one clock; the simulated receiver has inter-system biases), solved
/// when every fix source has reported at that time or when a later batch arrives.
///
/// A fix at time t_f is compared with the INS at its last sample time t_i, moved by the
/// INS velocity: r_fix + v̂ (t_i − t_f) (|t_i − t_f| ≤ `max_fix_lag_s`, else rejected).
/// The builtin filter makes a joint position–velocity update with a GNSS velocity
/// (eqs. 16–19), otherwise a position update. The generic filters always update position
/// and velocity: with the GNSS velocity, or with `v = (r_k − r_{k−1})/Δt` from the
/// previous fix (≤ 2 s before), whose covariance `(P_k + P_{k−1})/Δt²` and cross
/// covariance `P_k/Δt` with the position enter `R` (its correlation with the previous
/// epoch's position difference is not modelled); a fix with neither only becomes the
/// previous fix. `fix_velocity_noise_mps` is added to the velocity's variance. For these
/// filters `used` and `rejected` count the six components of the difference, and those
/// the eq. 24 gate removed are reported as gated.
pub struct InsEstimator {
    name: String,
    cfg: InsFilterConfig,
    frame: EnuFrame,
    earth: LocalEarth,
    start: GpsTime,
    systems: Vec<System>,
    ekf_cfg: InsEkfConfig,
    kf: Option<InsCore>,
    f_sum_mps2: Vector3<f64>,
    f_count: u32,
    last_imu_t_s: Option<f64>,
    last_fix: Option<Fix>,
    /// The previous fix the generic filters difference for a velocity.
    prev_fix: Option<Fix>,
    /// Recent position fixes (t s, ENU m, horizontal variance m²) for the position-only
    /// initialisation.
    ring: [Option<(f64, Vector3<f64>, f64)>; INIT_RING],
    ring_next: usize,
    scratch: Vec<RangeMeasurement>,
    fixes: Vec<Fix>,
    /// `joint_fix`: the epoch being collected, its ranges and which fix sources reported.
    pending_t: Option<GpsTime>,
    pending: Vec<RangeMeasurement>,
    pending_seen: Vec<bool>,
    latest: Option<Estimate>,
    resets: u32,
}

/// The error-state filter an [`InsEstimator`] runs.
enum InsCore {
    Builtin(Box<InsEkf>),
    Family(Box<InsFamilyFilter>),
}

impl InsCore {
    fn state(&self) -> &NavState {
        match self {
            InsCore::Builtin(k) => k.state(),
            InsCore::Family(k) => k.state(),
        }
    }

    /// The position covariance now (ENU m²).
    fn position_covariance_m2(&self) -> Matrix3<f64> {
        match self {
            InsCore::Builtin(k) => k.covariance().fixed_view::<3, 3>(0, 0).into_owned(),
            InsCore::Family(k) => k.position_covariance_m2(),
        }
    }

    fn covariance(&self) -> &super::ins_ekf::Cov15 {
        match self {
            InsCore::Builtin(k) => k.covariance(),
            InsCore::Family(k) => k.covariance(),
        }
    }

    fn propagate(&mut self, s: &ImuSample) {
        match self {
            InsCore::Builtin(k) => k.propagate(s),
            InsCore::Family(k) => k.propagate(s),
        }
    }
}

impl InsEstimator {
    /// An INS whose IMU is `imu` (the world's `[sensors.imu]`), in the world frame, with
    /// fixes from the sources `cfg.fix_sources` names; from GNSS batches it uses the
    /// `systems` (all when empty). `start` is the world's start time (sample times are
    /// seconds since it).
    ///
    /// # Errors
    /// A [`ConfigIssue`] for a bad IMU (key `imu.…`) or filter setting.
    pub fn new(
        name: &str,
        cfg: &InsFilterConfig,
        imu: &ImuConfig,
        systems: &[System],
        frame: &EnuFrame,
        start: GpsTime,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let spec = imu
            .resolve()
            .map_err(|i| ConfigIssue::new(format!("imu.{}", i.key), i.message))?;
        let mut ekf_cfg = InsEkfConfig::from_imu(&spec);
        let k = cfg.process_noise_scale;
        ekf_cfg.accel_vrw_mps_per_sqrt_s *= k;
        ekf_cfg.gyro_arw_rad_per_sqrt_s *= k;
        ekf_cfg.accel_bias_sigma_mps2 *= k;
        ekf_cfg.gyro_bias_sigma_rps *= k;
        ekf_cfg.accel_bias_rw *= k;
        ekf_cfg.gyro_bias_rw *= k;
        ekf_cfg.nis_gate = cfg.nis_gate;
        Ok(Self {
            name: name.to_string(),
            cfg: cfg.clone(),
            frame: frame.clone(),
            earth: local_earth_of(frame),
            start,
            systems: systems.to_vec(),
            ekf_cfg,
            kf: None,
            f_sum_mps2: Vector3::zeros(),
            f_count: 0,
            last_imu_t_s: None,
            last_fix: None,
            prev_fix: None,
            ring: [None; INIT_RING],
            ring_next: 0,
            scratch: Vec::with_capacity(64),
            fixes: Vec::with_capacity(4),
            pending_t: None,
            pending: Vec::with_capacity(64),
            pending_seen: vec![false; cfg.fix_sources.len()],
            latest: None,
            resets: 0,
        })
    }

    /// The builtin filter ([`InsEkf`]), once initialised; `None` before, or when a
    /// generic filter runs ([`InsEstimator::family_filter`]).
    pub fn filter(&self) -> Option<&InsEkf> {
        match self.kf.as_ref()? {
            InsCore::Builtin(k) => Some(k),
            InsCore::Family(_) => None,
        }
    }

    /// The generic filter (`kalman = "ekf"`, `"ckf"`, `"stf"`, `"rekf"`), once initialised.
    pub fn family_filter(&self) -> Option<&InsFamilyFilter> {
        match self.kf.as_ref()? {
            InsCore::Builtin(_) => None,
            InsCore::Family(k) => Some(k),
        }
    }

    /// The navigation solution, once initialised (whatever the filter).
    pub fn nav_state(&self) -> Option<&NavState> {
        self.kf.as_ref().map(InsCore::state)
    }

    /// How many times a numerical failure reset the filter.
    pub fn resets(&self) -> u32 {
        self.resets
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        let kf = self.kf.as_ref()?;
        let st = kf.state();
        let cov_enu = kf.position_covariance_m2();
        Some(Estimate {
            t,
            pos_ecef_m: self.frame.ecef_of_enu(&st.pos_enu_m),
            vel_ecef_mps: Some(self.frame.ecef_vector_of_enu(&st.vel_enu_mps)),
            cov_pos_m2: ecef_cov(&self.frame, &cov_enu),
        })
    }

    fn healthy(kf: &InsCore) -> bool {
        let st = kf.state();
        let p = kf.covariance();
        let pos = kf.position_covariance_m2();
        st.pos_enu_m.iter().all(|v| v.is_finite())
            && st.vel_enu_mps.iter().all(|v| v.is_finite())
            && st.q_nb.coords.iter().all(|v| v.is_finite())
            && (0..15).all(|i| p[(i, i)].is_finite() && p[(i, i)] >= 0.0 && p[(i, i)] < 1e15)
            && (0..3).all(|i| pos[(i, i)].is_finite() && pos[(i, i)] >= 0.0 && pos[(i, i)] < 1e15)
    }

    /// Drops the filter after a numerical failure; the next fixes re-initialise it.
    fn reset(&mut self, out: &mut EpochOutcome) {
        self.kf = None;
        self.last_fix = None;
        self.prev_fix = None;
        self.ring = [None; INIT_RING];
        self.f_sum_mps2 = Vector3::zeros();
        self.f_count = 0;
        self.latest = None;
        self.resets += 1;
        out.numerical_failure = true;
    }

    fn imu_sample(&mut self, s: &ImuSample, out: &mut EpochOutcome) {
        if !(s.t_s.is_finite()
            && s.gyro_rps.iter().all(|v| v.is_finite())
            && s.accel_mps2.iter().all(|v| v.is_finite()))
        {
            out.rejected += 1;
            return;
        }
        if self.last_imu_t_s.is_some_and(|t| s.t_s <= t) {
            out.rejected += 1;
            return;
        }
        self.last_imu_t_s = Some(s.t_s);
        match &mut self.kf {
            Some(kf) => {
                kf.propagate(s);
                out.used += 1;
            }
            None => {
                self.f_sum_mps2 += s.accel_mps2;
                self.f_count += 1;
            }
        }
    }

    fn apply_fix(&mut self, fix: &Fix, out: &mut EpochOutcome) {
        let prev = self.prev_fix.replace(*fix);
        let Some(kf) = &mut self.kf else {
            self.try_initialise(fix);
            return;
        };
        let st = *kf.state();
        let lag = st.t_s - fix.t_s;
        if lag.abs() > self.cfg.max_fix_lag_s {
            out.rejected += fix.n;
            return;
        }
        let pos = fix.pos_enu_m + st.vel_enu_mps * lag;
        match kf {
            InsCore::Builtin(kf) => {
                let [nh, nv] = self.cfg.fix_velocity_noise_mps;
                let extra = Matrix3::from_diagonal(&Vector3::new(nh * nh, nh * nh, nv * nv));
                let r = match &fix.vel {
                    Some((v, vc)) => {
                        kf.update_position_velocity(&pos, &fix.pos_cov_m2, v, &(vc + extra))
                    }
                    None => kf.update_position(&pos, &fix.pos_cov_m2),
                };
                match r {
                    Ok(o) if o.accepted => {
                        out.used += fix.n;
                        let dof = if fix.vel.is_some() { 6 } else { 3 };
                        tally_unwatched_nis(out, o.nis, dof);
                    }
                    _ => out.rejected += fix.n,
                }
            }
            InsCore::Family(kf) => {
                let mut r = Cov6::zeros();
                r.fixed_view_mut::<3, 3>(0, 0).copy_from(&fix.pos_cov_m2);
                let vel = match (&fix.vel, prev) {
                    (Some((v, vc)), _) => {
                        r.fixed_view_mut::<3, 3>(3, 3).copy_from(vc);
                        *v
                    }
                    (None, Some(p))
                        if fix.t_s > p.t_s && fix.t_s - p.t_s <= MAX_DIFFERENCE_INTERVAL_S =>
                    {
                        let dt = fix.t_s - p.t_s;
                        let cross = fix.pos_cov_m2 / dt;
                        r.fixed_view_mut::<3, 3>(3, 3)
                            .copy_from(&((fix.pos_cov_m2 + p.pos_cov_m2) / (dt * dt)));
                        r.fixed_view_mut::<3, 3>(0, 3).copy_from(&cross);
                        r.fixed_view_mut::<3, 3>(3, 0).copy_from(&cross.transpose());
                        (fix.pos_enu_m - p.pos_enu_m) / dt
                    }
                    // No velocity: the fix is only remembered for the next difference.
                    _ => return,
                };
                let [nh, nv] = self.cfg.fix_velocity_noise_mps;
                for (i, n) in [nh, nh, nv].iter().enumerate() {
                    r[(3 + i, 3 + i)] += n * n;
                }
                let rep = kf.update(&pos, &vel, &r);
                // Counted per component of the difference (eq. 17), which the gates act on.
                // Like the builtin filter, the NIS goes to the records but not to the
                // engine's divergence watch: the paper's filters have no divergence
                // detection and are compared as they are. A fully gated difference is
                // reported, so a gate that locks out every fix for ten epochs still
                // resets the filter.
                out.used += rep.used;
                out.rejected += rep.rejected;
                if let crate::fusion::ekf11::UpdateOutcome::Accepted { nis } = rep.outcome {
                    tally_unwatched_nis(out, nis, rep.used);
                }
                let gated = match rep.outcome {
                    crate::fusion::ekf11::UpdateOutcome::Accepted { .. } => {
                        self.cfg.residual_gate_c.is_some()
                    }
                    crate::fusion::ekf11::UpdateOutcome::Rejected { reason, .. } => {
                        reason == crate::fusion::ekf11::RejectReason::Gate
                    }
                };
                if gated {
                    out.rejected_gate += rep.rejected;
                }
            }
        }
    }

    fn try_initialise(&mut self, fix: &Fix) {
        let f_mean = (self.f_count > 0).then(|| self.f_sum_mps2 / f64::from(self.f_count));
        self.f_sum_mps2 = Vector3::zeros();
        self.f_count = 0;
        let prev = self.last_fix.replace(*fix);
        let horiz_var = 0.5 * (fix.pos_cov_m2[(0, 0)] + fix.pos_cov_m2[(1, 1)]);
        self.ring[self.ring_next % INIT_RING] = Some((fix.t_s, fix.pos_enu_m, horiz_var));
        self.ring_next += 1;
        // Velocity, acceleration and the σ of the acceleration at the fix.
        let (v, v_cov, a_n, sigma_a) = match (&fix.vel, &prev) {
            (Some((v, vc)), Some(p)) => {
                let dt = fix.t_s - p.t_s;
                match p.vel {
                    Some((pv, pc)) if dt > 0.0 && dt <= 2.0 => {
                        let var = 0.5 * (vc[(0, 0)] + vc[(1, 1)] + pc[(0, 0)] + pc[(1, 1)]);
                        (*v, *vc, (v - pv) / dt, var.max(0.0).sqrt() / dt)
                    }
                    _ => return,
                }
            }
            (Some(_), None) => return,
            (None, _) => {
                let window = self.cfg.init_window_s;
                let pts = self
                    .ring
                    .iter()
                    .flatten()
                    .filter(|(t, _, _)| fix.t_s - *t <= window && *t <= fix.t_s)
                    .map(|(t, p, var)| (*t - fix.t_s, *p, *var));
                let Some((v, a, var_v, var_a)) = quadratic_fit(pts, 0.2 * window) else {
                    return;
                };
                (v, Matrix3::identity() * var_v, a, var_a.sqrt())
            }
        };
        let speed = v.x.hypot(v.y);
        let sigma_perp = (0.5 * (v_cov[(0, 0)] + v_cov[(1, 1)])).max(0.0).sqrt();
        let heading_sigma = sigma_perp.atan2(speed);
        if speed < self.cfg.init_min_speed_mps
            || heading_sigma > self.cfg.init_max_heading_sigma_deg.to_radians()
        {
            return;
        }
        let (Some(f_b), Some(t_imu)) = (f_mean, self.last_imu_t_s) else {
            return;
        };
        let w = self.earth.omega_ie_enu_rps;
        let f_n = a_n - self.earth.gravity_enu_mps2(fix.pos_enu_m.z) + 2.0 * w.cross(&v);
        let Some(q_nb) = triad(&f_b, &f_n, &v) else {
            return;
        };
        let lag = t_imu - fix.t_s;
        if lag.abs() > self.cfg.max_fix_lag_s {
            return;
        }
        let mut c = self.ekf_cfg;
        c.init_pos_sigma_m = (0..3)
            .map(|i| fix.pos_cov_m2[(i, i)])
            .fold(0.0f64, f64::max)
            .sqrt()
            .max(0.1);
        c.init_vel_sigma_mps = (0..3)
            .map(|i| v_cov[(i, i)])
            .fold(0.0f64, f64::max)
            .sqrt()
            .max(0.01);
        // Levelling error: the tilt σ plus the uncertainty of a^n seen against gravity.
        c.init_tilt_sigma_rad = self
            .cfg
            .init_tilt_sigma_deg
            .to_radians()
            .hypot(sigma_a / self.earth.gravity_mps2(fix.pos_enu_m.z));
        c.init_heading_sigma_rad = heading_sigma.max(1f64.to_radians());
        let init = NavState {
            t_s: t_imu,
            pos_enu_m: fix.pos_enu_m + v * lag,
            vel_enu_mps: v,
            q_nb,
        };
        let kf = match self.cfg.kalman {
            InsKalmanKind::Builtin => InsCore::Builtin(Box::new(InsEkf::new(init, self.earth, &c))),
            _ => match InsFamilyFilter::new(init, self.earth, &c, &self.cfg.kalman_config()) {
                Ok(k) => InsCore::Family(Box::new(k)),
                Err(_) => return,
            },
        };
        if Self::healthy(&kf) {
            self.kf = Some(kf);
            self.ring = [None; INIT_RING];
        }
    }

    /// `joint_fix`: solves the collected epoch's pooled ranges (and GNSS velocity) as one
    /// fix and applies it.
    fn flush_joint(&mut self, out: &mut EpochOutcome) {
        let Some(t) = self.pending_t.take() else {
            return;
        };
        self.pending_seen.iter_mut().for_each(|s| *s = false);
        if self.pending.is_empty() {
            return;
        }
        let opts = WlsOptions {
            initial_pos_ecef_m: self.latest.map(|e| e.pos_ecef_m),
            ..WlsOptions::default()
        };
        let fix = match wls::solve(self.pending.iter(), &opts) {
            Ok(fix) => fix,
            Err(_) => {
                out.rejected += self.pending.len() as u32;
                self.pending.clear();
                return;
            }
        };
        let vel = if self.cfg.use_gnss_velocity {
            velocity_from_rates(&self.pending, &fix.pos_ecef_m)
                .map(|(v, c, _)| (self.frame.enu_vector_of_ecef(&v), enu_cov(&self.frame, &c)))
        } else {
            None
        };
        out.gdop = Some(fix.dop.gdop);
        let f = Fix {
            t_s: t.seconds_since(self.start),
            pos_enu_m: self.frame.enu_of_ecef(&fix.pos_ecef_m),
            pos_cov_m2: enu_cov(&self.frame, &fix.cov_pos_ecef_m2),
            vel,
            n: fix.n_measurements as u32,
        };
        self.pending.clear();
        self.apply_fix(&f, out);
    }

    /// `joint_fix`: adds a fix source's batch to the epoch being collected.
    fn collect_joint(&mut self, batch: &MeasurementBatch, out: &mut EpochOutcome) {
        if self.pending_t.is_some_and(|t| t != batch.t) {
            self.flush_joint(out);
        }
        self.pending_t = Some(batch.t);
        let systems = &self.systems;
        self.pending.extend(
            batch
                .ranges()
                .filter(|m| systems.is_empty() || systems.contains(&m.system()))
                .copied(),
        );
        if let Some(i) = self.cfg.fix_sources.iter().position(|s| *s == batch.source) {
            self.pending_seen[i] = true;
        }
        // Position items of the batch (a fix source such as "fm") are fixes of their own.
        let t_s = batch.t.seconds_since(self.start);
        for m in &batch.items {
            if let Measurement::Position(p) = m {
                if p.pos_ecef_m
                    .iter()
                    .chain(p.cov_m2.iter())
                    .all(|v| v.is_finite())
                {
                    let f = Fix {
                        t_s,
                        pos_enu_m: self.frame.enu_of_ecef(&p.pos_ecef_m),
                        pos_cov_m2: enu_cov(&self.frame, &p.cov_m2),
                        vel: None,
                        n: 1,
                    };
                    self.apply_fix(&f, out);
                } else {
                    out.rejected += 1;
                }
            }
        }
        if self.pending_seen.iter().all(|s| *s) {
            self.flush_joint(out);
        }
    }
}

impl Estimator for InsEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        source == SourceKind::Imu || self.cfg.fix_sources.contains(&source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        if self.cfg.joint_fix && self.pending_t.is_some_and(|t| batch.t > t) {
            self.flush_joint(&mut out);
        }
        if batch.source == SourceKind::Imu {
            for m in &batch.items {
                if let Measurement::Imu(s) = m {
                    self.imu_sample(s, &mut out);
                }
            }
        } else if self.cfg.fix_sources.contains(&batch.source) {
            if self.cfg.joint_fix {
                self.collect_joint(batch, &mut out);
            } else {
                let t_s = batch.t.seconds_since(self.start);
                let near = self.latest.map(|e| e.pos_ecef_m);
                let mut fixes = std::mem::take(&mut self.fixes);
                fixes_of_batch(
                    batch,
                    t_s,
                    &self.frame,
                    &self.systems,
                    self.cfg.use_gnss_velocity,
                    near,
                    &mut self.scratch,
                    &mut fixes,
                    &mut out.rejected,
                    &mut out.gdop,
                );
                for f in &fixes {
                    self.apply_fix(f, &mut out);
                }
                self.fixes = fixes;
            }
        }
        if self.kf.as_ref().is_some_and(|kf| !Self::healthy(kf)) {
            self.reset(&mut out);
            return out;
        }
        self.latest = self.estimate(batch.t);
        out.estimate = self.latest;
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.latest
    }

    fn reset(&mut self) {
        self.reset(&mut EpochOutcome::default());
        self.pending_t = None;
        self.pending.clear();
        self.pending_seen.iter_mut().for_each(|s| *s = false);
    }
}

fn d_start_sigma() -> f64 {
    0.5
}
fn d_ocxo_h0() -> f64 {
    2e-25
}
fn d_ocxo_hm2() -> f64 {
    6e-25
}
fn d_calibration_s() -> f64 {
    5.0
}
fn d_rd_floor() -> f64 {
    0.05
}
fn d_rd_multipath() -> f64 {
    0.01
}

/// `[estimator.pdr]`: where dead reckoning starts and which fixes (if any) reset it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PdrFilterConfig {
    /// Start position (ENU m, up optional as 0); default the world's known start point (the
    /// constructor's `known_start_enu_m`), else the first fix.
    #[serde(default)]
    pub start_enu_m: Option<Vec<f64>>,
    /// 1-σ of the start position per axis (m); default 0.5.
    #[serde(default = "d_start_sigma")]
    pub start_sigma_m: f64,
    /// Sources whose fixes update the position (`"gnss"` by least squares, others by their
    /// position items); default none (PDR only, seed 002's "PDR" row).
    #[serde(default)]
    pub fix_sources: Vec<SourceKind>,
    /// Reject fixes whose NIS exceeds this (χ², 2 degrees of freedom); default none.
    #[serde(default)]
    pub nis_gate: Option<f64>,
    /// Sources whose TPS-CFO range differences (seed 002 §3.2) update the filter, e.g.
    /// `["dtmb"]`; default none. Only the first tower seen is used.
    #[serde(default)]
    pub range_difference_sources: Vec<SourceKind>,
    /// The power-law coefficients h₀ (s) and h₋₂ (1/s) of the DTMB receiver's oscillator,
    /// whose phase wander the range differences integrate; default Brown & Hwang's OCXO
    /// (2e-25, 6e-25), the `ocxo` preset of `[receiver.clock]` (a TCXO is 2e-19, 2e-20).
    #[serde(default = "d_ocxo_h0")]
    pub range_difference_h0_s: f64,
    #[serde(default = "d_ocxo_hm2")]
    pub range_difference_h_minus2_hz: f64,
    /// Duration of the static CFO calibration at the start (s); default 5, as
    /// [`crate::dtmb::tps::STATIC_CALIBRATION_S`].
    #[serde(default = "d_calibration_s")]
    pub range_difference_calibration_s: f64,
    /// Random-walk intensity of the range-difference error that the oscillator does not
    /// explain, the integrated multipath Doppler error (m/√s); default 0.01 (the
    /// multipath part of `worlds/seed002-lianhua.toml`'s range differences stays within
    /// 2 cm over its 188 s walk; the default leaves 0.14 m for sites with more).
    #[serde(default = "d_rd_multipath")]
    pub range_difference_multipath_m_per_sqrt_s: f64,
    /// Added in quadrature to the range difference's own σ (m); default 0.05: between steps
    /// the walker's position is extrapolated with the last step's velocity, and the gait's
    /// surge (±0.13 m/s for the default gait) moves it by centimetres about that.
    #[serde(default = "d_rd_floor")]
    pub range_difference_sigma_floor_m: f64,
}

impl Default for PdrFilterConfig {
    fn default() -> Self {
        Self {
            start_enu_m: None,
            start_sigma_m: d_start_sigma(),
            fix_sources: Vec::new(),
            nis_gate: None,
            range_difference_sources: Vec::new(),
            range_difference_h0_s: d_ocxo_h0(),
            range_difference_h_minus2_hz: d_ocxo_hm2(),
            range_difference_calibration_s: d_calibration_s(),
            range_difference_sigma_floor_m: d_rd_floor(),
            range_difference_multipath_m_per_sqrt_s: d_rd_multipath(),
        }
    }
}

impl PdrFilterConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if let Some(s) = &self.start_enu_m {
            if !(s.len() == 2 || s.len() == 3) || s.iter().any(|v| !v.is_finite()) {
                return Err(ConfigIssue::new(
                    "start_enu_m",
                    format!("expected [east, north] or [east, north, up] in m, got {s:?}"),
                ));
            }
        }
        positive("start_sigma_m", self.start_sigma_m, 1.0e4, "a start σ in m")?;
        if self.fix_sources.contains(&SourceKind::Pdr) {
            return Err(ConfigIssue::new(
                "fix_sources",
                format!(
                    "expected names of fix sources such as \"gnss\" (not \"pdr\"), got {:?}",
                    self.fix_sources
                ),
            ));
        }
        if let Some(g) = self.nis_gate {
            positive("nis_gate", g, 1.0e6, "a χ² gate")?;
        }
        if self.range_difference_sources.contains(&SourceKind::Pdr) {
            return Err(ConfigIssue::new(
                "range_difference_sources",
                format!(
                    "expected names of range-difference sources such as \"dtmb\", got {:?}",
                    self.range_difference_sources
                ),
            ));
        }
        for (key, v) in [
            ("range_difference_h0_s", self.range_difference_h0_s),
            (
                "range_difference_h_minus2_hz",
                self.range_difference_h_minus2_hz,
            ),
        ] {
            if !(v.is_finite() && (0.0..1e-12).contains(&v)) {
                return Err(ConfigIssue::new(
                    key,
                    format!("expected an oscillator coefficient within [0, 1e-12), got {v}"),
                ));
            }
        }
        let f = self.range_difference_sigma_floor_m;
        if !(f.is_finite() && (0.0..=100.0).contains(&f)) {
            return Err(ConfigIssue::new(
                "range_difference_sigma_floor_m",
                format!("expected a σ in m within [0, 100], got {f}"),
            ));
        }
        positive(
            "range_difference_calibration_s",
            self.range_difference_calibration_s,
            3600.0,
            "a calibration time in s",
        )?;
        let q = self.range_difference_multipath_m_per_sqrt_s;
        if !(q.is_finite() && (0.0..=100.0).contains(&q)) {
            return Err(ConfigIssue::new(
                "range_difference_multipath_m_per_sqrt_s",
                format!("expected a random-walk intensity in m/√s within [0, 100], got {q}"),
            ));
        }
        Ok(())
    }
}

/// The range difference to one tower as a measurement of the [`PdrEstimator`]'s state
/// `[x, y, e, ė]` (east, north m; the accumulated range-difference error e (m) and its
/// rate (m/s)), seed 002 §3.2 and §4.2:
///
/// ```text
/// Δr = ‖p + d − p_b‖ − r₀ + e + w,   p = (x, y, up),   w ~ N(0, σ²)
/// H  = [u_x, u_y, 1, 0],              u = (p + d − p_b)/‖p + d − p_b‖
/// ```
///
/// with `r₀` the range at the reference epoch as the filter anchored it and `d` the
/// walker's displacement since the last step (the PDR state is the position at the last
/// step; `d` = the last step's velocity × the time since it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeDifferenceModel {
    /// Tower position (ENU m).
    pub tower_enu_m: Vector3<f64>,
    /// The walker's up coordinate (m), held fixed by the PDR.
    pub up_m: f64,
    /// The anchored reference range r₀ (m).
    pub r0_m: f64,
    /// The displacement d since the last step (east, north m).
    pub offset_en_m: Vector2<f64>,
    /// σ of the white part w (m).
    pub sigma_m: f64,
}

impl MeasurementModel<4, 1> for RangeDifferenceModel {
    fn h(&self, x: &SVector<f64, 4>) -> SVector<f64, 1> {
        let d = Vector3::new(
            x[0] + self.offset_en_m.x,
            x[1] + self.offset_en_m.y,
            self.up_m,
        ) - self.tower_enu_m;
        SVector::<f64, 1>::new(d.norm() - self.r0_m + x[2])
    }
    fn jacobian(&self, x: &SVector<f64, 4>) -> SMatrix<f64, 1, 4> {
        let d = Vector3::new(
            x[0] + self.offset_en_m.x,
            x[1] + self.offset_en_m.y,
            self.up_m,
        ) - self.tower_enu_m;
        let n = d.norm().max(1e-9);
        SMatrix::<f64, 1, 4>::new(d.x / n, d.y / n, 1.0, 0.0)
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(self.sigma_m * self.sigma_m)
    }
}

/// The anchored tower of a [`PdrEstimator`] that fuses range differences.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Anchor {
    emitter: crate::core::EmitterId,
    tower_enu_m: Vector3<f64>,
    r0_m: f64,
}

/// Dead reckoning from [`StepEvent`]s (seed 002 §4.2's PDR), a filter on the horizontal
/// position [x_east, y_north] with covariance P:
///
/// ```text
/// x ← x + L sin ψ,   y ← y + L cos ψ                        (ψ from north, clockwise)
/// P ← P + J diag(σ_L², σ_ψ²) Jᵀ,   J = [[sin ψ,  L cos ψ], [cos ψ, −L sin ψ]]
/// ```
///
/// (seed 002's x_t = x_{t−1} + v Δt cos θ with θ = π/2 − ψ and v Δt = L), and, when fixes
/// come, the Kalman update with H = I₂ and the horizontal block of the fix covariance. The
/// up coordinate stays at the start's. The step covariance treats heading errors as
/// independent from step to step, so it understates the drift of a biased heading; the
/// 5-state EKF of seed 002 that estimates θ̇ and v is the fusion module's.
///
/// # Range differences (`range_difference_sources`)
///
/// Seed 002 observes `Δr_t = r_t − r_{t−1} + δ₃`, the increment against the previous
/// estimate. The error of a TPS-CFO range difference is not white from epoch to epoch but
/// the receiver oscillator's phase wander plus the integrated multipath Doppler
/// ([`crate::dtmb::tps`]), so the filter carries it: the state is `[x, y, e, ė]`, the
/// cumulative Δr is the measurement ([`RangeDifferenceModel`]) and between batches
///
/// ```text
/// e ← e + ė Δt,   Q_e = c² Q_clock(h₀, h₋₂, Δt) + diag(q_mp² Δt, 0)
/// ```
///
/// (Brown & Hwang's two-state clock noise of the configured h₀, h₋₂; `q_mp` is
/// `range_difference_multipath_m_per_sqrt_s`). The first range difference anchors
/// `r₀ = ‖p̂ − p_b‖ − Δr`, and e starts at 0 with the position's uncertainty along the line
/// of sight, `var e = uᵀ P u`, `cov(p, e) = −P u`, and ė with the static calibration's
/// (`c² (h₀/(2T) + 2π² h₋₂ T/3)`, T = `range_difference_calibration_s`). Without range differences e and ė stay
/// uncorrelated with the position and the filter is the 2-state one.
pub struct PdrEstimator {
    name: String,
    cfg: PdrFilterConfig,
    frame: EnuFrame,
    systems: Vec<System>,
    start_sigma_m: f64,
    pos_en_m: Option<Vector2<f64>>,
    up_m: f64,
    /// `[e, ė]` of the range differences.
    rd: Vector2<f64>,
    /// Covariance of `[x, y, e, ė]`.
    p: Matrix4<f64>,
    anchor: Option<Anchor>,
    last_t: Option<GpsTime>,
    /// Time of the last step and the walking velocity of that step (east, north m/s).
    last_step: Option<(GpsTime, Vector2<f64>)>,
    scratch: Vec<RangeMeasurement>,
    fixes: Vec<Fix>,
    latest: Option<Estimate>,
}

impl PdrEstimator {
    /// Dead reckoning in the world frame from `cfg.start_enu_m`, else `known_start_enu_m`
    /// (the world's surveyed start, e.g. its trajectory's first point), else the first fix.
    /// From GNSS batches it uses the `systems` (all when empty).
    ///
    /// # Errors
    /// A [`ConfigIssue`] for a bad setting.
    pub fn new(
        name: &str,
        cfg: &PdrFilterConfig,
        systems: &[System],
        frame: &EnuFrame,
        known_start_enu_m: Option<Vector3<f64>>,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let start = cfg
            .start_enu_m
            .as_ref()
            .map(|s| Vector3::new(s[0], s[1], s.get(2).copied().unwrap_or(0.0)))
            .or(known_start_enu_m.filter(|s| s.iter().all(|v| v.is_finite())));
        let start_sigma_m = cfg.start_sigma_m;
        let mut p = Matrix4::zeros();
        p.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&(Matrix2::identity() * start_sigma_m * start_sigma_m));
        Ok(Self {
            name: name.to_string(),
            cfg: cfg.clone(),
            frame: frame.clone(),
            systems: systems.to_vec(),
            start_sigma_m,
            pos_en_m: start.map(|s| s.xy()),
            up_m: start.map_or(0.0, |s| s.z),
            rd: Vector2::zeros(),
            p,
            anchor: None,
            last_t: None,
            last_step: None,
            scratch: Vec::with_capacity(64),
            fixes: Vec::with_capacity(4),
            latest: None,
        })
    }

    /// The dead-reckoned position (east, north m), once started.
    pub fn position_en_m(&self) -> Option<Vector2<f64>> {
        self.pos_en_m
    }

    /// The horizontal covariance (m²).
    pub fn covariance_m2(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The range-difference error states `[e, ė]` (m, m/s), once anchored.
    pub fn range_difference_error(&self) -> Option<Vector2<f64>> {
        self.anchor.map(|_| self.rd)
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        let pos = self.pos_en_m?;
        let mut cov = Matrix3::zeros();
        cov.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&self.covariance_m2());
        cov[(2, 2)] = self.start_sigma_m * self.start_sigma_m;
        Some(Estimate {
            t,
            pos_ecef_m: self
                .frame
                .ecef_of_enu(&Vector3::new(pos.x, pos.y, self.up_m)),
            vel_ecef_mps: None,
            cov_pos_m2: ecef_cov(&self.frame, &cov),
        })
    }

    /// Moves `[e, ė]` to time `t` (only once anchored: before, they are not in use).
    fn propagate_rd(&mut self, t: GpsTime) {
        let last = self.last_t.replace(t);
        let (Some(last), Some(_)) = (last, self.anchor) else {
            return;
        };
        let dt = t.seconds_since(last);
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        // Brown & Hwang's two-state clock noise, S_b = h₀/2, S_d = 2π² h₋₂, in metres.
        let c2 = crate::core::C_MPS * crate::core::C_MPS;
        let sb = self.cfg.range_difference_h0_s / 2.0 * c2;
        let sd = 2.0 * std::f64::consts::PI.powi(2) * self.cfg.range_difference_h_minus2_hz * c2;
        let qc = Matrix2::new(
            sb * dt + sd * dt.powi(3) / 3.0,
            sd * dt * dt / 2.0,
            sd * dt * dt / 2.0,
            sd * dt,
        );
        let mut phi = Matrix4::identity();
        phi[(2, 3)] = dt;
        let mut p = phi * self.p * phi.transpose();
        let block = p.fixed_view::<2, 2>(2, 2) + qc;
        p.fixed_view_mut::<2, 2>(2, 2).copy_from(&block);
        p[(2, 2)] += self.cfg.range_difference_multipath_m_per_sqrt_s.powi(2) * dt;
        self.rd.x += self.rd.y * dt;
        self.p = 0.5 * (p + p.transpose());
    }

    /// One step at `t`; false when it cannot be used (non-finite, negative length, no
    /// start yet).
    fn step(&mut self, s: &StepEvent, t: GpsTime) -> bool {
        let Some(pos) = self.pos_en_m else {
            return false;
        };
        let ok = [
            s.length_m,
            s.sigma_length_m,
            s.heading_rad,
            s.sigma_heading_rad,
        ]
        .iter()
        .all(|v| v.is_finite())
            && s.length_m >= 0.0
            && s.length_m < 10.0;
        if !ok {
            return false;
        }
        let (sn, cs) = s.heading_rad.sin_cos();
        let l = s.length_m;
        let new_pos = pos + Vector2::new(sn, cs) * l;
        let j = Matrix2::new(sn, l * cs, cs, -l * sn);
        let q = Matrix2::new(
            s.sigma_length_m * s.sigma_length_m,
            0.0,
            0.0,
            s.sigma_heading_rad * s.sigma_heading_rad,
        );
        let new_pp = self.p.fixed_view::<2, 2>(0, 0) + j * q * j.transpose();
        if new_pos.iter().chain(new_pp.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(new_pos);
            self.p.fixed_view_mut::<2, 2>(0, 0).copy_from(&new_pp);
            // The walking velocity of this step, for range differences between steps.
            let vel = match self.last_step {
                Some((t_prev, _)) => {
                    let dt = t.seconds_since(t_prev);
                    if dt > 0.1 && dt < 2.0 {
                        Vector2::new(sn, cs) * (l / dt)
                    } else {
                        Vector2::zeros()
                    }
                }
                None => Vector2::zeros(),
            };
            self.last_step = Some((t, vel));
            true
        } else {
            false
        }
    }

    /// A horizontal position fix: initialises, or updates with H = [I₂ 0]. Returns (used,
    /// numerical failure).
    fn fix(&mut self, f: &Fix) -> PdrUpdate {
        let z = f.pos_enu_m.xy();
        let r: Matrix2<f64> = f.pos_cov_m2.fixed_view::<2, 2>(0, 0).into_owned();
        let Some(pos) = self.pos_en_m else {
            if r.cholesky().is_none() {
                return PdrUpdate::Refused;
            }
            self.pos_en_m = Some(z);
            self.up_m = f.pos_enu_m.z;
            self.p = Matrix4::zeros();
            self.p.fixed_view_mut::<2, 2>(0, 0).copy_from(&r);
            self.anchor = None;
            self.rd = Vector2::zeros();
            return PdrUpdate::Anchored;
        };
        let s = self.p.fixed_view::<2, 2>(0, 0) + r;
        let Some(chol) = s.cholesky() else {
            return PdrUpdate::Refused;
        };
        let innov = z - pos;
        let nis = innov.dot(&chol.solve(&innov));
        if self.cfg.nis_gate.is_some_and(|g| nis > g) {
            return PdrUpdate::Gated;
        }
        // K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ, Joseph form.
        let hp: SMatrix<f64, 2, 4> = self.p.fixed_rows::<2>(0).into_owned();
        let k = chol.solve(&hp).transpose();
        let mut h = SMatrix::<f64, 2, 4>::zeros();
        h.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&Matrix2::identity());
        let ikh = Matrix4::identity() - k * h;
        let new_p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        let dx = k * innov;
        let new_pos = pos + dx.fixed_rows::<2>(0);
        if new_pos.iter().chain(new_p.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(new_pos);
            self.rd += dx.fixed_rows::<2>(2);
            self.p = 0.5 * (new_p + new_p.transpose());
            PdrUpdate::Used { nis, dof: 2 }
        } else {
            PdrUpdate::Failed
        }
    }

    /// A range difference: anchors on the first, then a scalar Joseph update. Returns
    /// (used, numerical failure).
    fn range_difference(&mut self, m: &RangeDifference, t: GpsTime) -> PdrUpdate {
        let Some(pos) = self.pos_en_m else {
            return PdrUpdate::Refused;
        };
        let offset = match self.last_step {
            Some((ts, v)) => {
                let dt = t.seconds_since(ts);
                if (0.0..2.0).contains(&dt) {
                    v * dt
                } else {
                    Vector2::zeros()
                }
            }
            None => Vector2::zeros(),
        };
        let pos_now = pos + offset;
        let sigma = m.sigma_m.hypot(self.cfg.range_difference_sigma_floor_m);
        if !(m.delta_range_m.is_finite() && m.sigma_m.is_finite() && m.sigma_m > 0.0)
            || m.emitter_pos_ecef_m.iter().any(|v| !v.is_finite())
        {
            return PdrUpdate::Refused;
        }
        let tower = self.frame.enu_of_ecef(&m.emitter_pos_ecef_m);
        let anchor = match self.anchor {
            Some(a) if a.emitter == m.emitter => a,
            Some(_) => return PdrUpdate::Refused,
            None => {
                let d = Vector3::new(pos_now.x, pos_now.y, self.up_m) - tower;
                let n = d.norm();
                if n.is_nan() || n <= 1.0 {
                    return PdrUpdate::Refused;
                }
                let u = Vector2::new(d.x / n, d.y / n);
                let pp: Matrix2<f64> = self.p.fixed_view::<2, 2>(0, 0).into_owned();
                let pu = pp * u;
                let (h0, hm2) = (
                    self.cfg.range_difference_h0_s,
                    self.cfg.range_difference_h_minus2_hz,
                );
                let t_cal = self.cfg.range_difference_calibration_s;
                let var_rate = crate::core::C_MPS.powi(2)
                    * (h0 / (2.0 * t_cal) + 2.0 * std::f64::consts::PI.powi(2) * hm2 * t_cal / 3.0);
                self.rd = Vector2::zeros();
                let mut p = Matrix4::zeros();
                p.fixed_view_mut::<2, 2>(0, 0).copy_from(&pp);
                p[(0, 2)] = -pu.x;
                p[(1, 2)] = -pu.y;
                p[(2, 0)] = -pu.x;
                p[(2, 1)] = -pu.y;
                p[(2, 2)] = u.dot(&pu) + sigma * sigma;
                p[(3, 3)] = var_rate;
                self.p = p;
                let a = Anchor {
                    emitter: m.emitter,
                    tower_enu_m: tower,
                    r0_m: n - m.delta_range_m,
                };
                self.anchor = Some(a);
                return PdrUpdate::Anchored;
            }
        };
        let model = RangeDifferenceModel {
            tower_enu_m: anchor.tower_enu_m,
            up_m: self.up_m,
            r0_m: anchor.r0_m,
            offset_en_m: offset,
            sigma_m: sigma,
        };
        let x = SVector::<f64, 4>::new(pos.x, pos.y, self.rd.x, self.rd.y);
        let h = model.jacobian(&x);
        let nu = m.delta_range_m - model.h(&x)[0];
        let ph = self.p * h.transpose();
        let s = (h * ph)[(0, 0)] + sigma * sigma;
        if !(s.is_finite() && s > 0.0) {
            return PdrUpdate::Failed;
        }
        let k = ph / s;
        let ikh = Matrix4::identity() - k * h;
        let new_p = ikh * self.p * ikh.transpose() + k * k.transpose() * (sigma * sigma);
        let dx = k * nu;
        if dx.iter().chain(new_p.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(pos + dx.fixed_rows::<2>(0));
            self.rd += dx.fixed_rows::<2>(2);
            self.p = 0.5 * (new_p + new_p.transpose());
            PdrUpdate::Used {
                nis: nu * nu / s,
                dof: 1,
            }
        } else {
            PdrUpdate::Failed
        }
    }
}

/// Adds one update's NIS of `dof` components to the epoch's record, outside the
/// divergence watch's χ² test (`EpochOutcome::nis_unwatched`).
fn tally_unwatched_nis(out: &mut EpochOutcome, nis: f64, dof: u32) {
    if dof > 0 && out.record_nis(nis, dof) {
        out.nis_unwatched = true;
    }
}

/// What the PDR filter did with one fix or range difference.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PdrUpdate {
    /// A Kalman update with its normalised innovation squared and dimension.
    Used { nis: f64, dof: u32 },
    /// The measurement started the filter (the first fix) or its range-difference anchor.
    Anchored,
    /// The innovation gate refused it as an outlier.
    Gated,
    /// Invalid input, or no filter state to update yet.
    Refused,
    /// The update produced a non-finite state or covariance, which was not kept.
    Failed,
}

impl PdrUpdate {
    /// Tallies `n` measurements (a fix counts the ranges it came from) into `out`.
    fn tally(self, n: u32, out: &mut EpochOutcome) {
        match self {
            PdrUpdate::Used { nis, dof } => {
                out.used += n;
                out.record_nis(nis, dof);
            }
            PdrUpdate::Anchored => out.used += n,
            PdrUpdate::Gated => {
                out.rejected += n;
                out.rejected_gate += n;
            }
            PdrUpdate::Refused => out.rejected += n,
            PdrUpdate::Failed => {
                out.rejected += n;
                out.numerical_failure = true;
            }
        }
    }
}

impl Estimator for PdrEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        source == SourceKind::Pdr
            || self.cfg.fix_sources.contains(&source)
            || self.cfg.range_difference_sources.contains(&source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        if !self.cfg.range_difference_sources.is_empty() {
            self.propagate_rd(batch.t);
        }
        if batch.source == SourceKind::Pdr {
            for m in &batch.items {
                if let Measurement::Step(s) = m {
                    if self.step(s, batch.t) {
                        out.used += 1;
                    } else {
                        out.rejected += 1;
                    }
                }
            }
        } else if self.cfg.range_difference_sources.contains(&batch.source) {
            for m in &batch.items {
                if let Measurement::RangeDifference(rd) = m {
                    self.range_difference(rd, batch.t).tally(1, &mut out);
                }
            }
        }
        if self.cfg.fix_sources.contains(&batch.source) {
            let near = self.latest.map(|e| e.pos_ecef_m);
            let mut fixes = std::mem::take(&mut self.fixes);
            fixes_of_batch(
                batch,
                0.0,
                &self.frame,
                &self.systems,
                false,
                near,
                &mut self.scratch,
                &mut fixes,
                &mut out.rejected,
                &mut out.gdop,
            );
            for f in &fixes {
                self.fix(f).tally(f.n, &mut out);
            }
            self.fixes = fixes;
        }
        self.latest = self.estimate(batch.t);
        out.estimate = self.latest;
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.latest
    }

    /// Dead reckoning restarts from the next fix, with the start's uncertainty.
    fn reset(&mut self) {
        self.pos_en_m = None;
        self.p = Matrix4::zeros();
        self.p
            .fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&(Matrix2::identity() * self.start_sigma_m * self.start_sigma_m));
        self.anchor = None;
        self.rd = Vector2::zeros();
        self.last_step = None;
        self.latest = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, Geodetic};
    use crate::measurement::PositionFix;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::from_deg(30.55, 114.27, 25.0))
    }

    #[test]
    fn velocity_from_exact_rates_is_exact() {
        // Six emitters around and above the receiver with arbitrary velocities; rates from
        // the model with a drift of 3 m/s recover the velocity to rounding.
        let f = frame();
        let rx = f.ecef_of_enu(&Vector3::new(10.0, 20.0, 5.0));
        let v = Vector3::new(3.0, -7.0, 0.5);
        let drift = 3.0;
        let dirs: [(f64, f64); 6] = [
            (0.3, 1.2),
            (1.5, 0.4),
            (2.8, 0.9),
            (4.0, 0.2),
            (5.2, 1.0),
            (0.0, 1.5),
        ];
        let ranges: Vec<RangeMeasurement> = dirs
            .iter()
            .enumerate()
            .map(|(i, &(az, el))| {
                let d_enu = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
                let e = rx + f.ecef_vector_of_enu(&(d_enu * 2.0e7));
                let ve = Vector3::new(1000.0 * i as f64, -2000.0, 500.0);
                let u = (rx - e).normalize();
                RangeMeasurement {
                    emitter: EmitterId {
                        system: System::Gps,
                        number: i as u16 + 1,
                    },
                    emitter_pos_ecef_m: e,
                    emitter_vel_ecef_mps: ve,
                    pseudorange_m: (rx - e).norm(),
                    sigma_m: 3.0,
                    range_rate_mps: Some(u.dot(&(v - ve)) + drift),
                    sigma_rate_mps: 0.1,
                    cn0_dbhz: 45.0,
                    elevation_rad: el,
                }
            })
            .collect();
        let (est, cov, n) = velocity_from_rates(&ranges, &rx).unwrap();
        assert_eq!(n, 6);
        assert!((est - v).norm() < 1e-6, "{est}");
        assert!(cov[(0, 0)] > 0.0 && cov[(0, 0)].sqrt() < 1.0);
        assert!(velocity_from_rates(&ranges[..3], &rx).is_none());
    }

    /// A batch of IMU samples from `k0` (100 Hz) with a constant specific force.
    fn imu_batch(start: GpsTime, k0: u64, n: u64, accel: Vector3<f64>) -> MeasurementBatch {
        let t = |k: u64| k as f64 * 0.01;
        MeasurementBatch {
            unscored: false,
            raw: None,
            t: start.add_seconds(t(k0 + n - 1)),
            source: SourceKind::Imu,
            items: (k0..k0 + n)
                .map(|k| {
                    Measurement::Imu(ImuSample {
                        t_s: t(k),
                        gyro_rps: Vector3::zeros(),
                        accel_mps2: accel,
                    })
                })
                .collect(),
        }
    }

    #[test]
    fn ins_initialises_from_fixes_and_resets_on_a_numerical_failure() {
        // A level body gliding east at 2 m/s (specific force = gravity), position fixes
        // every second: the INS initialises from the quadratic fit, heading east. Then a
        // sample with an absurd (finite) specific force overflows the state: the epoch
        // reports a numerical failure and no estimate, never NaN, and later fixes
        // re-initialise the filter.
        let f = frame();
        let start = GpsTime::from_week_tow(2300, 0.0);
        let cfg = InsFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            ..Default::default()
        };
        let mut ins =
            InsEstimator::new("INS", &cfg, &ImuConfig::default(), &[], &f, start).unwrap();
        let g = local_earth_of(&f).gravity_mps2(0.0);
        let level = Vector3::new(0.0, 0.0, g);
        // A fix at the time of IMU sample `k`.
        let fix_at = |k: u64| MeasurementBatch {
            unscored: false,
            raw: None,
            t: start.add_seconds(k as f64 * 0.01),
            source: SourceKind::Fm,
            items: vec![Measurement::Position(PositionFix {
                pos_ecef_m: f.ecef_of_enu(&Vector3::new(0.02 * k as f64, 0.0, 0.0)),
                cov_m2: Matrix3::identity() * 0.01,
                support: 0,
            })],
        };
        let mut k = 0;
        let mut sec = 0;
        while ins.filter().is_none() && sec < 20 {
            ins.process(&imu_batch(start, k, 100, level));
            k += 100;
            let o = ins.process(&fix_at(k - 1));
            assert!(!o.numerical_failure);
            sec += 1;
        }
        assert!(ins.filter().is_some(), "not initialised after {sec} s");
        let h = crate::inertial::heading_of_attitude(&ins.filter().unwrap().state().q_nb);
        assert!(
            (h - std::f64::consts::FRAC_PI_2).abs() < 0.01,
            "heading {h}"
        );
        let o = ins.process(&imu_batch(start, k, 1, Vector3::new(1e300, 0.0, 0.0)));
        k += 1;
        assert!(o.numerical_failure && o.estimate.is_none() && ins.latest().is_none());
        assert_eq!(ins.resets(), 1);
        // NaN samples are rejected, not failures.
        let mut nan = imu_batch(start, k, 1, level);
        if let Measurement::Imu(s) = &mut nan.items[0] {
            s.accel_mps2.x = f64::NAN;
        }
        let o = ins.process(&nan);
        assert!(!o.numerical_failure && o.rejected == 1);
        k += 1;
        let restart = sec;
        while ins.filter().is_none() && sec < restart + 20 {
            ins.process(&imu_batch(start, k, 100, level));
            k += 100;
            ins.process(&fix_at(k - 1));
            sec += 1;
        }
        assert!(ins.filter().is_some());
        let e = ins.latest().unwrap();
        assert!(e.pos_ecef_m.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn quadratic_fit_is_exact_on_a_parabola() {
        // p(τ) = p₀ + v τ + ½ a τ² sampled at τ = −4 … 0 s: the fit returns v and a; its
        // variances are those of the unweighted LS with σ² = 2 (closed form for 5 equispaced
        // points: var(v) = σ² · 31/35 · … checked against the normal-matrix inverse).
        let v = Vector3::new(3.0, -1.0, 0.2);
        let a = Vector3::new(0.5, 1.5, 0.0);
        let p0 = Vector3::new(10.0, 20.0, 1.0);
        let pts = (0..5).map(|i| {
            let tau = -(i as f64);
            (tau, p0 + v * tau + a * (0.5 * tau * tau), 2.0)
        });
        let (ve, ae, var_v, var_a) = quadratic_fit(pts, 1.0).unwrap();
        assert!((ve - v).norm() < 1e-9 && (ae - a).norm() < 1e-9);
        // Independent: invert HᵀH for H rows [1, τ, τ²/2] by hand-built 3×3 and compare.
        let mut hth = Matrix3::zeros();
        for i in 0..5 {
            let tau = -(i as f64);
            let h = Vector3::new(1.0, tau, 0.5 * tau * tau);
            hth += h * h.transpose();
        }
        let inv = hth.try_inverse().unwrap() * 2.0;
        assert!((var_v - inv[(1, 1)]).abs() < 1e-9 && (var_a - inv[(2, 2)]).abs() < 1e-9);
        // Too short a span or too few points: no fit.
        let few = (0..2).map(|i| (-(i as f64), p0, 1.0));
        assert!(quadratic_fit(few, 1.0).is_none());
    }

    #[test]
    fn triad_recovers_an_attitude() {
        use crate::inertial::attitude::attitude_from_euler;
        // A phone pitched 30° up and rolled 5°, heading 70°, walking along its heading.
        let q = attitude_from_euler(70f64.to_radians(), 30f64.to_radians(), 0.0);
        let f_n = Vector3::new(0.3, -0.2, 9.8);
        let f_b = q.inverse() * f_n;
        let v = Vector3::new(70f64.to_radians().sin(), 70f64.to_radians().cos(), 0.0) * 1.2;
        let est = triad(&f_b, &f_n, &v).unwrap();
        // Specific force matched exactly; forward axis in the vertical plane of v.
        assert!((est * f_b - f_n).norm() < 1e-9);
        let fwd = est * Vector3::x();
        assert!((fwd.x.atan2(fwd.y) - 70f64.to_radians()).abs() < 0.05);
        assert!(triad(&Vector3::x(), &f_n, &v).is_none());
    }

    #[test]
    fn pdr_steps_a_square_and_a_fix_pulls_it() {
        let f = frame();
        let cfg = PdrFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            ..Default::default()
        };
        let mut est =
            PdrEstimator::new("PDR", &cfg, &[], &f, Some(Vector3::new(1.0, 2.0, 0.0))).unwrap();
        let mut batch = MeasurementBatch {
            unscored: false,
            raw: None,
            source: SourceKind::Pdr,
            ..Default::default()
        };
        // Four sides of 10 steps of 0.5 m: back to the start.
        for side in 0..4 {
            for _ in 0..10 {
                batch.items = vec![Measurement::Step(StepEvent {
                    length_m: 0.5,
                    sigma_length_m: 0.05,
                    heading_rad: side as f64 * std::f64::consts::FRAC_PI_2,
                    sigma_heading_rad: 0.05,
                })];
                let o = est.process(&batch);
                assert_eq!(o.used, 1);
            }
        }
        let p = est.position_en_m().unwrap();
        assert!((p - Vector2::new(1.0, 2.0)).norm() < 1e-9, "{p}");
        // Covariance: start 0.25 m² per axis + Σ over steps of σ_L² along and (L σ_ψ)²
        // across the step: each axis gets 20 along-track and 20 cross-track terms.
        let expect = 0.25 + 20.0 * 0.05f64.powi(2) + 20.0 * (0.5f64 * 0.05).powi(2);
        assert!((est.covariance_m2()[(0, 0)] - expect).abs() < 1e-12);
        // A fix 4 m east with σ² equal to P: the estimate moves halfway.
        let fix_enu = Vector3::new(5.0, 2.0, 0.0);
        let pe = est.covariance_m2()[(0, 0)];
        let mut cov = Matrix3::identity() * pe;
        cov[(2, 2)] = 1.0;
        let b = MeasurementBatch {
            unscored: false,
            raw: None,
            source: SourceKind::Fm,
            items: vec![Measurement::Position(PositionFix {
                pos_ecef_m: f.ecef_of_enu(&fix_enu),
                cov_m2: ecef_cov(&f, &cov),
                support: 0,
            })],
            ..Default::default()
        };
        let o = est.process(&b);
        assert_eq!((o.used, o.rejected), (1, 0));
        let p = est.position_en_m().unwrap();
        assert!((p - Vector2::new(3.0, 2.0)).norm() < 1e-6, "{p}");
        // Bad steps are rejected, never NaN.
        batch.items = vec![Measurement::Step(StepEvent {
            length_m: f64::NAN,
            sigma_length_m: 0.05,
            heading_rad: 0.0,
            sigma_heading_rad: 0.05,
        })];
        let o = est.process(&batch);
        assert_eq!(o.rejected, 1);
        assert!(o.estimate.unwrap().pos_ecef_m.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn range_difference_jacobian_matches_finite_differences() {
        let m = RangeDifferenceModel {
            tower_enu_m: Vector3::new(600.0, -160.0, 240.0),
            up_m: 1.2,
            r0_m: 688.2,
            offset_en_m: Vector2::new(0.3, -0.1),
            sigma_m: 0.05,
        };
        for x in [
            SVector::<f64, 4>::new(0.0, 0.0, 0.0, 0.0),
            SVector::<f64, 4>::new(36.0, 22.0, 1.3, -0.01),
            SVector::<f64, 4>::new(-10.0, 40.0, -2.0, 0.02),
        ] {
            let j = m.jacobian(&x);
            for i in 0..4 {
                let h = 1e-4;
                let mut a = x;
                let mut b = x;
                a[i] += h;
                b[i] -= h;
                let fd = (m.h(&a)[0] - m.h(&b)[0]) / (2.0 * h);
                assert!(
                    (fd - j[(0, i)]).abs() < 1e-8,
                    "∂h/∂x{i}: {fd} vs {}",
                    j[(0, i)]
                );
            }
        }
    }

    #[test]
    fn fusing_range_differences_reduces_the_error_against_the_truth() {
        // A walker heads north at 1 m/s (steps of 0.5 m every 0.5 s) for 120 s with a
        // heading error of 0.2 rad per step (the σ the filter is told), so the PDR drifts
        // across the track, east, along the line to a tower 600 m east. The range
        // differences carry the error of an OCXO-referenced receiver (the clock's phase
        // wander about its frequency at the start, Brown & Hwang's OCXO, the filter's
        // default model) plus 2 mm of white noise. Over 20 seeded walks the RMS horizontal
        // error against the truth must fall when they are fused.
        use crate::core::receiver_clock::{ClockConfig, ClockTrack, Oscillator, ReceiverClock};
        use rand_distr::{Distribution, Normal};
        let f = frame();
        let tower = Vector3::new(600.0, 0.0, 200.0);
        let start = GpsTime::from_week_tow(2300, 0.0);
        let p0 = Vector3::new(0.0, 0.0, 1.2);
        let (mut sum_without, mut sum_with, mut n) = (0.0, 0.0, 0usize);
        for seed in 0..20u64 {
            let rng = crate::core::TrialRng::new(seed, 0);
            let clock_cfg = ClockConfig {
                oscillator: Oscillator::Ocxo,
                ..ClockConfig::default()
            };
            let clock = ClockTrack::record(
                ReceiverClock::new(&clock_cfg, &mut rng.stream("clock")),
                130.0,
                0.1,
                &mut rng.stream("clock/track"),
            );
            let mut heading = rng.stream("heading");
            let mut white = rng.stream("white");
            let heading_err: Vec<f64> = (0..240)
                .map(|_| Normal::new(0.0, 0.2).unwrap().sample(&mut heading))
                .collect();
            for fuse in [false, true] {
                let cfg = PdrFilterConfig {
                    range_difference_sources: if fuse { vec![SourceKind::Dtmb] } else { vec![] },
                    ..Default::default()
                };
                let mut est = PdrEstimator::new("PDR", &cfg, &[], &f, Some(p0)).unwrap();
                let mut sq = 0.0;
                for k in 1..=240usize {
                    let t = k as f64 * 0.5;
                    let step = MeasurementBatch {
                        t: start.add_seconds(t),
                        source: SourceKind::Pdr,
                        items: vec![Measurement::Step(StepEvent {
                            length_m: 0.5,
                            sigma_length_m: 0.05,
                            heading_rad: heading_err[k - 1],
                            sigma_heading_rad: 0.2,
                        })],
                        ..Default::default()
                    };
                    est.process(&step);
                    if k % 2 != 0 {
                        continue;
                    }
                    let truth = Vector3::new(0.0, t, 1.2);
                    let r = (truth - tower).norm() - (p0 - tower).norm();
                    let osc = crate::core::C_MPS
                        * (clock.bias_s(t) - clock.bias_s(0.0) - clock.drift_s_per_s(0.0) * t);
                    let w: f64 = 0.002 * Normal::new(0.0, 1.0).unwrap().sample(&mut white);
                    let b = MeasurementBatch {
                        t: start.add_seconds(t),
                        source: SourceKind::Dtmb,
                        items: vec![Measurement::RangeDifference(RangeDifference {
                            emitter: crate::core::EmitterId {
                                system: System::Dtmb,
                                number: 1,
                            },
                            emitter_pos_ecef_m: f.ecef_of_enu(&tower),
                            t0: start,
                            delta_range_m: r + osc + w,
                            sigma_m: 0.002,
                        })],
                        ..Default::default()
                    };
                    let o = est.process(&b);
                    assert_eq!(o.used, u32::from(fuse));
                    let e = est.position_en_m().unwrap() - truth.xy();
                    sq += e.norm_squared();
                    if fuse {
                        n += 1;
                    }
                }
                if fuse {
                    sum_with += sq;
                } else {
                    sum_without += sq;
                }
            }
        }
        let (without, with) = (
            (sum_without / n as f64).sqrt(),
            (sum_with / n as f64).sqrt(),
        );
        println!("RMS horizontal error over 20 walks: PDR {without:.2} m, PDR + Δr {with:.2} m");
        assert!(without > 0.5, "{without}");
        assert!(with < 0.7 * without, "{with} vs {without}");
    }

    #[test]
    fn bad_filter_configs_are_named() {
        let e = toml::from_str::<InsFilterConfig>("fix_source = [\"gnss\"]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fix_source"), "{e}");
        let c: InsFilterConfig = toml::from_str("process_noise_scale = -1").unwrap();
        assert_eq!(c.validate().unwrap_err().key, "process_noise_scale");
        let c: InsFilterConfig = toml::from_str("fix_sources = [\"imu\"]").unwrap();
        assert_eq!(c.validate().unwrap_err().key, "fix_sources");
        let c: PdrFilterConfig = toml::from_str("start_enu_m = [1.0]").unwrap();
        assert_eq!(c.validate().unwrap_err().key, "start_enu_m");
        let imu = ImuConfig {
            rate_hz: 0.0,
            ..ImuConfig::default()
        };
        let e = InsEstimator::new(
            "INS",
            &InsFilterConfig::default(),
            &imu,
            &[],
            &frame(),
            GpsTime::from_ns(0),
        )
        .err()
        .unwrap();
        assert_eq!(e.key, "imu.rate_hz");
    }
}
