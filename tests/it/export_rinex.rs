//! RINEX export: the observation file's layout and physics, and the tools that read it.
//!
//! `tests/python/rinex_check.py` reads the file with georinex and runs RTKLIB's `rnx2rtkp`
//! on it (single point, broadcast Klobuchar and Saastamoinen); its positions must have the
//! error of hybridnav's own snapshot WLS on the same trial. The world here is the default
//! drive under an open sky with a real broadcast file (non-zero group delays) when
//! `../shared` is there, and with a receiver clock that crosses 0.5 ms, so the file has
//! the millisecond clock steps of a real receiver.

use crate::common::{hybridnav, python_has, repo, shared_gnss, stderr, tmp_dir};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const C_MPS: f64 = 299_792_458.0;

/// The default world without its buildings, shielding, DTMB tower and the estimators that
/// use the tower or the IMU, its receiver clock started just under 0.5 ms; on the
/// synthetic `builtin:nominal-gps-bds` constellation (2018-06-01 04:00 GPST), or with
/// `nav`, on a real broadcast file at its place and day.
fn open_sky_world(dir: &Path, nav: Option<&Path>) -> PathBuf {
    let text = crate::common::default_world_text();
    // Split into tables (a header line and the lines up to the next header).
    let mut tables: Vec<Vec<&str>> = vec![Vec::new()];
    for line in text.lines() {
        if line.starts_with('[') {
            tables.push(Vec::new());
        }
        tables.last_mut().unwrap().push(line);
    }
    let mut out = Vec::new();
    let mut in_dropped_estimator = false;
    for t in &tables {
        let header = t[0];
        let body = t.join("\n");
        if header.starts_with("[[estimator]]") {
            in_dropped_estimator = body.contains("\"dtmb\"") || body.contains("filter = \"ins\"");
        } else if !header.starts_with("[estimator.") {
            in_dropped_estimator = false;
        }
        let skip = header.starts_with("[[shielding]]")
            || header.starts_with("[scene")
            || header.starts_with("[[scene")
            || header.starts_with("[[transmitter]]")
            || header.starts_with("[sensors.dtmb]")
            || in_dropped_estimator;
        if !skip {
            out.extend(t.iter().map(|l| l.to_string()));
        }
    }
    let (ephemeris, start) = match nav {
        Some(nav) => (nav.display().to_string(), "2020-06-25T10:00:00 GPST"),
        None => (
            "builtin:nominal-gps-bds".to_string(),
            "2018-06-01T04:00:00 GPST",
        ),
    };
    let mut w = out
        .iter()
        .map(|l| {
            if l.starts_with("ephemeris = ") {
                format!("ephemeris = {ephemeris:?}")
            } else if l.starts_with("start = ") {
                format!("start = {start:?}")
            } else {
                l.clone()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    w = w
        .replace("initial_bias_s = 1.0e-4", "initial_bias_s = 4.999e-4")
        .replace(
            "initial_bias_sigma_s = 1.0e-5",
            "initial_bias_sigma_s = 0.0",
        );
    if nav.is_some() {
        w = w.replace(
            "origin = { lat_deg = 40.00470, lon_deg = 116.39690, h_m = 45.0 }",
            "origin = { lat_deg = 55.40, lon_deg = 8.45, h_m = 20.0 }",
        );
    }
    crate::common::write(dir, "open-sky.toml", &w)
}

/// One satellite's observables at one epoch.
#[derive(Clone, Copy, Debug)]
struct Obs {
    code_m: f64,
    phase_cyc: f64,
    doppler_hz: f64,
    cn0: f64,
    lli: bool,
}

/// A minimal RINEX 3 observation reader, independent of the writer: header labels, epoch
/// tags (seconds of the day) and the four observables per satellite.
/// An epoch: its time tag (seconds of the GPST day) and the observables by satellite.
type Epoch = (f64, BTreeMap<String, Obs>);

fn read_obs(path: &Path) -> (Vec<String>, Vec<Epoch>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let mut labels = Vec::new();
    for l in lines.by_ref() {
        assert!(l.len() <= 80, "header line over 80 columns: {l:?}");
        let label = l.get(60..).unwrap_or("").trim().to_string();
        if label == "END OF HEADER" {
            break;
        }
        labels.push(label);
    }
    let mut epochs = Vec::new();
    let mut lines = lines.peekable();
    while let Some(l) = lines.next() {
        assert!(l.starts_with("> "), "expected an epoch record: {l:?}");
        let f = |a: usize, b: usize| l[a..b].trim().parse::<f64>().unwrap();
        let sod = f(13, 15) * 3600.0 + f(16, 18) * 60.0 + f(18, 29);
        let n = f(32, 35) as usize;
        let mut sats = BTreeMap::new();
        for _ in 0..n {
            let s = lines.next().expect("a satellite line");
            let v = |k: usize| {
                s[3 + 16 * k..3 + 16 * k + 14]
                    .trim()
                    .parse::<f64>()
                    .unwrap()
            };
            sats.insert(
                s[..3].to_string(),
                Obs {
                    code_m: v(0),
                    phase_cyc: v(1),
                    doppler_hz: v(2),
                    cn0: v(3),
                    lli: &s[3 + 16 + 14..3 + 16 + 15] == "1",
                },
            );
        }
        epochs.push((sod, sats));
    }
    (labels, epochs)
}

fn export(world: &Path, out: &Path) {
    let o = hybridnav(&[
        "export",
        world.to_str().unwrap(),
        "--format",
        "rinex,csv,tum",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn the_observation_file_is_well_formed_and_physically_consistent() {
    let dir = tmp_dir("rinex-self");
    let world = open_sky_world(&dir, None);
    let out = dir.join("out");
    export(&world, &out);
    let (labels, epochs) = read_obs(&out.join("hybridnav.obs"));
    for required in [
        "RINEX VERSION / TYPE",
        "PGM / RUN BY / DATE",
        "MARKER NAME",
        "OBSERVER / AGENCY",
        "REC # / TYPE / VERS",
        "ANT # / TYPE",
        "APPROX POSITION XYZ",
        "ANTENNA: DELTA H/E/N",
        "SYS / # / OBS TYPES",
        "TIME OF FIRST OBS",
        "SYS / PHASE SHIFT",
    ] {
        assert!(labels.iter().any(|l| l == required), "no {required}");
    }
    assert_eq!(epochs.len(), 172);

    // Receiver time tags: the clock starts at 0.4999 ms and drifts up; the receiver steps
    // it by 1 ms, so every tag stays within 0.5 ms of the whole second (GPST).
    let mut stepped = false;
    for (sod, _) in &epochs {
        let frac = sod - sod.round();
        assert!(frac.abs() <= 0.5e-3 + 1e-7, "tag {sod}");
        stepped |= frac < 0.0;
    }
    assert!(stepped, "the clock never crossed 0.5 ms");

    // Per satellite: Doppler against the carrier phase's rate, and the code–carrier
    // difference, which moves only by twice the (slow) ionosphere and the code noise.
    let mut rate_diff = Vec::new();
    let mut by_sat: BTreeMap<&str, Vec<(f64, Obs)>> = BTreeMap::new();
    for (sod, sats) in &epochs {
        for (s, o) in sats {
            by_sat.entry(s).or_default().push((*sod, *o));
        }
    }
    for (sat, track) in &by_sat {
        let lambda = C_MPS
            / if sat.starts_with('C') {
                1_561.098e6
            } else {
                1_575.42e6
            };
        assert!(
            track[0].1.lli,
            "{sat}: the first epoch of an arc flags loss of lock"
        );
        let mut cmc = Vec::new();
        for w in track.windows(2) {
            let ((t0, a), (t1, b)) = (w[0], w[1]);
            let dt = t1 - t0;
            if (dt - 1.0).abs() > 2e-3 || b.lli {
                continue;
            }
            // A clock step moves code and phase together by c·1 ms: both differences
            // below see it equally and the Doppler does not.
            let phase_rate = (b.phase_cyc - a.phase_cyc) * lambda / dt;
            let code_rate = (b.code_m - a.code_m) / dt;
            // A step applied to one and not the other would part them by 300 km; the
            // code noise of a weak signal is a few metres.
            let apart = (code_rate - phase_rate).abs() * dt;
            assert!(
                apart < 30.0,
                "{sat}: code and phase moved apart by {apart} m"
            );
            let jumped = (phase_rate.abs() - C_MPS * 1e-3).abs() < 5_000.0;
            if !jumped {
                rate_diff.push(-lambda * 0.5 * (a.doppler_hz + b.doppler_hz) - phase_rate);
            }
        }
        for (_, o) in track {
            cmc.push(o.code_m - o.phase_cyc * lambda);
        }
        let mean = cmc.iter().sum::<f64>() / cmc.len() as f64;
        let sd = (cmc.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / cmc.len() as f64).sqrt();
        assert!(
            sd < 3.0,
            "{sat}: code − carrier varies by {sd} m under an open sky"
        );
        assert!(track.iter().all(|(_, o)| (20.0..60.0).contains(&o.cn0)));
    }
    let rms = (rate_diff.iter().map(|x| x * x).sum::<f64>() / rate_diff.len() as f64).sqrt();
    println!(
        "Doppler vs carrier-phase rate: RMS {rms:.3} m/s over {} pairs",
        rate_diff.len()
    );
    assert!(rate_diff.len() > 1000 && rms < 0.3, "{rms}");
}

fn run_tools(world: &Path, out: &Path) {
    if !python_has(&["georinex", "pandas"]) {
        return;
    }
    if !crate::common::has_rnx2rtkp() {
        return;
    }
    export(world, out);
    let py = std::process::Command::new("python3")
        .args(["-W", "ignore"])
        .arg(repo().join("tests/python/rinex_check.py"))
        .arg(out)
        .output()
        .expect("python3");
    let text = String::from_utf8_lossy(&py.stdout);
    println!("{text}");
    assert!(py.status.success(), "{text}{}", stderr(&py));
}

#[test]
fn georinex_reads_it_and_rtklib_positions_match_the_error_budget() {
    let dir = tmp_dir("rinex-tools");
    run_tools(&open_sky_world(&dir, None), &dir.join("out"));
}

#[test]
fn on_a_real_broadcast_file_too() {
    let Some(gnss) = shared_gnss() else {
        return;
    };
    let dir = tmp_dir("rinex-tools-real");
    let nav = gnss.join("ESBC00DNK_R_20201770000_01D_MN.rnx");
    run_tools(&open_sky_world(&dir, Some(&nav)), &dir.join("out"));
}

/// A GPS-only receiver's file declares GPS observables only (file type `G`, no BeiDou
/// `SYS / # / OBS TYPES` or phase-shift line), and georinex reads it as GPS data.
#[test]
fn a_gps_only_file_declares_no_beidou_observables() {
    let dir = tmp_dir("rinex-gps-only");
    let world = open_sky_world(&dir, None);
    let text = std::fs::read_to_string(&world).unwrap();
    assert!(text.contains("systems = [\"gps\", \"bds\"]"));
    let gps_only = text
        .replace("systems = [\"gps\", \"bds\"]", "systems = [\"gps\"]")
        .replace("sources = [\"gps\", \"bds\"]", "sources = [\"gps\"]");
    let world = crate::common::write(&dir, "gps-only.toml", &gps_only);
    let out = dir.join("out");
    export(&world, &out);
    let obs = std::fs::read_to_string(out.join("hybridnav.obs")).unwrap();
    let header: Vec<&str> = obs
        .lines()
        .take_while(|l| !l.contains("END OF HEADER"))
        .collect();
    let first = header[0];
    assert_eq!(&first[40..41], "G", "{first}");
    assert!(
        header.iter().any(|l| l.starts_with("G    4 C1C")),
        "{header:?}"
    );
    assert!(
        !header
            .iter()
            .any(|l| l.starts_with('C') && l.contains("SYS /")),
        "{header:?}"
    );
    // The body holds GPS satellites only.
    assert!(obs
        .lines()
        .skip(header.len() + 1)
        .filter(|l| !l.starts_with('>'))
        .all(|l| l.starts_with('G')));
    if python_has(&["georinex"]) {
        let py = std::process::Command::new("python3")
            .args(["-W", "ignore", "-c"])
            .arg(
                "import sys, georinex as gr\n\
                 o = gr.load(sys.argv[1])\n\
                 svs = sorted(str(s) for s in o.sv.values)\n\
                 assert svs and all(s.startswith('G') for s in svs), svs\n\
                 assert sorted(o.data_vars) == ['C1C', 'D1C', 'L1C', 'S1C'], list(o.data_vars)\n\
                 print(len(svs), 'GPS satellites,', list(o.data_vars))",
            )
            .arg(out.join("hybridnav.obs"))
            .output()
            .expect("python3");
        let text = String::from_utf8_lossy(&py.stdout);
        println!("{text}");
        assert!(py.status.success(), "{text}{}", stderr(&py));
    }
}
