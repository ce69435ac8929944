//! Bit-to-symbol mapping of GB 20600-2006 §4.5: 4QAM-NR, 4QAM, 16QAM, 32QAM and 64QAM.
//!
//! Square QAM with `2h` bits per symbol: the first `h` bits `b₀ … b_{h−1}` select the
//! in-phase level, the next `h` the quadrature level; on each axis the levels
//! `−(L−1), …, −1, +1, …, L−1` (index `i = 0 … L−1` ascending) carry the reflected Gray
//! label `i ⊕ (i ≫ 1)` with `b₀` its least significant bit (16QAM `b₀b₁`: −6 → 00,
//! −2 → 10, +2 → 11, +6 → 01). 32QAM is the cross constellation of the standard's
//! Figure 4 (points on the ±1.5, ±4.5, ±7.5 grid without the four corners), tabulated
//! below. 4QAM-NR sends each 8 bits as the 16-bit Nordstrom–Robinson codeword on eight
//! 4QAM symbols. These are the labels the receiver dtmb-sdr demaps with (its tests
//! transcribe Figure 4 independently). Every constellation is scaled to unit mean power.

use num_complex::Complex32;

/// A data constellation of the frame body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Constellation {
    /// 4QAM with the Nordstrom–Robinson (16, 8) code: 1 information bit per symbol.
    Qam4Nr,
    /// 4QAM.
    Qam4,
    /// 16QAM.
    Qam16,
    /// 32QAM (cross).
    Qam32,
    /// 64QAM.
    Qam64,
}

/// Figure 4 of GB 20600-2006 (32QAM): the label `b₀b₁b₂b₃b₄` (as a string, `b₀` first) of
/// each point `(I, Q)` in units of the 1.5 grid step's half.
const QAM32: [(&str, f32, f32); 32] = [
    ("10111", -4.5, 7.5),
    ("10011", -1.5, 7.5),
    ("11011", 1.5, 7.5),
    ("11111", 4.5, 7.5),
    ("10010", -7.5, 4.5),
    ("00111", -4.5, 4.5),
    ("00011", -1.5, 4.5),
    ("01011", 1.5, 4.5),
    ("01111", 4.5, 4.5),
    ("11010", 7.5, 4.5),
    ("10110", -7.5, 1.5),
    ("00110", -4.5, 1.5),
    ("00010", -1.5, 1.5),
    ("01010", 1.5, 1.5),
    ("01110", 4.5, 1.5),
    ("11110", 7.5, 1.5),
    ("10100", -7.5, -1.5),
    ("00100", -4.5, -1.5),
    ("00000", -1.5, -1.5),
    ("01000", 1.5, -1.5),
    ("01100", 4.5, -1.5),
    ("11100", 7.5, -1.5),
    ("10000", -7.5, -4.5),
    ("00101", -4.5, -4.5),
    ("00001", -1.5, -4.5),
    ("01001", 1.5, -4.5),
    ("01101", 4.5, -4.5),
    ("11000", 7.5, -4.5),
    ("10101", -4.5, -7.5),
    ("10001", -1.5, -7.5),
    ("11001", 1.5, -7.5),
    ("11101", 4.5, -7.5),
];

impl Constellation {
    /// All five, in the standard's order.
    pub const ALL: [Constellation; 5] = [
        Constellation::Qam4Nr,
        Constellation::Qam4,
        Constellation::Qam16,
        Constellation::Qam32,
        Constellation::Qam64,
    ];

    /// Coded bits per symbol (4QAM-NR: 2 code bits, 1 information bit).
    pub fn bits_per_symbol(self) -> usize {
        match self {
            Constellation::Qam4Nr | Constellation::Qam4 => 2,
            Constellation::Qam16 => 4,
            Constellation::Qam32 => 5,
            Constellation::Qam64 => 6,
        }
    }

    /// LDPC bits carried per symbol (4QAM-NR: 1, the NR code halves the rate).
    pub fn ldpc_bits_per_symbol(self) -> usize {
        match self {
            Constellation::Qam4Nr => 1,
            c => c.bits_per_symbol(),
        }
    }

    /// The name used on the command line and in the standard.
    pub fn name(self) -> &'static str {
        match self {
            Constellation::Qam4Nr => "4qam-nr",
            Constellation::Qam4 => "4qam",
            Constellation::Qam16 => "16qam",
            Constellation::Qam32 => "32qam",
            Constellation::Qam64 => "64qam",
        }
    }

    /// Every point, indexed by its label `Σ bₜ 2ᵗ` (`b₀` the first bit sent), at unit mean
    /// power. 4QAM-NR uses the 4QAM points.
    pub fn points(self) -> Vec<Complex32> {
        match self {
            Constellation::Qam32 => {
                let mut p = vec![Complex32::default(); 32];
                let s = 1.0 / 45f32.sqrt();
                for (label, i, q) in QAM32 {
                    let idx = label
                        .bytes()
                        .enumerate()
                        .fold(0usize, |a, (t, c)| a | (usize::from(c == b'1') << t));
                    p[idx] = Complex32::new(i * s, q * s);
                }
                p
            }
            c => {
                let h = c.bits_per_symbol() / 2;
                let levels = 1usize << h;
                // Mean power of the levels ±1, ±3, …: (L² − 1)/3 per axis.
                let s = 1.0 / (2.0 * ((levels * levels - 1) as f32) / 3.0).sqrt();
                let level_of = |label: usize| {
                    // Gray label → ascending level index.
                    let mut i = label;
                    let mut t = label >> 1;
                    while t != 0 {
                        i ^= t;
                        t >>= 1;
                    }
                    (2 * i as i32 - (levels as i32 - 1)) as f32 * s
                };
                (0..1usize << (2 * h))
                    .map(|l| Complex32::new(level_of(l & (levels - 1)), level_of(l >> h)))
                    .collect()
            }
        }
    }
}

impl std::str::FromStr for Constellation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        Constellation::ALL
            .into_iter()
            .find(|c| c.name() == t)
            .ok_or_else(|| {
                format!("unknown constellation {s:?}: valid names are 4qam-nr, 4qam, 16qam, 32qam, 64qam")
            })
    }
}

/// Maps a stream of bits (one per byte) to symbols: each symbol takes the next
/// `bits_per_symbol` bits, the first as `b₀`.
pub fn map_bits(points: &[Complex32], bits_per_symbol: usize, bits: &[u8], out: &mut [Complex32]) {
    for (chunk, o) in bits.chunks_exact(bits_per_symbol).zip(out.iter_mut()) {
        let label = chunk
            .iter()
            .enumerate()
            .fold(0usize, |a, (t, &b)| a | (usize::from(b & 1) << t));
        *o = points[label];
    }
}

/// The labels [`map_bits`] maps, from a packed bit stream: bit `k` of the stream is bit
/// `k mod 64` of `stream[k / 64]`, so symbol `n`'s label (`b₀` its least significant bit)
/// is simply the `bits_per_symbol` bits from stream bit `n·bits_per_symbol` on. `stream`
/// carries one word beyond the symbols' last bit (read, not used).
///
/// # Panics
/// When `stream` is shorter than `out`'s bits plus one word (an internal invariant).
pub fn labels_packed(bits_per_symbol: usize, stream: &[u64], out: &mut [u8]) {
    assert!(stream.len() * 64 >= out.len() * bits_per_symbol + 64);
    let mask = (1u64 << bits_per_symbol) - 1;
    for (n, o) in out.iter_mut().enumerate() {
        let start = n * bits_per_symbol;
        let (w, sh) = (start / 64, (start % 64) as u32);
        // `<< 1 << (63 − sh)` is `<< (64 − sh)` without the undefined shift by 64 at sh = 0.
        let v = (stream[w] >> sh) | ((stream[w + 1] << 1) << (63 - sh));
        *o = (v & mask) as u8;
    }
}

/// The Nordstrom–Robinson (16, 8) codeword of `byte` (GB 20600-2006 §4.5.1): the byte
/// (first bit most significant) followed by 7 parity bits and an overall parity bit,
///
/// ```text
/// y_i = x₇ ⊕ x_{i+6} ⊕ x_i ⊕ x_{i+1} ⊕ x_{i+3} ⊕ (x_i ⊕ x_{i+4})(x_{i+1} ⊕ x_{i+2} ⊕ x_{i+3} ⊕ x_{i+5})
///       ⊕ (x_{i+1} ⊕ x_{i+2})(x_{i+3} ⊕ x_{i+5}),   indices mod 7, i = 0 … 6,
/// ```
///
/// with `x₀` the byte's first bit; the 16 bits are sent first bit (most significant)
/// first. This is the generator form the receiver dtmb-sdr decodes with.
pub fn nr_encode(byte: u8) -> u16 {
    let x: [u8; 8] = std::array::from_fn(|i| (byte >> (7 - i)) & 1);
    let mut parity = 0u16;
    let mut last = (byte.count_ones() & 1) as u8;
    for i in 0..7 {
        let at = |j: usize| x[(i + j) % 7];
        let y = x[7]
            ^ at(6)
            ^ at(0)
            ^ at(1)
            ^ at(3)
            ^ ((at(0) ^ at(4)) & (at(1) ^ at(2) ^ at(3) ^ at(5)))
            ^ ((at(1) ^ at(2)) & (at(3) ^ at(5)));
        parity |= u16::from(y) << (7 - i);
        last ^= y;
    }
    (u16::from(byte) << 8) | parity | u16::from(last)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Nordstrom–Robinson code is nonlinear with 256 codewords at minimum Hamming
    /// distance 6 (its defining property).
    #[test]
    fn nordstrom_robinson_has_distance_6() {
        let words: Vec<u16> = (0..=255u8).map(nr_encode).collect();
        let mut dmin = 16;
        for i in 0..256 {
            for j in 0..i {
                dmin = dmin.min((words[i] ^ words[j]).count_ones());
            }
        }
        assert_eq!(dmin, 6);
    }

    #[test]
    fn constellations_have_unit_power_and_distinct_points() {
        for c in Constellation::ALL {
            let p = c.points();
            assert_eq!(p.len(), 1 << c.bits_per_symbol());
            let power: f32 = p.iter().map(|x| x.norm_sqr()).sum::<f32>() / p.len() as f32;
            assert!((power - 1.0).abs() < 1e-5, "{c:?} {power}");
            for i in 0..p.len() {
                for j in 0..i {
                    assert!((p[i] - p[j]).norm() > 0.1, "{c:?} {i} {j}");
                }
            }
        }
    }

    /// The packed labels give the bit-per-byte mapper's symbols for every constellation.
    #[test]
    fn packed_mapping_equals_bit_mapping() {
        let mut state = 0x0123_4567_89ab_cdefu64;
        let words: Vec<u64> = (0..120)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state
            })
            .collect();
        let bits: Vec<u8> = (0..119 * 64)
            .map(|k| (words[k / 64] >> (k % 64)) as u8 & 1)
            .collect();
        for c in Constellation::ALL {
            let p = c.points();
            let bps = c.bits_per_symbol();
            let n = bits.len() / bps;
            let mut a = vec![Complex32::default(); n];
            let mut labels = vec![0u8; n];
            map_bits(&p, bps, &bits, &mut a);
            labels_packed(bps, &words, &mut labels);
            let b: Vec<Complex32> = labels.iter().map(|&l| p[usize::from(l)]).collect();
            assert_eq!(a, b, "{c:?}");
        }
    }

    /// 16QAM on the I axis, b₀b₁: −6 → 00, −2 → 10, +2 → 11, +6 → 01 (levels ×√10 … scaled).
    #[test]
    fn sixteen_qam_labels_follow_the_standard() {
        let p = Constellation::Qam16.points();
        let s = 40f32.sqrt();
        let lvl = |label: usize| (p[label].re * s).round() as i32;
        assert_eq!([lvl(0b00), lvl(0b01), lvl(0b11), lvl(0b10)], [-6, -2, 2, 6]);
        // Q is the upper two bits, same labels.
        assert_eq!((p[0b0100].im * s).round() as i32, -2);
        // 64QAM I: b₀b₁b₂ = 000 → −7, 100 → −5, 110 → −3, 010 → −1, 011 → +1.
        let p = Constellation::Qam64.points();
        let s = 42f32.sqrt();
        let lvl = |label: usize| (p[label].re * s).round() as i32;
        assert_eq!(
            [lvl(0b000), lvl(0b001), lvl(0b011), lvl(0b010), lvl(0b110)],
            [-7, -5, -3, -1, 1]
        );
    }
}
