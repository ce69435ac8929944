//! Measurement types every estimator consumes.
//!
//! A measurement carries everything an estimator needs to use it (the emitter's position
//! and velocity as the receiver computes them, the noise it should assume) and nothing of
//! the truth. Sources produce them; the engine hands each batch to every estimator.

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
    /// One IMU output sample ([`crate::inertial::imu::ImuSample`]).
    Imu(crate::inertial::imu::ImuSample),
    RangeDifference(RangeDifference),
}

/// All measurements one source produced at one instant.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MeasurementBatch {
    /// Reception time (GPST, the receiver's true time; the clock offset is in the ranges).
    pub t: GpsTime,
    /// Name of the source that produced the batch (e.g. `"gnss"`).
    pub source: String,
    pub items: Vec<Measurement>,
    /// True for a batch the estimators process but the metrics do not score (all but the
    /// first of each second's IMU propagation batches), so that a fast source neither
    /// outweighs the 1 Hz sources in the statistics nor floods the per-epoch output.
    pub unscored: bool,
    /// The raw observations behind the batch, as a receiver logs them (dataset export).
    /// `None` unless a [`crate::engine::trial::BatchObserver`] asked for them, so a Monte
    /// Carlo trial neither fills nor allocates it; estimators never read it.
    pub raw: Option<RawLog>,
}

/// Raw observations a source logs beside its measurements when asked (see
/// [`MeasurementBatch::raw`]).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct RawLog {
    /// GNSS code, phase, Doppler and C/N0 per tracked satellite (RINEX observables).
    pub gnss: Vec<crate::gnss::raw::RawGnssObservation>,
    /// FM scan: (carrier frequency in MHz, RSSI in dBm) per scanned station.
    pub fm_rssi: Vec<(f64, f64)>,
    /// Magnetometer samples (each with its own time and true position: the magnetic
    /// source logs the samples since its previous batch).
    pub mag: Vec<MagSample>,
}

/// One magnetometer sample as logged for a dataset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MagSample {
    /// Seconds since the trial start.
    pub t_s: f64,
    /// Body-frame reading (µT).
    pub b_body_ut: [f64; 3],
    /// True position (ENU, m).
    pub true_pos_enu_m: [f64; 3],
}

impl RawLog {
    /// Empties every list, keeping the capacity.
    pub fn clear(&mut self) {
        self.gnss.clear();
        self.fm_rssi.clear();
        self.mag.clear();
    }
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
