//! Benchmarks of the inertial hot paths: the IMU error model alone (one sample of six
//! sensors), truth + ideal IMU + error model for a walking phone, one INS step
//! (mechanisation + 15-state covariance prediction), and per engine epoch: the IMU source
//! (truth with attitude, increment IMU, error model, batch) for a car and a handheld phone,
//! the INS estimator on a one-sample IMU batch, and the INS estimator on a GNSS batch of
//! eight pseudoranges and rates (least-squares position and velocity, 6-D update); the
//! tightly coupled filter's step (18-state prediction) and its eight-satellite epoch (eight
//! pseudorange and eight range-rate scalar updates); the INS rows' PCRLB (`ins_bound`): one
//! IMU step of the 18-state bound and one eight-satellite epoch's information and update.
//!
//! Run: `cargo bench --bench inertial -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::{EmitterId, EnuFrame, Geodetic, GpsTime, SimTime, System, TrialRng};
use hybridnav::engine::trial::truth_at;
use hybridnav::inertial::attitude::{ideal_imu, Platform, PlatformConfig, PlatformTruth};
use hybridnav::inertial::imu::{Imu, ImuConfig, ImuGrade};
use hybridnav::inertial::ins_bound::{add_epoch_information, BoundCoupling, EpochInfo, InsBound};
use hybridnav::inertial::ins_ekf::{InsEkf, InsEkfConfig};
use hybridnav::inertial::ins_estimator::{InsEstimator, InsFilterConfig};
use hybridnav::inertial::ins_tight::{InsTightEkf, TightClockConfig};
use hybridnav::inertial::source::{local_earth_of, ImuSource};
use hybridnav::inertial::strapdown::NavState;
use hybridnav::inertial::LocalEarth;
use hybridnav::measurement::{
    Estimator, ImuSample, Measurement, MeasurementBatch, PositionFix, RangeMeasurement,
    SampleContext, Source,
};
use hybridnav::motion::TrajectoryConfig;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

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
        leg_speeds_mps: None,
        stops: None,
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
    tight(&mut g, init, earth, &InsEkfConfig::from_imu(&spec));
    engine_epochs(&mut g);
    g.finish();
}

/// The tightly coupled filter: one IMU step, and one epoch of eight GPS satellites
/// (pseudorange and range rate each) at the INS position, the clock known.
fn tight(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    init: NavState,
    earth: LocalEarth,
    cfg: &InsEkfConfig,
) {
    let frame = EnuFrame::new(Geodetic::from_deg(40.1, 116.3, 50.0));
    let earth = LocalEarth::new(frame.origin().lat_rad, earth.origin_h_m);
    let mut kf = InsTightEkf::new(init, earth, cfg, &TightClockConfig::default());
    let mut n = 0u64;
    g.bench_function("ins_tight_step_mechanisation_and_kf_predict", |b| {
        b.iter(|| {
            n += 1;
            let s = ImuSample {
                t_s: n as f64 * 0.01,
                gyro_rps: earth.omega_ie_enu_rps,
                accel_mps2: Vector3::new(0.0, 0.0, earth.gravity_mps2(0.0)),
            };
            kf.propagate(black_box(&s));
        })
    });
    let rx = frame.ecef_of_enu(&kf.state().pos_enu_m);
    let ranges: Vec<RangeMeasurement> = (0..8)
        .map(|i| {
            let az = i as f64 * 0.785 + 0.2;
            let el: f64 = if i == 7 { 1.4 } else { 0.25 + 0.12 * i as f64 };
            let d = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
            let e = frame.ecef_of_enu(&(d * 2.0e7));
            RangeMeasurement {
                emitter: EmitterId {
                    system: System::Gps,
                    number: i + 1,
                },
                emitter_pos_ecef_m: e,
                emitter_vel_ecef_mps: Vector3::zeros(),
                pseudorange_m: (rx - e).norm() + kf.clock_bias_m(),
                sigma_m: 3.0,
                range_rate_mps: Some(kf.clock_drift_mps()),
                sigma_rate_mps: 0.1,
                cn0_dbhz: 45.0,
                elevation_rad: el,
            }
        })
        .collect();
    g.bench_function("ins_tight_gnss_epoch_8_sats", |b| {
        b.iter(|| {
            for m in &ranges {
                let _ = black_box(kf.update_range(black_box(m), &frame, 0.0));
                let _ = black_box(kf.update_range_rate(black_box(m), &frame, 0.0));
            }
        })
    });
    // The INS rows' PCRLB (ins_bound): one IMU step of the 18-state bound along the truth
    // (block-wise F), beside the filter's step above, and one epoch's information and update.
    let bound = InsBound::new(
        cfg,
        0.03,
        BoundCoupling::Tight(TightClockConfig::default()),
        earth,
        *frame.rotation(),
    );
    let mut st = bound.start(0.0);
    let c = init.q_nb.to_rotation_matrix().into_inner();
    let f_n = Vector3::new(0.2, -0.1, earth.gravity_mps2(0.0));
    let mut n = 0u64;
    g.bench_function("ins_bound_tight_imu_step", |b| {
        b.iter(|| {
            n += 1;
            bound.predict(
                &mut st,
                n as f64 * 0.01,
                black_box(&c),
                black_box(&f_n),
                1.2,
            );
        })
    });
    g.bench_function("ins_bound_tight_epoch_8_sats", |b| {
        b.iter(|| {
            let mut info = EpochInfo::zeros();
            add_epoch_information(&mut info, &rx, &Vector3::zeros(), black_box(&ranges), true);
            let mut s = st;
            black_box(bound.update(&mut s, &bound.information(&info)))
        })
    });
}

fn car_config() -> TrajectoryConfig {
    TrajectoryConfig::Waypoints {
        points_enu_m: vec![
            vec![0.0, 0.0, 0.0],
            vec![400.0, 0.0, 5.0],
            vec![400.0, 250.0, 5.0],
            vec![0.0, 250.0, 0.0],
        ],
        speed_mps: 12.0,
        accel_mps2: Some(1.5),
        lateral_accel_mps2: Some(2.0),
        dwell_s: None,
        leg_speeds_mps: None,
        stops: None,
        laps: Some(20),
        height_m: None,
    }
}

fn walk_config() -> TrajectoryConfig {
    TrajectoryConfig::Waypoints {
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
        leg_speeds_mps: None,
        stops: None,
        laps: Some(20),
        height_m: None,
    }
}

/// Per-event costs of the inertial parts inside the engine.
fn engine_epochs(g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>) {
    let frame = EnuFrame::new(Geodetic::from_deg(30.558, 114.268, 25.0));
    let start = GpsTime::from_week_tow(2300, 0.0);
    let imu_cfg = ImuConfig::grade(ImuGrade::Mid);
    let rng = TrialRng::new(1, 0);

    for (label, traj_cfg, platform) in [
        ("imu_source_event_car_100hz", car_config(), Platform::Car),
        (
            "imu_source_event_handheld_100hz",
            walk_config(),
            Platform::Handheld,
        ),
    ] {
        let build = || {
            traj_cfg
                .build(&mut rng.stream("motion/trajectory"))
                .unwrap()
        };
        let engine_traj = build();
        let end = SimTime::from_seconds(engine_traj.duration_s());
        let plat = PlatformConfig {
            platform,
            ..Default::default()
        };
        let make = || ImuSource::new(&imu_cfg, &plat, build(), &frame, &rng, end).unwrap();
        let mut src = make();
        let mut at = src.first_sample();
        let mut batch = MeasurementBatch::default();
        g.bench_function(label, |b| {
            b.iter(|| {
                // What the engine does per IMU event: the truth, then the source.
                let truth = truth_at(&frame, start, engine_traj.as_ref(), at);
                batch.items.clear();
                let ctx = SampleContext {
                    truth: &truth,
                    estimates: &[],
                };
                match src.sample(&ctx, &mut batch) {
                    Some(n) => at = n,
                    None => {
                        src = make();
                        at = src.first_sample();
                    }
                }
                black_box(batch.items.len())
            })
        });
    }

    // An INS estimator initialised from position fixes on a level body gliding east.
    let cfg = InsFilterConfig {
        fix_sources: vec![
            hybridnav::measurement::SourceKind::Fm,
            hybridnav::measurement::SourceKind::Gnss,
        ],
        ..Default::default()
    };
    let mut ins = InsEstimator::new("INS", &cfg, &imu_cfg, &[System::Gps], &frame, start).unwrap();
    let gravity = local_earth_of(&frame).gravity_mps2(0.0);
    let mut imu_batch = MeasurementBatch {
        unscored: false,
        raw: None,
        t: start,
        source: hybridnav::measurement::SourceKind::Imu,
        items: vec![Measurement::Imu(ImuSample {
            t_s: 0.0,
            gyro_rps: Vector3::zeros(),
            accel_mps2: Vector3::new(0.0, 0.0, gravity),
        })],
    };
    let mut k = 0u64;
    let feed = |ins: &mut InsEstimator, batch: &mut MeasurementBatch, k: &mut u64| {
        let t = *k as f64 * 0.01;
        batch.t = start.add_seconds(t);
        if let Measurement::Imu(s) = &mut batch.items[0] {
            s.t_s = t;
        }
        *k += 1;
        ins.process(batch)
    };
    let mut fix = MeasurementBatch {
        unscored: false,
        raw: None,
        t: start,
        source: hybridnav::measurement::SourceKind::Fm,
        items: vec![Measurement::Position(PositionFix {
            pos_ecef_m: frame.origin_ecef(),
            cov_m2: Matrix3::identity() * 0.01,
            support: 0,
        })],
    };
    // A position fix at the time of the last IMU sample (the body glides east at 2 m/s).
    let mut fix_now = |ins: &mut InsEstimator, k: u64| {
        let t = (k - 1) as f64 * 0.01;
        fix.t = start.add_seconds(t);
        if let Measurement::Position(p) = &mut fix.items[0] {
            p.pos_ecef_m = frame.ecef_of_enu(&Vector3::new(2.0 * t, 0.0, 0.0));
        }
        ins.process(&fix)
    };
    while ins.filter().is_none() && k < 5000 {
        for _ in 0..100 {
            feed(&mut ins, &mut imu_batch, &mut k);
        }
        fix_now(&mut ins, k);
    }
    assert!(ins.filter().is_some(), "the INS did not initialise");
    // One IMU epoch, with a position fix after every hundredth (1 Hz fixes at 100 Hz, as in
    // a world; the fix's share is about 1 % of the iterations).
    g.bench_function("ins_estimator_imu_epoch", |b| {
        b.iter(|| {
            let out = feed(&mut ins, &mut imu_batch, &mut k);
            if k % 100 == 0 {
                fix_now(&mut ins, k);
            }
            black_box(out)
        })
    });
    assert!(ins.filter().is_some(), "the INS reset during the benchmark");

    // The same epoch with seed 004's RE-KF on the error state (chained transition per
    // sample, one generic-filter prediction and update per fix).
    let rekf_cfg = InsFilterConfig {
        fix_sources: vec![hybridnav::measurement::SourceKind::Fm],
        kalman: hybridnav::inertial::ins_family::InsKalmanKind::Rekf,
        residual_gate_c: Some(3.0),
        ..Default::default()
    };
    let mut rekf =
        InsEstimator::new("RE-KF", &rekf_cfg, &imu_cfg, &[System::Gps], &frame, start).unwrap();
    let mut k2 = 0u64;
    while rekf.nav_state().is_none() && k2 < 5000 {
        for _ in 0..100 {
            feed(&mut rekf, &mut imu_batch, &mut k2);
        }
        fix_now(&mut rekf, k2);
    }
    assert!(
        rekf.nav_state().is_some(),
        "the RE-KF INS did not initialise"
    );
    g.bench_function("ins_rekf_estimator_imu_epoch", |b| {
        b.iter(|| {
            let out = feed(&mut rekf, &mut imu_batch, &mut k2);
            if k2 % 100 == 0 {
                fix_now(&mut rekf, k2);
            }
            black_box(out)
        })
    });
    assert!(
        rekf.family_filter().is_some(),
        "the RE-KF INS reset during the benchmark"
    );

    // A GNSS epoch of eight satellites around the INS position, at the INS time.
    let t_ins = ins.filter().unwrap().state().t_s;
    let rx = frame.ecef_of_enu(&ins.filter().unwrap().state().pos_enu_m);
    let ranges: Vec<Measurement> = (0..8)
        .map(|i| {
            let az = i as f64 * 0.785 + 0.2;
            let el: f64 = if i == 7 { 1.4 } else { 0.25 + 0.12 * i as f64 };
            let d = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
            let e = frame.ecef_of_enu(&(d * 2.0e7));
            Measurement::Range(RangeMeasurement {
                emitter: EmitterId {
                    system: System::Gps,
                    number: i + 1,
                },
                emitter_pos_ecef_m: e,
                emitter_vel_ecef_mps: Vector3::zeros(),
                pseudorange_m: (rx - e).norm() + 50.0,
                sigma_m: 3.0,
                range_rate_mps: Some(0.1),
                sigma_rate_mps: 0.1,
                cn0_dbhz: 45.0,
                elevation_rad: el,
            })
        })
        .collect();
    let gnss = MeasurementBatch {
        unscored: false,
        raw: None,
        t: start.add_seconds(t_ins),
        source: hybridnav::measurement::SourceKind::Gnss,
        items: ranges,
    };
    g.bench_function("ins_estimator_gnss_epoch_8_sats", |b| {
        b.iter(|| black_box(ins.process(black_box(&gnss))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
