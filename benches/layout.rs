//! Benchmarks of `hybridnav layout`: grid points evaluated per second on the default world
//! (Kehui Road: 9 buildings, 2 tree rows, 19 satellites in view, one DTMB tower) at 10 m
//! (79 × 15 = 1185 cells), and one objective evaluation of the placement search (one
//! candidate pair added to every outdoor cell's geometry).
//!
//! * `grid_10m_parallel`: the whole grid with rayon over rows (the command's path).
//! * `grid_10m_one_thread`: the same inside a one-thread pool, the per-core figure.
//! * `objective_pair`: `Problem::score` of one K = 2 placement.
//!
//! Run: `cargo bench --bench layout -- --warm-up-time 1 --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::layout::candidate_site;
use hybridnav::layout::eval::Context;
use hybridnav::layout::grid::{Grid, Region};
use hybridnav::layout::metrics::ClockModel;
use hybridnav::layout::place::{self, Objective};
use std::path::Path;

fn bench_layout(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let world = hybridnav::world::load_world(&root.join("worlds/default.toml")).expect("world");
    let region = Region::of_world(&world).expect("region");
    let grid = Grid::new(region, 10.0, 1, 0).expect("grid");
    let centre = (
        0.5 * (region.west_m + region.east_m),
        0.5 * (region.south_m + region.north_m),
    );
    let ctx = Context::new(&world, &[world.start], ClockModel::Shared, 1.5, centre);
    let mut g = c.benchmark_group("layout");
    g.throughput(Throughput::Elements(grid.cells() as u64));
    g.bench_function("grid_10m_parallel", |b| {
        b.iter(|| black_box(ctx.evaluate(&grid, false)))
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    g.bench_function("grid_10m_one_thread", |b| {
        b.iter(|| one.install(|| black_box(ctx.evaluate(&grid, false))))
    });

    let cands = place::parse_candidates(
        &root.join("tests/data/layout/canyon-candidates.csv"),
        &region,
    )
    .expect("candidates");
    let (cells, base) = ctx.evaluate(&grid, true);
    let considered: Vec<usize> = (0..cells.len()).filter(|&k| !cells[k].indoor).collect();
    let sites: Vec<_> = cands.iter().map(|x| candidate_site(&ctx, x)).collect();
    let rows = ctx.site_rows(&grid, &sites);
    let problem = place::Problem {
        base: &base,
        epochs: 1,
        rows: &rows,
        cells: grid.cells(),
        considered: &considered,
        objective: Objective::Gdop95,
    };
    g.throughput(Throughput::Elements(considered.len() as u64));
    g.bench_function("objective_pair", |b| {
        b.iter(|| black_box(problem.score(&[5, 7])))
    });
    g.finish();
}

criterion_group!(benches, bench_layout);
criterion_main!(benches);
