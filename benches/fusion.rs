//! Benchmarks of the fusion hot paths: one EKF epoch (predict, then 12 pseudoranges each
//! with a range rate, i.e. 24 sequential scalar updates) and one 12-range WLS fix.
//!
//! Run: `cargo bench --bench fusion -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hybridnav::fusion::ekf11::{Ekf11, Ekf11Config};
use hybridnav::fusion::wls::{self, WlsOptions};
use nalgebra::Vector3;

mod common;
use common::scene;

fn bench_fusion(c: &mut Criterion) {
    let (r, ms) = scene();
    let mut ekf = Ekf11::new(Ekf11Config::default()).expect("default configuration is valid");
    ekf.initialise(r + Vector3::new(5.0, -3.0, 2.0), 0.0, 10.0, 100.0)
        .expect("finite initial state");
    // Converge first, so that the benchmarked epoch is a steady-state one.
    for _ in 0..20 {
        ekf.predict(1.0).expect("valid interval");
        for m in &ms {
            ekf.update_range(m);
        }
    }
    c.bench_function("ekf11 epoch: predict + 12 pseudoranges + 12 rates", |b| {
        b.iter(|| {
            let mut f = ekf.clone();
            f.predict(black_box(1.0)).expect("valid interval");
            for m in &ms {
                black_box(f.update_range(black_box(m)));
            }
            f
        })
    });
    let opts = WlsOptions::default();
    c.bench_function("wls fix: 12 ranges, GPS + BDS clocks", |b| {
        b.iter(|| wls::solve(black_box(&ms), &opts).expect("good geometry"))
    });
}

criterion_group!(benches, bench_fusion);
criterion_main!(benches);
