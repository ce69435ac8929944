//! Platform truth motion: where the receiver really is, how fast it moves and where it
//! points, at any instant of a trial.
//!
//! A world file describes the motion with a [`TrajectoryConfig`]; [`TrajectoryConfig::build`]
//! turns it into a [`Trajectory`], which answers [`Trajectory::state_at`] for any time in
//! seconds since the trial start. Four kinds exist:
//!
//! * [`TrajectoryConfig::Waypoints`]: a car or a pedestrian following a polyline at a set
//!   speed, with optional trapezoidal speed ramps, circular corner arcs, dwells and laps
//!   (module [`waypoints`]).
//! * [`TrajectoryConfig::Singer`]: seed 001's target, uniform motion in x and a Singer (1970)
//!   manoeuvring y (module [`singer`]).
//! * [`TrajectoryConfig::PlaneTurning`]: seed 003's three-dimensional plane variable-speed
//!   turning model (module [`turning`]).
//! * [`TrajectoryConfig::Static`]: a receiver that does not move.
//!
//! Coordinates are local East-North-Up metres of the world's ENU frame. The papers' `x`, `y`,
//! `z` map to East, North, Up. Heading is measured from north, clockwise, in `[0, 2π)`.
//!
//! Stochastic models draw all their randomness inside [`TrajectoryConfig::build`] from the
//! generator the caller passes (a named stream such as `"motion/trajectory"`), so a built
//! trajectory is an immutable, thread-safe function of time.

pub mod singer;
pub mod turning;
pub mod waypoints;

use crate::core::config::{check_finite, check_range};
use crate::core::ConfigIssue;
use nalgebra::Vector3;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// The longest trajectory a world may ask for: ten days, in seconds.
pub const MAX_DURATION_S: f64 = 10.0 * 86_400.0;
/// The most steps a stochastic model may generate (memory is a few hundred bytes a step).
pub const MAX_STEPS: f64 = 10_000_000.0;

/// The platform's true kinematic state at one instant, in the world's ENU frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthState {
    /// Seconds since the trial start.
    pub t_s: f64,
    /// Position (m).
    pub pos_enu_m: Vector3<f64>,
    /// Velocity (m/s).
    pub vel_enu_mps: Vector3<f64>,
    /// Acceleration (m/s²), the time derivative of `vel_enu_mps`.
    pub acc_enu_mps2: Vector3<f64>,
    /// Heading of the horizontal velocity, from north, clockwise, in `[0, 2π)` rad.
    pub heading_rad: f64,
}

/// A platform trajectory: a deterministic function of time once built.
pub trait Trajectory: Send + Sync {
    /// The state at `t_s` seconds since the trial start. Times outside `[0, duration_s]`
    /// are clamped to the nearest end (so the state at the end, velocity included, is
    /// returned after the end); a NaN time reads as 0.
    fn state_at(&self, t_s: f64) -> TruthState;
    /// The length of the trajectory in seconds.
    fn duration_s(&self) -> f64;
}

/// Checks a stochastic model's duration and step: both positive, the duration at most ten
/// days and the number of steps at most [`MAX_STEPS`].
pub(crate) fn check_duration_and_step(duration_s: f64, step_s: f64) -> Result<(), ConfigIssue> {
    check_range(
        "duration_s",
        duration_s,
        0.0,
        MAX_DURATION_S,
        true,
        "a duration in seconds",
    )?;
    check_range(
        "step_s",
        step_s,
        0.0,
        duration_s,
        true,
        "a step in seconds no longer than duration_s",
    )?;
    let steps = (duration_s / step_s).ceil();
    if steps > MAX_STEPS {
        return Err(ConfigIssue::new(
            "step_s",
            format!("step_s = {step_s} s over duration_s = {duration_s} s would generate {steps} steps; expected at most {MAX_STEPS}"),
        ));
    }
    Ok(())
}

/// Heading from north, clockwise, in `[0, 2π)`, of a horizontal ENU direction, or `None`
/// when the direction has (almost) no horizontal part.
pub(crate) fn heading_of(v: &Vector3<f64>) -> Option<f64> {
    let h = v.x.hypot(v.y);
    if h <= 1e-12 * (1.0 + v.z.abs()) {
        return None;
    }
    let mut az = v.x.atan2(v.y);
    if az < 0.0 {
        az += std::f64::consts::TAU;
    }
    // atan2 of a tiny negative x can round to exactly 2π after the shift.
    if az >= std::f64::consts::TAU {
        az = 0.0;
    }
    Some(az)
}

/// Maps a query time into `[0, duration]` (NaN reads as 0).
pub(crate) fn clamp_time(t_s: f64, duration_s: f64) -> f64 {
    if t_s.is_nan() {
        0.0
    } else {
        t_s.clamp(0.0, duration_s)
    }
}

fn default_singer_state() -> [f64; 5] {
    [4000.0, 14.0, 0.0, 11.0, 0.0]
}
fn default_singer_alpha() -> f64 {
    0.1
}
fn default_singer_accel_var() -> f64 {
    3.5
}
fn default_step() -> f64 {
    1.0
}
fn default_paper_duration() -> f64 {
    100.0
}
fn default_turning_velocity() -> [f64; 3] {
    [4.0, -4.0, 4.0]
}
fn default_turning_accel() -> [f64; 3] {
    [0.5, -0.5, -0.5]
}
fn default_turning_attenuation() -> f64 {
    0.03
}
fn default_turning_rate() -> f64 {
    0.1
}
fn default_turning_noise() -> f64 {
    0.01
}

/// How the platform moves, as a world file writes it (`kind = "waypoints"` etc.).
///
/// Every field of the two paper models defaults to the paper's value, so
/// `trajectory = { kind = "singer" }` is seed 001's target and
/// `trajectory = { kind = "plane_turning" }` is seed 003's.
/// A stop at one waypoint of a [`TrajectoryConfig::Waypoints`] path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WaypointStop {
    /// Index of the waypoint in `points_enu_m`.
    pub at: usize,
    /// Time at rest there (s).
    pub dwell_s: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum TrajectoryConfig {
    /// A polyline followed at `speed_mps` (see [`waypoints`] for the exact kinematics).
    Waypoints {
        /// Waypoints in ENU metres, each `[e, n]` (at `height_m`) or `[e, n, u]`; at least two
        /// distinct points. Consecutive repeats are dropped.
        points_enu_m: Vec<Vec<f64>>,
        /// Cruise speed (m/s); the speed never exceeds it.
        speed_mps: f64,
        /// Longitudinal acceleration and braking limit (m/s²). When given the platform starts
        /// and ends at rest with trapezoidal speed ramps, and brakes for corners; when absent
        /// it moves at `speed_mps` from the first instant to the last.
        #[serde(default)]
        accel_mps2: Option<f64>,
        /// Lateral (centripetal) acceleration limit in corners (m/s²). When given, each corner
        /// is a circular arc of radius `speed_mps² / lateral_accel_mps2` (smaller when the legs
        /// are too short, with the speed lowered to keep the limit if `accel_mps2` is given);
        /// when absent the direction changes instantly at the waypoint.
        #[serde(default)]
        lateral_accel_mps2: Option<f64>,
        /// Time spent at rest at each waypoint after the first and before the last (s).
        /// With a dwell the platform stops at every waypoint, so corners are not rounded.
        #[serde(default)]
        dwell_s: Option<f64>,
        /// Speed cap of each leg (m/s), in the order of `points_enu_m`: one per leg (one
        /// fewer than the points, or as many as the points with `laps`, whose closing leg
        /// is the last), each overriding `speed_mps` on its leg, which stays the cap of
        /// everything else (corner radii are sized for the faster adjacent leg). Traffic:
        /// split a street into collinear legs to slow down and speed up along it.
        #[serde(default)]
        leg_speeds_mps: Option<Vec<f64>>,
        /// Stops at single waypoints (a traffic light, a junction): the platform brakes to
        /// rest at waypoint `at` (an index into `points_enu_m`, neither the first nor, without
        /// `laps`, the last) and waits `dwell_s` there, on every lap.
        #[serde(default)]
        stops: Option<Vec<WaypointStop>>,
        /// When given, the polygon is closed (last point back to the first) and driven this
        /// many times; when absent the polyline is driven once, first point to last.
        #[serde(default)]
        laps: Option<u32>,
        /// Up coordinate (m) of the `[e, n]` points; 0 when absent.
        #[serde(default)]
        height_m: Option<f64>,
    },
    /// Seed 001: uniform motion in x (east) and a Singer-manoeuvring y (north).
    Singer {
        /// The paper's X(0) = [x (m), ẋ (m/s), y (m), ẏ (m/s), ÿ (m/s²)]; default
        /// [4000, 14, 0, 11, 0].
        #[serde(default = "default_singer_state")]
        initial_state: [f64; 5],
        /// Manoeuvre frequency α (1/s), the inverse manoeuvre time constant; default 0.1.
        #[serde(default = "default_singer_alpha")]
        alpha_per_s: f64,
        /// Manoeuvre (acceleration) variance σ_m² ((m/s²)²); default 3.5.
        #[serde(default = "default_singer_accel_var")]
        accel_var_m2ps4: f64,
        /// Generation step (s); default 1.
        #[serde(default = "default_step")]
        step_s: f64,
        /// Length (s); default 100.
        #[serde(default = "default_paper_duration")]
        duration_s: f64,
        /// Up coordinate (m); default 0.
        #[serde(default)]
        height_m: f64,
    },
    /// Seed 003: the three-dimensional plane variable-speed turning model.
    PlaneTurning {
        /// Initial position (m); default [0, 0, 0].
        #[serde(default)]
        initial_position_m: [f64; 3],
        /// Initial velocity (m/s); default [4, −4, 4].
        #[serde(default = "default_turning_velocity")]
        initial_velocity_mps: [f64; 3],
        /// Initial acceleration (m/s²); default [0.5, −0.5, −0.5].
        #[serde(default = "default_turning_accel")]
        initial_accel_mps2: [f64; 3],
        /// Attenuation coefficient α of the acceleration (1/s); default 0.03.
        #[serde(default = "default_turning_attenuation")]
        attenuation_per_s: f64,
        /// Angular velocity ω at which the horizontal acceleration turns (rad/s, positive
        /// counter-clockwise seen from above); default 0.1.
        #[serde(default = "default_turning_rate")]
        turn_rate_rad_per_s: f64,
        /// Variance of the Gaussian process noise added to each acceleration component at
        /// every step ((m/s²)²); default 0.01.
        #[serde(default = "default_turning_noise")]
        noise_var_m2ps4: f64,
        /// Generation step (s); default 1.
        #[serde(default = "default_step")]
        step_s: f64,
        /// Length (s); default 100.
        #[serde(default = "default_paper_duration")]
        duration_s: f64,
    },
    /// A receiver at rest.
    Static {
        /// Position (m).
        position_enu_m: [f64; 3],
        /// Length (s).
        duration_s: f64,
    },
}

impl TrajectoryConfig {
    /// Checks every value; the first problem found is returned with the key that holds it.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the field for non-finite numbers, non-positive speeds, fewer
    /// than two distinct waypoints, durations over ten days or steps that would generate more
    /// than [`MAX_STEPS`] samples.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        match self {
            TrajectoryConfig::Waypoints { .. } => {
                waypoints::WaypointPlan::from_config(self).map(|_| ())
            }
            TrajectoryConfig::Singer {
                initial_state,
                alpha_per_s,
                accel_var_m2ps4,
                step_s,
                duration_s,
                height_m,
            } => {
                check_finite("initial_state", initial_state, "[x, ẋ, y, ẏ, ÿ]")?;
                check_range(
                    "alpha_per_s",
                    *alpha_per_s,
                    0.0,
                    1.0e3,
                    true,
                    "a manoeuvre frequency in 1/s",
                )?;
                check_range(
                    "accel_var_m2ps4",
                    *accel_var_m2ps4,
                    0.0,
                    1.0e4,
                    false,
                    "an acceleration variance in (m/s²)²",
                )?;
                check_range("height_m", *height_m, -1.0e4, 1.0e5, false, "a height in m")?;
                check_duration_and_step(*duration_s, *step_s)
            }
            TrajectoryConfig::PlaneTurning {
                initial_position_m,
                initial_velocity_mps,
                initial_accel_mps2,
                attenuation_per_s,
                turn_rate_rad_per_s,
                noise_var_m2ps4,
                step_s,
                duration_s,
            } => {
                check_finite("initial_position_m", initial_position_m, "a position in m")?;
                check_finite(
                    "initial_velocity_mps",
                    initial_velocity_mps,
                    "a velocity in m/s",
                )?;
                check_finite(
                    "initial_accel_mps2",
                    initial_accel_mps2,
                    "an acceleration in m/s²",
                )?;
                check_range(
                    "attenuation_per_s",
                    *attenuation_per_s,
                    0.0,
                    1.0e3,
                    false,
                    "an attenuation coefficient in 1/s",
                )?;
                check_range(
                    "turn_rate_rad_per_s",
                    *turn_rate_rad_per_s,
                    -1.0e3,
                    1.0e3,
                    false,
                    "an angular velocity in rad/s",
                )?;
                check_range(
                    "noise_var_m2ps4",
                    *noise_var_m2ps4,
                    0.0,
                    1.0e4,
                    false,
                    "a process noise variance in (m/s²)²",
                )?;
                check_duration_and_step(*duration_s, *step_s)
            }
            TrajectoryConfig::Static {
                position_enu_m,
                duration_s,
            } => {
                check_finite("position_enu_m", position_enu_m, "a position in m")?;
                check_range(
                    "duration_s",
                    *duration_s,
                    0.0,
                    MAX_DURATION_S,
                    true,
                    "a duration in seconds",
                )
            }
        }
    }

    /// Validates and builds the trajectory, drawing the randomness of stochastic models from
    /// `rng` (deterministic models do not touch it).
    ///
    /// # Errors
    /// The first [`ConfigIssue`] [`TrajectoryConfig::validate`] finds.
    pub fn build(&self, rng: &mut impl Rng) -> Result<Box<dyn Trajectory>, ConfigIssue> {
        self.validate()?;
        Ok(match self {
            TrajectoryConfig::Waypoints { .. } => {
                Box::new(waypoints::WaypointPlan::from_config(self)?)
            }
            TrajectoryConfig::Singer {
                initial_state,
                alpha_per_s,
                accel_var_m2ps4,
                step_s,
                duration_s,
                height_m,
            } => Box::new(singer::SingerTrajectory::generate(
                *initial_state,
                *alpha_per_s,
                *accel_var_m2ps4,
                *step_s,
                *duration_s,
                *height_m,
                rng,
            )),
            TrajectoryConfig::PlaneTurning {
                initial_position_m,
                initial_velocity_mps,
                initial_accel_mps2,
                attenuation_per_s,
                turn_rate_rad_per_s,
                noise_var_m2ps4,
                step_s,
                duration_s,
            } => Box::new(turning::PlaneTurningTrajectory::generate(
                &turning::PlaneTurningParams {
                    initial_position_m: Vector3::from(*initial_position_m),
                    initial_velocity_mps: Vector3::from(*initial_velocity_mps),
                    initial_accel_mps2: Vector3::from(*initial_accel_mps2),
                    attenuation_per_s: *attenuation_per_s,
                    turn_rate_rad_per_s: *turn_rate_rad_per_s,
                    noise_var_m2ps4: *noise_var_m2ps4,
                    step_s: *step_s,
                    duration_s: *duration_s,
                },
                rng,
            )),
            TrajectoryConfig::Static {
                position_enu_m,
                duration_s,
            } => Box::new(StaticTrajectory {
                position_enu_m: Vector3::from(*position_enu_m),
                duration_s: *duration_s,
            }),
        })
    }
}

/// A platform at rest at one point; its heading is 0 (north).
#[derive(Clone, Debug, PartialEq)]
pub struct StaticTrajectory {
    /// Position (m).
    pub position_enu_m: Vector3<f64>,
    /// Length (s).
    pub duration_s: f64,
}

impl Trajectory for StaticTrajectory {
    fn state_at(&self, t_s: f64) -> TruthState {
        TruthState {
            t_s: clamp_time(t_s, self.duration_s),
            pos_enu_m: self.position_enu_m,
            vel_enu_mps: Vector3::zeros(),
            acc_enu_mps2: Vector3::zeros(),
            heading_rad: 0.0,
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

    fn parse(text: &str) -> Result<TrajectoryConfig, toml::de::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Doc {
            trajectory: TrajectoryConfig,
        }
        toml::from_str::<Doc>(text).map(|d| d.trajectory)
    }

    #[test]
    fn paper_defaults_parse() {
        let s = parse("trajectory = { kind = \"singer\" }").unwrap();
        assert_eq!(
            s,
            TrajectoryConfig::Singer {
                initial_state: [4000.0, 14.0, 0.0, 11.0, 0.0],
                alpha_per_s: 0.1,
                accel_var_m2ps4: 3.5,
                step_s: 1.0,
                duration_s: 100.0,
                height_m: 0.0
            }
        );
        let p = parse("trajectory = { kind = \"plane_turning\" }").unwrap();
        match p {
            TrajectoryConfig::PlaneTurning {
                initial_velocity_mps,
                attenuation_per_s,
                turn_rate_rad_per_s,
                noise_var_m2ps4,
                ..
            } => {
                assert_eq!(initial_velocity_mps, [4.0, -4.0, 4.0]);
                assert_eq!(
                    (attenuation_per_s, turn_rate_rad_per_s, noise_var_m2ps4),
                    (0.03, 0.1, 0.01)
                );
            }
            other => panic!("{other:?}"),
        }
        let w = parse("[trajectory]\nkind = \"waypoints\"\npoints_enu_m = [[0, 0], [100, 0, 2]]\nspeed_mps = 10\n").unwrap();
        assert!(w.validate().is_ok());
    }

    #[test]
    fn unknown_fields_and_kinds_are_rejected() {
        let e = parse("trajectory = { kind = \"singer\", alpha = 0.1 }").unwrap_err();
        assert!(e.to_string().contains("alpha"), "{e}");
        assert!(parse("trajectory = { kind = \"teleport\" }").is_err());
        assert!(parse("trajectory = { kind = \"static\", position_enu_m = [0, 0, 0], duration_s = 5, speed_mps = 1 }").is_err());
    }

    #[test]
    fn validation_names_the_key() {
        let bad = TrajectoryConfig::Waypoints {
            points_enu_m: vec![vec![0.0, 0.0], vec![10.0, 0.0]],
            speed_mps: -3.0,
            accel_mps2: None,
            lateral_accel_mps2: None,
            dwell_s: None,
            leg_speeds_mps: None,
            stops: None,
            laps: None,
            height_m: None,
        };
        let issue = bad.validate().unwrap_err();
        assert_eq!(issue.key, "speed_mps");
        assert!(issue.message.contains("-3"), "{}", issue.message);

        let bad = TrajectoryConfig::Singer {
            initial_state: [0.0, 1.0, 0.0, f64::NAN, 0.0],
            alpha_per_s: 0.1,
            accel_var_m2ps4: 3.5,
            step_s: 1.0,
            duration_s: 100.0,
            height_m: 0.0,
        };
        assert_eq!(bad.validate().unwrap_err().key, "initial_state");
        let bad = TrajectoryConfig::Singer {
            initial_state: [0.0; 5],
            alpha_per_s: 0.1,
            accel_var_m2ps4: 3.5,
            step_s: 1.0,
            duration_s: 20.0 * 86_400.0,
            height_m: 0.0,
        };
        assert_eq!(bad.validate().unwrap_err().key, "duration_s");
        let bad = TrajectoryConfig::Singer {
            initial_state: [0.0; 5],
            alpha_per_s: 0.1,
            accel_var_m2ps4: 3.5,
            step_s: 1e-6,
            duration_s: 86_400.0,
            height_m: 0.0,
        };
        assert_eq!(bad.validate().unwrap_err().key, "step_s");
        let bad = TrajectoryConfig::Static {
            position_enu_m: [0.0, f64::INFINITY, 0.0],
            duration_s: 10.0,
        };
        assert_eq!(bad.validate().unwrap_err().key, "position_enu_m");
        let bad = TrajectoryConfig::Static {
            position_enu_m: [0.0; 3],
            duration_s: 0.0,
        };
        assert_eq!(bad.validate().unwrap_err().key, "duration_s");
        let mut rng = TrialRng::new(1, 0).stream("motion/test");
        assert_eq!(bad.build(&mut rng).err().unwrap().key, "duration_s");
    }

    #[test]
    fn static_is_static_and_clamps() {
        let cfg = TrajectoryConfig::Static {
            position_enu_m: [1.0, 2.0, 3.0],
            duration_s: 10.0,
        };
        let t = cfg.build(&mut TrialRng::new(1, 0).stream("m")).unwrap();
        assert_eq!(t.duration_s(), 10.0);
        let s = t.state_at(20.0);
        assert_eq!(s.t_s, 10.0);
        assert_eq!(s.pos_enu_m, Vector3::new(1.0, 2.0, 3.0));
        assert_eq!(t.state_at(f64::NAN).t_s, 0.0);
        assert_eq!(s.vel_enu_mps, Vector3::zeros());
    }

    #[test]
    fn headings() {
        use std::f64::consts::{FRAC_PI_2, PI};
        assert_eq!(heading_of(&Vector3::new(0.0, 1.0, 0.0)), Some(0.0));
        assert!((heading_of(&Vector3::new(1.0, 0.0, 0.0)).unwrap() - FRAC_PI_2).abs() < 1e-15);
        assert!((heading_of(&Vector3::new(0.0, -1.0, 0.0)).unwrap() - PI).abs() < 1e-15);
        assert!(
            (heading_of(&Vector3::new(-1.0, 0.0, 0.0)).unwrap() - 3.0 * FRAC_PI_2).abs() < 1e-15
        );
        assert_eq!(heading_of(&Vector3::new(0.0, 0.0, 1.0)), None);
    }
}
