//! The orderings seeds 000, 002 and 004 report, on their site worlds, over a few trials (the
//! full tables, with more trials, are in docs/reproductions.md; seeds 001 and 003 are in
//! `reproductions_abstract`).

use hybridnav::montecarlo::store::Shard;
use hybridnav::montecarlo::{run_trials, summarise, RunOptions, Summary};
use hybridnav::world::load_world;

fn run(world: &str, trials: u64, seed: u64) -> Summary {
    let w = load_world(&crate::common::repo().join(world)).expect("world loads");
    let opts = RunOptions {
        trials,
        seed,
        threads: 2,
        progress: false,
        shard: Shard::WHOLE,
    };
    let r = run_trials(&w, &opts).expect("trials run");
    summarise(&w, &opts, &r).expect("summary")
}

fn get<'a>(s: &'a Summary, name: &str) -> &'a hybridnav::montecarlo::EstimatorSummary {
    s.estimators
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no estimator {name} in {}", s.world))
}

/// Seed 000 site 1: at 3σ, Proposed < GPS+DTMB < GPS (the paper: 27.80 < 35.31 < 87.46),
/// and the same order in mean ATE (9.90 < 13.53 < 24.52).
#[test]
fn seed000_beihang_proposed_beats_gps_dtmb_beats_gps() {
    let s = run("worlds/seed000-beihang.toml", 6, 2);
    let s3 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma3;
    let ate = |n: &str| get(&s, n).ate_m.unwrap().mean;
    println!(
        "3σ: GPS {:.1}, GPS+DTMB {:.1}, Proposed {:.1}; ATE: {:.1} {:.1} {:.1}",
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

/// Seed 000 site 2: at 2σ, 3σ and in mean ATE, Proposed < GPS+DTMB < GPS (the paper, 3σ:
/// 60.23 < 262.80 < 416.60). The GPS-only and GPS+DTMB tails come from a few long coasts
/// of the 11-state EKF in the two-satellite windows, so the ordering of the two needs many
/// trials: 100 (as `docs/reproductions.md`), where seeds 1–5 give GPS+DTMB / GPS at 3σ of
/// 0.65–0.72; at 20 trials the two come within a few per cent (seed 1: 628.9 against
/// 648.8 m).
#[test]
fn seed000_kehui_proposed_beats_gps_dtmb_beats_gps() {
    let s = run("worlds/seed000-kehui.toml", 100, 1);
    let s2 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma2;
    let s3 = |n: &str| get(&s, n).error_3d_m.unwrap().sigma3;
    let ate = |n: &str| get(&s, n).ate_m.unwrap().mean;
    println!(
        "2σ: GPS {:.1}, GPS+DTMB {:.1}, Proposed {:.1}; 3σ: {:.1} {:.1} {:.1}; ATE: {:.1} {:.1} {:.1}",
        s2("GPS"),
        s2("GPS+DTMB"),
        s2("Proposed"),
        s3("GPS"),
        s3("GPS+DTMB"),
        s3("Proposed"),
        ate("GPS"),
        ate("GPS+DTMB"),
        ate("Proposed")
    );
    for (what, f) in [
        ("2σ", &s2 as &dyn Fn(&str) -> f64),
        ("3σ", &s3),
        ("ATE", &ate),
    ] {
        assert!(
            f("Proposed") < f("GPS+DTMB") && f("GPS+DTMB") < f("GPS"),
            "{what}: Proposed {}, GPS+DTMB {}, GPS {}",
            f("Proposed"),
            f("GPS+DTMB"),
            f("GPS")
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
