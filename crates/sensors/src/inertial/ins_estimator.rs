//! The loosely coupled INS as an estimator the engine drives ([`InsEstimator`], seed 004
//! §2.1–2.3): the strapdown mechanisation between fixes, GNSS and TC-OFDM position and
//! velocity fixes through the 15-state error-state filter (the built-in EKF or a member of
//! the Kalman family), initialisation from the fixes' velocity and accelerometer levelling.
//!
//! It works in the world's ENU frame (`EnuFrame`) and reports ECEF estimates. It never
//! panics on its input: a measurement it cannot use is counted as rejected, and a state
//! that stops being finite is reported as `numerical_failure` and the filter
//! re-initialises from the next fixes.

use super::imu::ImuConfig;
use super::ins_ekf::{InsEkf, InsEkfConfig};
use super::ins_family::{Cov6, InsFamilyFilter, InsKalmanConfig, InsKalmanKind};
use super::ins_tight::{InsTightEkf, TightClockConfig};
use super::source::local_earth_of;
use super::strapdown::NavState;
use super::{velocity_noise_var_enu, LocalEarth};
use crate::core::config::check_range;
use crate::core::stats::chi2;
use crate::core::{ConfigIssue, EnuFrame, GpsTime, System};
use crate::fusion::wls::{self, WlsOptions};
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, ImuSample, Measurement, MeasurementBatch, RangeMeasurement,
    SourceKind,
};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::fixes::{
    ecef_cov, enu_cov, fix_of_position, fixes_of_batch, tally_unwatched_nis, velocity_from_rates,
    Fix,
};

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
fn d_stf_max_fading() -> f64 {
    super::ins_family::DEFAULT_STF_MAX_FADING
}
fn d_forgetting() -> f64 {
    0.95
}
fn d_builtin() -> InsKalmanKind {
    InsKalmanKind::Builtin
}
/// A fix whose normalised innovation exceeds this cannot come from the motion the INS
/// has tracked: χ² of 3 or 6 degrees of freedom exceeds 100 with probability below
/// 10⁻¹⁹, and 10⁵ is a fix more than 316 σ away (1.9 km at a 6 m innovation σ) — a
/// receiver that teleported or a stream that jumped, not an outlier. The builtin filter
/// refuses such a fix and restarts from the fixes that follow, reporting the reset
/// (instead of absorbing kilometres into its velocity and attitude and coasting off).
const IMPLAUSIBLE_FIX_NIS: f64 = 1.0e5;

/// The longest interval between two fixes whose difference still gives a velocity (s).
const MAX_DIFFERENCE_INTERVAL_S: f64 = 2.0;

/// Fixes kept for the position-only initialisation.
const INIT_RING: usize = 16;

/// The position-only initialisation's quadratic fit is refused when its horizontal
/// residuals exceed this quantile of their χ² distribution (the 0.999 of the filters'
/// gates, e.g. `CHI2_3DOF_P999` in the family EKF).
const INIT_FIT_CONFIDENCE: f64 = 0.999;

/// A weighted least-squares fit of p(τ) = p₀ + v τ + ½ a τ² ([`quadratic_fit`]).
#[derive(Clone, Copy, Debug)]
struct QuadraticFit {
    /// Velocity and acceleration at τ = 0.
    v: Vector3<f64>,
    a: Vector3<f64>,
    /// Their variances, the same on every axis.
    var_v: f64,
    var_a: f64,
    /// The weighted residual sum of squares of the two horizontal axes,
    /// `Σᵢ (‖pᵢ − p̂(τᵢ)‖²_EN) / σᵢ²`, and its degrees of freedom `2 (n − 3)`: a χ² when the
    /// fixes' errors are as reported and the track is a parabola over the window.
    chi2_h: f64,
    dof_h: usize,
}

/// Weighted least-squares fit of p(τ) = p₀ + v τ + ½ a τ² to positions at times τ ≤ 0
/// relative to now (each with its variance), spanning at least `min_span_s`. Does not
/// allocate.
fn quadratic_fit(
    pts: impl Iterator<Item = (f64, Vector3<f64>, f64)>,
    min_span_s: f64,
) -> Option<QuadraticFit> {
    let mut n = Matrix3::<f64>::zeros();
    let mut rhs = Matrix3::<f64>::zeros();
    // Σ p²/σ² per axis: with the normal equations it gives the residual sum of squares
    // without a second pass, `Σ p²/σ² − x̂ᵀ N x̂` for each axis.
    let mut spp = Vector3::<f64>::zeros();
    let (mut count, mut earliest) = (0usize, 0.0f64);
    for (tau, p, var) in pts {
        if !(var.is_finite() && var > 0.0 && tau.is_finite()) {
            continue;
        }
        let h = Vector3::new(1.0, tau, 0.5 * tau * tau);
        n += h * h.transpose() / var;
        rhs += h * p.transpose() / var;
        spp += p.component_mul(&p) / var;
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
    let chi2_h = (0..2)
        .map(|axis| (spp[axis] - x.column(axis).dot(&rhs.column(axis))).max(0.0))
        .sum();
    (inv[(1, 1)] > 0.0 && inv[(2, 2)] > 0.0 && v.iter().chain(a.iter()).all(|e| e.is_finite()))
        .then_some(QuadraticFit {
            v,
            a,
            var_v: inv[(1, 1)],
            var_a: inv[(2, 2)],
            chi2_h,
            dof_h: 2 * (count - 3),
        })
}

/// How the INS takes its radio measurements.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum InsCoupling {
    /// Position (and velocity) fixes solved by least squares (seed 004's loose coupling).
    #[default]
    Loose,
    /// Each pseudorange and range rate updates the INS directly, with the receiver clock
    /// in the filter ([`InsTightEkf`]); fixes only initialise it.
    Tight,
}

/// `[estimator.ins]`: how the INS takes its fixes and initialises.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// 16) give the initial velocity and acceleration by a quadratic fit, used only when
    /// its horizontal residuals pass a χ² test at 0.999 against the fixes' σ (s); default 5.
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
    /// STF: the weakening factor β ≥ 1 (Zhou & Frank).
    #[serde(default = "d_noise_scale")]
    pub stf_weakening: f64,
    /// STF: the largest fading factor λ_max ≥ 1; default 10, the limit of the 12-state
    /// range STF (Zhou & Frank's factor has no upper limit).
    #[serde(default = "d_stf_max_fading")]
    pub stf_max_fading: f64,
    /// Pool the pseudoranges of every fix source at one epoch (e.g. `"gnss"` and
    /// `"tcofdm"` or `"dtmb"`) into one least-squares fix, seed 004's joint TC-OFDM/GNSS
    /// solution (eqs. 10–13; DTMB ranges on the GPS clock); default false (one fix per
    /// GNSS batch, TC-OFDM and DTMB ranges unused).
    #[serde(default)]
    pub joint_fix: bool,
    /// σ of what a fix velocity does not describe of the IMU's motion, `[horizontal,
    /// vertical]` (m/s), added in quadrature to the fix velocity's covariance (tightly
    /// coupled: to each range rate's variance, projected on its line of sight,
    /// [`InsTightEkf::with_velocity_noise`]); default `[0, 0]`. A walker's receiver reports the velocity of the walk, while a handheld
    /// or body-worn IMU also moves with the gait (`[platform.attitude]`'s bounce and
    /// surge: amplitudes B/ω₀ vertically and S/ω₀ forward, so σ = B/(√2 ω₀) ≈ 0.25 m/s
    /// and S/(√2 ω₀) ≈ 0.09 m/s for the default gait).
    #[serde(default)]
    pub fix_velocity_noise_mps: [f64; 2],
    /// `"loose"` (default): the fixes above update the 15-state filter. `"tight"`: once
    /// the filter has initialised from those fixes, every pseudorange (and, with
    /// `use_gnss_velocity`, range rate) of the fix sources updates it directly, with the
    /// receiver clock, its drift and the BeiDou inter-system bias as states, so that fewer
    /// than four ranges still correct it ([`InsTightEkf`]; with `kalman` one of seed 004's
    /// filters, that filter decides each scalar update, [`InsTightEkf::with_kalman`]).
    #[serde(default)]
    pub coupling: InsCoupling,
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
            stf_max_fading: d_stf_max_fading(),
            joint_fix: false,
            fix_velocity_noise_mps: [0.0, 0.0],
            coupling: InsCoupling::Loose,
        }
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
        check_range(
            "init_max_heading_sigma_deg",
            self.init_max_heading_sigma_deg,
            0.0,
            45.0,
            true,
            "a heading σ in degrees",
        )?;
        check_range(
            "init_tilt_sigma_deg",
            self.init_tilt_sigma_deg,
            0.0,
            45.0,
            true,
            "a tilt σ in degrees",
        )?;
        check_range(
            "process_noise_scale",
            self.process_noise_scale,
            0.0,
            1.0e3,
            true,
            "a noise scale",
        )?;
        if let Some(g) = self.nis_gate {
            check_range("nis_gate", g, 0.0, 1.0e6, true, "a χ² gate")?;
        }
        check_range(
            "max_fix_lag_s",
            self.max_fix_lag_s,
            0.0,
            60.0,
            true,
            "a time lag in s",
        )?;
        check_range(
            "init_window_s",
            self.init_window_s,
            0.0,
            60.0,
            true,
            "a time window in s",
        )?;
        if let Some(c) = self.residual_gate_c {
            check_range("residual_gate_c", c, 0.0, 1.0e3, true, "a gate factor C")?;
        }
        check_range(
            "aleph_threshold",
            self.aleph_threshold,
            0.0,
            1.0e3,
            true,
            "a coupling-degree threshold",
        )?;
        check_range(
            "stf_forgetting",
            self.stf_forgetting,
            0.0,
            1.0,
            true,
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
        if !(self.stf_max_fading.is_finite() && (1.0..=1.0e6).contains(&self.stf_max_fading)) {
            return Err(ConfigIssue::new(
                "stf_max_fading",
                format!(
                    "expected a largest fading factor λ_max within [1, 1e6], got {}",
                    self.stf_max_fading
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
            stf_max_fading: self.stf_max_fading,
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
///   the window) whose horizontal residuals pass the χ² test at 0.999 (`2 (n − 3)` degrees
///   of freedom; a window with a fix far off its reported σ waits for the next);
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
/// With `joint_fix`, the pseudoranges of every fix source at one epoch (GNSS, DTMB and
/// TC-OFDM) are pooled into one weighted least-squares fix with one clock per system
/// (seed 004 eqs. 10–13 write one clock; the simulated receiver has inter-system biases)
/// except DTMB, whose towers are taken to be on GPS time and share the GPS clock (seed
/// 000's single clock for GPS and DTMB, §5.1; a tower with its own clock would only
/// determine that clock), solved when every fix source has reported at that time or when
/// a later batch arrives.
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

/// Counts one scalar update of the tight filter: used with its NIS (watched, as the EKF
/// rows' are), gated, or rejected; `Ok(None)` is a measurement without a range rate.
fn tally_scalar(
    out: &mut EpochOutcome,
    r: Result<Option<super::ins_ekf::FixOutcome>, super::ins_ekf::InsFixError>,
) {
    match r {
        Ok(Some(o)) if o.accepted => {
            out.used += 1;
            out.record_nis(o.nis, 1);
        }
        Ok(Some(o)) => {
            out.rejected += 1;
            out.rejected_gate += 1;
            out.rejected_gate_state_led += u32::from(o.state_led);
        }
        Ok(None) => {}
        Err(_) => out.rejected += 1,
    }
}

/// The error-state filter an [`InsEstimator`] runs.
enum InsCore {
    Builtin(Box<InsEkf>),
    Family(Box<InsFamilyFilter>),
    Tight(Box<InsTightEkf>),
}

impl InsCore {
    fn state(&self) -> &NavState {
        match self {
            InsCore::Builtin(k) => k.state(),
            InsCore::Family(k) => k.state(),
            InsCore::Tight(k) => k.state(),
        }
    }

    /// The position covariance now (ENU m²).
    fn position_covariance_m2(&self) -> Matrix3<f64> {
        match self {
            InsCore::Builtin(k) => k.covariance().fixed_view::<3, 3>(0, 0).into_owned(),
            InsCore::Family(k) => k.position_covariance_m2(),
            InsCore::Tight(k) => k.position_covariance_m2(),
        }
    }

    /// Whether every variance is finite, non-negative and below 10¹⁵.
    fn variances_ok(&self) -> bool {
        let ok = |v: f64| v.is_finite() && (0.0..1e15).contains(&v);
        match self {
            InsCore::Builtin(k) => k.covariance().diagonal().iter().all(|v| ok(*v)),
            InsCore::Family(k) => k.covariance().diagonal().iter().all(|v| ok(*v)),
            InsCore::Tight(k) => k.covariance().diagonal().iter().all(|v| ok(*v)),
        }
    }

    fn propagate(&mut self, s: &ImuSample) {
        match self {
            InsCore::Builtin(k) => k.propagate(s),
            InsCore::Family(k) => k.propagate(s),
            InsCore::Tight(k) => k.propagate(s),
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
        // The user's gate, and never looser than the implausible-jump bound.
        ekf_cfg.nis_gate = Some(
            cfg.nis_gate
                .map_or(IMPLAUSIBLE_FIX_NIS, |g| g.min(IMPLAUSIBLE_FIX_NIS)),
        );
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
            InsCore::Family(_) | InsCore::Tight(_) => None,
        }
    }

    /// The generic filter (`kalman = "ekf"`, `"ckf"`, `"stf"`, `"rekf"`), once initialised.
    pub fn family_filter(&self) -> Option<&InsFamilyFilter> {
        match self.kf.as_ref()? {
            InsCore::Builtin(_) | InsCore::Tight(_) => None,
            InsCore::Family(k) => Some(k),
        }
    }

    /// The tightly coupled filter (`coupling = "tight"`), once initialised.
    pub fn tight_filter(&self) -> Option<&InsTightEkf> {
        match self.kf.as_ref()? {
            InsCore::Tight(k) => Some(k),
            _ => None,
        }
    }

    /// The navigation solution, once initialised (whatever the filter).
    pub fn nav_state(&self) -> Option<&NavState> {
        self.kf.as_ref().map(InsCore::state)
    }

    /// The error model the filter runs: the IMU's noise densities and bias σ scaled by
    /// `process_noise_scale`, and the fix gate (the initial σ are set at initialisation
    /// from the fixes, see the type's documentation).
    pub fn error_model(&self) -> &InsEkfConfig {
        &self.ekf_cfg
    }

    /// The `[estimator.ins]` settings.
    pub fn config(&self) -> &InsFilterConfig {
        &self.cfg
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
        let pos = kf.position_covariance_m2();
        st.pos_enu_m.iter().all(|v| v.is_finite())
            && st.vel_enu_mps.iter().all(|v| v.is_finite())
            && st.q_nb.coords.iter().all(|v| v.is_finite())
            && kf.variances_ok()
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
                out.inputs += 1;
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
            InsCore::Tight(kf) => match kf.update_position(&pos, &fix.pos_cov_m2) {
                Ok(o) if o.accepted => {
                    out.used += fix.n;
                    out.record_nis(o.nis, 3);
                }
                Ok(o) if o.nis > IMPLAUSIBLE_FIX_NIS => {
                    out.rejected += fix.n;
                    self.reset(out);
                }
                _ => out.rejected += fix.n,
            },
            InsCore::Builtin(kf) => {
                let extra = Matrix3::from_diagonal(&velocity_noise_var_enu(
                    self.cfg.fix_velocity_noise_mps,
                ));
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
                    Ok(o) if o.nis > IMPLAUSIBLE_FIX_NIS => {
                        out.rejected += fix.n;
                        self.reset(out);
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
                let var = velocity_noise_var_enu(self.cfg.fix_velocity_noise_mps);
                for i in 0..3 {
                    r[(3 + i, 3 + i)] += var[i];
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
                        matches!(reason, crate::fusion::ekf11::RejectReason::Gate { .. })
                    }
                };
                if gated {
                    out.rejected_gate += rep.rejected;
                    out.rejected_gate_state_led += rep.rejected_state_led;
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
                let Some(fit) = quadratic_fit(pts, 0.2 * window) else {
                    return;
                };
                // A window whose fixes the parabola does not describe within their
                // reported σ (an NLOS fix metres off) gives a velocity and acceleration
                // wrong by more than their variances say: wait for one it describes,
                // tested at the 0.999 quantile as the filters' gates are. (A smooth corner
                // within the window still fits; the unit test shows both.)
                if fit.dof_h > 0
                    && fit.chi2_h > chi2::quantile(INIT_FIT_CONFIDENCE, fit.dof_h as f64)
                {
                    return;
                }
                (
                    fit.v,
                    Matrix3::identity() * fit.var_v,
                    fit.a,
                    fit.var_a.sqrt(),
                )
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
            _ if self.cfg.coupling == InsCoupling::Tight => {
                match InsTightEkf::new(init, self.earth, &c, &TightClockConfig::default())
                    .with_velocity_noise(self.cfg.fix_velocity_noise_mps)
                    .with_kalman(&self.cfg.kalman_config())
                {
                    Ok(k) => InsCore::Tight(Box::new(k)),
                    Err(_) => return,
                }
            }
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

    /// `coupling = "tight"`, once initialised: every range (and range rate) of the batch
    /// from the estimator's systems updates the filter, and position items are fixes.
    fn tight_batch(&mut self, batch: &MeasurementBatch, out: &mut EpochOutcome) {
        let t_s = batch.t.seconds_since(self.start);
        let Some(InsCore::Tight(kf)) = &mut self.kf else {
            return;
        };
        let lag = t_s - kf.state().t_s;
        if lag.is_nan() || lag.abs() > self.cfg.max_fix_lag_s {
            out.rejected += batch.items.len() as u32;
            return;
        }
        let systems = &self.systems;
        // The strong tracking filter's one fading factor of the epoch, from all of its
        // scalars at the prediction (a no-op for the other filters).
        kf.stf_inflate(
            batch
                .ranges()
                .filter(|m| systems.is_empty() || systems.contains(&m.system())),
            &self.frame,
            lag,
            self.cfg.use_gnss_velocity,
        );
        for m in batch
            .ranges()
            .filter(|m| systems.is_empty() || systems.contains(&m.system()))
        {
            tally_scalar(out, kf.update_range(m, &self.frame, lag).map(Some));
            if self.cfg.use_gnss_velocity {
                tally_scalar(out, kf.update_range_rate(m, &self.frame, lag));
            }
        }
        self.apply_position_items(batch, t_s, out);
    }

    /// Applies the batch's position items (a fix source such as "fm") as fixes of their
    /// own; one with a non-finite value is rejected.
    fn apply_position_items(&mut self, batch: &MeasurementBatch, t_s: f64, out: &mut EpochOutcome) {
        for m in &batch.items {
            if let Measurement::Position(p) = m {
                match fix_of_position(&self.frame, t_s, p) {
                    Some(f) => self.apply_fix(&f, out),
                    None => out.rejected += 1,
                }
            }
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
        // DTMB ranges share the GPS clock, as in seed 000's filter: a tower on a clock of
        // its own would have its one range absorbed by that clock and add nothing.
        let opts = WlsOptions {
            initial_pos_ecef_m: self.latest.map(|e| e.pos_ecef_m),
            dtmb_on_gps_clock: true,
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
        self.apply_position_items(batch, t_s, out);
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
            if matches!(self.kf, Some(InsCore::Tight(_))) {
                self.tight_batch(batch, &mut out);
            } else if self.cfg.joint_fix {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, Geodetic};
    use crate::inertial::pdr_estimator::PdrFilterConfig;
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
    fn a_fix_that_jumps_kilometres_resets_the_ins_and_it_follows_the_new_fixes() {
        // The glide of the test below, initialised; then every fix moves 5 km north (a
        // stream that jumped). The first such fix is refused with a reported reset (NIS
        // far beyond IMPLAUSIBLE_FIX_NIS), and the filter restarts from the moved fixes:
        // its estimate ends within metres of them, never kilometres off.
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
        let fix_at = |k: u64, north_m: f64| MeasurementBatch {
            unscored: false,
            raw: None,
            t: start.add_seconds(k as f64 * 0.01),
            source: SourceKind::Fm,
            items: vec![Measurement::Position(PositionFix {
                pos_ecef_m: f.ecef_of_enu(&Vector3::new(0.02 * k as f64, north_m, 0.0)),
                cov_m2: Matrix3::identity() * 0.01,
                support: 0,
            })],
        };
        let mut k = 0;
        for _ in 0..20 {
            ins.process(&imu_batch(start, k, 100, level));
            k += 100;
            ins.process(&fix_at(k - 1, 0.0));
        }
        assert!(ins.filter().is_some(), "not initialised");
        let mut resets = 0;
        for _ in 0..20 {
            ins.process(&imu_batch(start, k, 100, level));
            k += 100;
            let o = ins.process(&fix_at(k - 1, 5000.0));
            resets += usize::from(o.numerical_failure);
        }
        assert_eq!((resets, ins.resets()), (1, 1));
        let e = ins.latest().expect("re-initialised from the moved fixes");
        let want = f.ecef_of_enu(&Vector3::new(0.02 * (k - 1) as f64, 5000.0, 0.0));
        let off_m = (e.pos_ecef_m - want).norm();
        assert!(off_m < 5.0, "{off_m} m from the moved fixes");
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
        let QuadraticFit {
            v: ve,
            a: ae,
            var_v,
            var_a,
            chi2_h,
            dof_h,
        } = quadratic_fit(pts, 1.0).unwrap();
        // Exact data: no residual, 2 (5 − 3) horizontal degrees of freedom.
        assert!(chi2_h < 1e-9 && dof_h == 4, "{chi2_h} {dof_h}");
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
    fn the_quadratic_fit_residual_is_the_two_pass_one_and_refuses_a_fix_off_its_sigma() {
        // Noisy fixes on a parabola: the one-pass residual equals the residuals recomputed
        // from the fitted p₀, v, a (p₀ by a second solve here), on the horizontal axes.
        let v = Vector3::new(1.2, 0.4, 0.0);
        let a = Vector3::new(0.1, -0.2, 0.0);
        let noise = [0.3, -0.5, 0.2, 0.6, -0.1, -0.4, 0.25];
        let pts: Vec<(f64, Vector3<f64>, f64)> = (0..7)
            .map(|i| {
                let tau = -(i as f64);
                let e = Vector3::new(noise[i], -noise[6 - i], 0.1 * noise[i]);
                (
                    tau,
                    Vector3::new(500.0, -300.0, 2.0) + v * tau + a * (0.5 * tau * tau) + e,
                    0.25,
                )
            })
            .collect();
        let fit = quadratic_fit(pts.iter().copied(), 1.0).unwrap();
        let mut hth = Matrix3::zeros();
        let mut hp = Matrix3::zeros();
        for (tau, p, _) in &pts {
            let h = Vector3::new(1.0, *tau, 0.5 * tau * tau);
            hth += h * h.transpose();
            hp += h * p.transpose();
        }
        let x = hth.try_inverse().unwrap() * hp;
        let two_pass: f64 = pts
            .iter()
            .map(|(tau, p, var)| {
                let h = Vector3::new(1.0, *tau, 0.5 * tau * tau);
                let r = p - x.transpose() * h;
                (r.x * r.x + r.y * r.y) / var
            })
            .sum();
        assert!(
            (fit.chi2_h - two_pass).abs() < 1e-6 * two_pass.max(1.0),
            "{} {two_pass}",
            fit.chi2_h
        );
        assert_eq!(fit.dof_h, 8);
        // A straight walk at 1.3 m/s with fixes of σ 0.3 m, one of them 4 m off (an NLOS
        // fix): refused at the 0.999 quantile, and accepted without that fix.
        let walk = |outlier_m: f64| {
            (0..6).map(move |i| {
                let tau = -(i as f64);
                let off = if i == 2 { outlier_m } else { 0.0 };
                (tau, Vector3::new(1.3 * tau, off, 0.0), 0.09)
            })
        };
        let limit = |fit: &QuadraticFit| chi2::quantile(INIT_FIT_CONFIDENCE, fit.dof_h as f64);
        let bad = quadratic_fit(walk(4.0), 1.0).unwrap();
        assert!(
            bad.chi2_h > limit(&bad),
            "{} over {} dof",
            bad.chi2_h,
            bad.dof_h
        );
        let good = quadratic_fit(walk(0.0), 1.0).unwrap();
        assert!(good.chi2_h < 1e-9);
        // What the test cannot see: a corner inside the window (east at 1.3 m/s, then
        // north) fits a parabola to within σ 0.3 m (χ² 4.6 over 6 dof), though the velocity
        // at its end is the parabola's, between the two legs.
        let corner = quadratic_fit(
            (0..6).map(|i| {
                let tau = -(i as f64);
                let p = if tau <= -2.0 {
                    Vector3::new(1.3 * (tau + 2.0), 0.0, 0.0)
                } else {
                    Vector3::new(0.0, 1.3 * (tau + 2.0), 0.0)
                };
                (tau, p, 0.09)
            }),
            1.0,
        )
        .unwrap();
        assert!(corner.chi2_h < limit(&corner));
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
