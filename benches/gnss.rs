//! Benchmarks of the broadcast-orbit hot path: `Ephemeris::state` for a GPS satellite and
//! a BeiDou GEO (which adds two rotations), and `NavData::select`.
//!
//! The ephemerides come from the shared brdc1820.10n / ESBC00DNK files when present (so
//! the numbers reflect real elements), otherwise from the synthetic nominal constellation.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hybridnav::core::{EmitterId, GpsTime, System};
use hybridnav::gnss::ephemeris::Ephemeris;
use hybridnav::gnss::rinex_nav::{read_nav_file, NavData};
use hybridnav::gnss::synth::{default_klobuchar, synth_nav};
use std::path::Path;

/// Real navigation data if available, else two days of the synthetic constellation.
fn nav_data() -> (NavData, &'static str) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(|p| p.join("shared/data/gnss"));
    if let Some(dir) = dir {
        if let (Ok(gps), Ok(mixed)) = (
            read_nav_file(&dir.join("brdc1820.10n")),
            read_nav_file(&dir.join("ESBC00DNK_R_20201770000_01D_MN.rnx")),
        ) {
            let mut all = gps.ephemerides;
            all.extend(mixed.ephemerides);
            return (
                NavData::new(all, gps.klobuchar, gps.leap_seconds),
                "brdc1820.10n + ESBC00DNK",
            );
        }
    }
    let start = GpsTime::parse_iso("2018-06-01T00:00:00").unwrap_or_default();
    (
        NavData::new(
            synth_nav(start, 48.0, 2.0),
            Some(default_klobuchar()),
            Some(18),
        ),
        "synthetic",
    )
}

fn pick(nav: &NavData, system: System, geo: bool) -> Option<Ephemeris> {
    nav.ephemerides
        .iter()
        .find(|e| e.sat.system == system && e.is_bds_geo() == geo && e.is_healthy())
        .cloned()
}

fn benches(c: &mut Criterion) {
    let (nav, source) = nav_data();
    eprintln!(
        "ephemerides from {source}: {} records",
        nav.ephemerides.len()
    );
    let gps = pick(&nav, System::Gps, false);
    let geo = pick(&nav, System::Bds, true);
    let mut group = c.benchmark_group("sat_state");
    for (name, eph) in [("gps", gps), ("bds_geo", geo)] {
        let Some(eph) = eph else { continue };
        let t = eph.toe.add_seconds(1234.5);
        group.bench_function(name, |b| b.iter(|| black_box(&eph).state(black_box(t))));
    }
    group.finish();

    let sats: Vec<EmitterId> = nav.satellites();
    let t = nav
        .ephemerides
        .first()
        .map(|e| e.toe.add_seconds(3000.0))
        .unwrap_or_default();
    let g05 = EmitterId::new(System::Gps, 5);
    c.bench_function("nav_select/one", |b| {
        b.iter(|| nav.select(black_box(g05), black_box(t)))
    });
    c.bench_function("nav_select/all_sats", |b| {
        b.iter(|| {
            sats.iter()
                .filter(|s| nav.select(**s, black_box(t)).is_some())
                .count()
        })
    });
}

/// A static receiver under the builtin nominal constellation (2018-06-01 04:00 GPST,
/// Beijing), with or without the default world's street scene around it.
fn iq_world_text(scene: bool) -> String {
    let mut text = String::from(
        r#"
[world]
name = "gnss iq bench"
origin = { lat_deg = 40.0047, lon_deg = 116.3969, h_m = 45.0 }
start = "2018-06-01T04:00:00 GPST"
ephemeris = "builtin:nominal-gps-bds"

[platform]
kind = "car"
trajectory = { kind = "static", position_enu_m = [230, 0, 1.5], duration_s = 60 }

[sensors.gnss]
systems = ["gps"]
elevation_mask_deg = 5.0

[[estimator]]
name = "WLS"
sources = ["gps"]
filter = "wls"
"#,
    );
    if scene {
        // The default world's first canyon: glass to the north, concrete to the south.
        text.push_str(
            r#"
[scene]
ground = { material = "paved" }
[[scene.buildings]]
footprint_enu_m = [[130, -18], [200, -18], [200, -45], [130, -45]]
height_m = 62
material = "concrete"
[[scene.buildings]]
footprint_enu_m = [[220, -20], [320, -20], [320, -48], [220, -48]]
height_m = 58
material = "concrete"
[[scene.buildings]]
footprint_enu_m = [[125, 26], [320, 26], [320, 60], [125, 60]]
height_m = 45
material = "glass"
"#,
        );
    }
    text
}

/// Samples per second of `gnss iq` at 2.6 Msps ci8 (0.5 s recordings into a sink), open sky
/// and in a street canyon (every path of the scene its own replica).
fn iq_benches(c: &mut Criterion) {
    use hybridnav::core::TrialRng;
    use hybridnav::gnss::link::Signal;
    use hybridnav::gnss::signal::baseband::SampleFormat;
    use hybridnav::gnss::signal::scenario::{record, validate, IqRequest, IqSinks, IqWorld};
    let mut g = c.benchmark_group("gnss_iq");
    g.sample_size(10);
    let rate = 2.6e6;
    let duration_s = 0.5;
    g.throughput(criterion::Throughput::Elements((rate * duration_s) as u64));
    for (name, scene) in [("open_sky", false), ("canyon", true)] {
        let w = hybridnav::world::parse_world(&iq_world_text(scene), Path::new("bench.toml"))
            .expect("bench world");
        let rng = TrialRng::new(1, 0);
        let trajectory = w.build_trajectory(&rng).expect("trajectory");
        let clock = w.receiver_clock(&rng);
        let gnss = w.file.sensors.gnss.clone().unwrap_or_default();
        let iw = IqWorld {
            nav: std::sync::Arc::clone(&w.nav),
            start: w.start,
            frame: &w.frame,
            trajectory: trajectory.as_ref(),
            clock: &clock,
            scene: w.scene.as_deref(),
            gnss: &gnss,
            rng,
            duration_s: w.duration_s,
            leap_seconds: 18,
        };
        let req = IqRequest {
            signal: Signal::GpsL1Ca,
            from_s: 0.0,
            duration_s,
            rate_sps: rate,
            format: SampleFormat::Ci8,
        };
        let sats = validate(&iw, &req).expect("valid request");
        let run = || {
            let (mut a, mut b, mut c) = (std::io::sink(), std::io::sink(), std::io::sink());
            record(
                &iw,
                &req,
                &sats,
                &mut IqSinks {
                    data: &mut a,
                    truth: &mut b,
                    paths: &mut c,
                },
            )
            .expect("records")
        };
        let s = run();
        let paths: usize = s.satellites.iter().map(|a| a.max_paths).sum();
        eprintln!(
            "gnss_iq/{name}: {} satellites, {paths} replicas",
            s.satellites.len()
        );
        g.bench_function(name, |b| b.iter(|| black_box(run())));
    }
    g.finish();
}

criterion_group!(gnss, benches, iq_benches);
criterion_main!(gnss);
