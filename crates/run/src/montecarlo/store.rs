//! A run's directory: its manifest, one file per finished trial, and the merge of shards.
//!
//! ```text
//! OUT/.hybridnav.lock            the advisory lock of the process writing OUT (its pid)
//! OUT/run.json                   the manifest: world (name, file, hash), seed, trials, shard
//! OUT/trials/trial-000042.json.gz  trial 42's records (gzip'd JSON: `zcat` reads it),
//!                                stamped with the run's world hash, seed, trial count
//!                                and shard, written atomically when it finishes
//! OUT/summary.json …             the outputs, computed from the trial files alone
//! OUT/report/figures/*.svg       the report's charts, one standalone SVG each
//! ```
//!
//! Because every output is a function of the manifest and the trial files, a run that was
//! interrupted and resumed (`--resume`), or run as shards and merged, writes the same bytes
//! as one uninterrupted run.
//!
//! A directory belongs to one run. The process writing it holds an advisory lock
//! (`flock(2)` on `OUT/.hybridnav.lock`) from start to end, so a second run or merge into
//! it is refused with the holder's pid; a run into a directory that holds another run is
//! refused unless `--resume` (the same run) or `--force` (the old run is first renamed
//! aside whole, [`Takeover::Force`]); a resume checks every trial file's stamp, so trials
//! of two runs are never mixed; and the outputs of the previous attempt are removed
//! before the first trial runs, so no old summary sits beside a new manifest.

use crate::engine::trial::TrialResult;
use crate::io::atomic::write_atomic;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// The version of the trial-file and manifest layout; a resume or merge refuses others.
pub const STORE_FORMAT: u32 = 3;

/// The lock file in a run directory.
pub const LOCK_FILE: &str = ".hybridnav.lock";

/// The outputs a run writes from its trials, removed when a new attempt starts
/// (`summary.json` first: a directory with a summary is a complete run).
pub const OUTPUT_FILES: [&str; 4] = [
    "summary.json",
    "report.html",
    "epochs.csv",
    "trials.parquet",
];

/// Deflate level of the trial files: the fastest, which still shrinks a trial's JSON
/// about 4.8× (a Beihang trial: 1.8 MB → 0.38 MB) for ~10 % of the trial's own time; the
/// higher levels gain little more on decimal digits.
const TRIAL_GZIP_LEVEL: u32 = 1;

/// Which part of a run's trials a process runs: trials `i` with `i mod count == index`.
///
/// Round-robin rather than contiguous blocks, so that shards of a world whose trials grow
/// slower with `i` (none do today) would still take similar times.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 0-based shard index (`--shard 1/4` is index 0).
    pub index: u64,
    pub count: u64,
}

impl Shard {
    /// The whole run.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Parses `K/N` with 1 ≤ K ≤ N, as `--shard` takes it.
    ///
    /// # Errors
    /// A message saying what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad = || format!("--shard {text:?}: expected K/N with 1 ≤ K ≤ N, e.g. 2/4");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let k: u64 = k.trim().parse().map_err(|_| bad())?;
        let n: u64 = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k == 0 || k > n {
            return Err(bad());
        }
        Ok(Shard {
            index: k - 1,
            count: n,
        })
    }

    /// Parses `--shard` as [`Shard::parse`] does, and also `auto/N`, where K comes from the
    /// array-job scheduler running this process (`env` looks a variable up):
    ///
    /// - Slurm job arrays: K = `SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN` + 1, so
    ///   `--array=0-63` and `--array=1-64` both give shards 1…64; when Slurm says how many
    ///   tasks the array has (`SLURM_ARRAY_TASK_COUNT`), it must be N.
    /// - Kubernetes Indexed Jobs: K = `JOB_COMPLETION_INDEX` + 1 (the index is 0-based).
    ///
    /// # Errors
    /// A message naming the variable that is missing, malformed or inconsistent with N.
    pub fn parse_with_env(
        text: &str,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, String> {
        let Some(n_text) = text.trim().strip_prefix("auto/") else {
            return Shard::parse(text);
        };
        let n: u64 = n_text
            .trim()
            .parse()
            .ok()
            .filter(|n| *n > 0)
            .ok_or_else(|| format!("--shard {text:?}: expected auto/N with N ≥ 1, e.g. auto/64"))?;
        let int = |name: &str| -> Result<Option<u64>, String> {
            match env(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    format!("--shard auto: {name}={v:?} is not a non-negative integer")
                }),
            }
        };
        let k = if let Some(id) = int("SLURM_ARRAY_TASK_ID")? {
            if let Some(count) = int("SLURM_ARRAY_TASK_COUNT")? {
                if count != n {
                    return Err(format!(
                        "--shard auto/{n}: the Slurm array has {count} tasks \
                         (SLURM_ARRAY_TASK_COUNT), not {n}"
                    ));
                }
            }
            let min = int("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            id.checked_sub(min).map(|k| k + 1).ok_or_else(|| {
                format!(
                    "--shard auto: SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
                )
            })?
        } else if let Some(index) = int("JOB_COMPLETION_INDEX")? {
            index + 1
        } else {
            return Err(format!(
                "--shard auto/{n}: neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor \
                 JOB_COMPLETION_INDEX (a Kubernetes Indexed Job) is set; give --shard K/N"
            ));
        };
        if k > n {
            return Err(format!(
                "--shard auto/{n}: this task is shard {k}, beyond the {n} shards \
                 (is the array or the job's completions larger than N?)"
            ));
        }
        Ok(Shard {
            index: k - 1,
            count: n,
        })
    }

    /// Whether trial `i` belongs to this shard.
    pub fn contains(&self, i: u64) -> bool {
        i % self.count == self.index
    }

    /// The trials of this shard among `0..trials`, ascending.
    pub fn trials(&self, trials: u64) -> impl Iterator<Item = u64> + '_ {
        (self.index..trials).step_by(self.count as usize)
    }

    /// How many of `trials` trials are this shard's (computed, not counted).
    pub fn count(&self, trials: u64) -> u64 {
        if self.index >= trials {
            0
        } else {
            (trials - self.index - 1) / self.count + 1
        }
    }

    pub fn is_whole(&self) -> bool {
        self.count == 1
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index + 1, self.count)
    }
}

/// `OUT/run.json`: what a run directory holds, checked before resuming or merging.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: u32,
    pub hybridnav_version: String,
    pub world: String,
    /// The world file as the command line named it.
    pub world_file: String,
    pub world_hash: String,
    pub seed: u64,
    /// Trials of the whole run (not of this shard).
    pub trials: u64,
    pub shard: Shard,
}

/// What every trial file carries of its run, so that a trial of one run is never taken
/// for a trial of another: checked whenever a trial file is read back (resume, merge).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    pub format: u32,
    pub world_hash: String,
    pub seed: u64,
    /// Trials of the whole run.
    pub trials: u64,
    pub shard: Shard,
}

impl Stamp {
    /// Why `found` (a trial file's stamp) is not this run's, naming each differing key.
    fn mismatch(&self, found: &Stamp) -> Option<String> {
        let mut why = Vec::new();
        if self.format != found.format {
            why.push(format!(
                "store format {}, not {}",
                found.format, self.format
            ));
        }
        if self.world_hash != found.world_hash {
            why.push(format!(
                "world hash {}, not {}",
                short(&found.world_hash),
                short(&self.world_hash)
            ));
        }
        if self.seed != found.seed {
            why.push(format!("seed {}, not {}", found.seed, self.seed));
        }
        if self.trials != found.trials {
            why.push(format!("{} trials, not {}", found.trials, self.trials));
        }
        if self.shard != found.shard {
            why.push(format!("shard {}, not {}", found.shard, self.shard));
        }
        (!why.is_empty()).then(|| why.join(", "))
    }
}

/// A trial file as written: the stamp, then the trial.
#[derive(Serialize)]
struct TrialFileOut<'a> {
    stamp: &'a Stamp,
    trial: &'a TrialResult,
}

/// A trial file as read back.
#[derive(Deserialize)]
struct TrialFileIn {
    stamp: Stamp,
    trial: TrialResult,
}

impl Manifest {
    /// The stamp this run's trial files carry.
    pub fn stamp(&self) -> Stamp {
        Stamp {
            format: self.format,
            world_hash: self.world_hash.clone(),
            seed: self.seed,
            trials: self.trials,
            shard: self.shard,
        }
    }

    /// One line for messages: world, seed, trials, shard.
    pub fn describe(&self) -> String {
        format!(
            "world {} ({}), seed {}, {} trials{}",
            self.world,
            self.world_file,
            self.seed,
            self.trials,
            if self.shard.is_whole() {
                String::new()
            } else {
                format!(", shard {}", self.shard)
            }
        )
    }

    /// Why `other` (a directory's manifest) is not a continuation of or a sibling shard
    /// of `self`, or `None` when it is. Names each differing key.
    pub fn mismatch(&self, other: &Manifest, compare_shard: bool) -> Option<String> {
        let mut why = Vec::new();
        if self.format != other.format {
            why.push(format!("store format {} vs {}", self.format, other.format));
        }
        if self.world_hash != other.world_hash {
            why.push(format!(
                "world {} ({}, hash {}) vs {} ({}, hash {})",
                self.world,
                self.world_file,
                short(&self.world_hash),
                other.world,
                other.world_file,
                short(&other.world_hash)
            ));
        }
        if self.seed != other.seed {
            why.push(format!("seed {} vs {}", self.seed, other.seed));
        }
        if self.trials != other.trials {
            why.push(format!("trials {} vs {}", self.trials, other.trials));
        }
        if compare_shard && self.shard != other.shard {
            why.push(format!("shard {} vs {}", self.shard, other.shard));
        }
        (!why.is_empty()).then(|| why.join("; "))
    }
}

fn short(hash: &str) -> &str {
    &hash[..hash.len().min(12)]
}

/// Errors of reading and writing a run directory; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a hybridnav {what}: {message}")]
    Parse {
        path: PathBuf,
        what: &'static str,
        message: String,
    },
    #[error("{0}")]
    Refused(String),
}

/// How a run takes its output directory over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Takeover {
    /// A new run: the directory must not hold a run (no manifest, summary or trial file).
    Fresh,
    /// `--resume`: continue the run the directory holds (its manifest is checked by the
    /// run).
    Resume,
    /// `--force`: a run the directory holds is first renamed aside whole, to
    /// `OUT.previous-K` (K the smallest free number), and the new run starts empty.
    Force,
}

/// The advisory lock of a run directory: an exclusive `flock(2)` on its [`LOCK_FILE`]
/// (shared when a merge reads the directory), released when the last clone of the
/// [`RunDir`] is dropped or the process ends — also by `kill -9`, so a killed run never
/// leaves a stale lock.
#[derive(Debug)]
struct Lock {
    _file: std::fs::File,
}

impl Lock {
    /// Takes the lock of `root`, exclusive for a writer, shared for a reader; on success a
    /// writer records its pid in the file.
    fn take(root: &Path, exclusive: bool) -> Result<Self, StoreError> {
        use std::io::{Seek, Write};
        let path = root.join(LOCK_FILE);
        let io = |source| StoreError::Io {
            path: path.clone(),
            source,
        };
        let mut f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        match crate::io::lock::try_lock(&f, exclusive) {
            Ok(true) => {}
            Ok(false) => {
                let holder = std::fs::read_to_string(&path).unwrap_or_default();
                let holder = holder.trim();
                let who = if holder.is_empty() {
                    "another hybridnav process".to_string()
                } else {
                    format!("another hybridnav process ({holder})")
                };
                return Err(StoreError::Refused(format!(
                    "{} is in use by {who}: one directory, one run; wait for it to end or \
                     choose another --out",
                    root.display()
                )));
            }
            Err(e) => return Err(io(e)),
        }
        if exclusive {
            let me = format!(
                "pid {} on {}\n",
                std::process::id(),
                std::fs::read_to_string("/proc/sys/kernel/hostname")
                    .map(|h| h.trim().to_string())
                    .unwrap_or_else(|_| "this host".into())
            );
            f.set_len(0)
                .and_then(|()| f.rewind())
                .and_then(|()| f.write_all(me.as_bytes()))
                .map_err(io)?;
        }
        Ok(Self { _file: f })
    }
}

/// What a directory holds of a run, for the refusal of a fresh run into it.
fn holds_run(root: &Path) -> Option<String> {
    let manifest = root.join("run.json").is_file();
    let summary = root.join("summary.json").is_file();
    let trials = std::fs::read_dir(root.join("trials"))
        .map(|d| {
            d.flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with("trial-"))
                .count()
        })
        .unwrap_or(0);
    if !(manifest || summary || trials > 0) {
        return None;
    }
    let what = match RunDir::existing(root).read_manifest() {
        Ok(Some(m)) => format!("a run of {}", m.describe()),
        Ok(None) => "a run's outputs".to_string(),
        Err(e) => format!("an unreadable run ({e})"),
    };
    Some(format!(
        "{what}: {trials} trial file(s), {}",
        if summary { "complete" } else { "unfinished" }
    ))
}

/// A run's output directory, locked by this process while any clone of it lives.
#[derive(Clone, Debug)]
pub struct RunDir {
    pub root: PathBuf,
    lock: Option<std::sync::Arc<Lock>>,
}

impl RunDir {
    /// Opens (and creates) `root` and its `trials/` folder for a run, taking its lock.
    /// Equivalent to [`RunDir::take`] with [`Takeover::Resume`]: nothing in the
    /// directory is refused or moved (the caller checks the manifest).
    ///
    /// # Errors
    /// As [`RunDir::take`].
    pub fn create(root: &Path) -> Result<Self, StoreError> {
        Self::take(root, Takeover::Resume).map(|(d, _)| d)
    }

    /// Takes `root` over for a run or a merge: creates it, takes its lock (refused, with
    /// the holder's pid, while another process holds it), then applies `how` to a run the
    /// directory already holds — refuse ([`Takeover::Fresh`]), keep
    /// ([`Takeover::Resume`]) or rename aside ([`Takeover::Force`]; the new path is
    /// returned). Creates `trials/`, removes temporaries that dead processes left, and
    /// checks that the directory is writable (by writing a probe file, so an unwritable
    /// directory is reported before any trial runs, not after).
    ///
    /// # Errors
    /// [`StoreError::Refused`] naming the lock holder or the run the directory holds; I/O
    /// errors naming the path.
    pub fn take(root: &Path, how: Takeover) -> Result<(Self, Option<PathBuf>), StoreError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| StoreError::Io { path, source }
        };
        std::fs::create_dir_all(root).map_err(io(root))?;
        let mut lock = Lock::take(root, true)?;
        let mut aside = None;
        if let Some(what) = holds_run(root) {
            match how {
                Takeover::Resume => {}
                Takeover::Fresh => {
                    return Err(StoreError::Refused(format!(
                        "{} holds {what}; continue it with --resume, move it aside with \
                         --force (it is renamed, not deleted), or choose another --out",
                        root.display()
                    )))
                }
                Takeover::Force => {
                    let to = move_aside(root)?;
                    std::fs::create_dir_all(root).map_err(io(root))?;
                    // The moved directory's lock goes with it; the new one is taken
                    // before the old one is released.
                    lock = Lock::take(root, true)?;
                    aside = Some(to);
                }
            }
        }
        let trials = root.join("trials");
        std::fs::create_dir_all(&trials).map_err(io(&trials))?;
        // A process killed mid-write leaves hidden temporary files; the run that takes
        // the directory over removes them (never a live process's).
        for d in [root, trials.as_path()] {
            crate::io::atomic::remove_stale_temporaries(d).map_err(io(d))?;
        }
        let probe = root.join(".hybridnav-write-probe");
        write_atomic(&probe, b"").map_err(io(&probe))?;
        let _ = std::fs::remove_file(&probe);
        Ok((
            Self {
                root: root.to_path_buf(),
                lock: Some(std::sync::Arc::new(lock)),
            },
            aside,
        ))
    }

    /// Opens an existing run directory for reading, without creating or locking anything.
    pub fn existing(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
            lock: None,
        }
    }

    /// Opens an existing run directory for reading (a merge's input) under a shared lock,
    /// so that a shard still being written is refused rather than read half-done.
    ///
    /// # Errors
    /// [`StoreError::Refused`] naming the process writing it; I/O errors of the lock file
    /// (a directory that cannot hold one, e.g. read-only, is read without a lock).
    pub fn for_reading(root: &Path) -> Result<Self, StoreError> {
        let lock = match Lock::take(root, false) {
            Ok(l) => Some(std::sync::Arc::new(l)),
            Err(StoreError::Io { source, .. })
                if matches!(
                    source.kind(),
                    std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::ReadOnlyFilesystem
                ) =>
            {
                None
            }
            Err(StoreError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                return Err(StoreError::Refused(format!(
                    "{}: no such directory",
                    root.display()
                )))
            }
            Err(e) => return Err(e),
        };
        Ok(Self {
            root: root.to_path_buf(),
            lock,
        })
    }

    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("run.json")
    }

    pub fn trial_path(&self, trial: u64) -> PathBuf {
        self.root
            .join("trials")
            .join(format!("trial-{trial:06}.json.gz"))
    }

    /// Reads `run.json`; `Ok(None)` when the directory has none.
    ///
    /// # Errors
    /// When the file exists but cannot be read or parsed.
    pub fn read_manifest(&self) -> Result<Option<Manifest>, StoreError> {
        let path = self.manifest_path();
        let text = match crate::io::read::read_bytes(&path, crate::io::read::RUN_MANIFEST) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(StoreError::Io { path, source }),
        };
        serde_json::from_slice(&text)
            .map(Some)
            .map_err(|e| StoreError::Parse {
                path,
                what: "run manifest",
                message: e.to_string(),
            })
    }

    /// Writes `run.json` atomically.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_manifest(&self, m: &Manifest) -> Result<(), StoreError> {
        let path = self.manifest_path();
        let mut text = serde_json::to_string_pretty(m).map_err(|e| StoreError::Parse {
            path: path.clone(),
            what: "run manifest",
            message: e.to_string(),
        })?;
        text.push('\n');
        write_atomic(&path, text.as_bytes()).map_err(|source| StoreError::Io { path, source })
    }

    /// Removes the outputs of an earlier attempt ([`OUTPUT_FILES`], `summary.json` first,
    /// `datasets/` and `report/`), so that nothing of it sits beside the new run's manifest.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn remove_outputs(&self) -> Result<(), StoreError> {
        for name in OUTPUT_FILES {
            let path = self.root.join(name);
            match std::fs::remove_file(&path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(StoreError::Io { path, source }),
            }
        }
        // The datasets and the report's figures (`report/figures/`) are directories.
        for dir in ["datasets", "report"] {
            let path = self.root.join(dir);
            match std::fs::remove_dir_all(&path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(StoreError::Io { path, source }),
            }
        }
        crate::io::atomic::sync_dir(&self.root.join(OUTPUT_FILES[0])).map_err(|source| {
            StoreError::Io {
                path: self.root.clone(),
                source,
            }
        })
    }

    /// Writes one finished trial atomically, stamped with `stamp`.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_trial(&self, stamp: &Stamp, r: &TrialResult) -> Result<(), StoreError> {
        let path = self.trial_path(r.trial);
        use std::io::Write;
        let text = serde_json::to_vec(&TrialFileOut { stamp, trial: r }).map_err(|e| {
            StoreError::Parse {
                path: path.clone(),
                what: "trial file",
                message: e.to_string(),
            }
        })?;
        // The gzip header carries no time stamp or name (flate2 writes zeros), so the
        // bytes depend on the trial alone and merged runs stay byte-identical.
        let mut gz = flate2::write::GzEncoder::new(
            Vec::with_capacity(text.len() / 4),
            flate2::Compression::new(TRIAL_GZIP_LEVEL),
        );
        let bytes = gz
            .write_all(&text)
            .and_then(|()| gz.finish())
            .map_err(|source| StoreError::Io {
                path: path.clone(),
                source,
            })?;
        write_atomic(&path, &bytes).map_err(|source| StoreError::Io { path, source })
    }

    /// Reads trial `trial`, checking that its stamp is `stamp` (the trial belongs to this
    /// run); `Ok(None)` when it has not been written.
    ///
    /// # Errors
    /// When the file exists but cannot be read, does not parse, holds another trial, or
    /// belongs to another run (the message names the keys that differ).
    pub fn read_trial(&self, stamp: &Stamp, trial: u64) -> Result<Option<TrialResult>, StoreError> {
        let path = self.trial_path(trial);
        let bytes = match crate::io::read::read_bytes(&path, crate::io::read::TRIAL_FILE) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(StoreError::Io { path, source }),
        };
        let mut text = Vec::with_capacity(bytes.len() * 5);
        std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&bytes[..]), &mut text)
            .map_err(|e| StoreError::Parse {
                path: path.clone(),
                what: "trial file",
                message: format!("not gzip'd JSON: {e}"),
            })?;
        let f: TrialFileIn = serde_json::from_slice(&text).map_err(|e| StoreError::Parse {
            path: path.clone(),
            what: "trial file",
            message: format!(
                "{e} (a trial file of store format {STORE_FORMAT} starts with its run's stamp)"
            ),
        })?;
        if let Some(why) = stamp.mismatch(&f.stamp) {
            return Err(StoreError::Refused(format!(
                "{}: this trial belongs to another run ({why}); a directory holds one run's \
                 trials — remove the file, or run into another --out",
                path.display()
            )));
        }
        if f.trial.trial != trial {
            return Err(StoreError::Parse {
                path,
                what: "trial file",
                message: format!("it holds trial {}, not {trial}", f.trial.trial),
            });
        }
        Ok(Some(f.trial))
    }

    /// Removes every trial file.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn clear_trials(&self) -> Result<usize, StoreError> {
        let dir = self.root.join("trials");
        let entries = match std::fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            Err(source) => return Err(StoreError::Io { path: dir, source }),
        };
        let mut removed = 0;
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with("trial-") && (name.ends_with(".json.gz") || name.ends_with(".json"))
            {
                std::fs::remove_file(&path).map_err(|source| StoreError::Io { path, source })?;
                removed += 1;
            }
        }
        Ok(removed)
    }

    /// Whether this process holds the directory's lock.
    pub fn is_locked(&self) -> bool {
        self.lock.is_some()
    }
}

/// Renames `root` (which holds a run) to `root.previous-K`, K the smallest number free:
/// the name is reserved by creating an empty directory (which fails if it exists), and
/// the rename replaces that empty directory atomically, so the old run is moved whole —
/// never mixed with the new one, never half-moved — and nothing else is overwritten.
fn move_aside(root: &Path) -> Result<PathBuf, StoreError> {
    let name = root
        .file_name()
        .filter(|n| !n.is_empty())
        .ok_or_else(|| {
            StoreError::Refused(format!(
                "--force: {} cannot be moved aside (name the directory itself, not . or /)",
                root.display()
            ))
        })?
        .to_string_lossy()
        .into_owned();
    for k in 1..10_000 {
        let to = root.with_file_name(format!("{name}.previous-{k}"));
        match std::fs::create_dir(&to) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(source) => return Err(StoreError::Io { path: to, source }),
        }
        if let Err(source) = std::fs::rename(root, &to) {
            let _ = std::fs::remove_dir(&to);
            return Err(StoreError::Io {
                path: root.to_path_buf(),
                source,
            });
        }
        crate::io::atomic::sync_dir(&to).map_err(|source| StoreError::Io {
            path: to.clone(),
            source,
        })?;
        return Ok(to);
    }
    Err(StoreError::Refused(format!(
        "--force: {name}.previous-1 … 9999 all exist beside {}; remove some",
        root.display()
    )))
}

/// Which shard directory holds each trial of a run to merge; the trials themselves are
/// read one window at a time by [`crate::montecarlo::merge_into`].
#[derive(Debug)]
pub struct MergePlan {
    /// The merged run's manifest (the shards', with the whole run as its shard).
    pub manifest: Manifest,
    /// Each input directory (locked shared while the plan lives) and the stamp its trial
    /// files must carry.
    dirs: Vec<(RunDir, Stamp)>,
    /// `owner[i]`: the index in `dirs` of the directory holding trial `i`.
    owner: Vec<u32>,
}

impl MergePlan {
    /// Checks shard directories: every one must hold a manifest of the same world, seed
    /// and trial count, the shards must not overlap, and together they must hold every
    /// trial `0..trials`. Only file names are looked at here; contents are read (and
    /// checked) when merged.
    ///
    /// # Errors
    /// A message naming the directory and what disagrees, or the missing trials.
    pub fn new(dirs: &[PathBuf]) -> Result<Self, StoreError> {
        let mut first: Option<(PathBuf, Manifest)> = None;
        if dirs.is_empty() {
            return Err(StoreError::Refused(
                "merge: name at least one run directory".into(),
            ));
        }
        let mut owner: Vec<u32> = Vec::new();
        let mut opened = Vec::with_capacity(dirs.len());
        for (k, d) in dirs.iter().enumerate() {
            let dir = RunDir::for_reading(d)?;
            let m = dir.read_manifest()?.ok_or_else(|| {
                StoreError::Refused(format!(
                    "{}: no run.json here; not the output directory of `hybridnav run`",
                    d.display()
                ))
            })?;
            if let Some((p0, m0)) = &first {
                if let Some(why) = m0.mismatch(&m, false) {
                    return Err(StoreError::Refused(format!(
                        "cannot merge {} with {}: {why}",
                        d.display(),
                        p0.display()
                    )));
                }
            } else {
                let max = crate::world::schema::MAX_TRIALS;
                let n = usize::try_from(m.trials).ok().filter(|_| m.trials <= max);
                let Some(n) = n else {
                    return Err(StoreError::Refused(format!(
                        "{}: run.json says {} trials; expected at most {max}",
                        d.display(),
                        m.trials
                    )));
                };
                owner = vec![u32::MAX; n];
                first = Some((d.clone(), m.clone()));
            }
            for i in m.shard.trials(m.trials) {
                if !dir.trial_path(i).is_file() {
                    continue;
                }
                let slot = &mut owner[i as usize];
                if *slot != u32::MAX {
                    return Err(StoreError::Refused(format!(
                        "trial {i} is in both {} and {}: the same shard given twice?",
                        dirs[*slot as usize].display(),
                        d.display()
                    )));
                }
                *slot = k as u32;
            }
            opened.push((dir, m.stamp()));
        }
        let (_, mut manifest) = first.expect("at least one directory was read");
        let missing: Vec<u64> = (0..manifest.trials)
            .filter(|&i| owner[i as usize] == u32::MAX)
            .take(11)
            .collect();
        if !missing.is_empty() {
            let count = owner.iter().filter(|&&o| o == u32::MAX).count();
            let list: Vec<String> = missing.iter().take(10).map(u64::to_string).collect();
            return Err(StoreError::Refused(format!(
                "merge: {count} of {} trials are missing (e.g. {}{}); merge every shard, and \
                 resume unfinished ones with `hybridnav run … --shard K/N --resume`",
                manifest.trials,
                list.join(", "),
                if count > 10 { ", …" } else { "" }
            )));
        }
        manifest.shard = Shard::WHOLE;
        Ok(Self {
            manifest,
            dirs: opened,
            owner,
        })
    }

    /// The input directories.
    pub fn inputs(&self) -> impl Iterator<Item = &Path> {
        self.dirs.iter().map(|(d, _)| d.root.as_path())
    }

    /// Reads trial `i` from the directory that holds it.
    ///
    /// # Errors
    /// When the file cannot be read or parsed, or vanished since the plan was made.
    pub fn read(&self, i: u64) -> Result<TrialResult, String> {
        let (dir, stamp) = &self.dirs[self.owner[i as usize] as usize];
        dir.read_trial(stamp, i)
            .map_err(|e| e.to_string())?
            .ok_or_else(|| format!("{} vanished during the merge", dir.trial_path(i).display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_from_the_schedulers_environment() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(name, _)| *name == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "8"),
        ]);
        assert_eq!(
            Shard::parse_with_env("auto/8", slurm).unwrap(),
            Shard { index: 6, count: 8 }
        );
        let err = Shard::parse_with_env("auto/9", slurm).unwrap_err();
        assert!(err.contains("has 8 tasks"), "{err}");
        let k8s = env(&[("JOB_COMPLETION_INDEX", "0")]);
        assert_eq!(
            Shard::parse_with_env("auto/3", k8s).unwrap(),
            Shard { index: 0, count: 3 }
        );
        let err =
            Shard::parse_with_env("auto/3", env(&[("JOB_COMPLETION_INDEX", "3")])).unwrap_err();
        assert!(err.contains("shard 4, beyond the 3"), "{err}");
        let err = Shard::parse_with_env("auto/3", env(&[])).unwrap_err();
        assert!(err.contains("neither SLURM_ARRAY_TASK_ID"), "{err}");
        let err =
            Shard::parse_with_env("auto/3", env(&[("JOB_COMPLETION_INDEX", "x")])).unwrap_err();
        assert!(err.contains("JOB_COMPLETION_INDEX=\"x\""), "{err}");
        // Explicit K/N ignores the environment.
        assert_eq!(
            Shard::parse_with_env("2/3", k8s).unwrap(),
            Shard { index: 1, count: 3 }
        );
    }

    #[test]
    fn shard_parsing_and_membership() {
        let s = Shard::parse("2/4").unwrap();
        assert_eq!(s, Shard { index: 1, count: 4 });
        assert_eq!(s.to_string(), "2/4");
        assert_eq!(s.trials(10).collect::<Vec<_>>(), [1, 5, 9]);
        assert!(s.contains(5) && !s.contains(4));
        for (k, n, trials) in [
            (1, 1, 0),
            (1, 1, 7),
            (2, 4, 10),
            (4, 4, 3),
            (3, 3, 2),
            (5, 7, 100),
        ] {
            let s = Shard::parse(&format!("{k}/{n}")).unwrap();
            assert_eq!(
                s.count(trials),
                s.trials(trials).count() as u64,
                "{k}/{n} of {trials}"
            );
        }
        for bad in ["0/4", "5/4", "1/0", "x/2", "3", ""] {
            let e = Shard::parse(bad).unwrap_err();
            assert!(e.contains("expected K/N"), "{e}");
        }
        // The shards of a run partition its trials.
        let mut all: Vec<u64> = (1..=3)
            .flat_map(|k| {
                Shard::parse(&format!("{k}/3"))
                    .unwrap()
                    .trials(11)
                    .collect::<Vec<_>>()
            })
            .collect();
        all.sort_unstable();
        assert_eq!(all, (0..11).collect::<Vec<_>>());
    }
}
