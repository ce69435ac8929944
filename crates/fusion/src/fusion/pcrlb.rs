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

use crate::core::System;
use crate::fusion::models::{PlaneTurning, ProcessModel, Singer5};
use crate::fusion::paper::{ClockMode, ProcessSpec, N_CLOCKS};
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
