//! Raw GNSS observables as a receiver logs them (RINEX 3 observation records), kept beside
//! the corrected ranges the estimators read.

use crate::core::EmitterId;

/// One satellite's raw observables at one epoch (RINEX 3.04 §5.1: code, phase, Doppler,
/// signal strength on GPS L1 C/A = `C1C L1C D1C S1C`, BeiDou B1I = `C2I L2I D2I S2I`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawGnssObservation {
    pub sat: EmitterId,
    /// Pseudorange as measured: geometric range plus the receiver and satellite clock
    /// offsets, the atmospheric delays and the errors, before any correction (m).
    pub pseudorange_m: f64,
    /// Accumulated carrier phase (cycles).
    pub carrier_phase_cycles: f64,
    /// Doppler (Hz), positive for an approaching satellite.
    pub doppler_hz: f64,
    /// Carrier-to-noise density (dB-Hz).
    pub cn0_dbhz: f64,
    /// Loss of lock since the previous epoch (RINEX LLI bit 0).
    pub lock_lost: bool,
    /// The receiver clock offset δt_r at this epoch (s; without the inter-system bias):
    /// the time tag of a real receiver is its clock's reading, GPST + δt_r.
    pub rx_clock_s: f64,
}
