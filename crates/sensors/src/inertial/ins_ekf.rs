//! The loosely coupled INS error-state Kalman filter of seed 004 (Guo et al., "INS,
//! TC-OFDM and GNSS loose coupling", §2.1 eqs. 1–8 and §2.3 eqs. 14–19), closed loop.
//!
//! # Error state (eq. 14)
//!
//! X = [δr, δv, ψ, δα, δε] (15 states): position and velocity errors (ENU), the psi-angle
//! attitude error, the residual accelerometer bias δα and the residual gyro drift δε (both
//! in body axes). Errors are estimate minus truth: r̂ = r + δr, v̂ = v + δv,
//! Ĉ_b^n = (I − [ψ×]) C_b^n, and the corrected IMU outputs are f̂ = f + δα, ω̂ = ω + δε.
//!
//! # Dynamics (eqs. 1–3, 5–6, specialised to the tangent plane)
//!
//! In the Earth-fixed tangent plane the transport rate is zero, so ω_in^n = ω_ie^n, the
//! psi- and phi-angle models coincide and F_rr = 0, F_φr = F_φv = 0 (Groves 2013 §14.2.3,
//! eqs. 14.48–14.50 in rotated axes):
//!
//! ```text
//! δṙ = δv
//! δv̇ = −2[ω_ie×] δv + [f^n×] ψ + Ĉ_b^n δα + (0, 0, −∂γ/∂h δr_up)
//! ψ̇  = −[ω_ie×] ψ − Ĉ_b^n δε
//! δα̇ = −δα/τ_a + w_a,   δε̇ = −δε/τ_g + w_g
//! ```
//!
//! Eq. 6 as printed puts C_b^n in the δε column of the velocity row and −C_b^n in the δα
//! column of the attitude row; physically (and in Groves eq. 14.63) the accelerometer bias
//! drives the velocity error and the gyro drift the attitude error, which is what we use
//! (the printed order looks like a transposition; the signs agree with ours).
//!
//! Discretisation: Φ = I + F Δt; Q = G Q_c Gᵀ Δt (eqs. 7–8) with white accelerometer noise
//! N_a² (VRW), white gyro noise N_g² (ARW) and Gauss–Markov drives 2σ²/τ (+ K² for rate
//! random walk) on the biases; isotropic noise makes the C_b^n in G drop out.
//!
//! # Measurements (eqs. 16–19)
//!
//! z = r̂ − r_fix (and/or v̂ − v_fix), H = [I₆ 0₆ₓ₉] (or the position/velocity half), with
//! the fix's own covariance R: a GNSS fix, a TC-OFDM fix or their combination. The update is
//! the Joseph form. After each update the estimated errors are fed back (closed loop:
//! r̂ −= δr, v̂ −= δv, Ĉ ← exp([ψ×]) Ĉ, b̂_a += δα, b̂_g += δε) and the error state is
//! reset to zero, so the linearisation stays about the corrected solution.

use super::imu::ImuSpec;
use super::strapdown::{NavState, Strapdown};
use super::{skew, LocalEarth};
use crate::measurement::ImuSample;
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// 15-state covariance.
pub type Cov15 = SMatrix<f64, 15, 15>;

/// Noise model and initial uncertainty of the filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsEkfConfig {
    /// Accelerometer white noise density N_a (m/s/√s).
    pub accel_vrw_mps_per_sqrt_s: f64,
    /// Gyro white noise density N_g (rad/√s).
    pub gyro_arw_rad_per_sqrt_s: f64,
    /// Stationary σ of the accelerometer bias process (m/s²).
    pub accel_bias_sigma_mps2: f64,
    /// Stationary σ of the gyro bias process (rad/s).
    pub gyro_bias_sigma_rps: f64,
    /// Bias correlation time τ_a = τ_g (s).
    pub bias_corr_time_s: f64,
    /// Accelerometer bias random walk (m/s²/√s).
    pub accel_bias_rw: f64,
    /// Gyro bias random walk (rad/s/√s).
    pub gyro_bias_rw: f64,
    /// Initial position σ per axis (m).
    pub init_pos_sigma_m: f64,
    /// Initial velocity σ per axis (m/s).
    pub init_vel_sigma_mps: f64,
    /// Initial attitude σ: roll/pitch (east, north tilt) and heading (rad).
    pub init_tilt_sigma_rad: f64,
    /// Initial heading σ (rad).
    pub init_heading_sigma_rad: f64,
    /// Initial accelerometer bias σ (m/s²).
    pub init_accel_bias_sigma_mps2: f64,
    /// Initial gyro bias σ (rad/s).
    pub init_gyro_bias_sigma_rps: f64,
    /// Reject fixes whose NIS exceeds this (χ² with 3 or 6 degrees of freedom); `None`
    /// accepts every fix.
    pub nis_gate: Option<f64>,
}

impl InsEkfConfig {
    /// The filter tuned to an IMU specification: the IMU's own noise densities, its
    /// Gauss–Markov σ (B/0.6174) and correlation time, and initial bias σ covering the
    /// turn-on bias too. Initial position 5 m, velocity 0.5 m/s, tilt 1°, heading 5°.
    pub fn from_imu(spec: &ImuSpec) -> Self {
        Self {
            accel_vrw_mps_per_sqrt_s: spec.accel_vrw_mps_per_sqrt_s,
            gyro_arw_rad_per_sqrt_s: spec.gyro_arw_rad_per_sqrt_s,
            accel_bias_sigma_mps2: spec.accel_gm_sigma_mps2(),
            gyro_bias_sigma_rps: spec.gyro_gm_sigma_rps(),
            bias_corr_time_s: spec.bias_corr_time_s,
            accel_bias_rw: spec.accel_rrw_mps2_per_sqrt_s,
            gyro_bias_rw: spec.gyro_rrw_rps_per_sqrt_s,
            init_pos_sigma_m: 5.0,
            init_vel_sigma_mps: 0.5,
            init_tilt_sigma_rad: 1f64.to_radians(),
            init_heading_sigma_rad: 5f64.to_radians(),
            init_accel_bias_sigma_mps2: spec
                .accel_gm_sigma_mps2()
                .hypot(spec.accel_turn_on_bias_mps2),
            init_gyro_bias_sigma_rps: spec.gyro_gm_sigma_rps().hypot(spec.gyro_turn_on_bias_rps),
            nis_gate: None,
        }
    }
}

/// Why a fix was not used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InsFixError {
    /// The fix or its covariance has a NaN or infinite element.
    #[error("the {what} fix has a non-finite value")]
    NonFinite {
        /// "position" or "velocity".
        what: &'static str,
    },
    /// The innovation covariance H P Hᵀ + R is not positive definite (a bad R).
    #[error("the {what} fix covariance is not positive definite")]
    NotPositiveDefinite {
        /// "position" or "velocity".
        what: &'static str,
    },
}

/// The outcome of a fix update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixOutcome {
    /// Normalised innovation squared zᵀ S⁻¹ z.
    pub nis: f64,
    /// False when the NIS gate rejected the fix (the state is then unchanged).
    pub accepted: bool,
    /// For a gated fix: whether the filter's own variance along it, `tr(H P Hᵀ)`, was at
    /// least the fix's, `tr(R)` (`hybridnav_fusion::fusion::ekf11::RejectReason::Gate`).
    pub state_led: bool,
}

/// The closed-loop INS / fix Kalman filter.
#[derive(Clone, Debug)]
pub struct InsEkf {
    ins: Strapdown,
    p: Cov15,
    q_diag_rate: SVector<f64, 15>,
    inv_tau: f64,
    accel_bias_mps2: Vector3<f64>,
    gyro_bias_rps: Vector3<f64>,
    nis_gate: Option<f64>,
    /// Specific force in ENU at the last sample, for F.
    f_n: Vector3<f64>,
}

/// The initial error covariance of [`InsEkfConfig`]: a diagonal in the order δr, δv, ψ
/// (east and north tilt, then heading), δα, δε.
pub fn initial_covariance(cfg: &InsEkfConfig) -> Cov15 {
    let mut p = Cov15::zeros();
    let tilt2 = cfg.init_tilt_sigma_rad.powi(2);
    let diag = [
        cfg.init_pos_sigma_m.powi(2),
        cfg.init_pos_sigma_m.powi(2),
        cfg.init_pos_sigma_m.powi(2),
        cfg.init_vel_sigma_mps.powi(2),
        cfg.init_vel_sigma_mps.powi(2),
        cfg.init_vel_sigma_mps.powi(2),
        tilt2,
        tilt2,
        cfg.init_heading_sigma_rad.powi(2),
        cfg.init_accel_bias_sigma_mps2.powi(2),
        cfg.init_accel_bias_sigma_mps2.powi(2),
        cfg.init_accel_bias_sigma_mps2.powi(2),
        cfg.init_gyro_bias_sigma_rps.powi(2),
        cfg.init_gyro_bias_sigma_rps.powi(2),
        cfg.init_gyro_bias_sigma_rps.powi(2),
    ];
    for (i, d) in diag.iter().enumerate() {
        p[(i, i)] = *d;
    }
    p
}

/// The continuous process noise of [`InsEkfConfig`] as the diagonal of `G Q_c Gᵀ` per
/// second (eqs. 7–8: VRW² on δv, ARW² on ψ, the Gauss–Markov drives 2σ²/τ plus the
/// random-walk intensities on δα and δε), and `1/τ` (0 for no correlation time).
pub fn process_noise_rate(cfg: &InsEkfConfig) -> (SVector<f64, 15>, f64) {
    let tau = cfg.bias_corr_time_s;
    let inv_tau = if tau.is_finite() && tau > 0.0 {
        1.0 / tau
    } else {
        0.0
    };
    let qa = 2.0 * cfg.accel_bias_sigma_mps2.powi(2) * inv_tau + cfg.accel_bias_rw.powi(2);
    let qg = 2.0 * cfg.gyro_bias_sigma_rps.powi(2) * inv_tau + cfg.gyro_bias_rw.powi(2);
    let mut q = SVector::<f64, 15>::zeros();
    for i in 0..3 {
        q[3 + i] = cfg.accel_vrw_mps_per_sqrt_s.powi(2);
        q[6 + i] = cfg.gyro_arw_rad_per_sqrt_s.powi(2);
        q[9 + i] = qa;
        q[12 + i] = qg;
    }
    (q, inv_tau)
}

/// One IMU sample through the strapdown mechanisation with the bias estimates removed,
/// shared by this filter and the Kalman-family one (`ins_family`). Returns the interval
/// since the previous sample, the error dynamics F at the new state and the specific
/// force in ENU, or `None` when the sample does not advance time (the mechanisation has
/// then still run, as it always did).
pub(crate) fn mechanise(
    ins: &mut Strapdown,
    s: &ImuSample,
    accel_bias_mps2: &Vector3<f64>,
    gyro_bias_rps: &Vector3<f64>,
    inv_tau: f64,
) -> Option<(f64, Cov15, Vector3<f64>)> {
    let dt = s.t_s - ins.state().t_s;
    let f_b = s.accel_mps2 - accel_bias_mps2;
    ins.step(s.t_s, &(s.gyro_rps - gyro_bias_rps), &f_b);
    if dt.is_nan() || dt <= 0.0 {
        return None;
    }
    let st = *ins.state();
    let c = st.q_nb.to_rotation_matrix().into_inner();
    let f_n = c * f_b;
    let f = error_dynamics(ins.earth(), &c, &f_n, st.pos_enu_m.z, inv_tau);
    Some((dt, f, f_n))
}

/// The error dynamics matrix F of the module documentation at one IMU sample: `c` is
/// Ĉ_b^n, `f_n` the specific force in ENU, `up_m` the INS height (for the gravity
/// gradient) and `inv_tau` the bias correlation rate.
pub fn error_dynamics(
    earth: &LocalEarth,
    c: &Matrix3<f64>,
    f_n: &Vector3<f64>,
    up_m: f64,
    inv_tau: f64,
) -> Cov15 {
    let w_ie = skew(&earth.omega_ie_enu_rps);
    let mut f = Cov15::zeros();
    f.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    f.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-2.0 * w_ie));
    f.fixed_view_mut::<3, 3>(3, 6).copy_from(&skew(f_n));
    f.fixed_view_mut::<3, 3>(3, 9).copy_from(c);
    f[(5, 2)] = -earth.gravity_gradient_per_s2(up_m);
    f.fixed_view_mut::<3, 3>(6, 6).copy_from(&(-w_ie));
    f.fixed_view_mut::<3, 3>(6, 12).copy_from(&(-c));
    for i in 9..15 {
        f[(i, i)] = -inv_tau;
    }
    f
}

/// What a Joseph-form update computed: a gated innovation, or the error estimate and
/// the new (symmetrised) covariance, for the caller to check and apply.
pub(crate) enum JosephStep<const N: usize> {
    Gated {
        nis: f64,
        /// `tr(H P Hᵀ) ≥ tr(R)`.
        state_led: bool,
    },
    Update {
        nis: f64,
        dx: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    },
}

/// The Joseph-form Kalman update of an `M`-dimensional measurement on an `N`-state error
/// covariance `p`: innovation `z` (predicted minus measured), Jacobian `h`, noise `r`,
/// NIS gate `gate`. `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, `K = P Hᵀ S⁻¹`. Shared by this
/// filter and the tightly coupled one (`ins_tight`). Does not allocate.
///
/// # Errors
/// [`InsFixError`] for a non-finite input or an innovation covariance that is not
/// positive definite.
pub(crate) fn joseph_update<const N: usize, const M: usize>(
    p: &SMatrix<f64, N, N>,
    z: &SVector<f64, M>,
    h: &SMatrix<f64, M, N>,
    r: &SMatrix<f64, M, M>,
    gate: Option<f64>,
    what: &'static str,
) -> Result<JosephStep<N>, InsFixError> {
    if z.iter()
        .chain(r.iter())
        .chain(h.iter())
        .any(|v| !v.is_finite())
    {
        return Err(InsFixError::NonFinite { what });
    }
    let hp = h * p;
    let hph = hp * h.transpose();
    let s = hph + r;
    let chol = s
        .cholesky()
        .ok_or(InsFixError::NotPositiveDefinite { what })?;
    let nis = z.dot(&chol.solve(z));
    if gate.is_some_and(|g| nis > g) {
        return Ok(JosephStep::Gated {
            nis,
            state_led: hph.trace() >= r.trace(),
        });
    }
    // K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ since P and S are symmetric.
    let k = chol.solve(&hp).transpose();
    let dx = k * z;
    let ikh = SMatrix::<f64, N, N>::identity() - k * h;
    let p = ikh * p * ikh.transpose() + k * r * k.transpose();
    Ok(JosephStep::Update {
        nis,
        dx,
        p: 0.5 * (p + p.transpose()),
    })
}

/// Closed-loop correction of the navigation solution by the 15 navigation error states
/// `dx` (δr, δv, ψ, δα, δε): r̂ −= δr, v̂ −= δv, Ĉ ← exp([ψ×]) Ĉ, b̂_a += δα, b̂_g += δε.
/// Shared by this filter and the tightly coupled one (`ins_tight`).
pub(crate) fn feed_back_nav(
    ins: &mut Strapdown,
    accel_bias_mps2: &mut Vector3<f64>,
    gyro_bias_rps: &mut Vector3<f64>,
    dx: &SVector<f64, 15>,
) {
    let mut st = *ins.state();
    st.pos_enu_m -= dx.fixed_rows::<3>(0);
    st.vel_enu_mps -= dx.fixed_rows::<3>(3);
    let psi: Vector3<f64> = dx.fixed_rows::<3>(6).into();
    st.q_nb = UnitQuaternion::from_scaled_axis(psi) * st.q_nb;
    ins.set_state(st);
    *accel_bias_mps2 += dx.fixed_rows::<3>(9);
    *gyro_bias_rps += dx.fixed_rows::<3>(12);
}

impl InsEkf {
    /// A filter starting at `initial` with zero bias estimates.
    pub fn new(initial: NavState, earth: LocalEarth, cfg: &InsEkfConfig) -> Self {
        let (q, inv_tau) = process_noise_rate(cfg);
        Self {
            ins: Strapdown::new(initial, earth),
            p: initial_covariance(cfg),
            q_diag_rate: q,
            inv_tau,
            accel_bias_mps2: Vector3::zeros(),
            gyro_bias_rps: Vector3::zeros(),
            nis_gate: cfg.nis_gate,
            f_n: Vector3::zeros(),
        }
    }

    /// The corrected navigation solution.
    pub fn state(&self) -> &NavState {
        self.ins.state()
    }

    /// The error covariance (order δr, δv, ψ, δα, δε).
    pub fn covariance(&self) -> &Cov15 {
        &self.p
    }

    /// The accelerometer bias estimate b̂_a (m/s², body axes).
    pub fn accel_bias_mps2(&self) -> Vector3<f64> {
        self.accel_bias_mps2
    }

    /// The gyro bias estimate b̂_g (rad/s, body axes).
    pub fn gyro_bias_rps(&self) -> Vector3<f64> {
        self.gyro_bias_rps
    }

    /// 1σ position uncertainty per ENU axis (m).
    pub fn position_sigma_m(&self) -> Vector3<f64> {
        Vector3::new(
            self.p[(0, 0)].sqrt(),
            self.p[(1, 1)].sqrt(),
            self.p[(2, 2)].sqrt(),
        )
    }

    /// Mechanises one IMU sample (bias estimates removed) and propagates the covariance over
    /// the interval since the previous sample: the INS step. Does not allocate.
    pub fn propagate(&mut self, s: &ImuSample) {
        let Some((dt, f, f_n)) = mechanise(
            &mut self.ins,
            s,
            &self.accel_bias_mps2,
            &self.gyro_bias_rps,
            self.inv_tau,
        ) else {
            return;
        };
        self.f_n = f_n;
        let phi = Cov15::identity() + f * dt;
        self.p = phi * self.p * phi.transpose();
        for i in 0..15 {
            self.p[(i, i)] += self.q_diag_rate[i] * dt;
        }
        self.p = 0.5 * (self.p + self.p.transpose());
    }

    fn update<const M: usize>(
        &mut self,
        z: SVector<f64, M>,
        h: SMatrix<f64, M, 15>,
        r: SMatrix<f64, M, M>,
        what: &'static str,
    ) -> Result<FixOutcome, InsFixError> {
        match joseph_update(&self.p, &z, &h, &r, self.nis_gate, what)? {
            JosephStep::Gated { nis, state_led } => Ok(FixOutcome {
                nis,
                accepted: false,
                state_led,
            }),
            JosephStep::Update { nis, dx, p } => {
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

    /// Closed-loop correction: applies the estimated errors to the solution and the bias
    /// estimates; the error state is thereby reset to zero.
    fn feed_back(&mut self, dx: &SVector<f64, 15>) {
        feed_back_nav(
            &mut self.ins,
            &mut self.accel_bias_mps2,
            &mut self.gyro_bias_rps,
            dx,
        );
    }

    /// A position fix (ENU m) with its covariance (m²), e.g. from GNSS or TC-OFDM (eqs.
    /// 16–19, position half). The fix is taken to be at the filter's current time.
    ///
    /// # Errors
    /// [`InsFixError`] for a non-finite fix or a covariance that is not positive definite.
    pub fn update_position(
        &mut self,
        pos_enu_m: &Vector3<f64>,
        cov_m2: &Matrix3<f64>,
    ) -> Result<FixOutcome, InsFixError> {
        let z = self.ins.state().pos_enu_m - pos_enu_m;
        let mut h = SMatrix::<f64, 3, 15>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        self.update(z, h, *cov_m2, "position")
    }

    /// A velocity fix (ENU m/s) with its covariance ((m/s)²).
    ///
    /// # Errors
    /// As [`InsEkf::update_position`].
    pub fn update_velocity(
        &mut self,
        vel_enu_mps: &Vector3<f64>,
        cov_m2ps2: &Matrix3<f64>,
    ) -> Result<FixOutcome, InsFixError> {
        let z = self.ins.state().vel_enu_mps - vel_enu_mps;
        let mut h = SMatrix::<f64, 3, 15>::zeros();
        h.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        self.update(z, h, *cov_m2ps2, "velocity")
    }

    /// A joint position and velocity fix (eqs. 16–19 in full): z = [r̂ − r; v̂ − v],
    /// H = [I₆ 0], R = blockdiag(pos, vel).
    ///
    /// # Errors
    /// As [`InsEkf::update_position`].
    pub fn update_position_velocity(
        &mut self,
        pos_enu_m: &Vector3<f64>,
        pos_cov_m2: &Matrix3<f64>,
        vel_enu_mps: &Vector3<f64>,
        vel_cov_m2ps2: &Matrix3<f64>,
    ) -> Result<FixOutcome, InsFixError> {
        let st = self.ins.state();
        let mut z = SVector::<f64, 6>::zeros();
        z.fixed_rows_mut::<3>(0)
            .copy_from(&(st.pos_enu_m - pos_enu_m));
        z.fixed_rows_mut::<3>(3)
            .copy_from(&(st.vel_enu_mps - vel_enu_mps));
        let mut h = SMatrix::<f64, 6, 15>::zeros();
        h.fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&SMatrix::<f64, 6, 6>::identity());
        let mut r = SMatrix::<f64, 6, 6>::zeros();
        r.fixed_view_mut::<3, 3>(0, 0).copy_from(pos_cov_m2);
        r.fixed_view_mut::<3, 3>(3, 3).copy_from(vel_cov_m2ps2);
        self.update(z, h, r, "position-velocity")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inertial::imu::{ImuConfig, ImuGrade};

    fn level_at_rest() -> (InsEkf, LocalEarth) {
        let earth = LocalEarth::new(0.7, 0.0);
        let cfg = InsEkfConfig::from_imu(&ImuConfig::grade(ImuGrade::Mid).resolve().unwrap());
        let st = NavState {
            t_s: 0.0,
            pos_enu_m: Vector3::zeros(),
            vel_enu_mps: Vector3::zeros(),
            q_nb: UnitQuaternion::identity(),
        };
        (InsEkf::new(st, earth, &cfg), earth)
    }

    #[test]
    fn bad_fixes_are_typed_errors() {
        let (mut f, _) = level_at_rest();
        let e = f
            .update_position(&Vector3::new(f64::NAN, 0.0, 0.0), &Matrix3::identity())
            .unwrap_err();
        assert_eq!(e, InsFixError::NonFinite { what: "position" });
        let e = f
            .update_velocity(&Vector3::zeros(), &(-1e6 * Matrix3::identity()))
            .unwrap_err();
        assert_eq!(e, InsFixError::NotPositiveDefinite { what: "velocity" });
    }

    #[test]
    fn a_fix_pulls_the_solution_and_shrinks_the_covariance() {
        let (mut f, earth) = level_at_rest();
        let g = earth.gravity_mps2(0.0);
        for k in 1..=100 {
            let s = ImuSample {
                t_s: k as f64 * 0.01,
                gyro_rps: UnitQuaternion::<f64>::identity().inverse() * earth.omega_ie_enu_rps,
                accel_mps2: Vector3::new(0.0, 0.0, g),
            };
            f.propagate(&s);
        }
        let before = f.position_sigma_m().x;
        let out = f
            .update_position(&Vector3::new(3.0, 0.0, 0.0), &(4.0 * Matrix3::identity()))
            .unwrap();
        assert!(out.accepted && out.nis > 0.0);
        let x = f.state().pos_enu_m.x;
        // Scalar KF on one axis: x = P/(P + R) · 3 with P ≈ 25 m², R = 4 m².
        let p = before * before;
        assert!((x - p / (p + 4.0) * 3.0).abs() < 1e-6, "{x}");
        assert!(f.position_sigma_m().x < 2.0);
    }
}
