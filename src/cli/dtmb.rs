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
    pub qam: String,
    pub fec: String,
    pub interleaver: usize,
    pub carriers: usize,
    pub mode: String,
    pub snr_db: String,
    pub frames: usize,
    pub seed: u64,
    pub out: Option<PathBuf>,
}

/// `hybridnav dtmb ber`: one measured point per SNR, printed as a table and written as
/// CSV; then the SNRs where the curves cross BER 10⁻⁴ and PER 10⁻² when the grid holds
/// the crossing.
pub fn ber(a: &BerArgs) -> Result<()> {
    use crate::dtmb::ber::{crossing_snr_db, measure_point, parse_snr_range};
    use crate::dtmb::data_layer::Profile;
    use crate::dtmb::frame::CarrierMode;
    use crate::dtmb::ldpc::CodeRate;
    use crate::dtmb::mapping::Constellation;
    use crate::dtmb::pn::PnMode;
    let c: Constellation = a
        .qam
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--qam: {e}"))?;
    let rate: CodeRate = a
        .fec
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--fec: {e}"))?;
    let carrier = match a.carriers {
        3780 => CarrierMode::Multi3780,
        1 => CarrierMode::Single,
        n => anyhow::bail!("--carriers must be 3780 or 1, got {n}"),
    };
    let profile = Profile::new(c, rate, a.interleaver, carrier)?;
    let mode: PnMode = a.mode.parse()?;
    let grid = parse_snr_range(&a.snr_db)?;
    println!(
        "# {} {} frames per point after a {}-frame interleaver delay, seed {}",
        profile.name(),
        a.frames,
        profile.interleaver_delay_frames(),
        a.seed
    );
    println!(
        "{:>8} {:>10} {:>10} {:>12} {:>10} {:>12} {:>10}",
        "snr_db", "packets", "pkt_err", "per", "bit_err", "ber", "cw_fail"
    );
    let mut csv = String::from(
        "snr_db,frames,packets,packet_errors,per,bits,bit_errors,ber,codewords,ldpc_failures,cwer\n",
    );
    let mut points = Vec::with_capacity(grid.len());
    for &snr in &grid {
        let p = measure_point(profile, mode, snr, a.frames, a.seed)?;
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
        csv.push_str(&format!(
            "{},{},{},{},{:e},{},{},{:e},{},{},{:e}\n",
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
        ));
        points.push(p);
    }
    let ber_pts: Vec<_> = points.iter().map(|p| (p.snr_db, p.ber(), p.bits)).collect();
    let per_pts: Vec<_> = points
        .iter()
        .map(|p| (p.snr_db, p.per(), p.packets))
        .collect();
    for (what, pts, target) in [("BER", &ber_pts, 1e-4), ("PER", &per_pts, 1e-2)] {
        match crossing_snr_db(pts, target) {
            Some(s) => println!("# {what} crosses {target:e} at {s:.2} dB"),
            None => println!("# {what} does not cross {target:e} inside the grid"),
        }
    }
    if let Some(out) = &a.out {
        crate::io::atomic::write_atomic(out, csv.as_bytes())
            .with_context(|| format!("cannot write {}", out.display()))?;
        eprintln!("wrote {} points to {}", points.len(), out.display());
    }
    Ok(())
}
