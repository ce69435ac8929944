//! The deliberate mistakes of `tests/world-mistakes/`: `hybridnav check` on each file must
//! report the error or warning its `# expect:` line names, at that line and column and
//! with that table path.

use crate::common::{hybridnav, repo, stderr};

/// One `# expect: KIND LINE:COLUMN KEY | TEXT` line.
struct Expectation {
    error: bool,
    line: usize,
    column: usize,
    key: Option<String>,
    text: String,
}

fn expectation(file: &str, text: &str) -> Expectation {
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("# expect: "))
        .unwrap_or_else(|| panic!("{file}: no '# expect:' line"));
    let (head, want) = line
        .split_once(" | ")
        .unwrap_or_else(|| panic!("{file}: expected 'KIND L:C KEY | TEXT'"));
    let parts: Vec<&str> = head.split_whitespace().collect();
    assert_eq!(parts.len(), 3, "{file}: {head}");
    let (l, c) = parts[1].split_once(':').expect("LINE:COLUMN");
    Expectation {
        error: match parts[0] {
            "error" => true,
            "warning" => false,
            k => panic!("{file}: unknown kind {k}"),
        },
        line: l.parse().unwrap(),
        column: c.parse().unwrap(),
        key: (parts[2] != "-").then(|| parts[2].to_string()),
        text: want.to_string(),
    }
}

#[test]
fn every_deliberate_mistake_is_reported_at_its_line_and_table() {
    let dir = repo().join("tests/world-mistakes");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("tests/world-mistakes exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 16, "{} mistakes", files.len());
    let mut warnings = 0;
    for path in &files {
        let name = path.display().to_string();
        let exp = expectation(&name, &std::fs::read_to_string(path).unwrap());
        let o = hybridnav(&["check", &name]);
        let err = stderr(&o);
        let kind = if exp.error { "error" } else { "warning" };
        let prefix = match &exp.key {
            Some(k) => format!("{kind}: {name}:{}:{}: {k}: ", exp.line, exp.column),
            None => format!("{kind}: {name}:{}:{}: ", exp.line, exp.column),
        };
        let hit = err
            .lines()
            .find(|l| l.starts_with(&prefix))
            .unwrap_or_else(|| panic!("{name}: expected a line starting '{prefix}', got:\n{err}"));
        assert!(
            hit.contains(&exp.text),
            "{name}: '{}' not in '{hit}'",
            exp.text
        );
        if exp.error {
            assert_eq!(o.status.code(), Some(2), "{name}");
        } else {
            warnings += 1;
            assert!(o.status.success(), "{name}: {err}");
            // A warning is the only thing wrong with the file.
            assert_eq!(err.matches("warning:").count(), 1, "{name}: {err}");
        }
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    assert!(warnings >= 6, "{warnings} warnings");
}

/// The shipped worlds raise no plausibility warning: the warnings fire on slips, not on
/// the values real scenarios use.
#[test]
fn shipped_worlds_have_no_warnings() {
    let mut worlds: Vec<_> = std::fs::read_dir(repo().join("worlds"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    worlds.sort();
    for w in worlds {
        let o = hybridnav(&["check", w.to_str().unwrap(), "--step", "10"]);
        let err = stderr(&o);
        assert!(o.status.success(), "{}: {err}", w.display());
        assert!(!err.contains("warning:"), "{}: {err}", w.display());
    }
}
