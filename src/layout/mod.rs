//! Transmitter-layout design: coverage, geometry and predicted accuracy over a grid, and
//! the choice of new transmitter sites.

use std::path::PathBuf;

/// `hybridnav layout` options.
#[derive(Debug, clap::Args)]
pub struct LayoutArgs {
    /// The world file.
    pub world: PathBuf,
    /// Grid spacing (m).
    #[arg(long, default_value_t = 10.0)]
    pub grid: f64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `hybridnav layout`.
///
/// # Errors
/// Every user-facing failure, with what was expected.
pub fn run(args: &LayoutArgs) -> anyhow::Result<()> {
    let _ = args;
    anyhow::bail!("layout: not yet written")
}
