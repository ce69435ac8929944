//! `report.html` as a user opens it: a self-contained page that headless Chromium loads,
//! whose every chart is well-formed SVG, and whose pages, laid out by Chromium, have no
//! overflow and no overlapping labels; and `report/figures/`, each chart as its own SVG.

use crate::common::{hybridnav, tmp_dir};
use std::path::{Path, PathBuf};
use std::process::Command;

#[test]
fn the_report_is_self_contained_and_opens_in_headless_chromium() {
    let d = tmp_dir("report");
    let out = d.join("run");
    let o = hybridnav(&[
        "run",
        "worlds/seed000-beihang.toml",
        "--trials",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    // Self-contained: nothing fetched, nothing executed.
    for banned in ["<script", "src=\"http", "href=\"http", "<link", "@import"] {
        assert!(!html.contains(banned), "report.html contains {banned}");
    }
    for section in [
        "Position error",
        "Error distribution",
        "Trajectories (trial 0)",
        "Error against time (trial 0)",
        "Modes (trial 0)",
        "Geometry (trial 0)",
        "Sky",
    ] {
        assert!(
            html.contains(&format!(">{section}</h2>")),
            "no section {section}"
        );
    }
    // The table lists the world's estimators under their names.
    for name in ["GPS", "GPS+DTMB", "Proposed"] {
        assert!(
            html.contains(&format!("<tr><td>{name}</td>"))
                || html.contains(&format!("<tr><td>{name} <span class=\"flag\">")),
            "no row {name}"
        );
    }
    let n_svg = html.matches("<svg ").count();
    assert_eq!(
        n_svg, 7,
        "seven charts expected (two trials: RMSE against time too)"
    );
    assert!(html.contains("<h2>RMSE against time</h2>"));

    // Every chart parses as XML (what a strict SVG reader requires).
    let script = r#"
import re, sys
import xml.etree.ElementTree as ET
html = open(sys.argv[1], encoding="utf-8").read()
svgs = re.findall(r"<svg .*?</svg>", html, re.S)
for s in svgs:
    ET.fromstring(s)
print(len(svgs))
"#;
    match Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(out.join("report.html"))
        .output()
    {
        Ok(o) => {
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), n_svg.to_string());
        }
        Err(e) => crate::common::skip(&format!("python3 not found ({e}); SVGs not parsed as XML")),
    }

    // Headless Chromium loads it: the DOM it builds holds every chart.
    let Some(chromium) = chromium() else {
        crate::common::skip("Chromium not installed (CI installs Debian's chromium)");
        let _ = std::fs::remove_dir_all(&d);
        return;
    };
    let profile = d.join("chromium-profile");
    let png = d.join("report.png");
    let run = |extra: &[&str]| {
        Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--allow-file-access-from-files",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(extra)
            .arg(format!("file://{}", out.join("report.html").display()))
            .output()
            .expect("run chromium")
    };
    let dom = run(&["--dump-dom"]);
    assert!(
        dom.status.success(),
        "{}",
        String::from_utf8_lossy(&dom.stderr)
    );
    let dom_text = String::from_utf8_lossy(&dom.stdout);
    assert_eq!(
        dom_text.matches("<svg ").count(),
        n_svg,
        "Chromium's DOM lost charts"
    );
    assert!(dom_text.contains("Proposed"));
    // And renders it: a screenshot of the page that is not blank.
    let shot = run(&[
        "--window-size=1200,3000",
        &format!("--screenshot={}", png.display()),
    ]);
    assert!(
        shot.status.success(),
        "{}",
        String::from_utf8_lossy(&shot.stderr)
    );
    let bytes = std::fs::read(&png).expect("screenshot written");
    assert!(bytes.starts_with(b"\x89PNG"), "not a PNG");
    assert!(
        bytes.len() > 50_000,
        "screenshot of {} bytes: blank page?",
        bytes.len()
    );
    let _ = std::fs::remove_dir_all(&d);
}

fn chromium() -> Option<&'static str> {
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| std::path::Path::new(p).exists())
}

/// Measures a page as Chromium lays it out, and writes what it finds into the page as
/// JSON in `<pre id="layout-check">` (read back from `--dump-dom`):
/// - `overflow`: the page wider than the window, an element whose content is wider than
///   its box (a scrolled or clipped table), or an element reaching past the window's
///   right edge;
/// - `clipped`: an SVG label leaving its figure, a table cell's text wider than the cell;
/// - `overlaps`: two labels (SVG `<text>`, the text of table cells) whose boxes intersect
///   by more than a pixel each way.
///
/// The report itself has no script (a test bans it); this is appended to a copy.
const LAYOUT_CHECK_JS: &str = r#"
(function () {
  var vw = document.documentElement.clientWidth;
  var out = { width: vw, labels: 0, overflow: [], clipped: [], overlaps: [] };
  var name = function (el) {
    var t = (el.textContent || '').trim().replace(/\s+/g, ' ').slice(0, 40);
    return el.tagName.toLowerCase() + ' "' + t + '"';
  };
  if (document.documentElement.scrollWidth > vw + 1) {
    out.overflow.push('page ' + document.documentElement.scrollWidth + ' px wide in a ' + vw + ' px window');
  }
  var all = document.body.querySelectorAll('*');
  for (var i = 0; i < all.length; i++) {
    var el = all[i];
    if (el.ownerSVGElement) continue;
    if (el.clientWidth > 0 && el.scrollWidth > el.clientWidth + 1) {
      out.overflow.push(name(el) + ': content ' + el.scrollWidth + ' px in ' + el.clientWidth + ' px');
    }
    var r = el.getBoundingClientRect();
    if (r.width > 0 && r.right > vw + 1) {
      out.overflow.push(name(el) + ': right edge at ' + Math.round(r.right) + ' px');
    }
  }
  var boxes = [];
  var texts = document.querySelectorAll('svg text');
  for (var i = 0; i < texts.length; i++) {
    var t = texts[i];
    var r = t.getBoundingClientRect();
    if (!(r.width > 0 && r.height > 0)) continue;
    var s = t.ownerSVGElement.getBoundingClientRect();
    if (r.left < s.left - 1 || r.right > s.right + 1 || r.top < s.top - 1 || r.bottom > s.bottom + 1) {
      out.clipped.push(name(t) + ' leaves its figure');
    }
    boxes.push({ r: r, el: t });
  }
  var cells = document.querySelectorAll('td, th');
  for (var i = 0; i < cells.length; i++) {
    var range = document.createRange();
    range.selectNodeContents(cells[i]);
    var rs = range.getClientRects();
    for (var k = 0; k < rs.length; k++) {
      if (rs[k].width > 0 && rs[k].height > 0) boxes.push({ r: rs[k], el: cells[i] });
    }
    var c = cells[i].getBoundingClientRect();
    var u = range.getBoundingClientRect();
    if (u.width > 0 && (u.left < c.left - 1 || u.right > c.right + 1)) {
      out.clipped.push(name(cells[i]) + ' wider than its cell');
    }
  }
  out.labels = boxes.length;
  for (var a = 0; a < boxes.length; a++) {
    for (var b = a + 1; b < boxes.length; b++) {
      if (boxes[a].el === boxes[b].el) continue;
      var p = boxes[a].r, q = boxes[b].r;
      var w = Math.min(p.right, q.right) - Math.max(p.left, q.left);
      var h = Math.min(p.bottom, q.bottom) - Math.max(p.top, q.top);
      if (w > 1 && h > 1) {
        out.overlaps.push(name(boxes[a].el) + ' overlaps ' + name(boxes[b].el));
      }
    }
  }
  var pre = document.createElement('pre');
  pre.id = 'layout-check';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
})();
"#;

/// What [`LAYOUT_CHECK_JS`] found on a page.
#[derive(Debug)]
struct LayoutCheck {
    labels: u64,
    overflow: Vec<String>,
    clipped: Vec<String>,
    overlaps: Vec<String>,
}

/// Chromium's flags for a headless run with its own profile in `dir`.
fn chromium_command(chromium: &str, dir: &Path, window: &str) -> Command {
    let mut c = Command::new(chromium);
    c.args([
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
        "--virtual-time-budget=5000",
    ])
    .arg(format!("--window-size={window}"))
    .arg(format!(
        "--user-data-dir={}",
        dir.join("chromium-profile").display()
    ));
    c
}

/// Lays `page` out in headless Chromium in a window of `window` ("W,H" px) and measures
/// it.
fn check_layout(chromium: &str, page: &Path, dir: &Path, window: &str) -> LayoutCheck {
    let html = std::fs::read_to_string(page).unwrap();
    let copy = dir.join(format!(
        "{}-check.html",
        page.file_stem().unwrap().to_string_lossy()
    ));
    let with_script = html.replacen(
        "</body>",
        &format!("<script>{LAYOUT_CHECK_JS}</script></body>"),
        1,
    );
    assert_ne!(with_script, html, "{} has no </body>", page.display());
    std::fs::write(&copy, with_script).unwrap();
    let o = chromium_command(chromium, dir, window)
        .arg("--dump-dom")
        .arg(format!("file://{}", copy.display()))
        .output()
        .expect("run chromium");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dom = String::from_utf8_lossy(&o.stdout);
    let start = dom
        .find("<pre id=\"layout-check\">")
        .unwrap_or_else(|| panic!("the check did not run on {}", page.display()))
        + "<pre id=\"layout-check\">".len();
    let end = start + dom[start..].find("</pre>").unwrap();
    // The DOM dump escapes text as HTML does.
    let json = dom[start..end]
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&nbsp;", "\u{a0}")
        .replace("&amp;", "&");
    let v: serde_json::Value = serde_json::from_str(&json).expect("the check's JSON");
    let list = |k: &str| -> Vec<String> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_str().unwrap().to_string())
            .collect()
    };
    LayoutCheck {
        labels: v["labels"].as_u64().unwrap(),
        overflow: list("overflow"),
        clipped: list("clipped"),
        overlaps: list("overlaps"),
    }
}

/// The check finds what it looks for: a hand-made page with two labels drawn over each
/// other, a label leaving its figure and a table wider than the window.
#[test]
fn the_layout_check_finds_overlapping_labels_and_overflow() {
    let Some(chromium) = chromium() else {
        crate::common::skip("Chromium not installed (CI installs Debian's chromium)");
        return;
    };
    let d = tmp_dir("report-check-negative");
    let bad = d.join("bad.html");
    let wide_row: String = (0..60).map(|k| format!("<td>column{k}</td>")).collect();
    std::fs::write(
        &bad,
        format!(
            r#"<!DOCTYPE html><html><head><meta charset="utf-8"><style>td{{white-space:nowrap}}</style></head><body>
<svg xmlns="http://www.w3.org/2000/svg" width="300" height="100" viewBox="0 0 300 100" font-size="11">
<text x="10" y="20">DTMB D01 (tower)</text><text x="14" y="22">FM F01 (tower)</text>
<text x="260" y="60">leaves the figure</text></svg>
<table><tr>{wide_row}</tr></table></body></html>"#
        ),
    )
    .unwrap();
    let r = check_layout(chromium, &bad, &d, "1280,2000");
    assert_eq!(r.overlaps.len(), 1, "{r:?}");
    assert!(r.overlaps[0].contains("DTMB D01") && r.overlaps[0].contains("FM F01"));
    assert_eq!(r.clipped.len(), 1, "{r:?}");
    assert!(r.clipped[0].contains("leaves the figure"));
    assert!(r.overflow.iter().any(|o| o.starts_with("page ")), "{r:?}");
    // And the same labels a line apart are not reported.
    let good = d.join("good.html");
    std::fs::write(
        &good,
        r#"<!DOCTYPE html><html><head><meta charset="utf-8"></head><body>
<svg xmlns="http://www.w3.org/2000/svg" width="300" height="100" viewBox="0 0 300 100" font-size="11">
<text x="10" y="20">DTMB D01 (tower)</text><text x="10" y="34">FM F01 (tower)</text></svg>
<table><tr><td>a</td><td>b</td></tr></table></body></html>"#,
    )
    .unwrap();
    let r = check_layout(chromium, &good, &d, "1280,2000");
    assert!(
        r.overlaps.is_empty() && r.clipped.is_empty() && r.overflow.is_empty(),
        "{r:?}"
    );
    assert_eq!(r.labels, 4);
    let _ = std::fs::remove_dir_all(&d);
}

/// The goal of the report's figures: Beihang (four estimators, towers on one mast far
/// off the map), seed 003 (seven estimators, the widest table) and the default world (the
/// per-segment table, long estimator names), laid out by Chromium
/// at 1280 and at 800 px, have no overflow, no label leaving its figure and no two labels over each
/// other; every figure is also a standalone SVG file under `report/figures/`, the same
/// bytes for the same seed.
#[test]
fn report_pages_have_no_overflow_or_overlapping_labels_in_chromium() {
    let d = tmp_dir("report-layout");
    let mut pages = Vec::new();
    for (world, name) in [
        ("worlds/seed000-beihang.toml", "beihang"),
        ("worlds/seed003-seamless.toml", "seed003"),
        ("worlds/default.toml", "default"),
    ] {
        let out = d.join(name);
        let o = hybridnav(&[
            "run",
            world,
            "--trials",
            "2",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        // Every inline chart is also a figure file, byte for byte.
        let figures = out.join("report/figures");
        let mut files: Vec<PathBuf> = std::fs::read_dir(&figures)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        assert_eq!(files.len(), html.matches("<svg ").count(), "{files:?}");
        for f in &files {
            assert_eq!(f.extension().unwrap(), "svg");
            let svg = std::fs::read_to_string(f).unwrap();
            assert!(
                html.contains(&svg),
                "{} is not the page's chart",
                f.display()
            );
        }
        pages.push((name, out, files));
    }
    // Same seed, same bytes: Beihang again into another directory.
    let again = d.join("beihang-again");
    let o = hybridnav(&[
        "run",
        "worlds/seed000-beihang.toml",
        "--trials",
        "2",
        "--quiet",
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    for f in &pages[0].2 {
        let name = f.file_name().unwrap();
        assert!(
            std::fs::read(f).unwrap()
                == std::fs::read(again.join("report/figures").join(name)).unwrap(),
            "{name:?} differs between two runs of one seed"
        );
    }

    // Each figure file is a standalone SVG document: the SVG namespace, a viewBox, a
    // width and a height, and a title, as a strict XML reader sees it.
    let script = r#"
import sys
import xml.etree.ElementTree as ET
NS = "{http://www.w3.org/2000/svg}"
n = 0
for path in sys.argv[1:]:
    root = ET.parse(path).getroot()
    assert root.tag == NS + "svg", (path, root.tag)
    for a in ("viewBox", "width", "height"):
        assert root.get(a), (path, a)
    w, h = float(root.get("width")), float(root.get("height"))
    assert root.get("viewBox").split() == ["0", "0", root.get("width"), root.get("height")], path
    assert w > 0 and h > 0, path
    title = root.find(NS + "title")
    assert title is not None and title.text.strip(), (path, "no title")
    n += 1
print(n)
"#;
    let all: Vec<&PathBuf> = pages.iter().flat_map(|p| p.2.iter()).collect();
    match Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(&all)
        .output()
    {
        Ok(o) => {
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            assert_eq!(
                String::from_utf8_lossy(&o.stdout).trim(),
                all.len().to_string()
            );
        }
        Err(e) => crate::common::skip(&format!("python3 not found ({e}); figures not parsed")),
    }

    let Some(chromium) = chromium() else {
        crate::common::skip("Chromium not installed (CI installs Debian's chromium)");
        let _ = std::fs::remove_dir_all(&d);
        return;
    };
    for (name, out, _) in &pages {
        // A desktop window, and a narrow one (the tables wrap, the charts scale down).
        for window in ["1280,2000", "800,2000"] {
            let r = check_layout(chromium, &out.join("report.html"), &d, window);
            eprintln!(
                "{name} at {window}: {} labels, {} overflowing, {} clipped, {} overlapping pairs",
                r.labels,
                r.overflow.len(),
                r.clipped.len(),
                r.overlaps.len()
            );
            assert!(r.labels > 200, "{name}: only {} labels measured", r.labels);
            assert!(
                r.overflow.is_empty(),
                "{name} {window}: overflow {:#?}",
                r.overflow
            );
            assert!(
                r.clipped.is_empty(),
                "{name} {window}: clipped {:#?}",
                r.clipped
            );
            assert!(
                r.overlaps.is_empty(),
                "{name} {window}: overlaps {:#?}",
                r.overlaps
            );
        }
        // And a screenshot of the page as a reader sees its first screens.
        let png = d.join(format!("{name}.png"));
        let shot = chromium_command(chromium, &d, "1280,2000")
            .arg(format!("--screenshot={}", png.display()))
            .arg(format!("file://{}", out.join("report.html").display()))
            .output()
            .expect("run chromium");
        assert!(
            shot.status.success(),
            "{}",
            String::from_utf8_lossy(&shot.stderr)
        );
        let bytes = std::fs::read(&png).expect("screenshot written");
        assert!(bytes.starts_with(b"\x89PNG"), "not a PNG");
        assert!(
            bytes.len() > 50_000,
            "{name}: screenshot of {} bytes",
            bytes.len()
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
