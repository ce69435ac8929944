//! The sampling-importance-resampling (SIR) particle filter of seed 001 (GPS + DTMB,
//! §3, steps 1–6) on the models of [`crate::fusion::models`], after Gordon, Salmond &
//! Smith, "Novel approach to nonlinear/non-Gaussian Bayesian state estimation", *IEE
//! Proc. F* 140(2), 1993, and Arulampalam et al., "A tutorial on particle filters", *IEEE
//! Trans. SP* 50(2), 2002 (Algorithm 4):
//!
//! ```text
//! predict:    x_i ← f(x_i, T) + G w_i,   w_i ~ N(0, I),   G Gᵀ = Q
//! weight:     w_i ← w_i · p(z | x_i),    normalised so that Σ w_i = 1
//! N_eff = 1 / Σ w_i²;   resample when N_eff < θ·N, then w_i = 1/N   (seed 001 step 4–5)
//! estimate:   x̂ = Σ w_i x_i                                          (seed 001 eq. 10)
//! ```
//!
//! The other members ([`PfVariant`]) share these buffers and the column-wise likelihood:
//! the regularised, Rao-Blackwellised and marginalised filters, and the Gaussian particle
//! filter of Kotecha & Djurić (2003), which never resamples and carries the posterior as
//! the Gaussian of the weighted cloud's moments ([`ParticleFilter::gaussian`]).
//!
//! Each member can draw from the prior (the bootstrap filter above) or from a proposal
//! linearised on the epoch's ranges ([`ParticleFilter::update_linearised`]): the resampling
//! filters condition their process noise, and after a resampling the regularised filter's
//! kernel, on the ranges (Doucet, Godsill & Andrieu 2000, §II.D.2), the Rao-Blackwellised
//! one with its Kalman-carried clocks integrated out; the Gaussian filter
//! draws from the EKF update of its predicted Gaussian and weights each particle by the
//! exact over the linearised likelihood. With few particles on the papers' models, whose
//! positions have little or no process noise, this is what keeps the weights from
//! collapsing (docs/reproductions.md, seeds 001 and 003).
//!
//! # Layout and speed
//!
//! The particles live in a [`ParticleBuffer`] the caller builds once (and can take back
//! with [`ParticleFilter::into_buffer`]): one contiguous `f64` column per state component
//! (structure of arrays), plus the weight, log-likelihood and resampling buffers. Nothing
//! is allocated after construction.
//!
//! The weights are formed in the log domain: each measurement adds its
//! `−½ (z_j − h_j(x_i))² / σ_j²` to a per-particle sum, and a single `exp` per particle
//! (after subtracting the largest sum, so that it cannot underflow to all zeros) turns the
//! sum into a weight factor. [`PseudorangeLikelihood`] evaluates the pseudorange terms
//! over the columns in blocks that stay in the L1 cache, measurement by measurement, with
//! `−½/σ²` precomputed; the inner loop is branch-free over contiguous arrays so the
//! compiler vectorises it.
//!
//! # Failure handling
//!
//! When every particle gets weight zero (all log-likelihoods `−∞` or NaN, e.g. from a
//! measurement far outside the cloud), the update cannot be normalised. The filter keeps
//! its particles, resets the weights to uniform and reports `degenerate = true` in the
//! [`PfUpdate`], so the caller sees the failure instead of a NaN estimate.

use crate::core::System;
use crate::fusion::models::{MeasurementModel, ProcessModel, Pseudoranges, RangeRow, StateLayout};
use nalgebra::{SMatrix, SVector, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// Errors of the particle filter.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ParticleError {
    /// A parameter is unusable (zero particles, a threshold outside [0, 1], …).
    #[error("invalid particle-filter parameter: {0}")]
    InvalidParameter(String),
    /// A mean, covariance, interval or model output is not finite.
    #[error("non-finite value in the input or result; the particles are unchanged")]
    NonFinite,
    /// A covariance has a negative eigenvalue.
    #[error("a covariance is not positive semi-definite")]
    NotPositiveSemiDefinite,
}

/// How the resampling step draws its `N` ordered uniforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resampling {
    /// One uniform `u ~ U[0, 1/N)`, then `u + i/N` (Kitagawa 1996; Carpenter, Clifford &
    /// Fearnhead 1999). Lowest variance, O(N).
    Systematic,
    /// `u_i ~ U[i/N, (i+1)/N)` independently (Kitagawa 1996). O(N).
    Stratified,
    /// Residual resampling (Liu & Chen, "Sequential Monte Carlo methods for dynamic
    /// systems", *JASA* 93, 1998, §3): `⌊N w_i⌋` copies of particle `i` deterministically,
    /// then the `R = N − Σ⌊N w_i⌋` remaining slots drawn from the residual weights
    /// `(N w_i − ⌊N w_i⌋) / R`, here systematically. O(N).
    Residual,
}

/// The regularisation kernel's placement after a resampling
/// ([`ParticleFilter::resample_regularised`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelPlacement {
    /// Each particle is first shrunk towards the cloud's mean so that the jittered cloud
    /// keeps the posterior covariance the weighted cloud estimates (Liu & West 2001): no
    /// inflation. The estimate is the unbiased one, the weighted covariance over
    /// `1 − Σ w_i²`, and the bandwidth is sized by the weighted cloud's effective sample
    /// size (see [`ParticleFilter::resample_regularised`]).
    Shrunk,
    /// The jitter is added to the resampled particles as they are (Musso, Oudjane & Le
    /// Gland 2001, the regularised PF as they define it): the cloud's covariance grows by
    /// `h_opt²` of itself at each resampling.
    Plain,
    /// Each kernel where its authors put it: the static parameters (the components the
    /// process model holds constant, [`ParticleFilter::with_static_components`]: seed
    /// 003's clocks) are shrunk as Liu & West (2001) do for the fixed parameters they
    /// designed the shrinkage for, and the states the process noise drives get Musso's
    /// plain kernel. A constant clock then keeps its spread across resamplings instead
    /// of growing by `h_opt²` at each one, which nothing in its dynamics ever takes back.
    ShrunkStatic,
}

/// Which member of the particle-filter family runs (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PfVariant {
    /// Plain sampling-importance-resampling: the process noise is the only diversity.
    Sir,
    /// The regularised PF: each resampling is followed by a Gaussian kernel jitter with
    /// the optimal bandwidth, shaped by the cloud's covariance.
    Regularised,
    /// The Rao-Blackwellised PF: the clock states are carried by a Kalman filter per
    /// particle (their means in the clock columns, their common variance beside), the
    /// rest is sampled and regularised as in [`PfVariant::Regularised`].
    RaoBlackwellised,
    /// The marginalised PF of mixed linear/nonlinear models: only the positions are
    /// sampled; the other motion states (velocity, acceleration), which enter the
    /// dynamics linearly and the ranges not at all, are carried by a Kalman filter per
    /// particle, as are the clocks (see [`ParticleFilter::marginalised`]).
    Marginalised,
    /// The Gaussian particle filter (Kotecha & Djurić 2003, see [`ParticleFilter::gaussian`]): no
    /// resampling; the posterior is the Gaussian of the weighted cloud's moments, and
    /// each prediction redraws the cloud from the predicted Gaussian.
    Gaussian,
}

impl PfVariant {
    /// Whether this member can bring an epoch's likelihood in by progressive correction
    /// ([`ParticleFilter::with_progressive_correction`]): the regularised and
    /// Rao-Blackwellised members with the prior proposal (the linearised proposal already
    /// conditions on the ranges; the others keep their single update). Where it can, it is
    /// the world's default.
    pub fn takes_progressive_correction(self, linearised: bool) -> bool {
        matches!(self, PfVariant::Regularised | PfVariant::RaoBlackwellised) && !linearised
    }
}

/// The storage of `n` particles of dimension `N`, allocated once.
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleBuffer<const N: usize> {
    n: usize,
    /// Column `k` (state component `k` of every particle) is `cols[k·n .. (k+1)·n]`.
    cols: Vec<f64>,
    weights: Vec<f64>,
    log_lik: Vec<f64>,
    /// The cumulative weights, then the copy of a column during resampling.
    scratch: Vec<f64>,
    idx: Vec<usize>,
    /// The linearised proposal's component means `x_i + G ν_i`, laid out as `cols`
    /// (see [`ParticleFilter::update_linearised`]).
    centres: Vec<f64>,
}

impl<const N: usize> ParticleBuffer<N> {
    /// Storage for `n` particles.
    ///
    /// # Errors
    /// When `n` is 0.
    pub fn new(n: usize) -> Result<Self, ParticleError> {
        if n == 0 || N == 0 {
            return Err(ParticleError::InvalidParameter(
                "a particle filter needs at least one particle of dimension ≥ 1".into(),
            ));
        }
        Ok(Self {
            n,
            cols: vec![0.0; N * n],
            weights: vec![1.0 / n as f64; n],
            log_lik: vec![0.0; n],
            scratch: vec![0.0; n],
            idx: vec![0; n],
            centres: vec![0.0; N * n],
        })
    }

    /// The number of particles.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always false: a buffer holds at least one particle.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// State component `k` of every particle.
    pub fn column(&self, k: usize) -> &[f64] {
        &self.cols[k * self.n..(k + 1) * self.n]
    }

    /// State component `k` of every particle, writable (to seed particles directly).
    pub fn column_mut(&mut self, k: usize) -> &mut [f64] {
        &mut self.cols[k * self.n..(k + 1) * self.n]
    }

    /// All columns, component-major.
    pub fn columns(&self) -> &[f64] {
        &self.cols
    }

    /// The normalised weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The largest log-likelihood of a particle that still has weight (NaN ones left
    /// out); −∞ when there is none.
    fn top_log_lik(&self) -> f64 {
        self.log_lik
            .iter()
            .zip(&self.weights)
            .filter(|(l, w)| **w > 0.0 && !l.is_nan())
            .map(|(l, _)| *l)
            .fold(f64::NEG_INFINITY, f64::max)
    }

    fn get(&self, i: usize) -> SVector<f64, N> {
        SVector::<f64, N>::from_fn(|k, _| self.cols[k * self.n + i])
    }

    fn set(&mut self, i: usize, x: &SVector<f64, N>) {
        for k in 0..N {
            self.cols[k * self.n + i] = x[k];
        }
    }
}

/// A measurement whose log-likelihood can be evaluated over the particle columns at once.
pub trait SoaLikelihood<const N: usize> {
    /// Adds `log p(z | x_i)` (up to a constant common to all particles) to `out[i]` for
    /// the `n = out.len()` particles whose component `k` is `cols[k·n + i]`.
    fn add_log_likelihood(&self, cols: &[f64], out: &mut [f64]);
}

/// What one weight update did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PfUpdate {
    /// The effective sample size after weighting, before any resampling.
    pub n_eff: f64,
    /// True when the update resampled.
    pub resampled: bool,
    /// True when no particle had a usable weight; the weights were reset to uniform.
    pub degenerate: bool,
}

impl PfUpdate {
    /// An update no particle survived: every weight underflowed (reset to uniform).
    const DEGENERATE: Self = Self {
        n_eff: 0.0,
        resampled: false,
        degenerate: true,
    };
}

/// The clock states a Rao-Blackwellised filter carries in closed form: one Kalman filter
/// per particle, whose mean is the particle's clock column and whose variance is common
/// to every particle (it depends only on the ranges' σ, not on the particle's position).
#[derive(Clone, Debug, PartialEq)]
struct RbClocks {
    /// The clock column of each system in [`System::ALL`] order.
    cols: [Option<usize>; System::COUNT],
    /// The Kalman variance (m²) of each system's clock; infinite for a flat prior (a clock
    /// not yet seen), zero for a known one.
    var_m2: [f64; System::COUNT],
}

impl RbClocks {
    /// The time update of the clocks' Kalman filters: each variance grows by its clock's
    /// process noise `Q_kk` (the means do not move: the clocks are random walks in the
    /// paper models). A flat prior stays flat.
    fn predict<const N: usize>(&mut self, q: &SMatrix<f64, N, N>) {
        for (var, col) in self.var_m2.iter_mut().zip(&self.cols) {
            if let Some(k) = *col {
                *var += q[(k, k)].max(0.0);
            }
        }
    }
}

/// The motion states a marginalised filter carries in closed form: the components that
/// are neither sampled nor clocks. Their Kalman covariance is common to every particle,
/// because neither the model (linear, with state-independent noise) nor the conditioning
/// on each particle's own sampled positions depends on the particle's values.
#[derive(Clone, Debug, PartialEq)]
struct MarginalMotion<const N: usize> {
    /// The Kalman-carried motion components.
    linear: [bool; N],
    /// Their covariance, zero outside the `linear` block.
    p: SMatrix<f64, N, N>,
}

/// A lower-triangular factor of a joint Gaussian over the sampled components `s` and the
/// Kalman-carried ones `l`, in the order `[s, l]`:
///
/// ```text
/// Σ = [[Σ_ss, Σ_sl], [Σ_ls, Σ_ll]] = L Lᵀ,   L = [[L_ss, 0], [L_ls, L_ll]]
/// x_s = μ_s + L_ss ε,   E[x_l | x_s] = μ_l + L_ls ε,   Cov[x_l | x_s] = L_ll L_llᵀ
/// ```
///
/// i.e. the draw of the sampled part and the conditional mean of the rest share one `ε`,
/// and the conditional covariance needs no inverse of `Σ_ss` (which is singular where a
/// position has no noise of its own, as in seed 001's x axis and seed 003's model). The
/// factor tolerates zero pivots ([`psd_factor`]): a sampled direction with no variance
/// then neither moves nor informs the rest.
struct JointFactor<const N: usize> {
    l: SMatrix<f64, N, N>,
    /// `perm[i]`: the state component at position `i` of the `[s, l]` order.
    perm: [usize; N],
    n_s: usize,
    n_l: usize,
}

impl<const N: usize> JointFactor<N> {
    fn new(
        sigma: &SMatrix<f64, N, N>,
        sampled: &[bool; N],
        linear: &[bool; N],
    ) -> Result<Self, ParticleError> {
        let mut perm = [0usize; N];
        let mut n = 0;
        for (k, _) in sampled.iter().enumerate().filter(|(_, s)| **s) {
            perm[n] = k;
            n += 1;
        }
        let n_s = n;
        for (k, _) in linear.iter().enumerate().filter(|(_, l)| **l) {
            perm[n] = k;
            n += 1;
        }
        let n_l = n - n_s;
        let sym = (sigma + sigma.transpose()) * 0.5;
        let permuted = SMatrix::<f64, N, N>::from_fn(|i, j| {
            if i < n && j < n {
                sym[(perm[i], perm[j])]
            } else {
                0.0
            }
        });
        Ok(Self {
            l: psd_factor(&permuted)?,
            perm,
            n_s,
            n_l,
        })
    }

    /// Adds `L_ss ε` to the sampled components of `x` and `L_ls ε` to the Kalman means.
    fn draw<R: Rng + ?Sized>(&self, x: &mut SVector<f64, N>, rng: &mut R) {
        let mut eps = [0.0f64; N];
        for e in eps.iter_mut().take(self.n_s) {
            *e = rng.sample(StandardNormal);
        }
        for i in 0..self.n_s + self.n_l {
            let dx: f64 = (0..self.n_s.min(i + 1))
                .map(|j| self.l[(i, j)] * eps[j])
                .sum();
            x[self.perm[i]] += dx;
        }
    }

    /// `L_ll L_llᵀ` in the state's own indexing (zero outside the Kalman block).
    fn conditional_covariance(&self) -> SMatrix<f64, N, N> {
        let (a, b) = (self.n_s, self.n_s + self.n_l);
        let mut p = SMatrix::<f64, N, N>::zeros();
        for i in a..b {
            for j in a..=i {
                let v: f64 = (a..=j).map(|k| self.l[(i, k)] * self.l[(j, k)]).sum();
                p[(self.perm[i], self.perm[j])] = v;
                p[(self.perm[j], self.perm[i])] = v;
            }
        }
        p
    }
}

/// The most ranges an epoch may have for the linearised proposal
/// ([`ParticleFilter::update_linearised`]); beyond, the bootstrap epoch runs.
pub const MAX_PROPOSAL_ROWS: usize = 12;

/// How the Gaussian particle filter estimates the covariance of its Gaussian from the
/// weighted cloud ([`ParticleFilter::with_covariance_estimate`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CovarianceEstimate {
    /// `Σ w_i (x_i − μ)(x_i − μ)ᵀ` with normalised weights, as Kotecha & Djurić 2003 write
    /// the GPF's measurement update. Its expectation is `(1 − Σ w_i²) Σ`.
    Weighted,
    /// The same divided by `1 − Σ w_i²`, the unbiased estimator for normalised weights
    /// (with uniform weights, the sample covariance with `N − 1`).
    Unbiased,
}

/// The particle-filter family (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleFilter<const N: usize> {
    buf: ParticleBuffer<N>,
    resampling: Resampling,
    neff_threshold: f64,
    variant: PfVariant,
    /// The components drawn by sampling (false: carried by the per-particle Kalman filter).
    sampled: [bool; N],
    rb: Option<RbClocks>,
    mm: Option<MarginalMotion<N>>,
    kernel: KernelPlacement,
    /// The components the process model holds constant (see
    /// [`KernelPlacement::ShrunkStatic`]).
    static_cols: [bool; N],
    /// The Gaussian filter's exact predicted moments `(μ̄, Σ̄)`, kept from
    /// [`Self::predict`] for a linearised importance function
    /// ([`Self::update_linearised`]) until the cloud is weighted or changed from outside.
    predicted: Option<(SVector<f64, N>, SMatrix<f64, N, N>)>,
    /// The Gaussian filter's covariance estimator.
    covariance: CovarianceEstimate,
    /// The regularised filter with the linearised proposal: the kernel covariance
    /// `h² D Dᵀ` of its last resampling (moved through the process model by
    /// [`Self::propagate`]), which the next proposal conditions on the epoch's ranges
    /// together with `Q` instead of jittering the resampled cloud blindly.
    deferred_kernel: Option<SMatrix<f64, N, N>>,
    /// During a linearised update of the regularised filter: the proposal's conditional
    /// covariance `Σ` (sampled components), the within-component part of the posterior
    /// mixture whose component means are the buffer's `centres`.
    centred: Option<SMatrix<f64, N, N>>,
    /// The regularised filter with the prior proposal: bring each epoch's likelihood in
    /// by progressive correction ([`Self::with_progressive_correction`]).
    progressive: bool,
    /// A Rao-Blackwellised filter's per-particle range sums for the stages of a
    /// progressive correction, allocated when both are configured.
    stage: Option<StageSums>,
}

/// The sums a Rao-Blackwellised stage needs per particle (see
/// [`ParticleFilter::with_progressive_correction`]): for each system's clock the
/// residual sums `A_is = Σ_j r_ij / σ_j²`, `B_is = Σ_j r_ij² / σ_j²` at the clock's prior
/// mean, and the plain log-likelihood of the ranges whose clock is sampled.
#[derive(Clone, Debug, PartialEq)]
struct StageSums {
    /// `A` of system `s`, particle `i` at `s·n + i`.
    a: Vec<f64>,
    /// `B`, laid out as `a`.
    b: Vec<f64>,
    plain: Vec<f64>,
    /// `Σ_j 1/σ_j²` of each system's ranges.
    w_sum: [f64; System::COUNT],
}

/// The effective sample size each stage of a progressive correction keeps, as a fraction
/// of `N`: the stage's exponent is the largest that leaves the tempered weights this
/// many effective particles (Jasra, Stephens, Doucet & Tsagaris 2011 choose their
/// tempering steps by the same rule; ½ is the resampling threshold most filters use).
pub const PROGRESSIVE_STAGE_NEFF: f64 = 0.5;

/// The most stages a progressive correction takes in one update; the last takes whatever
/// exponent is left. Each stage costs one likelihood evaluation and one resampling.
pub const PROGRESSIVE_MAX_STAGES: usize = 8;

impl<const N: usize> ParticleFilter<N> {
    /// A SIR filter over the particles of `buf`, resampling with `resampling` when `N_eff`
    /// falls below `neff_threshold · N` (seed 001 resamples below a fixed count; ½ of `N`
    /// is the common choice; 1 resamples every step, 0 never).
    ///
    /// # Errors
    /// When the threshold is outside [0, 1].
    pub fn new(
        buf: ParticleBuffer<N>,
        resampling: Resampling,
        neff_threshold: f64,
    ) -> Result<Self, ParticleError> {
        if !(0.0..=1.0).contains(&neff_threshold) {
            return Err(ParticleError::InvalidParameter(format!(
                "N_eff threshold {neff_threshold}: expected a fraction in [0, 1]"
            )));
        }
        Ok(Self {
            buf,
            resampling,
            neff_threshold,
            variant: PfVariant::Sir,
            sampled: [true; N],
            rb: None,
            mm: None,
            kernel: KernelPlacement::Shrunk,
            static_cols: [false; N],
            predicted: None,
            covariance: CovarianceEstimate::Weighted,
            deferred_kernel: None,
            centred: None,
            progressive: false,
            stage: None,
        })
    }

    /// The regularised filter: every resampling is followed by the kernel jitter.
    pub fn regularised(mut self) -> Self {
        self.variant = PfVariant::Regularised;
        self
    }

    /// The Gaussian particle filter of Kotecha & Djurić, "Gaussian particle filtering",
    /// *IEEE Trans. SP* 51(10), 2003 (§III, Algorithms 1–2). The posterior at each
    /// epoch is represented by the Gaussian `N(μ, Σ)` of the weighted cloud's moments,
    /// and nothing is ever resampled:
    ///
    /// ```text
    /// time update:         μ̄ = F μ,   Σ̄ = F Σ Fᵀ + Q                      (exact, see below)
    /// measurement update:  x_i ~ N(μ̄, Σ̄),   w_i ∝ p(z | x_i),   Σ w_i = 1
    ///                      μ = Σ w_i x_i,   Σ = Σ w_i (x_i − μ)(x_i − μ)ᵀ
    /// ```
    ///
    /// Kotecha & Djurić's time update draws `x_i ~ N(μ, Σ)`, moves each through the
    /// process model with its noise and takes the sample moments; for a process model
    /// that is linear in the state with additive, state-independent Gaussian noise (every
    /// model of [`crate::fusion::models`] the paper worlds run: Singer, the plane turning
    /// model, the clock random walks) those moments converge to `f(μ)` and `F Σ Fᵀ + Q`,
    /// so they are computed exactly here and the Monte Carlo error of that step is
    /// removed at no cost (with a nonlinear `f` this member would be the EKF-linearised
    /// time update followed by the GPF's measurement update). The draw from `N(μ̄, Σ̄)`
    /// (importance function = the predicted Gaussian) happens at the end of
    /// [`Self::predict`], so [`Self::update_ranges`] and [`Self::update`] only weight the
    /// cloud: several updates in one epoch multiply the weights, which is the joint
    /// update. `Σ̄` is factored by the zero-pivot-tolerant Cholesky (`psd_factor`), as
    /// the singular covariances of these models need (seed 001's noise-free x axis,
    /// seed 003's noise-free positions, known clocks).
    ///
    /// All components are sampled: the model is all-Gaussian, so there is nothing for a
    /// per-particle Kalman part to carry that the Gaussian does not carry already.
    pub fn gaussian(mut self) -> Self {
        self.variant = PfVariant::Gaussian;
        self
    }

    /// Estimates the Gaussian filter's covariance with `estimate` (default
    /// [`CovarianceEstimate::Weighted`]); the other members carry no moment estimate of
    /// their own and ignore it. Why it matters: with uniform weights the weighted estimate
    /// has expectation `(1 − 1/N) Σ`, and the recursion feeds it back, so on a state
    /// without process noise or measurements the expected covariance after k epochs is
    /// `(1 − 1/N)^k Σ` (0.36 Σ after 20 epochs of 20 particles); the unbiased one keeps `Σ`.
    pub fn with_covariance_estimate(mut self, estimate: CovarianceEstimate) -> Self {
        self.covariance = estimate;
        self
    }

    /// Brings each epoch's likelihood into the regularised filter by progressive
    /// correction (Oudjane & Musso, "Progressive correction for regularized particle
    /// filters", *FUSION 2000*; Musso, Oudjane & Le Gland 2001, §12.4.2): the likelihood
    /// `p(z|x)` is split into factors `p(z|x)^{λ_1} ⋯ p(z|x)^{λ_k}`, `Σ λ_j = 1`, and
    /// after each factor but the last the cloud is resampled and jittered by the kernel,
    ///
    /// ```text
    /// w_i ← w_i · p(z | x_i)^{λ_j}   (normalised),   λ_j the largest ≤ 1 − Σ_{l<j} λ_l
    ///                                               with N_eff(w) ≥ ½ N,
    /// resample, kernel jitter, re-evaluate p(z | x_i) at the moved particles,
    /// ```
    ///
    /// so that a likelihood much narrower than the cloud (an outlier, the first epochs,
    /// a cloud that drifted) moves the particles towards it in steps instead of leaving
    /// the whole epoch's weight on a few of them. An epoch whose full likelihood keeps
    /// `N_eff ≥ ½ N` is the single update it was, bit for bit.
    ///
    /// The Rao-Blackwellised member splits its clocks' Kalman update the same way: a
    /// Gaussian likelihood to the power `Λ` is the likelihood of noise `R/Λ`, so after
    /// the stages up to `Λ = Σ_{l≤j} λ_l` each particle's clock posterior is the Kalman
    /// update of its prior `N(m_i, v)` with `R/Λ`, and its weight is the clocks'
    /// marginal likelihood at that noise,
    ///
    /// ```text
    /// log p_Λ(z | x_i) = −½ (Λ B_i − Λ² A_i² / (1/v + Λ W)) + const,
    /// A_i = Σ_j (z_j − ρ_j(x_i) − m_i)/σ_j²,   B_i = Σ_j (z_j − ρ_j(x_i) − m_i)²/σ_j²,   W = Σ_j 1/σ_j²
    /// ```
    ///
    /// (per system), so stage `j` weights by `log p_{Λ_j} − log p_{Λ_{j−1}}` at the moved
    /// particles and the last applies the whole update, `m_i ← m_i + A_i/(1/v + W)`. The
    /// prior means travel with their particles through the intermediate resamplings.
    /// Only the regularised and Rao-Blackwellised members with the prior proposal use
    /// it (the linearised proposal already conditions on the ranges); the others ignore it.
    pub fn with_progressive_correction(mut self, on: bool) -> Self {
        self.progressive = on;
        self.plan_stage_sums();
        self
    }

    /// Allocates the Rao-Blackwellised stage sums once both the Kalman clocks and the
    /// progressive correction are configured (whichever builder comes second).
    fn plan_stage_sums(&mut self) {
        if self.progressive && self.rb.is_some() && self.stage.is_none() {
            let n = self.buf.n;
            self.stage = Some(StageSums {
                a: vec![0.0; System::COUNT * n],
                b: vec![0.0; System::COUNT * n],
                plain: vec![0.0; n],
                w_sum: [0.0; System::COUNT],
            });
        }
    }

    /// Places the regularisation kernel as `kernel` (default [`KernelPlacement::Shrunk`]).
    pub fn with_kernel(mut self, kernel: KernelPlacement) -> Self {
        self.kernel = kernel;
        self
    }

    /// Marks the components the process model holds constant (identity transition, no
    /// process noise): the static parameters that [`KernelPlacement::ShrunkStatic`]
    /// shrinks.
    pub fn with_static_components(mut self, static_cols: [bool; N]) -> Self {
        self.static_cols = static_cols;
        self
    }

    /// The Rao-Blackwellised filter: the clock of system `s` (column `clock_cols[s]`) is
    /// carried by a Kalman filter per particle, with a flat prior until
    /// [`Self::set_clock_prior`] says otherwise; the other components are sampled and
    /// regularised.
    ///
    /// # Errors
    /// A clock column outside the state.
    pub fn rao_blackwellised(
        mut self,
        clock_cols: [Option<usize>; System::COUNT],
    ) -> Result<Self, ParticleError> {
        if clock_cols.iter().flatten().any(|&k| k >= N) {
            return Err(ParticleError::InvalidParameter(format!(
                "a clock column is outside the {N}-state"
            )));
        }
        let mut seen = [false; N];
        for &k in clock_cols.iter().flatten() {
            if std::mem::replace(&mut seen[k], true) {
                return Err(ParticleError::InvalidParameter(format!(
                    "state {k} is the clock of two systems: each needs its own column"
                )));
            }
        }
        for &k in clock_cols.iter().flatten() {
            self.sampled[k] = false;
        }
        self.variant = PfVariant::RaoBlackwellised;
        self.rb = Some(RbClocks {
            cols: clock_cols,
            var_m2: [f64::INFINITY; System::COUNT],
        });
        self.plan_stage_sums();
        Ok(self)
    }

    /// The marginalised filter (Schön, Gustafsson & Nordlund, "Marginalized particle
    /// filters for mixed linear/nonlinear state-space models", *IEEE Trans. SP* 53(7),
    /// 2005, §III–IV): only the position components `pos_cols` are sampled; the clocks
    /// are carried as in [`Self::rao_blackwellised`], and every other component (the
    /// velocities and accelerations, which the ranges do not see and the model moves
    /// linearly) by a Kalman filter per particle whose mean is the particle's column and
    /// whose covariance `P` is common. With a linear model `F`, `Q` and the particle's
    /// conditional Gaussian over `[s, l]` (sampled, linear), one epoch's prediction is
    ///
    /// ```text
    /// μ_i = F [s_i; m_i],   Σ = F_{·l} P F_{·l}ᵀ + Q            (the predictive joint)
    /// s_i ← μ_i,s + L_ss ε_i,   m_i ← μ_i,l + L_ls ε_i,   P ← L_ll L_llᵀ
    /// ```
    ///
    /// (`Σ = L Lᵀ` over `[s, l]`, see `JointFactor`): the new positions are drawn from
    /// their marginal prediction, which carries the velocity's uncertainty, and the
    /// velocity's Kalman filter is conditioned on them — Schön et al.'s time update, with
    /// the correlation of the position and velocity noises handled by the joint factor
    /// instead of their decorrelation step. The draw is from the marginal transition, so
    /// the weights are unchanged; the ranges then weight the particles as in the
    /// Rao-Blackwellised filter and leave `P` alone. Resampling is plain (the cloud
    /// regains its spread from `P` at the next draw); the model must be linear in the
    /// Kalman-carried components (its Jacobian is taken at the cloud's mean).
    ///
    /// # Errors
    /// A position or clock column outside the state, or a column named twice.
    pub fn marginalised(
        self,
        pos_cols: [Option<usize>; 3],
        clock_cols: [Option<usize>; System::COUNT],
    ) -> Result<Self, ParticleError> {
        let mut pf = self.rao_blackwellised(clock_cols)?;
        let mut is_pos = [false; N];
        for &k in pos_cols.iter().flatten() {
            if k >= N || clock_cols.contains(&Some(k)) || std::mem::replace(&mut is_pos[k], true) {
                return Err(ParticleError::InvalidParameter(format!(
                    "position column {k}: expected a distinct non-clock column of the {N}-state"
                )));
            }
        }
        if !is_pos.iter().any(|p| *p) {
            return Err(ParticleError::InvalidParameter(
                "a marginalised filter samples the positions: none was given".into(),
            ));
        }
        let linear = std::array::from_fn(|k| pf.sampled[k] && !is_pos[k]);
        pf.sampled = is_pos;
        pf.variant = PfVariant::Marginalised;
        pf.mm = Some(MarginalMotion {
            linear,
            p: SMatrix::zeros(),
        });
        Ok(pf)
    }

    /// True when the clocks are carried by the per-particle Kalman filters (their priors
    /// are then [`Self::set_clock_prior`]'s, not drawn).
    pub fn clocks_in_closed_form(&self) -> bool {
        self.rb.is_some()
    }

    /// Sets the Kalman prior of system `s`'s clock on every particle: mean `mean_m`,
    /// variance `var_m2` (0: known; infinite: flat). No effect on a filter that is not
    /// Rao-Blackwellised or a system without a clock column.
    pub fn set_clock_prior(&mut self, s: usize, mean_m: f64, var_m2: f64) {
        if let Some(rb) = &mut self.rb {
            if let Some(k) = rb.cols.get(s).copied().flatten() {
                rb.var_m2[s] = var_m2;
                self.buf.column_mut(k).fill(mean_m);
            }
        }
    }

    /// Which member of the family this is.
    pub fn variant(&self) -> PfVariant {
        self.variant
    }

    /// Gives the particle storage back.
    pub fn into_buffer(self) -> ParticleBuffer<N> {
        self.buf
    }

    /// The particles.
    pub fn particles(&self) -> &ParticleBuffer<N> {
        &self.buf
    }

    /// The particles, writable. A Gaussian filter's kept prediction is dropped: its
    /// next linearised update takes the moments of the cloud as changed.
    pub fn particles_mut(&mut self) -> &mut ParticleBuffer<N> {
        self.predicted = None;
        &mut self.buf
    }

    /// Draws every particle from `N(mean, cov)` with uniform weights. A component carried
    /// by the Kalman filters (Rao-Blackwellised clocks) is set to its mean instead; its
    /// variance is [`Self::set_clock_prior`]'s.
    ///
    /// # Errors
    /// A non-finite input or a covariance with a negative eigenvalue; the particles are
    /// then unchanged.
    pub fn init_gaussian<R: Rng + ?Sized>(
        &mut self,
        mean: &SVector<f64, N>,
        cov: &SMatrix<f64, N, N>,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        if !mean.iter().all(|v| v.is_finite()) {
            return Err(ParticleError::NonFinite);
        }
        self.predicted = None;
        self.deferred_kernel = None;
        if let Some(mm) = &self.mm {
            // The positions from their marginal, the motion states' Kalman means from
            // their conditional given each particle's positions.
            let joint = JointFactor::new(cov, &self.sampled, &mm.linear)?;
            for i in 0..self.buf.n {
                let mut x = *mean;
                joint.draw(&mut x, rng);
                self.buf.set(i, &x);
            }
            let p = joint.conditional_covariance();
            if let Some(mm) = &mut self.mm {
                mm.p = p;
            }
            self.buf.weights.fill(1.0 / self.buf.n as f64);
            return Ok(());
        }
        let g = psd_factor(&self.mask(cov))?;
        for i in 0..self.buf.n {
            let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
            self.buf.set(i, &(mean + g * w));
        }
        self.buf.weights.fill(1.0 / self.buf.n as f64);
        Ok(())
    }

    /// `m` with the rows and columns of the components that are not sampled set to zero.
    fn mask(&self, m: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
        SMatrix::<f64, N, N>::from_fn(|i, j| {
            if self.sampled[i] && self.sampled[j] {
                m[(i, j)]
            } else {
                0.0
            }
        })
    }

    /// Moves every particle through `model` over `dt_s` seconds and adds process noise
    /// (to the sampled components; the Kalman-carried clocks' variances grow by their
    /// `Q` instead). The Gaussian filter instead redraws the whole cloud from its
    /// predicted Gaussian ([`Self::gaussian`]).
    ///
    /// # Errors
    /// An invalid interval, a `Q` with a negative eigenvalue or a non-finite particle;
    /// the error means the model is unusable and the caller must reinitialise.
    pub fn predict<P: ProcessModel<N>, R: Rng + ?Sized>(
        &mut self,
        model: &P,
        dt_s: f64,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        if !(dt_s.is_finite() && dt_s >= 0.0) {
            return Err(ParticleError::NonFinite);
        }
        // Q is evaluated at the weighted mean: the models here have state-independent
        // noise, and a per-particle factorisation would cost N³ per particle.
        let mean = self.mean();
        let q = model.q(&mean, dt_s);
        if self.mm.is_some() {
            return self.predict_marginalised(model, &mean, &q, dt_s, rng);
        }
        if self.variant == PfVariant::Gaussian {
            return self.predict_gaussian(model, &mean, &q, dt_s, rng);
        }
        // A kernel left pending by a linearised epoch is drawn blindly here, after the move
        // (for the linear models here, the same as jittering before it).
        let q = match self.deferred_kernel.take() {
            Some(k) => {
                let f = model.jacobian(&mean, dt_s);
                q + f * k * f.transpose()
            }
            None => q,
        };
        let g = psd_factor(&self.mask(&q))?;
        if let Some(rb) = &mut self.rb {
            rb.predict(&q);
        }
        let noisy = g.iter().any(|v| *v != 0.0);
        for i in 0..self.buf.n {
            let mut x = model.f(&self.buf.get(i), dt_s);
            if noisy {
                let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
                x += g * w;
            }
            if !x.iter().all(|v| v.is_finite()) {
                return Err(ParticleError::NonFinite);
            }
            self.buf.set(i, &x);
        }
        Ok(())
    }

    /// The Gaussian particle filter's time update and draw (see [`Self::gaussian`]):
    /// `μ̄ = f(μ)`, `Σ̄ = F Σ Fᵀ + Q` from the weighted cloud's moments, then every
    /// particle `x_i = μ̄ + G ε_i` with `G Gᵀ = Σ̄`, `ε_i ~ N(0, I)`, and uniform weights.
    fn predict_gaussian<P: ProcessModel<N>, R: Rng + ?Sized>(
        &mut self,
        model: &P,
        mean: &SVector<f64, N>,
        q: &SMatrix<f64, N, N>,
        dt_s: f64,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        let f = model.jacobian(mean, dt_s);
        let mu = model.f(mean, dt_s);
        let sigma = f * self.gaussian_covariance() * f.transpose() + q;
        let g = psd_factor(&((sigma + sigma.transpose()) * 0.5))?;
        if !mu.iter().all(|v| v.is_finite()) {
            return Err(ParticleError::NonFinite);
        }
        for i in 0..self.buf.n {
            let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
            self.buf.set(i, &(mu + g * w));
        }
        self.buf.weights.fill(1.0 / self.buf.n as f64);
        self.predicted = Some((mu, sigma));
        Ok(())
    }

    /// The marginalised filter's prediction (see [`Self::marginalised`]).
    fn predict_marginalised<P: ProcessModel<N>, R: Rng + ?Sized>(
        &mut self,
        model: &P,
        mean: &SVector<f64, N>,
        q: &SMatrix<f64, N, N>,
        dt_s: f64,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        let Some(mm) = &self.mm else {
            return Ok(());
        };
        let f = model.jacobian(mean, dt_s);
        let sigma = f * mm.p * f.transpose() + q;
        let joint = JointFactor::new(&sigma, &self.sampled, &mm.linear)?;
        let p = joint.conditional_covariance();
        if let Some(rb) = &mut self.rb {
            rb.predict(q);
        }
        for i in 0..self.buf.n {
            let mut x = model.f(&self.buf.get(i), dt_s);
            joint.draw(&mut x, rng);
            if !x.iter().all(|v| v.is_finite()) {
                return Err(ParticleError::NonFinite);
            }
            self.buf.set(i, &x);
        }
        if let Some(mm) = &mut self.mm {
            mm.p = p;
        }
        Ok(())
    }

    /// Weights the particles by measurement `z` of any `model` (a gather per particle),
    /// then resamples if `N_eff` is below the threshold. Not for a Rao-Blackwellised
    /// filter, whose clocks take ranges only ([`Self::update_ranges`]).
    pub fn update<H: MeasurementModel<N, M>, const M: usize, R: Rng + ?Sized>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
        rng: &mut R,
    ) -> PfUpdate {
        for i in 0..self.buf.n {
            let x = self.buf.get(i);
            self.buf.log_lik[i] = model.log_likelihood(&x, z);
        }
        self.finish_update(rng, false)
    }

    /// Weights the particles by a column-wise likelihood (the fast path), then resamples
    /// if `N_eff` is below the threshold.
    pub fn update_soa<L: SoaLikelihood<N>, R: Rng + ?Sized>(
        &mut self,
        lik: &L,
        rng: &mut R,
    ) -> PfUpdate {
        if self.progressive && self.variant == PfVariant::Regularised {
            return self.update_progressive(lik, rng);
        }
        self.buf.log_lik.fill(0.0);
        lik.add_log_likelihood(&self.buf.cols, &mut self.buf.log_lik);
        self.finish_update(rng, false)
    }

    /// Moves every particle by the noise-free model `f` over `dt_s` (the first half of an
    /// epoch with [`Self::update_linearised`]).
    ///
    /// # Errors
    /// An invalid interval or a non-finite particle.
    pub fn propagate<P: ProcessModel<N>>(
        &mut self,
        model: &P,
        dt_s: f64,
    ) -> Result<(), ParticleError> {
        if !(dt_s.is_finite() && dt_s >= 0.0) {
            return Err(ParticleError::NonFinite);
        }
        if let Some(k) = self.deferred_kernel {
            // The kernel's jitter would have moved through the model with its particle.
            let f = model.jacobian(&self.mean(), dt_s);
            self.deferred_kernel = Some(self.mask(&(f * k * f.transpose())));
        }
        for i in 0..self.buf.n {
            let x = model.f(&self.buf.get(i), dt_s);
            if !x.iter().all(|v| v.is_finite()) {
                return Err(ParticleError::NonFinite);
            }
            self.buf.set(i, &x);
        }
        Ok(())
    }

    /// Adds `N(0, q)` to every particle (sampled components only).
    fn add_noise<R: Rng + ?Sized>(
        &mut self,
        q: &SMatrix<f64, N, N>,
        rng: &mut R,
    ) -> Result<(), ParticleError> {
        let g = psd_factor(&self.mask(q))?;
        if g.iter().all(|v| *v == 0.0) {
            return Ok(());
        }
        for i in 0..self.buf.n {
            let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
            let x = self.buf.get(i) + g * w;
            self.buf.set(i, &x);
        }
        Ok(())
    }

    /// One epoch with the linearised optimal proposal (Doucet, Godsill & Andrieu, "On
    /// sequential Monte Carlo sampling methods for Bayesian filtering", *Statistics and
    /// Computing* 10, 2000, §II.D.2): with additive process noise `Q` and the ranges
    /// linearised at the predicted mean (`H`; the emitters are far from the cloud, so one
    /// `H` serves every particle),
    ///
    /// ```text
    /// S = H Q Hᵀ + R,   K = Q Hᵀ S⁻¹,   Σ = Q − K H Q
    /// x_i ← f(x_i) + K ν_i + chol(Σ) ε_i,   ν_i = z − h(f(x_i))
    /// w_i ← w_i · exp(−½ ν_iᵀ S⁻¹ ν_i)
    /// ```
    ///
    /// i.e. each particle is drawn from the process noise already conditioned on this
    /// epoch's ranges, and weighted by the predictive likelihood of its parent, which is
    /// far flatter than the likelihood itself: few particles then keep a useful N_eff when
    /// the likelihood is peaked against the process noise.
    ///
    /// A Rao-Blackwellised filter integrates its Kalman-carried clocks `c ~ N(c̄_i, P_c)`
    /// out of the proposal: with `E` the ranges' clock columns, `ν_i` taken at the
    /// particle's clock mean `c̄_i` and `S = H Q Hᵀ + E P_c Eᵀ + R`, the sampled states are
    /// drawn as above (the gain reaches them only, `Q` being zero on the clocks); each
    /// particle's clock filter is then updated at its new position, and its marginal
    /// likelihood, already in the predictive weight, is not applied twice. This is the
    /// exact optimal proposal of the linear-Gaussian case, the sampled states' marginal
    /// then the clocks' conditional. Under a clock's flat prior (no range of its system
    /// seen yet) the predictive density is improper and the epoch is a bootstrap one.
    ///
    /// Falls back to the bootstrap epoch ([`Self::predict`] and [`Self::update_ranges`])
    /// for more than [`MAX_PROPOSAL_ROWS`] ranges. The epoch is split in two: the
    /// caller first moves the cloud by the noise-free model ([`Self::propagate`]), then
    /// calls this with the interval's `Q`.
    ///
    /// # Errors
    /// A `Σ` with a negative eigenvalue or a non-finite particle.
    pub fn update_linearised<R: Rng + ?Sized>(
        &mut self,
        q: &SMatrix<f64, N, N>,
        lik: &PseudorangeLikelihood,
        rng: &mut R,
    ) -> Result<PfUpdate, ParticleError> {
        let m = lik.rows.len();
        if self.mm.is_some() {
            return Err(ParticleError::InvalidParameter(
                "the linearised proposal is for the resampling and Gaussian filters, not the marginalised one"
                    .into(),
            ));
        }
        // A Kalman-carried clock's variance grows by its own process noise, as in
        // `predict`; the proposal moves only the sampled components.
        if let Some(rb) = &mut self.rb {
            rb.predict(q);
        }
        // The process noise, and the kernel of the last resampling where one is pending.
        let q = self.mask(q) + self.deferred_kernel.take().unwrap_or_else(SMatrix::zeros);
        let bootstrap = |pf: &mut Self, rng: &mut R| -> Result<PfUpdate, ParticleError> {
            pf.add_noise(&q, rng)?;
            Ok(pf.update_ranges(lik, rng))
        };
        if m == 0 || m > MAX_PROPOSAL_ROWS {
            return bootstrap(self, rng);
        }
        if self.variant == PfVariant::Gaussian {
            return self.update_gaussian_linearised(lik, rng);
        }
        let mean = self.mean();
        let Some(h) = range_linearisation::<N>(lik, &mean) else {
            return bootstrap(self, rng);
        };
        // A Kalman-carried clock adds its variance to the predictive covariance of every
        // range it biases (`E P_c Eᵀ`); under a flat prior (no range of its system seen
        // yet) the predictive density is improper, and the epoch is a bootstrap one.
        let mut clock_cov = SMatrix::<f64, N, N>::zeros();
        if let Some(rb) = &self.rb {
            for (s, col) in rb.cols.iter().enumerate() {
                let Some(k) = *col else { continue };
                if !lik.rows.iter().any(|r| r.clock_col == Some(k)) {
                    continue;
                }
                if !rb.var_m2[s].is_finite() {
                    return bootstrap(self, rng);
                }
                clock_cov[(k, k)] = rb.var_m2[s];
            }
        }
        let mut s = h * (q + clock_cov) * h.transpose();
        for (j, r) in lik.rows.iter().enumerate() {
            s[(j, j)] += -0.5 / r.neg_half_inv_var;
        }
        // The unused rows are an identity block, so that S stays invertible.
        for j in m..MAX_PROPOSAL_ROWS {
            s[(j, j)] = 1.0;
        }
        let Some(chol) = s.cholesky() else {
            return bootstrap(self, rng);
        };
        let s_inv = chol.inverse();
        let gain = q * h.transpose() * s_inv;
        let sigma = q - gain * h * q;
        let g = psd_factor(&((sigma + sigma.transpose()) * 0.5))?;
        let noisy = g.iter().any(|v| *v != 0.0);
        for i in 0..self.buf.n {
            let x = self.buf.get(i);
            let nu = range_residuals(lik, &x);
            let mut y = x + gain * nu;
            for k in 0..N {
                self.buf.centres[k * self.buf.n + i] = y[k];
            }
            if noisy {
                let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
                y += g * w;
            }
            if !y.iter().all(|v| v.is_finite()) {
                return Err(ParticleError::NonFinite);
            }
            self.buf.set(i, &y);
            self.buf.log_lik[i] = -0.5 * nu.dot(&(s_inv * nu));
        }
        // The clocks' Kalman update at each particle's new position. Its marginal
        // likelihood is already in the weight (the predictive density above integrates
        // the clocks out), so the proposal's log-weights are kept aside meanwhile.
        if let Some(rb) = &mut self.rb {
            let b = &mut self.buf;
            b.scratch.copy_from_slice(&b.log_lik);
            b.log_lik.fill(0.0);
            rb_update::<N>(rb, lik, &mut b.cols, &mut b.log_lik);
            b.log_lik.copy_from_slice(&b.scratch);
        }
        // The weights depend on the centres alone, so the resampling's kernel takes the
        // posterior mixture's moments from them and `Σ` (`resample_and_kernel`).
        self.centred = Some(self.mask(&((sigma + sigma.transpose()) * 0.5)));
        let update = self.finish_update(rng, true);
        self.centred = None;
        Ok(update)
    }

    /// The Gaussian filter's measurement update with the linearised importance function:
    /// Kotecha & Djurić's GPF leaves the importance function `π` free (their examples draw
    /// from the prediction); this one is the EKF update of the predicted Gaussian, the
    /// local linearisation of the optimal importance function (Doucet, Godsill & Andrieu
    /// 2000, §II.D.2) applied to the GPF's Gaussian. With the ranges linearised at the
    /// predicted mean, `h(x) ≈ h(μ̄) + H (x − μ̄)`,
    ///
    /// ```text
    /// S = H Σ̄ Hᵀ + R,   K = Σ̄ Hᵀ S⁻¹
    /// π = N(μ̄ + K (z − h(μ̄)),  (I − K H) Σ̄ (I − K H)ᵀ + K R Kᵀ)
    /// x_i ~ π,   w_i ∝ p(z | x_i) N(x_i; μ̄, Σ̄) / π(x_i) = p(z | x_i) / p_lin(z | x_i) · const
    /// ```
    ///
    /// The last identity holds because `N(x; μ̄, Σ̄) p_lin(z | x) = π(x) N(z; h(μ̄), S)` for
    /// the linearised likelihood `p_lin(z | x) = N(z; h(μ̄) + H (x − μ̄), R)`: the weights
    /// then need no density of the (often singular) `Σ̄`, and they are uniform when the
    /// ranges are linear, so every particle counts. `(μ̄, Σ̄)` are the exact predicted
    /// moments kept by [`Self::predict`], or the weighted cloud's moments when the cloud
    /// was changed or weighted since.
    fn update_gaussian_linearised<R: Rng + ?Sized>(
        &mut self,
        lik: &PseudorangeLikelihood,
        rng: &mut R,
    ) -> Result<PfUpdate, ParticleError> {
        let (mu, sigma) = match self.predicted.take() {
            Some(pred) => pred,
            None => (self.mean(), self.gaussian_covariance()),
        };
        let m = lik.rows.len();
        let Some(h) = range_linearisation::<N>(lik, &mu) else {
            return Ok(self.update_ranges(lik, rng));
        };
        let mut r = SMatrix::<f64, MAX_PROPOSAL_ROWS, MAX_PROPOSAL_ROWS>::zeros();
        for (j, row) in lik.rows.iter().enumerate() {
            r[(j, j)] = -0.5 / row.neg_half_inv_var;
        }
        let mut s = h * sigma * h.transpose() + r;
        // The unused rows are an identity block, so that S stays invertible.
        for j in m..MAX_PROPOSAL_ROWS {
            s[(j, j)] = 1.0;
        }
        let Some(chol) = s.cholesky() else {
            return Ok(self.update_ranges(lik, rng));
        };
        let gain = sigma * h.transpose() * chol.inverse();
        let nu0 = range_residuals(lik, &mu);
        let mean = mu + gain * nu0;
        let i_kh = SMatrix::<f64, N, N>::identity() - gain * h;
        let cov = i_kh * sigma * i_kh.transpose() + gain * r * gain.transpose();
        let g = psd_factor(&((cov + cov.transpose()) * 0.5))?;
        if !mean.iter().all(|v| v.is_finite()) {
            return Err(ParticleError::NonFinite);
        }
        for i in 0..self.buf.n {
            let w = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
            let x = mean + g * w;
            self.buf.set(i, &x);
            // log p(z | x) − log p_lin(z | x): the exact residual against the linear one.
            let nu = range_residuals(lik, &x);
            let nu_lin = nu0 - h * (x - mu);
            let mut log_w = 0.0;
            for (j, row) in lik.rows.iter().enumerate() {
                log_w += row.neg_half_inv_var * (nu[j] * nu[j] - nu_lin[j] * nu_lin[j]);
            }
            self.buf.log_lik[i] = log_w;
        }
        self.buf.weights.fill(1.0 / self.buf.n as f64);
        Ok(self.finish_update(rng, false))
    }

    /// Weights the particles by an epoch's pseudoranges: the column-wise likelihood, or
    /// for a Rao-Blackwellised filter the clocks' marginal likelihood and Kalman update
    /// (see the module documentation); then resamples if `N_eff` is below the threshold.
    pub fn update_ranges<R: Rng + ?Sized>(
        &mut self,
        lik: &PseudorangeLikelihood,
        rng: &mut R,
    ) -> PfUpdate {
        if self.progressive && self.variant == PfVariant::Regularised {
            return self.update_progressive(lik, rng);
        }
        if self.progressive && self.stage.is_some() {
            return self.update_progressive_rb(lik, rng);
        }
        self.buf.log_lik.fill(0.0);
        match &mut self.rb {
            Some(rb) => rb_update::<N>(rb, lik, &mut self.buf.cols, &mut self.buf.log_lik),
            None => {
                SoaLikelihood::<N>::add_log_likelihood(lik, &self.buf.cols, &mut self.buf.log_lik)
            }
        }
        self.finish_update(rng, false)
    }

    /// The progressive correction of [`Self::with_progressive_correction`] for a
    /// column-wise likelihood.
    fn update_progressive<L: SoaLikelihood<N>, R: Rng + ?Sized>(
        &mut self,
        lik: &L,
        rng: &mut R,
    ) -> PfUpdate {
        let mut remaining = 1.0;
        for stage in 0..PROGRESSIVE_MAX_STAGES {
            self.buf.log_lik.fill(0.0);
            lik.add_log_likelihood(&self.buf.cols, &mut self.buf.log_lik);
            let lambda = if stage + 1 == PROGRESSIVE_MAX_STAGES {
                remaining
            } else {
                self.tempering_exponent(remaining, PROGRESSIVE_STAGE_NEFF)
            };
            if lambda >= remaining {
                for l in &mut self.buf.log_lik {
                    *l *= remaining;
                }
                return self.finish_update(rng, false);
            }
            for l in &mut self.buf.log_lik {
                *l *= lambda;
            }
            remaining -= lambda;
            if !self.between_stages(rng) {
                return PfUpdate::DEGENERATE;
            }
        }
        // Unreachable: the last stage takes the rest.
        self.finish_update(rng, false)
    }

    /// Between two stages of a progressive correction: the weights of the stages so far,
    /// then a resampling and the kernel; false when no particle keeps a weight.
    fn between_stages<R: Rng + ?Sized>(&mut self, rng: &mut R) -> bool {
        if self.reweight().is_none() {
            return false;
        }
        self.resample_regularised(rng);
        true
    }

    /// The progressive correction of a Rao-Blackwellised filter (see
    /// [`Self::with_progressive_correction`]).
    fn update_progressive_rb<R: Rng + ?Sized>(
        &mut self,
        lik: &PseudorangeLikelihood,
        rng: &mut R,
    ) -> PfUpdate {
        let mut done = 0.0;
        for stage in 0..PROGRESSIVE_MAX_STAGES {
            if !self.stage_sums(lik) {
                self.buf.log_lik.fill(f64::NAN);
                return self.finish_update(rng, false);
            }
            let lambda = if stage + 1 == PROGRESSIVE_MAX_STAGES {
                1.0 - done
            } else {
                self.rb_tempering_exponent(done, PROGRESSIVE_STAGE_NEFF)
            };
            if stage == 0 && lambda >= 1.0 {
                // The whole likelihood keeps enough particles: the single update.
                self.buf.log_lik.fill(0.0);
                if let Some(rb) = &mut self.rb {
                    rb_update::<N>(rb, lik, &mut self.buf.cols, &mut self.buf.log_lik);
                }
                return self.finish_update(rng, false);
            }
            let last = done + lambda >= 1.0;
            let next = if last { 1.0 } else { done + lambda };
            self.rb_stage_increments(done, next);
            if last {
                self.apply_stage_clock_update();
                return self.finish_update(rng, false);
            }
            done = next;
            if !self.between_stages(rng) {
                return PfUpdate::DEGENERATE;
            }
        }
        // Unreachable: the last stage takes the rest.
        self.finish_update(rng, false)
    }

    /// Fills the stage sums at the particles' positions and prior clock means; false when
    /// the filter has none or the columns are short.
    fn stage_sums(&mut self, lik: &PseudorangeLikelihood) -> bool {
        let (Some(rb), Some(st)) = (&self.rb, &mut self.stage) else {
            return false;
        };
        let n = self.buf.n;
        let cols = &self.buf.cols;
        if cols.len() < N * n {
            return false;
        }
        let marginal = |c: Option<usize>| c.is_some() && rb.cols.contains(&c);
        st.a.fill(0.0);
        st.b.fill(0.0);
        st.plain.fill(0.0);
        st.w_sum = [0.0; System::COUNT];
        for r in &lik.rows {
            for (s, c) in rb.cols.iter().enumerate() {
                if c.is_some() && *c == r.clock_col {
                    st.w_sum[s] += -2.0 * r.neg_half_inv_var;
                }
            }
        }
        let zeros = [0.0; BLOCK];
        let col = |k: Option<usize>| k.filter(|&k| k < N).map(|k| &cols[k * n..(k + 1) * n]);
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            let len = end - start;
            let z3 = &zeros[..len];
            let sub = |k: Option<usize>| col(k).map(|c| &c[start..end]);
            let p = |a: usize| sub(lik.pos_col[a]).unwrap_or(z3);
            let (bx, by, bz) = (p(0), p(1), p(2));
            for r in lik.rows.iter().filter(|r| !marginal(r.clock_col)) {
                range_terms(
                    &mut st.plain[start..end],
                    bx,
                    by,
                    bz,
                    sub(r.clock_col),
                    sub(r.isb_col),
                    r,
                );
            }
            for (s, c) in rb.cols.iter().enumerate() {
                let Some(k) = *c else {
                    continue;
                };
                let m = &cols[k * n + start..k * n + end];
                let (a, b) = (
                    &mut st.a[s * n + start..s * n + end],
                    &mut st.b[s * n + start..s * n + end],
                );
                for r in lik.rows.iter().filter(|r| r.clock_col == Some(k)) {
                    let isb = sub(r.isb_col).unwrap_or(z3);
                    clock_residual_sums(a, b, bx, by, bz, isb, m, r);
                }
            }
            start = end;
        }
        true
    }

    /// `log p_Λ(z | x_i)` of the stage sums (see [`Self::with_progressive_correction`]).
    fn rb_stage_target(&self, i: usize, lambda: f64) -> f64 {
        let (Some(rb), Some(st)) = (&self.rb, &self.stage) else {
            return 0.0;
        };
        if lambda == 0.0 {
            return 0.0;
        }
        let n = self.buf.n;
        let mut t = lambda * st.plain[i];
        for s in 0..System::COUNT {
            if rb.cols[s].is_none() || st.w_sum[s] == 0.0 {
                continue;
            }
            let g = 1.0 / (1.0 / rb.var_m2[s] + lambda * st.w_sum[s]);
            let (a, b) = (st.a[s * n + i], st.b[s * n + i]);
            t += -0.5 * (lambda * b - lambda * lambda * a * a * g);
        }
        t
    }

    /// Sets the log-likelihood buffer to the stage's increments
    /// `log p_to − log p_from` at every particle.
    fn rb_stage_increments(&mut self, from: f64, to: f64) {
        for i in 0..self.buf.n {
            let v = self.rb_stage_target(i, to) - self.rb_stage_target(i, from);
            self.buf.log_lik[i] = v;
        }
    }

    /// The clocks' whole Kalman update from the stage sums (the last stage).
    fn apply_stage_clock_update(&mut self) {
        let n = self.buf.n;
        let (Some(rb), Some(st)) = (&mut self.rb, &self.stage) else {
            return;
        };
        for s in 0..System::COUNT {
            let Some(k) = rb.cols[s] else {
                continue;
            };
            if st.w_sum[s] <= 0.0 {
                continue;
            }
            let gain = 1.0 / (1.0 / rb.var_m2[s] + st.w_sum[s]);
            let m = &mut self.buf.cols[k * n..(k + 1) * n];
            for (mi, a) in m.iter_mut().zip(&st.a[s * n..(s + 1) * n]) {
                *mi += a * gain;
            }
            rb.var_m2[s] = 1.0 / (1.0 / rb.var_m2[s] + st.w_sum[s]);
        }
    }

    /// [`Self::tempering_exponent`] for the Rao-Blackwellised stages: the largest step
    /// `λ ≤ 1 − done` whose increments keep `fraction · N` effective. The increments go
    /// through the log-likelihood buffer.
    fn rb_tempering_exponent(&mut self, done: f64, fraction: f64) -> f64 {
        let target = fraction * self.buf.n as f64;
        bisect_exponent(1.0 - done, target, |lambda| {
            self.rb_stage_increments(done, done + lambda);
            let b = &self.buf;
            tempered_n_eff(&b.weights, |i| b.log_lik[i])
        })
    }

    /// The largest exponent `λ ≤ max` whose tempered weights `w_i p(z|x_i)^λ` (the
    /// log-likelihoods in the buffer) keep an effective sample size of at least
    /// `fraction · N`, by bisection (the size falls from the current weights' as `λ`
    /// grows); `max` itself when it keeps that many. At least a small positive step, so
    /// that the correction always advances.
    fn tempering_exponent(&self, max: f64, fraction: f64) -> f64 {
        let b = &self.buf;
        let top = b.top_log_lik();
        if !top.is_finite() {
            return max;
        }
        let target = fraction * b.n as f64;
        bisect_exponent(max, target, |lambda| {
            tempered_n_eff(&b.weights, |i| lambda * (b.log_lik[i] - top))
        })
    }

    /// Normalises the weights by the log-likelihoods just formed and resamples when
    /// `N_eff` falls below the threshold; `defer_kernel` (a linearised epoch) leaves the
    /// regularised filter's kernel to the next proposal
    /// ([`Self::resample_deferring_kernel`]).
    fn finish_update<R: Rng + ?Sized>(&mut self, rng: &mut R, defer_kernel: bool) -> PfUpdate {
        let Some(n_eff) = self.reweight() else {
            return PfUpdate::DEGENERATE;
        };
        let b = &self.buf;
        // The Gaussian filter never resamples: its next prediction redraws the cloud.
        let resampled =
            self.variant != PfVariant::Gaussian && n_eff < self.neff_threshold * b.n as f64;
        if resampled {
            match self.variant {
                PfVariant::Sir | PfVariant::Marginalised | PfVariant::Gaussian => {
                    self.resample(rng)
                }
                PfVariant::Regularised | PfVariant::RaoBlackwellised if defer_kernel => {
                    self.resample_deferring_kernel(rng)
                }
                PfVariant::Regularised | PfVariant::RaoBlackwellised => {
                    self.resample_regularised(rng)
                }
            }
        }
        PfUpdate {
            n_eff,
            resampled,
            degenerate: false,
        }
    }

    /// Multiplies the weights by the log-likelihoods in the buffer and normalises them;
    /// the effective sample size, or `None` (weights reset to uniform) when no particle
    /// keeps a finite weight.
    fn reweight(&mut self) -> Option<f64> {
        self.predicted = None;
        let b = &mut self.buf;
        let max = b.top_log_lik();
        let mut sum = 0.0;
        if max.is_finite() {
            for (w, l) in b.weights.iter_mut().zip(&b.log_lik) {
                // A NaN log-likelihood is an unusable particle: weight zero.
                let f = if l.is_nan() { 0.0 } else { (l - max).exp() };
                *w *= f;
                sum += *w;
            }
        }
        if !(sum > 0.0 && sum.is_finite()) {
            b.weights.fill(1.0 / b.n as f64);
            return None;
        }
        let inv = 1.0 / sum;
        let mut sq = 0.0;
        for w in &mut b.weights {
            *w *= inv;
            sq += *w * *w;
        }
        Some(1.0 / sq)
    }

    /// The effective sample size `1 / Σ w_i²` of the current weights.
    pub fn n_eff(&self) -> f64 {
        1.0 / self.weight_square_sum()
    }

    /// Resamples now with the configured scheme; the weights become `1/N`.
    pub fn resample<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let b = &mut self.buf;
        let n = b.n;
        match self.resampling {
            Resampling::Systematic | Resampling::Stratified => {
                let stratified = self.resampling == Resampling::Stratified;
                cumulative(&b.weights, &mut b.scratch);
                let u0: f64 = rng.random::<f64>();
                let inv_n = 1.0 / n as f64;
                let mut j = 0;
                for i in 0..n {
                    let u = if stratified {
                        (i as f64 + rng.random::<f64>()) * inv_n
                    } else {
                        (i as f64 + u0) * inv_n
                    };
                    while b.scratch[j] < u {
                        j += 1;
                    }
                    b.idx[i] = j;
                }
            }
            Resampling::Residual => {
                let nf = n as f64;
                let mut filled = 0;
                for (i, w) in b.weights.iter().enumerate() {
                    let copies = ((nf * w).floor() as usize).min(n - filled);
                    b.idx[filled..filled + copies].fill(i);
                    filled += copies;
                }
                let rest = n - filled;
                if rest > 0 {
                    // The residual weights N w_i − ⌊N w_i⌋, unnormalised; the uniforms
                    // are scaled by their total instead.
                    let mut c = 0.0;
                    for (s, w) in b.scratch.iter_mut().zip(&b.weights) {
                        c += nf * w - (nf * w).floor();
                        *s = c;
                    }
                    let total = c;
                    b.scratch[n - 1] = f64::INFINITY;
                    let u0: f64 = rng.random::<f64>();
                    let mut j = 0;
                    for slot in 0..rest {
                        let u = (slot as f64 + u0) / rest as f64 * total;
                        while b.scratch[j] < u {
                            j += 1;
                        }
                        b.idx[filled + slot] = j;
                    }
                }
            }
        }
        for k in 0..N {
            let col = &mut b.cols[k * n..(k + 1) * n];
            b.scratch.copy_from_slice(col);
            for (dst, &src) in col.iter_mut().zip(&b.idx) {
                *dst = b.scratch[src];
            }
        }
        b.weights.fill(1.0 / n as f64);
    }

    /// Resamples, then moves every particle by the regularisation kernel (Musso, Oudjane
    /// & Le Gland, "Improving regularised particle filters", in Doucet, de Freitas &
    /// Gordon (eds.), *Sequential Monte Carlo Methods in Practice*, Springer 2001, ch. 12,
    /// §12.2.3): `x_i ← x_i + h_opt D ε_i`, `ε_i ~ N(0, I)`, where `D Dᵀ` is the weighted
    /// covariance of the sampled components before resampling and
    /// `h_opt = (4 / (N (n + 2)))^{1/(n + 4)}` the bandwidth that minimises the mean
    /// integrated squared error of a Gaussian kernel for a Gaussian density of dimension
    /// `n` (here the rank of the sampled covariance).
    ///
    /// The kernel alone adds `h_opt² D Dᵀ` to the cloud's covariance at every resampling —
    /// with a dozen states `h_opt ≈ 0.6`, so +40 % each time, which compounds into a
    /// loose, inefficient cloud wherever the model has no process noise (seed 003's
    /// constant clocks). With [`KernelPlacement::Shrunk`] (the default) the particles are
    /// therefore first shrunk towards the mean, `x_i ← x̄ + a (x_i − x̄)` with
    /// `a = √(1 − h²)`, so that the jittered cloud keeps the mean and covariance of the
    /// weighted one (Liu & West, "Combined parameter and state estimation in
    /// simulation-based filtering", same book, ch. 10, §10.3.2); with
    /// [`KernelPlacement::Plain`] they are not (`a = 1`), as Musso et al. define the
    /// filter. The inflation is what keeps a cloud of a few dozen particles from
    /// collapsing: resampling loses about `1/N` of the cloud's spread each time, and the
    /// shrunk kernel as stated does not give it back (docs/reproductions.md, seed 001).
    ///
    /// Liu & West's mixture keeps `V`, the posterior covariance; the weighted covariance
    /// `Σ w_i (x_i − x̄)(x_i − x̄)ᵀ` of normalised weights estimates it with expectation
    /// `(1 − Σ w_i²) V` (the reliability-weights correction; as the Gaussian PF's
    /// [`CovarianceEstimate::Unbiased`]). So [`KernelPlacement::Shrunk`] takes
    /// `D Dᵀ = Σ w_i (x_i − x̄)(x_i − x̄)ᵀ / (1 − Σ w_i²)` and
    /// `a = √((1 − h²) / (1 − Σ w_i²))`, which keeps the jittered cloud's covariance at
    /// that estimate (`a²` times the resampled cloud's, about the weighted covariance,
    /// plus `h² D Dᵀ`): an epoch whose weights leave few particles effective is given back
    /// the spread its weighting took, which is what the uncorrected shrinkage lost (seed
    /// 003, 100 particles, the default RPF-100 over seeds 1–5: 1.27–1.65× of the PCRLB
    /// against 1.38–1.87×; docs/reproductions.md, "The unbiased covariance in Liu & West's
    /// kernel"). The placements with Musso's kernel keep the weighted covariance, as
    /// Musso et al. define it.
    ///
    /// Liu & West's kernel density is one of the *weighted* cloud, so its bandwidth takes
    /// that sample's size, Kish's effective sample size `N_eff = 1 / Σ w_i²` (Kish,
    /// *Survey Sampling*, Wiley 1965, §11.7), in place of `N`:
    /// `h = (4 / (N_eff (n + 2)))^{1/(n + 4)}`, capped at 1 (a cloud of one effective
    /// particle is redrawn whole from the Gaussian of its moments). This is how a
    /// weighted sample's Gaussian kernel density is sized elsewhere too (SciPy's
    /// `gaussian_kde` puts its `neff` into Scott's and Silverman's factors). With `N`
    /// the kernel was sized for more information than an unevenly weighted cloud holds,
    /// and at 20–100 particles the cloud grew over-confident (seed 003, the default
    /// RPF-100 over seeds 1–5: 1.22–1.37× of the PCRLB against 1.27–1.65×, seed 001's
    /// RPF-20 at 200 trials 1.26–1.40× against 1.31–1.59×; docs/reproductions.md, "The
    /// kernel sized by the effective sample size"). Musso's placements smooth the `N`
    /// resampled particles and keep `N`, as Musso et al. define their `h_opt`.
    ///
    /// Liu & West's cloud also carries the Monte Carlo error of the estimate it stands
    /// for. The weighted mean misses the posterior mean by an importance-sampling error
    /// of covariance `≈ V / N_eff` (the approximation that defines the effective sample
    /// size: Kong, Liu & Wong, "Sequential imputations and Bayesian missing data
    /// problems", *JASA* 89, 1994), and drawing the `N` new particles from the kernel
    /// mixture, whose covariance is `V` (resampling and jitter together, `N` draws of
    /// it), moves their mean by `V / N` more. Both are errors of the estimate,
    /// independent of the posterior's own spread, so the estimate's error covariance is
    /// `V (1 + 1/N_eff + 1/N)` (the law of total variance), and the kernel adds the two
    /// terms: `h² D Dᵀ` becomes `(h² + 1/N_eff + 1/N) D Dᵀ`. Like a process noise of that
    /// size, the next epochs then weigh their ranges against a covariance that contains
    /// the filter's own Monte Carlo error. Without it that error accumulates unseen in
    /// the directions the ranges reach only through the dynamics, and the cloud grows
    /// over-confident (seed 003, the default RPF-100 over seeds 1–5: mean NEES 5.3–6.9
    /// for 3 dof against 6.8–11.6; seed 001's RPF-20 over 200 trials 1.15–1.18× of the
    /// PCRLB, NEES 1.3–1.4 for the 2 dof then counted, against 1.26–1.40× and 2.7–4.8;
    /// docs/reproductions.md, "The kernel carries the Monte Carlo error"). The terms
    /// vanish as `1/N`: with 2000 particles and even weights they add 0.1 %.
    ///
    /// After a linearised proposal ([`Self::update_linearised`]) the weighted cloud is a
    /// draw from the posterior mixture `Σ w_i N(c_i, Σ)`, whose weights depend on the
    /// component means `c_i = x_i + G ν_i` alone. Its moments are then taken with the
    /// draws integrated out (Rao-Blackwellisation: Casella & Robert, "Rao-Blackwellisation
    /// of sampling schemes", *Biometrika* 83, 1996): the mean `c̄ = Σ w_i c_i` and the
    /// covariance `V = Σ + Σ w_i (c_i − c̄)(c_i − c̄)ᵀ / (1 − Σ w_i²)`, and the mean's error
    /// is the centres' share, `(V − Σ)/N_eff`, plus `V/N` for the new draws: the kernel is
    /// `h² V + (V − Σ)/N_eff + V/N`. (The Rao-Blackwellised filter shrinks towards the
    /// drawn cloud's mean instead of `c̄`: its Kalman-carried clocks are each particle's
    /// Kalman mean at its drawn position, and the shrink does not move them; towards `c̄`
    /// the positions and clocks disagree, which the linear test below shows as a clock
    /// mean off the Kalman filter's by up to 6 standard errors.) The sample moments of
    /// the drawn cloud have the same expectation, but the draws carry `Σ`, most of `V`
    /// when the ranges are precise, and their noise in the kernel's covariance and in the
    /// next proposal's gain is what left 100 particles over-confident on seed 003 (unit
    /// test `the_linearised_posterior_moments_come_from_the_centres`: 64× less scatter;
    /// the default RPF-100 over seeds 1–5: 1.07–1.10× of the PCRLB, mean NEES 3.4–3.7 for
    /// 3 dof, against 1.18–1.27× and 5.3–7.0; docs/reproductions.md, "The kernel from the
    /// centres of the linearised proposal").
    ///
    /// Musso's placements ([`KernelPlacement::Plain`], [`KernelPlacement::ShrunkStatic`])
    /// take their `D Dᵀ`, the weighted covariance of the cloud, the same way after a
    /// linearised proposal: given the centres, the draws `x_i = c_i + G ε_i` give it the
    /// expectation `Σ w_i (c_i − c̄)(c_i − c̄)ᵀ + (1 − Σ w_i²) Σ`, which is used in its
    /// place (and `c̄` as the mean the static components shrink towards, the drawn mean
    /// for the Rao-Blackwellised filter as above). It is the covariance Musso et al.
    /// define, with the draws' noise integrated out; their bandwidth and inflation are
    /// unchanged. Without it the rows with the linearised
    /// proposal and Musso's kernel were over-confident on some seeds (seed 003,
    /// RPF-100-lin-Musso-LW-static over seeds 1–5: mean NEES 3.5–17.7 for 3 dof, with it
    /// 3.2–4.2; seed 001's RPF-20-lin-Musso-theta1 0.8 on every seed against 0.9–5.5;
    /// docs/reproductions.md, "Musso's kernel from the centres").
    pub fn resample_regularised<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let Some((mean, g, a)) = self.resample_and_kernel(rng) else {
            return;
        };
        for i in 0..self.buf.n {
            let w = SVector::<f64, N>::from_fn(|k, _| {
                if self.sampled[k] {
                    rng.sample(StandardNormal)
                } else {
                    0.0
                }
            });
            let x = self.shrunk(i, &mean, a) + g * w;
            self.buf.set(i, &x);
        }
    }

    /// [`Self::resample_regularised`] with the kernel's jitter left to the next epoch's
    /// linearised proposal ([`Self::update_linearised`]): the particles are resampled
    /// and shrunk as there, and the kernel covariance `h² D Dᵀ` is kept. Drawing the
    /// jitter after the propagation, conditioned on the next ranges together with the
    /// process noise, is the linearised optimal proposal of the kernel density the
    /// regularised filter stands for (its prior between two updates is the mixture
    /// `Σ w_i N(f(x_i), F h² D Dᵀ Fᵀ + Q)`); jittering blindly first and conditioning
    /// only `Q` would leave the kernel's spread to the weights.
    fn resample_deferring_kernel<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let Some((mean, g, a)) = self.resample_and_kernel(rng) else {
            return;
        };
        for i in 0..self.buf.n {
            let x = self.shrunk(i, &mean, a);
            self.buf.set(i, &x);
        }
        self.deferred_kernel = Some(g * g.transpose());
    }

    /// Resamples, and returns the kernel of the weighted cloud before it: its mean, the
    /// factor `h_opt D` and the shrink `a` (see [`Self::resample_regularised`]); `None`
    /// when the cloud has no spread to regularise.
    fn resample_and_kernel<R: Rng + ?Sized>(
        &mut self,
        rng: &mut R,
    ) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>, f64)> {
        // Liu & West's shrinkage keeps the unbiased estimate of the posterior covariance,
        // whose divisor is `unbiased` = 1 − Σ w_i²; its mixture is a kernel density of the
        // weighted cloud, whose size is Kish's N_eff = 1 / Σ w_i²; and its cloud carries
        // the Monte Carlo error of its mean, `monte_carlo` = 1/N_eff + 1/N of the
        // covariance (see `resample_regularised`). Musso's kernels smooth the N resampled
        // particles with the weighted covariance, as their authors define them.
        let n = self.buf.n as f64;
        let (unbiased, sample_size, monte_carlo) = match self.kernel {
            KernelPlacement::Shrunk => {
                let sum_sq = self.weight_square_sum();
                let n_eff = 1.0 / sum_sq;
                (1.0 - sum_sq, n_eff, 1.0 / n_eff + 1.0 / n)
            }
            KernelPlacement::Plain | KernelPlacement::ShrunkStatic => (1.0, n, 0.0),
        };
        if unbiased <= 0.0 {
            // All the weight on one particle: the cloud has no spread to estimate.
            self.resample(rng);
            return None;
        }
        // After a linearised proposal, the Rao-Blackwellised moments of its posterior
        // mixture (see `resample_regularised`): the centres' weighted mean, and for Liu &
        // West `Σ` plus the centres' unbiased covariance, the mean's error then being the
        // centres' share over N_eff plus the covariance over N for the new draws; for
        // Musso's placements the weighted covariance with the draws integrated out,
        // `cov_w(c) + (1 − Σ w_i²) Σ`.
        let (mean, cov, mc_cov) = match self.centred {
            Some(sigma) => {
                let (centre, c) = self.centre_moments();
                // A Kalman-carried clock is each particle's Kalman mean at its drawn
                // position, which the shrink does not move: the positions then shrink
                // towards the drawn cloud's mean, with which those clocks agree.
                let m = if self.rb.is_some() {
                    self.mean()
                } else {
                    centre
                };
                match self.kernel {
                    KernelPlacement::Shrunk => {
                        let between = self.mask(&c) / unbiased;
                        let v = between + sigma;
                        (m, v, Some(between * (1.0 - unbiased) + v / n))
                    }
                    KernelPlacement::Plain | KernelPlacement::ShrunkStatic => {
                        // Σ w_i² ≤ 1; the clamp only guards its rounding.
                        let spread = (1.0 - self.weight_square_sum()).max(0.0);
                        (m, self.mask(&c) + sigma * spread, None)
                    }
                }
            }
            None => (
                self.mean(),
                self.mask(&self.sample_covariance()) / unbiased,
                None,
            ),
        };
        self.resample(rng);
        let d = psd_factor(&cov).ok()?;
        let rank = (0..N).filter(|&k| d[(k, k)] != 0.0).count();
        if rank == 0 {
            return None;
        }
        let nd = rank as f64;
        let h = (4.0 / (sample_size * (nd + 2.0)))
            .powf(1.0 / (nd + 4.0))
            .min(1.0);
        let a = match self.kernel {
            KernelPlacement::Shrunk | KernelPlacement::ShrunkStatic => {
                ((1.0 - h * h) / unbiased).sqrt()
            }
            KernelPlacement::Plain => 1.0,
        };
        let kernel = match mc_cov {
            Some(mc) => psd_factor(&(cov * (h * h) + mc)).ok()?,
            None => d * (h * h + monte_carlo).sqrt(),
        };
        Some((mean, kernel, a))
    }

    /// The weighted mean and weighted covariance `Σ w_i (c_i − c̄)(c_i − c̄)ᵀ` of the
    /// linearised proposal's component means `c_i` (the buffer's `centres`).
    fn centre_moments(&self) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        weighted_moments(&self.buf.centres, &self.buf.weights)
    }

    /// Particle `i` shrunk towards `mean` by `a` (the sampled components the kernel
    /// placement shrinks).
    fn shrunk(&self, i: usize, mean: &SVector<f64, N>, a: f64) -> SVector<f64, N> {
        let mut x = self.buf.get(i);
        for k in 0..N {
            let shrinks = match self.kernel {
                KernelPlacement::ShrunkStatic => self.static_cols[k],
                _ => true,
            };
            if self.sampled[k] && shrinks {
                x[k] = mean[k] + a * (x[k] - mean[k]);
            }
        }
        x
    }

    /// The weighted mean `Σ w_i x_i` (seed 001 eq. 10).
    pub fn mean(&self) -> SVector<f64, N> {
        let b = &self.buf;
        SVector::<f64, N>::from_fn(|k, _| {
            b.column(k).iter().zip(&b.weights).map(|(x, w)| x * w).sum()
        })
    }

    /// The weighted covariance of the cloud, `Σ w_i (x_i − x̂)(x_i − x̂)ᵀ`, column by column.
    fn sample_covariance(&self) -> SMatrix<f64, N, N> {
        weighted_moments(&self.buf.cols, &self.buf.weights).1
    }

    /// The Gaussian filter's covariance from the weighted cloud, by its estimator.
    fn gaussian_covariance(&self) -> SMatrix<f64, N, N> {
        let p = self.sample_covariance();
        match self.covariance {
            CovarianceEstimate::Weighted => p,
            CovarianceEstimate::Unbiased => {
                let sum_sq = self.weight_square_sum();
                // A single particle carries all the weight: nothing to correct.
                if sum_sq < 1.0 {
                    p / (1.0 - sum_sq)
                } else {
                    p
                }
            }
        }
    }

    /// `Σ w_i²` of the normalised weights (`1 / N_eff`).
    fn weight_square_sum(&self) -> f64 {
        self.buf.weights.iter().map(|w| w * w).sum()
    }

    /// The covariance of the estimate: the cloud's weighted covariance (the Gaussian
    /// filter's by its estimator), plus, for a
    /// Rao-Blackwellised clock, its Kalman variance (law of total variance); a clock
    /// still under a flat prior contributes only its spread. A regularised filter whose
    /// kernel is pending (left by a resampling in a linearised epoch,
    /// [`Self::update_linearised`]) stands for the kernel
    /// density `Σ w_i N(x_i, h² D Dᵀ)`, whose covariance is the cloud's plus the kernel's:
    /// the one its cloud has once the kernel is drawn, and the one the same filter
    /// reports when it jitters at once (Musso, Oudjane & Le Gland 2001, the regularised
    /// empirical density).
    pub fn covariance(&self) -> SMatrix<f64, N, N> {
        let mut p = if self.variant == PfVariant::Gaussian {
            self.gaussian_covariance()
        } else {
            self.sample_covariance()
        };
        if let Some(k) = &self.deferred_kernel {
            p += k;
        }
        if let Some(mm) = &self.mm {
            p += mm.p;
        }
        if let Some(rb) = &self.rb {
            for (s, col) in rb.cols.iter().enumerate() {
                if let Some(k) = *col {
                    if rb.var_m2[s].is_finite() {
                        p[(k, k)] += rb.var_m2[s];
                    }
                }
            }
        }
        p
    }

    /// The Kalman variance (m²) of system `s`'s clock in a Rao-Blackwellised filter
    /// (infinite under a flat prior); `None` for other filters or systems.
    pub fn clock_variance_m2(&self, s: usize) -> Option<f64> {
        let rb = self.rb.as_ref()?;
        rb.cols.get(s).copied().flatten().map(|_| rb.var_m2[s])
    }
}

/// The weighted mean `Σ w_i x_i` and covariance `Σ w_i (x_i − x̄)(x_i − x̄)ᵀ` of the
/// `n = weights.len()` points whose component `k` is `cols[k·n .. (k+1)·n]`, column by
/// column.
fn weighted_moments<const N: usize>(
    cols: &[f64],
    weights: &[f64],
) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
    let n = weights.len();
    let col = |k: usize| &cols[k * n..(k + 1) * n];
    let m = SVector::<f64, N>::from_fn(|k, _| col(k).iter().zip(weights).map(|(x, w)| x * w).sum());
    let mut p = SMatrix::<f64, N, N>::zeros();
    for k in 0..N {
        for l in 0..=k {
            let (mk, ml) = (m[k], m[l]);
            let s: f64 = col(k)
                .iter()
                .zip(col(l))
                .zip(weights)
                .map(|((x, y), w)| w * (x - mk) * (y - ml))
                .sum();
            p[(k, l)] = s;
            p[(l, k)] = s;
        }
    }
    (m, p)
}

/// The largest exponent `λ ∈ (0, max]` whose tempered weights keep `n_eff(λ) ≥ target`
/// (a progressive correction's next stage): `max` itself when it does, else by 40 steps
/// of bisection (the size falls from the current weights' as `λ` grows), and at least
/// `max/1000`, so that the correction always advances.
fn bisect_exponent(max: f64, target: f64, mut n_eff: impl FnMut(f64) -> f64) -> f64 {
    if n_eff(max) >= target {
        return max;
    }
    let (mut lo, mut hi) = (0.0, max);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if n_eff(mid) >= target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo.max(max * 1e-3)
}

/// The effective sample size of the weights `w_i · exp(inc(i))`, `(Σ v_i)² / Σ v_i²`,
/// formed after subtracting the largest increment of a weighted particle (so that the
/// exponentials cannot all underflow); a NaN increment is a particle left out; infinite
/// when no weighted particle has a finite increment (no step to limit).
fn tempered_n_eff(weights: &[f64], inc: impl Fn(usize) -> f64) -> f64 {
    let top = weights
        .iter()
        .enumerate()
        .filter(|(i, w)| **w > 0.0 && !inc(*i).is_nan())
        .map(|(i, _)| inc(i))
        .fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return f64::INFINITY;
    }
    let (mut s1, mut s2) = (0.0, 0.0);
    for (i, w) in weights.iter().enumerate() {
        let l = inc(i);
        if l.is_nan() {
            continue;
        }
        let v = w * (l - top).exp();
        s1 += v;
        s2 += v * v;
    }
    if s2 > 0.0 {
        s1 * s1 / s2
    } else {
        0.0
    }
}

/// The running sums of `w` into `out`, the last set to +∞ (rounding can leave the true
/// total a hair below 1; the last particle must catch every uniform up to it).
fn cumulative(w: &[f64], out: &mut [f64]) {
    let mut c = 0.0;
    for (s, w) in out.iter_mut().zip(w) {
        c += w;
        *s = c;
    }
    if let Some(last) = out.last_mut() {
        *last = f64::INFINITY;
    }
}

/// The Rao-Blackwellised weight update of an epoch's ranges.
///
/// For a system `s` with ranges `j`, weights `w_j = 1/σ_j²`, `W = Σ w_j`, and a particle
/// whose clock has Kalman mean `m_i` and the common variance `P`, the residuals
/// `r_ij = z_j − ‖e_j − p_i‖ − m_i` have the joint covariance `R + P 1 1ᵀ`; by the
/// Sherman–Morrison identity their log-density is, up to a term common to all particles,
///
/// ```text
/// log p(z_s | p_i) = −½ (B_i − A_i² / (1/P + W)),   A_i = Σ w_j r_ij,  B_i = Σ w_j r_ij²
/// m_i ← m_i + A_i / (1/P + W),                      P ← 1 / (1/P + W)
/// ```
///
/// the second line being the Kalman update of the clock given the particle's position.
/// `1/P = 0` (a flat prior) gives the profile likelihood about the weighted mean residual;
/// `P = 0` (a known clock) gives the plain likelihood and leaves `m_i` alone.
fn rb_update<const N: usize>(
    rb: &mut RbClocks,
    lik: &PseudorangeLikelihood,
    cols: &mut [f64],
    out: &mut [f64],
) {
    let n = out.len();
    if cols.len() < N * n {
        out.fill(f64::NAN);
        return;
    }
    let marginal = |c: Option<usize>| c.is_some() && rb.cols.contains(&c);
    let mut sum_w = [0.0; System::COUNT];
    for r in &lik.rows {
        for (s, c) in rb.cols.iter().enumerate() {
            if c.is_some() && *c == r.clock_col {
                sum_w[s] += -2.0 * r.neg_half_inv_var;
            }
        }
    }
    let zeros = [0.0; BLOCK];
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        let len = end - start;
        {
            let col = |k: Option<usize>| {
                k.filter(|&k| k < N)
                    .map(|k| &cols[k * n + start..k * n + end])
            };
            let p = |a: usize| col(lik.pos_col[a]).unwrap_or(&zeros[..len]);
            let (px, py, pz) = (p(0), p(1), p(2));
            // Ranges whose clock is sampled (none in the paper models) take the plain terms.
            for r in lik.rows.iter().filter(|r| !marginal(r.clock_col)) {
                range_terms(
                    &mut out[start..end],
                    px,
                    py,
                    pz,
                    col(r.clock_col),
                    col(r.isb_col),
                    r,
                );
            }
        }
        for (s, &w_sum) in sum_w.iter().enumerate() {
            let Some(k) = rb.cols[s] else {
                continue;
            };
            if w_sum == 0.0 {
                continue;
            }
            let mut a = [0.0; BLOCK];
            let mut b = [0.0; BLOCK];
            {
                let col = |k: Option<usize>| {
                    k.filter(|&k| k < N)
                        .map(|k| &cols[k * n + start..k * n + end])
                };
                let p = |a: usize| col(lik.pos_col[a]).unwrap_or(&zeros[..len]);
                let (px, py, pz) = (p(0), p(1), p(2));
                let m = &cols[k * n + start..k * n + end];
                for r in lik.rows.iter().filter(|r| r.clock_col == Some(k)) {
                    let isb = col(r.isb_col).unwrap_or(&zeros[..len]);
                    clock_residual_sums(&mut a[..len], &mut b[..len], px, py, pz, isb, m, r);
                }
            }
            let gain = 1.0 / (1.0 / rb.var_m2[s] + w_sum);
            let m = &mut cols[k * n + start..k * n + end];
            for i in 0..len {
                out[start + i] += -0.5 * (b[i] - a[i] * a[i] * gain);
                m[i] += a[i] * gain;
            }
        }
        start = end;
    }
    for ((var, col), w_sum) in rb.var_m2.iter_mut().zip(&rb.cols).zip(&sum_w) {
        if col.is_some() && *w_sum > 0.0 {
            *var = 1.0 / (1.0 / *var + w_sum);
        }
    }
}

/// One range's contribution to a system's clock sums `A_i`, `B_i` over a block.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn clock_residual_sums(
    a: &mut [f64],
    b: &mut [f64],
    px: &[f64],
    py: &[f64],
    pz: &[f64],
    isb: &[f64],
    m: &[f64],
    r: &LikRow,
) {
    let [ex, ey, ez] = r.e;
    let (z, w) = (r.z_m, -2.0 * r.neg_half_inv_var);
    let n = a.len();
    let (b, px, py, pz, isb, m) = (
        &mut b[..n],
        &px[..n],
        &py[..n],
        &pz[..n],
        &isb[..n],
        &m[..n],
    );
    for i in 0..n {
        let (dx, dy, dz) = (ex - px[i], ey - py[i], ez - pz[i]);
        let res = z - (dx * dx + dy * dy + dz * dz).sqrt() - isb[i] - m[i];
        a[i] += w * res;
        b[i] += w * res * res;
    }
}

/// The rows of `H` (unit line of sight and clock columns) of an epoch's ranges at state
/// `x`; the unused rows are zero. `None` when the state sits on an emitter or is not
/// finite.
fn range_linearisation<const N: usize>(
    lik: &PseudorangeLikelihood,
    x: &SVector<f64, N>,
) -> Option<ProposalRows<N>> {
    let p = position(lik, x);
    let mut h = ProposalRows::<N>::zeros();
    for (j, r) in lik.rows.iter().enumerate().take(MAX_PROPOSAL_ROWS) {
        let d = p - Vector3::from(r.e);
        let dist = d.norm();
        if dist.is_nan() || dist <= 0.0 {
            return None;
        }
        for a in 0..3 {
            if let Some(k) = lik.pos_col[a].filter(|&k| k < N) {
                h[(j, k)] = d[a] / dist;
            }
        }
        for k in [r.clock_col, r.isb_col].into_iter().flatten() {
            if k < N {
                h[(j, k)] += 1.0;
            }
        }
    }
    Some(h)
}

/// The residuals `z − h(x)` of an epoch's ranges at state `x` (the unused rows zero).
fn range_residuals<const N: usize>(
    lik: &PseudorangeLikelihood,
    x: &SVector<f64, N>,
) -> SVector<f64, MAX_PROPOSAL_ROWS> {
    let p = position(lik, x);
    let mut nu = SVector::<f64, MAX_PROPOSAL_ROWS>::zeros();
    for (j, r) in lik.rows.iter().enumerate().take(MAX_PROPOSAL_ROWS) {
        let mut pred = (Vector3::from(r.e) - p).norm();
        for k in [r.clock_col, r.isb_col].into_iter().flatten() {
            if k < N {
                pred += x[k];
            }
        }
        nu[j] = r.z_m - pred;
    }
    nu
}

/// The position of state `x` under the likelihood's columns (a missing one is 0).
fn position<const N: usize>(lik: &PseudorangeLikelihood, x: &SVector<f64, N>) -> Vector3<f64> {
    Vector3::from_fn(|a, _| lik.pos_col[a].filter(|&k| k < N).map_or(0.0, |k| x[k]))
}

/// `H` of the linearised proposals: one row per range, up to [`MAX_PROPOSAL_ROWS`].
type ProposalRows<const N: usize> = SMatrix<f64, MAX_PROPOSAL_ROWS, N>;

/// A factor `G` with `G Gᵀ = Q` for a positive semi-definite `Q`: Cholesky when it
/// exists, else the symmetric eigen-decomposition `V √D` (a model such as seed 001's,
/// noise-free in x, has a singular `Q`).
fn psd_factor<const N: usize>(q: &SMatrix<f64, N, N>) -> Result<SMatrix<f64, N, N>, ParticleError> {
    if !q.iter().all(|v| v.is_finite()) {
        return Err(ParticleError::NonFinite);
    }
    if q.iter().all(|v| *v == 0.0) {
        return Ok(SMatrix::<f64, N, N>::zeros());
    }
    if let Some(c) = q.cholesky() {
        return Ok(c.l());
    }
    // Cholesky–Banachiewicz that tolerates zero pivots: for a semi-definite matrix a
    // pivot at the rounding level means the column is a combination of the previous
    // ones, so its part of the factor is zero.
    let tol = 1e-12 * q.amax();
    let mut g = SMatrix::<f64, N, N>::zeros();
    for j in 0..N {
        let mut d = q[(j, j)];
        for k in 0..j {
            d -= g[(j, k)] * g[(j, k)];
        }
        if d < -tol {
            return Err(ParticleError::NotPositiveSemiDefinite);
        }
        if d <= tol {
            continue;
        }
        let l = d.sqrt();
        g[(j, j)] = l;
        for i in j + 1..N {
            let mut s = q[(i, j)];
            for k in 0..j {
                s -= g[(i, k)] * g[(j, k)];
            }
            g[(i, j)] = s / l;
        }
    }
    Ok(g)
}

/// The pseudorange likelihood over particle columns:
/// `log p(z | x_i) = Σ_j −½ (ρ_j − ‖r_j − r_i‖ − b_i)² / σ_j²`, with the clock and
/// inter-system-bias columns of each system as in [`Pseudoranges`].
///
/// Its buffers are sized by [`PseudorangeLikelihood::with_capacity`] and refilled each
/// epoch by [`PseudorangeLikelihood::set`] without allocating.
#[derive(Clone, Debug, PartialEq)]
pub struct PseudorangeLikelihood {
    pos_col: [Option<usize>; 3],
    rows: Vec<LikRow>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct LikRow {
    e: [f64; 3],
    z_m: f64,
    /// `−½ / σ²` (1/m²).
    neg_half_inv_var: f64,
    clock_col: Option<usize>,
    isb_col: Option<usize>,
}

/// The block of particles processed measurement by measurement: 512 particles × (4
/// columns + the sum) × 8 bytes = 20 KiB, inside a 32 KiB L1 data cache.
const BLOCK: usize = 512;

impl PseudorangeLikelihood {
    /// An empty likelihood with room for `m` ranges.
    pub fn with_capacity(m: usize) -> Self {
        Self {
            pos_col: [None; 3],
            rows: Vec::with_capacity(m),
        }
    }

    /// Loads the model's ranges and the measured pseudoranges `z`.
    pub fn set<const N: usize, const M: usize>(
        &mut self,
        model: &Pseudoranges<N, M>,
        z: &SVector<f64, M>,
    ) {
        let layout = model.layout();
        self.pos_col = layout.pos;
        self.rows.clear();
        for (row, zj) in model.rows().iter().zip(z.iter()) {
            let s = row.system.index();
            self.rows.push(LikRow {
                e: [
                    row.emitter_pos_m.x,
                    row.emitter_pos_m.y,
                    row.emitter_pos_m.z,
                ],
                z_m: *zj,
                neg_half_inv_var: -0.5 / (row.sigma_m * row.sigma_m),
                clock_col: layout.clock[s],
                isb_col: layout.isb[s],
            });
        }
    }

    /// Empties the likelihood for an epoch of any number of ranges, on a state whose
    /// position components are `pos_col` (`None`: a coordinate taken as 0). Ranges are then
    /// added one by one with [`PseudorangeLikelihood::push`], without allocating while
    /// they fit the capacity.
    pub fn clear(&mut self, pos_col: [Option<usize>; 3]) {
        self.pos_col = pos_col;
        self.rows.clear();
    }

    /// Adds one range `z_m` to the emitter of `row`, its clock columns taken from `layout`.
    pub fn push(&mut self, layout: &StateLayout, row: &RangeRow, z_m: f64) {
        let s = row.system.index();
        self.rows.push(LikRow {
            e: [
                row.emitter_pos_m.x,
                row.emitter_pos_m.y,
                row.emitter_pos_m.z,
            ],
            z_m,
            neg_half_inv_var: -0.5 / (row.sigma_m * row.sigma_m),
            clock_col: layout.clock[s],
            isb_col: layout.isb[s],
        });
    }

    /// The number of ranges loaded.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when no range is loaded.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

/// One range's terms over a block: the loop the compiler vectorises.
#[inline(always)]
fn range_terms(
    out: &mut [f64],
    px: &[f64],
    py: &[f64],
    pz: &[f64],
    bias: Option<&[f64]>,
    bias2: Option<&[f64]>,
    r: &LikRow,
) {
    let [ex, ey, ez] = r.e;
    let (z, c) = (r.z_m, r.neg_half_inv_var);
    let n = out.len();
    let (px, py, pz) = (&px[..n], &py[..n], &pz[..n]);
    match (bias, bias2) {
        (Some(b), Some(b2)) => {
            let (b, b2) = (&b[..n], &b2[..n]);
            for i in 0..n {
                let (dx, dy, dz) = (ex - px[i], ey - py[i], ez - pz[i]);
                let d = (dx * dx + dy * dy + dz * dz).sqrt() + b[i] + b2[i] - z;
                out[i] += c * d * d;
            }
        }
        (Some(b), None) | (None, Some(b)) => {
            let b = &b[..n];
            for i in 0..n {
                let (dx, dy, dz) = (ex - px[i], ey - py[i], ez - pz[i]);
                let d = (dx * dx + dy * dy + dz * dz).sqrt() + b[i] - z;
                out[i] += c * d * d;
            }
        }
        (None, None) => {
            for i in 0..n {
                let (dx, dy, dz) = (ex - px[i], ey - py[i], ez - pz[i]);
                let d = (dx * dx + dy * dy + dz * dz).sqrt() - z;
                out[i] += c * d * d;
            }
        }
    }
}

impl<const N: usize> SoaLikelihood<N> for PseudorangeLikelihood {
    fn add_log_likelihood(&self, cols: &[f64], out: &mut [f64]) {
        let n = out.len();
        if cols.len() < N * n {
            // A mismatched buffer is a programming error in the caller; every particle
            // gets an unusable likelihood rather than a panic.
            out.fill(f64::NAN);
            return;
        }
        let col = |k: Option<usize>| k.filter(|&k| k < N).map(|k| &cols[k * n..(k + 1) * n]);
        let zeros = [0.0; BLOCK];
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            let len = end - start;
            let block = |k: Option<usize>| col(k).map(|c| &c[start..end]);
            let p = |a: usize| block(self.pos_col[a]).unwrap_or(&zeros[..len]);
            let (px, py, pz) = (p(0), p(1), p(2));
            for r in &self.rows {
                range_terms(
                    &mut out[start..end],
                    px,
                    py,
                    pz,
                    block(r.clock_col),
                    block(r.isb_col),
                    r,
                );
            }
            start = end;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use crate::fusion::models::{RangeRow, StateLayout};
    use nalgebra::Vector3;

    /// Position in columns 0–2 and one clock, shared by every system, in column 3.
    fn position_clock_layout() -> StateLayout {
        StateLayout {
            pos: [Some(0), Some(1), Some(2)],
            vel: [None; 3],
            clock: [Some(3); System::COUNT],
            isb: [None; System::COUNT],
            drift: None,
        }
    }

    fn model() -> Pseudoranges<4, 3> {
        let layout = position_clock_layout();
        let row = |x: f64, y: f64| RangeRow {
            emitter_pos_m: Vector3::new(x, y, 500.0),
            emitter_vel_mps: Vector3::zeros(),
            system: System::Dtmb,
            sigma_m: 2.0,
            sigma_rate_mps: 1.0,
        };
        Pseudoranges::new(
            layout,
            [row(1000.0, 0.0), row(0.0, 1000.0), row(-700.0, -700.0)],
        )
        .unwrap()
    }

    #[test]
    fn soa_likelihood_equals_the_generic_one() {
        let m = model();
        let z = SVector::<f64, 3>::new(1100.0, 1050.0, 1000.0);
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(1500).unwrap(),
            Resampling::Systematic,
            0.0,
        )
        .unwrap();
        let mut rng = TrialRng::new(1, 0).stream("test/pf");
        pf.init_gaussian(
            &SVector::<f64, 4>::new(0.0, 0.0, 0.0, 10.0),
            &(SMatrix::<f64, 4, 4>::identity() * 400.0),
            &mut rng,
        )
        .unwrap();
        let mut lik = PseudorangeLikelihood::with_capacity(3);
        lik.set(&m, &z);
        let mut out = vec![0.0; 1500];
        SoaLikelihood::<4>::add_log_likelihood(&lik, pf.particles().columns(), &mut out);
        for (i, o) in out.iter().enumerate() {
            let x = pf.particles().get(i);
            let g = m.log_likelihood(&x, &z);
            assert!((o - g).abs() <= 1e-9 * g.abs().max(1.0), "{i}: {o} vs {g}");
        }
    }

    /// Ranges pushed one by one give the same likelihood as a whole model loaded at once.
    #[test]
    fn pushed_rows_equal_a_loaded_model() {
        let m = model();
        let z = SVector::<f64, 3>::new(1100.0, 1050.0, 1000.0);
        let mut a = PseudorangeLikelihood::with_capacity(3);
        a.set(&m, &z);
        let mut b = PseudorangeLikelihood::with_capacity(3);
        b.clear(m.layout().pos);
        for (row, zj) in m.rows().iter().zip(z.iter()) {
            b.push(m.layout(), row, *zj);
        }
        assert_eq!(a, b);
    }

    #[test]
    fn resampling_keeps_heavy_particles_and_degeneracy_is_reported() {
        let mut rng = TrialRng::new(2, 0).stream("test/pf");
        for scheme in [Resampling::Systematic, Resampling::Stratified] {
            let mut pf =
                ParticleFilter::new(ParticleBuffer::<1>::new(4).unwrap(), scheme, 1.0).unwrap();
            pf.particles_mut()
                .column_mut(0)
                .copy_from_slice(&[1.0, 2.0, 3.0, 4.0]);
            pf.particles_mut()
                .weights
                .copy_from_slice(&[0.0, 1.0, 0.0, 0.0]);
            pf.resample(&mut rng);
            assert_eq!(pf.particles().column(0), &[2.0; 4]);
            assert_eq!(pf.particles().weights(), &[0.25; 4]);
        }
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(10).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap();
        let z = SVector::<f64, 3>::new(f64::NAN, 0.0, 0.0);
        let up = pf.update(&model(), &z, &mut rng);
        assert!(up.degenerate);
        assert!(pf.mean().iter().all(|v| v.is_finite()));
        assert!(ParticleBuffer::<4>::new(0).is_err());
        assert!(ParticleFilter::new(
            ParticleBuffer::<4>::new(3).unwrap(),
            Resampling::Systematic,
            1.5
        )
        .is_err());
    }

    /// A Rao-Blackwellised filter of `n` particles over `[x, y, z, b]` whose clock `b`
    /// (column 3, the DTMB system's) is carried by the per-particle Kalman filters.
    fn rbpf_on_dtmb_clock(n: usize) -> ParticleFilter<4> {
        ParticleFilter::new(
            ParticleBuffer::<4>::new(n).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .rao_blackwellised(std::array::from_fn(|s| {
            (s == System::Dtmb.index()).then_some(3)
        }))
        .unwrap()
    }

    /// The Rao-Blackwellised progressive correction against the joint Kalman posterior:
    /// a receiver 30 m (1 σ) from its prior mean, a clock prior `N(250, 50²)` m, six
    /// ranges of σ = 1 m from 20 000 km (linear to 10⁻⁴ m over the prior), 2 000
    /// particles, 5 seeds. The stages split the clocks' Kalman update (their likelihood
    /// to the power `Λ` is a Kalman update with `R/Λ`), so the cloud's position and the
    /// clock's mean and variance reach the Kalman filter's: the means within 0.2 posterior
    /// σ, the variances within [0.7, 1.4] of its. The single update on the same seeds is
    /// further from the mean (the test requires twice as far). A wide likelihood
    /// (σ = 300 m) keeps half the particles and is the single update, bit for bit.
    #[test]
    fn rao_blackwellised_progressive_correction_reaches_the_kalman_posterior() {
        let layout = position_clock_layout();
        let row = |az_deg: f64, el_deg: f64, sigma_m: f64| {
            let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
            RangeRow {
                emitter_pos_m: Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin())
                    * 2.0e7,
                emitter_vel_mps: Vector3::zeros(),
                system: System::Dtmb,
                sigma_m,
                sigma_rate_mps: 1.0,
            }
        };
        let sky = [
            (0.0, 75.0),
            (60.0, 30.0),
            (130.0, 45.0),
            (200.0, 20.0),
            (260.0, 50.0),
            (320.0, 15.0),
        ];
        let truth = SVector::<f64, 4>::new(20.0, -25.0, 10.0, 290.0);
        let (x0, p0_pos, clock0, clock_var) = (SVector::<f64, 4>::zeros(), 900.0, 250.0, 2500.0);
        let n = 2000;
        let run = |sigma_m: f64, progressive: bool, seed: u64| {
            let model =
                Pseudoranges::<4, 6>::new(layout, sky.map(|(a, e)| row(a, e, sigma_m))).unwrap();
            let mut noise = TrialRng::new(seed, 1).stream("test/rbpf-progressive/noise");
            let z = SVector::<f64, 6>::from_fn(|j, _| {
                let e: f64 = noise.sample(StandardNormal);
                model.h(&truth)[j] + sigma_m * e
            });
            let mut lik = PseudorangeLikelihood::with_capacity(6);
            lik.set(&model, &z);
            let mut pf = rbpf_on_dtmb_clock(n).with_progressive_correction(progressive);
            let mut rng = TrialRng::new(seed, 0).stream("test/rbpf-progressive");
            pf.init_gaussian(&x0, &(SMatrix::<f64, 4, 4>::identity() * p0_pos), &mut rng)
                .unwrap();
            pf.set_clock_prior(System::Dtmb.index(), clock0, clock_var);
            let up = pf.update_ranges(&lik, &mut rng);
            // The Kalman posterior, linearised at the truth.
            let mut mu = x0;
            mu[3] = clock0;
            let mut p = SMatrix::<f64, 4, 4>::identity() * p0_pos;
            p[(3, 3)] = clock_var;
            let h = model.jacobian(&truth);
            let r = SMatrix::<f64, 6, 6>::identity() * (sigma_m * sigma_m);
            let nu = z - model.h(&truth) - h * (mu - truth);
            let s_inv = (h * p * h.transpose() + r).try_inverse().unwrap();
            let k = p * h.transpose() * s_inv;
            let mean = mu + k * nu;
            let cov = (SMatrix::<f64, 4, 4>::identity() - k * h) * p;
            (pf, up, mean, cov)
        };
        let (mut worst_pc, mut worst_single) = (0.0f64, 0.0f64);
        for seed in 0..5 {
            let (pf, up, mean, cov) = run(1.0, true, seed);
            assert!(!up.degenerate);
            let (m, c) = (pf.mean(), pf.covariance());
            for k in 0..4 {
                let err = (m[k] - mean[k]).abs() / cov[(k, k)].sqrt();
                worst_pc = worst_pc.max(err);
                assert!(err < 0.2, "seed {seed}, state {k}: mean {err} σ off");
                let ratio = c[(k, k)] / cov[(k, k)];
                assert!(
                    (0.7..1.4).contains(&ratio),
                    "seed {seed}, state {k}: variance {ratio} of the Kalman filter's"
                );
            }
            let (single, _, mean, cov) = run(1.0, false, seed);
            let m = single.mean();
            for k in 0..4 {
                worst_single = worst_single.max((m[k] - mean[k]).abs() / cov[(k, k)].sqrt());
            }
        }
        assert!(
            worst_single > 2.0 * worst_pc,
            "single {worst_single} σ, progressive {worst_pc} σ"
        );
        let (a, ua, ..) = run(300.0, true, 9);
        let (b, ub, ..) = run(300.0, false, 9);
        assert_eq!(ua, ub);
        assert_eq!(a.particles(), b.particles());
        assert_eq!(a.covariance(), b.covariance());
    }

    /// A static receiver with a random-walk clock: state `[x, y, z, b]`.
    struct StaticClock {
        clock_q_m2ps: f64,
    }

    impl ProcessModel<4> for StaticClock {
        fn f(&self, x: &SVector<f64, 4>, _dt_s: f64) -> SVector<f64, 4> {
            *x
        }
        fn jacobian(&self, _x: &SVector<f64, 4>, _dt_s: f64) -> SMatrix<f64, 4, 4> {
            SMatrix::<f64, 4, 4>::identity()
        }
        fn q(&self, _x: &SVector<f64, 4>, dt_s: f64) -> SMatrix<f64, 4, 4> {
            let mut q = SMatrix::<f64, 4, 4>::zeros();
            q[(3, 3)] = self.clock_q_m2ps * dt_s;
            q
        }
    }

    /// When the sampled part is known exactly (a receiver at a known point) the model is
    /// linear-Gaussian in the clock, and the Rao-Blackwellised filter's clock mean and
    /// variance must be the textbook Kalman filter's, epoch after epoch.
    #[test]
    fn rao_blackwellised_clock_equals_the_kalman_filter_when_all_is_linear() {
        use crate::fusion::linear_kf::LinearKf;
        use nalgebra::{DMatrix, DVector};
        let m = model();
        let pos = Vector3::new(10.0, -20.0, 5.0);
        let model_q = StaticClock { clock_q_m2ps: 4.0 };
        let mut pf = rbpf_on_dtmb_clock(64);
        let mut rng = TrialRng::new(5, 0).stream("test/rbpf");
        let x0 = SVector::<f64, 4>::new(pos.x, pos.y, pos.z, 0.0);
        pf.init_gaussian(&x0, &SMatrix::<f64, 4, 4>::zeros(), &mut rng)
            .unwrap();
        let s = System::Dtmb.index();
        pf.set_clock_prior(s, 100.0, 400.0);
        let mut kf = LinearKf::new(
            DVector::from_vec(vec![100.0]),
            DMatrix::from_element(1, 1, 400.0),
        )
        .unwrap();
        let mut lik = PseudorangeLikelihood::with_capacity(3);
        let mut nrng = TrialRng::new(5, 1).stream("test/rbpf/noise");
        for epoch in 0..30 {
            let b_true = 130.0 + epoch as f64;
            let mut z = SVector::<f64, 3>::zeros();
            for (j, row) in m.rows().iter().enumerate() {
                let n: f64 = nrng.sample(StandardNormal);
                z[j] = (row.emitter_pos_m - pos).norm() + b_true + row.sigma_m * n;
            }
            pf.predict(&model_q, 1.0, &mut rng).unwrap();
            lik.set(&m, &z);
            pf.update_ranges(&lik, &mut rng);
            kf.predict(&DMatrix::identity(1, 1), &DMatrix::from_element(1, 1, 4.0))
                .unwrap();
            let zk = DVector::from_iterator(
                3,
                m.rows()
                    .iter()
                    .zip(z.iter())
                    .map(|(r, zj)| zj - (r.emitter_pos_m - pos).norm()),
            );
            let r = DMatrix::from_diagonal(&DVector::from_iterator(
                3,
                m.rows().iter().map(|r| r.sigma_m * r.sigma_m),
            ));
            kf.update(&zk, &DMatrix::from_element(3, 1, 1.0), &r)
                .unwrap();
            let (mean, var) = (pf.mean()[3], pf.clock_variance_m2(s).unwrap());
            let (km, kv) = (kf.state()[0], kf.covariance()[(0, 0)]);
            assert!(
                (mean - km).abs() <= 1e-9 * km.abs().max(1.0),
                "{epoch}: {mean} vs {km}"
            );
            assert!((var - kv).abs() <= 1e-9 * kv, "{epoch}: {var} vs {kv}");
            // Every particle carries the same clock, and the position stayed known.
            assert!(pf
                .particles()
                .column(3)
                .iter()
                .all(|b| (b - mean).abs() < 1e-9));
            assert_eq!(pf.particles().column(0)[0], pos.x);
        }
    }

    /// The known-position clock both clock tests run: three pseudoranges (σ 2 m, the
    /// module's test geometry) from a receiver whose position is known, a clock random
    /// walk of 4 m²/s from a 400 m² prior at 100 m, the true clock 130 m + 1 m per epoch,
    /// and the textbook Kalman filter of that clock alone as the truth a particle filter
    /// must follow.
    struct KnownPositionClock {
        ranges: Pseudoranges<4, 3>,
        pos: Vector3<f64>,
        process: StaticClock,
        kf: crate::fusion::linear_kf::LinearKf,
        noise: crate::core::StreamRng,
    }

    impl KnownPositionClock {
        fn new(noise: crate::core::StreamRng) -> Self {
            use nalgebra::{DMatrix, DVector};
            let kf = crate::fusion::linear_kf::LinearKf::new(
                DVector::from_vec(vec![100.0]),
                DMatrix::from_element(1, 1, 400.0),
            )
            .unwrap();
            KnownPositionClock {
                ranges: model(),
                pos: Vector3::new(10.0, -20.0, 5.0),
                process: StaticClock { clock_q_m2ps: 4.0 },
                kf,
                noise,
            }
        }

        /// The particle filters' prior: the position exact, the clock N(100, 400).
        fn prior(&self) -> (SVector<f64, 4>, SMatrix<f64, 4, 4>) {
            let x0 = SVector::<f64, 4>::new(self.pos.x, self.pos.y, self.pos.z, 100.0);
            let mut p0 = SMatrix::<f64, 4, 4>::zeros();
            p0[(3, 3)] = 400.0;
            (x0, p0)
        }

        /// Draws epoch `k`'s pseudoranges, runs the Kalman filter's epoch on them and
        /// returns them.
        fn epoch(&mut self, k: usize) -> SVector<f64, 3> {
            use nalgebra::{DMatrix, DVector};
            let b_true = 130.0 + k as f64;
            let mut z = SVector::<f64, 3>::zeros();
            for (j, row) in self.ranges.rows().iter().enumerate() {
                let e: f64 = self.noise.sample(StandardNormal);
                z[j] = (row.emitter_pos_m - self.pos).norm() + b_true + row.sigma_m * e;
            }
            let q = DMatrix::from_element(1, 1, self.process.clock_q_m2ps);
            self.kf.predict(&DMatrix::identity(1, 1), &q).unwrap();
            let rows = self.ranges.rows();
            let zk = DVector::from_iterator(
                3,
                rows.iter()
                    .zip(z.iter())
                    .map(|(r, zj)| zj - (r.emitter_pos_m - self.pos).norm()),
            );
            let r = DMatrix::from_diagonal(&DVector::from_iterator(
                3,
                rows.iter().map(|r| r.sigma_m * r.sigma_m),
            ));
            self.kf
                .update(&zk, &DMatrix::from_element(3, 1, 1.0), &r)
                .unwrap();
            z
        }

        /// The Kalman filter's clock mean and variance.
        fn kalman(&self) -> (f64, f64) {
            (self.kf.state()[0], self.kf.covariance()[(0, 0)])
        }

        /// Asserts that a Gaussian filter's clock mean and variance at `epoch` (1-based)
        /// follow the Kalman filter's: within `4√(k P / N_eff)` and `4√(2k / N_eff)`, the
        /// Monte Carlo error of k successive moment estimates from `n_eff` samples.
        fn assert_followed(&self, epoch: usize, pf: &ParticleFilter<4>, n_eff: f64) {
            let (km, kv) = self.kalman();
            let (mean, var) = (pf.mean()[3], pf.covariance()[(3, 3)]);
            let k = epoch as f64;
            let tol_mean = 4.0 * (k * kv / n_eff).sqrt();
            let tol_var = 4.0 * (2.0 * k / n_eff).sqrt();
            assert!(
                (mean - km).abs() < tol_mean,
                "{epoch}: {mean} vs {km} ({tol_mean})"
            );
            assert!(
                (var / kv - 1.0).abs() < tol_var,
                "{epoch}: {var} vs {kv} ({tol_var})"
            );
        }
    }

    /// After a linearised proposal the posterior is the mixture `Σ w_i N(c_i, Σ)`, whose
    /// weights depend on the centres `c_i` alone; its covariance `Σ + cov_w(c)` is the
    /// drawn cloud's weighted covariance with the draws' noise integrated out (Casella &
    /// Robert 1996). On the linear clock, over 4000 ten-particle epochs, both estimates
    /// (each divided by `1 − Σ w²`) average to the Kalman filter's posterior variance, and
    /// the Rao-Blackwellised one scatters much less. Musso's kernel, which takes the
    /// weighted covariance itself, gets `cov_w(c) + (1 − Σ w²) Σ`: the drawn cloud's
    /// weighted covariance averages to it (the weights do not depend on the draws), and
    /// it scatters much less.
    #[test]
    fn the_linearised_posterior_moments_come_from_the_centres() {
        let truth = KnownPositionClock::new(TrialRng::new(9, 1).stream("test/centres/noise"));
        let (x0, mut p0) = truth.prior();
        // A prior of 4 m² plus the clock's 4 m² of process noise; with three ranges of
        // σ 2 m the Kalman posterior variance is 1 / (1/8 + 3/4) and the proposal's
        // conditional variance `Σ = 1 / (1/4 + 3/4)`.
        p0[(3, 3)] = 4.0;
        let kalman_var = 1.0 / (1.0 / 8.0 + 0.75);
        let sigma = 1.0 / (0.25 + 0.75);
        let q = ProcessModel::<4>::q(&truth.process, &x0, 1.0);
        let mut lik = PseudorangeLikelihood::with_capacity(3);
        let mut noise = TrialRng::new(9, 2).stream("test/centres/ranges");
        let mut rng = TrialRng::new(9, 0).stream("test/centres");
        let mut resampling = TrialRng::new(9, 3).stream("test/centres/resampling");
        let mut sigma_m = SMatrix::<f64, 4, 4>::zeros();
        sigma_m[(3, 3)] = sigma;
        // Musso's bandwidth for one dimension (the clock) and ten particles.
        let h2 = (4.0f64 / (10.0 * 3.0)).powf(2.0 / 5.0);
        let reps = 4000;
        let (mut rb, mut plain) = (Vec::with_capacity(reps), Vec::with_capacity(reps));
        let mut musso = Vec::with_capacity(reps);
        for _ in 0..reps {
            // The truth's clock drawn from the filter's own predictive, so that the
            // Kalman variance is the posterior's on average.
            let b: f64 = 100.0 + 8f64.sqrt() * noise.sample::<f64, _>(StandardNormal);
            let z = SVector::<f64, 3>::from_fn(|j, _| {
                let row = &truth.ranges.rows()[j];
                let e: f64 = noise.sample(StandardNormal);
                (row.emitter_pos_m - truth.pos).norm() + b + row.sigma_m * e
            });
            // No resampling: the weighted cloud and its centres stay to be read.
            let mut pf = ParticleFilter::new(
                ParticleBuffer::<4>::new(10).unwrap(),
                Resampling::Systematic,
                0.0,
            )
            .unwrap()
            .regularised();
            pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
            lik.set(&truth.ranges, &z);
            pf.update_linearised(&q, &lik, &mut rng).unwrap();
            let unbiased = 1.0 - pf.weight_square_sum();
            rb.push(sigma + pf.centre_moments().1[(3, 3)] / unbiased);
            plain.push(pf.sample_covariance()[(3, 3)] / unbiased);
            // Musso's kernel as the linearised update's resampling would size it: `D Dᵀ`
            // is the kernel `h² D Dᵀ` over h², against the drawn cloud's weighted
            // covariance (both undivided).
            let cloud = pf.sample_covariance()[(3, 3)];
            let mut pf = pf.with_kernel(KernelPlacement::Plain);
            pf.centred = Some(sigma_m);
            let (_, g, _) = pf.resample_and_kernel(&mut resampling).unwrap();
            musso.push(((g * g.transpose())[(3, 3)] / h2, cloud));
        }
        let stats = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() - 1) as f64;
            (m, var)
        };
        let ((m_rb, v_rb), (m_plain, v_plain)) = (stats(&rb), stats(&plain));
        // Within 4 standard errors of the mean, plus 2 %: the divisor removes the weighted
        // covariance's bias exactly only for weights independent of the points, and
        // these weights depend on the centres (a bias of order 1/N; measured 0.6 % for
        // the centres' estimate, 1.8 % for the cloud's).
        for (name, m, v) in [("centres", m_rb, v_rb), ("cloud", m_plain, v_plain)] {
            let se = (v / reps as f64).sqrt();
            assert!(
                (m - kalman_var).abs() < 4.0 * se + 0.02 * kalman_var,
                "{name}: {m} vs {kalman_var} (se {se})"
            );
        }
        // The draws carry Σ / V = 7/8 of the variance: integrated out, the estimate's
        // scatter falls by far more than the factor asserted (measured 64×).
        assert!(v_rb < 0.1 * v_plain, "scatter {v_rb} vs {v_plain}");
        // Musso's: the paired difference averages to zero within 4 standard errors, and
        // the centres' estimate scatters less than a tenth as much as the cloud's.
        let diff: Vec<f64> = musso.iter().map(|(m, c)| m - c).collect();
        let (m_diff, v_diff) = stats(&diff);
        let musso_k: Vec<f64> = musso.iter().map(|(m, _)| *m).collect();
        let cloud: Vec<f64> = musso.iter().map(|(_, c)| *c).collect();
        let ((_, v_musso), (m_cloud, v_cloud)) = (stats(&musso_k), stats(&cloud));
        let se = (v_diff / reps as f64).sqrt();
        assert!(
            m_diff.abs() < 4.0 * se,
            "Musso: {m_diff} (se {se}) of {m_cloud}"
        );
        assert!(
            v_musso < 0.1 * v_cloud,
            "Musso scatter {v_musso} vs {v_cloud}"
        );
    }

    /// With the position known, the clock is linear-Gaussian and the linearised proposal
    /// is the exact optimal one: the weighted cloud's clock mean and variance follow the
    /// textbook Kalman filter up to Monte Carlo error (4 standard errors of the prior
    /// sample's mean).
    #[test]
    fn linearised_proposal_follows_the_kalman_filter_on_a_linear_clock() {
        let mut truth =
            KnownPositionClock::new(TrialRng::new(6, 1).stream("test/linearised/noise"));
        let n = 20_000;
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .regularised();
        let mut rng = TrialRng::new(6, 0).stream("test/linearised");
        let (x0, p0) = truth.prior();
        pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let mut lik = PseudorangeLikelihood::with_capacity(3);
        for epoch in 0..10 {
            let z = truth.epoch(epoch);
            pf.propagate(&truth.process, 1.0).unwrap();
            lik.set(&truth.ranges, &z);
            let q = ProcessModel::<4>::q(&truth.process, &x0, 1.0);
            pf.update_linearised(&q, &lik, &mut rng).unwrap();
            let (km, kv) = truth.kalman();
            let (mean, var) = (pf.mean()[3], pf.covariance()[(3, 3)]);
            // The Monte Carlo error is set by the initial draw from the prior (404 m²).
            let se = (404.0 / n as f64).sqrt();
            assert!(
                (mean - km).abs() < 4.0 * se,
                "{epoch}: {mean} vs {km} (se {se})"
            );
            assert!((var / kv - 1.0).abs() < 0.05, "{epoch}: {var} vs {kv}");
        }
    }

    /// A receiver whose position and clock both random-walk, ranged by four emitters
    /// 20 000 km away (linear to micrometres over the cloud): the Rao-Blackwellised filter
    /// with the linearised proposal samples the position from its predictive density
    /// with the clock integrated out and carries the clock by its Kalman filter. Its
    /// position and clock must follow the four-state Kalman filter (the optimal filter of
    /// this linear-Gaussian model) up to Monte Carlo error; the first epoch, under the
    /// clock's flat prior, is a bootstrap one, and the clock's variance grows by its `Q`.
    /// The Monte Carlo error of the means is carried from epoch to epoch as the Kalman
    /// update contracts it: with only this epoch's (the former tolerance) the test
    /// failed on five of six other seeds of its stream, in the z and clock states; with
    /// the carried error it passes on seven of eight (seeds 1–9), the other (6) missing
    /// by 2 % in the clock at its seventh epoch.
    #[test]
    fn rao_blackwellised_linearised_proposal_follows_the_kalman_filter() {
        use crate::fusion::linear_kf::LinearKf;
        use nalgebra::{DMatrix, DVector};
        struct Wander;
        impl ProcessModel<4> for Wander {
            fn f(&self, x: &SVector<f64, 4>, _dt_s: f64) -> SVector<f64, 4> {
                *x
            }
            fn jacobian(&self, _x: &SVector<f64, 4>, _dt_s: f64) -> SMatrix<f64, 4, 4> {
                SMatrix::identity()
            }
            fn q(&self, _x: &SVector<f64, 4>, dt_s: f64) -> SMatrix<f64, 4, 4> {
                SMatrix::from_diagonal(&SVector::<f64, 4>::new(4.0, 4.0, 1.0, 9.0)) * dt_s
            }
        }
        let layout = position_clock_layout();
        let row = |az_deg: f64, el_deg: f64| {
            let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
            RangeRow {
                emitter_pos_m: Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin())
                    * 2.0e7,
                emitter_vel_mps: Vector3::zeros(),
                system: System::Dtmb,
                sigma_m: 3.0,
                sigma_rate_mps: 1.0,
            }
        };
        let ranges = Pseudoranges::<4, 4>::new(
            layout,
            [
                row(0.0, 70.0),
                row(100.0, 30.0),
                row(220.0, 40.0),
                row(300.0, 20.0),
            ],
        )
        .unwrap();
        let n = 20_000;
        let mut pf = rbpf_on_dtmb_clock(n);
        let mut rng = TrialRng::new(7, 0).stream("test/rbpf-linearised");
        let mut noise = TrialRng::new(7, 1).stream("test/rbpf-linearised/noise");
        let p0 = 100.0;
        let x0 = SVector::<f64, 4>::new(0.0, 0.0, 0.0, 0.0);
        pf.init_gaussian(&x0, &(SMatrix::<f64, 4, 4>::identity() * p0), &mut rng)
            .unwrap();
        let s = System::Dtmb.index();
        // The Kalman filter starts after the flat-prior epoch, from the particle filter's
        // own state then: the comparison is of the linearised epochs.
        let mut kf: Option<LinearKf> = None;
        let mut monte_carlo_var = [0.0; 4];
        let mut truth = SVector::<f64, 4>::new(5.0, -3.0, 2.0, 250.0);
        let mut lik = PseudorangeLikelihood::with_capacity(4);
        let q = ProcessModel::<4>::q(&Wander, &x0, 1.0);
        for epoch in 0..12 {
            for k in 0..4 {
                let w: f64 = noise.sample(StandardNormal);
                truth[k] += q[(k, k)].sqrt() * w;
            }
            let mut z = SVector::<f64, 4>::zeros();
            for (j, r) in ranges.rows().iter().enumerate() {
                let e: f64 = noise.sample(StandardNormal);
                z[j] = (r.emitter_pos_m - truth.xyz()).norm() + truth[3] + r.sigma_m * e;
            }
            pf.propagate(&Wander, 1.0).unwrap();
            lik.set(&ranges, &z);
            let var_before = pf.clock_variance_m2(s).unwrap();
            let update = pf.update_linearised(&q, &lik, &mut rng).unwrap();
            let var_after = pf.clock_variance_m2(s).unwrap();
            assert!(var_after.is_finite(), "{epoch}: the clock stays unresolved");
            let Some(kf) = kf.as_mut() else {
                assert!(
                    !var_before.is_finite(),
                    "the first epoch is under a flat prior"
                );
                kf = Some(
                    LinearKf::new(
                        DVector::from_iterator(4, pf.mean().iter().copied()),
                        DMatrix::from_iterator(4, 4, pf.covariance().iter().copied()),
                    )
                    .unwrap(),
                );
                continue;
            };
            // The clock's Kalman variance grew by its Q before the ranges shrank it.
            let info = 1.0 / (var_before + q[(3, 3)])
                + ranges
                    .rows()
                    .iter()
                    .map(|r| r.sigma_m.powi(-2))
                    .sum::<f64>();
            assert!(
                (var_after * info - 1.0).abs() < 1e-9,
                "{epoch}: {var_after}"
            );
            kf.predict(
                &DMatrix::identity(4, 4),
                &DMatrix::from_iterator(4, 4, q.iter().copied()),
            )
            .unwrap();
            let predicted_var: [f64; 4] = std::array::from_fn(|k| kf.covariance()[(k, k)]);
            let xp = kf.state().clone();
            let p = Vector3::new(xp[0], xp[1], xp[2]);
            let mut h = DMatrix::zeros(4, 4);
            let mut innov = DVector::zeros(4);
            for (j, r) in ranges.rows().iter().enumerate() {
                let d = p - r.emitter_pos_m;
                let dist = d.norm();
                for a in 0..3 {
                    h[(j, a)] = d[a] / dist;
                }
                h[(j, 3)] = 1.0;
                // The update takes `z − h(x̂) + H x̂`, the linearised measurement.
                innov[j] = z[j] - dist - xp[3] + (0..4).map(|k| h[(j, k)] * xp[k]).sum::<f64>();
            }
            let rm = DMatrix::from_diagonal(&DVector::from_iterator(
                4,
                ranges.rows().iter().map(|r| r.sigma_m * r.sigma_m),
            ));
            kf.update(&innov, &h, &rm).unwrap();
            let (mean, cov) = (pf.mean(), pf.covariance());
            for k in 0..4 {
                let kv = kf.covariance()[(k, k)];
                // The Monte Carlo error of the cloud's mean: this epoch's, the weighted
                // mean of N_eff draws and, after a resampling, N draws more, plus the
                // earlier epochs' as the update contracts it (`P⁺/P⁻` of the Kalman
                // filter; each state alone, the correlations left out).
                let fresh = 1.0 / update.n_eff
                    + if update.resampled {
                        1.0 / n as f64
                    } else {
                        0.0
                    };
                monte_carlo_var[k] =
                    (kv / predicted_var[k]).powi(2) * monte_carlo_var[k] + kv * fresh;
                let tol = 4.0 * monte_carlo_var[k].sqrt() + 1e-6;
                assert!(
                    (mean[k] - kf.state()[k]).abs() < tol,
                    "{epoch} state {k}: {} vs {} ({tol})",
                    mean[k],
                    kf.state()[k]
                );
                assert!(
                    (cov[(k, k)] / kv - 1.0).abs() < 0.1,
                    "{epoch} state {k}: variance {} vs {kv}",
                    cov[(k, k)]
                );
            }
        }
    }

    /// Each scheme is unbiased: the expected number of copies of particle i is N w_i, so
    /// the mean of the resampled cloud, averaged over many draws, is the weighted mean;
    /// the check allows 5 standard errors of that average.
    #[test]
    fn every_resampling_scheme_preserves_the_weighted_mean() {
        let n = 50;
        let draws = 4000;
        let values: Vec<f64> = (0..n)
            .map(|i| (i as f64 * 0.37).sin() * 10.0 + i as f64)
            .collect();
        let raw: Vec<f64> = (0..n).map(|i| ((i * 7919) % 13) as f64 + 0.25).collect();
        let total: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
        let target: f64 = values.iter().zip(&weights).map(|(v, w)| v * w).sum();
        for scheme in [
            Resampling::Systematic,
            Resampling::Stratified,
            Resampling::Residual,
        ] {
            let mut rng = TrialRng::new(9, 0).stream("test/resampling");
            let mut pf =
                ParticleFilter::new(ParticleBuffer::<1>::new(n).unwrap(), scheme, 1.0).unwrap();
            let (mut sum, mut sum_sq) = (0.0, 0.0);
            for _ in 0..draws {
                pf.particles_mut().column_mut(0).copy_from_slice(&values);
                pf.particles_mut().weights.copy_from_slice(&weights);
                pf.resample(&mut rng);
                let m = pf.particles().column(0).iter().sum::<f64>() / n as f64;
                sum += m;
                sum_sq += m * m;
            }
            let avg = sum / draws as f64;
            let var = (sum_sq / draws as f64 - avg * avg).max(0.0);
            let se = (var / draws as f64).sqrt().max(1e-12);
            assert!(
                (avg - target).abs() <= 5.0 * se + 1e-9,
                "{scheme:?}: {avg} vs {target} (se {se})"
            );
        }
    }

    /// The particles of the kernel tests below.
    const KERNEL_TEST_PARTICLES: usize = 20_000;

    /// A regularised filter with the kernel `placement` over a 4-state Gaussian cloud of
    /// [`KERNEL_TEST_PARTICLES`] (means 1, −2, 3, 100; variances 4, 9, 1, 25), drawn from
    /// `rng`, which is returned for the test's resampling.
    fn kernel_test_cloud(
        mut rng: crate::core::StreamRng,
        placement: KernelPlacement,
        static_cols: [bool; 4],
    ) -> (ParticleFilter<4>, crate::core::StreamRng) {
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(KERNEL_TEST_PARTICLES).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .regularised()
        .with_kernel(placement)
        .with_static_components(static_cols);
        let mean = SVector::<f64, 4>::new(1.0, -2.0, 3.0, 100.0);
        let cov = SMatrix::<f64, 4, 4>::from_diagonal(&SVector::<f64, 4>::new(4.0, 9.0, 1.0, 25.0));
        pf.init_gaussian(&mean, &cov, &mut rng).unwrap();
        (pf, rng)
    }

    /// The regularisation kernel with the shrinkage keeps the cloud's mean and
    /// covariance (up to Monte Carlo error) and spreads duplicated particles apart.
    #[test]
    fn regularised_resampling_keeps_the_moments_and_separates_duplicates() {
        let (mut pf, mut rng) = kernel_test_cloud(
            TrialRng::new(11, 0).stream("test/rpf"),
            KernelPlacement::Shrunk,
            [false; 4],
        );
        let (m0, c0) = (pf.mean(), pf.covariance());
        pf.resample_regularised(&mut rng);
        let (m1, c1) = (pf.mean(), pf.covariance());
        for k in 0..4 {
            let sd = c0[(k, k)].sqrt();
            assert!((m1[k] - m0[k]).abs() < 0.05 * sd, "mean {k}");
            assert!((c1[(k, k)] / c0[(k, k)] - 1.0).abs() < 0.05, "variance {k}");
        }
        let col = pf.particles().column(0);
        let mut sorted = col.to_vec();
        sorted.sort_by(f64::total_cmp);
        sorted.dedup();
        assert_eq!(
            sorted.len(),
            col.len(),
            "no two particles coincide after the kernel"
        );
    }

    /// With uneven weights the shrunk kernel keeps the unbiased estimate of the posterior
    /// covariance, the weighted covariance over `1 − Σ w_i²`, not the weighted covariance
    /// itself: two particles carrying 0.3 of the weight each (`Σ w_i² ≈ 0.18`) leave the
    /// jittered cloud with 1/0.82 = 1.22 times the weighted variance, each computed here
    /// from the cloud before the resampling.
    #[test]
    fn the_shrunk_kernel_keeps_the_unbiased_covariance_of_uneven_weights() {
        let (mut pf, mut rng) = kernel_test_cloud(
            TrialRng::new(11, 2).stream("test/rpf-unbiased"),
            KernelPlacement::Shrunk,
            [false; 4],
        );
        let n = KERNEL_TEST_PARTICLES;
        let rest = 0.4 / (n - 2) as f64;
        for (i, w) in pf.buf.weights.iter_mut().enumerate() {
            *w = if i < 2 { 0.3 } else { rest };
        }
        let sum_sq: f64 = pf.buf.weights.iter().map(|w| w * w).sum();
        let weighted = pf.covariance();
        pf.resample_regularised(&mut rng);
        let after = pf.covariance();
        for k in 0..4 {
            let ratio = after[(k, k)] / weighted[(k, k)];
            // The unbiased estimate, plus its Monte Carlo error (`1/N_eff + 1/N` of it).
            let expected = (1.0 + sum_sq + 1.0 / n as f64) / (1.0 - sum_sq);
            assert!(
                (ratio / expected - 1.0).abs() < 0.05,
                "state {k}: variance {ratio} of the weighted one, expected {expected}"
            );
        }
    }

    /// Liu & West's kernel is sized by the weighted cloud's effective sample size: with the
    /// weight spread evenly over 8 of the 20 000 particles (`N_eff` = 8) every copy of a
    /// resampled particle is jittered by `(h² + 1/N_eff + 1/N) D Dᵀ` with
    /// `h² = (4 / (8 · 6))^{2/8} ≈ 0.54` (four sampled states), not
    /// `(4 / (20 000 · 6))^{2/8} ≈ 0.076`: 0.67 against 0.20. `D Dᵀ` is computed
    /// here as the 8 particles' sample covariance (divisor 7, the unbiased estimate the
    /// kernel keeps), and the jitter's variance as the spread among the copies of each
    /// parent.
    #[test]
    fn the_shrunk_kernel_is_sized_by_the_effective_sample_size() {
        let (mut pf, mut rng) = kernel_test_cloud(
            TrialRng::new(11, 3).stream("test/rpf-neff-bandwidth"),
            KernelPlacement::Shrunk,
            [false; 4],
        );
        const CARRIERS: usize = 8;
        for (i, w) in pf.buf.weights.iter_mut().enumerate() {
            *w = if i < CARRIERS {
                1.0 / CARRIERS as f64
            } else {
                0.0
            };
        }
        let before: Vec<SVector<f64, 4>> = (0..CARRIERS).map(|i| pf.buf.get(i)).collect();
        let centre = before.iter().sum::<SVector<f64, 4>>() / CARRIERS as f64;
        let sample_var = |k: usize| {
            before
                .iter()
                .map(|x| (x[k] - centre[k]).powi(2))
                .sum::<f64>()
                / (CARRIERS - 1) as f64
        };
        pf.resample_regularised(&mut rng);
        let h2 = (4.0_f64 / (CARRIERS as f64 * 6.0)).powf(2.0 / 8.0);
        // The jitter also carries the Monte Carlo error, `1/N_eff + 1/N` of the covariance.
        let jitter_share = h2 + 1.0 / CARRIERS as f64 + 1.0 / KERNEL_TEST_PARTICLES as f64;
        for k in 0..4 {
            let (mut sum, mut sum_sq) = ([0.0; CARRIERS], [0.0; CARRIERS]);
            let mut count = [0usize; CARRIERS];
            for (i, &parent) in pf.buf.idx.iter().enumerate() {
                let x = pf.buf.get(i)[k];
                sum[parent] += x;
                sum_sq[parent] += x * x;
                count[parent] += 1;
            }
            let (mut within, mut dof) = (0.0, 0usize);
            for p in 0..CARRIERS {
                let c = count[p] as f64;
                within += sum_sq[p] - sum[p] * sum[p] / c;
                dof += count[p] - 1;
            }
            let jitter_var = within / dof as f64;
            let expected = jitter_share * sample_var(k);
            assert!(
                (jitter_var / expected - 1.0).abs() < 0.05,
                "state {k}: jitter variance {jitter_var}, expected {expected}"
            );
        }
    }

    /// The shrunk kernel's cloud covers the Monte Carlo error of its own mean. A state
    /// the weights do not depend on (here the weights are drawn apart from the cloud, as
    /// the ranges weigh a particle without looking at its velocity) keeps its posterior,
    /// the prior `N(μ, σ²)`, yet the regularised cloud's mean misses `μ`: by the weighted
    /// mean's error, of variance `σ² Σ w_i²` exactly, and by the resampling and the
    /// jitter. Over many independent ten-particle clouds the mean square of that miss
    /// plus `σ²` is the error variance of the estimate, and the cloud's own variance
    /// after the kernel (the spread of its ten equally weighted particles with the
    /// divisor `N − 1`, the unbiased estimate the kernel keeps) must match it on average:
    /// within 5 %, where a kernel that keeps only the posterior's covariance (the former
    /// one) falls 18 % short (4.12 against 5.05 for `σ² = 4`).
    #[test]
    fn the_shrunk_kernel_covers_the_monte_carlo_error_of_its_mean() {
        const PARTICLES: usize = 10;
        const CLOUDS: usize = 40_000;
        let mut rng = TrialRng::new(11, 4).stream("test/rpf-monte-carlo-error");
        let mean = SVector::<f64, 4>::new(1.0, -2.0, 3.0, 100.0);
        let var = SVector::<f64, 4>::new(4.0, 9.0, 1.0, 25.0);
        let cov = SMatrix::<f64, 4, 4>::from_diagonal(&var);
        let (mut miss_sq, mut reported) = (SVector::<f64, 4>::zeros(), SVector::<f64, 4>::zeros());
        for _ in 0..CLOUDS {
            let mut pf = ParticleFilter::new(
                ParticleBuffer::<4>::new(PARTICLES).unwrap(),
                Resampling::Systematic,
                1.0,
            )
            .unwrap()
            .regularised();
            pf.init_gaussian(&mean, &cov, &mut rng).unwrap();
            // Log-normal weights (σ = 1): N_eff about half of N.
            let mut total = 0.0;
            for w in pf.buf.weights.iter_mut() {
                let g: f64 = rng.sample(StandardNormal);
                *w = g.exp();
                total += *w;
            }
            pf.buf.weights.iter_mut().for_each(|w| *w /= total);
            pf.resample_regularised(&mut rng);
            let (m, p) = (pf.mean(), pf.covariance());
            for k in 0..4 {
                miss_sq[k] += (m[k] - mean[k]).powi(2) / CLOUDS as f64;
                let unbiased = p[(k, k)] * PARTICLES as f64 / (PARTICLES - 1) as f64;
                reported[k] += unbiased / CLOUDS as f64;
            }
        }
        for k in 0..4 {
            let error_var = var[k] + miss_sq[k];
            assert!(
                (reported[k] / error_var - 1.0).abs() < 0.05,
                "state {k}: the cloud reports {} where the estimate's error variance is {error_var} \
                 (posterior {}, Monte Carlo {})",
                reported[k],
                var[k],
                miss_sq[k]
            );
        }
    }

    /// Musso's placement adds the kernel to the resampled cloud as it is: the variance
    /// grows by the factor `1 + h_opt²` (`h_opt` of 4 sampled dimensions and N = 20 000),
    /// which is what the shrunk kernel above avoids.
    #[test]
    fn musso_kernel_inflates_the_cloud_by_the_bandwidth() {
        let n = KERNEL_TEST_PARTICLES;
        let (mut pf, mut rng) = kernel_test_cloud(
            TrialRng::new(11, 1).stream("test/rpf-musso"),
            KernelPlacement::Plain,
            [false; 4],
        );
        let c0 = pf.covariance();
        pf.resample_regularised(&mut rng);
        let c1 = pf.covariance();
        let h2 = (4.0 / (n as f64 * 6.0)).powf(2.0 / 8.0);
        for k in 0..4 {
            let ratio = c1[(k, k)] / c0[(k, k)];
            assert!(
                (ratio - (1.0 + h2)).abs() < 0.04,
                "variance {k}: {ratio} vs {}",
                1.0 + h2
            );
        }
    }

    /// Each kernel where its authors put it: with [`KernelPlacement::ShrunkStatic`] the
    /// static components keep their variance (Liu & West's shrinkage) and the others grow
    /// by `1 + h_opt²` (Musso's plain kernel), from one resampling of the same cloud as
    /// the two tests above; with no static component it is Musso's placement.
    #[test]
    fn the_static_shrunk_kernel_keeps_the_static_spread_and_inflates_the_rest() {
        let n = KERNEL_TEST_PARTICLES;
        let run = |static_cols: [bool; 4]| {
            let (mut pf, mut rng) = kernel_test_cloud(
                TrialRng::new(11, 2).stream("test/rpf-static"),
                KernelPlacement::ShrunkStatic,
                static_cols,
            );
            let (m0, c0) = (pf.mean(), pf.covariance());
            pf.resample_regularised(&mut rng);
            let (m1, c1) = (pf.mean(), pf.covariance());
            (m0, c0, m1, c1)
        };
        let h2 = (4.0 / (n as f64 * 6.0)).powf(2.0 / 8.0);
        let (m0, c0, m1, c1) = run([false, false, true, true]);
        for k in 0..4 {
            let sd = c0[(k, k)].sqrt();
            assert!((m1[k] - m0[k]).abs() < 0.05 * sd, "mean {k}");
            let want = if k >= 2 { 1.0 } else { 1.0 + h2 };
            let ratio = c1[(k, k)] / c0[(k, k)];
            assert!(
                (ratio - want).abs() < 0.04,
                "variance {k}: {ratio} vs {want}"
            );
        }
        let (_, c0, _, c1) = run([false; 4]);
        for k in 0..4 {
            let ratio = c1[(k, k)] / c0[(k, k)];
            assert!((ratio - (1.0 + h2)).abs() < 0.04, "variance {k}: {ratio}");
        }
    }

    /// The joint factor's conditional moments equal the Schur complement computed with an
    /// explicit inverse: `E[x_l | x_s] − μ_l = Σ_ls Σ_ss⁻¹ (x_s − μ_s)` and
    /// `Cov[x_l | x_s] = Σ_ll − Σ_ls Σ_ss⁻¹ Σ_sl`, on a full-rank covariance with the
    /// sampled components not first in the state.
    #[test]
    fn the_joint_factor_conditions_as_the_schur_complement() {
        let a = SMatrix::<f64, 5, 5>::from_fn(|i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 1.5 + (i == j) as u8 as f64 * 4.0
        });
        let sigma = a * a.transpose();
        let sampled = [false, true, false, true, false];
        let linear = [true, false, true, false, true];
        let joint = JointFactor::new(&sigma, &sampled, &linear).unwrap();
        let (s, l) = ([1usize, 3], [0usize, 2, 4]);
        let sss = SMatrix::<f64, 2, 2>::from_fn(|i, j| sigma[(s[i], s[j])]);
        let sls = SMatrix::<f64, 3, 2>::from_fn(|i, j| sigma[(l[i], s[j])]);
        let sll = SMatrix::<f64, 3, 3>::from_fn(|i, j| sigma[(l[i], l[j])]);
        let gain = sls * sss.try_inverse().unwrap();
        let schur = sll - gain * sls.transpose();
        let p = joint.conditional_covariance();
        for i in 0..3 {
            for j in 0..3 {
                assert!((p[(l[i], l[j])] - schur[(i, j)]).abs() < 1e-9 * schur.amax());
            }
            for k in s {
                assert_eq!(p[(l[i], k)], 0.0);
            }
        }
        let mut rng = TrialRng::new(5, 0).stream("test/joint");
        for _ in 0..10 {
            let mut x = SVector::<f64, 5>::zeros();
            joint.draw(&mut x, &mut rng);
            let ds = SVector::<f64, 2>::new(x[1], x[3]);
            let dl = gain * ds;
            for i in 0..3 {
                assert!(
                    (x[l[i]] - dl[i]).abs() < 1e-9 * (1.0 + dl.amax()),
                    "component {}",
                    l[i]
                );
            }
        }
    }

    /// The marginalised filter on a linear-Gaussian model (2-D constant velocity, the
    /// positions measured directly): the positions are sampled and the velocities carried
    /// by the Kalman filters, and with many particles the estimate and its covariance
    /// (cloud plus Kalman part) are the Kalman filter's.
    #[test]
    fn marginalised_filter_follows_the_kalman_filter_on_a_linear_model() {
        use crate::fusion::kalman::Ekf;
        use crate::fusion::models::{ConstantVelocity, PositionFixModel};
        let cv = ConstantVelocity::<4>::new(0.3).unwrap();
        let fix =
            PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity() * 9.0).unwrap();
        let x0 = SVector::<f64, 4>::new(0.0, 1.0, 0.0, -0.5);
        let p0 = SMatrix::<f64, 4, 4>::from_diagonal(&SVector::<f64, 4>::new(25.0, 4.0, 25.0, 4.0));
        let mut rng = TrialRng::new(17, 0).stream("test/mpf");
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(40_000).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .marginalised([Some(0), Some(2), None], [None; System::COUNT])
        .unwrap();
        assert_eq!(pf.variant(), PfVariant::Marginalised);
        pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let mut kf = Ekf::new(x0, p0).unwrap();
        let mut x = x0;
        for k in 0..15 {
            x = ProcessModel::<4>::f(&cv, &x, 1.0);
            let z = SVector::<f64, 2>::new(x[0] + 3.0 * (k as f64 * 0.7).sin(), x[2] - 2.0);
            kf.predict(&cv, 1.0).unwrap();
            kf.update(&fix, &z);
            pf.predict(&cv, 1.0, &mut rng).unwrap();
            assert!(!pf.update(&fix, &z, &mut rng).degenerate);
        }
        let (m, c) = (pf.mean(), pf.covariance());
        let (mk, ck) = (kf.state(), kf.covariance());
        for i in 0..4 {
            let sd = ck[(i, i)].sqrt();
            assert!(
                (m[i] - mk[i]).abs() < 0.05 * sd,
                "mean {i}: {} vs {}",
                m[i],
                mk[i]
            );
            assert!(
                (c[(i, i)] / ck[(i, i)] - 1.0).abs() < 0.08,
                "variance {i}: {} vs {}",
                c[(i, i)],
                ck[(i, i)]
            );
        }
        // The velocities are never sampled: their Kalman part carries most of their
        // variance, not the cloud.
        assert!(pf.mm.as_ref().unwrap().p[(1, 1)] > 0.0);
        // A position column that is also a clock is refused.
        let bad = ParticleFilter::new(
            ParticleBuffer::<4>::new(4).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .marginalised(
            [Some(3), None, None],
            std::array::from_fn(|s| (s == 0).then_some(3)),
        );
        assert!(bad.is_err());
    }

    /// The Gaussian particle filter on a linear-Gaussian model (2-D constant velocity, the
    /// positions measured directly) is exact up to Monte Carlo error: every epoch its mean
    /// and covariance are the Kalman filter's. The tolerance is derived from N: one
    /// epoch's importance-sampling error in the mean of component i has variance about
    /// `P_ii / N_eff` (Kish's effective sample size of that epoch's weights), and without
    /// credit for the filter forgetting earlier errors the k-th epoch carries at most k
    /// of them: `|μ_i − μ_KF,i| < 4 √(k P_ii / N_eff,min)`. A sample variance has relative
    /// standard error `√(2 / N_eff)` per epoch, accumulated the same way.
    #[test]
    fn gaussian_filter_equals_the_kalman_filter_on_a_linear_model() {
        use crate::fusion::kalman::Ekf;
        use crate::fusion::models::{ConstantVelocity, PositionFixModel};
        let cv = ConstantVelocity::<4>::new(0.3).unwrap();
        let fix =
            PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity() * 9.0).unwrap();
        let x0 = SVector::<f64, 4>::new(0.0, 1.0, 0.0, -0.5);
        let p0 = SMatrix::<f64, 4, 4>::from_diagonal(&SVector::<f64, 4>::new(25.0, 4.0, 25.0, 4.0));
        let mut rng = TrialRng::new(19, 0).stream("test/gpf");
        let n = 40_000;
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).unwrap(),
            Resampling::Systematic,
            // The threshold is ignored: the Gaussian filter never resamples.
            1.0,
        )
        .unwrap()
        .gaussian();
        assert_eq!(pf.variant(), PfVariant::Gaussian);
        pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let mut kf = Ekf::new(x0, p0).unwrap();
        let mut x = x0;
        let mut n_eff_min = f64::INFINITY;
        for k in 1..=15 {
            x = ProcessModel::<4>::f(&cv, &x, 1.0);
            let z = SVector::<f64, 2>::new(x[0] + 3.0 * (k as f64 * 0.7).sin(), x[2] - 2.0);
            kf.predict(&cv, 1.0).unwrap();
            kf.update(&fix, &z);
            pf.predict(&cv, 1.0, &mut rng).unwrap();
            let up = pf.update(&fix, &z, &mut rng);
            assert!(!up.degenerate && !up.resampled);
            n_eff_min = n_eff_min.min(up.n_eff);
            let (m, c) = (pf.mean(), pf.covariance());
            let (mk, ck) = (kf.state(), kf.covariance());
            let kf64 = k as f64;
            for i in 0..4 {
                let tol_mean = 4.0 * (kf64 * ck[(i, i)] / n_eff_min).sqrt();
                assert!(
                    (m[i] - mk[i]).abs() < tol_mean,
                    "epoch {k}, mean {i}: {} vs {} (tolerance {tol_mean})",
                    m[i],
                    mk[i]
                );
                let tol_var = 4.0 * (2.0 * kf64 / n_eff_min).sqrt();
                assert!(
                    (c[(i, i)] / ck[(i, i)] - 1.0).abs() < tol_var,
                    "epoch {k}, variance {i}: {} vs {} (tolerance {tol_var})",
                    c[(i, i)],
                    ck[(i, i)]
                );
            }
            // The cross-covariance of position and velocity too (correlation error).
            let rho = |p: &SMatrix<f64, 4, 4>| p[(0, 1)] / (p[(0, 0)] * p[(1, 1)]).sqrt();
            let tol_rho = 4.0 * (kf64 / n_eff_min).sqrt();
            assert!(
                (rho(&c) - rho(ck)).abs() < tol_rho,
                "epoch {k}: correlation {} vs {}",
                rho(&c),
                rho(ck)
            );
        }
        // The weights of a prior draw against a 3 m fix: far from degenerate.
        assert!(n_eff_min > 0.2 * n as f64, "N_eff {n_eff_min}");
    }

    /// With the position known (a singular covariance: three of four components have no
    /// variance) the Gaussian filter's clock follows the textbook Kalman filter through
    /// the column-wise pseudorange likelihood, with the tolerance of the test above.
    #[test]
    fn gaussian_filter_follows_the_kalman_filter_with_a_singular_covariance() {
        gaussian_filter_on_the_known_position_clock(false);
    }

    /// The Gaussian filter with the linearised importance function on the known-position
    /// clock: the ranges are linear in the clock, so the importance function is the exact
    /// posterior, every weight stays 1/N (N_eff = N to rounding), and the cloud's clock
    /// mean and variance follow the textbook Kalman filter with the tolerances of the
    /// test above at N_eff = N.
    #[test]
    fn linearised_gaussian_filter_follows_the_kalman_filter_with_uniform_weights() {
        gaussian_filter_on_the_known_position_clock(true);
    }

    /// Ten epochs of a 20 000-particle Gaussian filter on [`KnownPositionClock`], weighted
    /// by the column-wise likelihood or drawn from the linearised importance function.
    fn gaussian_filter_on_the_known_position_clock(linearised: bool) {
        let name = if linearised {
            "gpf-lin-clock"
        } else {
            "gpf-clock"
        };
        let mut truth = KnownPositionClock::new(
            TrialRng::new(6, if linearised { 5 } else { 3 }).stream(&format!("test/{name}/noise")),
        );
        let pos = truth.pos;
        let n = 20_000;
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .gaussian();
        let mut rng =
            TrialRng::new(6, if linearised { 4 } else { 2 }).stream(&format!("test/{name}"));
        let (x0, p0) = truth.prior();
        pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let mut lik = PseudorangeLikelihood::with_capacity(3);
        let mut n_eff_min = f64::INFINITY;
        for epoch in 1..=10 {
            let z = truth.epoch(epoch);
            pf.predict(&truth.process, 1.0, &mut rng).unwrap();
            lik.set(&truth.ranges, &z);
            let up = if linearised {
                let q = ProcessModel::<4>::q(&truth.process, &x0, 1.0);
                let up = pf.update_linearised(&q, &lik, &mut rng).unwrap();
                assert!(
                    (up.n_eff / n as f64 - 1.0).abs() < 1e-9,
                    "{epoch}: N_eff {}",
                    up.n_eff
                );
                up
            } else {
                pf.update_ranges(&lik, &mut rng)
            };
            assert!(!up.degenerate && !up.resampled);
            n_eff_min = n_eff_min.min(up.n_eff);
            truth.assert_followed(epoch, &pf, n_eff_min);
            // The known position stays known: no particle moved off it.
            for (k, p) in pos.iter().enumerate() {
                assert!(pf
                    .particles()
                    .column(k)
                    .iter()
                    .all(|x| (x - p).abs() < 1e-9));
            }
        }
    }

    /// Where the linearisation is poor (an emitter 150 m from a prior of σ 30 m), the
    /// weights `p(z | x) / p_lin(z | x)` carry the importance function to the exact
    /// posterior: the weighted mean equals the posterior mean computed independently by
    /// importance sampling from the prior, while the importance function's own mean (the
    /// EKF update, i.e. the cloud without the weights) is far from it.
    #[test]
    fn linearised_gaussian_weights_correct_a_poor_linearisation() {
        let layout = position_clock_layout();
        let row = |x: f64, y: f64, sigma_m: f64| RangeRow {
            emitter_pos_m: Vector3::new(x, y, 0.0),
            emitter_vel_mps: Vector3::zeros(),
            system: System::Dtmb,
            sigma_m,
            sigma_rate_mps: 1.0,
        };
        // A far emitter fixes x; the near one, 133 m from the truth, gives y through a
        // circle that the line x = 30 m meets at y = 20 m and at y = 280 m, the second
        // 9 prior σ out: one mode. Linearised at the prior mean the near range puts y at
        // 16.6 m, a proposal about half a posterior σ off, which importance weights can
        // carry to the posterior.
        let ranges =
            Pseudoranges::<4, 2>::new(layout, [row(-3000.0, 0.0, 5.0), row(0.0, 150.0, 5.0)])
                .unwrap();
        // The truth at (30, 20, 0), clock known (0) and the prior N(0, 30² I) in the plane.
        let truth = Vector3::new(30.0, 20.0, 0.0);
        let z = SVector::<f64, 2>::from_fn(|j, _| (ranges.rows()[j].emitter_pos_m - truth).norm());
        let x0 = SVector::<f64, 4>::zeros();
        let p0 =
            SMatrix::<f64, 4, 4>::from_diagonal(&SVector::<f64, 4>::new(900.0, 900.0, 0.0, 0.0));
        let mut lik = PseudorangeLikelihood::with_capacity(2);
        lik.set(&ranges, &z);
        let n = 400_000;
        let new_pf = |gaussian: bool| {
            let pf = ParticleFilter::new(
                ParticleBuffer::<4>::new(n).unwrap(),
                Resampling::Systematic,
                0.0,
            )
            .unwrap();
            if gaussian {
                pf.gaussian()
            } else {
                pf
            }
        };
        // The exact posterior mean: prior draws weighted by the likelihood (no resampling).
        let mut exact = new_pf(false);
        let mut rng = TrialRng::new(7, 0).stream("test/gpf-lin-exact");
        exact.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let up = exact.update_ranges(&lik, &mut rng);
        let se = (exact.covariance()[(0, 0)] / up.n_eff).sqrt();
        let exact_mean = exact.mean();
        // The linearised Gaussian filter: one epoch from the same prior.
        let mut pf = new_pf(true);
        let mut rng = TrialRng::new(7, 1).stream("test/gpf-lin");
        pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
        let q = SMatrix::<f64, 4, 4>::zeros();
        let up_lin = pf.update_linearised(&q, &lik, &mut rng).unwrap();
        let weighted = pf.mean();
        let b = pf.particles();
        let unweighted = Vector3::from_fn(|a, _| b.column(a).iter().sum::<f64>() / n as f64);
        let tol = 4.0 * se + 4.0 * (pf.covariance()[(0, 0)] / up_lin.n_eff).sqrt();
        for a in 0..2 {
            assert!(
                (weighted[a] - exact_mean[a]).abs() < tol,
                "axis {a}: weighted {} vs exact {} (tolerance {tol})",
                weighted[a],
                exact_mean[a]
            );
        }
        let off = (unweighted - Vector3::new(exact_mean[0], exact_mean[1], 0.0)).norm();
        assert!(
            off > 10.0 * tol,
            "the linearisation is not poor here: {off} m"
        );
        assert!(up_lin.n_eff < 0.9 * n as f64 && up_lin.n_eff > 0.01 * n as f64);
    }

    /// On a static state with no measurement, the Gaussian filter's covariance after k
    /// predictions is a product of k sample covariances of N draws. With the weighted
    /// (1/N) estimator its expectation is `(1 − 1/N)^k Σ₀`; with the unbiased one, `Σ₀`.
    /// Checked over 4000 independent filters (N = 10, k = 5: 0.59 against 1), each mean
    /// within 4 of its empirical standard errors.
    #[test]
    fn the_gaussian_covariance_estimators_have_their_analytic_expectations() {
        let (n, k, runs) = (10usize, 5, 4000);
        let model = StaticClock { clock_q_m2ps: 0.0 };
        let x0 = SVector::<f64, 4>::new(1.0, 2.0, 3.0, 4.0);
        let p0 =
            SMatrix::<f64, 4, 4>::from_diagonal(&SVector::<f64, 4>::new(100.0, 25.0, 1.0, 400.0));
        for (estimate, expected) in [
            (CovarianceEstimate::Weighted, (1.0 - 1.0 / n as f64).powi(k)),
            (CovarianceEstimate::Unbiased, 1.0),
        ] {
            let mut rng = TrialRng::new(8, 0).stream(&format!("test/gpf-cov/{estimate:?}"));
            let mut ratios = [Vec::with_capacity(runs), Vec::with_capacity(runs)];
            for _ in 0..runs {
                let mut pf = ParticleFilter::new(
                    ParticleBuffer::<4>::new(n).unwrap(),
                    Resampling::Systematic,
                    0.5,
                )
                .unwrap()
                .gaussian()
                .with_covariance_estimate(estimate);
                pf.init_gaussian(&x0, &p0, &mut rng).unwrap();
                // The first prediction takes the moments of the initial draw, so k
                // predictions see k + 1 sample covariances; the reported covariance after
                // k − 1 predictions is the k-th.
                for _ in 0..k - 1 {
                    pf.predict(&model, 1.0, &mut rng).unwrap();
                }
                let c = pf.covariance();
                ratios[0].push(c[(0, 0)] / p0[(0, 0)]);
                ratios[1].push(c[(3, 3)] / p0[(3, 3)]);
            }
            for (axis, r) in ratios.iter().enumerate() {
                let mean = r.iter().sum::<f64>() / runs as f64;
                let var = r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (runs - 1) as f64;
                let se = (var / runs as f64).sqrt();
                assert!(
                    (mean - expected).abs() < 4.0 * se,
                    "{estimate:?}, axis {axis}: mean ratio {mean} vs {expected} (se {se})"
                );
            }
        }
    }

    /// A direct measurement of each of two states, `z = x + v`, `v ~ N(0, σ² I)`.
    struct DirectLikelihood {
        z: [f64; 2],
        sigma: f64,
    }

    impl SoaLikelihood<2> for DirectLikelihood {
        fn add_log_likelihood(&self, cols: &[f64], out: &mut [f64]) {
            let n = out.len();
            for (k, zk) in self.z.iter().enumerate() {
                for (o, x) in out.iter_mut().zip(&cols[k * n..(k + 1) * n]) {
                    *o += -0.5 * (zk - x) * (zk - x) / (self.sigma * self.sigma);
                }
            }
        }
    }

    /// Progressive correction against the conjugate posterior: a prior `N(0, 10² I)` and
    /// a direct measurement 2.5 σ out in its tail with σ = 0.5 m (the likelihood 20 times
    /// narrower than the cloud). All at once, 2 000 particles leave a handful effective;
    /// in stages the cloud reaches the analytic posterior `N(z·100/100.25, 0.2494 I)`:
    /// over 20 seeds its mean is within 0.15 posterior σ in RMS (0.09 measured over 60
    /// seeds; a single run's error is a draw of that spread, so the bound is on the RMS)
    /// and each run's variance within 0.75–1.33 of the posterior's. A likelihood as wide
    /// as the cloud is the single update, bit for bit.
    #[test]
    fn progressive_correction_reaches_the_conjugate_posterior() {
        let n = 2000;
        let prior_var = 100.0;
        let lik = DirectLikelihood {
            z: [25.0, -15.0],
            sigma: 0.5,
        };
        let post_var = 1.0 / (1.0 / prior_var + 1.0 / (lik.sigma * lik.sigma));
        let new_pf = |progressive: bool, seed: u64| {
            let mut rng = TrialRng::new(seed, 0).stream("test/pf-progressive");
            let mut pf = ParticleFilter::new(
                ParticleBuffer::<2>::new(n).unwrap(),
                Resampling::Systematic,
                0.5,
            )
            .unwrap()
            .regularised()
            .with_progressive_correction(progressive);
            pf.init_gaussian(
                &SVector::<f64, 2>::zeros(),
                &(SMatrix::<f64, 2, 2>::identity() * prior_var),
                &mut rng,
            )
            .unwrap();
            (pf, rng)
        };
        let (mut sq_pc, mut sq_single) = (0.0f64, 0.0f64);
        let seeds = 20;
        for seed in 0..seeds {
            let (mut pf, mut rng) = new_pf(true, seed);
            let up = pf.update_soa(&lik, &mut rng);
            assert!(!up.degenerate);
            let (m, c) = (pf.mean(), pf.covariance());
            for k in 0..2 {
                let post_mean = lik.z[k] * prior_var / (prior_var + lik.sigma * lik.sigma);
                sq_pc += ((m[k] - post_mean) / post_var.sqrt()).powi(2);
                let ratio = c[(k, k)] / post_var;
                assert!(
                    (0.75..1.33).contains(&ratio),
                    "seed {seed}, state {k}: variance {ratio} of the posterior's"
                );
            }
            let (mut single, mut rng) = new_pf(false, seed);
            single.update_soa(&lik, &mut rng);
            let m = single.mean();
            for k in 0..2 {
                let post_mean = lik.z[k] * prior_var / (prior_var + lik.sigma * lik.sigma);
                sq_single += ((m[k] - post_mean) / post_var.sqrt()).powi(2);
            }
        }
        let rms_pc = (sq_pc / (2 * seeds) as f64).sqrt();
        let rms_single = (sq_single / (2 * seeds) as f64).sqrt();
        assert!(rms_pc < 0.15, "progressive: mean {rms_pc} σ off in RMS");
        // The single update's error, for scale: the same seeds leave it several times
        // further from the posterior mean.
        assert!(
            rms_single > 2.0 * rms_pc,
            "single {rms_single} σ, progressive {rms_pc} σ"
        );

        // One stage when the full likelihood keeps N_eff ≥ ½ N: bit for bit.
        let wide = DirectLikelihood {
            z: [1.0, -2.0],
            sigma: 30.0,
        };
        let (mut a, mut ra) = new_pf(true, 9);
        let (mut b, mut rb) = new_pf(false, 9);
        let ua = a.update_soa(&wide, &mut ra);
        let ub = b.update_soa(&wide, &mut rb);
        assert_eq!(ua, ub);
        assert_eq!(a.particles(), b.particles());
    }

    /// The regularised filter's kernel, deferred by a linearised epoch: after the
    /// resampling the particles are only shrunk, the kept kernel covariance is exactly
    /// `h_opt² D Dᵀ` of the cloud before it, `propagate` moves it as `F K Fᵀ`, and the next
    /// linearised update draws it (once): with an uninformative range the cloud's variance
    /// grows by the kernel, in 8 dimensions where `h² = 0.14` stands well above the Monte
    /// Carlo error of 50 000 particles (tolerance 25 % of the kernel, about four standard
    /// errors of the difference of two sample variances).
    #[test]
    fn the_deferred_kernel_is_kept_moved_and_drawn_once() {
        #[derive(Clone, Copy)]
        struct Drift8;
        impl ProcessModel<8> for Drift8 {
            fn f(&self, x: &SVector<f64, 8>, dt_s: f64) -> SVector<f64, 8> {
                self.jacobian(x, dt_s) * x
            }
            fn jacobian(&self, _x: &SVector<f64, 8>, dt_s: f64) -> SMatrix<f64, 8, 8> {
                // Component 0 integrates component 4 (a position and its velocity).
                let mut f = SMatrix::<f64, 8, 8>::identity();
                f[(0, 4)] = dt_s;
                f
            }
            fn q(&self, _x: &SVector<f64, 8>, _dt_s: f64) -> SMatrix<f64, 8, 8> {
                SMatrix::zeros()
            }
        }
        let n = 50_000;
        let mut rng = TrialRng::new(12, 0).stream("test/rpf-deferred");
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<8>::new(n).unwrap(),
            Resampling::Systematic,
            0.5,
        )
        .unwrap()
        .regularised()
        .with_kernel(KernelPlacement::Plain);
        let mean = SVector::<f64, 8>::from_fn(|k, _| k as f64);
        let cov = SMatrix::<f64, 8, 8>::from_fn(|i, j| if i == j { 4.0 + i as f64 } else { 0.0 });
        pf.init_gaussian(&mean, &cov, &mut rng).unwrap();
        let c0 = pf.covariance();
        pf.resample_deferring_kernel(&mut rng);
        let h2 = (4.0 / (n as f64 * 10.0)).powf(2.0 / 12.0);
        let kernel = pf.deferred_kernel.expect("a kernel is kept");
        assert!((kernel - c0 * h2).amax() < 1e-9 * c0.amax());
        // The pending kernel is part of the estimate's covariance.
        let c1 = pf.covariance();
        assert!((c1 - pf.sample_covariance() - kernel).amax() < 1e-9 * c0.amax());
        pf.propagate(&Drift8, 2.0).unwrap();
        let f = Drift8.jacobian(&mean, 2.0);
        let moved = pf.deferred_kernel.expect("still kept");
        assert!((moved - f * kernel * f.transpose()).amax() < 1e-9 * kernel.amax());
        let c1 = f * c1 * f.transpose();
        // One range from 10 000 km with σ = 10⁹ m: no information.
        let mut layout = position_clock_layout();
        layout.clock = [None; System::COUNT];
        let row = RangeRow {
            emitter_pos_m: Vector3::new(1.0e7, 0.0, 0.0),
            emitter_vel_mps: Vector3::zeros(),
            system: System::Dtmb,
            sigma_m: 1.0e9,
            sigma_rate_mps: 1.0,
        };
        let mut lik = PseudorangeLikelihood::with_capacity(1);
        lik.clear(layout.pos);
        lik.push(&layout, &row, 1.0e7);
        let up = pf
            .update_linearised(&SMatrix::zeros(), &lik, &mut rng)
            .unwrap();
        assert!(!up.resampled);
        assert!(pf.deferred_kernel.is_none(), "the kernel is drawn once");
        // Drawn, the kernel leaves the covariance where the pending one had put it: the
        // cloud grew by one kernel.
        let c2 = pf.covariance();
        for k in 0..8 {
            let change = (c2[(k, k)] - c1[(k, k)]) / moved[(k, k)];
            assert!(
                change.abs() < 0.25,
                "component {k}: the drawn kernel moved the covariance by {change} kernels"
            );
        }
    }
}
