//! hybridnav's own receiver for the GB 20600 data layer, the inverse of
//! [`super::data_layer::DataLayer`] on the logical symbols of each frame body: max-log
//! soft demapping, time de-interleaving, a layered normalised min-sum LDPC decoder, BCH
//! single-error correction and descrambling back to transport-stream packets.
//!
//! Soft demapping (max-log, for a symbol `y` in noise of variance `σ²` per complex
//! sample): `LLR(b) = (min_{x: b=1} |y − x|² − min_{x: b=0} |y − x|²)/σ²`, positive for 0.
//! 4QAM-NR bits are the max-log decisions over the 256 Nordstrom–Robinson codewords of
//! each 16 code-bit LLRs. The layered min-sum decoder updates each check row in turn
//! with messages `α · Π sign · min |·|` (α = 0.75; Chen & Fossorier, *Near optimum
//! universal belief propagation based decoding of LDPC codes*, IEEE Trans. Commun. 50(3),
//! 2002, normalised min-sum), and stops when every check is satisfied.

use super::bch::{self, BCH_K, BCH_N};
use super::data_layer::{Profile, DATA_SYMBOLS};
use super::frame::{CarrierMode, SI_LEN};
use super::interleaver::TimeInterleaver;
use super::ldpc::{self, LdpcCode, CODEWORD_BITS, DELETED_BITS, FULL_BITS};
use super::mapping::{nr_encode, Constellation};
use super::pn::BODY_LEN;
use super::scrambler::Scrambler;
use super::system_info;
use num_complex::Complex32;

/// The normalisation of the min-sum check messages.
const ALPHA: f32 = 0.75;

/// Decoding counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// LDPC codewords decoded.
    pub codewords: u64,
    /// Codewords whose LDPC decoder did not satisfy every check.
    pub ldpc_failures: u64,
    /// BCH blocks left with errors it could not correct.
    pub bch_failures: u64,
    /// Bit errors the BCH decoder corrected.
    pub bch_corrected: u64,
}

/// A layered normalised min-sum decoder of one of the three codes.
#[derive(Debug)]
pub struct LdpcDecoder {
    code: &'static LdpcCode,
    /// Check rows as variable indices, flattened, with their offsets.
    vars: Vec<u16>,
    offsets: Vec<u32>,
    /// Check-to-variable messages per edge, and the posteriors.
    c2v: Vec<f32>,
    post: Vec<f32>,
    /// Maximum iterations.
    pub max_iterations: usize,
}

impl LdpcDecoder {
    /// A decoder of `code` with 50 iterations at most.
    pub fn new(code: &'static LdpcCode) -> Self {
        let mut vars = Vec::new();
        let mut offsets = vec![0u32];
        for row in code.checks() {
            vars.extend_from_slice(row);
            offsets.push(vars.len() as u32);
        }
        Self {
            code,
            c2v: vec![0.0; vars.len()],
            vars,
            offsets,
            post: vec![0.0; FULL_BITS],
            max_iterations: 50,
        }
    }

    /// Decodes the 7488 transmitted LLRs (positive for 0) into hard bits of the full
    /// 7493-bit word (`out`); returns whether every check is satisfied and the iterations.
    pub fn decode(&mut self, llr: &[f32], out: &mut [u8]) -> (bool, usize) {
        self.post[..DELETED_BITS].fill(0.0);
        self.post[DELETED_BITS..].copy_from_slice(&llr[..CODEWORD_BITS]);
        self.c2v.fill(0.0);
        let rows = self.offsets.len() - 1;
        for it in 0..=self.max_iterations {
            // Stop as soon as the hard decisions satisfy every check.
            let mut ok = true;
            for r in 0..rows {
                let (a, b) = (self.offsets[r] as usize, self.offsets[r + 1] as usize);
                let parity = self.vars[a..b]
                    .iter()
                    .fold(false, |p, &v| p ^ (self.post[v as usize] < 0.0));
                if parity {
                    ok = false;
                    break;
                }
            }
            if ok || it == self.max_iterations {
                for (o, &p) in out.iter_mut().zip(&self.post) {
                    *o = u8::from(p < 0.0);
                }
                return (ok, it);
            }
            for r in 0..rows {
                let (a, b) = (self.offsets[r] as usize, self.offsets[r + 1] as usize);
                let mut sign = false;
                let (mut min1, mut min2, mut arg) = (f32::INFINITY, f32::INFINITY, a);
                for e in a..b {
                    let m = self.post[self.vars[e] as usize] - self.c2v[e];
                    sign ^= m < 0.0;
                    let x = m.abs();
                    if x < min1 {
                        min2 = min1;
                        min1 = x;
                        arg = e;
                    } else if x < min2 {
                        min2 = x;
                    }
                }
                for e in a..b {
                    let v = self.vars[e] as usize;
                    let m = self.post[v] - self.c2v[e];
                    let mag = ALPHA * if e == arg { min2 } else { min1 };
                    let s = sign ^ (m < 0.0);
                    let c = if s { -mag } else { mag };
                    self.c2v[e] = c;
                    self.post[v] = m + c;
                }
            }
        }
        (false, self.max_iterations)
    }

    /// The code.
    pub fn code(&self) -> &'static LdpcCode {
        self.code
    }
}

/// The receiver of the data layer: frame bodies' logical symbols in, TS bytes out.
#[derive(Debug)]
pub struct DataReceiver {
    profile: Profile,
    points: Vec<Complex32>,
    decoder: LdpcDecoder,
    deinterleaver: Option<TimeInterleaver>,
    bit_deinterleaver: Option<TimeInterleaver<f32>>,
    /// Symbols (or, for 4QAM-NR, bit LLRs) still to drop: the de-interleaver's latency.
    to_skip: usize,
    /// The current group's LLRs and how many are filled.
    llr: Vec<f32>,
    filled: usize,
    data: Vec<Complex32>,
    frame_llr: Vec<f32>,
    full: Vec<u8>,
    stats: DecodeStats,
}

impl DataReceiver {
    /// A receiver of `profile`.
    pub fn new(profile: Profile) -> Self {
        let nr = profile.constellation == Constellation::Qam4Nr;
        let m = profile.interleaver_m;
        Self {
            profile,
            points: profile.constellation.points(),
            decoder: LdpcDecoder::new(ldpc::code(profile.rate)),
            deinterleaver: (!nr).then(|| TimeInterleaver::new(m, true, |_| Complex32::default())),
            bit_deinterleaver: nr.then(|| TimeInterleaver::new(m, true, |_| 0.0f32)),
            to_skip: TimeInterleaver::latency_symbols(m),
            llr: vec![0.0; profile.codewords_per_group() * CODEWORD_BITS],
            filled: 0,
            data: vec![Complex32::default(); DATA_SYMBOLS],
            frame_llr: vec![0.0; DATA_SYMBOLS * 6],
            full: vec![0; FULL_BITS],
            stats: DecodeStats::default(),
        }
    }

    /// The counts so far.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Max-log LLRs of one symbol's bits against the constellation.
    fn demap(points: &[Complex32], bps: usize, y: Complex32, inv_var: f32, out: &mut [f32]) {
        let mut d0 = [f32::INFINITY; 6];
        let mut d1 = [f32::INFINITY; 6];
        for (label, p) in points.iter().enumerate() {
            let d = (y - p).norm_sqr();
            for t in 0..bps {
                if label >> t & 1 == 0 {
                    d0[t] = d0[t].min(d);
                } else {
                    d1[t] = d1[t].min(d);
                }
            }
        }
        for t in 0..bps {
            out[t] = (d1[t] - d0[t]) * inv_var;
        }
    }

    /// Takes one frame body's 3780 logical symbols (after equalisation, at the
    /// transmitter's unit-power scale) in noise of variance `noise_var` per symbol, and
    /// appends the TS bytes of every FEC group it completes to `out`.
    pub fn push_frame(&mut self, logical: &[Complex32], noise_var: f32, out: &mut Vec<u8>) {
        debug_assert_eq!(logical.len(), BODY_LEN);
        match self.profile.carrier {
            CarrierMode::Multi3780 => {
                let mut d = 0;
                let mut next_si = 0;
                for (l, &x) in logical.iter().enumerate() {
                    if next_si < SI_LEN && system_info::C3780_POSITIONS[next_si] == l {
                        next_si += 1;
                    } else {
                        self.data[d] = x;
                        d += 1;
                    }
                }
            }
            CarrierMode::Single => self.data.copy_from_slice(&logical[SI_LEN..]),
        }
        let inv_var = 1.0 / noise_var.max(1e-12);
        let n = if self.bit_deinterleaver.is_some() {
            // 4QAM LLRs, then the NR code's 8 information-bit LLRs of every 16, through
            // the bit de-interleaver.
            let mut code_llr = [0f32; 16];
            for (syms, info) in self
                .data
                .chunks_exact(8)
                .zip(self.frame_llr.chunks_exact_mut(8))
            {
                for (t, &y) in syms.iter().enumerate() {
                    let mut l = [0f32; 2];
                    Self::demap(&self.points, 2, y, inv_var, &mut l);
                    code_llr[2 * t] = l[0];
                    code_llr[2 * t + 1] = l[1];
                }
                nr_soft_decode(&code_llr, info);
            }
            if let Some(d) = &mut self.bit_deinterleaver {
                d.process(&mut self.frame_llr[..DATA_SYMBOLS]);
            }
            let skip = self.to_skip.min(DATA_SYMBOLS);
            self.to_skip -= skip;
            self.frame_llr.copy_within(skip..DATA_SYMBOLS, 0);
            DATA_SYMBOLS - skip
        } else {
            if let Some(d) = &mut self.deinterleaver {
                d.process(&mut self.data);
            }
            let skip = self.to_skip.min(DATA_SYMBOLS);
            self.to_skip -= skip;
            let bps = self.profile.constellation.bits_per_symbol();
            for (k, &y) in self.data[skip..].iter().enumerate() {
                Self::demap(
                    &self.points,
                    bps,
                    y,
                    inv_var,
                    &mut self.frame_llr[k * bps..(k + 1) * bps],
                );
            }
            (DATA_SYMBOLS - skip) * bps
        };
        self.feed(n, out);
    }

    /// Moves the first `n` LLRs of `frame_llr` into the group, decoding full groups.
    fn feed(&mut self, n: usize, out: &mut Vec<u8>) {
        let mut pos = 0;
        while pos < n {
            let take = (n - pos).min(self.llr.len() - self.filled);
            self.llr[self.filled..self.filled + take]
                .copy_from_slice(&self.frame_llr[pos..pos + take]);
            self.filled += take;
            pos += take;
            if self.filled == self.llr.len() {
                self.decode_group(out);
                self.filled = 0;
            }
        }
    }

    fn decode_group(&mut self, out: &mut Vec<u8>) {
        let rate = self.profile.rate;
        let per_cw = rate.ts_bytes_per_codeword();
        let per_frame =
            self.profile.codewords_per_group() * per_cw / self.profile.frames_per_group();
        let parity = rate.parity_blocks() * ldpc::Z;
        let mut scrambler = Scrambler::new();
        let mut word = [0u8; BCH_N];
        for cw in 0..self.profile.codewords_per_group() {
            let (ok, _) = self.decoder.decode(
                &self.llr[cw * CODEWORD_BITS..(cw + 1) * CODEWORD_BITS],
                &mut self.full,
            );
            self.stats.codewords += 1;
            self.stats.ldpc_failures += u64::from(!ok);
            let start = out.len();
            for blk in 0..rate.bch_per_codeword() {
                let a = parity + blk * BCH_N;
                word.copy_from_slice(&self.full[a..a + BCH_N]);
                match bch::decode(&mut word) {
                    Some(c) => self.stats.bch_corrected += c as u64,
                    None => self.stats.bch_failures += 1,
                }
                for byte in word[..BCH_K].chunks_exact(8) {
                    out.push(byte.iter().fold(0u8, |v, &b| (v << 1) | b));
                }
            }
            for (i, b) in out[start..].iter_mut().enumerate() {
                if (cw * per_cw + i) % per_frame == 0 {
                    scrambler.reset();
                }
                *b ^= scrambler.next_byte();
            }
        }
    }
}

/// Max-log decoding of the Nordstrom–Robinson (16, 8) code: the LLRs of the 8
/// information bits from those of the 16 code bits (first bit first; positive for 0).
pub fn nr_soft_decode(code_llr: &[f32; 16], info: &mut [f32]) {
    static WORDS: std::sync::OnceLock<[u16; 256]> = std::sync::OnceLock::new();
    let words = WORDS.get_or_init(|| std::array::from_fn(|b| nr_encode(b as u8)));
    // Cost of a codeword: the sum of the LLRs of its one bits (its negative log
    // likelihood up to a constant).
    let mut best = [[f32::INFINITY; 2]; 8];
    for (b, &w) in words.iter().enumerate() {
        let mut cost = 0.0;
        for (t, &l) in code_llr.iter().enumerate() {
            if w >> (15 - t) & 1 != 0 {
                cost += l;
            }
        }
        for (t, slot) in best.iter_mut().enumerate() {
            let bit = (b >> (7 - t)) & 1;
            slot[bit] = slot[bit].min(cost);
        }
    }
    for (o, b) in info.iter_mut().zip(&best) {
        *o = b[1] - b[0];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use crate::dtmb::data_layer::DataLayer;
    use crate::dtmb::ldpc::CodeRate;
    use crate::dtmb::ts::PacketSource;
    use rand_distr::{Distribution, StandardNormal};

    /// Every profile round-trips through transmitter and receiver at 30 dB SNR: the TS
    /// packets that leave the de-interleaver are the null packets sent, none wrong.
    #[test]
    fn every_profile_round_trips_at_high_snr() {
        let mut rng = TrialRng::new(5, 0).stream("dtmb/test");
        for c in Constellation::ALL {
            for rate in CodeRate::ALL {
                for carrier in [CarrierMode::Multi3780, CarrierMode::Single] {
                    let Ok(p) = Profile::new(c, rate, 240, carrier) else {
                        continue;
                    };
                    let mut tx = DataLayer::new(p, PacketSource::null());
                    let mut rx = DataReceiver::new(p);
                    let var = 1e-3f32;
                    let s = (var / 2.0).sqrt();
                    let mut body = vec![Complex32::default(); BODY_LEN];
                    let mut out = Vec::new();
                    let frames = p.interleaver_delay_frames() + 4;
                    for _ in 0..frames {
                        tx.next_frame(p.si_index(), &mut body).unwrap();
                        for x in body.iter_mut() {
                            let n: f32 = StandardNormal.sample(&mut rng);
                            let m: f32 = StandardNormal.sample(&mut rng);
                            *x += Complex32::new(n * s, m * s);
                        }
                        rx.push_frame(&body, var, &mut out);
                    }
                    let st = rx.stats();
                    assert!(st.codewords > 0, "{}", p.name());
                    assert_eq!(
                        st.ldpc_failures + st.bch_failures,
                        0,
                        "{}: {st:?}",
                        p.name()
                    );
                    assert_eq!(out.len() % 188, 0);
                    assert!(!out.is_empty());
                    let null = crate::dtmb::ts::null_packet();
                    assert!(out.chunks(188).all(|k| k == null), "{}", p.name());
                }
            }
        }
    }

    #[test]
    fn nr_soft_decoding_inverts_the_code() {
        for b in [0u8, 1, 0x5a, 0xff, 0x80] {
            let w = nr_encode(b);
            let llr: [f32; 16] =
                std::array::from_fn(|t| if w >> (15 - t) & 1 == 0 { 4.0 } else { -4.0 });
            let mut info = [0f32; 8];
            nr_soft_decode(&llr, &mut info);
            let got = info.iter().fold(0u8, |a, &l| (a << 1) | u8::from(l < 0.0));
            assert_eq!(got, b);
        }
    }
}
