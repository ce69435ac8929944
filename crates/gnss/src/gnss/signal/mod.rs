//! GNSS at signal level: the satellites of a world as baseband IQ a software receiver can
//! acquire, track, decode and position from (`hybridnav gnss iq`).
//!
//! - [`ca_code`]: GPS L1 C/A Gold codes (IS-GPS-200 §3.3.2.3).
//! - [`lnav`]: the GPS LNAV message (subframes 1–5 with the 25-page almanac rotation,
//!   TLM/HOW, parity; IS-GPS-200 §20.3).
//! - [`b1i`]: BeiDou B1I ranging codes; [`d1d2`]: the D1 message with its NH code (MEO/IGSO;
//!   almanac, health and time pages in subframes 4–5) and the 500 bit/s D2 message (GEO),
//!   both with BCH(15,11), interleaving and the BDS Klobuchar set of the RINEX header.
//! - [`almanac`]: the almanacs both messages carry, derived from the world's ephemerides.
//! - [`baseband`]: replicas, noise, AGC and quantisation; the sample formats.
//! - [`scenario`]: a world's geometry per epoch (the measurement level's orbits, clocks,
//!   atmosphere, Sagnac and the scene's paths) turned into replicas and streamed.

pub mod almanac;
pub mod b1i;
pub mod baseband;
pub mod ca_code;
pub mod d1d2;
pub mod lnav;
pub mod scenario;

/// `x/scale` rounded to a `width`-bit two's complement field, saturated at its range (the
/// navigation messages' signed fields).
pub(crate) fn signed_raw(x: f64, scale: f64, width: usize) -> u64 {
    let half = 1i64 << (width - 1);
    let v = ((x / scale).round() as i64).clamp(-half, half - 1);
    v as u64 & ((1u64 << width) - 1)
}

/// `x/scale` rounded to a `width`-bit unsigned field, saturated at its range.
pub(crate) fn unsigned_raw(x: f64, scale: f64, width: usize) -> u64 {
    ((x / scale).round().max(0.0) as u64).min((1u64 << width) - 1)
}

/// Why a recording cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum SignalError {
    /// A request the world cannot satisfy, named by the option at fault.
    #[error("{what}: {reason}")]
    InvalidRequest { what: &'static str, reason: String },
    /// Writing an output failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}
