//! The inner code of GB 20600-2006 §4.3: the three quasi-cyclic LDPC codes of 7493 bits
//! (59 blocks of 127) with 24, 36 or 48 message blocks (rates 0.4, 0.6, 0.8), of which the
//! first five parity bits are deleted, leaving 7488 transmitted bits.
//!
//! The parity-check matrix `H = [H_p | H_m]` (`ldpc_tables`) is made of 127 × 127
//! circulant permutations. Because the code is quasi-cyclic, rotating every block of a
//! codeword by the same amount gives a codeword, so the systematic generator is fixed by
//! the parity of one message bit per block: `g_b = H_p⁻¹ H_m e_{127·b}` (C blocks of 127
//! bits each). This module derives those `K × C` circulant first rows once per code (a
//! Gauss–Jordan solve of `H_p`, which is invertible for all three codes) and encodes by
//! rotation,
//!
//! ```text
//! p_j = Σ_b Σ_{s ∈ u_b} rot(g_{b,j}, s) = Σ_s rot(Σ_{b: s ∈ u_b} g_{b,j}, s),
//! ```
//!
//! (`u_b` message block b; the second form, one rotation per shift and parity block, is
//! the one computed)
//!
//! which is the standard's own quasi-cyclic generator form (`G_qc`, §4.3.2) — no dense
//! generator matrix is built. The transmitted order is the one the receiver dtmb-sdr
//! reads (and decodes broadcast signals with): parity bits 5 … 127·C − 1, then the message.
//!
//! The fast encoder ([`LdpcCode::encode_blocks`]) works on packed 127-bit blocks. A
//! circulant whose first row is `g` maps a block `u` to the cyclic convolution of the two,
//! the polynomial product `u(z)·g(z) mod (z¹²⁷ − 1)` over GF(2) with bit `t` the
//! coefficient of `zᵗ` (`rot(g, s)` is `zˢ·g(z)`). So
//!
//! ```text
//! p_j(z) = Σ_b u_b(z)·g_{b,j}(z) mod (z¹²⁷ − 1),
//! ```
//!
//! K·C carry-less 128 × 128-bit products (three 64 × 64-bit ones each, Karatsuba),
//! summed unreduced for each parity block and folded once (`z¹²⁷ = 1`: bits 127 … 252
//! are added to bits 0 … 125). With the CPU's carry-less multiply (x86-64 PCLMULQDQ) a
//! rate-0.6 codeword costs about 2 500 multiplies; without it, the rotation form above
//! runs on the packed blocks. Both give the bits of the bit-per-byte [`LdpcCode::encode`],
//! which is kept as the straightforward reference they are tested against.

// The one kind of unsafe code hybridnav has: SIMD intrinsics in `#[target_feature]`
// functions called only after run-time CPU detection, with a same-bits test against the
// portable code.
#![allow(unsafe_code)]

use super::ldpc_tables;
use std::sync::OnceLock;

/// Circulant size.
pub const Z: usize = 127;
/// Bits of the full (mother) codeword.
pub const FULL_BITS: usize = 59 * Z;
/// Transmitted bits of a codeword.
pub const CODEWORD_BITS: usize = 7488;
/// Parity bits deleted before transmission (the first five).
pub const DELETED_BITS: usize = FULL_BITS - CODEWORD_BITS;

/// The 127 low bits.
const MASK: u128 = (1u128 << 127) - 1;

/// Rotates a 127-bit block: bit `t` moves to `(t + s) mod 127`.
#[inline(always)]
fn rot(x: u128, s: u32) -> u128 {
    if s == 0 {
        x
    } else {
        ((x << s) | (x >> (127 - s))) & MASK
    }
}

/// The LDPC code rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CodeRate {
    /// Rate 0.4: 24 message blocks, 3048 message bits (4 BCH codewords).
    R04,
    /// Rate 0.6: 36 message blocks, 4572 message bits (6 BCH codewords).
    R06,
    /// Rate 0.8: 48 message blocks, 6096 message bits (8 BCH codewords).
    R08,
}

impl CodeRate {
    /// All three.
    pub const ALL: [CodeRate; 3] = [CodeRate::R04, CodeRate::R06, CodeRate::R08];

    /// Message blocks `K`.
    pub fn message_blocks(self) -> usize {
        match self {
            CodeRate::R04 => 24,
            CodeRate::R06 => 36,
            CodeRate::R08 => 48,
        }
    }

    /// Parity blocks `C = 59 − K`.
    pub fn parity_blocks(self) -> usize {
        59 - self.message_blocks()
    }

    /// Message bits `127·K` (whole BCH codewords of 762 bits).
    pub fn message_bits(self) -> usize {
        self.message_blocks() * Z
    }

    /// BCH codewords per LDPC codeword.
    pub fn bch_per_codeword(self) -> usize {
        self.message_bits() / super::bch::BCH_N
    }

    /// Transport-stream bytes per LDPC codeword (`752/8` per BCH codeword).
    pub fn ts_bytes_per_codeword(self) -> usize {
        self.bch_per_codeword() * super::bch::BCH_K / 8
    }

    /// The name in the standard: "0.4", "0.6" or "0.8".
    pub fn name(self) -> &'static str {
        match self {
            CodeRate::R04 => "0.4",
            CodeRate::R06 => "0.6",
            CodeRate::R08 => "0.8",
        }
    }

    fn table(self) -> &'static [&'static [(u8, u8)]] {
        match self {
            CodeRate::R04 => &ldpc_tables::RATE_04,
            CodeRate::R06 => &ldpc_tables::RATE_06,
            CodeRate::R08 => &ldpc_tables::RATE_08,
        }
    }
}

impl std::str::FromStr for CodeRate {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "0.4" => Ok(CodeRate::R04),
            "0.6" => Ok(CodeRate::R06),
            "0.8" => Ok(CodeRate::R08),
            other => Err(format!(
                "unknown LDPC code rate {other:?}: valid rates are 0.4, 0.6, 0.8"
            )),
        }
    }
}

/// One of the three codes with its derived quasi-cyclic generator.
#[derive(Debug)]
pub struct LdpcCode {
    rate: CodeRate,
    /// `g[b·C + j]`: first row of the generator's circulant (message block b, parity
    /// block j), bit t at position t.
    g: Vec<u128>,
    /// Check rows as lists of full-codeword columns (for checks and the decoder).
    checks: Vec<Vec<u16>>,
    /// The same first rows parity-block major (`gt[j·K + b]`) as 64-bit halves and their
    /// XOR, the operands of the carry-less products.
    gt: Vec<[u64; 3]>,
    /// Whether the CPU multiplies carry-less (checked once, when the code is derived).
    clmul: bool,
}

/// The code of `rate`, derived on first use.
pub fn code(rate: CodeRate) -> &'static LdpcCode {
    static CODES: [OnceLock<LdpcCode>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let i = match rate {
        CodeRate::R04 => 0,
        CodeRate::R06 => 1,
        CodeRate::R08 => 2,
    };
    CODES[i].get_or_init(|| LdpcCode::derive(rate))
}

impl LdpcCode {
    fn derive(rate: CodeRate) -> Self {
        let kb = rate.message_blocks();
        let cb = rate.parity_blocks();
        let table = rate.table();
        let m = cb * Z;
        let checks: Vec<Vec<u16>> = (0..m)
            .map(|row| {
                let (r, s) = (row / Z, row % Z);
                let mut v: Vec<u16> = table[r]
                    .iter()
                    .map(|&(c, sh)| (c as usize * Z + (sh as usize + s) % Z) as u16)
                    .collect();
                v.sort_unstable();
                v
            })
            .collect();
        // [H_p | H_m e_{127 b} for every b], bit-packed, solved by Gauss–Jordan.
        let cols = m + kb;
        let words = cols.div_ceil(64);
        let mut a = vec![0u64; m * words];
        for (row, vars) in checks.iter().enumerate() {
            for &v in vars {
                let v = v as usize;
                let col = if v < m {
                    v
                } else if (v - m) % Z == 0 {
                    m + (v - m) / Z
                } else {
                    continue;
                };
                a[row * words + col / 64] ^= 1u64 << (col % 64);
            }
        }
        for col in 0..m {
            let bit = 1u64 << (col % 64);
            let w0 = col / 64;
            let pivot = (col..m)
                .find(|&r| a[r * words + w0] & bit != 0)
                .expect("the parity part of every GB 20600 LDPC code is invertible");
            if pivot != col {
                for w in 0..words {
                    a.swap(pivot * words + w, col * words + w);
                }
            }
            let (before, rest) = a.split_at_mut(col * words);
            let (prow, after) = rest.split_at_mut(words);
            for r in before
                .chunks_exact_mut(words)
                .chain(after.chunks_exact_mut(words))
            {
                if r[w0] & bit != 0 {
                    for w in w0..words {
                        r[w] ^= prow[w];
                    }
                }
            }
        }
        let mut g = vec![0u128; kb * cb];
        for b in 0..kb {
            let col = m + b;
            for i in 0..m {
                if a[i * words + col / 64] >> (col % 64) & 1 != 0 {
                    g[b * cb + i / Z] |= 1u128 << (i % Z);
                }
            }
        }
        let mut gt = vec![[0u64; 3]; kb * cb];
        for j in 0..cb {
            for b in 0..kb {
                let v = g[b * cb + j];
                let (lo, hi) = (v as u64, (v >> 64) as u64);
                gt[j * kb + b] = [lo, hi, lo ^ hi];
            }
        }
        Self {
            rate,
            g,
            checks,
            gt,
            clmul: clmul_available(),
        }
    }

    /// The code rate.
    pub fn rate(&self) -> CodeRate {
        self.rate
    }

    /// The parity-check matrix by block rows: each block row's circulants as
    /// `(block column, shift)`, check row `127·r + s` having a one in column
    /// `127·c + (shift + s) mod 127`. No block column occurs twice in a block row, so the
    /// 127 rows of a block row share no variable.
    pub fn circulants(&self) -> &'static [&'static [(u8, u8)]] {
        self.rate.table()
    }

    /// The check rows (full-codeword column indices, 0..7493).
    pub fn checks(&self) -> &[Vec<u16>] {
        &self.checks
    }

    /// Encodes the message bits (`127·K`, one per byte, 0/1) into the 7488 transmitted
    /// bits: parity bits 5 … 127·C − 1, then the message.
    ///
    /// # Panics
    /// When the slices have other lengths (an internal invariant of the data layer).
    pub fn encode(&self, message: &[u8], out: &mut [u8]) {
        let kb = self.rate.message_blocks();
        let cb = self.rate.parity_blocks();
        assert_eq!(message.len(), kb * Z);
        assert_eq!(out.len(), CODEWORD_BITS);
        // p_j = Σ_s rot(Σ_{b: u_b[s] = 1} g_{b,j}, s): for each shift, add up the first
        // rows of the blocks whose bit s is set (plain XORs, which vectorise), then rotate
        // that sum once per parity block.
        let mut acc = [0u128; 35];
        let acc = &mut acc[..cb];
        let mut sum = [0u128; 35];
        let sum = &mut sum[..cb];
        for s in 0..Z {
            sum.fill(0);
            let mut any = false;
            for b in 0..kb {
                if message[b * Z + s] & 1 != 0 {
                    any = true;
                    for (t, &gj) in sum.iter_mut().zip(&self.g[b * cb..(b + 1) * cb]) {
                        *t ^= gj;
                    }
                }
            }
            if any {
                for (a, &t) in acc.iter_mut().zip(sum.iter()) {
                    *a ^= rot(t, s as u32);
                }
            }
        }
        let parity = cb * Z;
        for (q, o) in (DELETED_BITS..parity).zip(out.iter_mut()) {
            *o = (acc[q / Z] >> (q % Z)) as u8 & 1;
        }
        out[parity - DELETED_BITS..].copy_from_slice(message);
    }

    /// The fast encoder: the `C` parity blocks (all `127·C` parity bits, the five deleted
    /// ones included: bit `t` of block `j` is parity bit `127·j + t`) of the `K` message
    /// blocks (bit `s` of block `b` is message bit `127·b + s`; bit 127 must be zero).
    /// Carry-less products when the CPU has them, else the rotation form on packed blocks;
    /// both equal [`LdpcCode::encode`]'s bits.
    ///
    /// # Panics
    /// When the slices have other lengths (an internal invariant of the data layer).
    pub fn encode_blocks(&self, message: &[u128], parity: &mut [u128]) {
        let kb = self.rate.message_blocks();
        let cb = self.rate.parity_blocks();
        assert_eq!(message.len(), kb);
        assert_eq!(parity.len(), cb);
        debug_assert!(message.iter().all(|&u| u >> 127 == 0));
        #[cfg(target_arch = "x86_64")]
        if self.clmul {
            // SAFETY: `clmul` is set only when the CPU has PCLMULQDQ (and SSE2).
            unsafe { parity_clmul(&self.gt, message, parity) };
            return;
        }
        self.encode_blocks_portable(message, parity);
    }

    /// [`LdpcCode::encode_blocks`] without carry-less multiplies: for each shift `s`, the
    /// first rows of the blocks whose bit `s` is set are added, and the sum rotated once
    /// per parity block.
    pub fn encode_blocks_portable(&self, message: &[u128], parity: &mut [u128]) {
        let kb = self.rate.message_blocks();
        let cb = self.rate.parity_blocks();
        assert_eq!(message.len(), kb);
        assert_eq!(parity.len(), cb);
        parity.fill(0);
        let mut sum = [0u128; 35];
        let sum = &mut sum[..cb];
        for s in 0..Z {
            sum.fill(0);
            let mut any = false;
            for (b, &u) in message.iter().enumerate() {
                if u >> s & 1 != 0 {
                    any = true;
                    for (t, &gj) in sum.iter_mut().zip(&self.g[b * cb..(b + 1) * cb]) {
                        *t ^= gj;
                    }
                }
            }
            if any {
                for (a, &t) in parity.iter_mut().zip(sum.iter()) {
                    *a ^= rot(t, s as u32);
                }
            }
        }
    }

    /// The number of unsatisfied checks of a full 7493-bit word (0 for a codeword).
    pub fn syndrome_weight(&self, full: &[u8]) -> usize {
        self.checks
            .iter()
            .filter(|row| row.iter().fold(0u8, |p, &v| p ^ full[v as usize]) & 1 != 0)
            .count()
    }

    /// The full 7493-bit word of a transmitted codeword, with the deleted parity bits set
    /// to `deleted` (the encoder's own values, for checks).
    pub fn full_word(&self, tx: &[u8], deleted: [u8; DELETED_BITS]) -> Vec<u8> {
        let mut f = Vec::with_capacity(FULL_BITS);
        f.extend_from_slice(&deleted);
        f.extend_from_slice(tx);
        f
    }

    /// The five deleted parity bits of a message (for checks).
    pub fn deleted_bits(&self, message: &[u8]) -> [u8; DELETED_BITS] {
        let cb = self.rate.parity_blocks();
        let mut p0 = 0u128;
        for (b, block) in message.chunks_exact(Z).enumerate() {
            for (s, &bit) in block.iter().enumerate() {
                if bit & 1 != 0 {
                    p0 ^= rot(self.g[b * cb], s as u32);
                }
            }
        }
        std::array::from_fn(|i| (p0 >> i) as u8 & 1)
    }
}

/// Whether the CPU has the carry-less multiply the fast encoder uses.
fn clmul_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("pclmulqdq")
            && std::arch::is_x86_feature_detected!("sse2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `p_j = Σ_b u_b·g_{b,j} mod (z¹²⁷ − 1)` with PCLMULQDQ: per parity block, the three
/// Karatsuba partial products `u_lo·g_lo`, `u_hi·g_hi` and `(u_lo ⊕ u_hi)·(g_lo ⊕ g_hi)`
/// are summed over the message blocks (the sum commutes with the product), then combined
/// into the 253-bit product and folded at bit 127.
///
/// # Safety
/// The CPU must support PCLMULQDQ and SSE2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "pclmulqdq,sse2")]
unsafe fn parity_clmul(gt: &[[u64; 3]], message: &[u128], parity: &mut [u128]) {
    use std::arch::x86_64::{
        __m128i, _mm_clmulepi64_si128, _mm_set_epi64x, _mm_setzero_si128, _mm_storeu_si128,
        _mm_xor_si128,
    };
    let kb = message.len();
    // The message blocks as (lo, hi) registers and their halves' XOR (in the low lane).
    let mut u = [_mm_setzero_si128(); 48];
    let mut ux = [_mm_setzero_si128(); 48];
    for (b, &m) in message.iter().enumerate() {
        let (lo, hi) = (m as u64, (m >> 64) as u64);
        u[b] = _mm_set_epi64x(hi as i64, lo as i64);
        ux[b] = _mm_set_epi64x(0, (lo ^ hi) as i64);
    }
    for (p, gj) in parity.iter_mut().zip(gt.chunks_exact(kb)) {
        let mut lo = _mm_setzero_si128();
        let mut hi = _mm_setzero_si128();
        let mut mid = _mm_setzero_si128();
        for ((g, &ub), &uxb) in gj.iter().zip(&u[..kb]).zip(&ux[..kb]) {
            let gv = _mm_set_epi64x(g[1] as i64, g[0] as i64);
            let gx = _mm_set_epi64x(0, g[2] as i64);
            lo = _mm_xor_si128(lo, _mm_clmulepi64_si128::<0x00>(ub, gv));
            hi = _mm_xor_si128(hi, _mm_clmulepi64_si128::<0x11>(ub, gv));
            mid = _mm_xor_si128(mid, _mm_clmulepi64_si128::<0x00>(uxb, gx));
        }
        let mut l = [0u64; 2];
        let mut h = [0u64; 2];
        let mut m = [0u64; 2];
        // SAFETY: each destination is 16 bytes; unaligned stores are allowed.
        unsafe {
            _mm_storeu_si128(l.as_mut_ptr().cast::<__m128i>(), lo);
            _mm_storeu_si128(h.as_mut_ptr().cast::<__m128i>(), hi);
            _mm_storeu_si128(m.as_mut_ptr().cast::<__m128i>(), mid);
        }
        // The middle term of Karatsuba: (a0 ⊕ a1)(b0 ⊕ b1) ⊕ a0b0 ⊕ a1b1 = a0b1 ⊕ a1b0.
        let m0 = m[0] ^ l[0] ^ h[0];
        let m1 = m[1] ^ l[1] ^ h[1];
        let low = u128::from(l[0]) | (u128::from(l[1] ^ m0) << 64);
        let high = u128::from(h[0] ^ m1) | (u128::from(h[1]) << 64);
        // z¹²⁷ = 1: bits 127 … 252 of the product fold onto bits 0 … 125.
        *p = (low & MASK) ^ (low >> 127) ^ (high << 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_bits(n: usize, mut state: u64) -> Vec<u8> {
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 33) as u8 & 1
            })
            .collect()
    }

    /// Every encoded word satisfies every check of dtmb-sdr's parity-check matrix, and
    /// the code is systematic in the order dtmb-sdr reads.
    #[test]
    fn encoded_words_satisfy_all_checks() {
        for rate in CodeRate::ALL {
            let c = code(rate);
            assert_eq!(c.checks().len(), rate.parity_blocks() * Z);
            for seed in 1..4u64 {
                let msg = random_bits(rate.message_bits(), seed * 0x9e37_79b9);
                let mut tx = vec![0u8; CODEWORD_BITS];
                c.encode(&msg, &mut tx);
                assert_eq!(&tx[CODEWORD_BITS - msg.len()..], &msg[..]);
                let full = c.full_word(&tx, c.deleted_bits(&msg));
                assert_eq!(c.syndrome_weight(&full), 0, "rate {}", rate.name());
                // One flipped bit breaks some checks (every column has weight ≥ 3).
                let mut bad = full.clone();
                bad[1000] ^= 1;
                assert!(c.syndrome_weight(&bad) >= 3);
            }
        }
    }

    /// The fast encoder (carry-less products where the CPU has them) and its portable
    /// form give the straightforward bit-per-byte encoder's bits, for random messages of
    /// all three rates, the all-ones message and single bits at the blocks' ends.
    #[test]
    fn packed_encoders_equal_the_reference() {
        for rate in CodeRate::ALL {
            let c = code(rate);
            let cb = rate.parity_blocks();
            let mut msgs: Vec<Vec<u8>> = (1..40u64)
                .map(|seed| random_bits(rate.message_bits(), seed * 0x2545_f491_4f6c_dd1d))
                .collect();
            msgs.push(vec![1; rate.message_bits()]);
            for p in [0, 126, 127, rate.message_bits() - 1] {
                let mut m = vec![0; rate.message_bits()];
                m[p] = 1;
                msgs.push(m);
            }
            for msg in &msgs {
                let mut tx = vec![0u8; CODEWORD_BITS];
                c.encode(msg, &mut tx);
                let blocks: Vec<u128> = msg
                    .chunks_exact(Z)
                    .map(|blk| {
                        blk.iter()
                            .enumerate()
                            .fold(0u128, |a, (s, &bit)| a | (u128::from(bit) << s))
                    })
                    .collect();
                let mut fast = vec![0u128; cb];
                let mut portable = vec![u128::MAX; cb];
                c.encode_blocks(&blocks, &mut fast);
                c.encode_blocks_portable(&blocks, &mut portable);
                assert_eq!(fast, portable, "rate {}", rate.name());
                let bits: Vec<u8> = (DELETED_BITS..cb * Z)
                    .map(|q| (fast[q / Z] >> (q % Z)) as u8 & 1)
                    .collect();
                assert_eq!(&tx[..bits.len()], &bits[..], "rate {}", rate.name());
                let deleted: [u8; DELETED_BITS] = std::array::from_fn(|i| (fast[0] >> i) as u8 & 1);
                assert_eq!(deleted, c.deleted_bits(msg));
                assert!(fast.iter().all(|&p| p >> 127 == 0));
            }
        }
    }

    /// The block rows' circulants sit in distinct block columns (what lets a decoder
    /// update the 127 rows of a block row at once), and expand to the check rows.
    #[test]
    fn block_rows_have_distinct_columns() {
        for rate in CodeRate::ALL {
            let c = code(rate);
            assert_eq!(c.circulants().len(), rate.parity_blocks());
            for (r, row) in c.circulants().iter().enumerate() {
                let mut cols: Vec<u8> = row.iter().map(|&(col, _)| col).collect();
                cols.sort_unstable();
                cols.dedup();
                assert_eq!(cols.len(), row.len(), "rate {} block row {r}", rate.name());
                assert_eq!(c.checks()[r * Z].len(), row.len());
            }
        }
    }

    #[test]
    fn code_sizes_match_the_standard() {
        assert_eq!(CodeRate::R04.message_bits(), 3048);
        assert_eq!(CodeRate::R06.ts_bytes_per_codeword(), 3 * 188);
        assert_eq!(CodeRate::R08.bch_per_codeword(), 8);
        assert_eq!(CodeRate::R04.ts_bytes_per_codeword(), 2 * 188);
        assert_eq!(DELETED_BITS, 5);
    }
}
