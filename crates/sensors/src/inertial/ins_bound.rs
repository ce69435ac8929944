//! The posterior Cramér–Rao bound of the INS rows (seed 004): the 15-state error model of
//! [`super::ins_ekf`] (loosely coupled) or the 18-state one of [`super::ins_tight`] (tightly
//! coupled), linearised along the true trajectory, with the information of the ranges the
//! world's receivers give at the truth.
//!
//! # Why this is the bound
//!
//! Along a given true trajectory the INS error obeys the linear error model of the module
//! documentation of [`super::ins_ekf`], driven by the IMU's white noise and bias processes
//! (the estimator's own model: its densities, bias σ and correlation time), and every
//! range is linear in the position error to first order. For a linear-Gaussian model the
//! posterior Cramér–Rao bound is the Kalman filter's covariance (Tichavský, Muravchik &
//! Nehorai 1998, §IV; [`crate::fusion::pcrlb`]); here the Jacobians are evaluated at the
//! truth — the true attitude `C_b^n` and specific force `f^n = a^n − g^n + 2 ω_ie × v^n` —
//! rather than at an estimate. The recursion is the filters' own discretisation, so that
//! the bound is that of the estimator's model and not of a finer one:
//!
//! ```text
//! B⁻ = Φ B Φᵀ + Q Δt,   Φ = I + F Δt (F at the truth, one step per IMU sample)
//! B  = B⁻ (I + Ī B⁻)⁻¹  at every measurement instant
//! ```
//!
//! The trajectory of a walker differs from trial to trial (the gait's wander), so the bound
//! is computed along each trial's truth and the mean-square errors are averaged over the
//! trials: each trial's estimator error is bounded by its own trajectory's bound, so their
//! average bounds the average.
//!
//! # Information
//!
//! Each pseudorange contributes `hᵀh/σ²` and each range rate `hᵀh/σ_ρ̇²` (the σ its
//! receiver reports), with the exact Jacobians at the true position and velocity
//! (`∂ρ/∂r = −u`, `∂ρ̇/∂v = −u`, `∂ρ̇/∂r = −(I − u uᵀ)(v_s − v)/ρ`, `u` the unit vector to
//! the emitter), over the receiver clocks the estimator solves for:
//!
//! - **loose** (seed 004's §2.3): each epoch's fix is least squares with a clock per
//!   system — GPS and DTMB on one clock, BeiDou and TC-OFDM on their own — and a velocity
//!   with one drift, so the information the fix carries on position and velocity is the
//!   Schur complement of the epoch's information over those clocks; it enters the
//!   15-state error through the ECEF → ENU rotation;
//! - **tight**: the 18-state filter's clock bias (GPS, DTMB and TC-OFDM), drift and BeiDou
//!   inter-system bias are states with their own process model
//!   ([`TightClockConfig`]), so the information enters whole, mapped onto those states.
//!
//! # Prior
//!
//! Position and velocity (and the tight filter's clock bias) start flat
//! ([`FLAT_PRIOR_VAR_M2`]: their information comes from the ranges). The attitude starts
//! with the most informative σ the estimator ever claims at initialisation — roll and pitch
//! `init_tilt_sigma_deg` from levelling, heading 1°, the floor of the heading the estimator
//! takes from the fix velocity — and the IMU biases with the σ of the IMU's specification
//! (the estimator's). Information the estimator might have beyond this (levelling better
//! than its stated σ) is not counted, which is where the bound could rise above an
//! estimator; information it does not have (the first epoch's range rates before it
//! initialises) is counted, which only lowers the bound.
//!
//! # The gait
//!
//! A walker's receiver measures the velocity of the walk, while a handheld IMU also moves
//! with the gait. The estimators take that as velocity noise of σ `fix_velocity_noise_mps`
//! (white at the fix rate), the loose one on each fix's velocity and the tight one on each
//! range rate along its line of sight; the bound takes the same
//! ([`InsBound::with_velocity_noise`]), so that it is the bound of their model. Without
//! it (`[0, 0]`) the rates are counted as measuring the IMU's velocity exactly, to their
//! receiver's σ.

use super::attitude::BodyTruth;
use super::ins_ekf::{initial_covariance, process_noise_rate, InsEkfConfig};
use super::ins_tight::{tidx, Cov18, TightClockConfig, N_TIGHT};
use super::{skew, LocalEarth};
use crate::core::System;
use crate::fusion::pcrlb::FLAT_PRIOR_VAR_M2;
use crate::measurement::RangeMeasurement;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// The clocks of a least-squares fix (loose coupling) and the layout of the epoch
/// information: `[r (3), v (3), b_gps_dtmb, b_bds, b_tcofdm, ḃ]`, ECEF.
const N_EPOCH: usize = 10;
/// The epoch information over `N_EPOCH` (10) states.
pub type EpochInfo = SMatrix<f64, N_EPOCH, N_EPOCH>;
/// Index of a system's clock in [`EpochInfo`].
fn clock_of(sys: System) -> usize {
    match sys {
        System::Gps | System::Dtmb => 6,
        System::Bds => 7,
        System::Tcofdm => 8,
    }
}
/// Index of the clock drift in [`EpochInfo`].
const DRIFT: usize = 9;

/// Adds to `info` the information of `ranges` seen from the true ECEF position and
/// velocity (see the module documentation); range rates only when `rates`. A range whose
/// σ is not positive and finite, or whose emitter sits on the receiver, adds nothing.
/// Does not allocate.
pub fn add_epoch_information(
    info: &mut EpochInfo,
    truth_pos_ecef_m: &Vector3<f64>,
    truth_vel_ecef_mps: &Vector3<f64>,
    ranges: &[RangeMeasurement],
    rates: bool,
) {
    add_information(
        info,
        truth_pos_ecef_m,
        truth_vel_ecef_mps,
        ranges,
        rates,
        &Matrix3::zeros(),
    );
}

/// [`add_epoch_information`] with `rate_noise_ecef_m2ps2` (ECEF, m²/s²) of velocity that
/// the range rates do not describe: a rate along `u` has variance `σ_ρ̇² + uᵀ Σ u`.
fn add_information(
    info: &mut EpochInfo,
    truth_pos_ecef_m: &Vector3<f64>,
    truth_vel_ecef_mps: &Vector3<f64>,
    ranges: &[RangeMeasurement],
    rates: bool,
    rate_noise_ecef_m2ps2: &Matrix3<f64>,
) {
    for m in ranges {
        let d = m.emitter_pos_ecef_m - truth_pos_ecef_m;
        let rho = d.norm();
        if rho <= 0.0 || !rho.is_finite() {
            continue;
        }
        let u = d / rho;
        if m.sigma_m > 0.0 && m.sigma_m.is_finite() {
            let mut h = SVector::<f64, N_EPOCH>::zeros();
            h.fixed_rows_mut::<3>(0).copy_from(&(-u));
            h[clock_of(m.system())] = 1.0;
            *info += h * h.transpose() / (m.sigma_m * m.sigma_m);
        }
        let good_rate = m.sigma_rate_mps > 0.0 && m.sigma_rate_mps.is_finite();
        if rates && m.range_rate_mps.is_some() && good_rate {
            let dv = m.emitter_vel_ecef_mps - truth_vel_ecef_mps;
            let mut h = SVector::<f64, N_EPOCH>::zeros();
            h.fixed_rows_mut::<3>(0)
                .copy_from(&(-(dv - u * u.dot(&dv)) / rho));
            h.fixed_rows_mut::<3>(3).copy_from(&(-u));
            h[DRIFT] = 1.0;
            let var = m.sigma_rate_mps * m.sigma_rate_mps + u.dot(&(rate_noise_ecef_m2ps2 * u));
            *info += h * h.transpose() / var;
        }
    }
}

/// How the INS takes the ranges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoundCoupling {
    /// Position and velocity fixes by least squares (clocks solved per epoch).
    Loose,
    /// Every range and range rate, with the receiver clock as states.
    Tight(TightClockConfig),
}

/// The bound's state along one trajectory: the bound `B` on the error covariance and the
/// time it holds at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundState {
    /// Seconds since the trial start.
    pub t_s: f64,
    /// `B` over the 18 states of [`super::ins_tight`] (the loose model leaves the three
    /// clock states inert at unit variance).
    pub b: Cov18,
}

impl BoundState {
    /// The bound on the position's mean-square error (m², the trace of the position block).
    pub fn position_mse_m2(&self) -> f64 {
        (0..3).map(|i| self.b[(i, i)]).sum()
    }
}

/// The PCRLB of an INS estimator's error model (see the module documentation).
#[derive(Clone, Debug)]
pub struct InsBound {
    coupling: BoundCoupling,
    prior: Cov18,
    q_nav_rate: SVector<f64, 15>,
    inv_tau: f64,
    earth: LocalEarth,
    /// ECEF → ENU (the world frame's rotation).
    enu_from_ecef: Matrix3<f64>,
    /// Covariance (ENU, m²/s²) of the IMU's velocity that the fixes' velocities and the
    /// range rates do not describe ([`InsBound::with_velocity_noise`]).
    vel_noise_enu_m2ps2: Matrix3<f64>,
}

impl InsBound {
    /// The bound of an estimator whose error model is `cfg` (as it runs it:
    /// [`super::ins_estimator::InsEstimator::error_model`]) with roll and pitch σ
    /// `init_tilt_sigma_rad` at initialisation, coupled as `coupling`, in a world whose
    /// tangent plane is `earth` with ECEF → ENU rotation `enu_from_ecef`.
    pub fn new(
        cfg: &InsEkfConfig,
        init_tilt_sigma_rad: f64,
        coupling: BoundCoupling,
        earth: LocalEarth,
        enu_from_ecef: Matrix3<f64>,
    ) -> Self {
        let mut c = *cfg;
        c.init_pos_sigma_m = FLAT_PRIOR_VAR_M2.sqrt();
        c.init_vel_sigma_mps = FLAT_PRIOR_VAR_M2.sqrt();
        c.init_tilt_sigma_rad = init_tilt_sigma_rad;
        c.init_heading_sigma_rad = 1f64.to_radians();
        let mut prior = Cov18::identity();
        prior
            .fixed_view_mut::<15, 15>(0, 0)
            .copy_from(&initial_covariance(&c));
        if let BoundCoupling::Tight(clock) = coupling {
            prior[(tidx::CLOCK_BIAS, tidx::CLOCK_BIAS)] = FLAT_PRIOR_VAR_M2;
            prior[(tidx::CLOCK_DRIFT, tidx::CLOCK_DRIFT)] =
                clock.init_clock_drift_sigma_mps.powi(2);
            prior[(tidx::ISB_BDS, tidx::ISB_BDS)] = clock.isb_bds_init_sigma_m.powi(2);
        }
        let (q_nav_rate, inv_tau) = process_noise_rate(cfg);
        Self {
            coupling,
            prior,
            q_nav_rate,
            inv_tau,
            earth,
            enu_from_ecef,
            vel_noise_enu_m2ps2: Matrix3::zeros(),
        }
    }

    /// The same bound for an estimator that takes `[horizontal, vertical]` σ (m/s) of the
    /// IMU's velocity as not described by its velocity measurements (its
    /// `fix_velocity_noise_mps`, a walker's gait): loose, added to the velocity block of
    /// each fix's covariance, as the loose filter adds it; tight, to each range rate's
    /// variance along its line of sight, as the tight filter does. The gait is a narrow-band
    /// oscillation, not white noise; as noise white at the fix rate it is the model the
    /// estimators run, so the bound stays that of their model.
    pub fn with_velocity_noise(mut self, sigma_mps: [f64; 2]) -> Self {
        self.vel_noise_enu_m2ps2 =
            Matrix3::from_diagonal(&super::velocity_noise_var_enu(sigma_mps));
        self
    }

    /// Adds to `info` the information of one epoch's `ranges` (and range rates, when
    /// `rates`) at the truth, as [`add_epoch_information`] does, with the tight
    /// coupling's velocity noise on each range rate. Does not allocate.
    pub fn add_epoch_information(
        &self,
        info: &mut EpochInfo,
        truth_pos_ecef_m: &Vector3<f64>,
        truth_vel_ecef_mps: &Vector3<f64>,
        ranges: &[RangeMeasurement],
        rates: bool,
    ) {
        let noise = match self.coupling {
            // The loose coupling adds it to the fix ([`InsBound::information`]).
            BoundCoupling::Loose => Matrix3::zeros(),
            BoundCoupling::Tight(_) => {
                self.enu_from_ecef.transpose() * self.vel_noise_enu_m2ps2 * self.enu_from_ecef
            }
        };
        add_information(
            info,
            truth_pos_ecef_m,
            truth_vel_ecef_mps,
            ranges,
            rates,
            &noise,
        );
    }

    /// The prior at `t_s`.
    pub fn start(&self, t_s: f64) -> BoundState {
        BoundState { t_s, b: self.prior }
    }

    /// `F X` for the error dynamics at attitude `c` (C_b^n), specific force `f_n` (ENU)
    /// and height `up_m`, from F's blocks ([`error_dynamics`]) rather than a dense
    /// product: F has 8 non-zero 3 × 3 blocks of 36. Does not allocate.
    fn f_times(&self, c: &Matrix3<f64>, f_n: &Vector3<f64>, up_m: f64, x: &Cov18) -> Cov18 {
        let w = skew(&self.earth.omega_ie_enu_rps);
        let sf = skew(f_n);
        let blk = |r: usize| x.fixed_rows::<3>(r);
        let mut out = Cov18::zeros();
        out.fixed_rows_mut::<3>(0).copy_from(&blk(3));
        out.fixed_rows_mut::<3>(3)
            .copy_from(&(-2.0 * w * blk(3) + sf * blk(6) + c * blk(9)));
        let gg = -self.earth.gravity_gradient_per_s2(up_m);
        for j in 0..N_TIGHT {
            out[(5, j)] += gg * x[(2, j)];
        }
        out.fixed_rows_mut::<3>(6)
            .copy_from(&(-w * blk(6) - c * blk(12)));
        for i in 9..15 {
            for j in 0..N_TIGHT {
                out[(i, j)] = -self.inv_tau * x[(i, j)];
            }
        }
        if matches!(self.coupling, BoundCoupling::Tight(_)) {
            for j in 0..N_TIGHT {
                out[(tidx::CLOCK_BIAS, j)] = x[(tidx::CLOCK_DRIFT, j)];
            }
        }
        out
    }

    /// Propagates `st` to `t_s` over one IMU interval with the truth at `t_s`: attitude
    /// `c` (C_b^n), specific force `f_n` (ENU m/s²) and height `up_m` — the filters'
    /// `Φ B Φᵀ + Q Δt` with `Φ = I + F Δt`. An interval that is not positive leaves `st`.
    /// Does not allocate.
    pub fn predict(
        &self,
        st: &mut BoundState,
        t_s: f64,
        c: &Matrix3<f64>,
        f_n: &Vector3<f64>,
        up_m: f64,
    ) {
        let dt = t_s - st.t_s;
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        // Φ B Φᵀ = A + Δt (F Aᵀ)ᵀ with A = B + Δt F B, since (F B)ᵀ = B Fᵀ for symmetric B.
        let a = st.b + self.f_times(c, f_n, up_m, &st.b) * dt;
        let fat = self.f_times(c, f_n, up_m, &a.transpose());
        let mut b = a + fat.transpose() * dt;
        for i in 0..15 {
            b[(i, i)] += self.q_nav_rate[i] * dt;
        }
        if let BoundCoupling::Tight(clock) = self.coupling {
            let (st_psd, sf) = (clock.clock_bias_psd_m2ps, clock.clock_drift_psd_m2ps3);
            let (cb, cd) = (tidx::CLOCK_BIAS, tidx::CLOCK_DRIFT);
            b[(cb, cb)] += st_psd * dt + sf * dt.powi(3) / 3.0;
            b[(cb, cd)] += sf * dt * dt / 2.0;
            b[(cd, cb)] += sf * dt * dt / 2.0;
            b[(cd, cd)] += sf * dt;
            b[(tidx::ISB_BDS, tidx::ISB_BDS)] += clock.isb_bds_psd_m2ps * dt;
        }
        st.b = 0.5 * (b + b.transpose());
        st.t_s = t_s;
    }

    /// The information of one epoch ([`add_epoch_information`], ECEF) on the bound's 18
    /// states (see the module documentation): loose, the Schur complement over the clocks
    /// the epoch's information touches, rotated to ENU; tight, mapped whole onto the
    /// position, velocity and clock states.
    pub fn information(&self, info: &EpochInfo) -> Cov18 {
        // T maps the 18 error states to the epoch's 10: r_ecef = Rᵀ δr_enu, v likewise.
        let rt = self.enu_from_ecef.transpose();
        let mut out = Cov18::zeros();
        match self.coupling {
            BoundCoupling::Loose => {
                // The clocks with information (a clock no range touched has a zero row).
                let mut kv = SMatrix::<f64, 6, 6>::zeros();
                let mut nuisance = [0usize; 4];
                let mut n = 0;
                for k in 6..N_EPOCH {
                    if info[(k, k)] > 0.0 {
                        nuisance[n] = k;
                        n += 1;
                    }
                }
                let mut cc = SMatrix::<f64, 4, 4>::identity();
                let mut kc = SMatrix::<f64, 6, 4>::zeros();
                for (a, &ia) in nuisance[..n].iter().enumerate() {
                    for (b, &ib) in nuisance[..n].iter().enumerate() {
                        cc[(a, b)] = info[(ia, ib)];
                    }
                    for i in 0..6 {
                        kc[(i, a)] = info[(i, ia)];
                    }
                }
                kv.copy_from(&info.fixed_view::<6, 6>(0, 0));
                if n > 0 {
                    if let Some(ch) = cc.cholesky() {
                        kv -= kc * ch.solve(&kc.transpose());
                    }
                }
                let mut t = SMatrix::<f64, 6, 6>::zeros();
                t.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
                t.fixed_view_mut::<3, 3>(3, 3).copy_from(&rt);
                let mut enu = t.transpose() * kv * t;
                // The fix's covariance gains the velocity noise, as the loose filter's
                // fix velocity does. Only a fix that determines position and velocity has
                // a covariance; one that does not (fewer than four rates) keeps its
                // information, which can only lower the bound.
                if self.vel_noise_enu_m2ps2 != Matrix3::zeros() {
                    if let Some(ch) = (0.5 * (enu + enu.transpose())).cholesky() {
                        let mut cov = ch.inverse();
                        let mut vv = cov.fixed_view_mut::<3, 3>(3, 3);
                        vv += self.vel_noise_enu_m2ps2;
                        if let Some(ci) = cov.cholesky() {
                            enu = ci.inverse();
                        }
                    }
                }
                out.fixed_view_mut::<6, 6>(0, 0)
                    .copy_from(&(0.5 * (enu + enu.transpose())));
            }
            BoundCoupling::Tight(_) => {
                let mut t = SMatrix::<f64, N_EPOCH, N_TIGHT>::zeros();
                t.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
                t.fixed_view_mut::<3, 3>(3, 3).copy_from(&rt);
                // GPS, DTMB and TC-OFDM on b; BeiDou on b + isb.
                t[(6, tidx::CLOCK_BIAS)] = 1.0;
                t[(7, tidx::CLOCK_BIAS)] = 1.0;
                t[(7, tidx::ISB_BDS)] = 1.0;
                t[(8, tidx::CLOCK_BIAS)] = 1.0;
                t[(DRIFT, tidx::CLOCK_DRIFT)] = 1.0;
                let m = t.transpose() * info * t;
                out = 0.5 * (m + m.transpose());
            }
        }
        out
    }

    /// The measurement update `B = B⁻ (I + Ī B⁻)⁻¹` with the information `info` of
    /// [`InsBound::information`]. Returns false (leaving `st`) when `I + Ī B⁻` is singular,
    /// which an information matrix that is positive semi-definite never makes it.
    pub fn update(&self, st: &mut BoundState, info: &Cov18) -> bool {
        let m = Cov18::identity() + info * st.b;
        let Some(inv) = m.try_inverse() else {
            return false;
        };
        let b = st.b * inv;
        st.b = 0.5 * (b + b.transpose());
        true
    }
}

/// The truth an IMU step of the bound needs, from a body truth: `C_b^n` and
/// `f^n = a^n − g^n(h) + 2 ω_ie × v^n` (the ideal IMU's specific force in ENU).
pub fn truth_dynamics(earth: &LocalEarth, b: &BodyTruth) -> (Matrix3<f64>, Vector3<f64>) {
    let c = b.q_nb.to_rotation_matrix().into_inner();
    let f_n = b.acc_enu_mps2 - earth.gravity_enu_mps2(b.pos_enu_m.z)
        + 2.0 * earth.omega_ie_enu_rps.cross(&b.vel_enu_mps);
    (c, f_n)
}

/// The dense error dynamics, for the tests' check of [`InsBound::predict`].
#[cfg(test)]
fn dense_phi(bound: &InsBound, c: &Matrix3<f64>, f_n: &Vector3<f64>, up_m: f64, dt: f64) -> Cov18 {
    let f = super::ins_ekf::error_dynamics(&bound.earth, c, f_n, up_m, bound.inv_tau);
    let mut phi = Cov18::identity();
    phi.fixed_view_mut::<15, 15>(0, 0)
        .copy_from(&(SMatrix::<f64, 15, 15>::identity() + f * dt));
    if matches!(bound.coupling, BoundCoupling::Tight(_)) {
        phi[(tidx::CLOCK_BIAS, tidx::CLOCK_DRIFT)] = dt;
    }
    phi
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, EnuFrame, Geodetic};
    use crate::inertial::imu::ImuConfig;
    use crate::inertial::ins_ekf::InsEkf;
    use crate::inertial::ins_tight::InsTightEkf;
    use crate::inertial::strapdown::NavState;
    use crate::measurement::ImuSample;
    use nalgebra::UnitQuaternion;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::from_deg(39.96, 116.36, 50.0))
    }

    fn cfg() -> InsEkfConfig {
        let imu: ImuConfig = toml::from_str("grade = \"mid\"").unwrap();
        InsEkfConfig::from_imu(&imu.resolve().unwrap())
    }

    /// Five directions (ECEF, not normalised) to satellites spread over the sky.
    fn sky() -> [Vector3<f64>; 5] {
        [
            Vector3::new(1.0, 0.2, 0.3),
            Vector3::new(-0.5, 1.0, 0.4),
            Vector3::new(0.1, -1.0, 0.8),
            Vector3::new(-0.7, -0.6, 0.5),
            Vector3::new(0.3, 0.4, 1.0),
        ]
    }

    /// A range from an emitter `d` (ECEF offset from the receiver) with σ 2 m, and a range
    /// rate with σ 0.1 m/s.
    fn range(sys: System, d: Vector3<f64>, at: &Vector3<f64>) -> RangeMeasurement {
        RangeMeasurement {
            emitter: EmitterId::new(sys, 1),
            emitter_pos_ecef_m: at + d,
            emitter_vel_ecef_mps: Vector3::new(100.0, -2000.0, 500.0),
            pseudorange_m: d.norm(),
            sigma_m: 2.0,
            range_rate_mps: Some(0.0),
            sigma_rate_mps: 0.1,
            cn0_dbhz: 45.0,
            elevation_rad: 0.5,
        }
    }

    /// The largest `|P_ij − B_ij| / √(P_ii P_jj)`: every element compared on the scale of
    /// its own standard deviations, so that a small state is not drowned by a large one.
    fn normalised_gap(p: &SMatrix<f64, 15, 15>, b: &SMatrix<f64, 15, 15>) -> f64 {
        let mut worst = 0.0f64;
        for i in 0..15 {
            for j in 0..15 {
                let scale = (p[(i, i)] * p[(j, j)]).sqrt();
                worst = worst.max((p[(i, j)] - b[(i, j)]).abs() / scale);
            }
        }
        worst
    }

    /// The block-wise propagation equals the dense `Φ B Φᵀ + Q Δt` with `Φ = I + F Δt` of
    /// [`error_dynamics`], for both couplings, on a full (random symmetric) bound.
    #[test]
    fn the_blockwise_step_is_the_dense_one() {
        let earth = LocalEarth::new(0.7, 50.0);
        let c = UnitQuaternion::from_euler_angles(0.1, -0.2, 1.3)
            .to_rotation_matrix()
            .into_inner();
        let f_n = Vector3::new(0.4, -0.3, 9.81);
        for coupling in [
            BoundCoupling::Loose,
            BoundCoupling::Tight(TightClockConfig::default()),
        ] {
            let bound = InsBound::new(&cfg(), 0.03, coupling, earth, Matrix3::identity());
            let mut g = Cov18::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 * 0.1);
            g += Cov18::identity() * 2.0;
            let b0 = g * g.transpose();
            let mut st = BoundState { t_s: 0.0, b: b0 };
            bound.predict(&mut st, 0.01, &c, &f_n, 12.0);
            let phi = dense_phi(&bound, &c, &f_n, 12.0, 0.01);
            let mut want = phi * b0 * phi.transpose();
            for i in 0..15 {
                want[(i, i)] += bound.q_nav_rate[i] * 0.01;
            }
            if let BoundCoupling::Tight(clk) = coupling {
                let (cb, cd, dt) = (tidx::CLOCK_BIAS, tidx::CLOCK_DRIFT, 0.01f64);
                want[(cb, cb)] +=
                    clk.clock_bias_psd_m2ps * dt + clk.clock_drift_psd_m2ps3 * dt.powi(3) / 3.0;
                want[(cb, cd)] += clk.clock_drift_psd_m2ps3 * dt * dt / 2.0;
                want[(cd, cb)] += clk.clock_drift_psd_m2ps3 * dt * dt / 2.0;
                want[(cd, cd)] += clk.clock_drift_psd_m2ps3 * dt;
                want[(tidx::ISB_BDS, tidx::ISB_BDS)] += clk.isb_bds_psd_m2ps * dt;
            }
            let err = (st.b - want).abs().max();
            assert!(err < 1e-12 * want.abs().max(), "{coupling:?}: {err}");
        }
    }

    /// The loose information is the information of a least-squares fix: the inverse of the
    /// position block of the fix's covariance `(Σ hhᵀ/σ²)⁻¹` over position and the clocks,
    /// computed here by a dense inverse of the whole epoch rather than a Schur complement.
    #[test]
    fn the_loose_information_is_that_of_a_least_squares_fix() {
        let frame = frame();
        let at = frame.origin_ecef();
        let dirs = sky();
        let mut ranges: Vec<RangeMeasurement> = dirs
            .iter()
            .map(|d| range(System::Gps, d.normalize() * 2.2e7, &at))
            .collect();
        ranges.push(range(System::Tcofdm, Vector3::new(50.0, 80.0, 20.0), &at));
        ranges.push(range(System::Tcofdm, Vector3::new(-90.0, 10.0, 30.0), &at));
        let mut info = EpochInfo::zeros();
        add_epoch_information(&mut info, &at, &Vector3::zeros(), &ranges, false);
        let bound = InsBound::new(
            &cfg(),
            0.03,
            BoundCoupling::Loose,
            LocalEarth::new(0.7, 50.0),
            *frame.rotation(),
        );
        let got = bound.information(&info);
        // Dense route over [r, b_gps, b_tcofdm].
        let idx = [0usize, 1, 2, 6, 8];
        let sub = nalgebra::DMatrix::from_fn(5, 5, |i, j| info[(idx[i], idx[j])]);
        let cov = sub.try_inverse().unwrap();
        let pos_cov_ecef = Matrix3::from_fn(|i, j| cov[(i, j)]);
        let r = frame.rotation();
        let want = (r * pos_cov_ecef * r.transpose()).try_inverse().unwrap();
        let got_pos = got.fixed_view::<3, 3>(0, 0).into_owned();
        assert!(
            (got_pos - want).abs().max() < 1e-9 * want.abs().max(),
            "{got_pos} vs {want}"
        );
        // Nothing outside the position block without range rates.
        assert_eq!(got.fixed_view::<12, 18>(6, 0).abs().max(), 0.0);
    }

    /// On the filters' own covariance: a perfect IMU at rest and fixes at the truth keep
    /// the builtin loose EKF and the tight EKF on the truth, so their covariance (Joseph
    /// form, Jacobians at their estimate = the truth) is the bound from the same prior.
    /// This holds the bound's information form, block-wise step and information maps to
    /// two filters that compute them another way.
    #[test]
    fn the_bound_is_the_filters_covariance_on_the_truth() {
        let frame = frame();
        let earth = LocalEarth::new(frame.origin().lat_rad, frame.origin().h_m);
        let rate = 100.0;
        let c = cfg();
        // A level platform at rest, heading north-east.
        let q_nb = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.6);
        let init = NavState {
            t_s: 0.0,
            pos_enu_m: Vector3::new(0.0, 0.0, 1.2),
            vel_enu_mps: Vector3::zeros(),
            q_nb,
        };
        let g = earth.gravity_enu_mps2(1.2);
        let w = earth.omega_ie_enu_rps;
        // The perfect IMU at rest: f^b = −Cᵀ g, ω_ib^b = Cᵀ ω_ie.
        let f_b = q_nb.inverse() * (-g);
        let w_b = q_nb.inverse() * w;
        let at = frame.ecef_of_enu(&init.pos_enu_m);
        let dirs = sky();
        let ranges: Vec<RangeMeasurement> = dirs
            .iter()
            .map(|d| {
                let mut m = range(System::Gps, d.normalize() * 2.2e7, &at);
                m.emitter_vel_ecef_mps = Vector3::zeros();
                m
            })
            .collect();
        // Loose: the builtin filter with fixes of the epoch's least-squares covariance,
        // from the bound's own prior (flat position and velocity stand in as 10 km and
        // 10 km/s so that the filter's Joseph form stays well conditioned). Position fixes
        // alone, then position and velocity fixes with the gait's velocity noise (the
        // emitters are at rest, so a fix's position and velocity errors are uncorrelated
        // and the filter's separate blocks are the whole covariance).
        let mut c0 = c;
        c0.init_pos_sigma_m = 1e4;
        c0.init_vel_sigma_mps = 1e4;
        c0.init_tilt_sigma_rad = 0.03;
        c0.init_heading_sigma_rad = 1f64.to_radians();
        let (cn, fn_) = (q_nb.to_rotation_matrix().into_inner(), -g);
        let imu_at = |k: u32| ImuSample {
            t_s: f64::from(k) / rate,
            gyro_rps: w_b,
            accel_mps2: f_b,
        };
        let gait = [0.1, 0.25];
        let mut loose_mse = Vec::new();
        for (rates, noise) in [(false, [0.0, 0.0]), (true, [0.0, 0.0]), (true, gait)] {
            let mut bound = InsBound::new(&c, 0.03, BoundCoupling::Loose, earth, *frame.rotation())
                .with_velocity_noise(noise);
            bound
                .prior
                .fixed_view_mut::<15, 15>(0, 0)
                .copy_from(&initial_covariance(&c0));
            let mut ekf = InsEkf::new(init, earth, &c0);
            let mut st = bound.start(0.0);
            let mut info = EpochInfo::zeros();
            bound.add_epoch_information(&mut info, &at, &Vector3::zeros(), &ranges, rates);
            // The fix's covariance, from the epoch's information without the noise.
            let plain = InsBound::new(&c, 0.03, BoundCoupling::Loose, earth, *frame.rotation());
            let k6 = plain
                .information(&info)
                .fixed_view::<6, 6>(0, 0)
                .into_owned();
            let (pos_cov, vel_cov) = if rates {
                let cov = k6.try_inverse().unwrap();
                let [h, v] = noise;
                let extra = Matrix3::from_diagonal(&Vector3::new(h * h, h * h, v * v));
                let vel = cov.fixed_view::<3, 3>(3, 3).into_owned() + extra;
                (cov.fixed_view::<3, 3>(0, 0).into_owned(), Some(vel))
            } else {
                let pos = k6.fixed_view::<3, 3>(0, 0).into_owned();
                (pos.try_inverse().unwrap(), None)
            };
            let info18 = bound.information(&info);
            for k in 1..=300 {
                let s = imu_at(k);
                ekf.propagate(&s);
                bound.predict(&mut st, s.t_s, &cn, &fn_, 1.2);
                if k % 100 == 0 {
                    match vel_cov {
                        Some(vc) => ekf
                            .update_position_velocity(
                                &init.pos_enu_m,
                                &pos_cov,
                                &Vector3::zeros(),
                                &vc,
                            )
                            .unwrap(),
                        None => ekf.update_position(&init.pos_enu_m, &pos_cov).unwrap(),
                    };
                    assert!(bound.update(&mut st, &info18));
                }
            }
            let p = ekf.covariance();
            let b = st.b.fixed_view::<15, 15>(0, 0).into_owned();
            let rel = normalised_gap(&p.fixed_view::<15, 15>(0, 0).into_owned(), &b);
            assert!(
                rel < 1e-6,
                "loose {rates} {noise:?}: normalised difference {rel:e}"
            );
            let pos = (0..3).map(|i| p[(i, i)]).sum::<f64>();
            assert!((st.position_mse_m2() - pos).abs() < 1e-6 * pos);
            loose_mse.push(st.b[(3, 3)] + st.b[(4, 4)] + st.b[(5, 5)]);
        }
        // The noise is felt: the velocity bound with it lies above the one without.
        assert!(loose_mse[2] > 1.5 * loose_mse[1], "{loose_mse:?}");

        // Tight: the tight EKF with every pseudorange and range rate at the truth, without
        // and with the gait's velocity noise on the rates.
        let clk = TightClockConfig {
            gate_chi2: None,
            ..TightClockConfig::default()
        };
        let mut tight_mse = Vec::new();
        for noise in [[0.0, 0.0], gait] {
            let mut bound = InsBound::new(
                &c,
                0.03,
                BoundCoupling::Tight(clk),
                earth,
                *frame.rotation(),
            )
            .with_velocity_noise(noise);
            let mut c1 = c0;
            c1.nis_gate = None;
            let mut tight = InsTightEkf::new(init, earth, &c1, &clk).with_velocity_noise(noise);
            bound.prior = *tight.covariance();
            let mut st = bound.start(0.0);
            let mut info = EpochInfo::zeros();
            bound.add_epoch_information(&mut info, &at, &Vector3::zeros(), &ranges, true);
            let info18 = bound.information(&info);
            for k in 1..=300 {
                let s = imu_at(k);
                tight.propagate(&s);
                bound.predict(&mut st, s.t_s, &cn, &fn_, 1.2);
                if k % 100 == 0 {
                    for m in &ranges {
                        // The true range and rate as measured: the innovation is zero.
                        let mut m = *m;
                        m.pseudorange_m = (m.emitter_pos_ecef_m - at).norm();
                        let u = (m.emitter_pos_ecef_m - at).normalize();
                        m.range_rate_mps = Some(u.dot(&m.emitter_vel_ecef_mps));
                        tight.update_range(&m, &frame, 0.0).unwrap();
                        tight.update_range_rate(&m, &frame, 0.0).unwrap();
                    }
                    assert!(bound.update(&mut st, &info18));
                }
            }
            let p = tight.covariance();
            let rel = normalised_gap(
                &p.fixed_view::<15, 15>(0, 0).into_owned(),
                &st.b.fixed_view::<15, 15>(0, 0).into_owned(),
            );
            assert!(rel < 1e-6, "tight {noise:?}: normalised difference {rel:e}");
            let clocks = (15..18)
                .map(|i| (p[(i, i)] - st.b[(i, i)]).abs() / p[(i, i)])
                .fold(0.0, f64::max);
            assert!(
                clocks < 1e-6,
                "tight clocks {noise:?}: relative difference {clocks:e}"
            );
            tight_mse.push(st.b[(3, 3)] + st.b[(4, 4)] + st.b[(5, 5)]);
        }
        assert!(tight_mse[1] > 1.5 * tight_mse[0], "{tight_mse:?}");
    }
}
