//! Foundations every other module builds on: time scales, WGS-84 geodesy and named
//! random streams. Nothing here knows about signals, scenes or estimators.

pub mod config;
pub mod geodesy;
pub mod ids;
pub mod noise;
pub mod receiver_clock;
pub mod rng;
pub mod stats;
pub mod time;

pub use config::ConfigIssue;
pub use geodesy::{azimuth_elevation, EnuFrame, Geodetic, C_MPS};
pub use ids::{EmitterId, System};
pub use rng::{StreamRng, TrialRng};
pub use time::{GpsTime, SimTime};
