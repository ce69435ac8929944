//! Seed 004's four filters on the INS error state: the 15-state psi-angle error model
//! (eqs. 1–8, 14–15) as a [`ProcessModel`] and the loosely coupled position–velocity
//! differences (eqs. 16–19) as a [`MeasurementModel`], run by the generic EKF, CKF,
//! strong tracking filter and relative-entropy KF of [`crate::fusion::kalman`], closed
//! loop like [`super::ins_ekf::InsEkf`].
//!
//! # Discretisation at the fix rate (eqs. 25–28)
//!
//! The strapdown runs at the IMU rate; between two fixes the error dynamics
//! `F_k` of each sample interval (the same `F` as [`super::ins_ekf`],
//! [`super::ins_ekf::error_dynamics`]) are chained into one transition and one process noise,
//!
//! ```text
//! Φ_k = I + F_k Δt_k,   Q_k = diag(q) Δt_k            (per IMU sample, as InsEkf)
//! Φ  ← Φ_k Φ,           Q  ← Φ_k Q Φ_kᵀ + Q_k          (from the last fix to this one)
//! ```
//!
//! so that the filter predicts once per fix, `x⁻ = Φ x`, `P⁻ = Φ P Φᵀ + Q` (eqs. 27–28),
//! which is exactly the sample-by-sample propagation of `InsEkf` for the linear error
//! model, and gives the strong tracking filter one fading factor per fix over the whole
//! propagated part (Zhou & Frank's λ_k inflates `Φ P Φᵀ`).
//!
//! # Measurement (eqs. 16–19)
//!
//! `z = [r̂ − r_fix; v̂ − v_fix]`, `H = [I₆ 0₆ₓ₉]`, `R` the fix's covariance (with the
//! position–velocity cross term when the velocity is a difference of fixes).
//!
//! # Closed loop without resetting the generic filters
//!
//! `InsEkf` zeroes its error state after feeding it back. The generic filters keep their
//! state, so this filter keeps `a`, the corrections already applied, propagated with the
//! same `Φ` as the state, and the measurement model sees `h(x) = H (x − a)`: after a
//! feedback `x = a`, the corrected solution has zero predicted error, and the next
//! innovation is `z − H(Φx − Φa) = z`, exactly the closed-loop filter's (the error model
//! is linear, so `Φ` does not depend on `x`). The update then feeds `x⁺ − a` back into
//! the solution and the bias estimates and sets `a = x⁺`.
//!
//! # What the four filters do on this model
//!
//! The model is linear in the error state, so the cubature points of the CKF and the
//! RE-KF are propagated and measured exactly by their mean and covariance: the CKF equals
//! the EKF to rounding, and the RE-KF's unexplained spread `χ = P_zz − Ψᵀ P⁻¹ Ψ` is zero,
//! so its coupling-degree factor ℵ = ½ log|I + R⁻¹χ| is zero, every component passes the
//! ℵ threshold, and the RE-KF is the Kalman update with seed 004's eq. 24 residual gate.
//! The strong tracking filter differs by its fading factor.

use super::ins_ekf::{initial_covariance, mechanise, process_noise_rate, Cov15, InsEkfConfig};
use super::strapdown::{NavState, Strapdown};
use super::LocalEarth;
use crate::fusion::ekf11::RejectReason;
use crate::fusion::kalman::{
    Ekf, FilterError, Gating, RelativeEntropyKf, ResidualGate, SigmaPointKf, StrongTrackingFilter,
    UpdateOutcome, UpdateReport, DEFAULT_ALEPH_THRESHOLD,
};
use crate::fusion::models::{MeasurementModel, ProcessModel};
use crate::measurement::ImuSample;
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// A 15-state vector (order δr, δv, ψ, δα, δε).
pub type State15 = SVector<f64, 15>;
/// The 6 × 6 covariance of a position–velocity difference.
pub type Cov6 = SMatrix<f64, 6, 6>;

/// Which member of the Kalman family runs the INS error state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum InsKalmanKind {
    /// The hand-written closed-loop EKF of [`super::ins_ekf::InsEkf`] (the default).
    Builtin,
    /// The generic EKF (Joseph form).
    Ekf,
    /// The cubature Kalman filter.
    Ckf,
    /// The strong tracking filter.
    Stf,
    /// Seed 004's relative-entropy Kalman filter.
    Rekf,
}

/// The default upper limit λ_max of the strong tracking filter's fading factor: 10, the
/// same limit as the 12-state range filters' STF (`FamilyConfig::stf_max_fading` in
/// hybridnav-fusion). Zhou & Frank (1996) define no upper limit and seed 004 gives none;
/// 10 is an order of magnitude of inflation, a round value chosen before the seed-004
/// results were looked at, not fitted to them.
pub const DEFAULT_STF_MAX_FADING: f64 = 10.0;

/// The tuning of the generic filters on the INS error state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsKalmanConfig {
    /// The filter (not [`InsKalmanKind::Builtin`], which is not a generic filter).
    pub kind: InsKalmanKind,
    /// Seed 004's eq. 24 gate `|d_j| ≤ C·√ε_jj` on each component of the difference:
    /// `C`, or `None` for no gate.
    pub residual_gate_c: Option<f64>,
    /// RE-KF: ℵ_threshold (eq. 38).
    pub aleph_threshold: f64,
    /// STF: forgetting factor ρ and weakening factor β.
    pub stf_forgetting: f64,
    pub stf_weakening: f64,
    /// STF: the largest fading factor λ_max (`∞`: Zhou & Frank's unbounded factor).
    pub stf_max_fading: f64,
}

impl Default for InsKalmanConfig {
    fn default() -> Self {
        Self {
            kind: InsKalmanKind::Ekf,
            residual_gate_c: None,
            aleph_threshold: DEFAULT_ALEPH_THRESHOLD,
            stf_forgetting: 0.95,
            stf_weakening: 1.0,
            stf_max_fading: DEFAULT_STF_MAX_FADING,
        }
    }
}

/// The error-state transition and process noise accumulated since the last prediction.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorTransition {
    phi: Cov15,
    q: Cov15,
}

impl Default for ErrorTransition {
    fn default() -> Self {
        Self {
            phi: Cov15::identity(),
            q: Cov15::zeros(),
        }
    }
}

impl ErrorTransition {
    /// Chains one sample interval: `Φ ← (I + F Δt) Φ`, `Q ← (I + F Δt) Q (I + F Δt)ᵀ +
    /// diag(q_rate) Δt`. Does not allocate.
    pub fn push(&mut self, f: &Cov15, q_rate: &State15, dt_s: f64) {
        let phi_k = Cov15::identity() + f * dt_s;
        self.phi = phi_k * self.phi;
        let mut q = phi_k * self.q * phi_k.transpose();
        for i in 0..15 {
            q[(i, i)] += q_rate[i] * dt_s;
        }
        self.q = (q + q.transpose()) * 0.5;
    }

    /// Back to the identity transition with no noise (after a prediction).
    pub fn clear(&mut self) {
        self.phi = Cov15::identity();
        self.q = Cov15::zeros();
    }

    /// The accumulated transition Φ.
    pub fn phi(&self) -> &Cov15 {
        &self.phi
    }

    /// The accumulated process noise Q.
    pub fn q(&self) -> &Cov15 {
        &self.q
    }
}

/// The INS error model over the accumulated interval (eqs. 25, 27–28): `x⁻ = Φ x`,
/// Jacobian `Φ`, noise `Q`. The interval argument of [`ProcessModel`] is not used: the
/// interval is the one [`ErrorTransition`] accumulated.
pub struct InsErrorProcess<'a>(pub &'a ErrorTransition);

impl ProcessModel<15> for InsErrorProcess<'_> {
    fn f(&self, x: &State15, _dt_s: f64) -> State15 {
        self.0.phi * x
    }
    fn jacobian(&self, _x: &State15, _dt_s: f64) -> Cov15 {
        self.0.phi
    }
    fn q(&self, _x: &State15, _dt_s: f64) -> Cov15 {
        self.0.q
    }
}

/// The loosely coupled position–velocity difference (eqs. 16–19) of a closed-loop INS:
/// `h(x) = [I₆ 0] (x − a)` with `a` the corrections already fed back, noise `R`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsDifferenceModel {
    /// The corrections already applied (`a` of the module documentation).
    pub applied: State15,
    /// Covariance of the fix's position and velocity (m², m²/s).
    pub r: Cov6,
}

impl MeasurementModel<15, 6> for InsDifferenceModel {
    fn h(&self, x: &State15) -> SVector<f64, 6> {
        (x - self.applied).fixed_rows::<6>(0).into_owned()
    }
    fn jacobian(&self, _x: &State15) -> SMatrix<f64, 6, 15> {
        let mut h = SMatrix::<f64, 6, 15>::zeros();
        h.fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&SMatrix::<f64, 6, 6>::identity());
        h
    }
    fn r(&self) -> Cov6 {
        self.r
    }
}

/// The generic filter holding the error state.
#[derive(Clone, Debug)]
enum Core {
    Ekf(Box<Ekf<15>>),
    Ckf(Box<SigmaPointKf<15>>),
    Stf(Box<StrongTrackingFilter<15, 6>>),
    Rekf(Box<RelativeEntropyKf<15>>),
}

/// Seed 004's INS/fix integration under any of its four filters (see the module
/// documentation).
#[derive(Clone, Debug)]
pub struct InsFamilyFilter {
    ins: Strapdown,
    core: Core,
    transition: ErrorTransition,
    applied: State15,
    q_rate: State15,
    inv_tau: f64,
    accel_bias_mps2: Vector3<f64>,
    gyro_bias_rps: Vector3<f64>,
    last_aleph: Option<f64>,
}

impl InsFamilyFilter {
    /// A filter at `initial` with the initial covariance and IMU noise of `cfg`, run by
    /// the filter `k.kind`.
    ///
    /// # Errors
    /// A [`FilterError`] for an unusable prior or tuning, or for
    /// [`InsKalmanKind::Builtin`].
    pub fn new(
        initial: NavState,
        earth: LocalEarth,
        cfg: &InsEkfConfig,
        k: &InsKalmanConfig,
    ) -> Result<Self, FilterError> {
        let (q_rate, inv_tau) = process_noise_rate(cfg);
        let x0 = State15::zeros();
        let p0 = initial_covariance(cfg);
        let gating = Gating {
            chi2_prob: None,
            residual: k.residual_gate_c.map(ResidualGate::sigmas),
        };
        let core = match k.kind {
            InsKalmanKind::Builtin => {
                return Err(FilterError::InvalidParameter(
                    "the builtin INS filter is InsEkf, not a generic filter".into(),
                ))
            }
            InsKalmanKind::Ekf => Core::Ekf(Box::new(Ekf::new(x0, p0)?.with_gating(gating)?)),
            InsKalmanKind::Ckf => Core::Ckf(Box::new(
                SigmaPointKf::cubature(x0, p0)?.with_gating(gating)?,
            )),
            InsKalmanKind::Stf => Core::Stf(Box::new(
                StrongTrackingFilter::new(x0, p0, k.stf_forgetting, k.stf_weakening)?
                    .with_max_fading(k.stf_max_fading)?
                    .with_gating(gating)?,
            )),
            InsKalmanKind::Rekf => Core::Rekf(Box::new(RelativeEntropyKf::new(
                x0,
                p0,
                k.aleph_threshold,
                gating.residual,
            )?)),
        };
        Ok(Self {
            ins: Strapdown::new(initial, earth),
            core,
            transition: ErrorTransition::default(),
            applied: x0,
            q_rate,
            inv_tau,
            accel_bias_mps2: Vector3::zeros(),
            gyro_bias_rps: Vector3::zeros(),
            last_aleph: None,
        })
    }

    /// The corrected navigation solution.
    pub fn state(&self) -> &NavState {
        self.ins.state()
    }

    /// The error covariance at the last fix (order δr, δv, ψ, δα, δε).
    pub fn covariance(&self) -> &Cov15 {
        match &self.core {
            Core::Ekf(f) => f.covariance(),
            Core::Ckf(f) => f.covariance(),
            Core::Stf(f) => f.covariance(),
            Core::Rekf(f) => f.covariance(),
        }
    }

    fn error_state(&self) -> &State15 {
        match &self.core {
            Core::Ekf(f) => f.state(),
            Core::Ckf(f) => f.state(),
            Core::Stf(f) => f.state(),
            Core::Rekf(f) => f.state(),
        }
    }

    /// The position covariance now (ENU m²): the position rows of `Φ P Φᵀ + Q` over the
    /// samples since the last fix. Does not allocate.
    pub fn position_covariance_m2(&self) -> Matrix3<f64> {
        let phi_r = self.transition.phi.fixed_rows::<3>(0);
        let p = self.covariance();
        let c = phi_r * p * phi_r.transpose() + self.transition.q.fixed_view::<3, 3>(0, 0);
        (c + c.transpose()) * 0.5
    }

    /// The accelerometer bias estimate (m/s², body axes).
    pub fn accel_bias_mps2(&self) -> Vector3<f64> {
        self.accel_bias_mps2
    }

    /// The gyro bias estimate (rad/s, body axes).
    pub fn gyro_bias_rps(&self) -> Vector3<f64> {
        self.gyro_bias_rps
    }

    /// The RE-KF's coupling-degree factor ℵ of the last update (eq. 34); `None` for the
    /// other filters or before the first update.
    pub fn last_aleph(&self) -> Option<f64> {
        self.last_aleph
    }

    /// The strong tracking filter's fading factor λ of the last update; `None` for the
    /// other filters.
    pub fn last_fading_factor(&self) -> Option<f64> {
        match &self.core {
            Core::Stf(f) => Some(f.last_fading_factor()),
            _ => None,
        }
    }

    /// Mechanises one IMU sample (bias estimates removed) and chains its error transition,
    /// as [`super::ins_ekf::InsEkf::propagate`]. Does not allocate.
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
        self.transition.push(&f, &self.q_rate, dt);
    }

    /// Predicts the error state to now (eqs. 27–28) and updates it with the difference
    /// between the solution and the fix `pos_enu_m`, `vel_enu_mps` of covariance `r`
    /// (eqs. 16–19, with the filter's gates); an accepted correction is fed back. Does not
    /// allocate.
    pub fn update(
        &mut self,
        pos_enu_m: &Vector3<f64>,
        vel_enu_mps: &Vector3<f64>,
        r: &Cov6,
    ) -> UpdateReport {
        let process = InsErrorProcess(&self.transition);
        let predicted = match &mut self.core {
            Core::Ekf(f) => f.predict(&process, 0.0),
            Core::Ckf(f) => f.predict(&process, 0.0),
            Core::Stf(f) => f.predict(&process, 0.0),
            Core::Rekf(f) => f.predict(&process, 0.0),
        };
        if predicted.is_err() {
            return UpdateReport {
                outcome: UpdateOutcome::Rejected {
                    nis: f64::NAN,
                    reason: RejectReason::NumericalFailure,
                },
                used: 0,
                rejected: 6,
                rejected_state_led: 0,
            };
        }
        self.applied = self.transition.phi * self.applied;
        self.transition.clear();
        let st = *self.ins.state();
        let mut z = SVector::<f64, 6>::zeros();
        z.fixed_rows_mut::<3>(0)
            .copy_from(&(st.pos_enu_m - pos_enu_m));
        z.fixed_rows_mut::<3>(3)
            .copy_from(&(st.vel_enu_mps - vel_enu_mps));
        let model = InsDifferenceModel {
            applied: self.applied,
            r: *r,
        };
        let rep = match &mut self.core {
            Core::Ekf(f) => f.update(&model, &z),
            Core::Ckf(f) => f.update(&model, &z),
            Core::Stf(f) => f.update(&model, &z),
            Core::Rekf(f) => {
                let (rep, coupling) = f.update(&model, &z);
                self.last_aleph = coupling.map(|c| c.aleph);
                rep
            }
        };
        if rep.outcome.is_accepted() {
            let x = *self.error_state();
            let dx = x - self.applied;
            self.applied = x;
            self.feed_back(&dx);
        }
        rep
    }

    /// Applies the estimated errors to the solution and the bias estimates (as
    /// `InsEkf::feed_back`).
    fn feed_back(&mut self, dx: &State15) {
        let mut st = *self.ins.state();
        st.pos_enu_m -= dx.fixed_rows::<3>(0);
        st.vel_enu_mps -= dx.fixed_rows::<3>(3);
        let psi: Vector3<f64> = dx.fixed_rows::<3>(6).into();
        st.q_nb = UnitQuaternion::from_scaled_axis(psi) * st.q_nb;
        self.ins.set_state(st);
        self.accel_bias_mps2 += dx.fixed_rows::<3>(9);
        self.gyro_bias_rps += dx.fixed_rows::<3>(12);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inertial::imu::{ImuConfig, ImuGrade};
    use crate::inertial::ins_ekf::InsEkf;

    fn start() -> (NavState, LocalEarth, InsEkfConfig) {
        let earth = LocalEarth::new(0.7, 0.0);
        let cfg = InsEkfConfig::from_imu(&ImuConfig::grade(ImuGrade::Mid).resolve().unwrap());
        let st = NavState {
            t_s: 0.0,
            pos_enu_m: Vector3::zeros(),
            vel_enu_mps: Vector3::new(1.0, 0.5, 0.0),
            q_nb: UnitQuaternion::from_euler_angles(0.02, -0.01, 0.6),
        };
        (st, earth, cfg)
    }

    /// A body accelerating and turning slowly: (time, gyro, accel) at 100 Hz.
    fn sample(k: u64, earth: &LocalEarth) -> ImuSample {
        let t = k as f64 * 0.01;
        ImuSample {
            t_s: t,
            gyro_rps: Vector3::new(0.0, 0.0, 0.05 * (0.3 * t).sin()),
            accel_mps2: Vector3::new(0.3 * (0.5 * t).cos(), 0.1, earth.gravity_mps2(0.0)),
        }
    }

    #[test]
    fn generic_ekf_on_the_error_state_equals_the_builtin_filter() {
        // Second implementation: InsEkf propagates P sample by sample and resets its error
        // state; the generic EKF predicts once per fix with the chained Φ, Q and keeps the
        // applied corrections. On the same samples and fixes the solutions and covariances
        // must agree to rounding.
        let (st, earth, cfg) = start();
        let mut a = InsEkf::new(st, earth, &cfg);
        let mut b = InsFamilyFilter::new(st, earth, &cfg, &InsKalmanConfig::default()).unwrap();
        let mut pos_err = 0.0f64;
        let mut cov_err = 0.0f64;
        for k in 1..=3000u64 {
            let s = sample(k, &earth);
            a.propagate(&s);
            b.propagate(&s);
            if k % 100 == 0 {
                let sec = (k / 100) as f64;
                let pos = Vector3::new(1.0 * sec + 0.3 * sec.sin(), 0.5 * sec, 0.2 * sec.cos());
                let vel = Vector3::new(1.0, 0.5 + 0.1 * sec.sin(), 0.0);
                let pc = Matrix3::from_diagonal(&Vector3::new(1.0, 1.5, 4.0));
                let vc = Matrix3::identity() * 0.04;
                // Before the update: the predicted position covariances agree.
                let pa = a.covariance().fixed_view::<3, 3>(0, 0).into_owned();
                cov_err = cov_err.max((pa - b.position_covariance_m2()).amax() / pa.amax());
                a.update_position_velocity(&pos, &pc, &vel, &vc).unwrap();
                let mut r = Cov6::zeros();
                r.fixed_view_mut::<3, 3>(0, 0).copy_from(&pc);
                r.fixed_view_mut::<3, 3>(3, 3).copy_from(&vc);
                assert!(b.update(&pos, &vel, &r).outcome.is_accepted());
                pos_err = pos_err.max((a.state().pos_enu_m - b.state().pos_enu_m).amax());
                let rel = (a.covariance() - b.covariance()).amax() / a.covariance().amax();
                cov_err = cov_err.max(rel);
            }
        }
        assert!(pos_err < 1e-6, "position differs by {pos_err} m");
        assert!(cov_err < 1e-9, "covariance differs by {cov_err} (relative)");
        assert!((a.gyro_bias_rps() - b.gyro_bias_rps()).amax() < 1e-9);
        assert!((a.accel_bias_mps2() - b.accel_bias_mps2()).amax() < 1e-9);
    }

    #[test]
    fn on_the_linear_error_model_ckf_equals_ekf_and_the_rekf_coupling_is_zero() {
        // The error model and the difference measurement are linear, so the cubature rule
        // is exact: CKF = EKF to rounding, and the RE-KF's χ (eq. 35) vanishes, ℵ = 0.
        let (st, earth, cfg) = start();
        let mk = |kind| {
            InsFamilyFilter::new(
                st,
                earth,
                &cfg,
                &InsKalmanConfig {
                    kind,
                    ..InsKalmanConfig::default()
                },
            )
            .unwrap()
        };
        let mut f = [
            mk(InsKalmanKind::Ekf),
            mk(InsKalmanKind::Ckf),
            mk(InsKalmanKind::Rekf),
        ];
        let r = Cov6::from_diagonal(&SVector::<f64, 6>::new(1.0, 1.0, 4.0, 0.04, 0.04, 0.09));
        for k in 1..=1500u64 {
            let s = sample(k, &earth);
            for x in f.iter_mut() {
                x.propagate(&s);
            }
            if k % 100 == 0 {
                let sec = (k / 100) as f64;
                let pos = Vector3::new(sec, 0.5 * sec, 0.3);
                let vel = Vector3::new(1.0, 0.5, 0.0);
                for x in f.iter_mut() {
                    assert!(x.update(&pos, &vel, &r).outcome.is_accepted());
                }
                let aleph = f[2].last_aleph().unwrap();
                assert!(aleph.abs() < 1e-6, "ℵ = {aleph}");
            }
        }
        for x in &f[1..] {
            let d = (x.state().pos_enu_m - f[0].state().pos_enu_m).amax();
            assert!(d < 1e-6, "{d}");
            let c = (x.covariance() - f[0].covariance()).amax() / f[0].covariance().amax();
            assert!(c < 1e-8, "{c}");
        }
    }

    #[test]
    fn the_residual_gate_drops_an_outlying_component_and_the_stf_inflates() {
        // A 40 m outlier on the east position with 1 m σ: eq. 24 with C = 3 removes that
        // component only, so the gated filter's east position is the prediction's, while
        // an ungated EKF is pulled by metres. The STF's fading factor grows on the same
        // innovation, so it moves further than the EKF.
        let (st, earth, cfg) = start();
        let mk = |kind, gate| {
            InsFamilyFilter::new(
                st,
                earth,
                &cfg,
                &InsKalmanConfig {
                    kind,
                    residual_gate_c: gate,
                    ..InsKalmanConfig::default()
                },
            )
            .unwrap()
        };
        let mut f = [
            mk(InsKalmanKind::Ekf, None),
            mk(InsKalmanKind::Rekf, Some(3.0)),
            mk(InsKalmanKind::Ekf, Some(3.0)),
            mk(InsKalmanKind::Stf, None),
        ];
        let r = Cov6::from_diagonal(&SVector::<f64, 6>::new(1.0, 1.0, 1.0, 0.01, 0.01, 0.01));
        let mut k = 0u64;
        // Ten good fixes at the INS's own solution, then the outlier.
        for sec in 1..=11u64 {
            for _ in 0..100 {
                k += 1;
                let s = ImuSample {
                    t_s: k as f64 * 0.01,
                    gyro_rps: Vector3::zeros(),
                    accel_mps2: Vector3::new(0.0, 0.0, earth.gravity_mps2(0.0)),
                };
                for x in f.iter_mut() {
                    x.propagate(&s);
                }
            }
            for x in f.iter_mut() {
                let mut pos = x.state().pos_enu_m;
                if sec == 11 {
                    pos.x += 40.0;
                }
                let vel = x.state().vel_enu_mps;
                let before = x.state().pos_enu_m;
                let rep = x.update(&pos, &vel, &r);
                if sec == 11 {
                    let moved = (x.state().pos_enu_m - before).x.abs();
                    match rep.used {
                        5 => assert!(moved < 0.05, "gated filter moved {moved} m"),
                        6 => assert!(moved > 1.0, "ungated filter moved only {moved} m"),
                        u => panic!("{u} components used"),
                    }
                }
            }
        }
        let moved = |i: usize| (f[i].state().pos_enu_m.x - f[2].state().pos_enu_m.x).abs();
        assert!(moved(3) > moved(0), "STF {} vs EKF {}", moved(3), moved(0));
        // The RE-KF (χ = 0) with the gate is the gated EKF.
        assert!((f[1].state().pos_enu_m - f[2].state().pos_enu_m).amax() < 1e-6);
    }
}
