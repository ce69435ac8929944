//! Median path-loss models, each with its equation, source and validity range.
//!
//! Models used outside their validity range still return a number (extrapolating the
//! formula), together with a [`Validity`] that says which input was out of range. There is
//! no global "warned once" flag: a caller that wants one warning per model keeps a
//! [`ValidityLog`] of its own (one per trial or per source) and logs what
//! [`ValidityLog::note`] returns.
//!
//! Logarithms are base 10; f is in MHz unless a name says otherwise, distances in km for
//! the Hata family (as the sources write them) and in m elsewhere.

use crate::core::C_MPS;
use std::f64::consts::PI;

/// Which inputs of a model call were outside its stated validity range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Validity {
    /// The frequency was out of range.
    pub frequency: bool,
    /// The transmitter (base station) height was out of range.
    pub tx_height: bool,
    /// The receiver (mobile) height was out of range.
    pub rx_height: bool,
    /// The distance was out of range.
    pub distance: bool,
    /// Another model-specific input (elevation, probability) was out of range.
    pub other: bool,
}

impl Validity {
    /// Whether every input was in range.
    pub fn ok(&self) -> bool {
        !(self.frequency || self.tx_height || self.rx_height || self.distance || self.other)
    }

    /// A short list of the offending inputs, e.g. `"frequency, distance"`.
    pub fn describe(&self) -> String {
        let names = [
            (self.frequency, "frequency"),
            (self.tx_height, "transmitter height"),
            (self.rx_height, "receiver height"),
            (self.distance, "distance"),
            (self.other, "other input"),
        ];
        names
            .iter()
            .filter(|(b, _)| *b)
            .map(|(_, n)| *n)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The path-loss models, for [`ValidityLog`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    OkumuraHata,
    ExtendedHata,
    BuildingEntryP2109,
    VegetationP833,
}

/// A caller-owned record of which models have already been reported as used out of range.
#[derive(Clone, Copy, Debug, Default)]
pub struct ValidityLog {
    warned: [bool; 4],
}

impl ValidityLog {
    /// Returns a warning message the first time `model` is used out of range, `None`
    /// otherwise (in range, or already reported).
    pub fn note(&mut self, model: Model, v: Validity) -> Option<String> {
        let k = model as usize;
        if v.ok() || self.warned[k] {
            return None;
        }
        self.warned[k] = true;
        Some(format!(
            "{model:?} used outside its validity range ({}); the result is extrapolated",
            v.describe()
        ))
    }
}

/// The gain of a lossless half-wave dipole over an isotropic antenna (dBi): 10·log10(1.64)
/// = 2.15 dB (ITU-R BS.561 / ITU-R V.573 definitions of e.r.p. and e.i.r.p.).
pub const HALF_WAVE_DIPOLE_GAIN_DBI: f64 = 2.15;

/// The e.i.r.p. of a transmitter whose e.r.p. (relative to a half-wave dipole, the figure
/// broadcast licences give) is `erp_dbw`: EIRP = ERP + 2.15 dB. The path losses here (free
/// space, Hata, Extended Hata) are between isotropic antennas, so a link budget takes
/// the EIRP.
pub fn eirp_dbw_from_erp(erp_dbw: f64) -> f64 {
    erp_dbw + HALF_WAVE_DIPOLE_GAIN_DBI
}

/// Free-space basic transmission loss (ITU-R P.525): `L = 20 log10(4π d f / c)` dB, any
/// distance and frequency (far field: d ≫ λ).
pub fn free_space_db(distance_m: f64, freq_hz: f64) -> f64 {
    20.0 * (4.0 * PI * distance_m * freq_hz / C_MPS).log10()
}

/// The environment class of the Hata models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HataEnvironment {
    /// Urban, small or medium city.
    UrbanSmallMedium,
    /// Urban, large city (the large-city mobile-height correction).
    UrbanLarge,
    /// Suburban.
    Suburban,
    /// Open (rural) area.
    Open,
}

/// Okumura–Hata median loss (M. Hata, IEEE Trans. Veh. Tech. 29(3), 1980):
///
/// ```text
/// L_urban = 69.55 + 26.16 log f − 13.82 log hb − a(hm) + (44.9 − 6.55 log hb) log d
/// a(hm), small/medium city = (1.1 log f − 0.7) hm − (1.56 log f − 0.8)
/// a(hm), large city        = 8.29 (log 1.54 hm)² − 1.1   (f ≤ 300 MHz)
///                          = 3.2 (log 11.75 hm)² − 4.97  (f > 300 MHz)
/// L_suburban = L_urban − 2 [log(f/28)]² − 5.4
/// L_open     = L_urban − 4.78 (log f)² + 18.33 log f − 40.94
/// ```
///
/// The suburban and open formulas start from the small/medium-city urban loss. Validity:
/// f 150–1500 MHz, hb 30–200 m, hm 1–10 m, d 1–20 km.
pub fn okumura_hata_db(
    env: HataEnvironment,
    f_mhz: f64,
    hb_m: f64,
    hm_m: f64,
    d_km: f64,
) -> (f64, Validity) {
    let lf = f_mhz.log10();
    let lhb = hb_m.log10();
    let a_hm = match env {
        HataEnvironment::UrbanLarge if f_mhz <= 300.0 => 8.29 * (1.54 * hm_m).log10().powi(2) - 1.1,
        HataEnvironment::UrbanLarge => 3.2 * (11.75 * hm_m).log10().powi(2) - 4.97,
        _ => (1.1 * lf - 0.7) * hm_m - (1.56 * lf - 0.8),
    };
    let urban = 69.55 + 26.16 * lf - 13.82 * lhb - a_hm + (44.9 - 6.55 * lhb) * d_km.log10();
    let l = match env {
        HataEnvironment::UrbanSmallMedium | HataEnvironment::UrbanLarge => urban,
        HataEnvironment::Suburban => urban - 2.0 * (f_mhz / 28.0).log10().powi(2) - 5.4,
        HataEnvironment::Open => urban - 4.78 * lf * lf + 18.33 * lf - 40.94,
    };
    let v = Validity {
        frequency: !(150.0..=1500.0).contains(&f_mhz),
        tx_height: !(30.0..=200.0).contains(&hb_m),
        rx_height: !(1.0..=10.0).contains(&hm_m),
        distance: !(1.0..=20.0).contains(&d_km),
        other: false,
    };
    (l, v)
}

/// Extended Hata median loss (ITU-R Report SM.2028-2 §6.1, as SEAMCAT implements it), which
/// reaches down to 30 MHz and so covers FM broadcast (88–108 MHz), and up to 3 GHz:
///
/// ```text
/// H = max(30, hb),  a(hm) = (1.1 log f − 0.7) min(10, hm) − (1.56 log f − 0.8) + max(0, 20 log(hm/10))
/// b(hb) = min(0, 20 log(hb/30)),  α = 1 (d ≤ 20 km),
///          α = 1 + (0.14 + 1.87e-4 f + 1.07e-3 hb) [log(d/20)]^0.8 (d > 20 km)
/// urban, d ≥ 0.1 km:
///   30 < f ≤ 150:    69.6 + 26.2 log 150 − 20 log(150/f) − 13.82 log H + (44.9 − 6.55 log H)(log d)^α − a(hm) − b(hb)
///   150 < f ≤ 1500:  69.6 + 26.2 log f − …   (the same tail)
///   1500 < f ≤ 2000: 46.3 + 33.9 log f − …
///   2000 < f ≤ 3000: 46.3 + 33.9 log 2000 + 10 log(f/2000) − …
/// suburban: L_urban − 2 {log[min(max(150, f), 2000)/28]}² − 5.4
/// open:     L_urban − 4.78 {log min(max(150, f), 2000)}² + 18.33 log min(max(150, f), 2000) − 40.94
/// d ≤ 0.04 km: L = 32.4 + 20 log f + 10 log(d² + (hb − hm)²/10⁶)
/// 0.04 < d < 0.1 km: linear in log d between L(0.04) and L(0.1)
/// ```
///
/// and never below free space. For `UrbanLarge` the urban formula is used (SM.2028 has one
/// urban class). Validity: f 30–3000 MHz, hb 30–200 m, hm 1–10 m, d ≤ 100 km.
pub fn extended_hata_db(
    env: HataEnvironment,
    f_mhz: f64,
    hb_m: f64,
    hm_m: f64,
    d_km: f64,
) -> (f64, Validity) {
    let v = Validity {
        frequency: !(30.0..=3000.0).contains(&f_mhz),
        tx_height: !(30.0..=200.0).contains(&hb_m),
        rx_height: !(1.0..=10.0).contains(&hm_m),
        distance: !(d_km > 0.0 && d_km <= 100.0),
        other: false,
    };
    let short =
        |d: f64| 32.4 + 20.0 * f_mhz.log10() + 10.0 * (d * d + (hb_m - hm_m).powi(2) / 1e6).log10();
    let l = if d_km <= 0.04 {
        short(d_km)
    } else if d_km >= 0.1 {
        extended_hata_far(env, f_mhz, hb_m, hm_m, d_km)
    } else {
        let l0 = short(0.04);
        let l1 = extended_hata_far(env, f_mhz, hb_m, hm_m, 0.1);
        l0 + (d_km.log10() - 0.04f64.log10()) / (0.1f64.log10() - 0.04f64.log10()) * (l1 - l0)
    };
    let fs = free_space_db(d_km * 1e3, f_mhz * 1e6);
    (l.max(fs), v)
}

fn extended_hata_far(env: HataEnvironment, f: f64, hb: f64, hm: f64, d: f64) -> f64 {
    let lf = f.log10();
    let h = hb.max(30.0).log10();
    let a_hm =
        (1.1 * lf - 0.7) * hm.min(10.0) - (1.56 * lf - 0.8) + (20.0 * (hm / 10.0).log10()).max(0.0);
    let b_hb = (20.0 * (hb / 30.0).log10()).min(0.0);
    let alpha = if d <= 20.0 {
        1.0
    } else {
        1.0 + (0.14 + 1.87e-4 * f + 1.07e-3 * hb) * (d / 20.0).log10().powf(0.8)
    };
    let head = if f <= 150.0 {
        69.6 + 26.2 * 150f64.log10() - 20.0 * (150.0 / f).log10()
    } else if f <= 1500.0 {
        69.6 + 26.2 * lf
    } else if f <= 2000.0 {
        46.3 + 33.9 * lf
    } else {
        46.3 + 33.9 * 2000f64.log10() + 10.0 * (f / 2000.0).log10()
    };
    let urban = head - 13.82 * h + (44.9 - 6.55 * h) * d.log10().powf(alpha) - a_hm - b_hb;
    let fc = f.clamp(150.0, 2000.0);
    match env {
        HataEnvironment::UrbanSmallMedium | HataEnvironment::UrbanLarge => urban,
        HataEnvironment::Suburban => urban - 2.0 * (fc / 28.0).log10().powi(2) - 5.4,
        HataEnvironment::Open => urban - 4.78 * fc.log10().powi(2) + 18.33 * fc.log10() - 40.94,
    }
}

/// ITU-R P.2109-1 building entry loss not exceeded with probability `p` (0 < p < 1), for
/// frequency `freq_hz` and elevation `elevation_rad` of the path at the façade:
///
/// ```text
/// L_BEL(P) = 10 log10(10^{0.1 A(P)} + 10^{0.1 B(P)} + 10^{0.1 C})
/// A(P) = F⁻¹(P) σ1 + μ1,  B(P) = F⁻¹(P) σ2 + μ2,  C = −3.0
/// μ1 = L_h + L_e,  L_h = r + s log f + t (log f)²,  L_e = 0.212 |θ|   (f in GHz, θ in °)
/// μ2 = w + x log f,  σ1 = u + v log f,  σ2 = y + z log f
/// traditional:          r 12.64, s 3.72, t 0.96, u 9.6, v 2.0, w 9.1, x −3.0, y 4.5, z −2.0
/// thermally efficient:  r 28.19, s −3.00, t 8.48, u 13.5, v 3.8, w 27.8, x 9.4, y 6.1, z 0.7
/// ```
///
/// F⁻¹ is the inverse standard normal distribution. The median (P = 0.5) is about 14 dB
/// for a traditional building and 31–40 dB for a thermally efficient one at 0.1–0.6 GHz.
/// Validity: f 0.08–100 GHz, 0 < P < 1 (P is clamped to [1e-6, 1 − 1e-6]).
pub fn building_entry_loss_db(
    class: super::scene::BuildingClass,
    freq_hz: f64,
    elevation_rad: f64,
    p: f64,
) -> (f64, Validity) {
    let (r, s, t, u, v, w, x, y, z) = match class {
        super::scene::BuildingClass::Traditional => {
            (12.64, 3.72, 0.96, 9.6, 2.0, 9.1, -3.0, 4.5, -2.0)
        }
        super::scene::BuildingClass::ThermallyEfficient => {
            (28.19, -3.00, 8.48, 13.5, 3.8, 27.8, 9.4, 6.1, 0.7)
        }
    };
    let f_ghz = freq_hz * 1e-9;
    let lf = f_ghz.log10();
    let l_h = r + s * lf + t * lf * lf;
    let l_e = 0.212 * elevation_rad.to_degrees().abs();
    let mu1 = l_h + l_e;
    let mu2 = w + x * lf;
    let sigma1 = u + v * lf;
    let sigma2 = y + z * lf;
    let q = inverse_normal_cdf(p.clamp(1e-6, 1.0 - 1e-6));
    let a = q * sigma1 + mu1;
    let b = q * sigma2 + mu2;
    let c = -3.0f64;
    let l = 10.0 * (10f64.powf(0.1 * a) + 10f64.powf(0.1 * b) + 10f64.powf(0.1 * c)).log10();
    let val = Validity {
        frequency: !(0.08..=100.0).contains(&f_ghz),
        other: !(p > 0.0 && p < 1.0),
        ..Validity::default()
    };
    (l, val)
}

/// The inverse of the standard normal distribution function; `p` must lie in (0, 1).
pub use crate::core::stats::normal_quantile as inverse_normal_cdf;

/// The specific attenuation of dense in-leaf foliage (dB/m) at `freq_hz`: the short-path
/// slope of Weissberger's modified exponential decay model (M. A. Weissberger, ECAC-CR-81-
/// 101, 1981), `γ = 0.45 f^0.284` with f in GHz, stated for 0.23–95 GHz and a foliage
/// depth up to 14 m. It is used as the P.833 specific attenuation γ; a forest's
/// `foliage_density` scales it.
pub fn foliage_specific_attenuation_db_per_m(freq_hz: f64) -> f64 {
    0.45 * (freq_hz * 1e-9).powf(0.284)
}

/// ITU-R P.833 vegetation loss for a terrestrial path with a terminal in woodland:
///
/// ```text
/// A_ev = A_m [1 − exp(−d γ / A_m)]
/// A_m  = A1 f^α,  A1 = 0.18 dB, α = 0.752   (f in MHz; P.833 §2.1, the maximum
///                                             attenuation one terminal in woodland)
/// ```
///
/// `weighted_path_m` is d·density summed over the forests crossed (so `γ` is that of
/// dense foliage, [`foliage_specific_attenuation_db_per_m`]). Validity: 30 MHz–100 GHz
/// (P.833's scope), and 0.23 GHz upwards for the γ fit.
pub fn vegetation_loss_db(freq_hz: f64, weighted_path_m: f64) -> (f64, Validity) {
    let a_m = 0.18 * (freq_hz * 1e-6).powf(0.752);
    let gamma = foliage_specific_attenuation_db_per_m(freq_hz);
    let l = if weighted_path_m > 0.0 {
        a_m * (1.0 - (-weighted_path_m * gamma / a_m).exp())
    } else {
        0.0
    };
    let v = Validity {
        frequency: !(30e6..=100e9).contains(&freq_hz),
        ..Validity::default()
    };
    (l, v)
}
