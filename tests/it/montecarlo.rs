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
    refused(
        &["merge", &s(&d), "--out", &s(&d.join("m"))],
        &["no run.json"],
    );
    let _ = std::fs::remove_dir_all(&d);
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
/// with `epochs.csv` and with the ENU/ECEF geometry.
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
                crate::common::skip(&format!("pandas/pyarrow not installed ({})", text.trim()));
            } else {
                assert!(text.starts_with("OK"), "{text}");
            }
        }
        Err(e) => crate::common::skip(&format!("python3 not found ({e})")),
    }
    let _ = std::fs::remove_dir_all(&d);
}
