//! Nothing lost, and the same bytes whatever happens: runs killed at random moments and
//! resumed, a disk that fills up mid-run, and the determinism matrix over threads, shard
//! splits and estimator subsets.

use crate::common::{hybridnav, repo, stderr, tmp_dir, write};
use crate::montecarlo::{assert_same_run, trial_files};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn s(p: &Path) -> String {
    p.to_str().expect("UTF-8 path").to_string()
}

fn ok(args: &[&str]) {
    let o = hybridnav(args);
    assert!(o.status.success(), "hybridnav {args:?}: {}", stderr(&o));
}

fn trial_count(dir: &Path) -> usize {
    trial_files(dir).len()
}

/// Hidden temporary files (atomic writes, spilled sort runs) anywhere in a run directory.
fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for d in [dir.to_path_buf(), dir.join("trials")] {
        if let Ok(rd) = std::fs::read_dir(&d) {
            for e in rd.flatten() {
                let n = e.file_name().to_string_lossy().into_owned();
                if n.ends_with(".tmp") || n.starts_with(".hybridnav-spill-") {
                    out.push(e.path());
                }
            }
        }
    }
    out
}

/// The arguments of one attempt of a run into `out`, resuming when an earlier attempt left
/// a manifest (as `docs/cluster/shard.sh` does).
fn attempt_args(world: &str, trials: &str, threads: &str, out: &Path) -> Vec<String> {
    let mut a: Vec<String> = [
        "run",
        world,
        "--trials",
        trials,
        "--threads",
        threads,
        "--quiet",
        "--out",
    ]
    .iter()
    .map(|x| x.to_string())
    .collect();
    a.push(s(out));
    if out.join("run.json").exists() {
        a.push("--resume".into());
    }
    a
}

/// Kills a run with SIGKILL at random moments, several times over, resuming after each
/// kill with a random thread count; the finished directory must equal an uninterrupted
/// run's byte for byte, with no temporary file left behind. The moments are drawn from a
/// fixed seed (after 1–3 more trials, plus 0–250 ms, so that a slow machine cannot turn
/// every kill into one before the first trial), and a last kill aims at the window after
/// the last trial file and before `summary.json`, where the outputs are published.
#[test]
fn runs_killed_at_random_moments_resume_to_the_uninterrupted_result() {
    let d = tmp_dir("rel-kills");
    // ~0.3 s per trial on one thread: a 12-trial run lasts a few seconds.
    let world = "worlds/seed004-bupt.toml";
    let trials = "12";
    let whole = d.join("whole");
    ok(&[
        "run",
        world,
        "--trials",
        trials,
        "--quiet",
        "--out",
        &s(&whole),
    ]);

    let out = d.join("killed");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(20261122);
    let mut kills = Vec::new();
    for attempt in 0..5 {
        let threads = if rng.random_bool(0.5) { "1" } else { "2" };
        let args = attempt_args(world, trials, threads, &out);
        let mut child = Command::new(env!("CARGO_BIN_EXE_hybridnav"))
            .args(&args)
            .current_dir(repo())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start hybridnav");
        let before = trial_count(&out);
        let start = Instant::now();
        // Polls until `ready` holds (or two minutes pass); true when the run exited first.
        let mut wait_until = |ready: &dyn Fn() -> bool| {
            while !ready() && start.elapsed() < Duration::from_secs(120) {
                if child.try_wait().expect("poll").is_some() {
                    return true;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            child.try_wait().expect("poll").is_some()
        };
        let finished = if attempt == 4 {
            // Aim at the output phase: kill as soon as every trial file exists.
            wait_until(&|| trial_count(&out) >= 12)
        } else {
            // A random moment that is sure to fall after some progress, however fast the
            // machine: once 1–3 more trials are written, a further 0–250 ms.
            let target = (before + rng.random_range(1..=3)).min(11);
            wait_until(&|| trial_count(&out) >= target) || {
                let wait = start.elapsed() + Duration::from_millis(rng.random_range(0..250));
                wait_until(&|| start.elapsed() >= wait)
            }
        };
        if finished {
            kills.push(format!("attempt {attempt}: finished by itself"));
            break;
        }
        child.kill().expect("kill");
        let _ = child.wait();
        kills.push(format!(
            "attempt {attempt} ({threads} thread(s)): killed after {:?} with {} → {} trial files, summary {}",
            start.elapsed(),
            before,
            trial_count(&out),
            if out.join("summary.json").exists() { "written" } else { "absent" }
        ));
    }
    eprintln!("{}", kills.join("\n"));
    assert!(
        kills.iter().filter(|k| k.contains("killed")).count() >= 3,
        "too few kills landed: {kills:?}"
    );
    // At least one kill interrupted the run between its first and its last trial.
    assert!(
        kills
            .iter()
            .any(|k| k.contains("killed") && !k.contains("→ 0 ") && !k.contains("→ 12 ")),
        "no kill landed mid-run: {kills:?}"
    );
    let last = attempt_args(world, trials, "2", &out);
    let last: Vec<&str> = last.iter().map(String::as_str).collect();
    ok(&last);
    assert_same_run(&whole, &out);
    assert!(
        temporaries(&out).is_empty(),
        "temporary files of killed processes were left: {:?}",
        temporaries(&out)
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// Runs into a 600 KiB file system (a tmpfs in a private mount namespace) that fills up
/// mid-run: the run must stop with a message naming the file and the cause, every trial
/// file it finished must be complete, and the directory, moved to a disk with room and
/// resumed, must finish as the uninterrupted run. Skipped (with the reason) where a mount
/// namespace cannot be made.
#[test]
fn a_full_disk_is_a_clear_error_and_the_finished_trials_resume() {
    let d = tmp_dir("rel-disk");
    let world = repo().join("worlds/default.toml");
    let whole = d.join("whole");
    ok(&[
        "run",
        &s(&world),
        "--trials",
        "40",
        "--quiet",
        "--out",
        &s(&whole),
    ]);
    let mnt = d.join("small");
    let rescued = d.join("rescued");
    std::fs::create_dir_all(&mnt).unwrap();
    // The script runs hybridnav on the small file system, then copies what it left to
    // `rescued` before the namespace (and the tmpfs with it) goes away.
    let script = format!(
        "set -u; mount -t tmpfs -o size=600k tmpfs '{mnt}' || exit 77; \
         '{bin}' run '{world}' --trials 40 --threads 2 --quiet --out '{mnt}/run'; \
         echo \"exit=$?\" >&2; cp -a '{mnt}/run' '{rescued}'",
        mnt = s(&mnt),
        bin = env!("CARGO_BIN_EXE_hybridnav"),
        world = s(&world),
        rescued = s(&rescued),
    );
    let o = Command::new("unshare")
        .args(["--mount", "--map-root-user", "sh", "-c", &script])
        .output();
    let o = match o {
        Ok(o) if o.status.code() != Some(77) && rescued.exists() => o,
        Ok(o) => {
            eprintln!(
                "skipped: cannot mount a small tmpfs in a private namespace here: {}",
                stderr(&o).trim()
            );
            return;
        }
        Err(e) => {
            eprintln!("skipped: unshare is not available: {e}");
            return;
        }
    };
    let err = stderr(&o);
    eprintln!("{err}");
    assert!(
        err.contains("exit=") && !err.contains("exit=0"),
        "the run should fail: {err}"
    );
    assert!(
        err.contains("No space left on device") && err.contains("writing /"),
        "the error should name the file and the cause: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    let kept = trial_count(&rescued);
    assert!(
        (1..40).contains(&kept),
        "the disk should fill midway; {kept} trial files were written"
    );
    assert!(!rescued.join("summary.json").exists());
    // Every trial file that exists is whole: resuming reads each one back.
    ok(&[
        "run",
        &s(&world),
        "--trials",
        "40",
        "--quiet",
        "--resume",
        "--out",
        &s(&rescued),
    ]);
    assert_same_run(&whole, &rescued);
    assert!(
        temporaries(&rescued).is_empty(),
        "{:?}",
        temporaries(&rescued)
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// The determinism matrix: one thread or two, the whole run or shards of it (2 and 3,
/// merged, with different thread counts per shard) give byte-identical run directories.
#[test]
fn threads_and_shard_splits_give_identical_bytes() {
    let d = tmp_dir("rel-matrix");
    let world = "worlds/default.toml";
    let base = d.join("t1");
    ok(&[
        "run",
        world,
        "--trials",
        "7",
        "--seed",
        "9",
        "--threads",
        "1",
        "--quiet",
        "--out",
        &s(&base),
    ]);
    let t2 = d.join("t2");
    ok(&[
        "run",
        world,
        "--trials",
        "7",
        "--seed",
        "9",
        "--threads",
        "2",
        "--quiet",
        "--out",
        &s(&t2),
    ]);
    assert_same_run(&base, &t2);
    for n in [2u32, 3] {
        let mut dirs = Vec::new();
        for k in 1..=n {
            let dir = d.join(format!("s{k}of{n}"));
            let threads = if k % 2 == 0 { "2" } else { "1" };
            ok(&[
                "run",
                world,
                "--trials",
                "7",
                "--seed",
                "9",
                "--threads",
                threads,
                "--shard",
                &format!("{k}/{n}"),
                "--quiet",
                "--out",
                &s(&dir),
            ]);
            dirs.push(s(&dir));
        }
        let merged = d.join(format!("merged{n}"));
        let mut args = vec!["merge"];
        args.extend(dirs.iter().map(String::as_str));
        let m = s(&merged);
        args.extend(["--out", &m, "--quiet"]);
        ok(&args);
        assert_same_run(&base, &merged);
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// The rows of `epochs.csv` of estimator `name`.
fn rows_of(dir: &Path, name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("epochs.csv")).unwrap();
    let quoted = format!(",\"{name}\",");
    text.lines()
        .filter(|l| l.contains(&quoted))
        .map(str::to_string)
        .collect()
}

/// The summary entry of estimator `name`.
fn summary_of(dir: &Path, name: &str) -> serde_json::Value {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    v["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["name"] == name)
        .unwrap_or_else(|| panic!("{name} in the summary"))
        .clone()
}

/// An estimator's results do not depend on which other estimators run beside it or in
/// what order: each draws from its own named random streams and sees the same
/// measurements. Checked on the default world (WLS, two EKFs, two INS) and on seed 001's world,
/// whose particle filters draw random numbers of their own.
#[test]
fn estimator_subsets_and_orders_give_identical_estimator_results() {
    let d = tmp_dir("rel-subsets");
    for (world, keep) in [("default.toml", 1usize), ("seed001-pf2d.toml", 1)] {
        // The default world's text with its ephemeris path made absolute, so that the
        // edited copies written elsewhere find it.
        let text = if world == "default.toml" {
            crate::common::default_world_text()
        } else {
            std::fs::read_to_string(repo().join("worlds").join(world)).unwrap()
        };
        let (head, tables) = split_estimators(&text);
        assert!(tables.len() >= 2, "{world} has several estimators");
        let full = d.join(format!("{world}-all"));
        ok(&[
            "run",
            &s(&repo().join("worlds").join(world)),
            "--trials",
            "3",
            "--quiet",
            "--out",
            &s(&full),
        ]);
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(full.join("summary.json")).unwrap())
                .unwrap();
        let names: Vec<String> = summary["estimators"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["name"].as_str().unwrap().to_string())
            .collect();
        assert_eq!(names.len(), tables.len());
        // Only one estimator; then all of them in reverse order. The world's
        // `[comparison]` then lists only the kept row (its protocol stays the same).
        let only_head: String = head
            .lines()
            .map(|l| {
                if l.starts_with("estimators = [") && l.contains(&format!("\"{}\"", names[keep])) {
                    format!("estimators = [\"{}\"]\n", names[keep])
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        let only = write(
            &d,
            &format!("only-{world}"),
            &format!("{only_head}{}", tables[keep]),
        );
        let mut rev = tables.clone();
        rev.reverse();
        let reversed = write(
            &d,
            &format!("rev-{world}"),
            &format!("{head}{}", rev.concat()),
        );
        for (file, out, which) in [
            (
                &only,
                d.join(format!("{world}-only")),
                vec![names[keep].clone()],
            ),
            (&reversed, d.join(format!("{world}-rev")), names.clone()),
        ] {
            ok(&[
                "run",
                &s(file),
                "--trials",
                "3",
                "--quiet",
                "--out",
                &s(&out),
            ]);
            for n in &which {
                let rows = rows_of(&full, n);
                assert!(!rows.is_empty());
                assert_eq!(rows, rows_of(&out, n), "{world}: {n}'s epochs differ");
                assert_eq!(summary_of(&full, n), summary_of(&out, n), "{world}: {n}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Splits a world file into what precedes its `[[estimator]]` tables (and follows them,
/// moved to the front) and the tables themselves, each with its lines.
fn split_estimators(text: &str) -> (String, Vec<String>) {
    let mut head = String::new();
    let mut tables: Vec<String> = Vec::new();
    let mut in_estimator = false;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("[[estimator]]") {
            in_estimator = true;
            tables.push(String::new());
        } else if t.starts_with('[') && !t.starts_with("[estimator.") {
            // A sub-table such as [estimator.ins] belongs to the estimator above it.
            in_estimator = false;
        }
        if in_estimator {
            let last = tables.last_mut().expect("a table was opened");
            last.push_str(line);
            last.push('\n');
        } else {
            head.push_str(line);
            head.push('\n');
        }
    }
    (head, tables)
}

/// A filter whose model cannot follow the platform (an EKF that believes the car never
/// accelerates, on the default world's U-turns) diverges: the engine's watch reports it at
/// its epoch with the estimator's name — in `epochs.csv`, in `summary.json`'s
/// `first_failures` and on stderr — resets it, and writes no NaN anywhere; the correctly
/// tuned EKF beside it reports no failure.
#[test]
fn a_diverging_filter_is_reported_at_its_epoch_and_reset() {
    let d = tmp_dir("rel-diverge");
    let text = crate::common::default_world_text();
    let head = &text[..text.find("[[estimator]]").unwrap()];
    let world = write(
        &d,
        "stiff.toml",
        &format!(
            "{head}
[[estimator]]
name = \"GPS\"
sources = [\"gps\"]
filter = \"ekf11\"

[[estimator]]
name = \"stiff\"
sources = [\"gps\"]
filter = \"ekf11\"
[estimator.ekf]
accel_psd_m2ps5 = [1e-9, 1e-9, 1e-9]
init_vel_sigma_mps = 0.01
init_acc_sigma_mps2 = 0.001

[montecarlo]
trials = 2
seed = 1
"
        ),
    );
    let out = d.join("out");
    let o = hybridnav(&["run", &s(&world), "--out", &s(&out), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("estimator \"stiff\" reported") && err.contains("first in trial 0 at t ="),
        "{err}"
    );
    assert!(!err.contains("\"GPS\" reported"), "{err}");
    let csv = std::fs::read_to_string(out.join("epochs.csv")).unwrap();
    let mut failures = Vec::new();
    let mut previous: Option<Vec<String>> = None;
    for line in csv.lines().skip(1) {
        let f: Vec<String> = line.split(',').map(str::to_string).collect();
        assert!(
            !line.contains("NaN") && !line.contains("inf"),
            "a non-finite number: {line}"
        );
        if f[13] == "1" {
            assert_eq!(f[1], "\"stiff\"", "{line}");
            assert!(f[3].is_empty(), "a failure epoch has no estimate: {line}");
            // The epoch before it had at least a quarter of its measurements (and three
            // or more) refused by the gate.
            let p = previous.as_ref().expect("not the first row");
            assert_eq!(p[1], "\"stiff\"", "{p:?}");
            let (used, gated): (u32, u32) = (p[7].parse().unwrap(), p[9].parse().unwrap());
            assert!(gated >= 3 && 4 * gated >= used + gated, "{p:?}");
            failures.push((f[0].clone(), f[2].clone()));
        }
        previous = Some(f);
    }
    assert!(!failures.is_empty(), "the stiff filter should diverge");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let stiff = &summary["estimators"][1];
    assert_eq!(stiff["name"], "stiff");
    assert_eq!(stiff["numerical_failures"], failures.len());
    let listed: Vec<(String, String)> = stiff["first_failures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["trial"].to_string(),
                format!("{:.3}", f["t_s"].as_f64().unwrap()),
            )
        })
        .collect();
    assert_eq!(listed, failures);
    assert_eq!(summary["estimators"][0]["numerical_failures"], 0);
    let _ = std::fs::remove_dir_all(&d);
}

/// Runs `trials` trials of `world` (seed 3) on `threads` threads into `dir`, as `hybridnav
/// run` does.
fn run_library(world: &::hybridnav::world::World, trials: u64, threads: usize, dir: &Path) {
    let opts = ::hybridnav::montecarlo::RunOptions {
        trials,
        seed: 3,
        threads,
        progress: false,
        shard: ::hybridnav::montecarlo::store::Shard::WHOLE,
    };
    let run_dir = ::hybridnav::montecarlo::store::RunDir::create(dir).expect("run directory");
    ::hybridnav::montecarlo::run_into(world, &opts, &run_dir, false).expect("run");
}

/// The per-run epoch cache (`engine::cache`) changes no output byte: a world whose truth
/// is the same in every trial runs with its cache (2 threads), with its tables bounded to
/// a third of their epochs so that the later epochs are computed by each trial (1 thread),
/// and with the cache off (1 thread), and the three runs write the same `summary.json`,
/// `epochs.csv`, `trials.parquet` and trial files. Checked on the default world (GNSS
/// only), Kehui Road (GNSS through a scene with shielding windows, measurement-level
/// DTMB and 21 FM stations: both tables), the Beihang campus (FM database kriged from
/// sparse RPs) and a world with a random trajectory (seed 003, no cache is built).
#[test]
fn the_epoch_cache_changes_no_output_byte() {
    let d = tmp_dir("rel-cache");
    for (name, trials) in [
        ("default", 4),
        ("seed000-kehui", 3),
        ("seed000-beihang", 2),
        ("seed003-seamless", 3),
    ] {
        let world = ::hybridnav::world::load_world(&repo().join(format!("worlds/{name}.toml")))
            .expect("world loads");
        let cache = world.epoch_cache(3).expect("cache builds");
        let gnss_epochs = if name == "seed003-seamless" {
            assert!(cache.is_none(), "a random trajectory has no cache");
            0
        } else {
            let c = cache.expect("a waypoint world has a cache");
            let g = c.gnss.as_ref().expect("GNSS links cached");
            // Every epoch of the run: 1 Hz from 0 to the end of the trajectory.
            assert_eq!(g.len(), world.duration_s.floor() as usize + 1, "{name}");
            assert!(!g.truncated());
            if name.starts_with("seed000") {
                let f = c.fm.as_ref().expect("FM means cached");
                assert_eq!(f.len(), g.len(), "{name}");
            }
            g.len()
        };
        let cached = d.join(format!("{name}-cached"));
        run_library(&world, trials, 2, &cached);

        let bounded = d.join(format!("{name}-bounded"));
        if gnss_epochs > 0 {
            // A bound of a third of the smaller table: both tables stop early.
            let full = world.epoch_cache(3).unwrap().unwrap();
            let bytes = full.gnss.as_ref().unwrap().bytes();
            let bytes = full.fm.as_ref().map_or(bytes, |f| f.bytes().min(bytes));
            world.epoch_cache.set_max_table_bytes(bytes / 3);
            let part = world.epoch_cache(3).unwrap().unwrap();
            let g = part.gnss.as_ref().unwrap();
            assert!(
                g.truncated() && !g.is_empty() && g.len() < gnss_epochs,
                "{name}"
            );
            if let Some(f) = &part.fm {
                assert!(
                    f.truncated() && !f.is_empty() && f.len() < gnss_epochs,
                    "{name}"
                );
            }
            run_library(&world, trials, 1, &bounded);
            assert_same_run(&cached, &bounded);
            world.epoch_cache.set_max_table_bytes(0);
        }

        world.set_epoch_cache(false);
        assert!(world.epoch_cache(3).unwrap().is_none());
        let uncached = d.join(format!("{name}-uncached"));
        run_library(&world, trials, 1, &uncached);
        assert_same_run(&cached, &uncached);
        // The report too (it is drawn from the same trials).
        assert_eq!(
            std::fs::read(cached.join("report.html")).unwrap(),
            std::fs::read(uncached.join("report.html")).unwrap(),
            "{name}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Defect 7 of issue 28 (the parts of input handling): CR-only line endings gave an empty
/// message, non-UTF-8 input reported `:0:0:`, and an OS error was printed twice. Each now
/// names the line and column of the first offending byte, and the OS error once.
#[test]
fn cr_only_and_non_utf8_worlds_are_located_and_os_errors_printed_once() {
    let d = tmp_dir("rel-text");
    let text = std::fs::read_to_string(repo().join("worlds/default.toml")).unwrap();
    let first_line_chars = text.lines().next().unwrap().chars().count();
    std::fs::write(d.join("cr.toml"), text.replace('\n', "\r")).unwrap();
    let o = hybridnav(&["check", &s(&d.join("cr.toml"))]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    let at = format!("cr.toml:1:{}: a carriage return", first_line_chars + 1);
    assert!(e.contains(&at), "expected {at:?} in: {e}");
    // A byte 0xff in the middle of line 5 (after its 3rd character).
    let mut bytes = Vec::new();
    for (k, line) in text.split_inclusive('\n').enumerate() {
        if k == 4 {
            let cut = line.char_indices().nth(3).unwrap().0;
            bytes.extend_from_slice(&line.as_bytes()[..cut]);
            bytes.push(0xff);
            bytes.extend_from_slice(&line.as_bytes()[cut..]);
        } else {
            bytes.extend_from_slice(line.as_bytes());
        }
    }
    std::fs::write(d.join("latin1.toml"), bytes).unwrap();
    let o = hybridnav(&["check", &s(&d.join("latin1.toml"))]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("latin1.toml:5:4: not UTF-8 text (byte 0xff)"),
        "{e}"
    );
    // One OS error, printed once.
    for args in [
        vec![
            "ephemeris",
            "positions",
            "--nav",
            "/nonexistent/brdc.nav",
            "--start",
            "2020-01-01T00:00:00",
            "--end",
            "2020-01-01T00:01:00",
            "--step",
            "60",
        ],
        vec!["check", "/nonexistent/world.toml"],
        vec![
            "run",
            "/nonexistent/world.toml",
            "--out",
            "/nonexistent/out",
        ],
    ] {
        let o = hybridnav(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{e}");
        // The OS's words or hybridnav's own ("does not exist"), but said once.
        assert_eq!(
            e.matches("No such file or directory").count() + e.matches("does not exist").count(),
            1,
            "{args:?}: {e}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Defect 8 of issue 28: atomic writes did not flush the directory after the rename, so
/// a finished file could vanish on power loss. Watched with strace: every rename of a
/// run's files into the output directory is followed by an fsync of that directory.
#[test]
fn every_rename_into_the_run_directory_is_followed_by_a_directory_fsync() {
    if Command::new("strace").arg("-V").output().is_err() {
        crate::common::skip("strace is not installed (CI installs it in .ci/slurm-test)");
        return;
    }
    let d = tmp_dir("rel-fsync");
    let out = d.join("out");
    let log = d.join("strace.log");
    let o = Command::new("strace")
        .args([
            "-f",
            "-y",
            "-qq",
            "-e",
            "trace=rename,renameat,renameat2,fsync",
            "-o",
        ])
        .arg(&log)
        .arg(env!("CARGO_BIN_EXE_hybridnav"))
        .args(["run", "--trials", "2", "--threads", "1", "--quiet", "--out"])
        .arg(&out)
        .current_dir(repo())
        .output()
        .unwrap();
    if !o.status.success() && stderr(&o).contains("PTRACE") {
        crate::common::skip("ptrace is not permitted here");
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    let trace = std::fs::read_to_string(&log).unwrap();
    let dir = std::fs::canonicalize(&out).unwrap().display().to_string();
    let mut renamed = Vec::new();
    let lines: Vec<&str> = trace.lines().collect();
    for (k, line) in lines.iter().enumerate() {
        if !line.contains("rename") || line.contains("= -1") {
            continue;
        }
        // The destination: the last quoted path of the call.
        let dest = line.rsplit('"').nth(1).unwrap_or("");
        let parent = Path::new(dest).parent().map(|p| p.display().to_string());
        let Some(parent) = parent.filter(|p| p.starts_with(&dir)) else {
            continue;
        };
        let pid = line.split_whitespace().next().unwrap_or("");
        let synced = lines[k + 1..].iter().any(|l| {
            l.split_whitespace().next() == Some(pid)
                && l.contains("fsync(")
                && l.contains(&format!("<{parent}>"))
        });
        assert!(synced, "no fsync of {parent} after: {line}");
        renamed.push(dest.to_string());
    }
    for f in [
        "summary.json",
        "epochs.csv",
        "trials.parquet",
        "report.html",
        "run.json",
    ] {
        assert!(
            renamed.iter().any(|r| r.ends_with(&format!("/{f}"))),
            "{f} was not seen renamed: {renamed:?}"
        );
    }
    assert!(
        renamed
            .iter()
            .filter(|r| r.contains("/trials/trial-"))
            .count()
            == 2,
        "{renamed:?}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// The fuzz targets' bodies, compiled here on stable Rust.
#[allow(dead_code)]
mod fuzz_entries {
    include!("../../fuzz/entries.rs");
}

/// Fuzzing that keeps paying: every input kept for a target in `fuzz/replay/T/` (the
/// seeds, the minimised corpus and every crash found, committed) — and, on a machine that
/// fuzzed, the working corpus `fuzz/corpus/T/` and the crashes `fuzz/artifacts/T/` (both
/// git-ignored) — runs through the target's own code on every `cargo test`, so a fixed
/// finding stays fixed without a nightly compiler. Each input must return (not panic)
/// within seconds.
#[test]
fn the_fuzz_corpora_and_crashes_replay_without_a_panic() {
    type Entry = fn(&[u8]);
    let targets: [(&str, Entry); 8] = [
        ("world_file", fuzz_entries::world_file),
        ("rinex_nav", fuzz_entries::rinex_nav),
        ("sp3", fuzz_entries::sp3),
        ("layout_candidates", fuzz_entries::layout_candidates),
        ("sigmf_fmdb", fuzz_entries::sigmf_fmdb),
        ("cli_args", fuzz_entries::cli_args),
        ("ts_payload", fuzz_entries::ts_payload),
        ("rinex_obs", fuzz_entries::rinex_obs),
    ];
    let fuzz = repo().join("fuzz");
    let scratch = std::env::temp_dir().join(format!("hybridnav-fuzz-{}", std::process::id()));
    // Every target of fuzz/Cargo.toml is replayed.
    let manifest = std::fs::read_to_string(fuzz.join("Cargo.toml")).unwrap();
    let declared = manifest.matches("[[bin]]").count();
    assert_eq!(
        declared,
        targets.len(),
        "a fuzz target is not replayed here"
    );
    for (name, entry) in targets {
        let mut inputs = Vec::new();
        for dir in ["replay", "corpus", "artifacts"].map(|d| fuzz.join(d).join(name)) {
            if let Ok(rd) = std::fs::read_dir(&dir) {
                inputs.extend(rd.flatten().map(|e| e.path()).filter(|p| p.is_file()));
            }
        }
        assert!(!inputs.is_empty(), "{name}: nothing in fuzz/replay/{name}");
        inputs.sort();
        for p in inputs {
            let data = std::fs::read(&p).unwrap();
            let start = Instant::now();
            entry(&data);
            let took = start.elapsed();
            assert!(
                took < Duration::from_secs(20),
                "{}: took {took:?}",
                p.display()
            );
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
}
