//! The estimator side of the engine: the trait every filter implements, its estimate and
//! what it did with one batch.

use super::{MeasurementBatch, SourceKind};
use crate::core::GpsTime;
use nalgebra::{Matrix3, Vector3};

/// An estimator's output at one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    pub t: GpsTime,
    pub pos_ecef_m: Vector3<f64>,
    pub vel_ecef_mps: Option<Vector3<f64>>,
    /// Position covariance (ECEF, m²).
    pub cov_pos_m2: Matrix3<f64>,
}

/// What one estimator did with one batch.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct EpochOutcome {
    /// The estimate after the batch, if the estimator has one.
    pub estimate: Option<Estimate>,
    /// Measurements used.
    pub used: u32,
    /// Of `used`, the inputs that drove the state's propagation (an INS's IMU samples)
    /// rather than updated it: no gate ever sees them, so the divergence watch leaves them
    /// out of the measurements offered ([`crate::engine::health`]).
    pub inputs: u32,
    /// Measurements rejected (gate, numerical failure).
    pub rejected: u32,
    /// GDOP of the measurements used, when the estimator computed one.
    pub gdop: Option<f64>,
    /// True when the estimator detected a numerical failure and reset or refused the epoch.
    pub numerical_failure: bool,
    /// Sum of the normalised innovations squared νᵀS⁻¹ν of the updates used this epoch
    /// (with `nis_count`, their mean: about the measurement dimension when consistent).
    pub nis_sum: f64,
    pub nis_count: u32,
    /// The summed dimensions of the updates in `nis_sum`: its expectation for a
    /// consistent filter, and the degrees of freedom of its χ² distribution.
    pub nis_dof: u32,
    /// Of `rejected`, how many an innovation gate refused as outliers (the rest were
    /// refused for invalid input or a numerical failure).
    pub rejected_gate: u32,
    /// Of `rejected_gate`, those refused while the filter's own variance along the
    /// measurement, `H P Hᵀ`, was at least the measurement's `R`: the gate then trusted
    /// the less certain of the two. The divergence watch counts only these towards a
    /// persistently gated filter ([`crate::engine::health`]).
    pub rejected_gate_state_led: u32,
    /// The integration mode chosen this epoch, for estimators that select one.
    pub mode: Option<&'static str>,
    /// The NIS above goes to the records only, not to the divergence watch's χ² test:
    /// set by the filters compared as their papers run them (seed 004's INS filters have
    /// no divergence detection). Gated epochs still count.
    pub nis_unwatched: bool,
}

impl EpochOutcome {
    /// Adds one accepted update's normalised innovation squared, of `dof` components, to
    /// the epoch's NIS record; a non-finite NIS is left out. Returns whether it was added.
    pub fn record_nis(&mut self, nis: f64, dof: u32) -> bool {
        if !nis.is_finite() {
            return false;
        }
        self.nis_sum += nis;
        self.nis_count += 1;
        self.nis_dof += dof;
        true
    }
}

/// An estimator the engine drives: it consumes batches from the sources it names and
/// keeps its own latest estimate.
pub trait Estimator: Send {
    /// The name the world gives it (the row name in the papers' tables).
    fn name(&self) -> &str;
    /// True when it consumes batches of the given kind of source. Asked once per source
    /// when the trial is built: the answer must not change during a trial.
    fn consumes(&self, source: SourceKind) -> bool;
    /// Processes one batch (predicting to its time first).
    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome;
    /// The latest estimate.
    fn latest(&self) -> Option<Estimate>;
    /// Forgets a diverged state, after the engine's divergence watch
    /// (the engine's health monitor) caught it: the estimator re-initialises as at its start
    /// (from the next fix, or from its prior around its last finite estimate) and reports
    /// no estimate until then.
    fn reset(&mut self);
}
