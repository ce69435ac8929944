//! The world file's JSON Schema (`hybridnav schema`), its generated reference
//! (`docs/world-file.md`) and `check --resolved`.
//!
//! The schema is checked by an independent implementation, Python's `jsonschema` reading
//! the TOML with `tomllib`: every shipped world must be valid, and every deliberate
//! mistake of `tests/world-mistakes/` that a schema can express must be refused at the
//! table path the loader names.

use crate::common::{hybridnav, python_has, repo, shared_gnss, stderr, tmp_dir};
use hybridnav::world::reference;
use std::path::PathBuf;

/// The shipped worlds: `worlds/*.toml`, sorted.
fn shipped_worlds() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(repo().join("worlds"))
        .expect("worlds/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 8, "{} worlds", files.len());
    files
}

/// Whether a world can be loaded here: the worlds that read a navigation file from
/// `../shared` need it.
fn loadable(path: &std::path::Path) -> bool {
    let text = std::fs::read_to_string(path).expect("read world");
    !text.contains("shared/data/gnss/") || shared_gnss().is_some()
}

#[test]
fn the_committed_world_file_reference_is_current() {
    let fresh = reference::markdown();
    let committed = std::fs::read_to_string(repo().join("docs/world-file.md"))
        .expect("docs/world-file.md is committed");
    assert!(
        fresh == committed,
        "docs/world-file.md is stale: run `cargo run --release -- schema --markdown --out docs/world-file.md`"
    );
}

/// The reference lists every key of the schema's top-level tables, with the units in the
/// keys' names, defaults and the ranges the loader enforces.
#[test]
fn the_reference_carries_types_units_defaults_and_ranges() {
    let md = reference::markdown();
    for row in [
        "| `sensors.gnss.rate_hz` | float | Hz | `1.0` | 0.001 to 100.0 |",
        "| `sensors.gnss.elevation_mask_deg` | float | ° | `10.0` | ≥ -5.0; < 90.0 |",
        "| `montecarlo.trials` | integer |  | `1` | 1 to 100000000 |",
        "| `world.origin.lat_deg` | float | ° | required | -90.0 to 90.0 |",
        "| `sensors.imu.gyro_arw_deg_per_sqrt_h` | float | °/√h | — |",
    ] {
        assert!(md.contains(row), "missing row {row}");
    }
    for section in [
        "`[world]`",
        "`[platform]`",
        "`[[estimator]]`",
        "`[[transmitter]]`",
    ] {
        assert!(
            md.contains(&format!("## {section}")),
            "no section {section}"
        );
    }
}

#[test]
fn schema_command_writes_the_schema_atomically_and_prints_the_same() {
    let dir = tmp_dir("schema-cmd");
    let out = dir.join("world.schema.json");
    let o = hybridnav(&["schema", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let written = std::fs::read_to_string(&out).expect("schema written");
    let printed = hybridnav(&["schema"]);
    assert!(printed.status.success());
    assert_eq!(written, String::from_utf8(printed.stdout).unwrap());
    let v: serde_json::Value = serde_json::from_str(&written).expect("JSON");
    assert_eq!(
        v["$schema"], "http://json-schema.org/draft-07/schema#",
        "draft-07, the draft taplo supports"
    );
    assert_eq!(v["additionalProperties"], false, "unknown keys are refused");
}

/// Runs `tests/python/schema_check.py` on `files`; one JSON object per file.
fn python_check(files: &[PathBuf]) -> Option<Vec<serde_json::Value>> {
    if !python_has(&["jsonschema", "tomllib"]) {
        return None;
    }
    let dir = tmp_dir("schema-py");
    let schema = dir.join("world.schema.json");
    std::fs::write(
        &schema,
        serde_json::to_string(&reference::json_schema()).unwrap(),
    )
    .unwrap();
    let o = std::process::Command::new("python3")
        .arg(repo().join("tests/python/schema_check.py"))
        .arg(&schema)
        .args(files)
        .output()
        .expect("run python3");
    assert!(
        o.status.success(),
        "schema_check.py failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    assert_eq!(lines.len(), files.len());
    Some(lines)
}

#[test]
fn jsonschema_accepts_every_shipped_world_and_its_resolved_form() {
    let mut files = shipped_worlds();
    // The resolved form writes every default out: those values must satisfy the schema too.
    let dir = tmp_dir("schema-resolved");
    for w in shipped_worlds().iter().filter(|w| loadable(w)) {
        let world = hybridnav::world::load_world(w).expect("shipped world loads");
        let text = reference::resolved_toml(&world.file).expect("resolved");
        let p = dir.join(w.file_name().unwrap());
        std::fs::write(&p, text).unwrap();
        files.push(p);
    }
    let Some(results) = python_check(&files) else {
        return;
    };
    for r in &results {
        assert_eq!(r["ok"], true, "jsonschema refuses a shipped world: {r}");
    }
}

/// The mistakes a JSON Schema cannot express: they are refused by the loader only.
const BEYOND_A_SCHEMA: &[(&str, &str)] = &[
    (
        "06-duplicate-estimator-name.toml",
        "uniqueness of a key across the tables of an array",
    ),
    (
        "07-bad-start-date.toml",
        "a calendar date that does not exist",
    ),
    (
        "17-residual-gate-on-the-builtin-ins.toml",
        "a constraint between two keys of one table (the gate needs a generic filter)",
    ),
    (
        "18-comparison-row-with-its-own-gate.toml",
        "a constraint across tables (a compared estimator's gate against [comparison])",
    ),
    (
        "20-rpe-interval-off-the-scoring-grid.toml",
        "a constraint between two keys of one table (the RPE interval a multiple of 1/rate_hz)",
    ),
];

#[test]
fn jsonschema_refuses_the_deliberate_mistakes_the_loader_refuses_at_the_same_table() {
    let dir = repo().join("tests/world-mistakes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/world-mistakes exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    let Some(results) = python_check(&files) else {
        return;
    };
    let mut refused = 0;
    for (path, r) in files.iter().zip(&results) {
        let name = path.file_name().unwrap().to_str().unwrap();
        let text = std::fs::read_to_string(path).unwrap();
        let expect = text
            .lines()
            .find_map(|l| l.strip_prefix("# expect: "))
            .unwrap_or_else(|| panic!("{name}: no expect line"));
        let parts: Vec<&str> = expect.split_whitespace().collect();
        let (kind, key) = (parts[0], parts[2]);
        let beyond = BEYOND_A_SCHEMA.iter().any(|(f, _)| *f == name);
        if kind == "warning" || beyond {
            // A warning is about a valid world; a mistake beyond a schema passes it.
            assert_eq!(
                r["ok"], true,
                "{name}: the schema refuses a valid world: {r}"
            );
            continue;
        }
        assert_eq!(
            r["ok"], false,
            "{name}: the loader refuses it, the schema accepts it"
        );
        let path = r["path"].as_str().unwrap();
        let message = r["message"].as_str().unwrap();
        // The schema names the table for an unknown key (the loader names the key itself).
        let same_place = path == key
            || key
                .strip_prefix(path)
                .and_then(|rest| rest.strip_prefix('.'))
                .is_some_and(|k| message.contains(&format!("'{k}'")));
        assert!(
            same_place,
            "{name}: the loader reports {key}, jsonschema {path}: {message}"
        );
        refused += 1;
    }
    assert!(
        refused >= 7,
        "only {refused} mistakes refused by the schema"
    );
}

#[test]
fn a_resolved_world_loads_as_the_same_world_for_every_shipped_world() {
    for w in shipped_worlds().iter().filter(|w| loadable(w)) {
        let world = hybridnav::world::load_world(w).expect("shipped world loads");
        let resolved = reference::resolved_toml(&world.file).expect("resolved");
        // Parsed as if it were the file itself, so relative paths resolve the same way.
        let again = hybridnav::world::parse_world(&resolved, w)
            .unwrap_or_else(|e| panic!("{}: resolved text does not load: {e}", w.display()));
        let resolved_again = reference::resolved_toml(&again.file).unwrap();
        assert_eq!(resolved, resolved_again, "{}", w.display());
        // The summary names the text's hash, which differs; every other line must agree.
        let summary = |s: String| -> Vec<String> {
            s.lines()
                .filter(|l| !l.starts_with("file "))
                .map(String::from)
                .collect()
        };
        assert_eq!(
            summary(world.summary()),
            summary(again.summary()),
            "{}",
            w.display()
        );
        assert_eq!(world.warnings, again.warnings, "{}", w.display());
        // Presets are expanded: the resolved text names none.
        assert!(!resolved.contains("preset ="), "{}", w.display());
    }
}

#[test]
fn check_resolved_prints_the_resolved_world() {
    let o = hybridnav(&["check", "worlds/default.toml", "--resolved"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let world = hybridnav::world::load_world(&repo().join("worlds/default.toml")).unwrap();
    assert_eq!(
        String::from_utf8(o.stdout).unwrap(),
        reference::resolved_toml(&world.file).unwrap()
    );
}
