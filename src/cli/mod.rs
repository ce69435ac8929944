//! The command line: clap definitions turned into validated actions in one place.

// The clap doc comments are the CLI's help text, where `[montecarlo]` and
// `[[transmitter]]` name world-file tables, not Rust items; clap prints them verbatim,
// so they cannot be escaped for rustdoc without showing the escapes in `--help`.
#![allow(rustdoc::broken_intra_doc_links)]

mod dtmb;
mod ephemeris;
mod gnss_iq;
mod gnss_position;

use crate::core::GpsTime;
use crate::io::atomic::write_atomic;
use crate::layout::metrics::ClockModel;
use crate::layout::place::Objective;
use crate::layout::LayoutRequest;
use crate::montecarlo::store::{MergePlan, RunDir, Shard, Takeover};
use crate::montecarlo::{merge_into, run_into_with, OutputSet, RunOptions};
use anyhow::{bail, Context, Result};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};

/// hybridnav: discrete-event, signal-level simulator for GNSS + terrestrial-signal +
/// inertial positioning.
#[derive(Debug, Parser)]
#[command(name = "hybridnav", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the Monte Carlo trials of a world and write OUT/summary.json.
    Run(RunArgs),
    /// Combine the output directories of a sharded run (`run --shard K/N`) into the
    /// outputs the unsharded run would have written.
    Merge {
        /// The shards' output directories.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Output directory of the merged run (not one of the shards, nor inside one).
        #[arg(long)]
        out: PathBuf,
        /// No table.
        #[arg(long)]
        quiet: bool,
        /// If OUT holds a run, rename it aside to OUT.previous-K first.
        #[arg(long)]
        force: bool,
        /// Outputs to write, as `run --outputs` (summary.json and run.json always).
        #[arg(long, default_value = "all", value_name = "LIST")]
        outputs: String,
    },
    /// Validate a world file, print a summary of it and the link visibility along its
    /// trajectory (share of links LOS / through foliage / NLOS / lost per system).
    Check {
        /// The world file.
        world: PathBuf,
        /// Also draw the scene, transmitters and trajectory to this SVG file.
        #[arg(long, value_name = "SVG")]
        map: Option<PathBuf>,
        /// Interval of the visibility survey along the trajectory (s).
        #[arg(long, default_value_t = 1.0, value_name = "S")]
        step: f64,
        /// Print only the world as TOML with every default filled in and presets expanded
        /// (loading that text gives the same world); warnings go to stderr.
        #[arg(long, conflicts_with = "map")]
        resolved: bool,
    },
    /// Print the JSON Schema of world files (for TOML editors: taplo, Even Better TOML),
    /// or with `--markdown` the world-file reference (docs/world-file.md).
    Schema {
        /// Write to this file (atomically) instead of standard output.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
        /// The Markdown reference of every key instead of the JSON Schema.
        #[arg(long)]
        markdown: bool,
    },
    /// Broadcast ephemeris tools.
    #[command(subcommand)]
    Ephemeris(EphemerisCommand),
    /// DTMB signal tools.
    #[command(subcommand)]
    Dtmb(DtmbCommand),
    /// GNSS signal tools.
    #[command(subcommand)]
    Gnss(gnss_iq::GnssCommand),
    /// List the estimator presets (the papers' systems) an `[[estimator]]` can name, with
    /// the keys each one sets.
    Presets,
    /// FM fingerprinting tools.
    #[command(subcommand)]
    Fm(FmCommand),
    /// Write one trial of a world as datasets other tools read: RINEX observations (with
    /// the navigation file), NMEA, TUM, measurement tables (CSV, Parquet), GeoJSON/KML and
    /// SigMF IQ.
    Export(ExportArgs),
    /// Transmitter-layout design: coverage, GDOP and predicted accuracy over a grid, and
    /// the choice of new transmitter sites (`--place K --candidates FILE`).
    Layout(LayoutArgs),
    /// Run the paper worlds and print each paper's table with hybridnav's figure beside
    /// the published one, their ratio, and whether each ordering the paper claims holds.
    Reproduce(ReproduceArgs),
}

#[derive(Debug, Args)]
pub struct ReproduceArgs {
    /// Papers to run, by world name or prefix (seed000-beihang, seed000-kehui, seed001,
    /// seed002, seed003, seed004); all when none is given.
    pub papers: Vec<String>,
    /// Trials per world.
    #[arg(long, default_value_t = crate::reproduce::DEFAULT_TRIALS)]
    pub trials: u64,
    /// Master seed.
    #[arg(long, default_value_t = crate::reproduce::DEFAULT_SEED)]
    pub seed: u64,
    /// Run every paper on each of these master seeds (`1-5`, `1,3,7`) and print, per
    /// figure, the smallest, median and largest value and on how many seeds it is within
    /// 2×; per ordering, on how many seeds it holds; and the totals per seed.
    #[arg(long, value_name = "LIST", conflicts_with = "seed")]
    pub seeds: Option<String>,
    /// Also write the tables as Markdown to this file (docs/reproductions-tables.md; with
    /// `--seeds`, the tables across the seeds).
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<PathBuf>,
    /// The directory the paper worlds' paths (`worlds/…`) are relative to.
    #[arg(long, default_value = ".", value_name = "DIR")]
    pub root: PathBuf,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The world file.
    pub world: PathBuf,
    /// Formats, comma-separated: rinex, nmea, tum, csv, parquet, geojson, kml, sigmf, or
    /// all.
    #[arg(long, default_value = "all")]
    pub format: String,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Master seed (default: the world's [montecarlo] seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// The trial to record (its trajectory, clocks and noise are those of trial N of a
    /// `run` with the same seed).
    #[arg(long, default_value_t = 0)]
    pub trial: u64,
}

#[derive(Debug, Subcommand)]
pub enum FmCommand {
    /// Survey a world's FM field and krige it to its grid as [sensors.fm.survey] says, then
    /// save the fingerprint database (JSON) for `[sensors.fm] database = "…"` to reuse.
    Survey {
        /// The world file (it needs a [sensors.fm] table).
        world: PathBuf,
        /// The database file to write.
        #[arg(long)]
        out: PathBuf,
        /// Master seed (the city's shadowing and the surveyor's noise); default: the
        /// world's [montecarlo] seed.
        #[arg(long)]
        seed: Option<u64>,
    },
}

#[derive(Debug, Subcommand)]
pub enum DtmbCommand {
    /// Bit and packet error rates of the GB 20600 data layer against SNR (hybridnav's own
    /// data receiver): in white Gaussian noise with ideal synchronisation, or with
    /// --world through the multipath between a world's tower and its receiver at one
    /// instant, received by a TDS-OFDM receiver that estimates the channel from the PN
    /// headers (or, --csi ideal, knows it). A table on standard output and, with --out, a
    /// CSV file.
    Ber {
        /// Data constellation: 4qam-nr, 4qam, 16qam, 32qam or 64qam (default 64qam; with
        /// --world the tower's [[transmitter]] qam, else 64qam).
        #[arg(long)]
        qam: Option<String>,
        /// LDPC code rate: 0.4, 0.6 or 0.8 (default 0.6; with --world the tower's).
        #[arg(long)]
        fec: Option<String>,
        /// Time-interleaver depth M: 240 or 720 (default 240; with --world the tower's).
        /// No effect in a static channel but its delay.
        #[arg(long)]
        interleaver: Option<usize>,
        /// Carriers: 3780 or 1 (default 3780; with --world the tower's). With --world, C = 1
        /// bodies are equalised in the frequency domain (MMSE).
        #[arg(long)]
        carriers: Option<usize>,
        /// Frame header (sets the frame power the SNR is defined on): pn420, pn595, pn945
        /// (default pn945; with --world the tower's).
        #[arg(long)]
        mode: Option<String>,
        /// SNR grid over the 7.56 MHz band, FROM:TO:STEP in dB (or one value): the
        /// received frame power over the noise.
        #[arg(long, allow_hyphen_values = true, value_name = "FROM:TO:STEP")]
        snr_db: String,
        /// Frames measured per SNR point (after the interleaver's delay).
        #[arg(long, default_value_t = 100)]
        frames: usize,
        /// Seed of the payload and noise streams (default 1; with --world the master
        /// seed of the trial's trajectory and shadowing too, default the world's
        /// [montecarlo] seed).
        #[arg(long)]
        seed: Option<u64>,
        /// CSV output (written atomically).
        #[arg(long, value_name = "FILE.csv")]
        out: Option<PathBuf>,
        /// Measure through a world's tower's channel: its scene multipath to the
        /// receiver at --at-s (as `dtmb iq --world` computes it), each path's delay and
        /// gain held and its phase turning at its Doppler for the trial's receiver motion
        /// at --at-s.
        #[arg(long, value_name = "WORLD.toml")]
        world: Option<PathBuf>,
        /// With --world: the tower id (default: the world's first DTMB tower).
        #[arg(long)]
        tower: Option<String>,
        /// With --world: the trial whose trajectory, clock and shadowing are used.
        #[arg(long, default_value_t = 0)]
        trial: u64,
        /// With --world: the instant of the channel, seconds from the world's start.
        #[arg(long, default_value_t = 0.0, value_name = "T")]
        at_s: f64,
        /// With --world: the receiver's channel knowledge: interpolated (estimated from
        /// the PN headers before and after each body, interpolated linearly to the body's
        /// centre), estimated (from the header before the body only), ideal (the true
        /// response; with Doppler, at each body's centre), or both (two curves:
        /// interpolated and ideal).
        #[arg(long, default_value = "interpolated")]
        csi: String,
        /// With --world: hold the channel static (no Doppler), to measure what the
        /// receiver's motion costs against the same paths standing still.
        #[arg(long)]
        no_doppler: bool,
        /// With --world: hold each path's delay at its value at --at-s while its phase
        /// turns at its Doppler (the model before the delay drift). By default a moving
        /// receiver's paths also lengthen or shorten at their range rates, −f_D/f_c
        /// seconds a second (0.015 samples over a 64QAM point at Kehui's 5 m/s, 2.4
        /// samples a second at 350 km/h), and the estimating receivers follow the
        /// frame timing's drift from the PN headers unless --no-timing-tracking.
        #[arg(long)]
        no_delay_drift: bool,
        /// With --world: give the estimating receivers the true frame start. By default
        /// they acquire it (and the frame number) from the PN headers with the ranging
        /// receiver's frame sync and start each frame 16 samples before the first path
        /// found; the genie always has the true timing. The true-timing receivers still
        /// search and estimate a carrier offset (--cfo-hz, an oscillator error) as the
        /// acquiring ones do: they are given the timing, not the carrier.
        #[arg(long)]
        true_timing: bool,
        /// With --world: a pure carrier-frequency offset in Hz (e.g. 1000 = 1.7 ppm at
        /// 600 MHz), added to every path's Doppler shift, with no sampling-clock offset;
        /// it replaces the world's oscillator (sensors.dtmb.rx_oscillator_ppm) and
        /// excludes --oscillator-ppm. The estimating receivers estimate it from the PN
        /// headers and correct it (the genie knows it) unless --no-cfo-correction.
        #[arg(long, allow_hyphen_values = true, value_name = "HZ")]
        cfo_hz: Option<f64>,
        /// With --cfo-hz: the offset drifts at this rate in Hz/s (|rate| ≤ 100000), a ramp
        /// from --cfo-hz at the first frame (e.g. 200: a 300 km/h train passing a mast at
        /// 600 MHz). The estimating receivers then follow it with a type-2 tracking loop
        /// instead of summing every header (the genie knows the ramp).
        #[arg(long, allow_hyphen_values = true, value_name = "HZ_PER_S")]
        cfo_rate_hz_per_s: Option<f64>,
        /// With --world: the receiver's oscillator error in ppm (|ppm| ≤ 100), overriding
        /// the world's sensors.dtmb.rx_oscillator_ppm (which applies by default, as in
        /// `dtmb iq --world`). One reference drives the local oscillator and the sample
        /// clock: a CFO of −ppm·10⁻⁶ times the tower's carrier (estimated and corrected
        /// unless --no-cfo-correction) and a sample clock of f_s(1 + ppm·10⁻⁶), whose frame
        /// timing drift (+ppm·10⁻⁶ × the frame length a frame) the estimating receivers
        /// track from the PN headers unless --no-timing-tracking. 0: no offset.
        #[arg(long, allow_hyphen_values = true, value_name = "PPM")]
        oscillator_ppm: Option<f64>,
        /// With a CFO (--cfo-hz, or an oscillator error): leave it uncorrected (to see
        /// what it costs).
        #[arg(long)]
        no_cfo_correction: bool,
        /// With an oscillator error (--oscillator-ppm or the world key): hold the frame
        /// timing the receiver started with instead of tracking the sample clock's drift
        /// (to see what it costs once the drift leaves the PN guard).
        #[arg(long)]
        no_timing_tracking: bool,
    },
    /// Write DTMB baseband frames through white noise as a SigMF recording
    /// (BASE.sigmf-data and BASE.sigmf-meta, with an annotation per frame); with --world,
    /// one tower of a world as the platform's receiver hears it along its trajectory
    /// (scene multipath, link budget, Doppler, receiver and tower clocks).
    Iq {
        /// Frame header: pn420, pn595 or pn945 (with --world: the tower's).
        #[arg(long)]
        mode: Option<String>,
        /// Number of signal frames.
        #[arg(long)]
        frames: usize,
        /// Signal-to-noise ratio over the 7.56 MHz band (dB); required without --world,
        /// refused with it (the link budget sets it).
        #[arg(long, allow_hyphen_values = true)]
        snr_db: Option<f64>,
        /// Record a world's DTMB tower along the platform's trajectory instead of AWGN.
        #[arg(long, value_name = "WORLD.toml")]
        world: Option<PathBuf>,
        /// With --world: the tower id (default: the world's first DTMB tower).
        #[arg(long)]
        tower: Option<String>,
        /// With --world: start of the recording, seconds from the world's start.
        #[arg(long, default_value_t = 0.0, value_name = "T0")]
        from_s: f64,
        /// With --world: the trial whose trajectory, clock and noise are used.
        #[arg(long, default_value_t = 0)]
        trial: u64,
        /// Sample format: cf32 (32-bit float I/Q) or ci8 (8-bit integer I/Q).
        #[arg(long, default_value = "cf32")]
        format: String,
        /// Integer oversampling of the 7.56 Msps symbol rate (SRRC shaping when > 1).
        #[arg(long, default_value_t = 1)]
        oversampling: usize,
        /// UHF channel number (China: DS-13 … DS-48), for the recorded centre frequency
        /// (with --world: ignored, the tower's carrier is recorded).
        #[arg(long, default_value_t = 14)]
        channel: u32,
        /// Seed of the payload and noise streams (with --world: the master seed, default
        /// the world's [montecarlo] seed; without: default 1).
        #[arg(long)]
        seed: Option<u64>,
        /// The receiver oscillator's error in ppm (|ppm| ≤ 100): the recording carries
        /// its carrier offset −ppm·f_c and sampling-clock offset (default 0; with --world
        /// it replaces the world's [sensors.dtmb] rx_oscillator_ppm, as in dtmb ber).
        #[arg(long, allow_hyphen_values = true, value_name = "PPM")]
        oscillator_ppm: Option<f64>,
        /// Output base path (without the .sigmf-data / .sigmf-meta suffix).
        #[arg(long)]
        out: PathBuf,
        /// The data layer (GB 20600 transmitter: scrambler, BCH, LDPC, mapping, time
        /// interleaver, system information): see `hybridnav_dtmb::dtmb::data_layer`. With
        /// --world each option replaces the recorded tower's own ([[transmitter]] qam,
        /// fec, interleaver, carriers, payload).
        #[command(flatten)]
        profile: dtmb::ProfileArgs,
    },
}

#[derive(Debug, Args)]
pub struct RunArgs {
    /// The world file (default: worlds/default.toml).
    pub world: Option<PathBuf>,
    /// Number of trials (default: the world's [montecarlo] trials).
    #[arg(long)]
    pub trials: Option<u64>,
    /// Master seed (default: the world's [montecarlo] seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output directory.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar and no table.
    #[arg(long)]
    pub quiet: bool,
    /// Run only shard K of N (trials i with i mod N = K − 1), e.g. on N machines; combine
    /// the shards' directories with `hybridnav merge`. `auto/N` takes K from a Slurm job
    /// array (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Continue the interrupted run in OUT: keep the trials it finished, run the rest.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
    /// If OUT holds another run, rename it aside to OUT.previous-K (K the first free
    /// number) and start afresh; without it (or --resume) such an OUT is refused.
    #[arg(long)]
    pub force: bool,
    /// Outputs to write, comma-separated: summary, report, epochs, parquet, trials, or
    /// all. summary.json and run.json are always written; without `trials` the run cannot
    /// be resumed or merged.
    #[arg(long, default_value = "all", value_name = "LIST")]
    pub outputs: String,
    /// Also export each trial this run ran as datasets (formats as `export --format`) to
    /// OUT/datasets/trial-NNNNNN/.
    #[arg(long, value_name = "FORMATS")]
    pub datasets: Option<String>,
}

#[derive(Debug, Subcommand)]
pub enum EphemerisCommand {
    /// Print satellite positions and clocks as CSV (ECEF metres, clock in seconds).
    Positions {
        /// RINEX 2 or 3 navigation file, or embedded data such as `builtin:nominal-gps-bds`.
        #[arg(long)]
        nav: String,
        /// First epoch (ISO-8601; GPST unless it ends in Z or UTC).
        #[arg(long)]
        start: String,
        /// Last epoch (inclusive).
        #[arg(long)]
        end: String,
        /// Step in seconds.
        #[arg(long)]
        step: f64,
        /// Satellites, e.g. G05,C01 (default: all GPS and BeiDou satellites in the file).
        #[arg(long, value_delimiter = ',')]
        sats: Vec<String>,
        /// Largest |t − toe| in seconds at which a record is used: one value for every
        /// system, or per system as gps=7200,bds=3600 [default: gps=7200,bds=3600, as
        /// RTKLIB].
        #[arg(long, value_name = "SECONDS")]
        max_age: Option<String>,
    },
    /// Write a RINEX 3 navigation file for the nominal GPS and BeiDou constellations.
    Synth {
        /// Start epoch (ISO-8601; GPST unless it ends in Z or UTC).
        #[arg(long)]
        start: String,
        /// Hours of ephemerides to write.
        #[arg(long, default_value_t = 48.0)]
        hours: f64,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Loads a world and prints its warnings (dropped navigation records, implausible
/// values) on stderr, so that every command that reads a world shows them.
pub(crate) fn load_world(path: &Path) -> Result<crate::world::World, crate::world::WorldError> {
    let w = crate::world::load_world(path)?;
    for m in &w.warnings {
        eprintln!("warning: {m}");
    }
    Ok(w)
}

/// The default world: `worlds/default.toml` in the current directory, else the one next
/// to the sources this binary was built from.
fn default_world() -> PathBuf {
    let local = PathBuf::from("worlds/default.toml");
    if local.exists() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/default.toml")
    }
}

/// Runs a parsed command line.
///
/// # Errors
/// Every user-facing failure, with a message saying what was wrong and what was expected.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(a) => cmd_run(a),
        Command::Merge {
            dirs,
            out,
            quiet,
            force,
            outputs,
        } => cmd_merge(&dirs, &out, quiet, force, &outputs),
        Command::Check {
            world,
            map,
            step,
            resolved,
        } => {
            let w = load_world(&world)?;
            if resolved {
                let text =
                    crate::world::reference::resolved_toml(&w.file).map_err(anyhow::Error::msg)?;
                print!("{text}");
                return Ok(());
            }
            print!("{}", w.summary());
            if !(step.is_finite() && step > 0.0) {
                anyhow::bail!("--step must be a positive number of seconds, got {step}");
            }
            let epochs = crate::world::visibility::survey(&w, step).map_err(anyhow::Error::msg)?;
            print!("{}", crate::world::visibility::table(&epochs));
            if let Some(path) = map {
                let svg = crate::report::map::svg(&w).map_err(anyhow::Error::msg)?;
                write_atomic(&path, svg.as_bytes())
                    .with_context(|| format!("cannot write the map {}", path.display()))?;
                println!("map        {}", path.display());
            }
            println!("ok");
            Ok(())
        }
        Command::Ephemeris(EphemerisCommand::Positions {
            nav,
            start,
            end,
            step,
            sats,
            max_age,
        }) => ephemeris::positions(&nav, &start, &end, step, &sats, max_age.as_deref()),
        Command::Dtmb(DtmbCommand::Ber {
            qam,
            fec,
            interleaver,
            carriers,
            mode,
            snr_db,
            frames,
            seed,
            out,
            world,
            tower,
            trial,
            at_s,
            csi,
            no_doppler,
            no_delay_drift,
            true_timing,
            cfo_hz,
            cfo_rate_hz_per_s,
            no_cfo_correction,
            oscillator_ppm,
            no_timing_tracking,
        }) => dtmb::ber(&dtmb::BerArgs {
            qam,
            fec,
            interleaver,
            carriers,
            mode,
            snr_db,
            frames,
            seed,
            out,
            world,
            tower,
            trial,
            at_s,
            csi,
            no_doppler,
            no_delay_drift,
            true_timing,
            cfo_hz,
            cfo_rate_hz_per_s,
            no_cfo_correction,
            oscillator_ppm,
            no_timing_tracking,
        }),
        Command::Dtmb(DtmbCommand::Iq {
            mode,
            frames,
            snr_db,
            world,
            tower,
            from_s,
            trial,
            format,
            oversampling,
            channel,
            seed,
            oscillator_ppm,
            out,
            profile,
        }) => cmd_dtmb_iq(DtmbIqArgs {
            mode,
            frames,
            snr_db,
            world,
            tower,
            from_s,
            trial,
            format,
            oversampling,
            channel,
            seed,
            oscillator_ppm,
            out,
            profile,
        }),
        Command::Ephemeris(EphemerisCommand::Synth { start, hours, out }) => {
            cmd_synth(&start, hours, &out)
        }
        Command::Fm(FmCommand::Survey { world, out, seed }) => cmd_fm_survey(&world, &out, seed),
        Command::Export(a) => cmd_export(&a),
        Command::Gnss(c) => gnss_iq::run(c),
        Command::Layout(a) => Ok(crate::layout::run(&a.request())?),
        Command::Reproduce(a) => cmd_reproduce(&a),
        Command::Schema { out, markdown } => {
            let text = if markdown {
                crate::world::reference::markdown()
            } else {
                let mut s = serde_json::to_string_pretty(&crate::world::reference::json_schema())?;
                s.push('\n');
                s
            };
            match out {
                Some(path) => write_atomic(&path, text.as_bytes())
                    .with_context(|| format!("cannot write {}", path.display()))?,
                None => print!("{text}"),
            }
            Ok(())
        }
        Command::Presets => {
            for p in crate::world::presets::PRESETS {
                println!("{}\n  {}", p.name, p.about);
                for line in p.toml.lines() {
                    println!("    {line}");
                }
            }
            Ok(())
        }
    }
}

fn cmd_reproduce(a: &ReproduceArgs) -> Result<()> {
    use crate::reproduce;
    if !(1..=crate::world::schema::MAX_TRIALS).contains(&a.trials) {
        anyhow::bail!(
            "--trials must be 1 to {}, got {}",
            crate::world::schema::MAX_TRIALS,
            a.trials
        );
    }
    let papers = reproduce::select(&a.papers).map_err(anyhow::Error::msg)?;
    let threads = a.threads.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    if let Some(list) = &a.seeds {
        let seeds = reproduce::seeds::parse_seeds(list).map_err(anyhow::Error::msg)?;
        let mut runs = Vec::with_capacity(seeds.len());
        for &seed in &seeds {
            let mut results = Vec::with_capacity(papers.len());
            for &p in &papers {
                eprintln!("running {} ({} trials, seed {seed})", p.world, a.trials);
                results.push(
                    reproduce::run_paper(&a.root, p, a.trials, seed, threads.max(1))
                        .map_err(anyhow::Error::msg)?,
                );
            }
            runs.push(results);
        }
        let sweep = reproduce::seeds::Sweep::new(seeds, &runs).map_err(anyhow::Error::msg)?;
        print!("{}", sweep.text());
        if let Some(path) = &a.markdown {
            write_atomic(path, sweep.markdown().as_bytes())
                .with_context(|| format!("cannot write {}", path.display()))?;
            println!("wrote {}", path.display());
        }
        return Ok(());
    }
    let mut results = Vec::with_capacity(papers.len());
    for p in papers {
        eprintln!("running {} ({} trials)", p.world, a.trials);
        results.push(
            reproduce::run_paper(&a.root, p, a.trials, a.seed, threads.max(1))
                .map_err(anyhow::Error::msg)?,
        );
    }
    print!("{}", reproduce::text(&results));
    if let Some(path) = &a.markdown {
        write_atomic(path, reproduce::markdown(&results).as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn cmd_export(a: &ExportArgs) -> Result<()> {
    let formats = crate::export::Format::parse_list(&a.format)
        .map_err(anyhow::Error::msg)
        .context("--format")?;
    let world = load_world(&a.world)?;
    let seed = a.seed.unwrap_or(world.file.montecarlo.seed);
    let rec = crate::export::record_trial(&world, seed, a.trial).map_err(anyhow::Error::msg)?;
    let done = crate::export::export(&world, &rec, &formats, names_all(&a.format), &a.out)
        .map_err(anyhow::Error::msg)?;
    for f in &done.files {
        println!("wrote {}", f.display());
    }
    for s in &done.skipped {
        eprintln!("note: skipped {s}");
    }
    Ok(())
}

/// Whether a format list asks for `all` (formats the world cannot produce are then
/// skipped rather than refused).
fn names_all(list: &str) -> bool {
    list.split(',')
        .any(|n| n.trim().eq_ignore_ascii_case("all"))
}

fn cmd_run(a: RunArgs) -> Result<()> {
    let path = a.world.unwrap_or_else(default_world);
    let all_datasets = a.datasets.as_deref().is_some_and(names_all);
    let datasets = match &a.datasets {
        Some(list) => Some(
            crate::export::Format::parse_list(list)
                .map_err(anyhow::Error::msg)
                .context("--datasets")?,
        ),
        None => None,
    };
    let outputs = OutputSet::parse(&a.outputs).map_err(anyhow::Error::msg)?;
    if a.shard.is_some() && !outputs.trials {
        bail!("--shard needs `trials` in --outputs: merge reads the shards' trial files");
    }
    let world = load_world(&path)?;
    let trials = a.trials.unwrap_or(world.file.montecarlo.trials);
    if !(1..=crate::world::schema::MAX_TRIALS).contains(&trials) {
        bail!(
            "--trials {trials}: expected 1 to {} (run more as several runs with different --seed)",
            crate::world::schema::MAX_TRIALS
        );
    }
    let shard = match &a.shard {
        Some(s) => {
            Shard::parse_with_env(s, |k| std::env::var(k).ok()).map_err(anyhow::Error::msg)?
        }
        None => Shard::WHOLE,
    };
    let threads = match a.threads {
        Some(t) if !(1..=crate::montecarlo::MAX_THREADS).contains(&t) => bail!(
            "--threads {t}: expected 1 to {}",
            crate::montecarlo::MAX_THREADS
        ),
        Some(t) => t,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let opts = RunOptions {
        trials,
        seed: a.seed.unwrap_or(world.file.montecarlo.seed),
        threads,
        progress: !a.quiet,
        shard,
    };
    let how = match (a.resume, a.force) {
        (true, _) => Takeover::Resume,
        (false, true) => Takeover::Force,
        (false, false) => Takeover::Fresh,
    };
    let dir = take_out(&a.out, how)?;
    let written =
        run_into_with(&world, &opts, &dir, a.resume, outputs).map_err(anyhow::Error::msg)?;
    report_written(&written, a.quiet);
    if let Some(formats) = datasets {
        // Each trial is simulated again with a recorder; it depends only on (seed, trial),
        // so the datasets are those of the trial just stored.
        let first = opts.shard.trials(opts.trials).next();
        for trial in opts.shard.trials(opts.trials) {
            let rec = crate::export::record_trial(&world, opts.seed, trial)
                .map_err(anyhow::Error::msg)?;
            let dir = a.out.join("datasets").join(format!("trial-{trial:06}"));
            let done = crate::export::export(&world, &rec, &formats, all_datasets, &dir)
                .map_err(anyhow::Error::msg)?;
            if Some(trial) == first {
                for s in &done.skipped {
                    eprintln!("note: datasets: skipped {s}");
                }
            }
        }
        if !a.quiet {
            println!("datasets   {}", a.out.join("datasets").display());
        }
    }
    Ok(())
}

fn report_written(written: &crate::montecarlo::Written, quiet: bool) {
    for w in &written.summary.warnings {
        eprintln!("warning: {w}");
    }
    for e in &written.summary.estimators {
        if let Some(f) = e.first_failures.first() {
            eprintln!(
                "warning: estimator {:?} reported {} numerical failure(s) (first in trial {} at t = {:.3} s); it re-initialised each time, and summary.json lists them",
                e.name, e.numerical_failures, f.trial, f.t_s
            );
        }
    }
    if !quiet {
        print!("{}", written.summary.table());
        let names: Vec<String> = written
            .files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        println!("wrote {}", names.join(", "));
    }
}

/// Takes the output directory `out` over for a run or merge ([`RunDir::take`]), saying
/// where a run it held was moved.
fn take_out(out: &Path, how: Takeover) -> Result<RunDir> {
    use crate::montecarlo::store::StoreError;
    let (dir, aside) = RunDir::take(out, how).map_err(|e| match e {
        StoreError::Refused(m) => anyhow::Error::msg(m),
        e => anyhow::Error::msg(format!(
            "cannot write to output directory {}: {e}",
            out.display()
        )),
    })?;
    if let Some(aside) = aside {
        eprintln!(
            "note: the run {} held was moved aside to {}",
            out.display(),
            aside.display()
        );
    }
    Ok(dir)
}

/// `path` made absolute with symbolic links resolved, also when its last components do
/// not exist yet (they are appended to the nearest existing ancestor, resolved).
fn resolved(path: &Path) -> PathBuf {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut tail = Vec::new();
    let mut head = abs.as_path();
    loop {
        if let Ok(real) = head.canonicalize() {
            return tail.iter().rev().fold(real, |p, c| p.join(c));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                tail.push(name.to_os_string());
                head = parent;
            }
            _ => return abs,
        }
    }
}

fn cmd_merge(dirs: &[PathBuf], out: &Path, quiet: bool, force: bool, outputs: &str) -> Result<()> {
    let outputs = OutputSet::parse(outputs).map_err(anyhow::Error::msg)?;
    // The output must be none of the inputs, neither inside one (its trials would be
    // written among a shard's) nor around one (--force would move the shard aside).
    let out_real = resolved(out);
    for d in dirs {
        let d_real = resolved(d);
        if out_real.starts_with(&d_real) || d_real.starts_with(&out_real) {
            bail!(
                "merge: --out {} {} the input {}; write the merged run to a directory of \
                 its own (the shards are left as they are)",
                out.display(),
                if out_real == d_real {
                    "is"
                } else if out_real.starts_with(&d_real) {
                    "is inside"
                } else {
                    "contains"
                },
                d.display()
            );
        }
    }
    let plan = MergePlan::new(dirs).map_err(anyhow::Error::msg)?;
    let manifest = &plan.manifest;
    // The outputs need the world (its frame, scene and estimators): it must still be the
    // file the shards ran, unchanged.
    let world = load_world(Path::new(&manifest.world_file)).with_context(|| {
        format!(
            "merge: the shards ran {}, which must still be readable from here",
            manifest.world_file
        )
    })?;
    if world.hash != manifest.world_hash {
        bail!(
            "merge: {} has changed since the shards ran (hash {} now, {} then)",
            manifest.world_file,
            world.hash,
            manifest.world_hash
        );
    }
    let how = if force {
        Takeover::Force
    } else {
        Takeover::Fresh
    };
    let dir = take_out(out, how)?;
    let written = merge_into(&world, &plan, &dir, outputs).map_err(anyhow::Error::msg)?;
    report_written(&written, quiet);
    Ok(())
}

fn cmd_fm_survey(world: &Path, out: &Path, seed: Option<u64>) -> Result<()> {
    let w = load_world(world)?;
    let cfg = w
        .file
        .sensors
        .fm
        .as_ref()
        .with_context(|| format!("{}: the world has no [sensors.fm] table", world.display()))?;
    let seed = seed.unwrap_or(w.file.montecarlo.seed);
    let (db, report) = crate::world::fm::survey(&w, cfg, seed).map_err(anyhow::Error::msg)?;
    for (ch, r) in db.channels().iter().zip(&report) {
        match &r.fit {
            Some(f) => println!(
                "{:>6}  {:7.2} MHz  {:4} RPs  {:?} nugget {:.2} dB² psill {:.2} dB² range {:.0} m  (rms residual {:.2} dB²)",
                ch.id,
                ch.freq_hz * 1e-6,
                r.data_points,
                f.model.kind,
                f.model.nugget,
                f.model.psill,
                f.model.range_m,
                f.rms_residual
            ),
            None => println!("{:>6}  {:7.2} MHz  {:4} RPs  too few values: missing on the grid", ch.id, ch.freq_hz * 1e-6, r.data_points),
        }
    }
    db.save(out)
        .with_context(|| format!("cannot write {}", out.display()))?;
    println!(
        "wrote {} RPs × {} channels to {}",
        db.len(),
        db.channels().len(),
        out.display()
    );
    Ok(())
}

fn cmd_synth(start: &str, hours: f64, out: &Path) -> Result<()> {
    let t0 = GpsTime::parse_iso(start)
        .map_err(anyhow::Error::msg)
        .context("--start")?;
    if !(hours.is_finite() && hours > 0.0 && hours <= 24.0 * 31.0) {
        bail!("--hours must be within (0, 744], got {hours}");
    }
    let ephs = crate::gnss::synth::synth_nav(t0, hours, 2.0);
    let klob = crate::gnss::synth::default_klobuchar();
    crate::gnss::synth::write_rinex3_nav(&ephs, Some(&klob), t0.gpst_minus_utc_s() as i32, out)
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("wrote {} ephemerides to {}", ephs.len(), out.display());
    Ok(())
}

/// The options of `dtmb iq`.
struct DtmbIqArgs {
    mode: Option<String>,
    frames: usize,
    snr_db: Option<f64>,
    world: Option<PathBuf>,
    tower: Option<String>,
    from_s: f64,
    trial: u64,
    format: String,
    oversampling: usize,
    channel: u32,
    seed: Option<u64>,
    oscillator_ppm: Option<f64>,
    out: PathBuf,
    profile: dtmb::ProfileArgs,
}

fn cmd_dtmb_iq(a: DtmbIqArgs) -> Result<()> {
    use crate::dtmb::pn::{PnMode, SAMPLE_RATE_HZ};
    use crate::dtmb::sigmf::SampleFormat;
    let format = match a.format.to_ascii_lowercase().as_str() {
        "cf32" | "cf32_le" => SampleFormat::Cf32,
        "ci8" => SampleFormat::Ci8,
        other => bail!("--format: unknown sample format '{other}'; expected cf32 or ci8"),
    };
    let out = a.out.as_path();
    let mkdir = || -> Result<()> {
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create output directory {}", dir.display()))?;
        }
        Ok(())
    };
    // Bad data-layer options are refused before anything is created.
    let data = a.profile.data_layer()?;
    let ppm = a.oscillator_ppm.unwrap_or(0.0);
    if !crate::dtmb::multipath::rx_oscillator_ppm_valid(ppm) {
        bail!("--oscillator-ppm must be a finite error of at most 100 ppm, got {ppm}");
    }
    if let Some(path) = &a.world {
        if a.snr_db.is_some() {
            bail!("--snr-db cannot be given with --world: the world's link budget sets the SNR");
        }
        if a.oversampling != 1 {
            bail!("--oversampling is not supported with --world (7.56 Msps only)");
        }
        if a.frames == 0 {
            bail!("--frames must be at least 1");
        }
        let mut w = load_world(path).map_err(|e| anyhow::anyhow!("{e}"))?;
        // The command line's oscillator replaces the world's, as `dtmb ber --world` does.
        if let Some(p) = a.oscillator_ppm {
            w.file
                .sensors
                .dtmb
                .get_or_insert_with(Default::default)
                .rx_oscillator_ppm = p;
        }
        let req = crate::world::dtmb_iq::WorldIqRequest {
            tower: a.tower.clone(),
            from_s: a.from_s,
            frames: a.frames,
            seed: a.seed.unwrap_or(w.file.montecarlo.seed),
            trial: a.trial,
            // The profile options replace the tower table's, key by key.
            data_layer: crate::world::dtmb_iq::DataLayerOverride {
                payload: a.profile.payload.clone(),
                qam: a.profile.qam.clone(),
                fec: a.profile.fec.clone(),
                interleaver: a.profile.interleaver,
                carriers: a.profile.carriers,
            },
        };
        // The mode is known before the recording: check it first.
        if let Some(m) = &a.mode {
            let m: PnMode = m.parse()?;
            let (tower, mode) = crate::world::dtmb_iq::requested_tower(&w, &req)?;
            if m != mode {
                bail!(
                    "--mode {} contradicts tower {}'s {} (with --world the tower sets the mode)",
                    m.name(),
                    tower,
                    mode.name()
                );
            }
        }
        mkdir()?;
        let rec = crate::world::dtmb_iq::write_world_sigmf(&w, &req, out, format)?;
        let others: Vec<&str> = rec
            .towers
            .iter()
            .filter(|id| **id != rec.tower)
            .map(String::as_str)
            .collect();
        eprintln!(
            "wrote {} samples ({} frames of tower {}{} {}, SNR {:.1} dB at the start, {:.0} MHz) \
             to {}.sigmf-data and .sigmf-meta",
            rec.samples,
            a.frames,
            rec.tower,
            if others.is_empty() {
                String::new()
            } else {
                format!(" with co-channel towers {}", others.join(", "))
            },
            rec.mode.name(),
            rec.snr_db,
            rec.center_freq_hz * 1e-6,
            out.display()
        );
        return Ok(());
    }
    if a.tower.is_some() || a.from_s != 0.0 || a.trial != 0 {
        bail!("--tower, --from-s and --trial need --world");
    }
    let mode: PnMode = a.mode.as_deref().unwrap_or("pn945").parse()?;
    let Some(snr_db) = a.snr_db else {
        bail!("--snr-db is required without --world");
    };
    if !snr_db.is_finite() {
        bail!("--snr-db must be a finite number of dB, got {snr_db}");
    }
    let center_hz = crate::dtmb::uhf_channel_center_hz(a.channel)?;
    // Refuse bad data-layer options before creating anything.
    drop(data);
    mkdir()?;
    let rate_hz = SAMPLE_RATE_HZ * a.oversampling as f64;
    let profile = &a.profile;
    let rec = crate::dtmb::sigmf::AwgnRecording::new(
        mode,
        a.frames,
        snr_db,
        a.oversampling,
        a.seed.unwrap_or(1),
    )
    .with_oscillator(ppm, center_hz);
    let samples = crate::dtmb::sigmf::write_iq_sigmf(out, format, &rec, &|| {
        crate::dtmb::data_layer::data_layer_from_options(
            profile.payload.as_deref(),
            profile.qam.as_deref(),
            profile.fec.as_deref(),
            profile.interleaver,
            profile.carriers,
        )
    })?;
    eprintln!(
        "wrote {} samples ({} frames at {:.2} Msps, {:.0} MHz) to {}.sigmf-data and .sigmf-meta",
        samples,
        a.frames,
        rate_hz * 1e-6,
        center_hz * 1e-6,
        out.display()
    );
    Ok(())
}

/// `hybridnav layout` options.
#[derive(Debug, Clone, Args)]
pub struct LayoutArgs {
    /// The world file.
    pub world: PathBuf,
    /// Grid spacing (m).
    #[arg(long, default_value_t = 10.0)]
    pub grid: f64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Receiver antenna height above the ground (m).
    #[arg(long, default_value_t = 1.5)]
    pub height: f64,
    /// GNSS epoch: `YYYY-MM-DDTHH:MM:SS GPST`, or `+SECONDS` after the world's start
    /// (default: the start). Repeat for several epochs; each cell reports its worst.
    #[arg(long = "time")]
    pub times: Vec<String>,
    /// The region as `W,S,E,N` in the world's ENU metres (default: the scene and the
    /// trajectory; see docs/layout.md).
    #[arg(long)]
    pub region: Option<String>,
    /// How ranges share clock unknowns.
    #[arg(long, default_value = "shared", value_parser = PossibleValuesParser::new(ClockModel::NAMES).try_map(|s| s.parse::<ClockModel>()))]
    pub clocks: ClockModel,
    /// Choose this many new sites from `--candidates`.
    #[arg(long)]
    pub place: Option<usize>,
    /// Candidate sites: CSV `id,east_m,north_m,height_m[,kind[,erp_kw[,freq_mhz]]]`.
    #[arg(long)]
    pub candidates: Option<PathBuf>,
    /// What the placement minimises over the region.
    #[arg(long, default_value = "gdop95", value_parser = PossibleValuesParser::new(Objective::NAMES).try_map(|s| s.parse::<Objective>()))]
    pub objective: Objective,
    /// Seed of the random-placement baseline.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Random placements in the baseline.
    #[arg(long, default_value_t = 20)]
    pub random_trials: usize,
}

impl LayoutArgs {
    /// The request the layout module runs.
    fn request(self) -> LayoutRequest {
        LayoutRequest {
            world: self.world,
            grid: self.grid,
            out: self.out,
            height: self.height,
            times: self.times,
            region: self.region,
            clocks: self.clocks,
            place: self.place,
            candidates: self.candidates,
            objective: self.objective,
            seed: self.seed,
            random_trials: self.random_trials,
        }
    }
}
