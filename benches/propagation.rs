//! Benchmarks of the propagation hot paths over random cities of 10 to 10 000 buildings:
//!
//! * `sat_ray`: is the ray from a street-level receiver to a satellite (elevation 10–80°,
//!   any azimuth) blocked? One any-hit BVH query.
//! * `street_link`: is the segment from a street-level receiver to a point 50–500 m away
//!   at 1.5–30 m height blocked?
//! * `gnss_link`: the whole [`Scene::link`] for a satellite: direct path with its
//!   obstruction, the ground and every wall reflection within 200 m, both legs checked.
//!
//! The city is a grid of 60 m blocks, one 30–50 m building of 6–60 m height per block,
//! √n blocks a side, so the city's area grows with n at constant density (what a bigger
//! city looks like). Run: `cargo bench --bench propagation -- --warm-up-time 1
//! --measurement-time 3`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use hybridnav::core::TrialRng;
use hybridnav::propagation::{
    BuildingClass, BuildingConfig, Emitter, LinkParams, LinkPaths, Polarisation, Scene,
    SceneConfig, WallMaterial,
};
use nalgebra::Vector3;
use rand::Rng;

fn city(n: usize) -> (Scene, f64) {
    let mut rng = TrialRng::new(42, 0).stream("bench/city");
    let side = (n as f64).sqrt().ceil() as usize;
    let buildings = (0..n)
        .map(|i| {
            let (bx, by) = ((i % side) as f64 * 60.0, (i / side) as f64 * 60.0);
            let w = rng.random_range(30.0..50.0);
            let d = rng.random_range(30.0..50.0);
            let ox = rng.random_range(0.0..(55.0 - w));
            let oy = rng.random_range(0.0..(55.0 - d));
            BuildingConfig {
                footprint_enu_m: vec![
                    [bx + ox, by + oy],
                    [bx + ox + w, by + oy],
                    [bx + ox + w, by + oy + d],
                    [bx + ox, by + oy + d],
                ],
                height_m: rng.random_range(6.0..60.0),
                material: WallMaterial::Concrete,
                class: BuildingClass::Traditional,
            }
        })
        .collect();
    let scene = Scene::new(&SceneConfig {
        buildings,
        ..SceneConfig::default()
    })
    .expect("valid city");
    (scene, side as f64 * 60.0)
}

/// Street-level receivers (outside every building) spread over the city.
fn receivers(scene: &Scene, extent_m: f64, k: usize) -> Vec<Vector3<f64>> {
    let mut rng = TrialRng::new(42, 0).stream("bench/receivers");
    let mut out = Vec::with_capacity(k);
    while out.len() < k {
        let p = Vector3::new(
            rng.random_range(0.0..extent_m),
            rng.random_range(0.0..extent_m),
            1.5,
        );
        if scene.building_at(&p).is_none() {
            out.push(p);
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    const K: usize = 1024;
    let mut group = c.benchmark_group("propagation");
    group.throughput(Throughput::Elements(K as u64));
    for n in [10usize, 100, 1_000, 10_000] {
        let (scene, extent) = city(n);
        let rx = receivers(&scene, extent, K);
        let mut rng = TrialRng::new(42, 0).stream("bench/rays");
        let sats: Vec<Vector3<f64>> = (0..K)
            .map(|_| {
                let e: f64 = rng.random_range(10f64..80.0).to_radians();
                let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                Vector3::new(e.cos() * a.sin(), e.cos() * a.cos(), e.sin())
            })
            .collect();
        let far: Vec<Vector3<f64>> = rx
            .iter()
            .zip(&sats)
            .map(|(r, u)| scene.far_end(r, &Emitter::Direction(*u)))
            .collect();
        let street: Vec<Vector3<f64>> = rx
            .iter()
            .map(|r| {
                let d = rng.random_range(50.0..500.0);
                let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                r + Vector3::new(d * a.sin(), d * a.cos(), rng.random_range(0.0..28.5))
            })
            .collect();
        group.bench_function(format!("sat_ray/{n}"), |b| {
            b.iter(|| {
                rx.iter()
                    .zip(&far)
                    .filter(|(r, f)| scene.segment_blocked(r, f))
                    .count()
            })
        });
        group.bench_function(format!("street_link/{n}"), |b| {
            b.iter(|| {
                rx.iter()
                    .zip(&street)
                    .filter(|(r, t)| scene.segment_blocked(r, t))
                    .count()
            })
        });
        let params = LinkParams {
            freq_hz: 1.575_42e9,
            polarisation: Polarisation::Rhcp,
            rx_vel_enu_mps: Vector3::new(1.0, 0.5, 0.0),
        };
        let mut out = LinkPaths::new();
        group.bench_function(format!("gnss_link/{n}"), |b| {
            b.iter(|| {
                let mut paths = 0usize;
                for (r, u) in rx.iter().zip(&sats) {
                    scene
                        .link(r, &Emitter::Direction(*u), &params, &mut out)
                        .expect("finite input");
                    paths += out.paths().len();
                }
                black_box(paths)
            })
        });
    }
    group.finish();
}

/// The DLL's lock point on a four-path channel (direct, ground, two walls): with one
/// Doppler (the static discriminator |C|²) and with the walls' Dopplers differing, where
/// every cross term is weighed by the loop's response (O(N²) per evaluation).
fn dll(c: &mut Criterion) {
    use hybridnav::gnss::multipath::dll_lock;
    use hybridnav::propagation::{Path, PathKind};
    const CHIP_M: f64 = 293.052_256;
    let path = |kind, delay_m: f64, amplitude, phase_rad, doppler_hz| Path {
        kind,
        excess_delay_s: delay_m / hybridnav::core::C_MPS,
        amplitude,
        phase_rad,
        doppler_hz,
        arrival_enu: Vector3::z(),
    };
    let mut group = c.benchmark_group("dll_lock");
    for (name, f_wall_hz) in [
        ("four_paths_one_doppler", 0.0),
        ("four_paths_rotating", 9.0),
    ] {
        let paths = [
            path(PathKind::Direct, 0.0, 1.0, 0.0, 0.0),
            path(PathKind::Ground, 2.9, 0.3, 1.1, 0.0),
            path(PathKind::Wall { building: 0 }, 60.0, 0.2, -0.7, f_wall_hz),
            path(PathKind::Wall { building: 1 }, 120.0, 0.1, 2.5, -f_wall_hz),
        ];
        group.bench_function(name, |b| {
            b.iter(|| dll_lock(black_box(&paths), CHIP_M, 0.5, 2.0))
        });
    }
    group.finish();
}

criterion_group!(benches, bench, dll);
criterion_main!(benches);
