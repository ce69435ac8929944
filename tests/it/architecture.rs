//! The layers of hybridnav, written down once and held against the code (a tidy test, as
//! rust-analyzer keeps one).
//!
//! Every top-level module has a layer and a crate. A module may name (`crate::x`) only
//! modules of a strictly lower layer, so the module graph is acyclic and every
//! dependency points down; a module's crate may depend only on the crates listed for it
//! here. The compiler already refuses a path into a crate that is not a dependency; this
//! test also refuses the edges the compiler cannot see (two modules of one crate, a new
//! upward crate dependency) and keeps the table below the one place the layering is
//! stated. `docs/architecture.md` draws the same table.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `(module, crate directory, layer)`, bottom to top.
const MODULES: &[(&str, &str, u8)] = &[
    ("core", "crates/core", 0),
    ("io", "crates/core", 1),
    ("motion", "crates/core", 1),
    ("measurement", "crates/core", 2),
    ("metrics", "crates/core", 2),
    ("engine", "crates/core", 3),
    ("fusion", "crates/fusion", 4),
    ("propagation", "crates/gnss", 2),
    ("gnss", "crates/gnss", 4),
    ("dtmb", "crates/dtmb", 4),
    ("tcofdm", "crates/dtmb", 5),
    ("beacons", "crates/sensors", 4),
    ("inertial", "crates/sensors", 5),
    ("fm", "crates/sensors", 5),
    ("magnetic", "crates/sensors", 6),
    ("world", "crates/sim", 7),
    ("report", "crates/run", 8),
    ("montecarlo", "crates/run", 9),
    ("spp", ".", 5),
    ("export", ".", 9),
    ("layout", ".", 9),
    ("reproduce", ".", 10),
    ("cli", ".", 11),
];

/// `(crate directory, the workspace crates it may depend on)`.
const CRATES: &[(&str, &[&str])] = &[
    ("crates/core", &[]),
    ("crates/fusion", &["core"]),
    ("crates/gnss", &["core"]),
    ("crates/dtmb", &["core", "gnss"]),
    ("crates/sensors", &["core", "fusion", "gnss"]),
    ("crates/sim", &["core", "fusion", "gnss", "dtmb", "sensors"]),
    (
        "crates/run",
        &["core", "fusion", "gnss", "dtmb", "sensors", "sim"],
    ),
    (
        ".",
        &["core", "fusion", "gnss", "dtmb", "sensors", "sim", "run"],
    ),
];

/// One `crate::to` path in a file of module `from`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Edge {
    from: String,
    to: String,
    at: String,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn module_dir(module: &str, krate: &str) -> PathBuf {
    root().join(krate).join("src").join(module)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The modules named by `crate::…` paths in `text` (a file of module `from`), with line
/// numbers: plain paths (`crate::gnss::…`) and the first segment of each item of a
/// grouped import (`use crate::{gnss::…, fm::…}`). Comments, doc comments included, are
/// left out, so an intra-doc link to a higher layer is not an edge.
fn edges_in(from: &str, at: &str, text: &str) -> Vec<Edge> {
    let mut out = Vec::new();
    let code: Vec<&str> = text
        .lines()
        .map(|l| l.find("//").map_or(l, |i| &l[..i]))
        .collect();
    let joined = code.join("\n");
    let line_of = |pos: usize| joined[..pos].matches('\n').count() + 1;
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut push = |to: &str, pos: usize| {
        if to != from {
            out.push(Edge {
                from: from.to_string(),
                to: to.to_string(),
                at: format!("{at}:{}", line_of(pos)),
            });
        }
    };
    let mut search = 0;
    while let Some(i) = joined[search..].find("crate::") {
        let start = search + i;
        search = start + "crate::".len();
        // `hybridnav_core::…` or `$crate::` are not this crate's paths.
        if joined[..start].chars().next_back().is_some_and(is_ident) {
            continue;
        }
        let rest = &joined[search..];
        if let Some(group) = rest.strip_prefix('{') {
            // A grouped import: the first segment of every top-level item.
            let mut depth = 0usize;
            let mut item_start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && is_ident(c) => {
                        let name: String =
                            group[k..].chars().take_while(|&c| is_ident(c)).collect();
                        push(&name, search + 1 + k);
                        item_start = false;
                    }
                    c if !c.is_whitespace() => item_start = false,
                    _ => {}
                }
            }
        } else {
            let name: String = rest.chars().take_while(|&c| is_ident(c)).collect();
            push(&name, search);
        }
    }
    out
}

fn layer_of(module: &str) -> Option<(&'static str, u8)> {
    MODULES
        .iter()
        .find(|(m, _, _)| *m == module)
        .map(|&(_, k, l)| (k, l))
}

fn crate_name(dir: &str) -> &str {
    dir.rsplit('/').next().unwrap()
}

/// The edges that break the layering: to an unknown module, to a module of the same or a
/// higher layer, or into a crate the source crate may not depend on.
fn violations(edges: &[Edge]) -> Vec<String> {
    let mut v = Vec::new();
    for e in edges {
        let (Some((from_crate, from_layer)), Some((to_crate, to_layer))) =
            (layer_of(&e.from), layer_of(&e.to))
        else {
            // Every crate root holds only modules, so `crate::X` must name one of the
            // table (edges are only ever read from the table's modules).
            v.push(format!(
                "{}: {} -> {}: not a module of the layer table",
                e.at, e.from, e.to
            ));
            continue;
        };
        if to_layer >= from_layer {
            v.push(format!(
                "{}: {} (layer {from_layer}) uses {} (layer {to_layer}): dependencies point down",
                e.at, e.from, e.to
            ));
        }
        if from_crate != to_crate {
            let allowed = CRATES
                .iter()
                .find(|(c, _)| *c == from_crate)
                .map_or(&[][..], |(_, d)| *d);
            if !allowed.contains(&crate_name(to_crate)) {
                v.push(format!(
                    "{}: {} ({from_crate}) uses {} ({to_crate}), a crate it may not depend on",
                    e.at, e.from, e.to
                ));
            }
        }
    }
    v
}

fn all_edges() -> Vec<Edge> {
    let mut edges = Vec::new();
    for &(module, krate, _) in MODULES {
        let dir = module_dir(module, krate);
        let mut files = Vec::new();
        rust_files(&dir, &mut files);
        assert!(!files.is_empty(), "{}: no sources", dir.display());
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            let at = f.strip_prefix(root()).unwrap().display().to_string();
            edges.extend(edges_in(module, &at, &text));
        }
    }
    edges
}

/// Every strongly connected component of more than one module (Tarjan).
fn cycles(edges: &[Edge]) -> Vec<Vec<String>> {
    let names: Vec<&str> = MODULES.iter().map(|m| m.0).collect();
    let index = |n: &str| names.iter().position(|&m| m == n);
    let mut adj = vec![Vec::new(); names.len()];
    for e in edges {
        if let (Some(a), Some(b)) = (index(&e.from), index(&e.to)) {
            adj[a].push(b);
        }
    }
    struct T<'a> {
        adj: &'a [Vec<usize>],
        idx: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(t: &mut T<'_>, v: usize) {
        t.idx[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for k in 0..t.adj[v].len() {
            let w = t.adj[v][k];
            match t.idx[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(iw) if t.on[w] => t.low[v] = t.low[v].min(iw),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.idx[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on[w] = false;
                comp.push(w);
                if w == v {
                    break;
                }
            }
            t.out.push(comp);
        }
    }
    let n = names.len();
    let mut t = T {
        adj: &adj,
        idx: vec![None; n],
        low: vec![0; n],
        on: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if t.idx[v].is_none() {
            visit(&mut t, v);
        }
    }
    t.out
        .into_iter()
        .filter(|c| c.len() > 1)
        .map(|c| {
            let mut c: Vec<String> = c.into_iter().map(|i| names[i].to_string()).collect();
            c.sort();
            c
        })
        .collect()
}

#[test]
fn the_module_graph_follows_the_layers() {
    let edges = all_edges();
    assert!(
        edges.len() > 300,
        "the scan found only {} edges",
        edges.len()
    );
    let v = violations(&edges);
    assert!(
        v.is_empty(),
        "{} forbidden imports:\n{}",
        v.len(),
        v.join("\n")
    );
    assert_eq!(cycles(&edges), Vec::<Vec<String>>::new());
}

#[test]
fn every_module_and_crate_is_in_the_layer_table() {
    let mut found = Vec::new();
    for &(krate, _) in CRATES {
        let src = root().join(krate).join("src");
        for e in std::fs::read_dir(&src).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                let m = p.file_name().unwrap().to_string_lossy().to_string();
                assert_eq!(
                    layer_of(&m).map(|l| l.0),
                    Some(krate),
                    "{} is not in the layer table under {krate}",
                    p.display()
                );
                found.push(m);
            }
        }
    }
    found.sort();
    let mut listed: Vec<String> = MODULES.iter().map(|m| m.0.to_string()).collect();
    listed.sort();
    assert_eq!(
        found, listed,
        "the table lists a module that does not exist"
    );

    // The workspace members are the table's crates, and each depends only on crates the
    // table allows.
    let root_toml = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    for &(krate, allowed) in CRATES {
        if krate != "." {
            assert!(
                root_toml.contains(&format!("\"{krate}\"")),
                "{krate} is not a workspace member"
            );
        }
        let toml = std::fs::read_to_string(root().join(krate).join("Cargo.toml")).unwrap();
        let deps_section = toml
            .split("\n[")
            .find(|s| s.starts_with("dependencies]"))
            .unwrap_or("");
        let mut deps: Vec<&str> = deps_section
            .lines()
            .filter_map(|l| l.strip_prefix("hybridnav-"))
            .map(|l| l.split([' ', '=', '.']).next().unwrap())
            .collect();
        deps.sort_unstable();
        let mut want = allowed.to_vec();
        want.sort_unstable();
        assert_eq!(deps, want, "{krate}/Cargo.toml's workspace dependencies");
    }
}

/// The check itself fails on what it must refuse: an upward import (fusion naming
/// world), a same-layer import, a grouped import, a module outside the table, a crate
/// dependency the table does not allow, and a cycle.
#[test]
fn the_layer_check_refuses_forbidden_imports() {
    let e = edges_in(
        "fusion",
        "x.rs",
        "use crate::core::System;\n// crate::world in a comment\nuse crate::world::World;\n",
    );
    assert_eq!(e.len(), 2, "{e:?}");
    let v = violations(&e);
    assert_eq!(v.len(), 2, "{v:?}");
    assert!(
        v[0].starts_with("x.rs:3: fusion (layer 4) uses world (layer 7)"),
        "{v:?}"
    );
    assert!(v[1].contains("a crate it may not depend on"), "{v:?}");

    let e = edges_in(
        "gnss",
        "y.rs",
        "use crate::{\n    core::Geodetic,\n    dtmb::pn,\n};",
    );
    let v = violations(&e);
    assert_eq!(v.len(), 2, "{v:?}");
    assert!(
        v[0].starts_with("y.rs:3: gnss (layer 4) uses dtmb (layer 4)"),
        "{v:?}"
    );

    let e = edges_in(
        "core",
        "z.rs",
        "let x = crate::nowhere::f(); let y = hybridnav_core::core::f();",
    );
    assert_eq!(violations(&e).len(), 1);

    let mut e = all_edges();
    e.push(Edge {
        from: "core".into(),
        to: "world".into(),
        at: "injected".into(),
    });
    let c = cycles(&e);
    assert_eq!(c.len(), 1, "{c:?}");
    assert!(c[0].contains(&"core".to_string()) && c[0].contains(&"world".to_string()));
}

/// The architecture document names every crate and every module of the table, so a new
/// crate or module cannot land without its place in the map.
#[test]
fn the_architecture_document_lists_every_crate() {
    let doc = std::fs::read_to_string(root().join("docs/architecture.md")).unwrap();
    let mut by_crate: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for &(m, k, _) in MODULES {
        by_crate.entry(k).or_default().push(m);
    }
    for (krate, modules) in by_crate {
        let name = if krate == "." { "hybridnav" } else { krate };
        assert!(
            doc.contains(name),
            "docs/architecture.md does not mention {name}"
        );
        for m in modules {
            assert!(
                doc.contains(&format!("`{m}`")) || doc.contains(&format!("`{m}/`")),
                "docs/architecture.md does not name `{m}`"
            );
        }
    }
}
