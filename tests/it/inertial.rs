//! Inertial module validation: Allan deviation of a simulated static IMU, the closed-form
//! drift of a stationary INS, the loosely coupled filter with fixes and an outage, PDR
//! step detection and drift, and bad input. Figures are printed with `--nocapture` and
//! quoted in docs/validation.md ("Inertial"). All randomness comes from named streams.
//!
//! The allantools cross-check needs `python3` with the `allantools` package (pip packages
//! `allantools`, which pulls `numpy` and `scipy`); without it the test prints
//! "skipped: allantools not installed" and passes.

use hybridnav::core::TrialRng;
use hybridnav::inertial::allan::{
    adev_at, fit_white_density, log_cluster_sizes, overlapping_adev, AllanPoint,
};
use hybridnav::inertial::attitude::{
    attitude_from_euler, ideal_imu, BodyTruth, Platform, PlatformConfig, PlatformTruth,
};
use hybridnav::inertial::imu::{Imu, ImuConfig, ImuGrade, ImuSample, GM_ADEV_PEAK_TAU_OVER_T};
use hybridnav::inertial::ins_ekf::{InsEkf, InsEkfConfig};
use hybridnav::inertial::magnetometer::{Magnetometer, MagnetometerConfig};
use hybridnav::inertial::pdr::{Ahrs, Pdr, PdrConfig, StepEvent};
use hybridnav::inertial::strapdown::{NavState, Strapdown};
use hybridnav::inertial::LocalEarth;
use hybridnav::motion::TrajectoryConfig;
use nalgebra::{Matrix3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

fn earth() -> LocalEarth {
    LocalEarth::new(39.98f64.to_radians(), 60.0)
}

/// A static, level IMU's rate and specific-force series: 6 columns per sample.
fn static_series(cfg: &ImuConfig, hours: f64, seed: u64) -> (Vec<[f64; 6]>, f64) {
    let spec = cfg.resolve().unwrap();
    let e = earth();
    let q = attitude_from_euler(0.3, 0.0, 0.0);
    let truth = BodyTruth {
        t_s: 0.0,
        pos_enu_m: Vector3::zeros(),
        vel_enu_mps: Vector3::zeros(),
        acc_enu_mps2: Vector3::zeros(),
        q_nb: q,
        omega_nb_b_rps: Vector3::zeros(),
        heading_rad: 0.3,
    };
    let (w, f) = ideal_imu(&truth, &e);
    let mut imu = Imu::new(spec, TrialRng::new(seed, 0).stream("inertial/imu"));
    let n = (hours * 3600.0 * spec.rate_hz) as usize;
    let out = (0..n)
        .map(|k| {
            let s = imu.measure(k as f64 / spec.rate_hz, &w, &f);
            [
                s.gyro_rps.x,
                s.gyro_rps.y,
                s.gyro_rps.z,
                s.accel_mps2.x,
                s.accel_mps2.y,
                s.accel_mps2.z,
            ]
        })
        .collect();
    (out, spec.dt_s())
}

/// The Allan variance averaged over three axes (columns `c0..c0+3`).
fn mean_curve(series: &[[f64; 6]], c0: usize, dt: f64) -> Vec<AllanPoint> {
    let ms = log_cluster_sizes(series.len(), 20, 60);
    let mut acc: Option<Vec<AllanPoint>> = None;
    for c in c0..c0 + 3 {
        let y: Vec<f64> = series.iter().map(|r| r[c]).collect();
        let curve = overlapping_adev(&y, dt, &ms);
        acc = Some(match acc {
            None => curve
                .iter()
                .map(|p| AllanPoint {
                    adev: p.adev * p.adev,
                    ..*p
                })
                .collect(),
            Some(mut a) => {
                for (x, p) in a.iter_mut().zip(&curve) {
                    x.adev += p.adev * p.adev;
                }
                a
            }
        });
    }
    acc.unwrap()
        .into_iter()
        .map(|p| AllanPoint {
            adev: (p.adev / 3.0).sqrt(),
            ..p
        })
        .collect()
}

/// (σ_A(1 s), white density N fitted over τ ∈ [0.1, 0.5] s, bias-instability floor): the
/// floor is read at τ = 1.893 T, the Gauss–Markov hump, after removing the white term N²/τ.
fn read_curve(curve: &[AllanPoint], tau_corr_s: f64) -> (f64, f64, f64) {
    let at1 = adev_at(curve, 1.0).unwrap();
    let n = fit_white_density(curve, 0.1, 0.5).unwrap();
    let tau_b = GM_ADEV_PEAK_TAU_OVER_T * tau_corr_s;
    let total = adev_at(curve, tau_b).unwrap();
    let b = (total * total - n * n / tau_b).max(0.0).sqrt();
    (at1, n, b)
}

#[test]
fn allan_deviation_reproduces_the_grades() {
    // 12 h of a static, level IMU at 10 Hz per grade; Allan variances averaged over the
    // three axes of each triad. σ_A(1 s) = N holds where white noise dominates at 1 s; for
    // the high grade's accelerometer the bias term is larger than the white term there
    // (σ_GM √(2τ/3T) = 4.8e-7 vs N = 4.2e-7 m/s²), so N is always checked by the fit over
    // 0.1–0.5 s and σ_A(1 s) only where the white share of the variance at 1 s exceeds 90 %.
    println!("grade | gyro σ(1 s)/ARW | gyro N fit/ARW | gyro BI/conf. | accel σ(1 s)/VRW | accel N fit/VRW | accel BI/conf.");
    for (grade, seed) in [
        (ImuGrade::Low, 11),
        (ImuGrade::Mid, 12),
        (ImuGrade::High, 13),
    ] {
        let mut cfg = ImuConfig::grade(grade);
        cfg.rate_hz = 10.0;
        let spec = cfg.resolve().unwrap();
        let (series, dt) = static_series(&cfg, 12.0, seed);
        let g = mean_curve(&series, 0, dt);
        let a = mean_curve(&series, 3, dt);
        let (g1, gn, gb) = read_curve(&g, spec.bias_corr_time_s);
        let (a1, an, ab) = read_curve(&a, spec.bias_corr_time_s);
        let r = [
            g1 / spec.gyro_arw_rad_per_sqrt_s,
            gn / spec.gyro_arw_rad_per_sqrt_s,
            gb / spec.gyro_bias_instability_rps,
            a1 / spec.accel_vrw_mps_per_sqrt_s,
            an / spec.accel_vrw_mps_per_sqrt_s,
            ab / spec.accel_bias_instability_mps2,
        ];
        println!(
            "{grade:?} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4}",
            r[0], r[1], r[2], r[3], r[4], r[5]
        );
        let white_share = |n: f64, gm_sigma: f64| {
            let gm2 = gm_sigma * gm_sigma * 2.0 / (3.0 * spec.bias_corr_time_s);
            n * n / (n * n + gm2)
        };
        let check_at1 = [
            white_share(spec.gyro_arw_rad_per_sqrt_s, spec.gyro_gm_sigma_rps()) > 0.9,
            true,
            true,
            white_share(spec.accel_vrw_mps_per_sqrt_s, spec.accel_gm_sigma_mps2()) > 0.9,
            true,
            true,
        ];
        for (i, v) in r.iter().enumerate() {
            if check_at1[i] {
                assert!((v - 1.0).abs() < 0.10, "{grade:?} term {i}: ratio {v}");
            }
        }
    }
}

fn python_allantools() -> bool {
    std::process::Command::new("python3")
        .args(["-c", "import allantools"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

#[test]
fn allan_deviation_matches_allantools() {
    if !python_allantools() {
        println!("skipped: allantools not installed");
        return;
    }
    let mut cfg = ImuConfig::grade(ImuGrade::Low);
    cfg.rate_hz = 100.0;
    let (series, dt) = static_series(&cfg, 0.25, 21);
    let path = std::env::temp_dir().join(format!("hybridnav_allan_{}.csv", std::process::id()));
    let mut text = String::with_capacity(series.len() * 26);
    for r in &series {
        text.push_str(&format!("{:.17e}\n", r[0]));
    }
    std::fs::write(&path, text).unwrap();
    let ms = log_cluster_sizes(series.len(), 10, 10);
    let ours = overlapping_adev(&series.iter().map(|r| r[0]).collect::<Vec<_>>(), dt, &ms);
    let taus: Vec<String> = ours.iter().map(|p| format!("{}", p.m)).collect();
    let script = format!(
        "import numpy as np, allantools\n\
         y = np.loadtxt(r'{}')\n\
         m = np.array([{}], dtype=float)\n\
         t, d, e, n = allantools.oadev(y, rate={}, data_type='freq', taus=m/{})\n\
         print(' '.join(repr(float(v)) for v in t))\n\
         print(' '.join(repr(float(v)) for v in d))\n",
        path.display(),
        taus.join(","),
        1.0 / dt,
        1.0 / dt
    );
    let out = std::process::Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    let t: Vec<f64> = lines
        .next()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let d: Vec<f64> = lines
        .next()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(t.len(), ours.len(), "allantools taus {t:?}");
    let mut worst = 0.0f64;
    for ((tau, dev), p) in t.iter().zip(&d).zip(&ours) {
        assert!(
            (tau - p.tau_s).abs() < 1e-9 * p.tau_s,
            "{tau} vs {}",
            p.tau_s
        );
        worst = worst.max((dev / p.adev - 1.0).abs());
    }
    println!(
        "allantools oadev vs ours: {} taus, worst relative difference {worst:.2e}",
        t.len()
    );
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn stationary_ins_drifts_as_the_closed_form_predicts() {
    // A level, stationary INS heading north (body x = north, y = west, z = up) with a perfect
    // IMU plus one known bias. Closed forms (Groves §5.7, short horizon, Earth-rate coupling
    // neglected): accelerometer bias b → δr = ½ b t²; gyro bias ε about a horizontal axis →
    // tilt ε t → horizontal error g ε t³ / 6.
    let e = earth();
    let q = attitude_from_euler(0.0, 0.0, 0.0);
    let truth = BodyTruth {
        t_s: 0.0,
        pos_enu_m: Vector3::zeros(),
        vel_enu_mps: Vector3::zeros(),
        acc_enu_mps2: Vector3::zeros(),
        q_nb: q,
        omega_nb_b_rps: Vector3::zeros(),
        heading_rad: 0.0,
    };
    let (w, f) = ideal_imu(&truth, &e);
    let horizon_s: f64 = 60.0;
    let g = e.gravity_mps2(0.0);
    let b = 2e-3;
    let eps = 10f64.to_radians() / 3600.0;
    for (name, dw, df, predicted) in [
        (
            "accel bias 2e-3 m/s² (body x)",
            Vector3::zeros(),
            Vector3::new(b, 0.0, 0.0),
            0.5 * b * horizon_s.powi(2),
        ),
        (
            "gyro bias 10 °/h (body y)",
            Vector3::new(0.0, eps, 0.0),
            Vector3::zeros(),
            g * eps * horizon_s.powi(3) / 6.0,
        ),
    ] {
        let mut ins = Strapdown::new(
            NavState {
                t_s: 0.0,
                pos_enu_m: Vector3::zeros(),
                vel_enu_mps: Vector3::zeros(),
                q_nb: q,
            },
            e,
        );
        let rate = 100.0;
        for k in 0..=(horizon_s * rate) as usize {
            ins.step(k as f64 / rate, &(w + dw), &(f + df));
        }
        let err = ins.state().pos_enu_m;
        let horiz = err.x.hypot(err.y);
        println!("{name}: {horiz:.4} m after {horizon_s} s, closed form {predicted:.4} m (ratio {:.5}); north part {:.4}", horiz / predicted, err.y);
        assert!(
            (horiz / predicted - 1.0).abs() < 0.01,
            "{name}: {horiz} vs {predicted}"
        );
        // Both errors are along north (the accelerometer axis / the axis the tilt is about ⟂).
        assert!(err.y.abs() > 0.99 * horiz);
    }
}

fn car_truth(laps: u32) -> PlatformTruth {
    let traj = TrajectoryConfig::Waypoints {
        points_enu_m: vec![
            vec![0.0, 0.0],
            vec![400.0, 0.0],
            vec![400.0, 250.0],
            vec![0.0, 250.0],
        ],
        speed_mps: 12.0,
        accel_mps2: Some(1.5),
        lateral_accel_mps2: Some(2.0),
        dwell_s: None,
        laps: Some(laps),
        height_m: None,
    }
    .build(&mut TrialRng::new(5, 0).stream("motion/trajectory"))
    .unwrap();
    PlatformTruth::new(
        traj,
        &PlatformConfig::default(),
        &mut TrialRng::new(5, 0).stream("inertial/gait"),
    )
    .unwrap()
}

struct LcRun {
    rms_with_fixes_m: f64,
    max_with_fixes_m: f64,
    at_outage_start_m: f64,
    at_outage_end_m: f64,
    sigma_at_outage_end_m: f64,
    max_after_recovery_m: f64,
}

fn loosely_coupled(grade: ImuGrade, seed: u64, outage: (f64, f64)) -> LcRun {
    let car = car_truth(3);
    let e = earth();
    let cfg = ImuConfig::grade(grade);
    let spec = cfg.resolve().unwrap();
    let rng = TrialRng::new(seed, 0);
    let mut imu = Imu::new(spec, rng.stream("inertial/imu"));
    let mut fix_rng = rng.stream("gnss/fix");
    let t0 = car.sample(0.0);
    let init = NavState {
        t_s: 0.0,
        pos_enu_m: t0.pos_enu_m + Vector3::new(3.0, -2.0, 1.0),
        vel_enu_mps: t0.vel_enu_mps + Vector3::new(0.2, -0.1, 0.0),
        q_nb: UnitQuaternion::from_euler_angles(0.005, -0.005, 0.03) * t0.q_nb,
    };
    let mut kf = InsEkf::new(init, e, &InsEkfConfig::from_imu(&spec));
    let sigma_fix = 2.0;
    let r = Matrix3::identity() * sigma_fix * sigma_fix;
    let n = (car.duration_s() * spec.rate_hz) as usize;
    let (mut sum2, mut cnt, mut max_fix, mut at_start, mut at_end, mut sig_end, mut max_rec) =
        (0.0, 0, 0.0f64, 0.0, 0.0, 0.0, 0.0f64);
    for k in 0..=n {
        let t = k as f64 / spec.rate_hz;
        let s = car.sample(t);
        let (w, f) = ideal_imu(&s, &e);
        let m = imu.measure(t, &w, &f);
        kf.propagate(&m);
        let in_outage = t > outage.0 && t <= outage.1;
        let err = (kf.state().pos_enu_m - s.pos_enu_m).xy().norm();
        if t > 60.0 && t < outage.0 {
            sum2 += err * err;
            cnt += 1;
            max_fix = max_fix.max(err);
        }
        if t > outage.1 + 20.0 {
            max_rec = max_rec.max(err);
        }
        if (t - outage.0).abs() < 0.5 / spec.rate_hz {
            at_start = err;
        }
        if (t - outage.1).abs() < 0.5 / spec.rate_hz {
            at_end = err;
            sig_end = kf.position_sigma_m().xy().norm();
        }
        if k % (spec.rate_hz as usize) == 0 && k > 0 && !in_outage {
            let noise = Vector3::new(
                fix_rng.sample::<f64, _>(StandardNormal),
                fix_rng.sample(StandardNormal),
                fix_rng.sample(StandardNormal),
            );
            kf.update_position(&(s.pos_enu_m + noise * sigma_fix), &r)
                .unwrap();
            let err = (kf.state().pos_enu_m - s.pos_enu_m).xy().norm();
            if t > 60.0 && t < outage.0 {
                sum2 += err * err;
                cnt += 1;
                max_fix = max_fix.max(err);
            }
            if t > outage.1 + 30.0 {
                max_rec = max_rec.max(err);
            }
        }
    }
    LcRun {
        rms_with_fixes_m: (sum2 / cnt as f64).sqrt(),
        max_with_fixes_m: max_fix,
        at_outage_start_m: at_start,
        at_outage_end_m: at_end,
        sigma_at_outage_end_m: sig_end,
        max_after_recovery_m: max_rec,
    }
}

#[test]
fn loosely_coupled_filter_bounds_the_error_and_grows_in_an_outage() {
    // A car on a 400 m × 250 m rounded rectangle at 12 m/s (three laps, 330 s), 100 Hz IMU,
    // 1 Hz position fixes with σ = 2 m per axis, a 30 s outage from t = 150 s. Errors are
    // horizontal, at every IMU sample.
    println!("grade | seed | horiz. RMS with fixes (60–150 s) | max | at outage start | after 30 s outage | filter 2-D σ there | max from 20 s after the outage");
    for grade in [ImuGrade::Mid, ImuGrade::Low] {
        for seed in [1, 2, 3] {
            let r = loosely_coupled(grade, seed, (150.0, 180.0));
            println!(
                "{grade:?} | {seed} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2}",
                r.rms_with_fixes_m,
                r.max_with_fixes_m,
                r.at_outage_start_m,
                r.at_outage_end_m,
                r.sigma_at_outage_end_m,
                r.max_after_recovery_m
            );
            assert!(r.rms_with_fixes_m < 2.0 && r.max_with_fixes_m < 5.0);
            assert!(r.max_after_recovery_m < 5.0);
            // The outage error stays within the filter's own 3σ (2-D) prediction.
            assert!(r.at_outage_end_m < 3.0 * r.sigma_at_outage_end_m.max(1.0));
            if grade == ImuGrade::Mid {
                assert!(r.at_outage_end_m < 15.0);
            }
        }
    }
}

fn walk_truth(platform: Platform, seed: u64) -> PlatformTruth {
    // Seed 002's outdoor walk: two laps of a 116 m loop (38 m × 20 m, rounded corners).
    let traj = TrajectoryConfig::Waypoints {
        points_enu_m: vec![
            vec![0.0, 0.0],
            vec![38.0, 0.0],
            vec![38.0, 20.0],
            vec![0.0, 20.0],
        ],
        speed_mps: 1.1,
        accel_mps2: Some(0.5),
        lateral_accel_mps2: Some(0.4),
        dwell_s: None,
        laps: Some(2),
        height_m: None,
    }
    .build(&mut TrialRng::new(seed, 0).stream("motion/trajectory"))
    .unwrap();
    let cfg = PlatformConfig {
        platform,
        ..Default::default()
    };
    PlatformTruth::new(
        traj,
        &cfg,
        &mut TrialRng::new(seed, 0).stream("inertial/gait"),
    )
    .unwrap()
}

struct PdrRun {
    true_steps: usize,
    detected: usize,
    matched: usize,
    final_err_m: f64,
    max_err_m: f64,
    path_m: f64,
    pdr_path_m: f64,
}

fn run_pdr(platform: Platform, seed: u64, grade: ImuGrade, mag_gain: f64) -> PdrRun {
    let walk = walk_truth(platform, seed);
    let e = earth();
    let spec = ImuConfig::grade(grade).resolve().unwrap();
    let rng = TrialRng::new(seed, 0);
    let mut imu = Imu::new(spec, rng.stream("inertial/imu"));
    let mag_cfg = MagnetometerConfig::default();
    let mut mag = Magnetometer::new(&mag_cfg, rng.stream("inertial/mag")).unwrap();
    let pcfg = PdrConfig {
        mag_gain,
        ..PdrConfig::default()
    };
    let mut pdr: Option<Pdr> = None;
    let mut events: Vec<StepEvent> = Vec::new();
    let n = (walk.duration_s() * spec.rate_hz) as usize;
    let mut max_err = 0.0f64;
    let mut last = walk.sample(0.0);
    for k in 0..=n {
        let t = k as f64 / spec.rate_hz;
        let s = walk.sample(t);
        let (w, f) = ideal_imu(&s, &e);
        let m: ImuSample = imu.measure(t, &w, &f);
        let b = mag.measure(&s.q_nb);
        let p = pdr.get_or_insert_with(|| {
            let ahrs = Ahrs::align(&m.accel_mps2, &b, &mag_cfg.field_enu_ut(), e, &pcfg);
            Pdr::new(&pcfg, spec.rate_hz, ahrs, s.pos_enu_m.xy()).unwrap()
        });
        if let Some(ev) = p.update(&m, Some(&b)) {
            events.push(ev);
            let truth_then = walk.sample(ev.t_s).pos_enu_m.xy();
            max_err = max_err.max((p.position_en_m() - truth_then).norm());
        }
        last = s;
    }
    let truth_steps = walk.true_step_times_s();
    // Greedy one-to-one matching within ±0.2 s.
    let mut used = vec![false; events.len()];
    let mut matched = 0;
    for &ts in &truth_steps {
        if let Some((i, _)) = events
            .iter()
            .enumerate()
            .filter(|(i, ev)| !used[*i] && (ev.t_s - ts).abs() <= 0.2)
            .min_by(|a, b| (a.1.t_s - ts).abs().total_cmp(&(b.1.t_s - ts).abs()))
        {
            used[i] = true;
            matched += 1;
        }
    }
    let p = pdr.unwrap();
    PdrRun {
        true_steps: truth_steps.len(),
        detected: events.len(),
        matched,
        final_err_m: (p.position_en_m() - last.pos_enu_m.xy()).norm(),
        max_err_m: max_err,
        path_m: path_length(&walk),
        pdr_path_m: events.iter().map(|e| e.length_m).sum(),
    }
}

fn path_length(w: &PlatformTruth) -> f64 {
    let n = (w.duration_s() * 10.0) as usize;
    let mut len = 0.0;
    let mut prev: Vector2<f64> = w.trajectory().state_at(0.0).pos_enu_m.xy();
    for k in 1..=n {
        let p = w.trajectory().state_at(k as f64 / 10.0).pos_enu_m.xy();
        len += (p - prev).norm();
        prev = p;
    }
    len
}

#[test]
fn pdr_detects_steps_and_reports_its_drift() {
    println!("platform | seed | true steps | detected | matched % | false % | path m | PDR path m | final error m | max error m");
    let (mut tot_true, mut tot_match, mut tot_det) = (0, 0, 0);
    for platform in [Platform::Handheld, Platform::Pedestrian] {
        for seed in 1..=4 {
            let r = run_pdr(platform, seed, ImuGrade::Low, PdrConfig::default().mag_gain);
            let det_rate = r.matched as f64 / r.true_steps as f64;
            let false_rate = (r.detected - r.matched) as f64 / r.detected as f64;
            println!(
                "{platform:?} | {seed} | {} | {} | {:.2} | {:.2} | {:.1} | {:.1} | {:.2} | {:.2}",
                r.true_steps,
                r.detected,
                100.0 * det_rate,
                100.0 * false_rate,
                r.path_m,
                r.pdr_path_m,
                r.final_err_m,
                r.max_err_m
            );
            assert!(
                det_rate >= 0.98,
                "{platform:?}/{seed}: detection {det_rate}"
            );
            assert!(
                false_rate <= 0.01,
                "{platform:?}/{seed}: false steps {false_rate}"
            );
            assert!(r.max_err_m < 15.0);
            tot_true += r.true_steps;
            tot_match += r.matched;
            tot_det += r.detected;
        }
    }
    // Without the magnetometer the heading is the integrated gyro (10 °/h bias instability
    // and 0.75 °/√h ARW, consumer grade): the drift seed 002 describes for its second lap.
    for grade in [ImuGrade::Low, ImuGrade::Mid] {
        for seed in 1..=4 {
            let r = run_pdr(Platform::Handheld, seed, grade, 0.0);
            println!(
                "gyro-only heading, {grade:?} grade, seed {seed}: final error {:.2} m, max {:.2} m",
                r.final_err_m, r.max_err_m
            );
            assert!(r.final_err_m.is_finite());
        }
    }
    println!(
        "overall: {tot_match}/{tot_true} steps detected ({:.2} %), {} false ({:.2} %)",
        100.0 * tot_match as f64 / tot_true as f64,
        tot_det - tot_match,
        100.0 * (tot_det - tot_match) as f64 / tot_det as f64
    );
}

#[test]
fn bad_imu_input_gives_clear_messages() {
    let parse = |t: &str| toml::from_str::<ImuConfig>(t);
    let e = parse("grade = \"ultra\"").unwrap_err().to_string();
    assert!(
        e.contains("ultra") && e.contains("`low`") && e.contains("`mid`") && e.contains("`high`"),
        "{e}"
    );
    let e = parse("grade = \"low\"\nrate = 100")
        .unwrap_err()
        .to_string();
    assert!(e.contains("rate"), "{e}");
    for (text, key, needle) in [
        ("rate_hz = 0", "rate_hz", "(0, 1000]"),
        ("rate_hz = 5000", "rate_hz", "5000"),
        ("rate_hz = -10", "rate_hz", "-10"),
        (
            "gyro_arw_deg_per_sqrt_h = -0.1",
            "gyro_arw_deg_per_sqrt_h",
            "negative",
        ),
        (
            "accel_vrw_mps_per_sqrt_h = -1",
            "accel_vrw_mps_per_sqrt_h",
            "negative",
        ),
        (
            "accel_bias_instability_mps2 = -1e-4",
            "accel_bias_instability_mps2",
            "negative",
        ),
        (
            "gyro_rrw_deg_per_h_per_sqrt_h = -2",
            "gyro_rrw_deg_per_h_per_sqrt_h",
            "negative",
        ),
        (
            "bias_corr_time_s = 0",
            "bias_corr_time_s",
            "correlation time",
        ),
        (
            "grade = \"custom\"\ngyro_arw_deg_per_sqrt_h = 1",
            "gyro_bias_instability_deg_per_h",
            "custom",
        ),
        ("gyro_range_deg_per_s = 0", "gyro_range_deg_per_s", "range"),
    ] {
        let cfg = parse(text).unwrap();
        let issue = cfg.validate().unwrap_err();
        println!("{text:?} → {issue}");
        assert_eq!(issue.key, key, "{text}");
        assert!(issue.message.contains(needle), "{text}: {}", issue.message);
    }
    let c = ImuConfig {
        rate_hz: f64::NAN,
        ..Default::default()
    };
    assert_eq!(c.validate().unwrap_err().key, "rate_hz");
    assert!(ImuConfig::grade(ImuGrade::High).validate().is_ok());
    let ok = parse("grade = \"mid\"\nrate_hz = 1000").unwrap();
    assert!(ok.validate().is_ok());
}
