//! The source side of the engine: the trait every sensor model implements, what it sees
//! when it samples, and the kinds of source estimators subscribe to.

use super::{Estimate, MeasurementBatch};
use crate::core::{GpsTime, SimTime};
use crate::motion::TruthState;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// The kinds of measurement source, the key of the engine's routing: an estimator
/// subscribes to kinds ([`super::Estimator::consumes`]) and every batch carries the kind
/// that produced it. World files name them in lowercase (`"gnss"`, `"fm"`).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum SourceKind {
    /// A GNSS receiver: pseudoranges and rates of GPS and BeiDou satellites (the batch a
    /// reused buffer holds before any source has filled it).
    #[default]
    Gnss,
    /// Seeds 001 and 003's abstract emitters: every system's ranges in one batch.
    Emitters,
    /// A DTMB receiver ranging on towers.
    Dtmb,
    /// Seed 004's TC-OFDM base stations.
    Tcofdm,
    /// FM fingerprinting: position fixes.
    Fm,
    /// Magnetic landmarks: position fixes.
    Magnetic,
    /// An IMU: raw gyro and accelerometer samples.
    Imu,
    /// Pedestrian dead reckoning: step events.
    Pdr,
}

impl SourceKind {
    /// The name world files and outputs use.
    pub const fn name(self) -> &'static str {
        match self {
            SourceKind::Gnss => "gnss",
            SourceKind::Emitters => "emitters",
            SourceKind::Dtmb => "dtmb",
            SourceKind::Tcofdm => "tcofdm",
            SourceKind::Fm => "fm",
            SourceKind::Magnetic => "magnetic",
            SourceKind::Imu => "imu",
            SourceKind::Pdr => "pdr",
        }
    }
}

impl std::fmt::Display for SourceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The platform's truth at one instant, in the world's ENU frame and in ECEF.
#[derive(Clone, Copy, Debug)]
pub struct Truth {
    pub sim: SimTime,
    pub t: GpsTime,
    pub enu: TruthState,
    pub pos_ecef_m: Vector3<f64>,
    pub vel_ecef_mps: Vector3<f64>,
}

/// What a source sees when it samples.
pub struct SampleContext<'a> {
    pub truth: &'a Truth,
    /// The latest estimate of every estimator, in the world's estimator order (`None`
    /// before an estimator's first estimate).
    pub estimates: &'a [Option<Estimate>],
}

/// A producer of measurements: a GNSS receiver, a DTMB receiver, an FM scanner, an IMU.
///
/// A source owns its random streams (taken from the trial's [`crate::core::TrialRng`] when
/// it is built), so its samples depend only on the trial and the stream names.
pub trait Source: Send {
    /// The kind of source; estimators subscribe by kind.
    fn kind(&self) -> SourceKind;
    /// The time of the first sample.
    fn first_sample(&self) -> SimTime;
    /// Produces the measurements at `ctx.truth.sim` into `out` (which arrives cleared) and
    /// returns when to sample next, or `None` when the source is finished.
    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime>;
    /// Whether a sample that produced no measurement is still an epoch the estimators see.
    ///
    /// For a receiver (GNSS, DTMB) it is: an epoch with every satellite blocked is an
    /// outage the estimators must predict through and the metrics must count. For a source
    /// that samples often and reports rarely (a step detector running at the IMU rate) it
    /// is not, and the default skips such samples.
    fn empty_batches_are_epochs(&self) -> bool {
        false
    }
    /// Warnings the source collected (a propagation model used outside its validity range,
    /// reported once per model): gathered after the trial and shown to the user.
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}
