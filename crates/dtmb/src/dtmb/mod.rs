//! The DTMB (GB 20600-2006, TDS-OFDM) signal chain: PN frame headers, frame bodies, a
//! transmitter tied to GPS time, a multipath channel with exact fractional delays, a
//! frame-synchronising receiver and SigMF recording.
//!
//! ```text
//! pn (headers, phase schedule) ─┐
//! frame (SI, QAM, interleaver, IDFT) ─► transmitter (FrameSchedule, generate) ─► channel
//!     (paths, CFO/SFO, noise) ─► receiver (FFT correlation, first path, CFO) ─► pseudorange
//! sigmf: samples + frame annotations to BASE.sigmf-data / BASE.sigmf-meta
//! world_iq: a world's tower as its receiver hears it along the trajectory, for sigmf
//! measurement: the calibrated timing-error model (level = "measurement")
//! source: DtmbSource, the "dtmb" engine source at either level; tps: seed 002's
//!     TPS-CFO range differences; noise: the vectorised AWGN generator
//! ```
//!
//! The channel runs in the frequency domain (`fd_channel`, private) and is tested against
//! its time-domain reference [`Channel::process_exact`].
//!
//! Signal conventions: complex baseband `Complex<f32>` at 7.56 Msps; the frame body has
//! unit mean power and the header `ρ` (2 for PN420/PN945, 1 for PN595). SNR is the
//! nominal received frame power over the noise power in the 7.56 MHz band (one complex
//! sample's variance). The signal chain depends only on `core` and `io`; the measurement
//! source (`source`) also uses `engine`, `fusion::measurement`, `gnss::receiver_clock` and
//! `propagation`, as the GNSS source does.

pub mod bch;
pub mod ber;
pub mod ber_channel;
pub mod channel;
pub mod data_layer;
pub mod data_receiver;
mod fd_channel;
pub mod frame;
pub mod interleaver;
pub mod kernel;
pub mod ldpc;
mod ldpc_tables;
pub mod mapping;
pub mod measurement;
pub mod multipath;
/// The noise generator, shared with the GNSS recordings, lives in the core crate.
pub use crate::core::noise;
pub mod pn;
pub mod receiver;
pub mod scrambler;
pub mod service;
pub mod sigmf;
pub mod source;
pub mod system_info;
pub mod tps;
pub mod transmitter;
pub mod ts;

pub use channel::Channel;
pub use frame::{BodyModulator, CarrierMode, Qam};
pub use multipath::{link_snr_db, ChannelConfig, Path};
pub use pn::{PnMode, SAMPLE_RATE_HZ};
pub use receiver::{pseudorange_m, FirstPathConfig, Receiver, Search, SyncConfig, SyncResult};
pub use sigmf::{generate_iq, read_sigmf, write_sigmf, Annotation, SampleFormat, SigmfRecording};
pub use source::{DtmbLevel, DtmbSensorConfig, DtmbSource, TowerSpec};
pub use transmitter::{FrameSchedule, SampleSource, SrrcInterpolator, Transmitter, TxConfig};

use thiserror::Error;

/// Errors of the DTMB signal chain.
#[derive(Debug, Error)]
pub enum DtmbError {
    /// A PN mode name that is not one of the three.
    #[error("unknown DTMB PN mode {0:?}: valid names are PN420, PN595, PN945")]
    UnknownPnMode(String),
    /// A parameter outside its domain.
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// What was expected and what was given.
        reason: String,
    },
    /// A caller-owned buffer of the wrong length.
    #[error("{what} buffer has {got} samples, expected {expected}")]
    BufferLength {
        /// Which buffer.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// Too few samples to search.
    #[error("{what}: need at least {needed} samples, got {got}")]
    TooShort {
        /// What needed them.
        what: &'static str,
        /// Samples needed.
        needed: usize,
        /// Samples given.
        got: usize,
    },
    /// A UHF channel number outside the Chinese DS-13.. plan.
    #[error("UHF channel DS-{0} is not in the plan (DS-13 to DS-24 and DS-25 to DS-69)")]
    UnknownUhfChannel(u32),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A transport stream that is not 188-byte packets with sync bytes.
    #[error("{path}: {reason}")]
    Ts {
        /// The file.
        path: String,
        /// What is wrong, with the byte offset.
        reason: String,
    },
    /// A SigMF file that does not follow the subset this module reads.
    #[error("{path}: {reason}")]
    Sigmf {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

/// Centre frequency of Chinese UHF television channel DS-`n` (facts.md §1, UNCONFIRMED
/// plan): DS-13..DS-24 at `474 + 8(n − 13)` MHz, DS-25..DS-69 at `610 + 8(n − 25)` MHz.
///
/// # Errors
/// [`DtmbError::UnknownUhfChannel`] outside DS-13..DS-69.
pub fn uhf_channel_center_hz(n: u32) -> Result<f64, DtmbError> {
    match n {
        13..=24 => Ok((474.0 + 8.0 * f64::from(n - 13)) * 1e6),
        25..=69 => Ok((610.0 + 8.0 * f64::from(n - 25)) * 1e6),
        _ => Err(DtmbError::UnknownUhfChannel(n)),
    }
}

/// Whether two sample sequences are equal bit for bit: the tests that compare the
/// vectorised builds of the hot loops with their portable code, and the interpolating
/// channel receiver's check that a frame's header is the one it looked ahead at.
pub(crate) fn same_bits(a: &[num_complex::Complex32], b: &[num_complex::Complex32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.re.to_bits() == y.re.to_bits() && x.im.to_bits() == y.im.to_bits())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uhf_channel_plan() {
        assert_eq!(uhf_channel_center_hz(13).unwrap(), 474e6);
        assert_eq!(uhf_channel_center_hz(14).unwrap(), 482e6);
        assert_eq!(uhf_channel_center_hz(25).unwrap(), 610e6);
        assert!(uhf_channel_center_hz(12).is_err());
        assert!(uhf_channel_center_hz(70).is_err());
    }
}
