//! Reader of RINEX navigation files: RINEX 2.xx GPS (`N`) files and RINEX 3.0x mixed or
//! single-system files (RINEX 3.05 specification, IGS/RTCM 2020, §5 and Tables A6–A14;
//! RINEX 2.11 specification, IGS 2007, Table A4).
//!
//! GPS (`G`) and BeiDou (`C`) records become [`Ephemeris`] values. Records of the other
//! systems (GLONASS `R`, Galileo `E`, QZSS `J`, SBAS `S`, NavIC `I`) are skipped and
//! counted per system letter; that is not an error, mixed files are the norm.
//!
//! Layout (0-based columns):
//!
//! ```text
//! RINEX 2   epoch line:  I2 PRN | 1X,I2.2 yy | 4×(1X,I2) mm dd hh mi | F5.1 ss | 3D19.12 from col 22
//!           orbit lines: 3X, 4D19.12 (fields at cols 3, 22, 41, 60)
//! RINEX 3   epoch line:  A1,I2.2 sat | 1X,I4 yyyy | 5×(1X,I2.2) mm dd hh mi ss | 3D19.12 from col 23
//!           orbit lines: 4X, 4D19.12 (fields at cols 4, 23, 42, 61)
//! ```
//!
//! GPS and BeiDou records have seven orbit lines. Epochs (toc) are in the system's own time
//! scale: GPST for GPS, BDT for BeiDou (converted here: GPST = BDT + 14 s). The week that
//! goes with toe is the continuous GPS week (RINEX 3) or BDT week in the record; in RINEX 2
//! files the week is derived from the epoch date, since some writers put it modulo 1024.
//!
//! Every malformed input gives a [`RinexError`] naming the file, the 1-based line and
//! what was expected; the reader never panics.

use crate::core::time::{NS_PER_S, SECONDS_PER_WEEK};
use crate::core::{EmitterId, GpsTime, System};
use crate::gnss::atmosphere::Klobuchar;
use crate::gnss::ephemeris::Ephemeris;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Default largest |t − toe| (s) at which a GPS ephemeris is selected: half of the 4 h
/// curve-fit interval centred on toe (IS-GPS-200 §20.3.4.4), RTKLIB's `MAXDTOE`. Beyond it
/// the orbit is an extrapolation, measured at 5.9 m RMS for 2–3 h and 23 m RMS (67 m max)
/// for 3–4 h against precise orbits (docs/validation.md).
pub const GPS_MAX_AGE_S: f64 = 2.0 * 3600.0;
/// Default largest |t − toe| (s) at which a BeiDou ephemeris is selected: BeiDou uploads
/// a new ephemeris every hour (BDS-SIS-ICD-B1I-3.0 §5.2.4.11, AODE), so a receiver
/// tracking the satellite never holds one more than 1 h from toe.
pub const BDS_MAX_AGE_S: f64 = 3600.0;
/// Gap (s) within which records of one satellite are compared with each other when
/// screening duplicates: two GPS fit intervals.
const NEIGHBOUR_SPAN_S: f64 = 4.0 * 3600.0;
/// Two records of different satellites whose orbits stay within this distance (m) of each
/// other over ±1 h are copies of one orbit: distinct GNSS satellites never fly in
/// formation (the closest slots of one plane are thousands of km apart), while two
/// issues of one satellite's ephemeris agree to metres.
const SAME_ORBIT_M: f64 = 1_000.0;
/// A record further than this (m) from its own satellite's neighbouring record, at its
/// toe, does not describe that satellite: consecutive issues agree within tens of metres
/// even 4 h from toe (23 m RMS, 67 m max measured, docs/validation.md), and a manoeuvre
/// moves a GPS satellite by far less in a few hours.
const OWN_ORBIT_M: f64 = 10_000.0;

/// The age limits of ephemeris selection: the largest |t − toe| (s) at which a record is
/// used, per system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaxAge {
    /// GPS limit (s).
    pub gps_s: f64,
    /// BeiDou limit (s).
    pub bds_s: f64,
}

impl Default for MaxAge {
    /// RTKLIB's 2 h for GPS ([`GPS_MAX_AGE_S`]) and 1 h for BeiDou ([`BDS_MAX_AGE_S`]).
    fn default() -> Self {
        Self {
            gps_s: GPS_MAX_AGE_S,
            bds_s: BDS_MAX_AGE_S,
        }
    }
}

impl MaxAge {
    /// The limit for one system, `None` for a system without broadcast ephemerides.
    pub fn of(&self, system: System) -> Option<f64> {
        match system {
            System::Gps => Some(self.gps_s),
            System::Bds => Some(self.bds_s),
            _ => None,
        }
    }

    /// Parses a command-line value: seconds for every system (`7200`), or per system
    /// (`gps=7200,bds=3600`; a system left out keeps its default). Each limit must be a
    /// positive number of seconds of at most a week.
    ///
    /// # Errors
    /// A message saying which part is wrong and what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let seconds = |v: &str| -> Result<f64, String> {
            let x: f64 = v.trim().parse().map_err(|_| {
                format!("expected seconds such as 7200 or gps=7200,bds=3600, found '{v}'")
            })?;
            if x.is_finite() && x > 0.0 && x <= SECONDS_PER_WEEK as f64 {
                Ok(x)
            } else {
                Err(format!(
                    "expected a positive number of seconds up to a week (604800), found {x}"
                ))
            }
        };
        if !text.contains('=') {
            let s = seconds(text)?;
            return Ok(Self { gps_s: s, bds_s: s });
        }
        let mut out = Self::default();
        for part in text.split(',') {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("expected SYSTEM=SECONDS, found '{part}'"))?;
            match k.trim().to_ascii_lowercase().as_str() {
                "gps" | "g" => out.gps_s = seconds(v)?,
                "bds" | "c" => out.bds_s = seconds(v)?,
                other => return Err(format!("unknown system '{other}': expected gps or bds")),
            }
        }
        Ok(out)
    }
}

/// A record the reader read but does not use, and why: its elements are out of the
/// range a broadcast message can carry, or its orbit is another satellite's.
#[derive(Clone, Debug, PartialEq)]
pub struct DroppedRecord {
    /// The file the record came from.
    pub file: String,
    /// The 1-based line of the record's first line, when known.
    pub line: Option<usize>,
    /// The satellite the record claims to be.
    pub sat: EmitterId,
    /// The record's toe.
    pub toe: GpsTime,
    /// Why it was dropped.
    pub reason: String,
}

impl std::fmt::Display for DroppedRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}, line {l}: ", self.file)?,
            None => write!(f, "{}: ", self.file)?,
        }
        write!(
            f,
            "{} record with toe {} dropped: {}",
            self.sat, self.toe, self.reason
        )
    }
}

/// A failure to read a navigation file. Every variant names the file and, where the
/// problem is in the text, the 1-based line number and what was expected there.
#[derive(Debug, thiserror::Error)]
pub enum RinexError {
    /// The file could not be read at all.
    #[error("{file}: cannot read the file: {io}")]
    Io {
        file: String,
        /// Carried in the message rather than as the error's source, so that a chain
        /// printer (`{:#}`) shows the OS error once.
        io: std::io::Error,
    },
    /// A line or field does not hold what the format requires.
    #[error("{file}, line {line}: expected {expected}, found {found}")]
    Syntax {
        file: String,
        line: usize,
        expected: String,
        found: String,
    },
    /// A record ends before all its lines were read.
    #[error("{file}, line {line}: truncated {sat} record: expected {expected}, found {found}")]
    Truncated {
        file: String,
        line: usize,
        sat: String,
        expected: String,
        found: String,
    },
    /// The RINEX version is not one this reader knows.
    #[error("{file}, line {line}: unsupported RINEX version '{version}': expected 2.xx or 3.0x")]
    UnsupportedVersion {
        file: String,
        line: usize,
        version: String,
    },
    /// The file is RINEX, but not navigation data.
    #[error(
        "{file}, line {line}: not a navigation file: expected file type 'N' (navigation data) in column 21 \
         of the RINEX VERSION / TYPE line, found '{found}'"
    )]
    WrongFileType {
        file: String,
        line: usize,
        found: String,
    },
}

impl RinexError {
    /// The file the error is about.
    pub fn file(&self) -> &str {
        match self {
            RinexError::Io { file, .. }
            | RinexError::Syntax { file, .. }
            | RinexError::Truncated { file, .. }
            | RinexError::UnsupportedVersion { file, .. }
            | RinexError::WrongFileType { file, .. } => file,
        }
    }

    /// The 1-based line number, when the error is about the file's content.
    pub fn line(&self) -> Option<usize> {
        match self {
            RinexError::Io { .. } => None,
            RinexError::Syntax { line, .. }
            | RinexError::Truncated { line, .. }
            | RinexError::UnsupportedVersion { line, .. }
            | RinexError::WrongFileType { line, .. } => Some(*line),
        }
    }
}

/// The content of a navigation file that hybridnav uses.
///
/// Invariant: `ephemerides` is sorted by (satellite, toe, transmit time), which
/// [`NavData::select`] relies on for its binary search. [`parse_nav`], [`NavData::new`]
/// and [`crate::gnss::synth::synth_nav`] guarantee it; call [`NavData::sort`] after editing
/// the vector by hand.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NavData {
    /// GPS and BeiDou ephemerides, sorted by (satellite, toe, transmit time).
    pub ephemerides: Vec<Ephemeris>,
    /// The GPS Klobuchar coefficients from the header, when both α and β are present.
    pub klobuchar: Option<Klobuchar>,
    /// The BeiDou Klobuchar coefficients from a RINEX 3 header (`IONOSPHERIC CORR` lines
    /// `BDSA` and `BDSB`), when both are present: the α/β that BDS broadcasts in D1
    /// subframe 1 and D2 subframe 1 page 2 (BDS-SIS-ICD-B1I-3.0 §5.2.4.7), for its own
    /// model (geographic latitude, delay on B1I). Only the signal level uses them (they
    /// are sent in the generated D1/D2 messages); the measurement model's ionosphere is
    /// the GPS set's. When a header carries several `BDSA` (or `BDSB`) lines, as RINEX
    /// 3.04 allows for sets of different transmission times and satellites, the last one
    /// is kept, as for `GPSA`/`GPSB`.
    pub klobuchar_bds: Option<Klobuchar>,
    /// GPST − UTC leap seconds from the header.
    pub leap_seconds: Option<i32>,
    /// The rest of a RINEX 3 `LEAP SECONDS` line when it has it: the future or past leap
    /// seconds ΔtLSF, its week WN_LSF and day DN, and whether the line's values are in BDS
    /// time (its time-system field `BDS`) rather than GPS's.
    pub leap_announcement: Option<LeapAnnouncement>,
    /// The `TIME SYSTEM CORR` lines of a RINEX 3 header (GPUT, GAUT, BDUT, GLUT, GAGP, …),
    /// in file order; the D1 message's time offsets are derived from them
    /// ([`crate::gnss::signal::d1d2::BdsTimeParams`]).
    pub time_corr: Vec<TimeSystemCorr>,
    /// Number of records skipped per system letter (systems other than G and C).
    pub skipped: BTreeMap<char, usize>,
    /// GPS and BeiDou records read but not used (implausible elements, an orbit that is
    /// another satellite's); callers show them as warnings.
    pub dropped: Vec<DroppedRecord>,
    /// The age limits [`NavData::select`] applies.
    pub max_age: MaxAge,
}

/// One `TIME SYSTEM CORR` line (RINEX 3.05 §5.2 and Table A5): the correction
/// `CORR(t) = a0 + a1·(t − t_ref)` (s) between two time systems, beyond their whole-second
/// offset. For `xxUT` lines it is the system's time minus UTC beyond the leap seconds
/// (`GPUT`: GPST − UTC(USNO) − ΔtLS; `GLUT`: a0 = −τ_C, the GLONASS time correction);
/// for `GAGP` it is GST − GPST.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeSystemCorr {
    /// The four-letter type, e.g. `GPUT`.
    pub code: String,
    pub a0_s: f64,
    pub a1_s_per_s: f64,
    /// Reference time: seconds into week `ref_week` of the line's own system (BDT weeks for
    /// `BDUT`, GPS weeks otherwise; both zero for `GLUT`, whose a1 is zero).
    pub ref_sow_s: f64,
    pub ref_week: i64,
}

impl TimeSystemCorr {
    /// The reference time as a [`GpsTime`] (`None` for a line without one).
    pub fn reference(&self) -> Option<GpsTime> {
        if self.ref_week == 0 && self.ref_sow_s == 0.0 {
            return None;
        }
        Some(if self.code.starts_with("BD") {
            GpsTime::from_bdt_week_sow(self.ref_week, self.ref_sow_s)
        } else {
            GpsTime::from_week_tow(self.ref_week, self.ref_sow_s)
        })
    }

    /// `CORR(t)` (s).
    pub fn at(&self, t: GpsTime) -> f64 {
        self.a0_s
            + self
                .reference()
                .map_or(0.0, |r| self.a1_s_per_s * t.seconds_since(r))
    }
}

/// A leap second announced (or past) in a RINEX 3 `LEAP SECONDS` line (RINEX 3.05 Table
/// A5): ΔtLSF, WN_LSF and DN as the line gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LeapAnnouncement {
    /// ΔtLSF (s).
    pub future_s: i32,
    /// WN_LSF: a continuous week number (GPS weeks, or BDT weeks when `bds`).
    pub week: i64,
    /// DN: day of the week (1–7 in GPS's numbering, 0–6 in BDS's).
    pub day: i64,
    /// The line's values are BDS's (time-system field `BDS`).
    pub bds: bool,
}

/// Reads a navigation file from disk; see [`parse_nav`].
///
/// # Errors
/// [`RinexError::Io`] when the file cannot be read or is not UTF-8 text, otherwise as
/// [`parse_nav`].
pub fn read_nav_file(path: &Path) -> Result<NavData, RinexError> {
    let file = path.display().to_string();
    let bytes = crate::io::read::read_bytes(path, crate::io::read::RINEX_NAV).map_err(|io| {
        RinexError::Io {
            file: file.clone(),
            io,
        }
    })?;
    // RINEX is ASCII; bytes beyond it are replaced rather than rejected so that a stray
    // byte in a comment does not make a whole file unreadable. A replaced byte inside a
    // data field still fails that field's parse with a line number.
    let text = String::from_utf8_lossy(&bytes);
    parse_nav(&text, &file)
}

/// The fields of a header.
struct Header {
    version: f64,
    file_type: char,
    klobuchar: Option<Klobuchar>,
    klobuchar_bds: Option<Klobuchar>,
    leap_seconds: Option<i32>,
    leap_announcement: Option<LeapAnnouncement>,
    time_corr: Vec<TimeSystemCorr>,
    /// Index (0-based) of the first body line.
    body_start: usize,
}

/// A line-oriented cursor that knows the file name for error messages.
struct Ctx<'a> {
    file: &'a str,
}

impl Ctx<'_> {
    fn syntax(
        &self,
        line_idx: usize,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> RinexError {
        RinexError::Syntax {
            file: self.file.to_string(),
            line: line_idx + 1,
            expected: expected.into(),
            found: found.into(),
        }
    }
}

/// Quotes a piece of text for an error message, shortened to 40 characters (trailing
/// blanks dropped; the observation reader also drops leading ones).
pub(crate) fn quote(s: &str) -> String {
    let t = s.trim_end();
    if t.is_empty() {
        return "a blank field".to_string();
    }
    let short: String = t.chars().take(40).collect();
    if short.len() < t.len() {
        format!("'{short}…'")
    } else {
        format!("'{short}'")
    }
}

/// Columns `start..end` of a line, shortened when the line is shorter (RINEX writers
/// often drop trailing blanks). `None` when the cut would split a non-ASCII character.
fn cols(line: &str, start: usize, end: usize) -> Option<&str> {
    let end = end.min(line.len());
    if start >= end {
        return Some("");
    }
    line.get(start..end)
}

/// Parses a Fortran real (`D` or `E` exponent). `Ok(None)` for a blank field; `Err` with
/// the offending text for anything that is not a finite number. Allocates only for a `D`
/// exponent or an error (the observation reader calls it for every value).
pub(crate) fn parse_fortran_f64(field: &str) -> Result<Option<f64>, String> {
    let t = field.trim();
    if t.is_empty() {
        return Ok(None);
    }
    // Rust accepts "inf" and "NaN", which are never valid RINEX numbers.
    if t.bytes()
        .any(|b| b.is_ascii_alphabetic() && !matches!(b, b'E' | b'e' | b'D' | b'd'))
    {
        return Err(t.to_string());
    }
    let parsed = if t.bytes().any(|b| b == b'D' || b == b'd') {
        t.replace(['D', 'd'], "E").parse::<f64>()
    } else {
        t.parse::<f64>()
    };
    match parsed {
        Ok(v) if v.is_finite() => Ok(Some(v)),
        _ => Err(t.to_string()),
    }
}

/// Days from 1970-01-01 to the given proleptic Gregorian date (Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The date (y, m, d) of a day count from 1970-01-01 (inverse of [`days_from_civil`]).
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Days from 1970-01-01 to the GPS epoch 1980-01-06.
const GPS_EPOCH_DAYS: i64 = 3657;

fn is_leap_year(y: i64) -> bool {
    (y % 4 == 0 && y % 100 != 0) || y % 400 == 0
}

fn days_in_month(y: i64, m: i64) -> i64 {
    match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if is_leap_year(y) => 29,
        _ => 28,
    }
}

/// A GPS time from a calendar date read in the GPS time scale (which has no leap
/// seconds, so the conversion is pure day counting). `None` when any field is out of
/// range (years 1980–2200, seconds 0 ≤ s < 61), which callers turn into a parse error.
pub(crate) fn gpst_from_calendar(
    y: i64,
    mo: i64,
    d: i64,
    h: i64,
    mi: i64,
    sec: f64,
) -> Option<GpsTime> {
    if !(1980..=2200).contains(&y)
        || !(1..=12).contains(&mo)
        || d < 1
        || d > days_in_month(y, mo)
        || !(0..24).contains(&h)
        || !(0..60).contains(&mi)
        || !(0.0..61.0).contains(&sec)
    {
        return None;
    }
    let days = days_from_civil(y, mo, d) - GPS_EPOCH_DAYS;
    let whole_s = (days * 86_400 + h * 3600 + mi * 60) * NS_PER_S;
    let ns = whole_s + (sec * 1e9).round() as i64;
    if ns < 0 {
        return None;
    }
    Some(GpsTime::from_ns(ns))
}

/// The calendar reading (y, mo, d, h, mi, s, ns) of a time in the GPS time scale.
pub(crate) fn gpst_calendar(t: GpsTime) -> (i64, i64, i64, i64, i64, i64, i64) {
    let ns = t.ns();
    let secs = ns.div_euclid(NS_PER_S);
    let frac = ns.rem_euclid(NS_PER_S);
    let days = secs.div_euclid(86_400);
    let sod = secs.rem_euclid(86_400);
    let (y, mo, d) = civil_from_days(days + GPS_EPOCH_DAYS);
    (y, mo, d, sod / 3600, (sod / 60) % 60, sod % 60, frac)
}

/// The instant with seconds-of-week `sow` (in a week starting at `week_start`) nearest to
/// `reference`: used where a week number is absent, ambiguous, or modulo 1024.
fn nearest_sow(reference: GpsTime, week_start_offset_ns: i64, sow_s: f64) -> GpsTime {
    let week_ns = SECONDS_PER_WEEK * NS_PER_S;
    // Week boundaries of the broadcast system: GPST for GPS, GPST + 14 s for BDT.
    let shifted = reference.ns() - week_start_offset_ns;
    let week = shifted.div_euclid(week_ns);
    let sow_ns = (sow_s * 1e9).round() as i64;
    let mut best = week * week_ns + sow_ns;
    let diff = best - shifted;
    if diff > week_ns / 2 {
        best -= week_ns;
    } else if diff < -week_ns / 2 {
        best += week_ns;
    }
    GpsTime::from_ns(best + week_start_offset_ns)
}

/// Offset of the BDT week start from the GPS week start (ns): BDT = GPST − 14 s, so BDT
/// weeks begin 14 s later in GPS time.
const BDT_WEEK_OFFSET_NS: i64 = 14 * NS_PER_S;

/// Parses the text of a RINEX 2 or 3 navigation file. `file_name` is only used in error
/// messages.
///
/// # Errors
/// A [`RinexError`] naming the file, the 1-based line and what was expected, for: an
/// empty file or missing `RINEX VERSION / TYPE`; a non-navigation file type; a version
/// other than 2.xx or 3.0x; a header without `END OF HEADER`; an unparsable header value;
/// an invalid epoch, satellite id or number in a GPS or BeiDou record; a record with fewer
/// than seven orbit lines; an eccentricity outside [0, 1) or √A ≤ 0.
pub fn parse_nav(text: &str, file_name: &str) -> Result<NavData, RinexError> {
    let ctx = Ctx { file: file_name };
    let lines: Vec<&str> = text.lines().collect();
    let header = parse_header(&ctx, &lines)?;
    let mut nav = NavData {
        klobuchar: header.klobuchar,
        klobuchar_bds: header.klobuchar_bds,
        leap_seconds: header.leap_seconds,
        leap_announcement: header.leap_announcement,
        time_corr: header.time_corr.clone(),
        ..NavData::default()
    };
    let dialect = if header.version < 3.0 {
        &RINEX_2
    } else {
        &RINEX_3
    };
    let mut record_lines = Vec::new();
    parse_body(&ctx, &lines, &header, &mut nav, &mut record_lines, dialect)?;
    let records = std::mem::take(&mut nav.ephemerides)
        .into_iter()
        .zip(record_lines.into_iter().map(Some))
        .collect();
    let (kept, dropped) = screen(records, file_name);
    nav.ephemerides = kept;
    nav.dropped = dropped;
    nav.sort();
    Ok(nav)
}

fn parse_header(ctx: &Ctx<'_>, lines: &[&str]) -> Result<Header, RinexError> {
    let first = match lines.first() {
        Some(l) => *l,
        None => return Err(ctx.syntax(0, "a 'RINEX VERSION / TYPE' header line", "an empty file")),
    };
    if cols(first, 60, 80).map(str::trim) != Some("RINEX VERSION / TYPE") {
        return Err(ctx.syntax(
            0,
            "a 'RINEX VERSION / TYPE' header line (label in columns 61-80)",
            quote(first),
        ));
    }
    let version_text = cols(first, 0, 9).unwrap_or("").trim();
    let version: f64 = version_text
        .parse()
        .map_err(|_| RinexError::UnsupportedVersion {
            file: ctx.file.to_string(),
            line: 1,
            version: version_text.to_string(),
        })?;
    if !(2.0..3.1).contains(&version) {
        return Err(RinexError::UnsupportedVersion {
            file: ctx.file.to_string(),
            line: 1,
            version: version_text.to_string(),
        });
    }
    let file_type = cols(first, 20, 21)
        .and_then(|s| s.chars().next())
        .unwrap_or(' ');
    let known_v2_other = version < 3.0 && (file_type == 'G' || file_type == 'H');
    if file_type != 'N' && !known_v2_other {
        let what = cols(first, 20, 40).unwrap_or("").trim();
        return Err(RinexError::WrongFileType {
            file: ctx.file.to_string(),
            line: 1,
            found: what.to_string(),
        });
    }

    let mut alpha: Option<[f64; 4]> = None;
    let mut beta: Option<[f64; 4]> = None;
    let mut alpha_bds: Option<[f64; 4]> = None;
    let mut beta_bds: Option<[f64; 4]> = None;
    let mut leap_seconds = None;
    let mut leap_announcement = None;
    let mut time_corr = Vec::new();
    for (idx, line) in lines.iter().enumerate().skip(1) {
        let label = cols(line, 60, 80).unwrap_or("").trim();
        match label {
            "END OF HEADER" => {
                let klobuchar = match (alpha, beta) {
                    (Some(alpha), Some(beta)) => Some(Klobuchar { alpha, beta }),
                    _ => None,
                };
                let klobuchar_bds = match (alpha_bds, beta_bds) {
                    (Some(alpha), Some(beta)) => Some(Klobuchar { alpha, beta }),
                    _ => None,
                };
                return Ok(Header {
                    version,
                    file_type,
                    klobuchar,
                    klobuchar_bds,
                    leap_seconds,
                    leap_announcement,
                    time_corr,
                    body_start: idx + 1,
                });
            }
            "ION ALPHA" => alpha = Some(header_coefficients(ctx, idx, line, 2)?),
            "ION BETA" => beta = Some(header_coefficients(ctx, idx, line, 2)?),
            "IONOSPHERIC CORR" => match cols(line, 0, 4).unwrap_or("") {
                "GPSA" => alpha = Some(header_coefficients(ctx, idx, line, 5)?),
                "GPSB" => beta = Some(header_coefficients(ctx, idx, line, 5)?),
                "BDSA" => alpha_bds = Some(header_coefficients(ctx, idx, line, 5)?),
                "BDSB" => beta_bds = Some(header_coefficients(ctx, idx, line, 5)?),
                // Galileo NeQuick (GAL), QZSS and NavIC sets are not used by this
                // simulator.
                _ => {}
            },
            "LEAP SECONDS" => {
                let field = cols(line, 0, 6).unwrap_or("");
                let v: i32 = field.trim().parse().map_err(|_| {
                    ctx.syntax(
                        idx,
                        "the number of leap seconds (integer, columns 1-6)",
                        quote(field),
                    )
                })?;
                leap_seconds = Some(v);
                if version >= 3.0 {
                    leap_announcement = leap_line_rest(ctx, idx, line)?;
                }
            }
            "TIME SYSTEM CORR" => time_corr.push(time_system_corr(ctx, idx, line)?),
            _ => {}
        }
    }
    Err(ctx.syntax(lines.len(), "an 'END OF HEADER' line", "end of file"))
}

/// The optional ΔtLSF, WN_LSF, DN (I6 each, columns 7–24) and time system (columns 25–27)
/// of a RINEX 3 `LEAP SECONDS` line: `None` when the three numbers are blank, an error
/// naming the line when only some are there or one is not an integer.
fn leap_line_rest(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
) -> Result<Option<LeapAnnouncement>, RinexError> {
    let fields: Vec<&str> = (0..3)
        .map(|k| cols(line, 6 + 6 * k, 12 + 6 * k).unwrap_or("").trim())
        .collect();
    if fields.iter().all(|f| f.is_empty()) {
        return Ok(None);
    }
    let names = ["ΔtLSF", "WN_LSF", "DN"];
    let mut v = [0i64; 3];
    for (k, (f, name)) in fields.iter().zip(names).enumerate() {
        v[k] = f.parse().map_err(|_| {
            ctx.syntax(
                idx,
                format!(
                    "{name} (integer, columns {}-{}) after the leap seconds",
                    7 + 6 * k,
                    12 + 6 * k
                ),
                quote(f),
            )
        })?;
    }
    let system = cols(line, 24, 27).unwrap_or("").trim();
    Ok(Some(LeapAnnouncement {
        future_s: v[0] as i32,
        week: v[1],
        day: v[2],
        bds: system == "BDS",
    }))
}

/// A RINEX 3 `TIME SYSTEM CORR` line: A4 type, D17.10 a0 (columns 6–22), D16.9 a1
/// (23–38), I7 reference seconds (39–45), I5 reference week (46–50); blank reference
/// fields read as 0 (no reference).
fn time_system_corr(ctx: &Ctx<'_>, idx: usize, line: &str) -> Result<TimeSystemCorr, RinexError> {
    let code = cols(line, 0, 4).unwrap_or("").trim().to_string();
    if code.len() != 4 || !code.chars().all(|c| c.is_ascii_uppercase()) {
        return Err(ctx.syntax(
            idx,
            "a time system correction type such as GPUT or BDUT (columns 1-4)",
            quote(cols(line, 0, 4).unwrap_or(line)),
        ));
    }
    let number = |a: usize, b: usize, what: &str| -> Result<f64, RinexError> {
        let field = cols(line, a, b).unwrap_or("");
        match parse_fortran_f64(field) {
            Ok(Some(x)) => Ok(x),
            _ => Err(ctx.syntax(
                idx,
                format!("{what} of {code} (a number in columns {}-{b})", a + 1),
                quote(field),
            )),
        }
    };
    let a0_s = number(5, 22, "a0")?;
    let a1_s_per_s = number(22, 38, "a1")?;
    // Blank reference fields (GNSS-SDR 0.0.17 writes its BDUT line so) mean no reference
    // time: the line's a1 is then not applied.
    let integer = |a: usize, b: usize, what: &str| -> Result<i64, RinexError> {
        let field = cols(line, a, b).unwrap_or("").trim();
        if field.is_empty() {
            return Ok(0);
        }
        field.parse().map_err(|_| {
            ctx.syntax(
                idx,
                format!("{what} of {code} (an integer in columns {}-{b})", a + 1),
                quote(field),
            )
        })
    };
    let ref_sow_s = integer(38, 45, "the reference time")? as f64;
    let ref_week = integer(45, 50, "the reference week")?;
    Ok(TimeSystemCorr {
        code,
        a0_s,
        a1_s_per_s,
        ref_sow_s,
        ref_week,
    })
}

/// Four D12.4 coefficients starting at column `start`.
fn header_coefficients(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    start: usize,
) -> Result<[f64; 4], RinexError> {
    let mut out = [0.0; 4];
    for (k, v) in out.iter_mut().enumerate() {
        let (a, b) = (start + 12 * k, start + 12 * (k + 1));
        let field = cols(line, a, b).ok_or_else(|| ctx.syntax(idx, "ASCII text", quote(line)))?;
        *v = match parse_fortran_f64(field) {
            Ok(Some(x)) => x,
            _ => {
                return Err(ctx.syntax(
                    idx,
                    format!(
                        "ionospheric coefficient {} of 4 (a number in columns {}-{})",
                        k + 1,
                        a + 1,
                        b
                    ),
                    quote(field),
                ))
            }
        };
    }
    Ok(out)
}

/// True for a blank line (tolerated between records and at the end of a file).
fn is_blank(line: &str) -> bool {
    line.trim().is_empty()
}

/// True when a RINEX 2 line starts a record: the PRN occupies columns 1-2, whereas orbit
/// lines begin with three blanks.
fn v2_record_start(line: &str) -> bool {
    !is_blank(line) && cols(line, 0, 2).is_some_and(|s| !s.trim().is_empty())
}

/// True when a RINEX 3 line starts a record: a system letter in column 1.
fn v3_record_start(line: &str) -> bool {
    line.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
}

/// The 7 orbit lines' 4 fields each plus the epoch line's 3 clock fields of one record,
/// blank fields as `None`, with the line index of every field for error messages.
struct RawRecord {
    sat: EmitterId,
    clock: [Option<f64>; 3],
    orbit: [[Option<f64>; 4]; 7],
    orbit_line: [usize; 7],
}

/// Meaning of the orbit fields, for messages: [line][field].
const GPS_FIELD_NAMES: [[&str; 4]; 7] = [
    ["IODE", "Crs", "Delta n", "M0"],
    ["Cuc", "e (eccentricity)", "Cus", "sqrt(A)"],
    ["Toe (seconds of GPS week)", "Cic", "OMEGA0", "Cis"],
    ["i0", "Crc", "omega", "OMEGA DOT"],
    ["IDOT", "codes on L2", "GPS week", "L2 P data flag"],
    ["SV accuracy", "SV health", "TGD", "IODC"],
    [
        "transmission time of message",
        "fit interval",
        "spare",
        "spare",
    ],
];
const BDS_FIELD_NAMES: [[&str; 4]; 7] = [
    ["AODE", "Crs", "Delta n", "M0"],
    ["Cuc", "e (eccentricity)", "Cus", "sqrt(A)"],
    ["Toe (seconds of BDT week)", "Cic", "OMEGA0", "Cis"],
    ["i0", "Crc", "omega", "OMEGA DOT"],
    ["IDOT", "spare", "BDT week", "spare"],
    ["SV accuracy", "SatH1", "TGD1", "TGD2"],
    ["transmission time of message", "AODC", "spare", "spare"],
];

/// Which orbit fields may be blank (and then read as 0): spares, flags, the fit interval
/// and the issue-of-data counters that some writers leave out. Everything that enters the
/// orbit or clock computation is required.
const OPTIONAL_FIELDS: [[bool; 4]; 7] = [
    [true, false, false, false],
    [false, false, false, false],
    [false, false, false, false],
    [false, false, false, false],
    [false, true, true, true],
    [true, false, true, true],
    [true, true, true, true],
];

/// Reads the 4 fields of an orbit line at the given columns.
fn orbit_fields(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    first_col: usize,
    sat: EmitterId,
) -> Result<[Option<f64>; 4], RinexError> {
    let mut out = [None; 4];
    for (k, v) in out.iter_mut().enumerate() {
        let (a, b) = (first_col + 19 * k, first_col + 19 * (k + 1));
        let field = cols(line, a, b)
            .ok_or_else(|| ctx.syntax(idx, format!("ASCII text in a {sat} record"), quote(line)))?;
        *v = parse_fortran_f64(field).map_err(|bad| {
            ctx.syntax(
                idx,
                format!(
                    "a number (D19.12) in columns {}-{} of a {sat} record",
                    a + 1,
                    b
                ),
                quote(&bad),
            )
        })?;
    }
    Ok(out)
}

/// The three clock fields of an epoch line starting at `first_col`.
fn clock_fields(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    first_col: usize,
    sat: EmitterId,
) -> Result<[Option<f64>; 3], RinexError> {
    let mut out = [None; 3];
    let names = [
        "af0 (SV clock bias)",
        "af1 (SV clock drift)",
        "af2 (SV clock drift rate)",
    ];
    for (k, v) in out.iter_mut().enumerate() {
        let (a, b) = (first_col + 19 * k, first_col + 19 * (k + 1));
        let field = cols(line, a, b)
            .ok_or_else(|| ctx.syntax(idx, format!("ASCII text in a {sat} record"), quote(line)))?;
        match parse_fortran_f64(field) {
            Ok(Some(x)) => *v = Some(x),
            _ => {
                return Err(ctx.syntax(
                    idx,
                    format!("{} of {sat}: a number in columns {}-{}", names[k], a + 1, b),
                    quote(field),
                ))
            }
        }
    }
    Ok(out)
}

/// Reads an integer field of an epoch line.
fn int_field(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    a: usize,
    b: usize,
    what: &str,
) -> Result<i64, RinexError> {
    let field = cols(line, a, b).unwrap_or("");
    field.trim().parse::<i64>().map_err(|_| {
        ctx.syntax(
            idx,
            format!("{what} (integer in columns {}-{})", a + 1, b),
            quote(field),
        )
    })
}

/// The 7×4 orbit fields of a record and the line index of each orbit line.
type OrbitLines = ([[Option<f64>; 4]; 7], [usize; 7]);

/// Collects the 7 orbit lines following the epoch line at `idx`.
fn collect_orbit_lines(
    ctx: &Ctx<'_>,
    lines: &[&str],
    idx: usize,
    sat: EmitterId,
    first_col: usize,
    is_record_start: fn(&str) -> bool,
) -> Result<OrbitLines, RinexError> {
    let mut orbit = [[None; 4]; 7];
    let mut orbit_line = [0usize; 7];
    for k in 0..7 {
        let li = idx + 1 + k;
        let expected = format!("broadcast orbit line {} of 7", k + 1);
        let line = match lines.get(li) {
            Some(l) => *l,
            None => {
                return Err(RinexError::Truncated {
                    file: ctx.file.to_string(),
                    line: li + 1,
                    sat: sat.to_string(),
                    expected,
                    found: "end of file".into(),
                })
            }
        };
        if is_blank(line) || is_record_start(line) {
            return Err(RinexError::Truncated {
                file: ctx.file.to_string(),
                line: li + 1,
                sat: sat.to_string(),
                expected,
                found: if is_blank(line) {
                    "a blank line".into()
                } else {
                    format!("the start of another record {}", quote(line))
                },
            });
        }
        orbit[k] = orbit_fields(ctx, li, line, first_col, sat)?;
        orbit_line[k] = li;
    }
    Ok((orbit, orbit_line))
}

/// Index of the line after a skipped record starting at `idx`: all following lines up
/// to the next record start.
fn skip_record(lines: &[&str], idx: usize, is_record_start: fn(&str) -> bool) -> usize {
    let mut j = idx + 1;
    while j < lines.len() && !is_record_start(lines[j]) && !is_blank(lines[j]) {
        j += 1;
    }
    j
}

/// How one RINEX version lays out a record: what starts one, where its clock fields
/// begin, how far its orbit lines are indented, and how its first line names the
/// satellite and the epoch. The record loop ([`parse_body`]) is shared.
struct Dialect {
    is_record_start: fn(&str) -> bool,
    /// What the loop expected when a line does not start a record.
    record_start_expected: &'static str,
    /// Column (0-based) of the first of the three clock fields on the epoch line.
    clock_col: usize,
    /// Columns of indentation before an orbit line's first field.
    orbit_indent: usize,
    /// RINEX 3 (whose records carry the system letter and whose BeiDou epochs are BDT).
    v3: bool,
    /// Reads the satellite and the epoch (GPST) of a record's first line, or the system
    /// letter of a record this reader skips.
    first_line: fn(&Ctx<'_>, usize, &str, &Header) -> Result<FirstLine, RinexError>,
}

/// What a record's first line says.
enum FirstLine {
    /// A GPS or BeiDou record: its satellite and its time of clock (GPST).
    Record { sat: EmitterId, toc: GpsTime },
    /// A record of a system hybridnav does not use, by its RINEX letter.
    Skip(char),
}

const RINEX_2: Dialect = Dialect {
    is_record_start: v2_record_start,
    record_start_expected: "the first line of a record (PRN in columns 1-2, then the epoch)",
    clock_col: 22,
    orbit_indent: 3,
    v3: false,
    first_line: v2_first_line,
};

const RINEX_3: Dialect = Dialect {
    is_record_start: v3_record_start,
    record_start_expected:
        "the first line of a record (satellite id such as G05 or C01 in columns 1-3)",
    clock_col: 23,
    orbit_indent: 4,
    v3: true,
    first_line: v3_first_line,
};

/// The record loop of both versions: blank lines skipped, each record's first line read
/// by the dialect, then its clock fields, its 7 orbit lines and the check that a new
/// record (or the end) follows them.
fn parse_body(
    ctx: &Ctx<'_>,
    lines: &[&str],
    header: &Header,
    nav: &mut NavData,
    record_lines: &mut Vec<usize>,
    dialect: &Dialect,
) -> Result<(), RinexError> {
    let mut idx = header.body_start;
    while idx < lines.len() {
        let line = lines[idx];
        if is_blank(line) {
            idx += 1;
            continue;
        }
        if !(dialect.is_record_start)(line) {
            return Err(ctx.syntax(idx, dialect.record_start_expected, quote(line)));
        }
        let (sat, toc) = match (dialect.first_line)(ctx, idx, line, header)? {
            FirstLine::Skip(letter) => {
                *nav.skipped.entry(letter).or_insert(0) += 1;
                idx = skip_record(lines, idx, dialect.is_record_start);
                continue;
            }
            FirstLine::Record { sat, toc } => (sat, toc),
        };
        let clock = clock_fields(ctx, idx, line, dialect.clock_col, sat)?;
        let (orbit, orbit_line) = collect_orbit_lines(
            ctx,
            lines,
            idx,
            sat,
            dialect.orbit_indent,
            dialect.is_record_start,
        )?;
        let raw = RawRecord {
            sat,
            clock,
            orbit,
            orbit_line,
        };
        nav.ephemerides
            .push(build_ephemeris(ctx, &raw, toc, dialect.v3)?);
        record_lines.push(idx + 1);
        idx += 8;
        if let Some(next) = lines.get(idx) {
            if !is_blank(next) && !(dialect.is_record_start)(next) {
                return Err(ctx.syntax(
                    idx,
                    format!("a new record after the 7 orbit lines of {sat}"),
                    quote(next),
                ));
            }
        }
    }
    Ok(())
}

/// A RINEX 2 record's first line: the PRN (columns 1-2) and the epoch with a two-digit
/// year. GLONASS ('G') and SBAS ('H') navigation files are skipped whole.
fn v2_first_line(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    header: &Header,
) -> Result<FirstLine, RinexError> {
    if header.file_type != 'N' {
        return Ok(FirstLine::Skip(if header.file_type == 'G' {
            'R'
        } else {
            'S'
        }));
    }
    let prn = int_field(ctx, idx, line, 0, 2, "the satellite PRN")?;
    if !(1..=99).contains(&prn) {
        return Err(ctx.syntax(
            idx,
            "a PRN 1-99 in columns 1-2",
            quote(cols(line, 0, 2).unwrap_or("")),
        ));
    }
    let sat = EmitterId::new(System::Gps, prn as u16);
    let yy = int_field(ctx, idx, line, 2, 5, "the two-digit year")?;
    // RINEX 2 years: 80–99 are 1980–1999, 00–79 are 2000–2079.
    let year = match yy {
        0..=79 => 2000 + yy,
        80..=99 => 1900 + yy,
        _ => {
            return Err(ctx.syntax(
                idx,
                "a two-digit year 00-99 in columns 4-5",
                quote(cols(line, 2, 5).unwrap_or("")),
            ))
        }
    };
    let mo = int_field(ctx, idx, line, 5, 8, "the month")?;
    let d = int_field(ctx, idx, line, 8, 11, "the day")?;
    let h = int_field(ctx, idx, line, 11, 14, "the hour")?;
    let mi = int_field(ctx, idx, line, 14, 17, "the minute")?;
    let sec_field = cols(line, 17, 22).unwrap_or("");
    let sec = parse_fortran_f64(sec_field).ok().flatten().ok_or_else(|| {
        ctx.syntax(
            idx,
            "the seconds of the epoch (F5.1 in columns 18-22)",
            quote(sec_field),
        )
    })?;
    let toc = gpst_from_calendar(year, mo, d, h, mi, sec).ok_or_else(|| {
        ctx.syntax(
            idx,
            format!("a valid epoch date and time for {sat}"),
            quote(cols(line, 2, 22).unwrap_or("")),
        )
    })?;
    Ok(FirstLine::Record { sat, toc })
}

/// A RINEX 3 record's first line: the satellite id (system letter and number) and the
/// epoch, in BDT for BeiDou. Systems other than GPS and BeiDou are skipped.
fn v3_first_line(
    ctx: &Ctx<'_>,
    idx: usize,
    line: &str,
    _header: &Header,
) -> Result<FirstLine, RinexError> {
    let letter = line.chars().next().unwrap_or(' ');
    let system = match letter {
        'G' => System::Gps,
        'C' => System::Bds,
        'R' | 'E' | 'J' | 'S' | 'I' => return Ok(FirstLine::Skip(letter)),
        _ => {
            return Err(ctx.syntax(
                idx,
                "a satellite system letter G, R, E, C, J, S or I in column 1",
                quote(line),
            ));
        }
    };
    let prn_field = cols(line, 1, 3).unwrap_or("");
    let prn: u16 = match prn_field.trim().parse() {
        Ok(p) if (1..=99).contains(&p) => p,
        _ => {
            return Err(ctx.syntax(
                idx,
                "a satellite number 01-99 in columns 2-3",
                quote(prn_field),
            ))
        }
    };
    let sat = EmitterId::new(system, prn);
    let year = int_field(ctx, idx, line, 3, 8, "the year")?;
    let mo = int_field(ctx, idx, line, 8, 11, "the month")?;
    let d = int_field(ctx, idx, line, 11, 14, "the day")?;
    let h = int_field(ctx, idx, line, 14, 17, "the hour")?;
    let mi = int_field(ctx, idx, line, 17, 20, "the minute")?;
    let s = int_field(ctx, idx, line, 20, 23, "the second")?;
    let calendar = gpst_from_calendar(year, mo, d, h, mi, s as f64).ok_or_else(|| {
        ctx.syntax(
            idx,
            format!("a valid epoch date and time for {sat}"),
            quote(cols(line, 3, 23).unwrap_or("")),
        )
    })?;
    // BeiDou epochs are read in BDT: the same calendar reading is 14 s later in GPST.
    let toc = if system == System::Bds {
        calendar.add_ns(BDT_WEEK_OFFSET_NS)
    } else {
        calendar
    };
    Ok(FirstLine::Record { sat, toc })
}

/// Turns the raw fields of a GPS or BeiDou record into an [`Ephemeris`], checking that
/// every required field is present and physically meaningful.
fn build_ephemeris(
    ctx: &Ctx<'_>,
    raw: &RawRecord,
    toc: GpsTime,
    use_record_week: bool,
) -> Result<Ephemeris, RinexError> {
    let sat = raw.sat;
    let names = if sat.system == System::Bds {
        &BDS_FIELD_NAMES
    } else {
        &GPS_FIELD_NAMES
    };
    let get = |l: usize, f: usize| -> Result<f64, RinexError> {
        match raw.orbit[l][f] {
            Some(v) => Ok(v),
            None if OPTIONAL_FIELDS[l][f] => Ok(0.0),
            None => Err(ctx.syntax(
                raw.orbit_line[l],
                format!(
                    "{} of {sat} (broadcast orbit line {}, field {})",
                    names[l][f],
                    l + 1,
                    f + 1
                ),
                "a blank field",
            )),
        }
    };
    let counter = |l: usize, f: usize| -> Result<u32, RinexError> {
        let v = get(l, f)?;
        if (0.0..4.294_967_295e9).contains(&v) {
            Ok(v.round() as u32)
        } else {
            Err(ctx.syntax(
                raw.orbit_line[l],
                format!("{} of {sat}: a non-negative integer", names[l][f]),
                format!("{v}"),
            ))
        }
    };
    let sow = |l: usize, f: usize| -> Result<f64, RinexError> {
        let v = get(l, f)?;
        // Transmission times may be shifted by a week either way (RINEX 3.05 Table A6).
        if (-(SECONDS_PER_WEEK as f64)..2.0 * SECONDS_PER_WEEK as f64).contains(&v) {
            Ok(v)
        } else {
            Err(ctx.syntax(
                raw.orbit_line[l],
                format!("{} of {sat}: seconds of week", names[l][f]),
                format!("{v}"),
            ))
        }
    };

    let bds = sat.system == System::Bds;
    let week_offset_ns = if bds { BDT_WEEK_OFFSET_NS } else { 0 };
    let toe_sow = sow(2, 0)?;
    if !(0.0..SECONDS_PER_WEEK as f64).contains(&toe_sow) {
        return Err(ctx.syntax(
            raw.orbit_line[2],
            format!("Toe of {sat}: seconds of week in 0..604800"),
            format!("{toe_sow}"),
        ));
    }
    let week = get(4, 2)?;
    let toe = if use_record_week && week > 0.0 {
        if !(0.0..10_000.0).contains(&week) || week.fract() != 0.0 {
            return Err(ctx.syntax(
                raw.orbit_line[4],
                format!("{} of {sat}: a whole week number", names[4][2]),
                format!("{week}"),
            ));
        }
        let base = if bds {
            GpsTime::from_bdt_week_sow(week as i64, toe_sow)
        } else {
            GpsTime::from_week_tow(week as i64, toe_sow)
        };
        // Some writers put the week of transmission rather than of toe; the toe nearest
        // toc is the one meant.
        if base.seconds_since(toc).abs() > SECONDS_PER_WEEK as f64 / 2.0 {
            nearest_sow(toc, week_offset_ns, toe_sow)
        } else {
            base
        }
    } else {
        nearest_sow(toc, week_offset_ns, toe_sow)
    };
    // The transmission time is in seconds of the record's week; 0.9999e9 means unknown.
    let tx_raw = get(6, 0)?;
    let transmit_time = if raw.orbit[6][0].is_none() || tx_raw >= 0.9e9 {
        toc
    } else {
        let tx = sow(6, 0)?;
        let week_start = GpsTime::from_ns(
            toe.ns()
                - ((if bds {
                    toe.bdt_week_sow().1
                } else {
                    toe.tow_s()
                }) * 1e9)
                    .round() as i64,
        );
        week_start.add_seconds(tx)
    };

    let eph = Ephemeris {
        sat,
        toc,
        toe,
        transmit_time,
        af0: raw.clock[0].unwrap_or(0.0),
        af1: raw.clock[1].unwrap_or(0.0),
        af2: raw.clock[2].unwrap_or(0.0),
        iode: counter(0, 0)?,
        crs: get(0, 1)?,
        delta_n: get(0, 2)?,
        m0: get(0, 3)?,
        cuc: get(1, 0)?,
        e: get(1, 1)?,
        cus: get(1, 2)?,
        sqrt_a: get(1, 3)?,
        cic: get(2, 1)?,
        omega0: get(2, 2)?,
        cis: get(2, 3)?,
        i0: get(3, 0)?,
        crc: get(3, 1)?,
        omega: get(3, 2)?,
        omega_dot: get(3, 3)?,
        idot: get(4, 0)?,
        ura_m: get(5, 0)?,
        health: counter(5, 1)?,
        tgd_s: get(5, 2)?,
        tgd2_s: if bds { get(5, 3)? } else { 0.0 },
        iodc: if bds { counter(6, 1)? } else { counter(5, 3)? },
        fit_interval_h: if bds { 0.0 } else { get(6, 1)? },
    };
    // Elements out of their physical range are not a syntax error: the record is read,
    // then dropped with a warning by `screen`, so one corrupt record does not make a
    // whole day of navigation data unusable.
    Ok(eph)
}

/// Splits parsed records into the usable ones and the dropped ones (with the reason):
///
/// 1. A record whose elements a broadcast message cannot carry
///    ([`Ephemeris::implausibility`]) is dropped.
/// 2. A record whose orbit is another satellite's (the two stay within [`SAME_ORBIT_M`]
///    at toe − 1 h, toe and toe + 1 h) belongs to the satellite whose own nearest other
///    record (within [`NEIGHBOUR_SPAN_S`]) agrees with it. A record that is more than
///    [`OWN_ORBIT_M`] from its own satellite's nearest other record, or that has no
///    such record to vouch for it, is a copy under the wrong PRN and is dropped: RINEX
///    merging of station files has produced such copies (G01 of 2010-07-01 06:00 in
///    IGS brdc1820.10n is G23's record under G01's PRN).
///
/// Health plays no part here: an unhealthy record still describes its satellite's orbit.
fn screen(
    records: Vec<(Ephemeris, Option<usize>)>,
    file: &str,
) -> (Vec<Ephemeris>, Vec<DroppedRecord>) {
    let mut dropped = Vec::new();
    let drop = |e: &Ephemeris, line: Option<usize>, reason: String| DroppedRecord {
        file: file.to_string(),
        line,
        sat: e.sat,
        toe: e.toe,
        reason,
    };
    let mut plausible = Vec::with_capacity(records.len());
    for (e, line) in records {
        match e.implausibility() {
            Some(why) => dropped.push(drop(&e, line, why)),
            None => plausible.push((e, line)),
        }
    }
    // Positions at toe − 1 h, toe and toe + 1 h of record i, and the same instants from
    // record j: the largest distance between them.
    // The instant toe comes first so that the usual case (thousands of km apart) costs
    // one evaluation per pair.
    let spread = |a: &Ephemeris, b: &Ephemeris| -> f64 {
        let mut worst = 0.0f64;
        for dt in [0.0, -3600.0, 3600.0] {
            let t = a.toe.add_seconds(dt);
            worst = worst.max((a.state(t).pos_ecef_m - b.state(t).pos_ecef_m).norm());
            if worst >= SAME_ORBIT_M {
                break;
            }
        }
        worst
    };
    let near = |a: &Ephemeris, b: &Ephemeris| a.toe.seconds_since(b.toe).abs() <= NEIGHBOUR_SPAN_S;
    // Records sharing their orbit with a record of another satellite of the same system.
    let shared: Vec<Option<EmitterId>> = plausible
        .iter()
        .map(|(a, _)| {
            plausible
                .iter()
                .find(|(b, _)| {
                    b.sat != a.sat
                        && b.sat.system == a.sat.system
                        && near(a, b)
                        && spread(a, b) < SAME_ORBIT_M
                })
                .map(|(b, _)| b.sat)
        })
        .collect();
    let mut kept = Vec::with_capacity(plausible.len());
    for (i, (a, line)) in plausible.iter().enumerate() {
        let Some(other) = shared[i] else {
            continue;
        };
        // The satellite's own other record with toe nearest to this one's.
        let own = plausible
            .iter()
            .enumerate()
            .filter(|(j, (b, _))| *j != i && b.sat == a.sat && near(a, b))
            .map(|(_, (b, _))| b)
            .min_by_key(|b| (b.toe.ns() - a.toe.ns()).unsigned_abs());
        let verdict = match own {
            Some(b) => {
                let d = (a.state(a.toe).pos_ecef_m - b.state(a.toe).pos_ecef_m).norm();
                (d > OWN_ORBIT_M).then(|| {
                    format!(
                        "its orbit is {other}'s (within {SAME_ORBIT_M} m over ±1 h) and \
                         {:.0} km from {}'s own record with toe {}",
                        d / 1e3,
                        a.sat,
                        b.toe
                    )
                })
            }
            None => Some(format!(
                "its orbit is {other}'s (within {SAME_ORBIT_M} m over ±1 h) and no other \
                 record of {} within {} h confirms it",
                a.sat,
                NEIGHBOUR_SPAN_S / 3600.0
            )),
        };
        if let Some(why) = verdict {
            dropped.push(drop(a, *line, why));
        }
    }
    let doubtful: BTreeSet<(EmitterId, GpsTime, Option<usize>)> =
        dropped.iter().map(|d| (d.sat, d.toe, d.line)).collect();
    for (e, line) in plausible {
        if !doubtful.contains(&(e.sat, e.toe, line)) {
            kept.push(e);
        }
    }
    dropped.sort_by_key(|d| (d.line, d.sat, d.toe));
    (kept, dropped)
}

impl NavData {
    /// Navigation data from ephemerides (sorted here) and header values.
    pub fn new(
        mut ephemerides: Vec<Ephemeris>,
        klobuchar: Option<Klobuchar>,
        leap_seconds: Option<i32>,
    ) -> Self {
        ephemerides.sort_by(eph_order);
        Self {
            ephemerides,
            klobuchar,
            klobuchar_bds: None,
            leap_seconds,
            leap_announcement: None,
            time_corr: Vec::new(),
            skipped: BTreeMap::new(),
            dropped: Vec::new(),
            max_age: MaxAge::default(),
        }
    }

    /// Restores the sort order [`NavData::select`] relies on.
    pub fn sort(&mut self) {
        self.ephemerides.sort_by(eph_order);
    }

    /// The ephemeris to use for `sat` at time `t`, chosen as RTKLIB does (`seleph` in
    /// `ephemeris.c`, with the satellite then excluded when its health word is non-zero):
    /// among *all* records with |t − toe| within [`NavData::max_age`] for the system, the
    /// one with toe nearest to `t` (among equally near ones the latest transmitted, then
    /// the later toe). If that record is unhealthy the satellite is unusable at `t` and
    /// the answer is `None`: a healthy neighbour further away is never substituted, since
    /// the control segment flags a satellite unhealthy precisely when its older or newer
    /// orbit must not be used. `None` also when no record is near enough, or for a
    /// non-GNSS emitter.
    pub fn select(&self, sat: EmitterId, t: GpsTime) -> Option<&Ephemeris> {
        let max_age_s = self.max_age.of(sat.system)?;
        self.select_with_max_age(sat, t, max_age_s)
    }

    /// As [`NavData::select`] with an explicit bound on |t − toe| (s).
    pub fn select_with_max_age(
        &self,
        sat: EmitterId,
        t: GpsTime,
        max_age_s: f64,
    ) -> Option<&Ephemeris> {
        self.nearest(sat, t, max_age_s).filter(|e| e.is_healthy())
    }

    /// The record of `sat` with toe nearest to `t` within `max_age_s`, healthy or not
    /// (ties as in [`NavData::select`]).
    pub fn nearest(&self, sat: EmitterId, t: GpsTime, max_age_s: f64) -> Option<&Ephemeris> {
        debug_assert!(self
            .ephemerides
            .windows(2)
            .all(|w| eph_order(&w[0], &w[1]) != std::cmp::Ordering::Greater));
        let max_age_ns = (max_age_s * 1e9) as i64;
        let eph = &self.ephemerides;
        let earliest = t.ns().saturating_sub(max_age_ns);
        let start = eph.partition_point(|e| (e.sat, e.toe.ns()) < (sat, earliest));
        let mut best: Option<&Ephemeris> = None;
        for e in eph[start..]
            .iter()
            .take_while(|e| e.sat == sat && e.toe.ns() <= t.ns().saturating_add(max_age_ns))
        {
            best = match best {
                None => Some(e),
                Some(b) => {
                    let (de, db) = ((e.toe.ns() - t.ns()).abs(), (b.toe.ns() - t.ns()).abs());
                    if de < db || (de == db && (e.transmit_time, e.toe) >= (b.transmit_time, b.toe))
                    {
                        Some(e)
                    } else {
                        Some(b)
                    }
                }
            };
        }
        best
    }

    /// The satellites with at least one ephemeris, sorted and unique.
    pub fn satellites(&self) -> Vec<EmitterId> {
        self.ephemerides
            .iter()
            .map(|e| e.sat)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    }
}

/// The order of [`NavData::ephemerides`]: satellite, then toe, then transmit time.
fn eph_order(a: &Ephemeris, b: &Ephemeris) -> std::cmp::Ordering {
    (a.sat, a.toe, a.transmit_time).cmp(&(b.sat, b.toe, b.transmit_time))
}

#[cfg(test)]
mod tests {
    use super::*;

    const V2_HEADER: &str =
        "     2              NAVIGATION DATA                         RINEX VERSION / TYPE
    0.4657D-08  0.1490D-07 -0.5960D-07 -0.1192D-06          ION ALPHA
    0.8192D+05  0.8192D+05 -0.6554D+05 -0.5243D+06          ION BETA
    15                                                      LEAP SECONDS
                                                            END OF HEADER
";
    const V2_G02: &str =
        " 2 10  7  1  0  0  0.0 0.269108917564D-03 0.318323145621D-11 0.000000000000D+00
    0.850000000000D+02 0.414375000000D+02 0.525557597442D-08 0.165772167412D+01
    0.232271850109D-05 0.960697804112D-02 0.617466866970D-05 0.515359739113D+04
    0.345600000000D+06-0.558793544769D-08-0.127458719764D+01 0.167638063431D-06
    0.939349150611D+00 0.249937500000D+03 0.309739903949D+01-0.838784952606D-08
   -0.232152526369D-10 0.100000000000D+01 0.159000000000D+04 0.000000000000D+00
    0.200000000000D+01 0.000000000000D+00-0.172294676304D-07 0.850000000000D+02
    0.338418000000D+06 0.400000000000D+01 0.000000000000D+00 0.000000000000D+00
";

    const V3_MIXED: &str =
        "     3.05           NAVIGATION DATA     MIXED               RINEX VERSION / TYPE
GPSA   4.6566e-09  1.4901e-08 -5.9605e-08 -1.1921E-07       IONOSPHERIC CORR
GPSB   8.1920e+04  9.8304e+04 -6.5536e+04 -5.2429E+05       IONOSPHERIC CORR
    18                                                      LEAP SECONDS
                                                            END OF HEADER
C05 2020 06 24 22 00 00-5.154609680176e-04-6.708145150469e-11 0.000000000000e+00
     1.000000000000e+00-4.142968750000e+02-3.141559429989e-09-1.101749161212e+00
    -1.366203650832e-05 3.830116475001e-04-1.177610829473e-05 6.493378950119e+03
     3.384000000000e+05-6.146728992462e-08 2.697580724014e+00 6.146728992462e-08
     1.136268367853e-01 3.549843750000e+02-1.027125663175e+00 4.100527946305e-09
     3.321566928024e-10 0.000000000000e+00 7.550000000000e+02
     2.000000000000e+00 0.000000000000e+00 1.000000000000e-10-9.300000000000e-09
     3.384276000000e+05 0.000000000000e+00
R01 2020 06 24 23 45 00 1.120567321777e-05 0.000000000000e+00 3.447000000000e+05
    -1.089794335938e+04-1.004791259766e+00 9.313225746155e-10 0.000000000000e+00
     1.203460546875e+04-2.542285919189e+00 0.000000000000e+00 1.000000000000e+00
     1.982380371094e+04 1.360239982605e+00-2.793967723846e-09 0.000000000000e+00
     0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
E01 2020 06 25 00 00 00-6.472196057439e-04-7.531752999057e-12 0.000000000000e+00
     1.000000000000e+00-3.187500000000e+01 2.780473537133e-09-1.826027512164e+00
    -1.529976725578e-06 1.588219311088e-04 1.104548573494e-05 5.440605087280e+03
     3.456000000000e+05 3.725290298462e-09-2.877929457108e+00 1.862645149231e-08
     9.879516737547e-01 1.176562500000e+02-4.766513036880e-01-5.456655564040e-09
    -5.000208274269e-10 5.170000000000e+02 2.111000000000e+03 0.000000000000e+00
     3.120000000000e+00 0.000000000000e+00 1.862645149231e-09 2.095475792885e-09
     3.463240000000e+05
G01 2020 06 25 04 00 00 1.604342833161e-05 7.048583938740e-12 0.000000000000e+00
     1.000000000000e+00-4.142968750000e+01 4.026596389650e-09 2.871534990340e+00
    -2.676621079440e-06 5.957618006510e-03 4.174187779430e-06 5.153636478420e+03
     3.600000000000e+05 1.061707735060e-07-2.493184817740e+00-9.313225746150e-08
     9.833919144490e-01 3.093750000000e+02-1.650496813270e+00-7.889971342930e-09
    -8.571785642400e-12 1.000000000000e+00 2.111000000000e+03 0.000000000000e+00
     2.000000000000e+00 0.000000000000e+00-3.259629011150e-09 1.000000000000e+00
     3.528180000000e+05 4.000000000000e+00
";

    #[test]
    fn reads_rinex2_record() {
        let text = format!("{V2_HEADER}{V2_G02}");
        let nav = parse_nav(&text, "test.10n").unwrap();
        assert_eq!(nav.ephemerides.len(), 1);
        assert_eq!(nav.leap_seconds, Some(15));
        let k = nav.klobuchar.unwrap();
        assert_eq!(k.alpha[0], 0.4657e-08);
        assert_eq!(k.beta[3], -0.5243e+06);
        let e = &nav.ephemerides[0];
        assert_eq!(*e, crate::gnss::ephemeris::tests::g02_2010());
    }

    #[test]
    fn reads_rinex3_mixed_and_counts_skipped() {
        let nav = parse_nav(V3_MIXED, "mixed.rnx").unwrap();
        assert_eq!(
            nav.satellites(),
            vec![
                EmitterId::new(System::Gps, 1),
                EmitterId::new(System::Bds, 5)
            ]
        );
        assert_eq!(nav.skipped.get(&'R'), Some(&1));
        assert_eq!(nav.skipped.get(&'E'), Some(&1));
        assert_eq!(nav.skipped.len(), 2);
        assert_eq!(nav.leap_seconds, Some(18));
        assert_eq!(nav.klobuchar.unwrap().beta[1], 9.8304e+04);
        let c05 = nav
            .ephemerides
            .iter()
            .find(|e| e.sat.system == System::Bds)
            .unwrap();
        assert_eq!(*c05, crate::gnss::ephemeris::tests::c05_2020());
        // BDT 2020-06-24 22:00:00 is 22:00:14 GPST.
        assert_eq!(
            c05.toc,
            GpsTime::from_gpst_calendar(2020, 6, 24, 22, 0, 14, 0)
        );
        let g01 = nav
            .ephemerides
            .iter()
            .find(|e| e.sat.system == System::Gps)
            .unwrap();
        assert_eq!(g01.toe, GpsTime::from_week_tow(2111, 360_000.0));
        assert_eq!(g01.iodc, 1);
        assert_eq!(g01.fit_interval_h, 4.0);
    }

    #[test]
    fn calendar_agrees_with_core_time() {
        for &(y, mo, d, h, mi, s) in &[
            (1980, 1, 6, 0, 0, 0),
            (2010, 7, 1, 0, 0, 0),
            (2020, 2, 29, 23, 59, 59),
            (2100, 3, 1, 12, 0, 0),
        ] {
            let mine = gpst_from_calendar(y, mo, d, h, mi, s as f64).unwrap();
            let core = GpsTime::from_gpst_calendar(
                y as i32, mo as u8, d as u8, h as u8, mi as u8, s as u8, 0,
            );
            assert_eq!(mine, core);
            assert_eq!(gpst_calendar(mine), (y, mo, d, h, mi, s, 0));
        }
        assert!(gpst_from_calendar(2021, 2, 29, 0, 0, 0.0).is_none());
        assert!(gpst_from_calendar(2021, 13, 1, 0, 0, 0.0).is_none());
        assert!(gpst_from_calendar(1979, 1, 1, 0, 0, 0.0).is_none());
        assert!(gpst_from_calendar(2021, 1, 1, 24, 0, 0.0).is_none());
    }

    #[test]
    fn fortran_numbers() {
        assert_eq!(parse_fortran_f64(" 0.1D+01"), Ok(Some(1.0)));
        assert_eq!(parse_fortran_f64("-.5d-1"), Ok(Some(-0.05)));
        assert_eq!(parse_fortran_f64("   "), Ok(None));
        assert!(parse_fortran_f64("NaN").is_err());
        assert!(parse_fortran_f64("inf").is_err());
        assert!(parse_fortran_f64("1.0E+999").is_err());
        assert!(parse_fortran_f64("1.2.3").is_err());
    }

    #[test]
    fn truncated_record_names_the_line() {
        // Header is 5 lines; the record starts on line 6 and loses its last 2 lines.
        let rec: Vec<&str> = V2_G02.lines().take(6).collect();
        let text = format!("{V2_HEADER}{}\n", rec.join("\n"));
        let err = parse_nav(&text, "cut.10n").unwrap_err();
        assert!(
            matches!(err, RinexError::Truncated { line: 12, .. }),
            "{err}"
        );
        let msg = err.to_string();
        assert!(
            msg.contains("cut.10n")
                && msg.contains("line 12")
                && msg.contains("G02")
                && msg.contains("orbit line 6 of 7"),
            "{msg}"
        );
    }

    #[test]
    fn garbage_numbers_are_reported() {
        let text = format!(
            "{V2_HEADER}{}",
            V2_G02.replace("0.525557597442D-08", "0.52555759x442D-08")
        );
        let err = parse_nav(&text, "bad.10n").unwrap_err();
        let msg = err.to_string();
        assert_eq!(err.line(), Some(7), "{msg}");
        assert!(
            msg.contains("a number") && msg.contains("0.52555759x442D-08"),
            "{msg}"
        );
        // A blank required field.
        let text = format!(
            "{V2_HEADER}{}",
            V2_G02.replace("0.515359739113D+04", "                  ")
        );
        let msg = parse_nav(&text, "bad.10n").unwrap_err().to_string();
        assert!(
            msg.contains("sqrt(A) of G02") && msg.contains("line 8"),
            "{msg}"
        );
        // An impossible eccentricity: the record is read and dropped with its line.
        let text = format!(
            "{V2_HEADER}{}",
            V2_G02.replace("0.960697804112D-02", "0.160697804112D+01")
        );
        let nav = parse_nav(&text, "bad.10n").unwrap();
        assert!(nav.ephemerides.is_empty());
        let msg = nav.dropped[0].to_string();
        assert!(
            msg.contains("eccentricity") && msg.contains("bad.10n, line 6"),
            "{msg}"
        );
        // A bad date.
        let text = format!(
            "{V2_HEADER}{}",
            V2_G02.replace(" 2 10  7  1", " 2 10 13  1")
        );
        let msg = parse_nav(&text, "bad.10n").unwrap_err().to_string();
        assert!(
            msg.contains("line 6") && msg.contains("valid epoch"),
            "{msg}"
        );
    }

    /// The BeiDou Klobuchar set of a RINEX 3 header. The two lines are those of an IGS
    /// merged broadcast file's header (CDDIS, `CCRINEXN V1.6.0`, March 2016) as quoted in
    /// the RINEX 3 navigation parser of the Norwegian Mapping Authority's Where software;
    /// then the same with RINEX 3.04's optional time mark and satellite columns.
    #[test]
    fn reads_the_beidou_klobuchar_set_of_a_rinex3_header() {
        let bds = "BDSA    .1397E-07   .0000E+00  -.5960E-07   .5960E-07       IONOSPHERIC CORR
BDSB    .1106E+06  -.3277E+05  -.2621E+06   .1966E+06       IONOSPHERIC CORR
";
        let with = V3_MIXED.replacen("    18 ", &format!("{bds}    18 "), 1);
        let nav = parse_nav(&with, "bds.rnx").unwrap();
        let k = nav.klobuchar_bds.expect("BDSA/BDSB read");
        assert_eq!(k.alpha, [0.1397e-7, 0.0, -0.5960e-7, 0.5960e-7]);
        assert_eq!(k.beta, [0.1106e6, -0.3277e5, -0.2621e6, 0.1966e6]);
        // The GPS set is read as before and kept apart.
        assert_eq!(nav.klobuchar.unwrap().beta[1], 9.8304e+04);
        // RINEX 3.04's optional time mark (column 55) and satellite (columns 57-58).
        let marked = with.replace(".5960E-07       IONOSPHERIC", ".5960E-07 A 05  IONOSPHERIC");
        assert_eq!(
            parse_nav(&marked, "bds.rnx").unwrap().klobuchar_bds,
            Some(k)
        );
        // Without BDSA/BDSB, or with only one of them, there is no BeiDou set.
        assert_eq!(parse_nav(V3_MIXED, "x.rnx").unwrap().klobuchar_bds, None);
        let first = bds.lines().next().unwrap_or("");
        let half = V3_MIXED.replacen("    18 ", &format!("{first}\n    18 "), 1);
        assert_eq!(parse_nav(&half, "x.rnx").unwrap().klobuchar_bds, None);
        // A damaged coefficient names the file, the line and what was expected.
        let bad = with.replace("-.3277E+05", "-.3277X+05");
        let err = parse_nav(&bad, "bds.rnx").unwrap_err();
        assert_eq!(err.line(), Some(5));
        let msg = err.to_string();
        assert!(
            msg.contains("bds.rnx") && msg.contains("ionospheric coefficient 2 of 4"),
            "{msg}"
        );
    }

    #[test]
    fn reads_time_system_corrections_and_the_leap_second_announcement() {
        let head =
            "     3.04           N: GNSS NAV DATA    M: MIXED            RINEX VERSION / TYPE
GPUT  9.3132257462E-10 2.664535259E-15 589824 2111          TIME SYSTEM CORR
BDUT  0.0000000000e+00-4.085620730e-14     14  782          TIME SYSTEM CORR
GLUT -1.8626451492e-09 0.000000000e+00      0    0          TIME SYSTEM CORR
    18    18  1929     7GPS                                 LEAP SECONDS
                                                            END OF HEADER
";
        let nav = parse_nav(head, "t.rnx").expect("header");
        let codes: Vec<&str> = nav.time_corr.iter().map(|c| c.code.as_str()).collect();
        assert_eq!(codes, ["GPUT", "BDUT", "GLUT"]);
        let gp = &nav.time_corr[0];
        assert_eq!(
            (gp.a0_s, gp.a1_s_per_s),
            (9.3132257462E-10, 2.664535259E-15)
        );
        assert_eq!((gp.ref_sow_s, gp.ref_week), (589_824.0, 2111));
        // 1000 s after the reference, the drift adds 1000·a1.
        let r = GpsTime::from_week_tow(2111, 589_824.0);
        assert_eq!(gp.reference(), Some(r));
        let at = gp.at(r.add_seconds(1000.0));
        assert!((at - (9.3132257462E-10 + 1000.0 * 2.664535259E-15)).abs() < 1e-22);
        // BDUT's reference is in BDT (week 782, second 14 = GPS week 2138, 28 s).
        assert_eq!(
            nav.time_corr[1].reference(),
            Some(GpsTime::from_week_tow(2138, 28.0))
        );
        assert_eq!(nav.time_corr[2].reference(), None);
        assert_eq!(nav.time_corr[2].at(r), -1.8626451492e-09);
        assert_eq!(nav.leap_seconds, Some(18));
        assert_eq!(
            nav.leap_announcement,
            Some(LeapAnnouncement {
                future_s: 18,
                week: 1929,
                day: 7,
                bds: false
            })
        );
        // A bare LEAP SECONDS line announces nothing; a damaged one is refused with its line.
        let bare = head.replace("    18  1929     7GPS", "                    ");
        assert_eq!(
            parse_nav(&bare, "t.rnx").expect("bare").leap_announcement,
            None
        );
        let err = parse_nav(&head.replace("  1929", "  19x9"), "t.rnx").unwrap_err();
        assert_eq!(err.line(), Some(5));
        assert!(err.to_string().contains("WN_LSF"), "{err}");
        let err =
            parse_nav(&head.replace("2.664535259E-15", "2.664535259Q-15"), "t.rnx").unwrap_err();
        assert_eq!(err.line(), Some(2));
        assert!(err.to_string().contains("a1 of GPUT"), "{err}");
        let err = parse_nav(&head.replace("GLUT", "gl-t"), "t.rnx").unwrap_err();
        assert_eq!(err.line(), Some(4));
        // GNSS-SDR 0.0.17's RINEX header: a BDUT line without reference time or week.
        let gsdr = head.replace(
            "BDUT  0.0000000000e+00-4.085620730e-14     14  782",
            "BDUT   .0000000000D+00  .000000000D+00           ",
        );
        let nav = parse_nav(&gsdr, "GSDR.26N").expect("GNSS-SDR's header");
        assert_eq!(nav.time_corr[1].reference(), None);
    }

    #[test]
    fn header_errors() {
        let err = parse_nav("", "empty.rnx").unwrap_err();
        assert_eq!(err.line(), Some(1));
        assert!(err.to_string().contains("empty file"), "{err}");
        let err = parse_nav("hello\n", "x.rnx").unwrap_err();
        assert!(err.to_string().contains("RINEX VERSION / TYPE"), "{err}");
        let obs =
            "     2.10           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE\n";
        let err = parse_nav(obs, "x.05o").unwrap_err();
        assert!(matches!(err, RinexError::WrongFileType { .. }), "{err}");
        assert!(err.to_string().contains("OBSERVATION DATA"), "{err}");
        let v4 =
            "     4.00           N: GNSS NAV DATA    M: MIXED            RINEX VERSION / TYPE\n";
        let err = parse_nav(v4, "x.rnx").unwrap_err();
        assert!(
            matches!(err, RinexError::UnsupportedVersion { .. }),
            "{err}"
        );
        let err = parse_nav(&V2_HEADER.replace("END OF HEADER", "COMMENT"), "x.rnx").unwrap_err();
        assert!(err.to_string().contains("END OF HEADER"), "{err}");
        let err = parse_nav(&V2_HEADER.replace("0.1490D-07", "0.1490Q-07"), "x.rnx").unwrap_err();
        assert_eq!(err.line(), Some(2));
    }

    #[test]
    fn short_lines_and_non_ascii_never_panic() {
        // Every prefix of a valid file, and a file with multi-byte characters at field
        // boundaries, must give Ok or Err, never a panic.
        let text = format!("{V2_HEADER}{V2_G02}");
        for cut in 0..text.len() {
            if text.is_char_boundary(cut) {
                let _ = parse_nav(&text[..cut], "prefix");
            }
        }
        let weird = text
            .replace("0.850000000000D+02", "0.8500000000€0D+02")
            .replace("ION ALPHA", "ION ÄLPHA");
        assert!(parse_nav(&weird, "weird").is_err());
        for cut in 0..V3_MIXED.len() {
            let _ = parse_nav(&V3_MIXED[..cut], "prefix3");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(400))]
        /// Random single-character damage anywhere in a valid file gives Ok or a typed
        /// error, never a panic.
        #[test]
        fn damaged_files_never_panic(pos in 0usize..4000, c in proptest::char::any(), v3 in proptest::bool::ANY) {
            let base = if v3 { V3_MIXED.to_string() } else { format!("{V2_HEADER}{V2_G02}") };
            let mut chars: Vec<char> = base.chars().collect();
            let at = pos % chars.len();
            chars[at] = c;
            let text: String = chars.into_iter().collect();
            let _ = parse_nav(&text, "fuzz");
        }
    }

    #[test]
    fn select_picks_nearest_healthy() {
        let base = crate::gnss::ephemeris::tests::g02_2010();
        let mk = |hours: f64, health: u32, tx_s: f64| {
            let mut e = base.clone();
            e.toe = base.toe.add_seconds(hours * 3600.0);
            e.toc = e.toe;
            e.transmit_time = base.toe.add_seconds(tx_s);
            e.health = health;
            e
        };
        let nav = NavData::new(
            vec![
                mk(2.0, 0, 0.0),
                mk(0.0, 0, -100.0),
                mk(4.0, 1, 0.0),
                mk(0.0, 0, -50.0),
            ],
            None,
            None,
        );
        let t = base.toe;
        // Two with toe = 0: the later transmitted one wins.
        assert_eq!(
            nav.select(base.sat, t).unwrap().transmit_time,
            base.toe.add_seconds(-50.0)
        );
        // At 1.5 h the 2 h one is nearest.
        assert_eq!(
            nav.select(base.sat, t.add_seconds(5400.0)).unwrap().toe,
            base.toe.add_seconds(7200.0)
        );
        // At 4 h the nearest record is the unhealthy one: the satellite is unusable, and
        // the healthy 2 h record (2 h away, within the limit) is not substituted.
        assert!(nav.select(base.sat, t.add_seconds(14_400.0)).is_none());
        assert_eq!(
            nav.nearest(base.sat, t.add_seconds(14_400.0), GPS_MAX_AGE_S)
                .unwrap()
                .health,
            1
        );
        // At 2.9 h the healthy 2 h record is still the nearest.
        assert_eq!(
            nav.select(base.sat, t.add_seconds(2.9 * 3600.0))
                .unwrap()
                .toe,
            base.toe.add_seconds(7200.0)
        );
        // More than 2 h from every toe: nothing, unless the limit is raised.
        assert!(nav.select(base.sat, t.add_seconds(-7201.0)).is_none());
        assert!(nav
            .select_with_max_age(base.sat, t.add_seconds(-7201.0), 4.0 * 3600.0)
            .is_some());
        let mut wide = nav.clone();
        wide.max_age = MaxAge::parse("gps=7300").unwrap();
        assert!(wide.select(base.sat, t.add_seconds(-7201.0)).is_some());
        assert!(nav.select(EmitterId::new(System::Gps, 3), t).is_none());
        assert!(nav.select(EmitterId::new(System::Dtmb, 2), t).is_none());
        // Exactly halfway between two healthy ones: the later issue.
        assert_eq!(
            nav.select(base.sat, t.add_seconds(3600.0)).unwrap().toe,
            base.toe.add_seconds(7200.0)
        );
    }

    #[test]
    fn rinex2_week_comes_from_the_date() {
        // A week field written modulo 1024 (566 = 1590 − 1024) does not matter in RINEX 2.
        let text = format!(
            "{V2_HEADER}{}",
            V2_G02.replace("0.159000000000D+04", "0.566000000000D+03")
        );
        let nav = parse_nav(&text, "w.10n").unwrap();
        assert_eq!(
            nav.ephemerides[0].toe,
            GpsTime::from_week_tow(1590, 345_600.0)
        );
    }

    #[test]
    fn max_age_parses() {
        assert_eq!(
            MaxAge::parse("7200").unwrap(),
            MaxAge {
                gps_s: 7200.0,
                bds_s: 7200.0
            }
        );
        assert_eq!(
            MaxAge::parse("bds=1800").unwrap(),
            MaxAge {
                gps_s: GPS_MAX_AGE_S,
                bds_s: 1800.0
            }
        );
        assert_eq!(MaxAge::parse("G=100, C=200").unwrap().bds_s, 200.0);
        for bad in ["", "-1", "0", "inf", "1e9", "gal=100", "gps", "gps=x"] {
            assert!(MaxAge::parse(bad).is_err(), "{bad}");
        }
    }

    /// Each harmonic amplitude and orbit size out of its broadcast range drops the record
    /// (with its line), while the same record with in-range values is kept.
    #[test]
    fn implausible_elements_drop_the_record() {
        let ok = parse_nav(&format!("{V2_HEADER}{V2_G02}"), "ok.10n").unwrap();
        assert_eq!(ok.ephemerides.len(), 1);
        assert!(ok.dropped.is_empty());
        for (field, bad, needle) in [
            ("0.414375000000D+02", "0.100000000000D+31", "Crs"), // Crs = 1e30 m
            ("0.249937500000D+03", "-0.20000000000D+04", "Crc"),
            ("0.232271850109D-05", "0.100000000000D-02", "Cuc"),
            ("0.617466866970D-05", "0.100000000000D+01", "Cus"),
            ("-0.558793544769D-08", "-0.100000000000D-03", "Cic"),
            ("0.167638063431D-06", "0.700000000000D-04", "Cis"),
            ("0.960697804112D-02", "0.500000000000D-01", "eccentricity"),
            ("0.515359739113D+04", "0.900000000000D+04", "sqrt(A)"),
            ("0.515359739113D+04", "0.200000000000D+04", "sqrt(A)"),
            ("0.525557597442D-08", "0.525557597442D-06", "Delta n"),
        ] {
            let text = format!("{V2_HEADER}{}", V2_G02.replace(field, bad));
            let nav = parse_nav(&text, "bad.10n").unwrap();
            assert!(nav.ephemerides.is_empty(), "{needle}");
            let msg = nav.dropped[0].to_string();
            assert!(
                msg.contains(needle) && msg.contains("line 6") && msg.contains("G02"),
                "{msg}"
            );
        }
    }

    /// A copy of G02's record under PRN 7 is dropped and G02's own kept, since G02's
    /// other record vouches for G02; without that second record neither can be told
    /// apart and both are dropped.
    #[test]
    fn a_record_under_the_wrong_prn_is_dropped() {
        let next = V2_G02
            .replace(" 2 10  7  1  0  0  0.0", " 2 10  7  1  2  0  0.0")
            .replace("0.345600000000D+06", "0.352800000000D+06")
            // Two hours later the mean anomaly has moved on by n·7200 s (n = √(μ/A³) + Δn
            // = 1.458657e-4 rad/s): 1.65772167412 + 1.050233 = 2.707954530837 rad.
            .replace("0.165772167412D+01", "0.270795453084D+01");
        let copy = V2_G02.replace(" 2 10  7  1", " 7 10  7  1");
        let nav = parse_nav(&format!("{V2_HEADER}{V2_G02}{next}{copy}"), "dup.10n").unwrap();
        let g07 = EmitterId::new(System::Gps, 7);
        assert!(
            nav.ephemerides.iter().all(|e| e.sat != g07),
            "{:?}",
            nav.dropped
        );
        assert_eq!(nav.ephemerides.len(), 2);
        assert_eq!(nav.dropped.len(), 1);
        let msg = nav.dropped[0].to_string();
        assert!(
            msg.contains("G07") && msg.contains("G02's") && msg.contains("line 22"),
            "{msg}"
        );
        let alone = parse_nav(&format!("{V2_HEADER}{V2_G02}{copy}"), "dup.10n").unwrap();
        assert!(alone.ephemerides.is_empty(), "{:?}", alone.ephemerides);
        assert_eq!(alone.dropped.len(), 2);
    }
}
