//! The outer code of GB 20600-2006 §4.3: BCH(762, 752), the BCH(1023, 1013) code shortened
//! by 261 bits, with generator polynomial `g(x) = 1 + x³ + x¹⁰`. It is systematic: the 752
//! message bits (the first the highest power) are followed by the 10 parity bits
//! `m(x)·x¹⁰ mod g(x)`. A single-error-correcting code; the receiver corrects one bit.

/// Message bits of a BCH codeword.
pub const BCH_K: usize = 752;
/// Bits of a BCH codeword.
pub const BCH_N: usize = 762;
/// `g(x)` without its leading `x¹⁰` term.
const G_LOW: u16 = 0b00_0000_1001;

/// The 10-bit remainder of the bit sequence `bits` (first bit the highest power) times
/// `x¹⁰` divided by `g(x)`.
fn remainder(bits: impl Iterator<Item = u8>) -> u16 {
    let mut reg = 0u16;
    for b in bits {
        let fb = ((reg >> 9) as u8 & 1) ^ (b & 1);
        reg = (reg << 1) & 0x3ff;
        if fb != 0 {
            reg ^= G_LOW;
        }
    }
    reg
}

/// Encodes `message` (752 bits, one per byte, values 0/1) into `codeword` (762 bits).
///
/// # Panics
/// When the slices have other lengths (an internal invariant of the data layer).
pub fn encode(message: &[u8], codeword: &mut [u8]) {
    assert_eq!(message.len(), BCH_K);
    assert_eq!(codeword.len(), BCH_N);
    codeword[..BCH_K].copy_from_slice(message);
    let r = remainder(message.iter().copied());
    for (i, c) in codeword[BCH_K..].iter_mut().enumerate() {
        *c = ((r >> (9 - i)) & 1) as u8;
    }
}

/// The 10 parity bits of a message given as its 94 bytes (first bit of the message the
/// most significant bit of the first byte): [`encode`]'s parity, `r` with the codeword's
/// bit `752 + i` equal to bit `9 − i` of `r`. The division runs a byte at a time with a
/// 256-entry table of the remainders of `i·x¹⁰` (the usual table-driven CRC), which
/// is the bit-serial division of [`encode`] regrouped, since the division is linear.
///
/// # Panics
/// When `bytes` is not 94 long (an internal invariant of the data layer).
pub fn parity_of_bytes(bytes: &[u8]) -> u16 {
    assert_eq!(bytes.len(), BCH_K / 8);
    let table = byte_table();
    bytes.iter().fold(0u16, |reg, &b| {
        ((reg << 8) & 0x3ff) ^ table[usize::from((reg >> 2) as u8 ^ b)]
    })
}

/// [`parity_of_bytes`] of up to eight consecutive 94-byte messages, computed in lockstep
/// (each division is a chain of dependent table lookups; interleaving the blocks' chains
/// lets them overlap).
///
/// # Panics
/// When `bytes` is not `94 · parity.len()` long or `parity` is longer than 8.
pub fn parities_of_bytes(bytes: &[u8], parity: &mut [u16]) {
    const K8: usize = BCH_K / 8;
    let n = parity.len();
    assert!(n <= 8);
    assert_eq!(bytes.len(), n * K8);
    let table = byte_table();
    let mut reg = [0u16; 8];
    for i in 0..K8 {
        for (b, r) in reg[..n].iter_mut().enumerate() {
            *r = ((*r << 8) & 0x3ff) ^ table[usize::from((*r >> 2) as u8 ^ bytes[b * K8 + i])];
        }
    }
    parity.copy_from_slice(&reg[..n]);
}

/// `table[i]`: the remainder after shifting the byte `i` (most significant bit first)
/// into an empty register.
fn byte_table() -> &'static [u16; 256] {
    static TABLE: std::sync::OnceLock<[u16; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| remainder((0..8).map(|t| ((i >> (7 - t)) & 1) as u8)))
    })
}

/// The syndrome of a received 762-bit word: the remainder of its polynomial (first bit the
/// highest power) divided by `g(x)`; zero for a codeword.
pub fn syndrome(word: &[u8]) -> u16 {
    // Dividing w(x) by g(x) directly: shift each bit in and reduce.
    let mut reg = 0u16;
    for &b in word {
        reg = (reg << 1) | u16::from(b & 1);
        if reg & 0x400 != 0 {
            reg ^= 0x400 | G_LOW;
        }
    }
    reg
}

/// Decodes a received word in place: corrects a single bit error, which the code always
/// can. Returns `Some(corrected bits)` (0 or 1) or `None` when the syndrome matches no
/// single error (two or more errors).
pub fn decode(word: &mut [u8]) -> Option<usize> {
    let s = syndrome(word);
    if s == 0 {
        return Some(0);
    }
    let pos = single_error_table()[s as usize];
    if pos == u16::MAX {
        return None;
    }
    word[pos as usize] ^= 1;
    Some(1)
}

/// Syndrome → error position of every single-bit error of a 762-bit word.
fn single_error_table() -> &'static [u16; 1024] {
    static TABLE: std::sync::OnceLock<[u16; 1024]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [u16::MAX; 1024];
        // The syndrome of an error at position p is x^(761−p) mod g(x).
        let mut r = 1u16;
        for p in (0..BCH_N).rev() {
            t[r as usize] = p as u16;
            r <<= 1;
            if r & 0x400 != 0 {
                r ^= 0x400 | G_LOW;
            }
        }
        t
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codewords_have_zero_syndrome_and_single_errors_are_corrected() {
        let mut state = 0x1234_5678u32;
        let msg: Vec<u8> = (0..BCH_K)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state & 1) as u8
            })
            .collect();
        let mut cw = vec![0u8; BCH_N];
        encode(&msg, &mut cw);
        assert_eq!(syndrome(&cw), 0);
        for p in [0, 1, 377, 751, 752, 761] {
            let mut w = cw.clone();
            w[p] ^= 1;
            assert_ne!(syndrome(&w), 0);
            assert_eq!(decode(&mut w), Some(1));
            assert_eq!(w, cw, "error at {p}");
        }
        // The 1023-bit mother code has distance 3: every single error has its own syndrome.
        let t = single_error_table();
        assert_eq!(t.iter().filter(|&&p| p != u16::MAX).count(), BCH_N);
    }

    /// The byte-wise division gives the bit-serial encoder's parity for random messages.
    #[test]
    fn byte_wise_parity_equals_the_bit_serial_encoder() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..500 {
            let bytes: Vec<u8> = (0..BCH_K / 8)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 24) as u8
                })
                .collect();
            let bits: Vec<u8> = bytes
                .iter()
                .flat_map(|&b| (0..8).map(move |t| (b >> (7 - t)) & 1))
                .collect();
            let mut cw = vec![0u8; BCH_N];
            encode(&bits, &mut cw);
            let r = parity_of_bytes(&bytes);
            let mut lockstep = [0u16; 1];
            parities_of_bytes(&bytes, &mut lockstep);
            assert_eq!(lockstep[0], r);
            let fast: Vec<u8> = (0..10).map(|i| ((r >> (9 - i)) & 1) as u8).collect();
            assert_eq!(&cw[BCH_K..], &fast[..]);
        }
        // Eight blocks in lockstep equal eight separate divisions.
        let bytes: Vec<u8> = (0..8 * BCH_K / 8).map(|i| (i * 37 % 251) as u8).collect();
        let mut lockstep = [0u16; 8];
        parities_of_bytes(&bytes, &mut lockstep);
        for (b, &r) in lockstep.iter().enumerate() {
            assert_eq!(r, parity_of_bytes(&bytes[b * 94..(b + 1) * 94]));
        }
    }

    /// g(x) = 1 + x³ + x¹⁰ is primitive: x has order 1023 modulo g, so the mother code has
    /// length 1023 as the standard says.
    #[test]
    fn generator_is_primitive() {
        let mut r = 1u16;
        let mut order = 0;
        loop {
            r <<= 1;
            if r & 0x400 != 0 {
                r ^= 0x400 | G_LOW;
            }
            order += 1;
            if r == 1 {
                break;
            }
        }
        assert_eq!(order, 1023);
    }
}
