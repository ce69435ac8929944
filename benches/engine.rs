//! Benchmark of whole trials: the default world (Kehui Road with its buildings: the GNSS
//! source with orbits, light time, atmosphere, tracking noise and every satellite link
//! through the scene, and three estimators over ~172 epochs), and the same world with the
//! scene switched off for the GNSS receiver, so the difference is the cost of the scene.
//!
//! Run: `cargo bench --bench engine -- --warm-up-time 1 --measurement-time 5`.

use criterion::{criterion_group, criterion_main, Criterion};
use hybridnav::world::trial::run_trial;
use hybridnav::world::{load_world, parse_world};
use std::path::Path;

fn trial(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/default.toml");
    let world = load_world(&path).expect("default world loads");
    let text = std::fs::read_to_string(&path).expect("default world reads");
    let open_sky = parse_world(
        &text.replacen(
            "elevation_mask_deg = 10.0",
            "elevation_mask_deg = 10.0\nscene = false",
            1,
        ),
        &path,
    )
    .expect("open-sky variant parses");
    let mut i = 0u64;
    c.bench_function("default_world_trial", |b| {
        b.iter(|| {
            i += 1;
            run_trial(&world, 1, i).expect("trial runs")
        })
    });
    c.bench_function("default_world_trial_without_scene", |b| {
        b.iter(|| {
            i += 1;
            run_trial(&open_sky, 1, i).expect("trial runs")
        })
    });
}

criterion_group!(benches, trial);
criterion_main!(benches);
