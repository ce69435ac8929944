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
use crate::metrics::{
    ate_errors, mean_ci95, nees_summary, nis_summary, rpe_errors, Alignment, ConsistencySummary,
    ErrorStats, TrajectoryStats,
};
use crate::world::World;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
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
    /// Absolute trajectory error as seed 000 computes it (TUM definition, ECEF, no
    /// alignment), over every epoch with an estimate of every trial.
    pub ate_m: Option<TrajectoryStats>,
    /// The ATE after a rigid (Horn) alignment of each trial's trajectory to the truth.
    pub ate_aligned_m: Option<TrajectoryStats>,
    /// Relative pose error of the translation over Δ = 1 s, no alignment (seed 000).
    pub rpe_m: Option<TrajectoryStats>,
    /// The RPE after each trial's rigid alignment.
    pub rpe_aligned_m: Option<TrajectoryStats>,
    /// Position NEES (3 degrees of freedom) against its χ² bands over the trials.
    pub nees: Option<ConsistencySummary>,
    /// NIS (summed over each epoch's updates, with their summed dimensions as degrees of
    /// freedom) against its χ² bands. Particle filters have no innovation covariance and
    /// report none.
    pub nis: Option<ConsistencySummary>,
    /// Share of scored epochs in each integration mode (mode-selecting estimators only).
    pub modes: BTreeMap<String, f64>,
    /// How much each statistic varies from trial to trial: the 95 % confidence interval
    /// (Student t) of the mean over trials of each trial's own value.
    pub across_trials: AcrossTrials,
}

/// 95 % confidence intervals, across trials, of per-trial statistics (`[lo, hi]`; absent
/// with fewer than two trials with an estimate).
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct AcrossTrials {
    /// Trials that contributed (those with at least one estimate).
    pub trials: usize,
    pub sigma1_ci95_m: Option<[f64; 2]>,
    pub sigma2_ci95_m: Option<[f64; 2]>,
    pub sigma3_ci95_m: Option<[f64; 2]>,
    pub mean_ci95_m: Option<[f64; 2]>,
    pub rmse_ci95_m: Option<[f64; 2]>,
    pub ate_rmse_ci95_m: Option<[f64; 2]>,
    pub rpe_rmse_ci95_m: Option<[f64; 2]>,
    pub availability_ci95: Option<[f64; 2]>,
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

/// The trajectory of one trial's estimator: times, truth and estimate of the epochs with
/// an estimate.
struct Track {
    t_s: Vec<f64>,
    truth: Vec<nalgebra::Vector3<f64>>,
    est: Vec<nalgebra::Vector3<f64>>,
}

fn track(trace: &crate::engine::trial::EstimatorTrace) -> Track {
    let mut tr = Track {
        t_s: Vec::new(),
        truth: Vec::new(),
        est: Vec::new(),
    };
    for ep in &trace.epochs {
        if let Some(e) = ep.est_ecef_m {
            // Two batches at one instant (e.g. GNSS and FM) give two records with the
            // same time; the TUM metrics need one pose per time, the last one.
            if tr.t_s.last() == Some(&ep.t_s) {
                tr.t_s.pop();
                tr.truth.pop();
                tr.est.pop();
            }
            tr.t_s.push(ep.t_s);
            tr.truth.push(nalgebra::Vector3::from(ep.truth_ecef_m));
            tr.est.push(nalgebra::Vector3::from(e));
        }
    }
    tr
}

fn ci(values: &[f64]) -> Option<[f64; 2]> {
    mean_ci95(values).map(|(a, b)| [a, b])
}

/// Each trial's own value of the statistics [`AcrossTrials`] gives intervals of.
#[derive(Default)]
struct PerTrial {
    sigma1: Vec<f64>,
    sigma2: Vec<f64>,
    sigma3: Vec<f64>,
    mean: Vec<f64>,
    rmse: Vec<f64>,
    ate_rmse: Vec<f64>,
    rpe_rmse: Vec<f64>,
    availability: Vec<f64>,
}

impl PerTrial {
    fn intervals(&self) -> AcrossTrials {
        AcrossTrials {
            trials: self.sigma1.len(),
            sigma1_ci95_m: ci(&self.sigma1),
            sigma2_ci95_m: ci(&self.sigma2),
            sigma3_ci95_m: ci(&self.sigma3),
            mean_ci95_m: ci(&self.mean),
            rmse_ci95_m: ci(&self.rmse),
            ate_rmse_ci95_m: ci(&self.ate_rmse),
            rpe_rmse_ci95_m: ci(&self.rpe_rmse),
            availability_ci95: ci(&self.availability),
        }
    }
}

/// One estimator's line of the summary, from its traces in every trial.
fn estimator_summary(name: &str, k: usize, trials: &[TrialResult]) -> EstimatorSummary {
    let mut e3 = Vec::new();
    let mut eh = Vec::new();
    let (mut epochs, mut without, mut failures) = (0usize, 0usize, 0usize);
    let (mut nees_sum, mut nees_n) = (0.0, 0usize);
    let mut modes: BTreeMap<String, usize> = BTreeMap::new();
    let mut moded = 0usize;
    // NEES grouped by epoch time across trials (every trial has the same time grid).
    let mut nees_by_t: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    let mut nis_by_t: BTreeMap<u64, Vec<(f64, usize)>> = BTreeMap::new();
    let (mut ate, mut ate_al, mut rpe, mut rpe_al) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut per_trial = PerTrial::default();
    for t in trials {
        let Some(trace) = t.estimators.get(k) else {
            continue;
        };
        let mut trial_errs = Vec::new();
        // One NEES per time per trial: the last record of an instant with several
        // batches (GNSS and FM at the same second), as the TUM tracks below keep.
        let mut trial_nees: BTreeMap<u64, f64> = BTreeMap::new();
        let mut trial_nis: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
        for ep in &trace.epochs {
            epochs += 1;
            failures += usize::from(ep.numerical_failure);
            match (ep.err_3d_m, ep.err_h_m) {
                (Some(a), Some(b)) => {
                    e3.push(a);
                    eh.push(b);
                    trial_errs.push(a);
                }
                _ => without += 1,
            }
            if let Some(n) = ep.nees_pos {
                nees_sum += n;
                nees_n += 1;
                trial_nees.insert(ep.t_s.to_bits(), n);
            }
            if let Some(n) = ep.nis {
                // Several batches at one instant: their NIS add, as do their dimensions.
                let slot = trial_nis.entry(ep.t_s.to_bits()).or_insert((0.0, 0));
                slot.0 += n;
                slot.1 += ep.nis_dof as usize;
            }
            if let Some(m) = &ep.mode {
                *modes.entry(m.to_string()).or_default() += 1;
                moded += 1;
            }
        }
        for (t, n) in trial_nees {
            nees_by_t.entry(t).or_default().push(n);
        }
        for (t, n) in trial_nis {
            nis_by_t.entry(t).or_default().push(n);
        }
        let tr = track(trace);
        let a = ate_errors(&tr.truth, &tr.est, Alignment::None);
        let r = rpe_errors(&tr.t_s, &tr.truth, &tr.est, 1.0, Alignment::None);
        if let Some(v) = &a {
            ate.extend_from_slice(v);
        }
        if let Some(v) = &r {
            rpe.extend_from_slice(v);
        }
        if let Some(v) = ate_errors(&tr.truth, &tr.est, Alignment::Rigid) {
            ate_al.extend(v);
        }
        if let Some(v) = rpe_errors(&tr.t_s, &tr.truth, &tr.est, 1.0, Alignment::Rigid) {
            rpe_al.extend(v);
        }
        let n_ep = trace.epochs.len();
        if let Some(st) = ErrorStats::from_errors(&mut trial_errs) {
            per_trial.sigma1.push(st.sigma1);
            per_trial.sigma2.push(st.sigma2);
            per_trial.sigma3.push(st.sigma3);
            per_trial.mean.push(st.mean);
            per_trial.rmse.push(st.rmse);
            if let Some(v) = a.and_then(|mut v| TrajectoryStats::from_errors(&mut v)) {
                per_trial.ate_rmse.push(v.rmse);
            }
            if let Some(v) = r.and_then(|mut v| TrajectoryStats::from_errors(&mut v)) {
                per_trial.rpe_rmse.push(v.rmse);
            }
        }
        if n_ep > 0 {
            let with = trace.epochs.iter().filter(|e| e.err_3d_m.is_some()).count();
            per_trial.availability.push(with as f64 / n_ep as f64);
        }
    }
    let nees_epochs: Vec<Vec<f64>> = nees_by_t.into_values().collect();
    EstimatorSummary {
        name: name.to_string(),
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
        ate_m: TrajectoryStats::from_errors(&mut ate),
        ate_aligned_m: TrajectoryStats::from_errors(&mut ate_al),
        rpe_m: TrajectoryStats::from_errors(&mut rpe),
        rpe_aligned_m: TrajectoryStats::from_errors(&mut rpe_al),
        nees: nees_summary(&nees_epochs, 3),
        nis: nis_summary(&nis_by_t.into_values().collect::<Vec<_>>()),
        modes: modes
            .into_iter()
            .map(|(m, n)| (m, n as f64 / moded.max(1) as f64))
            .collect(),
        across_trials: per_trial.intervals(),
    }
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
        .map(|(k, name)| estimator_summary(name, k, trials))
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
            "{:<16} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7}",
            "estimator", "1σ", "2σ", "3σ", "rmse", "ATE", "ATE rms", "RPE", "RPE rms", "avail"
        );
        let f = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{x:.2}"));
        for e in &self.estimators {
            let x = e.error_3d_m.as_ref();
            let _ = writeln!(
                s,
                "{:<16} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6.1}%",
                e.name,
                f(x.map(|x| x.sigma1)),
                f(x.map(|x| x.sigma2)),
                f(x.map(|x| x.sigma3)),
                f(x.map(|x| x.rmse)),
                f(e.ate_m.as_ref().map(|a| a.mean)),
                f(e.ate_m.as_ref().map(|a| a.rmse)),
                f(e.rpe_m.as_ref().map(|a| a.mean)),
                f(e.rpe_m.as_ref().map(|a| a.rmse)),
                100.0 * e.availability
            );
        }
        let _ = writeln!(
            s,
            "(metres; σ-levels: 3-D error percentiles 68.27/95.45/99.73 % over all epochs of all trials;\n ATE/RPE: mean and RMSE, TUM definitions in ECEF, no alignment, RPE over 1 s)"
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
