//! BeiDou B1I ranging codes (BDS-SIS-ICD-B1I-3.0 §4.2.1, Table 4-1/4-2).
//!
//! Each code is the modulo-2 sum of two 11-stage sequences clocked at 2.046 Mchip/s,
//! truncated by one chip to 2046 chips (1 ms):
//!
//! ```text
//! G1(X) = 1 + X + X⁷ + X⁸ + X⁹ + X¹⁰ + X¹¹
//! G2(X) = 1 + X + X² + X³ + X⁴ + X⁵ + X⁸ + X⁹ + X¹¹
//! initial phases: G1 = G2 = 01010101010 (stages 1…11)
//! ```
//!
//! G2's phase per satellite is the modulo-2 sum of two (PRN 1–37) or three (PRN 38–63)
//! of its stages (the ICD's phase-assignment table; the same table GNSS-SDR's replica
//! uses). The output of each register is its stage 11.

/// Chips per B1I code period (1 ms).
pub const B1I_CODE_LEN: usize = 2046;

/// The G2 stages summed for PRN 1–63 (0 = unused third stage).
const G2_TAPS: [(u8, u8, u8); 63] = [
    (1, 3, 0),
    (1, 4, 0),
    (1, 5, 0),
    (1, 6, 0),
    (1, 8, 0),
    (1, 9, 0),
    (1, 10, 0),
    (1, 11, 0),
    (2, 7, 0),
    (3, 4, 0),
    (3, 5, 0),
    (3, 6, 0),
    (3, 8, 0),
    (3, 9, 0),
    (3, 10, 0),
    (3, 11, 0),
    (4, 5, 0),
    (4, 6, 0),
    (4, 8, 0),
    (4, 9, 0),
    (4, 10, 0),
    (4, 11, 0),
    (5, 6, 0),
    (5, 8, 0),
    (5, 9, 0),
    (5, 10, 0),
    (5, 11, 0),
    (6, 8, 0),
    (6, 9, 0),
    (6, 10, 0),
    (6, 11, 0),
    (8, 9, 0),
    (8, 10, 0),
    (8, 11, 0),
    (9, 10, 0),
    (9, 11, 0),
    (10, 11, 0),
    (2, 7, 1),
    (3, 4, 1),
    (3, 6, 1),
    (3, 8, 1),
    (3, 10, 1),
    (3, 11, 1),
    (4, 5, 1),
    (4, 9, 1),
    (5, 6, 1),
    (5, 8, 1),
    (5, 10, 1),
    (5, 11, 1),
    (6, 9, 1),
    (8, 9, 1),
    (9, 10, 1),
    (9, 11, 1),
    (3, 7, 2),
    (5, 7, 2),
    (7, 9, 2),
    (4, 5, 3),
    (4, 9, 3),
    (5, 6, 3),
    (5, 8, 3),
    (5, 10, 3),
    (5, 11, 3),
    (6, 9, 3),
];

/// The B1I code of `prn` (1–63) as bits (0/1), chip 0 first; `None` for other PRNs.
pub fn b1i_code_bits(prn: u16) -> Option<Vec<u8>> {
    let (a, b, c) = *G2_TAPS.get(usize::from(prn).checked_sub(1)?)?;
    // s[k] is stage k+1.
    let init = [0u8, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0];
    let (mut g1, mut g2) = (init, init);
    let stage = |r: &[u8; 11], k: u8| if k == 0 { 0 } else { r[usize::from(k) - 1] };
    let mut out = Vec::with_capacity(B1I_CODE_LEN);
    for _ in 0..B1I_CODE_LEN {
        let g2i = stage(&g2, a) ^ stage(&g2, b) ^ stage(&g2, c);
        out.push(g1[10] ^ g2i);
        // Feedback: the stages of each polynomial's terms X^k.
        let f1 = g1[0] ^ g1[6] ^ g1[7] ^ g1[8] ^ g1[9] ^ g1[10];
        let f2 = g2[0] ^ g2[1] ^ g2[2] ^ g2[3] ^ g2[4] ^ g2[7] ^ g2[8] ^ g2[10];
        g1.copy_within(0..10, 1);
        g2.copy_within(0..10, 1);
        g1[0] = f1;
        g2[0] = f2;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_balanced_and_nearly_orthogonal() {
        let codes: Vec<Vec<i32>> = (1..=63)
            .map(|p| {
                b1i_code_bits(p)
                    .expect("valid PRN")
                    .iter()
                    .map(|&x| 1 - 2 * i32::from(x))
                    .collect()
            })
            .collect();
        assert!(b1i_code_bits(0).is_none() && b1i_code_bits(64).is_none());
        for c in &codes {
            assert_eq!(c.len(), B1I_CODE_LEN);
            // A truncated Gold code: 1024 or 1023 ones of 2047, minus the dropped chip.
            let ones = c.iter().filter(|&&x| x == -1).count();
            assert!((1022..=1024).contains(&ones), "{ones}");
        }
        // Distinct codes, with cross-correlations far below the 2046 peak (Gold bound
        // 65/2047 before truncation, a few chips more after it).
        for i in 0..codes.len() {
            for j in (i + 1)..codes.len() {
                for lag in (0..B1I_CODE_LEN).step_by(97) {
                    let r: i32 = (0..B1I_CODE_LEN)
                        .map(|k| codes[i][k] * codes[j][(k + lag) % B1I_CODE_LEN])
                        .sum();
                    assert!(r.abs() < 200, "PRN {} vs {} lag {lag}: {r}", i + 1, j + 1);
                }
            }
        }
    }
}
