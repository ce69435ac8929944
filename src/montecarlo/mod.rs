//! Monte Carlo: many trials of one world, in parallel, reduced in trial order.
//!
//! Trial `i` depends only on `(world, seed, i)`; results are collected in trial order
//! before any reduction, so the summary is bit-identical whatever the thread count. With a
//! run directory ([`store::RunDir`]) each trial is written to its own file the moment it
//! finishes, which is what makes `--resume` after an interruption and `merge` of shards
//! reproduce an uninterrupted run byte for byte.

pub mod outputs;
pub mod store;

use crate::engine::trial::{run_trial, TrialResult};
use crate::metrics::ErrorStats;
use crate::world::World;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use store::{Manifest, RunDir, Shard, STORE_FORMAT};

/// How to run.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    /// Trials of the whole run (a shard runs its part of them).
    pub trials: u64,
    pub seed: u64,
    /// Worker threads (1 runs on the calling thread's pool of one).
    pub threads: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// The part of the trials this process runs.
    pub shard: Shard,
}

impl RunOptions {
    /// The manifest a run directory of this run carries.
    pub fn manifest(&self, world: &World) -> Manifest {
        Manifest {
            format: STORE_FORMAT,
            hybridnav_version: env!("CARGO_PKG_VERSION").to_string(),
            world: world.file.world.name.clone(),
            world_file: world.path.display().to_string(),
            world_hash: world.hash.clone(),
            seed: self.seed,
            trials: self.trials,
            shard: self.shard,
        }
    }
}

/// One estimator's line of the summary.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EstimatorSummary {
    pub name: String,
    /// Statistics of the 3-D position error over every epoch of every trial.
    pub error_3d_m: Option<ErrorStats>,
    /// Statistics of the horizontal position error.
    pub error_h_m: Option<ErrorStats>,
    /// Share of measurement epochs with an estimate.
    pub availability: f64,
    /// Measurement epochs over all trials.
    pub epochs: usize,
    /// Epochs without an estimate.
    pub epochs_without_fix: usize,
    /// Mean position NEES (3 degrees of freedom; 3 for a consistent filter).
    pub mean_nees_pos: Option<f64>,
    /// Epochs where the estimator reported a numerical failure.
    pub numerical_failures: usize,
}

/// The content of `summary.json`.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    pub hybridnav_version: String,
    pub world: String,
    pub world_file: String,
    pub world_hash: String,
    pub seed: u64,
    pub trials: u64,
    /// `"K/N"` for the summary of one shard's trials; absent for a whole run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
    pub duration_s: f64,
    pub estimators: Vec<EstimatorSummary>,
    /// Distinct warnings of every trial's sources, sorted (a model used outside its
    /// validity range, …).
    pub warnings: Vec<String>,
}

/// Runs the trials of `opts.shard` and returns them in trial order, without a run
/// directory (nothing written).
///
/// # Errors
/// When the thread pool cannot be built or a trial cannot be set up.
pub fn run_trials(world: &World, opts: &RunOptions) -> Result<Vec<TrialResult>, String> {
    execute(world, opts, None, Vec::new())
}

/// Runs the trials of `opts.shard` into `dir`: writes the manifest, then each trial's file
/// as soon as it finishes. With `resume`, the trials the directory already holds are read
/// back instead of run (after checking that its manifest is this run's); without it, any
/// older trial files there are removed first.
///
/// Returns every trial of the shard in trial order.
///
/// # Errors
/// A message naming the file or the manifest key that stops the run.
pub fn run_into(
    world: &World,
    opts: &RunOptions,
    dir: &RunDir,
    resume: bool,
) -> Result<Vec<TrialResult>, String> {
    let manifest = opts.manifest(world);
    let existing = dir.read_manifest().map_err(|e| e.to_string())?;
    let mut done = Vec::new();
    if resume {
        match existing {
            None => {
                return Err(format!(
                    "--resume: {} holds no run to resume (no run.json); run without --resume",
                    dir.root.display()
                ))
            }
            Some(m) => {
                if let Some(why) = manifest.mismatch(&m, true) {
                    return Err(format!(
                        "--resume: {} holds a different run ({why}); resume it with the same \
                         world, --seed, --trials and --shard, or choose another --out",
                        dir.root.display()
                    ));
                }
            }
        }
        for i in opts.shard.trials(opts.trials) {
            if let Some(r) = dir.read_trial(i).map_err(|e| e.to_string())? {
                done.push(r);
            }
        }
    } else {
        dir.clear_trials().map_err(|e| e.to_string())?;
    }
    dir.write_manifest(&manifest).map_err(|e| e.to_string())?;
    execute(world, opts, Some(dir), done)
}

/// The common loop: runs the shard's trials that `done` lacks, writing each to `dir` (when
/// given) as it finishes, and returns all of them in trial order.
fn execute(
    world: &World,
    opts: &RunOptions,
    dir: Option<&RunDir>,
    done: Vec<TrialResult>,
) -> Result<Vec<TrialResult>, String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.max(1))
        .build()
        .map_err(|e| format!("cannot start {} worker threads: {e}", opts.threads))?;
    let have: std::collections::BTreeSet<u64> = done.iter().map(|r| r.trial).collect();
    let todo: Vec<u64> = opts
        .shard
        .trials(opts.trials)
        .filter(|i| !have.contains(i))
        .collect();
    let total = (todo.len() + done.len()) as u64;
    let bar = if opts.progress {
        ProgressBar::new(total)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} trials {pos}/{len} [{bar:30}] {per_sec} elapsed {elapsed} left {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_position(done.len() as u64);
    bar.reset_eta();
    let fresh = pool.install(|| {
        todo.par_iter()
            .map(|&i| {
                let r = run_trial(world, opts.seed, i).map_err(|e| format!("trial {i}: {e}"))?;
                if let Some(dir) = dir {
                    dir.write_trial(&r).map_err(|e| e.to_string())?;
                }
                bar.inc(1);
                Ok(r)
            })
            .collect::<Result<Vec<_>, String>>()
    });
    bar.finish_and_clear();
    let mut all = done;
    all.extend(fresh?);
    all.sort_by_key(|r| r.trial);
    Ok(all)
}

/// Reduces trials (in trial order) to the summary.
pub fn summarise(world: &World, opts: &RunOptions, trials: &[TrialResult]) -> Summary {
    let names: Vec<String> = world
        .file
        .estimators
        .iter()
        .map(|e| e.name.clone())
        .collect();
    let estimators = names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let mut e3 = Vec::new();
            let mut eh = Vec::new();
            let (mut epochs, mut without, mut failures) = (0usize, 0usize, 0usize);
            let (mut nees_sum, mut nees_n) = (0.0, 0usize);
            for t in trials {
                for ep in &t.estimators[k].epochs {
                    epochs += 1;
                    failures += usize::from(ep.numerical_failure);
                    match (ep.err_3d_m, ep.err_h_m) {
                        (Some(a), Some(b)) => {
                            e3.push(a);
                            eh.push(b);
                        }
                        _ => without += 1,
                    }
                    if let Some(n) = ep.nees_pos {
                        nees_sum += n;
                        nees_n += 1;
                    }
                }
            }
            EstimatorSummary {
                name: name.clone(),
                error_3d_m: ErrorStats::from_errors(&mut e3),
                error_h_m: ErrorStats::from_errors(&mut eh),
                availability: if epochs > 0 {
                    (epochs - without) as f64 / epochs as f64
                } else {
                    0.0
                },
                epochs,
                epochs_without_fix: without,
                mean_nees_pos: (nees_n > 0).then(|| nees_sum / nees_n as f64),
                numerical_failures: failures,
            }
        })
        .collect();
    Summary {
        hybridnav_version: env!("CARGO_PKG_VERSION").to_string(),
        world: world.file.world.name.clone(),
        world_file: world.path.display().to_string(),
        world_hash: world.hash.clone(),
        seed: opts.seed,
        trials: opts.trials,
        shard: (!opts.shard.is_whole()).then(|| opts.shard.to_string()),
        duration_s: world.duration_s,
        estimators,
        warnings: {
            let mut w: Vec<String> = trials.iter().flat_map(|t| t.warnings.clone()).collect();
            w.sort();
            w.dedup();
            w
        },
    }
}

impl Summary {
    /// The table printed after a run, in the papers' layout.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} — {} trial(s), seed {}",
            self.world, self.trials, self.seed
        );
        let _ = writeln!(
            s,
            "{:<16} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7}",
            "estimator", "1σ (m)", "2σ (m)", "3σ (m)", "mean", "std", "rmse", "max", "avail"
        );
        for e in &self.estimators {
            match &e.error_3d_m {
                Some(x) => {
                    let _ = writeln!(
                        s,
                        "{:<16} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>6.1}%",
                        e.name,
                        x.sigma1,
                        x.sigma2,
                        x.sigma3,
                        x.mean,
                        x.std,
                        x.rmse,
                        x.max,
                        100.0 * e.availability
                    );
                }
                None => {
                    let _ = writeln!(
                        s,
                        "{:<16} {:>9} (no estimate in any epoch) {:>6.1}%",
                        e.name,
                        "-",
                        100.0 * e.availability
                    );
                }
            }
        }
        let _ = writeln!(
            s,
            "(3-D position error percentiles 68.27/95.45/99.73 % over all epochs of all trials)"
        );
        s
    }
}

/// The files a run directory ends with, all computed from the trials alone.
#[derive(Clone, Debug)]
pub struct Written {
    pub summary: Summary,
    pub files: Vec<std::path::PathBuf>,
}

/// Writes `summary.json`, `epochs.csv`, `trials.parquet` and `report.html` of `trials`
/// into `out`,
/// each atomically.
///
/// # Errors
/// I/O and encoding errors, naming the file.
pub fn write_outputs(
    world: &World,
    opts: &RunOptions,
    trials: &[TrialResult],
    out: &std::path::Path,
) -> Result<Written, String> {
    use crate::io::atomic::write_atomic;
    let summary = summarise(world, opts, trials);
    let mut json = serde_json::to_string_pretty(&summary)
        .map_err(|e| format!("encoding summary.json: {e}"))?;
    json.push('\n');
    let mut files = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<(), String> {
        let p = out.join(name);
        write_atomic(&p, bytes).map_err(|e| e.to_string())?;
        files.push(p);
        Ok(())
    };
    put("summary.json", json.as_bytes())?;
    put("epochs.csv", outputs::epochs_csv(trials).as_bytes())?;
    let parquet = outputs::trials_parquet(&world.frame, trials)
        .map_err(|e| format!("encoding trials.parquet: {e}"))?;
    put("trials.parquet", &parquet)?;
    let report = crate::report::html(world, &summary, trials)?;
    put("report.html", report.as_bytes())?;
    Ok(Written { summary, files })
}
