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

criterion_group!(gnss, benches);
criterion_main!(gnss);
