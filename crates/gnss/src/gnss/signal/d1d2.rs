//! The BeiDou navigation messages on B1I (BDS-SIS-ICD-B1I-3.0 §5): D1 (§5.2), the message
//! of the MEO and IGSO satellites, and D2 (§5.3), the message of the GEO satellites
//! (C01–C05, C59–C63).
//!
//! # D1
//!
//! A subframe is 300 bits at 50 bit/s (6 s), starting at a BDT second of week that is a
//! multiple of 6; five subframes make a 30 s frame (FraID = SOW/6 mod 5 + 1). Each bit is
//! spread by the 20-chip Neumann–Hoffman code 00000100110101001110, one chip per 1 ms code
//! period, so the symbol of code period `m` (BDT ms of week) is `bit(m/20) ⊕ NH(m mod 20)`.
//!
//! # D2
//!
//! 500 bit/s without NH code: one bit per two code periods, the symbol of code period `m`
//! is `bit(m/2)`. A subframe is 300 bits (0.6 s); five make a 3 s frame, the subframe of
//! code period `m` is `(m/600 mod 5) + 1`. Every subframe of a frame carries the frame's
//! SOW (the BDT second of week of its subframe 1, a multiple of 3). Subframe 1 has 10
//! pages, page `SOW/3 mod 10 + 1`, so the basic navigation information (clock, group
//! delays, Klobuchar α/β, ephemeris; fields split across pages MSBs first) repeats every
//! 30 s; a receiver has an ephemeris after 10 frames.
//!
//! # Both
//!
//! Word 1 is the 11-bit preamble 11100010010, 4 reserved bits and 11 information bits (FraID,
//! the 8 MSBs of SOW) protected by a BCH(15,11) code; words 2–10 carry 22 information bits as
//! two BCH(15,11) codewords, sent interleaved chip by chip (codeword 1 bit 1, codeword 2 bit 1,
//! …). The BCH code is systematic with generator g(X) = X⁴ + X + 1: the 4 check bits are
//! the remainder of info(X)·X⁴ divided by g(X) (§5.1.3).
//!
//! Field positions below are those of the de-interleaved subframe (words of 30 bits, each
//! word's information bits first, then its check bits), as the ICD's figures number them;
//! scale factors as the ICD's tables (angles in semicircles, π = 3.1415926535898). The
//! positions agree with independent code read for the purpose: the ephemeris and clock
//! fields with RTKLIB's `decode_bds_d1`/`decode_bds_d2` and GNSS-SDR's `Beidou_DNAV.h`, the
//! α/β of D1 and of D2's page 2 with GNSS-SDR's and the SignalSim generator's (RTKLIB
//! does not decode them).
//!
//! - D1 subframe 1: SatH1, AODC, URAI, WN, toc, TGD1/2, the BDS Klobuchar α0–α3 (bits
//!   127–166) and β0–β3 (167–172 + 181–182, 183–198, 199–202 + 211–214), a0–a2, AODE;
//!   subframes 2–3: the Keplerian elements. Subframes 4 and 5 rotate through 24 pages
//!   ([`d1_page`]: page `SOW/30 mod 24 + 1`, a 12-minute cycle): subframe 4 pages 1–24 the
//!   almanac of C01–C24, subframe 5 pages 1–6 that of C25–C30 (√A, a1, a0, Ω0, e, δi, toa,
//!   Ω̇, ω, M0, ICD Figure 5-11-1; derived from the world's ephemerides,
//!   [`crate::gnss::signal::almanac`]), page 7 the 9-bit health of C01–C19, page 8 that of
//!   C20–C30 with WNa and toa, page 9 the time offsets to GPS, Galileo and GLONASS
//!   (A0/A1, 0.1 ns and 0.1 ns/s), page 10 the UTC parameters (ΔtLS, ΔtLSF, WN_LSF,
//!   A0UTC 2⁻³⁰ s, A1UTC 2⁻⁵⁰, DN), both from the navigation header ([`BdsTimeParams`]);
//!   pages 11–24 of subframe 5 are reserved (page number only). The health words Hea_i
//!   follow ICD Table 5-15 ([`bds_health_word`]): 0 for a satellite whose ephemeris says
//!   healthy; 1 1111 1111 ("in failure or permanently shut off") for one flagged SatH1 = 1
//!   and for a slot without an almanac.
//! - D2 subframe 1 pages 1–10 as §5.3.3 (page 1: SatH1, AODC, URAI, WN, toc, TGD1/2; page 2:
//!   α/β; page 3: a0, a1's 4 MSBs; … page 10: ω's 5 LSBs, IDOT). Subframe 5 ([`d2_page5`]:
//!   page `SOW/3 mod 120 + 1`) carries D1's almanac, health and time pages at D2's page
//!   numbers: 35–36 health, WNa, toa; 37–60 and 95–100 the almanac of C01–C24 and C25–C30;
//!   101–102 the time offsets and UTC parameters.
//! - D2 subframes 2–4 (integrity and differential corrections, pages 1–6,
//!   [`d2_integrity_page`]) and subframe 5's ionospheric grid pages (1–13, 61–73):
//!   hybridnav has no monitoring network and no grid, and says so with the codes public
//!   D2 encoders and decoders use rather than with zeros (which would read as "correction
//!   0 m, best UDRE, grid delay 0 m, best GIVE"): every BDID 0 (BDID = 1 marks a
//!   satellite whose integrity and corrections are sent, as SatGen uses it), every UDREI and RURAI slot 15 ([`UDREI_SENT`], [`RURAI_SENT`]), every Δt
//!   0, every grid point dτ = 1 1111 1111 with GIVEI = 1111 ([`GRID_POINT_SENT`]). Bit
//!   positions: a public Python D2 decoder's tables (`D2DictSf2`, `Sf3`, `Sf4`,
//!   `Sf5IonoGridA/B`), the Racelogic SatGen generator's `NavigationDataB1ID2` (subframes
//!   2, 3 and the grid) and the "bnav" decoder's `Ionosphere::parseIonospherePage` (the
//!   grid) agree. **Not confirmed** from any source read: the ICD's names for UDREI 15 and
//!   RURAI 15 (its UDRE/RURA tables were not available), which of dτ = 510 / 511 is "not
//!   monitored" (the bnav decoder treats both as no value; SatGen sends 511), a "not
//!   available" code of Δt (none is used: the slots belong to no satellite), and the codes
//!   of SatH2 and BDEpID (sent 00). GIVEI has no "not monitored" code: its table
//!   (§5.3.3.8.2, as bnav quotes it) gives GIVE = 45 m for index 15.
//!
//! The Klobuchar α/β are BeiDou's own set (`BDSA`/`BDSB` of a RINEX 3 header,
//! [`NavData::klobuchar_bds`]). When the file has none they are sent as zeros, which keeps
//! a receiver's broadcast model off. The GPS set is not substituted: the BDS model is not
//! the GPS one (the ICD's §5.2.4.7 evaluates it at the geographic, not geomagnetic,
//! latitude of a 375 km pierce point and gives the delay on B1I, where the GPS model gives
//! L1's at 350 km; "BDS-2 slightly modifies the Klobuchar model", Park et al., J. Position.
//! Navig. Timing 12(2), 2023), so GPS coefficients would describe an ionosphere neither
//! constellation broadcast.

use crate::core::{EmitterId, GpsTime};
use crate::gnss::atmosphere::Klobuchar;
use crate::gnss::ephemeris::Ephemeris;
use crate::gnss::rinex_nav::NavData;
use crate::gnss::signal::almanac::{self, Almanac};
use crate::gnss::signal::baseband::NavSymbols;
use crate::gnss::signal::{signed_raw, unsigned_raw};
use std::sync::Arc;

/// π of the BDS ICD.
// The ICD's rounded value on purpose: receivers convert with it, so must the encoder.
#[allow(clippy::approx_constant)]
const BDS_PI: f64 = 3.141_592_653_589_8;
/// The preamble.
const PREAMBLE: u64 = 0b111_0001_0010;
/// The Neumann–Hoffman code (first chip first).
pub const NH: [u8; 20] = [0, 0, 0, 0, 0, 1, 0, 0, 1, 1, 0, 1, 0, 1, 0, 0, 1, 1, 1, 0];
/// ms from the GPS epoch to the BDT epoch (2006-01-01 00:00:00 UTC = GPS week 1356 + 14 s).
const BDT_EPOCH_MS: i64 = 1356 * 604_800_000 + 14_000;
const WEEK_MS: i64 = 604_800_000;

/// BCH(15,11) check bits (4, MSB first) of 11 information bits (MSB first).
pub fn bch15_11(info: u32) -> u32 {
    let mut reg = 0u32; // 4-bit remainder
    for k in (0..11).rev() {
        let fb = ((info >> k) & 1) ^ ((reg >> 3) & 1);
        reg = ((reg << 1) & 0b1111) ^ if fb == 1 { 0b0011 } else { 0 };
    }
    reg
}

/// The 300 decoded bits of a subframe (1-based positions) being filled.
struct Fields([u8; 300]);

impl Fields {
    fn put(&mut self, first: usize, width: usize, value: u64) {
        for k in 0..width {
            self.0[first - 1 + k] = ((value >> (width - 1 - k)) & 1) as u8;
        }
    }

    /// A field split over slices `(first, width)`, MSBs first.
    fn put_slices(&mut self, slices: &[(usize, usize)], value: u64) {
        let total: usize = slices.iter().map(|s| s.1).sum();
        let mut done = 0;
        for &(first, width) in slices {
            let v = (value >> (total - done - width)) & ((1u64 << width) - 1);
            self.put(first, width, v);
            done += width;
        }
    }

    fn signed(&mut self, slices: &[(usize, usize)], x: f64, scale: f64) {
        let total: usize = slices.iter().map(|s| s.1).sum();
        self.put_slices(slices, signed_raw(x, scale, total));
    }

    fn unsigned(&mut self, slices: &[(usize, usize)], x: f64, scale: f64) {
        let total: usize = slices.iter().map(|s| s.1).sum();
        self.put_slices(slices, unsigned_raw(x, scale, total));
    }

    /// Encodes into the 300 transmitted bits (BCH and interleaving).
    fn encode(&self, out: &mut [u8; 300]) {
        let bits = |from: usize, n: usize| -> u32 {
            (0..n).fold(0, |a, k| (a << 1) | u32::from(self.0[from - 1 + k]))
        };
        // Word 1: 15 plain bits, then one codeword.
        out[..15].copy_from_slice(&self.0[..15]);
        let info = bits(16, 11);
        let cw = (info << 4) | bch15_11(info);
        for k in 0..15 {
            out[15 + k] = ((cw >> (14 - k)) & 1) as u8;
        }
        for w in 1..10 {
            let base = w * 30 + 1;
            let i1 = bits(base, 11);
            let i2 = bits(base + 11, 11);
            let c1 = (i1 << 4) | bch15_11(i1);
            let c2 = (i2 << 4) | bch15_11(i2);
            for k in 0..15 {
                out[w * 30 + 2 * k] = ((c1 >> (14 - k)) & 1) as u8;
                out[w * 30 + 2 * k + 1] = ((c2 >> (14 - k)) & 1) as u8;
            }
        }
    }
}

/// 2^x.
fn p2(x: i32) -> f64 {
    2f64.powi(x)
}

/// Where the eight Klobuchar coefficients go: α0–α3 then β0–β3, each as slices.
type IonoSlots = [&'static [(usize, usize)]; 8];

/// D1 subframe 1 (§5.2.4.7).
const D1_IONO: IonoSlots = [
    &[(127, 8)],
    &[(135, 8)],
    &[(151, 8)],
    &[(159, 8)],
    &[(167, 6), (181, 2)],
    &[(183, 8)],
    &[(191, 8)],
    &[(199, 4), (211, 4)],
];

/// D2 subframe 1 page 2 (§5.3.3).
const D2_IONO: IonoSlots = [
    &[(47, 6), (61, 2)],
    &[(63, 8)],
    &[(71, 8)],
    &[(79, 4), (91, 4)],
    &[(95, 8)],
    &[(103, 8)],
    &[(111, 2), (121, 6)],
    &[(127, 8)],
];

/// The scale factors (LSBs) of α0–α3 (s, s/π, s/π², s/π³) and β0–β3 (s, s/π, …) as powers
/// of two: the ICD's table, the same as GPS's.
pub const IONO_LSB_LOG2: [i32; 8] = [-30, -27, -24, -24, 11, 14, 16, 16];

impl Fields {
    /// The Klobuchar set (zeros without one) into `slots`.
    fn iono(&mut self, k: Option<&Klobuchar>, slots: &IonoSlots) {
        let values = k.map_or([0.0; 8], |k| {
            [
                k.alpha[0], k.alpha[1], k.alpha[2], k.alpha[3], k.beta[0], k.beta[1], k.beta[2],
                k.beta[3],
            ]
        });
        for ((slot, v), lsb) in slots.iter().zip(values).zip(IONO_LSB_LOG2) {
            self.signed(slot, v, p2(lsb));
        }
    }

    /// Word 1 and the SOW of word 2 (both messages).
    fn header(&mut self, fra_id: u32, sow: i64) {
        self.put(1, 11, PREAMBLE);
        self.put(16, 3, u64::from(fra_id));
        self.put_slices(&[(19, 8), (31, 12)], sow as u64 & 0xf_ffff);
    }
}

/// What a D1 or D2 subframe carries besides its satellite's ephemeris, the same for every
/// satellite: the BeiDou Klobuchar set (D1 subframe 1, D2 subframe 1 page 2), the almanac
/// and health (D1 subframe 4 pages 1–24 and subframe 5 pages 1–8; D2 subframe 5 pages
/// 35–60 and 95–100) and the time parameters (D1 subframe 5 pages 9 and 10; D2 subframe 5
/// pages 101 and 102).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SharedPages<'a> {
    pub iono: Option<Klobuchar>,
    pub time: BdsTimeParams,
    /// The almanacs of C01–C30 (index PRN − 1) for subframes 4 and 5; an empty slice or a
    /// `None` sends that page's almanac as zeros and its health as "no almanac".
    pub almanac: &'a [Option<Almanac>],
}

/// The time parameters of D1 subframe 5 pages 9 and 10 (BDS-SIS-ICD-B1I-3.0 §5.2.4.18–19),
/// as values (s, s/s, weeks, days) before quantisation.
///
/// # Derivation from the navigation file's header
///
/// A `TIME SYSTEM CORR` line gives `CORR_X(t) = a0 + a1·(t − t_ref)`, the sub-second part
/// of `X − UTC` (`GPUT`, `GAUT`, `BDUT`; `GLUT` with a0 = −τ_C). With
/// `BDT = UTC + ΔtLS_BDS + CORR_BD`, `GPST = UTC + ΔtLS_GPS + CORR_GP`,
/// `ΔtLS_BDS = ΔtLS_GPS − 14 s`, GST aligned to GPST and GLONASS time = UTC(SU) + 3 h, the
/// sub-second offsets of BDT from the other systems are
///
/// ```text
/// δ_GPS = CORR_BD − CORR_GP     (BDT − GPST = −14 s + δ_GPS)
/// δ_Gal = CORR_BD − CORR_GA     (BDT − GST  = −14 s + δ_Gal)
/// δ_GLO = CORR_BD − CORR_GL     (BDT − GLONASST = ΔtLS_BDS − 3 h + δ_GLO)
/// ```
///
/// each defined only when both lines are in the header (zeros otherwise: a RINEX 3 header
/// has no direct BDT−GPST line). The UTC realisations differ (UTC(NTSC) for BDUT,
/// UTC(USNO) for GPUT, …) by a few ns (BIPM Circular T), which the derived offsets carry.
/// The message's polynomials have no reference time: `Δt = A0 + A1·t_E` with `t_E` the BDT
/// second of week (as GNSS-SDR's `utc_time` evaluates it), so A1 = the file's drift
/// (`a1_BD − a1_X`, or `a1_BD` for UTC) and A0 = the file's offset at the subframe's
/// transmission time `t` minus `A1_sent·t_E(t)`, with A1 as its field will carry it
/// (0.1 ns/s LSB for the GPS/Galileo/GLONASS drifts, far coarser than any real drift, so
/// those A1 go out as 0 and A0 carries the offset at `t`). A0UTC and A1UTC are zero
/// without a `BDUT` line.
///
/// ΔtLS = GPST − UTC − 14 s (the leap seconds of BDT, which equalled UTC on 2006-01-01,
/// when GPST − UTC was 14 s). ΔtLSF, WN_LSF and DN come from the `LEAP SECONDS` line when
/// it has them (GPS values converted: ΔtLSF − 14 s, week − 1356, day − 1 from GPS's 1–7 to
/// BDS's 0–6); otherwise no leap second is announced: ΔtLSF = ΔtLS, WN_LSF the current BDT
/// week and DN = 6, which changes nothing (IS-GPS-200 §20.3.3.5.2.4's convention).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BdsTimeParams {
    pub a0_gps_s: f64,
    pub a1_gps: f64,
    pub a0_gal_s: f64,
    pub a1_gal: f64,
    pub a0_glo_s: f64,
    pub a1_glo: f64,
    pub dt_ls_s: i32,
    pub dt_lsf_s: i32,
    /// WN_LSF as a full BDT week (8 LSBs sent).
    pub wn_lsf: i64,
    /// DN, 0–6.
    pub dn: i64,
    pub a0_utc_s: f64,
    pub a1_utc: f64,
}

/// The LSB of A0/A1 GPS, Galileo and GLONASS (0.1 ns, 0.1 ns/s; ICD Table 5-13).
pub const A_GNSS_LSB: f64 = 1e-10;

impl BdsTimeParams {
    /// The parameters for a subframe sent at `t`, from `nav`'s header and GPST − UTC
    /// (`gpst_minus_utc_s`) (derivation in the type's documentation).
    pub fn from_nav(nav: &NavData, gpst_minus_utc_s: i32, t: GpsTime) -> Self {
        let corr = |code: &str| nav.time_corr.iter().rev().find(|c| c.code == code);
        let (week, sow) = t.bdt_week_sow();
        let bd = corr("BDUT");
        // A0, A1 of a polynomial A0 + A1·t_E whose value at `t` is `at_t` and whose A1,
        // as sent, is `a1` quantised to `lsb` over `width` bits.
        let poly = |at_t: f64, a1: f64, lsb: f64, width: usize| -> (f64, f64) {
            let raw = signed_raw(a1, lsb, width);
            let a1_sent = sext(raw, width) as f64 * lsb;
            (at_t - a1_sent * sow, a1)
        };
        let offset = |code: &str| -> (f64, f64) {
            match (bd, corr(code)) {
                (Some(b), Some(x)) => poly(
                    b.at(t) - x.at(t),
                    b.a1_s_per_s - x.a1_s_per_s,
                    A_GNSS_LSB,
                    16,
                ),
                _ => (0.0, 0.0),
            }
        };
        let (a0_gps_s, a1_gps) = offset("GPUT");
        let (a0_gal_s, a1_gal) = offset("GAUT");
        let (a0_glo_s, a1_glo) = offset("GLUT");
        let (a0_utc_s, a1_utc) =
            bd.map_or((0.0, 0.0), |b| poly(b.at(t), b.a1_s_per_s, p2(-50), 24));
        let dt_ls_s = gpst_minus_utc_s - 14;
        let (dt_lsf_s, wn_lsf, dn) = match nav.leap_announcement {
            Some(l) if l.bds => (l.future_s, l.week, l.day),
            Some(l) => (l.future_s - 14, l.week - 1356, l.day - 1),
            None => (dt_ls_s, week, 6),
        };
        Self {
            a0_gps_s,
            a1_gps,
            a0_gal_s,
            a1_gal,
            a0_glo_s,
            a1_glo,
            dt_ls_s,
            dt_lsf_s,
            wn_lsf,
            dn,
            a0_utc_s,
            a1_utc,
        }
    }
}

/// Two's complement value of the low `width` bits of `raw`.
fn sext(raw: u64, width: usize) -> i64 {
    let shift = 64 - width;
    ((raw << shift) as i64) >> shift
}

/// The D1 page (1–24) of subframes 4 and 5 in the frame that contains BDT second of week
/// `sow`. The ICD sub-commutates subframes 4 and 5 over 24 pages, a 12-minute superframe
/// (§5.2.2), and numbers each page (Pnum) without tying the number to the time; hybridnav
/// sends page `(SOW/30 mod 24) + 1`, as the SignalSim generator does, so page 1 starts at
/// every multiple of 720 s of the week and page `p` at `720·k + 30·(p − 1)`. A receiver
/// reads Pnum, so any rotation decodes.
pub fn d1_page(sow: i64) -> i64 {
    (sow / 30).rem_euclid(24) + 1
}

/// The decoded bits of D1 subframe `fra_id` (1–5) starting at BDT `week`, `sow`.
fn d1_fields(e: &Ephemeris, c: &SharedPages, week: i64, sow: i64, fra_id: u32) -> Fields {
    let iono = c.iono.as_ref();
    let mut f = Fields([0; 300]);
    f.header(fra_id, sow);
    let sc = BDS_PI;
    match fra_id {
        1 => {
            f.put(43, 1, u64::from(e.health != 0));
            f.put(44, 5, u64::from(e.iodc) & 0x1f);
            f.put(49, 4, crate::gnss::signal::lnav::ura_index(e.ura_m));
            f.put(61, 13, (week as u64) & 0x1fff);
            f.unsigned(&[(74, 9), (91, 8)], e.toc.bdt_week_sow().1, 8.0);
            f.signed(&[(99, 10)], e.tgd_s, 1e-10);
            f.signed(&[(109, 4), (121, 6)], e.tgd2_s, 1e-10);
            f.iono(iono, &D1_IONO);
            f.signed(&[(215, 11)], e.af2, p2(-66));
            f.signed(&[(226, 7), (241, 17)], e.af0, p2(-33));
            f.signed(&[(258, 5), (271, 17)], e.af1, p2(-50));
            f.put(288, 5, u64::from(e.iode) & 0x1f);
        }
        2 => {
            f.signed(&[(43, 10), (61, 6)], e.delta_n / sc, p2(-43));
            f.signed(&[(67, 16), (91, 2)], e.cuc, p2(-31));
            f.signed(&[(93, 20), (121, 12)], e.m0 / sc, p2(-31));
            f.unsigned(&[(133, 10), (151, 22)], e.e, p2(-33));
            f.signed(&[(181, 18)], e.cus, p2(-31));
            f.signed(&[(199, 4), (211, 14)], e.crc, p2(-6));
            f.signed(&[(225, 8), (241, 10)], e.crs, p2(-6));
            f.unsigned(&[(251, 12), (271, 20)], e.sqrt_a, p2(-19));
            let toe = (e.toe_sow_s() / 8.0).round() as u64;
            f.put(291, 2, toe >> 15);
        }
        3 => {
            let toe = (e.toe_sow_s() / 8.0).round() as u64;
            f.put_slices(&[(43, 10), (61, 5)], toe & 0x7fff);
            f.signed(&[(66, 17), (91, 15)], e.i0 / sc, p2(-31));
            f.signed(&[(106, 7), (121, 11)], e.cic, p2(-31));
            f.signed(&[(132, 11), (151, 13)], e.omega_dot / sc, p2(-43));
            f.signed(&[(164, 9), (181, 9)], e.cis, p2(-31));
            f.signed(&[(190, 13), (211, 1)], e.idot / sc, p2(-43));
            f.signed(&[(212, 21), (241, 11)], e.omega0 / sc, p2(-31));
            f.signed(&[(252, 11), (271, 21)], e.omega / sc, p2(-31));
        }
        _ => {
            let page = d1_page(sow);
            f.put(44, 7, page as u64);
            let alm = |prn: i64| c.almanac.get(prn as usize - 1).copied().flatten();
            match (fra_id, page) {
                (4, p) => d1_almanac_page(&mut f, alm(p).as_ref()),
                (5, p @ 1..=6) => d1_almanac_page(&mut f, alm(p + 24).as_ref()),
                (5, 7 | 8) => d1_health_page(&mut f, c.almanac, page == 8, week, sow),
                (5, p) => d1_time_page(&mut f, &c.time, p),
                _ => {}
            }
        }
    }
    f
}

/// An almanac page (subframe 4 pages 1–24: C01–C24; subframe 5 pages 1–6: C25–C30), ICD
/// Figure 5-11-1 and Table 5-12; zeros without an almanac.
fn d1_almanac_page(f: &mut Fields, a: Option<&Almanac>) {
    let Some(a) = a else { return };
    let sc = BDS_PI;
    f.unsigned(&[(51, 2), (61, 22)], a.sqrt_a, p2(-11));
    f.signed(&[(91, 11)], a.af1, p2(-38));
    f.signed(&[(102, 11)], a.af0, p2(-20));
    f.signed(&[(121, 22), (151, 2)], a.omega0 / sc, p2(-23));
    f.unsigned(&[(153, 17)], a.e, p2(-21));
    f.signed(&[(170, 3), (181, 13)], a.delta_i / sc, p2(-19));
    f.unsigned(&[(194, 8)], a.toa_sow_s, 4096.0);
    f.signed(&[(202, 1), (211, 16)], a.omega_dot / sc, p2(-38));
    f.signed(&[(227, 6), (241, 18)], a.omega / sc, p2(-23));
    f.signed(&[(259, 4), (271, 20)], a.m0 / sc, p2(-23));
}

/// Where the 9-bit health words Hea1–Hea19 (page 7) and Hea20–Hea30 (page 8) go, ICD
/// Figures 5-11-2/3 (as GNSS-SDR's `Beidou_DNAV.h` and GNSSTk's `BDSD1Bits.hpp` read them).
const HEA_SLOTS: [&[(usize, usize)]; 19] = [
    &[(51, 2), (61, 7)],
    &[(68, 9)],
    &[(77, 6), (91, 3)],
    &[(94, 9)],
    &[(103, 9)],
    &[(112, 1), (121, 8)],
    &[(129, 9)],
    &[(138, 5), (151, 4)],
    &[(155, 9)],
    &[(164, 9)],
    &[(181, 9)],
    &[(190, 9)],
    &[(199, 4), (211, 5)],
    &[(216, 9)],
    &[(225, 8), (241, 1)],
    &[(242, 9)],
    &[(251, 9)],
    &[(260, 3), (271, 6)],
    &[(277, 9)],
];

/// The bits of the 9-bit satellite health word Hea_i (BDS-SIS-ICD Table 5-15, MSB = bit
/// 8, as GNSSTk's `BDSD1NavHealth.hpp`/`BDSD2NavHealth.hpp` quote the table): 0 means OK
/// in every bit. Bit 8: satellite clock; bits 7, 6, 5: B1I, B2I, B3I signal power more
/// than 10 dB below nominal; bit 1: navigation message abnormal (GNSSTk: "IOD over
/// limit"); bits 4–2 and 0 reserved. With bit 8 set the table's footnote gives the other
/// eight their meaning: all 0, "the satellite clock is unavailable"; all 1, "the
/// satellite is in failure or permanently shut off"; anything else reserved.
pub const HEA_CLOCK_UNAVAILABLE: u64 = 0x100;
/// Hea = 1 1111 1111: "the satellite is in failure or permanently shut off" (Table 5-15).
pub const HEA_FAILED_OR_SHUT_OFF: u64 = 0x1ff;

/// The health word Hea_i of a satellite (subframe 5 pages 7–8 of D1, 35–36 of D2), with
/// Table 5-15's meanings ([`HEA_FAILED_OR_SHUT_OFF`]):
///
/// - almanac from an ephemeris that says healthy (SatH1 = 0): 0, all OK;
/// - almanac from an ephemeris flagged unhealthy (SatH1 = 1, the only health a BeiDou
///   navigation file carries, which says the satellite is unusable but not why): 1 1111
///   1111, "in failure or permanently shut off", the table's one code for a satellite
///   that is out as a whole (1 0000 0000 would assert a clock failure nobody reported);
/// - no almanac (no satellite in the slot, or none with an ephemeris near toa): the same
///   1 1111 1111 — the ICD gives no separate "not in the constellation" value that could
///   be confirmed here (GNSSTk quotes only the two footnote codes).
pub fn bds_health_word(a: Option<&Almanac>) -> u64 {
    match a {
        Some(a) if a.healthy => 0,
        _ => HEA_FAILED_OR_SHUT_OFF,
    }
}

/// D1 subframe 5 page 7 / D2 subframe 5 page 35 (health of C01–C19) when `!second`, page 8
/// / page 36 (C20–C30, WNa, toa) when `second`.
fn d1_health_page(f: &mut Fields, almanac: &[Option<Almanac>], second: bool, week: i64, sow: i64) {
    let first = if second { 20 } else { 1 };
    let count = if second { 11 } else { 19 };
    for (k, slot) in HEA_SLOTS.iter().take(count).enumerate() {
        let a = almanac.get(first + k - 1).copied().flatten();
        f.put_slices(slot, bds_health_word(a.as_ref()));
    }
    if second {
        let t = GpsTime::from_bdt_week_sow(week, sow as f64);
        let (wna, toa) = crate::gnss::signal::almanac::toa_for(crate::core::System::Bds, t);
        f.put(190, 8, wna.rem_euclid(256) as u64);
        f.put_slices(&[(198, 5), (211, 3)], (toa / 4096.0) as u64);
    }
}

/// Subframe 5 pages 9 (time offsets to GPS, Galileo, GLONASS) and 10 (UTC), ICD Figures
/// 5-11-4/5 and Table 5-13 (positions as GNSS-SDR's `Beidou_DNAV.h` and GNSSTk's
/// `BDSD1Bits.hpp` read them; page 10 also as SignalSim writes it); other pages untouched.
fn d1_time_page(f: &mut Fields, t: &BdsTimeParams, page: i64) {
    match page {
        9 => {
            f.signed(&[(97, 14)], t.a0_gps_s, A_GNSS_LSB);
            f.signed(&[(111, 2), (121, 14)], t.a1_gps, A_GNSS_LSB);
            f.signed(&[(135, 8), (151, 6)], t.a0_gal_s, A_GNSS_LSB);
            f.signed(&[(157, 16)], t.a1_gal, A_GNSS_LSB);
            f.signed(&[(181, 14)], t.a0_glo_s, A_GNSS_LSB);
            f.signed(&[(195, 8), (211, 8)], t.a1_glo, A_GNSS_LSB);
        }
        10 => {
            f.signed(&[(51, 2), (61, 6)], f64::from(t.dt_ls_s), 1.0);
            f.signed(&[(67, 8)], f64::from(t.dt_lsf_s), 1.0);
            f.put(75, 8, t.wn_lsf.rem_euclid(256) as u64);
            f.signed(&[(91, 22), (121, 10)], t.a0_utc_s, p2(-30));
            f.signed(&[(131, 12), (151, 12)], t.a1_utc, p2(-50));
            f.put(163, 8, t.dn.clamp(0, 255) as u64);
        }
        _ => {}
    }
}

/// A field of `width` bits split over two pages: its `msb` most significant bits on one,
/// the rest on the next.
fn split(raw: u64, width: usize, msb: usize) -> (u64, u64) {
    (raw >> (width - msb), raw & ((1u64 << (width - msb)) - 1))
}

/// The decoded bits of D2 subframe `fra_id` (1–5) of the frame starting at BDT `week`,
/// `sow` (a multiple of 3); subframe 1 is page `sow/3 mod 10 + 1`.
fn d2_fields(e: &Ephemeris, c: &SharedPages, week: i64, sow: i64, fra_id: u32) -> Fields {
    let iono = c.iono.as_ref();
    let mut f = Fields([0; 300]);
    f.header(fra_id, sow);
    match fra_id {
        2..=4 => d2_integrity(&mut f, sow, fra_id),
        5 => d2_subframe5(&mut f, c, week, sow),
        _ => {}
    }
    if fra_id != 1 {
        return f;
    }
    let sc = BDS_PI;
    let page = (sow / 3).rem_euclid(10) + 1;
    f.put(43, 4, page as u64);
    match page {
        1 => {
            f.put(47, 1, u64::from(e.health != 0));
            f.put(48, 5, u64::from(e.iodc) & 0x1f);
            f.put(61, 4, crate::gnss::signal::lnav::ura_index(e.ura_m));
            f.put(65, 13, (week as u64) & 0x1fff);
            f.unsigned(&[(78, 5), (91, 12)], e.toc.bdt_week_sow().1, 8.0);
            f.signed(&[(103, 10)], e.tgd_s, 1e-10);
            f.signed(&[(121, 10)], e.tgd2_s, 1e-10);
        }
        2 => f.iono(iono, &D2_IONO),
        3 => {
            f.signed(&[(101, 12), (121, 12)], e.af0, p2(-33));
            let (hi, _) = split(signed_raw(e.af1, p2(-50), 22), 22, 4);
            f.put(133, 4, hi);
        }
        4 => {
            let (_, lo) = split(signed_raw(e.af1, p2(-50), 22), 22, 4);
            f.put_slices(&[(47, 6), (61, 12)], lo);
            f.signed(&[(73, 10), (91, 1)], e.af2, p2(-66));
            f.put(92, 5, u64::from(e.iode) & 0x1f);
            f.signed(&[(97, 16)], e.delta_n / sc, p2(-43));
            let (hi, _) = split(signed_raw(e.cuc, p2(-31), 18), 18, 14);
            f.put(121, 14, hi);
        }
        5 => {
            let (_, lo) = split(signed_raw(e.cuc, p2(-31), 18), 18, 14);
            f.put(47, 4, lo);
            f.signed(&[(51, 2), (61, 22), (91, 8)], e.m0 / sc, p2(-31));
            f.signed(&[(99, 14), (121, 4)], e.cus, p2(-31));
            let (hi, _) = split(unsigned_raw(e.e, p2(-33), 32), 32, 10);
            f.put(125, 10, hi);
        }
        6 => {
            let (_, lo) = split(unsigned_raw(e.e, p2(-33), 32), 32, 10);
            f.put_slices(&[(47, 6), (61, 16)], lo);
            f.unsigned(&[(77, 6), (91, 22), (121, 4)], e.sqrt_a, p2(-19));
            let (hi, _) = split(signed_raw(e.cic, p2(-31), 18), 18, 10);
            f.put(125, 10, hi);
        }
        7 => {
            let (_, lo) = split(signed_raw(e.cic, p2(-31), 18), 18, 10);
            f.put_slices(&[(47, 6), (61, 2)], lo);
            f.signed(&[(63, 18)], e.cis, p2(-31));
            let toe = (e.toe_sow_s() / 8.0).round() as u64;
            f.put_slices(&[(81, 2), (91, 15)], toe & 0x1_ffff);
            let (hi, _) = split(signed_raw(e.i0 / sc, p2(-31), 32), 32, 21);
            f.put_slices(&[(106, 7), (121, 14)], hi);
        }
        8 => {
            let (_, lo) = split(signed_raw(e.i0 / sc, p2(-31), 32), 32, 21);
            f.put_slices(&[(47, 6), (61, 5)], lo);
            f.signed(&[(66, 17), (91, 1)], e.crc, p2(-6));
            f.signed(&[(92, 18)], e.crs, p2(-6));
            let (hi, _) = split(signed_raw(e.omega_dot / sc, p2(-43), 24), 24, 19);
            f.put_slices(&[(110, 3), (121, 16)], hi);
        }
        9 => {
            let (_, lo) = split(signed_raw(e.omega_dot / sc, p2(-43), 24), 24, 19);
            f.put(47, 5, lo);
            f.signed(&[(52, 1), (61, 22), (91, 9)], e.omega0 / sc, p2(-31));
            let (hi, _) = split(signed_raw(e.omega / sc, p2(-31), 32), 32, 27);
            f.put_slices(&[(100, 13), (121, 14)], hi);
        }
        _ => {
            let (_, lo) = split(signed_raw(e.omega / sc, p2(-31), 32), 32, 27);
            f.put(47, 5, lo);
            f.signed(&[(52, 1), (61, 13)], e.idot / sc, p2(-43));
        }
    }
    f
}

/// The page (1–6) of D2 subframes 2–4 in the frame that starts at BDT second of week
/// `sow` (a multiple of 3): `SOW/3 mod 6 + 1`, an 18 s cycle (as the SatGen generator
/// numbers them; subframe 2 carries the number, Pnum, subframes 3 and 4 none).
pub fn d2_integrity_page(sow: i64) -> i64 {
    (sow / 3).rem_euclid(6) + 1
}

/// The value sent in every UDREI (user differential range error index, 4 bits) slot.
/// 15 is the top of the 4-bit range, the value the Racelogic SatGen D2 generator
/// (`NavigationDataB1ID2`, `udrei = 15`) sends in every slot. The ICD's UDRE table that
/// names each index (§5.3.3, "not monitored" / "not available" in the SBAS convention) was
/// not available in any source checked here, so its label is not asserted.
pub const UDREI_SENT: u64 = 15;
/// The value sent in every RURAI (regional user range accuracy index, 4 bits) slot: 15,
/// the top of the range, which SatGen sends for a satellite it flags unhealthy
/// (`ruraiBad = 15`; `ruraiGood = 4` otherwise). Its table entry was not read either.
pub const RURAI_SENT: u64 = 15;
/// The value of every ionospheric grid point (13 bits: dτ, 9 bits at 0.125 m, then GIVEI,
/// 4 bits): dτ = 1 1111 1111 and GIVEI = 1111. dτ = 511 is what SatGen writes to every
/// grid point (`dTau = 63.875` m, with `givei = 15`); the "bnav" D2 decoder reads
/// dτ ≥ 510 as "no value" ("maximum value is 63.875 m, which is 511") and quotes the
/// GIVEI table of ICD §5.3.3.8.2, where GIVEI 15 is not a flag but the largest error
/// class, GIVE = 45.0 m ("according to the ICD there are no invalid values [of GIVEI]").
/// Which of 510 and 511 the ICD calls "not monitored" was not confirmed.
pub const GRID_POINT_SENT: u64 = (0x1ff << 4) | 0xf;

/// Where D2 subframes 2–4 (pages 1–6) put their fields, in the decoded numbering
/// (BDS-SIS-ICD-B1I-3.0 §5.3.2, Figures 5-18-x). Subframe 2: Pnum 44–47, SatH2 48–49,
/// BDID1–BDID30 (one bit each) 50–52, 61–82, 91–95, reserved, UDREI1–UDREI18 from 172,
/// RURAI1 276–279, Δt1 280–292. Subframe 3: RURAI2 44–47, Δt2, RURAI3 69–72, Δt3.
/// Subframe 4 (the ICD 3.0 extension to C31–C63): BDEpID 169–170, BDID31–BDID63,
/// UDREI19–UDREI24, RURAI4 252–255, Δt4. Positions as a public Python D2 decoder's tables
/// (`D2DictSf2`/`Sf3`/`Sf4`) give them; subframes 2 and 3 also as SatGen's
/// `NavigationDataB1ID2` composes its words (its subframe 4 predates ICD 3.0 and is all
/// reserved, so subframe 4 rests on the one decoder).
const UDREI_SLOTS_SF2: [&[(usize, usize)]; 18] = [
    &[(172, 1), (181, 3)],
    &[(184, 4)],
    &[(188, 4)],
    &[(192, 4)],
    &[(196, 4)],
    &[(200, 3), (211, 1)],
    &[(212, 4)],
    &[(216, 4)],
    &[(220, 4)],
    &[(224, 4)],
    &[(228, 4)],
    &[(232, 1), (241, 3)],
    &[(244, 4)],
    &[(248, 4)],
    &[(252, 4)],
    &[(256, 4)],
    &[(260, 3), (271, 1)],
    &[(272, 4)],
];
const UDREI_SLOTS_SF4: [&[(usize, usize)]; 6] = [
    &[(220, 4)],
    &[(224, 4)],
    &[(228, 4)],
    &[(232, 1), (241, 3)],
    &[(244, 4)],
    &[(248, 4)],
];
/// The RURAI fields of subframes 2 (RURAI1), 3 (RURAI2, RURAI3) and 4 (RURAI4).
const RURAI_SLOTS: [(u32, usize); 4] = [(2, 276), (3, 44), (3, 69), (4, 252)];

/// D2 subframes 2–4 (§5.3.3: integrity and differential correction information). hybridnav
/// runs no monitoring network, so no satellite is given corrections: every BDID (BDID1–63:
/// "1" when the satellite's integrity and differential information is broadcast, as
/// SatGen sets it for the satellites it sends RURAI/Δt for) is 0, every UDREI and RURAI
/// slot carries [`UDREI_SENT`] / [`RURAI_SENT`], and every equivalent clock correction
/// Δt (13 bits, 0.1 m) is 0 — no "not available" code of Δt could be confirmed in any
/// source (SatGen sends 0 for satellites it does not correct), and with every BDID 0 the
/// Δt slots belong to no satellite. SatH2 and BDEpID (2 bits each) are sent as 00: their
/// code tables were not found in any source checked here. Reserved bits are 0.
fn d2_integrity(f: &mut Fields, sow: i64, fra_id: u32) {
    if fra_id == 2 {
        f.put(44, 4, d2_integrity_page(sow) as u64);
        for slot in UDREI_SLOTS_SF2 {
            f.put_slices(slot, UDREI_SENT);
        }
    }
    if fra_id == 4 {
        for slot in UDREI_SLOTS_SF4 {
            f.put_slices(slot, UDREI_SENT);
        }
    }
    for (sf, first) in RURAI_SLOTS {
        if sf == fra_id {
            f.put(first, 4, RURAI_SENT);
        }
    }
}

/// The 13 grid points Ion1–Ion13 of an ionospheric grid page (subframe 5 pages 1–13 and
/// 61–73; pages 13 and 73 carry Ion1–Ion4 only, 320 points in all), in the decoded
/// numbering: as the "bnav" decoder (`Ionosphere::parseIonospherePage`) and the Python
/// decoder's `D2DictSf5IonoGridA`/`B` read them and SatGen writes them.
const GRID_SLOTS: [&[(usize, usize)]; 13] = [
    &[(51, 2), (61, 11)],
    &[(72, 11), (91, 2)],
    &[(93, 13)],
    &[(106, 7), (121, 6)],
    &[(127, 13)],
    &[(140, 3), (151, 10)],
    &[(161, 12), (181, 1)],
    &[(182, 13)],
    &[(195, 8), (211, 5)],
    &[(216, 13)],
    &[(229, 4), (241, 9)],
    &[(250, 13)],
    &[(271, 13)],
];

/// The D2 page (1–120) of subframe 5 in the frame that starts at BDT second of week `sow`
/// (a multiple of 3): `SOW/3 mod 120 + 1`, a 6-minute cycle (the ICD numbers pages without
/// tying them to the time, as for D1's [`d1_page`]).
pub fn d2_page5(sow: i64) -> i64 {
    (sow / 3).rem_euclid(120) + 1
}

/// D2 subframe 5 (§5.3.3; page layouts as GNSSTk's `BDSD2Bits.hpp` gives them, the same
/// fields at the same bits as D1's): pages 35–36 the health of C01–C30 with WNa and toa,
/// pages 37–60 the almanac of C01–C24, pages 95–100 that of C25–C30, page 101 the time
/// offsets to GPS, Galileo and GLONASS, page 102 the UTC parameters — the same data as D1
/// subframes 4–5. The ionospheric grid pages (1–13, 61–73) carry [`GRID_POINT_SENT`] in
/// every grid point: hybridnav has no grid to broadcast. The reserved pages carry only
/// their number.
fn d2_subframe5(f: &mut Fields, c: &SharedPages, week: i64, sow: i64) {
    let page = d2_page5(sow);
    f.put(44, 7, page as u64);
    let alm = |prn: i64| c.almanac.get(prn as usize - 1).copied().flatten();
    match page {
        1..=13 | 61..=73 => {
            let points = if page % 60 == 13 { 4 } else { 13 };
            for slot in GRID_SLOTS.iter().take(points) {
                f.put_slices(slot, GRID_POINT_SENT);
            }
        }
        35 | 36 => d1_health_page(f, c.almanac, page == 36, week, sow),
        37..=60 => d1_almanac_page(f, alm(page - 36).as_ref()),
        95..=100 => d1_almanac_page(f, alm(page - 70).as_ref()),
        101 => d1_time_page(f, &c.time, 9),
        102 => d1_time_page(f, &c.time, 10),
        _ => {}
    }
}

/// The 300 transmitted bits of the D1 subframe of `e` that starts at BDT `week`, `sow`,
/// with the Klobuchar set and time parameters of `c` (a missing set goes out as zeros).
pub fn d1_subframe(e: &Ephemeris, c: &SharedPages, week: i64, sow: i64, out: &mut [u8; 300]) {
    let fra_id = ((sow / 6).rem_euclid(5) + 1) as u32;
    d1_fields(e, c, week, sow, fra_id).encode(out);
}

/// The 300 transmitted bits of D2 subframe `fra_id` (1–5) of `e` in the frame that starts
/// at BDT `week`, `sow` (a multiple of 3), with the Klobuchar set, almanacs and time
/// parameters of `c`.
pub fn d2_subframe(
    e: &Ephemeris,
    c: &SharedPages,
    week: i64,
    sow: i64,
    fra_id: u32,
    out: &mut [u8; 300],
) {
    d2_fields(e, c, week, sow, fra_id).encode(out);
}

/// D1 subframes last 6 s, D2 subframes 0.6 s.
const D1_SUBFRAME_MS: i64 = 6000;
const D2_SUBFRAME_MS: i64 = 600;
/// D2's frame (3 s) and the cycle of subframe 1's ten pages (30 s).
const D2_FRAME_MS: i64 = 3000;
const D2_PAGES_MS: i64 = 30_000;

/// A satellite's navigation symbols over time: D1 for MEO/IGSO, D2 for GEO; the subframe
/// is rebuilt when a code period enters a new one.
pub struct BdsNavStream {
    nav: Arc<NavData>,
    sat: EmitterId,
    /// GPST − UTC (s), for the D1 UTC parameters.
    gpst_minus_utc_s: i32,
    /// The almanacs of C01–C30 and the toa they are referred to (rebuilt when a subframe's
    /// toa changes, every 4096 s).
    almanac: Vec<Option<Almanac>>,
    almanac_toa: Option<(i64, f64)>,
    geo: bool,
    subframe: i64,
    bits: [u8; 300],
}

impl BdsNavStream {
    /// The stream of `sat`: D2 when it is a GEO satellite, D1 otherwise; `gpst_minus_utc_s`
    /// gives D1's leap seconds.
    pub fn new(nav: Arc<NavData>, sat: EmitterId, gpst_minus_utc_s: i32) -> Self {
        Self {
            nav,
            gpst_minus_utc_s,
            almanac: Vec::new(),
            almanac_toa: None,
            geo: sat.is_bds_geo(),
            sat,
            subframe: i64::MIN,
            bits: [0; 300],
        }
    }

    /// Builds the subframe with index `sf` (subframes since the BDT epoch).
    fn build(&mut self, sf: i64) {
        let iono = self.nav.klobuchar_bds;
        let bdt = |ms: i64| GpsTime::from_ns((ms + BDT_EPOCH_MS) * 1_000_000);
        let len = if self.geo {
            D2_SUBFRAME_MS
        } else {
            D1_SUBFRAME_MS
        };
        let start_ms = sf * len;
        let t = bdt(start_ms);
        let toa = almanac::toa_for(crate::core::System::Bds, t);
        if self.almanac_toa != Some(toa) {
            almanac::fill_constellation(
                &self.nav,
                crate::core::System::Bds,
                30,
                t,
                &mut self.almanac,
            );
            self.almanac_toa = Some(toa);
        }
        let common = SharedPages {
            iono,
            time: BdsTimeParams::from_nav(&self.nav, self.gpst_minus_utc_s, t),
            almanac: &self.almanac,
        };
        if self.geo {
            let frame_ms = start_ms.div_euclid(D2_FRAME_MS) * D2_FRAME_MS;
            let week = frame_ms.div_euclid(WEEK_MS);
            let sow = frame_ms.rem_euclid(WEEK_MS) / 1000;
            let fra_id = (sf.rem_euclid(5) + 1) as u32;
            // One ephemeris for a whole 30 s cycle of pages, so that a receiver never
            // joins pages of two different ephemerides.
            let cycle_ms = start_ms.div_euclid(D2_PAGES_MS) * D2_PAGES_MS;
            match self.nav.select(self.sat, bdt(cycle_ms)) {
                Some(e) => d2_subframe(e, &common, week, sow, fra_id, &mut self.bits),
                None => self.bits = [0; 300],
            }
        } else {
            let week = start_ms.div_euclid(WEEK_MS);
            let sow = start_ms.rem_euclid(WEEK_MS) / 1000;
            match self.nav.select(self.sat, t) {
                Some(e) => d1_subframe(e, &common, week, sow, &mut self.bits),
                None => self.bits = [0; 300],
            }
        }
    }
}

impl NavSymbols for BdsNavStream {
    fn symbol(&mut self, ms: i64) -> u8 {
        let bdt_ms = ms - BDT_EPOCH_MS;
        let len = if self.geo {
            D2_SUBFRAME_MS
        } else {
            D1_SUBFRAME_MS
        };
        let sf = bdt_ms.div_euclid(len);
        if sf != self.subframe {
            self.subframe = sf;
            self.build(sf);
        }
        let in_sf = bdt_ms.rem_euclid(len);
        if self.geo {
            // 500 bit/s: two code periods a bit, no overlay code.
            self.bits[(in_sf / 2) as usize]
        } else {
            self.bits[(in_sf / 20) as usize] ^ NH[(in_sf % 20) as usize]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::ephemeris::tests::c05_2020;

    /// Polynomial remainder of a 15-bit word by X⁴ + X + 1, by long division.
    fn rem(word: u32) -> u32 {
        let mut w = word;
        for k in (4..15).rev() {
            if (w >> k) & 1 == 1 {
                w ^= 0b10011 << (k - 4);
            }
        }
        w
    }

    #[test]
    fn bch_codewords_are_multiples_of_the_generator() {
        for info in [0u32, 1, 0b101_1010_0110, 0x7ff, 0x400, 0x2aa] {
            let cw = (info << 4) | bch15_11(info);
            assert_eq!(rem(cw), 0, "info {info:011b}");
        }
        // A single flipped bit always leaves a non-zero syndrome.
        let cw = (0b101_1010_0110 << 4) | bch15_11(0b101_1010_0110);
        for k in 0..15 {
            assert_ne!(rem(cw ^ (1 << k)), 0);
        }
    }

    /// De-interleaves transmitted bits back to the decoded layout.
    fn deinterleave(tx: &[u8; 300]) -> [u8; 300] {
        let mut d = [0u8; 300];
        d[..30].copy_from_slice(&tx[..30]);
        for w in 1..10 {
            for k in 0..15 {
                let (a, b) = (tx[w * 30 + 2 * k], tx[w * 30 + 2 * k + 1]);
                if k < 11 {
                    d[w * 30 + k] = a;
                    d[w * 30 + 11 + k] = b;
                } else {
                    d[w * 30 + 22 + (k - 11)] = a;
                    d[w * 30 + 26 + (k - 11)] = b;
                }
            }
        }
        d
    }

    #[test]
    fn subframes_decode_back_to_the_ephemeris() {
        let mut e = c05_2020();
        e.sat = EmitterId::new(crate::core::System::Bds, 20);
        let (week, sow) = e.toe.bdt_week_sow();
        let sow = sow as i64 + 6; // FraID 2 (toe is a multiple of 30 s)
        let mut tx = [0u8; 300];
        d1_subframe(&e, &SharedPages::default(), week, sow, &mut tx);
        let d = deinterleave(&tx);
        let get = |sl: &[(usize, usize)]| -> u64 {
            sl.iter()
                .flat_map(|&(f, w)| (0..w).map(move |k| f - 1 + k))
                .fold(0u64, |a, i| (a << 1) | u64::from(d[i]))
        };
        assert_eq!(get(&[(1, 11)]), PREAMBLE);
        assert_eq!(get(&[(16, 3)]), 2);
        assert_eq!(get(&[(19, 8), (31, 12)]), sow as u64);
        let sqrt_a = get(&[(251, 12), (271, 20)]) as f64 * 2f64.powi(-19);
        assert!((sqrt_a - e.sqrt_a).abs() < 2f64.powi(-19));
        let m0 = get(&[(93, 20), (121, 12)]) as u32 as i32;
        assert!((f64::from(m0) * 2f64.powi(-31) * BDS_PI - e.m0).abs() < 1e-9);
        // Every codeword of every word is valid.
        for w in 0..10 {
            let cws: Vec<u32> = if w == 0 {
                vec![(15..30).fold(0, |a, k| (a << 1) | u32::from(tx[k]))]
            } else {
                (0..2)
                    .map(|r| (0..15).fold(0, |a, k| (a << 1) | u32::from(tx[w * 30 + 2 * k + r])))
                    .collect()
            };
            for cw in cws {
                assert_eq!(rem(cw), 0, "word {}", w + 1);
            }
        }
        // The NH code has its ICD value.
        assert_eq!(
            NH.iter().fold(0u32, |a, &b| (a << 1) | u32::from(b)),
            0b0000_0100_1101_0100_1110
        );
    }

    /// An unsigned field of decoded bits `d` over `slices` (1-based, MSBs first).
    fn uget(d: &[u8; 300], slices: &[(usize, usize)]) -> u64 {
        slices
            .iter()
            .flat_map(|&(f, w)| (0..w).map(move |k| f - 1 + k))
            .fold(0u64, |a, i| (a << 1) | u64::from(d[i]))
    }

    /// Two's complement value of the low `width` bits of `raw`.
    fn sext(raw: u64, width: u32) -> i64 {
        let shift = 64 - width;
        ((raw << shift) as i64) >> shift
    }

    fn sget(d: &[u8; 300], slices: &[(usize, usize)]) -> i64 {
        let width: usize = slices.iter().map(|s| s.1).sum();
        sext(uget(d, slices), width as u32)
    }

    /// Every BCH(15,11) codeword of the 300 transmitted bits is valid.
    fn assert_codewords_valid(tx: &[u8; 300]) {
        assert_eq!(rem((15..30).fold(0, |a, k| (a << 1) | u32::from(tx[k]))), 0);
        for w in 1..10 {
            for r in 0..2 {
                let cw = (0..15).fold(0, |a, k| (a << 1) | u32::from(tx[w * 30 + 2 * k + r]));
                assert_eq!(rem(cw), 0, "word {}", w + 1);
            }
        }
    }

    /// A BeiDou Klobuchar set as RINEX headers carry it (the `BDSA`/`BDSB` lines of the
    /// rinex_nav test).
    fn bds_klobuchar() -> Klobuchar {
        Klobuchar {
            alpha: [0.1397e-7, 0.0, -0.5960e-7, 0.5960e-7],
            beta: [0.1106e6, -0.3277e5, -0.2621e6, 0.1966e6],
        }
    }

    /// α0…β3 of a decoded subframe, read with the ICD's positions and scale factors
    /// (BDS-SIS-ICD-B1I-3.0 §5.2.4.7 and §5.3.3 as GNSS-SDR's decoder and SignalSim's
    /// encoder place them, written out here rather than taken from the encoder).
    fn decode_iono(d: &[u8; 300], d2: bool) -> [f64; 8] {
        let d1: [(&[(usize, usize)], i32); 8] = [
            (&[(127, 8)], -30),
            (&[(135, 8)], -27),
            (&[(151, 8)], -24),
            (&[(159, 8)], -24),
            (&[(167, 6), (181, 2)], 11),
            (&[(183, 8)], 14),
            (&[(191, 8)], 16),
            (&[(199, 4), (211, 4)], 16),
        ];
        let p2: [(&[(usize, usize)], i32); 8] = [
            (&[(47, 6), (61, 2)], -30),
            (&[(63, 8)], -27),
            (&[(71, 8)], -24),
            (&[(79, 4), (91, 4)], -24),
            (&[(95, 8)], 11),
            (&[(103, 8)], 14),
            (&[(111, 2), (121, 6)], 16),
            (&[(127, 8)], 16),
        ];
        let table = if d2 { p2 } else { d1 };
        table.map(|(sl, e)| sget(d, sl) as f64 * 2f64.powi(e))
    }

    fn assert_iono(got: [f64; 8], k: &Klobuchar) {
        let want = [
            k.alpha[0], k.alpha[1], k.alpha[2], k.alpha[3], k.beta[0], k.beta[1], k.beta[2],
            k.beta[3],
        ];
        for (i, ((g, w), lsb)) in got.iter().zip(want).zip(IONO_LSB_LOG2).enumerate() {
            assert!(
                (g - w).abs() <= 0.5 * 2f64.powi(lsb),
                "coefficient {i}: sent {w}, decoded {g}"
            );
        }
    }

    #[test]
    fn d1_subframe_1_carries_the_bds_klobuchar_set() {
        let mut e = c05_2020();
        e.sat = EmitterId::new(crate::core::System::Bds, 20);
        let (week, sow) = e.toe.bdt_week_sow();
        let sow = sow as i64; // FraID 1
        let k = bds_klobuchar();
        let (mut with, mut without) = ([0u8; 300], [0u8; 300]);
        let with_k = SharedPages {
            iono: Some(k),
            ..SharedPages::default()
        };
        d1_subframe(&e, &with_k, week, sow, &mut with);
        d1_subframe(&e, &SharedPages::default(), week, sow, &mut without);
        assert_codewords_valid(&with);
        let (dw, dn) = (deinterleave(&with), deinterleave(&without));
        assert_eq!(uget(&dw, &[(16, 3)]), 1);
        assert_iono(decode_iono(&dw, false), &k);
        // Without a BeiDou set the coefficients are zeros …
        assert_eq!(decode_iono(&dn, false), [0.0; 8]);
        // … and the set changes no other information bit (a0–a2, AODE, TGD2 around it).
        let iono_bits: Vec<usize> = [(127, 40), (167, 6), (181, 22), (211, 4)]
            .iter()
            .flat_map(|&(f, w)| (f..f + w).collect::<Vec<_>>())
            .collect();
        for w in 0..10 {
            for i in (w * 30 + 1)..=(w * 30 + 22) {
                if !iono_bits.contains(&i) {
                    assert_eq!(dw[i - 1], dn[i - 1], "bit {i}");
                }
            }
        }
        let a0 = sget(&dw, &[(226, 7), (241, 17)]) as f64 * 2f64.powi(-33);
        assert!((a0 - e.af0).abs() <= 2f64.powi(-34));
        // A coefficient outside its 8-bit range saturates instead of wrapping.
        let mut big = k;
        big.beta[0] = 1e6;
        let big = SharedPages {
            iono: Some(big),
            ..SharedPages::default()
        };
        d1_subframe(&e, &big, week, sow, &mut with);
        assert_eq!(sget(&deinterleave(&with), &[(167, 6), (181, 2)]), 127);
    }

    /// A RINEX 3 header with the time-system lines an IGS merged file carries: GPUT and
    /// GAUT of the ESBC00DNK file of 2020-06-25, BDUT and GLUT with the a0/a1 of an IGS
    /// header of 2021 (as the `rinex` crate's tests quote it) referred to that day, and a
    /// full LEAP SECONDS line (the 2017-01-01 leap second: GPS week 1929, day 7).
    pub(crate) const TIME_HEADER: &str =
        "     3.04           N: GNSS NAV DATA    M: MIXED            RINEX VERSION / TYPE
GPUT  9.3132257462E-10 2.664535259E-15 589824 2111          TIME SYSTEM CORR
GAUT -9.3132257462E-10 0.000000000E+00 345600 2111          TIME SYSTEM CORR
BDUT  1.8626451492E-09-4.085620730E-14 345600  755          TIME SYSTEM CORR
GLUT -1.8626451492E-09 0.000000000E+00      0    0          TIME SYSTEM CORR
    18    18  1929     7GPS                                 LEAP SECONDS
                                                            END OF HEADER
";

    #[test]
    fn d1_subframe_5_pages_9_and_10_carry_the_time_parameters() {
        let nav = crate::gnss::rinex_nav::parse_nav(TIME_HEADER, "time.rnx").expect("header");
        let mut e = c05_2020();
        e.sat = EmitterId::new(crate::core::System::Bds, 20);
        // BDT week 755, a frame whose subframes 4–5 carry page 9 (SOW = 720k + 240), and
        // the next frame (page 10).
        let week = 755;
        let sow9 = 720 * 490 + 240;
        assert_eq!(d1_page(sow9), 9);
        assert_eq!(d1_page(sow9 + 30), 10);
        let decode = |sow: i64| -> [u8; 300] {
            let t = GpsTime::from_bdt_week_sow(week, sow as f64);
            let c = SharedPages {
                iono: None,
                time: BdsTimeParams::from_nav(&nav, 18, t),
                almanac: &[],
            };
            let mut tx = [0u8; 300];
            d1_subframe(&e, &c, week, sow, &mut tx);
            assert_codewords_valid(&tx);
            deinterleave(&tx)
        };
        let p9 = decode(sow9 + 24);
        let p10 = decode(sow9 + 30 + 24);
        assert_eq!(uget(&p9, &[(16, 3)]), 5, "FraID");
        assert_eq!(uget(&p9, &[(44, 7)]), 9, "Pnum");
        assert_eq!(uget(&p10, &[(44, 7)]), 10, "Pnum");
        // The header's corrections at the page's time, written out here from RINEX 3.05
        // §5.2: CORR = a0 + a1·(t − t_ref), t_ref in the line's own system.
        let t9 = GpsTime::from_bdt_week_sow(week, (sow9 + 24) as f64);
        let gps_ref = |w: i64, s: f64| GpsTime::from_week_tow(w, s);
        let corr_gp =
            9.3132257462E-10 + 2.664535259E-15 * t9.seconds_since(gps_ref(2111, 589_824.0));
        let corr_ga = -9.3132257462E-10;
        let corr_bd = 1.8626451492E-09
            - 4.085620730E-14 * t9.seconds_since(GpsTime::from_bdt_week_sow(755, 345_600.0));
        let corr_gl = -1.8626451492E-09;
        // Page 9 (GNSSTk's BDSD1Bits.hpp positions): 0.1 ns and 0.1 ns/s LSBs; the
        // drifts (~1e-14) are far below 0.1 ns/s, so A1 = 0 and A0 = the offset now.
        let ns = |sl: &[(usize, usize)]| sget(&p9, sl) as f64 * 0.1e-9;
        let within = |name: &str, got: f64, want: f64, lsb: f64| {
            assert!(
                (got - want).abs() <= 0.5 * lsb * (1.0 + 1e-9),
                "{name}: sent {want:e}, decoded {got:e}"
            );
        };
        within("A0GPS", ns(&[(97, 14)]), corr_bd - corr_gp, 0.1e-9);
        assert_eq!(sget(&p9, &[(111, 2), (121, 14)]), 0, "A1GPS");
        within(
            "A0Gal",
            ns(&[(135, 8), (151, 6)]),
            corr_bd - corr_ga,
            0.1e-9,
        );
        assert_eq!(sget(&p9, &[(157, 16)]), 0, "A1Gal");
        within("A0GLO", ns(&[(181, 14)]), corr_bd - corr_gl, 0.1e-9);
        assert_eq!(sget(&p9, &[(195, 8), (211, 8)]), 0, "A1GLO");
        assert_ne!(sget(&p9, &[(97, 14)]), 0, "a non-zero offset was sent");
        // Page 10: ΔtLS = 18 − 14, the announced leap (GPS week 1929 day 7 → BDT week 573
        // day 6, ΔtLSF 18 − 14), A0UTC + A1UTC·SOW = CORR_BD at the page's time.
        assert_eq!(sget(&p10, &[(51, 2), (61, 6)]), 4, "ΔtLS");
        assert_eq!(sget(&p10, &[(67, 8)]), 4, "ΔtLSF");
        assert_eq!(uget(&p10, &[(75, 8)]), 573 % 256, "WNLSF");
        assert_eq!(uget(&p10, &[(163, 8)]), 6, "DN");
        let a1_utc = sget(&p10, &[(131, 12), (151, 12)]) as f64 * 2f64.powi(-50);
        within("A1UTC", a1_utc, -4.085620730E-14, 2f64.powi(-50));
        let a0_utc = sget(&p10, &[(91, 22), (121, 10)]) as f64 * 2f64.powi(-30);
        let t10 = GpsTime::from_bdt_week_sow(week, (sow9 + 54) as f64);
        let corr_bd10 = 1.8626451492E-09
            - 4.085620730E-14 * t10.seconds_since(GpsTime::from_bdt_week_sow(755, 345_600.0));
        within(
            "A0UTC + A1UTC·SOW",
            a0_utc + a1_utc * (sow9 + 54) as f64,
            corr_bd10,
            2f64.powi(-30),
        );
        // A reserved page of subframe 5 leaves those bits alone, and without the lines the
        // offsets are zeros, the leap seconds still GPST − UTC − 14 s.
        let bare = NavData::new(Vec::new(), None, Some(18));
        let tp = BdsTimeParams::from_nav(&bare, 18, t9);
        assert_eq!((tp.a0_gps_s, tp.a0_utc_s, tp.a1_utc), (0.0, 0.0, 0.0));
        assert_eq!((tp.dt_ls_s, tp.dt_lsf_s, tp.wn_lsf, tp.dn), (4, 4, 755, 6));
        let p11 = decode(sow9 + 60 + 24);
        assert_eq!(uget(&p11, &[(44, 7)]), 11);
        assert_eq!(uget(&p11, &[(97, 14)]), 0);
    }

    /// D2 subframe 5 pages 35–37, 95, 101, 102 carry exactly the fields of D1's subframe 5
    /// pages 7, 8, subframe 4 page 1, subframe 5 page 1, pages 9, 10 (GNSSTk's D2 layout is
    /// D1's), with their own page numbers; a grid page (1) only its number.
    #[test]
    fn d2_subframe_5_repeats_the_d1_almanac_health_and_time_pages() {
        let nav = crate::gnss::rinex_nav::parse_nav(TIME_HEADER, "time.rnx").expect("header");
        let geo = c05_2020();
        let (week, toe_sow) = geo.toe.bdt_week_sow();
        let t = GpsTime::from_bdt_week_sow(week, toe_sow);
        let mut meo = c05_2020();
        meo.sat = EmitterId::new(crate::core::System::Bds, 20);
        // Almanacs of C05 and C20 (index PRN − 1), the rest absent.
        let mut almanac = vec![None; 30];
        for e in [&geo, &meo] {
            let (w, s) = almanac::toa_for(crate::core::System::Bds, t);
            almanac[usize::from(e.sat.number) - 1] = Some(Almanac::from_ephemeris(e, w, s));
        }
        let c = SharedPages {
            iono: None,
            time: BdsTimeParams::from_nav(&nav, 18, t),
            almanac: &almanac,
        };
        // The D2 frame whose subframe 5 is page `p`, the D1 frame whose subframe `fra` is
        // page `q`: their decoded bits from 51 on (after the page number).
        let week_start = 720 * 490; // a multiple of 360 s (D2) and 720 s (D1)
        let d2 = |p: i64| {
            let sow = week_start + 3 * (p - 1);
            let mut tx = [0u8; 300];
            d2_subframe(&geo, &c, week, sow, 5, &mut tx);
            assert_codewords_valid(&tx);
            let d = deinterleave(&tx);
            assert_eq!(uget(&d, &[(44, 7)]), p as u64, "D2 Pnum");
            d
        };
        let d1 = |fra: i64, q: i64| {
            let sow = week_start + 30 * (q - 1) + 6 * (fra - 1);
            let mut tx = [0u8; 300];
            d1_subframe(&meo, &c, week, sow, &mut tx);
            let d = deinterleave(&tx);
            assert_eq!(uget(&d, &[(44, 7)]), q as u64, "D1 Pnum");
            d
        };
        let info = |d: &[u8; 300]| -> Vec<u8> {
            (1..10)
                .flat_map(|w| (w * 30..w * 30 + 22).collect::<Vec<_>>())
                .filter(|&i| i >= 50)
                .map(|i| d[i])
                .collect()
        };
        for (p, fra, q) in [(35, 5, 7), (37, 4, 1), (101, 5, 9), (102, 5, 10)] {
            assert_eq!(
                info(&d2(p)),
                info(&d1(fra, q)),
                "D2 page {p} vs D1 {fra}/{q}"
            );
        }
        // Page 36 (WNa, toa at the frame's time) against D1 page 8 sent in the same toa.
        assert_eq!(info(&d2(36)), info(&d1(5, 8)), "D2 page 36 vs D1 page 8");
        // C05's almanac page is 41 (37 + 4) and not zero; C25's (page 95) is zeros.
        assert_ne!(uget(&d2(41), &[(51, 2), (61, 22)]), 0);
        assert_eq!(uget(&d2(95), &[(51, 2), (61, 22)]), 0);
        // A reserved page (14) carries its number only.
        assert!(info(&d2(14)).iter().all(|&b| b == 0), "page 14 reserved");
    }

    /// A field of decoded bits over 0-based inclusive ranges `[first, last]`, the notation
    /// of the Python D2 decoder's tables (`D2DictSf2` …) whose positions are transcribed
    /// below, MSBs first.
    fn field0(d: &[u8; 300], ranges: &[(usize, usize)]) -> u64 {
        ranges
            .iter()
            .flat_map(|&(a, b)| a..=b)
            .fold(0, |acc, i| (acc << 1) | u64::from(d[i]))
    }

    /// Asserts that every information bit (0-based) of `d` outside the header (bits 0–41:
    /// preamble, reserved, FraID, SOW) and outside `fields` is 0: the reserved bits.
    fn assert_reserved_zero(d: &[u8; 300], fields: &[&[(usize, usize)]], what: &str) {
        let used: Vec<usize> = fields
            .iter()
            .flat_map(|f| f.iter().flat_map(|&(a, b)| a..=b))
            .collect();
        for w in 1..10 {
            for (i, &bit) in d.iter().enumerate().skip(30 * w).take(22) {
                if i >= 42 && !used.contains(&i) {
                    assert_eq!(bit, 0, "{what}: reserved bit {i} (0-based)");
                }
            }
        }
    }

    /// The D2 integrity subframes (2–4, pages 1–6) and the ionospheric grid pages of
    /// subframe 5 (1–13, 61–73), read with positions transcribed from the Python D2
    /// decoder's tables (0-based; subframes 2–3 also agree with SatGen's
    /// `NavigationDataB1ID2`, the grid with the "bnav" decoder), not from the encoder's
    /// constants: no BDID is set, every UDREI and RURAI slot is 15, every Δt is 0, every
    /// grid point is dτ = 511 with GIVEI = 15, and every other information bit is 0.
    #[test]
    fn d2_integrity_subframes_and_grid_pages_carry_no_corrections() {
        let e = c05_2020();
        let (week, _) = e.toe.bdt_week_sow();
        let base = 720 * 490; // a multiple of 18 s (subframes 2–4) and 360 s (subframe 5)
        let c = SharedPages::default();
        let decoded = |sow: i64, fra: u32| {
            let mut tx = [0u8; 300];
            d2_subframe(&e, &c, week, sow, fra, &mut tx);
            assert_codewords_valid(&tx);
            let d = deinterleave(&tx);
            assert_eq!(field0(&d, &[(0, 10)]), 0b111_0001_0010, "preamble");
            assert_eq!(field0(&d, &[(15, 17)]), u64::from(fra), "FraID");
            assert_eq!(field0(&d, &[(18, 25), (30, 41)]), sow as u64, "SOW");
            d
        };
        // D2DictSf2: UDREI1 … UDREI18.
        let udrei_sf2: [&[(usize, usize)]; 18] = [
            &[(171, 171), (180, 182)],
            &[(183, 186)],
            &[(187, 190)],
            &[(191, 194)],
            &[(195, 198)],
            &[(199, 201), (210, 210)],
            &[(211, 214)],
            &[(215, 218)],
            &[(219, 222)],
            &[(223, 226)],
            &[(227, 230)],
            &[(231, 231), (240, 242)],
            &[(243, 246)],
            &[(247, 250)],
            &[(251, 254)],
            &[(255, 258)],
            &[(259, 261), (270, 270)],
            &[(271, 274)],
        ];
        // D2DictSf4: UDREI19 … UDREI24.
        let udrei_sf4: [&[(usize, usize)]; 6] = [
            &[(219, 222)],
            &[(223, 226)],
            &[(227, 230)],
            &[(231, 231), (240, 242)],
            &[(243, 246)],
            &[(247, 250)],
        ];
        for page in 1..=6u64 {
            let sow = base + 3 * (page as i64 - 1);
            // Subframe 2.
            let d = decoded(sow, 2);
            let pnum: &[(usize, usize)] = &[(43, 46)];
            let sath2: &[(usize, usize)] = &[(47, 48)];
            let bdid: &[(usize, usize)] = &[(49, 51), (60, 81), (90, 94)];
            let rurai1: &[(usize, usize)] = &[(275, 278)];
            let dt1: &[(usize, usize)] = &[(279, 291)];
            assert_eq!(field0(&d, pnum), page, "Pnum");
            assert_eq!(field0(&d, sath2), 0, "SatH2");
            assert_eq!(field0(&d, bdid), 0, "BDID1–30");
            for (i, u) in udrei_sf2.iter().enumerate() {
                assert_eq!(field0(&d, u), 15, "UDREI{} page {page}", i + 1);
            }
            assert_eq!(field0(&d, rurai1), 15, "RURAI1");
            assert_eq!(field0(&d, dt1), 0, "Δt1");
            let mut f2: Vec<&[(usize, usize)]> = vec![pnum, sath2, bdid, rurai1, dt1];
            f2.extend(udrei_sf2);
            assert_reserved_zero(&d, &f2, "subframe 2");
            // Subframe 3 (D2DictSf3).
            let d = decoded(sow, 3);
            let rurai2: &[(usize, usize)] = &[(43, 46)];
            let dt2: &[(usize, usize)] = &[(47, 51), (60, 67)];
            let rurai3: &[(usize, usize)] = &[(68, 71)];
            let dt3: &[(usize, usize)] = &[(72, 81), (90, 92)];
            assert_eq!(field0(&d, rurai2), 15, "RURAI2");
            assert_eq!(field0(&d, dt2), 0, "Δt2");
            assert_eq!(field0(&d, rurai3), 15, "RURAI3");
            assert_eq!(field0(&d, dt3), 0, "Δt3");
            assert_reserved_zero(&d, &[rurai2, dt2, rurai3, dt3], "subframe 3");
            // Subframe 4 (D2DictSf4).
            let d = decoded(sow, 4);
            let bdepid: &[(usize, usize)] = &[(168, 169)];
            let bdid_ext: &[(usize, usize)] = &[(170, 171), (180, 201), (210, 218)];
            let rurai4: &[(usize, usize)] = &[(251, 254)];
            let dt4: &[(usize, usize)] = &[(255, 261), (270, 275)];
            assert_eq!(field0(&d, bdepid), 0, "BDEpID");
            assert_eq!(field0(&d, bdid_ext), 0, "BDID31–63");
            for (i, u) in udrei_sf4.iter().enumerate() {
                assert_eq!(field0(&d, u), 15, "UDREI{} page {page}", i + 19);
            }
            assert_eq!(field0(&d, rurai4), 15, "RURAI4");
            assert_eq!(field0(&d, dt4), 0, "Δt4");
            let mut f4: Vec<&[(usize, usize)]> = vec![bdepid, bdid_ext, rurai4, dt4];
            f4.extend(udrei_sf4);
            assert_reserved_zero(&d, &f4, "subframe 4");
        }
        // D2DictSf5IonoGridA (pages 1–12, 61–72: IonoA … IonoM) and B (13, 73: A … D).
        let grid: [&[(usize, usize)]; 13] = [
            &[(50, 51), (60, 70)],
            &[(71, 81), (90, 91)],
            &[(92, 104)],
            &[(105, 111), (120, 125)],
            &[(126, 138)],
            &[(139, 141), (150, 159)],
            &[(160, 171), (180, 180)],
            &[(181, 193)],
            &[(194, 201), (210, 214)],
            &[(215, 227)],
            &[(228, 231), (240, 248)],
            &[(249, 261)],
            &[(270, 282)],
        ];
        let pnum5: &[(usize, usize)] = &[(43, 49)];
        let mut points = 0;
        for page in (1..=13).chain(61..=73) {
            let d = decoded(base + 3 * (page - 1), 5);
            assert_eq!(field0(&d, pnum5), page as u64, "Pnum");
            let n = if page == 13 || page == 73 { 4 } else { 13 };
            for (i, g) in grid.iter().take(n).enumerate() {
                let v = field0(&d, g);
                // dτ: the 9 MSBs (0.125 m); GIVEI: the 4 LSBs.
                assert_eq!(v >> 4, 511, "dτ of Ion{} page {page}", i + 1);
                assert_eq!(v & 0xf, 15, "GIVEI of Ion{} page {page}", i + 1);
                points += 1;
            }
            let mut fields: Vec<&[(usize, usize)]> = vec![pnum5];
            fields.extend(grid.iter().take(n));
            assert_reserved_zero(&d, &fields, "grid page");
        }
        assert_eq!(points, 320, "the ICD's 320 grid points");
    }

    /// The 9-bit health words Hea_i (D1 subframe 5 page 7, read at the Python decoder's
    /// `D1DictHealthA` positions) against ICD Table 5-15 as GNSSTk quotes it: 0 for a
    /// healthy satellite; for one whose ephemeris says SatH1 = 1 and for an empty slot,
    /// bit 8 (clock) set with the other eight all 1, "in failure or permanently shut off".
    #[test]
    fn bds_health_words_follow_table_5_15() {
        let mut ok = c05_2020();
        ok.sat = EmitterId::new(crate::core::System::Bds, 1);
        let mut bad = ok.clone();
        bad.sat = EmitterId::new(crate::core::System::Bds, 2);
        bad.health = 1; // SatH1 = 1
        let (w, s) = ok.toe.bdt_week_sow();
        let mut almanac = vec![None; 30];
        almanac[0] = Some(Almanac::from_ephemeris(&ok, w, s));
        almanac[1] = Some(Almanac::from_ephemeris(&bad, w, s));
        let c = SharedPages {
            almanac: &almanac,
            ..SharedPages::default()
        };
        let week = 755;
        let sow = 720 * 490 + 30 * 6 + 24; // page 7, subframe 5
        assert_eq!(d1_page(sow), 7);
        let mut tx = [0u8; 300];
        d1_subframe(&ok, &c, week, sow, &mut tx);
        let d = deinterleave(&tx);
        let hea = [
            field0(&d, &[(50, 51), (60, 66)]),
            field0(&d, &[(67, 75)]),
            field0(&d, &[(76, 81), (90, 92)]),
        ];
        // Table 5-15 read bit by bit: bit 8 clock, bits 7–5 B1I/B2I/B3I, bit 1 message.
        let failed_or_shut_off = |h: u64| h >> 8 == 1 && h & 0xff == 0xff;
        assert_eq!(hea[0], 0, "C01 healthy: every bit OK");
        assert!(failed_or_shut_off(hea[1]), "C02 SatH1 = 1: {:09b}", hea[1]);
        assert!(failed_or_shut_off(hea[2]), "C03 no almanac: {:09b}", hea[2]);
    }

    #[test]
    fn d2_pages_decode_back_to_the_ephemeris() {
        let e = c05_2020();
        assert!(e.sat.is_bds_geo());
        let k = bds_klobuchar();
        let with_k = SharedPages {
            iono: Some(k),
            ..SharedPages::default()
        };
        let (week, toe_sow) = e.toe.bdt_week_sow();
        let sow0 = toe_sow as i64; // a multiple of 30 s: page 1
        let pages: Vec<[u8; 300]> = (0..10)
            .map(|p| {
                let sow = sow0 + 3 * p;
                let mut tx = [0u8; 300];
                d2_subframe(&e, &with_k, week, sow, 1, &mut tx);
                assert_codewords_valid(&tx);
                let d = deinterleave(&tx);
                assert_eq!(uget(&d, &[(1, 11)]), PREAMBLE);
                assert_eq!(uget(&d, &[(16, 3)]), 1);
                assert_eq!(uget(&d, &[(19, 8), (31, 12)]), sow as u64);
                assert_eq!(uget(&d, &[(43, 4)]), p as u64 + 1, "Pnum");
                d
            })
            .collect();
        let pg = |n: usize| &pages[n - 1];
        // The ICD's D2 subframe 1 layout (§5.3.3, as RTKLIB's `decode_bds_d2` reads it),
        // written out here.
        assert_eq!(uget(pg(1), &[(47, 1)]), 0, "SatH1");
        assert_eq!(uget(pg(1), &[(48, 5)]), u64::from(e.iodc), "AODC");
        assert_eq!(uget(pg(1), &[(65, 13)]), week as u64, "WN");
        assert_eq!(uget(pg(1), &[(78, 5), (91, 12)]) * 8, toe_sow as u64, "toc");
        let close = |name: &str, got: f64, want: f64, lsb: f64| {
            assert!(
                (got - want).abs() <= 0.5 * lsb * (1.0 + 1e-9),
                "{name}: sent {want}, decoded {got}"
            );
        };
        close(
            "TGD1",
            sget(pg(1), &[(103, 10)]) as f64 * 1e-10,
            e.tgd_s,
            1e-10,
        );
        close(
            "TGD2",
            sget(pg(1), &[(121, 10)]) as f64 * 1e-10,
            e.tgd2_s,
            1e-10,
        );
        assert_iono(decode_iono(pg(2), true), &k);
        let s = |x: i64, e: i32| x as f64 * 2f64.powi(e);
        close(
            "a0",
            s(sget(pg(3), &[(101, 12), (121, 12)]), -33),
            e.af0,
            2f64.powi(-33),
        );
        let a1 = (uget(pg(3), &[(133, 4)]) << 18) | uget(pg(4), &[(47, 6), (61, 12)]);
        close("a1", s(sext(a1, 22), -50), e.af1, 2f64.powi(-50));
        close(
            "a2",
            s(sget(pg(4), &[(73, 10), (91, 1)]), -66),
            e.af2,
            2f64.powi(-66),
        );
        assert_eq!(uget(pg(4), &[(92, 5)]), u64::from(e.iode), "AODE");
        let pi = BDS_PI;
        let ang = |x: i64, e: i32| x as f64 * 2f64.powi(e) * pi;
        close(
            "Δn",
            ang(sget(pg(4), &[(97, 16)]), -43),
            e.delta_n,
            pi * 2f64.powi(-43),
        );
        let cuc = (uget(pg(4), &[(121, 14)]) << 4) | uget(pg(5), &[(47, 4)]);
        close("Cuc", s(sext(cuc, 18), -31), e.cuc, 2f64.powi(-31));
        let m0 = sget(pg(5), &[(51, 2), (61, 22), (91, 8)]);
        close("M0", ang(m0, -31), e.m0, pi * 2f64.powi(-31));
        close(
            "Cus",
            s(sget(pg(5), &[(99, 14), (121, 4)]), -31),
            e.cus,
            2f64.powi(-31),
        );
        let ecc = (uget(pg(5), &[(125, 10)]) << 22) | uget(pg(6), &[(47, 6), (61, 16)]);
        close("e", ecc as f64 * 2f64.powi(-33), e.e, 2f64.powi(-33));
        let sqrt_a = uget(pg(6), &[(77, 6), (91, 22), (121, 4)]);
        close(
            "√A",
            sqrt_a as f64 * 2f64.powi(-19),
            e.sqrt_a,
            2f64.powi(-19),
        );
        let cic = (uget(pg(6), &[(125, 10)]) << 8) | uget(pg(7), &[(47, 6), (61, 2)]);
        close("Cic", s(sext(cic, 18), -31), e.cic, 2f64.powi(-31));
        close(
            "Cis",
            s(sget(pg(7), &[(63, 18)]), -31),
            e.cis,
            2f64.powi(-31),
        );
        assert_eq!(uget(pg(7), &[(81, 2), (91, 15)]) * 8, toe_sow as u64, "toe");
        let i0 = (uget(pg(7), &[(106, 7), (121, 14)]) << 11) | uget(pg(8), &[(47, 6), (61, 5)]);
        close("i0", ang(sext(i0, 32), -31), e.i0, pi * 2f64.powi(-31));
        close(
            "Crc",
            s(sget(pg(8), &[(66, 17), (91, 1)]), -6),
            e.crc,
            2f64.powi(-6),
        );
        close("Crs", s(sget(pg(8), &[(92, 18)]), -6), e.crs, 2f64.powi(-6));
        let od = (uget(pg(8), &[(110, 3), (121, 16)]) << 5) | uget(pg(9), &[(47, 5)]);
        close(
            "Ω̇",
            ang(sext(od, 24), -43),
            e.omega_dot,
            pi * 2f64.powi(-43),
        );
        let o0 = sget(pg(9), &[(52, 1), (61, 22), (91, 9)]);
        close("Ω0", ang(o0, -31), e.omega0, pi * 2f64.powi(-31));
        let w = (uget(pg(9), &[(100, 13), (121, 14)]) << 5) | uget(pg(10), &[(47, 5)]);
        close("ω", ang(sext(w, 32), -31), e.omega, pi * 2f64.powi(-31));
        let idot = sget(pg(10), &[(52, 1), (61, 13)]);
        close("IDOT", ang(idot, -43), e.idot, pi * 2f64.powi(-43));
        // The other subframes of a frame: the frame's SOW (not their own start), their
        // FraID, valid codewords.
        for fra_id in 2..=5 {
            let mut tx = [0u8; 300];
            d2_subframe(&e, &with_k, week, sow0, fra_id, &mut tx);
            assert_codewords_valid(&tx);
            let d = deinterleave(&tx);
            assert_eq!(uget(&d, &[(16, 3)]), u64::from(fra_id));
            assert_eq!(uget(&d, &[(19, 8), (31, 12)]), sow0 as u64);
        }
    }

    #[test]
    fn geo_satellites_send_d2_at_500_bps_and_the_others_d1_with_nh() {
        let c05 = c05_2020();
        let mut c20 = c05_2020();
        c20.sat = EmitterId::new(crate::core::System::Bds, 20);
        let mut nav = NavData::new(vec![c05.clone(), c20.clone()], None, Some(18));
        nav.klobuchar_bds = Some(bds_klobuchar());
        let nav = Arc::new(nav);
        let (week, toe_sow) = c05.toe.bdt_week_sow();
        // Satellite time (ms since the GPS epoch) of BDT week `week`, `sow` + `ms`.
        let at = |sow: i64, ms: i64| BDT_EPOCH_MS + week * WEEK_MS + sow * 1000 + ms;
        let sow0 = toe_sow as i64;
        let k = bds_klobuchar();
        // C05: subframe 3 of the frame at sow0 + 3 starts 1.2 s into the frame; each of its
        // 300 bits lasts two code periods, with no overlay code.
        let mut geo = BdsNavStream::new(Arc::clone(&nav), c05.sat, 18);
        let mut want = [0u8; 300];
        d2_subframe(
            &c05,
            &SharedPages {
                iono: Some(k),
                ..SharedPages::default()
            },
            week,
            sow0 + 3,
            3,
            &mut want,
        );
        for (i, &bit) in want.iter().enumerate() {
            let ms = at(sow0 + 3, 1200 + 2 * i as i64);
            assert_eq!(geo.symbol(ms), bit, "bit {i}");
            assert_eq!(geo.symbol(ms + 1), bit, "bit {i}, second period");
        }
        // Page 2 of subframe 1 (3 s after page 1) carries the BeiDou Klobuchar set.
        let mut tx = [0u8; 300];
        for (i, b) in tx.iter_mut().enumerate() {
            *b = geo.symbol(at(sow0 + 3, 2 * i as i64));
        }
        assert_iono(decode_iono(&deinterleave(&tx), true), &k);
        // C20: D1 subframe 2 (6 s in), each bit over 20 periods ⊕ the NH code.
        let mut meo = BdsNavStream::new(Arc::clone(&nav), c20.sat, 18);
        let c = SharedPages {
            iono: Some(k),
            time: BdsTimeParams::from_nav(
                &nav,
                18,
                GpsTime::from_bdt_week_sow(week, (sow0 + 6) as f64),
            ),
            almanac: &[],
        };
        d1_subframe(&c20, &c, week, sow0 + 6, &mut want);
        for (i, &bit) in want.iter().enumerate() {
            for m in 0..20 {
                let ms = at(sow0 + 6, 20 * i as i64 + m);
                assert_eq!(meo.symbol(ms), bit ^ NH[m as usize], "bit {i} chip {m}");
            }
        }
    }
}
