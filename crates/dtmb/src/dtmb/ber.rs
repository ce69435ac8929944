//! Bit and packet error rates of the GB 20600 data layer in additive white Gaussian
//! noise, measured with hybridnav's own data receiver ([`super::data_receiver`]).
//!
//! A pseudo-random transport stream ([`super::ts::pseudo_random_packet`]) goes through
//! the whole transmit data layer (scrambler, BCH, LDPC, mapping, time interleaver, system
//! information); every frame body's 3780 logical symbols get complex white Gaussian noise
//! of variance `σ²` per symbol, and the receiver (max-log demapping, de-interleaving,
//! normalised min-sum LDPC, BCH, descrambling) gives back packets that are compared bit
//! by bit with the ones sent.
//!
//! The SNR is the carrier-to-noise ratio over the 7.56 MHz band, as `dtmb iq --snr-db`
//! defines it: the whole frame's power (header included) over the noise,
//!
//! ```text
//! σ² = P_frame / 10^(SNR/10),   P_frame = (H ρ + 3780) / (H + 3780)
//! ```
//!
//! with the body at unit power, `H` the header length and `ρ` its power ratio
//! ([`PnMode::nominal_frame_power`]). Noise added to the logical symbols is the noise an
//! ideal receiver sees after removing the known header and transforming the body: the
//! body transform (the 3780-point DFT for C = 3780, none for C = 1) is unitary, so white
//! noise of variance `σ²` per time sample stays white with `σ²` per symbol. This is the
//! data layer's performance with ideal synchronisation and channel knowledge; a real
//! receiver adds its estimation losses on top.
//!
//! Random streams of `TrialRng::new(seed, 0)`: `dtmb/ber/payload` (the stream's key) and
//! `dtmb/ber/noise`. Every SNR point starts both afresh, so the points see the same
//! payload and the same unit-variance noise scaled by `σ` (common random numbers: a
//! curve is monotone up to the decoder's own behaviour, not the draw).

use super::data_layer::{DataLayer, Profile};
use super::data_receiver::DataReceiver;
use super::pn::{PnMode, BODY_LEN};
use super::ts::{pseudo_random_packet, PacketSource, PACKET_LEN};
use super::DtmbError;
use crate::core::TrialRng;
use num_complex::Complex32;
use rand::Rng;
use rand_distr::StandardNormal;

/// The counts of one SNR point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BerPoint {
    /// Carrier-to-noise ratio over the 7.56 MHz band (dB).
    pub snr_db: f64,
    /// Frames sent after the interleaver's delay.
    pub frames: usize,
    /// TS packets received and compared.
    pub packets: u64,
    /// Packets with at least one wrong bit.
    pub packet_errors: u64,
    /// TS bits compared (188 · 8 per packet).
    pub bits: u64,
    /// Wrong TS bits (after LDPC, BCH and descrambling).
    pub bit_errors: u64,
    /// LDPC codewords decoded.
    pub codewords: u64,
    /// Codewords whose decoder did not satisfy every check.
    pub ldpc_failures: u64,
}

impl BerPoint {
    /// Bit error rate after BCH (0 when nothing was compared).
    pub fn ber(&self) -> f64 {
        self.bit_errors as f64 / (self.bits.max(1)) as f64
    }

    /// Packet error rate.
    pub fn per(&self) -> f64 {
        self.packet_errors as f64 / (self.packets.max(1)) as f64
    }

    /// LDPC codeword failure rate.
    pub fn cwer(&self) -> f64 {
        self.ldpc_failures as f64 / (self.codewords.max(1)) as f64
    }

    /// A point at `snr_db` with nothing counted yet.
    pub(crate) fn empty(snr_db: f64, frames: usize) -> Self {
        Self {
            snr_db,
            frames,
            packets: 0,
            packet_errors: 0,
            bits: 0,
            bit_errors: 0,
            codewords: 0,
            ldpc_failures: 0,
        }
    }
}

/// Compares the receiver's packets with the pseudo-random stream of `key` that was sent,
/// counting into `p` (the receiver gives whole packets: a FEC group holds a whole number
/// of them).
pub(crate) fn count_packets(out: &[u8], key: u64, p: &mut BerPoint) {
    let mut expected = [0u8; PACKET_LEN];
    for got in out.chunks_exact(PACKET_LEN) {
        pseudo_random_packet(key, p.packets, &mut expected);
        let wrong: u32 = got
            .iter()
            .zip(&expected)
            .map(|(a, b)| (a ^ b).count_ones())
            .sum();
        p.packets += 1;
        p.bits += (PACKET_LEN * 8) as u64;
        p.bit_errors += u64::from(wrong);
        p.packet_errors += u64::from(wrong > 0);
    }
}

/// Most frames one point may measure.
pub const MAX_BER_FRAMES: usize = 1_000_000;

/// Measures one SNR point: `frames` frames after the interleaver's delay (the delay's
/// frames are sent too, and the receiver drops them).
///
/// # Errors
/// [`DtmbError::InvalidParameter`] for zero or too many frames or a non-finite SNR.
pub fn measure_point(
    profile: Profile,
    mode: PnMode,
    snr_db: f64,
    frames: usize,
    seed: u64,
) -> Result<BerPoint, DtmbError> {
    if frames == 0 || frames > MAX_BER_FRAMES {
        return Err(DtmbError::InvalidParameter {
            name: "frames",
            reason: format!("must lie in 1..={MAX_BER_FRAMES}, got {frames}"),
        });
    }
    if !snr_db.is_finite() {
        return Err(DtmbError::InvalidParameter {
            name: "snr_db",
            reason: format!("must be finite, got {snr_db}"),
        });
    }
    let streams = TrialRng::new(seed, 0);
    let key: u64 = streams.stream("dtmb/ber/payload").random();
    let mut noise = streams.stream("dtmb/ber/noise");
    let mut tx = DataLayer::new(profile, PacketSource::pseudo_random(key));
    let mut rx = DataReceiver::new(profile);
    let var = (mode.nominal_frame_power() / 10f64.powf(snr_db / 10.0)) as f32;
    let sigma = (var / 2.0).sqrt();
    let mut body = vec![Complex32::default(); BODY_LEN];
    let mut out = Vec::new();
    let mut p = BerPoint::empty(snr_db, frames);
    let total = profile.interleaver_delay_frames() + frames;
    for _ in 0..total {
        tx.next_frame(profile.si_index(), &mut body)?;
        for x in body.iter_mut() {
            let i: f32 = noise.sample(StandardNormal);
            let q: f32 = noise.sample(StandardNormal);
            *x += Complex32::new(i * sigma, q * sigma);
        }
        out.clear();
        rx.push_frame(&body, var, &mut out);
        count_packets(&out, key, &mut p);
    }
    let st = rx.stats();
    p.codewords = st.codewords;
    p.ldpc_failures = st.ldpc_failures;
    Ok(p)
}

/// The SNR grid `FROM:TO:STEP` (dB), both ends included (to a thousandth of a step).
///
/// # Errors
/// [`DtmbError::InvalidParameter`] for a malformed range, a non-positive step, `TO` below
/// `FROM`, or more than 1000 points.
pub fn parse_snr_range(s: &str) -> Result<Vec<f64>, DtmbError> {
    let bad = |reason: String| DtmbError::InvalidParameter {
        name: "--snr-db",
        reason,
    };
    let parts: Vec<&str> = s.split(':').collect();
    let num = |t: &str| -> Result<f64, DtmbError> {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(format!("{t:?} in {s:?} is not a finite number of dB")))
    };
    let (from, to, step) = match parts.as_slice() {
        [one] => {
            let v = num(one)?;
            (v, v, 1.0)
        }
        [a, b, c] => (num(a)?, num(b)?, num(c)?),
        _ => {
            return Err(bad(format!(
                "{s:?}: expected FROM:TO:STEP (e.g. 12:16:0.5) or one value"
            )))
        }
    };
    if step <= 0.0 || to < from {
        return Err(bad(format!(
            "{s:?}: the step must be positive and TO at least FROM"
        )));
    }
    let n = ((to - from) / step + 1e-3).floor() as usize + 1;
    if n > 1000 {
        return Err(bad(format!("{s:?} gives {n} points, more than 1000")));
    }
    Ok((0..n).map(|i| from + i as f64 * step).collect())
}

/// The SNR at which `rate` (per point, decreasing with SNR) first falls to `target`, by
/// linear interpolation of `log10(rate)` between the last point above and the first at
/// or below it; `None` when no point is at or below the target or the first point
/// already is (the crossing is outside the grid). A zero rate counts as
/// `0.5 / trials` (half an event) so that the logarithm stays finite.
pub fn crossing_snr_db(points: &[(f64, f64, u64)], target: f64) -> Option<f64> {
    let lg = |r: f64, n: u64| {
        if r > 0.0 {
            r.log10()
        } else {
            (0.5 / n.max(1) as f64).log10()
        }
    };
    let first = points.iter().position(|&(_, r, _)| r <= target)?;
    if first == 0 {
        return None;
    }
    let (s0, r0, n0) = points[first - 1];
    let (s1, r1, n1) = points[first];
    let (l0, l1, lt) = (lg(r0, n0), lg(r1, n1), target.log10());
    if (l0 - l1).abs() < 1e-12 {
        return Some(s1);
    }
    Some(s0 + (s1 - s0) * (l0 - lt) / (l0 - l1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dtmb::frame::CarrierMode;
    use crate::dtmb::ldpc::CodeRate;
    use crate::dtmb::mapping::Constellation;

    fn p64() -> Profile {
        Profile::new(
            Constellation::Qam64,
            CodeRate::R06,
            240,
            CarrierMode::Multi3780,
        )
        .unwrap()
    }

    /// At 30 dB every packet comes back, in order: the receiver's output is aligned
    /// with the stream sent, and the counts add up.
    #[test]
    fn high_snr_gives_every_packet_back() {
        let p = measure_point(p64(), PnMode::Pn945, 30.0, 3, 1).unwrap();
        assert_eq!((p.bit_errors, p.packet_errors, p.ldpc_failures), (0, 0, 0));
        // 64QAM 0.6: 3 codewords of 6 BCH blocks (752 bits) a frame = 9 packets a frame.
        assert_eq!(p.packets, 3 * 9, "{p:?}");
        assert_eq!(p.bits, p.packets * 188 * 8);
    }

    /// Far below the threshold almost every packet is wrong and about half the bits of a
    /// failed codeword's packets; the measurement is deterministic.
    #[test]
    fn low_snr_fails_and_is_deterministic() {
        let a = measure_point(p64(), PnMode::Pn945, 5.0, 2, 7).unwrap();
        assert!(a.per() > 0.9 && a.ber() > 0.01, "{a:?}");
        let b = measure_point(p64(), PnMode::Pn945, 5.0, 2, 7).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn snr_ranges_parse_and_crossings_interpolate() {
        assert_eq!(
            parse_snr_range("12:13:0.5").unwrap(),
            vec![12.0, 12.5, 13.0]
        );
        assert_eq!(parse_snr_range("7").unwrap(), vec![7.0]);
        assert!(parse_snr_range("1:0:1").is_err());
        assert!(parse_snr_range("1:2").is_err());
        assert!(parse_snr_range("a:2:1").is_err());
        let pts = [(10.0, 1.0, 100), (11.0, 1e-1, 100), (12.0, 1e-3, 100)];
        assert!((crossing_snr_db(&pts, 1e-2).unwrap() - 11.5).abs() < 1e-9);
        assert_eq!(crossing_snr_db(&pts[..1], 1e-2), None);
        assert_eq!(crossing_snr_db(&pts[2..], 1e-2), None);
    }
}
