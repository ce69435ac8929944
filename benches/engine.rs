//! Benchmark of a whole trial of the default world: the GNSS source (orbits, light time,
//! atmosphere, tracking noise) and three estimators over ~184 epochs.
//!
//! Run: `cargo bench --bench engine -- --warm-up-time 1 --measurement-time 5`.

use criterion::{criterion_group, criterion_main, Criterion};
use hybridnav::engine::trial::run_trial;
use hybridnav::world::load_world;
use std::path::Path;

fn trial(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/default.toml");
    let world = load_world(&path).expect("default world loads");
    let mut i = 0u64;
    c.bench_function("default_world_trial", |b| {
        b.iter(|| {
            i += 1;
            run_trial(&world, 1, i).expect("trial runs")
        })
    });
}

criterion_group!(benches, trial);
criterion_main!(benches);
