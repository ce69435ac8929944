//! Atmospheric delays of GNSS signals: the broadcast Klobuchar ionosphere model and the
//! Saastamoinen troposphere model with a standard atmosphere.
//!
//! # Ionosphere (IS-GPS-200 §20.3.3.5.2.5)
//!
//! The single-frequency user algorithm, with angles in semicircles (E elevation, A azimuth,
//! φu/λu the user's geodetic latitude/longitude):
//!
//! ```text
//! ψ  = 0.0137 / (E + 0.11) − 0.022                 Earth-centred angle
//! φi = φu + ψ cos A,  clamped to ±0.416             ionospheric pierce point latitude
//! λi = λu + ψ sin A / cos φi                        pierce point longitude
//! φm = φi + 0.064 cos(λi − 1.617)                   geomagnetic latitude
//! t  = 43200 λi + tGPS  (mod 86400)                 local time (s)
//! F  = 1 + 16 (0.53 − E)³                           obliquity factor
//! AMP = Σ αn φmⁿ (≥ 0),  PER = Σ βn φmⁿ (≥ 72000)
//! x  = 2π (t − 50400) / PER
//! T  = F [5e-9 + AMP (1 − x²/2 + x⁴/24)]  if |x| < 1.57,  else F · 5e-9
//! ```
//!
//! The delay is `c · T` metres on L1. On another frequency f the first-order ionospheric
//! delay scales by (f_L1 / f)², so BeiDou B1I sees (1575.42 / 1561.098)² ≈ 1.0184 times
//! the L1 delay (the GPS broadcast coefficients are used for BeiDou here; the BeiDou
//! broadcast uses its own coefficients and a different 8-parameter variant).
//!
//! # Troposphere (Saastamoinen 1972, standard atmosphere as in RTKLIB `tropmodel`)
//!
//! ```text
//! P = 1013.25 (1 − 2.2557e-5 h)^5.2568           hPa
//! T = 15 − 6.5e-3 h + 273.16                     K
//! e = 6.108 · humi · exp((17.15 T − 4684) / (T − 38.45))   hPa (water vapour pressure)
//! z = π/2 − el
//! dry = 0.0022768 P / (1 − 0.00266 cos 2φ − 0.00028 h_km) / cos z
//! wet = 0.002277 (1255 / T + 0.05) e / cos z
//! ```

use crate::core::{GpsTime, C_MPS};
use std::f64::consts::PI;

/// GPS L1 carrier frequency (Hz), IS-GPS-200 §3.3.1.1.
pub const F_L1_HZ: f64 = 1_575.42e6;
/// BeiDou B1I carrier frequency (Hz), BDS-SIS-ICD-B1I-3.0 §4.2.
pub const F_B1I_HZ: f64 = 1_561.098e6;

/// The factor by which a first-order ionospheric delay computed for GPS L1 must be
/// multiplied to apply on a carrier of frequency `freq_hz`: the delay goes as 1/f², so the
/// factor is (f_L1 / f)².
pub fn iono_scale_from_l1(freq_hz: f64) -> f64 {
    let r = F_L1_HZ / freq_hz;
    r * r
}

/// The Klobuchar coefficients broadcast in the GPS navigation message (subframe 4 page
/// 18), as written in RINEX headers (`ION ALPHA`/`ION BETA` in RINEX 2,
/// `IONOSPHERIC CORR GPSA`/`GPSB` in RINEX 3).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Klobuchar {
    /// Amplitude coefficients α0..α3, in s, s/semicircle, s/semicircle², s/semicircle³.
    pub alpha: [f64; 4],
    /// Period coefficients β0..β3, in s, s/semicircle, s/semicircle², s/semicircle³.
    pub beta: [f64; 4],
}

impl Klobuchar {
    /// The ionospheric group delay (m) on GPS L1 for a user at geodetic latitude/longitude
    /// `lat_rad`/`lon_rad` seeing a satellite at azimuth `az_rad` and elevation `el_rad`, at
    /// GPS time `t`, per IS-GPS-200 §20.3.3.5.2.5 (equations in the module documentation).
    ///
    /// The model is defined for satellites above the horizon; for negative elevations the
    /// formulas still give a finite (night-time floor or larger) value, which is returned
    /// as is because the caller decides visibility.
    pub fn delay_l1_m(
        &self,
        lat_rad: f64,
        lon_rad: f64,
        az_rad: f64,
        el_rad: f64,
        t: GpsTime,
    ) -> f64 {
        // The algorithm works in semicircles (π rad), as the broadcast coefficients do.
        let e_sc = el_rad / PI;
        let phi_u = lat_rad / PI;
        let lam_u = lon_rad / PI;
        let psi = 0.0137 / (e_sc + 0.11) - 0.022;
        let phi_i = (phi_u + psi * az_rad.cos()).clamp(-0.416, 0.416);
        let lam_i = lam_u + psi * az_rad.sin() / (phi_i * PI).cos();
        let phi_m = phi_i + 0.064 * ((lam_i - 1.617) * PI).cos();
        let t_local_s = (43_200.0 * lam_i + t.tow_s()).rem_euclid(86_400.0);
        let f = 1.0 + 16.0 * (0.53 - e_sc).powi(3);
        let poly = |c: &[f64; 4]| c[0] + phi_m * (c[1] + phi_m * (c[2] + phi_m * c[3]));
        let amp_s = poly(&self.alpha).max(0.0);
        let per_s = poly(&self.beta).max(72_000.0);
        let x = 2.0 * PI * (t_local_s - 50_400.0) / per_s;
        let delay_s = if x.abs() < 1.57 {
            let x2 = x * x;
            f * (5e-9 + amp_s * (1.0 - x2 / 2.0 + x2 * x2 / 24.0))
        } else {
            f * 5e-9
        };
        C_MPS * delay_s
    }

    /// The same delay on BeiDou B1I (1561.098 MHz): the L1 delay times (f_L1 / f_B1I)².
    pub fn delay_b1i_m(
        &self,
        lat_rad: f64,
        lon_rad: f64,
        az_rad: f64,
        el_rad: f64,
        t: GpsTime,
    ) -> f64 {
        self.delay_l1_m(lat_rad, lon_rad, az_rad, el_rad, t) * iono_scale_from_l1(F_B1I_HZ)
    }
}

/// The slant tropospheric delay (m) from the Saastamoinen model with the standard
/// atmosphere (equations in the module documentation), for a receiver at geodetic latitude
/// `lat_rad` and ellipsoidal height `h_m`, a satellite at elevation `el_rad`, and relative
/// humidity `humidity` in 0..1 (clamped to that range).
///
/// Heights below the ellipsoid are treated as 0 m (the standard atmosphere is not defined
/// below sea level); above 10 km, at or below the horizon, or for non-finite inputs the
/// function returns 0, since the model is not meant for those cases.
pub fn saastamoinen_m(lat_rad: f64, h_m: f64, el_rad: f64, humidity: f64) -> f64 {
    // Comparisons with NaN are false, so NaN inputs fall out here too and never leak into
    // a pseudorange.
    let in_domain = el_rad > 0.0 && h_m <= 1.0e4 && lat_rad.is_finite();
    if !in_domain {
        return 0.0;
    }
    let h = h_m.max(0.0);
    let humi = if humidity.is_finite() {
        humidity.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let pressure_hpa = 1013.25 * (1.0 - 2.2557e-5 * h).powf(5.2568);
    let temp_k = 15.0 - 6.5e-3 * h + 273.16;
    let vapour_hpa = 6.108 * humi * ((17.15 * temp_k - 4684.0) / (temp_k - 38.45)).exp();
    let cos_z = (PI / 2.0 - el_rad).cos();
    let dry_m = 0.0022768 * pressure_hpa
        / (1.0 - 0.00266 * (2.0 * lat_rad).cos() - 0.00028 * h / 1e3)
        / cos_z;
    let wet_m = 0.002277 * (1255.0 / temp_k + 0.05) * vapour_hpa / cos_z;
    dry_m + wet_m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The brdc1820.10n (2010-07-01) coefficients.
    fn brdc_2010() -> Klobuchar {
        Klobuchar {
            alpha: [0.4657e-08, 0.1490e-07, -0.5960e-07, -0.1192e-06],
            beta: [0.8192e+05, 0.8192e+05, -0.6554e+05, -0.5243e+06],
        }
    }

    #[test]
    fn klobuchar_night_time_is_the_5ns_floor_times_obliquity() {
        // At the zenith E = 0.5 semicircles, so F = 1 + 16·0.03³ = 1.000432. At local time
        // 02:00 the cosine term is outside |x| < 1.57 and the delay is c·F·5 ns.
        let k = brdc_2010();
        let t = GpsTime::from_week_tow(1590, 345_600.0 + 2.0 * 3600.0);
        let d = k.delay_l1_m(0.0, 0.0, 0.0, PI / 2.0, t);
        let expected = C_MPS * (1.0 + 16.0 * 0.03f64.powi(3)) * 5e-9;
        assert!((d - expected).abs() < 1e-9, "{d} vs {expected}");
        assert!((d - 1.4996).abs() < 1e-3);
    }

    #[test]
    fn klobuchar_hand_computed_daytime_value() {
        // User at φ = 40° N, λ = 116° E, satellite at A = 0, E = 30°, 14:00 local time
        // computed step by step by hand:
        //   E = 1/6 sc; ψ = 0.0137/(0.27667) − 0.022 = 0.0275181;
        //   φi = 0.222222 + 0.0275181 = 0.249740; λi = 0.644444 (sin A = 0);
        //   φm = 0.249740 + 0.064 cos(π(0.644444 − 1.617)) = 0.249740 − 0.063762 = 0.185978;
        //   AMP = 4.657e-9 + 1.490e-8·φm − 5.96e-8·φm² − 1.192e-7·φm³ = 4.5999e-9 s;
        //   PER = 81920 + 81920 φm − 65540 φm² − 524300 φm³ = 91515.8 s;
        //   tGPS chosen so that t = 43200·λi + tGPS = 50400 + 3600 → x = 2π·3600/PER = 0.247165;
        //   F = 1 + 16 (0.53 − 1/6)³ = 1.767442;
        //   T = F (5e-9 + AMP (1 − x²/2 + x⁴/24)) = 1.767442 (5e-9 + 4.45942e-9) = 1.67190e-8 s.
        let k = brdc_2010();
        let lam_i = 116.0 / 180.0;
        let t_gps = 54_000.0 - 43_200.0 * lam_i;
        let t = GpsTime::from_week_tow(1590, 345_600.0 + t_gps);
        let d = k.delay_l1_m(
            40f64.to_radians(),
            116f64.to_radians(),
            0.0,
            30f64.to_radians(),
            t,
        );
        let expected = C_MPS * 1.67190e-8;
        assert!((d - expected).abs() < 1e-4 * expected, "{d} vs {expected}");
        // B1I scaling.
        let b = k.delay_b1i_m(
            40f64.to_radians(),
            116f64.to_radians(),
            0.0,
            30f64.to_radians(),
            t,
        );
        assert!((b / d - (1575.42f64 / 1561.098).powi(2)).abs() < 1e-12);
        assert!((iono_scale_from_l1(F_B1I_HZ) - 1.018_435).abs() < 1e-5);
    }

    #[test]
    fn saastamoinen_zenith_at_sea_level() {
        // φ = 45° makes cos 2φ = 0: dry = 0.0022768 · 1013.25 = 2.30697 m. With humidity
        // 0.5: T = 288.16 K, e = 3.054 exp(1.032966) = 8.5802 hPa,
        // wet = 0.002277 (4.35522 + 0.05) 8.5802 = 0.086065 m. Total 2.39304 m.
        let z = saastamoinen_m(45f64.to_radians(), 0.0, PI / 2.0, 0.5);
        assert!((z - 2.39304).abs() < 2e-4, "{z}");
        let dry = saastamoinen_m(45f64.to_radians(), 0.0, PI / 2.0, 0.0);
        assert!((dry - 2.306_968).abs() < 1e-5, "{dry}");
        // Slant at 30° elevation is 1/sin 30° = 2 times the zenith value in this model.
        let s = saastamoinen_m(45f64.to_radians(), 0.0, PI / 6.0, 0.5);
        assert!((s - 2.0 * z).abs() < 1e-9);
    }

    #[test]
    fn saastamoinen_domain() {
        assert_eq!(saastamoinen_m(0.5, 0.0, 0.0, 0.5), 0.0);
        assert_eq!(saastamoinen_m(0.5, 0.0, -0.1, 0.5), 0.0);
        assert_eq!(saastamoinen_m(0.5, 10_001.0, 1.0, 0.5), 0.0);
        assert_eq!(saastamoinen_m(0.5, f64::NAN, 1.0, 0.5), 0.0);
        assert_eq!(saastamoinen_m(0.5, 0.0, f64::NAN, 0.5), 0.0);
        // Negative heights are clamped to the sea-level value.
        assert_eq!(
            saastamoinen_m(0.5, -50.0, 1.0, 0.5),
            saastamoinen_m(0.5, 0.0, 1.0, 0.5)
        );
        // Delay decreases with height.
        assert!(saastamoinen_m(0.5, 2000.0, 1.0, 0.5) < saastamoinen_m(0.5, 0.0, 1.0, 0.5));
    }
}
