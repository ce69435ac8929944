//! The BeiDou D1 navigation message on B1I (BDS-SIS-ICD-B1I-3.0 §5.2): the message of the
//! MEO and IGSO satellites. (D2, the GEO satellites' 500 bit/s message, is not generated:
//! a recording leaves the GEO satellites out.)
//!
//! A subframe is 300 bits at 50 bit/s (6 s), starting at a BDT second of week that is a
//! multiple of 6; five subframes make a 30 s frame (FraID = SOW/6 mod 5 + 1). Each bit is
//! spread by the 20-chip Neumann–Hoffman code 00000100110101001110, one chip per 1 ms code
//! period, so the symbol of code period `m` (BDT ms of week) is `bit(m/20) ⊕ NH(m mod 20)`.
//!
//! Word 1 is the 11-bit preamble 11100010010, 4 reserved bits and 11 information bits (FraID,
//! the 8 MSBs of SOW) protected by a BCH(15,11) code; words 2–10 carry 22 information bits as
//! two BCH(15,11) codewords, sent interleaved chip by chip (codeword 1 bit 1, codeword 2 bit 1,
//! …). The BCH code is systematic with generator g(X) = X⁴ + X + 1: the 4 check bits are
//! the remainder of info(X)·X⁴ divided by g(X) (§5.1.3).
//!
//! Field positions below are those of the de-interleaved subframe (words of 30 bits, each
//! word's information bits first, then its check bits), as the ICD's figures number them:
//! SOW = SOW at the subframe's first bit. Subframe 1: SatH1, AODC, URAI, WN, toc, TGD1/2, the
//! Klobuchar α/β (GPS-style coefficients broadcast by BDS), a0–a2, AODE; subframes 2–3: the
//! Keplerian elements (angles in semicircles, π = 3.1415926535898); subframes 4–5: the page
//! number only (no almanac is broadcast).

use crate::core::{EmitterId, GpsTime};
use crate::gnss::ephemeris::Ephemeris;
use crate::gnss::rinex_nav::NavData;
use crate::gnss::signal::baseband::NavSymbols;
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
        let v = (x / scale).round() as i64 as u64 & ((1u64 << total) - 1);
        self.put_slices(slices, v);
    }

    fn unsigned(&mut self, slices: &[(usize, usize)], x: f64, scale: f64) {
        let total: usize = slices.iter().map(|s| s.1).sum();
        let v = (x / scale).round().max(0.0) as u64 & ((1u64 << total) - 1);
        self.put_slices(slices, v);
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

/// The decoded bits of D1 subframe `fra_id` (1–5) starting at BDT `week`, `sow`.
fn d1_fields(e: &Ephemeris, week: i64, sow: i64, fra_id: u32) -> Fields {
    let mut f = Fields([0; 300]);
    f.put(1, 11, PREAMBLE);
    f.put(16, 3, u64::from(fra_id));
    f.put_slices(&[(19, 8), (31, 12)], sow as u64 & 0xf_ffff);
    let sc = BDS_PI;
    let p = |x: i32| 2f64.powi(x);
    match fra_id {
        1 => {
            f.put(43, 1, u64::from(e.health != 0));
            f.put(44, 5, u64::from(e.iodc) & 0x1f);
            f.put(49, 4, crate::gnss::signal::lnav::ura_index(e.ura_m));
            f.put(61, 13, (week as u64) & 0x1fff);
            f.unsigned(&[(74, 9), (91, 8)], e.toc.bdt_week_sow().1, 8.0);
            f.signed(&[(99, 10)], e.tgd_s, 1e-10);
            f.signed(&[(109, 4), (121, 6)], e.tgd2_s, 1e-10);
            // The Klobuchar coefficients of the file's header are GPS's; BDS broadcasts its
            // own, which RINEX files carry apart (BDSA/BDSB). Zero keeps the receiver's
            // model off rather than wrong.
            f.signed(&[(215, 11)], e.af2, p(-66));
            f.signed(&[(226, 7), (241, 17)], e.af0, p(-33));
            f.signed(&[(258, 5), (271, 17)], e.af1, p(-50));
            f.put(288, 5, u64::from(e.iode) & 0x1f);
        }
        2 => {
            f.signed(&[(43, 10), (61, 6)], e.delta_n / sc, p(-43));
            f.signed(&[(67, 16), (91, 2)], e.cuc, p(-31));
            f.signed(&[(93, 20), (121, 12)], e.m0 / sc, p(-31));
            f.unsigned(&[(133, 10), (151, 22)], e.e, p(-33));
            f.signed(&[(181, 18)], e.cus, p(-31));
            f.signed(&[(199, 4), (211, 14)], e.crc, p(-6));
            f.signed(&[(225, 8), (241, 10)], e.crs, p(-6));
            f.unsigned(&[(251, 12), (271, 20)], e.sqrt_a, p(-19));
            let toe = (e.toe_sow_s() / 8.0).round() as u64;
            f.put(291, 2, toe >> 15);
        }
        3 => {
            let toe = (e.toe_sow_s() / 8.0).round() as u64;
            f.put_slices(&[(43, 10), (61, 5)], toe & 0x7fff);
            f.signed(&[(66, 17), (91, 15)], e.i0 / sc, p(-31));
            f.signed(&[(106, 7), (121, 11)], e.cic, p(-31));
            f.signed(&[(132, 11), (151, 13)], e.omega_dot / sc, p(-43));
            f.signed(&[(164, 9), (181, 9)], e.cis, p(-31));
            f.signed(&[(190, 13), (211, 1)], e.idot / sc, p(-43));
            f.signed(&[(212, 21), (241, 11)], e.omega0 / sc, p(-31));
            f.signed(&[(252, 11), (271, 21)], e.omega / sc, p(-31));
        }
        _ => {
            // Page number: pages 1–24 cycle with the frames.
            f.put(44, 7, ((sow / 30).rem_euclid(24) + 1) as u64);
        }
    }
    f
}

/// The 300 transmitted bits of the D1 subframe of `e` that starts at BDT `week`, `sow`.
pub fn d1_subframe(e: &Ephemeris, week: i64, sow: i64, out: &mut [u8; 300]) {
    let fra_id = ((sow / 6).rem_euclid(5) + 1) as u32;
    d1_fields(e, week, sow, fra_id).encode(out);
}

/// A MEO/IGSO satellite's D1 symbols over time (subframes rebuilt every 6 s).
pub struct BdsNavStream {
    nav: Arc<NavData>,
    sat: EmitterId,
    subframe: i64,
    bits: [u8; 300],
}

impl BdsNavStream {
    /// The D1 stream of `sat`; `None` for a GEO satellite (D2 is not generated).
    pub fn new(nav: Arc<NavData>, sat: EmitterId) -> Option<Self> {
        (!sat.is_bds_geo()).then_some(Self {
            nav,
            sat,
            subframe: i64::MIN,
            bits: [0; 300],
        })
    }
}

impl NavSymbols for BdsNavStream {
    fn symbol(&mut self, ms: i64) -> u8 {
        let bdt_ms = ms - BDT_EPOCH_MS;
        let sf = bdt_ms.div_euclid(6000);
        if sf != self.subframe {
            self.subframe = sf;
            let week = (sf * 6000).div_euclid(WEEK_MS);
            let sow = (sf * 6000).rem_euclid(WEEK_MS) / 1000;
            let t = GpsTime::from_ns((sf * 6000 + BDT_EPOCH_MS) * 1_000_000);
            match self.nav.select(self.sat, t) {
                Some(e) => d1_subframe(e, week, sow, &mut self.bits),
                None => self.bits = [0; 300],
            }
        }
        let in_sf = bdt_ms.rem_euclid(6000);
        self.bits[(in_sf / 20) as usize] ^ NH[(in_sf % 20) as usize]
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
        d1_subframe(&e, week, sow, &mut tx);
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
}
