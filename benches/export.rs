//! Dataset export rates: recording a trial (the simulation with every batch kept) and
//! writing each format from the recording, on the default world (172 s of city driving,
//! GPS + BeiDou at 1 Hz, three estimators) and on seed 000's Kehui world (GNSS, DTMB and
//! a 21-station FM scan every second, five estimators). Throughput is receiver epochs per second.
//!
//! Run: `cargo bench --bench export`. Files go to a temporary directory (the page cache,
//! not the disk, is measured).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::export::{export, record_trial, Format};
use hybridnav::world::load_world;
use std::path::Path;
use std::time::Duration;

fn export_rates(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("hybridnav-bench-export-{}", std::process::id()));
    let mut g = c.benchmark_group("export");
    g.sample_size(10);
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(5));
    for name in ["default", "seed000-kehui"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("worlds/{name}.toml"));
        let world = load_world(&path).expect("world loads");
        let rec = record_trial(&world, 1, 0).expect("trial records");
        let epochs = rec
            .batches
            .iter()
            .filter(|b| b.source == hybridnav::measurement::SourceKind::Gnss)
            .count() as u64;
        g.throughput(Throughput::Elements(epochs));
        g.bench_function(format!("{name}/record"), |b| {
            b.iter(|| record_trial(&world, 1, 0).expect("trial records"));
        });
        for f in Format::ALL {
            // The IQ recording's cost is the DTMB signal model's (benchmarked in `dtmb`).
            if f == Format::Sigmf {
                continue;
            }
            if export(&world, &rec, &[f], false, &dir).is_err() {
                continue;
            }
            g.bench_function(format!("{name}/{f}"), |b| {
                b.iter(|| export(&world, &rec, &[f], false, &dir).expect("export"));
            });
        }
    }
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, export_rates);
criterion_main!(benches);
