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

fn side_by_side_world_text() -> String {
    format!(
        r#"
[world]
name = "gnss iq bench, side by side with gps-sdr-sim"
origin = {{ lat_deg = 40.0, lon_deg = 116.4, h_m = 50.0 }}
start = "2010-07-01T00:00:00 GPST"
ephemeris = "{SIDE_BY_SIDE_NAV}"

[platform]
kind = "car"
trajectory = {{ kind = "static", position_enu_m = [0, 0, 0], duration_s = 60 }}

[sensors.gnss]
systems = ["gps"]
elevation_mask_deg = 0.0

[[estimator]]
name = "WLS"
sources = ["gps"]
filter = "wls"
"#
    )
}

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
        cases.push(("open_sky_10_brdc1820", side_by_side_world_text()));
    } else {
        eprintln!("gnss_iq/open_sky_10_brdc1820: skipped, {SIDE_BY_SIDE_NAV} not found");
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
    gps_sdr_sim_side_by_side(rate);
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
