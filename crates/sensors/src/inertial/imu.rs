//! The IMU error model: what a real gyro triad and accelerometer triad report when the
//! true angular rate ω_ib^b and specific force f^b are given (from
//! [`crate::inertial::attitude::ideal_imu`]).
//!
//! # Model (per sensor triad, Groves 2013 §4.4, eqs. 4.16–4.19)
//!
//! ```text
//! ỹ = Q( sat( (I + S + M) y + b_on + b_GM(t) + b_RW(t) + w ) )
//! ```
//!
//! * `S = diag(s)`: scale-factor errors, each s ~ N(0, σ_s²), drawn once at switch-on.
//! * `M`: misalignment / cross-coupling, off-diagonal entries ~ N(0, σ_m²), drawn once.
//! * `b_on` ~ N(0, σ_on²): turn-on bias, constant for the run.
//! * `b_GM`: bias instability as a first-order Gauss–Markov process with correlation time
//!   T (default 100 s, facts §4 and gnss-ins-sim), started in its stationary distribution,
//!   `b_{k+1} = e^{−Δt/T} b_k + σ_GM √(1 − e^{−2Δt/T}) n_k`.
//! * `b_RW`: rate random walk (gyro) or acceleration random walk (accelerometer),
//!   `b_{k+1} = b_k + K √Δt n_k`, with K the Allan τ^{+1/2} coefficient (IEEE 952 Annex C).
//! * `w`: white noise of density N (ARW or VRW); per sample σ_w = N / √Δt, so that
//!   σ_Allan(τ) = N / √τ (IEEE 952 Annex C, Table C.1).
//! * `sat`: clipping at the full-scale range; `Q`: quantisation to the LSB with the
//!   remainder carried to the next sample, as delta-angle/delta-velocity outputs do, so the
//!   integrated output loses nothing.
//!
//! # Bias instability convention
//!
//! A datasheet's bias instability B is read here as the **floor of the Allan deviation**.
//! A first-order Gauss–Markov process of stationary standard deviation σ_GM and correlation
//! time T has the Allan variance
//!
//! ```text
//! σ_A²(τ) = σ_GM² (2x − 3 + 4e^{−x} − e^{−2x}) / x²,   x = τ/T,
//! ```
//!
//! whose maximum, 0.6174 σ_GM at τ = 1.893 T, is the flat part of the curve between the
//! white-noise slope and the random-walk slope. We therefore set
//! σ_GM = B / [`GM_ADEV_PEAK_FACTOR`], so that the Allan deviation around τ ≈ 1.9 T reads B.
//! (IEEE 952's flicker reading "floor = 0.664 B" belongs to a true 1/f process; we simulate
//! the Gauss–Markov process of facts §4 instead and calibrate its hump to the floor.)
//!
//! Units in the configuration are the datasheet units (°/√h, °/h, m/s/√h, m/s²); the
//! resolved [`ImuSpec`] is in SI.

use crate::core::{ConfigIssue, StreamRng};
use crate::measurement::ImuSample;
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// max_x √((2x − 3 + 4e^{−x} − e^{−2x}) / x²): the Allan deviation peak of a unit
/// Gauss–Markov process, reached at τ = 1.893 T.
pub const GM_ADEV_PEAK_FACTOR: f64 = 0.617_364;
/// τ / T at which the Gauss–Markov Allan deviation peaks.
pub const GM_ADEV_PEAK_TAU_OVER_T: f64 = 1.893;
/// The highest sample rate the model accepts (Hz).
pub const MAX_RATE_HZ: f64 = 1000.0;

const DEG: f64 = std::f64::consts::PI / 180.0;
const HOUR_S: f64 = 3600.0;

/// An IMU performance grade with the values of facts §4 (Aceinna gnss-ins-sim
/// `imu_model.py`), or `custom` to give all four values explicitly.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ImuGrade {
    /// Consumer MEMS (a phone): ARW 0.75 °/√h, BI 10 °/h, VRW 0.05 m/s/√h, accel BI 2e-4 m/s².
    #[default]
    Low,
    /// Industrial MEMS: 0.25 °/√h, 3.5 °/h, 0.03 m/s/√h, 5e-5 m/s².
    Mid,
    /// Navigation grade: 0.002 °/√h, 0.1 °/h, 2.5e-5 m/s/√h, 3.6e-6 m/s².
    High,
    /// No preset: the four noise values must all be given.
    Custom,
}

impl ImuGrade {
    /// (gyro ARW °/√h, gyro bias instability °/h, accel VRW m/s/√h, accel bias instability
    /// m/s²) of the grade, or `None` for `custom`.
    pub fn values(self) -> Option<[f64; 4]> {
        match self {
            ImuGrade::Low => Some([0.75, 10.0, 0.05, 2e-4]),
            ImuGrade::Mid => Some([0.25, 3.5, 0.03, 5e-5]),
            ImuGrade::High => Some([0.002, 0.1, 2.5e-5, 3.6e-6]),
            ImuGrade::Custom => None,
        }
    }
}

fn default_rate_hz() -> f64 {
    100.0
}
fn default_bias_corr_time_s() -> f64 {
    100.0
}
fn default_gyro_range() -> f64 {
    2000.0
}
fn default_accel_range() -> f64 {
    16.0 * STANDARD_GRAVITY
}
const STANDARD_GRAVITY: f64 = crate::inertial::STANDARD_GRAVITY_MPS2;

/// An IMU as a world file writes it (`[imu]`). Every field but `grade` has a default; the
/// four noise values default to the grade's and override it when given.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ImuConfig {
    /// Sample rate (Hz), in (0, 1000]; default 100.
    #[serde(default = "default_rate_hz")]
    pub rate_hz: f64,
    /// `low`, `mid`, `high` or `custom`; default `low`.
    #[serde(default)]
    pub grade: ImuGrade,
    /// Gyro angle random walk (°/√h); default from the grade.
    #[serde(default)]
    pub gyro_arw_deg_per_sqrt_h: Option<f64>,
    /// Gyro bias instability, the Allan floor (°/h); default from the grade.
    #[serde(default)]
    pub gyro_bias_instability_deg_per_h: Option<f64>,
    /// Accelerometer velocity random walk (m/s/√h); default from the grade.
    #[serde(default)]
    pub accel_vrw_mps_per_sqrt_h: Option<f64>,
    /// Accelerometer bias instability, the Allan floor (m/s²); default from the grade.
    #[serde(default)]
    pub accel_bias_instability_mps2: Option<f64>,
    /// Gauss–Markov correlation time of both bias instabilities (s); default 100.
    #[serde(default = "default_bias_corr_time_s")]
    pub bias_corr_time_s: f64,
    /// Gyro rate random walk K (°/h/√h); default 0.
    #[serde(default)]
    pub gyro_rrw_deg_per_h_per_sqrt_h: f64,
    /// Accelerometer random walk K (m/s²/√h); default 0.
    #[serde(default)]
    pub accel_rrw_mps2_per_sqrt_h: f64,
    /// σ of the gyro turn-on bias (°/h); default 0.
    #[serde(default)]
    pub gyro_turn_on_bias_deg_per_h: f64,
    /// σ of the accelerometer turn-on bias (m/s²); default 0.
    #[serde(default)]
    pub accel_turn_on_bias_mps2: f64,
    /// σ of the gyro scale-factor errors (ppm); default 0.
    #[serde(default)]
    pub gyro_scale_factor_ppm: f64,
    /// σ of the accelerometer scale-factor errors (ppm); default 0.
    #[serde(default)]
    pub accel_scale_factor_ppm: f64,
    /// σ of the gyro misalignment / cross-coupling terms (mrad); default 0.
    #[serde(default)]
    pub gyro_misalignment_mrad: f64,
    /// σ of the accelerometer misalignment / cross-coupling terms (mrad); default 0.
    #[serde(default)]
    pub accel_misalignment_mrad: f64,
    /// Gyro output LSB (rad/s); 0 (default) turns quantisation off.
    #[serde(default)]
    pub gyro_quantum_rad_per_s: f64,
    /// Accelerometer output LSB (m/s²); 0 (default) turns quantisation off.
    #[serde(default)]
    pub accel_quantum_mps2: f64,
    /// Gyro full-scale range (°/s); default 2000.
    #[serde(default = "default_gyro_range")]
    pub gyro_range_deg_per_s: f64,
    /// Accelerometer full-scale range (m/s²); default 16 g = 156.9.
    #[serde(default = "default_accel_range")]
    pub accel_range_mps2: f64,
}

impl Default for ImuConfig {
    fn default() -> Self {
        Self::grade(ImuGrade::Low)
    }
}

/// The resolved IMU, all in SI units, per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSpec {
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// Gyro angle random walk N (rad/√s).
    pub gyro_arw_rad_per_sqrt_s: f64,
    /// Gyro bias instability B, the Allan floor (rad/s).
    pub gyro_bias_instability_rps: f64,
    /// Accelerometer velocity random walk N (m/s/√s).
    pub accel_vrw_mps_per_sqrt_s: f64,
    /// Accelerometer bias instability B (m/s²).
    pub accel_bias_instability_mps2: f64,
    /// Gauss–Markov correlation time T (s).
    pub bias_corr_time_s: f64,
    /// Gyro rate random walk K (rad/s/√s).
    pub gyro_rrw_rps_per_sqrt_s: f64,
    /// Accelerometer random walk K (m/s²/√s).
    pub accel_rrw_mps2_per_sqrt_s: f64,
    /// σ of the gyro turn-on bias (rad/s).
    pub gyro_turn_on_bias_rps: f64,
    /// σ of the accelerometer turn-on bias (m/s²).
    pub accel_turn_on_bias_mps2: f64,
    /// σ of the gyro scale-factor errors (dimensionless).
    pub gyro_scale_factor: f64,
    /// σ of the accelerometer scale-factor errors (dimensionless).
    pub accel_scale_factor: f64,
    /// σ of the gyro misalignment terms (rad).
    pub gyro_misalignment_rad: f64,
    /// σ of the accelerometer misalignment terms (rad).
    pub accel_misalignment_rad: f64,
    /// Gyro LSB (rad/s), 0 = off.
    pub gyro_quantum_rps: f64,
    /// Accelerometer LSB (m/s²), 0 = off.
    pub accel_quantum_mps2: f64,
    /// Gyro range (rad/s).
    pub gyro_range_rps: f64,
    /// Accelerometer range (m/s²).
    pub accel_range_mps2: f64,
}

impl ImuSpec {
    /// The stationary σ of the gyro Gauss–Markov bias, B / 0.6174 (rad/s).
    pub fn gyro_gm_sigma_rps(&self) -> f64 {
        self.gyro_bias_instability_rps / GM_ADEV_PEAK_FACTOR
    }
    /// The stationary σ of the accelerometer Gauss–Markov bias (m/s²).
    pub fn accel_gm_sigma_mps2(&self) -> f64 {
        self.accel_bias_instability_mps2 / GM_ADEV_PEAK_FACTOR
    }
    /// The sample interval (s).
    pub fn dt_s(&self) -> f64 {
        1.0 / self.rate_hz
    }
}

fn check(
    key: &str,
    v: f64,
    lo: f64,
    hi: f64,
    open_lo: bool,
    what: &str,
) -> Result<f64, ConfigIssue> {
    let ok = v.is_finite() && v <= hi && if open_lo { v > lo } else { v >= lo };
    if ok {
        return Ok(v);
    }
    let why = if v.is_finite() && v < 0.0 && lo >= 0.0 {
        format!("expected {what}, a non-negative value up to {hi}, got {v} (noise densities and σ values cannot be negative)")
    } else {
        let b = if open_lo { "(" } else { "[" };
        format!("expected {what} within {b}{lo}, {hi}], got {v}")
    };
    Err(ConfigIssue::new(key, why))
}

impl ImuConfig {
    /// The configuration of a preset grade at 100 Hz with every other term at its default.
    pub fn grade(grade: ImuGrade) -> Self {
        Self {
            rate_hz: default_rate_hz(),
            grade,
            gyro_arw_deg_per_sqrt_h: None,
            gyro_bias_instability_deg_per_h: None,
            accel_vrw_mps_per_sqrt_h: None,
            accel_bias_instability_mps2: None,
            bias_corr_time_s: default_bias_corr_time_s(),
            gyro_rrw_deg_per_h_per_sqrt_h: 0.0,
            accel_rrw_mps2_per_sqrt_h: 0.0,
            gyro_turn_on_bias_deg_per_h: 0.0,
            accel_turn_on_bias_mps2: 0.0,
            gyro_scale_factor_ppm: 0.0,
            accel_scale_factor_ppm: 0.0,
            gyro_misalignment_mrad: 0.0,
            accel_misalignment_mrad: 0.0,
            gyro_quantum_rad_per_s: 0.0,
            accel_quantum_mps2: 0.0,
            gyro_range_deg_per_s: default_gyro_range(),
            accel_range_mps2: default_accel_range(),
        }
    }

    /// Checks every value; the first problem is returned with its key.
    ///
    /// # Errors
    /// A [`ConfigIssue`] for a rate outside (0, 1000] Hz, a negative or non-finite noise
    /// value, a `custom` grade with a missing noise value, or a non-positive range.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        self.resolve().map(|_| ())
    }

    /// Validates and converts to SI units.
    ///
    /// # Errors
    /// As [`ImuConfig::validate`].
    pub fn resolve(&self) -> Result<ImuSpec, ConfigIssue> {
        let rate_hz = self.rate_hz;
        if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= MAX_RATE_HZ) {
            return Err(ConfigIssue::new(
                "rate_hz",
                format!("expected a sample rate in Hz within (0, {MAX_RATE_HZ}], got {rate_hz}"),
            ));
        }
        let preset = self.grade.values();
        let pick = |key: &str, given: Option<f64>, i: usize| -> Result<f64, ConfigIssue> {
            match (given, preset) {
                (Some(v), _) => Ok(v),
                (None, Some(p)) => Ok(p[i]),
                (None, None) => Err(ConfigIssue::new(
                    key,
                    format!("grade = \"custom\" needs {key}; give it, or use grade \"low\", \"mid\" or \"high\""),
                )),
            }
        };
        let arw = check(
            "gyro_arw_deg_per_sqrt_h",
            pick("gyro_arw_deg_per_sqrt_h", self.gyro_arw_deg_per_sqrt_h, 0)?,
            0.0,
            1.0e4,
            false,
            "a gyro angle random walk in °/√h",
        )?;
        let gbi = check(
            "gyro_bias_instability_deg_per_h",
            pick(
                "gyro_bias_instability_deg_per_h",
                self.gyro_bias_instability_deg_per_h,
                1,
            )?,
            0.0,
            1.0e6,
            false,
            "a gyro bias instability in °/h",
        )?;
        let vrw = check(
            "accel_vrw_mps_per_sqrt_h",
            pick("accel_vrw_mps_per_sqrt_h", self.accel_vrw_mps_per_sqrt_h, 2)?,
            0.0,
            1.0e3,
            false,
            "an accelerometer velocity random walk in m/s/√h",
        )?;
        let abi = check(
            "accel_bias_instability_mps2",
            pick(
                "accel_bias_instability_mps2",
                self.accel_bias_instability_mps2,
                3,
            )?,
            0.0,
            10.0,
            false,
            "an accelerometer bias instability in m/s²",
        )?;
        let tau = check(
            "bias_corr_time_s",
            self.bias_corr_time_s,
            0.0,
            1.0e7,
            true,
            "a bias correlation time in s",
        )?;
        let grrw = check(
            "gyro_rrw_deg_per_h_per_sqrt_h",
            self.gyro_rrw_deg_per_h_per_sqrt_h,
            0.0,
            1.0e6,
            false,
            "a gyro rate random walk in °/h/√h",
        )?;
        let arrw = check(
            "accel_rrw_mps2_per_sqrt_h",
            self.accel_rrw_mps2_per_sqrt_h,
            0.0,
            1.0e3,
            false,
            "an accelerometer random walk in m/s²/√h",
        )?;
        let gon = check(
            "gyro_turn_on_bias_deg_per_h",
            self.gyro_turn_on_bias_deg_per_h,
            0.0,
            1.0e7,
            false,
            "a gyro turn-on bias σ in °/h",
        )?;
        let aon = check(
            "accel_turn_on_bias_mps2",
            self.accel_turn_on_bias_mps2,
            0.0,
            100.0,
            false,
            "an accelerometer turn-on bias σ in m/s²",
        )?;
        let gsf = check(
            "gyro_scale_factor_ppm",
            self.gyro_scale_factor_ppm,
            0.0,
            1.0e5,
            false,
            "a gyro scale-factor σ in ppm",
        )?;
        let asf = check(
            "accel_scale_factor_ppm",
            self.accel_scale_factor_ppm,
            0.0,
            1.0e5,
            false,
            "an accelerometer scale-factor σ in ppm",
        )?;
        let gma = check(
            "gyro_misalignment_mrad",
            self.gyro_misalignment_mrad,
            0.0,
            100.0,
            false,
            "a gyro misalignment σ in mrad",
        )?;
        let ama = check(
            "accel_misalignment_mrad",
            self.accel_misalignment_mrad,
            0.0,
            100.0,
            false,
            "an accelerometer misalignment σ in mrad",
        )?;
        let gq = check(
            "gyro_quantum_rad_per_s",
            self.gyro_quantum_rad_per_s,
            0.0,
            1.0,
            false,
            "a gyro LSB in rad/s",
        )?;
        let aq = check(
            "accel_quantum_mps2",
            self.accel_quantum_mps2,
            0.0,
            10.0,
            false,
            "an accelerometer LSB in m/s²",
        )?;
        let grange = check(
            "gyro_range_deg_per_s",
            self.gyro_range_deg_per_s,
            0.0,
            1.0e5,
            true,
            "a gyro full-scale range in °/s",
        )?;
        let arange = check(
            "accel_range_mps2",
            self.accel_range_mps2,
            0.0,
            1.0e5,
            true,
            "an accelerometer full-scale range in m/s²",
        )?;
        Ok(ImuSpec {
            rate_hz,
            gyro_arw_rad_per_sqrt_s: arw * DEG / 60.0,
            gyro_bias_instability_rps: gbi * DEG / HOUR_S,
            accel_vrw_mps_per_sqrt_s: vrw / 60.0,
            accel_bias_instability_mps2: abi,
            bias_corr_time_s: tau,
            gyro_rrw_rps_per_sqrt_s: grrw * DEG / HOUR_S / 60.0,
            accel_rrw_mps2_per_sqrt_s: arrw / 60.0,
            gyro_turn_on_bias_rps: gon * DEG / HOUR_S,
            accel_turn_on_bias_mps2: aon,
            gyro_scale_factor: gsf * 1e-6,
            accel_scale_factor: asf * 1e-6,
            gyro_misalignment_rad: gma * 1e-3,
            accel_misalignment_rad: ama * 1e-3,
            gyro_quantum_rps: gq,
            accel_quantum_mps2: aq,
            gyro_range_rps: grange * DEG,
            accel_range_mps2: arange,
        })
    }
}

/// One sensor triad's error state.
#[derive(Clone, Debug)]
struct Triad {
    /// I + S + M.
    gain: Matrix3<f64>,
    turn_on: Vector3<f64>,
    gm: Vector3<f64>,
    rw: Vector3<f64>,
    white_sigma: f64,
    gm_phi: f64,
    gm_drive: f64,
    rw_step: f64,
    quantum: f64,
    range: f64,
    residual: Vector3<f64>,
}

fn normal3(rng: &mut StreamRng) -> Vector3<f64> {
    Vector3::new(
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
    )
}

impl Triad {
    #[allow(clippy::too_many_arguments)]
    fn new(
        rng: &mut StreamRng,
        dt_s: f64,
        white_density: f64,
        gm_sigma: f64,
        tau_s: f64,
        rw_k: f64,
        turn_on_sigma: f64,
        scale_sigma: f64,
        mis_sigma: f64,
        quantum: f64,
        range: f64,
    ) -> Self {
        let s = normal3(rng) * scale_sigma;
        let mut gain = Matrix3::identity() + Matrix3::from_diagonal(&s);
        for i in 0..3 {
            for j in 0..3 {
                if i != j {
                    gain[(i, j)] += mis_sigma * rng.sample::<f64, _>(StandardNormal);
                }
            }
        }
        let turn_on = normal3(rng) * turn_on_sigma;
        // Start the Gauss–Markov bias in its stationary distribution so its statistics do not
        // depend on the run length.
        let gm = normal3(rng) * gm_sigma;
        let gm_phi = (-dt_s / tau_s).exp();
        Self {
            gain,
            turn_on,
            gm,
            rw: Vector3::zeros(),
            white_sigma: white_density / dt_s.sqrt(),
            gm_phi,
            gm_drive: gm_sigma * (1.0 - gm_phi * gm_phi).max(0.0).sqrt(),
            rw_step: rw_k * dt_s.sqrt(),
            quantum,
            range,
            residual: Vector3::zeros(),
        }
    }

    fn bias(&self) -> Vector3<f64> {
        self.turn_on + self.gm + self.rw
    }

    fn measure(&mut self, truth: &Vector3<f64>, rng: &mut StreamRng) -> Vector3<f64> {
        let mut y = self.gain * truth + self.bias() + normal3(rng) * self.white_sigma;
        for i in 0..3 {
            y[i] = y[i].clamp(-self.range, self.range);
        }
        if self.quantum > 0.0 {
            // Quantise with the remainder carried forward: the running sum of outputs stays
            // within one LSB of the running sum of inputs, as with delta-angle outputs.
            let want = y + self.residual;
            let q = want.map(|v| (v / self.quantum).round() * self.quantum);
            self.residual = want - q;
            y = q;
        }
        // Advance the processes to the next sample.
        self.gm = self.gm * self.gm_phi + normal3(rng) * self.gm_drive;
        if self.rw_step > 0.0 {
            self.rw += normal3(rng) * self.rw_step;
        }
        y
    }
}

/// A simulated IMU: feed it the true ω_ib^b and f^b at its sample times.
#[derive(Clone, Debug)]
pub struct Imu {
    spec: ImuSpec,
    rng: StreamRng,
    gyro: Triad,
    accel: Triad,
}

impl Imu {
    /// Switches the IMU on: draws the turn-on biases, scale factors, misalignments and the
    /// initial Gauss–Markov biases from `rng` (a named stream such as `"inertial/imu"`).
    pub fn new(spec: ImuSpec, mut rng: StreamRng) -> Self {
        let dt = spec.dt_s();
        let gyro = Triad::new(
            &mut rng,
            dt,
            spec.gyro_arw_rad_per_sqrt_s,
            spec.gyro_gm_sigma_rps(),
            spec.bias_corr_time_s,
            spec.gyro_rrw_rps_per_sqrt_s,
            spec.gyro_turn_on_bias_rps,
            spec.gyro_scale_factor,
            spec.gyro_misalignment_rad,
            spec.gyro_quantum_rps,
            spec.gyro_range_rps,
        );
        let accel = Triad::new(
            &mut rng,
            dt,
            spec.accel_vrw_mps_per_sqrt_s,
            spec.accel_gm_sigma_mps2(),
            spec.bias_corr_time_s,
            spec.accel_rrw_mps2_per_sqrt_s,
            spec.accel_turn_on_bias_mps2,
            spec.accel_scale_factor,
            spec.accel_misalignment_rad,
            spec.accel_quantum_mps2,
            spec.accel_range_mps2,
        );
        Self {
            spec,
            rng,
            gyro,
            accel,
        }
    }

    /// The resolved specification.
    pub fn spec(&self) -> &ImuSpec {
        &self.spec
    }

    /// One sample: the true angular rate ω_ib^b (rad/s) and specific force f^b (m/s²) at
    /// `t_s` in, the measured ones out. Calls are assumed to be 1/rate apart: each call
    /// advances the bias processes by one sample interval. Does not allocate.
    pub fn measure(
        &mut self,
        t_s: f64,
        omega_ib_b_rps: &Vector3<f64>,
        f_b_mps2: &Vector3<f64>,
    ) -> ImuSample {
        let gyro_rps = self.gyro.measure(omega_ib_b_rps, &mut self.rng);
        let accel_mps2 = self.accel.measure(f_b_mps2, &mut self.rng);
        ImuSample {
            t_s,
            gyro_rps,
            accel_mps2,
        }
    }

    /// The current total gyro bias (turn-on + Gauss–Markov + random walk), for tests (rad/s).
    pub fn gyro_bias_rps(&self) -> Vector3<f64> {
        self.gyro.bias()
    }

    /// The current total accelerometer bias (m/s²), for tests.
    pub fn accel_bias_mps2(&self) -> Vector3<f64> {
        self.accel.bias()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn gm_peak_factor_is_the_maximum() {
        let f = |x: f64| ((2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp()) / (x * x)).sqrt();
        let peak = f(GM_ADEV_PEAK_TAU_OVER_T);
        assert!((peak - GM_ADEV_PEAK_FACTOR).abs() < 1e-5, "{peak}");
        assert!(f(1.7) < peak && f(2.1) < peak);
    }

    #[test]
    fn grades_resolve_to_si() {
        let s = ImuConfig::grade(ImuGrade::Low).resolve().unwrap();
        assert!((s.gyro_arw_rad_per_sqrt_s - 0.75f64.to_radians() / 60.0).abs() < 1e-15);
        assert!((s.gyro_bias_instability_rps - 10f64.to_radians() / 3600.0).abs() < 1e-15);
        assert!((s.accel_vrw_mps_per_sqrt_s - 0.05 / 60.0).abs() < 1e-15);
        assert_eq!(s.accel_bias_instability_mps2, 2e-4);
        let mut c = ImuConfig::grade(ImuGrade::Custom);
        assert_eq!(c.validate().unwrap_err().key, "gyro_arw_deg_per_sqrt_h");
        c.gyro_arw_deg_per_sqrt_h = Some(1.0);
        c.gyro_bias_instability_deg_per_h = Some(1.0);
        c.accel_vrw_mps_per_sqrt_h = Some(1.0);
        assert_eq!(c.validate().unwrap_err().key, "accel_bias_instability_mps2");
        c.accel_bias_instability_mps2 = Some(1e-3);
        assert!(c.validate().is_ok());
    }

    #[test]
    fn quantisation_keeps_the_sum_and_saturation_clips() {
        let mut c = ImuConfig::grade(ImuGrade::Custom);
        c.gyro_arw_deg_per_sqrt_h = Some(0.0);
        c.gyro_bias_instability_deg_per_h = Some(0.0);
        c.accel_vrw_mps_per_sqrt_h = Some(0.0);
        c.accel_bias_instability_mps2 = Some(0.0);
        c.gyro_quantum_rad_per_s = 0.01;
        c.accel_range_mps2 = 20.0;
        let mut imu = Imu::new(c.resolve().unwrap(), TrialRng::new(1, 0).stream("t"));
        let w = Vector3::new(0.0123, -0.0049, 0.0);
        let mut sum = Vector3::zeros();
        for k in 0..1000 {
            let s = imu.measure(k as f64 * 0.01, &w, &Vector3::new(0.0, 30.0, -5.0));
            for i in 0..3 {
                let r = s.gyro_rps[i] / 0.01;
                assert!((r - r.round()).abs() < 1e-9);
            }
            assert_eq!(s.accel_mps2, Vector3::new(0.0, 20.0, -5.0));
            sum += s.gyro_rps;
        }
        assert!((sum - w * 1000.0).amax() <= 0.01 + 1e-9, "{sum}");
    }
}
