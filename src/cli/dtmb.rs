//! The DTMB data-layer options of `hybridnav dtmb iq` (the GB 20600 transmitter profile).

use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

/// `--payload FILE.ts --qam … --fec … --interleaver … --carriers …`.
#[derive(Debug, Clone, Default, Args)]
pub struct ProfileArgs {
    /// Carry this MPEG transport stream (188-byte packets) through the whole GB 20600
    /// transmitter; after its end the multiplex carries null packets (PID 0x1FFF).
    /// Without it but with a profile option, null packets only.
    #[arg(long, value_name = "FILE.ts")]
    pub payload: Option<PathBuf>,
    /// Data constellation: 4qam-nr, 4qam, 16qam, 32qam or 64qam (default 64qam when any
    /// data-layer option is given; without all of them the bodies are random 64QAM).
    #[arg(long)]
    pub qam: Option<String>,
    /// LDPC code rate: 0.4, 0.6 or 0.8 (default 0.6; 32QAM and 4QAM-NR take 0.8 only).
    #[arg(long)]
    pub fec: Option<String>,
    /// Time-interleaver depth M: 240 or 720 (default 720).
    #[arg(long)]
    pub interleaver: Option<usize>,
    /// Carriers: 3780 (TDS-OFDM) or 1 (single carrier) (default 3780).
    #[arg(long)]
    pub carriers: Option<usize>,
}

impl ProfileArgs {
    /// The data layer these options ask for, `None` when none is given.
    pub fn data_layer(&self) -> Result<Option<crate::dtmb::data_layer::DataLayer>> {
        Ok(crate::dtmb::data_layer::data_layer_from_options(
            self.payload.as_deref(),
            self.qam.as_deref(),
            self.fec.as_deref(),
            self.interleaver,
            self.carriers,
        )?)
    }
}

/// The options of `dtmb ber`.
pub struct BerArgs {
    pub qam: Option<String>,
    pub fec: Option<String>,
    pub interleaver: Option<usize>,
    pub carriers: Option<usize>,
    pub mode: Option<String>,
    pub snr_db: String,
    pub frames: usize,
    pub seed: Option<u64>,
    pub out: Option<PathBuf>,
    pub world: Option<PathBuf>,
    pub tower: Option<String>,
    pub trial: u64,
    pub at_s: f64,
    pub csi: String,
    pub no_doppler: bool,
    pub no_delay_drift: bool,
    pub true_timing: bool,
    pub cfo_hz: Option<f64>,
    pub cfo_rate_hz_per_s: Option<f64>,
    pub no_cfo_correction: bool,
    pub oscillator_ppm: Option<f64>,
    pub no_timing_tracking: bool,
}

/// The data-layer profile of `dtmb ber` from its options (each `None` takes the default:
/// 64QAM, rate 0.6, M = 240, C = 3780).
fn ber_profile(
    qam: Option<&str>,
    fec: Option<&str>,
    interleaver: Option<usize>,
    carriers: Option<usize>,
) -> Result<crate::dtmb::data_layer::Profile> {
    use crate::dtmb::data_layer::Profile;
    use crate::dtmb::frame::CarrierMode;
    use crate::dtmb::ldpc::CodeRate;
    use crate::dtmb::mapping::Constellation;
    let c: Constellation = qam
        .unwrap_or("64qam")
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--qam: {e}"))?;
    let rate: CodeRate = fec
        .unwrap_or("0.6")
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--fec: {e}"))?;
    let carrier = match carriers.unwrap_or(3780) {
        3780 => CarrierMode::Multi3780,
        1 => CarrierMode::Single,
        n => anyhow::bail!("--carriers must be 3780 or 1, got {n}"),
    };
    Ok(Profile::new(c, rate, interleaver.unwrap_or(240), carrier)?)
}

/// One measured curve: its points, printed as a table as they come, then the SNRs where
/// BER crosses 10⁻⁴ and PER 10⁻² (when the grid holds them), returned.
fn run_curve(
    grid: &[f64],
    mut measure: impl FnMut(f64) -> Result<crate::dtmb::ber::BerPoint>,
) -> Result<(Vec<crate::dtmb::ber::BerPoint>, Option<f64>, Option<f64>)> {
    use crate::dtmb::ber::crossing_snr_db;
    println!(
        "{:>8} {:>10} {:>10} {:>12} {:>10} {:>12} {:>10}",
        "snr_db", "packets", "pkt_err", "per", "bit_err", "ber", "cw_fail"
    );
    let mut points = Vec::with_capacity(grid.len());
    for &snr in grid {
        let p = measure(snr)?;
        println!(
            "{:>8.2} {:>10} {:>10} {:>12.3e} {:>10} {:>12.3e} {:>10}",
            p.snr_db,
            p.packets,
            p.packet_errors,
            p.per(),
            p.bit_errors,
            p.ber(),
            p.ldpc_failures
        );
        points.push(p);
    }
    let ber_pts: Vec<_> = points.iter().map(|p| (p.snr_db, p.ber(), p.bits)).collect();
    let per_pts: Vec<_> = points
        .iter()
        .map(|p| (p.snr_db, p.per(), p.packets))
        .collect();
    let mut cross = [None, None];
    for (i, (what, pts, target)) in [("BER", &ber_pts, 1e-4), ("PER", &per_pts, 1e-2)]
        .into_iter()
        .enumerate()
    {
        cross[i] = crossing_snr_db(pts, target);
        match cross[i] {
            Some(s) => println!("# {what} crosses {target:e} at {s:.2} dB"),
            None => println!("# {what} does not cross {target:e} inside the grid"),
        }
    }
    Ok((points, cross[0], cross[1]))
}

/// A CSV row's measured columns.
fn csv_columns(p: &crate::dtmb::ber::BerPoint) -> String {
    format!(
        "{},{},{},{},{:e},{},{},{:e},{},{},{:e}",
        p.snr_db,
        p.frames,
        p.packets,
        p.packet_errors,
        p.per(),
        p.bits,
        p.bit_errors,
        p.ber(),
        p.codewords,
        p.ldpc_failures,
        p.cwer()
    )
}

const CSV_HEADER: &str =
    "snr_db,frames,packets,packet_errors,per,bits,bit_errors,ber,codewords,ldpc_failures,cwer";

fn write_csv(out: &Option<PathBuf>, csv: &str, n: usize) -> Result<()> {
    if let Some(out) = out {
        crate::io::atomic::write_atomic(out, csv.as_bytes())
            .with_context(|| format!("cannot write {}", out.display()))?;
        eprintln!("wrote {n} points to {}", out.display());
    }
    Ok(())
}

/// `hybridnav dtmb ber`: one measured point per SNR, printed as a table and written as
/// CSV; then the SNRs where the curves cross BER 10⁻⁴ and PER 10⁻² when the grid holds
/// the crossing. With `--world`, through the tower's channel (see [`ber_world`]).
pub fn ber(a: &BerArgs) -> Result<()> {
    use crate::dtmb::ber::{measure_point, parse_snr_range};
    use crate::dtmb::pn::PnMode;
    if a.world.is_some() {
        return ber_world(a);
    }
    for (given, what) in [
        (a.tower.is_some(), "--tower"),
        (a.trial != 0, "--trial"),
        (a.at_s != 0.0, "--at-s"),
        (a.csi != "interpolated", "--csi"),
        (a.no_doppler, "--no-doppler"),
        (a.no_delay_drift, "--no-delay-drift"),
        (a.true_timing, "--true-timing"),
        (a.cfo_hz.is_some(), "--cfo-hz"),
        (a.cfo_rate_hz_per_s.is_some(), "--cfo-rate-hz-per-s"),
        (a.no_cfo_correction, "--no-cfo-correction"),
        (a.oscillator_ppm.is_some(), "--oscillator-ppm"),
        (a.no_timing_tracking, "--no-timing-tracking"),
    ] {
        if given {
            anyhow::bail!("{what} needs --world (without it the channel is white noise)");
        }
    }
    let profile = ber_profile(
        a.qam.as_deref(),
        a.fec.as_deref(),
        a.interleaver,
        a.carriers,
    )?;
    let mode: PnMode = a.mode.as_deref().unwrap_or("pn945").parse()?;
    let grid = parse_snr_range(&a.snr_db)?;
    let seed = a.seed.unwrap_or(1);
    println!(
        "# {} {} frames per point after a {}-frame interleaver delay, seed {}",
        profile.name(),
        a.frames,
        profile.interleaver_delay_frames(),
        seed
    );
    let (points, _, _) = run_curve(&grid, |snr| {
        Ok(measure_point(profile, mode, snr, a.frames, seed)?)
    })?;
    let mut csv = format!("{CSV_HEADER}\n");
    for p in &points {
        csv.push_str(&csv_columns(p));
        csv.push('\n');
    }
    write_csv(&a.out, &csv, points.len())
}

/// `dtmb ber --world`: the tower's paths at `--at-s` (as `dtmb iq --world` computes them
/// for that frame), as an impulse response at 7.56 Msps whose paths turn at their
/// Dopplers (unless `--no-doppler`), and one curve per
/// receiver (`--csi`). The SNR axis is the received frame power over the noise; the link
/// budget's SNR at that instant is printed beside each threshold as the margin.
fn ber_world(a: &BerArgs) -> Result<()> {
    use crate::dtmb::ber::parse_snr_range;
    use crate::dtmb::ber_channel::{
        acquisition_search_hz, cfo_range_hz, doppler_responses, frequency_response,
        measure_channel_point_clocked, measure_channel_point_synced_with_cfo,
        measure_channel_point_with_cfo, with_delay_drift, CfoEstimator, ChannelBer, Csi,
        Oscillator, CFO_LOOP_MEMORY_HEADERS, MAX_CFO_RATE_HZ_PER_S, SYNC_ADVANCE_SAMPLES,
    };
    use crate::dtmb::pn::PnMode;
    use crate::world::dtmb_iq::{tower_channel_at, DataLayerOverride, WorldIqRequest};
    let path = a.world.as_deref().unwrap_or(std::path::Path::new(""));
    let csis: Vec<Csi> = match a.csi.to_ascii_lowercase().as_str() {
        "both" => vec![Csi::Interpolated, Csi::Ideal],
        s => vec![s.parse()?],
    };
    let grid = parse_snr_range(&a.snr_db)?;
    if a.cfo_hz.is_some() && a.oscillator_ppm.is_some() {
        anyhow::bail!(
            "--cfo-hz (a pure carrier offset) and --oscillator-ppm (the oscillator: carrier \
             offset and sample clock) are alternatives: give one"
        );
    }
    if a.cfo_hz.is_some_and(|f| !f.is_finite()) {
        anyhow::bail!("--cfo-hz must be a finite frequency in Hz");
    }
    if let Some(r) = a.cfo_rate_hz_per_s {
        // The drift is a ramp of the pure carrier offset from --cfo-hz; an oscillator
        // (--oscillator-ppm, the world key) would drift its sample clock too, which is not
        // modelled, so the rate needs --cfo-hz.
        if a.cfo_hz.is_none() {
            anyhow::bail!(
                "--cfo-rate-hz-per-s needs --cfo-hz (the offset at the first frame, 0 for a \
                 drift from zero): the drift is a ramp of the pure carrier offset"
            );
        }
        if !(r.is_finite() && r.abs() <= MAX_CFO_RATE_HZ_PER_S) {
            anyhow::bail!(
                "--cfo-rate-hz-per-s must be a finite drift within ±{MAX_CFO_RATE_HZ_PER_S} \
                 Hz/s, got {r}"
            );
        }
    }
    if let Some(p) = a.oscillator_ppm {
        if !crate::dtmb::multipath::rx_oscillator_ppm_valid(p) {
            anyhow::bail!(
                "--oscillator-ppm must be a finite oscillator error within ±{} ppm, got {p}",
                Oscillator::MAX_PPM
            );
        }
    }
    let w = super::load_world(path).map_err(|e| anyhow::anyhow!("{e}"))?;
    let seed = a.seed.unwrap_or(w.file.montecarlo.seed);
    let req = WorldIqRequest {
        tower: a.tower.clone(),
        from_s: a.at_s,
        frames: 1,
        seed,
        trial: a.trial,
        data_layer: DataLayerOverride {
            payload: None,
            qam: a.qam.clone(),
            fec: a.fec.clone(),
            interleaver: a.interleaver,
            carriers: a.carriers,
        },
    };
    let ch = tower_channel_at(&w, &req)?;
    if let Some(m) = &a.mode {
        let m: PnMode = m.parse()?;
        if m != ch.mode {
            anyhow::bail!(
                "--mode {} contradicts tower {}'s {} (with --world the tower sets the mode)",
                m.name(),
                ch.tower,
                ch.mode.name()
            );
        }
    }
    if ch.paths.is_empty() {
        anyhow::bail!(
            "tower {} is blocked at {:.3} s (no path reaches the receiver): nothing to measure",
            ch.tower,
            a.at_s
        );
    }
    let profile = ber_profile(
        ch.qam.as_deref(),
        ch.fec.as_deref(),
        ch.interleaver,
        ch.carriers,
    )
    .with_context(|| format!("tower {}'s data layer", ch.tower))?;
    // The receiver's oscillator: --cfo-hz (a pure carrier offset), else --oscillator-ppm,
    // else the world's sensors.dtmb.rx_oscillator_ppm (carrier offset and sample clock).
    let (ppm, ppm_from) = match (a.cfo_hz, a.oscillator_ppm) {
        (Some(_), _) => (0.0, ""),
        (None, Some(p)) => (p, "--oscillator-ppm"),
        (None, None) => (
            ch.rx_oscillator_ppm,
            "the world's sensors.dtmb.rx_oscillator_ppm",
        ),
    };
    let mut osc = match a.cfo_hz {
        Some(f) => {
            let rate = a.cfo_rate_hz_per_s.unwrap_or(0.0);
            Oscillator {
                cfo_hz: f,
                correct: true,
                cfo_rate_hz_per_s: rate,
                // A receiver designed for a drifting offset tracks it; without a drift
                // the sum (the constant offset's maximum-likelihood estimate) as before.
                cfo_estimator: if rate != 0.0 {
                    CfoEstimator::Track
                } else {
                    CfoEstimator::Sum
                },
                ..Oscillator::default()
            }
        }
        None => Oscillator::from_ppm(ppm, ch.freq_hz)
            .map_err(|e| anyhow::anyhow!("{e} (from {ppm_from})"))?,
    };
    if a.no_cfo_correction {
        if a.cfo_hz.is_none() && osc.cfo_hz == 0.0 {
            anyhow::bail!(
                "--no-cfo-correction needs a carrier offset: --cfo-hz, --oscillator-ppm or \
                 the world's sensors.dtmb.rx_oscillator_ppm (without one there is no offset)"
            );
        }
        osc.correct = false;
    }
    if a.no_doppler && a.no_delay_drift {
        anyhow::bail!(
            "--no-delay-drift holds a moving receiver's delays while their phases turn; \
             --no-doppler already holds the whole channel static: give one"
        );
    }
    let with_doppler: Vec<(f64, num_complex::Complex64, f64)> = ch
        .paths
        .iter()
        .zip(&ch.dopplers_hz)
        .map(|(&(d, g), &f)| (d, g, if a.no_doppler { 0.0 } else { f }))
        .collect();
    let (h, groups) = doppler_responses(&with_doppler)?;
    // A receiver whose motion turns the paths also lengthens them: each group's delay
    // drifts at −f_D/f_c, and the estimating receivers follow the frame timing.
    let delay_drift = !a.no_delay_drift && groups.iter().any(|g| g.doppler_hz != 0.0);
    let groups = if delay_drift {
        with_delay_drift(&groups, ch.freq_hz)?
    } else {
        groups
    };
    if delay_drift {
        osc.track_timing = true;
    }
    if a.no_timing_tracking {
        if osc.sfo_ppm == 0.0 && !delay_drift {
            anyhow::bail!(
                "--no-timing-tracking needs a drifting frame timing: an oscillator error \
                 (--oscillator-ppm or the world's sensors.dtmb.rx_oscillator_ppm; --cfo-hz \
                 has no sample-clock offset) or a moving receiver's delay drift"
            );
        }
        osc.track_timing = false;
    }
    // The frame timing's drift a frame that the paths' motion adds, weighted by the
    // groups' energy (the response's centre of power moves at that rate).
    let (e_sum, e_rate) = groups.iter().fold((0.0, 0.0), |(e, r), g| {
        let eg: f64 = g.taps.iter().map(|x| f64::from(x.norm_sqr())).sum();
        (e + eg, r + eg * g.delay_rate)
    });
    let path_drift_per_frame = if e_sum > 0.0 {
        e_rate / e_sum * ch.mode.frame_len() as f64
    } else {
        0.0
    };
    let hk = frequency_response(&h);
    let (lo, hi) = hk.iter().fold((f64::MAX, f64::MIN), |(a, b), x| {
        (a.min(x.norm_sqr()), b.max(x.norm_sqr()))
    });
    println!(
        "# world {} tower {} ({}, {:.0} MHz) at {:.4} s, trial {}, seed {}: range {:.0} m, \
         {} path(s), link-budget SNR {:.2} dB",
        w.file.world.name,
        ch.tower,
        ch.mode.name(),
        ch.freq_hz * 1e-6,
        ch.at_s,
        a.trial,
        seed,
        ch.range_m,
        ch.paths.len(),
        ch.snr_db
    );
    for ((d, g), f) in ch.paths.iter().zip(&ch.dopplers_hz) {
        println!(
            "#   path: excess delay {:8.3} samples, power {:7.2} dB, phase {:6.3} rad, \
             Doppler {:8.3} Hz",
            d,
            10.0 * g.norm_sqr().log10(),
            g.arg(),
            f
        );
    }
    println!(
        "# channel: {} taps at 7.56 Msps ({}), |H_k|² at {:.4} s from {:.2} to {:.2} dB on \
         the 3780 carriers; receiver timing: {}",
        h.len(),
        if a.no_doppler {
            "static: --no-doppler".to_string()
        } else {
            format!(
                "each path turning at its Doppler, {} group(s)",
                groups.len()
            )
        },
        ch.at_s,
        10.0 * lo.max(1e-30).log10(),
        10.0 * hi.log10(),
        if a.true_timing {
            "the true frame start (--true-timing)".to_string()
        } else {
            format!(
                "acquired from the PN headers by the estimating receivers (frame sync, \
                 frames started {SYNC_ADVANCE_SAMPLES} samples before the first path), the \
                 true frame start for the genie"
            )
        }
    );
    if delay_drift {
        let rates: Vec<String> = groups
            .iter()
            .map(|g| format!("{:+.3e}", g.delay_rate))
            .collect();
        println!(
            "# delay drift: each path's delay follows its range rate, −f_D/f_c = {} s/s by \
             Doppler group, {:+.2e} samples a frame at the response's centre of power; {} \
             (--no-delay-drift holds the delays)",
            rates.join(", "),
            path_drift_per_frame,
            if osc.track_timing {
                "the estimating receivers follow the frame timing from the PN headers (the \
                 genie's stream holds the delays, which it knows)"
            } else {
                "the estimating receivers hold their starting timing (--no-timing-tracking)"
            }
        );
    }
    if osc.sfo_ppm != 0.0 {
        println!(
            "# receiver oscillator {:+.3} ppm (from {ppm_from}): the CFO below and a sample \
             clock of f_s(1 + ε), ε = {:.3e}, the frame timing drifting {:+.5} samples a \
             frame; {}",
            osc.sfo_ppm,
            osc.sfo_ppm * 1e-6,
            osc.sfo_ppm * 1e-6 * ch.mode.frame_len() as f64,
            if osc.track_timing {
                "tracked from the PN headers' channel estimates by the estimating receivers \
                 (the genie's stream has no clock offset: it knows the clock)"
            } else {
                "held at the starting timing (--no-timing-tracking)"
            }
        );
    }
    if a.cfo_hz.is_some() || osc.cfo_hz != 0.0 {
        let f = osc.cfo_hz;
        let range = cfo_range_hz(ch.mode);
        println!(
            "# receiver CFO {f:.1} Hz ({:.3} ppm at {:.0} MHz) on every path: {}{}",
            f / ch.freq_hz * 1e6,
            ch.freq_hz * 1e-6,
            if osc.correct && osc.cfo_rate_hz_per_s != 0.0 {
                format!(
                    "drifting {:+.1} Hz/s, followed from the PN headers by a type-2 tracking \
                     loop (memory {CFO_LOOP_MEMORY_HEADERS} headers; unambiguous within \
                     ±{range:.0} Hz of its prediction in {}), known to the genie",
                    osc.cfo_rate_hz_per_s,
                    ch.mode.name()
                )
            } else if osc.cfo_rate_hz_per_s != 0.0 {
                format!(
                    "drifting {:+.1} Hz/s, not corrected (--no-cfo-correction)",
                    osc.cfo_rate_hz_per_s
                )
            } else if osc.correct {
                format!(
                    "estimated from the PN headers and corrected (unambiguous within \
                     ±{range:.0} Hz in {}), known to the genie",
                    ch.mode.name()
                )
            } else {
                "not corrected (--no-cfo-correction)".to_string()
            },
            if osc.correct && f.abs() > range {
                format!(
                    " — beyond the range: the {} receiver's coarse frequency search \
                     (±{:.0} Hz) unwraps it",
                    if a.true_timing {
                        "true-timing"
                    } else {
                        "acquiring"
                    },
                    acquisition_search_hz(osc)
                )
            } else {
                String::new()
            }
        );
    }
    println!(
        "# {} {} frames per point after a {}-frame interleaver delay",
        profile.name(),
        a.frames,
        profile.interleaver_delay_frames()
    );
    let mut csv = format!("csi,{CSV_HEADER},link_snr_db\n");
    let mut n = 0;
    let mut per_cross = Vec::new();
    for csi in csis {
        println!("# CSI {}", csi.name());
        let cfg = ChannelBer {
            profile,
            mode: ch.mode,
            h: &h,
            doppler: &groups,
            csi,
            frames: a.frames,
            seed,
        };
        let synced = csi != Csi::Ideal && !a.true_timing;
        let clocked = csi != Csi::Ideal && (osc.sfo_ppm != 0.0 || delay_drift);
        let mut acquired = Vec::new();
        let mut tracks = Vec::new();
        let (points, _, per) = run_curve(&grid, |snr| {
            if clocked {
                let r = measure_channel_point_clocked(&cfg, osc, snr, synced).map_err(|e| {
                    anyhow::anyhow!(
                        "{e}{}",
                        if synced {
                            " (--true-timing gives the estimating receiver the true frame start)"
                        } else {
                            ""
                        }
                    )
                })?;
                acquired.extend(r.acquisition);
                tracks.push(r.timing);
                Ok(r.point)
            } else if synced {
                let (p, acq) =
                    measure_channel_point_synced_with_cfo(&cfg, osc, snr).map_err(|e| {
                        anyhow::anyhow!(
                        "{e} (--true-timing gives the estimating receiver the true frame start)"
                    )
                    })?;
                acquired.push(acq);
                Ok(p)
            } else {
                Ok(measure_channel_point_with_cfo(&cfg, osc, snr)?)
            }
        })?;
        if !acquired.is_empty() {
            // The receiver's frame start relative to the response's start (the true frame
            // start), over the grid's points.
            let (lo, hi) = acquired.iter().fold((i64::MAX, i64::MIN), |(l, h), x| {
                (l.min(x.offset_samples), h.max(x.offset_samples))
            });
            let wrong = acquired
                .iter()
                .filter(|x| x.frame_index.is_some_and(|i| i != x.true_frame_index))
                .count();
            println!(
                "# CSI {}: frame start acquired {lo}..{hi} samples from the true one over the \
                 {} points; frame number wrong at {wrong}",
                csi.name(),
                acquired.len(),
            );
        }
        if let Some(t) = tracks.last() {
            // The drift the receiver measured at the grid's last (highest-SNR) point.
            println!(
                "# CSI {}: frame timing drift measured {:+.5} ± {:.1e} samples a frame over {} \
                 frames (the clock's +ε·F {:+.5}, the paths' {:+.5}); frame start moved {} \
                 samples",
                csi.name(),
                t.drift_samples_per_frame,
                t.drift_std,
                t.frames,
                osc.sfo_ppm * 1e-6 * ch.mode.frame_len() as f64,
                path_drift_per_frame,
                t.shifted_samples
            );
        }
        if let Some(t) = per {
            println!(
                "# CSI {}: PER 1e-2 at {t:.2} dB; the link budget gives {:.2} dB, a margin of \
                 {:.2} dB",
                csi.name(),
                ch.snr_db,
                ch.snr_db - t
            );
        }
        per_cross.push((csi, per));
        for p in &points {
            csv.push_str(&format!(
                "{},{},{}\n",
                csi.name(),
                csv_columns(p),
                ch.snr_db
            ));
        }
        n += points.len();
    }
    if let [(_, Some(e)), (_, Some(i))] = per_cross.as_slice() {
        println!("# estimation loss at PER 1e-2: {:.2} dB", e - i);
    }
    write_csv(&a.out, &csv, n)
}
