//! The DTMB data-layer options of `hybridnav dtmb iq` (the GB 20600 transmitter profile).

use anyhow::Result;
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
