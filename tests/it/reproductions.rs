//! The orderings seeds 000, 002 and 004 report, on their site worlds, over a few trials (the
//! full tables, with more trials, are in docs/reproductions.md; seeds 001 and 003 are in
//! `reproductions_abstract`).

use hybridnav::montecarlo::{run_trials, summarise, RunOptions, Summary};
use hybridnav::world::load_world;

fn run(world: &str, trials: u64, seed: u64) -> Summary {
    let w = load_world(&crate::common::repo().join(world)).expect("world loads");
    let opts = crate::common::run_options(trials, seed);
    let r = run_trials(&w, &opts).expect("trials run");
    summarise(&w, &opts, &r).expect("summary")
}

fn get<'a>(s: &'a Summary, name: &str) -> &'a hybridnav::montecarlo::EstimatorSummary {
    s.estimators
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no estimator {name} in {}", s.world))
}

/// Seed 000 site 1. The paper claims Proposed < GPS+DTMB < GPS at 3σ (27.80 < 35.31 <
/// 87.46) and in mean ATE (9.90 < 13.53 < 24.52). The FM database is surveyed with an
/// independent survey-to-test change of the field, and master seed 2's survey is the one
/// that used to break the claim: one trial's proposed filter drifted in the second
/// three-satellite window while the FM constraint circle followed its drifting estimate, so
/// the FM fixes confirmed the drift (1.97 km at t = 573 s, 3σ 819 m at 20 trials). With the
/// circle held at the last reliable position, as seed 000 §3.2 describes, the claim holds on
/// seed 2 (20 trials, measured 2026-12-04: 3σ 69.4 < 104.1 < 520.4 m, mean ATE 4.53 < 5.72
/// < 37.79 m), and on seeds 1 and 3–7 (docs/reproductions.md).
#[test]
fn seed000_beihang_proposed_beats_gps_dtmb_beats_gps() {
    let s = run("worlds/seed000-beihang.toml", 20, 2);
    let s3 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma3;
    let ate = |n: &str| get(&s, n).ate_m.unwrap().mean;
    println!(
        "3σ: GPS {:.1}, GPS+DTMB {:.1}, Proposed {:.1}; ATE: {:.2} {:.2} {:.2}",
        s3("GPS"),
        s3("GPS+DTMB"),
        s3("Proposed"),
        ate("GPS"),
        ate("GPS+DTMB"),
        ate("Proposed")
    );
    assert!(s3("Proposed") < s3("GPS+DTMB") && s3("GPS+DTMB") < s3("GPS"));
    assert!(ate("Proposed") < ate("GPS+DTMB") && ate("GPS+DTMB") < ate("GPS"));
    // The mode-selecting estimator records its modes; both A and C occur on this campus.
    let modes = &get(&s, "Proposed").modes;
    assert!(
        modes.contains_key("A") && modes.contains_key("C"),
        "{modes:?}"
    );
    let total: f64 = modes.values().sum();
    assert!((total - 1.0).abs() < 1e-9);
}

/// Seed 000 site 2. The paper claims, at 2σ, 3σ and in mean ATE, Proposed < GPS+DTMB <
/// GPS (3σ: 60.23 < 262.80 < 416.60). On this world, with the default (exact range-rate
/// Jacobian) rows and 100 trials, the measured facts are different, and this test states
/// them rather than the paper's claim (docs/reproductions.md, seed 000 site 2):
/// - the proposed system beats both others in every one of the three statistics (the
///   paper's headline holds), and
/// - GPS+DTMB does *not* beat GPS: the exact Jacobian lets the GPS-only filter coast
///   through the two-satellite windows on Doppler, while the single tower's NLOS ranges
///   in the street canyons pull GPS+DTMB off (seed 1: 3σ 532.6 against 147.1 m, 2σ 117.7
///   against 31.0 m, mean ATE 19.1 against 7.3 m).
///
/// The paper's GPS+DTMB < GPS needs its printed eq. 17 (rows "(eq. 17)", printed here but
/// not asserted): there it holds at 3σ and in mean ATE but not at 2σ at 100 trials, seed
/// 1 (535.9 < 781.7, 18.4 < 19.4, 110.4 > 85.1), with margins too thin (and at 20 trials,
/// 3σ, reversed) to assert.
#[test]
fn seed000_kehui_proposed_beats_both_and_gps_dtmb_does_not_beat_gps() {
    let s = run("worlds/seed000-kehui.toml", 100, 1);
    let s2 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma2;
    let s3 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma3;
    let ate = |n: &str| get(&s, n).ate_m.unwrap().mean;
    for suffix in ["", " (eq. 17)"] {
        let (g, gd, p) = (
            format!("GPS{suffix}"),
            format!("GPS+DTMB{suffix}"),
            format!("Proposed{suffix}"),
        );
        println!(
            "{suffix:>9} 2σ: GPS {:.1}, GPS+DTMB {:.1}, Proposed {:.1}; 3σ: {:.1} {:.1} {:.1}; ATE: {:.1} {:.1} {:.1}",
            s2(&g),
            s2(&gd),
            s2(&p),
            s3(&g),
            s3(&gd),
            s3(&p),
            ate(&g),
            ate(&gd),
            ate(&p)
        );
    }
    for (what, f) in [
        ("2σ", &s2 as &dyn Fn(&str) -> f64),
        ("3σ", &s3),
        ("ATE", &ate),
    ] {
        assert!(
            f("Proposed") < f("GPS+DTMB") && f("Proposed") < f("GPS"),
            "{what}: Proposed {}, GPS+DTMB {}, GPS {}",
            f("Proposed"),
            f("GPS+DTMB"),
            f("GPS")
        );
        assert!(
            f("GPS") < f("GPS+DTMB"),
            "{what}: GPS {}, GPS+DTMB {}",
            f("GPS"),
            f("GPS+DTMB")
        );
    }
}

/// Seed 002 outdoors: the proposed PDR + magnetic landmarks + DTMB beats plain PDR at the
/// 68 % and 95 % levels of the horizontal error (the paper: 2.84 vs 8.77 m, 3.98 vs 12.84).
#[test]
fn seed002_lianhua_proposed_beats_pdr() {
    let s = run("worlds/seed002-lianhua.toml", 6, 2);
    let h = |n: &str| get(&s, n).error_h_m.unwrap();
    println!(
        "68 %: PDR {:.2}, Proposed {:.2}; 95 %: {:.2}, {:.2}",
        h("PDR").sigma1,
        h("Proposed").sigma1,
        h("PDR").sigma2,
        h("Proposed").sigma2
    );
    assert!(h("Proposed").sigma1 < h("PDR").sigma1);
    assert!(h("Proposed").sigma2 < h("PDR").sigma2);
    // Fusing the DTMB range differences (§3.2, §4.2) is what takes the proposed row below
    // the landmarks alone: 1.25 against 1.58 m at 68 % over 20 trials (docs).
    println!(
        "68 %: PDR+MAG without Δr {:.2}; 95 %: {:.2}",
        h("PDR+MAG (no Δr)").sigma1,
        h("PDR+MAG (no Δr)").sigma2
    );
    assert!(h("Proposed").sigma1 < 0.9 * h("PDR+MAG (no Δr)").sigma1);
    assert!(h("Proposed").sigma2 < h("PDR+MAG (no Δr)").sigma2);
}

/// Seed 004 on the BUPT campus, every filter of the paper's comparison with the same eq. 24
/// gate (C = 3). Loosely coupled (the paper's §2.3, eqs. 16–19), the error model and
/// `H = [I₆ 0]` are linear: the cubature rule is exact, the RE-KF's χ is zero, and the
/// RE-KF, CKF and EKF are one Kalman filter with one gate, equal to rounding (analytic). The
/// tightly coupled rows update on each pseudorange, nonlinear in the position error: the
/// CKF differs from the EKF there. The STF's fading factor is bounded (λ_max = 10), and no
/// estimator of the world errs by 1 km or resets in more than 1 % of its epochs.
#[test]
fn seed004_bupt_four_filters_with_one_gate_bounded_stf_and_no_resets() {
    let s = run("worlds/seed004-bupt.toml", 6, 2);
    let d = |n: &str| get(&s, n).error_3d_m.unwrap();
    for n in ["RE-KF", "EKF", "CKF", "STF"] {
        for sfx in ["", " (tight)"] {
            let name = format!("{n}{sfx}");
            println!(
                "{name}: 3-D RMSE {:.4} m, max {:.2} m",
                d(&name).rmse,
                d(&name).max
            );
        }
    }
    for other in ["EKF", "CKF"] {
        let rel = (d("RE-KF").rmse - d(other).rmse).abs() / d(other).rmse;
        assert!(
            rel < 1e-6,
            "RE-KF and {other} differ by {rel} on the linear model"
        );
    }
    let rel = (d("CKF (tight)").rmse - d("EKF (tight)").rmse).abs() / d("EKF (tight)").rmse;
    assert!(
        rel > 1e-6,
        "tight CKF and EKF equal ({rel}) on nonlinear ranges"
    );
    // The paper's stated accuracy ("indoor … better than 1 m, outdoor … 0.5 m", §4.3) is
    // scored from each RE-KF's horizontal RMS where the truth was, as the summary splits it.
    let paper = hybridnav::reproduce::papers::PAPERS
        .iter()
        .find(|p| p.id == "seed004-bupt")
        .unwrap();
    let scored = hybridnav::reproduce::score(paper, &s).unwrap();
    assert_eq!(scored.stated.len(), 4);
    for st in &scored.stated {
        let env = &get(&s, st.stated.estimator).environments;
        let place = env
            .iter()
            .find(|g| g.label == st.stated.place.label())
            .unwrap_or_else(|| panic!("{}: no {:?} epochs", st.stated.estimator, st.stated.place));
        assert!(place.epochs > 0);
        assert_eq!(st.simulated_m, place.rmse_h_m);
        println!(
            "{} {:?}: horizontal RMS {:.2} m (paper {} m)",
            st.stated.estimator,
            st.stated.place,
            st.simulated_m.unwrap(),
            st.stated.paper_m
        );
    }
    for e in &s.estimators {
        let err = e.error_3d_m.unwrap();
        assert!(err.max < 1000.0, "{}: largest error {} m", e.name, err.max);
        assert!(
            e.numerical_failures as f64 <= 0.01 * e.epochs as f64,
            "{}: {} resets in {} epochs",
            e.name,
            e.numerical_failures,
            e.epochs
        );
    }
}

/// `docs/reproductions-tables.md` is `hybridnav reproduce --markdown`'s output for the
/// default trials and seed: regenerated here, it must match the committed file byte for
/// byte (a change that moves a paper figure must regenerate the tables).
#[test]
fn the_committed_reproduction_tables_are_current() {
    use hybridnav::reproduce;
    let root = crate::common::repo();
    let results: Vec<_> = reproduce::select(&[])
        .expect("every paper")
        .into_iter()
        .map(|p| {
            reproduce::run_paper(
                &root,
                p,
                reproduce::DEFAULT_TRIALS,
                reproduce::DEFAULT_SEED,
                2,
            )
            .expect("paper world runs")
        })
        .collect();
    let fresh = reproduce::markdown(&results);
    let committed = std::fs::read_to_string(root.join("docs/reproductions-tables.md"))
        .expect("docs/reproductions-tables.md is committed");
    assert!(
        fresh == committed,
        "docs/reproductions-tables.md is stale: run `cargo run --release -- reproduce --markdown docs/reproductions-tables.md`\n{}",
        reproduce::text(&results)
    );
}

/// Scoring is paired: on a world whose estimators consume different sources (GPS alone,
/// GPS+DTMB, GPS+DTMB+FM), every estimator has one record per scoring instant, the same
/// instants for all, in increasing time; so the 3-D error RMSE and the unaligned ATE RMSE,
/// computed over the same epochs, agree.
#[test]
fn every_estimator_is_scored_at_the_same_instants() {
    let w = load_world(&crate::common::repo().join("worlds/seed000-beihang.toml")).unwrap();
    let t = hybridnav::world::trial::run_trial(&w, 1, 0).expect("trial runs");
    let times: Vec<Vec<f64>> = t
        .estimators
        .iter()
        .map(|e| e.epochs.iter().map(|r| r.t_s).collect())
        .collect();
    assert!(times.len() >= 3);
    for (e, ts) in t.estimators.iter().zip(&times) {
        assert_eq!(ts, &times[0], "{} is scored at other instants", e.name);
        assert!(ts.windows(2).all(|w| w[0] < w[1]), "{}", e.name);
    }
    let s = run("worlds/seed000-beihang.toml", 2, 1);
    for e in &s.estimators {
        assert_eq!(e.epochs, s.estimators[0].epochs, "{}", e.name);
        if let (Some(err), Some(ate)) = (&e.error_3d_m, &e.ate_m) {
            assert!(
                (err.rmse - ate.rmse).abs() < 1e-9 * err.rmse,
                "{}: error RMSE {} against ATE RMSE {}",
                e.name,
                err.rmse,
                ate.rmse
            );
        }
    }
}

/// `hybridnav reproduce --seeds 1-2` scores each seed as the one-seed command does: its
/// per-seed totals are the totals line of `--seed 1` and of `--seed 2` run apart (a second
/// computation by the same scoring over separate runs), its median of two seeds is the
/// mean of their two figures, its Markdown names every seed, and a bad list is refused.
#[test]
fn the_seed_sweep_matches_the_one_seed_runs() {
    use crate::common::{hybridnav, refused, tmp_dir};
    let out = |o: &std::process::Output| {
        assert!(o.status.success(), "{}", crate::common::stderr(o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let one = |seed: &str| {
        out(&hybridnav(&[
            "reproduce",
            "seed002",
            "--trials",
            "2",
            "--seed",
            seed,
        ]))
    };
    let dir = tmp_dir("seed-sweep");
    let md = dir.join("seeds.md");
    let sweep = out(&hybridnav(&[
        "reproduce",
        "seed002",
        "--trials",
        "2",
        "--seeds",
        "1-2",
        "--markdown",
        md.to_str().unwrap(),
    ]));
    // "6 of 8 figures within 2× of the papers; 2 of 3 claimed orderings hold" per run.
    let totals = |text: &str| -> (String, String) {
        let line = text
            .lines()
            .find(|l| l.contains("figures within 2× of the papers"))
            .expect("totals line")
            .to_string();
        let w: Vec<&str> = line.split_whitespace().collect();
        (
            format!("{} of {} figures", w[0], w[2]),
            format!("{} of {} orderings", w[9], w[11]),
        )
    };
    for seed in ["1", "2"] {
        let (f, o) = totals(&one(seed));
        let want = format!("seed {seed}: {f}, {o}");
        assert!(sweep.contains(&want), "sweep lacks {want:?}:\n{sweep}");
    }
    // The PDR 68 % row: the one-seed figures, and the sweep's median is their mean.
    let pdr68 = |text: &str| -> f64 {
        let l = text
            .lines()
            .find(|l| l.trim_start().starts_with("PDR") && l.contains("68 %"))
            .expect("PDR 68 % row");
        l.split_whitespace().nth(5).unwrap().parse().unwrap()
    };
    let (a, b) = (pdr68(&one("1")), pdr68(&one("2")));
    let row = sweep
        .lines()
        .find(|l| l.trim_start().starts_with("PDR") && l.contains("68 %"))
        .unwrap();
    let cells: Vec<&str> = row.split_whitespace().collect();
    let (lo, med, hi): (f64, f64, f64) = (
        cells[5].parse().unwrap(),
        cells[6].parse().unwrap(),
        cells[7].parse().unwrap(),
    );
    assert_eq!((lo, hi), (a.min(b), a.max(b)), "{row}");
    assert!(
        (med - 0.5 * (a + b)).abs() <= 0.006,
        "{row}: median of {a} and {b}"
    );
    let md = std::fs::read_to_string(&md).unwrap();
    assert!(md.contains("master seeds 1, 2") && md.contains("| PDR | 68 % horiz. | 8.77 |"));
    refused(
        &["reproduce", "seed002", "--seeds", "3-1"],
        &["--seeds", "runs backwards"],
    );
    refused(&["reproduce", "seed002", "--seeds", "1,1"], &["repeated"]);
}

/// The paired comparisons under each claimed ordering take each trial's own value of the
/// ordering's metric (`reproduce::paired::trial_metric`). With one trial that value is the
/// summary's pooled one, which the run's reducer computes on its own path (a sorted spill
/// per statistic, the TUM tracks): every metric of every estimator of Beihang and Lianhua
/// must agree to 1e-9. And `pair` splits every trial of a two-trial run into holds,
/// reversed or tied.
#[test]
fn the_trial_by_trial_metric_is_the_summarys_on_one_trial() {
    use hybridnav::reproduce::paired::{pair, trial_metric};
    use hybridnav::reproduce::papers::Metric::*;
    use hybridnav::reproduce::{metric_of, OrderingResult};
    for world in ["worlds/seed000-beihang.toml", "worlds/seed002-lianhua.toml"] {
        let w = load_world(&crate::common::repo().join(world)).unwrap();
        let opts = crate::common::run_options(2, 1);
        let trials = run_trials(&w, &opts).unwrap();
        let one = RunOptions { trials: 1, ..opts };
        let s = summarise(&w, &one, &trials[..1]).unwrap();
        let mut compared = 0;
        for (k, e) in s.estimators.iter().enumerate() {
            for m in [
                Sigma1,
                Sigma2,
                Sigma3,
                Mean,
                Std,
                Rmse,
                Horizontal1,
                Horizontal2,
                AteMean,
                AteRmse,
            ] {
                let pooled = metric_of(e, m);
                let own = trial_metric(&trials[0].estimators[k], m);
                match (pooled, own) {
                    (Some(a), Some(b)) => {
                        assert!(
                            (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                            "{world} {} {m:?}: {a} against {b}",
                            e.name
                        );
                        compared += 1;
                    }
                    (a, b) => assert_eq!(a.is_some(), b.is_some(), "{world} {} {m:?}", e.name),
                }
            }
            assert_eq!(trial_metric(&trials[0].estimators[k], RpeMean), None);
        }
        assert!(compared >= 30, "{world}: {compared}");
        let names: Vec<String> = s.estimators.iter().map(|e| e.name.clone()).collect();
        let mut o = [OrderingResult {
            metric: Sigma2,
            values: vec![
                (s.estimators[0].name.clone().leak(), None),
                (s.estimators[1].name.clone().leak(), None),
            ],
            paired: Vec::new(),
        }];
        pair(&mut o, &trials, &names);
        let p = o[0].paired[0].expect("a pair with per-trial values");
        assert_eq!(p.holds + p.reversed + p.ties, 2);
    }
}
