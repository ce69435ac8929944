//! Monte Carlo throughput: trials per second of each reproduction world, on one and two
//! worker threads (parallel efficiency = the ratio over 2), as `hybridnav run` executes
//! them (rayon pool, trials reduced in order; no files written).
//!
//! Run: `cargo bench --bench montecarlo`. Criterion's "thrpt" line is trials per second.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hybridnav::montecarlo::store::Shard;
use hybridnav::montecarlo::{run_trials, RunOptions};
use hybridnav::world::load_world;
use std::path::Path;
use std::time::Duration;

/// The worlds and the trials per measured batch (fewer for the slow worlds, so that a
/// sample stays around a second).
const WORLDS: [(&str, u64); 7] = [
    ("default", 16),
    ("seed000-kehui", 16),
    ("seed000-beihang", 4),
    ("seed001-pf2d", 16),
    ("seed002-lianhua", 8),
    ("seed003-seamless", 4),
    ("seed004-bupt", 4),
];

fn trials_per_second(c: &mut Criterion) {
    let mut g = c.benchmark_group("trials_per_second");
    g.sample_size(10);
    g.warm_up_time(Duration::from_secs(2));
    g.measurement_time(Duration::from_secs(8));
    for (name, batch) in WORLDS {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("worlds/{name}.toml"));
        let world = load_world(&path).expect("world loads");
        g.throughput(Throughput::Elements(batch));
        for threads in [1usize, 2] {
            // One master seed throughout: the FM survey a world caches per seed is paid in
            // the warm-up, as a long run pays it once (its cost is benchmarked in `fm`).
            let opts = RunOptions {
                trials: batch,
                seed: 1,
                threads,
                progress: false,
                shard: Shard::WHOLE,
            };
            g.bench_with_input(BenchmarkId::new(name, threads), &opts, |b, opts| {
                b.iter(|| run_trials(&world, opts).expect("trials run"))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, trials_per_second);
criterion_main!(benches);
