//! The abstract papers' own estimators: seed 001's particle filter on the 2-D Singer model
//! and seed 003's EKF and particle filter on the 3-D plane variable-speed turning model,
//! each with one pseudorange clock state per system — and, since the models are kept
//! apart from the algorithms, every other filter of the family on the same models
//! ([`PaperFilter`]: EKF, UKF, CKF, strong tracking, relative-entropy KF, and the particle
//! filters: SIR, regularised, Rao-Blackwellised, marginalised, Gaussian), chosen
//! by `filter` beside `[estimator.process]`.
//!
//! # Filters
//!
//! Every filter takes an epoch's pseudoranges one at a time, each relinearised (or, for
//! the sigma-point filters and the RE-KF, its points redrawn) at the estimate the previous
//! one left, which for the EKF is the paper's update. The strong tracking filter computes
//! one fading factor per epoch from all the epoch's whitened pseudorange innovations at
//! the prediction ([`EpochFading`]) before those updates, as the family's does on seed
//! 000's model. A state these models know exactly has zero variance — the clocks of
//! `clocks = "known"`, the clock of a system the world lacks, seed 001's x axis (uniform
//! motion without noise) and, at the start, everything but seed 003's accelerations
//! (`P(0) = Q(T)`) — so the covariance is only semi-definite; the sigma-point filters and
//! the RE-KF then draw their points from a pivoted Cholesky factor
//! ([`crate::fusion::kalman::psd_sqrt`]), whose points along a known state sit on the
//! mean.
//!
//! # State
//!
//! The motion states of the paper's model, then one clock state (m) per system in
//! [`System::ALL`] order (GPS, BDS, DTMB, TC-OFDM):
//!
//! ```text
//! seed 001 (N = 5 + 4):  [x, ẋ, y, ẏ, ÿ, b_GPS, b_BDS, b_DTMB, b_TCOFDM]   (Singer5)
//! seed 003 (N = 9 + 4):  [p, v, a, b_GPS, b_BDS, b_DTMB, b_TCOFDM]          (PlaneTurning)
//! ρ_j = ‖r_j − r‖ + b_sys(j) + ε_j                                         (Pseudoranges)
//! ```
//!
//! in the world's ENU frame (x east, y north, z up); the estimate is reported in ECEF. Seed
//! 001's eq. 1 has a receiver clock `b_u` on every range and a DTMB-to-GPS offset `b_D` on
//! the DTMB ranges only; that is the same as a GPS clock `b_GPS = b_u` and a DTMB clock
//! `b_DTMB = b_u + b_D`. Seed 003's eqs. 1–3 have one clock per system (`a₁`, `a₂`, `a₃`).
//! A clock state of a system the world does not have is inert (zero variance, no range
//! refers to it).
//!
//! # Clocks: known or estimated
//!
//! * `clocks = "known"`: the clock states hold the offsets the world's emitters declare,
//!   with zero variance. This is seed 001's reading: its state `[x, ẋ, y, ẏ, ÿ]` has no
//!   clock, so its filter must take the offsets of eq. 1 as calibrated.
//! * `clocks = "estimated"`: the clocks are unknowns, as seed 003 §2.1 says ("at least six
//!   unknown parameters, namely, three-dimensional position coordinates and clock deviation
//!   of three systems"). Each system's clock is initialised from the first batch that has
//!   its ranges, at the predicted position: `b_s = mean_j∈s (ρ_j − ‖r_j − r̂‖)` (per
//!   particle for the particle filter, so that position and clock are drawn jointly), with
//!   variance `σ_s² / n_s`, and then follows a random walk of PSD `clock_noise_m2ps`.
//!
//! # The 2-D case (seed 001)
//!
//! The paper works in the horizontal plane. The ranges are computed with the receiver at
//! the plane's height (the platform's start height, the "surveyed start point"), and the
//! estimate is reported on that plane with a vertical variance of
//! [`PLANE_VARIANCE_M2`] — small against the horizontal variances, so that the position
//! NEES is in effect the horizontal one, but invertible so that it stays defined.
//!
//! # Initialisation
//!
//! Both papers start their filters at the known X(0): seed 001 step 1 draws the particles
//! from "the distribution function of system noise" around X(0); seed 003 gives X(0) and
//! P(0) without values. The prior is therefore `N(X(0), P(0))` with `P(0) = Q(T)` (one step's
//! process noise) unless `initial_sigma` gives standard deviations, at the world's start
//! time; the first batch is predicted to from there.

use crate::core::rng::{StreamRng, TrialRng};
use crate::core::{EnuFrame, GpsTime, System};
use crate::fusion::kalman::{
    Ekf, EpochFading, Gating, RelativeEntropyKf, ResidualGate, SigmaPointKf, UpdateReport,
};
use crate::fusion::models::{
    PlaneTurning, ProcessModel, Pseudoranges, RangeRow, Singer5, StateLayout,
};
use crate::fusion::particle::{
    CovarianceEstimate, KernelPlacement, ParticleBuffer, ParticleFilter, PfVariant,
    PseudorangeLikelihood, Resampling,
};
use crate::fusion::preprocess::FrontEnd;
use crate::fusion::selection::ModeSelection;
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, MeasurementBatch, RangeMeasurement, SourceKind,
};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::Deserialize;

/// The vertical variance (m²) reported by a 2-D estimator on its plane.
pub const PLANE_VARIANCE_M2: f64 = 1e-2;

/// Number of clock states appended to a paper model's motion states.
pub const N_CLOCKS: usize = System::COUNT;

/// Whether the receiver knows its clock offsets.
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ClockMode {
    /// The offsets the world's emitters declare, exactly (seed 001's 5-state reading).
    Known,
    /// One unknown clock per system (seed 003 eqs. 1–3).
    Estimated,
}

fn d_alpha() -> f64 {
    0.1
}
fn d_accel_var() -> f64 {
    3.5
}
fn d_singer_x0() -> [f64; 5] {
    [4000.0, 14.0, 0.0, 11.0, 0.0]
}
fn d_known() -> ClockMode {
    ClockMode::Known
}
fn d_estimated() -> ClockMode {
    ClockMode::Estimated
}
fn d_attenuation() -> f64 {
    0.03
}
fn d_turn() -> f64 {
    0.1
}
fn d_turn_noise() -> f64 {
    0.01
}
fn d_turn_x0() -> [f64; 9] {
    [0.0, 0.0, 0.0, 4.0, -4.0, 4.0, 0.5, -0.5, -0.5]
}
fn d_clock_noise() -> f64 {
    0.0
}

/// `[estimator.process]`: the process model an estimator runs. Absent, or
/// `model = "pva_clock"`, is seed 000's position–velocity–acceleration + clock model of
/// the filter family ([`crate::fusion::family`]).
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum ProcessSpec {
    /// Seed 000's 12-state model (the filter family's default).
    PvaClock {},
    /// Seed 001: uniform motion in x, Singer in y ([`Singer5`]), on the plane.
    #[serde(rename = "singer_2d")]
    Singer2d {
        /// Manoeuvre frequency α (1/s); default 0.1.
        #[serde(default = "d_alpha")]
        alpha_per_s: f64,
        /// Acceleration variance σ_a² ((m/s²)²); default 3.5.
        #[serde(default = "d_accel_var")]
        accel_var_m2ps4: f64,
        /// X(0) = [x, ẋ, y, ẏ, ÿ] (ENU m, m/s, m/s²); default [4000, 14, 0, 11, 0].
        #[serde(default = "d_singer_x0")]
        initial_state: [f64; 5],
        /// Standard deviations of the prior around X(0); default √diag of P(0) = Q(T).
        #[serde(default)]
        initial_sigma: Option<[f64; 5]>,
        /// `known` (default) or `estimated`.
        #[serde(default = "d_known")]
        clocks: ClockMode,
        /// Random-walk PSD of estimated clocks (m²/s); default 0 (constant offsets).
        #[serde(default = "d_clock_noise")]
        clock_noise_m2ps: f64,
    },
    /// Seed 003: the 3-D plane variable-speed turning model ([`PlaneTurning`]).
    PlaneTurning {
        /// Attenuation coefficient α (1/s); default 0.03.
        #[serde(default = "d_attenuation")]
        attenuation_per_s: f64,
        /// Angular velocity ω (rad/s); default 0.1.
        #[serde(default = "d_turn")]
        turn_rate_rad_per_s: f64,
        /// Acceleration noise variance per step ((m/s²)²); default 0.01.
        #[serde(default = "d_turn_noise")]
        noise_var_m2ps4: f64,
        /// X(0) = [p, v, a] (ENU); default [0, 0, 0, 4, −4, 4, 0.5, −0.5, −0.5].
        #[serde(default = "d_turn_x0")]
        initial_state: [f64; 9],
        /// Standard deviations of the prior around X(0); default √diag of P(0) = Q(T).
        #[serde(default)]
        initial_sigma: Option<[f64; 9]>,
        /// `estimated` (default) or `known`.
        #[serde(default = "d_estimated")]
        clocks: ClockMode,
        /// Random-walk PSD of estimated clocks (m²/s); default 0 (constant offsets).
        #[serde(default = "d_clock_noise")]
        clock_noise_m2ps: f64,
    },
}

impl ProcessSpec {
    /// The name a world file writes.
    pub fn label(&self) -> &'static str {
        match self {
            ProcessSpec::PvaClock {} => "pva_clock",
            ProcessSpec::Singer2d { .. } => "singer_2d",
            ProcessSpec::PlaneTurning { .. } => "plane_turning",
        }
    }

    /// The degrees of freedom of the model's position NEES: the position axes along which
    /// the estimate can err. The 2-D model's estimate lies on the truth's plane (its
    /// vertical error is zero by construction and its vertical variance the fixed
    /// [`PLANE_VARIANCE_M2`]), and its x moves uniformly without process noise (seed 001
    /// §2), so x is known whenever the prior gives x and ẋ no spread, as the paper's
    /// `P(0) = Q(T)` does: every filter then carries X(0)'s x exactly, its east error is
    /// zero (its NEES term, against the covariance floor, below 10⁻¹⁰), and a consistent
    /// filter's NEES is χ² with 1 degree of freedom; with an `initial_sigma` on x or ẋ, 2.
    /// The 3-D models: 3.
    pub fn position_dof(&self) -> usize {
        match self {
            ProcessSpec::Singer2d { initial_sigma, .. } => {
                let x_known = initial_sigma.is_none_or(|s| s[0] == 0.0 && s[1] == 0.0);
                if x_known {
                    1
                } else {
                    2
                }
            }
            ProcessSpec::PvaClock {} | ProcessSpec::PlaneTurning { .. } => 3,
        }
    }

    /// [`Self::position_dof`] once the estimator has been reset in a trial: the restart
    /// from a least-squares fix of the epoch's ranges places x with the fix's error, so
    /// the 2-D model's x can err from then on (2); the 3-D models keep 3.
    pub fn position_dof_after_restart(&self) -> usize {
        match self {
            ProcessSpec::Singer2d { .. } => 2,
            ProcessSpec::PvaClock {} | ProcessSpec::PlaneTurning { .. } => 3,
        }
    }
}

/// Which filter a paper estimator runs. Every member of the Kalman family runs every paper
/// model (the models are kept apart from the algorithms, [`crate::fusion::models`]); each
/// takes the epoch's pseudoranges one at a time, relinearised at the latest estimate, with
/// seed 004's residual gate `|ν| ≤ C·√S` (eq. 24) when `residual_gate_c` is set and no χ²
/// gate (the papers' filters have none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PaperFilter {
    /// The EKF (Joseph form), as in seed 003 (eqs. 9–12).
    Ekf { residual_gate_c: Option<f64> },
    /// The unscented Kalman filter with Merwe's scaled points `(α, β, κ)`.
    Ukf {
        alpha: f64,
        beta: f64,
        kappa: f64,
        residual_gate_c: Option<f64>,
    },
    /// The cubature Kalman filter (Arasaratnam & Haykin).
    Ckf { residual_gate_c: Option<f64> },
    /// The strong tracking filter: the EKF with its prediction inflated once per epoch by
    /// the fading factor of the epoch's whitened pseudorange innovations
    /// ([`EpochFading`]: forgetting ρ, weakening β, largest factor λ_max).
    Stf {
        forgetting: f64,
        weakening: f64,
        max_fading: f64,
        residual_gate_c: Option<f64>,
    },
    /// Seed 004's relative-entropy Kalman filter with coupling threshold ℵ_threshold.
    Rekf {
        aleph_threshold: f64,
        residual_gate_c: Option<f64>,
    },
    /// A particle filter ([`crate::fusion::particle`]): `particles`, the resampling
    /// scheme, the fraction θ of N below which N_eff triggers resampling, and the member
    /// of the family — SIR as in seed 001 §4 / seed 003 §2.3, regularised,
    /// Rao-Blackwellised over the clock states, marginalised, or the Gaussian PF.
    Pf {
        particles: usize,
        resampling: Resampling,
        neff_threshold: f64,
        variant: PfVariant,
        /// Draw from the linearised optimal proposal instead of the process model.
        linearised: bool,
        /// Where the regularisation kernel goes after a resampling.
        kernel: KernelPlacement,
        /// How the Gaussian PF estimates its covariance.
        covariance: CovarianceEstimate,
        /// Bring each epoch's likelihood in by progressive correction (the regularised
        /// filter with the prior proposal only).
        progressive: bool,
    },
}

/// What a paper estimator needs from its world.
pub struct PaperContext<'a> {
    pub frame: &'a EnuFrame,
    pub start: GpsTime,
    /// The platform's true start (ENU): the plane of the 2-D model.
    pub start_enu_m: Vector3<f64>,
    /// The clock term of each system's ranges the world declares (for `clocks = "known"`).
    pub emitter_clocks_m: Option<[f64; N_CLOCKS]>,
    pub rng: &'a TrialRng,
}

/// A motion model with `N − NM` clock states appended, each a random walk of PSD
/// `clock_q[s]` (m²/s).
#[derive(Clone, Copy, Debug)]
pub struct WithClocks<P, const NM: usize> {
    motion: P,
    clock_q: [f64; N_CLOCKS],
}

impl<P: ProcessModel<NM>, const NM: usize, const N: usize> ProcessModel<N> for WithClocks<P, NM> {
    fn f(&self, x: &SVector<f64, N>, dt_s: f64) -> SVector<f64, N> {
        let m = SVector::<f64, NM>::from_fn(|i, _| x[i]);
        let fm = self.motion.f(&m, dt_s);
        let mut y = *x;
        y.fixed_rows_mut::<NM>(0).copy_from(&fm);
        y
    }
    fn jacobian(&self, x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let m = SVector::<f64, NM>::from_fn(|i, _| x[i]);
        let mut j = SMatrix::<f64, N, N>::identity();
        j.fixed_view_mut::<NM, NM>(0, 0)
            .copy_from(&self.motion.jacobian(&m, dt_s));
        j
    }
    fn q(&self, x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let m = SVector::<f64, NM>::from_fn(|i, _| x[i]);
        let mut q = SMatrix::<f64, N, N>::zeros();
        q.fixed_view_mut::<NM, NM>(0, 0)
            .copy_from(&self.motion.q(&m, dt_s));
        for (s, psd) in self.clock_q.iter().enumerate() {
            if NM + s < N {
                q[(NM + s, NM + s)] = psd * dt_s.max(0.0);
            }
        }
        q
    }
}

enum Core<const N: usize> {
    Ekf(Box<Ekf<N>>),
    Sigma(Box<SigmaPointKf<N>>),
    Stf(Box<Ekf<N>>, Box<EpochFading<N>>),
    Rekf(Box<RelativeEntropyKf<N>>),
    Pf(Box<ParticleFilter<N>>),
}

impl<const N: usize> Core<N> {
    /// The filter of `filter` started at `(x0, p0)`.
    fn new(
        filter: PaperFilter,
        pos_cols: [Option<usize>; 3],
        static_cols: [bool; N],
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        rng: &mut StreamRng,
    ) -> Result<Self, String> {
        let err = |e: crate::fusion::kalman::FilterError| e.to_string();
        let gating = |c: Option<f64>| Gating {
            chi2_prob: None,
            residual: c.map(ResidualGate::sigmas),
        };
        Ok(match filter {
            PaperFilter::Ekf { residual_gate_c } => Core::Ekf(Box::new(
                Ekf::new(x0, p0)
                    .and_then(|f| f.with_gating(gating(residual_gate_c)))
                    .map_err(err)?,
            )),
            PaperFilter::Ukf {
                alpha,
                beta,
                kappa,
                residual_gate_c,
            } => Core::Sigma(Box::new(
                SigmaPointKf::unscented(x0, p0, alpha, beta, kappa)
                    .and_then(|f| f.with_gating(gating(residual_gate_c)))
                    .map_err(err)?,
            )),
            PaperFilter::Ckf { residual_gate_c } => Core::Sigma(Box::new(
                SigmaPointKf::cubature(x0, p0)
                    .and_then(|f| f.with_gating(gating(residual_gate_c)))
                    .map_err(err)?,
            )),
            PaperFilter::Stf {
                forgetting,
                weakening,
                max_fading,
                residual_gate_c,
            } => Core::Stf(
                Box::new(
                    Ekf::new(x0, p0)
                        .and_then(|f| f.with_gating(gating(residual_gate_c)))
                        .map_err(err)?,
                ),
                Box::new(EpochFading::new(forgetting, weakening, max_fading).map_err(err)?),
            ),
            PaperFilter::Rekf {
                aleph_threshold,
                residual_gate_c,
            } => Core::Rekf(Box::new(
                RelativeEntropyKf::new(
                    x0,
                    p0,
                    aleph_threshold,
                    residual_gate_c.map(ResidualGate::sigmas),
                )
                .map_err(err)?,
            )),
            PaperFilter::Pf {
                particles,
                resampling,
                neff_threshold,
                variant,
                kernel,
                covariance,
                progressive,
                ..
            } => {
                let buf = ParticleBuffer::<N>::new(particles).map_err(|e| e.to_string())?;
                let pf = ParticleFilter::new(buf, resampling, neff_threshold)
                    .map_err(|e| e.to_string())?
                    .with_kernel(kernel)
                    .with_static_components(static_cols)
                    .with_covariance_estimate(covariance)
                    .with_progressive_correction(progressive);
                let mut pf = match variant {
                    PfVariant::Sir => pf,
                    PfVariant::Regularised => pf.regularised(),
                    // The clock states are the last N_CLOCKS, one per system.
                    PfVariant::RaoBlackwellised => pf
                        .rao_blackwellised(std::array::from_fn(|s| Some(N - N_CLOCKS + s)))
                        .map_err(|e| e.to_string())?,
                    PfVariant::Marginalised => pf
                        .marginalised(pos_cols, std::array::from_fn(|s| Some(N - N_CLOCKS + s)))
                        .map_err(|e| e.to_string())?,
                    // All-Gaussian: the clocks are sampled with the rest (no Kalman part).
                    PfVariant::Gaussian => pf.gaussian(),
                };
                pf.init_gaussian(&x0, &p0, rng).map_err(|e| e.to_string())?;
                Core::Pf(Box::new(pf))
            }
        })
    }

    /// The state and covariance (the particle cloud's weighted moments for the PF).
    fn moments(&self) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        match self {
            Core::Ekf(f) | Core::Stf(f, _) => (*f.state(), *f.covariance()),
            Core::Sigma(f) => (*f.state(), *f.covariance()),
            Core::Rekf(f) => (*f.state(), *f.covariance()),
            Core::Pf(p) => (p.mean(), p.covariance()),
        }
    }

    /// Restarts a Kalman-type filter at `(x, p)`, keeping its tuning; the strong tracking
    /// filter also forgets its innovation memory and pending prediction, so that the
    /// restart is not undone by this epoch's fading factor. False for the particle filter
    /// (which is re-drawn by its caller) or when `(x, p)` is unusable.
    fn restart(&mut self, x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> bool {
        match self {
            Core::Ekf(f) => f.restart(x, p).is_ok(),
            Core::Stf(f, fading) => {
                fading.reset();
                f.restart(x, p).is_ok()
            }
            Core::Sigma(f) => f.restart(x, p).is_ok(),
            Core::Rekf(f) => f.restart(x, p).is_ok(),
            Core::Pf(_) => false,
        }
    }

    /// One pseudorange update of a Kalman-type filter; `None` for the particle filter.
    fn update(&mut self, pr: &Pseudoranges<N, 1>, z: &SVector<f64, 1>) -> Option<UpdateReport> {
        Some(match self {
            Core::Ekf(f) | Core::Stf(f, _) => f.update(pr, z),
            Core::Sigma(f) => f.update(pr, z),
            Core::Rekf(f) => f.update(pr, z).0,
            Core::Pf(_) => return None,
        })
    }
}

/// A paper model with its filter, driven by the engine (see the module documentation).
pub struct PaperEstimator<P, const NM: usize, const N: usize> {
    name: String,
    model: WithClocks<P, NM>,
    layout: StateLayout,
    frame: EnuFrame,
    /// The plane's height (2-D models), reported as the estimate's up coordinate.
    plane_up_m: Option<f64>,
    core: Core<N>,
    last_t: GpsTime,
    clocks: ClockMode,
    /// Which systems' clocks have been initialised (estimated clocks).
    clock_ready: [bool; N_CLOCKS],
    front: FrontEnd,
    rng: StreamRng,
    lik: PseudorangeLikelihood,
    rows: Vec<(RangeRow, f64)>,
    geometry: Vec<(Vector3<f64>, usize)>,
    /// The prior the filter started from, to restart it after a divergence.
    x0: SVector<f64, N>,
    p0: SMatrix<f64, N, N>,
    /// Consecutive epochs in which a particle filter's N_eff collapsed below
    /// [`COLLAPSE_FRACTION`] of its particles.
    collapse_run: u32,
    /// Set by a reset: the next epoch restarts the filter from a least-squares fix of its
    /// ranges when they determine one.
    recover: bool,
    /// A particle filter with the linearised proposal: a resampling filter's prediction
    /// only moves the cloud by `f`, and the update draws the process noise; the Gaussian
    /// filter predicts its moments as always and draws from their linearised update.
    linearised: bool,
}

/// A particle filter whose effective sample size stays below this fraction of its
/// particles for [`COLLAPSE_EPOCHS`] consecutive epochs is declared diverged: its weight
/// sits on a handful of particles far in the likelihood's tail. (A filter whose cloud
/// matches the likelihood keeps N_eff near N/2 or above; the fraction is a detector's
/// choice, not a paper's value.)
pub const COLLAPSE_FRACTION: f64 = 0.02;

/// See [`COLLAPSE_FRACTION`]; the engine's divergence watch uses the same window.
pub const COLLAPSE_EPOCHS: u32 = 10;

/// Builds the estimator for a paper `spec` (not [`ProcessSpec::PvaClock`]).
///
/// # Errors
/// An unusable parameter, or `clocks = "known"` in a world without emitters.
pub fn build(
    name: &str,
    spec: &ProcessSpec,
    filter: PaperFilter,
    systems: &[System],
    selection: Option<&ModeSelection>,
    ctx: &PaperContext<'_>,
) -> Result<Box<dyn Estimator>, String> {
    match spec {
        ProcessSpec::PvaClock {} => {
            Err("process model 'pva_clock' is built by the filter family".into())
        }
        ProcessSpec::Singer2d {
            alpha_per_s,
            accel_var_m2ps4,
            initial_state,
            initial_sigma,
            clocks,
            clock_noise_m2ps,
        } => {
            let motion = Singer5::new(*alpha_per_s, *accel_var_m2ps4)
                .map_err(|e| format!("process: {e}"))?;
            let layout = layout([Some(0), Some(2), None], [Some(1), Some(3), None], 5);
            let est = PaperEstimator::<Singer5, 5, { 5 + N_CLOCKS }>::new(
                name,
                motion,
                layout,
                SVector::from(*initial_state),
                initial_sigma.map(SVector::from),
                *clocks,
                *clock_noise_m2ps,
                Some(ctx.start_enu_m.z),
                filter,
                systems,
                selection,
                ctx,
            )?;
            Ok(Box::new(est))
        }
        ProcessSpec::PlaneTurning {
            attenuation_per_s,
            turn_rate_rad_per_s,
            noise_var_m2ps4,
            initial_state,
            initial_sigma,
            clocks,
            clock_noise_m2ps,
        } => {
            let motion =
                PlaneTurning::new(*attenuation_per_s, *turn_rate_rad_per_s, *noise_var_m2ps4)
                    .map_err(|e| format!("process: {e}"))?;
            let layout = layout([Some(0), Some(1), Some(2)], [Some(3), Some(4), Some(5)], 9);
            let est = PaperEstimator::<PlaneTurning, 9, { 9 + N_CLOCKS }>::new(
                name,
                motion,
                layout,
                SVector::from(*initial_state),
                initial_sigma.map(SVector::from),
                *clocks,
                *clock_noise_m2ps,
                None,
                filter,
                systems,
                selection,
                ctx,
            )?;
            Ok(Box::new(est))
        }
    }
}

fn layout(pos: [Option<usize>; 3], vel: [Option<usize>; 3], nm: usize) -> StateLayout {
    StateLayout {
        pos,
        vel,
        clock: std::array::from_fn(|s| Some(nm + s)),
        isb: [None; System::COUNT],
        drift: None,
    }
}

impl<P, const NM: usize, const N: usize> PaperEstimator<P, NM, N>
where
    P: ProcessModel<NM> + Copy + Send,
{
    #[allow(clippy::too_many_arguments)]
    fn new(
        name: &str,
        motion: P,
        layout: StateLayout,
        x0_motion: SVector<f64, NM>,
        sigma0: Option<SVector<f64, NM>>,
        clocks: ClockMode,
        clock_noise_m2ps: f64,
        plane_up_m: Option<f64>,
        filter: PaperFilter,
        systems: &[System],
        selection: Option<&ModeSelection>,
        ctx: &PaperContext<'_>,
    ) -> Result<Self, String> {
        if N != NM + N_CLOCKS {
            return Err(format!("state dimension {N} ≠ {NM} + {N_CLOCKS}"));
        }
        if !x0_motion.iter().all(|v| v.is_finite()) {
            return Err("process.initial_state: expected finite numbers".into());
        }
        if let Some(s) = &sigma0 {
            if !s.iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err("process.initial_sigma: expected finite values ≥ 0".into());
            }
        }
        if !(clock_noise_m2ps.is_finite() && clock_noise_m2ps >= 0.0) {
            return Err(format!(
                "process.clock_noise_m2ps: expected a finite PSD ≥ 0, got {clock_noise_m2ps}"
            ));
        }
        let known = match clocks {
            ClockMode::Known => Some(ctx.emitter_clocks_m.ok_or(
                "process.clocks: \"known\" takes the clock offsets of [sensors.emitters], which this world does not have; use clocks = \"estimated\"",
            )?),
            ClockMode::Estimated => None,
        };
        let q_clock = if known.is_some() {
            0.0
        } else {
            clock_noise_m2ps
        };
        let model = WithClocks {
            motion,
            clock_q: [q_clock; N_CLOCKS],
        };
        let mut x0 = SVector::<f64, N>::zeros();
        x0.fixed_rows_mut::<NM>(0).copy_from(&x0_motion);
        let mut p0 = SMatrix::<f64, N, N>::zeros();
        match sigma0 {
            Some(s) => {
                for i in 0..NM {
                    p0[(i, i)] = s[i] * s[i];
                }
            }
            None => p0
                .fixed_view_mut::<NM, NM>(0, 0)
                .copy_from(&motion.q(&x0_motion, 1.0)),
        }
        if let Some(k) = known {
            for s in 0..N_CLOCKS {
                x0[NM + s] = k[s];
            }
        }
        let mut rng = ctx.rng.stream(&format!("estimator/{name}/paper"));
        if let PaperFilter::Pf {
            variant: PfVariant::Marginalised,
            linearised: true,
            ..
        } = filter
        {
            return Err(
                "options.pf_proposal = \"linearised\" is for filter = \"pf\", \"sir\", \"rbpf\" or \"gpf\": the marginalised filter draws from its exact prediction".into(),
            );
        }
        if let PaperFilter::Pf {
            variant,
            linearised,
            progressive: true,
            ..
        } = filter
        {
            if !variant.takes_progressive_correction(linearised) {
                return Err(
                    "options.pf_correction = \"progressive\" is for filter = \"pf\" or \"rbpf\" with pf_proposal = \"prior\": the linearised proposal already conditions on the ranges, and the other members keep their single update".into(),
                );
            }
        }
        // The clocks (the last N_CLOCKS states) are the model's constants when their
        // random walk has no noise.
        let static_cols = std::array::from_fn(|k| k >= NM && q_clock == 0.0);
        let core = Core::new(filter, layout.pos, static_cols, x0, p0, &mut rng)?;
        let mut est = Self {
            name: name.to_string(),
            model,
            layout,
            frame: ctx.frame.clone(),
            plane_up_m,
            core,
            last_t: ctx.start,
            clocks,
            clock_ready: [known.is_some(); N_CLOCKS],
            front: FrontEnd::new(systems, &[], selection, None)?,
            rng,
            lik: PseudorangeLikelihood::with_capacity(64),
            rows: Vec::with_capacity(64),
            geometry: Vec::with_capacity(64),
            x0,
            p0,
            collapse_run: 0,
            recover: false,
            linearised: matches!(
                filter,
                PaperFilter::Pf {
                    linearised: true,
                    ..
                }
            ),
        };
        est.set_rb_clock_priors();
        Ok(est)
    }

    /// A Rao-Blackwellised filter's clock priors: the declared offsets with zero variance
    /// for known clocks, a flat prior for estimated ones (the first ranges of a system
    /// then set its clock exactly, per particle).
    fn set_rb_clock_priors(&mut self) {
        if let Core::Pf(pf) = &mut self.core {
            for s in 0..N_CLOCKS {
                match self.clocks {
                    ClockMode::Known => pf.set_clock_prior(s, self.x0[NM + s], 0.0),
                    ClockMode::Estimated => pf.set_clock_prior(s, 0.0, f64::INFINITY),
                }
            }
        }
    }

    /// The ENU position of a state (the plane's height for a 2-D model).
    fn position_enu(&self, x: &SVector<f64, N>) -> Vector3<f64> {
        Vector3::from_fn(|a, _| match self.layout.pos[a] {
            Some(k) => x[k],
            None => self.plane_up_m.unwrap_or(0.0),
        })
    }

    fn moments(&self) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        self.core.moments()
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        let (x, p) = self.moments();
        let pos = self.position_enu(&x);
        let vel = Vector3::from_fn(|a, _| self.layout.vel[a].map_or(0.0, |k| x[k]));
        let cov_enu = Matrix3::from_fn(|i, j| match (self.layout.pos[i], self.layout.pos[j]) {
            (Some(a), Some(b)) => p[(a, b)],
            (None, None) if i == j => PLANE_VARIANCE_M2,
            _ => 0.0,
        });
        let cov_enu = floor_psd(&cov_enu, COV_FLOOR_M2);
        let r = self.frame.rotation().transpose();
        Some(Estimate {
            t,
            pos_ecef_m: self.frame.ecef_of_enu(&pos),
            vel_ecef_mps: Some(self.frame.ecef_vector_of_enu(&vel)),
            cov_pos_m2: r * cov_enu * r.transpose(),
        })
    }

    /// Fills `rows` with the admitted ranges, emitter positions in ENU.
    fn load_rows(&mut self) {
        self.rows.clear();
        for m in &self.front.ranges {
            let m: &RangeMeasurement = m;
            let mut row = RangeRow::from(m);
            row.emitter_pos_m = self.frame.enu_of_ecef(&m.emitter_pos_ecef_m);
            row.emitter_vel_mps = Vector3::zeros();
            self.rows.push((row, m.pseudorange_m));
        }
    }

    /// Restarts the filter after a divergence from the weighted least-squares fix of this
    /// epoch's ranges (Gauss–Newton from the current estimate over the position
    /// components and, for estimated clocks, the clock of each system with ranges): the
    /// position is drawn from the fix and its covariance `(AᵀWA)⁻¹`, every other state
    /// from the prior around the current estimate; estimated clocks are then initialised
    /// from the ranges as at the start. Nothing happens when the ranges do not determine a
    /// fix (fewer ranges than unknowns, a singular geometry or no convergence).
    fn restart_from_least_squares(&mut self) {
        const MAX_UNKNOWNS: usize = 3 + N_CLOCKS;
        type Normal = SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>;
        let (mut x, _) = self.moments();
        if !x.iter().all(|v| v.is_finite()) {
            x = self.x0;
        }
        // Unknown i is state component states[i]; the first n_pos are positions along
        // axes[i].
        let mut states = [0usize; MAX_UNKNOWNS];
        let mut axes = [0usize; 3];
        let mut n = 0;
        for (a, k) in self.layout.pos.iter().enumerate() {
            if let Some(k) = *k {
                states[n] = k;
                axes[n] = a;
                n += 1;
            }
        }
        let n_pos = n;
        if self.clocks == ClockMode::Estimated {
            for s in 0..N_CLOCKS {
                let sys = System::ALL[s];
                if self.rows.iter().any(|(r, _)| r.system == sys) {
                    states[n] = NM + s;
                    n += 1;
                }
            }
        }
        if n_pos == 0 || self.rows.len() < n {
            return;
        }
        let mut normal = Normal::identity();
        let mut converged = false;
        for _ in 0..20 {
            let mut ata = Normal::zeros();
            let mut atb = SVector::<f64, MAX_UNKNOWNS>::zeros();
            let pos = position_of(&self.layout, self.plane_up_m, &x);
            for (row, z) in &self.rows {
                let d = pos - row.emitter_pos_m;
                let r = d.norm();
                if r.is_nan() || r <= 0.0 {
                    return;
                }
                let mut a = SVector::<f64, MAX_UNKNOWNS>::zeros();
                for i in 0..n_pos {
                    a[i] = d[axes[i]] / r;
                }
                let clock = NM + row.system.index();
                for i in n_pos..n {
                    if states[i] == clock {
                        a[i] = 1.0;
                    }
                }
                let w = 1.0 / (row.sigma_m * row.sigma_m);
                ata += a * a.transpose() * w;
                atb += a * ((z - r - x[clock]) * w);
            }
            for i in n..MAX_UNKNOWNS {
                ata[(i, i)] = 1.0;
            }
            let Some(chol) = ata.cholesky() else {
                return;
            };
            let dx = chol.solve(&atb);
            for i in 0..n {
                x[states[i]] += dx[i];
            }
            normal = ata;
            if !dx.iter().all(|v| v.is_finite()) {
                return;
            }
            if dx.norm() < 1e-4 {
                converged = true;
                break;
            }
        }
        let Some(cov_ls) = normal.try_inverse() else {
            return;
        };
        if !converged || !cov_ls.iter().all(|v| v.is_finite()) {
            return;
        }
        let mut p = self.p0;
        for i in 0..n_pos {
            for k in 0..N {
                p[(states[i], k)] = 0.0;
                p[(k, states[i])] = 0.0;
            }
        }
        for i in 0..n_pos {
            for j in 0..n_pos {
                p[(states[i], states[j])] = cov_ls[(i, j)];
            }
        }
        let restarted = match &mut self.core {
            Core::Pf(pf) => pf.init_gaussian(&x, &p, &mut self.rng).is_ok(),
            kalman => kalman.restart(x, p),
        };
        if restarted {
            self.set_rb_clock_priors();
        }
    }

    /// Initialises the clock of every system that has ranges this epoch and no clock yet
    /// (estimated clocks only).
    fn initialise_clocks(&mut self) {
        if self.clocks == ClockMode::Known {
            return;
        }
        for s in 0..N_CLOCKS {
            if self.clock_ready[s] {
                continue;
            }
            let sys = System::ALL[s];
            let n = self.rows.iter().filter(|(r, _)| r.system == sys).count();
            if n == 0 {
                continue;
            }
            self.clock_ready[s] = true;
            let k = NM + s;
            let mean_residual = |pos: &Vector3<f64>| {
                let mut sum = 0.0;
                let mut var = 0.0;
                for (r, z) in self.rows.iter().filter(|(r, _)| r.system == sys) {
                    sum += z - (r.emitter_pos_m - pos).norm();
                    var += r.sigma_m * r.sigma_m;
                }
                (sum / n as f64, var / (n * n) as f64)
            };
            match &mut self.core {
                // The Kalman filter of each particle takes the clock from a flat prior.
                Core::Pf(pf) if pf.clocks_in_closed_form() => {}
                Core::Pf(pf) => {
                    use rand::Rng;
                    let len = pf.particles().len();
                    for i in 0..len {
                        let b = pf.particles();
                        let pos = Vector3::from_fn(|a, _| match self.layout.pos[a] {
                            Some(c) => b.column(c)[i],
                            None => self.plane_up_m.unwrap_or(0.0),
                        });
                        let (mean, var) = mean_residual(&pos);
                        let w: f64 = self.rng.sample(rand_distr::StandardNormal);
                        pf.particles_mut().column_mut(k)[i] = mean + var.sqrt() * w;
                    }
                }
                kalman => {
                    let (mut x, mut p) = kalman.moments();
                    let (b, var) = mean_residual(&position_of(&self.layout, self.plane_up_m, &x));
                    x[k] = b;
                    for i in 0..N {
                        p[(i, k)] = 0.0;
                        p[(k, i)] = 0.0;
                    }
                    p[(k, k)] = var;
                    // An unusable (non-finite) result leaves the filter as it was.
                    kalman.restart(x, p);
                }
            }
        }
    }
}

/// The normalised innovation squared of an epoch's ranges against the predicted moments
/// `(x, P)` of a particle cloud, and its degrees of freedom: the ranges are taken one at
/// a time through the EKF's update, each linearised at the state the previous one left,
/// so that `Σ ν_j² / S_j` is the NIS of the whole epoch (the chain rule of a Gaussian
/// density). `None` when a range is degenerate (receiver at the emitter) or a variance is
/// unusable.
fn linearised_nis<const N: usize>(
    layout: &StateLayout,
    plane_up_m: Option<f64>,
    x: &SVector<f64, N>,
    cov: &SMatrix<f64, N, N>,
    rows: &[(RangeRow, f64)],
) -> Option<(f64, u32)> {
    let (mut x, mut p) = (*x, *cov);
    let (mut nis, mut dof) = (0.0, 0);
    for (row, z) in rows {
        let d = position_of(layout, plane_up_m, &x) - row.emitter_pos_m;
        let r = d.norm();
        if !(r > 0.0 && r.is_finite()) {
            return None;
        }
        let mut h = SVector::<f64, N>::zeros();
        for (a, k) in layout.pos.iter().enumerate() {
            if let Some(k) = *k {
                h[k] = d[a] / r;
            }
        }
        let mut predicted = r;
        let s = row.system.index();
        for k in [layout.clock[s], layout.isb[s]].into_iter().flatten() {
            h[k] += 1.0;
            predicted += x[k];
        }
        let ph = p * h;
        let var = h.dot(&ph) + row.sigma_m * row.sigma_m;
        if !(var > 0.0 && var.is_finite()) {
            return None;
        }
        let nu = z - predicted;
        nis += nu * nu / var;
        dof += 1;
        let gain = ph / var;
        x += gain * nu;
        p -= gain * ph.transpose();
    }
    Some((nis, dof))
}

/// The smallest variance (m²) a reported position covariance has along any axis.
///
/// A particle cloud that resampling has collapsed onto one or two particles has a weighted
/// covariance that is zero along some direction, or slightly indefinite after rounding, and
/// its inverse (the NEES) would be meaningless or negative. Flooring the eigenvalues at
/// (1 mm)² keeps the NEES defined and positive; it stays huge for a collapsed cloud that
/// is far from the truth, which is what the NEES should say about it.
pub const COV_FLOOR_M2: f64 = 1e-6;

/// `m` symmetrised, with its eigenvalues raised to at least `floor`.
fn floor_psd(m: &Matrix3<f64>, floor: f64) -> Matrix3<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = nalgebra::SymmetricEigen::new(sym);
    if eig.eigenvalues.iter().all(|l| *l >= floor) {
        return sym;
    }
    let d = Matrix3::from_diagonal(&eig.eigenvalues.map(|l| l.max(floor)));
    eig.eigenvectors * d * eig.eigenvectors.transpose()
}

fn position_of<const N: usize>(
    layout: &StateLayout,
    plane_up_m: Option<f64>,
    x: &SVector<f64, N>,
) -> Vector3<f64> {
    Vector3::from_fn(|a, _| match layout.pos[a] {
        Some(k) => x[k],
        None => plane_up_m.unwrap_or(0.0),
    })
}

impl<P, const NM: usize, const N: usize> Estimator for PaperEstimator<P, NM, N>
where
    P: ProcessModel<NM> + Copy + Send,
{
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        self.front.consumes(source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        let rx = self.estimate(self.last_t).map(|e| e.pos_ecef_m);
        self.front.admit(batch, rx.as_ref(), &mut out);
        let dt = batch.t.seconds_since(self.last_t).max(0.0);
        self.last_t = batch.t;
        let predicted = match &mut self.core {
            Core::Ekf(f) => f.predict(&self.model, dt).is_ok(),
            Core::Sigma(f) => f.predict(&self.model, dt).is_ok(),
            Core::Stf(f, fading) => fading.predict(f, &self.model, dt).is_ok(),
            Core::Rekf(f) => f.predict(&self.model, dt).is_ok(),
            Core::Pf(p) if self.linearised && p.variant() != PfVariant::Gaussian => {
                p.propagate(&self.model, dt).is_ok()
            }
            Core::Pf(p) => p.predict(&self.model, dt, &mut self.rng).is_ok(),
        };
        if !predicted {
            Estimator::reset(self);
            out.numerical_failure = true;
            return out;
        }
        self.load_rows();
        if std::mem::take(&mut self.recover) {
            self.restart_from_least_squares();
        }
        let ready_before = self.clock_ready;
        self.initialise_clocks();
        if let Core::Stf(f, fading) = &mut self.core {
            // The fading factor of this epoch, from all its pseudoranges at the prediction.
            let layout = self.layout;
            let rows = self.rows.iter().filter_map(|(row, z)| {
                Pseudoranges::<N, 1>::new(layout, [*row])
                    .ok()
                    .map(|pr| (pr, *z))
            });
            if fading.inflate(f, rows).is_err() {
                Estimator::reset(self);
                out.numerical_failure = true;
                return out;
            }
        }
        match &mut self.core {
            Core::Pf(p) => {
                if !self.rows.is_empty() {
                    // The innovations of the predicted cloud's moments, for the engine's
                    // divergence watch and the records (only once every clock the ranges
                    // refer to has a prior).
                    let known = self
                        .rows
                        .iter()
                        .all(|(r, _)| ready_before[r.system.index()]);
                    if known {
                        let (x, mut cov) = (p.mean(), p.covariance());
                        if self.linearised && p.variant() != PfVariant::Gaussian {
                            // The cloud has moved by f only; the prediction adds Q.
                            cov += self.model.q(&x, dt);
                        }
                        if let Some((nis, dof)) =
                            linearised_nis(&self.layout, self.plane_up_m, &x, &cov, &self.rows)
                        {
                            out.record_nis(nis, dof);
                        }
                    }
                    self.lik.clear(self.layout.pos);
                    for (row, z) in &self.rows {
                        self.lik.push(&self.layout, row, *z);
                    }
                    let up = if self.linearised {
                        let q = self.model.q(&p.mean(), dt);
                        match p.update_linearised(&q, &self.lik, &mut self.rng) {
                            Ok(up) => up,
                            Err(_) => {
                                Estimator::reset(self);
                                out.numerical_failure = true;
                                return out;
                            }
                        }
                    } else {
                        p.update_ranges(&self.lik, &mut self.rng)
                    };
                    let n = p.particles().len() as f64;
                    if up.degenerate {
                        // Every weight underflowed: the cloud has lost the measurements.
                        out.rejected += self.rows.len() as u32;
                        Estimator::reset(self);
                        out.numerical_failure = true;
                        return out;
                    }
                    out.used += self.rows.len() as u32;
                    if up.n_eff < COLLAPSE_FRACTION * n {
                        self.collapse_run += 1;
                    } else {
                        self.collapse_run = 0;
                    }
                    if self.collapse_run >= COLLAPSE_EPOCHS {
                        Estimator::reset(self);
                        out.numerical_failure = true;
                        return out;
                    }
                }
            }
            kalman => {
                for (row, z) in &self.rows {
                    let Ok(pr) = Pseudoranges::<N, 1>::new(self.layout, [*row]) else {
                        out.rejected += 1;
                        continue;
                    };
                    let Some(rep) = kalman.update(&pr, &SVector::<f64, 1>::new(*z)) else {
                        continue;
                    };
                    out.used += rep.used;
                    out.rejected += rep.rejected;
                    match rep.outcome {
                        crate::fusion::ekf11::UpdateOutcome::Accepted { nis } => {
                            out.record_nis(nis, 1);
                        }
                        crate::fusion::ekf11::UpdateOutcome::Rejected {
                            reason: crate::fusion::ekf11::RejectReason::Gate { .. },
                            ..
                        } => {
                            out.rejected_gate += rep.rejected;
                            out.rejected_gate_state_led += rep.rejected_state_led;
                        }
                        _ => {}
                    }
                }
            }
        }
        let (x, p) = self.moments();
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            Estimator::reset(self);
            out.numerical_failure = true;
            return out;
        }
        out.estimate = self.estimate(batch.t);
        if let Some(e) = &out.estimate {
            out.gdop = crate::fusion::estimator::gdop_of(
                &e.pos_ecef_m,
                &self.front.ranges,
                &mut self.geometry,
            );
        }
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.estimate(self.last_t)
    }

    /// Restarts the filter from its initial covariance around its last finite state (the
    /// initial state when that is not finite): the paper models have no least-squares
    /// start, so the prior's spread is what lets the measurements pull the filter back.
    fn reset(&mut self) {
        let (x, _) = self.moments();
        let mut centre = if x.iter().all(|v| v.is_finite()) {
            x
        } else {
            self.x0
        };
        // Clocks go back to their prior: a diverged clock estimate is as suspect as the
        // position it was fitted with.
        for s in 0..N_CLOCKS {
            centre[N - N_CLOCKS + s] = self.x0[N - N_CLOCKS + s];
        }
        if matches!(self.clocks, ClockMode::Estimated) {
            self.clock_ready = [false; N_CLOCKS];
        }
        let restarted = match &mut self.core {
            Core::Pf(p) => p.init_gaussian(&centre, &self.p0, &mut self.rng).is_ok(),
            kalman => kalman.restart(centre, self.p0),
        };
        debug_assert!(restarted, "the prior was valid at build time");
        self.set_rb_clock_priors();
        self.collapse_run = 0;
        self.recover = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 2-D model's NEES counts x only when the prior lets x err; the 3-D models count
    /// three axes.
    #[test]
    fn the_position_dof_counts_the_axes_that_can_err() {
        let spec = |s: &str| toml::from_str::<ProcessSpec>(s).unwrap();
        assert_eq!(spec("model = \"singer_2d\"").position_dof(), 1);
        let zero_x = "model = \"singer_2d\"\ninitial_sigma = [0.0, 0.0, 1.0, 1.0, 1.0]";
        assert_eq!(spec(zero_x).position_dof(), 1);
        let with_x = "model = \"singer_2d\"\ninitial_sigma = [0.0, 0.5, 1.0, 1.0, 1.0]";
        assert_eq!(spec(with_x).position_dof(), 2);
        assert_eq!(spec("model = \"plane_turning\"").position_dof(), 3);
        assert_eq!(
            spec("model = \"singer_2d\"").position_dof_after_restart(),
            2
        );
        assert_eq!(
            spec("model = \"plane_turning\"").position_dof_after_restart(),
            3
        );
    }

    /// The clock-augmented model leaves the motion block to the motion model and adds a
    /// random walk to each clock.
    #[test]
    fn clocks_are_appended_as_random_walks() {
        let m = WithClocks {
            motion: Singer5::new(0.1, 3.5).unwrap(),
            clock_q: [2.0; N_CLOCKS],
        };
        let x = SVector::<f64, 9>::from_fn(|i, _| i as f64);
        let f = ProcessModel::<9>::jacobian(&m, &x, 1.0);
        let inner = Singer5::new(0.1, 3.5)
            .unwrap()
            .jacobian(&SVector::<f64, 5>::zeros(), 1.0);
        assert_eq!(f.fixed_view::<5, 5>(0, 0).into_owned(), inner);
        assert_eq!(f[(7, 7)], 1.0);
        let q = ProcessModel::<9>::q(&m, &x, 0.5);
        assert_eq!(q[(8, 8)], 1.0);
        assert_eq!(q[(0, 0)], 0.0);
        let y = ProcessModel::<9>::f(&m, &x, 1.0);
        assert_eq!(y[0], 0.0 + 1.0);
        assert_eq!(y[6], 6.0);
    }
}
