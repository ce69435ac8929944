//! The filter family behind one engine estimator: the same measurements, the same process
//! model, a different filter.
//!
//! Seeds 001, 003 and 004 compare filters on one problem (PF against EKF; RE-KF against
//! STF, CKF and EKF). [`FamilyEstimator`] makes that comparison a world-file choice: every
//! filter of [`crate::fusion::kalman`] and [`crate::fusion::particle`] runs seed 000's
//! position–velocity–acceleration + clock model ([`Pva11Clock`], eqs. 4–8) and takes
//! pseudoranges, pseudorange rates and position fixes through the generic measurement
//! models of [`crate::fusion::models`]:
//!
//! ```text
//! ρ_j  = ‖r_j − r‖ + b (+ isb for BDS) + ε            (Pseudoranges, M = 1)
//! ρ̇_j  = u_j·(v_j − v) + ḃ + ε                        (row 2 of PseudorangesAndRates)
//! L    = r + ε,  ε ~ N(0, R_f)                          (PositionFixModel, M = 3)
//! ```
//!
//! A range rate is a second scalar update linearised at the state the pseudorange left,
//! as [`crate::fusion::ekf11::Ekf11`] does, so with `filter = "ekf"` the family reproduces
//! the hand-optimised `ekf11` (a test checks it to 1e-6 m on a whole trial). The strong
//! tracking filter is that EKF with its prediction inflated by a fading factor computed
//! from the epoch's stacked, whitened pseudorange innovations (see `stf_inflate`).
//!
//! Divergence is detected, never passed on: a prediction or update that fails, a state that
//! is not finite, a position σ beyond [`FamilyConfig::divergence_pos_sigma_m`] or
//! pseudorange residuals beyond [`FamilyConfig::divergence_residual_nis`] reset the filter, the epoch is reported with `numerical_failure`, and the next epoch
//! re-initialises from least squares.

use crate::core::rng::{StreamRng, TrialRng};
use crate::core::stats::chi2;
use crate::core::{GpsTime, System};
use crate::fusion::ekf11::{idx, Ekf11Config, RejectReason, UpdateOutcome};
use crate::fusion::kalman::{
    Ekf, Gating, RelativeEntropyKf, ResidualGate, SigmaPointKf, UpdateReport,
    DEFAULT_ALEPH_THRESHOLD,
};
use crate::fusion::models::{
    MeasurementModel, PositionFixModel, ProcessModel, Pseudoranges, PseudorangesAndRates,
    Pva11Clock, RangeRow, StateLayout,
};
use crate::fusion::particle::{ParticleBuffer, ParticleFilter, PfVariant, Resampling};
use crate::fusion::preprocess::{ClockCorrectionConfig, FrontEnd};
use crate::fusion::selection::ModeSelection;
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, MeasurementBatch, RangeMeasurement, SourceKind,
};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::Deserialize;

/// The state dimension: seed 000's eleven states plus the BeiDou inter-system bias.
pub const N: usize = crate::fusion::ekf11::N_STATES;

type State = SVector<f64, N>;
type Cov = SMatrix<f64, N, N>;

/// Which member of the family an estimator runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FamilyKind {
    /// The generic EKF with the Joseph-form update.
    Ekf,
    /// The unscented Kalman filter (Merwe's scaled points).
    Ukf,
    /// The cubature Kalman filter.
    Ckf,
    /// The strong tracking filter.
    Stf,
    /// Seed 004's relative-entropy Kalman filter.
    Rekf,
    /// The SIR particle filter.
    Pf,
}

impl FamilyKind {
    /// The name a world file uses.
    pub fn label(self) -> &'static str {
        match self {
            FamilyKind::Ekf => "ekf",
            FamilyKind::Ukf => "ukf",
            FamilyKind::Ckf => "ckf",
            FamilyKind::Stf => "stf",
            FamilyKind::Rekf => "rekf",
            FamilyKind::Pf => "pf",
        }
    }
}

/// How the particle filter resamples (`[estimator.options] resampling`).
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ResamplingKind {
    Systematic,
    Stratified,
    Residual,
}

/// Where a particle filter draws its particles from (`[estimator.options] pf_proposal`).
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ProposalKind {
    Prior,
    Linearised,
}

/// Where a regularised particle filter places its kernel (`[estimator.options]
/// pf_kernel`, [`crate::fusion::particle::KernelPlacement`]).
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum KernelKind {
    /// Shrunk towards the mean first: the cloud's covariance is kept (Liu & West 2001), as
    /// its unbiased estimate from the weighted cloud, with the bandwidth sized by the
    /// weighted cloud's effective sample size, and grown by the Monte Carlo error of the
    /// cloud's mean (`1/N_eff + 1/N` of it). After the linearised proposal, the moments
    /// are the posterior mixture's, from the proposal's centres and its conditional
    /// covariance (the draws' noise integrated out).
    LiuWest,
    /// On the resampled particles as they are (Musso, Oudjane & Le Gland 2001), shaped by
    /// the weighted cloud's covariance (after the linearised proposal, its expectation
    /// given the proposal's centres, the draws' noise integrated out).
    Musso,
    /// Musso's on the states the process noise drives, Liu & West's shrinkage on the
    /// static parameters (the constant clocks); after the linearised proposal, shaped as
    /// `Musso` is.
    MussoLiuWestStatic,
}

/// How a regularised particle filter brings an epoch's likelihood in (`[estimator.options]
/// pf_correction`, [`crate::fusion::particle::ParticleFilter::with_progressive_correction`]).
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionKind {
    /// All at once: one weighting, then a resampling if `N_eff` fell below the threshold.
    Single,
    /// In stages, each keeping half the particles effective, with a resampling and the
    /// kernel between them (Oudjane & Musso 2000).
    Progressive,
}

/// How the Gaussian particle filter estimates its covariance from the weighted cloud
/// (`[estimator.options] gpf_covariance`,
/// [`crate::fusion::particle::CovarianceEstimate`]).
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum GpfCovarianceKind {
    /// `Σ w_i (x_i − μ)(x_i − μ)ᵀ`, as Kotecha & Djurić write it.
    Weighted,
    /// The same divided by `1 − Σ w_i²`: the unbiased estimator for normalised weights.
    Unbiased,
}

impl GpfCovarianceKind {
    /// The particle filter's estimator of this name.
    pub fn estimate(self) -> crate::fusion::particle::CovarianceEstimate {
        match self {
            GpfCovarianceKind::Weighted => crate::fusion::particle::CovarianceEstimate::Weighted,
            GpfCovarianceKind::Unbiased => crate::fusion::particle::CovarianceEstimate::Unbiased,
        }
    }
}

/// The resampling threshold θ of a particle filter whose world gives none (resample when
/// N_eff < θ·N): ½, the usual choice (Doucet & Johansen, "A tutorial on particle
/// filtering and smoothing: fifteen years later", 2009, §3.5).
pub const DEFAULT_NEFF_THRESHOLD: f64 = 0.5;

impl FamilyConfig {
    /// The proposal a paper-model particle filter of this member draws from: the world's
    /// `pf_proposal`, else the linearised one for the regularised and Rao-Blackwellised
    /// PF and the prior for the others.
    ///
    /// Why linearised for those two: on seed 003 (`worlds/seed003-seamless.toml`, 50
    /// trials, master seeds 1–5) the regularised PF with Liu & West's kernel, drawing
    /// from the linearised proposal and resampling at every epoch, is at 1.27–1.65× of
    /// the PCRLB with 100 particles and loses 0–3 tracks, where the same filter drawing
    /// from the prior (with progressive correction, on N_eff < N/2) is at 2.4–3.1× and
    /// loses 10–23; with 500 and 2000 particles the two are equally efficient
    /// (1.02–1.07× against 1.03–1.07×; 1.00× each). Seed 001 (10 and 20 particles) moves
    /// the same way. `docs/reproductions.md`, "The linearised proposal as the default".
    pub fn pf_proposal_for(&self, variant: PfVariant) -> ProposalKind {
        self.pf_proposal.unwrap_or(match variant {
            PfVariant::Regularised | PfVariant::RaoBlackwellised => ProposalKind::Linearised,
            PfVariant::Sir | PfVariant::Marginalised | PfVariant::Gaussian => ProposalKind::Prior,
        })
    }

    /// The resampling threshold of a particle filter of this member drawing from this
    /// proposal: the world's `neff_threshold`, else 1 (resample at every epoch) for the
    /// regularised and Rao-Blackwellised PF with the linearised proposal and
    /// [`DEFAULT_NEFF_THRESHOLD`] for the others. The linearised proposal conditions the
    /// kernel's jitter on the ranges only in the epoch after a resampling (the kernel is
    /// deferred into the proposal's noise, [`ParticleFilter::update_linearised`]);
    /// between resamplings only the process noise is conditioned, and with 100 particles
    /// on seed 003 N_eff < N/2 loses the track (3.5× of the PCRLB, against 1.3× at
    /// every epoch).
    ///
    /// [`ParticleFilter::update_linearised`]: crate::fusion::particle::ParticleFilter::update_linearised
    pub fn neff_threshold_for(&self, variant: PfVariant, proposal: ProposalKind) -> f64 {
        self.neff_threshold.unwrap_or(match (variant, proposal) {
            (PfVariant::Regularised | PfVariant::RaoBlackwellised, ProposalKind::Linearised) => 1.0,
            _ => DEFAULT_NEFF_THRESHOLD,
        })
    }
}

impl KernelKind {
    /// The particle filter's placement of this name.
    pub fn placement(self) -> crate::fusion::particle::KernelPlacement {
        match self {
            KernelKind::LiuWest => crate::fusion::particle::KernelPlacement::Shrunk,
            KernelKind::Musso => crate::fusion::particle::KernelPlacement::Plain,
            KernelKind::MussoLiuWestStatic => {
                crate::fusion::particle::KernelPlacement::ShrunkStatic
            }
        }
    }
}

impl ResamplingKind {
    /// The particle filter's scheme of this name.
    pub fn scheme(self) -> Resampling {
        match self {
            ResamplingKind::Systematic => Resampling::Systematic,
            ResamplingKind::Stratified => Resampling::Stratified,
            ResamplingKind::Residual => Resampling::Residual,
        }
    }
}

/// `[estimator.options]`: the tuning of the family's filters. The process model's tuning
/// (PSDs, initial sigmas, χ² gates) is `[estimator.ekf]`, shared with `ekf11`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct FamilyConfig {
    /// UKF: Merwe's α, β, κ. Defaults α = 0.5, β = 2, κ = 0: with twelve states a small α
    /// makes the centre weight hugely negative and the covariance indefinite in rounding.
    pub ukf_alpha: f64,
    /// UKF: Merwe's β (2 is optimal for Gaussian priors).
    pub ukf_beta: f64,
    /// UKF: Merwe's κ (secondary scaling, default 0).
    pub ukf_kappa: f64,
    /// STF: forgetting factor ρ (0 < ρ ≤ 1) and weakening factor β ≥ 1 (Zhou & Frank).
    pub stf_forgetting: f64,
    /// STF: the weakening (softening) factor β ≥ 1 (Zhou & Frank); default 1.
    pub stf_weakening: f64,
    /// STF: the largest fading factor λ applied. Default 10. Not in Zhou & Frank: λ also
    /// inflates states the ranges do not observe (velocity and acceleration when there are
    /// no range rates, indoors on TC-OFDM alone), and uncapped it compounds there epoch
    /// after epoch until the filter diverges (measured on `worlds/seed004-bupt.toml`).
    pub stf_max_fading: f64,
    /// RE-KF: the coupling-degree threshold ℵ_threshold (seed 004 eq. 38; the paper gives
    /// no value, default ½ ln 2).
    pub rekf_aleph_threshold: f64,
    /// Seed 004's data-layer residual gate `|d_j| ≤ C·√ε_jj` (eq. 24): `C`. Default none,
    /// except for `rekf`, whose default is 3 (the paper uses 2 or 3).
    pub residual_gate_c: Option<f64>,
    /// PF: number of particles, resampling scheme and the N_eff fraction below which it
    /// resamples.
    pub particles: usize,
    pub resampling: ResamplingKind,
    /// PF: resample when N_eff < θ·N (θ in [0, 1]). Default ½ (Doucet & Johansen 2009,
    /// §3.5), except 1 (a resampling at every epoch) for the regularised and
    /// Rao-Blackwellised PF with the linearised proposal, their default proposal.
    pub neff_threshold: Option<f64>,
    /// PF: also weight by the pseudorange rates. Default false: seeds 001 and 003 use
    /// pseudoranges only, and a Doppler an order of magnitude more precise than the
    /// process noise collapses a bootstrap filter's weights onto one particle.
    pub pf_use_rates: bool,
    /// PF on the paper models: the proposal particles are drawn from — `"prior"` (the
    /// process model, the bootstrap filter) or `"linearised"` (for the resampling
    /// filters, the process noise conditioned on the epoch's ranges linearised at the
    /// predicted mean, with a Rao-Blackwellised filter's clocks integrated out; for the
    /// Gaussian PF, the EKF update of its predicted Gaussian as the GPF's importance
    /// function; [`crate::fusion::particle::ParticleFilter::update_linearised`]). Not for
    /// the marginalised PF. Default: `"linearised"` for the regularised and
    /// Rao-Blackwellised PF (`"pf"`, `"rbpf"`), `"prior"` for the others (`"sir"` is the
    /// bootstrap filter by definition, the GPF as Kotecha & Djurić ran it, and the
    /// marginalised PF draws from its exact prediction).
    pub pf_proposal: Option<ProposalKind>,
    /// The regularised and Rao-Blackwellised PF on the paper models: the kernel after a
    /// resampling is `"liu_west"` (shrunk towards the mean so that the cloud keeps its
    /// covariance, the weighted cloud's over `1 − Σ w_i²`, its unbiased estimate, plus
    /// the Monte Carlo error of its mean, `1/N_eff + 1/N` of it; after the linearised
    /// proposal, the posterior mixture's moments from the proposal's centres and
    /// conditional covariance; default), `"musso"`
    /// (added as it is: the cloud inflates by `h_opt²` of its covariance at each
    /// resampling, as the regularised PF was defined; after the linearised proposal the
    /// covariance is the weighted cloud's expected one given the proposal's centres) or
    /// `"musso_liu_west_static"` (Musso's on the states the process noise drives, Liu &
    /// West's shrinkage on the model's constant clocks).
    pub pf_kernel: KernelKind,
    /// The regularised and Rao-Blackwellised PF (`filter = "pf"`, `"rbpf"`) with the prior
    /// proposal: each epoch's likelihood is brought in `"progressive"` (in stages, each the
    /// largest that keeps half the particles effective, with a resampling and the kernel
    /// between stages: Oudjane & Musso, "Progressive correction for regularized particle
    /// filters", FUSION 2000; the Rao-Blackwellised clocks' Kalman update split with it;
    /// an epoch whose whole likelihood keeps half the particles effective is the single
    /// update, bit for bit) or `"single"` (all at once). Default: `"progressive"` for
    /// those two with the prior proposal, `"single"` for every other member, which
    /// refuses an explicit `"progressive"`.
    pub pf_correction: Option<CorrectionKind>,
    /// The Gaussian PF (`filter = "gpf"`; the other members carry no moment estimate and
    /// ignore it): the covariance of its Gaussian is the weighted cloud's,
    /// `Σ w_i (x_i − μ)(x_i − μ)ᵀ` (`"weighted"`, Kotecha & Djurić 2003; default), or that
    /// divided by `1 − Σ w_i²` (`"unbiased"`). The first has expectation `(1 − Σ w_i²) Σ`;
    /// fed back through the recursion, the deficit compounds on states without process
    /// noise, `(1 − 1/N)^k` after k epochs of uniform weights.
    pub gpf_covariance: GpfCovarianceKind,
    /// A position 1-σ (m, from the trace of the position covariance) beyond which the
    /// filter is declared diverged and reset. Default 100 km.
    pub divergence_pos_sigma_m: f64,
    /// The median squared normalised pseudorange residual at the estimate, `(ν_j/σ_j)²`,
    /// beyond which the track is declared lost and the filter reset. Default 400 (most
    /// residuals beyond 20 σ; the median ignores a few NLOS outliers): a filter can be confidently wrong (a particle cloud that
    /// collapsed away from the truth has a small covariance), and only the measurements
    /// show it.
    pub divergence_residual_nis: f64,
}

impl Default for FamilyConfig {
    fn default() -> Self {
        Self {
            ukf_alpha: 0.5,
            ukf_beta: 2.0,
            ukf_kappa: 0.0,
            stf_forgetting: 0.95,
            stf_weakening: 1.0,
            stf_max_fading: 10.0,
            rekf_aleph_threshold: DEFAULT_ALEPH_THRESHOLD,
            residual_gate_c: None,
            particles: 2000,
            resampling: ResamplingKind::Systematic,
            neff_threshold: None,
            pf_use_rates: false,
            pf_proposal: None,
            pf_kernel: KernelKind::LiuWest,
            pf_correction: None,
            gpf_covariance: GpfCovarianceKind::Weighted,
            divergence_pos_sigma_m: 1e5,
            divergence_residual_nis: 400.0,
        }
    }
}

impl FamilyConfig {
    /// Checks the numbers a filter cannot use, naming the key.
    ///
    /// # Errors
    /// `(key, message)`.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |k: &str, m: String| Err((k.to_string(), m));
        if !(self.ukf_alpha.is_finite() && self.ukf_alpha > 0.0) {
            return bad("ukf_alpha", format!("{}: expected > 0", self.ukf_alpha));
        }
        if !(self.ukf_beta.is_finite() && self.ukf_kappa.is_finite()) {
            return bad("ukf_beta", "expected finite ukf_beta and ukf_kappa".into());
        }
        if !(self.stf_forgetting > 0.0 && self.stf_forgetting <= 1.0) {
            return bad(
                "stf_forgetting",
                format!("{}: expected 0 < ρ ≤ 1", self.stf_forgetting),
            );
        }
        if !(self.stf_weakening.is_finite() && self.stf_weakening >= 1.0) {
            return bad(
                "stf_weakening",
                format!("{}: expected β ≥ 1", self.stf_weakening),
            );
        }
        if !(self.stf_max_fading.is_finite() && self.stf_max_fading >= 1.0) {
            return bad(
                "stf_max_fading",
                format!("{}: expected λ_max ≥ 1", self.stf_max_fading),
            );
        }
        if !(self.rekf_aleph_threshold.is_finite() && self.rekf_aleph_threshold > 0.0) {
            return bad(
                "rekf_aleph_threshold",
                format!("{}: expected > 0", self.rekf_aleph_threshold),
            );
        }
        if let Some(c) = self.residual_gate_c {
            if !(c.is_finite() && c > 0.0) {
                return bad("residual_gate_c", format!("{c}: expected > 0"));
            }
        }
        if !(2..=1_000_000).contains(&self.particles) {
            return bad(
                "particles",
                format!("{}: expected 2 to 1 000 000", self.particles),
            );
        }
        if let Some(theta) = self.neff_threshold {
            if !(0.0..=1.0).contains(&theta) {
                return bad(
                    "neff_threshold",
                    format!("{theta}: expected a fraction in [0, 1]"),
                );
            }
        }
        if !(self.divergence_residual_nis.is_finite() && self.divergence_residual_nis > 0.0) {
            return bad(
                "divergence_residual_nis",
                format!("{}: expected > 0", self.divergence_residual_nis),
            );
        }
        if !(self.divergence_pos_sigma_m.is_finite() && self.divergence_pos_sigma_m > 0.0) {
            return bad(
                "divergence_pos_sigma_m",
                format!("{}: expected > 0", self.divergence_pos_sigma_m),
            );
        }
        Ok(())
    }
}

/// One scalar row of a whitened measurement: `h'(x) = (L⁻¹ h(x))_row`, `R' = 1`, with
/// `L Lᵀ = R` (the rows of `L⁻¹ν` are independent with unit variance).
struct WhitenedRow<'a, H, const M: usize> {
    model: &'a H,
    linv: SMatrix<f64, M, M>,
    row: usize,
}

impl<'a, H, const NN: usize, const M: usize> MeasurementModel<NN, 1> for WhitenedRow<'a, H, M>
where
    H: MeasurementModel<NN, M>,
{
    fn h(&self, x: &SVector<f64, NN>) -> SVector<f64, 1> {
        SVector::<f64, 1>::new((self.linv * self.model.h(x))[self.row])
    }
    fn jacobian(&self, x: &SVector<f64, NN>) -> SMatrix<f64, 1, NN> {
        (self.linv * self.model.jacobian(x))
            .fixed_rows::<1>(self.row)
            .into_owned()
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::identity()
    }
}

/// Adds what one update (of dimension `dim`) did to the epoch's outcome.
fn tally(out: &mut EpochOutcome, rep: &UpdateReport, dim: u32) {
    out.used += rep.used;
    out.rejected += rep.rejected;
    match rep.outcome {
        UpdateOutcome::Accepted { nis } => {
            out.record_nis(nis, dim);
        }
        UpdateOutcome::Rejected {
            reason: RejectReason::Gate { .. },
            ..
        } => {
            out.rejected_gate += rep.rejected;
            out.rejected_gate_state_led += rep.rejected_state_led;
        }
        _ => {}
    }
}

/// The strong tracking prediction (Zhou & Frank 1996), first half: `x⁻ = f(x)` and the
/// un-inflated `P⁻ = F P Fᵀ + Q`, keeping `F P Fᵀ` and `Q` apart until a batch with
/// ranges arrives (two predictions without such a batch compose, as in
/// [`crate::fusion::kalman::StrongTrackingFilter`]). A zero interval changes nothing, so a
/// second batch at the same instant is not inflated twice.
fn stf_predict(
    f: &mut Ekf<N>,
    mem: &mut StfMemory,
    model: &Pva11Clock,
    dt_s: f64,
    gating: Gating,
) -> bool {
    if dt_s == 0.0 {
        return true;
    }
    let (x, p) = (*f.state(), *f.covariance());
    let fj = model.jacobian(&x, dt_s);
    let q = model.q(&x, dt_s);
    let (fpf, q) = match mem.pending {
        Some((fpf0, q0)) => (fj * fpf0 * fj.transpose(), fj * q0 * fj.transpose() + q),
        None => (fj * p * fj.transpose(), q),
    };
    let pp = fpf + q;
    let pp = (pp + pp.transpose()) * 0.5;
    mem.pending = Some((fpf, q));
    match Ekf::new(model.f(&x, dt_s), pp).and_then(|e| e.with_gating(gating)) {
        Ok(e) => {
            *f = e;
            true
        }
        Err(_) => false,
    }
}

/// The strong tracking prediction, second half: the fading factor from the first batch
/// with ranges after a prediction. On a stacked, whitened measurement of variable size,
/// with `m` whitened pseudorange innovations `ν_j` and rows `h_j` at the predicted state,
///
/// ```text
/// V_k = (ρ V_{k−1} + Σν_j²/m) / (1 + ρ)          (V_1 = Σν_j²/m)
/// c_k = (V_k − Σ h_j Q h_jᵀ/m − β) / (Σ h_j F P Fᵀ h_jᵀ/m),   λ_k = min(λ_max, max(1, c_k))
/// P⁻ = λ_k F P Fᵀ + Q
/// ```
/// which is the trace form `tr N_k / tr M_k` of the vector filter divided through by the
/// number of components, so that the memory stays meaningful when the number of
/// emitters changes from epoch to epoch.
fn stf_inflate(
    f: &mut Ekf<N>,
    mem: &mut StfMemory,
    ranges: &[RangeMeasurement],
    layout: &StateLayout,
    cfg: &FamilyConfig,
    gating: Gating,
) -> bool {
    let Some((fpf, q)) = mem.pending else {
        return true;
    };
    let xp = *f.state();
    let (mut nu2, mut hqh, mut hfh, mut m) = (0.0, 0.0, 0.0, 0usize);
    for r in ranges {
        let Ok(pr) = Pseudoranges::<N, 1>::new(*layout, [RangeRow::from(r)]) else {
            continue;
        };
        let h = pr.jacobian(&xp) / r.sigma_m;
        let nu = (r.pseudorange_m - pr.h(&xp)[0]) / r.sigma_m;
        nu2 += nu * nu;
        hqh += (h * q * h.transpose())[(0, 0)];
        hfh += (h * fpf * h.transpose())[(0, 0)];
        m += 1;
    }
    if m == 0 {
        return true;
    }
    mem.pending = None;
    let k = m as f64;
    let v = match mem.v {
        None => nu2 / k,
        Some(v0) => (cfg.stf_forgetting * v0 + nu2 / k) / (1.0 + cfg.stf_forgetting),
    };
    mem.v = Some(v);
    let c = (v - hqh / k - cfg.stf_weakening) / (hfh / k);
    let lambda = if c.is_finite() {
        c.clamp(1.0, cfg.stf_max_fading)
    } else {
        1.0
    };
    if lambda == 1.0 {
        return true;
    }
    let pp = fpf * lambda + q;
    let pp = (pp + pp.transpose()) * 0.5;
    match Ekf::new(xp, pp).and_then(|e| e.with_gating(gating)) {
        Ok(e) => {
            *f = e;
            true
        }
        Err(_) => false,
    }
}

/// Resamples a particle filter whose effective sample size fell below `threshold · N`, then
/// roughens it: the regularised particle filter of Musso, Oudjane & Le Gland (2001) with
/// the Gaussian kernel's optimal bandwidth `h = (4 / (N (d + 2)))^{1/(d+4)}` on the
/// weighted covariance `Σ̂` before resampling. `q` (one step's process noise) is added as
/// a floor, so that a cloud that collapsed onto one particle spreads again.
fn regularise(p: &mut PfCore, threshold: f64, q: &Cov) {
    use rand_distr::{Distribution, StandardNormal};
    let n = p.pf.particles().len();
    if p.pf.n_eff() >= threshold * n as f64 {
        return;
    }
    let d = N as f64;
    let h = (4.0 / (n as f64 * (d + 2.0))).powf(1.0 / (d + 4.0));
    let sigma = p.pf.covariance() * (h * h) + q;
    let sigma = (sigma + sigma.transpose()) * 0.5;
    p.pf.resample(&mut p.rng);
    let Some(chol) = sigma.cholesky() else {
        return;
    };
    let g = chol.l();
    let b = p.pf.particles_mut();
    for i in 0..n {
        let w = State::from_fn(|_, _| StandardNormal.sample(&mut p.rng));
        let jitter = g * w;
        for k in 0..N {
            b.column_mut(k)[i] += jitter[k];
        }
    }
}

/// A draw of velocity and clock drift `[v_x, v_y, v_z, ḃ]` for a receiver at `pos` from
/// the weighted least-squares solution of the range rates, `ρ̇_j − u_j·v_j = −u_j·v + ḃ`,
/// and its covariance `(AᵀWA)⁻¹`; `None` with fewer than four rates.
fn velocity_and_drift(
    pos: &Vector3<f64>,
    ranges: &[RangeMeasurement],
    rng: &mut StreamRng,
) -> Option<nalgebra::Vector4<f64>> {
    use rand_distr::{Distribution, StandardNormal};
    let mut ata = nalgebra::Matrix4::<f64>::zeros();
    let mut aty = nalgebra::Vector4::<f64>::zeros();
    let mut n = 0;
    for m in ranges {
        let Some(rate) = m.range_rate_mps else {
            continue;
        };
        let d = m.emitter_pos_ecef_m - pos;
        let u = d / d.norm();
        let a = nalgebra::Vector4::new(-u.x, -u.y, -u.z, 1.0);
        let w = 1.0 / (m.sigma_rate_mps * m.sigma_rate_mps);
        ata += a * a.transpose() * w;
        aty += a * ((rate - u.dot(&m.emitter_vel_ecef_mps)) * w);
        n += 1;
    }
    if n < 4 {
        return None;
    }
    let chol = ata.cholesky()?;
    let mean = chol.solve(&aty);
    let cov = chol.inverse();
    let g = cov.cholesky()?.l();
    let w = nalgebra::Vector4::from_fn(|_, _| StandardNormal.sample(rng));
    Some(mean + g * w)
}

/// The strong tracking filter's innovation memory `V` (per whitened component).
struct StfMemory {
    v: Option<f64>,
    /// `F P Fᵀ` and `Q` of the prediction not yet inflated.
    pending: Option<(Cov, Cov)>,
}

/// A particle filter with its own random stream.
struct PfCore {
    pf: ParticleFilter<N>,
    rng: StreamRng,
}

/// The filter itself, once initialised.
enum Core {
    Ekf(Ekf<N>),
    Sigma(SigmaPointKf<N>),
    /// The strong tracking filter: an EKF whose prediction [`FamilyEstimator`] inflates.
    Stf(Ekf<N>, Box<StfMemory>),
    Rekf(RelativeEntropyKf<N>),
    Pf(Box<PfCore>),
}

impl Core {
    fn predict(&mut self, model: &Pva11Clock, dt_s: f64) -> bool {
        match self {
            Core::Ekf(f) => f.predict(model, dt_s).is_ok(),
            Core::Sigma(f) => f.predict(model, dt_s).is_ok(),
            // The strong tracking prediction needs the epoch's innovations; it is done
            // by `FamilyEstimator::stf_predict` before the updates.
            Core::Stf(..) => true,
            Core::Rekf(f) => f.predict(model, dt_s).is_ok(),
            Core::Pf(p) => p.pf.predict(model, dt_s, &mut p.rng).is_ok(),
        }
    }

    /// Updates with `z` of `model` and adds what happened to `out`.
    fn update<H: MeasurementModel<N, M>, const M: usize>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
        out: &mut EpochOutcome,
    ) {
        let rep = match self {
            Core::Ekf(f) => f.update(model, z),
            Core::Sigma(f) => f.update(model, z),
            Core::Rekf(f) => f.update(model, z).0,
            Core::Stf(f, _) => f.update(model, z),
            Core::Pf(p) => {
                let u = p.pf.update(model, z, &mut p.rng);
                if u.degenerate {
                    UpdateReport {
                        outcome: UpdateOutcome::Rejected {
                            nis: f64::NAN,
                            reason: RejectReason::NumericalFailure,
                        },
                        used: 0,
                        rejected: M as u32,
                        rejected_state_led: 0,
                    }
                } else {
                    // A particle filter has no innovation covariance, so no NIS.
                    UpdateReport {
                        outcome: UpdateOutcome::Accepted { nis: f64::NAN },
                        used: M as u32,
                        rejected: 0,
                        rejected_state_led: 0,
                    }
                }
            }
        };
        tally(out, &rep, M as u32);
    }

    fn moments(&self) -> (State, Cov) {
        match self {
            Core::Ekf(f) => (*f.state(), *f.covariance()),
            Core::Sigma(f) => (*f.state(), *f.covariance()),
            Core::Stf(f, _) => (*f.state(), *f.covariance()),
            Core::Rekf(f) => (*f.state(), *f.covariance()),
            Core::Pf(p) => (p.pf.mean(), p.pf.covariance()),
        }
    }
}

/// Any member of the filter family on seed 000's model, driven epoch by epoch like
/// [`crate::fusion::estimator::EkfEstimator`]: initialised from a least-squares fix,
/// predicted to each batch's time, updated with each range, range rate and position fix.
pub struct FamilyEstimator {
    name: String,
    kind: FamilyKind,
    ekf_cfg: Ekf11Config,
    cfg: FamilyConfig,
    model: Pva11Clock,
    layout: StateLayout,
    gating: Gating,
    rng: StreamRng,
    core: Option<Core>,
    /// The state and covariance after the last epoch (what `latest` reports).
    moments: Option<(State, Cov)>,
    last_t: Option<GpsTime>,
    /// Systems, fix sources, mode selection and DTMB clock correction; holds the current
    /// batch's admitted ranges.
    front: FrontEnd,
    residual_scratch: Vec<f64>,
    /// The residual verdict of each source's last batch with four ranges or more: the
    /// source, the batch time and whether the estimate was far from its ranges.
    verdicts: Vec<(SourceKind, GpsTime, bool)>,
    geometry: Vec<(Vector3<f64>, usize)>,
}

/// Two batches this close in time (s) are of one epoch for the divergence watch: the
/// sources of a 1 Hz world arrive at the same second, or one epoch apart in the order the
/// engine delivers them.
const SAME_EPOCH_S: f64 = 1.0;

impl FamilyEstimator {
    /// An estimator named `name` running `kind` on the ranges of `systems` and the
    /// position fixes of the sources named in `fixes`. `rng` gives the particle filter
    /// its stream (`estimator/<name>/pf`).
    ///
    /// # Errors
    /// When a configuration is invalid.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        name: &str,
        kind: FamilyKind,
        systems: &[System],
        fixes: &[SourceKind],
        ekf: Option<Ekf11Config>,
        cfg: Option<FamilyConfig>,
        selection: Option<&ModeSelection>,
        correction: Option<ClockCorrectionConfig>,
        rng: &TrialRng,
    ) -> Result<Self, String> {
        let mut ekf_cfg = ekf.unwrap_or_default();
        if !ekf_cfg.rate_position_jacobian {
            // The family's range-rate model is the exact one; dropping its position terms
            // (seed 000's eq. 17 as printed) is an option of `ekf11` alone.
            return Err(
                "ekf.rate_position_jacobian = false is supported by filter = \"ekf11\" only; the filter family linearises range rates exactly"
                    .into(),
            );
        }
        ekf_cfg = ekf_cfg.for_systems(systems);
        let mut cfg = cfg.unwrap_or_default();
        if kind == FamilyKind::Rekf && cfg.residual_gate_c.is_none() {
            cfg.residual_gate_c = Some(3.0);
        }
        cfg.validate()
            .map_err(|(k, m)| format!("options.{k}: {m}"))?;
        let model = Pva11Clock::new(ekf_cfg).map_err(|e| format!("ekf: {e}"))?;
        let mut layout = StateLayout::ekf11();
        if ekf_cfg.isb_bds.is_none() {
            // The inert ISB state is left out of the ranges; it keeps a unit variance so
            // that the sigma-point filters can factor the covariance.
            layout.isb = [None; System::COUNT];
        }
        let gating = Gating {
            chi2_prob: ekf_cfg.gate_chi2.map(|g| chi2::cdf(g, 1.0)),
            residual: cfg.residual_gate_c.map(ResidualGate::sigmas),
        };
        let front = FrontEnd::new(systems, fixes, selection, correction)?;
        Ok(Self {
            name: name.to_string(),
            kind,
            ekf_cfg,
            cfg,
            model,
            layout,
            gating,
            rng: rng.stream(&format!("estimator/{name}/pf")),
            core: None,
            moments: None,
            last_t: None,
            front,
            residual_scratch: Vec::with_capacity(64),
            verdicts: Vec::with_capacity(8),
            geometry: Vec::with_capacity(64),
        })
    }

    /// The prior of a first fix, as [`crate::fusion::ekf11::Ekf11::initialise`] builds it.
    fn prior(&self, pos: Vector3<f64>, clock_m: f64, pos_sigma_m: f64) -> (State, Cov) {
        let c = &self.ekf_cfg;
        let mut x = State::zeros();
        let mut p = Cov::zeros();
        for axis in 0..3 {
            x[idx::POS[axis]] = pos[axis];
            p[(idx::POS[axis], idx::POS[axis])] = pos_sigma_m * pos_sigma_m;
            p[(idx::VEL[axis], idx::VEL[axis])] = c.init_vel_sigma_mps.powi(2);
            p[(idx::ACC[axis], idx::ACC[axis])] = c.init_acc_sigma_mps2.powi(2);
        }
        x[idx::CLOCK_BIAS] = clock_m;
        let clock_sigma_m = 10.0 * pos_sigma_m;
        p[(idx::CLOCK_BIAS, idx::CLOCK_BIAS)] = clock_sigma_m * clock_sigma_m;
        p[(idx::CLOCK_DRIFT, idx::CLOCK_DRIFT)] = c.init_clock_drift_sigma_mps.powi(2);
        p[(idx::ISB_BDS, idx::ISB_BDS)] = c.isb_bds.map_or(1.0, |i| i.initial_sigma_m.powi(2));
        (x, p)
    }

    fn build_core(&mut self, x0: State, p0: Cov) -> Result<Core, String> {
        let cfg = &self.cfg;
        let err = |e: crate::fusion::kalman::FilterError| e.to_string();
        Ok(match self.kind {
            FamilyKind::Ekf => Core::Ekf(
                Ekf::new(x0, p0)
                    .and_then(|f| f.with_gating(self.gating))
                    .map_err(err)?,
            ),
            FamilyKind::Ukf => Core::Sigma(
                SigmaPointKf::unscented(x0, p0, cfg.ukf_alpha, cfg.ukf_beta, cfg.ukf_kappa)
                    .and_then(|f| f.with_gating(self.gating))
                    .map_err(err)?,
            ),
            FamilyKind::Ckf => Core::Sigma(
                SigmaPointKf::cubature(x0, p0)
                    .and_then(|f| f.with_gating(self.gating))
                    .map_err(err)?,
            ),
            FamilyKind::Stf => Core::Stf(
                Ekf::new(x0, p0)
                    .and_then(|f| f.with_gating(self.gating))
                    .map_err(err)?,
                Box::new(StfMemory {
                    v: None,
                    pending: None,
                }),
            ),
            FamilyKind::Rekf => Core::Rekf(
                RelativeEntropyKf::new(x0, p0, cfg.rekf_aleph_threshold, self.gating.residual)
                    .map_err(err)?,
            ),
            FamilyKind::Pf => {
                let buf = ParticleBuffer::new(cfg.particles).map_err(|e| e.to_string())?;
                let resampling = cfg.resampling.scheme();
                // The filter never resamples inside an update: the estimator resamples once
                // per epoch, with regularisation (see `regularise`).
                let mut pf =
                    ParticleFilter::new(buf, resampling, 0.0).map_err(|e| e.to_string())?;
                pf.init_gaussian(&x0, &p0, &mut self.rng)
                    .map_err(|e| e.to_string())?;
                // A least-squares position error and its clock error are strongly
                // correlated (a common vertical-and-clock mode); drawing them independently
                // would put almost every particle far from the likelihood. Each particle's
                // clock is therefore re-solved for its own position from this epoch's
                // ranges, which draws the pair from the joint prior.
                let b = pf.particles_mut();
                let n = b.len();
                for i in 0..n {
                    let pos = Vector3::new(
                        b.column(idx::POS[0])[i],
                        b.column(idx::POS[1])[i],
                        b.column(idx::POS[2])[i],
                    );
                    let (mut sw, mut s) = (0.0, 0.0);
                    for m in &self.front.ranges {
                        let w = 1.0 / (m.sigma_m * m.sigma_m);
                        s += w * (m.pseudorange_m - (m.emitter_pos_ecef_m - pos).norm());
                        sw += w;
                    }
                    if sw > 0.0 {
                        b.column_mut(idx::CLOCK_BIAS)[i] = s / sw;
                    }
                    // Velocity and clock drift the same way, from the range rates: a
                    // prior of ±10 m/s and ±300 m/s drawn independently would leave a
                    // handful of particles anywhere near the Doppler.
                    if let Some(vd) = velocity_and_drift(&pos, &self.front.ranges, &mut self.rng) {
                        for axis in 0..3 {
                            b.column_mut(idx::VEL[axis])[i] = vd[axis];
                        }
                        b.column_mut(idx::CLOCK_DRIFT)[i] = vd[3];
                    }
                }
                Core::Pf(Box::new(PfCore {
                    pf,
                    rng: self.rng.clone(),
                }))
            }
        })
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        let (x, p) = self.moments.as_ref()?;
        let pos = Vector3::new(x[idx::POS[0]], x[idx::POS[1]], x[idx::POS[2]]);
        let vel = Vector3::new(x[idx::VEL[0]], x[idx::VEL[1]], x[idx::VEL[2]]);
        let cov = Matrix3::from_fn(|i, j| p[(idx::POS[i], idx::POS[j])]);
        Some(Estimate {
            t,
            pos_ecef_m: pos,
            vel_ecef_mps: Some(vel),
            cov_pos_m2: cov,
        })
    }

    /// Forgets the filter after a divergence; the next epoch re-initialises.
    fn reset(&mut self, out: &mut EpochOutcome) {
        self.core = None;
        self.moments = None;
        self.verdicts.clear();
        out.numerical_failure = true;
        out.estimate = None;
    }

    /// True when the estimate `x` is far from the ranges of every source of this epoch
    /// (see [`FamilyConfig::divergence_residual_nis`]). Each source's batch with at least
    /// four ranges gives a verdict; the track is lost when this batch's verdict is "far"
    /// and no other source's batch of the same epoch fits. A filter that fits one source
    /// (TC-OFDM indoors) and gates another that is biased (GNSS through a roof, every range
    /// tens of metres long) has not diverged: a diverged filter is far from them all.
    fn lost(&mut self, x: &State, source: SourceKind, t: GpsTime) -> bool {
        let Some(far) = self.far_from_ranges(x) else {
            return false;
        };
        match self.verdicts.iter_mut().find(|v| v.0 == source) {
            Some(v) => *v = (source, t, far),
            None => self.verdicts.push((source, t, far)),
        }
        far && !self
            .verdicts
            .iter()
            .any(|&(s, tv, f)| s != source && !f && t.seconds_since(tv).abs() <= SAME_EPOCH_S)
    }

    /// Whether the median squared normalised residual of this batch's pseudoranges at `x`
    /// exceeds [`FamilyConfig::divergence_residual_nis`]; `None` with fewer than four.
    fn far_from_ranges(&mut self, x: &State) -> Option<bool> {
        let nu2 = &mut self.residual_scratch;
        nu2.clear();
        for r in &self.front.ranges {
            if let Ok(pr) = Pseudoranges::<N, 1>::new(self.layout, [RangeRow::from(r)]) {
                let nu = (r.pseudorange_m - pr.h(x)[0]) / r.sigma_m;
                nu2.push(nu * nu);
            }
        }
        if nu2.len() < 4 {
            return None;
        }
        // The median, so that a few NLOS outliers (which the gates handle) do not count.
        let mid = nu2.len() / 2;
        let (_, median, _) = nu2.select_nth_unstable_by(mid, f64::total_cmp);
        Some(*median > self.cfg.divergence_residual_nis)
    }

    fn usable(&self, x: &State, p: &Cov) -> bool {
        let limit = self.cfg.divergence_pos_sigma_m.powi(2);
        let pos_var: f64 = idx::POS.iter().map(|&k| p[(k, k)]).sum();
        x.iter().all(|v| v.is_finite())
            && p.iter().all(|v| v.is_finite())
            && pos_var.is_finite()
            && pos_var <= limit
    }
}

impl Estimator for FamilyEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        self.front.consumes(source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        let rx = self
            .moments
            .as_ref()
            .map(|(x, _)| Vector3::new(x[idx::POS[0]], x[idx::POS[1]], x[idx::POS[2]]));
        self.front.admit(batch, rx.as_ref(), &mut out);
        if self.core.is_none() {
            let Some(fix) = self.front.first_fix() else {
                return out;
            };
            let (x0, p0) = self.prior(fix.pos_ecef_m, fix.clock_m, fix.pos_sigma_m);
            match self.build_core(x0, p0) {
                Ok(core) => self.core = Some(core),
                Err(_) => {
                    out.numerical_failure = true;
                    return out;
                }
            }
            self.moments = self.core.as_ref().map(Core::moments);
            self.last_t = Some(batch.t);
            out.used = fix.n_measurements;
            out.gdop = Some(fix.gdop);
            out.estimate = self.estimate(batch.t);
            return out;
        }
        let dt = self
            .last_t
            .map_or(0.0, |l| batch.t.seconds_since(l))
            .max(0.0);
        self.last_t = Some(batch.t);
        let Some(core) = self.core.as_mut() else {
            return out;
        };
        let predicted = match &mut *core {
            Core::Stf(f, mem) => {
                stf_predict(f, mem, &self.model, dt, self.gating)
                    && stf_inflate(
                        f,
                        mem,
                        &self.front.ranges,
                        &self.layout,
                        &self.cfg,
                        self.gating,
                    )
            }
            c => c.predict(&self.model, dt),
        };
        if !predicted {
            self.reset(&mut out);
            return out;
        }
        for m in &self.front.ranges {
            let row = RangeRow::from(m);
            let Ok(pr) = Pseudoranges::<N, 1>::new(self.layout, [row]) else {
                out.rejected += 1;
                continue;
            };
            core.update(&pr, &SVector::<f64, 1>::new(m.pseudorange_m), &mut out);
            let rate = m
                .range_rate_mps
                .filter(|_| self.kind != FamilyKind::Pf || self.cfg.pf_use_rates);
            if let Some(rate) = rate {
                let Ok(both) = PseudorangesAndRates::<N, 2>::new(self.layout, &[row]) else {
                    out.rejected += 1;
                    continue;
                };
                let linv = SMatrix::<f64, 2, 2>::from_diagonal(&nalgebra::Vector2::new(
                    1.0 / m.sigma_m,
                    1.0 / m.sigma_rate_mps,
                ));
                let rate_row = WhitenedRow {
                    model: &both,
                    linv,
                    row: 1,
                };
                let z = SVector::<f64, 1>::new(rate / m.sigma_rate_mps);
                core.update(&rate_row, &z, &mut out);
            }
        }
        for f in self.front.position_fixes(batch) {
            match PositionFixModel::<N, 3>::new(idx::POS, f.cov_m2) {
                Ok(model) => core.update(&model, &f.pos_ecef_m, &mut out),
                Err(_) => out.rejected += 1,
            }
        }
        if let Core::Pf(p) = core {
            let q = self.model.q(&p.pf.mean(), dt.max(1e-3));
            regularise(
                p,
                self.cfg.neff_threshold.unwrap_or(DEFAULT_NEFF_THRESHOLD),
                &q,
            );
        }
        let (x, p) = core.moments();
        if !self.usable(&x, &p) || self.lost(&x, batch.source, batch.t) {
            self.reset(&mut out);
            return out;
        }
        let rx = Vector3::new(x[idx::POS[0]], x[idx::POS[1]], x[idx::POS[2]]);
        self.moments = Some((x, p));
        out.gdop = crate::fusion::estimator::gdop_of(&rx, &self.front.ranges, &mut self.geometry);
        out.estimate = self.estimate(batch.t);
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.last_t.and_then(|t| self.estimate(t))
    }

    fn reset(&mut self) {
        self.reset(&mut EpochOutcome::default());
    }
}
