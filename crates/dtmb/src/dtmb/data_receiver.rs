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

// The one kind of unsafe code hybridnav has: an AVX2 build of the LDPC decoder's lane
// loops, called only after run-time CPU detection, with a same-bits test against the
// row-by-row reference decoder.
#![allow(unsafe_code)]

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

/// Lanes per circulant: its 127 rows and one idle lane, so each block is a whole
/// number of SIMD registers.
const LANES: usize = 128;

/// A layered normalised min-sum decoder of one of the three codes.
///
/// The layers are the block rows of the quasi-cyclic parity-check matrix. The 127 rows of
/// a block row share no variable (each circulant is a permutation and no block column
/// occurs twice in a block row), so updating them one after the other, as a row-layered
/// decoder does, equals updating them all at once. The decoder does the latter: for
/// each circulant `(c, sh)` of the layer, row `s` reads variable `127·c + (sh + s) mod
/// 127`, so the layer's messages are two contiguous runs of the posteriors per
/// circulant, processed as 128-lane arrays (one lane per row) that the compiler
/// vectorises. Every row sees the same arithmetic in the same order as in a row-by-row
/// decoder; the tie between two equal minima picks a different edge only when both
/// minima are equal, so the messages are the same bits (a test compares the two).
#[derive(Debug)]
pub struct LdpcDecoder {
    code: &'static LdpcCode,
    /// Each circulant's first variable `127·c` and shift, layer after layer.
    circ: Vec<(u32, u32)>,
    /// Start of each layer in `circ`.
    layer_start: Vec<usize>,
    /// Check-to-variable messages: 128 lanes per circulant.
    c2v: Vec<f32>,
    /// The posteriors.
    post: Vec<f32>,
    /// The current layer's variable-to-check messages, 128 lanes per circulant.
    msg: Vec<f32>,
    /// Maximum iterations.
    pub max_iterations: usize,
}

impl LdpcDecoder {
    /// A decoder of `code` with 50 iterations at most.
    pub fn new(code: &'static LdpcCode) -> Self {
        let mut circ = Vec::new();
        let mut layer_start = vec![0];
        let mut max_degree = 0;
        for row in code.circulants() {
            for &(c, sh) in row.iter() {
                circ.push((u32::from(c) * ldpc::Z as u32, u32::from(sh)));
            }
            max_degree = max_degree.max(row.len());
            layer_start.push(circ.len());
        }
        Self {
            code,
            c2v: vec![0.0; circ.len() * LANES],
            circ,
            layer_start,
            post: vec![0.0; FULL_BITS],
            msg: vec![0.0; max_degree * LANES],
            max_iterations: 50,
        }
    }

    /// Decodes the 7488 transmitted LLRs (positive for 0) into hard bits of the full
    /// 7493-bit word (`out`); returns whether every check is satisfied and the iterations.
    /// Allocates nothing.
    pub fn decode(&mut self, llr: &[f32], out: &mut [u8]) -> (bool, usize) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { self.decode_avx2(llr, out) };
        }
        self.decode_impl(llr, out)
    }

    /// [`LdpcDecoder::decode_impl`] compiled for AVX2: the lane loops run eight floats
    /// at a time. Comparisons, selects, subtractions, additions and the one
    /// multiplication per message round as in the portable build, so the bits are equal.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn decode_avx2(&mut self, llr: &[f32], out: &mut [u8]) -> (bool, usize) {
        self.decode_impl(llr, out)
    }

    #[inline(always)]
    fn decode_impl(&mut self, llr: &[f32], out: &mut [u8]) -> (bool, usize) {
        const Z: usize = ldpc::Z;
        self.post[..DELETED_BITS].fill(0.0);
        self.post[DELETED_BITS..].copy_from_slice(&llr[..CODEWORD_BITS]);
        self.c2v.fill(0.0);
        let layers = self.layer_start.len() - 1;
        for it in 0..=self.max_iterations {
            // Stop as soon as the hard decisions satisfy every check.
            let mut ok = true;
            'layers: for l in 0..layers {
                let mut parity = [0u8; LANES];
                for &(base, sh) in &self.circ[self.layer_start[l]..self.layer_start[l + 1]] {
                    let (base, sh) = (base as usize, sh as usize);
                    let (head, tail) = parity[..Z].split_at_mut(Z - sh);
                    for (p, &x) in head.iter_mut().zip(&self.post[base + sh..base + Z]) {
                        *p ^= u8::from(x < 0.0);
                    }
                    for (p, &x) in tail.iter_mut().zip(&self.post[base..base + sh]) {
                        *p ^= u8::from(x < 0.0);
                    }
                }
                if parity.iter().any(|&p| p != 0) {
                    ok = false;
                    break 'layers;
                }
            }
            if ok || it == self.max_iterations {
                for (o, &p) in out.iter_mut().zip(&self.post) {
                    *o = u8::from(p < 0.0);
                }
                return (ok, it);
            }
            for l in 0..layers {
                let (e0, e1) = (self.layer_start[l], self.layer_start[l + 1]);
                let circ = &self.circ[e0..e1];
                let c2v = &mut self.c2v[e0 * LANES..e1 * LANES];
                let msg = &mut self.msg[..(e1 - e0) * LANES];
                // Variable-to-check messages m = posterior − old check message, and per
                // row the sign product and the two smallest magnitudes.
                let mut sign = [0u32; LANES];
                let mut min1 = [f32::INFINITY; LANES];
                let mut min2 = [f32::INFINITY; LANES];
                let mut arg = [0u32; LANES];
                for (e, ((&(base, sh), m), c)) in circ
                    .iter()
                    .zip(msg.chunks_exact_mut(LANES))
                    .zip(c2v.chunks_exact(LANES))
                    .enumerate()
                {
                    let (base, sh) = (base as usize, sh as usize);
                    let (head, tail) = m[..Z].split_at_mut(Z - sh);
                    let (c_head, c_tail) = c[..Z].split_at(Z - sh);
                    for ((d, &p), &cv) in head
                        .iter_mut()
                        .zip(&self.post[base + sh..base + Z])
                        .zip(c_head)
                    {
                        *d = p - cv;
                    }
                    for ((d, &p), &cv) in
                        tail.iter_mut().zip(&self.post[base..base + sh]).zip(c_tail)
                    {
                        *d = p - cv;
                    }
                    m[Z] = 1.0;
                    let e = e as u32;
                    for s in 0..LANES {
                        let x = m[s];
                        sign[s] ^= u32::from(x < 0.0);
                        let a = x.abs();
                        let lt1 = a < min1[s];
                        let lt2 = a < min2[s];
                        min2[s] = if lt1 {
                            min1[s]
                        } else if lt2 {
                            a
                        } else {
                            min2[s]
                        };
                        min1[s] = if lt1 { a } else { min1[s] };
                        arg[s] = if lt1 { e } else { arg[s] };
                    }
                }
                // New check messages α·Π sign·min and posteriors m + c, written back.
                for (e, ((&(base, sh), m), c)) in circ
                    .iter()
                    .zip(msg.chunks_exact_mut(LANES))
                    .zip(c2v.chunks_exact_mut(LANES))
                    .enumerate()
                {
                    let e = e as u32;
                    for s in 0..LANES {
                        let x = m[s];
                        let mag = ALPHA * if arg[s] == e { min2[s] } else { min1[s] };
                        let neg = (sign[s] ^ u32::from(x < 0.0)) != 0;
                        let cv = if neg { -mag } else { mag };
                        c[s] = cv;
                        m[s] = x + cv;
                    }
                    let (base, sh) = (base as usize, sh as usize);
                    self.post[base + sh..base + Z].copy_from_slice(&m[..Z - sh]);
                    self.post[base..base + sh].copy_from_slice(&m[Z - sh..Z]);
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
    /// Per-symbol weights `1/σ_k²` of [`DataReceiver::push_frame_weighted`]: the frame's
    /// data symbols' and their de-interleaver (built on the first weighted frame).
    weights: Vec<f32>,
    weight_deinterleaver: Option<TimeInterleaver<f32>>,
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
            weights: Vec::new(),
            weight_deinterleaver: None,
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

    /// [`DataReceiver::push_frame`] with a noise variance per symbol: `inv_var[l]` is
    /// `1/σ_l²` of logical symbol `l` (3780), e.g. `|Ĥ_k|²/σ²` for a symbol equalised by
    /// a one-tap equaliser on a carrier of response `Ĥ_k`. The weights go through a
    /// de-interleaver of their own alongside the symbols, so each symbol is demapped with
    /// its own variance. A receiver is fed either by this or by `push_frame`, not both
    /// (the weights' de-interleaver starts with the first weighted frame). Allocates only
    /// on the first call.
    pub fn push_frame_weighted(
        &mut self,
        logical: &[Complex32],
        inv_var: &[f32],
        out: &mut Vec<u8>,
    ) {
        debug_assert_eq!(logical.len(), BODY_LEN);
        debug_assert_eq!(inv_var.len(), BODY_LEN);
        if self.weights.len() != DATA_SYMBOLS {
            self.weights = vec![0.0; DATA_SYMBOLS];
        }
        match self.profile.carrier {
            CarrierMode::Multi3780 => {
                let mut d = 0;
                let mut next_si = 0;
                for (l, (&x, &w)) in logical.iter().zip(inv_var).enumerate() {
                    if next_si < SI_LEN && system_info::C3780_POSITIONS[next_si] == l {
                        next_si += 1;
                    } else {
                        self.data[d] = x;
                        self.weights[d] = w;
                        d += 1;
                    }
                }
            }
            CarrierMode::Single => {
                self.data.copy_from_slice(&logical[SI_LEN..]);
                self.weights.copy_from_slice(&inv_var[SI_LEN..]);
            }
        }
        let n = if self.bit_deinterleaver.is_some() {
            // 4QAM-NR: demapped (with each symbol's own weight) before the bit
            // de-interleaver, as in `push_frame`.
            let mut code_llr = [0f32; 16];
            for ((syms, ws), info) in self
                .data
                .chunks_exact(8)
                .zip(self.weights.chunks_exact(8))
                .zip(self.frame_llr.chunks_exact_mut(8))
            {
                for (t, (&y, &w)) in syms.iter().zip(ws).enumerate() {
                    let mut l = [0f32; 2];
                    Self::demap(&self.points, 2, y, w, &mut l);
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
            let m = self.profile.interleaver_m;
            self.weight_deinterleaver
                .get_or_insert_with(|| TimeInterleaver::new(m, true, |_| 0.0f32))
                .process(&mut self.weights);
            let skip = self.to_skip.min(DATA_SYMBOLS);
            self.to_skip -= skip;
            let bps = self.profile.constellation.bits_per_symbol();
            for (k, (&y, &w)) in self.data[skip..]
                .iter()
                .zip(&self.weights[skip..])
                .enumerate()
            {
                Self::demap(
                    &self.points,
                    bps,
                    y,
                    w,
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
    use rand::Rng;
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

    /// With every weight `1/σ²`, the per-symbol path is the uniform one: the same bytes
    /// and counts, for a square QAM (weights through their own de-interleaver) and for
    /// 4QAM-NR (demapped before the bit de-interleaver), near the threshold where the
    /// LLRs' exact values decide the decoding.
    #[test]
    fn uniform_weights_equal_the_uniform_variance() {
        for (c, rate, var) in [
            (Constellation::Qam64, CodeRate::R06, 0.045f32),
            (Constellation::Qam4Nr, CodeRate::R08, 0.6),
        ] {
            let p = Profile::new(c, rate, 240, CarrierMode::Multi3780).unwrap();
            let mut tx = DataLayer::new(p, PacketSource::pseudo_random(3));
            let mut a = DataReceiver::new(p);
            let mut b = DataReceiver::new(p);
            let mut rng = TrialRng::new(8, 0).stream("dtmb/test");
            let s = (var / 2.0).sqrt();
            let w = vec![1.0 / var; BODY_LEN];
            let mut body = vec![Complex32::default(); BODY_LEN];
            let (mut out_a, mut out_b) = (Vec::new(), Vec::new());
            for _ in 0..p.interleaver_delay_frames() + 4 {
                tx.next_frame(p.si_index(), &mut body).unwrap();
                for x in body.iter_mut() {
                    let n: f32 = StandardNormal.sample(&mut rng);
                    let m: f32 = StandardNormal.sample(&mut rng);
                    *x += Complex32::new(n * s, m * s);
                }
                a.push_frame(&body, var, &mut out_a);
                b.push_frame_weighted(&body, &w, &mut out_b);
            }
            assert!(!out_a.is_empty(), "{}", p.name());
            assert_eq!(out_a, out_b, "{}", p.name());
            assert_eq!(a.stats(), b.stats(), "{}", p.name());
        }
    }

    /// The straightforward row-by-row layered min-sum decoder (the previous
    /// implementation), the reference of the block-row decoder.
    fn decode_row_by_row(
        code: &LdpcCode,
        max_it: usize,
        llr: &[f32],
        out: &mut [u8],
    ) -> (bool, usize) {
        let rows = code.checks();
        let mut post = vec![0f32; FULL_BITS];
        post[DELETED_BITS..].copy_from_slice(llr);
        let mut c2v: Vec<Vec<f32>> = rows.iter().map(|r| vec![0.0; r.len()]).collect();
        for it in 0..=max_it {
            let ok = rows
                .iter()
                .all(|row| !row.iter().fold(false, |p, &v| p ^ (post[v as usize] < 0.0)));
            if ok || it == max_it {
                for (o, &p) in out.iter_mut().zip(&post) {
                    *o = u8::from(p < 0.0);
                }
                return (ok, it);
            }
            for (row, c) in rows.iter().zip(c2v.iter_mut()) {
                let mut sign = false;
                let (mut min1, mut min2, mut arg) = (f32::INFINITY, f32::INFINITY, 0);
                for (e, &v) in row.iter().enumerate() {
                    let m = post[v as usize] - c[e];
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
                for (e, &v) in row.iter().enumerate() {
                    let m = post[v as usize] - c[e];
                    let mag = ALPHA * if e == arg { min2 } else { min1 };
                    let cv = if sign ^ (m < 0.0) { -mag } else { mag };
                    c[e] = cv;
                    post[v as usize] = m + cv;
                }
            }
        }
        (false, max_it)
    }

    /// Noisy codewords of all three rates (BPSK in AWGN at Eb/N0 from hopeless to easy,
    /// LLR = 2y/σ²): the block-row decoder (AVX2 where the CPU has it, and the portable
    /// build) returns the row-by-row reference's bits, success and iteration count. And
    /// at Eb/N0 = 3 dB, 2.3 dB above the binary-input AWGN capacity limit of rate
    /// 4572/7488 (0.74 dB, computed numerically from the capacity integral), where the
    /// hard decisions are wrong at a rate of Q(√(2·R·Eb/N0)) ≈ 6 % (~440 bits a codeword),
    /// rate-0.6 codewords are corrected back to the ones sent.
    #[test]
    fn block_row_decoder_equals_row_by_row_and_corrects_noise() {
        let mut rng = TrialRng::new(9, 0).stream("dtmb/ldpc-test");
        for rate in CodeRate::ALL {
            let code = ldpc::code(rate);
            let mut dec = LdpcDecoder::new(code);
            for (k, ebn0_db) in [0.0f32, 1.5, 2.0, 3.0, 3.0, 3.0, 3.0, 4.0, 6.0]
                .into_iter()
                .enumerate()
            {
                let msg: Vec<u8> = (0..rate.message_bits())
                    .map(|_| u8::from(rng.random::<bool>()))
                    .collect();
                let mut tx = vec![0u8; CODEWORD_BITS];
                code.encode(&msg, &mut tx);
                let r = rate.message_bits() as f32 / CODEWORD_BITS as f32;
                let sigma2 = 1.0 / (2.0 * r * 10f32.powf(ebn0_db / 10.0));
                let sigma = sigma2.sqrt();
                let llr: Vec<f32> = tx
                    .iter()
                    .map(|&b| {
                        let n: f32 = StandardNormal.sample(&mut rng);
                        let y = if b == 0 { 1.0 } else { -1.0 } + sigma * n;
                        2.0 * y / sigma2
                    })
                    .collect();
                let mut want = vec![0u8; FULL_BITS];
                let mut got = vec![0u8; FULL_BITS];
                let mut portable = vec![0u8; FULL_BITS];
                let r_ref = decode_row_by_row(code, 50, &llr, &mut want);
                let r_fast = dec.decode(&llr, &mut got);
                let r_port = dec.decode_impl(&llr, &mut portable);
                assert_eq!(r_fast, r_ref, "rate {} case {k}", rate.name());
                assert_eq!(r_port, r_ref, "rate {} case {k}", rate.name());
                assert!(
                    got == want && portable == want,
                    "rate {} case {k}",
                    rate.name()
                );
                if rate == CodeRate::R06 && ebn0_db == 3.0 {
                    let hard_errors = llr
                        .iter()
                        .zip(&tx)
                        .filter(|(&l, &b)| u8::from(l < 0.0) != b)
                        .count();
                    assert!(hard_errors > 100, "{hard_errors}");
                    assert!(r_fast.0, "not corrected at 3 dB");
                    assert_eq!(&got[DELETED_BITS..], &tx[..], "wrong codeword at 3 dB");
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
