//! RINEX 3.04 observation files of a recorded trial, and the navigation file it used.
//!
//! The observation file is what a GPS + BeiDou receiver would log (RINEX 3.04, IGS/RTCM
//! 2018, §5 and Appendix A2–A3): mixed (`M`), one epoch per receiver epoch with at least
//! one satellite, the observables `C1C L1C D1C S1C` (GPS L1 C/A) and `C2I L2I D2I S2I`
//! (BeiDou B1I; RINEX 3.04 names B1I band 2).
//!
//! Receiver clock, as in a real receiver: the time tag of an epoch is the receiver clock's
//! reading, GPST + δt_r, and the code and phase carry the same δt_r (`RCV CLOCK OFFS APPL
//! 0`). Like a receiver with a free-running oscillator that keeps its clock within
//! ±0.5 ms of GPS time, the clock is stepped by whole milliseconds: when δt_r would exceed
//! 0.5 ms, the tag, the code and the phase all lose k·1 ms (k = round(δt_r / 1 ms)), so
//! `RCV CLOCK OFFS APPL` stays 0 and a reader sees the usual millisecond jumps. A
//! single-point solver (RTKLIB's `rnx2rtkp`) estimates δt_r and recovers the true
//! reception time from the tag.
//!
//! Values are printed F14.3 with the loss-of-lock indicator (bit 0, on the phase) and the
//! signal-strength indicator SSI = clamp(⌊C/N0 / 6⌋, 1, 9) (RINEX 3.04 §5.7).

use super::Recording;
use crate::core::{GpsTime, System, C_MPS};
use crate::gnss::measurement::{F_B1I_HZ, F_L1_HZ};
use crate::io::atomic::write_atomic;
use crate::measurement::{RawGnssObservation, SourceKind};
use crate::world::{World, BUILTIN_EPHEMERIS, BUILTIN_EPHEMERIS_NAME};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// One epoch's record before formatting.
struct Epoch<'a> {
    /// The time tag: receiver time after the millisecond steps.
    tag: GpsTime,
    /// Whole milliseconds the receiver stepped its clock by (removed from code and phase).
    jump_ms: f64,
    sats: Vec<&'a RawGnssObservation>,
}

/// A header line: `content` in columns 1–60, `label` in 61–80.
fn header(out: &mut String, content: &str, label: &str) {
    // Content beyond column 60 would shift the label where readers look for it.
    let content: String = content.chars().take(60).collect();
    let _ = writeln!(out, "{content:<60}{label:<20}");
}

fn calendar(t: GpsTime) -> (i32, u8, u8, u8, u8, f64) {
    // Rounded to 100 ns first (the record's 7 decimals), so a carry reaches the minutes.
    // In integer nanoseconds: through f64 seconds since 1980 (spacing 2⁻²² s near
    // 1.3·10⁹ s, and 2 units of 100 ns once scaled by 10⁷) the tag was off by up to
    // 0.3 µs, which the observation reader's round trip found.
    let t = GpsTime::from_ns((t.ns() + 50).div_euclid(100) * 100);
    let (y, mo, d, h, mi, s, ns) = t.to_gpst_calendar();
    (y, mo, d, h, mi, f64::from(s) + f64::from(ns) * 1e-9)
}

fn ssi(cn0_dbhz: f64) -> u8 {
    (cn0_dbhz / 6.0).floor().clamp(1.0, 9.0) as u8
}

fn lambda_m(system: System) -> f64 {
    C_MPS
        / if system == System::Bds {
            F_B1I_HZ
        } else {
            F_L1_HZ
        }
}

/// The receiver epochs with their time tags and clock steps.
fn epochs(rec: &Recording) -> Vec<Epoch<'_>> {
    let mut out = Vec::new();
    for b in rec.batches.iter().filter(|b| b.source == SourceKind::Gnss) {
        let mut sats: Vec<&RawGnssObservation> = b
            .raw
            .gnss
            .iter()
            .filter(|o| matches!(o.sat.system, System::Gps | System::Bds))
            .collect();
        if sats.is_empty() {
            continue;
        }
        sats.sort_by_key(|o| (o.sat.system != System::Gps, o.sat.number));
        let dt_r = sats[0].rx_clock_s;
        let jump_ms = (dt_r * 1e3).round();
        out.push(Epoch {
            tag: b.truth.t.add_seconds(dt_r - jump_ms * 1e-3),
            jump_ms,
            sats,
        });
    }
    out
}

/// The observation file's text.
///
/// # Errors
/// A recording without GNSS observations (a world without `[sensors.gnss]`).
pub fn observation_text(world: &World, rec: &Recording) -> Result<String, String> {
    let epochs = epochs(rec);
    let (Some(first), Some(last)) = (epochs.first(), epochs.last()) else {
        return Err(
            "the trial has no GNSS observations (the world needs [sensors.gnss] and a \
             satellite in view)"
                .into(),
        );
    };
    // The receiver's systems: the header declares observables for those only, and the
    // file type is the system's letter when there is one (RINEX 3.04 §5.1, Table A1).
    let systems: Vec<System> = world
        .file
        .sensors
        .gnss
        .as_ref()
        .map(|g| g.systems.clone())
        .unwrap_or_default();
    let has = |s: System| systems.contains(&s);
    let file_system = match (has(System::Gps), has(System::Bds)) {
        (true, false) => "G",
        (false, true) => "C",
        _ => "M",
    };
    let mut h = String::new();
    header(
        &mut h,
        &format!(
            "{:>9}{:11}{:<20}{:<20}",
            "3.04", "", "OBSERVATION DATA", file_system
        ),
        "RINEX VERSION / TYPE",
    );
    // The "file creation" date is the first epoch's (UTC), not the wall clock: the same
    // world and seed must give the same bytes.
    let (y, mo, d, hh, mi, s, _) = first.tag.to_utc_calendar();
    header(
        &mut h,
        &format!(
            "{:<20}{:<20}{y:04}{mo:02}{d:02} {hh:02}{mi:02}{s:02} UTC ",
            format!("hybridnav {}", env!("CARGO_PKG_VERSION")),
            "hybridnav",
        ),
        "PGM / RUN BY / DATE",
    );
    header(
        &mut h,
        &format!(
            "world {:?}, seed {}, trial {}",
            world.file.world.name.chars().take(30).collect::<String>(),
            rec.seed,
            rec.trial
        )
        .chars()
        .take(60)
        .collect::<String>(),
        "COMMENT",
    );
    header(
        &mut h,
        "time tags: receiver time; clock stepped by 1 ms at 0.5 ms",
        "COMMENT",
    );
    header(&mut h, "HYBRIDNAV", "MARKER NAME");
    header(&mut h, "NON_GEODETIC", "MARKER TYPE");
    header(
        &mut h,
        &format!("{:<20}{:<40}", "hybridnav", "simulation"),
        "OBSERVER / AGENCY",
    );
    header(
        &mut h,
        &format!(
            "{:<20}{:<20}{:<20}",
            "0",
            "HYBRIDNAV-SIM",
            env!("CARGO_PKG_VERSION")
        ),
        "REC # / TYPE / VERS",
    );
    header(
        &mut h,
        &format!("{:<20}{:<20}", "0", "SIMULATED"),
        "ANT # / TYPE",
    );
    let p0 = rec
        .batches
        .iter()
        .find(|b| b.source == SourceKind::Gnss)
        .map(|b| b.truth.pos_ecef_m)
        .unwrap_or_default();
    header(
        &mut h,
        &format!("{:14.4}{:14.4}{:14.4}", p0.x, p0.y, p0.z),
        "APPROX POSITION XYZ",
    );
    header(
        &mut h,
        &format!("{:14.4}{:14.4}{:14.4}", 0.0, 0.0, 0.0),
        "ANTENNA: DELTA H/E/N",
    );
    if has(System::Gps) {
        header(&mut h, "G    4 C1C L1C D1C S1C", "SYS / # / OBS TYPES");
    }
    if has(System::Bds) {
        header(&mut h, "C    4 C2I L2I D2I S2I", "SYS / # / OBS TYPES");
    }
    header(&mut h, "DBHZ", "SIGNAL STRENGTH UNIT");
    if epochs.len() >= 2 {
        let dt = epochs[1].tag.seconds_since(epochs[0].tag);
        header(
            &mut h,
            &format!("{:10.3}", dt.round_ties_even()),
            "INTERVAL",
        );
    }
    for (e, label) in [(first, "TIME OF FIRST OBS"), (last, "TIME OF LAST OBS")] {
        let (y, mo, d, hh, mi, s) = calendar(e.tag);
        header(
            &mut h,
            &format!("{y:6}{mo:6}{d:6}{hh:6}{mi:6}{s:13.7}{:>8}", "GPS"),
            label,
        );
    }
    header(&mut h, &format!("{:6}", 0), "RCV CLOCK OFFS APPL");
    if has(System::Gps) {
        header(&mut h, "G L1C  0.00000", "SYS / PHASE SHIFT");
    }
    if has(System::Bds) {
        header(&mut h, "C L2I  0.00000", "SYS / PHASE SHIFT");
    }
    header(
        &mut h,
        &format!("{:6}", first.tag.gpst_minus_utc_s()),
        "LEAP SECONDS",
    );
    header(&mut h, "", "END OF HEADER");

    for e in &epochs {
        let (y, mo, d, hh, mi, s) = calendar(e.tag);
        let _ = writeln!(
            h,
            "> {y:4} {mo:02} {d:02} {hh:02} {mi:02}{s:11.7}  0{:3}",
            e.sats.len()
        );
        for o in &e.sats {
            let lambda = lambda_m(o.sat.system);
            let jump_m = C_MPS * e.jump_ms * 1e-3;
            let code = o.pseudorange_m - jump_m;
            let phase = o.carrier_phase_cycles - jump_m / lambda;
            let s = ssi(o.cn0_dbhz);
            let lli = if o.lock_lost { '1' } else { ' ' };
            let _ = writeln!(
                h,
                "{}{:02}{code:14.3} {s}{phase:14.3}{lli}{s}{:14.3} {s}{:14.3} {s}",
                o.sat.system.letter(),
                o.sat.number,
                o.doppler_hz,
                o.cn0_dbhz
            );
        }
    }
    Ok(h)
}

/// Writes `DIR/hybridnav.obs` and the navigation file the trial used (`DIR/hybridnav.nav`:
/// the embedded nominal constellation, or a copy of the world's file).
///
/// # Errors
/// No GNSS observations, or an unreadable navigation file.
pub fn write(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let obs = dir.join("hybridnav.obs");
    write_atomic(&obs, observation_text(world, rec)?.as_bytes()).map_err(|e| e.to_string())?;
    let nav = dir.join("hybridnav.nav");
    let bytes = if world.nav_source == BUILTIN_EPHEMERIS_NAME {
        BUILTIN_EPHEMERIS.as_bytes().to_vec()
    } else {
        crate::io::read::read_bytes(
            std::path::Path::new(&world.nav_source),
            crate::io::read::RINEX_NAV,
        )
        .map_err(|e| format!("cannot copy the navigation file {}: {e}", world.nav_source))?
    };
    write_atomic(&nav, &bytes).map_err(|e| e.to_string())?;
    Ok(vec![obs, nav])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signal_strength_indicator_follows_rinex() {
        // RINEX 3.04 §5.7: 1 below 12 dB-Hz, 9 at 54 and above, ⌊C/N0 / 6⌋ between.
        assert_eq!(ssi(5.0), 1);
        assert_eq!(ssi(44.9), 7);
        assert_eq!(ssi(48.0), 8);
        assert_eq!(ssi(60.0), 9);
    }

    #[test]
    fn header_lines_put_the_label_in_columns_61_to_80() {
        let mut s = String::new();
        header(&mut s, "DBHZ", "SIGNAL STRENGTH UNIT");
        assert_eq!(s.len(), 81);
        assert_eq!(&s[60..80], "SIGNAL STRENGTH UNIT");
    }
}
