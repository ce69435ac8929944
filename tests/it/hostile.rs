//! The hostile-input corpus (`tests/data/hostile/cases.toml`): every malformed, impossible
//! or enormous input there must be refused with a clear message — the file, the line and
//! column, the key, what was expected — quickly and without a large allocation (each case
//! runs under a 2 GiB address-space limit where the shell can set one).

use crate::common::{repo, tmp_dir};
use serde::Deserialize;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

#[derive(Deserialize)]
struct Corpus {
    case: Vec<WorldCase>,
    cli: Vec<CliCase>,
}

#[derive(Deserialize)]
struct WorldCase {
    name: String,
    world: String,
    find: String,
    replace: String,
    expect: Vec<String>,
}

#[derive(Deserialize)]
struct CliCase {
    name: String,
    args: Vec<String>,
    expect: Vec<String>,
}

fn corpus() -> Corpus {
    let path = repo().join("tests/data/hostile/cases.toml");
    let text = std::fs::read_to_string(&path).expect("read the corpus");
    toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Runs the binary with `args` under `ulimit -v` (2 GiB) and returns (exit code, stderr,
/// wall time).
fn run_limited(args: &[String], dir: &Path) -> (Option<i32>, String, Duration) {
    let mut script = String::from("ulimit -v 2097152 2>/dev/null; exec \"$0\"");
    for k in 1..=args.len() {
        script.push_str(&format!(" \"${k}\""));
    }
    let start = Instant::now();
    let o = Command::new("sh")
        .arg("-c")
        .arg(&script)
        .arg(env!("CARGO_BIN_EXE_hybridnav"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run hybridnav through sh");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        start.elapsed(),
    )
}

fn assert_refused(name: &str, code: Option<i32>, err: &str, took: Duration, expect: &[String]) {
    assert_eq!(
        code,
        Some(2),
        "{name}: expected a refusal (exit 2), got {code:?}: {err}"
    );
    assert!(!err.contains("panicked"), "{name}: panicked: {err}");
    assert!(
        err.trim_start().starts_with("error:"),
        "{name}: the message should start with `error:`: {err}"
    );
    for e in expect {
        assert!(err.contains(e.as_str()), "{name}: expected {e:?} in: {err}");
    }
    assert!(
        took < Duration::from_secs(20),
        "{name}: took {took:?} to refuse"
    );
}

#[test]
fn every_hostile_world_is_refused_with_file_line_key_and_expectation() {
    let d = tmp_dir("hostile-worlds");
    let c = corpus();
    assert!(c.case.len() >= 25, "the corpus lost cases");
    let mut names = std::collections::BTreeSet::new();
    for case in &c.case {
        assert!(
            names.insert(&case.name),
            "{}: duplicate case name",
            case.name
        );
        let base = std::fs::read_to_string(repo().join("worlds").join(&case.world))
            .unwrap_or_else(|e| panic!("{}: {}: {e}", case.name, case.world));
        assert_eq!(
            base.matches(case.find.as_str()).count().min(1),
            1,
            "{}: {:?} is not in {}",
            case.name,
            case.find,
            case.world
        );
        let text = base.replacen(&case.find, &case.replace, 1);
        let file = format!("{}.toml", case.name);
        std::fs::write(d.join(&file), text).unwrap();
        let (code, err, took) = run_limited(&["check".into(), file.clone()], &d);
        // The message names the file (with the line and column fragments of `expect`).
        let mut expect = case.expect.clone();
        expect.push(format!("{file}:"));
        assert_refused(&case.name, code, &err, took, &expect);
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn every_hostile_command_line_is_refused_before_it_allocates() {
    let d = tmp_dir("hostile-cli");
    let world = repo().join("worlds/default.toml");
    for case in corpus().cli {
        let out = d.join(&case.name);
        let args: Vec<String> = case
            .args
            .iter()
            .map(|a| {
                a.replace("{world}", world.to_str().unwrap())
                    .replace("{out}", out.to_str().unwrap())
            })
            .collect();
        let (code, err, took) = run_limited(&args, &d);
        assert_refused(&case.name, code, &err, took, &case.expect);
    }
    let _ = std::fs::remove_dir_all(&d);
}
