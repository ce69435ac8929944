//! The fingerprint database: reference points × channels, and the world it was built for.
//!
//! # File format
//!
//! JSON (serde), written atomically ([`crate::io::atomic::write_atomic`]):
//!
//! ```text
//! { "format": "hybridnav-fm-fingerprints", "version": 1,
//!   "world": { "name": …, "origin_lat_deg": …, "origin_lon_deg": …, "origin_h_m": …,
//!              "content_hash": null | "…" },
//!   "channels": [ { "id": "F01", "freq_hz": 97.4e6 }, … ],
//!   "rp_enu_m": [ [e, n, u], … ],            // in the world's ENU frame
//!   "rp_lat_lon_deg": [ [lat, lon], … ],     // the same points, WGS-84, for other tools
//!   "rssi_dbm": [ [v | null, …], … ] }       // one row per RP, one column per channel
//! ```
//!
//! A missing reading (below the sensitivity, or a channel not surveyed at that RP) is
//! `null` in the file and NaN in memory. JSON was chosen over CSV because the world tag
//! and the channel list are structured and because `null` says "missing" unambiguously.
//!
//! Loading checks that the database was built for the expected world (same name and ENU
//! origin, and the same content hash when both carry one): RPs are stored in a world's
//! ENU frame, so a database from another world would place every fix wrongly.

use super::FmError;
use crate::core::{EnuFrame, Geodetic};
use serde::{Deserialize, Serialize};
use std::path::Path;

const FORMAT: &str = "hybridnav-fm-fingerprints";
const VERSION: u32 = 1;

/// The world a database belongs to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldTag {
    pub name: String,
    pub origin_lat_deg: f64,
    pub origin_lon_deg: f64,
    pub origin_h_m: f64,
    /// A hash of the world's content, when the caller has one (e.g. of the world file).
    #[serde(default)]
    pub content_hash: Option<String>,
}

impl WorldTag {
    /// The tag of the world `name` with ENU frame `frame`.
    pub fn new(name: &str, frame: &EnuFrame, content_hash: Option<String>) -> Self {
        let o = frame.origin();
        Self {
            name: name.to_string(),
            origin_lat_deg: o.lat_deg(),
            origin_lon_deg: o.lon_deg(),
            origin_h_m: o.h_m,
            content_hash,
        }
    }

    /// Whether `other` is the same world: same name, origin within 1e-9° and 1 mm, and
    /// the same content hash when both have one.
    pub fn matches(&self, other: &WorldTag) -> bool {
        self.name == other.name
            && (self.origin_lat_deg - other.origin_lat_deg).abs() <= 1e-9
            && (self.origin_lon_deg - other.origin_lon_deg).abs() <= 1e-9
            && (self.origin_h_m - other.origin_h_m).abs() <= 1e-3
            && match (&self.content_hash, &other.content_hash) {
                (Some(a), Some(b)) => a == b,
                _ => true,
            }
    }

    fn describe(&self) -> String {
        format!(
            "\"{}\" (origin {:.7}°, {:.7}°, {:.2} m{})",
            self.name,
            self.origin_lat_deg,
            self.origin_lon_deg,
            self.origin_h_m,
            self.content_hash
                .as_ref()
                .map(|h| format!(", hash {h}"))
                .unwrap_or_default()
        )
    }
}

/// One channel (an FM station) of the database.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelInfo {
    /// The station id (the world's transmitter id).
    pub id: String,
    pub freq_hz: f64,
}

/// Reference points with their fingerprints.
#[derive(Clone, Debug, PartialEq)]
pub struct FingerprintDb {
    world: WorldTag,
    channels: Vec<ChannelInfo>,
    rp_enu_m: Vec<[f64; 3]>,
    rp_lat_lon_deg: Vec<[f64; 2]>,
    /// Row-major: RP × channel; NaN is missing.
    rssi_dbm: Vec<f64>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DbFile {
    format: String,
    version: u32,
    world: WorldTag,
    channels: Vec<ChannelInfo>,
    rp_enu_m: Vec<[f64; 3]>,
    rp_lat_lon_deg: Vec<[f64; 2]>,
    rssi_dbm: Vec<Vec<Option<f64>>>,
}

impl FingerprintDb {
    /// A database for `world` (whose ENU frame is `frame`) from RPs in ENU and their
    /// fingerprints (row-major RP × channel, NaN for missing). Errors on size mismatches,
    /// non-finite positions, infinite readings, or a frame whose origin is not the tag's.
    pub fn new(
        world: WorldTag,
        frame: &EnuFrame,
        channels: Vec<ChannelInfo>,
        rp_enu_m: Vec<[f64; 3]>,
        rssi_dbm: Vec<f64>,
    ) -> Result<Self, FmError> {
        if !world.matches(&WorldTag::new(
            &world.name,
            frame,
            world.content_hash.clone(),
        )) {
            return Err(FmError::Data(format!(
                "the ENU frame's origin is not the origin of world {}",
                world.describe()
            )));
        }
        let rp_lat_lon_deg = rp_enu_m
            .iter()
            .map(|p| {
                let g = Geodetic::from_ecef(
                    &frame.ecef_of_enu(&nalgebra::Vector3::new(p[0], p[1], p[2])),
                );
                [g.lat_deg(), g.lon_deg()]
            })
            .collect();
        let db = Self {
            world,
            channels,
            rp_enu_m,
            rp_lat_lon_deg,
            rssi_dbm,
        };
        db.check()?;
        Ok(db)
    }

    fn check(&self) -> Result<(), FmError> {
        let (n, c) = (self.rp_enu_m.len(), self.channels.len());
        if c == 0 || n == 0 {
            return Err(FmError::Data(format!(
                "expected at least one RP and one channel, got {n} RPs, {c} channels"
            )));
        }
        if self.rssi_dbm.len() != n * c || self.rp_lat_lon_deg.len() != n {
            return Err(FmError::Data(format!(
                "expected {n} × {c} readings and {n} geodetic positions, got {} and {}",
                self.rssi_dbm.len(),
                self.rp_lat_lon_deg.len()
            )));
        }
        if let Some(i) = self
            .rp_enu_m
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(FmError::Data(format!(
                "RP {i}: expected a finite ENU position, got {:?}",
                self.rp_enu_m[i]
            )));
        }
        if let Some(i) = self.rssi_dbm.iter().position(|v| v.is_infinite()) {
            return Err(FmError::Data(format!(
                "RP {}, channel {}: expected a finite reading or missing, got {}",
                i / c,
                i % c,
                self.rssi_dbm[i]
            )));
        }
        for (i, ch) in self.channels.iter().enumerate() {
            if self.channels[..i].iter().any(|o| o.id == ch.id) {
                return Err(FmError::Data(format!("channel {} appears twice", ch.id)));
            }
        }
        Ok(())
    }

    /// The world tag.
    pub fn world(&self) -> &WorldTag {
        &self.world
    }
    /// The channels, in column order.
    pub fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }
    /// Number of RPs.
    pub fn len(&self) -> usize {
        self.rp_enu_m.len()
    }
    /// Whether there is no RP (never true for a constructed database).
    pub fn is_empty(&self) -> bool {
        self.rp_enu_m.is_empty()
    }
    /// RP positions (ENU, m).
    pub fn rp_enu_m(&self) -> &[[f64; 3]] {
        &self.rp_enu_m
    }
    /// RP positions (latitude, longitude in degrees).
    pub fn rp_lat_lon_deg(&self) -> &[[f64; 2]] {
        &self.rp_lat_lon_deg
    }
    /// All readings, row-major RP × channel (NaN missing).
    pub fn rssi_dbm(&self) -> &[f64] {
        &self.rssi_dbm
    }
    /// The fingerprint of RP `i`.
    pub fn fingerprint(&self, i: usize) -> &[f64] {
        let c = self.channels.len();
        &self.rssi_dbm[i * c..(i + 1) * c]
    }

    /// Writes the database as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<(), FmError> {
        let file = DbFile {
            format: FORMAT.into(),
            version: VERSION,
            world: self.world.clone(),
            channels: self.channels.clone(),
            rp_enu_m: self.rp_enu_m.clone(),
            rp_lat_lon_deg: self.rp_lat_lon_deg.clone(),
            rssi_dbm: (0..self.len())
                .map(|i| {
                    self.fingerprint(i)
                        .iter()
                        .map(|v| v.is_finite().then_some(*v))
                        .collect()
                })
                .collect(),
        };
        let text = serde_json::to_vec(&file).map_err(|e| FmError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        crate::io::atomic::write_atomic(path, &text).map_err(|e| FmError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })
    }

    /// Reads a database and checks it was built for `expected`.
    pub fn load(path: &Path, expected: &WorldTag) -> Result<Self, FmError> {
        let p = path.display().to_string();
        let text =
            crate::io::read::read_bytes(path, crate::io::read::FM_DATABASE).map_err(|e| {
                FmError::Io {
                    path: p.clone(),
                    message: e.to_string(),
                }
            })?;
        let file: DbFile = serde_json::from_slice(&text).map_err(|e| FmError::Io {
            path: p.clone(),
            message: format!(
                "expected an FM fingerprint database (JSON, format \"{FORMAT}\"): {e}"
            ),
        })?;
        if file.format != FORMAT || file.version != VERSION {
            return Err(FmError::Io {
                path: p,
                message: format!(
                    "expected format \"{FORMAT}\" version {VERSION}, got \"{}\" version {}",
                    file.format, file.version
                ),
            });
        }
        if !file.world.matches(expected) {
            return Err(FmError::WorldMismatch {
                path: p,
                expected: expected.describe(),
                found: file.world.describe(),
            });
        }
        let c = file.channels.len();
        if let Some(i) = file.rssi_dbm.iter().position(|r| r.len() != c) {
            return Err(FmError::Io {
                path: p,
                message: format!(
                    "RP {i}: expected {c} readings, got {}",
                    file.rssi_dbm[i].len()
                ),
            });
        }
        let db = Self {
            world: file.world,
            channels: file.channels,
            rp_enu_m: file.rp_enu_m,
            rp_lat_lon_deg: file.rp_lat_lon_deg,
            rssi_dbm: file
                .rssi_dbm
                .iter()
                .flatten()
                .map(|v| v.unwrap_or(f64::NAN))
                .collect(),
        };
        db.check().map_err(|e| FmError::Io {
            path: p,
            message: e.to_string(),
        })?;
        Ok(db)
    }
}

/// The offline stage in one call: surveys `rp_en_m` with `field` (the surveyor's stream
/// `rng`, antenna at ENU height `up_m`), kriges every channel onto `grid_en_m`, and
/// returns the database (the grid as RPs) with the per-channel kriging report. A channel
/// with fewer than 10 surveyed values is left missing on the grid (see
/// [`super::kriging::krige_channels`]).
#[allow(clippy::too_many_arguments)]
pub fn build_kriged(
    world: WorldTag,
    frame: &EnuFrame,
    field: &mut super::FmField,
    rp_en_m: &[[f64; 2]],
    up_m: f64,
    survey_cfg: &super::SurveyConfig,
    grid_en_m: &[[f64; 2]],
    opts: &super::kriging::FitOptions,
    rng: &mut crate::core::StreamRng,
) -> Result<(FingerprintDb, Vec<super::kriging::ChannelKriging>), FmError> {
    let surveyed = super::survey::survey(field, rp_en_m, up_m, survey_cfg, rng)?;
    let channels: Vec<ChannelInfo> = field
        .stations()
        .iter()
        .map(|s| ChannelInfo {
            id: s.id.clone(),
            freq_hz: s.freq_hz,
        })
        .collect();
    let (values, report) =
        super::kriging::krige_channels(rp_en_m, &surveyed, channels.len(), grid_en_m, opts, 10)?;
    let rps = grid_en_m.iter().map(|p| [p[0], p[1], up_m]).collect();
    Ok((
        FingerprintDb::new(world, frame, channels, rps, values)?,
        report,
    ))
}
