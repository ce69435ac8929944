//! The discrete-event engine: one trial, on one thread.
//!
//! Sources schedule their own samples; each sample produces a [`MeasurementBatch`] that
//! every estimator consuming that source processes at once; each estimator's latest
//! estimate is then visible to every source at its next event (the closed loop: DTMB search
//! windows, FM reference-point circles and clock corrections use it in later issues).

pub mod cache;
pub mod queue;
pub mod trial;

use crate::core::{GpsTime, SimTime};
use crate::fusion::estimator::Estimate;
use crate::fusion::measurement::MeasurementBatch;
use crate::motion::TruthState;
use nalgebra::Vector3;

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
    /// Stable name (`"gnss"`, `"dtmb"`); estimators select sources by it.
    fn name(&self) -> &str;
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
