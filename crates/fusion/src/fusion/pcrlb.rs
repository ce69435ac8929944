//! The posterior Cramér–Rao lower bound (PCRLB) on the mean-square error of any estimator
//! of a state-space model, after Tichavský, Muravchik & Nehorai, "Posterior Cramér–Rao
//! bounds for discrete-time nonlinear filtering", *IEEE Trans. SP* 46(5), 1998.
//!
//! # The recursion
//!
//! For `x_{k+1} = F x_k + w_k`, `w_k ~ N(0, Q)`, and measurements `z_k = h_k(x_k) + v_k`,
//! `v_k ~ N(0, R_k)`, the information matrix of the bound obeys (their eq. 21 with the
//! additive-Gaussian terms of §IV)
//!
//! ```text
//! J_{k+1} = (Q + F J_k⁻¹ Fᵀ)⁻¹ + E[H_{k+1}ᵀ R⁻¹ H_{k+1}],   H = ∂h/∂x at the true state
//! ```
//!
//! the expectation taken over the true trajectories. The bound is then
//! `E[(x̂_k − x_k)(x̂_k − x_k)ᵀ] ⪰ J_k⁻¹`. The paper models have a singular `Q` (seed 001's
//! noise-free x axis, constant clocks) and known states with zero prior variance, so the
//! recursion is run here on the bound `B_k = J_k⁻¹` itself, which needs no inverse of `Q`
//! or of `B`:
//!
//! ```text
//! B⁻_{k+1} = F B_k Fᵀ + Q,          B_{k+1} = B⁻_{k+1} (I + Ī_{k+1} B⁻_{k+1})⁻¹
//! ```
//!
//! (`(B⁻⁻¹ + Ī)⁻¹ = B⁻ (I + Ī B⁻)⁻¹`, and `I + Ī B⁻` is invertible whenever both are
//! positive semi-definite), with `Ī_k` the measurement information averaged over the
//! trials' truth at epoch `k`. On a linear-Gaussian model `Ī` is the same for every
//! trajectory and this is the Kalman filter's own covariance recursion: the KF is
//! efficient there, and the test below holds the bound to it.
//!
//! # The paper models
//!
//! [`PaperBound`] builds `F`, `Q` and the prior of a paper estimator
//! ([`crate::fusion::paper`]: the motion model with one clock per system) and accumulates,
//! epoch by epoch and trial by trial, the pseudorange information
//! `Σ_j h_j h_jᵀ / σ_j²`, `h_j = [∂ρ_j/∂r at the truth, 1 on the clock of the range's
//! system]`. A clock the estimator estimates has a flat prior (it is initialised from the
//! first ranges), represented by [`FLAT_PRIOR_VAR_M2`]; a known clock has zero variance.
//!
//! # Seed 000's model
//!
//! [`PvaClockBound`] is the bound of seed 000's 12-state model
//! ([`crate::fusion::ekf11`], eqs. 4–8: ECEF position, velocity and acceleration, clock
//! bias and drift, BeiDou inter-system bias), which `ekf11` and the filter family
//! ([`crate::fusion::family`]) share. `F = Φ(Δt)` and `Q = Q(Δt)` are
//! [`Ekf11::transition`] and [`Ekf11::process_noise`] of the estimator's own
//! [`Ekf11Config`] (with the inter-system-bias state switched on exactly when the
//! estimator switches it on, [`Ekf11Config::for_systems`]), at the intervals between the
//! instants at which measurements arrive. Every range of every system shares the clock
//! `b`; BeiDou ranges add the inter-system bias when it is a state. Each pseudorange
//! contributes `hᵀh/σ²` with `h` the Jacobian of [`Pseudoranges`], each range rate
//! `hᵀh/σ_ρ̇²` with `h` row 2 of [`PseudorangesAndRates`] (the exact Jacobian, position
//! terms included, whatever linearisation the estimator uses: the bound concerns the
//! data, not the filter), both evaluated at the true position and velocity.
//!
//! The prior is the estimator's: before its first fix it knows nothing of the position
//! and the clock bias (flat, [`FLAT_PRIOR_VAR_M2`]; the first fix is least squares on the
//! first epoch's ranges, whose covariance is this flat prior updated with that epoch's
//! information), and the configured initial σ of velocity, acceleration, clock drift and
//! inter-system bias. The first epoch's range rates are counted although the estimators
//! initialise without them, which can only lower the bound.

use crate::core::System;
use crate::fusion::ekf11::{idx, Ekf11, Ekf11Config, N_STATES};
use crate::fusion::models::{
    MeasurementModel, PlaneTurning, ProcessModel, Pseudoranges, PseudorangesAndRates, RangeRow,
    Singer5, StateLayout,
};
use crate::fusion::paper::{ClockMode, ProcessSpec, N_CLOCKS};
use crate::measurement::RangeMeasurement;
use nalgebra::{DMatrix, SMatrix, SVector, Vector3};

/// The variance (m²) standing for a flat prior on a clock: 10¹⁰ m² (a 100 km σ), far above
/// any range's information and far below where rounding would spoil the recursion.
pub const FLAT_PRIOR_VAR_M2: f64 = 1e10;

/// One step of the bound: `B⁻ = F B Fᵀ + Q`, then `B⁻ (I + Ī B⁻)⁻¹`, symmetrised.
///
/// # Errors
/// When `I + Ī B⁻` is singular (an information matrix that is not semi-definite).
pub fn bound_step(
    b: &DMatrix<f64>,
    f: &DMatrix<f64>,
    q: &DMatrix<f64>,
    info: &DMatrix<f64>,
) -> Result<DMatrix<f64>, String> {
    let n = b.nrows();
    let pred = f * b * f.transpose() + q;
    let m = DMatrix::<f64>::identity(n, n) + info * &pred;
    let lu = m.lu();
    // B⁻ M⁻¹ = (M⁻ᵀ B⁻ᵀ)ᵀ = (Mᵀ \ B⁻)ᵀ since B⁻ is symmetric.
    let mt = lu
        .solve(&DMatrix::<f64>::identity(n, n))
        .ok_or("singular I + J B")?;
    let out = &pred * mt;
    Ok((&out + out.transpose()) * 0.5)
}

/// The bound `B_k` for every epoch `k` of a model with constant `F` and `Q`, from the
/// prior `b0` and the (trial-averaged) measurement information of each epoch.
///
/// # Errors
/// See [`bound_step`].
pub fn bound_sequence(
    b0: &DMatrix<f64>,
    f: &DMatrix<f64>,
    q: &DMatrix<f64>,
    infos: &[DMatrix<f64>],
) -> Result<Vec<DMatrix<f64>>, String> {
    let mut b = b0.clone();
    let mut out = Vec::with_capacity(infos.len());
    for info in infos {
        b = bound_step(&b, f, q, info)?;
        out.push(b.clone());
    }
    Ok(out)
}

fn dyn_of<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_fn(R, C, |i, j| m[(i, j)])
}

/// The PCRLB of a paper estimator's model over a world's epochs (see the module
/// documentation).
#[derive(Clone, Debug)]
pub struct PaperBound {
    n: usize,
    nm: usize,
    pos: [Option<usize>; 3],
    plane_up_m: Option<f64>,
    f: DMatrix<f64>,
    q: DMatrix<f64>,
    b0: DMatrix<f64>,
    sums: Vec<DMatrix<f64>>,
    counts: Vec<usize>,
}

impl PaperBound {
    /// The bound of `spec` for `epochs` epochs `dt_s` apart, the first `dt_s` after the
    /// prior; `plane_up_m` is the plane's height for the 2-D model.
    ///
    /// # Errors
    /// `spec` is seed 000's model (its bound is not built here) or unusable.
    pub fn new(
        spec: &ProcessSpec,
        dt_s: f64,
        epochs: usize,
        plane_up_m: f64,
    ) -> Result<Self, String> {
        let (fm, qm, p0m, nm, pos, plane, clocks, clock_q, sigma0) = match spec {
            ProcessSpec::PvaClock {} => {
                return Err("the bound is built for the paper models only".into())
            }
            ProcessSpec::Singer2d {
                alpha_per_s,
                accel_var_m2ps4,
                initial_state,
                initial_sigma,
                clocks,
                clock_noise_m2ps,
            } => {
                let m = Singer5::new(*alpha_per_s, *accel_var_m2ps4).map_err(|e| e.to_string())?;
                let x0 = SVector::<f64, 5>::from(*initial_state);
                (
                    dyn_of(&m.jacobian(&x0, dt_s)),
                    dyn_of(&m.q(&x0, dt_s)),
                    dyn_of(&m.q(&x0, 1.0)),
                    5,
                    [Some(0), Some(2), None],
                    Some(plane_up_m),
                    *clocks,
                    *clock_noise_m2ps,
                    initial_sigma.map(|s| s.to_vec()),
                )
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
                let m =
                    PlaneTurning::new(*attenuation_per_s, *turn_rate_rad_per_s, *noise_var_m2ps4)
                        .map_err(|e| e.to_string())?;
                let x0 = SVector::<f64, 9>::from(*initial_state);
                (
                    dyn_of(&m.jacobian(&x0, dt_s)),
                    dyn_of(&m.q(&x0, dt_s)),
                    dyn_of(&m.q(&x0, 1.0)),
                    9,
                    [Some(0), Some(1), Some(2)],
                    None,
                    *clocks,
                    *clock_noise_m2ps,
                    initial_sigma.map(|s| s.to_vec()),
                )
            }
        };
        let n = nm + N_CLOCKS;
        let mut f = DMatrix::<f64>::identity(n, n);
        f.view_mut((0, 0), (nm, nm)).copy_from(&fm);
        let mut q = DMatrix::<f64>::zeros(n, n);
        q.view_mut((0, 0), (nm, nm)).copy_from(&qm);
        let mut b0 = DMatrix::<f64>::zeros(n, n);
        match sigma0 {
            Some(s) => {
                for (i, v) in s.iter().enumerate() {
                    b0[(i, i)] = v * v;
                }
            }
            None => b0.view_mut((0, 0), (nm, nm)).copy_from(&p0m),
        }
        for s in 0..N_CLOCKS {
            let k = nm + s;
            match clocks {
                ClockMode::Known => {}
                ClockMode::Estimated => {
                    b0[(k, k)] = FLAT_PRIOR_VAR_M2;
                    q[(k, k)] = clock_q * dt_s;
                }
            }
        }
        Ok(Self {
            n,
            nm,
            pos,
            plane_up_m: plane,
            f,
            q,
            b0,
            sums: vec![DMatrix::zeros(n, n); epochs],
            counts: vec![0; epochs],
        })
    }

    /// Adds one trial's epoch `k`: the receiver's true ENU position and the ranges'
    /// emitters (ENU), systems and σ.
    pub fn add(
        &mut self,
        k: usize,
        truth_enu_m: &Vector3<f64>,
        ranges: &[(Vector3<f64>, System, f64)],
    ) {
        let Some(sum) = self.sums.get_mut(k) else {
            return;
        };
        let mut r = *truth_enu_m;
        if let Some(up) = self.plane_up_m {
            r.z = up;
        }
        let mut h = DMatrix::<f64>::zeros(self.n, 1);
        for (e, system, sigma_m) in ranges {
            let d = r - e;
            let dist = d.norm();
            if !(dist > 0.0 && *sigma_m > 0.0) {
                continue;
            }
            h.fill(0.0);
            for (a, c) in self.pos.iter().enumerate() {
                if let Some(c) = c {
                    h[(*c, 0)] = d[a] / dist;
                }
            }
            h[(self.nm + system.index(), 0)] = 1.0;
            *sum += &h * h.transpose() / (sigma_m * sigma_m);
        }
        self.counts[k] += 1;
    }

    /// The bound on the position's mean-square error (m², the trace of its block) at
    /// every epoch, from the information averaged over the trials added.
    ///
    /// # Errors
    /// See [`bound_step`].
    pub fn position_mse_m2(&self) -> Result<Vec<f64>, String> {
        let infos: Vec<DMatrix<f64>> = self
            .sums
            .iter()
            .zip(&self.counts)
            .map(|(s, c)| if *c > 0 { s / *c as f64 } else { s.clone() })
            .collect();
        let seq = bound_sequence(&self.b0, &self.f, &self.q, &infos)?;
        Ok(seq
            .iter()
            .map(|b| self.pos.iter().flatten().map(|&c| b[(c, c)]).sum())
            .collect())
    }
}

/// A position trace (m²) below which the position counts as determined: a kilometre
/// RMS, far below the flat prior's `3·10¹⁰ m²` and far above any fix.
pub const DETERMINED_POS_MSE_M2: f64 = 1e6;

/// The PCRLB of seed 000's 12-state model over a run's measurement instants (see the
/// module documentation).
#[derive(Clone, Debug)]
pub struct PvaClockBound {
    cfg: Ekf11Config,
    layout: StateLayout,
    b0: DMatrix<f64>,
    instants_s: Vec<f64>,
    sums: Vec<SMatrix<f64, N_STATES, N_STATES>>,
    trials: usize,
    /// The current trial's pseudorange information of each instant it had an epoch at.
    snapshot: Vec<Option<SMatrix<f64, N_STATES, N_STATES>>>,
    /// Whether every epoch so far, from the first whose ranges fixed the position on,
    /// had ranges that fix the position and the clock on their own.
    snapshot_determined: bool,
}

impl PvaClockBound {
    /// The bound of an estimator tuned by `cfg` on the ranges of `systems`, with
    /// measurements at `instants_s` (s, strictly increasing; the first is the instant of
    /// the estimator's first fix).
    ///
    /// # Errors
    /// `cfg` is unusable or the instants are not finite and strictly increasing.
    pub fn new(cfg: Ekf11Config, systems: &[System], instants_s: Vec<f64>) -> Result<Self, String> {
        let cfg = cfg.for_systems(systems);
        cfg.validate().map_err(|e| e.to_string())?;
        if instants_s.iter().any(|t| !t.is_finite()) || instants_s.windows(2).any(|w| w[1] <= w[0])
        {
            return Err("the instants must be finite and strictly increasing".into());
        }
        let mut layout = StateLayout::ekf11();
        if cfg.isb_bds.is_none() {
            layout.isb = [None; System::COUNT];
        }
        Ok(Self {
            b0: Self::prior(&cfg),
            cfg,
            layout,
            sums: vec![SMatrix::zeros(); instants_s.len()],
            snapshot: vec![None; instants_s.len()],
            instants_s,
            trials: 0,
            snapshot_determined: true,
        })
    }

    /// The same bound from another prior `b0` (12 × 12, symmetric).
    ///
    /// # Errors
    /// When `b0` is not 12 × 12 or holds a value that is not finite.
    pub fn with_prior(mut self, b0: DMatrix<f64>) -> Result<Self, String> {
        if b0.shape() != (N_STATES, N_STATES) || b0.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "a prior of {:?}: expected a finite {N_STATES} × {N_STATES} matrix",
                b0.shape()
            ));
        }
        self.b0 = b0;
        Ok(self)
    }

    /// The estimator's prior (see the module documentation): flat on position and clock
    /// bias, the configured initial variances of the other states. An inert
    /// inter-system bias keeps the unit variance the filter family gives it; no
    /// measurement and no process noise reach it.
    pub fn prior(cfg: &Ekf11Config) -> DMatrix<f64> {
        let mut b = DMatrix::<f64>::zeros(N_STATES, N_STATES);
        for axis in 0..3 {
            b[(idx::POS[axis], idx::POS[axis])] = FLAT_PRIOR_VAR_M2;
            b[(idx::VEL[axis], idx::VEL[axis])] = cfg.init_vel_sigma_mps.powi(2);
            b[(idx::ACC[axis], idx::ACC[axis])] = cfg.init_acc_sigma_mps2.powi(2);
        }
        b[(idx::CLOCK_BIAS, idx::CLOCK_BIAS)] = FLAT_PRIOR_VAR_M2;
        b[(idx::CLOCK_DRIFT, idx::CLOCK_DRIFT)] = cfg.init_clock_drift_sigma_mps.powi(2);
        b[(idx::ISB_BDS, idx::ISB_BDS)] = cfg.isb_bds.map_or(1.0, |i| i.initial_sigma_m.powi(2));
        b
    }

    /// The measurement instants (s).
    pub fn instants_s(&self) -> &[f64] {
        &self.instants_s
    }

    /// Adds to instant `k` of the current trial the information of `ranges` seen from the
    /// true ECEF position and velocity: `hᵀh/σ²` for each pseudorange and, when it
    /// carries one, `hᵀh/σ_ρ̇²` for its range rate. A row whose σ is not positive and
    /// finite, or whose emitter sits on the receiver, carries no information (the
    /// estimators reject it too). Instant `k` is an epoch of the estimator (a batch of a
    /// source it uses arrived, even an empty one); several calls may add to one instant
    /// (two sources at one time).
    pub fn add(
        &mut self,
        k: usize,
        truth_pos_ecef_m: &Vector3<f64>,
        truth_vel_ecef_mps: &Vector3<f64>,
        ranges: &[RangeMeasurement],
    ) {
        let (Some(sum), Some(snap)) = (self.sums.get_mut(k), self.snapshot.get_mut(k)) else {
            return;
        };
        let snap = snap.get_or_insert_with(SMatrix::zeros);
        let mut x = SVector::<f64, N_STATES>::zeros();
        for axis in 0..3 {
            x[idx::POS[axis]] = truth_pos_ecef_m[axis];
            x[idx::VEL[axis]] = truth_vel_ecef_mps[axis];
        }
        for m in ranges {
            let row = RangeRow::from(m);
            if (row.emitter_pos_m - truth_pos_ecef_m).norm() <= 0.0 {
                continue;
            }
            if let Ok(pr) = Pseudoranges::<N_STATES, 1>::new(self.layout, [row]) {
                let h = pr.jacobian(&x);
                let info = h.transpose() * h / (m.sigma_m * m.sigma_m);
                *sum += info;
                *snap += info;
            }
            if m.range_rate_mps.is_none() {
                continue;
            }
            if let Ok(both) = PseudorangesAndRates::<N_STATES, 2>::new(self.layout, &[row]) {
                let h = both.jacobian(&x).fixed_rows::<1>(1).into_owned();
                let w = 1.0 / (m.sigma_rate_mps * m.sigma_rate_mps);
                if h.iter().all(|v| v.is_finite()) && w.is_finite() {
                    *sum += h.transpose() * h * w;
                }
            }
        }
    }

    /// Closes one trial: the information of each instant is averaged over the trials
    /// closed, and the trial's epochs are checked for
    /// [`PvaClockBound::measurement_determined`].
    pub fn end_trial(&mut self) {
        self.trials += 1;
        let mut fixed = false;
        let isb = self.cfg.isb_bds.is_some();
        for snap in &mut self.snapshot {
            let Some(info) = snap.take() else {
                continue;
            };
            let ok = Self::snapshot_pos_mse_m2(&info, isb) < DETERMINED_POS_MSE_M2;
            fixed |= ok;
            if fixed && !ok {
                self.snapshot_determined = false;
            }
        }
    }

    /// The position MSE (m²) of a least-squares fix on one epoch's pseudoranges alone,
    /// `tr[(Ī_s)⁻¹]_pos` over the position, the clock bias and (when it is a state) the
    /// BeiDou inter-system bias; infinite when they do not determine them. An epoch
    /// without BeiDou ranges has no information on the bias, and none of its ranges
    /// depends on it: the bias is then left out rather than counted as undetermined (its
    /// row of the information is zero, so the position block is the same either way).
    fn snapshot_pos_mse_m2(info: &SMatrix<f64, N_STATES, N_STATES>, isb: bool) -> f64 {
        let mut cols: Vec<usize> = idx::POS.to_vec();
        cols.push(idx::CLOCK_BIAS);
        if isb && info[(idx::ISB_BDS, idx::ISB_BDS)] > 0.0 {
            cols.push(idx::ISB_BDS);
        }
        let n = cols.len();
        let sub = DMatrix::from_fn(n, n, |i, j| info[(cols[i], cols[j])]);
        match sub.cholesky() {
            Some(c) => {
                let inv = c.inverse();
                (0..3).map(|i| inv[(i, i)]).sum()
            }
            None => f64::INFINITY,
        }
    }

    /// Whether, in every trial, every epoch from the first whose pseudoranges fixed the
    /// position on had pseudoranges that fix the position and the clock on their own
    /// (a snapshot position RMS below [`DETERMINED_POS_MSE_M2`]'s kilometre).
    ///
    /// Where they do, the bound is carried by the measurements. Where they do not (two or
    /// three satellites in a shielding window) it is carried by the spread of the
    /// trajectories the process model allows: the PCRLB is a bound on the MSE averaged
    /// over trajectories drawn from the model, and a world whose truth is one gentler
    /// trajectory (seed 000's waypoint plans against a white jerk of 1 m²/s⁵ on every
    /// ECEF axis) lets an estimator far below it there — measured on seed 000's Kehui
    /// world, a GPS-only EKF at 31 m RMS during 150–180 s against a "bound" of 487 m
    /// (docs/validation.md). The world reports the bound only when this holds.
    pub fn measurement_determined(&self) -> bool {
        self.snapshot_determined
    }

    /// The bound on the position's mean-square error (m², the trace of its ECEF block) at
    /// every instant, from the information averaged over the trials closed: `None` at
    /// the instants before the position is first determined ([`DETERMINED_POS_MSE_M2`]),
    /// where the estimator has no first fix either.
    ///
    /// # Errors
    /// See [`bound_step`].
    pub fn position_mse_m2(&self) -> Result<Vec<Option<f64>>, String> {
        let mut determined = false;
        Ok(self
            .bounds()?
            .iter()
            .map(|b| {
                let mse: f64 = idx::POS.iter().map(|&c| b[(c, c)]).sum();
                determined |= mse < DETERMINED_POS_MSE_M2;
                determined.then_some(mse)
            })
            .collect())
    }

    /// The whole bound `B_k` (12 × 12) at every instant: the prior updated with the first
    /// instant's information, then `Φ(Δt)`, `Q(Δt)` and each next instant's.
    ///
    /// # Errors
    /// See [`bound_step`].
    pub fn bounds(&self) -> Result<Vec<DMatrix<f64>>, String> {
        let n = self.trials.max(1) as f64;
        let mut b = self.b0.clone();
        let mut last_t: Option<f64> = None;
        let mut out = Vec::with_capacity(self.instants_s.len());
        for (t, sum) in self.instants_s.iter().zip(&self.sums) {
            let dt = last_t.map_or(0.0, |l| t - l);
            last_t = Some(*t);
            let f = dyn_of(&Ekf11::transition(dt));
            let q = dyn_of(&Ekf11::process_noise(&self.cfg, dt));
            let info = DMatrix::from_fn(N_STATES, N_STATES, |i, j| sum[(i, j)] / n);
            b = bound_step(&b, &f, &q, &info)?;
            out.push(b.clone());
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::linear_kf::LinearKf;
    use nalgebra::DVector;

    /// On a linear-Gaussian model (a 1-D constant-velocity target and a clock, observed by
    /// two range-like rows whose H changes from epoch to epoch) the bound equals the
    /// covariance of the textbook Kalman filter (Joseph form, explicit S⁻¹): the KF is
    /// efficient there. A singular Q (the clock is constant) is part of the check.
    #[test]
    fn the_bound_is_the_kalman_covariance_on_a_linear_gaussian_model() {
        let f = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let q = DMatrix::from_row_slice(
            3,
            3,
            &[
                0.25 / 4.0,
                0.5 / 2.0,
                0.0,
                0.5 / 2.0,
                0.5,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        );
        let p0 = DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 4.0, 2500.0]));
        let mut kf = LinearKf::new(DVector::zeros(3), p0.clone()).unwrap();
        let mut infos = Vec::new();
        let mut kf_covs = Vec::new();
        for k in 0..60 {
            let c = (0.3 * k as f64).cos();
            let h = DMatrix::from_row_slice(2, 3, &[c, 0.0, 1.0, -0.5, 0.1 * c, 1.0]);
            let r = DMatrix::from_diagonal(&DVector::from_vec(vec![9.0, 25.0]));
            kf.predict(&f, &q).unwrap();
            kf.update(&DVector::zeros(2), &h, &r).unwrap();
            kf_covs.push(kf.covariance().clone());
            infos.push(h.transpose() * r.try_inverse().unwrap() * &h);
        }
        let bounds = bound_sequence(&p0, &f, &q, &infos).unwrap();
        for (k, (b, p)) in bounds.iter().zip(&kf_covs).enumerate() {
            let diff = (b - p).abs().max();
            assert!(diff <= 1e-9 * p.abs().max().max(1.0), "epoch {k}: {diff}");
        }
    }

    /// Seed 000's model on a linear-Gaussian case: emitters 10¹⁵ m away in fixed
    /// directions, so that every pseudorange and range-rate row is constant to 10⁻¹³
    /// however the receiver moves, GPS and BeiDou rows (the inter-system bias is a state)
    /// and a tower without a rate, at irregular intervals. The bound equals the covariance
    /// of the textbook Kalman filter run on the same Φ, Q, H and R, its H written out here
    /// from the model's equations (−u on position and velocity, 1 on the clock bias,
    /// drift and inter-system bias), to 1e-9 of the largest entry.
    #[test]
    fn the_pva_clock_bound_is_the_kalman_covariance_on_a_linear_gaussian_case() {
        use crate::core::EmitterId;
        use crate::fusion::ekf11::idx;
        let cfg = Ekf11Config::default().for_systems(&[System::Gps, System::Bds]);
        assert!(cfg.isb_bds.is_some());
        let r0 = Vector3::new(-2_178_000.0, 4_388_000.0, 4_069_000.0);
        let v = Vector3::new(9.0, -4.0, 1.5);
        let dirs = [
            (Vector3::new(0.3, 0.5, 0.81), System::Gps, 3.0, Some(0.05)),
            (Vector3::new(-0.6, 0.2, 0.77), System::Gps, 4.5, Some(0.08)),
            (Vector3::new(0.1, -0.7, 0.7), System::Bds, 2.5, Some(0.06)),
            (Vector3::new(-0.2, -0.3, 0.93), System::Bds, 5.0, Some(0.2)),
            (Vector3::new(0.8, 0.1, 0.59), System::Gps, 3.5, Some(0.1)),
            (Vector3::new(0.9, -0.4, 0.05), System::Dtmb, 6.0, None),
        ];
        let far_m = 1e15;
        // (position, unit direction, system, σ, range-rate σ)
        type Emitter = (Vector3<f64>, Vector3<f64>, System, f64, Option<f64>);
        let emitters: Vec<Emitter> = dirs
            .iter()
            .map(|(d, s, sig, rate)| {
                let n = d.normalize();
                (r0 + n * far_m, n, *s, *sig, *rate)
            })
            .collect();
        let instants: Vec<f64> = (0..40).map(|k| k as f64 + 0.3 * (k % 3) as f64).collect();
        // The estimator's prior with a 100 m σ for position and clock instead of the flat
        // one: from 10¹⁰ m² the first update cancels ten digits in both filters alike, and
        // the comparison would measure rounding rather than the recursion.
        let mut p0 = PvaClockBound::prior(&cfg);
        for k in idx::POS.iter().chain(&[idx::CLOCK_BIAS]) {
            p0[(*k, *k)] = 1e4;
        }
        let mut bound = PvaClockBound::new(cfg, &[System::Gps, System::Bds], instants.clone())
            .unwrap()
            .with_prior(p0.clone())
            .unwrap();
        for (k, t) in instants.iter().enumerate() {
            let truth = r0 + v * *t;
            let ranges: Vec<RangeMeasurement> = emitters
                .iter()
                .enumerate()
                .map(|(j, (e, _, s, sig, rate))| RangeMeasurement {
                    emitter: EmitterId::new(*s, j as u16 + 1),
                    emitter_pos_ecef_m: *e,
                    emitter_vel_ecef_mps: Vector3::zeros(),
                    pseudorange_m: (e - truth).norm(),
                    sigma_m: *sig,
                    range_rate_mps: rate.map(|_| 0.0),
                    sigma_rate_mps: rate.unwrap_or(0.0),
                    cn0_dbhz: 45.0,
                    elevation_rad: 0.5,
                })
                .collect();
            bound.add(k, &truth, &v, &ranges);
        }
        bound.end_trial();
        // The independent Kalman filter: stacked rows with H written out by hand.
        let n_rows: usize = emitters.iter().map(|e| 1 + e.4.is_some() as usize).sum();
        let mut h = DMatrix::<f64>::zeros(n_rows, N_STATES);
        let mut r = DMatrix::<f64>::zeros(n_rows, n_rows);
        let mut row = 0;
        for (_, n, s, sig, rate) in &emitters {
            for a in 0..3 {
                h[(row, idx::POS[a])] = -n[a];
            }
            h[(row, idx::CLOCK_BIAS)] = 1.0;
            if *s == System::Bds {
                h[(row, idx::ISB_BDS)] = 1.0;
            }
            r[(row, row)] = sig * sig;
            row += 1;
            if let Some(sr) = rate {
                for a in 0..3 {
                    h[(row, idx::VEL[a])] = -n[a];
                }
                h[(row, idx::CLOCK_DRIFT)] = 1.0;
                r[(row, row)] = sr * sr;
                row += 1;
            }
        }
        let mut kf = LinearKf::new(DVector::zeros(N_STATES), p0).unwrap();
        let bounds = bound.bounds().unwrap();
        let mut last = None;
        for (k, t) in instants.iter().enumerate() {
            if let Some(l) = last {
                let dt: f64 = t - l;
                kf.predict(
                    &dyn_of(&Ekf11::transition(dt)),
                    &dyn_of(&Ekf11::process_noise(&cfg, dt)),
                )
                .unwrap();
            }
            last = Some(*t);
            kf.update(&DVector::zeros(n_rows), &h, &r).unwrap();
            let p = kf.covariance();
            let diff = (&bounds[k] - p).abs().max();
            assert!(
                diff <= 1e-9 * p.abs().max().max(1.0),
                "instant {k}: {diff} of {}",
                p.abs().max()
            );
        }
        // Every epoch has five pseudoranges for position, clock and inter-system bias.
        assert!(bound.measurement_determined());
        let mse = bound.position_mse_m2().unwrap();
        assert!(
            mse.iter()
                .all(|m| m.is_some_and(|m| m > 0.0 && m.is_finite())),
            "{mse:?}"
        );
    }

    /// An epoch whose pseudoranges cannot fix position and clock on their own (three
    /// satellites) after the first fix makes the bound process-model-carried, and the
    /// flag says so; the same epochs with four satellites do not.
    #[test]
    fn an_epoch_short_of_satellites_is_flagged() {
        use crate::core::EmitterId;
        let r0 = Vector3::new(-2_178_000.0, 4_388_000.0, 4_069_000.0);
        let dirs = [
            Vector3::new(0.3, 0.5, 0.81),
            Vector3::new(-0.6, 0.2, 0.77),
            Vector3::new(0.1, -0.7, 0.7),
            Vector3::new(0.8, 0.1, 0.59),
        ];
        let ranges: Vec<RangeMeasurement> = dirs
            .iter()
            .enumerate()
            .map(|(j, d)| RangeMeasurement {
                emitter: EmitterId::new(System::Gps, j as u16 + 1),
                emitter_pos_ecef_m: r0 + d.normalize() * 2.2e7,
                emitter_vel_ecef_mps: Vector3::zeros(),
                pseudorange_m: 0.0,
                sigma_m: 3.0,
                range_rate_mps: Some(0.0),
                sigma_rate_mps: 0.05,
                cn0_dbhz: 45.0,
                elevation_rad: 0.5,
            })
            .collect();
        for (short, want) in [(false, true), (true, false)] {
            let mut b =
                PvaClockBound::new(Ekf11Config::default(), &[System::Gps], vec![0.0, 1.0, 2.0])
                    .unwrap();
            for k in 0..3 {
                let n = if short && k == 1 { 3 } else { 4 };
                b.add(k, &r0, &Vector3::zeros(), &ranges[..n]);
            }
            b.end_trial();
            assert_eq!(b.measurement_determined(), want, "short epoch: {short}");
        }
    }

    /// A known state (zero prior variance, no process noise) stays exactly known, and a
    /// flat-prior clock does not leak into the position block.
    #[test]
    fn known_states_stay_known() {
        let spec = ProcessSpec::Singer2d {
            alpha_per_s: 0.1,
            accel_var_m2ps4: 3.5,
            initial_state: [4000.0, 14.0, 0.0, 11.0, 0.0],
            initial_sigma: Some([0.0, 0.0, 1.0, 1.0, 1.0]),
            clocks: ClockMode::Known,
            clock_noise_m2ps: 0.0,
        };
        let mut b = PaperBound::new(&spec, 1.0, 3, 0.0).unwrap();
        for k in 0..3 {
            b.add(
                k,
                &Vector3::new(4000.0, 0.0, 0.0),
                &[(Vector3::new(0.0, 1e7, 2e7), System::Gps, 10.0)],
            );
        }
        let mse = b.position_mse_m2().unwrap();
        // x is known exactly; y's bound is positive and below its prior's growth.
        assert!(mse.iter().all(|v| *v > 0.0 && v.is_finite()));
        let seq = bound_sequence(&b.b0, &b.f, &b.q, &b.sums).unwrap();
        assert!(seq.iter().all(|m| m[(0, 0)].abs() < 1e-12));
    }
}
