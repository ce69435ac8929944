//! Process and measurement models, kept apart from the filters that use them.
//!
//! The split follows Stone Soup (Last et al., "Stone Soup: announcement of beta release of
//! an open-source framework for tracking and state estimation", *Proc. SPIE* 11018, 2019):
//! a model says how the state moves ([`ProcessModel`]) or what a sensor sees
//! ([`MeasurementModel`]); an algorithm ([`crate::fusion::kalman`],
//! [`crate::fusion::particle`]) says how to combine them. Every filter works with every
//! model of the right dimensions, so comparing an EKF with a UKF or a particle filter on
//! one scenario changes one type, not the scenario.
//!
//! All models are on const-generic static nalgebra types (`SVector<f64, N>`,
//! `SMatrix<f64, M, N>`) with `N` the state dimension and `M` the measurement dimension,
//! so evaluating a model never touches the heap and the filters' hot loops stay
//! allocation-free.
//!
//! # Process models
//!
//! | model | state | source |
//! |---|---|---|
//! | [`ConstantVelocity`] | `[p₀, v₀, p₁, v₁, …]` | white-acceleration (Bar-Shalom et al. §6.3.2) |
//! | [`ConstantAcceleration`] | `[p₀, v₀, a₀, …]` | white-jerk (Bar-Shalom et al. §6.3.3; seed 000 eq. 7) |
//! | [`Pva11Clock`] | seed 000's 12 states | [`crate::fusion::ekf11`] eqs. 5–8 |
//! | [`Singer5`] | `[x, ẋ, y, ẏ, ÿ]` | seed 001 (Singer in y, uniform motion in x) |
//! | [`PlaneTurning`] | `[p, v, a]` (9) | seed 003, [`crate::motion::turning`] |
//! | [`Pdr`] | `[x, y, θ̇, θ, v]` | seed 002, nonlinear |
//!
//! # Measurement models
//!
//! | model | measurement | source |
//! |---|---|---|
//! | [`Pseudoranges`] | `ρ_j = ‖r_j − r‖ + b_sys(j) (+ isb_sys(j))` | seeds 000, 001, 003 |
//! | [`PseudorangesAndRates`] | the ranges, then `ρ̇_j = u_j·(v_j − v) + ḃ` | seed 000 eqs. 9–17 |
//! | [`PositionFixModel`] | `L = r + ε` | seed 000 eqs. 18–19, seed 002 |
//! | [`HeadingModel`] | `θ` (wrapped residual) | seed 002 |
//! | [`SpeedModel`] | `v` or `‖v‖` | seed 002 |

use crate::core::System;
use crate::fusion::ekf11::{Ekf11, Ekf11Config, N_STATES as N_EKF11};
use crate::measurement::RangeMeasurement;
use crate::motion::singer::{singer_process_noise, singer_transition};
use crate::motion::turning;
use nalgebra::{SMatrix, SVector, Vector3};

/// Errors of model construction: the models refuse unusable parameters up front so that
/// a filter never meets a NaN produced by a model.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A parameter is negative, zero where it must be positive, or not finite.
    #[error("invalid model parameter {name} = {value}: {expected}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        expected: &'static str,
    },
    /// A state index or a dimension does not fit the state or measurement dimension.
    #[error("invalid model dimension: {0}")]
    Dimension(String),
}

fn check(name: &'static str, value: f64, positive: bool) -> Result<(), ModelError> {
    let ok = value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 };
    if ok {
        Ok(())
    } else {
        Err(ModelError::InvalidParameter {
            name,
            value,
            expected: if positive {
                "expected a finite value > 0"
            } else {
                "expected a finite value ≥ 0"
            },
        })
    }
}

fn check_index(what: &str, idx: usize, n: usize) -> Result<(), ModelError> {
    if idx < n {
        Ok(())
    } else {
        Err(ModelError::Dimension(format!(
            "{what} index {idx} is outside a state of dimension {n}"
        )))
    }
}

/// How the state evolves over an interval: `x_{k+1} = f(x_k, Δt) + w`, `w ~ N(0, Q)`.
pub trait ProcessModel<const N: usize> {
    /// The noise-free state after `dt_s` seconds.
    fn f(&self, x: &SVector<f64, N>, dt_s: f64) -> SVector<f64, N>;
    /// `∂f/∂x` at `x` (the transition matrix for a linear model).
    fn jacobian(&self, x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N>;
    /// The covariance of the process noise accumulated over `dt_s` seconds.
    fn q(&self, x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N>;
}

/// What a sensor sees: `z = h(x) + v`, `v ~ N(0, R)`.
pub trait MeasurementModel<const N: usize, const M: usize> {
    /// The noise-free measurement of state `x`.
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, M>;
    /// `∂h/∂x` at `x`.
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N>;
    /// The measurement-noise covariance.
    fn r(&self) -> SMatrix<f64, M, M>;
    /// The difference `z − ẑ`; models of angles override it to wrap into (−π, π].
    fn residual(&self, z: &SVector<f64, M>, z_hat: &SVector<f64, M>) -> SVector<f64, M> {
        z - z_hat
    }
    /// `log p(z | x)` up to the constant `−½ log|2πR|`, which is the same for every state
    /// and so cancels in particle weights: `−½ νᵀ R⁻¹ ν` with `ν = z − h(x)`. Returns
    /// `−∞` when `R` is not positive definite or a number is not finite, so that a
    /// particle with an unusable likelihood gets weight zero rather than NaN.
    fn log_likelihood(&self, x: &SVector<f64, N>, z: &SVector<f64, M>) -> f64 {
        let nu = self.residual(z, &self.h(x));
        let Some(chol) = self.r().cholesky() else {
            return f64::NEG_INFINITY;
        };
        let w = chol.l().solve_lower_triangular(&nu);
        match w {
            Some(w) if w.iter().all(|v| v.is_finite()) => -0.5 * w.norm_squared(),
            _ => f64::NEG_INFINITY,
        }
    }
}

/// Constant velocity on `N / 2` axes, state `[p₀, v₀, p₁, v₁, …]` (m, m/s), driven by
/// continuous white acceleration of PSD `q` (m²/s³) per axis (Bar-Shalom, Li &
/// Kirubarajan, *Estimation with Applications to Tracking and Navigation*, §6.2.2):
///
/// ```text
/// F = [[1, T], [0, 1]],   Q = q [[T³/3, T²/2], [T²/2, T]]   (per axis)
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantVelocity<const N: usize> {
    accel_psd_m2ps3: f64,
}

impl<const N: usize> ConstantVelocity<N> {
    /// A model with acceleration PSD `accel_psd_m2ps3` on every axis.
    ///
    /// # Errors
    /// When `N` is not even or the PSD is negative or not finite.
    pub fn new(accel_psd_m2ps3: f64) -> Result<Self, ModelError> {
        if N == 0 || N % 2 != 0 {
            return Err(ModelError::Dimension(format!(
                "a constant-velocity state has 2 entries per axis; N = {N}"
            )));
        }
        check("accel_psd_m2ps3", accel_psd_m2ps3, false)?;
        Ok(Self { accel_psd_m2ps3 })
    }
}

impl<const N: usize> ProcessModel<N> for ConstantVelocity<N> {
    fn f(&self, x: &SVector<f64, N>, dt_s: f64) -> SVector<f64, N> {
        let mut y = *x;
        for a in 0..N / 2 {
            y[2 * a] += dt_s * x[2 * a + 1];
        }
        y
    }
    fn jacobian(&self, _x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let mut f = SMatrix::<f64, N, N>::identity();
        for a in 0..N / 2 {
            f[(2 * a, 2 * a + 1)] = dt_s;
        }
        f
    }
    fn q(&self, _x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let (t, q) = (dt_s, self.accel_psd_m2ps3);
        let mut m = SMatrix::<f64, N, N>::zeros();
        for a in 0..N / 2 {
            let (i, j) = (2 * a, 2 * a + 1);
            m[(i, i)] = q * t * t * t / 3.0;
            m[(i, j)] = q * t * t / 2.0;
            m[(j, i)] = q * t * t / 2.0;
            m[(j, j)] = q * t;
        }
        m
    }
}

/// Constant acceleration on `N / 3` axes, state `[p₀, v₀, a₀, p₁, …]`, driven by white
/// jerk of PSD `S_a` (m²/s⁵) per axis; this is seed 000's eq. 7 block:
///
/// ```text
/// F = [[1, T, T²/2], [0, 1, T], [0, 0, 1]]
/// Q = S_a [[T⁵/20, T⁴/8, T³/6], [T⁴/8, T³/3, T²/2], [T³/6, T²/2, T]]
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantAcceleration<const N: usize> {
    jerk_psd_m2ps5: f64,
}

impl<const N: usize> ConstantAcceleration<N> {
    /// A model with jerk PSD `jerk_psd_m2ps5` on every axis.
    ///
    /// # Errors
    /// When `N` is not a multiple of 3 or the PSD is negative or not finite.
    pub fn new(jerk_psd_m2ps5: f64) -> Result<Self, ModelError> {
        if N == 0 || N % 3 != 0 {
            return Err(ModelError::Dimension(format!(
                "a constant-acceleration state has 3 entries per axis; N = {N}"
            )));
        }
        check("jerk_psd_m2ps5", jerk_psd_m2ps5, false)?;
        Ok(Self { jerk_psd_m2ps5 })
    }
}

impl<const N: usize> ProcessModel<N> for ConstantAcceleration<N> {
    fn f(&self, x: &SVector<f64, N>, dt_s: f64) -> SVector<f64, N> {
        self.jacobian(x, dt_s) * x
    }
    fn jacobian(&self, _x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let mut f = SMatrix::<f64, N, N>::identity();
        for a in 0..N / 3 {
            let i = 3 * a;
            f[(i, i + 1)] = dt_s;
            f[(i, i + 2)] = 0.5 * dt_s * dt_s;
            f[(i + 1, i + 2)] = dt_s;
        }
        f
    }
    fn q(&self, _x: &SVector<f64, N>, dt_s: f64) -> SMatrix<f64, N, N> {
        let t = dt_s;
        let s = self.jerk_psd_m2ps5;
        let block = [
            [t.powi(5) / 20.0, t.powi(4) / 8.0, t.powi(3) / 6.0],
            [t.powi(4) / 8.0, t.powi(3) / 3.0, t * t / 2.0],
            [t.powi(3) / 6.0, t * t / 2.0, t],
        ];
        let mut m = SMatrix::<f64, N, N>::zeros();
        for a in 0..N / 3 {
            for (r, row) in block.iter().enumerate() {
                for (c, v) in row.iter().enumerate() {
                    m[(3 * a + r, 3 * a + c)] = s * v;
                }
            }
        }
        m
    }
}

/// Seed 000's position–velocity–acceleration + clock model (12 states, the twelfth the
/// BeiDou inter-system bias, inert unless configured): it delegates to
/// [`Ekf11::transition`] and [`Ekf11::process_noise`], so the generic filters and the
/// hand-optimised [`Ekf11`] run exactly the same model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pva11Clock {
    cfg: Ekf11Config,
}

impl Pva11Clock {
    /// The model with seed 000's tuning `cfg`.
    ///
    /// # Errors
    /// When the configuration holds an unusable number.
    pub fn new(cfg: Ekf11Config) -> Result<Self, ModelError> {
        cfg.validate()
            .map_err(|e| ModelError::Dimension(e.to_string()))?;
        Ok(Self { cfg })
    }
}

impl ProcessModel<N_EKF11> for Pva11Clock {
    fn f(&self, x: &SVector<f64, N_EKF11>, dt_s: f64) -> SVector<f64, N_EKF11> {
        Ekf11::transition(dt_s) * x
    }
    fn jacobian(&self, _x: &SVector<f64, N_EKF11>, dt_s: f64) -> SMatrix<f64, N_EKF11, N_EKF11> {
        Ekf11::transition(dt_s)
    }
    fn q(&self, _x: &SVector<f64, N_EKF11>, dt_s: f64) -> SMatrix<f64, N_EKF11, N_EKF11> {
        Ekf11::process_noise(&self.cfg, dt_s)
    }
}

/// Seed 001's model (§3): state `[x, ẋ, y, ẏ, ÿ]`, uniform motion without error in x and
/// the Singer manoeuvre model in y with manoeuvre time constant `1/α` and acceleration
/// variance `σ_a²` (Singer, *IEEE Trans. AES* 6(4), 1970). The y block reuses
/// [`crate::motion::singer`], which is accurate for every `αT`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Singer5 {
    alpha_per_s: f64,
    accel_var_m2ps4: f64,
}

impl Singer5 {
    /// A model with `α` (1/s) and `σ_a²` ((m/s²)²).
    ///
    /// # Errors
    /// When `α` is not positive or `σ_a²` is negative (either not finite).
    pub fn new(alpha_per_s: f64, accel_var_m2ps4: f64) -> Result<Self, ModelError> {
        check("alpha_per_s", alpha_per_s, true)?;
        check("accel_var_m2ps4", accel_var_m2ps4, false)?;
        Ok(Self {
            alpha_per_s,
            accel_var_m2ps4,
        })
    }
}

impl ProcessModel<5> for Singer5 {
    fn f(&self, x: &SVector<f64, 5>, dt_s: f64) -> SVector<f64, 5> {
        self.jacobian(x, dt_s) * x
    }
    fn jacobian(&self, _x: &SVector<f64, 5>, dt_s: f64) -> SMatrix<f64, 5, 5> {
        let mut f = SMatrix::<f64, 5, 5>::identity();
        f[(0, 1)] = dt_s;
        f.fixed_view_mut::<3, 3>(2, 2)
            .copy_from(&singer_transition(self.alpha_per_s, dt_s));
        f
    }
    fn q(&self, _x: &SVector<f64, 5>, dt_s: f64) -> SMatrix<f64, 5, 5> {
        let mut q = SMatrix::<f64, 5, 5>::zeros();
        if dt_s > 0.0 {
            q.fixed_view_mut::<3, 3>(2, 2)
                .copy_from(&singer_process_noise(
                    self.alpha_per_s,
                    self.accel_var_m2ps4,
                    dt_s,
                ));
        }
        q
    }
}

/// Seed 003's plane variable-speed turning model, state `[p, v, a]` (x, y, z each), with
/// the exact transition `Φ(T) = exp(A T)` of [`crate::motion::turning::transition_matrix`]
/// and the paper's discrete acceleration noise `Q = Γ σ_w² I₃ Γᵀ`, `Γ = [0 0 I₃]ᵀ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneTurning {
    attenuation_per_s: f64,
    turn_rate_rad_per_s: f64,
    noise_var_m2ps4: f64,
}

impl PlaneTurning {
    /// A model with attenuation α (1/s), turn rate ω (rad/s) and noise variance σ_w².
    ///
    /// # Errors
    /// When α or σ_w² is negative or any value is not finite.
    pub fn new(
        attenuation_per_s: f64,
        turn_rate_rad_per_s: f64,
        noise_var_m2ps4: f64,
    ) -> Result<Self, ModelError> {
        check("attenuation_per_s", attenuation_per_s, false)?;
        if !turn_rate_rad_per_s.is_finite() {
            return Err(ModelError::InvalidParameter {
                name: "turn_rate_rad_per_s",
                value: turn_rate_rad_per_s,
                expected: "expected a finite value",
            });
        }
        check("noise_var_m2ps4", noise_var_m2ps4, false)?;
        Ok(Self {
            attenuation_per_s,
            turn_rate_rad_per_s,
            noise_var_m2ps4,
        })
    }
}

impl ProcessModel<9> for PlaneTurning {
    fn f(&self, x: &SVector<f64, 9>, dt_s: f64) -> SVector<f64, 9> {
        self.jacobian(x, dt_s) * x
    }
    fn jacobian(&self, _x: &SVector<f64, 9>, dt_s: f64) -> SMatrix<f64, 9, 9> {
        turning::transition_matrix(self.attenuation_per_s, self.turn_rate_rad_per_s, dt_s)
    }
    fn q(&self, _x: &SVector<f64, 9>, dt_s: f64) -> SMatrix<f64, 9, 9> {
        let mut q = SMatrix::<f64, 9, 9>::zeros();
        if dt_s > 0.0 {
            for i in 6..9 {
                q[(i, i)] = self.noise_var_m2ps4;
            }
        }
        q
    }
}

/// Seed 002's pedestrian dead-reckoning model (§5, the fusion state), state
/// `[x, y, θ̇, θ, v]` (east m, north m, heading rate rad/s, heading rad, speed m/s):
///
/// ```text
/// x_t = x + v Δt cos θ     y_t = y + v Δt sin θ     θ̇_t = θ̇     θ_t = θ + Δt θ̇     v_t = v
/// F = ∂f/∂x = [[1, 0, 0, −vΔt sin θ, Δt cos θ], [0, 1, 0, vΔt cos θ, Δt sin θ],
///              [0, 0, 1, 0, 0], [0, 0, Δt, 1, 0], [0, 0, 0, 0, 1]]
/// ```
/// The paper's printed F omits the heading column (`−vΔt sin θ`, `vΔt cos θ`); it is the
/// exact derivative and is kept. The noises `w₁…w₅` are independent with variances
/// growing linearly in Δt: `Q = diag(q) Δt`, so that a step of 2 s is the same as two of
/// 1 s to first order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pdr {
    q_diag_per_s: [f64; 5],
}

impl Pdr {
    /// A model with noise rates `q_diag_per_s` (units of each state squared per second).
    ///
    /// # Errors
    /// When a rate is negative or not finite.
    pub fn new(q_diag_per_s: [f64; 5]) -> Result<Self, ModelError> {
        for q in q_diag_per_s {
            check("q_diag_per_s", q, false)?;
        }
        Ok(Self { q_diag_per_s })
    }
}

impl ProcessModel<5> for Pdr {
    fn f(&self, x: &SVector<f64, 5>, dt_s: f64) -> SVector<f64, 5> {
        let (s, c) = x[3].sin_cos();
        SVector::<f64, 5>::new(
            x[0] + x[4] * dt_s * c,
            x[1] + x[4] * dt_s * s,
            x[2],
            x[3] + dt_s * x[2],
            x[4],
        )
    }
    fn jacobian(&self, x: &SVector<f64, 5>, dt_s: f64) -> SMatrix<f64, 5, 5> {
        let (s, c) = x[3].sin_cos();
        let mut f = SMatrix::<f64, 5, 5>::identity();
        f[(0, 3)] = -x[4] * dt_s * s;
        f[(0, 4)] = dt_s * c;
        f[(1, 3)] = x[4] * dt_s * c;
        f[(1, 4)] = dt_s * s;
        f[(3, 2)] = dt_s;
        f
    }
    fn q(&self, _x: &SVector<f64, 5>, dt_s: f64) -> SMatrix<f64, 5, 5> {
        SMatrix::<f64, 5, 5>::from_diagonal(&SVector::<f64, 5>::from(self.q_diag_per_s))
            * dt_s.max(0.0)
    }
}

/// Where a pseudorange model finds the receiver position and the clock states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateLayout {
    /// Indices of the ECEF (or local) x, y, z position; `None` for a coordinate that is
    /// not estimated and taken as 0 (a 2-D problem).
    pub pos: [Option<usize>; 3],
    /// Indices of the velocity components, used by range rates.
    pub vel: [Option<usize>; 3],
    /// Clock-bias state (m) of each system, indexed like [`System::ALL`]; `None` when
    /// that system's ranges have no clock term (a true range).
    pub clock: [Option<usize>; System::COUNT],
    /// Inter-system-bias state (m) added to a system's ranges on top of its clock.
    pub isb: [Option<usize>; System::COUNT],
    /// Clock-drift state (m/s) used by range rates.
    pub drift: Option<usize>,
}

impl StateLayout {
    /// Seed 000's 12-state layout: one clock for every system, the BeiDou ranges adding
    /// the inter-system bias.
    pub fn ekf11() -> Self {
        use crate::fusion::ekf11::idx;
        let c = Some(idx::CLOCK_BIAS);
        Self {
            pos: idx::POS.map(Some),
            vel: idx::VEL.map(Some),
            clock: [c; System::COUNT],
            isb: [None, Some(idx::ISB_BDS), None, None],
            drift: Some(idx::CLOCK_DRIFT),
        }
    }

    fn check<const N: usize>(&self) -> Result<(), ModelError> {
        for i in self
            .pos
            .iter()
            .chain(&self.vel)
            .chain(&self.clock)
            .chain(&self.isb)
            .flatten()
        {
            check_index("layout", *i, N)?;
        }
        if let Some(d) = self.drift {
            check_index("drift", d, N)?;
        }
        Ok(())
    }
}

/// One emitter row of a range model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeRow {
    pub emitter_pos_m: Vector3<f64>,
    pub emitter_vel_mps: Vector3<f64>,
    pub system: System,
    pub sigma_m: f64,
    pub sigma_rate_mps: f64,
}

impl From<&RangeMeasurement> for RangeRow {
    fn from(m: &RangeMeasurement) -> Self {
        Self {
            emitter_pos_m: m.emitter_pos_ecef_m,
            emitter_vel_mps: m.emitter_vel_ecef_mps,
            system: m.system(),
            sigma_m: m.sigma_m,
            sigma_rate_mps: m.sigma_rate_mps,
        }
    }
}

fn position<const N: usize>(layout: &StateLayout, x: &SVector<f64, N>) -> Vector3<f64> {
    Vector3::from_fn(|i, _| layout.pos[i].map_or(0.0, |k| x[k]))
}

fn velocity<const N: usize>(layout: &StateLayout, x: &SVector<f64, N>) -> Vector3<f64> {
    Vector3::from_fn(|i, _| layout.vel[i].map_or(0.0, |k| x[k]))
}

/// The bias (m) a system's range carries in state `x`: its clock plus its inter-system
/// bias.
fn bias<const N: usize>(layout: &StateLayout, sys: System, x: &SVector<f64, N>) -> f64 {
    let s = sys.index();
    layout.clock[s].map_or(0.0, |k| x[k]) + layout.isb[s].map_or(0.0, |k| x[k])
}

fn check_rows(rows: &[RangeRow], rates: bool) -> Result<(), ModelError> {
    for r in rows {
        check("sigma_m", r.sigma_m, true)?;
        if rates {
            check("sigma_rate_mps", r.sigma_rate_mps, true)?;
        }
        if !(r.emitter_pos_m.iter().chain(r.emitter_vel_mps.iter())).all(|v| v.is_finite()) {
            return Err(ModelError::InvalidParameter {
                name: "emitter position/velocity",
                value: f64::NAN,
                expected: "expected finite coordinates",
            });
        }
    }
    Ok(())
}

/// `M` pseudoranges with a clock state per system and inter-system biases (seeds 000,
/// 001, 003: GPS, BDS and DTMB clocks), independent noises:
///
/// ```text
/// ρ_j = ‖r_j − r‖ + b_sys(j) + isb_sys(j) + ε_j,   ε_j ~ N(0, σ_j²)
/// ∂ρ_j/∂r = −u_j = −(r_j − r)/‖r_j − r‖,   ∂ρ_j/∂b_sys(j) = ∂ρ_j/∂isb_sys(j) = 1
/// ```
/// A system whose clock index is `None` gives true ranges (a beacon with a
/// synchronised clock, or a 2-D range test problem).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pseudoranges<const N: usize, const M: usize> {
    layout: StateLayout,
    rows: [RangeRow; M],
}

impl<const N: usize, const M: usize> Pseudoranges<N, M> {
    /// A model of the `M` rows in `rows` on a state laid out as `layout`.
    ///
    /// # Errors
    /// When an index is outside the state or a σ is not positive and finite.
    pub fn new(layout: StateLayout, rows: [RangeRow; M]) -> Result<Self, ModelError> {
        layout.check::<N>()?;
        check_rows(&rows, false)?;
        Ok(Self { layout, rows })
    }

    /// The emitter rows.
    pub fn rows(&self) -> &[RangeRow; M] {
        &self.rows
    }

    /// The state layout.
    pub fn layout(&self) -> &StateLayout {
        &self.layout
    }
}

impl<const N: usize, const M: usize> MeasurementModel<N, M> for Pseudoranges<N, M> {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        let r = position(&self.layout, x);
        SVector::<f64, M>::from_fn(|j, _| {
            let row = &self.rows[j];
            (row.emitter_pos_m - r).norm() + bias(&self.layout, row.system, x)
        })
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        let r = position(&self.layout, x);
        let mut h = SMatrix::<f64, M, N>::zeros();
        for (j, row) in self.rows.iter().enumerate() {
            let d = row.emitter_pos_m - r;
            let u = d / d.norm();
            for (a, k) in self.layout.pos.iter().enumerate() {
                if let Some(k) = k {
                    h[(j, *k)] = -u[a];
                }
            }
            let s = row.system.index();
            if let Some(k) = self.layout.clock[s] {
                h[(j, k)] += 1.0;
            }
            if let Some(k) = self.layout.isb[s] {
                h[(j, k)] += 1.0;
            }
        }
        h
    }
    fn r(&self) -> SMatrix<f64, M, M> {
        SMatrix::<f64, M, M>::from_fn(|i, j| {
            if i == j {
                self.rows[i].sigma_m * self.rows[i].sigma_m
            } else {
                0.0
            }
        })
    }
    fn log_likelihood(&self, x: &SVector<f64, N>, z: &SVector<f64, M>) -> f64 {
        // The noises are independent, so the quadratic form is a sum of scalar terms and
        // needs no factorisation.
        let zh = self.h(x);
        let mut s = 0.0;
        for j in 0..M {
            let d = (z[j] - zh[j]) / self.rows[j].sigma_m;
            s += d * d;
        }
        if s.is_finite() {
            -0.5 * s
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// `K = M / 2` pseudoranges followed by their `K` range rates (seed 000 eqs. 9–17):
///
/// ```text
/// z = [ρ_1 … ρ_K, ρ̇_1 … ρ̇_K]
/// ρ̇_j = u_j·(v_j − v) + ḃ,   ∂ρ̇_j/∂v = −u_j,   ∂ρ̇_j/∂ḃ = 1,
/// ∂ρ̇_j/∂r = −(w − u_j(u_j·w))/‖r_j − r‖,   w = v_j − v
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PseudorangesAndRates<const N: usize, const M: usize> {
    layout: StateLayout,
    rows: [RangeRow; M],
}

impl<const N: usize, const M: usize> PseudorangesAndRates<N, M> {
    /// A model of `M / 2` emitters: `rows[..M/2]` are used (the second half is ignored and
    /// may repeat the first), because `M / 2` cannot be a const-generic length on stable
    /// Rust.
    ///
    /// # Errors
    /// When `M` is odd, an index is outside the state or a σ is not positive and finite.
    pub fn new(layout: StateLayout, emitters: &[RangeRow]) -> Result<Self, ModelError> {
        if M % 2 != 0 || emitters.len() != M / 2 {
            return Err(ModelError::Dimension(format!(
                "{} emitters for a measurement of dimension {M}: expected M / 2",
                emitters.len()
            )));
        }
        layout.check::<N>()?;
        check_rows(emitters, true)?;
        let mut rows = [emitters
            .first()
            .copied()
            .ok_or_else(|| ModelError::Dimension("at least one emitter is needed".into()))?;
            M];
        rows[..M / 2].copy_from_slice(emitters);
        Ok(Self { layout, rows })
    }
}

impl<const N: usize, const M: usize> MeasurementModel<N, M> for PseudorangesAndRates<N, M> {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        let k = M / 2;
        let r = position(&self.layout, x);
        let v = velocity(&self.layout, x);
        let drift = self.layout.drift.map_or(0.0, |i| x[i]);
        let mut z = SVector::<f64, M>::zeros();
        for (j, row) in self.rows[..k].iter().enumerate() {
            let d = row.emitter_pos_m - r;
            let n = d.norm();
            z[j] = n + bias(&self.layout, row.system, x);
            z[k + j] = (d / n).dot(&(row.emitter_vel_mps - v)) + drift;
        }
        z
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        let k = M / 2;
        let r = position(&self.layout, x);
        let v = velocity(&self.layout, x);
        let mut h = SMatrix::<f64, M, N>::zeros();
        for (j, row) in self.rows[..k].iter().enumerate() {
            let d = row.emitter_pos_m - r;
            let n = d.norm();
            let u = d / n;
            let w = row.emitter_vel_mps - v;
            let dr = -(w - u * u.dot(&w)) / n;
            for a in 0..3 {
                if let Some(i) = self.layout.pos[a] {
                    h[(j, i)] = -u[a];
                    h[(k + j, i)] = dr[a];
                }
                if let Some(i) = self.layout.vel[a] {
                    h[(k + j, i)] = -u[a];
                }
            }
            let s = row.system.index();
            if let Some(i) = self.layout.clock[s] {
                h[(j, i)] += 1.0;
            }
            if let Some(i) = self.layout.isb[s] {
                h[(j, i)] += 1.0;
            }
            if let Some(i) = self.layout.drift {
                h[(k + j, i)] += 1.0;
            }
        }
        h
    }
    fn r(&self) -> SMatrix<f64, M, M> {
        let k = M / 2;
        SMatrix::<f64, M, M>::from_fn(|i, j| match (i == j, i < k) {
            (true, true) => self.rows[i].sigma_m.powi(2),
            (true, false) => self.rows[i - k].sigma_rate_mps.powi(2),
            _ => 0.0,
        })
    }
}

/// A position fix `L = [x_{i₁}, …, x_{i_M}] + ε`, `ε ~ N(0, R_f)` (seed 000 eqs. 18–19;
/// seed 002's magnetic landmark with `M = 2`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionFixModel<const N: usize, const M: usize> {
    pos_idx: [usize; M],
    cov_m2: SMatrix<f64, M, M>,
}

impl<const N: usize, const M: usize> PositionFixModel<N, M> {
    /// A fix of the states `pos_idx` with covariance `cov_m2`.
    ///
    /// # Errors
    /// When an index is outside the state or `cov_m2` is not symmetric positive definite.
    pub fn new(pos_idx: [usize; M], cov_m2: SMatrix<f64, M, M>) -> Result<Self, ModelError> {
        for i in pos_idx {
            check_index("position", i, N)?;
        }
        let sym = (cov_m2 - cov_m2.transpose()).amax() <= 1e-12 * cov_m2.amax();
        if !(sym && cov_m2.iter().all(|v| v.is_finite()) && cov_m2.cholesky().is_some()) {
            return Err(ModelError::InvalidParameter {
                name: "cov_m2",
                value: f64::NAN,
                expected: "expected a symmetric positive-definite matrix",
            });
        }
        Ok(Self { pos_idx, cov_m2 })
    }
}

impl<const N: usize, const M: usize> MeasurementModel<N, M> for PositionFixModel<N, M> {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        SVector::<f64, M>::from_fn(|j, _| x[self.pos_idx[j]])
    }
    fn jacobian(&self, _x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        let mut h = SMatrix::<f64, M, N>::zeros();
        for (j, i) in self.pos_idx.iter().enumerate() {
            h[(j, *i)] = 1.0;
        }
        h
    }
    fn r(&self) -> SMatrix<f64, M, M> {
        self.cov_m2
    }
}

/// Wraps an angle into (−π, π].
pub fn wrap_angle_rad(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let w = a - two_pi * (a / two_pi).round();
    if w <= -std::f64::consts::PI {
        w + two_pi
    } else {
        w
    }
}

/// A heading measurement of the heading state (seed 002's `θ_pdr = θ + δ₄`), with the
/// residual wrapped into (−π, π] so that 359° against 1° is a 2° innovation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingModel<const N: usize> {
    theta_idx: usize,
    sigma_rad: f64,
}

impl<const N: usize> HeadingModel<N> {
    /// A heading of state `theta_idx` with noise σ `sigma_rad`.
    ///
    /// # Errors
    /// When the index is outside the state or σ is not positive and finite.
    pub fn new(theta_idx: usize, sigma_rad: f64) -> Result<Self, ModelError> {
        check_index("heading", theta_idx, N)?;
        check("sigma_rad", sigma_rad, true)?;
        Ok(Self {
            theta_idx,
            sigma_rad,
        })
    }
}

impl<const N: usize> MeasurementModel<N, 1> for HeadingModel<N> {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, 1> {
        SVector::<f64, 1>::new(x[self.theta_idx])
    }
    fn jacobian(&self, _x: &SVector<f64, N>) -> SMatrix<f64, 1, N> {
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, self.theta_idx)] = 1.0;
        h
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(self.sigma_rad * self.sigma_rad)
    }
    fn residual(&self, z: &SVector<f64, 1>, z_hat: &SVector<f64, 1>) -> SVector<f64, 1> {
        SVector::<f64, 1>::new(wrap_angle_rad(z[0] - z_hat[0]))
    }
}

/// A speed measurement: either a speed state (seed 002's `v_pdr = v + δ₅`) or the norm
/// of velocity states, `‖v‖`, with Jacobian `vᵀ/‖v‖` (zero at rest, where the norm has no
/// derivative and the measurement carries no direction information).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedModel<const N: usize> {
    idx: [Option<usize>; 3],
    direct: bool,
    sigma_mps: f64,
}

impl<const N: usize> SpeedModel<N> {
    /// The speed state `idx`.
    ///
    /// # Errors
    /// When the index is outside the state or σ is not positive and finite.
    pub fn of_state(idx: usize, sigma_mps: f64) -> Result<Self, ModelError> {
        check_index("speed", idx, N)?;
        check("sigma_mps", sigma_mps, true)?;
        Ok(Self {
            idx: [Some(idx), None, None],
            direct: true,
            sigma_mps,
        })
    }

    /// The norm of the velocity states `vel_idx` (1 to 3 of them).
    ///
    /// # Errors
    /// When there are not 1–3 indices, one is outside the state, or σ is unusable.
    pub fn of_velocity(vel_idx: &[usize], sigma_mps: f64) -> Result<Self, ModelError> {
        if vel_idx.is_empty() || vel_idx.len() > 3 {
            return Err(ModelError::Dimension(
                "a speed needs 1 to 3 velocity states".into(),
            ));
        }
        check("sigma_mps", sigma_mps, true)?;
        let mut idx = [None; 3];
        for (slot, &i) in idx.iter_mut().zip(vel_idx) {
            check_index("velocity", i, N)?;
            *slot = Some(i);
        }
        Ok(Self {
            idx,
            direct: false,
            sigma_mps,
        })
    }
}

impl<const N: usize> MeasurementModel<N, 1> for SpeedModel<N> {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, 1> {
        if self.direct {
            return SVector::<f64, 1>::new(self.idx[0].map_or(0.0, |i| x[i]));
        }
        let s2: f64 = self.idx.iter().flatten().map(|&i| x[i] * x[i]).sum();
        SVector::<f64, 1>::new(s2.sqrt())
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, 1, N> {
        let mut h = SMatrix::<f64, 1, N>::zeros();
        if self.direct {
            if let Some(i) = self.idx[0] {
                h[(0, i)] = 1.0;
            }
            return h;
        }
        let s = self.h(x)[0];
        if s > 0.0 {
            for &i in self.idx.iter().flatten() {
                h[(0, i)] = x[i] / s;
            }
        }
        h
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(self.sigma_mps * self.sigma_mps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::EmitterId;

    /// Central-difference Jacobian, the independent check of every analytic one.
    fn numeric_jacobian<const N: usize, const M: usize>(
        h: impl Fn(&SVector<f64, N>) -> SVector<f64, M>,
        x: &SVector<f64, N>,
    ) -> SMatrix<f64, M, N> {
        let mut j = SMatrix::<f64, M, N>::zeros();
        for k in 0..N {
            // Large enough that rounding of a 2e7 m range (4e-9 m) stays below 1e-6 of
            // the slope, small enough that curvature does not matter.
            let step = (1e-5 * x[k].abs()).max(1e-2);
            let (mut a, mut b) = (*x, *x);
            a[k] += step;
            b[k] -= step;
            j.set_column(k, &((h(&a) - h(&b)) / (2.0 * step)));
        }
        j
    }

    #[test]
    fn process_jacobians_match_finite_differences() {
        let pdr = Pdr::new([0.1; 5]).unwrap();
        let x = SVector::<f64, 5>::new(3.0, -2.0, 0.1, 0.7, 1.4);
        let num = numeric_jacobian(|x| pdr.f(x, 0.5), &x);
        // Central differences with a 1e-2 step are good to h²/6·|f‴| ≈ 2e-5 here.
        assert!((num - pdr.jacobian(&x, 0.5)).amax() < 5e-5);
        let cv = ConstantVelocity::<4>::new(0.3).unwrap();
        let x4 = SVector::<f64, 4>::new(1.0, 2.0, 3.0, 4.0);
        assert!((numeric_jacobian(|x| cv.f(x, 2.0), &x4) - cv.jacobian(&x4, 2.0)).amax() < 1e-8);
        let turn = PlaneTurning::new(0.03, 0.1, 0.01).unwrap();
        let x9 = SVector::<f64, 9>::from_fn(|i, _| i as f64 - 3.0);
        let p = turning::propagate(
            0.03,
            0.1,
            &Vector3::new(x9[0], x9[1], x9[2]),
            &Vector3::new(x9[3], x9[4], x9[5]),
            &Vector3::new(x9[6], x9[7], x9[8]),
            1.0,
        );
        let y = turn.f(&x9, 1.0);
        assert!((Vector3::new(y[0], y[1], y[2]) - p.0).amax() < 1e-12);
        assert!(ConstantVelocity::<3>::new(1.0).is_err());
        assert!(Singer5::new(-1.0, 1.0).is_err());
    }

    #[test]
    fn range_jacobians_match_finite_differences() {
        let layout = StateLayout::ekf11();
        let rows: Vec<RangeRow> = (0..4)
            .map(|i| RangeRow {
                emitter_pos_m: Vector3::new(2e7 + 1e6 * i as f64, -1e7 * i as f64, 1.5e7),
                emitter_vel_mps: Vector3::new(100.0, 3000.0 - 500.0 * i as f64, -200.0),
                system: if i % 2 == 0 { System::Gps } else { System::Bds },
                sigma_m: 3.0,
                sigma_rate_mps: 0.05,
            })
            .collect();
        let model = PseudorangesAndRates::<12, 8>::new(layout, &rows).unwrap();
        let x = SVector::<f64, 12>::from_fn(|i, _| {
            [4e6, 5.0, 0.1, 3e6, -2.0, 0.0, 4e6, 1.0, 0.0, 30.0, 2.0, 7.0][i]
        });
        let num = numeric_jacobian(|x| model.h(x), &x);
        let ana = model.jacobian(&x);
        assert!((num - ana).amax() < 1e-6, "{}", (num - ana).amax());
        // The BDS ranges see the inter-system bias, the GPS ones do not.
        assert_eq!(ana[(1, 11)], 1.0);
        assert_eq!(ana[(0, 11)], 0.0);
        let m = RangeMeasurement {
            emitter: EmitterId::new(System::Dtmb, 1),
            emitter_pos_ecef_m: Vector3::zeros(),
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m: 1.0,
            sigma_m: -1.0,
            range_rate_mps: None,
            sigma_rate_mps: 0.1,
            cn0_dbhz: 40.0,
            elevation_rad: 0.0,
        };
        assert!(Pseudoranges::<12, 1>::new(layout, [RangeRow::from(&m)]).is_err());
    }

    #[test]
    fn heading_residual_wraps_and_speed_is_safe_at_rest() {
        let h = HeadingModel::<5>::new(3, 0.1).unwrap();
        let nu = h.residual(
            &SVector::<f64, 1>::new(179f64.to_radians()),
            &SVector::<f64, 1>::new(-179f64.to_radians()),
        );
        assert!((nu[0] + 2f64.to_radians()).abs() < 1e-12);
        let s = SpeedModel::<4>::of_velocity(&[1, 3], 0.2).unwrap();
        let j = s.jacobian(&SVector::<f64, 4>::zeros());
        assert!(j.iter().all(|v| *v == 0.0));
        assert_eq!(s.h(&SVector::<f64, 4>::new(0.0, 3.0, 0.0, 4.0))[0], 5.0);
        assert!(PositionFixModel::<4, 2>::new([0, 2], -SMatrix::<f64, 2, 2>::identity()).is_err());
    }
}
