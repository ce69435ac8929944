//! Seed 003's target: the three-dimensional plane variable-speed turning model (PVSTM).
//!
//! # What the paper gives
//!
//! Seed 003 (GPS + BeiDou + DTMB seamless positioning, Sensors and Materials 30(11), 2018,
//! §3.1) states only the model's name and its parameters: "the target is set to move in
//! accordance with the plane variable speed turning model (PVSTM) … the attenuation
//! coefficient of 0.03, the angular velocity of 0.1, the initial position … (0, 0, 0) m,
//! the velocity component … in the X-, Y-, and Z-directions of (4, −4, 4) m/s, and the
//! acceleration component of (0.5, −0.5, −0.5) m/s². Process noise obeys a Gaussian
//! distribution with zero mean, the noise variance is set to 0.01 m/s² … 100 s and the
//! observation time interval is 1 s." Its numbered equations (1)–(13) are the pseudorange
//! model, the EKF and the particle filter; none defines the motion model. The state
//! transition below is therefore the standard variable-speed turning model of the Chinese
//! tracking literature that the paper's parameter names refer to, and the choices this
//! module makes where the paper is silent are listed under *Assumptions*.
//!
//! # The model
//!
//! The state is position p, velocity v and acceleration a, each in x (east), y (north),
//! z (up), nine components in all. The acceleration is a Singer-like manoeuvre whose
//! horizontal part also turns: it decays with the attenuation coefficient α and rotates
//! at the angular velocity ω, so the speed varies while the path curves:
//!
//! ```text
//! ṗ = v,   v̇ = a,   ȧ = M a,      ┌ −α  −ω   0 ┐
//!                                 M = │  ω  −α   0 │
//!                                     └  0   0  −α ┘
//! ```
//!
//! Writing the horizontal acceleration as the complex number a_h = a_x + i a_y, the
//! horizontal block is `ȧ_h = λ a_h` with λ = −α + iω, and the vertical one is `ȧ_z = −α a_z`.
//! Over an interval τ the exact solution, with φ₁(z) = (eᶻ − 1)/z and
//! φ₂(z) = (eᶻ − 1 − z)/z², is, per block (λ_z = −α for z):
//!
//! ```text
//! a(τ) = e^{λτ} a(0)
//! v(τ) = v(0) + τ φ₁(λτ) a(0)
//! p(τ) = p(0) + τ v(0) + τ² φ₂(λτ) a(0)
//! ```
//!
//! which is the transition matrix Φ(τ) = exp(A τ) of [`transition_matrix`]. The discrete
//! model generated at the step T is
//!
//! ```text
//! X(k+1) = Φ(T) X(k) + Γ W(k),   Γ = [0₃ 0₃ I₃]ᵀ,   W(k) ~ N(0, σ_w² I₃),
//! ```
//!
//! with σ_w² = `noise_var_m2ps4` (0.01 in the paper): the process noise perturbs the
//! acceleration by a Gaussian amount at each step instant (after t = 0, so the configured
//! initial state is the state at t = 0). Between steps the state follows the noise-free
//! dynamics exactly, so position and velocity are continuous and the acceleration is the
//! derivative of velocity everywhere except at the step instants, where it jumps by W(k).
//!
//! # Assumptions where the paper is silent
//!
//! * The turn is in the horizontal (x–y) plane, counter-clockwise seen from above for
//!   ω > 0; z has the attenuation but no rotation. The paper's "plane" turning model with
//!   one angular velocity fits this reading; its three-dimensional initial velocity and
//!   acceleration are then used unchanged.
//! * The paper's "noise variance 0.01 m/s²" is read as the variance (m/s²)² of a discrete
//!   acceleration perturbation per step and per axis, the noise entering through Γ above.
//! * ω and α are taken in rad/s and 1/s (the paper gives no units).

use super::{clamp_time, heading_of, Trajectory, TruthState};
use nalgebra::{Complex, SMatrix, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// The parameters of a plane variable-speed turning run.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneTurningParams {
    pub initial_position_m: Vector3<f64>,
    pub initial_velocity_mps: Vector3<f64>,
    pub initial_accel_mps2: Vector3<f64>,
    /// α (1/s).
    pub attenuation_per_s: f64,
    /// ω (rad/s).
    pub turn_rate_rad_per_s: f64,
    /// σ_w² ((m/s²)²).
    pub noise_var_m2ps4: f64,
    pub step_s: f64,
    pub duration_s: f64,
}

/// φ₁(z) = (eᶻ − 1)/z and φ₂(z) = (eᶻ − 1 − z)/z², by their power series near 0 (where the
/// direct forms cancel) and directly elsewhere.
fn phi12(z: Complex<f64>) -> (Complex<f64>, Complex<f64>) {
    if z.norm() < 0.1 {
        // φ₁ = Σ zᵏ/(k+1)!, φ₂ = Σ zᵏ/(k+2)!; twelve terms leave < 1e-20 at |z| < 0.1.
        let mut p1 = Complex::new(0.0, 0.0);
        let mut p2 = Complex::new(0.0, 0.0);
        let mut zk = Complex::new(1.0, 0.0);
        let mut fact1 = 1.0; // (k+1)!
        let mut fact2 = 2.0; // (k+2)!
        for k in 0..12 {
            p1 += zk / fact1;
            p2 += zk / fact2;
            zk *= z;
            fact1 *= (k + 2) as f64;
            fact2 *= (k + 3) as f64;
        }
        (p1, p2)
    } else {
        let em1 = z.exp() - 1.0;
        (em1 / z, (em1 - z) / (z * z))
    }
}

/// The three complex coefficients (e^{λτ}, τφ₁(λτ), τ²φ₂(λτ)) that carry a(0) into a, v and
/// p after τ.
fn coefficients(lambda: Complex<f64>, tau: f64) -> [Complex<f64>; 3] {
    let z = lambda * tau;
    let (p1, p2) = phi12(z);
    [z.exp(), p1 * tau, p2 * (tau * tau)]
}

/// The noise-free state after `tau` seconds from (p, v, a).
pub fn propagate(
    alpha: f64,
    omega: f64,
    p: &Vector3<f64>,
    v: &Vector3<f64>,
    a: &Vector3<f64>,
    tau: f64,
) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let [eh, c1h, c2h] = coefficients(Complex::new(-alpha, omega), tau);
    let [ez, c1z, c2z] = coefficients(Complex::new(-alpha, 0.0), tau);
    let ah = Complex::new(a.x, a.y);
    let a_new = eh * ah;
    let dv = c1h * ah;
    let dp = c2h * ah;
    (
        Vector3::new(
            p.x + tau * v.x + dp.re,
            p.y + tau * v.y + dp.im,
            p.z + tau * v.z + c2z.re * a.z,
        ),
        Vector3::new(v.x + dv.re, v.y + dv.im, v.z + c1z.re * a.z),
        Vector3::new(a_new.re, a_new.im, ez.re * a.z),
    )
}

/// The 9×9 transition matrix Φ(τ) = exp(Aτ) for the state ordered
/// `[x, y, z, ẋ, ẏ, ż, ẍ, ÿ, z̈]`, for filters that use this model.
pub fn transition_matrix(alpha: f64, omega: f64, tau: f64) -> SMatrix<f64, 9, 9> {
    // Multiplying (a_x + i a_y) by c = c_r + i c_i is the real matrix [c_r −c_i; c_i c_r].
    let [eh, c1h, c2h] = coefficients(Complex::new(-alpha, omega), tau);
    let [ez, c1z, c2z] = coefficients(Complex::new(-alpha, 0.0), tau);
    let mut f = SMatrix::<f64, 9, 9>::identity();
    let mut put = |row: usize, col: usize, c: Complex<f64>, cz: Complex<f64>| {
        f[(row, col)] = c.re;
        f[(row, col + 1)] = -c.im;
        f[(row + 1, col)] = c.im;
        f[(row + 1, col + 1)] = c.re;
        f[(row + 2, col + 2)] = cz.re;
    };
    put(0, 6, c2h, c2z);
    put(3, 6, c1h, c1z);
    put(6, 6, eh, ez);
    for i in 0..3 {
        f[(i, i + 3)] = tau;
    }
    f
}

/// A generated plane-turning trajectory: the state just after each step instant.
#[derive(Clone, Debug)]
pub struct PlaneTurningTrajectory {
    alpha: f64,
    omega: f64,
    step_s: f64,
    duration_s: f64,
    /// (p, v, a) at t = k·step_s, the acceleration including that instant's noise.
    knots: Vec<[Vector3<f64>; 3]>,
}

impl PlaneTurningTrajectory {
    /// Generates the run from `rng` (three standard normals a step, drawn even when the
    /// noise variance is zero so that the stream's use does not depend on it). The
    /// parameters must have passed [`super::TrajectoryConfig::validate`].
    pub fn generate(p: &PlaneTurningParams, rng: &mut impl Rng) -> Self {
        let steps = ((p.duration_s / p.step_s) - 1e-9).ceil().max(1.0) as usize;
        let sigma = p.noise_var_m2ps4.max(0.0).sqrt();
        let mut knots = Vec::with_capacity(steps + 1);
        let mut s = [
            p.initial_position_m,
            p.initial_velocity_mps,
            p.initial_accel_mps2,
        ];
        knots.push(s);
        for _ in 0..steps {
            let (pos, vel, acc) = propagate(
                p.attenuation_per_s,
                p.turn_rate_rad_per_s,
                &s[0],
                &s[1],
                &s[2],
                p.step_s,
            );
            let w = Vector3::new(
                rng.sample::<f64, _>(StandardNormal),
                rng.sample(StandardNormal),
                rng.sample(StandardNormal),
            );
            s = [pos, vel, acc + sigma * w];
            knots.push(s);
        }
        Self {
            alpha: p.attenuation_per_s,
            omega: p.turn_rate_rad_per_s,
            step_s: p.step_s,
            duration_s: p.duration_s,
            knots,
        }
    }

    /// The states (p, v, a) just after each step instant, from t = 0.
    pub fn knots(&self) -> &[[Vector3<f64>; 3]] {
        &self.knots
    }
}

impl Trajectory for PlaneTurningTrajectory {
    fn state_at(&self, t_s: f64) -> TruthState {
        let t = clamp_time(t_s, self.duration_s);
        let k = ((t / self.step_s).floor() as usize).min(self.knots.len() - 2);
        let tau = (t - k as f64 * self.step_s).clamp(0.0, self.step_s);
        let [p, v, a] = &self.knots[k];
        let (pos, vel, acc) = propagate(self.alpha, self.omega, p, v, a, tau);
        TruthState {
            t_s: t,
            pos_enu_m: pos,
            vel_enu_mps: vel,
            acc_enu_mps2: acc,
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

    fn paper(noise: f64) -> PlaneTurningParams {
        PlaneTurningParams {
            initial_position_m: Vector3::zeros(),
            initial_velocity_mps: Vector3::new(4.0, -4.0, 4.0),
            initial_accel_mps2: Vector3::new(0.5, -0.5, -0.5),
            attenuation_per_s: 0.03,
            turn_rate_rad_per_s: 0.1,
            noise_var_m2ps4: noise,
            step_s: 1.0,
            duration_s: 100.0,
        }
    }

    fn continuous_a(alpha: f64, omega: f64) -> SMatrix<f64, 9, 9> {
        let mut a = SMatrix::<f64, 9, 9>::zeros();
        for i in 0..3 {
            a[(i, i + 3)] = 1.0;
            a[(i + 3, i + 6)] = 1.0;
            a[(i + 6, i + 6)] = -alpha;
        }
        a[(6, 7)] = -omega;
        a[(7, 6)] = omega;
        a
    }

    #[test]
    fn transition_is_the_matrix_exponential() {
        for &(al, om, tau) in &[
            (0.03, 0.1, 1.0),
            (0.03, 0.1, 0.37),
            (0.0, 0.0, 2.0),
            (0.5, -0.8, 3.0),
            (1e-9, 1e-9, 1.0),
        ] {
            let f = transition_matrix(al, om, tau);
            let e = (continuous_a(al, om) * tau).exp();
            assert!(
                (f - e).abs().max() < 1e-12,
                "α={al} ω={om} τ={tau}: {}",
                (f - e).abs().max()
            );
        }
    }

    #[test]
    fn noise_free_run_equals_closed_form_and_hand_iteration() {
        let mut rng = TrialRng::new(1, 0).stream("motion/trajectory");
        let tr = PlaneTurningTrajectory::generate(&paper(0.0), &mut rng);
        let x0 = SMatrix::<f64, 9, 1>::from_column_slice(&[
            0.0, 0.0, 0.0, 4.0, -4.0, 4.0, 0.5, -0.5, -0.5,
        ]);
        // Hand-iterated first steps: X(k+1) = Φ(1) X(k).
        let phi = transition_matrix(0.03, 0.1, 1.0);
        let mut x = x0;
        for k in 0..=5 {
            let s = tr.state_at(k as f64);
            let got = SMatrix::<f64, 9, 1>::from_column_slice(&[
                s.pos_enu_m.x,
                s.pos_enu_m.y,
                s.pos_enu_m.z,
                s.vel_enu_mps.x,
                s.vel_enu_mps.y,
                s.vel_enu_mps.z,
                s.acc_enu_mps2.x,
                s.acc_enu_mps2.y,
                s.acc_enu_mps2.z,
            ]);
            assert!((got - x).abs().max() < 1e-10, "step {k}");
            x = phi * x;
        }
        // Closed form at an arbitrary time: Φ(t) X(0).
        let s = tr.state_at(37.25);
        let want = transition_matrix(0.03, 0.1, 37.25) * x0;
        assert!((s.pos_enu_m - Vector3::new(want[0], want[1], want[2])).norm() < 1e-8);
        // Hand values of the first step: a(1) = e^{−0.03}·R(0.1)·a(0) for the horizontal pair.
        let s1 = tr.state_at(1.0);
        let e = (-0.03f64).exp();
        let (sn, cs) = 0.1f64.sin_cos();
        assert!((s1.acc_enu_mps2.x - e * (0.5 * cs + 0.5 * sn)).abs() < 1e-14);
        assert!((s1.acc_enu_mps2.y - e * (0.5 * sn - 0.5 * cs)).abs() < 1e-14);
        assert!((s1.acc_enu_mps2.z + 0.5 * e).abs() < 1e-14);
        // ż(1) = 4 − 0.5 (1 − e^{−0.03})/0.03.
        assert!((s1.vel_enu_mps.z - (4.0 - 0.5 * (1.0 - e) / 0.03)).abs() < 1e-13);
    }

    #[test]
    fn noise_enters_the_acceleration_only_at_steps() {
        let mut rng = TrialRng::new(9, 0).stream("motion/trajectory");
        let tr = PlaneTurningTrajectory::generate(&paper(0.01), &mut rng);
        let k = tr.knots();
        assert_eq!(k.len(), 101);
        assert_eq!(
            k[0],
            [
                Vector3::zeros(),
                Vector3::new(4.0, -4.0, 4.0),
                Vector3::new(0.5, -0.5, -0.5)
            ]
        );
        let mut w2 = 0.0;
        for i in 0..100 {
            let (p, v, a) = propagate(0.03, 0.1, &k[i][0], &k[i][1], &k[i][2], 1.0);
            assert!((p - k[i + 1][0]).norm() < 1e-9 && (v - k[i + 1][1]).norm() < 1e-9);
            w2 += (a - k[i + 1][2]).norm_squared();
        }
        // 300 draws of variance 0.01: the mean square is 0.01 within a few 10 %.
        let ms = w2 / 300.0;
        assert!((0.007..0.013).contains(&ms), "{ms}");
        // Velocity is the derivative of position between steps.
        let h = 1e-5;
        let t = 12.4;
        let d = (tr.state_at(t + h).pos_enu_m - tr.state_at(t - h).pos_enu_m) / (2.0 * h);
        assert!((d - tr.state_at(t).vel_enu_mps).norm() < 1e-7);
        let d = (tr.state_at(t + h).vel_enu_mps - tr.state_at(t - h).vel_enu_mps) / (2.0 * h);
        assert!((d - tr.state_at(t).acc_enu_mps2).norm() < 1e-7);
    }
}
