//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The shared GNSS data directory, or `None` (with the reason printed) when absent.
pub fn shared_gnss() -> Option<PathBuf> {
    let p = repo().join("../shared/data/gnss");
    if p.join("brdc1820.10n").exists() {
        Some(p)
    } else {
        skip(&format!(
            "{} not found (the real GNSS files live in ../shared, which CI provides)",
            p.display()
        ));
        None
    }
}

/// Reports a cross-check that cannot run here because a tool or data file is missing.
///
/// Locally the test prints `skipped: REASON` and passes, so the crate tests anywhere. In CI
/// (`CI=true`) a missing oracle is a failure: `.ci/run` installs every tool, and a
/// comparison that silently did not run must not count as passed. When
/// `HYBRIDNAV_SKIP_LOG` names a file, the reason is also appended there, so `.ci/run` can
/// count skips separately from passes (cargo hides a passing test's output).
pub fn skip(reason: &str) {
    eprintln!("skipped: {reason}");
    if let Ok(log) = std::env::var("HYBRIDNAV_SKIP_LOG") {
        use std::io::Write;
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
        {
            let _ = writeln!(f, "{reason}");
        }
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("CI=true and a cross-check could not run: {reason}");
    }
}

/// A fresh temporary directory for one test.
pub fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hybridnav-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create temp dir");
    d
}

/// Runs the `hybridnav` binary.
pub fn hybridnav(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybridnav"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("run hybridnav")
}

/// The standard error of a finished command, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `hybridnav` with `args`, asserts that it refused them (exit code 2) with a message
/// containing every one of `needles`, and returns the message.
pub fn refused(args: &[&str], needles: &[&str]) -> String {
    let o = hybridnav(args);
    let e = stderr(&o);
    assert_eq!(
        o.status.code(),
        Some(2),
        "hybridnav {args:?} was not refused: {e}"
    );
    for n in needles {
        assert!(e.contains(n), "hybridnav {args:?}: expected {n:?} in: {e}");
    }
    e
}

/// The options of a whole (unsharded) in-process run on two threads, without a progress
/// bar: what the tests that call `run_trials` directly use.
pub fn run_options(trials: u64, seed: u64) -> hybridnav::montecarlo::RunOptions {
    hybridnav::montecarlo::RunOptions {
        trials,
        seed,
        threads: 2,
        progress: false,
        shard: hybridnav::montecarlo::store::Shard::WHOLE,
    }
}

/// Runs `hybridnav run WORLD --quiet --outputs summary --out OUT` with `extra` arguments
/// (trials, seed …), asserts that it succeeded, and returns its `summary.json`.
pub fn run_summary(world: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "run",
        world.to_str().expect("utf-8 path"),
        "--quiet",
        "--outputs",
        "summary",
        "--out",
        out.to_str().expect("utf-8 path"),
    ];
    args.extend_from_slice(extra);
    let o = hybridnav(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
        .expect("summary.json")
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write test file");
    p
}

/// The default world's text, with its ephemeris path (relative to `worlds/`) made absolute
/// so that a test can write the text, edited or not, into any directory.
pub fn default_world_text() -> String {
    let text =
        std::fs::read_to_string(repo().join("worlds/default.toml")).expect("read default world");
    let eph = repo().join("ephemeris");
    text.replace(
        "\"../ephemeris/",
        &format!("\"{}/", eph.display().to_string().replace('\\', "/")),
    )
}

/// Whether RTKLIB's `rnx2rtkp` can be started; prints why not (the test then reports
/// itself skipped; CI installs Debian's rtklib in `.ci/run`).
pub fn has_rnx2rtkp() -> bool {
    let found = Command::new("rnx2rtkp").arg("-?").output().is_ok();
    if !found {
        skip("rnx2rtkp not found (Debian package rtklib; .ci/run installs it)");
    }
    found
}

/// Whether `python3` can import every one of `modules`; prints why not (the test then
/// reports itself skipped; CI installs them in `.ci/run`).
pub fn python_has(modules: &[&str]) -> bool {
    let probe = format!("import {}", modules.join(", "));
    match Command::new("python3").args(["-c", &probe]).output() {
        Ok(o) if o.status.success() => true,
        Ok(o) => {
            skip(&format!(
                "python3 cannot import {}: {}",
                modules.join(", "),
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            ));
            false
        }
        Err(e) => {
            skip(&format!("python3 not found ({e})"));
            false
        }
    }
}
