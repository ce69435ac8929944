//! TC-OFDM base stations (seed 004): ranging signals from time-synchronised base stations.
//!
//! Seed 004 (§2.2) describes TC-OFDM as a broadcast/cellular network whose signal carries a
//! navigation component "much lower than the noise" in the same spectrum as the
//! communication signal, with the base stations synchronised to about 3 ns. It gives no
//! waveform, so this module **assumes** (documented here, configurable):
//!
//! * **Waveform**: the ranging code is a PN frame header of the DTMB family (TC-OFDM grew
//!   out of the CMMB/DTMB broadcast networks): by default the 945-chip header
//!   ([`PnMode::Pn945`]), chip rate 7.56 Mcps in an 8 MHz channel, repeated every
//!   4725-sample frame with an OFDM body as in DTMB. The signal is generated, passed
//!   through the multipath channel and synchronised by exactly the DTMB machinery
//!   ([`crate::dtmb::Transmitter`], [`crate::dtmb::Channel`], [`crate::dtmb::Receiver`]),
//!   and its measurement-level error model is DTMB's calibrated one.
//! * **Band and power**: an LTE-like carrier (default 1.9 GHz, inside Extended Hata's
//!   30–3000 MHz) and a navigation component `nav_power_db` below the station's ERP
//!   (default −10 dB), so its SNR is `ERP + 2.15 + nav_power_db − L − N` (ERP + 2.15 dB
//!   is the EIRP).
//! * **Synchronisation**: each base station's clock is offset from GPS time by a
//!   configured value plus a random `N(0, σ_sync²)` drawn once per trial from stream
//!   `tcofdm/Tnn/sync` (σ_sync default 3 ns, seed 004), which enters the pseudorange as
//!   `−c δt_station` like a tower clock.
//!
//! The source is [`TcofdmSource`] (name `"tcofdm"`, emitters of [`System::Tcofdm`]).

use crate::core::receiver_clock::ClockTrack;
use crate::core::{ConfigIssue, EmitterId, EnuFrame, SimTime, System, TrialRng};
use crate::dtmb::source::{DtmbLevel, DtmbSensorConfig, DtmbSource, Environment, TowerSpec};
use crate::dtmb::PnMode;
use crate::measurement::{MeasurementBatch, SampleContext, Source, SourceKind};
use crate::propagation::{Scene, ShadowingConfig};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;
use std::sync::Arc;

fn one() -> f64 {
    1.0
}
fn one_u32() -> u32 {
    1
}
fn default_window_m() -> f64 {
    300.0
}
fn default_nf() -> f64 {
    5.0
}
fn default_rx_height() -> f64 {
    1.5
}
fn default_sigma_floor_m() -> f64 {
    1.0
}

fn default_sync_ns() -> f64 {
    3.0
}
fn default_nav_db() -> f64 {
    -10.0
}

/// `[sensors.tcofdm]` in a world file. Fields as [`DtmbSensorConfig`] plus the two below.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TcofdmSensorConfig {
    /// `"signal"` or `"measurement"` (default).
    #[serde(default)]
    pub level: DtmbLevel,
    /// Measurement rate (Hz), default 1.
    #[serde(default = "one")]
    pub rate_hz: f64,
    /// Centre the search window on the aiding estimator's prediction (default false).
    #[serde(default)]
    pub aided: bool,
    /// Half-width of the aided search window (m), default 300.
    #[serde(default = "default_window_m")]
    pub search_window_m: f64,
    /// Receiver noise figure (dB), default 5.
    #[serde(default = "default_nf")]
    pub noise_figure_db: f64,
    /// Receive antenna gain (dBi), default 0.
    #[serde(default)]
    pub antenna_gain_dbi: f64,
    /// Frames accumulated per measurement (1–16), default 1.
    #[serde(default = "one_u32")]
    pub accumulation_frames: u32,
    /// Hata environment, default `"urban"`.
    #[serde(default)]
    pub environment: Environment,
    /// Receive antenna height (m), default 1.5.
    #[serde(default = "default_rx_height")]
    pub rx_antenna_height_m: f64,
    /// Log-normal shadowing, default σ 4 dB, 37 m.
    #[serde(default)]
    pub shadowing: ShadowingConfig,
    /// Receiver oscillator error (ppm), default 0.
    #[serde(default)]
    pub rx_oscillator_ppm: f64,
    /// Floor under the reported σ (m), default 1 (see `DtmbSensorConfig::sigma_floor_m`;
    /// smaller than DTMB's because the base stations are near and mostly in view).
    #[serde(default = "default_sigma_floor_m")]
    pub sigma_floor_m: f64,
    /// 1-σ synchronisation error between base stations (ns), default 3 (seed 004).
    #[serde(default = "default_sync_ns")]
    pub sync_sigma_ns: f64,
    /// Power of the navigation component relative to the station's ERP (dB), default −10.
    #[serde(default = "default_nav_db")]
    pub nav_power_db: f64,
}

impl Default for TcofdmSensorConfig {
    fn default() -> Self {
        Self {
            level: DtmbLevel::default(),
            rate_hz: 1.0,
            aided: false,
            search_window_m: default_window_m(),
            noise_figure_db: default_nf(),
            antenna_gain_dbi: 0.0,
            accumulation_frames: 1,
            environment: Environment::default(),
            rx_antenna_height_m: default_rx_height(),
            shadowing: ShadowingConfig::default(),
            rx_oscillator_ppm: 0.0,
            sigma_floor_m: default_sigma_floor_m(),
            sync_sigma_ns: default_sync_ns(),
            nav_power_db: default_nav_db(),
        }
    }
}

impl TcofdmSensorConfig {
    fn as_dtmb(&self) -> DtmbSensorConfig {
        DtmbSensorConfig {
            level: self.level,
            rate_hz: self.rate_hz,
            aided: self.aided,
            search_window_m: self.search_window_m,
            noise_figure_db: self.noise_figure_db,
            antenna_gain_dbi: self.antenna_gain_dbi,
            accumulation_frames: self.accumulation_frames,
            range_differences: false,
            environment: self.environment,
            rx_antenna_height_m: self.rx_antenna_height_m,
            shadowing: self.shadowing.clone(),
            rx_oscillator_ppm: self.rx_oscillator_ppm,
            sigma_floor_m: self.sigma_floor_m,
        }
    }

    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        self.as_dtmb().validate()?;
        if !(self.sync_sigma_ns.is_finite() && (0.0..=1e6).contains(&self.sync_sigma_ns)) {
            return Err(ConfigIssue::new(
                "sync_sigma_ns",
                format!(
                    "expected a synchronisation σ in [0, 1e6] ns, got {}",
                    self.sync_sigma_ns
                ),
            ));
        }
        if !(self.nav_power_db.is_finite() && (-60.0..=0.0).contains(&self.nav_power_db)) {
            return Err(ConfigIssue::new(
                "nav_power_db",
                format!(
                    "expected a navigation power in [−60, 0] dB, got {}",
                    self.nav_power_db
                ),
            ));
        }
        Ok(())
    }
}

/// One TC-OFDM base station.
#[derive(Clone, Debug, PartialEq)]
pub struct BaseStationSpec {
    /// Its id (system [`System::Tcofdm`]).
    pub id: EmitterId,
    /// Antenna position in the world's ENU frame (m); `z` is the height above ground.
    pub pos_enu_m: Vector3<f64>,
    /// The same in ECEF (m).
    pub pos_ecef_m: Vector3<f64>,
    /// Carrier frequency (Hz), default band 1.9 GHz.
    pub freq_hz: f64,
    /// Effective radiated power of the station (dBW).
    pub erp_dbw: f64,
    /// Ranging-code header mode (default PN945).
    pub pn_mode: PnMode,
    /// Configured clock offset from GPS time (s), before the random synchronisation error.
    pub clock_offset_s: f64,
    /// Clock drift (s/s).
    pub clock_drift_s_per_s: f64,
}

impl From<TowerSpec> for BaseStationSpec {
    /// A base station from a tower description (the UHF channel number does not apply).
    fn from(t: TowerSpec) -> Self {
        Self {
            id: t.id,
            pos_enu_m: t.pos_enu_m,
            pos_ecef_m: t.pos_ecef_m,
            freq_hz: t.freq_hz,
            erp_dbw: t.erp_dbw,
            pn_mode: t.pn_mode,
            clock_offset_s: t.clock_offset_s,
            clock_drift_s_per_s: t.clock_drift_s_per_s,
        }
    }
}

/// TC-OFDM base stations as a measurement source (`"tcofdm"`).
pub struct TcofdmSource {
    inner: DtmbSource,
    sync_errors_s: Vec<f64>,
}

impl std::fmt::Debug for TcofdmSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcofdmSource")
            .field("sync_errors_s", &self.sync_errors_s)
            .finish_non_exhaustive()
    }
}

impl TcofdmSource {
    /// Builds the source (same arguments as [`DtmbSource::new`]).
    ///
    /// # Errors
    /// A [`ConfigIssue`] for an invalid configuration or base station.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        cfg: TcofdmSensorConfig,
        stations: Vec<BaseStationSpec>,
        scene: Option<Arc<Scene>>,
        frame: EnuFrame,
        clock: Arc<ClockTrack>,
        aid_estimator: Option<usize>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let mut sync_errors_s = Vec::with_capacity(stations.len());
        let towers = stations
            .into_iter()
            .map(|s| {
                let n: f64 = rng
                    .stream(&format!("tcofdm/{}/sync", s.id))
                    .sample(StandardNormal);
                let sync_s = n * cfg.sync_sigma_ns * 1e-9;
                sync_errors_s.push(sync_s);
                TowerSpec {
                    id: s.id,
                    pos_enu_m: s.pos_enu_m,
                    pos_ecef_m: s.pos_ecef_m,
                    channel: 0,
                    freq_hz: s.freq_hz,
                    erp_dbw: s.erp_dbw + cfg.nav_power_db,
                    pn_mode: s.pn_mode,
                    clock_offset_s: s.clock_offset_s + sync_s,
                    clock_drift_s_per_s: s.clock_drift_s_per_s,
                    sfn: None,
                }
            })
            .collect();
        let inner = DtmbSource::with_system(
            System::Tcofdm,
            SourceKind::Tcofdm,
            cfg.as_dtmb(),
            towers,
            scene,
            frame,
            clock,
            aid_estimator,
            rng,
            end,
        )?;
        Ok(Self {
            inner,
            sync_errors_s,
        })
    }

    /// The random synchronisation error drawn for each station (s), in station order.
    pub fn sync_errors_s(&self) -> &[f64] {
        &self.sync_errors_s
    }

    /// Warnings noted so far (path-loss validity, link failures).
    pub fn warnings(&self) -> &[String] {
        self.inner.warnings()
    }

    /// The ranges the receiver holds at `truth`, with the σ it reports and no noise
    /// drawn ([`DtmbSource::noise_free_ranges`]; the bound of `world::bound` reads them).
    pub fn noise_free_ranges(
        &mut self,
        truth: &crate::measurement::Truth,
        out: &mut Vec<crate::measurement::RangeMeasurement>,
    ) {
        self.inner.noise_free_ranges(truth, out);
    }

    /// The interval between the receiver's epochs (ns).
    pub fn period_ns(&self) -> i64 {
        self.inner.period_ns()
    }
}

impl Source for TcofdmSource {
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings().to_vec()
    }

    fn kind(&self) -> SourceKind {
        SourceKind::Tcofdm
    }

    fn first_sample(&self) -> SimTime {
        self.inner.first_sample()
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        self.inner.sample(ctx, out)
    }
}
