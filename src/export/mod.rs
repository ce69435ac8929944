//! Synthetic datasets for other tools: one trial of a world, recorded as the files a real
//! receiver, logger or GIS would have produced.
//!
//! `hybridnav export WORLD --format rinex,nmea,… --out DIR` re-simulates one trial with a
//! [`BatchObserver`] that keeps every batch, the truth at its time, and the raw
//! observations the sources log on request; each format's writer then reads only that
//! [`Recording`]. Because a trial depends only on `(world, seed, trial)` and observing does
//! not perturb it, the exported estimator trajectories are those of the same trial in a
//! Monte Carlo run (`run --datasets` exports each trial it ran this way).

pub mod geo;
pub mod nmea;
pub mod rinex_obs;
pub mod tables;

use crate::core::TrialRng;
use crate::engine::trial::{simulate_observed, BatchObserver, EstimatorTrace};
use crate::io::atomic::write_atomic;
use crate::measurement::{Measurement, MeasurementBatch, RawLog, SourceKind, Truth};
use crate::world::World;
use std::fmt;
use std::path::{Path, PathBuf};

/// A dataset format `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Format {
    /// RINEX 3.04 observation file plus the navigation file the trial used.
    Rinex,
    /// NMEA 0183 GGA/RMC/GSA/GSV for the truth and each estimator.
    Nmea,
    /// TUM trajectories (truth and each estimator), as evo reads them.
    Tum,
    /// One CSV per measurement kind, each row with its truth.
    Csv,
    /// The same tables as Parquet.
    Parquet,
    /// GeoJSON of the scene, transmitters and trajectories.
    Geojson,
    /// KML of the same.
    Kml,
    /// SigMF baseband IQ of each DTMB tower along the trajectory.
    Sigmf,
}

impl Format {
    /// Every format, in the order `all` writes them.
    pub const ALL: [Format; 8] = [
        Format::Rinex,
        Format::Nmea,
        Format::Tum,
        Format::Csv,
        Format::Parquet,
        Format::Geojson,
        Format::Kml,
        Format::Sigmf,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Format::Rinex => "rinex",
            Format::Nmea => "nmea",
            Format::Tum => "tum",
            Format::Csv => "csv",
            Format::Parquet => "parquet",
            Format::Geojson => "geojson",
            Format::Kml => "kml",
            Format::Sigmf => "sigmf",
        }
    }

    /// Parses a comma-separated list (`rinex,nmea`, or `all`), sorted and deduplicated.
    ///
    /// # Errors
    /// An unknown or empty name, with the known names.
    pub fn parse_list(list: &str) -> Result<Vec<Format>, String> {
        let mut out = Vec::new();
        for name in list.split(',').map(str::trim) {
            if name.eq_ignore_ascii_case("all") {
                out.extend(Format::ALL);
                continue;
            }
            match Format::ALL
                .iter()
                .find(|f| f.name().eq_ignore_ascii_case(name))
            {
                Some(f) => out.push(*f),
                None => {
                    let known: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
                    return Err(format!(
                        "unknown dataset format '{name}'; expected one or more of {}, or all \
                         (comma-separated)",
                        known.join(", ")
                    ));
                }
            }
        }
        out.sort();
        out.dedup();
        Ok(out)
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One batch as recorded: when, from which source, the truth then, what it measured.
#[derive(Clone, Debug)]
pub struct RecordedBatch {
    pub truth: Truth,
    pub source: SourceKind,
    pub items: Vec<Measurement>,
    pub raw: RawLog,
}

/// Everything one trial produced, for the format writers.
pub struct Recording {
    pub seed: u64,
    pub trial: u64,
    /// Every batch every source produced, in event order (empty receiver epochs included).
    pub batches: Vec<RecordedBatch>,
    /// The estimators' traces (estimates at their scored epochs).
    pub estimators: Vec<EstimatorTrace>,
}

impl Recording {
    /// A file stem per estimator, in the world's order: the name with every character
    /// other than a letter, digit or `-` replaced by `_`, made unique (`-2`, `-3`, …) and
    /// never `truth`, whose files hold the reference.
    pub fn estimator_stems(&self) -> Vec<String> {
        let mut used: Vec<String> = vec!["truth".to_string()];
        let mut out = Vec::with_capacity(self.estimators.len());
        for est in &self.estimators {
            let base = file_stem(&est.name);
            let mut stem = base.clone();
            let mut k = 2;
            while used.iter().any(|u| u.eq_ignore_ascii_case(&stem)) {
                stem = format!("{base}-{k}");
                k += 1;
            }
            used.push(stem.clone());
            out.push(stem);
        }
        out
    }

    /// The truth at the epochs of the first source that samples at the start (the GNSS
    /// receiver in most worlds), one per distinct time: the reference trajectory.
    pub fn truth_track(&self) -> Vec<&Truth> {
        let mut out: Vec<&Truth> = Vec::new();
        let Some(first) = self.batches.first() else {
            return out;
        };
        for b in self.batches.iter().filter(|b| b.source == first.source) {
            if out.last().is_none_or(|t| t.sim != b.truth.sim) {
                out.push(&b.truth);
            }
        }
        out
    }
}

struct Recorder {
    batches: Vec<RecordedBatch>,
}

impl BatchObserver for Recorder {
    fn wants_raw(&self) -> bool {
        true
    }
    fn batch(&mut self, truth: &Truth, batch: &MeasurementBatch) {
        self.batches.push(RecordedBatch {
            truth: *truth,
            source: batch.source,
            items: batch.items.clone(),
            raw: batch.raw.clone().unwrap_or_default(),
        });
    }
}

/// Simulates trial `trial` of `world` under `seed` and records it.
///
/// # Errors
/// When the world cannot build the trial.
pub fn record_trial(world: &World, seed: u64, trial: u64) -> Result<Recording, String> {
    let rng = TrialRng::new(seed, trial);
    let mut setup = world.build_trial(&rng)?;
    let mut rec = Recorder {
        batches: Vec::new(),
    };
    let estimators = simulate_observed(&world.frame, world.start, &mut setup, Some(&mut rec));
    Ok(Recording {
        seed,
        trial,
        batches: rec.batches,
        estimators,
    })
}

impl Format {
    /// Why the recording has nothing to write in this format, if so: no GNSS receiver for
    /// RINEX, no DTMB tower for SigMF.
    pub fn unavailable(self, world: &World, rec: &Recording) -> Option<String> {
        match self {
            Format::Rinex if !rec.batches.iter().any(|b| !b.raw.gnss.is_empty()) => Some(
                "the trial has no GNSS observations (the world needs [sensors.gnss] and a \
                 satellite in view)"
                    .into(),
            ),
            Format::Sigmf
                if !world
                    .transmitters
                    .iter()
                    .any(|t| t.kind == crate::world::scene::TransmitterKind::Dtmb) =>
            {
                Some("the world has no DTMB tower to record".into())
            }
            _ => None,
        }
    }
}

/// What an export wrote, and the formats it passed over.
#[derive(Debug, Default)]
pub struct Exported {
    pub files: Vec<PathBuf>,
    /// `format: reason` for each format the world cannot produce (only when those may be
    /// skipped, as with `--format all`).
    pub skipped: Vec<String>,
}

/// Writes `formats` of a recorded trial into `dir`.
///
/// A format the world cannot produce ([`Format::unavailable`]) is an error when asked for
/// by name, and passed over (listed in [`Exported::skipped`]) when `skip_unavailable`
/// (`--format all`).
///
/// # Errors
/// A writer's failure, naming the format and the file.
pub fn export(
    world: &World,
    rec: &Recording,
    formats: &[Format],
    skip_unavailable: bool,
    dir: &Path,
) -> Result<Exported, String> {
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("cannot create the dataset directory {}: {e}", dir.display()))?;
    let mut out = Exported::default();
    for f in formats {
        if let Some(why) = f.unavailable(world, rec) {
            if skip_unavailable {
                out.skipped.push(format!("{f}: {why}"));
                continue;
            }
            return Err(format!("{f} export: {why}"));
        }
        let written = match f {
            Format::Rinex => rinex_obs::write(world, rec, dir),
            Format::Nmea => nmea::write(world, rec, dir),
            Format::Tum => tables::write_tum(world, rec, dir),
            Format::Csv => tables::write_csv(world, rec, dir),
            Format::Parquet => tables::write_parquet(world, rec, dir),
            Format::Geojson => geo::write_geojson(world, rec, dir),
            Format::Kml => geo::write_kml(world, rec, dir),
            Format::Sigmf => write_sigmf(world, rec, dir),
        }
        .map_err(|e| format!("{f} export: {e}"))?;
        out.files.extend(written);
    }
    Ok(out)
}

/// Writes `text` atomically to `dir/name`, returning the path.
pub(crate) fn write_text(dir: &Path, name: &str, text: &str) -> Result<PathBuf, String> {
    let path = dir.join(name);
    write_atomic(&path, text.as_bytes()).map_err(|e| e.to_string())?;
    Ok(path)
}

/// A file-name-safe form of a name (`GPS+DTMB` → `GPS_DTMB`).
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// DTMB signal frames each SigMF recording holds: 50 PN945 frames (4725 symbols each) are
/// 31 ms at 7.56 Msps (1.9 MB of cf32), enough for a receiver's acquisition and a few tracking updates; a
/// longer recording is `hybridnav dtmb iq --world … --frames N`.
pub const SIGMF_FRAMES: usize = 50;

/// The SigMF recordings: each DTMB tower as the platform hears it from the trial's start
/// (`dtmb-<tower>.sigmf-data` and `.sigmf-meta`, cf32 at 7.56 Msps).
fn write_sigmf(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    use crate::dtmb::sigmf::SampleFormat;
    use crate::world::scene::TransmitterKind;
    let mut files = Vec::new();
    for t in world
        .transmitters
        .iter()
        .filter(|t| t.kind == TransmitterKind::Dtmb)
    {
        let req = crate::world::dtmb_iq::WorldIqRequest {
            tower: Some(t.id.clone()),
            from_s: 0.0,
            frames: SIGMF_FRAMES,
            seed: rec.seed,
            trial: rec.trial,
            data_layer: Default::default(),
        };
        let base = dir.join(format!("dtmb-{}", file_stem(&t.id)));
        crate::world::dtmb_iq::write_world_sigmf(world, &req, &base, SampleFormat::Cf32)
            .map_err(|e| e.to_string())?;
        files.push(base.with_extension("sigmf-data"));
        files.push(base.with_extension("sigmf-meta"));
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::trial::EstimatorTrace;

    #[test]
    fn estimator_file_stems_are_safe_and_unique() {
        let est = |name: &str| EstimatorTrace {
            name: name.into(),
            epochs: Vec::new(),
        };
        let rec = Recording {
            seed: 0,
            trial: 0,
            batches: Vec::new(),
            estimators: vec![est("GPS+BDS"), est("GPS BDS"), est("Truth"), est("a/b")],
        };
        assert_eq!(
            rec.estimator_stems(),
            ["GPS_BDS", "GPS_BDS-2", "Truth-2", "a_b"]
        );
    }

    #[test]
    fn format_lists() {
        assert_eq!(
            Format::parse_list("kml, NMEA,kml").unwrap(),
            [Format::Nmea, Format::Kml]
        );
        assert_eq!(Format::parse_list("all").unwrap(), Format::ALL);
        assert!(Format::parse_list("nmea,")
            .unwrap_err()
            .contains("unknown dataset format ''"));
    }
}
