//! Monte Carlo runs as a user drives them: shards merged, runs killed and resumed, the
//! Parquet table read by pandas, and the refusals of bad arguments.

use crate::common::{hybridnav, refused, repo, stderr, tmp_dir};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The files of a finished run directory that must not depend on how it was produced.
const OUTPUTS: [&str; 4] = ["summary.json", "epochs.csv", "trials.parquet", "run.json"];

fn ok(o: std::process::Output) -> std::process::Output {
    assert!(o.status.success(), "hybridnav failed: {}", stderr(&o));
    o
}

pub(crate) fn trial_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir.join("trials"))
        .map(|rd| {
            rd.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("trial-") && n.ends_with(".json.gz"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Asserts that two run directories hold byte-identical outputs and trial files.
pub(crate) fn assert_same_run(a: &Path, b: &Path) {
    for f in OUTPUTS {
        let x = std::fs::read(a.join(f)).unwrap_or_else(|e| panic!("{}: {e}", a.join(f).display()));
        let y = std::fs::read(b.join(f)).unwrap_or_else(|e| panic!("{}: {e}", b.join(f).display()));
        assert!(
            x == y,
            "{f} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
    let (ta, tb) = (trial_files(a), trial_files(b));
    assert_eq!(ta, tb);
    for t in &ta {
        let x = std::fs::read(a.join("trials").join(t)).unwrap();
        let y = std::fs::read(b.join("trials").join(t)).unwrap();
        assert!(x == y, "trials/{t} differs");
    }
}

#[test]
fn four_shards_merged_equal_the_unsharded_run_byte_for_byte() {
    let d = tmp_dir("mc-shards");
    let whole = d.join("whole");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    ok(hybridnav(&[
        "run",
        "--trials",
        "10",
        "--seed",
        "7",
        "--quiet",
        "--out",
        &s(&whole),
    ]));
    let mut shard_dirs = Vec::new();
    for k in 1..=4 {
        let sd = d.join(format!("shard{k}"));
        // Different thread counts per shard: the split must not matter either.
        let threads = if k % 2 == 0 { "1" } else { "2" };
        ok(hybridnav(&[
            "run",
            "--trials",
            "10",
            "--seed",
            "7",
            "--quiet",
            "--threads",
            threads,
            "--shard",
            &format!("{k}/4"),
            "--out",
            &s(&sd),
        ]));
        // A shard holds only its own trials (k−1, k−1+4, …) and says so in its summary.
        let expect: Vec<String> = (k - 1..10)
            .step_by(4)
            .map(|i| format!("trial-{i:06}.json.gz"))
            .collect();
        assert_eq!(trial_files(&sd), expect);
        let summary = std::fs::read_to_string(sd.join("summary.json")).unwrap();
        assert!(
            summary.contains(&format!("\"shard\": \"{k}/4\"")),
            "{summary}"
        );
        shard_dirs.push(s(&sd));
    }
    let merged = d.join("merged");
    let mut args = vec!["merge".to_string()];
    // Shards in any order.
    args.extend(shard_dirs.iter().rev().cloned());
    args.extend(["--out".into(), s(&merged), "--quiet".into()]);
    let argv: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(hybridnav(&argv));
    assert_same_run(&whole, &merged);

    // Merging with a shard missing names what is missing; a shard given twice is refused.
    refused(
        &[
            "merge",
            &shard_dirs[0],
            &shard_dirs[1],
            "--out",
            &s(&d.join("x")),
        ],
        &["4 of 10 trials are missing (e.g. 2, 3, 6, 7)"],
    );
    refused(
        &[
            "merge",
            &shard_dirs[0],
            &shard_dirs[0],
            &shard_dirs[1],
            &shard_dirs[2],
            &shard_dirs[3],
            "--out",
            &s(&d.join("x")),
        ],
        &["given twice"],
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn merging_shards_of_different_seeds_or_worlds_is_refused() {
    let d = tmp_dir("mc-mismatch");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    let (a, b, c) = (d.join("a"), d.join("b"), d.join("c"));
    ok(hybridnav(&[
        "run",
        "--trials",
        "4",
        "--seed",
        "1",
        "--shard",
        "1/2",
        "--quiet",
        "--out",
        &s(&a),
    ]));
    ok(hybridnav(&[
        "run",
        "--trials",
        "4",
        "--seed",
        "2",
        "--shard",
        "2/2",
        "--quiet",
        "--out",
        &s(&b),
    ]));
    refused(
        &["merge", &s(&a), &s(&b), "--out", &s(&d.join("m"))],
        &["seed 1 vs 2"],
    );
    ok(hybridnav(&[
        "run",
        "worlds/seed002-lianhua.toml",
        "--trials",
        "4",
        "--seed",
        "1",
        "--shard",
        "2/2",
        "--quiet",
        "--out",
        &s(&c),
    ]));
    refused(
        &["merge", &s(&a), &s(&c), "--out", &s(&d.join("m"))],
        &["cannot merge", "seed002-lianhua.toml"],
    );
    // A directory that is not a run.
    let elsewhere = tmp_dir("mc-mismatch-out");
    refused(
        &["merge", &s(&d), "--out", &s(&elsewhere.join("m"))],
        &["no run.json"],
    );
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&elsewhere);
}

/// Kills a real run with SIGKILL once it has finished a few trials, resumes it, and
/// compares every output with an uninterrupted run's.
#[test]
fn a_killed_run_resumed_equals_an_uninterrupted_one() {
    let d = tmp_dir("mc-resume");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    // A world with trials slow enough (~0.3 s each on one thread) to be caught midway.
    let world = "worlds/seed004-bupt.toml";
    let trials = "12";
    let whole = d.join("whole");
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        trials,
        "--quiet",
        "--out",
        &s(&whole),
    ]));

    let killed = d.join("killed");
    let mut child = Command::new(env!("CARGO_BIN_EXE_hybridnav"))
        .args([
            "run",
            world,
            "--trials",
            trials,
            "--threads",
            "1",
            "--quiet",
            "--out",
        ])
        .arg(&killed)
        .current_dir(repo())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start hybridnav");
    let start = Instant::now();
    while trial_files(&killed).len() < 3 && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("kill the run");
    let _ = child.wait();
    let done = trial_files(&killed).len();
    assert!(
        (3..12).contains(&done),
        "the run should have been killed midway, but {done} of 12 trials were written"
    );
    assert!(
        !killed.join("summary.json").exists(),
        "a killed run wrote its summary"
    );

    // Resuming with another seed or trial count is refused, naming the difference.
    refused(
        &[
            "run",
            world,
            "--trials",
            "13",
            "--resume",
            "--quiet",
            "--out",
            &s(&killed),
        ],
        &["trials 13 vs 12"],
    );

    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        trials,
        "--resume",
        "--quiet",
        "--out",
        &s(&killed),
    ]));
    assert_same_run(&whole, &killed);
    // No temporary file of the killed process survives in the outputs that matter: they
    // are all named and compared above, and the trial list equals the whole run's.
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_output_directories_and_resumes_are_refused_clearly() {
    let d = tmp_dir("mc-bad-out");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    // A file where the output directory should be.
    let file = d.join("not-a-dir");
    std::fs::write(&file, "x").unwrap();
    refused(
        &["run", "--trials", "1", "--quiet", "--out", &s(&file)],
        &["cannot write to output directory", "not-a-dir"],
    );
    // A read-only directory (unless we are root, who may write anyway).
    let ro = d.join("ro");
    std::fs::create_dir_all(ro.join("trials")).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::write(ro.join("probe"), "x").is_err() {
        refused(
            &["run", "--trials", "1", "--quiet", "--out", &s(&ro)],
            &["cannot write to output directory"],
        );
    } else {
        println!("skipped: running as root, a read-only directory is still writable");
    }
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    // --resume where there is nothing to resume; a malformed --shard.
    refused(
        &[
            "run",
            "--trials",
            "1",
            "--resume",
            "--quiet",
            "--out",
            &s(&d.join("new")),
        ],
        &["no run to resume"],
    );
    refused(
        &[
            "run",
            "--trials",
            "4",
            "--shard",
            "5/4",
            "--quiet",
            "--out",
            &s(&d.join("new")),
        ],
        &["expected K/N"],
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// `trials.parquet` as pandas reads it: the columns, the row count and the values agree
/// with `epochs.csv` and with the ENU/ECEF geometry; and the summary's per-segment
/// statistics and across-trial RMSE intervals are what pandas and scipy compute from
/// `epochs.csv`.
#[test]
fn trials_parquet_reads_in_pandas() {
    let d = tmp_dir("mc-parquet");
    let out = d.join("run");
    ok(hybridnav(&[
        "run",
        "--trials",
        "3",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]));
    let script = r#"
import sys
try:
    import pandas as pd, numpy as np
    import pyarrow  # noqa: F401
    import scipy  # noqa: F401
except ImportError as e:
    print("SKIP", e); sys.exit(0)
out = sys.argv[1]
p = pd.read_parquet(out + "/trials.parquet")
c = pd.read_csv(out + "/epochs.csv")
assert len(p) == len(c), (len(p), len(c))
assert list(p.trial.unique()) == [0, 1, 2]
for col in ["t_s", "err_3d_m", "err_h_m", "nees_pos", "gdop"]:
    a, b = p[col].to_numpy(float), c[col].to_numpy(float)
    assert ((np.isnan(a) == np.isnan(b)).all()), col
    m = ~np.isnan(a)
    assert np.abs(a[m] - b[m]).max() < 1e-5, col
assert (p.estimator.to_numpy() == c.estimator.to_numpy()).all()
# The error columns are the distance between the truth and estimate columns.
m = p.est_x_ecef_m.notna()
d = np.sqrt((p.est_x_ecef_m - p.truth_x_ecef_m)[m]**2 + (p.est_y_ecef_m - p.truth_y_ecef_m)[m]**2
            + (p.est_z_ecef_m - p.truth_z_ecef_m)[m]**2)
assert np.abs(d - p.err_3d_m[m]).max() < 1e-6
h = np.hypot((p.est_e_m - p.truth_e_m)[m], (p.est_n_m - p.truth_n_m)[m])
assert np.abs(h - p.err_h_m[m]).max() < 1e-2, np.abs(h - p.err_h_m[m]).max()
assert str(p.numerical_failure.dtype) == "bool"
assert p.n_gps.max() > 4 and p.n_bds.max() > 0
# The summary's per-segment statistics, recomputed by pandas from epochs.csv: the epochs
# inside each shielding window, then those outside every window.
import json
s = json.load(open(out + "/summary.json"))
for e in s["estimators"]:
    g = c[c.estimator == e["name"]]
    segs = e["segments"]
    assert [x["label"] for x in segs] == [
        "40–80 s (3 per system)", "120–150 s (2 per system)", "outside shielding"], segs
    inside = np.zeros(len(g), bool)
    for x in segs:
        if "window_s" in x:
            a, b = x["window_s"]
            m = ((g.t_s >= a) & (g.t_s < b)).to_numpy()
            inside |= m
        else:
            m = ~inside
        sel = g[m & g.err_3d_m.notna().to_numpy()]
        assert x["epochs"] == len(sel), (e["name"], x["label"], x["epochs"], len(sel))
        if len(sel) == 0:
            assert x["error_3d_m"] is None
            continue
        rms = np.sqrt((sel.err_3d_m ** 2).mean())
        q = np.quantile(sel.err_3d_m, 0.9545)
        st = x["error_3d_m"]
        assert abs(rms - st["rmse"]) < 1e-5 and abs(q - st["sigma2"]) < 1e-5, (e["name"], x, rms, q)
        assert abs(np.sqrt((sel.err_h_m ** 2).mean()) - x["rmse_h_m"]) < 1e-5
    # The across-trial interval of the RMSE: a Student t interval of the mean of the
    # per-trial RMSEs (scipy's t quantile) taken on the log scale, x̄·exp(∓h/x̄).
    from scipy import stats
    per = g.dropna(subset=["err_3d_m"]).groupby("trial").err_3d_m.apply(
        lambda v: np.sqrt((v ** 2).mean()))
    n = len(per)
    xbar, sd = per.mean(), per.std(ddof=1)
    h = stats.t.ppf(0.975, n - 1) * sd / np.sqrt(n)
    lo, hi = e["across_trials"]["rmse_ci95_m"]
    assert abs(lo - xbar * np.exp(-h / xbar)) < 1e-4 and abs(hi - xbar * np.exp(h / xbar)) < 1e-4, (
        e["name"], lo, hi, xbar, h)
    assert 0 < lo < xbar < hi
print("OK", len(p))
"#;
    match Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(&out)
        .output()
    {
        Ok(o) => {
            let text = String::from_utf8_lossy(&o.stdout);
            assert!(o.status.success(), "{text}{}", stderr(&o));
            if text.starts_with("SKIP") {
                crate::common::skip(&format!(
                    "pandas/pyarrow/scipy not installed ({})",
                    text.trim()
                ));
            } else {
                assert!(text.starts_with("OK"), "{text}");
            }
        }
        Err(e) => crate::common::skip(&format!("python3 not found ({e})")),
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Every file under `dir` (relative name → bytes) but the lock file, for "nothing
/// changed" checks.
fn snapshot(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if e.file_name() != ".hybridnav.lock" {
                // The lock file names the last process that held the directory.
                let name = p.strip_prefix(dir).unwrap().display().to_string();
                out.insert(name, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Starts `hybridnav args…` in the background (no output).
fn spawn(args: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_hybridnav"))
        .args(args)
        .current_dir(repo())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start hybridnav")
}

/// Waits (at most 2 min) until `dir` holds at least `n` trial files.
fn wait_for_trials(dir: &Path, n: usize) {
    let start = Instant::now();
    while trial_files(dir).len() < n && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Defect 1 of issue 28: `merge s1 s2 --out s1` deleted shard s1's trials and rewrote its
/// manifest. Now an output that is an input, inside one or around one is refused before
/// anything is touched, the shard stays byte for byte as it was and still resumes.
#[test]
fn merge_onto_one_of_its_inputs_is_refused_and_the_shard_is_untouched() {
    let d = tmp_dir("mc-merge-onto-input");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    let (s1, s2) = (d.join("s1"), d.join("s2"));
    for (k, dir) in [("1/2", &s1), ("2/2", &s2)] {
        ok(hybridnav(&[
            "run",
            "--trials",
            "4",
            "--seed",
            "3",
            "--shard",
            k,
            "--threads",
            "1",
            "--quiet",
            "--out",
            &s(dir),
        ]));
    }
    let before = snapshot(&s1);
    for (out, says) in [
        (s1.clone(), "is the input"),
        (s1.join("merged"), "is inside the input"),
        (d.clone(), "contains the input"),
        // The same directory by another spelling.
        (s1.join("..").join("s1"), "is the input"),
    ] {
        let e = refused(&["merge", &s(&s1), &s(&s2), "--out", &s(&out)], &[says]);
        assert!(e.contains("s1"), "{e}");
        let e = refused(
            &["merge", &s(&s1), &s(&s2), "--out", &s(&out), "--force"],
            &[says],
        );
        assert!(e.contains("s1"), "{e}");
    }
    assert!(
        before == snapshot(&s1),
        "the refused merges changed shard s1"
    );
    assert!(!s1.join("merged").exists());
    // The shard is still a shard: resuming it is accepted and changes nothing.
    ok(hybridnav(&[
        "run",
        "--trials",
        "4",
        "--seed",
        "3",
        "--shard",
        "1/2",
        "--threads",
        "1",
        "--quiet",
        "--resume",
        "--out",
        &s(&s1),
    ]));
    let after = snapshot(&s1);
    for (name, bytes) in &before {
        if name != ".hybridnav.lock" {
            assert!(after.get(name) == Some(bytes), "{name} changed on resume");
        }
    }
    // A merge to a directory of its own works.
    ok(hybridnav(&[
        "merge",
        &s(&s1),
        &s(&s2),
        "--quiet",
        "--out",
        &s(&d.join("m")),
    ]));
    assert_eq!(trial_files(&d.join("m")).len(), 4);
    let _ = std::fs::remove_dir_all(&d);
}

/// Defect 2 of issue 28: two runs shared one directory (a seed-2 run killed in a seed-1
/// directory, resumed: 15 of 60 trials were seed 1's). Now: a second process is refused
/// while the first holds the directory (naming its pid); a run into a directory that
/// holds another run is refused without --force; and a trial file of another run found
/// on resume is refused, naming the key that differs.
#[test]
fn two_runs_never_share_an_output_directory() {
    let d = tmp_dir("mc-two-runs");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    let world = "worlds/seed004-bupt.toml";
    let x = d.join("x");
    let mut child = spawn(&[
        "run",
        world,
        "--trials",
        "12",
        "--seed",
        "1",
        "--threads",
        "1",
        "--quiet",
        "--out",
        &s(&x),
    ]);
    wait_for_trials(&x, 1);
    let pid = format!("pid {}", child.id());
    // While it runs: every other writer of x is refused, naming the holder.
    for args in [
        vec!["run", world, "--trials", "12", "--seed", "2", "--force"],
        vec!["run", world, "--trials", "12", "--seed", "1", "--resume"],
        vec!["run", world, "--trials", "12", "--seed", "2"],
    ] {
        let mut a = args.clone();
        a.extend(["--quiet", "--out", x.to_str().unwrap()]);
        refused(&a, &["is in use by another hybridnav process", &pid]);
    }
    // A merge reading it as a shard is refused too: it is being written.
    refused(
        &["merge", &s(&x), "--out", &s(&d.join("m"))],
        &["is in use by another hybridnav process", &pid],
    );
    child.kill().unwrap();
    let _ = child.wait();
    let seed1 = trial_files(&x);
    assert!(!seed1.is_empty() && seed1.len() < 12, "{seed1:?}");
    // The kill released the lock; a seed-2 run into the seed-1 directory is refused …
    refused(
        &[
            "run",
            world,
            "--trials",
            "12",
            "--seed",
            "2",
            "--quiet",
            "--out",
            &s(&x),
        ],
        &[
            "holds a run of world",
            "seed 1, 12 trials",
            "--resume",
            "--force",
        ],
    );
    // … and resuming it as seed 2 names the difference.
    refused(
        &[
            "run",
            world,
            "--trials",
            "12",
            "--seed",
            "2",
            "--resume",
            "--quiet",
            "--out",
            &s(&x),
        ],
        &["seed 2 vs 1"],
    );
    // A trial of another run copied in (the mix of the defect) is found by its stamp.
    let y = d.join("y");
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        "12",
        "--seed",
        "2",
        "--threads",
        "1",
        "--quiet",
        "--out",
        &s(&y),
    ]));
    let foreign = "trial-000011.json.gz";
    assert!(!seed1.iter().any(|t| t == foreign));
    std::fs::copy(
        y.join("trials").join(foreign),
        x.join("trials").join(foreign),
    )
    .unwrap();
    refused(
        &[
            "run",
            world,
            "--trials",
            "12",
            "--seed",
            "1",
            "--resume",
            "--quiet",
            "--out",
            &s(&x),
        ],
        &[foreign, "belongs to another run (seed 2, not 1)"],
    );
    assert!(!x.join("summary.json").exists());
    std::fs::remove_file(x.join("trials").join(foreign)).unwrap();
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        "12",
        "--seed",
        "1",
        "--resume",
        "--quiet",
        "--out",
        &s(&x),
    ]));
    let single = d.join("single");
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        "12",
        "--seed",
        "1",
        "--quiet",
        "--out",
        &s(&single),
    ]));
    assert_same_run(&x, &single);
    let _ = std::fs::remove_dir_all(&d);
}

/// Defects 3 and 4 of issue 28: rerunning without --resume silently deleted every
/// finished trial (18 → 2), and a new run left the previous run's outputs in place until
/// it finished. Now the rerun is refused; with --force the old run is renamed aside
/// whole, byte for byte; and a new attempt's directory never holds the old outputs.
#[test]
fn a_rerun_loses_nothing_and_never_shows_old_outputs() {
    let d = tmp_dir("mc-rerun");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    let world = "worlds/seed004-bupt.toml";
    let x = d.join("x");
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        "6",
        "--quiet",
        "--out",
        &s(&x),
    ]));
    let old = snapshot(&x);
    assert_eq!(trial_files(&x).len(), 6);
    let e = refused(
        &["run", world, "--trials", "2", "--quiet", "--out", &s(&x)],
        &["holds a run", "6 trial file(s), complete", "--force"],
    );
    assert!(!e.contains("panicked"));
    assert!(old == snapshot(&x), "a refused rerun changed the directory");

    // --force: the old run moves to x.previous-1 whole; a run killed right after it
    // started shows no output of the old one beside its own manifest.
    let mut child = spawn(&[
        "run",
        world,
        "--trials",
        "12",
        "--threads",
        "1",
        "--seed",
        "9",
        "--force",
        "--quiet",
        "--out",
        &s(&x),
    ]);
    // The old run's trial files count until it has been moved aside.
    let aside = d.join("x.previous-1");
    let start = Instant::now();
    while !aside.exists() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
    wait_for_trials(&x, 1);
    child.kill().unwrap();
    let _ = child.wait();
    let moved = snapshot(&aside);
    for (name, bytes) in &old {
        if name != ".hybridnav.lock" {
            assert!(
                moved.get(name) == Some(bytes),
                "{name} was not moved aside intact"
            );
        }
    }
    assert!(std::fs::read_to_string(x.join("run.json"))
        .unwrap()
        .contains("\"seed\": 9"));
    for f in [
        "summary.json",
        "epochs.csv",
        "trials.parquet",
        "report.html",
    ] {
        assert!(
            !x.join(f).exists(),
            "{f} of the old run beside the new manifest"
        );
    }

    // A resumed attempt removes its earlier outputs before its first trial: a complete
    // run that lost half its trial files, resumed and killed at its first new trial.
    let z = d.join("z");
    ok(hybridnav(&[
        "run",
        world,
        "--trials",
        "12",
        "--quiet",
        "--out",
        &s(&z),
    ]));
    for t in trial_files(&z).iter().skip(2) {
        std::fs::remove_file(z.join("trials").join(t)).unwrap();
    }
    let mut child = spawn(&[
        "run",
        world,
        "--trials",
        "12",
        "--threads",
        "1",
        "--resume",
        "--quiet",
        "--out",
        &s(&z),
    ]);
    wait_for_trials(&z, 3);
    child.kill().unwrap();
    let _ = child.wait();
    if trial_files(&z).len() < 12 {
        for f in [
            "summary.json",
            "epochs.csv",
            "trials.parquet",
            "report.html",
        ] {
            assert!(
                !z.join(f).exists(),
                "{f} survived the start of a new attempt"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Issue 27, item 4: `--outputs` writes less, and what it writes is what the full run
/// writes, byte for byte.
#[test]
fn outputs_selects_the_files_and_changes_none_of_their_bytes() {
    let d = tmp_dir("mc-outputs");
    let s = |x: &Path| x.to_str().unwrap().to_string();
    let (full, part) = (d.join("full"), d.join("part"));
    ok(hybridnav(&[
        "run",
        "--trials",
        "2",
        "--quiet",
        "--out",
        &s(&full),
    ]));
    let o = ok(hybridnav(&[
        "run",
        "--trials",
        "2",
        "--outputs",
        "summary,epochs",
        "--out",
        &s(&part),
    ]));
    let printed = String::from_utf8_lossy(&o.stdout);
    assert!(
        printed.contains("epochs.csv") && !printed.contains("report.html"),
        "{printed}"
    );
    for f in ["summary.json", "epochs.csv", "run.json"] {
        assert!(
            std::fs::read(full.join(f)).unwrap() == std::fs::read(part.join(f)).unwrap(),
            "{f} differs"
        );
    }
    for f in ["trials.parquet", "report.html"] {
        assert!(!part.join(f).exists(), "{f} written though not asked for");
    }
    assert!(trial_files(&part).is_empty());
    refused(
        &[
            "run",
            "--trials",
            "2",
            "--outputs",
            "summary,csv",
            "--out",
            &s(&d.join("b")),
        ],
        &[
            "\"csv\" is not an output",
            "summary, report, epochs, parquet, trials",
        ],
    );
    refused(
        &[
            "run",
            "--trials",
            "2",
            "--shard",
            "1/2",
            "--outputs",
            "summary",
            "--out",
            &s(&d.join("c")),
        ],
        &["--shard needs `trials`"],
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// Whether `(e, n)` lies inside the polygon `poly` (even–odd rule), written here apart from
/// the scene's prism index so the summary's indoor/outdoor split is checked against a
/// second computation.
fn inside_polygon(poly: &[[f64; 2]], e: f64, n: f64) -> bool {
    let mut inside = false;
    for k in 0..poly.len() {
        let [x0, y0] = poly[k];
        let [x1, y1] = poly[(k + 1) % poly.len()];
        if (y0 > n) != (y1 > n) && e < x0 + (n - y0) * (x1 - x0) / (y1 - y0) {
            inside = !inside;
        }
    }
    inside
}

/// `summary.json`'s `environments`: each estimator's errors at the epochs whose truth was
/// outdoors and indoors. Seed 004's pedestrian crosses the teaching building; every
/// epoch's truth is put inside or outside the world file's building footprints by the
/// even–odd rule above, and the epoch counts and horizontal RMS must match the summary's.
/// A world whose truth never goes indoors (Kehui, with buildings along the road) and one
/// without a scene (seed 003) report no split.
#[test]
fn the_summary_splits_each_estimator_by_where_the_truth_was() {
    use hybridnav::montecarlo::{run_trials, summarise, RunOptions};
    let opts = crate::common::run_options(2, 1);
    let world = hybridnav::world::load_world(&repo().join("worlds/seed004-bupt.toml")).unwrap();
    let results = run_trials(&world, &opts).unwrap();
    let summary = summarise(&world, &opts, &results).unwrap();
    let scene = world.file.scene.as_ref().expect("seed 004 has a scene");
    let buildings: Vec<(Vec<[f64; 2]>, f64)> = scene
        .buildings
        .iter()
        .map(|b| {
            (
                b.footprint_enu_m.clone().expect("ENU footprints"),
                b.height_m,
            )
        })
        .collect();
    assert!(scene.indoor_zones.is_empty());
    for (k, e) in summary.estimators.iter().enumerate() {
        // (epochs with an estimate, sum of squared horizontal errors) outdoors and indoors.
        let mut acc = [(0usize, 0.0f64); 2];
        for t in &results {
            for ep in &t.estimators[k].epochs {
                let (Some(_), Some(eh)) = (ep.err_3d_m, ep.err_h_m) else {
                    continue;
                };
                let p = world
                    .frame
                    .enu_of_ecef(&nalgebra::Vector3::from(ep.truth_ecef_m));
                let indoor = buildings
                    .iter()
                    .any(|(poly, h)| p.z >= 0.0 && p.z < *h && inside_polygon(poly, p.x, p.y));
                let slot = &mut acc[usize::from(indoor)];
                slot.0 += 1;
                slot.1 += eh * eh;
            }
        }
        let labels: Vec<&str> = e.environments.iter().map(|g| g.label.as_str()).collect();
        assert_eq!(labels, ["outdoor", "indoor"], "{}", e.name);
        for (g, (n, sum)) in e.environments.iter().zip(acc) {
            assert_eq!(g.epochs, n, "{} {}", e.name, g.label);
            match g.rmse_h_m {
                Some(r) => {
                    let want = (sum / n as f64).sqrt();
                    assert!(
                        (r - want).abs() < 1e-9 * want.max(1.0),
                        "{} {}: {r} against {want}",
                        e.name,
                        g.label
                    );
                }
                None => assert_eq!(n, 0, "{} {}", e.name, g.label),
            }
        }
    }
    // The walk spends about 46 of its 354 s inside the teaching building.
    let re_kf = summary
        .estimators
        .iter()
        .find(|e| e.name == "RE-KF")
        .unwrap();
    let indoor = re_kf.environments[1].epochs;
    assert!(
        (80..=100).contains(&indoor),
        "indoor epochs over 2 trials: {indoor}"
    );
    for (name, trials) in [
        ("worlds/seed000-kehui.toml", 1),
        ("worlds/seed003-seamless.toml", 1),
    ] {
        let w = hybridnav::world::load_world(&repo().join(name)).unwrap();
        let o = RunOptions { trials, ..opts };
        let s = summarise(&w, &o, &run_trials(&w, &o).unwrap()).unwrap();
        assert!(
            s.estimators.iter().all(|e| e.environments.is_empty()),
            "{name}"
        );
    }
}
