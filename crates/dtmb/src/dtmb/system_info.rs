//! The system information of GB 20600-2006 §4.7 (Appendix G): 36 symbols in every frame
//! body, 4 carrier-mode bits (`1111` for C = 3780, `0000` for C = 1) and a 32-bit spread
//! codeword; each bit maps to `±(1+j)/√2` (0 → +, 1 → −). The 64 codewords are the 32
//! "odd" vectors below and their complements (index `2k+1` is vector `k`, index `2k+2` its
//! complement). Index 1 and 2 mark the first frame of an odd and an even superframe;
//! indices 3 to 24 name the profiles: 4QAM-NR 0.8 (3, 4), 4QAM 0.4/0.6/0.8 (5–10), 16QAM
//! (11–16), 32QAM 0.8 (17, 18), 64QAM (19–24), odd for interleaver mode 1 (M = 240), even
//! for mode 2 (M = 720). Vectors transcribed from Appendix G as the receiver dtmb-sdr
//! lists them.
//!
//! For C = 3780 the 36 symbols take these logical positions of the 3780-symbol block
//! before the frequency interleaver (one at each end of every 420-symbol sixth, and at
//! 140 and 279 within it), the data symbols filling the others in order.

/// The 32 odd system-information vectors, first bit sent first.
const ODD_VECTORS: [&str; 32] = [
    "00011110101011100100100010110011",
    "01111000110010000010111011010101",
    "01110111110001110010000111011010",
    "00100010100100100111010010001111",
    "01001011111110110001110111100110",
    "00010001101000010100011110111100",
    "01111000001101110010111000101010",
    "00101101100111010111101110000000",
    "01110111001110000010000100100101",
    "00100010011011010111010001110000",
    "01000100000010110001001000010110",
    "00010001010111100100011101000011",
    "00101101011000100111101101111111",
    "01000100111101000001001011101001",
    "01001011000001000001110100011001",
    "00011110010100010100100001001100",
    "01111000110010001101000100101010",
    "00101101100111011000010001111111",
    "01001011111110111110001000011001",
    "00011110101011101011011101001100",
    "01110111110001111101111000100101",
    "00100010100100101000101101110000",
    "01000100111101001110110100010110",
    "00010001101000011011100001000011",
    "01111000001101111101000111010101",
    "00101101011000101000010010000000",
    "01001011000001001110001011100110",
    "00011110010100011011011110110011",
    "01110111001110001101111011011010",
    "00100010011011011000101110001111",
    "01000100000010111110110111101001",
    "00010001010111101011100010111100",
];

/// Logical positions of the 36 system-information symbols in a C = 3780 block.
pub const C3780_POSITIONS: [usize; 36] = [
    0, 140, 279, 419, 420, 560, 699, 839, 840, 980, 1119, 1259, 1260, 1400, 1539, 1679, 1680, 1820,
    1959, 2099, 2100, 2240, 2379, 2519, 2520, 2660, 2799, 2939, 2940, 3080, 3219, 3359, 3360, 3500,
    3639, 3779,
];

/// The 32-bit vector of system-information index `index` (1..=64), first bit sent in the
/// most significant place.
///
/// # Panics
/// For an index outside 1..=64 (callers pass profile indices 3..=24 or the markers 1, 2).
pub fn vector(index: u8) -> u32 {
    assert!(
        (1..=64).contains(&index),
        "system-information index {index}"
    );
    let odd = ODD_VECTORS[usize::from(index - 1) / 2];
    let v = odd
        .bytes()
        .fold(0u32, |a, c| (a << 1) | u32::from(c == b'1'));
    if index % 2 == 0 {
        !v
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectors are distinct, and odd/even pairs complement: the receiver tells 64
    /// indices apart by correlation, so no two may coincide.
    #[test]
    fn vectors_are_distinct_and_pairs_complement() {
        let all: Vec<u32> = (1..=64).map(vector).collect();
        for i in 0..64 {
            for j in 0..i {
                assert_ne!(all[i], all[j], "{i} {j}");
            }
        }
        assert_eq!(vector(3), !vector(4));
        assert_eq!(vector(1) >> 28, 0b0001);
    }

    #[test]
    fn positions_are_sorted_and_in_range() {
        assert!(C3780_POSITIONS.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(*C3780_POSITIONS.last().unwrap(), 3779);
    }
}
