//! The discrete-event engine: one trial, on one thread.
//!
//! Sources schedule their own samples; each sample produces a [`crate::measurement::MeasurementBatch`] that
//! every estimator consuming that source processes at once; each estimator's latest
//! estimate is then visible to every source at its next event (the closed loop: DTMB search
//! windows, FM reference-point circles and clock corrections use it in later issues).

pub mod cache;
pub mod health;
pub mod queue;
pub mod trial;
