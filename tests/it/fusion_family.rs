//! The filter family of `fusion::{models, kalman, particle}` against independent
//! references: the textbook linear KF, each other on a nearly linear problem, χ² bands
//! over seeded Monte Carlo runs, injected outliers, and filterpy on a recorded sequence.
//!
//! Figures are printed; run with
//! `cargo test --release --test fusion_family -- --nocapture --test-threads 1`.

use hybridnav::core::{StreamRng, System, TrialRng};
use hybridnav::fusion::kalman::{
    chi2, Ekf, Gating, RelativeEntropyKf, ResidualGate, SigmaPointKf, StrongTrackingFilter,
    DEFAULT_ALEPH_THRESHOLD,
};
use hybridnav::fusion::linear_kf::LinearKf;
use hybridnav::fusion::models::{
    ConstantVelocity, MeasurementModel, PositionFixModel, ProcessModel, Pseudoranges, RangeRow,
    StateLayout,
};
use hybridnav::fusion::particle::{ParticleBuffer, ParticleFilter, Resampling};
use nalgebra::{DMatrix, DVector, SMatrix, SVector, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

type V4 = SVector<f64, 4>;
type M4 = SMatrix<f64, 4, 4>;

fn normal<const K: usize>(rng: &mut StreamRng) -> SVector<f64, K> {
    SVector::<f64, K>::from_fn(|_, _| rng.sample(StandardNormal))
}

/// A draw from `N(0, P)`.
fn draw<const K: usize>(p: &SMatrix<f64, K, K>, rng: &mut StreamRng) -> SVector<f64, K> {
    p.cholesky().expect("positive definite").l() * normal::<K>(rng)
}

/// A 2-D range layout for the state `[x, vx, y, vy]`: true ranges, no clock.
fn range_layout() -> StateLayout {
    StateLayout {
        pos: [Some(0), Some(2), None],
        vel: [Some(1), Some(3), None],
        clock: [None; System::COUNT],
        isb: [None; System::COUNT],
        drift: None,
    }
}

fn ranges<const M: usize>(beacons: [(f64, f64); M], sigma_m: f64) -> Pseudoranges<4, M> {
    let rows = beacons.map(|(x, y)| RangeRow {
        emitter_pos_m: Vector3::new(x, y, 0.0),
        emitter_vel_mps: Vector3::zeros(),
        system: System::Dtmb,
        sigma_m,
        sigma_rate_mps: 1.0,
    });
    Pseudoranges::new(range_layout(), rows).expect("valid model")
}

/// One truth trajectory of the CV model and its noisy measurements.
fn simulate<H: MeasurementModel<4, M>, const M: usize>(
    cv: &ConstantVelocity<4>,
    meas: &H,
    x0: V4,
    dt: f64,
    steps: usize,
    rng: &mut StreamRng,
) -> (Vec<V4>, Vec<SVector<f64, M>>) {
    let q = cv.q(&x0, dt);
    let r = meas.r();
    let mut x = x0;
    let mut xs = Vec::with_capacity(steps);
    let mut zs = Vec::with_capacity(steps);
    for _ in 0..steps {
        x = cv.f(&x, dt) + draw(&q, rng);
        xs.push(x);
        zs.push(meas.h(&x) + draw(&r, rng));
    }
    (xs, zs)
}

fn to_d<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_column_slice(R, C, m.as_slice())
}

#[test]
fn generic_ekf_equals_the_linear_kf_on_a_linear_model() {
    let mut rng = TrialRng::new(11, 0).stream("test/ekf_vs_kf");
    let cv = ConstantVelocity::<4>::new(0.5).unwrap();
    let x0 = V4::new(10.0, 1.0, -5.0, 2.0);
    let p0 = M4::from_diagonal(&V4::new(25.0, 4.0, 25.0, 4.0));
    let mut ekf = Ekf::new(x0, p0).unwrap();
    let mut kf = LinearKf::new(DVector::from_column_slice(x0.as_slice()), to_d(&p0)).unwrap();
    let (mut dx, mut dp) = (0.0_f64, 0.0_f64);
    for k in 0..50 {
        let dt = 0.2 + rng.random::<f64>();
        // A random full fix covariance, so that the update is not diagonal.
        let a = SMatrix::<f64, 2, 2>::from_fn(|_, _| rng.random::<f64>());
        let r = a * a.transpose() + SMatrix::<f64, 2, 2>::identity();
        let fix = PositionFixModel::<4, 2>::new([0, 2], r).unwrap();
        let z = SVector::<f64, 2>::new(10.0 + k as f64, -5.0 + 2.0 * k as f64)
            + SVector::<f64, 2>::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
        ekf.predict(&cv, dt).unwrap();
        kf.predict(&to_d(&cv.jacobian(&x0, dt)), &to_d(&cv.q(&x0, dt)))
            .unwrap();
        assert!(ekf.update(&fix, &z).outcome.is_accepted());
        kf.update(
            &DVector::from_column_slice(z.as_slice()),
            &to_d(&fix.jacobian(&x0)),
            &to_d(&r),
        )
        .unwrap();
        for i in 0..4 {
            let s = kf.covariance()[(i, i)].sqrt();
            dx = dx.max((ekf.state()[i] - kf.state()[i]).abs() / kf.state()[i].abs().max(s));
            for j in 0..4 {
                let n = (kf.covariance()[(i, i)] * kf.covariance()[(j, j)]).sqrt();
                dp = dp.max((ekf.covariance()[(i, j)] - kf.covariance()[(i, j)]).abs() / n);
            }
        }
    }
    println!("EKF vs LinearKf, 50 steps: state {dx:.1e}, covariance {dp:.1e}");
    assert!(dx < 1e-9 && dp < 1e-9);
}

#[test]
fn ukf_and_ckf_agree_with_the_ekf_on_a_nearly_linear_problem() {
    // Beacons 100 km away: over a prior of a few metres the ranges are linear to 1e-4.
    let mut rng = TrialRng::new(12, 0).stream("test/sigma_vs_ekf");
    let cv = ConstantVelocity::<4>::new(0.1).unwrap();
    let meas = ranges([(1e5, 0.0), (0.0, 1e5), (-7e4, -7e4)], 2.0);
    let x0 = V4::new(0.0, 1.0, 0.0, -1.0);
    let p0 = M4::from_diagonal(&V4::new(100.0, 1.0, 100.0, 1.0));
    let (_, zs) = simulate(&cv, &meas, x0, 1.0, 60, &mut rng);
    let mut ekf = Ekf::new(x0, p0).unwrap();
    let mut ukf = SigmaPointKf::unscented(x0, p0, 1e-3, 2.0, 0.0).unwrap();
    let mut ckf = SigmaPointKf::cubature(x0, p0).unwrap();
    let (mut du, mut dc) = (0.0_f64, 0.0_f64);
    for z in &zs {
        ekf.predict(&cv, 1.0).unwrap();
        ukf.predict(&cv, 1.0).unwrap();
        ckf.predict(&cv, 1.0).unwrap();
        ekf.update(&meas, z);
        ukf.update(&meas, z);
        ckf.update(&meas, z);
        for i in 0..4 {
            let s = ekf.covariance()[(i, i)].sqrt();
            du = du.max((ukf.state()[i] - ekf.state()[i]).abs() / s);
            dc = dc.max((ckf.state()[i] - ekf.state()[i]).abs() / s);
        }
    }
    println!("largest |x_UKF − x_EKF| / σ = {du:.2e}, |x_CKF − x_EKF| / σ = {dc:.2e} (60 epochs)");
    assert!(du < 0.01 && dc < 0.01);
}

#[test]
fn particle_filter_error_falls_towards_the_kalman_filter() {
    // Linear-Gaussian: CV with 2-D position fixes, where the KF is the exact posterior.
    let cv = ConstantVelocity::<4>::new(0.2).unwrap();
    let fix =
        PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity() * 4.0).unwrap();
    let x0 = V4::new(0.0, 1.0, 0.0, 0.5);
    let p0 = M4::from_diagonal(&V4::new(9.0, 1.0, 9.0, 1.0));
    let runs = 10;
    let steps = 30;
    let mut last = f64::INFINITY;
    let (mut rmse_kf, mut figures) = (0.0, Vec::new());
    for &n in &[100usize, 1000, 10_000] {
        let (mut sq_diff, mut sq_pf, mut sq_kf, mut count) = (0.0, 0.0, 0.0, 0.0);
        for run in 0..runs {
            let trial = TrialRng::new(13, run);
            let mut rng = trial.stream("test/pf_vs_kf/truth");
            let truth0 = x0 + draw(&p0, &mut rng);
            let (xs, zs) = simulate(&cv, &fix, truth0, 1.0, steps, &mut rng);
            let mut kf = Ekf::new(x0, p0).unwrap();
            let mut prng = trial.stream("test/pf_vs_kf/particles");
            let mut pf = ParticleFilter::new(
                ParticleBuffer::<4>::new(n).unwrap(),
                Resampling::Systematic,
                0.5,
            )
            .unwrap();
            pf.init_gaussian(&x0, &p0, &mut prng).unwrap();
            for (x, z) in xs.iter().zip(&zs) {
                kf.predict(&cv, 1.0).unwrap();
                kf.update(&fix, z);
                pf.predict(&cv, 1.0, &mut prng).unwrap();
                assert!(!pf.update(&fix, z, &mut prng).degenerate);
                let m = pf.mean();
                let d = Vector3::new(m[0] - kf.state()[0], m[2] - kf.state()[2], 0.0);
                sq_diff += d.norm_squared();
                sq_pf += (m[0] - x[0]).powi(2) + (m[2] - x[2]).powi(2);
                sq_kf += (kf.state()[0] - x[0]).powi(2) + (kf.state()[2] - x[2]).powi(2);
                count += 1.0;
            }
        }
        let diff = (sq_diff / count).sqrt();
        rmse_kf = (sq_kf / count).sqrt();
        figures.push((n, (sq_pf / count).sqrt(), diff));
        assert!(diff < last, "PF–KF difference did not shrink at N = {n}");
        last = diff;
    }
    for (n, rmse, diff) in &figures {
        println!("PF N = {n:>5}: position RMSE {rmse:.4} m, RMS |x_PF − x_KF| {diff:.4} m");
    }
    println!("KF: position RMSE {rmse_kf:.4} m");
    assert!(
        figures[2].2 < 0.05 * rmse_kf,
        "10 000 particles should be within 5 % of the KF"
    );
}

/// Runs `runs` seeded trials of a CV target seen by three range beacons and returns the
/// fraction of epochs whose run-averaged NEES lies in the two-sided 95 % χ² band, with
/// the overall mean NEES.
fn nees_band(cubature: bool, runs: u64) -> (f64, f64) {
    let cv = ConstantVelocity::<4>::new(0.05).unwrap();
    let meas = ranges([(800.0, 0.0), (0.0, 900.0), (-600.0, -700.0)], 5.0);
    let x0 = V4::new(0.0, 2.0, 0.0, 1.0);
    let p0 = M4::from_diagonal(&V4::new(25.0, 1.0, 25.0, 1.0));
    let steps = 60;
    let mut sum = vec![0.0; steps];
    for run in 0..runs {
        let mut rng = TrialRng::new(14, run).stream("test/nees");
        let truth0 = x0 + draw(&p0, &mut rng);
        let (xs, zs) = simulate(&cv, &meas, truth0, 1.0, steps, &mut rng);
        let mut f = if cubature {
            SigmaPointKf::cubature(x0, p0).unwrap()
        } else {
            SigmaPointKf::unscented(x0, p0, 1.0, 2.0, -1.0).unwrap()
        };
        for (k, (x, z)) in xs.iter().zip(&zs).enumerate() {
            f.predict(&cv, 1.0).unwrap();
            assert!(f.update(&meas, z).outcome.is_accepted());
            let e = x - f.state();
            let pinv = f.covariance().try_inverse().unwrap();
            sum[k] += (e.transpose() * pinv * e)[(0, 0)];
        }
    }
    let n = runs as f64;
    let lo = chi2::quantile(0.025, 4.0 * n) / n;
    let hi = chi2::quantile(0.975, 4.0 * n) / n;
    let inside = sum.iter().filter(|s| (lo..=hi).contains(&(*s / n))).count();
    let mean = sum.iter().sum::<f64>() / (n * steps as f64);
    (inside as f64 / steps as f64, mean)
}

#[test]
fn ukf_and_ckf_are_consistent_over_200_runs() {
    for (name, cubature) in [("UKF (α 1, β 2, κ 3 − n)", false), ("CKF", true)] {
        let (frac, mean) = nees_band(cubature, 200);
        println!("{name}: mean NEES {mean:.3} (n = 4), {:.1} % of 60 epochs in the 95 % band of the 200-run average", 100.0 * frac);
        assert!(
            frac >= 0.85 && (mean - 4.0).abs() < 0.3,
            "{name}: {frac} {mean}"
        );
    }
}

#[test]
fn relative_entropy_kf_and_residual_gate_reject_outliers_the_plain_ekf_absorbs() {
    let cv = ConstantVelocity::<4>::new(0.05).unwrap();
    let meas = ranges(
        [
            (800.0, 0.0),
            (0.0, 900.0),
            (-600.0, -700.0),
            (700.0, -650.0),
        ],
        3.0,
    );
    let x0 = V4::new(0.0, 2.0, 0.0, 1.0);
    let p0 = M4::from_diagonal(&V4::new(25.0, 1.0, 25.0, 1.0));
    let gated = Gating {
        chi2_prob: None,
        residual: Some(ResidualGate::sigmas(3.0)),
    };
    let names = [
        "EKF, no gate",
        "EKF + eq. 24 gate (C = 3)",
        "RE-KF (ℵ ½ln2, C = 3)",
        "STF, no gate",
    ];
    let mut sq = [[0.0; 4]; 2];
    let mut count = 0.0;
    let mut outliers_rejected = 0u32;
    let mut outliers = 0u32;
    for run in 0..50 {
        let trial = TrialRng::new(15, run);
        let mut rng = trial.stream("test/outliers/truth");
        let truth0 = x0 + draw(&p0, &mut rng);
        let (xs, zs) = simulate(&cv, &meas, truth0, 1.0, 80, &mut rng);
        let mut orng = trial.stream("test/outliers/inject");
        for inject in [false, true] {
            let mut ekf = Ekf::new(x0, p0).unwrap();
            let mut gekf = Ekf::new(x0, p0).unwrap().with_gating(gated).unwrap();
            let mut rekf = RelativeEntropyKf::new(
                x0,
                p0,
                DEFAULT_ALEPH_THRESHOLD,
                Some(ResidualGate::sigmas(3.0)),
            )
            .unwrap();
            let mut stf = StrongTrackingFilter::<4, 4>::new(x0, p0, 0.95, 1.0).unwrap();
            for (k, (x, z)) in xs.iter().zip(&zs).enumerate() {
                let mut z = *z;
                // One range in ten epochs carries a 20–60 m multipath error (7–20 σ).
                let hit = inject && k >= 10 && orng.random::<f64>() < 0.1;
                let which = orng.random_range(0..4);
                let size = 20.0 + 40.0 * orng.random::<f64>();
                if hit {
                    z[which] += size;
                    outliers += 1;
                }
                ekf.predict(&cv, 1.0).unwrap();
                gekf.predict(&cv, 1.0).unwrap();
                rekf.predict(&cv, 1.0).unwrap();
                stf.predict(&cv, 1.0).unwrap();
                ekf.update(&meas, &z);
                gekf.update(&meas, &z);
                let (_, coupling) = rekf.update(&meas, &z);
                if hit && !coupling.unwrap().kept[which] {
                    outliers_rejected += 1;
                }
                stf.update(&meas, &z);
                if k >= 10 {
                    for (i, s) in [ekf.state(), gekf.state(), rekf.state(), stf.state()]
                        .iter()
                        .enumerate()
                    {
                        sq[usize::from(inject)][i] += (s[0] - x[0]).powi(2) + (s[2] - x[2]).powi(2);
                    }
                    if !inject {
                        count += 1.0;
                    }
                }
            }
        }
    }
    let rmse = |v: f64| (v / count).sqrt();
    for (i, name) in names.iter().enumerate() {
        println!(
            "{name:<28} position RMSE clean {:.3} m, with outliers {:.3} m",
            rmse(sq[0][i]),
            rmse(sq[1][i])
        );
    }
    println!("RE-KF data layer removed {outliers_rejected} of {outliers} injected outliers");
    let (plain, gate, re) = (rmse(sq[1][0]), rmse(sq[1][1]), rmse(sq[1][2]));
    assert!(
        gate < 0.8 * plain && re < 0.8 * plain,
        "{plain} {gate} {re}"
    );
    // On clean data the gates cost little.
    assert!(rmse(sq[0][2]) < 1.1 * rmse(sq[0][0]));
    assert!(f64::from(outliers_rejected) > 0.9 * f64::from(outliers));
}

/// Finds the cross-check script whatever the working directory.
fn script() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/python/filterpy_crosscheck.py")
}

#[test]
fn ekf_and_ukf_match_filterpy_on_a_recorded_sequence() {
    let mut rng = TrialRng::new(16, 0).stream("test/filterpy");
    let cv = ConstantVelocity::<4>::new(0.3).unwrap();
    let beacons = [
        (300.0, 40.0),
        (-50.0, 420.0),
        (-380.0, -260.0),
        (200.0, -350.0),
    ];
    let sigma = 4.0;
    let meas = ranges(beacons, sigma);
    let x0 = V4::new(5.0, 1.5, -3.0, 0.5);
    let p0 = M4::from_diagonal(&V4::new(100.0, 4.0, 100.0, 4.0));
    let dt = 1.0;
    let (_, zs) = simulate(&cv, &meas, x0, dt, 40, &mut rng);
    let (alpha, beta, kappa) = (0.3, 2.0, 1.0);
    let problem = serde_json::json!({
        "beacons": beacons.iter().map(|b| [b.0, b.1]).collect::<Vec<_>>(),
        "sigma_m": vec![sigma; 4],
        "x0": x0.as_slice(),
        "p0": (0..4).map(|i| (0..4).map(|j| p0[(i, j)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "dt_s": dt,
        "accel_psd": 0.3,
        "alpha": alpha, "beta": beta, "kappa": kappa,
        "z": zs.iter().map(|z| z.as_slice().to_vec()).collect::<Vec<_>>(),
    });
    let dir = std::env::temp_dir().join(format!("hybridnav_filterpy_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (inp, out) = (dir.join("in.json"), dir.join("out.json"));
    std::fs::write(&inp, problem.to_string()).unwrap();
    let status = std::process::Command::new("python3")
        .arg(script())
        .arg(&inp)
        .arg(&out)
        .status();
    match status {
        Ok(s) if s.success() => {}
        Ok(s) if s.code() == Some(3) => {
            crate::common::skip("filterpy not installed");
            return;
        }
        Ok(s) => panic!("the filterpy script failed: {s}"),
        Err(_) => {
            crate::common::skip("filterpy not installed (no python3)");
            return;
        }
    }
    let res: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let mut ekf = Ekf::new(x0, p0).unwrap();
    let mut ukf = SigmaPointKf::unscented(x0, p0, alpha, beta, kappa).unwrap();
    let (mut de, mut du) = (0.0_f64, 0.0_f64);
    for (k, z) in zs.iter().enumerate() {
        ekf.predict(&cv, dt).unwrap();
        ekf.update(&meas, z);
        ukf.predict(&cv, dt).unwrap();
        ukf.update(&meas, z);
        for i in 0..4 {
            let fe = res["ekf"][k][i].as_f64().unwrap();
            let fu = res["ukf"][k][i].as_f64().unwrap();
            de = de.max((ekf.state()[i] - fe).abs());
            du = du.max((ukf.state()[i] - fu).abs());
            let pe = res["ekf_p"][k][i].as_f64().unwrap();
            let pu = res["ukf_p"][k][i].as_f64().unwrap();
            de = de.max((ekf.covariance()[(i, i)] - pe).abs() / pe.max(1.0));
            du = du.max((ukf.covariance()[(i, i)] - pu).abs() / pu.max(1.0));
        }
    }
    println!("vs filterpy over 40 epochs: EKF largest difference {de:.2e}, UKF {du:.2e} (state in m, m/s; variances relative)");
    assert!(de < 1e-6 && du < 1e-6, "EKF {de}, UKF {du}");
}
