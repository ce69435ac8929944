//! Reader of SP3-c and SP3-d precise orbit files (NGS/IGS "The Extended Standard Product 3
//! Orbit Format (SP3-c)", 2010; SP3-d, 2016). Only position records (`P`) are used;
//! velocity (`V`) and correlation (`EP`, `EV`) records are passed over.
//!
//! Layout (0-based columns):
//!
//! ```text
//! line 1   #cP|#dP, start epoch yyyy mm dd hh mm ss.ssssssss (cols 3-31), epochs (32-39),
//!          data used (40-44), coordinate system (46-50), orbit type (52-54), agency (56-59)
//! %c       first %c line: file type (cols 3-4), time system (cols 9-11): GPS, GLO, GAL, BDT, TAI, UTC
//! *        epoch header: yyyy mm dd hh mm ss.ssssssss (cols 3-30)
//! P        PG01 x y z (km, F14.6 at cols 4, 18, 32), clock (µs, F14.6 at col 46)
//! ```
//!
//! Positions are converted to metres and clocks to seconds. A clock of 999999.999999 µs
//! means "no value" (`clock_s = None`); a position of 0.000000 in all three axes (or any
//! axis at 999999.999999) means "no position" and the sample is absent. Epochs are
//! returned as [`GpsTime`] whatever the file's time system (GPS, GAL and QZS are GPST;
//! BDT = GPST − 14 s; TAI = GPST + 19 s; UTC is converted with the leap seconds in force).
//! Only GPS (`G`) and BeiDou (`C`) satellites are kept; the others are counted per letter.

use crate::core::{EmitterId, GpsTime, System};
use crate::gnss::rinex_nav::{gpst_from_calendar, parse_fortran_f64};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::path::Path;

/// A failure to read an SP3 file: the file, the 1-based line and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum Sp3Error {
    /// The file could not be read.
    #[error("{file}: cannot read the file: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// A line or field does not hold what the format requires.
    #[error("{file}, line {line}: expected {expected}, found {found}")]
    Syntax {
        file: String,
        line: usize,
        expected: String,
        found: String,
    },
}

impl Sp3Error {
    /// The 1-based line number, when the error is about the file's content.
    pub fn line(&self) -> Option<usize> {
        match self {
            Sp3Error::Io { .. } => None,
            Sp3Error::Syntax { line, .. } => Some(*line),
        }
    }
}

/// One precise position (and clock) of one satellite at one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sp3Sample {
    /// Centre-of-mass position in the file's terrestrial frame (m).
    pub pos_ecef_m: Vector3<f64>,
    /// Clock offset (s), `None` when the file flags it as missing.
    pub clock_s: Option<f64>,
}

/// The content of an SP3 file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sp3Data {
    /// Format version letter (`c` or `d`; `a`/`b` are accepted too).
    pub version: char,
    /// Time system of the file as written (`GPS` when the file does not say).
    pub time_system: String,
    /// Coordinate system label, e.g. `IGS14`.
    pub coordinate_system: String,
    /// Agency label.
    pub agency: String,
    /// The epochs, in file order, converted to GPS time.
    pub epochs: Vec<GpsTime>,
    /// Per GPS/BeiDou satellite, one entry per epoch (index as in `epochs`); `None` where
    /// the satellite has no (valid) position at that epoch.
    pub samples: BTreeMap<EmitterId, Vec<Option<Sp3Sample>>>,
    /// Number of position records skipped per system letter (systems other than G and C).
    pub skipped: BTreeMap<char, usize>,
}

impl Sp3Data {
    /// The satellites with at least one sample, sorted.
    pub fn satellites(&self) -> Vec<EmitterId> {
        self.samples
            .iter()
            .filter(|(_, v)| v.iter().any(Option::is_some))
            .map(|(k, _)| *k)
            .collect()
    }

    /// The sample of `sat` at epoch index `epoch_index`, if any.
    pub fn sample(&self, sat: EmitterId, epoch_index: usize) -> Option<&Sp3Sample> {
        self.samples.get(&sat)?.get(epoch_index)?.as_ref()
    }

    /// All valid samples of `sat` with their epochs.
    pub fn track(&self, sat: EmitterId) -> impl Iterator<Item = (GpsTime, &Sp3Sample)> + '_ {
        let v = self.samples.get(&sat);
        self.epochs
            .iter()
            .enumerate()
            .filter_map(move |(i, t)| Some((*t, v?.get(i)?.as_ref()?)))
    }
}

/// Reads an SP3 file from disk; see [`parse_sp3`].
///
/// # Errors
/// [`Sp3Error::Io`] when the file cannot be read, otherwise as [`parse_sp3`].
pub fn read_sp3_file(path: &Path) -> Result<Sp3Data, Sp3Error> {
    let file = path.display().to_string();
    let bytes =
        crate::io::read::read_bytes(path, crate::io::read::SP3).map_err(|source| Sp3Error::Io {
            file: file.clone(),
            source,
        })?;
    parse_sp3(&String::from_utf8_lossy(&bytes), &file)
}

/// Missing-value marker of SP3 positions and clocks.
const BAD_VALUE: f64 = 999_999.0;

/// Parses the text of an SP3-a/b/c/d file. `file_name` is only used in error messages.
///
/// # Errors
/// An [`Sp3Error`] naming the file, line and expected content for: an empty file or a
/// first line that is not `#a`..`#d`; an unknown time system; an invalid epoch; a `P`
/// record before the first epoch, with a bad satellite id or with unparsable numbers.
pub fn parse_sp3(text: &str, file_name: &str) -> Result<Sp3Data, Sp3Error> {
    let err = |idx: usize, expected: &str, found: &str| Sp3Error::Syntax {
        file: file_name.to_string(),
        line: idx + 1,
        expected: expected.to_string(),
        found: if found.trim().is_empty() {
            "a blank field".to_string()
        } else {
            format!(
                "'{}'",
                found.trim_end().chars().take(40).collect::<String>()
            )
        },
    };
    let cols = |line: &str, a: usize, b: usize| -> Option<String> {
        let b = b.min(line.len());
        if a >= b {
            Some(String::new())
        } else {
            line.get(a..b).map(str::to_string)
        }
    };

    let lines: Vec<&str> = text.lines().collect();
    let first = lines
        .first()
        .ok_or_else(|| err(0, "an SP3 header line starting with '#c' or '#d'", ""))?;
    let version = first.chars().nth(1).unwrap_or(' ');
    if !first.starts_with('#') || !matches!(version, 'a' | 'b' | 'c' | 'd') {
        return Err(err(
            0,
            "an SP3 header line starting with '#a', '#b', '#c' or '#d'",
            first,
        ));
    }
    let mut data = Sp3Data {
        version,
        time_system: "GPS".to_string(),
        coordinate_system: cols(first, 46, 51).unwrap_or_default().trim().to_string(),
        agency: cols(first, 56, 60).unwrap_or_default().trim().to_string(),
        ..Sp3Data::default()
    };
    let mut seen_time_system = false;
    // Offset added to a calendar reading in the file's time scale to get GPST (ns); for
    // UTC the offset depends on the date and is computed per epoch.
    let mut offset_ns: Option<i64> = Some(0);

    for (idx, line) in lines.iter().enumerate().skip(1) {
        let line = *line;
        if line.starts_with("%c") && !seen_time_system {
            seen_time_system = true;
            let ts = cols(line, 9, 12).unwrap_or_default().trim().to_string();
            offset_ns = match ts.as_str() {
                // "ccc" is the SP3 placeholder: the default, GPS.
                "GPS" | "GAL" | "QZS" | "ccc" | "" => Some(0),
                "BDT" => Some(14_000_000_000),
                "TAI" => Some(-19_000_000_000),
                "UTC" => None,
                _ => return Err(err(idx, "a time system GPS, GAL, QZS, BDT, TAI or UTC in columns 10-12 of the first %c line", &ts)),
            };
            if ts != "ccc" && !ts.is_empty() {
                data.time_system = ts;
            }
        } else if line.starts_with('*') {
            let num = |a: usize, b: usize, what: &str| -> Result<i64, Sp3Error> {
                let f = cols(line, a, b).unwrap_or_default();
                f.trim().parse::<i64>().map_err(|_| {
                    err(
                        idx,
                        &format!("the epoch {what} (columns {}-{})", a + 1, b),
                        &f,
                    )
                })
            };
            let y = num(3, 7, "year")?;
            let mo = num(8, 10, "month")?;
            let d = num(11, 13, "day")?;
            let h = num(14, 16, "hour")?;
            let mi = num(17, 19, "minute")?;
            let sec_text = cols(line, 20, 31).unwrap_or_default();
            let sec = parse_fortran_f64(&sec_text)
                .ok()
                .flatten()
                .ok_or_else(|| err(idx, "the epoch seconds (columns 21-31)", &sec_text))?;
            let cal = gpst_from_calendar(y, mo, d, h, mi, sec)
                .ok_or_else(|| err(idx, "a valid epoch date and time", line))?;
            let t = match offset_ns {
                Some(o) => cal.add_ns(o),
                None => {
                    // UTC reading: GPST = UTC + leap seconds at that date.
                    let leap = GpsTime::from_utc(y as i32, mo as u8, d as u8, 0, 0, 0, 0)
                        .gpst_minus_utc_s();
                    cal.add_ns(leap * 1_000_000_000)
                }
            };
            data.epochs.push(t);
        } else if line.starts_with('P') {
            if data.epochs.is_empty() {
                return Err(err(
                    idx,
                    "an epoch line ('*') before the first position record",
                    line,
                ));
            }
            let id =
                cols(line, 1, 4).ok_or_else(|| err(idx, "a satellite id in columns 2-4", line))?;
            let letter = id.chars().next().unwrap_or(' ');
            // SP3-a files write GPS satellites as a bare number.
            let letter = if letter == ' ' { 'G' } else { letter };
            let prn: u16 = match id.get(1..).map(str::trim).and_then(|s| s.parse().ok()) {
                Some(p) if (1..=99).contains(&p) => p,
                _ => {
                    return Err(err(
                        idx,
                        "a satellite id such as G01 or C05 in columns 2-4",
                        &id,
                    ))
                }
            };
            let system = match letter {
                'G' => System::Gps,
                'C' => System::Bds,
                c if c.is_ascii_uppercase() => {
                    *data.skipped.entry(c).or_insert(0) += 1;
                    continue;
                }
                _ => return Err(err(idx, "a satellite system letter in column 2", &id)),
            };
            let mut v = [0.0; 4];
            for (k, slot) in v.iter_mut().enumerate() {
                let (a, b) = (4 + 14 * k, 18 + 14 * k);
                let f = cols(line, a, b).ok_or_else(|| err(idx, "ASCII text", line))?;
                let what = ["x (km)", "y (km)", "z (km)", "clock (µs)"][k];
                *slot = match parse_fortran_f64(&f) {
                    Ok(Some(x)) => x,
                    // A blank clock is a missing clock; a blank coordinate is an error.
                    Ok(None) if k == 3 => 999_999.999_999,
                    _ => {
                        return Err(err(
                            idx,
                            &format!(
                                "the {what} of {letter}{prn:02} (F14.6 in columns {}-{})",
                                a + 1,
                                b
                            ),
                            &f,
                        ))
                    }
                };
            }
            let sat = EmitterId::new(system, prn);
            let n_epochs = data.epochs.len();
            let track = data.samples.entry(sat).or_default();
            track.resize(n_epochs, None);
            let absent = (v[0] == 0.0 && v[1] == 0.0 && v[2] == 0.0)
                || v[..3].iter().any(|c| c.abs() >= BAD_VALUE);
            track[n_epochs - 1] = if absent {
                None
            } else {
                Some(Sp3Sample {
                    pos_ecef_m: Vector3::new(v[0], v[1], v[2]) * 1e3,
                    clock_s: if v[3].abs() >= BAD_VALUE {
                        None
                    } else {
                        Some(v[3] * 1e-6)
                    },
                })
            };
        } else if line.starts_with("EOF") {
            break;
        }
        // Header lines (##, +, ++, %f, %i, /*), velocity and correlation records need no
        // action.
    }
    if data.epochs.is_empty() {
        return Err(err(
            lines.len(),
            "at least one epoch line ('*')",
            "end of file",
        ));
    }
    let n = data.epochs.len();
    for track in data.samples.values_mut() {
        track.resize(n, None);
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "#dP2020  6 25  0  0  0.00000000       2 __u+U IGS14 FIT  IAC
## 2111 345600.00000000   900.00000000 59025 0.0000000000000
+    4   C01G01R01E01  0  0  0  0  0  0  0  0  0  0  0  0  0
%c M  cc GPS ccc cccc cccc cccc cccc ccccc ccccc ccccc ccccc
%c cc cc ccc ccc cccc cccc cccc cccc ccccc ccccc ccccc ccccc
/* comment
*  2020 06 25  0  0  0.00000000
PC01 -34346.145771  24493.239073    626.704364   -387.166264
PG01  18392.619117   7490.690408 -17846.346485 999999.999999
PR01 -12699.804671   5258.967720  21500.325395   -392.016830
*  2020 06 25  0 15  0.00000000
PC01 -34346.145000  24493.239000    626.704000
PG01      0.000000      0.000000      0.000000 999999.999999
PE01 -12699.804671   5258.967720  21500.325395   -392.016830
EOF
";

    #[test]
    fn reads_positions_and_flags() {
        let d = parse_sp3(SAMPLE, "s.sp3").unwrap();
        assert_eq!(d.version, 'd');
        assert_eq!(d.time_system, "GPS");
        assert_eq!(d.coordinate_system, "IGS14");
        assert_eq!(d.agency, "IAC");
        assert_eq!(d.epochs.len(), 2);
        assert_eq!(d.epochs[0], GpsTime::from_week_tow(2111, 345_600.0));
        assert_eq!(d.epochs[1], GpsTime::from_week_tow(2111, 346_500.0));
        let c01 = EmitterId::new(System::Bds, 1);
        let g01 = EmitterId::new(System::Gps, 1);
        let s = d.sample(c01, 0).unwrap();
        assert!((s.pos_ecef_m.x + 34_346_145.771).abs() < 1e-6);
        assert!((s.clock_s.unwrap() + 387.166264e-6).abs() < 1e-15);
        assert_eq!(d.sample(c01, 1).unwrap().clock_s, None);
        assert_eq!(d.sample(g01, 0).unwrap().clock_s, None);
        assert!(d.sample(g01, 1).is_none());
        assert_eq!(d.skipped.get(&'R'), Some(&1));
        assert_eq!(d.skipped.get(&'E'), Some(&1));
        assert_eq!(d.satellites(), vec![g01, c01]);
        assert_eq!(d.track(g01).count(), 1);
    }

    #[test]
    fn time_systems() {
        let bdt = SAMPLE.replacen("cc GPS ccc", "cc BDT ccc", 1);
        let d = parse_sp3(&bdt, "s.sp3").unwrap();
        assert_eq!(d.epochs[0], GpsTime::from_week_tow(2111, 345_614.0));
        let bad = SAMPLE.replacen("cc GPS ccc", "cc XYZ ccc", 1);
        let e = parse_sp3(&bad, "s.sp3").unwrap_err();
        assert_eq!(e.line(), Some(4));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        /// Random single-character damage gives Ok or a typed error, never a panic.
        #[test]
        fn damaged_files_never_panic(pos in 0usize..2000, c in proptest::char::any()) {
            let mut chars: Vec<char> = SAMPLE.chars().collect();
            let at = pos % chars.len();
            chars[at] = c;
            let text: String = chars.into_iter().collect();
            let _ = parse_sp3(&text, "fuzz");
        }
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse_sp3("", "e.sp3").unwrap_err();
        assert_eq!(e.line(), Some(1));
        let e = parse_sp3("     3.05           NAVIGATION DATA", "n.sp3").unwrap_err();
        assert!(e.to_string().contains("'#c' or '#d'"), "{e}");
        let bad = SAMPLE.replace("24493.239073", "24493.2x9073");
        let e = parse_sp3(&bad, "b.sp3").unwrap_err();
        assert_eq!(e.line(), Some(8));
        assert!(e.to_string().contains("y (km) of C01"), "{e}");
        let bad = SAMPLE.replace("*  2020 06 25  0 15", "*  2020 13 25  0 15");
        assert_eq!(parse_sp3(&bad, "b.sp3").unwrap_err().line(), Some(11));
        // Every prefix parses or fails cleanly.
        for cut in 0..SAMPLE.len() {
            let _ = parse_sp3(&SAMPLE[..cut], "p.sp3");
        }
    }
}
