//! A run's directory: its manifest, one file per finished trial, and the merge of shards.
//!
//! ```text
//! OUT/run.json                   the manifest: world (name, file, hash), seed, trials, shard
//! OUT/trials/trial-000042.json.gz  trial 42's records (gzip'd JSON: `zcat` reads it),
//!                                written atomically when it finishes
//! OUT/summary.json …             the outputs, computed from the trial files alone
//! ```
//!
//! Because every output is a function of the manifest and the trial files, a run that was
//! interrupted and resumed (`--resume`), or run as shards and merged, writes the same bytes
//! as one uninterrupted run.

use crate::engine::trial::TrialResult;
use crate::io::atomic::write_atomic;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// The version of the trial-file and manifest layout; a resume or merge refuses others.
pub const STORE_FORMAT: u32 = 2;

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

impl Manifest {
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

/// A run's output directory.
#[derive(Clone, Debug)]
pub struct RunDir {
    pub root: PathBuf,
}

impl RunDir {
    /// Opens (and creates) `root` and its `trials/` folder.
    ///
    /// # Errors
    /// When the directory cannot be created or written (checked by writing a probe file,
    /// so an unwritable directory is reported before any trial runs, not after).
    pub fn create(root: &Path) -> Result<Self, StoreError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| StoreError::Io { path, source }
        };
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
        Ok(Self {
            root: root.to_path_buf(),
        })
    }

    /// Opens an existing run directory for reading (merge), without creating anything.
    pub fn existing(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
        }
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
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(StoreError::Io { path, source }),
        };
        serde_json::from_str(&text)
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

    /// Writes one finished trial atomically.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_trial(&self, r: &TrialResult) -> Result<(), StoreError> {
        let path = self.trial_path(r.trial);
        use std::io::Write;
        let text = serde_json::to_vec(r).map_err(|e| StoreError::Parse {
            path: path.clone(),
            what: "trial file",
            message: e.to_string(),
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

    /// Reads trial `trial`; `Ok(None)` when it has not been written.
    ///
    /// # Errors
    /// When the file exists but cannot be read, does not parse, or holds another trial.
    pub fn read_trial(&self, trial: u64) -> Result<Option<TrialResult>, StoreError> {
        let path = self.trial_path(trial);
        let bytes = match std::fs::read(&path) {
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
        let r: TrialResult = serde_json::from_slice(&text).map_err(|e| StoreError::Parse {
            path: path.clone(),
            what: "trial file",
            message: e.to_string(),
        })?;
        if r.trial != trial {
            return Err(StoreError::Parse {
                path,
                what: "trial file",
                message: format!("it holds trial {}, not {trial}", r.trial),
            });
        }
        Ok(Some(r))
    }

    /// Removes every trial file (a fresh run into a directory that held an older one).
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
}

/// Which shard directory holds each trial of a run to merge; the trials themselves are
/// read one window at a time by [`crate::montecarlo::merge_into`].
#[derive(Debug)]
pub struct MergePlan {
    /// The merged run's manifest (the shards', with the whole run as its shard).
    pub manifest: Manifest,
    dirs: Vec<RunDir>,
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
        for (k, d) in dirs.iter().enumerate() {
            let dir = RunDir::existing(d);
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
            dirs: dirs.iter().map(|d| RunDir::existing(d)).collect(),
            owner,
        })
    }

    /// Reads trial `i` from the directory that holds it.
    ///
    /// # Errors
    /// When the file cannot be read or parsed, or vanished since the plan was made.
    pub fn read(&self, i: u64) -> Result<TrialResult, String> {
        let dir = &self.dirs[self.owner[i as usize] as usize];
        dir.read_trial(i)
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
