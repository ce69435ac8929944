//! The extended Kalman filter of seed 000 (Cong et al., "Robust Fusion of GPS, DTMB and FM
//! for Positioning", *Sensors* 18(10), 2018, §5, eqs. 4–19), with one optional extra state
//! for the BeiDou inter-system bias.
//!
//! # State (eq. 4, plus one inert state)
//!
//! ```text
//! x = [x, ẋ, ẍ, y, ẏ, ÿ, z, ż, z̈, b, ḃ, isb_bds]ᵀ
//! ```
//! Position, velocity and acceleration are ECEF (m, m/s, m/s²). The receiver clock bias
//! `b = c·δt` is kept in metres and its drift `ḃ = c·δf` in m/s, so that every state and
//! every measurement share one unit system. GPS, DTMB and TC-OFDM ranges share this clock:
//! the paper triggers the DTMB receiver from the GPS 1PPS and corrects its clock to the GPS
//! clock (§5.1), and TC-OFDM is treated the same way.
//!
//! The twelfth state `isb_bds` (m) is the BeiDou inter-system bias. Unless
//! [`Ekf11Config::isb_bds`] is set it is *inert*: zero initial variance, zero process
//! noise and a zero column in every measurement Jacobian, so the filter is exactly the
//! paper's 11-state filter and BeiDou ranges use the GPS clock `b`. When it is configured
//! it is a random walk observed by BeiDou pseudoranges, `h = ‖r_s − r‖ + b + isb_bds`.
//!
//! # Dynamics (eqs. 5–8)
//!
//! ```text
//! x_{k+1} = Φ x_k + ω_k,   Φ = diag(M, M, M, A_c, 1)
//! M   = [[1, T, T²/2], [0, 1, T], [0, 0, 1]]          A_c = [[1, T], [0, 1]]
//! Q_k = S_a,k [[T⁵/20, T⁴/8, T³/6], [T⁴/8, T³/3, T²/2], [T³/6, T²/2, T]]   (k = x, y, z)
//! Q_c = [[S_t T + S_f T³/3, S_f T²/2], [S_f T²/2, S_f T]]
//! Q_isb = S_isb T                                     (0 when the state is inert)
//! ```
//! Eq. 7 is the discretised white-jerk (constant-acceleration, "Singer with α → 0")
//! model, so `S_a` is the power spectral density of the jerk, in m²/s⁵.
//!
//! # Measurements (eqs. 9–19)
//!
//! With `u = (r_s − r)/‖r_s − r‖` the unit line of sight from the receiver to the emitter:
//! ```text
//! pseudorange  ρ = ‖r_s − r‖ + b (+ isb_bds for BDS) + ε        H: ∂ρ/∂r = −u, ∂ρ/∂b = 1
//! range rate   ρ̇ = u·(v_s − v) + ḃ + ε                          H: ∂ρ̇/∂v = −u, ∂ρ̇/∂ḃ = 1,
//!                                                                  ∂ρ̇/∂r = −(w − u(u·w))/‖r_s − r‖,
//!                                                                  w = v_s − v
//! position fix L = [x, y, z]ᵀ + ε_f,   ε_f ~ N(0, R_f)          H_f = [I₃ 0]  (eqs. 18–19)
//! ```
//! `−u` is the paper's `e = (r̂ − r_s)/r` of eqs. 10–12. The paper's eq. 16 writes the
//! range rate as `e·(v_s − v) + Δf`; differentiating eq. 9 gives `−e·(v_s − v) + Δf`
//! instead (the range shrinks when the receiver moves towards the emitter), which is the
//! sign used here and in [`crate::measurement::RangeMeasurement`]. Eq. 17 also drops
//! the position derivative of the range rate; it is kept here by default because it costs
//! nothing and is the exact Jacobian, and dropped with
//! [`Ekf11Config::rate_position_jacobian`] = false, as seed 000's `-eq17` presets do to
//! run the paper's filter as printed (the default seed 000 presets keep the exact one). For satellites it is the transverse velocity over the range, about
//! 3.9 km/s / 20 000 km ≈ 2·10⁻⁴ (m/s) per metre: small beside the ranges when four or
//! more satellites fix the position, but at a range-rate σ of a few cm/s each Doppler
//! then weighs like a ~150 m position observation, enough to hold a filter through a
//! two-satellite outage (Doppler positioning). For a nearby tower seen from a moving car
//! it is the correct linearisation.
//!
//! # Update
//!
//! Ranges and range rates are processed as sequential scalar updates (the measurement
//! noises are independent), each relinearised at the latest estimate, with no heap
//! allocation. The covariance update is the Joseph form
//! `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, evaluated in its expanded form
//! `P − K Cᵀ − C Kᵀ + K S Kᵀ` (with `C = P Hᵀ`, `S = H P Hᵀ + R`), which is the same
//! polynomial in `K` and so keeps the Joseph form's first-order insensitivity to errors in
//! the gain while costing O(n²) for a scalar measurement. For a scalar it is written
//! `P − (k eᵀ + e kᵀ)` with `e = c − (s/2) k`, four operations per entry, symmetric to the
//! last bit. Each update is checked: an innovation whose normalised square (NIS) exceeds
//! the gate is rejected, and an update that would write a non-finite or negative-variance
//! result is refused and leaves the filter unchanged.
//!
//! # Cost
//!
//! `P h` sums the four to seven columns of `P` that `h` selects; the prediction applies
//! the block-sparse Φ as column and row operations. The update is written in place: the
//! new variances are checked before anything is written, and a running bound on
//! `max |P_ij|` (exact after each prediction, raised by each update by the most it can add)
//! proves that no entry can overflow, so neither a copy of `P` nor a check of its 144
//! entries is needed; near the top of the floating-point range the update falls back to a
//! checked copy. The hot bodies are compiled a second time for AVX2 and chosen at run
//! time; they use no fused multiply–add, so both builds give the same bits (tested).

// The one kind of unsafe code hybridnav has: its AVX2 builds of the predict and scalar update, `#[target_feature]`
// functions called only after run-time CPU detection, each with a same-bits test against
// the portable code.
#![allow(unsafe_code)]

use crate::core::{System, C_MPS};
use crate::measurement::{PositionFix, RangeMeasurement};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// Number of states: the paper's 11 plus the BeiDou inter-system bias.
pub const N_STATES: usize = 12;

/// The state vector.
pub type StateVector = SVector<f64, N_STATES>;
/// The state covariance (and the transition and process-noise matrices).
pub type StateMatrix = SMatrix<f64, N_STATES, N_STATES>;

/// Indices of the states in [`StateVector`].
pub mod idx {
    /// ECEF position components x, y, z (m).
    pub const POS: [usize; 3] = [0, 3, 6];
    /// ECEF velocity components (m/s).
    pub const VEL: [usize; 3] = [1, 4, 7];
    /// ECEF acceleration components (m/s²).
    pub const ACC: [usize; 3] = [2, 5, 8];
    /// Receiver clock bias `c·δt` (m).
    pub const CLOCK_BIAS: usize = 9;
    /// Receiver clock drift `c·δf` (m/s).
    pub const CLOCK_DRIFT: usize = 10;
    /// BeiDou inter-system bias (m); inert unless configured.
    pub const ISB_BDS: usize = 11;
}

/// White-frequency-noise Allan coefficient `h₀` (s) of a typical TCXO, from Brown & Hwang,
/// *Introduction to Random Signals and Applied Kalman Filtering*, 4th ed., Table 9.2.
pub const TCXO_H0_S: f64 = 2e-19;
/// Random-walk-frequency-noise Allan coefficient `h₋₂` (1/s) of the same TCXO.
pub const TCXO_H_MINUS_2_PER_S: f64 = 2e-20;

/// χ²(1) quantile at 0.999: a scalar innovation is rejected 0.1 % of the time when the
/// filter is consistent.
pub const CHI2_1DOF_P999: f64 = 10.827_566_170_662_733;
/// χ²(3) quantile at 0.999, the matching gate for a 3-D position fix.
pub const CHI2_3DOF_P999: f64 = 16.266_236_196_238_13;

/// Clock-bias noise PSD `S_t` (m²/s) of eq. 8 from the Allan coefficient `h₀`.
///
/// Brown & Hwang (4th ed., §9.3) model the clock as two integrators driven by white
/// frequency noise of PSD `S_f = h₀/2` (s²/s) and white frequency-rate noise of PSD
/// `S_g = 2π²·h₋₂` (1/s); in the paper's notation those are `S_t` and `S_f`. The state
/// here is in metres, so both are scaled by `c²`: `S_t = c²·h₀/2`.
pub fn clock_bias_psd_m2ps(h0_s: f64) -> f64 {
    C_MPS * C_MPS * h0_s / 2.0
}

/// Clock-drift noise PSD `S_f` (m²/s³) of eq. 8 from `h₋₂`: `S_f = c²·2π²·h₋₂` (see
/// [`clock_bias_psd_m2ps`]).
pub fn clock_drift_psd_m2ps3(h_minus_2_per_s: f64) -> f64 {
    C_MPS * C_MPS * 2.0 * std::f64::consts::PI * std::f64::consts::PI * h_minus_2_per_s
}

/// Configuration of the BeiDou inter-system-bias state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct IsbConfig {
    /// 1-σ of the bias when the filter is initialised (m). Default 30 m (100 ns), the
    /// order of receiver hardware delays between GPS L1 and BDS B1I.
    pub initial_sigma_m: f64,
    /// Random-walk PSD of the bias (m²/s). Default 1e-4 m²/s (1 cm drift in a second,
    /// about 0.6 m in an hour), a bias that is nearly constant over a drive.
    pub psd_m2ps: f64,
}

impl Default for IsbConfig {
    fn default() -> Self {
        Self {
            initial_sigma_m: 30.0,
            psd_m2ps: 1e-4,
        }
    }
}

/// Tuning of [`Ekf11`]. Every field has a default, so a world file lists only what it
/// changes; unknown fields are an error, so a misspelt name does not silently fall back.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Ekf11Config {
    /// `S_a` of eq. 7 per ECEF axis x, y, z: PSD of the jerk (m²/s⁵). Default 1.0 on each
    /// axis, a car in town (acceleration changing by about 1 m/s² in a second).
    pub accel_psd_m2ps5: [f64; 3],
    /// `S_t` of eq. 8 (m²/s). Default `c²·h₀/2` for a TCXO (h₀ = 2e-19 s): 8.99e-3 m²/s.
    pub clock_bias_psd_m2ps: f64,
    /// `S_f` of eq. 8 (m²/s³). Default `c²·2π²·h₋₂` for a TCXO (h₋₂ = 2e-20 /s):
    /// 3.55e-2 m²/s³.
    pub clock_drift_psd_m2ps3: f64,
    /// The BeiDou inter-system bias state; `None` (the default) keeps it inert, making the
    /// filter the paper's 11-state filter with BeiDou on the GPS clock.
    pub isb_bds: Option<IsbConfig>,
    /// Gate on the normalised innovation squared of scalar updates (pseudoranges and range
    /// rates), a χ²(1) quantile. Default [`CHI2_1DOF_P999`] (10.83, 0.1 % false
    /// rejections). `None` (or `inf` in a TOML file) disables the gate.
    pub gate_chi2: Option<f64>,
    /// Gate on the NIS of 3-D position fixes, a χ²(3) quantile. Default
    /// [`CHI2_3DOF_P999`] (16.27).
    pub gate_chi2_position: Option<f64>,
    /// Initial 1-σ of each velocity component (m/s). Default 10 m/s.
    pub init_vel_sigma_mps: f64,
    /// Initial 1-σ of each acceleration component (m/s²). Default 1 m/s².
    pub init_acc_sigma_mps2: f64,
    /// Initial 1-σ of the clock drift (m/s). Default 300 m/s, a 1 ppm frequency offset.
    pub init_clock_drift_sigma_mps: f64,
    /// Whether the range-rate Jacobian keeps its position terms `∂ρ̇/∂r = −(w − u(u·w))/‖r_s −
    /// r‖` (default true, the exact linearisation). The paper's eq. 17 drops them, and seed
    /// 000's `-eq17` presets follow the paper (its default presets do not): through them a satellite's transverse velocity
    /// (≈ 3.9 km/s over 20 000 km, 2·10⁻⁴ (m/s) per metre) makes each Doppler a weak
    /// observation of position, which keeps a GPS-only filter bounded through a
    /// two-satellite outage that the paper's filter cannot coast through.
    pub rate_position_jacobian: bool,
}

impl Default for Ekf11Config {
    fn default() -> Self {
        Self {
            accel_psd_m2ps5: [1.0; 3],
            clock_bias_psd_m2ps: clock_bias_psd_m2ps(TCXO_H0_S),
            clock_drift_psd_m2ps3: clock_drift_psd_m2ps3(TCXO_H_MINUS_2_PER_S),
            isb_bds: None,
            gate_chi2: Some(CHI2_1DOF_P999),
            gate_chi2_position: Some(CHI2_3DOF_P999),
            init_vel_sigma_mps: 10.0,
            init_acc_sigma_mps2: 1.0,
            init_clock_drift_sigma_mps: 300.0,
            rate_position_jacobian: true,
        }
    }
}

impl Ekf11Config {
    /// The configuration an estimator on `systems` runs: when they mix BeiDou with another
    /// system and no inter-system-bias state is configured, one is switched on with its
    /// defaults (a receiver's BDS ranges carry a hardware and time-scale bias relative to
    /// GPS that a shared clock would turn into position error). Shared by `ekf11`, the
    /// filter family and their PCRLB ([`crate::fusion::pcrlb::PvaClockBound`]).
    pub fn for_systems(mut self, systems: &[System]) -> Self {
        if systems.contains(&System::Bds)
            && systems.iter().any(|s| *s != System::Bds)
            && self.isb_bds.is_none()
        {
            self.isb_bds = Some(IsbConfig::default());
        }
        self
    }

    /// Checks that every number is usable.
    ///
    /// # Errors
    /// [`Ekf11Error::InvalidConfig`] naming the first field that is negative or not finite.
    pub fn validate(&self) -> Result<(), Ekf11Error> {
        let non_negative = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(Ekf11Error::InvalidConfig(format!(
                    "{name} = {v}: expected a finite value ≥ 0"
                )))
            }
        };
        for (axis, &s) in ["x", "y", "z"].iter().zip(&self.accel_psd_m2ps5) {
            non_negative(&format!("accel_psd_m2ps5[{axis}]"), s)?;
        }
        non_negative("clock_bias_psd_m2ps", self.clock_bias_psd_m2ps)?;
        non_negative("clock_drift_psd_m2ps3", self.clock_drift_psd_m2ps3)?;
        non_negative("init_vel_sigma_mps", self.init_vel_sigma_mps)?;
        non_negative("init_acc_sigma_mps2", self.init_acc_sigma_mps2)?;
        non_negative(
            "init_clock_drift_sigma_mps",
            self.init_clock_drift_sigma_mps,
        )?;
        if let Some(isb) = &self.isb_bds {
            non_negative("isb_bds.initial_sigma_m", isb.initial_sigma_m)?;
            non_negative("isb_bds.psd_m2ps", isb.psd_m2ps)?;
        }
        for (name, gate) in [
            ("gate_chi2", self.gate_chi2),
            ("gate_chi2_position", self.gate_chi2_position),
        ] {
            if let Some(g) = gate {
                // An infinite gate is allowed: it is how a TOML file switches the gate off.
                if g.is_nan() || g <= 0.0 {
                    return Err(Ekf11Error::InvalidConfig(format!(
                        "{name} = {g}: expected a threshold > 0"
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Errors of the filter's non-update operations.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Ekf11Error {
    /// The configuration holds an unusable number.
    #[error("invalid EKF configuration: {0}")]
    InvalidConfig(String),
    /// `predict` was called before `initialise`.
    #[error("the EKF has not been initialised: call initialise() with a first position fix")]
    NotInitialised,
    /// The prediction interval is negative or not finite.
    #[error("invalid prediction interval {dt_s} s: expected a finite number of seconds ≥ 0")]
    InvalidInterval { dt_s: f64 },
    /// The initial position, clock or their sigmas are not finite (or a sigma is negative).
    #[error("invalid initial state: {0}")]
    InvalidInitialState(String),
    /// The prediction produced a non-finite state or covariance; the filter is unchanged.
    #[error(
        "the prediction produced a non-finite state or covariance; the filter was left unchanged"
    )]
    NumericalFailure,
}

/// Why an update was refused. A refused update leaves the filter exactly as it was.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RejectReason {
    /// The normalised innovation squared exceeded the configured gate (an outlier).
    ///
    /// `state_led` records where the innovation's variance `S = H P Hᵀ + R` came from:
    /// true when the filter's own share, `H P Hᵀ`, was at least the measurement's `R`
    /// (for a vector, compared by trace). Refusing such a measurement means trusting a
    /// state that is itself the less certain of the two, which is what a filter that has
    /// lost its track does; refusing a measurement noisier than the state is the gate
    /// removing an outlier. The divergence watch ([`hybridnav_core::engine::health`])
    /// counts only the former towards a persistently gated filter.
    Gate { state_led: bool },
    /// The measurement holds a NaN or infinite number.
    NonFiniteInput,
    /// The stated noise is zero, negative, or (for a fix) not a positive-definite matrix.
    InvalidNoise,
    /// The emitter sits on the receiver estimate, so the line of sight is undefined.
    DegenerateGeometry,
    /// The filter has not been initialised.
    NotInitialised,
    /// The update would have produced a non-finite or non-positive covariance.
    NumericalFailure,
}

/// The result of one update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum UpdateOutcome {
    /// The measurement was used; `nis` is its normalised innovation squared `νᵀS⁻¹ν`.
    Accepted { nis: f64 },
    /// The measurement was not used; `nis` is NaN when it could not be computed.
    Rejected { nis: f64, reason: RejectReason },
}

impl UpdateOutcome {
    /// True when the measurement was used.
    pub fn is_accepted(&self) -> bool {
        matches!(self, UpdateOutcome::Accepted { .. })
    }
    /// The normalised innovation squared (NaN when it could not be computed).
    pub fn nis(&self) -> f64 {
        match *self {
            UpdateOutcome::Accepted { nis } | UpdateOutcome::Rejected { nis, .. } => nis,
        }
    }
    /// The reason of a rejection.
    pub fn reject_reason(&self) -> Option<RejectReason> {
        match *self {
            UpdateOutcome::Accepted { .. } => None,
            UpdateOutcome::Rejected { reason, .. } => Some(reason),
        }
    }
    fn rejected(reason: RejectReason) -> Self {
        UpdateOutcome::Rejected {
            nis: f64::NAN,
            reason,
        }
    }
}

/// The results of the (up to) two scalar updates a [`RangeMeasurement`] makes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeUpdateOutcome {
    /// The pseudorange update.
    pub range: UpdateOutcome,
    /// The range-rate update, when the measurement carries a rate.
    pub rate: Option<UpdateOutcome>,
}

/// Seed 000's EKF (see the module documentation for the model).
#[derive(Clone, Debug)]
pub struct Ekf11 {
    cfg: Ekf11Config,
    x: StateVector,
    p: StateMatrix,
    /// An upper bound on `max |P_ij|`: exact after an initialisation, a prediction or a
    /// position fix, and raised by every scalar update by the most that update can add.
    /// While it stays below [`SAFE_ABS`] a scalar update cannot overflow, so it is
    /// written in place without a copy and without checking the 144 results.
    p_abs_bound: f64,
    initialised: bool,
}

/// Below this magnitude (far from `f64::MAX` ≈ 1.8e308) sums and products of a few
/// covariance entries cannot overflow.
const SAFE_ABS: f64 = 1e300;

impl Ekf11 {
    /// A filter with the given tuning, not yet initialised.
    ///
    /// # Errors
    /// [`Ekf11Error::InvalidConfig`] when a PSD, sigma or gate is unusable.
    pub fn new(cfg: Ekf11Config) -> Result<Self, Ekf11Error> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            x: StateVector::zeros(),
            p: StateMatrix::zeros(),
            p_abs_bound: 0.0,
            initialised: false,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Ekf11Config {
        &self.cfg
    }

    /// True when the inter-system-bias state is live (configured), false when inert.
    pub fn isb_active(&self) -> bool {
        self.cfg.isb_bds.is_some()
    }

    /// Sets the state to a first fix: position and clock bias as given, velocity,
    /// acceleration, drift and inter-system bias zero, with a diagonal covariance from the
    /// given sigmas and the configured initial sigmas of the other states.
    ///
    /// # Errors
    /// [`Ekf11Error::InvalidInitialState`] when a value is not finite or a sigma negative;
    /// the filter is then unchanged.
    pub fn initialise(
        &mut self,
        pos_ecef_m: Vector3<f64>,
        clock_bias_m: f64,
        pos_sigma_m: f64,
        clock_sigma_m: f64,
    ) -> Result<(), Ekf11Error> {
        if !(pos_ecef_m.iter().all(|v| v.is_finite()) && clock_bias_m.is_finite()) {
            return Err(Ekf11Error::InvalidInitialState(
                "position or clock bias is not finite".into(),
            ));
        }
        if !(pos_sigma_m.is_finite()
            && pos_sigma_m >= 0.0
            && clock_sigma_m.is_finite()
            && clock_sigma_m >= 0.0)
        {
            return Err(Ekf11Error::InvalidInitialState(format!(
                "sigmas ({pos_sigma_m} m, {clock_sigma_m} m) must be finite and ≥ 0"
            )));
        }
        let mut x = StateVector::zeros();
        let mut p = StateMatrix::zeros();
        for axis in 0..3 {
            x[idx::POS[axis]] = pos_ecef_m[axis];
            p[(idx::POS[axis], idx::POS[axis])] = pos_sigma_m * pos_sigma_m;
            p[(idx::VEL[axis], idx::VEL[axis])] = self.cfg.init_vel_sigma_mps.powi(2);
            p[(idx::ACC[axis], idx::ACC[axis])] = self.cfg.init_acc_sigma_mps2.powi(2);
        }
        x[idx::CLOCK_BIAS] = clock_bias_m;
        p[(idx::CLOCK_BIAS, idx::CLOCK_BIAS)] = clock_sigma_m * clock_sigma_m;
        p[(idx::CLOCK_DRIFT, idx::CLOCK_DRIFT)] = self.cfg.init_clock_drift_sigma_mps.powi(2);
        if let Some(isb) = &self.cfg.isb_bds {
            p[(idx::ISB_BDS, idx::ISB_BDS)] = isb.initial_sigma_m.powi(2);
        }
        self.x = x;
        self.p = p;
        self.p_abs_bound = max_abs(&self.p);
        self.initialised = true;
        Ok(())
    }

    /// Replaces the whole state and covariance, for callers that initialise from a
    /// snapshot solution with a full covariance (and for tests).
    ///
    /// # Errors
    /// [`Ekf11Error::InvalidInitialState`] when a value is not finite, the covariance is
    /// not symmetric or has a negative variance, or the inert ISB state is given variance.
    pub fn set_state(&mut self, x: StateVector, p: StateMatrix) -> Result<(), Ekf11Error> {
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            return Err(Ekf11Error::InvalidInitialState(
                "state or covariance is not finite".into(),
            ));
        }
        let scale = p.diagonal().amax().max(f64::MIN_POSITIVE);
        if (p - p.transpose()).amax() > 1e-12 * scale || p.diagonal().iter().any(|&v| v < 0.0) {
            return Err(Ekf11Error::InvalidInitialState(
                "covariance must be symmetric with non-negative variances".into(),
            ));
        }
        if !self.isb_active()
            && (x[idx::ISB_BDS] != 0.0 || p.row(idx::ISB_BDS).iter().any(|&v| v != 0.0))
        {
            return Err(Ekf11Error::InvalidInitialState(
                "the BeiDou ISB state is inert (not configured) and must stay zero".into(),
            ));
        }
        self.x = x;
        self.p = p;
        self.p_abs_bound = max_abs(&self.p);
        self.initialised = true;
        Ok(())
    }

    /// True once `initialise` (or `set_state`) has been called.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// The state transition matrix Φ of eq. 5 for an interval `dt_s`; the ISB state is a
    /// random walk (its entry is 1).
    pub fn transition(dt_s: f64) -> StateMatrix {
        let t = dt_s;
        let mut phi = StateMatrix::identity();
        for axis in 0..3 {
            let (p, v, a) = (idx::POS[axis], idx::VEL[axis], idx::ACC[axis]);
            phi[(p, v)] = t;
            phi[(p, a)] = 0.5 * t * t;
            phi[(v, a)] = t;
        }
        phi[(idx::CLOCK_BIAS, idx::CLOCK_DRIFT)] = t;
        phi
    }

    /// The process-noise covariance Q of eqs. 6–8 for an interval `dt_s`, plus `S_isb·T`
    /// on the ISB state when it is configured.
    pub fn process_noise(cfg: &Ekf11Config, dt_s: f64) -> StateMatrix {
        let blocks = NoiseBlocks::new(cfg, dt_s);
        let mut q = StateMatrix::zeros();
        blocks.add_to(&mut q.data.0);
        q
    }

    /// Propagates the state by `dt_s` seconds: `x ← Φx`, `P ← ΦPΦᵀ + Q` (eq. 5).
    ///
    /// # Errors
    /// [`Ekf11Error::NotInitialised`], [`Ekf11Error::InvalidInterval`] for a negative or
    /// non-finite interval, [`Ekf11Error::NumericalFailure`] when the result would not be
    /// finite; in every case the filter is unchanged.
    pub fn predict(&mut self, dt_s: f64) -> Result<(), Ekf11Error> {
        if !self.initialised {
            return Err(Ekf11Error::NotInitialised);
        }
        if !(dt_s.is_finite() && dt_s >= 0.0) {
            return Err(Ekf11Error::InvalidInterval { dt_s });
        }
        if dt_s == 0.0 {
            return Ok(());
        }
        #[cfg(target_arch = "x86_64")]
        {
            if use_avx2() {
                // SAFETY: the CPU supports AVX2, checked by `use_avx2`.
                return unsafe { self.predict_avx2(dt_s) };
            }
        }
        self.predict_body(dt_s)
    }

    /// [`Ekf11::predict_body`] compiled for AVX2; bit-identical results, as for
    /// [`Ekf11::scalar_update_avx2`].
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn predict_avx2(&mut self, dt_s: f64) -> Result<(), Ekf11Error> {
        self.predict_body(dt_s)
    }

    #[inline(always)]
    fn predict_body(&mut self, dt_s: f64) -> Result<(), Ekf11Error> {
        // Φ is the identity plus seven entries (three 3×3 blocks M and the 2×2 clock block
        // A_c), so Φx and ΦPΦᵀ are applied as row and column operations, O(n) and O(n²),
        // rather than as dense products, O(n³). P Φᵀ replaces each position column by
        // itself plus T times the velocity column and T²/2 times the acceleration column
        // (contiguous in column-major storage); Φ (P Φᵀ) does the same to the rows.
        let mut x = self.x;
        apply_transition_rows(&mut x, dt_s);
        let mut p = self.p.data.0;
        apply_transition_columns(&mut p, dt_s);
        apply_transition_rows_cm(&mut p, dt_s);
        NoiseBlocks::new(&self.cfg, dt_s).add_to(&mut p);
        // Φ P Φᵀ summed rows-then-columns differs from columns-then-rows in the last bit;
        // the mean of the two triangles is the symmetric matrix closest to both.
        symmetrise_cm(&mut p);
        // One pass gives both the finiteness check (v·0 is NaN exactly when v is not
        // finite) and the exact bound the scalar updates start from.
        let (mut not_finite, mut bound) = (0.0, 0.0_f64);
        for col in &p {
            for &v in col {
                not_finite += v * 0.0;
                // A comparison rather than `f64::max`, whose NaN rule keeps it from
                // vectorising; a NaN is caught by `not_finite` instead.
                let a = v.abs();
                bound = if a > bound { a } else { bound };
            }
        }
        if !(not_finite == 0.0 && x.iter().all(|v| v.is_finite())) {
            return Err(Ekf11Error::NumericalFailure);
        }
        self.x = x;
        self.p.data.0 = p;
        self.p_abs_bound = bound;
        Ok(())
    }

    /// Uses one range measurement: the pseudorange, then (if present) the range rate as a
    /// second scalar update linearised at the state the first left. The two are gated
    /// independently, so a code-phase outlier does not discard a good Doppler.
    pub fn update_range(&mut self, m: &RangeMeasurement) -> RangeUpdateOutcome {
        let range = self.update_pseudorange(m);
        let rate = m.range_rate_mps.map(|_| self.update_range_rate(m));
        RangeUpdateOutcome { range, rate }
    }

    /// The pseudorange update (eqs. 9–15): `h = ‖r_s − r‖ + b (+ isb for BDS)`,
    /// `H = [−u at the position states, 1 at b (and at isb for BDS when it is live)]`.
    pub fn update_pseudorange(&mut self, m: &RangeMeasurement) -> UpdateOutcome {
        if !self.initialised {
            return UpdateOutcome::rejected(RejectReason::NotInitialised);
        }
        if !(m.pseudorange_m.is_finite() && m.emitter_pos_ecef_m.iter().all(|v| v.is_finite())) {
            return UpdateOutcome::rejected(RejectReason::NonFiniteInput);
        }
        if !(m.sigma_m.is_finite() && m.sigma_m > 0.0) {
            return UpdateOutcome::rejected(RejectReason::InvalidNoise);
        }
        let Some((u, dist_m)) = self.line_of_sight(&m.emitter_pos_ecef_m) else {
            return UpdateOutcome::rejected(RejectReason::DegenerateGeometry);
        };
        // The non-zero entries of H in ascending state order: −u at the positions, 1 at
        // the clock bias (and at the ISB).
        let h = [
            (idx::POS[0], -u[0]),
            (idx::POS[1], -u[1]),
            (idx::POS[2], -u[2]),
            (idx::CLOCK_BIAS, 1.0),
            (idx::ISB_BDS, 1.0),
        ];
        let mut predicted_m = dist_m + self.x[idx::CLOCK_BIAS];
        let with_isb = m.system() == System::Bds && self.isb_active();
        if with_isb {
            predicted_m += self.x[idx::ISB_BDS];
        }
        let gate = self.cfg.gate_chi2;
        self.scalar_update(
            &h[..if with_isb { 5 } else { 4 }],
            m.pseudorange_m - predicted_m,
            m.sigma_m * m.sigma_m,
            gate,
        )
    }

    /// The range-rate update (eqs. 16–17 with the sign derived from eq. 9):
    /// `h = u·(v_s − v) + ḃ`, `H = [−(w − u(u·w))/d at position, −u at velocity, 1 at ḃ]`.
    /// A measurement without a rate is rejected as non-finite input.
    pub fn update_range_rate(&mut self, m: &RangeMeasurement) -> UpdateOutcome {
        if !self.initialised {
            return UpdateOutcome::rejected(RejectReason::NotInitialised);
        }
        let rate_mps = m.range_rate_mps.unwrap_or(f64::NAN);
        if !(rate_mps.is_finite()
            && m.emitter_pos_ecef_m.iter().all(|v| v.is_finite())
            && m.emitter_vel_ecef_mps.iter().all(|v| v.is_finite()))
        {
            return UpdateOutcome::rejected(RejectReason::NonFiniteInput);
        }
        if !(m.sigma_rate_mps.is_finite() && m.sigma_rate_mps > 0.0) {
            return UpdateOutcome::rejected(RejectReason::InvalidNoise);
        }
        let Some((u, dist_m)) = self.line_of_sight(&m.emitter_pos_ecef_m) else {
            return UpdateOutcome::rejected(RejectReason::DegenerateGeometry);
        };
        let w = m.emitter_vel_ecef_mps - self.velocity_ecef();
        let u_dot_w = u.dot(&w);
        let d_pos = -(w - u * u_dot_w) / dist_m;
        // The non-zero entries of H in ascending state order (x, ẋ, y, ẏ, z, ż, ḃ); without
        // the position terms (eq. 17 as printed) only the velocity and drift entries.
        let full = [
            (idx::POS[0], d_pos[0]),
            (idx::VEL[0], -u[0]),
            (idx::POS[1], d_pos[1]),
            (idx::VEL[1], -u[1]),
            (idx::POS[2], d_pos[2]),
            (idx::VEL[2], -u[2]),
            (idx::CLOCK_DRIFT, 1.0),
        ];
        let velocity_only = [
            (idx::VEL[0], -u[0]),
            (idx::VEL[1], -u[1]),
            (idx::VEL[2], -u[2]),
            (idx::CLOCK_DRIFT, 1.0),
        ];
        let h: &[(usize, f64)] = if self.cfg.rate_position_jacobian {
            &full
        } else {
            &velocity_only
        };
        let predicted_mps = u_dot_w + self.x[idx::CLOCK_DRIFT];
        let gate = self.cfg.gate_chi2;
        self.scalar_update(
            h,
            rate_mps - predicted_mps,
            m.sigma_rate_mps * m.sigma_rate_mps,
            gate,
        )
    }

    /// The position-fix update (eqs. 18–19), as one 3-D update with the fix's full
    /// covariance `R_f`.
    pub fn update_position(&mut self, fix: &PositionFix) -> UpdateOutcome {
        if !self.initialised {
            return UpdateOutcome::rejected(RejectReason::NotInitialised);
        }
        if !(fix.pos_ecef_m.iter().all(|v| v.is_finite())
            && fix.cov_m2.iter().all(|v| v.is_finite()))
        {
            return UpdateOutcome::rejected(RejectReason::NonFiniteInput);
        }
        let r = fix.cov_m2;
        let r_scale = r.diagonal().amax();
        // Every entry is finite here, so the scale is a number.
        if r_scale <= 0.0 || (r - r.transpose()).amax() > 1e-9 * r_scale || r.cholesky().is_none() {
            return UpdateOutcome::rejected(RejectReason::InvalidNoise);
        }
        // C = P Hᵀ is the three position columns of P; H P Hᵀ is their position rows.
        let mut c = SMatrix::<f64, N_STATES, 3>::zeros();
        for (j, &pj) in idx::POS.iter().enumerate() {
            c.set_column(j, &self.p.column(pj));
        }
        let mut s = r;
        for (i, &pi) in idx::POS.iter().enumerate() {
            for j in 0..3 {
                s[(i, j)] += c[(pi, j)];
            }
        }
        let s = 0.5 * (s + s.transpose());
        let Some(s_chol) = s.cholesky() else {
            return UpdateOutcome::rejected(RejectReason::NumericalFailure);
        };
        let innovation = fix.pos_ecef_m - self.position_ecef();
        let nis = innovation.dot(&s_chol.solve(&innovation));
        if !nis.is_finite() {
            return UpdateOutcome::Rejected {
                nis,
                reason: RejectReason::NumericalFailure,
            };
        }
        if let Some(g) = self.cfg.gate_chi2_position {
            if nis > g {
                return UpdateOutcome::Rejected {
                    nis,
                    reason: RejectReason::Gate {
                        state_led: s.trace() - r.trace() >= r.trace(),
                    },
                };
            }
        }
        // K = C S⁻¹, computed as (S⁻¹ Cᵀ)ᵀ because S is symmetric.
        let k: SMatrix<f64, N_STATES, 3> = s_chol.solve(&c.transpose()).transpose();
        let x_new = self.x + k * innovation;
        // Joseph form, expanded: P − K Cᵀ − C Kᵀ + K S Kᵀ.
        let kct = k * c.transpose();
        let mut p_new = self.p - kct - kct.transpose() + k * s * k.transpose();
        symmetrise(&mut p_new);
        self.commit(x_new, p_new, nis)
    }

    /// The state vector.
    pub fn state(&self) -> &StateVector {
        &self.x
    }

    /// The state covariance.
    pub fn covariance(&self) -> &StateMatrix {
        &self.p
    }

    /// The estimated position (ECEF, m).
    pub fn position_ecef(&self) -> Vector3<f64> {
        Vector3::new(
            self.x[idx::POS[0]],
            self.x[idx::POS[1]],
            self.x[idx::POS[2]],
        )
    }

    /// The estimated velocity (ECEF, m/s).
    pub fn velocity_ecef(&self) -> Vector3<f64> {
        Vector3::new(
            self.x[idx::VEL[0]],
            self.x[idx::VEL[1]],
            self.x[idx::VEL[2]],
        )
    }

    /// The estimated receiver clock bias (m).
    pub fn clock_bias_m(&self) -> f64 {
        self.x[idx::CLOCK_BIAS]
    }

    /// The estimated receiver clock drift (m/s).
    pub fn clock_drift_mps(&self) -> f64 {
        self.x[idx::CLOCK_DRIFT]
    }

    /// The estimated BeiDou inter-system bias (m); 0 while the state is inert.
    pub fn isb_bds_m(&self) -> f64 {
        self.x[idx::ISB_BDS]
    }

    /// The 3×3 covariance of the ECEF position (m²).
    pub fn position_covariance(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.p[(idx::POS[i], idx::POS[j])])
    }

    /// The 3×3 covariance of the ECEF velocity (m²/s²).
    pub fn velocity_covariance(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.p[(idx::VEL[i], idx::VEL[j])])
    }

    /// Position NEES `eᵀ P_pos⁻¹ e` with `e` the estimate minus the truth; χ²(3) when the
    /// filter is consistent. `None` when the position covariance is not positive definite.
    pub fn nees_position(&self, truth_pos_ecef_m: &Vector3<f64>) -> Option<f64> {
        let e = self.position_ecef() - truth_pos_ecef_m;
        let chol = self.position_covariance().cholesky()?;
        Some(e.dot(&chol.solve(&e)))
    }

    /// The unit line of sight from the estimated position to `emitter` and the distance,
    /// or `None` when they (nearly) coincide and the direction is undefined.
    fn line_of_sight(&self, emitter: &Vector3<f64>) -> Option<(Vector3<f64>, f64)> {
        let los = emitter - self.position_ecef();
        let d = los.norm();
        // A millimetre is far below any ranging noise: closer than that the Jacobian is
        // meaningless, and it only happens when something upstream has gone wrong.
        (d.is_finite() && d > 1e-3).then(|| (los / d, d))
    }

    /// One scalar update with the row Jacobian `h` given by its non-zero entries
    /// `(state, value)` in ascending state order, innovation `z − h(x)` and noise variance
    /// `r_var`; Joseph form expanded for a scalar (see the module documentation).
    fn scalar_update(
        &mut self,
        h: &[(usize, f64)],
        innovation: f64,
        r_var: f64,
        gate: Option<f64>,
    ) -> UpdateOutcome {
        #[cfg(target_arch = "x86_64")]
        {
            if use_avx2() {
                // SAFETY: the CPU supports AVX2, checked by `use_avx2`.
                return unsafe { self.scalar_update_avx2(h, innovation, r_var, gate) };
            }
        }
        self.scalar_update_body(h, innovation, r_var, gate)
    }

    /// [`Ekf11::scalar_update_body`] compiled for AVX2: a 12-entry column of P is three
    /// registers instead of six, and the Joseph pass no longer spills registers. Every
    /// number is computed by the same IEEE operations in the same order in either build
    /// (there is no fused multiply–add), so the results are bit-identical (tested).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_update_avx2(
        &mut self,
        h: &[(usize, f64)],
        innovation: f64,
        r_var: f64,
        gate: Option<f64>,
    ) -> UpdateOutcome {
        self.scalar_update_body(h, innovation, r_var, gate)
    }

    #[inline(always)]
    fn scalar_update_body(
        &mut self,
        h: &[(usize, f64)],
        innovation: f64,
        r_var: f64,
        gate: Option<f64>,
    ) -> UpdateOutcome {
        const NS: usize = N_STATES;
        // h has four to seven non-zero entries, so c = P h is a sum of that many columns
        // of P rather than a dense product.
        let cols = &self.p.data.0;
        let mut c = [0.0; NS];
        for &(j, hj) in h {
            for (o, &v) in c.iter_mut().zip(&cols[j]) {
                *o += hj * v;
            }
        }
        let s = h.iter().map(|&(j, hj)| hj * c[j]).sum::<f64>() + r_var;
        if !(s.is_finite() && s > 0.0) {
            return UpdateOutcome::rejected(RejectReason::NumericalFailure);
        }
        let nis = innovation * innovation / s;
        if !nis.is_finite() {
            return UpdateOutcome::Rejected {
                nis,
                reason: RejectReason::NumericalFailure,
            };
        }
        if let Some(g) = gate {
            if nis > g {
                return UpdateOutcome::Rejected {
                    nis,
                    reason: RejectReason::Gate {
                        state_led: s - r_var >= r_var,
                    },
                };
            }
        }
        // The Joseph form expanded for a scalar, P⁺ = P − k cᵀ − c kᵀ + s k kᵀ, is written
        // P⁺ = P − (k eᵀ + e kᵀ) with e = c − (s/2) k: the same polynomial in k (so an
        // error in the gain still enters only to second order), at four operations per
        // entry instead of seven. Each entry is k_i e_j + e_i k_j, symmetric in (i, j) to
        // the last bit, so the full square (which vectorises) stays exactly symmetric.
        let half_s = 0.5 * s;
        let k: [f64; NS] = std::array::from_fn(|i| c[i] / s);
        let e: [f64; NS] = std::array::from_fn(|i| c[i] - half_s * k[i]);
        let mut x_new = self.x;
        for (xi, &ki) in x_new.iter_mut().zip(&k) {
            *xi += ki * innovation;
        }
        let (k_max, e_max) = (max_abs_finite(&k), max_abs_finite(&e));
        let bound = (self.p_abs_bound + 2.0 * k_max * e_max) * (1.0 + 4.0 * f64::EPSILON);
        if !(bound < SAFE_ABS && x_new.iter().all(|v| v.is_finite())) {
            // Extreme numbers (or a non-finite gain): compute on a copy and check every
            // entry, as the bound can no longer promise a finite result.
            let mut p_new = self.p.data.0;
            joseph_scalar(&mut p_new, &k, &e, self.live_states());
            return self.commit(x_new, StateMatrix::from(p_new), nis);
        }
        // Every entry is finite (the bound); only the variances can go wrong, by rounding
        // to below zero, and they are checked before anything is written.
        let mut diagonal_ok = true;
        for (i, (&ki, &ei)) in k.iter().zip(&e).enumerate() {
            diagonal_ok &= cols[i][i] - (ki * ei + ei * ki) >= 0.0;
        }
        if !diagonal_ok {
            return UpdateOutcome::Rejected {
                nis,
                reason: RejectReason::NumericalFailure,
            };
        }
        let live = self.live_states();
        joseph_scalar(&mut self.p.data.0, &k, &e, live);
        self.x = x_new;
        self.p_abs_bound = bound;
        UpdateOutcome::Accepted { nis }
    }

    /// The number of leading states whose columns an update can change: all twelve, or
    /// eleven when the ISB state is inert (its row and column of P are zero and stay so).
    fn live_states(&self) -> usize {
        if self.isb_active() {
            N_STATES
        } else {
            idx::ISB_BDS
        }
    }

    /// Writes an updated state and covariance if they are finite with non-negative
    /// variances; otherwise refuses and keeps the old ones.
    fn commit(&mut self, x_new: StateVector, p_new: StateMatrix, nis: f64) -> UpdateOutcome {
        let finite = x_new.iter().all(|v| v.is_finite()) && p_new.iter().all(|v| v.is_finite());
        if !finite || p_new.diagonal().iter().any(|&v| v < 0.0) {
            return UpdateOutcome::Rejected {
                nis,
                reason: RejectReason::NumericalFailure,
            };
        }
        self.x = x_new;
        self.p = p_new;
        self.p_abs_bound = max_abs(&self.p);
        UpdateOutcome::Accepted { nis }
    }
}

/// True when the AVX2 builds of the predict and update bodies can run (and, in unit tests,
/// unless the test thread asked for the portable build, to compare the two).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn use_avx2() -> bool {
    #[cfg(test)]
    {
        if tests::PORTABLE_ONLY.with(|c| c.get()) {
            return false;
        }
    }
    std::arch::is_x86_feature_detected!("avx2")
}

/// `P ← P − (k eᵀ + e kᵀ)` on the columns `0..live` of a column-major 12 × 12 matrix
/// (the scalar Joseph update of [`Ekf11::scalar_update`]).
#[inline(always)]
fn joseph_scalar(
    p: &mut [[f64; N_STATES]; N_STATES],
    k: &[f64; N_STATES],
    e: &[f64; N_STATES],
    live: usize,
) {
    for ((col, &kj), &ej) in p.iter_mut().zip(k).zip(e).take(live) {
        for ((v, &ki), &ei) in col.iter_mut().zip(k).zip(e) {
            *v -= ki * ej + ei * kj;
        }
    }
}

/// The largest magnitude of a finite vector, or infinity when an entry is not finite.
#[inline(always)]
fn max_abs_finite(v: &[f64; N_STATES]) -> f64 {
    let mut m = 0.0_f64;
    let mut not_finite = 0.0;
    for &x in v {
        let a = x.abs();
        m = if a > m { a } else { m };
        not_finite += x * 0.0;
    }
    if not_finite == 0.0 {
        m
    } else {
        f64::INFINITY
    }
}

/// The largest magnitude of an entry of `p` (infinity if one is not finite).
fn max_abs(p: &StateMatrix) -> f64 {
    p.iter().fold(0.0_f64, |m, v| {
        if v.is_finite() {
            m.max(v.abs())
        } else {
            f64::INFINITY
        }
    })
}

/// The non-zero blocks of the process noise Q of eqs. 6–8 for one interval: the 3×3
/// white-jerk block per axis, the 2×2 clock block and the ISB variance.
struct NoiseBlocks {
    axis: [[[f64; 3]; 3]; 3],
    clock: [[f64; 2]; 2],
    isb: f64,
}

impl NoiseBlocks {
    #[inline(always)]
    fn new(cfg: &Ekf11Config, dt_s: f64) -> Self {
        let t = dt_s;
        let (t2, t3) = (t * t, t * t * t);
        let (t4, t5) = (t3 * t, t3 * t2);
        let block = [
            [t5 / 20.0, t4 / 8.0, t3 / 6.0],
            [t4 / 8.0, t3 / 3.0, t2 / 2.0],
            [t3 / 6.0, t2 / 2.0, t],
        ];
        let axis = cfg
            .accel_psd_m2ps5
            .map(|s| block.map(|row| row.map(|v| s * v)));
        let (st, sf) = (cfg.clock_bias_psd_m2ps, cfg.clock_drift_psd_m2ps3);
        let clock = [
            [st * t + sf * t3 / 3.0, sf * t2 / 2.0],
            [sf * t2 / 2.0, sf * t],
        ];
        let isb = cfg.isb_bds.map_or(0.0, |i| i.psd_m2ps * t);
        Self { axis, clock, isb }
    }

    /// Adds the blocks to a column-major 12 × 12 matrix.
    #[inline(always)]
    fn add_to(&self, m: &mut [[f64; N_STATES]; N_STATES]) {
        for (axis, block) in self.axis.iter().enumerate() {
            let ix = [idx::POS[axis], idx::VEL[axis], idx::ACC[axis]];
            for (i, row) in block.iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    m[ix[j]][ix[i]] += v;
                }
            }
        }
        let ix = [idx::CLOCK_BIAS, idx::CLOCK_DRIFT];
        for (i, row) in self.clock.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                m[ix[j]][ix[i]] += v;
            }
        }
        m[idx::ISB_BDS][idx::ISB_BDS] += self.isb;
    }
}

/// Replaces the column-major `p` by `(p + pᵀ)/2`.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // Mirrored writes need both indices.
fn symmetrise_cm(p: &mut [[f64; N_STATES]; N_STATES]) {
    for j in 0..N_STATES {
        for i in (j + 1)..N_STATES {
            let v = 0.5 * (p[j][i] + p[i][j]);
            p[j][i] = v;
            p[i][j] = v;
        }
    }
}

/// Replaces the rows of the column-major `m` by those of `Φ m` (see
/// [`apply_transition_rows`]), column by column.
#[inline(always)]
fn apply_transition_rows_cm(m: &mut [[f64; N_STATES]; N_STATES], dt_s: f64) {
    let half_t2 = 0.5 * dt_s * dt_s;
    for col in m.iter_mut() {
        for axis in 0..3 {
            let (p, v, a) = (idx::POS[axis], idx::VEL[axis], idx::ACC[axis]);
            let (mv, ma) = (col[v], col[a]);
            col[p] = (col[p] + dt_s * mv) + half_t2 * ma;
            col[v] += dt_s * ma;
        }
        col[idx::CLOCK_BIAS] += dt_s * col[idx::CLOCK_DRIFT];
    }
}

/// Replaces the columns of the column-major `m` by those of `m Φᵀ` for the Φ of eq. 5:
/// each position column takes `T` times the velocity column and `T²/2` times the
/// acceleration column, each velocity column `T` times the acceleration column, and the
/// clock-bias column `T` times the drift column (the transpose of
/// [`apply_transition_rows`]).
#[inline(always)]
fn apply_transition_columns(m: &mut [[f64; N_STATES]; N_STATES], dt_s: f64) {
    let half_t2 = 0.5 * dt_s * dt_s;
    for axis in 0..3 {
        let (p, v, a) = (idx::POS[axis], idx::VEL[axis], idx::ACC[axis]);
        let (cv, ca) = (m[v], m[a]);
        for ((o, &mv), &ma) in m[p].iter_mut().zip(&cv).zip(&ca) {
            *o = (*o + dt_s * mv) + half_t2 * ma;
        }
        for (o, &ma) in m[v].iter_mut().zip(&ca) {
            *o += dt_s * ma;
        }
    }
    let drift = m[idx::CLOCK_DRIFT];
    for (o, &d) in m[idx::CLOCK_BIAS].iter_mut().zip(&drift) {
        *o += dt_s * d;
    }
}

/// Replaces the rows of `m` by those of `Φ m` for the Φ of eq. 5 ([`Ekf11::transition`]),
/// in place. Each position row takes `T` times the velocity row and `T²/2` times the
/// acceleration row, each velocity row `T` times the acceleration row, and the clock-bias
/// row `T` times the drift row; rows are updated in an order that reads only old values.
fn apply_transition_rows<const C: usize>(m: &mut SMatrix<f64, N_STATES, C>, dt_s: f64) {
    let half_t2 = 0.5 * dt_s * dt_s;
    for axis in 0..3 {
        let (p, v, a) = (idx::POS[axis], idx::VEL[axis], idx::ACC[axis]);
        for c in 0..C {
            let (mv, ma) = (m[(v, c)], m[(a, c)]);
            // Summed in the order of the dense product, so that both give the same
            // rounding on ECEF coordinates, whose last bit is a nanometre.
            m[(p, c)] = (m[(p, c)] + dt_s * mv) + half_t2 * ma;
            m[(v, c)] += dt_s * ma;
        }
    }
    for c in 0..C {
        let drift = m[(idx::CLOCK_DRIFT, c)];
        m[(idx::CLOCK_BIAS, c)] += dt_s * drift;
    }
}

/// Replaces `p` by `(p + pᵀ)/2`, removing the asymmetry round-off leaves.
fn symmetrise(p: &mut StateMatrix) {
    for i in 0..N_STATES {
        for j in (i + 1)..N_STATES {
            let v = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, Geodetic};
    use crate::fusion::kalman::chi2;
    use approx::assert_relative_eq;

    thread_local! {
        /// Set by a test to run the portable build of the hot paths on its thread.
        pub(super) static PORTABLE_ONLY: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }

    fn range_meas(
        sys: System,
        emitter: Vector3<f64>,
        pr: f64,
        rate: Option<f64>,
    ) -> RangeMeasurement {
        RangeMeasurement {
            emitter: EmitterId::new(sys, 1),
            emitter_pos_ecef_m: emitter,
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m: pr,
            sigma_m: 3.0,
            range_rate_mps: rate,
            sigma_rate_mps: 0.1,
            cn0_dbhz: 45.0,
            elevation_rad: 0.5,
        }
    }

    fn filter_at(cfg: Ekf11Config, pos: Vector3<f64>) -> Ekf11 {
        let mut f = Ekf11::new(cfg).unwrap();
        f.initialise(pos, 0.0, 10.0, 100.0).unwrap();
        f
    }

    #[test]
    fn clock_psd_conversion() {
        // c² = 8.987 551 787 368 176e16 m²/s²; h0/2 = 1e-19 → 8.99e-3 m²/s;
        // 2π²·2e-20 = 3.947 842e-19 s⁻¹ → 3.548e-2 m²/s³.
        assert_relative_eq!(
            clock_bias_psd_m2ps(2e-19),
            8.987_551_787_368_176e-3,
            max_relative = 1e-12
        );
        assert_relative_eq!(
            clock_drift_psd_m2ps3(2e-20),
            3.548_143_227_025_099e-2,
            max_relative = 1e-12
        );
    }

    #[test]
    fn transition_and_noise_match_eqs_5_to_8() {
        let cfg = Ekf11Config {
            accel_psd_m2ps5: [2.0, 3.0, 4.0],
            ..Default::default()
        };
        let t = 0.5;
        let phi = Ekf11::transition(t);
        assert_eq!(phi[(0, 1)], 0.5);
        assert_eq!(phi[(0, 2)], 0.125);
        assert_eq!(phi[(4, 5)], 0.5);
        assert_eq!(phi[(9, 10)], 0.5);
        assert_eq!(phi[(11, 11)], 1.0);
        assert_eq!(phi.sum(), 12.0 + 3.0 * (0.5 + 0.125 + 0.5) + 0.5);
        let q = Ekf11::process_noise(&cfg, t);
        assert_relative_eq!(q[(3, 3)], 3.0 * t.powi(5) / 20.0);
        assert_relative_eq!(q[(6, 7)], 4.0 * t.powi(4) / 8.0);
        assert_relative_eq!(q[(2, 0)], 2.0 * t.powi(3) / 6.0);
        assert_relative_eq!(q[(8, 8)], 4.0 * t);
        let (st, sf) = (cfg.clock_bias_psd_m2ps, cfg.clock_drift_psd_m2ps3);
        assert_relative_eq!(q[(9, 9)], st * t + sf * t.powi(3) / 3.0);
        assert_relative_eq!(q[(10, 9)], sf * t * t / 2.0);
        assert_eq!(q[(11, 11)], 0.0);
        // No coupling between axes or between motion and clock.
        assert_eq!(q[(0, 3)], 0.0);
        assert_eq!(q[(0, 9)], 0.0);
        let with_isb = Ekf11Config {
            isb_bds: Some(IsbConfig::default()),
            ..cfg
        };
        assert_relative_eq!(Ekf11::process_noise(&with_isb, t)[(11, 11)], 1e-4 * t);
    }

    #[test]
    fn in_place_transition_equals_the_dense_product() {
        let phi = Ekf11::transition(0.7);
        let m = StateMatrix::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0 + 0.1 * i as f64);
        let mut rows = m;
        apply_transition_rows(&mut rows, 0.7);
        assert!((rows - phi * m).amax() < 1e-12);
        let mut both = rows.transpose();
        apply_transition_rows(&mut both, 0.7);
        // Φ(Φm)ᵀ = Φ mᵀ Φᵀ, which is ΦPΦᵀ for a symmetric P.
        assert!((both - phi * m.transpose() * phi.transpose()).amax() < 1e-12);
        let mut x = StateVector::from_fn(|i, _| i as f64);
        apply_transition_rows(&mut x, 0.7);
        assert!((x - phi * StateVector::from_fn(|i, _| i as f64)).amax() < 1e-12);
    }

    #[test]
    fn config_parses_with_defaults_and_rejects_unknown_fields() {
        let cfg: Ekf11Config =
            toml::from_str("accel_psd_m2ps5 = [0.5, 0.5, 0.1]\ngate_chi2 = inf\n").unwrap();
        assert_eq!(cfg.accel_psd_m2ps5, [0.5, 0.5, 0.1]);
        assert_eq!(cfg.gate_chi2, Some(f64::INFINITY));
        assert_eq!(
            cfg.clock_bias_psd_m2ps,
            Ekf11Config::default().clock_bias_psd_m2ps
        );
        assert!(Ekf11::new(cfg).is_ok());
        assert!(toml::from_str::<Ekf11Config>("accel_psd = 1.0").is_err());
        let isb: Ekf11Config = toml::from_str("[isb_bds]\ninitial_sigma_m = 5.0\n").unwrap();
        assert_eq!(
            isb.isb_bds,
            Some(IsbConfig {
                initial_sigma_m: 5.0,
                psd_m2ps: 1e-4
            })
        );
        let bad = Ekf11Config {
            clock_bias_psd_m2ps: -1.0,
            ..Default::default()
        };
        assert!(matches!(Ekf11::new(bad), Err(Ekf11Error::InvalidConfig(_))));
    }

    #[test]
    fn uninitialised_filter_refuses_work() {
        let mut f = Ekf11::new(Ekf11Config::default()).unwrap();
        assert!(!f.is_initialised());
        assert_eq!(f.predict(1.0), Err(Ekf11Error::NotInitialised));
        let m = range_meas(System::Gps, Vector3::new(2e7, 0.0, 0.0), 2e7, None);
        assert_eq!(
            f.update_range(&m).range.reject_reason(),
            Some(RejectReason::NotInitialised)
        );
    }

    #[test]
    fn pseudorange_moves_the_state_along_the_line_of_sight() {
        let r = Geodetic::from_deg(40.0, 116.0, 50.0).to_ecef();
        let sat = r * (26_560e3 / r.norm());
        let mut f = filter_at(Ekf11Config::default(), r);
        // The measured range is 5 m longer than predicted: the receiver must be further
        // from the satellite (position moves away) and/or the clock later.
        let d = (sat - r).norm();
        let out = f.update_range(&range_meas(System::Gps, sat, d + 5.0, None));
        assert!(out.range.is_accepted());
        assert!(out.rate.is_none());
        let moved = f.position_ecef() - r;
        assert!(
            moved.dot(&(sat - r)) < 0.0,
            "moved towards the satellite: {moved:?}"
        );
        assert!(f.clock_bias_m() > 0.0);
        // The ISB stays inert.
        assert_eq!(f.isb_bds_m(), 0.0);
        assert!(f.covariance().row(idx::ISB_BDS).iter().all(|&v| v == 0.0));
    }

    /// The position terms of the range-rate Jacobian: with them, a satellite's transverse
    /// velocity turns a Doppler innovation into a position correction of the size the
    /// finite-difference derivative of the predicted rate gives; without them (seed 000's
    /// eq. 17) the position is untouched.
    #[test]
    fn range_rate_position_terms_follow_the_flag() {
        let r = Geodetic::from_deg(40.0, 116.0, 50.0).to_ecef();
        let sat = r * (26_560e3 / r.norm());
        let u = (sat - r).normalize();
        // 3.9 km/s across the line of sight, 300 m/s along it.
        let across = u.cross(&Vector3::z()).normalize();
        let v_sat = across * 3900.0 + u * 300.0;
        let mut m = range_meas(System::Gps, sat, (sat - r).norm(), Some(300.0 + 0.05));
        m.emitter_vel_ecef_mps = v_sat;
        m.sigma_rate_mps = 0.02;
        // The predicted rate u·(v_s − v) at r + δ, by finite differences along `across`.
        let rate_at = |p: Vector3<f64>| (sat - p).normalize().dot(&v_sat);
        let step = 10.0;
        let fd = (rate_at(r + across * step) - rate_at(r - across * step)) / (2.0 * step);
        let analytic = -(v_sat - u * u.dot(&v_sat)).dot(&across) / (sat - r).norm();
        assert!(
            (fd - analytic).abs() < 1e-9 * analytic.abs(),
            "{fd} vs {analytic}"
        );
        assert!((analytic.abs() - 3900.0 / (sat - r).norm()).abs() < 1e-9);

        // A position known to 1 km and a clock drift known to 1 cm/s, so that the rate
        // innovation is shared between velocity and position.
        let cfg = Ekf11Config {
            init_clock_drift_sigma_mps: 0.01,
            ..Default::default()
        };
        let start = |cfg: Ekf11Config| {
            let mut f = Ekf11::new(cfg).unwrap();
            f.initialise(r, 0.0, 1000.0, 100.0).unwrap();
            f
        };
        let mut exact = start(cfg);
        assert!(exact.update_range_rate(&m).is_accepted());
        let moved = (exact.position_ecef() - r).dot(&across);
        // K_pos ν ≈ σ_pos² |∂ρ̇/∂r| ν / (σ_v² + σ_pos² |∂ρ̇/∂r|²) ≈ 1e6 · 1.5e-4 · 0.05 / 100.
        assert!(
            (0.03..0.2).contains(&moved.abs()),
            "the Doppler moved the position by {moved} m"
        );
        let mut paper = start(Ekf11Config {
            rate_position_jacobian: false,
            ..cfg
        });
        assert!(paper.update_range_rate(&m).is_accepted());
        assert_eq!(paper.position_ecef(), r);
        assert!((paper.velocity_ecef() - exact.velocity_ecef()).norm() < 1e-3);
    }

    #[test]
    fn range_rate_sign() {
        // A receiver moving towards a static tower sees a negative range rate.
        let r = Geodetic::from_deg(40.0, 116.0, 50.0).to_ecef();
        let frame = crate::core::EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 50.0));
        let tower = frame.ecef_of_enu(&Vector3::new(0.0, 5_000.0, 0.0));
        // A small drift uncertainty makes the velocity, not the clock, explain the rate.
        let cfg = Ekf11Config {
            init_clock_drift_sigma_mps: 0.1,
            ..Default::default()
        };
        let mut f = filter_at(cfg, r);
        let d = (tower - r).norm();
        // Measured rate −10 m/s: the filter should find a velocity of about 10 m/s north.
        let out = f.update_range(&range_meas(System::Dtmb, tower, d, Some(-10.0)));
        assert!(out.rate.unwrap().is_accepted());
        let v_enu = frame.enu_vector_of_ecef(&f.velocity_ecef());
        assert!((v_enu.y - 10.0).abs() < 0.1, "{v_enu:?}");
    }

    #[test]
    fn bds_ranges_observe_the_isb_only_when_configured() {
        let r = Geodetic::from_deg(40.0, 116.0, 50.0).to_ecef();
        let sat = r * (26_560e3 / r.norm());
        let d = (sat - r).norm();
        let cfg = Ekf11Config {
            isb_bds: Some(IsbConfig::default()),
            ..Default::default()
        };
        let mut f = filter_at(cfg, r);
        assert!(f
            .update_range(&range_meas(System::Bds, sat, d + 20.0, None))
            .range
            .is_accepted());
        assert!(f.isb_bds_m() > 0.0);
        let mut g = filter_at(Ekf11Config::default(), r);
        assert!(g
            .update_range(&range_meas(System::Bds, sat, d + 20.0, None))
            .range
            .is_accepted());
        assert_eq!(g.isb_bds_m(), 0.0);
        assert!(g.clock_bias_m() > 0.0);
    }

    #[test]
    fn position_fix_pulls_towards_the_fix_and_shrinks_covariance() {
        let r = Geodetic::from_deg(40.0, 116.0, 50.0).to_ecef();
        let mut f = filter_at(Ekf11Config::default(), r);
        let fix = PositionFix {
            pos_ecef_m: r + Vector3::new(10.0, 0.0, 0.0),
            cov_m2: Matrix3::identity() * 100.0,
            support: 0,
        };
        let before = f.position_covariance();
        let out = f.update_position(&fix);
        // Prior σ² = 100 and fix σ² = 100: the estimate moves half-way, variance halves.
        assert!(out.is_accepted());
        assert_relative_eq!(out.nis(), 0.5, max_relative = 1e-12);
        assert_relative_eq!((f.position_ecef() - r).x, 5.0, max_relative = 1e-9);
        assert_relative_eq!(
            f.position_covariance()[(0, 0)],
            before[(0, 0)] / 2.0,
            max_relative = 1e-12
        );
        let bad = PositionFix {
            cov_m2: -Matrix3::identity(),
            ..fix
        };
        assert_eq!(
            f.update_position(&bad).reject_reason(),
            Some(RejectReason::InvalidNoise)
        );
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // Tabulated values (e.g. NIST/SEMATECH e-Handbook, Table 1.3.6.7.4).
        assert_relative_eq!(chi2::quantile(0.975, 100.0), 129.561, max_relative = 1e-5);
        assert_relative_eq!(chi2::quantile(0.025, 100.0), 74.222, max_relative = 1e-5);
        assert!((chi2::quantile(0.95, 1.0) - 3.841).abs() < 5e-4);
        assert_relative_eq!(
            chi2::quantile(0.999, 1.0),
            CHI2_1DOF_P999,
            max_relative = 1e-10
        );
        assert_relative_eq!(
            chi2::quantile(0.999, 3.0),
            CHI2_3DOF_P999,
            max_relative = 1e-10
        );
        assert_relative_eq!(
            chi2::quantile(0.5, 2.0),
            2.0 * 2f64.ln(),
            max_relative = 1e-12
        );
        // Wilson–Hilferty is good to a fraction of a per cent at 100 degrees of freedom.
        assert_relative_eq!(
            chi2::quantile_wilson_hilferty(0.975, 100.0),
            129.561,
            max_relative = 1e-3
        );
        assert_relative_eq!(
            chi2::normal_quantile(0.975),
            1.959_963_985,
            max_relative = 1e-8
        );
        assert_relative_eq!(chi2::ln_gamma(5.0), 24f64.ln(), max_relative = 1e-13);
        assert_relative_eq!(
            chi2::ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            max_relative = 1e-13
        );
        for &(p, k) in &[(0.01, 3.0), (0.3, 11.0), (0.9, 300.0), (0.999, 5000.0)] {
            assert_relative_eq!(chi2::cdf(chi2::quantile(p, k), k), p, max_relative = 1e-10);
        }
    }

    /// Row 2 of [`PseudorangesAndRates`] for one emitter: the range rate alone, as a
    /// scalar model for the generic filters.
    struct RateRow(
        crate::fusion::models::PseudorangesAndRates<N_STATES, 2>,
        f64,
    );

    use crate::fusion::models::MeasurementModel;

    impl MeasurementModel<N_STATES, 1> for RateRow {
        fn h(&self, x: &StateVector) -> SVector<f64, 1> {
            SVector::<f64, 1>::new(self.0.h(x)[1])
        }
        fn jacobian(&self, x: &StateVector) -> SMatrix<f64, 1, N_STATES> {
            self.0.jacobian(x).fixed_rows::<1>(1).into_owned()
        }
        fn r(&self) -> SMatrix<f64, 1, 1> {
            SMatrix::<f64, 1, 1>::new(self.1 * self.1)
        }
    }

    /// A random drive of `epochs` epochs: receiver site, velocity, 6–12 satellites of both
    /// systems in random directions above the horizon with their measurements (5 % of the
    /// pseudoranges 200 σ off, so the gate works), and random intervals.
    struct Drive {
        start: Vector3<f64>,
        epochs: Vec<(f64, Vec<RangeMeasurement>, Vector3<f64>)>,
    }

    fn drive(seed: u64, epochs: usize, isb_m: f64) -> Drive {
        use rand::Rng;
        use rand_distr::StandardNormal;
        let mut rng = crate::core::TrialRng::new(seed, 0).stream("test/ekf11/drive");
        let mut g = || -> f64 { rng.sample(StandardNormal) };
        let up = Vector3::new(g(), g(), g()).normalize();
        let mut pos = up * 6.371e6;
        let vel = Vector3::new(g(), g(), g()) * 8.0;
        let start = pos;
        let (clock0, drift) = (3.0e4, 20.0);
        let mut t = 0.0;
        let mut out = Vec::new();
        let mut rng = crate::core::TrialRng::new(seed, 1).stream("test/ekf11/drive");
        for _ in 0..epochs {
            let dt = 0.2 + 1.8 * rng.random::<f64>();
            t += dt;
            pos += vel * dt;
            let clock = clock0 + drift * t;
            let n = rng.random_range(6..=12);
            let ms = (0..n)
                .map(|j| {
                    let mut d = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
                    d += up * (d.dot(&up).abs() + 0.2 - d.dot(&up));
                    let los = d.normalize();
                    let sat = pos + 2.0e7 * los;
                    let sat_vel =
                        Vector3::from_fn(|_, _| 3000.0 * rng.sample::<f64, _>(StandardNormal));
                    let system = if j % 3 == 2 { System::Bds } else { System::Gps };
                    let sigma_m = 0.5 + 5.0 * rng.random::<f64>();
                    let outlier = if rng.random_bool(0.05) {
                        200.0 * sigma_m
                    } else {
                        0.0
                    };
                    let bias = clock + if system == System::Bds { isb_m } else { 0.0 };
                    let noise: f64 = rng.sample(StandardNormal);
                    let rate_noise: f64 = rng.sample(StandardNormal);
                    RangeMeasurement {
                        emitter: EmitterId::new(system, j as u16 + 1),
                        emitter_pos_ecef_m: sat,
                        emitter_vel_ecef_mps: sat_vel,
                        pseudorange_m: (sat - pos).norm() + bias + sigma_m * noise + outlier,
                        sigma_m,
                        range_rate_mps: Some(los.dot(&(sat_vel - vel)) + drift + 0.05 * rate_noise),
                        sigma_rate_mps: 0.05,
                        cn0_dbhz: 45.0,
                        elevation_rad: 0.5,
                    }
                })
                .collect();
            out.push((dt, ms, pos));
        }
        Drive { start, epochs: out }
    }

    /// The rewritten filter (sparse products, in-place Joseph update of P − (k eᵀ + e kᵀ),
    /// overflow bound instead of a copy and a full finiteness check, block-sparse
    /// prediction) against the generic [`crate::fusion::kalman::Ekf`] on the same model
    /// (`Pva11Clock`, dense Φ P Φᵀ + Q) and the same scalar measurements (one-row
    /// `Pseudoranges` and the rate row of `PseudorangesAndRates`, dense Joseph form
    /// (I − K H) P (I − K H)ᵀ + K R Kᵀ): every outcome, reason and NIS, and the state and
    /// covariance after every update, over 16 random drives of 40 epochs with and
    /// without the ISB state.
    ///
    /// Both filters round differently, and an ECEF coordinate's last bit (1 nm) feeds the
    /// next innovation, so the weakly observed states drift apart by some 1e-8 of their
    /// σ over 40 epochs: the tolerances are 1e-9 |x| + 1e-7 σ on the state, 1e-8 σ_i σ_j
    /// on the covariance and 1e-7 on the normalised innovation ν/√S. The implementation
    /// this one replaced (dense h, Joseph terms grouped in seven operations, checked
    /// copies) measured 1.4e-8 σ, 1.8e-9 and 1.2e-8 against the same reference; this one
    /// 1.2e-8 σ, 7.7e-10 and 1.0e-8 (printed).
    #[test]
    fn matches_the_generic_ekf_update_by_update() {
        use crate::fusion::kalman::{Ekf, Gating};
        use crate::fusion::models::{
            Pseudoranges, PseudorangesAndRates, Pva11Clock, RangeRow, StateLayout,
        };
        let (mut worst_x, mut worst_p, mut worst_nis) = (0.0_f64, 0.0_f64, 0.0_f64);
        let (mut accepted, mut gated) = (0, 0);
        for case in 0..16u64 {
            let isb = case % 2 == 0;
            let cfg = Ekf11Config {
                isb_bds: isb.then(IsbConfig::default),
                ..Default::default()
            };
            let d = drive(500 + case, 40, if isb { 12.0 } else { 0.0 });
            let mut f = Ekf11::new(cfg).unwrap();
            f.initialise(
                d.start + Vector3::new(4.0, -3.0, 2.0),
                3.0e4 - 20.0,
                10.0,
                100.0,
            )
            .unwrap();
            let model = Pva11Clock::new(cfg).unwrap();
            let mut layout = StateLayout::ekf11();
            if !isb {
                layout.isb = [None; System::COUNT];
            }
            let gating = Gating {
                chi2_prob: Some(chi2::cdf(CHI2_1DOF_P999, 1.0)),
                residual: None,
            };
            let mut g = Ekf::new(*f.state(), *f.covariance())
                .unwrap()
                .with_gating(gating)
                .unwrap();
            let mut compare = |f: &Ekf11, g: &Ekf<N_STATES>, what: &str| {
                for i in 0..N_STATES {
                    let scale = f.covariance()[(i, i)].sqrt();
                    let dx = (f.state()[i] - g.state()[i]).abs();
                    let tol = 1e-9 * f.state()[i].abs() + 1e-7 * scale;
                    assert!(
                        dx <= tol,
                        "case {case}, {what}: x[{i}] differs by {dx:e} (tolerance {tol:e})"
                    );
                    if scale > 0.0 {
                        worst_x = worst_x.max(dx / scale);
                    }
                    for j in 0..N_STATES {
                        let scale = (f.covariance()[(i, i)] * f.covariance()[(j, j)]).sqrt();
                        let dp = (f.covariance()[(i, j)] - g.covariance()[(i, j)]).abs();
                        assert!(
                            dp <= 1e-8 * scale,
                            "case {case}, {what}: P[{i},{j}] differs by {dp:e} of {scale:e}"
                        );
                        if scale > 0.0 {
                            worst_p = worst_p.max(dp / scale);
                        }
                    }
                }
            };
            for (epoch, (dt, ms, _)) in d.epochs.iter().enumerate() {
                f.predict(*dt).unwrap();
                g.predict(&model, *dt).unwrap();
                compare(&f, &g, &format!("epoch {epoch} predict"));
                for m in ms {
                    let row = RangeRow::from(m);
                    let pr = Pseudoranges::<N_STATES, 1>::new(layout, [row]).unwrap();
                    let rate = RateRow(
                        PseudorangesAndRates::<N_STATES, 2>::new(layout, &[row]).unwrap(),
                        m.sigma_rate_mps,
                    );
                    let ours = f.update_range(m);
                    let theirs = [
                        g.update(&pr, &SVector::<f64, 1>::new(m.pseudorange_m))
                            .outcome,
                        g.update(&rate, &SVector::<f64, 1>::new(m.range_rate_mps.unwrap()))
                            .outcome,
                    ];
                    for (a, b) in [ours.range, ours.rate.unwrap()].iter().zip(&theirs) {
                        assert_eq!(
                            a.reject_reason(),
                            b.reject_reason(),
                            "case {case}, epoch {epoch}: outcomes {a:?} and {b:?}"
                        );
                        let (na, nb) = (a.nis().sqrt(), b.nis().sqrt());
                        let diff = (na - nb).abs();
                        assert!(
                            diff <= 1e-9 * nb + 1e-7,
                            "case {case}, epoch {epoch}: NIS {a:?} and {b:?}"
                        );
                        worst_nis = worst_nis.max(diff);
                        accepted += usize::from(a.is_accepted());
                        gated += usize::from(matches!(
                            a.reject_reason(),
                            Some(RejectReason::Gate { .. })
                        ));
                    }
                    compare(&f, &g, &format!("epoch {epoch} after {}", m.emitter));
                }
            }
        }
        println!(
            "Ekf11 vs generic Ekf<12>: {accepted} updates accepted, {gated} gated; largest differences: state {worst_x:.1e} σ, covariance {worst_p:.1e} (relative to σ_i σ_j), normalised innovation {worst_nis:.1e}"
        );
        assert!(
            gated > 20 && accepted > 10 * gated,
            "{accepted} accepted, {gated} gated"
        );
    }

    /// The AVX2 and the portable builds of the predict and update bodies give the same
    /// bits, outcome by outcome (so results do not depend on the machine).
    #[test]
    fn avx2_and_portable_builds_are_bit_identical() {
        #[cfg(target_arch = "x86_64")]
        if !std::arch::is_x86_feature_detected!("avx2") {
            println!("skipped: this CPU has no AVX2, only the portable build runs");
            return;
        }
        let run = |portable: bool| {
            PORTABLE_ONLY.with(|c| c.set(portable));
            let mut outcomes = Vec::new();
            let mut filters = Vec::new();
            for case in 0..4u64 {
                let isb = case % 2 == 0;
                let cfg = Ekf11Config {
                    isb_bds: isb.then(IsbConfig::default),
                    ..Default::default()
                };
                let d = drive(700 + case, 30, 12.0);
                let mut f = Ekf11::new(cfg).unwrap();
                f.initialise(d.start, 3.0e4, 10.0, 100.0).unwrap();
                for (dt, ms, _) in &d.epochs {
                    f.predict(*dt).unwrap();
                    for m in ms {
                        outcomes.push(f.update_range(m));
                    }
                }
                filters.push((*f.state(), *f.covariance()));
            }
            PORTABLE_ONLY.with(|c| c.set(false));
            (outcomes, filters)
        };
        let (fast, portable) = (run(false), run(true));
        assert_eq!(fast.0.len(), portable.0.len());
        for (a, b) in fast.0.iter().zip(&portable.0) {
            assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
        for ((xa, pa), (xb, pb)) in fast.1.iter().zip(&portable.1) {
            let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(xa.as_slice()), bits(xb.as_slice()));
            assert_eq!(bits(pa.as_slice()), bits(pb.as_slice()));
        }
    }

    /// Near the top of the floating-point range the overflow bound can no longer vouch
    /// for the in-place update, and the checked update on a copy runs instead. Scaling P
    /// and R by 2¹⁰⁰⁰ is exact in every operation of the update, so the checked path must
    /// give exactly 2¹⁰⁰⁰ times what the in-place path gives on the unscaled problem.
    #[test]
    fn the_checked_path_near_overflow_equals_the_in_place_path() {
        let (r, ms) = {
            let d = drive(900, 1, 0.0);
            (d.start, d.epochs[0].1.clone())
        };
        let cfg = Ekf11Config {
            gate_chi2: None,
            ..Default::default()
        };
        let mut a = filter_at(cfg, r);
        a.predict(1.0).unwrap();
        let scale = 2f64.powi(1000);
        let mut b = Ekf11::new(cfg).unwrap();
        b.set_state(*a.state(), a.covariance() * scale).unwrap();
        assert!(b.p_abs_bound > SAFE_ABS / 1e3);
        for m in &ms {
            let mut big = *m;
            big.sigma_m *= 2f64.powi(500);
            big.range_rate_mps = None;
            let mut small = *m;
            small.range_rate_mps = None;
            assert!(a.update_range(&small).range.is_accepted());
            assert!(b.update_range(&big).range.is_accepted());
            assert_eq!(a.state(), b.state());
            assert_eq!(a.covariance() * scale, *b.covariance());
        }
        // A covariance that is not positive semi-definite (a velocity–clock covariance far
        // beyond the two variances) makes an update overflow: it is refused and the filter
        // is left as it was.
        let mut p = StateMatrix::identity();
        p[(idx::ISB_BDS, idx::ISB_BDS)] = 0.0;
        p[(idx::VEL[1], idx::CLOCK_BIAS)] = 1e200;
        p[(idx::CLOCK_BIAS, idx::VEL[1])] = 1e200;
        let mut c = Ekf11::new(cfg).unwrap();
        c.set_state(*a.state(), p).unwrap();
        let before = c.clone();
        let mut m = ms[0];
        m.range_rate_mps = None;
        m.pseudorange_m = (m.emitter_pos_ecef_m - a.position_ecef()).norm() + a.clock_bias_m();
        assert_eq!(
            c.update_range(&m).range.reject_reason(),
            Some(RejectReason::NumericalFailure)
        );
        assert_eq!(
            (c.state(), c.covariance()),
            (before.state(), before.covariance())
        );
    }
}
