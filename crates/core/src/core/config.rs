//! Configuration checks shared by every model: one error type that names the offending
//! key, and the range checks every config's `validate` is built from.
//!
//! A model's config reports the first bad value as a [`ConfigIssue`] whose `key` is the
//! field name as written in the world file, so the world loader can point at its line and
//! column; the message says what was expected and what was found.

use std::fmt;

/// A configuration value that cannot be used, with the key that holds it.
///
/// `key` is the offending field's name as written in the world file (e.g. `"speed_mps"`),
/// so the world loader can point at its line; `message` says what was expected and what
/// was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigIssue {
    /// The offending field name, e.g. `"speed_mps"` or `"points_enu_m"`.
    pub key: String,
    /// What was expected, e.g. `"expected a positive speed in m/s, got -3"`.
    pub message: String,
}

impl ConfigIssue {
    /// An issue with `key`.
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for ConfigIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.key, self.message)
    }
}

impl std::error::Error for ConfigIssue {}

/// `Ok` when `ok`, else an issue with `key` and the message `msg` builds (only then).
///
/// # Errors
/// The issue, when `ok` is false.
pub fn check(key: &str, ok: bool, msg: impl FnOnce() -> String) -> Result<(), ConfigIssue> {
    if ok {
        Ok(())
    } else {
        Err(ConfigIssue::new(key, msg()))
    }
}

/// Checks that `value` is finite and inside `[lo, hi]` (or `(lo, hi]` when `open_lo`); the
/// message reads "expected {what} within [lo, hi], got {value}".
///
/// # Errors
/// An issue with `key` when the value is outside the interval or not finite.
pub fn check_range(
    key: &str,
    value: f64,
    lo: f64,
    hi: f64,
    open_lo: bool,
    what: &str,
) -> Result<(), ConfigIssue> {
    let ok = value.is_finite() && value <= hi && if open_lo { value > lo } else { value >= lo };
    check(key, ok, || {
        let bracket = if open_lo { "(" } else { "[" };
        format!("expected {what} within {bracket}{lo}, {hi}], got {value}")
    })
}

/// Checks that every element of a vector is finite.
///
/// # Errors
/// An issue with `key` naming the values when one is NaN or infinite.
pub fn check_finite(key: &str, values: &[f64], what: &str) -> Result<(), ConfigIssue> {
    check(key, values.iter().all(|v| v.is_finite()), || {
        format!("expected {what} with finite components, got {values:?}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_checks_name_the_interval_and_the_value() {
        assert!(check_range("k", 1.0, 0.0, 1.0, true, "x").is_ok());
        let e = check_range("k", 0.0, 0.0, 1.0, true, "a step").unwrap_err();
        assert_eq!(e.key, "k");
        assert_eq!(e.message, "expected a step within (0, 1], got 0");
        let e = check_range("k", f64::NAN, 0.0, 1.0, false, "a gain").unwrap_err();
        assert_eq!(e.message, "expected a gain within [0, 1], got NaN");
        assert!(check_finite("v", &[1.0, f64::INFINITY], "a vector").is_err());
        assert!(check("k", true, || unreachable!()).is_ok());
    }
}
