//! The `[scene]` of a world file: buildings, forests, tree rows, indoor zones and ground
//! surfaces, with outlines given in the world's ENU frame or as geodetic coordinates, and
//! the `[[transmitter]]` tables (DTMB towers, TC-OFDM base stations, FM stations).
//!
//! Geodetic outlines (`*_lla_deg = [[lat, lon], …]`) are projected onto the world's ENU
//! plane at the origin's height; a city block is far too small for the projection to
//! matter (the east–north error of projecting at 1 km from the origin is below 0.1 m).
//! The result is a [`SceneConfig`] the propagation module validates and indexes.

use crate::core::{EnuFrame, Geodetic};
use crate::propagation::{
    BuildingClass, BuildingConfig, ForestConfig, GroundConfig, IndoorZoneConfig, LinkOptions,
    SceneConfig, ShadowingConfig, SurfaceConfig, WallMaterial,
};
use serde::Deserialize;

/// An outline given either in ENU metres or in degrees.
fn outline(
    frame: &EnuFrame,
    key: &str,
    enu: &Option<Vec<[f64; 2]>>,
    lla: &Option<Vec<[f64; 2]>>,
) -> Result<Vec<[f64; 2]>, (String, String)> {
    match (enu, lla) {
        (Some(v), None) => Ok(v.clone()),
        (None, Some(v)) => v
            .iter()
            .enumerate()
            .map(|(i, [lat, lon])| {
                if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0) {
                    return Err((
                        format!("{key}_lla_deg[{i}]"),
                        format!("expected [latitude, longitude] in degrees, got [{lat}, {lon}]"),
                    ));
                }
                let h = frame.origin().h_m;
                let p = frame.enu_of_ecef(&Geodetic::from_deg(*lat, *lon, h).to_ecef());
                Ok([p.x, p.y])
            })
            .collect(),
        _ => Err((
            key.to_string(),
            format!("expected exactly one of {key}_enu_m = [[e, n], …] or {key}_lla_deg = [[lat, lon], …]"),
        )),
    }
}

/// `[[scene.buildings]]`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BuildingSpec {
    /// Footprint corners `[[e, n], …]` in the world's ENU frame (m); exactly one of this and
    /// `footprint_lla_deg`.
    #[serde(default)]
    pub footprint_enu_m: Option<Vec<[f64; 2]>>,
    /// Footprint corners `[[lat, lon], …]` (degrees, WGS-84).
    #[serde(default)]
    pub footprint_lla_deg: Option<Vec<[f64; 2]>>,
    /// Roof height above the ground (m), positive.
    pub height_m: f64,
    #[serde(default)]
    pub material: WallMaterial,
    #[serde(default)]
    pub class: BuildingClass,
    /// A label for maps and messages (e.g. "New Main Building").
    #[serde(default)]
    pub name: Option<String>,
}

/// `[[scene.forests]]`: a park, wood or hedge.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ForestSpec {
    /// Outline `[[e, n], …]` in the world's ENU frame (m); exactly one of this and
    /// `polygon_lla_deg`.
    #[serde(default)]
    pub polygon_enu_m: Option<Vec<[f64; 2]>>,
    /// Outline `[[lat, lon], …]` (degrees, WGS-84).
    #[serde(default)]
    pub polygon_lla_deg: Option<Vec<[f64; 2]>>,
    /// Top of the canopy above the ground (m), positive.
    pub height_m: f64,
    /// Bottom of the canopy (m), in [0, `height_m`): a ray below it passes under the crowns.
    #[serde(default)]
    #[schemars(range(min = 0.0))]
    pub canopy_base_m: f64,
    /// In (0, 1]: scales the specific attenuation of dense in-leaf foliage (Weissberger's
    /// slope, used as ITU-R P.833's γ; 1 = dense).
    #[serde(default = "one")]
    #[schemars(range(min = 0.0, max = 1.0))]
    pub foliage_density: f64,
}

/// `[[scene.tree_rows]]`: street trees along a polyline, expanded into one foliage prism
/// per segment, `width_m` wide (the crown diameter).
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TreeRowSpec {
    /// The row's polyline `[[e, n], …]` in the world's ENU frame (m); exactly one of this
    /// and `line_lla_deg`.
    #[serde(default)]
    pub line_enu_m: Option<Vec<[f64; 2]>>,
    /// The row's polyline `[[lat, lon], …]` (degrees, WGS-84).
    #[serde(default)]
    pub line_lla_deg: Option<Vec<[f64; 2]>>,
    /// Crown diameter (m); default 6.
    #[serde(default = "six")]
    pub width_m: f64,
    /// Top of the crowns above the ground (m), positive.
    pub height_m: f64,
    /// Trunk height below the crown (m); default 2.5.
    #[serde(default = "trunk")]
    pub canopy_base_m: f64,
    /// In (0, 1]: scales the specific attenuation of dense in-leaf foliage (Weissberger's
    /// slope, used as ITU-R P.833's γ; 1 = dense).
    #[serde(default = "one")]
    #[schemars(range(min = 0.0, max = 1.0))]
    pub foliage_density: f64,
}

/// `[[scene.indoor_zones]]`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IndoorZoneSpec {
    /// Outline `[[e, n], …]` in the world's ENU frame (m); exactly one of this and
    /// `polygon_lla_deg`.
    #[serde(default)]
    pub polygon_enu_m: Option<Vec<[f64; 2]>>,
    /// Outline `[[lat, lon], …]` (degrees, WGS-84).
    #[serde(default)]
    pub polygon_lla_deg: Option<Vec<[f64; 2]>>,
    /// Floor of the zone above the ground (m).
    pub floor_m: f64,
    /// Ceiling of the zone above the ground (m), above `floor_m`.
    pub ceiling_m: f64,
    #[serde(default)]
    pub class: BuildingClass,
}

/// `[[scene.surfaces]]`: water, wet meadow, paving.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SurfaceSpec {
    /// Outline `[[e, n], …]` in the world's ENU frame (m); exactly one of this and
    /// `polygon_lla_deg`.
    #[serde(default)]
    pub polygon_enu_m: Option<Vec<[f64; 2]>>,
    /// Outline `[[lat, lon], …]` (degrees, WGS-84).
    #[serde(default)]
    pub polygon_lla_deg: Option<Vec<[f64; 2]>>,
    pub material: crate::propagation::GroundMaterial,
}

fn one() -> f64 {
    1.0
}
fn six() -> f64 {
    6.0
}
fn trunk() -> f64 {
    2.5
}

/// `[scene]`.
#[derive(Clone, Debug, Default, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneSection {
    /// Buildings: prisms that block, reflect and diffract.
    #[serde(default)]
    pub buildings: Vec<BuildingSpec>,
    /// Parks, woods and hedges: foliage that attenuates.
    #[serde(default)]
    pub forests: Vec<ForestSpec>,
    /// Street trees along polylines.
    #[serde(default)]
    pub tree_rows: Vec<TreeRowSpec>,
    /// Indoor volumes (the receiver inside gets the building-entry loss).
    #[serde(default)]
    pub indoor_zones: Vec<IndoorZoneSpec>,
    /// Ground patches of another material (water, wet meadow, paving).
    #[serde(default)]
    pub surfaces: Vec<SurfaceSpec>,
    #[serde(default)]
    pub ground: GroundConfig,
    #[serde(default)]
    pub link: LinkOptions,
    /// Log-normal shadowing of terrestrial links (σ, decorrelation distance).
    #[serde(default)]
    pub shadowing: Option<ShadowingConfig>,
    /// `[[scene.magnetic_anomaly]]`: ferromagnetic structures (point dipoles) whose field
    /// the magnetic-landmark source detects (seed 002 §2).
    #[serde(default, rename = "magnetic_anomaly")]
    pub magnetic_anomalies: Vec<crate::magnetic::MagneticAnomalyConfig>,
}

impl SceneSection {
    /// The propagation module's configuration, outlines in ENU metres. Tree rows become
    /// forests after the declared ones (their indices follow `forests`).
    ///
    /// # Errors
    /// `(key below "scene", message)` for an outline given twice, not at all, or with a
    /// non-geographic coordinate, or a tree row with fewer than two points or a
    /// non-positive width.
    pub fn resolve(&self, frame: &EnuFrame) -> Result<ResolvedScene, (String, String)> {
        let at = |t: &str, i: usize, e: (String, String)| (format!("{t}[{i}].{}", e.0), e.1);
        let mut cfg = SceneConfig {
            ground: self.ground.clone(),
            link: self.link.clone(),
            ..SceneConfig::default()
        };
        for (i, b) in self.buildings.iter().enumerate() {
            cfg.buildings.push(BuildingConfig {
                footprint_enu_m: outline(
                    frame,
                    "footprint",
                    &b.footprint_enu_m,
                    &b.footprint_lla_deg,
                )
                .map_err(|e| at("buildings", i, e))?,
                height_m: b.height_m,
                material: b.material,
                class: b.class,
            });
        }
        for (i, f) in self.forests.iter().enumerate() {
            cfg.forests.push(ForestConfig {
                polygon_enu_m: outline(frame, "polygon", &f.polygon_enu_m, &f.polygon_lla_deg)
                    .map_err(|e| at("forests", i, e))?,
                height_m: f.height_m,
                canopy_base_m: f.canopy_base_m,
                foliage_density: f.foliage_density,
            });
        }
        let mut tree_row_of_forest = vec![None; self.forests.len()];
        for (i, r) in self.tree_rows.iter().enumerate() {
            let line = outline(frame, "line", &r.line_enu_m, &r.line_lla_deg)
                .map_err(|e| at("tree_rows", i, e))?;
            if line.len() < 2 {
                return Err((
                    format!("tree_rows[{i}].line"),
                    format!("expected at least two points, got {}", line.len()),
                ));
            }
            if !(r.width_m.is_finite() && r.width_m > 0.0) {
                return Err((
                    format!("tree_rows[{i}].width_m"),
                    format!("expected a crown width > 0 m, got {}", r.width_m),
                ));
            }
            for w in line.windows(2) {
                let (a, b) = (w[0], w[1]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = dx.hypot(dy);
                if len <= 0.0 || len.is_nan() {
                    continue;
                }
                // The segment's rectangle, half a crown either side.
                let (nx, ny) = (-dy / len * r.width_m / 2.0, dx / len * r.width_m / 2.0);
                cfg.forests.push(ForestConfig {
                    polygon_enu_m: vec![
                        [a[0] + nx, a[1] + ny],
                        [a[0] - nx, a[1] - ny],
                        [b[0] - nx, b[1] - ny],
                        [b[0] + nx, b[1] + ny],
                    ],
                    height_m: r.height_m,
                    canopy_base_m: r.canopy_base_m,
                    foliage_density: r.foliage_density,
                });
                tree_row_of_forest.push(Some(i));
            }
        }
        for (i, z) in self.indoor_zones.iter().enumerate() {
            cfg.indoor_zones.push(IndoorZoneConfig {
                polygon_enu_m: outline(frame, "polygon", &z.polygon_enu_m, &z.polygon_lla_deg)
                    .map_err(|e| at("indoor_zones", i, e))?,
                floor_m: z.floor_m,
                ceiling_m: z.ceiling_m,
                class: z.class,
            });
        }
        for (i, s) in self.surfaces.iter().enumerate() {
            cfg.surfaces.push(SurfaceConfig {
                polygon_enu_m: outline(frame, "polygon", &s.polygon_enu_m, &s.polygon_lla_deg)
                    .map_err(|e| at("surfaces", i, e))?,
                material: s.material,
            });
        }
        Ok(ResolvedScene {
            config: cfg,
            tree_row_of_forest,
        })
    }
}

/// A resolved scene and where its forests came from.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedScene {
    pub config: SceneConfig,
    /// For each forest of `config`, the tree row it was expanded from (`None` for a
    /// declared forest), so that errors name the table the user wrote.
    pub tree_row_of_forest: Vec<Option<usize>>,
}

impl ResolvedScene {
    /// Rewrites a propagation key (`forests[7].height_m`) into the world file's
    /// (`tree_rows[2].height_m`).
    pub fn user_key(&self, key: &str) -> String {
        if let Some(rest) = key.strip_prefix("forests[") {
            if let Some((n, tail)) = rest.split_once(']') {
                if let Ok(k) = n.parse::<usize>() {
                    if let Some(Some(row)) = self.tree_row_of_forest.get(k) {
                        return format!("tree_rows[{row}]{tail}");
                    }
                }
            }
        }
        key.to_string()
    }
}

/// What a transmitter is.
#[derive(
    Clone,
    Copy,
    Debug,
    Deserialize,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum TransmitterKind {
    /// A DTMB (GB 20600-2006) television transmitter used as a pseudo-satellite.
    Dtmb,
    /// A TC-OFDM base station (seed 004).
    Tcofdm,
    /// An FM broadcast station (fingerprinting).
    Fm,
}

impl TransmitterKind {
    pub fn label(self) -> &'static str {
        match self {
            TransmitterKind::Dtmb => "DTMB",
            TransmitterKind::Tcofdm => "TC-OFDM",
            TransmitterKind::Fm => "FM",
        }
    }
}

/// A geodetic antenna position (WGS-84 ellipsoidal height).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GeodeticSpec {
    /// Geodetic latitude (degrees, north positive).
    pub lat_deg: f64,
    /// Geodetic longitude (degrees, east positive).
    pub lon_deg: f64,
    /// Antenna height above the WGS-84 ellipsoid (m).
    pub h_m: f64,
}

/// One `[[transmitter]]`: exactly one of `position` (geodetic) or `position_enu_m`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TransmitterSpec {
    /// Identifier: `"D01"` for DTMB, `"T01"` for TC-OFDM, any label for FM.
    pub id: String,
    pub kind: TransmitterKind,
    /// A label for maps and tables (e.g. "Central Radio and TV Tower").
    #[serde(default)]
    pub name: Option<String>,
    /// Antenna position as latitude, longitude and height; exactly one of this and
    /// `position_enu_m`.
    #[serde(default)]
    pub position: Option<GeodeticSpec>,
    /// Antenna position in the world's ENU frame (m).
    #[serde(default)]
    pub position_enu_m: Option<[f64; 3]>,
    /// UHF channel (DTMB; China's plan, channels 13–69).
    #[serde(default)]
    pub channel: Option<u32>,
    /// Carrier frequency (MHz); required for FM and TC-OFDM, derived from the channel for DTMB.
    #[serde(default)]
    pub freq_mhz: Option<f64>,
    /// Effective radiated power (kW).
    pub erp_kw: f64,
    /// DTMB or TC-OFDM frame header: `"pn420"`, `"pn595"` or `"pn945"`; default pn945.
    #[serde(default)]
    pub pn_mode: Option<String>,
    /// Transmitter clock offset from GPS time (ns).
    #[serde(default)]
    pub clock_offset_ns: f64,
    /// Transmitter clock drift (ns/s, i.e. parts per billion).
    #[serde(default)]
    pub clock_drift_ppb: f64,
    /// DTMB single-frequency network: towers naming the same network transmit the same
    /// signal (payload and frame schedule) on the same channel and PN mode. Towers on one
    /// channel always add at the receiver; without a common `sfn` their payloads are
    /// independent. Default: none.
    #[serde(default)]
    pub sfn: Option<String>,
    /// DTMB data layer (GB 20600 transmitter, issue 25): the constellation (`"4qam-nr"`,
    /// `"4qam"`, `"16qam"`, `"32qam"`, `"64qam"`), LDPC rate (`"0.4"`, `"0.6"`, `"0.8"`),
    /// time-interleaver depth (240, 720), carriers (3780, 1) and the transport stream it
    /// carries (a path relative to the world file; null packets after it, or only null
    /// packets without it). With none of these keys the tower's bodies are random 64QAM.
    /// `hybridnav layout` takes the constellation and rate for the tower's service
    /// threshold (64QAM 0.6 without them).
    #[serde(default)]
    pub qam: Option<String>,
    /// See `qam`.
    #[serde(default)]
    pub fec: Option<String>,
    /// See `qam`.
    #[serde(default)]
    pub interleaver: Option<usize>,
    /// See `qam`.
    #[serde(default)]
    pub carriers: Option<usize>,
    /// See `qam`.
    #[serde(default)]
    pub payload: Option<String>,
}

/// A transmitter with its position resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Transmitter {
    pub id: String,
    pub kind: TransmitterKind,
    pub name: Option<String>,
    pub pos_enu_m: nalgebra::Vector3<f64>,
    pub pos_ecef_m: nalgebra::Vector3<f64>,
    pub freq_hz: f64,
    pub erp_dbw: f64,
    pub spec: TransmitterSpec,
}

impl Transmitter {
    /// The transmitter as a DTMB or TC-OFDM receiver takes it (an id that does not parse
    /// becomes emitter 1 of `system`). Every receiver of a trial and a world's IQ
    /// recording build their towers here, so they describe the same towers.
    pub fn tower_spec(&self, system: crate::core::System) -> crate::dtmb::TowerSpec {
        crate::dtmb::TowerSpec {
            id: self
                .id
                .parse()
                .unwrap_or(crate::core::EmitterId::new(system, 1)),
            pos_enu_m: self.pos_enu_m,
            pos_ecef_m: self.pos_ecef_m,
            channel: self.spec.channel.unwrap_or(0).min(255) as u8,
            freq_hz: self.freq_hz,
            erp_dbw: self.erp_dbw,
            pn_mode: self.pn_mode(),
            clock_offset_s: self.spec.clock_offset_ns * 1e-9,
            clock_drift_s_per_s: self.spec.clock_drift_ppb * 1e-9,
            sfn: self.spec.sfn.clone(),
        }
    }

    /// The DTMB/TC-OFDM frame-header mode (validated at load; PN945 by default).
    pub fn pn_mode(&self) -> crate::dtmb::PnMode {
        self.spec
            .pn_mode
            .as_deref()
            .and_then(|m| m.parse().ok())
            .unwrap_or(crate::dtmb::PnMode::Pn945)
    }
}

/// Checks that the DTMB towers of each single-frequency network share their carrier and
/// PN mode (they transmit one signal). Returns the index of the first offending
/// transmitter, the key and the message.
///
/// # Errors
/// `(index, "sfn", message)` naming both towers and what differs.
pub fn check_sfn_groups(transmitters: &[Transmitter]) -> Result<(), (usize, String, String)> {
    for (i, t) in transmitters.iter().enumerate() {
        let Some(name) = &t.spec.sfn else { continue };
        let first = transmitters[..i]
            .iter()
            .find(|o| o.spec.sfn.as_deref() == Some(name.as_str()));
        if let Some(o) = first {
            if o.freq_hz != t.freq_hz || o.pn_mode() != t.pn_mode() {
                return Err((
                    i,
                    "sfn".into(),
                    format!(
                        "towers {} and {} are both in single-frequency network {name:?} but                          differ in carrier ({} vs {} MHz) or PN mode ({} vs {}): an SFN's                          towers transmit one signal on one channel",
                        o.id,
                        t.id,
                        o.freq_hz * 1e-6,
                        t.freq_hz * 1e-6,
                        o.pn_mode(),
                        t.pn_mode()
                    ),
                ));
            }
        }
    }
    Ok(())
}

impl TransmitterSpec {
    /// Resolves position and frequency.
    ///
    /// # Errors
    /// `(key below "transmitter[i]", message)`.
    pub fn resolve(&self, frame: &EnuFrame) -> Result<Transmitter, (String, String)> {
        let err = |k: &str, m: String| Err((k.to_string(), m));
        let (pos_enu_m, pos_ecef_m) = match (&self.position, &self.position_enu_m) {
            (Some(g), None) => {
                if !(g.lat_deg.is_finite()
                    && g.lon_deg.is_finite()
                    && g.h_m.is_finite()
                    && g.lat_deg.abs() <= 90.0
                    && g.h_m.abs() < 1e5)
                {
                    return err(
                        "position",
                        format!("expected a latitude, longitude (degrees) and height (m), got {g:?}"),
                    );
                }
                let ecef = Geodetic::from_deg(g.lat_deg, g.lon_deg, g.h_m).to_ecef();
                (frame.enu_of_ecef(&ecef), ecef)
            }
            (None, Some(p)) => {
                if !p.iter().all(|v| v.is_finite() && v.abs() < 1e6) {
                    return err("position_enu_m", format!("expected finite [e, n, u] in m, got {p:?}"));
                }
                let enu = nalgebra::Vector3::new(p[0], p[1], p[2]);
                (enu, frame.ecef_of_enu(&enu))
            }
            _ => {
                return err(
                    "position",
                    "expected exactly one of position = { lat_deg, lon_deg, h_m } or position_enu_m = [e, n, u]".into(),
                )
            }
        };
        if !(self.erp_kw.is_finite() && self.erp_kw > 0.0 && self.erp_kw <= 1e4) {
            return err(
                "erp_kw",
                format!("expected an ERP in (0, 10000] kW, got {}", self.erp_kw),
            );
        }
        let freq_hz = match (self.kind, self.channel, self.freq_mhz) {
            (TransmitterKind::Dtmb, Some(ch), None) => crate::dtmb::uhf_channel_center_hz(ch)
                .map_err(|e| ("channel".to_string(), e.to_string()))?,
            (TransmitterKind::Dtmb, None, Some(f)) if (470.0..=862.0).contains(&f) => f * 1e6,
            (TransmitterKind::Dtmb, _, _) => {
                return err(
                    "channel",
                    "expected exactly one of channel = 13…69 or freq_mhz in 470–862 for a DTMB transmitter".into(),
                )
            }
            (TransmitterKind::Fm, None, Some(f)) if (87.0..=108.0).contains(&f) => f * 1e6,
            (TransmitterKind::Fm, _, _) => {
                return err("freq_mhz", "expected freq_mhz in 87–108 (and no channel) for an FM station".into())
            }
            (TransmitterKind::Tcofdm, None, Some(f)) if f.is_finite() && (100.0..=6000.0).contains(&f) => f * 1e6,
            (TransmitterKind::Tcofdm, _, _) => {
                return err("freq_mhz", "expected freq_mhz in 100–6000 (and no channel) for a TC-OFDM base station".into())
            }
        };
        if let Some(m) = &self.pn_mode {
            if self.kind == TransmitterKind::Fm {
                return err(
                    "pn_mode",
                    "pn_mode applies to DTMB and TC-OFDM transmitters only".into(),
                );
            }
            if let Err(e) = m.parse::<crate::dtmb::PnMode>() {
                return err("pn_mode", e.to_string());
            }
        }
        if let Some(name) = &self.sfn {
            if self.kind != TransmitterKind::Dtmb {
                return err("sfn", "sfn applies to DTMB transmitters only".into());
            }
            if name.trim().is_empty() {
                return err("sfn", "expected a network name, got an empty string".into());
            }
        }
        for (k, v) in [
            ("clock_offset_ns", self.clock_offset_ns),
            ("clock_drift_ppb", self.clock_drift_ppb),
        ] {
            if !(v.is_finite() && v.abs() < 1e9) {
                return err(k, format!("expected a finite value, got {v}"));
            }
        }
        Ok(Transmitter {
            id: self.id.clone(),
            kind: self.kind,
            name: self.name.clone(),
            pos_enu_m,
            pos_ecef_m,
            freq_hz,
            erp_dbw: 10.0 * (self.erp_kw * 1e3).log10(),
            spec: self.clone(),
        })
    }
}
