//! Single-point positioning of real receiver data: the pseudoranges of a RINEX
//! observation file, one weighted least-squares fix per epoch, with the broadcast orbits
//! and clocks of a navigation file.
//!
//! Per satellite s with code pseudorange P (GPS `C1`/`C1C` on L1 C/A; BeiDou `C2I`, or
//! `C1I` as RINEX 3.02 names B1I) at the epoch's time tag t_r (receiver time):
//!
//! ```text
//! t_t   = t_r − P/c − Δt_sv(t_t)          transmit time in system time (P/c is exact in
//!                                          receiver time, so δt_r does not enter)
//! r_s   = R_z(−Ω̇e τ) · r_s(t_t),  τ = ‖r_s − r_r‖ / c      Earth rotation in flight
//! ρ     = P + c (Δt_sv − TGD) − I_Klobuchar − T_Saastamoinen
//!       = ‖r_s − r_r‖ + c δt_r,sys + ε
//! ```
//!
//! Δt_sv includes the relativistic term ([`crate::gnss::ephemeris::SatState::clock_s`]);
//! TGD is the L1 C/A group delay for GPS and TGD1 (B1I) for BeiDou. I is the GPS
//! broadcast Klobuchar model on L1, scaled by (f_L1/f_B1I)² for B1I, and T the Saastamoinen
//! model, both evaluated as the simulator's receiver evaluates them
//! ([`crate::gnss::measurement`]). The unknowns are the position and one clock per
//! system ([`crate::fusion::wls::solve`]). Satellites below the elevation mask (10°, the
//! simulator's default) are left out. Each σ is the simulator's own error model with its
//! default budget: σ² = σ_DLL² + σ_URE² + ((σ_iono² + σ_iono,sat²)^½ I)² + (σ_trop T)²,
//! σ_DLL from the C/N0 of the `S` observable when the file has one, else from the
//! simulator's link budget at the satellite's elevation.
//!
//! The geometry (τ, elevation, atmosphere) needs the receiver position, so each epoch is
//! solved in passes: from the previous epoch's fix, or for the first epoch from a first
//! solution without atmosphere or mask; the passes stop when the position moves by less
//! than 1 mm, after at most four. The header's `APPROX POSITION XYZ` is never used, so
//! that it can serve as the independent truth of a static station.

use crate::core::geodesy::{azimuth_elevation_with, ecef_to_enu_rotation};
use crate::core::{Geodetic, GpsTime, System, C_MPS};
use crate::fusion::wls::{solve, WlsOptions};
use crate::gnss::atmosphere::saastamoinen_m;
use crate::gnss::ephemeris::sagnac_rotate;
use crate::gnss::measurement::{GnssConfig, F_B1I_HZ, F_L1_HZ};
use crate::gnss::rinex_nav::NavData;
use crate::gnss::rinex_obs::{ObsEpoch, ObsHeader};
use crate::measurement::RangeMeasurement;
use nalgebra::Vector3;

/// Smallest and largest code pseudorange (m) taken as one: GNSS orbits lie 19 100 km
/// (GLONASS) to 35 800 km (GEO) above the surface, i.e. ranges of about 1.9·10⁷–4.2·10⁷
/// m, and a receiver clock adds at most ±1 ms (3·10⁵ m); outside 10⁷–6·10⁷ the value is
/// a placeholder (some writers put 0 for "not tracked"), not a measurement.
const PSEUDORANGE_RANGE_M: (f64, f64) = (1.0e7, 6.0e7);

/// Position change (m) below which the geometry passes of an epoch stop.
const PASS_TOLERANCE_M: f64 = 1e-3;

/// Most geometry passes per epoch.
const MAX_PASSES: usize = 4;

/// Where an epoch's records hold the observables the solution uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Observables {
    /// GPS L1 C/A code (`C1` in RINEX 2, `C1C` in RINEX 3).
    pub gps_code: Option<usize>,
    /// GPS L1 C/A C/N0 (`S1`, `S1C`).
    pub gps_snr: Option<usize>,
    /// BeiDou B1I code (`C2I`; `C1I` in RINEX 3.02).
    pub bds_code: Option<usize>,
    /// BeiDou B1I C/N0 (`S2I`, `S1I`).
    pub bds_snr: Option<usize>,
}

impl Observables {
    /// The observables of a file's header.
    pub fn of(header: &ObsHeader) -> Self {
        let first = |sys: char, codes: &[&str]| codes.iter().find_map(|c| header.index_of(sys, c));
        if header.is_v2() {
            Self {
                gps_code: first('G', &["C1"]),
                gps_snr: first('G', &["S1"]),
                bds_code: None,
                bds_snr: None,
            }
        } else {
            Self {
                gps_code: first('G', &["C1C"]),
                gps_snr: first('G', &["S1C"]),
                bds_code: first('C', &["C2I", "C1I"]),
                bds_snr: first('C', &["S2I", "S1I"]),
            }
        }
    }

    fn code_and_snr(&self, system: System) -> (Option<usize>, Option<usize>) {
        match system {
            System::Gps => (self.gps_code, self.gps_snr),
            System::Bds => (self.bds_code, self.bds_snr),
            _ => (None, None),
        }
    }
}

/// One epoch's fix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SppFix {
    /// The epoch's time tag (receiver time, GPST).
    pub t_gpst: GpsTime,
    /// Receiver position (ECEF, m).
    pub pos_ecef_m: Vector3<f64>,
    /// The same position as latitude, longitude, ellipsoidal height.
    pub geodetic: Geodetic,
    /// Satellites used.
    pub n_sats: usize,
    /// Position dilution of precision.
    pub pdop: f64,
    /// Receiver clock offset against GPST (m), when GPS satellites were used.
    pub clock_gps_m: Option<f64>,
    /// Receiver clock offset against BDT-as-GPST (m), when BeiDou satellites were used.
    pub clock_bds_m: Option<f64>,
    /// RMS of the post-fit residuals (m).
    pub residual_rms_m: f64,
}

/// A satellite's transmit-time state, before the geometry of a pass.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    emitter: crate::core::EmitterId,
    /// Position at transmit time, in the ECEF frame of that instant (m).
    pos_tx_ecef_m: Vector3<f64>,
    /// Satellite clock minus group delay (s).
    clock_s: f64,
    pseudorange_m: f64,
    cn0_dbhz: Option<f64>,
}

/// The per-epoch solver; keeps the previous fix as the next epoch's starting point and
/// its buffers from epoch to epoch.
pub struct Spp<'a> {
    nav: &'a NavData,
    obs: Observables,
    cfg: GnssConfig,
    candidates: Vec<Candidate>,
    ranges: Vec<RangeMeasurement>,
    last_fix: Option<Vector3<f64>>,
}

impl<'a> Spp<'a> {
    /// A solver for the epochs of a file with `header`, on `nav`.
    ///
    /// # Errors
    /// The header declares neither GPS L1 C/A nor BeiDou B1I code observations.
    pub fn new(nav: &'a NavData, header: &ObsHeader) -> Result<Self, String> {
        let obs = Observables::of(header);
        if obs.gps_code.is_none() && obs.bds_code.is_none() {
            return Err(
                "the observation file has no GPS L1 C/A code (C1, C1C) or BeiDou B1I code \
                 (C2I, C1I) observable: nothing to position with"
                    .into(),
            );
        }
        Ok(Self {
            nav,
            obs,
            cfg: GnssConfig::default(),
            candidates: Vec::new(),
            ranges: Vec::new(),
            last_fix: None,
        })
    }

    /// The fix of one epoch.
    ///
    /// # Errors
    /// Why there is none: an epoch flag other than 0 or 1, too few satellites with a
    /// usable ephemeris above the mask, or the least-squares failure.
    pub fn solve(&mut self, epoch: &ObsEpoch) -> Result<SppFix, String> {
        if epoch.flag > 1 {
            return Err(format!("epoch flag {} (not observations)", epoch.flag));
        }
        let t_r = epoch.t;
        self.candidates.clear();
        for (sat, values) in epoch.iter() {
            let Some(emitter) = sat.emitter() else {
                continue;
            };
            let (code, snr) = self.obs.code_and_snr(emitter.system);
            let Some(p) = code.and_then(|k| values.get(k)).and_then(|v| v.value) else {
                continue;
            };
            if !(PSEUDORANGE_RANGE_M.0..=PSEUDORANGE_RANGE_M.1).contains(&p) {
                continue;
            }
            let Some(eph) = self.nav.select(emitter, t_r) else {
                continue;
            };
            // The transmit time in satellite time is t_r − P/c exactly; the satellite
            // clock then moves it to system time (two evaluations: Δt_sv changes by
            // < 1e-12 s over its own size).
            let t_sv = t_r.add_seconds(-p / C_MPS);
            let dt = eph.state(t_sv).clock_s;
            let st = eph.state(t_sv.add_seconds(-dt));
            self.candidates.push(Candidate {
                emitter,
                pos_tx_ecef_m: st.pos_ecef_m,
                clock_s: st.clock_s - eph.tgd_s,
                pseudorange_m: p,
                cn0_dbhz: snr
                    .and_then(|k| values.get(k))
                    .and_then(|v| v.value)
                    .filter(|c| *c > 0.0),
            });
        }
        let mut rx = match self.last_fix {
            Some(p) => p,
            None => self.pass(t_r, None)?.pos_ecef_m,
        };
        let mut fix = None;
        for _ in 0..MAX_PASSES {
            let f = self.pass(t_r, Some(rx))?;
            let moved = (f.pos_ecef_m - rx).norm();
            rx = f.pos_ecef_m;
            fix = Some(f);
            if moved < PASS_TOLERANCE_M {
                break;
            }
        }
        let fix = fix.ok_or("no pass ran")?;
        self.last_fix = Some(fix.pos_ecef_m);
        Ok(fix)
    }

    /// One least-squares solution with the geometry seen from `rx` (or, without it, with
    /// the nominal 75 ms flight time, no atmosphere, no mask and unit σ).
    fn pass(&mut self, t_r: GpsTime, rx: Option<Vector3<f64>>) -> Result<SppFix, String> {
        self.ranges.clear();
        let geo = rx.map(|p| Geodetic::from_ecef(&p));
        let rot = geo.map(|g| ecef_to_enu_rotation(g.lat_rad, g.lon_rad));
        let mask = self.cfg.elevation_mask_deg.to_radians();
        let e = &self.cfg.errors;
        for c in &self.candidates {
            let (pos, el, iono_m, tropo_m) = match (rx, geo, rot) {
                (Some(rx), Some(g), Some(rot)) => {
                    // τ from the geometric range, iterated as transmit_geometry does.
                    let mut pos = sagnac_rotate(&c.pos_tx_ecef_m, 0.075);
                    for _ in 0..3 {
                        pos = sagnac_rotate(&c.pos_tx_ecef_m, (pos - rx).norm() / C_MPS);
                    }
                    let (az, el) = azimuth_elevation_with(&rot, &rx, &pos);
                    if el < mask {
                        continue;
                    }
                    let scale = if c.emitter.system == System::Bds {
                        (F_L1_HZ / F_B1I_HZ).powi(2)
                    } else {
                        1.0
                    };
                    let iono = self.nav.klobuchar.map_or(0.0, |k| {
                        k.delay_l1_m(g.lat_rad, g.lon_rad, az, el, t_r) * scale
                    });
                    let tropo = saastamoinen_m(g.lat_rad, g.h_m, el, e.humidity);
                    (pos, el, iono, tropo)
                }
                _ => (sagnac_rotate(&c.pos_tx_ecef_m, 0.075), f64::NAN, 0.0, 0.0),
            };
            let sigma_m = if el.is_nan() {
                1.0
            } else {
                let sys = c.emitter.system;
                let cn0 = c
                    .cn0_dbhz
                    .unwrap_or_else(|| self.cfg.tracking.cn0_dbhz(sys, el));
                let ure = if sys == System::Bds {
                    e.ure_bds_m
                } else {
                    e.ure_gps_m
                };
                (self.cfg.tracking.code_sigma_m(sys, cn0).powi(2)
                    + ure.powi(2)
                    + (e.iono_residual.hypot(e.iono_residual_per_sat) * iono_m).powi(2)
                    + (e.tropo_residual * tropo_m).powi(2))
                .sqrt()
            };
            self.ranges.push(RangeMeasurement {
                emitter: c.emitter,
                emitter_pos_ecef_m: pos,
                emitter_vel_ecef_mps: Vector3::zeros(),
                pseudorange_m: c.pseudorange_m + C_MPS * c.clock_s - iono_m - tropo_m,
                sigma_m,
                range_rate_mps: None,
                sigma_rate_mps: 1.0,
                cn0_dbhz: c.cn0_dbhz.unwrap_or(f64::NAN),
                elevation_rad: el,
            });
        }
        let opts = WlsOptions {
            initial_pos_ecef_m: rx,
            ..WlsOptions::default()
        };
        let fix = solve(&self.ranges, &opts).map_err(|e| e.to_string())?;
        Ok(SppFix {
            t_gpst: t_r,
            pos_ecef_m: fix.pos_ecef_m,
            geodetic: Geodetic::from_ecef(&fix.pos_ecef_m),
            n_sats: fix.n_measurements,
            pdop: fix.dop.pdop,
            clock_gps_m: fix.clock_m(System::Gps),
            clock_bds_m: fix.clock_m(System::Bds),
            residual_rms_m: fix.residual_rms_m,
        })
    }
}
