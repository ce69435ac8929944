//! The inertial sensors as event-engine sources: an IMU ([`ImuSource`], name `"imu"`) and a
//! pedestrian dead-reckoning unit ([`PdrSource`], name `"pdr"`).
//!
//! # Consistency with the engine's truth
//!
//! The engine scores estimators against the world's trajectory (`ctx.truth`), but an IMU
//! needs more than one truth state per sample: the attitude, its rate, and (for walkers)
//! the gait. Both sources therefore own a [`PlatformTruth`] built on **the same
//! trajectory** as the engine's: either a second build of the world's trajectory config
//! from the same random stream (`"motion/trajectory"`, which is deterministic), or the
//! engine's own trajectory shared through [`SharedTrajectory`]. At every event the IMU
//! source compares its path with `ctx.truth` and records the largest difference
//! ([`ImuSource::max_truth_mismatch_m`]); a wrong wiring shows up there (and in a debug
//! assertion), never silently.
//!
//! For walkers the body moves on the path plus the gait overlay of
//! [`crate::inertial::attitude`] (a few centimetres of bounce and surge), so the IMU
//! integrates back to path + overlay, within `bounce/ω₀²` ≈ 3 cm of the scored truth.
//!
//! # Random streams
//!
//! * `"imu/gait"`: the gait's slow cadence and intensity wander. Both sources draw it from
//!   the same stream, so an IMU and a PDR in one world see the same walker.
//! * `"imu/sensor"`: the IMU source's error processes (turn-on bias, Gauss–Markov, white
//!   noise, …).
//! * `"imu/pdr/sensor"`, `"imu/pdr/mag"`: the PDR unit's own IMU and magnetometer (a
//!   different device from the `"imu"` source: a phone, say, next to a car's IMU); the
//!   magnetometer's per-trial calibration residuals come first from its stream.
//! * `"imu/pdr/step"`: the walker's Weinberg-K calibration error (one draw per trial).
//!
//! # What a sample is: the increments over its interval
//!
//! A navigation IMU does not report the instantaneous rate and specific force: it reports
//! the **delta angle and delta velocity** over each sample interval (MEMS parts low-pass to
//! a similar effect). Sample k, stamped t_k = k/rate, covers the interval
//! [t_k − Δ/2, t_k + Δ/2] (Δ = 1/rate; consecutive intervals tile the time axis) and
//! reports the increments divided by Δ, computed exactly from the truth at the interval
//! edges a and b:
//!
//! ```text
//! ω̄_k = (1/Δ) · rotvec( q_nb(a)⁻¹ ⊗ exp(ω_ie^n Δ) ⊗ q_nb(b) )        (body rotation w.r.t. inertial space)
//! f̄_k = C_n^b(t_k) · [ (v(b) − v(a))/Δ − g^n(h̄) + 2 ω_ie^n × (r(b) − r(a))/Δ ]
//! ```
//!
//! (Groves 2013 eqs. 5.28 and 5.39 integrated over the interval.) With these samples the
//! trapezoid velocity update of [`crate::inertial::strapdown`] telescopes to the exact
//! velocity change of the truth, Σ ½(C_{k−1} f̄_{k−1} + C_k f̄_k) Δ = v(t_K) − v(t_0) + end
//! terms, so the steps of a waypoint path's acceleration (corner arcs and speed ramps
//! begin and end abruptly) and the small velocity kinks of the gait overlay in a turn no
//! longer leave velocity errors of up to Δa·Δ/2 each, errors an INS filter with a
//! navigation-grade process noise would treat as impossible. Before the trajectory starts
//! the edge state is extrapolated with the initial acceleration, as if the IMU had been
//! running. Each sample costs one truth evaluation (the shared edge is reused) plus one
//! attitude evaluation at t_k.
//!
//! # Batching
//!
//! At rates up to [`MAX_BATCH_RATE_HZ`] = 100 Hz the IMU source emits one batch per sample.
//! Above that it groups `m = ⌈rate / 100⌉` consecutive samples per batch, so the engine sees
//! at most 100 events per second from it; a batch is stamped with the time of its last
//! sample, and every sample in it carries its own `t_s`. Sample k is at
//! `round(k · 10⁹ / rate)` ns, so the sample clock never drifts.
//!
//! The PDR source runs its IMU, magnetometer, step detector and AHRS ahead of the engine
//! (they depend only on the truth, not on any estimate) and schedules its next event at the
//! instant the detector confirms the next step: one event per step, never an empty batch
//! except a final one when no step is ever detected.

use super::attitude::{BodyTruth, PlatformConfig, PlatformTruth};
use super::imu::{Imu, ImuConfig};
use super::magnetometer::{Magnetometer, MagnetometerConfig};
use super::pdr::{Ahrs, Pdr, PdrConfig};
use super::LocalEarth;
use crate::core::{ConfigIssue, EnuFrame, SimTime, TrialRng};
use crate::measurement::{
    Measurement, MeasurementBatch, SampleContext, Source, SourceKind, StepEvent,
};
use crate::motion::{Trajectory, TruthState};
use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The highest rate at which the IMU source emits batches (Hz); above it, samples are grouped.
pub const MAX_BATCH_RATE_HZ: f64 = 100.0;

/// Stream of the gait wander, shared by the IMU and the PDR source.
pub const GAIT_STREAM: &str = "imu/gait";
/// Stream of the IMU source's error processes.
pub const IMU_STREAM: &str = "imu/sensor";
/// Stream of the PDR unit's IMU.
pub const PDR_IMU_STREAM: &str = "imu/pdr/sensor";
/// Stream of the PDR unit's magnetometer.
pub const PDR_MAG_STREAM: &str = "imu/pdr/mag";
/// Stream of the PDR walker's step-length calibration error.
pub const PDR_STEP_STREAM: &str = "imu/pdr/step";

/// The magnetic field a PDR unit walks through: the Earth's field at the world's origin
/// and date plus the scene's anomalies (`crate::magnetic::MagneticScene` implements it; a
/// trait here, so that this layer does not depend on the magnetic-landmark one above it).
pub trait AmbientField: Send + Sync {
    /// The Earth's field alone (ENU, µT): what the phone's own field model knows.
    fn earth_enu_ut(&self) -> Vector3<f64>;
    /// The whole field at a point (ENU, µT).
    fn b_enu_ut(&self, x_enu_m: &Vector3<f64>) -> Vector3<f64>;
}

/// A trajectory shared between the engine and a source (`Arc`), so both read one object.
#[derive(Clone)]
pub struct SharedTrajectory(pub Arc<dyn Trajectory>);

impl Trajectory for SharedTrajectory {
    fn state_at(&self, t_s: f64) -> TruthState {
        self.0.state_at(t_s)
    }
    fn duration_s(&self) -> f64 {
        self.0.duration_s()
    }
}

/// The local Earth of a world frame: the Earth rate and normal gravity at its origin.
pub fn local_earth_of(frame: &EnuFrame) -> LocalEarth {
    let o = frame.origin();
    LocalEarth::new(o.lat_rad, o.h_m)
}

/// The simulation time of sample `k` at `rate_hz`, rounded to the nanosecond.
fn sample_time(k: u64, rate_hz: f64) -> SimTime {
    SimTime((k as f64 * 1e9 / rate_hz).round() as i64)
}

/// The ideal increment IMU of the module documentation: samples k = 0, 1, 2, … in order,
/// reusing the shared interval edge. Does not allocate.
#[derive(Clone, Debug)]
struct IncrementImu {
    rate_hz: f64,
    /// The truth at the edge t_k − Δ/2 of the next sample, with its index k.
    edge: Option<(u64, BodyTruth)>,
}

impl IncrementImu {
    fn new(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            edge: None,
        }
    }

    /// The truth at the edge (k − ½)/rate; before the trajectory starts, extrapolated from
    /// the state at 0 with its acceleration (attitude held).
    fn edge_truth(&self, truth: &PlatformTruth, k: u64) -> BodyTruth {
        let t = (k as f64 - 0.5) / self.rate_hz;
        if t >= 0.0 {
            return truth.sample(t);
        }
        let mut s = truth.sample(0.0);
        s.pos_enu_m += s.vel_enu_mps * t + 0.5 * s.acc_enu_mps2 * t * t;
        s.vel_enu_mps += s.acc_enu_mps2 * t;
        s.t_s = t;
        s
    }

    /// (ω̄_ib^b rad/s, f̄^b m/s², attitude at t_k) of sample `k`.
    fn sample(
        &mut self,
        truth: &PlatformTruth,
        earth: &LocalEarth,
        k: u64,
    ) -> (Vector3<f64>, Vector3<f64>, UnitQuaternion<f64>) {
        let a = match self.edge.take() {
            Some((kk, e)) if kk == k => e,
            _ => self.edge_truth(truth, k),
        };
        let b = self.edge_truth(truth, k + 1);
        let dt = 1.0 / self.rate_hz;
        let turn = UnitQuaternion::from_scaled_axis(earth.omega_ie_enu_rps * dt);
        let w = (a.q_nb.inverse() * turn * b.q_nb).scaled_axis() / dt;
        let up = 0.5 * (a.pos_enu_m.z + b.pos_enu_m.z);
        let f_n = (b.vel_enu_mps - a.vel_enu_mps) / dt - earth.gravity_enu_mps2(up)
            + 2.0
                * earth
                    .omega_ie_enu_rps
                    .cross(&((b.pos_enu_m - a.pos_enu_m) / dt));
        let q = truth.attitude_at(k as f64 / self.rate_hz);
        self.edge = Some((k + 1, b));
        (w, q.inverse() * f_n, q)
    }
}

/// Prefixes a component's key path to a configuration issue.
fn under(prefix: &str, issue: ConfigIssue) -> ConfigIssue {
    ConfigIssue::new(format!("{prefix}.{}", issue.key), issue.message)
}

/// The IMU as an engine source: specific force and angular rate along the truth (gravity
/// and Earth rotation included; increments over each sample interval, see the module
/// documentation), through the error model of
/// [`crate::inertial::imu`], emitted as [`Measurement::Imu`] items.
pub struct ImuSource {
    truth: PlatformTruth,
    earth: LocalEarth,
    imu: Imu,
    rate_hz: f64,
    ideal: IncrementImu,
    samples_per_batch: u64,
    /// Index of the next sample to produce.
    next_k: u64,
    end: SimTime,
    max_mismatch_m: f64,
    /// The whole second of the last scored batch.
    scored_second: Option<i64>,
}

impl ImuSource {
    /// An IMU carried as `platform` says along `trajectory` (the world's trajectory, see the
    /// module documentation), in the world frame `frame`, sampling until `end`.
    ///
    /// # Errors
    /// A [`ConfigIssue`] for a bad IMU (key as in `[sensors.imu]`, e.g. `rate_hz`) or a bad
    /// platform (key prefixed `platform.`/`gait.`).
    pub fn new(
        imu: &ImuConfig,
        platform: &PlatformConfig,
        trajectory: Box<dyn Trajectory>,
        frame: &EnuFrame,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        let spec = imu.resolve()?;
        let truth =
            PlatformTruth::of_trial(trajectory, platform, rng).map_err(|i| under("gait", i))?;
        let samples_per_batch = (spec.rate_hz / MAX_BATCH_RATE_HZ).ceil().max(1.0) as u64;
        Ok(Self {
            truth,
            earth: local_earth_of(frame),
            imu: Imu::new(spec, rng.stream(IMU_STREAM)),
            rate_hz: spec.rate_hz,
            ideal: IncrementImu::new(spec.rate_hz),
            samples_per_batch,
            next_k: 0,
            end,
            max_mismatch_m: 0.0,
            scored_second: None,
        })
    }

    /// Samples per emitted batch (1 at rates up to 100 Hz).
    pub fn samples_per_batch(&self) -> u64 {
        self.samples_per_batch
    }

    /// The truth with attitude the IMU is sampled along.
    pub fn truth(&self) -> &PlatformTruth {
        &self.truth
    }

    /// The largest distance seen so far between this source's path and the engine's truth
    /// at the source's events (m); 0 when both come from the same trajectory.
    pub fn max_truth_mismatch_m(&self) -> f64 {
        self.max_mismatch_m
    }

    fn batch_time(&self, first_k: u64) -> SimTime {
        sample_time(first_k + self.samples_per_batch - 1, self.rate_hz)
    }
}

impl Source for ImuSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Imu
    }

    fn first_sample(&self) -> SimTime {
        self.batch_time(0)
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        out.t = ctx.truth.t;
        out.source = SourceKind::Imu;
        // Only the first batch of each whole second is scored: the INS is judged at 1 Hz
        // like every other estimator, whatever the IMU rate and batch grouping.
        let second = ctx.truth.sim.0.div_euclid(1_000_000_000);
        out.unscored = self.scored_second == Some(second);
        self.scored_second = Some(second);
        let path = self.truth.trajectory().state_at(ctx.truth.sim.seconds());
        let mismatch = (path.pos_enu_m - ctx.truth.enu.pos_enu_m).norm();
        debug_assert!(
            mismatch < 1e-3,
            "the IMU source's trajectory is not the engine's ({mismatch} m apart)"
        );
        self.max_mismatch_m = self.max_mismatch_m.max(mismatch);
        for _ in 0..self.samples_per_batch {
            let t = sample_time(self.next_k, self.rate_hz);
            if t > ctx.truth.sim {
                break;
            }
            let t_s = t.seconds();
            let (w, f, _) = self.ideal.sample(&self.truth, &self.earth, self.next_k);
            out.items
                .push(Measurement::Imu(self.imu.measure(t_s, &w, &f)));
            self.next_k += 1;
        }
        let next = self.batch_time(self.next_k);
        (next < self.end).then_some(next)
    }
}

fn d_sigma_length() -> f64 {
    0.05
}
fn d_sigma_heading() -> f64 {
    5.0
}

/// `[sensors.pdr]`: the PDR unit (a phone): its IMU, magnetometer, detector settings and
/// the σ its step events declare.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PdrSensorConfig {
    /// The unit's IMU; default a `low` (consumer MEMS) grade at 100 Hz.
    #[serde(default)]
    pub imu: ImuConfig,
    /// The magnetometer: noise, hard and soft iron and their per-trial calibration
    /// residuals. In a world it reads the world's field (IGRF-14 at the origin and start
    /// date plus the scene's magnetic anomalies); its `total_ut`, `inclination_deg` and
    /// `declination_deg` (default 54 µT, 59°, −7°) serve only a unit built without one.
    #[serde(default)]
    pub magnetometer: MagnetometerConfig,
    /// Step detection, Weinberg K and AHRS gains (`mag_gain = 0` for a gyro-only heading).
    #[serde(default)]
    pub detector: PdrConfig,
    /// 1-σ of the step length the step events declare (m); default 0.05.
    #[serde(default = "d_sigma_length")]
    pub sigma_length_m: f64,
    /// 1-σ of the step heading the step events declare (°); default 5.
    #[serde(default = "d_sigma_heading")]
    pub sigma_heading_deg: f64,
}

impl Default for PdrSensorConfig {
    fn default() -> Self {
        Self {
            imu: ImuConfig::default(),
            magnetometer: MagnetometerConfig::default(),
            detector: PdrConfig::default(),
            sigma_length_m: d_sigma_length(),
            sigma_heading_deg: d_sigma_heading(),
        }
    }
}

impl PdrSensorConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] whose key is the path inside `[sensors.pdr]` (`imu.rate_hz`,
    /// `detector.lowpass_hz`, `sigma_length_m`, …).
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let spec = self.imu.resolve().map_err(|i| under("imu", i))?;
        self.magnetometer
            .validate()
            .map_err(|i| under("magnetometer", i))?;
        self.detector
            .validate(spec.rate_hz)
            .map_err(|i| under("detector", i))?;
        if !(self.sigma_length_m.is_finite()
            && self.sigma_length_m > 0.0
            && self.sigma_length_m <= 5.0)
        {
            return Err(ConfigIssue::new(
                "sigma_length_m",
                format!(
                    "expected a step-length σ in m within (0, 5], got {}",
                    self.sigma_length_m
                ),
            ));
        }
        if !(self.sigma_heading_deg.is_finite()
            && self.sigma_heading_deg > 0.0
            && self.sigma_heading_deg <= 180.0)
        {
            return Err(ConfigIssue::new(
                "sigma_heading_deg",
                format!(
                    "expected a heading σ in degrees within (0, 180], got {}",
                    self.sigma_heading_deg
                ),
            ));
        }
        Ok(())
    }
}

/// A step confirmed by the detector, waiting for its event.
#[derive(Clone, Copy, Debug)]
struct PendingStep {
    at: SimTime,
    step: super::pdr::StepEvent,
}

/// Pedestrian dead reckoning as an engine source: a phone's IMU and magnetometer simulated
/// along the truth, the step detector, Weinberg length and AHRS of [`crate::inertial::pdr`],
/// and one [`Measurement::Step`] per detected step, emitted at the sample where the detector
/// confirms it.
///
/// The AHRS is aligned on the first sample (TRIAD: up from the accelerometer, north from
/// the magnetometer and the configured declination).
pub struct PdrSource {
    truth: PlatformTruth,
    earth: LocalEarth,
    imu: Imu,
    mag: Magnetometer,
    field_enu_ut: Vector3<f64>,
    scene: Option<Box<dyn AmbientField>>,
    detector_cfg: PdrConfig,
    pdr: Option<Pdr>,
    rate_hz: f64,
    ideal: IncrementImu,
    next_k: u64,
    end: SimTime,
    pending: Option<PendingStep>,
    sigma_length_m: f64,
    sigma_heading_rad: f64,
    emitted: Vec<f64>,
    record: bool,
}

impl PdrSource {
    /// A PDR unit carried as `platform` says (use `pedestrian` or `handheld`; a car takes no
    /// steps) along `trajectory` (the world's, see the module documentation), until `end`.
    ///
    /// # Errors
    /// The first [`ConfigIssue`] of [`PdrSensorConfig::validate`] or of the platform.
    pub fn new(
        cfg: &PdrSensorConfig,
        platform: &PlatformConfig,
        trajectory: Box<dyn Trajectory>,
        frame: &EnuFrame,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        Self::in_scene(cfg, platform, trajectory, frame, None, rng, end)
    }

    /// As [`PdrSource::new`], with the magnetometer reading the field of `scene` at the
    /// walker's position (the Earth's field at the world's origin and date plus the scene's
    /// anomalies, the field the landmark matcher sees) instead of the configured constant
    /// field. The AHRS then references heading to the scene's Earth field (its declination),
    /// as a phone does with its built-in field model; the anomalies are what it does not
    /// know. With `None` it reads the configured field, as [`PdrSource::new`].
    ///
    /// When `cfg.detector.weinberg_k_error` is positive, this walker's K is
    /// K (1 + ε), ε ~ N(0, σ²) drawn once from the stream `imu/pdr/step`.
    ///
    /// # Errors
    /// As [`PdrSource::new`].
    #[allow(clippy::too_many_arguments)]
    pub fn in_scene(
        cfg: &PdrSensorConfig,
        platform: &PlatformConfig,
        trajectory: Box<dyn Trajectory>,
        frame: &EnuFrame,
        scene: Option<Box<dyn AmbientField>>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let spec = cfg.imu.resolve().map_err(|i| under("imu", i))?;
        let truth =
            PlatformTruth::of_trial(trajectory, platform, rng).map_err(|i| under("gait", i))?;
        let mag = Magnetometer::new(&cfg.magnetometer, rng.stream(PDR_MAG_STREAM))
            .map_err(|i| under("magnetometer", i))?;
        let mut detector_cfg = cfg.detector.clone();
        if detector_cfg.weinberg_k_error > 0.0 {
            let eps: f64 = rng.stream(PDR_STEP_STREAM).sample(StandardNormal);
            // K stays positive: a draw beyond −1/σ (ten σ at the largest accepted σ) is
            // clipped to 10 % of the nominal K.
            detector_cfg.weinberg_k *= (1.0 + detector_cfg.weinberg_k_error * eps).max(0.1);
        }
        let field_enu_ut = scene
            .as_ref()
            .map_or_else(|| cfg.magnetometer.field_enu_ut(), |s| s.earth_enu_ut());
        let mut s = Self {
            truth,
            earth: local_earth_of(frame),
            imu: Imu::new(spec, rng.stream(PDR_IMU_STREAM)),
            mag,
            field_enu_ut,
            scene,
            detector_cfg,
            pdr: None,
            rate_hz: spec.rate_hz,
            ideal: IncrementImu::new(spec.rate_hz),
            next_k: 0,
            end,
            pending: None,
            sigma_length_m: cfg.sigma_length_m,
            sigma_heading_rad: cfg.sigma_heading_deg.to_radians(),
            emitted: Vec::new(),
            record: false,
        };
        s.pending = s.run_to_next_step()?;
        Ok(s)
    }

    /// Records the detected step (peak) times for validation ([`PdrSource::step_times_s`]).
    pub fn record_steps(&mut self) {
        self.record = true;
    }

    /// The peak times of the steps emitted so far (s), when recording.
    pub fn step_times_s(&self) -> &[f64] {
        &self.emitted
    }

    /// The truth with attitude the unit is carried along.
    pub fn truth(&self) -> &PlatformTruth {
        &self.truth
    }

    /// Runs the unit sample by sample until the detector confirms a step (its confirmation
    /// time and the step) or the end is reached (`None`).
    fn run_to_next_step(&mut self) -> Result<Option<PendingStep>, ConfigIssue> {
        loop {
            let at = sample_time(self.next_k, self.rate_hz);
            if at >= self.end {
                return Ok(None);
            }
            let t_s = at.seconds();
            let (w, f, q_nb) = self.ideal.sample(&self.truth, &self.earth, self.next_k);
            let m = self.imu.measure(t_s, &w, &f);
            let b = match &self.scene {
                Some(scene) => {
                    let field = scene.b_enu_ut(&self.truth.sample(t_s).pos_enu_m);
                    self.mag.measure_in_field(&q_nb, &field)
                }
                None => self.mag.measure(&q_nb),
            };
            self.next_k += 1;
            let pdr = match &mut self.pdr {
                Some(p) => p,
                None => {
                    let ahrs = Ahrs::align(
                        &m.accel_mps2,
                        &b,
                        &self.field_enu_ut,
                        self.earth,
                        &self.detector_cfg,
                    );
                    self.pdr.insert(
                        Pdr::new(
                            &self.detector_cfg,
                            self.rate_hz,
                            ahrs,
                            self.truth.trajectory().state_at(t_s).pos_enu_m.xy(),
                        )
                        .map_err(|i| under("detector", i))?,
                    )
                }
            };
            if let Some(step) = pdr.update(&m, Some(&b)) {
                return Ok(Some(PendingStep { at, step }));
            }
        }
    }
}

impl Source for PdrSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Pdr
    }

    fn first_sample(&self) -> SimTime {
        self.pending.map_or(self.end, |p| p.at)
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        out.t = ctx.truth.t;
        out.source = SourceKind::Pdr;
        let p = self.pending.take()?;
        out.items.push(Measurement::Step(StepEvent {
            length_m: p.step.length_m,
            sigma_length_m: self.sigma_length_m,
            heading_rad: p.step.heading_rad,
            sigma_heading_rad: self.sigma_heading_rad,
        }));
        if self.record {
            self.emitted.push(p.step.t_s);
        }
        // The configuration was validated in `new`, so the detector cannot fail here.
        self.pending = self.run_to_next_step().ok().flatten();
        self.pending.map(|n| n.at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{Geodetic, GpsTime};
    use crate::inertial::attitude::Platform;
    use crate::inertial::imu::ImuGrade;
    use crate::measurement::Truth;
    use crate::motion::TrajectoryConfig;

    fn walk() -> TrajectoryConfig {
        TrajectoryConfig::Waypoints {
            points_enu_m: vec![vec![0.0, 0.0], vec![20.0, 0.0], vec![20.0, 10.0]],
            speed_mps: 1.1,
            accel_mps2: Some(0.5),
            lateral_accel_mps2: Some(0.4),
            dwell_s: None,
            leg_speeds_mps: None,
            stops: None,
            laps: None,
            height_m: None,
        }
    }

    fn truth_at(traj: &dyn Trajectory, frame: &EnuFrame, sim: SimTime) -> Truth {
        crate::engine::trial::truth_at(frame, GpsTime::from_ns(0), traj, sim)
    }

    #[test]
    fn batches_group_samples_above_100_hz_and_keep_the_clock() {
        let frame = EnuFrame::new(Geodetic::from_deg(30.5, 114.3, 20.0));
        let rng = TrialRng::new(3, 0);
        let build = || walk().build(&mut rng.stream("motion/trajectory")).unwrap();
        let mut cfg = ImuConfig::grade(ImuGrade::Mid);
        cfg.rate_hz = 250.0;
        let plat = PlatformConfig {
            platform: Platform::Handheld,
            ..Default::default()
        };
        let end = SimTime::from_seconds(2.0);
        let mut src = ImuSource::new(&cfg, &plat, build(), &frame, &rng, end).unwrap();
        assert_eq!(src.samples_per_batch(), 3);
        let engine_traj = build();
        let mut at = src.first_sample();
        // Batch 0 ends with sample 2 at 8 ms.
        assert_eq!(at, SimTime(8_000_000));
        let mut batch = MeasurementBatch::default();
        let mut times = Vec::new();
        loop {
            batch.items.clear();
            let truth = truth_at(engine_traj.as_ref(), &frame, at);
            let ctx = SampleContext {
                truth: &truth,
                estimates: &[],
            };
            let next = src.sample(&ctx, &mut batch);
            assert_eq!(batch.source, SourceKind::Imu);
            for m in &batch.items {
                let Measurement::Imu(s) = m else {
                    panic!("not an IMU sample")
                };
                assert!(s.t_s <= at.seconds() + 1e-12);
                times.push(s.t_s);
            }
            match next {
                Some(n) => at = n,
                None => break,
            }
        }
        // Every sample before the end, once, 4 ms apart.
        assert_eq!(times.len(), 498, "{}", times.len());
        for (k, t) in times.iter().enumerate() {
            assert!((t - k as f64 * 0.004).abs() < 1e-9);
        }
        assert_eq!(src.max_truth_mismatch_m(), 0.0);
    }

    #[test]
    fn bad_sensor_config_names_the_key() {
        let frame = EnuFrame::new(Geodetic::from_deg(30.5, 114.3, 20.0));
        let rng = TrialRng::new(3, 0);
        let mut cfg = PdrSensorConfig::default();
        cfg.imu.rate_hz = 0.0;
        assert_eq!(cfg.validate().unwrap_err().key, "imu.rate_hz");
        cfg.imu.rate_hz = 100.0;
        cfg.detector.lowpass_hz = 80.0;
        assert_eq!(cfg.validate().unwrap_err().key, "detector.lowpass_hz");
        cfg.detector.lowpass_hz = 5.0;
        cfg.sigma_heading_deg = -1.0;
        assert_eq!(cfg.validate().unwrap_err().key, "sigma_heading_deg");
        let traj = walk().build(&mut rng.stream("motion/trajectory")).unwrap();
        let mut plat = PlatformConfig::default();
        plat.gait.step_frequency_hz = 50.0;
        let e = ImuSource::new(
            &ImuConfig::default(),
            &plat,
            traj,
            &frame,
            &rng,
            SimTime::from_seconds(1.0),
        )
        .err()
        .unwrap();
        assert_eq!(e.key, "gait.step_frequency_hz");
    }
}
