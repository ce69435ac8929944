//! FM fingerprinting benchmarks: one WKNN query over seed 000's 16 640 RPs × 21 channels
//! (unconstrained, and inside a 30 m constraint circle), and ordinary kriging of 282
//! surveyed RPs onto the 16 640-point 3 m grid (variogram fit + LU solve + prediction)
//! for one channel and for all 21.
//!
//! `cargo bench --bench fm -- --warm-up-time 1 --measurement-time 3`; figures in
//! docs/performance.md, section "FM fingerprinting".

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hybridnav::core::{EnuFrame, Geodetic, TrialRng};
use hybridnav::fm::database::ChannelInfo;
use hybridnav::fm::field::synthesize_stations;
use hybridnav::fm::kriging::{fit_best, krige_channels, FitOptions};
use hybridnav::fm::survey::survey;
use hybridnav::fm::wknn::locate;
use hybridnav::fm::*;
use nalgebra::Vector3;
use rand::Rng;

const SEED: u64 = 2018;

fn setup() -> (EnuFrame, FmField) {
    let frame = EnuFrame::new(Geodetic::from_deg(39.98070, 116.34680, 45.0));
    let tower = frame.enu_of_ecef(&Geodetic::from_deg(39.9205, 116.3004, 300.0).to_ecef());
    let declared = [("F01", 97.4e6), ("F02", 103.9e6), ("F03", 106.1e6)]
        .map(|(id, f)| FmStation::new(id, tower, f, 40.0, 0.0))
        .to_vec();
    let stations = synthesize_stations(&declared, 21, SEED);
    let field = FmField::new(FmFieldConfig::default(), stations, None, SEED).unwrap();
    (frame, field)
}

fn bench(c: &mut Criterion) {
    let (frame, mut field) = setup();
    let grid = grid_points([-192.0, -195.0], [189.0, 192.0], 3.0).unwrap();
    assert_eq!(grid.len(), 16_640);
    let mut rng = TrialRng::new(SEED, 0).stream("bench/fm/survey");
    let fp = survey(&mut field, &grid, 1.2, &SurveyConfig::default(), &mut rng).unwrap();
    let channels: Vec<ChannelInfo> = field
        .stations()
        .iter()
        .map(|s| ChannelInfo {
            id: s.id.clone(),
            freq_hz: s.freq_hz,
        })
        .collect();
    let tag = WorldTag::new("bench", &frame, None);
    let db = FingerprintDb::new(
        tag,
        &frame,
        channels,
        grid.iter().map(|p| [p[0], p[1], 1.2]).collect(),
        fp,
    )
    .unwrap();
    let mut scan = vec![0.0; 21];
    field.scan(&Vector3::new(10.0, -20.0, 1.2), &mut rng, &mut scan);
    let cfg = WknnConfig::default();
    let mut scratch = WknnScratch::new(cfg.k);

    let mut g = c.benchmark_group("fm_wknn_16640x21");
    g.bench_function("unconstrained", |b| {
        b.iter(|| {
            locate(
                &db,
                black_box(&scan),
                &cfg,
                None,
                NoRpPolicy::Unconstrained,
                &mut scratch,
            )
            .unwrap()
        })
    });
    let circle = Constraint {
        centre_en_m: [5.0, -15.0],
        radius_m: 30.0,
    };
    g.bench_function("circle_30m", |b| {
        b.iter(|| {
            locate(
                &db,
                black_box(&scan),
                &cfg,
                Some(&circle),
                NoRpPolicy::Unconstrained,
                &mut scratch,
            )
            .unwrap()
        })
    });
    g.finish();

    // 282 surveyed RPs at random places over the same area.
    let mut prng = TrialRng::new(SEED, 0).stream("bench/fm/rp282");
    let rps: Vec<[f64; 2]> = (0..282)
        .map(|_| {
            [
                -192.0 + 381.0 * prng.random::<f64>(),
                -195.0 + 387.0 * prng.random::<f64>(),
            ]
        })
        .collect();
    let surveyed = survey(&mut field, &rps, 1.2, &SurveyConfig::default(), &mut prng).unwrap();
    let z0: Vec<f64> = (0..282).map(|i| surveyed[i * 21]).collect();
    let opts = FitOptions::default();
    let mut out = vec![0.0; grid.len()];
    let mut g = c.benchmark_group("fm_kriging_282_to_16640");
    g.sample_size(10);
    g.bench_function("one_channel_fit_solve_predict", |b| {
        b.iter(|| {
            let (fit, _) = fit_best(&rps, black_box(&z0), &opts).unwrap();
            let ok = OrdinaryKriging::new(&rps, &z0, fit.model).unwrap();
            ok.predict_many(&grid, &mut out);
            out[0]
        })
    });
    g.bench_function("21_channels", |b| {
        b.iter(|| {
            krige_channels(&rps, black_box(&surveyed), 21, &grid, &opts, 10)
                .unwrap()
                .0
                .len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
