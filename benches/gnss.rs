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

/// gps-sdr-sim's scenario for the side-by-side case: brdc1820.10n, Beijing (40.0° N,
/// 116.4° E, 50 m), 2010-07-01 00:00:00 GPST, where both simulators put 10 GPS satellites
/// above the horizon (gps-sdr-sim's mask is 0°, so is this world's).
const SIDE_BY_SIDE_NAV: &str = "../shared/data/gnss/brdc1820.10n";

fn side_by_side_world_text(three_paths: bool) -> String {
    let height_m = if three_paths { 1.5 } else { 0.0 };
    let mut text = format!(
        r#"
[world]
name = "gnss iq bench, side by side with gps-sdr-sim"
origin = {{ lat_deg = 40.0, lon_deg = 116.4, h_m = 50.0 }}
start = "2010-07-01T00:00:00 GPST"
ephemeris = "{SIDE_BY_SIDE_NAV}"

[platform]
kind = "car"
trajectory = {{ kind = "static", position_enu_m = [0, 0, {height_m}], duration_s = 60 }}

[sensors.gnss]
systems = ["gps"]
elevation_mask_deg = 0.0

[[estimator]]
name = "WLS"
sources = ["gps"]
filter = "wls"
"#
    );
    if three_paths {
        text.push_str(THREE_PATH_SCENE);
    }
    text
}

/// The side-by-side sky with three paths a satellite: the direct path, the ground's and one
/// wall's. Each wall is a 1 m thick concrete slab 40 m from the antenna (1.5 m up), facing
/// it, on the side opposite its satellite's azimuth and tall enough for the specular point
/// (`h ≥ 1.5 + 40·tan el`); narrow (4 m; 6 m for the three satellites at azimuth 59.5–63.9°,
/// which share one) so that it blocks no other satellite's line of sight. Azimuths and
/// elevations are the 10 satellites' at 2010-07-01 00:00:00 GPST from brdc1820.10n. The
/// ground is very dry soil because on paved ground G21's co-polar ground reflection (at
/// 46°, past the Brewster angle) vanishes. The bench checks that every satellite has
/// exactly three paths at every epoch of the recording.
const THREE_PATH_SCENE: &str = r#"
[scene]
ground = { material = "very_dry" }
# For G26, G15, G27 (az 59.5-63.9, el up to 61.5)
[[scene.buildings]]
footprint_enu_m = [[-33.80, -21.60], [-36.64, -16.32], [-37.52, -16.80], [-34.68, -22.08]]
height_m = 90
material = "concrete"
# For G09 (96.5, 72.6)
[[scene.buildings]]
footprint_enu_m = [[-39.97, 2.54], [-39.52, 6.52], [-40.51, 6.63], [-40.96, 2.65]]
height_m = 145
material = "concrete"
# For G12 (143.9, 9.3)
[[scene.buildings]]
footprint_enu_m = [[-25.18, 31.14], [-21.95, 33.50], [-22.54, 34.31], [-25.77, 31.95]]
height_m = 15
material = "concrete"
# For G14 (260.9, 16.1)
[[scene.buildings]]
footprint_enu_m = [[39.18, 8.30], [39.81, 4.35], [40.80, 4.51], [40.17, 8.46]]
height_m = 20
material = "concrete"
# For G18 (330.4, 76.7)
[[scene.buildings]]
footprint_enu_m = [[21.50, -33.79], [18.02, -35.77], [18.51, -36.64], [21.99, -34.66]]
height_m = 190
material = "concrete"
# For G21 (216.2, 46.1)
[[scene.buildings]]
footprint_enu_m = [[22.01, 33.46], [25.24, 31.10], [25.83, 31.90], [22.60, 34.27]]
height_m = 55
material = "concrete"
# For G22 (308.0, 40.7)
[[scene.buildings]]
footprint_enu_m = [[32.75, -23.05], [30.29, -26.20], [31.08, -26.82], [33.54, -23.67]]
height_m = 45
material = "concrete"
# For G24 (293.8, 40.5)
[[scene.buildings]]
footprint_enu_m = [[37.41, -14.31], [35.79, -17.97], [36.71, -18.38], [38.32, -14.72]]
height_m = 45
material = "concrete"
"#;

/// Samples per second of `gnss iq` at 2.6 Msps ci8 (0.5 s recordings into a sink), open sky
/// and in a street canyon (every path of the scene its own replica), and on the real
/// 2010-07-01 ephemeris with 10 satellites, timed beside gps-sdr-sim when `GPS_SDR_SIM`
/// names its binary.
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
    let mut cases = vec![
        ("open_sky", iq_world_text(false)),
        ("canyon", iq_world_text(true)),
    ];
    if Path::new(SIDE_BY_SIDE_NAV).exists() {
        cases.push(("open_sky_10_brdc1820", side_by_side_world_text(false)));
        cases.push(("three_paths_10_brdc1820", side_by_side_world_text(true)));
    } else {
        eprintln!("gnss_iq/*_10_brdc1820: skipped, {SIDE_BY_SIDE_NAV} not found");
    }
    for (name, text) in cases {
        let w = hybridnav::world::parse_world(&text, Path::new("bench.toml")).expect("bench world");
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
        let record_into = |paths: &mut dyn std::io::Write| {
            let (mut a, mut b) = (std::io::sink(), std::io::sink());
            record(
                &iw,
                &req,
                &sats,
                &mut IqSinks {
                    data: &mut a,
                    truth: &mut b,
                    paths,
                },
            )
            .expect("records")
        };
        let mut paths_csv = Vec::new();
        let s = record_into(&mut paths_csv);
        let paths: usize = s.satellites.iter().map(|a| a.max_paths).sum();
        if name.starts_with("three_paths") {
            assert_three_paths_everywhere(&paths_csv);
        }
        eprintln!(
            "gnss_iq/{name}: {} satellites, {paths} replicas",
            s.satellites.len()
        );
        g.bench_function(name, |b| {
            b.iter(|| black_box(record_into(&mut std::io::sink())))
        });
    }
    g.finish();
    gps_sdr_sim_side_by_side(rate);
}

/// Checks the three-path case measures what it claims: in its paths.csv, every satellite
/// has exactly three paths (direct, ground, wall) at every epoch of the recording.
fn assert_three_paths_everywhere(paths_csv: &[u8]) {
    let text = std::str::from_utf8(paths_csv).expect("paths.csv is UTF-8");
    let mut kinds = std::collections::BTreeMap::<(&str, &str), Vec<&str>>::new();
    for row in text.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        kinds.entry((f[0], f[1])).or_default().push(f[9]);
    }
    let satellites: std::collections::BTreeSet<_> = kinds.keys().map(|k| k.1).collect();
    assert_eq!(satellites.len(), 10, "three-path case: 10 satellites");
    for ((t, sat), k) in &kinds {
        assert_eq!(
            k.len(),
            3,
            "three-path case: {sat} at {t} s has paths {k:?}"
        );
    }
}

/// Times gps-sdr-sim (its binary named by `GPS_SDR_SIM`) on the side-by-side scenario:
/// 10 s at 2.6 Msps, 8-bit I/Q, into /dev/null, five runs; prints the median's samples/s.
/// gps-sdr-sim is one thread, so on an idle machine its wall time is its time on a core.
fn gps_sdr_sim_side_by_side(rate: f64) {
    let Some(bin) = std::env::var_os("GPS_SDR_SIM") else {
        eprintln!("gps-sdr-sim: not timed (set GPS_SDR_SIM to its binary; docs/performance.md)");
        return;
    };
    if !Path::new(SIDE_BY_SIDE_NAV).exists() {
        eprintln!("gps-sdr-sim: not timed, {SIDE_BY_SIDE_NAV} not found");
        return;
    }
    let duration_s = 10.0;
    let mut walls: Vec<f64> = (0..5)
        .map(|_| {
            let t0 = std::time::Instant::now();
            let st = std::process::Command::new(&bin)
                .args(["-e", SIDE_BY_SIDE_NAV, "-l", "40.0,116.4,50"])
                .args(["-t", "2010/07/01,00:00:00", "-d", "10", "-b", "8"])
                .args(["-s", &format!("{rate}"), "-o", "/dev/null"])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .status()
                .expect("run gps-sdr-sim");
            assert!(st.success(), "gps-sdr-sim failed: {st}");
            t0.elapsed().as_secs_f64()
        })
        .collect();
    walls.sort_by(f64::total_cmp);
    let median = walls[2];
    eprintln!(
        "gps-sdr-sim, same scenario, {duration_s} s at {rate} sps, 8-bit: median {median:.3} s \
         ({:.2} M samples/s; runs {walls:.3?})",
        rate * duration_s / median / 1e6
    );
}

/// The baseband alone, as `gnss iq` runs it for one 10 ms segment: `n` replicas (PRNs
/// cycling over 1–10, distinct Dopplers and code phases) added piece by piece, the noise,
/// and the ci8 quantiser. 10 replicas are the open sky of 10 satellites, 30 the same sky
/// with three paths a satellite; their ratio is the issue's "with 3 paths per satellite".
fn baseband_benches(c: &mut Criterion) {
    use hybridnav::core::TrialRng;
    use hybridnav::gnss::signal::baseband::{
        add_noise, CarrierTable, NavSymbols, Quantiser, Replica, ReplicaCursor, SampleFormat,
        PIECE_SAMPLES,
    };
    use hybridnav::gnss::signal::ca_code::ca_code_bits;
    use num_complex::Complex32;
    struct Alternating;
    impl NavSymbols for Alternating {
        fn symbol(&mut self, ms: i64) -> u8 {
            ((ms / 20) & 1) as u8
        }
    }
    let fs = 2.6e6;
    let n = (fs * 0.01) as usize;
    let mut g = c.benchmark_group("gnss_iq_baseband");
    g.throughput(criterion::Throughput::Elements(n as u64));
    let carrier = CarrierTable::default();
    let codes: Vec<Vec<u8>> = (1..=10)
        .map(|p| ca_code_bits(p).expect("PRN").to_vec())
        .collect();
    for replicas in [10usize, 30] {
        let rs: Vec<(usize, Replica)> = (0..replicas)
            .map(|k| {
                let doppler_hz = -4000.0 + 800.0 * (k % 10) as f64 + 3.0 * (k / 10) as f64;
                (
                    k % 10,
                    Replica {
                        amplitude: 0.1 / (1 + k / 10) as f32,
                        ms: 1000 + k as i64,
                        chip: (97.3 * k as f64) % 1023.0,
                        chips_per_sample: 1.023e6 * (1.0 + doppler_hz / 1575.42e6) / fs,
                        phase_cycles: 0.1 * k as f64,
                        cycles_per_sample: doppler_hz / fs,
                    },
                )
            })
            .collect();
        let mut block = vec![Complex32::default(); n];
        let mut cursors: Vec<(usize, ReplicaCursor)> = Vec::with_capacity(replicas);
        let mut bytes: Vec<u8> = Vec::with_capacity(2 * n);
        let mut noise = TrialRng::new(1, 0).stream("bench noise");
        let mut quant = Quantiser::new(SampleFormat::Ci8, 2.0);
        g.bench_function(format!("{replicas}_replicas_10ms"), |b| {
            b.iter(|| {
                block.iter_mut().for_each(|s| *s = Complex32::default());
                cursors.clear();
                for (k, r) in &rs {
                    cursors.push((*k, ReplicaCursor::new(r, 1023, &mut Alternating)));
                }
                for piece in block.chunks_mut(PIECE_SAMPLES) {
                    for (k, cur) in cursors.iter_mut() {
                        cur.add(piece, &codes[*k], &mut Alternating, &carrier);
                    }
                }
                add_noise(&mut block, &mut noise);
                bytes.clear();
                quant.quantise(&block, &mut bytes);
                black_box(bytes.len())
            })
        });
    }
    g.finish();
}

/// The RINEX observation reader on the GEONET file `07590920.05o` (RINEX 2.10, 120
/// epochs, 68 kB) held in memory, in bytes per second, and `gnss position`'s solver on
/// every epoch of it; skipped without `../shared`.
fn obs_benches(c: &mut Criterion) {
    let Some(dir) = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(|p| p.join("shared/data/gnss"))
    else {
        return;
    };
    let (Ok(text), Ok(nav)) = (
        std::fs::read(dir.join("07590920.05o")),
        read_nav_file(&dir.join("07590920.05n")),
    ) else {
        eprintln!("skipped: the GEONET files are not in ../shared");
        return;
    };
    let mut g = c.benchmark_group("rinex_obs");
    g.throughput(criterion::Throughput::Bytes(text.len() as u64));
    g.bench_function("read_geonet_day_hour", |b| {
        b.iter(|| {
            let mut n = 0usize;
            hybridnav::gnss::rinex_obs::read_all(&text, "07590920.05o", |_, e| n += e.len())
                .expect("the GEONET file reads");
            black_box(n)
        })
    });
    let mut epochs = Vec::new();
    let header = hybridnav::gnss::rinex_obs::read_all(&text, "07590920.05o", |_, e| {
        epochs.push(e.clone());
    })
    .expect("the GEONET file reads");
    g.throughput(criterion::Throughput::Elements(epochs.len() as u64));
    g.bench_function("spp_120_epochs", |b| {
        b.iter(|| {
            let mut spp = hybridnav::spp::Spp::new(&nav, &header).expect("C1 present");
            let mut sum = 0.0;
            for e in &epochs {
                sum += spp.solve(e).map_or(0.0, |f| f.pdop);
            }
            black_box(sum)
        })
    });
    g.finish();
}

criterion_group!(gnss, benches, iq_benches, baseband_benches, obs_benches);
criterion_main!(gnss);
