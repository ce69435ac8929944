//! The filter family inside the engine: every filter a world can name runs on the same
//! measurements, presets expand, modes are recorded, divergence is reported.

use crate::common::default_world_text;
use hybridnav::engine::trial::EstimatorTrace;
use hybridnav::world::load_world;
use hybridnav::world::trial::run_trial;

/// The default world (Kehui Road, real GPS/BDS geometry, shielding windows) with the
/// estimator tables replaced by `estimators`.
fn world_with(name: &str, estimators: &str) -> std::path::PathBuf {
    let text = default_world_text();
    let head = &text[..text
        .find("[[estimator]]")
        .expect("default world has estimators")];
    // Relative paths in the default world are relative to worlds/, so the test world is
    // written there under a unique name and removed by the caller.
    let path = crate::common::repo()
        .join("worlds")
        .join(format!("_test-{name}-{}.toml", std::process::id()));
    std::fs::write(&path, format!("{head}{estimators}")).unwrap();
    path
}

fn trace<'a>(t: &'a [EstimatorTrace], name: &str) -> &'a EstimatorTrace {
    t.iter().find(|e| e.name == name).expect(name)
}

/// `filter = "ekf"` (the generic Joseph-form EKF through the generic models) reproduces
/// the hand-optimised `ekf11` over a whole trial, outages included; the UKF and CKF agree
/// with it to centimetres (the ranges are nearly linear over a few metres of prior).
#[test]
fn family_filters_reproduce_ekf11_on_a_whole_trial() {
    let path = world_with(
        "family",
        r#"
[[estimator]]
name = "EKF11"
sources = ["gps", "bds"]
filter = "ekf11"

[[estimator]]
name = "EKF"
sources = ["gps", "bds"]
filter = "ekf"

[[estimator]]
name = "UKF"
sources = ["gps", "bds"]
filter = "ukf"

[[estimator]]
name = "CKF"
sources = ["gps", "bds"]
filter = "ckf"
"#,
    );
    let world = load_world(&path);
    let _ = std::fs::remove_file(&path);
    let world = world.unwrap();
    let r = run_trial(&world, 7, 0).unwrap();
    let base = trace(&r.estimators, "EKF11");
    assert!(base.epochs.len() > 100);
    for (name, tol_m) in [("EKF", 1e-6), ("UKF", 0.05), ("CKF", 0.05)] {
        let other = trace(&r.estimators, name);
        assert_eq!(other.epochs.len(), base.epochs.len(), "{name}");
        let mut worst: f64 = 0.0;
        for (a, b) in base.epochs.iter().zip(&other.epochs) {
            assert_eq!(a.t_s, b.t_s);
            let (Some(ea), Some(eb)) = (a.err_3d_m, b.err_3d_m) else {
                assert_eq!(
                    a.err_3d_m.is_some(),
                    b.err_3d_m.is_some(),
                    "{name} at {}",
                    a.t_s
                );
                continue;
            };
            worst = worst.max((ea - eb).abs());
            assert_eq!(a.used, b.used, "{name} at {} s", a.t_s);
        }
        eprintln!("{name}: largest |Δ error| against ekf11 {worst:.3e} m");
        assert!(worst < tol_m, "{name}: {worst} m");
    }
}

/// Presets expand into the paper's systems; a table's own keys override them; seed 003's
/// seamless scheme records its mode at every epoch and switches to GPS+BDS+DTMB in the
/// world's three-satellite window (40–80 s) and back to GPS+BDS outside it.
#[test]
fn presets_run_and_the_seamless_mode_follows_the_satellite_count() {
    let path = world_with(
        "presets",
        r#"
[[estimator]]
preset = "seed000-gps"

[[estimator]]
preset = "seed003-ekf"
sources = ["gps", "bds"]
# The preset's plane-turning model is seed 003's simulated aircraft; a car on real
# orbits takes the PVA + clock model with the same seamless scheme.
process = { model = "pva_clock" }

[[estimator]]
preset = "seed004-rekf-ranges"
name = "RE-KF (GNSS)"
sources = ["gps", "bds"]
"#,
    );
    let world = load_world(&path);
    let _ = std::fs::remove_file(&path);
    let world = world.unwrap();
    let r = run_trial(&world, 3, 0).unwrap();
    let names: Vec<&str> = r.estimators.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["GPS", "EKF", "RE-KF (GNSS)"]);
    let ekf = trace(&r.estimators, "EKF");
    let mode_at = |t: f64| {
        ekf.epochs
            .iter()
            .find(|e| (e.t_s - t).abs() < 1e-9)
            .and_then(|e| e.mode.as_deref())
    };
    assert_eq!(mode_at(10.0), Some("GPS+BDS"));
    assert_eq!(mode_at(60.0), Some("GPS+BDS+DTMB"));
    assert_eq!(mode_at(100.0), Some("GPS+BDS"));
    for e in &r.estimators {
        assert!(
            e.epochs.iter().all(|x| !x.numerical_failure),
            "{}: numerical failure",
            e.name
        );
    }
}

/// Bad estimator tables are refused with the key and what was expected.
#[test]
fn bad_family_tables_are_named() {
    let cases = [
        ("preset = \"seed009-x\"\n", "unknown preset 'seed009-x'"),
        (
            "name = \"P\"\nsources = [\"gps\"]\nfilter = \"pf\"\noptions = { particles = 1 }\n",
            "particles",
        ),
        (
            "name = \"W\"\nsources = [\"gps\"]\nfilter = \"wls\"\nselection = \"seamless\"\n",
            "'selection' applies to the filters",
        ),
        (
            "name = \"F\"\nsources = [\"gps\"]\nfilter = \"ekf\"\nfixes = [\"fm\"]\n",
            "'fm' is not a position-fix source",
        ),
        (
            "name = \"U\"\nsources = [\"gps\"]\nfilter = \"ukf\"\noptions = { ukf_alpha = -1.0 }\n",
            "ukf_alpha",
        ),
    ];
    for (i, (table, expect)) in cases.iter().enumerate() {
        let path = world_with(&format!("bad{i}"), &format!("[[estimator]]\n{table}"));
        let e = load_world(&path);
        let _ = std::fs::remove_file(&path);
        let msg = match e {
            Ok(_) => panic!("case {i} was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(msg.contains(expect), "case {i}: {msg}");
    }
}

/// A filter that diverges is reset and the reset reported, never a NaN in the output: a
/// particle filter with four particles cannot hold the 12-state problem, and every epoch
/// it gives is either finite or counted as a numerical failure.
#[test]
fn divergence_is_reported_not_propagated() {
    let path = world_with(
        "diverge",
        r#"
[[estimator]]
name = "PF4"
sources = ["gps"]
filter = "pf"
options = { particles = 4, divergence_pos_sigma_m = 50.0 }
"#,
    );
    let world = load_world(&path);
    let _ = std::fs::remove_file(&path);
    let world = world.unwrap();
    let r = run_trial(&world, 1, 0).unwrap();
    let pf = trace(&r.estimators, "PF4");
    for e in &pf.epochs {
        if let Some(err) = e.err_3d_m {
            assert!(err.is_finite(), "t = {}", e.t_s);
            assert!(!e.numerical_failure);
        }
        if let Some(s) = e.pos_sigma_m {
            assert!(s.is_finite() && s <= 50.0 + 1e-9, "t = {}: σ {s}", e.t_s);
        }
    }
}

/// Seed 000's DTMB clock correction (§3.1): with a tower whose clock runs 150 ns off GPS
/// time (and drifts 0.5 ppb), the uncorrected GPS+DTMB filter is pulled by tens of metres
/// and more; the preset `seed000-gps-dtmb`, which calibrates the tower from good GPS fixes,
/// removes that bias: its error with the offset is about its error on the same world
/// without one (the independent truth here), while the uncorrected filter's is several
/// times larger.
#[test]
fn dtmb_clock_correction_removes_a_tower_clock_offset() {
    let text =
        std::fs::read_to_string(crate::common::repo().join("worlds/seed000-kehui.toml")).unwrap();
    assert!(text.contains("pn_mode = \"pn945\""));
    let offset = text.replacen(
        "pn_mode = \"pn945\"",
        "pn_mode = \"pn945\"\nclock_offset_ns = 150.0\nclock_drift_ppb = 0.5",
        1,
    );
    // Mean 3-D error of the uncorrected and the corrected filter over two trials.
    let errors = |text: &str, tag: &str| -> (f64, f64) {
        let head = &text[..text.find("[[estimator]]").unwrap()];
        let path = crate::common::repo()
            .join("worlds")
            .join(format!("_test-clockcorr-{tag}-{}.toml", std::process::id()));
        std::fs::write(
            &path,
            format!(
                "{head}
[[estimator]]
name = \"raw\"
sources = [\"gps\", \"dtmb\"]
filter = \"ekf11\"

[[estimator]]
preset = \"seed000-gps-dtmb\"
"
            ),
        )
        .unwrap();
        let world = load_world(&path);
        let _ = std::fs::remove_file(&path);
        let world = world.unwrap();
        let mean = |t: &EstimatorTrace| {
            let e: Vec<f64> = t.epochs.iter().filter_map(|e| e.err_3d_m).collect();
            e.iter().sum::<f64>() / e.len() as f64
        };
        let (mut raw, mut corrected) = (0.0, 0.0);
        for trial in 0..2 {
            let r = run_trial(&world, 1, trial).unwrap();
            raw += mean(trace(&r.estimators, "raw")) / 2.0;
            corrected += mean(trace(&r.estimators, "GPS+DTMB")) / 2.0;
        }
        (raw, corrected)
    };
    let (raw, corrected) = errors(&offset, "offset");
    let (raw_clean, corrected_clean) = errors(&text, "clean");
    eprintln!(
        "mean 3-D error with the offset: uncorrected {raw:.1} m, corrected {corrected:.1} m; \
         without it: {raw_clean:.1} m, {corrected_clean:.1} m"
    );
    assert!(
        raw > 2.0 * raw_clean.max(corrected_clean),
        "the offset should bias the uncorrected filter: {raw} vs {raw_clean}"
    );
    assert!(
        corrected < 1.25 * corrected_clean + 2.0,
        "the correction should leave the error of the world without offset: {corrected} vs {corrected_clean}"
    );
    assert!(corrected < 0.5 * raw, "{corrected} vs {raw}");
}

/// Seed 000's adaptive system on its Beihang world: the fuzzy system leaves GPS-only mode
/// where the world keeps three satellites per system (the paper's sections 2 and 4,
/// t = 38–179 s and 382–574 s) and returns to it when the satellites come back (sections 3
/// and 5), as the paper's Fig. 9 narrative says; in the windows it uses the tower, whose
/// clock it calibrated while GPS alone was selected; and the adaptive row's tail is below
/// GPS+DTMB's, which is below GPS's (the order of the paper's Table 2).
#[test]
fn seed000_adaptive_switches_modes_where_fig9_says() {
    let world = load_world(&crate::common::repo().join("worlds/seed000-beihang.toml")).unwrap();
    let (mut in_window, mut in_window_not_a) = (0, 0);
    let (mut in_window_withheld, mut in_window_offered) = (0, 0);
    let (mut open, mut open_a) = (0, 0);
    let mut p95 = std::collections::BTreeMap::<String, Vec<f64>>::new();
    for trial in 0..2 {
        let r = run_trial(&world, 1, trial).unwrap();
        for e in &r.estimators {
            p95.entry(e.name.clone())
                .or_default()
                .extend(e.epochs.iter().filter_map(|x| x.err_3d_m));
        }
        for e in &trace(&r.estimators, "Proposed").epochs {
            let t = e.t_s;
            let window = (45.0..175.0).contains(&t) || (390.0..570.0).contains(&t);
            let clear = (10.0..35.0).contains(&t) || (200.0..370.0).contains(&t);
            if window {
                in_window += 1;
                in_window_not_a += usize::from(e.mode.as_deref() != Some("A"));
                // Outside its gate the filter refuses only DTMB ranges whose tower has no
                // clock calibration: the tower was calibrated before the window, while
                // GPS was good and the mode left DTMB out (§3.1, Fig. 2).
                in_window_withheld += e.rejected - e.rejected_gate;
                in_window_offered += e.used + e.rejected;
            }
            if clear {
                open += 1;
                open_a += usize::from(e.mode.as_deref() == Some("A"));
            }
        }
    }
    let share = |a: usize, b: usize| a as f64 / b as f64;
    eprintln!(
        "not A in the windows: {:.3}; A outside them: {:.3}",
        share(in_window_not_a, in_window),
        share(open_a, open)
    );
    assert!(share(in_window_not_a, in_window) > 0.95);
    assert!(share(open_a, open) > 0.8);
    assert_eq!(
        in_window_withheld, 0,
        "ranges withheld in the windows, of {in_window_offered} offered"
    );
    let q95 = |name: &str| {
        let mut v = p95[name].clone();
        v.sort_by(f64::total_cmp);
        v[(0.95 * (v.len() - 1) as f64) as usize]
    };
    let (gps, dtmb, proposed) = (q95("GPS"), q95("GPS+DTMB"), q95("Proposed"));
    eprintln!("95 % error: GPS {gps:.1} m, GPS+DTMB {dtmb:.1} m, Proposed {proposed:.1} m");
    assert!(proposed < dtmb && dtmb < gps);
}

/// A survey saved by `hybridnav fm survey` and named by `[sensors.fm] database` gives the
/// same fixes as the survey the world runs itself (same master seed); a database from
/// another world is refused with both worlds named.
#[test]
fn a_saved_fm_survey_is_reused_and_checked_against_its_world() {
    let d = crate::common::tmp_dir("fm-reuse");
    let db = d.join("beihang-fm.json");
    let o = crate::common::hybridnav(&[
        "fm",
        "survey",
        "worlds/seed000-beihang.toml",
        "--out",
        db.to_str().unwrap(),
        "--seed",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("wrote 16641 RPs × 21 channels"), "{stdout}");
    let text =
        std::fs::read_to_string(crate::common::repo().join("worlds/seed000-beihang.toml")).unwrap();
    let with_db = text.replacen(
        "[sensors.fm]\n",
        &format!("[sensors.fm]\ndatabase = {:?}\n", db.to_str().unwrap()),
        1,
    );
    assert_ne!(with_db, text);
    let write_world = |name: &str, body: &str| {
        let p = crate::common::repo()
            .join("worlds")
            .join(format!("_test-{name}-{}.toml", std::process::id()));
        std::fs::write(&p, body).unwrap();
        p
    };
    let p = write_world("fmdb", &with_db);
    let loaded = load_world(&p);
    let _ = std::fs::remove_file(&p);
    let loaded = loaded.unwrap();
    let surveyed = load_world(&crate::common::repo().join("worlds/seed000-beihang.toml")).unwrap();
    let a = run_trial(&loaded, 1, 0).unwrap();
    let b = run_trial(&surveyed, 1, 0).unwrap();
    let (ta, tb) = (
        trace(&a.estimators, "Proposed"),
        trace(&b.estimators, "Proposed"),
    );
    assert_eq!(ta.epochs.len(), tb.epochs.len());
    // The file holds decimal numbers, so the fixes agree to rounding, not to the bit.
    for (x, y) in ta.epochs.iter().zip(&tb.epochs) {
        let (Some(ex), Some(ey)) = (x.err_3d_m, y.err_3d_m) else {
            assert_eq!(x.err_3d_m, y.err_3d_m, "t = {}", x.t_s);
            continue;
        };
        assert!((ex - ey).abs() < 1e-6, "t = {}: {ex} vs {ey}", x.t_s);
    }
    let renamed = with_db.replacen(
        "name = \"Seed 000 site 1 — Beihang campus, Beijing\"",
        "name = \"Another campus\"",
        1,
    );
    assert_ne!(renamed, with_db);
    let p = write_world("fmdb-other", &renamed);
    let e = load_world(&p);
    let _ = std::fs::remove_file(&p);
    let msg = e
        .expect_err("a database of another world is refused")
        .to_string();
    assert!(
        msg.contains("sensors.fm.database") && msg.contains("Another campus"),
        "{msg}"
    );
}

/// The magnetic-landmark source on seed 002's Lianhua world: the survey labels windows at
/// the landmarks, the trial walks (two laps, a different phone) recognise them, and seed
/// 002's DTMB consistency check does not lower the precision (it removes look-alike
/// confusions). Precision and recall are measured against the true landmark positions.
#[test]
fn magnetic_landmarks_are_recognised_on_the_lianhua_world() {
    use hybridnav::core::TrialRng;
    use hybridnav::magnetic::source::MagneticSource;
    use nalgebra::Vector3;
    let world = load_world(&crate::common::repo().join("worlds/seed002-lianhua.toml")).unwrap();
    let cfg = world.file.sensors.magnetic.clone().unwrap();
    let anomalies = world
        .file
        .scene
        .as_ref()
        .unwrap()
        .magnetic_anomalies
        .clone();
    let truth: Vec<Vector3<f64>> = anomalies
        .iter()
        .map(|a| Vector3::from(a.position_enu_m))
        .collect();
    let tower = world
        .transmitters
        .iter()
        .find(|t| t.kind == hybridnav::world::scene::TransmitterKind::Dtmb)
        .map(|t| t.pos_enu_m);
    let mut rows = Vec::new();
    let off = hybridnav::magnetic::source::DtmbCheck {
        enabled: false,
        ..cfg.dtmb_check
    };
    for (label, check) in [("DTW", off), ("DTW + DTMB", cfg.dtmb_check)] {
        let c = hybridnav::magnetic::source::MagneticSensorConfig {
            dtmb_check: check,
            ..cfg.clone()
        };
        let (mut detections, mut correct, mut passes) = (0, 0, 0);
        let mut fix_err = Vec::new();
        for trial in 0..4 {
            let rng = TrialRng::new(1, trial);
            let s = MagneticSource::new(
                &c,
                &anomalies,
                &world.file.platform.attitude(),
                world.build_trajectory(&TrialRng::new(1, 0)).unwrap(),
                world.build_trajectory(&rng).unwrap(),
                &world.frame,
                world.start,
                tower,
                &rng,
                hybridnav::core::SimTime::from_seconds(world.duration_s),
            )
            .unwrap();
            let (windows, labelled) = s.window_counts();
            assert!(
                labelled >= 5 && labelled <= windows,
                "{labelled} of {windows}"
            );
            // Two laps pass each landmark twice.
            passes += 2 * truth.len();
            for d in s.detections() {
                detections += 1;
                let p = d.true_pos_enu_m;
                let f = s.landmarks_enu_m()[d.label];
                fix_err.push((p.x - f.x).hypot(p.y - f.y));
                let l = truth[d.label];
                if (p.x - l.x).hypot(p.y - l.y) <= 3.0 {
                    correct += 1;
                }
            }
        }
        let precision = correct as f64 / detections.max(1) as f64;
        let recall = correct as f64 / passes as f64;
        fix_err.sort_by(f64::total_cmp);
        eprintln!(
            "{label}: {detections} detections, precision {precision:.3}, recall {recall:.3}, fix error median {:.2} m, 90 % {:.2} m",
            fix_err[fix_err.len() / 2],
            fix_err[fix_err.len() * 9 / 10]
        );
        rows.push((precision, recall));
    }
    assert!(rows[0].1 > 0.3 && rows[1].1 > 0.3, "{rows:?}");
    assert!(rows[1].0 >= rows[0].0, "{rows:?}");
    assert!(rows[1].0 > 0.8, "{rows:?}");
}
