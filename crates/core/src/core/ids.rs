//! Identifiers of emitters: GNSS satellites and terrestrial transmitters.

use std::fmt;
use std::str::FromStr;

/// A positioning system. Each system has its own receiver clock offset in a filter
/// (inter-system biases), except where a world says two systems share a clock.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum System {
    /// GPS L1 C/A.
    Gps,
    /// BeiDou B1I.
    Bds,
    /// DTMB digital-TV towers used as pseudo-satellites.
    Dtmb,
    /// TC-OFDM base stations.
    Tcofdm,
}

impl System {
    /// How many systems there are (the clock unknowns of a multi-system solution).
    pub const COUNT: usize = 4;
    /// Every system, in the order of [`System::index`]: the order of per-system clock
    /// arrays throughout (least squares, the abstract emitters, the paper estimators).
    pub const ALL: [System; System::COUNT] =
        [System::Gps, System::Bds, System::Dtmb, System::Tcofdm];

    /// The position of the system in [`System::ALL`].
    pub const fn index(self) -> usize {
        match self {
            System::Gps => 0,
            System::Bds => 1,
            System::Dtmb => 2,
            System::Tcofdm => 3,
        }
    }

    /// The one-letter code used in RINEX (`G`, `C`) and for terrestrial emitters (`D`, `T`).
    pub fn letter(self) -> char {
        match self {
            System::Gps => 'G',
            System::Bds => 'C',
            System::Dtmb => 'D',
            System::Tcofdm => 'T',
        }
    }

    /// The system of a one-letter code.
    pub fn from_letter(c: char) -> Option<Self> {
        match c {
            'G' => Some(System::Gps),
            'C' => Some(System::Bds),
            'D' => Some(System::Dtmb),
            'T' => Some(System::Tcofdm),
            _ => None,
        }
    }

    /// The lower-case name used in world files.
    pub fn name(self) -> &'static str {
        match self {
            System::Gps => "gps",
            System::Bds => "bds",
            System::Dtmb => "dtmb",
            System::Tcofdm => "tcofdm",
        }
    }

    /// True for satellite systems.
    pub fn is_gnss(self) -> bool {
        matches!(self, System::Gps | System::Bds)
    }
}

/// One emitter: a satellite (`G05`, `C01`) or a terrestrial transmitter (`D01`, `T03`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct EmitterId {
    pub system: System,
    /// PRN for satellites; 1-based index in the world for terrestrial transmitters.
    pub number: u16,
}

impl EmitterId {
    /// Builds an id.
    pub const fn new(system: System, number: u16) -> Self {
        Self { system, number }
    }

    /// True for a BeiDou GEO satellite (PRN 1–5 and 59 and above), whose orbit is computed
    /// differently (BDS-SIS-ICD §5.2.4.12).
    pub fn is_bds_geo(self) -> bool {
        self.system == System::Bds && (self.number <= 5 || self.number >= 59)
    }
}

impl fmt::Display for EmitterId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{:02}", self.system.letter(), self.number)
    }
}

impl FromStr for EmitterId {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        let mut chars = s.chars();
        let letter = chars
            .next()
            .ok_or_else(|| "empty emitter id: expected e.g. G05 or C01".to_string())?;
        let system = System::from_letter(letter.to_ascii_uppercase()).ok_or_else(|| {
            format!("emitter id '{s}': expected a system letter G, C, D or T followed by a number")
        })?;
        let number: u16 = chars
            .as_str()
            .trim()
            .parse()
            .map_err(|_| format!("emitter id '{s}': expected a number after '{letter}'"))?;
        if number == 0 {
            return Err(format!("emitter id '{s}': numbers start at 1"));
        }
        Ok(Self { system, number })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn parse_and_print() {
        let id: EmitterId = "G05".parse().unwrap();
        assert_eq!(id, EmitterId::new(System::Gps, 5));
        assert_eq!(id.to_string(), "G05");
        assert_eq!("c1".parse::<EmitterId>().unwrap().to_string(), "C01");
        assert!("X01".parse::<EmitterId>().is_err());
        assert!("G".parse::<EmitterId>().is_err());
        assert!(EmitterId::new(System::Bds, 3).is_bds_geo());
        assert!(!EmitterId::new(System::Bds, 8).is_bds_geo());
    }
}
