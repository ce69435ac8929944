//! The tightly coupled INS: the 15-state error-state filter of [`super::ins_ekf`] extended
//! by the receiver clock, updated with each pseudorange and pseudorange rate directly
//! instead of with a least-squares fix (Groves, *Principles of GNSS, Inertial, and
//! Multisensor Integrated Navigation Systems*, 2nd ed., 2013, §14.3.3; the measurement
//! model is seed 000's, eqs. 9–17, as [`crate::fusion::ekf11`] uses it).
//!
//! # Why
//!
//! A loosely coupled INS needs a position fix, and a fix needs four ranges on one clock
//! (five with a BeiDou inter-system bias). Under a bridge or in a deep canyon, where two
//! satellites of each system are left, the fix is missing or poor and the INS coasts. In
//! the tight filter every range still corrects the INS along its line of sight, with the
//! clock carried by the filter from the epochs before: fewer than four ranges still help.
//!
//! # State
//!
//! X = [δr, δv, ψ, δα, δε, δb, δḃ, δisb_bds] (18): the loosely coupled filter's 15 error
//! states, then the errors of the receiver clock bias `b = c·δt` (m), its drift `ḃ` (m/s)
//! and the BeiDou inter-system bias (m). Errors are estimate minus truth throughout, and
//! the closed loop feeds every estimated error back and resets it to zero after each
//! update, as in [`super::ins_ekf::InsEkf`].
//!
//! GPS, DTMB and TC-OFDM ranges share the clock `b` (seed 000 §5.1: the DTMB receiver is
//! triggered from the GPS 1PPS; DTMB single-frequency networks run on GPS time) and BeiDou
//! ranges see `b + isb_bds`.
//!
//! # Dynamics
//!
//! The navigation block is the loosely coupled filter's Φ = I + F Δt. The clock is two
//! integrators driven by white frequency and white frequency-rate noise (Brown & Hwang,
//! 4th ed., §9.3; seed 000 eq. 8) and the inter-system bias a random walk:
//!
//! ```text
//! Φ_c = [[1, Δt], [0, 1]],   Q_c = [[S_t Δt + S_f Δt³/3, S_f Δt²/2], [S_f Δt²/2, S_f Δt]]
//! Q_isb = S_isb Δt
//! ```
//!
//! # Measurements
//!
//! With `u` the unit vector from the receiver to the emitter (ECEF), `r̂` the INS position
//! moved to the measurement time by its velocity, and `R` the ECEF → ENU rotation:
//!
//! ```text
//! pseudorange   ρ̂ = ‖r_s − r̂‖ + b̂ (+ isb̂ for BDS)    z = ρ̂ − ρ,  H = [−(R u)ᵀ 0 0 0 0 | 1 0 (1)]
//! range rate    ρ̂̇ = u·(v_s − v̂) + ḃ̂                  z = ρ̂̇ − ρ̇,  H = [0 −(R u)ᵀ 0 0 0 | 0 1 0]
//! ```
//!
//! Each is a scalar update in the Joseph form, gated on its normalised innovation squared
//! at the χ²(1) 99.9 % quantile by default, as the EKF rows are
//! ([`crate::fusion::ekf11::CHI2_1DOF_P999`]); a position fix (FM, a magnetic landmark) is a
//! three-dimensional update with H = [I₃ 0].
//!
//! # Clock initialisation
//!
//! The clock starts diffuse: b̂ = 0 with σ = 1 ms (3·10⁵ m, the span of a receiver clock
//! that keeps itself within a millisecond of GPS time), so the first range of the first
//! epoch sets it and nothing else; the drift and inter-system-bias priors are the EKF's
//! ([`crate::fusion::ekf11::Ekf11Config`], [`crate::fusion::ekf11::IsbConfig`]).

use super::ins_ekf::{
    feed_back_nav, initial_covariance, joseph_update, mechanise, process_noise_rate, Cov15,
    FixOutcome, InsEkfConfig, InsFixError, JosephStep,
};
use super::ins_family::{InsKalmanConfig, InsKalmanKind};
use super::strapdown::{NavState, Strapdown};
use super::LocalEarth;
use crate::core::{EnuFrame, System};
use crate::fusion::ekf11::{Ekf11Config, IsbConfig, RejectReason, UpdateOutcome};
use crate::fusion::kalman::{
    Ekf, FilterError, Gating, RelativeEntropyKf, ResidualGate, SigmaPointKf,
};
use crate::fusion::models::MeasurementModel;
use crate::measurement::{ImuSample, RangeMeasurement};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Number of error states.
pub const N_TIGHT: usize = 18;
/// The error covariance.
pub type Cov18 = SMatrix<f64, N_TIGHT, N_TIGHT>;

/// Indices of the clock states after the 15 navigation states.
pub mod tidx {
    /// Receiver clock bias `c·δt` (m), shared by GPS, DTMB and TC-OFDM.
    pub const CLOCK_BIAS: usize = 15;
    /// Receiver clock drift (m/s).
    pub const CLOCK_DRIFT: usize = 16;
    /// BeiDou inter-system bias (m).
    pub const ISB_BDS: usize = 17;
}

/// An 18-state error vector.
pub type State18 = SVector<f64, N_TIGHT>;

/// One scalar measurement of the tight filter as a function of the error state `δ`
/// (estimate minus truth), for the generic filters of seed 004's comparison.
///
/// A pseudorange with `ℓ` the vector from the INS position to the emitter (ENU m) is
/// predicted minus true range: the true receiver is at `r̂ − δr`, so
///
/// ```text
/// h(δ) = ‖ℓ‖ − ‖ℓ + δr‖ + δb (+ δisb),   ∂h/∂δr = −(ℓ + δr)ᵀ / ‖ℓ + δr‖
/// ```
///
/// which is the module's linear row at `δ = 0` and curves with `1/‖ℓ‖`: a TC-OFDM base
/// station 50 m away bends the range by `σ²/(2·50 m)` across a position prior of σ, which
/// is what separates the CKF from the EKF and gives the relative-entropy filter a non-zero
/// coupling degree χ. A range rate is the linear row `h(δ) = hᵀδ`.
#[derive(Clone, Copy, Debug)]
pub struct TightScalarModel {
    /// The receiver → emitter vector (ENU m) of a pseudorange; `None` for a linear row.
    pub los_enu_m: Option<Vector3<f64>>,
    /// The linear row (for a pseudorange: the clock and inter-system-bias entries are
    /// used, the position entries are replaced by the exact geometry).
    pub h: State18,
    /// The noise variance.
    pub r: f64,
}

impl MeasurementModel<N_TIGHT, 1> for TightScalarModel {
    fn h(&self, x: &State18) -> SVector<f64, 1> {
        match self.los_enu_m {
            Some(l) => {
                let dr: Vector3<f64> = x.fixed_rows::<3>(0).into_owned();
                let clock = self.h.dot(x) - self.h.fixed_rows::<3>(0).dot(&dr);
                SVector::<f64, 1>::new(l.norm() - (l + dr).norm() + clock)
            }
            None => SVector::<f64, 1>::new(self.h.dot(x)),
        }
    }
    fn jacobian(&self, x: &State18) -> SMatrix<f64, 1, N_TIGHT> {
        let mut j = self.h.transpose();
        if let Some(l) = self.los_enu_m {
            let v = l + x.fixed_rows::<3>(0);
            let n = v.norm();
            for i in 0..3 {
                j[i] = -v[i] / n;
            }
        }
        j
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(self.r)
    }
}

/// The generic filter that takes the tight filter's scalar updates (seed 004's
/// comparison). Each update restarts it from the zero error state and the tight filter's
/// covariance, so it only decides the update; propagation and feedback stay the tight
/// filter's.
#[derive(Clone, Debug)]
enum TightCore {
    Ekf(Box<Ekf<N_TIGHT>>),
    Ckf(Box<SigmaPointKf<N_TIGHT>>),
    Rekf(Box<RelativeEntropyKf<N_TIGHT>>),
}

/// The strong tracking filter's memory on the tight filter: the propagated part `Φ P Φᵀ`
/// and the process noise `Q` since the last update, kept apart so that one fading factor
/// per epoch inflates the propagated part only (Zhou & Frank's `P⁻ = λ Φ P Φᵀ + Q`), and
/// the smoothed innovation statistic `V` (see [`crate::fusion::kalman::EpochFading`],
/// the same statistic for whitened scalar rows).
#[derive(Clone, Debug)]
struct TightFading {
    forgetting: f64,
    weakening: f64,
    max_fading: f64,
    fpf: Cov18,
    q: Cov18,
    pending: bool,
    v: Option<f64>,
    last_lambda: f64,
}

/// One millisecond of receiver clock in metres: the diffuse prior of the clock bias.
const DIFFUSE_CLOCK_SIGMA_M: f64 = 1.0e-3 * crate::core::C_MPS;

/// The clock model and the range gate of [`InsTightEkf`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TightClockConfig {
    /// `S_t` (m²/s).
    pub clock_bias_psd_m2ps: f64,
    /// `S_f` (m²/s³).
    pub clock_drift_psd_m2ps3: f64,
    /// Initial σ of the clock bias (m).
    pub init_clock_bias_sigma_m: f64,
    /// Initial σ of the clock drift (m/s).
    pub init_clock_drift_sigma_mps: f64,
    /// Initial σ of the BeiDou inter-system bias (m).
    pub isb_bds_init_sigma_m: f64,
    /// Random-walk PSD of the inter-system bias (m²/s).
    pub isb_bds_psd_m2ps: f64,
    /// NIS gate of each scalar range or range-rate update (χ²(1)); `None` accepts all.
    pub gate_chi2: Option<f64>,
}

impl Default for TightClockConfig {
    /// The EKF rows' TCXO, drift prior, inter-system-bias model and gate, and a diffuse
    /// clock bias.
    fn default() -> Self {
        let ekf = Ekf11Config::default();
        let isb = IsbConfig::default();
        Self {
            clock_bias_psd_m2ps: ekf.clock_bias_psd_m2ps,
            clock_drift_psd_m2ps3: ekf.clock_drift_psd_m2ps3,
            init_clock_bias_sigma_m: DIFFUSE_CLOCK_SIGMA_M,
            init_clock_drift_sigma_mps: ekf.init_clock_drift_sigma_mps,
            isb_bds_init_sigma_m: isb.initial_sigma_m,
            isb_bds_psd_m2ps: isb.psd_m2ps,
            gate_chi2: ekf.gate_chi2,
        }
    }
}

/// The closed-loop tightly coupled INS / range Kalman filter.
#[derive(Clone, Debug)]
pub struct InsTightEkf {
    ins: Strapdown,
    p: Cov18,
    q_nav_rate: SVector<f64, 15>,
    inv_tau: f64,
    accel_bias_mps2: Vector3<f64>,
    gyro_bias_rps: Vector3<f64>,
    clock_bias_m: f64,
    clock_drift_mps: f64,
    isb_bds_m: f64,
    clock: TightClockConfig,
    /// The implausible-jump bound on a position fix's NIS (χ²(3)).
    position_gate: Option<f64>,
    /// Seed 004's comparison: the generic filter deciding each scalar update (`None`: the
    /// module's own Joseph-form EKF with its χ² gate).
    generic: Option<TightCore>,
    /// The strong tracking filter's fading memory (`kalman = "stf"`).
    fading: Option<Box<TightFading>>,
    /// The RE-KF's coupling-degree factor ℵ of the last scalar update.
    last_aleph: Option<f64>,
    /// Seed 004's eq. 24 gate of the generic filters (the STF's statistic leaves out
    /// what it removes).
    residual_gate: Option<ResidualGate>,
    /// Variance (m²/s², ENU) of the IMU's velocity that a range rate does not describe
    /// (a walker's gait, [`Self::with_velocity_noise`]); zero by default.
    rate_velocity_var_enu: Vector3<f64>,
}

impl InsTightEkf {
    /// A filter starting at `initial` with zero bias estimates and the clock of `clock`.
    pub fn new(
        initial: NavState,
        earth: LocalEarth,
        cfg: &InsEkfConfig,
        clock: &TightClockConfig,
    ) -> Self {
        let (q, inv_tau) = process_noise_rate(cfg);
        let mut p = Cov18::zeros();
        p.fixed_view_mut::<15, 15>(0, 0)
            .copy_from(&initial_covariance(cfg));
        p[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)] = clock.init_clock_bias_sigma_m.powi(2);
        p[(tidx::CLOCK_DRIFT, tidx::CLOCK_DRIFT)] = clock.init_clock_drift_sigma_mps.powi(2);
        p[(tidx::ISB_BDS, tidx::ISB_BDS)] = clock.isb_bds_init_sigma_m.powi(2);
        Self {
            ins: Strapdown::new(initial, earth),
            p,
            q_nav_rate: q,
            inv_tau,
            accel_bias_mps2: Vector3::zeros(),
            gyro_bias_rps: Vector3::zeros(),
            clock_bias_m: 0.0,
            clock_drift_mps: 0.0,
            isb_bds_m: 0.0,
            clock: *clock,
            position_gate: cfg.nis_gate,
            generic: None,
            fading: None,
            last_aleph: None,
            residual_gate: None,
            rate_velocity_var_enu: Vector3::zeros(),
        }
    }

    /// The same filter with `[horizontal, vertical]` σ (m/s) of the IMU's motion that a
    /// range rate does not describe: the receiver reports the rate of the walk, while a
    /// handheld IMU also moves with the gait (the loosely coupled filter's
    /// `fix_velocity_noise_mps`, [`super::ins_estimator::InsFilterConfig`]). Along the
    /// unit vector `u` (ENU) to the emitter, a rate's variance becomes
    /// `σ_ρ̇² + σ_h² (u_e² + u_n²) + σ_v² u_u²`: the projection of the velocity noise
    /// `diag(σ_h², σ_h², σ_v²)` the loose filter adds to a fix velocity's covariance.
    pub fn with_velocity_noise(mut self, sigma_mps: [f64; 2]) -> Self {
        self.rate_velocity_var_enu = super::velocity_noise_var_enu(sigma_mps);
        self
    }

    /// The same filter with its scalar updates decided by one of seed 004's four filters
    /// (`k.kind`; [`InsKalmanKind::Builtin`] keeps the module's EKF): the EKF, the CKF or
    /// the RE-KF on [`TightScalarModel`], each with `k`'s eq. 24 gate and no χ² gate, or
    /// the EKF with Zhou & Frank's fading factor (`"stf"`, one factor per epoch over every
    /// scalar of the epoch, see [`InsTightEkf::stf_inflate`]).
    ///
    /// # Errors
    /// An unusable tuning.
    pub fn with_kalman(mut self, k: &InsKalmanConfig) -> Result<Self, FilterError> {
        let gating = Gating {
            chi2_prob: None,
            residual: k.residual_gate_c.map(ResidualGate::sigmas),
        };
        let (x0, p0) = (State18::zeros(), self.p);
        self.residual_gate = gating.residual;
        self.generic = match k.kind {
            InsKalmanKind::Builtin => None,
            InsKalmanKind::Ekf | InsKalmanKind::Stf => Some(TightCore::Ekf(Box::new(
                Ekf::new(x0, p0)?.with_gating(gating)?,
            ))),
            InsKalmanKind::Ckf => Some(TightCore::Ckf(Box::new(
                SigmaPointKf::cubature(x0, p0)?.with_gating(gating)?,
            ))),
            InsKalmanKind::Rekf => Some(TightCore::Rekf(Box::new(RelativeEntropyKf::new(
                x0,
                p0,
                k.aleph_threshold,
                gating.residual,
            )?))),
        };
        if k.kind == InsKalmanKind::Stf {
            let (rho, beta, lmax) = (k.stf_forgetting, k.stf_weakening, k.stf_max_fading);
            if !(rho > 0.0 && rho <= 1.0 && beta.is_finite() && beta >= 1.0 && lmax >= 1.0) {
                return Err(FilterError::InvalidParameter(format!(
                    "ρ = {rho}, β = {beta}, λ_max = {lmax}: expected 0 < ρ ≤ 1, β ≥ 1 and λ_max ≥ 1"
                )));
            }
            self.fading = Some(Box::new(TightFading {
                forgetting: rho,
                weakening: beta,
                max_fading: lmax,
                fpf: self.p,
                q: Cov18::zeros(),
                pending: false,
                v: None,
                last_lambda: 1.0,
            }));
        }
        Ok(self)
    }

    /// The RE-KF's coupling-degree factor ℵ of the last scalar update; `None` for the
    /// other filters.
    pub fn last_aleph(&self) -> Option<f64> {
        self.last_aleph
    }

    /// The strong tracking filter's fading factor of the last epoch; `None` for the other
    /// filters.
    pub fn last_fading_factor(&self) -> Option<f64> {
        self.fading.as_ref().map(|f| f.last_lambda)
    }

    /// The strong tracking filter's fading factor for this epoch (`kalman = "stf"`; a no-op
    /// returning `None` otherwise, or when nothing was propagated since the last update):
    /// with the epoch's `m` pseudoranges (and, with `rates`, range rates) `j`, their linear
    /// rows `h_j` whitened by `σ_j` and innovations `ν_j/σ_j` at the current solution,
    ///
    /// ```text
    /// ν̄² = Σ (ν_j/σ_j)² / m,   V_k = ν̄² (first epoch),   V_k = (ρ V_{k−1} + ν̄²)/(1 + ρ)
    /// c_k = (V_k − Σ h_j Q h_jᵀ / m − β) / (Σ h_j Φ P Φᵀ h_jᵀ / m)
    /// λ_k = min(λ_max, max(1, c_k)),   P⁻ = λ_k Φ P Φᵀ + Q
    /// ```
    /// (Zhou & Frank 1996's `tr N_k / tr M_k` for whitened scalar rows; an epoch whose
    /// clock bias is still at its diffuse prior does not enter V), applied before
    /// the epoch's sequential updates; a scalar the eq. 24 gate removes at the
    /// un-inflated prediction is left out. Only the batch given counts: when GNSS and
    /// TC-OFDM arrive as two batches of one epoch, the first one sets the factor. Does not
    /// allocate.
    pub fn stf_inflate<'a>(
        &mut self,
        ranges: impl IntoIterator<Item = &'a RangeMeasurement>,
        frame: &EnuFrame,
        lag_s: f64,
        rates: bool,
    ) -> Option<f64> {
        if !self.fading.as_ref().is_some_and(|f| f.pending) {
            return None;
        }
        let (mut nu2, mut hqh, mut hfh, mut m) = (0.0, 0.0, 0.0, 0usize);
        for meas in ranges {
            let rows = [
                self.range_row(meas, frame, lag_s),
                if rates {
                    self.rate_row(meas, frame, lag_s)
                } else {
                    None
                },
            ];
            for (z, model) in rows.into_iter().flatten() {
                let sigma = model.r.sqrt();
                let (nu, h) = (z / sigma, model.h / sigma);
                if !(nu.is_finite() && h.iter().all(|v| v.is_finite())) {
                    continue;
                }
                // The data layer (eq. 24, ahead of the filter in the paper's Fig. 3)
                // removes an outlier before the fading factor sees it, judged at the
                // un-inflated prediction. Counted, the NLOS GNSS ranges indoors keep V_k
                // high and the factor inflates the prediction epoch after epoch (measured
                // on worlds/seed004-bupt.toml, 20 trials: RMSE 45.6 m, largest error
                // 2.6 km, 8 resets; left out: 2.7 m, 27 m, none). The loosely coupled STF
                // keeps every component (see `StrongTrackingFilter`).
                let eps = model.h.dot(&(self.p * model.h)) + model.r;
                if self.residual_gate.is_some_and(|g| !g.keeps(z, eps)) {
                    continue;
                }
                let f = self.fading.as_ref()?;
                nu2 += nu * nu;
                hqh += h.dot(&(f.q * h));
                hfh += h.dot(&(f.fpf * h));
                m += 1;
            }
        }
        let f = self.fading.as_mut()?;
        if m == 0 {
            return None;
        }
        let k = m as f64;
        let v = match f.v {
            None => nu2 / k,
            Some(v0) => (f.forgetting * v0 + nu2 / k) / (1.0 + f.forgetting),
        };
        let c = (v - hqh / k - f.weakening) / (hfh / k);
        let lambda = if c.is_finite() {
            c.clamp(1.0, f.max_fading)
        } else {
            1.0
        };
        let p = f.fpf * lambda + f.q;
        let p = 0.5 * (p + p.transpose());
        if (0..N_TIGHT).any(|i| !(p[(i, i)].is_finite() && p[(i, i)] >= 0.0)) {
            return None;
        }
        // While the clock bias is still at its diffuse prior (the filter's first epoch,
        // σ = 1 ms·c), the innovations, whitened by the measurements' σ alone, are the
        // receiver clock the epoch resolves, not a model mismatch: its factor is computed
        // (c is small, M holding the same prior) but it does not seed the memory V, as
        // Zhou & Frank's V₀ is the first innovation of a filter with a proper prior.
        // Seeded with it, V ≈ 6·10⁵ held λ at its limit for the first 20 s of seed 004.
        let diffuse = f.fpf[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)]
            > 0.25 * DIFFUSE_CLOCK_SIGMA_M * DIFFUSE_CLOCK_SIGMA_M;
        if !diffuse {
            f.v = Some(v);
        }
        f.last_lambda = lambda;
        f.pending = false;
        f.fpf = p;
        f.q = Cov18::zeros();
        self.p = p;
        Some(lambda)
    }

    /// The corrected navigation solution.
    pub fn state(&self) -> &NavState {
        self.ins.state()
    }

    /// The error covariance (order δr, δv, ψ, δα, δε, δb, δḃ, δisb).
    pub fn covariance(&self) -> &Cov18 {
        &self.p
    }

    /// The position block of the covariance (ENU m²).
    pub fn position_covariance_m2(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// The navigation block of the covariance, as the loosely coupled filter reports it.
    pub fn navigation_covariance(&self) -> Cov15 {
        self.p.fixed_view::<15, 15>(0, 0).into_owned()
    }

    /// The receiver clock bias estimate (m).
    pub fn clock_bias_m(&self) -> f64 {
        self.clock_bias_m
    }

    /// The receiver clock drift estimate (m/s).
    pub fn clock_drift_mps(&self) -> f64 {
        self.clock_drift_mps
    }

    /// The BeiDou inter-system bias estimate (m).
    pub fn isb_bds_m(&self) -> f64 {
        self.isb_bds_m
    }

    /// Mechanises one IMU sample and propagates the covariance and the clock over the
    /// interval since the previous sample. Does not allocate.
    pub fn propagate(&mut self, s: &ImuSample) {
        let Some((dt, f, _)) = mechanise(
            &mut self.ins,
            s,
            &self.accel_bias_mps2,
            &self.gyro_bias_rps,
            self.inv_tau,
        ) else {
            return;
        };
        let mut phi = Cov18::identity();
        phi.fixed_view_mut::<15, 15>(0, 0)
            .copy_from(&(Cov15::identity() + f * dt));
        phi[(tidx::CLOCK_BIAS, tidx::CLOCK_DRIFT)] = dt;
        self.p = phi * self.p * phi.transpose();
        let propagated = self.p;
        for i in 0..15 {
            self.p[(i, i)] += self.q_nav_rate[i] * dt;
        }
        let (st, sf) = (
            self.clock.clock_bias_psd_m2ps,
            self.clock.clock_drift_psd_m2ps3,
        );
        let (b, d) = (tidx::CLOCK_BIAS, tidx::CLOCK_DRIFT);
        self.p[(b, b)] += st * dt + sf * dt.powi(3) / 3.0;
        self.p[(b, d)] += sf * dt * dt / 2.0;
        self.p[(d, b)] += sf * dt * dt / 2.0;
        self.p[(d, d)] += sf * dt;
        self.p[(tidx::ISB_BDS, tidx::ISB_BDS)] += self.clock.isb_bds_psd_m2ps * dt;
        self.p = 0.5 * (self.p + self.p.transpose());
        self.clock_bias_m += self.clock_drift_mps * dt;
        if let Some(fd) = self.fading.as_mut() {
            // P = Φ P Φᵀ + Q_k with P = F + Q: the propagated part and the noise apart.
            fd.fpf = phi * fd.fpf * phi.transpose();
            fd.q = phi * fd.q * phi.transpose() + (self.p - propagated);
            fd.pending = true;
        }
    }

    /// The Joseph-form update of an `M`-dimensional measurement with innovation `z`
    /// (predicted minus measured), Jacobian `h` and noise `r`, gated at `gate`
    /// ([`joseph_update`]); the estimated errors are then fed back. A result with a
    /// non-finite or negative variance is refused and leaves the filter unchanged.
    fn update<const M: usize>(
        &mut self,
        z: SVector<f64, M>,
        h: SMatrix<f64, M, N_TIGHT>,
        r: SMatrix<f64, M, M>,
        gate: Option<f64>,
        what: &'static str,
    ) -> Result<FixOutcome, InsFixError> {
        match joseph_update(&self.p, &z, &h, &r, gate, what)? {
            JosephStep::Gated { nis, state_led } => Ok(FixOutcome {
                nis,
                accepted: false,
                state_led,
            }),
            JosephStep::Update { nis, dx, p } => {
                if dx.iter().any(|v| !v.is_finite())
                    || (0..N_TIGHT).any(|i| !(p[(i, i)].is_finite() && p[(i, i)] >= 0.0))
                {
                    return Err(InsFixError::NotPositiveDefinite { what });
                }
                self.p = p;
                self.feed_back(&dx);
                Ok(FixOutcome {
                    nis,
                    accepted: true,
                    state_led: false,
                })
            }
        }
    }

    /// The scalar case of [`Self::update`] in O(n²): with `c = P h`, `s = hᵀ c + r` and
    /// `k = c / s`, the Joseph form `(I − k hᵀ) P (I − k hᵀ)ᵀ + r k kᵀ` expands to
    /// `P − k cᵀ − c kᵀ + s k kᵀ`, written `P − (k eᵀ + e kᵀ)` with `e = c − (s/2) k`:
    /// the same polynomial in `k` (so the same first-order insensitivity to gain errors),
    /// symmetric by construction. Does not allocate.
    fn update_scalar(
        &mut self,
        z: f64,
        h: &SVector<f64, N_TIGHT>,
        r: f64,
        what: &'static str,
    ) -> Result<FixOutcome, InsFixError> {
        if !(z.is_finite() && r.is_finite() && h.iter().all(|v| v.is_finite())) {
            return Err(InsFixError::NonFinite { what });
        }
        let c = self.p * h;
        let s = h.dot(&c) + r;
        if !(s.is_finite() && s > 0.0) {
            return Err(InsFixError::NotPositiveDefinite { what });
        }
        let nis = z * z / s;
        if self.clock.gate_chi2.is_some_and(|g| nis > g) {
            return Ok(FixOutcome {
                nis,
                accepted: false,
                state_led: s - r >= r,
            });
        }
        let k = c / s;
        let e = c - k * (0.5 * s);
        let p = self.p - (k * e.transpose() + e * k.transpose());
        if (0..N_TIGHT).any(|i| !(p[(i, i)].is_finite() && p[(i, i)] >= 0.0)) {
            return Err(InsFixError::NotPositiveDefinite { what });
        }
        self.p = p;
        self.feed_back(&(k * z));
        Ok(FixOutcome {
            nis,
            accepted: true,
            state_led: false,
        })
    }

    fn feed_back(&mut self, dx: &SVector<f64, N_TIGHT>) {
        if let Some(fd) = self.fading.as_mut() {
            // After an update the whole covariance is the next epoch's propagated part.
            fd.fpf = self.p;
            fd.q = Cov18::zeros();
        }
        let nav: SVector<f64, 15> = dx.fixed_rows::<15>(0).into_owned();
        feed_back_nav(
            &mut self.ins,
            &mut self.accel_bias_mps2,
            &mut self.gyro_bias_rps,
            &nav,
        );
        self.clock_bias_m -= dx[tidx::CLOCK_BIAS];
        self.clock_drift_mps -= dx[tidx::CLOCK_DRIFT];
        self.isb_bds_m -= dx[tidx::ISB_BDS];
    }

    /// The receiver position (ECEF) and velocity (ECEF) the INS predicts `lag_s` after its
    /// last sample, and the unit vector from there to the emitter with its distance.
    fn geometry(
        &self,
        m: &RangeMeasurement,
        frame: &EnuFrame,
        lag_s: f64,
    ) -> (Vector3<f64>, Vector3<f64>, f64) {
        let st = self.ins.state();
        let rx = frame.ecef_of_enu(&(st.pos_enu_m + st.vel_enu_mps * lag_s));
        let v = frame.ecef_vector_of_enu(&st.vel_enu_mps);
        let los = m.emitter_pos_ecef_m - rx;
        let d = los.norm();
        (los / d, v, d)
    }

    /// The innovation (predicted minus measured) and the model of pseudorange `m`
    /// measured `lag_s` after the INS's last sample; `None` when its noise or geometry is
    /// unusable.
    fn range_row(
        &self,
        m: &RangeMeasurement,
        frame: &EnuFrame,
        lag_s: f64,
    ) -> Option<(f64, TightScalarModel)> {
        if !(m.sigma_m.is_finite() && m.sigma_m > 0.0) {
            return None;
        }
        let (u, _, d) = self.geometry(m, frame, lag_s);
        let bds = m.system() == System::Bds;
        let clock = self.clock_bias_m
            + self.clock_drift_mps * lag_s
            + if bds { self.isb_bds_m } else { 0.0 };
        let z = d + clock - m.pseudorange_m;
        let u_enu = frame.enu_vector_of_ecef(&u);
        let mut h = SVector::<f64, N_TIGHT>::zeros();
        for i in 0..3 {
            h[i] = -u_enu[i];
        }
        h[tidx::CLOCK_BIAS] = 1.0;
        if bds {
            h[tidx::ISB_BDS] = 1.0;
        }
        Some((
            z,
            TightScalarModel {
                los_enu_m: Some(u_enu * d),
                h,
                r: m.sigma_m * m.sigma_m,
            },
        ))
    }

    /// As [`Self::range_row`] for the pseudorange rate of `m`, if it has one.
    fn rate_row(
        &self,
        m: &RangeMeasurement,
        frame: &EnuFrame,
        lag_s: f64,
    ) -> Option<(f64, TightScalarModel)> {
        let rate = m.range_rate_mps?;
        if !(m.sigma_rate_mps.is_finite() && m.sigma_rate_mps > 0.0) {
            return None;
        }
        let (u, v, _) = self.geometry(m, frame, lag_s);
        let z = u.dot(&(m.emitter_vel_ecef_mps - v)) + self.clock_drift_mps - rate;
        let u_enu = frame.enu_vector_of_ecef(&u);
        let mut h = SVector::<f64, N_TIGHT>::zeros();
        for i in 0..3 {
            h[3 + i] = -u_enu[i];
        }
        h[tidx::CLOCK_DRIFT] = 1.0;
        let gait_var = u_enu.component_mul(&u_enu).dot(&self.rate_velocity_var_enu);
        Some((
            z,
            TightScalarModel {
                los_enu_m: None,
                h,
                r: m.sigma_rate_mps * m.sigma_rate_mps + gait_var,
            },
        ))
    }

    /// One scalar update by the module's EKF or, when set, by the generic filter.
    fn apply_row(
        &mut self,
        z: f64,
        model: &TightScalarModel,
        what: &'static str,
    ) -> Result<FixOutcome, InsFixError> {
        if self.generic.is_none() {
            return self.update_scalar(z, &model.h, model.r, what);
        }
        if !(z.is_finite() && model.r.is_finite() && model.h.iter().all(|v| v.is_finite())) {
            return Err(InsFixError::NonFinite { what });
        }
        let zv = SVector::<f64, 1>::new(z);
        let (x0, p0) = (State18::zeros(), self.p);
        let bad = InsFixError::NotPositiveDefinite { what };
        let mut aleph = None;
        let (rep, dx, p) = match self.generic.as_mut() {
            Some(TightCore::Ekf(f)) => {
                f.restart(x0, p0).map_err(|_| bad.clone())?;
                (f.update(model, &zv), *f.state(), *f.covariance())
            }
            Some(TightCore::Ckf(f)) => {
                f.restart(x0, p0).map_err(|_| bad.clone())?;
                (f.update(model, &zv), *f.state(), *f.covariance())
            }
            Some(TightCore::Rekf(f)) => {
                f.restart(x0, p0).map_err(|_| bad.clone())?;
                let (rep, coupling) = f.update(model, &zv);
                aleph = coupling.map(|c| c.aleph);
                (rep, *f.state(), *f.covariance())
            }
            None => return Err(bad),
        };
        if aleph.is_some() {
            self.last_aleph = aleph;
        }
        match rep.outcome {
            UpdateOutcome::Accepted { nis } => {
                if dx.iter().any(|v| !v.is_finite())
                    || (0..N_TIGHT).any(|i| !(p[(i, i)].is_finite() && p[(i, i)] >= 0.0))
                {
                    return Err(bad);
                }
                self.p = p;
                self.feed_back(&dx);
                Ok(FixOutcome {
                    nis,
                    accepted: true,
                    state_led: false,
                })
            }
            UpdateOutcome::Rejected {
                reason: RejectReason::NumericalFailure,
                ..
            } => Err(bad),
            UpdateOutcome::Rejected { nis, reason } => Ok(FixOutcome {
                nis,
                accepted: false,
                state_led: matches!(reason, RejectReason::Gate { state_led: true }),
            }),
        }
    }

    /// One pseudorange, measured `lag_s` after the INS's last sample (see the module
    /// documentation for the model).
    ///
    /// # Errors
    /// [`InsFixError`] for a non-finite measurement or noise that is not positive.
    pub fn update_range(
        &mut self,
        m: &RangeMeasurement,
        frame: &EnuFrame,
        lag_s: f64,
    ) -> Result<FixOutcome, InsFixError> {
        let what = "pseudorange";
        let (z, model) = self
            .range_row(m, frame, lag_s)
            .ok_or(InsFixError::NotPositiveDefinite { what })?;
        self.apply_row(z, &model, what)
    }

    /// One pseudorange rate, if the measurement has one (`Ok(None)` otherwise).
    ///
    /// # Errors
    /// As [`InsTightEkf::update_range`].
    pub fn update_range_rate(
        &mut self,
        m: &RangeMeasurement,
        frame: &EnuFrame,
        lag_s: f64,
    ) -> Result<Option<FixOutcome>, InsFixError> {
        if m.range_rate_mps.is_none() {
            return Ok(None);
        }
        let what = "pseudorange rate";
        let (z, model) = self
            .rate_row(m, frame, lag_s)
            .ok_or(InsFixError::NotPositiveDefinite { what })?;
        self.apply_row(z, &model, what).map(Some)
    }

    /// A position fix (ENU m) at the filter's time, with its covariance (m²).
    ///
    /// # Errors
    /// As [`InsTightEkf::update_range`].
    pub fn update_position(
        &mut self,
        pos_enu_m: &Vector3<f64>,
        cov_m2: &Matrix3<f64>,
    ) -> Result<FixOutcome, InsFixError> {
        let z = self.ins.state().pos_enu_m - pos_enu_m;
        let mut h = SMatrix::<f64, 3, N_TIGHT>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        self.update(z, h, *cov_m2, self.position_gate, "position")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, Geodetic};
    use crate::inertial::imu::{ImuConfig, ImuGrade};
    use nalgebra::UnitQuaternion;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::from_deg(40.0, 116.4, 50.0))
    }

    fn filter_at_rest(frame: &EnuFrame) -> InsTightEkf {
        let earth = crate::inertial::source::local_earth_of(frame);
        let cfg = InsEkfConfig::from_imu(&ImuConfig::grade(ImuGrade::Mid).resolve().unwrap());
        let st = NavState {
            t_s: 0.0,
            pos_enu_m: Vector3::zeros(),
            vel_enu_mps: Vector3::zeros(),
            q_nb: UnitQuaternion::identity(),
        };
        InsTightEkf::new(st, earth, &cfg, &TightClockConfig::default())
    }

    fn range(
        frame: &EnuFrame,
        system: System,
        az: f64,
        el: f64,
        rx_enu: Vector3<f64>,
    ) -> RangeMeasurement {
        let d_enu = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
        let e = frame.ecef_of_enu(&(d_enu * 2.0e7));
        RangeMeasurement {
            emitter: EmitterId { system, number: 1 },
            emitter_pos_ecef_m: e,
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m: (e - frame.ecef_of_enu(&rx_enu)).norm(),
            sigma_m: 3.0,
            range_rate_mps: None,
            sigma_rate_mps: 0.1,
            cn0_dbhz: 45.0,
            elevation_rad: el,
        }
    }

    #[test]
    fn the_first_range_sets_the_diffuse_clock_and_leaves_the_position() {
        // A diffuse clock prior (σ 3e5 m) against a 5 m position prior: the Kalman gain on
        // the clock is σ_b²/(σ_b² + ‖h_r‖² σ_r² + σ²) → 1, on the position ≈ 5²/σ_b² → 0.
        let f = frame();
        let mut k = filter_at_rest(&f);
        let mut m = range(&f, System::Gps, 0.3, 0.9, Vector3::zeros());
        m.pseudorange_m += 30_000.0; // a clock of 100 µs
        let o = k.update_range(&m, &f, 0.0).unwrap();
        assert!(o.accepted);
        let pb = DIFFUSE_CLOCK_SIGMA_M.powi(2);
        let expect = 30_000.0 * pb / (pb + 25.0 + 9.0);
        assert!(
            (k.clock_bias_m() - expect).abs() < 1e-6,
            "{}",
            k.clock_bias_m()
        );
        assert!(k.state().pos_enu_m.norm() < 1e-4);
        // The clock is now known to the range noise and the position uncertainty.
        let sb = k.covariance()[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)].sqrt();
        assert!((sb - (25.0f64 + 9.0).sqrt()).abs() < 1e-3, "{sb}");
    }

    #[test]
    fn a_range_with_a_known_clock_corrects_the_position_along_its_line_of_sight() {
        // With the clock pinned by many ranges, one more range 4 m long from straight
        // above moves the solution up by the scalar Kalman gain P/(P + σ²) on that axis.
        let f = frame();
        let mut k = filter_at_rest(&f);
        let dirs = [(0.0, 0.3), (2.1, 0.3), (4.2, 0.3)];
        for _ in 0..200 {
            for &(az, el) in &dirs {
                let m = range(&f, System::Gps, az, el, Vector3::zeros());
                k.update_range(&m, &f, 0.0).unwrap();
            }
        }
        let before = *k.state();
        let p = k.covariance();
        let mut m = range(
            &f,
            System::Gps,
            1.0,
            std::f64::consts::FRAC_PI_2,
            Vector3::zeros(),
        );
        m.pseudorange_m -= 4.0; // the receiver is 4 m higher than the INS says
                                // Predicted gain from the covariance: h = [−u, 1 at the clock].
        let mut h = SVector::<f64, N_TIGHT>::zeros();
        h[2] = -1.0;
        h[tidx::CLOCK_BIAS] = 1.0;
        let s = (h.transpose() * p * h)[0] + 9.0;
        let gain_up = (p * h)[2] / s;
        k.update_range(&m, &f, 0.0).unwrap();
        let moved = k.state().pos_enu_m.z - before.pos_enu_m.z;
        // z = ρ̂ − ρ = +4: δr_up = gain·4 is subtracted.
        assert!(
            (moved + gain_up * 4.0).abs() < 1e-6,
            "{moved} vs {}",
            -gain_up * 4.0
        );
        assert!(moved > 0.5, "{moved}");
    }

    #[test]
    fn the_scalar_update_is_the_joseph_form() {
        // The O(n²) scalar update against the dense Joseph form (I − K H) P (I − K H)ᵀ +
        // K R Kᵀ of the same range, after a few updates have correlated the states.
        let f = frame();
        let mut a = filter_at_rest(&f);
        for &(az, el) in &[(0.0, 0.5), (2.0, 0.6), (4.0, 0.7)] {
            a.update_range(&range(&f, System::Gps, az, el, Vector3::zeros()), &f, 0.0)
                .unwrap();
        }
        let mut b = a.clone();
        let mut m = range(&f, System::Bds, 1.0, 0.9, Vector3::zeros());
        m.pseudorange_m += 2.0;
        a.update_range(&m, &f, 0.0).unwrap();
        // The same range through the dense path.
        let (u, _, d) = b.geometry(&m, &f, 0.0);
        let u_enu = f.enu_vector_of_ecef(&u);
        let mut h = SMatrix::<f64, 1, N_TIGHT>::zeros();
        for i in 0..3 {
            h[(0, i)] = -u_enu[i];
        }
        h[(0, tidx::CLOCK_BIAS)] = 1.0;
        h[(0, tidx::ISB_BDS)] = 1.0;
        let z = d + b.clock_bias_m() + b.isb_bds_m() - m.pseudorange_m;
        b.update(
            SVector::<f64, 1>::new(z),
            h,
            SMatrix::<f64, 1, 1>::new(9.0),
            None,
            "pseudorange",
        )
        .unwrap();
        let scale = b.covariance().amax();
        assert!((a.covariance() - b.covariance()).amax() < 1e-9 * scale);
        assert!((a.state().pos_enu_m - b.state().pos_enu_m).norm() < 1e-9);
        assert!((a.isb_bds_m() - b.isb_bds_m()).abs() < 1e-9);
    }

    #[test]
    fn a_beidou_range_sees_the_inter_system_bias() {
        let f = frame();
        let mut k = filter_at_rest(&f);
        for _ in 0..50 {
            for (i, &(az, el)) in [(0.0, 0.5), (2.0, 0.6), (4.0, 0.7), (1.0, 1.2)]
                .iter()
                .enumerate()
            {
                let m = range(&f, System::Gps, az, el, Vector3::zeros());
                k.update_range(&m, &f, 0.0).unwrap();
                let mut b = range(&f, System::Bds, az + 0.5, el, Vector3::zeros());
                b.emitter.number = i as u16 + 1;
                b.pseudorange_m += 4.5; // 15 ns
                k.update_range(&b, &f, 0.0).unwrap();
            }
        }
        assert!((k.isb_bds_m() - 4.5).abs() < 0.2, "{}", k.isb_bds_m());
        assert!(k.clock_bias_m().abs() < 0.2, "{}", k.clock_bias_m());
        assert!(k.state().pos_enu_m.norm() < 0.2);
    }

    #[test]
    fn bad_ranges_are_typed_errors_and_outliers_are_gated() {
        let f = frame();
        let mut k = filter_at_rest(&f);
        let mut m = range(&f, System::Gps, 0.0, 0.5, Vector3::zeros());
        m.sigma_m = 0.0;
        assert!(k.update_range(&m, &f, 0.0).is_err());
        m.sigma_m = 3.0;
        m.pseudorange_m = f64::NAN;
        assert_eq!(
            k.update_range(&m, &f, 0.0).unwrap_err(),
            InsFixError::NonFinite {
                what: "pseudorange"
            }
        );
        // Pin the clock, then a range 500 m long is refused by the χ²(1) gate.
        for &(az, el) in &[(0.0, 0.5), (2.0, 0.6), (4.0, 0.7), (1.0, 1.2)] {
            k.update_range(&range(&f, System::Gps, az, el, Vector3::zeros()), &f, 0.0)
                .unwrap();
        }
        let before = k.clone();
        let mut m = range(&f, System::Gps, 3.0, 0.8, Vector3::zeros());
        m.pseudorange_m += 500.0;
        let o = k.update_range(&m, &f, 0.0).unwrap();
        assert!(!o.accepted && o.nis > 1000.0);
        assert_eq!(k.state(), before.state());
        assert_eq!(k.covariance(), before.covariance());
    }
    /// A fixed xorshift64* stream with Box–Muller normals, for the Monte Carlo truth.
    struct Normals(u64);
    impl Normals {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn pair(&mut self) -> (f64, f64) {
            let (u, v) = (self.uniform(), self.uniform());
            let r = (-2.0 * u.ln()).sqrt();
            let a = std::f64::consts::TAU * v;
            (r * a.cos(), r * a.sin())
        }
    }

    #[test]
    fn near_an_emitter_the_cubature_update_follows_the_range_curvature_and_the_ekf_does_not() {
        // Toy: a position prior of σ = 3 m per axis, a known clock, an emitter 50 m away,
        // and z = 0 (the measured range equals the predicted one). The true range is on
        // average longer than the predicted one by σ²·(3 − 1)/(2·50 m) = 0.18 m (second
        // order), so the best linear update moves the estimate, while the EKF (h
        // linearised at δ = 0, ẑ = 0) does not move at all. Truth: the linear MMSE update
        // with the moments of h(δ) from 400 000 Monte Carlo draws.
        let (sigma, d, r) = (3.0, 50.0, 0.25);
        let mut p = Cov18::identity() * 1e-6;
        for i in 0..3 {
            p[(i, i)] = sigma * sigma;
        }
        let l = Vector3::new(30.0, 40.0, 0.0);
        let mut h = State18::zeros();
        for i in 0..3 {
            h[i] = -l[i] / d;
        }
        h[tidx::CLOCK_BIAS] = 1.0;
        let model = TightScalarModel {
            los_enu_m: Some(l),
            h,
            r,
        };
        let z = SVector::<f64, 1>::new(0.0);
        let x0 = State18::zeros();
        let mut ekf = Ekf::new(x0, p).unwrap();
        let mut ckf = SigmaPointKf::cubature(x0, p).unwrap();
        let mut rekf = RelativeEntropyKf::new(x0, p, 1.0e3, None).unwrap();
        assert!(ekf.update(&model, &z).outcome.is_accepted());
        assert!(ckf.update(&model, &z).outcome.is_accepted());
        let (rep, coupling) = rekf.update(&model, &z);
        assert!(rep.outcome.is_accepted());
        let (mut rng, n) = (Normals(0x9e37_79b9_7f4a_7c15), 400_000);
        let (mut sh, mut shh, mut sxh) = (0.0, 0.0, Vector3::<f64>::zeros());
        for _ in 0..n {
            let (a, b) = rng.pair();
            let (c, _) = rng.pair();
            let mut x = State18::zeros();
            x[0] = sigma * a;
            x[1] = sigma * b;
            x[2] = sigma * c;
            let hz = model.h(&x)[0];
            sh += hz;
            shh += hz * hz;
            sxh += x.fixed_rows::<3>(0) * hz;
        }
        let nf = n as f64;
        let mean_h = sh / nf;
        let var_h = shh / nf - mean_h * mean_h;
        let cov_xh = sxh / nf;
        assert!((mean_h + sigma * sigma / d).abs() < 0.02, "E[h] = {mean_h}");
        let dx_mc = cov_xh * (0.0 - mean_h) / (var_h + r);
        let dx_ckf: Vector3<f64> = ckf.state().fixed_rows::<3>(0).into_owned();
        let dx_ekf: Vector3<f64> = ekf.state().fixed_rows::<3>(0).into_owned();
        assert!(dx_mc.norm() > 0.1, "{dx_mc}");
        assert!(
            (dx_ckf - dx_mc).norm() < 0.02,
            "CKF {dx_ckf} against MC {dx_mc}"
        );
        assert!(dx_ekf.norm() < 1e-12, "EKF moved {dx_ekf}");
        assert!((dx_ckf - dx_ekf).norm() > 0.1);
        // The RE-KF with no component left out is the cubature update, and its coupling
        // degree is not zero: χ is the curvature the best linear function misses.
        assert!((rekf.state() - ckf.state()).amax() < 1e-9);
        assert!(coupling.unwrap().aleph > 1e-4, "{:?}", coupling);
    }

    #[test]
    fn on_a_linear_row_the_rekf_and_the_ckf_are_the_kalman_filter() {
        // A range-rate row is linear in the error state: χ = 0, ℵ = 0, and the RE-KF and
        // the CKF give the Kalman posterior (the EKF's) to rounding.
        let f = frame();
        let k = filter_at_rest(&f);
        let mut m = range(&f, System::Gps, 0.3, 0.9, Vector3::zeros());
        m.range_rate_mps = Some(0.4);
        let (z, model) = k.rate_row(&m, &f, 0.0).unwrap();
        let mut p = *k.covariance();
        p[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)] = 4.0;
        let zv = SVector::<f64, 1>::new(z);
        let x0 = State18::zeros();
        let mut ekf = Ekf::new(x0, p).unwrap();
        let mut rekf = RelativeEntropyKf::new(x0, p, 0.3, None).unwrap();
        assert!(ekf.update(&model, &zv).outcome.is_accepted());
        let (rep, coupling) = rekf.update(&model, &zv);
        assert!(rep.outcome.is_accepted());
        let aleph = coupling.unwrap().aleph;
        // ℵ is zero but for the rounding of χ = P_zz − Ψᵀ P⁻¹ Ψ across a covariance
        // whose variances span 1e-12 to 1e1.
        assert!(aleph.abs() < 1e-8, "ℵ = {aleph}");
        assert!((rekf.state() - ekf.state()).amax() < 1e-12);
        assert!((rekf.covariance() - ekf.covariance()).amax() < 1e-12 * p.amax());
    }

    /// Six GPS ranges of [`range`] from the origin, each `offset_m` long (a common clock
    /// or position error).
    fn offset_ranges(f: &EnuFrame, offset_m: f64) -> Vec<RangeMeasurement> {
        (0..6)
            .map(|j| {
                let mut m = range(
                    f,
                    System::Gps,
                    j as f64,
                    0.5 + 0.1 * j as f64,
                    Vector3::zeros(),
                );
                m.pseudorange_m += offset_m;
                m
            })
            .collect()
    }

    /// One second of a perfect IMU at rest (100 samples) from `t0_s`.
    fn rest_one_second(k: &mut InsTightEkf, f: &EnuFrame, t0_s: f64) {
        let earth = crate::inertial::source::local_earth_of(f);
        for i in 1..=100 {
            k.propagate(&ImuSample {
                t_s: t0_s + i as f64 * 0.01,
                accel_mps2: Vector3::new(0.0, 0.0, earth.gravity_mps2(0.0)),
                gyro_rps: Vector3::zeros(),
            });
        }
    }

    /// The first epoch of a filter whose clock bias is at its diffuse prior resolves a
    /// 30 km receiver clock; its innovations (10⁴ σ) must not enter the fading memory V:
    /// at the next epoch, with ranges that fit, the factor is 1. Seeded with the first
    /// epoch (the rule before), V ≈ 10⁸ and the factor is at its limit.
    #[test]
    fn the_diffuse_clock_epoch_does_not_enter_the_stf_memory() {
        let f = frame();
        let kcfg = InsKalmanConfig {
            kind: InsKalmanKind::Stf,
            stf_max_fading: 10.0,
            ..InsKalmanConfig::default()
        };
        let mut k = filter_at_rest(&f).with_kalman(&kcfg).unwrap();
        let ms = offset_ranges(&f, 30_000.0);
        let mut lambdas = Vec::new();
        for epoch in 0..2 {
            rest_one_second(&mut k, &f, f64::from(epoch));
            lambdas.push(k.stf_inflate(ms.iter(), &f, 0.0, false).unwrap());
            for m in &ms {
                k.update_range(m, &f, 0.0).unwrap();
            }
        }
        assert!(k.clock_bias_m > 29_990.0, "clock {}", k.clock_bias_m);
        assert_eq!(lambdas, vec![1.0, 1.0]);
    }

    #[test]
    fn the_tight_stf_factor_never_exceeds_its_limit() {
        // Ranges 40 m off a filter that has coasted: c ≫ λ_max, so λ = λ_max exactly, and
        // P⁻ = λ_max Φ P Φᵀ + Q.
        let f = frame();
        let kcfg = InsKalmanConfig {
            kind: InsKalmanKind::Stf,
            stf_max_fading: 3.0,
            ..InsKalmanConfig::default()
        };
        let mut k = filter_at_rest(&f);
        // A known clock (σ 1 m, drift 0.1 m/s), so that the common 40 m offset is a
        // position error.
        k.p[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)] = 1.0;
        k.p[(tidx::CLOCK_DRIFT, tidx::CLOCK_DRIFT)] = 0.01;
        let mut k = k.with_kalman(&kcfg).unwrap();
        rest_one_second(&mut k, &f, 0.0);
        let before = *k.covariance();
        let fd = k.fading.as_ref().unwrap();
        let want = fd.fpf * 3.0 + fd.q;
        let ms = offset_ranges(&f, 40.0);
        let lambda = k.stf_inflate(ms.iter(), &f, 0.0, false);
        assert_eq!(lambda, Some(3.0));
        assert!((k.covariance() - want).amax() < 1e-9 * want.amax());
        assert!(k.covariance()[(0, 0)] > before[(0, 0)]);
        // Nothing propagated since: no second factor.
        assert!(k.stf_inflate(ms.iter(), &f, 0.0, false).is_none());
    }
}
