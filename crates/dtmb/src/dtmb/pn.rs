//! PN frame headers of GB 20600-2006 (DTMB, TDS-OFDM) and their frame-by-frame phase
//! schedule.
//!
//! Each header is a run of a binary maximum-length LFSR sequence `a[n]`, mapped chip by
//! chip `0 → +1`, `1 → −1` on both I and Q, i.e. to `±(1 + j)`. The first `d` output chips
//! equal the seed and the header is the register run on (GB 20600-2006 §4.5.2; facts.md §1):
//!
//! | mode  | recurrence                              | seed       | layout          |
//! |-------|-----------------------------------------|------------|-----------------|
//! | PN420 | `a[n] = a[n−1] ⊕ a[n−5] ⊕ a[n−6] ⊕ a[n−8]` | 10110000   | 82 + 255 + 83   |
//! | PN595 | `a[n] = a[n−3] ⊕ a[n−10]` | 0000000001 | 595 (no cycles) |
//! | PN945 | `a[n] = a[n−2] ⊕ a[n−7] ⊕ a[n−8] ⊕ a[n−9]` | 111110111  | 217 + 511 + 217 |
//!
//! Because the sequence is periodic with period `C` (255 or 511), running it on for the
//! whole header makes the preamble the cyclic tail of the core and the postamble its head:
//! the header is its own cyclic prefix and suffix.
//!
//! Phase schedule (PN420, PN945): with frame index `i` in the superframe, `F` frames per
//! superframe and core length `C`, `i ← i mod F`; if `i > ⌊F/2⌋` then `i ← 2⌊F/2⌋ − i`;
//! the phase is `0` for `i = 0`, `(i+1)/2` for odd `i` and `C − i/2` for even `i`. The
//! header at phase `p` is the phase-0 header advanced by `p` chips: `h_p[n] = a[n + p]`.
//! PN595 has one fixed phase.
//!
//! Normalisation: the frame body has unit mean power per sample, and a header sample is
//! `(1 − 2a[n]) (1 + j) √(ρ/2)` with `ρ` the header/body power ratio (2 for PN420 and
//! PN945, 1 for PN595), so the header's mean power is exactly `ρ`.

use super::DtmbError;
use num_complex::Complex32;
use std::fmt;
use std::str::FromStr;

/// The symbol (sample) rate of DTMB in an 8 MHz channel, in samples per second.
pub const SAMPLE_RATE_HZ: f64 = 7.56e6;
/// The symbol rate as an integer, for exact sample ↔ nanosecond arithmetic.
pub const SAMPLE_RATE_HZ_INT: i64 = 7_560_000;
/// Samples in a superframe: 125 ms at 7.56 Msps, in every mode.
pub const SUPERFRAME_SAMPLES: usize = 945_000;
/// Samples in a frame body (C = 3780 and C = 1 alike).
pub const BODY_LEN: usize = 3780;

/// The three frame-header modes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PnMode {
    /// 420-chip header: 82 + 255 + 83, 225 frames per superframe.
    Pn420,
    /// 595-chip header: the first 595 chips of a 1023-chip sequence, 216 frames.
    Pn595,
    /// 945-chip header: 217 + 511 + 217, 200 frames per superframe.
    Pn945,
}

impl PnMode {
    /// Every mode, for iteration in tests and tables.
    pub const ALL: [PnMode; 3] = [PnMode::Pn420, PnMode::Pn595, PnMode::Pn945];

    /// The canonical name, as accepted by [`FromStr`].
    pub fn name(self) -> &'static str {
        match self {
            PnMode::Pn420 => "PN420",
            PnMode::Pn595 => "PN595",
            PnMode::Pn945 => "PN945",
        }
    }

    /// Header length in chips (= samples at 7.56 Msps).
    pub fn header_len(self) -> usize {
        match self {
            PnMode::Pn420 => 420,
            PnMode::Pn595 => 595,
            PnMode::Pn945 => 945,
        }
    }

    /// Period of the underlying m-sequence: 255, 1023 or 511 chips.
    pub fn period(self) -> usize {
        match self {
            PnMode::Pn420 => 255,
            PnMode::Pn595 => 1023,
            PnMode::Pn945 => 511,
        }
    }

    /// Length of the cyclic core inside the header (255, 595 or 511 chips). For PN595 the
    /// whole header is the "core": it has no cyclic extension.
    pub fn core_len(self) -> usize {
        match self {
            PnMode::Pn420 => 255,
            PnMode::Pn595 => 595,
            PnMode::Pn945 => 511,
        }
    }

    /// Preamble length (cyclic tail of the core) in chips.
    pub fn preamble_len(self) -> usize {
        match self {
            PnMode::Pn420 => 82,
            PnMode::Pn595 => 0,
            PnMode::Pn945 => 217,
        }
    }

    /// Postamble length (cyclic head of the core) in chips.
    pub fn postamble_len(self) -> usize {
        match self {
            PnMode::Pn420 => 83,
            PnMode::Pn595 => 0,
            PnMode::Pn945 => 217,
        }
    }

    /// Whether the header carries a cyclic preamble/postamble around an m-sequence core.
    pub fn is_cyclic(self) -> bool {
        self != PnMode::Pn595
    }

    /// Samples in one signal frame: header + 3780-symbol body.
    pub fn frame_len(self) -> usize {
        self.header_len() + BODY_LEN
    }

    /// Signal frames per 125 ms superframe: 225, 216 or 200.
    pub fn frames_per_superframe(self) -> usize {
        match self {
            PnMode::Pn420 => 225,
            PnMode::Pn595 => 216,
            PnMode::Pn945 => 200,
        }
    }

    /// Frame duration in seconds (555.56 µs, 578.70 µs or 625 µs).
    pub fn frame_duration_s(self) -> f64 {
        self.frame_len() as f64 / SAMPLE_RATE_HZ
    }

    /// Header/body mean power ratio ρ (2 for PN420 and PN945, 1 for PN595).
    pub fn header_power_ratio(self) -> f64 {
        match self {
            PnMode::Pn595 => 1.0,
            _ => 2.0,
        }
    }

    /// Mean power of a whole frame when the body has unit power:
    /// `(H ρ + 3780) / (H + 3780)`. This is the nominal signal power SNR is defined on.
    pub fn nominal_frame_power(self) -> f64 {
        let h = self.header_len() as f64;
        (h * self.header_power_ratio() + BODY_LEN as f64) / (h + BODY_LEN as f64)
    }

    fn lfsr_spec(self) -> (&'static [usize], &'static [u8]) {
        match self {
            PnMode::Pn420 => (&[1, 5, 6, 8], &[1, 0, 1, 1, 0, 0, 0, 0]),
            PnMode::Pn595 => (&[3, 10], &[0, 0, 0, 0, 0, 0, 0, 0, 0, 1]),
            PnMode::Pn945 => (&[2, 7, 8, 9], &[1, 1, 1, 1, 1, 0, 1, 1, 1]),
        }
    }

    /// One full period of the m-sequence, `a[0..period]`, as chips 0/1.
    pub fn m_sequence(self) -> Vec<u8> {
        let (taps, seed) = self.lfsr_spec();
        lfsr(taps, seed, self.period())
    }

    /// The pn phase (chip advance) of frame `frame_in_superframe` by the schedule above.
    /// Indices at or beyond the superframe length wrap.
    pub fn phase_of_frame(self, frame_in_superframe: usize) -> usize {
        if !self.is_cyclic() {
            return 0;
        }
        let f = self.frames_per_superframe();
        let half = f / 2;
        let mut i = frame_in_superframe % f;
        if i > half {
            i = 2 * half - i;
        }
        let c = self.period();
        if i == 0 {
            0
        } else if i % 2 == 1 {
            i.div_ceil(2)
        } else {
            c - i / 2
        }
    }

    /// The number of distinct phases used in one superframe (113, 1 or 101).
    pub fn distinct_phases(self) -> usize {
        let mut seen = vec![false; self.period()];
        for i in 0..self.frames_per_superframe() {
            seen[self.phase_of_frame(i)] = true;
        }
        seen.iter().filter(|&&s| s).count()
    }

    /// Header chips (0/1) at pn phase `phase`: `h_p[n] = a[(n + p) mod period]`.
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] when `phase` is not below the sequence period, or is
    /// non-zero for PN595 (which has a single fixed phase).
    pub fn header_chips(self, phase: usize) -> Result<Vec<u8>, DtmbError> {
        self.check_phase(phase)?;
        let seq = self.m_sequence();
        let p = seq.len();
        Ok((0..self.header_len())
            .map(|n| seq[(n + phase) % p])
            .collect())
    }

    /// Writes the complex baseband header at `phase` into `out` (length `header_len`),
    /// with the power normalisation of the module documentation.
    ///
    /// # Errors
    /// As [`PnMode::header_chips`], plus a wrong output length.
    pub fn header_samples(self, phase: usize, out: &mut [Complex32]) -> Result<(), DtmbError> {
        if out.len() != self.header_len() {
            return Err(DtmbError::BufferLength {
                what: "PN header",
                expected: self.header_len(),
                got: out.len(),
            });
        }
        let chips = self.header_chips(phase)?;
        let a = (self.header_power_ratio() / 2.0).sqrt() as f32;
        for (o, &c) in out.iter_mut().zip(&chips) {
            let v = if c == 0 { a } else { -a };
            *o = Complex32::new(v, v);
        }
        Ok(())
    }

    fn check_phase(self, phase: usize) -> Result<(), DtmbError> {
        let ok = if self.is_cyclic() {
            phase < self.period()
        } else {
            phase == 0
        };
        if ok {
            Ok(())
        } else {
            Err(DtmbError::InvalidParameter {
                name: "pn_phase",
                reason: format!(
                    "{} has phases 0..{} (PN595 only phase 0), got {phase}",
                    self.name(),
                    if self.is_cyclic() { self.period() } else { 1 }
                ),
            })
        }
    }
}

/// Runs the Fibonacci LFSR `a[n] = ⊕_t a[n − t]` for `len` chips from `seed`.
fn lfsr(taps: &[usize], seed: &[u8], len: usize) -> Vec<u8> {
    let mut a = Vec::with_capacity(len.max(seed.len()));
    a.extend_from_slice(seed);
    while a.len() < len {
        let n = a.len();
        a.push(taps.iter().fold(0, |acc, &t| acc ^ a[n - t]));
    }
    a.truncate(len);
    a
}

/// Packs chips (0/1) most significant first into an upper-case hex string, for the check
/// values of facts.md §1.
pub fn chips_to_hex(chips: &[u8]) -> String {
    chips
        .chunks(8)
        .filter(|c| c.len() == 8)
        .map(|c| format!("{:02X}", c.iter().fold(0u8, |acc, &b| (acc << 1) | b)))
        .collect()
}

impl fmt::Display for PnMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for PnMode {
    type Err = DtmbError;

    /// Accepts `PN420`, `PN595`, `PN945` in any case, or the bare numbers.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_uppercase();
        let t = t.strip_prefix("PN").unwrap_or(&t);
        match t {
            "420" => Ok(PnMode::Pn420),
            "595" => Ok(PnMode::Pn595),
            "945" => Ok(PnMode::Pn945),
            _ => Err(DtmbError::UnknownPnMode(s.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase0_headers_match_check_values() {
        let cases = [
            (PnMode::Pn420, "B0A5E9FEA1CF0D9A"),
            (PnMode::Pn945, "FB946DFF3259AD7E"),
            (PnMode::Pn595, "004934D7CC7C8EFC"),
        ];
        for (mode, hex) in cases {
            let h = chips_to_hex(&mode.header_chips(0).unwrap());
            assert!(h.starts_with(hex), "{mode}: {}", &h[..16]);
        }
    }

    #[test]
    fn pn420_header_seeds_follow_the_schedule() {
        let expect = [
            (0, 0xB0u8),
            (1, 0x61),
            (2, 0xD8),
            (111, 0x9A),
            (112, 0x83),
            (113, 0x9A),
            (224, 0xB0),
        ];
        for (frame, byte) in expect {
            let p = PnMode::Pn420.phase_of_frame(frame);
            let chips = PnMode::Pn420.header_chips(p).unwrap();
            assert_eq!(
                chips_to_hex(&chips[..8]),
                format!("{byte:02X}"),
                "frame {frame}"
            );
        }
    }

    #[test]
    fn distinct_phase_counts() {
        assert_eq!(PnMode::Pn420.distinct_phases(), 113);
        assert_eq!(PnMode::Pn945.distinct_phases(), 101);
        assert_eq!(PnMode::Pn595.distinct_phases(), 1);
    }

    #[test]
    fn headers_are_cyclically_extended_m_sequences() {
        for mode in [PnMode::Pn420, PnMode::Pn945] {
            let seq = mode.m_sequence();
            // A maximum-length sequence has 2^(d−1) ones per period.
            let ones = seq.iter().filter(|&&c| c == 1).count();
            assert_eq!(ones, mode.period().div_ceil(2));
            for p in [0, 5, mode.period() - 3] {
                let h = mode.header_chips(p).unwrap();
                let (pre, c) = (mode.preamble_len(), mode.core_len());
                assert_eq!(&h[..pre], &h[c..c + pre], "{mode} preamble = core tail");
                assert_eq!(
                    &h[pre + c..],
                    &h[pre..pre + mode.postamble_len()],
                    "{mode} postamble = core head"
                );
            }
        }
    }

    #[test]
    fn header_power_follows_the_boost() {
        for mode in PnMode::ALL {
            let mut h = vec![Complex32::default(); mode.header_len()];
            mode.header_samples(0, &mut h).unwrap();
            let p: f64 = h.iter().map(|x| x.norm_sqr() as f64).sum::<f64>() / h.len() as f64;
            assert!((p - mode.header_power_ratio()).abs() < 1e-6, "{mode}: {p}");
        }
    }

    #[test]
    fn mode_names_parse_and_bad_ones_list_the_valid_names() {
        assert_eq!("pn945".parse::<PnMode>().unwrap(), PnMode::Pn945);
        assert_eq!("420".parse::<PnMode>().unwrap(), PnMode::Pn420);
        let e = "PN500".parse::<PnMode>().unwrap_err().to_string();
        assert!(
            e.contains("PN500")
                && e.contains("PN420")
                && e.contains("PN595")
                && e.contains("PN945"),
            "{e}"
        );
        assert!(PnMode::Pn595.header_chips(1).is_err());
        assert!(PnMode::Pn420.header_chips(255).is_err());
    }
}
