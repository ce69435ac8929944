//! FM broadcast fingerprinting (seed 000, Cong et al., Sensors 2018, §3.2 and §4.1).
//!
//! The offline stage surveys the received signal strength (RSSI) of FM stations at
//! reference points (RPs), interpolates the survey onto a dense grid by ordinary kriging
//! and stores the result as a fingerprint database. The online stage measures the RSSI
//! at the receiver and locates it by weighted K-nearest neighbours (WKNN) in signal space
//! among the RPs inside seed 000's GPS-constraint circle, producing a position fix for
//! the EKF (`R_f`, seed 000 eqs. 18–19).
//!
//! - [`field`]: stations and the RSSI field (Extended Hata, scene losses, shadowing,
//!   receiver noise, quantisation, sensitivity).
//! - [`survey`]: RP layouts (grid, polyline) and the surveyor's averaged scans.
//! - [`kriging`]: empirical semivariogram, spherical/exponential fits, ordinary kriging.
//! - [`database`]: the fingerprint database and its JSON file.
//! - [`wknn`]: the online WKNN search with the constraint circle.
//! - [`source`]: `FmSource`, the `"fm"` measurement source.

pub mod database;
pub mod field;
pub mod kriging;
pub mod source;
pub mod survey;
pub mod wknn;

pub use database::{FingerprintDb, WorldTag};
pub use field::{FmField, FmFieldConfig, FmStation};
pub use kriging::{OrdinaryKriging, VariogramFit, VariogramKind, VariogramModel};
pub use source::{FmSensorConfig, FmSource};
pub use survey::{grid_points, grid_points_en, polyline_points, SurveyConfig};
pub use wknn::{
    Constraint, ConstraintConfig, NoRpPolicy, Weighting, WknnConfig, WknnFix, WknnScratch,
};

/// Errors of the FM module. Each message says what was expected.
#[derive(Debug, thiserror::Error)]
pub enum FmError {
    /// A configuration value is out of range (key, message).
    #[error("{}: {}", .0.key, .0.message)]
    Config(crate::core::ConfigIssue),
    /// Reading or writing a database file failed.
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    /// The database was built for another world.
    #[error("fingerprint database {path} was built for world {found}, but this world is {expected}; rebuild the database for this world")]
    WorldMismatch {
        path: String,
        expected: String,
        found: String,
    },
    /// The input data are inconsistent (sizes, non-finite values, duplicates).
    #[error("{0}")]
    Data(String),
    /// No RP shares enough channels with the measurement.
    #[error("no reference point shares at least {min_common} channels with the measurement ({measured} channels measured)")]
    NoComparableRp { min_common: usize, measured: usize },
    /// No RP lies inside the constraint circle and the policy is `error`.
    #[error("no reference point inside the constraint circle of radius {radius_m:.1} m around ({east_m:.1}, {north_m:.1}) m ENU")]
    NoRpInCircle {
        east_m: f64,
        north_m: f64,
        radius_m: f64,
    },
}

impl From<crate::core::ConfigIssue> for FmError {
    fn from(c: crate::core::ConfigIssue) -> Self {
        FmError::Config(c)
    }
}
