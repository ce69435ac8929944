//! The convolutional time interleaver of GB 20600-2006 §4.6: the data-symbol stream is
//! dealt in turn to B = 52 branches; branch `b` delays its symbols by `b·M` of its own
//! visits (M = 240 in mode 1, 720 in mode 2), so every symbol is delayed `52·51·M`
//! symbols end to end after the de-interleaver's complementary `(51 − b)·M`. A frame body's
//! 3744 data symbols are 72 turns of the 52 branches, so each frame starts on branch 0,
//! which is how the receiver dtmb-sdr de-interleaves (phase 0).

use num_complex::Complex32;

/// Number of branches.
pub const BRANCHES: usize = 52;

/// The time interleaver (or, with `deinterleave`, its inverse), of symbols or (4QAM-NR,
/// whose interleaver runs on the LDPC bits before the NR code) of bits.
#[derive(Clone, Debug)]
pub struct TimeInterleaver<T = Complex32> {
    /// All branches' delay lines, branch after branch.
    line: Vec<T>,
    /// Start of each branch's line in `line`, and its length.
    offset: [usize; BRANCHES],
    len: [usize; BRANCHES],
    /// The position of each branch's oldest symbol.
    pos: [usize; BRANCHES],
    /// The branch of the next input symbol.
    branch: usize,
}

impl TimeInterleaver<Complex32> {
    /// The end-to-end delay of interleaver and de-interleaver in symbols: `52·51·M`.
    pub fn latency_symbols(m: usize) -> usize {
        BRANCHES * (BRANCHES - 1) * m
    }
}

impl<T: Copy> TimeInterleaver<T> {
    /// An interleaver of depth `m` (240 or 720) with delay lines filled by `fill(i)`:
    /// the symbols "sent before" the stream starts.
    pub fn new(m: usize, deinterleave: bool, mut fill: impl FnMut(usize) -> T) -> Self {
        let mut offset = [0usize; BRANCHES];
        let mut len = [0usize; BRANCHES];
        let mut total = 0;
        for b in 0..BRANCHES {
            let d = if deinterleave { BRANCHES - 1 - b } else { b };
            offset[b] = total;
            len[b] = d * m;
            total += d * m;
        }
        Self {
            line: (0..total).map(&mut fill).collect(),
            offset,
            len,
            pos: [0; BRANCHES],
            branch: 0,
        }
    }

    /// Passes `data` through in place.
    pub fn process(&mut self, data: &mut [T]) {
        if self.branch == 0 && data.len() % BRANCHES == 0 {
            // Whole turns of the commutator (a frame body's 72): each branch's symbols
            // are swapped with its delay line in one sequential sweep, branch after
            // branch, which reads the long lines in order instead of hopping between
            // 52 of them for every symbol. The same swaps in another order: equal output.
            let turns = data.len() / BRANCHES;
            for b in 0..BRANCHES {
                let n = self.len[b];
                if n == 0 {
                    continue;
                }
                let line = &mut self.line[self.offset[b]..self.offset[b] + n];
                let mut p = self.pos[b];
                for t in 0..turns {
                    std::mem::swap(&mut data[t * BRANCHES + b], &mut line[p]);
                    p = if p + 1 == n { 0 } else { p + 1 };
                }
                self.pos[b] = p;
            }
            return;
        }
        for x in data {
            let b = self.branch;
            let n = self.len[b];
            if n != 0 {
                let i = self.offset[b] + self.pos[b];
                std::mem::swap(x, &mut self.line[i]);
                self.pos[b] = if self.pos[b] + 1 == n {
                    0
                } else {
                    self.pos[b] + 1
                };
            }
            self.branch = if b + 1 == BRANCHES { 0 } else { b + 1 };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interleaver_then_deinterleaver_is_a_pure_delay() {
        let m = 3;
        let mut tx = TimeInterleaver::new(m, false, |_| Complex32::new(-1.0, 0.0));
        let mut rx = TimeInterleaver::new(m, true, |_| Complex32::new(-1.0, 0.0));
        let n = 20_000;
        let mut x: Vec<Complex32> = (0..n).map(|i| Complex32::new(i as f32, 0.0)).collect();
        tx.process(&mut x);
        // The interleaver alone spreads neighbours: branch b's symbol leaves b·M turns later.
        assert_eq!(x[52 * 10 + 1].re, (52 * (10 - m) + 1) as f32);
        rx.process(&mut x);
        let d = TimeInterleaver::latency_symbols(m);
        for (i, v) in x.iter().enumerate().skip(d) {
            assert_eq!(v.re, (i - d) as f32);
        }
    }

    /// Frames of whole turns (the branch-major sweep) give what the symbol-by-symbol
    /// commutator gives, for interleaver and de-interleaver, including a stream that
    /// switches between the two paths.
    #[test]
    fn whole_turns_equal_symbol_by_symbol() {
        for de in [false, true] {
            let mut a = TimeInterleaver::new(5, de, |i| i as u32 + 1_000_000);
            let mut b = a.clone();
            let mut next = 0u32;
            for len in [52 * 72, 52 * 3, 7, 45, 52 * 72, 52 * 10, 52] {
                let x: Vec<u32> = (0..len as u32).map(|i| next + i).collect();
                next += len as u32;
                let mut fast = x.clone();
                a.process(&mut fast);
                let mut slow = x;
                for s in slow.iter_mut() {
                    b.process(std::slice::from_mut(s));
                }
                assert_eq!(fast, slow, "deinterleave {de}, len {len}");
            }
        }
    }
}
