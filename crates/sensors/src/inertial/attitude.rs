//! Truth with attitude: a [`Trajectory`] (the path) dressed with a body attitude and, for a
//! walker, a gait, so that an IMU sampled along it measures what a real one would.
//!
//! # Platforms
//!
//! * `car`: body forward along the velocity: heading ψ from the path, pitch
//!   θ = atan2(v_up, |v_horizontal|) on slopes (0 at rest), no roll.
//! * `pedestrian`: a body-worn (waist) IMU, level, heading along the path, plus the gait.
//! * `handheld`: a phone held in front, pointing along the walk, screen up and tilted nose up
//!   by `phone_pitch_deg`, bobbing in pitch at the step frequency (`phone_bob_deg`) and
//!   swaying in roll at half of it (`phone_sway_deg`, one sway per stride of two steps),
//!   plus the gait.
//!
//! # Gait overlay
//!
//! The walker's centre of mass oscillates about the path. With step phase φ(t) and a
//! walking-activity factor α ∈ [0, 1] (a smoothstep of the path speed between
//! `min_walk_speed_mps` and twice that, so a standing walker takes no steps), the overlay is
//!
//! ```text
//! Δr_up(t)      = −α A(t) (B/ω₀²) (cos φ + (h₂/4) cos 2φ)     (vertical bounce)
//! Δr_forward(t) =  α A(t) (S/ω₀²) sin φ                        (forward surge)
//! ```
//!
//! with ω₀ = 2π f_step, B = `bounce_accel_mps2`, S = `surge_accel_mps2`, h₂ =
//! `heel_strike_harmonic`, so the vertical acceleration is ≈ α A B (cos φ + h₂ cos 2φ): a
//! peak at every φ = 2πk (heel strike), the instant counted as the true step. The phase
//! φ(t) = ω₀ t + π + Σᵢ cᵢ (sin(νᵢ t + θᵢ) − sin θᵢ) has a slowly wandering cadence
//! (relative spread `cadence_jitter`), and A(t) = 1 + Σᵢ aᵢ sin(μᵢ t + ϑᵢ) a wandering
//! step intensity (`amplitude_jitter`); the νᵢ, μᵢ, θᵢ, ϑᵢ are drawn once from the
//! trajectory's random stream. Because φ is an explicit monotone function of time the true
//! step times are known exactly ([`PlatformTruth::true_step_times_s`]).
//!
//! The default B = 4 m/s² at 1.8 Hz with K = 0.364 makes Weinberg's L = K (a_max − a_min)^¼
//! give ≈ 0.61 m, the stride of a 1.1 m/s walk at 1.8 steps/s (Weinberg 2002, AN-602).
//!
//! Velocity and acceleration of the overlay are its derivatives, taken with five-point
//! central differences (h = 1 ms; truncation error below 1e-6 m/s² for the default gait),
//! so position, velocity and acceleration are consistent and an ideal IMU integrates back
//! to the truth. The angular rate ω_nb^b is the central difference of the attitude
//! quaternion over ±1 ms. At an instantaneous corner of a waypoint path (no
//! `lateral_accel_mps2`) the truth itself jumps, and so do these derivatives: give corner
//! arcs for IMU work.

use super::{heading_of_attitude, LocalEarth};
use crate::core::ConfigIssue;
use crate::motion::{Trajectory, TruthState};
use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// How the IMU is carried.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Platform {
    /// A car: heading along the path, pitch on slopes.
    #[default]
    Car,
    /// A body-worn IMU on a walker.
    Pedestrian,
    /// A phone held in front of a walker.
    Handheld,
}

fn d_step_hz() -> f64 {
    1.8
}
fn d_bounce() -> f64 {
    4.0
}
fn d_surge() -> f64 {
    1.5
}
fn d_h2() -> f64 {
    0.25
}
fn d_cadence_jitter() -> f64 {
    0.05
}
fn d_amp_jitter() -> f64 {
    0.1
}
fn d_min_walk() -> f64 {
    0.2
}
fn d_phone_pitch() -> f64 {
    30.0
}
fn d_phone_bob() -> f64 {
    2.0
}
fn d_phone_sway() -> f64 {
    3.0
}

/// The walker's gait (ignored for a car). Every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GaitConfig {
    /// Mean step frequency f_step (Hz); default 1.8.
    #[serde(default = "d_step_hz")]
    pub step_frequency_hz: f64,
    /// Vertical acceleration amplitude B of the step fundamental (m/s²); default 4.
    #[serde(default = "d_bounce")]
    pub bounce_accel_mps2: f64,
    /// Forward surge acceleration amplitude S (m/s²); default 1.5.
    #[serde(default = "d_surge")]
    pub surge_accel_mps2: f64,
    /// Second-harmonic ratio h₂ of the vertical acceleration (heel strike); default 0.25.
    #[serde(default = "d_h2")]
    pub heel_strike_harmonic: f64,
    /// Relative peak deviation of the cadence, in [0, 0.5]; default 0.05.
    #[serde(default = "d_cadence_jitter")]
    pub cadence_jitter: f64,
    /// Relative peak deviation of the step intensity, in [0, 0.5]; default 0.1.
    #[serde(default = "d_amp_jitter")]
    pub amplitude_jitter: f64,
    /// Below this path speed the walker stands still (m/s); default 0.2.
    #[serde(default = "d_min_walk")]
    pub min_walk_speed_mps: f64,
    /// Handheld phone: nose-up tilt (°); default 30.
    #[serde(default = "d_phone_pitch")]
    pub phone_pitch_deg: f64,
    /// Handheld phone: pitch bob amplitude at the step frequency (°); default 2.
    #[serde(default = "d_phone_bob")]
    pub phone_bob_deg: f64,
    /// Handheld phone: roll sway amplitude at half the step frequency (°); default 3.
    #[serde(default = "d_phone_sway")]
    pub phone_sway_deg: f64,
}

impl Default for GaitConfig {
    fn default() -> Self {
        Self {
            step_frequency_hz: d_step_hz(),
            bounce_accel_mps2: d_bounce(),
            surge_accel_mps2: d_surge(),
            heel_strike_harmonic: d_h2(),
            cadence_jitter: d_cadence_jitter(),
            amplitude_jitter: d_amp_jitter(),
            min_walk_speed_mps: d_min_walk(),
            phone_pitch_deg: d_phone_pitch(),
            phone_bob_deg: d_phone_bob(),
            phone_sway_deg: d_phone_sway(),
        }
    }
}

/// The platform: how the IMU is carried, and the gait of a walker.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlatformConfig {
    /// `car`, `pedestrian` or `handheld`; default `car`.
    #[serde(default)]
    pub platform: Platform,
    /// The gait (walkers only).
    #[serde(default)]
    pub gait: GaitConfig,
}

fn range(key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<(), ConfigIssue> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(ConfigIssue::new(
            key,
            format!("expected {what} within [{lo}, {hi}], got {v}"),
        ))
    }
}

impl PlatformConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the gait field that is out of range.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let g = &self.gait;
        range(
            "step_frequency_hz",
            g.step_frequency_hz,
            0.2,
            5.0,
            "a step frequency in Hz",
        )?;
        range(
            "bounce_accel_mps2",
            g.bounce_accel_mps2,
            0.0,
            50.0,
            "an acceleration in m/s²",
        )?;
        range(
            "surge_accel_mps2",
            g.surge_accel_mps2,
            0.0,
            50.0,
            "an acceleration in m/s²",
        )?;
        range(
            "heel_strike_harmonic",
            g.heel_strike_harmonic,
            0.0,
            1.0,
            "a harmonic ratio",
        )?;
        range(
            "cadence_jitter",
            g.cadence_jitter,
            0.0,
            0.5,
            "a relative cadence deviation",
        )?;
        range(
            "amplitude_jitter",
            g.amplitude_jitter,
            0.0,
            0.5,
            "a relative intensity deviation",
        )?;
        range(
            "min_walk_speed_mps",
            g.min_walk_speed_mps,
            0.01,
            5.0,
            "a speed in m/s",
        )?;
        range(
            "phone_pitch_deg",
            g.phone_pitch_deg,
            -89.0,
            89.0,
            "a pitch in degrees",
        )?;
        range(
            "phone_bob_deg",
            g.phone_bob_deg,
            0.0,
            30.0,
            "an angle in degrees",
        )?;
        range(
            "phone_sway_deg",
            g.phone_sway_deg,
            0.0,
            30.0,
            "an angle in degrees",
        )
    }
}

/// The true state of the body at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyTruth {
    /// Seconds since the trial start.
    pub t_s: f64,
    /// Position, path plus gait overlay (ENU m).
    pub pos_enu_m: Vector3<f64>,
    /// Velocity (ENU m/s).
    pub vel_enu_mps: Vector3<f64>,
    /// Acceleration d²r/dt² (ENU m/s²).
    pub acc_enu_mps2: Vector3<f64>,
    /// Attitude: rotates body (FLU) vectors into ENU.
    pub q_nb: UnitQuaternion<f64>,
    /// Angular rate of the body relative to the ENU frame, in body axes (rad/s).
    pub omega_nb_b_rps: Vector3<f64>,
    /// Heading of the body forward axis from north, clockwise, in [0, 2π) (rad).
    pub heading_rad: f64,
}

/// Ideal IMU outputs for a truth state (Groves eqs. 5.39 and 5.28 in a local tangent
/// plane): ω_ib^b = ω_nb^b + C_n^b ω_ie^n and f^b = C_n^b (a^n − g^n + 2 ω_ie^n × v^n).
/// Returns (angular rate rad/s, specific force m/s²).
pub fn ideal_imu(truth: &BodyTruth, earth: &LocalEarth) -> (Vector3<f64>, Vector3<f64>) {
    let q_bn = truth.q_nb.inverse();
    let omega = truth.omega_nb_b_rps + q_bn * earth.omega_ie_enu_rps;
    let f_n = truth.acc_enu_mps2 - earth.gravity_enu_mps2(truth.pos_enu_m.z)
        + 2.0 * earth.omega_ie_enu_rps.cross(&truth.vel_enu_mps);
    (omega, q_bn * f_n)
}

/// Attitude of FLU body axes with heading ψ (from north, clockwise), pitch θ (nose up) and
/// roll φ (right side down): C_b^n = R_z(π/2 − ψ) R_y(−θ) R_x(φ).
pub fn attitude_from_euler(heading_rad: f64, pitch_rad: f64, roll_rad: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll_rad, -pitch_rad, FRAC_PI_2 - heading_rad)
}

/// The heading ψ ∈ [0, 2π), pitch θ and roll φ of an attitude (rad), the inverse of
/// [`attitude_from_euler`] for |θ| < π/2.
pub fn euler_from_attitude(q_nb: &UnitQuaternion<f64>) -> (f64, f64, f64) {
    let (roll, minus_pitch, yaw) = q_nb.euler_angles();
    ((FRAC_PI_2 - yaw).rem_euclid(TAU), -minus_pitch, roll)
}

/// The pitch of a car: the slope of its direction of travel. The direction is the
/// velocity, or at (almost) rest the acceleration (a car starting or stopping on a slope
/// accelerates along it), signed so that its horizontal part points along the heading. A car
/// at rest with no acceleration (a dwell) is level: give flat dwells for IMU work, since the
/// attitude would jump when it moves off a slope.
fn car_pitch_rad(base: &TruthState) -> f64 {
    let d = if base.vel_enu_mps.norm() > 1e-3 {
        base.vel_enu_mps
    } else {
        base.acc_enu_mps2
    };
    let dh = d.x.hypot(d.y);
    if d.norm() <= 1e-9 || dh <= 1e-12 {
        return 0.0;
    }
    let (s, c) = base.heading_rad.sin_cos();
    let along = d.x * s + d.y * c;
    (d.z * along.signum()).atan2(dh)
}

/// A trajectory with attitude and gait: the truth an IMU is sampled along.
pub struct PlatformTruth {
    trajectory: Box<dyn Trajectory>,
    platform: Platform,
    gait: GaitConfig,
    omega0_rps: f64,
    /// Cadence wander terms (cᵢ rad, νᵢ rad/s, θᵢ rad).
    cadence: [(f64, f64, f64); 2],
    /// Intensity wander terms (aᵢ, μᵢ rad/s, ϑᵢ rad).
    intensity: [(f64, f64, f64); 2],
}

const STENCIL_H_S: f64 = 1e-3;

impl PlatformTruth {
    /// The body every inertial sensor of a trial carries: `trajectory` dressed as `cfg`
    /// says with the trial's gait stream ([`super::source::GAIT_STREAM`]), so the IMU, the
    /// PDR phone and an export of the trial all see one attitude.
    ///
    /// # Errors
    /// As [`PlatformTruth::new`].
    pub fn of_trial(
        trajectory: Box<dyn Trajectory>,
        cfg: &PlatformConfig,
        rng: &crate::core::TrialRng,
    ) -> Result<Self, ConfigIssue> {
        Self::new(trajectory, cfg, &mut rng.stream(super::source::GAIT_STREAM))
    }

    /// Dresses `trajectory` as `cfg` says, drawing the gait's slow wander from `rng`.
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`PlatformConfig::validate`].
    pub fn new(
        trajectory: Box<dyn Trajectory>,
        cfg: &PlatformConfig,
        rng: &mut impl Rng,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let g = &cfg.gait;
        let omega0_rps = TAU * g.step_frequency_hz;
        let mut cadence = [(0.0, 0.0, 0.0); 2];
        for c in &mut cadence {
            // Each term moves the instantaneous cadence by up to half the jitter, over
            // periods of 10–60 s.
            let nu = TAU / (10.0 + 50.0 * rng.random::<f64>());
            let c_rad = 0.5 * g.cadence_jitter * omega0_rps / nu;
            *c = (c_rad, nu, TAU * rng.random::<f64>());
        }
        let mut intensity = [(0.0, 0.0, 0.0); 2];
        for a in &mut intensity {
            let mu = TAU / (5.0 + 25.0 * rng.random::<f64>());
            *a = (0.5 * g.amplitude_jitter, mu, TAU * rng.random::<f64>());
        }
        Ok(Self {
            trajectory,
            platform: cfg.platform,
            gait: g.clone(),
            omega0_rps,
            cadence,
            intensity,
        })
    }

    /// The underlying path.
    pub fn trajectory(&self) -> &dyn Trajectory {
        self.trajectory.as_ref()
    }

    /// The length of the truth (s).
    pub fn duration_s(&self) -> f64 {
        self.trajectory.duration_s()
    }

    /// The step phase φ(t) (rad); a step falls at every multiple of 2π.
    pub fn step_phase_rad(&self, t_s: f64) -> f64 {
        let mut phi = self.omega0_rps * t_s + PI;
        for &(c, nu, th) in &self.cadence {
            phi += c * ((nu * t_s + th).sin() - th.sin());
        }
        phi
    }

    fn intensity(&self, t_s: f64) -> f64 {
        let mut a = 1.0;
        for &(amp, mu, th) in &self.intensity {
            a += amp * (mu * t_s + th).sin();
        }
        a
    }

    fn activity(&self, base: &TruthState) -> f64 {
        let v = base.vel_enu_mps.x.hypot(base.vel_enu_mps.y);
        let v0 = self.gait.min_walk_speed_mps;
        let x = ((v - v0) / v0).clamp(0.0, 1.0);
        x * x * (3.0 - 2.0 * x)
    }

    fn walking(&self) -> bool {
        self.platform != Platform::Car
    }

    /// The gait displacement at `t_s` (ENU m); zero for a car.
    fn overlay(&self, t_s: f64) -> Vector3<f64> {
        if !self.walking() {
            return Vector3::zeros();
        }
        let base = self.trajectory.state_at(t_s);
        let alpha = self.activity(&base);
        if alpha == 0.0 {
            return Vector3::zeros();
        }
        let g = &self.gait;
        let phi = self.step_phase_rad(t_s);
        let a = alpha * self.intensity(t_s) / (self.omega0_rps * self.omega0_rps);
        let up = -a
            * g.bounce_accel_mps2
            * (phi.cos() + 0.25 * g.heel_strike_harmonic * (2.0 * phi).cos());
        let fwd = a * g.surge_accel_mps2 * phi.sin();
        let (s, c) = base.heading_rad.sin_cos();
        Vector3::new(fwd * s, fwd * c, up)
    }

    fn attitude(&self, t_s: f64) -> UnitQuaternion<f64> {
        let base = self.trajectory.state_at(t_s);
        match self.platform {
            Platform::Car => attitude_from_euler(base.heading_rad, car_pitch_rad(&base), 0.0),
            Platform::Pedestrian => attitude_from_euler(base.heading_rad, 0.0, 0.0),
            Platform::Handheld => {
                let g = &self.gait;
                let alpha = self.activity(&base);
                let phi = self.step_phase_rad(t_s);
                let pitch = (g.phone_pitch_deg + alpha * g.phone_bob_deg * phi.sin()).to_radians();
                let roll = (alpha * g.phone_sway_deg * (0.5 * phi).sin()).to_radians();
                attitude_from_euler(base.heading_rad, pitch, roll)
            }
        }
    }

    /// The body attitude alone at `t_s` (cheaper than [`PlatformTruth::sample`]).
    pub fn attitude_at(&self, t_s: f64) -> UnitQuaternion<f64> {
        self.attitude(t_s)
    }

    /// The full truth at `t_s` (clamped to the trajectory's span like the trajectory).
    pub fn sample(&self, t_s: f64) -> BodyTruth {
        let base = self.trajectory.state_at(t_s);
        let t = base.t_s;
        let (mut pos, mut vel, mut acc) = (base.pos_enu_m, base.vel_enu_mps, base.acc_enu_mps2);
        if self.walking() {
            let h = STENCIL_H_S;
            let o = [
                self.overlay(t - 2.0 * h),
                self.overlay(t - h),
                self.overlay(t),
                self.overlay(t + h),
                self.overlay(t + 2.0 * h),
            ];
            pos += o[2];
            // Five-point central differences: O(h⁴) truncation.
            vel += (o[0] - 8.0 * o[1] + 8.0 * o[3] - o[4]) / (12.0 * h);
            acc += (-o[0] + 16.0 * o[1] - 30.0 * o[2] + 16.0 * o[3] - o[4]) / (12.0 * h * h);
        }
        let q_nb = self.attitude(t);
        let h = STENCIL_H_S;
        let dq = self.attitude(t - h).inverse() * self.attitude(t + h);
        let omega_nb_b_rps = dq.scaled_axis() / (2.0 * h);
        BodyTruth {
            t_s: t,
            pos_enu_m: pos,
            vel_enu_mps: vel,
            acc_enu_mps2: acc,
            q_nb,
            omega_nb_b_rps,
            heading_rad: heading_of_attitude(&q_nb),
        }
    }

    /// Every true step (heel strike, φ = 2πk while walking, α ≥ ½) in the truth's span (s).
    /// Empty for a car. Allocates; meant for validation, not hot loops.
    pub fn true_step_times_s(&self) -> Vec<f64> {
        let mut out = Vec::new();
        if !self.walking() {
            return out;
        }
        let dur = self.duration_s();
        let wander: f64 = self.cadence.iter().map(|c| 2.0 * c.0.abs()).sum();
        let mut k = 1.0f64;
        loop {
            let target = TAU * k;
            let mut lo = ((target - PI - wander) / self.omega0_rps).max(0.0);
            let mut hi = (target - PI + wander) / self.omega0_rps;
            if lo > dur {
                break;
            }
            // φ is strictly increasing (cadence jitter ≤ 0.5), so bisection finds the crossing.
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if self.step_phase_rad(mid) < target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let t = 0.5 * (lo + hi);
            if t <= dur && t > 0.0 && self.activity(&self.trajectory.state_at(t)) >= 0.5 {
                out.push(t);
            }
            k += 1.0;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_come_back_from_the_attitude() {
        for (h, p, r) in [
            (0.0, 0.0, 0.0),
            (1.0, 0.2, -0.3),
            (5.9, -1.2, 2.9),
            (3.2, 0.7, 0.01),
        ] {
            let (h2, p2, r2) = euler_from_attitude(&attitude_from_euler(h, p, r));
            assert!((h2 - h).abs() < 1e-12 && (p2 - p).abs() < 1e-12 && (r2 - r).abs() < 1e-12);
        }
        // Heading 90° (east): the body's forward axis points east.
        let fwd = attitude_from_euler(FRAC_PI_2, 0.0, 0.0) * Vector3::x();
        assert!((fwd - Vector3::x()).norm() < 1e-12, "{fwd}");
    }
    use crate::core::TrialRng;
    use crate::motion::TrajectoryConfig;

    fn walk(platform: Platform) -> PlatformTruth {
        let traj = TrajectoryConfig::Waypoints {
            points_enu_m: vec![vec![0.0, 0.0], vec![30.0, 0.0], vec![30.0, 20.0]],
            speed_mps: 1.1,
            accel_mps2: Some(0.5),
            lateral_accel_mps2: Some(0.5),
            dwell_s: None,
            leg_speeds_mps: None,
            stops: None,
            laps: None,
            height_m: None,
        }
        .build(&mut TrialRng::new(1, 0).stream("motion/trajectory"))
        .unwrap();
        let cfg = PlatformConfig {
            platform,
            gait: GaitConfig::default(),
        };
        PlatformTruth::new(traj, &cfg, &mut TrialRng::new(1, 0).stream("inertial/gait")).unwrap()
    }

    #[test]
    fn derivatives_are_consistent() {
        // Integrating the reported velocity and acceleration with the trapezoid rule must
        // reproduce position and velocity: the truth is a consistent kinematic history.
        let w = walk(Platform::Handheld);
        let dt = 1e-3;
        let mut prev = w.sample(5.0);
        let (mut p, mut v) = (prev.pos_enu_m, prev.vel_enu_mps);
        for k in 1..=10_000 {
            let s = w.sample(5.0 + k as f64 * dt);
            let v_new = v + 0.5 * (prev.acc_enu_mps2 + s.acc_enu_mps2) * dt;
            p += 0.5 * (v + v_new) * dt;
            v = v_new;
            prev = s;
        }
        assert!(
            (v - prev.vel_enu_mps).norm() < 2e-3,
            "{}",
            (v - prev.vel_enu_mps).norm()
        );
        assert!(
            (p - prev.pos_enu_m).norm() < 5e-3,
            "{}",
            (p - prev.pos_enu_m).norm()
        );
    }

    #[test]
    fn steps_follow_the_cadence() {
        let w = walk(Platform::Pedestrian);
        let steps = w.true_step_times_s();
        let dur = w.duration_s();
        // About 1.8 steps per second of walking (the ramps at both ends are short).
        let rate = steps.len() as f64 / dur;
        assert!((rate - 1.8).abs() < 0.15, "{rate} steps/s over {dur} s");
        for p in steps.windows(2) {
            let dt = p[1] - p[0];
            assert!(dt > 0.45 && dt < 0.65, "{dt}");
        }
        // At a true step the vertical acceleration is near its peak.
        let s = w.sample(steps[10]);
        assert!(s.acc_enu_mps2.z > 3.0, "{}", s.acc_enu_mps2.z);
    }

    #[test]
    fn car_pitch_follows_slope_and_imu_is_gravity_at_rest() {
        let traj = TrajectoryConfig::Waypoints {
            points_enu_m: vec![vec![0.0, 0.0, 0.0], vec![0.0, 100.0, 10.0]],
            speed_mps: 10.0,
            accel_mps2: None,
            lateral_accel_mps2: None,
            dwell_s: None,
            leg_speeds_mps: None,
            stops: None,
            laps: None,
            height_m: None,
        }
        .build(&mut TrialRng::new(1, 0).stream("m"))
        .unwrap();
        let car = PlatformTruth::new(
            traj,
            &PlatformConfig::default(),
            &mut TrialRng::new(1, 0).stream("g"),
        )
        .unwrap();
        let s = car.sample(3.0);
        let fwd = s.q_nb * Vector3::x();
        assert!((fwd - Vector3::new(0.0, 100.0, 10.0).normalize()).norm() < 1e-12);
        assert!(s.heading_rad.abs() < 1e-12 || (s.heading_rad - TAU).abs() < 1e-12);
        let earth = LocalEarth::new(0.7, 0.0);
        let (w, f) = ideal_imu(&s, &earth);
        // Uniform motion: the accelerometer reads gravity's reaction, the gyro the Earth rate
        // (plus a negligible Coriolis term).
        assert!((f.norm() - earth.gravity_mps2(s.pos_enu_m.z)).abs() < 1e-2);
        assert!((w.norm() - super::super::OMEGA_IE_RAD_PER_S).abs() < 1e-9);
    }
}
