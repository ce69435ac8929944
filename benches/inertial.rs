//! Benchmarks of the inertial hot paths: the IMU error model alone (one sample of six
//! sensors), truth + ideal IMU + error model for a walking phone, and one INS step
//! (mechanisation + 15-state covariance prediction).
//!
//! Run: `cargo bench --bench inertial -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::TrialRng;
use hybridnav::inertial::attitude::{ideal_imu, Platform, PlatformConfig, PlatformTruth};
use hybridnav::inertial::imu::{Imu, ImuConfig, ImuGrade, ImuSample};
use hybridnav::inertial::ins_ekf::{InsEkf, InsEkfConfig};
use hybridnav::inertial::strapdown::NavState;
use hybridnav::inertial::LocalEarth;
use hybridnav::motion::TrajectoryConfig;
use nalgebra::{UnitQuaternion, Vector3};

fn bench(c: &mut Criterion) {
    let earth = LocalEarth::new(0.7, 50.0);
    let spec = ImuConfig::grade(ImuGrade::Mid).resolve().unwrap();
    let mut g = c.benchmark_group("inertial");
    g.throughput(Throughput::Elements(1));

    let mut imu = Imu::new(spec, TrialRng::new(1, 0).stream("inertial/imu"));
    let w = Vector3::new(0.01, -0.02, 0.3);
    let f = Vector3::new(0.1, 0.2, 9.8);
    let mut t = 0.0;
    g.bench_function("imu_sample_error_model", |b| {
        b.iter(|| {
            t += 0.01;
            black_box(imu.measure(t, black_box(&w), black_box(&f)))
        })
    });

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
    .build(&mut TrialRng::new(1, 0).stream("motion/trajectory"))
    .unwrap();
    let cfg = PlatformConfig {
        platform: Platform::Handheld,
        ..Default::default()
    };
    let walk =
        PlatformTruth::new(traj, &cfg, &mut TrialRng::new(1, 0).stream("inertial/gait")).unwrap();
    let dur = walk.duration_s();
    let mut k = 0u64;
    g.bench_function("imu_sample_with_walking_truth", |b| {
        b.iter(|| {
            k += 1;
            let t = (k as f64 * 0.01) % dur;
            let s = walk.sample(t);
            let (w, f) = ideal_imu(&s, &earth);
            black_box(imu.measure(t, &w, &f))
        })
    });

    let init = NavState {
        t_s: 0.0,
        pos_enu_m: Vector3::zeros(),
        vel_enu_mps: Vector3::zeros(),
        q_nb: UnitQuaternion::identity(),
    };
    let mut kf = InsEkf::new(init, earth, &InsEkfConfig::from_imu(&spec));
    let mut n = 0u64;
    g.bench_function("ins_step_mechanisation_and_kf_predict", |b| {
        b.iter(|| {
            n += 1;
            let s = ImuSample {
                t_s: n as f64 * 0.01,
                gyro_rps: w * 1e-3,
                accel_mps2: Vector3::new(0.0, 0.0, earth.gravity_mps2(0.0)),
            };
            kf.propagate(black_box(&s));
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
