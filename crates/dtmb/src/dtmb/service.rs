//! Where a viewer can watch a DTMB channel: the decoding threshold of each GB 20600
//! profile in white Gaussian noise, for the layout's *service coverage* map (beside its
//! ranging maps, which ask where a receiver can range on the same signal).
//!
//! The threshold of a profile is the SNR (over 7.56 MHz, on the whole frame's power, as
//! `dtmb iq --snr-db` and `dtmb ber` define it) at which the packet error rate of
//! hybridnav's own data receiver ([`crate::dtmb::data_receiver`]: max-log demapping,
//! normalised min-sum LDPC, BCH) crosses [`SERVICE_PER`], 1 %. The waterfall is steep —
//! every profile goes from PER ≈ 1 to 0 within about 0.6 dB — so a stricter criterion
//! moves a threshold by a few tenths of a dB. The table is measured, not taken from a
//! publication (no published GB 20600 AWGN table was found; docs/validation.md):
//! `hybridnav dtmb ber --qam Q --fec F --snr-db A:B:0.1 --frames 60` (PN945, M = 240,
//! C = 3780, seed 1, 2026-12-03), the crossing interpolated log-linearly
//! ([`crate::dtmb::ber::crossing_snr_db`]) and rounded to the grid's 0.1 dB. The 64QAM 0.6
//! entry agrees with dtmb-sdr's complete receiver within 0.3 dB (docs/validation.md). A
//! test re-measures every entry with other noise. The receiver's synchronisation and
//! channel estimate are ideal and the channel is white noise, so a multipath or fading
//! link needs more: the service map marks where a link's SNR clears the AWGN threshold,
//! an optimistic service area.

use crate::dtmb::ldpc::CodeRate;
use crate::dtmb::mapping::Constellation;

/// The packet error rate that defines a profile's threshold.
pub const SERVICE_PER: f64 = 1e-2;

/// The profile `dtmb iq` and a `[[transmitter]]` without data-layer keys stand for: 64QAM,
/// rate 0.6 (the defaults of `--qam` and `--fec`).
pub const DEFAULT_PROFILE: (Constellation, CodeRate) = (Constellation::Qam64, CodeRate::R06);

/// The AWGN decoding threshold (dB) of `constellation` at `rate`, C = 3780; `None` for a
/// combination GB 20600 does not define (4QAM-NR and 32QAM exist at rate 0.8 only).
pub fn awgn_threshold_db(constellation: Constellation, rate: CodeRate) -> Option<f64> {
    use CodeRate::{R04, R06, R08};
    use Constellation::{Qam16, Qam32, Qam4, Qam4Nr, Qam64};
    // Measured 2026-12-03 (module docs); one decimal, the grid's step.
    Some(match (constellation, rate) {
        (Qam4Nr, R08) => 2.3,
        (Qam4, R04) => 2.0,
        (Qam4, R06) => 3.9,
        (Qam4, R08) => 6.1,
        (Qam16, R04) => 7.3,
        (Qam16, R06) => 9.7,
        (Qam16, R08) => 12.4,
        (Qam32, R08) => 15.5,
        (Qam64, R04) => 11.9,
        (Qam64, R06) => 14.7,
        (Qam64, R08) => 17.9,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dtmb::ber::measure_point;
    use crate::dtmb::data_layer::Profile;
    use crate::dtmb::CarrierMode;
    use crate::dtmb::PnMode;

    /// Every entry is a threshold of the receiver as it is now, measured with noise the
    /// table did not see (seed 2): 0.4 dB below it at least one packet in ten is lost,
    /// 0.4 dB above it fewer than one in a hundred.
    #[test]
    fn every_threshold_is_where_the_packet_error_rate_falls_through_one_percent() {
        let mut checked = 0;
        for c in Constellation::ALL {
            for r in CodeRate::ALL {
                let Some(th) = awgn_threshold_db(c, r) else {
                    assert!(Profile::new(c, r, 240, CarrierMode::Multi3780).is_err());
                    continue;
                };
                let p = Profile::new(c, r, 240, CarrierMode::Multi3780).unwrap();
                let below = measure_point(p, PnMode::Pn945, th - 0.4, 20, 2).unwrap();
                let above = measure_point(p, PnMode::Pn945, th + 0.4, 20, 2).unwrap();
                assert!(
                    below.per() >= 0.1,
                    "{c:?} {r:?}: PER {} at {} dB",
                    below.per(),
                    th - 0.4
                );
                assert!(
                    above.per() < SERVICE_PER,
                    "{c:?} {r:?}: PER {} at {} dB",
                    above.per(),
                    th + 0.4
                );
                checked += 1;
            }
        }
        assert_eq!(
            checked, 11,
            "GB 20600 defines eleven constellation and rate pairs"
        );
    }
}
