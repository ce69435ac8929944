//! The GPS legacy navigation message (LNAV) on L1 C/A, IS-GPS-200 §20.3.
//!
//! A frame is 1500 bits at 50 bit/s (30 s): five 300-bit subframes of ten 30-bit words.
//! Every word carries 24 data bits and 6 parity bits (IS-GPS-200 Table 20-XIV):
//!
//! ```text
//! D_i = d_i ⊕ D30*                       (i = 1..24; * marks the previous word's bits)
//! D25 = D29* ⊕ d1⊕d2⊕d3⊕d5⊕d6⊕d10⊕d11⊕d12⊕d13⊕d14⊕d17⊕d18⊕d20⊕d23
//! D26 = D30* ⊕ d2⊕d3⊕d4⊕d6⊕d7⊕d11⊕d12⊕d13⊕d14⊕d15⊕d18⊕d19⊕d21⊕d24
//! D27 = D29* ⊕ d1⊕d3⊕d4⊕d5⊕d7⊕d8⊕d12⊕d13⊕d14⊕d15⊕d16⊕d19⊕d20⊕d22
//! D28 = D30* ⊕ d2⊕d4⊕d5⊕d6⊕d8⊕d9⊕d13⊕d14⊕d15⊕d16⊕d17⊕d20⊕d21⊕d23
//! D29 = D30* ⊕ d1⊕d3⊕d5⊕d6⊕d7⊕d9⊕d10⊕d14⊕d15⊕d16⊕d17⊕d18⊕d21⊕d22⊕d24
//! D30 = D29* ⊕ d3⊕d5⊕d6⊕d8⊕d9⊕d10⊕d11⊕d13⊕d15⊕d19⊕d22⊕d23⊕d24
//! ```
//!
//! Words 2 (HOW) and 10 end with two non-information bits chosen so that D29 = D30 = 0
//! (§20.3.5.2), so every subframe starts with D29* = D30* = 0 and its TLM preamble is sent
//! upright. Word 1 (TLM) holds the preamble 10001011; word 2 (HOW) the 17-bit truncated
//! TOW count of the *next* subframe's start, the alert and anti-spoof flags and the
//! subframe ID. A frame starts at a GPS time of week that is a multiple of 30 s, so
//! subframe ID = (TOW/6 mod 5) + 1.
//!
//! Subframes 1–3 carry the clock and ephemeris (Figure 20-1, Table 20-III), with the
//! scale factors below; angles go out in semicircles (π = 3.1415926535898, the ICD's
//! value).
//!
//! Subframes 4 and 5 rotate through 25 pages, page `(TOW/30 mod 25) + 1` of the frame
//! (12.5 min for the whole set; the ICD numbers pages without tying them to TOW, so any
//! rotation decodes: receivers read the SV ID). Table 20-V's page assignment:
//!
//! - subframe 5 pages 1–24: the almanac of G01–G24 (SV ID = PRN; a dummy page, SV ID 0 and
//!   zeros, for a PRN without an ephemeris); page 25 (SV ID 51): toa, WNa and the 6-bit
//!   health of G01–G24;
//! - subframe 4 pages 2, 3, 4, 5, 7, 8, 9, 10: the almanac of G25–G32; page 25 (SV ID 63):
//!   anti-spoofing flags and SV configurations of G01–G32 and the health of G25–G32.
//!   Every other subframe 4 page (1, 6, 11–24, and an almanac page of a PRN without an
//!   ephemeris) carries page 18's content, SV ID 56: the Klobuchar α/β and the UTC
//!   parameters. The ICD lets a page carry another function, named by its SV ID
//!   (§20.3.3.5.1: "the SV ID of that page defines the format and content"); hybridnav
//!   has nothing for the reserved, special-message and NMCT pages, and sending page 18
//!   in their place keeps the ionosphere at most 150 s away (pages 6 and 11 around the four
//!   almanac pages 7–10) rather than once per 12.5 min, which a short recording needs.
//!
//! The almanacs come from the world's ephemerides ([`crate::gnss::signal::almanac`]). Almanac
//! page layout (§20.3.3.5.1.2, Figure 20-1 sheet 4; positions as RTKLIB's
//! `decode_almanac` reads them): e (16 bits, 2⁻²¹), toa (8, 2¹² s), δi (16, 2⁻¹⁹ sc), Ω̇
//! (16, 2⁻³⁸ sc/s), health (8), √A (24, 2⁻¹¹), Ω0, ω, M0 (24 each, 2⁻²³ sc), af0 (11,
//! 2⁻²⁰ s: 8 MSBs, then af1 (11, 2⁻³⁸), then its 3 LSBs).
//!
//! Health words follow IS-GPS-200 §20.3.3.5.1.3 and Tables 20-VII/20-VIII ([`health6`],
//! [`health8`]): `000000` / `000 00000` for a satellite whose ephemeris says healthy; for
//! one flagged unhealthy the ephemeris's own 6-bit subframe-1 word (same layout: NAV-data
//! summary bit, then the signal code) and, in the 8-bit word, `111` ALL DATA BAD when that
//! summary bit is set followed by the same signal code; for a PRN without an almanac the
//! page-25 combination `111111` ("SV not available") and a dummy almanac page. Checked
//! by the tests below with a reader written from the IS's tables.
use crate::core::GpsTime;
use crate::gnss::atmosphere::Klobuchar;
use crate::gnss::ephemeris::Ephemeris;
use crate::gnss::signal::almanac::{self, Almanac};
use crate::gnss::signal::{signed_raw, unsigned_raw};

/// π as IS-GPS-200 defines it for converting semicircles (§20.3.3.4.3).
// The ICD's rounded value on purpose: receivers convert with it, so must the encoder.
#[allow(clippy::approx_constant)]
pub const GPS_PI: f64 = 3.141_592_653_589_8;
/// Bits per subframe.
pub const SUBFRAME_BITS: usize = 300;
/// Bits per frame (5 subframes, 30 s).
pub const FRAME_BITS: usize = 1500;
/// The TLM preamble.
const PREAMBLE: u32 = 0b1000_1011;

/// The UTC parameters of subframe 4 page 18 (IS-GPS-200 §20.3.3.5.1.6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UtcParams {
    /// GPST − UTC leap seconds ΔtLS (and ΔtLSF: no leap second is announced).
    pub leap_seconds: i32,
}

/// Everything one satellite's frame carries besides the time.
#[derive(Clone, Debug)]
pub struct LnavContent<'a> {
    pub eph: &'a Ephemeris,
    pub klobuchar: Option<Klobuchar>,
    pub utc: UtcParams,
    /// The almanacs of G01–G32 (index PRN − 1) for subframes 4 and 5.
    pub almanac: &'a [Option<Almanac>],
}

/// A subframe being filled: ten words of 24 data bits (bit 1 is the word's MSB).
struct Words([u32; 10]);

impl Words {
    fn new() -> Self {
        Self([0; 10])
    }

    /// Puts the `width` low bits of `value` at subframe bit `first` (1-based, IS-GPS-200
    /// numbering, parity bits included); a field may span two words.
    fn put(&mut self, first: usize, width: usize, value: u64) {
        for k in 0..width {
            let bit = (value >> (width - 1 - k)) & 1;
            let pos = first + k - 1; // 0-based subframe bit
            let (w, b) = (pos / 30, pos % 30);
            debug_assert!(b < 24, "field over parity bits at {first}+{k}");
            if bit == 1 {
                self.0[w] |= 1 << (23 - b);
            }
        }
    }

    /// Puts a two's-complement field: `x / scale` rounded.
    fn put_signed(&mut self, first: usize, width: usize, x: f64, scale: f64) {
        let v = (x / scale).round() as i64;
        self.put(first, width, (v as u64) & ((1u64 << width) - 1));
    }

    /// Puts an unsigned field: `x / scale` rounded.
    fn put_unsigned(&mut self, first: usize, width: usize, x: f64, scale: f64) {
        let v = (x / scale).round().max(0.0) as u64;
        self.put(first, width, v & ((1u64 << width) - 1));
    }

    /// Puts `width` bits at data-bit index `i` (0-based over the 240 data bits, 24 a word,
    /// parity left out: the numbering of RTKLIB's decoders), across word boundaries.
    fn put_data(&mut self, i: usize, width: usize, value: u64) {
        for k in 0..width {
            let d = i + k;
            self.put(
                30 * (d / 24) + d % 24 + 1,
                1,
                (value >> (width - 1 - k)) & 1,
            );
        }
    }

    /// `x/scale` rounded to a `width`-bit two's complement field at data index `i`.
    fn put_data_signed(&mut self, i: usize, width: usize, x: f64, scale: f64) {
        self.put_data(i, width, signed_raw(x, scale, width));
    }

    /// `x/scale` rounded to a `width`-bit unsigned field at data index `i`.
    fn put_data_unsigned(&mut self, i: usize, width: usize, x: f64, scale: f64) {
        self.put_data(i, width, unsigned_raw(x, scale, width));
    }

    /// A 32-bit field split as 8 MSBs ending word `w` and 24 LSBs filling word `w + 1`.
    fn put_split32(&mut self, msb_first: usize, x: f64, scale: f64, signed: bool) {
        let v = (x / scale).round();
        let raw = if signed {
            (v as i64 as u64) & 0xffff_ffff
        } else {
            (v.max(0.0) as u64) & 0xffff_ffff
        };
        self.put(msb_first, 8, raw >> 24);
        self.put(msb_first + 30 - 16, 24, raw & 0x00ff_ffff);
    }
}

/// Parity bits D25..D30 of 24 data bits `d` (d1 the MSB) after the previous word's D29*,
/// D30* (IS-GPS-200 Table 20-XIV).
pub fn parity(d: u32, d29s: u32, d30s: u32) -> u32 {
    let bit = |i: u32| (d >> (24 - i)) & 1;
    let x = |idx: &[u32]| idx.iter().fold(0, |a, &i| a ^ bit(i));
    let p25 = d29s ^ x(&[1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23]);
    let p26 = d30s ^ x(&[2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24]);
    let p27 = d29s ^ x(&[1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22]);
    let p28 = d30s ^ x(&[2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23]);
    let p29 = d30s ^ x(&[1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24]);
    let p30 = d29s ^ x(&[3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24]);
    (p25 << 5) | (p26 << 4) | (p27 << 3) | (p28 << 2) | (p29 << 1) | p30
}

/// Encodes ten data words into 300 transmitted bits (0/1), solving the last two data bits
/// of words 2 and 10 so that their D29 = D30 = 0.
fn encode(words: &Words, out: &mut [u8]) {
    let (mut d29s, mut d30s) = (0u32, 0u32);
    for (w, &data) in words.0.iter().enumerate() {
        let mut d = data;
        if w == 1 || w == 9 {
            // Try the four values of d23 d24 for the one that zeroes D29 and D30.
            d &= !0b11;
            if let Some(t) = (0..4u32).find(|&t| parity(d | t, d29s, d30s) & 0b11 == 0) {
                d |= t;
            }
        }
        let p = parity(d, d29s, d30s);
        let sent = if d30s == 1 { !d & 0x00ff_ffff } else { d };
        let word = (sent << 6) | p;
        for k in 0..30 {
            out[w * 30 + k] = ((word >> (29 - k)) & 1) as u8;
        }
        d29s = (p >> 1) & 1;
        d30s = p & 1;
    }
}

/// The URA index (0–15) of a user range accuracy in metres (IS-GPS-200 §20.3.3.3.1.3).
pub fn ura_index(ura_m: f64) -> u64 {
    const BOUNDS: [f64; 15] = [
        2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0,
        6144.0,
    ];
    BOUNDS.iter().position(|&b| ura_m <= b).unwrap_or(15) as u64
}

/// The 1500 bits (0/1) of the frame that starts at `frame_start` (a GPS time of week that
/// is a multiple of 30 s).
pub fn frame_bits(content: &LnavContent<'_>, frame_start: GpsTime, out: &mut [u8; FRAME_BITS]) {
    let tow0 = frame_start.tow_s().round() as i64;
    for sf in 0..5 {
        let start_tow = tow0 + 6 * sf as i64;
        let words = subframe_words(content, frame_start, sf as u32 + 1, start_tow);
        encode(
            &words,
            &mut out[sf * SUBFRAME_BITS..(sf + 1) * SUBFRAME_BITS],
        );
    }
}

fn subframe_words(c: &LnavContent<'_>, frame_start: GpsTime, id: u32, start_tow: i64) -> Words {
    let e = c.eph;
    let mut w = Words::new();
    w.put(1, 8, u64::from(PREAMBLE));
    // HOW: TOW count of the next subframe (wrapping at the end of the week).
    let next = ((start_tow + 6) / 6).rem_euclid(100_800);
    w.put(31, 17, next as u64);
    w.put(50, 3, u64::from(id));
    let sc = GPS_PI;
    match id {
        1 => {
            w.put(61, 10, (frame_start.week().rem_euclid(1024)) as u64);
            // Code on L2: 01 = P code on; URA; health; IODC (10 bits).
            w.put(71, 2, 1);
            w.put(73, 4, ura_index(e.ura_m));
            w.put(77, 6, u64::from(e.health) & 0x3f);
            let iodc = u64::from(e.iodc) & 0x3ff;
            w.put(83, 2, iodc >> 8);
            w.put_signed(197, 8, e.tgd_s, 2f64.powi(-31));
            w.put(211, 8, iodc & 0xff);
            w.put_unsigned(219, 16, e.toc.tow_s(), 16.0);
            w.put_signed(241, 8, e.af2, 2f64.powi(-55));
            w.put_signed(249, 16, e.af1, 2f64.powi(-43));
            w.put_signed(271, 22, e.af0, 2f64.powi(-31));
        }
        2 => {
            w.put(61, 8, u64::from(e.iode) & 0xff);
            w.put_signed(69, 16, e.crs, 2f64.powi(-5));
            w.put_signed(91, 16, e.delta_n / sc, 2f64.powi(-43));
            w.put_split32(107, e.m0 / sc, 2f64.powi(-31), true);
            w.put_signed(151, 16, e.cuc, 2f64.powi(-29));
            w.put_split32(167, e.e, 2f64.powi(-33), false);
            w.put_signed(211, 16, e.cus, 2f64.powi(-29));
            w.put_split32(227, e.sqrt_a, 2f64.powi(-19), false);
            w.put_unsigned(271, 16, e.toe.tow_s(), 16.0);
            // Fit interval flag: 0 (4 hours); AODO 0.
        }
        3 => {
            w.put_signed(61, 16, e.cic, 2f64.powi(-29));
            w.put_split32(77, e.omega0 / sc, 2f64.powi(-31), true);
            w.put_signed(121, 16, e.cis, 2f64.powi(-29));
            w.put_split32(137, e.i0 / sc, 2f64.powi(-31), true);
            w.put_signed(181, 16, e.crc, 2f64.powi(-5));
            w.put_split32(197, e.omega / sc, 2f64.powi(-31), true);
            w.put_signed(241, 24, e.omega_dot / sc, 2f64.powi(-43));
            w.put(271, 8, u64::from(e.iode) & 0xff);
            w.put_signed(279, 14, e.idot / sc, 2f64.powi(-43));
        }
        4 => {
            let page = lnav_page(frame_start);
            // Data ID 01 on every page of both subframes.
            w.put(61, 2, 1);
            const SF4_ALMANAC: [(i64, usize); 8] = [
                (2, 25),
                (3, 26),
                (4, 27),
                (5, 28),
                (7, 29),
                (8, 30),
                (9, 31),
                (10, 32),
            ];
            let prn = SF4_ALMANAC.iter().find(|p| p.0 == page).map(|p| p.1);
            if let Some(a) = prn.and_then(|n| c.almanac.get(n - 1).copied().flatten()) {
                almanac_page(&mut w, &a);
                return w;
            }
            if page == 25 {
                sf4_page25(&mut w, c.almanac);
                return w;
            }
            // Page 18's content (SV ID 56).
            w.put(63, 6, 56);
            let k = c.klobuchar.unwrap_or(Klobuchar {
                alpha: [0.0; 4],
                beta: [0.0; 4],
            });
            w.put_signed(69, 8, k.alpha[0], 2f64.powi(-30));
            w.put_signed(77, 8, k.alpha[1], 2f64.powi(-27));
            w.put_signed(91, 8, k.alpha[2], 2f64.powi(-24));
            w.put_signed(99, 8, k.alpha[3], 2f64.powi(-24));
            w.put_signed(107, 8, k.beta[0], 2f64.powi(11));
            w.put_signed(121, 8, k.beta[1], 2f64.powi(14));
            w.put_signed(129, 8, k.beta[2], 2f64.powi(16));
            w.put_signed(137, 8, k.beta[3], 2f64.powi(16));
            // A1 = A0 = 0 (GPS time steered to UTC exactly), tot and WNt at the frame's
            // week, ΔtLS = ΔtLSF, WNLSF and DN at the frame's week (no leap announced).
            let wn8 = (frame_start.week().rem_euclid(256)) as u64;
            w.put(219, 8, 0);
            w.put(227, 8, wn8);
            w.put(241, 8, (c.utc.leap_seconds as i64 as u64) & 0xff);
            w.put(249, 8, wn8);
            w.put(257, 8, 7);
            w.put(271, 8, (c.utc.leap_seconds as i64 as u64) & 0xff);
        }
        _ => {
            let page = lnav_page(frame_start);
            w.put(61, 2, 1);
            if page == 25 {
                sf5_page25(&mut w, c.almanac, frame_start);
            } else if let Some(a) = c.almanac.get(page as usize - 1).copied().flatten() {
                almanac_page(&mut w, &a);
            }
            // Otherwise a dummy page: SV ID 0, zeros.
        }
    }
    w
}

/// The page (1–25) of subframes 4 and 5 in the frame that starts at `frame_start`.
pub fn lnav_page(frame_start: GpsTime) -> i64 {
    ((frame_start.tow_s().round() as i64) / 30).rem_euclid(25) + 1
}

/// The 6-bit health word of subframe 5 page 25 (G01–G24) and subframe 4 page 25
/// (G25–G32), IS-GPS-200 §20.3.3.5.1.3: the MSB summarises the NAV data (0 all OK, 1 some
/// or all bad, as §20.3.3.3.1.4 defines it for subframe 1) and the five LSBs give the
/// signal components' health with Table 20-VIII's codes.
///
/// - A satellite whose ephemeris says healthy: `000000`.
/// - One whose ephemeris flags it unhealthy: the ephemeris's own subframe-1 health word,
///   which has the same layout (§20.3.3.5.1.3: "the six-bit words provide a one-bit
///   summary of the NAV data's health status in the MSB position in accordance with
///   paragraph 20.3.3.3.1.4"); a non-zero health value with no bit inside the 6-bit field
///   (not a subframe-1 word, so only from a hand-written record) goes out as `1 11100`,
///   NAV data bad and Table 20-VIII's "SV is temporarily out".
/// - A PRN without an almanac: `111111`, the combination §20.3.3.5.1.3 reserves in page 25
///   for "the SV which has that ID is not available and there may be no data regarding
///   that SV in that page of subframes 4 and 5 that is assigned to normally contain the
///   almanac data of that SV".
pub fn health6(a: Option<&Almanac>) -> u64 {
    match a {
        None => HEALTH6_NOT_AVAILABLE,
        Some(a) if a.healthy => 0,
        Some(a) => match u64::from(a.health_word) & 0x3f {
            0 => (1 << 5) | SIGNALS_SV_TEMPORARILY_OUT,
            h => h,
        },
    }
}

/// Page 25's "SV not available" combination (§20.3.3.5.1.3).
pub const HEALTH6_NOT_AVAILABLE: u64 = 0b11_1111;
/// Table 20-VIII's `11100`: "SV is temporarily out (do not use this SV during current
/// pass)".
const SIGNALS_SV_TEMPORARILY_OUT: u64 = 0b1_1100;
/// Table 20-VII's `111`: "ALL DATA BAD".
const NAV_ALL_DATA_BAD: u64 = 0b111;

/// The 8-bit health word of an almanac page (§20.3.3.5.1.3): three MSBs with Table
/// 20-VII's NAV data codes, five LSBs with Table 20-VIII's signal codes, the latter the
/// same as in [`health6`]. The 6-bit word's summary bit cannot say which of Table
/// 20-VII's failures occurred, so a set summary bit goes out as the table's most
/// inclusive code, `111` ALL DATA BAD, and a clear one as `000` ALL DATA OK. A PRN
/// without an almanac has no almanac page (a dummy page, SV ID 0, is sent instead), so no
/// 8-bit word.
pub fn health8(a: &Almanac) -> u64 {
    let h6 = health6(Some(a));
    let nav = if h6 >> 5 == 1 { NAV_ALL_DATA_BAD } else { 0 };
    (nav << 5) | (h6 & 0x1f)
}

/// An almanac page (SV ID = PRN), IS-GPS-200 §20.3.3.5.1.2.
fn almanac_page(w: &mut Words, a: &Almanac) {
    let sc = GPS_PI;
    w.put_data(50, 6, u64::from(a.sat.number));
    w.put_data_unsigned(56, 16, a.e, 2f64.powi(-21));
    w.put_data_unsigned(72, 8, a.toa_sow_s, 4096.0);
    w.put_data_signed(80, 16, a.delta_i / sc, 2f64.powi(-19));
    w.put_data_signed(96, 16, a.omega_dot / sc, 2f64.powi(-38));
    w.put_data(112, 8, health8(a));
    w.put_data_unsigned(120, 24, a.sqrt_a, 2f64.powi(-11));
    w.put_data_signed(144, 24, a.omega0 / sc, 2f64.powi(-23));
    w.put_data_signed(168, 24, a.omega / sc, 2f64.powi(-23));
    w.put_data_signed(192, 24, a.m0 / sc, 2f64.powi(-23));
    let af0 = signed_raw(a.af0, 2f64.powi(-20), 11);
    w.put_data(216, 8, af0 >> 3);
    w.put_data_signed(224, 11, a.af1, 2f64.powi(-38));
    w.put_data(235, 3, af0 & 0b111);
}

/// Subframe 5 page 25 (SV ID 51): toa, WNa, health of G01–G24.
fn sf5_page25(w: &mut Words, almanac: &[Option<Almanac>], frame_start: GpsTime) {
    let (week, toa) = almanac::toa_for(crate::core::System::Gps, frame_start);
    w.put_data(50, 6, 51);
    w.put_data(56, 8, (toa / 4096.0) as u64);
    w.put_data(64, 8, week.rem_euclid(256) as u64);
    for prn in 1..=24usize {
        let a = almanac.get(prn - 1).copied().flatten();
        w.put_data(72 + 6 * (prn - 1), 6, health6(a.as_ref()));
    }
}

/// Subframe 4 page 25 (SV ID 63): anti-spoofing flag and configuration of G01–G32 (A-S off,
/// configuration 001 for a PRN with an almanac, 000 otherwise) and the health of G25–G32.
fn sf4_page25(w: &mut Words, almanac: &[Option<Almanac>]) {
    w.put_data(50, 6, 63);
    for prn in 1..=32usize {
        let a = almanac.get(prn - 1).copied().flatten();
        w.put_data(56 + 4 * (prn - 1), 4, u64::from(a.is_some()));
        if prn >= 25 {
            w.put_data(186 + 6 * (prn - 25), 6, health6(a.as_ref()));
        }
    }
}

/// A satellite's LNAV symbols over time: the frame in force is rebuilt from the navigation
/// data whenever a code period falls in a new 30 s frame. One bit spans 20 code periods;
/// L1 C/A has no overlay code.
pub struct LnavStream {
    nav: std::sync::Arc<crate::gnss::rinex_nav::NavData>,
    sat: crate::core::EmitterId,
    utc: UtcParams,
    frame: i64,
    bits: [u8; FRAME_BITS],
    /// The almanacs of G01–G32 and their toa (rebuilt when a frame's toa changes).
    almanac: Vec<Option<Almanac>>,
    almanac_toa: Option<(i64, f64)>,
}

impl LnavStream {
    /// The stream of `sat` from `nav` (its Klobuchar and leap seconds go in subframe 4).
    pub fn new(
        nav: std::sync::Arc<crate::gnss::rinex_nav::NavData>,
        sat: crate::core::EmitterId,
        leap_seconds: i32,
    ) -> Self {
        Self {
            nav,
            sat,
            utc: UtcParams { leap_seconds },
            frame: i64::MIN,
            bits: [0; FRAME_BITS],
            almanac: Vec::new(),
            almanac_toa: None,
        }
    }
}

impl crate::gnss::signal::baseband::NavSymbols for LnavStream {
    fn symbol(&mut self, ms: i64) -> u8 {
        let bit = ms.div_euclid(20);
        let frame = bit.div_euclid(FRAME_BITS as i64);
        if frame != self.frame {
            self.frame = frame;
            let start = GpsTime::from_ns(frame * 30_000_000_000);
            let toa = almanac::toa_for(crate::core::System::Gps, start);
            if self.almanac_toa != Some(toa) {
                almanac::fill_constellation(
                    &self.nav,
                    crate::core::System::Gps,
                    32,
                    start,
                    &mut self.almanac,
                );
                self.almanac_toa = Some(toa);
            }
            match self.nav.select(self.sat, start) {
                Some(eph) => {
                    let content = LnavContent {
                        eph,
                        klobuchar: self.nav.klobuchar,
                        utc: self.utc,
                        almanac: &self.almanac,
                    };
                    frame_bits(&content, start, &mut self.bits);
                }
                None => self.bits = [0; FRAME_BITS],
            }
        }
        self.bits[bit.rem_euclid(FRAME_BITS as i64) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::ephemeris::tests::g02_2010;

    /// Reads `width` bits at subframe bit `first` (1-based) from decoded data bits.
    fn field(sf: &[u8], first: usize, width: usize) -> u64 {
        (0..width).fold(0, |a, k| (a << 1) | u64::from(sf[first - 1 + k]))
    }

    /// Undoes the D30* inversion and checks every word's parity like a receiver.
    fn decode_subframe(bits: &[u8]) -> Vec<u8> {
        let mut out = bits.to_vec();
        let (mut d29s, mut d30s) = (0u32, 0u32);
        for w in 0..10 {
            let word: u32 = bits[w * 30..w * 30 + 30]
                .iter()
                .fold(0, |a, &b| (a << 1) | u32::from(b));
            let mut d = word >> 6;
            if d30s == 1 {
                d = !d & 0x00ff_ffff;
            }
            assert_eq!(
                parity(d, d29s, d30s),
                word & 0x3f,
                "parity of word {}",
                w + 1
            );
            for k in 0..24 {
                out[w * 30 + k] = ((d >> (23 - k)) & 1) as u8;
            }
            d29s = (word >> 1) & 1;
            d30s = word & 1;
        }
        out
    }

    #[test]
    fn frame_decodes_back_to_the_ephemeris() {
        let eph = g02_2010();
        let content = LnavContent {
            eph: &eph,
            klobuchar: Some(Klobuchar {
                alpha: [0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06],
                beta: [0.1167e+06, -0.2294e+06, -0.1311e+06, 0.1049e+07],
            }),
            utc: UtcParams { leap_seconds: 15 },
            almanac: &[],
        };
        let start = GpsTime::from_week_tow(1590, 345_600.0);
        let mut bits = [0u8; FRAME_BITS];
        frame_bits(&content, start, &mut bits);
        let sfs: Vec<Vec<u8>> = bits.chunks(SUBFRAME_BITS).map(decode_subframe).collect();
        for (i, sf) in sfs.iter().enumerate() {
            assert_eq!(field(sf, 1, 8), 0x8b);
            // TOW count of the next subframe; subframe IDs 1..5.
            assert_eq!(field(sf, 31, 17), (345_600 + 6 * (i as u64 + 1)) / 6);
            assert_eq!(field(sf, 50, 3), i as u64 + 1);
            // D29 = D30 = 0 at the end of words 2 and 10.
            assert_eq!(bits[i * 300 + 58..i * 300 + 60], [0, 0]);
            assert_eq!(bits[i * 300 + 298..i * 300 + 300], [0, 0]);
        }
        let signed = |v: u64, w: usize| -> f64 {
            let s = (v << (64 - w)) as i64 >> (64 - w);
            s as f64
        };
        assert_eq!(field(&sfs[0], 61, 10), 1590 % 1024);
        let af0 = signed(field(&sfs[0], 271, 22), 22) * 2f64.powi(-31);
        assert!((af0 - eph.af0).abs() <= 2f64.powi(-32));
        let toc = field(&sfs[0], 219, 16) as f64 * 16.0;
        assert_eq!(toc, 345_600.0);
        let m0 = (field(&sfs[1], 107, 8) << 24 | field(&sfs[1], 121, 24)) as u32 as i32;
        assert!((f64::from(m0) * 2f64.powi(-31) * GPS_PI - eph.m0).abs() < 1e-9);
        let sqrt_a =
            (field(&sfs[1], 227, 8) << 24 | field(&sfs[1], 241, 24)) as f64 * 2f64.powi(-19);
        assert!((sqrt_a - eph.sqrt_a).abs() < 2f64.powi(-19));
        let ecc = (field(&sfs[1], 167, 8) << 24 | field(&sfs[1], 181, 24)) as f64 * 2f64.powi(-33);
        assert!((ecc - eph.e).abs() < 2f64.powi(-33));
        let omega = (field(&sfs[2], 197, 8) << 24 | field(&sfs[2], 211, 24)) as u32 as i32;
        assert!((f64::from(omega) * 2f64.powi(-31) * GPS_PI - eph.omega).abs() < 1e-9);
        let odot = signed(field(&sfs[2], 241, 24), 24) * 2f64.powi(-43) * GPS_PI;
        assert!((odot - eph.omega_dot).abs() < 1e-12 * GPS_PI);
        assert_eq!(field(&sfs[1], 61, 8), u64::from(eph.iode));
        assert_eq!(field(&sfs[2], 271, 8), u64::from(eph.iode));
        assert_eq!(field(&sfs[0], 211, 8), u64::from(eph.iodc & 0xff));
        assert_eq!(field(&sfs[3], 63, 6), 56);
        assert_eq!(field(&sfs[3], 241, 8), 15);
    }

    /// The almanac health words read at the positions IS-GPS-200 §20.3.3.5.1.3 states in
    /// words ("the 24 MSBs of words four through nine in page 25 of subframe 5", "bits 19
    /// through 24 of word 8, the 24 MSBs of word 9, and the 18 MSBs of word 10 in page 25
    /// of subframe 4", "bits 17 through 24 of word five" of an almanac page), against the
    /// meanings of Tables 20-VII/20-VIII: a healthy satellite 000000; one whose ephemeris
    /// says 1 00001 (NAV data bad, all signals weak) sends that word and 111 00001 on its
    /// page; 0 00100 (NAV data OK, L1 P signal weak) stays 0 00100 / 000 00100; a PRN
    /// without an almanac 111111 ("SV not available") and a dummy page.
    #[test]
    fn almanac_health_words_follow_is_gps_200() {
        let mut almanac = vec![None; 32];
        let mut put = |prn: u16, health: u32| {
            let mut e = g02_2010();
            e.sat = crate::core::EmitterId::new(crate::core::System::Gps, prn);
            e.health = health;
            let a = Almanac::from_ephemeris(&e, 1590, 344_064.0);
            almanac[usize::from(prn) - 1] = Some(a);
        };
        put(1, 0);
        put(2, 0b10_0001);
        put(3, 0b00_0100);
        put(25, 0b10_0001);
        put(26, 0);
        let eph = g02_2010();
        let content = LnavContent {
            eph: &eph,
            klobuchar: None,
            utc: UtcParams { leap_seconds: 15 },
            almanac: &almanac,
        };
        // Subframes 4 and 5 of the frame carrying page `p` (TOW 345 000 is a multiple of
        // 750 s, the 25-page cycle).
        let pages = |p: i64| {
            let start = GpsTime::from_week_tow(1590, (345_000 + 30 * (p - 1)) as f64);
            assert_eq!(lnav_page(start), p);
            let mut bits = [0u8; FRAME_BITS];
            frame_bits(&content, start, &mut bits);
            let sf: Vec<Vec<u8>> = bits.chunks(SUBFRAME_BITS).map(decode_subframe).collect();
            (sf[3].clone(), sf[4].clone())
        };
        let (sf4_25, sf5_25) = pages(25);
        // Subframe 5 page 25: SV n's 6 bits start at bit (n − 1) % 4 · 6 + 1 of word
        // 4 + (n − 1) / 4.
        let h_sf5 = |n: usize| field(&sf5_25, 30 * (3 + (n - 1) / 4) + (n - 1) % 4 * 6 + 1, 6);
        assert_eq!(field(&sf5_25, 63, 6), 51, "SV ID 51");
        assert_eq!(h_sf5(1), 0, "G01 healthy");
        assert_eq!(h_sf5(2), 0b10_0001, "G02: NAV data bad, all signals weak");
        assert_eq!(h_sf5(3), 0b00_0100, "G03: NAV OK, L1 P signal weak");
        for n in 4..=24 {
            assert_eq!(h_sf5(n), 0b11_1111, "G{n:02}: SV not available");
        }
        // Subframe 4 page 25: G25 at word 8 bits 19–24, G26–G29 word 9, G30–G32 word 10.
        let sf4_pos = [229, 241, 247, 253, 259, 271, 277, 283];
        assert_eq!(field(&sf4_25, 63, 6), 63, "SV ID 63");
        let h_sf4: Vec<u64> = sf4_pos.iter().map(|&b| field(&sf4_25, b, 6)).collect();
        assert_eq!(h_sf4, [0b10_0001, 0, 63, 63, 63, 63, 63, 63]);
        // Almanac pages (subframe 5 page n = G0n): SV ID in word 3 bits 3–8, the 8-bit
        // health in word 5 bits 17–24 (NAV code 3 MSBs, signal code 5 LSBs).
        let page_health = |p: i64| {
            let (_, sf5) = pages(p);
            (field(&sf5, 63, 6), field(&sf5, 137, 8))
        };
        assert_eq!(page_health(1), (1, 0));
        assert_eq!(
            page_health(2),
            (2, 0b111_00001),
            "ALL DATA BAD, all signals weak"
        );
        assert_eq!(page_health(3), (3, 0b000_00100), "ALL DATA OK, L1 P weak");
        assert_eq!(page_health(4), (0, 0), "G04: dummy page");
    }

    #[test]
    fn ura_table() {
        assert_eq!(ura_index(2.0), 0);
        assert_eq!(ura_index(2.8), 1);
        assert_eq!(ura_index(10000.0), 15);
    }
}
