//! Time scales and simulation time.
//!
//! Every instant inside hybridnav is a [`GpsTime`]: an integer count of nanoseconds since
//! the GPS epoch (1980-01-06T00:00:00 GPST). Integer time keeps the event queue exactly
//! ordered and makes runs bit-reproducible, as ns-3 does with its integer `Time`.
//! Conversions to and from calendar dates in UTC (with leap seconds) are delegated to
//! `hifitime`; BeiDou time is an exact offset (IS-GPS-200 / BDS-SIS-ICD):
//!
//! ```text
//! BDT = GPST − 14 s,   BDT week 0 began at GPS week 1356, seconds-of-week 14.
//! ```

use hifitime::{Epoch, TimeScale};
use std::fmt;

/// Nanoseconds in one second.
pub const NS_PER_S: i64 = 1_000_000_000;
/// Seconds in one GPS week.
pub const SECONDS_PER_WEEK: i64 = 604_800;
/// BDT lags GPST by exactly 14 s (BDS-SIS-ICD-2.0 §5.1.3).
pub const BDT_MINUS_GPST_S: i64 = -14;
/// GPS week in which the BDT epoch (2006-01-01T00:00:00 UTC) falls.
pub const BDT_EPOCH_GPS_WEEK: i64 = 1356;

/// An instant in GPS time, as integer nanoseconds since 1980-01-06T00:00:00 GPST.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct GpsTime {
    ns: i64,
}

/// A signed span of time in integer nanoseconds.
pub type DurationNs = i64;

impl GpsTime {
    /// Builds a time from nanoseconds since the GPS epoch.
    pub const fn from_ns(ns: i64) -> Self {
        Self { ns }
    }

    /// Nanoseconds since the GPS epoch.
    pub const fn ns(self) -> i64 {
        self.ns
    }

    /// Builds a time from a GPS week and seconds of week. Fractions below 1 ns are rounded.
    pub fn from_week_tow(week: i64, tow_s: f64) -> Self {
        let whole = tow_s.floor();
        let frac_ns = ((tow_s - whole) * 1e9).round() as i64;
        Self::from_ns((week * SECONDS_PER_WEEK + whole as i64) * NS_PER_S + frac_ns)
    }

    /// Builds a time from BDT week and BDT seconds of week.
    pub fn from_bdt_week_sow(bdt_week: i64, sow_s: f64) -> Self {
        let t = Self::from_week_tow(bdt_week + BDT_EPOCH_GPS_WEEK, sow_s);
        t.add_ns(-BDT_MINUS_GPST_S * NS_PER_S)
    }

    /// GPS week number (not rolled over at 1024).
    pub fn week(self) -> i64 {
        self.ns.div_euclid(SECONDS_PER_WEEK * NS_PER_S)
    }

    /// GPS seconds of week, `0 ≤ tow < 604800`.
    pub fn tow_s(self) -> f64 {
        let rem = self.ns.rem_euclid(SECONDS_PER_WEEK * NS_PER_S);
        (rem / NS_PER_S) as f64 + (rem % NS_PER_S) as f64 * 1e-9
    }

    /// BDT week and seconds of week: BDT = GPST − 14 s, week 0 = GPS week 1356.
    pub fn bdt_week_sow(self) -> (i64, f64) {
        let b = self.add_ns(BDT_MINUS_GPST_S * NS_PER_S);
        (b.week() - BDT_EPOCH_GPS_WEEK, b.tow_s())
    }

    /// Seconds since the GPS epoch as f64 (loses precision below ~0.1 µs for modern dates;
    /// use [`GpsTime::seconds_since`] for differences).
    pub fn as_seconds_f64(self) -> f64 {
        (self.ns / NS_PER_S) as f64 + (self.ns % NS_PER_S) as f64 * 1e-9
    }

    /// `self − earlier` in seconds, exact to the nanosecond before the conversion.
    pub fn seconds_since(self, earlier: GpsTime) -> f64 {
        let d = self.ns - earlier.ns;
        (d / NS_PER_S) as f64 + (d % NS_PER_S) as f64 * 1e-9
    }

    /// The time shifted by a number of nanoseconds.
    pub const fn add_ns(self, d: DurationNs) -> Self {
        Self { ns: self.ns + d }
    }

    /// The time shifted by seconds (rounded to the nanosecond).
    pub fn add_seconds(self, s: f64) -> Self {
        self.add_ns((s * 1e9).round() as i64)
    }

    /// Builds a time from a UTC calendar date, applying the leap seconds in force.
    pub fn from_utc(y: i32, mo: u8, d: u8, h: u8, mi: u8, s: u8, ns: u32) -> Self {
        Self::from_epoch(Epoch::from_gregorian(
            y,
            mo,
            d,
            h,
            mi,
            s,
            ns,
            TimeScale::UTC,
        ))
    }

    /// Builds a time from a calendar date read in the GPS time scale.
    pub fn from_gpst_calendar(y: i32, mo: u8, d: u8, h: u8, mi: u8, s: u8, ns: u32) -> Self {
        Self::from_epoch(Epoch::from_gregorian(
            y,
            mo,
            d,
            h,
            mi,
            s,
            ns,
            TimeScale::GPST,
        ))
    }

    /// Builds a time from a calendar date read in BeiDou time.
    pub fn from_bdt_calendar(y: i32, mo: u8, d: u8, h: u8, mi: u8, s: u8, ns: u32) -> Self {
        Self::from_gpst_calendar(y, mo, d, h, mi, s, ns).add_ns(-BDT_MINUS_GPST_S * NS_PER_S)
    }

    fn from_epoch(e: Epoch) -> Self {
        let ns = e
            .to_duration_in_time_scale(TimeScale::GPST)
            .total_nanoseconds();
        Self::from_ns(ns as i64)
    }

    fn to_epoch(self) -> Epoch {
        Epoch::from_gpst_duration(hifitime::Duration::from_total_nanoseconds(self.ns as i128))
    }

    /// The calendar date in the GPS time scale: (year, month, day, hour, minute, second, ns).
    pub fn to_gpst_calendar(self) -> (i32, u8, u8, u8, u8, u8, u32) {
        self.to_epoch().to_gregorian(TimeScale::GPST)
    }

    /// The calendar date in UTC.
    pub fn to_utc_calendar(self) -> (i32, u8, u8, u8, u8, u8, u32) {
        self.to_epoch().to_gregorian_utc()
    }

    /// Leap seconds GPST − UTC at this instant (18 s since 2017).
    pub fn gpst_minus_utc_s(self) -> i64 {
        let (y, mo, d, h, mi, s, ns) = self.to_utc_calendar();
        (self.ns - Self::from_gpst_calendar(y, mo, d, h, mi, s, ns).ns) / NS_PER_S
    }

    /// Parses an ISO-8601 date-time. The time scale is GPST unless the text ends in `Z`,
    /// `UTC`, `BDT` or `GPST` (separated by a space or not): every time a user writes says its
    /// scale, and a bare time is GPST.
    ///
    /// # Errors
    /// A message saying what was expected when the text is not `YYYY-MM-DDTHH:MM:SS[.f]`.
    pub fn parse_iso(text: &str) -> Result<Self, String> {
        let t = text.trim();
        let (body, scale) = if let Some(b) = t.strip_suffix("GPST") {
            (b, TimeScale::GPST)
        } else if let Some(b) = t.strip_suffix("UTC") {
            (b, TimeScale::UTC)
        } else if let Some(b) = t.strip_suffix("BDT") {
            (b, TimeScale::BDT)
        } else if let Some(b) = t.strip_suffix('Z') {
            (b, TimeScale::UTC)
        } else {
            (t, TimeScale::GPST)
        };
        let body = body.trim();
        let err = || {
            format!(
                "invalid time '{text}': expected YYYY-MM-DDTHH:MM:SS[.fff] optionally followed by GPST, UTC, Z or BDT"
            )
        };
        let (date, clock) = body.split_once(['T', ' ']).ok_or_else(err)?;
        let mut dp = date.split('-');
        let y: i32 = dp.next().and_then(|v| v.parse().ok()).ok_or_else(err)?;
        let mo: u8 = dp.next().and_then(|v| v.parse().ok()).ok_or_else(err)?;
        let d: u8 = dp.next().and_then(|v| v.parse().ok()).ok_or_else(err)?;
        if dp.next().is_some() {
            return Err(err());
        }
        let mut cp = clock.split(':');
        let h: u8 = cp.next().and_then(|v| v.parse().ok()).ok_or_else(err)?;
        let mi: u8 = cp.next().and_then(|v| v.parse().ok()).ok_or_else(err)?;
        let sec_text = cp.next().unwrap_or("0");
        if cp.next().is_some() {
            return Err(err());
        }
        let sec: f64 = sec_text.parse().map_err(|_| err())?;
        if !(1..=12).contains(&mo)
            || !(1..=31).contains(&d)
            || h > 23
            || mi > 59
            || !(0.0..61.0).contains(&sec)
            || !(1970..=2200).contains(&y)
        {
            return Err(err());
        }
        let s_whole = sec.floor() as u8;
        // Rounding 59.9999999997 s would give 1e9 ns: keep it within the second.
        let ns = (((sec - sec.floor()) * 1e9).round() as u32).min(999_999_999);
        // A day the month does not have (June 31) or a leap second where there is none
        // is an error here, not a panic in the calendar conversion.
        if Epoch::maybe_from_gregorian(y, mo, d, h, mi, s_whole, ns, scale).is_err() {
            return Err(err());
        }
        Ok(match scale {
            TimeScale::UTC => Self::from_utc(y, mo, d, h, mi, s_whole, ns),
            TimeScale::BDT => Self::from_bdt_calendar(y, mo, d, h, mi, s_whole, ns),
            _ => Self::from_gpst_calendar(y, mo, d, h, mi, s_whole, ns),
        })
    }

    /// ISO-8601 text in GPST, with the scale written out.
    pub fn to_iso_gpst(self) -> String {
        let (y, mo, d, h, mi, s, ns) = self.to_gpst_calendar();
        if ns == 0 {
            format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02} GPST")
        } else {
            format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{ns:09} GPST")
        }
    }
}

impl fmt::Display for GpsTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_iso_gpst())
    }
}

/// Simulation time: integer nanoseconds since the start of a trial.
///
/// The event queue orders on this value and then on insertion order, so two events at the
/// same instant are handled in the order they were scheduled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct SimTime(pub i64);

impl SimTime {
    /// Simulation time from seconds (rounded to the nanosecond).
    pub fn from_seconds(s: f64) -> Self {
        Self((s * 1e9).round() as i64)
    }
    /// Seconds since the trial start.
    pub fn seconds(self) -> f64 {
        self.0 as f64 * 1e-9
    }
    /// The absolute GPS time of this simulation instant.
    pub fn to_gps(self, start: GpsTime) -> GpsTime {
        start.add_ns(self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gps_epoch_is_week_zero() {
        let t = GpsTime::from_gpst_calendar(1980, 1, 6, 0, 0, 0, 0);
        assert_eq!(t.ns(), 0);
    }

    #[test]
    fn known_week_and_tow() {
        // 2010-07-01 00:00:00 GPST is GPS week 1590, day 4 (Thursday): tow 345600 s,
        // as in the header of IGS file igs15904.sp3.
        let t = GpsTime::from_gpst_calendar(2010, 7, 1, 0, 0, 0, 0);
        assert_eq!(t.week(), 1590);
        assert_eq!(t.tow_s(), 345_600.0);
        // 2020-06-25 00:00:00 GPST is week 2111, tow 345600 (header of Sta21114.sp3).
        let t = GpsTime::from_gpst_calendar(2020, 6, 25, 0, 0, 0, 0);
        assert_eq!((t.week(), t.tow_s()), (2111, 345_600.0));
    }

    #[test]
    fn leap_seconds() {
        // GPST − UTC was 15 s in mid-2010 (brdc1820.10n header) and 18 s in 2020.
        assert_eq!(
            GpsTime::from_utc(2010, 7, 1, 0, 0, 0, 0).gpst_minus_utc_s(),
            15
        );
        assert_eq!(
            GpsTime::from_utc(2020, 6, 25, 0, 0, 0, 0).gpst_minus_utc_s(),
            18
        );
        let utc = GpsTime::parse_iso("2020-06-25T00:00:00Z").unwrap();
        let gps = GpsTime::parse_iso("2020-06-25T00:00:18").unwrap();
        assert_eq!(utc, gps);
    }

    #[test]
    fn bdt_offset() {
        // The BDT epoch 2006-01-01T00:00:00 UTC is BDT week 0, sow 0.
        let t = GpsTime::from_utc(2006, 1, 1, 0, 0, 0, 0);
        let (w, s) = t.bdt_week_sow();
        assert_eq!((w, s), (0, 0.0));
        assert_eq!(t.week(), 1356);
        assert_eq!(t.tow_s(), 14.0);
        let b = GpsTime::parse_iso("2020-06-25T00:00:00 BDT").unwrap();
        assert_eq!(
            b.seconds_since(GpsTime::parse_iso("2020-06-25T00:00:00").unwrap()),
            14.0
        );
    }

    #[test]
    fn parse_errors_say_what_was_expected() {
        let e = GpsTime::parse_iso("2020-13-01T00:00:00").unwrap_err();
        assert!(e.contains("expected YYYY-MM-DD"), "{e}");
        assert!(GpsTime::parse_iso("yesterday").is_err());
        // Days a month does not have, and a leap second in a scale without them, are
        // errors rather than panics in the calendar conversion.
        for bad in [
            "2018-06-31T04:00:00 GPST",
            "2019-02-29T00:00:00",
            "2018-06-30T23:59:60 GPST",
        ] {
            let e = GpsTime::parse_iso(bad).unwrap_err();
            assert!(e.contains("expected YYYY-MM-DD"), "{e}");
        }
        assert!(GpsTime::parse_iso("2020-02-29T00:00:59.9999999999").is_ok());
    }

    #[test]
    fn iso_round_trip() {
        let t = GpsTime::parse_iso("2018-06-01T04:00:00.25 GPST").unwrap();
        assert_eq!(t.to_iso_gpst(), "2018-06-01T04:00:00.250000000 GPST");
        assert_eq!(GpsTime::parse_iso(&t.to_iso_gpst()).unwrap(), t);
    }
}
