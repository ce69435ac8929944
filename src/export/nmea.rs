//! NMEA 0183 (v4.10) sentences of a recorded trial: GGA, RMC, GSA and GSV, as a
//! multi-constellation receiver logs them, for the truth and for each estimator.
//!
//! Conventions (NMEA 0183 v4.10):
//! - Position and fix sentences use the combined talker `GN`; the satellite sentences use
//!   the talker of their system, `GP` (GPS) and `GB` (BeiDou), so that a reader never has
//!   to guess the system from the satellite number (BeiDou C33 read from a `GN` sentence
//!   is SBAS PRN 120 in the NMEA 2.x numbering many readers still apply).
//! - GSA lists the satellites of one system (up to 12) and ends with the NMEA 4.10 system
//!   id (1 GPS, 4 BeiDou); the DOPs are those of the whole GPS + BeiDou geometry with one
//!   clock per system. Each epoch gives GGA, RMC, every GSA, then every GSV, the order
//!   of multi-constellation receivers.
//! - GSV carries the signal id 1 (GPS L1 C/A, BeiDou B1I).
//! - No sentence exceeds the 82 characters NMEA 0183 allows (`$` to CR LF): latitude and
//!   longitude carry 6 decimals of a minute (1.9 mm), and the altitude and speed lose
//!   decimals only when a diverged estimate would not fit otherwise.
//! - Times are UTC (GPST minus the leap seconds of the epoch).
//! - The GGA altitude is the WGS-84 ellipsoidal height with a geoid separation of 0, so
//!   altitude + separation is exactly the ellipsoidal height a reader reconstructs.
//! - Every sentence ends with `*hh` (XOR of the bytes between `$` and `*`) and CR LF.

use super::{write_text, RecordedBatch, Recording};
use crate::core::geodesy::azimuth_elevation;
use crate::core::{Geodetic, GpsTime, System};
use crate::measurement::{Measurement, SourceKind};
use crate::world::World;
use nalgebra::Vector3;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Metres per second in a knot.
const MPS_PER_KNOT: f64 = 1852.0 / 3600.0;

/// Longest sentence NMEA 0183 allows, `$` to CR LF included (NMEA 0183 v4.10 §5.3).
pub const MAX_SENTENCE_LEN: usize = 82;

/// `x` with `decimals` decimals, or fewer (down to none) when the text would be longer
/// than `width` characters.
fn fit(x: f64, decimals: usize, width: usize) -> String {
    (0..=decimals)
        .rev()
        .map(|d| format!("{x:.d$}"))
        .find(|t| t.len() <= width)
        .unwrap_or_else(|| format!("{x:.0}"))
}

/// Appends `$body*hh\r\n`.
fn sentence(out: &mut String, body: &str) {
    let cs = body.bytes().fold(0u8, |a, b| a ^ b);
    let _ = write!(out, "${body}*{cs:02X}\r\n");
}

/// `ddmm.mmmmmm,N` or `dddmm.mmmmmm,E` (6 decimals of a minute: 1.9 mm).
fn lat_lon(g: &Geodetic) -> String {
    let f = |deg: f64, width: usize, pos: char, neg: char| {
        let a = deg.abs();
        let mut d = a.trunc();
        let mut m = (a - d) * 60.0;
        // Rounding to 6 decimals can carry a minute to 60.
        if (m * 1e6).round() >= 60.0 * 1e6 {
            d += 1.0;
            m = 0.0;
        }
        format!(
            "{:0width$}{:09.6},{}",
            d as u32,
            m,
            if deg < 0.0 { neg } else { pos }
        )
    };
    format!(
        "{},{}",
        f(g.lat_deg(), 2, 'N', 'S'),
        f(g.lon_deg(), 3, 'E', 'W')
    )
}

/// UTC `hhmmss.ss` and `ddmmyy`.
fn utc(t: GpsTime) -> (String, String) {
    // Rounded to the hundredth first, so 59.999 s does not print as 60.00.
    let t = GpsTime::from_ns((t.as_seconds_f64() * 100.0).round() as i64 * 10_000_000);
    let (y, mo, d, h, mi, s, ns) = t.to_utc_calendar();
    (
        format!("{h:02}{mi:02}{s:02}.{:02}", ns / 10_000_000),
        format!("{d:02}{mo:02}{:02}", y.rem_euclid(100)),
    )
}

/// One satellite as GSA/GSV list it.
#[derive(Clone, Copy)]
struct SatInView {
    system: System,
    prn: u16,
    el_deg: f64,
    az_deg: f64,
    cn0_dbhz: f64,
}

fn sats_in_view(batch: &RecordedBatch) -> Vec<SatInView> {
    batch
        .items
        .iter()
        .filter_map(|m| match m {
            Measurement::Range(r) if matches!(r.emitter.system, System::Gps | System::Bds) => {
                let (az, el) = azimuth_elevation(&batch.truth.pos_ecef_m, &r.emitter_pos_ecef_m);
                Some(SatInView {
                    system: r.emitter.system,
                    prn: r.emitter.number,
                    el_deg: el.to_degrees(),
                    az_deg: az.to_degrees(),
                    cn0_dbhz: r.cn0_dbhz,
                })
            }
            _ => None,
        })
        .collect()
}

/// PDOP, HDOP, VDOP of the satellites (one clock per system) seen from `pos`.
fn dops(batch: &RecordedBatch, pos: &Vector3<f64>) -> Option<(f64, f64, f64)> {
    let mut systems: Vec<System> = Vec::new();
    let emitters: Vec<(Vector3<f64>, usize)> = batch
        .items
        .iter()
        .filter_map(|m| match m {
            Measurement::Range(r) if matches!(r.emitter.system, System::Gps | System::Bds) => {
                let k = match systems.iter().position(|s| *s == r.emitter.system) {
                    Some(k) => k,
                    None => {
                        systems.push(r.emitter.system);
                        systems.len() - 1
                    }
                };
                Some((r.emitter_pos_ecef_m, k))
            }
            _ => None,
        })
        .collect();
    crate::fusion::wls::dop(pos, &emitters, systems.len()).map(|d| (d.pdop, d.hdop, d.vdop))
}

/// What one epoch's sentences say.
struct Fix<'a> {
    t: GpsTime,
    /// The position reported, `None` for an epoch without a fix.
    pos_ecef_m: Option<Vector3<f64>>,
    vel_enu_mps: Option<Vector3<f64>>,
    /// The receiver epoch whose satellites GSA and GSV list.
    gnss: Option<&'a RecordedBatch>,
}

fn epoch(out: &mut String, f: &Fix<'_>) {
    let (hms, date) = utc(f.t);
    let sats = f.gnss.map(sats_in_view).unwrap_or_default();
    let dop = match (f.gnss, f.pos_ecef_m) {
        (Some(b), Some(p)) => dops(b, &p),
        _ => None,
    };
    let fmt_dop = |v: Option<f64>| {
        v.map(|x| format!("{:.2}", x.min(99.99)))
            .unwrap_or_default()
    };
    match f.pos_ecef_m {
        Some(p) => {
            let g = Geodetic::from_ecef(&p);
            sentence(
                out,
                &format!(
                    "GNGGA,{hms},{},1,{:02},{},{},M,0.0,M,,",
                    lat_lon(&g),
                    sats.len().min(99),
                    fmt_dop(dop.map(|d| d.1)),
                    // −999.999 … 99999.999 m keep millimetres.
                    fit(g.h_m, 3, 9)
                ),
            );
            let (speed, course) = match f.vel_enu_mps {
                Some(v) => {
                    let s = (v.x * v.x + v.y * v.y).sqrt();
                    let c = v.x.atan2(v.y).to_degrees().rem_euclid(360.0);
                    (fit(s / MPS_PER_KNOT, 3, 7), format!("{c:.2}"))
                }
                None => (String::new(), String::new()),
            };
            sentence(
                out,
                &format!(
                    "GNRMC,{hms},A,{},{speed},{course},{date},,,A,V",
                    lat_lon(&g)
                ),
            );
        }
        None => {
            sentence(out, &format!("GNGGA,{hms},,,,,0,00,,,M,,M,,"));
            sentence(out, &format!("GNRMC,{hms},V,,,,,,,{date},,,N,V"));
        }
    }
    const SYSTEMS: [(System, &str, u8); 2] = [(System::Gps, "GP", 1), (System::Bds, "GB", 4)];
    for (system, talker, sys_id) in SYSTEMS {
        let mine: Vec<&SatInView> = sats.iter().filter(|s| s.system == system).collect();
        let mut gsa = format!(
            "{talker}GSA,A,{}",
            if f.pos_ecef_m.is_some() && dop.is_some() {
                3
            } else {
                1
            }
        );
        for k in 0..12 {
            gsa.push(',');
            if let Some(s) = mine.get(k) {
                let _ = write!(gsa, "{:02}", s.prn);
            }
        }
        let _ = write!(
            gsa,
            ",{},{},{},{sys_id}",
            fmt_dop(dop.map(|d| d.0)),
            fmt_dop(dop.map(|d| d.1)),
            fmt_dop(dop.map(|d| d.2))
        );
        sentence(out, &gsa);
    }
    for (system, talker, _) in SYSTEMS {
        let mine: Vec<&SatInView> = sats.iter().filter(|s| s.system == system).collect();
        // GSV: four satellites per sentence; a system with none still says so.
        let n_msgs = mine.len().div_ceil(4).max(1);
        for m in 0..n_msgs {
            let mut gsv = format!("{talker}GSV,{n_msgs},{},{:02}", m + 1, mine.len());
            for s in mine.iter().skip(4 * m).take(4) {
                let _ = write!(
                    gsv,
                    ",{:02},{:02},{:03},{:02}",
                    s.prn,
                    s.el_deg.round().clamp(0.0, 90.0) as i32,
                    (s.az_deg.round() as i32).rem_euclid(360),
                    s.cn0_dbhz.round().clamp(0.0, 99.0) as i32
                );
            }
            gsv.push_str(",1");
            sentence(out, &gsv);
        }
    }
}

/// The receiver (GNSS) batches of the recording, in time order.
fn gnss_batches(rec: &Recording) -> Vec<&RecordedBatch> {
    rec.batches
        .iter()
        .filter(|b| b.source == SourceKind::Gnss)
        .collect()
}

/// Writes `DIR/truth.nmea` and `DIR/<estimator>.nmea`.
///
/// The truth file has an epoch per receiver epoch (per truth-track epoch when the world
/// has no GNSS receiver); an estimator's file one per scored epoch, listing the satellites
/// of the latest receiver epoch and a course and speed from successive estimates.
pub fn write(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let gnss = gnss_batches(rec);
    let latest_gnss = |t_s: f64| -> Option<&RecordedBatch> {
        let k = gnss.partition_point(|b| b.truth.sim.seconds() <= t_s + 1e-9);
        k.checked_sub(1).map(|k| gnss[k])
    };
    let mut files = Vec::new();

    let mut text = String::new();
    if gnss.is_empty() {
        for t in rec.truth_track() {
            epoch(
                &mut text,
                &Fix {
                    t: t.t,
                    pos_ecef_m: Some(t.pos_ecef_m),
                    vel_enu_mps: Some(t.enu.vel_enu_mps),
                    gnss: None,
                },
            );
        }
    } else {
        for b in &gnss {
            epoch(
                &mut text,
                &Fix {
                    t: b.truth.t,
                    pos_ecef_m: Some(b.truth.pos_ecef_m),
                    vel_enu_mps: Some(b.truth.enu.vel_enu_mps),
                    gnss: Some(b),
                },
            );
        }
    }
    files.push(write_text(dir, "truth.nmea", &text)?);

    for (est, stem) in rec.estimators.iter().zip(rec.estimator_stems()) {
        let mut text = String::new();
        let mut prev: Option<(f64, Vector3<f64>)> = None;
        for e in &est.epochs {
            let pos = e.est_ecef_m.map(Vector3::from);
            let vel = match (prev, pos) {
                (Some((t0, p0)), Some(p)) if e.t_s > t0 => {
                    Some(world.frame.enu_vector_of_ecef(&((p - p0) / (e.t_s - t0))))
                }
                _ => None,
            };
            if let Some(p) = pos {
                prev = Some((e.t_s, p));
            }
            epoch(
                &mut text,
                &Fix {
                    t: world.start.add_seconds(e.t_s),
                    pos_ecef_m: pos,
                    vel_enu_mps: vel,
                    gnss: latest_gnss(e.t_s),
                },
            );
        }
        files.push(write_text(dir, &format!("{stem}.nmea"), &text)?);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_matches_a_published_sentence() {
        // The GGA example of the NMEA 0183 literature (gpsd's "NMEA revealed"):
        // $GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47
        let mut s = String::new();
        sentence(
            &mut s,
            "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        );
        assert_eq!(
            s,
            "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n"
        );
    }

    #[test]
    fn coordinates_in_degrees_and_minutes() {
        let g = Geodetic::from_deg(48.1173, -11.516_666_666_666_667, 0.0);
        assert_eq!(lat_lon(&g), "4807.038000,N,01131.000000,W");
        // A minute that rounds up to 60 carries into the degrees.
        let g = Geodetic::from_deg(-(40.0 - 1e-12), 116.0, 0.0);
        assert_eq!(lat_lon(&g), "4000.000000,S,11600.000000,E");
    }

    /// The longest fields a fix can produce — a southern, western position, a 99.99 HDOP
    /// field, a 5-digit altitude, and a diverged estimate far above the Earth moving at
    /// 1e6 m/s — still fit in 82 characters.
    #[test]
    fn sentences_fit_in_82_characters() {
        let t = GpsTime::from_gpst_calendar(2018, 12, 31, 23, 59, 59, 990_000_000);
        for (lat, lon, h, v) in [
            (-89.999_999, -179.999_999, -999.999_4, 1e3),
            (-45.5, -120.25, 99_999.999, 340.0),
            (-45.5, -120.25, 1.234e7, 1e6),
            (-45.5, -120.25, -6.3e6, -1e6),
        ] {
            let g = Geodetic::from_deg(lat, lon, h);
            let mut out = String::new();
            epoch(
                &mut out,
                &Fix {
                    t,
                    pos_ecef_m: Some(g.to_ecef()),
                    vel_enu_mps: Some(Vector3::new(v, -v, 0.0)),
                    gnss: None,
                },
            );
            for line in out.split_inclusive("\r\n") {
                assert!(
                    line.len() <= MAX_SENTENCE_LEN,
                    "{} chars: {line}",
                    line.len()
                );
            }
        }
        assert_eq!(fit(-999.9994, 3, 9), "-999.999");
        assert_eq!(fit(1.234e7, 3, 9), "12340000");
    }

    #[test]
    fn utc_is_gpst_minus_leap_seconds() {
        // 2018-06-01 04:00:00 GPST is 03:59:42 UTC (18 leap seconds).
        let t = GpsTime::from_gpst_calendar(2018, 6, 1, 4, 0, 0, 0);
        assert_eq!(utc(t), ("035942.00".to_string(), "010618".to_string()));
    }
}
