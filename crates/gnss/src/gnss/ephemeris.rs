//! Broadcast ephemerides of GPS and BeiDou satellites and the satellite position, velocity
//! and clock they define.
//!
//! # Orbit (IS-GPS-200 §20.3.3.4.3, Table 20-IV; BDS-SIS-ICD-2.0 §5.2.4.12)
//!
//! With A = (√A)², the time from the ephemeris reference epoch tk = t − toe (corrected for
//! week crossover: ±604800 s when |tk| > 302400 s):
//!
//! ```text
//! n  = √(μ/A³) + Δn                       corrected mean motion
//! Mk = M0 + n tk                          mean anomaly
//! Mk = Ek − e sin Ek                      Kepler's equation, solved by Newton to 1e-13 rad
//! νk = atan2(√(1−e²) sin Ek, cos Ek − e)  true anomaly
//! Φk = νk + ω                             argument of latitude
//! δu = Cus sin 2Φk + Cuc cos 2Φk,  δr = Crs sin 2Φk + Crc cos 2Φk,  δi = Cis sin 2Φk + Cic cos 2Φk
//! uk = Φk + δu,  rk = A(1 − e cos Ek) + δr,  ik = i0 + IDOT tk + δi
//! x' = rk cos uk,  y' = rk sin uk                                   in the orbital plane
//! Ωk = Ω0 + (Ω̇ − Ω̇e) tk − Ω̇e toe                                  node longitude (ECEF)
//! x = x' cos Ωk − y' cos ik sin Ωk,  y = x' sin Ωk + y' cos ik cos Ωk,  z = y' sin ik
//! ```
//!
//! `toe` in the last node equation is the seconds-of-week value of the broadcast system:
//! GPS seconds of week for GPS, BDT seconds of week for BeiDou.
//!
//! BeiDou GEO satellites (PRN 1–5 and ≥ 59) use a different node and two extra rotations,
//! because their orbit planes are nearly equatorial and the node is ill-defined in the
//! usual element set (BDS-SIS-ICD-2.0 §5.2.4.12):
//!
//! ```text
//! Ωk = Ω0 + Ω̇ tk − Ω̇e toe               (inertial-like frame fixed at toe)
//! (xg, yg, zg) = as above with this Ωk
//! r  = Rz(Ω̇e tk) · Rx(−5°) · (xg, yg, zg)
//! Rx(φ) = [[1, 0, 0], [0, cos φ, sin φ], [0, −sin φ, cos φ]]
//! Rz(φ) = [[cos φ, sin φ, 0], [−sin φ, cos φ, 0], [0, 0, 1]]
//! ```
//!
//! Velocities are the exact time derivatives of these expressions:
//!
//! ```text
//! Ė = n / (1 − e cos E),  Φ̇ = ν̇ = √(1−e²) Ė / (1 − e cos E)
//! u̇ = Φ̇ (1 + 2 (Cus cos 2Φ − Cuc sin 2Φ))
//! ṙ = A e sin E · Ė + 2 Φ̇ (Crs cos 2Φ − Crc sin 2Φ)
//! i̇ = IDOT + 2 Φ̇ (Cis cos 2Φ − Cic sin 2Φ)
//! ẋ' = ṙ cos u − r u̇ sin u,  ẏ' = ṙ sin u + r u̇ cos u,  Ω̇k = Ω̇ − Ω̇e (GEO: Ω̇)
//! ẋ = ẋ' cos Ω − ẏ' cos i sin Ω + y' sin i sin Ω · i̇ − y Ω̇k
//! ẏ = ẋ' sin Ω + ẏ' cos i cos Ω − y' sin i cos Ω · i̇ + x Ω̇k
//! ż = ẏ' sin i + y' cos i · i̇
//! GEO: v = Rz Rx vg + Ṙz Rx rg,  Ṙz = Ω̇e [[−sin θ, cos θ, 0], [−cos θ, −sin θ, 0], [0, 0, 0]], θ = Ω̇e tk
//! ```
//!
//! # Clock (IS-GPS-200 §20.3.3.3.3.1; BDS-SIS-ICD-2.0 §5.2.4.10)
//!
//! ```text
//! Δt_sv = af0 + af1 (t − toc) + af2 (t − toc)² + Δtr,   Δtr = F e √A sin Ek,   F = −2√μ / c²
//! ```
//!
//! `SatState::clock_s` is Δt_sv *without* the group delay: a single-frequency GPS L1 C/A
//! user subtracts `tgd_s` (IS-GPS-200 §20.3.3.3.3.2), a BeiDou B1I user subtracts
//! `tgd_s` (TGD1, BDS-SIS-ICD-2.0 §5.2.4.9). Keeping the group delay out of the state lets
//! dual-frequency and ionosphere-free users share the same orbit/clock code.
//!
//! Positions are in the ECEF frame *at time t*. Light time and the Earth's rotation during
//! signal travel are the caller's business: see [`sagnac_rotate`].

use crate::core::{EmitterId, GpsTime, System};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::{PI, TAU};

/// GPS value of the Earth's gravitational constant μ (m³/s²), IS-GPS-200 Table 20-IV.
pub const GPS_MU_M3_PER_S2: f64 = 3.986005e14;
/// GPS value of the Earth's rotation rate Ω̇e (rad/s), IS-GPS-200 Table 20-IV.
pub const GPS_OMEGA_E_RAD_PER_S: f64 = 7.292_115_146_7e-5;
/// GPS relativistic clock constant F = −2√μ/c² (s/√m), IS-GPS-200 §20.3.3.3.3.1.
pub const GPS_F_S_PER_SQRT_M: f64 = -4.442_807_633e-10;
/// BeiDou (CGCS2000) μ (m³/s²), BDS-SIS-ICD-2.0 §5.2.4.12.
pub const BDS_MU_M3_PER_S2: f64 = 3.986_004_418e14;
/// BeiDou (CGCS2000) Ω̇e (rad/s), BDS-SIS-ICD-2.0 §5.2.4.12.
pub const BDS_OMEGA_E_RAD_PER_S: f64 = 7.292_115e-5;
/// BeiDou relativistic clock constant F = −2√μ/c² with the CGCS2000 μ (s/√m).
pub const BDS_F_S_PER_SQRT_M: f64 = -4.442_807_309_043_98e-10;
/// Tilt of the frame in which BeiDou GEO elements are expressed (rad): −5°.
pub const BDS_GEO_TILT_RAD: f64 = -5.0 * PI / 180.0;
/// Half a week (s): the bound beyond which tk wraps, IS-GPS-200 §20.3.3.4.3.
const HALF_WEEK_S: f64 = 302_400.0;

/// One broadcast ephemeris (clock and orbit) of a GPS or BeiDou satellite, as carried by a
/// RINEX navigation record. All times are GPS time: BeiDou epochs broadcast in BDT have
/// been converted (BDT = GPST − 14 s). Angles are in radians and rates in rad/s (RINEX
/// already converts the broadcast semicircles).
#[derive(Clone, Debug, PartialEq)]
pub struct Ephemeris {
    /// The satellite.
    pub sat: EmitterId,
    /// Clock reference epoch toc.
    pub toc: GpsTime,
    /// Orbit reference epoch toe.
    pub toe: GpsTime,
    /// When the message was transmitted (from the RINEX record; toc when not known). Used
    /// to prefer the latest issue among otherwise equal candidates.
    pub transmit_time: GpsTime,
    /// Clock bias af0 (s).
    pub af0: f64,
    /// Clock drift af1 (s/s).
    pub af1: f64,
    /// Clock drift rate af2 (s/s²).
    pub af2: f64,
    /// Square root of the semi-major axis √A (√m).
    pub sqrt_a: f64,
    /// Eccentricity e (dimensionless).
    pub e: f64,
    /// Inclination at toe i0 (rad).
    pub i0: f64,
    /// Longitude of the ascending node at the weekly epoch Ω0 (rad).
    pub omega0: f64,
    /// Argument of perigee ω (rad).
    pub omega: f64,
    /// Mean anomaly at toe M0 (rad).
    pub m0: f64,
    /// Mean motion difference Δn (rad/s).
    pub delta_n: f64,
    /// Rate of inclination IDOT (rad/s).
    pub idot: f64,
    /// Rate of right ascension Ω̇ (rad/s).
    pub omega_dot: f64,
    /// Argument-of-latitude cosine correction Cuc (rad).
    pub cuc: f64,
    /// Argument-of-latitude sine correction Cus (rad).
    pub cus: f64,
    /// Orbit-radius cosine correction Crc (m).
    pub crc: f64,
    /// Orbit-radius sine correction Crs (m).
    pub crs: f64,
    /// Inclination cosine correction Cic (rad).
    pub cic: f64,
    /// Inclination sine correction Cis (rad).
    pub cis: f64,
    /// Group delay (s): GPS TGD (L1/L2 P), BeiDou TGD1 (B1I/B3I). Not in `clock_s`.
    pub tgd_s: f64,
    /// BeiDou TGD2 (B2I/B3I) (s); 0 for GPS.
    pub tgd2_s: f64,
    /// Health: GPS 6-bit SV health, BeiDou SatH1. 0 means healthy.
    pub health: u32,
    /// Issue of data, ephemeris (GPS IODE, BeiDou AODE).
    pub iode: u32,
    /// Issue of data, clock (GPS IODC, BeiDou AODC).
    pub iodc: u32,
    /// User range accuracy as written in RINEX (m).
    pub ura_m: f64,
    /// Curve-fit interval (h) for GPS as written in RINEX (0 means 4 h); 0 for BeiDou.
    pub fit_interval_h: f64,
}

/// Bounds of the broadcast elements a real navigation message can carry, from the field
/// widths and scale factors of the message (a value outside them cannot have been
/// broadcast) and, where the interface specification narrows it, its valid range.
///
/// GPS, IS-GPS-200 Table 20-III (LNAV subframes 2 and 3):
///
/// ```text
/// Crs, Crc   16 bits × 2⁻⁵ m           → |C| ≤ 2¹⁵·2⁻⁵  = 1024 m
/// Cuc, Cus, Cic, Cis 16 bits × 2⁻²⁹ rad → |C| ≤ 2¹⁵·2⁻²⁹ = 6.1035e-5 rad
/// e          32 bits unsigned × 2⁻³³, valid range 0 … 0.03
/// √A         32 bits unsigned × 2⁻¹⁹ √m → ≤ 8192 √m; valid range from 2530 √m
/// Δn         16 bits × 2⁻⁴³ semicircles/s → |Δn| ≤ 2⁻²⁸ π rad/s = 1.17e-8 rad/s
/// ```
///
/// BeiDou, BDS-SIS-ICD-B1I-3.0 §5.2.4 (the D1/D2 ephemeris parameter table):
///
/// ```text
/// Crs, Crc   18 bits × 2⁻⁶ m           → |C| ≤ 2¹⁷·2⁻⁶  = 2048 m
/// Cuc, Cus, Cic, Cis 18 bits × 2⁻³¹ rad → |C| ≤ 2¹⁷·2⁻³¹ = 6.1035e-5 rad
/// e          32 bits unsigned × 2⁻³³   → 0 … 0.5
/// √A         32 bits unsigned × 2⁻¹⁹ √m → ≤ 8192 √m
/// Δn         16 bits × 2⁻⁴³ semicircles/s → |Δn| ≤ 1.17e-8 rad/s
/// ```
///
/// The lower bound on √A (2530 √m, A = 6401 km) is the Earth's radius plus a few tens of
/// kilometres: no orbit lies lower. The same physical reason bounds the perigee
/// A (1 − e) from below. Rounding in RINEX (12 significant digits) is far inside the
/// 1e-9 relative slack allowed.
#[derive(Clone, Copy, Debug)]
struct ElementBounds {
    radius_correction_m: f64,
    angle_correction_rad: f64,
    eccentricity_max: f64,
    delta_n_rad_per_s: f64,
}

const GPS_BOUNDS: ElementBounds = ElementBounds {
    radius_correction_m: 1024.0,
    angle_correction_rad: 6.103_515_625e-5,
    eccentricity_max: 0.03,
    delta_n_rad_per_s: 3.725_290_298_461_914e-9 * PI,
};

const BDS_BOUNDS: ElementBounds = ElementBounds {
    radius_correction_m: 2048.0,
    angle_correction_rad: 6.103_515_625e-5,
    eccentricity_max: 0.5,
    delta_n_rad_per_s: 3.725_290_298_461_914e-9 * PI,
};

/// Smallest √A (√m) of a broadcast orbit: IS-GPS-200's valid range starts here, and
/// A = 6401 km is just above the Earth's surface.
pub const SQRT_A_MIN: f64 = 2530.0;
/// Largest √A (√m) a broadcast message can carry (32 unsigned bits × 2⁻¹⁹).
pub const SQRT_A_MAX: f64 = 8192.0;
/// Mean equatorial radius of the Earth (m), WGS-84: a perigee below it is impossible.
const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// A satellite's position, velocity and clock at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SatState {
    /// Antenna (broadcast reference point) position in ECEF at the evaluation time (m).
    pub pos_ecef_m: Vector3<f64>,
    /// Velocity in the rotating ECEF frame (m/s).
    pub vel_ecef_mps: Vector3<f64>,
    /// Satellite clock offset Δt_sv (s) including the relativistic term, excluding TGD.
    pub clock_s: f64,
    /// Clock drift d(Δt_sv)/dt (s/s), including the relativistic term's derivative.
    pub clock_drift_s_per_s: f64,
}

/// Solves Kepler's equation M = E − e sin E for the eccentric anomaly E (rad) by Newton
/// iteration until the correction is below 1e-13 rad (at most 30 steps; for e < 0.9
/// convergence takes 3–6 steps). M is first reduced to [−π, π) so that the result does
/// not lose precision for large tk; the returned E is therefore congruent to, not equal
/// to, the unreduced solution — only sin E and cos E are used downstream.
pub fn solve_kepler(m_rad: f64, e: f64) -> f64 {
    let m = (m_rad + PI).rem_euclid(TAU) - PI;
    // Starting from M converges for every e < 1 when M is in [−π, π); starting at π for
    // very eccentric orbits avoids the slow first steps near perigee.
    let mut ek = if e < 0.8 { m } else { PI.copysign(m) };
    for _ in 0..30 {
        let (s, c) = ek.sin_cos();
        let step = (ek - e * s - m) / (1.0 - e * c);
        ek -= step;
        if step.abs() < 1e-13 {
            break;
        }
    }
    ek
}

/// Applies the IS-GPS-200 week-crossover rule to a time difference (s): values beyond
/// ±302400 s are brought back by one week. Time differences here come from absolute
/// [`GpsTime`]s, so this only acts when an ephemeris is evaluated more than half a week
/// from its reference epoch, where it reproduces what a receiver working in seconds of
/// week would compute.
pub fn week_crossover(dt_s: f64) -> f64 {
    if dt_s > HALF_WEEK_S {
        dt_s - 2.0 * HALF_WEEK_S
    } else if dt_s < -HALF_WEEK_S {
        dt_s + 2.0 * HALF_WEEK_S
    } else {
        dt_s
    }
}

/// Rotates an ECEF position computed at transmit time into the ECEF frame of the receive
/// time, `travel_time_s` later: the Earth turns by Ω̇e·τ meanwhile, so the satellite's
/// coordinates turn by −Ω̇e·τ about z (the Sagnac correction):
///
/// ```text
/// x' =  x cos(Ω̇e τ) + y sin(Ω̇e τ),   y' = −x sin(Ω̇e τ) + y cos(Ω̇e τ),   z' = z
/// ```
///
/// Uses the GPS value of Ω̇e; the BeiDou value differs by 1.5e-13 rad/s, i.e. by 1e-8 m
/// over a 0.08 s travel time.
pub fn sagnac_rotate(pos_ecef_m: &Vector3<f64>, travel_time_s: f64) -> Vector3<f64> {
    let p = pos_ecef_m;
    let (s, c) = (GPS_OMEGA_E_RAD_PER_S * travel_time_s).sin_cos();
    Vector3::new(c * p.x + s * p.y, -s * p.x + c * p.y, p.z)
}

/// The constants of one broadcast system.
#[derive(Clone, Copy, Debug)]
struct SystemConstants {
    mu: f64,
    omega_e: f64,
    f_rel: f64,
}

impl Ephemeris {
    /// True when the broadcast health word says the satellite may be used (health = 0).
    pub fn is_healthy(&self) -> bool {
        self.health == 0
    }

    /// Why this record cannot describe a real orbit, or `None` when every element lies in
    /// the range the broadcast message can carry (`ElementBounds`): a non-finite
    /// number, an eccentricity or semi-major axis out of range, a perigee inside the
    /// Earth, or a harmonic correction larger than its field allows. Such records come
    /// from corrupted files; evaluated, they put satellites anywhere (Crs = 1e30 m gives a
    /// satellite 4.6e29 m away), so readers drop them.
    pub fn implausibility(&self) -> Option<String> {
        let fields = [
            ("af0", self.af0),
            ("af1", self.af1),
            ("af2", self.af2),
            ("sqrt(A)", self.sqrt_a),
            ("e", self.e),
            ("i0", self.i0),
            ("OMEGA0", self.omega0),
            ("omega", self.omega),
            ("M0", self.m0),
            ("Delta n", self.delta_n),
            ("IDOT", self.idot),
            ("OMEGA DOT", self.omega_dot),
            ("Cuc", self.cuc),
            ("Cus", self.cus),
            ("Crc", self.crc),
            ("Crs", self.crs),
            ("Cic", self.cic),
            ("Cis", self.cis),
            ("TGD", self.tgd_s),
            ("TGD2", self.tgd2_s),
        ];
        if let Some((name, v)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Some(format!("{name} = {v} is not a finite number"));
        }
        let b = match self.sat.system {
            System::Bds => BDS_BOUNDS,
            _ => GPS_BOUNDS,
        };
        let slack = 1.0 + 1e-9;
        if !(0.0..=b.eccentricity_max * slack).contains(&self.e) {
            return Some(format!(
                "eccentricity {} is outside 0 … {} (the broadcast range)",
                self.e, b.eccentricity_max
            ));
        }
        if !(SQRT_A_MIN..=SQRT_A_MAX * slack).contains(&self.sqrt_a) {
            return Some(format!(
                "sqrt(A) {} sqrt(m) (semi-major axis {:.0} km) is outside {SQRT_A_MIN} … {SQRT_A_MAX} sqrt(m)",
                self.sqrt_a,
                self.semi_major_axis_m() / 1e3
            ));
        }
        let perigee_m = self.semi_major_axis_m() * (1.0 - self.e);
        if perigee_m < EARTH_RADIUS_M {
            return Some(format!(
                "the perigee ({:.0} km from the geocentre) is inside the Earth",
                perigee_m / 1e3
            ));
        }
        for (name, v) in [("Crs", self.crs), ("Crc", self.crc)] {
            if v.abs() > b.radius_correction_m * slack {
                return Some(format!(
                    "{name} = {v} m exceeds the ±{} m the message can carry",
                    b.radius_correction_m
                ));
            }
        }
        for (name, v) in [
            ("Cuc", self.cuc),
            ("Cus", self.cus),
            ("Cic", self.cic),
            ("Cis", self.cis),
        ] {
            if v.abs() > b.angle_correction_rad * slack {
                return Some(format!(
                    "{name} = {v} rad exceeds the ±{:.4e} rad the message can carry",
                    b.angle_correction_rad
                ));
            }
        }
        if self.delta_n.abs() > b.delta_n_rad_per_s * slack {
            return Some(format!(
                "Delta n = {} rad/s exceeds the ±{:.3e} rad/s the message can carry",
                self.delta_n, b.delta_n_rad_per_s
            ));
        }
        None
    }

    /// True when the BeiDou GEO algorithm applies (BDS PRN 1–5 and ≥ 59).
    pub fn is_bds_geo(&self) -> bool {
        self.sat.is_bds_geo()
    }

    /// μ, Ω̇e and F of the satellite's system: BeiDou uses CGCS2000 constants, every other
    /// system the GPS ones.
    fn constants(&self) -> SystemConstants {
        match self.sat.system {
            System::Bds => SystemConstants {
                mu: BDS_MU_M3_PER_S2,
                omega_e: BDS_OMEGA_E_RAD_PER_S,
                f_rel: BDS_F_S_PER_SQRT_M,
            },
            _ => SystemConstants {
                mu: GPS_MU_M3_PER_S2,
                omega_e: GPS_OMEGA_E_RAD_PER_S,
                f_rel: GPS_F_S_PER_SQRT_M,
            },
        }
    }

    /// toe as seconds of week of the broadcasting system (BDT for BeiDou), the value that
    /// enters the node equation.
    pub fn toe_sow_s(&self) -> f64 {
        match self.sat.system {
            System::Bds => self.toe.bdt_week_sow().1,
            _ => self.toe.tow_s(),
        }
    }

    /// Semi-major axis A (m).
    pub fn semi_major_axis_m(&self) -> f64 {
        self.sqrt_a * self.sqrt_a
    }

    /// The relativistic clock correction Δtr = F e √A sin Ek (s) at time `t`.
    pub fn relativistic_correction_s(&self, t: GpsTime) -> f64 {
        let k = self.constants();
        let a = self.semi_major_axis_m();
        let n = (k.mu / (a * a * a)).sqrt() + self.delta_n;
        let tk = week_crossover(t.seconds_since(self.toe));
        let ek = solve_kepler(self.m0 + n * tk, self.e);
        k.f_rel * self.e * self.sqrt_a * ek.sin()
    }

    /// Position, velocity and clock at GPS time `t` (equations in the module
    /// documentation). No light-time or Sagnac correction is applied.
    pub fn state(&self, t: GpsTime) -> SatState {
        let k = self.constants();
        let a = self.semi_major_axis_m();
        let n0 = (k.mu / (a * a * a)).sqrt();
        let n = n0 + self.delta_n;
        let tk = week_crossover(t.seconds_since(self.toe));

        // Anomalies.
        let ek = solve_kepler(self.m0 + n * tk, self.e);
        let (sin_e, cos_e) = ek.sin_cos();
        let one_minus_ecos = 1.0 - self.e * cos_e;
        let sqrt_1me2 = (1.0 - self.e * self.e).sqrt();
        let nu = (sqrt_1me2 * sin_e).atan2(cos_e - self.e);
        let phi = nu + self.omega;
        let (s2, c2) = (2.0 * phi).sin_cos();

        // Second-harmonic corrections and corrected elements.
        let u = phi + self.cus * s2 + self.cuc * c2;
        let r = a * one_minus_ecos + self.crs * s2 + self.crc * c2;
        let inc = self.i0 + self.idot * tk + self.cis * s2 + self.cic * c2;

        // Their rates.
        let e_dot = n / one_minus_ecos;
        let phi_dot = sqrt_1me2 * e_dot / one_minus_ecos;
        let u_dot = phi_dot * (1.0 + 2.0 * (self.cus * c2 - self.cuc * s2));
        let r_dot = a * self.e * sin_e * e_dot + 2.0 * phi_dot * (self.crs * c2 - self.crc * s2);
        let i_dot = self.idot + 2.0 * phi_dot * (self.cis * c2 - self.cic * s2);

        // Position and velocity in the orbital plane.
        let (sin_u, cos_u) = u.sin_cos();
        let xp = r * cos_u;
        let yp = r * sin_u;
        let xp_dot = r_dot * cos_u - r * u_dot * sin_u;
        let yp_dot = r_dot * sin_u + r * u_dot * cos_u;

        let geo = self.is_bds_geo();
        let toe_sow = self.toe_sow_s();
        // GEO elements live in a frame fixed at toe, so the node does not follow the Earth's
        // rotation during tk; that rotation is applied afterwards by Rz.
        let node_rate = if geo {
            self.omega_dot
        } else {
            self.omega_dot - k.omega_e
        };
        let node = self.omega0 + node_rate * tk - k.omega_e * toe_sow;
        let (sin_o, cos_o) = node.sin_cos();
        let (sin_i, cos_i) = inc.sin_cos();

        let pos = Vector3::new(
            xp * cos_o - yp * cos_i * sin_o,
            xp * sin_o + yp * cos_i * cos_o,
            yp * sin_i,
        );
        let vel = Vector3::new(
            xp_dot * cos_o - yp_dot * cos_i * sin_o + yp * sin_i * sin_o * i_dot
                - pos.y * node_rate,
            xp_dot * sin_o + yp_dot * cos_i * cos_o - yp * sin_i * cos_o * i_dot
                + pos.x * node_rate,
            yp_dot * sin_i + yp * cos_i * i_dot,
        );

        let (pos_ecef_m, vel_ecef_mps) = if geo {
            let (st, ct) = (k.omega_e * tk).sin_cos();
            let (sx, cx) = BDS_GEO_TILT_RAD.sin_cos();
            let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cx, sx, 0.0, -sx, cx);
            let rz = Matrix3::new(ct, st, 0.0, -st, ct, 0.0, 0.0, 0.0, 1.0);
            let rz_dot = Matrix3::new(-st, ct, 0.0, -ct, -st, 0.0, 0.0, 0.0, 0.0) * k.omega_e;
            let p_tilted = rx * pos;
            (rz * p_tilted, rz * (rx * vel) + rz_dot * p_tilted)
        } else {
            (pos, vel)
        };

        // Clock: polynomial about toc plus the relativistic eccentricity term.
        let dt = week_crossover(t.seconds_since(self.toc));
        let rel_scale = k.f_rel * self.e * self.sqrt_a;
        let clock_s = self.af0 + dt * (self.af1 + dt * self.af2) + rel_scale * sin_e;
        let clock_drift_s_per_s = self.af1 + 2.0 * self.af2 * dt + rel_scale * cos_e * e_dot;

        SatState {
            pos_ecef_m,
            vel_ecef_mps,
            clock_s,
            clock_drift_s_per_s,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// G02 from brdc1820.10n (2010-07-01 00:00:00 GPST), transcribed by hand.
    pub(crate) fn g02_2010() -> Ephemeris {
        let toe = GpsTime::from_week_tow(1590, 345_600.0);
        Ephemeris {
            sat: EmitterId::new(System::Gps, 2),
            toc: toe,
            toe,
            transmit_time: GpsTime::from_week_tow(1590, 338_418.0),
            af0: 0.269108917564e-03,
            af1: 0.318323145621e-11,
            af2: 0.0,
            iode: 85,
            crs: 0.414375000000e+02,
            delta_n: 0.525557597442e-08,
            m0: 0.165772167412e+01,
            cuc: 0.232271850109e-05,
            e: 0.960697804112e-02,
            cus: 0.617466866970e-05,
            sqrt_a: 0.515359739113e+04,
            cic: -0.558793544769e-08,
            omega0: -0.127458719764e+01,
            cis: 0.167638063431e-06,
            i0: 0.939349150611e+00,
            crc: 0.249937500000e+03,
            omega: 0.309739903949e+01,
            omega_dot: -0.838784952606e-08,
            idot: -0.232152526369e-10,
            ura_m: 2.0,
            health: 0,
            tgd_s: -0.172294676304e-07,
            tgd2_s: 0.0,
            iodc: 85,
            fit_interval_h: 4.0,
        }
    }

    #[test]
    fn kepler_hand_values() {
        // E − e sin E = M: for M = 1, e = 0.1 the solution is 1.0885977523978936 (checked
        // by substitution: 1.0885977524 − 0.1 sin 1.0885977524 = 1.0000000000).
        let e1 = solve_kepler(1.0, 0.1);
        assert!((e1 - 1.088_597_752_397_893_6).abs() < 1e-13, "{e1}");
        assert!((e1 - 0.1 * e1.sin() - 1.0).abs() < 1e-14);
        let e2 = solve_kepler(2.5, 0.6);
        assert!((e2 - 0.6 * e2.sin() - 2.5).abs() < 1e-13);
        // Circular orbit: E = M. Large M is reduced modulo 2π.
        assert!((solve_kepler(0.3, 0.0) - 0.3).abs() < 1e-15);
        let big = 0.3 + 1000.0 * TAU;
        let eb = solve_kepler(big, 0.01);
        assert!((eb.sin() - solve_kepler(0.3, 0.01).sin()).abs() < 1e-10);
        // Very eccentric orbits still converge.
        for &m in &[-3.0, -0.01, 0.0, 0.01, 3.1] {
            let ek = solve_kepler(m, 0.97);
            assert!((ek - 0.97 * ek.sin() - m).abs() < 1e-12, "m {m}");
        }
    }

    /// A circular orbit in the equator with all corrections zero, whose position follows
    /// by hand: r = A, the argument of latitude is M0 + n tk, and the ECEF longitude is
    /// Ω0 − Ω̇e toe + (n − Ω̇e) tk + M0.
    fn circular_equatorial() -> Ephemeris {
        let mut e = g02_2010();
        e.e = 0.0;
        e.i0 = 0.0;
        e.omega = 0.0;
        e.cuc = 0.0;
        e.cus = 0.0;
        e.crc = 0.0;
        e.crs = 0.0;
        e.cic = 0.0;
        e.cis = 0.0;
        e.idot = 0.0;
        e.omega_dot = 0.0;
        e.delta_n = 0.0;
        e.sqrt_a = 26_560_000f64.sqrt();
        e.m0 = 0.25;
        e.omega0 = 1.0;
        e
    }

    #[test]
    fn hand_checkable_circular_orbit() {
        let eph = circular_equatorial();
        let a = 26_560_000.0;
        let n = (GPS_MU_M3_PER_S2 / (a * a * a)).sqrt();
        for &tk in &[0.0, 600.0, -3600.0] {
            let t = eph.toe.add_seconds(tk);
            let s = eph.state(t);
            let lon =
                1.0 - GPS_OMEGA_E_RAD_PER_S * 345_600.0 + (n - GPS_OMEGA_E_RAD_PER_S) * tk + 0.25;
            let expect = Vector3::new(a * lon.cos(), a * lon.sin(), 0.0);
            assert!(
                (s.pos_ecef_m - expect).norm() < 1e-6,
                "tk {tk}: {:?} vs {expect:?}",
                s.pos_ecef_m
            );
            // Speed in ECEF: (n − Ω̇e) A, tangential.
            let v = (n - GPS_OMEGA_E_RAD_PER_S) * a;
            let expect_v = Vector3::new(-v * lon.sin(), v * lon.cos(), 0.0);
            assert!((s.vel_ecef_mps - expect_v).norm() < 1e-9);
            // No eccentricity → no relativistic term; clock is the polynomial.
            assert!((s.clock_s - (eph.af0 + eph.af1 * tk)).abs() < 1e-18);
        }
        // A polar orbit puts z = A sin u.
        let mut polar = eph.clone();
        polar.i0 = PI / 2.0;
        let s = polar.state(polar.toe);
        assert!((s.pos_ecef_m.z - a * 0.25f64.sin()).abs() < 1e-6);
    }

    /// Central differences of position over ±h for the velocity; the truncation error is
    /// |a'| h²/6 ≈ 1e-6 m/s for h = 0.5 s, far below the 1 mm/s bound.
    fn check_velocity(eph: &Ephemeris, t: GpsTime) {
        let h = 0.5;
        let s = eph.state(t);
        let p1 = eph.state(t.add_seconds(h)).pos_ecef_m;
        let p0 = eph.state(t.add_seconds(-h)).pos_ecef_m;
        let fd = (p1 - p0) / (2.0 * h);
        let err = (fd - s.vel_ecef_mps).norm();
        assert!(err < 1e-3, "{}: velocity error {err} m/s", eph.sat);
        let c1 = eph.state(t.add_seconds(h)).clock_s;
        let c0 = eph.state(t.add_seconds(-h)).clock_s;
        let drift_fd = (c1 - c0) / (2.0 * h);
        assert!(
            (drift_fd - s.clock_drift_s_per_s).abs() < 1e-15,
            "{}: drift",
            eph.sat
        );
    }

    #[test]
    fn velocity_matches_finite_differences() {
        let g = g02_2010();
        for &dt in &[-7000.0, 0.0, 1234.5, 7000.0] {
            check_velocity(&g, g.toe.add_seconds(dt));
        }
        // A BeiDou GEO (C05 of 2020-06-24 22:00 BDT, ESBC00DNK) exercises the GEO
        // rotations and their derivative.
        let c05 = c05_2020();
        for &dt in &[-3000.0, 0.0, 3000.0] {
            check_velocity(&c05, c05.toe.add_seconds(dt));
        }
        let mut meo = c05.clone();
        meo.sat = EmitterId::new(System::Bds, 20);
        check_velocity(&meo, meo.toe.add_seconds(500.0));
    }

    /// C05 from ESBC00DNK_R_20201770000_01D_MN.rnx, toc 2020-06-24 22:00:00 BDT.
    pub(crate) fn c05_2020() -> Ephemeris {
        let toe = GpsTime::from_bdt_week_sow(755, 338_400.0);
        Ephemeris {
            sat: EmitterId::new(System::Bds, 5),
            toc: toe,
            toe,
            transmit_time: GpsTime::from_bdt_week_sow(755, 338_427.6),
            af0: -5.154609680176e-04,
            af1: -6.708145150469e-11,
            af2: 0.0,
            iode: 1,
            crs: -4.142968750000e+02,
            delta_n: -3.141559429989e-09,
            m0: -1.101749161212e+00,
            cuc: -1.366203650832e-05,
            e: 3.830116475001e-04,
            cus: -1.177610829473e-05,
            sqrt_a: 6.493378950119e+03,
            cic: -6.146728992462e-08,
            omega0: 2.697580724014e+00,
            cis: 6.146728992462e-08,
            i0: 1.136268367853e-01,
            crc: 3.549843750000e+02,
            omega: -1.027125663175e+00,
            omega_dot: 4.100527946305e-09,
            idot: 3.321566928024e-10,
            ura_m: 2.0,
            health: 0,
            tgd_s: 1.0e-10,
            tgd2_s: -9.3e-09,
            iodc: 0,
            fit_interval_h: 0.0,
        }
    }

    #[test]
    fn broadcast_positions_match_precise_orbit_at_epoch() {
        // igs15904.sp3, 2010-07-01 00:00:00: PG02 −14889.160729 −5131.952946 −21416.801336 km,
        // clock 269.108429 µs. Broadcast orbits agree to a few metres.
        let s = g02_2010().state(GpsTime::from_week_tow(1590, 345_600.0));
        let sp3 = Vector3::new(-14_889_160.729, -5_131_952.946, -21_416_801.336);
        assert!(
            (s.pos_ecef_m - sp3).norm() < 5.0,
            "{}",
            (s.pos_ecef_m - sp3).norm()
        );
        // SP3 clocks exclude the relativistic term, like af0..af2.
        let rel = g02_2010().relativistic_correction_s(GpsTime::from_week_tow(1590, 345_600.0));
        assert!((s.clock_s - rel - 269.108429e-6).abs() < 5e-9);
        // Sta21114.sp3 at 2020-06-25 00:00:00 GPST: PC05 21892.326139 36001.717218 −1109.124143 km.
        // The GEO broadcast is good to some tens of metres.
        let c05 = c05_2020();
        let s = c05.state(GpsTime::from_week_tow(2111, 345_600.0));
        let sp3 = Vector3::new(21_892_326.139, 36_001_717.218, -1_109_124.143);
        assert!(
            (s.pos_ecef_m - sp3).norm() < 50.0,
            "{}",
            (s.pos_ecef_m - sp3).norm()
        );
    }

    #[test]
    fn week_crossover_is_handled() {
        // An ephemeris with toe near the end of a week evaluated early in the next week.
        let mut g = g02_2010();
        g.toe = GpsTime::from_week_tow(1590, 604_000.0);
        g.toc = g.toe;
        let s1 = g.state(GpsTime::from_week_tow(1591, 200.0));
        let s2 = g.state(g.toe.add_seconds(1000.0));
        assert_eq!(s1, s2);
        assert_eq!(week_crossover(302_401.0), 302_401.0 - 604_800.0);
        assert_eq!(week_crossover(-302_401.0), -302_401.0 + 604_800.0);
        assert_eq!(week_crossover(1.0), 1.0);
    }

    #[test]
    fn sagnac_rotation() {
        let p = Vector3::new(20_000e3, 0.0, 10_000e3);
        let tau = 0.07;
        let r = sagnac_rotate(&p, tau);
        // Rotating back restores the point.
        assert!((sagnac_rotate(&r, -tau) - p).norm() < 1e-6);
        // The point moves west (negative y) by ≈ x Ω̇e τ ≈ 102 m; z is untouched, norm kept.
        assert!((r.y + 20_000e3 * GPS_OMEGA_E_RAD_PER_S * tau).abs() < 1e-3);
        assert_eq!(r.z, p.z);
        assert!((r.norm() - p.norm()).abs() < 1e-6);
    }
}
