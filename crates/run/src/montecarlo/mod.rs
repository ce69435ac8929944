//! Monte Carlo: many trials of one world, in parallel, reduced in trial order.
//!
//! Trial `i` depends only on `(world, seed, i)`. Trials run in parallel a window at a
//! time and are handed on in trial order — to their own files in the run directory
//! ([`store::RunDir`]), to the streamed outputs (`epochs.csv`, `trials.parquet`) and to
//! the [`reduce::RunReducer`] — so every output is bit-identical whatever the thread
//! count, and memory does not grow with the number of trials. Because each trial's file is
//! written the moment it finishes and the outputs are a function of those files, a run
//! resumed after an interruption (`--resume`) or merged from shards reproduces an
//! uninterrupted run byte for byte.

pub mod outputs;
pub mod reduce;
pub mod store;

use crate::engine::trial::TrialResult;
use crate::io::atomic::AtomicFile;
pub use crate::metrics::summary::{AcrossTrials, EstimatorSummary, FailureEpoch, Summary};
use crate::world::trial::run_trial;
use crate::world::World;
use indicatif::{ProgressBar, ProgressStyle};
pub use outputs::OutputSet;
use rayon::prelude::*;
use store::{Manifest, RunDir, Shard, Stamp, STORE_FORMAT};

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

/// The most worker threads `--threads` starts.
pub const MAX_THREADS: usize = 4096;

/// Trials in memory at once per worker thread: enough to keep every thread busy while
/// the slowest trial of a window finishes, few enough that memory stays flat.
const WINDOW_PER_THREAD: usize = 8;

/// Runs the trials of `opts.shard` and returns them in trial order, without a run
/// directory (nothing written). For benchmarks and tests; a run of many trials should
/// stream them instead ([`run_into`]).
///
/// # Errors
/// When the thread pool cannot be built or a trial cannot be set up.
pub fn run_trials(world: &World, opts: &RunOptions) -> Result<Vec<TrialResult>, String> {
    let mut all = Vec::new();
    execute(world, opts, None, &|_| false, &mut |t| {
        all.push(t);
        Ok(())
    })?;
    Ok(all)
}

/// Runs the trials of `opts.shard` into `dir` and writes every output there; see
/// [`run_into_with`].
///
/// # Errors
/// As [`run_into_with`].
pub fn run_into(
    world: &World,
    opts: &RunOptions,
    dir: &RunDir,
    resume: bool,
) -> Result<Written, String> {
    run_into_with(world, opts, dir, resume, OutputSet::ALL)
}

/// Runs the trials of `opts.shard` into `dir` and writes the run's outputs there: the
/// outputs of an earlier attempt are removed first (`summary.json` first), then the
/// manifest is written, each trial's file as soon as it finishes (stamped with the run's
/// world hash, seed, trial count and shard), then `epochs.csv`, `trials.parquet`,
/// `report.html` and, last, `summary.json`, streamed as the trials come in trial order —
/// those of `outputs` (`summary.json` and `run.json` always). With `resume`, the trials
/// the directory already holds are read back instead of run, after checking that its
/// manifest and each trial's stamp are this run's; without it, any older trial files
/// there are removed first.
///
/// # Errors
/// A message naming the file or the manifest key that stops the run. Trial files finished
/// before the error stay complete and readable: `--resume` continues from them.
pub fn run_into_with(
    world: &World,
    opts: &RunOptions,
    dir: &RunDir,
    resume: bool,
    outputs: OutputSet,
) -> Result<Written, String> {
    let manifest = opts.manifest(world);
    let existing = dir.read_manifest().map_err(|e| e.to_string())?;
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
    } else {
        dir.clear_trials().map_err(|e| e.to_string())?;
    }
    dir.remove_outputs().map_err(|e| e.to_string())?;
    dir.write_manifest(&manifest).map_err(|e| e.to_string())?;
    let mut out = Outputs::create(world, &dir.root, outputs)?;
    let has = |i: u64| resume && dir.trial_path(i).is_file();
    let store = Store {
        dir,
        stamp: manifest.stamp(),
        write: outputs.trials,
    };
    execute(world, opts, Some(&store), &has, &mut |t| out.push(&t))?;
    out.finish(world, opts)
}

/// Where [`execute`] reads stored trials from and writes finished ones to.
struct Store<'a> {
    dir: &'a RunDir,
    /// The stamp the run's trial files carry.
    stamp: Stamp,
    /// Whether finished trials are written (`--outputs` without `trials` does not).
    write: bool,
}

/// Where trials go, in trial order.
type Sink<'a> = dyn FnMut(TrialResult) -> Result<(), String> + Send + 'a;

/// Produces the trials `ids` on `pool` a window ([`WINDOW_PER_THREAD`] per thread) at a
/// time, in parallel within a window, and hands them to `sink` in the order of `ids`. The
/// sink consumes one window while the pool produces the next, so its serial work (the
/// streamed outputs) overlaps the trials; at most two windows are in memory.
fn in_windows(
    pool: &rayon::ThreadPool,
    mut ids: impl Iterator<Item = u64>,
    produce: &(dyn Fn(u64) -> Result<TrialResult, String> + Sync),
    sink: &mut Sink<'_>,
) -> Result<(), String> {
    let size = pool.current_num_threads().max(1) * WINDOW_PER_THREAD;
    let mut window: Vec<u64> = Vec::with_capacity(size);
    let mut pending: Vec<Result<TrialResult, String>> = Vec::new();
    loop {
        window.clear();
        window.extend(ids.by_ref().take(size));
        if window.is_empty() && pending.is_empty() {
            return Ok(());
        }
        let consume = std::mem::take(&mut pending);
        let (done, consumed) = pool.install(|| {
            rayon::join(
                || window.par_iter().map(|&i| produce(i)).collect::<Vec<_>>(),
                || -> Result<(), String> {
                    for r in consume {
                        sink(r?)?;
                    }
                    Ok(())
                },
            )
        });
        consumed?;
        pending = done;
    }
}

/// The common loop: runs the shard's trials in windows of [`WINDOW_PER_THREAD`] per
/// thread, in parallel within a window, and hands each to `sink` in trial order. A trial
/// with `stored(i)` is read back from `dir` instead of run; a trial that is run is written
/// to `dir` (when given) as soon as it finishes.
fn execute(
    world: &World,
    opts: &RunOptions,
    dir: Option<&Store<'_>>,
    stored: &(dyn Fn(u64) -> bool + Sync),
    sink: &mut Sink<'_>,
) -> Result<(), String> {
    let threads = opts.threads.max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start {} worker threads: {e}", opts.threads))?;
    let total = opts.shard.count(opts.trials);
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
    let one = |i: u64| -> Result<TrialResult, String> {
        if let Some(s) = dir.filter(|_| stored(i)) {
            if let Some(r) = s.dir.read_trial(&s.stamp, i).map_err(|e| e.to_string())? {
                return Ok(r);
            }
        }
        let r = run_trial(world, opts.seed, i).map_err(|e| format!("trial {i}: {e}"))?;
        if let Some(s) = dir.filter(|s| s.write) {
            s.dir.write_trial(&s.stamp, &r).map_err(|e| e.to_string())?;
        }
        Ok(r)
    };
    let produce = |i: u64| {
        let r = one(i);
        bar.inc(1);
        r
    };
    in_windows(&pool, opts.shard.trials(opts.trials), &produce, sink)?;
    bar.finish_and_clear();
    Ok(())
}

/// Where, under a run's directory, the report's charts are written one SVG file each.
pub const FIGURES_DIR: &str = "report/figures";

/// The outputs of a run, written as its trials stream past in trial order.
struct Outputs {
    dir: std::path::PathBuf,
    csv: Option<outputs::EpochsCsv<AtomicFile>>,
    parquet: Option<outputs::TrialsParquet<AtomicFile>>,
    report: bool,
    reducer: reduce::RunReducer,
}

impl Outputs {
    fn create(world: &World, dir: &std::path::Path, which: OutputSet) -> Result<Self, String> {
        let open = |name: &str| AtomicFile::create(&dir.join(name)).map_err(|e| e.to_string());
        let csv = if which.epochs {
            Some(outputs::EpochsCsv::new(open("epochs.csv")?).map_err(|e| e.to_string())?)
        } else {
            None
        };
        let parquet = if which.parquet {
            Some(
                outputs::TrialsParquet::new(open("trials.parquet")?, &world.frame).map_err(
                    |e| format!("writing {}: {e}", dir.join("trials.parquet").display()),
                )?,
            )
        } else {
            None
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            csv,
            parquet,
            report: which.report,
            reducer: reduce::RunReducer::new(world, dir),
        })
    }

    fn push(&mut self, t: &TrialResult) -> Result<(), String> {
        let path = |n: &str| self.dir.join(n).display().to_string();
        if let Some(csv) = &mut self.csv {
            csv.push(t)
                .map_err(|e| format!("writing {}: {e}", path("epochs.csv")))?;
        }
        if let Some(parquet) = &mut self.parquet {
            parquet
                .push(t)
                .map_err(|e| format!("writing {}: {e}", path("trials.parquet")))?;
        }
        self.reducer.push(t)
    }

    /// Publishes every output; `summary.json` last, so a directory with a summary is a
    /// complete run.
    fn finish(self, world: &World, opts: &RunOptions) -> Result<Written, String> {
        let dir = self.dir;
        let path = |n: &str| dir.join(n);
        let commit = |f: AtomicFile| f.commit().map_err(|e| e.to_string());
        let mut files = Vec::new();
        if let Some(csv) = self.csv {
            commit(
                csv.finish()
                    .map_err(|e| format!("writing {}: {e}", path("epochs.csv").display()))?,
            )?;
            files.push(path("epochs.csv"));
        }
        if let Some(parquet) = self.parquet {
            commit(
                parquet
                    .finish()
                    .map_err(|e| format!("writing {}: {e}", path("trials.parquet").display()))?,
            )?;
            files.push(path("trials.parquet"));
        }
        let reduce::Reduced {
            summary,
            first,
            curves,
        } = self.reducer.finish(world, opts)?;
        if self.report {
            let report = crate::report::render(world, &summary, first.as_ref(), &curves)?;
            // Each chart also as its own SVG file, for papers: `report/figures/NAME.svg`.
            let figures = path(FIGURES_DIR);
            std::fs::create_dir_all(&figures)
                .map_err(|e| format!("creating {}: {e}", figures.display()))?;
            for (name, svg) in &report.figures {
                let file = figures.join(name);
                crate::io::atomic::write_atomic(&file, svg.as_bytes())
                    .map_err(|e| format!("writing {}: {e}", file.display()))?;
            }
            crate::io::atomic::write_atomic(&path("report.html"), report.html.as_bytes())
                .map_err(|e| e.to_string())?;
            files.push(path("report.html"));
            // The figures' directory, once, rather than each of its files.
            files.push(figures);
        }
        let mut json = serde_json::to_string_pretty(&summary)
            .map_err(|e| format!("encoding summary.json: {e}"))?;
        json.push('\n');
        crate::io::atomic::write_atomic(&path("summary.json"), json.as_bytes())
            .map_err(|e| e.to_string())?;
        files.insert(0, path("summary.json"));
        Ok(Written { summary, files })
    }
}

/// Merges the shard directories `dirs` (their manifests agree and together they hold
/// every trial) into `out`: copies each trial file (checking its stamp against its
/// shard's manifest, and stamping the copy as the whole run's) and writes the outputs of
/// the whole run, streaming the trials in order as [`run_into`] does; `outputs` as
/// [`run_into_with`]. Returns the merged summary.
///
/// # Errors
/// A message naming the directory, file or manifest key at fault.
pub fn merge_into(
    world: &World,
    plan: &store::MergePlan,
    out: &RunDir,
    outputs: OutputSet,
) -> Result<Written, String> {
    let opts = RunOptions {
        trials: plan.manifest.trials,
        seed: plan.manifest.seed,
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        progress: false,
        shard: Shard::WHOLE,
    };
    out.clear_trials().map_err(|e| e.to_string())?;
    out.remove_outputs().map_err(|e| e.to_string())?;
    let manifest = opts.manifest(world);
    out.write_manifest(&manifest).map_err(|e| e.to_string())?;
    let stamp = manifest.stamp();
    let which = outputs;
    let mut outputs = Outputs::create(world, &out.root, which)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| format!("cannot start worker threads: {e}"))?;
    let copy = |i: u64| {
        let r = plan.read(i)?;
        if which.trials {
            out.write_trial(&stamp, &r).map_err(|e| e.to_string())?;
        }
        Ok(r)
    };
    in_windows(&pool, 0..opts.trials, &copy, &mut |t| outputs.push(&t))?;
    outputs.finish(world, &opts)
}

/// Reduces trials (in trial order) to the summary; spilled errors, if any, go to the
/// system's temporary directory.
///
/// # Errors
/// When spilled errors cannot be written or read back.
pub fn summarise(
    world: &World,
    opts: &RunOptions,
    trials: &[TrialResult],
) -> Result<Summary, String> {
    let mut r = reduce::RunReducer::new(world, &std::env::temp_dir());
    for t in trials {
        r.push(t)?;
    }
    Ok(r.finish(world, opts)?.summary)
}

/// The files a run directory ends with, all computed from the trials alone.
#[derive(Clone, Debug)]
pub struct Written {
    pub summary: Summary,
    pub files: Vec<std::path::PathBuf>,
}
