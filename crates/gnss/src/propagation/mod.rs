//! Radio propagation in a city: buildings, vegetation, indoor zones and ground, and what a
//! link between a receiver and an emitter looks like through them.
//!
//! * [`scene`]: the serde configuration ([`SceneConfig`]) and its validation.
//! * [`index`]: the bounding-volume hierarchy that makes a ray test cost ~O(log n).
//! * [`los`]: segment tests: clear, through foliage (with the path length), or blocked.
//! * [`reflect`]: single-bounce specular reflections off walls and the ground.
//! * [`pathloss`]: free space, Okumura–Hata, Extended Hata (SM.2028), P.2109 building entry
//!   loss, P.833 vegetation, wall penetration.
//! * [`shadowing`]: the spatially consistent log-normal shadowing field.
//!
//! The entry point of the hot loop is [`Scene::link`], which fills a caller-owned
//! [`LinkPaths`] (a fixed-capacity list: no allocation per call) with the direct path and
//! the reflections, each with excess delay, amplitude relative to the free-space line of
//! sight, phase and Doppler. Path loss proper (distance, environment, shadowing) is the
//! caller's: it picks the model for its band from [`pathloss`] and adds the field value.
//!
//! Coordinates are metres of the world's ENU frame ([`crate::core::EnuFrame`]); a
//! satellite is an [`Emitter::Direction`], the unit ENU vector towards it (from
//! `azimuth_elevation`: `(cos e sin a, cos e cos a, sin e)`).
//!
//! Receivers and transmitters inside buildings: see [`Scene::check_receiver`] and
//! [`Scene::check_transmitter`]; in [`Scene::link`] a receiver inside a building or an
//! indoor zone is *indoor*: the building it is in is ignored for blocking, the direct path
//! carries the P.2109 median building entry loss, and no reflection is computed. A
//! transmitter inside a building is treated as an antenna mounted on it (its building is
//! ignored for blocking); the world loader should reject it with `check_transmitter`.

pub mod index;
pub mod los;
pub mod pathloss;
pub mod reflect;
pub mod scene;
pub mod shadowing;

pub use los::{LosState, Obstruction};
pub use reflect::Polarisation;
pub use scene::{
    BuildingClass, BuildingConfig, ForestConfig, GroundConfig, GroundMaterial, IndoorZoneConfig,
    LinkOptions, SceneConfig, SurfaceConfig, WallMaterial,
};
pub use shadowing::{ShadowingConfig, ShadowingField};

use crate::core::{ConfigIssue, C_MPS};
use index::Aabb;
use los::{point_in_polygon, PrismSet};
use nalgebra::Vector3;
use reflect::Surface;

/// The most paths one link reports: the direct path, the ground and up to 14 walls. When
/// more reflections exist the weakest are dropped.
pub const MAX_PATHS: usize = 16;

/// Where the signal comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Emitter {
    /// A transmitter at a point (ENU, m).
    Point(Vector3<f64>),
    /// A source at infinity in this unit ENU direction (a satellite): a plane wave.
    Direction(Vector3<f64>),
}

/// The radio parameters of a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkParams {
    /// Carrier frequency (Hz), > 0.
    pub freq_hz: f64,
    /// Polarisation of the transmitted wave and the receive antenna.
    pub polarisation: Polarisation,
    /// Receiver velocity (ENU, m/s), for the Doppler of each path.
    pub rx_vel_enu_mps: Vector3<f64>,
}

/// What a path is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// The direct path (possibly attenuated by foliage, walls or building entry).
    Direct,
    /// Reflected off the ground.
    Ground,
    /// Reflected off a wall of building `building` (its index in the configuration).
    Wall { building: u32 },
}

/// One propagation path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Path {
    /// What it is.
    pub kind: PathKind,
    /// Extra delay over the geometric direct path (s), ≥ 0.
    pub excess_delay_s: f64,
    /// Linear field amplitude relative to the free-space line of sight.
    pub amplitude: f64,
    /// Carrier phase relative to the free-space line of sight (rad, in (−π, π]).
    pub phase_rad: f64,
    /// Doppler shift due to the receiver's velocity (Hz).
    pub doppler_hz: f64,
    /// Unit ENU direction the path arrives from (towards the emitter or the reflector).
    pub arrival_enu: Vector3<f64>,
}

const EMPTY_PATH: Path = Path {
    kind: PathKind::Direct,
    excess_delay_s: 0.0,
    amplitude: 0.0,
    phase_rad: 0.0,
    doppler_hz: 0.0,
    arrival_enu: Vector3::new(0.0, 0.0, 0.0),
};

/// The result of [`Scene::link`], owned and reused by the caller.
#[derive(Clone, Debug)]
pub struct LinkPaths {
    /// Line-of-sight state of the direct path.
    pub los: LosState,
    /// Everything on the direct path.
    pub obstruction: Obstruction,
    /// The receiver's indoor state: the building or indoor zone it is in.
    pub rx_indoor: Option<Indoor>,
    /// Total extra loss on the direct path (dB): walls + vegetation + building entry.
    pub direct_loss_db: f64,
    paths: [Path; MAX_PATHS],
    len: usize,
}

impl Default for LinkPaths {
    fn default() -> Self {
        Self::new()
    }
}

impl LinkPaths {
    /// An empty result.
    pub fn new() -> Self {
        Self {
            los: LosState::Clear,
            obstruction: Obstruction::default(),
            rx_indoor: None,
            direct_loss_db: 0.0,
            paths: [EMPTY_PATH; MAX_PATHS],
            len: 0,
        }
    }

    /// The paths, direct first, then reflections in discovery order.
    pub fn paths(&self) -> &[Path] {
        &self.paths[..self.len]
    }

    fn clear(&mut self) {
        *self = Self {
            paths: self.paths,
            ..Self::new()
        };
        self.len = 0;
    }

    /// Adds a path; when full, replaces the weakest reflection if the new one is stronger.
    fn push(&mut self, p: Path) {
        if self.len < MAX_PATHS {
            self.paths[self.len] = p;
            self.len += 1;
            return;
        }
        let weakest = (1..MAX_PATHS)
            .min_by(|&a, &b| self.paths[a].amplitude.total_cmp(&self.paths[b].amplitude));
        if let Some(w) = weakest {
            if self.paths[w].amplitude < p.amplitude {
                self.paths[w] = p;
            }
        }
    }
}

/// Where a receiver is indoors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Indoor {
    /// Inside building `i` of the configuration.
    Building(u32),
    /// Inside indoor zone `i` of the configuration.
    Zone(u32),
}

/// A validated scene, ready for link queries. Immutable and `Sync`: one per world, shared
/// by every trial thread.
#[derive(Clone, Debug)]
pub struct Scene {
    pub(crate) buildings: PrismSet,
    pub(crate) materials: Vec<WallMaterial>,
    classes: Vec<BuildingClass>,
    pub(crate) forests: PrismSet,
    pub(crate) foliage_density: Vec<f64>,
    zones: PrismSet,
    zone_classes: Vec<BuildingClass>,
    surfaces: Vec<SurfaceConfig>,
    ground: GroundConfig,
    options: LinkOptions,
    /// The box around every building and forest.
    pub(crate) bounds: Aabb,
}

fn ccw(poly: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut v = poly.to_vec();
    if scene::signed_area2(&v) < 0.0 {
        v.reverse();
    }
    v
}

fn finite(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Scene {
    /// Validates `cfg` and builds the spatial indices.
    pub fn new(cfg: &SceneConfig) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let g = cfg.ground.height_m;
        let buildings = PrismSet::new(
            cfg.buildings
                .iter()
                .map(|b| (ccw(&b.footprint_enu_m), g, g + b.height_m)),
        );
        let forests = PrismSet::new(
            cfg.forests
                .iter()
                .map(|f| (ccw(&f.polygon_enu_m), g + f.canopy_base_m, g + f.height_m)),
        );
        let zones = PrismSet::new(
            cfg.indoor_zones
                .iter()
                .map(|z| (ccw(&z.polygon_enu_m), z.floor_m, z.ceiling_m)),
        );
        let bounds = buildings.bvh.bounds().union(&forests.bvh.bounds());
        Ok(Self {
            buildings,
            materials: cfg.buildings.iter().map(|b| b.material).collect(),
            classes: cfg.buildings.iter().map(|b| b.class).collect(),
            forests,
            foliage_density: cfg.forests.iter().map(|f| f.foliage_density).collect(),
            zones,
            zone_classes: cfg.indoor_zones.iter().map(|z| z.class).collect(),
            surfaces: cfg
                .surfaces
                .iter()
                .map(|s| SurfaceConfig {
                    polygon_enu_m: ccw(&s.polygon_enu_m),
                    material: s.material,
                })
                .collect(),
            ground: cfg.ground.clone(),
            options: cfg.link.clone(),
            bounds,
        })
    }

    /// The number of buildings.
    pub fn building_count(&self) -> usize {
        self.materials.len()
    }

    /// The building that contains `p` (`ground ≤ z < roof`, footprint closed), if any.
    pub fn building_at(&self, p: &Vector3<f64>) -> Option<u32> {
        self.buildings.containing([p.x, p.y, p.z])
    }

    /// Where a receiver at `p` is: outdoor (`None`) or indoor. Errors (key `"receiver"`)
    /// for a non-finite position or one below the ground plane. A receiver inside a
    /// building is not an error: it is indoor, and [`Scene::link`] applies the building
    /// entry loss.
    pub fn check_receiver(&self, p: &Vector3<f64>) -> Result<Option<Indoor>, ConfigIssue> {
        if !finite(p) {
            return Err(ConfigIssue::new(
                "receiver",
                format!("expected a finite ENU position, got {p:?}"),
            ));
        }
        if p.z < self.ground.height_m {
            return Err(ConfigIssue::new(
                "receiver",
                format!(
                    "the receiver at up = {} m is below the ground plane at {} m",
                    p.z, self.ground.height_m
                ),
            ));
        }
        Ok(self.indoor_at(p))
    }

    /// Where a point `p` (ENU, m) is: inside a building (`ground ≤ z < roof`, footprint
    /// closed), inside an indoor zone, or outdoors (`None`). Unlike
    /// [`Scene::check_receiver`] it takes any point, as the run's reduction does when it
    /// splits each estimator's errors by where the truth was.
    pub fn indoor_at(&self, p: &Vector3<f64>) -> Option<Indoor> {
        if let Some(b) = self.building_at(p) {
            return Some(Indoor::Building(b));
        }
        self.zones.containing([p.x, p.y, p.z]).map(Indoor::Zone)
    }

    /// Checks a transmitter position: finite, not below the ground, and not inside a
    /// building (an antenna on a roof stands at or above the roof height). The error's
    /// key is `"transmitter"` and its message names the building.
    pub fn check_transmitter(&self, p: &Vector3<f64>) -> Result<(), ConfigIssue> {
        if !finite(p) || p.z < self.ground.height_m {
            return Err(ConfigIssue::new(
                "transmitter",
                format!("expected a finite position above the ground plane, got {p:?}"),
            ));
        }
        if let Some(b) = self.building_at(p) {
            let roof = self.buildings.prisms[b as usize].hi_m;
            return Err(ConfigIssue::new(
                "transmitter",
                format!(
                    "the transmitter at {:?} is inside building {b} (roof at {roof} m); place it at or above the roof",
                    [p.x, p.y, p.z]
                ),
            ));
        }
        Ok(())
    }

    fn ground_material_at(&self, x: f64, y: f64) -> GroundMaterial {
        self.surfaces
            .iter()
            .find(|s| point_in_polygon(&s.polygon_enu_m, [x, y]))
            .map_or(self.ground.material, |s| s.material)
    }

    /// The propagation paths of the link from `tx` to a receiver at `rx` (see the module
    /// documentation and [`reflect`]). `out` is cleared and filled; nothing is allocated.
    ///
    /// Errors (key `"link"`) for non-finite positions, a non-unit or downward-useless zero
    /// direction, or a non-positive frequency; `out` is then left empty.
    pub fn link(
        &self,
        rx: &Vector3<f64>,
        tx: &Emitter,
        params: &LinkParams,
        out: &mut LinkPaths,
    ) -> Result<(), ConfigIssue> {
        out.clear();
        let tx_ok = match tx {
            Emitter::Point(p) => finite(p),
            Emitter::Direction(u) => finite(u) && (u.norm() - 1.0).abs() < 1e-6,
        };
        let ok = finite(rx)
            && tx_ok
            && params.freq_hz.is_finite()
            && params.freq_hz > 0.0
            && finite(&params.rx_vel_enu_mps);
        if !ok {
            return Err(ConfigIssue::new(
                "link",
                format!(
                    "expected finite positions, a unit direction and a positive frequency, got rx {:?}, {tx:?}, {} Hz",
                    [rx.x, rx.y, rx.z],
                    params.freq_hz
                ),
            ));
        }
        let lambda_m = C_MPS / params.freq_hz;
        let indoor = self.indoor_at(rx);
        let rx_building = match indoor {
            Some(Indoor::Building(b)) => Some(b),
            _ => None,
        };
        let tx_building = match tx {
            Emitter::Point(p) => self.building_at(p),
            Emitter::Direction(_) => None,
        };
        let far = self.far_end(rx, tx);
        let obstruction = self.obstruction(rx, &far, [rx_building, tx_building]);
        let (direct_dist_m, arrival) = match tx {
            Emitter::Point(p) => {
                let d = p - rx;
                let n = d.norm();
                (n, if n > 0.0 { d / n } else { Vector3::z() })
            }
            Emitter::Direction(u) => (f64::INFINITY, *u),
        };
        let mut loss_db = obstruction.wall_loss_db(params.freq_hz)
            + pathloss::vegetation_loss_db(params.freq_hz, obstruction.foliage_weighted_m).0;
        if let Some(ind) = indoor {
            let class = match ind {
                Indoor::Building(b) => self.classes[b as usize],
                Indoor::Zone(z) => self.zone_classes[z as usize],
            };
            let elevation = arrival.z.clamp(-1.0, 1.0).asin();
            loss_db += pathloss::building_entry_loss_db(class, params.freq_hz, elevation, 0.5).0;
        }
        out.los = obstruction.state();
        out.obstruction = obstruction;
        out.rx_indoor = indoor;
        out.direct_loss_db = loss_db;
        out.push(Path {
            kind: PathKind::Direct,
            excess_delay_s: 0.0,
            amplitude: 10f64.powf(-loss_db / 20.0),
            phase_rad: 0.0,
            doppler_hz: params.rx_vel_enu_mps.dot(&arrival) / lambda_m,
            arrival_enu: arrival,
        });
        if indoor.is_some() {
            return Ok(());
        }
        let ctx = Ctx {
            rx: *rx,
            tx: *tx,
            params,
            lambda_m,
            direct_dist_m,
            tx_building,
        };
        if self.ground.reflect {
            self.ground_reflection(&ctx, out);
        }
        self.wall_reflections(&ctx, out);
        Ok(())
    }

    fn ground_reflection(&self, c: &Ctx, out: &mut LinkPaths) {
        let g = self.ground.height_m;
        let h = c.rx.z - g;
        if h <= 0.0 {
            return;
        }
        let (p, excess_m) = match c.tx {
            Emitter::Point(t) => {
                let ht = t.z - g;
                if ht <= 0.0 {
                    return;
                }
                let image = Vector3::new(t.x, t.y, g - ht);
                let p = c.rx + (image - c.rx) * (h / (h + ht));
                (p, (image - c.rx).norm() - c.direct_dist_m)
            }
            Emitter::Direction(u) => {
                if u.z <= 0.0 {
                    return;
                }
                let t = h / u.z;
                let p = c.rx + Vector3::new(u.x, u.y, -u.z) * t;
                (p, 2.0 * h * u.z)
            }
        };
        let horizontal = ((p.x - c.rx.x).powi(2) + (p.y - c.rx.y).powi(2)).sqrt();
        if horizontal > self.options.max_reflection_range_m {
            return;
        }
        // A reflection point under a building is a floor, not open ground.
        if self.building_at(&Vector3::new(p.x, p.y, g)).is_some() {
            return;
        }
        let (eps, sigma) = self
            .ground_material_at(p.x, p.y)
            .permittivity(c.params.freq_hz);
        self.finish_reflection(c, p, h, excess_m, Surface::Ground, eps, sigma, None, out);
    }

    fn wall_reflections(&self, c: &Ctx, out: &mut LinkPaths) {
        let r = self.options.max_reflection_range_m;
        let query = Aabb {
            min: [c.rx.x - r, c.rx.y - r, f64::NEG_INFINITY],
            max: [c.rx.x + r, c.rx.y + r, f64::INFINITY],
        };
        self.buildings.bvh.overlapping(&query, |b| {
            let poly = self.buildings.poly(b);
            let top = self.buildings.prisms[b as usize].hi_m;
            let n_v = poly.len();
            for k in 0..n_v {
                let (p0, p1) = (poly[k], poly[(k + 1) % n_v]);
                self.try_wall(c, b, p0, p1, top, out);
            }
            false
        });
    }

    #[allow(clippy::too_many_arguments)]
    fn try_wall(
        &self,
        c: &Ctx,
        b: u32,
        p0: [f64; 2],
        p1: [f64; 2],
        top_m: f64,
        out: &mut LinkPaths,
    ) {
        let e = [p1[0] - p0[0], p1[1] - p0[1]];
        let len = (e[0] * e[0] + e[1] * e[1]).sqrt();
        // Counter-clockwise footprint: the outward normal is the edge turned clockwise.
        let n = Vector3::new(e[1] / len, -e[0] / len, 0.0);
        let d_rx = n.x * (c.rx.x - p0[0]) + n.y * (c.rx.y - p0[1]);
        if d_rx <= 0.0 {
            return;
        }
        let (p, excess_m) = match c.tx {
            Emitter::Point(t) => {
                let d_tx = n.x * (t.x - p0[0]) + n.y * (t.y - p0[1]);
                if d_tx <= 0.0 {
                    return;
                }
                let image = t - n * (2.0 * d_tx);
                let p = c.rx + (image - c.rx) * (d_rx / (d_rx + d_tx));
                (p, (image - c.rx).norm() - c.direct_dist_m)
            }
            Emitter::Direction(u) => {
                let nu = n.dot(&u);
                if nu <= 0.0 {
                    return;
                }
                let mirrored = u - n * (2.0 * nu);
                (c.rx + mirrored * (d_rx / nu), 2.0 * d_rx * nu)
            }
        };
        let along = ((p.x - p0[0]) * e[0] + (p.y - p0[1]) * e[1]) / (len * len);
        if !(0.0..=1.0).contains(&along) || p.z < self.ground.height_m || p.z > top_m {
            return;
        }
        let horizontal = ((p.x - c.rx.x).powi(2) + (p.y - c.rx.y).powi(2)).sqrt();
        if horizontal > self.options.max_reflection_range_m {
            return;
        }
        let (eps, sigma) = self.materials[b as usize].permittivity(c.params.freq_hz);
        self.finish_reflection(
            c,
            p,
            d_rx,
            excess_m,
            Surface::Wall,
            eps,
            sigma,
            Some(b),
            out,
        );
    }

    /// Checks both legs of a reflection through point `p`, computes its amplitude, phase
    /// and Doppler, and adds it to `out` if it is strong enough.
    #[allow(clippy::too_many_arguments)]
    fn finish_reflection(
        &self,
        c: &Ctx,
        p: Vector3<f64>,
        d_plane_m: f64,
        excess_m: f64,
        surface: Surface,
        eps: f64,
        sigma: f64,
        building: Option<u32>,
        out: &mut LinkPaths,
    ) {
        let to_p = p - c.rx;
        let leg1_m = to_p.norm();
        if leg1_m <= 0.0 {
            return;
        }
        let arrival = to_p / leg1_m;
        let far = match c.tx {
            Emitter::Point(t) => t,
            Emitter::Direction(u) => self.far_end(&p, &Emitter::Direction(u)),
        };
        let skip = [building, c.tx_building];
        if self.segment_blocked_except(&c.rx, &p, skip)
            || self.segment_blocked_except(&p, &far, skip)
        {
            return;
        }
        let foliage_m = if self.forests.prisms.is_empty() {
            0.0
        } else {
            self.obstruction(&c.rx, &p, skip).foliage_weighted_m
                + self.obstruction(&p, &far, skip).foliage_weighted_m
        };
        let veg_db = pathloss::vegetation_loss_db(c.params.freq_hz, foliage_m).0;
        // The grazing angle's sine is the receiver's distance from the reflecting plane
        // over the length of the receiver's leg.
        let sin_psi = d_plane_m / leg1_m;
        let psi = sin_psi.clamp(0.0, 1.0).asin();
        let eta = reflect::complex_permittivity(eps, sigma, c.params.freq_hz);
        let gamma = reflect::effective_coefficient(
            eta,
            psi,
            c.params.polarisation,
            surface,
            self.options.gnss_antenna_xpd_db,
        );
        let spreading = if c.direct_dist_m.is_finite() {
            c.direct_dist_m / (c.direct_dist_m + excess_m)
        } else {
            1.0
        };
        let amplitude = gamma.norm() * spreading * 10f64.powf(-veg_db / 20.0);
        if 20.0 * amplitude.max(1e-300).log10() < self.options.min_relative_amplitude_db {
            return;
        }
        let phase =
            reflect::wrap_phase(gamma.arg() - std::f64::consts::TAU * excess_m / c.lambda_m);
        out.push(Path {
            kind: match building {
                Some(b) => PathKind::Wall { building: b },
                None => PathKind::Ground,
            },
            excess_delay_s: excess_m.max(0.0) / C_MPS,
            amplitude,
            phase_rad: phase,
            doppler_hz: c.params.rx_vel_enu_mps.dot(&arrival) / c.lambda_m,
            arrival_enu: arrival,
        });
    }
}

struct Ctx<'a> {
    rx: Vector3<f64>,
    tx: Emitter,
    params: &'a LinkParams,
    lambda_m: f64,
    direct_dist_m: f64,
    tx_building: Option<u32>,
}
