//! The GNSS receiver as a measurement source: pseudoranges, pseudorange rates and C/N0
//! from broadcast orbits, with the receiver clock, the atmosphere, broadcast-orbit errors,
//! tracking noise, an elevation mask and manual satellite shielding.
//!
//! Truth and correction (per satellite s, reception time t_r, transmission t_t = t_r − τ):
//!
//! ```text
//! τ        solves  τ = ‖R_z(−Ω̇e τ)·r_s(t_t) − r_r(t_r)‖ / c      (light time + Sagnac)
//! ρ_raw    = ‖·‖ + c(δt_r + ISB_sys − δt_s) + I_true + T_true + e_ure + ε_dll
//! ρ_corr   = ρ_raw + c·δt_s − I_model − T_model
//!          = ‖·‖ + c(δt_r + ISB_sys) + (I_true − I_model) + (T_true − T_model) + e_ure + ε_dll
//! ρ̇_corr  = u·(v_s − v_r) + c·δṫ_r + ε_fll,     u = (r_s − r_r)/‖r_s − r_r‖
//! ```
//! `I_model` is Klobuchar (IS-GPS-200 §20.3.3.5.2.5) scaled by (f_L1/f)² for BeiDou B1I;
//! `I_true = I_model·(1 + k + k_s)` with a residual factor k ~ N(0, σ_iono²) common to
//! the trial (Klobuchar removes roughly half of the delay, and what it misses is mostly
//! large-scale) and a small per-satellite part k_s ~ N(0, σ_iono,sat²). `T_model` is Saastamoinen; `T_true = T_model·(1 + k_T)`, k_T ~ N(0, σ_trop²)
//! per trial. The broadcast orbit-and-clock error `e_ure` is a first-order Gauss–Markov
//! process per satellite (σ_URE, τ_URE). ε_dll and ε_fll come from the C/N0 through the
//! tracking-loop models of [`crate::gnss::link`].
//!
//! In a world with a scene, each satellite link goes through
//! [`crate::gnss::visibility::scene_effect`]: the C/N0 drops by the walls and foliage in
//! the way (and rises or falls with the multipath interference at the prompt correlator),
//! a satellite whose C/N0 falls below the lock threshold is lost, and the pseudorange
//! gains the DLL's multipath error `e_mp` (the whole excess path when only a reflection is
//! tracked, the NLOS bias) and the range rate the Doppler difference of the tracked path:
//! `ρ_corr += e_mp`, `ρ̇_corr += −v_r·(a_tracked − a_direct)`.
//!
//! The σ the receiver reports to estimators is its own error model, which knows the
//! magnitudes but not the realisations:
//! σ² = σ_dll² + σ_URE² + ((σ_iono² + σ_iono,sat²)^½·I_model)² + (σ_trop·T_model)².
//!
//! The receiver is split in two: [`GnssGeometry`] computes everything above that does not
//! depend on the trial's draws (satellites in view after shielding, transmit-time orbits,
//! the scene's effect, I_model, T_model, the σs) as a list of [`LinkGeometry`], and
//! [`GnssSource`] adds the trial's clock, atmosphere residuals, URE and tracking noise.
//! When the truth is the same in every trial of a run the links are computed once per run
//! ([`GnssEpochTable`], see [`crate::engine::cache`]).

use crate::core::geodesy::{azimuth_elevation_with, ecef_to_enu_rotation};
use crate::core::receiver_clock::ClockTrack;
use crate::core::rng::{StreamRng, TrialRng};
use crate::core::{EmitterId, EnuFrame, Geodetic, SimTime, System, C_MPS};
use crate::engine::cache::EpochTable;
use crate::gnss::atmosphere::{saastamoinen_m, Klobuchar};
use crate::gnss::ephemeris::sagnac_rotate;
use crate::gnss::link::{Signal, TrackingConfig};
use crate::gnss::rinex_nav::NavData;
use crate::gnss::visibility::{scene_effect, LinkClass};
use crate::measurement::{
    Measurement, MeasurementBatch, RangeMeasurement, RawGnssObservation, SampleContext, Source,
    SourceKind, Truth,
};
use crate::propagation::{LinkPaths, Scene};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;
use std::sync::Arc;

/// GPS L1 and BeiDou B1I carrier frequencies (Hz).
pub const F_L1_HZ: f64 = 1_575.42e6;
pub const F_B1I_HZ: f64 = 1_561.098e6;

fn default_systems() -> Vec<System> {
    vec![System::Gps]
}
/// A satellite system a GNSS receiver tracks: the values `systems` accepts. The
/// terrestrial systems (DTMB, TC-OFDM) are `System` values too, but have sensors of their
/// own, so they are not offered here.
#[derive(serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
enum Satellite {
    /// GPS L1 C/A.
    Gps,
    /// BeiDou B1I.
    Bds,
}

/// Reads `systems`, offering only the satellite systems ([`Satellite`]).
fn gnss_systems<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<System>, D::Error> {
    Ok(Vec::<Satellite>::deserialize(d)?
        .into_iter()
        .map(|s| match s {
            Satellite::Gps => System::Gps,
            Satellite::Bds => System::Bds,
        })
        .collect())
}

fn default_rate_hz() -> f64 {
    1.0
}
fn default_mask_deg() -> f64 {
    10.0
}
fn default_true() -> bool {
    true
}

/// Error budget of the simulated GNSS receiver beyond tracking noise.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GnssErrorConfig {
    /// 1-σ broadcast orbit + clock error (user range error) for GPS, m.
    pub ure_gps_m: f64,
    /// 1-σ user range error for BeiDou, m.
    pub ure_bds_m: f64,
    /// Correlation time of the user range error, s.
    pub ure_tau_s: f64,
    /// 1-σ relative residual of the Klobuchar model common to every satellite of a trial
    /// (the large-scale part of the ionosphere the model misses; 0.4: 40 % remains).
    pub iono_residual: f64,
    /// 1-σ relative residual of the Klobuchar model per satellite (small-scale structure).
    pub iono_residual_per_sat: f64,
    /// 1-σ relative residual of the Saastamoinen model.
    pub tropo_residual: f64,
    /// Relative humidity used by the receiver's troposphere model (0–1).
    pub humidity: f64,
}

impl Default for GnssErrorConfig {
    fn default() -> Self {
        Self {
            ure_gps_m: 0.8,
            ure_bds_m: 1.2,
            ure_tau_s: 1800.0,
            iono_residual: 0.4,
            iono_residual_per_sat: 0.1,
            tropo_residual: 0.05,
            humidity: 0.5,
        }
    }
}

/// `[sensors.gnss]` in a world file.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GnssConfig {
    /// Systems tracked: `"gps"`, `"bds"`.
    #[serde(default = "default_systems", deserialize_with = "gnss_systems")]
    #[schemars(with = "Vec<Satellite>", length(min = 1))]
    pub systems: Vec<System>,
    /// Measurement rate (Hz).
    #[serde(default = "default_rate_hz")]
    #[schemars(range(min = 1e-3, max = 100.0))]
    pub rate_hz: f64,
    /// Elevation mask (degrees), at least -5° and below 90°.
    #[serde(default = "default_mask_deg")]
    #[schemars(range(min = -5.0), extend("exclusiveMaximum" = 90.0))]
    pub elevation_mask_deg: f64,
    /// Whether pseudorange rates are output.
    #[serde(default = "default_true")]
    pub range_rates: bool,
    /// Tracking loops and the loss-of-lock threshold.
    #[serde(default)]
    pub tracking: TrackingConfig,
    /// Orbit, clock and atmosphere error budget.
    #[serde(default)]
    pub errors: GnssErrorConfig,
    /// Whether the world's scene (buildings, foliage, reflections) acts on the satellite
    /// links; default true. Off, the receiver sees an open sky whatever the scene.
    #[serde(default = "default_true")]
    pub scene: bool,
}

impl Default for GnssConfig {
    fn default() -> Self {
        Self {
            systems: default_systems(),
            rate_hz: default_rate_hz(),
            elevation_mask_deg: default_mask_deg(),
            range_rates: true,
            tracking: TrackingConfig::default(),
            errors: GnssErrorConfig::default(),
            scene: true,
        }
    }
}

/// Manual shielding over a time window, as in seed 000's experiments.
#[derive(Clone, Debug, PartialEq)]
pub struct Shielding {
    pub from_s: f64,
    pub to_s: f64,
    pub rule: ShieldingRule,
}

/// Which satellites survive a shielding window.
#[derive(Clone, Debug, PartialEq)]
pub enum ShieldingRule {
    /// Keep only the N highest satellites of each system.
    KeepHighest(usize),
    /// Keep only these satellites.
    Keep(Vec<EmitterId>),
    /// Remove these satellites.
    Block(Vec<EmitterId>),
}

/// Per-satellite state of the simulated receiver.
struct Channel {
    sat: EmitterId,
    rng: StreamRng,
    ure_m: f64,
    iono_factor: f64,
    /// The carrier-phase arc a dataset export logs (created at the first raw epoch, so a
    /// Monte Carlo trial never builds it).
    raw: Option<PhaseArc>,
}

/// A channel's carrier tracking as logged for RINEX: its own random stream (phase noise,
/// ambiguities), the integer ambiguity of the current arc and the last epoch it tracked.
struct PhaseArc {
    rng: StreamRng,
    ambiguity_cycles: f64,
    last: Option<SimTime>,
}

/// A satellite above the mask at one epoch, before shielding.
#[derive(Clone, Copy)]
struct Candidate {
    channel: usize,
    el_rad: f64,
    az_rad: f64,
    pos_rot: Vector3<f64>,
    vel_rot: Vector3<f64>,
}

/// The scene a receiver's links pass through, with the world frame its geometry uses.
pub struct SceneView {
    pub scene: Arc<Scene>,
    pub frame: EnuFrame,
    /// The caller-owned path buffer of [`Scene::link`].
    paths: LinkPaths,
}

impl SceneView {
    pub fn new(scene: Arc<Scene>, frame: EnuFrame) -> Self {
        Self {
            scene,
            frame,
            paths: LinkPaths::new(),
        }
    }
}

/// The deterministic part of one tracked satellite link at one epoch: what the orbits, the
/// receiver's position, the scene and the broadcast models fix, and nothing a trial draws.
///
/// A link is listed only when the receiver tracks it (not lost in the scene, C/N0 above
/// the lock threshold). With `u = (r_s − r_r)/‖r_s − r_r‖` the trial adds, per the module
/// documentation,
///
/// ```text
/// ρ_corr  = range_m + c(δt_r + ISB_sys) + iono_model_m·k + tropo_model_m·k_T + e_ure
///           + scene_code_m + sigma_dll_m·n
/// ρ̇_corr = geometric_rate_mps + c·δṫ_r + scene_rate_mps + sigma_rate_mps·n'
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkGeometry {
    /// The satellite's index in the receiver's channel list ([`GnssGeometry::satellites`]).
    pub channel: u32,
    pub el_rad: f64,
    /// Transmit-time position and velocity in the reception-time ECEF frame.
    pub pos_ecef_m: Vector3<f64>,
    pub vel_ecef_mps: Vector3<f64>,
    /// ‖r_s − r_r‖ (m).
    pub range_m: f64,
    /// u·(v_s − v_r) (m/s).
    pub geometric_rate_mps: f64,
    /// C/N0 after the scene (dB-Hz).
    pub cn0_dbhz: f64,
    /// The scene's code (multipath, NLOS) and range-rate errors.
    pub scene_code_m: f64,
    pub scene_rate_mps: f64,
    /// Tracking-noise σ of the code and of the range rate at this C/N0.
    pub sigma_dll_m: f64,
    pub sigma_rate_mps: f64,
    /// Klobuchar (scaled to the signal's frequency) and Saastamoinen delays (m).
    pub iono_model_m: f64,
    pub tropo_model_m: f64,
    /// The σ the receiver reports.
    pub sigma_m: f64,
}

/// The geometry half of the receiver: which satellites it tracks at an epoch and the
/// deterministic terms of each link ([`LinkGeometry`]). A trial's [`GnssSource`] runs it
/// at every epoch the run's [`GnssEpochTable`] does not hold.
pub struct GnssGeometry {
    cfg: GnssConfig,
    nav: Arc<NavData>,
    klobuchar: Option<Klobuchar>,
    shielding: Vec<Shielding>,
    scene: Option<SceneView>,
    sats: Vec<EmitterId>,
    candidates: Vec<Candidate>,
}

/// The links of every epoch of a run whose truth does not change between trials (see
/// [`crate::engine::cache`]).
pub type GnssEpochTable = EpochTable<LinkGeometry>;

impl GnssGeometry {
    /// The geometry of a receiver configured by `cfg` (its systems, mask, tracking loops,
    /// error budget, whether the scene applies).
    pub fn new(
        cfg: &GnssConfig,
        nav: Arc<NavData>,
        shielding: Vec<Shielding>,
        scene: Option<SceneView>,
    ) -> Self {
        let sats: Vec<EmitterId> = nav
            .satellites()
            .into_iter()
            .filter(|s| cfg.systems.contains(&s.system))
            .collect();
        Self {
            cfg: cfg.clone(),
            klobuchar: nav.klobuchar,
            nav,
            shielding,
            scene: scene.filter(|_| cfg.scene),
            candidates: Vec::with_capacity(sats.len()),
            sats,
        }
    }

    /// The receiver's channels: the satellites of its systems in the navigation data, in
    /// id order.
    pub fn satellites(&self) -> &[EmitterId] {
        &self.sats
    }

    /// The epoch between sample times of a receiver at `rate_hz` (ns).
    pub fn step_ns(rate_hz: f64) -> i64 {
        (1e9 / rate_hz).round() as i64
    }

    /// Fills a table with the links of every epoch `0, step, …, end`, `truth_of` giving the
    /// engine's truth at each; at most `max_bytes`.
    pub fn table(
        &mut self,
        end: SimTime,
        max_bytes: usize,
        truth_of: &mut dyn FnMut(SimTime) -> Truth,
    ) -> GnssEpochTable {
        EpochTable::build(
            Self::step_ns(self.cfg.rate_hz),
            end,
            max_bytes,
            truth_of,
            |truth, out| self.epoch(truth, out),
        )
    }

    fn sigma_ure(&self, sys: System) -> f64 {
        match sys {
            System::Bds => self.cfg.errors.ure_bds_m,
            _ => self.cfg.errors.ure_gps_m,
        }
    }

    /// Applies the shielding windows active at `t_s` to the candidates.
    fn apply_shielding(&mut self, t_s: f64) {
        for w in &self.shielding {
            if t_s < w.from_s || t_s >= w.to_s {
                continue;
            }
            let sats = &self.sats;
            match &w.rule {
                ShieldingRule::KeepHighest(n) => {
                    // Keep the N highest satellites of each system. Sorting by system,
                    // then elevation (highest first), then id makes the choice independent
                    // of the order of the navigation file.
                    self.candidates.sort_by(|a, b| {
                        let (sa, sb) = (sats[a.channel], sats[b.channel]);
                        sa.system
                            .cmp(&sb.system)
                            .then(b.el_rad.total_cmp(&a.el_rad))
                            .then(sa.cmp(&sb))
                    });
                    let mut kept = 0usize;
                    let mut current: Option<System> = None;
                    self.candidates.retain(|c| {
                        let sys = sats[c.channel].system;
                        if current != Some(sys) {
                            current = Some(sys);
                            kept = 0;
                        }
                        kept += 1;
                        kept <= *n
                    });
                }
                ShieldingRule::Keep(list) => {
                    self.candidates.retain(|c| list.contains(&sats[c.channel]))
                }
                ShieldingRule::Block(list) => {
                    self.candidates.retain(|c| !list.contains(&sats[c.channel]))
                }
            }
        }
    }

    /// Appends the links the receiver tracks at `truth` to `out`, in channel order after
    /// shielding (the order in which a trial draws their noise).
    pub fn epoch(&mut self, truth: &Truth, out: &mut Vec<LinkGeometry>) {
        let rx = truth.pos_ecef_m;
        let rx_geo = Geodetic::from_ecef(&rx);
        let rot = ecef_to_enu_rotation(rx_geo.lat_rad, rx_geo.lon_rad);
        let mask = self.cfg.elevation_mask_deg.to_radians();

        self.candidates.clear();
        for (i, &sat) in self.sats.iter().enumerate() {
            let Some((pos_rot, vel_rot, az, el)) =
                satellite_in_view(&self.nav, sat, truth.t, &rx, &rot, mask)
            else {
                continue;
            };
            self.candidates.push(Candidate {
                channel: i,
                el_rad: el,
                az_rad: az,
                pos_rot,
                vel_rot,
            });
        }
        self.apply_shielding(truth.sim.seconds());

        for k in 0..self.candidates.len() {
            let c = self.candidates[k];
            let sat = self.sats[c.channel];
            let mut cn0 = self.cfg.tracking.cn0_dbhz(sat.system, c.el_rad);
            let (mut scene_code_m, mut scene_rate_mps) = (0.0, 0.0);
            if let (Some(view), Some(signal)) = (self.scene.as_mut(), Signal::of_system(sat.system))
            {
                let u_enu = view.frame.enu_vector_of_ecef(&(c.pos_rot - rx)).normalize();
                let effect = scene_effect(
                    &view.scene,
                    &self.cfg.tracking,
                    signal,
                    &truth.enu.pos_enu_m,
                    &truth.enu.vel_enu_mps,
                    &u_enu,
                    cn0,
                    &mut view.paths,
                );
                if let Some(e) = effect {
                    if e.class == LinkClass::Lost {
                        continue;
                    }
                    cn0 = e.cn0_dbhz;
                    scene_code_m = e.code_error_m;
                    scene_rate_mps = e.range_rate_error_mps;
                }
            }
            if !self.cfg.tracking.in_lock(cn0) {
                continue;
            }
            let sigma_dll = self.cfg.tracking.code_sigma_m(sat.system, cn0);
            let sigma_rate = self.cfg.tracking.rate_sigma_mps(sat.system, cn0);
            let sigma_ure = self.sigma_ure(sat.system);
            let freq_scale = if sat.system == System::Bds {
                (F_L1_HZ / F_B1I_HZ).powi(2)
            } else {
                1.0
            };
            let iono_model = self.klobuchar.map_or(0.0, |k| {
                k.delay_l1_m(rx_geo.lat_rad, rx_geo.lon_rad, c.az_rad, c.el_rad, truth.t)
            }) * freq_scale;
            let tropo_model = saastamoinen_m(
                rx_geo.lat_rad,
                rx_geo.h_m,
                c.el_rad,
                self.cfg.errors.humidity,
            );
            let los = c.pos_rot - rx;
            let range = los.norm();
            let u = los / range;
            let sigma_m = (sigma_dll.powi(2)
                + sigma_ure.powi(2)
                + (self
                    .cfg
                    .errors
                    .iono_residual
                    .hypot(self.cfg.errors.iono_residual_per_sat)
                    * iono_model)
                    .powi(2)
                + (self.cfg.errors.tropo_residual * tropo_model).powi(2))
            .sqrt();
            out.push(LinkGeometry {
                channel: c.channel as u32,
                el_rad: c.el_rad,
                pos_ecef_m: c.pos_rot,
                vel_ecef_mps: c.vel_rot,
                range_m: range,
                geometric_rate_mps: u.dot(&(c.vel_rot - truth.vel_ecef_mps)),
                cn0_dbhz: cn0,
                scene_code_m,
                scene_rate_mps,
                sigma_dll_m: sigma_dll,
                sigma_rate_mps: sigma_rate,
                iono_model_m: iono_model,
                tropo_model_m: tropo_model,
                sigma_m,
            });
        }
    }
}

/// The GNSS receiver source.
pub struct GnssSource {
    cfg: GnssConfig,
    geometry: GnssGeometry,
    /// The run's cached links, when its truth is the same in every trial.
    table: Option<Arc<GnssEpochTable>>,
    clock: Arc<ClockTrack>,
    tropo_factor: f64,
    channels: Vec<Channel>,
    /// This epoch's links when the table does not hold it.
    links: Vec<LinkGeometry>,
    step_ns: i64,
    end: SimTime,
    last_sim: Option<SimTime>,
    /// The trial's streams, for the raw-observable streams made on demand.
    trial_rng: TrialRng,
}

impl GnssSource {
    /// Builds the receiver for one trial. `clock` is the receiver's clock track (shared
    /// with the receiver's other sources; already drawn
    /// from its own stream).
    pub fn new(
        cfg: GnssConfig,
        nav: Arc<NavData>,
        shielding: Vec<Shielding>,
        scene: Option<SceneView>,
        clock: Arc<ClockTrack>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Self {
        let mut trop_rng = rng.stream("gnss/tropo");
        let z: f64 = trop_rng.sample(StandardNormal);
        let tropo_factor = cfg.errors.tropo_residual * z;
        let mut iono_rng = rng.stream("gnss/iono");
        let z: f64 = iono_rng.sample(StandardNormal);
        let iono_common = cfg.errors.iono_residual * z;
        let geometry = GnssGeometry::new(&cfg, nav, shielding, scene);
        let channels = geometry
            .satellites()
            .iter()
            .map(|&sat| {
                let mut r = rng.stream(&format!("gnss/{sat}"));
                let sigma_ure = geometry.sigma_ure(sat.system);
                let z_ure: f64 = r.sample(StandardNormal);
                let z_iono: f64 = r.sample(StandardNormal);
                let ure_m = sigma_ure * z_ure;
                let iono_factor = iono_common + cfg.errors.iono_residual_per_sat * z_iono;
                Channel {
                    sat,
                    rng: r,
                    ure_m,
                    iono_factor,
                    raw: None,
                }
            })
            .collect::<Vec<_>>();
        Self {
            links: Vec::with_capacity(channels.len()),
            channels,
            step_ns: GnssGeometry::step_ns(cfg.rate_hz),
            geometry,
            table: None,
            cfg,
            clock,
            tropo_factor,
            end,
            last_sim: None,
            trial_rng: *rng,
        }
    }

    /// Uses the run's cached links at the epochs `table` holds (built by
    /// [`GnssGeometry::table`] for this receiver's configuration, world and truth); the
    /// measurements are the same with or without it.
    pub fn with_table(mut self, table: Option<Arc<GnssEpochTable>>) -> Self {
        self.table = table;
        self
    }

    /// Draws this trial's errors on `links` and emits the measurements.
    fn measure(&mut self, links: &[LinkGeometry], truth: &Truth, out: &mut MeasurementBatch) {
        let dt_s = self
            .last_sim
            .map_or(0.0, |l| (truth.sim.0 - l.0) as f64 * 1e-9);
        self.last_sim = Some(truth.sim);
        let t_s = truth.sim.seconds();
        let rx_bias_s = self.clock.bias_s(t_s);
        let rx_drift = self.clock.drift_s_per_s(t_s);
        // The user range error evolves as a first-order Gauss–Markov process between
        // epochs: e_k = φ e_{k−1} + σ√(1 − φ²) n_k, φ = exp(−Δt/τ).
        let phi = (-dt_s / self.cfg.errors.ure_tau_s).exp();
        let gm_scale = (1.0 - phi * phi).sqrt();
        for l in links {
            let ch = &mut self.channels[l.channel as usize];
            let sat = ch.sat;
            let sigma_ure = self.geometry.sigma_ure(sat.system);
            if dt_s > 0.0 {
                let n: f64 = ch.rng.sample(StandardNormal);
                ch.ure_m = phi * ch.ure_m + sigma_ure * gm_scale * n;
            }
            let n_code: f64 = ch.rng.sample(StandardNormal);
            let n_rate: f64 = ch.rng.sample(StandardNormal);
            let isb_s = self.clock.isb_s(sat.system, t_s);
            let pseudorange_m = l.range_m
                + C_MPS * (rx_bias_s + isb_s)
                + l.iono_model_m * ch.iono_factor
                + l.tropo_model_m * self.tropo_factor
                + ch.ure_m
                + l.scene_code_m
                + l.sigma_dll_m * n_code;
            let range_rate = l.geometric_rate_mps
                + C_MPS * rx_drift
                + l.scene_rate_mps
                + l.sigma_rate_mps * n_rate;
            if let Some(raw) = out.raw.as_mut() {
                let eph = self.geometry.nav.select(sat, truth.t);
                let (clock_s, drift) = eph.map_or((0.0, 0.0), |e| {
                    let st = e.state(truth.t.add_seconds(-l.range_m / C_MPS));
                    // IS-GPS-200 §20.3.3.3.3.2 (L1 C/A) and BDS-SIS-ICD §5.2.4.10 (B1I):
                    // the single-frequency user's satellite clock is Δt_sv − T_GD.
                    (st.clock_s - e.tgd_s, st.clock_drift_s_per_s)
                });
                let geometry = RawGeometry {
                    range_m: l.range_m,
                    rx_clock_m: C_MPS * (rx_bias_s + isb_s),
                    iono_m: l.iono_model_m * (1.0 + ch.iono_factor),
                    tropo_m: l.tropo_model_m * (1.0 + self.tropo_factor),
                    ure_m: ch.ure_m,
                    sat_clock_m: C_MPS * clock_s,
                    sat_drift_mps: C_MPS * drift,
                };
                raw.gnss.push(raw_observation(
                    ch,
                    &self.trial_rng,
                    truth.sim,
                    self.step_ns,
                    &geometry,
                    // The receiver removes the broadcast models it knows; the raw code has
                    // them back, and the satellite clock it never had.
                    pseudorange_m + l.iono_model_m + l.tropo_model_m - geometry.sat_clock_m,
                    range_rate,
                    l.cn0_dbhz,
                    rx_bias_s,
                ));
            }
            out.items.push(Measurement::Range(RangeMeasurement {
                emitter: sat,
                emitter_pos_ecef_m: l.pos_ecef_m,
                emitter_vel_ecef_mps: l.vel_ecef_mps,
                pseudorange_m,
                sigma_m: l.sigma_m,
                range_rate_mps: self.cfg.range_rates.then_some(range_rate),
                sigma_rate_mps: l.sigma_rate_mps,
                cn0_dbhz: l.cn0_dbhz,
                elevation_rad: l.el_rad,
            }));
        }
    }
}

/// The terms of one satellite's observables at one epoch (m, m/s).
struct RawGeometry {
    range_m: f64,
    /// c·(receiver clock + inter-system bias).
    rx_clock_m: f64,
    /// The true ionospheric group delay (the phase advances by as much).
    iono_m: f64,
    tropo_m: f64,
    ure_m: f64,
    /// c·(Δt_sv − T_GD), the broadcast satellite clock of the signal.
    sat_clock_m: f64,
    sat_drift_mps: f64,
}

/// Carrier-phase tracking noise (m): the PLL's thermal jitter
/// σ_φ = (λ/2π)·√(B_L/(C/N0)·(1 + 1/(2·T·C/N0))) (Kaplan & Hegarty, *Understanding GPS*,
/// 2nd ed., eq. 5.6) with a 15 Hz loop and 20 ms coherent integration.
fn phase_sigma_m(lambda_m: f64, cn0_dbhz: f64) -> f64 {
    let (b_l_hz, t_s) = (15.0, 0.02);
    let cn0 = 10f64.powf(cn0_dbhz / 10.0);
    lambda_m / std::f64::consts::TAU * (b_l_hz / cn0 * (1.0 + 1.0 / (2.0 * t_s * cn0))).sqrt()
}

/// The raw observables a receiver logs for one satellite (RINEX 3.04 §5.1):
///
/// ```text
/// C = ρ + c(δt_r + b_sys) − c(Δt_sv − T_GD) + I + T + e_URE + m + ε_code
/// L = [ρ + c(δt_r + b_sys) − c(Δt_sv − T_GD) − I + T + e_URE + ε_φ] / λ + N
/// D = −(ρ̇ + c·δṫ_r − c·Δṫ_sv) / λ
/// ```
///
/// The ionosphere delays the code and advances the carrier by the same amount
/// (code–carrier divergence); N is an integer, drawn anew when tracking resumes after a
/// gap, with the loss of lock flagged on that epoch. The phase is started within a few
/// hundred cycles of the code, as receivers do.
#[allow(clippy::too_many_arguments)]
fn raw_observation(
    ch: &mut Channel,
    trial_rng: &TrialRng,
    now: SimTime,
    step_ns: i64,
    g: &RawGeometry,
    code_m: f64,
    range_rate_mps: f64,
    cn0_dbhz: f64,
    rx_clock_s: f64,
) -> RawGnssObservation {
    let f_hz = if ch.sat.system == System::Bds {
        F_B1I_HZ
    } else {
        F_L1_HZ
    };
    let lambda_m = C_MPS / f_hz;
    let arc = ch.raw.get_or_insert_with(|| PhaseArc {
        rng: trial_rng.stream(&format!("gnss/raw/{}", ch.sat)),
        ambiguity_cycles: 0.0,
        last: None,
    });
    let n: f64 = arc.rng.sample(StandardNormal);
    let phase_m = g.range_m + g.rx_clock_m - g.sat_clock_m - g.iono_m
        + g.tropo_m
        + g.ure_m
        + phase_sigma_m(lambda_m, cn0_dbhz) * n;
    let lock_lost = arc.last.is_none_or(|l| now.0 - l.0 > step_ns);
    if lock_lost {
        let offset: i32 = arc.rng.random_range(-500..=500);
        arc.ambiguity_cycles = ((code_m - phase_m) / lambda_m).round() + f64::from(offset);
    }
    arc.last = Some(now);
    RawGnssObservation {
        sat: ch.sat,
        pseudorange_m: code_m,
        carrier_phase_cycles: phase_m / lambda_m + arc.ambiguity_cycles,
        doppler_hz: -(range_rate_mps - g.sat_drift_mps) / lambda_m,
        cn0_dbhz,
        lock_lost,
        rx_clock_s,
    }
}

/// A healthy satellite with a usable ephemeris above the elevation mask `mask_rad`, seen
/// from `rx` (ECEF, with `rot` its ECEF→ENU rotation) at `t`: its transmit-time position and
/// velocity in the reception-time frame ([`transmit_geometry`]), azimuth and elevation.
pub fn satellite_in_view(
    nav: &NavData,
    sat: EmitterId,
    t: crate::core::GpsTime,
    rx: &Vector3<f64>,
    rot: &nalgebra::Matrix3<f64>,
    mask_rad: f64,
) -> Option<(Vector3<f64>, Vector3<f64>, f64, f64)> {
    let eph = nav.select(sat, t).filter(|e| e.is_healthy())?;
    let (pos, vel) = transmit_geometry(eph, t, rx);
    let (az, el) = azimuth_elevation_with(rot, rx, &pos);
    (el >= mask_rad).then_some((pos, vel, az, el))
}

/// Position and velocity of a satellite at transmission time, rotated into the ECEF frame
/// of the reception time, with the light time τ found by fixed-point iteration.
pub fn transmit_geometry(
    eph: &crate::gnss::ephemeris::Ephemeris,
    t_rx: crate::core::GpsTime,
    rx: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    // Fixed-point iteration on the light time; it converges to 1e-12 s in two or three
    // steps from the nominal 75 ms of a MEO satellite.
    let mut tau = 0.075;
    let mut st = eph.state(t_rx.add_seconds(-tau));
    let mut pos = sagnac_rotate(&st.pos_ecef_m, tau);
    for _ in 0..4 {
        let new_tau = (pos - rx).norm() / C_MPS;
        let converged = (new_tau - tau).abs() < 1e-12;
        tau = new_tau;
        if converged {
            break;
        }
        st = eph.state(t_rx.add_seconds(-tau));
        pos = sagnac_rotate(&st.pos_ecef_m, tau);
    }
    (pos, sagnac_rotate(&st.vel_ecef_mps, tau))
}

impl Source for GnssSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Gnss
    }

    fn first_sample(&self) -> SimTime {
        SimTime(0)
    }

    fn empty_batches_are_epochs(&self) -> bool {
        true
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        let truth = ctx.truth;
        out.t = truth.t;
        out.source = SourceKind::Gnss;
        // The run's table when it holds this epoch at this truth, else this epoch's own
        // geometry: the same links either way.
        let table = self.table.take();
        match table.as_deref().and_then(|t| t.epoch(truth)) {
            Some((links, ())) => self.measure(links, truth, out),
            None => {
                let mut links = std::mem::take(&mut self.links);
                links.clear();
                self.geometry.epoch(truth, &mut links);
                self.measure(&links, truth, out);
                self.links = links;
            }
        }
        self.table = table;
        let next = SimTime(truth.sim.0 + self.step_ns);
        (next <= self.end).then_some(next)
    }
}
