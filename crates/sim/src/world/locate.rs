//! Mapping a key path in a TOML document back to its line and column.
//!
//! serde reports type errors with a byte span, but checks made after deserialisation
//! (impossible values, references to things that do not exist) only know the key path
//! (`estimator[2].filter`). This module re-reads the document with `toml_edit`, which keeps
//! spans, so every error can name the line and column a user must edit.

use toml_edit::{ImDocument, Item};

/// One step of a key path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PathSeg {
    Key(String),
    Index(usize),
}

impl std::fmt::Display for PathSeg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PathSeg::Key(k) => f.write_str(k),
            PathSeg::Index(i) => write!(f, "[{i}]"),
        }
    }
}

/// Renders a key path as a user reads it: `estimator[1].filter`.
pub fn path_to_string(path: &[PathSeg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            PathSeg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            PathSeg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// 1-based line and column of a byte offset.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(offset, |nl| offset - nl - 1) + 1;
    (line, col)
}

/// The byte span of the deepest item of `path` present in the document (so a missing
/// key points at the table that should hold it), or `None` when the text does not parse.
pub fn span_of(text: &str, path: &[PathSeg]) -> Option<std::ops::Range<usize>> {
    let doc = ImDocument::parse(text).ok()?;
    let mut item: &Item = doc.as_item();
    let mut best = None;
    for seg in path {
        let next = match seg {
            PathSeg::Key(k) => item.get(k.as_str()),
            PathSeg::Index(i) => item.get(*i),
        };
        match next {
            Some(n) => {
                item = n;
                if let Some(sp) = n.span() {
                    best = Some(sp);
                } else if let Some(t) = n.as_table() {
                    best = t.span().or(best);
                }
            }
            None => break,
        }
    }
    best
}

/// Line and column of a key path (1, 1 when nothing of it can be found).
pub fn locate(text: &str, path: &[PathSeg]) -> (usize, usize) {
    span_of(text, path).map_or((1, 1), |sp| line_col(text, sp.start))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_keys_and_array_tables() {
        let text = "[world]\nname = \"x\"\n\n[[estimator]]\nname = \"a\"\n\n[[estimator]]\nname = \"b\"\nfilter = \"ekf\"\n";
        let p = vec![
            PathSeg::Key("estimator".into()),
            PathSeg::Index(1),
            PathSeg::Key("filter".into()),
        ];
        assert_eq!(locate(text, &p), (9, 10));
        let p = vec![PathSeg::Key("world".into()), PathSeg::Key("name".into())];
        assert_eq!(locate(text, &p), (2, 8));
        assert_eq!(
            path_to_string(&[
                PathSeg::Key("estimator".into()),
                PathSeg::Index(1),
                PathSeg::Key("filter".into())
            ]),
            "estimator[1].filter"
        );
    }

    #[test]
    fn inline_tables() {
        let text = "[platform]\ntrajectory = { kind = \"waypoints\", speed_mps = -3 }\n";
        let p = vec![
            PathSeg::Key("platform".into()),
            PathSeg::Key("trajectory".into()),
            PathSeg::Key("speed_mps".into()),
        ];
        let (l, c) = locate(text, &p);
        assert_eq!(l, 2);
        assert_eq!(&text.lines().nth(1).unwrap()[c - 1..c + 1], "-3");
    }
}
