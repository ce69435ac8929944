//! Benchmarks of the magnetic-landmark hot paths: one DTW match of a landmark window against
//! a library of 63 templates (seven landmarks × nine edge-jittered copies, the size of the
//! survey library in tests/it/landmark.rs), and one SNN classification (phase encoding and
//! seven Tempotron neurons over a 256-point time grid). Both use caller-owned scratch and
//! allocate nothing per call. Also one field evaluation (Earth + 13 dipoles).
//!
//! Run: `cargo bench --bench magnetic -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::TrialRng;
use hybridnav::magnetic::landmark::{
    Candidate, DtwLibrary, DtwScratch, LandmarkFeature, FEATURE_LEN,
};
use hybridnav::magnetic::snn::{SnnClassifier, SnnConfig, SnnScratch};
use hybridnav::magnetic::{EarthField, MagneticAnomalyConfig, MagneticScene};
use nalgebra::Vector3;

/// A landmark-like bipolar curve of shape parameter `k`, with a small deterministic
/// variation `v` standing in for another pass.
fn curve(k: usize, v: usize) -> Vec<f64> {
    (0..48)
        .map(|i| {
            let u = i as f64 / 47.0;
            let a = 2.0 + k as f64;
            let w = 1.0 + 0.03 * v as f64;
            a * (std::f64::consts::TAU * w * u + 0.4 * k as f64).sin()
                * (-4.0 * (u - 0.5).powi(2)).exp()
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("magnetic");
    g.throughput(Throughput::Elements(1));

    let n_labels = 7;
    let mut lib = DtwLibrary::new(n_labels, 4, 0.8).unwrap();
    let mut samples = Vec::new();
    for k in 0..n_labels {
        for v in 0..9 {
            let f = LandmarkFeature::from_samples(&curve(k, v)).unwrap();
            lib.add(k, &f).unwrap();
            samples.push((Some(k), f.image(24.0)));
        }
    }
    let query = LandmarkFeature::from_samples(&curve(3, 4)).unwrap();
    let mut ds = DtwScratch::default();
    let mut out: Vec<Candidate> = Vec::new();
    g.bench_function("dtw_match_window_vs_63_templates", |b| {
        b.iter(|| {
            lib.candidates(black_box(&query), &mut ds, &mut out);
            black_box(out.len())
        })
    });

    let mut rng = TrialRng::new(1, 0).stream("magnetic/snn/train");
    let snn = SnnClassifier::train(&samples, n_labels, &SnnConfig::default(), &mut rng).unwrap();
    let image: [u8; FEATURE_LEN] = query.image(24.0);
    let mut ss = SnnScratch::default();
    g.bench_function("snn_classify_7_neurons", |b| {
        b.iter(|| {
            snn.candidates(black_box(&image), &mut ss, &mut out);
            black_box(out.len())
        })
    });

    let earth = EarthField::from_elements(45_000.0, 45.0, -3.0).unwrap();
    let anomalies: Vec<MagneticAnomalyConfig> = (0..13)
        .map(|i| MagneticAnomalyConfig {
            name: String::new(),
            position_enu_m: [8.0 * i as f64, 1.0, 0.0],
            moment_am2: [10.0, 50.0, -100.0],
            min_distance_m: 0.3,
        })
        .collect();
    let scene = MagneticScene::new(earth, &anomalies).unwrap();
    let x = Vector3::new(37.0, 0.1, 1.2);
    g.bench_function("field_earth_plus_13_dipoles", |b| {
        b.iter(|| black_box(scene.b_enu_nt(black_box(&x))))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
