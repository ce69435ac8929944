//! The abstract-simulation papers (seeds 001 and 003) on their own world files: the
//! emitters source, the papers' process models and filters, the orderings of their tables,
//! and the simulated numbers printed beside the papers'.

use hybridnav::beacons::{EmittersConfig, EmittersSource};
use hybridnav::core::{EnuFrame, Geodetic, GpsTime, SimTime, System, TrialRng};
use hybridnav::engine::trial::{truth_at, EstimatorTrace, TrialResult};
use hybridnav::measurement::{MeasurementBatch, SampleContext, Source};
use hybridnav::motion::TrajectoryConfig;
use hybridnav::world::trial::run_trial;
use hybridnav::world::{load_world, parse_world, World};
use std::path::PathBuf;

fn world_path(name: &str) -> PathBuf {
    crate::common::repo().join("worlds").join(name)
}

fn world_text(name: &str) -> String {
    std::fs::read_to_string(world_path(name)).expect("read world")
}

fn trace<'a>(r: &'a TrialResult, name: &str) -> &'a EstimatorTrace {
    r.estimators.iter().find(|e| e.name == name).expect(name)
}

/// Error statistics of one estimator over trials: the pooled mean and standard deviation
/// of the 3-D error over every epoch of every trial, and the within-trial mean and
/// standard deviation averaged over the trials (a paper's table is one run of 100 epochs,
/// so its std is a within-run spread).
#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    pooled_mean: f64,
    pooled_std: f64,
    within_mean: f64,
    within_std: f64,
    median_trial_mean: f64,
}

fn stats(results: &[TrialResult], name: &str) -> Stats {
    let mut all = Vec::new();
    let mut per_trial = Vec::new();
    let mut within_std = 0.0;
    for r in results {
        let e: Vec<f64> = trace(r, name)
            .epochs
            .iter()
            .filter_map(|x| x.err_3d_m)
            .collect();
        let m = e.iter().sum::<f64>() / e.len() as f64;
        let v = e.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (e.len() - 1) as f64;
        per_trial.push(m);
        within_std += v.sqrt();
        all.extend(e);
    }
    let n = all.len() as f64;
    let mean = all.iter().sum::<f64>() / n;
    let std = (all.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let k = per_trial.len();
    let within_mean = per_trial.iter().sum::<f64>() / k as f64;
    per_trial.sort_by(f64::total_cmp);
    Stats {
        pooled_mean: mean,
        pooled_std: std,
        within_mean,
        within_std: within_std / k as f64,
        median_trial_mean: per_trial[k / 2],
    }
}

fn run(world: &World, trials: u64) -> Vec<TrialResult> {
    let seed = world.file.montecarlo.seed;
    (0..trials)
        .map(|i| run_trial(world, seed, i).expect("trial runs"))
        .collect()
}

fn report(paper: &str, rows: &[(&str, f64, f64, Stats)], trials: u64) {
    eprintln!("{paper}: {trials} trials");
    eprintln!(
        "  {:<8} {:>10} {:>10} | {:>10} {:>10} {:>14} {:>14} {:>12}",
        "row",
        "paper mean",
        "paper std",
        "mean",
        "std",
        "mean in trial",
        "std in trial",
        "median trial"
    );
    for (name, pm, ps, s) in rows {
        eprintln!(
            "  {name:<8} {pm:>10.2} {ps:>10.2} | {:>10.2} {:>10.2} {:>14.2} {:>14.2} {:>12.2}",
            s.pooled_mean, s.pooled_std, s.within_mean, s.within_std, s.median_trial_mean
        );
    }
}

/// Both worlds load, name the papers' rows first (the regularised and Rao-Blackwellised
/// rows follow), run 100 epochs at 1 Hz, and seed 003's seamless scheme picks GPS + BDS +
/// DTMB at every epoch (three GPS satellites: "between zero and four"). The EKF and the
/// 500-particle regularised and Rao-Blackwellised filters have no numerical failure; the
/// particle filters short of particles (the papers' SIR rows, 100 particles) may diverge,
/// which their NIS and N_eff now report: every other epoch has an error and a NEES.
#[test]
fn abstract_worlds_load_and_run_the_papers_rows() {
    for (file, rows) in [
        ("seed001-pf2d.toml", &["PF-10", "PF-20"][..]),
        ("seed003-seamless.toml", &["EKF", "PF-100", "PF-500"][..]),
    ] {
        let world = load_world(&world_path(file)).expect(file);
        let r = run_trial(&world, 1, 0).unwrap();
        let names: Vec<&str> = r.estimators.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(&names[..rows.len()], rows, "{file}");
        for e in &r.estimators {
            assert_eq!(e.epochs.len(), 100, "{file} {}", e.name);
            assert!((e.epochs[0].t_s - 1.0).abs() < 1e-9);
            if ["EKF", "RPF-500", "RBPF-500"].contains(&e.name.as_str()) {
                assert!(
                    e.epochs.iter().all(|x| !x.numerical_failure),
                    "{file} {}",
                    e.name
                );
            }
            let healthy = || e.epochs.iter().filter(|x| !x.numerical_failure);
            assert!(healthy().all(|x| x.err_3d_m.is_some()), "{file} {}", e.name);
            assert!(healthy().all(|x| x.nees_pos.is_some_and(|n| n >= 0.0)));
            if file.starts_with("seed003") {
                assert!(e
                    .epochs
                    .iter()
                    .all(|x| x.mode.as_deref() == Some("GPS+BDS+DTMB")));
                assert!(healthy().all(|x| x.used == 6), "{file} {}", e.name);
            }
        }
    }
}

/// Seed 001, Table 1: twenty particles track better than ten. The paper's run is one
/// realisation; the ordering is checked on the mean over 200 trials (the per-trial means
/// spread from tens of metres to over a kilometre, see docs/reproductions.md).
/// The simulated mean error is within a factor of 2 of the paper's for both rows.
#[test]
fn seed001_twenty_particles_beat_ten() {
    let world = load_world(&world_path("seed001-pf2d.toml")).unwrap();
    let trials = 200;
    let results = run(&world, trials);
    let s10 = stats(&results, "PF-10");
    let s20 = stats(&results, "PF-20");
    report(
        "seed 001 (paper: one run)",
        &[
            ("PF-10", 138.6599, 126.2985, s10),
            ("PF-20", 97.3565, 70.6565, s20),
        ],
        trials,
    );
    assert!(s20.pooled_mean < s10.pooled_mean, "{s20:?} vs {s10:?}");
    assert!(s20.median_trial_mean < s10.median_trial_mean);
    for (s, paper) in [(s10, 138.6599), (s20, 97.3565)] {
        let ratio = s.pooled_mean / paper;
        assert!(
            (0.5..2.0).contains(&ratio),
            "mean {} vs paper {paper}",
            s.pooled_mean
        );
    }
}

/// Seed 003, Table 2: 500 particles beat 100. The EKF's row does not reproduce: on this
/// problem (far emitters: over the EKF's few metres of uncertainty the ranges curve by
/// millimetres) the EKF is
/// consistent (mean NEES ≈ 3) and therefore close to the optimal filter, so no particle
/// filter can beat it on average; the bootstrap filters' sample impoverishment makes them
/// worse, and they approach the EKF as the particle count grows
/// (docs/reproductions.md has the evidence). The EKF's mean error is within a
/// factor of 2 of the paper's.
#[test]
fn seed003_more_particles_help_and_the_ekf_is_consistent() {
    let world = load_world(&world_path("seed003-seamless.toml")).unwrap();
    let trials = 16;
    let results = run(&world, trials);
    let ekf = stats(&results, "EKF");
    let pf100 = stats(&results, "PF-100");
    let pf500 = stats(&results, "PF-500");
    report(
        "seed 003 (paper: one run)",
        &[
            ("EKF", 11.2065, 5.4361, ekf),
            ("PF-100", 5.3601, 3.1325, pf100),
            ("PF-500", 2.8736, 1.7603, pf500),
        ],
        trials,
    );
    assert!(pf500.pooled_mean < pf100.pooled_mean);
    let ratio = ekf.pooled_mean / 11.2065;
    assert!((0.5..2.0).contains(&ratio), "EKF mean {}", ekf.pooled_mean);
    // The EKF's consistency: its position NEES averages the dimension (3).
    let nees: Vec<f64> = results
        .iter()
        .flat_map(|r| trace(r, "EKF").epochs.iter().filter_map(|e| e.nees_pos))
        .collect();
    let mean_nees = nees.iter().sum::<f64>() / nees.len() as f64;
    eprintln!("  EKF mean position NEES {mean_nees:.2} (3 when consistent)");
    assert!((2.0..4.5).contains(&mean_nees), "{mean_nees}");
    // Documented departure from the paper: the EKF is the best row here.
    assert!(ekf.pooled_mean < pf500.pooled_mean);
}

/// Seed 003's seamless scheme on the emitters source: with every GPS satellite in an
/// outage the scheme falls back to DTMB only, with one to four it uses all three systems.
#[test]
fn seed003_seamless_mode_follows_gps_outages() {
    let text = world_text("seed003-seamless.toml").replace(
        "system = \"gps\"\n",
        "system = \"gps\"\noutages_s = [[30.0, 50.0]]\n",
    );
    let world = parse_world(&text, &world_path("_test-seamless.toml")).unwrap();
    let r = run_trial(&world, 1, 0).unwrap();
    let ekf = trace(&r, "EKF");
    let at = |t: f64| {
        ekf.epochs
            .iter()
            .find(|e| (e.t_s - t).abs() < 1e-9)
            .unwrap()
    };
    assert_eq!(at(20.0).mode.as_deref(), Some("GPS+BDS+DTMB"));
    assert_eq!(at(40.0).mode.as_deref(), Some("DTMB"));
    assert_eq!(at(40.0).used, 1);
    assert_eq!(at(60.0).mode.as_deref(), Some("GPS+BDS+DTMB"));
    assert!(ekf.epochs.iter().all(|e| !e.numerical_failure));
}

/// The source's ranges are the geometric range plus the system's clock terms plus
/// Gaussian noise of the configured σ: over 4000 epochs each emitter's residual has a mean
/// within 4 standard errors of 0 and a standard deviation within 6 % of σ (4 standard
/// errors of a sample σ).
#[test]
fn emitter_ranges_are_geometry_plus_clock_plus_noise() {
    let cfg: EmittersConfig = toml::from_str(
        r#"
sigma_m = { gps = 150.0, dtmb = 50.0 }
receiver_clock_m = 3000.0
clock_offset_m = { dtmb = 450.0, bds = -20.0 }
[[emitter]]
system = "gps"
azimuth_deg = 40.0
elevation_deg = 60.0
range_m = 2.2e7
[[emitter]]
system = "dtmb"
position_enu_m = [1000.0, -2000.0, 300.0]
[[emitter]]
system = "bds"
id = "C07"
position_enu_m = [-5.0e6, 1.0e7, 3.0e7]
sigma_m = 10.0
"#,
    )
    .unwrap();
    let frame = EnuFrame::new(Geodetic::from_deg(39.9, 116.4, 50.0));
    let start = GpsTime::from_week_tow(2000, 0.0);
    let n = 4000;
    let traj = TrajectoryConfig::Static {
        position_enu_m: [120.0, 40.0, 2.0],
        duration_s: n as f64 + 1.0,
    }
    .build(&mut TrialRng::new(0, 0).stream("t"))
    .unwrap();
    let mut src = EmittersSource::new(
        &cfg,
        &frame,
        &TrialRng::new(5, 0),
        SimTime::from_seconds(n as f64 + 1.0),
    )
    .unwrap();
    let resolved = cfg.resolve(&frame).unwrap();
    let mut sums = vec![(0.0, 0.0); resolved.len()];
    let mut batch = MeasurementBatch::default();
    let mut t = src.first_sample();
    for _ in 0..n {
        let truth = truth_at(&frame, start, traj.as_ref(), t);
        batch.items.clear();
        let ctx = SampleContext {
            truth: &truth,
            estimates: &[],
        };
        let next = src.sample(&ctx, &mut batch);
        assert_eq!(batch.source, hybridnav::measurement::SourceKind::Emitters);
        for (k, m) in batch.ranges().enumerate() {
            assert_eq!(m.emitter, resolved[k].id);
            let geo = (m.emitter_pos_ecef_m - truth.pos_ecef_m).norm();
            let res = m.pseudorange_m - geo - cfg.clock_m(m.system());
            sums[k].0 += res;
            sums[k].1 += res * res;
        }
        t = next.expect("source continues");
    }
    assert_eq!(cfg.clock_m(System::Dtmb), 3450.0);
    assert_eq!(cfg.clock_m(System::Gps), 3000.0);
    for (k, (s, s2)) in sums.iter().enumerate() {
        let sigma = resolved[k].sigma_m;
        let mean = s / n as f64;
        let std = (s2 / n as f64 - mean * mean).sqrt();
        assert!(
            mean.abs() < 4.0 * sigma / (n as f64).sqrt(),
            "{k}: mean {mean}"
        );
        assert!(
            (std / sigma - 1.0).abs() < 0.06,
            "{k}: std {std} vs {sigma}"
        );
    }
    assert_eq!(resolved[2].id.to_string(), "C07");
    assert_eq!(resolved[2].sigma_m, 10.0);
}

/// Bad emitter tables and paper-model tables are refused with the file, line, key and what
/// was expected.
#[test]
fn bad_emitter_and_model_tables_are_named() {
    let base = world_text("seed003-seamless.toml");
    let path = world_path("_test-bad.toml");
    let no_emitters = {
        let cut = base.find("[[sensors.emitters.emitter]]").unwrap();
        let resume = base.find("[[estimator]]").unwrap();
        format!("{}{}", &base[..cut], &base[resume..])
    };
    let cases: Vec<(String, &str, &str)> = vec![
        (
            base.replacen("system = \"bds\"", "system = \"galileo\"", 1),
            "unknown variant `galileo`",
            "system = \"galileo\"",
        ),
        (
            base.replace("gps = 10.0, bds = 10.0", "gps = 0.0, bds = 10.0"),
            "sensors.emitters.sigma_m.gps: expected a noise σ > 0 m, got 0",
            "sigma_m = {",
        ),
        (
            base.replacen(
                "position_enu_m = [2000.0",
                "sigma_m = -5.0\nposition_enu_m = [2000.0",
                1,
            ),
            "emitter[5].sigma_m: expected a noise σ > 0 m, got -5",
            "sigma_m = -5.0",
        ),
        (
            base.replace(", bds = 10.0, dtmb", ", dtmb"),
            "no range noise for this bds emitter",
            "",
        ),
        (
            no_emitters,
            "expected at least one [[sensors.emitters.emitter]]",
            "",
        ),
        (
            base.replacen("range_m = 2.2e7", "range_m = 2.2e7\nposition_enu_m = [0.0, 0.0, 1.0]", 1),
            "expected either position_enu_m or all of azimuth_deg",
            "",
        ),
        (
            base.replacen("system = \"dtmb\"", "system = \"dtmb\"\npower_w = 5.0", 1),
            "unknown field `power_w`",
            "power_w",
        ),
        (
            base.replacen(
                "preset = \"seed003-ekf\"",
                "preset = \"seed003-ekf\"\nfilter = \"ekf11\"",
                1,
            ),
            "process model 'plane_turning' runs with filter = \"ekf\", \"ukf\", \"ckf\", \"stf\", \"rekf\" or \"pf\", not 'ekf11'",
            "filter = \"ekf11\"",
        ),
        (
            base.replacen(
                "preset = \"seed003-ekf\"",
                "preset = \"seed003-ekf\"\nprocess = { model = \"plane_turning\", noise_var_m2ps4 = -1.0 }",
                1,
            ),
            "noise_var_m2ps4",
            "",
        ),
    ];
    for (i, (text, expect, line_has)) in cases.iter().enumerate() {
        let msg = match parse_world(text, &path) {
            Ok(_) => panic!("case {i} was accepted"),
            Err(e) => {
                if !line_has.is_empty() {
                    let line = text.lines().nth(e.line - 1).unwrap_or("");
                    assert!(
                        line.contains(line_has),
                        "case {i}: line {} is {line:?}",
                        e.line
                    );
                }
                e.to_string()
            }
        };
        assert!(msg.contains("_test-bad.toml:"), "case {i}: {msg}");
        assert!(msg.contains(expect), "case {i}: {msg}");
    }
    // A paper model with known clocks needs the emitters' offsets.
    let default = crate::common::default_world_text();
    let head = &default[..default.find("[[estimator]]").unwrap()];
    let text = format!("{head}[[estimator]]\npreset = \"seed001-pf\"\nsources = [\"gps\"]\n");
    let e = parse_world(&text, &world_path("_test-known.toml")).unwrap_err();
    assert!(e.to_string().contains("clocks = \"estimated\""), "{e}");
}

/// `text` with every `[[estimator]]` table replaced by `tables`.
fn with_estimators(text: &str, tables: &str) -> String {
    let cut = text.find("[[estimator]]").expect("an estimator table");
    let tail = &text[cut..];
    let rest = tail.find("[montecarlo]").map_or("", |i| &tail[i..]);
    format!("{}{tables}\n{rest}", &text[..cut])
}

/// The same paper estimator under each filter of the family: `(row name, filter)`.
fn family_rows(preset: &str, filters: &[(&str, &str)]) -> String {
    filters
        .iter()
        .map(|(name, filter)| {
            format!("[[estimator]]\npreset = \"{preset}\"\nname = \"{name}\"\nfilter = \"{filter}\"\n\n")
        })
        .collect()
}

/// The largest distance between two estimators' positions at the same epoch, over every
/// epoch of every trial, in units of the reference's position σ.
fn largest_normalised_gap(results: &[TrialResult], name: &str, reference: &str) -> f64 {
    let mut worst = 0.0_f64;
    for r in results {
        for (a, b) in trace(r, name)
            .epochs
            .iter()
            .zip(&trace(r, reference).epochs)
        {
            if let (Some(a), Some(b), Some(sigma)) = (a.est_ecef_m, b.est_ecef_m, b.pos_sigma_m) {
                let d = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
                worst = worst.max(d / sigma);
            }
        }
    }
    worst
}

fn mean_nees(results: &[TrialResult], name: &str) -> f64 {
    let nees: Vec<f64> = results
        .iter()
        .flat_map(|r| trace(r, name).epochs.iter().filter_map(|e| e.nees_pos))
        .collect();
    nees.iter().sum::<f64>() / nees.len() as f64
}

const KALMAN_ROWS: [(&str, &str); 5] = [
    ("EKF", "ekf"),
    ("UKF", "ukf"),
    ("CKF", "ckf"),
    ("STF", "stf"),
    ("RE-KF", "rekf"),
];

/// Seed 003's model and measurements under every Kalman filter of the family. The problem
/// is nearly linear (emitters 3 km to 38 000 km away, a few metres of uncertainty), where
/// the unscented and cubature filters must reproduce the EKF: their estimates stay within
/// 1 % of the EKF's σ at every epoch (measured 4.3e-4), with the same consistent NEES
/// (≈ 3, the dimension). The RE-KF equals the EKF wherever its C = 3 gate keeps every
/// range (its mean error is within 10 % of the EKF's). The strong tracking filter inflates
/// its prediction by a noisy factor when nothing needs it (the model is exact here), so
/// it is worse than the optimal EKF, and conservative.
#[test]
fn seed003_every_kalman_filter_runs_the_plane_turning_model() {
    let text = with_estimators(
        &world_text("seed003-seamless.toml"),
        &family_rows("seed003-ekf", &KALMAN_ROWS),
    );
    let world = parse_world(&text, &world_path("seed003-seamless.toml")).unwrap();
    let trials = 16;
    let results = run(&world, trials);
    let s: Vec<Stats> = KALMAN_ROWS
        .iter()
        .map(|(n, _)| stats(&results, n))
        .collect();
    eprintln!("seed 003, every Kalman filter: {trials} trials (the paper has the EKF only)");
    for (name, _) in KALMAN_ROWS {
        for r in &results {
            let e = &trace(r, name).epochs;
            assert_eq!(e.len(), 100, "{name}");
            assert!(
                e.iter()
                    .all(|x| !x.numerical_failure && x.err_3d_m.is_some()),
                "{name}: a failure or a missing estimate"
            );
        }
        let st = stats(&results, name);
        eprintln!(
            "  {name}: 3-D error mean {:.2} m, std {:.2} m, mean NEES {:.2}, largest gap to the EKF {:.1e} σ",
            st.pooled_mean,
            st.pooled_std,
            mean_nees(&results, name),
            largest_normalised_gap(&results, name, "EKF")
        );
    }
    for name in ["UKF", "CKF"] {
        let gap = largest_normalised_gap(&results, name, "EKF");
        assert!(gap < 0.01, "{name} departs from the EKF by {gap} σ");
        let nees = mean_nees(&results, name);
        assert!((2.0..4.5).contains(&nees), "{name} NEES {nees}");
    }
    let (ekf, rekf, stf) = (s[0], s[4], s[3]);
    assert!(
        (rekf.pooled_mean / ekf.pooled_mean - 1.0).abs() < 0.1,
        "RE-KF {} against EKF {}",
        rekf.pooled_mean,
        ekf.pooled_mean
    );
    assert!((2.0..4.5).contains(&mean_nees(&results, "RE-KF")));
    assert!(stf.pooled_mean > ekf.pooled_mean);
    let stf_nees = mean_nees(&results, "STF");
    assert!((1.0..3.0).contains(&stf_nees), "STF NEES {stf_nees}");
}

/// Seed 001's 2-D Singer model with known clocks under every Kalman filter: the x axis and
/// the clocks are known exactly (zero variance), so the sigma-point filters and the RE-KF
/// draw their points from the semi-definite factor; they run every epoch and the UKF and
/// CKF follow the EKF to 1 % of its σ (measured 1.2e-3).
#[test]
fn seed001_every_kalman_filter_runs_the_singer_model() {
    let text = with_estimators(
        &world_text("seed001-pf2d.toml"),
        &family_rows("seed001-pf", &KALMAN_ROWS),
    );
    let world = parse_world(&text, &world_path("seed001-pf2d.toml")).unwrap();
    let results = run(&world, 8);
    for (name, _) in KALMAN_ROWS {
        for r in &results {
            assert!(trace(r, name)
                .epochs
                .iter()
                .all(|x| !x.numerical_failure && x.err_3d_m.is_some()));
        }
    }
    for name in ["UKF", "CKF"] {
        let gap = largest_normalised_gap(&results, name, "EKF");
        eprintln!("seed 001: {name} largest gap to the EKF {gap:.1e} σ");
        assert!(gap < 0.01, "{name} departs from the EKF by {gap} σ");
    }
}

/// A world file with the paper model under four new filters runs through the binary and
/// its summary lists every row; an unsupported filter for a paper model is refused with
/// the file, the line and what would work.
#[test]
fn paper_models_under_every_filter_through_the_binary() {
    use crate::common::{hybridnav, refused, stderr, tmp_dir};
    let d = tmp_dir("paper-filters");
    let rows = [
        ("UKF", "ukf"),
        ("CKF", "ckf"),
        ("STF", "stf"),
        ("RE-KF", "rekf"),
    ];
    let text = with_estimators(
        &world_text("seed003-seamless.toml"),
        &family_rows("seed003-ekf", &rows),
    );
    let world = d.join("w.toml");
    std::fs::write(&world, &text).unwrap();
    let out = d.join("out");
    let o = hybridnav(&[
        "run",
        world.to_str().unwrap(),
        "--trials",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let names: Vec<&str> = v["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["UKF", "CKF", "STF", "RE-KF"]);
    for e in v["estimators"].as_array().unwrap() {
        let mean = e["error_3d_m"]["mean"].as_f64().unwrap();
        assert!(mean.is_finite() && mean > 0.0 && mean < 50.0, "{e}");
    }
    let bad = text.replacen("filter = \"rekf\"", "filter = \"ekf11\"", 1);
    let bad_path = d.join("bad.toml");
    std::fs::write(&bad_path, &bad).unwrap();
    let line = bad
        .lines()
        .position(|l| l.contains("filter = \"ekf11\""))
        .unwrap()
        + 1;
    refused(
        &["check", bad_path.to_str().unwrap()],
        &[
            &format!("bad.toml:{line}:"),
            "process model 'plane_turning' runs with filter = \"ekf\", \"ukf\", \"ckf\", \"stf\", \"rekf\" or \"pf\", not 'ekf11'",
        ],
    );
}
