//! The data layer of a GB 20600-2006 transmitter: a transport stream through the
//! scrambler (§4.2), BCH(762, 752) and LDPC (§4.3), bit-to-symbol mapping (§4.5), the
//! convolutional time interleaver (§4.6) and the system information (§4.7), to the 3780
//! logical symbols of each frame body that [`super::frame::BodyModulator::modulate_logical`]
//! frequency-interleaves and transforms (C = 3780) or sends as they are (C = 1).
//!
//! Symbols are produced in FEC groups: the codewords that fill one signal frame (4QAM: 1,
//! 16QAM: 2, 64QAM: 3) or two (32QAM: 5 codewords; 4QAM-NR: 1), with the scrambler
//! restarted at each signal frame's share of the group's transport-stream bytes (for
//! 32QAM in the middle of the third codeword), as the receiver dtmb-sdr descrambles. The interleaver's delay lines start filled with
//! constellation points of a fixed hash sequence (what a tower sent before the recording),
//! so the receiver's de-interleaver output is data from its `52·51·M`-th symbol on: the
//! first TS packet of the payload leaves a receiver after `51·M/72` frames (170 for
//! M = 240, 510 for M = 720).

use super::bch::{self, BCH_K};
use super::frame::{CarrierMode, SI_LEN};
use super::interleaver::TimeInterleaver;
use super::ldpc::{self, CodeRate, LdpcCode, CODEWORD_BITS, DELETED_BITS, Z};
use super::mapping::{labels_packed, nr_encode, Constellation};
use super::pn::BODY_LEN;
use super::scrambler::Scrambler;
use super::system_info;
use super::ts::{PacketSource, PACKET_LEN};
use super::DtmbError;
use num_complex::Complex32;

/// Data symbols of a frame body.
pub const DATA_SYMBOLS: usize = BODY_LEN - SI_LEN;

/// 64-bit words of a packed LDPC codeword (7488 = 117 · 64 bits).
const CODEWORD_WORDS: usize = CODEWORD_BITS / 64;

/// Appends bits to a packed stream: stream bit `k` is bit `k mod 64` of word `k / 64`.
struct BitWriter<'a> {
    out: &'a mut [u64],
    pos: usize,
    acc: u64,
    fill: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut [u64]) -> Self {
        Self {
            out,
            pos: 0,
            acc: 0,
            fill: 0,
        }
    }

    /// Appends the `n` (1 … 64) low bits of `v`, whose other bits are zero.
    #[inline(always)]
    fn push(&mut self, v: u64, n: u32) {
        debug_assert!(n == 64 || v >> n == 0);
        self.acc |= v << self.fill;
        let total = self.fill + n;
        if total >= 64 {
            self.out[self.pos] = self.acc;
            self.pos += 1;
            self.acc = if self.fill == 0 {
                0
            } else {
                v >> (64 - self.fill)
            };
            self.fill = total - 64;
        } else {
            self.fill = total;
        }
    }

    /// Appends the `n` (65 … 128) low bits of `v`.
    #[inline(always)]
    fn push128(&mut self, v: u128, n: u32) {
        self.push(v as u64, 64);
        self.push((v >> 64) as u64, n - 64);
    }

    /// Writes the last partial word; returns the bits written.
    fn finish(self) -> usize {
        if self.fill > 0 {
            self.out[self.pos] = self.acc;
        }
        self.pos * 64 + self.fill as usize
    }
}

/// The 128 stream bits from bit `start` on (`words` holds two words past them).
#[inline(always)]
fn read128(words: &[u64], start: usize) -> u128 {
    let (w, o) = (start / 64, (start % 64) as u32);
    let a = u128::from(words[w]) | (u128::from(words[w + 1]) << 64);
    if o == 0 {
        a
    } else {
        (a >> o) | (u128::from(words[w + 2]) << (128 - o))
    }
}

/// A transmission profile: constellation, code rate, interleaver depth and carrier mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Profile {
    /// Data constellation.
    pub constellation: Constellation,
    /// LDPC code rate.
    pub rate: CodeRate,
    /// Time-interleaver depth M: 240 (mode 1) or 720 (mode 2).
    pub interleaver_m: usize,
    /// Carrier mode.
    pub carrier: CarrierMode,
}

impl Profile {
    /// A checked profile: the standard defines 4QAM-NR and 32QAM with rate 0.8 only.
    ///
    /// # Errors
    /// [`DtmbError::InvalidParameter`] for a combination the standard lacks.
    pub fn new(
        constellation: Constellation,
        rate: CodeRate,
        interleaver_m: usize,
        carrier: CarrierMode,
    ) -> Result<Self, DtmbError> {
        if interleaver_m != 240 && interleaver_m != 720 {
            return Err(DtmbError::InvalidParameter {
                name: "interleaver",
                reason: format!("must be 240 or 720, got {interleaver_m}"),
            });
        }
        if matches!(constellation, Constellation::Qam4Nr | Constellation::Qam32)
            && rate != CodeRate::R08
        {
            return Err(DtmbError::InvalidParameter {
                name: "fec",
                reason: format!(
                    "GB 20600 defines {} with the 0.8 code only, not {}",
                    constellation.name(),
                    rate.name()
                ),
            });
        }
        Ok(Self {
            constellation,
            rate,
            interleaver_m,
            carrier,
        })
    }

    /// The system-information index of the profile (3..=24, as in the standard's table).
    pub fn si_index(&self) -> u8 {
        let r = match self.rate {
            CodeRate::R04 => 0,
            CodeRate::R06 => 1,
            CodeRate::R08 => 2,
        };
        let base = match self.constellation {
            Constellation::Qam4Nr => 3,
            Constellation::Qam4 => 5 + 2 * r,
            Constellation::Qam16 => 11 + 2 * r,
            Constellation::Qam32 => 17,
            Constellation::Qam64 => 19 + 2 * r,
        };
        base + u8::from(self.interleaver_m == 720)
    }

    /// Signal frames per FEC group: 2 for 32QAM and 4QAM-NR, else 1.
    pub fn frames_per_group(&self) -> usize {
        match self.constellation {
            Constellation::Qam32 | Constellation::Qam4Nr => 2,
            _ => 1,
        }
    }

    /// LDPC codewords per FEC group.
    pub fn codewords_per_group(&self) -> usize {
        self.frames_per_group() * DATA_SYMBOLS * self.constellation.ldpc_bits_per_symbol()
            / CODEWORD_BITS
    }

    /// TS packets carried per signal frame (on average over a group).
    pub fn packets_per_frame(&self) -> f64 {
        (self.codewords_per_group() * self.rate.ts_bytes_per_codeword() / PACKET_LEN) as f64
            / self.frames_per_group() as f64
    }

    /// Frames from a symbol's frame to the frame its de-interleaved copy leaves a
    /// receiver: `51·M/72`.
    pub fn interleaver_delay_frames(&self) -> usize {
        TimeInterleaver::latency_symbols(self.interleaver_m) / DATA_SYMBOLS
    }

    /// A readable name, e.g. `64QAM 0.6 M720 C3780 (SI 22)`.
    pub fn name(&self) -> String {
        format!(
            "{} {} M{} {} (SI {})",
            self.constellation.name().to_ascii_uppercase(),
            self.rate.name(),
            self.interleaver_m,
            match self.carrier {
                CarrierMode::Multi3780 => "C3780",
                CarrierMode::Single => "C1",
            },
            self.si_index()
        )
    }
}

/// The profile and packet source of `dtmb iq`'s options: `--payload FILE.ts --qam …
/// --fec … --interleaver … --carriers …`. `None` when none is given (the recording then
/// keeps random bodies); otherwise the missing options take the defaults 64QAM, 0.6,
/// 720, 3780 (the profile of index 22) and a missing payload means null packets only.
///
/// # Errors
/// [`DtmbError::InvalidParameter`] for a name that is not an option's value or a
/// combination the standard lacks; the payload's [`PacketSource::from_file`] errors.
pub fn data_layer_from_options(
    payload: Option<&std::path::Path>,
    qam: Option<&str>,
    fec: Option<&str>,
    interleaver: Option<usize>,
    carriers: Option<usize>,
) -> Result<Option<DataLayer>, DtmbError> {
    if payload.is_none()
        && qam.is_none()
        && fec.is_none()
        && interleaver.is_none()
        && carriers.is_none()
    {
        return Ok(None);
    }
    let bad = |name: &'static str, reason: String| DtmbError::InvalidParameter { name, reason };
    let constellation: Constellation = qam
        .unwrap_or("64qam")
        .parse()
        .map_err(|e| bad("--qam", e))?;
    let rate: CodeRate = fec.unwrap_or("0.6").parse().map_err(|e| bad("--fec", e))?;
    let carrier = match carriers.unwrap_or(3780) {
        3780 => CarrierMode::Multi3780,
        1 => CarrierMode::Single,
        c => return Err(bad("--carriers", format!("must be 3780 or 1, got {c}"))),
    };
    let profile = Profile::new(constellation, rate, interleaver.unwrap_or(720), carrier)?;
    let packets = match payload {
        Some(p) => PacketSource::from_file(p)?,
        None => PacketSource::null(),
    };
    Ok(Some(DataLayer::new(profile, packets)))
}

/// SplitMix64's output function, for the interleaver's initial contents.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The transmit data layer: TS packets in, frame bodies' logical symbols out.
pub struct DataLayer {
    profile: Profile,
    code: &'static LdpcCode,
    /// The constellation's points by label (unused labels zero), so a label masked to
    /// six bits indexes it without a bounds check.
    points: [Complex32; 64],
    packets: PacketSource,
    /// The symbol interleaver, or for 4QAM-NR the bit interleaver (the NR code follows it).
    /// Symbols pass it as their labels, one byte each rather than an eight-byte point
    /// (M = 720's delay lines are 0.95 MB instead of 7.6 MB, so they stay in cache); the
    /// interleaver only moves them, so mapping after it sends the same points.
    interleaver: Option<TimeInterleaver<u8>>,
    bit_interleaver: Option<TimeInterleaver<u8>>,
    frame_bits: Vec<u8>,
    /// The scrambler's sequence over one signal frame's share of the group's bytes (it
    /// restarts there).
    key: Vec<u8>,
    /// The current group's symbol labels and the next unread one.
    group: Vec<u8>,
    group_pos: usize,
    ts: Vec<u8>,
    /// 4QAM-NR: the group's LDPC bits, one per byte (the bit interleaver's input).
    bits: Vec<u8>,
    /// One codeword's message (BCH codewords) as a packed stream, two spare words.
    message: Vec<u64>,
    /// The group's LDPC codewords as a packed stream, one spare word.
    stream: Vec<u64>,
    /// The frame's data-symbol labels.
    data: Vec<u8>,
    frames: u64,
}

impl std::fmt::Debug for DataLayer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DataLayer")
            .field("profile", &self.profile)
            .field("frames", &self.frames)
            .finish_non_exhaustive()
    }
}

impl DataLayer {
    /// A data layer sending `packets` with `profile`.
    pub fn new(profile: Profile, packets: PacketSource) -> Self {
        let list = profile.constellation.points();
        let np = list.len() as u64;
        let mut points = [Complex32::default(); 64];
        points[..list.len()].copy_from_slice(&list);
        let nr = profile.constellation == Constellation::Qam4Nr;
        let interleaver = (!nr).then(|| {
            TimeInterleaver::new(profile.interleaver_m, false, move |i| {
                (mix64(i as u64 ^ 0x5eed) % np) as u8
            })
        });
        let bit_interleaver = nr.then(|| {
            TimeInterleaver::new(profile.interleaver_m, false, |i| {
                (mix64(i as u64 ^ 0x5eed) & 1) as u8
            })
        });
        let group_symbols = profile.frames_per_group() * DATA_SYMBOLS;
        let code = ldpc::code(profile.rate);
        let cw_per_group = profile.codewords_per_group();
        let per_frame =
            cw_per_group * profile.rate.ts_bytes_per_codeword() / profile.frames_per_group();
        Self {
            profile,
            code,
            points,
            packets,
            interleaver,
            bit_interleaver,
            frame_bits: vec![0; if nr { DATA_SYMBOLS } else { 0 }],
            key: Scrambler::keystream(per_frame),
            group: vec![0; group_symbols],
            group_pos: if nr {
                cw_per_group * CODEWORD_BITS
            } else {
                group_symbols
            },
            ts: vec![0; profile.rate.ts_bytes_per_codeword()],
            bits: vec![0; if nr { cw_per_group * CODEWORD_BITS } else { 0 }],
            message: vec![0; profile.rate.message_bits().div_ceil(64) + 2],
            stream: vec![0; cw_per_group * CODEWORD_WORDS + 1],
            data: vec![0; DATA_SYMBOLS],
            frames: 0,
        }
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// The packet source (its counts of payload and null packets sent).
    pub fn packets(&self) -> &PacketSource {
        &self.packets
    }

    /// Encodes the next FEC group into `self.group` (4QAM-NR: into `self.bits`).
    ///
    /// The bits stay packed 64 to a word from the transport stream to the mapper: the
    /// scrambler's key is XORed a byte at a time, BCH parity is computed a byte at a time,
    /// the message's 127-bit blocks are read out of the packed stream for the
    /// quasi-cyclic encoder, and each symbol's label is read out of the codewords'
    /// stream. The unit tests hold this path to the straightforward bit-per-byte chain.
    fn fill_group(&mut self) -> Result<(), DtmbError> {
        let rate = self.profile.rate;
        let per_cw = rate.ts_bytes_per_codeword();
        let per_frame = self.key.len();
        let (kb, cb) = (rate.message_blocks(), rate.parity_blocks());
        let message_bits = rate.message_bits();
        let mut blocks = [0u128; 48];
        let mut parity = [0u128; 35];
        for cw in 0..self.profile.codewords_per_group() {
            for p in self.ts.chunks_exact_mut(PACKET_LEN) {
                self.packets.next_packet(p)?;
            }
            // The scrambler restarts with every signal frame's share of the group's bytes
            // (for 32QAM 0.8, ten packets: in the middle of the third codeword).
            let (mut i, mut k) = (0, (cw * per_cw) % per_frame);
            while i < per_cw {
                let take = (per_cw - i).min(per_frame - k);
                for (b, &x) in self.ts[i..i + take].iter_mut().zip(&self.key[k..k + take]) {
                    *b ^= x;
                }
                i += take;
                k = (k + take) % per_frame;
            }
            let mut bch_parity = [0u16; 8];
            let bch_parity = &mut bch_parity[..rate.bch_per_codeword()];
            bch::parities_of_bytes(&self.ts, bch_parity);
            // The BCH codewords, first bit first: the 752 message bits (each byte most
            // significant bit first, which `from_be_bytes(..).reverse_bits()` puts first
            // in the word), then the 10 parity bits, highest power first.
            let mut w = BitWriter::new(&mut self.message);
            for (bytes, &r) in self.ts.chunks_exact(BCH_K / 8).zip(bch_parity.iter()) {
                for chunk in bytes.chunks(8) {
                    let mut b8 = [0u8; 8];
                    b8[..chunk.len()].copy_from_slice(chunk);
                    w.push(
                        u64::from_be_bytes(b8).reverse_bits(),
                        8 * chunk.len() as u32,
                    );
                }
                w.push(u64::from(r.reverse_bits() >> 6), 10);
            }
            let written = w.finish();
            debug_assert_eq!(written, message_bits);
            for (b, blk) in blocks[..kb].iter_mut().enumerate() {
                *blk = read128(&self.message, b * Z) & ((1u128 << Z) - 1);
            }
            self.code.encode_blocks(&blocks[..kb], &mut parity[..cb]);
            // The transmitted codeword: parity bits 5 … 127·C − 1, then the message.
            let out = &mut self.stream[cw * CODEWORD_WORDS..(cw + 1) * CODEWORD_WORDS];
            let mut w = BitWriter::new(out);
            w.push128(parity[0] >> DELETED_BITS, (Z - DELETED_BITS) as u32);
            for &p in &parity[1..cb] {
                w.push128(p, Z as u32);
            }
            let full = message_bits / 64;
            for &m in &self.message[..full] {
                w.push(m, 64);
            }
            if message_bits % 64 != 0 {
                w.push(self.message[full], (message_bits % 64) as u32);
            }
            let written = w.finish();
            debug_assert_eq!(written, CODEWORD_BITS);
        }
        if self.bit_interleaver.is_none() {
            let bps = self.profile.constellation.bits_per_symbol();
            labels_packed(bps, &self.stream, &mut self.group);
        } else {
            for (k, b) in self.bits.iter_mut().enumerate() {
                *b = (self.stream[k / 64] >> (k % 64)) as u8 & 1;
            }
        }
        self.group_pos = 0;
        Ok(())
    }

    /// Writes the next frame body's 3780 logical symbols (system information with index
    /// `si_index`, then the interleaved data in their positions) into `out`.
    ///
    /// # Errors
    /// [`DtmbError::Io`] when the payload cannot be read; [`DtmbError::BufferLength`] when
    /// `out` is not 3780 long.
    pub fn next_frame(&mut self, si_index: u8, out: &mut [Complex32]) -> Result<(), DtmbError> {
        if out.len() != BODY_LEN {
            return Err(DtmbError::BufferLength {
                what: "frame body",
                expected: BODY_LEN,
                got: out.len(),
            });
        }
        if self.bit_interleaver.is_some() {
            // 4QAM-NR: 3744 LDPC bits a frame through the bit interleaver, then each byte
            // (first bit most significant) as its 16-bit NR codeword on eight 4QAM symbols.
            let mut filled = 0;
            while filled < DATA_SYMBOLS {
                if self.group_pos == self.bits.len() {
                    self.fill_group()?;
                }
                let take = (DATA_SYMBOLS - filled).min(self.bits.len() - self.group_pos);
                self.frame_bits[filled..filled + take]
                    .copy_from_slice(&self.bits[self.group_pos..self.group_pos + take]);
                self.group_pos += take;
                filled += take;
            }
            if let Some(bil) = &mut self.bit_interleaver {
                bil.process(&mut self.frame_bits);
            }
            for (byte_bits, syms) in self
                .frame_bits
                .chunks_exact(8)
                .zip(self.data.chunks_exact_mut(8))
            {
                let byte = byte_bits.iter().fold(0u8, |a, &b| (a << 1) | (b & 1));
                let w = nr_encode(byte);
                for (t, s) in syms.iter_mut().enumerate() {
                    let b0 = (w >> (15 - 2 * t)) & 1;
                    let b1 = (w >> (14 - 2 * t)) & 1;
                    *s = (b0 | (b1 << 1)) as u8;
                }
            }
        } else {
            let mut filled = 0;
            while filled < DATA_SYMBOLS {
                if self.group_pos == self.group.len() {
                    self.fill_group()?;
                }
                let take = (DATA_SYMBOLS - filled).min(self.group.len() - self.group_pos);
                self.data[filled..filled + take]
                    .copy_from_slice(&self.group[self.group_pos..self.group_pos + take]);
                self.group_pos += take;
                filled += take;
            }
            if let Some(il) = &mut self.interleaver {
                il.process(&mut self.data);
            }
        }
        let mut si = [Complex32::default(); SI_LEN];
        super::frame::system_info_symbols(
            self.profile.carrier,
            system_info::vector(si_index),
            &mut si,
        );
        match self.profile.carrier {
            CarrierMode::Multi3780 => {
                // The data symbols fill the runs between the system-information positions.
                let mut l = 0;
                let mut d = 0;
                for (&p, &x) in system_info::C3780_POSITIONS.iter().zip(&si) {
                    let run = p - l;
                    for (o, &lab) in out[l..p].iter_mut().zip(&self.data[d..d + run]) {
                        *o = self.points[usize::from(lab & 63)];
                    }
                    out[p] = x;
                    d += run;
                    l = p + 1;
                }
                for (o, &lab) in out[l..].iter_mut().zip(&self.data[d..]) {
                    *o = self.points[usize::from(lab & 63)];
                }
            }
            CarrierMode::Single => {
                // C = 1 sends the system information at the start of the body with the
                // opposite chip polarity (0 → −(1+j)), as dtmb-sdr's C = 1 receiver
                // references it; the prefix 0000 thus looks like C = 3780's 1111.
                for (o, x) in out[..SI_LEN].iter_mut().zip(&si) {
                    *o = -x;
                }
                for (o, &lab) in out[SI_LEN..].iter_mut().zip(&self.data) {
                    *o = self.points[usize::from(lab & 63)];
                }
            }
        }
        self.frames += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dtmb::bch::BCH_N;
    use crate::dtmb::mapping::map_bits;

    /// The packed chain (key XOR, byte-wise BCH, carry-less LDPC, packed mapping) gives
    /// the straightforward bit-per-byte chain's symbols (4QAM-NR: LDPC bits) for every
    /// constellation and rate, over three groups of a pseudo-random transport stream.
    #[test]
    fn packed_chain_equals_the_bit_per_byte_chain() {
        for c in Constellation::ALL {
            for rate in CodeRate::ALL {
                let Ok(p) = Profile::new(c, rate, 240, CarrierMode::Multi3780) else {
                    continue;
                };
                let mut layer = DataLayer::new(p, PacketSource::pseudo_random(7));
                let mut packets = PacketSource::pseudo_random(7);
                let code = ldpc::code(rate);
                let per_cw = rate.ts_bytes_per_codeword();
                let cws = p.codewords_per_group();
                let per_frame = cws * per_cw / p.frames_per_group();
                let points = c.points();
                for group in 0..3 {
                    layer.fill_group().unwrap();
                    let mut bits = vec![0u8; cws * CODEWORD_BITS];
                    let mut scrambler = Scrambler::new();
                    let mut ts = vec![0u8; per_cw];
                    let mut message = vec![0u8; rate.message_bits()];
                    for cw in 0..cws {
                        for pk in ts.chunks_exact_mut(PACKET_LEN) {
                            packets.next_packet(pk).unwrap();
                        }
                        for (i, b) in ts.iter_mut().enumerate() {
                            if (cw * per_cw + i) % per_frame == 0 {
                                scrambler.reset();
                            }
                            let mut key = 0u8;
                            for _ in 0..8 {
                                key = (key << 1) | scrambler.next_bit();
                            }
                            *b ^= key;
                        }
                        for (blk, bytes) in ts.chunks_exact(BCH_K / 8).enumerate() {
                            let m: Vec<u8> = bytes
                                .iter()
                                .flat_map(|&b| (0..8).map(move |t| (b >> (7 - t)) & 1))
                                .collect();
                            bch::encode(&m, &mut message[blk * BCH_N..(blk + 1) * BCH_N]);
                        }
                        code.encode(
                            &message,
                            &mut bits[cw * CODEWORD_BITS..(cw + 1) * CODEWORD_BITS],
                        );
                    }
                    if c == Constellation::Qam4Nr {
                        let first = layer.bits.iter().zip(&bits).position(|(a, b)| a != b);
                        assert_eq!(first, None, "{} group {group}", p.name());
                    } else {
                        let mut want = vec![Complex32::default(); layer.group.len()];
                        map_bits(&points, c.bits_per_symbol(), &bits, &mut want);
                        let got: Vec<Complex32> = layer
                            .group
                            .iter()
                            .map(|&l| points[usize::from(l)])
                            .collect();
                        let first = got.iter().zip(&want).position(|(a, b)| a != b);
                        assert_eq!(first, None, "{} group {group}", p.name());
                    }
                }
            }
        }
    }

    #[test]
    fn profiles_have_the_standard_indices_and_groups() {
        let p = |c, r, m| Profile::new(c, r, m, CarrierMode::Multi3780).unwrap();
        assert_eq!(p(Constellation::Qam64, CodeRate::R06, 720).si_index(), 22);
        assert_eq!(p(Constellation::Qam4, CodeRate::R04, 240).si_index(), 5);
        assert_eq!(p(Constellation::Qam16, CodeRate::R08, 720).si_index(), 16);
        assert_eq!(p(Constellation::Qam32, CodeRate::R08, 240).si_index(), 17);
        assert_eq!(
            p(Constellation::Qam64, CodeRate::R06, 240).codewords_per_group(),
            3
        );
        assert_eq!(
            p(Constellation::Qam32, CodeRate::R08, 240).codewords_per_group(),
            5
        );
        assert_eq!(
            p(Constellation::Qam16, CodeRate::R04, 240).codewords_per_group(),
            2
        );
        assert_eq!(
            p(Constellation::Qam64, CodeRate::R06, 240).interleaver_delay_frames(),
            170
        );
        assert_eq!(
            p(Constellation::Qam64, CodeRate::R06, 720).interleaver_delay_frames(),
            510
        );
        assert!(Profile::new(
            Constellation::Qam32,
            CodeRate::R06,
            240,
            CarrierMode::Multi3780
        )
        .is_err());
    }
}
