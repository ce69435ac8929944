//! Seed 001's target: uniform motion in x and a Singer-manoeuvring y.
//!
//! Seed 001 (GPS + DTMB particle filter, §3 eq. (2) and §5) models a car in two dimensions:
//! "the target is in line with Singer model in y direction, and uniform motion model
//! without error in x direction", with state `X = [x, ẋ, y, ẏ, ÿ]ᵀ`, X(0) = [4000, 14, 0,
//! 11, 0]ᵀ, manoeuvre frequency α = 0.1 s⁻¹, acceleration variance σ_m² = 3.5 (m/s²)², 100 s
//! at 1 s. The paper's printed F and Q did not survive text extraction; the model is
//! Singer's (1970), which this module implements exactly.
//!
//! Singer's continuous-time model of the manoeuvring axis is a first-order Gauss–Markov
//! acceleration,
//!
//! ```text
//! ÿ' = −α ÿ + w(t),   E[w(t) w(t+τ)] = 2 α σ_m² δ(τ),
//! ```
//!
//! whose stationary variance is σ_m² and autocorrelation `σ_m² e^{−α|τ|}`. Sampled at a step
//! T, the state `[y, ẏ, ÿ]` evolves exactly as `s_{k+1} = F s_k + u_k`, u_k ~ N(0, Q), with
//! (Singer 1970, eqs. (13)–(15); Bar-Shalom, Li & Kirubarajan 2001, §8.2.3):
//!
//! ```text
//!     ┌ 1  T  (αT − 1 + e^{−αT})/α² ┐
//! F = │ 0  1  (1 − e^{−αT})/α       │
//!     └ 0  0  e^{−αT}               ┘
//!
//! Q = 2 α σ_m² [q_ij],
//! q11 = (1 − e^{−2αT} + 2αT + 2α³T³/3 − 2α²T² − 4αT e^{−αT}) / (2α⁵)
//! q12 = (e^{−2αT} + 1 − 2e^{−αT} + 2αT e^{−αT} − 2αT + α²T²) / (2α⁴)
//! q13 = (1 − e^{−2αT} − 2αT e^{−αT}) / (2α³)
//! q22 = (4e^{−αT} − 3 − e^{−2αT} + 2αT) / (2α³)
//! q23 = (e^{−2αT} + 1 − 2e^{−αT}) / (2α²)
//! q33 = (1 − e^{−2αT}) / (2α)
//! ```
//!
//! These closed forms cancel catastrophically when αT is small (q11 is a difference of O(1)
//! terms that equals O((αT)⁵)), so for αT < 0.1 Q is integrated instead,
//! `Q = 2ασ_m² ∫₀ᵀ g(s) g(s)ᵀ ds` with `g(s) = F(s)·[0, 0, 1]ᵀ`, by 8-point Gauss–Legendre
//! quadrature, which is exact to rounding there because the integrand is then nearly a
//! low-degree polynomial. Noise samples use the symmetric square root of Q (eigen
//! decomposition), which tolerates the near-singular Q of very short steps.
//!
//! Between the generated steps the y axis is a quintic Hermite interpolant of position,
//! velocity and acceleration at both ends: position, velocity and acceleration are then
//! continuous and exact derivatives of one another, and equal the generated Singer samples
//! at every step. x is exactly `x₀ + ẋ t`.

use super::{clamp_time, heading_of, Trajectory, TruthState};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// Below this αT the closed-form Q loses digits and quadrature is used instead.
const CLOSED_FORM_MIN_ALPHA_T: f64 = 0.1;

/// The Singer transition matrix F(T) for `[y, ẏ, ÿ]`.
pub fn singer_transition(alpha_per_s: f64, t_s: f64) -> Matrix3<f64> {
    let g = singer_gain(alpha_per_s, t_s);
    Matrix3::new(1.0, t_s, g.x, 0.0, 1.0, g.y, 0.0, 0.0, g.z)
}

/// The third column of F(s), i.e. the response of `[y, ẏ, ÿ]` at time s to a unit
/// acceleration at time 0, computed without cancellation: `expm1` keeps
/// `(1 − e^{−αs})/α` exact, and `(αs − 1 + e^{−αs})/α²` uses its series for small αs.
fn singer_gain(alpha: f64, s: f64) -> Vector3<f64> {
    let x = alpha * s;
    let e = (-x).exp();
    let one_minus_e_over_alpha = -(-x).exp_m1() / alpha;
    let pos = if x < 1e-3 {
        // (x − 1 + e^{−x})/α² = s² (1/2 − x/6 + x²/24 − x³/120 + …)
        s * s * (0.5 - x / 6.0 + x * x / 24.0 - x * x * x / 120.0)
    } else {
        (x + (-x).exp_m1()) / (alpha * alpha)
    };
    Vector3::new(pos, one_minus_e_over_alpha, e)
}

/// The closed-form Singer process noise covariance (Singer 1970) for `[y, ẏ, ÿ]`.
/// Accurate when αT ≳ 0.1; see [`singer_process_noise`] for all αT.
pub fn singer_process_noise_closed_form(alpha: f64, accel_var: f64, t: f64) -> Matrix3<f64> {
    let a = alpha;
    let at = a * t;
    let e1 = (-at).exp();
    let e2 = (-2.0 * at).exp();
    let q11 = (1.0 - e2 + 2.0 * at + 2.0 * at.powi(3) / 3.0 - 2.0 * at * at - 4.0 * at * e1)
        / (2.0 * a.powi(5));
    let q12 = (e2 + 1.0 - 2.0 * e1 + 2.0 * at * e1 - 2.0 * at + at * at) / (2.0 * a.powi(4));
    let q13 = (1.0 - e2 - 2.0 * at * e1) / (2.0 * a.powi(3));
    let q22 = (4.0 * e1 - 3.0 - e2 + 2.0 * at) / (2.0 * a.powi(3));
    let q23 = (e2 + 1.0 - 2.0 * e1) / (2.0 * a * a);
    let q33 = (1.0 - e2) / (2.0 * a);
    2.0 * a * accel_var * Matrix3::new(q11, q12, q13, q12, q22, q23, q13, q23, q33)
}

/// Nodes and weights of 8-point Gauss–Legendre quadrature on [−1, 1].
const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

/// `2ασ² ∫ g gᵀ ds` over `[0, t]` by composite 8-point Gauss–Legendre with `pieces`
/// sub-intervals.
pub(crate) fn singer_process_noise_quadrature(
    alpha: f64,
    accel_var: f64,
    t: f64,
    pieces: usize,
) -> Matrix3<f64> {
    let mut q = Matrix3::zeros();
    let h = t / pieces as f64;
    for p in 0..pieces {
        let mid = (p as f64 + 0.5) * h;
        for (x, w) in GL8 {
            let g = singer_gain(alpha, mid + 0.5 * h * x);
            q += (w * 0.5 * h) * g * g.transpose();
        }
    }
    2.0 * alpha * accel_var * q
}

/// The Singer process noise covariance Q(T) for `[y, ẏ, ÿ]`, accurate for every αT: the
/// closed form when αT ≥ 0.1, quadrature below.
pub fn singer_process_noise(alpha_per_s: f64, accel_var: f64, t_s: f64) -> Matrix3<f64> {
    if alpha_per_s * t_s >= CLOSED_FORM_MIN_ALPHA_T {
        singer_process_noise_closed_form(alpha_per_s, accel_var, t_s)
    } else {
        singer_process_noise_quadrature(alpha_per_s, accel_var, t_s, 1)
    }
}

/// A square root S of a symmetric positive semi-definite matrix (S Sᵀ = Q), with negative
/// rounding-level eigenvalues clamped to zero.
pub(crate) fn psd_sqrt(q: &Matrix3<f64>) -> Matrix3<f64> {
    let eig = SymmetricEigen::new(*q);
    let mut s = eig.eigenvectors;
    for (j, lam) in eig.eigenvalues.iter().enumerate() {
        let r = lam.max(0.0).sqrt();
        for i in 0..3 {
            s[(i, j)] *= r;
        }
    }
    s
}

/// Position, velocity and acceleration at fraction `u` ∈ [0, 1] of a step of length `h`
/// of the quintic that matches position, velocity and acceleration at both ends.
pub(crate) fn quintic_hermite(
    s0: &Vector3<f64>,
    s1: &Vector3<f64>,
    h: f64,
    u: f64,
) -> Vector3<f64> {
    let (p0, v0, a0) = (s0.x, s0.y, s0.z);
    let (p1, v1, a1) = (s1.x, s1.y, s1.z);
    let dp = p1 - p0;
    let h2 = h * h;
    let c0 = p0;
    let c1 = v0 * h;
    let c2 = 0.5 * a0 * h2;
    let c3 = 10.0 * dp - (6.0 * v0 + 4.0 * v1) * h - 0.5 * (3.0 * a0 - a1) * h2;
    let c4 = -15.0 * dp + (8.0 * v0 + 7.0 * v1) * h + 0.5 * (3.0 * a0 - 2.0 * a1) * h2;
    let c5 = 6.0 * dp - 3.0 * (v0 + v1) * h - 0.5 * (a0 - a1) * h2;
    let p = c0 + u * (c1 + u * (c2 + u * (c3 + u * (c4 + u * c5))));
    let dp_du = c1 + u * (2.0 * c2 + u * (3.0 * c3 + u * (4.0 * c4 + u * 5.0 * c5)));
    let d2p_du2 = 2.0 * c2 + u * (6.0 * c3 + u * (12.0 * c4 + u * 20.0 * c5));
    Vector3::new(p, dp_du / h, d2p_du2 / h2)
}

/// A generated Singer trajectory: knots of `[y, ẏ, ÿ]` every `step_s`.
#[derive(Clone, Debug)]
pub struct SingerTrajectory {
    x0_m: f64,
    vx_mps: f64,
    height_m: f64,
    step_s: f64,
    duration_s: f64,
    /// `[y, ẏ, ÿ]` at t = k·step_s, k = 0..=ceil(duration/step).
    knots: Vec<Vector3<f64>>,
}

impl SingerTrajectory {
    /// Generates the y axis at `step_s` from `rng` (three standard normals a step).
    /// The arguments must have passed [`super::TrajectoryConfig::validate`].
    pub fn generate(
        initial_state: [f64; 5],
        alpha_per_s: f64,
        accel_var_m2ps4: f64,
        step_s: f64,
        duration_s: f64,
        height_m: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let [x0, vx, y0, vy0, ay0] = initial_state;
        let steps = ((duration_s / step_s) - 1e-9).ceil().max(1.0) as usize;
        let f = singer_transition(alpha_per_s, step_s);
        let sq = psd_sqrt(&singer_process_noise(alpha_per_s, accel_var_m2ps4, step_s));
        let mut knots = Vec::with_capacity(steps + 1);
        let mut s = Vector3::new(y0, vy0, ay0);
        knots.push(s);
        for _ in 0..steps {
            let n = Vector3::new(
                rng.sample(StandardNormal),
                rng.sample(StandardNormal),
                rng.sample(StandardNormal),
            );
            s = f * s + sq * n;
            knots.push(s);
        }
        Self {
            x0_m: x0,
            vx_mps: vx,
            height_m,
            step_s,
            duration_s,
            knots,
        }
    }

    /// The generated `[y, ẏ, ÿ]` samples, one per step from t = 0.
    pub fn knots(&self) -> &[Vector3<f64>] {
        &self.knots
    }
}

impl Trajectory for SingerTrajectory {
    fn state_at(&self, t_s: f64) -> TruthState {
        let t = clamp_time(t_s, self.duration_s);
        let k = ((t / self.step_s).floor() as usize).min(self.knots.len() - 2);
        let u = ((t - k as f64 * self.step_s) / self.step_s).clamp(0.0, 1.0);
        let y = quintic_hermite(&self.knots[k], &self.knots[k + 1], self.step_s, u);
        let vel = Vector3::new(self.vx_mps, y.y, 0.0);
        TruthState {
            t_s: t,
            pos_enu_m: Vector3::new(self.x0_m + self.vx_mps * t, y.x, self.height_m),
            vel_enu_mps: vel,
            acc_enu_mps2: Vector3::new(0.0, y.z, 0.0),
            heading_rad: heading_of(&vel).unwrap_or(0.0),
        }
    }
    fn duration_s(&self) -> f64 {
        self.duration_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;

    #[test]
    fn closed_form_matches_quadrature() {
        for &(alpha, t) in &[(0.1, 1.0), (0.1, 5.0), (0.5, 1.0), (2.0, 1.0), (0.2, 0.5)] {
            let a = singer_process_noise_closed_form(alpha, 3.5, t);
            let b = singer_process_noise_quadrature(alpha, 3.5, t, 64);
            for i in 0..3 {
                for j in 0..3 {
                    let rel = (a[(i, j)] - b[(i, j)]).abs() / b[(i, j)].abs();
                    assert!(
                        rel < 1e-9,
                        "α={alpha} T={t} ({i},{j}): {} vs {}",
                        a[(i, j)],
                        b[(i, j)]
                    );
                }
            }
        }
    }

    #[test]
    fn small_alpha_t_limit_is_the_white_jerk_model() {
        // As αT → 0 the Singer Q tends to 2ασ² times the integrated white-jerk matrix
        // [T⁵/20, T⁴/8, T³/6; T³/3, T²/2; T] (Bar-Shalom et al. 2001, eq. 6.2.3-8 form).
        let (alpha, var, t) = (1e-6, 3.5, 0.01);
        let q = singer_process_noise(alpha, var, t);
        let s = 2.0 * alpha * var;
        let expect = s * Matrix3::new(
            t.powi(5) / 20.0,
            t.powi(4) / 8.0,
            t.powi(3) / 6.0,
            t.powi(4) / 8.0,
            t.powi(3) / 3.0,
            t * t / 2.0,
            t.powi(3) / 6.0,
            t * t / 2.0,
            t,
        );
        for i in 0..3 {
            for j in 0..3 {
                let rel = (q[(i, j)] - expect[(i, j)]).abs() / expect[(i, j)];
                assert!(rel < 1e-6, "({i},{j}) {} vs {}", q[(i, j)], expect[(i, j)]);
            }
        }
        // The Q33 entry is exactly σ²(1 − e^{−2αT}) at every αT.
        for &(a, t) in &[(0.1, 1.0), (1e-3, 0.5), (3.0, 2.0)] {
            let q = singer_process_noise(a, 3.5, t);
            let exact = 3.5 * -(-2.0 * a * t).exp_m1();
            assert!(
                (q[(2, 2)] - exact).abs() < 1e-12 * exact.max(1e-300),
                "{} vs {exact}",
                q[(2, 2)]
            );
        }
    }

    #[test]
    fn transition_matches_paper_alpha() {
        // Hand values for α = 0.1, T = 1: e^{−0.1} = 0.904837418…
        let f = singer_transition(0.1, 1.0);
        let e = (-0.1f64).exp();
        assert!((f[(0, 2)] - (0.1 - 1.0 + e) / 0.01).abs() < 1e-12);
        assert!((f[(1, 2)] - (1.0 - e) / 0.1).abs() < 1e-12);
        assert!((f[(2, 2)] - 0.904_837_418_035_959_6).abs() < 1e-15);
        assert!((f[(0, 2)] - 0.483_741_803_596_0).abs() < 1e-10);
    }

    #[test]
    fn quintic_hits_both_ends_and_is_self_consistent() {
        let s0 = Vector3::new(1.0, -2.0, 0.5);
        let s1 = Vector3::new(3.0, 1.0, -1.5);
        let h = 0.7;
        assert!((quintic_hermite(&s0, &s1, h, 0.0) - s0).norm() < 1e-12);
        assert!((quintic_hermite(&s0, &s1, h, 1.0) - s1).norm() < 1e-12);
        // Velocity and acceleration are the derivatives of position.
        let du = 1e-6;
        for &u in &[0.2, 0.5, 0.9] {
            let a = quintic_hermite(&s0, &s1, h, u - du);
            let b = quintic_hermite(&s0, &s1, h, u + du);
            let m = quintic_hermite(&s0, &s1, h, u);
            assert!(((b.x - a.x) / (2.0 * du * h) - m.y).abs() < 1e-6);
            assert!(((b.y - a.y) / (2.0 * du * h) - m.z).abs() < 1e-6);
        }
    }

    #[test]
    fn noise_free_singer_is_deterministic_decay() {
        // With σ² = 0 the manoeuvre decays: ÿ(t) = ÿ₀ e^{−αt}.
        let mut rng = TrialRng::new(3, 0).stream("motion/singer");
        let tr = SingerTrajectory::generate(
            [0.0, 14.0, 0.0, 11.0, 2.0],
            0.1,
            0.0,
            1.0,
            50.0,
            0.0,
            &mut rng,
        );
        for k in [0usize, 1, 7, 50] {
            let s = tr.state_at(k as f64);
            assert!((s.acc_enu_mps2.y - 2.0 * (-0.1 * k as f64).exp()).abs() < 1e-12);
            assert!((s.pos_enu_m.x - 14.0 * k as f64).abs() < 1e-12);
        }
        // ẏ(t) = ẏ₀ + ÿ₀ (1 − e^{−αt})/α.
        let s = tr.state_at(10.0);
        assert!((s.vel_enu_mps.y - (11.0 + 2.0 * (1.0 - (-1.0f64).exp()) / 0.1)).abs() < 1e-10);
    }

    #[test]
    fn paper_run_is_reproducible_and_clamped() {
        let run = |seed| {
            let mut rng = TrialRng::new(seed, 0).stream("motion/trajectory");
            SingerTrajectory::generate(
                [4000.0, 14.0, 0.0, 11.0, 0.0],
                0.1,
                3.5,
                1.0,
                100.0,
                0.0,
                &mut rng,
            )
        };
        let a = run(1);
        let b = run(1);
        assert_eq!(a.knots(), b.knots());
        assert_ne!(a.knots(), run(2).knots());
        assert_eq!(a.knots().len(), 101);
        let s0 = a.state_at(-5.0);
        assert_eq!(s0.pos_enu_m, Vector3::new(4000.0, 0.0, 0.0));
        assert_eq!(s0.vel_enu_mps, Vector3::new(14.0, 11.0, 0.0));
        assert_eq!(a.state_at(1e9).t_s, 100.0);
        assert!((a.state_at(100.0).pos_enu_m.x - 5400.0).abs() < 1e-9);
    }
}
