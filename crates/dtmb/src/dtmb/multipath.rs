//! What a DTMB channel is: its propagation paths, the carrier and sampling-frequency
//! offsets, and the SNR, with the link budget that gives the SNR. Both channel engines
//! ([`super::channel`], `fd_channel`) take this description.

use num_complex::Complex64;

/// One propagation path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Path {
    /// Propagation delay in seconds (may include tower and receiver clock offsets).
    pub delay_s: f64,
    /// Complex amplitude gain.
    pub gain: Complex64,
    /// Doppler shift of this path in hertz.
    pub doppler_hz: f64,
    /// How fast the delay grows (s/s, the path's range rate over c): the delay at receiver
    /// time `t` (from receiver sample 0) is `delay_s + delay_rate · t`. A receiver moving
    /// at range rate `ṙ` along a path at carrier `f_c` sees `delay_rate = ṙ/c =
    /// −doppler_hz/f_c`. 0 holds the delay (a channel whose paths are replaced between
    /// calls, or a static one).
    pub delay_rate: f64,
}

/// The largest `|delay_rate|` a channel takes: 10⁻⁵, a range rate of 3 km/s, far above any
/// terrestrial receiver's (a 350 km/h train: 3.2·10⁻⁷).
pub const MAX_DELAY_RATE: f64 = 1e-5;

impl Path {
    /// A path from amplitude and phase, its delay held.
    pub fn new(delay_s: f64, amplitude: f64, phase_rad: f64, doppler_hz: f64) -> Self {
        Self {
            delay_s,
            gain: Complex64::from_polar(amplitude, phase_rad),
            doppler_hz,
            delay_rate: 0.0,
        }
    }

    /// The same path with its delay growing at `delay_rate` (s/s).
    pub fn with_delay_rate(self, delay_rate: f64) -> Self {
        Self { delay_rate, ..self }
    }
}

/// Channel configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelConfig {
    /// The paths (at least one).
    pub paths: Vec<Path>,
    /// Carrier frequency offset in hertz, common to all paths.
    pub cfo_hz: f64,
    /// Receiver sampling-frequency offset in parts per million.
    pub sfo_ppm: f64,
    /// SNR over the 7.56 MHz band in dB; `None` for a noiseless channel.
    pub snr_db: Option<f64>,
}

/// The largest receiver oscillator error accepted anywhere a receiver's oscillator is
/// given (ppm): the world key `sensors.dtmb.rx_oscillator_ppm`, `dtmb iq` and `dtmb ber`.
/// A crystal without temperature compensation is specified to some tens of ppm. The
/// acquiring receivers (`dtmb ber`'s and the world's DTMB source's) search the carrier
/// offset `−ε f_c` over `±max(12 kHz, 1.25 |ε| f_c)`
/// ([`super::receiver::acquisition_cfo_search_hz`]), capped at the sync's largest search,
/// ±100 kHz ([`super::receiver::MAX_CFO_SEARCH_HZ`]): 100 ppm at the UHF band's top
/// (862 MHz) is an 86 kHz offset, still inside it, while a larger error could fall
/// outside.
pub const MAX_RX_OSCILLATOR_PPM: f64 = 100.0;

/// Whether `ppm` is a receiver oscillator error those accept: finite and within
/// ±[`MAX_RX_OSCILLATOR_PPM`].
pub fn rx_oscillator_ppm_valid(ppm: f64) -> bool {
    ppm.is_finite() && ppm.abs() <= MAX_RX_OSCILLATOR_PPM
}

impl ChannelConfig {
    /// A configuration whose CFO and SFO come from the oscillators: the receiver derives
    /// its local oscillator and sample clock from one reference (as SDRs do), so a
    /// fractional frequency error `e_rx` and a transmitter error `e_tx` give
    /// `Δf = (e_tx − e_rx) f_c` and `ε = e_rx`.
    pub fn from_oscillators(
        paths: Vec<Path>,
        tx_ppm: f64,
        rx_ppm: f64,
        carrier_hz: f64,
        snr_db: Option<f64>,
    ) -> Self {
        Self {
            paths,
            cfo_hz: (tx_ppm - rx_ppm) * 1e-6 * carrier_hz,
            sfo_ppm: rx_ppm,
            snr_db,
        }
    }
}

/// Link SNR over `bandwidth_hz` from the budget: `EIRP + G_rx − L − (kTB + NF)` with
/// `kT = 1.380649e-23 · 290` W/Hz (−203.98 dBW/Hz). DTMB's band is 7.56 MHz. The first
/// argument is the e.i.r.p. plus the receive antenna gain (dBW); `L` is a loss between
/// isotropic antennas (free space, Extended Hata). A transmitter's ERP becomes an EIRP
/// through [`crate::propagation::pathloss::eirp_dbw_from_erp`] (+2.15 dB).
pub fn link_snr_db(
    eirp_plus_rx_gain_dbw: f64,
    path_loss_db: f64,
    noise_figure_db: f64,
    bandwidth_hz: f64,
) -> f64 {
    let ktb_dbw = 10.0 * (1.380_649e-23 * 290.0 * bandwidth_hz).log10();
    eirp_plus_rx_gain_dbw - path_loss_db - ktb_dbw - noise_figure_db
}
