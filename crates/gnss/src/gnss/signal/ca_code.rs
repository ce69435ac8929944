//! GPS L1 C/A ranging codes (IS-GPS-200 §3.2.1.3, §3.3.2.3, Table 3-Ia).
//!
//! Each code is the modulo-2 sum of two 1023-chip maximal-length sequences clocked at
//! 1.023 Mchip/s, both registers starting from all ones:
//!
//! ```text
//! G1(X) = 1 + X³ + X¹⁰
//! G2(X) = 1 + X² + X³ + X⁶ + X⁸ + X⁹ + X¹⁰
//! C/A_i(n) = G1(n) ⊕ G2(n − d_i)
//! ```
//!
//! The delayed G2 sequence is obtained, as in the satellite hardware, as the sum of two
//! stages of the G2 register (the "phase selector" taps of Table 3-Ia).

/// Chips per C/A code period (1 ms).
pub const CA_CODE_LEN: usize = 1023;

/// G2 phase-selector taps (register stages, 1-based) of PRN 1–32, IS-GPS-200 Table 3-Ia.
const G2_TAPS: [(u8, u8); 32] = [
    (2, 6),
    (3, 7),
    (4, 8),
    (5, 9),
    (1, 9),
    (2, 10),
    (1, 8),
    (2, 9),
    (3, 10),
    (2, 3),
    (3, 4),
    (5, 6),
    (6, 7),
    (7, 8),
    (8, 9),
    (9, 10),
    (1, 4),
    (2, 5),
    (3, 6),
    (4, 7),
    (5, 8),
    (6, 9),
    (1, 3),
    (4, 6),
    (5, 7),
    (6, 8),
    (7, 9),
    (8, 10),
    (1, 6),
    (2, 7),
    (3, 8),
    (4, 9),
];

/// The C/A code of `prn` (1–32) as bits (0/1), chip 0 first; `None` for other PRNs.
pub fn ca_code_bits(prn: u16) -> Option<[u8; CA_CODE_LEN]> {
    let (a, b) = *G2_TAPS.get(usize::from(prn).checked_sub(1)?)?;
    // reg[k] is stage k+1; the output of a register is its stage 10.
    let mut g1 = [1u8; 10];
    let mut g2 = [1u8; 10];
    let mut out = [0u8; CA_CODE_LEN];
    for chip in out.iter_mut() {
        let g2i = g2[usize::from(a) - 1] ^ g2[usize::from(b) - 1];
        *chip = g1[9] ^ g2i;
        let f1 = g1[2] ^ g1[9];
        let f2 = g2[1] ^ g2[2] ^ g2[5] ^ g2[7] ^ g2[8] ^ g2[9];
        g1.copy_within(0..9, 1);
        g2.copy_within(0..9, 1);
        g1[0] = f1;
        g2[0] = f2;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first ten chips of a code as the octal number IS-GPS-200 Table 3-Ia lists.
    fn first_ten_octal(prn: u16) -> u32 {
        let c = ca_code_bits(prn).expect("valid PRN");
        c[..10]
            .iter()
            .fold(0u32, |acc, &b| (acc << 1) | u32::from(b))
    }

    #[test]
    fn first_chips_match_the_icd_table() {
        // IS-GPS-200 Table 3-Ia, "First 10 Chips C/A" (octal).
        let table: [(u16, u32); 8] = [
            (1, 0o1440),
            (2, 0o1620),
            (3, 0o1710),
            (4, 0o1744),
            (5, 0o1133),
            (10, 0o1504),
            (19, 0o1633),
            (32, 0o1712),
        ];
        for (prn, octal) in table {
            assert_eq!(first_ten_octal(prn), octal, "PRN {prn}");
        }
        assert!(ca_code_bits(0).is_none());
        assert!(ca_code_bits(33).is_none());
    }

    #[test]
    fn gold_code_correlation_properties() {
        // Balanced to one chip (512 ones), and the periodic cross- and auto-correlation
        // side lobes take only the three Gold values −1, −65, 63 (of 1023).
        let codes: Vec<Vec<i32>> = (1..=32)
            .map(|p| {
                ca_code_bits(p)
                    .expect("valid PRN")
                    .iter()
                    .map(|&b| 1 - 2 * i32::from(b))
                    .collect()
            })
            .collect();
        for c in &codes {
            assert_eq!(c.iter().filter(|&&x| x == -1).count(), 512);
        }
        for (i, a) in codes.iter().enumerate().take(6) {
            for b in codes.iter().skip(i) {
                for lag in (0..CA_CODE_LEN).step_by(37) {
                    let r: i32 = (0..CA_CODE_LEN)
                        .map(|k| a[k] * b[(k + lag) % CA_CODE_LEN])
                        .sum();
                    let same = std::ptr::eq(a, b) && lag == 0;
                    assert!(
                        same && r == 1023 || !same && [-1, -65, 63].contains(&r),
                        "r = {r}"
                    );
                }
            }
        }
    }
}
