//! FM stations and the received signal strength field.
//!
//! # Model
//!
//! The RSSI of station s at the ENU point x (dBm) is
//!
//! ```text
//! P̄_s(x) = ERP_s + 2.15 + 30 + G_rx − L_EH(f_s, h_b, h_m, d) − L_scene(x) − S_s(x)  (mean)
//! P_s(x) = Q( P̄_s(x) + n ),  n ~ N(0, σ_rx²);  missing (NaN) when P < P_sens
//! Q(p)   = step · round(p / step)
//! ```
//!
//! - `ERP_s + 2.15` is the station's e.i.r.p. (dBW): a broadcast ERP is relative to a
//!   half-wave dipole (2.15 dBi), and `L_EH` is a loss between isotropic antennas.
//! - `L_EH` is the Extended Hata median loss (ITU-R SM.2028 §6.1, see
//!   [`crate::propagation::pathloss::extended_hata_db`]). It is stated for 30–3000 MHz,
//!   so it covers the 87.5–108 MHz FM band, base heights 30–200 m, mobile heights
//!   1–10 m and distances up to 100 km. Below 40 m it becomes free space with the height
//!   difference, and it is never below free space. Out-of-range inputs are extrapolated
//!   and reported once per field ([`FmField::warnings`]). A broadcast mast taller than
//!   200 m is such a case: the model's height-gain term is then extrapolated.
//! - `L_scene` is the extra loss on the direct path through the scene (walls, foliage,
//!   building entry: `LinkPaths::direct_loss_db` of [`Scene::link`]) when a scene is given.
//!   The reflections that `Scene::link` also returns are ignored: an FM RSSI is a
//!   power averaged over many wavelengths (3 m), so fast fading is part of `n`.
//! - `S_s` is spatially consistent log-normal shadowing, one field per station, keyed by
//!   `(master seed, "fm/shadowing/<station id>")` ([`ShadowingField::from_key`]): the
//!   surveyor and the user see the same shadowing at the same place, which is what makes
//!   fingerprinting work at all.
//! - `n` is the receiver's per-scan noise (the residual fast fading and the estimator
//!   noise of the RSSI), `Q` the receiver's RSSI quantisation and `P_sens` its
//!   sensitivity floor.
//!
//! Seed 000 used 21 channels in Beijing. A world may declare fewer stations;
//! [`synthesize_stations`] adds stations at random sites and frequencies (documented
//! there) so that a study can run with 21 channels.

use crate::core::config::check;
use crate::core::rng::StreamRng;
use crate::core::{ConfigIssue, TrialRng};
use crate::propagation::pathloss::{
    eirp_dbw_from_erp, extended_hata_db, HataEnvironment, Model, ValidityLog,
};
use crate::propagation::{
    Emitter, LinkParams, LinkPaths, Polarisation, Scene, ShadowingConfig, ShadowingField,
};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;
use std::sync::Arc;

/// The lower and upper edges of the FM broadcast band (Hz).
pub const FM_BAND_HZ: (f64, f64) = (87.5e6, 108.0e6);

/// One FM broadcast station.
#[derive(Clone, Debug, PartialEq)]
pub struct FmStation {
    /// Identifier (the world's transmitter id, e.g. `"F01"`).
    pub id: String,
    /// Antenna position in the world's ENU frame (m).
    pub pos_enu_m: Vector3<f64>,
    /// Carrier frequency (Hz), within the FM band.
    pub freq_hz: f64,
    /// Effective radiated power (dBW).
    pub erp_dbw: f64,
    /// Antenna height above the local ground (m), the Hata base-station height.
    pub antenna_height_m: f64,
}

impl FmStation {
    /// A station from plain values; the antenna height above ground is taken as the ENU
    /// up coordinate minus `ground_up_m`, at least 1 m.
    pub fn new(
        id: &str,
        pos_enu_m: Vector3<f64>,
        freq_hz: f64,
        erp_dbw: f64,
        ground_up_m: f64,
    ) -> Self {
        Self {
            id: id.to_string(),
            pos_enu_m,
            freq_hz,
            erp_dbw,
            antenna_height_m: (pos_enu_m.z - ground_up_m).max(1.0),
        }
    }

    /// Checks the values; the key names the station.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let key = format!("station {}", self.id);
        check(&key, self.pos_enu_m.iter().all(|v| v.is_finite()), || {
            format!("expected a finite ENU position, got {:?}", self.pos_enu_m)
        })?;
        check(
            &key,
            (FM_BAND_HZ.0..=FM_BAND_HZ.1).contains(&self.freq_hz),
            || {
                format!(
                    "expected a frequency in the FM band 87.5–108 MHz, got {} MHz",
                    self.freq_hz / 1e6
                )
            },
        )?;
        check(
            &key,
            self.erp_dbw.is_finite() && (-30.0..=70.0).contains(&self.erp_dbw),
            || format!("expected an ERP in [−30, 70] dBW, got {}", self.erp_dbw),
        )?;
        check(
            &key,
            self.antenna_height_m.is_finite() && (1.0..=1000.0).contains(&self.antenna_height_m),
            || {
                format!(
                    "expected an antenna height in [1, 1000] m, got {}",
                    self.antenna_height_m
                )
            },
        )
    }
}

/// Adds synthetic stations to `declared` until there are `total` (seed 000 used 21).
///
/// The synthetic stations are this crate's assumption, not the paper's: sites at a
/// uniform azimuth and a distance uniform in 3–30 km from the ENU origin, antenna 100–300
/// m above ground, ERP 0.5–20 kW (log-uniform), frequencies on the 100 kHz raster of
/// the FM band at least 400 kHz from every other station. They are drawn from the
/// stream `fm/stations` of `TrialRng::new(seed, 0)` so that a city is the same in every
/// trial. Ids are `FS01`, `FS02`, … Returns the declared stations unchanged when there are
/// already `total` or more.
pub fn synthesize_stations(declared: &[FmStation], total: usize, seed: u64) -> Vec<FmStation> {
    let mut out = declared.to_vec();
    let mut rng = TrialRng::new(seed, 0).stream("fm/stations");
    let mut k = 0;
    while out.len() < total {
        let az = rng.random::<f64>() * std::f64::consts::TAU;
        let d = 3_000.0 + 27_000.0 * rng.random::<f64>();
        let h = 100.0 + 200.0 * rng.random::<f64>();
        let erp_kw = 0.5 * 40f64.powf(rng.random::<f64>());
        // Frequencies: draw on the raster until one is clear of every station.
        let mut freq_hz = 0.0;
        for _ in 0..1000 {
            let ch = rng.random_range(0..=205) as f64;
            let f = FM_BAND_HZ.0 + 100e3 * ch;
            if out.iter().all(|s| (s.freq_hz - f).abs() >= 400e3 - 1.0) {
                freq_hz = f;
                break;
            }
        }
        if freq_hz == 0.0 {
            // The band is full (more than ~50 stations): stop rather than loop forever.
            break;
        }
        k += 1;
        out.push(FmStation {
            id: format!("FS{k:02}"),
            pos_enu_m: Vector3::new(d * az.sin(), d * az.cos(), h),
            freq_hz,
            erp_dbw: 10.0 * (erp_kw * 1e3).log10(),
            antenna_height_m: h,
        });
    }
    out
}

/// The Hata environment class, as written in a configuration.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum FmEnvironment {
    /// Urban, small or medium city (default).
    #[default]
    Urban,
    /// Urban, large city.
    UrbanLarge,
    /// Suburban.
    Suburban,
    /// Open (rural).
    Open,
}

impl FmEnvironment {
    fn hata(self) -> HataEnvironment {
        match self {
            FmEnvironment::Urban => HataEnvironment::UrbanSmallMedium,
            FmEnvironment::UrbanLarge => HataEnvironment::UrbanLarge,
            FmEnvironment::Suburban => HataEnvironment::Suburban,
            FmEnvironment::Open => HataEnvironment::Open,
        }
    }
}

fn default_rx_height() -> f64 {
    1.5
}
fn default_noise() -> f64 {
    2.0
}
fn default_step() -> f64 {
    1.0
}
fn default_sens() -> f64 {
    -100.0
}

/// The receiver and propagation parameters of the RSSI field.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FmFieldConfig {
    /// Hata environment class, default `"urban"`.
    #[serde(default)]
    pub environment: FmEnvironment,
    /// Receive antenna height above ground (m) for the Hata model, default 1.5.
    #[serde(default = "default_rx_height")]
    pub rx_antenna_height_m: f64,
    /// Receive antenna gain (dBi), default 0.
    #[serde(default)]
    pub antenna_gain_dbi: f64,
    /// Per-scan RSSI noise σ (dB), default 2.
    #[serde(default = "default_noise")]
    pub noise_sigma_db: f64,
    /// RSSI quantisation step (dB), default 1; 0 disables quantisation.
    #[serde(default = "default_step")]
    pub quantisation_db: f64,
    /// Sensitivity floor (dBm), default −100: weaker readings are missing.
    #[serde(default = "default_sens")]
    pub sensitivity_dbm: f64,
    /// Shadowing per station (σ 0 disables it), default σ 4 dB, 37 m.
    #[serde(default)]
    pub shadowing: ShadowingConfig,
}

impl Default for FmFieldConfig {
    fn default() -> Self {
        Self {
            environment: FmEnvironment::default(),
            rx_antenna_height_m: default_rx_height(),
            antenna_gain_dbi: 0.0,
            noise_sigma_db: default_noise(),
            quantisation_db: default_step(),
            sensitivity_dbm: default_sens(),
            shadowing: ShadowingConfig::default(),
        }
    }
}

impl FmFieldConfig {
    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check(
            "rx_antenna_height_m",
            self.rx_antenna_height_m.is_finite()
                && (0.1..=100.0).contains(&self.rx_antenna_height_m),
            || {
                format!(
                    "expected a receive antenna height in [0.1, 100] m, got {}",
                    self.rx_antenna_height_m
                )
            },
        )?;
        check(
            "antenna_gain_dbi",
            self.antenna_gain_dbi.is_finite() && self.antenna_gain_dbi.abs() <= 40.0,
            || {
                format!(
                    "expected an antenna gain in [−40, 40] dBi, got {}",
                    self.antenna_gain_dbi
                )
            },
        )?;
        check(
            "noise_sigma_db",
            self.noise_sigma_db.is_finite() && (0.0..=30.0).contains(&self.noise_sigma_db),
            || {
                format!(
                    "expected an RSSI noise σ in [0, 30] dB, got {}",
                    self.noise_sigma_db
                )
            },
        )?;
        check(
            "quantisation_db",
            self.quantisation_db.is_finite() && (0.0..=10.0).contains(&self.quantisation_db),
            || {
                format!(
                    "expected a quantisation step in [0, 10] dB, got {}",
                    self.quantisation_db
                )
            },
        )?;
        check(
            "sensitivity_dbm",
            self.sensitivity_dbm.is_finite() && (-160.0..=0.0).contains(&self.sensitivity_dbm),
            || {
                format!(
                    "expected a sensitivity in [−160, 0] dBm, got {}",
                    self.sensitivity_dbm
                )
            },
        )?;
        self.shadowing
            .validate()
            .map_err(|c| ConfigIssue::new(format!("shadowing.{}", c.key), c.message))
    }

    /// One reading: noise, quantisation and the sensitivity floor applied to a mean RSSI.
    pub fn read(&self, mean_dbm: f64, noise_sigma_db: f64, rng: &mut StreamRng) -> f64 {
        let n: f64 = rng.sample(StandardNormal);
        self.finish(mean_dbm + noise_sigma_db * n)
    }

    /// Quantisation and the sensitivity floor (NaN below it).
    pub fn finish(&self, rssi_dbm: f64) -> f64 {
        let q = if self.quantisation_db > 0.0 {
            self.quantisation_db * (rssi_dbm / self.quantisation_db).round()
        } else {
            rssi_dbm
        };
        if q >= self.sensitivity_dbm {
            q
        } else {
            f64::NAN
        }
    }
}

/// The RSSI field of a set of stations over one world: a deterministic function of place
/// (its mean) plus the receiver's reading model.
pub struct FmField {
    cfg: FmFieldConfig,
    stations: Vec<FmStation>,
    shadowing: Vec<ShadowingField>,
    scene: Option<Arc<Scene>>,
    link: LinkPaths,
    log: ValidityLog,
    warnings: Vec<String>,
}

impl FmField {
    /// Builds the field. `master_seed` keys the shadowing (the same city in every trial).
    pub fn new(
        cfg: FmFieldConfig,
        stations: Vec<FmStation>,
        scene: Option<Arc<Scene>>,
        master_seed: u64,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        check("stations", !stations.is_empty(), || {
            "expected at least one FM station".into()
        })?;
        for (i, s) in stations.iter().enumerate() {
            s.validate()?;
            check(
                &format!("station {}", s.id),
                stations[..i].iter().all(|o| o.id != s.id),
                || format!("station id {} appears twice", s.id),
            )?;
        }
        let shadowing = stations
            .iter()
            .map(|s| {
                ShadowingField::from_key(
                    &cfg.shadowing,
                    master_seed,
                    &format!("fm/shadowing/{}", s.id),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            cfg,
            stations,
            shadowing,
            scene,
            link: LinkPaths::new(),
            log: ValidityLog::default(),
            warnings: Vec::new(),
        })
    }

    /// The stations, in channel order.
    pub fn stations(&self) -> &[FmStation] {
        &self.stations
    }

    /// The configuration.
    pub fn config(&self) -> &FmFieldConfig {
        &self.cfg
    }

    /// Warnings collected so far (a model used outside its validity range, once each).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The mean RSSI (dBm) of every station at `p_enu_m` (no noise, no quantisation, no
    /// floor) into `out` (one value per station).
    pub fn mean_rssi_dbm(&mut self, p_enu_m: &Vector3<f64>, out: &mut [f64]) {
        let hm = self.cfg.rx_antenna_height_m;
        let env = self.cfg.environment.hata();
        for (k, s) in self.stations.iter().enumerate() {
            let dh = s.pos_enu_m - p_enu_m;
            let d_km = (dh.x * dh.x + dh.y * dh.y).sqrt().max(1.0) * 1e-3;
            let (l, v) = extended_hata_db(env, s.freq_hz * 1e-6, s.antenna_height_m, hm, d_km);
            if let Some(w) = self.log.note(Model::ExtendedHata, v) {
                self.warnings.push(format!("FM field: {w}"));
            }
            let scene_db = match &self.scene {
                Some(scene) => {
                    let params = LinkParams {
                        freq_hz: s.freq_hz,
                        polarisation: Polarisation::Horizontal,
                        rx_vel_enu_mps: Vector3::zeros(),
                    };
                    match scene.link(
                        p_enu_m,
                        &Emitter::Point(s.pos_enu_m),
                        &params,
                        &mut self.link,
                    ) {
                        Ok(()) => self.link.direct_loss_db,
                        // The scene refuses only non-finite positions; the receiver's
                        // position comes from the trajectory or a survey layout that are
                        // already checked, so no extra loss is the neutral answer.
                        Err(_) => 0.0,
                    }
                }
                None => 0.0,
            };
            out[k] = eirp_dbw_from_erp(s.erp_dbw) + 30.0 + self.cfg.antenna_gain_dbi
                - l
                - scene_db
                - self.shadowing[k].value_db(p_enu_m.x, p_enu_m.y);
        }
    }

    /// One scan: the receiver's readings (dBm, NaN when below the sensitivity) of every
    /// station at `p_enu_m`, with the configured noise, quantisation and floor.
    pub fn scan(&mut self, p_enu_m: &Vector3<f64>, rng: &mut StreamRng, out: &mut [f64]) {
        self.mean_rssi_dbm(p_enu_m, out);
        self.read_scan(rng, out);
    }

    /// The readings of a scan whose mean RSSI ([`FmField::mean_rssi_dbm`]) is in `out`:
    /// noise, quantisation and floor, one draw per station in station order.
    pub fn read_scan(&self, rng: &mut StreamRng, out: &mut [f64]) {
        let sigma = self.cfg.noise_sigma_db;
        for v in out.iter_mut() {
            *v = self.cfg.read(*v, sigma, rng);
        }
    }

    /// The validity log and the number of warnings so far: with the warnings themselves,
    /// all the state [`FmField::mean_rssi_dbm`] carries from one call to the next.
    pub fn log_state(&self) -> (ValidityLog, usize) {
        (self.log, self.warnings.len())
    }

    /// Resumes from a state another field of the same stations reached
    /// ([`FmField::log_state`] and its warnings), so that this field goes on warning
    /// exactly as that one would have.
    pub fn restore_log(&mut self, log: ValidityLog, warnings: &[String]) {
        self.log = log;
        self.warnings.clear();
        self.warnings.extend_from_slice(warnings);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::propagation::pathloss::free_space_db;

    fn station(d_m: f64) -> FmStation {
        FmStation::new("F01", Vector3::new(d_m, 0.0, 150.0), 100e6, 40.0, 0.0)
    }

    #[test]
    fn mean_is_eirp_minus_extended_hata_without_shadowing() {
        let cfg = FmFieldConfig {
            shadowing: ShadowingConfig {
                sigma_db: 0.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut f = FmField::new(cfg, vec![station(5_000.0)], None, 1).unwrap();
        let mut out = [0.0];
        f.mean_rssi_dbm(&Vector3::zeros(), &mut out);
        let (l, v) = extended_hata_db(HataEnvironment::UrbanSmallMedium, 100.0, 150.0, 1.5, 5.0);
        assert!(v.ok());
        // 40 dBW ERP = 42.15 dBW EIRP = 72.15 dBm, less the loss between isotropic antennas.
        assert!((out[0] - (72.15 - l)).abs() < 1e-9);
        // Urban Hata at 5 km is well above free space (a sanity check on the model choice).
        assert!(l > free_space_db(5_000.0, 100e6) + 20.0);
    }

    /// Within 40 m Extended Hata is free space, so the mean RSSI is Friis's received power
    /// from the station's EIRP, computed here by hand: 1 W ERP is 10^0.215 W EIRP; over
    /// d = √(30² + 10²) m at λ = c / 100 MHz an isotropic antenna receives
    /// EIRP · (λ / 4πd)². (Extended Hata's short-range form rounds 32.45 dB to 32.4, hence
    /// the 0.06 dB tolerance.)
    #[test]
    fn short_range_mean_is_friis_from_the_eirp() {
        let cfg = FmFieldConfig {
            shadowing: ShadowingConfig {
                sigma_db: 0.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let st = FmStation::new("F01", Vector3::new(30.0, 0.0, 11.5), 100e6, 0.0, 0.0);
        let mut f = FmField::new(cfg, vec![st], None, 1).unwrap();
        let mut out = [0.0];
        f.mean_rssi_dbm(&Vector3::new(0.0, 0.0, 1.5), &mut out);
        let eirp_w = 10f64.powf(0.215);
        let lambda_m = 299_792_458.0 / 100e6;
        let d_m = (30.0f64 * 30.0 + 10.0 * 10.0).sqrt();
        let p_w = eirp_w * (lambda_m / (4.0 * std::f64::consts::PI * d_m)).powi(2);
        let friis_dbm = 10.0 * p_w.log10() + 30.0;
        assert!(
            (out[0] - friis_dbm).abs() < 0.06,
            "{} vs {friis_dbm}",
            out[0]
        );
    }

    #[test]
    fn a_building_in_the_way_costs_two_concrete_walls() {
        use crate::propagation::scene::{BuildingConfig, SceneConfig, WallMaterial};
        let cfg = FmFieldConfig {
            shadowing: ShadowingConfig {
                sigma_db: 0.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let scene = SceneConfig {
            buildings: vec![BuildingConfig {
                footprint_enu_m: vec![[20.0, -10.0], [40.0, -10.0], [40.0, 10.0], [20.0, 10.0]],
                height_m: 30.0,
                material: WallMaterial::Concrete,
                class: Default::default(),
            }],
            ..Default::default()
        };
        let scene = Arc::new(Scene::new(&scene).unwrap());
        let mut open = FmField::new(cfg.clone(), vec![station(5_000.0)], None, 1).unwrap();
        let mut built = FmField::new(cfg, vec![station(5_000.0)], Some(scene), 1).unwrap();
        let (mut a, mut b) = ([0.0], [0.0]);
        let rx = Vector3::new(0.0, 0.0, 1.5);
        open.mean_rssi_dbm(&rx, &mut a);
        built.mean_rssi_dbm(&rx, &mut b);
        // The path at 2–3 m height crosses the 30 m building's west and east walls.
        let expected = 2.0 * WallMaterial::Concrete.penetration_loss_db(100e6);
        assert!(
            (a[0] - b[0] - expected).abs() < 1e-9,
            "{} vs {expected}",
            a[0] - b[0]
        );
        // Beside the building the scene costs nothing.
        let rx = Vector3::new(0.0, 50.0, 1.5);
        open.mean_rssi_dbm(&rx, &mut a);
        built.mean_rssi_dbm(&rx, &mut b);
        assert_eq!(a[0], b[0]);
    }

    #[test]
    fn quantisation_and_floor() {
        let cfg = FmFieldConfig {
            quantisation_db: 2.0,
            sensitivity_dbm: -90.0,
            ..Default::default()
        };
        assert_eq!(cfg.finish(-71.2), -72.0);
        assert_eq!(cfg.finish(-70.9), -70.0);
        assert!(cfg.finish(-91.5).is_nan());
    }

    #[test]
    fn synthetic_stations_fill_to_total_with_distinct_frequencies() {
        let s = synthesize_stations(&[station(5_000.0)], 21, 3);
        assert_eq!(s.len(), 21);
        assert_eq!(s[0].id, "F01");
        for (i, a) in s.iter().enumerate() {
            a.validate().unwrap();
            for b in &s[..i] {
                assert!((a.freq_hz - b.freq_hz).abs() >= 399e3);
            }
        }
        assert_eq!(s, synthesize_stations(&[station(5_000.0)], 21, 3));
    }

    #[test]
    fn bad_station_and_config_are_named() {
        let mut s = station(1_000.0);
        s.freq_hz = 120e6;
        let e = FmField::new(FmFieldConfig::default(), vec![s], None, 1)
            .err()
            .unwrap();
        assert!(
            e.key.contains("F01") && e.message.contains("FM band"),
            "{e:?}"
        );
        let cfg = FmFieldConfig {
            noise_sigma_db: -1.0,
            ..Default::default()
        };
        assert_eq!(cfg.validate().unwrap_err().key, "noise_sigma_db");
    }
}
