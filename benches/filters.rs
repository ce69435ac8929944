//! Benchmarks of the filter family (`fusion::{models, kalman, particle}`) against the
//! Python baselines in `benches/python/`:
//!
//! * one 11-state EKF epoch, predict + 12 pseudoranges + 12 range rates: seed 000's
//!   hand-optimised `Ekf11` (sequential scalar updates) and the generic `Ekf<12>` on
//!   `Pva11Clock` + `PseudorangesAndRates<12, 24>` (one 24-row vector update, as filterpy
//!   computes it); baseline `benches/python/ekf_epoch_bench.py`;
//! * the SIR particle filter with 6 pseudoranges at 100, 500 and 10 000 particles: the
//!   likelihood alone and a whole epoch (predict, weight, N_eff-threshold resampling), in
//!   particle·measurement likelihood terms per second; baseline
//!   `benches/python/pf_bench.py`;
//! * the regularised and Rao-Blackwellised particle filters on the same scene, a whole
//!   epoch each, and the regularised resampling step alone.
//!
//! Run: `cargo bench --bench filters -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::{StreamRng, System, TrialRng};
use hybridnav::fusion::ekf11::{Ekf11, Ekf11Config, N_STATES};
use hybridnav::fusion::kalman::Ekf;
use hybridnav::fusion::models::{
    ConstantVelocity, MeasurementModel, ProcessModel, Pseudoranges, PseudorangesAndRates,
    Pva11Clock, RangeRow, StateLayout,
};
use hybridnav::fusion::particle::{
    ParticleBuffer, ParticleFilter, PseudorangeLikelihood, Resampling, SoaLikelihood,
};
use nalgebra::{SMatrix, SVector, Vector3};

mod common;
use common::scene;

fn bench_ekf(c: &mut Criterion) {
    let (r, ms) = scene();
    let mut ekf = Ekf11::new(Ekf11Config::default()).expect("default configuration is valid");
    ekf.initialise(r + Vector3::new(5.0, -3.0, 2.0), 0.0, 10.0, 100.0)
        .expect("finite initial state");
    for _ in 0..20 {
        ekf.predict(1.0).expect("valid interval");
        for m in &ms {
            ekf.update_range(m);
        }
    }
    c.bench_function(
        "ekf11 epoch: predict + 12 pr + 12 rates (sequential scalar)",
        |b| {
            b.iter(|| {
                let mut f = ekf.clone();
                f.predict(black_box(1.0)).expect("valid interval");
                for m in &ms {
                    black_box(f.update_range(black_box(m)));
                }
                f
            })
        },
    );

    // The generic EKF on the same model, one vector update of 24 rows.
    let model = Pva11Clock::new(Ekf11Config::default()).expect("valid");
    let rows: Vec<RangeRow> = ms.iter().map(RangeRow::from).collect();
    let meas =
        PseudorangesAndRates::<N_STATES, 24>::new(StateLayout::ekf11(), &rows).expect("valid");
    let z = SVector::<f64, 24>::from_fn(|j, _| {
        if j < 12 {
            ms[j].pseudorange_m
        } else {
            ms[j - 12].range_rate_mps.unwrap_or(0.0)
        }
    });
    let mut gen = Ekf::new(*ekf.state(), *ekf.covariance()).expect("valid prior");
    for _ in 0..5 {
        gen.predict(&model, 1.0).expect("valid");
        gen.update(&meas, &z);
    }
    c.bench_function(
        "generic Ekf<12> epoch: predict + 24-row vector update",
        |b| {
            b.iter(|| {
                let mut f = gen.clone();
                f.predict(&model, black_box(1.0)).expect("valid");
                black_box(f.update(&meas, black_box(&z)));
                f
            })
        },
    );
}

/// A random walk on `[x, y, z, b]` with 1 m (position) and 0.5 m (clock) per step, the
/// prediction of `benches/python/pf_bench.py`.
struct RandomWalk;

impl ProcessModel<4> for RandomWalk {
    fn f(&self, x: &SVector<f64, 4>, _dt_s: f64) -> SVector<f64, 4> {
        *x
    }
    fn jacobian(&self, _x: &SVector<f64, 4>, _dt_s: f64) -> SMatrix<f64, 4, 4> {
        SMatrix::identity()
    }
    fn q(&self, _x: &SVector<f64, 4>, dt_s: f64) -> SMatrix<f64, 4, 4> {
        SMatrix::from_diagonal(&SVector::<f64, 4>::new(1.0, 1.0, 1.0, 0.25)) * dt_s
    }
}

fn bench_pf(c: &mut Criterion) {
    let emitters = [
        [15_600e3, 7_540e3, 20_140e3],
        [18_760e3, 2_750e3, 18_610e3],
        [17_610e3, 14_630e3, 13_480e3],
        [19_170e3, 610e3, 18_390e3],
        [-2_000e3, 12_000e3, 21_000e3],
        [5_000e3, -14_000e3, 20_000e3],
    ];
    let truth = SVector::<f64, 4>::new(-2_177e3, 4_389e3, 4_070e3, 30.0);
    let layout = StateLayout {
        pos: [Some(0), Some(1), Some(2)],
        vel: [None; 3],
        clock: [Some(3); System::COUNT],
        isb: [None; System::COUNT],
        drift: None,
    };
    let rows = emitters.map(|e| RangeRow {
        emitter_pos_m: Vector3::from(e),
        emitter_vel_mps: Vector3::zeros(),
        system: System::Gps,
        sigma_m: 3.0,
        sigma_rate_mps: 1.0,
    });
    let model = Pseudoranges::<4, 6>::new(layout, rows).expect("valid");
    let z = model.h(&truth) + SVector::<f64, 6>::new(1.0, -2.0, 0.5, 3.0, -1.5, 2.0);
    let mut lik = PseudorangeLikelihood::with_capacity(6);
    lik.set(&model, &z);
    // The same ranges for a 3-D constant-velocity state without a clock (the marginalised
    // filter's bench): the clock term is taken out of the measurements.
    let cv = ConstantVelocity::<6>::new(0.5).expect("valid PSD");
    let cv_layout = StateLayout {
        pos: [Some(0), Some(2), Some(4)],
        vel: [Some(1), Some(3), Some(5)],
        clock: [None; System::COUNT],
        isb: [None; System::COUNT],
        drift: None,
    };
    let mut cv_lik = PseudorangeLikelihood::with_capacity(6);
    cv_lik.clear(cv_layout.pos);
    for (j, r) in rows.iter().enumerate() {
        cv_lik.push(&cv_layout, r, z[j] - truth[3]);
    }
    let mut group = c.benchmark_group("pf 6 pseudoranges");
    for n in [100usize, 500, 10_000] {
        let mut rng = TrialRng::new(1, 0).stream("bench/pf");
        let mut pf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).expect("n > 0"),
            Resampling::Systematic,
            0.5,
        )
        .expect("valid threshold");
        pf.init_gaussian(
            &truth,
            &(SMatrix::<f64, 4, 4>::identity() * 100.0),
            &mut rng,
        )
        .expect("valid prior");
        group.throughput(Throughput::Elements((n * 6) as u64));
        let mut out = vec![0.0; n];
        group.bench_function(format!("likelihood N={n}"), |b| {
            b.iter(|| {
                out.fill(0.0);
                SoaLikelihood::<4>::add_log_likelihood(
                    &lik,
                    black_box(pf.particles().columns()),
                    &mut out,
                );
                black_box(out[0])
            })
        });
        group.bench_function(format!("epoch N={n}"), |b| {
            b.iter(|| {
                pf.predict(&RandomWalk, 1.0, &mut rng).expect("valid");
                black_box(pf.update_soa(&lik, &mut rng))
            })
        });
        // The other members of the family on the same buffers and ranges: the
        // regularised PF (kernel jitter after each resampling) and the Rao-Blackwellised
        // PF (the clock column carried by a Kalman filter per particle), each a whole
        // epoch with N_eff < N/2 resampling; and the regularised resampling step alone,
        // forced every iteration (its worst case).
        let prior = SMatrix::<f64, 4, 4>::identity() * 100.0;
        let mut rpf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).expect("n > 0"),
            Resampling::Systematic,
            0.5,
        )
        .expect("valid threshold")
        .regularised();
        rpf.init_gaussian(&truth, &prior, &mut rng)
            .expect("valid prior");
        group.bench_function(format!("regularised epoch N={n}"), |b| {
            b.iter(|| {
                rpf.predict(&RandomWalk, 1.0, &mut rng).expect("valid");
                black_box(rpf.update_ranges(&lik, &mut rng))
            })
        });
        group.bench_function(format!("regularised resampling N={n}"), |b| {
            b.iter(|| {
                rpf.resample_regularised(&mut rng);
                black_box(rpf.particles().column(0)[0])
            })
        });
        // A likelihood much narrower than the cloud (the prior's 10 m against the ranges'
        // 3 m): the regularised update all at once, and by progressive correction (its
        // stages each a likelihood evaluation, a resampling and a kernel), each from a
        // fresh prior cloud every iteration (the draw is in both).
        let mut ppf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).expect("n > 0"),
            Resampling::Systematic,
            0.5,
        )
        .expect("valid threshold")
        .regularised()
        .with_progressive_correction(true);
        for (label, filter) in [("single", &mut rpf), ("progressive", &mut ppf)] {
            group.bench_function(
                format!("regularised {label} update from the prior N={n}"),
                |b| {
                    b.iter(|| {
                        filter
                            .init_gaussian(&truth, &prior, &mut rng)
                            .expect("valid prior");
                        black_box(filter.update_ranges(&lik, &mut rng))
                    })
                },
            );
        }
        // A Rao-Blackwellised filter (the GPS clock in column 3) resampling below θ·N,
        // started from the prior cloud and clock prior.
        let rb_started = |theta: f64, rng: &mut StreamRng| {
            let mut f = ParticleFilter::new(
                ParticleBuffer::<4>::new(n).expect("n > 0"),
                Resampling::Systematic,
                theta,
            )
            .expect("valid threshold")
            .rao_blackwellised(std::array::from_fn(|s| {
                (s == System::Gps.index()).then_some(3)
            }))
            .expect("one clock column");
            f.init_gaussian(&truth, &prior, rng).expect("valid prior");
            f.set_clock_prior(System::Gps.index(), truth[3], 100.0);
            f
        };
        let mut rbpf = rb_started(0.5, &mut rng);
        group.bench_function(format!("rao-blackwellised epoch N={n}"), |b| {
            b.iter(|| {
                rbpf.predict(&RandomWalk, 1.0, &mut rng).expect("valid");
                black_box(rbpf.update_ranges(&lik, &mut rng))
            })
        });
        // From a fresh 10 m prior cloud and clock prior each iteration, the
        // Rao-Blackwellised update all at once and by progressive correction (the clock's
        // Kalman update split into the stages).
        let rb_make = |progressive: bool| {
            ParticleFilter::new(
                ParticleBuffer::<4>::new(n).expect("n > 0"),
                Resampling::Systematic,
                0.5,
            )
            .expect("valid threshold")
            .with_progressive_correction(progressive)
            .rao_blackwellised(std::array::from_fn(|s| {
                (s == System::Gps.index()).then_some(3)
            }))
            .expect("one clock column")
        };
        for (label, mut filter) in [("single", rb_make(false)), ("progressive", rb_make(true))] {
            group.bench_function(
                format!("rao-blackwellised {label} update from the prior N={n}"),
                |b| {
                    b.iter(|| {
                        filter
                            .init_gaussian(&truth, &prior, &mut rng)
                            .expect("valid prior");
                        filter.set_clock_prior(System::Gps.index(), truth[3], 100.0);
                        black_box(filter.update_ranges(&lik, &mut rng))
                    })
                },
            );
        }
        // The same filter with the linearised proposal: the noise-free move, then the
        // proposal with the clock integrated out (one factorisation of the predictive
        // covariance), each particle's draw and predictive weight, and the clock filters'
        // update at the new positions.
        let q_rb = ProcessModel::<4>::q(&RandomWalk, &truth, 1.0);
        group.bench_function(format!("rao-blackwellised linearised epoch N={n}"), |b| {
            b.iter(|| {
                rbpf.propagate(&RandomWalk, 1.0).expect("valid");
                black_box(
                    rbpf.update_linearised(&q_rb, &lik, &mut rng)
                        .expect("valid"),
                )
            })
        });
        // The paper models' default Rao-Blackwellised PF (`filter = "rbpf"`): the same
        // epoch with a resampling and the Liu-West kernel at every epoch (θ = 1), so each
        // iteration also resamples, factors the kernel and shrinks the cloud.
        let mut rbpf_default = rb_started(1.0, &mut rng);
        group.bench_function(
            format!("rao-blackwellised linearised epoch, resampled N={n}"),
            |b| {
                b.iter(|| {
                    rbpf_default.propagate(&RandomWalk, 1.0).expect("valid");
                    black_box(
                        rbpf_default
                            .update_linearised(&q_rb, &lik, &mut rng)
                            .expect("valid"),
                    )
                })
            },
        );
        // The Gaussian PF on the same state and ranges: its prediction factors the
        // cloud's weighted covariance and redraws every particle from the predicted
        // Gaussian; the update weights them (no resampling).
        let mut gpf = ParticleFilter::new(
            ParticleBuffer::<4>::new(n).expect("n > 0"),
            Resampling::Systematic,
            0.5,
        )
        .expect("valid threshold")
        .gaussian();
        gpf.init_gaussian(&truth, &prior, &mut rng)
            .expect("valid prior");
        group.bench_function(format!("gaussian epoch N={n}"), |b| {
            b.iter(|| {
                gpf.predict(&RandomWalk, 1.0, &mut rng).expect("valid");
                black_box(gpf.update_ranges(&lik, &mut rng))
            })
        });
        // The same with the linearised importance function: the update factors the EKF
        // update of the kept prediction, redraws every particle from it and weights each
        // by the exact over the linearised likelihood.
        let q = ProcessModel::<4>::q(&RandomWalk, &truth, 1.0);
        group.bench_function(format!("gaussian linearised epoch N={n}"), |b| {
            b.iter(|| {
                gpf.predict(&RandomWalk, 1.0, &mut rng).expect("valid");
                black_box(gpf.update_linearised(&q, &lik, &mut rng).expect("valid"))
            })
        });
        // The marginalised PF on a 3-D constant-velocity state (no clock): the positions
        // sampled, the velocities carried by the per-particle Kalman filters, so each
        // epoch adds the joint factorisation and the conditional update of the means.
        let mut mpf = ParticleFilter::new(
            ParticleBuffer::<6>::new(n).expect("n > 0"),
            Resampling::Systematic,
            0.5,
        )
        .expect("valid threshold")
        .marginalised([Some(0), Some(2), Some(4)], [None; System::COUNT])
        .expect("three position columns");
        let cv_truth = SVector::<f64, 6>::new(truth[0], 1.0, truth[1], -2.0, truth[2], 0.5);
        mpf.init_gaussian(
            &cv_truth,
            &SMatrix::<f64, 6, 6>::from_diagonal(&SVector::<f64, 6>::new(
                100.0, 4.0, 100.0, 4.0, 100.0, 4.0,
            )),
            &mut rng,
        )
        .expect("valid prior");
        group.bench_function(format!("marginalised epoch N={n}"), |b| {
            b.iter(|| {
                mpf.predict(&cv, 1.0, &mut rng).expect("valid");
                black_box(mpf.update_ranges(&cv_lik, &mut rng))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_ekf, bench_pf);
criterion_main!(benches);
