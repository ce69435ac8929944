//! The energy-dispersal scrambler of GB 20600-2006 §4.2: a 15-stage LFSR with generator
//! polynomial `1 + x¹⁴ + x¹⁵` and initial state `100101010000000` (stages 1 to 15), whose
//! output is added modulo 2 to the transport-stream bits (most significant bit of each byte
//! first). The scrambler restarts at the first bit of every FEC group (the codewords that
//! fill one signal frame, or two for 32QAM and 4QAM-NR), which is where the receiver
//! dtmb-sdr restarts its descrambler.

/// The scrambler state after reset: stage `n` (1-based) is bit `n − 1`.
const INITIAL_STATE: u16 = 0b000_0000_1010_1001;

/// The energy-dispersal LFSR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scrambler {
    state: u16,
}

impl Default for Scrambler {
    fn default() -> Self {
        Self::new()
    }
}

impl Scrambler {
    /// A scrambler in its initial state.
    pub fn new() -> Self {
        Self {
            state: INITIAL_STATE,
        }
    }

    /// Returns to the initial state.
    pub fn reset(&mut self) {
        self.state = INITIAL_STATE;
    }

    /// The next sequence bit: the sum of stages 14 and 15, which is also shifted in.
    #[inline]
    pub fn next_bit(&mut self) -> u8 {
        let b = ((self.state >> 13) ^ (self.state >> 14)) & 1;
        self.state = ((self.state << 1) & 0x7fff) | b;
        b as u8
    }

    /// The next eight sequence bits as a byte, first bit in the most significant place.
    #[inline]
    pub fn next_byte(&mut self) -> u8 {
        let mut v = 0u8;
        for _ in 0..8 {
            v = (v << 1) | self.next_bit();
        }
        v
    }

    /// The first `len` bytes of the sequence after a reset. The scrambler restarts at
    /// every signal frame's share of the transport stream, so the data layer XORs each
    /// frame's bytes with this one precomputed key instead of clocking the register bit
    /// by bit.
    pub fn keystream(len: usize) -> Vec<u8> {
        let mut s = Scrambler::new();
        (0..len).map(|_| s.next_byte()).collect()
    }

    /// Scrambles (or descrambles: the operation is its own inverse) `bytes` in place.
    pub fn apply(&mut self, bytes: &mut [u8]) {
        for b in bytes {
            *b ^= self.next_byte();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sequence is an m-sequence of period 2¹⁵ − 1 (the polynomial is primitive), and
    /// its first bits follow from the initial state by hand: stages 14 and 15 are 0 for the
    /// first bits until the initial ones reach them (stage 8 → 15 after 7 shifts...).
    #[test]
    fn period_is_32767_and_the_start_follows_the_recurrence() {
        let mut s = Scrambler::new();
        let first: Vec<u8> = (0..40).map(|_| s.next_bit()).collect();
        // Recurrence a[n] = a[n−14] ⊕ a[n−15] over the initial stages read as a[−1] = stage 1,
        // …, a[−15] = stage 15.
        let init = [1u8, 0, 0, 1, 0, 1, 0, 1, 0, 0, 0, 0, 0, 0, 0];
        let mut a: Vec<u8> = init.iter().rev().copied().collect();
        for n in 15..55 {
            let v = a[n - 14] ^ a[n - 15];
            a.push(v);
        }
        assert_eq!(&a[15..], &first[..]);
        let mut s = Scrambler::new();
        let start = s;
        let mut period = 0;
        loop {
            s.next_bit();
            period += 1;
            if s == start {
                break;
            }
        }
        assert_eq!(period, 32767);
    }

    #[test]
    fn descrambling_inverts() {
        let data: Vec<u8> = (0..=255).collect();
        let mut x = data.clone();
        Scrambler::new().apply(&mut x);
        assert_ne!(x, data);
        Scrambler::new().apply(&mut x);
        assert_eq!(x, data);
    }
}
