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
//! sign used here and in [`crate::fusion::measurement::RangeMeasurement`]. Eq. 17 also drops
//! the position derivative of the range rate; it is kept here because it costs nothing
//! and is the exact Jacobian. For satellites it is below |v_s − v|/‖r_s − r‖ ≈ 4·10⁻⁵ per
//! metre and changes nothing; for a nearby tower seen from a moving car it is the correct
//! linearisation.
//!
//! # Update
//!
//! Ranges and range rates are processed as sequential scalar updates (the measurement
//! noises are independent), each relinearised at the latest estimate, with no heap
//! allocation. The covariance update is the Joseph form
//! `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, evaluated in its expanded form
//! `P − K Cᵀ − C Kᵀ + K S Kᵀ` (with `C = P Hᵀ`, `S = H P Hᵀ + R`), which is the same
//! polynomial in `K` and so keeps the Joseph form's first-order insensitivity to errors in
//! the gain while costing O(n²) for a scalar measurement. Each update is checked: an
//! innovation whose normalised square (NIS) exceeds the gate is rejected, and an update
//! that would write a non-finite or negative-variance result is refused and leaves the
//! filter unchanged.

use crate::core::{System, C_MPS};
use crate::fusion::measurement::{PositionFix, RangeMeasurement};
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
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
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
        }
    }
}

impl Ekf11Config {
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
    Gate,
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
    initialised: bool,
}

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
        let t = dt_s;
        let (t2, t3) = (t * t, t * t * t);
        let (t4, t5) = (t3 * t, t3 * t2);
        let mut q = StateMatrix::zeros();
        for axis in 0..3 {
            let s = cfg.accel_psd_m2ps5[axis];
            let ix = [idx::POS[axis], idx::VEL[axis], idx::ACC[axis]];
            let block = [
                [t5 / 20.0, t4 / 8.0, t3 / 6.0],
                [t4 / 8.0, t3 / 3.0, t2 / 2.0],
                [t3 / 6.0, t2 / 2.0, t],
            ];
            for (i, row) in block.iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    q[(ix[i], ix[j])] = s * v;
                }
            }
        }
        let (st, sf) = (cfg.clock_bias_psd_m2ps, cfg.clock_drift_psd_m2ps3);
        let (b, d) = (idx::CLOCK_BIAS, idx::CLOCK_DRIFT);
        q[(b, b)] = st * t + sf * t3 / 3.0;
        q[(b, d)] = sf * t2 / 2.0;
        q[(d, b)] = sf * t2 / 2.0;
        q[(d, d)] = sf * t;
        if let Some(isb) = &cfg.isb_bds {
            q[(idx::ISB_BDS, idx::ISB_BDS)] = isb.psd_m2ps * t;
        }
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
        // Φ is the identity plus seven entries, so Φx and ΦPΦᵀ are applied as row and
        // column operations (O(n) and O(n²)) rather than as dense products (O(n³)).
        let mut x = self.x;
        apply_transition_rows(&mut x, dt_s);
        let mut p = self.p;
        apply_transition_rows(&mut p, dt_s);
        let mut p = p.transpose();
        apply_transition_rows(&mut p, dt_s);
        p += Self::process_noise(&self.cfg, dt_s);
        symmetrise(&mut p);
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            return Err(Ekf11Error::NumericalFailure);
        }
        self.x = x;
        self.p = p;
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
        let mut h = StateVector::zeros();
        for axis in 0..3 {
            h[idx::POS[axis]] = -u[axis];
        }
        h[idx::CLOCK_BIAS] = 1.0;
        let mut predicted_m = dist_m + self.x[idx::CLOCK_BIAS];
        if m.system() == System::Bds && self.isb_active() {
            h[idx::ISB_BDS] = 1.0;
            predicted_m += self.x[idx::ISB_BDS];
        }
        let gate = self.cfg.gate_chi2;
        self.scalar_update(
            &h,
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
        let mut h = StateVector::zeros();
        for axis in 0..3 {
            h[idx::POS[axis]] = d_pos[axis];
            h[idx::VEL[axis]] = -u[axis];
        }
        h[idx::CLOCK_DRIFT] = 1.0;
        let predicted_mps = u_dot_w + self.x[idx::CLOCK_DRIFT];
        let gate = self.cfg.gate_chi2;
        self.scalar_update(
            &h,
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
                    reason: RejectReason::Gate,
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

    /// One scalar update with row Jacobian `h`, innovation `z − h(x)` and noise variance
    /// `r_var`; Joseph form expanded for a scalar (see the module documentation).
    fn scalar_update(
        &mut self,
        h: &StateVector,
        innovation: f64,
        r_var: f64,
        gate: Option<f64>,
    ) -> UpdateOutcome {
        const NS: usize = N_STATES;
        // h has four to seven non-zero entries, so P h is a sum of that many columns of P
        // rather than a dense product.
        let p = self.p.as_slice();
        let mut ph = [0.0; NS];
        for (c, &hc) in h.iter().enumerate() {
            if hc != 0.0 {
                let col = &p[c * NS..(c + 1) * NS];
                for (o, &v) in ph.iter_mut().zip(col) {
                    *o += hc * v;
                }
            }
        }
        let s = h.iter().zip(&ph).map(|(a, b)| a * b).sum::<f64>() + r_var;
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
                    reason: RejectReason::Gate,
                };
            }
        }
        let k: [f64; NS] = std::array::from_fn(|i| ph[i] / s);
        let x_new = self.x + StateVector::from(k) * innovation;
        // Joseph form expanded for a scalar: P⁺_ij = P_ij − (k_i c_j + c_i k_j) + s (k_i k_j)
        // with c = P h. Grouped this way every term is symmetric in (i, j) to the last bit,
        // so the full square (which vectorises) is as symmetric as the upper triangle was.
        // Column-major [[f64; 12]; 12] arrays let the compiler drop every bounds check.
        let old: [[f64; NS]; NS] = self.p.into();
        let mut new = [[0.0; NS]; NS];
        for ((col, old_col), (&kj, &cj)) in new.iter_mut().zip(&old).zip(k.iter().zip(&ph)) {
            for (((v, &o), &ki), &ci) in col.iter_mut().zip(old_col).zip(&k).zip(&ph) {
                *v = o - (ki * cj + ci * kj) + s * (ki * kj);
            }
        }
        self.commit(x_new, StateMatrix::from(new), nis)
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
        UpdateOutcome::Accepted { nis }
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

/// χ² distribution functions for filter-consistency tests (NEES, NIS).
///
/// The CDF is the regularised lower incomplete gamma function `P(k/2, x/2)`, evaluated by
/// its power series for `x < a + 1` and by Lentz's continued fraction for its complement
/// otherwise (Press et al., *Numerical Recipes*, 3rd ed., §6.2); `ln Γ` is Lanczos'
/// approximation with g = 7, n = 9 (error below 1e-15). The quantile starts from the
/// Wilson–Hilferty approximation and is polished by safeguarded Newton steps on the CDF.
///
/// Wilson–Hilferty (1931): `(X/k)^{1/3}` is nearly normal with mean `1 − 2/(9k)` and
/// variance `2/(9k)`, so `χ²_p(k) ≈ k·(1 − 2/(9k) + z_p·√(2/(9k)))³` with `z_p` the
/// standard normal quantile. Its relative error is below 1 % for k ≥ 3 and shrinks as
/// k grows; at k = 1 it is a few per cent in the tails.
pub mod chi2 {
    /// Natural log of the gamma function for `x > 0` (Lanczos, g = 7, n = 9).
    pub fn ln_gamma(x: f64) -> f64 {
        const G: f64 = 7.0;
        const COEF: [f64; 9] = [
            0.999_999_999_999_809_9,
            676.520_368_121_885_1,
            -1_259.139_216_722_402_8,
            771.323_428_777_653_1,
            -176.615_029_162_140_6,
            12.507_343_278_686_905,
            -0.138_571_095_265_720_12,
            9.984_369_578_019_572e-6,
            1.505_632_735_149_311_6e-7,
        ];
        if x < 0.5 {
            // Reflection: Γ(x)Γ(1 − x) = π / sin(πx).
            let pi = std::f64::consts::PI;
            return (pi / (pi * x).sin()).abs().ln() - ln_gamma(1.0 - x);
        }
        let x = x - 1.0;
        let mut a = COEF[0];
        for (i, &c) in COEF.iter().enumerate().skip(1) {
            a += c / (x + i as f64);
        }
        let t = x + G + 0.5;
        0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
    }

    /// Regularised lower incomplete gamma function `P(a, x)`, `a > 0`, `x ≥ 0`.
    pub fn gamma_p(a: f64, x: f64) -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        let log_prefactor = -x + a * x.ln() - ln_gamma(a);
        if x < a + 1.0 {
            // Series: P = e^{−x} x^a / Γ(a) · Σ x^n / (a (a+1) … (a+n)).
            let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
            for _ in 0..10_000 {
                ap += 1.0;
                term *= x / ap;
                sum += term;
                if term.abs() < sum.abs() * 1e-17 {
                    break;
                }
            }
            (sum.ln() + log_prefactor).exp().min(1.0)
        } else {
            // Continued fraction for Q = 1 − P (modified Lentz).
            let tiny = 1e-300;
            let mut b = x + 1.0 - a;
            let mut c = 1.0 / tiny;
            let mut d = 1.0 / b;
            let mut h = d;
            for i in 1..10_000 {
                let an = -(i as f64) * (i as f64 - a);
                b += 2.0;
                d = an * d + b;
                if d.abs() < tiny {
                    d = tiny;
                }
                c = b + an / c;
                if c.abs() < tiny {
                    c = tiny;
                }
                d = 1.0 / d;
                let delta = d * c;
                h *= delta;
                if (delta - 1.0).abs() < 1e-16 {
                    break;
                }
            }
            (1.0 - (log_prefactor.exp() * h)).max(0.0)
        }
    }

    /// CDF of χ²(k) at `x`.
    pub fn cdf(x: f64, dof: f64) -> f64 {
        gamma_p(0.5 * dof, 0.5 * x)
    }

    /// Standard normal quantile, used for the Wilson–Hilferty start (see
    /// [`crate::core::stats::normal_quantile`]).
    pub use crate::core::stats::normal_quantile;

    /// Wilson–Hilferty approximation of the χ²(k) quantile at probability `p`.
    pub fn quantile_wilson_hilferty(p: f64, dof: f64) -> f64 {
        let v = 2.0 / (9.0 * dof);
        let c = 1.0 - v + normal_quantile(p) * v.sqrt();
        dof * (c.max(0.0)).powi(3)
    }

    /// The χ²(k) quantile at probability `p` (0 < p < 1), accurate to about 1e-12
    /// relative: Wilson–Hilferty, then Newton on the CDF inside a shrinking bracket.
    pub fn quantile(p: f64, dof: f64) -> f64 {
        if !(p > 0.0 && p < 1.0 && dof > 0.0) {
            return f64::NAN;
        }
        let a = 0.5 * dof;
        let ln_norm = a * 2f64.ln() + ln_gamma(a);
        let pdf = |x: f64| ((a - 1.0) * x.ln() - 0.5 * x - ln_norm).exp();
        let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
        let mut x = quantile_wilson_hilferty(p, dof).max(1e-300);
        for _ in 0..200 {
            let f = cdf(x, dof) - p;
            if f == 0.0 {
                return x;
            }
            if f < 0.0 {
                lo = lo.max(x);
            } else {
                hi = hi.min(x);
            }
            let step = f / pdf(x);
            let mut next = x - step;
            // Keep the iterate inside the bracket: bisect (or expand) when Newton leaves it.
            if !(next.is_finite() && next > lo && next < hi) {
                next = if hi.is_finite() {
                    0.5 * (lo + hi)
                } else {
                    2.0 * x.max(lo) + 1.0
                };
            }
            if (next - x).abs() <= 1e-14 * x.abs() {
                return next;
            }
            x = next;
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, Geodetic};
    use approx::assert_relative_eq;

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
}
