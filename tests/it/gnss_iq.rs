//! `hybridnav gnss iq` against an independent receiver: GNSS-SDR (Debian `gnss-sdr`)
//! acquires, tracks and decodes hybridnav's GPS L1 C/A recording of an open-sky world
//! (the ESBC00DNK station with its own broadcast navigation file of 2020-06-25) and
//! positions from it; its fixes are compared with the recording's truth.csv. Bad requests
//! are refused before any file is written.

use crate::common::{hybridnav, refused, skip, stderr, tmp_dir};
use hybridnav::core::Geodetic;
use std::process::Command;

const WORLD: &str = "worlds/gnss-iq-open-sky.toml";

/// GNSS-SDR's configuration for an interleaved 8-bit recording at `rate` of GPS L1 C/A:
/// file source, no filtering, 8 channels, PCPS acquisition, DLL/PLL tracking, the LNAV
/// decoder and RTKLIB single-point positioning with the broadcast ionosphere (the
/// package's own example configurations, reduced to what a file needs).
///
/// Acquisition sums four 1 ms dwells non-coherently at a false-alarm probability of 10⁻³.
/// With the package examples' single dwell at 10⁻², a 39.7 dB-Hz satellite has a coherent
/// SNR of C/N0·1 ms ≈ 9.7 dB, detected with a probability of roughly 0.1–0.2 per search,
/// while each false alarm holds a channel for ~15 s: on one CI machine G05 (39.7 dB-Hz) was
/// never acquired in 120 s, and here it took 44 s after two false alarms. Four dwells
/// acquire every satellite within 5 s of it being in view, with no false alarm, on both
/// machines (docs/validation.md).
fn gps_conf(data: &str, rate: f64, out: &str) -> String {
    format!(
        "[GNSS-SDR]
GNSS-SDR.internal_fs_sps={rate}
SignalSource.implementation=File_Signal_Source
SignalSource.filename={data}
SignalSource.item_type=ibyte
SignalSource.sampling_frequency={rate}
SignalSource.samples=0
SignalSource.repeat=false
SignalSource.enable_throttle_control=false
SignalConditioner.implementation=Signal_Conditioner
DataTypeAdapter.implementation=Ibyte_To_Complex
InputFilter.implementation=Pass_Through
InputFilter.item_type=gr_complex
Resampler.implementation=Pass_Through
Resampler.item_type=gr_complex
Channels_1C.count=8
Channels.in_acquisition=1
Channel.signal=1C
Acquisition_1C.implementation=GPS_L1_CA_PCPS_Acquisition
Acquisition_1C.item_type=gr_complex
Acquisition_1C.coherent_integration_time_ms=1
Acquisition_1C.max_dwells=4
Acquisition_1C.pfa=0.001
Acquisition_1C.doppler_max=5000
Acquisition_1C.doppler_step=250
Tracking_1C.implementation=GPS_L1_CA_DLL_PLL_Tracking
Tracking_1C.item_type=gr_complex
Tracking_1C.pll_bw_hz=30.0
Tracking_1C.dll_bw_hz=2.0
Tracking_1C.early_late_space_chips=0.5
TelemetryDecoder_1C.implementation=GPS_L1_CA_Telemetry_Decoder
Observables.implementation=Hybrid_Observables
PVT.implementation=RTKLIB_PVT
PVT.positioning_mode=Single
PVT.iono_model=Broadcast
PVT.trop_model=Saastamoinen
PVT.output_rate_ms=1000
PVT.display_rate_ms=1000
PVT.output_path={out}
PVT.flag_rtcm_server=false
PVT.dump=false
"
    )
}

/// The fixes GNSS-SDR prints: `Position at … is Lat = X [deg], Long = Y [deg], Height = Z [m]`.
fn fixes(log: &str) -> Vec<Geodetic> {
    let num = |s: &str, key: &str| -> Option<f64> {
        let i = s.find(key)? + key.len();
        s[i..].split_whitespace().next()?.parse().ok()
    };
    log.lines()
        .filter(|l| l.contains("Position at"))
        .filter_map(|l| {
            Some(Geodetic::from_deg(
                num(l, "Lat = ")?,
                num(l, "Long = ")?,
                num(l, "Height = ")?,
            ))
        })
        .collect()
}

#[test]
fn gnss_iq_gps_l1ca_is_positioned_by_gnss_sdr_in_open_sky() {
    if Command::new("gnss-sdr").arg("--version").output().is_err() {
        skip("gnss-sdr not installed (Debian package gnss-sdr; .ci/install-gnss-sdr)");
        return;
    }
    let d = tmp_dir("gnss-iq-gps");
    let base = d.join("gps");
    let rate = 2.6e6;
    // 120 s: the first subframe 1 starts 12 s in (after acquisition), so an ephemeris is
    // complete after ~30 s and GNSS-SDR's fixes run at 1 Hz from there. A channel that
    // loses lock waits for the next subframes 1–3 (30 s more), and G17 rises 74 s in, so
    // the recording lasts long enough for every satellite's ephemeris to be decoded.
    let o = hybridnav(&[
        "gnss",
        "iq",
        WORLD,
        "--signal",
        "gps-l1ca",
        "--duration-s",
        "120",
        "--rate-sps",
        "2.6e6",
        "--format",
        "ci8",
        "--out",
        base.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "gnss iq failed: {}", stderr(&o));
    let meta = std::fs::read_to_string(d.join("gps.sigmf-meta")).expect("meta");
    let meta: serde_json::Value = serde_json::from_str(&meta).expect("meta is JSON");
    assert_eq!(meta["captures"][0]["core:frequency"], 1_575.42e6);
    assert_eq!(meta["global"]["core:datatype"], "ci8");
    let sats = meta["annotations"].as_array().expect("annotations");
    assert!(sats.len() >= 5, "{} satellites in view", sats.len());
    let data_len = std::fs::metadata(d.join("gps.sigmf-data"))
        .expect("data")
        .len();
    assert_eq!(data_len, 2 * 120 * 2_600_000);

    let conf = d.join("gps.conf");
    std::fs::write(
        &conf,
        gps_conf(
            d.join("gps.sigmf-data").to_str().expect("utf-8"),
            rate,
            d.to_str().expect("utf-8"),
        ),
    )
    .expect("write conf");
    let t0 = std::time::Instant::now();
    let run = Command::new("gnss-sdr")
        .arg(format!("--config_file={}", conf.display()))
        .arg(format!("--log_dir={}", d.display()))
        .current_dir(&d)
        .output()
        .expect("run gnss-sdr");
    let log = String::from_utf8_lossy(&run.stdout);
    eprintln!("gnss-sdr took {:.1} s", t0.elapsed().as_secs_f64());

    // Every satellite in the recording is tracked and its message decoded.
    for s in sats {
        let prn = s["hybridnav:prn"].as_u64().expect("prn");
        assert!(
            log.contains(&format!("GPS PRN {prn:02} ")),
            "G{prn:02} was never acquired:\n{log}"
        );
    }
    assert!(
        log.contains("subframe 2") && log.contains("subframe 3"),
        "no ephemeris subframes decoded:\n{log}"
    );

    // The truth: a static antenna, every row the same point.
    let truth = std::fs::read_to_string(d.join("gps.truth.csv")).expect("truth");
    let mut rows = truth.lines();
    assert_eq!(rows.next(), Some("t_gpst_s,x_m,y_m,z_m"));
    let first: Vec<f64> = rows
        .next()
        .expect("a truth row")
        .split(',')
        .map(|v| v.parse().expect("number"))
        .collect();
    let truth_ecef = nalgebra::Vector3::new(first[1], first[2], first[3]);

    let fixes = fixes(&log);
    assert!(fixes.len() >= 10, "{} fixes:\n{log}", fixes.len());
    let errors: Vec<f64> = fixes
        .iter()
        .map(|g| (g.to_ecef() - truth_ecef).norm())
        .collect();
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    eprintln!(
        "GNSS-SDR on hybridnav GPS L1 C/A: {} fixes, mean 3-D error {mean:.2} m, max {:.2} m",
        errors.len(),
        errors.iter().cloned().fold(0.0, f64::max)
    );
    // The goal: within 15 m mean 3-D error over every fix (the anchor, gps-sdr-sim's
    // static scenario through GNSS-SDR, gave 8.5 m). Once every ephemeris is decoded, the
    // fixes of the last 30 s stay within 10 m.
    assert!(mean <= 15.0, "mean 3-D error {mean:.2} m: {errors:?}");
    let tail = &errors[errors.len().saturating_sub(30)..];
    let tail_mean = tail.iter().sum::<f64>() / tail.len() as f64;
    eprintln!("last {} fixes: mean 3-D error {tail_mean:.2} m", tail.len());
    assert!(
        tail_mean <= 10.0,
        "last {} fixes: mean 3-D error {tail_mean:.2} m: {tail:?}",
        tail.len()
    );
}

#[test]
fn gnss_iq_refuses_bad_requests_before_writing() {
    let d = tmp_dir("gnss-iq-bad");
    let base = d.join("bad");
    let b = base.to_str().expect("utf-8");
    let args = |extra: &[&'static str]| -> Vec<String> {
        let mut v: Vec<String> = ["gnss", "iq", WORLD, "--out", b]
            .iter()
            .map(|s| s.to_string())
            .collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let run = |extra: &[&'static str], needles: &[&str]| {
        let a = args(extra);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        refused(&a, needles);
        assert!(
            std::fs::read_dir(&d).expect("dir").next().is_none(),
            "{extra:?} left files behind"
        );
    };
    run(
        &["--signal", "gal-e1", "--duration-s", "1"],
        &["--signal", "gal-e1", "gps-l1ca"],
    );
    // Below twice the 1.023 Mchip/s chip rate (and twice 2.046 for B1I).
    run(
        &[
            "--signal",
            "gps-l1ca",
            "--duration-s",
            "1",
            "--rate-sps",
            "2.0e6",
        ],
        &["--rate-sps", "twice"],
    );
    run(
        &[
            "--signal",
            "bds-b1i",
            "--duration-s",
            "1",
            "--rate-sps",
            "4.0e6",
        ],
        &["--rate-sps", "twice"],
    );
    // Past the world's 600 s.
    run(
        &["--signal", "gps-l1ca", "--duration-s", "700"],
        &["--duration-s", "600"],
    );
    run(
        &[
            "--signal",
            "gps-l1ca",
            "--duration-s",
            "1",
            "--format",
            "cu4",
        ],
        &["--format", "cu4"],
    );
}

/// GNSS-SDR's BeiDou B1I configuration: as [`gps_conf`] with the B1 blocks (and the same
/// four-dwell acquisition, which also acquires the 38 dB-Hz C07, C11 and C28), and one
/// channel assigned to each PRN of the recording's annotations (a warm start: GNSS-SDR
/// otherwise searches all 63 PRNs one channel at a time).
fn bds_conf(data: &str, rate: f64, out: &str, prns: &[u64]) -> String {
    let mut c = format!(
        "[GNSS-SDR]
GNSS-SDR.internal_fs_sps={rate}
SignalSource.implementation=File_Signal_Source
SignalSource.filename={data}
SignalSource.item_type=ibyte
SignalSource.sampling_frequency={rate}
SignalSource.samples=0
SignalSource.repeat=false
SignalSource.enable_throttle_control=false
SignalConditioner.implementation=Signal_Conditioner
DataTypeAdapter.implementation=Ibyte_To_Complex
InputFilter.implementation=Pass_Through
InputFilter.item_type=gr_complex
Resampler.implementation=Pass_Through
Resampler.item_type=gr_complex
Channels_B1.count={}
Channels.in_acquisition=1
Channel.signal=B1
Acquisition_B1.implementation=BEIDOU_B1I_PCPS_Acquisition
Acquisition_B1.item_type=gr_complex
Acquisition_B1.coherent_integration_time_ms=1
Acquisition_B1.max_dwells=4
Acquisition_B1.pfa=0.001
Acquisition_B1.doppler_max=5000
Acquisition_B1.doppler_step=250
Tracking_B1.implementation=BEIDOU_B1I_DLL_PLL_Tracking
Tracking_B1.item_type=gr_complex
Tracking_B1.pll_bw_hz=30.0
Tracking_B1.dll_bw_hz=2.0
TelemetryDecoder_B1.implementation=BEIDOU_B1I_Telemetry_Decoder
Observables.implementation=Hybrid_Observables
PVT.implementation=RTKLIB_PVT
PVT.positioning_mode=Single
PVT.iono_model=OFF
PVT.trop_model=Saastamoinen
PVT.output_rate_ms=1000
PVT.display_rate_ms=1000
PVT.output_path={out}
PVT.flag_rtcm_server=false
PVT.dump=false
",
        prns.len()
    );
    for (i, p) in prns.iter().enumerate() {
        c.push_str(&format!("Channel{i}.satellite={p}\n"));
    }
    c
}

/// BeiDou B1I (D1, MEO/IGSO) through GNSS-SDR. Not every satellite is acquired (see
/// docs/validation.md: C36 and C37 never are, the 38 dB-Hz ones rarely), so this asserts
/// the fix, from the four or more whose D1 ephemerides GNSS-SDR decodes.
#[test]
fn gnss_iq_bds_b1i_is_positioned_by_gnss_sdr_in_open_sky() {
    if Command::new("gnss-sdr").arg("--version").output().is_err() {
        skip("gnss-sdr not installed (Debian package gnss-sdr; .ci/install-gnss-sdr)");
        return;
    }
    let d = tmp_dir("gnss-iq-bds");
    let base = d.join("bds");
    // 90 s: BDT subframe 1 starts 26 s in, the ephemeris is complete ~44 s in.
    let o = hybridnav(&[
        "gnss",
        "iq",
        WORLD,
        "--signal",
        "bds-b1i",
        "--duration-s",
        "90",
        "--rate-sps",
        "4.2e6",
        "--format",
        "ci8",
        "--out",
        base.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "gnss iq failed: {}", stderr(&o));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("bds.sigmf-meta")).expect("meta"))
            .expect("meta is JSON");
    assert_eq!(meta["captures"][0]["core:frequency"], 1_561.098e6);
    let prns: Vec<u64> = meta["annotations"]
        .as_array()
        .expect("annotations")
        .iter()
        .map(|a| a["hybridnav:prn"].as_u64().expect("prn"))
        .collect();
    let conf = d.join("bds.conf");
    std::fs::write(
        &conf,
        bds_conf(
            d.join("bds.sigmf-data").to_str().expect("utf-8"),
            4.2e6,
            d.to_str().expect("utf-8"),
            &prns,
        ),
    )
    .expect("write conf");
    let run = Command::new("gnss-sdr")
        .arg(format!("--config_file={}", conf.display()))
        .arg(format!("--log_dir={}", d.display()))
        .current_dir(&d)
        .output()
        .expect("run gnss-sdr");
    let log = String::from_utf8_lossy(&run.stdout);
    let decoded = log
        .lines()
        .filter(|l| l.contains("New BEIDOU B1I DNAV message") && l.contains("ephemeris"))
        .count();
    assert!(decoded >= 4, "{decoded} D1 ephemerides decoded:\n{log}");
    let truth = std::fs::read_to_string(d.join("bds.truth.csv")).expect("truth");
    let first: Vec<f64> = truth
        .lines()
        .nth(1)
        .expect("a truth row")
        .split(',')
        .map(|v| v.parse().expect("number"))
        .collect();
    let truth_ecef = nalgebra::Vector3::new(first[1], first[2], first[3]);
    let errors: Vec<f64> = fixes(&log)
        .iter()
        .map(|g| (g.to_ecef() - truth_ecef).norm())
        .collect();
    assert!(errors.len() >= 10, "{} fixes:\n{log}", errors.len());
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    eprintln!(
        "GNSS-SDR on hybridnav BeiDou B1I: {} fixes, mean 3-D error {mean:.2} m",
        errors.len()
    );
    // The goal: within 15 m mean 3-D error over every fix (the anchor, gps-sdr-sim's
    // static scenario through GNSS-SDR, gave 8.5 m). Once every ephemeris is decoded, the
    // fixes of the last 30 s stay within 10 m.
    assert!(mean <= 15.0, "mean 3-D error {mean:.2} m: {errors:?}");
    let tail = &errors[errors.len().saturating_sub(30)..];
    let tail_mean = tail.iter().sum::<f64>() / tail.len() as f64;
    eprintln!("last {} fixes: mean 3-D error {tail_mean:.2} m", tail.len());
    assert!(
        tail_mean <= 10.0,
        "last {} fixes: mean 3-D error {tail_mean:.2} m: {tail:?}",
        tail.len()
    );
}
