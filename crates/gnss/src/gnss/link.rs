//! Link budget and tracking-loop noise: from geometry to C/N0, and from C/N0 to the noise
//! of the pseudorange and of the pseudorange rate.
//!
//! # Carrier-to-noise density
//!
//! From first principles ([`cn0_dbhz`]), for a transmitter of known EIRP at range R:
//!
//! ```text
//! C/N0 = EIRP − FSPL(R, f) + G_r − 10 log10(k T_sys) − L          [dB-Hz]
//! FSPL = 20 log10(4π R f / c),   10 log10(k) = −228.6 dBW/(K·Hz)
//! ```
//!
//! For satellites the default ([`TrackingConfig::cn0_dbhz`]) starts from the minimum
//! received power the signal specifications guarantee at the user for elevations above 5°,
//! P_min, which is already the power into a 0 dBic RHCP antenna (IS-GPS-200 Table 3-Va gives
//! −158.5 dBW for L1 C/A into a 3 dBi *linearly* polarised antenna, i.e. 0 dBic for the RHCP
//! signal; BDS-SIS-ICD-B1I gives −163 dBW for B1I into a 0 dBi RHCP antenna). Real
//! satellites deliver more than the minimum, most at high elevation where the path is short,
//! so a margin that falls towards the horizon is added:
//!
//! ```text
//! P(el)  = P_min + m_sys − m_roll (1 − sin el)
//! G(el)  = G_zenith + (G_horizon − G_zenith)(1 − sin el)^k          (patch antenna)
//! C/N0   = P(el) + G(el) − 10 log10(k T_sys) − L_impl − L_extra
//! ```
//!
//! Defaults: m_GPS = 3 dB, m_BDS = 6 dB (BeiDou MEO/IGSO B1I arrives several dB above its
//! conservative −163 dBW specification), m_roll = 3 dB, G_zenith = +3 dBic,
//! G_horizon = −5 dBic, k = 1 (3 dB down at 40° elevation, as a typical ceramic patch),
//! T_sys = 290 K (N0 = −204.0 dBW/Hz) and L_impl = 3 dB of implementation, quantisation and
//! cable losses. That gives GPS L1 C/A 48.5 dB-Hz at zenith and 39.4 dB-Hz at 10°, BeiDou
//! B1I 47.0 and 37.9 dB-Hz: the usual open-sky figures of a mass-market receiver.
//! `extra_attenuation_db` subtracts a further loss from every satellite (foliage, a car
//! roof, a building wall).
//!
//! # Code tracking noise
//!
//! The thermal-noise jitter of a DLL with a (noncoherent) early-minus-late power
//! discriminator, correlator spacing d chips, loop bandwidth B_L and predetection
//! integration T (Kaplan & Hegarty, *Understanding GPS*, 2nd ed., §5.6.2; the second term is
//! the squaring loss of the noncoherent discriminator):
//!
//! ```text
//! σ_τ² = B_L d / (2 C/N0) · [1 + 2 / ((2 − d) T C/N0)]             [chips²]
//! ```
//!
//! multiplied by the chip length c/R_c (293.05 m for GPS C/A, 146.53 m for B1I).
//!
//! # Pseudorange-rate noise
//!
//! The frequency jitter of an FLL of noise bandwidth B_n (Kaplan & Hegarty §5.6.1, FLL
//! tracking loop measurement errors), with F = 1 at high C/N0 and 2 near threshold,
//! converted to a range rate with the carrier wavelength λ:
//!
//! ```text
//! σ_f = 1/(2πT) · √( 4 F B_n / (C/N0) · [1 + 1/(T C/N0)] )          [Hz]
//! σ_ρ̇ = λ σ_f                                                         [m/s]
//! ```
//!
//! # Loss of lock
//!
//! A channel whose C/N0 is below `lock_threshold_dbhz` (28 dB-Hz by default, the usual
//! tracking threshold of a mass-market receiver with 20 ms integration) produces no
//! measurement.

use crate::core::config::check_range;
use crate::core::{ConfigIssue, System, C_MPS};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// 10·log10 of Boltzmann's constant 1.380649e-23 J/K, in dBW/(K·Hz).
pub const BOLTZMANN_DBW_PER_K_HZ: f64 = -228.599_163_1;

/// A satellite signal the receiver tracks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Signal {
    /// GPS L1 C/A (IS-GPS-200).
    GpsL1Ca,
    /// BeiDou B1I (BDS-SIS-ICD-B1I).
    BdsB1i,
}

impl Signal {
    /// The signal a system's satellites are tracked on; `None` for terrestrial systems.
    pub fn of_system(sys: System) -> Option<Self> {
        match sys {
            System::Gps => Some(Signal::GpsL1Ca),
            System::Bds => Some(Signal::BdsB1i),
            System::Dtmb | System::Tcofdm => None,
        }
    }

    /// Carrier frequency (Hz).
    pub fn carrier_hz(self) -> f64 {
        match self {
            Signal::GpsL1Ca => 1_575.42e6,
            Signal::BdsB1i => 1_561.098e6,
        }
    }

    /// Carrier wavelength (m).
    pub fn wavelength_m(self) -> f64 {
        C_MPS / self.carrier_hz()
    }

    /// Code chipping rate (chips/s).
    pub fn chip_rate_hz(self) -> f64 {
        match self {
            Signal::GpsL1Ca => 1.023e6,
            Signal::BdsB1i => 2.046e6,
        }
    }

    /// Length of one code chip (m): 293.05 m for C/A, 146.53 m for B1I.
    pub fn chip_length_m(self) -> f64 {
        C_MPS / self.chip_rate_hz()
    }

    /// Minimum received power the specification guarantees above 5° elevation, into a
    /// 0 dBic RHCP antenna (dBW).
    pub fn min_received_power_dbw(self) -> f64 {
        match self {
            Signal::GpsL1Ca => -158.5,
            Signal::BdsB1i => -163.0,
        }
    }
}

/// Free-space path loss 20·log10(4πRf/c) (dB).
pub fn fspl_db(range_m: f64, freq_hz: f64) -> f64 {
    20.0 * (4.0 * PI * range_m * freq_hz / C_MPS).log10()
}

/// Thermal noise density 10·log10(k T) (dBW/Hz).
pub fn noise_density_dbw_per_hz(noise_temp_k: f64) -> f64 {
    BOLTZMANN_DBW_PER_K_HZ + 10.0 * noise_temp_k.log10()
}

/// C/N0 (dB-Hz) of a transmitter of `eirp_dbw` at `range_m` on `freq_hz`, received with
/// `rx_gain_dbi` by a system of noise temperature `noise_temp_k`, with `extra_loss_db` of
/// further losses: `EIRP − FSPL + G_r − 10 log10(k T_sys) − L`.
pub fn cn0_dbhz(
    eirp_dbw: f64,
    range_m: f64,
    freq_hz: f64,
    rx_gain_dbi: f64,
    noise_temp_k: f64,
    extra_loss_db: f64,
) -> f64 {
    eirp_dbw - fspl_db(range_m, freq_hz) + rx_gain_dbi
        - noise_density_dbw_per_hz(noise_temp_k)
        - extra_loss_db
}

/// Gain (dBic) of a patch antenna at elevation `el_rad`:
/// `G_zenith + (G_horizon − G_zenith)(1 − sin el)^k`, continuing below the horizon (the
/// elevation is clamped to ±90°).
pub fn patch_gain_dbic(
    el_rad: f64,
    gain_zenith_dbic: f64,
    gain_horizon_dbic: f64,
    exponent: f64,
) -> f64 {
    let el = el_rad.clamp(-FRAC_PI_2, FRAC_PI_2);
    gain_zenith_dbic + (gain_horizon_dbic - gain_zenith_dbic) * (1.0 - el.sin()).powf(exponent)
}

/// DLL thermal-noise jitter (chips, 1-σ) of an early-minus-late power discriminator:
/// `√(B_L d/(2 C/N0) · [1 + 2/((2 − d) T C/N0)])`.
pub fn dll_sigma_chips(
    cn0_dbhz: f64,
    loop_bandwidth_hz: f64,
    spacing_chips: f64,
    integration_s: f64,
) -> f64 {
    let c = 10f64.powf(cn0_dbhz / 10.0);
    let d = spacing_chips;
    (loop_bandwidth_hz * d / (2.0 * c) * (1.0 + 2.0 / ((2.0 - d) * integration_s * c))).sqrt()
}

/// FLL thermal-noise frequency jitter (Hz, 1-σ):
/// `1/(2πT) · √(4 F B_n/(C/N0) · [1 + 1/(T C/N0)])`.
pub fn fll_sigma_hz(
    cn0_dbhz: f64,
    loop_bandwidth_hz: f64,
    integration_s: f64,
    noise_factor: f64,
) -> f64 {
    let c = 10f64.powf(cn0_dbhz / 10.0);
    (4.0 * noise_factor * loop_bandwidth_hz / c * (1.0 + 1.0 / (integration_s * c))).sqrt()
        / (2.0 * PI * integration_s)
}

/// Tracking loops, antenna and link budget of a GNSS receiver (`[sensors.gnss.tracking]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingConfig {
    /// DLL noise bandwidth B_L (Hz); default 1. It sets the code's thermal noise and how
    /// much of a reflection whose Doppler differs from the direct path's reaches the code
    /// estimate (the loop's response |H(Δf)|, `gnss::multipath`).
    pub dll_bandwidth_hz: f64,
    /// Early-minus-late correlator spacing d (chips), within (0, 1]; default 1. This is
    /// the distance between E and L: a receiver that sets each correlator's offset from
    /// the prompt (GNSS-SDR's `early_late_space_chips`) has d = twice that offset.
    pub correlator_spacing_chips: f64,
    /// Predetection integration time T (s); default 0.02.
    pub integration_time_s: f64,
    /// FLL noise bandwidth B_n (Hz); default 2.
    pub fll_bandwidth_hz: f64,
    /// FLL noise factor F: 1 at high C/N0, 2 near threshold; default 1.
    pub fll_noise_factor: f64,
    /// Channels below this C/N0 (dB-Hz) lose lock and produce nothing; default 28.
    pub lock_threshold_dbhz: f64,
    /// Antenna gain at zenith (dBic); default +3.
    pub antenna_gain_zenith_dbic: f64,
    /// Antenna gain at the horizon (dBic); default −5.
    pub antenna_gain_horizon_dbic: f64,
    /// Exponent k of the gain pattern's (1 − sin el)^k roll-off; default 1.
    pub antenna_pattern_exponent: f64,
    /// System noise temperature T_sys (K); default 290.
    pub noise_temp_k: f64,
    /// Implementation, quantisation and cable losses (dB); default 3.
    pub implementation_loss_db: f64,
    /// Received GPS L1 C/A power above the −158.5 dBW specification at zenith (dB); default 3.
    pub gps_power_margin_db: f64,
    /// Received BeiDou B1I power above the −163 dBW specification at zenith (dB); default 6.
    pub bds_power_margin_db: f64,
    /// How much of the margin is lost towards the horizon, m_roll (dB); default 3.
    pub power_margin_rolloff_db: f64,
    /// Attenuation applied to every satellite (dB), e.g. foliage or a roof; default 0.
    pub extra_attenuation_db: f64,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            dll_bandwidth_hz: 1.0,
            correlator_spacing_chips: 1.0,
            integration_time_s: 0.02,
            fll_bandwidth_hz: 2.0,
            fll_noise_factor: 1.0,
            lock_threshold_dbhz: 28.0,
            antenna_gain_zenith_dbic: 3.0,
            antenna_gain_horizon_dbic: -5.0,
            antenna_pattern_exponent: 1.0,
            noise_temp_k: 290.0,
            implementation_loss_db: 3.0,
            gps_power_margin_db: 3.0,
            bds_power_margin_db: 6.0,
            power_margin_rolloff_db: 3.0,
            extra_attenuation_db: 0.0,
        }
    }
}

impl TrackingConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the field: non-finite values, non-positive bandwidths or
    /// integration times, a spacing outside (0, 1] chip, a loop too wide for its update rate
    /// (B·T > 0.5), or values outside physically sensible ranges.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check_range(
            "dll_bandwidth_hz",
            self.dll_bandwidth_hz,
            0.0,
            50.0,
            true,
            "a DLL bandwidth in Hz",
        )?;
        check_range(
            "correlator_spacing_chips",
            self.correlator_spacing_chips,
            0.0,
            1.0,
            true,
            "a correlator spacing in chips",
        )?;
        check_range(
            "integration_time_s",
            self.integration_time_s,
            0.0,
            1.0,
            true,
            "an integration time in s",
        )?;
        check_range(
            "fll_bandwidth_hz",
            self.fll_bandwidth_hz,
            0.0,
            50.0,
            true,
            "an FLL bandwidth in Hz",
        )?;
        check_range(
            "fll_noise_factor",
            self.fll_noise_factor,
            1.0,
            2.0,
            false,
            "an FLL noise factor",
        )?;
        for (key, b) in [
            ("dll_bandwidth_hz", self.dll_bandwidth_hz),
            ("fll_bandwidth_hz", self.fll_bandwidth_hz),
        ] {
            if b * self.integration_time_s > 0.5 {
                return Err(ConfigIssue::new(
                    key,
                    format!(
                        "{key} = {b} Hz with integration_time_s = {} s gives B·T = {:.3}; expected B·T ≤ 0.5 for a stable discrete loop",
                        self.integration_time_s,
                        b * self.integration_time_s
                    ),
                ));
            }
        }
        check_range(
            "lock_threshold_dbhz",
            self.lock_threshold_dbhz,
            0.0,
            60.0,
            false,
            "a C/N0 threshold in dB-Hz",
        )?;
        check_range(
            "antenna_gain_zenith_dbic",
            self.antenna_gain_zenith_dbic,
            -30.0,
            20.0,
            false,
            "an antenna gain in dBic",
        )?;
        check_range(
            "antenna_gain_horizon_dbic",
            self.antenna_gain_horizon_dbic,
            -40.0,
            20.0,
            false,
            "an antenna gain in dBic",
        )?;
        check_range(
            "antenna_pattern_exponent",
            self.antenna_pattern_exponent,
            0.0,
            10.0,
            true,
            "a pattern exponent",
        )?;
        check_range(
            "noise_temp_k",
            self.noise_temp_k,
            1.0,
            10_000.0,
            false,
            "a system noise temperature in K",
        )?;
        check_range(
            "implementation_loss_db",
            self.implementation_loss_db,
            0.0,
            30.0,
            false,
            "a loss in dB",
        )?;
        check_range(
            "gps_power_margin_db",
            self.gps_power_margin_db,
            -20.0,
            20.0,
            false,
            "a power margin in dB",
        )?;
        check_range(
            "bds_power_margin_db",
            self.bds_power_margin_db,
            -20.0,
            20.0,
            false,
            "a power margin in dB",
        )?;
        check_range(
            "power_margin_rolloff_db",
            self.power_margin_rolloff_db,
            0.0,
            20.0,
            false,
            "a margin roll-off in dB",
        )?;
        check_range(
            "extra_attenuation_db",
            self.extra_attenuation_db,
            0.0,
            100.0,
            false,
            "an attenuation in dB",
        )?;
        Ok(())
    }

    /// Receive antenna gain (dBic) at elevation `el_rad`.
    pub fn antenna_gain_dbic(&self, el_rad: f64) -> f64 {
        patch_gain_dbic(
            el_rad,
            self.antenna_gain_zenith_dbic,
            self.antenna_gain_horizon_dbic,
            self.antenna_pattern_exponent,
        )
    }

    /// Power (dBW) a 0 dBic RHCP antenna receives from a satellite of `system` at elevation
    /// `el_rad`: `P_min + m_sys − m_roll(1 − sin el)`; −∞ for terrestrial systems.
    pub fn received_power_dbw(&self, system: System, el_rad: f64) -> f64 {
        let Some(sig) = Signal::of_system(system) else {
            return f64::NEG_INFINITY;
        };
        let margin = match sig {
            Signal::GpsL1Ca => self.gps_power_margin_db,
            Signal::BdsB1i => self.bds_power_margin_db,
        };
        let el = el_rad.clamp(-FRAC_PI_2, FRAC_PI_2);
        sig.min_received_power_dbw() + margin - self.power_margin_rolloff_db * (1.0 - el.sin())
    }

    /// C/N0 (dB-Hz) of a satellite of `system` at elevation `el_rad`; −∞ for terrestrial
    /// systems, whose link budgets come from [`cn0_dbhz`] with their transmitters' EIRP.
    pub fn cn0_dbhz(&self, system: System, el_rad: f64) -> f64 {
        self.received_power_dbw(system, el_rad) + self.antenna_gain_dbic(el_rad)
            - noise_density_dbw_per_hz(self.noise_temp_k)
            - self.implementation_loss_db
            - self.extra_attenuation_db
    }

    /// Whether a channel at `cn0_dbhz` keeps lock.
    pub fn in_lock(&self, cn0_dbhz: f64) -> bool {
        cn0_dbhz >= self.lock_threshold_dbhz
    }

    /// DLL jitter (chips, 1-σ) at `cn0_dbhz`.
    pub fn code_sigma_chips(&self, cn0_dbhz: f64) -> f64 {
        dll_sigma_chips(
            cn0_dbhz,
            self.dll_bandwidth_hz,
            self.correlator_spacing_chips,
            self.integration_time_s,
        )
    }

    /// Pseudorange thermal noise (m, 1-σ) of `system` at `cn0_dbhz`; +∞ for terrestrial
    /// systems (their receivers model their own tracking).
    pub fn code_sigma_m(&self, system: System, cn0_dbhz: f64) -> f64 {
        Signal::of_system(system).map_or(f64::INFINITY, |s| {
            self.code_sigma_chips(cn0_dbhz) * s.chip_length_m()
        })
    }

    /// Pseudorange-rate thermal noise (m/s, 1-σ) of `system` at `cn0_dbhz`, from the FLL;
    /// +∞ for terrestrial systems.
    pub fn rate_sigma_mps(&self, system: System, cn0_dbhz: f64) -> f64 {
        Signal::of_system(system).map_or(f64::INFINITY, |s| {
            s.wavelength_m()
                * fll_sigma_hz(
                    cn0_dbhz,
                    self.fll_bandwidth_hz,
                    self.integration_time_s,
                    self.fll_noise_factor,
                )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signal_constants() {
        assert!((Signal::GpsL1Ca.chip_length_m() - 293.052_2).abs() < 1e-3);
        assert!((Signal::BdsB1i.chip_length_m() - 146.526_1).abs() < 1e-3);
        assert!((Signal::GpsL1Ca.wavelength_m() - 0.190_293_7).abs() < 1e-6);
        assert_eq!(Signal::of_system(System::Dtmb), None);
    }

    #[test]
    fn dll_hand_value() {
        // C/N0 = 45 dB-Hz = 31622.78 Hz, d = 1, B_L = 1 Hz, T = 20 ms:
        // σ² = 1/(2·31622.78) · (1 + 2/(0.02·31622.78)) = 1.58114e-5 · 1.0031623 = 1.58614e-5
        // σ = 3.98264e-3 chip = 1.16712 m.
        let cfg = TrackingConfig::default();
        let chips = cfg.code_sigma_chips(45.0);
        assert!((chips - 3.982_64e-3).abs() < 1e-8, "{chips}");
        let m = cfg.code_sigma_m(System::Gps, 45.0);
        assert!((m - 1.167_12).abs() < 1e-4, "{m}");
        // B1I chips are half as long.
        assert!((cfg.code_sigma_m(System::Bds, 45.0) - m / 2.0).abs() < 1e-12);
    }

    #[test]
    fn fll_hand_value() {
        // 4·1·2/31622.78 = 2.52982e-4; ×(1 + 1/632.456) = 2.53382e-4; √ = 1.59180e-2;
        // /(2π·0.02) = 0.126670 Hz; ×λ_L1 0.1902937 m = 0.0241045 m/s.
        let cfg = TrackingConfig::default();
        let hz = fll_sigma_hz(45.0, 2.0, 0.02, 1.0);
        assert!((hz - 0.126_670).abs() < 1e-5, "{hz}");
        let v = cfg.rate_sigma_mps(System::Gps, 45.0);
        assert!((v - 0.024_104_5).abs() < 1e-6, "{v}");
    }

    #[test]
    fn noise_falls_with_cn0() {
        let cfg = TrackingConfig::default();
        let mut last = (f64::INFINITY, f64::INFINITY);
        for i in 0..=40 {
            let cn0 = 20.0 + i as f64;
            let now = (
                cfg.code_sigma_m(System::Gps, cn0),
                cfg.rate_sigma_mps(System::Bds, cn0),
            );
            assert!(now.0 < last.0 && now.1 < last.1, "at {cn0} dB-Hz");
            last = now;
        }
    }

    #[test]
    fn link_budget_hand_values() {
        // FSPL at 20 200 km on L1: 20 log10(4π · 2.02e7 · 1.57542e9 / c) = 182.49 dB.
        assert!((fspl_db(2.02e7, 1_575.42e6) - 182.494).abs() < 1e-2);
        assert!((noise_density_dbw_per_hz(290.0) - (-203.975)).abs() < 1e-3);
        // EIRP 26.8 dBW at 20 200 km, 3 dBic, 290 K, 3 dB loss: 26.8 − 182.494 + 3 + 203.975 − 3.
        let c = cn0_dbhz(26.8, 2.02e7, 1_575.42e6, 3.0, 290.0, 3.0);
        assert!((c - 48.281).abs() < 1e-2, "{c}");
    }

    #[test]
    fn typical_cn0_by_elevation() {
        let cfg = TrackingConfig::default();
        let z = cfg.cn0_dbhz(System::Gps, FRAC_PI_2);
        let ten = cfg.cn0_dbhz(System::Gps, 10f64.to_radians());
        assert!((45.0..=50.0).contains(&z), "zenith {z}");
        assert!((35.0..=40.0).contains(&ten), "10° {ten}");
        assert!((z - 48.475).abs() < 1e-2);
        let zb = cfg.cn0_dbhz(System::Bds, FRAC_PI_2);
        let tb = cfg.cn0_dbhz(System::Bds, 10f64.to_radians());
        assert!(
            (45.0..=50.0).contains(&zb) && (35.0..=40.0).contains(&tb),
            "{zb} {tb}"
        );
        // Monotonic in elevation; below the threshold nothing is tracked.
        let mut last = f64::NEG_INFINITY;
        for d in 0..=90 {
            let c = cfg.cn0_dbhz(System::Gps, (d as f64).to_radians());
            assert!(c > last);
            last = c;
        }
        assert!(!cfg.in_lock(27.9) && cfg.in_lock(28.0));
        let shaded = TrackingConfig {
            extra_attenuation_db: 25.0,
            ..TrackingConfig::default()
        };
        assert!(!shaded.in_lock(shaded.cn0_dbhz(System::Gps, 0.3)));
        assert_eq!(cfg.cn0_dbhz(System::Dtmb, 1.0), f64::NEG_INFINITY);
        assert_eq!(cfg.code_sigma_m(System::Tcofdm, 40.0), f64::INFINITY);
    }

    #[test]
    fn validation_names_keys() {
        assert!(TrackingConfig::default().validate().is_ok());
        let key = |c: TrackingConfig| c.validate().unwrap_err().key;
        assert_eq!(
            key(TrackingConfig {
                dll_bandwidth_hz: 0.0,
                ..Default::default()
            }),
            "dll_bandwidth_hz"
        );
        assert_eq!(
            key(TrackingConfig {
                correlator_spacing_chips: 1.5,
                ..Default::default()
            }),
            "correlator_spacing_chips"
        );
        assert_eq!(
            key(TrackingConfig {
                integration_time_s: f64::NAN,
                ..Default::default()
            }),
            "integration_time_s"
        );
        assert_eq!(
            key(TrackingConfig {
                fll_bandwidth_hz: 40.0,
                ..Default::default()
            }),
            "fll_bandwidth_hz"
        );
        assert_eq!(
            key(TrackingConfig {
                lock_threshold_dbhz: -1.0,
                ..Default::default()
            }),
            "lock_threshold_dbhz"
        );
        assert_eq!(
            key(TrackingConfig {
                noise_temp_k: 0.0,
                ..Default::default()
            }),
            "noise_temp_k"
        );
        let parsed: TrackingConfig =
            toml::from_str("dll_bandwidth_hz = 0.5\nlock_threshold_dbhz = 30\n").unwrap();
        assert_eq!(parsed.dll_bandwidth_hz, 0.5);
        assert_eq!(parsed.integration_time_s, 0.02);
        assert!(toml::from_str::<TrackingConfig>("dll_bw = 0.5").is_err());
    }
}
