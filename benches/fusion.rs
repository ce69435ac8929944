//! Benchmarks of the fusion hot paths: one EKF epoch (predict, then 12 pseudoranges each
//! with a range rate, i.e. 24 sequential scalar updates) and one 12-range WLS fix.
//!
//! Run: `cargo bench --bench fusion -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hybridnav::core::{EmitterId, EnuFrame, Geodetic, System};
use hybridnav::fusion::ekf11::{Ekf11, Ekf11Config};
use hybridnav::fusion::measurement::RangeMeasurement;
use hybridnav::fusion::wls::{self, WlsOptions};
use nalgebra::Vector3;

/// Twelve emitters (8 GPS, 4 BDS) spread over the sky of a Beijing receiver, with their
/// true pseudoranges and range rates for a receiver at rest with zero clock.
fn scene() -> (Vector3<f64>, Vec<RangeMeasurement>) {
    let frame = EnuFrame::new(Geodetic::from_deg(39.98, 116.35, 60.0));
    let r = frame.origin_ecef();
    let ms = (0..12)
        .map(|i| {
            let az = (i as f64 * 30.0 + 7.0).to_radians();
            let el = (15.0 + (i * 37 % 70) as f64).to_radians();
            let u = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
            let p = frame.ecef_of_enu(&(u * 20_200e3));
            // A tangential velocity of GPS magnitude.
            let v = frame.ecef_vector_of_enu(&Vector3::new(-u.y, u.x, 0.0).normalize()) * 3_874.0;
            let los = (p - r).normalize();
            let system = if i < 8 { System::Gps } else { System::Bds };
            RangeMeasurement {
                emitter: EmitterId::new(system, i as u16 + 1),
                emitter_pos_ecef_m: p,
                emitter_vel_ecef_mps: v,
                pseudorange_m: (p - r).norm(),
                sigma_m: 3.0,
                range_rate_mps: Some(los.dot(&v)),
                sigma_rate_mps: 0.05,
                cn0_dbhz: 45.0,
                elevation_rad: el,
            }
        })
        .collect();
    (r, ms)
}

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
