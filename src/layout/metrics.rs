//! What a receiver at one grid cell would see: usable signals per system, the class of
//! each terrestrial link, the dilution of precision and the predicted position error.
//!
//! **Geometry.** Every usable range contributes the row `h_i = [−u_iᵀ, e_{c(i)}ᵀ]` of the
//! pseudorange Jacobian (seed 000 eqs. 9–13; Kaplan & Hegarty, *Understanding GPS*, 2nd
//! ed., §7.3), `u_i` the unit vector from the receiver to the emitter in local ENU axes and
//! `c(i)` the clock its range carries. The clock model ([`ClockModel`]) is either
//! `shared` (default): GPS, DTMB and TC-OFDM ranges carry the receiver clock and BeiDou
//! its own (the receiver clock plus the GPS–BDS inter-system bias), as in hybridnav's
//! EKF-11 state layout and seed 000's mode selection (§4, towers synchronised to GPS
//! time); or `per-system`: one clock per system, as the WLS snapshot solver does, in which
//! case a lone tower of a system adds nothing (its range is absorbed by its clock).
//! With `G = (Hᵀ H)⁻¹` and `C = (Hᵀ W H)⁻¹`, `W = diag(1/σ_i²)`:
//!
//! ```text
//! GDOP = √(tr G)                   (unweighted, textbook; clock columns in use only)
//! σ_3D = √(C_EE + C_NN + C_UU)     (predicted 3-D position error, 1σ, m)
//! ```
//!
//! Both are computed GNSS-only (GPS + BeiDou as the world's receiver tracks them) and
//! hybrid (GNSS + DTMB + TC-OFDM). A cell whose geometry does not determine position and
//! clocks has GDOP = σ_3D = +∞.
//!
//! **GNSS.** Satellites above the world's elevation mask at the region's centre (the
//! directions change by less than 10⁻⁴ rad across a few kilometres), with the open-sky
//! C/N0 of the world's tracking model and, when the world has a scene and
//! `sensors.gnss.scene` is on, the scene's effect ([`scene_effect`]: LOS, foliage, NLOS
//! through a reflection, or lost below the lock threshold). `σ_i² = σ_DLL(C/N0)² + URE² +
//! e_scene²`: the DLL jitter of the tracking model, the system's user range error, and the
//! multipath or NLOS code error the scene puts on the link (a bias, counted at its size).
//!
//! **Terrestrial.** As the DTMB and TC-OFDM sources (module `dtmb::source`): the
//! reference SNR `γ = ERP + 2.15 (the EIRP; + nav_power_db for TC-OFDM) + G_rx − L_Hata(d) − (kTB + NF)`,
//! the scene's paths as taps, the correlation peak's SNR after multipath
//! ([`multipath_estimate`]) and the calibrated sync statistics ([`thermal_stats`]). A
//! link is *usable* when the sources would use it: some path arrives and the outlier
//! probability of the frame sync is at most one half (the sync threshold; about
//! [`sync_threshold_snr_db`] for PN945 with one frame). Its σ is
//! `√(σ_thermal² + σ_floor² + b_mp²)`: the thermal σ the source reports, its configured
//! floor, and the noiseless multipath bias of the first-path rule. Log-normal shadowing
//! is left out: the maps show the median link. Tower clock offsets are taken as known
//! (calibrated), so they add no unknowns.

use crate::core::System;
use crate::dtmb::measurement::{multipath_estimate, thermal_stats, Tap, METRES_PER_SAMPLE};
use crate::dtmb::source::{DtmbSensorConfig, Environment, BANDWIDTH_HZ};
use crate::dtmb::{link_snr_db, FirstPathConfig, PnMode, SAMPLE_RATE_HZ};
use crate::gnss::link::{Signal, TrackingConfig};
use crate::gnss::visibility::{scene_effect, LinkClass};
use crate::propagation::pathloss::{extended_hata_db, HataEnvironment};
use crate::propagation::{Emitter, LinkParams, LinkPaths, LosState, Polarisation, Scene};
use nalgebra::{SMatrix, Vector3};
use num_complex::Complex64;

/// Unknowns of the geometry: east, north, up and four clock columns.
pub const UNKNOWNS: usize = 7;
/// A normal matrix `Hᵀ W H` over the fixed unknowns.
pub type Normal = SMatrix<f64, UNKNOWNS, UNKNOWNS>;

/// How ranges share clock unknowns (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ClockModel {
    /// GPS, DTMB and TC-OFDM on the receiver clock; BeiDou on its own.
    Shared,
    /// One clock per system.
    PerSystem,
}

impl ClockModel {
    /// The names the command line and the outputs use.
    pub const NAMES: [&'static str; 2] = ["shared", "per-system"];
}

impl std::str::FromStr for ClockModel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "shared" => Ok(ClockModel::Shared),
            "per-system" => Ok(ClockModel::PerSystem),
            _ => Err(format!(
                "expected one of {}, got {s:?}",
                Self::NAMES.join(", ")
            )),
        }
    }
}

impl ClockModel {
    /// The column (3–6) of the clock a range of `system` carries.
    pub fn column(self, system: System) -> u8 {
        3 + match (self, system) {
            (ClockModel::Shared, System::Bds) => 1,
            (ClockModel::Shared, _) => 0,
            (ClockModel::PerSystem, s) => s.index() as u8,
        }
    }
}

/// One range's row of the geometry: the unit ENU vector from the receiver to the emitter,
/// the clock column and the weight `1/σ²` (0 for an unusable link, which then adds nothing).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Row {
    pub u_enu: [f64; 3],
    pub column: u8,
    pub weight_per_m2: f64,
}

/// The unweighted and weighted normal matrices of a set of ranges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normals {
    pub geometry: Normal,
    pub weighted: Normal,
}

impl Default for Normals {
    fn default() -> Self {
        Self {
            geometry: Normal::zeros(),
            weighted: Normal::zeros(),
        }
    }
}

impl Normals {
    /// Adds a usable row (rows of weight 0 are skipped: the link is not received).
    pub fn add(&mut self, row: &Row) {
        if row.weight_per_m2 <= 0.0 {
            return;
        }
        let mut h = SMatrix::<f64, UNKNOWNS, 1>::zeros();
        h[0] = -row.u_enu[0];
        h[1] = -row.u_enu[1];
        h[2] = -row.u_enu[2];
        h[row.column as usize] = 1.0;
        // Only the upper triangle is accumulated; `solve` mirrors it. This halves the work
        // of the placement search, which adds rows millions of times.
        for c in 0..UNKNOWNS {
            if h[c] == 0.0 {
                continue;
            }
            for r in 0..=c {
                let v = h[r] * h[c];
                self.geometry[(r, c)] += v;
                self.weighted[(r, c)] += v * row.weight_per_m2;
            }
        }
    }

    /// `(GDOP, σ_3D)` of the accumulated ranges (module documentation); `(∞, ∞)` when the
    /// geometry is singular.
    pub fn solve(&self) -> (f64, f64) {
        let gdop = trace_of_inverse(&self.geometry, false);
        let sigma = trace_of_inverse(&self.weighted, true);
        (gdop.sqrt(), sigma.sqrt())
    }
}

/// The trace of the inverse of an upper-triangle-accumulated normal matrix over the clock
/// columns in use (a clock column no range touches is padded with an identity and left
/// out), of the position block only when `position_only`. +∞ when singular.
fn trace_of_inverse(upper: &Normal, position_only: bool) -> f64 {
    let mut n = *upper;
    for c in 0..UNKNOWNS {
        for r in 0..c {
            n[(c, r)] = n[(r, c)];
        }
    }
    let mut used = [true; UNKNOWNS];
    for (k, u) in used.iter_mut().enumerate().skip(3) {
        if n[(k, k)] == 0.0 {
            *u = false;
            n[(k, k)] = 1.0;
        }
    }
    let Some(chol) = n.cholesky() else {
        return f64::INFINITY;
    };
    // As the WLS solver: a pivot below 1e-12 of its diagonal means an unknown is (to that
    // precision) a combination of the others.
    let l = chol.l_dirty();
    for k in 0..UNKNOWNS {
        let p2 = l[(k, k)] * l[(k, k)];
        if p2.is_nan() || p2 <= 1e-12 * n[(k, k)] {
            return f64::INFINITY;
        }
    }
    let inv = chol.inverse();
    let last = if position_only { 3 } else { UNKNOWNS };
    let t: f64 = (0..last).filter(|&k| used[k]).map(|k| inv[(k, k)]).sum();
    if t.is_finite() && t >= 0.0 {
        t
    } else {
        f64::INFINITY
    }
}

/// A satellite as seen from the region at one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SatDir {
    pub system: System,
    /// Unit ENU vector towards the satellite.
    pub u_enu: Vector3<f64>,
    pub elevation_rad: f64,
    /// C/N0 without the scene (dB-Hz).
    pub open_cn0_dbhz: f64,
}

/// The GNSS receiver as the world configures it.
#[derive(Clone, Debug)]
pub struct GnssModel {
    pub tracking: TrackingConfig,
    pub ure_gps_m: f64,
    pub ure_bds_m: f64,
    /// Whether the scene acts on satellite links.
    pub scene: bool,
}

/// A terrestrial transmitter (declared in the world, or a candidate site) with the
/// receiver parameters of its system.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    pub id: String,
    pub system: System,
    pub pos_enu_m: Vector3<f64>,
    pub freq_hz: f64,
    /// ERP of the ranging signal (dBW): the TC-OFDM navigation component is below the
    /// station's ERP by the configured `nav_power_db`.
    pub ranging_erp_dbw: f64,
    pub pn_mode: PnMode,
    pub rx: TerrestrialRx,
    /// The SNR (dB) at which a viewer's receiver decodes the tower's programme
    /// ([`crate::dtmb::service`]); NaN for a TC-OFDM station (no broadcast service).
    pub service_threshold_db: f64,
}

/// The receiver parameters of a terrestrial system (`[sensors.dtmb]`/`[sensors.tcofdm]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TerrestrialRx {
    pub noise_figure_db: f64,
    pub antenna_gain_dbi: f64,
    pub frames: usize,
    pub environment: HataEnvironment,
    pub rx_antenna_height_m: f64,
    pub sigma_floor_m: f64,
}

impl TerrestrialRx {
    /// The parameters of a DTMB sensor configuration.
    pub fn of(cfg: &DtmbSensorConfig) -> Self {
        Self {
            noise_figure_db: cfg.noise_figure_db,
            antenna_gain_dbi: cfg.antenna_gain_dbi,
            frames: cfg.accumulation_frames.max(1) as usize,
            environment: match cfg.environment {
                Environment::Urban => HataEnvironment::UrbanSmallMedium,
                Environment::UrbanLarge => HataEnvironment::UrbanLarge,
                Environment::Suburban => HataEnvironment::Suburban,
                Environment::Open => HataEnvironment::Open,
            },
            rx_antenna_height_m: cfg.rx_antenna_height_m,
            sigma_floor_m: cfg.sigma_floor_m,
        }
    }
}

/// The largest accepted probability of a frame-sync outlier: the DTMB and TC-OFDM sources
/// drop a tower above it.
pub const MAX_OUTLIER_PROB: f64 = 0.5;

/// The reference SNR (dB) at which the calibrated sync's outlier probability crosses
/// [`MAX_OUTLIER_PROB`] for `mode` and `frames` on a single clean path, by bisection.
pub fn sync_threshold_snr_db(mode: PnMode, frames: usize) -> f64 {
    let (mut lo, mut hi) = (-60.0f64, 40.0f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if thermal_stats(mode, mid, frames).outlier_prob > MAX_OUTLIER_PROB {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// One terrestrial link at one cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SiteLink {
    pub usable: bool,
    pub class: LinkClass,
    /// Reference SNR of the budget (dB over 7.56 MHz).
    pub snr_db: f64,
    /// The SNR of every path's power together (dB over 7.56 MHz): what a broadcast
    /// receiver, whose guard interval holds the echoes, demodulates. −∞ without a path.
    pub service_snr_db: f64,
    pub row: Row,
}

/// Scratch buffers of one worker thread: nothing in the grid loop allocates.
pub struct Scratch {
    pub paths: LinkPaths,
    pub taps: Vec<Tap>,
}

impl Default for Scratch {
    fn default() -> Self {
        Self {
            paths: LinkPaths::new(),
            taps: Vec::with_capacity(crate::propagation::MAX_PATHS),
        }
    }
}

/// The link from `site` to a receiver at `rx_enu_m` (module documentation).
pub fn site_link(
    site: &Site,
    rx_enu_m: &Vector3<f64>,
    scene: Option<&Scene>,
    clocks: ClockModel,
    scratch: &mut Scratch,
) -> SiteLink {
    let d = site.pos_enu_m - rx_enu_m;
    let range_m = d.norm();
    let mut link = SiteLink {
        usable: false,
        class: LinkClass::Lost,
        snr_db: f64::NEG_INFINITY,
        service_snr_db: f64::NEG_INFINITY,
        row: Row::default(),
    };
    if !(range_m > 1e-3 && range_m.is_finite()) {
        return link;
    }
    let (pl_db, _validity) = extended_hata_db(
        site.rx.environment,
        site.freq_hz * 1e-6,
        site.pos_enu_m.z.max(1.0),
        site.rx.rx_antenna_height_m,
        (range_m * 1e-3).max(1e-3),
    );
    // The site's ERP is relative to a half-wave dipole; the budget takes its EIRP.
    link.snr_db = link_snr_db(
        crate::propagation::pathloss::eirp_dbw_from_erp(site.ranging_erp_dbw)
            + site.rx.antenna_gain_dbi,
        pl_db,
        site.rx.noise_figure_db,
        BANDWIDTH_HZ,
    );
    scratch.taps.clear();
    match scene {
        Some(scene) => {
            let params = LinkParams {
                freq_hz: site.freq_hz,
                polarisation: Polarisation::Horizontal,
                rx_vel_enu_mps: Vector3::zeros(),
            };
            if scene
                .link(
                    rx_enu_m,
                    &Emitter::Point(site.pos_enu_m),
                    &params,
                    &mut scratch.paths,
                )
                .is_err()
            {
                return link;
            }
            for p in scratch.paths.paths() {
                scratch.taps.push(Tap {
                    delay_samples: p.excess_delay_s * SAMPLE_RATE_HZ,
                    gain: Complex64::from_polar(p.amplitude, p.phase_rad),
                });
            }
            link.class = match scratch.paths.los {
                LosState::Clear => LinkClass::Los,
                LosState::Foliage { .. } => LinkClass::Foliage,
                LosState::Blocked { .. } => LinkClass::Nlos,
            };
        }
        None => {
            scratch.taps.push(Tap {
                delay_samples: 0.0,
                gain: Complex64::new(1.0, 0.0),
            });
            link.class = LinkClass::Los;
        }
    }
    let path_power: f64 = scratch.taps.iter().map(|t| t.gain.norm_sqr()).sum();
    if path_power == 0.0 {
        link.class = LinkClass::Lost;
        return link;
    }
    link.service_snr_db = link.snr_db + 10.0 * path_power.log10();
    let mp = multipath_estimate(
        site.pn_mode,
        &scratch.taps,
        link.snr_db,
        &FirstPathConfig::default(),
    );
    let snr_peak_db = link.snr_db + 10.0 * mp.peak_power.max(1e-30).log10();
    let stats = thermal_stats(site.pn_mode, snr_peak_db, site.rx.frames);
    if stats.outlier_prob > MAX_OUTLIER_PROB {
        link.class = LinkClass::Lost;
        return link;
    }
    let sigma_m = (stats.sigma_samples * METRES_PER_SAMPLE)
        .hypot(site.rx.sigma_floor_m)
        .hypot(mp.error_samples * METRES_PER_SAMPLE)
        .max(1e-3);
    let u = d / range_m;
    link.usable = true;
    link.row = Row {
        u_enu: [u.x, u.y, u.z],
        column: clocks.column(site.system),
        weight_per_m2: 1.0 / (sigma_m * sigma_m),
    };
    link
}

/// A satellite's row at a cell, its class and whether it is tracked.
pub fn sat_row(
    sat: &SatDir,
    gnss: &GnssModel,
    rx_enu_m: &Vector3<f64>,
    scene: Option<&Scene>,
    clocks: ClockModel,
    scratch: &mut Scratch,
) -> (LinkClass, Row) {
    let (class, cn0_dbhz, code_error_m) = match (scene, Signal::of_system(sat.system)) {
        (Some(scene), Some(signal)) if gnss.scene => scene_effect(
            scene,
            &gnss.tracking,
            signal,
            rx_enu_m,
            &Vector3::zeros(),
            &sat.u_enu,
            sat.open_cn0_dbhz,
            &mut scratch.paths,
        )
        .map_or((LinkClass::Los, sat.open_cn0_dbhz, 0.0), |e| {
            (e.class, e.cn0_dbhz, e.code_error_m)
        }),
        _ if gnss.tracking.in_lock(sat.open_cn0_dbhz) => (LinkClass::Los, sat.open_cn0_dbhz, 0.0),
        _ => (LinkClass::Lost, f64::NEG_INFINITY, 0.0),
    };
    if class == LinkClass::Lost {
        return (class, Row::default());
    }
    let ure_m = match sat.system {
        System::Bds => gnss.ure_bds_m,
        _ => gnss.ure_gps_m,
    };
    let dll_m = gnss.tracking.code_sigma_m(sat.system, cn0_dbhz);
    let var_m2 = (dll_m * dll_m + ure_m * ure_m + code_error_m * code_error_m).max(1e-6);
    (
        class,
        Row {
            u_enu: [sat.u_enu.x, sat.u_enu.y, sat.u_enu.z],
            column: clocks.column(sat.system),
            weight_per_m2: 1.0 / var_m2,
        },
    )
}

/// The best class of usable terrestrial links at a cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum Coverage {
    /// No usable DTMB or TC-OFDM link.
    #[default]
    None,
    /// Only links whose direct path is blocked (through a reflection or the walls).
    Nlos,
    /// The best link's direct path crosses foliage.
    Foliage,
    /// At least one usable link in line of sight.
    Los,
}

impl Coverage {
    pub fn label(self) -> &'static str {
        match self {
            Coverage::None => "none",
            Coverage::Nlos => "nlos",
            Coverage::Foliage => "foliage",
            Coverage::Los => "los",
        }
    }

    pub fn of(class: LinkClass) -> Self {
        match class {
            LinkClass::Los => Coverage::Los,
            LinkClass::Foliage => Coverage::Foliage,
            LinkClass::Nlos => Coverage::Nlos,
            LinkClass::Lost => Coverage::None,
        }
    }
}

/// Everything computed at one cell (worst case over the epochs for the GNSS figures).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellMetrics {
    /// Inside a building footprint or an indoor zone (left out of the statistics).
    pub indoor: bool,
    /// Tracked satellites (fewest over the epochs).
    pub n_gps: u16,
    pub n_bds: u16,
    /// Usable terrestrial transmitters.
    pub n_dtmb: u16,
    pub n_tcofdm: u16,
    /// Usable terrestrial links by class.
    pub n_terr_los: u16,
    pub n_terr_foliage: u16,
    pub n_terr_nlos: u16,
    pub coverage: Coverage,
    /// The strongest terrestrial reference SNR (dB), usable or not.
    pub best_terr_snr_db: f64,
    /// The best DTMB tower's service SNR less its profile's decoding threshold (dB): a
    /// viewer can watch some channel where it is ≥ 0. −∞ without a DTMB tower.
    pub dtmb_service_margin_db: f64,
    pub gdop_gnss: f64,
    pub gdop_hybrid: f64,
    pub sigma_gnss_m: f64,
    pub sigma_hybrid_m: f64,
}

impl Default for CellMetrics {
    fn default() -> Self {
        Self {
            indoor: false,
            n_gps: 0,
            n_bds: 0,
            n_dtmb: 0,
            n_tcofdm: 0,
            n_terr_los: 0,
            n_terr_foliage: 0,
            n_terr_nlos: 0,
            coverage: Coverage::None,
            best_terr_snr_db: f64::NEG_INFINITY,
            dtmb_service_margin_db: f64::NEG_INFINITY,
            gdop_gnss: f64::INFINITY,
            gdop_hybrid: f64::INFINITY,
            sigma_gnss_m: f64::INFINITY,
            sigma_hybrid_m: f64::INFINITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(u: [f64; 3], column: u8, sigma_m: f64) -> Row {
        let n = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        Row {
            u_enu: [u[0] / n, u[1] / n, u[2] / n],
            column,
            weight_per_m2: 1.0 / (sigma_m * sigma_m),
        }
    }

    /// One emitter at the zenith and three at elevation θ, 120° apart: checked against the
    /// 4 × 4 inverse computed independently by nalgebra, and the horizontal variances
    /// against their closed form 2 / (3 cos²θ) (the three low emitters alone fix E and N).
    #[test]
    fn gdop_matches_an_independent_inverse() {
        let th = 30f64.to_radians();
        let mut rows = vec![row([0.0, 0.0, 1.0], 3, 1.0)];
        for k in 0..3 {
            let az = 2.0 * std::f64::consts::PI * k as f64 / 3.0;
            rows.push(row(
                [th.cos() * az.sin(), th.cos() * az.cos(), th.sin()],
                3,
                1.0,
            ));
        }
        let mut n = Normals::default();
        for r in &rows {
            n.add(r);
        }
        let (gdop, sigma) = n.solve();
        let mut h = nalgebra::DMatrix::<f64>::zeros(4, 4);
        for (i, r) in rows.iter().enumerate() {
            h[(i, 0)] = -r.u_enu[0];
            h[(i, 1)] = -r.u_enu[1];
            h[(i, 2)] = -r.u_enu[2];
            h[(i, 3)] = 1.0;
        }
        let g = (h.transpose() * &h).try_inverse().unwrap();
        assert!((gdop - g.trace().sqrt()).abs() < 1e-9, "{gdop}");
        // With σ = 1 m the predicted error is the PDOP.
        let pdop = (g[(0, 0)] + g[(1, 1)] + g[(2, 2)]).sqrt();
        assert!((sigma - pdop).abs() < 1e-9, "{sigma} {pdop}");
        // Horizontal part analytically: E and N each have variance 2/(3 cos²θ).
        assert!((g[(0, 0)] - 2.0 / (3.0 * th.cos().powi(2))).abs() < 1e-9);
    }

    #[test]
    fn too_few_ranges_are_singular_and_unused_clocks_are_padded() {
        let mut n = Normals::default();
        n.add(&row([1.0, 0.0, 0.2], 3, 1.0));
        n.add(&row([0.0, 1.0, 0.2], 3, 1.0));
        n.add(&row([-1.0, 0.0, 0.2], 3, 1.0));
        assert_eq!(n.solve().0, f64::INFINITY);
        n.add(&row([0.0, -1.0, 0.9], 3, 1.0));
        let (g4, _) = n.solve();
        assert!(g4.is_finite());
        // A range of weight 0 is not received.
        n.add(&Row {
            weight_per_m2: 0.0,
            ..row([0.3, 0.3, 0.9], 4, 1.0)
        });
        assert_eq!(n.solve().0, g4);
        // A single range on a new clock adds an unknown and an equation: the position
        // error does not change.
        let s4 = n.solve().1;
        n.add(&row([0.3, 0.3, 0.9], 5, 1.0));
        assert!((n.solve().1 - s4).abs() < 1e-9 * s4);
        assert!(n.solve().0 > g4);
    }

    #[test]
    fn sync_threshold_is_where_the_outlier_probability_crosses_one_half() {
        let t = sync_threshold_snr_db(PnMode::Pn945, 1);
        assert!((-30.0..10.0).contains(&t), "{t}");
        assert!(thermal_stats(PnMode::Pn945, t + 0.5, 1).outlier_prob <= MAX_OUTLIER_PROB);
        assert!(thermal_stats(PnMode::Pn945, t - 0.5, 1).outlier_prob > MAX_OUTLIER_PROB);
    }
}
