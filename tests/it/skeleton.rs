//! The walking skeleton through the library API: the trial loop, shielding and the
//! closed loop between sources and estimators.

use crate::common::*;
use hybridnav::world::parse_world;
use hybridnav::world::trial::run_trial;

#[test]
fn shielding_removes_the_snapshot_fix_and_degrades_the_ekf() {
    let text = default_world_text();
    let w = parse_world(&text, &repo().join("worlds/default.toml")).unwrap();
    let r = run_trial(&w, 3, 0).unwrap();
    let wls = &r.estimators[0];
    let ekf = &r.estimators[1];
    assert_eq!(wls.name, "GPS WLS");
    assert_eq!(ekf.name, "GPS+BDS");
    let inside = |t: f64| (40.0..80.0).contains(&t) || (120.0..150.0).contains(&t);
    // Outside the windows a fix needs four tracked GPS satellites, which the buildings
    // sometimes leave fewer of: the survey says where.
    let survey = hybridnav::world::visibility::survey(&w, 1.0).unwrap();
    let gps = hybridnav::world::visibility::LinkGroup::Satellites(hybridnav::core::System::Gps);
    let tracked = |t: f64| {
        use hybridnav::gnss::visibility::LinkClass;
        survey.get(t.round() as usize).map_or(0, |e| {
            e.count(gps, LinkClass::Los)
                + e.count(gps, LinkClass::Foliage)
                + e.count(gps, LinkClass::Nlos)
        })
    };
    for ep in &wls.epochs {
        if inside(ep.t_s) {
            // With three GPS satellites or fewer a snapshot fix cannot exist.
            assert!(
                ep.err_3d_m.is_none(),
                "fix at {} s inside a shielded window",
                ep.t_s
            );
        } else if ep.t_s > 1.0 && tracked(ep.t_s) >= 4 {
            assert!(ep.err_3d_m.is_some(), "no fix at {} s in open sky", ep.t_s);
        }
    }
    // The EKF always has an estimate once initialised; its error in open sky is that of a
    // converged GNSS filter, and it grows while it coasts on two satellites of each system
    // (four ranges for five unknowns with the BeiDou inter-system bias).
    let open: Vec<f64> = ekf
        .epochs
        .iter()
        .filter(|e| e.t_s > 10.0 && e.t_s < 40.0)
        .filter_map(|e| e.err_3d_m)
        .collect();
    let late_shield: Vec<f64> = ekf
        .epochs
        .iter()
        .filter(|e| e.t_s > 140.0 && e.t_s < 150.0)
        .filter_map(|e| e.err_3d_m)
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(mean(&open) < 10.0, "open-sky EKF error {}", mean(&open));
    assert!(
        mean(&late_shield) > mean(&open),
        "{} vs {}",
        mean(&late_shield),
        mean(&open)
    );
}

#[test]
fn trials_depend_only_on_seed_and_index() {
    let text = default_world_text();
    let w = parse_world(&text, &repo().join("worlds/default.toml")).unwrap();
    let a = run_trial(&w, 11, 4).unwrap();
    let b = run_trial(&w, 11, 4).unwrap();
    assert_eq!(a, b);
    let c = run_trial(&w, 11, 5).unwrap();
    assert_ne!(a, c);
}

/// The default world in open sky with white measurement errors only: the conditions under
/// which seed 000's EKF model is exactly right about the measurements. Its estimators are
/// GPS WLS, a GPS EKF and a GPS+BDS EKF (indices 0, 1, 2). The sky is the synthetic
/// nominal constellation of 2018-06-01 04:00 GPST on which this test was established; on
/// the default world's real 2020 sky the GPS row passes (98.7 % of epochs in the band) but
/// the GPS+BDS row has 85.8 % (mean NEES 3.145), an open question (docs/validation.md).
fn open_sky_white_world() -> String {
    let s: String = default_world_text()
        .lines()
        .map(|l| {
            if l.starts_with("ephemeris = ") {
                "ephemeris = \"builtin:nominal-gps-bds\"".to_string()
            } else if l.starts_with("start = ") {
                "start = \"2018-06-01T04:00:00 GPST\"".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    // Without the DTMB receiver, the IMU, the shielding windows, the scene and the
    // transmitters: an open sky, GNSS only.
    let d = s.find("# The DTMB receiver").unwrap();
    let m = s.find("[montecarlo]").unwrap();
    let estimators = "[[estimator]]\nname = \"GPS WLS\"\nsources = [\"gps\"]\nfilter = \"wls\"\n\n\
        [[estimator]]\nname = \"GPS\"\nsources = [\"gps\"]\nfilter = \"ekf11\"\n\n\
        [[estimator]]\nname = \"GPS+BDS\"\nsources = [\"gps\", \"bds\"]\nfilter = \"ekf11\"\n\n";
    let s = format!("{}{}{}", &s[..d], estimators, &s[m..]);
    // A straight road at constant speed: the truth has no jerk, so a small acceleration PSD
    // in the filter is the right model and the filter should be consistent.
    let s = s.replace(
        "points_enu_m = [[0, 0], [789, 0], [789, 8], [0, 8]], speed_mps = 10.0, accel_mps2 = 1.5, lateral_accel_mps2 = 2.0,",
        "points_enu_m = [[0, 0], [1500, 900]], speed_mps = 10.0,",
    );
    let s = s.replace(
        "filter = \"ekf11\"\n",
        "filter = \"ekf11\"\nekf = { accel_psd_m2ps5 = [0.01, 0.01, 0.01] }\n",
    );
    s.replace(
        "elevation_mask_deg = 10.0",
        "elevation_mask_deg = 10.0\n\n[sensors.gnss.errors]\nure_tau_s = 0.001\niono_residual = 0.0\niono_residual_per_sat = 0.0\ntropo_residual = 0.0\n",
    )
}

#[test]
fn full_chain_nees_is_within_its_chi2_band_in_open_sky() {
    use hybridnav::core::stats::chi2;
    let text = open_sky_white_world();
    let w = parse_world(&text, &repo().join("worlds/default.toml")).unwrap();
    let runs = 50;
    let results: Vec<_> = (0..runs).map(|i| run_trial(&w, 21, i).unwrap()).collect();
    // Two-sided 95 % band of the run-averaged NEES: N·ε̄ ~ χ²(3N).
    let dof = 3.0 * runs as f64;
    let (lo, hi) = (
        chi2::quantile(0.025, dof) / runs as f64,
        chi2::quantile(0.975, dof) / runs as f64,
    );
    for k in [1usize, 2] {
        let n_epochs = results[0].estimators[k].epochs.len();
        let mut inside = 0;
        let mut counted = 0;
        let mut grand = 0.0;
        for e in 0..n_epochs {
            if results[0].estimators[k].epochs[e].t_s < 20.0 {
                continue; // Let the filter converge from its least-squares start.
            }
            let mean = results
                .iter()
                .map(|r| r.estimators[k].epochs[e].nees_pos.unwrap())
                .sum::<f64>()
                / runs as f64;
            grand += mean;
            counted += 1;
            inside += usize::from((lo..=hi).contains(&mean));
        }
        let share = inside as f64 / counted as f64;
        let name = &results[0].estimators[k].name;
        eprintln!(
            "{name}: mean NEES {:.3}, {:.1} % of epochs inside [{lo:.3}, {hi:.3}]",
            grand / counted as f64,
            100.0 * share
        );
        assert!(
            share >= 0.9,
            "{name}: only {:.1} % of epochs inside the 95 % band",
            100.0 * share
        );
    }
}
