//! `hybridnav gnss position`: single-point positioning of a RINEX observation file
//! (`crate::spp` does the work), written as CSV.

use crate::gnss::rinex_nav::MaxAge;
use crate::gnss::rinex_obs;
use crate::io::atomic::write_atomic;
use crate::spp::Spp;
use anyhow::{Context, Result};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Options of `gnss position`.
#[derive(Debug, Args)]
pub struct GnssPositionArgs {
    /// RINEX 2.10/2.11 or 3.02–3.05 observation file.
    #[arg(long)]
    pub obs: PathBuf,
    /// RINEX 2 or 3 navigation file with the broadcast ephemerides of the same time.
    #[arg(long)]
    pub nav: PathBuf,
    /// Output CSV (written atomically); standard output when absent.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Largest |t − toe| of a usable ephemeris: seconds for every system (7200) or per
    /// system (gps=7200,bds=3600). Default: 2 h GPS, 1 h BeiDou.
    #[arg(long)]
    pub max_age: Option<String>,
}

/// The CSV header line.
pub const CSV_HEADER: &str = "t_gpst,gpst_week,gpst_tow_s,x_m,y_m,z_m,lat_deg,lon_deg,h_m,\
n_sats,pdop,clock_gps_m,clock_bds_m,residual_rms_m";

/// Runs `gnss position`.
///
/// # Errors
/// An unreadable or malformed observation or navigation file (named with its line), a
/// bad `--max-age`, or an output that cannot be written. Epochs without a fix are
/// counted on standard error, not errors.
pub fn run(a: &GnssPositionArgs) -> Result<()> {
    let mut nav = crate::gnss::rinex_nav::read_nav_file(&a.nav)?;
    if let Some(spec) = &a.max_age {
        nav.max_age = MaxAge::parse(spec)
            .map_err(anyhow::Error::msg)
            .context("--max-age")?;
    }
    for d in &nav.dropped {
        eprintln!("warning: {d}");
    }
    let mut reader = rinex_obs::open(&a.obs)?;
    let mut spp = Spp::new(&nav, reader.header())
        .map_err(anyhow::Error::msg)
        .with_context(|| a.obs.display().to_string())?;
    let mut csv = String::from(CSV_HEADER);
    csv.push('\n');
    let mut epoch = rinex_obs::ObsEpoch::default();
    let (mut n_epochs, mut n_fixes) = (0usize, 0usize);
    let mut first_failure: Option<String> = None;
    while reader.next_epoch(&mut epoch)? {
        n_epochs += 1;
        match spp.solve(&epoch) {
            Ok(f) => {
                n_fixes += 1;
                let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
                let _ = writeln!(
                    csv,
                    "{},{},{:.7},{:.4},{:.4},{:.4},{:.9},{:.9},{:.4},{},{:.3},{},{},{:.3}",
                    f.t_gpst,
                    f.t_gpst.week(),
                    f.t_gpst.tow_s(),
                    f.pos_ecef_m.x,
                    f.pos_ecef_m.y,
                    f.pos_ecef_m.z,
                    f.geodetic.lat_rad.to_degrees(),
                    f.geodetic.lon_rad.to_degrees(),
                    f.geodetic.h_m,
                    f.n_sats,
                    f.pdop,
                    opt(f.clock_gps_m),
                    opt(f.clock_bds_m),
                    f.residual_rms_m
                );
            }
            Err(why) => {
                first_failure.get_or_insert_with(|| {
                    format!("{}, line {}: {why}", a.obs.display(), epoch.line)
                });
            }
        }
    }
    eprintln!(
        "{}: {n_fixes} fixes from {n_epochs} epochs",
        a.obs.display()
    );
    if let Some(why) = first_failure {
        eprintln!(
            "note: {} epochs without a fix; the first: {why}",
            n_epochs - n_fixes
        );
    }
    write_out(a.out.as_deref(), &csv)
}

fn write_out(out: Option<&Path>, csv: &str) -> Result<()> {
    match out {
        Some(p) => write_atomic(p, csv.as_bytes()).with_context(|| format!("{}", p.display())),
        None => {
            use std::io::Write;
            std::io::stdout().lock().write_all(csv.as_bytes())?;
            Ok(())
        }
    }
}
