//! The Kalman filter family on the models of [`crate::fusion::models`]: a generic EKF, the
//! unscented and cubature filters, the strong tracking filter and seed 004's relative
//! entropy Kalman filter, with χ² innovation gating and seed 004's data-layer residual
//! gate.
//!
//! Every filter is generic over a state dimension `N` and the measurement dimension `M`
//! of each update, on nalgebra static types, so a predict or an update allocates nothing
//! (the sigma-point filters keep their points in buffers sized when they are built).
//!
//! Every operation validates what it is given and what it computes: a non-finite input,
//! an innovation covariance that is not positive definite or a result with a non-finite
//! or non-positive variance leaves the filter unchanged and is reported as a typed
//! [`FilterError`] (predictions) or a rejected [`UpdateOutcome`] (updates), never a
//! panic.
//!
//! # Gating
//!
//! * **χ² innovation gate.** With `ν = z − ẑ` and `S` its covariance, the update is
//!   refused when `νᵀ S⁻¹ ν > χ²_p(m)` for the `m` components left (Bar-Shalom, Li &
//!   Kirubarajan, *Estimation with Applications to Tracking and Navigation*, §5.4).
//! * **Residual gate (seed 004 eq. 24).** Component `j` of the residual `d = z − ẑ`
//!   (eq. 22) is kept when `|d_j| ≤ C·√ε_jj`, with `ε = H P⁻ Hᵀ + R` (eq. 23) and the
//!   balance factor `C` typically 2 or 3. The paper prints `C·ε_jj`, which compares metres
//!   with square metres; [`GateScale::StdDev`] (the default) reads `ε_jj` as the variance
//!   it is and bounds by `C` standard deviations, [`GateScale::Variance`] applies the
//!   printed form literally.
//!
//! A component that is gated out is removed exactly: its innovation is zeroed, its row
//! and column of `S` become those of the identity and its column of the cross covariance
//! is zeroed, so the gain has a zero column for it and the update is the update with the
//! remaining components alone.

pub use crate::core::stats::chi2;
pub use crate::fusion::ekf11::{RejectReason, UpdateOutcome};
use crate::fusion::models::{MeasurementModel, ProcessModel};
use nalgebra::{SMatrix, SVector};

/// Errors of construction and prediction. A failed prediction leaves the filter unchanged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// The prediction interval is negative or not finite.
    #[error("invalid prediction interval {dt_s} s: expected a finite number of seconds ≥ 0")]
    InvalidInterval { dt_s: f64 },
    /// A state, covariance or model output holds NaN or infinity.
    #[error("non-finite value in the state, covariance or model output; the filter is unchanged")]
    NonFinite,
    /// A covariance that must be positive definite is not (no Cholesky factor exists).
    #[error("a covariance is not positive definite; the filter is unchanged")]
    NotPositiveDefinite,
    /// A tuning parameter is unusable.
    #[error("invalid filter parameter: {0}")]
    InvalidParameter(String),
}

/// How seed 004's eq. 24 scales its bound (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GateScale {
    /// `|d_j| ≤ C·√ε_jj`: `C` standard deviations.
    StdDev,
    /// `|d_j| ≤ C·ε_jj`: the equation as printed.
    Variance,
}

/// Seed 004's data-layer residual gate, eq. 24.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResidualGate {
    /// The balance factor `C` (2 or 3 in the paper).
    pub c: f64,
    pub scale: GateScale,
}

impl ResidualGate {
    /// `C` standard deviations.
    pub fn sigmas(c: f64) -> Self {
        Self {
            c,
            scale: GateScale::StdDev,
        }
    }

    /// True when residual `d` with variance `eps` passes.
    pub fn keeps(&self, d: f64, eps: f64) -> bool {
        let bound = match self.scale {
            GateScale::StdDev => self.c * eps.max(0.0).sqrt(),
            GateScale::Variance => self.c * eps,
        };
        d.abs() <= bound
    }
}

/// The gates an update applies, in order: the residual gate per component, then the χ²
/// gate on what is left.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Gating {
    /// Probability `p` of the χ² gate: the update is refused when the NIS exceeds the
    /// χ²(m) quantile at `p` (e.g. 0.999). `None`: no χ² gate.
    pub chi2_prob: Option<f64>,
    /// Seed 004's eq. 24. `None`: no residual gate.
    pub residual: Option<ResidualGate>,
}

impl Gating {
    fn validate(&self) -> Result<(), FilterError> {
        if let Some(p) = self.chi2_prob {
            if !(p > 0.0 && p < 1.0) {
                return Err(FilterError::InvalidParameter(format!(
                    "chi2_prob = {p}: expected 0 < p < 1"
                )));
            }
        }
        if let Some(g) = self.residual {
            if !(g.c.is_finite() && g.c > 0.0) {
                return Err(FilterError::InvalidParameter(format!(
                    "residual gate C = {}: expected a finite value > 0",
                    g.c
                )));
            }
        }
        Ok(())
    }
}

/// What one (vector) update did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateReport {
    /// Accepted (with the NIS of the components used) or rejected with the reason.
    pub outcome: UpdateOutcome,
    /// Components used.
    pub used: u32,
    /// Components removed by a gate (or all of them when the update was refused).
    pub rejected: u32,
    /// Of `rejected`, the components an innovation gate refused while the filter's own
    /// variance along them, `(H P Hᵀ)_jj`, was at least the measurement's `R_jj`
    /// ([`RejectReason::Gate`]'s `state_led`).
    pub rejected_state_led: u32,
}

impl UpdateReport {
    fn refused<const M: usize>(reason: RejectReason, nis: f64) -> Self {
        Self {
            outcome: UpdateOutcome::Rejected { nis, reason },
            used: 0,
            rejected: M as u32,
            rejected_state_led: 0,
        }
    }

    /// The whole update refused by a gate; `state_led` of its `M` components were led by
    /// the state's variance.
    fn gated<const M: usize>(nis: f64, state_led: u32) -> Self {
        Self {
            outcome: UpdateOutcome::Rejected {
                nis,
                reason: RejectReason::Gate {
                    state_led: 2 * state_led >= M as u32,
                },
            },
            used: 0,
            rejected: M as u32,
            rejected_state_led: state_led,
        }
    }
}

fn finite<'a>(it: impl IntoIterator<Item = &'a f64>) -> bool {
    it.into_iter().all(|v| v.is_finite())
}

fn check_prior<const N: usize>(
    x: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
) -> Result<(), FilterError> {
    if !(finite(x.iter()) && finite(p.iter())) {
        return Err(FilterError::NonFinite);
    }
    if p.cholesky().is_none() && !(0..N).all(|i| p[(i, i)] >= 0.0) {
        return Err(FilterError::NotPositiveDefinite);
    }
    Ok(())
}

fn check_dt(dt_s: f64) -> Result<(), FilterError> {
    if dt_s.is_finite() && dt_s >= 0.0 {
        Ok(())
    } else {
        Err(FilterError::InvalidInterval { dt_s })
    }
}

/// A posterior is usable when every number is finite and every variance positive.
fn usable<const N: usize>(x: &SVector<f64, N>, p: &SMatrix<f64, N, N>) -> bool {
    finite(x.iter()) && finite(p.iter()) && (0..N).all(|i| p[(i, i)] >= 0.0)
}

/// The extended-Kalman prediction shared by the EKF and the RE-KF:
/// `x⁻ = f(x, Δt)`, `P⁻ = F P Fᵀ + Q` with `F = ∂f/∂x` at `x`. The state is left unchanged
/// when the interval is invalid or the result not finite.
fn linearised_predict<P: ProcessModel<N>, const N: usize>(
    x: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    model: &P,
    dt_s: f64,
) -> Result<(), FilterError> {
    check_dt(dt_s)?;
    let f = model.jacobian(x, dt_s);
    let x_new = model.f(x, dt_s);
    let p_new = symmetrise(&(f * *p * f.transpose() + model.q(x, dt_s)));
    if !usable(&x_new, &p_new) {
        return Err(FilterError::NonFinite);
    }
    *x = x_new;
    *p = p_new;
    Ok(())
}

fn symmetrise<const N: usize>(p: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    (p + p.transpose()) * 0.5
}

/// The outcome of gating: which components survive, and the masked innovation,
/// innovation covariance and cross covariance (see the module documentation).
struct Gated<const N: usize, const M: usize> {
    keep: [bool; M],
    used: u32,
    /// Components whose `(H P Hᵀ)_jj ≥ R_jj`, and how many of those the residual gate
    /// removed.
    state_led: u32,
    state_led_gated: u32,
    nu: SVector<f64, M>,
    s: SMatrix<f64, M, M>,
    pxz: SMatrix<f64, N, M>,
}

fn apply_residual_gate<const N: usize, const M: usize>(
    gate: Option<ResidualGate>,
    extra_keep: &[bool; M],
    r: &SMatrix<f64, M, M>,
    mut nu: SVector<f64, M>,
    mut s: SMatrix<f64, M, M>,
    mut pxz: SMatrix<f64, N, M>,
) -> Gated<N, M> {
    let mut keep = *extra_keep;
    let (mut state_led, mut state_led_gated) = (0, 0);
    for j in 0..M {
        // S_jj − R_jj is (H P Hᵀ)_jj, the state's share of the innovation's variance.
        let led = s[(j, j)] - r[(j, j)] >= r[(j, j)];
        state_led += u32::from(led);
        if let Some(g) = gate {
            if keep[j] && !g.keeps(nu[j], s[(j, j)]) {
                keep[j] = false;
                state_led_gated += u32::from(led);
            }
        }
    }
    let mut used = 0;
    for (j, k) in keep.iter().enumerate() {
        if *k {
            used += 1;
        } else {
            nu[j] = 0.0;
            s.row_mut(j).fill(0.0);
            s.column_mut(j).fill(0.0);
            s[(j, j)] = 1.0;
            pxz.column_mut(j).fill(0.0);
        }
    }
    Gated {
        keep,
        used,
        state_led,
        state_led_gated,
        nu,
        s,
        pxz,
    }
}

/// `K = Pxz S⁻¹` and the NIS `νᵀ S⁻¹ ν` through a Cholesky factor of `S`, with the χ²
/// gate applied; `Err` carries the refusal.
fn gain_and_nis<const N: usize, const M: usize>(
    g: &Gated<N, M>,
    chi2_prob: Option<f64>,
) -> Result<(SMatrix<f64, N, M>, f64), UpdateReport> {
    if g.used == 0 {
        return Err(UpdateReport::gated::<M>(f64::NAN, g.state_led_gated));
    }
    let Some(chol) = g.s.cholesky() else {
        return Err(UpdateReport::refused::<M>(
            RejectReason::NumericalFailure,
            f64::NAN,
        ));
    };
    let nis = g.nu.dot(&chol.solve(&g.nu));
    if let Some(p) = chi2_prob {
        if nis > chi2::quantile(p, f64::from(g.used)) {
            return Err(UpdateReport::gated::<M>(nis, g.state_led));
        }
    }
    let k = chol.solve(&g.pxz.transpose()).transpose();
    Ok((k, nis))
}

fn accepted<const N: usize, const M: usize>(nis: f64, g: &Gated<N, M>) -> UpdateReport {
    UpdateReport {
        outcome: UpdateOutcome::Accepted { nis },
        used: g.used,
        rejected: M as u32 - g.used,
        rejected_state_led: g.state_led_gated,
    }
}

/// Evaluates a model's measurement and noise and refuses non-finite ones.
fn measurement_inputs<const N: usize, const M: usize, H: MeasurementModel<N, M>>(
    model: &H,
    z: &SVector<f64, M>,
) -> Result<SMatrix<f64, M, M>, UpdateReport> {
    let r = model.r();
    if !(finite(z.iter()) && finite(r.iter())) {
        return Err(UpdateReport::refused::<M>(
            RejectReason::NonFiniteInput,
            f64::NAN,
        ));
    }
    if (0..M).any(|i| r[(i, i)] <= 0.0) {
        return Err(UpdateReport::refused::<M>(
            RejectReason::InvalidNoise,
            f64::NAN,
        ));
    }
    Ok(r)
}

/// The extended Kalman filter on any [`ProcessModel`] and [`MeasurementModel`]
/// (Gelb, *Applied Optimal Estimation*, 1974, §6.1; Bar-Shalom et al. §10.3):
///
/// ```text
/// predict:  x⁻ = f(x, T),   F = ∂f/∂x|ₓ,   P⁻ = F P Fᵀ + Q
/// update:   ν = z − h(x⁻),  H = ∂h/∂x|ₓ⁻,  S = H P⁻ Hᵀ + R,   K = P⁻ Hᵀ S⁻¹
///           x⁺ = x⁻ + K ν,  P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ   (Joseph form)
/// ```
/// The update is a vector update linearised once at `x⁻`, which is what filterpy's
/// `ExtendedKalmanFilter.update` computes, so the two agree to rounding on the same data.
/// On a linear model it is exactly the Kalman filter.
#[derive(Clone, Debug, PartialEq)]
pub struct Ekf<const N: usize> {
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    gating: Gating,
}

impl<const N: usize> Ekf<N> {
    /// A filter at `x0` with covariance `p0`, no gates.
    ///
    /// # Errors
    /// When a number is not finite or `p0` has a negative variance.
    pub fn new(x0: SVector<f64, N>, p0: SMatrix<f64, N, N>) -> Result<Self, FilterError> {
        check_prior(&x0, &p0)?;
        Ok(Self {
            x: x0,
            p: p0,
            gating: Gating::default(),
        })
    }

    /// Restarts the filter from `x0`, `p0` (keeping its gating), as after a divergence.
    ///
    /// # Errors
    /// When `x0` or `p0` is not finite or `p0` is not a covariance.
    pub fn restart(
        &mut self,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        check_prior(&x0, &p0)?;
        self.x = x0;
        self.p = p0;
        Ok(())
    }

    /// The same filter with `gating`.
    ///
    /// # Errors
    /// When a gate parameter is unusable.
    pub fn with_gating(mut self, gating: Gating) -> Result<Self, FilterError> {
        gating.validate()?;
        self.gating = gating;
        Ok(self)
    }

    /// The state.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// The covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Predicts over `dt_s` seconds.
    ///
    /// # Errors
    /// An invalid interval or a non-finite result; the filter is then unchanged.
    pub fn predict<P: ProcessModel<N>>(&mut self, model: &P, dt_s: f64) -> Result<(), FilterError> {
        linearised_predict(&mut self.x, &mut self.p, model, dt_s)
    }

    /// Updates with measurement `z` of `model`.
    pub fn update<H: MeasurementModel<N, M>, const M: usize>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
    ) -> UpdateReport {
        let r = match measurement_inputs(model, z) {
            Ok(r) => r,
            Err(rep) => return rep,
        };
        let h = model.jacobian(&self.x);
        let nu = model.residual(z, &model.h(&self.x));
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        if !(finite(nu.iter()) && finite(s.iter())) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, f64::NAN);
        }
        let g = apply_residual_gate(self.gating.residual, &[true; M], &r, nu, s, pht);
        let (k, nis) = match gain_and_nis(&g, self.gating.chi2_prob) {
            Ok(v) => v,
            Err(rep) => return rep,
        };
        let x = self.x + k * g.nu;
        let a = SMatrix::<f64, N, N>::identity() - k * h;
        let p = symmetrise(&(a * self.p * a.transpose() + k * r * k.transpose()));
        if !usable(&x, &p) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, nis);
        }
        self.x = x;
        self.p = p;
        accepted(nis, &g)
    }
}

/// The sigma-point rule of a [`SigmaPointKf`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SigmaRule {
    /// Van der Merwe's scaled unscented points (Wan & van der Merwe, "The unscented
    /// Kalman filter for nonlinear estimation", *AS-SPCC* 2000; Julier, "The scaled
    /// unscented transformation", *ACC* 2002), exactly as filterpy's
    /// `MerweScaledSigmaPoints`:
    ///
    /// ```text
    /// λ = α²(n + κ) − n,   L Lᵀ = (n + λ) P
    /// χ₀ = x,   χ_i = x + L_i,   χ_{n+i} = x − L_i          (i = 1…n, L_i column i)
    /// W₀ᵐ = λ/(n + λ),   W₀ᶜ = W₀ᵐ + 1 − α² + β,   W_iᵐ = W_iᶜ = 1/(2(n + λ))
    /// ```
    Merwe { alpha: f64, beta: f64, kappa: f64 },
    /// The third-degree spherical–radial cubature rule (Arasaratnam & Haykin, "Cubature
    /// Kalman filters", *IEEE Trans. AC* 54(6), 2009, eq. 38):
    /// `χ_i = x ± √n L_i` with `L Lᵀ = P`, `2n` points of weight `1/(2n)`.
    Cubature,
}

/// A sigma-point Kalman filter: the UKF ([`SigmaRule::Merwe`]) or the CKF
/// ([`SigmaRule::Cubature`]).
///
/// ```text
/// predict:  χ_i from (x, P);   χ_i⁻ = f(χ_i, T);   x⁻ = Σ Wᵐ χ_i⁻
///           P⁻ = Σ Wᶜ (χ_i⁻ − x⁻)(χ_i⁻ − x⁻)ᵀ + Q
/// update:   χ_i from (x⁻, P⁻);  ζ_i = h(χ_i);  ẑ = Σ Wᵐ ζ_i
///           S = Σ Wᶜ (ζ_i − ẑ)(ζ_i − ẑ)ᵀ + R,   P_xz = Σ Wᶜ (χ_i − x⁻)(ζ_i − ẑ)ᵀ
///           K = P_xz S⁻¹,   x⁺ = x⁻ + K (z − ẑ),   P⁺ = P⁻ − K S Kᵀ
/// ```
/// The update redraws its points from the predicted moments, as Arasaratnam & Haykin's
/// CKF does and as filterpy 2's `UnscentedKalmanFilter.predict` leaves its `sigmas_f`.
#[derive(Clone, Debug, PartialEq)]
pub struct SigmaPointKf<const N: usize> {
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    rule: SigmaRule,
    gating: Gating,
    /// `(n + λ)` for Merwe, `n` for cubature: the scale of `P` whose factor spreads the
    /// points.
    spread: f64,
    wm: Vec<f64>,
    wc: Vec<f64>,
    /// The points (reused buffer, 2n + 1 or 2n entries).
    points: Vec<SVector<f64, N>>,
    /// The measurement points, `M` values per point (reused; grows once to the largest
    /// `M` seen).
    zbuf: Vec<f64>,
}

impl<const N: usize> SigmaPointKf<N> {
    fn build(
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        rule: SigmaRule,
    ) -> Result<Self, FilterError> {
        check_prior(&x0, &p0)?;
        let n = N as f64;
        let (spread, wm, wc) = match rule {
            SigmaRule::Merwe { alpha, beta, kappa } => {
                if !(alpha.is_finite() && alpha > 0.0 && beta.is_finite() && kappa.is_finite()) {
                    return Err(FilterError::InvalidParameter(format!(
                        "Merwe α = {alpha}, β = {beta}, κ = {kappa}: expected finite values, α > 0"
                    )));
                }
                let lambda = alpha * alpha * (n + kappa) - n;
                if n + lambda <= 0.0 {
                    return Err(FilterError::InvalidParameter(format!(
                        "n + λ = {}: expected > 0 (raise α or κ)",
                        n + lambda
                    )));
                }
                let c = 0.5 / (n + lambda);
                let mut wm = vec![c; 2 * N + 1];
                let mut wc = vec![c; 2 * N + 1];
                wm[0] = lambda / (n + lambda);
                wc[0] = wm[0] + (1.0 - alpha * alpha + beta);
                (n + lambda, wm, wc)
            }
            SigmaRule::Cubature => {
                let w = 0.5 / n;
                (n, vec![w; 2 * N], vec![w; 2 * N])
            }
        };
        let points = vec![SVector::<f64, N>::zeros(); wm.len()];
        Ok(Self {
            x: x0,
            p: p0,
            rule,
            gating: Gating::default(),
            spread,
            wm,
            wc,
            points,
            zbuf: Vec::new(),
        })
    }

    /// An unscented Kalman filter with Merwe's scaled points `(α, β, κ)`.
    ///
    /// # Errors
    /// Non-finite or unusable parameters, or an unusable prior.
    pub fn unscented(
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        alpha: f64,
        beta: f64,
        kappa: f64,
    ) -> Result<Self, FilterError> {
        Self::build(x0, p0, SigmaRule::Merwe { alpha, beta, kappa })
    }

    /// A cubature Kalman filter.
    ///
    /// # Errors
    /// An unusable prior.
    pub fn cubature(x0: SVector<f64, N>, p0: SMatrix<f64, N, N>) -> Result<Self, FilterError> {
        Self::build(x0, p0, SigmaRule::Cubature)
    }

    /// The same filter with `gating`.
    ///
    /// # Errors
    /// When a gate parameter is unusable.
    pub fn with_gating(mut self, gating: Gating) -> Result<Self, FilterError> {
        gating.validate()?;
        self.gating = gating;
        Ok(self)
    }

    /// Restarts the filter from `x0`, `p0` (keeping its rule and gating), as after a
    /// divergence or when a state is (re)initialised.
    ///
    /// # Errors
    /// When `x0` or `p0` is not finite or `p0` is not a covariance.
    pub fn restart(
        &mut self,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        check_prior(&x0, &p0)?;
        self.x = x0;
        self.p = p0;
        Ok(())
    }

    /// The sigma-point rule.
    pub fn rule(&self) -> SigmaRule {
        self.rule
    }

    /// The state.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// The covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Fills `points` from `(x, P)`, with the factor of [`psd_sqrt`] (the Cholesky factor
    /// whenever P is positive definite).
    fn draw(&mut self) -> Result<(), FilterError> {
        let l = psd_sqrt(&(self.p * self.spread)).ok_or(FilterError::NotPositiveDefinite)?;
        match self.rule {
            SigmaRule::Merwe { .. } => {
                self.points[0] = self.x;
                for i in 0..N {
                    self.points[1 + i] = self.x + l.column(i);
                    self.points[1 + N + i] = self.x - l.column(i);
                }
            }
            SigmaRule::Cubature => {
                for i in 0..N {
                    self.points[i] = self.x + l.column(i);
                    self.points[N + i] = self.x - l.column(i);
                }
            }
        }
        Ok(())
    }

    /// Predicts over `dt_s` seconds.
    ///
    /// # Errors
    /// An invalid interval, a covariance without a Cholesky factor or a non-finite result;
    /// the filter is then unchanged.
    pub fn predict<P: ProcessModel<N>>(&mut self, model: &P, dt_s: f64) -> Result<(), FilterError> {
        check_dt(dt_s)?;
        self.draw()?;
        let mut x = SVector::<f64, N>::zeros();
        for (pt, w) in self.points.iter_mut().zip(&self.wm) {
            *pt = model.f(pt, dt_s);
            x += *pt * *w;
        }
        let mut p = model.q(&self.x, dt_s);
        for (pt, w) in self.points.iter().zip(&self.wc) {
            let d = pt - x;
            p += d * d.transpose() * *w;
        }
        let p = symmetrise(&p);
        if !usable(&x, &p) {
            return Err(FilterError::NonFinite);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Updates with measurement `z` of `model`.
    pub fn update<H: MeasurementModel<N, M>, const M: usize>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
    ) -> UpdateReport {
        let r = match measurement_inputs(model, z) {
            Ok(r) => r,
            Err(rep) => return rep,
        };
        if self.draw().is_err() {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, f64::NAN);
        }
        let m = sigma_moments(
            model,
            &self.points,
            &self.wm,
            &self.wc,
            &self.x,
            &mut self.zbuf,
        );
        let s = m.pzz + r;
        let nu = model.residual(z, &m.z_hat);
        if !(finite(nu.iter()) && finite(s.iter()) && finite(m.pxz.iter())) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, f64::NAN);
        }
        let g = apply_residual_gate(self.gating.residual, &[true; M], &r, nu, s, m.pxz);
        let (k, nis) = match gain_and_nis(&g, self.gating.chi2_prob) {
            Ok(v) => v,
            Err(rep) => return rep,
        };
        let x = self.x + k * g.nu;
        let p = symmetrise(&(self.p - k * g.s * k.transpose()));
        if !usable(&x, &p) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, nis);
        }
        self.x = x;
        self.p = p;
        accepted(nis, &g)
    }
}

/// A square root `L` with `L Lᵀ = P` of a covariance, for drawing sigma points.
///
/// When `P` is positive definite this is its Cholesky factor, as it always was. When it is
/// only semi-definite — a state known exactly (zero variance, as the clocks a world
/// declares, or seed 001's x axis, which moves without noise), or a prior `P(0) = Q(T)`
/// of rank three in nine states — it is the factor of Cholesky with complete pivoting
/// (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §10.3): at each
/// step the largest remaining variance is the pivot, and the factorisation stops when
/// every remaining variance is below `n·ε·max P_ii`, the rounding level of the
/// remaining Schur complement. The columns of `L` are then in pivot order and those
/// past the rank are zero, so the points along them coincide with the mean. `None` when
/// a number is not finite or `P` has a remaining variance below `−1e-9·max P_ii` (it is not
/// a covariance).
pub fn psd_sqrt<const N: usize>(p: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    if let Some(c) = p.cholesky() {
        return Some(c.l());
    }
    if !finite(p.iter()) {
        return None;
    }
    let mut a = symmetrise(p);
    let scale = (0..N).map(|i| a[(i, i)]).fold(0.0_f64, f64::max);
    let mut l = SMatrix::<f64, N, N>::zeros();
    if scale <= 0.0 {
        // Nothing is uncertain (or a variance is negative).
        return (0..N).all(|i| a[(i, i)] == 0.0).then_some(l);
    }
    let tol = N as f64 * f64::EPSILON * scale;
    let mut done = [false; N];
    for step in 0..N {
        let Some(k) = (0..N)
            .filter(|&i| !done[i])
            .max_by(|&i, &j| a[(i, i)].total_cmp(&a[(j, j)]))
        else {
            break;
        };
        if a[(k, k)] <= tol {
            break;
        }
        done[k] = true;
        let d = a[(k, k)].sqrt();
        l[(k, step)] = d;
        for i in 0..N {
            if !done[i] {
                l[(i, step)] = a[(i, k)] / d;
            }
        }
        for i in 0..N {
            for j in 0..N {
                if !done[i] && !done[j] {
                    a[(i, j)] -= l[(i, step)] * l[(j, step)];
                }
            }
        }
    }
    let left_ok = (0..N).all(|i| done[i] || a[(i, i)] >= -1e-9 * scale);
    left_ok.then_some(l)
}

/// Zhou & Frank's fading factor for an [`Ekf`] updated by sequential scalar measurements:
/// one factor per epoch, from the epoch's stacked, whitened scalar innovations (the
/// strong tracking filter of [`crate::fusion::family`], generic over the state and the
/// process model). With `m` scalar measurements, whitened rows `h_j = H_j/σ_j` and
/// innovations `ν_j/σ_j` at the predicted state:
///
/// ```text
/// ν̄² = Σ (ν_j/σ_j)² / m,   V_k = ν̄² (k = 1),   V_k = (ρ V_{k−1} + ν̄²)/(1 + ρ)
/// c_k = (V_k − Σ h_j Q h_jᵀ / m − β) / (Σ h_j F P Fᵀ h_jᵀ / m)
/// λ_k = min(λ_max, max(1, c_k)),   P⁻ = λ_k F P Fᵀ + Q
/// ```
/// which is [`StrongTrackingFilter`]'s `tr N_k / tr M_k` for whitened scalar rows. `λ_max`
/// bounds the factor (see `FamilyConfig::stf_max_fading`).
#[derive(Clone, Debug, PartialEq)]
pub struct EpochFading<const N: usize> {
    forgetting: f64,
    weakening: f64,
    max_fading: f64,
    v: Option<f64>,
    pending: Option<(SMatrix<f64, N, N>, SMatrix<f64, N, N>)>,
    last_lambda: f64,
}

impl<const N: usize> EpochFading<N> {
    /// Forgetting factor `ρ` (0 < ρ ≤ 1), weakening factor `β ≥ 1` and the largest factor
    /// `λ_max ≥ 1`.
    ///
    /// # Errors
    /// When a factor is outside its range.
    pub fn new(forgetting: f64, weakening: f64, max_fading: f64) -> Result<Self, FilterError> {
        if !(forgetting > 0.0
            && forgetting <= 1.0
            && weakening.is_finite()
            && weakening >= 1.0
            && max_fading.is_finite()
            && max_fading >= 1.0)
        {
            return Err(FilterError::InvalidParameter(format!(
                "ρ = {forgetting}, β = {weakening}, λ_max = {max_fading}: expected 0 < ρ ≤ 1, β ≥ 1 and λ_max ≥ 1"
            )));
        }
        Ok(Self {
            forgetting,
            weakening,
            max_fading,
            v: None,
            pending: None,
            last_lambda: 1.0,
        })
    }

    /// Forgets the innovation memory, as after a restart of the filter.
    pub fn reset(&mut self) {
        self.v = None;
        self.pending = None;
        self.last_lambda = 1.0;
    }

    /// The factor of the last epoch.
    pub fn last_fading_factor(&self) -> f64 {
        self.last_lambda
    }

    /// Predicts `f` over `dt_s` seconds (`P⁻ = F P Fᵀ + Q`), keeping `F P Fᵀ` and `Q`
    /// for the factor. Two predictions without an [`EpochFading::inflate`] between them
    /// compose.
    ///
    /// # Errors
    /// An invalid interval or a non-finite result; `f` is then unchanged.
    pub fn predict<P: ProcessModel<N>>(
        &mut self,
        f: &mut Ekf<N>,
        model: &P,
        dt_s: f64,
    ) -> Result<(), FilterError> {
        check_dt(dt_s)?;
        let x = *f.state();
        let fj = model.jacobian(&x, dt_s);
        let q = model.q(&x, dt_s);
        let (fpf, q) = match self.pending {
            Some((fpf0, q0)) => (fj * fpf0 * fj.transpose(), fj * q0 * fj.transpose() + q),
            None => (fj * *f.covariance() * fj.transpose(), q),
        };
        let (fpf, q) = (symmetrise(&fpf), symmetrise(&q));
        let x_new = model.f(&x, dt_s);
        let p_new = fpf + q;
        if !usable(&x_new, &p_new) {
            return Err(FilterError::NonFinite);
        }
        f.restart(x_new, p_new)?;
        self.pending = Some((fpf, q));
        Ok(())
    }

    /// Inflates the prediction of `f` by the factor of this epoch's scalar measurements
    /// `(model, z)` and returns the factor (1 when there is no pending prediction or no
    /// usable measurement).
    ///
    /// # Errors
    /// When the inflated covariance is not usable; `f` is then unchanged.
    pub fn inflate<H: MeasurementModel<N, 1>>(
        &mut self,
        f: &mut Ekf<N>,
        rows: impl IntoIterator<Item = (H, f64)>,
    ) -> Result<f64, FilterError> {
        let Some((fpf, q)) = self.pending else {
            return Ok(1.0);
        };
        let x = *f.state();
        let (mut nu2, mut hqh, mut hfh, mut m) = (0.0, 0.0, 0.0, 0usize);
        for (model, z) in rows {
            let sigma = model.r()[(0, 0)].sqrt();
            let h = model.jacobian(&x) / sigma;
            let nu = model.residual(&SVector::<f64, 1>::new(z), &model.h(&x))[0] / sigma;
            if !(nu.is_finite() && h.iter().all(|v| v.is_finite())) {
                continue;
            }
            nu2 += nu * nu;
            hqh += (h * q * h.transpose())[(0, 0)];
            hfh += (h * fpf * h.transpose())[(0, 0)];
            m += 1;
        }
        if m == 0 {
            return Ok(1.0);
        }
        self.pending = None;
        let k = m as f64;
        let v = match self.v {
            None => nu2 / k,
            Some(v0) => (self.forgetting * v0 + nu2 / k) / (1.0 + self.forgetting),
        };
        self.v = Some(v);
        let c = (v - hqh / k - self.weakening) / (hfh / k);
        let lambda = if c.is_finite() {
            c.clamp(1.0, self.max_fading)
        } else {
            1.0
        };
        self.last_lambda = lambda;
        if lambda > 1.0 {
            f.restart(x, symmetrise(&(fpf * lambda + q)))?;
        }
        Ok(lambda)
    }
}

/// The predicted measurement moments of a set of weighted points.
struct SigmaMoments<const N: usize, const M: usize> {
    z_hat: SVector<f64, M>,
    pzz: SMatrix<f64, M, M>,
    pxz: SMatrix<f64, N, M>,
}

fn sigma_moments<const N: usize, const M: usize, H: MeasurementModel<N, M>>(
    model: &H,
    points: &[SVector<f64, N>],
    wm: &[f64],
    wc: &[f64],
    x_mean: &SVector<f64, N>,
    zbuf: &mut Vec<f64>,
) -> SigmaMoments<N, M> {
    if zbuf.len() < points.len() * M {
        zbuf.resize(points.len() * M, 0.0);
    }
    let mut z_hat = SVector::<f64, M>::zeros();
    for (i, (pt, w)) in points.iter().zip(wm).enumerate() {
        let zi = model.h(pt);
        zbuf[i * M..(i + 1) * M].copy_from_slice(zi.as_slice());
        z_hat += zi * *w;
    }
    let mut pzz = SMatrix::<f64, M, M>::zeros();
    let mut pxz = SMatrix::<f64, N, M>::zeros();
    for (i, (pt, w)) in points.iter().zip(wc).enumerate() {
        let zi = SVector::<f64, M>::from_column_slice(&zbuf[i * M..(i + 1) * M]);
        let dz = model.residual(&zi, &z_hat);
        pzz += dz * dz.transpose() * *w;
        pxz += (pt - x_mean) * dz.transpose() * *w;
    }
    SigmaMoments { z_hat, pzz, pxz }
}

/// The strong tracking filter (Zhou & Frank, "Strong tracking filtering of nonlinear
/// time-varying stochastic systems with coloured noise", *Int. J. Control* 65(2), 1996;
/// Zhou & Xiao, *Acta Autom. Sin.* 38(9), 2012, seed 004's ref. 31): an EKF whose
/// predicted covariance is inflated by a fading factor `λ_k ≥ 1` chosen so that the
/// innovations stay orthogonal, which lets it follow a manoeuvre the model does not
/// describe:
///
/// ```text
/// V_k = ν₁ν₁ᵀ (k = 1),   V_k = (ρ V_{k−1} + ν_k ν_kᵀ)/(1 + ρ)        (ρ = 0.95)
/// N_k = V_k − H Q Hᵀ − β R,   M_k = H F P Fᵀ Hᵀ,   c_k = tr N_k / tr M_k
/// λ_k = min(λ_max, max(1, c_k)),   P⁻ = λ_k F P Fᵀ + Q
/// ```
/// then the EKF update (Joseph form) with that `P⁻` (and the filter's gates). `V`, `N`
/// and `M` take every component, gated or not: leaving out the components seed 004's eq.
/// 24 gate removes at the un-inflated prediction was tried on the loosely coupled INS of
/// `worlds/seed004-bupt.toml` and made it worse (RMSE 221 m against 10 m with every
/// component, 20 trials). `β ≥ 1` is the weakening (softening)
/// factor that smooths the estimate. Zhou & Frank's factor has no upper limit
/// (`λ_max = ∞`, the default of [`StrongTrackingFilter::new`]); an upper limit
/// ([`StrongTrackingFilter::with_max_fading`]) keeps a burst of innovations that no state
/// error explains (a biased fix indoors) from inflating the states the measurement does
/// not observe without bound, epoch after epoch. The factor needs the innovation, so [`StrongTrackingFilter::predict`]
/// keeps `F P Fᵀ` and `Q` apart until the update.
#[derive(Clone, Debug, PartialEq)]
pub struct StrongTrackingFilter<const N: usize, const M: usize> {
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    pending: Option<(SMatrix<f64, N, N>, SMatrix<f64, N, N>)>,
    v: Option<SMatrix<f64, M, M>>,
    forgetting: f64,
    weakening: f64,
    gating: Gating,
    max_fading: f64,
    last_lambda: f64,
}

impl<const N: usize, const M: usize> StrongTrackingFilter<N, M> {
    /// A filter at `x0`, `p0` with forgetting factor `ρ` (0 < ρ ≤ 1, 0.95 typical) and
    /// weakening factor `β ≥ 1`.
    ///
    /// # Errors
    /// An unusable prior or factor.
    pub fn new(
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        forgetting: f64,
        weakening: f64,
    ) -> Result<Self, FilterError> {
        check_prior(&x0, &p0)?;
        if !(forgetting > 0.0 && forgetting <= 1.0 && weakening.is_finite() && weakening >= 1.0) {
            return Err(FilterError::InvalidParameter(format!(
                "ρ = {forgetting}, β = {weakening}: expected 0 < ρ ≤ 1 and β ≥ 1"
            )));
        }
        Ok(Self {
            x: x0,
            p: p0,
            pending: None,
            v: None,
            forgetting,
            weakening,
            gating: Gating::default(),
            max_fading: f64::INFINITY,
            last_lambda: 1.0,
        })
    }

    /// The same filter with the fading factor limited to `λ_max` (≥ 1; `∞` is Zhou &
    /// Frank's unbounded factor).
    ///
    /// # Errors
    /// When `λ_max` is NaN or below 1.
    pub fn with_max_fading(mut self, max_fading: f64) -> Result<Self, FilterError> {
        if max_fading.is_nan() || max_fading < 1.0 {
            return Err(FilterError::InvalidParameter(format!(
                "λ_max = {max_fading}: expected ≥ 1"
            )));
        }
        self.max_fading = max_fading;
        Ok(self)
    }

    /// The same filter with `gating`.
    ///
    /// # Errors
    /// When a gate parameter is unusable.
    pub fn with_gating(mut self, gating: Gating) -> Result<Self, FilterError> {
        gating.validate()?;
        self.gating = gating;
        Ok(self)
    }

    /// The state.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// The covariance (after a prediction, the un-inflated `F P Fᵀ + Q`).
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// The fading factor of the last update.
    pub fn last_fading_factor(&self) -> f64 {
        self.last_lambda
    }

    /// Predicts over `dt_s` seconds, keeping `F P Fᵀ` and `Q` for the fading factor.
    ///
    /// # Errors
    /// An invalid interval or a non-finite result; the filter is then unchanged.
    pub fn predict<P: ProcessModel<N>>(&mut self, model: &P, dt_s: f64) -> Result<(), FilterError> {
        check_dt(dt_s)?;
        let f = model.jacobian(&self.x, dt_s);
        let x = model.f(&self.x, dt_s);
        let (fpf, q) = match self.pending {
            // Two predictions without an update between them compose; the factor of the
            // next update then inflates the whole propagated part.
            Some((fpf0, q0)) => (
                f * fpf0 * f.transpose(),
                f * q0 * f.transpose() + model.q(&self.x, dt_s),
            ),
            None => (f * self.p * f.transpose(), model.q(&self.x, dt_s)),
        };
        let p = symmetrise(&(fpf + q));
        if !usable(&x, &p) {
            return Err(FilterError::NonFinite);
        }
        self.x = x;
        self.p = p;
        self.pending = Some((symmetrise(&fpf), q));
        Ok(())
    }

    /// Updates with measurement `z` of `model`, inflating the prediction by `λ_k` first.
    pub fn update<H: MeasurementModel<N, M>>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
    ) -> UpdateReport {
        let r = match measurement_inputs(model, z) {
            Ok(r) => r,
            Err(rep) => return rep,
        };
        let h = model.jacobian(&self.x);
        let nu = model.residual(z, &model.h(&self.x));
        if !finite(nu.iter()) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, f64::NAN);
        }
        let outer = nu * nu.transpose();
        let v = match self.v {
            None => outer,
            Some(v) => (v * self.forgetting + outer) / (1.0 + self.forgetting),
        };
        let (lambda, p_prior) = match self.pending {
            Some((fpf, q)) => {
                let n_k = v - h * q * h.transpose() - r * self.weakening;
                let m_k = h * fpf * h.transpose();
                let c = n_k.trace() / m_k.trace();
                let lambda = if c.is_finite() {
                    c.clamp(1.0, self.max_fading)
                } else {
                    1.0
                };
                (lambda, symmetrise(&(fpf * lambda + q)))
            }
            None => (1.0, self.p),
        };
        let pht = p_prior * h.transpose();
        let s = h * pht + r;
        let g = apply_residual_gate(self.gating.residual, &[true; M], &r, nu, s, pht);
        let (k, nis) = match gain_and_nis(&g, self.gating.chi2_prob) {
            Ok(v) => v,
            Err(rep) => return rep,
        };
        let x = self.x + k * g.nu;
        let a = SMatrix::<f64, N, N>::identity() - k * h;
        let p = symmetrise(&(a * p_prior * a.transpose() + k * r * k.transpose()));
        if !usable(&x, &p) {
            return UpdateReport::refused::<M>(RejectReason::NumericalFailure, nis);
        }
        self.x = x;
        self.p = p;
        self.v = Some(v);
        self.pending = None;
        self.last_lambda = lambda;
        accepted(nis, &g)
    }
}

/// The coupling-degree figures of one relative-entropy update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingReport<const M: usize> {
    /// `ℵ = ½ log|I + R⁻¹ χ|` of the whole measurement (eq. 34).
    pub aleph: f64,
    /// `ℵ̂_i = ½ log(1 + χ_ii / R_ii)` per component (eq. 37).
    pub aleph_i: [f64; M],
    /// Components kept by the coupling threshold and by the residual gate.
    pub kept: [bool; M],
}

/// Seed 004's relative-entropy Kalman filter (Zhang et al., "Relative entropy-based
/// Kalman filter for seamless indoor/outdoor multi-source fusion positioning with
/// INS/TC-OFDM/GNSS", §3, eqs. 20–41, after Gultekin & Paisley, *IEEE Trans. SP* 2017).
///
/// Prediction is eqs. 27–28 (`x⁻ = F x`, `P⁻ = F P Fᵀ + Q`, with `F` the Jacobian of a
/// nonlinear model). The update:
///
/// ```text
/// data layer (eqs. 22–24):  d = z − ẑ,  ε = P_zz + R,  keep j if |d_j| ≤ C·√ε_jj
/// moments (eqs. 35–36):     Ψ = Σ w (χ_i − μ⁻)(ζ_i − ẑ)ᵀ = P_xz,   P_zz = Σ w (ζ_i − ẑ)(ζ_i − ẑ)ᵀ
///                           χ = P_zz − Ψᵀ (P⁻)⁻¹ Ψ
/// coupling (eqs. 34, 37):   ℵ = ½ log|I + R⁻¹ χ|,   ℵ̂_i = ½ log(1 + χ_ii / R_ii)
/// selection (eq. 38):       ϖ keeps component i when ℵ̂_i < ℵ_threshold (and eq. 24 holds)
/// gain, mean, covariance (eqs. 39–41):
///     K̃ = Ψ ϖᵀ (ϖ (P_zz + R) ϖᵀ)⁻¹,   μ⁺ = μ⁻ + K̃ ϖ (z − ẑ),   P⁺ = P⁻ − K̃ ϖ(P_zz + R)ϖᵀ K̃ᵀ
/// ```
///
/// # Reading of the paper
///
/// The paper's sums `Σ_X Σ_Z` are expectations over the predicted joint density of state
/// and measurement (its eqs. 31–32 are the general Gaussian filter, where `Σ_Z (Z_k −
/// Z_{k−1})(Z_k − Z_{k−1})ᵀ + R` can only be the innovation covariance); they are
/// evaluated here with Arasaratnam & Haykin's cubature points. `χ` is then the part of the
/// measurement spread that the best linear function of the state does not explain: zero
/// for a linear `h`, where the filter is exactly the Kalman filter, and growing with the
/// curvature of `h` across the prior. `ℵ̂_i` measures that linearisation loss against the
/// noise, and a component whose loss is too large is left out rather than allowed to
/// corrupt the estimate. The paper gives no value for `ℵ_threshold`; the default
/// `½ ln 2` leaves out a component whose unexplained spread exceeds its noise variance.
/// Outliers are the data layer's job (eq. 24), applied before the coupling test as in the
/// paper's Fig. 3.
#[derive(Clone, Debug, PartialEq)]
pub struct RelativeEntropyKf<const N: usize> {
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    threshold: f64,
    residual_gate: Option<ResidualGate>,
    points: Vec<SVector<f64, N>>,
    weights: Vec<f64>,
    zbuf: Vec<f64>,
}

/// The default coupling-degree threshold `ℵ_threshold = ½ ln 2`.
pub const DEFAULT_ALEPH_THRESHOLD: f64 = 0.346_573_590_279_972_6;

impl<const N: usize> RelativeEntropyKf<N> {
    /// A filter at `x0`, `p0` with coupling threshold `threshold` and the data-layer gate
    /// `residual_gate` (seed 004 suggests `C = 2` or `3`; `None` switches it off).
    ///
    /// # Errors
    /// An unusable prior, a threshold that is not positive, or a gate factor ≤ 0.
    pub fn new(
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        threshold: f64,
        residual_gate: Option<ResidualGate>,
    ) -> Result<Self, FilterError> {
        check_prior(&x0, &p0)?;
        if threshold.is_nan() || threshold <= 0.0 {
            return Err(FilterError::InvalidParameter(format!(
                "ℵ threshold = {threshold}: expected > 0"
            )));
        }
        Gating {
            chi2_prob: None,
            residual: residual_gate,
        }
        .validate()?;
        Ok(Self {
            x: x0,
            p: p0,
            threshold,
            residual_gate,
            points: vec![SVector::<f64, N>::zeros(); 2 * N],
            weights: vec![0.5 / N as f64; 2 * N],
            zbuf: Vec::new(),
        })
    }

    /// The state.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// The covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Restarts the filter from `x0`, `p0` (keeping its threshold and gate).
    ///
    /// # Errors
    /// When `x0` or `p0` is not finite or `p0` is not a covariance.
    pub fn restart(
        &mut self,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        check_prior(&x0, &p0)?;
        self.x = x0;
        self.p = p0;
        Ok(())
    }

    /// Predicts over `dt_s` seconds (eqs. 27–28).
    ///
    /// # Errors
    /// An invalid interval or a non-finite result; the filter is then unchanged.
    pub fn predict<P: ProcessModel<N>>(&mut self, model: &P, dt_s: f64) -> Result<(), FilterError> {
        linearised_predict(&mut self.x, &mut self.p, model, dt_s)
    }

    /// Updates with measurement `z` of `model` (eqs. 22–24, 34–41). Returns the report and
    /// the coupling figures (`None` when the update could not compute them).
    pub fn update<H: MeasurementModel<N, M>, const M: usize>(
        &mut self,
        model: &H,
        z: &SVector<f64, M>,
    ) -> (UpdateReport, Option<CouplingReport<M>>) {
        let r = match measurement_inputs(model, z) {
            Ok(r) => r,
            Err(rep) => return (rep, None),
        };
        let refused = || UpdateReport::refused::<M>(RejectReason::NumericalFailure, f64::NAN);
        // A prior that is only semi-definite (a state known exactly) has no Cholesky
        // factor; its points come from the semi-definite factor of [`psd_sqrt`] instead.
        let chol_p = self.p.cholesky();
        let factor = match &chol_p {
            Some(c) => Some(c.l()),
            None => psd_sqrt(&self.p),
        };
        let Some(factor) = factor else {
            return (refused(), None);
        };
        let l = factor * (N as f64).sqrt();
        for i in 0..N {
            self.points[i] = self.x + l.column(i);
            self.points[N + i] = self.x - l.column(i);
        }
        let m = sigma_moments(
            model,
            &self.points,
            &self.weights,
            &self.weights,
            &self.x,
            &mut self.zbuf,
        );
        let psi = m.pxz;
        let chi = match &chol_p {
            Some(c) => m.pzz - psi.transpose() * c.solve(&psi),
            // With χ_i = μ ± √n L_i the cross covariance is Ψ = L Dᵀ, D's column i being
            // (ζ_i⁺ − ζ_i⁻)/(2√n), so Ψᵀ P⁻¹ Ψ = D Dᵀ whenever L has full rank; when it
            // does not, the columns of L that are zero give ζ_i⁺ = ζ_i⁻ and D Dᵀ is the
            // same product with the pseudo-inverse. No inverse of P is needed.
            None => {
                let scale = 0.5 / (N as f64).sqrt();
                let mut ddt = SMatrix::<f64, M, M>::zeros();
                for i in 0..N {
                    let d = SVector::<f64, M>::from_fn(|j, _| {
                        (self.zbuf[i * M + j] - self.zbuf[(N + i) * M + j]) * scale
                    });
                    ddt += d * d.transpose();
                }
                m.pzz - ddt
            }
        };
        let nu = model.residual(z, &m.z_hat);
        let s = m.pzz + r;
        if !(finite(chi.iter()) && finite(nu.iter()) && finite(s.iter())) {
            return (refused(), None);
        }
        // Eq. 34 on the whole measurement: |I + R⁻¹χ| = |R + χ| / |R|, both through
        // Cholesky factors. R + χ is positive definite in exact arithmetic (χ is a Schur
        // complement of the joint covariance, so it is semi-definite); when rounding
        // spoils that, ℵ is reported as NaN and the per-component test below still works.
        let log_det = |m: SMatrix<f64, M, M>| {
            m.cholesky()
                .map_or(f64::NAN, |c| 2.0 * c.l().diagonal().map(|v| v.ln()).sum())
        };
        let aleph = 0.5 * (log_det(r + chi) - log_det(r));
        let mut aleph_i = [0.0; M];
        let mut keep = [true; M];
        for j in 0..M {
            aleph_i[j] = 0.5 * (chi[(j, j)].max(0.0) / r[(j, j)]).ln_1p();
            keep[j] = aleph_i[j] < self.threshold;
        }
        let g = apply_residual_gate(self.residual_gate, &keep, &r, nu, s, psi);
        let coupling = CouplingReport {
            aleph,
            aleph_i,
            kept: g.keep,
        };
        let (k, nis) = match gain_and_nis(&g, None) {
            Ok(v) => v,
            Err(rep) => return (rep, Some(coupling)),
        };
        let x = self.x + k * g.nu;
        let p = symmetrise(&(self.p - k * g.s * k.transpose()));
        if !usable(&x, &p) {
            return (
                UpdateReport::refused::<M>(RejectReason::NumericalFailure, nis),
                Some(coupling),
            );
        }
        self.x = x;
        self.p = p;
        (accepted(nis, &g), Some(coupling))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::models::{ConstantVelocity, PositionFixModel};

    fn prior() -> (SVector<f64, 4>, SMatrix<f64, 4, 4>) {
        (
            SVector::<f64, 4>::new(0.0, 1.0, 0.0, -1.0),
            SMatrix::<f64, 4, 4>::identity() * 4.0,
        )
    }

    #[test]
    fn scalar_textbook_case_for_every_filter() {
        // Prior N(0, 4) on x, fix z = 2 with R = 4: posterior mean 1, variance 2 whatever
        // the filter, since the model is linear.
        let fix = PositionFixModel::<4, 1>::new([0], SMatrix::<f64, 1, 1>::new(4.0)).unwrap();
        let z = SVector::<f64, 1>::new(2.0);
        let (x0, p0) = prior();
        let mut ekf = Ekf::new(x0, p0).unwrap();
        let mut ukf = SigmaPointKf::unscented(x0, p0, 0.5, 2.0, 0.0).unwrap();
        let mut ckf = SigmaPointKf::cubature(x0, p0).unwrap();
        let mut rekf = RelativeEntropyKf::new(x0, p0, DEFAULT_ALEPH_THRESHOLD, None).unwrap();
        let mut stf = StrongTrackingFilter::<4, 1>::new(x0, p0, 0.95, 1.0).unwrap();
        assert!(ekf.update(&fix, &z).outcome.is_accepted());
        assert!(ukf.update(&fix, &z).outcome.is_accepted());
        assert!(ckf.update(&fix, &z).outcome.is_accepted());
        let (rep, coupling) = rekf.update(&fix, &z);
        assert!(rep.outcome.is_accepted());
        assert!(coupling.unwrap().aleph.abs() < 1e-12, "linear h: χ = 0");
        assert!(stf.update(&fix, &z).outcome.is_accepted());
        for (x, p) in [
            (ekf.state(), ekf.covariance()),
            (ukf.state(), ukf.covariance()),
            (ckf.state(), ckf.covariance()),
            (rekf.state(), rekf.covariance()),
            (stf.state(), stf.covariance()),
        ] {
            assert!((x[0] - 1.0).abs() < 1e-12 && (p[(0, 0)] - 2.0).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_numbers_are_refused_and_leave_the_filter_unchanged() {
        let (x0, p0) = prior();
        let cv = ConstantVelocity::<4>::new(0.1).unwrap();
        let mut ekf = Ekf::new(x0, p0).unwrap();
        assert!(matches!(
            ekf.predict(&cv, f64::NAN),
            Err(FilterError::InvalidInterval { .. })
        ));
        assert!(ekf.predict(&cv, -1.0).is_err());
        let fix = PositionFixModel::<4, 1>::new([0], SMatrix::<f64, 1, 1>::new(4.0)).unwrap();
        let before = ekf.clone();
        let rep = ekf.update(&fix, &SVector::<f64, 1>::new(f64::NAN));
        assert_eq!(
            rep.outcome.reject_reason(),
            Some(RejectReason::NonFiniteInput)
        );
        assert_eq!(ekf, before);
        // A covariance without a Cholesky factor: the UKF cannot draw points.
        let mut bad = SMatrix::<f64, 4, 4>::identity();
        bad[(0, 1)] = 2.0;
        bad[(1, 0)] = 2.0;
        let mut ukf = SigmaPointKf::unscented(x0, bad, 1.0, 2.0, 0.0).unwrap();
        assert_eq!(ukf.predict(&cv, 1.0), Err(FilterError::NotPositiveDefinite));
        assert!(Ekf::new(SVector::<f64, 4>::from_element(f64::INFINITY), p0).is_err());
        assert!(SigmaPointKf::unscented(x0, p0, 0.0, 2.0, 0.0).is_err());
    }

    #[test]
    fn residual_gate_removes_exactly_one_component() {
        // Two independent fixes of x and y; an outlier on y. The gated update must equal
        // the update with the x fix alone.
        let (x0, p0) = prior();
        let both = PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity()).unwrap();
        let only_x = PositionFixModel::<4, 1>::new([0], SMatrix::<f64, 1, 1>::identity()).unwrap();
        let gating = Gating {
            chi2_prob: None,
            residual: Some(ResidualGate::sigmas(3.0)),
        };
        let mut a = Ekf::new(x0, p0).unwrap().with_gating(gating).unwrap();
        let mut b = Ekf::new(x0, p0).unwrap();
        let rep = a.update(&both, &SVector::<f64, 2>::new(1.0, 100.0));
        assert_eq!((rep.used, rep.rejected), (1, 1));
        b.update(&only_x, &SVector::<f64, 1>::new(1.0));
        assert!((a.state() - b.state()).amax() < 1e-12);
        assert!((a.covariance() - b.covariance()).amax() < 1e-12);
        // The χ² gate refuses the whole update.
        let mut c = Ekf::new(x0, p0)
            .unwrap()
            .with_gating(Gating {
                chi2_prob: Some(0.999),
                residual: None,
            })
            .unwrap();
        let rep = c.update(&both, &SVector::<f64, 2>::new(1.0, 100.0));
        assert!(matches!(
            rep.outcome.reject_reason(),
            Some(RejectReason::Gate { .. })
        ));
        assert_eq!(c.state(), &x0);
    }

    /// A gated component is "state-led" exactly when the prior variance along it, here
    /// `P_jj = 4`, is at least its noise `R_jj`: with `R = diag(1, 9)` an outlier on x is
    /// refused against the state's greater doubt, one on y against the measurement's;
    /// the χ² refusal of the whole vector counts the components whose `P_jj ≥ R_jj`. Every
    /// filter of the family reports the same count.
    #[test]
    fn gated_components_are_state_led_when_the_state_is_the_less_certain() {
        let (x0, p0) = prior();
        let r = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::<f64, 2>::new(1.0, 9.0));
        let fix = PositionFixModel::<4, 2>::new([0, 2], r).unwrap();
        let residual = Gating {
            chi2_prob: None,
            residual: Some(ResidualGate::sigmas(3.0)),
        };
        let state_led = |z: SVector<f64, 2>, gating: Gating| {
            let mut ekf = Ekf::new(x0, p0).unwrap().with_gating(gating).unwrap();
            let mut ckf = SigmaPointKf::cubature(x0, p0)
                .unwrap()
                .with_gating(gating)
                .unwrap();
            let (a, b) = (ekf.update(&fix, &z), ckf.update(&fix, &z));
            assert_eq!(
                (a.rejected, a.rejected_state_led),
                (b.rejected, b.rejected_state_led)
            );
            (a.rejected, a.rejected_state_led)
        };
        // Innovations 100 and 1 (x0 = (0, 1, 0, −1)): x refused, state-led (4 ≥ 1).
        assert_eq!(
            state_led(SVector::<f64, 2>::new(100.0, 1.0), residual),
            (1, 1)
        );
        // y refused, measurement-led (4 < 9).
        assert_eq!(
            state_led(SVector::<f64, 2>::new(1.0, 100.0), residual),
            (1, 0)
        );
        let chi2 = Gating {
            chi2_prob: Some(0.999),
            residual: None,
        };
        assert_eq!(state_led(SVector::<f64, 2>::new(1.0, 100.0), chi2), (2, 1));
        assert_eq!(state_led(SVector::<f64, 2>::new(0.5, 0.5), chi2), (0, 0));
    }

    #[test]
    fn psd_sqrt_factors_semi_definite_covariances() {
        // Positive definite: exactly the Cholesky factor.
        let (_, p0) = prior();
        let pd = p0 + SMatrix::<f64, 4, 4>::from_fn(|i, j| 0.3 / (1.0 + (i + j) as f64));
        assert_eq!(psd_sqrt(&pd), Some(pd.cholesky().unwrap().l()));
        // Rank two in four states, one of them known exactly (zero row and column).
        let a = SMatrix::<f64, 4, 2>::new(3.0, 0.0, 1.0, 2.0, 0.0, 0.0, -2.0, 5.0);
        let p = a * a.transpose();
        assert!(p.cholesky().is_none());
        let l = psd_sqrt(&p).unwrap();
        assert!((l * l.transpose() - p).amax() < 1e-12 * p.amax());
        assert!(
            l.row(2).iter().all(|&v| v == 0.0),
            "the known state moves no point"
        );
        assert_eq!(
            l.column(2),
            SVector::<f64, 4>::zeros(),
            "rank 2: two zero columns"
        );
        assert_eq!(l.column(3), SVector::<f64, 4>::zeros());
        // Not a covariance: refused.
        let mut bad = SMatrix::<f64, 4, 4>::identity();
        bad[(1, 1)] = -1.0;
        assert!(psd_sqrt(&bad).is_none());
        assert_eq!(
            psd_sqrt(&SMatrix::<f64, 4, 4>::zeros()),
            Some(SMatrix::zeros())
        );
    }

    #[test]
    fn a_known_state_gives_every_filter_the_kalman_posterior() {
        // Constant velocity in two axes with the x axis known exactly (zero variance, no
        // process noise on it is not needed: it is only updated once). The model is linear,
        // so every filter must give the Kalman filter's posterior, and the known position
        // must not move.
        let x0 = SVector::<f64, 4>::new(1.0, 0.5, -2.0, 1.0);
        let mut p0 = SMatrix::<f64, 4, 4>::zeros();
        p0[(1, 1)] = 0.25;
        p0[(2, 2)] = 9.0;
        p0[(3, 3)] = 1.0;
        p0[(2, 3)] = 0.5;
        p0[(3, 2)] = 0.5;
        let fix =
            PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity() * 4.0).unwrap();
        let z = SVector::<f64, 2>::new(1.5, 0.0);
        let mut ekf = Ekf::new(x0, p0).unwrap();
        ekf.update(&fix, &z);
        let mut ukf = SigmaPointKf::unscented(x0, p0, 0.5, 2.0, 0.0).unwrap();
        let mut ckf = SigmaPointKf::cubature(x0, p0).unwrap();
        let mut rekf = RelativeEntropyKf::new(x0, p0, DEFAULT_ALEPH_THRESHOLD, None).unwrap();
        assert!(ukf.update(&fix, &z).outcome.is_accepted());
        assert!(ckf.update(&fix, &z).outcome.is_accepted());
        let (rep, coupling) = rekf.update(&fix, &z);
        assert!(rep.outcome.is_accepted());
        assert!(coupling.unwrap().aleph.abs() < 1e-12, "linear h: χ = 0");
        // Prior y variance 9, fix variance 4: y moves 9/13 of the way to 0.
        assert!((ekf.state()[2] - (-2.0 + 2.0 * 9.0 / 13.0)).abs() < 1e-12);
        for (x, p) in [
            (ukf.state(), ukf.covariance()),
            (ckf.state(), ckf.covariance()),
            (rekf.state(), rekf.covariance()),
        ] {
            assert!((x - ekf.state()).amax() < 1e-12, "{x:?}");
            assert!((p - ekf.covariance()).amax() < 1e-12, "{p:?}");
            assert_eq!(x[0], 1.0);
        }
        // The prediction works from the semi-definite prior too (it spreads x by ẋ).
        let cv = ConstantVelocity::<4>::new(0.0).unwrap();
        let mut e = Ekf::new(x0, p0).unwrap();
        e.predict(&cv, 2.0).unwrap();
        ckf.restart(x0, p0).unwrap();
        ckf.predict(&cv, 2.0).unwrap();
        assert!((ckf.covariance() - e.covariance()).amax() < 1e-12);
        assert!(
            (e.covariance()[(0, 0)] - 1.0).abs() < 1e-12,
            "4 s² · 0.25 m²/s²"
        );
    }

    #[test]
    fn epoch_fading_factor_matches_its_formula() {
        // One axis of constant velocity, two position fixes in the epoch, by hand:
        // FPFᵀ₀₀ = P₀₀ + 2T P₀₁ + T² P₁₁, Q₀₀ = qT³/3, c = (ν̄² − Q₀₀/σ² − β)/(FPFᵀ₀₀/σ²).
        let cv = ConstantVelocity::<2>::new(0.5).unwrap();
        let x0 = SVector::<f64, 2>::new(0.0, 1.0);
        let p0 = SMatrix::<f64, 2, 2>::new(1.0, 0.2, 0.2, 0.5);
        let sigma: f64 = 0.5;
        let fix =
            PositionFixModel::<2, 1>::new([0], SMatrix::<f64, 1, 1>::new(sigma * sigma)).unwrap();
        let mut f = Ekf::new(x0, p0).unwrap();
        let mut fading = EpochFading::<2>::new(0.95, 1.0, 10.0).unwrap();
        let t = 1.0;
        fading.predict(&mut f, &cv, t).unwrap();
        assert_eq!(f.state()[0], 1.0);
        let zs = [4.0, 3.0];
        let lambda = fading.inflate(&mut f, zs.map(|z| (fix, z))).unwrap();
        let fpf = 1.0 + 2.0 * t * 0.2 + t * t * 0.5;
        let q = 0.5 * t * t * t / 3.0;
        let nu2 = zs.iter().map(|z| ((z - 1.0) / sigma).powi(2)).sum::<f64>() / 2.0;
        let c = (nu2 - q / (sigma * sigma) - 1.0) / (fpf / (sigma * sigma));
        assert!(c > 1.0 && c < 10.0);
        assert!((lambda - c).abs() < 1e-12, "{lambda} against {c}");
        assert!((f.covariance()[(0, 0)] - (c * fpf + q)).abs() < 1e-12);
        // Small innovations: no inflation; no pending prediction: factor 1.
        fading.predict(&mut f, &cv, t).unwrap();
        let x = f.state()[0];
        assert_eq!(fading.inflate(&mut f, [(fix, x)]).unwrap(), 1.0);
        assert_eq!(fading.inflate(&mut f, [(fix, x + 100.0)]).unwrap(), 1.0);
        assert!(EpochFading::<2>::new(0.0, 1.0, 10.0).is_err());
        assert!(EpochFading::<2>::new(0.95, 0.5, 10.0).is_err());
    }
    #[test]
    fn stf_fading_factor_is_zhou_and_franks_and_never_exceeds_its_limit() {
        // One axis of constant velocity and a scalar position fix, by hand (Zhou & Frank):
        // V₁ = ν², c = (V₁ − Q₀₀ − βR)/FPFᵀ₀₀, λ = min(λ_max, max(1, c)), and the update
        // is the Kalman update with P⁻ = λ FPFᵀ + Q.
        let cv = ConstantVelocity::<2>::new(0.5).unwrap();
        let x0 = SVector::<f64, 2>::new(0.0, 1.0);
        let p0 = SMatrix::<f64, 2, 2>::new(1.0, 0.2, 0.2, 0.5);
        let r = 0.25;
        let fix = PositionFixModel::<2, 1>::new([0], SMatrix::<f64, 1, 1>::new(r)).unwrap();
        let (t, beta) = (1.0, 1.0);
        let fpf = 1.0 + 2.0 * t * 0.2 + t * t * 0.5;
        let q = 0.5 * t * t * t / 3.0;
        for (z, lambda_max) in [(4.0, f64::INFINITY), (4.0, 2.0), (1.5, 2.0), (30.0, 10.0)] {
            let mut stf = StrongTrackingFilter::<2, 1>::new(x0, p0, 0.95, beta)
                .unwrap()
                .with_max_fading(lambda_max)
                .unwrap();
            stf.predict(&cv, t).unwrap();
            let nu: f64 = z - 1.0;
            let c = (nu * nu - q - beta * r) / fpf;
            let want = c.clamp(1.0, lambda_max);
            assert!(stf
                .update(&fix, &SVector::<f64, 1>::new(z))
                .outcome
                .is_accepted());
            let got = stf.last_fading_factor();
            assert!(got <= lambda_max, "λ = {got} above λ_max = {lambda_max}");
            assert!((got - want).abs() < 1e-12, "λ = {got}, analytic {want}");
            let p00 = want * fpf + q;
            let k = p00 / (p00 + r);
            assert!((stf.state()[0] - (1.0 + k * nu)).abs() < 1e-12);
            assert!((stf.covariance()[(0, 0)] - (1.0 - k) * p00).abs() < 1e-12);
        }
        let base = StrongTrackingFilter::<2, 1>::new(x0, p0, 0.95, 1.0).unwrap();
        assert!(base.clone().with_max_fading(0.5).is_err());
        assert!(base.with_max_fading(f64::NAN).is_err());
    }
}
