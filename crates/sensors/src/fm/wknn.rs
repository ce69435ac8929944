//! Online positioning: weighted K-nearest neighbours in signal space, with seed 000's
//! GPS-constraint circle.
//!
//! # Signal distance
//!
//! Between a measurement m and the fingerprint r_i of RP i, over the set C_i of channels
//! both have (a channel missing in either is skipped):
//!
//! ```text
//! D_i = √( Σ_{c ∈ C_i} (m_c − r_{i,c})² / |C_i| )      (dB, RMS over the common channels)
//! ```
//!
//! An RP with |C_i| < `min_common_channels` is not comparable and is skipped. The mean
//! (rather than the sum) makes RPs with different numbers of common channels comparable.
//!
//! # Estimate and covariance
//!
//! The K smallest D_i give weights w_i = 1/(D_i + ε) (inverse distance) or 1 (uniform),
//! normalised to sum to 1, and
//!
//! ```text
//! p̂ = Σ w_i p_i,     R_f = Σ w_i (p_i − p̂)(p_i − p̂)ᵀ + diag(σ_floor², σ_floor², σ_up²)
//! ```
//!
//! The weighted spread of the neighbours measures how ambiguous the match is; the floor
//! keeps R_f from collapsing when the K neighbours are adjacent grid points (their spread
//! is then the grid spacing, far below the real error). The RPs carry no vertical
//! information beyond the surveyor's antenna height, hence the separate σ_up.
//!
//! # The constraint circle (seed 000 §3.2, Fig. 3)
//!
//! Only RPs within the horizontal radius
//!
//! ```text
//! r(t) = min(r0 + growth · (t − t_last_reliable_fix), r_max)
//! ```
//!
//! of the constraint centre (the last reliable GPS fix propagated by the filter) are
//! searched; their number is the fix's `support` (a fuzzy input of seed 000's mode
//! selection). When no RP lies inside, [`NoRpPolicy`] decides: `unconstrained` searches
//! every RP and flags the fix (`constrained = false`, support 0), `error` returns
//! [`FmError::NoRpInCircle`].

use super::database::FingerprintDb;
use super::FmError;
use crate::core::config::check;
use crate::core::ConfigIssue;
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// How the K neighbours are weighted.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// w = 1/(D + ε) (default).
    #[default]
    InverseDistance,
    /// w = 1.
    Uniform,
}

/// What to do when no RP lies inside the constraint circle.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum NoRpPolicy {
    /// Search every RP and flag the fix as unconstrained (default).
    #[default]
    Unconstrained,
    /// Return [`FmError::NoRpInCircle`] (the source then emits no fix).
    Error,
}

fn default_k() -> usize {
    4
}
fn default_eps() -> f64 {
    0.1
}
fn default_min_common() -> usize {
    3
}
fn default_floor() -> f64 {
    3.0
}
fn default_up() -> f64 {
    5.0
}

/// WKNN parameters.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WknnConfig {
    /// Number of neighbours K (1–64), default 4.
    #[serde(default = "default_k")]
    pub k: usize,
    /// `"inverse_distance"` (default) or `"uniform"`.
    #[serde(default)]
    pub weighting: Weighting,
    /// ε of the inverse-distance weights (dB), > 0, default 0.1.
    #[serde(default = "default_eps")]
    pub epsilon_db: f64,
    /// Channels an RP must share with the measurement to be compared (≥ 1), default 3.
    #[serde(default = "default_min_common")]
    pub min_common_channels: usize,
    /// Horizontal σ floor of R_f (m), default 3.
    #[serde(default = "default_floor")]
    pub sigma_floor_m: f64,
    /// Vertical σ of R_f (m), default 5.
    #[serde(default = "default_up")]
    pub sigma_up_m: f64,
}

impl Default for WknnConfig {
    fn default() -> Self {
        Self {
            k: default_k(),
            weighting: Weighting::default(),
            epsilon_db: default_eps(),
            min_common_channels: default_min_common(),
            sigma_floor_m: default_floor(),
            sigma_up_m: default_up(),
        }
    }
}

impl WknnConfig {
    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check("k", (1..=64).contains(&self.k), || {
            format!("expected K in 1–64 neighbours, got {}", self.k)
        })?;
        check(
            "epsilon_db",
            self.epsilon_db.is_finite() && self.epsilon_db > 0.0 && self.epsilon_db <= 100.0,
            || format!("expected ε in (0, 100] dB, got {}", self.epsilon_db),
        )?;
        check(
            "min_common_channels",
            (1..=256).contains(&self.min_common_channels),
            || {
                format!(
                    "expected 1 to 256 common channels, got {}",
                    self.min_common_channels
                )
            },
        )?;
        check(
            "sigma_floor_m",
            self.sigma_floor_m.is_finite()
                && self.sigma_floor_m > 0.0
                && self.sigma_floor_m <= 10_000.0,
            || {
                format!(
                    "expected a σ floor in (0, 10000] m, got {}",
                    self.sigma_floor_m
                )
            },
        )?;
        check(
            "sigma_up_m",
            self.sigma_up_m.is_finite() && self.sigma_up_m > 0.0 && self.sigma_up_m <= 10_000.0,
            || {
                format!(
                    "expected a vertical σ in (0, 10000] m, got {}",
                    self.sigma_up_m
                )
            },
        )
    }
}

fn default_r0() -> f64 {
    30.0
}
fn default_growth() -> f64 {
    2.0
}
fn default_rmax() -> f64 {
    200.0
}
fn default_reliable() -> f64 {
    15.0
}
fn yes() -> bool {
    true
}

/// Seed 000's constraint circle (§3.2, Fig. 3): centred on the aiding estimate while it is
/// reliable, then held at its last reliable position while the radius grows.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ConstraintConfig {
    /// Use the circle (default true); false searches every RP.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Radius right after a reliable fix (m), default 30.
    #[serde(default = "default_r0")]
    pub r0_m: f64,
    /// Growth of the radius per second since the last reliable fix (m/s), default 2
    /// (a walker's speed with margin).
    #[serde(default = "default_growth")]
    pub growth_mps: f64,
    /// Largest radius (m), default 200.
    #[serde(default = "default_rmax")]
    pub r_max_m: f64,
    /// A fix is reliable when the aiding estimate's horizontal position σ
    /// (√((σ_e² + σ_n²)/2)) is at most this (m), default 15.
    #[serde(default = "default_reliable")]
    pub reliable_sigma_m: f64,
    /// `"unconstrained"` (default) or `"error"` when no RP is inside.
    #[serde(default)]
    pub no_rp: NoRpPolicy,
}

impl Default for ConstraintConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            r0_m: default_r0(),
            growth_mps: default_growth(),
            r_max_m: default_rmax(),
            reliable_sigma_m: default_reliable(),
            no_rp: NoRpPolicy::default(),
        }
    }
}

impl ConstraintConfig {
    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check(
            "r0_m",
            self.r0_m.is_finite() && self.r0_m > 0.0 && self.r0_m <= 1e5,
            || {
                format!(
                    "expected an initial radius in (0, 100000] m, got {}",
                    self.r0_m
                )
            },
        )?;
        check(
            "growth_mps",
            self.growth_mps.is_finite() && (0.0..=1000.0).contains(&self.growth_mps),
            || {
                format!(
                    "expected a radius growth in [0, 1000] m/s, got {}",
                    self.growth_mps
                )
            },
        )?;
        check(
            "r_max_m",
            self.r_max_m.is_finite() && self.r_max_m >= self.r0_m && self.r_max_m <= 1e6,
            || {
                format!(
                    "expected a largest radius in [r0_m = {}, 1e6] m, got {}",
                    self.r0_m, self.r_max_m
                )
            },
        )?;
        check(
            "reliable_sigma_m",
            self.reliable_sigma_m.is_finite() && self.reliable_sigma_m > 0.0,
            || {
                format!(
                    "expected a positive reliability threshold (m), got {}",
                    self.reliable_sigma_m
                )
            },
        )
    }

    /// r(t) for `since_reliable_s` seconds since the last reliable fix.
    pub fn radius_m(&self, since_reliable_s: f64) -> f64 {
        (self.r0_m + self.growth_mps * since_reliable_s.max(0.0)).min(self.r_max_m)
    }
}

/// One constraint circle (horizontal, ENU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Constraint {
    pub centre_en_m: [f64; 2],
    pub radius_m: f64,
}

/// Caller-owned scratch of [`locate`]: the K best so far. Sized once; a query does not
/// allocate.
#[derive(Clone, Debug)]
pub struct WknnScratch {
    dist: Vec<f64>,
    idx: Vec<u32>,
}

impl WknnScratch {
    /// Scratch for up to `k` neighbours.
    pub fn new(k: usize) -> Self {
        Self {
            dist: vec![0.0; k.max(1)],
            idx: vec![0; k.max(1)],
        }
    }
}

/// A WKNN position fix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WknnFix {
    /// Position (ENU, m).
    pub pos_enu_m: Vector3<f64>,
    /// R_f in ENU (m²).
    pub cov_enu_m2: Matrix3<f64>,
    /// RPs inside the circle (0 without a constraint, or when the fallback searched all).
    pub support: u32,
    /// Whether the search was restricted to the circle.
    pub constrained: bool,
    /// Neighbours used (≤ K).
    pub neighbours: usize,
    /// Signal distance of the best neighbour (dB).
    pub best_distance_db: f64,
}

#[inline]
fn signal_distance(m: &[f64], r: &[f64], min_common: usize) -> Option<f64> {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, b) in m.iter().zip(r) {
        let d = a - b;
        // NaN on either side (missing) makes d NaN: skipped.
        if d.is_finite() {
            s += d * d;
            n += 1;
        }
    }
    (n >= min_common).then(|| (s / n as f64).sqrt())
}

/// Scans the RPs (inside `circle` when given) and keeps the K best in `scratch`; returns
/// (RPs inside the circle, neighbours kept).
fn scan(
    db: &FingerprintDb,
    m: &[f64],
    k: usize,
    min_common: usize,
    circle: Option<&Constraint>,
    scratch: &mut WknnScratch,
) -> (u32, usize) {
    let c = db.channels().len();
    let rss = db.rssi_dbm();
    let (mut support, mut kept) = (0u32, 0usize);
    for (i, p) in db.rp_enu_m().iter().enumerate() {
        if let Some(cc) = circle {
            let (dx, dy) = (p[0] - cc.centre_en_m[0], p[1] - cc.centre_en_m[1]);
            if dx * dx + dy * dy > cc.radius_m * cc.radius_m {
                continue;
            }
            support += 1;
        }
        let Some(d) = signal_distance(m, &rss[i * c..(i + 1) * c], min_common) else {
            continue;
        };
        if kept == k && d >= scratch.dist[k - 1] {
            continue;
        }
        // Insertion into the sorted K best.
        let mut j = kept.min(k - 1);
        while j > 0 && scratch.dist[j - 1] > d {
            scratch.dist[j] = scratch.dist[j - 1];
            scratch.idx[j] = scratch.idx[j - 1];
            j -= 1;
        }
        scratch.dist[j] = d;
        scratch.idx[j] = i as u32;
        kept = (kept + 1).min(k);
    }
    (support, kept)
}

/// Locates the measurement `rssi_dbm` (one value per database channel, NaN missing) in
/// `db`. See the module documentation for the model, the constraint and its fallback.
/// `cfg` must be valid and `scratch` sized for `cfg.k` (it is resized otherwise, the only
/// allocation).
pub fn locate(
    db: &FingerprintDb,
    rssi_dbm: &[f64],
    cfg: &WknnConfig,
    constraint: Option<&Constraint>,
    policy: NoRpPolicy,
    scratch: &mut WknnScratch,
) -> Result<WknnFix, FmError> {
    let c = db.channels().len();
    if rssi_dbm.len() != c {
        return Err(FmError::Data(format!(
            "expected {c} readings (one per database channel), got {}",
            rssi_dbm.len()
        )));
    }
    if scratch.dist.len() < cfg.k {
        *scratch = WknnScratch::new(cfg.k);
    }
    let k = cfg.k.max(1);
    let (mut support, mut kept) = scan(
        db,
        rssi_dbm,
        k,
        cfg.min_common_channels,
        constraint,
        scratch,
    );
    let mut constrained = constraint.is_some();
    if let Some(cc) = constraint {
        if support == 0 {
            match policy {
                NoRpPolicy::Error => {
                    return Err(FmError::NoRpInCircle {
                        east_m: cc.centre_en_m[0],
                        north_m: cc.centre_en_m[1],
                        radius_m: cc.radius_m,
                    })
                }
                NoRpPolicy::Unconstrained => {
                    (support, kept) = scan(db, rssi_dbm, k, cfg.min_common_channels, None, scratch);
                    constrained = false;
                }
            }
        }
    }
    if kept == 0 {
        return Err(FmError::NoComparableRp {
            min_common: cfg.min_common_channels,
            measured: rssi_dbm.iter().filter(|v| v.is_finite()).count(),
        });
    }
    let rps = db.rp_enu_m();
    let weight = |d: f64| match cfg.weighting {
        Weighting::InverseDistance => 1.0 / (d + cfg.epsilon_db),
        Weighting::Uniform => 1.0,
    };
    let wsum: f64 = (0..kept).map(|j| weight(scratch.dist[j])).sum();
    let mut mean = Vector3::zeros();
    for j in 0..kept {
        let p = rps[scratch.idx[j] as usize];
        mean += weight(scratch.dist[j]) / wsum * Vector3::new(p[0], p[1], p[2]);
    }
    let mut cov = Matrix3::zeros();
    for j in 0..kept {
        let p = rps[scratch.idx[j] as usize];
        let d = Vector3::new(p[0], p[1], p[2]) - mean;
        cov += weight(scratch.dist[j]) / wsum * d * d.transpose();
    }
    cov += Matrix3::from_diagonal(&Vector3::new(
        cfg.sigma_floor_m.powi(2),
        cfg.sigma_floor_m.powi(2),
        cfg.sigma_up_m.powi(2),
    ));
    Ok(WknnFix {
        pos_enu_m: mean,
        cov_enu_m2: cov,
        support: if constrained { support } else { 0 },
        constrained,
        neighbours: kept,
        best_distance_db: scratch.dist[0],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EnuFrame, Geodetic};
    use crate::fm::database::{ChannelInfo, WorldTag};

    fn db() -> FingerprintDb {
        let frame = EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 50.0));
        let channels = (0..3)
            .map(|i| ChannelInfo {
                id: format!("F{i}"),
                freq_hz: 90e6 + 1e6 * i as f64,
            })
            .collect();
        let rps = vec![[0.0, 0.0, 1.0], [10.0, 0.0, 1.0], [0.0, 50.0, 1.0]];
        let rssi = vec![
            -60.0, -60.0, -60.0, -61.0, -61.0, -61.0, -65.0, -65.0, -65.0,
        ];
        FingerprintDb::new(
            WorldTag::new("t", &frame, None),
            &frame,
            channels,
            rps,
            rssi,
        )
        .unwrap()
    }

    #[test]
    fn two_neighbours_give_the_closed_form_mean_and_spread() {
        // D = 0 dB and 1 dB: w ∝ 1/0.1 and 1/1.1. For two points the weighted spread along
        // their axis is w0 w1 |Δ|² (normalised weights).
        let cfg = WknnConfig {
            k: 2,
            ..Default::default()
        };
        let mut s = WknnScratch::new(2);
        let fix = locate(
            &db(),
            &[-60.0, -60.0, -60.0],
            &cfg,
            None,
            NoRpPolicy::Error,
            &mut s,
        )
        .unwrap();
        let (a, b) = (1.0 / 0.1, 1.0 / 1.1);
        let (w0, w1) = (a / (a + b), b / (a + b));
        assert!((fix.pos_enu_m.x - 10.0 * w1).abs() < 1e-12 && fix.pos_enu_m.y.abs() < 1e-12);
        assert!((fix.cov_enu_m2[(0, 0)] - (w0 * w1 * 100.0 + 9.0)).abs() < 1e-9);
        assert!(
            (fix.cov_enu_m2[(1, 1)] - 9.0).abs() < 1e-12
                && (fix.cov_enu_m2[(2, 2)] - 25.0).abs() < 1e-12
        );
        assert_eq!((fix.neighbours, fix.best_distance_db), (2, 0.0));
        // Uniform weights: the midpoint, spread |Δ|²/4.
        let cfg = WknnConfig {
            weighting: Weighting::Uniform,
            ..cfg
        };
        let fix = locate(
            &db(),
            &[-60.0, -60.0, -60.0],
            &cfg,
            None,
            NoRpPolicy::Error,
            &mut s,
        )
        .unwrap();
        assert!((fix.pos_enu_m.x - 5.0).abs() < 1e-12);
        assert!((fix.cov_enu_m2[(0, 0)] - (25.0 + 9.0)).abs() < 1e-9);
        // K larger than the RPs uses them all.
        let cfg = WknnConfig { k: 10, ..cfg };
        let mut s = WknnScratch::new(10);
        let fix = locate(
            &db(),
            &[-60.0, -60.0, -60.0],
            &cfg,
            None,
            NoRpPolicy::Error,
            &mut s,
        )
        .unwrap();
        assert_eq!(fix.neighbours, 3);
        assert!((fix.pos_enu_m.y - 50.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn radius_grows_and_saturates() {
        let c = ConstraintConfig::default();
        assert_eq!(c.radius_m(0.0), 30.0);
        assert_eq!(c.radius_m(10.0), 50.0);
        assert_eq!(c.radius_m(-5.0), 30.0);
        assert_eq!(c.radius_m(1e6), 200.0);
    }
}
