//! What flows from the sources to the estimators, and the two traits at its ends.
//!
//! A measurement carries everything an estimator needs to use it (the emitter's position
//! and velocity as the receiver computes them, the noise it should assume) and nothing of
//! the truth. Sources ([`Source`]) produce them in batches tagged with their
//! [`SourceKind`]; the engine hands each batch to the estimators ([`Estimator`]) that
//! subscribe to that kind, computed once when a trial is built.
//!
//! This module sits below every source and every filter: it knows `core` and `motion`
//! and nothing else, so the sensor models and the fusion algorithms never see each other.

pub mod estimator;
pub mod raw;
pub mod source;

pub use estimator::{EpochOutcome, Estimate, Estimator};
pub use raw::{MagSample, RawGnssObservation, RawLog};
pub use source::{SampleContext, Source, SourceKind, Truth};

use crate::core::{EmitterId, GpsTime, System};
use nalgebra::{Matrix3, Vector3};

/// A pseudorange (and optionally a pseudorange rate) to one emitter.
///
/// Model (seed 000 eqs. 9, 14, 16):
/// ```text
/// ρ  = ‖r_e − r‖ + b_sys + ε_ρ          (b_sys: receiver clock offset of the system, m)
/// ρ̇  = (r − r_e)/‖r − r_e‖ · (v − v_e) + ḃ + ε_ρ̇
/// ```
/// The emitter position is the one at transmission time, already rotated into the ECEF
/// frame at reception time (Sagnac), and the pseudorange is already corrected for the
/// emitter clock and the atmospheric models the receiver applies, as a receiver's
/// navigation processor does before its filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeMeasurement {
    pub emitter: EmitterId,
    /// Emitter position (ECEF, m).
    pub emitter_pos_ecef_m: Vector3<f64>,
    /// Emitter velocity (ECEF, m/s); zero for towers.
    pub emitter_vel_ecef_mps: Vector3<f64>,
    /// Corrected pseudorange (m).
    pub pseudorange_m: f64,
    /// 1-σ noise the estimator should assume for the pseudorange (m).
    pub sigma_m: f64,
    /// Corrected pseudorange rate (m/s), if the receiver measured one.
    pub range_rate_mps: Option<f64>,
    /// 1-σ noise the estimator should assume for the pseudorange rate (m/s).
    pub sigma_rate_mps: f64,
    /// Carrier-to-noise density (dB-Hz) the receiver reports.
    pub cn0_dbhz: f64,
    /// Elevation of the emitter seen from the receiver's true position (rad); informative.
    pub elevation_rad: f64,
}

impl RangeMeasurement {
    /// The system of the emitter, which selects the clock offset state.
    pub fn system(&self) -> System {
        self.emitter.system
    }
}

/// A position fix from another positioning method (FM fingerprinting, a magnetic
/// landmark): `L = r + ε`, `ε ~ N(0, R_f)` (seed 000 eqs. 18–19).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionFix {
    pub pos_ecef_m: Vector3<f64>,
    pub cov_m2: Matrix3<f64>,
    /// How many reference points (FM: the RPs inside the constraint circle) or matched
    /// landmark samples support the fix; 0 when the method has no such count. Mode
    /// selection reads it (seed 000 §3.3: the number of RPs is one of the fuzzy inputs).
    pub support: u32,
}

/// One step detected by pedestrian dead reckoning (seed 002 §4.2): its length and the
/// heading it was walked in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepEvent {
    /// Step length (m), e.g. from the Weinberg model.
    pub length_m: f64,
    /// 1-σ of the step length (m).
    pub sigma_length_m: f64,
    /// Heading of the step: azimuth in the world's ENU frame, clockwise from north (rad).
    pub heading_rad: f64,
    /// 1-σ of the heading (rad).
    pub sigma_heading_rad: f64,
}

/// A range difference to one emitter accumulated since a reference epoch (seed 002 §3.2:
/// the integral of the Doppler velocity measured from carrier-frequency offsets):
/// `Δr = ‖r_e − r(t)‖ − ‖r_e − r(t₀)‖ + ε`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeDifference {
    pub emitter: EmitterId,
    /// Emitter position (ECEF, m).
    pub emitter_pos_ecef_m: Vector3<f64>,
    /// Reference time t₀ of the accumulation.
    pub t0: GpsTime,
    /// Accumulated range difference (m).
    pub delta_range_m: f64,
    /// 1-σ noise (m).
    pub sigma_m: f64,
}

/// One measurement of any kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Measurement {
    Range(RangeMeasurement),
    Position(PositionFix),
    Step(StepEvent),
    /// One IMU output sample.
    Imu(ImuSample),
    RangeDifference(RangeDifference),
}

/// All measurements one source produced at one instant.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MeasurementBatch {
    /// Reception time (GPST, the receiver's true time; the clock offset is in the ranges).
    pub t: GpsTime,
    /// The kind of source that produced the batch.
    pub source: SourceKind,
    pub items: Vec<Measurement>,
    /// True for a batch the estimators process but the metrics do not score (all but the
    /// first of each second's IMU propagation batches), so that a fast source neither
    /// outweighs the 1 Hz sources in the statistics nor floods the per-epoch output.
    pub unscored: bool,
    /// The raw observations behind the batch, as a receiver logs them (dataset export).
    /// `None` unless a `BatchObserver` (the engine's) asked for them, so a Monte
    /// Carlo trial neither fills nor allocates it; estimators never read it.
    pub raw: Option<RawLog>,
}

impl MeasurementBatch {
    /// The range measurements in the batch.
    pub fn ranges(&self) -> impl Iterator<Item = &RangeMeasurement> {
        self.items.iter().filter_map(|m| match m {
            Measurement::Range(r) => Some(r),
            _ => None,
        })
    }
}

/// One IMU output sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Sample time (s since the trial start).
    pub t_s: f64,
    /// Measured angular rate ω̃_ib^b (rad/s).
    pub gyro_rps: Vector3<f64>,
    /// Measured specific force f̃^b (m/s²).
    pub accel_mps2: Vector3<f64>,
}
