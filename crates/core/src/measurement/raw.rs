//! Raw observations as receivers log them (RINEX 3 observables, FM RSSI, magnetometer
//! samples), kept beside the corrected measurements the estimators read.

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

/// Raw observations a source logs beside its measurements when asked (see
/// [`super::MeasurementBatch::raw`]).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct RawLog {
    /// GNSS code, phase, Doppler and C/N0 per tracked satellite (RINEX observables).
    pub gnss: Vec<RawGnssObservation>,
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
