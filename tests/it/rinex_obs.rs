//! The RINEX observation reader and `gnss position` on real and exported files: a GEONET
//! station's positions against its surveyed header position, every value of some epochs
//! against georinex, the export read back, and hostile inputs.

use crate::common::{hybridnav, python_has, refused, repo, shared_gnss, stderr, tmp_dir};
use hybridnav::core::geodesy::ecef_to_enu_rotation;
use hybridnav::core::{Geodetic, System, C_MPS};
use hybridnav::gnss::rinex_obs::{self, ObsEpoch};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::path::Path;

const GEONET_OBS: &str = "07590920.05o";
const GEONET_NAV: &str = "07590920.05n";

/// `APPROX POSITION XYZ` read straight from the text (not through the reader under test).
fn header_position(path: &Path) -> Vector3<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let line = text
        .lines()
        .find(|l| {
            l.get(60..)
                .is_some_and(|s| s.trim() == "APPROX POSITION XYZ")
        })
        .expect("an APPROX POSITION XYZ line");
    let v: Vec<f64> = line[..42]
        .split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect();
    Vector3::new(v[0], v[1], v[2])
}

/// The nearest-rank 95th percentile of `v`.
fn p95(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((0.95 * s.len() as f64).ceil() as usize).max(1) - 1]
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// A static GEONET station (0759, 2 April 2005, one hour at 30 s, GPS only, Trimble 5700)
/// positioned epoch by epoch from its C1 code and the day's broadcast file, against the
/// position in its header (GSI's surveyed coordinates of the marker).
///
/// Bound: the GPS Standard Positioning Service Performance Standard in force in 2005
/// (SPS PS, 4 October 2001, §3.8, positioning accuracy standard) specifies, for a single-frequency L1 C/A
/// user with the broadcast ephemeris, clock and Klobuchar ionosphere, a global-average
/// positioning accuracy of ≤ 13 m horizontal and ≤ 22 m vertical (95 %). The test
/// asserts those figures; the measured ones are in docs/validation.md.
#[test]
fn a_geonet_station_is_positioned_within_the_sps_accuracy_standard() {
    let Some(gnss) = shared_gnss() else {
        return;
    };
    let obs = gnss.join(GEONET_OBS);
    if !obs.exists() {
        crate::common::skip(&format!("{} not found", obs.display()));
        return;
    }
    let dir = tmp_dir("spp-geonet");
    let out = dir.join("pos.csv");
    let o = hybridnav(&[
        "gnss",
        "position",
        "--obs",
        obs.to_str().unwrap(),
        "--nav",
        gnss.join(GEONET_NAV).to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let truth = header_position(&obs);
    let g = Geodetic::from_ecef(&truth);
    let rot = ecef_to_enu_rotation(g.lat_rad, g.lon_rad);
    let csv = std::fs::read_to_string(&out).unwrap();
    let mut lines = csv.lines();
    let cols: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| cols.iter().position(|c| *c == name).unwrap();
    let (x, y, z, n, pdop) = (
        col("x_m"),
        col("y_m"),
        col("z_m"),
        col("n_sats"),
        col("pdop"),
    );
    let (mut horiz, mut vert, mut n_sats, mut pdops) = (vec![], vec![], vec![], vec![]);
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        let p = Vector3::new(
            f[x].parse::<f64>().unwrap(),
            f[y].parse().unwrap(),
            f[z].parse().unwrap(),
        );
        let enu = rot * (p - truth);
        horiz.push(enu.x.hypot(enu.y));
        vert.push(enu.z);
        n_sats.push(f[n].parse::<usize>().unwrap());
        pdops.push(f[pdop].parse::<f64>().unwrap());
    }
    // Every epoch of the file (counted from its text) has a fix: at least seven GPS
    // satellites are above 10° throughout.
    let text = std::fs::read_to_string(&obs).unwrap();
    let epochs = text.lines().filter(|l| l.starts_with(" 05  4  2")).count();
    assert_eq!(epochs, 120);
    assert_eq!(horiz.len(), epochs, "{}", stderr(&o));
    let vabs: Vec<f64> = vert.iter().map(|v| v.abs()).collect();
    let mean_up = vert.iter().sum::<f64>() / vert.len() as f64;
    println!(
        "GEONET 0759, {} epochs: horizontal RMS {:.2} m, 95 % {:.2} m, max {:.2} m; \
         vertical RMS {:.2} m, 95 % {:.2} m, mean {:+.2} m; satellites {}–{}, PDOP {:.2}–{:.2}",
        horiz.len(),
        rms(&horiz),
        p95(&horiz),
        horiz.iter().copied().fold(0.0, f64::max),
        rms(&vert),
        p95(&vabs),
        mean_up,
        n_sats.iter().min().unwrap(),
        n_sats.iter().max().unwrap(),
        pdops.iter().copied().fold(f64::INFINITY, f64::min),
        pdops.iter().copied().fold(0.0, f64::max),
    );
    assert!(p95(&horiz) <= 13.0, "horizontal 95 % {}", p95(&horiz));
    assert!(p95(&vabs) <= 22.0, "vertical 95 % {}", p95(&vabs));
    against_rtklib(&obs, &gnss.join(GEONET_NAV), &csv, &dir);
}

/// RTKLIB's single-point solution of the same file (`rnx2rtkp`: broadcast orbits and
/// clocks, Klobuchar, Saastamoinen, 10° mask, GPS L1), epoch by epoch against ours. The
/// two solvers take the same ranges with the same corrections and differ in their
/// weights (RTKLIB: σ² = 0.3² (1 + 1/sin² el) m² plus its model variances; hybridnav: the
/// simulator's error budget), and reweighting a least-squares fix moves it by about the
/// post-fit residuals carried through the geometry: each epoch must agree within its
/// PDOP × residual RMS.
fn against_rtklib(obs: &Path, nav: &Path, csv: &str, dir: &Path) {
    if !crate::common::has_rnx2rtkp() {
        return;
    }
    let conf = crate::common::write(
        dir,
        "spp.conf",
        "pos1-posmode=single\npos1-frequency=l1\npos1-elmask=10\npos1-ionoopt=brdc\n\
         pos1-tropopt=saas\npos1-navsys=1\nout-solformat=xyz\nout-timesys=gpst\n\
         out-timeform=tow\n",
    );
    let pos = dir.join("rtklib.pos");
    let o = std::process::Command::new("rnx2rtkp")
        .arg("-k")
        .arg(&conf)
        .arg("-o")
        .arg(&pos)
        .arg(obs)
        .arg(nav)
        .output()
        .expect("rnx2rtkp");
    assert!(o.status.success(), "{}", stderr(&o));
    // RTKLIB tags a fix with the reception time it estimated (tag minus its clock, at
    // most a few ms away): the nearest whole second is the epoch.
    let rtk: BTreeMap<i64, Vector3<f64>> = std::fs::read_to_string(&pos)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('%'))
        .map(|l| {
            let f: Vec<f64> = l
                .split_whitespace()
                .take(5)
                .map(|v| v.parse().unwrap())
                .collect();
            (f[1].round() as i64, Vector3::new(f[2], f[3], f[4]))
        })
        .collect();
    let mut lines = csv.lines();
    let cols: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| cols.iter().position(|c| *c == name).unwrap();
    let (tow, x, y, z) = (col("gpst_tow_s"), col("x_m"), col("y_m"), col("z_m"));
    let (pdop, res) = (col("pdop"), col("residual_rms_m"));
    let mut diffs = Vec::new();
    for l in lines {
        let f: Vec<f64> = l
            .split(',')
            .skip(1)
            .map(|v| v.parse().unwrap_or(f64::NAN))
            .collect();
        let g = |c: usize| f[c - 1];
        let ours = Vector3::new(g(x), g(y), g(z));
        let theirs = rtk
            .get(&(g(tow).round() as i64))
            .unwrap_or_else(|| panic!("RTKLIB has no fix at {}", g(tow)));
        let d = (ours - theirs).norm();
        assert!(
            d <= g(pdop) * g(res),
            "epoch {}: {d} m from RTKLIB, PDOP {} × residual RMS {} m",
            g(tow),
            g(pdop),
            g(res)
        );
        diffs.push(d);
    }
    assert_eq!(diffs.len(), rtk.len());
    let mut sorted = diffs.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "against RTKLIB rnx2rtkp, {} epochs: median {:.3} m, max {:.3} m apart",
        diffs.len(),
        sorted[sorted.len() / 2],
        sorted[sorted.len() - 1]
    );
}

/// One observation: (epoch index, satellite, observable), and [value, LLI, SSI].
type Value = (usize, String, String, [f64; 3]);

/// What georinex reads: one line per (epoch index, satellite, observable) that holds a
/// value, with its LLI and SSI (NaN when blank, +∞ when georinex does not report that
/// indicator).
fn georinex_values(path: &Path, epochs: &[usize]) -> Option<Vec<Value>> {
    if !python_has(&["georinex", "numpy"]) {
        return None;
    }
    let script = "import sys, georinex as gr, numpy as np\n\
        o = gr.load(sys.argv[1], useindicators=True)\n\
        ks = [int(k) for k in sys.argv[2].split(',')]\n\
        obs = [v for v in o.data_vars if not v.endswith('lli') and not v.endswith('ssi')]\n\
        for k in ks:\n\
        \x20   for sv in o.sv.values:\n\
        \x20       for v in obs:\n\
        \x20           x = float(o[v].values[k, list(o.sv.values).index(sv)])\n\
        \x20           if np.isnan(x):\n\
        \x20               continue\n\
        \x20           ind = [repr(float(o[v + s].values[k, list(o.sv.values).index(sv)])) if v + s in o else 'None' for s in ('lli', 'ssi')]\n\
        \x20           print(k, sv, v, repr(x), ind[0], ind[1])\n\
        print('times', ' '.join(str(t) for t in o.time.values[ks]))\n";
    let epochs_arg = epochs
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(",");
    let py = std::process::Command::new("python3")
        .args(["-W", "ignore", "-c", script])
        .arg(path)
        .arg(&epochs_arg)
        .output()
        .expect("python3");
    assert!(py.status.success(), "{}", stderr(&py));
    let text = String::from_utf8_lossy(&py.stdout).into_owned();
    let mut out = Vec::new();
    for l in text.lines().filter(|l| !l.starts_with("times")) {
        let f: Vec<&str> = l.split_whitespace().collect();
        // `None`: georinex has no indicator variable for this observable (it keeps LLI
        // for phase only, although RINEX 2.11 lets bit 2, AS on, mark a code too).
        let num = |s: &str| {
            if s == "None" {
                f64::INFINITY
            } else {
                s.parse::<f64>().unwrap()
            }
        };
        out.push((
            f[0].parse().unwrap(),
            f[1].to_string(),
            f[2].to_string(),
            [num(f[3]), num(f[4]), num(f[5])],
        ));
    }
    Some(out)
}

/// The same values through the reader under test.
fn our_values(path: &Path, epochs: &[usize]) -> Vec<Value> {
    let mut r = rinex_obs::open(path).unwrap();
    let mut e = ObsEpoch::default();
    let mut k = 0;
    let mut out = Vec::new();
    let ind = |d: Option<u8>| d.map_or(f64::NAN, f64::from);
    while r.next_epoch(&mut e).unwrap() {
        if epochs.contains(&k) {
            for (sat, values) in e.iter() {
                let types = r.header().obs_types(sat.system).unwrap();
                for (t, v) in types.iter().zip(values) {
                    if let Some(x) = v.value {
                        out.push((k, sat.to_string(), t.clone(), [x, ind(v.lli), ind(v.ssi)]));
                    }
                }
            }
        }
        k += 1;
    }
    out
}

fn compare_with_georinex(path: &Path, epochs: &[usize]) {
    let Some(theirs) = georinex_values(path, epochs) else {
        return;
    };
    let ours = our_values(path, epochs);
    let key = |v: &Value| (v.0, v.1.clone(), v.2.clone());
    let theirs: BTreeMap<_, _> = theirs.iter().map(|v| (key(v), v.3)).collect();
    let ours: BTreeMap<_, _> = ours.iter().map(|v| (key(v), v.3)).collect();
    assert_eq!(
        ours.keys().collect::<Vec<_>>(),
        theirs.keys().collect::<Vec<_>>(),
        "{}: the observations present differ",
        path.display()
    );
    let same = |a: f64, b: f64| (a.is_nan() && b.is_nan()) || a == b || b == f64::INFINITY;
    for (k, a) in &ours {
        let b = theirs[k];
        // Both parse the same F14.3 text; the values must be the same double.
        assert!(
            same(a[0], b[0]) && same(a[1], b[1]) && same(a[2], b[2]),
            "{}: {k:?}: ours {a:?}, georinex {b:?}",
            path.display()
        );
    }
    println!(
        "{}: {} observations (value, LLI, SSI) of epochs {epochs:?} equal georinex's",
        path.display(),
        ours.len()
    );
    assert!(ours.len() > 50);
}

#[test]
fn georinex_reads_the_same_values_from_the_geonet_file() {
    let Some(gnss) = shared_gnss() else {
        return;
    };
    compare_with_georinex(&gnss.join(GEONET_OBS), &[0, 1, 59, 119]);
}

/// The default world's text written into `dir`.
fn default_world(dir: &Path) -> std::path::PathBuf {
    crate::common::write(dir, "world.toml", &crate::common::default_world_text())
}

/// `hybridnav export WORLD --format rinex` of the default world (GPS + BeiDou, a city
/// drive of 172 receiver epochs), read back: every pseudorange and time tag the writer
/// was given, and the same values as georinex reads.
#[test]
fn the_exported_rinex3_file_reads_back_as_the_recorded_pseudoranges() {
    let dir = tmp_dir("obs-roundtrip");
    let world_path = default_world(&dir);
    let out = dir.join("out");
    let o = hybridnav(&[
        "export",
        world_path.to_str().unwrap(),
        "--format",
        "rinex",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let obs = out.join("hybridnav.obs");
    // The recording the export made (same world, seed and trial: deterministic).
    let world = hybridnav::world::load_world(&world_path).unwrap();
    let rec = hybridnav::export::record_trial(&world, world.file.montecarlo.seed, 0).unwrap();
    let mut expected = Vec::new();
    for b in rec
        .batches
        .iter()
        .filter(|b| b.source == hybridnav::measurement::SourceKind::Gnss)
    {
        let mut sats: Vec<_> = b
            .raw
            .gnss
            .iter()
            .filter(|o| matches!(o.sat.system, System::Gps | System::Bds))
            .collect();
        if sats.is_empty() {
            continue;
        }
        sats.sort_by_key(|o| (o.sat.system != System::Gps, o.sat.number));
        // The writer steps the receiver clock by whole milliseconds (src/export/rinex_obs.rs):
        // tag and code both lose k·1 ms.
        let jump_s = (sats[0].rx_clock_s * 1e3).round() * 1e-3;
        let tag = b.truth.t.add_seconds(sats[0].rx_clock_s - jump_s);
        let codes: Vec<(String, f64)> = sats
            .iter()
            .map(|o| {
                (
                    format!("{}{:02}", o.sat.system.letter(), o.sat.number),
                    o.pseudorange_m - C_MPS * jump_s,
                )
            })
            .collect();
        expected.push((tag, codes));
    }
    let mut r = rinex_obs::open(&obs).unwrap();
    let (c1c, c2i) = (
        r.header().index_of('G', "C1C").unwrap(),
        r.header().index_of('C', "C2I").unwrap(),
    );
    let mut e = ObsEpoch::default();
    let mut k = 0;
    let mut worst_m: f64 = 0.0;
    let mut n = 0;
    while r.next_epoch(&mut e).unwrap() {
        let (tag, codes) = &expected[k];
        // Tags are printed to 100 ns (F11.7).
        let dt = e.t.seconds_since(*tag);
        assert!(dt.abs() <= 50e-9, "epoch {k}: {dt} s");
        assert_eq!(e.len(), codes.len(), "epoch {k}");
        for ((sat, values), (name, code)) in e.iter().zip(codes) {
            assert_eq!(&sat.to_string(), name);
            let idx = if sat.system == 'G' { c1c } else { c2i };
            let read = values[idx].value.unwrap();
            // Printed F14.3: the value read is the recorded one rounded to the millimetre.
            worst_m = worst_m.max((read - code).abs());
            n += 1;
        }
        k += 1;
    }
    assert_eq!(k, expected.len());
    println!("{k} epochs, {n} pseudoranges read back, largest difference {worst_m:.6} m");
    assert!(worst_m <= 0.0005 + 1e-6, "{worst_m}");
    assert!(n > 1000);
    compare_with_georinex(&obs, &[0, 1, k - 1]);
}

/// Hostile observation files: each refused with exit code 2 and a message naming the file,
/// the line (and column for a field) and what was expected; a directory, `/dev/zero` and
/// a file over the cap before anything is read.
#[test]
fn hostile_observation_files_are_refused_with_their_line() {
    let dir = tmp_dir("obs-hostile");
    let nav = repo().join("ephemeris/nominal-gps-bds.rnx");
    let nav = nav.to_str().unwrap();
    let seeds = repo().join("fuzz/replay/rinex_obs");
    let v2 = std::fs::read_to_string(seeds.join("seed-07590920-head.05o")).unwrap();
    let v3 = std::fs::read_to_string(seeds.join("seed-export-head.obs")).unwrap();
    let lines = |t: &str, n: usize| {
        t.lines()
            .take(n)
            .map(|l| format!("{l}\n"))
            .collect::<String>()
    };
    let run = |name: &str, text: &str, needles: &[&str]| {
        let p = crate::common::write(&dir, name, text);
        let e = refused(
            &[
                "gnss",
                "position",
                "--obs",
                p.to_str().unwrap(),
                "--nav",
                nav,
            ],
            needles,
        );
        println!("{name}: {e}");
    };
    // The header (17 lines), the first epoch line and five of its eight satellites.
    run(
        "truncated.05o",
        &lines(&v2, 23),
        &["truncated.05o, line 24", "truncated file", "G20"],
    );
    run(
        "count.05o",
        &v2.replacen("  0  8G 3G 7", "  0  xG 3G 7", 1),
        &[
            "count.05o, line 18, column 30",
            "number of satellites",
            "'x'",
        ],
    );
    run(
        "count.obs",
        &v3.replacen("  0 17\n", "  0 18\n", 1),
        &[
            "count.obs, line 41, column 1",
            "satellite 18 of 18",
            "a new epoch record",
        ],
    );
    run(
        "number.05o",
        &v2.replacen("24767686.375", "24767686.3x5", 1),
        &[
            "number.05o, line 19, column 17",
            "an observation (F14.3)",
            "'24767686.3x5'",
        ],
    );
    let e = refused(
        &[
            "gnss",
            "position",
            "--obs",
            dir.to_str().unwrap(),
            "--nav",
            nav,
        ],
        &["is a directory", "RINEX observation file"],
    );
    println!("directory: {e}");
    let e = refused(
        &["gnss", "position", "--obs", "/dev/zero", "--nav", nav],
        &[
            "/dev/zero",
            "is a character device",
            "RINEX observation file",
        ],
    );
    println!("/dev/zero: {e}");
    // One byte over the cap, as a sparse file (no disk used): refused before a read.
    let huge = dir.join("huge.obs");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(hybridnav::gnss::rinex_obs::RINEX_OBS.max_bytes + 1)
        .unwrap();
    let e = refused(
        &[
            "gnss",
            "position",
            "--obs",
            huge.to_str().unwrap(),
            "--nav",
            nav,
        ],
        &[
            "huge.obs",
            "more than the 8 GiB a RINEX observation file may have",
        ],
    );
    println!("over the cap: {e}");
    let _ = std::fs::remove_file(&huge);
}
