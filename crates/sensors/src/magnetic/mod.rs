//! Magnetic-field landmarks (seed 002, §2 and §4.1): the Earth's main field, ferromagnetic
//! anomalies placed in the world, the field-magnitude sequence a phone's magnetometer
//! records along a walk, and the detection of landmarks in that sequence by dynamic time
//! warping (the baseline) and by a spiking neural network (Tempotron neurons), with the
//! selection of candidates by their consistency with a DTMB range.
//!
//! * [`earth`] — the IGRF-14 main field (degrees 1–13, [`igrf14_coeffs`]) and its tilted
//!   centred dipole, with secular variation: B in ENU, declination, inclination, total
//!   intensity.
//! * [`anomaly`] — point magnetic dipoles (B = μ0/4π · (3(m·r̂)r̂ − m)/r³) with a serde
//!   configuration, the [`anomaly::MagneticScene`] (Earth + Σ anomalies) and the sampling of
//!   a magnetometer along a [`crate::inertial::attitude::PlatformTruth`].
//! * [`landmark`] — smoothing, peak/valley windows with a change-rate threshold, the mapping
//!   of a window to a fixed-size image, DTW with caller-owned scratch, the DTW landmark
//!   library and the DTMB-ranging consistency check | ‖P_i − P_base‖ − r_dtmb | < δr.
//! * [`snn`] — the LIF kernel K(t) = V0(e^(−t/τ) − e^(−t/τs)), phase encoding of an image
//!   into spike times, the Tempotron (Gütig & Sompolinsky 2006) and a one-neuron-per-class
//!   classifier.
//!
//! Units are in the names: `_nt` and `_ut` for nano- and microtesla, `_am2` for magnetic
//! moments in A·m², `_m` for metres.

pub mod anomaly;
pub mod earth;
pub mod igrf14_coeffs;
pub mod landmark;
pub mod snn;
pub mod source;

pub use anomaly::{DipoleAnomaly, MagneticAnomalyConfig, MagneticScene, MagneticWalk};
pub use earth::EarthField;
pub use landmark::{
    dtw_distance, DtwLibrary, DtwScratch, LandmarkDetectorConfig, LandmarkFeature, LandmarkWindow,
};
pub use snn::{SnnClassifier, SnnConfig, SnnEncoding, Tempotron};

use crate::core::ConfigIssue;

/// What went wrong in the magnetic module: a bad configuration value (with its key) or an
/// input that cannot be processed (an empty sequence, a window longer than the sequence).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MagneticError {
    /// A configuration value out of range, with the key that holds it.
    #[error("{0}")]
    Config(#[from] ConfigIssue),
    /// An input that cannot be used, with what was expected.
    #[error("{0}")]
    Input(String),
}

/// The vacuum permeability over 4π expressed for the dipole formula in nanotesla:
/// μ0/4π = 1e-7 T·m/A = 100 nT·m³/(A·m²).
pub const MU0_OVER_4PI_NT_M3_PER_AM2: f64 = 100.0;
