//! Streaming reader of RINEX observation files: RINEX 2.10/2.11 (GPS or mixed; RINEX
//! 2.11 specification, IGS 2007, §5 and Tables A1–A2) and RINEX 3.00–3.05 (RINEX 3.04
//! specification, IGS/RTCM 2018, §5 and Tables A1–A3).
//!
//! The header gives the marker name, `APPROX POSITION XYZ`, `INTERVAL`, `TIME OF FIRST
//! OBS` (and its time system) and the observation types: one list for every system in
//! RINEX 2 (`# / TYPES OF OBSERV`, nine types a line, continuation lines after), one list
//! per system letter in RINEX 3 (`SYS / # / OBS TYPES`, thirteen a line). The body is read
//! one epoch at a time into a reused [`ObsEpoch`], so memory does not grow with the file
//! and, once the buffers have the size of the largest epoch, no epoch allocates.
//!
//! Layout (0-based columns):
//!
//! ```text
//! RINEX 2 epoch:  1X,I2.2 yy | 4×(1X,I2) mo dd hh mi | F11.7 sec (cols 15–25) | 2X,I1 flag (col 28)
//!                 I3 n (cols 29–31) | 12×(A1,I2) satellites (cols 32–67) | F12.9 clock (cols 68–79)
//!                 more than 12 satellites: continuation lines, 32X then 12×(A1,I2)
//!         record: per satellite ⌈types / 5⌉ lines of 5×(F14.3, I1 LLI, I1 SSI)
//! RINEX 3 epoch:  '>' | 1X,I4 yyyy | 4×(1X,I2.2) mo dd hh mi | F11.7 sec (cols 18–28)
//!                 2X,I1 flag (col 31) | I3 n (cols 32–34) | 6X,F15.12 clock (cols 41–55)
//!         record: A1,I2.2 satellite | per type of its system F14.3, I1 LLI, I1 SSI (from col 3)
//! ```
//!
//! A blank value field is a missing observation; blank LLI/SSI digits are absent
//! indicators. Epoch flags 0 (OK), 1 (power failure since the previous epoch) and 6
//! (cycle-slip records, which have the observation layout) are returned; the event
//! records of flags 2–5 (antenna moving, new occupation, header information, external
//! event) are skipped with the `n` special lines that follow them, except that a new
//! observation-type list among the header lines of a flag-4 event replaces the old one. In RINEX 2 a blank
//! satellite letter means GPS. Epoch times are read in the file's time system (`TIME OF
//! FIRST OBS`, GPS when absent): GPST and GST are used as they are, BDT is moved to GPST
//! (GPST = BDT + 14 s); GLONASS (UTC-based) time is refused rather than guessed.
//!
//! Every malformed input gives an [`ObsError`] naming the file, the 1-based line (and
//! column, for a field) and what was expected; the reader never panics. Files are opened
//! through [`crate::io::read`]: regular files only, at most [`RINEX_OBS`] bytes.

use crate::core::time::NS_PER_S;
use crate::core::{EmitterId, GpsTime, System};
use crate::gnss::rinex_nav::{gpst_from_calendar, parse_fortran_f64};
use crate::io::read::{Capped, Limit};
use nalgebra::Vector3;
use std::fmt;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// RINEX observation files: a daily 30-s multi-GNSS file of a station tracking about 40
/// satellites with 16 observables is about 40 × 2 880 epochs × 16 × 16 bytes ≈ 30 MB
/// uncompressed, a 1-Hz one thirty times that (≈ 1 GB); the reader streams them, never
/// holding more than one epoch, so the cap only refuses what no station-day could be:
/// 8 GiB.
pub const RINEX_OBS: Limit = Limit {
    what: "RINEX observation file",
    max_bytes: 8 << 30,
};

/// Most observation types of one system: RINEX 3 counts them in an I3 field, but no
/// signal plan has more than 60 (RINEX 3.04 Table 4 lists fewer than 40 per system);
/// 99 bounds the per-satellite work of a hostile header.
pub const MAX_OBS_TYPES: usize = 99;

/// Longest line accepted (bytes): RINEX lines are at most 80 columns, except RINEX 3
/// observation lines of 3 + 16·n columns (1 587 for 99 types).
pub const MAX_LINE_BYTES: usize = 2048;

/// Offset of BDT epochs from GPST: GPST = BDT + 14 s (BDS-SIS-ICD-B1I-3.0 §5.1.3).
const BDT_TO_GPST_NS: i64 = 14 * NS_PER_S;

/// A satellite as RINEX names it: system letter (`G`, `R`, `E`, `C`, `J`, `S`, `I`)
/// and PRN.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SatId {
    /// The RINEX system letter.
    pub system: char,
    /// The PRN (slot number for GLONASS).
    pub prn: u8,
}

impl SatId {
    /// The emitter hybridnav models for this satellite: GPS and BeiDou only.
    pub fn emitter(self) -> Option<EmitterId> {
        match self.system {
            'G' => Some(EmitterId::new(System::Gps, u16::from(self.prn))),
            'C' => Some(EmitterId::new(System::Bds, u16::from(self.prn))),
            _ => None,
        }
    }
}

impl fmt::Display for SatId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{:02}", self.system, self.prn)
    }
}

/// One observation: the value (m, cycles, Hz or dB-Hz, as its type says), and the
/// loss-of-lock and signal-strength indicators when given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ObsValue {
    /// `None` for a blank field (not observed).
    pub value: Option<f64>,
    /// Loss-of-lock indicator (0–7), `None` when blank.
    pub lli: Option<u8>,
    /// Signal-strength indicator (1–9; 0 unknown), `None` when blank.
    pub ssi: Option<u8>,
}

/// The time system of a file's epochs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeSystem {
    /// GPS time (also Galileo system time, which is steered to it).
    Gps,
    /// BeiDou time: epochs are moved to GPST by +14 s.
    Bdt,
}

/// The header fields hybridnav uses.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsHeader {
    /// Format version (2.10, 3.04, …).
    pub version: f64,
    /// The file's satellite system letter (`G`, `C`, `M`, …; blank in RINEX 2 is `G`).
    pub file_system: char,
    /// `MARKER NAME`, trimmed; empty when absent.
    pub marker_name: String,
    /// `APPROX POSITION XYZ` (ECEF, m), when given.
    pub approx_pos_ecef_m: Option<Vector3<f64>>,
    /// `INTERVAL` (s), when given.
    pub interval_s: Option<f64>,
    /// `TIME OF FIRST OBS`, converted to GPST, when given.
    pub time_of_first_obs: Option<GpsTime>,
    /// The epochs' time system.
    pub time_system: TimeSystem,
    /// Observation types per system letter; RINEX 2 files have one list under `' '` that
    /// applies to every system.
    obs_types: Vec<(char, Vec<String>)>,
}

impl ObsHeader {
    /// The observation types of a system's satellites, in record order.
    pub fn obs_types(&self, system: char) -> Option<&[String]> {
        self.obs_types
            .iter()
            .find(|(s, _)| *s == system || *s == ' ')
            .map(|(_, t)| t.as_slice())
    }

    /// Where observation type `code` (`C1`, `C1C`, `C2I`) sits in a system's records.
    pub fn index_of(&self, system: char, code: &str) -> Option<usize> {
        self.obs_types(system)?.iter().position(|t| t == code)
    }

    /// Whether the file is RINEX 2 (one type list for every system).
    pub fn is_v2(&self) -> bool {
        self.version < 3.0
    }
}

/// One epoch: its time tag, flag, receiver clock offset and the observations of each
/// satellite. Reused from epoch to epoch by [`ObsReader::next_epoch`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObsEpoch {
    /// The time tag (receiver time) in GPST.
    pub t: GpsTime,
    /// The epoch flag: 0 OK, 1 power failure before it, 6 cycle-slip records.
    pub flag: u8,
    /// Receiver clock offset (s) when the file gives it.
    pub clock_offset_s: Option<f64>,
    /// The 1-based line of the epoch record.
    pub line: usize,
    sats: Vec<SatId>,
    /// Start of each satellite's values in `values`, and one past the last.
    starts: Vec<usize>,
    values: Vec<ObsValue>,
}

impl ObsEpoch {
    /// Number of satellites.
    pub fn len(&self) -> usize {
        self.sats.len()
    }

    /// Whether the epoch has no satellite.
    pub fn is_empty(&self) -> bool {
        self.sats.is_empty()
    }

    /// The satellites, in record order.
    pub fn sats(&self) -> &[SatId] {
        &self.sats
    }

    /// The observations of the `k`-th satellite, in the order of its system's types.
    pub fn values(&self, k: usize) -> &[ObsValue] {
        match (self.starts.get(k), self.starts.get(k + 1)) {
            (Some(&a), Some(&b)) => &self.values[a..b],
            _ => &[],
        }
    }

    /// Each satellite with its observations.
    pub fn iter(&self) -> impl Iterator<Item = (SatId, &[ObsValue])> + '_ {
        (0..self.sats.len()).map(move |k| (self.sats[k], self.values(k)))
    }

    fn clear(&mut self) {
        self.sats.clear();
        self.starts.clear();
        self.values.clear();
        self.starts.push(0);
    }
}

/// A failure to read an observation file. Every variant names the file and, where the
/// problem is in the text, the 1-based line (and column) and what was expected there.
#[derive(Debug)]
pub enum ObsError {
    /// The file could not be opened or read.
    Io { file: String, io: std::io::Error },
    /// A line or field does not hold what the format requires.
    Syntax {
        file: String,
        line: usize,
        /// 1-based column of the field, when the problem is one field.
        column: Option<usize>,
        expected: String,
        found: String,
    },
    /// The file ends inside the header or an epoch.
    Truncated {
        file: String,
        line: usize,
        expected: String,
    },
    /// The RINEX version is not one this reader knows.
    UnsupportedVersion {
        file: String,
        line: usize,
        version: String,
    },
}

impl fmt::Display for ObsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ObsError::Io { file, io } => write!(f, "{file}: cannot read the file: {io}"),
            ObsError::Syntax {
                file,
                line,
                column,
                expected,
                found,
            } => {
                write!(f, "{file}, line {line}")?;
                if let Some(c) = column {
                    write!(f, ", column {c}")?;
                }
                write!(f, ": expected {expected}, found {found}")
            }
            ObsError::Truncated {
                file,
                line,
                expected,
            } => write!(
                f,
                "{file}, line {line}: truncated file: expected {expected}, found the end of the file"
            ),
            ObsError::UnsupportedVersion {
                file,
                line,
                version,
            } => write!(
                f,
                "{file}, line {line}: unsupported RINEX version '{version}': expected 2.xx or 3.0x"
            ),
        }
    }
}

impl std::error::Error for ObsError {}

impl ObsError {
    /// The 1-based line the error is about, when it is about the content.
    pub fn line(&self) -> Option<usize> {
        match self {
            ObsError::Io { .. } => None,
            ObsError::Syntax { line, .. }
            | ObsError::Truncated { line, .. }
            | ObsError::UnsupportedVersion { line, .. } => Some(*line),
        }
    }
}

/// Quotes a piece of text for an error message, shortened to 40 characters and trimmed.
fn quote(s: &str) -> String {
    super::rinex_nav::quote(s.trim_start())
}

/// A streaming reader of one observation file: the header is read by [`ObsReader::new`],
/// the epochs one at a time by [`ObsReader::next_epoch`].
pub struct ObsReader<R> {
    inner: R,
    file: String,
    header: ObsHeader,
    /// Number of the line in `line` (1-based; 0 before the first).
    line_no: usize,
    bytes: Vec<u8>,
    line: String,
}

/// Opens `path` (a regular file of at most [`RINEX_OBS`]) and reads its header.
///
/// # Errors
/// [`ObsError::Io`] when the file cannot be opened (a directory, a device, over the cap),
/// otherwise as [`ObsReader::new`].
pub fn open(path: &Path) -> Result<ObsReader<BufReader<Capped>>, ObsError> {
    let file = path.display().to_string();
    let r = crate::io::read::reader(path, RINEX_OBS).map_err(|io| ObsError::Io {
        file: file.clone(),
        io,
    })?;
    ObsReader::new(r, &file)
}

/// Reads the whole of `data` (the text of an observation file named `file_name` in
/// messages): the header and every epoch, each handed to `each`.
///
/// # Errors
/// As [`ObsReader::new`] and [`ObsReader::next_epoch`].
pub fn read_all(
    data: &[u8],
    file_name: &str,
    mut each: impl FnMut(&ObsHeader, &ObsEpoch),
) -> Result<ObsHeader, ObsError> {
    let mut r = ObsReader::new(data, file_name)?;
    let mut e = ObsEpoch::default();
    while r.next_epoch(&mut e)? {
        each(&r.header, &e);
    }
    Ok(r.header)
}

impl<R: BufRead> ObsReader<R> {
    /// Reads the header of an observation file from `inner`; `file_name` is used in
    /// messages only.
    ///
    /// # Errors
    /// An [`ObsError`] naming the line: no `RINEX VERSION / TYPE` first line, a file type
    /// other than `O` (a Hatanaka-compressed file is named as such), a version other than
    /// 2.xx or 3.0x, an unreadable header value, an observation-type list shorter than its
    /// count or longer than [`MAX_OBS_TYPES`], no observation types, a GLONASS time
    /// system, or no `END OF HEADER`.
    pub fn new(inner: R, file_name: &str) -> Result<Self, ObsError> {
        let mut r = Self {
            inner,
            file: file_name.to_string(),
            header: ObsHeader {
                version: 0.0,
                file_system: 'G',
                marker_name: String::new(),
                approx_pos_ecef_m: None,
                interval_s: None,
                time_of_first_obs: None,
                time_system: TimeSystem::Gps,
                obs_types: Vec::new(),
            },
            line_no: 0,
            bytes: Vec::with_capacity(128),
            line: String::with_capacity(128),
        };
        r.read_header()?;
        Ok(r)
    }

    /// The header.
    pub fn header(&self) -> &ObsHeader {
        &self.header
    }

    /// Reads the next epoch with observations into `out` (flags 0, 1 and 6; event records
    /// are skipped). `Ok(false)` at the end of the file.
    ///
    /// # Errors
    /// An [`ObsError`] naming the line and column: an epoch line that is not one (no `>`
    /// in RINEX 3, a flag other than 0–6, a bad date or satellite count), a satellite
    /// identifier or value that does not parse, a RINEX 3 satellite of a system without
    /// observation types, or a file that ends inside an epoch.
    pub fn next_epoch(&mut self, out: &mut ObsEpoch) -> Result<bool, ObsError> {
        loop {
            if !self.next_line()? {
                return Ok(false);
            }
            // Blank lines between epochs carry nothing (some writers end files with one).
            if self.line.trim().is_empty() {
                continue;
            }
            let v2 = self.header.is_v2();
            let (flag_col, count_cols) = if v2 { (28, (29, 32)) } else { (31, (32, 35)) };
            if !v2 && !self.line.starts_with('>') {
                return Err(self.syntax(
                    Some(1),
                    "an epoch record starting with '>'",
                    quote(&self.line),
                ));
            }
            let flag = match self.line.as_bytes().get(flag_col) {
                Some(&b) if (b'0'..=b'6').contains(&b) => b - b'0',
                // A blank flag is 0 (RINEX 2.11 Table A2: "0: OK").
                Some(b' ') | None if v2 => 0,
                _ => {
                    let found = self.field(flag_col, flag_col + 1)?.to_string();
                    return Err(self.syntax(
                        Some(flag_col + 1),
                        "an epoch flag 0–6",
                        quote(&found),
                    ));
                }
            };
            let n = self.int(count_cols.0, count_cols.1, "the number of satellites (I3)")?;
            let Ok(n) = usize::try_from(n) else {
                return Err(self.syntax(
                    Some(count_cols.0 + 1),
                    "a number of satellites or special records ≥ 0",
                    n.to_string(),
                ));
            };
            if (2..=5).contains(&flag) {
                // Event records: n special lines follow. Those of flag 4 are header lines,
                // and a new observation-type list among them (RINEX 2.11 §5.4, RINEX 3.04
                // §5.2: a receiver that changes its signals mid-file) governs the epochs
                // after it; the other header lines change nothing this reader keeps.
                let line = self.line_no;
                let mut pending = None;
                for k in 0..n {
                    if !self.next_line()? {
                        return Err(self.truncated(format!(
                            "special record {} of {n} announced by the event (flag {flag}) at line {line}",
                            k + 1
                        )));
                    }
                    if flag == 4 {
                        self.types_header_line(&mut pending)?;
                    }
                }
                if let Some((sys, missing)) = pending {
                    return Err(self.syntax(
                        None,
                        format!(
                            "{missing} more observation types of system '{sys}' among the \
                             header records of the event at line {line}"
                        ),
                        "the end of those records",
                    ));
                }
                continue;
            }
            out.clear();
            out.flag = flag;
            out.line = self.line_no;
            out.t = self.epoch_time()?;
            out.clock_offset_s = if v2 {
                self.real_opt(68, 80, "a receiver clock offset (F12.9, s)")?
            } else {
                self.real_opt(41, 56, "a receiver clock offset (F15.12, s)")?
            };
            if v2 {
                self.read_body_v2(n, out)?;
            } else {
                self.read_body_v3(n, out)?;
            }
            return Ok(true);
        }
    }

    /// The satellite list (with continuation lines) and records of a RINEX 2 epoch.
    fn read_body_v2(&mut self, n: usize, out: &mut ObsEpoch) -> Result<(), ObsError> {
        let epoch_line = self.line_no;
        for i in 0..n {
            if i > 0 && i % 12 == 0 && !self.next_line()? {
                return Err(self.truncated(format!(
                    "the continuation of the satellite list of the epoch at line {epoch_line} \
                     ({n} satellites)"
                )));
            }
            let col = 32 + 3 * (i % 12);
            let sat = self.sat_id(col, true)?;
            out.sats.push(sat);
        }
        let n_types = self.header.obs_types(' ').map_or(0, <[String]>::len);
        for k in 0..n {
            let sat = out.sats[k];
            let lines = n_types.div_ceil(5).max(1);
            for j in 0..lines {
                if !self.next_line()? {
                    return Err(self.truncated(format!(
                        "observation line {} of {lines} of {sat} in the epoch at line {epoch_line}",
                        j + 1
                    )));
                }
                for f in 0..(n_types - 5 * j).min(5) {
                    let v = self.obs_value(16 * f)?;
                    out.values.push(v);
                }
            }
            out.starts.push(out.values.len());
        }
        Ok(())
    }

    /// The satellite records of a RINEX 3 epoch.
    fn read_body_v3(&mut self, n: usize, out: &mut ObsEpoch) -> Result<(), ObsError> {
        let epoch_line = self.line_no;
        for k in 0..n {
            if !self.next_line()? {
                return Err(self.truncated(format!(
                    "the record of satellite {} of {n} of the epoch at line {epoch_line}",
                    k + 1
                )));
            }
            if self.line.starts_with('>') {
                return Err(self.syntax(
                    Some(1),
                    format!(
                        "the record of satellite {} of {n} of the epoch at line {epoch_line}",
                        k + 1
                    ),
                    "a new epoch record (the epoch is truncated or its satellite count is wrong)",
                ));
            }
            let sat = self.sat_id(0, false)?;
            let Some(n_types) = self.header.obs_types(sat.system).map(<[String]>::len) else {
                return Err(self.syntax(
                    Some(1),
                    "a satellite of a system the header declares observation types for \
                     (SYS / # / OBS TYPES)",
                    format!("{sat}"),
                ));
            };
            out.sats.push(sat);
            for f in 0..n_types {
                let v = self.obs_value(3 + 16 * f)?;
                out.values.push(v);
            }
            out.starts.push(out.values.len());
        }
        Ok(())
    }

    /// The time tag of the epoch line in `line`, in GPST.
    fn epoch_time(&self) -> Result<GpsTime, ObsError> {
        let v2 = self.header.is_v2();
        let (y, mo, d, h, mi, sec_cols) = if v2 {
            let yy = self.int(1, 3, "a two-digit year (I2)")?;
            // RINEX 2.11 §6.5: two-digit years 80–99 are 1980–1999, 00–79 are 2000–2079.
            let y = if (80..=99).contains(&yy) {
                1900 + yy
            } else {
                2000 + yy
            };
            (
                y,
                self.int(4, 6, "a month (I2)")?,
                self.int(7, 9, "a day (I2)")?,
                self.int(10, 12, "an hour (I2)")?,
                self.int(13, 15, "a minute (I2)")?,
                (15, 26),
            )
        } else {
            (
                self.int(2, 6, "a year (I4)")?,
                self.int(7, 9, "a month (I2)")?,
                self.int(10, 12, "a day (I2)")?,
                self.int(13, 15, "an hour (I2)")?,
                self.int(16, 18, "a minute (I2)")?,
                (18, 29),
            )
        };
        let sec = self
            .real_opt(sec_cols.0, sec_cols.1, "seconds (F11.7)")?
            .ok_or_else(|| self.syntax(Some(sec_cols.0 + 1), "seconds (F11.7)", "a blank field"))?;
        let t = gpst_from_calendar(y, mo, d, h, mi, sec).ok_or_else(|| {
            self.syntax(
                Some(1),
                "a valid epoch date (years 1980–2200, seconds 0–60)",
                quote(self.field(0, sec_cols.1).unwrap_or("")),
            )
        })?;
        Ok(match self.header.time_system {
            TimeSystem::Gps => t,
            TimeSystem::Bdt => t.add_ns(BDT_TO_GPST_NS),
        })
    }

    /// A satellite identifier (A1,I2) at `col`; in RINEX 2 a blank letter is GPS.
    fn sat_id(&self, col: usize, v2: bool) -> Result<SatId, ObsError> {
        let text = self.field(col, col + 3)?;
        let mut chars = text.chars();
        let letter = chars.next().unwrap_or(' ');
        let letter = if v2 && letter == ' ' { 'G' } else { letter };
        let prn = text.get(1..).unwrap_or("").trim();
        let ok_letter = matches!(letter, 'G' | 'R' | 'E' | 'C' | 'J' | 'S' | 'I' | 'T');
        match prn.parse::<u8>() {
            Ok(p) if ok_letter && (1..=99).contains(&p) && prn.len() <= 2 => Ok(SatId {
                system: letter,
                prn: p,
            }),
            _ => Err(self.syntax(
                Some(col + 1),
                "a satellite such as G05 or C19 (system letter G, R, E, C, J, S, I, \
                 then a PRN 1–99)",
                quote(text),
            )),
        }
    }

    /// One observation (F14.3, I1 LLI, I1 SSI) at `col` of the line; columns past the end
    /// of the line are blank.
    fn obs_value(&self, col: usize) -> Result<ObsValue, ObsError> {
        let value = self.real_opt(col, col + 14, "an observation (F14.3)")?;
        let digit = |c: usize, what: &str| -> Result<Option<u8>, ObsError> {
            match self.line.as_bytes().get(c) {
                None | Some(b' ') => Ok(None),
                Some(b) if b.is_ascii_digit() => Ok(Some(b - b'0')),
                Some(_) => Err(self.syntax(
                    Some(c + 1),
                    format!("a {what} digit or a blank"),
                    quote(self.field(c, c + 1).unwrap_or("?")),
                )),
            }
        };
        Ok(ObsValue {
            value,
            lli: digit(col + 14, "loss-of-lock indicator")?,
            ssi: digit(col + 15, "signal-strength indicator")?,
        })
    }

    /// Reads the header lines up to `END OF HEADER`.
    fn read_header(&mut self) -> Result<(), ObsError> {
        if !self.next_line()? {
            return Err(self.syntax(
                None,
                "a 'RINEX VERSION / TYPE' header line",
                "an empty file",
            ));
        }
        let label = self.label();
        if label != "RINEX VERSION / TYPE" {
            let found = if label.starts_with("CRINEX") {
                "a Hatanaka-compressed (CRINEX) file: decompress it with CRX2RNX first".to_string()
            } else {
                quote(&self.line)
            };
            return Err(self.syntax(None, "a 'RINEX VERSION / TYPE' header line", found));
        }
        let version_text = self.field(0, 9)?.trim().to_string();
        let version: f64 = version_text.parse().unwrap_or(f64::NAN);
        if !((2.0..3.0).contains(&version) || (3.0..3.06).contains(&version)) {
            return Err(ObsError::UnsupportedVersion {
                file: self.file.clone(),
                line: self.line_no,
                version: version_text,
            });
        }
        self.header.version = version;
        let file_type = self.line.as_bytes().get(20).copied().unwrap_or(b' ');
        if file_type != b'O' {
            let found = quote(self.field(20, 21)?);
            return Err(self.syntax(
                Some(21),
                "file type 'O' (observation data) in column 21 of the RINEX VERSION / TYPE line",
                found,
            ));
        }
        self.header.file_system = match self.line.as_bytes().get(40) {
            None | Some(b' ') => 'G',
            Some(&b) => b as char,
        };
        // A list whose count exceeds one line continues on the next lines of its label.
        let mut pending: Option<(char, usize)> = None;
        let mut time_system_text = String::new();
        loop {
            if !self.next_line()? {
                return Err(self.truncated("the header line 'END OF HEADER'".to_string()));
            }
            let label = self.label().to_string();
            match label.as_str() {
                "END OF HEADER" => break,
                "MARKER NAME" => self.header.marker_name = self.field(0, 60)?.trim().to_string(),
                "APPROX POSITION XYZ" => {
                    let x = self.real(0, 14, "an X coordinate (F14.4, m)")?;
                    let y = self.real(14, 28, "a Y coordinate (F14.4, m)")?;
                    let z = self.real(28, 42, "a Z coordinate (F14.4, m)")?;
                    self.header.approx_pos_ecef_m = Some(Vector3::new(x, y, z));
                }
                "INTERVAL" => {
                    let dt = self.real(0, 10, "an interval (F10.3, s)")?;
                    if dt < 0.0 {
                        return Err(self.syntax(Some(1), "an interval ≥ 0 s", dt.to_string()));
                    }
                    self.header.interval_s = Some(dt);
                }
                "TIME OF FIRST OBS" => {
                    let y = self.int(0, 6, "a year (I6)")?;
                    let mo = self.int(6, 12, "a month (I6)")?;
                    let d = self.int(12, 18, "a day (I6)")?;
                    let h = self.int(18, 24, "an hour (I6)")?;
                    let mi = self.int(24, 30, "a minute (I6)")?;
                    let s = self.real(30, 43, "seconds (F13.7)")?;
                    let t = gpst_from_calendar(y, mo, d, h, mi, s).ok_or_else(|| {
                        self.syntax(
                            Some(1),
                            "a valid date (years 1980–2200, seconds 0–60)",
                            quote(self.field(0, 43).unwrap_or("")),
                        )
                    })?;
                    self.header.time_of_first_obs = Some(t);
                    time_system_text = self.field(48, 51)?.trim().to_string();
                }
                _ => self.types_header_line(&mut pending)?,
            }
        }
        if let Some((sys, missing)) = pending {
            return Err(self.syntax(
                None,
                format!("{missing} more observation types of system '{sys}' before END OF HEADER"),
                "END OF HEADER",
            ));
        }
        if self.header.obs_types.is_empty() {
            let label = if self.header.is_v2() {
                "# / TYPES OF OBSERV"
            } else {
                "SYS / # / OBS TYPES"
            };
            return Err(self.syntax(
                None,
                format!("a '{label}' header line before END OF HEADER"),
                "none",
            ));
        }
        self.header.time_system = match time_system_text.as_str() {
            // RINEX 3.04 §5.4: files of one system default to that system's time; GPS
            // otherwise (and in RINEX 2 G and M files).
            "" if self.header.file_system == 'C' && !self.header.is_v2() => TimeSystem::Bdt,
            "" if self.header.file_system == 'R' => {
                return Err(self.time_system_error("GLO (implied by a GLONASS file)"));
            }
            "" | "GPS" | "GAL" | "QZS" | "IRN" => TimeSystem::Gps,
            "BDT" => TimeSystem::Bdt,
            other => return Err(self.time_system_error(&quote(other))),
        };
        if self.header.time_system == TimeSystem::Bdt {
            if let Some(t) = self.header.time_of_first_obs.as_mut() {
                *t = t.add_ns(BDT_TO_GPST_NS);
            }
        }
        Ok(())
    }

    /// An observation-type header line (`# / TYPES OF OBSERV` in RINEX 2, `SYS / # / OBS
    /// TYPES` in RINEX 3) read into the header; any other line is left alone.
    fn types_header_line(&mut self, pending: &mut Option<(char, usize)>) -> Result<(), ObsError> {
        match self.label() {
            "# / TYPES OF OBSERV" if self.header.is_v2() => {
                self.obs_types_line(pending, ' ', (0, 6), 10, 6, 9, 2)
            }
            "SYS / # / OBS TYPES" if !self.header.is_v2() => {
                let letter = self.line.chars().next().unwrap_or(' ');
                self.obs_types_line(pending, letter, (3, 6), 7, 4, 13, 3)
            }
            _ => Ok(()),
        }
    }

    fn time_system_error(&self, found: &str) -> ObsError {
        ObsError::Syntax {
            file: self.file.clone(),
            line: self.line_no,
            column: None,
            expected: "epochs in GPS, Galileo or BeiDou time (TIME OF FIRST OBS time system \
                       GPS, GAL or BDT; GLONASS time needs leap seconds this reader does \
                       not apply)"
                .to_string(),
            found: found.to_string(),
        }
    }

    /// One line of an observation-type list of system `letter` (`' '` in RINEX 2): the
    /// count in columns `count.0..count.1`, then `per_line` types of `width` characters,
    /// the first at column `first`, one every `pitch` columns (RINEX 2: I6, 9×(4X,A2);
    /// RINEX 3: A1, 2X, I3, 13×(1X,A3)). A line with a blank count (and, in RINEX 3, a
    /// blank letter) continues the list before it.
    #[allow(clippy::too_many_arguments)]
    fn obs_types_line(
        &mut self,
        pending: &mut Option<(char, usize)>,
        letter: char,
        count: (usize, usize),
        first: usize,
        pitch: usize,
        per_line: usize,
        width: usize,
    ) -> Result<(), ObsError> {
        let count_blank = self.field(count.0, count.1)?.trim().is_empty();
        let (sys, remaining) = match (*pending, count_blank) {
            (Some((sys, remaining)), true) if letter == ' ' || self.header.is_v2() => {
                (sys, remaining)
            }
            (_, false) => {
                let n = self.int(count.0, count.1, "a number of observation types")?;
                if !(1..=MAX_OBS_TYPES as i64).contains(&n) {
                    return Err(self.syntax(
                        Some(count.0 + 1),
                        format!("a number of observation types from 1 to {MAX_OBS_TYPES}"),
                        n.to_string(),
                    ));
                }
                if !self.header.is_v2()
                    && !matches!(letter, 'G' | 'R' | 'E' | 'C' | 'J' | 'S' | 'I')
                {
                    return Err(self.syntax(
                        Some(1),
                        "a system letter (G, R, E, C, J, S, I)",
                        quote(&letter.to_string()),
                    ));
                }
                if let Some((sys, missing)) = *pending {
                    return Err(self.syntax(
                        None,
                        format!("{missing} more observation types of system '{sys}'"),
                        "a new list",
                    ));
                }
                // A repeated system replaces its list.
                self.header.obs_types.retain(|(s, _)| *s != letter);
                self.header.obs_types.push((letter, Vec::new()));
                (letter, n as usize)
            }
            _ => {
                return Err(self.syntax(
                    Some(count.0 + 1),
                    "a number of observation types",
                    "a blank field (a continuation line without a list to continue)",
                ))
            }
        };
        let take = remaining.min(per_line);
        let mut codes = Vec::with_capacity(take);
        for k in 0..take {
            let start = first + pitch * k;
            let code = self.field(start, start + width)?.trim().to_string();
            let valid = code.len() >= 2
                && code.bytes().all(|b| b.is_ascii_alphanumeric())
                && code.as_bytes()[0].is_ascii_uppercase();
            if !valid {
                let have = self.header.obs_types.last().map_or(0, |(_, l)| l.len());
                return Err(self.syntax(
                    Some(start + 1),
                    format!(
                        "observation type {} of {}{} (such as {})",
                        have + codes.len() + 1,
                        if sys == ' ' { "the file" } else { "system " },
                        if sys == ' ' {
                            String::new()
                        } else {
                            format!("'{sys}'")
                        },
                        if width == 2 { "C1 or L2" } else { "C1C or L2I" }
                    ),
                    quote(&code),
                ));
            }
            codes.push(code);
        }
        // The list being filled is always the last one pushed.
        if let Some((_, list)) = self.header.obs_types.last_mut() {
            list.extend(codes);
        }
        let left = remaining - take;
        *pending = (left > 0).then_some((sys, left));
        Ok(())
    }

    /// Reads the next line into `line` (without its line ending). `Ok(false)` at the end.
    fn next_line(&mut self) -> Result<bool, ObsError> {
        self.bytes.clear();
        let limit = MAX_LINE_BYTES as u64 + 1;
        let n = (&mut self.inner)
            .take(limit)
            .read_until(b'\n', &mut self.bytes)
            .map_err(|io| ObsError::Io {
                file: self.file.clone(),
                io,
            })?;
        if n == 0 {
            return Ok(false);
        }
        self.line_no += 1;
        if self.bytes.last() == Some(&b'\n') {
            self.bytes.pop();
            if self.bytes.last() == Some(&b'\r') {
                self.bytes.pop();
            }
        } else if n as u64 == limit {
            return Err(self.syntax(
                None,
                format!("a line of at most {MAX_LINE_BYTES} bytes"),
                "a longer line",
            ));
        }
        self.line.clear();
        // RINEX is ASCII: a stray byte beyond it is replaced, so that it cannot end the
        // read in a comment; in a data field the replacement fails that field's parse.
        self.line.push_str(&String::from_utf8_lossy(&self.bytes));
        Ok(true)
    }

    /// The header label (columns 61–80), trimmed.
    fn label(&self) -> &str {
        self.line.get(60..).map_or("", |s| s.trim())
    }

    /// Columns `start..end` of the line, shortened when the line is shorter.
    fn field(&self, start: usize, end: usize) -> Result<&str, ObsError> {
        let end = end.min(self.line.len());
        if start >= end {
            return Ok("");
        }
        self.line.get(start..end).ok_or_else(|| {
            self.syntax(
                Some(start + 1),
                "ASCII text",
                "a character outside ASCII".to_string(),
            )
        })
    }

    fn int(&self, start: usize, end: usize, what: &str) -> Result<i64, ObsError> {
        let f = self.field(start, end)?;
        f.trim()
            .parse::<i64>()
            .map_err(|_| self.syntax(Some(start + 1), what, quote(f)))
    }

    fn real_opt(&self, start: usize, end: usize, what: &str) -> Result<Option<f64>, ObsError> {
        let f = self.field(start, end)?;
        parse_fortran_f64(f).map_err(|_| self.syntax(Some(start + 1), what, quote(f)))
    }

    fn real(&self, start: usize, end: usize, what: &str) -> Result<f64, ObsError> {
        self.real_opt(start, end, what)?
            .ok_or_else(|| self.syntax(Some(start + 1), what, "a blank field"))
    }

    fn syntax(
        &self,
        column: Option<usize>,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> ObsError {
        ObsError::Syntax {
            file: self.file.clone(),
            line: self.line_no.max(1),
            column,
            expected: expected.into(),
            found: found.into(),
        }
    }

    fn truncated(&self, expected: String) -> ObsError {
        ObsError::Truncated {
            file: self.file.clone(),
            line: self.line_no + 1,
            expected,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header line: `content` in columns 1–60, `label` in 61–80.
    fn h(content: &str, label: &str) -> String {
        format!("{content:<60}{label:<20}\n")
    }

    /// A RINEX 2.11 mixed file with ten observation types (a continuation line of the
    /// type list, two record lines per satellite), 13 satellites in the first epoch (a
    /// continuation line of the satellite list), an event with header records (flag 4),
    /// an external event without records (flag 5) and a power-failure epoch (flag 1).
    fn v2_file() -> String {
        let types = ["L1", "L2", "C1", "P1", "P2", "D1", "D2", "S1", "S2", "C2"];
        let mut s = h(
            "     2.11           OBSERVATION DATA    M (MIXED)",
            "RINEX VERSION / TYPE",
        );
        s += &h("TEST", "MARKER NAME");
        s += &h(
            " -3976219.5082  3382372.5671  3652512.9849",
            "APPROX POSITION XYZ",
        );
        let list = |ts: &[&str]| ts.iter().map(|t| format!("{t:>6}")).collect::<String>();
        s += &h(
            &format!("    10{}", list(&types[..9])),
            "# / TYPES OF OBSERV",
        );
        s += &h(
            &format!("      {}", list(&types[9..])),
            "# / TYPES OF OBSERV",
        );
        s += &h("    30.000", "INTERVAL");
        s += &h(
            "  2005     4     2     0     0    0.0000000     GPS",
            "TIME OF FIRST OBS",
        );
        s += &h("", "END OF HEADER");
        let sats = [
            "G01", "G02", "G03", "G04", "G05", "G06", "R07", "G08", "G09", "G10", "G11", "G12",
            "E13",
        ];
        s += &format!(
            " 05  4  2  0  0  0.0000000  0 13{} 0.000123456\n",
            sats[..12].concat()
        );
        s += &format!("{:32}{}\n", "", sats[12]);
        for i in 0..13 {
            let c1 = 2.1e7 + 1000.0 * i as f64;
            s += &format!(
                "{:14.3}17{:14.3}  {c1:14.3} 6{:16}{:14.3}\n",
                1e8 + i as f64,
                7.8e7,
                "",
                c1 + 3.2
            );
            s += &format!(
                "{:14.3}  {:14.3}  {:14.3}  {:14.3}  {:14.3}\n",
                -1234.5,
                -961.9,
                45.0,
                30.25,
                c1 + 1.5
            );
        }
        s += " 05  4  2  0  0 15.0000000  4  2\n";
        s += &h("event: a header record", "COMMENT");
        s += &h(
            "        1.5000        0.0000        0.0000",
            "ANTENNA: DELTA H/E/N",
        );
        s += "                            5  0\n";
        s += " 05  4  2  0  0 30.0000000  1  1G05\n";
        // The second record line is blank (all five values missing), trailing blanks
        // dropped as RINEX 2.11 §6.3 allows.
        s += &format!("{:14.3}  {:14.3}  {:14.3}\n\n", 1e8, 7e7, 2.2e7);
        s
    }

    fn read(text: &str) -> Result<(ObsHeader, Vec<ObsEpoch>), ObsError> {
        let mut out = Vec::new();
        let header = read_all(text.as_bytes(), "t.obs", |_, e| out.push(e.clone()))?;
        Ok((header, out))
    }

    #[test]
    fn reads_rinex2_continuations_events_and_indicators() {
        let (hd, epochs) = read(&v2_file()).unwrap();
        assert_eq!(hd.marker_name, "TEST");
        assert_eq!(hd.interval_s, Some(30.0));
        assert_eq!(hd.obs_types('G').unwrap().len(), 10);
        assert_eq!(hd.index_of('R', "C2"), Some(9));
        assert_eq!(
            hd.approx_pos_ecef_m,
            Some(Vector3::new(-3976219.5082, 3382372.5671, 3652512.9849))
        );
        // The events (flags 4 and 5) are skipped: two epochs remain.
        assert_eq!(epochs.len(), 2);
        let e = &epochs[0];
        assert_eq!(e.len(), 13);
        assert_eq!(
            e.sats()[6],
            SatId {
                system: 'R',
                prn: 7
            }
        );
        assert_eq!(
            e.sats()[12],
            SatId {
                system: 'E',
                prn: 13
            }
        );
        assert_eq!(e.clock_offset_s, Some(0.000123456));
        assert_eq!(e.t, GpsTime::from_week_tow(1316, 518_400.0));
        let v = e.values(4);
        assert_eq!(v.len(), 10);
        assert_eq!(v[0].value, Some(1e8 + 4.0));
        assert_eq!((v[0].lli, v[0].ssi), (Some(1), Some(7)));
        assert_eq!(
            (v[2].value, v[2].lli, v[2].ssi),
            (Some(21_004_000.0), None, Some(6))
        );
        assert_eq!(v[3], ObsValue::default());
        assert_eq!(v[4].value, Some(21_004_003.2));
        assert_eq!(v[9].value, Some(21_004_001.5));
        let last = &epochs[1];
        assert_eq!((last.flag, last.len()), (1, 1));
        assert_eq!(last.t, GpsTime::from_week_tow(1316, 518_430.0));
        // A blank record line holds five missing values.
        let w = last.values(0);
        assert_eq!(w.len(), 10);
        assert_eq!(w[2].value, Some(2.2e7));
        assert!(w[3..].iter().all(|o| o.value.is_none()));
    }

    fn v3_file(sys: char, tos: &str) -> String {
        let mut s = h(
            &format!("     3.04           OBSERVATION DATA    {sys}"),
            "RINEX VERSION / TYPE",
        );
        s += &h("C    4 C2I L2I D2I S2I", "SYS / # / OBS TYPES");
        s += &h(
            "G   15 C1C L1C D1C S1C C2W L2W D2W S2W C5Q L5Q D5Q S5Q C1W",
            "SYS / # / OBS TYPES",
        );
        s += &h("       L1W S1W", "SYS / # / OBS TYPES");
        s += &h(
            &format!("  2020     6    25     4     0    0.0000000     {tos}"),
            "TIME OF FIRST OBS",
        );
        s += &h("", "END OF HEADER");
        s += "> 2020 06 25 04 00  0.0000000  0  2       0.000000001000\n";
        s += "C19  21284135.528 7 111848395.59017     -2601.595 7        45.701 7\n";
        s += &format!("G05{:14.3}  {:>222}\n", 2.2e7, "42.000  ");
        s
    }

    #[test]
    fn reads_rinex3_per_system_types_and_bdt() {
        let (hd, epochs) = read(&v3_file('M', "GPS")).unwrap();
        assert_eq!(hd.obs_types('G').unwrap().len(), 15);
        assert_eq!(hd.index_of('G', "S1W"), Some(14));
        assert_eq!(hd.index_of('C', "C2I"), Some(0));
        assert_eq!(hd.obs_types('E'), None);
        let e = &epochs[0];
        assert_eq!(e.clock_offset_s, Some(1e-9));
        assert_eq!(e.values(0)[1].value, Some(111_848_395.590));
        assert_eq!((e.values(0)[1].lli, e.values(0)[1].ssi), (Some(1), Some(7)));
        assert_eq!(e.values(1).len(), 15);
        assert_eq!(e.values(1)[0].value, Some(2.2e7));
        assert_eq!(e.values(1)[14].value, Some(42.0));
        let t_gps = e.t;
        // The same tag in BeiDou time is 14 s later in GPST.
        let (_, bdt) = read(&v3_file('C', "BDT")).unwrap();
        assert_eq!(bdt[0].t.seconds_since(t_gps), 14.0);
    }

    #[test]
    fn errors_name_the_line_column_and_what_was_expected() {
        let v2 = v2_file();
        // A value that is not a number.
        let bad = v2.replacen("21002000.000", "2100x000.000", 1);
        let e = read(&bad).unwrap_err();
        assert_eq!(e.line(), Some(15), "{e}");
        assert!(e.to_string().contains("column 33"), "{e}");
        assert!(e.to_string().contains("an observation (F14.3)"), "{e}");
        // The file ends inside an epoch.
        let cut: String = v2.lines().take(20).map(|l| format!("{l}\n")).collect();
        let e = read(&cut).unwrap_err();
        assert!(matches!(e, ObsError::Truncated { line: 21, .. }), "{e}");
        assert!(e.to_string().contains("of G06"), "{e}");
        // A satellite count that is not a number.
        let e = read(&v2.replacen("  0 13G01", "  0 1xG01", 1)).unwrap_err();
        assert!(e.to_string().contains("line 9, column 30"), "{e}");
        // RINEX 3: one satellite fewer than announced runs into the next epoch.
        let v3 = v3_file('M', "GPS");
        let two = format!("{v3}{}", v3.lines().skip(6).collect::<Vec<_>>().join("\n"));
        let short = two.replacen("  0  2       0.0", "  0  3       0.0", 1);
        let e = read(&short).unwrap_err();
        assert!(e.to_string().contains("a new epoch record"), "{e}");
        assert_eq!(e.line(), Some(10));
        // A satellite of a system without types.
        let e = read(&v3.replace("C19  ", "E19  ")).unwrap_err();
        assert!(e.to_string().contains("SYS / # / OBS TYPES"), "{e}");
        // Header problems.
        let e = read(&v2.replacen("2.11", "4.01", 1)).unwrap_err();
        assert!(matches!(e, ObsError::UnsupportedVersion { .. }), "{e}");
        let e = read(&v2.replacen("OBSERVATION DATA", "NAVIGATION DATA ", 1)).unwrap_err();
        assert!(e.to_string().contains("file type 'O'"), "{e}");
        let e = read(&v2.replace("END OF HEADER", "END OF HEADEX")).unwrap_err();
        assert!(e.to_string().contains("END OF HEADER"), "{e}");
        let e = read(&v3_file('R', "GLO")).unwrap_err();
        assert!(e.to_string().contains("GLONASS time"), "{e}");
        let e = read(
            "1.0                 COMPACT RINEX FORMAT                    CRINEX VERS   / TYPE\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("Hatanaka"), "{e}");
    }

    #[test]
    fn an_event_with_a_new_type_list_governs_the_epochs_after_it() {
        // Flag 4 with a header record that cuts the list to two types (C1, P2).
        let mut s = v2_file();
        s += " 05  4  2  0  1  0.0000000  4  1\n";
        s += &h("     2    C1    P2", "# / TYPES OF OBSERV");
        s += " 05  4  2  0  1 30.0000000  0  1G05\n";
        s += &format!("{:14.3}  {:14.3}\n", 2.2e7, 2.2e7 + 1.0);
        let (hd, epochs) = read(&s).unwrap();
        assert_eq!(epochs.len(), 3);
        assert_eq!(hd.obs_types('G').unwrap(), ["C1", "P2"]);
        assert_eq!(epochs[2].values(0).len(), 2);
        assert_eq!(epochs[2].values(0)[1].value, Some(2.2e7 + 1.0));
        // A list announced longer than its line, without the continuation line.
        let bad = s.replace(
            "     2    C1    P2",
            "    10    C1    P2    L1    L2    D1    D2    S1    S2    C2",
        );
        let e = read(&bad).unwrap_err();
        assert!(
            e.to_string().contains("1 more observation types of system ' ' among the header records of the event at line 44"),
            "{e}"
        );
    }

    #[test]
    fn short_lines_and_non_ascii_never_panic() {
        for text in [v2_file(), v3_file('M', "GPS")] {
            for cut in 0..text.len() {
                let _ = read(&text[..cut]);
            }
            let weird = text.replacen("0.000", "0.€00", 3).replace("TYPES", "TŸPES");
            let _ = read(&weird);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(400))]
        /// Random single-character damage anywhere in a valid file gives Ok or a typed
        /// error, never a panic, and every satellite keeps its system's number of values.
        #[test]
        fn damaged_files_never_panic(pos in 0usize..6000, c in proptest::char::any(), v3 in proptest::bool::ANY) {
            let base = if v3 { v3_file('M', "GPS") } else { v2_file() };
            let mut chars: Vec<char> = base.chars().collect();
            let at = pos % chars.len();
            chars[at] = c;
            let text: String = chars.into_iter().collect();
            let _ = read_all(text.as_bytes(), "fuzz", |hd, e| {
                for (sat, v) in e.iter() {
                    assert_eq!(v.len(), hd.obs_types(sat.system).map_or(0, <[String]>::len));
                }
            });
        }
    }
}
