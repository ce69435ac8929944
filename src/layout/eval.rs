//! The grid evaluation: the world's receivers and transmitters set up once
//! ([`Context`]), then every cell evaluated in parallel by rows into preallocated
//! outputs, each worker with its own [`Scratch`] buffers (nothing is allocated per cell).
//! Each cell depends only on its own position, so the output is the same whatever the
//! number of threads.

use super::grid::Grid;
use super::metrics::{
    sat_row, site_link, CellMetrics, ClockModel, Coverage, GnssModel, Normals, Row, SatDir,
    Scratch, Site, TerrestrialRx,
};
use crate::core::geodesy::ecef_to_enu_rotation;
use crate::core::{Geodetic, GpsTime, System};
use crate::dtmb::ldpc::CodeRate;
use crate::dtmb::mapping::Constellation;
use crate::dtmb::service::{awgn_threshold_db, DEFAULT_PROFILE};
use crate::dtmb::source::DtmbSensorConfig;
use crate::gnss::measurement::satellite_in_view;
use crate::gnss::visibility::LinkClass;
use crate::propagation::Scene;
use crate::world::scene::TransmitterKind;
use crate::world::World;
use nalgebra::Vector3;
use rayon::prelude::*;

/// The satellites of one epoch.
#[derive(Clone, Debug)]
pub struct Epoch {
    pub t: GpsTime,
    pub sats: Vec<SatDir>,
}

/// Everything the grid loop reads, built once from the world.
pub struct Context<'a> {
    pub world: &'a World,
    pub scene: Option<&'a Scene>,
    pub gnss: Option<GnssModel>,
    pub epochs: Vec<Epoch>,
    /// The world's DTMB and TC-OFDM transmitters.
    pub sites: Vec<Site>,
    pub clocks: ClockModel,
    pub rx_height_m: f64,
    dtmb_rx: TerrestrialRx,
    tcofdm_rx: TerrestrialRx,
    tcofdm_nav_power_db: f64,
}

impl<'a> Context<'a> {
    /// Sets up the receivers of `world` at the epochs `times`, the satellites' directions
    /// taken from `centre_enu_m` (east, north) at `rx_height_m`.
    pub fn new(
        world: &'a World,
        times: &[GpsTime],
        clocks: ClockModel,
        rx_height_m: f64,
        centre_enu_m: (f64, f64),
    ) -> Self {
        let sensors = &world.file.sensors;
        let dtmb_cfg = sensors.dtmb.clone().unwrap_or_default();
        let tc_cfg = sensors.tcofdm.clone().unwrap_or_default();
        let tc_as_dtmb = DtmbSensorConfig {
            noise_figure_db: tc_cfg.noise_figure_db,
            antenna_gain_dbi: tc_cfg.antenna_gain_dbi,
            accumulation_frames: tc_cfg.accumulation_frames,
            environment: tc_cfg.environment,
            rx_antenna_height_m: tc_cfg.rx_antenna_height_m,
            sigma_floor_m: tc_cfg.sigma_floor_m,
            ..DtmbSensorConfig::default()
        };
        let gnss = sensors.gnss.as_ref().map(|g| GnssModel {
            tracking: g.tracking.clone(),
            ure_gps_m: g.errors.ure_gps_m,
            ure_bds_m: g.errors.ure_bds_m,
            scene: g.scene,
        });
        let centre = Vector3::new(centre_enu_m.0, centre_enu_m.1, rx_height_m);
        let rx_ecef = world.frame.ecef_of_enu(&centre);
        let geo = Geodetic::from_ecef(&rx_ecef);
        let rot = ecef_to_enu_rotation(geo.lat_rad, geo.lon_rad);
        let epochs = times
            .iter()
            .map(|&t| {
                let mut sats = Vec::new();
                if let Some(g) = &sensors.gnss {
                    let mask = g.elevation_mask_deg.to_radians();
                    for sat in world.nav.satellites() {
                        if !g.systems.contains(&sat.system) {
                            continue;
                        }
                        let Some((pos, _, _, el)) =
                            satellite_in_view(&world.nav, sat, t, &rx_ecef, &rot, mask)
                        else {
                            continue;
                        };
                        let u_enu = world.frame.enu_vector_of_ecef(&(pos - rx_ecef)).normalize();
                        sats.push(SatDir {
                            system: sat.system,
                            u_enu,
                            elevation_rad: el,
                            open_cn0_dbhz: g.tracking.cn0_dbhz(sat.system, el),
                        });
                    }
                }
                Epoch { t, sats }
            })
            .collect();
        // The receiver of a layout study stands at `--height`: the Hata mobile-height term
        // follows it (at least 1 m, the model's lower bound) rather than the sensors'.
        let mut dtmb_rx = TerrestrialRx::of(&dtmb_cfg);
        let mut tcofdm_rx = TerrestrialRx::of(&tc_as_dtmb);
        dtmb_rx.rx_antenna_height_m = rx_height_m.max(1.0);
        tcofdm_rx.rx_antenna_height_m = rx_height_m.max(1.0);
        let mut ctx = Self {
            world,
            scene: world.scene.as_deref(),
            gnss,
            epochs,
            sites: Vec::new(),
            clocks,
            rx_height_m,
            dtmb_rx,
            tcofdm_rx,
            tcofdm_nav_power_db: tc_cfg.nav_power_db,
        };
        ctx.sites = world
            .transmitters
            .iter()
            .filter_map(|t| {
                let system = match t.kind {
                    TransmitterKind::Dtmb => System::Dtmb,
                    TransmitterKind::Tcofdm => System::Tcofdm,
                    TransmitterKind::Fm => return None,
                };
                // The world's loader has checked the data-layer keys; a tower without
                // them stands for `dtmb iq`'s default profile.
                let constellation = t.spec.qam.as_deref().and_then(|q| q.parse().ok());
                let rate = t.spec.fec.as_deref().and_then(|f| f.parse().ok());
                Some(ctx.site(
                    &t.id,
                    system,
                    t.pos_enu_m,
                    t.freq_hz,
                    t.erp_dbw,
                    t.pn_mode(),
                    (
                        constellation.unwrap_or(DEFAULT_PROFILE.0),
                        rate.unwrap_or(DEFAULT_PROFILE.1),
                    ),
                ))
            })
            .collect();
        ctx
    }

    /// A terrestrial site with the world's receiver parameters for its system; `erp_dbw`
    /// is the station's ERP (the TC-OFDM navigation component is set below it here), and
    /// a DTMB tower's `profile` sets its service threshold.
    #[allow(clippy::too_many_arguments)]
    pub fn site(
        &self,
        id: &str,
        system: System,
        pos_enu_m: Vector3<f64>,
        freq_hz: f64,
        erp_dbw: f64,
        pn_mode: crate::dtmb::PnMode,
        profile: (Constellation, CodeRate),
    ) -> Site {
        let (rx, ranging_erp_dbw) = if system == System::Tcofdm {
            (self.tcofdm_rx, erp_dbw + self.tcofdm_nav_power_db)
        } else {
            (self.dtmb_rx, erp_dbw)
        };
        Site {
            id: id.to_string(),
            system,
            pos_enu_m,
            freq_hz,
            ranging_erp_dbw,
            pn_mode,
            rx,
            service_threshold_db: if system == System::Tcofdm {
                f64::NAN
            } else {
                awgn_threshold_db(profile.0, profile.1).unwrap_or(f64::NAN)
            },
        }
    }

    /// Evaluates one cell at ENU `rx`; when `base` is given (one slot per epoch) it
    /// receives the hybrid normal matrices, the starting point of the placement search.
    pub fn eval_cell(
        &self,
        rx: &Vector3<f64>,
        scratch: &mut Scratch,
        mut base: Option<&mut [Normals]>,
    ) -> CellMetrics {
        let mut m = CellMetrics::default();
        if let Some(scene) = self.scene {
            m.indoor = !matches!(scene.check_receiver(rx), Ok(None));
        }
        let mut terrestrial = Normals::default();
        for site in &self.sites {
            let link = site_link(site, rx, self.scene, self.clocks, scratch);
            m.best_terr_snr_db = m.best_terr_snr_db.max(link.snr_db);
            if site.service_threshold_db.is_finite() {
                m.dtmb_service_margin_db = m
                    .dtmb_service_margin_db
                    .max(link.service_snr_db - site.service_threshold_db);
            }
            if !link.usable {
                continue;
            }
            terrestrial.add(&link.row);
            match site.system {
                System::Tcofdm => m.n_tcofdm += 1,
                _ => m.n_dtmb += 1,
            }
            match link.class {
                LinkClass::Los => m.n_terr_los += 1,
                LinkClass::Foliage => m.n_terr_foliage += 1,
                _ => m.n_terr_nlos += 1,
            }
            m.coverage = m.coverage.max(Coverage::of(link.class));
        }
        let (mut n_gps, mut n_bds) = (u16::MAX, u16::MAX);
        let (mut gdop_g, mut sig_g, mut gdop_h, mut sig_h) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (e, epoch) in self.epochs.iter().enumerate() {
            let mut gnss = Normals::default();
            let (mut ng, mut nb) = (0u16, 0u16);
            if let Some(model) = &self.gnss {
                for sat in &epoch.sats {
                    let (class, row) = sat_row(sat, model, rx, self.scene, self.clocks, scratch);
                    if class == LinkClass::Lost {
                        continue;
                    }
                    gnss.add(&row);
                    if sat.system == System::Bds {
                        nb += 1;
                    } else {
                        ng += 1;
                    }
                }
            }
            n_gps = n_gps.min(ng);
            n_bds = n_bds.min(nb);
            let (g, s) = gnss.solve();
            gdop_g = gdop_g.max(g);
            sig_g = sig_g.max(s);
            let hybrid = merged(&gnss, &terrestrial);
            let (g, s) = hybrid.solve();
            gdop_h = gdop_h.max(g);
            sig_h = sig_h.max(s);
            if let Some(b) = base.as_deref_mut() {
                b[e] = hybrid;
            }
        }
        if !self.epochs.is_empty() {
            m.n_gps = n_gps;
            m.n_bds = n_bds;
            m.gdop_gnss = gdop_g;
            m.sigma_gnss_m = sig_g;
            m.gdop_hybrid = gdop_h;
            m.sigma_hybrid_m = sig_h;
        }
        m
    }

    /// The receiver position of cell `(i, j)`.
    pub fn cell_rx(&self, grid: &Grid, i: usize, j: usize) -> Vector3<f64> {
        let (e, n) = grid.centre(i, j);
        Vector3::new(e, n, self.rx_height_m)
    }

    /// Evaluates every cell, row-major from the south-west; with `want_base` also the
    /// hybrid normal matrices (`cells × epochs`, cell-major) for the placement search.
    pub fn evaluate(&self, grid: &Grid, want_base: bool) -> (Vec<CellMetrics>, Vec<Normals>) {
        let nx = grid.nx;
        let ne = self.epochs.len().max(1);
        let mut metrics = vec![CellMetrics::default(); grid.cells()];
        let mut base = if want_base {
            vec![Normals::default(); grid.cells() * ne]
        } else {
            Vec::new()
        };
        if want_base {
            metrics
                .par_chunks_mut(nx)
                .zip(base.par_chunks_mut(nx * ne))
                .enumerate()
                .for_each_init(Scratch::default, |scratch, (j, (row, brow))| {
                    for (i, (cell, b)) in row.iter_mut().zip(brow.chunks_mut(ne)).enumerate() {
                        let rx = self.cell_rx(grid, i, j);
                        *cell = self.eval_cell(&rx, scratch, Some(b));
                    }
                });
        } else {
            metrics.par_chunks_mut(nx).enumerate().for_each_init(
                Scratch::default,
                |scratch, (j, row)| {
                    for (i, cell) in row.iter_mut().enumerate() {
                        let rx = self.cell_rx(grid, i, j);
                        *cell = self.eval_cell(&rx, scratch, None);
                    }
                },
            );
        }
        (metrics, base)
    }

    /// The geometry row of every site at every cell (`sites × cells`, site-major); an
    /// unusable link has weight 0.
    pub fn site_rows(&self, grid: &Grid, sites: &[Site]) -> Vec<Row> {
        let cells = grid.cells();
        let mut rows = vec![Row::default(); sites.len() * cells];
        if cells == 0 {
            return rows;
        }
        rows.par_chunks_mut(cells)
            .zip(sites.par_iter())
            .for_each_init(Scratch::default, |scratch, (out, site)| {
                for (k, r) in out.iter_mut().enumerate() {
                    let rx = self.cell_rx(grid, k % grid.nx, k / grid.nx);
                    *r = site_link(site, &rx, self.scene, self.clocks, scratch).row;
                }
            });
        rows
    }
}

/// The sum of two sets of normal matrices.
pub fn merged(a: &Normals, b: &Normals) -> Normals {
    Normals {
        geometry: a.geometry + b.geometry,
        weighted: a.weighted + b.weighted,
    }
}
