//! The scene's configuration: buildings, vegetation, indoor zones and ground surfaces, as a
//! world file would write them, with their validation.
//!
//! Every polygon is a list of `[east, north]` vertices in metres of the world's ENU frame,
//! without repeating the first vertex at the end. Either winding is accepted; validation
//! normalises footprints to counter-clockwise order so that the outward normal of the edge
//! from `v[i]` to `v[i+1]` is `(dy, −dx)/len`, which the reflection code relies on.
//!
//! Heights are metres above the scene's flat ground plane `ground.height_m` (the ENU up
//! coordinate of the ground). Terrain is not modelled: the scene is a flat city.
//!
//! Material constants are those of ITU-R P.2040-1 Table 3 (relative permittivity
//! `ε' = a f^b`, conductivity `σ = c f^d` S/m, f in GHz, stated valid 1–100 GHz for most
//! materials; below 1 GHz the 1 GHz values are used, which is the usual practice because
//! both vary slowly there) and ITU-R P.527 for water. Penetration losses per wall are those
//! of 3GPP TR 38.901 Table 7.4.3-1 (stated valid 0.5–100 GHz, used at the 0.5 GHz value
//! below it).

use crate::core::config::check_range;
use crate::core::ConfigIssue;
use serde::{Deserialize, Serialize};

/// The largest number of vertices one polygon may have. Footprints of real buildings have
/// tens; the limit bounds the per-ray stack buffer of edge crossings.
pub const MAX_POLYGON_VERTICES: usize = 512;

/// The largest scene coordinate accepted (m): 1 000 km, far beyond any city, so that
/// products of coordinates stay exact enough for the geometric predicates.
pub const MAX_COORDINATE_M: f64 = 1.0e6;

/// The material of a building's outer walls.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum WallMaterial {
    /// Reinforced concrete (the default: most urban façades).
    #[default]
    Concrete,
    /// Brick masonry.
    Brick,
    /// Standard multi-pane glass curtain wall.
    Glass,
    /// Infrared-reflective (metal-coated) glass of thermally efficient buildings.
    IrrGlass,
    /// Wood.
    Wood,
    /// Metal cladding: a perfect conductor for reflection.
    Metal,
}

impl WallMaterial {
    /// All materials, in the order of [`WallMaterial::index`].
    pub const ALL: [WallMaterial; 6] = [
        WallMaterial::Concrete,
        WallMaterial::Brick,
        WallMaterial::Glass,
        WallMaterial::IrrGlass,
        WallMaterial::Wood,
        WallMaterial::Metal,
    ];

    /// A dense index `0..6`, used to count wall crossings per material.
    pub fn index(self) -> usize {
        match self {
            WallMaterial::Concrete => 0,
            WallMaterial::Brick => 1,
            WallMaterial::Glass => 2,
            WallMaterial::IrrGlass => 3,
            WallMaterial::Wood => 4,
            WallMaterial::Metal => 5,
        }
    }

    /// Relative permittivity ε' and conductivity σ (S/m) at `freq_hz` (ITU-R P.2040-1
    /// Table 3: concrete a = 5.31, c = 0.0326, d = 0.8095; brick 3.75, 0.038, 0; glass 6.27,
    /// 0.0043, 1.1925; wood 1.99, 0.0047, 1.0718; b = 0 for all of them). IRR glass is
    /// glass with a metal coating; its reflection is dominated by the coating, so it uses a
    /// conductivity of 1e5 S/m (an assumption: P.2040 lists no value). Metal is modelled
    /// with σ = 1e7 S/m, as P.2040 does.
    pub fn permittivity(self, freq_hz: f64) -> (f64, f64) {
        // Below 1 GHz the 1 GHz value is used (see the module documentation).
        let f_ghz = (freq_hz * 1e-9).max(1.0);
        match self {
            WallMaterial::Concrete => (5.31, 0.0326 * f_ghz.powf(0.8095)),
            WallMaterial::Brick => (3.75, 0.038),
            WallMaterial::Glass => (6.27, 0.0043 * f_ghz.powf(1.1925)),
            WallMaterial::IrrGlass => (6.27, 1.0e5),
            WallMaterial::Wood => (1.99, 0.0047 * f_ghz.powf(1.0718)),
            WallMaterial::Metal => (1.0, 1.0e7),
        }
    }

    /// The loss of one wall crossing (dB), 3GPP TR 38.901 Table 7.4.3-1 with f in GHz:
    /// standard glass 2 + 0.2 f, IRR glass 23 + 0.3 f, concrete 5 + 4 f, wood 4.85 + 0.12 f.
    /// Brick uses the concrete formula (TR 38.901 has no brick entry; masonry is close to
    /// it in ITU-R P.2040 measurements) and metal a fixed 50 dB (an assumption: a metal-clad
    /// wall passes nothing but what leaks through joints and windows).
    pub fn penetration_loss_db(self, freq_hz: f64) -> f64 {
        let f_ghz = (freq_hz * 1e-9).max(0.5);
        match self {
            WallMaterial::Concrete | WallMaterial::Brick => 5.0 + 4.0 * f_ghz,
            WallMaterial::Glass => 2.0 + 0.2 * f_ghz,
            WallMaterial::IrrGlass => 23.0 + 0.3 * f_ghz,
            WallMaterial::Wood => 4.85 + 0.12 * f_ghz,
            WallMaterial::Metal => 50.0,
        }
    }
}

/// The building class of ITU-R P.2109 building entry loss.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum BuildingClass {
    /// Traditional construction (the default).
    #[default]
    Traditional,
    /// Thermally efficient: metallised glass, foil-backed insulation.
    ThermallyEfficient,
}

/// The material of an open ground surface (ITU-R P.2040-1 Table 3 for ground, ITU-R P.527
/// for water).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum GroundMaterial {
    /// Medium-dry ground (the default): ε' = 15 f^−0.1, σ = 0.035 f^1.63.
    #[default]
    MediumDry,
    /// Very dry ground: ε' = 3, σ = 0.00015 f^2.52.
    VeryDry,
    /// Wet ground: ε' = 30 f^−0.4, σ = 0.15 f^1.30.
    Wet,
    /// Asphalt or concrete paving: P.2040's concrete.
    Paved,
    /// Fresh water (lakes, rivers): ε' = 80, σ = 0.01 S/m (P.527 at VHF/UHF).
    FreshWater,
    /// Sea water: ε' = 70, σ = 5 S/m (P.527 at VHF/UHF).
    SeaWater,
}

impl GroundMaterial {
    /// Relative permittivity and conductivity (S/m) at `freq_hz`, f clamped to ≥ 1 GHz
    /// for the P.2040 power laws as for walls.
    pub fn permittivity(self, freq_hz: f64) -> (f64, f64) {
        let f_ghz = (freq_hz * 1e-9).max(1.0);
        match self {
            GroundMaterial::MediumDry => (15.0 * f_ghz.powf(-0.1), 0.035 * f_ghz.powf(1.63)),
            GroundMaterial::VeryDry => (3.0, 0.00015 * f_ghz.powf(2.52)),
            GroundMaterial::Wet => (30.0 * f_ghz.powf(-0.4), 0.15 * f_ghz.powf(1.30)),
            GroundMaterial::Paved => WallMaterial::Concrete.permittivity(freq_hz),
            GroundMaterial::FreshWater => (80.0, 0.01),
            GroundMaterial::SeaWater => (70.0, 5.0),
        }
    }
}

/// One building: a vertical prism over its footprint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BuildingConfig {
    /// Footprint vertices `[east, north]` (m), at least three, not self-intersecting.
    pub footprint_enu_m: Vec<[f64; 2]>,
    /// Roof height above the ground plane (m), > 0.
    pub height_m: f64,
    /// Outer wall material; default concrete.
    #[serde(default)]
    pub material: WallMaterial,
    /// Building class for the entry loss of a receiver inside; default traditional.
    #[serde(default)]
    pub class: BuildingClass,
}

/// A forest, park or row of trees: a vertical prism of foliage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ForestConfig {
    /// Outline vertices `[east, north]` (m).
    pub polygon_enu_m: Vec<[f64; 2]>,
    /// Canopy top above the ground plane (m), > 0.
    pub height_m: f64,
    /// Height of the canopy's underside (m), `0 ≤ base < height`; default 0 (foliage down
    /// to the ground, as a hedge or a young forest). Street trees have a trunk of 2–3 m.
    #[serde(default)]
    pub canopy_base_m: f64,
    /// Foliage density in (0, 1]: the specific attenuation relative to dense in-leaf
    /// woodland (see [`crate::propagation::pathloss::vegetation_loss_db`]); default 1.
    #[serde(default = "default_density")]
    pub foliage_density: f64,
}

fn default_density() -> f64 {
    1.0
}

/// An indoor area that is not a modelled building (a station concourse, an underground
/// mall, a covered market): a receiver inside it is indoor, but it blocks no ray.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IndoorZoneConfig {
    /// Outline vertices `[east, north]` (m).
    pub polygon_enu_m: Vec<[f64; 2]>,
    /// Floor height (m); may be negative for underground zones.
    pub floor_m: f64,
    /// Ceiling height (m), > floor.
    pub ceiling_m: f64,
    /// Building class for its entry loss; default traditional.
    #[serde(default)]
    pub class: BuildingClass,
}

/// An open ground surface of a particular material (water, wet meadow, paving).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SurfaceConfig {
    /// Outline vertices `[east, north]` (m).
    pub polygon_enu_m: Vec<[f64; 2]>,
    /// The surface material.
    pub material: GroundMaterial,
}

/// The flat ground plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GroundConfig {
    /// ENU up coordinate of the ground (m); default 0.
    #[serde(default)]
    pub height_m: f64,
    /// Material wherever no [`SurfaceConfig`] says otherwise; default medium-dry ground.
    #[serde(default)]
    pub material: GroundMaterial,
    /// Whether the ground reflection is computed; default true.
    #[serde(default = "default_true")]
    pub reflect: bool,
}

fn default_true() -> bool {
    true
}

impl Default for GroundConfig {
    fn default() -> Self {
        Self {
            height_m: 0.0,
            material: GroundMaterial::default(),
            reflect: true,
        }
    }
}

/// How the link computation behaves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LinkOptions {
    /// Walls farther than this from the receiver (horizontal distance, m) are not tried as
    /// reflectors; default 200 m. A reflection from farther away arrives with > 400 m of
    /// excess path in a street canyon and is usually weaker than the local ones.
    #[serde(default = "default_reflection_range")]
    pub max_reflection_range_m: f64,
    /// Cross-polarisation discrimination of the GNSS receive antenna (dB): the gain of
    /// an RHCP antenna to LHCP relative to RHCP is −XPD; default 10 dB, a typical patch.
    #[serde(default = "default_xpd")]
    pub gnss_antenna_xpd_db: f64,
    /// Reflections weaker than this relative to the line of sight (dB, ≤ 0) are dropped;
    /// default −40 dB.
    #[serde(default = "default_min_rel")]
    pub min_relative_amplitude_db: f64,
}

fn default_reflection_range() -> f64 {
    200.0
}
fn default_xpd() -> f64 {
    10.0
}
fn default_min_rel() -> f64 {
    -40.0
}

impl Default for LinkOptions {
    fn default() -> Self {
        Self {
            max_reflection_range_m: default_reflection_range(),
            gnss_antenna_xpd_db: default_xpd(),
            min_relative_amplitude_db: default_min_rel(),
        }
    }
}

/// The whole scene as a world file writes it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// Buildings; default none.
    #[serde(default)]
    pub buildings: Vec<BuildingConfig>,
    /// Forests and tree rows; default none.
    #[serde(default)]
    pub forests: Vec<ForestConfig>,
    /// Indoor zones; default none.
    #[serde(default)]
    pub indoor_zones: Vec<IndoorZoneConfig>,
    /// Ground surfaces of particular materials; default none.
    #[serde(default)]
    pub surfaces: Vec<SurfaceConfig>,
    /// The ground plane.
    #[serde(default)]
    pub ground: GroundConfig,
    /// Link computation options.
    #[serde(default)]
    pub link: LinkOptions,
}

fn positive(key: &str, v: f64, what: &str) -> Result<(), ConfigIssue> {
    if v.is_finite() && v > 0.0 && v <= MAX_COORDINATE_M {
        Ok(())
    } else {
        Err(ConfigIssue::new(
            key,
            format!("expected {what} > 0 (m), got {v}"),
        ))
    }
}

impl SceneConfig {
    /// Checks every value and returns the first issue, with the key path of the offending
    /// field (e.g. `"buildings[3].footprint_enu_m"`).
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        for (i, b) in self.buildings.iter().enumerate() {
            validate_polygon(
                &format!("buildings[{i}].footprint_enu_m"),
                &b.footprint_enu_m,
            )?;
            positive(
                &format!("buildings[{i}].height_m"),
                b.height_m,
                "a building height",
            )?;
        }
        for (i, f) in self.forests.iter().enumerate() {
            validate_polygon(&format!("forests[{i}].polygon_enu_m"), &f.polygon_enu_m)?;
            positive(
                &format!("forests[{i}].height_m"),
                f.height_m,
                "a canopy height",
            )?;
            let key = format!("forests[{i}].canopy_base_m");
            if !(f.canopy_base_m.is_finite()
                && f.canopy_base_m >= 0.0
                && f.canopy_base_m < f.height_m)
            {
                return Err(ConfigIssue::new(
                    key,
                    format!(
                        "expected a canopy base in [0, height_m = {}) m, got {}",
                        f.height_m, f.canopy_base_m
                    ),
                ));
            }
            let key = format!("forests[{i}].foliage_density");
            if !(f.foliage_density.is_finite()
                && f.foliage_density > 0.0
                && f.foliage_density <= 1.0)
            {
                return Err(ConfigIssue::new(
                    key,
                    format!(
                        "expected a foliage density in (0, 1], got {}",
                        f.foliage_density
                    ),
                ));
            }
        }
        for (i, z) in self.indoor_zones.iter().enumerate() {
            validate_polygon(
                &format!("indoor_zones[{i}].polygon_enu_m"),
                &z.polygon_enu_m,
            )?;
            check_range(
                &format!("indoor_zones[{i}].floor_m"),
                z.floor_m,
                -MAX_COORDINATE_M,
                MAX_COORDINATE_M,
                false,
                "a floor height (m)",
            )?;
            if !(z.ceiling_m.is_finite()
                && z.ceiling_m > z.floor_m
                && z.ceiling_m <= MAX_COORDINATE_M)
            {
                return Err(ConfigIssue::new(
                    format!("indoor_zones[{i}].ceiling_m"),
                    format!(
                        "expected a ceiling above floor_m = {} m, got {}",
                        z.floor_m, z.ceiling_m
                    ),
                ));
            }
        }
        for (i, s) in self.surfaces.iter().enumerate() {
            validate_polygon(&format!("surfaces[{i}].polygon_enu_m"), &s.polygon_enu_m)?;
        }
        check_range(
            "ground.height_m",
            self.ground.height_m,
            -MAX_COORDINATE_M,
            MAX_COORDINATE_M,
            false,
            "a ground height (m)",
        )?;
        check_range(
            "link.max_reflection_range_m",
            self.link.max_reflection_range_m,
            0.0,
            100_000.0,
            false,
            "a reflection range (m)",
        )?;
        check_range(
            "link.gnss_antenna_xpd_db",
            self.link.gnss_antenna_xpd_db,
            0.0,
            100.0,
            false,
            "a cross-polarisation discrimination (dB)",
        )?;
        check_range(
            "link.min_relative_amplitude_db",
            self.link.min_relative_amplitude_db,
            -300.0,
            0.0,
            false,
            "a relative amplitude threshold (dB)",
        )?;
        Ok(())
    }
}

/// Twice the signed area of a polygon (positive when counter-clockwise).
pub(crate) fn signed_area2(v: &[[f64; 2]]) -> f64 {
    let n = v.len();
    (0..n)
        .map(|i| {
            let a = v[i];
            let b = v[(i + 1) % n];
            a[0] * b[1] - b[0] * a[1]
        })
        .sum()
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Whether closed segments `ab` and `cd` share a point (orientation predicates, collinear
/// overlaps included).
pub(crate) fn segments_touch(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = orient(c, d, a);
    let d2 = orient(c, d, b);
    let d3 = orient(a, b, c);
    let d4 = orient(a, b, d);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

/// Checks that a polygon is usable: 3 to [`MAX_POLYGON_VERTICES`] finite vertices within
/// ±[`MAX_COORDINATE_M`], no repeated consecutive vertex, a non-zero area, and no two
/// non-adjacent edges touching (a simple polygon). The O(n²) edge test runs once, at
/// load time.
pub fn validate_polygon(key: &str, v: &[[f64; 2]]) -> Result<(), ConfigIssue> {
    let n = v.len();
    if !(3..=MAX_POLYGON_VERTICES).contains(&n) {
        return Err(ConfigIssue::new(
            key,
            format!("expected a polygon of 3 to {MAX_POLYGON_VERTICES} vertices, got {n}"),
        ));
    }
    if let Some(p) = v.iter().find(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(ConfigIssue::new(
            key,
            format!("expected finite vertices, got {p:?}"),
        ));
    }
    if let Some(p) = v
        .iter()
        .find(|p| p[0].abs() > MAX_COORDINATE_M || p[1].abs() > MAX_COORDINATE_M)
    {
        return Err(ConfigIssue::new(
            key,
            format!("expected vertices within ±{MAX_COORDINATE_M} m of the origin, got {p:?}"),
        ));
    }
    for i in 0..n {
        if v[i] == v[(i + 1) % n] {
            return Err(ConfigIssue::new(
                key,
                format!(
                    "vertex {i} {:?} repeats at {}; do not close the polygon by repeating the first vertex",
                    v[i],
                    (i + 1) % n
                ),
            ));
        }
    }
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        for j in i + 1..n {
            // Adjacent edges share a vertex by construction; skip them.
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            let (c, d) = (v[j], v[(j + 1) % n]);
            if segments_touch(a, b, c, d) {
                return Err(ConfigIssue::new(
                    key,
                    format!(
                        "the polygon intersects itself: edge {i} ({a:?}→{b:?}) touches edge {j} ({c:?}→{d:?})"
                    ),
                ));
            }
        }
        // A spike (an edge folding straight back on the previous one) touches its
        // neighbour along a stretch rather than at the shared vertex.
        let prev = v[(i + n - 1) % n];
        if orient(prev, a, b) == 0.0
            && (b[0] - a[0]) * (prev[0] - a[0]) + (b[1] - a[1]) * (prev[1] - a[1]) > 0.0
        {
            return Err(ConfigIssue::new(
                key,
                format!("the polygon folds back on itself at vertex {i} {a:?}"),
            ));
        }
    }
    if signed_area2(v).abs() < 1e-6 {
        return Err(ConfigIssue::new(
            key,
            "expected a polygon of non-zero area, got a degenerate one",
        ));
    }
    Ok(())
}
