//! The command line as a user drives it: runs, determinism, and bad input.

use crate::common::*;

/// The 1-based line of the first occurrence of `needle` in the default world.
fn line_of(needle: &str) -> usize {
    default_world_text()
        .lines()
        .position(|l| l.contains(needle))
        .expect("needle in default world")
        + 1
}

/// The default world's text with its `ephemeris = "…"` line naming `nav` instead.
fn with_ephemeris(text: &str, nav: &str) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with("ephemeris = ") {
                format!("ephemeris = \"{nav}\"")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn summary_is_identical_for_one_and_two_threads() {
    let d = tmp_dir("threads");
    let (a, b) = (d.join("a"), d.join("b"));
    for (out, threads) in [(&a, "1"), (&b, "2")] {
        let o = hybridnav(&[
            "run",
            "worlds/default.toml",
            "--trials",
            "6",
            "--seed",
            "7",
            "--threads",
            threads,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let sa = std::fs::read(a.join("summary.json")).unwrap();
    let sb = std::fs::read(b.join("summary.json")).unwrap();
    assert!(!sa.is_empty());
    assert_eq!(
        sa, sb,
        "summary.json differs between --threads 1 and --threads 2"
    );
    // A different seed gives different numbers: the test above is not comparing constants.
    let c = d.join("c");
    let o = hybridnav(&[
        "run",
        "worlds/default.toml",
        "--trials",
        "6",
        "--seed",
        "8",
        "--quiet",
        "--out",
        c.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert_ne!(sa, std::fs::read(c.join("summary.json")).unwrap());
}

#[test]
fn summary_has_the_documented_keys() {
    let d = tmp_dir("keys");
    let o = hybridnav(&[
        "run",
        "--trials",
        "2",
        "--quiet",
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("summary.json")).unwrap()).unwrap();
    for k in [
        "world",
        "seed",
        "trials",
        "estimators",
        "world_hash",
        "hybridnav_version",
    ] {
        assert!(v.get(k).is_some(), "missing key {k}");
    }
    assert_eq!(v["trials"], 2);
    let est = v["estimators"].as_array().unwrap();
    // One summary entry per [[estimator]] table of the world.
    assert_eq!(
        est.len(),
        default_world_text().matches("[[estimator]]").count()
    );
    for e in est {
        for k in ["sigma1", "sigma2", "sigma3", "mean", "std", "rmse", "max"] {
            let x = e["error_3d_m"][k]
                .as_f64()
                .unwrap_or_else(|| panic!("{k} missing in {e}"));
            assert!(x.is_finite() && x >= 0.0);
        }
        let s = &e["error_3d_m"];
        assert!(
            s["sigma1"].as_f64() <= s["sigma2"].as_f64()
                && s["sigma2"].as_f64() <= s["sigma3"].as_f64()
        );
        let a = e["availability"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&a));
    }
}

#[test]
fn check_prints_a_summary() {
    let o = hybridnav(&["check", "worlds/default.toml"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(s.contains("estimator  GPS+BDS"), "{s}");
    // The world starts on 2020-06-25 04:00 GPST: 14 781 days after the GPS epoch
    // (1980-01-06), week 2111 (day 4 of it).
    assert!(s.contains("GPS week 2111"), "{s}");
}

/// Runs `check` on the default world edited by `edit` and returns stderr.
fn check_edited(name: &str, edit: impl Fn(&str) -> String) -> String {
    let d = tmp_dir(name);
    let p = write(&d, "w.toml", &edit(&default_world_text()));
    let o = hybridnav(&["check", p.to_str().unwrap()]);
    assert!(!o.status.success(), "a bad world was accepted");
    assert_eq!(o.status.code(), Some(2));
    stderr(&o)
}

#[test]
fn world_with_a_typo_names_file_line_and_key() {
    let e = check_edited("typo", |t| {
        t.replace("elevation_mask_deg = 10.0", "elevation_mask_dg = 10.0")
    });
    assert!(
        e.contains(&format!("w.toml:{}:1", line_of("elevation_mask_deg"))),
        "{e}"
    );
    assert!(e.contains("unknown field `elevation_mask_dg`"), "{e}");
    assert!(e.contains("expected one of"), "{e}");
}

#[test]
fn world_with_a_wrong_type_says_what_was_expected() {
    let e = check_edited("type", |t| t.replace("rate_hz = 1.0", "rate_hz = \"fast\""));
    assert!(
        e.contains(&format!("w.toml:{}:11", line_of("rate_hz"))),
        "{e}"
    );
    assert!(
        e.contains("invalid type: string \"fast\", expected f64"),
        "{e}"
    );
}

#[test]
fn world_with_an_impossible_value_names_the_key() {
    let e = check_edited("neg", |t| {
        t.replace("speed_mps = 10.0", "speed_mps = -10.0")
    });
    assert!(
        e.contains(&format!("w.toml:{}:", line_of("speed_mps"))),
        "{e}"
    );
    assert!(e.contains("platform.trajectory.speed_mps"), "{e}");
    assert!(e.contains("positive speed"), "{e}");
    let e = check_edited("lat", |t| {
        t.replacen("lat_deg = 40.00470", "lat_deg = 140.0", 1)
    });
    assert!(
        e.contains("world.origin.lat_deg") && e.contains("-90.0..=90.0") && e.contains("got 140"),
        "{e}"
    );
    let e = check_edited("sat", |t| t.replace("keep_highest = 2", "keep = [\"G99\"]"));
    assert!(
        e.contains("shielding[1].keep[0]") && e.contains("G99"),
        "{e}"
    );
    let e = check_edited("src", |t| {
        t.replace("systems = [\"gps\", \"bds\"]", "systems = [\"gps\"]")
    });
    assert!(
        // The first estimator using BeiDou is the second, "GPS+BDS".
        e.contains("estimator[1].sources[1]") && e.contains("does not simulate"),
        "{e}"
    );
    let e = check_edited("dup", |t| {
        t.replace("name = \"GPS+BDS\"", "name = \"GPS WLS\"")
    });
    assert!(e.contains("used twice"), "{e}");
}

#[test]
fn missing_world_and_missing_ephemeris_are_clear() {
    let o = hybridnav(&["check", "worlds/does-not-exist.toml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("worlds/does-not-exist.toml") && stderr(&o).contains("cannot read"),
        "{}",
        stderr(&o)
    );
    let e = check_edited("eph", |t| with_ephemeris(t, "nowhere.rnx"));
    assert!(
        e.contains("world.ephemeris") && e.contains("does not exist"),
        "{e}"
    );
}

#[test]
fn malformed_toml_gives_line_and_column() {
    let e = check_edited("syntax", |t| t.replace("[sensors.gnss]", "[sensors.gnss"));
    assert!(
        e.contains(&format!("w.toml:{}:", line_of("[sensors.gnss]"))),
        "{e}"
    );
}

#[test]
fn empty_sky_is_a_clear_error() {
    let Some(g) = shared_gnss() else { return };
    // brdc1820.10n holds 2010 orbits; the world starts in 2020, so no satellite is usable.
    let nav = g.join("brdc1820.10n");
    let e = check_edited("empty", |t| {
        with_ephemeris(t, nav.to_str().unwrap())
            .replace("systems = [\"gps\", \"bds\"]", "systems = [\"gps\"]")
            .replace(
                "sources = [\"gps\", \"bds\", \"dtmb\"]",
                "sources = [\"gps\", \"dtmb\"]",
            )
            .replace("sources = [\"gps\", \"bds\"]", "sources = [\"gps\"]")
    });
    assert!(e.contains("empty sky"), "{e}");
    assert!(e.contains("2010-07-01"), "{e}");
}

#[test]
fn truncated_rinex_names_the_line() {
    let Some(g) = shared_gnss() else { return };
    let text = std::fs::read_to_string(g.join("brdc1820.10n")).unwrap();
    // Cut the file in the middle of the fourth record.
    let lines: Vec<&str> = text.lines().collect();
    let header_end = lines
        .iter()
        .position(|l| l.contains("END OF HEADER"))
        .unwrap();
    let cut = header_end + 1 + 8 * 3 + 5;
    let d = tmp_dir("trunc");
    let p = write(&d, "cut.10n", &(lines[..cut].join("\n") + "\n"));
    let o = hybridnav(&[
        "ephemeris",
        "positions",
        "--nav",
        p.to_str().unwrap(),
        "--start",
        "2010-07-01T00:00:00",
        "--end",
        "2010-07-01T00:10:00",
        "--step",
        "60",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("cut.10n"), "{e}");
    assert!(
        e.contains(&format!("{}", cut + 1)) || e.contains(&format!("{cut}")),
        "{e}"
    );
}

#[test]
fn bad_run_arguments_are_refused() {
    let o = hybridnav(&["run", "--trials", "0", "--quiet"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--trials 0: expected 1 to 100000000"),
        "{}",
        stderr(&o)
    );
    let o = hybridnav(&[
        "ephemeris",
        "positions",
        "--nav",
        "x",
        "--start",
        "2020-13-01T00:00:00",
        "--end",
        "2020-01-01T00:00:00",
        "--step",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn positions_csv_matches_precise_orbit() {
    let Some(g) = shared_gnss() else { return };
    let nav = g.join("brdc1820.10n");
    let o = hybridnav(&[
        "ephemeris",
        "positions",
        "--nav",
        nav.to_str().unwrap(),
        "--start",
        "2010-07-01T00:00:00",
        "--end",
        "2010-07-01T00:30:00",
        "--step",
        "900",
        "--sats",
        "G05",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let mut lines = out.lines();
    assert_eq!(
        lines.next(),
        Some("sat,gpst_week,gpst_tow_s,x_m,y_m,z_m,clock_s")
    );
    let first: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&first[..3], &["G05", "1590", "345600.000"]);
    // igs15904.sp3, epoch 2010-07-01 00:00:00, PG05 (km), read independently here.
    let sp3 = std::fs::read_to_string(g.join("igs15904.sp3")).unwrap();
    let line = sp3.lines().find(|l| l.starts_with("PG05")).unwrap();
    let v: Vec<f64> = line[4..]
        .split_whitespace()
        .take(3)
        .map(|x| x.parse::<f64>().unwrap() * 1000.0)
        .collect();
    let p: Vec<f64> = first[3..6].iter().map(|x| x.parse().unwrap()).collect();
    let err = ((p[0] - v[0]).powi(2) + (p[1] - v[1]).powi(2) + (p[2] - v[2]).powi(2)).sqrt();
    assert!(err < 5.0, "broadcast vs precise G05: {err} m");
    assert_eq!(out.lines().count(), 1 + 3);
}

#[test]
fn synth_reproduces_the_embedded_ephemeris_and_reads_back() {
    let d = tmp_dir("synth");
    let out = d.join("nominal.rnx");
    let o = hybridnav(&[
        "ephemeris",
        "synth",
        "--start",
        "2018-06-01T00:00:00",
        "--hours",
        "48",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let written = std::fs::read(&out).unwrap();
    let embedded = std::fs::read(repo().join("ephemeris/nominal-gps-bds.rnx")).unwrap();
    assert!(
        written == embedded,
        "ephemeris synth no longer reproduces ephemeris/nominal-gps-bds.rnx"
    );
    // The file reads back through the CLI: the BeiDou GEO C01 stays over its longitude.
    let o = hybridnav(&[
        "ephemeris",
        "positions",
        "--nav",
        out.to_str().unwrap(),
        "--start",
        "2018-06-01T00:00:00",
        "--end",
        "2018-06-01T12:00:00",
        "--step",
        "3600",
        "--sats",
        "G01,C01",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = String::from_utf8_lossy(&o.stdout);
    let rows: Vec<Vec<String>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(rows.len(), 2 * 13);
    for r in rows.iter().filter(|r| r[0] == "C01") {
        let (x, y, z): (f64, f64, f64) = (
            r[3].parse().unwrap(),
            r[4].parse().unwrap(),
            r[5].parse().unwrap(),
        );
        let lon = y.atan2(x).to_degrees();
        let radius = (x * x + y * y + z * z).sqrt();
        assert!((lon - 140.0).abs() < 0.5, "C01 longitude {lon}");
        assert!(
            (radius - 42_164_000.0).abs() < 20_000.0,
            "C01 radius {radius}"
        );
    }
    let o = hybridnav(&[
        "ephemeris",
        "synth",
        "--start",
        "2018-06-01T00:00:00",
        "--hours",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--hours"), "{}", stderr(&o));
}

/// `dtmb iq` output as the `sigmf` Python package (the SigMF reference implementation)
/// reads it: the metadata validates against the SigMF schema and the samples match.
#[test]
fn dtmb_iq_is_read_back_by_the_sigmf_package() {
    let probe = std::process::Command::new("python3")
        .args(["-c", "import sigmf"])
        .output();
    if !matches!(probe, Ok(ref o) if o.status.success()) {
        skip("the sigmf Python package is not installed (CI installs it)");
        return;
    }
    let d = tmp_dir("sigmf");
    let base = d.join("pn945");
    let o = hybridnav(&[
        "dtmb",
        "iq",
        "--mode",
        "pn945",
        "--frames",
        "3",
        "--snr-db",
        "12",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let script = r#"
import sys, numpy as np, sigmf
from sigmf import sigmffile
f = sigmffile.fromfile(sys.argv[1])
f.validate()
x = f.read_samples()
g = f.get_global_info()
ann = f.get_annotations()
cap = f.get_captures()
print(len(x), g["core:datatype"], g["core:sample_rate"], cap[0]["core:frequency"], len(ann), ann[1]["core:sample_start"], ann[1]["core:label"])
print(repr(float(np.sum(np.abs(x[:500]) ** 2))))
"#;
    let py = std::process::Command::new("python3")
        .args(["-c", script, base.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        py.status.success(),
        "python sigmf failed: {}",
        String::from_utf8_lossy(&py.stderr)
    );
    let out = String::from_utf8_lossy(&py.stdout);
    let mut lines = out.lines();
    let fields: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
    assert_eq!(
        fields[..7],
        [
            "14175",
            "cf32_le",
            "7560000.0",
            "482000000.0",
            "3",
            "4725",
            "frame"
        ]
    );
    let energy_py: f64 = lines.next().unwrap().parse().unwrap();
    let rec = hybridnav::dtmb::sigmf::read_sigmf(&base).unwrap();
    let energy_rs: f64 = rec.samples[..500]
        .iter()
        .map(|s| f64::from(s.norm_sqr()))
        .sum();
    assert!(
        (energy_py - energy_rs).abs() <= 1e-6 * energy_rs,
        "{energy_py} vs {energy_rs}"
    );
}

#[test]
fn dtmb_iq_bad_input_is_refused() {
    let d = tmp_dir("iqbad");
    let base = d.join("x");
    let b = base.to_str().unwrap();
    for (args, needle) in [
        (
            vec!["--mode", "pn999", "--frames", "2", "--snr-db", "3"],
            "valid names are PN420, PN595, PN945",
        ),
        (vec!["--frames", "0", "--snr-db", "3"], "frames"),
        (vec!["--frames", "2", "--snr-db", "NaN"], "finite"),
        (
            vec!["--frames", "2", "--snr-db", "3", "--channel", "99"],
            "DS-99",
        ),
        (
            vec!["--frames", "2", "--snr-db", "3", "--format", "ci16"],
            "cf32 or ci8",
        ),
    ] {
        let mut a = vec!["dtmb", "iq", "--out", b];
        a.extend(args);
        let o = hybridnav(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}");
        assert!(stderr(&o).contains(needle), "{a:?}: {}", stderr(&o));
    }
}

#[test]
fn dtmb_iq_rejects_negative_counts_and_infinite_snr() {
    let d = tmp_dir("iqbad2");
    let base = d.join("x");
    let b = base.to_str().unwrap();
    for (args, needle) in [
        (vec!["--frames", "-3", "--snr-db", "3"], "--frames"),
        (vec!["--frames", "2", "--snr-db", "inf"], "finite"),
        (vec!["--frames", "2", "--snr-db", "-inf"], "finite"),
        (
            vec!["--mode", "PN9450", "--frames", "2", "--snr-db", "3"],
            "PN945",
        ),
        (
            vec!["--frames", "2", "--snr-db", "3", "--channel", "12"],
            "DS-12",
        ),
    ] {
        let mut a = vec!["dtmb", "iq", "--out", b];
        a.extend(args);
        let o = hybridnav(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}");
        assert!(stderr(&o).contains(needle), "{a:?}: {}", stderr(&o));
    }
}
