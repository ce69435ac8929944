//! The fusion engine: measurement types, filters and the estimators a world lists.
//!
//! Depends only on `core` and its own measurement types, so every filter can be tested on
//! synthetic measurements.

pub mod ekf11;
pub mod estimator;
pub mod family;
pub mod kalman;
pub mod linear_kf;
pub mod mode;
pub mod models;
pub mod paper;
pub mod particle;
pub mod pcrlb;
pub mod preprocess;
pub mod selection;
pub mod wls;
