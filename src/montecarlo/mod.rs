//! Monte Carlo: many trials of one world, in parallel, reduced in trial order.
//!
//! Trial `i` depends only on `(world, seed, i)`; results are collected in trial order
//! before any reduction, so the summary is bit-identical whatever the thread count.

use crate::engine::trial::{run_trial, TrialResult};
use crate::metrics::ErrorStats;
use crate::world::World;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;

/// How to run.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    pub trials: u64,
    pub seed: u64,
    /// Worker threads (1 runs on the calling thread's pool of one).
    pub threads: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
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
    pub duration_s: f64,
    pub estimators: Vec<EstimatorSummary>,
    /// Distinct warnings of every trial's sources, sorted (a model used outside its
    /// validity range, …).
    pub warnings: Vec<String>,
}

/// Runs the trials and returns them in trial order.
///
/// # Errors
/// When the thread pool cannot be built.
pub fn run_trials(world: &World, opts: &RunOptions) -> Result<Vec<TrialResult>, String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.max(1))
        .build()
        .map_err(|e| format!("cannot start {} worker threads: {e}", opts.threads))?;
    let bar = if opts.progress {
        ProgressBar::new(opts.trials)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} trials {pos}/{len} [{bar:30}] {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let results = pool.install(|| {
        (0..opts.trials)
            .into_par_iter()
            .map(|i| {
                let r = run_trial(world, opts.seed, i);
                bar.inc(1);
                r
            })
            .collect::<Result<Vec<_>, _>>()
    });
    bar.finish_and_clear();
    results
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

/// Every estimator's epochs of every trial as CSV (one row per trial, estimator and epoch;
/// empty cells where an estimator had no estimate), for pandas and spreadsheets.
///
/// Columns: `trial, estimator, t_s, err_3d_m, err_h_m, nees_pos, pos_sigma_m, used,
/// rejected, rejected_gate, mean_nis, gdop, mode, numerical_failure`. Rows are in trial order, then the world's estimator order, then
/// time, so the file is identical for any thread count.
pub fn epochs_csv(results: &[TrialResult]) -> String {
    use std::fmt::Write;
    let mut s = String::from(
        "trial,estimator,t_s,err_3d_m,err_h_m,nees_pos,pos_sigma_m,used,rejected,rejected_gate,mean_nis,gdop,mode,numerical_failure\n",
    );
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    let mut sorted: Vec<&TrialResult> = results.iter().collect();
    sorted.sort_by_key(|r| r.trial);
    for r in sorted {
        for est in &r.estimators {
            // Names are free text: quote them as CSV requires.
            let name = format!("\"{}\"", est.name.replace('"', "\"\""));
            for e in &est.epochs {
                let _ = writeln!(
                    s,
                    "{},{},{:.3},{},{},{},{},{},{},{},{},{},{},{}",
                    r.trial,
                    name,
                    e.t_s,
                    opt(e.err_3d_m),
                    opt(e.err_h_m),
                    opt(e.nees_pos),
                    opt(e.pos_sigma_m),
                    e.used,
                    e.rejected,
                    e.rejected_gate,
                    opt(e.mean_nis),
                    opt(e.gdop),
                    e.mode.unwrap_or(""),
                    u8::from(e.numerical_failure)
                );
            }
        }
    }
    s
}
