//! The FM fingerprinting receiver as a measurement source (`"fm"`).
//!
//! At each epoch (default 1 Hz) the source
//!
//! 1. scans the RSSI of every station at the true position ([`FmField::scan`]: noise,
//!    quantisation, sensitivity floor), stream `fm/scan`;
//! 2. centres the constraint circle on the aiding estimator's last *reliable* estimate
//!    (closed loop): an estimate is reliable when its horizontal σ = √((σ_e² + σ_n²)/2)
//!    is at most `constraint.reliable_sigma_m`. While the estimates are reliable the
//!    centre is the latest one; once they are not, the centre stays at the last reliable
//!    position and the radius r(t) = min(r0 + growth (t − t_reliable), r_max) grows
//!    with the time since (seed 000 §3.2, Fig. 3: "when GPS positioning result is not
//!    reliable, we can deduce user's position with previous reliable GPS positioning
//!    results and increase the radius of the circle"). The circle is the region a walker
//!    can have reached since the last reliable fix; centring it on the latest unreliable
//!    estimate instead would let a drifting filter drag the FM search after itself, so
//!    that its FM fixes confirm the drift. Before the first reliable fix, without an
//!    aiding estimator or with the constraint disabled, every RP is searched;
//! 3. runs WKNN ([`super::wknn::locate`]) and emits a
//!    `Measurement::Position(PositionFix)` in ECEF with R_f rotated from ENU and
//!    `support` = the RPs inside the circle (seed 000 eqs. 18–19).
//!
//! An epoch whose search fails (no comparable RP, or no RP in the circle under the
//! `error` policy) emits nothing; the failures are counted in [`FmSource::warnings`].
//!
//! The mean RSSI of step 1 depends only on the place and the master seed, so when the
//! truth is the same in every trial of a run it is computed once per run
//! ([`FmEpochTable`], see [`crate::engine::cache`]); the trial draws only the scan noise.

use super::database::FingerprintDb;
use super::field::{FmField, FmFieldConfig, FmStation};
use super::survey::SurveyConfig;
use super::wknn::{locate, Constraint, ConstraintConfig, WknnConfig, WknnScratch};
use crate::core::config::check;
use crate::core::rng::StreamRng;
use crate::core::{ConfigIssue, EnuFrame, SimTime, TrialRng};
use crate::engine::cache::EpochTable;
use crate::measurement::{
    Measurement, MeasurementBatch, PositionFix, SampleContext, Source, SourceKind, Truth,
};
use crate::propagation::pathloss::ValidityLog;
use crate::propagation::Scene;
use serde::Deserialize;
use std::sync::Arc;

fn one() -> f64 {
    1.0
}

/// `[sensors.fm]` in a world file.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FmSensorConfig {
    /// Fix rate (Hz), default 1.
    #[serde(default = "one")]
    pub rate_hz: f64,
    /// The fingerprint database file (the world layer loads it with
    /// [`FingerprintDb::load`] and passes it to [`FmSource::new`]).
    #[serde(default)]
    pub database: Option<String>,
    /// Total number of stations; the world's declared FM stations are completed with
    /// [`super::field::synthesize_stations`] up to it (0, the default: only the declared).
    #[serde(default)]
    pub synthetic_stations_total: usize,
    /// The RSSI field and the receiver.
    #[serde(default)]
    pub field: FmFieldConfig,
    /// The WKNN search.
    #[serde(default)]
    pub wknn: WknnConfig,
    /// The constraint circle.
    #[serde(default)]
    pub constraint: ConstraintConfig,
    /// The offline survey a world runs when it names no `database` file.
    #[serde(default)]
    pub survey: FmSurveySpec,
}

/// `[sensors.fm.survey]`: the offline survey the world runs (once per master seed) when
/// `database` is not given. Seed 000 surveyed 282 RPs on its ~380 m campus and kriged them
/// to 16 640 RPs on a 3 m grid; the defaults reproduce that density: surveyed RPs every
/// 24 m and the kriged grid every 3 m over the trajectory's bounding box widened by
/// `margin_m`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct FmSurveySpec {
    /// Spacing of the surveyed reference points (m); default 24.
    #[schemars(range(min = 1.0, max = 10_000.0))]
    pub rp_spacing_m: f64,
    /// Spacing of the kriged fingerprint grid (m); default 3.
    #[schemars(range(min = 0.5, max = 10_000.0))]
    pub grid_spacing_m: f64,
    /// Northward spacing of the surveyed RPs (m), when it differs from `rp_spacing_m`
    /// (which is then the eastward one): a survey driven along parallel east-west lanes
    /// has one row of RPs per lane. Default: `rp_spacing_m`.
    #[schemars(range(min = 1.0, max = 10_000.0))]
    pub rp_spacing_north_m: Option<f64>,
    /// Northward spacing of the kriged grid (m), likewise; default `grid_spacing_m`.
    #[schemars(range(min = 0.5, max = 10_000.0))]
    pub grid_spacing_north_m: Option<f64>,
    /// How far the surveyed area extends beyond the trajectory's bounding box (m).
    pub margin_m: f64,
    /// The surveyed area `[[e_min, n_min], [e_max, n_max]]` (ENU, m); default: the
    /// trajectory's bounding box widened by `margin_m`.
    pub area_enu_m: Option<[[f64; 2]; 2]>,
    /// Scans averaged per surveyed RP and the surveyor's per-scan noise σ (dB).
    pub scans_per_point: u32,
    /// The surveyor's per-scan noise σ (dB).
    pub noise_sigma_db: f64,
    /// σ (dB) of the field's change between the survey and the test (another time and
    /// receiver; [`SurveyConfig::time_variation_sigma_db`]), default 0.
    pub time_variation_sigma_db: f64,
    /// Decorrelation distance (m) of that change, default 37.
    pub time_variation_decorrelation_m: f64,
}

impl Default for FmSurveySpec {
    fn default() -> Self {
        let s = SurveyConfig::default();
        Self {
            rp_spacing_m: 24.0,
            grid_spacing_m: 3.0,
            rp_spacing_north_m: None,
            grid_spacing_north_m: None,
            margin_m: 30.0,
            area_enu_m: None,
            scans_per_point: s.scans_per_point,
            noise_sigma_db: s.noise_sigma_db,
            time_variation_sigma_db: s.time_variation_sigma_db,
            time_variation_decorrelation_m: s.time_variation_decorrelation_m,
        }
    }
}

impl FmSurveySpec {
    /// The surveyor's scan settings.
    pub fn scan(&self) -> SurveyConfig {
        SurveyConfig {
            scans_per_point: self.scans_per_point,
            noise_sigma_db: self.noise_sigma_db,
            time_variation_sigma_db: self.time_variation_sigma_db,
            time_variation_decorrelation_m: self.time_variation_decorrelation_m,
        }
    }

    /// The surveyed RPs' spacing `[east, north]` (m).
    pub fn rp_spacing_en_m(&self) -> [f64; 2] {
        [
            self.rp_spacing_m,
            self.rp_spacing_north_m.unwrap_or(self.rp_spacing_m),
        ]
    }

    /// The kriged grid's spacing `[east, north]` (m).
    pub fn grid_spacing_en_m(&self) -> [f64; 2] {
        [
            self.grid_spacing_m,
            self.grid_spacing_north_m.unwrap_or(self.grid_spacing_m),
        ]
    }

    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        let [_, rp_north] = self.rp_spacing_en_m();
        let [_, grid_north] = self.grid_spacing_en_m();
        for (k, v, lo) in [
            ("rp_spacing_m", self.rp_spacing_m, 1.0),
            ("grid_spacing_m", self.grid_spacing_m, 0.5),
            ("rp_spacing_north_m", rp_north, 1.0),
            ("grid_spacing_north_m", grid_north, 0.5),
            ("margin_m", self.margin_m, 0.0),
        ] {
            check(k, v.is_finite() && v >= lo && v <= 10_000.0, || {
                format!("expected a distance in [{lo}, 10 000] m, got {v}")
            })?;
        }
        if let Some([lo, hi]) = self.area_enu_m {
            check(
                "area_enu_m",
                lo.iter().chain(&hi).all(|v| v.is_finite()) && hi[0] > lo[0] && hi[1] > lo[1],
                || {
                    format!("expected [[e_min, n_min], [e_max, n_max]] with max > min, got {lo:?}, {hi:?}")
                },
            )?;
            // The survey and its kriged grid are allocated from these counts: refuse an
            // area that would need more than the grid builder's 10 million points here,
            // with the key's line, rather than when the first trial builds it.
            for (k, [se, sn]) in [
                ("rp_spacing_m", self.rp_spacing_en_m()),
                ("grid_spacing_m", self.grid_spacing_en_m()),
            ] {
                let ne = ((hi[0] - lo[0]) / se).floor() + 1.0;
                let nn = ((hi[1] - lo[1]) / sn).floor() + 1.0;
                check("area_enu_m", ne * nn <= 1e7, || {
                    format!(
                        "{:.0} × {:.0} m at {k} = {se} m (east) × {sn} m (north) is {:.3e} points; expected at most 10 million (a smaller area or a coarser spacing)",
                        hi[0] - lo[0],
                        hi[1] - lo[1],
                        ne * nn
                    )
                })?;
            }
        }
        self.scan().validate()
    }
}

impl Default for FmSensorConfig {
    fn default() -> Self {
        Self {
            rate_hz: one(),
            database: None,
            synthetic_stations_total: 0,
            field: FmFieldConfig::default(),
            wknn: WknnConfig::default(),
            constraint: ConstraintConfig::default(),
            survey: FmSurveySpec::default(),
        }
    }
}

impl FmSensorConfig {
    /// Checks every value; the key is the field's path (`"wknn.k"`).
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check(
            "rate_hz",
            self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 100.0,
            || format!("expected a rate in (0, 100] Hz, got {}", self.rate_hz),
        )?;
        check(
            "synthetic_stations_total",
            self.synthetic_stations_total <= 50,
            || {
                format!(
                    "expected at most 50 stations in all (the FM band at 400 kHz spacing), got {}",
                    self.synthetic_stations_total
                )
            },
        )?;
        self.field.validate().map_err(|c| prefixed("field", c))?;
        self.wknn.validate().map_err(|c| prefixed("wknn", c))?;
        self.constraint
            .validate()
            .map_err(|c| prefixed("constraint", c))?;
        self.survey.validate().map_err(|c| prefixed("survey", c))
    }
}

fn prefixed(table: &str, c: ConfigIssue) -> ConfigIssue {
    ConfigIssue::new(format!("{table}.{}", c.key), c.message)
}

/// The mean RSSI of every station at every epoch of a run whose truth is the same in every
/// trial (see [`crate::engine::cache`]), with the field's warning state after each epoch.
#[derive(Debug)]
pub struct FmEpochTable {
    /// Per epoch: one mean RSSI (dBm) per station, and the field's validity log and
    /// warning count after it.
    table: EpochTable<f64, (ValidityLog, u32)>,
    /// The field's warnings, in the order it gave them.
    warnings: Vec<String>,
}

impl FmEpochTable {
    /// Fills the table for the receiver `cfg` with the world's declared `stations`
    /// (completed as [`FmSource::new`] completes them), `scene` and `master_seed`, at every
    /// epoch `0, 1/rate, …, end`, `truth_of` giving the engine's truth at each; at most
    /// `max_bytes`.
    ///
    /// # Errors
    /// As [`FmSource::new`], for an invalid configuration or station.
    pub fn build(
        cfg: &FmSensorConfig,
        stations: &[FmStation],
        scene: Option<Arc<Scene>>,
        master_seed: u64,
        end: SimTime,
        max_bytes: usize,
        truth_of: &mut dyn FnMut(SimTime) -> Truth,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let mut field = source_field(cfg, stations, scene, master_seed)?;
        let n = field.stations().len();
        let table = EpochTable::build(
            period_ns(cfg.rate_hz),
            end,
            max_bytes,
            truth_of,
            |truth, out| {
                let k = out.len();
                out.resize(k + n, 0.0);
                field.mean_rssi_dbm(&truth.enu.pos_enu_m, &mut out[k..]);
                let (log, warned) = field.log_state();
                (log, warned as u32)
            },
        );
        Ok(Self {
            table,
            warnings: field.warnings().to_vec(),
        })
    }

    /// Epochs held.
    pub fn len(&self) -> usize {
        self.table.len()
    }

    /// Whether the table holds no epoch.
    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }

    /// Whether the byte bound stopped the table before the source's last epoch.
    pub fn truncated(&self) -> bool {
        self.table.truncated()
    }

    /// Approximate heap bytes held.
    pub fn bytes(&self) -> usize {
        self.table.bytes() + self.warnings.iter().map(|w| w.len()).sum::<usize>()
    }
}

/// The field a source of `cfg` measures: the declared stations completed to
/// `synthetic_stations_total` with the master seed, the same completion (same seed, same
/// stream) as the survey that built the database, so the synthetic stations are the same.
fn source_field(
    cfg: &FmSensorConfig,
    stations: &[FmStation],
    scene: Option<Arc<Scene>>,
    master_seed: u64,
) -> Result<FmField, ConfigIssue> {
    let stations =
        super::field::synthesize_stations(stations, cfg.synthetic_stations_total, master_seed);
    FmField::new(cfg.field.clone(), stations, scene, master_seed)
}

fn period_ns(rate_hz: f64) -> i64 {
    ((1e9 / rate_hz).round() as i64).max(1)
}

/// The FM fingerprinting source.
pub struct FmSource {
    cfg: FmSensorConfig,
    field: FmField,
    /// The run's cached mean RSSI; dropped at the first epoch it does not hold.
    table: Option<Arc<FmEpochTable>>,
    /// The field's warning state after the last epoch served from the table.
    table_state: Option<(ValidityLog, u32)>,
    frame: EnuFrame,
    db: Arc<FingerprintDb>,
    aid: Option<usize>,
    rng: StreamRng,
    /// For each database channel, the index of its station in the field, if any.
    channel_station: Vec<Option<usize>>,
    scan_buf: Vec<f64>,
    meas_buf: Vec<f64>,
    scratch: WknnScratch,
    last_reliable_s: Option<f64>,
    /// The aiding estimate's horizontal position (ENU, m) at `last_reliable_s`.
    last_reliable_en_m: [f64; 2],
    period_ns: i64,
    end: SimTime,
    failures: u64,
    last_failure: Option<String>,
}

impl FmSource {
    /// Builds the source. `stations` are the world's declared FM stations, completed to
    /// `cfg.synthetic_stations_total` by [`super::field::synthesize_stations`] with the
    /// master seed (build the survey's field the same way); each database channel is
    /// matched to the station with its id. `rng` gives the scan
    /// stream `fm/scan` and its master seed keys the shadowing (`fm/shadowing/<id>`), as
    /// in the survey that built the database. `aid` is the index of the estimator whose
    /// estimate centres the constraint circle. Samples run from 0 to `end`.
    ///
    /// Errors (with the offending key) for an invalid configuration or station, or a
    /// database sharing fewer than `wknn.min_common_channels` channels with the stations.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        cfg: FmSensorConfig,
        stations: Vec<FmStation>,
        scene: Option<Arc<Scene>>,
        frame: EnuFrame,
        db: Arc<FingerprintDb>,
        rng: &TrialRng,
        aid: Option<usize>,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let field = source_field(&cfg, &stations, scene, rng.master_seed())?;
        let channel_station: Vec<Option<usize>> = db
            .channels()
            .iter()
            .map(|ch| field.stations().iter().position(|s| s.id == ch.id))
            .collect();
        let shared = channel_station.iter().flatten().count();
        check("database", shared >= cfg.wknn.min_common_channels, || {
            format!(
                "expected the database to share at least {} channels with the FM stations, got {shared} (database channels: {})",
                cfg.wknn.min_common_channels,
                db.channels().iter().map(|c| c.id.as_str()).collect::<Vec<_>>().join(", ")
            )
        })?;
        let n_st = field.stations().len();
        let n_ch = db.channels().len();
        Ok(Self {
            period_ns: period_ns(cfg.rate_hz),
            scratch: WknnScratch::new(cfg.wknn.k),
            cfg,
            field,
            table: None,
            table_state: None,
            frame,
            db,
            aid,
            rng: rng.stream("fm/scan"),
            channel_station,
            scan_buf: vec![0.0; n_st],
            meas_buf: vec![f64::NAN; n_ch],
            last_reliable_s: None,
            last_reliable_en_m: [0.0; 2],
            end,
            failures: 0,
            last_failure: None,
        })
    }

    /// Uses the run's cached mean RSSI at the epochs `table` holds (built by
    /// [`FmEpochTable::build`] for this source's configuration, stations, scene and master
    /// seed); the scans, fixes and warnings are the same with or without it.
    pub fn with_table(mut self, table: Option<Arc<FmEpochTable>>) -> Self {
        self.table = table;
        self
    }

    /// The mean RSSI of every station at `truth` into the scan buffer: from the table while
    /// it holds the epochs, then (for good) from the field, which takes over the warning
    /// state the table had reached.
    fn mean_rssi(&mut self, truth: &Truth) {
        if let Some(t) = &self.table {
            if let Some((means, state)) = t.table.epoch(truth) {
                self.scan_buf.copy_from_slice(means);
                self.table_state = Some(*state);
                return;
            }
            if let Some((log, warned)) = self.table_state {
                self.field.restore_log(log, &t.warnings[..warned as usize]);
            }
            self.table = None;
        }
        self.field
            .mean_rssi_dbm(&truth.enu.pos_enu_m, &mut self.scan_buf);
    }

    /// The constraint for this epoch from the aiding estimate, updating the time of the
    /// last reliable fix.
    fn constraint(&mut self, ctx: &SampleContext<'_>, t_s: f64) -> Option<Constraint> {
        if !self.cfg.constraint.enabled {
            return None;
        }
        let est = ctx.estimates.get(self.aid?)?.as_ref()?;
        let r = self.frame.rotation();
        let cov_enu = r * est.cov_pos_m2 * r.transpose();
        let sigma_h = (0.5 * (cov_enu[(0, 0)] + cov_enu[(1, 1)])).max(0.0).sqrt();
        if sigma_h <= self.cfg.constraint.reliable_sigma_m {
            let c = self.frame.enu_of_ecef(&est.pos_ecef_m);
            self.last_reliable_s = Some(t_s);
            self.last_reliable_en_m = [c.x, c.y];
        }
        let since = t_s - self.last_reliable_s?;
        Some(Constraint {
            centre_en_m: self.last_reliable_en_m,
            radius_m: self.cfg.constraint.radius_m(since),
        })
    }
}

impl Source for FmSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Fm
    }

    fn first_sample(&self) -> SimTime {
        SimTime(0)
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        let truth = ctx.truth;
        out.t = truth.t;
        out.source = SourceKind::Fm;
        let t_s = truth.sim.seconds();
        self.mean_rssi(truth);
        self.field.read_scan(&mut self.rng, &mut self.scan_buf);
        for (m, st) in self.meas_buf.iter_mut().zip(&self.channel_station) {
            *m = st.map_or(f64::NAN, |s| self.scan_buf[s]);
        }
        if let Some(raw) = out.raw.as_mut() {
            // The whole scan, every station the field holds, as a scanner would log it.
            for (st, &rssi_dbm) in self.field.stations().iter().zip(&self.scan_buf) {
                raw.fm_rssi.push((st.freq_hz * 1e-6, rssi_dbm));
            }
        }
        let constraint = self.constraint(ctx, t_s);
        match locate(
            &self.db,
            &self.meas_buf,
            &self.cfg.wknn,
            constraint.as_ref(),
            self.cfg.constraint.no_rp,
            &mut self.scratch,
        ) {
            Ok(fix) => {
                let r = self.frame.rotation();
                out.items.push(Measurement::Position(PositionFix {
                    pos_ecef_m: self.frame.ecef_of_enu(&fix.pos_enu_m),
                    cov_m2: r.transpose() * fix.cov_enu_m2 * r,
                    support: fix.support,
                }));
            }
            Err(e) => {
                self.failures += 1;
                self.last_failure = Some(e.to_string());
            }
        }
        let next = truth.sim.0 + self.period_ns;
        (next <= self.end.0).then_some(SimTime(next))
    }

    fn warnings(&self) -> Vec<String> {
        let mut w = match (&self.table, self.table_state) {
            (Some(t), Some((_, warned))) => t.warnings[..warned as usize].to_vec(),
            _ => self.field.warnings().to_vec(),
        };
        if let Some(last) = &self.last_failure {
            w.push(format!(
                "FM fingerprinting produced no fix at {} epochs (last: {last})",
                self.failures
            ));
        }
        w
    }
}
