//! Almanacs for the GPS LNAV (subframes 4 and 5) and BeiDou D1 (subframes 4 and 5)
//! messages, derived from the world's broadcast ephemerides: hybridnav has no almanac of
//! its own, so each satellite's almanac is its broadcast ephemeris carried to the almanac
//! reference time `toa` and stripped of what an almanac cannot say.
//!
//! # Reference time
//!
//! `toa` is a multiple of 2¹² s of the system's week (both ICDs send it as 8 bits × 2¹² s:
//! IS-GPS-200 Table 20-VI, BDS-SIS-ICD-B1I-3.0 Table 5-12): the multiple nearest the
//! transmission time, kept inside the week (at most 147·2¹² s = 602 112 s). An almanac is
//! then never more than 2048 s from its reference when sent, far inside the 3.5 days
//! IS-GPS-200 §20.3.3.5.2.2 allows between transmission and toa. WNa is the week of `toa`
//! (GPS weeks for GPS, BDT weeks for BeiDou), sent mod 256.
//!
//! # Elements (MEO, IGSO and GPS satellites)
//!
//! With `Δ = toa − toe` and the ephemeris's mean motion `n = √(μ/A³) + Δn`:
//!
//! ```text
//! √A, e, ω          unchanged
//! M0_a  = M0 + n·Δ                          mean anomaly at toa
//! δi    = i0 + IDOT·Δ − i_ref                i_ref = 0.30 semicircles (GPS; BDS MEO/IGSO)
//! Ω̇_a   = Ω̇
//! Ω0_a  = Ω0 + Ω̇·Δ + Ω̇e·((toa_sow − toe_sow) − Δ)
//! af0_a = af0 + af1·(toa − toc) + af2·(toa − toc)²,   af1_a = af1 + 2·af2·(toa − toc)
//! ```
//!
//! `Ω0_a` keeps the node the ephemeris gives at every time (both messages evaluate
//! `Ω = Ω0 + (Ω̇ − Ω̇e)·t_k − Ω̇e·t_ref` with their own reference); the last term is zero
//! when toa and toe fall in the same week. What the almanac drops — Δn (its mean motion is
//! `√(μ/A³)`), the six harmonic corrections, af2 — and the coarser scale factors make its
//! orbit a few km off the ephemeris's within hours of toa (measured against SP3 in
//! tests/it/gnss_nav.rs).
//!
//! # Elements (BeiDou GEO)
//!
//! A GEO's ephemeris elements describe its orbit in a frame tilted by 5° about X (ICD
//! §5.2.4.12), while its almanac uses the plain model with i_ref = 0 (ICD Table 5-12), so
//! the elements are not carried over: they are the osculating Keplerian elements of the
//! ephemeris's position and velocity at toa in the inertial frame aligned with the Earth
//! at toa (`v_i = v_ECEF + ω_e × r`), with `Ω0_a = Ω + Ω̇e·toa_sow` (so that the almanac's
//! node at toa is Ω) and the ephemeris's Ω̇.
//!
//! A satellite without a usable ephemeris within the system's age limit of `toa` (or of
//! the transmission time) has no almanac; an ephemeris that flags the satellite unhealthy
//! gives an almanac marked unhealthy.

use crate::core::{EmitterId, GpsTime, System};
use crate::gnss::ephemeris::{
    Ephemeris, BDS_MU_M3_PER_S2, BDS_OMEGA_E_RAD_PER_S, GPS_MU_M3_PER_S2, GPS_OMEGA_E_RAD_PER_S,
};
use crate::gnss::rinex_nav::NavData;
use nalgebra::Vector3;
use std::f64::consts::{PI, TAU};

/// The almanac's reference-time step (2¹² s).
pub const TOA_STEP_S: f64 = 4096.0;
/// The reference inclination of GPS and BeiDou MEO/IGSO almanacs: 0.30 semicircles.
pub const I_REF_RAD: f64 = 0.30 * PI;

/// One satellite's almanac (angles in rad, rates in rad/s, clock in s and s/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Almanac {
    pub sat: EmitterId,
    /// toa as seconds of its week (GPS or BDT week).
    pub toa_sow_s: f64,
    /// The week of toa (GPS or BDT, full).
    pub week: i64,
    pub sqrt_a: f64,
    pub e: f64,
    /// Inclination minus the reference (0.30 semicircles; 0 for a BeiDou GEO).
    pub delta_i: f64,
    pub omega0: f64,
    pub omega_dot: f64,
    pub omega: f64,
    pub m0: f64,
    pub af0: f64,
    pub af1: f64,
    /// The ephemeris it comes from flags the satellite healthy.
    pub healthy: bool,
    /// That ephemeris's broadcast health word as read from the navigation file (GPS: the
    /// 6-bit SV health of subframe 1, IS-GPS-200 §20.3.3.3.1.4; BeiDou: SatH1), from which
    /// the almanac health words are derived (lnav.rs, d1d2.rs).
    pub health_word: u32,
}

/// The almanac reference time for a message sent at `t` by `system`: (week, second of week)
/// in the system's own time (module documentation).
pub fn toa_for(system: System, t: GpsTime) -> (i64, f64) {
    let (week, sow) = match system {
        System::Bds => t.bdt_week_sow(),
        _ => (t.week(), t.tow_s()),
    };
    let k = ((sow / TOA_STEP_S).round()).min(147.0);
    (week, k * TOA_STEP_S)
}

fn wrap_pi(x: f64) -> f64 {
    (x + PI).rem_euclid(TAU) - PI
}

impl Almanac {
    /// The almanac of `e` at `toa` (`week`, `toa_sow_s` in `e`'s system).
    pub fn from_ephemeris(e: &Ephemeris, week: i64, toa_sow_s: f64) -> Self {
        let bds = e.sat.system == System::Bds;
        let (mu, omega_e) = if bds {
            (BDS_MU_M3_PER_S2, BDS_OMEGA_E_RAD_PER_S)
        } else {
            (GPS_MU_M3_PER_S2, GPS_OMEGA_E_RAD_PER_S)
        };
        let toa = if bds {
            GpsTime::from_bdt_week_sow(week, toa_sow_s)
        } else {
            GpsTime::from_week_tow(week, toa_sow_s)
        };
        let dtc = toa.seconds_since(e.toc);
        let af0 = e.af0 + e.af1 * dtc + e.af2 * dtc * dtc;
        let af1 = e.af1 + 2.0 * e.af2 * dtc;
        let base = Self {
            sat: e.sat,
            toa_sow_s,
            week,
            sqrt_a: e.sqrt_a,
            e: e.e,
            delta_i: 0.0,
            omega0: 0.0,
            omega_dot: e.omega_dot,
            omega: e.omega,
            m0: 0.0,
            af0,
            af1,
            healthy: e.is_healthy(),
            health_word: e.health,
        };
        if e.sat.is_bds_geo() {
            return Self::osculating(base, e, toa, mu, omega_e);
        }
        let d = toa.seconds_since(e.toe);
        let a = e.semi_major_axis_m();
        let n = (mu / (a * a * a)).sqrt() + e.delta_n;
        Self {
            m0: wrap_pi(e.m0 + n * d),
            delta_i: e.i0 + e.idot * d - I_REF_RAD,
            omega0: wrap_pi(
                e.omega0 + e.omega_dot * d + omega_e * ((toa_sow_s - e.toe_sow_s()) - d),
            ),
            ..base
        }
    }

    /// The GEO case: osculating elements of the ephemeris's state at `toa`.
    fn osculating(base: Self, e: &Ephemeris, toa: GpsTime, mu: f64, omega_e: f64) -> Self {
        let st = e.state(toa);
        let r = st.pos_ecef_m;
        let v = st.vel_ecef_mps + Vector3::new(0.0, 0.0, omega_e).cross(&r);
        let h = r.cross(&v);
        let node = Vector3::new(-h.y, h.x, 0.0);
        let rn = r.norm();
        let e_vec = ((v.norm_squared() - mu / rn) * r - r.dot(&v) * v) / mu;
        let ecc = e_vec.norm();
        let a = 1.0 / (2.0 / rn - v.norm_squared() / mu);
        let inc = (h.z / h.norm()).clamp(-1.0, 1.0).acos();
        let raan = node.y.atan2(node.x);
        let angle = |p: &Vector3<f64>, q: &Vector3<f64>| -> f64 {
            // The angle from p to q measured in the orbit's direction of motion.
            let c = p.dot(q) / (p.norm() * q.norm());
            let s = p.cross(q).dot(&h) / (p.norm() * q.norm() * h.norm());
            s.atan2(c)
        };
        let omega = angle(&node, &e_vec);
        let nu = angle(&e_vec, &r);
        let ea = 2.0 * (((1.0 - ecc) / (1.0 + ecc)).sqrt() * (nu / 2.0).tan()).atan();
        let m = ea - ecc * ea.sin();
        Self {
            sqrt_a: a.sqrt(),
            e: ecc,
            delta_i: inc,
            omega0: wrap_pi(raan + omega_e * base.toa_sow_s),
            omega: wrap_pi(omega),
            m0: wrap_pi(m),
            ..base
        }
    }
}

/// The almanacs of `system`'s satellites 1..=`count` for a message sent at `t`, into `out`
/// (index PRN − 1; `None` for a satellite without a usable ephemeris). `out` keeps its
/// capacity, so a stream that refills it every 4096 s allocates once.
pub fn fill_constellation(
    nav: &NavData,
    system: System,
    count: u16,
    t: GpsTime,
    out: &mut Vec<Option<Almanac>>,
) {
    let (week, toa_sow) = toa_for(system, t);
    let toa = match system {
        System::Bds => GpsTime::from_bdt_week_sow(week, toa_sow),
        _ => GpsTime::from_week_tow(week, toa_sow),
    };
    out.clear();
    out.extend((1..=count).map(|prn| {
        let sat = EmitterId::new(system, prn);
        nav.select(sat, toa)
            .or_else(|| nav.select(sat, t))
            .map(|e| Almanac::from_ephemeris(e, week, toa_sow))
    }));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::ephemeris::tests::{c05_2020, g02_2010};

    /// The almanac's own Keplerian orbit (IS-GPS-200 Table 20-IV without corrections).
    fn alm_pos(a: &Almanac, t_minus_toa: f64, i_ref: f64, mu: f64, we: f64) -> Vector3<f64> {
        let aa = a.sqrt_a * a.sqrt_a;
        let m = a.m0 + (mu / (aa * aa * aa)).sqrt() * t_minus_toa;
        let ea = crate::gnss::ephemeris::solve_kepler(m, a.e);
        let nu = ((1.0 - a.e * a.e).sqrt() * ea.sin()).atan2(ea.cos() - a.e);
        let u = nu + a.omega;
        let r = aa * (1.0 - a.e * ea.cos());
        let om = a.omega0 + (a.omega_dot - we) * t_minus_toa - we * a.toa_sow_s;
        let i = i_ref + a.delta_i;
        let (x, y) = (r * u.cos(), r * u.sin());
        Vector3::new(
            x * om.cos() - y * i.cos() * om.sin(),
            x * om.sin() + y * i.cos() * om.cos(),
            y * i.sin(),
        )
    }

    #[test]
    fn toa_is_the_nearest_multiple_of_4096_s_inside_the_week() {
        let t = GpsTime::from_week_tow(2111, 352_818.0);
        assert_eq!(toa_for(System::Gps, t), (2111, 86.0 * 4096.0));
        let late = GpsTime::from_week_tow(2111, 604_000.0);
        assert_eq!(toa_for(System::Gps, late), (2111, 602_112.0));
        let (w, s) = toa_for(System::Bds, t);
        assert_eq!((w, s), (755, 86.0 * 4096.0));
    }

    /// The derived almanac follows the ephemeris's orbit: within a few km over ±2 h of toa
    /// (the harmonic corrections and Δn it drops), for a GPS MEO and a BeiDou GEO.
    #[test]
    fn almanac_orbit_stays_within_km_of_the_ephemeris() {
        let g = g02_2010();
        let (w, s) = toa_for(System::Gps, g.toe.add_seconds(1500.0));
        let a = Almanac::from_ephemeris(&g, w, s);
        let toa = GpsTime::from_week_tow(w, s);
        let mut worst: f64 = 0.0;
        for k in -4..=4 {
            let dt = 1800.0 * f64::from(k);
            let p = alm_pos(&a, dt, I_REF_RAD, GPS_MU_M3_PER_S2, GPS_OMEGA_E_RAD_PER_S);
            worst = worst.max((p - g.state(toa.add_seconds(dt)).pos_ecef_m).norm());
        }
        assert!(worst < 5_000.0, "GPS almanac off by {worst:.0} m");
        let c = c05_2020();
        let (w, s) = toa_for(System::Bds, c.toe.add_seconds(1000.0));
        let a = Almanac::from_ephemeris(&c, w, s);
        let toa = GpsTime::from_bdt_week_sow(w, s);
        let mut worst: f64 = 0.0;
        for k in -4..=4 {
            let dt = 900.0 * f64::from(k);
            let p = alm_pos(&a, dt, 0.0, BDS_MU_M3_PER_S2, BDS_OMEGA_E_RAD_PER_S);
            worst = worst.max((p - c.state(toa.add_seconds(dt)).pos_ecef_m).norm());
        }
        assert!(worst < 5_000.0, "GEO almanac off by {worst:.0} m");
    }
}
