//! `hybridnav gnss iq`: a world's GPS L1 C/A or BeiDou B1I satellites as one trial's
//! receiver hears them, written as a SigMF recording with its truth
//! (`crate::gnss::signal::scenario` does the work).

use super::load_world;
use crate::core::TrialRng;
use crate::gnss::link::Signal;
use crate::gnss::signal::baseband::SampleFormat;
use crate::gnss::signal::scenario::{record, validate, IqRequest, IqSinks, IqSummary, IqWorld};
use crate::io::atomic::{write_atomic, AtomicFile};
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use serde_json::json;
use std::path::{Path, PathBuf};

/// `hybridnav gnss …`.
#[derive(Debug, Subcommand)]
pub enum GnssCommand {
    /// Record a world's satellites at signal level: BASE.sigmf-data/.sigmf-meta (one
    /// annotation per satellite), BASE.truth.csv (receiver ECEF truth) and BASE.paths.csv
    /// (per satellite and path: code phase, Doppler, C/N0, excess delay, LOS/NLOS).
    Iq(GnssIqArgs),
    /// Single-point positioning of a RINEX observation file (GPS L1 C/A and BeiDou B1I
    /// code) with a RINEX navigation file: one weighted least-squares fix per epoch, as CSV
    /// (t_gpst, ECEF, latitude/longitude/height, satellites used, PDOP).
    Position(super::gnss_position::GnssPositionArgs),
}

/// Options of `gnss iq`.
#[derive(Debug, Args)]
pub struct GnssIqArgs {
    /// The world file.
    pub world: PathBuf,
    /// gps-l1ca or bds-b1i.
    #[arg(long)]
    pub signal: String,
    /// The trial whose trajectory, clock and draws the recording uses.
    #[arg(long, default_value_t = 0)]
    pub trial: u64,
    /// Start: receiver-clock seconds after the world's start.
    #[arg(long, default_value_t = 0.0)]
    pub from_s: f64,
    /// Length (s).
    #[arg(long)]
    pub duration_s: f64,
    /// Sample rate (complex samples per second); at least twice the chip rate.
    #[arg(long, default_value_t = 4.0e6)]
    pub rate_sps: f64,
    /// ci8, ci16 or cf32.
    #[arg(long, default_value = "ci8")]
    pub format: String,
    /// Master seed (default: the world's [montecarlo] seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output base name: BASE.sigmf-data, BASE.sigmf-meta, BASE.truth.csv, BASE.paths.csv.
    #[arg(long)]
    pub out: PathBuf,
}

fn with_ext(base: &Path, ext: &str) -> PathBuf {
    let mut s = base.as_os_str().to_owned();
    s.push(ext);
    PathBuf::from(s)
}

/// Runs `gnss iq`.
///
/// # Errors
/// Bad options or a request the world cannot satisfy (before any sample is written), or an
/// output that cannot be written.
pub fn run(cmd: GnssCommand) -> Result<()> {
    let a = match cmd {
        GnssCommand::Iq(a) => a,
        GnssCommand::Position(a) => return super::gnss_position::run(&a),
    };
    let signal = match a.signal.to_ascii_lowercase().as_str() {
        "gps-l1ca" => Signal::GpsL1Ca,
        "bds-b1i" => Signal::BdsB1i,
        other => bail!("--signal: unsupported signal '{other}'; expected gps-l1ca or bds-b1i"),
    };
    let Some(format) = SampleFormat::parse(&a.format) else {
        bail!(
            "--format: unknown sample format '{}'; expected ci8, ci16 or cf32",
            a.format
        );
    };
    let w = load_world(&a.world).map_err(|e| anyhow::anyhow!("{e}"))?;
    let seed = a.seed.unwrap_or(w.file.montecarlo.seed);
    let rng = TrialRng::new(seed, a.trial);
    let trajectory = w.build_trajectory(&rng).map_err(anyhow::Error::msg)?;
    let clock = w.receiver_clock(&rng);
    let gnss = w.file.sensors.gnss.clone().unwrap_or_default();
    let iq_world = IqWorld {
        nav: std::sync::Arc::clone(&w.nav),
        start: w.start,
        frame: &w.frame,
        trajectory: trajectory.as_ref(),
        clock: &clock,
        scene: w.scene.as_deref(),
        gnss: &gnss,
        rng,
        duration_s: w.duration_s,
        leap_seconds: w
            .nav
            .leap_seconds
            .unwrap_or(w.start.gpst_minus_utc_s() as i32),
    };
    let req = IqRequest {
        signal,
        from_s: a.from_s,
        duration_s: a.duration_s,
        rate_sps: a.rate_sps,
        format,
    };
    let sats = validate(&iq_world, &req)?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    }
    let mut data = AtomicFile::create(&with_ext(&a.out, ".sigmf-data"))?;
    let mut truth = AtomicFile::create(&with_ext(&a.out, ".truth.csv"))?;
    let mut paths = AtomicFile::create(&with_ext(&a.out, ".paths.csv"))?;
    let summary = record(
        &iq_world,
        &req,
        &sats,
        &mut IqSinks {
            data: &mut data,
            truth: &mut truth,
            paths: &mut paths,
        },
    )?;
    data.commit()?;
    truth.commit()?;
    paths.commit()?;
    let meta = meta_json(&w, &a, &req, seed, &summary);
    write_atomic(
        &with_ext(&a.out, ".sigmf-meta"),
        serde_json::to_string_pretty(&meta)?.as_bytes(),
    )?;
    eprintln!(
        "wrote {} samples ({} s at {:.3} Msps {}, {} satellites, {:.3} MHz) to {}.sigmf-data",
        summary.samples,
        a.duration_s,
        a.rate_sps * 1e-6,
        format.datatype(),
        summary.satellites.len(),
        summary.center_freq_hz * 1e-6,
        a.out.display()
    );
    Ok(())
}

fn meta_json(
    w: &crate::world::World,
    a: &GnssIqArgs,
    req: &IqRequest,
    seed: u64,
    s: &IqSummary,
) -> serde_json::Value {
    let start = w.start.add_seconds(req.from_s);
    let (y, mo, d, h, mi, sec, ns) = start.to_utc_calendar();
    let utc_datetime = format!(
        "{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{sec:02}.{:03}Z",
        ns / 1_000_000
    );
    let annotations: Vec<serde_json::Value> = s
        .satellites
        .iter()
        .map(|x| {
            json!({
                "core:sample_start": x.first_sample,
                "core:sample_count": x.sample_count,
                "core:label": x.sat.to_string(),
                "hybridnav:prn": x.sat.number,
                "hybridnav:cn0_dbhz": (x.cn0_dbhz * 100.0).round() / 100.0,
                "hybridnav:paths": x.max_paths,
                "hybridnav:nlos": x.nlos,
            })
        })
        .collect();
    json!({
        "global": {
            "core:datatype": req.format.datatype(),
            "core:sample_rate": req.rate_sps,
            "core:version": "1.0.0",
            "core:recorder": "hybridnav",
            "core:description": format!(
                "{} baseband of world '{}' (trial {}, seed {}) generated by hybridnav",
                a.signal, w.file.world.name, a.trial, seed
            ),
            "hybridnav:world": w.path.display().to_string(),
            "hybridnav:signal": a.signal,
            "hybridnav:trial": a.trial,
            "hybridnav:seed": seed,
            "hybridnav:noise_power": 1.0,
        },
        "captures": [{
            "core:sample_start": 0,
            "core:frequency": s.center_freq_hz,
            "core:datetime": utc_datetime,
            "hybridnav:start_gpst": start.to_iso_gpst(),
        }],
        "annotations": annotations,
    })
}
