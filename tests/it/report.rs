//! `report.html` as a user opens it: a self-contained page that headless Chromium loads,
//! whose every chart is well-formed SVG.

use crate::common::{hybridnav, tmp_dir};
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
            html.contains(&format!("<tr><td>{name}</td>")),
            "no row {name}"
        );
    }
    let n_svg = html.matches("<svg ").count();
    assert_eq!(n_svg, 6, "six charts expected");

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
            assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "6");
        }
        Err(e) => crate::common::skip(&format!("python3 not found ({e}); SVGs not parsed as XML")),
    }

    // Headless Chromium loads it: the DOM it builds holds every chart.
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| std::path::Path::new(p).exists());
    let Some(chromium) = chromium else {
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
