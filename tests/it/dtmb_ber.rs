//! `hybridnav dtmb ber --world`: the GB 20600 data layer through a world tower's
//! multipath, received with an estimated (or the true) channel.

use crate::common::{hybridnav, refused, repo, tmp_dir};
use hybridnav::dtmb::ber_channel::{
    doppler_responses, impulse_response, measure_channel_point, ChannelBer, Csi,
};
use hybridnav::dtmb::data_layer::Profile;
use hybridnav::dtmb::frame::CarrierMode;
use hybridnav::dtmb::ldpc::CodeRate;
use hybridnav::dtmb::mapping::Constellation;
use hybridnav::world::dtmb_iq::{tower_channel_at, DataLayerOverride, WorldIqRequest};

/// The Kehui Road world's tower D01 at 5 s of trial 0 — the recording that dtmb-sdr
/// decodes without a wrong packet in `dtmb_ts_a_world_tower_carries_its_payload_through_the_scene`
/// (16QAM 0.6 M240) — measured here at its own link-budget SNR (the SNR `dtmb iq --world`
/// annotates on that frame, compared) with the estimating receiver: 20 frames after the
/// interleaver delay, no packet wrong, as dtmb-sdr found; and at 5 dB, 4.7 dB under 16QAM
/// 0.6's AWGN threshold (9.7 dB, docs/validation.md) on this flat channel (|H_k|² within
/// ±0.06 dB), every packet is wrong (the measurement can fail).
#[test]
fn dtmb_ber_kehui_tower_at_its_link_budget_snr_loses_no_packet() {
    let world = hybridnav::world::load_world(&repo().join("worlds/seed000-kehui.toml")).unwrap();
    let req = WorldIqRequest {
        tower: None,
        from_s: 5.0,
        frames: 1,
        seed: world.file.montecarlo.seed,
        trial: 0,
        data_layer: DataLayerOverride {
            qam: Some("16qam".into()),
            fec: Some("0.6".into()),
            interleaver: Some(240),
            ..DataLayerOverride::default()
        },
    };
    let ch = tower_channel_at(&world, &req).unwrap();
    assert_eq!(ch.tower, "D01");
    assert!(!ch.paths.is_empty());
    assert!(ch.snr_db > 20.0 && ch.snr_db < 45.0, "{}", ch.snr_db);
    let rec = hybridnav::world::dtmb_iq::world_iq(&world, &req).unwrap();
    assert_eq!(rec.meta.snr_db, ch.snr_db);
    let h = impulse_response(&ch.paths).unwrap();
    let profile = Profile::new(
        Constellation::Qam16,
        CodeRate::R06,
        240,
        CarrierMode::Multi3780,
    )
    .unwrap();
    let cfg = ChannelBer {
        profile,
        mode: ch.mode,
        h: &h,
        doppler: &[],
        csi: Csi::Estimated,
        frames: 20,
        seed: 1,
    };
    let p = measure_channel_point(&cfg, ch.snr_db).unwrap();
    println!("Kehui D01 at {:.2} dB: {p:?}", ch.snr_db);
    assert!(p.packets >= 20 * 6, "{p:?}");
    assert_eq!(
        (p.packet_errors, p.bit_errors, p.ldpc_failures),
        (0, 0, 0),
        "{p:?}"
    );
    let low = measure_channel_point(&cfg, 5.0).unwrap();
    assert_eq!(low.packet_errors, low.packets, "{low:?}");
    // The same with the receiver's motion: each path turning at its Doppler.
    let paths: Vec<_> = ch
        .paths
        .iter()
        .zip(&ch.dopplers_hz)
        .map(|(&(d, g), &f)| (d, g, f))
        .collect();
    let (hd, groups) = doppler_responses(&paths).unwrap();
    assert_eq!(hd, h);
    let moving = ChannelBer {
        doppler: &groups,
        ..cfg.clone()
    };
    let p = measure_channel_point(&moving, ch.snr_db).unwrap();
    println!("Kehui D01 moving at {:.2} dB: {p:?}", ch.snr_db);
    assert_eq!((p.packet_errors, p.ldpc_failures), (0, 0), "{p:?}");
    // And with the interpolating receiver (`dtmb ber --world`'s default).
    let interp = ChannelBer {
        csi: Csi::Interpolated,
        ..moving.clone()
    };
    let p = measure_channel_point(&interp, ch.snr_db).unwrap();
    println!(
        "Kehui D01 moving, interpolated, at {:.2} dB: {p:?}",
        ch.snr_db
    );
    assert!(p.packets >= 20 * 6, "{p:?}");
    assert_eq!((p.packet_errors, p.ldpc_failures), (0, 0), "{p:?}");
}

/// The Dopplers `dtmb ber --world` applies are the trial's receiver motion at `--at-s`:
/// the direct path's equals `−(dρ/dt)/λ`, the range rate differentiated numerically from
/// the ranges `tower_channel_at` gives 50 ms before and after (central difference: the
/// error is the range's third derivative times (50 ms)²/6, far below 0.05 Hz for a car),
/// within 0.05 Hz. The receiver moves (|f| > 1 Hz at Kehui Road at 5 s).
#[test]
fn dtmb_ber_world_dopplers_are_the_range_rate_of_the_trial() {
    let world = hybridnav::world::load_world(&repo().join("worlds/seed000-kehui.toml")).unwrap();
    let at = |t: f64| {
        let req = WorldIqRequest {
            tower: None,
            from_s: t,
            frames: 1,
            seed: world.file.montecarlo.seed,
            trial: 0,
            data_layer: DataLayerOverride::default(),
        };
        tower_channel_at(&world, &req).unwrap()
    };
    let (dt, t0) = (0.05, 5.0);
    let (before, now, after) = (at(t0 - dt), at(t0), at(t0 + dt));
    assert_eq!(now.dopplers_hz.len(), now.paths.len());
    let lambda = hybridnav::core::C_MPS / now.freq_hz;
    let rate = (after.range_m - before.range_m) / (after.at_s - before.at_s);
    let want = -rate / lambda;
    let direct = now
        .paths
        .iter()
        .zip(&now.dopplers_hz)
        .min_by(|a, b| a.0 .0.total_cmp(&b.0 .0))
        .map(|(_, &f)| f)
        .unwrap();
    println!("D01 at 5 s: direct-path Doppler {direct:.4} Hz, −ρ̇/λ {want:.4} Hz");
    assert!(direct.abs() > 1.0, "{direct}");
    assert!((direct - want).abs() < 0.05, "{direct} vs {want}");
}

/// The command line: the link-budget SNR and the paths are printed, both receivers'
/// curves are measured (`--csi both`: interpolated and ideal), the estimating receiver's
/// acquired timing is reported, and the CSV holds one row per receiver and grid
/// point with the link SNR; the same arguments give the same file.
#[test]
fn dtmb_ber_world_command_prints_the_margin_and_writes_both_curves() {
    let dir = tmp_dir("ber-world");
    let csv = dir.join("ber.csv");
    let args = |out: &str| -> Vec<String> {
        [
            "dtmb",
            "ber",
            "--world",
            "worlds/seed000-kehui.toml",
            "--at-s",
            "5",
            "--qam",
            "16qam",
            "--fec",
            "0.8",
            "--snr-db",
            "11.5:13.5:1",
            "--frames",
            "3",
            "--csi",
            "both",
            "--out",
            out,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let a = args(csv.to_str().unwrap());
    let o = hybridnav(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("tower D01 (PN945"), "{text}");
    assert!(
        text.contains("Doppler") && text.contains("turning at its Doppler"),
        "{text}"
    );
    assert!(text.contains("link-budget SNR"), "{text}");
    assert!(
        text.contains("# CSI interpolated") && text.contains("# CSI ideal"),
        "{text}"
    );
    // The estimating receiver acquires the timing (the genie does not) and finds the
    // frame number at every point, far above the sync's SNR needs.
    assert!(
        text.contains("# CSI interpolated: frame start acquired")
            && text.contains("frame number wrong at 0")
            && !text.contains("# CSI ideal: frame start acquired"),
        "{text}"
    );
    let body = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = body.lines().collect();
    assert!(lines[0].starts_with("csi,snr_db,frames,") && lines[0].ends_with(",link_snr_db"));
    assert_eq!(lines.len(), 1 + 2 * 3, "{body}");
    assert!(lines[1].starts_with("interpolated,11.5,3,") && lines[4].starts_with("ideal,11.5,3,"));
    // Far above 16QAM 0.8's AWGN threshold (12.4 dB) on a flat channel: nothing wrong.
    let last: Vec<&str> = lines[3].split(',').collect();
    assert_eq!(last[4], "0", "{}", lines[3]);
    let csv2 = dir.join("ber2.csv");
    let a = args(csv2.to_str().unwrap());
    assert!(hybridnav(&a.iter().map(String::as_str).collect::<Vec<_>>())
        .status
        .success());
    assert_eq!(body, std::fs::read_to_string(&csv2).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad input is refused with a message naming the problem.
#[test]
fn dtmb_ber_world_refuses_bad_input() {
    let base = ["dtmb", "ber", "--snr-db", "10", "--frames", "1"];
    let with = |extra: &[&str]| -> Vec<String> {
        base.iter().chain(extra).map(|s| s.to_string()).collect()
    };
    let run = |extra: &[&str], needles: &[&str]| {
        let a = with(extra);
        refused(&a.iter().map(String::as_str).collect::<Vec<_>>(), needles);
    };
    run(
        &["--world", "worlds/gnss-iq-open-sky.toml"],
        &["has no DTMB tower"],
    );
    run(
        &["--world", "worlds/seed000-kehui.toml", "--tower", "D07"],
        &["no DTMB tower \"D07\"", "D01"],
    );
    run(
        &["--world", "worlds/seed000-kehui.toml", "--csi", "genie"],
        &["--csi", "ideal, estimated or interpolated"],
    );
    run(
        &["--world", "worlds/seed000-kehui.toml", "--mode", "pn420"],
        &["contradicts tower D01's PN945"],
    );
    run(
        &["--world", "worlds/seed000-kehui.toml", "--carriers", "2"],
        &["--carriers must be 3780 or 1"],
    );
    run(
        &["--world", "worlds/seed000-kehui.toml", "--at-s", "1e9"],
        &["outside the world's duration"],
    );
    run(&["--tower", "D01"], &["--tower needs --world"]);
    run(&["--no-doppler"], &["--no-doppler needs --world"]);
    run(&["--true-timing"], &["--true-timing needs --world"]);
    run(&["--csi", "ideal"], &["--csi needs --world"]);
    run(&["--cfo-hz", "100"], &["--cfo-hz needs --world"]);
    run(
        &[
            "--world",
            "worlds/seed000-kehui.toml",
            "--no-cfo-correction",
        ],
        &["--no-cfo-correction needs a carrier offset"],
    );
    run(
        &["--oscillator-ppm", "2"],
        &["--oscillator-ppm needs --world"],
    );
    run(
        &["--no-timing-tracking"],
        &["--no-timing-tracking needs --world"],
    );
    for bad in ["nan", "inf", "150", "-100.5"] {
        run(
            &[
                "--world",
                "worlds/seed000-kehui.toml",
                "--oscillator-ppm",
                bad,
            ],
            &["--oscillator-ppm must be a finite oscillator error within ±100 ppm"],
        );
    }
    run(
        &[
            "--world",
            "worlds/seed000-kehui.toml",
            "--cfo-hz",
            "100",
            "--oscillator-ppm",
            "1",
        ],
        &["--cfo-hz", "--oscillator-ppm", "are alternatives"],
    );
    // Without an oscillator error the frame timing drifts only with the receiver's
    // motion, which --no-doppler stops.
    for extra in [&[][..], &["--cfo-hz", "100"][..]] {
        let mut a = vec![
            "--world",
            "worlds/seed000-kehui.toml",
            "--no-doppler",
            "--no-timing-tracking",
        ];
        a.extend_from_slice(extra);
        run(&a, &["--no-timing-tracking needs a drifting frame timing"]);
    }
    run(
        &[
            "--world",
            "worlds/seed000-kehui.toml",
            "--no-doppler",
            "--no-delay-drift",
        ],
        &["--no-delay-drift", "--no-doppler already holds"],
    );
    run(&["--no-delay-drift"], &["--no-delay-drift needs --world"]);
    run(
        &["--world", "worlds/seed000-kehui.toml", "--cfo-hz", "inf"],
        &["--cfo-hz must be a finite"],
    );
    run(
        &["--cfo-rate-hz-per-s", "200"],
        &["--cfo-rate-hz-per-s needs --world"],
    );
    for extra in [&[][..], &["--oscillator-ppm", "1"][..]] {
        let mut a = vec![
            "--world",
            "worlds/seed000-kehui.toml",
            "--cfo-rate-hz-per-s",
            "200",
        ];
        a.extend_from_slice(extra);
        run(&a, &["--cfo-rate-hz-per-s needs --cfo-hz"]);
    }
    for bad in ["nan", "inf", "-inf", "1e6", "-100001"] {
        run(
            &[
                "--world",
                "worlds/seed000-kehui.toml",
                "--cfo-hz",
                "100",
                "--cfo-rate-hz-per-s",
                bad,
            ],
            &["--cfo-rate-hz-per-s must be a finite drift within ±100000 Hz/s"],
        );
    }
    run(&["--world", "no/such/world.toml"], &["no/such/world.toml"]);
}

/// `hybridnav dtmb ber --world worlds/seed000-kehui.toml --at-s 5` (tower D01) with
/// `extra`, which must succeed; its standard output.
fn kehui_ber(extra: &[&str]) -> String {
    let mut a = vec![
        "dtmb",
        "ber",
        "--world",
        "worlds/seed000-kehui.toml",
        "--at-s",
        "5",
    ];
    a.extend_from_slice(extra);
    let o = hybridnav(&a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// `--carriers 1` through the world's channel (the C = 1 receiver) and `--no-doppler`
/// (the static channel): far above 16QAM 0.8's AWGN threshold (12.4 dB) nothing is
/// wrong, and the header says which channel was used.
#[test]
fn dtmb_ber_world_single_carrier_and_static_channel() {
    let run = |extra: &[&str]| -> String {
        let mut a = vec![
            "--qam", "16qam", "--fec", "0.8", "--snr-db", "20", "--frames", "2",
        ];
        a.extend_from_slice(extra);
        kehui_ber(&a)
    };
    let c1 = run(&["--carriers", "1"]);
    assert!(c1.contains("C1"), "{c1}");
    let row = c1
        .lines()
        .find(|l| l.trim_start().starts_with("20.00"))
        .unwrap();
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cols[2], "0", "{row}");
    assert!(cols[1].parse::<u64>().unwrap() > 0, "{row}");
    let still = run(&["--no-doppler"]);
    assert!(still.contains("static: --no-doppler"), "{still}");
}

/// The PER 10⁻² threshold (dB) of the interpolated-CSI curve that `dtmb ber` prints in
/// its `# CSI interpolated: PER 1e-2 at …` line.
fn interpolated_threshold_db(text: &str) -> f64 {
    const HEAD: &str = "# CSI interpolated: PER 1e-2 at ";
    let line = text
        .lines()
        .find(|l| l.starts_with(HEAD))
        .unwrap_or_else(|| panic!("no threshold in {text}"));
    line[HEAD.len()..]
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// The receiver's carrier-frequency offset on the command line (`--cfo-hz`): the Kehui
/// tower D01 at 5 s (PN945, 482 MHz), 64QAM 0.6, 20 frames a point. 1 kHz is
/// 1000/482·10⁶ = 2.075 ppm, printed. Corrected from the PN headers, the interpolating
/// receiver's PER 10⁻² threshold (acquired timing) lies within 0.2 dB of the one
/// without an offset (the Monte-Carlo 0.15 dB of two thresholds plus the residual of the
/// accumulated estimate, 1.7 Hz analytic; ber_channel's `a_corrected_1_khz_cfo_keeps_the_threshold`);
/// left uncorrected (`--no-cfo-correction`) half a carrier spacing of offset loses every
/// packet at 25 dB, 10 dB above the threshold. (Where the options mean nothing they are
/// refused: `dtmb_ber_world_refuses_bad_input`.)
#[test]
fn dtmb_ber_world_cfo_is_corrected_and_costs_everything_without() {
    let run = |extra: &[&str]| -> String {
        let mut a = vec!["--frames", "20"];
        a.extend_from_slice(extra);
        kehui_ber(&a)
    };
    let threshold = interpolated_threshold_db;
    let grid = ["--snr-db", "14.3:15.5:0.1"];
    let still = run(&grid);
    let cfo = run(&[grid[0], grid[1], "--cfo-hz", "1000"]);
    assert!(
        cfo.contains("receiver CFO 1000.0 Hz (2.075 ppm at 482 MHz)")
            && cfo.contains("estimated from the PN headers and corrected"),
        "{cfo}"
    );
    let (a, b) = (threshold(&still), threshold(&cfo));
    println!("Kehui D01 interpolated: no offset {a} dB, 1 kHz corrected {b} dB");
    assert!((a - b).abs() < 0.2, "{a} vs {b}");
    let dir = tmp_dir("ber-cfo");
    let csv = dir.join("uncorrected.csv");
    let text = run(&[
        "--snr-db",
        "25",
        "--cfo-hz",
        "1000",
        "--no-cfo-correction",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(
        text.contains("not corrected (--no-cfo-correction)"),
        "{text}"
    );
    let body = std::fs::read_to_string(&csv).unwrap();
    let row: Vec<&str> = body.lines().nth(1).unwrap().split(',').collect();
    let header: Vec<&str> = body.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (packets, errors): (u64, u64) = (
        row[col("packets")].parse().unwrap(),
        row[col("packet_errors")].parse().unwrap(),
    );
    println!("uncorrected 1 kHz at 25 dB: {errors} of {packets} packets wrong");
    assert!(packets > 0 && errors == packets, "{body}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A drifting offset on the command line (`--cfo-hz 1000 --cfo-rate-hz-per-s 2718`, the
/// steepest Doppler rate of a 350 km/h train past a mast 10 m from the track at 862 MHz,
/// ber_channel's `a_tracked_drifting_cfo_keeps_the_threshold_where_the_sum_fails`): on the
/// Kehui tower D01 at 5 s (PN945, 482 MHz, the world's multipath and Doppler), 64QAM 0.6,
/// 20 frames a point (190 frames, over which the offset drifts by 322 Hz), the note says
/// the loop follows it, and the interpolating receiver's threshold (acquired timing) lies
/// within 0.2 dB of the one without an offset (the bound of the 1 kHz test).
#[test]
fn dtmb_ber_world_drifting_cfo_is_tracked() {
    let run = |extra: &[&str]| -> String {
        let mut a = vec!["--frames", "20", "--snr-db", "14.3:15.5:0.1"];
        a.extend_from_slice(extra);
        kehui_ber(&a)
    };
    let threshold = interpolated_threshold_db;
    let still = run(&[]);
    let drift = run(&["--cfo-hz", "1000", "--cfo-rate-hz-per-s", "2718"]);
    assert!(
        drift.contains("receiver CFO 1000.0 Hz (2.075 ppm at 482 MHz)")
            && drift.contains("drifting +2718.0 Hz/s, followed from the PN headers by a type-2"),
        "{drift}"
    );
    let (a, b) = (threshold(&still), threshold(&drift));
    println!("Kehui D01 interpolated: no offset {a} dB, 1 kHz + 2718 Hz/s tracked {b} dB");
    assert!((a - b).abs() < 0.2, "{a} vs {b}");
}

/// The interpolating receiver's measured frame-timing drift, its standard error, and the
/// drift the command predicts (the clock's `εF` plus the paths' `τ̇F`), from
/// "# CSI interpolated: frame timing drift measured D ± S samples a frame over N frames
/// (the clock's +ε·F C, the paths' P); …".
fn measured_drift(text: &str) -> (f64, f64, f64) {
    let line = text
        .lines()
        .find(|l| l.starts_with("# CSI interpolated: frame timing drift measured"))
        .unwrap_or_else(|| panic!("no drift in {text}"));
    println!("{line}");
    let words: Vec<&str> = line.split_whitespace().collect();
    let after = |w: &str| -> f64 {
        let at = words.iter().position(|x| *x == w).unwrap();
        words[at + 1]
            .trim_end_matches([',', ')', ';'])
            .parse()
            .unwrap()
    };
    let at = words.iter().position(|w| *w == "measured").unwrap();
    let (drift, sd): (f64, f64) = (
        words[at + 1].parse().unwrap(),
        words[at + 3].parse().unwrap(),
    );
    (drift, sd, after("+ε·F") + after("paths'"))
}

/// Offsets beyond the header estimators' ranges, through the acquiring receiver's coarse
/// frequency search (automatic when it corrects an offset): on the Kehui tower D01 (PN945,
/// 482 MHz), 64QAM 0.6, 20 frames a point, `--cfo-hz -9000` (beyond PN945's ±7397 Hz
/// cyclic range; the sync alone loses the frame start past about 6 kHz) keeps the
/// threshold without an offset within the 0.2 dB of the 1 kHz test, and the note says the
/// search unwraps it; `--oscillator-ppm -10` (CFO +4.82 kHz, the frame timing drifting
/// −0.04725 samples a frame, tracked) keeps the threshold of `--oscillator-ppm -2`
/// (whose drift carries the response across the sample grid too) within the same 0.2 dB,
/// and reports the analytic drift. The true-timing receiver (`--true-timing`), given the
/// frame start but not the carrier, searches too: at `--cfo-hz 9000` it keeps the same
/// threshold within the same 0.2 dB, and its note says the search unwraps the offset.
#[test]
fn dtmb_ber_world_offsets_beyond_the_range_are_searched() {
    let threshold = interpolated_threshold_db;
    let grid = ["--frames", "20", "--snr-db", "14.3:15.5:0.1"];
    let with = |extra: &[&str]| {
        let mut a = grid.to_vec();
        a.extend_from_slice(extra);
        kehui_ber(&a)
    };
    let still = threshold(&with(&[]));
    let far = with(&["--cfo-hz", "-9000"]);
    assert!(
        far.contains("the acquiring receiver's coarse frequency search (±12000 Hz) unwraps it"),
        "{far}"
    );
    let far = threshold(&far);
    let two = threshold(&with(&["--oscillator-ppm", "-2"]));
    let ten_text = with(&["--oscillator-ppm", "-10"]);
    // The clock's −0.04725 samples a frame and the car's +7.8·10⁻⁵.
    let (drift, sd, want) = measured_drift(&ten_text);
    assert!((drift - want).abs() < 4.0 * sd, "{drift} ± {sd} vs {want}");
    let ten = threshold(&ten_text);
    println!("Kehui D01: no offset {still} dB, -9 kHz {far} dB; -2 ppm {two} dB, -10 ppm {ten} dB");
    assert!((far - still).abs() < 0.2, "{far} vs {still}");
    assert!((ten - two).abs() < 0.2, "{ten} vs {two}");
    let tt = with(&["--cfo-hz", "9000", "--true-timing"]);
    assert!(
        tt.contains("the true-timing receiver's coarse frequency search (±12000 Hz) unwraps it"),
        "{tt}"
    );
    let tt = threshold(&tt);
    println!("Kehui D01: true timing at +9 kHz {tt} dB");
    assert!((tt - still).abs() < 0.2, "{tt} vs {still}");
}

/// The receiver's oscillator from the world file: `sensors.dtmb.rx_oscillator_ppm`
/// (which `dtmb iq --world` records with) applies to `dtmb ber --world` as
/// `--oscillator-ppm` does. The Kehui world with the key set to −2 ppm gives the CSV of
/// the world without it and `--oscillator-ppm -2`, byte for byte (tower D01 at 5 s,
/// PN945 at 482 MHz: a CFO of +964 Hz, corrected, and the sample clock
/// `f_s(1 − 2·10⁻⁶)`, tracked; both receivers, the genie's stream without the clock
/// offset), and says where the error came from. The interpolating receiver's timing
/// tracker measures the drift `εF` = −0.00945 samples a frame within four of its standard
/// errors. The command line overrides the key: `--oscillator-ppm 0` on the keyed world
/// is the world without an offset, byte for byte, and so is `--cfo-hz` (a pure carrier
/// offset) the same option on the world without the key. A key beyond ±100 ppm is refused
/// by the world file's validation.
#[test]
fn dtmb_ber_world_oscillator_key_is_the_command_line_option() {
    let dir = tmp_dir("ber-oscillator");
    let text = std::fs::read_to_string(repo().join("worlds/seed000-kehui.toml")).unwrap();
    let keyed_with = |ppm: &str| {
        let t = text.replacen(
            "[sensors.dtmb]\n",
            &format!("[sensors.dtmb]\nrx_oscillator_ppm = {ppm}\n"),
            1,
        );
        assert_ne!(t, text, "the world has a [sensors.dtmb] section");
        t
    };
    let keyed = dir.join("kehui-oscillator.toml");
    std::fs::write(&keyed, keyed_with("-2.0")).unwrap();
    let keyed = keyed.to_str().unwrap().to_string();
    let plain = "worlds/seed000-kehui.toml";
    let mut n = 0;
    let mut run = |world: &str, extra: &[&str]| -> (String, String) {
        n += 1;
        let csv = dir.join(format!("ber{n}.csv"));
        let mut a = vec![
            "dtmb",
            "ber",
            "--world",
            world,
            "--at-s",
            "5",
            "--frames",
            "20",
            "--snr-db",
            "15:16:1",
            "--csi",
            "both",
            "--out",
            csv.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        let o = hybridnav(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            String::from_utf8_lossy(&o.stdout).into_owned(),
            std::fs::read_to_string(&csv).unwrap(),
        )
    };
    let (key_text, key_csv) = run(&keyed, &[]);
    let (opt_text, opt_csv) = run(plain, &["--oscillator-ppm", "-2"]);
    assert_eq!(key_csv, opt_csv);
    assert!(
        key_text.contains(
            "receiver oscillator -2.000 ppm (from the world's sensors.dtmb.rx_oscillator_ppm)"
        ) && key_text.contains("receiver CFO 964.0 Hz"),
        "{key_text}"
    );
    assert!(
        opt_text.contains("receiver oscillator -2.000 ppm (from --oscillator-ppm)"),
        "{opt_text}"
    );
    // The clock's εF = −0.00945 and the car's delay drift, +7.8·10⁻⁵ samples a frame.
    let (drift, sd, want) = measured_drift(&key_text);
    assert!((want - (-2e-6 * 4725.0 + 7.83e-5)).abs() < 2e-5, "{want}");
    assert!((drift - want).abs() < 4.0 * sd, "{drift} ± {sd} vs {want}");
    let (_, still_csv) = run(plain, &[]);
    let (_, zero_csv) = run(&keyed, &["--oscillator-ppm", "0"]);
    assert_eq!(zero_csv, still_csv);
    assert_ne!(key_csv, still_csv);
    let (cfo_text, cfo_csv) = run(&keyed, &["--cfo-hz", "964"]);
    assert!(!cfo_text.contains("receiver oscillator"), "{cfo_text}");
    assert_eq!(cfo_csv, run(plain, &["--cfo-hz", "964"]).1);
    let bad = dir.join("kehui-bad-oscillator.toml");
    std::fs::write(&bad, keyed_with("150.0")).unwrap();
    refused(
        &[
            "dtmb",
            "ber",
            "--world",
            bad.to_str().unwrap(),
            "--snr-db",
            "10",
        ],
        &["rx_oscillator_ppm", "within ±100 ppm"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A moving receiver's delay drift through the world's channel (`dtmb ber --world`, the
/// default; `ber_channel`'s *Delay drift*): on Kehui Road at 5 s the car recedes from
/// tower D01 at 4.97 m/s (Doppler −7.989 Hz at 482 MHz), so every path's delay grows at
/// −f_D/f_c = 1.658·10⁻⁸ s/s, 7.8·10⁻⁵ samples a frame — 0.015 samples over a point, too
/// little to cost the 64QAM 0.6 threshold anything: with and without `--no-delay-drift`
/// the PER 10⁻² thresholds agree within 0.2 dB. The header states the rates, and the held
/// run says nothing of a drift.
#[test]
fn dtmb_ber_world_delay_drift_costs_a_slow_car_nothing() {
    let grid = ["--frames", "20", "--snr-db", "14.3:15.5:0.2"];
    let run = |extra: &[&str]| {
        let mut a = grid.to_vec();
        a.extend_from_slice(extra);
        kehui_ber(&a)
    };
    let drifting = run(&[]);
    assert!(
        drifting.contains(
            "# delay drift: each path's delay follows its range rate, −f_D/f_c = +1.658e-8"
        ),
        "{drifting}"
    );
    let held = run(&["--no-delay-drift"]);
    assert!(!held.contains("delay drift"), "{held}");
    let (a, b) = (
        interpolated_threshold_db(&drifting),
        interpolated_threshold_db(&held),
    );
    println!("Kehui D01 at 5 s: PER 1e-2 at {a} dB drifting, {b} dB held");
    assert!((a - b).abs() < 0.2, "{a} vs {b}");
}
